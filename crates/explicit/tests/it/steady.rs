//! The steady states of FTCS and Jacobi equal diffusion-mg's on the same discrete problem.

use glam::DVec3;
use lucent_core::Stopping;
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, DiffusionProblem, Discretisation, Method, Sources, solve,
};
use lucent_explicit::ExplicitError;
use lucent_explicit::steady::{Iteration, SteadySettings, ftcs_limit, iterate};
use lucent_grid::GridGeometry;

#[test]
fn ftcs_and_jacobi_reach_the_multigrid_solution() {
    // A 12³ box of heterogeneous marble-like medium around an embedded sphere, Robin
    // boundary, a point source; both explicit iterations run to 1e-9 and must agree with
    // multigrid (1e-11) to 1e-5 relative in L2: the residual bound times the condition
    // number (~1e3 here) leaves a margin of 100.
    let grid = GridGeometry::from_bounds([12; 3], DVec3::splat(-3.0), DVec3::splat(3.0)).unwrap();
    let cells =
        CellGeometry::from_sdf(grid, |p| p.length() - 2.7, Discretisation::EmbeddedBoundary)
            .unwrap();
    let n = grid.voxel_count();
    let d: Vec<f32> = (0..n).map(|c| 0.1 + 0.1 * ((c * 7) % 5) as f32).collect();
    let problem = DiffusionProblem::new(
        cells,
        d,
        vec![0.05; n],
        Boundaries::uniform(Condition::Robin { a: 2.341 }),
    )
    .unwrap();
    let sources = Sources {
        points: vec![(DVec3::new(0.2, -0.1, 0.3), 1.0)],
        ..Sources::default()
    };
    let reference = solve(
        &problem,
        &sources,
        Method::default(),
        &Stopping {
            relative_tolerance: 1e-11,
            ..Stopping::default()
        },
    )
    .unwrap();
    let system = problem.assemble(&sources).unwrap();
    let exact: Vec<f64> = system.cells.iter().map(|&c| reference.fluence[c]).collect();
    let norm = exact.iter().map(|v| v * v).sum::<f64>().sqrt();
    let settings = SteadySettings {
        stopping: Stopping {
            relative_tolerance: 1e-9,
            max_iterations: 200_000,
            ..Stopping::default()
        },
        allow_unstable: false,
    };
    let volume = grid.cell_volume();
    for iteration in [
        Iteration::Ftcs {
            time_step: 0.95 * ftcs_limit(&system, volume),
            cell_volume: volume,
        },
        Iteration::Jacobi { omega: 1.0 },
    ] {
        let out = iterate(&system, grid.dims(), iteration, &settings).unwrap();
        assert!(
            out.stop_reason.is_converged(),
            "{iteration:?}: {:?}",
            out.stop_reason
        );
        let error = out
            .fluence
            .iter()
            .zip(&exact)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt()
            / norm;
        assert!(
            error < 1e-5,
            "{iteration:?}: {error} after {} sweeps",
            out.residuals.len()
        );
    }
    // Beyond the step bound: refused.
    let too_big = Iteration::Ftcs {
        time_step: 1.1 * ftcs_limit(&system, volume),
        cell_volume: volume,
    };
    assert!(matches!(
        iterate(&system, grid.dims(), too_big, &settings),
        Err(ExplicitError::Unstable { .. })
    ));
}
