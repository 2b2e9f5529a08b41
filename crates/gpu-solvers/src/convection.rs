//! `gpu-convection-diffusion`: Zhang & Ma's illumination on the device, per channel:
//! every directional and point light marched to steady state by short characteristics
//! (the CPU twin's default `characteristic` model, `shaders/convection.wgsl`), composed
//! with the lights' colours, then the implicit scattering step (Eq. 23) solved by
//! red–black Gauss–Seidel (`shaders/scatter.wgsl`).
//!
//! ## Layer sweeps
//!
//! A cell's characteristic value reads only nodes of the plane of cell centres one step
//! upstream across the light's dominant axis. A distant light's layers are those planes,
//! upwind first, one dispatch each: one pass, all recorded in one submit, is the exact
//! steady state (`StopReason::Exact`), as the CPU's ordered sweep. A point light's layers
//! are the cubic shells of Chebyshev distance s around the cell nearest to it: a shell's
//! cells read earlier shells from this pass and cells of their own shell (which the
//! quadratic stencil can reach on the diagonals) from the previous pass, so passes repeat
//! — each one submit — until the largest change over the largest value is below
//! `march_tolerance`, as the CPU's repeated ordered passes.
//!
//! ## Precision
//!
//! f32 on the device: the march's values agree with the CPU's f64 march to a few 10⁻⁶
//! relative (the attenuations e^{−τ} and interpolation weights round per step, and errors
//! do not grow: the interpolation is convex); the scattering step stops at a relative
//! residual of `scatter_tolerance` (≥ 10⁻⁶) where the CPU's multigrid reaches 10⁻⁸.

use std::sync::Arc;

use lucent_core::driver::{Context, Outcome, Record};
use lucent_core::{Light, Problem, Progress, SolveError, StopReason};
use lucent_explicit::Lattice;
use lucent_gpu::{
    DeviceField, GpuContext, GpuError, Kernel, UniformSlots, WORKGROUP, groups_2d, shaders,
};
use lucent_grid::Grid;

use crate::params::GpuConvectionParams;
use crate::solver::device_error;

/// How far (in cells, per axis) from the grid a point light's position may lie. The
/// device holds the light's position in f32 and the shells' cell indices in i32: 2²² cells
/// keeps two bits below a cell in the position and the shell arithmetic far from overflow.
/// Farther lights are refused (a directional light models them).
const POINT_LIGHT_REACH: f64 = (1u32 << 22) as f64;
/// Most passes of a point light's march.
const MAX_PASSES: usize = 200;
/// Red–black sweeps between residual checks of the scattering step.
const SWEEPS_PER_CHECK: usize = 16;
/// Most sweeps of the scattering step.
const MAX_SWEEPS: usize = 50_000;

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct MarchParams {
    dims: [u32; 4],
    origin: [f32; 4],
    light: [f32; 4],
    kind: [u32; 4],
    centre: [i32; 4],
}

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LayerParams {
    s: i32,
    pad: [i32; 3],
}

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ChangeParams {
    len: u32,
    groups_x: u32,
    pad: [u32; 2],
}

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ScatterParams {
    dims: [u32; 4],
    colour: [u32; 4],
    a: [f32; 4],
}

/// Bytes: on the host as `convection-diffusion` (its f64 fields per light and channel);
/// on the device σ_t, two march buffers, the scattering step's source and field and the
/// partials (about 24 bytes per cell).
pub(crate) fn memory_bytes(problem: &Problem) -> u64 {
    let n = problem.geometry().voxel_count() as u64;
    n * 8 * (6 + 2 * problem.lights().len() as u64) * problem.channels() as u64 + n * 24
}

/// The kernels, compiled once per solve.
struct Kernels {
    layer: Arc<Kernel>,
    change: Arc<Kernel>,
    sweep: Arc<Kernel>,
    residual: Arc<Kernel>,
}

/// A light as the march sees it.
#[derive(Debug, Clone, Copy)]
enum MarchLight {
    Distant(glam::DVec3),
    Point(glam::DVec3),
}

