//! One level of the discrete operator, stored matrix-free as face couplings, and the kernels
//! that run on it: matrix–vector products, residuals, red–black Gauss–Seidel and weighted
//! Jacobi sweeps, and the transfers between levels.
//!
//! The operator is the integrated (conservative) form of −∇·(D∇φ) + σ_a φ over each cell:
//!
//! (Aφ)_i = d_i φ_i − Σ_f c_f φ_{j(f)},  d_i = Σ_f c_f + σ_a κ_i V + Σ_patches b_p,
//!
//! with c_f = α_f A_f D_f / h the coupling through face f (aperture α_f, area A_f, harmonic
//! mean D_f of the two cells' D) and b_p the boundary patches' couplings. A is a symmetric
//! M-matrix. Each cell stores the coupling through its *low* face on each axis (zero on the
//! box), so a row reads c[g] and c[g + stride] for its two faces on an axis.
//!
//! Cells with d_i = 0 (outside the medium) have no couplings, so they are not unknowns: each
//! row stores the span between its first and last cell in the medium, and the sweeps,
//! transfers and corrections run on the spans only (a sphere fills 47 % of its box; measured
//! in one process against full rows at 128³ on 2 cores: a sweep 7.0 → 5.1 ms, a solve to 1e-8
//! 0.43 → 0.32 s, best of 100 and 20 alternating runs).
//!
//! Storage is f32 (5 arrays: three couplings, the diagonal and its inverse); sweeps run in
//! parallel over z-slabs. Red–black Gauss–Seidel is one wavefront over the slabs (red on
//! slab k, then black on slab k − 1, so each slab's operator is read once per sweep), cut
//! into chunks of equal work, one task each, whose boundary slabs are done in separate
//! passes ([`Level::sor`]). The result equals a plain red sweep followed by a black sweep.

use std::ops::Range;

use glam::DVec3;
use lucent_core::exact::{ExactSum, add_run_squares};
use rayon::prelude::*;

use crate::region::Region;

/// Two exact sums merged (the reductions' combining step: exact, so in any order).
fn merged(mut a: ExactSum, b: ExactSum) -> ExactSum {
    a.merge(&b);
    a
}

/// A level's operator.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Level {
    pub(crate) dims: [usize; 3],
    pub(crate) spacing: DVec3,
    /// Coupling through each cell's low x, y and z face (0 on the box and where closed).
    pub(crate) couplings: [Vec<f32>; 3],
    /// The diagonal d_i (0 for cells outside the medium).
    pub(crate) diag: Vec<f32>,
    /// The diagonal's part that is not a face coupling: absorption and boundary couplings.
    pub(crate) extra: Vec<f32>,
    /// 1/d_i, or 0 outside the medium.
    pub(crate) inv_diag: Vec<f32>,
    /// Per row (index j + ny k), the cells lo..hi between the row's first and last cell in
    /// the medium ([0, 0] for a row without any): the kernels that update or restrict run
    /// on these cells only.
    spans: Vec<[u32; 2]>,
    /// The parity of the sum of this grid's first cell's coordinates in the whole level (0
    /// for a whole level; a rank's box stored alone may start on a black cell): a cell's
    /// colour is that of i + j + k + parity.
    parity: usize,
}

impl Level {
    /// A level from its operator; finds each row's span of cells in the medium.
    pub(crate) fn new(
        dims: [usize; 3],
        spacing: DVec3,
        couplings: [Vec<f32>; 3],
        diag: Vec<f32>,
        extra: Vec<f32>,
        inv_diag: Vec<f32>,
    ) -> Self {
        let spans = inv_diag
            .chunks(dims[0].max(1))
            .map(|row| {
                let Some(lo) = row.iter().position(|&d| d != 0.0) else {
                    return [0, 0];
                };
                let hi = row.iter().rposition(|&d| d != 0.0).unwrap_or(lo) + 1;
                [lo as u32, hi as u32]
            })
            .collect();
        Self {
            dims,
            spacing,
            couplings,
            diag,
            extra,
            inv_diag,
            spans,
            parity: 0,
        }
    }

    /// The operator on the cells `origin + [0, dims)` of this level, as a level of its own
    /// (a rank's box and the halo around it). Each cell keeps its couplings, so a cell whose
    /// neighbours are all in the box, or in its halo, has the same row as here; a cell on
    /// the box's edge of the grid is on the edge of this one too.
    pub(crate) fn extract(&self, origin: [usize; 3], dims: [usize; 3]) -> Level {
        let region = Region::new(std::array::from_fn(|a| origin[a]..origin[a] + dims[a]));
        let cut = |v: &[f32]| region.cut(self.dims, v);
        let parity = (self.parity + origin.iter().sum::<usize>()) % 2;
        let level = Level::new(
            dims,
            self.spacing,
            [
                cut(&self.couplings[0]),
                cut(&self.couplings[1]),
                cut(&self.couplings[2]),
            ],
            cut(&self.diag),
            cut(&self.extra),
            cut(&self.inv_diag),
        );
        Level { parity, ..level }
    }

    /// This level as the frame of a level from cell `origin` on (a rank's box and the halo
    /// around it, built where it is held): the colours follow the whole level's, as
    /// [`Level::extract`]'s do.
    pub(crate) fn framed(self, origin: [usize; 3]) -> Level {
        let parity = (self.parity + origin.iter().sum::<usize>()) % 2;
        Level { parity, ..self }
    }

    /// Row j of slab k: the span lo..hi of its cells that are in the medium.
    #[inline(always)]
    fn span(&self, j: usize, k: usize) -> (usize, usize) {
        let [lo, hi] = self.spans[j + self.dims[1] * k];
        (lo as usize, hi as usize)
    }

    /// Cells the sweeps visit: the rows' spans.
    pub(crate) fn swept_cells(&self) -> usize {
        self.spans.iter().map(|[lo, hi]| (hi - lo) as usize).sum()
    }

    /// Σ v² over `region` as the solves' norms sum it: every x-line cut into runs of
    /// `NORM_RUN` cells (`lucent_core::exact`), each run left to right, the run sums added
    /// exactly. The bits depend on the grid alone, never on the threads, nor on how the
    /// level is split over ranks, as long as each region starts its x-lines at a multiple
    /// of `NORM_RUN` (each rank's sum then holds whole runs, and merges exactly).
    pub(crate) fn squares_in(&self, v: &[f64], region: &Region) -> ExactSum {
        let slab = self.slab();
        let z = region.z();
        v[z.start * slab..z.end * slab]
            .par_chunks(slab.max(1))
            .with_min_len(self.slabs_per_task())
            .fold(ExactSum::new, |mut sum, v| {
                self.add_region_squares(v, region, &mut sum);
                sum
            })
            .reduce(ExactSum::new, merged)
    }

    /// Adds the squares of one slab's values in `region`'s rows and columns to `sum`, in
    /// runs of `NORM_RUN` from the region's first column.
    fn add_region_squares(&self, slab: &[f64], region: &Region, sum: &mut ExactSum) {
        let nx = self.dims[0];
        let x = region.x();
        if x == (0..nx) {
            let y = region.y();
            add_run_squares(&slab[y.start * nx..y.end * nx], nx, sum);
            return;
        }
        for j in region.y() {
            add_run_squares(&slab[x.start + nx * j..x.end + nx * j], x.len(), sum);
        }
    }

    /// ‖v‖₂ by [`Level::squares_in`] over every cell.
    pub(crate) fn norm(&self, v: &[f64]) -> f64 {
        self.squares_in(v, &self.whole()).value().sqrt()
    }

    /// Every cell of the level.
    pub(crate) fn whole(&self) -> Region {
        Region::whole(self.dims)
    }
    pub(crate) fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    pub(crate) fn slab(&self) -> usize {
        self.dims[0] * self.dims[1]
    }

    /// Slabs per task of the parallel loops over slabs (at least [`PARALLEL_MIN_CELLS`]).
    fn slabs_per_task(&self) -> usize {
        PARALLEL_MIN_CELLS.div_ceil(self.slab().max(1))
    }

