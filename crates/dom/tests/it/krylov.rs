//! The GMRES outer iteration (`Outer::Gmres`) against source iteration: the same answer on
//! every closure and boundary, and fewer sweeps than DSA alone where the first moments'
//! error is what is left (albedo 0.95, forward scattering).

use lucent_core::Stopping;
use lucent_dom::angular::Ordinates;
use lucent_dom::{
    Acceleration, Closure, DeltaM, DomBoundary, DomProblem, DomSettings, DomSolution, Outer, solve,
};
use lucent_optics::{Phase, SphericalQuadrature};

use crate::common;

use common::{glowing_cube, relative_l2};

/// The tests' scene (`common::glowing_cube`) at albedo 0.95 with HG scattering of mean
/// cosine `g`, swept with S6.
fn scene(
    cells: usize,
    sigma: f64,
    g: f64,
    cloud: bool,
    boundary: DomBoundary,
) -> (DomProblem, Ordinates) {
    let ordinates = Ordinates::new(
        SphericalQuadrature::level_symmetric(6).unwrap(),
        None,
        Phase::henyey_greenstein(g).unwrap(),
    )
    .unwrap();
    let m = ordinates.storage().len();
    (
        glowing_cube(cells, sigma, 0.95, cloud, m, boundary),
        ordinates,
    )
}

fn run(
    problem: &DomProblem,
    ordinates: &Ordinates,
    settings: DomSettings,
    tolerance: f64,
) -> DomSolution {
    let stopping = Stopping {
        relative_tolerance: tolerance,
        max_iterations: 200,
        ..Stopping::default()
    };
    let s = solve(problem, ordinates, &settings, &stopping).unwrap();
    assert!(
        s.convergence.stop_reason.is_converged(),
        "{settings:?}: {:?}",
        s.convergence
    );
    assert!(s.convergence.dsa_abandoned.is_none(), "{:?}", s.convergence);
    s
}

fn settings(outer: Outer, closure: Closure, anderson: usize) -> DomSettings {
    DomSettings {
        outer,
        closure,
        anderson,
        ..DomSettings::default()
    }
}

/// Both iterations converge to the same fixed point: every closure (diamond's fix-up and
/// the exponential closure's clamp are left out of the Krylov sweeps and settled by the
/// source-iteration steps after them), vacuum and a reflecting boundary under a sky
/// (which puts the inflow into the Krylov vectors). Both stop at 1e-8 of the scattering
/// source; their fluences agree to 1e-6 (an error of tolerance/(1 − ρ) each, ρ ≤ 0.6 with
/// DSA, and f32 storage of the source at 6e-8; measured 3e-9), and the energy balances to
/// 1e-6. The reference is source iteration with Anderson mixing: under the reflecting
/// boundary DSA alone stalls and is dropped. With diamond difference on the cloud the
/// fix-up acts where the linear sweep's answer goes negative, and the source iteration
/// after GMRES needs about twenty sweeps more (41 against 25 for source iteration alone).
#[test]
fn gmres_converges_to_the_source_iteration_answer() {
    let boundaries = [
        DomBoundary::default(),
        DomBoundary {
            radiance: 0.3,
            reflectance: 0.5,
        },
    ];
    for boundary in boundaries {
        for (closure, cloud) in [
            (Closure::Step, false),
            (Closure::Diamond, true),
            (Closure::Exponential, true),
        ] {
            let (problem, ordinates) = scene(12, 12.0, 0.6, cloud, boundary);
            let si = run(
                &problem,
                &ordinates,
                settings(Outer::SourceIteration, closure, 2),
                1e-8,
            );
            let krylov = run(
                &problem,
                &ordinates,
                settings(Outer::Gmres, closure, 0),
                1e-8,
            );
            let difference = relative_l2(&krylov.fluence, &si.fluence);
            eprintln!(
                "{closure:?} cloud {cloud} {boundary:?}: {} sweeps by source iteration, {} by GMRES, fluences {difference:.1e} apart",
                si.convergence.sweeps, krylov.convergence.sweeps
            );
            assert!(difference < 1e-6, "{closure:?} {boundary:?}: {difference}");
            // Where the boundary returns half the light, DSA (whose Robin condition only
            // approximates the transport reflection) contracts slowly and source iteration
            // with Anderson mixing needed 45–49 sweeps; GMRES 23–26 (measured).
            if boundary.reflectance > 0.0 {
                assert!(
                    3 * krylov.convergence.sweeps <= 2 * si.convergence.sweeps,
                    "{closure:?}: {} against {}",
                    krylov.convergence.sweeps,
                    si.convergence.sweeps
                );
            }
            assert!(
                krylov.balance.relative_imbalance() < 1e-6,
                "{:?}",
                krylov.balance
            );
        }
    }
}

