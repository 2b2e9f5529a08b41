//! Monte Carlo against closed forms and against itself: Beer–Lambert transmission, cell
//! averages of the uncollided fluence, the energy balance, majorants, determinism.
//!
//! Statistical tests use 3σ bounds from the run's own batch statistics, with fixed seeds:
//! each is deterministic, and a wrong estimator fails by many σ.

use glam::DVec3;
use lucent_core::{Boundary, Field, Light, Medium, Problem, SolveOptions, Solver, Spectrum};
use lucent_grid::procedural::NoiseCloud;
use lucent_grid::{Grid, GridGeometry};
use lucent_mc::{MajorantGrid, McConfig, McSolver, estimate};
use lucent_optics::Phase;
use proptest::prelude::*;

fn problem(sigma_t: Grid, albedo: f32, phase: Phase, lights: Vec<Light>) -> Problem {
    let geometry = *sigma_t.geometry();
    let medium = Medium {
        sigma_t: vec![sigma_t],
        albedo: vec![Field::Constant(albedo)],
        phase,
    };
    Problem::new(geometry, medium, lights, Boundary::Vacuum, None).unwrap()
}

fn unit_cube(n: usize) -> GridGeometry {
    GridGeometry::new([n; 3], DVec3::splat(1.0 / n as f64), DVec3::ZERO).unwrap()
}

fn beam() -> Light {
    Light::Directional {
        direction: DVec3::X,
        irradiance: Spectrum::Grey(1.0),
    }
}

#[test]
fn pure_absorber_transmits_beer_lambert() {
    let g = unit_cube(8);
    let p = problem(Grid::filled(g, 2.0), 0.0, Phase::Isotropic, vec![beam()]);
    let config = McConfig {
        particles: 20_000,
        batches: 10,
        ..Default::default()
    };
    let run = estimate(&p, &config).unwrap();
    let e = &run.energy[0];
    let transmitted = e.escaped.mean / e.emitted.mean;
    let exact = (-2.0f64).exp();
    // Each entering particle crosses independently with probability e^{−2}: binomial.
    let power_per_particle = 1.0 / config.particles as f64; // E·A⊥: the unit face
    let entered = e.emitted.mean * config.batches as f64 / power_per_particle;
    let sigma = (exact * (1.0 - exact) / entered).sqrt();
    assert!(
        (transmitted - exact).abs() < 3.0 * sigma,
        "{transmitted} vs {exact} ± {sigma}"
    );
    assert!(
        e.imbalance.mean.abs() < 1e-12,
        "no scattering, no roulette: exact balance"
    );
}

