//! Reductions of device fields that match the CPU's f64 reductions: pairwise sums of 256
//! values per workgroup on the device (`shaders/reduce.wgsl`), the partials added in f64
//! on the host.

use wgpu::util::DeviceExt;

use crate::context::GpuContext;
use crate::error::GpuError;
use crate::field::{DeviceField, download_buffer};

const WORKGROUP: u64 = 256;

/// The reduction kernels, built once per context.
#[derive(Debug)]
pub struct Reducer {
    layout: wgpu::BindGroupLayout,
    sum: wgpu::ComputePipeline,
    sum_of_squares: wgpu::ComputePipeline,
    max_abs: wgpu::ComputePipeline,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Sum,
    SumOfSquares,
    MaxAbs,
}

impl Reducer {
    /// Compiles the kernels on `context`'s device.
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        let device = context.device();
        let module = crate::shaders::module(context, "reduce.wgsl", crate::shaders::REDUCE)?;
        let storage = |binding, read_only| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        context.checked(|| {
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("reduce"),
                entries: &[
                    storage(0, true),
                    storage(1, false),
                    wgpu::BindGroupLayoutEntry {
                        binding: 2,
                        visibility: wgpu::ShaderStages::COMPUTE,
                        ty: wgpu::BindingType::Buffer {
                            ty: wgpu::BufferBindingType::Uniform,
                            has_dynamic_offset: false,
                            min_binding_size: None,
                        },
                        count: None,
                    },
                ],
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("reduce"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let pipeline = |entry: &str| {
                device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(entry),
                    layout: Some(&pipeline_layout),
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    cache: None,
                })
            };
            Self {
                sum: pipeline("sum"),
                sum_of_squares: pipeline("sum_of_squares"),
                max_abs: pipeline("max_abs"),
                layout,
            }
        })
    }

    /// Σ x in f64 (see the crate's *Precision*).
    pub fn sum(&self, context: &GpuContext, field: &DeviceField) -> Result<f64, GpuError> {
        Ok(self
            .partials(context, field, Kind::Sum)?
            .iter()
            .map(|&p| f64::from(p))
            .sum())
    }

    /// Σ x² in f64: the squared L2 norm.
    pub fn sum_of_squares(
        &self,
        context: &GpuContext,
        field: &DeviceField,
    ) -> Result<f64, GpuError> {
        Ok(self
            .partials(context, field, Kind::SumOfSquares)?
            .iter()
            .map(|&p| f64::from(p))
            .sum())
    }

    /// max |x| (exact: a maximum does not round); 0 for an empty field.
    pub fn max_abs(&self, context: &GpuContext, field: &DeviceField) -> Result<f64, GpuError> {
        Ok(self
            .partials(context, field, Kind::MaxAbs)?
            .iter()
            .fold(0.0f64, |m, &p| m.max(f64::from(p))))
    }

    /// One partial per workgroup of 256 values, dispatched over two dimensions.
    fn partials(
        &self,
        context: &GpuContext,
        field: &DeviceField,
        kind: Kind,
    ) -> Result<Vec<f32>, GpuError> {
        let len = field.len() as u64;
        if len == 0 {
            return Ok(Vec::new());
        }
        let len32 = u32::try_from(len).map_err(|_| GpuError::OverBudget {
            what: "a reduction".into(),
            limit: "u32 indices",
            needed: len * 4,
            available: u64::from(u32::MAX),
        })?;
        let groups = len.div_ceil(WORKGROUP);
        let max_x = u64::from(context.limits().max_compute_workgroups_per_dimension);
        let groups_x = groups.min(max_x);
        let groups_y = groups.div_ceil(groups_x);
        let device = context.device();
        let partials = DeviceField::zeros(
            context,
            "reduction partials",
            (groups_x * groups_y) as usize,
        )?;
        context.checked(|| {
            let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("reduce params"),
                contents: bytemuck::cast_slice(&[len32, groups_x as u32, 0, 0]),
                usage: wgpu::BufferUsages::UNIFORM,
            });
            let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("reduce"),
                layout: &self.layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: field.buffer().as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: partials.buffer().as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: params.as_entire_binding(),
                    },
                ],
            });
            let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("reduce"),
            });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("reduce"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(match kind {
                    Kind::Sum => &self.sum,
                    Kind::SumOfSquares => &self.sum_of_squares,
                    Kind::MaxAbs => &self.max_abs,
                });
                pass.set_bind_group(0, &bind, &[]);
                pass.dispatch_workgroups(groups_x as u32, groups_y as u32, 1);
            }
            context.queue().submit([encoder.finish()]);
        })?;
        // Workgroups past the last value (the 2-D dispatch's padding) wrote zeros.
        download_buffer(
            context,
            partials.buffer(),
            groups as usize,
            "reduction partials",
        )
    }
}
