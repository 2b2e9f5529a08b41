//! `direct` on a paged medium against `direct` in memory: the same bits, for every light
//! kind, grey and RGB extinction, bricks of several sizes on a grid that is no multiple of
//! them with the medium touching the box, and a pool of 1/16 of the bricks over a backing
//! file. And the refusals: a budget below what the paged solve needs, a boundary `direct`
//! does not take, a solver that cannot page.

use std::sync::Arc;

use glam::DVec3;
use lucent_core::{
    Angular, Boundary, CellMedium, DirectSolver, Field, Light, Medium, PagedProblem, Problem,
    SolveError, SolveOptions, Solver, Spectrum,
};
use lucent_grid::{BrickLayout, Grid, GridGeometry};
use lucent_optics::Phase;
use lucent_paging::{Eviction, FileStore, PagedGrid, Pager, PagerOptions};

fn geometry() -> GridGeometry {
    GridGeometry::new(
        [21, 14, 17],
        DVec3::new(0.1, 0.07, 0.12),
        DVec3::new(-0.5, 0.0, 0.2),
    )
    .unwrap()
}

/// A cloud that touches the box on two faces and is empty elsewhere.
fn cloud(scale: f32) -> impl Fn(DVec3) -> f32 + Sync {
    move |p: DVec3| {
        let r = (p - DVec3::new(1.4, 0.9, 1.6)).length();
        if r > 1.0 {
            0.0
        } else {
            scale * (1.2 - r as f32) * (1.0 + 0.5 * (9.0 * p.x).sin() as f32).abs()
        }
    }
}

fn lights() -> Vec<Light> {
    vec![
        Light::Point {
            position: DVec3::new(2.5, 0.4, 1.0),
            intensity: Spectrum::Rgb([1.0, 2.0, 0.5]),
        },
        // Inside the box: the 1/r² floor at the cells around it.
        Light::Point {
            position: DVec3::new(0.3, 0.5, 1.1),
            intensity: Spectrum::Grey(0.2),
        },
        Light::Spot {
            position: DVec3::new(-1.0, 0.5, 3.0),
            direction: DVec3::new(1.0, 0.0, -0.8).normalize(),
            intensity: Spectrum::Grey(3.0),
            inner_angle: 0.2,
            outer_angle: 0.5,
        },
        Light::Directional {
            direction: DVec3::new(0.3, 0.5, -0.8).normalize(),
            irradiance: Spectrum::Grey(1.5),
        },
        Light::Sky {
            radiance: Spectrum::Rgb([0.2, 0.3, 0.5]),
        },
    ]
}

fn pager(brick: usize, fraction: f64, bricks_per_field: usize, fields: usize) -> Arc<Pager> {
    let len = BrickLayout::new(geometry().dims(), brick)
        .unwrap()
        .stored_len();
    let slots = ((bricks_per_field * fields) as f64 * fraction)
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
                eviction: Eviction::Nru,
                fill: 0.0,
            },
        )
        .unwrap(),
    )
}

fn bits(grid: &Grid) -> Vec<u32> {
    grid.data().iter().map(|v| v.to_bits()).collect()
}

fn paged_bits(field: &PagedGrid) -> Vec<u32> {
    bits(&field.to_grid().unwrap())
}

