//! Error against time: each solver swept over its accuracy knobs on a suite scene, its
//! error measured against the reference for what it computes, charted log-log.
//!
//! - `direct`: grid resolution (1× and 2× the scene's: the medium resampled trilinearly, so
//!   that it is the same medium, and the fine solution averaged back onto the scene's cells,
//!   so that cell averages are compared with cell averages) and the sky quadrature (8 and
//!   32 directions);
//! - `diffusion-*` and `fem-diffusion`: the stopping tolerance, and 1× and 2× cells for the
//!   multigrid methods
//!   (against the total fluence: the curves flatten at the diffusion model's error);
//! - `fem-p1-jacobi`: the Jacobi iteration count (its error grows: the method diverges),
//!   and the same system by GMRES (`fem-p1-gmres`) over the stopping tolerance, against
//!   the uncollided fluence;
//! - `dom`: the level-symmetric order S2–S12 with diamond difference, and step and
//!   exponential closures at S8 (tolerance 1e-4), against the total fluence;
//! - `mc`: particles per batch (8 batches).
//!
//! `cargo xtask pareto` writes `docs/pareto/<scene>.svg` and `.csv`.

use std::path::Path;
use std::time::Instant;

use lucent_core::{FluenceKind, Light, ParamValue, Params, Problem, SolveOptions};
use lucent_grid::Grid;
use lucent_grid::resample::{resample, restrict};

use crate::Error;
use crate::crosscheck::{SuiteScene, compare, reference};

/// One measured point.
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    /// Solver name.
    pub solver: String,
    /// The knob setting, in words.
    pub setting: String,
    /// Wall time of the solve, seconds.
    pub seconds: f64,
    /// Relative L2 error against the reference.
    pub error: f64,
}

fn params(pairs: &[(&str, i64)]) -> Params {
    Params(
        pairs
            .iter()
            .map(|(k, v)| ((*k).to_owned(), ParamValue::Int(*v)))
            .collect(),
    )
}

fn params_text(pairs: &[(&str, &str)]) -> Params {
    Params(
        pairs
            .iter()
            .map(|(k, v)| ((*k).to_owned(), ParamValue::Text((*v).to_owned())))
            .collect(),
    )
}

/// The same medium on `factor` times as many cells per axis: every grid resampled
/// trilinearly at the finer cell centres, so that refining converges to the scene's own
/// (trilinear) medium instead of revealing new detail of a procedural volume.
fn refined(scene: &SuiteScene, factor: usize) -> Result<Problem, Error> {
    let p = &scene.built.problem;
    let fine = p.geometry().dims().map(|n| n * factor);
    let up = |g: &Grid| {
        if factor == 1 {
            Ok(g.clone())
        } else {
            resample(g, fine)
        }
    };
    let medium = if factor == 1 {
        p.medium().clone()
    } else {
        p.medium().resampled(fine)?
    };
    let lights = p
        .lights()
        .iter()
        .map(|l| match l {
            Light::Emission { grid, scale } => up(grid).map(|grid| Light::Emission {
                grid,
                scale: *scale,
            }),
            other => Ok(other.clone()),
        })
        .collect::<Result<_, _>>()?;
    // The embedded body's SDF too: without it the medium would fill the box.
    let embedded = p.embedded().map(up).transpose()?;
    let geometry = *medium.sigma_t[0].geometry();
    Ok(Problem::new(
        geometry,
        medium,
        lights,
        p.boundary(),
        embedded,
    )?)
}

