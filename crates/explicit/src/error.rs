//! Typed errors of the explicit schemes.

/// Why a scheme did not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ExplicitError {
    /// The requested step is beyond the scheme's correct stability bound (and the study
    /// option `allow_unstable` is off). Nothing was run.
    #[error("{scheme}: {parameter} = {requested:?} is beyond the stability limit {limit:?}")]
    Unstable {
        /// The scheme.
        scheme: &'static str,
        /// The parameter that is too large (time step, Courant number, ...).
        parameter: &'static str,
        /// The largest stable value.
        limit: f64,
        /// The value asked for.
        requested: f64,
    },
    /// Bad input: sizes, ranges, non-finite values.
    #[error("{0}")]
    Invalid(String),
}