    /// Σ_f c_f (x_i − x_{j(f)}) in f64 for cell g = (i, j, k) of slab-local index l, with
    /// the slab's own values in `x` and the slabs below and above: the flux form, which
    /// keeps the tiny absorption term from drowning in a rounded diagonal.
    #[inline(always)]
    fn outflow<T: Copy + Into<f64>>(
        &self,
        g: usize,
        l: usize,
        [i, j]: [usize; 2],
        x: &[T],
        below: Option<&[T]>,
        above: Option<&[T]>,
    ) -> f64 {
        let [nx, ny, _] = self.dims;
        let slab = nx * ny;
        let [cx, cy, cz] = &self.couplings;
        let xi: f64 = x[l].into();
        let mut s = 0.0f64;
        if i > 0 {
            s += f64::from(cx[g]) * (xi - x[l - 1].into());
        }
        if i + 1 < nx {
            s += f64::from(cx[g + 1]) * (xi - x[l + 1].into());
        }
        if j > 0 {
            s += f64::from(cy[g]) * (xi - x[l - nx].into());
        }
        if j + 1 < ny {
            s += f64::from(cy[g + nx]) * (xi - x[l + nx].into());
        }
        if let Some(b) = below {
            s += f64::from(cz[g]) * (xi - b[l].into());
        }
        if let Some(a) = above {
            s += f64::from(cz[g + slab]) * (xi - a[l].into());
        }
        s
    }

    /// [`Level::neighbours`] in the arithmetic of the vectors (f32 in the cycles, f64 in the
    /// baselines).
    #[inline(always)]
    fn neighbour_sum<T: Real>(
        &self,
        g: usize,
        l: usize,
        [i, j]: [usize; 2],
        x: &[T],
        below: Option<&[T]>,
        above: Option<&[T]>,
    ) -> T {
        let [nx, ny, _] = self.dims;
        let slab = nx * ny;
        let [cx, cy, cz] = &self.couplings;
        let c = |v: f32| T::from(v);
        let mut s = T::default();
        if i > 0 {
            s += c(cx[g]) * x[l - 1];
        }
        if i + 1 < nx {
            s += c(cx[g + 1]) * x[l + 1];
        }
        if j > 0 {
            s += c(cy[g]) * x[l - nx];
        }
        if j + 1 < ny {
            s += c(cy[g + nx]) * x[l + nx];
        }
        if let Some(b) = below {
            s += c(cz[g]) * b[l];
        }
        if let Some(a) = above {
            s += c(cz[g + slab]) * a[l];
        }
        s
    }

    /// Σ_f c_f of cell g = (i, j, k) in the vectors' arithmetic.
    #[inline(always)]
    fn coupling_sum<T: Real>(&self, g: usize, [i, j, k]: [usize; 3]) -> T {
        let [nx, ny, nz] = self.dims;
        let slab = nx * ny;
        let [cx, cy, cz] = &self.couplings;
        let mut s = T::from(cx[g]) + T::from(cy[g]) + T::from(cz[g]);
        if i + 1 < nx {
            s += T::from(cx[g + 1]);
        }
        if j + 1 < ny {
            s += T::from(cy[g + nx]);
        }
        if k + 1 < nz {
            s += T::from(cz[g + slab]);
        }
        s
    }

    /// y = A x in f64 (x may be f32 or f64).
    pub(crate) fn apply<T: Copy + Into<f64> + Sync>(&self, x: &[T], y: &mut [f64]) {
        self.apply_then(x, y, &self.whole(), |_, _| ())
            .for_each(drop);
    }

    /// r = b − A x in f64, in one pass; returns ‖r‖₂ (summed as [`Level::norm`]).
    pub(crate) fn residual<T: Copy + Into<f64> + Sync>(
        &self,
        b: &[f64],
        x: &[T],
        r: &mut [f64],
    ) -> f64 {
        self.residual_in(b, x, r, &self.whole()).value().sqrt()
    }

    /// r = b − A x on `region` (reading x on the cells next to it too); returns Σ r² over
    /// it (as [`Level::squares_in`]).
    pub(crate) fn residual_in<T: Copy + Into<f64> + Sync>(
        &self,
        b: &[f64],
        x: &[T],
        r: &mut [f64],
        region: &Region,
    ) -> ExactSum {
        let slab = self.slab();
        let nx = self.dims[0];
        let cols = region.x();
        self.apply_then(x, r, region, move |k, rs| {
            for j in region.y() {
                let row = cols.start + nx * j..cols.end + nx * j;
                for (r, b) in rs[row.clone()].iter_mut().zip(&b[k * slab + row.start..]) {
                    *r = b - *r;
                }
            }
            let mut sum = ExactSum::new();
            self.add_region_squares(rs, region, &mut sum);
            sum
        })
        .reduce(ExactSum::new, merged)
    }

