//! What every registered solver promises through the registry, checked solver by solver on
//! a small problem each can take: it reports progress as it goes, a time budget stops it
//! with `TimeLimit` and a finite field, and its result does not depend on the thread count.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use glam::DVec3;
use lucent::core::{
    Boundary, Field, Light, Medium, ParamValue, Params, Problem, Progress, SolveOptions, Spectrum,
    StopReason,
};
use lucent::grid::{Grid, GridGeometry};
use lucent::optics::Phase;

/// A small problem the solver can take: a blob lit by a sun (or, for the solvers that take
/// only point lights, a point light inside it), vacuum boundaries.
fn problem_for(name: &str) -> Problem {
    let n = 12;
    let geometry =
        GridGeometry::from_bounds([n; 3], DVec3::splat(-1.0), DVec3::splat(1.0)).unwrap();
    let point_only = matches!(
        name,
        "ftcs-p1" | "gpu-ftcs-p1" | "ftcs-ordinates" | "fem-p1-jacobi"
    );
    let homogeneous = point_only;
    let sigma_t = if homogeneous {
        Grid::filled(geometry, 4.0)
    } else {
        Grid::from_fn(geometry, |x| {
            (1.0 + 6.0 * (-2.0 * x.length_squared()).exp()) as f32
        })
    };
    let albedo = if name == "fem-p1-jacobi" { 0.0 } else { 0.8 };
    let medium = Medium {
        sigma_t: vec![sigma_t],
        albedo: vec![Field::Constant(albedo)],
        phase: Phase::Isotropic,
    };
    let light = if point_only {
        Light::Point {
            position: DVec3::new(0.05, -0.04, 0.03),
            intensity: Spectrum::Grey(1.0),
        }
    } else {
        Light::Directional {
            direction: DVec3::new(-0.3, -0.4, -0.8).normalize(),
            irradiance: Spectrum::Grey(1.0),
        }
    };
    Problem::new(geometry, medium, vec![light], Boundary::Vacuum, None).unwrap()
}

/// Cheap parameters where a solver's defaults would take long on every test run.
fn params_for(name: &str) -> Params {
    let mut p = Params::default();
    if name == "mc" {
        p.0.insert("particles".into(), ParamValue::Int(2000));
        p.0.insert("batches".into(), ParamValue::Int(4));
    }
    p
}

/// Every registered solver; the GPU backends only where an adapter exists (outside CI a
/// machine without one skips them; under `CI=true` they stay and fail).
fn names() -> Vec<String> {
    let ci = std::env::var("CI").is_ok_and(|v| v == "true" || v == "1");
    let gpu = ci || lucent::gpu::GpuContext::shared().is_ok();
    lucent::registry()
        .entries()
        .iter()
        .map(|e| e.name.to_owned())
        .filter(|name| gpu || !name.starts_with("gpu-"))
        .collect()
}

#[test]
fn every_solver_reports_progress() {
    for name in names() {
        let problem = problem_for(&name);
        let solver = lucent::registry().build(&name, &params_for(&name)).unwrap();
        let calls = Arc::new(AtomicUsize::new(0));
        let seen = Arc::clone(&calls);
        let options = SolveOptions {
            progress: Some(Arc::new(move |_: Progress| {
                seen.fetch_add(1, Ordering::Relaxed);
            })),
            ..SolveOptions::default()
        };
        let solution = solver.solve(&problem, &options).unwrap();
        let calls = calls.load(Ordering::Relaxed);
        // At least one call per iteration of an iterative solver, at least one in all.
        assert!(
            calls >= 1 && calls >= solution.report.iterations,
            "{name}: {calls} progress calls for {} iterations",
            solution.report.iterations
        );
    }
}

#[test]
fn every_solver_stops_at_its_time_budget_with_a_finite_field() {
    for name in names() {
        let problem = problem_for(&name);
        let solver = lucent::registry().build(&name, &params_for(&name)).unwrap();
        let options = SolveOptions {
            time_budget: Some(Duration::ZERO),
            relative_tolerance: 1e-12,
            ..SolveOptions::default()
        };
        // Stopped before any result existed (in set-up): the error says so.
        let solution = match solver.solve(&problem, &options) {
            Err(lucent::core::SolveError::Halted {
                halt: lucent::core::Halt::TimeLimit,
                ..
            }) => continue,
            other => other.unwrap(),
        };
        let finite = solution
            .fluence
            .iter()
            .all(|g| g.data().iter().all(|v| v.is_finite()));
        assert!(finite, "{name}: a non-finite field");
        // Exact methods finish; everything that iterates stops at the budget (or diverges
        // first, as Murray's Jacobi must).
        assert!(
            matches!(
                solution.report.stop_reason,
                StopReason::TimeLimit { .. }
                    | StopReason::Exact
                    | StopReason::DivergedGrowth { .. }
            ),
            "{name}: {:?}",
            solution.report.stop_reason
        );
    }
}

/// A Ctrl-C (the caller's cancel flag) stops every iterative solver at its next check with
/// what it has, reported as interrupted (or, stopped in set-up before anything existed,
/// `SolveError::Halted`); the field is finite.
#[test]
fn every_solver_stops_when_interrupted_with_a_finite_field() {
    for name in names() {
        let problem = problem_for(&name);
        let solver = lucent::registry().build(&name, &params_for(&name)).unwrap();
        let options = SolveOptions {
            cancel: Some(Arc::new(std::sync::atomic::AtomicBool::new(true))),
            relative_tolerance: 1e-12,
            ..SolveOptions::default()
        };
        // Stopped before any result existed (in set-up): the error says so.
        let solution = match solver.solve(&problem, &options) {
            Err(lucent::core::SolveError::Halted {
                halt: lucent::core::Halt::Interrupted,
                ..
            }) => continue,
            other => other.unwrap(),
        };
        assert!(
            solution
                .fluence
                .iter()
                .all(|g| g.data().iter().all(|v| v.is_finite())),
            "{name}: a non-finite field"
        );
        assert!(
            matches!(
                solution.report.stop_reason,
                StopReason::Interrupted { .. }
                    | StopReason::Exact
                    | StopReason::DivergedGrowth { .. }
            ),
            "{name}: {:?}",
            solution.report.stop_reason
        );
    }
}

