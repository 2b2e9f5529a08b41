//! Anderson acceleration (type II, Walker & Ni 2011) of a fixed-point iteration x ← G(x),
//! here the DSA-corrected source iteration on the stored in-scattered radiance.
//!
//! Why: diffusion synthetic acceleration with a diffusion operator that is not derived
//! from the transport closure ("inconsistent" DSA) contracts to a few per cent per sweep
//! in cells up to about one mean free path wide, but for diamond difference its spectral
//! radius passes 1 in thicker cells (at σ_t h = 2 in this crate's tests, as Fourier
//! analysis predicts; Larsen 1982, Azmy). Krylov methods preconditioned by that same DSA
//! stay effective there (Warsa, Wareing & Morel 2004); Anderson mixing is the Krylov method
//! (GMRES, for a linear map) that needs only evaluations of the iteration itself, so it
//! tolerates the closures' non-linear positivity fix-ups. Each step solves the small
//! least-squares problem min‖f_k − ΔF γ‖ over the last `depth` residual differences
//! (inner product weighted by σ_s² w_m, the scattering source's norm) and sets
//! x_{k+1} = G(x_k) − ΔG γ.
//!
//! Memory: 2·depth + 2 vectors of the stored radiance (f32); the weights are formed from
//! σ_s per cell and w_m per direction. Each step makes three passes
//! over them (differences and norms; the new inner products; the update).

use rayon::prelude::*;

/// Cells per parallel chunk.
const ROWS: usize = 256;

/// The mixing state.
pub(crate) struct Anderson {
    depth: usize,
    /// The inner product's weight of entry (cell, m) is `cell_weight[cell]` ×
    /// `direction_weight[m]` (σ_s² and w_m), formed on the fly.
    cell_weight: Vec<f32>,
    direction_weight: Vec<f32>,
    /// Ring buffers of ΔF and ΔG; `order[i]` is the slot of the i-th oldest difference.
    delta_f: Vec<Vec<f32>>,
    delta_g: Vec<Vec<f32>>,
    order: Vec<usize>,
    /// ⟨ΔF_i, ΔF_j⟩ by slot.
    gram: Vec<f64>,
    last_f: Vec<f32>,
    last_g: Vec<f32>,
    started: bool,
}

impl Anderson {
    pub(crate) fn new(depth: usize, cell_weight: Vec<f32>, direction_weight: Vec<f32>) -> Self {
        Self {
            depth,
            cell_weight,
            direction_weight,
            delta_f: Vec::new(),
            delta_g: Vec::new(),
            order: Vec::new(),
            gram: vec![0.0; depth * depth],
            last_f: Vec::new(),
            last_g: Vec::new(),
            started: false,
        }
    }

    /// Forgets the history.
    pub(crate) fn reset(&mut self) {
        self.order.clear();
        self.started = false;
    }

