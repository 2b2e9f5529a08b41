//! `fem-p1-jacobi` through the registry: the study entry diverges, as the thesis found.

use lucent_core::{
    Boundary, Field, Light, Medium, ParamValue, Params, Problem, SolveOptions, Spectrum, StopReason,
};
use lucent_fem::FemP1Solver;
use lucent_grid::{Grid, GridGeometry};

fn problem(kt: f32) -> Problem {
    let geometry = GridGeometry::from_bounds([8; 3], Default::default(), [8.0; 3].into()).unwrap();
    let medium = Medium {
        sigma_t: vec![Grid::filled(geometry, kt)],
        albedo: vec![Field::Constant(0.0)],
        phase: lucent_optics::Phase::Isotropic,
        eta: 1.0,
    };
    let light = Light::Point {
        position: [4.5, 4.5, 4.5].into(),
        intensity: Spectrum::Grey(1.0),
    };
    Problem::new(geometry, medium, vec![light], Boundary::Vacuum, None).unwrap()
}

#[test]
fn jacobi_is_stopped_by_growth_and_gmres_converges() {
    // GMRES(60) converges where absorption holds the system (K_tΔ ≥ 1); at K_tΔ = 0.1 the
    // streaming-dominated, indefinite system stagnates it near 0.2 (measured), so only
    // Jacobi's divergence is checked there.
    for kt in [0.1f32, 1.0, 10.0] {
        let p = problem(kt);
        let jacobi = (FemP1Solver::ENTRY.build)(&Params::default())
            .unwrap()
            .solve(&p, &SolveOptions::default())
            .unwrap();
        assert!(
            matches!(jacobi.report.stop_reason, StopReason::DivergedGrowth { .. }),
            "K_t = {kt}: {:?}",
            jacobi.report.stop_reason
        );
        assert!(jacobi.fluence(0).data().iter().all(|v| v.is_finite()));
        if kt < 1.0 {
            continue;
        }
        let mut params = Params::default();
        params
            .0
            .insert("solver".into(), ParamValue::Text("gmres".into()));
        let gmres = (FemP1Solver::ENTRY.build)(&params)
            .unwrap()
            .solve(
                &p,
                &SolveOptions {
                    relative_tolerance: 1e-10,
                    ..SolveOptions::default()
                },
            )
            .unwrap();
        assert!(
            gmres.report.stop_reason.is_converged(),
            "{:?}",
            gmres.report.stop_reason
        );
        assert!(gmres.report.residual_history.len() > 2);
    }
}
