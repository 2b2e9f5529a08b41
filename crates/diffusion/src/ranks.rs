//! Multigrid on ranks: the hierarchy split into z-slabs or a Cartesian grid of boxes, the
//! finer levels over every rank and the coarser ones agglomerated onto fewer ranks, down
//! to one for the coarsest.
//!
//! **Layout** ([`RankLayout`]): the levels fall into *stages*, runs of levels split over
//! the same ranks 0..p. A stage of m levels cuts each axis of its first level into runs of
//! whole units of 2^m cells, balanced by units, so the box bounds stay whole cells on each
//! of its levels (level L + i owns cells [c₀/2^i, ⌈c₁/2^i⌉) per axis) and on the next
//! stage's first level: a coarse cell's eight children are on one rank, and restriction
//! and constant prolongation need no halo. On the fine level x is cut in runs of
//! `NORM_RUN` too, so each rank's norm sums whole runs ([`Decomposition`]: slabs cut z
//! only; boxes take the grid of least cut area, so the fine level of n³ splits over more
//! ranks than n/2 and the halo per rank shrinks as P^(-2/3)). m is the largest with every
//! box keeping a unit on every cut axis that leaves the coarsest level out and keeps every
//! level of the stage but the fine one at `coarse_cells_per_rank` cells per rank or more.
//! The next stage takes up to min(p, cells'/`coarse_cells_per_rank`) ranks, the most a
//! grid of two-cell units allows, as HPGMG and AMReX agglomerate coarse levels; the stage
//! on one rank (always the coarsest level's) is rank 0's, which cycles it serially. The
//! K-cycle splits its fine level only (its coarse Krylov steps run on rank 0).
//!
//! **A cycle on a split level** (as [`Multigrid`]'s, the same arithmetic per cell):
//! - red–black Gauss–Seidel: each colour starts by sending the layers of the box next to
//!   each face neighbour and sweeping the cells one in from those faces while they travel,
//!   then sweeps the box's outer shell with the received halo; weighted Jacobi likewise;
//! - the residual's restriction after one face exchange; trilinear prolongation after one
//!   on the coarse level that crosses edges and corners too (up to 26 neighbours;
//!   constant prolongation needs none);
//! - where the next level starts a stage, the restricted right-hand side moves from the
//!   boxes each rank computed to the next stage's owners (point to point, each owner
//!   receiving from the ranks whose boxes overlap its own), the ranks outside the next
//!   stage wait, and the coarse correction comes back with the one-cell halo trilinear
//!   prolongation reads. Ranks that own nothing on a level exchange nothing on it.
//!
//! **Norms** are the serial solve's (`Level::norm`): every x-line of the fine level cut
//! into runs of eight cells, each run summed left to right, the run sums added exactly
//! (`lucent_core::exact::ExactSum`). Each rank sums the runs of its box and the ranks
//! all-reduce the accumulators with their time-budget and cancel flags
//! (`lucent_core::ranks::all_reduce_sums`: log₂P messages of 71 words per norm). An exact
//! sum does not depend on the order of its terms, so the residual history, the stopping
//! decisions and φ are [`Multigrid::solve`]'s bits on every rank count and grid of boxes
//! (tested on 1–12 ranks, every cycle and smoother, both prolongations, grids cut along
//! each axis and all three, with and without agglomeration). The time budget and
//! cancellation are each rank's own and travel with the reduction, so all ranks stop on
//! the same cycle.
//!
//! **Storage.** On a split level a rank works on its box and the cells around it held as a
//! level of their own (`Level::extract`: the operator copied, the work vectors that size),
//! so its sweeps stream its own x-lines: a box cut along x inside full-length vectors swept
//! 3.5× slower per cell (BENCHMARKS.md). The transfers map indices through the two grids'
//! origins (`level::Origins`) and a box's colours through its origin's parity; the
//! hand-overs go through a second frame per stage boundary (the cells a rank restricts to
//! and one around them). Rank 0 keeps its serial stage's levels whole.
//!
//! **Two ways in.** [`Multigrid::solve_on_layout`] splits a hierarchy every rank built
//! whole (`Multigrid::build`: any medium, embedded boundaries included): each rank takes
//! the whole right-hand side and gets the whole φ back, so memory does not shrink with
//! ranks. For a medium that fills the grid's box,
//! [`SlabSystem::solve_multigrid_on_layout`](crate::SlabSystem::solve_multigrid_on_layout)
//! builds each rank's frames from its own box of the medium (the `local` module: positioned
//! reads of the box and the cell beyond its faces, coarsening of its own cells, the
//! operator's halo and hand-overs exchanged like the vectors'), and each rank gets back φ
//! on its box: no rank holds the whole volume, hierarchy or solution. Both give
//! [`Multigrid::solve`]'s bits.

use lucent_core::exact::{ExactSum, NORM_RUN};
use lucent_core::ranks::{Communicator, all_reduce_sums};
use lucent_core::{StopReason, Stopping};

use crate::error::DiffusionError;
use std::borrow::Cow;

use crate::level::{Level, Origins};
use crate::multigrid::{
    Convergence, Cycle, Multigrid, MultigridSettings, Prolongation, Smoother, Work,
};
use crate::region::Region;

mod local;
pub use local::BoxSolution;

/// How a stage cuts its levels over its ranks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Decomposition {
    /// Runs of whole z-layers: two neighbours per rank, each message a whole layer.
    #[default]
    Slabs,
    /// A Cartesian grid of boxes, the one with the least cut area: up to six face
    /// neighbours (26 for trilinear prolongation's halo), and on P ranks a halo that
    /// shrinks as P^(-2/3) of the level instead of staying a whole layer; the fine level
    /// splits over more ranks than it has layer pairs.
    Boxes,
    /// The fine level over this grid of boxes [p_x, p_y, p_z] (one rank per box), the
    /// coarse levels as [`Decomposition::Boxes`].
    Grid([usize; 3]),
}

/// A run of levels split over the same ranks.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stage {
    /// Its first level.
    pub first_level: usize,
    /// How many levels it spans: `first_level..first_level + levels`.
    pub levels: usize,
    /// Per axis (x, y, z), the cut positions on the first level, from 0 to its cells on
    /// that axis: p_a + 1 values for p_a boxes along it. Those inside are multiples of
    /// 2^`levels` (on the fine level x's also of `NORM_RUN`, so each rank's norm sums
    /// whole runs), so a coarse cell's children stay on one rank down to the next stage's
    /// first level. Rank r sits at (r mod p_x, ⌊r / p_x⌋ mod p_y, ⌊r / (p_x p_y)⌋); z-slabs
    /// are the grid 1 × 1 × p.
    pub cuts: [Vec<usize>; 3],
}

impl Stage {
    /// Boxes per axis.
    pub fn grid(&self) -> [usize; 3] {
        std::array::from_fn(|a| self.cuts[a].len().saturating_sub(1))
    }

    /// How many ranks work on it.
    pub fn ranks(&self) -> usize {
        self.grid().iter().product()
    }

