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
//!   and the same system by GMRES (the curve `fem-p1-jacobi solver=gmres`) over the stopping tolerance, against
//!   the uncollided fluence;
//! - `dom`: the level-symmetric order S2–S12 with diamond difference, and step and
//!   exponential closures at S8 (tolerance 1e-4), against the total fluence;
//! - `ftcs-diffusion`, `jacobi-diffusion`: the stopping tolerance; `convection-diffusion`:
//!   the characteristic and conservative models at 1× and 2× cells (against the uncollided
//!   fluence); `ftcs-p1` and `ftcs-ordinates` (S2, S4) where the scene's lights are point
//!   lights;
//! - `mc`: particles per batch (8 batches).
//!
//! The knobs live in one table, [`runs`]; a run whose solver does not admit the scene is
//! skipped.
//!
//! `cargo xtask pareto` writes `docs/pareto/<scene>.csv` (and draws its chart, `.svg`) (each run's error
//! against its own reference and against the total fluence), `auto`'s table
//! (`docs/pareto/auto.csv`, [`crate::auto::Table`]) and `auto`'s own runs on each scene
//! ([`measure_auto`]: with the scene's rows in the table, and with them left out), whose
//! table goes into `docs/validation.md`.

use std::path::Path;
use std::time::Instant;

use lucent_core::{FluenceKind, Params, Problem, SolveOptions, Solver};
use lucent_grid::Grid;
use lucent_grid::resample::restrict;

use crate::Error;
use crate::auto::{AutoSolver, Features, Measured, MeasuredScene, Table, csv_field};
use crate::crosscheck::{Reference, SuiteScene, compare, reference};

/// One measured point.
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    /// Solver name.
    pub solver: String,
    /// The knob setting, in words.
    pub setting: String,
    /// Wall time of the solve, seconds.
    pub seconds: f64,
    /// Relative L2 error against the reference for what the solver computes (uncollided
    /// or total fluence).
    pub error: f64,
    /// Relative L2 error against the total fluence (the same as `error` for solvers that
    /// compute it): what `auto` is asked to meet.
    pub error_total: f64,
}

/// The same medium on `factor` times as many cells per axis: every grid resampled
/// trilinearly at the finer cell centres ([`crate::resolution::on_grid`]), so that refining
/// converges to the scene's own (trilinear) medium instead of revealing new detail of a
/// procedural volume.
pub(crate) fn refined(scene: &SuiteScene, factor: usize) -> Result<Problem, Error> {
    let p = &scene.built.problem;
    if factor == 1 {
        return Ok(p.clone());
    }
    crate::resolution::on_grid(p, p.geometry().dims().map(|n| n * factor))
}

/// One run of the sweep: a solver, its parameters (as a scene's `[solver.params]` would
/// write them), the grid refinement and the options.
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    /// The curve it belongs to.
    pub label: &'static str,
    /// The registry name.
    pub solver: &'static str,
    /// Its parameters, in TOML.
    pub params: String,
    /// Cells per scene cell along each axis (the medium resampled, the result restricted
    /// back).
    pub factor: usize,
    /// Relative tolerance of the iteration (the default when `None`).
    pub tolerance: Option<f64>,
    /// Iteration limit (the default when `None`).
    pub max_iterations: Option<usize>,
    /// The knob setting, in words.
    pub setting: String,
}

impl Run {
    fn new(solver: &'static str, params: String, factor: usize, setting: String) -> Self {
        Self {
            label: solver,
            solver,
            params,
            factor,
            tolerance: None,
            max_iterations: None,
            setting,
        }
    }
}

impl Run {
    /// Its solver, built from `registry` with its parameters.
    pub fn solver(&self, registry: &lucent_core::Registry) -> Result<Box<dyn Solver>, Error> {
        let params: Params = toml::from_str(&self.params)
            .map_err(|e| Error::Invalid(format!("pareto parameters `{}`: {e}", self.params)))?;
        Ok(registry.build(self.solver, &params)?)
    }

    /// `base` with the run's iteration tolerance and limit where it sets them.
    pub fn options(&self, base: &SolveOptions) -> SolveOptions {
        SolveOptions {
            relative_tolerance: self.tolerance.unwrap_or(base.relative_tolerance),
            max_iterations: self.max_iterations.unwrap_or(base.max_iterations),
            ..base.clone()
        }
    }
}

