//! Zhang & Ma's absorption march on ranks gives the serial bits: a proptest over grids
//! (sides 1–13, not multiples of 8), light directions (every octant, components zero,
//! diagonal, each axis dominant), heterogeneous absorption, both one-pass models and 1–5
//! in-process ranks, so both shapes of the split run (the pipeline with chunks of one row
//! and of several, the lock step with slabs of two layers and more); then the refusals.

use glam::DVec3;
use lucent_core::StopReason;
use lucent_explicit::Lattice;
use lucent_explicit::convection::{Edges, Light, Model, Sweep, UpwindSettings, propagate};
use lucent_explicit::ranks::{Boxes, Decomposition, DecompositionError};
use lucent_explicit::wavefront::propagate_on_threads;
use proptest::prelude::*;

/// Absorption varying cell to cell (a hash of the index), within `[0, top]`.
fn absorption(n: usize, seed: u64, top: f64) -> Vec<f64> {
    (0..n as u64)
        .map(|c| {
            let h = (c ^ seed)
                .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                .rotate_left(29);
            top * (h % 1000) as f64 / 999.0
        })
        .collect()
}

fn settings(model: Model) -> UpwindSettings {
    UpwindSettings {
        model,
        ..UpwindSettings::default()
    }
}

/// A direction component: zero, ± the other components' size, or between.
fn component() -> impl Strategy<Value = f64> {
    prop_oneof![Just(0.0), Just(1.0), Just(-1.0), -1.0..1.0f64, Just(-0.0),]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    #[test]
    fn the_march_on_ranks_is_the_serial_march(
        dims in (1usize..=13, 1usize..=13, 1usize..=13),
        u in (component(), component(), component()),
        paper in any::<bool>(),
        ranks in 1usize..=5,
        seed in any::<u64>(),
        spacing in 0.05..0.5f64,
    ) {
        let dims = [dims.0, dims.1, dims.2];
        let direction = DVec3::new(u.0, u.1, u.2);
        prop_assume!(direction.length() > 1e-3);
        let lattice = Lattice::new(dims, spacing).unwrap();
        let n = lattice.len();
        // Per-step absorption in [0, 0.9] for the paper, a rate up to 4/length otherwise.
        let (model, sigma) = if paper {
            (Model::Paper, absorption(n, seed, 0.9))
        } else {
            (Model::Characteristic, absorption(n, seed, 4.0))
        };
        let light = Light::Distant { direction, density: 1.5 };
        let serial = propagate(&lattice, &sigma, &light, &settings(model)).unwrap();
        let split = propagate_on_threads(&lattice, &sigma, &light, &settings(model), &Decomposition::Slabs, ranks);
        let lockstep = model == Model::Characteristic
            && direction.normalize().abs().max_position() != 2;
        // Slabs of one layer are too thin for the lock step's halo when there are neighbours.
        let thin = ranks > 1
            && (0..ranks).any(|r| (r + 1) * dims[2] / ranks - r * dims[2] / ranks < 2);
        match split {
            Err(DecompositionError::TooManyRanks { .. }) => prop_assert!(ranks > dims[2]),
            Err(DecompositionError::StencilTooWide { .. }) => {
                prop_assert!(lockstep && ranks <= dims[2] && thin);
            }
            Err(e) => prop_assert!(false, "{e}"),
            Ok(split) => {
                prop_assert!(ranks <= dims[2] && !(lockstep && thin));
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                prop_assert_eq!(bits(&split.density), bits(&serial.density));
                prop_assert_eq!(split.iterations, serial.iterations);
                prop_assert_eq!(&split.residuals, &serial.residuals);
                prop_assert_eq!(split.stop_reason, StopReason::Exact);
                prop_assert_eq!(serial.stop_reason, StopReason::Exact);
            }
        }
    }
}

