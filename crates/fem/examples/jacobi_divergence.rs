//! lucent-fem on its own: Murray's finite-element system for the RTE, the spectral radius
//! of Jacobi on it over K_tΔ (never below 19/8), and what Jacobi, GMRES and a direct solve
//! do with it on a small grid. `cargo run --release -p lucent-fem --example jacobi_divergence`

use lucent_fem::murray::{Mesh, MurraySystem};
use lucent_fem::solvers::{default_stopping, gmres, jacobi, lu_solve};

#[allow(clippy::print_stdout)]
fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!("Jacobi spectral radius on Murray's system (periodic 12³ mesh):");
    for kt in [0.01, 0.1, 1.0, 10.0, 100.0] {
        let mesh = Mesh {
            nodes: [12; 3],
            spacing: 1.0,
            periodic: true,
        };
        let rho = MurraySystem::assemble(mesh, kt)?.jacobi_spectral_radius(400);
        println!("  K_tΔ = {kt:>6}: ρ = {rho:.3}");
    }
    let mesh = Mesh {
        nodes: [7; 3],
        spacing: 1.0,
        periodic: false,
    };
    let system = MurraySystem::assemble(mesh, 1.0)?;
    let b = system.point_source([3, 3, 3], 1.0);
    let mut x = vec![0.0; b.len()];
    let j = jacobi(&system.matrix, &b, &mut x, &default_stopping())?;
    println!(
        "Jacobi on a 7³ mesh, K_tΔ = 1: {:?} after {} sweeps",
        j.stop_reason,
        j.residuals.len() - 1
    );
    let mut x = vec![0.0; b.len()];
    let g = gmres(&system.matrix, &b, &mut x, 60, &default_stopping())?;
    println!(
        "GMRES(60): {:?} after {} products",
        g.stop_reason,
        g.residuals.len() - 1
    );
    let exact = lu_solve(&system.matrix, &b)?;
    let phi = system.fluence(&exact);
    let row: Vec<String> = (3..7)
        .map(|i| format!("{:.2}", phi[i + 7 * (3 + 7 * 3)]))
        .collect();
    println!(
        "fluence along +x from the source (direct solve): {}",
        row.join(", ")
    );
    Ok(())
}
