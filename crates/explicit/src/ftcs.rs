//! Murray's time-dependent diffusion with FTCS (thesis ch. 4, Eq. 4.4/4.8;
//! docs/reference-cases.md), marched to steady state.
//!
//! (1/c) ∂φ/∂t = D∇²φ + s ∇D·∇φ − σ_a φ + q, per step of cΔt:
//!
//! φ′ = φ + cΔt [ D_i Σ_nb (φ_nb − φ_i)/h² + s Σ_a (D_{a+} − D_{a−})(φ_{a+} − φ_{a−})/(4h²)
//!                − σ_a φ_i + q_i ]
//!
//! with s = +1, since ∇·(D∇φ) = D∇²φ **+** ∇D·∇φ ([`GradientSign::Conservative`]); the
//! thesis prints s = −1 (Eq. 4.3), kept as [`GradientSign::Printed`] for the study: it
//! converges to a different equation wherever D varies.
//!
//! Murray's parameters ([`murray_coefficients`]): β = D/Δ ∈ (0, 1], albedo α, g = 0, so
//! σ_a = (1 − α)/(3βΔ), and r = cΔt/Δ.
//!
//! Stability ([`crate::stability::ftcs_diffusion`]): von Neumann r ≤ 6β/(36β² + (1 − α))
//! (physical: cΔt ≤ 2/(σ_a + 12D/h²), taken with the largest D and σ_a); positivity needs
//! half the diffusive part; the thesis's Eq. 4.9 is safe and 2.2–3× too small. `march`
//! refuses a step beyond von Neumann unless `allow_unstable`.

use glam::DVec3;
use lucent_core::{History, StopReason, Stopping};
use rayon::prelude::*;

use crate::error::ExplicitError;
use crate::lattice::{GrowthMonitor, Lattice};

/// The sign of the ∇D·∇φ term.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum GradientSign {
    /// +∇D·∇φ: the expansion of ∇·(D∇φ).
    #[default]
    Conservative,
    /// −∇D·∇φ, as printed in the thesis (Eq. 4.3).
    Printed,
}

/// What lies beyond the grid.
#[derive(Clone, Copy)]
pub enum Edges<'a> {
    /// Periodic.
    Periodic,
    /// φ given at the ghost cell centres (Dirichlet); D extrapolated linearly.
    Dirichlet(&'a (dyn Fn(DVec3) -> f64 + Sync)),
}

impl std::fmt::Debug for Edges<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Edges::Periodic => write!(f, "Periodic"),
            Edges::Dirichlet(_) => write!(f, "Dirichlet(..)"),
        }
    }
}

/// A diffusion problem for FTCS.
#[derive(Debug, Clone, Copy)]
pub struct FtcsDiffusion<'a> {
    /// The grid.
    pub lattice: Lattice,
    /// D per cell (length).
    pub diffusion: &'a [f64],
    /// σ_a per cell (1/length).
    pub absorption: &'a [f64],
    /// Source q per cell (fluence per length, i.e. per unit cΔt).
    pub source: &'a [f64],
    /// The ∇D·∇φ sign.
    pub sign: GradientSign,
    /// Beyond the grid.
    pub edges: Edges<'a>,
}

/// How far and how to march.
#[derive(Debug, Clone, PartialEq)]
pub struct March {
    /// cΔt (length).
    pub time_step: f64,
    /// When to stop: the residual is ‖φ′ − φ‖/(cΔt‖q‖) per step (‖φ′ − φ‖/‖φ′‖ without a
    /// source), `max_iterations` the most steps.
    pub stopping: Stopping,
    /// Run beyond the von Neumann bound (studies); the growth monitor still stops it.
    pub allow_unstable: bool,
    /// Start (`None`: zero).
    pub initial: Option<Vec<f64>>,
}

