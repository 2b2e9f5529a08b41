//! The GPU ray march against the CPU renderer, on every class of solution the renderer
//! reads (a fluence kept without directions, per-light transmittance with each phase
//! function and light kind, discrete ordinates), grey and RGB, pinhole and orthographic,
//! on grids whose sizes are not multiples of 8 with the medium touching the box; and the
//! closed form of Beer–Lambert. Runs on lavapipe in CI; elsewhere skips without an adapter.
#![cfg(feature = "gpu")]

use std::sync::OnceLock;

use glam::DVec3;
use lucent_core::{
    Angular, Boundary, Field, Light, LightTransmittance, Medium, OrdinateRadiance, Problem,
    Solution, SolveReport, Spectrum, StopReason,
};
use lucent_gpu::GpuContext;
use lucent_grid::{Grid, GridGeometry};
use lucent_optics::{Phase, SphericalQuadrature};
use lucent_render::{Camera, Image, RenderError, RenderSettings, render, render_on_device};

fn gpu(test: &str) -> Option<&'static GpuContext> {
    static GPU: OnceLock<Option<GpuContext>> = OnceLock::new();
    GPU.get_or_init(|| lucent_gpu::context_or_skip(test))
        .as_ref()
}

/// 13 × 9 × 11 cells of unequal sizes, the box from (−0.3, 0.1, 0) upward.
fn geometry() -> GridGeometry {
    GridGeometry::new(
        [13, 9, 11],
        DVec3::new(0.1, 0.12, 0.09),
        DVec3::new(-0.3, 0.1, 0.0),
    )
    .unwrap()
}

/// A smooth positive field that is not zero on the box's faces (the medium touches them).
fn blob(geometry: GridGeometry, scale: f32, phase: f64) -> Grid {
    let (lo, hi) = geometry.bounds();
    let centre = 0.5 * (lo + hi);
    Grid::from_fn(geometry, |p| {
        let d = (p - centre) / (hi - lo);
        let wave = (7.0 * p.x + phase).sin() * (5.0 * p.y).cos() * (3.0 * p.z + phase).sin();
        scale * (0.35 + (-(d.length_squared()) * 6.0).exp() + 0.3 * wave).max(0.02) as f32
    })
}

fn report() -> SolveReport {
    SolveReport {
        solver: "test".into(),
        iterations: 0,
        residual_history: vec![],
        wall_time_s: 0.0,
        peak_memory_bytes: 0,
        measured_peak_bytes: None,
        paging: None,
        choice: None,
        composition: None,
        stop_reason: StopReason::Exact,
    }
}

fn oblique_pinhole() -> Camera {
    Camera::Pinhole {
        position: [2.2, -1.7, 1.9],
        look_at: [0.35, 0.65, 0.5],
        up: [0.0, 0.0, 1.0],
        fov: 38.0,
    }
}

fn orthographic() -> Camera {
    Camera::Orthographic {
        position: [0.35, -2.0, 0.5],
        look_at: [0.35, 0.65, 0.5],
        up: [0.1, 0.0, 1.0],
        height: 1.4,
    }
}

/// 37 × 23 pixels (not a multiple of the workgroup), steps of 0.45 cells.
fn settings(background: Option<[f64; 3]>) -> RenderSettings {
    RenderSettings {
        width: 37,
        height: 23,
        step: 0.45,
        background,
    }
}

