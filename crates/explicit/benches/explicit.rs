//! Criterion benchmarks of lucent-explicit at 128³: one FTCS diffusion step and Zhang &
//! Ma's full update for one light (upwind absorption to steady state by layer sweeps,
//! then the implicit scattering step).

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use lucent_core::Stopping;
use lucent_explicit::Lattice;
use lucent_explicit::convection::{Light, UpwindSettings, propagate};
use lucent_explicit::ftcs::{Edges, FtcsDiffusion, GradientSign, March};
use lucent_explicit::scatter::{StepSolver, diffuse};

fn bench(c: &mut Criterion) {
    let n = 128;
    let lattice = Lattice::new([n; 3], 1.0).unwrap();
    let cells = lattice.len();
    let d = vec![0.2; cells];
    let sa = vec![0.01; cells];
    let q = vec![0.0; cells];
    let problem = FtcsDiffusion {
        lattice,
        diffusion: &d,
        absorption: &sa,
        source: &q,
        sign: GradientSign::Conservative,
        edges: Edges::Periodic,
    };
    let initial: Vec<f64> = (0..cells).map(|i| (i % 13) as f64).collect();
    let march = March {
        time_step: 0.5 * problem.time_step_limit(),
        stopping: Stopping {
            relative_tolerance: 0.0,
            max_iterations: 1,
            ..Stopping::default()
        },
        allow_unstable: false,
        initial: Some(initial),
    };
    c.bench_function("ftcs-diffusion one step 128^3", |b| {
        b.iter(|| problem.march(&march).unwrap())
    });
    let absorption: Vec<f64> = (0..cells)
        .map(|i| if (i / 97) % 5 == 0 { 0.05 } else { 0.0 })
        .collect();
    let light = Light::Distant {
        direction: DVec3::new(0.3, 0.4, 1.0).normalize(),
        density: 1.0,
    };
    let settings = UpwindSettings {
        stopping: Stopping {
            max_iterations: 1,
            ..UpwindSettings::default().stopping
        },
        ..UpwindSettings::default()
    };
    c.bench_function(
        "zhang-ma absorption one light 128^3 (one layer pass)",
        |b| b.iter(|| propagate(&lattice, &absorption, &light, &settings).unwrap()),
    );
    let field = propagate(&lattice, &absorption, &light, &settings)
        .unwrap()
        .density;
    c.bench_function(
        "zhang-ma scattering step 128^3 (a = 1, multigrid, hierarchy built each time)",
        |b| {
            b.iter(|| {
                diffuse(
                    &lattice,
                    &field,
                    1.0,
                    1.0,
                    1,
                    StepSolver::Multigrid { tolerance: 1e-6 },
                )
                .unwrap()
            })
        },
    );
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench
}
criterion_main!(benches);
