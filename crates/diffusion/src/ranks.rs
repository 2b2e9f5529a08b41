//! Multigrid on ranks: the hierarchy split into z-slabs, one per rank, on the finer levels,
//! and gathered onto every rank below them.
//!
//! **Layout** ([`RankLayout`]). The fine level's z-layers are cut into runs of whole units
//! of 2^d layers, balanced by units, so the slab bounds stay whole layers on each of the
//! d distributed levels (level l owns layers [k₀/2^l, ⌈k₁/2^l⌉)): a coarse cell's eight
//! children are on its rank, and restriction and constant prolongation need no halo. d is
//! the largest with P·2^d ≤ n_z (every rank keeps two layers or more on level d − 1), at
//! most depth − 1; the K-cycle distributes the fine level only (its coarse Krylov steps
//! run on the gathered levels).
//!
//! **A cycle on a distributed level** (as [`Multigrid`]'s, the same arithmetic per cell):
//! - red–black Gauss–Seidel: each colour starts by sending the slab's first and last
//!   layers to the neighbours and sweeping the layers between them while the layers
//!   travel, then sweeps the two boundary layers with the received halo; weighted Jacobi
//!   likewise;
//! - the residual's restriction after one halo exchange; trilinear prolongation after one
//!   on the coarse level (constant prolongation needs none);
//! - on level d, the restricted right-hand side is all-gathered, and every rank runs the
//!   serial cycle below (replicated: each rank receives level d's n/8^d values and no
//!   rank waits for another's coarse solve; the agglomeration AMReX and HPGMG do onto
//!   fewer ranks, here onto all).
//!
//! **Norms** are Σ r² per fine layer, all-gathered and added one layer at a time in z
//! order, so the residual history, the stopping decision and φ are the same bits on every
//! rank count (tested on 1–5 ranks). [`Multigrid::solve`] groups its norm differently
//! (the spans' sums, then the cells outside them), so the history may differ in the last
//! bits and a tolerance be crossed one cycle apart; φ has been the serial bits in every
//! case tested (`tests/ranks.rs` asserts 1e-10 and ± 1 cycle). The time budget and cancellation are each rank's own and
//! travel with each gather, so all ranks stop on the same cycle.
//!
//! **Not yet.** Every rank holds the whole hierarchy and full-length work vectors (it
//! touches only its slabs and their halos), so memory does not scale with ranks.

use std::ops::Range;

use lucent_core::ranks::{Communicator, exchange};
use lucent_core::{StopReason, Stopping};

use crate::error::DiffusionError;
use crate::level::Level;
use crate::multigrid::{Convergence, Cycle, Multigrid, Smoother, Work};

/// How a hierarchy is split over ranks.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RankLayout {
    /// Levels split into z-slabs, finest first; the coarser ones are gathered onto every
    /// rank.
    pub distributed_levels: usize,
    /// Per rank, its fine z-layers [k₀, k₁).
    pub layers: Vec<(usize, usize)>,
}

impl RankLayout {
    /// The layout of a hierarchy of `depth` levels over `n_z` fine layers on `ranks` ranks.
    ///
    /// # Errors
    /// [`DiffusionError::Ranks`] for no ranks or more ranks than layers.
    pub fn new(
        n_z: usize,
        depth: usize,
        ranks: usize,
        cycle: Cycle,
    ) -> Result<Self, DiffusionError> {
        if ranks == 0 || ranks > n_z {
            return Err(DiffusionError::Ranks(format!(
                "{ranks} ranks for {n_z} z-layers: every rank needs at least one layer"
            )));
        }
        let mut d = 0;
        while d + 1 < depth && ranks << (d + 1) <= n_z {
            d += 1;
        }
        if cycle == Cycle::K {
            d = d.min(1);
        }
        let unit = 1usize << d;
        let units = n_z.div_ceil(unit);
        let layers = (0..ranks)
            .map(|r| {
                let (u0, u1) = (r * units / ranks, (r + 1) * units / ranks);
                (u0 * unit, (u1 * unit).min(n_z))
            })
            .collect();
        Ok(Self {
            distributed_levels: d,
            layers,
        })
    }

