//! The cycle of `diffusion-mg` on the device: lucent-diffusion's level hierarchy (the
//! operators it builds, cut cells folded into the couplings and the extra diagonal)
//! uploaded once, and V-cycles for A x = b with the same smoother, sweeps, transfers and
//! coarsest solve as the host's cycle ([`lucent_diffusion::Multigrid::cycle_from_zero`]),
//! in f32 (`shaders/multigrid.wgsl`).
//!
//! A cycle is one command buffer: pre-smoothing colours and the fused residual and
//! restriction level by level, the coarsest level's solve, prolongation and
//! post-smoothing. The coarsest level (a few cells on a cube; at most
//! [`DENSE_COARSEST_MAX`] unknowns) is solved on the device by its inverse, computed once
//! on the host in f64 by Cholesky; a larger or indefinite one goes to the host's own
//! coarsest solve (CG in f64) between two command buffers.
//!
//! The outer iteration that takes f32 cycles to 1e-8 relative is iterative refinement,
//! r = b − A φ in f64, e ≈ A⁻¹ r by a cycle, φ += e, r −= A e, as on the host
//! ([`Multigrid::solve_with`]). Where the device has f64 (`SHADER_F64`), φ, b and r live on
//! the device (`shaders/multigrid_f64.wgsl`) and only ‖r‖² (8 bytes) comes back per cycle
//! for the stopping rule: [`OuterIteration::Device`]. Elsewhere the host keeps them and
//! each cycle moves its right-hand side up and its correction down in f32:
//! [`OuterIteration::Host`]. Both stop by the same rule on the same f64 residual.
//!
//! What the host's cycle offers and this one does not is refused, not approximated: W, F
//! and K cycles, the Jacobi smoother and trilinear prolongation.

use std::time::Instant;

use lucent_core::{Problem, Stopping};
use lucent_diffusion::{
    Cycle, DiffusionError, DiffusionProblem, DiffusionSolution, LevelOperator, Multigrid,
    MultigridSettings, Prolongation, Smoother, Sources,
};
use lucent_gpu::{
    DeviceField, DeviceField64, DeviceIndices, GpuContext, GpuError, Kernel, Readback,
    TimingSource, Transfers, UniformSlots, WORKGROUP, groups_2d,
};

/// The most unknowns (cells in the medium) a coarsest level may have for the device to
/// solve it by its dense inverse: 512² f64 = 2 MiB, and a Cholesky factorisation and
/// inverse of about 0.1 s on the host at that size. Cubes coarsen to at most 27 cells.
pub const DENSE_COARSEST_MAX: usize = 512;

/// Where the f64 outer iteration of [`DeviceMultigrid::solve`] runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OuterIteration {
    /// On the device (φ, b and r in f64 device memory; 8 bytes back per cycle). Needs
    /// `SHADER_F64`.
    Device,
    /// On the host (the right-hand side up and the correction down in f32 per cycle).
    Host,
}

/// The uniform block of `shaders/multigrid_f64.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct OuterParams {
    dims: [u32; 4],
    count: [u32; 4],
}

/// Bindings of the entry points of `shaders/multigrid_f64.wgsl`.
const OUTER_RESIDUAL: [u32; 11] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10];
const OUTER_CORRECT: [u32; 10] = [0, 1, 2, 3, 4, 6, 7, 8, 9, 10];
const OUTER_START: [u32; 3] = [0, 6, 8];
const OUTER_LOAD: [u32; 4] = [0, 5, 9, 10];
const OUTER_SUM: [u32; 3] = [0, 10, 11];
const COARSEST_DENSE: [u32; 5] = [0, 12, 13, 14, 15];

/// The device's f64 outer iteration: its vectors and kernels.
struct Outer {
    rhs: DeviceField64,
    phi: DeviceField64,
    norm: DeviceField64,
    residual: (std::sync::Arc<Kernel>, wgpu::BindGroup),
    correct: (std::sync::Arc<Kernel>, wgpu::BindGroup),
    start: (std::sync::Arc<Kernel>, wgpu::BindGroup),
    load: (std::sync::Arc<Kernel>, wgpu::BindGroup),
    /// Σ partials into the norm buffer's first value.
    sum: (std::sync::Arc<Kernel>, wgpu::BindGroup),
    /// The same into its second value.
    sum_second: (std::sync::Arc<Kernel>, wgpu::BindGroup),
    groups: [u32; 2],
    readback: Readback,
    _vectors: [DeviceField64; 2],
    _uniforms: UniformSlots,
}

/// Records one dispatch into a pass.
type Recorder<'a> = Box<dyn Fn(&mut wgpu::ComputePass<'_>) + 'a>;

/// One kernel's time on the finest level ([`DeviceMultigrid::time_fine_kernels`]).
#[derive(Debug, Clone, PartialEq)]
pub struct KernelTiming {
    /// What it does.
    pub name: &'static str,
    /// Seconds per dispatch, by the device's timestamps.
    pub seconds: f64,
    /// Seconds per dispatch by the host's clock from recording to completion (submission
    /// and the wait included: an upper bound).
    pub wall_seconds: f64,
    /// Bytes a dispatch must move at the least (each value once).
    pub bytes: f64,
}

/// The coarsest level's solve by its dense inverse on the device.
struct DenseCoarsest {
    kernel: std::sync::Arc<Kernel>,
    bind: wgpu::BindGroup,
    groups: [u32; 2],
    _inverse: DeviceField64,
    _unknowns: DeviceIndices,
    _uniforms: UniformSlots,
}

/// The uniform block of `shaders/multigrid.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LevelParams {
    dims: [u32; 4],
    coarse: [u32; 4],
}

/// The bindings each entry point of `shaders/multigrid.wgsl` reads (wgpu derives each
/// pipeline's layout from what its entry point uses).
const SMOOTH: [u32; 8] = [0, 1, 2, 3, 4, 5, 6, 7];
const RESTRICT: [u32; 10] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9];
const PROLONG: [u32; 4] = [0, 5, 7, 8];