/// The largest per-pixel difference, against the image's largest value.
///
/// Tolerance 10⁻⁵ of the peak: the device marches in f32, so radiance and transmittance
/// summed over the ≤ 60 steps of these rays carry a relative rounding error of about
/// 60·2⁻²⁴ ≈ 4·10⁻⁶ at worst, and f32 positions move sample points by 10⁻⁷ of the box;
/// measured: 0.35–2.3·10⁻⁶ on these scenes. A march ending at the 10⁻⁴ opacity cut-off
/// one step apart would differ by 10⁻⁴ of the light behind, which these scenes do not
/// reach. What the test must catch is far above it: another jitter per pixel alone gives
/// 3·10⁻⁴, a linear instead of a smoothstep spot falloff fails the spot pixels, and a
/// wrong lerp order, phase function or light gives 10⁻³ to 1.
fn assert_same(gpu: &Image, cpu: &Image, what: &str) {
    assert_eq!((gpu.width, gpu.height), (cpu.width, cpu.height));
    let peak = cpu
        .pixels
        .iter()
        .flatten()
        .fold(0f32, |m, v| m.max(v.abs()));
    assert!(peak > 0.0, "{what}: a black reference proves nothing");
    let mut worst = (0.0f32, 0, 0);
    for (i, (g, c)) in gpu.pixels.iter().zip(&cpu.pixels).enumerate() {
        for k in 0..3 {
            let d = (g[k] - c[k]).abs();
            if d > worst.0 {
                worst = (d, i, k);
            }
        }
    }
    let (d, i, k) = worst;
    assert!(
        d <= 1e-5 * peak,
        "{what}: pixel {i} colour {k}: GPU {} vs CPU {} (peak {peak})",
        gpu.pixels[i][k],
        cpu.pixels[i][k]
    );
}

fn both(
    gpu: &GpuContext,
    problem: &Problem,
    solution: &Solution,
    camera: &Camera,
    settings: &RenderSettings,
    what: &str,
) {
    let cpu = render(problem, solution, camera, settings, None).unwrap();
    let device = render_on_device(gpu, problem, solution, camera, settings, None).unwrap();
    assert_same(&device, &cpu, what);
}

#[test]
fn isotropic_fluence_with_emission_matches_the_cpu() {
    let Some(gpu) = gpu("isotropic_fluence_with_emission_matches_the_cpu") else {
        return;
    };
    let g = geometry();
    // Grey σ_t, RGB albedo (a grid in one channel, constants in the others), emission in
    // two lights of different spectra, a coloured background.
    let medium = Medium {
        sigma_t: vec![blob(g, 4.0, 0.3)],
        albedo: vec![
            Field::Grid(blob(g, 1.0, 1.1).map(|a| a.min(1.0))),
            Field::Constant(0.5),
            Field::Constant(0.9),
        ],
        phase: Phase::Isotropic,
    };
    let lights = vec![
        Light::Emission {
            grid: blob(g, 0.5, 2.0),
            scale: Spectrum::Rgb([1.0, 0.3, 0.1]),
        },
        Light::Emission {
            grid: blob(g, 0.2, 0.7),
            scale: Spectrum::Grey(0.5),
        },
    ];
    let problem = Problem::new(g, medium, lights, Boundary::Vacuum, None).unwrap();
    let solution = Solution {
        fluence: vec![blob(g, 3.0, 0.1), blob(g, 2.0, 0.9), blob(g, 1.0, 1.7)],
        angular: None,
        standard_error: None,
        report: report(),
    };
    for (camera, name) in [
        (oblique_pinhole(), "pinhole"),
        (orthographic(), "orthographic"),
    ] {
        both(
            gpu,
            &problem,
            &solution,
            &camera,
            &settings(Some([0.2, 0.4, 0.8])),
            name,
        );
    }
}

/// Transmittance-like grids for a light: e^{−(distance-ish)}, different per channel.
fn transmittance(g: GridGeometry, channels: usize, seed: f64) -> Vec<Grid> {
    (0..channels)
        .map(|c| blob(g, 1.0, seed + c as f64).map(|v| (-1.5 * v).exp()))
        .collect()
}

