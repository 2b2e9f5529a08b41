//! What the progress bar shows, for every registered solver, through the command line's
//! adapter (`lucent::progress::Meter`): the fraction never goes back, it reaches 100 % once,
//! at the end, and the text says what the solver is doing.

use std::path::Path;
use std::sync::{Arc, Mutex};

use lucent::core::{Problem, SolveOptions};
use lucent::progress::{Meter, Shown};
use lucent::scene::Scene;

/// A small cloud under a sun and a sky, and a homogeneous box lit from inside (for the
/// solvers that take only point lights or a homogeneous medium).
fn problems() -> Vec<Problem> {
    let cloud = "[volume]\nkind = \"blob\"\nresolution = [12, 12, 12]\nbounds = [[-1, -1, -1], [1, 1, 1]]\ncentre = [0, 0, 0]\nsigma = 0.4\n[medium]\ndensity = 6.0\nalbedo = 0.9\n[[lights]]\nkind = \"directional\"\ndirection = [0.3, 0.2, -1.0]\nirradiance = 1.0\n[[lights]]\nkind = \"sky\"\nradiance = 0.2\n[camera]\nkind = \"pinhole\"\nposition = [4, 0, 0]\nlook_at = [0, 0, 0]\n";
    let sun_only = cloud.replace("[[lights]]\nkind = \"sky\"\nradiance = 0.2\n", "");
    let boxed = "[volume]\nkind = \"shape\"\nresolution = [10, 10, 10]\nbounds = [[-1, -1, -1], [1, 1, 1]]\nshape = { type = \"box\", min = [-2, -2, -2], max = [2, 2, 2] }\n[medium]\ndensity = 4.0\nalbedo = 0.9\n[[lights]]\nkind = \"point\"\nposition = [0.1, 0.05, -0.1]\nintensity = 1.0\n[camera]\nkind = \"pinhole\"\nposition = [4, 0, 0]\nlook_at = [0, 0, 0]\n";
    [cloud, sun_only.as_str(), boxed]
        .iter()
        .map(|text| {
            Scene::parse(text, Path::new("progress.toml"))
                .and_then(|s| s.build(Path::new(".")))
                .expect("a valid scene")
                .problem
        })
        .collect()
}

#[test]
fn the_bar_is_monotone_and_full_only_at_the_end_for_every_solver() {
    let problems = problems();
    let registry = lucent::registry();
    for entry in registry.entries() {
        let solver = (entry.build)(&Default::default()).unwrap();
        let problem = problems
            .iter()
            .find(|p| solver.admits(p).is_ok())
            .unwrap_or_else(|| panic!("no test problem for `{}`", entry.name));
        let shown: Arc<Mutex<Vec<Shown>>> = Arc::default();
        let record = Arc::clone(&shown);
        let meter = Meter::new(Arc::new(move |s: &Shown| {
            record.lock().unwrap().push(s.clone());
        }));
        let options = SolveOptions {
            progress: Some(meter.solver_callback()),
            // Enough for these small problems; the diverging ones stop earlier.
            max_iterations: 2000,
            ..SolveOptions::default()
        };
        let result = solver.solve(problem, &options);
        let shown = shown.lock().unwrap();
        let name = entry.name;
        assert!(
            shown.windows(2).all(|w| w[0].permille <= w[1].permille),
            "{name}: the fraction went back: {:?}",
            shown.iter().map(|s| s.permille).collect::<Vec<_>>()
        );
        let full: Vec<usize> = (0..shown.len())
            .filter(|&i| shown[i].permille == 1000)
            .collect();
        match result {
            Ok(_) => {
                assert_eq!(full, vec![shown.len() - 1], "{name}: 100 % once, last");
                assert_eq!(shown[shown.len() - 1].message, "done", "{name}");
                assert!(shown.len() >= 2, "{name}: something ticked before the end");
                assert!(
                    shown[..shown.len() - 1]
                        .iter()
                        .all(|s| !s.message.is_empty() && s.message != "done"),
                    "{name}: {:?}",
                    &shown[..]
                );
            }
            Err(e) => assert!(full.is_empty(), "{name}: failed ({e}) but showed 100 %"),
        }
    }
}

#[test]
fn the_text_names_the_stage_the_iteration_and_the_residual() {
    // Discrete ordinates on the cloud: the uncollided light first (its own share of the
    // bar), then source iterations with their residuals.
    let problem = &problems()[0];
    let solver = lucent::registry()
        .build("dom", &Default::default())
        .unwrap();
    let shown: Arc<Mutex<Vec<Shown>>> = Arc::default();
    let record = Arc::clone(&shown);
    let meter = Meter::new(Arc::new(move |s: &Shown| {
        record.lock().unwrap().push(s.clone())
    }));
    let options = SolveOptions {
        progress: Some(meter.solver_callback()),
        ..SolveOptions::default()
    };
    solver.solve(problem, &options).unwrap();
    let shown = shown.lock().unwrap();
    let messages: Vec<&str> = shown.iter().map(|s| s.message.as_str()).collect();
    let first_iteration = messages
        .iter()
        .position(|m| m.starts_with("source iteration"))
        .unwrap_or_else(|| panic!("{messages:?}"));
    assert!(
        messages[..first_iteration]
            .iter()
            .any(|m| m.contains("transmittance") || *m == "uncollided light"),
        "{messages:?}"
    );
    assert!(
        messages[first_iteration].contains(", residual "),
        "{messages:?}"
    );
    // The uncollided light's share ends at a quarter of the bar.
    assert!(
        shown[first_iteration - 1].permille <= 250,
        "{:?}",
        shown
            .iter()
            .map(|s| (s.permille, s.message.as_str()))
            .collect::<Vec<_>>()
    );
}
