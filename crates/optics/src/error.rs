//! The one error type of this crate.

use thiserror::Error;

/// Why an optical quantity could not be built.
///
/// Every constructor in this crate validates its input and returns one of these
/// instead of panicking or producing a NaN further down the pipeline.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum OpticsError {
    /// A value that must be finite was NaN or infinite.
    #[error("{name} must be finite, got {value:?}")]
    NotFinite {
        /// The parameter's name, as in the API (`sigma_a`, `g`, ...).
        name: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A coefficient that must be non-negative was negative.
    #[error("{name} must be non-negative, got {value:?}")]
    Negative {
        /// The parameter's name.
        name: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A value lies outside the interval the physics allows.
    #[error("{name} must lie in {range}, got {value:?}")]
    OutOfRange {
        /// The parameter's name.
        name: &'static str,
        /// The admissible range, written as an interval (`(-1, 1)`, `[0, 1]`).
        range: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A spherical quadrature was asked for with an order or size it does not have.
    #[error("no {family} quadrature of order {order}: {reason}")]
    UnsupportedQuadrature {
        /// The quadrature family (`level-symmetric`, `octahedral`, `Fibonacci`).
        family: &'static str,
        /// The requested order, level or point count.
        order: usize,
        /// What would have been accepted.
        reason: &'static str,
    },
    /// A numerical reference could not be computed (a singular system), which the inputs
    /// that passed validation should never cause.
    #[error("could not compute {what}: singular system")]
    Singular {
        /// What was being computed.
        what: &'static str,
    },
    /// A material name that is not in the measured table.
    #[error("unknown material `{0}`; see `lucent_optics::materials::JENSEN_2001` for the names")]
    UnknownMaterial(String),
}

/// Checks that `value` is finite and non-negative.
pub(crate) fn non_negative(name: &'static str, value: f64) -> Result<f64, OpticsError> {
    if !value.is_finite() {
        Err(OpticsError::NotFinite { name, value })
    } else if value < 0.0 {
        Err(OpticsError::Negative { name, value })
    } else {
        Ok(value)
    }
}

/// Checks that `value` is finite and lies in the closed or open interval described by
/// `range`; `inside` decides membership.
pub(crate) fn in_range(
    name: &'static str,
    value: f64,
    range: &'static str,
    inside: impl FnOnce(f64) -> bool,
) -> Result<f64, OpticsError> {
    if !value.is_finite() {
        Err(OpticsError::NotFinite { name, value })
    } else if !inside(value) {
        Err(OpticsError::OutOfRange { name, range, value })
    } else {
        Ok(value)
    }
}

/// Checks an anisotropy parameter: `g` must lie in the open interval (−1, 1).
///
/// |g| = 1 is a Dirac delta (no scattering at all for g = 1): it has no density to
/// evaluate and makes the reduced scattering coefficient degenerate.
pub(crate) fn anisotropy(name: &'static str, g: f64) -> Result<f64, OpticsError> {
    in_range(name, g, "(-1, 1)", |g| g > -1.0 && g < 1.0)
}

/// Checks a relative refractive index: finite and strictly positive.
pub(crate) fn refractive_index(eta: f64) -> Result<f64, OpticsError> {
    in_range("eta", eta, "(0, inf)", |e| e > 0.0)
}