/// A marched field.
#[derive(Debug, Clone, PartialEq)]
pub struct Marched {
    /// φ per cell.
    pub fluence: Vec<f64>,
    /// Steps run.
    pub steps: usize,
    /// Relative residual after each step.
    pub residuals: Vec<f64>,
    /// Why it stopped.
    pub stop_reason: StopReason,
}

/// Murray's (β, α) as D and σ_a per cell, g = 0: D = βΔ, σ_a = (1 − α)/(3βΔ).
pub fn murray_coefficients(
    spacing: f64,
    beta: &[f64],
    albedo: &[f64],
) -> Result<(Vec<f64>, Vec<f64>), ExplicitError> {
    if beta.len() != albedo.len()
        || beta.iter().any(|b| !(*b > 0.0 && *b <= 1.0))
        || albedo.iter().any(|a| !(0.0..=1.0).contains(a))
    {
        return Err(ExplicitError::Invalid(
            "Murray's parameters: β in (0, 1], α in [0, 1], one each per cell".into(),
        ));
    }
    let d = beta.iter().map(|b| b * spacing).collect();
    let sa = beta
        .iter()
        .zip(albedo)
        .map(|(b, a)| (1.0 - a) / (3.0 * b * spacing))
        .collect();
    Ok((d, sa))
}