/// Zhang & Ma per channel on `gpu`.
pub(crate) fn solve(
    context: &Context<'_>,
    gpu: &GpuContext,
    params: &GpuConvectionParams,
    name: &str,
) -> Result<Outcome, SolveError> {
    let err = |e| device_error(name, e);
    let problem = context.problem;
    let l = lucent_explicit::lattice(problem)?;
    let geometry = *problem.geometry();
    let lights = problem.lights();
    for light in lights {
        if let Light::Point { position, .. } = light
            && !within_reach(&l, *position)
        {
            return Err(SolveError::Unsupported {
                solver: name.into(),
                feature: format!(
                    "a point light more than 2^22 cells from the grid (at {position}); \
                     the device holds positions in f32: model it as a directional light"
                ),
            });
        }
    }
    let kernels = Kernels {
        layer: gpu
            .kernel("convection.wgsl", shaders::CONVECTION, "layer_sweep")
            .map_err(err)?,
        change: gpu
            .kernel("max_change.wgsl", shaders::MAX_CHANGE, "max_change")
            .map_err(err)?,
        sweep: gpu
            .kernel("scatter.wgsl", shaders::SCATTER, "sweep")
            .map_err(err)?,
        residual: gpu
            .kernel("scatter.wgsl", shaders::SCATTER, "residual")
            .map_err(err)?,
    };
    let mut record = Record::exact((l.len() * 8 * 4) as u64);
    let mut fluence = Vec::with_capacity(problem.channels());
    let marches = (problem.channels() * lights.len()).max(1);
    for c in 0..problem.channels() {
        let sigma = DeviceField::from_grid(gpu, "sigma_t", problem.medium().sigma_t(c), true)
            .map_err(err)?;
        let mut total = vec![0.0f64; l.len()];
        for (i, light) in lights.iter().enumerate() {
            let (march_light, colour) = match light {
                Light::Directional {
                    direction,
                    irradiance,
                } => (
                    MarchLight::Distant(direction.normalize()),
                    irradiance.channel(c),
                ),
                Light::Point {
                    position,
                    intensity,
                } => (MarchLight::Point(*position), intensity.channel(c)),
                other => {
                    return Err(SolveError::Unsupported {
                        solver: name.into(),
                        feature: format!("{:?} lights", other.kind()),
                    });
                }
            };
            let (density, march_record) = march(
                gpu,
                &kernels,
                &l,
                &sigma,
                march_light,
                params.march_tolerance,
            )
            .map_err(err)?;
            for (t, rho) in total.iter_mut().zip(&density) {
                *t += colour * f64::from(*rho);
            }
            context.report(Progress {
                stage: "light march",
                fraction: (c * lights.len() + i + 1) as f64 / marches as f64,
                iteration: march_record.iterations,
                residual: march_record.residuals.last().copied(),
            });
            record = record.worse(march_record);
        }
        if params.scattering > 0.0 {
            let a = params.scattering / (l.spacing * l.spacing);
            let (field, scatter_record) =
                scatter(gpu, &kernels, &l, &total, a, params.scatter_tolerance).map_err(err)?;
            total = field;
            record = record.worse(scatter_record);
        }
        fluence.push(Grid::from_vec(
            geometry,
            total.iter().map(|&v| v as f32).collect(),
        )?);
    }
    Ok(Outcome {
        fluence,
        angular: None,
        standard_error: None,
        record,
    })
}

/// Whether a point light at `p` lies within [`POINT_LIGHT_REACH`] cells of the lattice on
/// every axis.
fn within_reach(l: &Lattice, p: glam::DVec3) -> bool {
    let v = (p - l.origin) / l.spacing;
    (0..3).all(|a| (-POINT_LIGHT_REACH..=l.dims[a] as f64 + POINT_LIGHT_REACH).contains(&v[a]))
}

