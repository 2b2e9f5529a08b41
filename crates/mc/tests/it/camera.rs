//! Camera images: spectral MIS over RGB extinction must agree with tracing every channel on
//! its own (two unbiased estimators of the same image), and cost one path instead of three.

use glam::DVec3;
use lucent_core::{Boundary, Field, Light, Medium, Problem, Spectrum};
use lucent_grid::GridGeometry;
use lucent_grid::procedural::gaussian_blob;
use lucent_mc::{McConfig, camera_image};
use lucent_optics::Phase;

#[test]
fn spectral_mis_agrees_with_per_channel_tracing() {
    let geometry = GridGeometry::new([20; 3], DVec3::splat(0.1), DVec3::splat(-1.0)).unwrap();
    let blob = gaussian_blob(geometry, DVec3::ZERO, 0.4).unwrap();
    // Ketchup-like: the channels' extinctions differ by 3.5×, their albedos by 40×.
    let medium = Medium {
        sigma_t: [2.0f32, 5.0, 7.0]
            .iter()
            .map(|&s| blob.map(|d| s * d))
            .collect(),
        albedo: vec![
            Field::Constant(0.9),
            Field::Constant(0.3),
            Field::Constant(0.02),
        ],
        phase: Phase::henyey_greenstein(0.4).unwrap(),
    };
    let lights = vec![
        Light::Directional {
            direction: DVec3::new(0.3, 0.5, -0.81).normalize(),
            irradiance: Spectrum::Rgb([3.0, 3.0, 3.0]),
        },
        Light::Sky {
            radiance: Spectrum::Grey(0.2),
        },
    ];
    let problem = Problem::new(geometry, medium, lights, Boundary::Vacuum, None).unwrap();
    let ray = |u: f64, v: f64| {
        let origin = DVec3::new(-0.9 + 1.8 * u, -3.0, 0.9 - 1.8 * v);
        (origin, DVec3::Y)
    };
    let (w, h, spp) = (24, 24, 256);
    let mis = camera_image(
        &problem,
        w,
        h,
        spp,
        [0.0; 3],
        &McConfig {
            seed: 1,
            ..Default::default()
        },
        ray,
    )
    .unwrap();
    let separate = camera_image(
        &problem,
        w,
        h,
        spp,
        [0.0; 3],
        &McConfig {
            seed: 2,
            spectral_mis: false,
            ..Default::default()
        },
        ray,
    )
    .unwrap();
    for c in 0..3 {
        let mean =
            |img: &[[f32; 3]]| img.iter().map(|p| f64::from(p[c])).sum::<f64>() / img.len() as f64;
        let se = |err: &[[f32; 3]]| {
            err.iter()
                .map(|e| f64::from(e[c]).powi(2))
                .sum::<f64>()
                .sqrt()
                / err.len() as f64
        };
        let (a, b) = (mean(&mis.radiance), mean(&separate.radiance));
        let sigma = se(&mis.std_error).hypot(se(&separate.std_error));
        assert!(a > 0.0 && b > 0.0, "channel {c} is lit");
        assert!(
            (a - b).abs() < 4.0 * sigma,
            "channel {c}: spectral MIS {a}, per channel {b}, σ {sigma}"
        );
        // Per pixel, z-scores of the difference must look like noise.
        let z: Vec<f64> = mis
            .radiance
            .iter()
            .zip(&separate.radiance)
            .zip(mis.std_error.iter().zip(&separate.std_error))
            .filter(|(_, (e1, e2))| e1[c] > 0.0 && e2[c] > 0.0)
            .map(|((p, q), (e1, e2))| {
                (f64::from(p[c]) - f64::from(q[c])) / f64::from(e1[c]).hypot(f64::from(e2[c]))
            })
            .collect();
        let rms = (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt();
        assert!(rms < 1.3, "channel {c}: rms z {rms}");
    }
}

#[test]
fn an_index_matched_embedded_sphere_attenuates_by_its_chord() {
    // A pure absorber filling the box, cut to a sphere of radius 0.8 by an embedded SDF:
    // each camera ray keeps e^{−σ·2√(R² − b²)} of the background, b its distance from the
    // centre. Rays near the silhouette are left out (the trilinear SDF's surface is within
    // ~h²/R of the sphere there, and the chord's slope is infinite).
    use lucent_grid::Grid;
    use lucent_grid::procedural::Shape;
    let geometry =
        GridGeometry::new([24; 3], DVec3::splat(2.0 / 24.0), DVec3::splat(-1.0)).unwrap();
    let sigma = 1.5;
    let sphere = Shape::Sphere {
        centre: DVec3::ZERO,
        radius: 0.8,
    }
    .sdf_grid(geometry)
    .unwrap();
    let medium = Medium {
        sigma_t: vec![Grid::filled(geometry, sigma as f32)],
        albedo: vec![Field::Constant(0.0)],
        phase: Phase::Isotropic,
    };
    let problem = Problem::new(geometry, medium, vec![], Boundary::Vacuum, Some(sphere)).unwrap();
    let (w, h, spp) = (12, 12, 1024);
    let ray = |u: f64, v: f64| (DVec3::new(-0.9 + 1.8 * u, -3.0, 0.9 - 1.8 * v), DVec3::Y);
    let image = camera_image(&problem, w, h, spp, [1.0; 3], &McConfig::default(), ray).unwrap();
    let mut checked = 0;
    for y in 0..h {
        for x in 0..w {
            let (bx, bz) = (
                -0.9 + 1.8 * (x as f64 + 0.5) / w as f64,
                0.9 - 1.8 * (y as f64 + 0.5) / h as f64,
            );
            let b2 = bx * bx + bz * bz;
            if b2 > 0.6 * 0.6 {
                continue;
            }
            // The pixel averages over its footprint; the chord varies little this far in.
            let exact = (-sigma * 2.0 * (0.64 - b2).sqrt()).exp();
            let px = image.radiance[y * w + x][0] as f64;
            let se = (exact * (1.0 - exact) / spp as f64).sqrt();
            assert!(
                (px - exact).abs() < 4.0 * se + 0.02,
                "pixel ({x},{y}): {px} vs {exact} ± {se}"
            );
            checked += 1;
        }
    }
    assert!(checked >= 30, "{checked}");
    // Outside the sphere nothing attenuates, though the box is full of medium.
    assert!(
        (image.radiance[0][0] - 1.0).abs() < 1e-6,
        "corner {:?}",
        image.radiance[0]
    );
}

#[test]
fn emission_is_integrated_along_camera_paths() {
    // A pure absorber (σ = 1.5) emitting Q = 2 uniformly, seen through one unit of it:
    // L = Q/σ (1 − e^{−σ}). Absorbing, so the estimate is exact but for the tentative-
    // collision sampling noise.
    use lucent_grid::Grid;
    let geometry = GridGeometry::new([8; 3], DVec3::splat(0.125), DVec3::ZERO).unwrap();
    let medium = Medium {
        sigma_t: vec![Grid::filled(geometry, 1.5)],
        albedo: vec![Field::Constant(0.0)],
        phase: Phase::Isotropic,
    };
    let glow = Light::Emission {
        grid: Grid::filled(geometry, 1.0),
        scale: Spectrum::Grey(2.0),
    };
    let problem = Problem::new(geometry, medium, vec![glow], Boundary::Vacuum, None).unwrap();
    let ray = |u: f64, v: f64| (DVec3::new(-1.0, 0.1 + 0.8 * u, 0.9 - 0.8 * v), DVec3::X);
    let image = camera_image(&problem, 4, 4, 4096, [0.0; 3], &McConfig::default(), ray).unwrap();
    let exact = 2.0 / 1.5 * (1.0 - (-1.5f64).exp());
    for (px, se) in image.radiance.iter().zip(&image.std_error) {
        assert!(
            (f64::from(px[0]) - exact).abs() < 4.0 * f64::from(se[0]) + 1e-9,
            "{px:?} ± {se:?} vs {exact}"
        );
        assert!(f64::from(se[0]) < 0.02 * exact);
    }
}

#[test]
fn emission_particles_carry_the_emitted_power() {
    // Particle tracing from an emission light: the power that enters the domain is
    // 4π Σ Q V exactly (every particle starts inside), and it is all absorbed or escapes.
    use lucent_grid::Grid;
    use lucent_mc::estimate;
    let geometry = GridGeometry::new([6; 3], DVec3::splat(0.5), DVec3::ZERO).unwrap();
    let blob = gaussian_blob(geometry, DVec3::splat(1.5), 0.4).unwrap();
    let medium = Medium {
        sigma_t: vec![Grid::filled(geometry, 2.0)],
        albedo: vec![Field::Constant(0.5)],
        phase: Phase::Isotropic,
    };
    let glow = Light::Emission {
        grid: blob.clone(),
        scale: Spectrum::Grey(1.0),
    };
    let problem = Problem::new(geometry, medium, vec![glow], Boundary::Vacuum, None).unwrap();
    let run = estimate(
        &problem,
        &McConfig {
            particles: 20_000,
            batches: 8,
            ..Default::default()
        },
    )
    .unwrap();
    let e = &run.energy[0];
    // ∫ of the trilinear interpolant of the blob over the box, by a fine midpoint rule.
    let n = 120;
    let h = 3.0 / n as f64;
    let mut integral = 0.0;
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let x = DVec3::new(i as f64 + 0.5, j as f64 + 0.5, k as f64 + 0.5) * h;
                integral += f64::from(blob.sample_trilinear(x)) * h * h * h;
            }
        }
    }
    let expected = 4.0 * std::f64::consts::PI * integral;
    assert!(
        (e.emitted.mean - expected).abs() < 4.0 * e.emitted.std_error + 1e-3 * expected,
        "{:?} vs {expected}",
        e.emitted
    );
    assert!(
        e.imbalance.mean.abs() <= 4.0 * e.imbalance.std_error + 1e-9 * expected,
        "{:?}",
        e.imbalance
    );
}