    /// Rank `rank`'s place in the grid (none outside the stage).
    pub fn coords(&self, rank: usize) -> Option<[usize; 3]> {
        let [px, py, _] = self.grid();
        (rank < self.ranks()).then(|| [rank % px, (rank / px) % py, rank / (px * py)])
    }

    /// The rank at `coords` of the grid.
    pub fn rank_at(&self, [i, j, k]: [usize; 3]) -> usize {
        let [px, py, _] = self.grid();
        i + px * (j + py * k)
    }

    /// Rank `rank`'s box of level `level`, which may be the next stage's first level (the
    /// cells its box restricts to); empty for a rank outside the stage or a level above
    /// it.
    pub fn owned(&self, rank: usize, level: usize) -> Region {
        let (Some(c), Some(shift)) = (self.coords(rank), level.checked_sub(self.first_level))
        else {
            return Region::default();
        };
        let shift = shift.min(usize::BITS as usize - 1);
        Region::new(std::array::from_fn(|a| {
            let (c0, c1) = (self.cuts[a][c[a]], self.cuts[a][c[a] + 1]);
            (c0 >> shift)..c1.div_ceil(1 << shift)
        }))
    }
}

/// How a hierarchy is split over ranks: its stages, finest first, covering every level;
/// the last is on one rank and holds the coarsest level.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RankLayout {
    /// The stages, finest first.
    pub stages: Vec<Stage>,
}

/// The grid of `p` boxes over `dims` with the least cut area (Σ over cut planes of their
/// cells) among those that keep a whole `unit[a]` of cells per box on every cut axis
/// (p_a · unit_a ≤ n_a); ties go to grids cut along z, then y (whole x-lines in the
/// messages). Slabs take 1 × 1 × p only. None if no grid of `p` boxes fits.
fn box_grid(
    dims: [usize; 3],
    p: usize,
    unit: [usize; 3],
    decomposition: Decomposition,
) -> Option<[usize; 3]> {
    let fits = |g: [usize; 3]| fits(dims, g, unit);
    if decomposition != Decomposition::Boxes {
        return Some([1, 1, p]).filter(|&g| fits(g));
    }
    let area = |g: [usize; 3]| -> usize {
        (0..3)
            .map(|a| (g[a] - 1) * dims[(a + 1) % 3] * dims[(a + 2) % 3])
            .sum()
    };
    let mut best: Option<([usize; 3], (usize, usize, usize))> = None;
    for px in (1..=p).filter(|d| p.is_multiple_of(*d)) {
        for py in (1..=p / px).filter(|d| (p / px).is_multiple_of(*d)) {
            let g = [px, py, p / px / py];
            if !fits(g) {
                continue;
            }
            let key = (area(g), px, py);
            if best.as_ref().is_none_or(|(_, k)| key < *k) {
                best = Some((g, key));
            }
        }
    }
    best.map(|(g, _)| g)
}

/// Whether a grid `g` of boxes over `dims` keeps a whole `unit[a]` of cells per box on
/// every cut axis.
fn fits(dims: [usize; 3], g: [usize; 3], unit: [usize; 3]) -> bool {
    (0..3).all(|a| g[a] == 1 || g[a] * unit[a] <= dims[a])
}

impl RankLayout {
    /// Below this many cells per rank a level goes to fewer ranks: 16³, where a sweep's
    /// work per rank (tens of microseconds) is no longer large against a message's
    /// latency.
    pub const COARSE_CELLS_PER_RANK: usize = 4096;

    /// The layout of a hierarchy whose levels have `dims` (finest first) on `ranks` ranks,
    /// over z-slabs: the fine level over every rank while each keeps two layers, then a
    /// stage keeps at least `coarse_cells_per_rank` cells per rank on each of its coarse
    /// levels (0 or 1: split as far as the layers allow).
    ///
    /// # Errors
    /// [`DiffusionError::Ranks`] for no ranks or more ranks than fine layers;
    /// [`DiffusionError::Invalid`] for no levels.
    pub fn new(
        dims: &[[usize; 3]],
        ranks: usize,
        cycle: Cycle,
        coarse_cells_per_rank: usize,
    ) -> Result<Self, DiffusionError> {
        Self::with(
            dims,
            ranks,
            cycle,
            coarse_cells_per_rank,
            Decomposition::Slabs,
        )
    }

    /// [`RankLayout::new`] over `decomposition`: for boxes, each stage takes the most of
    /// its ranks that a grid of boxes keeping two cells per axis (eight along x on the
    /// fine level) allows, cut with the least area.
    ///
    /// # Errors
    /// [`DiffusionError::Ranks`] for no ranks, or more ranks than fine layers (slabs) or
    /// fine cells (boxes); [`DiffusionError::Invalid`] for no levels.
    pub fn with(
        dims: &[[usize; 3]],
        ranks: usize,
        cycle: Cycle,
        coarse_cells_per_rank: usize,
        decomposition: Decomposition,
    ) -> Result<Self, DiffusionError> {
        let Some(fine) = dims.first() else {
            return Err(DiffusionError::Invalid("a hierarchy of no levels".into()));
        };
        let (room, what) = match decomposition {
            Decomposition::Slabs => (fine[2], "z-layers: every rank needs at least one layer"),
            _ => (
                fine.iter().product(),
                "cells: every rank needs at least one cell",
            ),
        };
        if ranks == 0 || ranks > room {
            return Err(DiffusionError::Ranks(format!(
                "{ranks} ranks for {room} {what}"
            )));
        }
        let depth = dims.len();
        let per_rank = coarse_cells_per_rank.max(1);
        // The cells per box and axis that m levels of a stage starting at `level` need: a
        // coarse cell's 2^m children on one rank (and whole norm runs along x on the fine
        // level).
        let unit = |level: usize, m: usize| -> [usize; 3] {
            let u = 1usize << m.min(usize::BITS as usize - 2);
            [if level == 0 { u.max(NORM_RUN) } else { u }, u, u]
        };
        if let Decomposition::Grid(g) = decomposition
            && (g.iter().product::<usize>() != ranks || !fits(*fine, g, unit(0, 1)))
        {
            return Err(DiffusionError::Ranks(format!(
                "a grid of {g:?} boxes for {ranks} ranks on {fine:?} cells: the boxes must be \
                 one per rank and keep two cells per axis (eight along x)"
            )));
        }
        let cells = |l: usize| dims[l].iter().product::<usize>();
        let mut stages = Vec::new();
        let (mut level, mut p) = (0, ranks);
        loop {
            let n = dims[level];
            // The fine level is split over every rank it can be (the caller chose the
            // ranks, and its data lives split); coarser ones keep the threshold.
            if level > 0 {
                p = p.min(cells(level) / per_rank).max(1);
            }
            if level + 1 == depth || (cycle == Cycle::K && level > 0) {
                p = 1;
            }
            // The most ranks (up to p) whose grid keeps a unit of two levels per box, or
            // on the fine level the grid asked for.
            let (q, grid) = match decomposition {
                Decomposition::Grid(g) if level == 0 && p > 1 => (ranks, g),
                _ => {
                    let cut = match decomposition {
                        Decomposition::Slabs => Decomposition::Slabs,
                        _ => Decomposition::Boxes,
                    };
                    (1..=p)
                        .rev()
                        .find_map(|q| box_grid(n, q, unit(level, 1), cut).map(|g| (q, g)))
                        .unwrap_or((1, [1, 1, 1]))
                }
            };
            p = q;
            if p == 1 {
                stages.push(Stage {
                    first_level: level,
                    levels: depth - level,
                    cuts: n.map(|n| vec![0, n]),
                });
                return Ok(Self { stages });
            }
            let mut m = 1;
            while level + m + 1 < depth
                && cycle != Cycle::K
                && cells(level + m) >= p * per_rank
                && fits(n, grid, unit(level, m + 1))
            {
                m += 1;
            }
            let u = unit(level, m);
            let cuts = std::array::from_fn(|a| {
                let units = n[a].div_ceil(u[a]);
                (0..=grid[a])
                    .map(|r| (r * units / grid[a] * u[a]).min(n[a]))
                    .collect()
            });
            stages.push(Stage {
                first_level: level,
                levels: m,
                cuts,
            });
            level += m;
        }
    }