/// Sweeps `direct` and `mc` on `scene`.
pub fn sweep(scene: &SuiteScene, cache: Option<&Path>) -> Result<Vec<Point>, Error> {
    let registry = crate::registry();
    let mut points = Vec::new();
    let uncollided = reference(scene, FluenceKind::Uncollided, 0.005, cache)?;
    let total = reference(scene, FluenceKind::Total, 0.01, cache)?;
    for factor in [1usize, 2] {
        let problem = refined(scene, factor)?;
        for sky_level in [0i64, 1] {
            let solver = registry.build("direct", &params(&[("sky_level", sky_level)]))?;
            if solver.capabilities().check("direct", &problem).is_err() {
                continue;
            }
            let start = Instant::now();
            let solution = solver.solve(&problem, &SolveOptions::default())?;
            let seconds = start.elapsed().as_secs_f64();
            let averaged: Vec<Grid> = solution
                .fluence
                .iter()
                .map(|g| if factor == 2 { restrict(g) } else { g.clone() })
                .collect();
            points.push(Point {
                solver: "direct".into(),
                setting: format!("{factor}x cells, {} sky directions", 8 << (2 * sky_level)),
                seconds,
                error: compare(&averaged, &uncollided).relative_l2,
            });
        }
    }
    // Diffusion: every iterative method on the same operator, over the stopping tolerance
    // and (for the multigrid ones) the grid resolution. Its error against the total
    // fluence levels off at the diffusion model's own error.
    let diffusion_runs: [(&str, &[usize], &[f64]); 6] = [
        ("diffusion-mg", &[1, 2], &[1e-2, 1e-4, 1e-8]),
        ("diffusion-mgcg", &[1, 2], &[1e-4, 1e-8]),
        ("diffusion-cg", &[1], &[1e-2, 1e-4, 1e-8]),
        ("diffusion-sor", &[1], &[1e-2, 1e-4]),
        ("diffusion-jacobi", &[1], &[1e-2]),
        ("fem-diffusion", &[1, 2], &[1e-4, 1e-8]),
    ];
    for (name, factors, tolerances) in diffusion_runs {
        let solver = registry.build(name, &Params::default())?;
        if solver
            .capabilities()
            .check(name, &scene.built.problem)
            .is_err()
        {
            continue;
        }
        for &factor in factors {
            // Q1 elements need cubic cells; skip scenes without them.
            let h = scene.built.problem.geometry().spacing();
            if name == "fem-diffusion"
                && ((h.x - h.y).abs() > 1e-9 * h.x || (h.x - h.z).abs() > 1e-9 * h.x)
            {
                continue;
            }
            let problem = refined(scene, factor)?;
            for &relative_tolerance in tolerances {
                let options = SolveOptions {
                    relative_tolerance,
                    time_budget: Some(std::time::Duration::from_secs(60)),
                    ..SolveOptions::default()
                };
                let start = Instant::now();
                let solution = solver.solve(&problem, &options)?;
                let seconds = start.elapsed().as_secs_f64();
                let averaged: Vec<Grid> = solution
                    .fluence
                    .iter()
                    .map(|g| if factor == 2 { restrict(g) } else { g.clone() })
                    .collect();
                points.push(Point {
                    solver: name.into(),
                    setting: format!("{factor}x cells, tolerance {relative_tolerance:.0e}"),
                    seconds,
                    error: compare(&averaged, &total).relative_l2,
                });
            }
        }
    }
    // Discrete ordinates over the angular order (ray effects shrink as N grows) and, at
    // S8, the spatial closure.
    let dom_runs: [(i64, &str); 6] = [
        (2, "diamond"),
        (4, "diamond"),
        (8, "diamond"),
        (12, "diamond"),
        (8, "step"),
        (8, "exponential"),
    ];
    for (order, closure) in dom_runs {
        let mut params = params(&[("order", order)]);
        params
            .0
            .insert("closure".into(), ParamValue::Text(closure.into()));
        let solver = registry.build("dom", &params)?;
        if solver
            .capabilities()
            .check("dom", &scene.built.problem)
            .is_err()
        {
            break;
        }
        let options = SolveOptions {
            relative_tolerance: 1e-4,
            time_budget: Some(std::time::Duration::from_secs(120)),
            ..SolveOptions::default()
        };
        let start = Instant::now();
        let solution = solver.solve(&scene.built.problem, &options)?;
        points.push(Point {
            solver: "dom".into(),
            setting: format!("S{order} {closure}, tolerance 1e-4"),
            seconds: start.elapsed().as_secs_f64(),
            error: compare(&solution.fluence, &total).relative_l2,
        });
    }
    // Murray's finite elements by Jacobi: the error grows with every iteration (the
    // iteration matrix's spectral radius is ≥ 19/8); GMRES on the same system shows what
    // the Galerkin solution itself is worth.
    let murray = registry.build("fem-p1-jacobi", &Params::default())?;
    if murray
        .capabilities()
        .check("fem-p1-jacobi", &scene.built.problem)
        .is_ok()
    {
        for iterations in [1usize, 2, 4, 8] {
            let options = SolveOptions {
                max_iterations: iterations,
                ..SolveOptions::default()
            };
            let start = Instant::now();
            let solution = murray.solve(&scene.built.problem, &options)?;
            points.push(Point {
                solver: "fem-p1-jacobi".into(),
                setting: format!("{iterations} Jacobi iterations"),
                seconds: start.elapsed().as_secs_f64(),
                error: compare(&solution.fluence, &uncollided).relative_l2,
            });
        }
        let gmres = registry.build("fem-p1-jacobi", &params_text(&[("solver", "gmres")]))?;
        // One tolerance: restarted GMRES stagnates on this indefinite system at
        // K_tΔ < 1, so tighter tolerances only cost time (14 s each at 16³).
        let options = SolveOptions {
            relative_tolerance: 1e-4,
            ..SolveOptions::default()
        };
        let start = Instant::now();
        let solution = gmres.solve(&scene.built.problem, &options)?;
        points.push(Point {
            solver: "fem-p1-gmres".into(),
            setting: "GMRES to 1e-4".into(),
            seconds: start.elapsed().as_secs_f64(),
            error: compare(&solution.fluence, &uncollided).relative_l2,
        });
    }
    for particles in [1000i64, 4000, 16000, 64000] {
        let solver = registry.build("mc", &params(&[("particles", particles), ("batches", 8)]))?;
        if solver
            .capabilities()
            .check("mc", &scene.built.problem)
            .is_err()
        {
            continue;
        }
        let start = Instant::now();
        let solution = solver.solve(&scene.built.problem, &SolveOptions::default())?;
        points.push(Point {
            solver: "mc".into(),
            setting: format!("{} paths", particles * 8),
            seconds: start.elapsed().as_secs_f64(),
            error: compare(&solution.fluence, &total).relative_l2,
        });
    }
    Ok(points)
}

