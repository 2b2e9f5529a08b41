//! The unsteady RTE over a set of discrete directions with upwind FTCS (Murray §3.4.1;
//! ch. 3; the sign of ω·∇L corrected, docs/reference-cases.md), isotropic scattering:
//!
//! (1/c) ∂L_d/∂t + ω_d·∇L_d = −σ_t L_d + (σ_s φ + q)/(4π),   φ = Σ_d w_d L_d,
//!
//! per step of cΔt:
//!
//! L_d′ = L_d − r Σ_a |ω_a| (L_d − L_d,upwind(a)) − K L_d + cΔt (σ_s φ + q)/(4π),
//!
//! r = cΔt/h, K = cΔt σ_t. (The thesis prints the streaming term
//! with a + sign, a typo: it moves to the right-hand side with a minus.) Vacuum edges
//! (nothing enters). With few directions a point source's light leaves along the
//! directions only: the ray artefacts, measured by [`angular_error`].
//!
//! Stability ([`crate::stability::ordinates`]): von Neumann r·S ≤ 1 − K/2, positivity
//! r·S + K ≤ 1, S = max_d |ω_x| + |ω_y| + |ω_z| (√3 for level-symmetric sets' diagonal
//! directions). The thesis states none.

use lucent_core::{History, StopReason, Stopping};
use lucent_optics::SphericalQuadrature;
use rayon::prelude::*;

use crate::error::ExplicitError;
use crate::lattice::{GrowthMonitor, Lattice};

/// Settings of [`march`].
#[derive(Debug, Clone, PartialEq)]
pub struct OrdinatesSettings {
    /// cΔt (length).
    pub time_step: f64,
    /// When to stop: the residual is ‖φ′ − φ‖/(cΔt‖q‖) per step, `max_iterations` the most
    /// steps.
    pub stopping: Stopping,
    /// Run beyond the von Neumann bound (studies).
    pub allow_unstable: bool,
}

/// The result of [`march`].
#[derive(Debug, Clone, PartialEq)]
pub struct OrdinatesSolution {
    /// φ = Σ w_d L_d per cell.
    pub fluence: Vec<f64>,
    /// Steps run.
    pub steps: usize,
    /// Relative residual per step.
    pub residuals: Vec<f64>,
    /// Why it stopped.
    pub stop_reason: StopReason,
}