    /// y = A x on `region`, each of its slabs then passed to `then(k, y_slab)` while it is
    /// in cache; what `then` returns, per slab, as a parallel iterator.
    fn apply_then<'a, T: Copy + Into<f64> + Sync, R: Send>(
        &'a self,
        x: &'a [T],
        y: &'a mut [f64],
        region: &'a Region,
        then: impl Fn(usize, &mut [f64]) -> R + Sync + Send + 'a,
    ) -> impl ParallelIterator<Item = R> + 'a {
        let slab = self.slab();
        let z = region.z();
        y[z.start * slab..z.end * slab]
            .par_chunks_mut(slab)
            .with_min_len(self.slabs_per_task())
            .enumerate()
            .map(move |(i, y)| {
                let k = region.axes[2].start + i;
                self.apply_slab(k, x, y, region);
                then(k, y)
            })
    }

    /// Row j of slab k: the span of its cells in the medium, clipped to the columns `x`
    /// (empty where they do not meet).
    #[inline(always)]
    fn span_within(&self, j: usize, k: usize, x: &Range<usize>) -> (usize, usize) {
        let (lo, hi) = self.span(j, k);
        let lo = lo.clamp(x.start, x.end);
        (lo, hi.min(x.end).max(lo))
    }

    /// Slab k of A x into `y` (one slab long) on `region`'s rows and columns: computed on
    /// the rows' spans, 0 outside them (exactly what A gives there: those cells have no
    /// couplings); `y` outside the region is left as it is.
    fn apply_slab<T: Copy + Into<f64>>(&self, k: usize, x: &[T], y: &mut [f64], region: &Region) {
        let slab = self.slab();
        let nz = self.dims[2];
        let xs = &x[k * slab..(k + 1) * slab];
        let below = (k > 0).then(|| &x[(k - 1) * slab..k * slab]);
        let above = (k + 1 < nz).then(|| &x[(k + 1) * slab..(k + 2) * slab]);
        let [nx, ny, _] = self.dims;
        let general = |i: usize, j: usize| {
            let l = i + nx * j;
            let g = k * slab + l;
            f64::from(self.extra[g]) * xs[l].into() + self.outflow(g, l, [i, j], xs, below, above)
        };
        let cols = region.x();
        for j in region.y() {
            let row = &mut y[nx * j..nx * (j + 1)];
            let (lo, hi) = self.span_within(j, k, &cols);
            row[cols.start..lo].fill(0.0);
            row[hi..cols.end].fill(0.0);
            let (from, to) = (lo.max(1), hi.min(nx - 1));
            let (Some(down), Some(up), true) = (below, above, j > 0 && j + 1 < ny && from < to)
            else {
                for i in lo..hi {
                    row[i] = general(i, j);
                }
                continue;
            };
            for i in (lo..from).chain(to..hi) {
                row[i] = general(i, j);
            }
            let l = from + nx * j;
            self.interior_apply(k * slab + l, l, xs, down, up, &mut row[from..to]);
        }
    }

    /// Applies a correction e in one pass over the rows' spans: φ += e, r −= A e (the
    /// residual of φ updated without recomputing A φ) and b = r in f32 for the next cycle;
    /// returns ‖r‖₂ (summed as [`Level::norm`]; outside the spans e = 0 and A e = 0, so r
    /// keeps its value there and counts as it is).
    pub(crate) fn correct(&self, e: &[f32], phi: &mut [f64], r: &mut [f64], b: &mut [f32]) -> f64 {
        self.correct_in(e, phi, r, b, &self.whole()).value().sqrt()
    }

    /// [`Level::correct`] on `region` (reading e on the cells next to it too); returns
    /// Σ r² over it (as [`Level::squares_in`]).
    pub(crate) fn correct_in(
        &self,
        e: &[f32],
        phi: &mut [f64],
        r: &mut [f64],
        b: &mut [f32],
        region: &Region,
    ) -> ExactSum {
        let slab = self.slab();
        let nx = self.dims[0];
        let z = region.z();
        let cols = region.x();
        let owned = z.start * slab..z.end * slab;
        phi[owned.clone()]
            .par_chunks_mut(slab)
            .zip(r[owned.clone()].par_chunks_mut(slab))
            .zip(b[owned].par_chunks_mut(slab))
            .with_min_len(self.slabs_per_task())
            .enumerate()
            .map_init(
                || vec![0.0f64; slab],
                |ae, (i, ((phi, r), b))| {
                    let k = z.start + i;
                    self.apply_slab(k, e, ae, region);
                    let es = &e[k * slab..(k + 1) * slab];
                    for j in region.y() {
                        let (lo, hi) = self.span_within(j, k, &cols);
                        for l in nx * j + lo..nx * j + hi {
                            phi[l] += f64::from(es[l]);
                            r[l] -= ae[l];
                            b[l] = r[l] as f32;
                        }
                    }
                    let mut sum = ExactSum::new();
                    self.add_region_squares(r, region, &mut sum);
                    sum
                },
            )
            .reduce(ExactSum::new, merged)
    }

    /// One red–black Gauss–Seidel sweep for A x = b, colours in the order `first`, then
    /// the other (0 = red: (i + j + k) even).
    pub(crate) fn gauss_seidel(&self, b: &[f32], x: &mut [f32], first: usize) {
        self.sor(b, x, first, 1.0);
    }

    /// One red–black SOR sweep with relaxation ω (ω = 1: Gauss–Seidel), colours in the order
    /// `first`, then the other, as a wavefront over z-slabs: the first colour on slab k,
    /// then the second on slab k − 1, so each slab's operator is read once per sweep while
    /// it is still in cache. The slabs are cut into contiguous chunks of about equal work
    /// (cells swept), at least two slabs each, one task per chunk; the chunks' boundary
    /// slabs are done in separate passes so no task writes a slab another reads:
    /// 1. the first colour on each chunk's first slab, then on its last slab;
    /// 2. each chunk's wavefront over its slabs but the last (the first colour there reads
    ///    the second colour of its neighbours before they change; the second colour on a
    ///    slab runs once the first colour is final on both neighbours);
    /// 3. the second colour on each chunk's last slab.
    ///
    /// Every update reads the values a red sweep followed by a black sweep would read, so
    /// the result is that of the plain sweep (tested). Measured against the three passes it
    /// replaced (first colour on even slabs; both on odd slabs; second on even slabs, so
    /// even slabs were read twice), in one process at 128³: a sweep 4.75 → 4.22 ms on 2
    /// threads and 8.7 → 6.9 ms on one; a solve to 1e-8 0.32 → 0.28 s (best of 100 and 20
    /// alternating runs).
    pub(crate) fn sor<T: Real>(&self, b: &[T], x: &mut [T], first: usize, omega: T) {
        let second = 1 - first;
        let slab = self.slab();
        let chunks = self.sweep_chunks();
        let whole = self.whole();
        let colour =
            |k: usize, c: usize, xs: &mut [T], below: Option<&[T]>, above: Option<&[T]>| {
                self.colour(b, k, c, omega, xs, below, above, &whole);
            };
        if chunks.len() < 2 {
            // One chunk: the whole wavefront in this thread.
            let nz = self.dims[2];
            on_slab_of_run(x, slab, 0, None, None, |xs, below, above| {
                colour(0, first, xs, below, above)
            });
            self.wavefront(x, 0, nz, None, None, first, second, &colour);
            return;
        }
        let is_first = |k: usize| chunks.iter().any(|&(k0, _)| k0 == k);
        let is_last = |k: usize| chunks.iter().any(|&(_, k1)| k1 - 1 == k);
        self.on_slabs(x, is_first, |k, xs, below, above| {
            colour(k, first, xs, below, above)
        });
        self.on_slabs(x, is_last, |k, xs, below, above| {
            colour(k, first, xs, below, above)
        });
        {
            // Per chunk its slabs but the last (mutable) and its last slab (shared: the
            // slab above its run, and below the next chunk's).
            let mut runs: Vec<(usize, usize, &mut [T])> = Vec::with_capacity(chunks.len());
            let mut lasts: Vec<&[T]> = Vec::with_capacity(chunks.len());
            let mut rest = &mut x[..];
            for &(k0, k1) in &chunks {
                let (run, tail) = rest.split_at_mut((k1 - 1 - k0) * slab);
                let (last, tail) = tail.split_at_mut(slab);
                runs.push((k0, k1 - 1, run));
                lasts.push(last);
                rest = tail;
            }
            let lasts = &lasts;
            runs.into_par_iter()
                .enumerate()
                .for_each(|(c, (k0, end, run))| {
                    let below = c.checked_sub(1).map(|p| lasts[p]);
                    self.wavefront(run, k0, end, below, Some(lasts[c]), first, second, &colour);
                });
        }
        self.on_slabs(x, is_last, |k, xs, below, above| {
            colour(k, second, xs, below, above)
        });
    }

    /// One colour (0 = red) of a red–black SOR sweep on `region` only, reading the cells
    /// next to it: the distributed sweep's half step, between halo exchanges.
    pub(crate) fn colour_in<T: Real>(
        &self,
        b: &[T],
        x: &mut [T],
        colour: usize,
        omega: T,
        region: &Region,
    ) {
        if region.is_empty() {
            return;
        }
        let z = region.z();
        if region.cells() < PARALLEL_MIN_CELLS {
            // Too little work for rayon's hand-offs (a box's face, a coarse level): the
            // slabs in turn, here.
            let slab = self.slab();
            for k in z {
                on_slab_of_run(x, slab, k, None, None, |xs, below, above| {
                    self.colour(b, k, colour, omega, xs, below, above, region);
                });
            }
            return;
        }
        // Slabs of one parity at a time, so no two written slabs are adjacent.
        for parity in 0..2 {
            self.on_slabs(
                x,
                |k| z.contains(&k) && k % 2 == parity,
                |k, xs, below, above| {
                    self.colour(b, k, colour, omega, xs, below, above, region);
                },
            );
        }
    }

    /// The wavefront over the run of slabs k0..end (`run`, mutable), with the first colour
    /// already done on slab k0, on the slab below the run (`below`) and on the slab above
    /// it (`above`): the first colour on k, then the second on k − 1, for k = k0 + 1 .. end;
    /// then the second colour on end − 1.
    #[allow(clippy::too_many_arguments)]
    fn wavefront<T: Real>(
        &self,
        run: &mut [T],
        k0: usize,
        end: usize,
        below: Option<&[T]>,
        above: Option<&[T]>,
        first: usize,
        second: usize,
        colour: &(impl Fn(usize, usize, &mut [T], Option<&[T]>, Option<&[T]>) + Sync),
    ) {
        let slab = self.slab();
        for k in k0 + 1..end {
            on_slab_of_run(run, slab, k - k0, below, above, |xs, lo, hi| {
                colour(k, first, xs, lo, hi)
            });
            on_slab_of_run(run, slab, k - 1 - k0, below, above, |xs, lo, hi| {
                colour(k - 1, second, xs, lo, hi)
            });
        }
        if end > k0 {
            on_slab_of_run(run, slab, end - 1 - k0, below, above, |xs, lo, hi| {
                colour(end - 1, second, xs, lo, hi)
            });
        }
    }

    /// The sweep's chunks of slabs (k0, k1): contiguous, about equal in cells swept (plus a
    /// row's worth per row, for the rows' overhead), at least two slabs each, two per
    /// thread where the level is deep enough; one chunk on shallow levels.
    fn sweep_chunks(&self) -> Vec<(usize, usize)> {
        let [nx, ny, nz] = self.dims;
        let wanted = (2 * rayon::current_num_threads())
            .min(nz / 4)
            .min(self.len() / PARALLEL_MIN_CELLS);
        if wanted < 2 {
            return vec![(0, nz)];
        }
        let work: Vec<usize> = (0..nz)
            .map(|k| {
                (0..ny)
                    .map(|j| {
                        let (lo, hi) = self.span(j, k);
                        hi - lo + (nx / 8).max(1)
                    })
                    .sum()
            })
            .collect();
        let total: usize = work.iter().sum();
        let mut chunks = Vec::with_capacity(wanted);
        let (mut k0, mut done) = (0, 0);
        for (k, w) in work.iter().enumerate() {
            done += w;
            let target = total * (chunks.len() + 1) / wanted;
            let left = nz - (k + 1);
            let remaining = wanted - chunks.len() - 1;
            if chunks.len() + 1 < wanted
                && k + 1 - k0 >= 2
                && done >= target
                && left >= 2 * remaining
            {
                chunks.push((k0, k + 1));
                k0 = k + 1;
            }
        }
        chunks.push((k0, nz));
        chunks
    }

    #[inline]
    #[allow(clippy::too_many_arguments)]
    fn colour<T: Real>(
        &self,
        b: &[T],
        k: usize,
        colour: usize,
        omega: T,
        x: &mut [T],
        below: Option<&[T]>,
        above: Option<&[T]>,
        region: &Region,
    ) {
        let [nx, ny, _] = self.dims;
        let base = k * nx * ny;
        let one = T::from(1.0);
        let relaxed = omega != one;
        let cols = region.x();
        for j in region.y() {
            let (lo, hi) = self.span_within(j, k, &cols);
            // Cells of the colour have i ≡ first (mod 2).
            let first = (colour + j + k + self.parity) % 2;
            let (from, to) = (lo.max(1), hi.min(nx.saturating_sub(1)));
            if let (true, Some(below), Some(above)) =
                (j > 0 && j + 1 < ny && from < to, below, above)
            {
                let row = RowSweep {
                    g0: base + nx * j,
                    l0: nx * j,
                    parity: first,
                    omega,
                };
                self.colour_row_interior(b, &row, [from, to], x, below, above);
                // The span's cells on the box (i = 0, nx − 1), by the general code.
                for i in (lo..from).chain(to..hi) {
                    if i % 2 == first {
                        self.update_cell(
                            b,
                            [i, j, k],
                            base,
                            omega,
                            relaxed,
                            x,
                            Some(below),
                            Some(above),
                        );
                    }
                }
                continue;
            }
            let mut i = if lo % 2 == first { lo } else { lo + 1 };
            while i < hi {
                self.update_cell(b, [i, j, k], base, omega, relaxed, x, below, above);
                i += 2;
            }
        }
    }

    /// The update of one cell (any position), in residual form.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn update_cell<T: Real>(
        &self,
        b: &[T],
        [i, j, k]: [usize; 3],
        base: usize,
        omega: T,
        relaxed: bool,
        x: &mut [T],
        below: Option<&[T]>,
        above: Option<&[T]>,
    ) {
        let l = i + self.dims[0] * j;
        let g = base + l;
        let s = b[g] + self.neighbour_sum(g, l, [i, j], x, below, above);
        let r = s - (T::from(self.extra[g]) + self.coupling_sum(g, [i, j, k])) * x[l];
        let step = r * T::from(self.inv_diag[g]);
        x[l] += if relaxed { omega * step } else { step };
    }

    /// A x in f64, in the flux form of [`Level::outflow`], for `out.len()` consecutive
    /// cells from level index `g` (slab index `l`) that all have their six neighbours.
    #[inline(always)]
    fn interior_apply<T: Copy + Into<f64>>(
        &self,
        g: usize,
        l: usize,
        x: &[T],
        below: &[T],
        above: &[T],
        out: &mut [f64],
    ) {
        let len = out.len();
        let [nx, ny, _] = self.dims;
        let slab = nx * ny;
        let [cx, cy, cz] = &self.couplings;
        let (west, east) = (&x[l - 1..l - 1 + len], &x[l + 1..l + 1 + len]);
        let (south, north) = (&x[l - nx..l - nx + len], &x[l + nx..l + nx + len]);
        let (down, up) = (&below[l..l + len], &above[l..l + len]);
        let centre = &x[l..l + len];
        let (cw, ce) = (&cx[g..g + len], &cx[g + 1..g + 1 + len]);
        let (cs, cn) = (&cy[g..g + len], &cy[g + nx..g + nx + len]);
        let (cd, cu) = (&cz[g..g + len], &cz[g + slab..g + slab + len]);
        let extra = &self.extra[g..g + len];
        let f = f64::from;
        for t in 0..len {
            let xi: f64 = centre[t].into();
            out[t] = f(extra[t]) * xi
                + f(cw[t]) * (xi - west[t].into())
                + f(ce[t]) * (xi - east[t].into())
                + f(cs[t]) * (xi - south[t].into())
                + f(cn[t]) * (xi - north[t].into())
                + f(cd[t]) * (xi - down[t].into())
                + f(cu[t]) * (xi - up[t].into());
        }
    }

    /// The residual b − A x of `out.len()` consecutive cells from level index `g` (slab
    /// index `l`), all of which have their six neighbours (no box face among them): straight
    /// loads from contiguous slices, so that it vectorises. Residual form, as in
    /// [`Level::update_cell`].
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn interior_residuals<T: Real>(
        &self,
        b: &[T],
        g: usize,
        l: usize,
        x: &[T],
        below: &[T],
        above: &[T],
        out: &mut [T],
    ) {
        let len = out.len();
        let [nx, ny, _] = self.dims;
        let slab = nx * ny;
        let [cx, cy, cz] = &self.couplings;
        let west = &x[l - 1..l - 1 + len];
        let east = &x[l + 1..l + 1 + len];
        let centre = &x[l..l + len];
        let south = &x[l - nx..l - nx + len];
        let north = &x[l + nx..l + nx + len];
        let down = &below[l..l + len];
        let up = &above[l..l + len];
        let cw = &cx[g..g + len];
        let ce = &cx[g + 1..g + 1 + len];
        let cs = &cy[g..g + len];
        let cn = &cy[g + nx..g + nx + len];
        let cd = &cz[g..g + len];
        let cu = &cz[g + slab..g + slab + len];
        let extra = &self.extra[g..g + len];
        let rhs = &b[g..g + len];
        let f = T::from;
        for t in 0..len {
            let s = rhs[t]
                + f(cw[t]) * west[t]
                + f(ce[t]) * east[t]
                + f(cs[t]) * south[t]
                + f(cn[t]) * north[t]
                + f(cd[t]) * down[t]
                + f(cu[t]) * up[t];
            let d = f(extra[t]) + f(cw[t]) + f(cs[t]) + f(cd[t]) + f(ce[t]) + f(cn[t]) + f(cu[t]);
            out[t] = s - d * centre[t];
        }
    }

    /// Cells from..to of an interior row (1 ≤ from, to ≤ nx − 1: all six neighbours
    /// present) for one colour. The update is computed for every cell of a block of the row
    /// into a buffer, from contiguous slices, so that it vectorises; then only the colour's
    /// cells are stored. That is exact: the update of one colour reads only the other
    /// colour, which does not change during it. Twice the arithmetic, half the time of the
    /// strided loop.
    #[inline(always)]
    fn colour_row_interior<T: Real>(
        &self,
        b: &[T],
        row: &RowSweep<T>,
        [from, to]: [usize; 2],
        x: &mut [T],
        below: &[T],
        above: &[T],
    ) {
        let &RowSweep {
            g0,
            l0,
            parity,
            omega,
        } = row;
        let relaxed = omega != T::from(1.0);
        if to - from < SHORT_ROW {
            // A few cells (a box's face column, a sliver of the medium): the colour's cells
            // one by one, each through the block kernel (so its arithmetic), without the
            // block's buffer.
            let mut i = if from % 2 == parity { from } else { from + 1 };
            while i < to {
                let (g, l) = (g0 + i, l0 + i);
                let mut r = [T::default()];
                self.interior_residuals(b, g, l, x, below, above, &mut r);
                let step = r[0] * T::from(self.inv_diag[g]);
                x[l] += if relaxed { omega * step } else { step };
                i += 2;
            }
            return;
        }
        let mut buffer = [T::default(); BLOCK];
        let mut start = from;
        while start < to {
            let len = BLOCK.min(to - start);
            let (g, l) = (g0 + start, l0 + start);
            self.interior_residuals(b, g, l, x, below, above, &mut buffer[..len]);
            let mut t = (start + parity) % 2;
            while t < len {
                let step = buffer[t] * T::from(self.inv_diag[g + t]);
                x[l + t] += if relaxed { omega * step } else { step };
                t += 2;
            }
            start += len;
        }
    }

    /// Runs `f(k, slab, below, above)` in parallel on the slabs k with `mine(k)`, each with
    /// mutable access to its own slab and shared access to its neighbours (no two chosen
    /// slabs may be adjacent).
    fn on_slabs<T: Real>(
        &self,
        x: &mut [T],
        mine: impl Fn(usize) -> bool,
        f: impl Fn(usize, &mut [T], Option<&[T]>, Option<&[T]>) + Sync,
    ) {
        let slab = self.slab();
        let nz = self.dims[2];
        let mut chosen = Vec::with_capacity(nz / 2 + 1);
        let mut others: Vec<Option<&[T]>> = vec![None; nz];
        for (k, s) in x.chunks_mut(slab).enumerate() {
            if mine(k) {
                chosen.push((k, s));
            } else {
                others[k] = Some(&*s);
            }
        }
        let per_task = self.slabs_per_task();
        chosen
            .into_par_iter()
            .with_min_len(per_task)
            .for_each(|(k, s)| {
                let below = if k > 0 { others[k - 1] } else { None };
                let above = others.get(k + 1).copied().flatten();
                f(k, s, below, above);
            });
    }

    /// One weighted Jacobi sweep x ← x + ω D⁻¹(b − A x), using `scratch` (len n).
    pub(crate) fn jacobi(&self, b: &[f32], x: &mut [f32], omega: f32, scratch: &mut [f32]) {
        self.jacobi_in(b, x, omega, scratch, &self.whole());
        x.copy_from_slice(scratch);
    }

    /// The weighted Jacobi update of `region` into `scratch` (x unchanged).
    pub(crate) fn jacobi_in(
        &self,
        b: &[f32],
        x: &[f32],
        omega: f32,
        scratch: &mut [f32],
        region: &Region,
    ) {
        let slab = self.slab();
        let nz = self.dims[2];
        let nx = self.dims[0];
        let z = region.z();
        scratch[z.start * slab..z.end * slab]
            .par_chunks_mut(slab)
            .enumerate()
            .for_each(|(t, out)| {
                let k = z.start + t;
                let xs = &x[k * slab..(k + 1) * slab];
                let below = (k > 0).then(|| &x[(k - 1) * slab..k * slab]);
                let above = (k + 1 < nz).then(|| &x[(k + 1) * slab..(k + 2) * slab]);
                for j in region.y() {
                    for i in region.x() {
                        let l = i + nx * j;
                        let g = k * slab + l;
                        let r = b[g] + self.neighbour_sum(g, l, [i, j], xs, below, above)
                            - self.diag[g] * xs[l];
                        out[l] = xs[l] + omega * self.inv_diag[g] * r;
                    }
                }
            });
    }

    /// The coarse right-hand side Σ_children (b − A x): residual and restriction in one pass,
    /// over the rows' spans. Cells outside the medium (d = 0) are not unknowns: their
    /// residual, which is their b, is not passed down (whatever b holds there).
    pub(crate) fn restrict_residual(
        &self,
        b: &[f32],
        x: &[f32],
        coarse: &Level,
        out: &mut [f32],
        coarse_region: &Region,
        o: Origins,
    ) {
        let [nx, ny, nz] = self.dims;
        let [cx, cy, _] = coarse.dims;
        let slab = nx * ny;
        let (rows, cols) = self.children(coarse_region, o);
        let z = coarse_region.z();
        out[z.start * cx * cy..z.end * cx * cy]
            .par_chunks_mut(cx * cy)
            .with_min_len(coarse.slabs_per_task())
            .enumerate()
            .for_each(|(t, out)| {
                let kc = z.start + t;
                coarse.clear_rows(out, coarse_region);
                for k in o.children(2, kc, nz) {
                    let xs = &x[k * slab..(k + 1) * slab];
                    let below = (k > 0).then(|| &x[(k - 1) * slab..k * slab]);
                    let above = (k + 1 < nz).then(|| &x[(k + 1) * slab..(k + 2) * slab]);
                    let mut buffer = [0.0f32; BLOCK];
                    for j in rows.clone() {
                        let row = o.parent(1, j) * cx;
                        let (lo, hi) = self.span_within(j, k, &cols);
                        let general = |i: usize| {
                            let l = i + nx * j;
                            let g = k * slab + l;
                            if self.inv_diag[g] == 0.0 {
                                return 0.0;
                            }
                            b[g] + self.neighbour_sum(g, l, [i, j], xs, below, above)
                                - (self.extra[g] + self.coupling_sum::<f32>(g, [i, j, k])) * xs[l]
                        };
                        let (from, to) = (lo.max(1), hi.min(nx - 1));
                        let (Some(down), Some(up), true) =
                            (below, above, j > 0 && j + 1 < ny && from < to)
                        else {
                            for i in lo..hi {
                                out[row + o.parent(0, i)] += general(i);
                            }
                            continue;
                        };
                        for i in (lo..from).chain(to..hi) {
                            out[row + o.parent(0, i)] += general(i);
                        }
                        let mut start = from;
                        while start < to {
                            let len = BLOCK.min(to - start);
                            let l = start + nx * j;
                            let r = &mut buffer[..len];
                            let g = k * slab + l;
                            self.interior_residuals(b, g, l, xs, down, up, r);
                            let medium = &self.inv_diag[g..g + len];
                            for (t, (r, d)) in r.iter().zip(medium).enumerate() {
                                if *d != 0.0 {
                                    out[row + o.parent(0, start + t)] += r;
                                }
                            }
                            start += len;
                        }
                    }
                }
            });
    }

    /// The coarse right-hand side Σ_children b: [`Level::restrict_residual`] for x = 0,
    /// without reading the operator (full multigrid's first pass down the levels).
    pub(crate) fn restrict(
        &self,
        b: &[f32],
        coarse: &Level,
        out: &mut [f32],
        coarse_region: &Region,
        o: Origins,
    ) {
        let [nx, ny, nz] = self.dims;
        let [cx, cy, _] = coarse.dims;
        let slab = nx * ny;
        let (rows, cols) = self.children(coarse_region, o);
        let z = coarse_region.z();
        out[z.start * cx * cy..z.end * cx * cy]
            .par_chunks_mut(cx * cy)
            .with_min_len(coarse.slabs_per_task())
            .enumerate()
            .for_each(|(t, out)| {
                let kc = z.start + t;
                coarse.clear_rows(out, coarse_region);
                for k in o.children(2, kc, nz) {
                    for j in rows.clone() {
                        let row = o.parent(1, j) * cx;
                        let (lo, hi) = self.span_within(j, k, &cols);
                        let g = k * slab + nx * j;
                        for i in lo..hi {
                            if self.inv_diag[g + i] != 0.0 {
                                out[row + o.parent(0, i)] += b[g + i];
                            }
                        }
                    }
                }
            });
    }

    /// The fine rows (y) and columns (x) under the coarse `region` (whole children; the
    /// last clipped to this level).
    fn children(&self, coarse_region: &Region, o: Origins) -> (Range<usize>, Range<usize>) {
        let under = |a: usize| {
            let r = &coarse_region.axes[a];
            let n = self.dims[a];
            o.children(a, r.start, n).start..o.children(a, r.end, n).start
        };
        (under(1), under(0))
    }

    /// Zeroes `region`'s rows and columns of one slab of this level.
    fn clear_rows(&self, slab: &mut [f32], region: &Region) {
        let nx = self.dims[0];
        let cols = region.x();
        for j in region.y() {
            slab[cols.start + nx * j..cols.end + nx * j].fill(0.0);
        }
    }

    /// x_fine += x_coarse of the parent (piecewise-constant prolongation), on `region`.
    pub(crate) fn prolong_add(
        &self,
        coarse: &Level,
        xc: &[f32],
        x: &mut [f32],
        region: &Region,
        o: Origins,
    ) {
        let [nx, ny, _] = self.dims;
        let [cx, cy, _] = coarse.dims;
        let z = region.z();
        let cols = region.x();
        x[z.start * nx * ny..z.end * nx * ny]
            .par_chunks_mut(nx * ny)
            .with_min_len(self.slabs_per_task())
            .enumerate()
            .for_each(|(t, xs)| {
                let k = z.start + t;
                let base = o.parent(2, k) * cx * cy;
                for j in region.y() {
                    let row = base + o.parent(1, j) * cx;
                    let (lo, hi) = self.span_within(j, k, &cols);
                    for i in lo..hi {
                        if self.inv_diag[k * nx * ny + i + nx * j] != 0.0 {
                            xs[i + nx * j] += xc[row + o.parent(0, i)];
                        }
                    }
                }
            });
    }

    /// x_fine += trilinear interpolation of the coarse correction: each child takes 27/64 of
    /// its parent, 9/64 of each of the three parent's neighbours on its side, 3/64 of the
    /// three edge neighbours and 1/64 of the corner one, renormalised over the coarse cells
    /// in the medium (so it falls back to copying near boundaries).
    pub(crate) fn prolong_trilinear_add(
        &self,
        coarse: &Level,
        xc: &[f32],
        x: &mut [f32],
        region: &Region,
        o: Origins,
    ) {
        let [nx, ny, _] = self.dims;
        let [cx, cy, cz] = coarse.dims;
        let z = region.z();
        let cols = region.x();
        x[z.start * nx * ny..z.end * nx * ny]
            .par_chunks_mut(nx * ny)
            .with_min_len(self.slabs_per_task())
            .enumerate()
            .for_each(|(t, xs)| {
                let k = z.start + t;
                let kc = o.parent(2, k);
                let kn = if o.even(2, k) {
                    kc.checked_sub(1)
                } else {
                    Some(kc + 1).filter(|&v| v < cz)
                };
                for j in region.y() {
                    let jc = o.parent(1, j);
                    let jn = if o.even(1, j) {
                        jc.checked_sub(1)
                    } else {
                        Some(jc + 1).filter(|&v| v < cy)
                    };
                    let (lo, hi) = self.span_within(j, k, &cols);
                    for i in lo..hi {
                        let l = i + nx * j;
                        if self.inv_diag[k * nx * ny + l] == 0.0 {
                            continue;
                        }
                        let ic = o.parent(0, i);
                        let inb = if o.even(0, i) {
                            ic.checked_sub(1)
                        } else {
                            Some(ic + 1).filter(|&v| v < cx)
                        };
                        let (mut sum, mut weight) = (0.0f32, 0.0f32);
                        for (kk, wk) in [(Some(kc), 0.75f32), (kn, 0.25)] {
                            let Some(kk) = kk else { continue };
                            for (jj, wj) in [(Some(jc), 0.75f32), (jn, 0.25)] {
                                let Some(jj) = jj else { continue };
                                let row = cx * (jj + cy * kk);
                                for (ii, wi) in [(Some(ic), 0.75f32), (inb, 0.25)] {
                                    let Some(ii) = ii else { continue };
                                    let c = row + ii;
                                    if coarse.inv_diag[c] != 0.0 {
                                        let w = wk * wj * wi;
                                        sum += w * xc[c];
                                        weight += w;
                                    }
                                }
                            }
                        }
                        if weight > 0.0 {
                            xs[l] += sum / weight;
                        }
                    }
                }
            });
    }
}

