//! Criterion benchmarks of the optics that sit inside solver loops: phase-function
//! evaluation and sampling (Monte Carlo calls them per path vertex), Fresnel reflectance,
//! and quadrature construction (done once per solve).
//!
//! Run: `cargo bench --bench optics`. Results go in BENCHMARKS.md.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use lucent::optics::fresnel::Dielectric;
use lucent::optics::{Phase, PhaseFunction, SphericalQuadrature};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

const BATCH: usize = 4096;

fn phase_functions(c: &mut Criterion) {
    let mut rng = Pcg64Mcg::seed_from_u64(7);
    let u: Vec<[f64; 2]> = (0..BATCH).map(|_| [rng.random(), rng.random()]).collect();
    let cosines: Vec<f64> = (0..BATCH).map(|_| rng.random_range(-1.0..1.0)).collect();
    let omega_in = DVec3::new(0.3, -0.5, 0.8).normalize();
    for (name, phase) in [
        ("hg(0.8)", Phase::henyey_greenstein(0.8).unwrap()),
        (
            "double-hg(0.9,-0.3,0.7)",
            Phase::double_henyey_greenstein(0.9, -0.3, 0.7).unwrap(),
        ),
        ("rayleigh", Phase::Rayleigh),
    ] {
        c.bench_function(&format!("phase/eval/{name}/x{BATCH}"), |b| {
            b.iter(|| {
                cosines
                    .iter()
                    .map(|&mu| phase.eval_cos(black_box(mu)))
                    .sum::<f64>()
            })
        });
        c.bench_function(&format!("phase/sample/{name}/x{BATCH}"), |b| {
            b.iter(|| {
                u.iter()
                    .map(|&u| phase.sample(black_box(omega_in), u).pdf)
                    .sum::<f64>()
            })
        });
    }
}

fn fresnel(c: &mut Criterion) {
    let boundary = Dielectric::new(1.33).unwrap();
    let cosines: Vec<f64> = (0..BATCH)
        .map(|i| -1.0 + 2.0 * (i as f64 + 0.5) / BATCH as f64)
        .collect();
    c.bench_function(&format!("fresnel/reflectance/x{BATCH}"), |b| {
        b.iter(|| {
            cosines
                .iter()
                .map(|&mu| boundary.reflectance(black_box(mu)))
                .sum::<f64>()
        })
    });
}

fn quadratures(c: &mut Criterion) {
    c.bench_function("quadrature/level_symmetric(S16)", |b| {
        b.iter(|| {
            SphericalQuadrature::level_symmetric(black_box(16))
                .unwrap()
                .len()
        })
    });
    c.bench_function("quadrature/octahedral(level 4, 2048 dirs)", |b| {
        b.iter(|| SphericalQuadrature::octahedral(black_box(4)).unwrap().len())
    });
}

criterion_group!(benches, phase_functions, fresnel, quadratures);
criterion_main!(benches);
