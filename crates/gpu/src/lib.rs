//! # lucent-gpu: the GPU layer of lucent on wgpu
//!
//! What every GPU backend (the explicit schemes, `direct`, multigrid, discrete ordinates,
//! Lattice-Boltzmann) stands on: compute only, WGSL kernels from the repository's
//! top-level `shaders/` folder (compiled into the crate, validated by naga in a test so that
//! a shader error fails `cargo test`, not a user's run).
//!
//! - [`GpuContext`]: picks an adapter (honouring `WGPU_ADAPTER_NAME` and `WGPU_BACKEND`),
//!   requests the limits lucent needs explicitly (storage-buffer binding size, storage
//!   buffers per stage) and reports them; no adapter, or an adapter below what lucent needs,
//!   is a typed [`GpuError`], never a panic.
//! - [`DeviceField`]: one f32 grid on the device. Uploads refuse NaN, infinities and — where
//!   the caller says so — negative values before anything is allocated, and refuse a grid
//!   beyond the adapter's binding limit with the limit's name
//!   ([`GpuError::OverBudget`]). lavapipe binds at most 128 MiB: a 256³ f32 grid (64 MiB)
//!   fits, 512³ (512 MiB) is refused with the reason.
//! - [`DeviceField64`]: one f64 vector on the device, for kernels that keep a solution or a
//!   residual in double precision; only on a device with f64 in shaders
//!   ([`GpuContext::has_f64`]: Vulkan's `shaderFloat64`, which NVIDIA, AMD, Intel and
//!   lavapipe have; the context asks for it where the adapter offers it).
//! - [`Transfers`]: staging kept for moving large vectors up and down in chunks of at most
//!   [`TRANSFER_CHUNK_BYTES`], copied into and out of mapped memory by several threads;
//!   [`Readback`]: a small staging buffer an iteration copies a norm or timestamps into
//!   inside its own command buffer. `GpuContext::timed_commands` runs one command buffer
//!   (clears, one timed compute pass, copies) with one submit and one wait.
//! - [`DeviceMedium`]: a problem's σ_t and albedo per channel, uploaded once for every
//!   backend.
//! - [`BrickAtlas`]: a paged field (`lucent-paging`) on the device: its stored bricks
//!   (with their aprons) in one storage buffer and a software page table (WebGPU has no
//!   sparse resources); constant bricks cost a table entry. `gpu-direct` reads σ_t from
//!   it when the dense grid does not fit one binding.
//! - [`Reducer`]: sums, sums of squares and maxima of device fields that match the CPU's f64
//!   reductions (see *Precision*).
//! - [`GpuContext::timed_pass`]: one compute pass timed by timestamp queries where the
//!   adapter has them, by wall time otherwise ([`Timing`]).
//!
//! ## Precision
//!
//! WGSL has no portable f64: fields are f32 on the device, as on the host. Reductions are
//! pairwise within a workgroup of 256 values (error growing as log₂ 256 = 8 ulps instead of
//! 256) and the per-workgroup partials are added on the host in f64, so a device sum of
//! non-negative values agrees with the CPU's f64 sum to about 8·2⁻²⁴ ≈ 5·10⁻⁷ relative,
//! whatever the number of values (tested at 10⁶ values to 10⁻⁶).
//!
//! ## Units and limits
//!
//! Nothing here has physical units; byte counts are bytes. A binding is limited by the
//! adapter's `max_storage_buffer_binding_size` (lavapipe: 128 MiB), a dispatch to 65 535
//! workgroups per dimension (reductions use two dimensions).
//!
//! ```no_run
//! use lucent_gpu::{GpuContext, DeviceField, Reducer};
//! let context = GpuContext::new()?;
//! println!("{}", context.describe());
//! let field = DeviceField::upload(&context, "values", &[1.0, 2.0, 3.0], false)?;
//! let sum = Reducer::new(&context)?.sum(&context, &field)?;
//! assert_eq!(sum, 6.0);
//! # Ok::<(), lucent_gpu::GpuError>(())
//! ```

mod atlas;
mod context;
mod error;
mod field;
mod kernel;
mod medium;
mod reduce;
pub mod shaders;
mod timing;

pub use atlas::{BrickAtlas, CONSTANT_BRICK};
pub use context::{GpuContext, GpuOptions, context_or_skip};
pub use error::GpuError;
pub use field::{
    DeviceField, DeviceField64, DeviceIndices, Readback, TRANSFER_CHUNK_BYTES, Transfers,
};
pub use kernel::{Kernel, UniformSlots, WORKGROUP, groups_2d};
pub use medium::DeviceMedium;
pub use reduce::Reducer;
pub use timing::{Timing, TimingSource};
