//! Restarted GMRES (Saad & Schultz 1986) on the DSA-preconditioned transport fixed point,
//! the outer iteration of current discrete-ordinates codes (Warsa, Wareing & Morel 2004;
//! PDT, Denovo).
//!
//! # The system
//!
//! One step of DSA-accelerated source iteration is an affine map of the iterate
//! x = (J, I): the in-scattered radiance per cell and storage direction, and the radiance
//! entering through the boundary's face cells (which a reflecting boundary feeds back from
//! the outgoing current):
//!
//! H(x) = c + M x,  c = H(0),  M x = (I + C) K x − C x,
//!
//! with K one transport sweep of the scattering source σ_s J and the inflow I alone
//! (no fixed source, no sky: `homogeneous`), followed by the scattering product, and C the
//! DSA correction, linear in (x, Kx) because its multigrid runs a fixed number of V-cycles
//! from zero. The fixed point x = H(x) is the solution of source iteration; GMRES solves
//! (I − M) x = c for it, each iteration applying M once (one sweep). Source iteration with
//! DSA removes the isotropic error only, and the first moments' error still contracts by
//! about ωg per sweep; the preconditioned operator's spectrum is a few clusters (one per
//! Legendre order of the phase function), which a Krylov method resolves in a few
//! iterations each instead of contracting geometrically.
//!
//! # The inner product
//!
//! ⟨a, b⟩ = Σ_cells σ_s² Σ_m w_m a_Jm b_Jm + κ Σ_faces a_I b_I: the scattering source's norm
//! (the one the source iteration's stopping rule uses; J in non-scattering cells never
//! feeds anything back, so a semi-norm that ignores it is the right one), plus the inflow
//! weighted by κ = 4π times the mean σ_s², so that an inflow radiance counts like the same
//! in-scattered radiance in a cell. GMRES minimises the residual in this norm; the fixed
//! point does not depend on it.
//!
//! # Precision and memory
//!
//! The basis is stored like the iterate, J in f32 (the solver's storage precision) and
//! the inflow in f64; every inner product and update is formed in f64. Orthogonalisation
//! is classical Gram–Schmidt (one pass over the basis for all inner products instead of
//! one per vector), repeated where it cancelled (the DGKS criterion), which keeps it as
//! stable as modified Gram–Schmidt. A restart
//! starts from the true residual c − (I − M)x, at the cost of one application, so the
//! drift of the Arnoldi estimate with an f32 basis does not accumulate. Memory: `restart + 1` vectors of J (4 bytes per cell and storage
//! direction each).

use rayon::prelude::*;

/// Cells per parallel chunk: sums over chunks are added in chunk order, so the results do
/// not depend on the threads.
const ROWS: usize = 256;

/// An iterate or Krylov vector: in-scattered radiance per cell and storage direction
/// (block order, f32) and the inflow per face cell of the six faces.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Iterate {
    pub inscattered: Vec<f32>,
    pub inflow: [Vec<f64>; 6],
}

impl Iterate {
    /// The zero vector shaped like `like`.
    pub(crate) fn zeros_like(like: &Self) -> Self {
        Self {
            inscattered: vec![0.0; like.inscattered.len()],
            inflow: std::array::from_fn(|f| vec![0.0; like.inflow[f].len()]),
        }
    }
}

/// The inner product's weights.
pub(crate) struct Space {
    /// σ_s² per cell (block order).
    pub cell_weight: Vec<f64>,
    /// w_m per storage direction.
    pub direction_weight: Vec<f64>,
    /// κ, the weight of an inflow value.
    pub inflow_weight: f64,
}

impl Space {
    fn storage(&self) -> usize {
        self.direction_weight.len()
    }