    /// The stage that holds level `level`.
    pub fn stage_of(&self, level: usize) -> &Stage {
        self.stages
            .iter()
            .rev()
            .find(|s| s.first_level <= level)
            .unwrap_or(&self.stages[0])
    }

    /// Rank `rank`'s box of level `level` (empty where it does not work on it).
    pub fn owned(&self, rank: usize, level: usize) -> Region {
        self.stage_of(level).owned(rank, level)
    }
}

/// A rank's storage of one level: a box of the level's cells (a rank's box and the cells
/// around it, or the whole level) held as a grid of its own, so that a box cut along x
/// streams its own x-lines instead of parts of the level's (a sweep of the same cells ran
/// 3.5× faster so stored, BENCHMARKS.md).
#[derive(Debug, Clone, PartialEq, Eq)]
struct Frame {
    /// Its first cell in the level.
    origin: [usize; 3],
    /// Its cells per axis.
    dims: [usize; 3],
}

impl Frame {
    /// The whole level.
    fn whole(dims: [usize; 3]) -> Self {
        Self {
            origin: [0; 3],
            dims,
        }
    }

    /// `region` and one cell around it, within a level of `dims`.
    fn around(region: &Region, dims: [usize; 3]) -> Self {
        let grown = region.grown(1, dims);
        Self {
            origin: std::array::from_fn(|a| grown.axes[a].start),
            dims: std::array::from_fn(|a| grown.axes[a].len()),
        }
    }

    fn len(&self) -> usize {
        self.dims.iter().product()
    }

    /// `region` (cells of the level) in this frame's indices; it must lie inside.
    fn local(&self, region: &Region) -> Region {
        if region.is_empty() {
            return Region::default();
        }
        Region::new(std::array::from_fn(|a| {
            region.axes[a].start - self.origin[a]..region.axes[a].end - self.origin[a]
        }))
    }
}

/// A frame and the operator on it.
struct Held<'a> {
    frame: Frame,
    level: Cow<'a, Level>,
}

impl<'a> Held<'a> {
    /// Level `level` of `mg` on `frame` (borrowed when the frame is the whole level).
    fn new(mg: &'a Multigrid, level: usize, frame: Frame) -> Self {
        let whole = &mg.levels[level];
        let level = if frame == Frame::whole(whole.dims) {
            Cow::Borrowed(whole)
        } else {
            Cow::Owned(whole.extract(frame.origin, frame.dims))
        };
        Self { frame, level }
    }
}

/// The levels rank 0 cycles alone (the last stage's), as a hierarchy of their own whose
/// level 0 is level `first` of the whole one.
struct Serial<'a> {
    first: usize,
    mg: Cow<'a, Multigrid>,
}

/// The frames rank `rank` holds of each level of a hierarchy of `dims` split as `layout`:
/// per level its box and the cells around it on a split level, the whole level on the
/// stage of one rank (rank 0's), none elsewhere; and per level that starts a stage, for a
/// rank of the stage before, the cells its box restricts to and one around them (the
/// hand-over's).
#[allow(clippy::type_complexity)]
fn frames(
    layout: &RankLayout,
    dims: &[[usize; 3]],
    rank: usize,
) -> (Vec<Option<Frame>>, Vec<Option<Frame>>) {
    let held = (0..dims.len())
        .map(|l| {
            let stage = layout.stage_of(l);
            let own = stage.owned(rank, l);
            if own.is_empty() {
                None
            } else if stage.ranks() == 1 {
                Some(Frame::whole(dims[l]))
            } else {
                Some(Frame::around(&own, dims[l]))
            }
        })
        .collect();
    let handover = (0..dims.len())
        .map(|l| {
            let starts = l > 0 && layout.stage_of(l).first_level == l;
            let restricted = if starts {
                layout.stage_of(l - 1).owned(rank, l)
            } else {
                Region::default()
            };
            (!restricted.is_empty()).then(|| Frame::around(&restricted, dims[l]))
        })
        .collect();
    (held, handover)
}

/// One rank's view of the distributed solve: the communicator, the layout, the settings,
/// each level's dimensions and the part of the hierarchy this rank holds.
struct OnRanks<'a, C: ?Sized> {
    settings: MultigridSettings,
    /// Every level's cells per axis.
    dims: Vec<[usize; 3]>,
    /// Rank 0's serial levels (`None` on the other ranks).
    serial: Option<Serial<'a>>,
    comm: &'a C,
    layout: RankLayout,
    rank: usize,
    /// Per level, what this rank holds of it: its box and the cells around it on a split
    /// level, the whole level on a stage of one rank (rank 0's), nothing elsewhere.
    held: Vec<Option<Held<'a>>>,
    /// Per level that starts a stage, for a rank of the stage before: the cells its box
    /// restricts to and one around them, where the right-hand side goes down from and the
    /// correction comes back to.
    handover: Vec<Option<Held<'a>>>,
}

/// A message that did not fit the plan.
fn protocol(rank: usize, what: &str) -> DiffusionError {
    DiffusionError::Ranks(format!(
        "rank {rank}: {what} did not match the decomposition (a rank stopped or diverged from the protocol)"
    ))
}

/// A halo message: the neighbour, the cells sent to it, the cells it sends (level cells).
struct Neighbour {
    rank: usize,
    send: Region,
    receive: Region,
}

/// Where a hand-over's values are: a frame and its vector (none on a rank that holds none).
type Side<'s, V> = Option<(&'s Frame, V)>;