    /// Rank `rank`'s layers on level `level` (< `distributed_levels`).
    pub fn owned(&self, rank: usize, level: usize) -> Range<usize> {
        let (k0, k1) = self.layers[rank];
        (k0 >> level)..(k1 + (1 << level) - 1) >> level
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

impl<C: Communicator + ?Sized> OnRanks<'_, C> {
    fn level(&self, l: usize) -> &Level {
        &self.mg.levels[l]
    }

    fn distributed(&self, l: usize) -> bool {
        l < self.layout.distributed_levels
    }

    /// The layers of level `l` this rank computes: its slab on distributed levels, all of
    /// them on gathered ones.
    fn owned(&self, l: usize) -> Range<usize> {
        if self.distributed(l) {
            self.layout.owned(self.rank, l)
        } else {
            self.level(l).all_layers()
        }
    }

    /// Sends the first and last owned layers of `x` (level `l`) to the neighbours, runs
    /// `interior` on `x` while they travel, and writes what the neighbours sent into the
    /// halo layers.
    fn halo<T: Copy, R>(
        &self,
        l: usize,
        x: &mut [T],
        to_f64: fn(T) -> f64,
        from_f64: fn(f64) -> T,
        interior: impl FnOnce(&mut [T]) -> R,
    ) -> Result<R, DiffusionError> {
        let slab = self.level(l).slab();
        let nz = self.level(l).dims[2];
        let o = self.owned(l);
        let has_below = o.start > 0;
        let has_above = o.end < nz;
        let layer = |k: usize, x: &[T]| -> Vec<f64> {
            x[k * slab..(k + 1) * slab]
                .iter()
                .map(|&v| to_f64(v))
                .collect()
        };
        let to_below = if has_below {
            layer(o.start, x)
        } else {
            Vec::new()
        };
        let to_above = if has_above {
            layer(o.end - 1, x)
        } else {
            Vec::new()
        };
        let (from_below, from_above, out) =
            exchange(self.comm, &to_below, &to_above, || interior(&mut *x));
        let expected = |present: bool| if present { slab } else { 0 };
        if from_below.len() != expected(has_below) || from_above.len() != expected(has_above) {
            return Err(protocol(self.rank, "a halo"));
        }
        if has_below {
            for (x, v) in x[(o.start - 1) * slab..o.start * slab]
                .iter_mut()
                .zip(from_below)
            {
                *x = from_f64(v);
            }
        }
        if has_above {
            for (x, v) in x[o.end * slab..(o.end + 1) * slab]
                .iter_mut()
                .zip(from_above)
            {
                *x = from_f64(v);
            }
        }
        Ok(out)
    }

    fn halo32(&self, l: usize, x: &mut [f32]) -> Result<(), DiffusionError> {
        self.halo(l, x, f64::from, |v| v as f32, |_| ())
    }

    /// Zeroes level `l`'s vector where this rank reads it: its slab and halos on a
    /// distributed level (the rest is never read), all of it on a gathered one.
    fn zero(&self, l: usize, x: &mut [f32]) {
        let o = self.owned(l);
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

    /// The pre- or post-smoothing sweeps on distributed level `l`.
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

    /// Gathers the owned layers of `v` (level `l`, the first gathered level) onto every
    /// rank.
    fn gather_level(&self, l: usize, v: &mut [f32]) -> Result<(), DiffusionError> {
        let level = self.level(l);
        let slab = level.slab();
        let o = self.layout.owned(self.rank, l);
        let local: Vec<f64> = v[o.start * slab..o.end * slab]
            .iter()
            .map(|&x| f64::from(x))
            .collect();
        let all = self.comm.all_gather(&local);
        if all.len() != v.len() {
            return Err(protocol(self.rank, "a coarse level's gather"));
        }
        for (v, a) in v.iter_mut().zip(all) {
            *v = a as f32;
        }
        Ok(())
    }

    /// One cycle on level `l` for A x = b (x holds the initial guess on the owned layers).
    fn cycle(
        &self,
        l: usize,
        cycle: Cycle,
        b: &mut Work,
        x: &mut Work,
        s: &mut Work,
    ) -> Result<(), DiffusionError> {
        if !self.distributed(l) {
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
                self.layout.owned(self.rank, l + 1),
            );
        }
        if !self.distributed(l + 1) {
            self.gather_level(l + 1, &mut b[l + 1])?;
        }
        self.zero(l + 1, &mut x[l + 1]);
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
            // The layout keeps the K-cycle's coarse levels gathered.
            Cycle::K => self.mg.krylov_correction(l + 1, b, x, s),
        }
        self.prolong(l, x)?;
        self.smooth(l, &b[l], &mut x[l], &mut s[l], true)
    }

