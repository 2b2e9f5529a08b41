//! `cargo xtask bench-gpu [N...]`: every GPU backend at N³ (default 64 and 128) on the
//! adapter lucent picks, per kernel: seconds per step, cell updates per second and GB/s
//! by byte count, with the adapter's name.
//!
//! Timing is of whole solves with a fixed amount of work (a fixed number of steps, one
//! pass, one light), minus nothing: it includes uploading the problem, recording, the
//! host's reading of the per-step residual partials after every batch (up to 64 steps per
//! submit) and the download of the result, so it bounds the kernels' own time from above.
//! Bytes per cell are the compulsory traffic of one step (each field read or written
//! once, neighbours from cache):
//!
//! - `gpu-ftcs-diffusion`, one FTCS step on CSR: row start 4 + 7 × (column 4 + entry 4)
//!   + φ 4 + b 4 + φ′ 4 = 72 bytes;
//! - `gpu-ftcs-p1`, one step: φ, E_x, E_y, E_z, q read and φ′ written (24), φ, E read and
//!   E′ written (28) = 52 bytes;
//! - `gpu-convection-diffusion`, one light's pass: σ_t 4 + ρ 4 + ρ′ 4 = 12 bytes;
//! - `gpu-lbm` (D3Q7, the point light inside, so no first moment), one pull step: the
//!   populations read and written (7 × 8) + D/h, κ_a, q₀ (12) + ρ read and written (8)
//!   = 76 bytes;
//! - `gpu-direct`, one light: σ_t 4 + the transmittance 4 = 8 bytes (the march itself
//!   reads O(N) values per cell from cache: it is bound by arithmetic, not bandwidth).
//!
//! Then the renderer's ray march (`lucent render --gpu`) on `gpu-direct`'s solution of the
//! sun-lit blob, 640 × 480 at half-cell steps, against the CPU renderer in the same run:
//! seconds per frame, ray-march steps per second (the steps counted as the box's chord
//! over the step for every pixel: an upper bound, rays stop early where the cloud has
//! become opaque) and the largest pixel difference over the image's peak.
//!
//! On a CPU implementation (lavapipe) the run is a correctness run: it says so and its
//! numbers are never speed claims.

use std::time::Instant;

use glam::DVec3;
use lucent::core::{
    Boundary, Field, Light, Medium, ParamValue, Params, Problem, SolveOptions, Spectrum,
};
use lucent::gpu::GpuContext;
use lucent_grid::{Grid, GridGeometry};

/// Runs the benchmark at each size.
pub(crate) fn run(sizes: &[usize]) -> Result<(), String> {
    let context = GpuContext::shared().map_err(|e| e.to_string())?;
    println!("adapter: {}", context.describe());
    if context.is_software() {
        println!("a CPU implementation: this is a correctness run, not a measure of GPU speed");
    }
    println!("| backend | N³ | steps | s per step | cell updates/s | bytes/cell | GB/s | stop |");
    println!("|---|---|---|---|---|---|---|---|");
    for &n in sizes {
        let problems = Problems::new(n)?;
        let steps = 256;
        let fixed = |tolerance: f64| SolveOptions {
            relative_tolerance: tolerance,
            absolute_tolerance: 0.0,
            max_iterations: steps,
            // The host's share at 256³ (the CSR system of gpu-ftcs-diffusion: 12 GB) is
            // over the default 8 GiB.
            memory_budget: 96 << 30,
            ..SolveOptions::default()
        };
        let mut scattering = Params::default();
        scattering
            .0
            .insert("scattering".into(), ParamValue::Float(0.0));
        let cases: [(&str, &Problem, Params, SolveOptions, f64); 5] = [
            (
                "gpu-ftcs-diffusion",
                &problems.point,
                Params::default(),
                fixed(0.0),
                72.0,
            ),
            (
                "gpu-ftcs-p1",
                &problems.point,
                Params::default(),
                fixed(0.0),
                52.0,
            ),
            (
                "gpu-lbm",
                &problems.point,
                Params::default(),
                fixed(0.0),
                76.0,
            ),
            (
                "gpu-convection-diffusion",
                &problems.sun,
                scattering,
                SolveOptions::default(),
                12.0,
            ),
            (
                "gpu-direct",
                &problems.sun,
                Params::default(),
                SolveOptions::default(),
                8.0,
            ),
        ];
        for (name, problem, params, options, bytes) in cases {
            let registry = lucent::registry();
            let solver = registry.build(name, &params).map_err(|e| e.to_string())?;
            let start = Instant::now();
            let solution = solver.solve(problem, &options).map_err(|e| e.to_string())?;
            let seconds = start.elapsed().as_secs_f64();
            let steps = solution.report.iterations.max(1);
            let cells = (n * n * n) as f64;
            let per_step = seconds / steps as f64;
            println!(
                "| {name} | {n} | {steps} | {per_step:.3e} | {:.3e} | {bytes} | {:.2} | {} |",
                cells / per_step,
                cells * bytes / per_step * 1e-9,
                solution.report.stop_reason
            );
        }
    }
    println!();
    println!(
        "| ray march | N³ | pixels | s per frame, GPU | s per frame, CPU | steps/s, GPU | max pixel difference / peak |"
    );
    println!("|---|---|---|---|---|---|---|");
    for &n in sizes {
        let problems = Problems::new(n)?;
        let registry = lucent::registry();
        let solver = registry
            .build("gpu-direct", &Params::default())
            .map_err(|e| e.to_string())?;
        let solution = solver
            .solve(&problems.sun, &SolveOptions::default())
            .map_err(|e| e.to_string())?;
        let camera = lucent::render::Camera::Pinhole {
            position: [1.8, -1.6, 1.4],
            look_at: [0.5, 0.5, 0.5],
            up: [0.0, 0.0, 1.0],
            fov: 40.0,
        };
        let settings = lucent::render::RenderSettings {
            width: 640,
            height: 480,
            ..Default::default()
        };
        let time = |f: &dyn Fn() -> Result<lucent::render::Image, String>| {
            let start = Instant::now();
            let image = f()?;
            Ok::<_, String>((start.elapsed().as_secs_f64(), image))
        };
        // Once to compile the kernel, then timed.
        lucent::render::render_on_device(
            context,
            &problems.sun,
            &solution,
            &camera,
            &settings,
            None,
        )
        .map_err(|e| e.to_string())?;
        let (gpu_s, gpu) = time(&|| {
            lucent::render::render_on_device(
                context,
                &problems.sun,
                &solution,
                &camera,
                &settings,
                None,
            )
            .map_err(|e| e.to_string())
        })?;
        let (cpu_s, cpu) = time(&|| {
            lucent::render::render(&problems.sun, &solution, &camera, &settings, None)
                .map_err(|e| e.to_string())
        })?;
        let peak = cpu.pixels.iter().flatten().fold(0f32, |m, v| m.max(*v));
        let worst = cpu
            .pixels
            .iter()
            .zip(&gpu.pixels)
            .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
            .fold(0f32, f32::max);
        let steps = march_steps(&problems.sun, &camera, &settings);
        println!(
            "| render | {n} | {} | {gpu_s:.3e} | {cpu_s:.3e} | {:.3e} | {:.1e} |",
            settings.width * settings.height,
            steps / gpu_s,
            worst / peak
        );
    }
    Ok(())
}

