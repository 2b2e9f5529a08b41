//! Using `lucent-render` with `lucent-core` alone: a Gaussian blob of haze lit by a warm
//! sun and a blue sky, solved with `direct` and written to `lit_blob.png`.
//!
//! Run: `cargo run --release -p lucent-render --example lit_blob [OUT.png]`

#![allow(clippy::print_stdout)]

use glam::DVec3;
use lucent_core::{
    Boundary, DirectSolver, Field, Light, Medium, Problem, SolveOptions, Solver, Spectrum,
};
use lucent_grid::GridGeometry;
use lucent_grid::procedural::gaussian_blob;
use lucent_optics::Phase;
use lucent_render::{Camera, RenderSettings, ToneMap, render};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "lit_blob.png".into());
    let geometry = GridGeometry::new([48; 3], DVec3::splat(2.0 / 48.0), DVec3::splat(-1.0))?;
    let density = gaussian_blob(geometry, DVec3::ZERO, 0.35)?;
    let medium = Medium {
        sigma_t: vec![density.map(|d| 12.0 * d)],
        albedo: vec![Field::Constant(0.95)],
        phase: Phase::henyey_greenstein(0.4)?,
    };
    let lights = vec![
        Light::Directional {
            direction: DVec3::new(-0.4, -0.3, -0.87).normalize(),
            irradiance: Spectrum::Rgb([9.0, 8.0, 6.5]),
        },
        Light::Sky {
            radiance: Spectrum::Rgb([0.08, 0.12, 0.25]),
        },
    ];
    let problem = Problem::new(geometry, medium, lights, Boundary::Vacuum, None)?;
    let solution = DirectSolver::default().solve(&problem, &SolveOptions::default())?;
    let camera = Camera::Pinhole {
        position: [0.0, -3.5, 0.6],
        look_at: [0.0, 0.0, 0.0],
        up: [0.0, 0.0, 1.0],
        fov: 35.0,
    };
    let image = render(
        &problem,
        &solution,
        &camera,
        &RenderSettings {
            width: 320,
            height: 240,
            ..Default::default()
        },
        None,
    )?;
    image.write(&out, 0.0, ToneMap::Aces)?;
    println!("wrote {out} (solve {:.2} s)", solution.report.wall_time_s);
    Ok(())
}