impl FtcsDiffusion<'_> {
    /// The von Neumann limit of cΔt for this problem's largest D and σ_a.
    pub fn time_step_limit(&self) -> f64 {
        let d = self.diffusion.iter().fold(0.0f64, |a, &b| a.max(b));
        let s = self.absorption.iter().fold(0.0f64, |a, &b| a.max(b));
        crate::stability::ftcs_diffusion::time_step(d, s, self.lattice.spacing)
    }

    /// One FTCS step from `phi` into `out`.
    fn step(&self, phi: &[f64], out: &mut [f64], dt: f64) {
        let l = &self.lattice;
        let [nx, ny, _] = l.dims;
        let slab = nx * ny;
        let h2 = l.spacing * l.spacing;
        let sign = match self.sign {
            GradientSign::Conservative => 1.0,
            GradientSign::Printed => -1.0,
        };
        let [_, _, nz] = l.dims;
        let (phi_d, d, sa, q) = (phi, self.diffusion, self.absorption, self.source);
        out.par_chunks_mut(slab).enumerate().for_each(|(k, out)| {
            // Interior rows: every neighbour in the grid, straight index arithmetic.
            if k > 0 && k + 1 < nz && ny > 2 && nx > 2 {
                for j in 1..ny - 1 {
                    let row = k * slab + j * nx;
                    for i in 1..nx - 1 {
                        let g = row + i;
                        let (pi, di) = (phi_d[g], d[g]);
                        let mut laplacian = -6.0 * pi;
                        let mut gradient = 0.0;
                        for s in [1, nx, slab] {
                            let (pm, pp) = (phi_d[g - s], phi_d[g + s]);
                            laplacian += pm + pp;
                            gradient += (d[g + s] - d[g - s]) * (pp - pm);
                        }
                        out[j * nx + i] = pi
                            + dt * (di * laplacian / h2 + sign * gradient / (4.0 * h2)
                                - sa[g] * pi
                                + q[g]);
                    }
                }
            }
            let interior = |local: usize| {
                let (i, j) = (local % nx, local / nx);
                k > 0
                    && k + 1 < nz
                    && ny > 2
                    && nx > 2
                    && i > 0
                    && i + 1 < nx
                    && j > 0
                    && j + 1 < ny
            };
            for (local, o) in out.iter_mut().enumerate() {
                if interior(local) {
                    continue;
                }
                let g = k * slab + local;
                let at = l.coords(g).map(|v| v as isize);
                let (pi, di) = (phi[g], self.diffusion[g]);
                let mut laplacian = 0.0;
                let mut gradient = 0.0;
                for axis in 0..3 {
                    let (mut pv, mut dv) = ([0.0; 2], [di; 2]);
                    let mut ghost = [false; 2];
                    for (side, step) in [-1isize, 1].into_iter().enumerate() {
                        let mut to = at;
                        to[axis] += step;
                        let n = l.dims[axis] as isize;
                        if (0..n).contains(&to[axis]) || matches!(self.edges, Edges::Periodic) {
                            to[axis] = to[axis].rem_euclid(n);
                            let s = l.strides();
                            let c: usize = (0..3).map(|a| to[a] as usize * s[a]).sum();
                            pv[side] = phi[c];
                            dv[side] = self.diffusion[c];
                        } else if let Edges::Dirichlet(f) = self.edges {
                            pv[side] = f(l.centre(to));
                            ghost[side] = true;
                        }
                    }
                    // D beyond a Dirichlet edge: extrapolated linearly, so that ∇D keeps
                    // second order at the boundary cells.
                    match ghost {
                        [true, false] => dv[0] = 2.0 * di - dv[1],
                        [false, true] => dv[1] = 2.0 * di - dv[0],
                        _ => {}
                    }
                    laplacian += pv[0] + pv[1] - 2.0 * pi;
                    gradient += (dv[1] - dv[0]) * (pv[1] - pv[0]);
                }
                *o = pi
                    + dt * (di * laplacian / h2 + sign * gradient / (4.0 * h2)
                        - self.absorption[g] * pi
                        + self.source[g]);
            }
        });
    }

    /// Marches to steady state (or until `march` says stop).
    pub fn march(&self, march: &March) -> Result<Marched, ExplicitError> {
        let l = &self.lattice;
        l.check_field("diffusion", self.diffusion)?;
        l.check_field("absorption", self.absorption)?;
        l.check_field("source", self.source)?;
        if self.diffusion.iter().any(|&d| d < 0.0) || self.absorption.iter().any(|&s| s < 0.0) {
            return Err(ExplicitError::Invalid("D and σ_a must be ≥ 0".into()));
        }
        let dt = march.time_step;
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(ExplicitError::Invalid(format!("time step {dt}")));
        }
        let limit = self.time_step_limit();
        if dt > limit * (1.0 + 1e-12) && !march.allow_unstable {
            return Err(ExplicitError::Unstable {
                scheme: "FTCS diffusion",
                parameter: "cΔt",
                limit,
                requested: dt,
            });
        }
        let n = l.len();
        let mut phi = match &march.initial {
            Some(v) => {
                l.check_field("initial", v)?;
                v.clone()
            }
            None => vec![0.0; n],
        };
        let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let source_norm = norm(self.source);
        // The steady state is bounded by ‖q‖/min(σ_a) and by the data; the monitor's
        // reference is a generous bound on any stable run.
        let largest = |v: &[f64]| v.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        let reference = largest(&phi)
            + largest(self.source) * (l.len() as f64) * l.spacing.powi(2)
                / self
                    .diffusion
                    .iter()
                    .fold(f64::MAX, |a, &b| a.min(b))
                    .max(1e-300)
            + 1.0;
        let monitor = GrowthMonitor {
            reference,
            factor: 1e6,
        };
        let mut next = vec![0.0; n];
        let mut history = History::start();
        let mut steps = 0;
        loop {
            steps += 1;
            self.step(&phi, &mut next, dt);
            if let Some(stop_reason) = monitor.check(&next, steps) {
                return Ok(Marched {
                    fluence: phi,
                    steps,
                    residuals: history.into_residuals(),
                    stop_reason,
                });
            }
            let change: f64 = next
                .iter()
                .zip(&phi)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
                .sqrt();
            let scale = if source_norm > 0.0 {
                dt * source_norm
            } else {
                norm(&next).max(f64::MIN_POSITIVE)
            };
            let residual = change / scale;
            std::mem::swap(&mut phi, &mut next);
            if let Some(stop_reason) = history.record_step(&march.stopping, steps, residual, change)
            {
                return Ok(Marched {
                    fluence: phi,
                    steps,
                    residuals: history.into_residuals(),
                    stop_reason,
                });
            }
        }
    }
}
