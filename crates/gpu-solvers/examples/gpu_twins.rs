//! A GPU backend used alone, beside its CPU twin: Zhang & Ma's illumination of a smoke
//! blob under an oblique sun, `gpu-convection-diffusion` against `convection-diffusion`,
//! the exact uncollided light by `gpu-direct` against `direct`, and discrete ordinates
//! (S4) by `gpu-dom` against `dom`, with the time each took and how far apart they are.
//!
//! `cargo run --profile examples -p lucent-gpu-solvers --example gpu_twins [N]`
//! (N cells per side, default 64; `WGPU_ADAPTER_NAME` picks the adapter).

use std::time::Instant;

use glam::DVec3;
use lucent_core::{
    Boundary, Field, Light, Medium, ParamValue, Params, Problem, SolveOptions, Spectrum,
};
use lucent_gpu_solvers::GpuSolver;
use lucent_grid::{Grid, GridGeometry};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n: usize = std::env::args().nth(1).map_or(Ok(64), |a| a.parse())?;
    let geometry = GridGeometry::new([n; 3], DVec3::splat(1.0 / n as f64), DVec3::ZERO)?;
    let sigma_t = Grid::from_fn(geometry, |x| {
        (20.0 * (-12.0 * (x - DVec3::splat(0.5)).length_squared()).exp()) as f32
    });
    let medium = Medium {
        sigma_t: vec![sigma_t],
        albedo: vec![Field::Constant(0.9)],
        phase: lucent_optics::Phase::Isotropic,
    };
    let sun = Light::Directional {
        direction: DVec3::new(0.4, -0.3, 0.87).normalize(),
        irradiance: Spectrum::Grey(1.0),
    };
    let problem = Problem::new(geometry, medium, vec![sun], Boundary::Vacuum, None)?;
    let mut scattering = Params::default();
    scattering
        .0
        .insert("scattering".into(), ParamValue::Float(2e-4));
    let pairs = [
        (
            GpuSolver::GPU_DIRECT,
            lucent_core::DirectSolver::ENTRY,
            Params::default(),
        ),
        (
            GpuSolver::GPU_CONVECTION_DIFFUSION,
            lucent_explicit::ExplicitSolver::CONVECTION_DIFFUSION,
            scattering,
        ),
        (
            GpuSolver::GPU_DOM,
            lucent_dom::DomSolver::ENTRY,
            Params(
                [("order".to_string(), ParamValue::Int(4))]
                    .into_iter()
                    .collect(),
            ),
        ),
    ];
    for (gpu, cpu, params) in pairs {
        let mut fluence = Vec::new();
        for entry in [gpu, cpu] {
            let solver = (entry.build)(&params)?;
            let start = Instant::now();
            let solution = solver.solve(&problem, &SolveOptions::default())?;
            eprintln!(
                "{:>26}: {:.3} s, {}",
                entry.name,
                start.elapsed().as_secs_f64(),
                solution.report.stop_reason
            );
            fluence.push(solution.fluence(0).clone());
        }
        let peak = fluence[1].stats().max;
        let worst = fluence[0]
            .data()
            .iter()
            .zip(fluence[1].data())
            .map(|(a, b)| f64::from((a - b).abs()))
            .fold(0.0, f64::max);
        eprintln!(
            "{:>26}  largest difference {:.1e} of the peak",
            "",
            worst / f64::from(peak)
        );
    }
    Ok(())
}
