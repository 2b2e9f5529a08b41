//! `gpu-lbm`: `lbm` on the device. The same lattice problem (`LbmSolver::lattice_problem`:
//! D/h, κ_a, the first-collision sources in lattice units, the walls' condition), the same
//! collision, walls and stopping rule (`lucent_lbm::Ledger`), marched by the pull pattern:
//! one dispatch per step (`lbm.wgsl` after `lbm_d3q7.wgsl` or `lbm_d3q19.wgsl`), one
//! invocation per cell gathering f*_k(x − e_k) from one copy of the populations and writing
//! its collided f*_k into the other.
//!
//! Layout: one storage buffer per link holding that link's populations twice (the two
//! copies, n cells apart), so a D3Q19 step binds 19 population buffers and 6 others (25
//! storage buffers: lavapipe offers 32, desktop GPUs more; an adapter with fewer is refused
//! before upload), and each binding holds 8n bytes (256³ cells fit lavapipe's 128 MiB). A
//! GPU reads and writes each population once per step, in runs of consecutive cells per
//! link: (2Q + 4) × 4 bytes per cell update, the CPU's in-place figure plus Q × 4.
//!
//! Two copies rather than the AA pattern's one: the pull step keeps every wall rule local to
//! its cell (its own outgoing populations of the last step) and every write a cell's own,
//! so one dispatch is one synchronous step with no side slots and no conflicts. The
//! `streaming` parameter is therefore only the CPU's (its two patterns give the same
//! bits); blockwise scheduling is refused (it exists for a GPU whose textures did not hold
//! the volume; here one dispatch advances every block).
//!
//! Precision: f32 populations as on the CPU; per-workgroup sums pairwise in f32, added in
//! f64 on the host, so the energy imbalance the stopping rule reads is measured to about
//! 1e-7 of the emitted light (the CPU's to f64 over f32 cells): tolerances below that end
//! at the iteration limit, reported as such. Steps run in batches (up to 64 per submit,
//! sized by the observed rate, as `gpu-ftcs-p1`); a batch that meets the stopping rule
//! part way is finished, so the fluence returned is up to a batch's steps further on than
//! the step that met it (nearer the steady state, never further from it); every step run is
//! in the residual history and the iteration count, the stop reason is the first verdict.

use lucent_core::driver::{Channel, ChannelMethod, ChannelSolution, Context, Record};
use lucent_core::{Angular, History, Problem, SolveError, StopReason, Uncollided};
use lucent_gpu::{DeviceField, GpuContext, GpuError, UniformSlots, WORKGROUP, groups_2d, shaders};
use lucent_grid::Grid;
use lucent_lbm::{
    Bookkeeping, Collision, LatticeProblem, LbmSolver, Ledger, MarchSettings, Marched, Velocities,
    Wall,
};

use crate::solver::device_error;

const MAX_BATCH: usize = 64;
/// Partial sums per workgroup and step: Σ(ρ′ − ρ)², Σρ′², absorbed, escaped, max |ρ′|.
const PARTIALS: usize = 5;

/// The uniform block of `lbm.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LbmParams32 {
    dims: [u32; 4],
    step: [u32; 4],
    scheme: [u32; 4],
    wall: [f32; 4],
}

/// Storage buffers a step binds: one per link, the four coefficient and source fields,
/// ρ and the partials.
fn storage_buffers(velocities: Velocities) -> u32 {
    velocities.len() as u32 + 6
}

/// Bytes per cell on the device: two copies of the populations, D/h and κ_a, q₀ and q₁,
/// ρ; on the host the lattice problem (as `lbm`) and the downloaded populations.
pub(crate) fn bytes_per_cell(solver: &LbmSolver) -> u64 {
    let q = solver.params().lattice.len() as u64;
    4 * (2 * q + 7) + solver.bytes_per_cell()
}

/// `gpu-lbm` per channel: the CPU twin's lattice problem, marched on the device.
pub(crate) struct GpuLbm {
    pub(crate) cpu: LbmSolver,
    pub(crate) name: &'static str,
}

impl ChannelMethod for GpuLbm {
    type Setup = &'static GpuContext;
    /// The scattered fluence (the renderer's isotropic in-scattering), as `lbm`'s.
    type Extra = Grid;

