//! Multigrid on ranks (`Multigrid::solve_on_ranks`) against the serial solve, on in-process
//! ranks: the same bits for every rank count, and the serial φ to rounding with the same
//! cycle count ± 1, across grids whose sizes are not powers of two, media that fill the box
//! or sit inside it, jumps of D, every cycle, both smoothers and both prolongations.

use glam::DVec3;
use lucent_core::Stopping;
use lucent_core::ranks::{Communicator, Threads};
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, Convergence, Cycle, DiffusionError, DiffusionProblem,
    Discretisation, Multigrid, MultigridSettings, Prolongation, Smoother, Sources,
};
use lucent_grid::GridGeometry;
use proptest::prelude::*;

/// A scene: grid dims, whether an embedded sphere holds the medium (else it fills the box),
/// the contrast of D between blocks, and the box's condition.
#[derive(Debug, Clone, Copy)]
struct Scene {
    dims: [usize; 3],
    sphere: bool,
    contrast: f32,
    dirichlet_box: bool,
}

fn system(scene: Scene) -> (DiffusionProblem, Vec<f64>) {
    let size = DVec3::from_array(scene.dims.map(|n| n as f64)) * 0.5;
    let grid = GridGeometry::from_bounds(scene.dims, -size * 0.5, size * 0.5).unwrap();
    let radius = size.min_element() * 0.45;
    let sdf = move |p: DVec3| {
        if scene.sphere {
            (p - DVec3::new(0.11, -0.07, 0.05)).length() - radius
        } else {
            -1.0
        }
    };
    let cells = CellGeometry::from_sdf(grid, sdf, Discretisation::EmbeddedBoundary).unwrap();
    let n = grid.voxel_count();
    let d = (0..n)
        .map(|c| {
            let [i, j, k] = grid.coords(c);
            let b = (grid.cell_centre(i, j, k) / 1.5).floor();
            let h =
                (b.x as i64 * 73_856_093) ^ (b.y as i64 * 19_349_663) ^ (b.z as i64 * 83_492_791);
            if (h as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 63 == 1 {
                0.15
            } else {
                0.15 / scene.contrast
            }
        })
        .collect();
    let boundaries = if scene.dirichlet_box {
        let mut b = Boundaries::uniform(Condition::Robin { a: 2.341 });
        b.faces = [Condition::Dirichlet { value: 0.0 }; 6];
        b
    } else {
        Boundaries::uniform(Condition::Robin { a: 2.341 })
    };
    let problem = DiffusionProblem::new(cells, d, vec![0.01; n], boundaries).unwrap();
    let sources = Sources {
        points: vec![(DVec3::new(0.3, -0.2, 0.4), 1.0)],
        ..Sources::default()
    };
    let rhs = problem.rhs(&sources).unwrap();
    (problem, rhs)
}

fn stopping() -> Stopping {
    Stopping {
        relative_tolerance: 1e-9,
        max_iterations: 80,
        ..Stopping::default()
    }
}

/// The solve on `ranks` in-process ranks: every rank's (φ, history), which must agree.
fn on_ranks(
    mg: &Multigrid,
    rhs: &[f64],
    ranks: usize,
) -> Result<(Vec<f64>, Convergence), DiffusionError> {
    let results: Vec<Result<(Vec<f64>, Convergence), DiffusionError>> = std::thread::scope(|s| {
        let handles: Vec<_> = Threads::world(ranks)
            .into_iter()
            .map(|comm| {
                s.spawn(move || {
                    let mut phi = vec![0.0; rhs.len()];
                    let c = mg.solve_on_ranks(rhs, &mut phi, &stopping(), &comm)?;
                    assert_eq!(comm.size(), ranks);
                    Ok((phi, c))
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let first = results[0].clone()?;
    for (rank, other) in results.into_iter().enumerate().skip(1) {
        let other = other?;
        assert_eq!(other.1, first.1, "rank {rank}'s history");
        assert!(
            other
                .0
                .iter()
                .zip(&first.0)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "rank {rank}'s φ"
        );
    }
    Ok(first)
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Ranks 1..=max against each other (bits) and against the serial solve (φ to 1e-10
/// relative, cycles ± 1).
fn check(scene: Scene, settings: MultigridSettings, max_ranks: usize) {
    let (problem, rhs) = system(scene);
    let mg = Multigrid::build(&problem, settings).unwrap();
    let mut serial = vec![0.0; rhs.len()];
    let expected = mg.solve(&rhs, &mut serial, &stopping());
    assert!(
        expected.stop_reason.is_converged(),
        "{scene:?} {settings:?}: {expected:?}"
    );
    let (one, history) = on_ranks(&mg, &rhs, 1).unwrap();
    // The same cells and arithmetic as the serial cycles; only the norm's grouping differs
    // (layer sums with each layer's outside cells, against spans then outside), which may
    // move the history in the last bits and a tolerance one cycle: the bound is 1e-10 of
    // max |φ| and ± 1 cycle (every case here measured 0 difference and equal counts).
    let scale = serial.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let worst = serial
        .iter()
        .zip(&one)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(
        worst <= 1e-10 * scale,
        "{scene:?} {settings:?}: {worst:e} of {scale:e}"
    );
    assert!(
        expected.iterations().abs_diff(history.iterations()) <= 1,
        "{scene:?} {settings:?}: {} serial, {} on one rank",
        expected.iterations(),
        history.iterations()
    );
    for ranks in 2..=max_ranks {
        match on_ranks(&mg, &rhs, ranks) {
            Ok((phi, h)) => {
                assert_eq!(h, history, "{scene:?} {settings:?} on {ranks} ranks");
                assert_eq!(
                    bits(&phi),
                    bits(&one),
                    "{scene:?} {settings:?} on {ranks} ranks"
                );
            }
            Err(e) => panic!("{scene:?} on {ranks} ranks: {e}"),
        }
    }
}

#[test]
fn every_cycle_smoother_and_prolongation_gives_the_one_rank_bits_on_four_ranks() {
    let scene = Scene {
        dims: [13, 11, 37],
        sphere: true,
        contrast: 30.0,
        dirichlet_box: false,
    };
    for cycle in [Cycle::V, Cycle::W, Cycle::F, Cycle::K] {
        check(
            scene,
            MultigridSettings {
                cycle,
                ..MultigridSettings::default()
            },
            4,
        );
    }
    check(
        scene,
        MultigridSettings {
            smoother: Smoother::Jacobi { omega: 6.0 / 7.0 },
            prolongation: Prolongation::Trilinear,
            full_multigrid: false,
            ..MultigridSettings::default()
        },
        4,
    );
    check(
        scene,
        MultigridSettings {
            prolongation: Prolongation::Trilinear,
            pre_sweeps: 1,
            post_sweeps: 3,
            ..MultigridSettings::default()
        },
        3,
    );
}

#[test]
fn a_medium_filling_the_box_with_dirichlet_faces() {
    check(
        Scene {
            dims: [9, 14, 22],
            sphere: false,
            contrast: 1.0,
            dirichlet_box: true,
        },
        MultigridSettings::default(),
        5,
    );
}

#[test]
fn more_ranks_than_layers_is_a_typed_error() {
    let (problem, rhs) = system(Scene {
        dims: [8, 8, 3],
        sphere: false,
        contrast: 1.0,
        dirichlet_box: false,
    });
    let mg = Multigrid::build(&problem, MultigridSettings::default()).unwrap();
    let e = on_ranks(&mg, &rhs, 4).unwrap_err();
    assert!(matches!(e, DiffusionError::Ranks(_)), "{e}");
    assert!(e.to_string().contains("4 ranks for 3 z-layers"), "{e}");
}

#[test]
fn the_layout_keeps_coarse_cells_on_one_rank() {
    // Bounds are multiples of 2^d (a coarse cell's children on one rank), cover the layers
    // in order, and each rank keeps ≥ 2 layers on its coarsest distributed level.
    for (n_z, depth, ranks) in [(37, 4, 4), (64, 5, 2), (22, 3, 5), (1000, 8, 64), (9, 2, 9)] {
        let layout = lucent_diffusion::RankLayout::new(n_z, depth, ranks, Cycle::V).unwrap();
        let d = layout.distributed_levels;
        assert!(d < depth);
        assert_eq!(layout.layers.first().unwrap().0, 0);
        assert_eq!(layout.layers.last().unwrap().1, n_z);
        for w in layout.layers.windows(2) {
            assert_eq!(w[0].1, w[1].0);
            assert_eq!(w[0].1 % (1 << d), 0, "{n_z} {depth} {ranks}: {layout:?}");
        }
        if d > 0 {
            for r in 0..ranks {
                assert!(
                    layout.owned(r, d - 1).len() >= 2,
                    "{n_z} {depth} {ranks}: {layout:?}"
                );
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 6, ..ProptestConfig::default() })]
    #[test]
    fn random_grids_give_the_one_rank_bits(
        nx in 5usize..14, ny in 5usize..14, nz in 8usize..30,
        sphere in any::<bool>(), contrast in 1.0f32..100.0, ranks in 2usize..4,
    ) {
        check(
            Scene { dims: [nx, ny, nz], sphere, contrast, dirichlet_box: !sphere },
            MultigridSettings::default(),
            ranks,
        );
    }
}