#[test]
fn per_light_transmittance_matches_the_cpu_for_every_phase_and_light_kind() {
    let Some(gpu) = gpu("per_light_transmittance_matches_the_cpu_for_every_phase_and_light_kind")
    else {
        return;
    };
    let g = geometry();
    let lights = vec![
        Light::Point {
            position: DVec3::new(1.4, -0.5, 1.3),
            intensity: Spectrum::Rgb([3.0, 2.0, 1.0]),
        },
        // A point light inside the box: the 1/r² floor matters at the cells near it.
        Light::Point {
            position: DVec3::new(0.35, 0.62, 0.5),
            intensity: Spectrum::Grey(0.05),
        },
        Light::Spot {
            position: DVec3::new(-1.0, 0.6, 1.6),
            direction: DVec3::new(1.0, 0.0, -0.8).normalize(),
            intensity: Spectrum::Grey(4.0),
            inner_angle: 0.15,
            outer_angle: 0.35,
        },
        Light::Directional {
            direction: DVec3::new(0.3, 0.5, -1.0).normalize(),
            irradiance: Spectrum::Rgb([0.4, 0.6, 0.9]),
        },
    ];
    let phases = [
        Phase::Isotropic,
        Phase::henyey_greenstein(0.7).unwrap(),
        Phase::henyey_greenstein(-0.4).unwrap(),
        Phase::double_henyey_greenstein(0.85, -0.3, 0.7).unwrap(),
        Phase::Rayleigh,
    ];
    for phase in phases {
        // RGB σ_t: each channel marches its own extinction.
        let medium = Medium {
            sigma_t: vec![blob(g, 3.0, 0.2), blob(g, 5.0, 0.5), blob(g, 8.0, 0.8)],
            albedo: vec![Field::Constant(0.8)],
            phase,
        };
        let problem = Problem::new(g, medium, lights.clone(), Boundary::Vacuum, None).unwrap();
        let solution = Solution {
            fluence: vec![blob(g, 1.0, 0.0); 3],
            angular: Some(Angular::Lights(LightTransmittance {
                phase,
                lights: lights.clone(),
                transmittance: (0..lights.len())
                    .map(|l| transmittance(g, 3, l as f64))
                    .collect(),
                far: 100.0,
                min_distance: 0.05,
                isotropic_fluence: vec![blob(g, 0.3, 2.5)],
                arrivals: Vec::new(),
            })),
            standard_error: None,
            report: report(),
        };
        for camera in [oblique_pinhole(), orthographic()] {
            both(
                gpu,
                &problem,
                &solution,
                &camera,
                &settings(None),
                &format!("{phase}"),
            );
        }
    }
}

#[test]
fn discrete_ordinates_match_the_cpu() {
    let Some(gpu) = gpu("discrete_ordinates_match_the_cpu") else {
        return;
    };
    let g = geometry();
    let quadrature = SphericalQuadrature::octahedral(1).unwrap();
    let directions = quadrature.directions().to_vec();
    let m = directions.len();
    // A grey problem whose solution has three channels: the march follows the solution.
    let light = Light::Point {
        position: DVec3::new(1.5, 1.5, 1.5),
        intensity: Spectrum::Grey(2.0),
    };
    let medium = Medium {
        sigma_t: vec![blob(g, 6.0, 0.4)],
        albedo: vec![Field::Constant(0.95)],
        phase: Phase::henyey_greenstein(0.5).unwrap(),
    };
    let problem = Problem::new(g, medium, vec![light.clone()], Boundary::Vacuum, None).unwrap();
    let cells = g.voxel_count();
    let inscattered: Vec<Vec<f32>> = (0..3)
        .map(|c| {
            (0..cells * m)
                .map(|i| {
                    let (cell, d) = (i / m, i % m);
                    0.1 + 0.05 * ((cell as f32 * 0.37 + d as f32 * 1.3 + c as f32).sin() + 1.0)
                })
                .collect()
        })
        .collect();
    let solution = Solution {
        fluence: vec![blob(g, 1.0, 0.0); 3],
        angular: Some(Angular::Ordinates(OrdinateRadiance {
            directions,
            kernel: 6.0,
            inscattered,
            geometry: g,
            lights: Some(LightTransmittance {
                phase: Phase::henyey_greenstein(0.5).unwrap(),
                lights: vec![light],
                transmittance: vec![transmittance(g, 1, 3.0)],
                far: 100.0,
                min_distance: 0.05,
                isotropic_fluence: vec![Grid::filled(g, 0.0)],
                arrivals: Vec::new(),
            }),
        })),
        standard_error: None,
        report: report(),
    };
    both(
        gpu,
        &problem,
        &solution,
        &oblique_pinhole(),
        &settings(Some([0.0, 0.1, 0.3])),
        "ordinates",
    );
}

