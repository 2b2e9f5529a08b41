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
    let r = checked_ratio(
        quadrature,
        sigma_t.iter().fold(0.0f64, |a, &b| a.max(b)),
        settings,
        lattice.spacing,
    )?;
    let dirs = quadrature.directions();
    let weights = quadrature.weights();
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
    let monitor = growth_monitor(source.iter().fold(0.0f64, |a, b| a.max(b.abs())), settings);
    let mut history = History::start();
    let mut step = 0;
    loop {
        step += 1;
        {
            let (radiance, phi) = (&radiance, &phi);
            next.par_chunks_mut(m).enumerate().for_each(|(g, out)| {
                let at = lattice.coords(g);
                // The neighbours' blocks of m radiances, low and high, per axis.
                let blocks: [[Option<&[f64]>; 2]; 3] = std::array::from_fn(|axis| {
                    [
                        (at[axis] > 0).then(|| &radiance[(g - s[axis]) * m..(g - s[axis] + 1) * m]),
                        (at[axis] + 1 < lattice.dims[axis])
                            .then(|| &radiance[(g + s[axis]) * m..(g + s[axis] + 1) * m]),
                    ]
                });
                let cell = Cell {
                    sigma_t: sigma_t[g],
                    sigma_s: sigma_s[g],
                    source: source[g],
                    phi: phi[g],
                };
                cell_step(
                    dirs,
                    dt,
                    r,
                    &cell,
                    &radiance[g * m..(g + 1) * m],
                    &blocks,
                    out,
                );
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
            .map(|l| cell_fluence(l, weights))
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

/// r = cΔt/h for `settings` on cells of width `spacing` in a medium whose largest σ_t is
/// `sigma_t_max`, checked: a positive finite step within the von Neumann bound (unless
/// `allow_unstable`).
pub(crate) fn checked_ratio(
    quadrature: &SphericalQuadrature,
    sigma_t_max: f64,
    settings: &OrdinatesSettings,
    spacing: f64,
) -> Result<f64, ExplicitError> {
    let dt = settings.time_step;
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(ExplicitError::Invalid(format!("time step {dt}")));
    }
    let s_max = quadrature
        .directions()
        .iter()
        .map(|d| d.abs().element_sum())
        .fold(0.0, f64::max);
    let k_max = dt * sigma_t_max;
    let r = dt / spacing;
    let limit = crate::stability::ordinates::von_neumann_limit(s_max, k_max);
    if r > limit * (1.0 + 1e-12) && !settings.allow_unstable {
        return Err(ExplicitError::Unstable {
            scheme: "FTCS ordinates",
            parameter: "r = cΔt/h",
            limit,
            requested: r,
        });
    }
    Ok(r)
}

/// The growth monitor of a march from zero with sources of largest magnitude `source`.
pub(crate) fn growth_monitor(source: f64, settings: &OrdinatesSettings) -> GrowthMonitor {
    GrowthMonitor {
        reference: source
            * settings.time_step
            * settings.stopping.max_iterations.min(1 << 40) as f64
            / (4.0 * std::f64::consts::PI)
            + f64::MIN_POSITIVE,
        factor: 1e6,
    }
}

/// One cell's coefficients and φ for [`cell_step`].
pub(crate) struct Cell {
    pub(crate) sigma_t: f64,
    pub(crate) sigma_s: f64,
    pub(crate) source: f64,
    pub(crate) phi: f64,
}

/// One FTCS step of the cell whose radiances are `here` (one per direction of `dirs`) into
/// `out`, with the neighbours' radiances `blocks[axis][side]` (side 0 below, 1 above; `None`
/// beyond a vacuum edge): the one definition of the update, for the in-memory march and
/// the paged one.
#[inline]
pub(crate) fn cell_step(
    dirs: &[glam::DVec3],
    dt: f64,
    r: f64,
    cell: &Cell,
    here: &[f64],
    blocks: &[[Option<&[f64]>; 2]; 3],
    out: &mut [f64],
) {
    let four_pi = 4.0 * std::f64::consts::PI;
    let emission = dt * (cell.sigma_s * cell.phi + cell.source) / four_pi;
    let damping = 1.0 - dt * cell.sigma_t;
    for (d, o) in out.iter_mut().enumerate() {
        let l = here[d];
        let mut change = 0.0;
        for axis in 0..3 {
            let w = dirs[d][axis];
            if w != 0.0 {
                let side = usize::from(w < 0.0);
                let up = blocks[axis][side].map_or(0.0, |b| b[d]);
                change += w.abs() * (l - up);
            }
        }
        *o = damping * l - r * change + emission;
    }
}

/// φ = Σ_d w_d L_d of one cell: the one definition for both storages.
#[inline]
pub(crate) fn cell_fluence(radiance: &[f64], weights: &[f64]) -> f64 {
    radiance.iter().zip(weights).map(|(l, w)| l * w).sum()
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