/// Steps of the march over every pixel: the chord through the box over the step.
fn march_steps(
    problem: &Problem,
    camera: &lucent::render::Camera,
    settings: &lucent::render::RenderSettings,
) -> f64 {
    let geometry = problem.geometry();
    let (lo, hi) = geometry.bounds();
    let step = settings.step * geometry.spacing().min_element();
    let aspect = settings.width as f64 / settings.height as f64;
    let mut steps = 0.0;
    for y in 0..settings.height {
        for x in 0..settings.width {
            let u = (x as f64 + 0.5) / settings.width as f64;
            let v = (y as f64 + 0.5) / settings.height as f64;
            if let Ok((o, d)) = camera.ray(u, v, aspect)
                && let Some((t0, t1)) = lucent_grid::ray_box(o, d, lo, hi)
            {
                steps += ((t1 - t0) / step).ceil();
            }
        }
    }
    steps
}

/// A smoke blob at N³ lit by a sun (for the light marches) and by a point light inside
/// (for the time-stepping schemes, which take point lights).
struct Problems {
    sun: Problem,
    point: Problem,
}

impl Problems {
    fn new(n: usize) -> Result<Self, String> {
        let geometry = GridGeometry::new([n; 3], DVec3::splat(1.0 / n as f64), DVec3::ZERO)
            .map_err(|e| e.to_string())?;
        let medium = |sigma: &(dyn Fn(DVec3) -> f64 + Sync)| Medium {
            sigma_t: vec![Grid::from_fn(geometry, |x| sigma(x) as f32)],
            albedo: vec![Field::Constant(0.9)],
            phase: lucent::optics::Phase::Isotropic,
        };
        let blob = |x: DVec3| 2.0 + 20.0 * (-12.0 * (x - DVec3::splat(0.5)).length_squared()).exp();
        let sun = Problem::new(
            geometry,
            medium(&blob),
            vec![Light::Directional {
                direction: DVec3::new(0.4, -0.3, 0.87).normalize(),
                irradiance: Spectrum::Grey(1.0),
            }],
            Boundary::Vacuum,
            None,
        )
        .map_err(|e| e.to_string())?;
        // P1 by FTCS needs a homogeneous medium.
        let point = Problem::new(
            geometry,
            medium(&|_| 10.0),
            vec![Light::Point {
                position: DVec3::splat(0.5),
                intensity: Spectrum::Grey(1.0),
            }],
            Boundary::Vacuum,
            None,
        )
        .map_err(|e| e.to_string())?;
        Ok(Self { sun, point })
    }
}
