//! The WGSL sources of lucent's kernels, from the repository's top-level `shaders/` folder,
//! compiled into the crate. `tests/shaders.rs` validates every one with naga, so a shader
//! error fails `cargo test` rather than a user's run.

/// Pairwise workgroup reductions (sum, sum of squares, maximum of |x|) into per-workgroup
/// partials that the host adds in f64.
pub const REDUCE: &str = include_str!("../../../shaders/reduce.wgsl");

/// Every shader with its file name, for validation.
pub const ALL: &[(&str, &str)] = &[("reduce.wgsl", REDUCE)];

/// The module of `source` on `context`'s device.
pub(crate) fn module(
    context: &crate::GpuContext,
    name: &str,
    source: &str,
) -> Result<wgpu::ShaderModule, crate::GpuError> {
    context.checked(|| {
        context
            .device()
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(name),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            })
    })
}
