//! Delta-M truncation at g = 0.9: fewer sweeps, and an S6 answer closer to the S12
//! solution of the untruncated problem than S6 without it; the truncation's algebra.

use glam::DVec3;
use lucent_core::Stopping;
use lucent_dom::angular::Ordinates;
use lucent_dom::{DeltaM, DomBoundary, DomProblem, DomSettings, legendre_moment, solve};
use lucent_grid::GridGeometry;
use lucent_optics::{Phase, SphericalQuadrature};

use crate::common;

use common::{glowing_cube, relative_l2};

/// The tests' scene (`common::glowing_cube`): 24³ cells at albedo 0.95, σ_t = 12
/// (σ_t h = 0.5), for the storage directions of `ordinates`.
fn problem(ordinates: &Ordinates, cloud: bool) -> DomProblem {
    let m = ordinates.storage().len();
    glowing_cube(24, 12.0, 0.95, cloud, m, DomBoundary::default())
}

fn ordinates(order: usize, phase: Phase) -> Ordinates {
    Ordinates::new(
        SphericalQuadrature::level_symmetric(order).unwrap(),
        None,
        phase,
    )
    .unwrap()
}

/// Sweeps to 1e-6 and the error of the fluence against S12 without truncation, for S6
/// with and without delta-M (f = χ₆ = 0.531, g* = 0.787). Measured (2026-11-25): cube 26
/// sweeps at 4.8 % against 16 at 3.9 %; cloud 23 at 5.8 % against 14 at 5.2 %. Asserted:
/// at most 70 % of the sweeps, and an error no larger than without truncation (the
/// forward peak carried by the δ instead of smeared over S6's directions); the energy
/// balance of the truncated problem to 1e-6 (it is a transport problem of its own).
#[test]
fn delta_m_takes_fewer_sweeps_and_is_closer_to_a_finer_quadrature() {
    let phase = Phase::henyey_greenstein(0.9).unwrap();
    let stopping = Stopping {
        relative_tolerance: 1e-6,
        max_iterations: 200,
        ..Stopping::default()
    };
    let settings = DomSettings::default();
    for cloud in [false, true] {
        let fine = ordinates(12, phase);
        let reference = solve(&problem(&fine, cloud), &fine, &settings, &stopping).unwrap();
        let coarse = ordinates(6, phase);
        let plain = solve(&problem(&coarse, cloud), &coarse, &settings, &stopping).unwrap();
        let truncation = DeltaM::new(phase, 6).unwrap();
        let reduced = ordinates(6, truncation.reduced_phase());
        let truncated = truncation.apply(&problem(&reduced, cloud));
        let delta = solve(&truncated, &reduced, &settings, &stopping).unwrap();
        for s in [&reference, &plain, &delta] {
            assert!(
                s.convergence.stop_reason.is_converged(),
                "{:?}",
                s.convergence
            );
        }
        assert!(
            delta.balance.relative_imbalance() < 1e-6,
            "{:?}",
            delta.balance
        );
        let (plain_error, delta_error) = (
            relative_l2(&plain.fluence, &reference.fluence),
            relative_l2(&delta.fluence, &reference.fluence),
        );
        eprintln!(
            "cloud {cloud}: S6 {} sweeps, error {plain_error:.2e}; S6 + delta-M {} sweeps, error {delta_error:.2e}",
            plain.convergence.sweeps, delta.convergence.sweeps
        );
        assert!(
            10 * delta.convergence.sweeps <= 7 * plain.convergence.sweeps,
            "cloud {cloud}: {} against {} sweeps",
            delta.convergence.sweeps,
            plain.convergence.sweeps
        );
        assert!(
            delta_error <= plain_error,
            "cloud {cloud}: {delta_error} against {plain_error}"
        );
        // δ-Eddington (f = χ₂ = g² = 0.81, g* = 0.47) for comparison: fewer sweeps still,
        // a little less accurate than f = χ₆. Measured: cube 9 sweeps at 4.1 %, cloud 10 at
        // 5.4 %; asserted: fewer sweeps than f = χ₆ and no worse than S6 untruncated.
        let eddington = DeltaM::new(phase, 2).unwrap();
        let reduced = ordinates(6, eddington.reduced_phase());
        let truncated = eddington.apply(&problem(&reduced, cloud));
        let e = solve(&truncated, &reduced, &settings, &stopping).unwrap();
        assert!(
            e.convergence.stop_reason.is_converged(),
            "{:?}",
            e.convergence
        );
        let e_error = relative_l2(&e.fluence, &reference.fluence);
        eprintln!(
            "cloud {cloud}: S6 + delta-Eddington {} sweeps, error {e_error:.2e}",
            e.convergence.sweeps
        );
        assert!(e.convergence.sweeps < delta.convergence.sweeps);
        assert!(
            e_error <= plain_error,
            "cloud {cloud}: {e_error} against {plain_error}"
        );
    }
}