#[test]
fn every_solver_gives_the_same_result_on_one_and_two_threads() {
    let log = Mutex::new(Vec::new());
    for name in names() {
        let problem = problem_for(&name);
        let solver = lucent::registry().build(&name, &params_for(&name)).unwrap();
        let run = |threads| {
            let options = SolveOptions {
                threads: Some(threads),
                ..SolveOptions::default()
            };
            solver.solve(&problem, &options).unwrap()
        };
        let (one, two) = (run(1), run(2));
        let same = one.fluence == two.fluence;
        log.lock().unwrap().push(format!("{name}: {same}"));
        assert!(same, "{name}: results differ between 1 and 2 threads");
    }
}

/// Every scene file of `examples/scenes/`, `examples/scenes/suite/` and
/// `examples/scenes/mixed/`, built.
fn example_problems() -> Vec<(String, Problem)> {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes");
    let mut out = Vec::new();
    for dir in [root.clone(), root.join("suite"), root.join("mixed")] {
        let mut paths: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| {
                p.extension().is_some_and(|e| e == "toml")
                    && p.file_name().is_some_and(|n| n != "tolerances.toml")
            })
            .collect();
        paths.sort();
        for path in paths {
            let scene = lucent::scene::Scene::load(&path).unwrap();
            match scene.build(path.parent().unwrap()) {
                Ok(built) => out.push((path.display().to_string(), built.problem)),
                // Scenes of the shared data need LUCENT_DATA (CI sets it).
                Err(e) if std::env::var_os("LUCENT_DATA").is_none() => {
                    eprintln!("skipping {}: {e}", path.display())
                }
                Err(e) => panic!("{}: {e}", path.display()),
            }
        }
    }
    out
}

#[test]
fn info_says_can_solve_exactly_when_solve_does_not_refuse() {
    // `lucent info --solver` answers with `Solver::admits`. With a memory budget of one
    // byte an admitted solve must get as far as its memory estimate (every refusal comes
    // before it) and a refused one must fail with the refusal admits gave.
    let problems = example_problems();
    assert!(problems.len() >= 12, "{} scenes", problems.len());
    let mut disagreements = Vec::new();
    for (path, problem) in &problems {
        for name in names() {
            let solver = lucent::registry().build(&name, &Params::default()).unwrap();
            let admitted = solver.admits(problem);
            let options = SolveOptions {
                memory_budget: 1,
                ..SolveOptions::default()
            };
            let solved = solver.solve(problem, &options);
            let agree = match (&admitted, &solved) {
                (Ok(()), Err(lucent::core::SolveError::OverBudget { .. })) => true,
                (Err(a), Err(b)) => a.to_string() == b.to_string(),
                _ => false,
            };
            if !agree {
                disagreements.push(format!(
                    "{name} on {path}: admits {:?}, solve {:?}",
                    admitted.as_ref().err().map(|e| e.to_string()),
                    solved.as_ref().err().map(|e| e.to_string())
                ));
            }
        }
    }
    assert!(disagreements.is_empty(), "{}", disagreements.join("\n"));
}

/// Every solver's parameters are typed and documented: each has a meaning, writing every
/// default out explicitly builds the same solver, and an unknown key, an ill-typed value
/// or a value out of range is an error naming the solver and the key.
#[test]
fn every_parameter_is_documented_typed_and_checked() {
    let registry = lucent::registry();
    for entry in registry.entries() {
        let docs = (entry.params)();
        let mut explicit = Params::default();
        for p in &docs {
            assert!(
                !p.meaning.is_empty(),
                "{}: `{}` undocumented",
                entry.name,
                p.name
            );
            if p.default != "none" {
                let value: ParamValue = serde_json::from_str(&p.default).unwrap();
                explicit.0.insert(p.name.clone(), value);
            }
        }
        let by_default = registry.build(entry.name, &Params::default()).unwrap();
        let written_out = registry
            .build(entry.name, &explicit)
            .unwrap_or_else(|e| panic!("{}: its own defaults refused: {e}", entry.name));
        assert_eq!(
            by_default.capabilities(),
            written_out.capabilities(),
            "{}",
            entry.name
        );
        let mut unknown = Params::default();
        unknown.0.insert("no_such_key".into(), ParamValue::Int(1));
        let message = registry
            .build(entry.name, &unknown)
            .err()
            .unwrap()
            .to_string();
        assert!(
            message.contains("no_such_key") && message.contains(entry.name),
            "{message}"
        );
        // A value of the wrong type for every parameter.
        for p in &docs {
            let wrong = if p.default.starts_with('"') {
                ParamValue::Int(-3)
            } else {
                ParamValue::Text("?".into())
            };
            let mut bad = Params::default();
            bad.0.insert(p.name.clone(), wrong);
            let message = registry
                .build(entry.name, &bad)
                .err()
                .map(|e| e.to_string());
            assert!(
                message
                    .as_ref()
                    .is_some_and(|m| m.contains(&format!("`{}`", p.name))),
                "{} `{}`: {message:?}",
                entry.name,
                p.name
            );
        }
    }
}