/// Every solver's knobs, in one place: what `cargo xtask pareto` sweeps.
pub fn runs() -> Vec<Run> {
    let mut runs = Vec::new();
    // `direct`: resolution and sky quadrature.
    for factor in [1, 2] {
        for sky_level in [0, 1] {
            runs.push(Run::new(
                "direct",
                format!("sky_level = {sky_level}"),
                factor,
                format!("{factor}x cells, {} sky directions", 8 << (2 * sky_level)),
            ));
        }
    }
    // `direct-refractive`: the ray tracer's tolerance (on the suite's uniform index its rays
    // are straight: what the curved machinery costs over `direct`).
    for tolerance in ["1e-6", "1e-9"] {
        runs.push(Run::new(
            "direct-refractive",
            format!("tolerance = {tolerance}"),
            1,
            format!("ray tolerance {tolerance}"),
        ));
    }
    // Diffusion: every iterative method on the same operator, over the stopping tolerance
    // and (for the multigrid ones) the grid resolution. Its error against the total
    // fluence levels off at the diffusion model's own error.
    let diffusion: [(&str, &[usize], &[f64]); 6] = [
        ("diffusion-mg", &[1, 2], &[1e-2, 1e-4, 1e-8]),
        ("diffusion-mgcg", &[1, 2], &[1e-4, 1e-8]),
        ("diffusion-cg", &[1], &[1e-2, 1e-4, 1e-8]),
        ("diffusion-sor", &[1], &[1e-2, 1e-4]),
        ("diffusion-jacobi", &[1], &[1e-2]),
        ("fem-diffusion", &[1, 2], &[1e-4, 1e-8]),
    ];
    for (solver, factors, tolerances) in diffusion {
        for &factor in factors {
            for &tolerance in tolerances {
                runs.push(Run {
                    tolerance: Some(tolerance),
                    ..Run::new(
                        solver,
                        String::new(),
                        factor,
                        format!("{factor}x cells, tolerance {tolerance:.0e}"),
                    )
                });
            }
        }
    }
    // Discrete ordinates over the angular order (ray effects shrink as N grows) and, at
    // S8, the spatial closure.
    for (order, closure) in [
        (2, "diamond"),
        (4, "diamond"),
        (8, "diamond"),
        (12, "diamond"),
        (8, "step"),
        (8, "exponential"),
    ] {
        runs.push(Run {
            tolerance: Some(1e-4),
            ..Run::new(
                "dom",
                format!("order = {order}\nclosure = \"{closure}\""),
                1,
                format!("S{order} {closure}, tolerance 1e-4"),
            )
        });
    }
    // The hybrid: uncollided light exact, up to `orders` scattering orders by sweeps of
    // the S_N set, the rest by multigrid diffusion; the knobs are the orders and the set.
    for (order, orders) in [(4, 1), (4, 2), (4, 4), (4, 8), (8, 1), (8, 4)] {
        runs.push(Run {
            tolerance: Some(1e-4),
            ..Run::new(
                "hybrid",
                format!("order = {order}\norders = {orders}"),
                1,
                format!("S{order}, {orders} swept orders, tolerance 1e-4"),
            )
        });
    }
    // Lattice-Boltzmann: both lattices over the resolution and the stopping tolerance
    // (second order in h towards the diffusion model's error), and Geist's collision,
    // first order in h.
    for (lattice, collision, factors, tolerances) in [
        ("d3q7", "trt", &[1, 2][..], &[1e-3, 1e-6][..]),
        ("d3q19", "trt", &[1][..], &[1e-6][..]),
        ("d3q7", "geist", &[1, 2][..], &[1e-6][..]),
    ] {
        for &factor in factors {
            for &tolerance in tolerances {
                runs.push(Run {
                    tolerance: Some(tolerance),
                    ..Run::new(
                        "lbm",
                        format!("lattice = \"{lattice}\"\ncollision = \"{collision}\""),
                        factor,
                        format!(
                            "{lattice} {collision}, {factor}x cells, tolerance {tolerance:.0e}"
                        ),
                    )
                });
            }
        }
    }
    // Murray's finite elements by Jacobi: the error grows with every iteration (the
    // iteration matrix's spectral radius is ≥ 19/8); GMRES on the same system shows what
    // the Galerkin solution itself is worth (one tolerance: restarted GMRES stagnates on
    // this indefinite system at K_tΔ < 1, so tighter tolerances only cost time).
    for iterations in [1, 2, 4, 8] {
        runs.push(Run {
            max_iterations: Some(iterations),
            ..Run::new(
                "fem-p1-jacobi",
                String::new(),
                1,
                format!("{iterations} Jacobi iterations"),
            )
        });
    }
    runs.push(Run {
        label: "fem-p1-jacobi solver=gmres",
        tolerance: Some(1e-4),
        ..Run::new(
            "fem-p1-jacobi",
            "solver = \"gmres\"".into(),
            1,
            "GMRES to 1e-4".into(),
        )
    });
    // The explicit schemes: FTCS and Jacobi on diffusion-mg's discrete problem over the
    // stopping tolerance (their cost is the point), Zhang & Ma's convection per model and
    // resolution (against the uncollided fluence), Murray's P1 and ordinates by FTCS
    // (point lights only).
    for (solver, tolerances) in [
        ("ftcs-diffusion", &[1e-2, 1e-3][..]),
        ("jacobi-diffusion", &[1e-2][..]),
    ] {
        for &tolerance in tolerances {
            runs.push(Run {
                tolerance: Some(tolerance),
                ..Run::new(
                    solver,
                    String::new(),
                    1,
                    format!("tolerance {tolerance:.0e}"),
                )
            });
        }
    }
    for model in ["characteristic", "conservative"] {
        for factor in [1, 2] {
            runs.push(Run::new(
                "convection-diffusion",
                format!("model = \"{model}\""),
                factor,
                format!("{model}, {factor}x cells"),
            ));
        }
    }
    runs.push(Run {
        tolerance: Some(1e-4),
        ..Run::new("ftcs-p1", String::new(), 1, "tolerance 1e-4".into())
    });
    for order in [2, 4] {
        runs.push(Run {
            tolerance: Some(1e-4),
            ..Run::new(
                "ftcs-ordinates",
                format!("order = {order}"),
                1,
                format!("S{order}, tolerance 1e-4"),
            )
        });
    }
    // The GPU twins (f32 on the device): the same knobs as their CPU solvers, so each
    // curve lies on its twin's in error and shows the device's time.
    runs.push(Run::new(
        "gpu-direct",
        "sky_level = 1".into(),
        1,
        "1x cells, 32 sky directions".into(),
    ));
    for &tolerance in &[1e-2, 1e-3] {
        runs.push(Run {
            tolerance: Some(tolerance),
            ..Run::new(
                "gpu-ftcs-diffusion",
                String::new(),
                1,
                format!("tolerance {tolerance:.0e}"),
            )
        });
    }
    for &tolerance in &[1e-4, 1e-8] {
        runs.push(Run {
            tolerance: Some(tolerance),
            ..Run::new(
                "gpu-diffusion-mg",
                String::new(),
                1,
                format!("tolerance {tolerance:.0e}"),
            )
        });
    }
    for factor in [1, 2] {
        runs.push(Run::new(
            "gpu-convection-diffusion",
            String::new(),
            factor,
            format!("characteristic, {factor}x cells"),
        ));
    }
    runs.push(Run {
        tolerance: Some(1e-4),
        ..Run::new("gpu-ftcs-p1", String::new(), 1, "tolerance 1e-4".into())
    });
    for order in [4, 8] {
        runs.push(Run {
            tolerance: Some(1e-4),
            ..Run::new(
                "gpu-dom",
                format!("order = {order}"),
                1,
                format!("S{order} diamond, tolerance 1e-4"),
            )
        });
    }
    for &tolerance in &[1e-3, 1e-6] {
        runs.push(Run {
            tolerance: Some(tolerance),
            ..Run::new(
                "gpu-lbm",
                String::new(),
                1,
                format!("d3q7 trt, tolerance {tolerance:.0e}"),
            )
        });
    }
    // Monte Carlo: paths (8 batches).
    for particles in [1000, 4000, 16000, 64000] {
        runs.push(Run::new(
            "mc",
            format!("particles = {particles}\nbatches = 8"),
            1,
            format!("{} paths", particles * 8),
        ));
    }
    runs
}