/// One level's operator and vectors on the device.
struct DeviceLevel {
    cells: usize,
    b: DeviceField,
    x: DeviceField,
    /// Bind groups of `smooth` per colour, `restrict_residual` and `prolong` (the last
    /// two absent on the coarsest level).
    smooth: [wgpu::BindGroup; 2],
    restrict: Option<wgpu::BindGroup>,
    prolong: Option<wgpu::BindGroup>,
    groups: [u32; 2],
    coarse_groups: [u32; 2],
    /// Workgroups of a smoothing colour (over ⌈nx/2⌉ · ny · nz invocations).
    colour_groups: [u32; 2],
    /// The couplings, extra diagonal and inverse diagonal the bind groups read.
    operator: Vec<DeviceField>,
}

/// A multigrid hierarchy on the device, ready to run cycles.
pub struct DeviceMultigrid<'a> {
    host: &'a Multigrid,
    gpu: &'a GpuContext,
    levels: Vec<DeviceLevel>,
    smooth: Kernel,
    restrict: Kernel,
    prolong: Kernel,
    pre_sweeps: usize,
    post_sweeps: usize,
    kernels: Option<f64>,
    transfer_seconds: Option<f64>,
    outer: Option<Outer>,
    use_outer: bool,
    dense: Option<DenseCoarsest>,
    transfers: Transfers,
    _uniforms: UniformSlots,
}

impl<'a> DeviceMultigrid<'a> {
    /// Uploads `host`'s levels to `gpu`, with the f64 outer iteration's vectors where the
    /// device has f64 and the coarsest level's inverse where it is small enough. Refuses
    /// what the device cycle does not run (W, F and K cycles, Jacobi smoothing, trilinear
    /// prolongation) and a level beyond the adapter's binding limit (the f64 vectors
    /// included), before anything is allocated for it.
    pub fn new(gpu: &'a GpuContext, host: &'a Multigrid) -> Result<Self, GpuError> {
        let settings = host.settings();
        let refuse = |what: &str| {
            Err(GpuError::Device(format!(
                "gpu-diffusion-mg runs V-cycles with red–black Gauss–Seidel and piecewise-constant prolongation: {what} is not supported"
            )))
        };
        if settings.cycle != Cycle::V {
            return refuse(&format!("the {:?} cycle", settings.cycle));
        }
        if !matches!(settings.smoother, Smoother::RedBlackGaussSeidel) {
            return refuse("the Jacobi smoother");
        }
        if settings.prolongation != Prolongation::Constant {
            return refuse("trilinear prolongation");
        }
        let operators = host.levels();
        for op in &operators {
            gpu.check_binding(
                "gpu-diffusion-mg level",
                (op.dims.iter().product::<usize>() * 4) as u64,
            )?;
        }
        if gpu.has_f64() {
            gpu.check_binding(
                "gpu-diffusion-mg f64 solution",
                (operators[0].dims.iter().product::<usize>() * 8) as u64,
            )?;
        }
        let smooth = Kernel::new(
            gpu,
            "multigrid.wgsl",
            lucent_gpu::shaders::MULTIGRID,
            "smooth_colour",
        )?;
        let restrict = Kernel::new(
            gpu,
            "multigrid.wgsl",
            lucent_gpu::shaders::MULTIGRID,
            "restrict_residual",
        )?;
        let prolong = Kernel::new(
            gpu,
            "multigrid.wgsl",
            lucent_gpu::shaders::MULTIGRID,
            "prolong",
        )?;
        // Per level four slots: one per colour (dispatched over the colour's cells), the
        // restriction (over coarse cells) and the prolongation (over cells).
        let mut slots = Vec::new();
        for (l, op) in operators.iter().enumerate() {
            let cells = op.dims.iter().product::<usize>();
            let coarse = operators.get(l + 1).map_or([1; 3], |c| c.dims);
            let coarse_cells = coarse.iter().product::<usize>();
            let groups = groups_2d(gpu, cells as u64, WORKGROUP);
            let coarse_groups = groups_2d(gpu, coarse_cells as u64, WORKGROUP);
            let colour_groups = groups_2d(gpu, colour_cells(op.dims) as u64, WORKGROUP);
            for colour in 0..2u32 {
                slots.push(LevelParams {
                    dims: [
                        op.dims[0] as u32,
                        op.dims[1] as u32,
                        op.dims[2] as u32,
                        colour_groups[0],
                    ],
                    coarse: [coarse[0] as u32, coarse[1] as u32, coarse[2] as u32, colour],
                });
            }
            // The restriction dispatches over coarse cells: its own slot's groups_x.
            slots.push(LevelParams {
                dims: [
                    op.dims[0] as u32,
                    op.dims[1] as u32,
                    op.dims[2] as u32,
                    coarse_groups[0],
                ],
                coarse: [coarse[0] as u32, coarse[1] as u32, coarse[2] as u32, 0],
            });
            slots.push(LevelParams {
                dims: [
                    op.dims[0] as u32,
                    op.dims[1] as u32,
                    op.dims[2] as u32,
                    groups[0],
                ],
                coarse: [coarse[0] as u32, coarse[1] as u32, coarse[2] as u32, 0],
            });
        }
        let uniforms = UniformSlots::new(gpu, "gpu-diffusion-mg levels", &slots)?;
        let mut fields = Vec::new();
        for op in &operators {
            let cells = op.dims.iter().product::<usize>();
            let upload = |what: &str, v: &[f32]| DeviceField::upload(gpu, what, v, false);
            fields.push((
                cells,
                vec![
                    upload("gpu-diffusion-mg x couplings", op.couplings[0])?,
                    upload("gpu-diffusion-mg y couplings", op.couplings[1])?,
                    upload("gpu-diffusion-mg z couplings", op.couplings[2])?,
                    upload("gpu-diffusion-mg extra diagonal", op.extra)?,
                    upload("gpu-diffusion-mg inverse diagonal", op.inv_diag)?,
                ],
                DeviceField::zeros(gpu, "gpu-diffusion-mg b", cells)?,
                DeviceField::zeros(gpu, "gpu-diffusion-mg x", cells)?,
            ));
        }
        let mut binds = Vec::with_capacity(fields.len());
        for (l, (cells, operator, b, x)) in fields.iter().enumerate() {
            let next = fields.get(l + 1);
            let entries = |slot, coarse, used: &[u32]| {
                let mut e = bindings(&uniforms, slot, operator, b, x, coarse);
                e.retain(|(i, _)| used.contains(i));
                e
            };
            let smooth_bind = [
                smooth.bind_at(gpu, &entries(4 * l, None, &SMOOTH))?,
                smooth.bind_at(gpu, &entries(4 * l + 1, None, &SMOOTH))?,
            ];
            let (restrict_bind, prolong_bind) = match next {
                Some((_, _, cb, cx)) => (
                    Some(restrict.bind_at(gpu, &entries(4 * l + 2, Some((cb, cx)), &RESTRICT))?),
                    Some(prolong.bind_at(gpu, &entries(4 * l + 3, Some((cx, cx)), &PROLONG))?),
                ),
                None => (None, None),
            };
            let coarse_cells = next.map_or(1, |n| n.0);
            binds.push((
                smooth_bind,
                restrict_bind,
                prolong_bind,
                [
                    groups_2d(gpu, *cells as u64, WORKGROUP),
                    groups_2d(gpu, coarse_cells as u64, WORKGROUP),
                    groups_2d(gpu, colour_cells(operators[l].dims) as u64, WORKGROUP),
                ],
            ));
        }
        let levels: Vec<DeviceLevel> = fields
            .into_iter()
            .zip(binds)
            .map(
                |(
                    (cells, operator, b, x),
                    (smooth, restrict, prolong, [groups, coarse_groups, colour_groups]),
                )| {
                    DeviceLevel {
                        cells,
                        b,
                        x,
                        smooth,
                        restrict,
                        prolong,
                        groups,
                        coarse_groups,
                        colour_groups,
                        operator,
                    }
                },
            )
            .collect();
        let dense = dense_coarsest(gpu, &operators, &levels)?;
        let levels_fine_cells = levels[0].cells;
        let outer = match gpu.has_f64() {
            true => Some(outer_iteration(gpu, &operators[0], &levels[0])?),
            false => None,
        };
        Ok(Self {
            host,
            gpu,
            levels,
            smooth,
            restrict,
            prolong,
            pre_sweeps: settings.pre_sweeps,
            post_sweeps: settings.post_sweeps,
            kernels: None,
            transfer_seconds: None,
            use_outer: outer.is_some(),
            transfers: Transfers::new(
                gpu,
                (levels_fine_cells * if outer.is_some() { 8 } else { 4 }) as u64,
            )?,
            outer,
            dense,
            _uniforms: uniforms,
        })
    }