impl<'a, C: Communicator + ?Sized> OnRanks<'a, C> {
    fn new(mg: &'a Multigrid, comm: &'a C, layout: RankLayout) -> Self {
        let rank = comm.rank();
        let dims: Vec<[usize; 3]> = mg.levels.iter().map(|l| l.dims).collect();
        let (held, handover) = frames(&layout, &dims, rank);
        let take = |frames: Vec<Option<Frame>>| -> Vec<Option<Held<'a>>> {
            frames
                .into_iter()
                .enumerate()
                .map(|(l, f)| f.map(|f| Held::new(mg, l, f)))
                .collect()
        };
        let (held, handover) = (take(held), take(handover));
        let serial = (rank == 0).then_some(Serial {
            first: 0,
            mg: Cow::Borrowed(mg),
        });
        Self {
            settings: *mg.settings(),
            dims,
            serial,
            comm,
            layout,
            rank,
            held,
            handover,
        }
    }

    /// The work vectors (b, x and the smoothers' scratch) this rank needs: per level its
    /// frame's length; and the hand-overs' (b and x).
    fn work(&self) -> (Work, Work, Work, Work, Work) {
        let sized = |held: &[Option<Held<'_>>]| -> Work {
            held.iter()
                .map(|h| vec![0.0f32; h.as_ref().map_or(0, |h| h.frame.len())])
                .collect()
        };
        (
            sized(&self.held),
            sized(&self.held),
            sized(&self.held),
            sized(&self.handover),
            sized(&self.handover),
        )
    }

    fn held(&self, l: usize) -> Result<&Held<'a>, DiffusionError> {
        self.held[l]
            .as_ref()
            .ok_or_else(|| protocol(self.rank, "a level this rank does not hold"))
    }

    fn dims(&self, l: usize) -> [usize; 3] {
        self.dims[l]
    }

    /// Rank 0's serial levels.
    fn serial_levels(&self) -> Result<&Serial<'a>, DiffusionError> {
        self.serial
            .as_ref()
            .ok_or_else(|| protocol(self.rank, "a serial level on a rank other than 0"))
    }

    fn stage(&self, l: usize) -> &Stage {
        self.layout.stage_of(l)
    }

    /// Whether level `l` is on rank 0 alone (cycled serially there).
    fn serial(&self, l: usize) -> bool {
        self.stage(l).ranks() == 1
    }

    /// Whether level `l + 1` starts a new stage.
    fn hands_over(&self, l: usize) -> bool {
        self.stage(l + 1).first_level == l + 1
    }

    /// The box of level `l` this rank computes, in the level's cells (empty where it has
    /// no part in it).
    fn owned(&self, l: usize) -> Region {
        self.layout.owned(self.rank, l)
    }

    /// The coarse cells (level `l + 1`) this rank's box of level `l` restricts to.
    fn restricts_to(&self, l: usize) -> Region {
        self.stage(l).owned(self.rank, l + 1)
    }

    /// This rank's neighbours in its stage's grid on level `l`: across its faces, and with
    /// `corners` across its edges and corners too (what trilinear prolongation reads).
    /// Each sends the layer of its box next to this one.
    fn neighbours(&self, l: usize, corners: bool) -> Vec<Neighbour> {
        let stage = self.stage(l);
        let (Some(at), o) = (stage.coords(self.rank), self.owned(l)) else {
            return Vec::new();
        };
        let grid = stage.grid();
        let mut out = Vec::new();
        for dz in -1isize..=1 {
            for dy in -1isize..=1 {
                for dx in -1isize..=1 {
                    let d = [dx, dy, dz];
                    let off = d.iter().filter(|&&v| v != 0).count();
                    if off == 0 || (off > 1 && !corners) {
                        continue;
                    }
                    let mut there = [0usize; 3];
                    if (0..3).any(|a| {
                        let c = at[a] as isize + d[a];
                        there[a] = c as usize;
                        c < 0 || c >= grid[a] as isize
                    }) {
                        continue;
                    }
                    let (mut send, mut receive) = (o.clone(), o.clone());
                    for (a, &step) in d.iter().enumerate() {
                        let r = o.axes[a].clone();
                        match step {
                            -1 => {
                                send.axes[a] = r.start..r.start + 1;
                                receive.axes[a] = r.start - 1..r.start;
                            }
                            1 => {
                                send.axes[a] = r.end - 1..r.end;
                                receive.axes[a] = r.end..r.end + 1;
                            }
                            _ => {}
                        }
                    }
                    out.push(Neighbour {
                        rank: stage.rank_at(there),
                        send,
                        receive,
                    });
                }
            }
        }
        out
    }

    /// Sends the layers of `x`'s box (level `l`, this rank's frame) next to each neighbour
    /// of its stage (faces, and with `corners` edges and corners), runs `interior` on `x`
    /// while they travel, and writes what the neighbours sent into the halo. A rank alone
    /// on its stage only runs `interior`.
    #[allow(clippy::too_many_arguments)]
    fn halo<T: Copy, R>(
        &self,
        l: usize,
        x: &mut [T],
        to_f64: fn(T) -> f64,
        from_f64: fn(f64) -> T,
        corners: bool,
        interior: impl FnOnce(&mut [T]) -> R,
    ) -> Result<R, DiffusionError> {
        let Some(held) = self.held[l].as_ref() else {
            return Ok(interior(x));
        };
        if self.stage(l).ranks() == 1 {
            return Ok(interior(x));
        }
        let frame = &held.frame;
        let neighbours = self.neighbours(l, corners);
        let parts: Vec<Vec<f64>> = neighbours
            .iter()
            .map(|n| frame.local(&n.send).read(frame.dims, x, to_f64))
            .collect();
        let sends: Vec<(usize, &[f64])> = neighbours
            .iter()
            .zip(&parts)
            .map(|(n, v)| (n.rank, &v[..]))
            .collect();
        let from: Vec<usize> = neighbours.iter().map(|n| n.rank).collect();
        let mut interior = Some(interior);
        let mut out = None;
        let received = {
            let x = &mut *x;
            self.comm.exchange_with(&sends, &from, &mut || {
                if let Some(f) = interior.take() {
                    out = Some(f(&mut *x));
                }
            })
        };
        let out = match (out, interior) {
            (Some(out), _) => out,
            (None, Some(f)) => f(&mut *x),
            (None, None) => unreachable!("the closure takes `interior` only to store its result"),
        };
        if received.len() != neighbours.len() {
            return Err(protocol(self.rank, "a halo"));
        }
        for (n, values) in neighbours.iter().zip(received) {
            if !frame
                .local(&n.receive)
                .write(frame.dims, x, &values, from_f64)
            {
                return Err(protocol(self.rank, "a halo"));
            }
        }
        Ok(out)
    }

    /// The face halo of an f32 vector of level `l`.
    fn halo32(&self, l: usize, x: &mut [f32]) -> Result<(), DiffusionError> {
        self.halo(l, x, f64::from, |v| v as f32, false, |_| ())
    }

    /// Moves level `l`'s cells between ranks 0..`ranks`: rank q holds `have(q)` (in
    /// `from`'s vector) and wants `want(q)` (in `to`'s); every rank sends each rank the
    /// part of its cells that rank wants, its own part copied (the `have` boxes of one
    /// level are disjoint, so each wanted cell has one holder).
    fn move_regions(
        &self,
        ranks: usize,
        from: Side<'_, &[f32]>,
        to: Side<'_, &mut [f32]>,
        have: impl Fn(usize) -> Region,
        want: impl Fn(usize) -> Region,
    ) -> Result<(), DiffusionError> {
        if self.rank >= ranks {
            return Ok(());
        }
        let mine = have(self.rank);
        let wanted = want(self.rank);
        let mut parts: Vec<(usize, Vec<f64>)> = Vec::new();
        let mut own = None;
        if let Some((frame, v)) = &from {
            for q in 0..ranks {
                let part = mine.overlap(&want(q));
                if part.is_empty() {
                    continue;
                }
                let values = frame.local(&part).read(frame.dims, v, f64::from);
                if q == self.rank {
                    own = Some((part, values));
                } else {
                    parts.push((q, values));
                }
            }
        }
        let sends: Vec<(usize, &[f64])> = parts.iter().map(|(q, v)| (*q, &v[..])).collect();
        let sources: Vec<(usize, Region)> = (0..ranks)
            .filter(|&q| q != self.rank)
            .map(|q| (q, have(q).overlap(&wanted)))
            .filter(|(_, part)| !part.is_empty())
            .collect();
        let ranks_from: Vec<usize> = sources.iter().map(|(q, _)| *q).collect();
        let received = self.comm.exchange_with(&sends, &ranks_from, &mut || ());
        if received.len() != sources.len() || (!sources.is_empty() && to.is_none()) {
            return Err(protocol(self.rank, "a coarse level's hand-over"));
        }
        if let Some((frame, v)) = to {
            let incoming = sources.into_iter().map(|(_, part)| part).zip(received);
            for (part, values) in own.into_iter().chain(incoming) {
                if !frame
                    .local(&part)
                    .write(frame.dims, v, &values, |v| v as f32)
                {
                    return Err(protocol(self.rank, "a coarse level's hand-over"));
                }
            }
        }
        Ok(())
    }

    /// Hands level `l + 1`'s restricted right-hand side from the ranks of `l`'s stage (the
    /// cells each restricted to, in its hand-over vector `down`) to the owners in the next
    /// stage (`b`).
    fn hand_down(&self, l: usize, down: &[f32], b: &mut [f32]) -> Result<(), DiffusionError> {
        let (fine, coarse) = (self.stage(l), self.stage(l + 1));
        let from = self.handover[l + 1].as_ref().map(|h| (&h.frame, down));
        let to = self.held[l + 1].as_ref().map(|h| (&h.frame, b));
        self.move_regions(
            fine.ranks(),
            from,
            to,
            |q| fine.owned(q, l + 1),
            |q| coarse.owned(q, l + 1),
        )
    }

    /// Hands level `l + 1`'s correction back from the next stage's owners (`x`) to the
    /// ranks of `l`'s stage (their hand-over vectors `up`): the cells each restricted to
    /// and, for trilinear prolongation, one more on every side (edges and corners too).
    fn hand_up(&self, l: usize, x: &[f32], up: &mut [f32]) -> Result<(), DiffusionError> {
        let (fine, coarse) = (self.stage(l), self.stage(l + 1));
        let dims = self.dims(l + 1);
        let halo = usize::from(self.settings.prolongation == Prolongation::Trilinear);
        let from = self.held[l + 1].as_ref().map(|h| (&h.frame, x));
        let to = self.handover[l + 1].as_ref().map(|h| (&h.frame, up));
        self.move_regions(
            fine.ranks(),
            from,
            to,
            |q| coarse.owned(q, l + 1),
            |q| fine.owned(q, l + 1).grown(halo, dims),
        )
    }

    /// The box's cells that read no halo (one cell in from every face that has a
    /// neighbour), and the rest of the box in pieces, in the frame's indices: the sweeps'
    /// work while the halo travels, and after it.
    fn inner_and_edges(&self, l: usize) -> (Region, Vec<Region>) {
        let o = self.owned(l);
        let stage = self.stage(l);
        let (Some(at), Some(held)) = (
            stage.coords(self.rank).filter(|_| !o.is_empty()),
            self.held[l].as_ref(),
        ) else {
            return (Region::default(), Vec::new());
        };
        let frame = &held.frame;
        let grid = stage.grid();
        let mut inner = o.clone();
        for a in 0..3 {
            let r = &o.axes[a];
            let start = r.start + usize::from(at[a] > 0);
            let end = r.end - usize::from(at[a] + 1 < grid[a]);
            if start >= end {
                return (Region::default(), vec![frame.local(&o)]);
            }
            inner.axes[a] = start..end;
        }
        let mut edges = Vec::new();
        let mut rest = o;
        for a in [2, 1, 0] {
            let (r, i) = (rest.axes[a].clone(), inner.axes[a].clone());
            for part in [r.start..i.start, i.end..r.end] {
                if !part.is_empty() {
                    let mut piece = rest.clone();
                    piece.axes[a] = part;
                    edges.push(frame.local(&piece));
                }
            }
            rest.axes[a] = i;
        }
        (frame.local(&inner), edges)
    }

    /// The pre- or post-smoothing sweeps on split level `l`.
    fn smooth(
        &self,
        l: usize,
        b: &[f32],
        x: &mut [f32],
        scratch: &mut [f32],
        post: bool,
    ) -> Result<(), DiffusionError> {
        let settings = &self.settings;
        let sweeps = if post {
            settings.post_sweeps
        } else {
            settings.pre_sweeps
        };
        let held = self.held(l)?;
        let level = &*held.level;
        let owned = held.frame.local(&self.owned(l));
        let (inner, edges) = self.inner_and_edges(l);
        for _ in 0..sweeps {
            match settings.smoother {
                Smoother::RedBlackGaussSeidel => {
                    let first = usize::from(post);
                    for colour in [first, 1 - first] {
                        self.halo(
                            l,
                            x,
                            f64::from,
                            |v| v as f32,
                            false,
                            |x| level.colour_in(b, x, colour, 1.0, &inner),
                        )?;
                        for edge in &edges {
                            level.colour_in(b, x, colour, 1.0, edge);
                        }
                    }
                }
                Smoother::Jacobi { omega } => {
                    self.halo(
                        l,
                        x,
                        f64::from,
                        |v| v as f32,
                        false,
                        |x| {
                            if !inner.is_empty() {
                                level.jacobi_in(b, x, omega, scratch, &inner);
                            }
                        },
                    )?;
                    for edge in &edges {
                        level.jacobi_in(b, x, omega, scratch, edge);
                    }
                    owned.copy(level.dims, scratch, x);
                }
            }
        }
        Ok(())
    }

    /// Where level `l`'s restriction writes and its prolongation reads level `l + 1`: the
    /// hand-over's frame across a stage boundary, this rank's own within a stage.
    fn coarse_side(&self, l: usize) -> Result<&Held<'a>, DiffusionError> {
        let side = if self.hands_over(l) {
            self.handover[l + 1].as_ref()
        } else {
            self.held[l + 1].as_ref()
        };
        side.ok_or_else(|| protocol(self.rank, "a coarse level this rank does not hold"))
    }

    /// Restricts level `l`'s residual (or, with `residual` false, its right-hand side) into
    /// level `l + 1`'s, and hands it down where the next level starts a stage.
    fn restrict(
        &self,
        l: usize,
        residual: bool,
        b: &mut Work,
        x: &Work,
        down: &mut Work,
    ) -> Result<(), DiffusionError> {
        let held = self.held(l)?;
        let coarse = self.coarse_side(l)?;
        let region = coarse.frame.local(&self.restricts_to(l));
        let origins = Origins {
            fine: held.frame.origin,
            coarse: coarse.frame.origin,
        };
        let (bf, bc) = b.split_at_mut(l + 1);
        let out = if self.hands_over(l) {
            &mut down[l + 1]
        } else {
            &mut bc[0]
        };
        if residual {
            held.level
                .restrict_residual(&bf[l], &x[l], &coarse.level, out, &region, origins);
        } else {
            held.level
                .restrict(&bf[l], &coarse.level, out, &region, origins);
        }
        if self.hands_over(l) {
            self.hand_down(l, &down[l + 1], &mut b[l + 1])?;
        }
        Ok(())
    }

    /// One cycle on level `l` for A x = b (x holds the initial guess on the owned box);
    /// a rank with no part in level `l` returns at once.
    fn cycle(&self, l: usize, cycle: Cycle, w: &mut Vectors) -> Result<(), DiffusionError> {
        if self.owned(l).is_empty() {
            return Ok(());
        }
        if self.serial(l) {
            let Serial { first: f, mg } = self.serial_levels()?;
            mg.cycle(l - f, cycle, &mut w.b[*f..], &mut w.x[*f..], &mut w.s[*f..]);
            return Ok(());
        }
        self.smooth(l, &w.b[l], &mut w.x[l], &mut w.s[l], false)?;
        self.halo32(l, &mut w.x[l])?;
        self.restrict(l, true, &mut w.b, &w.x, &mut w.down)?;
        w.x[l + 1].fill(0.0);
        if !self.owned(l + 1).is_empty() {
            match cycle {
                Cycle::V => self.cycle(l + 1, Cycle::V, w)?,
                Cycle::W => {
                    self.cycle(l + 1, Cycle::W, w)?;
                    self.cycle(l + 1, Cycle::W, w)?;
                }
                Cycle::F => {
                    self.cycle(l + 1, Cycle::F, w)?;
                    self.cycle(l + 1, Cycle::V, w)?;
                }
                // The layout keeps the K-cycle's coarse levels on rank 0.
                Cycle::K => {
                    let Serial { first: f, mg } = self.serial_levels()?;
                    mg.krylov_correction(l + 1 - f, &mut w.b[*f..], &mut w.x[*f..], &mut w.s[*f..]);
                }
            }
        }
        self.prolong(l, w)?;
        self.smooth(l, &w.b[l], &mut w.x[l], &mut w.s[l], true)
    }

    /// x[l] += the prolonged x[l + 1], on the owned box of `l` (after fetching the coarse
    /// cells it reads: the halo within a stage, with edges and corners for trilinear
    /// prolongation; the hand-up across one).
    fn prolong(&self, l: usize, w: &mut Vectors) -> Result<(), DiffusionError> {
        if self.serial(l) {
            // Rank 0's serial levels: the serial prolongation.
            let Serial { first: f, mg } = self.serial_levels()?;
            let (xf, xc) = w.x.split_at_mut(l + 1);
            mg.prolong(l - f, &xc[0], &mut xf[l], &mg.levels[l - f].whole());
            return Ok(());
        }
        let trilinear = self.settings.prolongation == Prolongation::Trilinear;
        if self.hands_over(l) {
            self.hand_up(l, &w.x[l + 1], &mut w.up[l + 1])?;
        } else if trilinear {
            self.halo(
                l + 1,
                &mut w.x[l + 1],
                f64::from,
                |v| v as f32,
                true,
                |_| (),
            )?;
        }
        let held = self.held(l)?;
        let coarse = self.coarse_side(l)?;
        let origins = Origins {
            fine: held.frame.origin,
            coarse: coarse.frame.origin,
        };
        let region = held.frame.local(&self.owned(l));
        let (xf, xc) = w.x.split_at_mut(l + 1);
        let xc = if self.hands_over(l) {
            &w.up[l + 1]
        } else {
            &xc[0]
        };
        if trilinear {
            held.level
                .prolong_trilinear_add(&coarse.level, xc, &mut xf[l], &region, origins);
        } else {
            held.level
                .prolong_add(&coarse.level, xc, &mut xf[l], &region, origins);
        }
        Ok(())
    }

    /// Full multigrid from the owned box of the fine right-hand side (`rhs`, this rank's
    /// frame of level 0).
    fn full_multigrid(&self, rhs: &[f64], w: &mut Vectors) -> Result<(), DiffusionError> {
        let held = self.held(0)?;
        let owned = held.frame.local(&self.owned(0));
        let n = owned.axes[0].len();
        for start in owned.lines(held.frame.dims) {
            for (b, r) in w.b[0][start..start + n].iter_mut().zip(&rhs[start..]) {
                *b = *r as f32;
            }
        }
        let last = self.dims.len() - 1;
        for l in 0..last {
            if self.owned(l).is_empty() {
                break;
            }
            if self.serial(l) {
                // Rank 0's serial levels: the serial restriction.
                let Serial { first: f, mg } = self.serial_levels()?;
                let (bf, bc) = w.b.split_at_mut(l + 1);
                let coarse = &mg.levels[l + 1 - f];
                mg.levels[l - f].restrict(
                    &bf[l],
                    coarse,
                    &mut bc[0],
                    &coarse.whole(),
                    Origins::default(),
                );
                continue;
            }
            self.restrict(l, false, &mut w.b, &w.x, &mut w.down)?;
        }
        if !self.owned(last).is_empty() {
            w.x[last].fill(0.0);
            self.serial_levels()?
                .mg
                .coarsest(&w.b[last], &mut w.x[last]);
        }
        for l in (0..last).rev() {
            if self.owned(l).is_empty() {
                continue;
            }
            w.x[l].fill(0.0);
            self.prolong(l, w)?;
            self.cycle(l, self.settings.cycle, w)?;
        }
        Ok(())
    }

    /// The solve on this rank's frame of the fine level: `rhs` and `phi` (the initial
    /// guess, ignored under full multigrid) on it, φ left on the owned box. The history and
    /// stop reason are every rank's.
    fn iterate(
        &self,
        rhs: &[f64],
        phi_held: &mut [f64],
        stopping: &Stopping,
    ) -> Result<Convergence, DiffusionError> {
        let started = std::time::Instant::now();
        let (frame, fine) = match self.held[0].as_ref() {
            Some(h) if self.serial(0) => {
                (h.frame.clone(), Some(&self.serial_levels()?.mg.levels[0]))
            }
            Some(h) => (h.frame.clone(), Some(&*h.level)),
            None => (
                Frame {
                    origin: [0; 3],
                    dims: [0; 3],
                },
                None,
            ),
        };
        let o = frame.local(&self.owned(0));
        // Σ of every rank's exact run sums, with every rank's flags: the serial norm's bits.
        let gather = |sum: ExactSum| -> Result<Gathered, DiffusionError> {
            let flags = stopping.local_flags(started);
            let (flags, sums) = all_reduce_sums(self.comm, &flags, &[sum])
                .ok_or_else(|| protocol(self.rank, "a norm's reduction"))?;
            Ok(Gathered {
                norm: sums[0].value().sqrt(),
                time_up: flags[0],
                cancelled: flags[1],
            })
        };
        // The deterministic stops from the shared residual; the clock and the cancel flag
        // come with the gathers.
        let shared = Stopping {
            time_budget: None,
            cancel: None,
            // The deadline too: each rank's clock travels with the reduced flags;
            // asked alone, ranks would stop at different steps and wait on each other.
            deadline: None,
            progress: if self.rank == 0 {
                stopping.progress.clone()
            } else {
                None
            },
            ..stopping.clone()
        };
        let b_norm = gather(fine.map_or_else(ExactSum::new, |f| f.squares_in(rhs, &o)))?
            .norm
            .max(f64::MIN_POSITIVE);
        let (b, x, s, down, up) = self.work();
        let mut w = Vectors { b, x, s, down, up };
        if self.settings.full_multigrid && fine.is_some() {
            self.full_multigrid(rhs, &mut w)?;
            let values = o.read(frame.dims, &w.x[0], f64::from);
            o.write(frame.dims, phi_held, &values, |v| v);
        }
        let mut r = vec![0.0f64; frame.len()];
        let true_residual = |phi: &mut [f64], r: &mut [f64]| -> Result<ExactSum, DiffusionError> {
            self.halo(0, phi, |v| v, |v| v, false, |_| ())?;
            Ok(fine.map_or_else(ExactSum::new, |f| f.residual_in(rhs, phi, r, &o)))
        };
        let mut gathered = gather(true_residual(phi_held, &mut r)?)?;
        let to_b = |b: &mut [f32], r: &[f64]| {
            let n = o.axes[0].len();
            for start in o.lines(frame.dims) {
                for (b, r) in b[start..start + n].iter_mut().zip(&r[start..]) {
                    *b = *r as f32;
                }
            }
        };
        to_b(&mut w.b[0], &r);
        let mut residuals = vec![gathered.norm / b_norm];
        let initial = residuals[0];
        let stop_reason = loop {
            let iteration = residuals.len() - 1;
            let norm = gathered.norm;
            if let Some(reason) = shared.verdict(iteration, norm / b_norm, norm, initial, started) {
                if !reason.is_converged() {
                    break reason;
                }
                gathered = gather(true_residual(phi_held, &mut r)?)?;
                let norm = gathered.norm;
                *residuals.last_mut().unwrap_or(&mut 0.0) = norm / b_norm;
                if let Some(reason) = shared
                    .verdict(iteration, norm / b_norm, norm, initial, started)
                    .filter(|r| r.is_converged())
                {
                    break reason;
                }
                to_b(&mut w.b[0], &r);
            }
            let relative = norm / b_norm;
            if gathered.time_up {
                break StopReason::TimeLimit { residual: relative };
            }
            if gathered.cancelled {
                break StopReason::Interrupted { residual: relative };
            }
            let sum = match fine {
                Some(fine) => {
                    w.x[0].fill(0.0);
                    self.cycle(0, self.settings.cycle, &mut w)?;
                    self.halo32(0, &mut w.x[0])?;
                    fine.correct_in(&w.x[0], phi_held, &mut r, &mut w.b[0], &o)
                }
                None => ExactSum::new(),
            };
            gathered = gather(sum)?;
            residuals.push(gathered.norm / b_norm);
        };
        Ok(Convergence {
            residuals,
            stop_reason,
        })
    }
}

