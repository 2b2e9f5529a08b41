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
//! Storage is f32 (5 arrays: three couplings, the diagonal and its inverse); sweeps run in
//! parallel over z-slabs. Red–black Gauss–Seidel is done in three passes over slabs that
//! never conflict: red on even slabs; red then black on odd slabs (their red neighbours
//! above and below are final by then); black on even slabs. The result equals a plain red
//! sweep followed by a black sweep.

use glam::DVec3;
use rayon::prelude::*;

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
}

impl Level {
    pub(crate) fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    pub(crate) fn slab(&self) -> usize {
        self.dims[0] * self.dims[1]
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
        self.apply_then(x, y, |_, _| 0.0);
    }

    /// r = b − A x in f64, in one pass; returns ‖r‖₂.
    pub(crate) fn residual<T: Copy + Into<f64> + Sync>(
        &self,
        b: &[f64],
        x: &[T],
        r: &mut [f64],
    ) -> f64 {
        let slab = self.slab();
        self.apply_then(x, r, |k, rs| {
            let mut sum = 0.0;
            for (r, b) in rs.iter_mut().zip(&b[k * slab..]) {
                *r = b - *r;
                sum += *r * *r;
            }
            sum
        })
        .sqrt()
    }

    /// y = A x slab by slab, each slab then passed to `then(k, y_slab)` while it is in
    /// cache; returns the sum of what `then` returns.
    fn apply_then<T: Copy + Into<f64> + Sync>(
        &self,
        x: &[T],
        y: &mut [f64],
        then: impl Fn(usize, &mut [f64]) -> f64 + Sync,
    ) -> f64 {
        y.par_chunks_mut(self.slab())
            .enumerate()
            .map(|(k, y)| {
                self.apply_slab(k, x, y);
                then(k, y)
            })
            .sum()
    }

    /// Slab k of A x into `y` (one slab long).
    fn apply_slab<T: Copy + Into<f64>>(&self, k: usize, x: &[T], y: &mut [f64]) {
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
        for j in 0..ny {
            let (Some(down), Some(up), true) = (below, above, j > 0 && j + 1 < ny && nx > 2) else {
                for i in 0..nx {
                    y[i + nx * j] = general(i, j);
                }
                continue;
            };
            y[nx * j] = general(0, j);
            y[nx * j + nx - 1] = general(nx - 1, j);
            let l = 1 + nx * j;
            self.interior_apply(k * slab + l, l, xs, down, up, &mut y[l..l + nx - 2]);
        }
    }

    /// Applies a correction e in one pass: φ += e, r −= A e (the residual of φ updated
    /// without recomputing A φ) and b = r in f32 for the next cycle; returns ‖r‖₂.
    pub(crate) fn correct(&self, e: &[f32], phi: &mut [f64], r: &mut [f64], b: &mut [f32]) -> f64 {
        let slab = self.slab();
        phi.par_chunks_mut(slab)
            .zip(r.par_chunks_mut(slab))
            .zip(b.par_chunks_mut(slab))
            .enumerate()
            .map(|(k, ((phi, r), b))| {
                let mut ae = vec![0.0f64; slab];
                self.apply_slab(k, e, &mut ae);
                let es = &e[k * slab..(k + 1) * slab];
                let mut sum = 0.0;
                for l in 0..slab {
                    phi[l] += f64::from(es[l]);
                    r[l] -= ae[l];
                    b[l] = r[l] as f32;
                    sum += r[l] * r[l];
                }
                sum
            })
            .sum::<f64>()
            .sqrt()
    }

    /// One red–black Gauss–Seidel sweep for A x = b, colours in the order `first`, then
    /// the other (0 = red: (i + j + k) even).
    pub(crate) fn gauss_seidel(&self, b: &[f32], x: &mut [f32], first: usize) {
        self.sor(b, x, first, 1.0);
    }

