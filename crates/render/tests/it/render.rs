//! The renderer against closed forms: Beer–Lambert attenuation of the background, the
//! emission integral Q/σ_t (1 − e^{−σ_t L}), camera geometry, and the tone curves.

use glam::DVec3;
use lucent_core::{
    Boundary, Field, Light, Medium, Problem, Solution, SolveReport, Spectrum, StopReason,
};
use lucent_grid::{Grid, GridGeometry};
use lucent_optics::Phase;
use lucent_render::{Camera, Image, RenderSettings, ToneMap, render};

fn problem(sigma_t: f32, albedo: f32, lights: Vec<Light>) -> Problem {
    let geometry = GridGeometry::new([8, 8, 8], DVec3::splat(0.125), DVec3::ZERO).unwrap();
    let medium = Medium {
        sigma_t: vec![Grid::filled(geometry, sigma_t)],
        albedo: vec![Field::Constant(albedo)],
        phase: Phase::Isotropic,
    };
    Problem::new(geometry, medium, lights, Boundary::Vacuum, None).unwrap()
}

fn dark_solution(problem: &Problem) -> Solution {
    Solution {
        fluence: vec![Grid::filled(*problem.geometry(), 0.0)],
        angular: None,
        standard_error: None,
        report: SolveReport {
            solver: "none".into(),
            iterations: 0,
            residual_history: vec![],
            wall_time_s: 0.0,
            peak_memory_bytes: 0,
            measured_peak_bytes: None,
            paging: None,
            choice: None,
            composition: None,
            stop_reason: StopReason::Exact,
        },
    }
}

/// Looks along +x through the unit cube, so every ray crosses exactly one unit of medium.
fn side_view() -> Camera {
    Camera::Orthographic {
        position: [-1.0, 0.5, 0.5],
        look_at: [0.5, 0.5, 0.5],
        up: [0.0, 0.0, 1.0],
        height: 0.5,
    }
}

#[test]
fn background_is_attenuated_by_beer_lambert() {
    let p = problem(2.0, 0.0, vec![]);
    let settings = RenderSettings {
        width: 8,
        height: 8,
        step: 0.37,
        background: Some([1.0, 0.5, 0.25]),
    };
    let image = render(&p, &dark_solution(&p), &side_view(), &settings, None).unwrap();
    let t = (-2.0f64).exp();
    for px in &image.pixels {
        // Each step multiplies exactly by e^{−σ_t Δ}; f32 output.
        for (c, bg) in [1.0, 0.5, 0.25].iter().enumerate() {
            assert!((f64::from(px[c]) - bg * t).abs() < 1e-6, "{px:?}");
        }
    }
}

#[test]
fn emission_integrates_exactly() {
    let geometry = GridGeometry::new([8, 8, 8], DVec3::splat(0.125), DVec3::ZERO).unwrap();
    let glow = Light::Emission {
        grid: Grid::filled(geometry, 1.0),
        scale: Spectrum::Grey(3.0),
    };
    let p = problem(2.0, 0.0, vec![glow]);
    let settings = RenderSettings {
        width: 4,
        height: 4,
        step: 0.5,
        background: Some([0.0; 3]),
    };
    let image = render(&p, &dark_solution(&p), &side_view(), &settings, None).unwrap();
    let expected = 3.0 / 2.0 * (1.0 - (-2.0f64).exp());
    assert!(
        image
            .pixels
            .iter()
            .all(|px| (f64::from(px[0]) - expected).abs() < 1e-6),
        "{:?} vs {expected}",
        image.pixels[0]
    );
}