/// Every light of a fixed set (each axis dominant both ways, a diagonal, an axis) and
/// both one-pass models through heterogeneous absorption on a `dims` grid: each of
/// `splits` (a decomposition and its rank count) gives the serial march's bits.
fn larger_grid_against_serial(dims: [usize; 3], splits: &[(Decomposition, usize)]) {
    let lattice = Lattice::new(dims, 0.1).unwrap();
    let sigma = absorption(lattice.len(), 7, 3.0);
    let paper_sigma = absorption(lattice.len(), 11, 0.5);
    let directions = [
        DVec3::new(0.3, -0.2, 1.0),
        DVec3::new(-0.4, 0.5, -1.0),
        DVec3::new(1.0, 0.6, -0.3),
        DVec3::new(0.2, -1.0, 0.7),
        DVec3::new(-1.0, -1.0, 0.0),
        DVec3::new(0.0, 0.0, -1.0),
    ];
    for direction in directions {
        let light = Light::Distant {
            direction,
            density: 1.0,
        };
        for (model, sigma) in [
            (Model::Characteristic, &sigma),
            (Model::Paper, &paper_sigma),
        ] {
            let serial = propagate(&lattice, sigma, &light, &settings(model)).unwrap();
            assert!(serial.density.iter().all(|v| v.is_finite() && *v > 0.0));
            for (split, ranks) in splits {
                let out =
                    propagate_on_threads(&lattice, sigma, &light, &settings(model), split, *ranks)
                        .unwrap();
                assert!(
                    out.density
                        .iter()
                        .zip(&serial.density)
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{model:?} {direction} on {ranks} ranks over {split:?}"
                );
            }
        }
    }
}

/// A larger grid, every rank count to 5 over z-slabs (one rank runs the split code too):
/// the pipeline's chunks of several rows and the lock step's inner rows (slabs of five
/// layers and more).
#[test]
fn larger_grids_on_every_rank_count() {
    let splits: Vec<(Decomposition, usize)> =
        (1..=5).map(|ranks| (Decomposition::Slabs, ranks)).collect();
    larger_grid_against_serial([23, 19, 27], &splits);
}

#[test]
fn marches_that_do_not_split_are_refused_on_ranks_and_run_on_one() {
    let lattice = Lattice::new([6, 5, 8], 0.2).unwrap();
    let sigma = vec![0.3; lattice.len()];
    let distant = Light::Distant {
        direction: DVec3::new(0.1, 0.2, 1.0),
        density: 1.0,
    };
    let point = Light::Point {
        position: DVec3::new(0.6, 0.5, 0.8),
        density: 1.0,
        falloff: None,
    };
    let cases = [
        (point, settings(Model::Characteristic)),
        (distant, settings(Model::Conservative)),
        (
            distant,
            UpwindSettings {
                sweep: Sweep::Jacobi,
                ..settings(Model::Paper)
            },
        ),
        (
            distant,
            UpwindSettings {
                edges: Edges::Periodic,
                ..settings(Model::Paper)
            },
        ),
    ];
    for (light, settings) in cases {
        let serial = propagate(&lattice, &sigma, &light, &settings).unwrap();
        for split in [
            Decomposition::Slabs,
            Decomposition::Boxes(Boxes::new([6, 5, 8], [1, 1, 1]).unwrap()),
        ] {
            let one = propagate_on_threads(&lattice, &sigma, &light, &settings, &split, 1);
            assert_eq!(one.unwrap(), serial);
        }
        for split in [
            Decomposition::Slabs,
            Decomposition::Boxes(Boxes::new([6, 5, 8], [1, 2, 1]).unwrap()),
        ] {
            assert!(matches!(
                propagate_on_threads(&lattice, &sigma, &light, &settings, &split, 2),
                Err(DecompositionError::Unsupported(_))
            ));
        }
    }
    // Bad input is the serial march's error, on ranks too.
    let bad = vec![-1.0; lattice.len()];
    for split in [
        Decomposition::Slabs,
        Decomposition::Boxes(Boxes::new([6, 5, 8], [1, 1, 2]).unwrap()),
    ] {
        assert!(matches!(
            propagate_on_threads(&lattice, &bad, &distant, &settings(Model::Paper), &split, 2),
            Err(DecompositionError::Scheme(_))
        ));
    }
}