/// One light's steady density (per unit of its colour) over `sigma`.
fn march(
    gpu: &GpuContext,
    kernels: &Kernels,
    l: &Lattice,
    sigma: &DeviceField,
    light: MarchLight,
    tolerance: f64,
) -> Result<(Vec<f32>, Record), GpuError> {
    let n = l.len();
    let dims = l.dims.map(|d| d as i32);
    let h = l.spacing;
    let buffers = [
        DeviceField::zeros(gpu, "march (even)", n)?,
        DeviceField::zeros(gpu, "march (odd)", n)?,
    ];
    // Layers, threads per layer and the uniform block.
    let (kind, vector, axis, centre, layers, threads) = match light {
        MarchLight::Distant(d) => {
            let axis = d.abs().max_position();
            let (b, e) = ((axis + 1) % 3, (axis + 2) % 3);
            (
                0u32,
                d,
                axis as u32,
                [0i32; 3],
                0..dims[axis],
                (dims[b] * dims[e]) as u64,
            )
        }
        MarchLight::Point(p) => {
            let v = (p - l.origin) / h - 0.5;
            let centre = [0, 1, 2].map(|a| v[a].round() as i32);
            // Shells from the nearest grid cell's distance to the farthest corner's.
            let near = (0..3)
                .map(|a| (-centre[a]).max(centre[a] - (dims[a] - 1)).max(0))
                .max()
                .unwrap_or(0);
            let far = (0..3)
                .map(|a| centre[a].abs().max((centre[a] - (dims[a] - 1)).abs()))
                .max()
                .unwrap_or(0);
            let per_face = (0..3)
                .map(|a| dims[(a + 1) % 3] * dims[(a + 2) % 3])
                .max()
                .unwrap_or(1) as u64;
            (1u32, p, 0u32, centre, near..far + 1, 6 * per_face)
        }
    };
    let groups = groups_2d(gpu, threads, 64);
    let per_face = (threads / 6).max(1) as u32;
    let march_params = MarchParams {
        dims: [
            l.dims[0] as u32,
            l.dims[1] as u32,
            l.dims[2] as u32,
            groups[0],
        ],
        origin: [
            l.origin.x as f32,
            l.origin.y as f32,
            l.origin.z as f32,
            h as f32,
        ],
        light: [vector.x as f32, vector.y as f32, vector.z as f32, 1.0],
        kind: [kind, axis, per_face, 0],
        centre: [centre[0], centre[1], centre[2], 0],
    };
    let march_uniform = UniformSlots::new(gpu, "march", &[march_params])?;
    let layer_slots: Vec<LayerParams> = layers
        .clone()
        .map(|s| LayerParams { s, pad: [0; 3] })
        .collect();
    let layer_uniforms = UniformSlots::new(gpu, "layers", &layer_slots)?;
    // bind[p][layer]: previous = buffers[p], current = buffers[1 − p].
    let mut bind = [Vec::new(), Vec::new()];
    for (p, list) in bind.iter_mut().enumerate() {
        for i in 0..layer_slots.len() {
            list.push(kernels.layer.bind(
                gpu,
                &[
                    sigma.binding(),
                    buffers[p].binding(),
                    buffers[1 - p].binding(),
                    march_uniform.slot(0),
                    layer_uniforms.slot(i),
                ],
            )?);
        }
    }
    let sweep = |p: usize| {
        gpu.submit_pass("gpu-convection-diffusion march", |pass| {
            for b in &bind[p] {
                kernels.layer.dispatch(pass, b, groups);
            }
        })
    };
    if matches!(light, MarchLight::Distant(_)) {
        // Every cell after its whole upstream plane: exact in one pass.
        sweep(0)?;
        let density = buffers[1].download(gpu)?;
        let mut record = Record::from_residuals(vec![0.0], StopReason::Exact, 0);
        record.iterations = 1;
        return Ok((density, record));
    }
    let change_groups = groups_2d(gpu, n as u64, WORKGROUP);
    let change_count = (change_groups[0] * change_groups[1]) as usize;
    let partials = DeviceField::zeros(gpu, "march change", 2 * change_count)?;
    let change_uniform = UniformSlots::new(
        gpu,
        "march change",
        &[ChangeParams {
            len: n as u32,
            groups_x: change_groups[0],
            pad: [0; 2],
        }],
    )?;
    let change_bind = [0usize, 1].map(|p| {
        kernels.change.bind(
            gpu,
            &[
                buffers[p].binding(),
                buffers[1 - p].binding(),
                partials.binding(),
                change_uniform.slot(0),
            ],
        )
    });
    let [even, odd] = change_bind;
    let change_bind = [even?, odd?];
    let mut residuals = Vec::new();
    let mut p = 0;
    let reason = loop {
        sweep(p)?;
        gpu.submit_pass("march change", |pass| {
            kernels
                .change
                .dispatch(pass, &change_bind[p], change_groups)
        })?;
        let sums = partials.download(gpu)?;
        let (mut change, mut largest) = (0.0f64, 0.0f64);
        for w in sums.chunks_exact(2) {
            change = change.max(f64::from(w[0]));
            largest = largest.max(f64::from(w[1]));
        }
        p = 1 - p;
        if largest >= 3.0e38 || change >= 3.0e38 {
            break StopReason::DivergedNonFinite {
                iteration: residuals.len() + 1,
            };
        }
        let relative = if largest > 0.0 {
            change / largest
        } else {
            change
        };
        residuals.push(relative);
        if relative <= tolerance {
            break StopReason::ConvergedRelative { residual: relative };
        }
        if residuals.len() >= MAX_PASSES {
            break StopReason::IterationLimit { residual: relative };
        }
    };
    let density = buffers[p].download(gpu)?;
    let mut record = Record::from_residuals(Vec::new(), reason, 0);
    record.iterations = residuals.len();
    record.residuals = residuals;
    Ok((density, record))
}

