//! What can go wrong on the GPU side, with a message meant for the person at the command
//! line.

/// Errors of the GPU layer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GpuError {
    /// No adapter (no driver, or none matching `WGPU_ADAPTER_NAME` / `WGPU_BACKEND`).
    #[error(
        "no GPU adapter: {reason} (install a Vulkan driver — mesa-vulkan-drivers gives the software lavapipe — or check WGPU_ADAPTER_NAME and WGPU_BACKEND)"
    )]
    NoAdapter {
        /// Why none was found.
        reason: String,
    },
    /// The adapter lacks something lucent needs.
    #[error(
        "adapter `{adapter}` does not support {what}: lucent needs {needed}, it has {available}"
    )]
    Unsupported {
        /// The adapter's name.
        adapter: String,
        /// The limit or feature.
        what: &'static str,
        /// What lucent needs.
        needed: u64,
        /// What the adapter offers.
        available: u64,
    },
    /// A buffer or dispatch beyond one of the adapter's limits.
    #[error("{what} needs {needed} bytes, over the adapter's {limit} of {available} bytes")]
    OverBudget {
        /// What was being allocated.
        what: String,
        /// The limit's name in wgpu (`max_storage_buffer_binding_size`, ...).
        limit: &'static str,
        /// Bytes needed.
        needed: u64,
        /// The limit.
        available: u64,
    },
    /// Input the device must not see: NaN, infinity, or a negative coefficient.
    #[error("{what}: value {value:?} at index {index} is {problem}")]
    BadInput {
        /// The field.
        what: String,
        /// Its index in the field.
        index: usize,
        /// The value.
        value: f32,
        /// `not finite` or `negative`.
        problem: &'static str,
    },
    /// The host could not provide what was to be uploaded (a paged field's bricks).
    #[error("reading {what} for the device: {reason}")]
    Source {
        /// What was being uploaded.
        what: String,
        /// Why it could not be read.
        reason: String,
    },
    /// The device refused a request or was lost.
    #[error("GPU device: {0}")]
    Device(String),
}