/// Each rank handed only the layers `read_layers` names (as it reads them from a file)
/// returns its owned layers of the serial ρ; a bad value in one rank's layers stops every
/// rank with an error.
#[test]
fn a_rank_needs_only_its_layers() {
    use lucent_core::ranks::Threads;
    use lucent_explicit::wavefront::{owned_layers, propagate_slab, read_layers};
    let lattice = Lattice::new([9, 7, 17], 0.15).unwrap();
    let layer = 9 * 7;
    let sigma = absorption(lattice.len(), 3, 2.5);
    for direction in [DVec3::new(0.2, 0.3, -1.0), DVec3::new(0.9, -0.3, 0.4)] {
        let light = Light::Distant {
            direction,
            density: 2.0,
        };
        for model in [Model::Characteristic, Model::Paper] {
            let sigma: Vec<f64> = match model {
                Model::Paper => sigma.iter().map(|s| s / 3.0).collect(),
                _ => sigma.clone(),
            };
            let serial = propagate(&lattice, &sigma, &light, &settings(model)).unwrap();
            for ranks in 1..=4 {
                let parts = Threads::run(ranks, |comm| {
                    use lucent_core::ranks::Communicator;
                    let reads = read_layers(17, ranks, comm.rank());
                    let mine = &sigma[reads.start * layer..reads.end * layer];
                    propagate_slab(&lattice, mine, &light, &settings(model), comm)
                });
                for (rank, part) in parts.into_iter().enumerate() {
                    let owned = owned_layers(17, ranks, rank);
                    let part = part.unwrap().unwrap();
                    assert!(
                        part.iter()
                            .zip(&serial.density[owned.start * layer..owned.end * layer])
                            .all(|(a, b)| a.to_bits() == b.to_bits()),
                        "{model:?} {direction}: rank {rank} of {ranks}"
                    );
                }
            }
        }
        // A NaN in rank 1's layers only: every rank returns an error (none waits).
        let light = Light::Distant {
            direction,
            density: 1.0,
        };
        let results = Threads::run(3, |comm| {
            use lucent_core::ranks::Communicator;
            let reads = read_layers(17, 3, comm.rank());
            let mut mine = sigma[reads.start * layer..reads.end * layer].to_vec();
            if comm.rank() == 1 {
                mine[5] = f64::NAN;
            }
            propagate_slab(
                &lattice,
                &mine,
                &light,
                &settings(Model::Characteristic),
                comm,
            )
        });
        for (rank, result) in results.into_iter().enumerate() {
            let e = result.unwrap().unwrap_err();
            assert!(
                matches!(e, DecompositionError::Scheme(_)),
                "rank {rank}: {e}"
            );
        }
    }
}

