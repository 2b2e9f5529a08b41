//! `SlabSystem::block`, the rows one rank builds from its layers (and D's neighbouring
//! layers) alone, against `DiffusionProblem::assemble` on the whole box: the same columns,
//! value bits and right-hand side, for any run of layers, on grids with sides that are not
//! multiples of 8, under every boundary condition, with point sources; and the fields it
//! refuses.

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
    fn a_blocks_rows_are_the_assembled_rows_of_its_layers(
        dims in (1usize..9, 1usize..9, 1usize..12),
        cut in (0.0f64..1.0, 0.0f64..1.0),
        kinds in proptest::collection::vec(0u8..3, 6),
        seed in any::<u64>(),
        margin in (0usize..3, 0usize..3),
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
        let nz = dims[2];
        let slab = dims[0] * dims[1];
        let (a, b) = ((cut.0 * nz as f64) as usize, (cut.1 * nz as f64) as usize);
        let layers = a.min(b)..(a.max(b) + 1).min(nz);
        // The fields from a few layers below the block's reads to a few above.
        let first = layers.start.saturating_sub(1 + margin.0);
        let end = (layers.end + 1 + margin.1).min(nz);
        let part = |f: &[f32]| f[first * slab..end * slab].to_vec();
        let (dp, sp, qp) = (part(&d), part(&sigma_a), part(&q0));
        let fields = BlockFields { first, diffusion: &dp, absorption: &sp, source: &qp };
        let block = system.block(layers.clone(), fields, &shares).unwrap();
        prop_assert_eq!(block.layers.clone(), layers.clone());
        for (i, cell) in (layers.start * slab..layers.end * slab).enumerate() {
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
            first,
            diffusion: d,
            absorption: s,
            source: q,
        };
        system.block(2..4, fields, &[])
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