    fn stage(&self) -> &'static str {
        "lattice step"
    }

    fn memory_bytes(&self, problem: &Problem) -> u64 {
        problem.geometry().voxel_count() as u64 * bytes_per_cell(&self.cpu)
    }

    fn setup(&self, _: &Context<'_>) -> Result<Self::Setup, SolveError> {
        GpuContext::shared().map_err(|e| device_error(self.name, e))
    }

    fn solve_channel(
        &self,
        gpu: &Self::Setup,
        channel: Channel<'_>,
    ) -> Result<ChannelSolution<Grid>, SolveError> {
        let geometry = *channel.problem.geometry();
        let lattice = self.cpu.lattice_problem(&channel);
        let settings = self.cpu.settings(channel.stopping.clone());
        let marched = march(gpu, &lattice, &settings, self.name)?;
        let n = geometry.voxel_count() as u64;
        let mut record = Record::from_residuals(
            marched.residuals,
            marched.stop_reason,
            n * bytes_per_cell(&self.cpu),
        );
        record.iterations = marched.steps;
        Ok(ChannelSolution {
            fluence: marched.fluence.clone(),
            record,
            extra: Grid::from_vec(geometry, marched.fluence)?,
        })
    }

    fn angular(
        &self,
        _: &Self::Setup,
        _: &Problem,
        scattered: &mut [Grid],
        uncollided: Option<Uncollided>,
    ) -> Result<Option<Angular>, SolveError> {
        Ok(uncollided.and_then(|u| u.into_angular(scattered)))
    }
}