    /// Where [`DeviceMultigrid::solve`] runs its outer iteration: on the device where it
    /// has f64, else on the host.
    pub fn outer_iteration(&self) -> OuterIteration {
        match self.use_outer {
            true => OuterIteration::Device,
            false => OuterIteration::Host,
        }
    }

    /// Runs the outer iteration on the host even where the device could (for comparisons
    /// and benchmarks); asking for the device where it has no f64 is refused.
    pub fn set_outer_iteration(&mut self, outer: OuterIteration) -> Result<(), GpuError> {
        match outer {
            OuterIteration::Host => self.use_outer = false,
            OuterIteration::Device if self.outer.is_some() => self.use_outer = true,
            OuterIteration::Device => {
                return Err(GpuError::Device(format!(
                    "gpu-diffusion-mg: {} has no f64 in shaders (SHADER_F64) for the outer iteration",
                    self.gpu.info().name
                )));
            }
        }
        Ok(())
    }

    /// Whether the coarsest level is solved on the device (by its dense inverse) rather
    /// than by the host between two command buffers of a cycle.
    pub fn coarsest_on_device(&self) -> bool {
        self.dense.is_some()
    }

    /// Cells of the finest level.
    pub fn fine_cells(&self) -> usize {
        self.levels[0].cells
    }

    /// Solves A φ = `rhs` to `stopping` with the device's cycles and the same f64 outer
    /// iteration and stopping rule as [`Multigrid::solve_with`]: on the device where it
    /// has f64 ([`DeviceMultigrid::outer_iteration`]), else on the host. When the
    /// hierarchy's settings ask for full multigrid (`diffusion-mg`'s default), φ starts
    /// from the device's [`DeviceMultigrid::full_multigrid`], as the host's solve does;
    /// otherwise from `phi` as given.
    pub fn solve(
        &mut self,
        rhs: &[f64],
        phi: &mut [f64],
        stopping: &Stopping,
    ) -> Result<lucent_diffusion::Convergence, GpuError> {
        let host = self.host;
        self.check_len(rhs.len())?;
        if phi.len() != rhs.len() {
            return Err(GpuError::Device(format!(
                "gpu-diffusion-mg: a solution of {} values for {} cells",
                phi.len(),
                rhs.len()
            )));
        }
        if self.use_outer {
            match self.solve_on_device(rhs, phi, stopping) {
                // A right-hand side or start that is not finite is refused by the upload
                // before anything runs; the host's iteration reports it as it does.
                Err(GpuError::BadInput { .. }) => {}
                solved => return solved,
            }
        }
        let finite = rhs.iter().chain(phi.iter()).all(|v| v.is_finite());
        if host.settings().full_multigrid && finite {
            let start = self.full_multigrid(rhs)?;
            for (p, x) in phi.iter_mut().zip(start) {
                *p = f64::from(x);
            }
        }
        host.solve_with(rhs, phi, stopping, |b| self.cycle_from_zero(b))
    }

