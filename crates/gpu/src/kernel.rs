//! One compute kernel: a WGSL entry point, its pipeline and its bindings, numbered 0, 1, …
//! in the order a backend passes them; and the per-dispatch uniform slots the backends
//! record whole iterations with.

use wgpu::util::DeviceExt;

use crate::context::GpuContext;
use crate::error::GpuError;

/// Invocations per workgroup of lucent's 1-D kernels (and of `shaders/common.wgsl`'s
/// pairwise sums).
pub const WORKGROUP: u32 = 256;

/// A compute pipeline whose bind-group layout wgpu derives from the shader (group 0).
#[derive(Debug)]
pub struct Kernel {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    name: String,
}

impl Kernel {
    /// Compiles entry point `entry` of `source` (named `file` in errors).
    pub fn new(
        context: &GpuContext,
        file: &str,
        source: &str,
        entry: &str,
    ) -> Result<Self, GpuError> {
        let module = crate::shaders::module(context, file, source)?;
        context.checked(|| {
            let pipeline =
                context
                    .device()
                    .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                        label: Some(entry),
                        layout: None,
                        module: &module,
                        entry_point: Some(entry),
                        compilation_options: Default::default(),
                        cache: None,
                    });
            let layout = pipeline.get_bind_group_layout(0);
            Self {
                pipeline,
                layout,
                name: format!("{file}:{entry}"),
            }
        })
    }

    /// The pipeline, for `ComputePass::set_pipeline`.
    pub fn pipeline(&self) -> &wgpu::ComputePipeline {
        &self.pipeline
    }

    /// A bind group with `resources[i]` at binding i.
    pub fn bind(
        &self,
        context: &GpuContext,
        resources: &[wgpu::BindingResource<'_>],
    ) -> Result<wgpu::BindGroup, GpuError> {
        let numbered: Vec<(u32, wgpu::BindingResource<'_>)> = resources
            .iter()
            .enumerate()
            .map(|(i, r)| (i as u32, r.clone()))
            .collect();
        self.bind_at(context, &numbered)
    }

    /// A bind group with each `(binding, resource)` pair: for an entry point that uses a
    /// subset of its module's numbered bindings.
    pub fn bind_at(
        &self,
        context: &GpuContext,
        resources: &[(u32, wgpu::BindingResource<'_>)],
    ) -> Result<wgpu::BindGroup, GpuError> {
        let entries: Vec<wgpu::BindGroupEntry<'_>> = resources
            .iter()
            .map(|(binding, r)| wgpu::BindGroupEntry {
                binding: *binding,
                resource: r.clone(),
            })
            .collect();
        context.checked(|| {
            context
                .device()
                .create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some(&self.name),
                    layout: &self.layout,
                    entries: &entries,
                })
        })
    }

    /// Records one dispatch of `groups` workgroups (from [`groups_2d`]) with `bind`.
    pub fn dispatch(
        &self,
        pass: &mut wgpu::ComputePass<'_>,
        bind: &wgpu::BindGroup,
        groups: [u32; 2],
    ) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, bind, &[]);
        pass.dispatch_workgroups(groups[0], groups[1], 1);
    }
}

/// Workgroups for `items` invocations of `per_group` each, spread over two dimensions
/// (x fastest, at most the adapter's per-dimension limit) so that a 256³ grid (65 536
/// workgroups of 256) dispatches at once. Kernels number their workgroup
/// `wg.x + wg.y · groups[0]`.
pub fn groups_2d(context: &GpuContext, items: u64, per_group: u32) -> [u32; 2] {
    let groups = items.div_ceil(u64::from(per_group)).max(1);
    let max_x = u64::from(context.limits().max_compute_workgroups_per_dimension);
    let x = groups.min(max_x);
    [x as u32, groups.div_ceil(x) as u32]
}

/// Uniform blocks, one per dispatch, each at its own aligned offset of one buffer: the
/// per-step or per-layer parameters of a whole recorded iteration.
#[derive(Debug)]
pub struct UniformSlots {
    buffer: wgpu::Buffer,
    stride: u64,
    size: u64,
    count: usize,
}

impl UniformSlots {
    /// Uploads `slots` (each a `#[repr(C)]` block matching the shader's struct).
    pub fn new<T: bytemuck::Pod>(
        context: &GpuContext,
        label: &str,
        slots: &[T],
    ) -> Result<Self, GpuError> {
        let align = u64::from(context.limits().min_uniform_buffer_offset_alignment).max(16);
        let size = std::mem::size_of::<T>() as u64;
        let stride = size.div_ceil(align) * align;
        let mut bytes = vec![0u8; (stride * slots.len().max(1) as u64) as usize];
        for (i, slot) in slots.iter().enumerate() {
            let at = i * stride as usize;
            bytes[at..at + size as usize].copy_from_slice(bytemuck::bytes_of(slot));
        }
        let buffer = context.checked(|| {
            context
                .device()
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents: &bytes,
                    usage: wgpu::BufferUsages::UNIFORM,
                })
        })?;
        Ok(Self {
            buffer,
            stride,
            size,
            count: slots.len(),
        })
    }

    /// Slot `i` as a binding. Panics if `i` is not below [`UniformSlots::len`], as
    /// indexing a slice does: slots are addressed by the backend that made them.
    pub fn slot(&self, i: usize) -> wgpu::BindingResource<'_> {
        assert!(i < self.count.max(1), "uniform slot {i} of {}", self.count);
        wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer: &self.buffer,
            offset: i as u64 * self.stride,
            size: wgpu::BufferSize::new(self.size),
        })
    }

    /// Number of slots.
    pub fn len(&self) -> usize {
        self.count
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
}

impl GpuContext {
    /// Records `record` into one compute pass of one command buffer and submits it (no
    /// wait): a whole iteration, or several, per submit.
    pub fn submit_pass(
        &self,
        label: &str,
        record: impl FnOnce(&mut wgpu::ComputePass<'_>),
    ) -> Result<(), GpuError> {
        self.checked(|| {
            let mut encoder = self
                .device()
                .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some(label),
                    timestamp_writes: None,
                });
                record(&mut pass);
            }
            self.queue().submit([encoder.finish()]);
        })
    }

    /// Copies `bytes` bytes from `from` to `to` (both from offset 0) in its own submit.
    pub fn copy(&self, from: &wgpu::Buffer, to: &wgpu::Buffer, bytes: u64) -> Result<(), GpuError> {
        self.checked(|| {
            let mut encoder =
                self.device()
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                        label: Some("lucent copy"),
                    });
            encoder.copy_buffer_to_buffer(from, 0, to, 0, bytes);
            self.queue().submit([encoder.finish()]);
        })
    }
}
