//! lucent-diffusion on its own: a marble sphere (R = 10 mm, η = 1.3) with a unit point
//! source, solved by multigrid at a chosen resolution, against the closed form (Mertens
//! T7, docs/reference-cases.md). `cargo run --release -p lucent-diffusion --example marble_sphere -- 128`

use glam::DVec3;
use lucent_core::Boundary;
use lucent_core::Stopping;
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, DiffusionProblem, Discretisation, Method, Sources, solve,
};
use lucent_grid::GridGeometry;
use lucent_optics::{DiffusionMedium, OpticalCoefficients};

#[allow(clippy::print_stdout)]
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n: usize = std::env::args().nth(1).map_or(Ok(64), |a| a.parse())?;
    let (sigma_a, sigma_s) = (0.0021, 2.19);
    let a = Boundary::Robin { eta: 1.3 }
        .robin_factor()
        .ok_or("bad eta")?;
    let grid = GridGeometry::from_bounds([n; 3], DVec3::splat(-10.5), DVec3::splat(10.5))?;
    let centre = DVec3::new(0.173, -0.091, 0.057);
    let started = std::time::Instant::now();
    let cells = CellGeometry::from_sdf(
        grid,
        |p| (p - centre).length() - 10.0,
        Discretisation::EmbeddedBoundary,
    )?;
    let geometry_seconds = started.elapsed().as_secs_f64();
    let d = 1.0 / (3.0 * (sigma_a + sigma_s));
    let count = grid.voxel_count();
    let problem = DiffusionProblem::new(
        cells,
        vec![d as f32; count],
        vec![sigma_a as f32; count],
        Boundaries::uniform(Condition::Robin { a }),
    )?;
    let sources = Sources {
        points: vec![(centre, 1.0)],
        ..Sources::default()
    };
    let solution = solve(&problem, &sources, Method::default(), &Stopping::default())?;
    let coefficients = OpticalCoefficients::from_extinction_albedo(
        sigma_a + sigma_s,
        sigma_s / (sigma_a + sigma_s),
        0.0,
    )?;
    let exact = DiffusionMedium::new(coefficients, a)?.sphere(10.0)?;
    let b = solution.balance;
    println!(
        "{n}^3: geometry {geometry_seconds:.3} s, operator {:.3} s, solve {:.3} s ({} levels, {} cycles to {:.1e}, mean factor {:.3})",
        solution.setup_seconds,
        solution.solve_seconds,
        solution.levels,
        solution.convergence.iterations(),
        solution
            .convergence
            .residuals
            .last()
            .copied()
            .unwrap_or(0.0),
        solution.convergence.mean_factor()
    );
    println!(
        "escaped {:.6} (closed form {:.6}), absorbed {:.6} ({:.6}), imbalance {:.1e}",
        b.escaped_surface + b.escaped_box,
        exact.escaped_fraction(),
        b.absorbed,
        exact.absorbed_fraction(),
        b.relative_imbalance()
    );
    Ok(())
}
