//! Errors of problem assembly.

use thiserror::Error;

/// Why a diffusion problem cannot be set up.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum DiffusionError {
    /// A coefficient, source or boundary value is invalid.
    #[error("invalid diffusion problem: {0}")]
    Invalid(String),
    /// Without absorption and with only Neumann boundaries the solution is not unique.
    #[error(
        "the problem is singular: no absorption and no Robin or Dirichlet boundary to hold the fluence"
    )]
    Singular,
    /// The problem cannot be split over the ranks, or a rank left the protocol.
    #[error("on ranks: {0}")]
    Ranks(String),
}