    /// x[l] += the prolonged x[l + 1], on the owned layers of `l`.
    fn prolong(&self, l: usize, x: &mut Work) -> Result<(), DiffusionError> {
        let trilinear =
            self.mg.settings().prolongation == crate::multigrid::Prolongation::Trilinear;
        if trilinear && self.distributed(l + 1) {
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
            let (bf, bc) = b.split_at_mut(l + 1);
            // From a distributed level, the coarse layers of this rank's slab (gathered
            // below if the coarse level is not distributed).
            let coarse_layers = if self.distributed(l) {
                self.layout.owned(self.rank, l + 1)
            } else {
                self.level(l + 1).all_layers()
            };
            self.level(l)
                .restrict(&bf[l], self.level(l + 1), &mut bc[0], coarse_layers);
            if self.distributed(l) && !self.distributed(l + 1) {
                self.gather_level(l + 1, &mut b[l + 1])?;
            }
        }
        x[last].fill(0.0);
        self.mg.coarsest(&b[last], &mut x[last]);
        for l in (0..last).rev() {
            self.zero(l, &mut x[l]);
            self.prolong(l, x)?;
            self.cycle(l, self.mg.settings().cycle, b, x, s)?;
        }
        Ok(())
    }
}

/// What each gather carries besides the layer sums: whether any rank's clock ran out, or
/// any rank was cancelled.
struct Gathered {
    norm: f64,
    time_up: bool,
    cancelled: bool,
}

impl Multigrid {
    /// How [`Multigrid::solve_on_ranks`] splits this hierarchy over `ranks` ranks.
    ///
    /// # Errors
    /// [`DiffusionError::Ranks`] for no ranks or more ranks than z-layers.
    pub fn rank_layout(&self, ranks: usize) -> Result<RankLayout, DiffusionError> {
        RankLayout::new(
            self.fine().dims[2],
            self.depth(),
            ranks,
            self.settings().cycle,
        )
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
            layout: self.rank_layout(comm.size())?,
            rank: comm.rank(),
        };
        let started = std::time::Instant::now();
        let fine = self.fine();
        let slab = fine.slab();
        let o = on.owned(0);
        let owned = o.start * slab..o.end * slab;
        let counts: Vec<usize> = (0..comm.size())
            .map(|r| {
                let (k0, k1) = on.layout.layers[r];
                k1 - k0
            })
            .collect();
        // Σ of the gathered layer sums in z order, with every rank's flags.
        let gather = |layer_sums: &[f64]| -> Result<Gathered, DiffusionError> {
            let s = &stopping;
            let mut local = vec![
                f64::from(u8::from(
                    s.time_budget.is_some_and(|t| started.elapsed() >= t),
                )),
                f64::from(u8::from(
                    s.cancel
                        .as_ref()
                        .is_some_and(|c| c.load(std::sync::atomic::Ordering::Relaxed)),
                )),
            ];
            local.extend_from_slice(layer_sums);
            let all = comm.all_gather(&local);
            if all.len() != counts.iter().map(|c| c + 2).sum::<usize>() {
                return Err(protocol(on.rank, "a norm's gather"));
            }
            let mut g = Gathered {
                norm: 0.0,
                time_up: false,
                cancelled: false,
            };
            let mut at = 0;
            for &c in &counts {
                g.time_up |= all[at] != 0.0;
                g.cancelled |= all[at + 1] != 0.0;
                // One layer at a time, so the grouping does not depend on the ranks.
                for layer in &all[at + 2..at + 2 + c] {
                    g.norm += layer;
                }
                at += 2 + c;
            }
            g.norm = g.norm.sqrt();
            Ok(g)
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
        let rhs_layers: Vec<f64> = rhs[owned.clone()]
            .chunks(slab)
            .map(|l| l.iter().map(|v| v * v).sum())
            .collect();
        let b_norm = gather(&rhs_layers)?.norm.max(f64::MIN_POSITIVE);
        let (mut b, mut x, mut s) = self.work();
        if self.settings().full_multigrid {
            on.full_multigrid(rhs, &mut b, &mut x, &mut s)?;
            for (p, x) in phi[owned.clone()].iter_mut().zip(&x[0][owned.clone()]) {
                *p = f64::from(*x);
            }
        }
        let mut r = vec![0.0f64; n];
        let true_residual = |phi: &mut [f64], r: &mut [f64]| -> Result<Vec<f64>, DiffusionError> {
            on.halo(0, phi, |v| v, |v| v, |_| ())?;
            Ok(fine.residual_layers(rhs, phi, r, o.clone()))
        };
        let mut gathered = gather(&true_residual(phi, &mut r)?)?;
        // The residual outside the medium's spans, which no correction changes.
        let outside = fine.outside_layers(&r, o.clone());
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
                gathered = gather(&true_residual(phi, &mut r)?)?;
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
            let spans = fine.correct_layers(&x[0], phi, &mut r, &mut b[0], o.clone());
            let layers: Vec<f64> = spans.iter().zip(&outside).map(|(s, o)| s + o).collect();
            gathered = gather(&layers)?;
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
