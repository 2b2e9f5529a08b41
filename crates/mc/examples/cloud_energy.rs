//! Using `lucent-mc` alone: trace a lit noise cloud, print where the light went (emitted,
//! absorbed, escaped, with standard errors), the fluence profile with its error bars, and
//! the throughput.
//!
//! Run: `cargo run --release -p lucent-mc --example cloud_energy`

#![allow(clippy::print_stdout)]

use std::time::Instant;

use glam::DVec3;
use lucent_core::{Boundary, Field, Light, Medium, Problem, Spectrum};
use lucent_grid::GridGeometry;
use lucent_grid::procedural::NoiseCloud;
use lucent_mc::{McConfig, estimate};
use lucent_optics::Phase;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let geometry = GridGeometry::new([32; 3], DVec3::splat(1.0 / 32.0), DVec3::ZERO)?;
    let cloud = NoiseCloud::new(7, DVec3::splat(0.5), 0.48).rasterize(geometry)?;
    let medium = Medium {
        sigma_t: vec![cloud.map(|d| 25.0 * d)],
        albedo: vec![Field::Constant(0.95)],
        phase: Phase::henyey_greenstein(0.6)?,
    };
    let sun = Light::Directional {
        direction: DVec3::new(0.3, 0.2, -0.93).normalize(),
        irradiance: Spectrum::Grey(1.0),
    };
    let problem = Problem::new(geometry, medium, vec![sun], Boundary::Vacuum, None)?;
    let config = McConfig {
        particles: 50_000,
        batches: 16,
        ..Default::default()
    };
    let start = Instant::now();
    let run = estimate(&problem, &config)?;
    let seconds = start.elapsed().as_secs_f64();
    let e = &run.energy[0];
    println!(
        "{} paths in {seconds:.2} s ({:.0} paths/s)",
        run.paths,
        run.paths as f64 / seconds
    );
    for (name, q) in [
        ("emitted", e.emitted),
        ("absorbed", e.absorbed),
        ("escaped", e.escaped),
        ("imbalance", e.imbalance),
    ] {
        println!("  {name:<9} {:>10.6} ± {:.6}", q.mean, q.std_error);
    }
    println!("fluence down the centre column (z from top), with standard errors:");
    for k in (0..32).rev().step_by(4) {
        let (phi, se) = (
            run.fluence[0].get(16, 16, k).unwrap_or(0.0),
            run.standard_error[0].get(16, 16, k).unwrap_or(0.0),
        );
        println!("  z = {:.3}: {phi:.4} ± {se:.4}", (k as f64 + 0.5) / 32.0);
    }
    Ok(())
}