    /// ⟨w, v_i⟩ for every vector of `basis`, in one pass over them.
    fn dots(&self, w: &Iterate, basis: &[&Iterate]) -> Vec<f64> {
        let m = self.storage();
        let k = basis.len();
        let chunk = ROWS * m;
        let partial: Vec<Vec<f64>> = w
            .inscattered
            .par_chunks(chunk)
            .enumerate()
            .map(|(c, wc)| {
                let mut sums = vec![0.0f64; k];
                let start = c * chunk;
                for (i, v) in basis.iter().enumerate() {
                    let vc = &v.inscattered[start..start + wc.len()];
                    let mut s = 0.0;
                    for ((wr, vr), sw) in wc
                        .chunks(m)
                        .zip(vc.chunks(m))
                        .zip(&self.cell_weight[c * ROWS..])
                    {
                        if *sw == 0.0 {
                            continue;
                        }
                        let mut row = 0.0;
                        for q in 0..m {
                            row += self.direction_weight[q] * f64::from(wr[q]) * f64::from(vr[q]);
                        }
                        s += sw * row;
                    }
                    sums[i] = s;
                }
                sums
            })
            .collect();
        let mut dots = vec![0.0f64; k];
        for p in partial {
            for (d, s) in dots.iter_mut().zip(p) {
                *d += s;
            }
        }
        for (d, v) in dots.iter_mut().zip(basis) {
            let faces: f64 = (0..6)
                .map(|f| {
                    w.inflow[f]
                        .iter()
                        .zip(&v.inflow[f])
                        .map(|(a, b)| a * b)
                        .sum::<f64>()
                })
                .sum();
            *d += self.inflow_weight * faces;
        }
        dots
    }

    /// ‖v‖.
    pub(crate) fn norm(&self, v: &Iterate) -> f64 {
        self.dots(v, &[v])[0].max(0.0).sqrt()
    }

    /// w ← a·w + Σ_i y_i v_i, in one pass (each entry formed in f64, stored once).
    fn combine(&self, w: &mut Iterate, a: f64, basis: &[&Iterate], y: &[f64]) {
        let chunk = ROWS * self.storage();
        w.inscattered
            .par_chunks_mut(chunk)
            .enumerate()
            .for_each(|(c, wc)| {
                let start = c * chunk;
                let mut acc: Vec<f64> = wc.iter().map(|x| a * f64::from(*x)).collect();
                for (v, yi) in basis.iter().zip(y) {
                    for (s, x) in acc.iter_mut().zip(&v.inscattered[start..start + wc.len()]) {
                        *s += yi * f64::from(*x);
                    }
                }
                for (x, s) in wc.iter_mut().zip(acc) {
                    *x = s as f32;
                }
            });
        for f in 0..6 {
            for (i, x) in w.inflow[f].iter_mut().enumerate() {
                *x = a * *x
                    + basis
                        .iter()
                        .zip(y)
                        .map(|(v, yi)| yi * v.inflow[f][i])
                        .sum::<f64>();
            }
        }
    }
}

/// What the outer iteration reports after each application of M.
pub(crate) struct GmresStep {
    /// ‖r_k‖ / ‖c‖ (the Arnoldi estimate).
    pub relative: f64,
    /// ‖r_k‖.
    pub absolute: f64,
}

