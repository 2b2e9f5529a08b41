//! `ftcs-p1` and `ftcs-ordinates` on a paged medium against the same entries in memory:
//! the same stop reason, step count and residual history, and the same bits of the
//! fluence. Over grids whose sides are not multiples of the brick, both P1 layouts, S2 to
//! S6 ordinates on a medium with a clear region touching the box, grey and RGB lights,
//! point lights in cells on the box's faces, runs that stop at the iteration limit, at
//! the tolerance, and by the growth monitor beyond the stability bound; with 1/16 of the
//! medium's bricks resident and a pool of a few slabs of the state.

use std::sync::Arc;

use glam::DVec3;
use lucent_core::{
    Boundary, CellMedium, Field, Light, Medium, PagedProblem, ParamValue, Params, Problem,
    SolveError, SolveOptions, Solver, Spectrum, StopReason,
};
use lucent_explicit::ExplicitSolver;
use lucent_grid::{BrickLayout, Grid, GridGeometry};
use lucent_optics::Phase;
use lucent_paging::{Eviction, FileStore, Pager, PagerOptions};

type CellFn = Box<dyn Fn(DVec3) -> f32 + Sync>;

fn geometry() -> GridGeometry {
    GridGeometry::new([11, 9, 13], DVec3::splat(0.1), DVec3::new(0.0, -0.2, 0.1)).unwrap()
}

fn problems(
    sigma_t: &[CellFn],
    albedo: &[CellFn],
    phase: Phase,
    lights: &[Light],
    brick: usize,
) -> (Problem, PagedProblem) {
    let g = geometry();
    let medium = Medium {
        sigma_t: sigma_t.iter().map(|f| Grid::from_fn(g, f)).collect(),
        albedo: albedo
            .iter()
            .map(|f| Field::Grid(Grid::from_fn(g, f)))
            .collect(),
        phase,
    };
    let dense = Problem::new(g, medium, lights.to_vec(), Boundary::Vacuum, None).unwrap();
    let layout = BrickLayout::new(g.dims(), brick).unwrap();
    let len = layout.stored_len();
    let slots = ((layout.count() * (sigma_t.len() + albedo.len() + 3)) as f64 / 16.0)
        .ceil()
        .max(4.0) as u64;
    let pager = Arc::new(
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
    );
    let paged = PagedProblem::from_fn(
        pager,
        g,
        brick,
        CellMedium {
            sigma_t: sigma_t.iter().map(|f| f.as_ref()).collect(),
            albedo: albedo.iter().map(|f| f.as_ref()).collect(),
            phase,
        },
        lights.to_vec(),
        Boundary::Vacuum,
    )
    .unwrap();
    (dense, paged)
}

fn build(entry: lucent_core::SolverEntry, params: &[(&str, ParamValue)]) -> Box<dyn Solver> {
    let mut p = Params::default();
    for (k, v) in params {
        p.0.insert((*k).into(), v.clone());
    }
    (entry.build)(&p).unwrap()
}

/// The least budget the paged solve takes: its fixed needs and two slabs of state.
fn least_budget(solver: &dyn Solver, paged: &PagedProblem) -> u64 {
    let tight = SolveOptions {
        memory_budget: 1,
        ..SolveOptions::default()
    };
    match solver.solve_paged(paged, &tight) {
        Err(SolveError::OverBudget { needed, .. }) => needed,
        other => panic!("a one-byte budget must be refused: {other:?}"),
    }
}