/// A grid of boxes over `dims`: `grid` boxes per axis, cut evenly or, with `seed`, at
/// random places (x at multiples of 8, as `Boxes` asks); `None` where the axis is too short.
fn boxes(dims: [usize; 3], grid: [usize; 3], seed: Option<u64>) -> Option<Boxes> {
    let Some(seed) = seed else {
        return Boxes::new(dims, grid).ok();
    };
    let mut state = seed | 1;
    let mut draw = |n: usize| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state % n as u64) as usize
    };
    let cuts: [Vec<usize>; 3] = std::array::from_fn(|a| {
        let unit = if a == 0 { 8 } else { 1 };
        let places = dims[a].div_ceil(unit);
        let mut inner: Vec<usize> = (1..places).map(|p| p * unit).collect();
        // Keep grid[a] − 1 of the inner places, dropped at random.
        while inner.len() + 1 > grid[a] && !inner.is_empty() {
            let at = draw(inner.len());
            inner.remove(at);
        }
        let mut cuts = vec![0];
        cuts.extend(inner);
        cuts.push(dims[a]);
        cuts
    });
    if (0..3).any(|a| cuts[a].len() != grid[a] + 1) {
        return None;
    }
    Boxes::from_cuts(dims, cuts).ok()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    /// Over any grid of boxes (even or uneven cuts, boxes one cell thin, up to 8 ranks),
    /// every light direction and both one-pass models: the serial bits.
    #[test]
    fn the_march_over_boxes_is_the_serial_march(
        dims in (1usize..=20, 1usize..=11, 1usize..=11),
        grid in (1usize..=3, 1usize..=3, 1usize..=3),
        uneven in proptest::option::of(any::<u64>()),
        u in (component(), component(), component()),
        paper in any::<bool>(),
        seed in any::<u64>(),
        spacing in 0.05..0.5f64,
    ) {
        let dims = [dims.0, dims.1, dims.2];
        let grid = [grid.0, grid.1, grid.2];
        let direction = DVec3::new(u.0, u.1, u.2);
        prop_assume!(direction.length() > 1e-3);
        // None: fewer places to cut than boxes asked for.
        let boxes = boxes(dims, grid, uneven);
        prop_assume!(boxes.is_some());
        let boxes = boxes.unwrap();
        prop_assume!(boxes.ranks() <= 8);
        let lattice = Lattice::new(dims, spacing).unwrap();
        let n = lattice.len();
        let (model, sigma) = if paper {
            (Model::Paper, absorption(n, seed, 0.9))
        } else {
            (Model::Characteristic, absorption(n, seed, 4.0))
        };
        let light = Light::Distant { direction, density: 1.5 };
        let serial = propagate(&lattice, &sigma, &light, &settings(model)).unwrap();
        let ranks = boxes.ranks();
        let split = propagate_on_threads(
            &lattice,
            &sigma,
            &light,
            &settings(model),
            &Decomposition::Boxes(boxes.clone()),
            ranks,
        )
        .map_err(|e| TestCaseError::fail(format!("{boxes:?}: {e}")))?;
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        prop_assert_eq!(bits(&split.density), bits(&serial.density), "{:?}", boxes);
        prop_assert_eq!(split.stop_reason, StopReason::Exact);
    }
}

/// Larger grids over boxes cut along every axis, evenly and unevenly (boxes one and two
/// cells thin, where the characteristic's stencil reaches past the next box).
#[test]
fn larger_grids_over_boxes() {
    let dims = [27, 19, 23];
    let grids = [
        Boxes::new(dims, [2, 2, 1]).unwrap(),
        Boxes::new(dims, [1, 2, 3]).unwrap(),
        Boxes::new(dims, [2, 1, 2]).unwrap(),
        Boxes::from_cuts(dims, [vec![0, 8, 27], vec![0, 1, 3, 19], vec![0, 22, 23]]).unwrap(),
        Boxes::from_cuts(dims, [vec![0, 27], vec![0, 17, 18, 19], vec![0, 2, 3, 23]]).unwrap(),
    ];
    let splits: Vec<(Decomposition, usize)> = grids
        .into_iter()
        .map(|b| {
            let ranks = b.ranks();
            (Decomposition::Boxes(b), ranks)
        })
        .collect();
    larger_grid_against_serial(dims, &splits);
}

