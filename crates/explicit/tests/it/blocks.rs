//! `ranks::iterate_block`: FTCS and Jacobi from rows each rank builds for its own layers
//! or box of cells (`SlabSystem::block`, no rank holding the whole system) give the bits
//! of the serial iteration on the assembled whole, fluence, history and stop reason, on 1
//! to 5 slabs and on grids of up to 12 boxes (even and uneven cuts), for heterogeneous
//! media filling boxes whose sides are not multiples of 8, under Robin, Dirichlet and
//! Neumann faces, with a point source and a volumetric one; the checks the ranks agree on
//! before the first sweep (blocks out of place, rows reading past the touching boxes, the
//! FTCS bound) stop every rank alike.

use glam::DVec3;
use lucent_core::ranks::{Communicator, Threads};
use lucent_core::{StopReason, Stopping};
use lucent_diffusion::slab::{Block, BlockFields, PointShares};
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, DiffusionProblem, SlabSystem, Sources,
};
use lucent_explicit::ExplicitError;
use lucent_explicit::ranks::{BlockSteady, Boxes, DecompositionError, iterate_block};
use lucent_explicit::steady::{Iteration, SteadySettings, ftcs_limit, iterate as serial};
use lucent_grid::GridGeometry;

/// A box medium: D, σ_a and q0 per cell, its boundaries and one point source.
struct Medium {
    geometry: GridGeometry,
    d: Vec<f32>,
    sigma_a: Vec<f32>,
    q0: Vec<f32>,
    boundaries: Boundaries,
    point: (DVec3, f64),
}

fn medium(dims: [usize; 3], faces: [Condition; 6], seed: usize) -> Medium {
    let geometry = GridGeometry::new(
        dims,
        DVec3::new(0.4, 0.5, 0.45),
        DVec3::new(-2.0, -1.5, -1.0),
    )
    .unwrap();
    let n = geometry.voxel_count();
    let d = (0..n)
        .map(|c| 0.05 + 0.03 * ((c * 7 + seed) % 5) as f32)
        .collect();
    let sigma_a = (0..n)
        .map(|c| 0.02 + 0.01 * ((c * 3 + seed) % 4) as f32)
        .collect();
    let q0 = (0..n)
        .map(|c| {
            if (c + seed).is_multiple_of(11) {
                0.5
            } else {
                0.0
            }
        })
        .collect();
    let (lo, hi) = geometry.bounds();
    Medium {
        geometry,
        d,
        sigma_a,
        q0,
        boundaries: Boundaries {
            surface: Condition::Robin { a: 1.0 },
            faces,
        },
        point: (lo + (hi - lo) * DVec3::new(0.3, 0.6, 0.55), 2.0),
    }
}

/// Rank `rank`'s block of `ranks`: layers r·n_z/P..(r+1)·n_z/P, built from those layers
/// and one each side only.
fn block(m: &Medium, rank: usize, ranks: usize) -> Block {
    let [nx, ny, nz] = m.geometry.dims();
    cells_block(
        m,
        [0..nx, 0..ny, rank * nz / ranks..(rank + 1) * nz / ranks],
        true,
    )
}

/// The block of the box `cells`, built from the fields of that box grown by a cell (where
/// the grid has one) only, with the point source or without.
fn cells_block(m: &Medium, cells: [std::ops::Range<usize>; 3], point: bool) -> Block {
    let dims = m.geometry.dims();
    let origin: [usize; 3] = std::array::from_fn(|a| cells[a].start.saturating_sub(1));
    let end: [usize; 3] = std::array::from_fn(|a| (cells[a].end + 1).min(dims[a]));
    let part = |f: &[f32]| -> Vec<f32> {
        let mut out = Vec::new();
        for k in origin[2]..end[2] {
            for j in origin[1]..end[1] {
                let row = dims[0] * (j + dims[1] * k);
                out.extend_from_slice(&f[row + origin[0]..row + end[0]]);
            }
        }
        out
    };
    let (d, s, q) = (part(&m.d), part(&m.sigma_a), part(&m.q0));
    let system = SlabSystem::new(m.geometry, m.boundaries).unwrap();
    let shares: Vec<PointShares> = system
        .point_weights(m.point.0, m.point.1)
        .into_iter()
        .filter(|_| point)
        .collect();
    let fields = BlockFields {
        origin,
        dims: std::array::from_fn(|a| end[a] - origin[a]),
        diffusion: &d,
        absorption: &s,
        source: &q,
    };
    system.block(cells, fields, &shares).unwrap()
}

