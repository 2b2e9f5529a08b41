//! `cargo xtask bench-dom [N] [ORDER]`: a converged discrete-ordinates solve (relative
//! tolerance 1e-4) of a procedural cloud at N³ (128 by default) with level-symmetric
//! S_ORDER (6: 48 directions), Henyey–Greenstein g = 0.6, albedo 0.95, under a sun: the
//! the discrete-ordinates benchmark, against Bernabei's 5.3 s per frame at 128³ for three unconverged
//! iterations on a GTX 580. Prints wall time (with `direct` and set-up), sweeps, sweep
//! time, time per cell-direction update and the sweeps' GB/s by their minimal traffic, for
//! three solves by source iteration with DSA (the default), one by GMRES with DSA
//! (`outer = "gmres"`), and one by each with TSA (`acceleration = "tsa"`, whose S2
//! sweeps are counted apart and timed with the acceleration).

use glam::DVec3;
use lucent::core::{
    Boundary, Field, Light, Medium, ParamValue, Params, Problem, SolveOptions, Solver, Spectrum,
};
use lucent_grid::GridGeometry;
use lucent_grid::procedural::NoiseCloud;

use crate::bench_diffusion::copy_bandwidth;

/// Runs the benchmark (with `gpu`, the device's run instead: [`run_gpu`]).
pub(crate) fn run(n: usize, order: usize, gpu: bool) -> Result<(), String> {
    let err = |e: &dyn std::fmt::Display| e.to_string();
    let geometry =
        GridGeometry::from_bounds([n; 3], DVec3::ZERO, DVec3::ONE).map_err(|e| err(&e))?;
    let cloud = NoiseCloud::new(7, DVec3::splat(0.5), 0.45);
    let mut density = cloud.rasterize(geometry).map_err(|e| err(&e))?;
    // Peak σ_t = 64 per unit length: σ_t h ≤ 0.5 at 128³, 64 mean free paths across.
    let peak = density.stats().max.max(f32::MIN_POSITIVE);
    density
        .data_mut()
        .iter_mut()
        .for_each(|v| *v *= 64.0 / peak);
    let medium = Medium {
        sigma_t: vec![density],
        albedo: vec![Field::Constant(0.95)],
        phase: lucent::optics::Phase::henyey_greenstein(0.6).map_err(|e| err(&e))?,
    };
    let sun = Light::Directional {
        direction: DVec3::new(0.3, 0.4, -0.866).normalize(),
        irradiance: Spectrum::Grey(1.0),
    };
    let problem =
        Problem::new(geometry, medium, vec![sun], Boundary::Vacuum, None).map_err(|e| err(&e))?;
    let options = SolveOptions {
        relative_tolerance: 1e-4,
        ..SolveOptions::default()
    };
    let (_, copy) = copy_bandwidth();
    let directions = lucent::optics::SphericalQuadrature::level_symmetric(order)
        .map_err(|e| err(&e))?
        .len();
    println!(
        "# cargo xtask bench-dom ({n}³, S{order}: {directions} directions, {} threads)",
        rayon::current_num_threads()
    );
    println!();
    println!("copy bandwidth: {:.1} GB/s", copy / 1e9);
    println!();
    // `direct` alone (the renderer's transmittance), and the uncollided cell integrals that
    // make the first-collision source.
    let t = std::time::Instant::now();
    lucent::core::DirectSolver::default()
        .solve(&problem, &options)
        .map_err(|e| err(&e))?;
    println!("direct on {n}³: {:.2} s", t.elapsed().as_secs_f64());
    let t = std::time::Instant::now();
    for light in problem.lights() {
        lucent::core::uncollided_cells(problem.medium().sigma_t(0), light, 50.0);
    }
    println!(
        "uncollided cell integrals on {n}³: {:.2} s",
        t.elapsed().as_secs_f64()
    );
    println!();
    if gpu {
        return run_gpu(n, order, directions, &problem, &options);
    }
    println!(
        "| run | outer | acceleration | wall | sweeps (+ S2 sweeps) | sweeps alone | ns per cell-direction (sweeps) | sweep GB/s (sources read, radiance written, σ_t, σ_s) | sources + scattering products | DSA or TSA | Anderson | Krylov vectors | rest (direct, first-collision, set-up) | stop |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    // Source iteration (the default) three times, then GMRES once: the outer iterations
    // compared on the same problem and machine.
    for (run, (outer, acceleration)) in [
        ("source-iteration", "dsa"),
        ("source-iteration", "dsa"),
        ("source-iteration", "dsa"),
        ("gmres", "dsa"),
        ("source-iteration", "tsa"),
        ("gmres", "tsa"),
    ]
    .into_iter()
    .enumerate()
    {
        let mut params = Params::default();
        params
            .0
            .insert("order".into(), ParamValue::Int(order as i64));
        params
            .0
            .insert("outer".into(), ParamValue::Text(outer.into()));
        params
            .0
            .insert("acceleration".into(), ParamValue::Text(acceleration.into()));
        let solver = lucent::dom::DomSolver::from_params(&params).map_err(|e| err(&e))?;
        let t = std::time::Instant::now();
        let (solution, records) = solver
            .solve_with_details(&problem, &options)
            .map_err(|e| err(&e))?;
        let wall = t.elapsed().as_secs_f64();
        let r = &records[0].convergence;
        let sweeps = r.sweeps as f64;
        let cells = (n * n * n) as f64;
        let updates = cells * directions as f64 * sweeps;
        // Per cell and sweep the wavefronts fill each direction's source from the stored
        // fixed source and in-scattered radiance (two f32 reads, 8 B; storage =
        // propagation here), write its f64 radiance (8 B) and read σ_t and σ_s (8 B).
        let gbs = cells * (16.0 * directions as f64 + 8.0) * sweeps / r.sweep_seconds / 1e9;
        let rest = wall
            - r.sweep_seconds
            - r.scatter_seconds
            - r.dsa_seconds
            - r.anderson_seconds
            - r.krylov_seconds;
        println!(
            "| {run} | {outer} | {acceleration} | {wall:.2} s | {}{} | {:.2} s | {:.2} | {gbs:.1} ({:.0}% of copy) | {:.2} s | {:.2} s | {:.2} s | {:.2} s | {rest:.2} s | {:?} |",
            r.sweeps,
            if r.low_order_sweeps > 0 {
                format!(" (+ {})", r.low_order_sweeps)
            } else {
                String::new()
            },
            r.sweep_seconds,
            r.sweep_seconds / updates * 1e9,
            100.0 * gbs * 1e9 / copy,
            r.scatter_seconds,
            r.dsa_seconds,
            r.anderson_seconds,
            r.krylov_seconds,
            solution.report.stop_reason
        );
    }
    Ok(())
}

/// `gpu-dom` (source iteration, the default) on the adapter lucent picks, and `dom` on the
/// host beside it up to 128³ (beyond, the host's work alone would take minutes): wall per
/// converged solve, sweeps, the device's kernel time (one command buffer per sweep, timed
/// from submit to completion) per cell-direction and sweep, the transfers of the
/// in-scattered radiance, the host's DSA and mixing, and the largest difference of the two
/// fluences over the peak.
fn run_gpu(
    n: usize,
    order: usize,
    directions: usize,
    problem: &Problem,
    options: &SolveOptions,
) -> Result<(), String> {
    let err = |e: &dyn std::fmt::Display| e.to_string();
    let context = lucent::gpu::GpuContext::shared().map_err(|e| err(&e))?;
    println!("adapter: {}", context.describe());
    if context.is_software() {
        println!("a CPU implementation: this is a correctness run, not a measure of GPU speed");
    }
    println!();
    println!(
        "| solver | wall | sweeps | transport steps | of which device kernels | of which scattering products | ns per cell-direction (kernels) | DSA | Anderson | rest (direct, first-collision, set-up) | stop |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    // Up to 256³ × 48 directions the host holds about 30 GB of iterates.
    let options = SolveOptions {
        memory_budget: 96 << 30,
        ..options.clone()
    };
    let cells = (n * n * n) as f64;
    let mut fluences = Vec::new();
    // Both wavefronts of the device (blocks and cells, the default), and the host up to 128³.
    let names: &[&str] = if n <= 128 {
        &["gpu-dom (blocks)", "gpu-dom", "dom"]
    } else {
        &["gpu-dom (blocks)", "gpu-dom"]
    };
    for name in names {
        let mut params = Params::default();
        params
            .0
            .insert("order".into(), ParamValue::Int(order as i64));
        let solver = lucent::dom::DomSolver::from_params(&params).map_err(|e| err(&e))?;
        let solver = if name.starts_with("gpu-dom") {
            let wavefront = if name.contains("blocks") {
                lucent::gpu_solvers::Wavefront::Blocks
            } else {
                lucent::gpu_solvers::Wavefront::Cells
            };
            let factory: std::sync::Arc<lucent::dom::device::DeviceFactory> =
                std::sync::Arc::new(move || {
                    lucent::gpu_solvers::dom_transport_with(wavefront)
                        .map_err(|e| lucent::dom::DomError::Device(e.to_string()))
                });
            solver.on_device("gpu-dom", factory)
        } else {
            solver
        };
        let t = std::time::Instant::now();
        let (solution, records) = solver
            .solve_with_details(problem, &options)
            .map_err(|e| err(&e))?;
        let wall = t.elapsed().as_secs_f64();
        let r = &records[0].convergence;
        let updates = cells * directions as f64 * r.sweeps as f64;
        let rest = wall - r.sweep_seconds - r.scatter_seconds - r.dsa_seconds - r.anderson_seconds;
        let (kernels, products) = if r.device_seconds > 0.0 {
            (
                format!("{:.3} s", r.device_seconds),
                format!("{:.3} s", r.device_scatter_seconds),
            )
        } else {
            ("–".into(), "–".into())
        };
        let per_update = if r.device_seconds > 0.0 {
            r.device_seconds
        } else {
            r.sweep_seconds
        } / updates
            * 1e9;
        println!(
            "| {name} | {wall:.2} s | {} | {:.2} s | {kernels} | {products} | {per_update:.3} | {:.2} s | {:.2} s | {rest:.2} s | {:?} |",
            r.sweeps,
            r.sweep_seconds + r.scatter_seconds,
            r.dsa_seconds,
            r.anderson_seconds,
            solution.report.stop_reason
        );
        fluences.push(solution.fluence(0).data().to_vec());
    }
    // Each device run against the last run (the host's, or the first device run's).
    if let Some((reference, runs)) = fluences.split_last() {
        let peak = reference.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        println!();
        for (name, a) in names.iter().zip(runs) {
            let worst = a
                .iter()
                .zip(reference)
                .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
            println!(
                "largest difference {name} − {}: {:.2e} of the peak",
                names[runs.len()],
                worst / peak
            );
        }
    }
    Ok(())
}
