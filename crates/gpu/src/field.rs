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

    /// [`DeviceField::write`] through kept staging (done when it returns).
    pub fn write_staged(
        &self,
        context: &GpuContext,
        values: &[f32],
        nonnegative: bool,
        transfers: &Transfers,
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
        transfers.write(context, &self.buffer, bytemuck::cast_slice(values))
    }

    /// Copies the values into `out` (of the field's length) through kept staging.
    pub fn download_into(
        &self,
        context: &GpuContext,
        out: &mut [f32],
        transfers: &Transfers,
    ) -> Result<(), GpuError> {
        if out.len() != self.len {
            return Err(GpuError::Device(format!(
                "{}: {} values read from a field of {}",
                self.what,
                out.len(),
                self.len
            )));
        }
        transfers.read(context, &self.buffer, bytemuck::cast_slice_mut(out))
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

/// One f64 field in a storage buffer, for kernels that keep a solution or a residual in
/// double precision (on a device created with `SHADER_F64`: [`GpuContext::has_f64`]).
#[derive(Debug)]
pub struct DeviceField64 {
    buffer: wgpu::Buffer,
    len: usize,
    what: String,
}

impl DeviceField64 {
    /// Uploads `values` after checking that every one is finite and that they fit one
    /// binding, before anything is allocated on the device.
    pub fn upload(context: &GpuContext, what: &str, values: &[f64]) -> Result<Self, GpuError> {
        check_values64(what, values)?;
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

    /// A field of `len` zeros.
    pub fn zeros(context: &GpuContext, what: &str, len: usize) -> Result<Self, GpuError> {
        Self::upload(context, what, &vec![0.0; len])
    }

    /// The storage buffer.
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// The whole field as a binding.
    pub fn binding(&self) -> wgpu::BindingResource<'_> {
        self.buffer.as_entire_binding()
    }

    /// Number of values.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether it holds no values.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Replaces the values (same length, finite); the write lands before the next submit.
    pub fn write(&self, context: &GpuContext, values: &[f64]) -> Result<(), GpuError> {
        self.check_len(values.len())?;
        check_values64(&self.what, values)?;
        if !values.is_empty() {
            context.checked(|| {
                context
                    .queue()
                    .write_buffer(&self.buffer, 0, bytemuck::cast_slice(values))
            })?;
        }
        Ok(())
    }

    /// [`DeviceField64::write`] through kept staging (done when it returns).
    pub fn write_staged(
        &self,
        context: &GpuContext,
        values: &[f64],
        transfers: &Transfers,
    ) -> Result<(), GpuError> {
        self.check_len(values.len())?;
        check_values64(&self.what, values)?;
        transfers.write(context, &self.buffer, bytemuck::cast_slice(values))
    }

    /// Copies the values into `out` (of the field's length) through kept staging.
    pub fn download_into(
        &self,
        context: &GpuContext,
        out: &mut [f64],
        transfers: &Transfers,
    ) -> Result<(), GpuError> {
        self.check_len(out.len())?;
        transfers.read(context, &self.buffer, bytemuck::cast_slice_mut(out))
    }

    fn check_len(&self, len: usize) -> Result<(), GpuError> {
        if len != self.len {
            return Err(GpuError::Device(format!(
                "{}: {len} values for a field of {}",
                self.what, self.len
            )));
        }
        Ok(())
    }

    /// Copies the values back to the host (one staging buffer, one wait).
    pub fn download(&self, context: &GpuContext) -> Result<Vec<f64>, GpuError> {
        let bytes = download_bytes(context, &self.buffer, (self.len * 8) as u64, &self.what)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }
}

/// The most bytes [`Transfers`] stages at a time.
pub const TRANSFER_CHUNK_BYTES: u64 = 32 << 20;

/// Kept staging for moving large vectors between host and device in chunks of at most
/// [`TRANSFER_CHUNK_BYTES`]: two buffers mapped for writing and two for reading, allocated
/// once and used in turn, so the host copies one chunk while the device moves the other.
/// A transfer then neither allocates staging memory nor faults its pages in, as
/// `Queue::write_buffer` and a staging buffer made per download do each time (64 MiB each
/// way took 150 ms on an H200's host that way, under 1 GB/s).
#[derive(Debug)]
pub struct Transfers {
    up: [wgpu::Buffer; 2],
    down: [wgpu::Buffer; 2],
    chunk: u64,
}

impl Transfers {
    /// Staging for vectors of up to `largest` bytes (chunks of at most
    /// [`TRANSFER_CHUNK_BYTES`]).
    pub fn new(context: &GpuContext, largest: u64) -> Result<Self, GpuError> {
        Self::with_chunk(context, largest.min(TRANSFER_CHUNK_BYTES))
    }

    /// Staging of `chunk` bytes (rounded up to a multiple of 8; tests use small ones to
    /// cross chunk boundaries).
    pub fn with_chunk(context: &GpuContext, chunk: u64) -> Result<Self, GpuError> {
        let chunk = chunk.max(8).next_multiple_of(8);
        let buffer = |label, usage| {
            context.checked(|| {
                context.device().create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: chunk,
                    usage,
                    mapped_at_creation: false,
                })
            })
        };
        let up = wgpu::BufferUsages::MAP_WRITE | wgpu::BufferUsages::COPY_SRC;
        let down = wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST;
        Ok(Self {
            up: [
                buffer("lucent upload staging", up)?,
                buffer("lucent upload staging", up)?,
            ],
            down: [
                buffer("lucent download staging", down)?,
                buffer("lucent download staging", down)?,
            ],
            chunk,
        })
    }

    /// Copies `bytes` (a multiple of 4) to the start of `to`, chunk by chunk through the
    /// two upload buffers in turn (chunk i + 1 is copied into one while the device copies
    /// chunk i out of the other); done when it returns.
    fn write(&self, context: &GpuContext, to: &wgpu::Buffer, bytes: &[u8]) -> Result<(), GpuError> {
        let mut last: [Option<wgpu::SubmissionIndex>; 2] = [None, None];
        for (i, piece) in bytes.chunks(self.chunk as usize).enumerate() {
            let (staging, len) = (&self.up[i % 2], piece.len() as u64);
            map_after(
                context,
                staging,
                len,
                wgpu::MapMode::Write,
                last[i % 2].take(),
                "upload staging",
            )?;
            let copied = copy_in_parallel(staging, piece);
            staging.unmap();
            copied.map_err(|e| GpuError::Device(format!("upload staging: {e}")))?;
            last[i % 2] = Some(context.checked(|| {
                let mut encoder =
                    context
                        .device()
                        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                            label: Some("lucent upload"),
                        });
                encoder.copy_buffer_to_buffer(staging, 0, to, i as u64 * self.chunk, len);
                context.queue().submit([encoder.finish()])
            })?);
        }
        context.wait()
    }

    /// Copies the start of `from` into `out` (a multiple of 4 bytes), chunk by chunk
    /// through the two download buffers in turn (the device copies chunk i + 1 into one
    /// while the host copies chunk i out of the other).
    fn read(
        &self,
        context: &GpuContext,
        from: &wgpu::Buffer,
        out: &mut [u8],
    ) -> Result<(), GpuError> {
        let chunk = self.chunk as usize;
        let total = out.len();
        let pieces = total.div_ceil(chunk);
        let fetch = |i: usize| -> Result<wgpu::SubmissionIndex, GpuError> {
            let len = (total - i * chunk).min(chunk) as u64;
            context.checked(|| {
                let mut encoder =
                    context
                        .device()
                        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                            label: Some("lucent download"),
                        });
                encoder.copy_buffer_to_buffer(from, (i * chunk) as u64, &self.down[i % 2], 0, len);
                context.queue().submit([encoder.finish()])
            })
        };
        let mut pending: [Option<wgpu::SubmissionIndex>; 2] = [None, None];
        for i in 0..pieces.min(2) {
            pending[i % 2] = Some(fetch(i)?);
        }
        for (i, piece) in out.chunks_mut(chunk).enumerate() {
            let (staging, len) = (&self.down[i % 2], piece.len() as u64);
            map_after(
                context,
                staging,
                len,
                wgpu::MapMode::Read,
                pending[i % 2].take(),
                "download staging",
            )?;
            let copied = staging
                .slice(..len)
                .get_mapped_range()
                .map(|view| copy_out_in_parallel(&view, piece));
            staging.unmap();
            copied.map_err(|e| GpuError::Device(format!("download staging: {e}")))?;
            if i + 2 < pieces {
                pending[i % 2] = Some(fetch(i + 2)?);
            }
        }
        Ok(())
    }
}