/// Marches `problem` from zero to steady state on the device, as `lucent_lbm::march` does
/// on the host (two arrays, pull).
pub fn march(
    gpu: &GpuContext,
    problem: &LatticeProblem,
    settings: &MarchSettings,
    name: &str,
) -> Result<Marched, SolveError> {
    let err = |e| device_error(name, e);
    lucent_lbm::check(problem, settings).map_err(|e| e.into_solve_error(name))?;
    if settings.blocks.is_some() {
        return Err(SolveError::InvalidParameter {
            name: "block_slabs".into(),
            reason: format!(
                "{name} advances every cell in one dispatch per step; blockwise scheduling is the CPU lattice's option"
            ),
        });
    }
    let needed = storage_buffers(settings.velocities);
    let limits = gpu.limits();
    for (what, needed, offered) in [
        (
            "max_storage_buffers_per_shader_stage",
            needed,
            limits.max_storage_buffers_per_shader_stage,
        ),
        (
            "max_buffers_and_acceleration_structures_per_shader_stage",
            needed + 1,
            limits.max_buffers_and_acceleration_structures_per_shader_stage,
        ),
    ] {
        if offered < needed {
            return Err(err(GpuError::Unsupported {
                adapter: gpu.info().name.clone(),
                what,
                needed: u64::from(needed),
                available: u64::from(offered),
            }));
        }
    }
    let [nx, ny, nz] = problem.dims;
    let n = nx * ny * nz;
    let q = settings.velocities.len();
    gpu.check_binding("gpu-lbm populations (two copies of one link)", 8 * n as u64)
        .map_err(err)?;
    let upload = |what: &str, values: &[f32]| DeviceField::upload(gpu, what, values, false);
    let first = upload("LBM first coefficient", &problem.first).map_err(err)?;
    let second = upload("LBM second coefficient", &problem.second).map_err(err)?;
    let source = upload("LBM source", &problem.source).map_err(err)?;
    let has_moment = !problem.first_moment.is_empty();
    let moment: Vec<f32> = if has_moment {
        problem.first_moment.iter().flatten().copied().collect()
    } else {
        vec![0.0; 3]
    };
    let moment = upload("LBM first moment", &moment).map_err(err)?;
    let rho = DeviceField::zeros(gpu, "LBM fluence", n).map_err(err)?;
    let populations: Vec<DeviceField> = (0..q)
        .map(|k| DeviceField::zeros(gpu, &format!("LBM populations f{k}"), 2 * n))
        .collect::<Result<_, _>>()
        .map_err(err)?;
    let groups = groups_2d(gpu, n as u64, WORKGROUP);
    let per_step_values = (groups[0] * groups[1]) as usize;
    let partials = DeviceField::zeros(gpu, "LBM partials", PARTIALS * MAX_BATCH * per_step_values)
        .map_err(err)?;
    let (file, source_text) = match settings.velocities {
        Velocities::D3q7 => ("lbm_d3q7.wgsl + lbm.wgsl", shaders::LBM_D3Q7),
        Velocities::D3q19 => ("lbm_d3q19.wgsl + lbm.wgsl", shaders::LBM_D3Q19),
    };
    let kernel = gpu.kernel(file, source_text, "lbm_step").map_err(err)?;
    let (wall_kind, wall_value) = match problem.wall {
        Wall::Robin { a } => (0, a),
        Wall::Dirichlet { value } => (1, value),
        Wall::Neumann { flux } => (2, flux),
        Wall::Reflect { reflectance } => (3, reflectance),
    };
    let scheme = [
        match settings.collision {
            Collision::Trt => 0,
            Collision::Bgk => 1,
            Collision::Geist => 2,
        },
        match settings.absorption {
            lucent_lbm::Absorption::True => 0,
            lucent_lbm::Absorption::Thesis => 1,
        },
        wall_kind,
        0,
    ];
    // Slot 2j + c: step j of a batch, reading copy c.
    let slots: Vec<LbmParams32> = (0..2 * MAX_BATCH)
        .map(|s| LbmParams32 {
            dims: [nx as u32, ny as u32, nz as u32, groups[0]],
            step: [
                (s % 2) as u32,
                ((s / 2) * per_step_values) as u32,
                u32::from(has_moment),
                0,
            ],
            scheme,
            wall: [wall_value as f32, 0.0, 0.0, 0.0],
        })
        .collect();
    let uniforms = UniformSlots::new(gpu, "LBM steps", &slots).map_err(err)?;
    let binds = (0..2 * MAX_BATCH)
        .map(|s| {
            let mut resources = vec![
                uniforms.slot(s),
                first.binding(),
                second.binding(),
                source.binding(),
                moment.binding(),
                rho.binding(),
                partials.binding(),
            ];
            resources.extend(populations.iter().map(DeviceField::binding));
            kernel.bind(gpu, &resources)
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(err)?;
    // Records `k` steps, the first reading copy `read`.
    let run = |read: usize, k: usize| {
        gpu.submit_pass(name, |pass| {
            for j in 0..k {
                kernel.dispatch(pass, &binds[2 * j + (read + j) % 2], groups);
            }
        })
        .map_err(err)
    };
    let mut ledger = Ledger::new(problem, settings);
    let mut history = History::start();
    let stopping = &settings.stopping;
    let mut read = 0usize;
    let mut batch = 8usize;
    let stop_reason = loop {
        let done = ledger.steps();
        let k = crate::solver::bounded_batch(
            batch,
            n,
            crate::solver::cell_steps_per_submit(gpu, q.div_ceil(4)),
        )
        .min(MAX_BATCH)
        .min(stopping.max_iterations.saturating_sub(done))
        .max(1);
        run(read, k)?;
        read = (read + k) % 2;
        let sums = partials
            .download_prefix(gpu, PARTIALS * k * per_step_values)
            .map_err(err)?;
        let mut stopped = None;
        let mut changes = Vec::with_capacity(k);
        for block in sums.chunks_exact(PARTIALS * per_step_values) {
            let mut totals = [0.0f64; 4];
            let mut finite = true;
            for w in block.chunks_exact(PARTIALS) {
                for (t, v) in totals.iter_mut().zip(w) {
                    *t += f64::from(*v);
                }
                finite &= w[4] < 3.0e38 && w[..4].iter().all(|v| v.is_finite());
            }
            let [change, size, absorbed, escaped] = totals;
            let (relative, absolute) = ledger.step(absorbed, escaped, change, size);
            // Every step run is recorded (and reported to the progress callback), the
            // batch's steps after the one that met the rule too; the first verdict stands.
            let verdict = history.record_step(stopping, ledger.steps(), relative, absolute);
            if stopped.is_some() {
                continue;
            }
            if !finite {
                stopped = Some(StopReason::DivergedNonFinite {
                    iteration: ledger.steps(),
                });
                continue;
            }
            changes.push(relative);
            stopped = verdict;
        }
        if let Some(reason) = stopped {
            break reason;
        }
        batch = crate::solver::next_batch(&changes, stopping.relative_tolerance, MAX_BATCH);
    };
    let fluence = rho.download(gpu).map_err(err)?;
    // `read` is now the copy the next step would read: the one the last step wrote.
    let latest: Vec<Vec<f32>> = populations
        .iter()
        .map(|f| {
            f.download(gpu)
                .map(|all| all[read * n..(read + 1) * n].to_vec())
        })
        .collect::<Result<_, _>>()
        .map_err(err)?;
    let (held, pending) = lucent_lbm::held_and_pending(problem, settings, &latest);
    let steps = ledger.steps();
    let bookkeeping: Bookkeeping = ledger.finish(held, pending);
    Ok(Marched {
        fluence,
        steps,
        residuals: history.into_residuals(),
        stop_reason,
        bookkeeping,
    })
}