#[test]
fn beer_lambert_on_the_device() {
    let Some(gpu) = gpu("beer_lambert_on_the_device") else {
        return;
    };
    // One unit of σ_t = 2 along +x through the unit cube: the background times e^{−2},
    // to f32 rounding of ~30 products (10⁻⁶).
    let g = GridGeometry::new([8, 8, 8], DVec3::splat(0.125), DVec3::ZERO).unwrap();
    let medium = Medium {
        sigma_t: vec![Grid::filled(g, 2.0)],
        albedo: vec![Field::Constant(0.0)],
        phase: Phase::Isotropic,
    };
    let problem = Problem::new(g, medium, vec![], Boundary::Vacuum, None).unwrap();
    let solution = Solution {
        fluence: vec![Grid::filled(g, 0.0)],
        angular: None,
        standard_error: None,
        report: report(),
    };
    let camera = Camera::Orthographic {
        position: [-1.0, 0.5, 0.5],
        look_at: [0.5, 0.5, 0.5],
        up: [0.0, 0.0, 1.0],
        height: 0.5,
    };
    let s = RenderSettings {
        width: 8,
        height: 8,
        step: 0.37,
        background: Some([1.0, 0.5, 0.25]),
    };
    let image = render_on_device(gpu, &problem, &solution, &camera, &s, None).unwrap();
    let t = (-2.0f64).exp();
    for px in &image.pixels {
        for (c, bg) in [1.0, 0.5, 0.25].iter().enumerate() {
            assert!((f64::from(px[c]) - bg * t).abs() < 1e-6 * bg, "{px:?}");
        }
    }
}

#[test]
fn bad_solutions_and_oversized_images_are_refused_by_name() {
    let Some(gpu) = gpu("bad_solutions_and_oversized_images_are_refused_by_name") else {
        return;
    };
    let g = geometry();
    let medium = Medium {
        sigma_t: vec![blob(g, 2.0, 0.0)],
        albedo: vec![Field::Constant(0.5)],
        phase: Phase::Isotropic,
    };
    let problem = Problem::new(g, medium, vec![], Boundary::Vacuum, None).unwrap();
    let mut fluence = blob(g, 1.0, 0.0);
    fluence.data_mut()[17] = f32::NAN;
    let nan = Solution {
        fluence: vec![fluence],
        angular: None,
        standard_error: None,
        report: report(),
    };
    let camera = oblique_pinhole();
    match render_on_device(gpu, &problem, &nan, &camera, &settings(None), None) {
        Err(RenderError::Device {
            reason,
            unavailable,
        }) => {
            assert!(!unavailable);
            assert!(
                reason.contains("index 17") && reason.contains("not finite"),
                "{reason}"
            );
        }
        other => panic!("a NaN in the fluence must be refused: {other:?}"),
    }
    // A fluence on another grid.
    let elsewhere = Solution {
        fluence: vec![Grid::filled(
            GridGeometry::new([4, 4, 4], DVec3::splat(0.1), DVec3::ZERO).unwrap(),
            1.0,
        )],
        angular: None,
        standard_error: None,
        report: report(),
    };
    assert!(matches!(
        render_on_device(gpu, &problem, &elsewhere, &camera, &settings(None), None),
        Err(RenderError::Invalid(_))
    ));
    // 8192 × 8192 RGB f32 is 768 MiB: beyond lavapipe's 128 MiB binding (and most GPUs'),
    // refused before allocation with the limit's name.
    let fine = Solution {
        fluence: vec![blob(g, 1.0, 0.0)],
        angular: None,
        standard_error: None,
        report: report(),
    };
    let huge = RenderSettings {
        width: 8192,
        height: 8192,
        step: 0.5,
        background: None,
    };
    if gpu.limits().max_storage_buffer_binding_size < 8192 * 8192 * 12 {
        match render_on_device(gpu, &problem, &fine, &camera, &huge, None) {
            Err(RenderError::Device { reason, .. }) => {
                assert!(
                    reason.contains("max_storage_buffer_binding_size"),
                    "{reason}"
                )
            }
            other => panic!("an image beyond one binding must be refused: {other:?}"),
        }
    }
}