/// Maps the first `bytes` of `buffer` for `mode` once submission `after` (its last use)
/// has finished, without waiting for later submissions.
fn map_after(
    context: &GpuContext,
    buffer: &wgpu::Buffer,
    bytes: u64,
    mode: wgpu::MapMode,
    after: Option<wgpu::SubmissionIndex>,
    what: &str,
) -> Result<(), GpuError> {
    let (sender, receiver) = std::sync::mpsc::channel();
    buffer.slice(..bytes).map_async(mode, move |result| {
        let _ = sender.send(result);
    });
    let poll = |kind| {
        context
            .device()
            .poll(kind)
            .map(|_| ())
            .map_err(|e| GpuError::Device(format!("{what}: {e}")))
    };
    match after {
        Some(index) => poll(wgpu::PollType::Wait {
            submission_index: Some(index),
            timeout: None,
        })?,
        None => poll(wgpu::PollType::Poll)?,
    }
    let result = match receiver.try_recv() {
        Ok(result) => result,
        // Not resolved by that poll: wait for everything (correct, only slower).
        Err(_) => {
            context.wait()?;
            receiver
                .recv()
                .map_err(|e| GpuError::Device(format!("{what}: {e}")))?
        }
    };
    result.map_err(|e| GpuError::Device(format!("{what}: {e}")))
}