/// One rank's work vectors: per level b, x and the smoothers' scratch on its frame; per
/// level that starts a stage the hand-over's right-hand side and correction.
struct Vectors {
    b: Work,
    x: Work,
    s: Work,
    down: Work,
    up: Work,
}

/// A norm's reduction: the norm, whether any rank's clock ran out, whether any rank was
/// cancelled.
struct Gathered {
    norm: f64,
    time_up: bool,
    cancelled: bool,
}

/// Whether `layout` splits a hierarchy of levels of `dims` cells over `ranks` ranks as a stage layout must:
/// stages cover the levels in order, the last on one rank; each stage's grid of boxes
/// (no more than `ranks` boxes, no more than its predecessor's) cuts each axis of its
/// first level in order, inner cuts multiples of 2^levels, and on the fine level x's
/// of `NORM_RUN` (so the norms are the serial bits).
fn check_layout(
    layout: &RankLayout,
    dims: &[[usize; 3]],
    cycle: Cycle,
    ranks: usize,
) -> Result<(), DiffusionError> {
    let invalid = |why: &str| {
        Err(DiffusionError::Invalid(format!(
            "a rank layout whose {why} ({layout:?} for {} levels on {ranks} ranks)",
            dims.len()
        )))
    };
    let mut level = 0;
    let mut previous = ranks;
    for (i, stage) in layout.stages.iter().enumerate() {
        let last = i + 1 == layout.stages.len();
        if stage.first_level != level || stage.levels == 0 {
            return invalid("stages do not follow each other");
        }
        let p = stage.ranks();
        if p == 0 || p > previous || (last != (p == 1)) {
            return invalid("rank counts do not shrink to one on the last stage");
        }
        let Some(level_dims) = dims.get(level) else {
            return invalid("stages run past the coarsest level");
        };
        let unit = 1usize << stage.levels.min(usize::BITS as usize - 2);
        for (a, cuts) in stage.cuts.iter().enumerate() {
            let unit = if level == 0 && a == 0 {
                unit.max(NORM_RUN)
            } else {
                unit
            };
            let inner = cuts.get(1..cuts.len().saturating_sub(1)).unwrap_or(&[]);
            if cuts.first() != Some(&0)
                || cuts.last() != Some(&level_dims[a])
                || cuts.windows(2).any(|w| w[1] <= w[0])
                || inner.iter().any(|c| c % unit != 0)
            {
                return invalid("boxes do not cover a level in whole units");
            }
        }
        previous = p;
        level += stage.levels;
        if level > dims.len() {
            return invalid("stages run past the coarsest level");
        }
    }
    if level != dims.len() {
        return invalid("stages do not reach the coarsest level");
    }
    if cycle == Cycle::K
        && layout
            .stages
            .first()
            .is_some_and(|s| s.ranks() > 1 && s.levels > 1)
    {
        return invalid(
            "K-cycle splits more than its fine level (its Krylov steps run on one rank)",
        );
    }
    Ok(())
}

