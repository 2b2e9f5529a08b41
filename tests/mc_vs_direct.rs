//! Two independent single-scattering images must agree: Monte Carlo path tracing cut after
//! one scattering event (`max_depth = 1`) against `direct` + the ray-marching renderer.
//! They share nothing but the problem: MC samples collisions by delta tracking and
//! shadows by ratio tracking; `direct` integrates optical depths exactly on the grid and
//! the renderer marches with exact per-step attenuation.

use glam::DVec3;
use lucent::core::{
    Boundary, DirectSolver, Field, Light, Medium, Problem, SolveOptions, Solver, Spectrum,
};
use lucent::grid::GridGeometry;
use lucent::grid::procedural::NoiseCloud;
use lucent::mc::{McConfig, camera_image};
use lucent::optics::Phase;
use lucent::render::{Camera, RenderSettings, render};

#[test]
fn single_scattering_images_agree() {
    let geometry =
        GridGeometry::new([24; 3], DVec3::splat(2.0 / 24.0), DVec3::splat(-1.0)).unwrap();
    let cloud = NoiseCloud::new(4, DVec3::ZERO, 0.95)
        .rasterize(geometry)
        .unwrap();
    // Isotropic scattering: `direct` in-scatters the sky isotropically, which is exact only
    // for an isotropic phase function.
    let medium = Medium {
        sigma_t: vec![cloud.map(|d| 6.0 * d)],
        albedo: vec![Field::Constant(0.9)],
        phase: Phase::Isotropic,
        eta: 1.0,
    };
    let lights = vec![
        Light::Directional {
            direction: DVec3::new(-0.3, 0.4, -0.866).normalize(),
            irradiance: Spectrum::Grey(4.0),
        },
        Light::Sky {
            radiance: Spectrum::Grey(0.3),
        },
    ];
    let problem = Problem::new(geometry, medium, lights, Boundary::Vacuum, None).unwrap();
    let camera = Camera::Pinhole {
        position: [0.0, -3.5, 0.5],
        look_at: [0.0, 0.0, 0.0],
        up: [0.0, 0.0, 1.0],
        fov: 36.0,
    };
    let (w, h) = (48, 36);
    let background = [0.3; 3];

    let solution = DirectSolver {
        sky_level: 3,
        ..Default::default()
    }
    .solve(&problem, &SolveOptions::default())
    .unwrap();
    let settings = RenderSettings {
        width: w,
        height: h,
        step: 0.25,
        background: Some(background),
    };
    let deterministic = render(&problem, &solution, &camera, &settings, None).unwrap();

    let config = McConfig {
        max_depth: 1,
        seed: 3,
        ..Default::default()
    };
    let mc = camera_image(&problem, w, h, 400, background, &config, |u, v| {
        camera.ray(u, v, w as f64 / h as f64).unwrap()
    })
    .unwrap();

    let mean = |pixels: &[[f32; 3]]| {
        pixels.iter().map(|p| f64::from(p[0])).sum::<f64>() / pixels.len() as f64
    };
    let (a, b) = (mean(&mc.radiance), mean(&deterministic.pixels));
    let se_mean = (mc
        .std_error
        .iter()
        .map(|e| f64::from(e[0]).powi(2))
        .sum::<f64>())
    .sqrt()
        / mc.radiance.len() as f64;
    // Image means: MC noise (se_mean) plus the deterministic path's discretisation (sky
    // quadrature of 512 directions, trilinear transmittance between cell centres) of a
    // fraction of a percent.
    assert!(
        (a - b).abs() < 3.0 * se_mean + 0.01 * b,
        "image means: mc {a} ± {se_mean}, direct {b}"
    );
    // Per pixel, within noise and that discretisation allowance.
    let mut outliers = 0;
    for (m, (d, e)) in mc
        .radiance
        .iter()
        .zip(deterministic.pixels.iter().zip(&mc.std_error))
    {
        let allowance = 4.0 * f64::from(e[0]) + 0.03 * f64::from(d[0]);
        if (f64::from(m[0]) - f64::from(d[0])).abs() > allowance {
            outliers += 1;
        }
    }
    assert!(
        outliers <= mc.radiance.len() / 100,
        "{outliers} of {} pixels disagree",
        mc.radiance.len()
    );
}
