//! The registry parameters of the GPU backends. `gpu-direct`, `gpu-ftcs-diffusion` and
//! `gpu-ftcs-p1` take exactly their CPU twins' parameters ([`lucent_core::DirectSolver`],
//! [`lucent_explicit::FtcsDiffusionParams`], [`lucent_explicit::P1Params`]), so a scene
//! switches backend by its solver's name alone. `gpu-convection-diffusion` has its own:
//! the device runs the characteristic model by layer sweeps only (the CPU twin's
//! default), so it has no `model`, `sweep` or `courant`.

use lucent_core::{SolveError, SolverParams};
use serde::{Deserialize, Serialize};

/// Parameters of `gpu-convection-diffusion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GpuConvectionParams {
    /// σ̂_s t of the implicit scattering step (length², ≥ 0; 0: uncollided light only).
    pub scattering: f64,
    /// Relative residual the scattering step's red–black Gauss–Seidel reaches (f32 on
    /// the device: not below 1e-6).
    pub scatter_tolerance: f64,
    /// Largest change of a pass over the largest value at which a point light's march
    /// stops (f32 on the device: not below 1e-6).
    pub march_tolerance: f64,
}

impl Default for GpuConvectionParams {
    fn default() -> Self {
        Self {
            scattering: 0.0,
            scatter_tolerance: 1e-6,
            march_tolerance: 1e-6,
        }
    }
}

impl SolverParams for GpuConvectionParams {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[
        (
            "scattering",
            "σ̂_s t of the implicit scattering step (length², ≥ 0; 0: the uncollided light only)",
        ),
        (
            "scatter_tolerance",
            "relative residual of the scattering step's red–black Gauss–Seidel (≥ 1e-6: f32 on the device)",
        ),
        (
            "march_tolerance",
            "largest change of a point light's pass over the largest value at which its march stops (≥ 1e-6)",
        ),
    ];

    fn validate(&self) -> Result<(), SolveError> {
        let bad = |name: &str, reason: &str| SolveError::InvalidParameter {
            name: name.into(),
            reason: reason.into(),
        };
        if !(self.scattering >= 0.0 && self.scattering.is_finite()) {
            return Err(bad("scattering", "finite and ≥ 0 (length²)"));
        }
        for (name, value) in [
            ("scatter_tolerance", self.scatter_tolerance),
            ("march_tolerance", self.march_tolerance),
        ] {
            if !(1e-6..1.0).contains(&value) {
                return Err(bad(
                    name,
                    "in [1e-6, 1): f32 on the device cannot resolve smaller changes",
                ));
            }
        }
        Ok(())
    }
}
