//! Multigrid on ranks: the hierarchy split into z-slabs, the finer levels over every rank
//! and the coarser ones agglomerated onto fewer ranks, down to one for the coarsest.
//!
//! **Layout** ([`RankLayout`]): the levels fall into *stages*, runs of levels split over
//! the same ranks 0..p. A stage of m levels cuts its first level's z-layers into runs of
//! whole units of 2^m layers, balanced by units, so the slab bounds stay whole layers on
//! each of its levels (level L + i owns layers [k₀/2^i, ⌈k₁/2^i⌉)) and on the next
//! stage's first level: a coarse cell's eight children are on one rank, and restriction
//! and constant prolongation need no halo. m is the largest with p·2^m ≤ n_z (every rank
//! keeps a unit) that leaves the coarsest level out and keeps every level of the stage but
//! the fine one at `coarse_cells_per_rank` cells per rank or more. The next stage takes
//! p' = min(p, ⌊n_z'/2⌋, cells'/`coarse_cells_per_rank`) ranks, about half as many, as
//! HPGMG and AMReX agglomerate coarse levels; the stage on one rank (always the coarsest
//! level's) is rank 0's, which cycles it serially. The K-cycle splits its fine level only
//! (its coarse Krylov steps run on rank 0).
//!
//! **A cycle on a split level** (as [`Multigrid`]'s, the same arithmetic per cell):
//! - red–black Gauss–Seidel: each colour starts by sending the slab's first and last
//!   layers to the neighbours and sweeping the layers between them while the layers
//!   travel, then sweeps the two boundary layers with the received halo; weighted Jacobi
//!   likewise;
//! - the residual's restriction after one halo exchange; trilinear prolongation after one
//!   on the coarse level (constant prolongation needs none);
//! - where the next level starts a stage, the restricted right-hand side moves from the
//!   layers each rank computed to the next stage's owners (point to point, each owner
//!   receiving from the two or three ranks whose slabs cover its own), the ranks outside
//!   the next stage wait, and the coarse correction comes back with the one-layer halo
//!   trilinear prolongation reads. Ranks that own nothing on a level exchange nothing on
//!   it.
//!
//! **Norms** are the serial solve's (`Level::norm`): every x-line of the fine level cut
//! into runs of eight cells, each run summed left to right, the run sums added exactly
//! (`lucent_core::exact::ExactSum`). Each rank sums the runs of its layers and the ranks
//! all-reduce the accumulators with their time-budget and cancel flags
//! (`lucent_core::ranks::all_reduce_sums`: log₂P messages of 71 words per norm). An exact
//! sum does not depend on the order of its terms, so the residual history, the stopping
//! decisions and φ are [`Multigrid::solve`]'s bits on every rank count (tested on 1–5
//! ranks, every cycle and smoother, with and without agglomeration). The time budget and
//! cancellation are each rank's own and travel with the reduction, so all ranks stop on
//! the same cycle.
//!
//! **Not yet.** Every rank holds the whole hierarchy and full-length work vectors (it
//! touches only its slabs and their halos), so memory does not scale with ranks.

use std::ops::Range;

use lucent_core::exact::ExactSum;
use lucent_core::ranks::{Communicator, all_reduce_sums};
use lucent_core::{StopReason, Stopping};

use crate::error::DiffusionError;
use crate::level::Level;
use crate::multigrid::{Convergence, Cycle, Multigrid, Prolongation, Smoother, Work};

/// A run of levels split over the same ranks.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stage {
    /// Its first level.
    pub first_level: usize,
    /// How many levels it spans: `first_level..first_level + levels`.
    pub levels: usize,
    /// Per rank that works on it (ranks `0..layers.len()`), its z-layers [k₀, k₁) of the
    /// first level: the bounds are multiples of 2^`levels` but the last, so a coarse
    /// cell's children stay on one rank down to the next stage's first level.
    pub layers: Vec<(usize, usize)>,
}

impl Stage {
    /// How many ranks work on it.
    pub fn ranks(&self) -> usize {
        self.layers.len()
    }