/// A scene's sweep: the points and the total-fluence reference they were measured against.
#[derive(Debug, Clone)]
pub struct Sweep {
    /// One per run the scene admits, in [`runs`] order.
    pub points: Vec<Point>,
    /// The total fluence's reference.
    pub total: Reference,
}

/// Sweeps every [`runs`] entry the solver admits on `scene`, measuring each against the
/// reference for what its solver computes (uncollided or total fluence) and against the
/// total fluence.
pub fn sweep(scene: &SuiteScene, cache: Option<&Path>) -> Result<Sweep, Error> {
    let registry = crate::registry();
    let mut points = Vec::new();
    let uncollided = reference(scene, FluenceKind::Uncollided, 0.005, cache)?;
    let total = reference(scene, FluenceKind::Total, 0.01, cache)?;
    let mut problems: Vec<(usize, Problem)> = Vec::new();
    for run in runs() {
        let solver = run.solver(&registry)?;
        if !problems.iter().any(|(f, _)| *f == run.factor) {
            problems.push((run.factor, refined(scene, run.factor)?));
        }
        let problem = &problems.iter().find(|(f, _)| *f == run.factor).unwrap().1;
        if solver.admits(problem).is_err() {
            continue;
        }
        let options = run.options(&SolveOptions {
            time_budget: Some(std::time::Duration::from_secs(120)),
            ..SolveOptions::default()
        });
        let start = Instant::now();
        let solution = match solver.solve(problem, &options) {
            Err(e) if crate::device_missing(&e) => continue,
            other => other?,
        };
        let seconds = start.elapsed().as_secs_f64();
        let averaged: Vec<Grid> = solution
            .fluence
            .iter()
            .map(|g| {
                if run.factor == 2 {
                    restrict(g)
                } else {
                    g.clone()
                }
            })
            .collect();
        let error_total = compare(&averaged, &total).relative_l2;
        let error = match solver.capabilities().fluence {
            FluenceKind::Uncollided => compare(&averaged, &uncollided).relative_l2,
            FluenceKind::Total => error_total,
        };
        points.push(Point {
            solver: run.label.into(),
            setting: run.setting,
            seconds,
            error,
            error_total,
        });
    }
    Ok(Sweep { points, total })
}

