//! lucent-hybrid on its own: a thin, forward-scattering layer over a thick diffusive one
//! under an oblique sun, solved by the hybrid with one and with three swept scattering
//! orders; prints how much of the scattered power diffusion carried, each part's energy
//! balance, and the fluence down the middle column.
//!
//! `cargo run --release -p lucent-hybrid --example sunlit_layers`

use glam::DVec3;
use lucent_core::{Boundary, Field, Light, Medium, Problem, SolveOptions, Spectrum};
use lucent_grid::{Grid, GridGeometry};
use lucent_hybrid::HybridSolver;
use lucent_optics::Phase;

#[allow(clippy::print_stdout)]
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n = 24;
    let geometry = GridGeometry::from_bounds([n; 3], DVec3::splat(-1.0), DVec3::splat(1.0))?;
    // σ_t = 1 per unit above z = 0 (albedo 0.95), 24 below (albedo 0.99); HG g = 0.8.
    let mut sigma_t = Grid::filled(geometry, 1.0);
    let mut albedo = Grid::filled(geometry, 0.95);
    for c in 0..geometry.voxel_count() {
        let [i, j, k] = geometry.coords(c);
        if geometry.cell_centre(i, j, k).z < 0.0 {
            sigma_t.data_mut()[c] = 24.0;
            albedo.data_mut()[c] = 0.99;
        }
    }
    let medium = Medium {
        sigma_t: vec![sigma_t],
        albedo: vec![Field::Grid(albedo)],
        phase: Phase::henyey_greenstein(0.8)?,
    };
    let sun = Light::Directional {
        direction: DVec3::new(0.3, 0.2, -0.93).normalize(),
        irradiance: Spectrum::Grey(1.0),
    };
    let problem = Problem::new(geometry, medium, vec![sun], Boundary::Vacuum, None)?;
    for orders in [1, 3] {
        let hybrid = HybridSolver::default().with_orders(orders)?;
        let (solution, channels) = hybrid.solve_with_details(&problem, &SolveOptions::default())?;
        let c = &channels[0];
        // The whole problem's imbalance is the uncollided light's cell rule where the sun
        // enters cells of σ_t h = 2 across a sharp jump (`dom` shows the same); each part's
        // own closes to 1e-6.
        println!(
            "{orders} swept order(s): {:.1}% of the scattered power left to diffusion ({} V-cycles), \
             whole-problem imbalance {:.1e}, {:.3} s",
            100.0 * c.diffused_share,
            c.cycles,
            c.balance.relative_imbalance(),
            solution.report.wall_time_s
        );
        for (k, sweep) in c.sweeps.iter().enumerate() {
            println!(
                "  order {}: source {:.4} W, collided {:.4} W, left the box {:.4} W",
                k + 1,
                sweep.emitted + sweep.inflow,
                sweep.absorbed,
                sweep.outflow
            );
        }
        let phi = solution.fluence(0);
        let column: Vec<String> = (0..n)
            .rev()
            .step_by(3)
            .map(|k| format!("{:.3}", phi.data()[geometry.index(n / 2, n / 2, k)]))
            .collect();
        println!("  fluence down the middle column: {}", column.join(" "));
    }
    Ok(())
}