/// Sweeps to 1e-6 at albedo 0.95 on 24³ cells (σ_t h = 0.5) with S6, the step closure
/// (linear, so the Krylov answer needs one confirming sweep): GMRES(12) with DSA against
/// source iteration with DSA alone and with Anderson mixing, homogeneous cube and cloud,
/// g = 0.6 and 0.9. Measured (2026-11-25): cube g = 0.6: 14 / 21 / 14; g = 0.9: 22 / 36 / 23;
/// cloud g = 0.6: 14 / 19 / 15. The bounds are the measured counts plus two, and GMRES
/// must beat DSA alone by a quarter. DSA leaves the first moments' error: the 12 sweeps
/// at g = 0.6 take TSA (`tsa_reaches_g_0_6_in_twelve_sweeps`).
#[test]
fn gmres_needs_fewer_sweeps_than_dsa_alone() {
    for (g, cloud, bound) in [(0.6, false, 16), (0.9, false, 24), (0.6, true, 16)] {
        let (problem, ordinates) = scene(24, 12.0, g, cloud, DomBoundary::default());
        let sweeps = |outer, anderson| {
            run(
                &problem,
                &ordinates,
                settings(outer, Closure::Step, anderson),
                1e-6,
            )
            .convergence
            .sweeps
        };
        let (krylov, dsa, mixed) = (
            sweeps(Outer::Gmres, 0),
            sweeps(Outer::SourceIteration, 0),
            sweeps(Outer::SourceIteration, 2),
        );
        eprintln!(
            "g = {g}, cloud {cloud}: GMRES {krylov}, DSA {dsa}, DSA + Anderson(2) {mixed} sweeps"
        );
        assert!(krylov <= bound, "g = {g}, cloud {cloud}: {krylov} sweeps");
        assert!(
            4 * krylov <= 3 * dsa,
            "g = {g}, cloud {cloud}: {krylov} against {dsa}"
        );
    }
}

/// Why source iteration stays the default: with diamond difference (the default closure)
/// the Krylov sweeps leave out the fix-up, the fix-up then moves the answer (the first
/// change after GMRES has converged), and settling that takes more sweeps than
/// source iteration with Anderson mixing needs from zero. Homogeneous 24³ cube, S6, to
/// 1e-6. Measured (2026-11-25): g = 0.6: GMRES 25, DSA 24, mixed 16, the fix-up's move
/// 1.4e-3; g = 0.9: 48, 42, 26, 2.6e-2. If GMRES ever takes no more sweeps than the
/// default here, the default should be measured again.
#[test]
fn with_diamond_difference_source_iteration_with_mixing_needs_fewer_sweeps() {
    for g in [0.6, 0.9] {
        let (problem, ordinates) = scene(24, 12.0, g, false, DomBoundary::default());
        let solve = |outer, anderson| {
            run(
                &problem,
                &ordinates,
                settings(outer, Closure::Diamond, anderson),
                1e-6,
            )
            .convergence
        };
        let (krylov, dsa, mixed) = (
            solve(Outer::Gmres, 0),
            solve(Outer::SourceIteration, 0),
            solve(Outer::SourceIteration, 2),
        );
        // The Krylov phase ends at its first residual below the tolerance; the next entry
        // is the first source-iteration step's change, the fix-up's move.
        let ended = krylov
            .residuals
            .iter()
            .position(|r| *r <= 1e-6)
            .expect("GMRES reached the tolerance");
        let moved = krylov.residuals.get(ended + 1).copied().unwrap_or(0.0);
        eprintln!(
            "diamond, g = {g}: GMRES {}, DSA {}, DSA + Anderson(2) {} sweeps; the fix-up moved the Krylov answer by {moved:.1e}",
            krylov.sweeps, dsa.sweeps, mixed.sweeps
        );
        assert!(moved > 1e-6, "g = {g}: the fix-up changed nothing");
        assert!(
            mixed.sweeps < krylov.sweeps,
            "g = {g}: GMRES {} against {} sweeps",
            krylov.sweeps,
            mixed.sweeps
        );
    }
}

