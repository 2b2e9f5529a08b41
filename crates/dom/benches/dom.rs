//! Criterion benchmarks of lucent-dom at 64³ with S6 (48 directions), HG g = 0.6: one
//! source-iteration sweep (the eight octant wavefronts plus the scattering product), and a
//! converged solve to 1e-4 with DSA.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use lucent_core::Stopping;
use lucent_dom::angular::Ordinates;
use lucent_dom::{Acceleration, DomBoundary, DomProblem, DomSettings, solve};
use lucent_grid::GridGeometry;
use lucent_optics::{Phase, SphericalQuadrature};

fn bench(c: &mut Criterion) {
    let n = 64;
    let geometry = GridGeometry::from_bounds([n; 3], DVec3::ZERO, DVec3::ONE).unwrap();
    let cells = geometry.voxel_count();
    let ordinates = Ordinates::new(
        SphericalQuadrature::level_symmetric(6).unwrap(),
        None,
        Phase::henyey_greenstein(0.6).unwrap(),
    )
    .unwrap();
    let m = ordinates.storage().len();
    let problem = DomProblem {
        geometry,
        sigma_t: vec![32.0; cells],
        sigma_s: vec![30.4; cells],
        fixed: vec![1.0; cells * m],
        boundary: DomBoundary::default(),
    };
    let one = Stopping {
        relative_tolerance: 0.0,
        max_iterations: 1,
        ..Stopping::default()
    };
    let plain = DomSettings {
        acceleration: Acceleration::None,
        anderson: 0,
        ..DomSettings::default()
    };
    c.bench_function("dom one sweep 64^3 S6", |b| {
        b.iter(|| solve(&problem, &ordinates, &plain, &one).unwrap())
    });
    let converged = Stopping {
        relative_tolerance: 1e-4,
        ..Stopping::default()
    };
    c.bench_function("dom solve to 1e-4 64^3 S6 g=0.6", |b| {
        b.iter(|| solve(&problem, &ordinates, &DomSettings::default(), &converged).unwrap())
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench
}
criterion_main!(benches);