/// The points of a pareto CSV ([`csv`]'s format, [`CSV_HEADER`] first).
pub fn parse_csv(text: &str) -> Result<Vec<Point>, String> {
    let bad = |line: &str| format!("not a pareto row: `{line}`");
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    if lines.next() != Some(CSV_HEADER) {
        return Err(bad("(header)"));
    }
    lines
        .map(|line| {
            let f = crate::auto::split_csv(line);
            let num = |i: usize| {
                f.get(i)
                    .and_then(|v| v.parse::<f64>().ok())
                    .ok_or_else(|| bad(line))
            };
            Ok(Point {
                solver: f[0].clone(),
                setting: f.get(1).cloned().ok_or_else(|| bad(line))?,
                seconds: num(2)?,
                error: num(3)?,
                error_total: num(4)?,
            })
        })
        .collect()
}

/// The hybrid against every single CPU solver on each scene (name and points): for each
/// of the hybrid's points, its error of the total fluence and the least error any other
/// CPU run reached in no more time. A point "beats" them when its error is below that
/// (or nothing else ran that fast); such a point lies on the scene's error-against-time
/// front, below every single solver's curve.
pub fn hybrid_markdown(scenes: &[(String, Vec<Point>)]) -> String {
    let single =
        |p: &Point| p.solver != "hybrid" && p.solver != "auto" && !p.solver.starts_with("gpu-");
    let mut out = String::from(
        "| scene | hybrid | time (s) | error | best single solver in no more time | its error | hybrid beats it |\n\
         |---|---|---|---|---|---|---|\n",
    );
    let mut summary = Vec::new();
    for (scene, points) in scenes {
        let mut hybrid: Vec<&Point> = points.iter().filter(|p| p.solver == "hybrid").collect();
        if hybrid.is_empty() {
            continue;
        }
        hybrid.sort_by(|a, b| a.seconds.total_cmp(&b.seconds));
        let mut beats = 0;
        for h in &hybrid {
            let best = points
                .iter()
                .filter(|p| single(p) && p.seconds <= h.seconds)
                .min_by(|a, b| a.error_total.total_cmp(&b.error_total));
            let wins = best.is_none_or(|b| h.error_total < b.error_total);
            beats += usize::from(wins);
            let (name, error) = match best {
                Some(b) => (
                    format!("{} ({})", b.solver, b.setting),
                    format!("{:.1}%", 100.0 * b.error_total),
                ),
                None => ("none ran that fast".into(), "–".into()),
            };
            out.push_str(&format!(
                "| {scene} | {} | {:.3} | {:.1}% | {name} | {error} | {} |\n",
                h.setting,
                h.seconds,
                100.0 * h.error_total,
                if wins { "yes" } else { "no" }
            ));
        }
        summary.push(format!("{scene}: {beats} of {}", hybrid.len()));
    }
    format!(
        "{out}\nPoints of the hybrid below every single CPU solver's curve: {}.\n",
        summary.join("; ")
    )
}