/// One backward-Euler step (1 − aΔ_h)x = `field` with Neumann faces, by red–black
/// Gauss–Seidel to a relative residual of `tolerance`.
fn scatter(
    gpu: &GpuContext,
    kernels: &Kernels,
    l: &Lattice,
    field: &[f64],
    a: f64,
    tolerance: f64,
) -> Result<(Vec<f64>, Record), GpuError> {
    let n = l.len();
    let values: Vec<f32> = field.iter().map(|&v| v as f32).collect();
    let initial = DeviceField::upload(gpu, "scattering source", &values, false)?;
    let x = DeviceField::upload(gpu, "scattered field", &values, false)?;
    let half = (l.dims[0].div_ceil(2) * l.dims[1] * l.dims[2]) as u64;
    let sweep_groups = groups_2d(gpu, half, WORKGROUP);
    let residual_groups = groups_2d(gpu, n as u64, WORKGROUP);
    let count = (residual_groups[0] * residual_groups[1]) as usize;
    let partials = DeviceField::zeros(gpu, "scatter residual", 2 * count)?;
    let dims = [l.dims[0] as u32, l.dims[1] as u32, l.dims[2] as u32];
    let slot = |colour: u32, groups_x: u32| ScatterParams {
        dims: [dims[0], dims[1], dims[2], groups_x],
        colour: [colour, 0, 0, 0],
        a: [a as f32, 0.0, 0.0, 0.0],
    };
    let uniforms = UniformSlots::new(
        gpu,
        "scatter",
        &[
            slot(0, sweep_groups[0]),
            slot(1, sweep_groups[0]),
            slot(0, residual_groups[0]),
        ],
    )?;
    let colours = [0usize, 1].map(|c| {
        kernels
            .sweep
            .bind(gpu, &[initial.binding(), x.binding(), uniforms.slot(c)])
    });
    let [red, black] = colours;
    let colours = [red?, black?];
    let residual_bind = kernels.residual.bind(
        gpu,
        &[
            initial.binding(),
            x.binding(),
            uniforms.slot(2),
            partials.binding(),
        ],
    )?;
    let mut residuals = Vec::new();
    let mut sweeps = 0;
    let reason = loop {
        gpu.submit_pass("scatter sweeps", |pass| {
            for _ in 0..SWEEPS_PER_CHECK {
                kernels.sweep.dispatch(pass, &colours[0], sweep_groups);
                kernels.sweep.dispatch(pass, &colours[1], sweep_groups);
            }
            kernels
                .residual
                .dispatch(pass, &residual_bind, residual_groups);
        })?;
        sweeps += SWEEPS_PER_CHECK;
        let sums = partials.download(gpu)?;
        let (mut r2, mut b2) = (0.0f64, 0.0f64);
        for w in sums.chunks_exact(2) {
            r2 += f64::from(w[0]);
            b2 += f64::from(w[1]);
        }
        if !(r2.is_finite() && b2.is_finite()) {
            break StopReason::DivergedNonFinite { iteration: sweeps };
        }
        let relative = if b2 > 0.0 {
            (r2 / b2).sqrt()
        } else {
            r2.sqrt()
        };
        residuals.push(relative);
        if relative <= tolerance {
            break StopReason::ConvergedRelative { residual: relative };
        }
        if sweeps >= MAX_SWEEPS {
            break StopReason::IterationLimit { residual: relative };
        }
    };
    let out = x.download(gpu)?.iter().map(|&v| f64::from(v)).collect();
    let mut record = Record::from_residuals(Vec::new(), reason, 0);
    record.iterations = sweeps;
    record.residuals = residuals;
    Ok((out, record))
}
