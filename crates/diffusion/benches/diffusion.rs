//! Criterion benchmarks of lucent-diffusion: the marble sphere (R = 10 mm, embedded
//! boundary, Robin) solved to 1e-8 by multigrid at 64³, 128³ and 256³ (set-up included),
//! and one smoothing sweep at 128³. `cargo xtask bench-diffusion` adds the copy bandwidth,
//! pyamg and scipy.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use lucent_core::Stopping;
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, DiffusionProblem, Discretisation, Method, Multigrid,
    MultigridSettings, Sources, solve,
};
use lucent_grid::GridGeometry;

fn sphere(n: usize) -> DiffusionProblem {
    let grid = GridGeometry::from_bounds([n; 3], DVec3::splat(-10.5), DVec3::splat(10.5)).unwrap();
    let cells = CellGeometry::from_sdf(
        grid,
        |p| p.length() - 10.0,
        Discretisation::EmbeddedBoundary,
    )
    .unwrap();
    let count = grid.voxel_count();
    DiffusionProblem::new(
        cells,
        vec![0.152; count],
        vec![0.0021; count],
        Boundaries::uniform(Condition::Robin { a: 2.341 }),
    )
    .unwrap()
}

fn bench(c: &mut Criterion) {
    let sources = Sources {
        points: vec![(DVec3::new(0.1, 0.05, -0.02), 1.0)],
        ..Sources::default()
    };
    for n in [64, 128, 256] {
        let problem = sphere(n);
        c.bench_function(&format!("diffusion-mg sphere {n}^3 to 1e-8"), |b| {
            b.iter(|| solve(&problem, &sources, Method::default(), &Stopping::default()).unwrap())
        });
    }
    let mg = Multigrid::build(&sphere(128), MultigridSettings::default()).unwrap();
    let cells = mg.fine_cells();
    let rhs: Vec<f32> = (0..cells).map(|i| (i % 7) as f32 * 1e-3).collect();
    let mut x = vec![0.0f32; cells];
    c.bench_function("diffusion-mg red-black sweep 128^3", |b| {
        b.iter(|| mg.smoothing_sweep(&rhs, &mut x).unwrap())
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench
}
criterion_main!(benches);