/// The whole system, assembled as one process does.
fn assembled(m: &Medium) -> lucent_diffusion::AssembledSystem {
    let problem = DiffusionProblem::new(
        CellGeometry::full_box(m.geometry),
        m.d.clone(),
        m.sigma_a.clone(),
        m.boundaries,
    )
    .unwrap();
    let sources = Sources {
        volumetric: m.q0.clone(),
        points: vec![m.point],
        ..Sources::default()
    };
    problem.assemble(&sources).unwrap()
}

fn on_ranks(
    ranks: usize,
    blocks: impl Fn(usize) -> Block + Sync,
    dims: [usize; 3],
    iteration: Iteration,
    settings: &SteadySettings,
) -> Vec<Result<BlockSteady, DecompositionError>> {
    Threads::run(ranks, |comm| {
        iterate_block(&blocks(comm.rank()), dims, iteration, settings, comm)
    })
    .into_iter()
    .map(Option::unwrap)
    .collect()
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn settings(tolerance: f64, max_iterations: usize) -> SteadySettings {
    SteadySettings {
        stopping: Stopping {
            relative_tolerance: tolerance,
            max_iterations,
            ..Stopping::default()
        },
        allow_unstable: false,
    }
}

#[test]
fn blocks_on_any_rank_count_give_the_serial_bits_of_the_assembled_whole() {
    let robin = Condition::Robin { a: 2.341 };
    let cases = [
        ([11, 9, 13], [robin; 6]),
        (
            [7, 10, 9],
            [
                Condition::Dirichlet { value: 0.0 },
                robin,
                Condition::Neumann { flux: 0.0 },
                robin,
                Condition::Dirichlet { value: 0.2 },
                robin,
            ],
        ),
    ];
    for (case, (dims, faces)) in cases.into_iter().enumerate() {
        let m = medium(dims, faces, case);
        let system = assembled(&m);
        let volume = m.geometry.cell_volume();
        for iteration in [
            Iteration::Ftcs {
                time_step: 0.9 * ftcs_limit(&system, volume),
                cell_volume: volume,
            },
            Iteration::Jacobi { omega: 0.9 },
        ] {
            let settings = settings(1e-6, 20_000);
            let reference = serial(&system, dims, iteration, &settings).unwrap();
            assert!(
                reference.stop_reason.is_converged(),
                "{dims:?} {iteration:?}"
            );
            for ranks in 1..=5 {
                let outs = on_ranks(ranks, |r| block(&m, r, ranks), dims, iteration, &settings);
                let mut fluence = Vec::new();
                for (rank, out) in outs.into_iter().enumerate() {
                    let out = out.unwrap();
                    let case = format!("{dims:?} {iteration:?}, rank {rank} of {ranks}");
                    assert_eq!(out.stop_reason, reference.stop_reason, "{case}");
                    assert_eq!(bits(&out.residuals), bits(&reference.residuals), "{case}");
                    fluence.extend(out.fluence);
                }
                assert_eq!(
                    bits(&fluence),
                    bits(&reference.fluence),
                    "{dims:?} {iteration:?} on {ranks}"
                );
            }
        }
    }
}

#[test]
fn blocks_that_do_not_join_up_stop_every_rank_with_the_same_error() {
    let m = medium([6, 5, 8], [Condition::Robin { a: 2.0 }; 6], 0);
    let dims = [6, 5, 8];
    let jacobi = Iteration::Jacobi { omega: 1.0 };
    // Rank 1 builds layers 5..8 instead of 4..8: layer 4 belongs to no one.
    let outs = on_ranks(
        2,
        |r| {
            if r == 0 {
                block(&m, 0, 2)
            } else {
                shifted(&m, 5..8)
            }
        },
        dims,
        jacobi,
        &settings(1e-6, 100),
    );
    for out in outs {
        assert!(
            matches!(out.unwrap_err(), DecompositionError::Blocks { .. }),
            "a hole between the slabs"
        );
    }
    // Both ranks build the first half: the grid's upper half is missing.
    let outs = on_ranks(2, |_| block(&m, 0, 2), dims, jacobi, &settings(1e-6, 100));
    for out in outs {
        assert!(matches!(
            out.unwrap_err(),
            DecompositionError::Blocks { .. }
        ));
    }
}

fn shifted(m: &Medium, layers: std::ops::Range<usize>) -> Block {
    let [nx, ny, _] = m.geometry.dims();
    cells_block(m, [0..nx, 0..ny, layers], false)
}

#[test]
fn an_ftcs_step_beyond_the_whole_systems_bound_is_refused_on_every_rank() {
    // The bound is the largest Gershgorin sum over every rank's rows: a step each rank
    // alone would accept (its own rows' bound is larger) is refused on all of them.
    let mut m = medium([5, 6, 8], [Condition::Robin { a: 2.0 }; 6], 1);
    let [nx, ny, _] = m.geometry.dims();
    let slab = nx * ny;
    // Stiffer rows in the upper half: rank 1 holds the smallest bound.
    for d in &mut m.d[4 * slab..] {
        *d *= 8.0;
    }
    let volume = m.geometry.cell_volume();
    let lower_rows = block(&m, 0, 2);
    let own_bound = 2.0 * volume
        / lower_rows
            .matrix
            .outer_iterator()
            .map(|r| r.iter().map(|(_, v)| v.abs()).sum::<f64>())
            .fold(0.0, f64::max);
    let ftcs = Iteration::Ftcs {
        time_step: 0.99 * own_bound,
        cell_volume: volume,
    };
    let outs = on_ranks(
        2,
        |r| block(&m, r, 2),
        m.geometry.dims(),
        ftcs,
        &settings(1e-6, 100),
    );
    for out in outs {
        let e = out.unwrap_err();
        assert!(
            matches!(
                e,
                DecompositionError::Scheme(ExplicitError::Unstable { .. })
            ),
            "{e}"
        );
    }
    // Allowed beyond the bound it diverges as the serial iteration on the whole does:
    // the same stop, and the same φ (zeroed everywhere if anything is not finite).
    let unstable = SteadySettings {
        allow_unstable: true,
        ..settings(1e-6, 400)
    };
    let reference = serial(&assembled(&m), m.geometry.dims(), ftcs, &unstable).unwrap();
    assert!(
        matches!(
            reference.stop_reason,
            StopReason::DivergedGrowth { .. } | StopReason::DivergedNonFinite { .. }
        ),
        "{:?}",
        reference.stop_reason
    );
    let mut fluence = Vec::new();
    for out in on_ranks(2, |r| block(&m, r, 2), m.geometry.dims(), ftcs, &unstable) {
        let out = out.unwrap();
        assert_eq!(out.stop_reason, reference.stop_reason);
        fluence.extend(out.fluence);
    }
    assert_eq!(bits(&fluence), bits(&reference.fluence));
}

/// The ranks' φ, each of its block's cells, put back in the grid's order.
fn scatter(blocks: &[Block], fluence: &[Vec<f64>], dims: [usize; 3]) -> Vec<f64> {
    let mut out = vec![f64::NAN; dims.iter().product()];
    for (b, phi) in blocks.iter().zip(fluence) {
        for (c, &v) in b.grid_cells(dims).zip(phi) {
            out[c] = v;
        }
    }
    out
}

#[test]
fn boxes_even_and_uneven_give_the_serial_bits_of_the_assembled_whole() {
    let robin = Condition::Robin { a: 2.341 };
    let faces = [
        Condition::Dirichlet { value: 0.1 },
        robin,
        Condition::Neumann { flux: 0.0 },
        robin,
        robin,
        Condition::Neumann { flux: -0.1 },
    ];
    // 19 cells in x: three runs of 8 (the last short), so up to three boxes along x.
    let dims = [19, 7, 9];
    let m = medium(dims, faces, 3);
    let system = assembled(&m);
    let volume = m.geometry.cell_volume();
    let grids: Vec<Boxes> = [
        [1, 1, 1],
        [2, 1, 1],
        [1, 2, 2],
        [3, 1, 2],
        [2, 3, 2],
        [3, 2, 2],
    ]
    .into_iter()
    .map(|g| Boxes::new(dims, g).unwrap())
    .chain([
        // Uneven cuts: a thin box in every axis, the last x box a short run.
        Boxes::from_cuts(dims, [vec![0, 16, 19], vec![0, 1, 7], vec![0, 8, 9]]).unwrap(),
        Boxes::from_cuts(dims, [vec![0, 8, 19], vec![0, 7], vec![0, 1, 2, 9]]).unwrap(),
    ])
    .collect();
    for iteration in [
        Iteration::Ftcs {
            time_step: 0.9 * ftcs_limit(&system, volume),
            cell_volume: volume,
        },
        Iteration::Jacobi { omega: 0.9 },
    ] {
        let settings = settings(1e-6, 20_000);
        let reference = serial(&system, dims, iteration, &settings).unwrap();
        assert!(reference.stop_reason.is_converged(), "{iteration:?}");
        for boxes in &grids {
            let blocks: Vec<Block> = (0..boxes.ranks())
                .map(|r| cells_block(&m, boxes.bounds(r), true))
                .collect();
            let outs = on_ranks(
                boxes.ranks(),
                |r| blocks[r].clone(),
                dims,
                iteration,
                &settings,
            );
            let mut fluence = Vec::new();
            for (rank, out) in outs.into_iter().enumerate() {
                let out = out.unwrap();
                let case = format!("{:?} {iteration:?}, rank {rank}", boxes.grid());
                assert_eq!(out.stop_reason, reference.stop_reason, "{case}");
                assert_eq!(bits(&out.residuals), bits(&reference.residuals), "{case}");
                fluence.push(out.fluence);
            }
            assert_eq!(
                bits(&scatter(&blocks, &fluence, dims)),
                bits(&reference.fluence),
                "{:?} {iteration:?}",
                boxes.grid()
            );
        }
    }
}

#[test]
fn boxes_out_of_place_or_rows_reading_past_the_touching_boxes_stop_every_rank() {
    let dims = [19, 6, 8];
    let m = medium(dims, [Condition::Robin { a: 2.0 }; 6], 2);
    let jacobi = Iteration::Jacobi { omega: 1.0 };
    let run = |blocks: &[Block]| {
        on_ranks(
            blocks.len(),
            |r| blocks[r].clone(),
            dims,
            jacobi,
            &settings(1e-6, 50),
        )
    };
    // An x cut off a multiple of 8 (a norm's run would straddle two ranks): rank 1 is
    // out of place.
    let off = [
        cells_block(&m, [0..5, 0..6, 0..8], true),
        cells_block(&m, [5..19, 0..6, 0..8], true),
    ];
    for out in run(&off) {
        assert_eq!(out.unwrap_err(), DecompositionError::Blocks { rank: 1 });
    }
    // Boxes in the wrong rank order (y before x).
    let boxes = Boxes::new(dims, [2, 2, 1]).unwrap();
    let swapped: Vec<Block> = [0, 2, 1, 3]
        .into_iter()
        .map(|r| cells_block(&m, boxes.bounds(r), true))
        .collect();
    for out in run(&swapped) {
        assert!(matches!(
            out.unwrap_err(),
            DecompositionError::Blocks { .. }
        ));
    }
    // Overlapping boxes, and boxes that leave cells to no one.
    let overlap = [
        cells_block(&m, [0..8, 0..6, 0..8], true),
        cells_block(&m, [0..19, 0..6, 0..8], true),
    ];
    let hole = [
        cells_block(&m, [0..8, 0..6, 0..8], true),
        cells_block(&m, [8..19, 0..6, 0..7], true),
    ];
    for blocks in [&overlap[..], &hole[..]] {
        for out in run(blocks) {
            assert!(matches!(
                out.unwrap_err(),
                DecompositionError::Blocks { .. }
            ));
        }
    }
    // Three slabs; rank 0's first row also reads a cell of rank 2's (not a touching box):
    // every rank stops, naming rank 0.
    let nx_ny = dims[0] * dims[1];
    let mut far = [0..3, 3..5, 5..8].map(|l| cells_block(&m, [0..19, 0..6, l], true));
    let a = &far[0].matrix;
    let (mut indptr, mut indices, mut data) = (
        a.indptr().to_proper().to_vec(),
        a.indices().to_vec(),
        a.data().to_vec(),
    );
    indices.insert(indptr[1], 6 * nx_ny);
    data.insert(indptr[1], -1e-3);
    for p in &mut indptr[1..] {
        *p += 1;
    }
    far[0].matrix = sprs::CsMat::new(a.shape(), indptr, indices, data);
    for out in run(&far) {
        assert_eq!(
            out.unwrap_err(),
            DecompositionError::StencilTooWide { rank: 0 }
        );
    }
}
