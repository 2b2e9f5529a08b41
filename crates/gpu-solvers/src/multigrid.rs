//! The cycle of `diffusion-mg` on the device: lucent-diffusion's level hierarchy (the
//! operators it builds, cut cells folded into the couplings and the extra diagonal)
//! uploaded once, and one V-cycle from zero for A x = b per call, with the same smoother,
//! sweeps, transfers and coarsest solve as the host's cycle
//! ([`lucent_diffusion::Multigrid::cycle_from_zero`]), in f32 (`shaders/multigrid.wgsl`).
//!
//! Per cycle: one command buffer down (pre-smoothing colours, then the fused residual and
//! restriction, level by level), the coarsest level's right-hand side read back and solved
//! on the host by the host's own coarsest solve (a few hundred cells: CG in f64), one
//! command buffer up (prolongation, post-smoothing); each pass timed by the device's
//! timestamps where it has them ([`DeviceMultigrid::last_kernel_seconds`]). The host's f64 outer iteration
//! (residual, correction, stopping rule) stays where it is: a device cycle is a
//! preconditioner application, so 1e-8 is reached by the same iterative refinement as on
//! the host.
//!
//! What the host's cycle offers and this one does not is refused, not approximated: W and
//! F cycles, the Jacobi smoother and trilinear prolongation.

use std::time::Instant;

use lucent_core::{Problem, Stopping};
use lucent_diffusion::{
    Cycle, DiffusionError, DiffusionProblem, DiffusionSolution, Multigrid, MultigridSettings,
    Prolongation, Smoother, Sources,
};
use lucent_gpu::{
    DeviceField, GpuContext, GpuError, Kernel, TimingSource, UniformSlots, WORKGROUP, groups_2d,
};

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
const RESTRICT: [u32; 9] = [0, 1, 2, 3, 4, 5, 6, 7, 8];
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
    /// The couplings, extra diagonal and inverse diagonal the bind groups read.
    _operator: Vec<DeviceField>,
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
    _uniforms: UniformSlots,
}

impl<'a> DeviceMultigrid<'a> {
    /// Uploads `host`'s levels to `gpu`. Refuses what the device cycle does not run (W
    /// and F cycles, Jacobi smoothing, trilinear prolongation) and a level beyond the
    /// adapter's binding limit, before anything is allocated for it.
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
        // Per level two slots, one per colour; the transfers read the first.
        let mut slots = Vec::new();
        for (l, op) in operators.iter().enumerate() {
            let cells = op.dims.iter().product::<usize>();
            let coarse = operators.get(l + 1).map_or([1; 3], |c| c.dims);
            let coarse_cells = coarse.iter().product::<usize>();
            let groups = groups_2d(gpu, cells as u64, WORKGROUP);
            let coarse_groups = groups_2d(gpu, coarse_cells as u64, WORKGROUP);
            for colour in 0..2u32 {
                slots.push(LevelParams {
                    dims: [
                        op.dims[0] as u32,
                        op.dims[1] as u32,
                        op.dims[2] as u32,
                        groups[0],
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
                smooth.bind_at(gpu, &entries(3 * l, None, &SMOOTH))?,
                smooth.bind_at(gpu, &entries(3 * l + 1, None, &SMOOTH))?,
            ];
            let (restrict_bind, prolong_bind) = match next {
                Some((_, _, cb, cx)) => (
                    Some(restrict.bind_at(gpu, &entries(3 * l + 2, Some(cb), &RESTRICT))?),
                    Some(prolong.bind_at(gpu, &entries(3 * l, Some(cx), &PROLONG))?),
                ),
                None => (None, None),
            };
            let coarse_cells = next.map_or(1, |n| n.0);
            binds.push((
                smooth_bind,
                restrict_bind,
                prolong_bind,
                groups_2d(gpu, *cells as u64, WORKGROUP),
                groups_2d(gpu, coarse_cells as u64, WORKGROUP),
            ));
        }
        let levels = fields
            .into_iter()
            .zip(binds)
            .map(
                |((cells, operator, b, x), (smooth, restrict, prolong, groups, coarse_groups))| {
                    DeviceLevel {
                        cells,
                        b,
                        x,
                        smooth,
                        restrict,
                        prolong,
                        groups,
                        coarse_groups,
                        _operator: operator,
                    }
                },
            )
            .collect();
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
            _uniforms: uniforms,
        })
    }

    /// Cells of the finest level.
    pub fn fine_cells(&self) -> usize {
        self.levels[0].cells
    }