/// A box that absorbs and does not scatter but returns half of the outgoing light: the
/// Krylov vectors hold only the inflow (σ_s = 0 everywhere), and GMRES must still reach
/// source iteration's answer (to 1e-6, both at 1e-8) and its energy balance.
#[test]
fn gmres_iterates_the_reflected_inflow_of_a_non_scattering_box() {
    let boundary = DomBoundary {
        radiance: 0.2,
        reflectance: 0.5,
    };
    let ordinates = Ordinates::new(
        SphericalQuadrature::level_symmetric(4).unwrap(),
        None,
        Phase::Isotropic,
    )
    .unwrap();
    let m = ordinates.storage().len();
    let problem = common::glowing_cube(10, 3.0, 0.0, true, m, boundary);
    let si = run(
        &problem,
        &ordinates,
        settings(Outer::SourceIteration, Closure::Diamond, 2),
        1e-8,
    );
    let krylov = run(
        &problem,
        &ordinates,
        settings(Outer::Gmres, Closure::Diamond, 0),
        1e-8,
    );
    let difference = relative_l2(&krylov.fluence, &si.fluence);
    eprintln!(
        "non-scattering reflecting box: {} sweeps by source iteration, {} by GMRES, fluences {difference:.1e} apart",
        si.convergence.sweeps, krylov.convergence.sweeps
    );
    assert!(difference < 1e-6, "{difference}");
    assert!(
        krylov.balance.relative_imbalance() < 1e-6,
        "{:?}",
        krylov.balance
    );
}

fn tsa(outer: Outer, sweeps: usize) -> DomSettings {
    DomSettings {
        acceleration: Acceleration::Tsa,
        tsa_sweeps: sweeps,
        ..settings(outer, Closure::Step, 0)
    }
}

/// The goal: 1e-6 at albedo 0.95 and g = 0.6 in at most 12 sweeps, on the 24³
/// cube and cloud of `gmres_needs_fewer_sweeps_than_dsa_alone` (where DSA alone needs 21
/// and 19, GMRES with DSA 14). TSA corrects the first moments' error that DSA leaves.
/// Measured (2026-11-26), sweeps (S2 sweeps): GMRES with TSA 10 (20) on both, source
/// iteration with TSA 11 (22) on both; GMRES with DSA 14. Asserted: at most 12, two S2
/// sweeps per sweep (8 directions each against 48), and the fluence of GMRES with DSA to
/// 3e-6 (each stops at 1e-6 of the source change, an error up to 1e-6/(1 − ρ) with
/// ρ ≤ 0.3 measured for both; measured 1.2e-7 to 3.1e-7).
#[test]
fn tsa_reaches_g_0_6_in_twelve_sweeps() {
    for cloud in [false, true] {
        let (problem, ordinates) = scene(24, 12.0, 0.6, cloud, DomBoundary::default());
        let reference = run(
            &problem,
            &ordinates,
            settings(Outer::Gmres, Closure::Step, 0),
            1e-6,
        );
        for outer in [Outer::Gmres, Outer::SourceIteration] {
            let s = run(&problem, &ordinates, tsa(outer, 2), 1e-6);
            let c = &s.convergence;
            let difference = relative_l2(&s.fluence, &reference.fluence);
            eprintln!(
                "g = 0.6, cloud {cloud}, {outer:?} with TSA: {} sweeps ({} of S2), GMRES with DSA {}; fluences {difference:.1e} apart",
                c.sweeps, c.low_order_sweeps, reference.convergence.sweeps
            );
            assert!(
                c.sweeps <= 12,
                "cloud {cloud}, {outer:?}: {} sweeps",
                c.sweeps
            );
            assert!(c.low_order_sweeps <= 2 * c.sweeps, "{c:?}");
            assert!(difference < 3e-6, "cloud {cloud}, {outer:?}: {difference}");
        }
    }
}

