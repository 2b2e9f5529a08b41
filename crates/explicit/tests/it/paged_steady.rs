//! `ftcs-diffusion` and `jacobi-diffusion` on a paged medium against the same entries in
//! memory: the same residual history, stop reason and iteration count, and the same bits of
//! the fluence, the renderer's isotropic fluence and the lights' transmittance. Over classes
//! of scenes: grids whose sides are not multiples of the brick, cells that are not cubes,
//! media touching the box with a clear region, grey and RGB, isotropic and forward
//! scattering, every kind of light (suns, sky, spots and point lights outside the box,
//! point lights inside it with and without a homogeneous ball for their singular part),
//! vacuum, index-mismatched Robin, Dirichlet and reflecting boundaries, with 1/16 of the
//! medium's bricks resident and the solver's own pool a few slabs of its state.

use std::sync::Arc;

use glam::DVec3;
use lucent_core::{
    Angular, Boundary, CellMedium, Field, Light, Medium, PagedProblem, ParamValue, Params, Problem,
    SolveError, SolveOptions, Solver, Spectrum,
};
use lucent_explicit::ExplicitSolver;
use lucent_grid::{BrickLayout, Grid, GridGeometry};
use lucent_optics::Phase;
use lucent_paging::{Eviction, FileStore, Pager, PagerOptions};

type CellFn = Box<dyn Fn(DVec3) -> f32 + Sync>;

struct Case {
    name: &'static str,
    geometry: GridGeometry,
    sigma_t: Vec<CellFn>,
    albedo: Vec<CellFn>,
    phase: Phase,
    lights: Vec<Light>,
    boundary: Boundary,
    brick: usize,
}

/// A medium that touches the box, with a clear slab at low x and a homogeneous block
/// around (0.5, 0.4, 0.44) (σ_t = `base`), rough elsewhere.
fn medium(base: f32) -> CellFn {
    Box::new(move |p: DVec3| {
        if p.x < 0.12 {
            0.0
        } else if (p - DVec3::new(0.5, 0.4, 0.44)).abs().max_element() < 0.37 {
            base
        } else {
            base * (1.0 + 0.7 * ((9.0 * p.y).sin() * (6.0 * p.z).cos()) as f32).abs()
        }
    })
}

fn constant(v: f32) -> CellFn {
    Box::new(move |_| v)
}

