//! `auto`: the choice follows the measured table (the fastest admitted run meeting the
//! tolerance on the nearest scene, the closest one when none does, the time budget
//! respected), it never runs a solver that refuses the problem, what it runs is bit for bit
//! what that solver gives, and the committed table matches the suite it was measured on.

use std::path::Path;
use std::time::Duration;

use lucent::auto::{AutoSolver, Features, Measured, MeasuredScene, Table, choose};
use lucent::core::{Params, SolveError, SolveOptions, Solver};
use lucent::crosscheck::{SuiteScene, load_suite};
use lucent::pareto::{Run, runs};
use proptest::prelude::*;

fn suite() -> Vec<SuiteScene> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes/suite");
    load_suite(&dir).expect("the suite loads").0
}

fn suite_scene(name: &str) -> SuiteScene {
    suite()
        .into_iter()
        .find(|s| s.name == name)
        .expect("a suite scene")
}

/// A table of one scene lying exactly at `scene`'s regime, with `points`.
fn table_at(scene: &SuiteScene, points: Vec<Measured>) -> Table {
    Table {
        scenes: vec![MeasuredScene {
            name: scene.name.clone(),
            cells: scene.built.problem.geometry().voxel_count(),
            features: Features::of(&scene.built.problem),
            points,
        }],
    }
}

fn measured(run: &Run, seconds: f64, error_total: f64) -> Measured {
    Measured {
        label: run.label.into(),
        setting: run.setting.clone(),
        seconds,
        error_total,
    }
}

fn run(label: &str, setting: &str) -> Run {
    runs()
        .into_iter()
        .find(|r| r.label == label && r.setting == setting)
        .unwrap_or_else(|| panic!("no run {label} ({setting})"))
}

fn admits(run: &Run, scene: &SuiteScene) -> bool {
    let params: Params = toml::from_str(&run.params).unwrap();
    lucent::registry()
        .build(run.solver, &params)
        .unwrap()
        .admits(&scene.built.problem)
        .is_ok()
}

/// The committed table holds every suite scene, at the regime its scene has now, and
/// only runs that still exist: `cargo xtask pareto` regenerates it when either changes.
#[test]
fn the_committed_table_matches_the_suite_and_the_runs() {
    let table = Table::builtin();
    let all = runs();
    for scene in suite() {
        let row = table
            .scenes
            .iter()
            .find(|s| s.name == scene.name)
            .unwrap_or_else(|| panic!("{} is not in docs/pareto/auto.csv", scene.name));
        let now = Features::of(&scene.built.problem);
        // The table prints four or five significant digits.
        assert!(
            row.features.distance(&now) < 1e-3,
            "{}: the table's regime {:?} is not the scene's {:?}; run cargo xtask pareto",
            scene.name,
            row.features,
            now
        );
        assert_eq!(row.cells, scene.built.problem.geometry().voxel_count());
        for p in &row.points {
            assert!(
                all.iter()
                    .any(|r| r.label == p.label && r.setting == p.setting),
                "{}: the table's run {} ({}) is no longer swept",
                scene.name,
                p.label,
                p.setting
            );
            assert!(p.seconds >= 0.0 && p.error_total >= 0.0);
        }
        // Each scene's table has something that meets the suite's loosest tolerance.
        assert!(
            row.points
                .iter()
                .any(|p| !p.label.starts_with("gpu-") && p.error_total <= 0.2),
            "{}",
            scene.name
        );
    }
}

/// The scenes of mixed regime are held out: `auto`'s table never holds them (nor any scene
/// of that name), so what `docs/validation.md` reports on them is the rule's choice on
/// scenes it has not measured.
#[test]
fn the_mixed_scenes_are_held_out_of_the_table() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes/mixed");
    let mixed = lucent::crosscheck::load_scenes(&dir).expect("the mixed scenes load");
    assert!(!mixed.is_empty());
    for scene in &mixed {
        assert!(
            !Table::builtin().scenes.iter().any(|s| s.name == scene.name),
            "{} is in auto's table",
            scene.name
        );
        assert!(!suite().iter().any(|s| s.name == scene.name));
    }
}