    /// [`DeviceMultigrid::solve`] with φ, b and r on the device.
    fn solve_on_device(
        &mut self,
        rhs: &[f64],
        phi: &mut [f64],
        stopping: &Stopping,
    ) -> Result<lucent_diffusion::Convergence, GpuError> {
        let started = Instant::now();
        let gpu = self.gpu;
        let outer = self.outer.as_ref().expect("the device's outer iteration");
        if !self.host.settings().full_multigrid {
            outer.phi.write_staged(gpu, phi, &self.transfers)?;
        }
        outer.rhs.write_staged(gpu, rhs, &self.transfers)?;
        let mut transfers = started.elapsed().as_secs_f64();
        let full_multigrid = self.host.settings().full_multigrid;
        let (b_norm, mut norm, mut kernels) = if full_multigrid && self.dense.is_some() {
            // One command buffer: b and ‖rhs‖, full multigrid, φ from it, its residual.
            let timing = gpu.timed_commands(
                "gpu-diffusion-mg start",
                |encoder| self.record_clear(encoder, 0),
                |pass| {
                    outer.load.0.dispatch(pass, &outer.load.1, outer.groups);
                    outer
                        .sum_second
                        .0
                        .dispatch(pass, &outer.sum_second.1, [1, 1]);
                    self.record_full_multigrid(pass);
                    outer.start.0.dispatch(pass, &outer.start.1, outer.groups);
                    outer
                        .residual
                        .0
                        .dispatch(pass, &outer.residual.1, outer.groups);
                    outer.sum.0.dispatch(pass, &outer.sum.1, [1, 1]);
                },
                |encoder| {
                    outer
                        .readback
                        .record(encoder, outer.norm.buffer(), 0, 0, 16)
                },
            )?;
            let [norm, b_norm] = outer.read_norms(gpu)?;
            (b_norm, norm, timing.seconds)
        } else {
            // b = rhs in f32 (full multigrid's right-hand side) and ‖rhs‖.
            let load = gpu.timed_commands(
                "gpu-diffusion-mg load",
                |_| {},
                |pass| {
                    outer.load.0.dispatch(pass, &outer.load.1, outer.groups);
                    outer.sum.0.dispatch(pass, &outer.sum.1, [1, 1]);
                },
                |encoder| outer.readback.record(encoder, outer.norm.buffer(), 0, 0, 8),
            )?;
            let b_norm = outer.read_norms(gpu)?[0];
            let mut kernels = load.seconds;
            if full_multigrid {
                kernels += self.full_multigrid_in_place(None)?;
                let outer = self.outer.as_ref().expect("the device's outer iteration");
                kernels += gpu
                    .timed_pass("gpu-diffusion-mg start", |pass| {
                        outer.start.0.dispatch(pass, &outer.start.1, outer.groups);
                    })?
                    .seconds;
            }
            let (norm, seconds) = self.outer_residual()?;
            (b_norm, norm, kernels + seconds)
        };
        let b_norm = b_norm.max(f64::MIN_POSITIVE);
        let mut residuals = vec![norm / b_norm];
        let initial = residuals[0];
        let stop = loop {
            let iteration = residuals.len() - 1;
            if let Some(reason) = stopping.verdict(iteration, norm / b_norm, norm, initial, started)
            {
                if !reason.is_converged() {
                    break reason;
                }
                // Confirmed on the true residual, as on the host.
                let (true_norm, seconds) = self.outer_residual()?;
                kernels += seconds;
                norm = true_norm;
                *residuals.last_mut().unwrap_or(&mut 0.0) = norm / b_norm;
                if let Some(reason) = stopping
                    .verdict(iteration, norm / b_norm, norm, initial, started)
                    .filter(|r| r.is_converged())
                {
                    break reason;
                }
            }
            let (next, seconds) = self.outer_cycle()?;
            kernels += seconds;
            norm = next;
            residuals.push(norm / b_norm);
        };
        self.kernels = Some(kernels).filter(|k| k.is_finite());
        let outer = self.outer.as_ref().expect("the device's outer iteration");
        let downloading = Instant::now();
        outer.phi.download_into(gpu, phi, &self.transfers)?;
        transfers += downloading.elapsed().as_secs_f64();
        self.transfer_seconds = Some(transfers);
        Ok(lucent_diffusion::Convergence {
            residuals,
            stop_reason: stop,
        })
    }

    /// r = b − A φ on the device: returns ‖r‖₂ and the kernels' seconds.
    fn outer_residual(&mut self) -> Result<(f64, f64), GpuError> {
        let gpu = self.gpu;
        let outer = self.outer.as_ref().expect("the device's outer iteration");
        let timing = gpu.timed_commands(
            "gpu-diffusion-mg residual",
            |_| {},
            |pass| {
                outer
                    .residual
                    .0
                    .dispatch(pass, &outer.residual.1, outer.groups);
                outer.sum.0.dispatch(pass, &outer.sum.1, [1, 1]);
            },
            |encoder| outer.readback.record(encoder, outer.norm.buffer(), 0, 0, 8),
        )?;
        Ok((outer.read_norm(gpu)?, timing.seconds))
    }

    /// One cycle from zero for the residual in b, then φ += e and r −= A e on the device:
    /// returns the new ‖r‖₂ and the kernels' seconds.
    fn outer_cycle(&mut self) -> Result<(f64, f64), GpuError> {
        let gpu = self.gpu;
        let outer = self.outer.as_ref().expect("the device's outer iteration");
        let seconds = self.cycle_then(
            0,
            |pass| {
                outer
                    .correct
                    .0
                    .dispatch(pass, &outer.correct.1, outer.groups);
                outer.sum.0.dispatch(pass, &outer.sum.1, [1, 1]);
            },
            |encoder| outer.readback.record(encoder, outer.norm.buffer(), 0, 0, 8),
        )?;
        Ok((outer.read_norm(gpu)?, seconds))
    }

    /// Full multigrid on the device, the host's nested iteration: `rhs` (in f32) summed
    /// down every level, the coarsest solved, then on each finer level the prolonged
    /// coarse solution improved by one V-cycle from that level. Returns the finest
    /// level's solution.
    pub fn full_multigrid(&mut self, rhs: &[f64]) -> Result<Vec<f32>, GpuError> {
        self.check_len(rhs.len())?;
        let kernels = self.full_multigrid_in_place(Some(rhs))?;
        self.kernels = Some(kernels).filter(|k| k.is_finite());
        let mut x = vec![0.0; self.fine_cells()];
        self.levels[0]
            .x
            .download_into(self.gpu, &mut x, &self.transfers)?;
        Ok(x)
    }

