//! `SlabSystem::solve_multigrid_on_layout`, the multigrid on ranks that builds its hierarchy
//! from each rank's part of the medium (no rank assembles the problem or holds the whole
//! volume), against `Multigrid::solve` on the assembled problem: every rank's φ on its box,
//! the residual history and the stop reason are the serial solve's bits. Random media that
//! fill the box (D over two decades, σ_a over three, a volumetric source and point sources)
//! on grids whose sides are not multiples of 8 (odd ones among them), every face condition,
//! 1–6 ranks over slabs and grids of boxes, every level split or the coarse levels
//! agglomerated, every cycle, both smoothers, both prolongations, with and without full
//! multigrid; and a rank whose part of the medium is refused stops every rank with an
//! error instead of leaving them waiting.

use glam::DVec3;
use lucent_core::Stopping;
use lucent_core::ranks::{Communicator, Threads};
use lucent_diffusion::slab::{BlockFields, PointShares};
use lucent_diffusion::{
    Boundaries, BoxSolution, CellGeometry, Condition, Cycle, Decomposition, DiffusionError,
    DiffusionProblem, Multigrid, MultigridSettings, Prolongation, RankLayout, Region, SlabSystem,
    Smoother, Sources,
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

/// The fields of `region` of the whole grid's `d`, `sigma_a` and `q0`, as a rank reads them.
fn cut(region: &Region, dims: [usize; 3], f: &[f32]) -> Vec<f32> {
    let mut out = Vec::with_capacity(region.cells());
    for k in region.z() {
        for j in region.y() {
            let row = dims[0] * (j + dims[1] * k);
            out.extend_from_slice(&f[row + region.x().start..row + region.x().end]);
        }
    }
    out
}

struct Medium {
    geometry: GridGeometry,
    boundaries: Boundaries,
    d: Vec<f32>,
    sigma_a: Vec<f32>,
    q0: Vec<f32>,
    points: Vec<(DVec3, f64)>,
}

impl Medium {
    fn new(dims: [usize; 3], kinds: [u8; 6], seed: u64) -> Self {
        let geometry =
            GridGeometry::new(dims, DVec3::new(0.7, 0.5, 0.9), DVec3::new(-1.0, 0.2, 0.3)).unwrap();
        let n = geometry.voxel_count();
        let (lo, hi) = geometry.bounds();
        Self {
            geometry,
            boundaries: Boundaries {
                surface: Condition::Robin { a: 1.0 },
                faces: kinds.map(condition),
            },
            d: field(n, seed, 0.02, 2.0),
            sigma_a: field(n, seed ^ 1, 0.001, 3.0),
            q0: field(n, seed ^ 2, 0.1, 1.0),
            points: vec![
                (lo + (hi - lo) * DVec3::new(0.31, 0.62, 0.47), 2.5),
                (lo + (hi - lo) * DVec3::new(0.8, 0.1, 0.9), 0.5),
            ],
        }
    }

    /// The serial solve of the assembled problem: φ and the history.
    fn serial(
        &self,
        settings: MultigridSettings,
        stopping: &Stopping,
    ) -> (Multigrid, Vec<f64>, lucent_diffusion::Convergence) {
        let problem = DiffusionProblem::new(
            CellGeometry::full_box(self.geometry),
            self.d.clone(),
            self.sigma_a.clone(),
            self.boundaries,
        )
        .unwrap();
        let sources = Sources {
            volumetric: self.q0.clone(),
            points: self.points.clone(),
            ..Sources::default()
        };
        let rhs = problem.rhs(&sources).unwrap();
        let mg = Multigrid::build(&problem, settings).unwrap();
        let mut phi = vec![0.0; rhs.len()];
        let convergence = mg.solve(&rhs, &mut phi, stopping);
        (mg, phi, convergence)
    }

    /// The solve on `layout`'s ranks, each reading its box and the cell beyond its faces:
    /// every rank's result.
    fn on_ranks(
        &self,
        settings: MultigridSettings,
        stopping: &Stopping,
        layout: &RankLayout,
        ranks: usize,
    ) -> Vec<Result<BoxSolution, DiffusionError>> {
        let system = SlabSystem::new(self.geometry, self.boundaries).unwrap();
        let shares: Vec<PointShares> = self
            .points
            .iter()
            .map(|&(p, w)| system.point_weights(p, w).unwrap())
            .collect();
        let dims = self.geometry.dims();
        Threads::run(ranks, |comm| {
            let reads = layout.owned(comm.rank(), 0).grown(1, dims);
            let (d, s, q) = (
                cut(&reads, dims, &self.d),
                cut(&reads, dims, &self.sigma_a),
                cut(&reads, dims, &self.q0),
            );
            let fields = BlockFields {
                origin: [reads.x().start, reads.y().start, reads.z().start],
                dims: [reads.x().len(), reads.y().len(), reads.z().len()],
                diffusion: &d,
                absorption: &s,
                source: &q,
            };
            system.solve_multigrid_on_layout(
                fields,
                &shares,
                settings,
                stopping,
                comm,
                layout.clone(),
            )
        })
        .into_iter()
        .map(|r| r.expect("a rank panicked"))
        .collect()
    }
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn stopping() -> Stopping {
    Stopping {
        relative_tolerance: 1e-9,
        max_iterations: 60,
        ..Stopping::default()
    }
}

/// Every rank's box of φ and history against the serial solve's bits.
fn check(
    medium: &Medium,
    settings: MultigridSettings,
    ranks: usize,
    threshold: usize,
    decomposition: Decomposition,
) -> Result<(), TestCaseError> {
    let stopping = stopping();
    let (mg, serial, expected) = medium.serial(settings, &stopping);
    let system = SlabSystem::new(medium.geometry, medium.boundaries).unwrap();
    let layout = system
        .multigrid_layout(&settings, ranks, threshold, decomposition)
        .unwrap();
    // The layout is the one the whole hierarchy gets.
    prop_assert_eq!(
        &layout,
        &mg.layout(ranks, threshold, decomposition).unwrap()
    );
    let dims = medium.geometry.dims();
    let mut covered = 0;
    for (rank, result) in medium
        .on_ranks(settings, &stopping, &layout, ranks)
        .into_iter()
        .enumerate()
    {
        let solution = result.map_err(|e| TestCaseError::fail(format!("rank {rank}: {e}")))?;
        prop_assert_eq!(&solution.convergence, &expected, "rank {}'s history", rank);
        let region = Region::new(solution.cells.clone());
        prop_assert_eq!(&region, &layout.owned(rank, 0));
        let serial_box: Vec<f64> = {
            let mut out = Vec::new();
            for k in region.z() {
                for j in region.y() {
                    for i in region.x() {
                        out.push(serial[i + dims[0] * (j + dims[1] * k)]);
                    }
                }
            }
            out
        };
        prop_assert_eq!(
            bits(&solution.fluence),
            bits(&serial_box),
            "rank {}'s φ",
            rank
        );
        covered += region.cells();
    }
    prop_assert_eq!(covered, serial.len());
    Ok(())
}

fn settings(cycle: u8, jacobi: bool, trilinear: bool, full: bool) -> MultigridSettings {
    MultigridSettings {
        cycle: [Cycle::V, Cycle::W, Cycle::F, Cycle::K][usize::from(cycle % 4)],
        smoother: if jacobi {
            Smoother::Jacobi { omega: 0.8 }
        } else {
            Smoother::RedBlackGaussSeidel
        },
        prolongation: if trilinear {
            Prolongation::Trilinear
        } else {
            Prolongation::Constant
        },
        full_multigrid: full,
        ..MultigridSettings::default()
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn each_rank_building_from_its_own_box_gives_the_serial_bits(
        dims in (5usize..26, 5usize..22, 5usize..26),
        kinds in proptest::array::uniform6(0u8..3),
        seed in any::<u64>(),
        ranks in 1usize..7,
        boxes in any::<bool>(),
        threshold in prop::sample::select(vec![0usize, 64, RankLayout::COARSE_CELLS_PER_RANK]),
        cycle in 0u8..4,
        jacobi in any::<bool>(),
        trilinear in any::<bool>(),
        full in any::<bool>(),
    ) {
        let dims = [dims.0, dims.1, dims.2];
        let medium = Medium::new(dims, kinds, seed);
        let decomposition = if boxes { Decomposition::Boxes } else { Decomposition::Slabs };
        let system = SlabSystem::new(medium.geometry, medium.boundaries).unwrap();
        let s = settings(cycle, jacobi, trilinear, full);
        // A grid too thin for the ranks is the layout's typed error, as for the whole
        // hierarchy; the rest must give the bits.
        if system.multigrid_layout(&s, ranks, threshold, decomposition).is_ok() {
            check(&medium, s, ranks, threshold, decomposition)?;
        }
    }
}

/// Grids of boxes cut along each axis, two axes and all three, with every level split.
#[test]
fn grids_cut_along_every_axis_give_the_serial_bits() {
    let medium = Medium::new([24, 18, 20], [0, 1, 2, 0, 1, 0], 7);
    for grid in [
        [2, 1, 1],
        [1, 3, 1],
        [1, 1, 4],
        [2, 2, 1],
        [1, 2, 2],
        [2, 2, 2],
    ] {
        for s in [
            settings(0, false, true, false),
            settings(1, true, false, true),
        ] {
            check(
                &medium,
                s,
                grid.iter().product(),
                0,
                Decomposition::Grid(grid),
            )
            .unwrap_or_else(|e| panic!("{grid:?} {s:?}: {e}"));
        }
    }
}

/// Ranks the fine level leaves out (5 layers on 5 ranks: the fine level on 2) read
/// nothing, take part in the norms and the hand-overs, and get an empty box back; the
/// others their boxes of the serial φ.
#[test]
fn ranks_beyond_half_the_layers_read_nothing() {
    let medium = Medium::new([12, 10, 5], [0, 0, 1, 0, 2, 0], 5);
    let system = SlabSystem::new(medium.geometry, medium.boundaries).unwrap();
    let s = settings(0, false, true, false);
    let layout = system
        .multigrid_layout(&s, 5, 0, Decomposition::Slabs)
        .unwrap();
    assert_eq!(layout.stages[0].ranks(), 2);
    check(&medium, s, 5, 0, Decomposition::Slabs).unwrap();
    let solutions = medium.on_ranks(s, &stopping(), &layout, 5);
    for (rank, solution) in solutions.into_iter().enumerate().skip(2) {
        let solution = solution.unwrap();
        assert!(solution.fluence.is_empty(), "rank {rank}");
        assert!(solution.cells.iter().all(|r| r.is_empty()), "rank {rank}");
    }
}

/// A rank whose part of the medium holds a negative D, or fields that miss the cells its
/// rows read, returns the typed error naming the cell; the other ranks return an error
/// too (none waits for it).
#[test]
fn a_refused_part_of_the_medium_stops_every_rank() {
    let medium = Medium::new([16, 12, 20], [0; 6], 3);
    let system = SlabSystem::new(medium.geometry, medium.boundaries).unwrap();
    let s = MultigridSettings::default();
    let layout = system
        .multigrid_layout(&s, 3, 0, Decomposition::Slabs)
        .unwrap();
    let dims = medium.geometry.dims();
    for short in [false, true] {
        let results = Threads::run(3, |comm| {
            let rank = comm.rank();
            let reads = layout.owned(rank, 0).grown(1, dims);
            let mut d = cut(&reads, dims, &medium.d);
            let (mut sa, q) = (
                cut(&reads, dims, &medium.sigma_a),
                cut(&reads, dims, &medium.q0),
            );
            let mut fields_dims = [reads.x().len(), reads.y().len(), reads.z().len()];
            if rank == 1 {
                if short {
                    // One layer short: the layer beyond the box is missing.
                    fields_dims[2] -= 1;
                    let keep = fields_dims.iter().product();
                    d.truncate(keep);
                    sa.truncate(keep);
                } else {
                    d[5] = -1.0;
                }
            }
            let q = &q[..d.len()];
            let fields = BlockFields {
                origin: [reads.x().start, reads.y().start, reads.z().start],
                dims: fields_dims,
                diffusion: &d,
                absorption: &sa,
                source: q,
            };
            system.solve_multigrid_on_layout(fields, &[], s, &stopping(), comm, layout.clone())
        });
        for (rank, r) in results.into_iter().enumerate() {
            let e = r.expect("a rank panicked").unwrap_err();
            match (rank, &e) {
                (1, DiffusionError::Invalid(why)) if !short => {
                    assert!(why.contains("diffusion coefficient -1"), "{why}");
                }
                (1, DiffusionError::Invalid(_)) => {}
                (_, DiffusionError::Ranks(why)) => {
                    assert!(
                        why.contains("rank 1 refused its part of the medium"),
                        "{why}"
                    );
                }
                _ => panic!("rank {rank}: {e}"),
            }
        }
    }
}