/// Bytes below which a staging copy stays on one thread.
const PARALLEL_COPY_BYTES: usize = 4 << 20;

/// Threads for one staging copy: a single thread copies into or out of mapped memory at
/// a few GB/s, well below the bus.
fn copy_threads(bytes: usize) -> usize {
    if bytes < PARALLEL_COPY_BYTES {
        return 1;
    }
    std::thread::available_parallelism().map_or(1, |n| n.get().min(8))
}

/// The start of `to` (mapped for writing) = `from`, split over [`copy_threads`] scoped
/// threads, each through its own view (views of disjoint ranges may be held at once;
/// each part starts at a multiple of 8 bytes, wgpu's map alignment).
fn copy_in_parallel(to: &wgpu::Buffer, from: &[u8]) -> Result<(), wgpu::MapRangeError> {
    let threads = copy_threads(from.len());
    let part = from.len().div_ceil(threads).next_multiple_of(8);
    let views = from
        .chunks(part)
        .enumerate()
        .map(|(i, source)| {
            let at = (i * part) as u64;
            to.slice(at..at + source.len() as u64)
                .get_mapped_range_mut()
                .map(|view| (view, source))
        })
        .collect::<Result<Vec<_>, _>>()?;
    std::thread::scope(|scope| {
        for (mut view, source) in views {
            scope.spawn(move || view.copy_from_slice(source));
        }
    });
    Ok(())
}

/// `to` = `from` (mapped for reading), split over [`copy_threads`] scoped threads.
fn copy_out_in_parallel(from: &[u8], to: &mut [u8]) {
    let threads = copy_threads(from.len());
    let part = from.len().div_ceil(threads).next_multiple_of(4);
    std::thread::scope(|scope| {
        for (to, from) in to.chunks_mut(part).zip(from.chunks(part)) {
            scope.spawn(move || to.copy_from_slice(from));
        }
    });
}

/// Maps the first `bytes` of `buffer` for `mode` once the queue is done with it.
fn map(
    context: &GpuContext,
    buffer: &wgpu::Buffer,
    bytes: u64,
    mode: wgpu::MapMode,
    what: &str,
) -> Result<(), GpuError> {
    let (sender, receiver) = std::sync::mpsc::channel();
    buffer.slice(..bytes).map_async(mode, move |result| {
        let _ = sender.send(result);
    });
    context.wait()?;
    receiver
        .recv()
        .map_err(|e| GpuError::Device(format!("{what}: {e}")))?
        .map_err(|e| GpuError::Device(format!("{what}: {e}")))
}

/// A small mapped-read staging buffer kept for a loop that reads a few values back after
/// each submit (a norm, timestamps): the copy is recorded into the loop's own command
/// buffer ([`Readback::record`]), so reading costs a map and no extra submit.
#[derive(Debug)]
pub struct Readback {
    staging: wgpu::Buffer,
    bytes: u64,
    what: String,
}

impl Readback {
    /// A staging buffer of `bytes` bytes (a multiple of 4).
    pub fn new(context: &GpuContext, what: &str, bytes: u64) -> Result<Self, GpuError> {
        let staging = context.checked(|| {
            context.device().create_buffer(&wgpu::BufferDescriptor {
                label: Some(what),
                size: bytes.max(4),
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })?;
        Ok(Self {
            staging,
            bytes,
            what: what.to_owned(),
        })
    }

    /// Records a copy of `bytes` bytes of `from` (at `from_offset`) to `at` in the
    /// staging buffer (offsets and sizes multiples of 4).
    pub fn record(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        from: &wgpu::Buffer,
        from_offset: u64,
        at: u64,
        bytes: u64,
    ) {
        encoder.copy_buffer_to_buffer(from, from_offset, &self.staging, at, bytes);
    }

    /// The staging buffer's bytes, once what was submitted has finished (waits for it).
    pub fn read(&self, context: &GpuContext) -> Result<Vec<u8>, GpuError> {
        map_read(context, &self.staging, self.bytes, &self.what)
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

/// Refuses NaN and infinities in f64 values.
fn check_values64(what: &str, values: &[f64]) -> Result<(), GpuError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(GpuError::BadInput {
            what: what.to_owned(),
            index,
            value: values[index] as f32,
            problem: "not finite",
        }),
        None => Ok(()),
    }
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
    map_read(context, &staging, bytes, what)
}

/// Maps the first `bytes` bytes of a `MAP_READ` buffer once the queue has finished, copies
/// them out and unmaps it.
fn map_read(
    context: &GpuContext,
    staging: &wgpu::Buffer,
    bytes: u64,
    what: &str,
) -> Result<Vec<u8>, GpuError> {
    map(context, staging, bytes, wgpu::MapMode::Read, what)?;
    let slice = staging.slice(..bytes);
    let values = slice
        .get_mapped_range()
        .map_err(|e| GpuError::Device(format!("{what}: {e}")))?
        .to_vec();
    staging.unmap();
    Ok(values)
}
