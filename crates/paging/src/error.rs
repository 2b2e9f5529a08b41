//! What can go wrong when paging, with a message meant for the person at the command line.

/// Errors of the pager and of paged fields.
#[derive(Debug, thiserror::Error)]
pub enum PagingError {
    /// The byte budget cannot hold what one step needs at once (checked before any work).
    #[error(
        "memory budget of {budget} bytes is below the {needed} bytes that {what} needs at once"
    )]
    BudgetTooSmall {
        /// The budget.
        budget: u64,
        /// Bytes needed.
        needed: u64,
        /// What needs them.
        what: String,
    },
    /// Every slot of the pool is pinned: more bricks are in use at once than the budget
    /// holds.
    #[error(
        "all {slots} brick slots of the pool are pinned: the working set is larger than the budget"
    )]
    PoolExhausted {
        /// Slots in the pool.
        slots: usize,
    },
    /// A brick that is pinned cannot be discarded.
    #[error("brick {brick} is pinned and cannot be discarded")]
    Pinned {
        /// The brick.
        brick: usize,
    },
    /// A brick number beyond the pager's bricks.
    #[error("brick {brick} does not exist (the pager has {count})")]
    NoSuchBrick {
        /// The brick asked for.
        brick: usize,
        /// Bricks the pager holds.
        count: usize,
    },
    /// A read or write that does not fit the field: a cell, slab, plane or layer outside
    /// it, or a buffer of the wrong size.
    #[error("{0}")]
    Shape(String),
    /// The backing store could not be read or written. Nothing is lost: a brick whose
    /// write-back failed stays resident and dirty.
    #[error("{action} brick {brick} of {store}: {source}")]
    Io {
        /// `reading` or `writing`.
        action: &'static str,
        /// The brick.
        brick: usize,
        /// The store (a file's path, or what it is).
        store: String,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// Creating the backing file failed.
    #[error("cannot create a backing file in {dir}: {source}")]
    Create {
        /// The folder.
        dir: std::path::PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A grid-level error (geometry, brick size).
    #[error(transparent)]
    Grid(#[from] lucent_grid::GridError),
}