fn compare(
    what: &str,
    solver: &dyn Solver,
    dense: &Problem,
    paged: &PagedProblem,
    iterations: usize,
    tolerance: f64,
) -> StopReason {
    let options = SolveOptions {
        relative_tolerance: tolerance,
        max_iterations: iterations,
        ..SolveOptions::default()
    };
    let memory = solver.solve(dense, &options).unwrap();
    // The fewest pages (two slabs of state) plus four more.
    let least = least_budget(solver, paged);
    let [nx, ny, _] = paged.geometry().dims();
    let slab_bytes = |k: u64| k * (nx * ny * 8) as u64;
    let components = if solver.name() == "ftcs-p1" { 4 } else { 48 };
    let options = SolveOptions {
        memory_budget: least + slab_bytes(4 * components),
        ..options
    };
    let out = solver.solve_paged(paged, &options).unwrap();
    assert_eq!(out.report.stop_reason, memory.report.stop_reason, "{what}");
    assert_eq!(out.report.iterations, memory.report.iterations, "{what}");
    let bits = |r: &[f64]| r.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(
        bits(&out.report.residual_history),
        bits(&memory.report.residual_history),
        "{what}: residual history"
    );
    // Both record one relative change (P1) or residual per step, so the comparison above
    // compares something.
    assert!(
        !memory.report.residual_history.is_empty()
            && memory.report.residual_history.len() <= memory.report.iterations,
        "{what}: {} values over {} steps",
        memory.report.residual_history.len(),
        memory.report.iterations
    );
    assert_eq!(out.fluence.len(), memory.fluence.len(), "{what}");
    for (c, (p, m)) in out.fluence.iter().zip(&memory.fluence).enumerate() {
        let p = p.to_grid().unwrap();
        assert!(m.data().iter().any(|&v| v > 0.0), "{what}: lit");
        let same = p
            .data()
            .iter()
            .zip(m.data())
            .all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(same, "{what}: fluence, channel {c}");
    }
    let paging = out.report.paging.expect("paging counters");
    assert!(paging.evictions > 0, "{what}: {paging:?}");
    out.report.stop_reason
}

fn lights() -> Vec<Light> {
    vec![
        Light::Point {
            position: DVec3::new(0.52, 0.27, 0.73),
            intensity: Spectrum::Grey(1.0),
        },
        // In a cell on the box's faces.
        Light::Point {
            position: DVec3::new(0.02, 0.65, 1.35),
            intensity: Spectrum::Rgb([0.3, 1.0, 0.6]),
        },
    ]
}

#[test]
fn paged_p1_gives_the_in_memory_bits() {
    let constant = |v: f32| -> CellFn { Box::new(move |_| v) };
    for (layout, brick) in [("staggered", 4), ("collocated", 8)] {
        let (dense, paged) = problems(
            &[constant(6.0)],
            &[constant(0.8)],
            Phase::henyey_greenstein(0.4).unwrap(),
            &lights(),
            brick,
        );
        let layout = ParamValue::Text(layout.into());
        let solver = build(ExplicitSolver::FTCS_P1, &[("layout", layout.clone())]);
        compare(
            "P1 to the limit",
            solver.as_ref(),
            &dense,
            &paged,
            60,
            1e-12,
        );
        let converged = compare(
            "P1 to tolerance",
            solver.as_ref(),
            &dense,
            &paged,
            5000,
            1e-3,
        );
        assert!(converged.is_converged(), "{converged:?}");
        // Beyond the bound: the growth monitor stops both at the same step.
        let unstable = build(
            ExplicitSolver::FTCS_P1,
            &[
                ("layout", layout),
                ("step_fraction", ParamValue::Float(1.6)),
                ("allow_unstable", ParamValue::Bool(true)),
            ],
        );
        let diverged = compare(
            "P1 unstable",
            unstable.as_ref(),
            &dense,
            &paged,
            3000,
            1e-12,
        );
        assert!(
            matches!(diverged, StopReason::DivergedGrowth { .. }),
            "{diverged:?}"
        );
    }
}

#[test]
fn paged_ordinates_give_the_in_memory_bits() {
    // Clear at low x, touching the box elsewhere; RGB extinction.
    let medium = |scale: f32| -> CellFn {
        Box::new(move |p: DVec3| {
            if p.x < 0.25 {
                0.0
            } else {
                scale * (1.0 + 0.6 * ((8.0 * p.y).sin() * (5.0 * p.z).cos()) as f32).abs()
            }
        })
    };
    let albedo: CellFn = Box::new(|p: DVec3| (0.6 + 0.3 * p.z.clamp(0.0, 1.0)) as f32);
    for (order, brick) in [(2i64, 4), (6, 8)] {
        let (dense, paged) = problems(
            &[medium(4.0), medium(6.0), medium(9.0)],
            std::slice::from_ref(&albedo),
            Phase::Isotropic,
            &lights(),
            brick,
        );
        let solver = build(
            ExplicitSolver::FTCS_ORDINATES,
            &[("order", ParamValue::Int(order))],
        );
        compare(
            &format!("S{order} to the limit"),
            solver.as_ref(),
            &dense,
            &paged,
            40,
            1e-12,
        );
    }
}
