//! Errors of problem assembly and solving.

use thiserror::Error;

/// A problem that does not describe valid physics (negative extinction, albedo above one,
/// grids on different geometries, ...).
#[derive(Debug, Clone, PartialEq, Error)]
#[error("invalid problem: {0}")]
pub struct ProblemError(pub String);

/// Why a solve could not run. (A solve that ran but did not converge is not an error: it
/// returns a solution whose report says why it stopped.)
#[derive(Debug, Error)]
pub enum SolveError {
    /// The problem has a feature this solver cannot handle.
    #[error("solver `{solver}` cannot handle {feature}")]
    Unsupported {
        /// The solver's name.
        solver: String,
        /// The feature, in words.
        feature: String,
    },
    /// An option or solver parameter is invalid.
    #[error("invalid parameter `{name}`: {reason}")]
    InvalidParameter {
        /// The parameter.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// A requested parameter lies beyond the scheme's stability limit (an explicit time
    /// step, a Courant number); nothing was run. Ask for it anyway with the scheme's
    /// `allow_unstable` where studying the blow-up is the point.
    #[error(
        "solver `{solver}`: {parameter} = {requested:?} is beyond its stability limit {limit:?} (`allow_unstable = true` runs it anyway)"
    )]
    Unstable {
        /// The solver's name.
        solver: String,
        /// The parameter (time step, Courant number, fraction of the bound).
        parameter: String,
        /// The largest stable value.
        limit: f64,
        /// The value requested.
        requested: f64,
    },
    /// No solver of that name is registered.
    #[error("unknown solver `{name}`; available: {available}")]
    UnknownSolver {
        /// The requested name.
        name: String,
        /// The registered names, comma-separated.
        available: String,
    },
    /// The solve would need more memory than the budget allows.
    #[error("solver `{solver}` needs {needed} bytes, over the memory budget of {budget} bytes")]
    OverBudget {
        /// The solver's name.
        solver: String,
        /// Bytes needed.
        needed: u64,
        /// The budget.
        budget: u64,
    },
    /// The solve produced a value that is not finite (an overflow the checks before it did
    /// not foresee): refused rather than handed on, so no output holds NaN or infinity.
    #[error(
        "solver `{solver}` produced {value} in channel {channel}, cell {cell:?} of its {what}; nothing was written"
    )]
    NonFiniteOutput {
        /// The solver's name.
        solver: String,
        /// Which output (`fluence`, `standard error`).
        what: &'static str,
        /// The channel.
        channel: usize,
        /// The first offending cell (i, j, k).
        cell: [usize; 3],
        /// Its value.
        value: f32,
    },
    /// The work a solve would take, estimated before it runs, is beyond what the solver
    /// accepts: it would not finish (or not in hours) rather than fail.
    #[error(
        "solver `{solver}`: {what} would be about {estimate:.3e}, beyond its limit of {limit:.0e}; {advice}"
    )]
    TooMuchWork {
        /// The solver's name.
        solver: String,
        /// What was estimated.
        what: String,
        /// The estimate.
        estimate: f64,
        /// The limit.
        limit: f64,
        /// What to do instead.
        advice: String,
    },
    /// The compute device a backend needs is missing, lacks a limit, or failed (GPU
    /// backends: no adapter, a binding beyond the adapter's limit, a lost device).
    #[error("solver `{solver}`: {reason}")]
    Device {
        /// The solver's name.
        solver: String,
        /// What the device layer said.
        reason: String,
        /// Whether no device exists at all (no adapter): harnesses skip such solvers
        /// outside CI instead of failing.
        unavailable: bool,
    },
    /// The out-of-core storage (the pager's backing file) could not be read or written: a
    /// full disk, a quota, a lost file system. Nothing the solve computed was written.
    #[error("solver `{solver}`: its out-of-core storage failed: {reason}")]
    Storage {
        /// The solver's name.
        solver: String,
        /// What failed, with the operating system's words.
        reason: String,
    },
    /// Ctrl-C or the time limit stopped the solve before any result existed (in set-up:
    /// the uncollided light, a hierarchy, an assembly). An iteration stopped part way
    /// returns its last iterate with [`crate::StopReason::Interrupted`] or
    /// [`crate::StopReason::TimeLimit`] instead.
    #[error("solver `{solver}` {halt} during {stage}, before any result existed")]
    Halted {
        /// The solver's name.
        solver: String,
        /// What it was doing.
        stage: String,
        /// Why it stopped.
        halt: crate::Halt,
    },
    /// The problem is invalid.
    #[error(transparent)]
    Problem(#[from] ProblemError),
    /// A grid operation failed.
    #[error(transparent)]
    Grid(#[from] lucent_grid::GridError),
}
