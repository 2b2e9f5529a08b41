//! The cross-check harness in the default test run: every (solver, scene) entry of
//! `examples/scenes/suite/tolerances.toml` must meet its tolerance against its reference
//! (see `lucent::crosscheck`). Monte Carlo references are cached in Cargo's target folder.

use std::path::Path;

use lucent::crosscheck::{CheckResult, Selection, run_with};

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
    // Progress goes to the terminal as each entry finishes (written to stderr's handle,
    // which the test harness does not capture): a run that takes a while says where it is.
    let outcomes = run_with(&suite, Some(&cache), Selection::Quick, &mut |progress| {
        use std::io::Write;
        let _ = writeln!(std::io::stderr(), "cross-check {progress}");
    })
    .unwrap();
    let mut compared = 0;
    for o in &outcomes {
        match &o.result {
            CheckResult::Compared { comparison, .. } => {
                compared += 1;
                assert!(
                    o.passed(),
                    "{} on {}: relative L2 {:.4} over the tolerance {}, or not the expected \
                     stop ({})",
                    o.solver,
                    o.scene,
                    comparison.relative_l2,
                    o.tolerance.tolerance,
                    o.tolerance.why
                );
            }
            // A backend may skip for what it cannot handle, and a GPU backend for a
            // missing adapter outside CI (under CI=true that fails the harness instead);
            // the refined convergence checks run by `cargo xtask crosscheck --refined`.
            CheckResult::Skipped(reason) => assert!(
                reason.contains("cannot handle")
                    || reason.contains("no GPU adapter")
                    || reason.contains("crosscheck --refined")
                    || reason.contains("heavy for the default test run"),
                "{reason}"
            ),
        }
    }
    assert!(compared >= 9, "the harness compared {compared} pairs");
    // The quick selection still covers every solver of the table and every scene class:
    // each solver and each scene keeps an entry that is compared here, not only heavy ones
    // (`cargo xtask crosscheck` runs those).
    let quick = |pick: &dyn Fn(&lucent::crosscheck::Outcome) -> &str| {
        let all: std::collections::BTreeSet<&str> = outcomes.iter().map(pick).collect();
        let compared: std::collections::BTreeSet<&str> = outcomes
            .iter()
            .filter(|o| matches!(o.result, CheckResult::Compared { .. }))
            .map(pick)
            .collect();
        let missing: Vec<&&str> = all.difference(&compared).collect();
        missing
            .into_iter()
            .map(|s| s.to_string())
            .collect::<Vec<_>>()
    };
    // `direct` cannot handle the Robin sphere (its entry checks it says so), and a GPU
    // solver without an adapter outside CI is skipped: neither counts as uncovered.
    let uncovered_solvers: Vec<String> = quick(&|o| o.solver.as_str())
        .into_iter()
        .filter(|s| !(s.starts_with("gpu-") && std::env::var_os("CI").is_none()))
        .collect();
    assert!(
        uncovered_solvers.is_empty(),
        "solvers with only heavy entries: {uncovered_solvers:?}"
    );
    let uncovered_scenes = quick(&|o| o.scene.as_str());
    assert!(
        uncovered_scenes.is_empty(),
        "scenes with only heavy entries: {uncovered_scenes:?}"
    );
}