/// A sweep measured before: the points of `docs/pareto/<scene>.csv` in `dir`, with the
/// scene's total reference (from `cache` where it is there). What `cargo xtask pareto
/// --reuse` re-runs `auto` against when only `auto` or its features changed.
pub fn reuse(scene: &SuiteScene, dir: &Path, cache: Option<&Path>) -> Result<Sweep, Error> {
    let path = dir.join(format!("{}.csv", scene.name));
    let text = std::fs::read_to_string(&path).map_err(|e| Error::Io {
        path: path.clone(),
        reason: e.to_string(),
    })?;
    let points = parse_csv(&text).map_err(|reason| Error::Io {
        path: path.clone(),
        reason,
    })?;
    let total = reference(scene, FluenceKind::Total, 0.01, cache)?;
    Ok(Sweep { points, total })
}

/// `scene`'s entry in `auto`'s table: its regime and its measured points.
pub fn measured_scene(scene: &SuiteScene, points: &[Point]) -> MeasuredScene {
    let problem = &scene.built.problem;
    MeasuredScene {
        name: scene.name.clone(),
        cells: problem.geometry().voxel_count(),
        features: Features::of(problem),
        points: points
            .iter()
            .map(|p| Measured {
                label: p.solver.clone(),
                setting: p.setting.clone(),
                seconds: p.seconds,
                error_total: p.error_total,
            })
            .collect(),
    }
}

/// The tolerances `cargo xtask pareto` measures `auto` at: the two per cent, and a
/// looser and a tighter target around it.
pub const AUTO_TOLERANCES: [f64; 4] = [0.01, 0.02, 0.05, 0.2];

/// One measured run of `auto` on a suite scene.
#[derive(Debug, Clone, PartialEq)]
pub struct AutoPoint {
    /// The suite scene.
    pub scene: String,
    /// The tolerance asked for.
    pub tolerance: f64,
    /// Whether the table held the scene's own measurements (`false`: left out, so the
    /// choice came from the other scenes).
    pub own_rows: bool,
    /// The nearest scene it chose from.
    pub nearest: String,
    /// The run it chose, `label (setting)`.
    pub chose: String,
    /// Whether the chosen run was expected to meet the tolerance.
    pub expected_to_meet: bool,
    /// Its wall time, the choice included, seconds.
    pub seconds: f64,
    /// Its relative L2 error against the total fluence.
    pub error_total: f64,
    /// The fastest single run of the same sweep meeting the tolerance, `label (setting)`,
    /// and its time.
    pub fastest: Option<(String, f64)>,
    /// A scene outside the suite (`examples/scenes/mixed/`), never in the table.
    pub held_out: bool,
}

