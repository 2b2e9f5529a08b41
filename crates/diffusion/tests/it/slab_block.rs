//! `SlabSystem::block`, the rows one rank builds from its box of cells (and D's cells
//! beyond its faces) alone, against `DiffusionProblem::assemble` on the whole grid: the
//! same columns, value bits and right-hand side, for any box (whole layers among them), on
//! grids with sides that are not multiples of 8, under every boundary condition, with
//! point sources; and the fields it refuses.

use glam::DVec3;
use lucent_diffusion::slab::{BlockFields, PointShares};
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, DiffusionError, DiffusionProblem, SlabSystem, Sources,
};
use lucent_grid::GridGeometry;
use proptest::prelude::*;

fn field(n: usize, seed: u64, lo: f32, decades: f32) -> Vec<f32> {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..n)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            lo * 10f32.powf(decades * (state >> 40) as f32 / (1u64 << 24) as f32)
        })
        .collect()
}

fn condition(kind: u8) -> Condition {
    match kind % 3 {
        0 => Condition::Robin { a: 2.341 },
        1 => Condition::Dirichlet { value: 0.3 },
        _ => Condition::Neumann { flux: -0.2 },
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(40))]

    #[test]
    fn a_blocks_rows_are_the_assembled_rows_of_its_cells(
        dims in (1usize..9, 1usize..9, 1usize..12),
        cuts in proptest::collection::vec((0.0f64..1.0, 0.0f64..1.0), 3),
        whole_layers in any::<bool>(),
        kinds in proptest::collection::vec(0u8..3, 6),
        seed in any::<u64>(),
        margins in proptest::collection::vec((0usize..3, 0usize..3), 3),
    ) {
        let dims = [dims.0, dims.1, dims.2];
        let geometry =
            GridGeometry::new(dims, DVec3::new(0.7, 0.5, 0.9), DVec3::new(-1.0, 0.2, 0.3)).unwrap();
        let n = geometry.voxel_count();
        let (d, sigma_a, q0) =
            (field(n, seed, 0.02, 2.0), field(n, seed ^ 1, 0.001, 3.0), field(n, seed ^ 2, 0.1, 1.0));
        let faces: [Condition; 6] = std::array::from_fn(|f| condition(kinds[f]));
        let boundaries = Boundaries { surface: Condition::Robin { a: 1.0 }, faces };
        let (lo, hi) = geometry.bounds();
        let points = vec![(lo + (hi - lo) * DVec3::new(0.31, 0.62, 0.47), 2.5)];
        let problem = DiffusionProblem::new(
            CellGeometry::full_box(geometry), d.clone(), sigma_a.clone(), boundaries,
        ).unwrap();
        let sources = Sources { volumetric: q0.clone(), points: points.clone(), ..Sources::default() };
        let assembled = problem.assemble(&sources).unwrap();

        let system = SlabSystem::new(geometry, boundaries).unwrap();
        let shares: Vec<PointShares> =
            points.iter().map(|&(p, w)| system.point_weights(p, w).unwrap()).collect();
        // A box of cells (whole layers in x and y half the time, as a z-slab), and fields
        // from a few cells below its reads to a few above along each axis.
        let cells: [std::ops::Range<usize>; 3] = std::array::from_fn(|a| {
            let (u, v) = ((cuts[a].0 * dims[a] as f64) as usize, (cuts[a].1 * dims[a] as f64) as usize);
            if whole_layers && a < 2 { 0..dims[a] } else { u.min(v)..(u.max(v) + 1).min(dims[a]) }
        });
        let origin: [usize; 3] =
            std::array::from_fn(|a| cells[a].start.saturating_sub(1 + margins[a].0));
        let end: [usize; 3] =
            std::array::from_fn(|a| (cells[a].end + 1 + margins[a].1).min(dims[a]));
        let held: [usize; 3] = std::array::from_fn(|a| end[a] - origin[a]);
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
        let (dp, sp, qp) = (part(&d), part(&sigma_a), part(&q0));
        let fields = BlockFields { origin, dims: held, diffusion: &dp, absorption: &sp, source: &qp };
        let block = system.block(cells.clone(), fields, &shares).unwrap();
        prop_assert_eq!(block.cells.clone(), cells.clone());
        prop_assert_eq!(block.matrix.rows(), cells.iter().map(|r| r.len()).product::<usize>());
        for (i, cell) in block.grid_cells(dims).enumerate() {
            let expected: Vec<(usize, u64)> = assembled.matrix.outer_view(cell).unwrap()
                .iter().map(|(j, v)| (j, v.to_bits())).collect();
            let got: Vec<(usize, u64)> = block.matrix.outer_view(i).unwrap()
                .iter().map(|(j, v)| (j, v.to_bits())).collect();
            prop_assert_eq!(got, expected, "row of cell {}", cell);
            prop_assert_eq!(block.rhs[i].to_bits(), assembled.rhs[cell].to_bits(), "rhs of cell {}", cell);
        }
    }
}

