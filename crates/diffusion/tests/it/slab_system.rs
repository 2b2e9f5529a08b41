//! `SlabSystem` against `DiffusionProblem::assemble` on media that fill the box: every row
//! (columns and value bits) and every right-hand side entry must match, because the
//! out-of-core diffusion schemes run on the slab system and promise the in-memory bits.
//! Drawn over grids whose sides are 1 to 7 cells (one-cell-thick grids have both box faces
//! on one cell), cells that are not cubes, coefficients spanning three decades, every
//! boundary condition, with and without a first moment and point sources.

use glam::DVec3;
use lucent_diffusion::slab::{PointShares, Window};
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, DiffusionProblem, SlabSystem, Sources,
};
use lucent_grid::GridGeometry;
use proptest::prelude::*;

fn condition(kind: u8, value: f64) -> Condition {
    match kind % 3 {
        0 => Condition::Robin { a: 1.0 + value },
        1 => Condition::Dirichlet { value },
        _ => Condition::Neumann { flux: value - 0.5 },
    }
}

/// Values from a seed, spread over three decades.
fn values(n: usize, seed: u64, lo: f32, decades: f32) -> Vec<f32> {
    let mut state = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (0..n)
        .map(|_| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (state >> 40) as f32 / (1u64 << 24) as f32;
            lo * 10f32.powf(decades * u)
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn slab_rows_and_rhs_are_the_assembled_bits(
        dims in (1usize..8, 1usize..8, 1usize..8),
        spacing in (0.3f64..2.0, 0.3f64..2.0, 0.3f64..2.0),
        kinds in proptest::collection::vec(0u8..3, 6),
        values_seed in any::<u64>(),
        moment in any::<bool>(),
        point_count in 0usize..3,
    ) {
        let dims = [dims.0, dims.1, dims.2];
        let geometry = GridGeometry::new(
            dims,
            DVec3::new(spacing.0, spacing.1, spacing.2),
            DVec3::new(-0.4, 0.1, 0.7),
        )
        .unwrap();
        let n = geometry.voxel_count();
        let d = values(n, values_seed, 0.01, 3.0);
        let sigma_a = values(n, values_seed ^ 1, 0.001, 3.0);
        let q0 = values(n, values_seed ^ 2, 0.1, 2.0);
        let q1: Vec<[f32; 3]> = if moment {
            let raw = values(3 * n, values_seed ^ 3, 0.05, 2.0);
            raw.chunks(3).map(|c| [c[0] - 0.3, 0.2 - c[1], c[2]]).collect()
        } else {
            Vec::new()
        };
        let (lo, hi) = geometry.bounds();
        let points: Vec<(DVec3, f64)> = (0..point_count)
            .map(|p| {
                let t = DVec3::new(0.21 + 0.3 * p as f64, 0.77 - 0.2 * p as f64, 0.5);
                (lo + (hi - lo) * t, 1.5 + p as f64)
            })
            .collect();
        let faces: [Condition; 6] =
            std::array::from_fn(|f| condition(kinds[f], 0.25 + 0.5 * f as f64));
        let boundaries = Boundaries { surface: Condition::Robin { a: 1.0 }, faces };
        let problem = DiffusionProblem::new(
            CellGeometry::full_box(geometry),
            d.clone(),
            sigma_a.clone(),
            boundaries,
        )
        .unwrap();
        let sources = Sources {
            volumetric: q0.clone(),
            first_moment: q1.clone(),
            points: points.clone(),
        };
        let assembled = problem.assemble(&sources).unwrap();
        prop_assert_eq!(assembled.cells.len(), n, "every cell of a full box is an unknown");

        let system = SlabSystem::new(geometry, boundaries).unwrap();
        let shares: Vec<PointShares> = points
            .iter()
            .map(|&(p, power)| system.point_weights(p, power).unwrap())
            .collect();
        let [nx, ny, nz] = dims;
        let slab = nx * ny;
        let window = |field: &[f32], z: usize| -> (Option<Vec<f32>>, Vec<f32>, Option<Vec<f32>>) {
            let s = |z: usize| field[z * slab..(z + 1) * slab].to_vec();
            ((z > 0).then(|| s(z - 1)), s(z), (z + 1 < nz).then(|| s(z + 1)))
        };
        // Without a first moment the components are zeros, which the system never reads.
        let component = |axis: usize| -> Vec<f32> {
            if moment { q1.iter().map(|v| v[axis]).collect() } else { vec![0.0; n] }
        };
        let (qx, qy, qz) = (component(0), component(1), component(2));
        for z in 0..nz {
            let (db, dh, da) = window(&d, z);
            let dw = Window { below: db.as_deref(), here: &dh, above: da.as_deref() };
            let comps = [window(&qx, z), window(&qy, z), window(&qz, z)];
            let q1w = [0, 1, 2].map(|a| Window {
                below: comps[a].0.as_deref(),
                here: &comps[a].1,
                above: comps[a].2.as_deref(),
            });
            let mut rhs = vec![0.0; slab];
            system.rhs_slab(
                z,
                &q0[z * slab..(z + 1) * slab],
                moment.then_some(&q1w),
                &dw,
                &shares,
                &mut rhs,
            );
            for index in 0..slab {
                let at = [index % nx, index / nx, z];
                let cell = index + z * slab;
                let extra = system.extra(at, d[cell], sigma_a[cell]);
                let row = system.row(at, &dw, extra);
                let csr = assembled.matrix.outer_view(cell).unwrap();
                let expected: Vec<(isize, u64)> = csr
                    .iter()
                    .map(|(j, v)| (j as isize - cell as isize, v.to_bits()))
                    .collect();
                let got: Vec<(isize, u64)> =
                    row.entries().iter().map(|&(o, v)| (o, v.to_bits())).collect();
                prop_assert_eq!(got, expected, "row of cell {:?}", at);
                prop_assert_eq!(
                    rhs[index].to_bits(),
                    assembled.rhs[cell].to_bits(),
                    "rhs of cell {:?}: {} against {}",
                    at,
                    rhs[index],
                    assembled.rhs[cell]
                );
            }
        }
    }
}