/// TSA's fixed point is the transport answer wherever DSA's is: under a sky with a
/// boundary that returns half the light (the S2 problem reflects with the same R), and
/// with sources stored on fewer directions than are swept (octahedral level 1, 32
/// directions, under S8's 80, where the projection onto P0 and P1 and the correction use
/// the storage set). Both outer iterations with TSA against source iteration with DSA and
/// Anderson mixing, all to 1e-8: fluences to 1e-6 (as in
/// `gmres_converges_to_the_source_iteration_answer`) and energy balances to 1e-6.
/// Measured (2026-11-26): 3e-9 to 6e-9 apart; reflecting, GMRES with TSA 17 sweeps and
/// source iteration with TSA (unmixed) 45 against 37; stored, 14 and 17 against 23.
#[test]
fn tsa_converges_to_the_transport_answer_under_reflection_and_on_stored_directions() {
    let reflecting = DomBoundary {
        radiance: 0.3,
        reflectance: 0.5,
    };
    let stored = Ordinates::new(
        SphericalQuadrature::level_symmetric(8).unwrap(),
        Some(SphericalQuadrature::octahedral(1).unwrap()),
        Phase::henyey_greenstein(0.6).unwrap(),
    )
    .unwrap();
    let m = stored.storage().len();
    let cases = [
        ("reflecting", scene(12, 12.0, 0.6, true, reflecting)),
        (
            "stored on 32 directions",
            (
                glowing_cube(12, 12.0, 0.95, true, m, DomBoundary::default()),
                stored,
            ),
        ),
    ];
    for (name, (problem, ordinates)) in cases {
        let reference = run(
            &problem,
            &ordinates,
            settings(Outer::SourceIteration, Closure::Step, 2),
            1e-8,
        );
        for outer in [Outer::Gmres, Outer::SourceIteration] {
            let s = run(&problem, &ordinates, tsa(outer, 2), 1e-8);
            let difference = relative_l2(&s.fluence, &reference.fluence);
            eprintln!(
                "{name}, {outer:?} with TSA: {} sweeps ({} of S2) against {}; fluences {difference:.1e} apart",
                s.convergence.sweeps, s.convergence.low_order_sweeps, reference.convergence.sweeps
            );
            assert!(difference < 1e-6, "{name}, {outer:?}: {difference}");
            assert!(
                s.balance.relative_imbalance() < 1e-6,
                "{name}, {outer:?}: {:?}",
                s.balance
            );
        }
    }
}

/// At g = 0.9 the error left after DSA is mostly in the second and higher moments
/// (contracting by about ωg² = 0.77 per sweep), which S2 cannot carry: TSA saves little,
/// and delta-M is what removes them (the forward peak moved into the uncollided light,
/// g* = 0.787 on S6). GMRES to 1e-6 on the 24³ cube and cloud. Measured (2026-11-26),
/// sweeps with DSA / with TSA: cube 22 / 22 without truncation, 14 / 12 with delta-M;
/// cloud 20 / 20, 13 / 12. Asserted: with delta-M and TSA at most 13 and at most 0.65 of
/// the untruncated DSA count; without truncation TSA within one sweep of DSA (the
/// statement that it does not help there, which a better low-order operator would change).
#[test]
fn at_g_0_9_delta_m_removes_what_tsa_cannot() {
    for cloud in [false, true] {
        let phase = Phase::henyey_greenstein(0.9).unwrap();
        let truncation = DeltaM::new(phase, 6).unwrap();
        let ordinates = |phase| {
            Ordinates::new(
                SphericalQuadrature::level_symmetric(6).unwrap(),
                None,
                phase,
            )
            .unwrap()
        };
        let (full, reduced) = (ordinates(phase), ordinates(truncation.reduced_phase()));
        let problem = glowing_cube(24, 12.0, 0.95, cloud, 48, DomBoundary::default());
        let truncated = truncation.apply(&problem);
        let sweeps = |problem: &DomProblem, ordinates: &Ordinates, s| {
            run(problem, ordinates, s, 1e-6).convergence.sweeps
        };
        let dsa_settings = settings(Outer::Gmres, Closure::Step, 0);
        let counts = [
            sweeps(&problem, &full, dsa_settings),
            sweeps(&problem, &full, tsa(Outer::Gmres, 2)),
            sweeps(&truncated, &reduced, dsa_settings),
            sweeps(&truncated, &reduced, tsa(Outer::Gmres, 2)),
        ];
        eprintln!(
            "g = 0.9, cloud {cloud}: GMRES sweeps with DSA / TSA {} / {}, with delta-M {} / {}",
            counts[0], counts[1], counts[2], counts[3]
        );
        assert!(counts[3] <= 13, "cloud {cloud}: {counts:?}");
        assert!(
            20 * counts[3] <= 13 * counts[0],
            "cloud {cloud}: {counts:?}"
        );
        assert!(counts[1] + 1 >= counts[0], "cloud {cloud}: {counts:?}");
    }
}