/// Where a fine level's vector and its coarse level's start in their whole grids, per axis
/// (x, y, z): fine index i is cell `fine + i` of the fine grid, coarse index i cell
/// `coarse + i` of the coarse grid. Zero for vectors of whole levels; a rank's box and halo
/// otherwise.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Origins {
    pub(crate) fine: [usize; 3],
    pub(crate) coarse: [usize; 3],
}

impl Origins {
    /// The coarse index of fine index `i`'s parent on axis `a`.
    #[inline(always)]
    fn parent(&self, a: usize, i: usize) -> usize {
        (i + self.fine[a]) / 2 - self.coarse[a]
    }

    /// Whether fine index `i` is its parent's lower child on axis `a`.
    #[inline(always)]
    fn even(&self, a: usize, i: usize) -> bool {
        (i + self.fine[a]).is_multiple_of(2)
    }

    /// The fine indices of coarse index `ic`'s children on axis `a`, within `n` fine cells.
    #[inline(always)]
    fn children(&self, a: usize, ic: usize, n: usize) -> Range<usize> {
        let first = (2 * (ic + self.coarse[a])).saturating_sub(self.fine[a]);
        first.min(n)..(first + 2).min(n)
    }
}

/// Calls `f(slab i, below, above)` on slab `i` of a run of slabs, the neighbours taken from
/// the run or, at its ends, from `below` and `above`.
fn on_slab_of_run<T>(
    run: &mut [T],
    slab: usize,
    i: usize,
    below: Option<&[T]>,
    above: Option<&[T]>,
    f: impl FnOnce(&mut [T], Option<&[T]>, Option<&[T]>),
) {
    let (head, rest) = run.split_at_mut(i * slab);
    let (this, tail) = rest.split_at_mut(slab);
    let lo = if i == 0 {
        below
    } else {
        Some(&head[(i - 1) * slab..])
    };
    let hi = if tail.is_empty() {
        above
    } else {
        Some(&tail[..slab])
    };
    f(this, lo, hi)
}