/// Each rank handed only the cells `read_box` names (as it reads them from a file)
/// returns its box of the serial ρ; a bad value in one rank's cells stops every rank with
/// an error; boxes that do not fit the grid or the ranks are refused on every rank.
#[test]
fn a_rank_needs_only_its_box() {
    use lucent_core::ranks::{Communicator, Threads};
    use lucent_explicit::wavefront::{propagate_box, read_box};
    use lucent_grid::box_cells;
    let dims = [17, 11, 9];
    let lattice = Lattice::new(dims, 0.15).unwrap();
    let at = |p: [usize; 3]| p[0] + dims[0] * (p[1] + dims[1] * p[2]);
    let sigma = absorption(lattice.len(), 3, 2.5);
    let boxes = Boxes::new(dims, [2, 2, 2]).unwrap();
    for direction in [DVec3::new(0.2, 0.3, -1.0), DVec3::new(0.9, -0.3, 0.4)] {
        let light = Light::Distant {
            direction,
            density: 2.0,
        };
        for model in [Model::Characteristic, Model::Paper] {
            let sigma: Vec<f64> = match model {
                Model::Paper => sigma.iter().map(|s| s / 3.0).collect(),
                _ => sigma.clone(),
            };
            let serial = propagate(&lattice, &sigma, &light, &settings(model)).unwrap();
            let parts = Threads::run(8, |comm| {
                let mine: Vec<f64> = box_cells(&read_box(&boxes, comm.rank()))
                    .map(|p| sigma[at(p)])
                    .collect();
                propagate_box(&lattice, &mine, &light, &settings(model), &boxes, comm)
            });
            for (rank, part) in parts.into_iter().enumerate() {
                let part = part.unwrap().unwrap();
                let expected: Vec<u64> = box_cells(&boxes.bounds(rank))
                    .map(|p| serial.density[at(p)].to_bits())
                    .collect();
                let got: Vec<u64> = part.iter().map(|v| v.to_bits()).collect();
                assert_eq!(got, expected, "{model:?} {direction}: rank {rank}");
            }
        }
        // A NaN in rank 5's cells only, or one value short on rank 2: every rank returns
        // an error (none waits).
        let light = Light::Distant {
            direction,
            density: 1.0,
        };
        for bad_rank in [5, 2] {
            let results = Threads::run(8, |comm| {
                let mut mine: Vec<f64> = box_cells(&read_box(&boxes, comm.rank()))
                    .map(|p| sigma[at(p)])
                    .collect();
                if comm.rank() == bad_rank {
                    if bad_rank == 5 {
                        mine[3] = f64::NAN;
                    } else {
                        mine.pop();
                    }
                }
                let settings = settings(Model::Characteristic);
                propagate_box(&lattice, &mine, &light, &settings, &boxes, comm)
            });
            for (rank, result) in results.into_iter().enumerate() {
                let e = result.unwrap().unwrap_err();
                assert!(
                    matches!(e, DecompositionError::Scheme(_)),
                    "rank {rank}: {e}"
                );
            }
        }
    }
    // Boxes for another grid, or for another rank count.
    let light = Light::Distant {
        direction: DVec3::Z,
        density: 1.0,
    };
    for (other, ranks) in [(Boxes::new([16, 11, 9], [2, 1, 1]).unwrap(), 2), (boxes, 4)] {
        let results = Threads::run(ranks, |comm| {
            propagate_box(
                &lattice,
                &sigma,
                &light,
                &settings(Model::Paper),
                &other,
                comm,
            )
        });
        for result in results {
            assert!(matches!(
                result.unwrap(),
                Err(DecompositionError::BoxGrid { .. })
            ));
        }
    }
}

/// The grid of boxes the march picks leaves an axis whole, the light's dominant one first
/// for characteristics (every rank then works on every plane), and is the least cut
/// grid where none can.
#[test]
fn the_march_picks_boxes_that_leave_an_axis_whole() {
    use lucent_explicit::wavefront::march_boxes;
    let cube = [512, 512, 512];
    let along_z = DVec3::new(0.3, -0.2, 1.0);
    let along_x = DVec3::new(-1.0, 0.3, -0.2);
    let grid = |dims, ranks, u, model| march_boxes(dims, ranks, u, model).unwrap().grid();
    // Boxes::auto cuts every axis of a cube in 4.
    assert_eq!(Boxes::auto(cube, 64).unwrap().grid(), [4, 4, 4]);
    assert_eq!(grid(cube, 64, along_z, Model::Characteristic), [8, 8, 1]);
    assert_eq!(grid(cube, 64, along_x, Model::Characteristic), [1, 8, 8]);
    let paper = grid(cube, 64, along_z, Model::Paper);
    assert!(
        paper.contains(&1) && paper.iter().product::<usize>() == 64,
        "{paper:?}"
    );
    // x is cut at multiples of 8 only: a 12-wide grid stays whole in x.
    assert_eq!(
        grid([12, 40, 40], 16, along_x, Model::Characteristic),
        [1, 4, 4]
    );
    // 8 ranks on 16 × 2 × 2 cells: only 2 × 2 × 2 fits.
    assert_eq!(
        grid([16, 2, 2], 8, along_z, Model::Characteristic),
        [2, 2, 2]
    );
    assert!(march_boxes([16, 2, 2], 7, along_z, Model::Paper).is_err());
}