    /// [`DeviceMultigrid::full_multigrid`] for `rhs` (or for the finest level's b as it
    /// stands), its result left in the finest level's x; returns the kernels' seconds
    /// (NaN without timestamps).
    fn full_multigrid_in_place(&mut self, rhs: Option<&[f64]>) -> Result<f64, GpuError> {
        let gpu = self.gpu;
        if let Some(rhs) = rhs {
            let b: Vec<f32> = rhs.iter().map(|&v| v as f32).collect();
            self.levels[0]
                .b
                .write_staged(gpu, &b, false, &self.transfers)?;
        }
        let last = self.levels.len() - 1;
        // With every x zero the restricted residual is the sum of the children's b.
        let down = gpu.timed_commands(
            "gpu-diffusion-mg restrict",
            |encoder| self.record_clear(encoder, 0),
            |pass| {
                for level in &self.levels[..last] {
                    let restrict = level.restrict.as_ref().expect("a level above the coarsest");
                    self.restrict.dispatch(pass, restrict, level.coarse_groups);
                }
                self.record_dense_coarsest(pass);
            },
            |_| {},
        )?;
        if self.dense.is_none() {
            self.solve_coarsest_level()?;
        }
        let mut kernels = if down.source == TimingSource::Timestamps {
            down.seconds
        } else {
            f64::NAN
        };
        for top in (0..last).rev() {
            let level = &self.levels[top];
            let prolong = level.prolong.as_ref().expect("a level above the coarsest");
            // The coarse solution prolonged, then a cycle from it (in one command buffer
            // where the coarsest level is solved on the device).
            match self.dense {
                Some(_) => {
                    kernels += self.cycle_before(top, |pass| {
                        self.prolong.dispatch(pass, prolong, level.groups);
                    })?;
                }
                None => {
                    kernels += gpu
                        .timed_pass("gpu-diffusion-mg prolong", |pass| {
                            self.prolong.dispatch(pass, prolong, level.groups);
                        })?
                        .seconds;
                    kernels += self.cycle(top)?;
                }
            }
        }
        Ok(kernels)
    }

    fn check_len(&self, len: usize) -> Result<(), GpuError> {
        if len != self.fine_cells() {
            return Err(GpuError::Device(format!(
                "gpu-diffusion-mg: a right-hand side of {len} values for {} cells",
                self.fine_cells()
            )));
        }
        Ok(())
    }

    /// Records x = 0 on level `level` (the levels below are zeroed by the restriction
    /// into them).
    fn record_clear(&self, encoder: &mut wgpu::CommandEncoder, level: usize) {
        encoder.clear_buffer(self.levels[level].x.buffer(), 0, None);
    }

    /// Records the coarsest level's dense solve, where there is one.
    fn record_dense_coarsest(&self, pass: &mut wgpu::ComputePass<'_>) {
        if let Some(dense) = &self.dense {
            dense.kernel.dispatch(pass, &dense.bind, dense.groups);
        }
    }

    /// The coarsest level's solve by the host between two command buffers: its b down,
    /// the host's solve, x up.
    fn solve_coarsest_level(&self) -> Result<(), GpuError> {
        let gpu = self.gpu;
        let last = self.levels.len() - 1;
        let coarse_b = self.levels[last].b.download(gpu)?;
        let coarse_x = self.host.solve_coarsest(&coarse_b);
        self.levels[last].x.write(gpu, &coarse_x, false)
    }

    /// One V-cycle from x = 0 for A x = `b` on the finest level: the device's
    /// [`Multigrid::cycle_from_zero`].
    pub fn cycle_from_zero(&mut self, b: &[f32]) -> Result<Vec<f32>, GpuError> {
        let gpu = self.gpu;
        self.check_len(b.len())?;
        self.levels[0]
            .b
            .write_staged(gpu, b, false, &self.transfers)?;
        let kernels = self.cycle_then(0, |_| {}, |_| {})?;
        self.kernels = Some(kernels).filter(|k| k.is_finite());
        let mut x = vec![0.0; self.fine_cells()];
        self.levels[0]
            .x
            .download_into(gpu, &mut x, &self.transfers)?;
        Ok(x)
    }

    /// One V-cycle on level `top` for its b, from its x as it stands (the levels below
    /// start from zero). Returns the kernels' seconds by timestamps (NaN without them).
    fn cycle(&mut self, top: usize) -> Result<f64, GpuError> {
        self.cycle_before(top, |_| {})
    }