impl Multigrid {
    /// Whether `layout` splits this hierarchy over `ranks` ranks as a stage layout must:
    /// stages cover the levels in order, the last on one rank; each stage's grid of boxes
    /// (no more than `ranks` boxes, no more than its predecessor's) cuts each axis of its
    /// first level in order, inner cuts multiples of 2^levels, and on the fine level x's
    /// of `NORM_RUN` (so the norms are the serial bits).
    fn check_layout(&self, layout: &RankLayout, ranks: usize) -> Result<(), DiffusionError> {
        let dims: Vec<[usize; 3]> = self.levels.iter().map(|l| l.dims).collect();
        check_layout(layout, &dims, self.settings().cycle, ranks)
    }

    /// How [`Multigrid::solve_on_ranks`] splits this hierarchy over `ranks` ranks: coarse
    /// levels go to fewer ranks below [`RankLayout::COARSE_CELLS_PER_RANK`] cells per
    /// rank ([`Multigrid::rank_layout_with`] chooses the threshold).
    ///
    /// # Errors
    /// [`DiffusionError::Ranks`] for no ranks or more ranks than z-layers.
    pub fn rank_layout(&self, ranks: usize) -> Result<RankLayout, DiffusionError> {
        self.rank_layout_with(ranks, RankLayout::COARSE_CELLS_PER_RANK)
    }

