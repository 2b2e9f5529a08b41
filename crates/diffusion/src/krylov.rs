//! Baseline iterative solvers on the same matrix-free operator, in f64: Jacobi, red–black
//! SOR, (preconditioned) conjugate gradients. They exist to be compared with multigrid
//! (`cargo xtask bench-diffusion`, `cargo xtask pareto`), and CG also solves the coarsest
//! multigrid level.

use rayon::prelude::*;

use crate::level::{Level, PARALLEL_MIN_CELLS, norm2};
use lucent_core::Stopping;

use crate::multigrid::Convergence;

/// Σ aᵢbᵢ in a fixed order (the same bits on every run and thread count).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    lucent_core::reduce::dot(a, b)
}

/// Preconditioned conjugate gradients for the symmetric positive definite A x = b;
/// `precondition(r, z)` applies z = M⁻¹ r for a symmetric positive definite M.
pub(crate) fn conjugate_gradient(
    level: &Level,
    b: &[f64],
    x: &mut [f64],
    stopping: &Stopping,
    precondition: impl FnMut(&[f64], &mut [f64]),
) -> Convergence {
    preconditioned_cg(level, b, x, stopping, false, precondition)
}

/// [`conjugate_gradient`] for a preconditioner that is not a fixed linear map (a K-cycle):
/// flexible CG, whose β = zₖ₊₁ᵀ(rₖ₊₁ − rₖ)/zₖᵀrₖ (Polak–Ribière) equals the usual one when
/// the preconditioner is linear and keeps the directions conjugate when it is not (Notay
/// 2000).
pub(crate) fn flexible_conjugate_gradient(
    level: &Level,
    b: &[f64],
    x: &mut [f64],
    stopping: &Stopping,
    precondition: impl FnMut(&[f64], &mut [f64]),
) -> Convergence {
    preconditioned_cg(level, b, x, stopping, true, precondition)
}

fn preconditioned_cg(
    level: &Level,
    b: &[f64],
    x: &mut [f64],
    stopping: &Stopping,
    flexible: bool,
    mut precondition: impl FnMut(&[f64], &mut [f64]),
) -> Convergence {
    let started = std::time::Instant::now();
    let n = b.len();
    let b_norm = norm2(b).max(f64::MIN_POSITIVE);
    let mut r = vec![0.0; n];
    let mut norm = level.residual(b, x, &mut r);
    let mut z = vec![0.0; n];
    precondition(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let mut ap = vec![0.0; n];
    let mut residuals = vec![norm / b_norm];
    let initial = residuals[0];
    loop {
        let iteration = residuals.len() - 1;
        if let Some(stop_reason) =
            stopping.verdict(iteration, norm / b_norm, norm, initial, started)
        {
            return Convergence {
                residuals,
                stop_reason,
            };
        }
        level.apply(&p, &mut ap);
        let pap = dot(&p, &ap);
        if pap <= 0.0 || !pap.is_finite() {
            // Breakdown: A (or M) is not positive definite on this vector.
            return Convergence {
                residuals,
                stop_reason: lucent_core::StopReason::DivergedNonFinite { iteration },
            };
        }
        let alpha = rz / pap;
        let previous = flexible.then(|| r.clone());
        x.par_iter_mut()
            .zip(p.par_iter())
            .with_min_len(PARALLEL_MIN_CELLS)
            .for_each(|(x, p)| *x += alpha * p);
        r.par_iter_mut()
            .zip(ap.par_iter())
            .with_min_len(PARALLEL_MIN_CELLS)
            .for_each(|(r, ap)| *r -= alpha * ap);
        norm = norm2(&r);
        residuals.push(norm / b_norm);
        precondition(&r, &mut z);
        let rz_new = dot(&r, &z);
        let beta = match &previous {
            Some(previous) => (rz_new - dot(previous, &z)) / rz,
            None => rz_new / rz,
        };
        rz = rz_new;
        p.par_iter_mut()
            .zip(z.par_iter())
            .with_min_len(PARALLEL_MIN_CELLS)
            .for_each(|(p, z)| *p = z + beta * *p);
    }
}

/// The loop every residual-driven iteration shares: compute r = b − A x, stop by the rules,
/// else let `step(x, r)` improve x and go round. `started` is when the solve began (so a
/// time budget counts any set-up done before the loop).
pub(crate) fn residual_iteration(
    level: &Level,
    b: &[f64],
    x: &mut [f64],
    stopping: &Stopping,
    started: std::time::Instant,
    mut step: impl FnMut(&mut [f64], &[f64]),
) -> Convergence {
    let b_norm = norm2(b).max(f64::MIN_POSITIVE);
    let mut r = vec![0.0; b.len()];
    let mut norm = level.residual(b, x, &mut r);
    let mut residuals = vec![norm / b_norm];
    let initial = residuals[0];
    loop {
        let iteration = residuals.len() - 1;
        if let Some(stop_reason) =
            stopping.verdict(iteration, norm / b_norm, norm, initial, started)
        {
            return Convergence {
                residuals,
                stop_reason,
            };
        }
        step(x, &r);
        norm = level.residual(b, x, &mut r);
        residuals.push(norm / b_norm);
    }
}

/// Jacobi iteration x ← x + ω D⁻¹(b − A x).
pub(crate) fn jacobi(
    level: &Level,
    b: &[f64],
    x: &mut [f64],
    omega: f64,
    stopping: &Stopping,
) -> Convergence {
    let started = std::time::Instant::now();
    residual_iteration(level, b, x, stopping, started, |x, r| {
        x.par_iter_mut()
            .zip(r.par_iter())
            .zip(level.inv_diag.par_iter())
            .for_each(|((x, r), d)| *x += omega * f64::from(*d) * r);
    })
}

/// Red–black successive over-relaxation with factor ω (1: Gauss–Seidel).
pub(crate) fn sor(
    level: &Level,
    b: &[f64],
    x: &mut [f64],
    omega: f64,
    stopping: &Stopping,
) -> Convergence {
    let started = std::time::Instant::now();
    residual_iteration(level, b, x, stopping, started, |x, _| {
        level.sor(b, x, 0, omega)
    })
}

/// The optimal SOR factor 2/(1 + √(1 − ρ_J²)) for a Jacobi spectral radius ρ_J.
pub fn optimal_sor_factor(jacobi_radius: f64) -> f64 {
    2.0 / (1.0 + (1.0 - jacobi_radius * jacobi_radius).max(0.0).sqrt())
}
