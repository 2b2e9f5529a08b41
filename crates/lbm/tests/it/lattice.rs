//! The lattice march on its own: the in-place (AA) pattern against two arrays bit for bit,
//! energy bookkeeping to rounding for every wall and collision, the thesis's absorption
//! against true absorption, and the refusals at the stability limit.

use lucent_core::{StopReason, Stopping};
use lucent_lbm::{
    Absorption, Collision, LatticeProblem, LbmError, MarchSettings, Streaming, Velocities, Wall,
    march,
};
use proptest::prelude::*;

/// A drawn problem: coefficients between `lo` and `hi` by a hash of the cell.
fn problem(
    dims: [usize; 3],
    collision: Collision,
    wall: Wall,
    seed: u64,
    moment: bool,
) -> LatticeProblem {
    let n: usize = dims.iter().product();
    let hash = |c: usize, salt: u64| {
        let mut x = (c as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ seed ^ salt;
        x ^= x >> 29;
        x = x.wrapping_mul(0xbf58_476d_1ce4_e5b9);
        x ^= x >> 32;
        (x >> 11) as f64 / (1u64 << 53) as f64
    };
    let (first, second): (Vec<f32>, Vec<f32>) = (0..n)
        .map(|c| match collision {
            Collision::Geist => {
                let kt = 0.1 + 0.8 * hash(c, 1);
                (kt as f32, (kt * (0.3 + 0.7 * hash(c, 2))) as f32)
            }
            _ => ((0.05 + 2.0 * hash(c, 1)) as f32, (0.2 * hash(c, 2)) as f32),
        })
        .unzip();
    let source = (0..n)
        .map(|c| {
            if hash(c, 3) > 0.6 {
                hash(c, 4) as f32
            } else {
                0.0
            }
        })
        .collect();
    let first_moment = if moment {
        (0..n)
            .map(|c| [0.1 * hash(c, 5) as f32, -0.05 * hash(c, 6) as f32, 0.02])
            .collect()
    } else {
        Vec::new()
    };
    LatticeProblem {
        dims,
        first,
        second,
        source,
        first_moment,
        wall,
    }
}

fn settings(
    velocities: Velocities,
    collision: Collision,
    absorption: Absorption,
    streaming: Streaming,
    steps: usize,
) -> MarchSettings {
    MarchSettings {
        velocities,
        collision,
        absorption,
        streaming,
        stopping: Stopping {
            relative_tolerance: 0.0,
            max_iterations: steps,
            ..Stopping::default()
        },
        blocks: None,
    }
}

fn wall_of(kind: u8) -> Wall {
    match kind % 5 {
        0 => Wall::Robin { a: 1.0657 },
        1 => Wall::Robin { a: 2.6 },
        2 => Wall::Dirichlet { value: 0.3 },
        3 => Wall::Reflect { reflectance: 0.4 },
        _ => Wall::Neumann { flux: 0.0 },
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(40))]

    /// The AA pattern is the two-array march with the same arithmetic per cell: every
    /// step, even and odd, and the walls' side slots, give the same bits. Rows up to 89
    /// cells long reach every block size the interior kernels cut a row into (64, 16, 4, 1).
    #[test]
    fn in_place_streaming_is_two_arrays_bit_for_bit(
        dims in (1usize..90, 1usize..7, 1usize..7),
        d3q19 in any::<bool>(),
        collision in 0u8..3,
        thesis in any::<bool>(),
        wall in 0u8..5,
        seed in any::<u64>(),
        moment in any::<bool>(),
        steps in 1usize..14,
    ) {
        let velocities = if d3q19 { Velocities::D3q19 } else { Velocities::D3q7 };
        let collision = [Collision::Trt, Collision::Bgk, Collision::Geist][collision as usize];
        let absorption = if thesis { Absorption::Thesis } else { Absorption::True };
        let p = problem([dims.0, dims.1, dims.2], collision, wall_of(wall), seed, moment);
        let aa = march(&p, &settings(velocities, collision, absorption, Streaming::InPlace, steps)).unwrap();
        let ab = march(&p, &settings(velocities, collision, absorption, Streaming::TwoArrays, steps)).unwrap();
        prop_assert_eq!(aa.steps, ab.steps);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        prop_assert_eq!(bits(&aa.fluence), bits(&ab.fluence));
        prop_assert_eq!(&aa.residuals, &ab.residuals);
        // And the energy: what the sources emitted is what was absorbed, escaped, or is
        // still held, to the rounding of f32 populations.
        for m in [&aa, &ab] {
            let b = m.bookkeeping;
            prop_assert!(b.conservation_error() < 1e-5, "{:?}", b);
        }
        let held = |m: &lucent_lbm::Marched| m.bookkeeping.held;
        prop_assert!((held(&aa) - held(&ab)).abs() <= 1e-6 * held(&aa).abs().max(1e-30));
    }
}

