//! The decomposed explicit schemes give the serial bits on 1 to 12 in-process ranks. The
//! steady iterations: fluence, residual history and stop reason, for FTCS and Jacobi, on
//! heterogeneous problems with an embedded sphere on grids whose sides are not multiples
//! of 8, over z-slabs and over grids of boxes (cut in x, y and z, some boxes holding no
//! unknowns); P1 below.

use glam::DVec3;
use lucent_core::ranks::Threads;
use lucent_core::{StopReason, Stopping};
use lucent_diffusion::{
    AssembledSystem, Boundaries, CellGeometry, Condition, DiffusionProblem, Discretisation, Sources,
};
use lucent_explicit::ranks::{Boxes, Decomposition, DecompositionError, iterate_on};
use lucent_explicit::steady::{Iteration, Steady, SteadySettings, ftcs_limit, iterate as serial};
use lucent_grid::GridGeometry;

/// Diffusion in a sphere of `radius` (the box is 6 × 5 × 7) with a point source off the
/// centre: D varies cell to cell, Robin on the sphere.
fn system(dims: [usize; 3], radius: f64) -> (AssembledSystem, f64) {
    let grid = GridGeometry::from_bounds(
        dims,
        DVec3::new(-3.0, -2.5, -3.5),
        DVec3::new(3.0, 2.5, 3.5),
    )
    .unwrap();
    let cells = CellGeometry::from_sdf(
        grid,
        |p| p.length() - radius,
        Discretisation::EmbeddedBoundary,
    )
    .unwrap();
    let n = grid.voxel_count();
    let d: Vec<f32> = (0..n).map(|c| 0.1 + 0.1 * ((c * 7) % 5) as f32).collect();
    let problem = DiffusionProblem::new(
        cells,
        d,
        vec![0.05; n],
        Boundaries::uniform(Condition::Robin { a: 2.2 }),
    )
    .unwrap();
    let sources = Sources {
        points: vec![(DVec3::new(0.2, -0.1, 0.3), 1.0)],
        ..Sources::default()
    };
    (problem.assemble(&sources).unwrap(), grid.cell_volume())
}