#[test]
fn uncollided_fluence_matches_exact_cell_averages() {
    // φ averaged over cell [x0, x1] of e^{−σx} is (e^{−σx0} − e^{−σx1})/(σh).
    let n = 8;
    let sigma = 1.5;
    let g = unit_cube(n);
    let p = problem(
        Grid::filled(g, sigma as f32),
        0.0,
        Phase::Isotropic,
        vec![beam()],
    );
    let run = estimate(
        &p,
        &McConfig {
            particles: 20_000,
            batches: 32,
            seed: 9,
            ..Default::default()
        },
    )
    .unwrap();
    let h = 1.0 / n as f64;
    let mut z = Vec::new();
    for index in 0..g.voxel_count() {
        let [i, _, _] = g.coords(index);
        let (x0, x1) = (i as f64 * h, (i + 1) as f64 * h);
        let exact = ((-sigma * x0).exp() - (-sigma * x1).exp()) / (sigma * h);
        let got = f64::from(run.fluence[0].data()[index]);
        let se = f64::from(run.standard_error[0].data()[index]);
        z.push((got - exact) / se);
    }
    let outliers = z.iter().filter(|v| v.abs() > 4.0).count();
    let mean_z = z.iter().sum::<f64>() / z.len() as f64;
    let rms_z = (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt();
    // With 32 batches z follows Student's t with 31 degrees of freedom: P(|z| > 4) ≈ 4e-4
    // per cell (0.2 of 512 expected), rms ≈ 1.03, and the mean z has σ ≈ 0.045.
    assert!(
        outliers <= 2,
        "{outliers} cells beyond 4σ (mean z {mean_z}, rms {rms_z})"
    );
    assert!(
        mean_z.abs() < 0.2 && rms_z < 1.25,
        "mean z-score {mean_z}, rms {rms_z}: a biased estimator shifts them"
    );
}

#[test]
fn energy_is_conserved_at_every_albedo() {
    let g = unit_cube(16);
    let cloud = NoiseCloud::new(3, DVec3::splat(0.5), 0.48)
        .rasterize(g)
        .unwrap()
        .map(|d| 20.0 * d);
    for albedo in [0.5f32, 0.99, 1.0] {
        let lights = vec![
            beam(),
            Light::Sky {
                radiance: Spectrum::Grey(0.2),
            },
        ];
        let p = problem(
            cloud.clone(),
            albedo,
            Phase::henyey_greenstein(0.5).unwrap(),
            lights,
        );
        let run = estimate(
            &p,
            &McConfig {
                particles: 4_000,
                batches: 12,
                seed: 5,
                ..Default::default()
            },
        )
        .unwrap();
        let e = &run.energy[0];
        assert!(e.emitted.mean > 0.0);
        assert!(
            e.imbalance.mean.abs() <= 3.0 * e.imbalance.std_error + 1e-12 * e.emitted.mean,
            "albedo {albedo}: imbalance {:?} of emitted {}",
            e.imbalance,
            e.emitted.mean
        );
        if albedo == 1.0 {
            assert_eq!(e.absorbed.mean, 0.0, "nothing is absorbed at albedo 1");
        } else {
            assert!(e.absorbed.mean > 0.0);
        }
    }
}

#[test]
fn local_and_global_majorants_agree_within_noise() {
    let g = unit_cube(12);
    let cloud = NoiseCloud::new(11, DVec3::splat(0.5), 0.48)
        .rasterize(g)
        .unwrap()
        .map(|d| 30.0 * d);
    let p = problem(
        cloud,
        0.8,
        Phase::henyey_greenstein(0.3).unwrap(),
        vec![beam()],
    );
    let base = McConfig {
        particles: 6_000,
        batches: 12,
        seed: 21,
        ..Default::default()
    };
    let local = estimate(
        &p,
        &McConfig {
            majorant_cells: 4,
            ..base
        },
    )
    .unwrap();
    let global = estimate(
        &p,
        &McConfig {
            global_majorant: true,
            seed: 22,
            ..base
        },
    )
    .unwrap();
    let mut z = Vec::new();
    for v in 0..g.voxel_count() {
        let (a, b) = (
            f64::from(local.fluence[0].data()[v]),
            f64::from(global.fluence[0].data()[v]),
        );
        let se = f64::from(local.standard_error[0].data()[v])
            .hypot(f64::from(global.standard_error[0].data()[v]));
        if se > 0.0 {
            z.push((a - b) / se);
        }
    }
    let mean_z = z.iter().sum::<f64>() / z.len() as f64;
    let rms_z = (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt();
    // Independent unbiased estimates: z ~ N(0, 1) per cell (batch standard errors from 12
    // batches are themselves noisy, so allow an rms up to 1.4).
    assert!(
        mean_z.abs() < 0.15 && rms_z < 1.4,
        "mean z {mean_z}, rms z {rms_z}"
    );
}

#[test]
fn same_seed_same_bits_on_one_two_and_eight_threads() {
    let g = unit_cube(10);
    let cloud = NoiseCloud::new(1, DVec3::splat(0.5), 0.48)
        .rasterize(g)
        .unwrap()
        .map(|d| 15.0 * d);
    let p = problem(
        cloud,
        0.9,
        Phase::henyey_greenstein(0.6).unwrap(),
        vec![beam()],
    );
    let mut params = lucent_core::Params::default();
    params
        .0
        .insert("particles".into(), lucent_core::ParamValue::Int(2000));
    params
        .0
        .insert("batches".into(), lucent_core::ParamValue::Int(5));
    let solver = McSolver::from_params(&params).unwrap();
    let run = |threads: usize| {
        solver
            .solve(
                &p,
                &SolveOptions {
                    threads: Some(threads),
                    ..Default::default()
                },
            )
            .unwrap()
    };
    let one = run(1);
    assert!(one.standard_error.is_some());
    for threads in [2, 8] {
        let other = run(threads);
        assert_eq!(one.fluence, other.fluence, "{threads} threads");
        assert_eq!(
            one.standard_error, other.standard_error,
            "{threads} threads"
        );
    }
    // The camera tracer too: the same picture on pools of 1, 2 and 8 threads.
    let ray = |u: f64, v: f64| {
        let origin = DVec3::new(u, v, -1.0);
        (origin, DVec3::Z)
    };
    let picture = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            lucent_mc::camera_image(&p, 12, 9, 4, [0.1; 3], &solver.config, ray).unwrap()
        })
    };
    let first = picture(1);
    // The medium shows: pixels differ (a blank picture would be equal on any pool).
    assert!(first.radiance.iter().any(|p| p[0] != first.radiance[0][0]));
    for threads in [2, 8] {
        let other = picture(threads);
        assert_eq!(first.radiance, other.radiance, "{threads} threads");
        assert_eq!(first.std_error, other.std_error, "{threads} threads");
    }
}

