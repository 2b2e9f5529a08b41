//! `ranks::iterate_block`: FTCS and Jacobi from rows each rank builds for its own layers
//! (`SlabSystem::block`, no rank holding the whole system) give the bits of the serial
//! iteration on the assembled whole, fluence, history and stop reason, on 1 to 5 ranks,
//! for heterogeneous media filling boxes whose sides are not multiples of 8, under Robin,
//! Dirichlet and Neumann faces, with a point source and a volumetric one; the checks the
//! ranks agree on before the first sweep stop every rank alike.

use glam::DVec3;
use lucent_core::ranks::{Communicator, Threads};
use lucent_core::{StopReason, Stopping};
use lucent_diffusion::slab::{Block, BlockFields, PointShares};
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, DiffusionProblem, SlabSystem, Sources,
};
use lucent_explicit::ExplicitError;
use lucent_explicit::ranks::{BlockSteady, DecompositionError, iterate_block};
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
    let slab = nx * ny;
    let layers = rank * nz / ranks..(rank + 1) * nz / ranks;
    let (first, end) = (layers.start.saturating_sub(1), (layers.end + 1).min(nz));
    let part = |f: &[f32]| f[first * slab..end * slab].to_vec();
    let (d, s, q) = (part(&m.d), part(&m.sigma_a), part(&m.q0));
    let system = SlabSystem::new(m.geometry, m.boundaries).unwrap();
    let shares: Vec<PointShares> = system
        .point_weights(m.point.0, m.point.1)
        .into_iter()
        .collect();
    let fields = BlockFields {
        first,
        diffusion: &d,
        absorption: &s,
        source: &q,
    };
    system.block(layers, fields, &shares).unwrap()
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
        assert_eq!(out.unwrap_err(), DecompositionError::Blocks { rank: 1 });
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
    let [nx, ny, nz] = m.geometry.dims();
    let slab = nx * ny;
    let (first, end) = (layers.start - 1, (layers.end + 1).min(nz));
    let part = |f: &[f32]| f[first * slab..end * slab].to_vec();
    let (d, s, q) = (part(&m.d), part(&m.sigma_a), part(&m.q0));
    let system = SlabSystem::new(m.geometry, m.boundaries).unwrap();
    let fields = BlockFields {
        first,
        diffusion: &d,
        absorption: &s,
        source: &q,
    };
    system.block(layers, fields, &[]).unwrap()
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
