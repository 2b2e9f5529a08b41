//! `DeviceMultigrid`: the device's V-cycle against the host's, on embedded-boundary
//! spheres (cut cells, jumps of D) and boxes, on grids whose sides are odd or not powers
//! of two (coarse levels with partial parents).

use glam::DVec3;
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, Cycle, DiffusionProblem, Discretisation, Multigrid,
    MultigridSettings,
};
use lucent_gpu::context_or_skip;
use lucent_gpu_solvers::{DENSE_COARSEST_MAX, DeviceMultigrid, OuterIteration};
use lucent_grid::GridGeometry;

/// A sphere of radius 0.45 in the unit box (or the whole box), D jumping by `contrast`
/// across a tilted plane, σ_a = 0.3, Robin A = 2.341.
fn problem(dims: [usize; 3], sphere: bool, contrast: f32) -> DiffusionProblem {
    problem_in(dims, DVec3::ONE, sphere, contrast)
}

/// [`problem`] in the box [0, `corner`].
fn problem_in(dims: [usize; 3], corner: DVec3, sphere: bool, contrast: f32) -> DiffusionProblem {
    let grid = GridGeometry::from_bounds(dims, DVec3::ZERO, corner).unwrap();
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
    // The last two have one level (an axis of 3 cells does not coarsen): 12·12·3 = 432
    // unknowns, solved by the dense inverse, and 30·30·3 = 2700, more than the device
    // solves that way, by the host's coarsest solve.
    for (dims, sphere, contrast) in [
        ([16, 16, 16], false, 1.0),
        ([13, 9, 11], true, 1.0),
        ([33, 20, 17], true, 1e3),
        ([40, 40, 40], true, 10.0),
        ([12, 12, 3], false, 10.0),
        ([30, 30, 3], false, 10.0),
    ] {
        let problem = problem(dims, sphere, contrast);
        let host = Multigrid::build(&problem, MultigridSettings::default()).unwrap();
        let b = rhs(host.fine_cells());
        let expected = host.cycle_from_zero(&b).unwrap();
        let mut device = DeviceMultigrid::new(&gpu, &host).unwrap();
        // The coarsest level is solved on the device where it is small (and the device
        // has f64 for its inverse).
        let coarsest = host.levels().last().map_or(0, |l| l.dims.iter().product());
        assert_eq!(
            device.coarsest_on_device(),
            gpu.has_f64() && coarsest <= DENSE_COARSEST_MAX,
            "{dims:?}"
        );
        let got = device.cycle_from_zero(&b).unwrap();
        let scale = expected.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let difference = got
            .iter()
            .zip(&expected)
            .fold(0.0f32, |m, (a, e)| m.max((a - e).abs()))
            / scale;
        eprintln!(
            "{dims:?} sphere {sphere} contrast {contrast}: {} levels, coarsest on the device {}, difference {difference:.2e} of {scale:.3e}",
            host.depth(),
            device.coarsest_on_device()
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

/// Solved to 1e-8 (relative residual) with the device's cycles, the f64 outer iteration
/// on the device (φ, b and r in device memory, where the adapter has f64) and on the
/// host, with and without full multigrid, against the host's own solve with the same
/// settings: each correction differs by f32 rounding only (previous tests), which the
/// outer iteration removes like any other error of a correction, so both stop on the
/// same cycle or one apart, for the same reason, at fluences within 1e-6 of each other
/// (each within the tolerance's 1e-8 of the residual times the operator's condition;
/// measured 3e-15 to 5e-15: both converge to the same f64 solution). The residual
/// histories agree to 1e-3 per cycle while above 1e-7 (f32 cycles differ in the 7th
/// digit, and the error of a cycle's correction is that small a part of the residual it
/// leaves); and the device's solution balances its sources as the host's does.
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
    let outers: &[OuterIteration] = if gpu.has_f64() {
        &[OuterIteration::Device, OuterIteration::Host]
    } else {
        &[OuterIteration::Host]
    };
    // The first two coarsen to a few cells, solved on the device by their inverse (full
    // multigrid, start and first residual in one command buffer); a 72 × 72 × 8 slab of
    // cubic cells filled with the medium stops at 18 × 18 × 2, too many unknowns for that,
    // solved by the host between command buffers; 12 × 12 × 3 is one level.
    for (dims, sphere, contrast) in [
        ([24, 19, 21], true, 1.0),
        ([33, 20, 17], true, 1e3),
        ([72, 72, 8], false, 1.0),
        ([12, 12, 3], true, 1.0),
    ] {
        // The slab's cells are cubes; the spheres are in the unit box.
        let corner = match sphere {
            true => DVec3::ONE,
            false => DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64) / dims[0] as f64,
        };
        let problem = problem_in(dims, corner, sphere, contrast);
        let sources = Sources {
            points: vec![(DVec3::new(0.45, 0.5, 0.55) * corner, 1.0)],
            ..Sources::default()
        };
        let rhs = problem.rhs(&sources).unwrap();
        for full_multigrid in [false, true] {
            let host = Multigrid::build(
                &problem,
                MultigridSettings {
                    full_multigrid,
                    ..MultigridSettings::default()
                },
            )
            .unwrap();
            let mut expected = vec![0.0; rhs.len()];
            let on_host = host.solve(&rhs, &mut expected, &stopping);
            for &outer in outers {
                let mut device = DeviceMultigrid::new(&gpu, &host).unwrap();
                device.set_outer_iteration(outer).unwrap();
                assert_eq!(device.outer_iteration(), outer);
                let mut got = vec![0.0; rhs.len()];
                let on_device = device.solve(&rhs, &mut got, &stopping).unwrap();
                let scale = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let difference = got
                    .iter()
                    .zip(&expected)
                    .fold(0.0f64, |m, (a, e)| m.max((a - e).abs()))
                    / scale;
                eprintln!(
                    "{dims:?} contrast {contrast} fmg {full_multigrid} {outer:?}: {} cycles on the device, {} on the host; {difference:.1e} apart; residuals {:?} against {:?}",
                    on_device.iterations(),
                    on_host.iterations(),
                    on_device.residuals,
                    on_host.residuals
                );
                assert!(
                    on_device.stop_reason.is_converged(),
                    "{:?}",
                    on_device.stop_reason
                );
                assert_eq!(
                    std::mem::discriminant(&on_device.stop_reason),
                    std::mem::discriminant(&on_host.stop_reason)
                );
                assert!(
                    on_device.iterations().abs_diff(on_host.iterations()) <= 1,
                    "{} against {}",
                    on_device.iterations(),
                    on_host.iterations()
                );
                for (d, h) in on_device.residuals.iter().zip(&on_host.residuals) {
                    if *h > 1e-7 {
                        assert!((d - h).abs() <= 1e-3 * h, "{d:e} against {h:e}");
                    }
                }
                assert!(difference < 1e-6, "{dims:?}: {difference}");
                let balance = problem.balance(&sources, &got);
                assert!(balance.relative_imbalance() < 1e-6, "{balance:?}");
            }
        }
    }
}

/// The stop reasons other than convergence are the host's: an iteration limit after the
/// same cycles with the same residuals (to the f32 rounding of the cycles), divergence on
/// a right-hand side that is not finite, at once; with the outer iteration on the device
/// and on the host.
#[test]
fn device_solves_stop_for_the_hosts_reasons() {
    use lucent_core::{StopReason, Stopping};
    let Some(gpu) = context_or_skip("device_solves_stop_for_the_hosts_reasons") else {
        return;
    };
    let problem = problem([21, 18, 16], true, 10.0);
    let host = Multigrid::build(&problem, MultigridSettings::default()).unwrap();
    let n = host.fine_cells();
    let b: Vec<f64> = rhs(n).iter().map(|&v| f64::from(v)).collect();
    let limited = Stopping {
        relative_tolerance: 1e-14,
        max_iterations: 2,
        ..Default::default()
    };
    let mut nan = b.clone();
    nan[n / 2] = f64::NAN;
    for outer in [OuterIteration::Device, OuterIteration::Host] {
        let mut device = DeviceMultigrid::new(&gpu, &host).unwrap();
        if device.set_outer_iteration(outer).is_err() {
            assert!(!gpu.has_f64());
            continue;
        }
        let on_host = host.solve(&b, &mut vec![0.0; n], &limited);
        let on_device = device.solve(&b, &mut vec![0.0; n], &limited).unwrap();
        assert!(
            matches!(on_device.stop_reason, StopReason::IterationLimit { .. }),
            "{outer:?}: {:?}",
            on_device.stop_reason
        );
        assert_eq!(on_device.iterations(), 2);
        for (d, h) in on_device.residuals.iter().zip(&on_host.residuals) {
            assert!((d - h).abs() <= 1e-3 * h, "{outer:?}: {d:e} against {h:e}");
        }
        let on_host = host.solve(&nan, &mut vec![0.0; n], &Stopping::default());
        let on_device = device
            .solve(&nan, &mut vec![0.0; n], &Stopping::default())
            .unwrap();
        assert!(
            matches!(on_device.stop_reason, StopReason::DivergedNonFinite { .. }),
            "{outer:?}: {:?}",
            on_device.stop_reason
        );
        assert_eq!(on_device.stop_reason, on_host.stop_reason);
    }
}