fn cases() -> Vec<Case> {
    let cubic = GridGeometry::new([13, 10, 11], DVec3::splat(0.08), DVec3::ZERO).unwrap();
    let stretched =
        GridGeometry::new([9, 12, 7], DVec3::new(0.1, 0.07, 0.12), DVec3::ZERO).unwrap();
    let sun = |d: DVec3, e: Spectrum| Light::Directional {
        direction: d.normalize(),
        irradiance: e,
    };
    vec![
        Case {
            name: "grey sun and sky, vacuum, isotropic",
            geometry: cubic,
            sigma_t: vec![medium(12.0)],
            albedo: vec![constant(0.9)],
            phase: Phase::Isotropic,
            lights: vec![
                sun(DVec3::new(0.3, -0.2, -0.9), Spectrum::Grey(2.0)),
                Light::Sky {
                    radiance: Spectrum::Grey(0.3),
                },
            ],
            boundary: Boundary::Vacuum,
            brick: 4,
        },
        Case {
            name: "RGB media, forward scattering, spot and point outside, Robin 1.4",
            geometry: cubic,
            sigma_t: vec![medium(8.0), medium(12.0), medium(16.0)],
            albedo: vec![constant(0.95), constant(0.8), constant(0.6)],
            phase: Phase::henyey_greenstein(0.6).unwrap(),
            lights: vec![
                Light::Spot {
                    position: DVec3::new(0.5, 0.4, 1.6),
                    direction: DVec3::new(0.0, 0.1, -1.0).normalize(),
                    intensity: Spectrum::Rgb([1.0, 0.7, 0.4]),
                    inner_angle: 0.3,
                    outer_angle: 0.5,
                },
                Light::Point {
                    position: DVec3::new(-0.4, 0.3, 0.5),
                    intensity: Spectrum::Grey(0.8),
                },
            ],
            boundary: Boundary::Robin { eta: 1.4 },
            brick: 8,
        },
        Case {
            name: "point lights inside (singular part and plain), reflecting box",
            geometry: cubic,
            sigma_t: vec![medium(10.0)],
            // Constant albedo: D is homogeneous in the block, as the singular part needs.
            albedo: vec![constant(0.8)],
            phase: Phase::henyey_greenstein(0.3).unwrap(),
            lights: vec![
                // In the homogeneous block, far enough from the box for a ball of three
                // cells: its singular part is taken out.
                Light::Point {
                    position: DVec3::new(0.51, 0.41, 0.43),
                    intensity: Spectrum::Grey(1.0),
                },
                // In the rough medium: a plain point source.
                Light::Point {
                    position: DVec3::new(0.95, 0.1, 0.8),
                    intensity: Spectrum::Rgb([0.5, 1.0, 0.2]),
                },
                sun(DVec3::new(-0.1, 0.2, -1.0), Spectrum::Grey(1.0)),
            ],
            boundary: Boundary::Neumann { flux: 0.0 },
            brick: 4,
        },
        Case {
            name: "cells that are not cubes, Dirichlet, sky only",
            geometry: stretched,
            sigma_t: vec![medium(9.0)],
            albedo: vec![constant(0.85), constant(0.9), constant(0.95)],
            phase: Phase::Isotropic,
            lights: vec![Light::Sky {
                radiance: Spectrum::Rgb([0.2, 0.3, 0.5]),
            }],
            boundary: Boundary::Dirichlet { value: 0.05 },
            brick: 4,
        },
    ]
}

