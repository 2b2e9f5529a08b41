//! Choosing a spherical quadrature for a phase function: how well each set integrates a
//! Henyey–Greenstein lobe, ∫ p(ω_in·ω) dω = 1, as the lobe sharpens. The cheapest set that
//! is accurate enough is the one to use.
//!
//! Run: `cargo run --release --example quadrature_choice`

#![allow(clippy::print_stdout)]

use glam::DVec3;
use lucent::optics::{OpticsError, Phase, PhaseFunction, SphericalQuadrature};

fn main() -> Result<(), OpticsError> {
    let sets = [
        ("S4", SphericalQuadrature::level_symmetric(4)?),
        ("S8", SphericalQuadrature::level_symmetric(8)?),
        ("S16", SphericalQuadrature::level_symmetric(16)?),
        ("octahedral L2", SphericalQuadrature::octahedral(2)?),
        ("octahedral L4", SphericalQuadrature::octahedral(4)?),
        ("Fibonacci 1000", SphericalQuadrature::fibonacci(1000)?),
    ];
    // A direction that lines up with none of the sets' symmetry axes.
    let omega_in = DVec3::new(0.3, 0.5, 0.81).normalize();
    println!("relative error of the quadrature sum of an HG lobe (exact: 1)");
    print!("{:<16} {:>6} {:>7}", "set", "dirs", "degree");
    let gs = [0.0, 0.3, 0.6, 0.8, 0.9];
    for g in gs {
        print!(" {:>10}", format!("g = {g}"));
    }
    println!();
    for (name, q) in &sets {
        print!("{name:<16} {:>6} {:>7}", q.len(), q.design_degree());
        for g in gs {
            let phase = Phase::henyey_greenstein(g)?;
            let sum = q.integrate(|omega| phase.eval(omega_in, omega));
            print!(" {:>10.2e}", sum - 1.0);
        }
        println!();
    }
    Ok(())
}
