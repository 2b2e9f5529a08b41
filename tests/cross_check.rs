//! The cross-check harness in the default test run: every (solver, scene) entry of
//! `examples/scenes/suite/tolerances.toml` must meet its tolerance against its reference
//! (see `lucent::crosscheck`). Monte Carlo references are cached in Cargo's target folder.

use std::path::Path;

use lucent::crosscheck::{CheckResult, run};

#[test]
fn every_solver_meets_its_tolerance_on_the_suite() {
    if std::env::var_os("LUCENT_DATA").is_none()
        && !Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../shared/data/volumes")
            .is_dir()
    {
        eprintln!("skipping: the suite's CT scene needs LUCENT_DATA");
        return;
    }
    let suite = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes/suite");
    let cache = Path::new(env!("CARGO_TARGET_TMPDIR")).join("crosscheck-cache");
    let outcomes = run(&suite, Some(&cache)).unwrap();
    let mut compared = 0;
    for o in &outcomes {
        match &o.result {
            CheckResult::Compared { comparison, .. } => {
                compared += 1;
                assert!(
                    o.passed(),
                    "{} on {}: relative L2 {:.4} over the tolerance {} ({})",
                    o.solver,
                    o.scene,
                    comparison.relative_l2,
                    o.tolerance.tolerance,
                    o.tolerance.why
                );
            }
            CheckResult::Skipped(reason) => assert!(reason.contains("cannot handle"), "{reason}"),
        }
    }
    assert!(compared >= 9, "the harness compared {compared} pairs");
}

#[test]
fn the_marble_sphere_reference_is_the_t7_solution_for_the_scene_as_written() {
    // The analytic reference must describe the scene file's light and medium: a unit-power
    // source (intensity 1/4π) in marble red. Its absorbed power ∫ σ_a φ dV over the sphere
    // must then be T7's absorbed fraction 0.223790; the cell sum is a midpoint rule, good to
    // a few percent on 32³ cells (φ ~ 1/r near the source).
    use lucent::core::FluenceKind;
    use lucent::crosscheck::{load_suite, reference};
    let suite = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes/suite");
    let (scenes, _) = load_suite(&suite).unwrap();
    let scene = scenes.iter().find(|s| s.name == "marble_sphere").unwrap();
    let r = reference(scene, FluenceKind::Total, 0.01, None).unwrap();
    assert_eq!(r.kind, "analytic");
    let g = scene.built.problem.geometry();
    let sigma_a = 2.1921 * (1.0 - 0.999042);
    let absorbed: f64 = r.fluence[0]
        .data()
        .iter()
        .map(|&phi| sigma_a * f64::from(phi) * g.cell_volume())
        .sum();
    assert!(
        (absorbed - 0.223790).abs() < 0.05 * 0.223790,
        "absorbed {absorbed}"
    );
    match &scene.built.problem.lights()[0] {
        lucent::core::Light::Point { intensity, .. } => {
            assert!(
                (intensity.channel(0) * 4.0 * std::f64::consts::PI - 1.0).abs() < 1e-12,
                "unit power"
            )
        }
        other => panic!("the marble sphere has a point source, not {other:?}"),
    }
}

#[test]
fn pareto_sweep_shows_each_solvers_convergence_on_the_slab() {
    let suite = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes/suite");
    let (scenes, _) = lucent::crosscheck::load_suite(&suite).unwrap();
    let slab = scenes.iter().find(|s| s.name == "slab").unwrap();
    let cache = Path::new(env!("CARGO_TARGET_TMPDIR")).join("crosscheck-cache");
    let points = lucent::pareto::sweep(slab, Some(&cache)).unwrap();
    let mc: Vec<f64> = points
        .iter()
        .filter(|p| p.solver == "mc")
        .map(|p| p.error)
        .collect();
    assert_eq!(mc.len(), 4);
    // Monte Carlo error falls as 1/√N: 64 times the paths, about 8 times smaller (the
    // reference's own ±1% noise flattens the last step a little).
    assert!(mc.windows(2).all(|w| w[1] < w[0]), "{mc:?}");
    assert!(mc[0] / mc[3] > 4.0, "{mc:?}");
    let direct: Vec<f64> = points
        .iter()
        .filter(|p| p.solver == "direct")
        .map(|p| p.error)
        .collect();
    assert!(
        direct.iter().all(|&e| e < 0.01),
        "direct on the slab: {direct:?}"
    );
    let svg = lucent::pareto::svg("slab", &points);
    assert_eq!(svg.matches("<polyline").count(), 2, "one curve per solver");
    assert!(lucent::pareto::csv(&points).lines().count() == points.len() + 1);
}