/// The truncation keeps the first moment (f + (1 − f)g* = g), leaves σ_a alone, and moves
/// nothing for phase functions without a forward peak at order N.
#[test]
fn the_truncation_keeps_g_and_the_absorption() {
    for (phase, order) in [
        (Phase::henyey_greenstein(0.9).unwrap(), 6),
        (Phase::henyey_greenstein(0.8).unwrap(), 8),
        (Phase::double_henyey_greenstein(0.95, -0.3, 0.8).unwrap(), 4),
    ] {
        let t = DeltaM::new(phase, order).unwrap();
        let f = t.fraction();
        assert!((f - legendre_moment(&phase, order)).abs() < 1e-15);
        let kept = f + (1.0 - f) * legendre_moment(&t.reduced_phase(), 1);
        assert!(
            (kept - legendre_moment(&phase, 1)).abs() < 1e-12,
            "{phase:?}: {kept}"
        );
        let p = DomProblem {
            geometry: GridGeometry::from_bounds([2; 3], DVec3::ZERO, DVec3::ONE).unwrap(),
            sigma_t: vec![10.0, 5.0, 1.0, 0.0, 3.0, 3.0, 8.0, 2.0],
            sigma_s: vec![9.0, 1.0, 1.0, 0.0, 0.0, 3.0, 4.0, 2.0],
            fixed: Vec::new(),
            boundary: DomBoundary::default(),
        };
        let q = t.apply(&p);
        for c in 0..8 {
            let absorbed = |p: &DomProblem| f64::from(p.sigma_t[c]) - f64::from(p.sigma_s[c]);
            assert!((absorbed(&q) - absorbed(&p)).abs() < 1e-5, "cell {c}");
            assert!((f64::from(q.sigma_s[c]) - (1.0 - f) * f64::from(p.sigma_s[c])).abs() < 1e-5);
        }
    }
    for phase in [Phase::Isotropic, Phase::Rayleigh] {
        let t = DeltaM::new(phase, 4).unwrap();
        assert_eq!(t.fraction(), 0.0);
        assert_eq!(t.reduced_phase(), phase);
    }
    assert!(DeltaM::new(Phase::Isotropic, 1).is_err());
}

/// `truncation` through the registry, where the lights' uncollided light is integrated in
/// the truncated medium too: a sun on a 24³ cloud (σ_t h up to 0.75, albedo 0.95, HG
/// g = 0.9; the step closure), S6 with and without delta-M against S12 without, all to
/// 1e-6. Measured (2026-11-26): S6 23 iterations at 3.78e-2 of the reference, delta-M 14
/// at 3.63e-2, delta-Eddington 10 at 5.91e-2. Asserted: delta-M at most 70 % of the
/// iterations and no larger an error, delta-Eddington fewer iterations still; the
/// truncation adds no imbalance of its own; the renderer's exact single scattering keeps
/// the true phase function.
#[test]
fn the_registry_truncates_the_lights_uncollided_light_too() {
    use lucent_core::{
        Angular, Boundary, Field, Light, Medium, ParamValue, Params, Problem, SolveOptions,
        Spectrum,
    };
    use lucent_dom::DomSolver;
    let geometry = GridGeometry::from_bounds([24; 3], DVec3::ZERO, DVec3::ONE).unwrap();
    let density = lucent_grid::Grid::from_fn(geometry, |p| {
        let r = (p - DVec3::splat(0.5)).length();
        (12.0
            * (1.0 + 0.5 * (7.0 * p.x).sin() * (5.0 * p.y).cos())
            * if r < 0.4 { 1.0 } else { 0.02 }) as f32
    });
    let phase = Phase::henyey_greenstein(0.9).unwrap();
    let problem = Problem::new(
        geometry,
        Medium {
            sigma_t: vec![density],
            albedo: vec![Field::Constant(0.95)],
            phase,
        },
        vec![Light::Directional {
            direction: DVec3::new(0.3, 0.2, -0.93).normalize(),
            irradiance: Spectrum::Grey(1.0),
        }],
        Boundary::Vacuum,
        None,
    )
    .unwrap();
    let options = SolveOptions {
        relative_tolerance: 1e-6,
        max_iterations: 200,
        ..SolveOptions::default()
    };
    let run = |order: i64, truncation: &str| {
        let mut p = Params::default();
        p.0.insert("order".into(), ParamValue::Int(order));
        p.0.insert("truncation".into(), ParamValue::Text(truncation.into()));
        // The step closure conserves exactly (diamond difference's set-to-zero fix-up
        // does not, on this cloud's sharp edges).
        p.0.insert("closure".into(), ParamValue::Text("step".into()));
        let (solution, channels) = DomSolver::from_params(&p)
            .unwrap()
            .solve_with_details(&problem, &options)
            .unwrap();
        assert!(
            solution.report.stop_reason.is_converged(),
            "{truncation}: {:?}",
            solution.report
        );
        let imbalance = channels[0].balance.relative_imbalance();
        let Some(Angular::Ordinates(o)) = &solution.angular else {
            panic!("dom returns ordinates");
        };
        assert_eq!(o.lights.as_ref().unwrap().phase, phase);
        let fluence: Vec<f64> = solution
            .fluence(0)
            .data()
            .iter()
            .map(|&v| v.into())
            .collect();
        (fluence, solution.report.iterations, imbalance)
    };
    let (reference, _, _) = run(12, "none");
    let (plain, plain_sweeps, plain_imbalance) = run(6, "none");
    let (delta, delta_sweeps, delta_imbalance) = run(6, "delta-m");
    let (eddington, eddington_sweeps, eddington_imbalance) = run(6, "delta-eddington");
    // The balances: the uncollided light's 2×2×2 Gauss cell rule leaves 7.5e-3 of the
    // sun's power unaccounted on this sharp-edged cloud with or without truncation
    // (`lucent_core::uncollided_cells`: a cell's σ_t φ̄ V at its centre's σ_t against the
    // rays' trilinear one); the truncated problems, whose cells are optically thinner, no
    // more (measured 2.9e-3 and 9.0e-4).
    eprintln!(
        "imbalances: S6 {plain_imbalance:.1e}, delta-M {delta_imbalance:.1e}, delta-Eddington {eddington_imbalance:.1e}"
    );
    assert!(plain_imbalance < 1e-2, "{plain_imbalance}");
    for truncated in [delta_imbalance, eddington_imbalance] {
        assert!(
            truncated <= plain_imbalance,
            "{truncated} against {plain_imbalance}"
        );
    }
    let (plain_error, delta_error, eddington_error) = (
        relative_l2(&plain, &reference),
        relative_l2(&delta, &reference),
        relative_l2(&eddington, &reference),
    );
    eprintln!(
        "S6 {plain_sweeps} iterations, error {plain_error:.2e}; delta-M {delta_sweeps}, {delta_error:.2e}; delta-Eddington {eddington_sweeps}, {eddington_error:.2e}"
    );
    assert!(
        10 * delta_sweeps <= 7 * plain_sweeps,
        "{delta_sweeps} against {plain_sweeps}"
    );
    assert!(
        delta_error <= plain_error,
        "{delta_error} against {plain_error}"
    );
    assert!(eddington_sweeps < delta_sweeps);
}