fn on_ranks(
    ranks: usize,
    system: &AssembledSystem,
    dims: [usize; 3],
    decomposition: &Decomposition,
    iteration: Iteration,
    settings: &SteadySettings,
) -> Vec<Result<Steady, DecompositionError>> {
    Threads::run(ranks, |comm| {
        iterate_on(system, dims, decomposition, iteration, settings, comm)
    })
    .into_iter()
    .map(Option::unwrap)
    .collect()
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// To 10⁻⁴: converged (the stop is part of what must agree), in a few hundred steps; the
/// bits of every step agree or none do, so a tighter tolerance (10⁻⁷ took thousands of
/// steps per decomposition) proves nothing more.
fn converging() -> SteadySettings {
    SteadySettings {
        stopping: Stopping {
            relative_tolerance: 1e-4,
            max_iterations: 50_000,
            ..Stopping::default()
        },
        allow_unstable: false,
    }
}

/// Every rank's result is the serial fluence, history and stop reason, to the bit.
fn assert_serial_bits(
    system: &AssembledSystem,
    volume: f64,
    dims: [usize; 3],
    decompositions: &[(usize, Decomposition)],
) {
    let settings = converging();
    for iteration in [
        Iteration::Ftcs {
            time_step: 0.9 * ftcs_limit(system, volume),
            cell_volume: volume,
        },
        Iteration::Jacobi { omega: 0.8 },
    ] {
        let reference = serial(system, dims, iteration, &settings).unwrap();
        assert!(reference.stop_reason.is_converged(), "{iteration:?}");
        for (ranks, decomposition) in decompositions {
            for (rank, out) in on_ranks(*ranks, system, dims, decomposition, iteration, &settings)
                .into_iter()
                .enumerate()
            {
                let case = format!("{iteration:?}, {decomposition:?}, rank {rank} of {ranks}");
                let out = out.unwrap();
                assert_eq!(out.stop_reason, reference.stop_reason, "{case}");
                assert_eq!(bits(&out.residuals), bits(&reference.residuals), "{case}");
                assert_eq!(bits(&out.fluence), bits(&reference.fluence), "{case}");
            }
        }
    }
}

#[test]
fn every_slab_count_gives_the_serial_bits() {
    let dims = [13, 11, 19];
    let (system, volume) = system(dims, 2.4);
    let slabs: Vec<_> = (1..=5).map(|p| (p, Decomposition::Slabs)).collect();
    assert_serial_bits(&system, volume, dims, &slabs);
}

#[test]
fn every_grid_of_boxes_gives_the_serial_bits() {
    // 21 cells in x: three runs of 8 (the last of 5), so up to three boxes along x.
    let dims = [21, 11, 19];
    let (system, volume) = system(dims, 2.4);
    let grids = [
        [1, 1, 1],
        [2, 1, 1],
        [3, 1, 1],
        [1, 2, 1],
        [1, 1, 2],
        [2, 2, 1],
        [3, 1, 3],
        [2, 3, 2],
    ];
    let boxes: Vec<_> = grids
        .iter()
        .map(|&g| {
            let boxes = Boxes::new(dims, g).unwrap();
            (boxes.ranks(), Decomposition::Boxes(boxes))
        })
        .collect();
    assert_serial_bits(&system, volume, dims, &boxes);
}

#[test]
fn boxes_with_no_unknowns_wait_and_keep_the_bits() {
    // A small sphere: the eight corner boxes of 3 × 3 × 3 lie wholly outside it.
    let dims = [24, 10, 13];
    let (system, volume) = system(dims, 1.4);
    let boxes = Boxes::new(dims, [3, 3, 3]).unwrap();
    let empty = (0..boxes.ranks())
        .filter(|&r| !system.cells.iter().any(|&c| boxes.rank_of(c) == r))
        .count();
    assert!(empty >= 8, "{empty} empty boxes");
    assert_serial_bits(&system, volume, dims, &[(27, Decomposition::Boxes(boxes))]);
}

#[test]
fn the_automatic_grid_cuts_least_and_covers_every_cell() {
    // Least cut area; ties to more cuts in z, then y.
    for (dims, ranks, grid) in [
        ([64, 64, 64], 8, [2, 2, 2]),
        // docs/ranks.md's model.
        ([1024, 1024, 1024], 1024, [8, 8, 16]),
        ([1024, 1024, 1024], 64, [4, 4, 4]),
        ([64, 64, 64], 2, [1, 1, 2]),
        ([64, 64, 64], 4, [1, 2, 2]),
        ([64, 64, 8], 4, [2, 2, 1]),
        ([256, 16, 16], 4, [4, 1, 1]),
        ([13, 11, 19], 6, [2, 1, 3]),
        ([7, 3, 2], 3, [1, 3, 1]),
    ] {
        assert_eq!(
            Boxes::auto(dims, ranks).unwrap().grid(),
            grid,
            "{dims:?} on {ranks}"
        );
    }
    // Nothing fits: five ranks on a grid with one run in x, one cell in y and 4 in z.
    assert_eq!(
        Boxes::auto([8, 1, 4], 5),
        Err(DecompositionError::BoxGrid {
            grid: [1, 1, 1],
            dims: [8, 1, 4],
            ranks: 5
        })
    );
    assert!(Boxes::new([17, 4, 4], [4, 1, 1]).is_err());
    assert!(Boxes::new([17, 4, 4], [3, 1, 0]).is_err());
    // Every cell in exactly the box whose bounds hold it; x cuts at multiples of 8.
    for (dims, grid) in [
        ([17, 5, 6], [3, 2, 4]),
        ([40, 3, 7], [5, 3, 7]),
        ([9, 9, 9], [1, 1, 1]),
    ] {
        let boxes = Boxes::new(dims, grid).unwrap();
        let mut count = vec![0usize; boxes.ranks()];
        for c in 0..dims.iter().product() {
            let r = boxes.rank_of(c);
            let at = [
                c % dims[0],
                (c / dims[0]) % dims[1],
                c / (dims[0] * dims[1]),
            ];
            let bounds = boxes.bounds(r);
            assert!(
                (0..3).all(|a| bounds[a].contains(&at[a])),
                "{dims:?} cell {c}"
            );
            count[r] += 1;
        }
        for r in 0..boxes.ranks() {
            let b = boxes.bounds(r);
            assert_eq!(count[r], b.iter().map(|r| r.len()).product::<usize>());
            assert!(count[r] > 0);
            assert!(b[0].start.is_multiple_of(8), "{dims:?} {grid:?} rank {r}");
        }
    }
}

#[test]
fn boxes_for_another_rank_count_or_grid_are_refused_on_every_rank() {
    let dims = [13, 11, 19];
    let (system, _) = system(dims, 2.4);
    let settings = converging();
    let jacobi = Iteration::Jacobi { omega: 1.0 };
    let four = Decomposition::Boxes(Boxes::new(dims, [1, 2, 2]).unwrap());
    for out in on_ranks(3, &system, dims, &four, jacobi, &settings) {
        assert!(matches!(
            out,
            Err(DecompositionError::BoxGrid { ranks: 3, .. })
        ));
    }
    let other = Decomposition::Boxes(Boxes::new([13, 11, 18], [1, 1, 2]).unwrap());
    for out in on_ranks(2, &system, dims, &other, jacobi, &settings) {
        assert!(matches!(out, Err(DecompositionError::BoxGrid { .. })));
    }
    // A grid too small for the system's cells (nine layers missing): an error, not an
    // unknown given to a rank that is not there.
    let small = [13, 11, 10];
    let boxes = Decomposition::Boxes(Boxes::new(small, [1, 1, 2]).unwrap());
    for decomposition in [&Decomposition::Slabs, &boxes] {
        for out in on_ranks(2, &system, small, decomposition, jacobi, &settings) {
            assert!(
                matches!(&out, Err(DecompositionError::Matrix(m)) if m.contains("beyond")),
                "{out:?}"
            );
        }
    }
}

#[test]
fn a_time_limit_stops_every_rank_on_the_same_sweep() {
    let dims = [12, 12, 16];
    let (system, _) = system(dims, 2.4);
    let settings = SteadySettings {
        stopping: Stopping {
            relative_tolerance: 0.0,
            max_iterations: usize::MAX,
            time_budget: Some(std::time::Duration::from_millis(50)),
            ..Stopping::default()
        },
        allow_unstable: false,
    };
    let boxes = Decomposition::Boxes(Boxes::new(dims, [1, 2, 2]).unwrap());
    for (ranks, decomposition) in [(3, Decomposition::Slabs), (4, boxes)] {
        let outs: Vec<Steady> = on_ranks(
            ranks,
            &system,
            dims,
            &decomposition,
            Iteration::Jacobi { omega: 1.0 },
            &settings,
        )
        .into_iter()
        .map(Result::unwrap)
        .collect();
        assert!(matches!(outs[0].stop_reason, StopReason::TimeLimit { .. }));
        for out in &outs[1..] {
            assert_eq!(out.residuals.len(), outs[0].residuals.len());
            assert_eq!(bits(&out.fluence), bits(&outs[0].fluence));
        }
    }
}

#[test]
fn more_ranks_than_layers_is_an_error() {
    let dims = [6, 6, 4];
    let (system, _) = system(dims, 2.4);
    let settings = SteadySettings {
        stopping: Stopping::default(),
        allow_unstable: false,
    };
    for out in on_ranks(
        7,
        &system,
        dims,
        &Decomposition::Slabs,
        Iteration::Jacobi { omega: 1.0 },
        &settings,
    ) {
        assert!(matches!(
            out,
            Err(DecompositionError::TooManyRanks { ranks: 7, .. })
        ));
    }
}

#[test]
fn what_the_serial_iteration_refuses_every_rank_refuses() {
    let dims = [9, 10, 11];
    let (system, volume) = system(dims, 2.4);
    let settings = SteadySettings {
        stopping: Stopping::default(),
        allow_unstable: false,
    };
    let boxes = Decomposition::Boxes(Boxes::new(dims, [1, 2, 1]).unwrap());
    for iteration in [
        Iteration::Jacobi { omega: 1.5 },
        Iteration::Ftcs {
            time_step: 1.1 * ftcs_limit(&system, volume),
            cell_volume: volume,
        },
    ] {
        let serial_error = serial(&system, dims, iteration, &settings).unwrap_err();
        for decomposition in [&Decomposition::Slabs, &boxes] {
            for out in on_ranks(2, &system, dims, decomposition, iteration, &settings) {
                assert_eq!(
                    out.unwrap_err(),
                    DecompositionError::Scheme(serial_error.clone())
                );
            }
        }
    }
}

mod p1 {
    //! P1 by FTCS on ranks (`ranks::march_p1`, `march_p1_on`): the serial march's bits on
    //! 1 to 5 slabs and on grids of up to 12 boxes (even and uneven cuts), both layouts, from a point source off the grid's centre on grids whose sides are
    //! not multiples of 8, to convergence, to the step limit, and past the stability bound
    //! (the growth monitor must stop every rank on the serial step).

    use lucent_core::ranks::Threads;
    use lucent_core::{StopReason, Stopping};
    use lucent_explicit::Lattice;
    use lucent_explicit::p1::{Damping, Layout, P1Edges, P1Settings, P1State, march};
    use lucent_explicit::ranks::{Boxes, Decomposition, DecompositionError, march_p1_on};

    fn settings(layout: Layout, fraction: f64, stopping: Stopping) -> P1Settings {
        let (sigma_a, reduced) = (0.3, 2.0);
        let limit = lucent_explicit::stability::p1::largest_step(
            layout == Layout::Staggered,
            sigma_a,
            reduced,
            1.0,
        );
        P1Settings {
            layout,
            damping: Damping::Consistent {
                sigma_a,
                sigma_t_reduced: reduced,
            },
            time_step: fraction * limit,
            stopping,
            edges: P1Edges::Zero,
            allow_unstable: fraction > 1.0,
        }
    }

    fn on_ranks(
        ranks: usize,
        lattice: &Lattice,
        source: &[f64],
        decomposition: &Decomposition,
        settings: &P1Settings,
    ) -> Vec<Result<P1State, DecompositionError>> {
        std::thread::scope(|scope| {
            let handles: Vec<_> = Threads::world(ranks)
                .into_iter()
                .map(|comm| {
                    scope
                        .spawn(move || march_p1_on(lattice, source, decomposition, settings, &comm))
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        })
    }

    /// `out` is `reference` to the bit: stop, steps, every step's change (the norm's
    /// bits), φ and E.
    fn assert_serial_bits(out: &P1State, reference: &P1State, case: &str) {
        assert_eq!(out.stop_reason, reference.stop_reason, "{case}");
        assert_eq!(out.steps, reference.steps, "{case}");
        assert_eq!(bits(&out.changes), bits(&reference.changes), "{case}");
        assert_eq!(bits(&out.fluence), bits(&reference.fluence), "{case}");
        for a in 0..3 {
            assert_eq!(bits(&out.flux[a]), bits(&reference.flux[a]), "{case}");
        }
    }

    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    #[test]
    fn every_rank_count_gives_the_serial_bits() {
        let lattice = Lattice::new([11, 9, 13], 1.0).unwrap();
        let mut source = vec![0.0; lattice.len()];
        source[4 + 11 * (3 + 9 * 5)] = 1.0;
        let cases = [
            (Layout::Staggered, 0.9, 1e-6, 4000),
            (Layout::Collocated, 0.9, 1e-6, 4000),
            (Layout::Staggered, 0.5, 0.0, 37),
            (Layout::Staggered, 1.3, 0.0, 400),
        ];
        for (layout, fraction, tolerance, steps) in cases {
            let settings = settings(
                layout,
                fraction,
                Stopping {
                    relative_tolerance: tolerance,
                    max_iterations: steps,
                    ..Stopping::default()
                },
            );
            let reference = march(&lattice, &source, &settings, None).unwrap();
            if fraction > 1.0 {
                assert!(
                    matches!(reference.stop_reason, StopReason::DivergedGrowth { .. }),
                    "{:?}",
                    reference.stop_reason
                );
            }
            for ranks in 1..=5 {
                let slabs = Decomposition::Slabs;
                for out in on_ranks(ranks, &lattice, &source, &slabs, &settings) {
                    let case = format!("{layout:?} at {fraction}, {ranks} ranks");
                    assert_serial_bits(&out.unwrap(), &reference, &case);
                }
            }
        }
    }

    #[test]
    fn every_grid_of_boxes_gives_the_serial_bits() {
        // 19 cells in x: three runs of 8 (the last short); sources off the centre and on
        // a box's face.
        let lattice = Lattice::new([19, 7, 9], 1.0).unwrap();
        let dims = lattice.dims;
        let mut source = vec![0.0; lattice.len()];
        source[5 + 19 * (2 + 7 * 4)] = 1.0;
        source[8 + 19 * (3 + 7 * 5)] = 0.5;
        let grids: Vec<Boxes> = [[2, 1, 1], [1, 2, 2], [3, 1, 2], [2, 3, 2], [1, 1, 4]]
            .into_iter()
            .map(|g| Boxes::new(dims, g).unwrap())
            .chain([
                Boxes::from_cuts(dims, [vec![0, 16, 19], vec![0, 1, 7], vec![0, 8, 9]]).unwrap(),
            ])
            .collect();
        let cases = [
            (Layout::Staggered, 0.9, 1e-6, 4000),
            (Layout::Collocated, 0.9, 1e-6, 4000),
            (Layout::Collocated, 0.5, 0.0, 23),
            (Layout::Staggered, 1.3, 0.0, 400),
        ];
        for (layout, fraction, tolerance, steps) in cases {
            let settings = settings(
                layout,
                fraction,
                Stopping {
                    relative_tolerance: tolerance,
                    max_iterations: steps,
                    ..Stopping::default()
                },
            );
            let reference = march(&lattice, &source, &settings, None).unwrap();
            let expected = match (fraction > 1.0, tolerance > 0.0) {
                (true, _) => matches!(reference.stop_reason, StopReason::DivergedGrowth { .. }),
                (false, true) => reference.stop_reason.is_converged(),
                (false, false) => reference.steps == steps,
            };
            assert!(
                expected,
                "{layout:?} at {fraction}: {:?}",
                reference.stop_reason
            );
            for boxes in &grids {
                let decomposition = Decomposition::Boxes(boxes.clone());
                let outs = on_ranks(boxes.ranks(), &lattice, &source, &decomposition, &settings);
                for (rank, out) in outs.into_iter().enumerate() {
                    let case = format!("{layout:?} at {fraction}, {:?} rank {rank}", boxes.grid());
                    assert_serial_bits(&out.unwrap(), &reference, &case);
                }
            }
        }
    }

    /// `march_p1_box`: each rank handed only its box of the source (as it reads it from a
    /// volume) returns its box of the serial φ and E, and the serial steps, changes and
    /// stop; a bad value in one rank's box stops every rank, the one holding it naming the
    /// cell and the others that rank.
    #[test]
    fn a_rank_holding_only_its_box_of_the_source_gets_its_box_of_the_serial_state() {
        use lucent_explicit::ranks::march_p1_box;
        let lattice = Lattice::new([19, 7, 9], 1.0).unwrap();
        let dims = lattice.dims;
        let [nx, ny, _] = dims;
        // A source over the whole grid, largest away from rank 0's box (the growth
        // monitor starts from the all-reduced largest magnitude).
        let source: Vec<f64> = (0..lattice.len())
            .map(|c| {
                ((c * 37) % 11) as f64 * 0.01 + if c == 5 + 19 * (5 + 7 * 7) { 2.0 } else { 0.0 }
            })
            .collect();
        let cut = |boxes: &Boxes, rank: usize, field: &[f64]| -> Vec<f64> {
            let own = boxes.bounds(rank);
            let mut out = Vec::new();
            for k in own[2].clone() {
                for j in own[1].clone() {
                    for i in own[0].clone() {
                        out.push(field[i + nx * (j + ny * k)]);
                    }
                }
            }
            out
        };
        for (layout, fraction, tolerance, steps) in [
            (Layout::Staggered, 0.9, 1e-6, 4000),
            (Layout::Collocated, 0.5, 0.0, 23),
            (Layout::Staggered, 1.3, 0.0, 400),
        ] {
            let settings = settings(
                layout,
                fraction,
                Stopping {
                    relative_tolerance: tolerance,
                    max_iterations: steps,
                    ..Stopping::default()
                },
            );
            let reference = march(&lattice, &source, &settings, None).unwrap();
            for grid in [[1, 1, 3], [2, 1, 1], [1, 2, 2], [2, 3, 2]] {
                let boxes = Boxes::new(dims, grid).unwrap();
                let outs = Threads::run(boxes.ranks(), |comm| {
                    use lucent_core::ranks::Communicator;
                    let mine = cut(&boxes, comm.rank(), &source);
                    march_p1_box(&lattice, &mine, &boxes, &settings, comm)
                });
                for (rank, out) in outs.into_iter().enumerate() {
                    let out = out.unwrap().unwrap();
                    let case = format!("{layout:?} at {fraction}, {grid:?} rank {rank}");
                    let expected = P1State {
                        fluence: cut(&boxes, rank, &reference.fluence),
                        flux: std::array::from_fn(|a| cut(&boxes, rank, &reference.flux[a])),
                        ..reference.clone()
                    };
                    assert_serial_bits(&out, &expected, &case);
                }
            }
        }
        // A non-finite value in rank 1's box.
        let boxes = Boxes::new(dims, [1, 1, 3]).unwrap();
        let settings = settings(Layout::Staggered, 0.9, Stopping::default());
        let outs = Threads::run(3, |comm| {
            use lucent_core::ranks::Communicator;
            let mut mine = cut(&boxes, comm.rank(), &source);
            if comm.rank() == 1 {
                mine[4] = f64::NAN;
            }
            march_p1_box(&lattice, &mine, &boxes, &settings, comm)
        });
        for (rank, out) in outs.into_iter().enumerate() {
            let why = out.unwrap().unwrap_err().to_string();
            let expected = if rank == 1 {
                "NaN in cell"
            } else {
                "rank 1 refused its part of the source"
            };
            assert!(why.contains(expected), "rank {rank}: {why}");
        }
    }

    #[test]
    fn periodic_edges_and_too_many_ranks_are_refused() {
        let lattice = Lattice::new([6, 6, 4], 1.0).unwrap();
        let source = vec![0.1; lattice.len()];
        let mut periodic = settings(Layout::Staggered, 0.9, Stopping::default());
        periodic.edges = P1Edges::Periodic;
        for out in on_ranks(2, &lattice, &source, &Decomposition::Slabs, &periodic) {
            assert!(matches!(out, Err(DecompositionError::Scheme(_))), "{out:?}");
        }
        let zero = settings(Layout::Staggered, 0.9, Stopping::default());
        for out in on_ranks(5, &lattice, &source, &Decomposition::Slabs, &zero) {
            assert!(matches!(
                out,
                Err(DecompositionError::TooManyRanks {
                    ranks: 5,
                    layers: 4
                })
            ));
        }
    }
}
