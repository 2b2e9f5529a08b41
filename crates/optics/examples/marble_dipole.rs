//! Using `lucent-optics` alone: the diffuse reflectance of marble under the dipole model,
//! against the exact Robin half-space, and a Henyey–Greenstein lobe sampled exactly.
//!
//! Run: `cargo run -p lucent-optics --example marble_dipole`

#![allow(clippy::print_stdout)]

use glam::DVec3;
use lucent_optics::{
    Dielectric, DiffuseFresnel, DiffusionMedium, MeasuredMaterial, OpticsError, Phase,
    PhaseFunction,
};

fn main() -> Result<(), OpticsError> {
    let marble = MeasuredMaterial::by_name("marble")?;
    let boundary = Dielectric::new(marble.eta)?;
    println!(
        "Marble (Jensen et al. 2001), eta = {}, lengths in mm",
        marble.eta
    );
    println!(
        "{:>6} {:>12} {:>12} {:>12}",
        "r", "R_d red", "R_d green", "R_d blue"
    );
    let media = marble
        .rgb(0.0, 1.0)?
        .into_iter()
        .map(|c| DiffusionMedium::with_boundary(c, boundary, DiffuseFresnel::Groenhuis))
        .collect::<Result<Vec<_>, _>>()?;
    for r in [0.0, 0.5, 1.0, 2.0, 5.0, 10.0] {
        let rd: Vec<f64> = media
            .iter()
            .map(|m| m.dipole().reflectance_profile(r))
            .collect();
        println!(
            "{r:>6.1} {:>12.4e} {:>12.4e} {:>12.4e}",
            rd[0], rd[1], rd[2]
        );
    }
    for (name, m) in ["red", "green", "blue"].iter().zip(&media) {
        println!(
            "{name:>6}: total reflectance, dipole {:.5}, exact Robin half-space {:.5}",
            m.dipole().total_reflectance(),
            m.dipole().total_reflectance_exact()?
        );
    }

    // Scattering in marble is strongly forward in reality; sample g = 0.8.
    let phase = Phase::henyey_greenstein(0.8)?;
    let omega_in = DVec3::Z;
    let n = 100_000;
    let mean_cos: f64 = (0..n)
        .map(|i| {
            // A deterministic stratified pattern is enough to show the sampler's mean.
            let u = [
                (i as f64 + 0.5) / n as f64,
                (i as f64 * 0.618_033_988_749_895).fract(),
            ];
            phase.sample(omega_in, u).omega_out.dot(omega_in)
        })
        .sum::<f64>()
        / n as f64;
    println!("HG(0.8): mean cosine of {n} stratified samples = {mean_cos:.6}");
    Ok(())
}