#[test]
fn paged_direct_gives_the_in_memory_bits() {
    let g = geometry();
    let scales: [&[f32]; 2] = [&[6.0], &[3.0, 6.0, 12.0]];
    for sigma_scales in scales {
        for brick in [4, 8] {
            let sigmas: Vec<Box<dyn Fn(DVec3) -> f32 + Sync>> = sigma_scales
                .iter()
                .map(|&s| Box::new(cloud(s)) as Box<dyn Fn(DVec3) -> f32 + Sync>)
                .collect();
            let medium = Medium {
                sigma_t: sigmas.iter().map(|f| Grid::from_fn(g, f)).collect(),
                albedo: vec![Field::Constant(0.9)],
                phase: Phase::henyey_greenstein(0.4).unwrap(),
            };
            let dense = Problem::new(g, medium, lights(), Boundary::Vacuum, None).unwrap();
            let options = SolveOptions::default();
            let memory = DirectSolver::default().solve(&dense, &options).unwrap();

            let layout = BrickLayout::new(g.dims(), brick).unwrap();
            // Fields: σ_t, albedo, transmittance per light and channel, the sky's, the
            // isotropic fluence and the fluence: 1/16 of their bricks resident.
            let fields = 2 * sigma_scales.len() + 4 * sigma_scales.len() + sigma_scales.len() + 6;
            let pager = pager(brick, 1.0 / 16.0, layout.count(), fields);
            let refs: Vec<&(dyn Fn(DVec3) -> f32 + Sync)> =
                sigmas.iter().map(|f| f.as_ref()).collect();
            let albedo = |_: DVec3| 0.9f32;
            let paged = PagedProblem::from_fn(
                pager.clone(),
                g,
                brick,
                CellMedium {
                    sigma_t: refs,
                    albedo: vec![&albedo],
                    phase: Phase::henyey_greenstein(0.4).unwrap(),
                },
                lights(),
                Boundary::Vacuum,
            )
            .unwrap();
            let solution = DirectSolver::default()
                .solve_paged(&paged, &options)
                .unwrap();
            let what = format!(
                "{} extinction channels, bricks of {brick}",
                sigma_scales.len()
            );
            assert_eq!(solution.fluence.len(), memory.fluence.len(), "{what}");
            for (c, (p, m)) in solution.fluence.iter().zip(&memory.fluence).enumerate() {
                assert!(paged_bits(p) == bits(m), "{what}: fluence channel {c}");
            }
            let Some(Angular::Lights(l)) = &memory.angular else {
                panic!("direct keeps its lights")
            };
            for (light, (p, m)) in solution
                .transmittance
                .iter()
                .zip(&l.transmittance)
                .enumerate()
            {
                for (c, (p, m)) in p.iter().zip(m).enumerate() {
                    assert!(
                        paged_bits(p) == bits(m),
                        "{what}: light {light} channel {c}"
                    );
                }
            }
            for (c, (p, m)) in solution
                .isotropic_fluence
                .iter()
                .zip(&l.isotropic_fluence)
                .enumerate()
            {
                assert!(paged_bits(p) == bits(m), "{what}: isotropic fluence {c}");
            }
            // It paged: the pool is a sixteenth of the bricks, so bricks went to the file
            // and came back.
            assert!(
                solution.paging.evictions > 0 && solution.paging.bytes_read > 0,
                "{:?}",
                solution.paging
            );
            assert!(solution.report.stop_reason.is_converged());
        }
    }
}

#[test]
fn paged_solves_are_refused_before_work_when_they_cannot_run() {
    let g = geometry();
    let brick = 8;
    let layout = BrickLayout::new(g.dims(), brick).unwrap();
    let pager = pager(brick, 0.5, layout.count(), 4);
    let sigma = cloud(5.0);
    let albedo = |_: DVec3| 0.5f32;
    let problem = |boundary| {
        PagedProblem::from_fn(
            pager.clone(),
            g,
            brick,
            CellMedium {
                sigma_t: vec![&sigma],
                albedo: vec![&albedo],
                phase: Phase::Isotropic,
            },
            vec![Light::Directional {
                direction: DVec3::NEG_Z,
                irradiance: Spectrum::Grey(1.0),
            }],
            boundary,
        )
        .unwrap()
    };
    // A budget below the pool itself.
    let tight = SolveOptions {
        memory_budget: 1000,
        ..SolveOptions::default()
    };
    match DirectSolver::default().solve_paged(&problem(Boundary::Vacuum), &tight) {
        Err(SolveError::OverBudget { needed, budget, .. }) => {
            assert!(needed > budget && budget == 1000)
        }
        other => panic!("{other:?}"),
    }
    // A boundary direct does not take.
    assert!(matches!(
        DirectSolver::default().solve_paged(
            &problem(Boundary::Robin { eta: 1.4 }),
            &SolveOptions::default()
        ),
        Err(SolveError::Unsupported { .. })
    ));
    // A solver that needs its fields in memory says so.
    struct InMemoryOnly;
    impl Solver for InMemoryOnly {
        fn name(&self) -> &str {
            "in-memory-only"
        }
        fn capabilities(&self) -> lucent_core::Capabilities {
            lucent_core::Capabilities::default()
        }
        fn solve(
            &self,
            _: &Problem,
            _: &SolveOptions,
        ) -> Result<lucent_core::Solution, SolveError> {
            unreachable!()
        }
    }
    assert!(!InMemoryOnly.pages() && DirectSolver::default().pages());
    match InMemoryOnly.solve_paged(&problem(Boundary::Vacuum), &SolveOptions::default()) {
        Err(e @ SolveError::Unsupported { .. }) => {
            assert!(e.to_string().contains("paged"), "{e}")
        }
        other => panic!("{other:?}"),
    }
    // Bad values are refused while the paged medium is built.
    let nan = |_: DVec3| f32::NAN;
    assert!(
        PagedProblem::from_fn(
            pager.clone(),
            g,
            brick,
            CellMedium {
                sigma_t: vec![&nan],
                albedo: vec![&albedo],
                phase: Phase::Isotropic,
            },
            vec![],
            Boundary::Vacuum,
        )
        .is_err()
    );
}
