//! `gpu-dom`: `dom` with its transport steps on the device. The iteration — source
//! iteration with DSA and Anderson mixing, or GMRES, their stopping rules and safeguards —
//! runs on the host unchanged (`lucent_dom::SourceIteration::on_device`); each transport
//! step's sweeps and scattering product run in `shaders/dom.wgsl`, two compute passes
//! timed apart: nx + ny + nz − 2 dispatches of `sweep_plane`, each one cell hyperplane of
//! all eight octants and all their directions at once (one invocation per octant,
//! direction and cell), then `scatter` (J′ and the scalar flux).
//!
//! What stays on the device between steps: σ_t, the radiance ψ̄ per cell and direction,
//! and 3 face planes per direction (the sweep's in-flight faces). What moves per step: the
//! source S = Q + σ_s J (filled on the host while it is split by octant: cells × N f32) up
//! and J′ down, the scalar flux and the boundary's currents down — 4 bytes per cell and
//! direction each way, through staging buffers kept for the solve. The DSA and Anderson
//! steps, which need J on the host, are the reason for the round trip (the issue allows
//! the acceleration on the host).
//!
//! The wavefront ([`Wavefront`]): single cells by default (`sweep_plane`: each dispatch
//! covers the (octant, direction, j, k) tuples of a cell hyperplane's (j, k) bounding box,
//! 3n − 2 dispatches), or blocks of 4³ cells (`sweep_blocks`: one workgroup per octant and
//! block of a block hyperplane, which runs the block's own cell diagonals between storage
//! barriers, 3n/4 − 2 dispatches). Either way one compute pass per sweep (the scattering
//! product another), and the same bits. Measured on an H200 (BENCHMARKS.md): blocks 7 %
//! faster at 128³ and 19 % slower at 256³ — the sweep is bound by each cell-direction's
//! own work, not by launches. Per
//! cell and direction the arrays are split by octant (eight bindings each), so that
//! 256³ × 48 directions fits the 2 GiB a binding may hold on current drivers.
//!
//! Precision: f32 throughout (the CPU sweeps in f64 and stores f32): one transport step
//! agrees with the CPU's to about 1e-6 relative, and the converged fluence to the stopping
//! tolerance plus that (`tests/gpu_dom.rs`).

use lucent_dom::Closure;
use lucent_dom::DomError;
use lucent_dom::device::{DeviceTransport, TransportOutput, TransportSetup, TransportStep};
use lucent_dom::sweep::Layout;
use lucent_gpu::{
    DeviceField, DeviceIndices, GpuContext, GpuError, Kernel, UniformSlots, WORKGROUP, groups_2d,
    shaders,
};
use rayon::prelude::*;

/// Floats per direction in the geometry buffer (`dom.wgsl`'s GEOMETRY).
const GEOMETRY: usize = 28;
/// Invocations of a `sweep_blocks` workgroup (`dom.wgsl`: BLOCK² columns × LANES).
const BLOCK_INVOCATIONS: u32 = 64;
/// Storage buffers `sweep_plane` binds (the octants' sources and radiance, eight each,
/// and seven more).
const STORAGE_BUFFERS: u32 = 23;

/// The uniform block of `dom.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct DomParams32 {
    dims: [u32; 4],
    plane: [u32; 4],
    bounds: [u32; 4],
    h: [f32; 4],
}

/// The (j′, k′) bounding box of hyperplane i′ + j′ + k′ = p: lowest j′, lowest k′ and the
/// extents.
fn plane_bounds([nx, ny, nz]: [usize; 3], p: usize) -> [usize; 4] {
    let z_lo = p.saturating_sub((nx - 1) + (ny - 1));
    let z_hi = p.min(nz - 1);
    let y_lo = p.saturating_sub(z_hi + (nx - 1));
    let y_hi = (p - z_lo).min(ny - 1);
    [y_lo, z_lo, y_hi + 1 - y_lo, z_hi + 1 - z_lo]
}