/// The scene in the table nearest in regime decides: the slab's own rows for the slab,
/// the marble sphere's for the marble sphere.
#[test]
fn the_nearest_scene_in_regime_decides() {
    let (slab, marble) = (suite_scene("slab"), suite_scene("marble_sphere"));
    let direct = run("direct", "1x cells, 8 sky directions");
    let mg = run("diffusion-mg", "1x cells, tolerance 1e-8");
    let mut table = table_at(&slab, vec![measured(&direct, 0.01, 0.01)]);
    table
        .scenes
        .extend(table_at(&marble, vec![measured(&mg, 0.1, 0.01)]).scenes);
    let registry = lucent::registry();
    let on_slab = choose(&slab.built.problem, 0.05, None, &table, &registry).unwrap();
    assert_eq!((on_slab.nearest(), on_slab.run.label), ("slab", "direct"));
    assert_eq!(on_slab.neighbours, [("slab".to_owned(), 0.0)]);
    let on_marble = choose(&marble.built.problem, 0.05, None, &table, &registry).unwrap();
    assert_eq!(
        (on_marble.nearest(), on_marble.run.label),
        ("marble_sphere", "diffusion-mg")
    );
    // The refractive index alone moves the boundary's Robin factor, and with it the regime.
    let eta = suite_scene("marble_sphere_eta15");
    let f = Features::of(&eta.built.problem);
    assert!(f.distance(&Features::of(&marble.built.problem)) > 0.1);
}

/// A problem that is none of the measured scenes is decided by every scene near it: a
/// run counts with its worst error among them, and must meet the tolerance with a margin
/// ([`lucent::auto::UNSEEN_MARGIN`]).
#[test]
fn an_unseen_problem_is_decided_by_its_neighbours_with_a_margin() {
    let (slab, faces, aniso) = (
        suite_scene("slab"),
        suite_scene("touching_faces"),
        suite_scene("anisotropic"),
    );
    let mc = run("mc", "8000 paths");
    let dom = run("dom", "S8 diamond, tolerance 1e-4");
    let mut table = table_at(
        &faces,
        vec![measured(&mc, 0.01, 0.01), measured(&dom, 0.1, 0.01)],
    );
    table.scenes.extend(
        table_at(
            &slab,
            vec![measured(&mc, 0.01, 0.3), measured(&dom, 0.1, 0.01)],
        )
        .scenes,
    );
    let registry = lucent::registry();
    let problem = &aniso.built.problem;
    let f = Features::of(problem);
    let (d_faces, d_slab) = (
        f.distance(&Features::of(&faces.built.problem)),
        f.distance(&Features::of(&slab.built.problem)),
    );
    // Both within reach: touching_faces nearest, the slab within twice that plus 0.2.
    assert!(
        d_faces < d_slab && d_slab <= 2.0 * d_faces + 0.2,
        "{d_faces} {d_slab}"
    );
    let choice = choose(problem, 0.05, None, &table, &registry).unwrap();
    assert_eq!(choice.neighbours.len(), 2);
    assert_eq!(choice.nearest(), "touching_faces");
    assert_eq!((choice.run.label, choice.expected_error), ("dom", 0.01));
    assert!(choice.meets);
    // Alone, touching_faces' 4.5% is within 5% but not within 80% of it.
    let alone = table_at(
        &faces,
        vec![measured(&mc, 0.01, 0.3), measured(&dom, 0.1, 0.045)],
    );
    let choice = choose(problem, 0.05, None, &alone, &registry).unwrap();
    assert!(!choice.meets, "{choice}");
    // The line says the margin (without it, "cannot meet 5 % … with 4.5 %" read as a
    // contradiction) and labels the distance.
    assert!(
        choice
            .to_string()
            .contains("touching_faces (regime distance 0."),
        "{choice}"
    );
    assert!(
        choice
            .to_string()
            .contains("(at most 4.00% measured: a margin of 20 %"),
        "{choice}"
    );
    assert!((choice.error_limit - 0.04).abs() < 1e-12);
}