    /// One red–black SOR sweep with relaxation ω (ω = 1: Gauss–Seidel), in three passes
    /// over slabs that never conflict: the first colour on even slabs; both colours on odd
    /// slabs (their neighbours above and below have the first colour final by then); the
    /// second colour on even slabs. The result equals a red sweep followed by a black
    /// sweep (tested). A one-pass wavefront (first colour on slab k, second on k − 1, chunks
    /// of slabs per task) was measured no faster on 2 cores at 128³: the sweep is limited by
    /// arithmetic as much as by memory there.
    pub(crate) fn sor<T: Real>(&self, b: &[T], x: &mut [T], first: usize, omega: T) {
        let second = 1 - first;
        self.on_slabs(
            x,
            |k| k % 2 == 0,
            |k, xs, below, above| {
                self.colour(b, k, first, omega, xs, below, above);
            },
        );
        self.on_slabs(
            x,
            |k| k % 2 == 1,
            |k, xs, below, above| {
                self.colour(b, k, first, omega, xs, below, above);
                self.colour(b, k, second, omega, xs, below, above);
            },
        );
        self.on_slabs(
            x,
            |k| k % 2 == 0,
            |k, xs, below, above| {
                self.colour(b, k, second, omega, xs, below, above);
            },
        );
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
    ) {
        let [nx, ny, _] = self.dims;
        let base = k * nx * ny;
        let one = T::from(1.0);
        let relaxed = omega != one;
        for j in 0..ny {
            let first = (colour + j + k) % 2;
            if let (true, Some(below), Some(above)) = (j > 0 && j + 1 < ny && nx > 2, below, above)
            {
                let row = RowSweep {
                    g0: base + nx * j,
                    l0: nx * j,
                    parity: first,
                    omega,
                };
                self.colour_row_interior(b, &row, x, below, above);
                // The row's two end cells, by the general code below.
                for i in [0, nx - 1] {
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
            let mut i = first;
            while i < nx {
                let l = i + nx * j;
                let g = base + l;
                // Residual form r = b − e x_i − Σ c (x_i − x_j): its fixed point is the
                // operator's solution exactly, not that of a rounded diagonal.
                let s = b[g] + self.neighbour_sum(g, l, [i, j], x, below, above);
                let r = s - (T::from(self.extra[g]) + self.coupling_sum(g, [i, j, k])) * x[l];
                let step = r * T::from(self.inv_diag[g]);
                x[l] += if relaxed { omega * step } else { step };
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

    /// Cells 1 ..= nx − 2 of an interior row (all six neighbours present) for one colour.
    /// The update is computed for every cell of a block of the row into a buffer, from
    /// contiguous slices, so that it vectorises; then only the colour's cells are stored.
    /// That is exact: the update of one colour reads only the other colour, which does not
    /// change during it. Twice the arithmetic, half the time of the strided loop.
    #[inline(always)]
    fn colour_row_interior<T: Real>(
        &self,
        b: &[T],
        row: &RowSweep<T>,
        x: &mut [T],
        below: &[T],
        above: &[T],
    ) {
        let nx = self.dims[0];
        let &RowSweep {
            g0,
            l0,
            parity,
            omega,
        } = row;
        let relaxed = omega != T::from(1.0);
        let mut buffer = [T::default(); BLOCK];
        let mut start = 1;
        while start + 1 < nx {
            let len = BLOCK.min(nx - 1 - start);
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
        chosen.into_par_iter().for_each(|(k, s)| {
            let below = if k > 0 { others[k - 1] } else { None };
            let above = others.get(k + 1).copied().flatten();
            f(k, s, below, above);
        });
    }

    /// One weighted Jacobi sweep x ← x + ω D⁻¹(b − A x), using `scratch` (len n).
    pub(crate) fn jacobi(&self, b: &[f32], x: &mut [f32], omega: f32, scratch: &mut [f32]) {
        let slab = self.slab();
        let nz = self.dims[2];
        let [nx, ny, _] = self.dims;
        {
            let x: &[f32] = x;
            scratch
                .par_chunks_mut(slab)
                .enumerate()
                .for_each(|(k, out)| {
                    let xs = &x[k * slab..(k + 1) * slab];
                    let below = (k > 0).then(|| &x[(k - 1) * slab..k * slab]);
                    let above = (k + 1 < nz).then(|| &x[(k + 1) * slab..(k + 2) * slab]);
                    for j in 0..ny {
                        for i in 0..nx {
                            let l = i + nx * j;
                            let g = k * slab + l;
                            let r = b[g] + self.neighbour_sum(g, l, [i, j], xs, below, above)
                                - self.diag[g] * xs[l];
                            out[l] = xs[l] + omega * self.inv_diag[g] * r;
                        }
                    }
                });
        }
        x.copy_from_slice(scratch);
    }

    /// The coarse right-hand side Σ_children (b − A x): residual and restriction in one pass.
    pub(crate) fn restrict_residual(&self, b: &[f32], x: &[f32], coarse: &Level, out: &mut [f32]) {
        let [nx, ny, nz] = self.dims;
        let [cx, cy, _] = coarse.dims;
        let slab = nx * ny;
        out.par_chunks_mut(cx * cy)
            .enumerate()
            .for_each(|(kc, out)| {
                out.fill(0.0);
                for k in 2 * kc..(2 * kc + 2).min(nz) {
                    let xs = &x[k * slab..(k + 1) * slab];
                    let below = (k > 0).then(|| &x[(k - 1) * slab..k * slab]);
                    let above = (k + 1 < nz).then(|| &x[(k + 1) * slab..(k + 2) * slab]);
                    let mut buffer = [0.0f32; BLOCK];
                    for j in 0..ny {
                        let row = (j / 2) * cx;
                        let general = |i: usize| {
                            let l = i + nx * j;
                            let g = k * slab + l;
                            b[g] + self.neighbour_sum(g, l, [i, j], xs, below, above)
                                - (self.extra[g] + self.coupling_sum::<f32>(g, [i, j, k])) * xs[l]
                        };
                        let (Some(down), Some(up), true) =
                            (below, above, j > 0 && j + 1 < ny && nx > 2)
                        else {
                            for i in 0..nx {
                                out[row + i / 2] += general(i);
                            }
                            continue;
                        };
                        out[row] += general(0);
                        out[row + (nx - 1) / 2] += general(nx - 1);
                        let mut start = 1;
                        while start + 1 < nx {
                            let len = BLOCK.min(nx - 1 - start);
                            let l = start + nx * j;
                            let r = &mut buffer[..len];
                            self.interior_residuals(b, k * slab + l, l, xs, down, up, r);
                            for (t, r) in r.iter().enumerate() {
                                out[row + (start + t) / 2] += r;
                            }
                            start += len;
                        }
                    }
                }
            });
    }

    /// x_fine += x_coarse of the parent (piecewise-constant prolongation).
    pub(crate) fn prolong_add(&self, coarse: &Level, xc: &[f32], x: &mut [f32]) {
        let [nx, ny, _] = self.dims;
        let [cx, cy, _] = coarse.dims;
        x.par_chunks_mut(nx * ny).enumerate().for_each(|(k, xs)| {
            let base = (k / 2) * cx * cy;
            for j in 0..ny {
                let row = base + (j / 2) * cx;
                for i in 0..nx {
                    if self.inv_diag[k * nx * ny + i + nx * j] != 0.0 {
                        xs[i + nx * j] += xc[row + i / 2];
                    }
                }
            }
        });
    }

    /// x_fine += trilinear interpolation of the coarse correction: each child takes 27/64 of
    /// its parent, 9/64 of each of the three parent's neighbours on its side, 3/64 of the
    /// three edge neighbours and 1/64 of the corner one, renormalised over the coarse cells
    /// in the medium (so it falls back to copying near boundaries).
    pub(crate) fn prolong_trilinear_add(&self, coarse: &Level, xc: &[f32], x: &mut [f32]) {
        let [nx, ny, _] = self.dims;
        let [cx, cy, cz] = coarse.dims;
        x.par_chunks_mut(nx * ny).enumerate().for_each(|(k, xs)| {
            let kc = k / 2;
            let kn = if k % 2 == 0 {
                kc.checked_sub(1)
            } else {
                Some(kc + 1).filter(|&v| v < cz)
            };
            for j in 0..ny {
                let jc = j / 2;
                let jn = if j % 2 == 0 {
                    jc.checked_sub(1)
                } else {
                    Some(jc + 1).filter(|&v| v < cy)
                };
                for i in 0..nx {
                    let l = i + nx * j;
                    if self.inv_diag[k * nx * ny + l] == 0.0 {
                        continue;
                    }
                    let ic = i / 2;
                    let inb = if i % 2 == 0 {
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

    /// Dims and spacing of the next coarser level.
    /// Axes with a single cell stay single (a 2D problem is one cell thick).
    pub(crate) fn coarse_shape(&self) -> ([usize; 3], DVec3) {
        let dims = self.dims.map(|n| if n == 1 { 1 } else { n.div_ceil(2) });
        let scale = DVec3::from_array(self.dims.map(|n| if n == 1 { 1.0 } else { 2.0 }));
        (dims, self.spacing * scale)
    }
}

/// Cells per block of the vectorised row kernels.
const BLOCK: usize = 64;

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
    x.par_iter()
        .map(|&v| {
            let v: f64 = v.into();
            v * v
        })
        .sum::<f64>()
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A random-ish symmetric level with a diagonal that dominates strictly.
    fn level(dims: [usize; 3]) -> Level {
        let n = dims[0] * dims[1] * dims[2];
        let mut couplings = [vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]];
        let strides = [1, dims[0], dims[0] * dims[1]];
        let mut diag = vec![0.1f32; n];
        for g in 0..n {
            let at = [
                g % dims[0],
                (g / dims[0]) % dims[1],
                g / (dims[0] * dims[1]),
            ];
            for a in 0..3 {
                if at[a] > 0 {
                    let c = 1.0 + ((g * 7 + a * 13) % 5) as f32 * 0.3;
                    couplings[a][g] = c;
                    diag[g] += c;
                    diag[g - strides[a]] += c;
                }
            }
        }
        let inv_diag = diag.iter().map(|d| 1.0 / d).collect();
        Level {
            dims,
            spacing: DVec3::ONE,
            couplings,
            diag,
            extra: vec![0.1; n],
            inv_diag,
        }
    }

    #[test]
    fn red_black_in_three_passes_equals_red_then_black() {
        let lv = level([5, 4, 7]);
        let b: Vec<f32> = (0..lv.len())
            .map(|g| ((g * 31) % 17) as f32 - 8.0)
            .collect();
        let mut x = vec![0.5f32; lv.len()];
        lv.sor(&b, &mut x, 0, 1.0);
        assert_red_then_black(&lv, &b, &x);
    }

    /// Checks `x` against a serial red sweep then a serial black sweep from 0.5.
    fn assert_red_then_black(lv: &Level, b: &[f32], x: &[f32]) {
        let n = lv.len();
        let mut y = vec![0.5f32; n];
        let [nx, ny, nz] = lv.dims;
        for colour in [0, 1] {
            for k in 0..nz {
                for j in 0..ny {
                    for i in 0..nx {
                        if (i + j + k) % 2 != colour {
                            continue;
                        }
                        let g = i + nx * (j + ny * k);
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
            assert!((a - b).abs() <= 1e-6 * b.abs().max(1.0), "{a} vs {b}");
        }
    }

    #[test]
    fn restriction_sums_the_residual() {
        let lv = level([5, 6, 3]);
        let (dims, spacing) = lv.coarse_shape();
        let coarse = Level {
            dims,
            spacing,
            couplings: [vec![], vec![], vec![]],
            diag: vec![],
            extra: vec![],
            inv_diag: vec![],
        };
        let n = lv.len();
        let b: Vec<f32> = (0..n).map(|g| (g % 3) as f32).collect();
        let x: Vec<f32> = (0..n).map(|g| (g % 5) as f32 * 0.1).collect();
        let mut out = vec![0.0f32; coarse.len()];
        lv.restrict_residual(&b, &x, &coarse, &mut out);
        let b64: Vec<f64> = b.iter().map(|&v| f64::from(v)).collect();
        let mut r = vec![0.0; n];
        let _ = lv.residual(&b64, &x, &mut r);
        let total: f64 = r.iter().sum();
        let coarse_total: f64 = out.iter().map(|&v| f64::from(v)).sum();
        assert!((total - coarse_total).abs() < 1e-4 * total.abs().max(1.0));
    }
}