/// Solves (I − M) x = c from x = 0 by GMRES(`restart`). `apply(v)` returns M v;
/// `judge(k, step)` is told the residual after the k-th application and returns `true` to
/// stop. Returns the iterate reached.
pub(crate) fn gmres<E>(
    space: &Space,
    c: &Iterate,
    restart: usize,
    mut apply: impl FnMut(&Iterate) -> Result<Iterate, E>,
    mut judge: impl FnMut(usize, GmresStep) -> bool,
) -> Result<Iterate, E> {
    let restart = restart.max(1); // the callers refuse 0
    let mut x = Iterate::zeros_like(c);
    let c_norm = space.norm(c);
    let mut applications = 0;
    if c_norm == 0.0 || !c_norm.is_finite() {
        judge(
            0,
            GmresStep {
                relative: if c_norm == 0.0 { 0.0 } else { f64::NAN },
                absolute: c_norm,
            },
        );
        return Ok(x);
    }
    // The first residual is c itself (x = 0).
    let mut r = c.clone();
    let mut beta = c_norm;
    loop {
        // One cycle of Arnoldi from v₀ = r/β.
        let mut basis = vec![r];
        space.combine(&mut basis[0], 1.0 / beta, &[], &[]);
        // H̄ column by column; Givens rotations (cs, sn) reduce it to upper triangular R,
        // g = Qᵀ β e₁ holds the residual norm in its last entry.
        let mut h: Vec<Vec<f64>> = Vec::new();
        let mut rotations: Vec<(f64, f64)> = Vec::new();
        let mut g = vec![beta];
        let mut stop = false;
        for j in 0..restart {
            let mv = apply(&basis[j])?;
            applications += 1;
            // w = v_j − M v_j
            let mut w = mv;
            space.combine(&mut w, -1.0, &[&basis[j]], &[1.0]);
            // Classical Gram–Schmidt, repeated only where it cancelled (Daniel, Gragg,
            // Kaufman & Stewart 1976): when the projection removed more than 1 − 1/√2 of
            // ‖w‖, rounding may have left w short of orthogonal, and a second pass restores
            // it. The first pass forms ‖w‖² with the coefficients.
            let mut column = vec![0.0f64; j + 2];
            let mut norm = 0.0;
            for pass in 0..2 {
                let (coefficients, before) = {
                    let mut vectors: Vec<&Iterate> = basis.iter().collect();
                    if pass == 0 {
                        vectors.push(&w);
                    }
                    let mut dots = space.dots(&w, &vectors);
                    let before = if pass == 0 {
                        dots.pop().unwrap_or(0.0).max(0.0).sqrt()
                    } else {
                        norm
                    };
                    (dots, before)
                };
                let vectors: Vec<&Iterate> = basis.iter().collect();
                let negated: Vec<f64> = coefficients.iter().map(|v| -v).collect();
                space.combine(&mut w, 1.0, &vectors, &negated);
                for (col, v) in column.iter_mut().zip(&coefficients) {
                    *col += v;
                }
                norm = space.norm(&w);
                if norm > std::f64::consts::FRAC_1_SQRT_2 * before {
                    break;
                }
            }
            column[j + 1] = norm;
            // Apply the previous rotations, then one new one to zero the subdiagonal.
            for (i, &(cs, sn)) in rotations.iter().enumerate() {
                let (a, b) = (column[i], column[i + 1]);
                column[i] = cs * a + sn * b;
                column[i + 1] = -sn * a + cs * b;
            }
            let (a, b) = (column[j], column[j + 1]);
            let radius = a.hypot(b);
            let (cs, sn) = if radius == 0.0 {
                (1.0, 0.0)
            } else {
                (a / radius, b / radius)
            };
            column[j] = radius;
            column[j + 1] = 0.0;
            rotations.push((cs, sn));
            let gj = g[j];
            g[j] = cs * gj;
            g.push(-sn * gj);
            h.push(column);
            let residual = g[j + 1].abs();
            stop = judge(
                applications,
                GmresStep {
                    relative: residual / c_norm,
                    absolute: residual,
                },
            );
            // A lucky breakdown (w in the span) means the solution is in the basis.
            let breakdown = norm <= 1e-14 * beta || norm.is_nan();
            if stop || breakdown || j + 1 == restart {
                break;
            }
            space.combine(&mut w, 1.0 / norm, &[], &[]);
            basis.push(w);
        }
        // y = R⁻¹ g (back substitution), x += V y.
        let k = h.len();
        let mut y = vec![0.0f64; k];
        for i in (0..k).rev() {
            let mut s = g[i];
            for (l, yl) in y.iter().enumerate().take(k).skip(i + 1) {
                s -= h[l][i] * yl;
            }
            y[i] = if h[i][i] == 0.0 { 0.0 } else { s / h[i][i] };
        }
        let refs: Vec<&Iterate> = basis.iter().take(k).collect();
        space.combine(&mut x, 1.0, &refs, &y);
        if stop {
            return Ok(x);
        }
        // The next cycle starts from the true residual r = c − (I − M)x, one application
        // more: the Arnoldi estimate drifts from it with an f32 basis, and a restart is
        // where that drift would otherwise accumulate.
        let mx = apply(&x)?;
        applications += 1;
        let mut next = c.clone();
        // r = c − x + M x
        space.combine(&mut next, 1.0, &[&x, &mx], &[-1.0, 1.0]);
        beta = space.norm(&next);
        r = next;
        if judge(
            applications,
            GmresStep {
                relative: beta / c_norm,
                absolute: beta,
            },
        ) || beta == 0.0
        {
            return Ok(x);
        }
    }
}