#[test]
fn refuses_what_it_cannot_do() {
    let g = unit_cube(4);
    let medium = Medium {
        sigma_t: vec![Grid::filled(g, 1.0)],
        albedo: vec![Field::Constant(0.5)],
        phase: Phase::Isotropic,
    };
    let robin = Problem::new(g, medium, vec![beam()], Boundary::Robin { eta: 1.3 }, None).unwrap();
    assert!(
        McSolver::default()
            .solve(&robin, &SolveOptions::default())
            .is_err()
    );
    let p = problem(Grid::filled(g, 1.0), 0.5, Phase::Isotropic, vec![beam()]);
    assert!(
        estimate(
            &p,
            &McConfig {
                batches: 1,
                ..Default::default()
            }
        )
        .is_err()
    );
    let mut params = lucent_core::Params::default();
    params
        .0
        .insert("partcles".into(), lucent_core::ParamValue::Int(5));
    assert!(
        McSolver::from_params(&params).is_err(),
        "a misspelt parameter is an error"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn majorants_bound_the_extinction_everywhere(
        dims in [1usize..12, 1usize..12, 1usize..12],
        factor in 1usize..6,
        seed in any::<u64>(),
        points in prop::collection::vec([0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0], 64),
    ) {
        let g = GridGeometry::new(dims, DVec3::new(0.7, 1.1, 0.9), DVec3::new(-1.0, 0.5, 2.0)).unwrap();
        let (lo, hi) = g.bounds();
        let sigma = NoiseCloud::new(seed, 0.5 * (lo + hi), 0.6 * (hi - lo).max_element()).rasterize(g).unwrap().map(|d| 10.0 * d);
        let majorant = MajorantGrid::new(&sigma, factor);
        for t in points {
            let p = lo + (hi - lo) * DVec3::from_array(t);
            prop_assert!(majorant.at(p) >= f64::from(sigma.sample_trilinear(p)), "at {p}");
        }
    }
}

#[test]
fn spectral_mis_fluence_agrees_with_per_channel_tracing() {
    // Ketchup-like RGB extinction (channels 3.5× apart) and albedo (40× apart): the hero-
    // channel estimator and three separate traces estimate the same fluences.
    let g = unit_cube(12);
    let blob = lucent_grid::procedural::gaussian_blob(g, DVec3::splat(0.5), 0.25).unwrap();
    let medium = Medium {
        sigma_t: [4.0f32, 10.0, 14.0]
            .iter()
            .map(|&s| blob.map(|d| s * d))
            .collect(),
        albedo: vec![
            Field::Constant(0.9),
            Field::Constant(0.3),
            Field::Constant(0.02),
        ],
        phase: Phase::henyey_greenstein(0.3).unwrap(),
    };
    let p = Problem::new(
        g,
        medium,
        vec![
            beam(),
            Light::Sky {
                radiance: Spectrum::Grey(0.1),
            },
        ],
        Boundary::Vacuum,
        None,
    )
    .unwrap();
    let base = McConfig {
        particles: 6000,
        batches: 12,
        ..Default::default()
    };
    let mis = estimate(&p, &McConfig { seed: 31, ..base }).unwrap();
    let separate = estimate(
        &p,
        &McConfig {
            seed: 32,
            spectral_mis: false,
            ..base
        },
    )
    .unwrap();
    for c in 0..3 {
        let (a, b) = (&mis.energy[c], &separate.energy[c]);
        for (name, x, y) in [
            ("absorbed", a.absorbed, b.absorbed),
            ("escaped", a.escaped, b.escaped),
        ] {
            let sigma = x.std_error.hypot(y.std_error);
            assert!(
                (x.mean - y.mean).abs() < 4.0 * sigma + 1e-12,
                "channel {c} {name}: {x:?} vs {y:?}"
            );
        }
        let z: Vec<f64> = (0..g.voxel_count())
            .filter_map(|v| {
                let se = f64::from(mis.standard_error[c].data()[v])
                    .hypot(f64::from(separate.standard_error[c].data()[v]));
                (se > 0.0).then(|| {
                    (f64::from(mis.fluence[c].data()[v]) - f64::from(separate.fluence[c].data()[v]))
                        / se
                })
            })
            .collect();
        let mean = z.iter().sum::<f64>() / z.len() as f64;
        let rms = (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt();
        assert!(
            mean.abs() < 0.15 && rms < 1.4,
            "channel {c}: mean z {mean}, rms z {rms}"
        );
    }
}
