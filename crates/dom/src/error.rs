//! Errors of the discrete-ordinates solver.

/// What can go wrong before or while sweeping.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DomError {
    /// A setting or input is out of its domain.
    #[error("invalid input: {0}")]
    Invalid(String),
    /// A sweep or its DSA correction produced non-finite values inside the GMRES outer
    /// iteration (source iteration reports the same as
    /// `StopReason::DivergedNonFinite` and drops DSA where that is the cause).
    #[error("not finite: {0}")]
    NotFinite(String),
    /// An angular set could not be built.
    #[error(transparent)]
    Optics(#[from] lucent_optics::OpticsError),
    /// The DSA diffusion problem could not be set up.
    #[error("diffusion synthetic acceleration: {0}")]
    Diffusion(#[from] lucent_diffusion::DiffusionError),
    /// The pager holding the sweeps' work failed (its message: a pool too small, a
    /// backing file that could not be read or written).
    #[error("paging the sweeps' work: {0}")]
    Paging(String),
    /// The device running the transport steps failed (no adapter, a binding beyond its
    /// limits, a lost device).
    #[error("device: {0}")]
    Device(String),
    /// Ctrl-C or the time limit stopped a sweep part way.
    #[error("the sweep {0}")]
    Halted(lucent_core::Halt),
}

impl From<lucent_paging::PagingError> for DomError {
    fn from(e: lucent_paging::PagingError) -> Self {
        DomError::Paging(e.to_string())
    }
}