/// A pager for the case's medium with 1/16 of its bricks resident (at least four).
fn medium_pager(case: &Case) -> Arc<Pager> {
    let layout = BrickLayout::new(case.geometry.dims(), case.brick).unwrap();
    let len = layout.stored_len();
    let fields = 2 * (case.sigma_t.len() + case.albedo.len() + 12);
    let slots = ((layout.count() * fields) as f64 / 16.0).ceil().max(4.0) as u64;
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

fn problems(case: &Case) -> (Problem, PagedProblem) {
    let g = case.geometry;
    let medium = Medium {
        sigma_t: case.sigma_t.iter().map(|f| Grid::from_fn(g, f)).collect(),
        albedo: case
            .albedo
            .iter()
            .map(|f| Field::Grid(Grid::from_fn(g, f)))
            .collect(),
        phase: case.phase,
    };
    let dense = Problem::new(g, medium, case.lights.clone(), case.boundary, None).unwrap();
    let paged = PagedProblem::from_fn(
        medium_pager(case),
        g,
        case.brick,
        CellMedium {
            sigma_t: case.sigma_t.iter().map(|f| f.as_ref()).collect(),
            albedo: case.albedo.iter().map(|f| f.as_ref()).collect(),
            phase: case.phase,
        },
        case.lights.clone(),
        case.boundary,
    )
    .unwrap();
    (dense, paged)
}

fn entry(name: &str, params: &[(&str, f64)]) -> Box<dyn Solver> {
    let mut p = Params::default();
    for (k, v) in params {
        p.0.insert((*k).into(), ParamValue::Float(*v));
    }
    let entry = if name == "ftcs-diffusion" {
        ExplicitSolver::FTCS_DIFFUSION
    } else {
        ExplicitSolver::JACOBI_DIFFUSION
    };
    (entry.build)(&p).unwrap()
}

fn same_bits(a: &Grid, b: &Grid) -> bool {
    a.data()
        .iter()
        .zip(b.data())
        .all(|(x, y)| x.to_bits() == y.to_bits())
}

/// The budget that leaves the solver's own pool `pages` slabs of its state.
fn budget_for(
    solver: &dyn Solver,
    paged: &PagedProblem,
    options: &SolveOptions,
    pages: u64,
) -> u64 {
    let tight = SolveOptions {
        memory_budget: 1,
        ..options.clone()
    };
    match solver.solve_paged(paged, &tight) {
        Err(SolveError::OverBudget { needed, .. }) => {
            let [nx, ny, _] = paged.geometry().dims();
            // `needed` holds the fewest pages (two) of one slab of f64 each.
            needed + (pages.saturating_sub(2)) * (nx * ny * 8) as u64
        }
        other => panic!("a one-byte budget must be refused: {other:?}"),
    }
}

#[test]
fn the_paged_steady_schemes_give_the_in_memory_bits() {
    for case in cases() {
        for (name, params) in [
            ("ftcs-diffusion", vec![("step_fraction", 0.9)]),
            ("jacobi-diffusion", vec![("omega", 0.8)]),
        ] {
            let solver = entry(name, &params);
            let (dense, paged) = problems(&case);
            // A limit of iterations well short of convergence for FTCS on the clear
            // region's large D, and a tolerance Jacobi meets in some cases: both ways of
            // stopping are compared.
            let options = SolveOptions {
                relative_tolerance: 1e-3,
                max_iterations: 150,
                ..SolveOptions::default()
            };
            let memory = solver.solve(&dense, &options).unwrap();
            let options = SolveOptions {
                memory_budget: budget_for(solver.as_ref(), &paged, &options, 6),
                ..options
            };
            let out = solver.solve_paged(&paged, &options).unwrap();
            let what = format!("{} with {name}", case.name);
            assert_eq!(out.report.stop_reason, memory.report.stop_reason, "{what}");
            assert_eq!(out.report.iterations, memory.report.iterations, "{what}");
            let bits = |r: &[f64]| r.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&out.report.residual_history),
                bits(&memory.report.residual_history),
                "{what}: residual history"
            );
            assert!(memory.report.iterations > 3, "{what}: it iterated");
            assert_eq!(out.fluence.len(), memory.fluence.len(), "{what}");
            for (c, (p, m)) in out.fluence.iter().zip(&memory.fluence).enumerate() {
                let p = p.to_grid().unwrap();
                assert!(m.data().iter().any(|&v| v > 0.0), "{what}: lit");
                assert!(same_bits(&p, m), "{what}: fluence, channel {c}");
            }
            match &memory.angular {
                Some(Angular::Lights(lights)) => {
                    assert_eq!(out.isotropic_fluence.len(), lights.isotropic_fluence.len());
                    for (p, m) in out.isotropic_fluence.iter().zip(&lights.isotropic_fluence) {
                        assert!(same_bits(&p.to_grid().unwrap(), m), "{what}: isotropic");
                    }
                    assert_eq!(out.transmittance.len(), lights.transmittance.len());
                    for (p, m) in out.transmittance.iter().zip(&lights.transmittance) {
                        for (p, m) in p.iter().zip(m) {
                            assert!(same_bits(&p.to_grid().unwrap(), m), "{what}: T");
                        }
                    }
                }
                _ => assert!(out.isotropic_fluence.is_empty(), "{what}"),
            }
            // Both pools paged: the medium's and the solver's state.
            let paging = out.report.paging.expect("paging counters");
            assert!(
                paging.evictions > 0 && paging.bytes_written > 0,
                "{what}: {paging:?}"
            );
        }
    }
}

#[test]
fn a_budget_below_one_slab_of_state_is_refused_before_any_work() {
    let case = &cases()[0];
    let (_, paged) = problems(case);
    let solver = entry("ftcs-diffusion", &[]);
    let before = paged.pager().stats();
    let options = SolveOptions {
        memory_budget: 4096,
        ..SolveOptions::default()
    };
    match solver.solve_paged(&paged, &options) {
        Err(SolveError::OverBudget { needed, budget, .. }) => {
            assert_eq!(budget, 4096);
            assert!(needed > budget);
        }
        other => panic!("{other:?}"),
    }
    // Nothing was read or written.
    assert_eq!(paged.pager().stats(), before);
}