#[test]
fn isotropic_inscattering_of_a_uniform_fluence() {
    // φ = 4π everywhere (L = 1 isotropic), no extinction of the source: a ray through one
    // unit of σ_t = 1, albedo 1, picks up ∫ e^{−s} σ_s φ/(4π) ds = 1 − e^{−1}.
    let p = problem(1.0, 1.0, vec![]);
    let mut solution = dark_solution(&p);
    solution.fluence = vec![Grid::filled(
        *p.geometry(),
        (4.0 * std::f64::consts::PI) as f32,
    )];
    let settings = RenderSettings {
        width: 4,
        height: 4,
        step: 0.25,
        background: Some([0.0; 3]),
    };
    let image = render(&p, &solution, &side_view(), &settings, None).unwrap();
    let expected = 1.0 - (-1.0f64).exp();
    assert!(
        image
            .pixels
            .iter()
            .all(|px| (f64::from(px[1]) - expected).abs() < 1e-6),
        "{:?}",
        image.pixels[0]
    );
}

#[test]
fn pinhole_rays_start_at_the_eye_and_the_centre_ray_hits_the_target() {
    let camera = Camera::Pinhole {
        position: [1.0, 2.0, 3.0],
        look_at: [4.0, 6.0, 3.0],
        up: [0.0, 0.0, 1.0],
        fov: 60.0,
    };
    let (o, d) = camera.ray(0.5, 0.5, 1.5).unwrap();
    assert_eq!(o, DVec3::new(1.0, 2.0, 3.0));
    assert!((d - DVec3::new(0.6, 0.8, 0.0)).length() < 1e-12);
    // The top edge of the image is half the field of view above the axis.
    let (_, top) = camera.ray(0.5, 0.0, 1.5).unwrap();
    assert!((top.dot(d).acos().to_degrees() - 30.0).abs() < 1e-9);
    assert!(top.z > 0.0, "v = 0 is the top of the image");
    assert!(
        Camera::Pinhole {
            position: [0.0; 3],
            look_at: [0.0; 3],
            up: [0.0, 0.0, 1.0],
            fov: 40.0
        }
        .validate()
        .is_err()
    );
    assert!(
        Camera::Pinhole {
            position: [0.0; 3],
            look_at: [0.0, 0.0, 1.0],
            up: [0.0, 0.0, 1.0],
            fov: 40.0
        }
        .validate()
        .is_err()
    );
    assert!(
        Camera::Orthographic {
            position: [0.0; 3],
            look_at: [1.0, 0.0, 0.0],
            up: [0.0, 0.0, 1.0],
            height: -1.0
        }
        .validate()
        .is_err()
    );
}

#[test]
fn tone_curves_and_srgb_encoding() {
    let image = Image {
        width: 3,
        height: 1,
        pixels: vec![[0.0; 3], [0.5; 3], [100.0; 3]],
    };
    let clamp = image.to_srgb8(0.0, ToneMap::Clamp);
    assert_eq!(&clamp[..3], &[0, 0, 0]);
    // sRGB(0.5) = 0.7354 → 188.
    assert_eq!(clamp[3], 188);
    assert_eq!(clamp[6], 255);
    // One stop of exposure doubles the radiance before the curve.
    let brighter = image.to_srgb8(1.0, ToneMap::Clamp);
    assert_eq!(brighter[3], 255);
    let aces = image.to_srgb8(0.0, ToneMap::Aces);
    let reinhard = image.to_srgb8(0.0, ToneMap::Reinhard);
    assert!(aces[3] < 255 && aces[6] == 255 && reinhard[6] < 255);
}

#[test]
fn bad_settings_are_refused() {
    let p = problem(1.0, 0.5, vec![]);
    let s = dark_solution(&p);
    for settings in [
        RenderSettings {
            width: 0,
            height: 4,
            ..Default::default()
        },
        RenderSettings {
            width: 4,
            height: 4,
            step: 0.0,
            ..Default::default()
        },
    ] {
        assert!(render(&p, &s, &side_view(), &settings, None).is_err());
    }
    let dir = tempfile::tempdir().unwrap();
    let image = Image {
        width: 1,
        height: 1,
        pixels: vec![[0.0; 3]],
    };
    assert!(
        image
            .write(dir.path().join("x.jpg"), 0.0, ToneMap::Aces)
            .is_err()
    );
    image
        .write(dir.path().join("x.png"), 0.0, ToneMap::Aces)
        .unwrap();
}