    /// Rank `rank`'s layers of level `level`, which may be the next stage's first level
    /// (the layers its slab restricts to); empty for a rank outside the stage or a level
    /// above it.
    pub fn owned(&self, rank: usize, level: usize) -> Range<usize> {
        let (Some(&(k0, k1)), Some(shift)) =
            (self.layers.get(rank), level.checked_sub(self.first_level))
        else {
            return 0..0;
        };
        let shift = shift.min(usize::BITS as usize - 1);
        (k0 >> shift)..k1.div_ceil(1 << shift)
    }
}

/// How a hierarchy is split over ranks: its stages, finest first, covering every level;
/// the last is on one rank and holds the coarsest level.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RankLayout {
    /// The stages, finest first.
    pub stages: Vec<Stage>,
}

impl RankLayout {
    /// Below this many cells per rank a level goes to fewer ranks: 16³, where a sweep's
    /// work per rank (tens of microseconds) is no longer large against a message's
    /// latency.
    pub const COARSE_CELLS_PER_RANK: usize = 4096;

    /// The layout of a hierarchy whose levels have `dims` (finest first) on `ranks` ranks:
    /// the fine level over every rank while each keeps two layers, then a stage keeps at
    /// least `coarse_cells_per_rank` cells per rank on each of its coarse levels (0 or 1:
    /// split as far as the layers allow).
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
        let Some(fine) = dims.first() else {
            return Err(DiffusionError::Invalid("a hierarchy of no levels".into()));
        };
        let n_z = fine[2];
        if ranks == 0 || ranks > n_z {
            return Err(DiffusionError::Ranks(format!(
                "{ranks} ranks for {n_z} z-layers: every rank needs at least one layer"
            )));
        }
        let depth = dims.len();
        let per_rank = coarse_cells_per_rank.max(1);
        let cells = |l: usize| dims[l].iter().product::<usize>();
        let mut stages = Vec::new();
        let (mut level, mut p) = (0, ranks);
        loop {
            let n = dims[level][2];
            // The fine level is split over every rank it can be (the caller chose the
            // ranks, and its data lives split); coarser ones keep the threshold.
            p = p.min(n / 2).max(1);
            if level > 0 {
                p = p.min(cells(level) / per_rank).max(1);
            }
            if level + 1 == depth || (cycle == Cycle::K && level > 0) {
                p = 1;
            }
            if p == 1 {
                stages.push(Stage {
                    first_level: level,
                    levels: depth - level,
                    layers: vec![(0, n)],
                });
                return Ok(Self { stages });
            }
            let mut m = 1;
            while level + m + 1 < depth
                && p << (m + 1) <= n
                && cells(level + m) >= p * per_rank
                && !(cycle == Cycle::K)
            {
                m += 1;
            }
            let unit = 1usize << m;
            let units = n.div_ceil(unit);
            let layers = (0..p)
                .map(|r| {
                    let (u0, u1) = (r * units / p, (r + 1) * units / p);
                    (u0 * unit, (u1 * unit).min(n))
                })
                .collect();
            stages.push(Stage {
                first_level: level,
                levels: m,
                layers,
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

    /// Rank `rank`'s layers of level `level` (empty where it does not work on it).
    pub fn owned(&self, rank: usize, level: usize) -> Range<usize> {
        self.stage_of(level).owned(rank, level)
    }
}

/// One rank's view of the distributed solve: the communicator, the layout, the hierarchy.
struct OnRanks<'a, C: ?Sized> {
    mg: &'a Multigrid,
    comm: &'a C,
    layout: RankLayout,
    rank: usize,
}

/// A message that did not fit the plan.
fn protocol(rank: usize, what: &str) -> DiffusionError {
    DiffusionError::Ranks(format!(
        "rank {rank}: {what} did not match the decomposition (a rank stopped or diverged from the protocol)"
    ))
}

/// The common part of two layer ranges.
fn overlap(a: &Range<usize>, b: &Range<usize>) -> Range<usize> {
    let (start, end) = (a.start.max(b.start), a.end.min(b.end));
    start..end.max(start)
}

impl<C: Communicator + ?Sized> OnRanks<'_, C> {
    fn level(&self, l: usize) -> &Level {
        &self.mg.levels[l]
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

    /// The layers of level `l` this rank computes (empty where it has no part in it).
    fn owned(&self, l: usize) -> Range<usize> {
        self.layout.owned(self.rank, l)
    }

    /// The coarse layers (level `l + 1`) this rank's slab of level `l` restricts to.
    fn restricts_to(&self, l: usize) -> Range<usize> {
        self.stage(l).owned(self.rank, l + 1)
    }

    /// Sends the first and last owned layers of `x` (level `l`) to the neighbours of its
    /// stage, runs `interior` on `x` while they travel, and writes what the neighbours
    /// sent into the halo layers. A rank outside the stage only runs `interior`.
    fn halo<T: Copy, R>(
        &self,
        l: usize,
        x: &mut [T],
        to_f64: fn(T) -> f64,
        from_f64: fn(f64) -> T,
        interior: impl FnOnce(&mut [T]) -> R,
    ) -> Result<R, DiffusionError> {
        let slab = self.level(l).slab();
        let o = self.owned(l);
        let ranks = self.stage(l).ranks();
        if o.is_empty() || ranks == 1 {
            return Ok(interior(x));
        }
        let below = (self.rank > 0).then(|| self.rank - 1);
        let above = Some(self.rank + 1).filter(|&r| r < ranks);
        let layer = |k: usize, x: &[T]| -> Vec<f64> {
            x[k * slab..(k + 1) * slab]
                .iter()
                .map(|&v| to_f64(v))
                .collect()
        };
        let to_below = below.map(|_| layer(o.start, x)).unwrap_or_default();
        let to_above = above.map(|_| layer(o.end - 1, x)).unwrap_or_default();
        let sends: Vec<(usize, &[f64])> = below
            .map(|b| (b, &to_below[..]))
            .into_iter()
            .chain(above.map(|a| (a, &to_above[..])))
            .collect();
        let from: Vec<usize> = below.into_iter().chain(above).collect();
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
        let mut received = received.into_iter();
        for (k, present) in [(o.start.wrapping_sub(1), below), (o.end, above)] {
            if present.is_none() {
                continue;
            }
            let values = received.next().unwrap_or_default();
            if values.len() != slab {
                return Err(protocol(self.rank, "a halo"));
            }
            for (x, v) in x[k * slab..(k + 1) * slab].iter_mut().zip(values) {
                *x = from_f64(v);
            }
        }
        Ok(out)
    }

    fn halo32(&self, l: usize, x: &mut [f32]) -> Result<(), DiffusionError> {
        self.halo(l, x, f64::from, |v| v as f32, |_| ())
    }

    /// Moves level `l`'s layers between ranks 0..`ranks`: rank q holds `have(q)` and
    /// wants `want(q)`; every rank sends each other rank the part of its layers that rank
    /// wants and receives its own wants from their holders (the ranges on one level are
    /// disjoint for `have`, so each wanted layer has one holder).
    fn move_layers(
        &self,
        l: usize,
        v: &mut [f32],
        ranks: usize,
        have: impl Fn(usize) -> Range<usize>,
        want: impl Fn(usize) -> Range<usize>,
    ) -> Result<(), DiffusionError> {
        if self.rank >= ranks {
            return Ok(());
        }
        let slab = self.level(l).slab();
        let mine = have(self.rank);
        let parts: Vec<(usize, Vec<f64>)> = (0..ranks)
            .filter(|&q| q != self.rank)
            .filter_map(|q| {
                let part = overlap(&mine, &want(q));
                (!part.is_empty()).then(|| {
                    let values = v[part.start * slab..part.end * slab]
                        .iter()
                        .map(|&x| f64::from(x))
                        .collect();
                    (q, values)
                })
            })
            .collect();
        let sends: Vec<(usize, &[f64])> = parts.iter().map(|(q, v)| (*q, &v[..])).collect();
        let wanted = want(self.rank);
        let from: Vec<(usize, Range<usize>)> = (0..ranks)
            .filter(|&q| q != self.rank)
            .map(|q| (q, overlap(&have(q), &wanted)))
            .filter(|(_, part)| !part.is_empty())
            .collect();
        let sources: Vec<usize> = from.iter().map(|(q, _)| *q).collect();
        let received = self.comm.exchange_with(&sends, &sources, &mut || ());
        for ((_, part), values) in from.iter().zip(received) {
            if values.len() != part.len() * slab {
                return Err(protocol(self.rank, "a coarse level's hand-over"));
            }
            for (x, v) in v[part.start * slab..part.end * slab].iter_mut().zip(values) {
                *x = v as f32;
            }
        }
        Ok(())
    }

    /// Hands level `l + 1`'s restricted right-hand side from the ranks of `l`'s stage (the
    /// layers each restricted to) to the owners in the next stage.
    fn hand_down(&self, l: usize, b: &mut [f32]) -> Result<(), DiffusionError> {
        let (fine, coarse) = (self.stage(l), self.stage(l + 1));
        self.move_layers(
            l + 1,
            b,
            fine.ranks(),
            |q| fine.owned(q, l + 1),
            |q| coarse.owned(q, l + 1),
        )
    }

    /// Hands level `l + 1`'s correction back from the next stage's owners to the ranks of
    /// `l`'s stage: the layers each restricted to and, for trilinear prolongation, one
    /// more each side.
    fn hand_up(&self, l: usize, x: &mut [f32]) -> Result<(), DiffusionError> {
        let (fine, coarse) = (self.stage(l), self.stage(l + 1));
        let nz = self.level(l + 1).dims[2];
        let halo = usize::from(self.mg.settings().prolongation == Prolongation::Trilinear);
        self.move_layers(
            l + 1,
            x,
            fine.ranks(),
            |q| coarse.owned(q, l + 1),
            |q| {
                let r = fine.owned(q, l + 1);
                if r.is_empty() {
                    r
                } else {
                    r.start.saturating_sub(halo)..(r.end + halo).min(nz)
                }
            },
        )
    }

    /// Zeroes level `l`'s vector where this rank reads it: its slab and halos.
    fn zero(&self, l: usize, x: &mut [f32]) {
        let o = self.owned(l);
        if o.is_empty() {
            return;
        }
        let slab = self.level(l).slab();
        let nz = self.level(l).dims[2];
        x[o.start.saturating_sub(1) * slab..(o.end + 1).min(nz) * slab].fill(0.0);
    }

    /// The owned layers but the first and last, and those two (one when the slab is one
    /// layer thick).
    fn inner_and_edges(&self, l: usize) -> (Range<usize>, Vec<Range<usize>>) {
        let o = self.owned(l);
        if o.len() <= 2 {
            return (
                o.start..o.start,
                (o.start..o.end).map(|k| k..k + 1).collect(),
            );
        }
        (
            o.start + 1..o.end - 1,
            vec![o.start..o.start + 1, o.end - 1..o.end],
        )
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
        let settings = self.mg.settings();
        let sweeps = if post {
            settings.post_sweeps
        } else {
            settings.pre_sweeps
        };
        let level = self.level(l);
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
                            |x| {
                                level.colour_layers(b, x, colour, 1.0, inner.clone());
                            },
                        )?;
                        for edge in &edges {
                            level.colour_layers(b, x, colour, 1.0, edge.clone());
                        }
                    }
                }
                Smoother::Jacobi { omega } => {
                    self.halo(
                        l,
                        x,
                        f64::from,
                        |v| v as f32,
                        |x| {
                            level.jacobi_layers(b, x, omega, scratch, inner.clone());
                        },
                    )?;
                    for edge in &edges {
                        level.jacobi_layers(b, x, omega, scratch, edge.clone());
                    }
                    let o = self.owned(l);
                    let slab = level.slab();
                    x[o.start * slab..o.end * slab]
                        .copy_from_slice(&scratch[o.start * slab..o.end * slab]);
                }
            }
        }
        Ok(())
    }

    /// One cycle on level `l` for A x = b (x holds the initial guess on the owned layers);
    /// a rank with no part in level `l` returns at once.
    fn cycle(
        &self,
        l: usize,
        cycle: Cycle,
        b: &mut Work,
        x: &mut Work,
        s: &mut Work,
    ) -> Result<(), DiffusionError> {
        if self.owned(l).is_empty() {
            return Ok(());
        }
        if self.serial(l) {
            self.mg.cycle(l, cycle, b, x, s);
            return Ok(());
        }
        self.smooth(l, &b[l], &mut x[l], &mut s[l], false)?;
        self.halo32(l, &mut x[l])?;
        {
            let (bf, bc) = b.split_at_mut(l + 1);
            let coarse = self.level(l + 1);
            self.level(l).restrict_residual(
                &bf[l],
                &x[l],
                coarse,
                &mut bc[0],
                self.restricts_to(l),
            );
        }
        if self.hands_over(l) {
            self.hand_down(l, &mut b[l + 1])?;
        }
        self.zero(l + 1, &mut x[l + 1]);
        if !self.owned(l + 1).is_empty() {
            match cycle {
                Cycle::V => self.cycle(l + 1, Cycle::V, b, x, s)?,
                Cycle::W => {
                    self.cycle(l + 1, Cycle::W, b, x, s)?;
                    self.cycle(l + 1, Cycle::W, b, x, s)?;
                }
                Cycle::F => {
                    self.cycle(l + 1, Cycle::F, b, x, s)?;
                    self.cycle(l + 1, Cycle::V, b, x, s)?;
                }
                // The layout keeps the K-cycle's coarse levels on rank 0.
                Cycle::K => self.mg.krylov_correction(l + 1, b, x, s),
            }
        }
        self.prolong(l, x)?;
        self.smooth(l, &b[l], &mut x[l], &mut s[l], true)
    }

    /// x[l] += the prolonged x[l + 1], on the owned layers of `l` (after fetching the
    /// coarse layers it reads: the halo within a stage, the hand-up across one).
    fn prolong(&self, l: usize, x: &mut Work) -> Result<(), DiffusionError> {
        if self.hands_over(l) {
            self.hand_up(l, &mut x[l + 1])?;
        } else if self.mg.settings().prolongation == Prolongation::Trilinear {
            self.halo32(l + 1, &mut x[l + 1])?;
        }
        let (xf, xc) = x.split_at_mut(l + 1);
        self.mg.prolong(l, &xc[0], &mut xf[l], self.owned(l));
        Ok(())
    }

    /// Full multigrid from the owned layers of `rhs`.
    fn full_multigrid(
        &self,
        rhs: &[f64],
        b: &mut Work,
        x: &mut Work,
        s: &mut Work,
    ) -> Result<(), DiffusionError> {
        let slab = self.level(0).slab();
        let o = self.owned(0);
        for (b, r) in b[0][o.start * slab..o.end * slab]
            .iter_mut()
            .zip(&rhs[o.start * slab..])
        {
            *b = *r as f32;
        }
        let last = self.mg.levels.len() - 1;
        for l in 0..last {
            if self.owned(l).is_empty() {
                break;
            }
            let (bf, bc) = b.split_at_mut(l + 1);
            self.level(l)
                .restrict(&bf[l], self.level(l + 1), &mut bc[0], self.restricts_to(l));
            if self.hands_over(l) {
                self.hand_down(l, &mut b[l + 1])?;
            }
        }
        if !self.owned(last).is_empty() {
            x[last].fill(0.0);
            self.mg.coarsest(&b[last], &mut x[last]);
        }
        for l in (0..last).rev() {
            if self.owned(l).is_empty() {
                continue;
            }
            self.zero(l, &mut x[l]);
            self.prolong(l, x)?;
            self.cycle(l, self.mg.settings().cycle, b, x, s)?;
        }
        Ok(())
    }
}

