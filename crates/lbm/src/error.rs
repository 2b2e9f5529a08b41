//! What can go wrong on a lattice.

/// Errors of the lattice march.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LbmError {
    /// A coefficient, source or setting that is not usable.
    #[error("{0}")]
    Invalid(String),
    /// A coefficient beyond the scheme's stability limit.
    #[error("{parameter} = {value:?} is beyond the lattice's stability limit {limit:?}")]
    Unstable {
        /// Which.
        parameter: &'static str,
        /// The limit.
        limit: f64,
        /// The value asked for.
        value: f64,
    },
}

impl LbmError {
    /// The error as `solver`'s solve error: a stability limit as
    /// [`lucent_core::SolveError::Unstable`], anything else as an invalid problem.
    pub fn into_solve_error(self, solver: &str) -> lucent_core::SolveError {
        match self {
            LbmError::Unstable {
                parameter,
                limit,
                value,
            } => lucent_core::SolveError::Unstable {
                solver: solver.into(),
                parameter: parameter.into(),
                limit,
                requested: value,
            },
            LbmError::Invalid(reason) => lucent_core::SolveError::InvalidParameter {
                name: "problem".into(),
                reason,
            },
        }
    }
}
