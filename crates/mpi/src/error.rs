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
    /// An FTCS step beyond its stability bound (or not positive).
    #[error("FTCS step cΔt = {requested} is beyond its stability limit {limit}")]
    Unstable {
        /// The step asked for.
        requested: f64,
        /// The Gershgorin bound.
        limit: f64,
    },
    /// A neighbour sent what the plan did not expect (a rank stopped or diverged from the
    /// protocol).
    #[error("rank {rank}: a halo or gather did not match the decomposition")]
    Protocol {
        /// The rank that noticed.
        rank: usize,
    },
}