/// What `auto` runs is that run, bit for bit: the solver with the table's parameters and
/// iteration tolerance, on the refined grid restricted back where the run was refined. On
/// a slab under the sun, a medium touching its box on a grid of 13 × 11 × 19 cells, and a
/// point light inside the medium on 19 × 17 × 15 cells.
#[test]
fn auto_runs_exactly_the_chosen_run() {
    let registry = lucent::registry();
    let mut checked = 0;
    for (scene, label, setting) in [
        ("slab", "direct", "1x cells, 8 sky directions"),
        ("slab", "diffusion-mg", "2x cells, tolerance 1e-8"),
        ("touching_faces", "direct", "1x cells, 32 sky directions"),
        ("touching_faces", "diffusion-mg", "2x cells, tolerance 1e-4"),
        ("point_inside", "dom", "S4 diamond, tolerance 1e-4"),
        ("point_inside", "diffusion-cg", "1x cells, tolerance 1e-2"),
    ] {
        let slab = suite_scene(scene);
        let problem = &slab.built.problem;
        let chosen = run(label, setting);
        assert!(admits(&chosen, &slab), "{scene}: {label} refuses it");
        checked += 1;
        let table = table_at(&slab, vec![measured(&chosen, 0.01, 0.01)]);
        let auto = AutoSolver::with_table(0.05, table);
        let solution = auto.solve(problem, &SolveOptions::default()).unwrap();
        assert_eq!(solution.report.solver, "auto");
        let line = solution.report.choice.clone().unwrap();
        assert!(
            line.starts_with(&format!("auto chose `{label}` ({setting})")) && !line.contains('\n'),
            "{line}"
        );
        let params: Params = toml::from_str(&chosen.params).unwrap();
        let solver = registry.build(chosen.solver, &params).unwrap();
        let options = SolveOptions {
            relative_tolerance: chosen.tolerance.unwrap_or(1e-6),
            ..SolveOptions::default()
        };
        let expected = if chosen.factor == 1 {
            solver.solve(problem, &options).unwrap().fluence
        } else {
            let dims = problem.geometry().dims().map(|n| n * chosen.factor);
            let fine = lucent::resolution::on_grid(problem, dims).unwrap();
            let fluence = solver.solve(&fine, &options).unwrap().fluence;
            fluence
                .iter()
                .map(lucent::grid::resample::restrict)
                .collect()
        };
        assert_eq!(solution.fluence.len(), expected.len());
        for (a, b) in solution.fluence.iter().zip(&expected) {
            assert_eq!(a.geometry(), problem.geometry());
            assert!(
                a.data()
                    .iter()
                    .zip(b.data())
                    .all(|(x, y)| x.to_bits() == y.to_bits()),
                "{scene}, {label}: auto's fluence differs from the run's"
            );
        }
    }
    assert_eq!(checked, 6);
}

