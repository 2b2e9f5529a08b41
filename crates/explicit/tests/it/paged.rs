//! `convection-diffusion` on a paged medium against the same entry in memory: the same
//! bits, for suns along every dominant axis and sign, one and two lights, grey and RGB
//! extinction, with 1/16 of the bricks resident over a backing file; and the refusals.

use std::sync::Arc;

use glam::DVec3;
use lucent_core::{
    Boundary, CellMedium, Field, Light, Medium, PagedProblem, ParamValue, Params, Problem,
    SolveError, SolveOptions, Spectrum,
};
use lucent_explicit::ExplicitSolver;
use lucent_grid::{BrickLayout, Grid, GridGeometry};
use lucent_optics::Phase;
use lucent_paging::{Eviction, FileStore, Pager, PagerOptions};

fn geometry() -> GridGeometry {
    GridGeometry::new([19, 13, 11], DVec3::splat(0.08), DVec3::new(-0.2, 0.1, 0.0)).unwrap()
}

/// Empty on one side, rough on the other, touching the box.
fn cloud(scale: f32) -> impl Fn(DVec3) -> f32 + Sync {
    move |p: DVec3| {
        if p.x < 0.3 {
            0.0
        } else {
            scale * (1.0 + 0.8 * (11.0 * p.y).sin() as f32 * (7.0 * p.z).cos() as f32).abs()
        }
    }
}

fn pager(brick: usize, fraction: f64, fields: usize) -> Arc<Pager> {
    let layout = BrickLayout::new(geometry().dims(), brick).unwrap();
    let len = layout.stored_len();
    let slots = ((layout.count() * fields) as f64 * fraction)
        .ceil()
        .max(4.0) as u64;
    Arc::new(
        Pager::new(
            Box::new(FileStore::create().unwrap()),
            0,
            len,
            1,
            PagerOptions {
                budget_bytes: slots * 4 * len as u64,
                eviction: Eviction::Lru,
                fill: 0.0,
            },
        )
        .unwrap(),
    )
}

fn solver() -> Box<dyn lucent_core::Solver> {
    (ExplicitSolver::CONVECTION_DIFFUSION.build)(&Params::default()).unwrap()
}

#[test]
fn the_paged_absorption_march_gives_the_in_memory_bits() {
    let g = geometry();
    let suns = [
        DVec3::new(0.3, 0.2, -0.93),
        DVec3::new(0.9, -0.3, 0.2),
        DVec3::new(-0.95, 0.1, 0.25),
        DVec3::new(0.2, 0.97, -0.1),
        DVec3::new(-0.1, -0.9, -0.3),
        DVec3::new(0.0, 0.0, 1.0),
    ];
    let scales: [&[f32]; 2] = [&[9.0], &[4.0, 9.0, 16.0]];
    for (case, sigma_scales) in scales.iter().enumerate() {
        for (n, sun) in suns.iter().enumerate() {
            // One sun, or this one and the next in another colour.
            let mut lights = vec![Light::Directional {
                direction: sun.normalize(),
                irradiance: Spectrum::Rgb([1.0, 0.8, 0.6]),
            }];
            if n % 2 == 1 {
                lights.push(Light::Directional {
                    direction: suns[(n + 1) % suns.len()].normalize(),
                    irradiance: Spectrum::Grey(0.5),
                });
            }
            let sigmas: Vec<Box<dyn Fn(DVec3) -> f32 + Sync>> = sigma_scales
                .iter()
                .map(|&s| Box::new(cloud(s)) as Box<dyn Fn(DVec3) -> f32 + Sync>)
                .collect();
            let medium = Medium {
                sigma_t: sigmas.iter().map(|f| Grid::from_fn(g, f)).collect(),
                albedo: vec![Field::Constant(0.5)],
                phase: Phase::Isotropic,
            };
            let dense = Problem::new(g, medium, lights.clone(), Boundary::Vacuum, None).unwrap();
            let memory = solver().solve(&dense, &SolveOptions::default()).unwrap();

            let brick = if n % 2 == 0 { 4 } else { 8 };
            let pager = pager(brick, 1.0 / 16.0, 8);
            let albedo = |_: DVec3| 0.5f32;
            let paged = PagedProblem::from_fn(
                pager,
                g,
                brick,
                CellMedium {
                    sigma_t: sigmas.iter().map(|f| f.as_ref()).collect(),
                    albedo: vec![&albedo],
                    phase: Phase::Isotropic,
                },
                lights,
                Boundary::Vacuum,
            )
            .unwrap();
            let solution = solver()
                .solve_paged(&paged, &SolveOptions::default())
                .unwrap();
            assert_eq!(solution.fluence.len(), memory.fluence.len());
            for (c, (p, m)) in solution.fluence.iter().zip(&memory.fluence).enumerate() {
                let p = p.to_grid().unwrap();
                assert!(m.data().iter().any(|&v| v > 0.0));
                let same = p
                    .data()
                    .iter()
                    .zip(m.data())
                    .all(|(a, b)| a.to_bits() == b.to_bits());
                assert!(same, "case {case}, sun {n}, channel {c}");
            }
            assert!(solution.paging.evictions > 0, "{:?}", solution.paging);
        }
    }
}

#[test]
fn what_cannot_march_plane_by_plane_is_refused() {
    let g = geometry();
    let sigma = cloud(5.0);
    let albedo = |_: DVec3| 0.5f32;
    let problem = |lights: Vec<Light>| {
        PagedProblem::from_fn(
            pager(8, 0.5, 4),
            g,
            8,
            CellMedium {
                sigma_t: vec![&sigma],
                albedo: vec![&albedo],
                phase: Phase::Isotropic,
            },
            lights,
            Boundary::Vacuum,
        )
        .unwrap()
    };
    let sun = || Light::Directional {
        direction: DVec3::NEG_Z,
        irradiance: Spectrum::Grey(1.0),
    };
    let refused = |params: &[(&str, ParamValue)], lights: Vec<Light>| {
        let mut p = Params::default();
        for (k, v) in params {
            p.0.insert((*k).into(), v.clone());
        }
        let solver = (ExplicitSolver::CONVECTION_DIFFUSION.build)(&p).unwrap();
        match solver.solve_paged(&problem(lights), &SolveOptions::default()) {
            Err(SolveError::Unsupported { feature, .. }) => feature,
            other => panic!("{params:?}: {other:?}"),
        }
    };
    assert!(
        refused(&[("model", ParamValue::Text("paper".into()))], vec![sun()]).contains("upwind")
    );
    assert!(
        refused(&[("scattering", ParamValue::Float(0.01))], vec![sun()]).contains("scattering")
    );
    let point = Light::Point {
        position: DVec3::splat(0.5),
        intensity: Spectrum::Grey(1.0),
    };
    assert!(refused(&[], vec![point]).contains("point"));
    // Every other explicit entry pages (tests/it/paged_steady.rs, tests/it/paged_march.rs).
    for entry in ExplicitSolver::ENTRIES {
        let solver = (entry.build)(&Params::default()).unwrap();
        assert!(solver.pages(), "{}", entry.name);
    }
    // A budget below the pool.
    let tight = SolveOptions {
        memory_budget: 4096,
        ..SolveOptions::default()
    };
    assert!(matches!(
        solver().solve_paged(&problem(vec![sun()]), &tight),
        Err(SolveError::OverBudget { .. })
    ));
}
