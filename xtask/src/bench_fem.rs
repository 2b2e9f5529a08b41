//! `cargo xtask bench-fem [N...]`: Q1 finite elements against the matrix-free finite
//! volumes on the same box (marble-like, 12 mm, Robin η = 1.3, a point source) at N³ (64
//! and 128 by default): assembly and hierarchy time, bytes per unknown, solve time to 1e-8.

use std::time::Instant;

use glam::DVec3;
use lucent::core::Stopping;
use lucent::diffusion::{
    Boundaries, CellGeometry, Condition, DiffusionProblem, Method, Sources, solve,
};
use lucent::fem::q1::{Q1Multigrid, Q1Problem};
use lucent_grid::GridGeometry;

/// Runs the comparison.
pub(crate) fn run(sizes: &[usize]) -> Result<(), String> {
    let err = |e: &dyn std::fmt::Display| e.to_string();
    let (d, sigma_a, a) = (1.0 / (3.0 * 2.2 * 0.001 + 3.0 * 2.2 * 0.999), 0.0022, 2.341);
    println!(
        "# cargo xtask bench-fem ({} threads)",
        rayon::current_num_threads()
    );
    println!();
    println!(
        "| n³ | fem: assembly s | fem: hierarchy s | fem: bytes/unknown | fem: MG-CG solve s (iterations) | fv: set-up s | fv: bytes/unknown | fv: solve s (cycles) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for &n in sizes {
        let h = 12.0 / n as f64;
        let count = n * n * n;
        let problem = Q1Problem {
            cells: [n; 3],
            spacing: h,
            diffusion: vec![d; count],
            absorption: vec![sigma_a; count],
            robin: [Some(a); 6],
        };
        let t = Instant::now();
        let matrix = problem.assemble().map_err(|e| err(&e))?;
        let assembly = t.elapsed().as_secs_f64();
        let unknowns = matrix.rows();
        let bytes = (matrix.nnz() * (8 + 4) + (unknowns + 1) * 8) as f64 / unknowns as f64;
        let b = problem
            .point_source([6.1, 5.8, 6.3], 1.0)
            .map_err(|e| err(&e))?;
        let t = Instant::now();
        let mg = Q1Multigrid::new(&problem, matrix, 2);
        let hierarchy = t.elapsed().as_secs_f64();
        let mut x = vec![0.0; b.len()];
        let t = Instant::now();
        let c = mg
            .solve(
                &b,
                &mut x,
                &Stopping {
                    relative_tolerance: 1e-8,
                    max_iterations: 200,
                    ..lucent::fem::solvers::default_stopping()
                },
            )
            .map_err(|e| err(&e))?;
        let fem_solve = t.elapsed().as_secs_f64();
        // The finite-volume multigrid on the same box.
        let grid = GridGeometry::from_bounds([n; 3], DVec3::ZERO, DVec3::splat(12.0))
            .map_err(|e| err(&e))?;
        let fv = DiffusionProblem::new(
            CellGeometry::full_box(grid),
            vec![d as f32; count],
            vec![sigma_a as f32; count],
            Boundaries::uniform(Condition::Robin { a }),
        )
        .map_err(|e| err(&e))?;
        let sources = Sources {
            points: vec![(DVec3::new(6.1, 5.8, 6.3), 1.0)],
            ..Sources::default()
        };
        let s =
            solve(&fv, &sources, Method::default(), &Stopping::default()).map_err(|e| err(&e))?;
        println!(
            "| {n}³ | {assembly:.2} | {hierarchy:.2} | {bytes:.0} | {fem_solve:.2} ({}) | {:.2} | {:.0} | {:.2} ({}) |",
            c.residuals.len() - 1,
            s.setup_seconds,
            s.memory_bytes as f64 / count as f64,
            s.solve_seconds,
            s.convergence.iterations()
        );
    }
    Ok(())
}