/// Runs `auto` on `scene` at each of `tolerances` with `table` (which should hold the
/// scene's rows from `sweep`) where `own_rows` holds `true`, and with the scene's rows left
/// out where it holds `false`, each measured against the sweep's total reference; with its
/// own rows, `auto` and the sweep's fastest single run meeting the tolerance are timed
/// [`REPEATS`] times in turn and the least time of each is kept (the single run's sweep
/// time counting as one more).
pub fn measure_auto(
    scene: &SuiteScene,
    table: &Table,
    sweep: &Sweep,
    tolerances: &[f64],
    own_rows: &[bool],
) -> Result<Vec<AutoPoint>, Error> {
    let problem = &scene.built.problem;
    let registry = crate::registry();
    let all = runs();
    let mut out = Vec::new();
    for &tolerance in tolerances {
        let fastest = sweep
            .points
            .iter()
            .filter(|p| p.error_total <= tolerance)
            .min_by(|a, b| a.seconds.total_cmp(&b.seconds));
        // The fastest single run again, as the sweep ran it (its refined problem made
        // outside the timing), to be timed beside `auto`.
        let single = match fastest {
            Some(p) => {
                let run = all
                    .iter()
                    .find(|r| r.label == p.solver && r.setting == p.setting)
                    .ok_or_else(|| Error::Invalid(format!("no run {}", p.solver)))?;
                let options = run.options(&SolveOptions::default());
                Some((
                    p,
                    run.solver(&registry)?,
                    refined(scene, run.factor)?,
                    options,
                ))
            }
            None => None,
        };
        for &own_rows in own_rows {
            let table = if own_rows {
                table.clone()
            } else {
                table.without(&scene.name)
            };
            if table.scenes.is_empty() {
                continue;
            }
            let auto = AutoSolver::with_table(tolerance, table);
            if let Err(e) = auto.choose(problem, None) {
                // Left out, the nearest other scene's solvers may all refuse this one.
                if own_rows {
                    return Err(e.into());
                }
                eprintln!("pareto: {}: auto without its rows: {e}", scene.name);
                continue;
            }
            let options = SolveOptions {
                time_budget: Some(std::time::Duration::from_secs(120)),
                ..SolveOptions::default()
            };
            // Timed REPEATS times each, `auto` and the fastest single run in turn, and the
            // least of each taken: on a shared two-core machine a millisecond solve's
            // single timing varies by tens of per cent.
            let (mut seconds, mut single_seconds) = (f64::INFINITY, fastest.map(|p| p.seconds));
            let mut error_total = f64::NAN;
            let mut ran = None;
            let repeats = REPEATS;
            for _ in 0..repeats {
                let start = Instant::now();
                let (solution, choice) = match auto.solve_with_choice(problem, &options) {
                    Err(e) if crate::device_missing(&e) => break,
                    other => other?,
                };
                seconds = seconds.min(start.elapsed().as_secs_f64());
                ran = Some(choice);
                error_total = compare(&solution.fluence, &sweep.total).relative_l2;
                if let Some((_, solver, fine, run_options)) = &single {
                    let start = Instant::now();
                    solver.solve(fine, run_options)?;
                    let t = start.elapsed().as_secs_f64();
                    single_seconds = single_seconds.map(|s| s.min(t));
                }
            }
            let Some(choice) = ran.filter(|_| seconds.is_finite()) else {
                continue;
            };
            out.push(AutoPoint {
                scene: scene.name.clone(),
                tolerance,
                own_rows,
                nearest: choice.nearest().to_owned(),
                chose: format!("{} ({})", choice.run.label, choice.run.setting),
                expected_to_meet: choice.meets,
                seconds,
                error_total,
                fastest: fastest
                    .zip(single_seconds)
                    .map(|(p, t)| (format!("{} ({})", p.solver, p.setting), t)),
                held_out: false,
            });
        }
    }
    Ok(out)
}

/// How many times [`measure_auto`] times `auto` and the fastest single run beside it.
pub const REPEATS: usize = 3;

/// The header of `docs/pareto/auto_runs.csv`.
pub const AUTO_RUNS_HEADER: &str = "scene,tolerance,own_rows,nearest,chose,expected_to_meet,seconds,error_total,fastest,fastest_seconds,held_out";

