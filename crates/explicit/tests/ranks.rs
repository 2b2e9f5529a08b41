//! The decomposed explicit schemes give the serial bits on 1 to 5 in-process ranks. The
//! steady iterations: fluence, residual history and stop reason, for FTCS and Jacobi, on a
//! heterogeneous problem with an embedded sphere on a grid whose sides are not multiples
//! of 8; P1 below.

use glam::DVec3;
use lucent_core::ranks::Threads;
use lucent_core::{StopReason, Stopping};
use lucent_diffusion::{
    AssembledSystem, Boundaries, CellGeometry, Condition, DiffusionProblem, Discretisation, Sources,
};
use lucent_explicit::ranks::{DecompositionError, iterate as decomposed};
use lucent_explicit::steady::{Iteration, Steady, SteadySettings, ftcs_limit, iterate as serial};
use lucent_grid::GridGeometry;

fn system(dims: [usize; 3]) -> (AssembledSystem, usize, f64) {
    let grid = GridGeometry::from_bounds(
        dims,
        DVec3::new(-3.0, -2.5, -3.5),
        DVec3::new(3.0, 2.5, 3.5),
    )
    .unwrap();
    let cells =
        CellGeometry::from_sdf(grid, |p| p.length() - 2.4, Discretisation::EmbeddedBoundary)
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
    (
        problem.assemble(&sources).unwrap(),
        dims[0] * dims[1],
        grid.cell_volume(),
    )
}

fn on_ranks(
    ranks: usize,
    system: &AssembledSystem,
    slab: usize,
    iteration: Iteration,
    settings: &SteadySettings,
) -> Vec<Result<Steady, DecompositionError>> {
    std::thread::scope(|scope| {
        let handles: Vec<_> = Threads::world(ranks)
            .into_iter()
            .map(|comm| scope.spawn(move || decomposed(system, slab, iteration, settings, &comm)))
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    })
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn every_rank_count_gives_the_serial_bits() {
    let (system, slab, volume) = system([13, 11, 19]);
    let settings = SteadySettings {
        stopping: Stopping {
            relative_tolerance: 1e-7,
            max_iterations: 50_000,
            ..Stopping::default()
        },
        allow_unstable: false,
    };
    for iteration in [
        Iteration::Ftcs {
            time_step: 0.9 * ftcs_limit(&system, volume),
            cell_volume: volume,
        },
        Iteration::Jacobi { omega: 0.8 },
    ] {
        let reference = serial(&system, slab, iteration, &settings).unwrap();
        assert!(reference.stop_reason.is_converged(), "{iteration:?}");
        for ranks in 1..=5 {
            for (rank, out) in on_ranks(ranks, &system, slab, iteration, &settings)
                .into_iter()
                .enumerate()
            {
                let out = out.unwrap();
                assert_eq!(
                    out.stop_reason, reference.stop_reason,
                    "{iteration:?}, {ranks} ranks, rank {rank}"
                );
                assert_eq!(
                    bits(&out.residuals),
                    bits(&reference.residuals),
                    "{iteration:?}, {ranks} ranks"
                );
                assert_eq!(
                    bits(&out.fluence),
                    bits(&reference.fluence),
                    "{iteration:?}, {ranks} ranks"
                );
            }
        }
    }
}

#[test]
fn a_time_limit_stops_every_rank_on_the_same_sweep() {
    let (system, slab, _) = system([12, 12, 16]);
    let settings = SteadySettings {
        stopping: Stopping {
            relative_tolerance: 0.0,
            max_iterations: usize::MAX,
            time_budget: Some(std::time::Duration::from_millis(50)),
            ..Stopping::default()
        },
        allow_unstable: false,
    };
    let outs: Vec<Steady> = on_ranks(
        3,
        &system,
        slab,
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

#[test]
fn more_ranks_than_layers_is_an_error() {
    let (system, slab, _) = system([6, 6, 4]);
    let settings = SteadySettings {
        stopping: Stopping::default(),
        allow_unstable: false,
    };
    for out in on_ranks(
        7,
        &system,
        slab,
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
    let (system, slab, volume) = system([9, 10, 11]);
    let settings = SteadySettings {
        stopping: Stopping::default(),
        allow_unstable: false,
    };
    for iteration in [
        Iteration::Jacobi { omega: 1.5 },
        Iteration::Ftcs {
            time_step: 1.1 * ftcs_limit(&system, volume),
            cell_volume: volume,
        },
    ] {
        let serial_error = serial(&system, slab, iteration, &settings).unwrap_err();
        for out in on_ranks(2, &system, slab, iteration, &settings) {
            assert_eq!(
                out.unwrap_err(),
                DecompositionError::Scheme(serial_error.clone())
            );
        }
    }
}

mod p1 {
    //! P1 by FTCS on ranks (`ranks::march_p1`): the serial march's bits on 1 to 5 ranks,
    //! both layouts, from a point source off the grid's centre on grids whose sides are
    //! not multiples of 8, to convergence, to the step limit, and past the stability bound
    //! (the growth monitor must stop every rank on the serial step).

    use lucent_core::ranks::Threads;
    use lucent_core::{StopReason, Stopping};
    use lucent_explicit::Lattice;
    use lucent_explicit::p1::{Damping, Layout, P1Edges, P1Settings, P1State, march};
    use lucent_explicit::ranks::{DecompositionError, march_p1};

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
        settings: &P1Settings,
    ) -> Vec<Result<P1State, DecompositionError>> {
        std::thread::scope(|scope| {
            let handles: Vec<_> = Threads::world(ranks)
                .into_iter()
                .map(|comm| scope.spawn(move || march_p1(lattice, source, settings, &comm)))
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        })
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
                for out in on_ranks(ranks, &lattice, &source, &settings) {
                    let out = out.unwrap();
                    let case = format!("{layout:?} at {fraction}, {ranks} ranks");
                    assert_eq!(out.stop_reason, reference.stop_reason, "{case}");
                    assert_eq!(out.steps, reference.steps, "{case}");
                    assert_eq!(bits(&out.fluence), bits(&reference.fluence), "{case}");
                    for a in 0..3 {
                        assert_eq!(bits(&out.flux[a]), bits(&reference.flux[a]), "{case}");
                    }
                }
            }
        }
    }

    #[test]
    fn periodic_edges_and_too_many_ranks_are_refused() {
        let lattice = Lattice::new([6, 6, 4], 1.0).unwrap();
        let source = vec![0.1; lattice.len()];
        let mut periodic = settings(Layout::Staggered, 0.9, Stopping::default());
        periodic.edges = P1Edges::Periodic;
        for out in on_ranks(2, &lattice, &source, &periodic) {
            assert!(matches!(out, Err(DecompositionError::Scheme(_))), "{out:?}");
        }
        let zero = settings(Layout::Staggered, 0.9, Stopping::default());
        for out in on_ranks(5, &lattice, &source, &zero) {
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