    /// Solves A φ = `rhs` to `stopping` with the device's cycles: the host's outer
    /// iteration ([`Multigrid::solve_with`]: f64 solution and residual, the stopping rule).
    /// When the hierarchy's settings ask for full multigrid (`diffusion-mg`'s default), φ
    /// starts from the device's [`DeviceMultigrid::full_multigrid`], as the host's solve
    /// does; otherwise from `phi` as given.
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
        if host.settings().full_multigrid {
            let start = self.full_multigrid(rhs)?;
            for (p, x) in phi.iter_mut().zip(start) {
                *p = f64::from(x);
            }
        }
        host.solve_with(rhs, phi, stopping, |b| self.cycle_from_zero(b))
    }

    /// Full multigrid on the device, the host's nested iteration: `rhs` (in f32) summed
    /// down every level, the coarsest solved (on the host, as in a cycle), then on each
    /// finer level the prolonged coarse solution improved by one V-cycle from that level.
    /// Returns the finest level's solution.
    pub fn full_multigrid(&mut self, rhs: &[f64]) -> Result<Vec<f32>, GpuError> {
        let gpu = self.gpu;
        self.check_len(rhs.len())?;
        let b: Vec<f32> = rhs.iter().map(|&v| v as f32).collect();
        self.levels[0].b.write(gpu, &b, false)?;
        let last = self.levels.len() - 1;
        self.clear_x(0)?;
        // With every x zero the restricted residual is the sum of the children's b.
        let down = gpu.timed_pass("gpu-diffusion-mg restrict", |pass| {
            for level in &self.levels[..last] {
                let restrict = level.restrict.as_ref().expect("a level above the coarsest");
                self.restrict.dispatch(pass, restrict, level.coarse_groups);
            }
        })?;
        self.solve_coarsest_level()?;
        let mut kernels = down.seconds;
        let timed = down.source == TimingSource::Timestamps;
        for top in (0..last).rev() {
            let level = &self.levels[top];
            let prolong = level.prolong.as_ref().expect("a level above the coarsest");
            let up = gpu.timed_pass("gpu-diffusion-mg prolong", |pass| {
                self.prolong.dispatch(pass, prolong, level.groups);
            })?;
            kernels += up.seconds + self.cycle(top)?;
        }
        self.kernels = timed.then_some(kernels);
        self.levels[0].x.download(gpu)
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

    /// Sets x to zero on the levels from `from` down.
    fn clear_x(&self, from: usize) -> Result<(), GpuError> {
        let gpu = self.gpu;
        gpu.checked(|| {
            let mut encoder =
                gpu.device()
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                        label: Some("gpu-diffusion-mg clear"),
                    });
            for level in &self.levels[from..] {
                encoder.clear_buffer(level.x.buffer(), 0, None);
            }
            gpu.queue().submit([encoder.finish()]);
        })
    }

    /// The coarsest level's solve inside a cycle: its b down, the host's solve, x up.
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
        self.levels[0].b.write(gpu, b, false)?;
        self.clear_x(0)?;
        let kernels = self.cycle(0)?;
        self.kernels = Some(kernels).filter(|k| k.is_finite());
        self.levels[0].x.download(gpu)
    }

    /// One V-cycle on level `top` for its b, from its x as it stands (the levels below
    /// start from zero). Returns the kernels' seconds by timestamps (NaN without them).
    fn cycle(&mut self, top: usize) -> Result<f64, GpuError> {
        let gpu = self.gpu;
        let last = self.levels.len() - 1;
        if top == last {
            self.solve_coarsest_level()?;
            return Ok(0.0);
        }
        self.clear_x(top + 1)?;
        // Down: pre-smoothing (red first), residual restricted.
        let down = gpu.timed_pass("gpu-diffusion-mg down", |pass| {
            for level in &self.levels[top..last] {
                for _ in 0..self.pre_sweeps {
                    for colour in [0, 1] {
                        self.smooth
                            .dispatch(pass, &level.smooth[colour], level.groups);
                    }
                }
                let restrict = level.restrict.as_ref().expect("a level above the coarsest");
                self.restrict.dispatch(pass, restrict, level.coarse_groups);
            }
        })?;
        self.solve_coarsest_level()?;
        // Up: prolongation, post-smoothing (black first, as the host's).
        let up = gpu.timed_pass("gpu-diffusion-mg up", |pass| {
            for level in self.levels[top..last].iter().rev() {
                let prolong = level.prolong.as_ref().expect("a level above the coarsest");
                self.prolong.dispatch(pass, prolong, level.groups);
                for _ in 0..self.post_sweeps {
                    for colour in [1, 0] {
                        self.smooth
                            .dispatch(pass, &level.smooth[colour], level.groups);
                    }
                }
            }
        })?;
        Ok(if down.source == TimingSource::Timestamps {
            down.seconds + up.seconds
        } else {
            f64::NAN
        })
    }

    /// The last cycle's kernels alone by the device's timestamps (both passes; without the
    /// transfers and the host's coarsest solve), where the adapter has timestamps.
    pub fn last_kernel_seconds(&self) -> Option<f64> {
        self.kernels
    }
}

/// The bindings of `shaders/multigrid.wgsl` for one level: uniform slot `slot`, the
/// operator, b, x and (for the transfers) the coarse level's vector.
fn bindings<'f>(
    uniforms: &'f UniformSlots,
    slot: usize,
    operator: &'f [DeviceField],
    b: &'f DeviceField,
    x: &'f DeviceField,
    coarse: Option<&'f DeviceField>,
) -> Vec<(u32, wgpu::BindingResource<'f>)> {
    let mut e = vec![(0u32, uniforms.slot(slot))];
    for (i, f) in operator.iter().enumerate() {
        e.push((i as u32 + 1, f.binding()));
    }
    e.push((6, b.binding()));
    e.push((7, x.binding()));
    e.extend(coarse.map(|c| (8, c.binding())));
    e
}

/// Host bytes of `gpu-diffusion-mg` per solve: `diffusion-mg`'s own (the hierarchy the
/// device's is uploaded from, the f64 vectors, the cut-cell geometry: 112 bytes per cell
/// and channel) and the f32 right-hand side and correction each cycle hands over (8).
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
