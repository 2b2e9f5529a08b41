//! Iterative and direct solvers: Jacobi and Gauss–Seidel on a sparse matrix; BiCGSTAB and
//! restarted GMRES on any [`LinearOperator`] (non-symmetric systems); a dense LU with
//! partial pivoting for small systems. Each iterative solver reports its residual history
//! and why it stopped, PETSc-style.

use lucent_core::{StopReason, Stopping};

use crate::error::FemError;
use crate::operator::{LinearOperator, dot, norm};

/// The finite-element solvers' stopping rule when a caller asks for nothing else: a
/// relative residual of 10⁻¹⁰, 10 000 iterations, divergence at 10⁸ times the initial
/// residual (Jacobi on Murray's system must be seen to blow up, not merely stall).
pub fn default_stopping() -> Stopping {
    Stopping {
        relative_tolerance: 1e-10,
        max_iterations: 10_000,
        divergence: 1e8,
        ..Stopping::default()
    }
}

/// A solve's history.
#[derive(Debug, Clone, PartialEq)]
pub struct Convergence {
    /// Relative residual before the first iteration and after each.
    pub residuals: Vec<f64>,
    /// Why it stopped.
    pub stop_reason: StopReason,
}

fn residual(op: &dyn LinearOperator, b: &[f64], x: &[f64], r: &mut [f64]) {
    op.apply(x, r);
    for (r, b) in r.iter_mut().zip(b) {
        *r = b - *r;
    }
}

/// `Some` if the iteration must stop at relative residual `rel` (of ‖b‖ = `b_norm`), by
/// the one rule of [`Stopping::verdict`].
fn verdict(
    stopping: &Stopping,
    rel: f64,
    b_norm: f64,
    iteration: usize,
    started: std::time::Instant,
) -> Option<StopReason> {
    stopping.verdict(iteration, rel, rel * b_norm, 1.0, started)
}

/// The operator, right-hand side and iterate must have one size.
fn check_sizes(op: &dyn LinearOperator, b: &[f64], x: &[f64]) -> Result<(), FemError> {
    if b.len() != op.dim() || x.len() != op.dim() {
        return Err(FemError::Invalid(format!(
            "an operator of dimension {} with a right-hand side of {} and an iterate of {}",
            op.dim(),
            b.len(),
            x.len()
        )));
    }
    Ok(())
}

fn diagonal(a: &sprs::CsMat<f64>) -> Result<Vec<f64>, FemError> {
    (0..a.rows())
        .map(|i| match a.get(i, i) {
            Some(&d) if d != 0.0 => Ok(d),
            _ => Err(FemError::Singular { column: i }),
        })
        .collect()
}

/// Jacobi iteration x ← x + D⁻¹(b − Ax) from `x`. Diverges (stopped with
/// `DivergedGrowth`) where the iteration matrix's spectral radius exceeds 1. On divergence
/// `x` holds the last iterate whose residual was still finite.
pub fn jacobi(
    a: &sprs::CsMat<f64>,
    b: &[f64],
    x: &mut [f64],
    stopping: &Stopping,
) -> Result<Convergence, FemError> {
    check_sizes(a, b, x)?;
    let d = diagonal(a)?;
    let b_norm = norm(b).max(f64::MIN_POSITIVE);
    let started = std::time::Instant::now();
    let mut r = vec![0.0; b.len()];
    let mut residuals = Vec::new();
    let mut last = x.to_vec();
    let mut iteration = 0;
    loop {
        residual(a, b, x, &mut r);
        let rel = norm(&r) / b_norm;
        residuals.push(rel);
        if let Some(stop_reason) = verdict(stopping, rel, b_norm, iteration, started) {
            if !rel.is_finite() {
                x.copy_from_slice(&last);
            }
            return Ok(Convergence {
                residuals,
                stop_reason,
            });
        }
        last.copy_from_slice(x);
        for ((x, r), d) in x.iter_mut().zip(&r).zip(&d) {
            *x += r / d;
        }
        iteration += 1;
    }
}

