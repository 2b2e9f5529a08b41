//! The registry parameters of the finite-element solvers, read from a scene's
//! `[solver.params]` by serde (unknown keys and ill-typed values are errors naming the
//! key) and printed with their defaults by `lucent solvers`.

use lucent_core::{SolveError, SolverParams};
use serde::{Deserialize, Serialize};

/// The linear solver of `fem-p1-jacobi`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FemP1Iteration {
    /// Jacobi, as the thesis did (it diverges on this system).
    #[default]
    Jacobi,
    /// Restarted GMRES(60), to see what the converged system gives.
    Gmres,
}

/// The parameters of `fem-p1-jacobi`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FemP1Params {
    /// The linear solver.
    pub solver: FemP1Iteration,
}

impl SolverParams for FemP1Params {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[(
        "solver",
        "jacobi (the thesis' iteration, which diverges: kept for the study) or gmres",
    )];
}

/// The parameters of `fem-diffusion`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FemDiffusionParams {
    /// Smoothing sweeps per multigrid level.
    pub sweeps: usize,
}

impl Default for FemDiffusionParams {
    fn default() -> Self {
        Self { sweeps: 2 }
    }
}

impl SolverParams for FemDiffusionParams {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[(
        "sweeps",
        "smoothing sweeps per level of the preconditioning multigrid, 1 to 16",
    )];

    fn validate(&self) -> Result<(), SolveError> {
        if (1..=16).contains(&self.sweeps) {
            Ok(())
        } else {
            Err(SolveError::InvalidParameter {
                name: "sweeps".into(),
                reason: "1 to 16".into(),
            })
        }
    }
}