/// A norm's reduction: the norm, whether any rank's clock ran out, whether any rank was
/// cancelled.
struct Gathered {
    norm: f64,
    time_up: bool,
    cancelled: bool,
}

impl Multigrid {
    /// Whether `layout` splits this hierarchy over `ranks` ranks as a stage layout must:
    /// stages cover the levels in order, the last on one rank; each stage's ranks (no more
    /// than `ranks`, no more than its predecessor's) cover its first level's layers in
    /// order, bounds multiples of 2^levels but the last.
    fn check_layout(&self, layout: &RankLayout, ranks: usize) -> Result<(), DiffusionError> {
        let invalid = |why: &str| {
            Err(DiffusionError::Invalid(format!(
                "a rank layout whose {why} ({layout:?} for {} levels on {ranks} ranks)",
                self.levels.len()
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
            let n = self.levels[level].dims[2];
            let unit = 1usize << stage.levels.min(usize::BITS as usize - 1);
            let mut at = 0;
            for &(k0, k1) in &stage.layers {
                if k0 != at || k1 <= k0 || (!last && k1 != n && k1 % unit != 0) {
                    return invalid("slabs do not cover a level in whole units");
                }
                at = k1;
            }
            if at != n {
                return invalid("slabs do not cover a level");
            }
            previous = p;
            level += stage.levels;
            if level > self.levels.len() {
                return invalid("stages run past the coarsest level");
            }
        }
        if level != self.levels.len() {
            return invalid("stages do not reach the coarsest level");
        }
        if self.settings().cycle == Cycle::K
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
        let dims: Vec<[usize; 3]> = self.levels.iter().map(|l| l.dims).collect();
        RankLayout::new(&dims, ranks, self.settings().cycle, coarse_cells_per_rank)
    }

    /// [`Multigrid::solve`] on the ranks of `comm`, every rank calling it with the whole
    /// `rhs` (this rank reads its slab of it). `phi` is the initial guess (ignored under
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
        let on = OnRanks {
            mg: self,
            comm,
            layout,
            rank: comm.rank(),
        };
        let started = std::time::Instant::now();
        let fine = self.fine();
        let slab = fine.slab();
        let o = on.owned(0);
        let owned = o.start * slab..o.end * slab;
        // Σ of every rank's exact run sums, with every rank's flags: the serial norm's bits.
        let gather = |sum: ExactSum| -> Result<Gathered, DiffusionError> {
            let flags = stopping.local_flags(started);
            let (flags, sums) = all_reduce_sums(comm, &flags, &[sum])
                .ok_or_else(|| protocol(on.rank, "a norm's reduction"))?;
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
            progress: if on.rank == 0 {
                stopping.progress.clone()
            } else {
                None
            },
            ..stopping.clone()
        };
        let b_norm = gather(fine.squares_layers(rhs, o.clone()))?
            .norm
            .max(f64::MIN_POSITIVE);
        let (mut b, mut x, mut s) = self.work();
        if self.settings().full_multigrid {
            on.full_multigrid(rhs, &mut b, &mut x, &mut s)?;
            for (p, x) in phi[owned.clone()].iter_mut().zip(&x[0][owned.clone()]) {
                *p = f64::from(*x);
            }
        }
        let mut r = vec![0.0f64; n];
        let true_residual = |phi: &mut [f64], r: &mut [f64]| -> Result<ExactSum, DiffusionError> {
            on.halo(0, phi, |v| v, |v| v, |_| ())?;
            Ok(fine.residual_layers(rhs, phi, r, o.clone()))
        };
        let mut gathered = gather(true_residual(phi, &mut r)?)?;
        let to_b = |b: &mut [f32], r: &[f64]| {
            for (b, r) in b[owned.clone()].iter_mut().zip(&r[owned.clone()]) {
                *b = *r as f32;
            }
        };
        to_b(&mut b[0], &r);
        let mut residuals = vec![gathered.norm / b_norm];
        let initial = residuals[0];
        let stop_reason = loop {
            let iteration = residuals.len() - 1;
            let norm = gathered.norm;
            if let Some(reason) = shared.verdict(iteration, norm / b_norm, norm, initial, started) {
                if !reason.is_converged() {
                    break reason;
                }
                gathered = gather(true_residual(phi, &mut r)?)?;
                let norm = gathered.norm;
                *residuals.last_mut().unwrap_or(&mut 0.0) = norm / b_norm;
                if let Some(reason) = shared
                    .verdict(iteration, norm / b_norm, norm, initial, started)
                    .filter(|r| r.is_converged())
                {
                    break reason;
                }
                to_b(&mut b[0], &r);
            }
            let relative = norm / b_norm;
            if gathered.time_up {
                break StopReason::TimeLimit { residual: relative };
            }
            if gathered.cancelled {
                break StopReason::Interrupted { residual: relative };
            }
            on.zero(0, &mut x[0]);
            on.cycle(0, self.settings().cycle, &mut b, &mut x, &mut s)?;
            on.halo32(0, &mut x[0])?;
            gathered = gather(fine.correct_layers(&x[0], phi, &mut r, &mut b[0], o.clone()))?;
            residuals.push(gathered.norm / b_norm);
        };
        let whole = comm.all_gather(&phi[owned]);
        if whole.len() != n {
            return Err(protocol(on.rank, "the solution's gather"));
        }
        phi.copy_from_slice(&whole);
        Ok(Convergence {
            residuals,
            stop_reason,
        })
    }
}