    /// [`Multigrid::rank_layout`] with levels split while they have at least
    /// `coarse_cells_per_rank` cells per rank (0: as far as the layers allow).
    ///
    /// # Errors
    /// [`DiffusionError::Ranks`] for no ranks or more ranks than z-layers.
    pub fn rank_layout_with(
        &self,
        ranks: usize,
        coarse_cells_per_rank: usize,
    ) -> Result<RankLayout, DiffusionError> {
        self.layout(ranks, coarse_cells_per_rank, Decomposition::Slabs)
    }

    /// How this hierarchy splits over `ranks` ranks cut as `decomposition`, levels split
    /// while they have at least `coarse_cells_per_rank` cells per rank (0: as far as the
    /// cells allow; [`RankLayout::COARSE_CELLS_PER_RANK`] is the default).
    ///
    /// # Errors
    /// [`DiffusionError::Ranks`] for no ranks, or more ranks than z-layers (slabs) or cells
    /// (boxes).
    pub fn layout(
        &self,
        ranks: usize,
        coarse_cells_per_rank: usize,
        decomposition: Decomposition,
    ) -> Result<RankLayout, DiffusionError> {
        let dims: Vec<[usize; 3]> = self.levels.iter().map(|l| l.dims).collect();
        RankLayout::with(
            &dims,
            ranks,
            self.settings().cycle,
            coarse_cells_per_rank,
            decomposition,
        )
    }