/// A tolerance no measured run meets is said, and the closest run is made; an empty table,
/// a table whose solvers all refuse the problem and a tolerance outside (0, 1) are typed
/// errors.
#[test]
fn what_cannot_be_met_is_said_and_bad_requests_are_errors() {
    let slab = suite_scene("slab");
    let problem = &slab.built.problem;
    let registry = lucent::registry();
    let mc = run("mc", "8000 paths");
    let dom = run("dom", "S4 diamond, tolerance 1e-4");
    let table = table_at(
        &slab,
        vec![measured(&mc, 0.01, 0.1), measured(&dom, 0.05, 0.03)],
    );
    let choice = choose(problem, 0.01, None, &table, &registry).unwrap();
    assert!(!choice.meets);
    assert_eq!(choice.run.label, "dom");
    let line = choice.to_string();
    assert!(line.starts_with("auto cannot meet 1.00%"), "{line}");
    assert!(line.contains("3.00%"), "{line}");
    // Within a budget the faster but worse run is the best there is, and that is said.
    let choice = choose(
        problem,
        0.02,
        Some(Duration::from_millis(20)),
        &table,
        &registry,
    )
    .unwrap();
    assert!(!choice.meets);
    assert_eq!(choice.run.label, "mc");
    let table = table_at(
        &slab,
        vec![measured(&mc, 0.01, 0.1), measured(&dom, 0.05, 0.01)],
    );
    let choice = choose(
        problem,
        0.02,
        Some(Duration::from_millis(20)),
        &table,
        &registry,
    )
    .unwrap();
    assert!(!choice.meets && choice.budget_bound, "{choice:?}");
    assert!(choice.to_string().contains("within the time budget"));
    // Nothing to choose from.
    let empty = Table::default();
    assert!(matches!(
        choose(problem, 0.02, None, &empty, &registry),
        Err(SolveError::Unsupported { .. })
    ));
    let p1 = run("ftcs-p1", "tolerance 1e-4");
    assert!(!admits(&p1, &slab), "the slab's sun is not a point light");
    let refused = table_at(&slab, vec![measured(&p1, 0.01, 0.001)]);
    let auto = AutoSolver::with_table(0.02, refused);
    assert!(matches!(
        auto.admits(problem),
        Err(SolveError::Unsupported { .. })
    ));
    for bad in ["0.0", "1.0", "-0.5", "nan"] {
        let params: Params = toml::from_str(&format!("tolerance = {bad}")).unwrap();
        let message = lucent::registry()
            .build("auto", &params)
            .err()
            .unwrap_or_else(|| panic!("tolerance {bad} accepted"))
            .to_string();
        assert!(message.contains("tolerance"), "{message}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Over random measurements of every run on the slab (where `ftcs-p1` and the
    /// FTCS ordinates refuse its sun), random tolerances and budgets, the choice is the
    /// brute-force answer: never a refusing solver nor a GPU twin; when it meets, nothing
    /// admitted within the budget meets faster; when it does not, nothing admitted within
    /// the budget meets at all and the choice has the smallest error there.
    #[test]
    fn the_choice_is_the_fastest_admitted_run_meeting_the_tolerance(
        draws in proptest::collection::vec((-3.0f64..1.0, -3.0f64..0.0), 40..=40),
        tolerance_exp in -2.5f64..-0.5,
        budget in proptest::option::of(-2.0f64..0.5),
    ) {
        let slab = suite_scene("slab");
        let all = runs();
        let points: Vec<Measured> = all
            .iter()
            .zip(draws.iter().cycle())
            .map(|(r, (t, e))| measured(r, 10f64.powf(*t), 10f64.powf(*e)))
            .collect();
        let table = table_at(&slab, points.clone());
        let tolerance = 10f64.powf(tolerance_exp);
        let budget = budget.map(|b| Duration::from_secs_f64(10f64.powf(b)));
        let registry = lucent::registry();
        let choice = choose(&slab.built.problem, tolerance, budget, &table, &registry).unwrap();
        let fits = |s: f64| budget.is_none_or(|b| s <= b.as_secs_f64());
        let candidates: Vec<(&Run, &Measured)> = all
            .iter()
            .zip(&points)
            .filter(|(r, _)| !r.label.starts_with("gpu-") && admits(r, &slab))
            .collect();
        prop_assert!(admits(&choice.run, &slab));
        prop_assert!(!choice.run.label.starts_with("gpu-"));
        let meeting: Vec<&(&Run, &Measured)> = candidates
            .iter()
            .filter(|(_, m)| m.error_total <= tolerance && fits(m.seconds))
            .collect();
        if choice.meets {
            prop_assert!(choice.expected_error <= tolerance);
            let fastest = meeting.iter().map(|(_, m)| m.seconds).fold(f64::INFINITY, f64::min);
            prop_assert_eq!(choice.expected_seconds, fastest);
        } else {
            prop_assert!(meeting.is_empty());
            let within: Vec<f64> = candidates
                .iter()
                .filter(|(_, m)| fits(m.seconds))
                .map(|(_, m)| m.error_total)
                .collect();
            if !within.is_empty() {
                let best = within.iter().copied().fold(f64::INFINITY, f64::min);
                prop_assert_eq!(choice.expected_error, best);
            }
        }
    }
}

/// A chosen run over the memory budget gives way to the next choice, and the line says so;
/// when every run is over it, the error is the last refusal's.
#[test]
fn a_run_over_the_memory_budget_gives_way_to_the_next() {
    let slab = suite_scene("slab");
    let problem = &slab.built.problem;
    let registry = lucent::registry();
    let direct = run("direct", "1x cells, 8 sky directions");
    let mg = run("diffusion-mg", "2x cells, tolerance 1e-8");
    let peak = |r: &Run| {
        let params: Params = toml::from_str(&r.params).unwrap();
        let solver = registry.build(r.solver, &params).unwrap();
        let dims = problem.geometry().dims().map(|n| n * r.factor);
        let on = lucent::resolution::on_grid(problem, dims).unwrap();
        solver
            .solve(&on, &SolveOptions::default())
            .unwrap()
            .report
            .peak_memory_bytes
    };
    let (small, large) = (peak(&direct), peak(&mg));
    assert!(small < large, "{small} {large}");
    // diffusion-mg is the faster in the table, but does not fit.
    let table = table_at(
        &slab,
        vec![measured(&mg, 0.001, 0.01), measured(&direct, 0.01, 0.01)],
    );
    let auto = AutoSolver::with_table(0.05, table);
    let options = SolveOptions {
        memory_budget: (small + large) / 2,
        ..SolveOptions::default()
    };
    let solution = auto.solve(problem, &options).unwrap();
    let line = solution.report.choice.unwrap();
    assert!(line.starts_with("auto chose `direct`"), "{line}");
    assert!(
        line.contains("`diffusion-mg` (2x cells, tolerance 1e-8) could not run"),
        "{line}"
    );
    let options = SolveOptions {
        memory_budget: small / 2,
        ..SolveOptions::default()
    };
    assert!(matches!(
        auto.solve(problem, &options),
        Err(SolveError::OverBudget { .. })
    ));
}

/// A Monte Carlo run keeps its paths per cell on a problem with more cells than the scene
/// it was measured on: the error per cell the table measured, at the time it scales to.
#[test]
fn monte_carlo_paths_scale_with_the_problems_cells() {
    let slab = suite_scene("slab");
    let problem = &slab.built.problem;
    let mc = run("mc", "8000 paths");
    let mut table = table_at(&slab, vec![measured(&mc, 0.01, 0.05)]);
    let cells = problem.geometry().voxel_count();
    assert_eq!(cells % 8, 0);
    table.scenes[0].cells = cells / 8;
    let choice = choose(problem, 0.1, None, &table, &lucent::registry()).unwrap();
    assert_eq!(choice.cells_ratio, 8.0);
    assert!((choice.expected_seconds - 0.08).abs() < 1e-12);
    assert_eq!(
        choice.params().unwrap().0.get("particles"),
        Some(&lucent::core::ParamValue::Int(8000))
    );
    assert!(choice.to_string().contains("paths scaled ×8.0"), "{choice}");
    // A smaller problem keeps the measured paths (its error per cell only falls).
    table.scenes[0].cells = cells * 2;
    let choice = choose(problem, 0.1, None, &table, &lucent::registry()).unwrap();
    assert_eq!(
        choice.params().unwrap().0.get("particles"),
        Some(&lucent::core::ParamValue::Int(1000))
    );
}

/// The cells' optical depth is a feature: on the homogeneous slab (σ_t′ = 3) it is 3h,
/// and twice that on a grid twice as coarse, where the grid solvers' errors grow.
#[test]
fn the_optical_depth_of_a_cell_is_a_feature() {
    let slab = suite_scene("slab");
    let problem = &slab.built.problem;
    let h = problem.geometry().spacing().max_element();
    let fine = Features::of(problem);
    assert!((fine.cell_depth - 3.0 * h).abs() < 1e-5 * h, "{fine:?}");
    let coarse_dims = problem.geometry().dims().map(|n| n / 2);
    let coarse = Features::of(&lucent::resolution::on_grid(problem, coarse_dims).unwrap());
    assert!((coarse.cell_depth - 6.0 * h).abs() < 1e-5 * h, "{coarse:?}");
    assert!(
        fine.distance(&coarse) > 0.05,
        "two resolutions are two regimes"
    );
}
