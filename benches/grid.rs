//! Criterion benchmarks of the grid operations solvers and renderers call in their inner
//! loops: trilinear sampling, dense and bricked lookups, and the 2× restriction of multigrid.
//!
//! Run: `cargo bench --bench grid`. Results go in BENCHMARKS.md.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use lucent::grid::procedural::NoiseCloud;
use lucent::grid::resample::restrict;
use lucent::grid::{BrickedGrid, GridGeometry};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

const BATCH: usize = 65_536;

fn grid_lookups(c: &mut Criterion) {
    let geometry = GridGeometry::new([128; 3], DVec3::splat(1.0 / 128.0), DVec3::ZERO).unwrap();
    let cloud = NoiseCloud::new(7, DVec3::splat(0.5), 0.45)
        .rasterize(geometry)
        .unwrap();
    let bricks = BrickedGrid::from_dense(&cloud, 8).unwrap();
    let mut rng = Pcg64Mcg::seed_from_u64(11);
    let points: Vec<DVec3> = (0..BATCH)
        .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()))
        .collect();
    let cells: Vec<[usize; 3]> = (0..BATCH)
        .map(|_| {
            [
                rng.random_range(0..128),
                rng.random_range(0..128),
                rng.random_range(0..128),
            ]
        })
        .collect();

    // Random points: every sample is a cache miss in the 8 MiB grid.
    c.bench_function(&format!("grid/trilinear_random/128^3/x{BATCH}"), |b| {
        b.iter(|| {
            points
                .iter()
                .map(|&p| cloud.sample_trilinear(black_box(p)))
                .sum::<f32>()
        })
    });
    // Ray marching: 256 rays of 256 steps of half a cell, the access pattern of a renderer.
    let rays: Vec<DVec3> = (0..BATCH)
        .map(|n| {
            let (ray, step) = (n / 256, n % 256);
            let start = DVec3::new((ray % 16) as f64 / 16.0, (ray / 16) as f64 / 16.0, 0.0);
            start + DVec3::new(0.3, 0.2, 1.0).normalize() * (step as f64 * 0.5 / 128.0)
        })
        .collect();
    c.bench_function(&format!("grid/trilinear_march/128^3/x{BATCH}"), |b| {
        b.iter(|| {
            rays.iter()
                .map(|&p| cloud.sample_trilinear(black_box(p)))
                .sum::<f32>()
        })
    });
    c.bench_function(&format!("grid/dense_get/128^3/x{BATCH}"), |b| {
        b.iter(|| {
            cells
                .iter()
                .map(|&[i, j, k]| cloud.get(black_box(i), j, k).unwrap_or(0.0))
                .sum::<f32>()
        })
    });
    c.bench_function(&format!("grid/bricked_get/128^3/x{BATCH}"), |b| {
        b.iter(|| {
            cells
                .iter()
                .map(|&[i, j, k]| bricks.get(black_box(i), j, k).unwrap_or(0.0))
                .sum::<f32>()
        })
    });
    c.bench_function("grid/restrict/128^3", |b| {
        b.iter(|| restrict(black_box(&cloud)))
    });
    c.bench_function("grid/brick/128^3", |b| {
        b.iter(|| BrickedGrid::from_dense(black_box(&cloud), 8).unwrap())
    });
}

criterion_group!(benches, grid_lookups);
criterion_main!(benches);
