//! Using `lucent-core` alone: build a problem by hand (a slab with a dense block casting a
//! shadow), solve it with `direct`, and print the fluence along a line through the shadow.
//!
//! Run: `cargo run --release -p lucent-core --example shadowed_slab`

#![allow(clippy::print_stdout)]

use glam::DVec3;
use lucent_core::{
    Boundary, DirectSolver, Field, Light, Medium, Problem, SolveOptions, Solver, Spectrum,
};
use lucent_grid::procedural::Shape;
use lucent_grid::{Grid, GridGeometry};
use lucent_optics::Phase;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let geometry = GridGeometry::new([48, 48, 48], DVec3::splat(1.0 / 48.0), DVec3::ZERO)?;
    // A thin haze (σ_t = 0.5) with a dense cube (σ_t = 20) in the upper half.
    let block = Shape::Box {
        min: DVec3::new(0.35, 0.35, 0.6),
        max: DVec3::new(0.65, 0.65, 0.8),
    }
    .density_grid(geometry, 0.0)?;
    let sigma_t = block.map(|d| 0.5 + 19.5 * d);
    let medium = Medium {
        sigma_t: vec![sigma_t],
        albedo: vec![Field::Constant(0.9)],
        phase: Phase::henyey_greenstein(0.5)?,
    };
    let sun = Light::Directional {
        direction: -DVec3::Z,
        irradiance: Spectrum::Rgb([1.0, 0.95, 0.85]),
    };
    let sky = Light::Sky {
        radiance: Spectrum::Rgb([0.05, 0.08, 0.15]),
    };
    let problem = Problem::new(geometry, medium, vec![sun, sky], Boundary::Vacuum, None)?;
    let solution = DirectSolver::default().solve(&problem, &SolveOptions::default())?;
    println!(
        "direct: {:?} in {:.3} s",
        solution.report.stop_reason, solution.report.wall_time_s
    );
    println!(
        "fluence (red) along x at y = 0.5, z = 0.3 (inside the block's shadow for 0.35 < x < 0.65):"
    );
    let phi: &Grid = solution.fluence(0);
    for i in (0..48).step_by(4) {
        let x = (i as f64 + 0.5) / 48.0;
        println!(
            "  x = {x:.3}: φ = {:.4}",
            phi.sample_trilinear(DVec3::new(x, 0.5, 0.3))
        );
    }
    Ok(())
}