/// Forward Gauss–Seidel sweeps (CSR rows in order) from `x`.
pub fn gauss_seidel(
    a: &sprs::CsMat<f64>,
    b: &[f64],
    x: &mut [f64],
    stopping: &Stopping,
) -> Result<Convergence, FemError> {
    check_sizes(a, b, x)?;
    let d = diagonal(a)?;
    let csr = a.to_csr();
    let b_norm = norm(b).max(f64::MIN_POSITIVE);
    let started = std::time::Instant::now();
    let mut r = vec![0.0; b.len()];
    let mut residuals = Vec::new();
    let mut iteration = 0;
    loop {
        residual(&csr, b, x, &mut r);
        let rel = norm(&r) / b_norm;
        residuals.push(rel);
        if let Some(stop_reason) = verdict(stopping, rel, b_norm, iteration, started) {
            return Ok(Convergence {
                residuals,
                stop_reason,
            });
        }
        for (i, row) in csr.outer_iterator().enumerate() {
            let off: f64 = row
                .iter()
                .filter(|(j, _)| *j != i)
                .map(|(j, v)| v * x[j])
                .sum();
            x[i] = (b[i] - off) / d[i];
        }
        iteration += 1;
    }
}

/// BiCGSTAB (van der Vorst 1992) from `x`, unpreconditioned.
pub fn bicgstab(
    op: &dyn LinearOperator,
    b: &[f64],
    x: &mut [f64],
    stopping: &Stopping,
) -> Result<Convergence, FemError> {
    check_sizes(op, b, x)?;
    let n = b.len();
    let b_norm = norm(b).max(f64::MIN_POSITIVE);
    let started = std::time::Instant::now();
    let mut r = vec![0.0; n];
    residual(op, b, x, &mut r);
    let r0 = r.clone();
    let (mut rho, mut alpha, mut omega) = (1.0, 1.0, 1.0);
    let (mut v, mut p, mut s, mut t) = (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let mut residuals = vec![norm(&r) / b_norm];
    loop {
        let iteration = residuals.len() - 1;
        if let Some(stop_reason) =
            verdict(stopping, residuals[iteration], b_norm, iteration, started)
        {
            return Ok(Convergence {
                residuals,
                stop_reason,
            });
        }
        let rho_new = dot(&r0, &r);
        if rho_new == 0.0 || omega == 0.0 {
            // Breakdown (ρ or ω vanished): stop with the current iterate and its residual.
            residual(op, b, x, &mut r);
            return Ok(Convergence {
                stop_reason: StopReason::IterationLimit {
                    residual: norm(&r) / b_norm,
                },
                residuals,
            });
        }
        let beta = (rho_new / rho) * (alpha / omega);
        rho = rho_new;
        for i in 0..n {
            p[i] = r[i] + beta * (p[i] - omega * v[i]);
        }
        op.apply(&p, &mut v);
        alpha = rho / dot(&r0, &v);
        for i in 0..n {
            s[i] = r[i] - alpha * v[i];
        }
        op.apply(&s, &mut t);
        let tt = dot(&t, &t);
        omega = if tt > 0.0 { dot(&t, &s) / tt } else { 0.0 };
        for i in 0..n {
            x[i] += alpha * p[i] + omega * s[i];
            r[i] = s[i] - omega * t[i];
        }
        residuals.push(norm(&r) / b_norm);
    }
}

/// Restarted GMRES(m) from `x` (modified Gram–Schmidt, Givens rotations). One iteration
/// is one Arnoldi step (one matrix–vector product).
pub fn gmres(
    op: &dyn LinearOperator,
    b: &[f64],
    x: &mut [f64],
    restart: usize,
    stopping: &Stopping,
) -> Result<Convergence, FemError> {
    check_sizes(op, b, x)?;
    let n = b.len();
    let m = restart.max(1);
    let b_norm = norm(b).max(f64::MIN_POSITIVE);
    let started = std::time::Instant::now();
    let mut r = vec![0.0; n];
    residual(op, b, x, &mut r);
    let mut residuals = vec![norm(&r) / b_norm];
    let mut iteration = 0;
    // Asked after every Arnoldi step: a restart cycle of m products can outlast the time
    // a stop may take (0.3-0.5 s at 24³ on one thread); the cycle then ends at the steps
    // it has, and the verdict at the top of the loop names the stop.
    let interrupt = stopping.interrupt(started);
    loop {
        let beta = norm(&r);
        if let Some(stop_reason) = verdict(stopping, beta / b_norm, b_norm, iteration, started) {
            return Ok(Convergence {
                residuals,
                stop_reason,
            });
        }
        let mut basis: Vec<Vec<f64>> = vec![r.iter().map(|v| v / beta).collect()];
        let mut h = vec![vec![0.0; m]; m + 1];
        let (mut cs, mut sn) = (vec![0.0; m], vec![0.0; m]);
        let mut g = vec![0.0; m + 1];
        g[0] = beta;
        let mut k_done = 0;
        for k in 0..m {
            let mut w = vec![0.0; n];
            op.apply(&basis[k], &mut w);
            for (j, q) in basis.iter().enumerate() {
                h[j][k] = dot(&w, q);
                for (w, q) in w.iter_mut().zip(q) {
                    *w -= h[j][k] * q;
                }
            }
            h[k + 1][k] = norm(&w);
            for j in 0..k {
                let t = cs[j] * h[j][k] + sn[j] * h[j + 1][k];
                h[j + 1][k] = -sn[j] * h[j][k] + cs[j] * h[j + 1][k];
                h[j][k] = t;
            }
            let d = (h[k][k] * h[k][k] + h[k + 1][k] * h[k + 1][k]).sqrt();
            (cs[k], sn[k]) = if d > 0.0 {
                (h[k][k] / d, h[k + 1][k] / d)
            } else {
                (1.0, 0.0)
            };
            h[k][k] = d;
            h[k + 1][k] = 0.0;
            g[k + 1] = -sn[k] * g[k];
            g[k] *= cs[k];
            iteration += 1;
            k_done = k + 1;
            let rel = g[k + 1].abs() / b_norm;
            residuals.push(rel);
            if rel <= stopping.relative_tolerance
                || iteration >= stopping.max_iterations
                || d == 0.0
                || interrupt.halted()
            {
                break;
            }
            let wn = norm(&w);
            if wn == 0.0 {
                break;
            }
            basis.push(w.iter().map(|v| v / wn).collect());
        }
        // Back substitution for y, then x += Q y.
        let mut y = vec![0.0; k_done];
        for i in (0..k_done).rev() {
            let s: f64 = (i + 1..k_done).map(|j| h[i][j] * y[j]).sum();
            y[i] = (g[i] - s) / h[i][i];
        }
        for (j, yj) in y.iter().enumerate() {
            for (x, q) in x.iter_mut().zip(&basis[j]) {
                *x += yj * q;
            }
        }
        residual(op, b, x, &mut r);
        // The true residual replaces the estimate at each restart.
        if let Some(last) = residuals.last_mut() {
            *last = norm(&r) / b_norm;
        }
    }
}

/// Preconditioned conjugate gradients from `x` for a symmetric positive-definite `op`;
/// `precondition(r, z)` sets z ≈ A⁻¹ r with a symmetric positive-definite approximation
/// (the identity, Jacobi, a symmetric multigrid cycle).
pub fn conjugate_gradient(
    op: &dyn LinearOperator,
    b: &[f64],
    x: &mut [f64],
    stopping: &Stopping,
    mut precondition: impl FnMut(&[f64], &mut [f64]),
) -> Result<Convergence, FemError> {
    check_sizes(op, b, x)?;
    let n = b.len();
    let b_norm = norm(b).max(f64::MIN_POSITIVE);
    let started = std::time::Instant::now();
    let mut r = vec![0.0; n];
    residual(op, b, x, &mut r);
    let mut z = vec![0.0; n];
    precondition(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let mut ap = vec![0.0; n];
    let mut residuals = vec![norm(&r) / b_norm];
    loop {
        let iteration = residuals.len() - 1;
        if let Some(stop_reason) =
            verdict(stopping, residuals[iteration], b_norm, iteration, started)
        {
            return Ok(Convergence {
                residuals,
                stop_reason,
            });
        }
        op.apply(&p, &mut ap);
        let alpha = rz / dot(&p, &ap);
        for i in 0..n {
            x[i] += alpha * p[i];
            r[i] -= alpha * ap[i];
        }
        residuals.push(norm(&r) / b_norm);
        z.fill(0.0);
        precondition(&r, &mut z);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        for i in 0..n {
            p[i] = z[i] + beta * p[i];
        }
    }
}

/// The largest system [`lu_solve`] accepts.
pub const DENSE_LIMIT: usize = 6000;

/// Solves A x = b by dense LU with partial pivoting (A given as any operator, expanded
/// column by column): [`DenseLu::factor`] and one [`DenseLu::solve`].
pub fn lu_solve(op: &dyn LinearOperator, b: &[f64]) -> Result<Vec<f64>, FemError> {
    check_sizes(op, b, b)?;
    Ok(DenseLu::factor(op)?.solve(b))
}

/// The LU factors of a dense matrix with partial pivoting, P A = L U: factored once in
/// O(n³), each [`DenseLu::solve`] then costs O(n²) (a multigrid's coarsest level is
/// solved this way once per cycle).
#[derive(Debug, Clone)]
pub struct DenseLu {
    n: usize,
    /// L below the diagonal (unit diagonal implied), U on and above it; row-major.
    factors: Vec<f64>,
    /// Row `k` of the factors came from row `pivots[k]` of the permuted right-hand side
    /// at step `k`: the swaps in the order they were made.
    pivots: Vec<usize>,
}

impl DenseLu {
    /// Factors `op` (at most [`DENSE_LIMIT`] unknowns; an error naming the column if a
    /// pivot is below 10⁻¹⁴ of the largest entry).
    pub fn factor(op: &dyn LinearOperator) -> Result<Self, FemError> {
        let n = op.dim();
        if n > DENSE_LIMIT {
            return Err(FemError::TooLarge {
                unknowns: n,
                limit: DENSE_LIMIT,
            });
        }
        let mut a = vec![0.0; n * n];
        let mut e = vec![0.0; n];
        let mut col = vec![0.0; n];
        for j in 0..n {
            e.fill(0.0);
            e[j] = 1.0;
            op.apply(&e, &mut col);
            for i in 0..n {
                a[i * n + j] = col[i];
            }
        }
        let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mut pivots = Vec::with_capacity(n);
        for k in 0..n {
            let p = (k..n)
                .max_by(|&i, &j| a[i * n + k].abs().total_cmp(&a[j * n + k].abs()))
                .unwrap_or(k);
            let pivot = a[p * n + k].abs();
            if pivot.is_nan() || pivot <= 1e-14 * scale {
                return Err(FemError::Singular { column: k });
            }
            if p != k {
                for j in 0..n {
                    a.swap(k * n + j, p * n + j);
                }
            }
            pivots.push(p);
            let pivot = a[k * n + k];
            let (done, rest) = a.split_at_mut((k + 1) * n);
            let row_k = &done[k * n..];
            for row in rest.chunks_exact_mut(n) {
                let f = row[k] / pivot;
                row[k] = f;
                if f != 0.0 {
                    for (r, u) in row[k + 1..].iter_mut().zip(&row_k[k + 1..]) {
                        *r -= f * u;
                    }
                }
            }
        }
        Ok(Self {
            n,
            factors: a,
            pivots,
        })
    }

    /// Unknowns.
    pub fn dim(&self) -> usize {
        self.n
    }

    /// x = A⁻¹ b (`b` of [`DenseLu::dim`] entries).
    pub fn solve(&self, b: &[f64]) -> Vec<f64> {
        let (n, a) = (self.n, &self.factors);
        let mut x = b.to_vec();
        for (k, &p) in self.pivots.iter().enumerate() {
            x.swap(k, p);
        }
        for i in 0..n {
            let s: f64 = (0..i).map(|j| a[i * n + j] * x[j]).sum();
            x[i] -= s;
        }
        for k in (0..n).rev() {
            let s: f64 = (k + 1..n).map(|j| a[k * n + j] * x[j]).sum();
            x[k] = (x[k] - s) / a[k * n + k];
        }
        x
    }
}
