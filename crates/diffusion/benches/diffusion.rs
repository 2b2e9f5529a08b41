//! Criterion benchmarks of lucent-diffusion: the marble sphere (R = 10 mm, embedded
//! boundary, Robin) solved to 1e-8 by multigrid at 64³, 128³ and 256³ (set-up included),
//! and one smoothing sweep at 128³; and ten V(2,2) cycles on two in-process ranks over
//! z-slabs and over boxes cut along y and along x (`Multigrid::solve_on_layout`, a
//! 96 × 80 × 128 box medium; `cargo bench -p lucent-diffusion --bench diffusion -- ranks`),
//! the comparison BENCHMARKS.md's "Multigrid over boxes" quotes. `cargo xtask
//! bench-diffusion` adds the copy bandwidth, pyamg and scipy.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use lucent_core::Stopping;
use lucent_core::ranks::Threads;
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, Decomposition, DiffusionProblem, Discretisation, Method,
    Multigrid, MultigridSettings, Sources, solve,
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
    ranks(c);
}

/// Ten V(2,2) cycles of a medium filling a 96 × 80 × 128 box on two in-process ranks (a
/// thread each), cut as z-slabs, as boxes 1 × 2 × 1 (y) and 2 × 1 × 1 (x): the cost of
/// the cut's halos and of a box's shorter rows.
fn ranks(c: &mut Criterion) {
    let grid = GridGeometry::from_bounds(
        [96, 80, 128],
        DVec3::new(-4.8, -4.0, -6.4),
        DVec3::new(4.8, 4.0, 6.4),
    )
    .unwrap();
    let count = grid.voxel_count();
    let d: Vec<f32> = (0..count)
        .map(|i| 0.1 + 0.05 * ((i % 13) as f32 / 13.0))
        .collect();
    let problem = DiffusionProblem::new(
        CellGeometry::full_box(grid),
        d,
        vec![0.01; count],
        Boundaries::uniform(Condition::Robin { a: 2.341 }),
    )
    .unwrap();
    let sources = Sources {
        points: vec![(DVec3::new(0.3, -0.2, 0.4), 1.0)],
        ..Sources::default()
    };
    let rhs = problem.rhs(&sources).unwrap();
    let settings = MultigridSettings {
        full_multigrid: false,
        ..MultigridSettings::default()
    };
    let mg = Multigrid::build(&problem, settings).unwrap();
    let stopping = Stopping {
        relative_tolerance: 0.0,
        max_iterations: 10,
        ..Stopping::default()
    };
    let mut group = c.benchmark_group("ranks");
    for (name, decomposition) in [
        ("slabs", Decomposition::Slabs),
        ("boxes 1x2x1", Decomposition::Grid([1, 2, 1])),
        ("boxes 2x1x1", Decomposition::Grid([2, 1, 1])),
    ] {
        let layout = mg.layout(2, 0, decomposition).unwrap();
        group.bench_function(
            format!("diffusion-mg 10 V-cycles 96x80x128 on 2 ranks, {name}"),
            |b| {
                b.iter(|| {
                    Threads::run(2, |comm| {
                        let mut phi = vec![0.0; rhs.len()];
                        mg.solve_on_layout(&rhs, &mut phi, &stopping, comm, layout.clone())
                            .unwrap()
                    })
                })
            },
        );
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench
}
criterion_main!(benches);
