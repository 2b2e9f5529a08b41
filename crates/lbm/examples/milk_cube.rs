//! lucent-lbm on its own: a cube of skim milk (Jensen et al. 2001's σ_s′ = 0.70/mm,
//! σ_a = 0.0007/mm at green) 20 mm across, lit by a sun from above, solved by the D3Q7
//! lattice through the registry entry `lbm`; prints the fluence down the centre line, how
//! the march went, and the lattice's energy books on the same problem.
//!
//! `cargo run --profile examples -p lucent-lbm --example milk_cube`

use glam::DVec3;
use lucent_core::driver::Coefficients;
use lucent_core::{
    Boundary, Field, Light, Medium, Params, Problem, SolveOptions, Solver, Spectrum, Stopping,
};
use lucent_grid::{Grid, GridGeometry};
use lucent_lbm::{
    Absorption, Collision, LatticeProblem, LbmSolver, MarchSettings, Streaming, Velocities, Wall,
    march,
};
use lucent_optics::Phase;

#[allow(clippy::print_stdout)]
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n = 40;
    let geometry = GridGeometry::from_bounds([n; 3], DVec3::splat(-10.0), DVec3::splat(10.0))?;
    // Isotropic scattering with the reduced coefficient (the similarity relation).
    let (sigma_s, sigma_a) = (0.70f32, 0.0007f32);
    let medium = Medium {
        sigma_t: vec![Grid::filled(geometry, sigma_s + sigma_a)],
        albedo: vec![Field::Constant(sigma_s / (sigma_s + sigma_a))],
        phase: Phase::Isotropic,
    };
    let sun = Light::Directional {
        direction: DVec3::NEG_Z,
        irradiance: Spectrum::Grey(1.0),
    };
    // Milk's index 1.35 against air: a Robin boundary.
    let boundary = Boundary::Robin { eta: 1.35 };
    let problem = Problem::new(geometry, medium, vec![sun], boundary, None)?;
    let lbm = LbmSolver::from_params(&Params::default())?;
    let options = SolveOptions {
        relative_tolerance: 1e-6,
        ..SolveOptions::default()
    };
    let solution = lbm.solve(&problem, &options)?;
    println!(
        "D3Q7 TRT on {n}³ cells of 0.5 mm: {} ({} steps, {:.2} s)",
        solution.report.stop_reason, solution.report.iterations, solution.report.wall_time_s
    );
    println!("depth (mm)  fluence (W/mm², sun of 1 W/mm²)");
    for k in (0..n).rev().step_by(4) {
        let z = geometry.cell_centre(n / 2, n / 2, k).z;
        println!(
            "{:9.2}  {:.4}",
            10.0 - z,
            solution.fluence[0].get(n / 2, n / 2, k).unwrap_or(0.0)
        );
    }

    // The lattice alone: a source in the middle of the cube, true absorption, the energy
    // books after the march (lattice units: fluence per step times the cell volume).
    let h = geometry.spacing().x;
    let [s, a, d] = Coefficients::at(
        sigma_s + sigma_a,
        sigma_s / (sigma_s + sigma_a),
        0.0,
        1e-3 / h,
    );
    let _ = s;
    let cells = geometry.voxel_count();
    let mut source = vec![0.0f32; cells];
    source[geometry.index(n / 2, n / 2, n / 2)] = 1.0;
    let lattice = LatticeProblem {
        dims: geometry.dims(),
        first: vec![(f64::from(d) / h) as f32; cells],
        second: vec![(f64::from(a) * h) as f32; cells],
        source,
        first_moment: Vec::new(),
        wall: Wall::Robin {
            a: boundary.robin_factor().unwrap_or(1.0),
        },
    };
    let settings = MarchSettings {
        velocities: Velocities::D3q7,
        collision: Collision::Trt,
        absorption: Absorption::True,
        streaming: Streaming::InPlace,
        stopping: Stopping {
            relative_tolerance: 1e-6,
            max_iterations: 100_000,
            ..Stopping::default()
        },
        blocks: None,
    };
    let marched = march(&lattice, &settings)?;
    let b = marched.bookkeeping;
    println!(
        "a unit source inside, {} steps ({}): emitted {:.1}, absorbed {:.2}, escaped {:.1}, held {:.2}; books close to {:.1e}, steady to {:.1e}",
        marched.steps,
        marched.stop_reason,
        b.emitted,
        b.absorbed,
        b.escaped,
        b.held,
        b.conservation_error(),
        b.steady_imbalance()
    );
    Ok(())
}