/// `auto`'s measured runs as CSV.
pub fn auto_csv(points: &[AutoPoint]) -> String {
    let mut out = format!("{AUTO_RUNS_HEADER}\n");
    for p in points {
        let (fastest, fastest_seconds) = match &p.fastest {
            Some((f, s)) => (f.as_str(), format!("{s:.6}")),
            None => ("", String::new()),
        };
        out.push_str(&format!(
            "{},{},{},{},{},{},{:.6},{:.6},{},{},{}\n",
            p.scene,
            p.tolerance,
            p.own_rows,
            p.nearest,
            csv_field(&p.chose),
            p.expected_to_meet,
            p.seconds,
            p.error_total,
            csv_field(fastest),
            fastest_seconds,
            p.held_out
        ));
    }
    out
}

/// Parses [`auto_csv`]'s output.
pub fn parse_auto_csv(text: &str) -> Result<Vec<AutoPoint>, String> {
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    // The header before the `held_out` column is read too (its rows are the suite's).
    let header = lines.next().map(str::trim);
    if header != Some(AUTO_RUNS_HEADER) && header != AUTO_RUNS_HEADER.strip_suffix(",held_out") {
        return Err("auto_runs.csv: unexpected header".into());
    }
    lines
        .enumerate()
        .map(|(n, line)| {
            let f = crate::auto::split_csv(line);
            let bad = || format!("auto_runs.csv row {}: `{line}`", n + 2);
            if f.len() != 10 && f.len() != 11 {
                return Err(bad());
            }
            let num = |i: usize| f[i].parse::<f64>().map_err(|_| bad());
            Ok(AutoPoint {
                scene: f[0].clone(),
                tolerance: num(1)?,
                own_rows: f[2] == "true",
                nearest: f[3].clone(),
                chose: f[4].clone(),
                expected_to_meet: f[5] == "true",
                seconds: num(6)?,
                error_total: num(7)?,
                fastest: if f[8].is_empty() {
                    None
                } else {
                    Some((f[8].clone(), num(9)?))
                },
                held_out: f.get(10).is_some_and(|v| v == "true"),
            })
        })
        .collect()
}

/// Whether an `auto` run met its tolerance, in the tables' words.
fn verdict(p: &AutoPoint) -> &'static str {
    if p.error_total <= p.tolerance {
        "yes"
    } else if p.expected_to_meet {
        "**no**"
    } else {
        "no (said so)"
    }
}

/// The markdown table of `auto`'s runs for `docs/validation.md`: per scene and tolerance,
/// what it chose with the scene's own rows and without them, its error and its time over
/// the fastest single solver meeting the tolerance in the same sweep.
pub fn auto_markdown(points: &[AutoPoint]) -> String {
    let pct = |v: f64| format!("{:.2}%", 100.0 * v);
    let mut s = String::from(
        "| scene | tolerance | auto chose | its error | meets | auto time | fastest single meeting it | its time | ratio | left out: chose (nearest) | its error | meets |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for own in points.iter().filter(|p| p.own_rows && !p.held_out) {
        let out = points.iter().find(|p| {
            !p.own_rows && !p.held_out && p.scene == own.scene && p.tolerance == own.tolerance
        });
        let (fastest, fastest_time, ratio) = match &own.fastest {
            Some((f, t)) => (
                f.clone(),
                format!("{t:.3} s"),
                format!("{:.2}", own.seconds / t.max(1e-9)),
            ),
            None => ("none meets it".into(), "–".into(), "–".into()),
        };
        let (out_chose, out_error, out_meets) = match out {
            Some(o) => (
                format!("{} ({})", o.chose, o.nearest),
                pct(o.error_total),
                verdict(o),
            ),
            None => ("–".into(), "–".into(), "–"),
        };
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} | {:.3} s | {} | {} | {} | {} | {} | {} |\n",
            own.scene,
            pct(own.tolerance),
            own.chose,
            pct(own.error_total),
            verdict(own),
            own.seconds,
            fastest,
            fastest_time,
            ratio,
            out_chose,
            out_error,
            out_meets
        ));
    }
    let held: Vec<&AutoPoint> = points.iter().filter(|p| p.held_out).collect();
    if !held.is_empty() {
        s.push_str(
            "\n### Held-out scenes of mixed regime (`examples/scenes/mixed/`, never in the table)\n\n\
             | scene | tolerance | auto chose (nearest scene) | its error | meets | auto time | fastest single meeting it | its time | ratio |\n\
             |---|---|---|---|---|---|---|---|---|\n",
        );
        for p in held {
            let (fastest, fastest_time, ratio) = match &p.fastest {
                Some((f, t)) => (
                    f.clone(),
                    format!("{t:.3} s"),
                    format!("{:.2}", p.seconds / t.max(1e-9)),
                ),
                None => ("none meets it".into(), "–".into(), "–".into()),
            };
            s.push_str(&format!(
                "| {} | {} | {} ({}) | {} | {} | {:.3} s | {} | {} | {} |\n",
                p.scene,
                pct(p.tolerance),
                p.chose,
                p.nearest,
                pct(p.error_total),
                verdict(p),
                p.seconds,
                fastest,
                fastest_time,
                ratio
            ));
        }
    }
    s
}