    /// The next iterate from the current one `x` and its image `g` (overwritten with the
    /// result). Returns the map's measured contraction ‖G(x_k) − G(x_{k−1})‖/‖x_k − x_{k−1}‖
    /// when there is a previous pair.
    pub(crate) fn step(&mut self, x: &[f32], g: &mut [f32]) -> Option<f64> {
        let len = g.len();
        if !self.started {
            self.last_f.resize(len, 0.0);
            self.last_g.resize(len, 0.0);
            let chunk = ROWS * self.direction_weight.len();
            self.last_f
                .par_chunks_mut(chunk)
                .zip(self.last_g.par_chunks_mut(chunk))
                .zip(g.par_chunks(chunk).zip(x.par_chunks(chunk)))
                .for_each(|((lf, lg), (g, x))| {
                    for i in 0..g.len() {
                        lf[i] = g[i] - x[i];
                        lg[i] = g[i];
                    }
                });
            self.started = true;
            return None;
        }
        // The slot for the new difference: a fresh one, or the oldest.
        let slot = if self.order.len() < self.depth {
            if self.delta_f.len() <= self.order.len() {
                self.delta_f.push(vec![0.0; len]);
                self.delta_g.push(vec![0.0; len]);
            }
            self.order.len()
        } else {
            self.order.remove(0)
        };
        self.order.push(slot);
        // Pass 1: ΔF = f − f_last, ΔG = g − g_last, last ← current; ‖ΔG‖² and ‖ΔX‖².
        let dirs = self.direction_weight.len();
        let chunk = ROWS * dirs;
        let (cw, dw) = (&self.cell_weight, &self.direction_weight);
        let (norm_g, norm_x) = {
            let (df, dg) = (&mut self.delta_f[slot], &mut self.delta_g[slot]);
            df.par_chunks_mut(chunk)
                .zip(dg.par_chunks_mut(chunk))
                .zip(
                    self.last_f
                        .par_chunks_mut(chunk)
                        .zip(self.last_g.par_chunks_mut(chunk)),
                )
                .zip(g.par_chunks(chunk).zip(x.par_chunks(chunk)))
                .enumerate()
                .map(|(c, (((df, dg), (lf, lg)), (g, x)))| {
                    let (mut ng, mut nx) = (0.0f64, 0.0f64);
                    for i in 0..g.len() {
                        let f = g[i] - x[i];
                        df[i] = f - lf[i];
                        dg[i] = g[i] - lg[i];
                        lf[i] = f;
                        lg[i] = g[i];
                    }
                    for (r, row) in (c * ROWS..).zip(0..g.len() / dirs) {
                        let s = f64::from(cw[r]);
                        if s == 0.0 {
                            continue;
                        }
                        for q in 0..dirs {
                            let i = row * dirs + q;
                            let w = s * f64::from(dw[q]);
                            let dx = f64::from(dg[i] - df[i]);
                            ng += w * f64::from(dg[i]).powi(2);
                            nx += w * dx * dx;
                        }
                    }
                    (ng, nx)
                })
                // Chunk sums in chunk order: the same bits whatever the threads did.
                .collect::<Vec<_>>()
                .into_iter()
                .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1))
        };
        let contraction = (norm_x > 0.0).then(|| (norm_g / norm_x).sqrt());
        // Pass 2: ⟨ΔF_new, ΔF_i⟩ for every i, and ⟨ΔF_i, f⟩ (f = last_f now).
        let m = self.order.len();
        let slots = self.order.clone();
        let dots: Vec<f64> = {
            let df = &self.delta_f;
            let lf = &self.last_f;
            (0..len.div_ceil(chunk))
                .into_par_iter()
                .map(|c| {
                    let mut out = vec![0.0f64; 2 * m];
                    let cells = c * ROWS..((c + 1) * ROWS).min(len / dirs);
                    for (k, &s) in slots.iter().enumerate() {
                        let (v, new) = (&df[s], &df[slot]);
                        let (mut a, mut b) = (0.0f64, 0.0f64);
                        for cell in cells.clone() {
                            let weight = f64::from(cw[cell]);
                            if weight == 0.0 {
                                continue;
                            }
                            for q in 0..dirs {
                                let i = cell * dirs + q;
                                let wv = weight * f64::from(dw[q]) * f64::from(v[i]);
                                a += wv * f64::from(new[i]);
                                b += wv * f64::from(lf[i]);
                            }
                        }
                        out[k] = a;
                        out[m + k] = b;
                    }
                    out
                })
                // Chunk sums in chunk order: the same bits whatever the threads did.
                .collect::<Vec<_>>()
                .into_iter()
                .fold(vec![0.0; 2 * m], |mut a, b| {
                    a.iter_mut().zip(b).for_each(|(a, b)| *a += b);
                    a
                })
        };
        let d = self.depth;
        for (k, &s) in slots.iter().enumerate() {
            self.gram[slot * d + s] = dots[k];
            self.gram[s * d + slot] = dots[k];
        }
        // The small normal equations, Tikhonov-regularised relative to the trace.
        let mut a = vec![0.0f64; m * m];
        let mut b = vec![0.0f64; m];
        for (i, &si) in slots.iter().enumerate() {
            b[i] = dots[m + i];
            for (j, &sj) in slots.iter().enumerate() {
                a[i * m + j] = self.gram[si * d + sj];
            }
        }
        let trace: f64 = (0..m).map(|i| a[i * m + i]).sum();
        if !(trace > 0.0 && trace.is_finite()) {
            return contraction;
        }
        for i in 0..m {
            a[i * m + i] += 1e-10 * trace;
        }
        let Some(gamma) = solve_dense(&mut a, &mut b, m) else {
            self.order.clear();
            return contraction;
        };
        // Pass 3: g ← g − ΔG γ, kept non-negative (radiance; mixing can undershoot
        // where it is near zero).
        let dg: Vec<&Vec<f32>> = slots.iter().map(|&s| &self.delta_g[s]).collect();
        let gamma: Vec<f32> = gamma.iter().map(|v| *v as f32).collect();
        g.par_chunks_mut(chunk).enumerate().for_each(|(c, g)| {
            let start = c * chunk;
            for (k, v) in dg.iter().enumerate() {
                let v = &v[start..start + g.len()];
                let c = gamma[k];
                for (g, v) in g.iter_mut().zip(v) {
                    *g -= c * v;
                }
            }
            for g in g.iter_mut() {
                *g = g.max(0.0);
            }
        });
        contraction
    }
}

/// Gaussian elimination with partial pivoting on an m × m system.
fn solve_dense(a: &mut [f64], b: &mut [f64], m: usize) -> Option<Vec<f64>> {
    for col in 0..m {
        let pivot =
            (col..m).max_by(|&i, &j| a[i * m + col].abs().total_cmp(&a[j * m + col].abs()))?;
        if a[pivot * m + col].abs() < 1e-300 {
            return None;
        }
        for k in 0..m {
            a.swap(col * m + k, pivot * m + k);
        }
        b.swap(col, pivot);
        for row in col + 1..m {
            let factor = a[row * m + col] / a[col * m + col];
            for k in col..m {
                a[row * m + k] -= factor * a[col * m + k];
            }
            b[row] -= factor * b[col];
        }
    }
    let mut x = vec![0.0; m];
    for row in (0..m).rev() {
        let s: f64 = (row + 1..m).map(|k| a[row * m + k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row * m + row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}