/// `acceleration = "tsa"` and `tsa_sweeps` through the registry: accepted with a count of
/// 1 to 8, refused outside it with an error naming the key (0 sweeps would correct
/// nothing, and more than 8 cost more than the S6 sweep they accelerate).
#[test]
fn the_registry_takes_tsa_and_bounds_its_sweeps() {
    use lucent_core::{ParamValue, Params, SolveError};
    let params = |sweeps: i64| {
        let mut p = Params::default();
        p.0.insert("acceleration".into(), ParamValue::Text("tsa".into()));
        p.0.insert("tsa_sweeps".into(), ParamValue::Int(sweeps));
        p
    };
    for sweeps in [1, 8] {
        assert!(lucent_dom::DomSolver::from_params(&params(sweeps)).is_ok());
    }
    for sweeps in [0, 9] {
        match lucent_dom::DomSolver::from_params(&params(sweeps)) {
            Err(SolveError::InvalidParameter { name, .. }) => assert_eq!(name, "tsa_sweeps"),
            other => panic!("tsa_sweeps = {sweeps}: {:?}", other.map(|_| ())),
        }
    }
}

/// TSA in optically thick cells, where DSA with lucent-diffusion's operator stops working
/// (`inconsistent_dsa_fails_in_thick_cells_and_mixing_recovers`): a homogeneous 16³ cube
/// at albedo 0.99, S4, g = 0.6, glowing everywhere, to 1e-6, no mixing. Measured
/// (2026-11-26): diamond at σ_t h = 2, source iteration with TSA 14 sweeps where with DSA
/// alone DSA is dropped and 150 sweeps do not converge, GMRES with TSA 12 (with DSA 23);
/// exponential at σ_t h = 4, source iteration with TSA 11 (DSA 17), GMRES 9 (DSA 12). At
/// σ_t h = 8 GMRES with TSA needed 142 sweeps against 14 with DSA (the S2 problem's own
/// DSA amplifies there), so TSA refuses cells thicker than 4, naming itself. Asserted:
/// the measured counts plus two, and the fluence of GMRES with DSA to 1e-5 (each stops at
/// 1e-6 of the source change with ρ up to 0.6 measured for DSA: errors up to 2.5e-6
/// each, and f32 storage at albedo 0.99 amplifies rounding up to 100 times).
#[test]
fn tsa_works_in_thick_cells_up_to_four_mean_free_paths_and_refuses_thicker() {
    use glam::DVec3;
    use lucent_grid::GridGeometry;
    let cube = |sigma: f32, m: usize| {
        let geometry = GridGeometry::from_bounds([16; 3], DVec3::ZERO, DVec3::ONE).unwrap();
        let n = geometry.voxel_count();
        DomProblem {
            geometry,
            sigma_t: vec![sigma; n],
            sigma_s: vec![sigma * 0.99; n],
            fixed: vec![1.0; n * m],
            boundary: DomBoundary::default(),
        }
    };
    let ordinates = Ordinates::new(
        SphericalQuadrature::level_symmetric(4).unwrap(),
        None,
        Phase::henyey_greenstein(0.6).unwrap(),
    )
    .unwrap();
    let m = ordinates.storage().len();
    let with = |closure, outer, acceleration| DomSettings {
        closure,
        outer,
        acceleration,
        anderson: 0,
        ..DomSettings::default()
    };
    for (closure, sigma, si_most, gmres_most) in [
        (Closure::Diamond, 32.0, 16, 14),
        (Closure::Exponential, 64.0, 13, 11),
    ] {
        let problem = cube(sigma, m);
        let reference = run(
            &problem,
            &ordinates,
            with(closure, Outer::Gmres, Acceleration::Dsa),
            1e-6,
        );
        for (outer, most) in [
            (Outer::SourceIteration, si_most),
            (Outer::Gmres, gmres_most),
        ] {
            let s = run(
                &problem,
                &ordinates,
                with(closure, outer, Acceleration::Tsa),
                1e-6,
            );
            let difference = relative_l2(&s.fluence, &reference.fluence);
            eprintln!(
                "{closure:?}, σ_t h = {}: {outer:?} with TSA {} sweeps, GMRES with DSA {}; {difference:.1e} apart",
                sigma / 16.0,
                s.convergence.sweeps,
                reference.convergence.sweeps
            );
            assert!(
                s.convergence.sweeps <= most,
                "{closure:?} {outer:?}: {:?}",
                s.convergence
            );
            assert!(difference < 1e-5, "{closure:?} {outer:?}: {difference}");
        }
    }
    let refused = solve(
        &cube(128.0, m),
        &ordinates,
        &with(Closure::Exponential, Outer::Gmres, Acceleration::Tsa),
        &Stopping::default(),
    );
    match refused {
        Err(lucent_dom::DomError::Invalid(why)) => assert!(why.contains("tsa"), "{why}"),
        other => panic!("σ_t h = 8 with TSA: {:?}", other.map(|s| s.convergence)),
    }
}