/// What one dispatch of a sweep covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Wavefront {
    /// A hyperplane of blocks of 4³ cells, each block's diagonals inside one workgroup.
    Blocks,
    /// A hyperplane of cells.
    #[default]
    Cells,
}

impl Wavefront {
    /// Cells along a block's edge.
    fn edge(self) -> usize {
        match self {
            Wavefront::Blocks => 4,
            Wavefront::Cells => 1,
        }
    }
}

/// A transport device on the process's shared GPU context, for
/// [`lucent_dom::DomSolver::on_device`] (what `gpu-dom` builds its solver with).
pub fn dom_transport() -> Result<Box<dyn DeviceTransport>, GpuError> {
    dom_transport_with(Wavefront::default())
}

/// [`dom_transport`] with the given wavefront (`cargo xtask bench-dom --gpu` times both).
pub fn dom_transport_with(wavefront: Wavefront) -> Result<Box<dyn DeviceTransport>, GpuError> {
    Ok(Box::new(GpuTransport::new(
        GpuContext::shared()?,
        wavefront,
    )))
}

/// The transport steps of one channel on `gpu`.
pub(crate) struct GpuTransport {
    gpu: &'static GpuContext,
    wavefront: Wavefront,
    state: Option<State>,
}

impl GpuTransport {
    pub(crate) fn new(gpu: &'static GpuContext, wavefront: Wavefront) -> Self {
        Self {
            gpu,
            wavefront,
            state: None,
        }
    }
}

/// A device buffer and the host-visible buffer it is read back through.
struct Readable {
    field: DeviceField,
    staging: wgpu::Buffer,
}