    /// [`Multigrid::solve`] on the ranks of `comm` over z-slabs ([`Multigrid::layout`] and
    /// [`Multigrid::solve_on_layout`] for boxes), every rank calling it with the whole
    /// `rhs` (this rank reads its box of it). `phi` is the initial guess (ignored under
    /// full multigrid) and holds the whole solution on every rank on return; the history
    /// and the stop reason are the same on every rank and for any number of ranks.
    ///
    /// # Errors
    /// [`DiffusionError::Ranks`] if the ranks cannot split the grid or a rank left the
    /// protocol; [`DiffusionError::Invalid`] for vectors of the wrong length.
    pub fn solve_on_ranks(
        &self,
        rhs: &[f64],
        phi: &mut [f64],
        stopping: &Stopping,
        comm: &(impl Communicator + ?Sized),
    ) -> Result<Convergence, DiffusionError> {
        let layout = self.rank_layout(comm.size())?;
        self.solve_on_layout(rhs, phi, stopping, comm, layout)
    }

    /// [`Multigrid::solve_on_ranks`] with a chosen layout (every rank passes the same one,
    /// for `comm.size()` ranks; [`Multigrid::rank_layout_with`] makes one).
    ///
    /// # Errors
    /// As [`Multigrid::solve_on_ranks`]; [`DiffusionError::Invalid`] for a layout of
    /// another hierarchy or rank count.
    pub fn solve_on_layout(
        &self,
        rhs: &[f64],
        phi: &mut [f64],
        stopping: &Stopping,
        comm: &(impl Communicator + ?Sized),
        layout: RankLayout,
    ) -> Result<Convergence, DiffusionError> {
        self.check_layout(&layout, comm.size())?;
        let n = self.fine_cells();
        if rhs.len() != n || phi.len() != n {
            return Err(DiffusionError::Invalid(format!(
                "a right-hand side of {} and a solution of {} values for a hierarchy of {n} cells",
                rhs.len(),
                phi.len()
            )));
        }
        let on = OnRanks::new(self, comm, layout);
        let dims = self.fine().dims;
        // This rank's fine level: its box and the cells around it (nothing on a rank the
        // fine level leaves out), rhs and φ held there, o the box in the frame's indices.
        let frame = on.held[0].as_ref().map_or(
            Frame {
                origin: [0; 3],
                dims: [0; 3],
            },
            |h| h.frame.clone(),
        );
        let around = Region::new(std::array::from_fn(|a| {
            frame.origin[a]..frame.origin[a] + frame.dims[a]
        }));
        let o = frame.local(&on.owned(0));
        // A rank that holds the whole fine level (one rank, or the fine level on rank 0
        // alone) works on the caller's vectors; the others on copies of their frame.
        let whole_level = frame == Frame::whole(dims);
        let rhs: Cow<'_, [f64]> = if whole_level {
            Cow::Borrowed(rhs)
        } else {
            Cow::Owned(around.cut(dims, rhs))
        };
        let mut copied = (!whole_level).then(|| around.cut(dims, phi));
        let phi_held: &mut [f64] = match copied.as_mut() {
            Some(v) => v,
            None => &mut *phi,
        };
        let convergence = on.iterate(&rhs, phi_held, stopping)?;
        if comm.size() == 1 {
            // φ is the caller's already.
            return Ok(convergence);
        }
        // Every rank's box, in rank order (ranks past the fine stage hold none).
        let mine = o.read(frame.dims, phi_held, |v| v);
        let whole = comm.all_gather(&mine);
        let mut at = 0;
        for q in 0..comm.size() {
            let part = on.layout.owned(q, 0);
            let end = at + part.cells();
            if end > whole.len() || !part.write(dims, phi, &whole[at..end], |v| v) {
                return Err(protocol(on.rank, "the solution's gather"));
            }
            at = end;
        }
        if at != n || whole.len() != n {
            return Err(protocol(on.rank, "the solution's gather"));
        }
        Ok(convergence)
    }
}
