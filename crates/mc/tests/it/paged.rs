//! `mc` on a paged medium against `mc` in memory: the same bits (fluence and standard
//! error) when the bricks have `majorant_cells`³ cells, for grey and RGB extinction (the
//! spectral tracer), every point-like light and the sky, on a grid that is no multiple of
//! the bricks with the medium touching the box, the medium's pool and the tallies' pool
//! both far smaller than their bricks (so both page through their files). And the
//! refusals: a budget below what one round of batches needs, a boundary a paged medium
//! cannot have.

use std::sync::Arc;

use glam::DVec3;
use lucent_core::{
    Boundary, CellMedium, Field, Light, Medium, PagedProblem, Problem, SolveError, SolveOptions,
    Solver, Spectrum,
};
use lucent_grid::{BrickLayout, Grid, GridGeometry};
use lucent_mc::{McConfig, McSolver};
use lucent_optics::Phase;
use lucent_paging::{Eviction, FileStore, PagedGrid, Pager, PagerOptions};

fn geometry() -> GridGeometry {
    GridGeometry::new(
        [13, 10, 11],
        DVec3::new(0.1, 0.12, 0.09),
        DVec3::new(-0.5, 0.0, 0.2),
    )
    .unwrap()
}

/// A cloud touching the box on two faces, empty elsewhere.
fn cloud(scale: f32) -> impl Fn(DVec3) -> f32 + Sync {
    move |p: DVec3| {
        let r = (p - DVec3::new(0.6, 1.1, 1.1)).length();
        if r > 0.8 {
            0.0
        } else {
            scale * (1.0 - r as f32) * (1.0 + 0.5 * (9.0 * p.x).sin() as f32).abs()
        }
    }
}

fn lights() -> Vec<Light> {
    vec![
        Light::Directional {
            direction: DVec3::new(0.3, 0.5, -0.8).normalize(),
            irradiance: Spectrum::Rgb([1.0, 0.6, 0.3]),
        },
        Light::Point {
            position: DVec3::new(0.2, 0.5, 0.9),
            intensity: Spectrum::Grey(0.2),
        },
        Light::Spot {
            position: DVec3::new(-1.0, 0.5, 2.0),
            direction: DVec3::new(1.0, 0.0, -0.5).normalize(),
            intensity: Spectrum::Grey(3.0),
            inner_angle: 0.2,
            outer_angle: 0.5,
        },
        Light::Sky {
            radiance: Spectrum::Rgb([0.2, 0.3, 0.5]),
        },
    ]
}

fn bits(grid: &Grid) -> Vec<u32> {
    grid.data().iter().map(|v| v.to_bits()).collect()
}

fn paged_bits(field: &PagedGrid) -> Vec<u32> {
    bits(&field.to_grid().unwrap())
}

fn solver(brick: usize) -> McSolver {
    McSolver {
        config: McConfig {
            particles: 400,
            batches: 5,
            seed: 3,
            majorant_cells: brick,
            ..McConfig::default()
        },
        ..McSolver::default()
    }
}