    /// [`DeviceMultigrid::cycle`] with `before` recorded ahead of it in the same pass.
    fn cycle_before(
        &self,
        top: usize,
        before: impl FnOnce(&mut wgpu::ComputePass<'_>),
    ) -> Result<f64, GpuError> {
        self.run_cycle(top, false, before, |_| {}, |_| {})
    }

    /// One V-cycle from zero on level `top` (x cleared from `top` down), then `then`
    /// recorded into the cycle's last pass and `after` into its command buffer.
    fn cycle_then(
        &self,
        top: usize,
        then: impl FnOnce(&mut wgpu::ComputePass<'_>),
        after: impl FnOnce(&mut wgpu::CommandEncoder),
    ) -> Result<f64, GpuError> {
        self.run_cycle(top, true, |_| {}, then, after)
    }

    /// A V-cycle on level `top` (from x = 0 there where `from_zero`; the levels below start
    /// from zero, set by the restriction into them): `before` recorded first, then pre-smoothing (red first) and the restricted residual level
    /// by level, the coarsest solve, prolongation and post-smoothing (black first, as the
    /// host's), then `then`; `after` into the command buffer. One command buffer where the
    /// coarsest level is solved on the device, two around the host's solve otherwise.
    /// Returns the kernels' seconds by timestamps (NaN without them).
    fn run_cycle(
        &self,
        top: usize,
        from_zero: bool,
        before: impl FnOnce(&mut wgpu::ComputePass<'_>),
        then: impl FnOnce(&mut wgpu::ComputePass<'_>),
        after: impl FnOnce(&mut wgpu::CommandEncoder),
    ) -> Result<f64, GpuError> {
        let gpu = self.gpu;
        let last = self.levels.len() - 1;
        let seconds = |t: lucent_gpu::Timing| match t.source {
            TimingSource::Timestamps => t.seconds,
            TimingSource::WallClock => f64::NAN,
        };
        let clear = |encoder: &mut wgpu::CommandEncoder| {
            if from_zero {
                self.record_clear(encoder, top);
            }
        };
        if top == last {
            if self.dense.is_some() {
                let timing = gpu.timed_commands(
                    "gpu-diffusion-mg coarsest",
                    clear,
                    |pass| {
                        before(pass);
                        self.record_dense_coarsest(pass);
                        then(pass);
                    },
                    after,
                )?;
                return Ok(seconds(timing));
            }
            let first = gpu.timed_commands("gpu-diffusion-mg coarsest", clear, before, |_| {})?;
            self.solve_coarsest_level()?;
            let second = gpu.timed_commands("gpu-diffusion-mg coarsest", |_| {}, then, after)?;
            return Ok(seconds(first) + seconds(second));
        }
        let down = |pass: &mut wgpu::ComputePass<'_>| {
            before(pass);
            self.record_down(pass, top);
        };
        let up = |pass: &mut wgpu::ComputePass<'_>| {
            self.record_up(pass, top);
            then(pass);
        };
        if self.dense.is_some() {
            let timing = gpu.timed_commands(
                "gpu-diffusion-mg cycle",
                clear,
                |pass| {
                    down(pass);
                    self.record_dense_coarsest(pass);
                    up(pass);
                },
                after,
            )?;
            return Ok(seconds(timing));
        }
        let timing_down = gpu.timed_commands("gpu-diffusion-mg down", clear, down, |_| {})?;
        self.solve_coarsest_level()?;
        let timing_up = gpu.timed_commands("gpu-diffusion-mg up", |_| {}, up, after)?;
        Ok(seconds(timing_down) + seconds(timing_up))
    }

    /// Records a cycle's way down from level `top`: pre-smoothing (red first) and the
    /// restricted residual, level by level to the coarsest.
    fn record_down(&self, pass: &mut wgpu::ComputePass<'_>, top: usize) {
        let last = self.levels.len() - 1;
        for level in &self.levels[top..last] {
            for _ in 0..self.pre_sweeps {
                for colour in [0, 1] {
                    self.smooth
                        .dispatch(pass, &level.smooth[colour], level.colour_groups);
                }
            }
            let restrict = level.restrict.as_ref().expect("a level above the coarsest");
            self.restrict.dispatch(pass, restrict, level.coarse_groups);
        }
    }

    /// Records a cycle's way up to level `top`: prolongation and post-smoothing (black
    /// first, as the host's), level by level from the coarsest.
    fn record_up(&self, pass: &mut wgpu::ComputePass<'_>, top: usize) {
        let last = self.levels.len() - 1;
        for level in self.levels[top..last].iter().rev() {
            let prolong = level.prolong.as_ref().expect("a level above the coarsest");
            self.prolong.dispatch(pass, prolong, level.groups);
            for _ in 0..self.post_sweeps {
                for colour in [1, 0] {
                    self.smooth
                        .dispatch(pass, &level.smooth[colour], level.colour_groups);
                }
            }
        }
    }

    /// Records the whole of full multigrid for the finest level's b into one pass (the
    /// finest x must be zero): the coarsest level must be solved on the device.
    fn record_full_multigrid(&self, pass: &mut wgpu::ComputePass<'_>) {
        let last = self.levels.len() - 1;
        for level in &self.levels[..last] {
            let restrict = level.restrict.as_ref().expect("a level above the coarsest");
            self.restrict.dispatch(pass, restrict, level.coarse_groups);
        }
        self.record_dense_coarsest(pass);
        for top in (0..last).rev() {
            let level = &self.levels[top];
            let prolong = level.prolong.as_ref().expect("a level above the coarsest");
            self.prolong.dispatch(pass, prolong, level.groups);
            self.record_down(pass, top);
            self.record_dense_coarsest(pass);
            self.record_up(pass, top);
        }
    }

    /// Each kernel of a cycle and of the outer iteration on the finest level, for
    /// benchmarks: dispatched `repeats` times in one timed pass (same colour, same
    /// vectors), by the device's timestamps. Leaves the vectors meaningless (a solve sets
    /// them again); `None` without timestamps.
    pub fn time_fine_kernels(
        &mut self,
        repeats: u32,
    ) -> Result<Option<Vec<KernelTiming>>, GpuError> {
        let gpu = self.gpu;
        if !gpu.has_timestamps() || self.levels.len() < 2 {
            return Ok(None);
        }
        let cells = self.levels[0].cells as f64;
        let fine = &self.levels[0];
        let restrict = fine.restrict.as_ref().expect("a level above the coarsest");
        let prolong = fine.prolong.as_ref().expect("a level above the coarsest");
        // Compulsory bytes per cell (every value crossing once, f32 = 4 bytes): a colour
        // reads all three couplings (its cells' low faces and their neighbours' high
        // ones) and every x, and its own cells' extra and inverse diagonals and b, writing
        // half the x: 12 + 4 + 3 · 2 + 2 = 24. The restriction reads the operator, b and x
        // (28) and writes two coarse values per eight cells (1); the prolongation reads
        // the inverse diagonal and x, writes x and reads an eighth of a coarse value
        // (12.5). The outer residual reads the operator's four arrays, b and φ in f64 and
        // writes r in f64 and b in f32 (44); the correction reads the four arrays and e,
        // reads and writes φ and r, and writes b (56).
        let mut kernels: Vec<(&'static str, f64, Recorder<'_>)> = vec![
            (
                "smoothing colour",
                24.0,
                Box::new(|pass| {
                    self.smooth
                        .dispatch(pass, &fine.smooth[0], fine.colour_groups)
                }),
            ),
            (
                "residual + restriction",
                29.0,
                Box::new(|pass| self.restrict.dispatch(pass, restrict, fine.coarse_groups)),
            ),
            (
                "prolongation",
                12.5,
                Box::new(|pass| self.prolong.dispatch(pass, prolong, fine.groups)),
            ),
        ];
        if let Some(outer) = &self.outer {
            kernels.push((
                "outer residual (f64)",
                44.0,
                Box::new(|pass| {
                    outer
                        .residual
                        .0
                        .dispatch(pass, &outer.residual.1, outer.groups)
                }),
            ));
            kernels.push((
                "outer correction (f64)",
                56.0,
                Box::new(|pass| {
                    outer
                        .correct
                        .0
                        .dispatch(pass, &outer.correct.1, outer.groups)
                }),
            ));
        }
        let mut timings = Vec::new();
        for (name, bytes, record) in kernels {
            let started = Instant::now();
            let timing = gpu.timed_pass(name, |pass| {
                for _ in 0..repeats.max(1) {
                    record(pass);
                }
            })?;
            timings.push(KernelTiming {
                name,
                seconds: timing.seconds / f64::from(repeats.max(1)),
                wall_seconds: started.elapsed().as_secs_f64() / f64::from(repeats.max(1)),
                bytes: bytes * cells,
            });
        }
        Ok(Some(timings))
    }

    /// Wall seconds the last solve with the outer iteration on the device spent moving
    /// the right-hand side up and the solution down (the start too, without full
    /// multigrid).
    pub fn last_transfer_seconds(&self) -> Option<f64> {
        self.transfer_seconds
    }

    /// The last cycle's kernels alone by the device's timestamps (both passes; without the
    /// transfers and the host's coarsest solve), where the adapter has timestamps.
    pub fn last_kernel_seconds(&self) -> Option<f64> {
        self.kernels
    }
}

impl Outer {
    /// ‖r‖₂ from the readback the last command buffer filled.
    fn read_norm(&self, gpu: &GpuContext) -> Result<f64, GpuError> {
        Ok(self.read_norms(gpu)?[0])
    }

    /// The square roots of both sums in the readback (the second as of the last command
    /// buffer that copied it).
    fn read_norms(&self, gpu: &GpuContext) -> Result<[f64; 2], GpuError> {
        let bytes = self.readback.read(gpu)?;
        let squares: Vec<f64> = bytemuck::pod_collect_to_vec(&bytes);
        Ok([squares[0].sqrt(), squares[1].sqrt()])
    }
}

/// The device's f64 outer iteration on the finest level (`shaders/multigrid_f64.wgsl`).
fn outer_iteration(
    gpu: &GpuContext,
    op: &LevelOperator<'_>,
    fine: &DeviceLevel,
) -> Result<Outer, GpuError> {
    let cells = fine.cells;
    let groups = groups_2d(gpu, cells as u64, WORKGROUP);
    let partials = groups[0] as usize * groups[1] as usize;
    // Slot 0 for every kernel (sums into the norm's first value), slot 1 for the sum
    // into its second.
    let dims = [
        op.dims[0] as u32,
        op.dims[1] as u32,
        op.dims[2] as u32,
        groups[0],
    ];
    let uniforms = UniformSlots::new(
        gpu,
        "gpu-diffusion-mg outer",
        &[0, 1].map(|to| OuterParams {
            dims,
            count: [partials as u32, to, 0, 0],
        }),
    )?;
    let rhs = DeviceField64::zeros(gpu, "gpu-diffusion-mg f64 right-hand side", cells)?;
    let phi = DeviceField64::zeros(gpu, "gpu-diffusion-mg f64 solution", cells)?;
    let r = DeviceField64::zeros(gpu, "gpu-diffusion-mg f64 residual", cells)?;
    let sums = DeviceField64::zeros(gpu, "gpu-diffusion-mg residual partials", partials)?;
    let norm = DeviceField64::zeros(gpu, "gpu-diffusion-mg residual norms", 2)?;
    let all = || {
        let mut e = vec![(0u32, uniforms.slot(0))];
        for (i, f) in fine.operator[..4].iter().enumerate() {
            e.push((i as u32 + 1, f.binding()));
        }
        e.extend([
            (5, rhs.binding()),
            (6, phi.binding()),
            (7, r.binding()),
            (8, fine.x.binding()),
            (9, fine.b.binding()),
            (10, sums.binding()),
            (11, norm.binding()),
        ]);
        e
    };
    let bound = |entry: &str, used: &[u32]| -> Result<_, GpuError> {
        let k = gpu.kernel(
            "multigrid_f64.wgsl",
            lucent_gpu::shaders::MULTIGRID_F64,
            entry,
        )?;
        let mut e = all();
        e.retain(|(i, _)| used.contains(i));
        let bind = k.bind_at(gpu, &e)?;
        Ok((k, bind))
    };
    Ok(Outer {
        residual: bound("outer_residual", &OUTER_RESIDUAL)?,
        correct: bound("outer_correct", &OUTER_CORRECT)?,
        start: bound("outer_start", &OUTER_START)?,
        load: bound("outer_load", &OUTER_LOAD)?,
        sum: bound("outer_sum", &OUTER_SUM)?,
        sum_second: {
            let k = gpu.kernel(
                "multigrid_f64.wgsl",
                lucent_gpu::shaders::MULTIGRID_F64,
                "outer_sum",
            )?;
            let bind = k.bind_at(
                gpu,
                &[
                    (0, uniforms.slot(1)),
                    (10, sums.binding()),
                    (11, norm.binding()),
                ],
            )?;
            (k, bind)
        },
        groups,
        readback: Readback::new(gpu, "gpu-diffusion-mg residual norm", 16)?,
        rhs,
        phi,
        norm,
        _vectors: [r, sums],
        _uniforms: uniforms,
    })
}

/// The coarsest level's solve on the device by its dense inverse, where it has at most
/// [`DENSE_COARSEST_MAX`] unknowns and is positive definite (else `None`: the host
/// solves it).
fn dense_coarsest(
    gpu: &GpuContext,
    operators: &[LevelOperator<'_>],
    levels: &[DeviceLevel],
) -> Result<Option<DenseCoarsest>, GpuError> {
    let (Some(op), Some(level)) = (operators.last(), levels.last()) else {
        return Ok(None);
    };
    let Some((unknowns, inverse)) = coarsest_inverse(op) else {
        return Ok(None);
    };
    if !gpu.has_f64() {
        return Ok(None);
    }
    let m = unknowns.len();
    let groups = groups_2d(gpu, m as u64, WORKGROUP);
    let uniforms = UniformSlots::new(
        gpu,
        "gpu-diffusion-mg coarsest",
        &[OuterParams {
            dims: [
                op.dims[0] as u32,
                op.dims[1] as u32,
                op.dims[2] as u32,
                groups[0],
            ],
            count: [m as u32, 0, 0, 0],
        }],
    )?;
    let inverse = DeviceField64::upload(gpu, "gpu-diffusion-mg coarsest inverse", &inverse)?;
    let unknowns = DeviceIndices::upload(gpu, "gpu-diffusion-mg coarsest unknowns", &unknowns)?;
    let kernel = gpu.kernel(
        "multigrid_f64.wgsl",
        lucent_gpu::shaders::MULTIGRID_F64,
        "coarsest_dense",
    )?;
    let entries = [
        (0u32, uniforms.slot(0)),
        (12, inverse.binding()),
        (13, unknowns.binding()),
        (14, level.b.binding()),
        (15, level.x.binding()),
    ];
    debug_assert!(entries.iter().map(|e| e.0).eq(COARSEST_DENSE));
    let bind = kernel.bind_at(gpu, &entries)?;
    Ok(Some(DenseCoarsest {
        kernel,
        bind,
        groups,
        _inverse: inverse,
        _unknowns: unknowns,
        _uniforms: uniforms,
    }))
}

/// The unknowns (cells in the medium, d ≠ 0) of a level and the inverse of its operator
/// on them (row-major, f64), by Cholesky; `None` when there are none, more than
/// [`DENSE_COARSEST_MAX`], or the operator is not positive definite. Cells outside the
/// medium keep x = 0 in the host's coarsest solve too, so leaving them out is exact.
fn coarsest_inverse(op: &LevelOperator<'_>) -> Option<(Vec<u32>, Vec<f64>)> {
    let [nx, ny, nz] = op.dims;
    let n = nx * ny * nz;
    let unknowns: Vec<usize> = (0..n).filter(|&g| op.inv_diag[g] != 0.0).collect();
    let m = unknowns.len();
    if m == 0 || m > DENSE_COARSEST_MAX {
        return None;
    }
    let mut index = vec![usize::MAX; n];
    for (u, &g) in unknowns.iter().enumerate() {
        index[g] = u;
    }
    let [cx, cy, cz] = op.couplings;
    let mut a = vec![0.0f64; m * m];
    for (u, &g) in unknowns.iter().enumerate() {
        let (i, j, k) = (g % nx, (g / nx) % ny, g / (nx * ny));
        let mut diagonal = f64::from(op.extra[g]);
        // Each face: its coupling on the diagonal, and minus it off the diagonal where
        // the cell beyond is an unknown (a face on the box has no cell beyond).
        let mut face = |coupling: f32, beyond: Option<usize>| {
            diagonal += f64::from(coupling);
            if let Some(v) = beyond.map(|b| index[b]).filter(|&v| v != usize::MAX) {
                a[u * m + v] -= f64::from(coupling);
            }
        };
        face(cx[g], (i > 0).then(|| g - 1));
        face(cy[g], (j > 0).then(|| g - nx));
        face(cz[g], (k > 0).then(|| g - nx * ny));
        if i + 1 < nx {
            face(cx[g + 1], Some(g + 1));
        }
        if j + 1 < ny {
            face(cy[g + nx], Some(g + nx));
        }
        if k + 1 < nz {
            face(cz[g + nx * ny], Some(g + nx * ny));
        }
        a[u * m + u] += diagonal;
    }
    // A = L Lᵀ, L in the lower triangle of `a`.
    for c in 0..m {
        let mut d = a[c * m + c];
        for p in 0..c {
            d -= a[c * m + p] * a[c * m + p];
        }
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        let d = d.sqrt();
        a[c * m + c] = d;
        for r in c + 1..m {
            let mut v = a[r * m + c];
            for p in 0..c {
                v -= a[r * m + p] * a[c * m + p];
            }
            a[r * m + c] = v / d;
        }
    }
    // Column c of A⁻¹ by L y = e_c, Lᵀ x = y.
    let mut inverse = vec![0.0f64; m * m];
    let mut y = vec![0.0f64; m];
    for c in 0..m {
        for r in 0..m {
            let mut v = if r == c { 1.0 } else { 0.0 };
            for p in 0..r {
                v -= a[r * m + p] * y[p];
            }
            y[r] = v / a[r * m + r];
        }
        for r in (0..m).rev() {
            let mut v = y[r];
            for p in r + 1..m {
                v -= a[p * m + r] * inverse[p * m + c];
            }
            inverse[r * m + c] = v / a[r * m + r];
        }
    }
    Some((unknowns.iter().map(|&g| g as u32).collect(), inverse))
}

/// Invocations of a smoothing colour on a level of `dims`: ⌈nx/2⌉ per row.
fn colour_cells(dims: [usize; 3]) -> usize {
    dims[0].div_ceil(2) * dims[1] * dims[2]
}

/// The bindings of `shaders/multigrid.wgsl` for one level: uniform slot `slot`, the
/// operator, b, x and (for the transfers) two of the coarse level's vectors: the one
/// written or read (8; b for the restriction, x for the prolongation) and its x (9).
fn bindings<'f>(
    uniforms: &'f UniformSlots,
    slot: usize,
    operator: &'f [DeviceField],
    b: &'f DeviceField,
    x: &'f DeviceField,
    coarse: Option<(&'f DeviceField, &'f DeviceField)>,
) -> Vec<(u32, wgpu::BindingResource<'f>)> {
    let mut e = vec![(0u32, uniforms.slot(slot))];
    for (i, f) in operator.iter().enumerate() {
        e.push((i as u32 + 1, f.binding()));
    }
    e.push((6, b.binding()));
    e.push((7, x.binding()));
    if let Some((vector, x)) = coarse {
        e.push((8, vector.binding()));
        e.push((9, x.binding()));
    }
    e
}

/// Host bytes of `gpu-diffusion-mg` per solve, an upper bound: `diffusion-mg`'s own (the
/// hierarchy the device's is uploaded from, the f64 vectors, the cut-cell geometry: 112
/// bytes per cell and channel) and the f32 right-hand side and correction each cycle hands
/// over when the outer iteration runs on the host (8).
pub(crate) fn memory_bytes(problem: &Problem) -> u64 {
    problem.geometry().voxel_count() as u64 * (112 + 8) * problem.channels() as u64
}

/// One channel's steady diffusion by device cycles: the host builds the hierarchy as
/// `diffusion-mg` does, [`DeviceMultigrid`] uploads it and runs full multigrid (when the
/// settings ask) and the cycles, the host's outer iteration stops at `stop`.
pub(crate) fn steady(
    gpu: &GpuContext,
    problem: &DiffusionProblem,
    sources: &Sources,
    stop: &Stopping,
    settings: MultigridSettings,
) -> Result<DiffusionSolution, DiffusionError> {
    let device_error = |e: GpuError| DiffusionError::Invalid(format!("GPU: {e}"));
    let started = Instant::now();
    let rhs = problem.rhs(sources)?;
    let host = Multigrid::build(problem, settings)?;
    let mut device = DeviceMultigrid::new(gpu, &host).map_err(device_error)?;
    let setup_seconds = started.elapsed().as_secs_f64();
    let solving = Instant::now();
    let mut fluence = vec![0.0; rhs.len()];
    let convergence = device
        .solve(&rhs, &mut fluence, stop)
        .map_err(device_error)?;
    let solve_seconds = solving.elapsed().as_secs_f64();
    Ok(DiffusionSolution {
        balance: problem.balance(sources, &fluence),
        convergence,
        setup_seconds,
        solve_seconds,
        levels: host.depth(),
        memory_bytes: host.memory_bytes() + fluence.len() as u64 * 32,
        fluence,
    })
}
