//! lucent-dom on its own: a ball of glowing, forward-scattering haze (HG g = 0.6, albedo
//! 0.95) in a vacuum box, solved by discrete ordinates with DSA; prints the fluence along
//! the x axis, the energy balance and how the iteration went.
//!
//! `cargo run --release -p lucent-dom --example glowing_ball`

use glam::DVec3;
use lucent_core::Stopping;
use lucent_dom::angular::Ordinates;
use lucent_dom::{DomBoundary, DomProblem, DomSettings, solve};
use lucent_grid::GridGeometry;
use lucent_optics::{Phase, SphericalQuadrature};

#[allow(clippy::print_stdout)]
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n = 32;
    let geometry = GridGeometry::from_bounds([n; 3], DVec3::splat(-1.0), DVec3::splat(1.0))?;
    let cells = geometry.voxel_count();
    let ordinates = Ordinates::new(
        SphericalQuadrature::level_symmetric(8)?,
        None,
        Phase::henyey_greenstein(0.6)?,
    )?;
    let m = ordinates.storage().len();
    // σ_t = 8 per unit inside the unit ball, glowing isotropically (1 per steradian).
    let (mut sigma_t, mut sigma_s, mut fixed) =
        (vec![0.0; cells], vec![0.0; cells], vec![0.0; cells * m]);
    for c in 0..cells {
        let [i, j, k] = geometry.coords(c);
        if geometry.cell_centre(i, j, k).length() < 1.0 {
            sigma_t[c] = 8.0;
            sigma_s[c] = 8.0 * 0.95;
            fixed[c * m..(c + 1) * m].fill(1.0);
        }
    }
    let problem = DomProblem {
        geometry,
        sigma_t,
        sigma_s,
        fixed,
        boundary: DomBoundary::default(),
    };
    let stopping = Stopping {
        relative_tolerance: 1e-6,
        ..Stopping::default()
    };
    let solution = solve(&problem, &ordinates, &DomSettings::default(), &stopping)?;
    println!(
        "S8 ({} directions), {n}³ cells",
        ordinates.propagation().len()
    );
    println!(
        "{} sweeps, {:?}, measured contraction {:.3}",
        solution.convergence.sweeps,
        solution.convergence.stop_reason,
        solution.convergence.spectral_radius
    );
    let b = solution.balance;
    println!(
        "emitted {:.6}, absorbed {:.6}, leaked {:.6}: relative imbalance {:.1e}",
        b.emitted,
        b.absorbed,
        b.outflow,
        b.relative_imbalance()
    );
    println!("fluence along x (y = z = 0):");
    let (j, k) = (n / 2, n / 2);
    for i in (0..n).step_by(2) {
        let x = geometry.cell_centre(i, j, k).x;
        let phi = solution.fluence[i + n * (j + n * k)];
        println!("  x = {x:+.3}  φ = {phi:.5}");
    }
    Ok(())
}