/// The points as CSV.
pub fn csv(points: &[Point]) -> String {
    let mut out = String::from("solver,setting,seconds,relative_l2\n");
    for p in points {
        out.push_str(&format!(
            "{},{},{:.6},{:.6}\n",
            p.solver, p.setting, p.seconds, p.error
        ));
    }
    out
}

/// A log-log chart of error against time, one curve per solver, as SVG.
pub fn svg(title: &str, points: &[Point]) -> String {
    let (w, h) = (640.0, 420.0);
    let (left, right, top, bottom) = (70.0, 150.0, 40.0, 50.0);
    let lg = |v: f64| v.max(1e-12).log10();
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for p in points {
        x0 = x0.min(lg(p.seconds));
        x1 = x1.max(lg(p.seconds));
        y0 = y0.min(lg(p.error));
        y1 = y1.max(lg(p.error));
    }
    if !x0.is_finite() {
        (x0, x1, y0, y1) = (-3.0, 0.0, -3.0, 0.0);
    }
    let (x0, x1, y0, y1) = (
        x0.floor(),
        x1.ceil().max(x0.floor() + 1.0),
        y0.floor(),
        y1.ceil().max(y0.floor() + 1.0),
    );
    let px = |v: f64| left + (lg(v) - x0) / (x1 - x0) * (w - left - right);
    let py = |v: f64| h - bottom - (lg(v) - y0) / (y1 - y0) * (h - top - bottom);
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" font-family=\"sans-serif\" font-size=\"12\">\n\
         <rect width=\"{w}\" height=\"{h}\" fill=\"white\"/>\n<text x=\"{}\" y=\"22\" text-anchor=\"middle\" font-size=\"15\">{title}</text>\n",
        (left + w - right) / 2.0
    );
    for d in (x0 as i32)..=(x1 as i32) {
        let x = px(10f64.powi(d));
        s.push_str(&format!(
            "<line x1=\"{x}\" y1=\"{top}\" x2=\"{x}\" y2=\"{}\" stroke=\"#ddd\"/><text x=\"{x}\" y=\"{}\" text-anchor=\"middle\">1e{d}</text>\n",
            h - bottom,
            h - bottom + 16.0
        ));
    }
    for d in (y0 as i32)..=(y1 as i32) {
        let y = py(10f64.powi(d));
        s.push_str(&format!(
            "<line x1=\"{left}\" y1=\"{y}\" x2=\"{}\" y2=\"{y}\" stroke=\"#ddd\"/><text x=\"{}\" y=\"{}\" text-anchor=\"end\">1e{d}</text>\n",
            w - right,
            left - 6.0,
            y + 4.0
        ));
    }
    s.push_str(&format!(
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">wall time (s)</text>\n<text x=\"16\" y=\"{}\" text-anchor=\"middle\" transform=\"rotate(-90 16 {})\">relative L2 error</text>\n",
        (left + w - right) / 2.0,
        h - 12.0,
        (top + h - bottom) / 2.0,
        (top + h - bottom) / 2.0
    ));
    let colours = [
        "#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf",
    ];
    let mut solvers: Vec<&str> = points.iter().map(|p| p.solver.as_str()).collect();
    solvers.dedup();
    for (i, solver) in solvers.iter().enumerate() {
        let colour = colours[i % colours.len()];
        let mut curve: Vec<&Point> = points.iter().filter(|p| p.solver == *solver).collect();
        curve.sort_by(|a, b| a.seconds.total_cmp(&b.seconds));
        let path: Vec<String> = curve
            .iter()
            .map(|p| format!("{:.1},{:.1}", px(p.seconds), py(p.error)))
            .collect();
        s.push_str(&format!(
            "<polyline points=\"{}\" fill=\"none\" stroke=\"{colour}\" stroke-width=\"2\"/>\n",
            path.join(" ")
        ));
        for p in &curve {
            s.push_str(&format!(
                "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"4\" fill=\"{colour}\"><title>{}: {} ({:.3} s, {:.2}%)</title></circle>\n",
                px(p.seconds),
                py(p.error),
                p.solver,
                p.setting,
                p.seconds,
                100.0 * p.error
            ));
        }
        let label = if *solver == "direct" {
            "direct (uncollided)"
        } else {
            solver
        };
        let ly = top + 20.0 + 20.0 * i as f64;
        s.push_str(&format!(
            "<line x1=\"{}\" y1=\"{ly}\" x2=\"{}\" y2=\"{ly}\" stroke=\"{colour}\" stroke-width=\"3\"/><text x=\"{}\" y=\"{}\">{label}</text>\n",
            w - right + 10.0,
            w - right + 30.0,
            w - right + 36.0,
            ly + 4.0
        ));
    }
    s.push_str("</svg>\n");
    s
}