/// The truncated medium: σ_a = σ_t(1 − ω) unchanged per channel and cell, σ_s′ = (1 − f)σ_s,
/// a grey extinction under an RGB albedo becomes RGB, constants stay constants; and
/// `delta-m` with the octahedral family is refused, naming the parameter.
#[test]
fn the_truncated_medium_keeps_the_absorption_per_channel() {
    use lucent_core::{Field, Medium, ParamValue, Params, SolveError};
    let geometry = GridGeometry::from_bounds([3, 2, 2], DVec3::ZERO, DVec3::ONE).unwrap();
    let sigma = lucent_grid::Grid::from_fn(geometry, |p| (1.0 + 20.0 * p.x) as f32);
    let varying = lucent_grid::Grid::from_fn(geometry, |p| (0.5 + 0.4 * p.y) as f32);
    let medium = Medium {
        sigma_t: vec![sigma.clone()],
        albedo: vec![
            Field::Constant(0.99),
            Field::Grid(varying),
            Field::Constant(0.0),
        ],
        phase: Phase::henyey_greenstein(0.85).unwrap(),
    };
    let t = DeltaM::new(medium.phase, 4).unwrap();
    let f = t.fraction();
    let q = t.medium(&medium);
    assert_eq!(q.sigma_t.len(), 3);
    assert!(matches!(q.albedo[0], Field::Constant(_)));
    assert_eq!(q.phase, t.reduced_phase());
    for c in 0..3 {
        for i in 0..geometry.voxel_count() {
            let (t0, a0) = (
                f64::from(medium.sigma_t(c).data()[i]),
                f64::from(medium.albedo(c).at(i)),
            );
            let (t1, a1) = (
                f64::from(q.sigma_t(c).data()[i]),
                f64::from(q.albedo(c).at(i)),
            );
            // f32 storage: 1e-6 of σ_t.
            assert!(
                (t1 * (1.0 - a1) - t0 * (1.0 - a0)).abs() < 1e-6 * t0,
                "{c} {i}"
            );
            assert!((t1 * a1 - (1.0 - f) * t0 * a0).abs() < 1e-6 * t0, "{c} {i}");
        }
    }
    let mut p = Params::default();
    p.0.insert("family".into(), ParamValue::Text("octahedral".into()));
    p.0.insert("truncation".into(), ParamValue::Text("delta-m".into()));
    match lucent_dom::DomSolver::from_params(&p) {
        Err(SolveError::InvalidParameter { name, .. }) => assert_eq!(name, "truncation"),
        other => panic!("{other:?}"),
    }
    p.0.insert(
        "truncation".into(),
        ParamValue::Text("delta-eddington".into()),
    );
    assert!(lucent_dom::DomSolver::from_params(&p).is_ok());
}