#[test]
fn the_marble_sphere_reference_is_the_t7_solution_for_the_scene_as_written() {
    // The analytic reference must describe the scene file's light and medium: a unit-power
    // source (intensity 1/4π) in marble red, with the Milne A = 2.2119 of η = 1.3. Its
    // absorbed power ∫ σ_a φ dV over the sphere must then be that solution's closed-form
    // absorbed fraction (T7's 0.223790 is for the Groenhuis A); the cell sum is a midpoint
    // rule, good to a few percent on 32³ cells (φ ~ 1/r near the source).
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
    let a = scene.built.problem.boundary().robin_factor().unwrap();
    assert!((a - 2.2119).abs() < 1e-4, "A = {a}");
    let coefficients =
        lucent::optics::OpticalCoefficients::from_extinction_albedo(2.1921, 0.999042, 0.0).unwrap();
    let exact = lucent::optics::DiffusionMedium::new(coefficients, a)
        .unwrap()
        .sphere(10.0)
        .unwrap()
        .absorbed_fraction();
    assert!(
        (absorbed - exact).abs() < 0.05 * exact,
        "absorbed {absorbed} against {exact}"
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
    let sweep = lucent::pareto::sweep(slab, Some(&cache)).unwrap();
    let points = &sweep.points;
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
    // The diffusion solvers level off at the diffusion model's error on the slab (7.4%
    // measured; the suite's tolerance for diffusion there is 15%), whatever the method.
    let diffusion: Vec<&lucent::pareto::Point> = points
        .iter()
        .filter(|p| p.solver.starts_with("diffusion-") && p.setting.contains("1e-8"))
        .collect();
    assert!(diffusion.len() >= 3, "{diffusion:?}");
    assert!(
        diffusion.iter().all(|p| p.error < 0.15),
        "diffusion on the slab: {diffusion:?}"
    );
    assert!(lucent::pareto::csv(points).lines().count() == points.len() + 1);
    // `auto` with the slab's own measurements runs, at each tolerance, the fastest CPU run
    // of this sweep that met it, and meets it: every run it repeats is deterministic (Monte
    // Carlo's streams are seeded), so it lands on the sweep's error.
    let table = lucent::auto::Table {
        scenes: vec![lucent::pareto::measured_scene(slab, points)],
    };
    let autos = lucent::pareto::measure_auto(slab, &table, &sweep, &[0.05, 0.2], &[true]).unwrap();
    assert_eq!(autos.len(), 2);
    for a in &autos {
        let fastest = points
            .iter()
            .filter(|p| !p.solver.starts_with("gpu-") && p.error_total <= a.tolerance)
            .min_by(|x, y| x.seconds.total_cmp(&y.seconds))
            .expect("something meets it on the slab");
        assert_eq!(a.chose, format!("{} ({})", fastest.solver, fastest.setting));
        assert!(a.expected_to_meet);
        assert!(
            (a.error_total - fastest.error_total).abs() < 1e-6 && a.error_total <= a.tolerance,
            "{a:?} against {fastest:?}"
        );
    }
    let markdown = lucent::pareto::auto_markdown(&autos);
    assert_eq!(markdown.lines().count(), 2 + autos.len(), "{markdown}");
    assert_eq!(
        lucent::pareto::parse_auto_csv(&lucent::pareto::auto_csv(&autos))
            .unwrap()
            .len(),
        2
    );
}

/// Monte Carlo over analytic diffusion (the harness's reference, Robin condition with the
/// partial-current A), averaged over 1 mm shells of the compared region (3 transport mean
/// free paths from the source and from the surface), for the suite's marble sphere with its
/// boundary index replaced by `eta`.
fn marble_shell_ratios(eta: &str, particles: i64) -> Vec<f64> {
    use lucent::core::{FluenceKind, SolveOptions, Solver};
    use lucent::crosscheck::{load_suite, reference};
    let suite = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes/suite");
    let text = std::fs::read_to_string(suite.join("marble_sphere.toml"))
        .unwrap()
        .replace("eta = 1.3", &format!("eta = {eta}"));
    assert!(text.contains(&format!("eta = {eta}")));
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("marble_sphere.toml"), text).unwrap();
    std::fs::write(dir.path().join("tolerances.toml"), "entry = []\n").unwrap();
    let (scenes, _) = load_suite(dir.path()).unwrap();
    let scene = &scenes[0];
    let analytic = reference(scene, FluenceKind::Total, 0.01, None).unwrap();
    let mut params = lucent::core::Params::default();
    params
        .0
        .insert("particles".into(), lucent::core::ParamValue::Int(particles));
    params
        .0
        .insert("batches".into(), lucent::core::ParamValue::Int(8));
    let mc = lucent::mc::McSolver::from_params(&params).unwrap();
    let solution = mc
        .solve(&scene.built.problem, &SolveOptions::default())
        .unwrap();
    let g = scene.built.problem.geometry();
    let mask = analytic.mask.as_ref().unwrap();
    let mut shells = [(0.0f64, 0.0f64); 10];
    for index in 0..g.voxel_count() {
        if mask[index] {
            let [i, j, k] = g.coords(index);
            let r = g.cell_centre(i, j, k).length();
            let s = &mut shells[r as usize];
            s.0 += f64::from(solution.fluence[0].data()[index]);
            s.1 += f64::from(analytic.fluence[0].data()[index]);
        }
    }
    shells
        .iter()
        .filter(|s| s.1 > 0.0)
        .map(|s| s.0 / s.1)
        .collect()
}

