//! `DeviceMultigrid`: the device's V-cycle against the host's, on embedded-boundary
//! spheres (cut cells, jumps of D) and boxes, on grids whose sides are odd or not powers
//! of two (coarse levels with partial parents).

use glam::DVec3;
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, Cycle, DiffusionProblem, Discretisation, Multigrid,
    MultigridSettings,
};
use lucent_gpu::context_or_skip;
use lucent_gpu_solvers::DeviceMultigrid;
use lucent_grid::GridGeometry;

/// A sphere of radius 0.45 in the unit box (or the whole box), D jumping by `contrast`
/// across a tilted plane, σ_a = 0.3, Robin A = 2.341.
fn problem(dims: [usize; 3], sphere: bool, contrast: f32) -> DiffusionProblem {
    let grid = GridGeometry::from_bounds(dims, DVec3::ZERO, DVec3::ONE).unwrap();
    let centre = DVec3::new(0.51, 0.48, 0.503);
    let cells = if sphere {
        CellGeometry::from_sdf(
            grid,
            |p| (p - centre).length() - 0.45,
            Discretisation::EmbeddedBoundary,
        )
        .unwrap()
    } else {
        CellGeometry::full_box(grid)
    };
    let n = grid.voxel_count();
    let d = (0..n)
        .map(|c| {
            let [i, j, k] = grid.coords(c);
            let p = grid.cell_centre(i, j, k);
            if p.dot(DVec3::new(0.3, 0.2, 0.93)) > 0.6 {
                0.02
            } else {
                0.02 / contrast
            }
        })
        .collect();
    DiffusionProblem::new(
        cells,
        d,
        vec![0.3; n],
        Boundaries::uniform(Condition::Robin { a: 2.341 }),
    )
    .unwrap()
}

