//! What can go wrong on a lattice.

/// Errors of the lattice march.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LbmError {
    /// A coefficient, source or setting that is not usable.
    #[error("{0}")]
    Invalid(String),
    /// A coefficient beyond the scheme's stability limit.
    #[error("{parameter} = {value} is beyond the lattice's stability limit {limit}")]
    Unstable {
        /// Which.
        parameter: &'static str,
        /// The limit.
        limit: f64,
        /// The value asked for.
        value: f64,
    },
}