impl Readable {
    fn new(gpu: &GpuContext, what: &str, len: usize) -> Result<Self, GpuError> {
        let field = DeviceField::zeros(gpu, what, len)?;
        let staging = gpu.checked(|| {
            gpu.device().create_buffer(&wgpu::BufferDescriptor {
                label: Some(what),
                size: field.buffer().size(),
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })?;
        Ok(Self { field, staging })
    }
}

struct State {
    dims: [usize; 3],
    directions: usize,
    octants: [(usize, usize); 8],
    closure: u32,
    flags: wgpu::Buffer,
    /// Per octant: S up, J′ down.
    sources: Vec<Readable>,
    /// Host halves of the sources, per octant (cells × its directions).
    host: Vec<Vec<f32>>,
    inflow: DeviceField,
    fluence: Readable,
    outflow: Readable,
    sweep: std::sync::Arc<Kernel>,
    scatter: std::sync::Arc<Kernel>,
    sweep_binds: Vec<wgpu::BindGroup>,
    scatter_bind: wgpu::BindGroup,
    /// Per hyperplane.
    sweep_groups: Vec<[u32; 2]>,
    scatter_groups: [u32; 2],
    /// What only the bind groups read, held for their lifetime.
    _resident: Vec<DeviceField>,
    _indices: [DeviceIndices; 2],
    _slots: UniformSlots,
}

fn device(e: GpuError) -> DomError {
    DomError::Device(e.to_string())
}

impl DeviceTransport for GpuTransport {
    fn prepare(&mut self, setup: &TransportSetup<'_>) -> Result<(), DomError> {
        let gpu = self.gpu;
        let offered = gpu.limits().max_storage_buffers_per_shader_stage;
        if offered < STORAGE_BUFFERS {
            return Err(device(GpuError::Unsupported {
                adapter: gpu.info().name.clone(),
                what: "max_storage_buffers_per_shader_stage",
                needed: u64::from(STORAGE_BUFFERS),
                available: u64::from(offered),
            }));
        }
        let layout: &Layout = setup.layout;
        let dims = layout.dims();
        let [nx, ny, nz] = dims;
        let cells = layout.cells();
        let n = setup.directions.len();
        if setup.scattering.len() != n * n {
            return Err(DomError::Invalid(format!(
                "a device sweeps the storage directions: a {n} × {} scattering matrix",
                setup.scattering.len() / n.max(1)
            )));
        }
        let widest = setup.octants.iter().map(|o| o.1).max().unwrap_or(0);
        let plane_block = ny * nz + nx * nz + nx * ny;
        // The largest bindings are checked before anything is allocated.
        for (what, values) in [
            ("gpu-dom octant radiance", cells * widest),
            ("gpu-dom face planes", n * plane_block),
        ] {
            gpu.check_binding(what, 4 * values as u64).map_err(device)?;
        }
        let order: Vec<u32> = (0..cells as u32).collect();
        let grid_of = layout.to_blocks(&order, 1);
        let mut block_of = vec![0u32; cells];
        for (b, &g) in grid_of.iter().enumerate() {
            block_of[g as usize] = b as u32;
        }
        let mut geometry = vec![0.0f32; n * GEOMETRY];
        for (d, (omega, w)) in setup.directions.iter().zip(setup.weights).enumerate() {
            let cell = lucent_dom::closure::CellDirection::new(*omega, setup.spacing);
            let row = &mut geometry[d * GEOMETRY..(d + 1) * GEOMETRY];
            for a in 0..3 {
                row[a] = cell.c[a] as f32;
                row[22 + a] = omega[a].abs() as f32;
                for b in 0..3 {
                    row[4 + 3 * a + b] = cell.fraction[a][b] as f32;
                    row[13 + 3 * a + b] = cell.chords[a][b] as f32;
                }
            }
            row[3] = *w as f32;
        }
        let octants: Vec<u32> = setup
            .octants
            .iter()
            .flat_map(|&(first, count)| [first as u32, count as u32])
            .collect();
        let scattering: Vec<f32> = setup.scattering.iter().map(|&v| v as f32).collect();
        let err = device;
        let upload = |what: &str, values: &[f32], nonnegative: bool| {
            DeviceField::upload(gpu, what, values, nonnegative).map_err(err)
        };
        let geometry = upload("gpu-dom direction geometry", &geometry, false)?;
        let order = DeviceIndices::upload(gpu, "gpu-dom block order", &block_of).map_err(err)?;
        let octant_buffer = DeviceIndices::upload(gpu, "gpu-dom octants", &octants).map_err(err)?;
        let sigma_t = upload("gpu-dom σ_t", setup.sigma_t, true)?;
        let scattering = upload("gpu-dom scattering matrix", &scattering, false)?;
        let zeros = |what: &str, len: usize| DeviceField::zeros(gpu, what, len).map_err(err);
        let faces = zeros("gpu-dom face planes", n * plane_block)?;
        let inflow = zeros("gpu-dom inflow", 2 * plane_block)?;
        let readable = |what: &str, len: usize| Readable::new(gpu, what, len).map_err(err);
        let fluence = readable("gpu-dom fluence", cells)?;
        let outflow = readable("gpu-dom outflow", n * plane_block)?;
        let mut sources = Vec::with_capacity(8);
        let mut radiance = Vec::with_capacity(8);
        for (o, &(_, count)) in setup.octants.iter().enumerate() {
            sources.push(readable(
                &format!("gpu-dom octant {o} source"),
                cells * count,
            )?);
            radiance.push(zeros(
                &format!("gpu-dom octant {o} radiance"),
                cells * count,
            )?);
        }
        let flags = gpu
            .checked(|| {
                gpu.device().create_buffer(&wgpu::BufferDescriptor {
                    label: Some("gpu-dom step flags"),
                    size: 16,
                    usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            })
            .map_err(err)?;
        let (entry, per_group) = match self.wavefront {
            Wavefront::Blocks => ("sweep_blocks", BLOCK_INVOCATIONS),
            Wavefront::Cells => ("sweep_plane", WORKGROUP),
        };
        let sweep = gpu.kernel("dom.wgsl", shaders::DOM, entry).map_err(err)?;
        let scatter = gpu
            .kernel("dom.wgsl", shaders::DOM, "scatter")
            .map_err(err)?;
        // The wavefront's hyperplanes, of cells or of blocks; per plane one invocation per
        // octant, (j, k) of its bounding box and direction (cells), or one workgroup per
        // octant and (J, K) (blocks).
        let edge = self.wavefront.edge();
        let units = dims.map(|d| d.div_ceil(edge));
        let planes = units.iter().sum::<usize>() - 2;
        let bounds: Vec<[usize; 4]> = (0..planes).map(|p| plane_bounds(units, p)).collect();
        let sweep_groups: Vec<[u32; 2]> = bounds
            .iter()
            .map(|b| {
                let invocations = match self.wavefront {
                    Wavefront::Blocks => 8 * b[2] * b[3] * BLOCK_INVOCATIONS as usize,
                    Wavefront::Cells => 8 * widest * b[2] * b[3],
                };
                groups_2d(gpu, invocations as u64, per_group)
            })
            .collect();
        let scatter_groups = groups_2d(gpu, (cells * n) as u64, WORKGROUP);
        let h = setup.spacing;
        let width = h.iter().copied().fold(f64::INFINITY, f64::min);
        let block = |p: usize, groups: [u32; 2], bounds: [usize; 4]| DomParams32 {
            dims: [nx as u32, ny as u32, nz as u32, groups[0]],
            plane: [p as u32, n as u32, widest as u32, 0],
            bounds: bounds.map(|v| v as u32),
            h: [h[0] as f32, h[1] as f32, h[2] as f32, width as f32],
        };
        let mut blocks: Vec<DomParams32> = (0..planes)
            .map(|p| block(p, sweep_groups[p], bounds[p]))
            .collect();
        blocks.push(block(0, scatter_groups, [0, 0, 1, 1]));
        let slots = UniformSlots::new(gpu, "gpu-dom planes", &blocks).map_err(err)?;
        let octant_bindings = |first: u32| -> Vec<(u32, wgpu::BindingResource<'_>)> {
            let mut v: Vec<(u32, wgpu::BindingResource<'_>)> = Vec::with_capacity(16);
            for (o, s) in sources.iter().enumerate() {
                v.push((first + o as u32, s.field.binding()));
            }
            for (o, r) in radiance.iter().enumerate() {
                v.push((first + 8 + o as u32, r.binding()));
            }
            v
        };
        let sweep_binds = (0..planes)
            .map(|p| {
                let mut entries = vec![
                    (0, slots.slot(p)),
                    (1, flags.as_entire_binding()),
                    (2, octant_buffer.binding()),
                    (3, geometry.binding()),
                    (4, order.binding()),
                    (5, sigma_t.binding()),
                    (6, faces.binding()),
                    (7, inflow.binding()),
                    (8, outflow.field.binding()),
                ];
                entries.extend(octant_bindings(11));
                sweep.bind_at(gpu, &entries)
            })
            .collect::<Result<Vec<_>, _>>()
            .map_err(err)?;
        let mut entries = vec![
            (0, slots.slot(planes)),
            (2, octant_buffer.binding()),
            (3, geometry.binding()),
            (9, fluence.field.binding()),
            (10, scattering.binding()),
        ];
        entries.extend(octant_bindings(11));
        let scatter_bind = scatter.bind_at(gpu, &entries).map_err(err)?;
        drop(entries);
        let mut resident = vec![geometry, sigma_t, scattering, faces];
        resident.extend(radiance);
        self.state = Some(State {
            dims,
            directions: n,
            octants: setup.octants,
            closure: match setup.closure {
                Closure::Step => 0,
                Closure::Diamond => 1,
                Closure::Exponential => 2,
            },
            flags,
            host: setup
                .octants
                .iter()
                .map(|&(_, count)| vec![0.0; cells * count])
                .collect(),
            sources,
            inflow,
            fluence,
            outflow,
            sweep,
            scatter,
            sweep_binds,
            scatter_bind,
            sweep_groups,
            scatter_groups,
            _resident: resident,
            _indices: [order, octant_buffer],
            _slots: slots,
        });
        Ok(())
    }

    fn transport(
        &mut self,
        step: &TransportStep<'_>,
        inscattered: &mut [f32],
    ) -> Result<TransportOutput, DomError> {
        let gpu = self.gpu;
        let err = device;
        let s = self
            .state
            .as_mut()
            .ok_or_else(|| DomError::Invalid("gpu-dom: transport before prepare".into()))?;
        let [nx, ny, nz] = s.dims;
        let cells = nx * ny * nz;
        let n = s.directions;
        if inscattered.len() != n * cells || step.inscattered.len() != n * cells {
            return Err(DomError::Invalid(format!(
                "gpu-dom: {} in-scattered values for {cells} cells × {n} directions",
                step.inscattered.len(),
            )));
        }
        // S = Q + σ_s J, split by octant, as lucent-dom's sweep fills it (f32 inputs added in
        // f64, stored in f32).
        for (host, &(first, count)) in s.host.iter_mut().zip(&s.octants) {
            host.par_chunks_mut(count.max(1))
                .enumerate()
                .for_each(|(b, row)| {
                    let sigma = f64::from(step.sigma_s[b]);
                    let at = b * n + first;
                    for (d, v) in row.iter_mut().enumerate() {
                        let q = step.fixed.map_or(0.0, |f| f64::from(f[at + d]));
                        *v = (q + sigma * f64::from(step.inscattered[at + d])) as f32;
                    }
                });
        }
        let flags: [u32; 4] = [s.closure, u32::from(step.linear), 0, 0];
        let inflow: Vec<f32> = step.inflow.iter().flatten().map(|&v| v as f32).collect();
        gpu.checked(|| {
            let queue = gpu.queue();
            queue.write_buffer(&s.flags, 0, bytemuck::cast_slice(&flags));
            queue.write_buffer(s.inflow.buffer(), 0, bytemuck::cast_slice(&inflow));
            for (source, host) in s.sources.iter().zip(&s.host) {
                if !host.is_empty() {
                    queue.write_buffer(source.field.buffer(), 0, bytemuck::cast_slice(host));
                }
            }
        })
        .map_err(err)?;
        // The uploads land first; then the pass alone is timed: by the device's timestamps
        // where it has them (its own clock, recording and submission excluded), else from
        // submit to completion.
        gpu.wait().map_err(err)?;
        // The sweeps and the scattering product in two passes, timed apart (the second
        // submit costs one more wait per step, against the host's fill and transfers of
        // the whole radiance).
        let sweep_seconds = gpu
            .timed_pass("gpu-dom sweeps", |pass| {
                for (bind, &groups) in s.sweep_binds.iter().zip(&s.sweep_groups) {
                    s.sweep.dispatch(pass, bind, groups);
                }
            })
            .map_err(err)?
            .seconds;
        let scatter_seconds = gpu
            .timed_pass("gpu-dom scattering product", |pass| {
                s.scatter.dispatch(pass, &s.scatter_bind, s.scatter_groups);
            })
            .map_err(err)?
            .seconds;
        // J′ (in the sources' buffers), the fluence and the currents back through the
        // staging buffers: one submit, one wait.
        let readables: Vec<&Readable> = s.sources.iter().chain([&s.fluence, &s.outflow]).collect();
        gpu.checked(|| {
            let mut encoder =
                gpu.device()
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                        label: Some("gpu-dom read back"),
                    });
            for r in &readables {
                encoder.copy_buffer_to_buffer(
                    r.field.buffer(),
                    0,
                    &r.staging,
                    0,
                    r.field.buffer().size(),
                );
            }
            gpu.queue().submit([encoder.finish()]);
        })
        .map_err(err)?;
        let (sender, receiver) = std::sync::mpsc::channel();
        for r in &readables {
            let sender = sender.clone();
            r.staging
                .slice(..)
                .map_async(wgpu::MapMode::Read, move |result| {
                    let _ = sender.send(result);
                });
        }
        drop(sender);
        gpu.wait().map_err(err)?;
        for result in receiver {
            result.map_err(|e| DomError::Device(format!("gpu-dom read back: {e}")))?;
        }
        let mapped = |r: &Readable, f: &mut dyn FnMut(&[f32])| -> Result<(), DomError> {
            let view = r
                .staging
                .slice(..)
                .get_mapped_range()
                .map_err(|e| DomError::Device(format!("gpu-dom read back: {e}")))?;
            f(bytemuck::cast_slice(&view));
            Ok(())
        };
        for (r, &(first, count)) in s.sources.iter().zip(&s.octants) {
            if count == 0 {
                continue;
            }
            mapped(r, &mut |values| {
                inscattered
                    .par_chunks_mut(n)
                    .zip(values.par_chunks(count))
                    .for_each(|(row, octant)| row[first..first + count].copy_from_slice(octant));
            })?;
        }
        let mut fluence = Vec::new();
        mapped(&s.fluence, &mut |values| {
            fluence = values[..cells].iter().map(|&v| f64::from(v)).collect();
        })?;
        // Each slot's directions into the boundary faces: octant by octant, as the CPU
        // sweep adds them.
        let areas = [ny * nz, nx * nz, nx * ny];
        let mut outflow: [Vec<f64>; 6] = std::array::from_fn(|f| vec![0.0; areas[f / 2]]);
        mapped(&s.outflow, &mut |values| {
            for (o, &(first, count)) in s.octants.iter().enumerate() {
                for a in 0..3 {
                    let negative = o & (1 << a) != 0;
                    let face = 2 * a + usize::from(!negative);
                    let offset: usize = areas[..a].iter().sum();
                    for (slot, out) in outflow[face].iter_mut().enumerate() {
                        let at = (offset + slot) * n;
                        let current: f64 = values[at + first..at + first + count]
                            .iter()
                            .map(|&v| f64::from(v))
                            .sum();
                        *out += current;
                    }
                }
            }
        })?;
        for r in &readables {
            r.staging.unmap();
        }
        Ok(TransportOutput {
            fluence,
            outflow,
            kernel_seconds: sweep_seconds + scatter_seconds,
            scatter_seconds,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::plane_bounds;

    /// Every cell of every hyperplane lies in the plane's bounding box, and the box's
    /// corners are tight (each edge of the box holds a cell of the plane).
    #[test]
    fn the_plane_bounds_hold_exactly_the_plane() {
        for dims in [[1, 1, 1], [5, 3, 7], [7, 12, 10], [16, 16, 16], [2, 9, 4]] {
            let [nx, ny, nz] = dims;
            for p in 0..nx + ny + nz - 2 {
                let [y0, z0, wy, wz] = plane_bounds(dims, p);
                let mut seen = [usize::MAX, usize::MAX, 0, 0];
                for rz in 0..nz {
                    for ry in 0..ny {
                        if ry + rz <= p && p - ry - rz < nx {
                            assert!((y0..y0 + wy).contains(&ry), "{dims:?} p {p}: j′ {ry}");
                            assert!((z0..z0 + wz).contains(&rz), "{dims:?} p {p}: k′ {rz}");
                            seen = [
                                seen[0].min(ry),
                                seen[1].min(rz),
                                seen[2].max(ry),
                                seen[3].max(rz),
                            ];
                        }
                    }
                }
                assert_eq!(seen, [y0, z0, y0 + wy - 1, z0 + wz - 1], "{dims:?} p {p}");
            }
        }
    }
}