/// Below this many cells a parallel loop runs as one task: on the coarse levels rayon's
/// hand-offs would cost more than the work.
pub(crate) const PARALLEL_MIN_CELLS: usize = 16 * 1024;

/// Cells per block of the vectorised row kernels.
const BLOCK: usize = 64;

/// Below this many cells an interior row is swept cell by cell: the block's set-up costs
/// more than the arithmetic (a box's face column is one cell per row).
const SHORT_ROW: usize = 8;

/// Where an interior row sweep writes: the row's first cell in the level and in its slab,
/// the parity of the cells it updates, and the relaxation factor.
struct RowSweep<T> {
    g0: usize,
    l0: usize,
    parity: usize,
    omega: T,
}

/// The arithmetic the kernels run in: f32 (cycles) or f64 (baselines).
pub(crate) trait Real:
    Copy
    + Default
    + Send
    + Sync
    + PartialEq
    + From<f32>
    + Into<f64>
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::AddAssign
{
}

impl Real for f32 {}
impl Real for f64 {}

/// Σ x² in f64.
pub(crate) fn norm2<T: Copy + Into<f64> + Sync>(x: &[T]) -> f64 {
    lucent_core::reduce::norm2(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A random-ish symmetric level with a diagonal that dominates strictly, on the cells
    /// where `inside` holds; the others are outside the medium (no couplings, d = 0).
    fn level_in(dims: [usize; 3], inside: impl Fn([usize; 3]) -> bool) -> Level {
        let n = dims[0] * dims[1] * dims[2];
        let at = |g: usize| {
            [
                g % dims[0],
                (g / dims[0]) % dims[1],
                g / (dims[0] * dims[1]),
            ]
        };
        let mut couplings = [vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]];
        let strides = [1, dims[0], dims[0] * dims[1]];
        let extra: Vec<f32> = (0..n)
            .map(|g| if inside(at(g)) { 0.1 } else { 0.0 })
            .collect();
        let mut diag = extra.clone();
        for g in 0..n {
            for a in 0..3 {
                if at(g)[a] > 0 && inside(at(g)) && inside(at(g - strides[a])) {
                    let c = 1.0 + ((g * 7 + a * 13) % 5) as f32 * 0.3;
                    couplings[a][g] = c;
                    diag[g] += c;
                    diag[g - strides[a]] += c;
                }
            }
        }
        let inv_diag = diag
            .iter()
            .map(|&d| if d > 0.0 { 1.0 / d } else { 0.0 })
            .collect();
        Level::new(dims, DVec3::ONE, couplings, diag, extra, inv_diag)
    }

    fn level(dims: [usize; 3]) -> Level {
        level_in(dims, |_| true)
    }

    /// Media the span kernels must handle: the whole box; a ball with a hole, off centre so
    /// that it touches the box on two sides, in a box whose sides are not multiples of 8 and
    /// whose rows are longer than a block; single cells and a slab with empty rows.
    fn media() -> Vec<Level> {
        let ball = |[i, j, k]: [usize; 3]| {
            let p = [i as f64 - 40.0, j as f64 - 3.0, k as f64 - 6.0];
            let r2 = p[0] * p[0] / 900.0 + p[1] * p[1] / 9.0 + p[2] * p[2] / 16.0;
            (0.15..=1.0).contains(&r2)
        };
        vec![
            level([5, 4, 7]),
            level_in([70, 9, 11], ball),
            level_in([3, 5, 6], |[i, j, k]| (i + 2 * j + k) % 4 != 0),
            level_in([9, 6, 5], |[_, j, k]| j % 3 != 1 && k != 2),
            // Uneven work per slab and empty slabs; the second large enough for several
            // chunks of the parallel sweep.
            level_in([9, 7, 41], |[i, j, k]| k % 13 != 5 && (i + j) * 3 < k + 9),
            level_in([37, 29, 45], |[i, j, k]| k % 13 != 5 && (i + j) < 2 * k + 9),
        ]
    }

    #[test]
    fn sweep_chunks_cover_the_slabs_in_order_with_two_slabs_or_more() {
        for lv in media()
            .into_iter()
            .chain([level([4, 4, 64]), level([3, 3, 9]), level([5, 5, 1])])
        {
            let chunks = lv.sweep_chunks();
            let nz = lv.dims[2];
            assert_eq!(chunks[0].0, 0);
            assert_eq!(chunks[chunks.len() - 1].1, nz);
            for w in chunks.windows(2) {
                assert_eq!(w[0].1, w[1].0);
            }
            if chunks.len() > 1 {
                assert!(chunks.iter().all(|&(a, b)| b >= a + 2), "{chunks:?}");
            }
        }
    }

    #[test]
    fn the_wavefront_sweep_equals_red_then_black() {
        assert!(
            media().iter().any(|lv| lv.sweep_chunks().len() >= 2),
            "no medium runs the sweep in parallel chunks"
        );
        for lv in media() {
            let b: Vec<f32> = (0..lv.len())
                .map(|g| {
                    if lv.inv_diag[g] != 0.0 {
                        ((g * 31) % 17) as f32 - 8.0
                    } else {
                        0.0
                    }
                })
                .collect();
            let mut x = vec![0.5f32; lv.len()];
            lv.sor(&b, &mut x, 0, 1.0);
            assert_red_then_black(&lv, &b, &x);
        }
    }

    /// Checks `x` against a serial red sweep then a serial black sweep from 0.5 over every
    /// cell of the box (cells outside the medium keep 0.5).
    fn assert_red_then_black(lv: &Level, b: &[f32], x: &[f32]) {
        let n = lv.len();
        let mut y = vec![0.5f32; n];
        let [nx, ny, nz] = lv.dims;
        for colour in [0, 1] {
            for k in 0..nz {
                for j in 0..ny {
                    for i in 0..nx {
                        let g = i + nx * (j + ny * k);
                        if (i + j + k) % 2 != colour || lv.diag[g] == 0.0 {
                            continue;
                        }
                        let at = [i, j, k];
                        let strides = [1, nx, nx * ny];
                        let mut s = b[g];
                        for a in 0..3 {
                            if at[a] > 0 {
                                s += lv.couplings[a][g] * y[g - strides[a]];
                            }
                            if at[a] + 1 < lv.dims[a] {
                                s += lv.couplings[a][g + strides[a]] * y[g + strides[a]];
                            }
                        }
                        y[g] = s / lv.diag[g];
                    }
                }
            }
        }
        for (a, b) in x.iter().zip(&y) {
            assert!((a - b).abs() <= 1e-5 * b.abs().max(1.0), "{a} vs {b}");
        }
    }

    /// A x cell by cell over the whole box, in the flux form in f64.
    fn reference_apply(lv: &Level, x: &[f64]) -> Vec<f64> {
        let [nx, ny, _] = lv.dims;
        let strides = [1, nx, nx * ny];
        (0..lv.len())
            .map(|g| {
                let at = [g % nx, (g / nx) % ny, g / (nx * ny)];
                let mut y = f64::from(lv.extra[g]) * x[g];
                for a in 0..3 {
                    if at[a] > 0 {
                        y += f64::from(lv.couplings[a][g]) * (x[g] - x[g - strides[a]]);
                    }
                    if at[a] + 1 < lv.dims[a] {
                        let c = f64::from(lv.couplings[a][g + strides[a]]);
                        y += c * (x[g] - x[g + strides[a]]);
                    }
                }
                y
            })
            .collect()
    }

    #[test]
    fn products_and_corrections_on_spans_equal_the_dense_operator() {
        for lv in media() {
            let n = lv.len();
            let e: Vec<f32> = (0..n)
                .map(|g| {
                    if lv.inv_diag[g] != 0.0 {
                        ((g * 13) % 7) as f32 * 0.25 - 0.5
                    } else {
                        0.0
                    }
                })
                .collect();
            let e64: Vec<f64> = e.iter().map(|&v| f64::from(v)).collect();
            let expected = reference_apply(&lv, &e64);
            let mut y = vec![f64::NAN; n];
            lv.apply(&e, &mut y);
            for (a, b) in y.iter().zip(&expected) {
                // f32 couplings read in f64 either way: only the summation order differs.
                assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0), "{a} vs {b}");
            }
            // A residual that is non-zero outside the medium too: the correction leaves it
            // there, and the span sum plus the outside sum is the whole ‖r‖².
            let mut r: Vec<f64> = (0..n).map(|g| (g % 5) as f64 - 2.0).collect();
            let mut phi = vec![1.0; n];
            let mut b = vec![0.0f32; n];
            let before = r.clone();
            let norm = lv.correct(&e, &mut phi, &mut r, &mut b);
            // The norm counts every cell, inside the spans and out, as the exact sum of
            // the runs' sums (exact: the same bits as summing the runs by hand).
            let by_hand: ExactSum = r
                .chunks(lv.dims[0])
                .flat_map(|line| {
                    line.chunks(8)
                        .map(|run| run.iter().map(|v| v * v).sum::<f64>())
                })
                .collect();
            assert_eq!(norm.to_bits(), by_hand.value().sqrt().to_bits());
            for g in 0..n {
                assert!((r[g] - (before[g] - expected[g])).abs() <= 1e-12);
                assert_eq!(phi[g], 1.0 + e64[g]);
            }
        }
    }

    #[test]
    fn transfers_on_a_box_stored_alone_are_the_levels_bits() {
        // A rank holds its box and the cells around it as a level of its own
        // (`Level::extract`), the coarse level likewise: restriction and both
        // prolongations there, shifted by `Origins`, a colour of the sweep (whose cells
        // are those of the whole level's colour: a box at an odd origin starts on the
        // other colour) and the residual must give the bits of the same kernels on the
        // whole levels, for boxes at odd and even origins, touching the grid's faces or
        // not.
        for lv in media() {
            let (cdims, spacing) = crate::problem::coarse_shape(lv.dims, lv.spacing);
            let cn: usize = cdims.iter().product();
            let c_inv: Vec<f32> = (0..cn)
                .map(|c| if c % 7 == 3 { 0.0 } else { 0.5 })
                .collect();
            let zeros = vec![0.0f32; cn];
            let coarse = Level::new(
                cdims,
                spacing,
                [zeros.clone(), zeros.clone(), zeros.clone()],
                zeros.clone(),
                zeros,
                c_inv,
            );
            let n = lv.len();
            let b: Vec<f32> = (0..n).map(|g| ((g * 13) % 7) as f32 - 3.0).collect();
            let x: Vec<f32> = (0..n).map(|g| ((g * 29) % 11) as f32 * 0.1).collect();
            let xc: Vec<f32> = (0..cn).map(|c| ((c * 17) % 5) as f32 - 2.0).collect();
            let dims = lv.dims;
            let halves = |a: usize| {
                let c = cdims[a];
                [
                    0..c,
                    0..c.div_ceil(2),
                    c / 2..c,
                    (c / 3)..(c / 3 + 1).min(c),
                ]
            };
            for rx in halves(0) {
                for rz in halves(2) {
                    let rc = Region::new([rx.clone(), 0..cdims[1], rz.clone()]);
                    if rc.is_empty() {
                        continue;
                    }
                    let rf = Region::new(std::array::from_fn(|a| {
                        (2 * rc.axes[a].start).min(dims[a])..(2 * rc.axes[a].end).min(dims[a])
                    }));
                    let (gf, gc) = (rf.grown(1, dims), rc.grown(1, cdims));
                    let origin = |g: &Region| std::array::from_fn(|a| g.axes[a].start);
                    let size = |g: &Region| std::array::from_fn(|a| g.axes[a].len());
                    let o = Origins {
                        fine: origin(&gf),
                        coarse: origin(&gc),
                    };
                    let local = |g: &Region, r: &Region| {
                        Region::new(std::array::from_fn(|a| {
                            r.axes[a].start - g.axes[a].start..r.axes[a].end - g.axes[a].start
                        }))
                    };
                    let (lf, lc) = (
                        lv.extract(o.fine, size(&gf)),
                        coarse.extract(o.coarse, size(&gc)),
                    );
                    let (bl, xl, xcl) = (gf.cut(dims, &b), gf.cut(dims, &x), gc.cut(cdims, &xc));
                    // Restriction.
                    let mut whole = vec![0.0f32; cn];
                    lv.restrict_residual(&b, &x, &coarse, &mut whole, &rc, Origins::default());
                    let mut part = vec![0.0f32; lc.len()];
                    lf.restrict_residual(&bl, &xl, &lc, &mut part, &local(&gc, &rc), o);
                    assert_eq!(rc.cut(cdims, &whole), local(&gc, &rc).cut(lc.dims, &part));
                    // Prolongations.
                    for trilinear in [false, true] {
                        let mut whole = x.clone();
                        let mut part = xl.clone();
                        if trilinear {
                            lv.prolong_trilinear_add(
                                &coarse,
                                &xc,
                                &mut whole,
                                &rf,
                                Origins::default(),
                            );
                            lf.prolong_trilinear_add(&lc, &xcl, &mut part, &local(&gf, &rf), o);
                        } else {
                            lv.prolong_add(&coarse, &xc, &mut whole, &rf, Origins::default());
                            lf.prolong_add(&lc, &xcl, &mut part, &local(&gf, &rf), o);
                        }
                        assert_eq!(rf.cut(dims, &whole), local(&gf, &rf).cut(lf.dims, &part));
                    }
                    // A colour of the sweep and the residual on the box.
                    let mut whole = x.clone();
                    let mut part = xl.clone();
                    lv.colour_in(&b, &mut whole, 1, 1.0, &rf);
                    lf.colour_in(&bl, &mut part, 1, 1.0, &local(&gf, &rf));
                    assert_eq!(rf.cut(dims, &whole), local(&gf, &rf).cut(lf.dims, &part));
                    let (b64, bl64): (Vec<f64>, Vec<f64>) = (
                        b.iter().map(|&v| f64::from(v)).collect(),
                        bl.iter().map(|&v| f64::from(v)).collect(),
                    );
                    let (mut r, mut rl) = (vec![0.0; n], vec![0.0; lf.len()]);
                    let sum = lv.residual_in(&b64, &x, &mut r, &rf);
                    let suml = lf.residual_in(&bl64, &xl, &mut rl, &local(&gf, &rf));
                    assert_eq!(rf.cut(dims, &r), local(&gf, &rf).cut(lf.dims, &rl));
                    assert_eq!(sum.value().to_bits(), suml.value().to_bits());
                }
            }
        }
    }

    #[test]
    fn restriction_sums_the_residual_of_the_medium() {
        for lv in media() {
            let (dims, spacing) = crate::problem::coarse_shape(lv.dims, lv.spacing);
            let n = lv.len();
            let coarse = Level::new(
                dims,
                spacing,
                [vec![], vec![], vec![]],
                vec![],
                vec![],
                vec![0.0; dims[0] * dims[1] * dims[2]],
            );
            let medium = |g: usize| lv.inv_diag[g] != 0.0;
            // b is not zero outside the medium: those cells must not pass it down.
            let b: Vec<f32> = (0..n).map(|g| (g % 3) as f32).collect();
            let x: Vec<f32> = (0..n)
                .map(|g| if medium(g) { (g % 5) as f32 * 0.1 } else { 0.0 })
                .collect();
            let mut out = vec![0.0f32; coarse.len()];
            lv.restrict_residual(
                &b,
                &x,
                &coarse,
                &mut out,
                &coarse.whole(),
                Origins::default(),
            );
            let b64: Vec<f64> = b.iter().map(|&v| f64::from(v)).collect();
            let mut r = vec![0.0; n];
            let _ = lv.residual(&b64, &x, &mut r);
            // Each coarse cell holds the sum over its children.
            let [nx, ny, _] = lv.dims;
            let mut sums = vec![0.0f64; coarse.len()];
            for (g, r) in r.iter().enumerate().filter(|&(g, _)| medium(g)) {
                let [i, j, k] = [g % nx, (g / nx) % ny, g / (nx * ny)];
                sums[i / 2 + dims[0] * (j / 2 + dims[1] * (k / 2))] += r;
            }
            for (a, e) in out.iter().zip(&sums) {
                assert!(
                    (f64::from(*a) - e).abs() <= 1e-4 * e.abs().max(1.0),
                    "{a} vs {e}"
                );
            }
            // With x = 0 the residual is b: the plain restriction gives the same sums, in the
            // same order.
            let mut residual = vec![0.0f32; coarse.len()];
            let mut plain = vec![1.0f32; coarse.len()];
            lv.restrict_residual(
                &b,
                &vec![0.0; n],
                &coarse,
                &mut residual,
                &coarse.whole(),
                Origins::default(),
            );
            lv.restrict(&b, &coarse, &mut plain, &coarse.whole(), Origins::default());
            assert_eq!(residual, plain);
        }
    }
}