/// The header of `docs/pareto/<scene>.csv`.
pub const CSV_HEADER: &str = "solver,setting,seconds,relative_l2,relative_l2_total";

/// The points as CSV.
pub fn csv(points: &[Point]) -> String {
    let mut out = format!("{CSV_HEADER}\n");
    for p in points {
        out.push_str(&format!(
            "{},{},{:.6},{:.6},{:.6}\n",
            p.solver,
            crate::auto::csv_field(&p.setting),
            p.seconds,
            p.error,
            p.error_total
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hybrid point beats the single solvers when its error is below the least any of
    /// them reached in no more time (GPU twins and `auto` are not single CPU solvers); the
    /// CSV round-trips.
    #[test]
    fn the_hybrid_table_compares_with_the_best_single_run_in_no_more_time() {
        let point = |solver: &str, setting: &str, seconds: f64, error: f64| Point {
            solver: solver.into(),
            setting: setting.into(),
            seconds,
            error,
            error_total: error,
        };
        let points = vec![
            point("mc", "8000 paths", 0.05, 0.10),
            point("dom", "S4, diamond", 0.2, 0.02),
            point("gpu-dom", "S4", 0.01, 0.001),
            point("auto", "2%", 0.01, 0.001),
            point("hybrid", "S4, 1 swept orders", 0.1, 0.05),
            point("hybrid", "S4, 8 swept orders", 0.3, 0.03),
            point("hybrid", "S2, 1 swept orders", 0.01, 0.5),
        ];
        let parsed = parse_csv(&csv(&points)).unwrap();
        assert_eq!(parsed, points);
        let table = hybrid_markdown(&[("layers".into(), points)]);
        let row = |setting: &str| {
            table
                .lines()
                .find(|l| l.contains(setting))
                .unwrap_or_else(|| panic!("{setting}: {table}"))
                .to_owned()
        };
        // Only mc ran within 0.1 s: 5% beats its 10%.
        assert!(
            row("1 swept orders | 0.100").ends_with("| yes |"),
            "{table}"
        );
        assert!(row("1 swept orders | 0.100").contains("mc (8000 paths)"));
        // dom's 2% in 0.2 s beats 3% in 0.3 s.
        assert!(row("8 swept orders").ends_with("| no |"), "{table}");
        // Nothing single ran in 0.01 s (the GPU twin and auto do not count).
        assert!(row("S2").contains("none ran that fast"), "{table}");
        assert!(table.contains("layers: 2 of 3"), "{table}");
    }

    /// Every knob in the table is a parameter its solver takes, with a valid value, and
    /// every registered solver is charted.
    #[test]
    fn every_run_builds_its_solver() {
        let registry = crate::registry();
        for entry in registry.entries().iter().filter(|e| e.name != "auto") {
            assert!(
                runs().iter().any(|r| r.solver == entry.name),
                "{} has no run",
                entry.name
            );
        }
        // `auto`'s table names a run by its curve and setting: they must name one run.
        let all = runs();
        for (i, a) in all.iter().enumerate() {
            assert!(
                !all[..i]
                    .iter()
                    .any(|b| b.label == a.label && b.setting == a.setting),
                "{} ({}) twice",
                a.label,
                a.setting
            );
        }
        for run in runs() {
            let params: Params = toml::from_str(&run.params).unwrap();
            assert!(
                registry.build(run.solver, &params).is_ok(),
                "{} `{}`",
                run.solver,
                run.params
            );
        }
    }
}
