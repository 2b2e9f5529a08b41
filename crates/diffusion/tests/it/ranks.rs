//! Multigrid on ranks (`Multigrid::solve_on_ranks`) against the serial solve, on in-process
//! ranks: the serial solve's bits (history, stop and φ) for every rank count, over z-slabs
//! and over grids of boxes (cut along one, two and three axes), across grids whose sizes
//! are not powers of two, media that fill the box or sit inside it, jumps of D, every
//! cycle, both smoothers and both prolongations.

use glam::DVec3;
use lucent_core::Stopping;
use lucent_core::ranks::{Communicator, Threads};
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, Convergence, Cycle, Decomposition, DiffusionError,
    DiffusionProblem, Discretisation, Multigrid, MultigridSettings, Prolongation, RankLayout,
    Region, Smoother, Sources, Stage,
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

/// Coarse levels agglomerated below these cells per rank: 0 splits every level as far as
/// its layers allow (the most stages and hand-overs on these small grids), 64 mixes split
/// and agglomerated levels, the default agglomerates most of them here.
const THRESHOLDS: [usize; 3] = [0, 64, RankLayout::COARSE_CELLS_PER_RANK];

/// The solve on `ranks` in-process ranks cut as `decomposition`, coarse levels
/// agglomerated below `threshold` cells per rank: every rank's (φ, history), which must
/// agree.
fn on_ranks(
    mg: &Multigrid,
    rhs: &[f64],
    ranks: usize,
    threshold: usize,
    decomposition: Decomposition,
) -> Result<(Vec<f64>, Convergence), DiffusionError> {
    let results: Vec<Result<(Vec<f64>, Convergence), DiffusionError>> = std::thread::scope(|s| {
        let handles: Vec<_> = Threads::world(ranks)
            .into_iter()
            .map(|comm| {
                s.spawn(move || {
                    let mut phi = vec![0.0; rhs.len()];
                    let layout = mg.layout(ranks, threshold, decomposition)?;
                    let c = mg.solve_on_layout(rhs, &mut phi, &stopping(), &comm, layout)?;
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

/// Ranks 1..=max, over slabs and over boxes, against each other and against the serial
/// solve: the same bits.
fn check(scene: Scene, settings: MultigridSettings, max_ranks: usize) {
    let grids: Vec<Decomposition> = (2..=max_ranks).map(|_| Decomposition::Boxes).collect();
    check_on(scene, settings, max_ranks, &grids);
}

/// [`check`] over slabs on 2..=`max_ranks` ranks, then over each of `boxes` (on the ranks
/// a grid names, or 2..=`max_ranks` for [`Decomposition::Boxes`]).
fn check_on(scene: Scene, settings: MultigridSettings, max_ranks: usize, boxes: &[Decomposition]) {
    let (problem, rhs) = system(scene);
    let mg = Multigrid::build(&problem, settings).unwrap();
    let mut serial = vec![0.0; rhs.len()];
    let expected = mg.solve(&rhs, &mut serial, &stopping());
    assert!(
        expected.stop_reason.is_converged(),
        "{scene:?} {settings:?}: {expected:?}"
    );
    let (one, history) = on_ranks(&mg, &rhs, 1, 0, Decomposition::Slabs).unwrap();
    // The same cells and arithmetic as the serial cycles, and the same norm (runs of eight
    // cells along x, their sums added exactly, whatever rank holds them): the serial
    // history, stop and φ to the bit.
    assert_eq!(history, expected, "{scene:?} {settings:?}");
    assert_eq!(bits(&one), bits(&serial), "{scene:?} {settings:?}");
    let slabs = (2..=max_ranks).map(|r| (r, Decomposition::Slabs));
    let boxes = boxes.iter().enumerate().map(|(i, &d)| match d {
        Decomposition::Grid(g) => (g.iter().product(), d),
        _ => (2 + i % (max_ranks - 1).max(1), d),
    });
    for (ranks, decomposition) in slabs.chain(boxes) {
        for threshold in THRESHOLDS {
            let case = format!(
                "{scene:?} {settings:?} on {ranks} ranks as {decomposition:?}, {threshold} cells"
            );
            match on_ranks(&mg, &rhs, ranks, threshold, decomposition) {
                Ok((phi, h)) => {
                    assert_eq!(h, history, "{case}");
                    assert_eq!(bits(&phi), bits(&one), "{case}");
                }
                Err(e) => panic!("{case}: {e}"),
            }
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
fn boxes_cut_along_every_axis_give_the_one_rank_bits() {
    // Grids cut along x (in norm runs of 8), y and z, alone and together, up to 12 boxes,
    // and the grid the layout picks: the halo crosses faces (smoothing, residuals), and
    // for trilinear prolongation edges and corners; the hand-overs move boxes onto fewer
    // ranks. Every cycle, both smoothers and both prolongations.
    use Decomposition::{Boxes, Grid};
    let grids = [
        Grid([2, 1, 1]),
        Grid([1, 3, 1]),
        Grid([2, 2, 1]),
        Grid([1, 2, 2]),
        Grid([2, 2, 2]),
        Grid([2, 3, 2]),
        Boxes,
    ];
    let settings = [
        MultigridSettings::default(),
        MultigridSettings {
            prolongation: Prolongation::Trilinear,
            full_multigrid: false,
            ..MultigridSettings::default()
        },
        MultigridSettings {
            smoother: Smoother::Jacobi { omega: 6.0 / 7.0 },
            prolongation: Prolongation::Trilinear,
            ..MultigridSettings::default()
        },
        MultigridSettings {
            cycle: Cycle::W,
            ..MultigridSettings::default()
        },
        MultigridSettings {
            cycle: Cycle::F,
            prolongation: Prolongation::Trilinear,
            ..MultigridSettings::default()
        },
        MultigridSettings {
            cycle: Cycle::K,
            ..MultigridSettings::default()
        },
    ];
    let scene = Scene {
        dims: [20, 18, 14],
        sphere: true,
        contrast: 30.0,
        dirichlet_box: false,
    };
    for settings in settings {
        check_on(scene, settings, 2, &grids);
    }
    // A medium that fills the box (every box face a cut through the medium), grids of odd
    // sizes.
    check_on(
        Scene {
            dims: [27, 13, 11],
            sphere: false,
            contrast: 5.0,
            dirichlet_box: true,
        },
        MultigridSettings {
            prolongation: Prolongation::Trilinear,
            ..MultigridSettings::default()
        },
        2,
        &[Grid([3, 1, 1]), Grid([1, 2, 3]), Grid([3, 2, 2]), Boxes],
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
fn ranks_beyond_half_the_layers_wait_and_the_rest_split_the_grid() {
    // 5 layers: the fine level goes to 2 ranks (two layers or more each); ranks 2–4 own
    // nothing, take part in the norms' gathers only, and get the whole φ.
    check(
        Scene {
            dims: [12, 10, 5],
            sphere: true,
            contrast: 10.0,
            dirichlet_box: false,
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
    let e = on_ranks(&mg, &rhs, 4, 0, Decomposition::Slabs).unwrap_err();
    assert!(matches!(e, DiffusionError::Ranks(_)), "{e}");
    assert!(e.to_string().contains("4 ranks for 3 z-layers"), "{e}");
    // Boxes split the same grid over 4 ranks; a grid that is not one box per rank, or
    // that cuts x into boxes narrower than a norm run, is an error.
    assert!(on_ranks(&mg, &rhs, 4, 0, Decomposition::Boxes).is_ok());
    for grid in [[1, 2, 1], [2, 2, 1]] {
        let e = on_ranks(&mg, &rhs, 4, 0, Decomposition::Grid(grid)).unwrap_err();
        assert!(matches!(e, DiffusionError::Ranks(_)), "{grid:?}: {e}");
    }
}

/// The levels' dims of a hierarchy of `depth` levels over a fine grid `dims`.
fn level_dims(dims: [usize; 3], depth: usize) -> Vec<[usize; 3]> {
    std::iter::successors(Some(dims), |d| {
        Some(d.map(|n| if n == 1 { 1 } else { n.div_ceil(2) }))
    })
    .take(depth)
    .collect()
}

/// The checks every layout must pass: stages follow each other down to the coarsest level,
/// which is rank 0's alone; rank counts never grow; each stage's cuts cover each axis of
/// its first level in order with inner cuts in whole units of 2^levels (a coarse cell's
/// children on one rank, down to the next stage), x's on the fine level in norm runs of
/// 8; every rank keeps a unit on each level of its stage, and a coarse level the
/// threshold's cells per rank; the boxes of a stage restrict to boxes that tile the next
/// level.
fn check_layout(layout: &RankLayout, levels: &[[usize; 3]], ranks: usize, threshold: usize) {
    let case = format!("{:?} on {ranks} ranks, {threshold}: {layout:?}", levels[0]);
    let depth = levels.len();
    let last = layout.stages.last().unwrap();
    assert_eq!(last.ranks(), 1, "{case}");
    assert_eq!(last.first_level + last.levels, depth, "{case}");
    let mut level = 0;
    let mut previous = ranks;
    for stage in &layout.stages {
        assert_eq!(stage.first_level, level, "{case}");
        assert!(stage.ranks() <= previous && stage.levels > 0, "{case}");
        previous = stage.ranks();
        let dims = levels[level];
        for (a, cuts) in stage.cuts.iter().enumerate() {
            assert_eq!(cuts.first(), Some(&0), "{case}");
            assert_eq!(cuts.last(), Some(&dims[a]), "{case}");
            let unit = (1 << stage.levels).max(if level == 0 && a == 0 { 8 } else { 1 });
            if stage.ranks() > 1 {
                for w in cuts.windows(2) {
                    assert!(w[0] < w[1], "{case}");
                }
                for c in &cuts[1..cuts.len() - 1] {
                    assert_eq!(c % unit, 0, "{case}");
                }
            }
        }
        if stage.ranks() > 1 {
            for l in level..level + stage.levels {
                let cells: usize = levels[l].iter().product();
                assert!(l == 0 || cells >= stage.ranks() * threshold, "{case}");
                for r in 0..stage.ranks() {
                    assert!(!stage.owned(r, l).is_empty(), "{case}");
                }
            }
            // Its boxes restrict to boxes that tile the next level: per axis, the boxes
            // along it chain from 0 to the level's cells; their cells add up to the level's.
            let next = level + stage.levels;
            let grid = stage.grid();
            for a in 0..3 {
                let mut at = 0;
                for c in 0..grid[a] {
                    let mut coords = [0; 3];
                    coords[a] = c;
                    let o = stage.owned(stage.rank_at(coords), next);
                    assert_eq!(o.axes[a].start, at, "{case}");
                    at = o.axes[a].end;
                }
                assert_eq!(at, levels[next][a], "{case}");
            }
            let total: usize = (0..stage.ranks())
                .map(|r| stage.owned(r, next).cells())
                .sum();
            assert_eq!(total, levels[next].iter().product::<usize>(), "{case}");
        }
        level += stage.levels;
    }
}

#[test]
fn the_layout_keeps_coarse_cells_on_one_rank_and_agglomerates_onto_fewer() {
    // Over slabs the fine level is split over every rank while each keeps two layers; over
    // boxes over at least as many.
    let cases = [
        ([13, 11, 37], 4, 4),
        ([64, 64, 64], 5, 2),
        ([9, 14, 22], 3, 5),
        ([1000, 1000, 1000], 8, 64),
        ([1024, 1024, 1024], 9, 1024),
        ([40, 40, 9], 2, 9),
        ([33, 17, 33], 5, 3),
        ([50, 30, 6], 4, 5),
    ];
    for (dims, depth, ranks) in cases {
        let levels = level_dims(dims, depth);
        for threshold in [0, 64, RankLayout::COARSE_CELLS_PER_RANK] {
            let slabs = RankLayout::new(&levels, ranks, Cycle::V, threshold).unwrap();
            check_layout(&slabs, &levels, ranks, threshold);
            assert_eq!(
                slabs.stages[0].ranks(),
                ranks.min(dims[2] / 2).max(1),
                "{dims:?} {ranks} {threshold}: {slabs:?}"
            );
            for stage in &slabs.stages {
                assert_eq!(stage.grid()[..2], [1, 1], "{slabs:?}");
            }
            let boxes = RankLayout::with(&levels, ranks, Cycle::V, threshold, Decomposition::Boxes)
                .unwrap();
            check_layout(&boxes, &levels, ranks, threshold);
            assert!(
                boxes.stages[0].ranks() >= slabs.stages[0].ranks(),
                "{boxes:?} against {slabs:?}"
            );
        }
    }
    // Splitting as far as the layers allow on 1024³ over 1024 ranks: the fine level on
    // 512 ranks (two layers each), then about half as many per level.
    let layout = RankLayout::new(&level_dims([1024; 3], 9), 1024, Cycle::V, 0).unwrap();
    let counts: Vec<usize> = layout.stages.iter().map(|s| s.ranks()).collect();
    assert_eq!(counts, [512, 256, 128, 64, 32, 16, 8, 4, 1]);
    // 64 ranks on 1000³ split levels 0–2 over all (64·2³ ≤ 1000 layers), then level 3's
    // 125 layers over 62 ranks (two layers each); the default's 16³ cells per rank hold.
    let layout = RankLayout::new(
        &level_dims([1000; 3], 8),
        64,
        Cycle::V,
        RankLayout::COARSE_CELLS_PER_RANK,
    )
    .unwrap();
    let stages: Vec<(usize, usize)> = layout
        .stages
        .iter()
        .map(|s| (s.ranks(), s.levels))
        .collect();
    assert_eq!(stages, [(64, 3), (62, 1), (31, 1), (8, 1), (1, 2)]);
    // A level above a stage, or a rank outside it, owns nothing (no panic).
    let second = &layout.stages[1];
    assert!(second.owned(0, 0).is_empty());
    assert!(second.owned(63, 3).is_empty());
    assert_eq!(second.owned(61, 3), Region::layers([125; 3], 122..125));
    // Boxes put the fine level of 1024³ on all 1024 ranks (slabs: 512, two layers each),
    // as 8 × 8 × 16 boxes of 128 × 128 × 64 cells.
    let layout = RankLayout::with(
        &level_dims([1024; 3], 9),
        1024,
        Cycle::V,
        RankLayout::COARSE_CELLS_PER_RANK,
        Decomposition::Boxes,
    )
    .unwrap();
    assert_eq!(layout.stages[0].ranks(), 1024);
    let mut grid = layout.stages[0].grid();
    grid.sort_unstable();
    assert_eq!(grid, [8, 8, 16]);
    // A chosen grid is the fine stage's; the coarse stages pick theirs.
    let levels = level_dims([40, 24, 20], 3);
    let layout = RankLayout::with(&levels, 6, Cycle::V, 0, Decomposition::Grid([3, 2, 1])).unwrap();
    assert_eq!(layout.stages[0].grid(), [3, 2, 1]);
    check_layout(&layout, &levels, 6, 0);
}

#[test]
fn a_layout_of_another_hierarchy_is_a_typed_error() {
    let (problem, rhs) = system(Scene {
        dims: [8, 8, 16],
        sphere: false,
        contrast: 1.0,
        dirichlet_box: false,
    });
    let mg = Multigrid::build(&problem, MultigridSettings::default()).unwrap();
    let phi = vec![0.0; rhs.len()];
    let bad = [
        // Four ranks' layout on a communicator of two.
        mg.rank_layout_with(4, 0).unwrap(),
        // Bounds that split a coarse cell's children.
        RankLayout {
            stages: vec![
                Stage {
                    first_level: 0,
                    levels: 2,
                    cuts: [vec![0, 8], vec![0, 8], vec![0, 6, 16]],
                },
                Stage {
                    first_level: 2,
                    levels: mg.depth() - 2,
                    cuts: [vec![0, 2], vec![0, 2], vec![0, 4]],
                },
            ],
        },
        // Boxes that cut x inside a norm run (the norms would not be the serial bits).
        RankLayout {
            stages: vec![
                Stage {
                    first_level: 0,
                    levels: 1,
                    cuts: [vec![0, 4, 8], vec![0, 8], vec![0, 16]],
                },
                Stage {
                    first_level: 1,
                    levels: mg.depth() - 1,
                    cuts: [vec![0, 4], vec![0, 4], vec![0, 8]],
                },
            ],
        },
    ];
    for layout in bad {
        let results = Threads::run(2, |comm| {
            mg.solve_on_layout(&rhs, &mut phi.clone(), &stopping(), comm, layout.clone())
        });
        for r in results {
            let e = r.unwrap().unwrap_err();
            assert!(matches!(e, DiffusionError::Invalid(_)), "{e}");
        }
    }
    // The default layout passes the same check.
    let layout = mg.rank_layout_with(2, 0).unwrap();
    let results = Threads::run(2, |comm| {
        let mut phi = phi.clone();
        mg.solve_on_layout(&rhs, &mut phi, &stopping(), comm, layout.clone())
    });
    for r in results {
        assert!(r.unwrap().unwrap().stop_reason.is_converged());
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
