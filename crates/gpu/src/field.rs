//! Grids on the device and back: the one place host↔device transfers happen.

use lucent_grid::{Grid, GridGeometry};
use wgpu::util::DeviceExt;

use crate::context::GpuContext;
use crate::error::GpuError;

/// One f32 field in a storage buffer (x fastest, as on the host).
#[derive(Debug)]
pub struct DeviceField {
    buffer: wgpu::Buffer,
    len: usize,
    what: String,
}

impl DeviceField {
    /// Uploads `values` after checking them: no NaN or infinity (and, with `nonnegative`,
    /// no negative value: σ_t, albedo and sources), and one binding's worth at most —
    /// both before anything is allocated on the device.
    pub fn upload(
        context: &GpuContext,
        what: &str,
        values: &[f32],
        nonnegative: bool,
    ) -> Result<Self, GpuError> {
        check_values(what, values, nonnegative)?;
        let buffer = storage_init(
            context,
            what,
            bytemuck::cast_slice(values),
            wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        )?;
        Ok(Self {
            buffer,
            len: values.len(),
            what: what.to_owned(),
        })
    }

    /// Uploads a grid's values.
    pub fn from_grid(
        context: &GpuContext,
        what: &str,
        grid: &Grid,
        nonnegative: bool,
    ) -> Result<Self, GpuError> {
        Self::upload(context, what, grid.data(), nonnegative)
    }

    /// A field of `len` zeros, for results and ping-pong partners.
    pub fn zeros(context: &GpuContext, what: &str, len: usize) -> Result<Self, GpuError> {
        let bytes = (len.max(1) * 4) as u64;
        context.check_binding(what, bytes)?;
        let buffer = context.checked(|| {
            context.device().create_buffer(&wgpu::BufferDescriptor {
                label: Some(what),
                size: bytes,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })?;
        Ok(Self {
            buffer,
            len,
            what: what.to_owned(),
        })
    }

    /// The storage buffer.
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// The whole field as a binding.
    pub fn binding(&self) -> wgpu::BindingResource<'_> {
        self.buffer.as_entire_binding()
    }

    /// Replaces the values (same length, same checks as [`DeviceField::upload`]); the
    /// write lands before the next submit.
    pub fn write(
        &self,
        context: &GpuContext,
        values: &[f32],
        nonnegative: bool,
    ) -> Result<(), GpuError> {
        if values.len() != self.len {
            return Err(GpuError::Device(format!(
                "{}: {} values written to a field of {}",
                self.what,
                values.len(),
                self.len
            )));
        }
        check_values(&self.what, values, nonnegative)?;
        if !values.is_empty() {
            context.checked(|| {
                context
                    .queue()
                    .write_buffer(&self.buffer, 0, bytemuck::cast_slice(values))
            })?;
        }
        Ok(())
    }

    /// Sets every value to zero (before the next submit).
    pub fn clear(&self, context: &GpuContext) -> Result<(), GpuError> {
        context.checked(|| {
            let mut encoder =
                context
                    .device()
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                        label: Some("lucent clear"),
                    });
            encoder.clear_buffer(&self.buffer, 0, None);
            context.queue().submit([encoder.finish()]);
        })
    }

    /// Number of values.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether it holds no values.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Copies the values back to the host (one staging buffer, one wait).
    pub fn download(&self, context: &GpuContext) -> Result<Vec<f32>, GpuError> {
        download_buffer(context, &self.buffer, self.len, &self.what)
    }

    /// Copies the first `len` values back (at most the field's length).
    pub fn download_prefix(&self, context: &GpuContext, len: usize) -> Result<Vec<f32>, GpuError> {
        download_buffer(context, &self.buffer, len.min(self.len), &self.what)
    }

    /// Copies the values back as a grid of `geometry` (whose cell count must be the
    /// field's length).
    pub fn to_grid(&self, context: &GpuContext, geometry: GridGeometry) -> Result<Grid, GpuError> {
        let values = self.download(context)?;
        Grid::from_vec(geometry, values).map_err(|e| GpuError::Device(e.to_string()))
    }
}

/// A storage buffer holding `bytes` (plus `usage`), checked against the binding limit
/// before allocation. An empty one still binds four bytes (wgpu refuses empty storage
/// bindings).
fn storage_init(
    context: &GpuContext,
    what: &str,
    bytes: &[u8],
    usage: wgpu::BufferUsages,
) -> Result<wgpu::Buffer, GpuError> {
    let contents: &[u8] = if bytes.is_empty() { &[0; 4] } else { bytes };
    context.check_binding(what, contents.len() as u64)?;
    context.checked(|| {
        context
            .device()
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(what),
                contents,
                usage: wgpu::BufferUsages::STORAGE | usage,
            })
    })
}

/// Refuses NaN and infinities (and negative values where `nonnegative`).
fn check_values(what: &str, values: &[f32], nonnegative: bool) -> Result<(), GpuError> {
    let bad = |index: usize, problem| GpuError::BadInput {
        what: what.to_owned(),
        index,
        value: values[index],
        problem,
    };
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(bad(i, "not finite"));
    }
    if nonnegative && let Some(i) = values.iter().position(|&v| v < 0.0) {
        return Err(bad(i, "negative"));
    }
    Ok(())
}

/// u32 indices on the device (a sparse matrix's row pointers and columns).
#[derive(Debug)]
pub struct DeviceIndices {
    buffer: wgpu::Buffer,
    len: usize,
}

impl DeviceIndices {
    /// Uploads `indices` (one binding's worth at most, checked before allocation).
    pub fn upload(context: &GpuContext, what: &str, indices: &[u32]) -> Result<Self, GpuError> {
        let buffer = storage_init(
            context,
            what,
            bytemuck::cast_slice(indices),
            wgpu::BufferUsages::empty(),
        )?;
        Ok(Self {
            buffer,
            len: indices.len(),
        })
    }

    /// The whole buffer as a binding.
    pub fn binding(&self) -> wgpu::BindingResource<'_> {
        self.buffer.as_entire_binding()
    }

    /// Number of indices.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether it holds none.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

/// Reads `len` f32 values from the start of `buffer` (which must allow `COPY_SRC`).
pub(crate) fn download_buffer(
    context: &GpuContext,
    buffer: &wgpu::Buffer,
    len: usize,
    what: &str,
) -> Result<Vec<f32>, GpuError> {
    let bytes = download_bytes(context, buffer, (len * 4) as u64, what)?;
    Ok(bytemuck::pod_collect_to_vec(&bytes))
}

/// Reads the first `bytes` bytes of `buffer` (which must allow `COPY_SRC`): one staging
/// buffer, one submit, one wait.
pub(crate) fn download_bytes(
    context: &GpuContext,
    buffer: &wgpu::Buffer,
    bytes: u64,
    what: &str,
) -> Result<Vec<u8>, GpuError> {
    if bytes == 0 {
        return Ok(Vec::new());
    }
    let device = context.device();
    let staging = context.checked(|| {
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("lucent staging"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("lucent download"),
        });
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, bytes);
        context.queue().submit([encoder.finish()]);
        staging
    })?;
    let slice = staging.slice(..);
    let (sender, receiver) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |result| {
        let _ = sender.send(result);
    });
    context.wait()?;
    receiver
        .recv()
        .map_err(|e| GpuError::Device(format!("{what}: {e}")))?
        .map_err(|e| GpuError::Device(format!("{what}: {e}")))?;
    let values = slice
        .get_mapped_range()
        .map_err(|e| GpuError::Device(format!("{what}: {e}")))?
        .to_vec();
    staging.unmap();
    Ok(values)
}
