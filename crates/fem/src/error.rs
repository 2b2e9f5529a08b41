//! Typed errors of the finite-element crate.

/// Why a finite-element operation did not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FemError {
    /// Bad input: sizes, non-finite values, ranges.
    #[error("{0}")]
    Invalid(String),
    /// The matrix is singular to working precision (direct solve).
    #[error("singular matrix: zero pivot in column {column}")]
    Singular {
        /// The column without a usable pivot.
        column: usize,
    },
    /// The system is too large for a dense direct solve.
    #[error("{unknowns} unknowns is too many for a dense direct solve (at most {limit})")]
    TooLarge {
        /// Unknowns.
        unknowns: usize,
        /// The limit.
        limit: usize,
    },
    /// Ctrl-C or the time limit stopped the assembly.
    #[error("the assembly {0}")]
    Halted(lucent_core::Halt),
}