/// Marches L_d to steady state on a homogeneous-or-not medium (σ_t, σ_s per cell,
/// 1/length) with isotropic source density `source` (power per volume).
pub fn march(
    lattice: &Lattice,
    quadrature: &SphericalQuadrature,
    sigma_t: &[f64],
    sigma_s: &[f64],
    source: &[f64],
    settings: &OrdinatesSettings,
) -> Result<OrdinatesSolution, ExplicitError> {
    for (name, f) in [("σ_t", sigma_t), ("σ_s", sigma_s), ("source", source)] {
        lattice.check_field(name, f)?;
    }
    if sigma_t.iter().zip(sigma_s).any(|(t, s)| *s < 0.0 || s > t) {
        return Err(ExplicitError::Invalid(
            "need 0 ≤ σ_s ≤ σ_t in every cell".into(),
        ));
    }
    let dt = settings.time_step;
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(ExplicitError::Invalid(format!("time step {dt}")));
    }
    let dirs = quadrature.directions();
    let weights = quadrature.weights();
    let s_max = dirs
        .iter()
        .map(|d| d.abs().element_sum())
        .fold(0.0, f64::max);
    let k_max = dt * sigma_t.iter().fold(0.0f64, |a, &b| a.max(b));
    let r = dt / lattice.spacing;
    let limit = crate::stability::ordinates::von_neumann_limit(s_max, k_max);
    if r > limit * (1.0 + 1e-12) && !settings.allow_unstable {
        return Err(ExplicitError::Unstable {
            scheme: "FTCS ordinates",
            parameter: "r = cΔt/h",
            limit,
            requested: r,
        });
    }
    let n = lattice.len();
    let m = dirs.len();
    let s = lattice.strides();
    let mut radiance = vec![0.0f64; n * m];
    let mut next = vec![0.0f64; n * m];
    let mut phi = vec![0.0f64; n];
    let q_norm = source
        .iter()
        .map(|q| q * q)
        .sum::<f64>()
        .sqrt()
        .max(f64::MIN_POSITIVE);
    let monitor = GrowthMonitor {
        reference: source.iter().fold(0.0f64, |a, b| a.max(b.abs()))
            * dt
            * settings.stopping.max_iterations.min(1 << 40) as f64
            / (4.0 * std::f64::consts::PI)
            + f64::MIN_POSITIVE,
        factor: 1e6,
    };
    let four_pi = 4.0 * std::f64::consts::PI;
    let mut history = History::start();
    let mut step = 0;
    loop {
        step += 1;
        {
            let (radiance, phi) = (&radiance, &phi);
            next.par_chunks_mut(m).enumerate().for_each(|(g, out)| {
                let emission = dt * (sigma_s[g] * phi[g] + source[g]) / four_pi;
                let at = lattice.coords(g);
                // The neighbours' blocks of m radiances, low and high, per axis.
                let blocks: [[Option<usize>; 2]; 3] = std::array::from_fn(|axis| {
                    [
                        (at[axis] > 0).then(|| (g - s[axis]) * m),
                        (at[axis] + 1 < lattice.dims[axis]).then(|| (g + s[axis]) * m),
                    ]
                });
                let damping = 1.0 - dt * sigma_t[g];
                for (d, o) in out.iter_mut().enumerate() {
                    let l = radiance[g * m + d];
                    let mut change = 0.0;
                    for axis in 0..3 {
                        let w = dirs[d][axis];
                        if w != 0.0 {
                            let side = usize::from(w < 0.0);
                            let up = blocks[axis][side].map_or(0.0, |b| radiance[b + d]);
                            change += w.abs() * (l - up);
                        }
                    }
                    *o = damping * l - r * change + emission;
                }
            });
        }
        if let Some(stop_reason) = monitor.check(&next, step) {
            return Ok(OrdinatesSolution {
                fluence: phi,
                steps: step,
                residuals: history.into_residuals(),
                stop_reason,
            });
        }
        std::mem::swap(&mut radiance, &mut next);
        let new_phi: Vec<f64> = radiance
            .par_chunks(m)
            .map(|l| l.iter().zip(weights).map(|(l, w)| l * w).sum())
            .collect();
        let change = new_phi
            .iter()
            .zip(&phi)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        let residual = change / (dt * q_norm);
        phi = new_phi;
        if let Some(stop_reason) = history.record_step(&settings.stopping, step, residual, change) {
            return Ok(OrdinatesSolution {
                fluence: phi,
                steps: step,
                residuals: history.into_residuals(),
                stop_reason,
            });
        }
    }
}

/// The angular (ray-effect) error of `fluence`: its relative L2 difference from
/// `reference`, the same scheme on the same grid with many more directions, over the cells
/// at least `min_radius` from `centre` (the source's own cells are left out). The spatial
/// error of first-order upwind is anisotropic too; comparing with the same scheme isolates
/// the part the directions cause.
pub fn angular_error(
    lattice: &Lattice,
    fluence: &[f64],
    reference: &[f64],
    centre: glam::DVec3,
    min_radius: f64,
) -> f64 {
    let (mut difference, mut size) = (0.0, 0.0);
    for c in 0..lattice.len() {
        let x = lattice.centre(lattice.coords(c).map(|v| v as isize));
        if (x - centre).length() >= min_radius {
            difference += (fluence[c] - reference[c]).powi(2);
            size += reference[c].powi(2);
        }
    }
    if size > 0.0 {
        (difference / size).sqrt()
    } else {
        0.0
    }
}