/// The interior kernels cut each row from its low end into blocks of 64, 16 and 4 cells and
/// single cells (an 87-cell interior row: 64 + 16 + 4 + 3), so a mirror-symmetric problem's
/// low half runs through the long blocks and its high half through the short ones and the
/// scalar path. Its fluence must be mirror-symmetric: the per-cell arithmetic is the same
/// on every path, only the order of the link sums changes under the mirror, so the halves
/// agree to f32 rounding (1e-5 of the peak allows for 30 steps of it); a block reading or
/// writing a wrong cell or link is off by O(1).
#[test]
fn every_block_size_computes_the_scalar_cell() {
    let dims = [89usize, 5, 4];
    let [nx, ny, _] = dims;
    let n: usize = dims.iter().product();
    let mirrored = |c: usize| {
        let (x, rest) = (c % nx, c / nx);
        x.min(nx - 1 - x) + nx * rest
    };
    for velocities in [Velocities::D3q7, Velocities::D3q19] {
        for collision in [Collision::Trt, Collision::Bgk] {
            for streaming in [Streaming::InPlace, Streaming::TwoArrays] {
                let base = problem(dims, collision, Wall::Robin { a: 2.6 }, 7, false);
                let p = LatticeProblem {
                    first: (0..n).map(|c| base.first[mirrored(c)]).collect(),
                    second: (0..n).map(|c| base.second[mirrored(c)]).collect(),
                    source: (0..n).map(|c| base.source[mirrored(c)]).collect(),
                    ..base
                };
                let m = march(
                    &p,
                    &settings(velocities, collision, Absorption::True, streaming, 30),
                )
                .unwrap();
                let peak = m.fluence.iter().fold(0.0f32, |a, &b| a.max(b.abs()));
                assert!(peak > 0.0);
                for c in 0..n {
                    let (x, rest) = (c % nx, c / nx);
                    let twin = nx - 1 - x + nx * rest;
                    assert!(
                        (m.fluence[c] - m.fluence[twin]).abs() <= 1e-5 * peak,
                        "{velocities:?} {collision:?} {streaming:?}: cell ({x}, {}, {}) {} \
                         against its mirror {}",
                        rest % ny,
                        rest / ny,
                        m.fluence[c],
                        m.fluence[twin]
                    );
                }
            }
        }
    }
}

#[test]
fn energy_is_conserved_to_rounding_over_long_marches() {
    // 400 steps on a 9 x 8 x 10 box: the books close to 1e-6 for every wall, both lattices.
    for velocities in [Velocities::D3q7, Velocities::D3q19] {
        for kind in 0..5 {
            let p = problem([9, 8, 10], Collision::Trt, wall_of(kind), 7, true);
            let m = march(
                &p,
                &settings(
                    velocities,
                    Collision::Trt,
                    Absorption::True,
                    Streaming::InPlace,
                    400,
                ),
            )
            .unwrap();
            let b = m.bookkeeping;
            assert!(
                b.conservation_error() < 1e-6,
                "{velocities:?} wall {kind}: {b:?}"
            );
        }
    }
}

#[test]
fn the_thesis_absorption_keeps_the_energy_true_absorption_removes_it() {
    // A reflecting box: nothing escapes. With the thesis's matrices nothing is absorbed
    // either, so the lattice holds all that was emitted; with true absorption it holds less
    // and the books say where the rest went.
    for velocities in [Velocities::D3q7, Velocities::D3q19] {
        for collision in [Collision::Trt, Collision::Geist] {
            let p = problem([6, 5, 7], collision, Wall::Neumann { flux: 0.0 }, 3, false);
            let run = |absorption| {
                march(
                    &p,
                    &settings(velocities, collision, absorption, Streaming::InPlace, 120),
                )
                .unwrap()
                .bookkeeping
            };
            let thesis = run(Absorption::Thesis);
            assert_eq!(thesis.absorbed, 0.0);
            assert!(thesis.escaped.abs() < 1e-6 * thesis.emitted, "{thesis:?}");
            assert!(
                (thesis.held - thesis.emitted).abs() < 1e-5 * thesis.emitted,
                "{velocities:?} {collision:?}: {thesis:?}"
            );
            let true_ = run(Absorption::True);
            assert!(true_.absorbed > 0.05 * true_.emitted, "{true_:?}");
            assert!(true_.held < 0.95 * thesis.held);
            assert!(true_.conservation_error() < 1e-5, "{true_:?}");
        }
    }
}

#[test]
fn a_sink_beyond_one_per_step_is_refused() {
    let mut p = problem([4, 4, 4], Collision::Trt, Wall::Robin { a: 1.0 }, 1, false);
    p.second[5] = 1.2;
    let err = march(
        &p,
        &settings(
            Velocities::D3q7,
            Collision::Trt,
            Absorption::True,
            Streaming::InPlace,
            10,
        ),
    )
    .unwrap_err();
    assert!(
        matches!(err, LbmError::Unstable { limit, .. } if limit == 1.0),
        "{err:?}"
    );
    // Just below the limit, the march runs and stays finite.
    p.second[5] = 0.99;
    let m = march(
        &p,
        &settings(
            Velocities::D3q7,
            Collision::Trt,
            Absorption::True,
            Streaming::InPlace,
            200,
        ),
    )
    .unwrap();
    assert!(matches!(m.stop_reason, StopReason::IterationLimit { .. }));
    assert!(m.fluence.iter().all(|v| v.is_finite()));
}

#[test]
fn a_converged_march_balances_its_energy_to_the_tolerance() {
    // The stopping test includes the energy imbalance per step, so a march converged to
    // 1e-6 emits what it absorbs and lets escape to 1e-6, for every wall and lattice.
    for velocities in [Velocities::D3q7, Velocities::D3q19] {
        for kind in 0..5 {
            let p = problem([10, 9, 11], Collision::Trt, wall_of(kind), 11, true);
            let mut s = settings(
                velocities,
                Collision::Trt,
                Absorption::True,
                Streaming::InPlace,
                100_000,
            );
            s.stopping.relative_tolerance = 1e-6;
            let m = march(&p, &s).unwrap();
            assert!(
                m.stop_reason.is_converged(),
                "{velocities:?} {kind}: {:?}",
                m.stop_reason
            );
            let b = m.bookkeeping;
            assert!(
                b.steady_imbalance() <= 1e-6,
                "{velocities:?} wall {kind}: {b:?}"
            );
            assert!(
                b.conservation_error() < 1e-6,
                "{velocities:?} wall {kind}: {b:?}"
            );
        }
    }
}