/// A deterministic right-hand side with every scale in it.
fn rhs(n: usize) -> Vec<f32> {
    (0..n)
        .map(|c| {
            let h = (c as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40;
            (h as f32 / (1u64 << 24) as f32) + if c % 97 == 0 { 5.0 } else { 0.0 }
        })
        .collect()
}

/// One V(2,2) cycle from zero on the device and on the host: the same smoother colours in
/// the same order, the same transfers and the same coarsest solve (the host's), in f32
/// on both sides. Only rounding differs (sums in another order in the host's vectorised
/// interior paths, and fused multiply-adds): a few units of f32 rounding (6e-8) per
/// operation, through about twenty sweeps and transfers of a contracting map. Asserted
/// to 1e-5 of the host cycle's largest value; a wrong coupling, colour, parent or sign
/// is of the order of the values themselves.
#[test]
fn the_device_cycle_is_the_host_cycle() {
    let Some(gpu) = context_or_skip("the_device_cycle_is_the_host_cycle") else {
        return;
    };
    for (dims, sphere, contrast) in [
        ([16, 16, 16], false, 1.0),
        ([13, 9, 11], true, 1.0),
        ([33, 20, 17], true, 1e3),
        ([40, 40, 40], true, 10.0),
    ] {
        let problem = problem(dims, sphere, contrast);
        let host = Multigrid::build(&problem, MultigridSettings::default()).unwrap();
        let b = rhs(host.fine_cells());
        let expected = host.cycle_from_zero(&b).unwrap();
        let mut device = DeviceMultigrid::new(&gpu, &host).unwrap();
        let got = device.cycle_from_zero(&b).unwrap();
        let scale = expected.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let difference = got
            .iter()
            .zip(&expected)
            .fold(0.0f32, |m, (a, e)| m.max((a - e).abs()))
            / scale;
        eprintln!(
            "{dims:?} sphere {sphere} contrast {contrast}: {} levels, difference {difference:.2e} of {scale:.3e}",
            host.depth()
        );
        assert!(scale > 0.0);
        assert!(difference < 1e-5, "{dims:?}: {difference}");
    }
}

/// What the device cycle does not run is refused with the reason, and vectors of the wrong
/// length with a typed error.
#[test]
fn other_cycles_are_refused() {
    let Some(gpu) = context_or_skip("other_cycles_are_refused") else {
        return;
    };
    let problem = problem([8, 8, 8], false, 1.0);
    for cycle in [Cycle::W, Cycle::F, Cycle::K] {
        let host = Multigrid::build(
            &problem,
            MultigridSettings {
                cycle,
                ..MultigridSettings::default()
            },
        )
        .unwrap();
        match DeviceMultigrid::new(&gpu, &host) {
            Err(e) => assert!(e.to_string().contains(&format!("{cycle:?} cycle")), "{e}"),
            Ok(_) => panic!("a {cycle:?}-cycle hierarchy was accepted"),
        }
    }
    // Vectors of the wrong length are a typed error, not a panic, on every entry.
    let host = Multigrid::build(&problem, MultigridSettings::default()).unwrap();
    let mut device = DeviceMultigrid::new(&gpu, &host).unwrap();
    let n = host.fine_cells();
    let stopping = lucent_core::Stopping::default();
    assert!(device.cycle_from_zero(&vec![1.0; n - 1]).is_err());
    assert!(device.full_multigrid(&vec![1.0; n + 1]).is_err());
    assert!(
        device
            .solve(&vec![1.0; n - 1], &mut vec![0.0; n - 1], &stopping)
            .is_err()
    );
    assert!(
        device
            .solve(&vec![1.0; n], &mut vec![0.0; n - 1], &stopping)
            .is_err()
    );
}

/// Full multigrid on the device against the host's (the nested iteration `diffusion-mg`
/// starts from by default): the right-hand side summed down, the coarsest solved, and one
/// V-cycle per level on the way up, in f32 on both sides. As for one cycle, only rounding
/// differs (about one cycle's worth per level): asserted to 1e-5 of the host's peak, where
/// a level skipped or a cycle started from the wrong guess is of the order of the values.
/// The host's start is its solve stopped before any cycle.
#[test]
fn device_full_multigrid_is_the_hosts() {
    use lucent_diffusion::Sources;
    let Some(gpu) = context_or_skip("device_full_multigrid_is_the_hosts") else {
        return;
    };
    let before_any_cycle = lucent_core::Stopping {
        max_iterations: 0,
        ..Default::default()
    };
    for (dims, sphere, contrast) in [
        ([16, 16, 16], false, 1.0),
        ([33, 20, 17], true, 1e3),
        ([40, 40, 40], true, 10.0),
    ] {
        let problem = problem(dims, sphere, contrast);
        let sources = Sources {
            points: vec![(DVec3::new(0.45, 0.5, 0.55), 1.0)],
            ..Sources::default()
        };
        let rhs = problem.rhs(&sources).unwrap();
        let host = Multigrid::build(&problem, MultigridSettings::default()).unwrap();
        let mut expected = vec![0.0; rhs.len()];
        let stopped = host.solve(&rhs, &mut expected, &before_any_cycle);
        assert_eq!(stopped.iterations(), 0);
        let mut device = DeviceMultigrid::new(&gpu, &host).unwrap();
        let got = device.full_multigrid(&rhs).unwrap();
        let scale = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let difference = got
            .iter()
            .zip(&expected)
            .fold(0.0f64, |m, (a, e)| m.max((f64::from(*a) - e).abs()))
            / scale;
        eprintln!("{dims:?}: full multigrid {difference:.2e} of {scale:.3e} apart");
        assert!(scale > 0.0);
        assert!(difference < 1e-5, "{dims:?}: {difference}");
    }
}

/// Solved to 1e-8 (relative residual) with the device's cycles inside the host's f64
/// outer iteration, against the host's own cycles from the same start (no full
/// multigrid): each correction differs by f32 rounding only (previous test), which the
/// outer iteration removes like any other error of a correction, so both stop on the
/// same cycle or one apart, at fluences within 1e-6 of each other (each within the
/// tolerance's 1e-8 of the residual times the operator's condition; measured 3e-15 to
/// 5e-15: both converge to the same f64 solution), and the device's solution balances its
/// sources as the host's does.
#[test]
fn device_cycles_solve_to_the_host_answer() {
    use lucent_diffusion::Sources;
    let Some(gpu) = context_or_skip("device_cycles_solve_to_the_host_answer") else {
        return;
    };
    let stopping = lucent_core::Stopping {
        relative_tolerance: 1e-8,
        max_iterations: 60,
        ..Default::default()
    };
    for (dims, contrast) in [([24, 19, 21], 1.0), ([33, 20, 17], 1e3)] {
        let problem = problem(dims, true, contrast);
        let sources = Sources {
            points: vec![(DVec3::new(0.45, 0.5, 0.55), 1.0)],
            ..Sources::default()
        };
        let rhs = problem.rhs(&sources).unwrap();
        let host = Multigrid::build(
            &problem,
            MultigridSettings {
                full_multigrid: false,
                ..MultigridSettings::default()
            },
        )
        .unwrap();
        let mut expected = vec![0.0; rhs.len()];
        let on_host = host.solve(&rhs, &mut expected, &stopping);
        let mut device = DeviceMultigrid::new(&gpu, &host).unwrap();
        let mut got = vec![0.0; rhs.len()];
        let on_device = device.solve(&rhs, &mut got, &stopping).unwrap();
        let scale = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let difference = got
            .iter()
            .zip(&expected)
            .fold(0.0f64, |m, (a, e)| m.max((a - e).abs()))
            / scale;
        eprintln!(
            "{dims:?} contrast {contrast}: {} cycles on the device, {} on the host; {difference:.1e} apart",
            on_device.iterations(),
            on_host.iterations()
        );
        assert!(
            on_device.stop_reason.is_converged(),
            "{:?}",
            on_device.stop_reason
        );
        assert!(
            on_device.iterations().abs_diff(on_host.iterations()) <= 1,
            "{} against {}",
            on_device.iterations(),
            on_host.iterations()
        );
        assert!(difference < 1e-6, "{dims:?}: {difference}");
        let balance = problem.balance(&sources, &got);
        assert!(balance.relative_imbalance() < 1e-6, "{balance:?}");
    }
}
