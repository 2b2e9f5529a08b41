//! Errors of the discrete-ordinates solver.

/// What can go wrong before or while sweeping.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DomError {
    /// A setting or input is out of its domain.
    #[error("invalid input: {0}")]
    Invalid(String),
    /// An angular set could not be built.
    #[error(transparent)]
    Optics(#[from] lucent_optics::OpticsError),
    /// The DSA diffusion problem could not be set up.
    #[error("diffusion synthetic acceleration: {0}")]
    Diffusion(#[from] lucent_diffusion::DiffusionError),
}