/// Monte Carlo refracts and reflects at the sphere (Fresnel, total internal reflection),
/// diffusion applies the Robin condition with the Milne A (the transport-exact
/// extrapolation length). Three transport mean free paths from source and surface, every
/// 1 mm shell average must agree within 2.5%: measured with 8000 paths per batch within
/// 0.8% (η = 1), 1.5% (1.3), 1.6% (1.4), 1.3% (1.5), where the partial-current A of the
/// P1 boundary condition was 3.0–3.2% off at 8–8.6 mm for η ≥ 1.3 (its extrapolation
/// length is 5–6% too long). At 2000 paths per batch a shell average's own noise is
/// about 0.4% (the runs are seeded: the same numbers every run; measured at most 2.2%
/// off, at 11 mm for η = 1.3). η = 1.4, between 1.3 and 1.5, is left out (1.6% at 8000
/// paths when it was in); the suite's `mc` entries on the sphere at η = 1.3 and 1.5
/// (32k paths, cell by cell) are `cargo xtask crosscheck`'s. One test per index, so that
/// they run beside the other tests.
fn monte_carlo_matches_diffusion_through_a_fresnel_interface(eta: &str) {
    let ratios = marble_shell_ratios(eta, 2000);
    assert!(ratios.len() >= 6, "{ratios:?}");
    assert!(
        ratios.iter().all(|r| (r - 1.0).abs() < 0.025),
        "η = {eta}: mc / diffusion per 1 mm shell: {ratios:?}"
    );
}

#[test]
fn monte_carlo_matches_diffusion_through_a_fresnel_interface_at_1_0() {
    monte_carlo_matches_diffusion_through_a_fresnel_interface("1.0");
}

#[test]
fn monte_carlo_matches_diffusion_through_a_fresnel_interface_at_1_3() {
    monte_carlo_matches_diffusion_through_a_fresnel_interface("1.3");
}

#[test]
fn monte_carlo_matches_diffusion_through_a_fresnel_interface_at_1_5() {
    monte_carlo_matches_diffusion_through_a_fresnel_interface("1.5");
}

/// The stored Monte Carlo references describe the suite as it is: none is stale (a scene
/// edited without `cargo xtask crosscheck` would have its references computed again by
/// every test run), and the staleness rule itself tells a changed scene's or an old
/// recipe's file from a current one, leaving other scenes' files (`slab_x` is not `slab`).
#[test]
fn stored_references_describe_the_suite_as_it_is() {
    use lucent::crosscheck::{REFERENCE_VERSION, load_suite, stale_references};
    let suite = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes/suite");
    let (scenes, _) = load_suite(&suite).unwrap();
    let stored = suite.join("references");
    assert!(
        stale_references(&stored, &scenes).is_empty(),
        "stale references in {}: run `cargo xtask crosscheck`",
        stored.display()
    );
    let dir = tempfile::tempdir().unwrap();
    let slab = scenes.iter().find(|s| s.name == "slab").unwrap();
    let name = |hash: u64, version: u32| format!("slab-total-{hash:016x}-1e-2-v{version}.npy");
    let current = name(slab.text_hash, REFERENCE_VERSION);
    let edited = name(slab.text_hash ^ 1, REFERENCE_VERSION);
    let old = name(slab.text_hash, REFERENCE_VERSION + 1);
    let other = format!("slab_x-total-{:016x}-1e-2-v1.npy", 7);
    for file in [&current, &edited, &old, &other] {
        std::fs::write(dir.path().join(file), b"").unwrap();
    }
    let mut stale: Vec<String> = stale_references(dir.path(), &scenes)
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    stale.sort();
    let mut expected = vec![edited, old];
    expected.sort();
    assert_eq!(stale, expected);
}