#[test]
fn fields_that_miss_a_layer_or_hold_a_bad_value_are_refused_by_cell() {
    let geometry = GridGeometry::new([3, 2, 5], DVec3::ONE, DVec3::ZERO).unwrap();
    let system =
        SlabSystem::new(geometry, Boundaries::uniform(Condition::Robin { a: 2.0 })).unwrap();
    let slab = 6;
    let good = |layers: usize| vec![0.5f32; layers * slab];
    let build = |first: usize, d: &[f32], s: &[f32], q: &[f32]| {
        let fields = BlockFields {
            origin: [0, 0, first],
            dims: [3, 2, d.len() / slab],
            diffusion: d,
            absorption: s,
            source: q,
        };
        system.block([0..3, 0..2, 2..4], fields, &[])
    };
    // Layers 2–3 read D on 1–4: fields from layer 2 miss layer 1.
    let (d, s, q) = (good(3), good(3), good(3));
    assert!(matches!(
        build(2, &d, &s, &q),
        Err(DiffusionError::Invalid(_))
    ));
    // Lengths that disagree.
    let (d, s, q) = (good(4), good(3), good(4));
    assert!(matches!(
        build(1, &d, &s, &q),
        Err(DiffusionError::Invalid(_))
    ));
    // A zero D on layer 4 (read by layer 3's faces), a NaN σ_a, an infinite source.
    let (mut d, s, q) = (good(4), good(4), good(4));
    d[3 * slab + 1] = 0.0;
    let e = build(1, &d, &s, &q).unwrap_err();
    assert!(e.to_string().contains("cell 25"), "{e}");
    let (d, mut s, q) = (good(4), good(4), good(4));
    s[slab + 2] = f32::NAN;
    let e = build(1, &d, &s, &q).unwrap_err();
    assert!(e.to_string().contains("absorption NaN in cell 14"), "{e}");
    let (d, s, mut q) = (good(4), good(4), good(4));
    q[2 * slab] = f32::INFINITY;
    let e = build(1, &d, &s, &q).unwrap_err();
    assert!(e.to_string().contains("cell 18"), "{e}");
    // The good fields build two layers of rows.
    let (d, s, q) = (good(4), good(4), good(4));
    let block = build(1, &d, &s, &q).unwrap();
    assert_eq!(block.matrix.rows(), 2 * slab);
}

#[test]
fn a_box_without_the_cells_beyond_its_faces_or_beyond_the_grid_is_refused() {
    let geometry = GridGeometry::new([6, 5, 4], DVec3::ONE, DVec3::ZERO).unwrap();
    let system =
        SlabSystem::new(geometry, Boundaries::uniform(Condition::Robin { a: 2.0 })).unwrap();
    let build = |cells: [std::ops::Range<usize>; 3], origin: [usize; 3], held: [usize; 3]| {
        let v = vec![0.5f32; held.iter().product()];
        let fields = BlockFields {
            origin,
            dims: held,
            diffusion: &v,
            absorption: &v,
            source: &v,
        };
        system.block(cells, fields, &[]).map(|b| b.matrix.rows())
    };
    // Cells x 2..4, y 1..3, z 1..3 read D on x 1..5, y 0..4, z 0..4.
    assert_eq!(build([2..4, 1..3, 1..3], [1, 0, 0], [4, 4, 4]), Ok(8));
    // The x column below (x = 1) or above (x = 4) missing; y above (y = 3) missing.
    for (origin, held) in [
        ([2, 0, 0], [3, 4, 4]),
        ([1, 0, 0], [3, 4, 4]),
        ([1, 0, 0], [4, 3, 4]),
    ] {
        let e = build([2..4, 1..3, 1..3], origin, held).unwrap_err();
        assert!(
            e.to_string().contains("read D on"),
            "{origin:?} {held:?}: {e}"
        );
    }
    // Fields of another length than their box, an empty box, a box past the grid.
    let v = vec![0.5f32; 10];
    let fields = BlockFields {
        origin: [0; 3],
        dims: [6, 5, 4],
        diffusion: &v,
        absorption: &v,
        source: &v,
    };
    assert!(system.block([0..6, 0..5, 0..4], fields, &[]).is_err());
    assert!(build([2..2, 0..5, 0..4], [0; 3], [6, 5, 4]).is_err());
    assert!(build([0..7, 0..5, 0..4], [0; 3], [6, 5, 4]).is_err());
}
