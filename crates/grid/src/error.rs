//! The one error type of this crate.

use std::path::PathBuf;

use thiserror::Error;

/// Why a grid could not be built, transformed, read or written.
///
/// File errors name the file; every size problem is detected before the allocation it
/// would have caused.
#[derive(Debug, Error)]
pub enum GridError {
    /// Dimensions, spacing or origin that describe no valid grid.
    #[error("invalid grid geometry: {0}")]
    InvalidGeometry(String),
    /// Two grids (or a grid and a buffer) that must match do not.
    #[error("grid mismatch: {0}")]
    Mismatch(String),
    /// An invalid parameter of an operation (brick size, transfer function, ...).
    #[error("invalid {name}: {reason}")]
    InvalidParameter {
        /// The parameter.
        name: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// The operating system refused to read or write a file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A header or structure that does not follow the format.
    #[error("{path}: malformed {format} file: {reason}")]
    Malformed {
        /// The file.
        path: PathBuf,
        /// The format it claims to be.
        format: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// The file ends before the data its header announces.
    #[error("{path}: truncated: needs {expected} bytes of {what}, has {found}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// What was being read.
        what: &'static str,
        /// Bytes needed.
        expected: u64,
        /// Bytes present.
        found: u64,
    },
    /// The payload size does not match the dimensions and voxel type.
    #[error(
        "{path}: payload of {found} bytes does not match the {expected} bytes that the dimensions and type require"
    )]
    SizeMismatch {
        /// The file.
        path: PathBuf,
        /// Bytes required by the header.
        expected: u64,
        /// Bytes present.
        found: u64,
    },
    /// A voxel type, encoding or feature of the format that lucent does not read.
    #[error("{path}: unsupported {what}: {value}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// The kind of thing (`voxel type`, `encoding`, `compression`, ...).
        what: &'static str,
        /// Its value in the file.
        value: String,
    },
    /// Loading would need more memory than the budget allows.
    #[error("{path}: needs {needed} bytes, over the memory budget of {budget} bytes")]
    OverBudget {
        /// The file (or `<memory>` for in-memory operations).
        path: PathBuf,
        /// Bytes the operation would allocate.
        needed: u64,
        /// The configured budget.
        budget: u64,
    },
    /// A path that is not a regular file (a device, a FIFO, a folder): reading it could
    /// block or never end.
    #[error("{path}: not a regular file (devices, FIFOs and folders are not read)")]
    NotAFile {
        /// The path.
        path: PathBuf,
    },
    /// A volume holding NaN or an infinity.
    #[error("{path}: voxel {index} (cell {cell:?}) is {value}; volumes must be finite")]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// Linear index of the first offending voxel.
        index: usize,
        /// Its cell (i, j, k).
        cell: [usize; 3],
        /// Its value.
        value: f32,
    },
    /// Values that the target format cannot represent without loss.
    #[error("{path}: voxel {index} = {value} cannot be written as {target} without loss")]
    Lossy {
        /// The file being written.
        path: PathBuf,
        /// Linear index of the first offending voxel.
        index: usize,
        /// Its value.
        value: f32,
        /// The target voxel type.
        target: &'static str,
    },
}
