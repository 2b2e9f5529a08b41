//! What can go wrong when a problem is split over ranks.

/// Why a decomposed solve could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecompositionError {
    /// More ranks than z-layers holding unknowns.
    #[error(
        "{ranks} ranks for {layers} z-layers with unknowns: every rank needs at least one layer"
    )]
    TooManyRanks {
        /// Ranks asked for.
        ranks: usize,
        /// Layers there are.
        layers: usize,
    },
    /// A row reads beyond the neighbouring slabs (slabs thinner than the stencil).
    #[error("rank {rank}: the stencil reaches past the neighbouring slabs (use fewer ranks)")]
    StencilTooWide {
        /// The rank.
        rank: usize,
    },
    /// The system cannot be iterated.
    #[error("the system: {0}")]
    Matrix(String),
    /// The iteration refused the system or its step (`lucent_explicit::steady::row_scale`).
    #[error(transparent)]
    Scheme(#[from] lucent_explicit::ExplicitError),
    /// A neighbour sent what the plan did not expect (a rank stopped or diverged from the
    /// protocol).
    #[error("rank {rank}: a halo or gather did not match the decomposition")]
    Protocol {
        /// The rank that noticed.
        rank: usize,
    },
}