#[test]
fn paged_monte_carlo_gives_the_in_memory_bits() {
    let g = geometry();
    let scales: [&[f32]; 2] = [&[8.0], &[4.0, 8.0, 16.0]];
    for sigma_scales in scales {
        for brick in [4, 8] {
            let sigmas: Vec<Box<dyn Fn(DVec3) -> f32 + Sync>> = sigma_scales
                .iter()
                .map(|&s| Box::new(cloud(s)) as Box<dyn Fn(DVec3) -> f32 + Sync>)
                .collect();
            // A varying albedo, so that the albedo's bricks are read too.
            let albedo = |p: DVec3| (0.6 + 0.3 * (4.0 * p.y).cos()) as f32;
            let medium = Medium {
                sigma_t: sigmas.iter().map(|f| Grid::from_fn(g, f)).collect(),
                albedo: vec![Field::Grid(Grid::from_fn(g, albedo))],
                phase: Phase::henyey_greenstein(0.5).unwrap(),
            };
            let dense = Problem::new(g, medium, lights(), Boundary::Vacuum, None).unwrap();
            let mc = solver(brick);
            let options = SolveOptions::default();
            let memory = mc.solve(&dense, &options).unwrap();

            // The medium's pool: an eighth of its bricks (at least the pins of two
            // running batches).
            let layout = BrickLayout::new(g.dims(), brick).unwrap();
            let len = layout.stored_len();
            let fields = sigma_scales.len() + 1 + 2 * 3;
            let slots = (layout.count() * fields / 8).max(16) as u64;
            let pager = Arc::new(
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
            );
            let refs: Vec<&(dyn Fn(DVec3) -> f32 + Sync)> =
                sigmas.iter().map(|f| f.as_ref()).collect();
            let paged = PagedProblem::from_fn(
                pager,
                g,
                brick,
                CellMedium {
                    sigma_t: refs,
                    albedo: vec![&albedo],
                    phase: Phase::henyey_greenstein(0.5).unwrap(),
                },
                lights(),
                Boundary::Vacuum,
            )
            .unwrap();
            // The smallest budget it takes, named by its refusal, plus a few tally pages:
            // the tallies page through their file too.
            let needed = match mc.solve_paged(
                &paged,
                &SolveOptions {
                    memory_budget: 1,
                    ..SolveOptions::default()
                },
            ) {
                Err(SolveError::OverBudget { needed, budget, .. }) => {
                    assert_eq!(budget, 1);
                    needed
                }
                other => panic!("{other:?}"),
            };
            let page = (brick.pow(3) * 3 * 8) as u64;
            let options = SolveOptions {
                memory_budget: needed + 4 * page,
                ..SolveOptions::default()
            };
            let solution = mc.solve_paged(&paged, &options).unwrap();
            let what = format!(
                "{} extinction channels, bricks of {brick}",
                sigma_scales.len()
            );
            assert_eq!(solution.fluence.len(), memory.fluence.len(), "{what}");
            for (c, (p, m)) in solution.fluence.iter().zip(&memory.fluence).enumerate() {
                assert!(paged_bits(p) == bits(m), "{what}: fluence channel {c}");
            }
            let errors = memory.standard_error.as_ref().unwrap();
            for (c, (p, m)) in solution.standard_error.iter().zip(errors).enumerate() {
                assert!(paged_bits(p) == bits(m), "{what}: standard error {c}");
            }
            assert_eq!(
                solution.report.stop_reason, memory.report.stop_reason,
                "{what}"
            );
            // Both pools were too small for their bricks: bricks went to the files.
            let s = &solution.paging;
            assert!(
                s.evictions > 0 && s.bytes_written > 0 && s.bytes_read > 0,
                "{what}: {s:?}"
            );
            // Something was traced: the fluence is not all zero.
            assert!(memory.fluence[0].data().iter().any(|&v| v > 0.0));
        }
    }
}

#[test]
fn paged_monte_carlo_refuses_what_it_cannot_do() {
    let g = geometry();
    let brick = 4;
    let layout = BrickLayout::new(g.dims(), brick).unwrap();
    let len = layout.stored_len();
    let pager = |slots: u64| {
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
    };
    let sigma = cloud(5.0);
    let albedo = |_: DVec3| 0.8f32;
    let problem = |boundary, slots| {
        PagedProblem::from_fn(
            pager(slots),
            g,
            brick,
            CellMedium {
                sigma_t: vec![&sigma],
                albedo: vec![&albedo],
                phase: Phase::Isotropic,
            },
            vec![Light::Sky {
                radiance: Spectrum::Grey(1.0),
            }],
            boundary,
        )
        .unwrap()
    };
    let mc = solver(brick);
    // A medium pool that cannot hold the running batches' pins.
    let threads = rayon::current_num_threads() as u64;
    match mc.solve_paged(
        &problem(Boundary::Vacuum, 2 * threads - 1),
        &SolveOptions::default(),
    ) {
        Err(SolveError::OverBudget { needed, budget, .. }) => assert!(needed > budget),
        other => panic!("{other:?}"),
    }
    // A budget the medium's pool alone exceeds.
    let roomy = problem(Boundary::Vacuum, 64);
    let small = SolveOptions {
        memory_budget: 64 * 4 * len as u64,
        ..SolveOptions::default()
    };
    assert!(matches!(
        mc.solve_paged(&roomy, &small),
        Err(SolveError::OverBudget { .. })
    ));
    // A refracting boundary.
    assert!(matches!(
        mc.solve_paged(
            &problem(Boundary::Robin { eta: 1.33 }, 64),
            &SolveOptions::default()
        ),
        Err(SolveError::Unsupported { .. })
    ));
    // A medium too thick to cross, as in memory: refused by the bricks' ranges, before
    // any path.
    let thick = |_: DVec3| 1e8f32;
    let problem = PagedProblem::from_fn(
        pager(64),
        g,
        brick,
        CellMedium {
            sigma_t: vec![&thick],
            albedo: vec![&albedo],
            phase: Phase::Isotropic,
        },
        vec![Light::Sky {
            radiance: Spectrum::Grey(1.0),
        }],
        Boundary::Vacuum,
    )
    .unwrap();
    assert!(matches!(
        mc.solve_paged(&problem, &SolveOptions::default()),
        Err(SolveError::TooMuchWork { .. })
    ));
    assert!(mc.pages());
}
