//! The registry entries of the GPU backends, each the twin of a CPU solver: the same
//! parameters (but `gpu-convection-diffusion`'s), the same capabilities (taken from the
//! CPU twin itself), the same stability checks before anything runs, the same driver.
//!
//! | entry | CPU twin | on the device |
//! |---|---|---|
//! | `gpu-direct` | `direct` | transmittance per light, cell and extinction channel |
//! | `gpu-ftcs-diffusion` | `ftcs-diffusion` | FTCS steps on the assembled CSR system, in correction form |
//! | `gpu-ftcs-p1` | `ftcs-p1` | P1 FTCS steps (φ and E ping-pong) |
//! | `gpu-convection-diffusion` | `convection-diffusion` (characteristic model) | layer sweeps per light, red–black Gauss–Seidel scattering |
//! | `gpu-lbm` | `lbm` | Lattice-Boltzmann pull steps, one dispatch per step |
//! | `gpu-diffusion-mg` | `diffusion-mg` | full multigrid and V-cycles (red–black colours, fused residual and restriction, prolongation, the coarsest level by its dense inverse); the f64 outer iteration on the device where it has f64, else on the host |
//! | `gpu-dom` | `dom` | each transport step (source fill, octant sweeps by cell hyperplanes, scattering product); the iteration and DSA on the host |
//!
//! The device is the process's shared [`GpuContext`]; no adapter is a
//! [`SolveError::Device`] with `unavailable` set, raised after the capability check (so a
//! problem a backend cannot handle says so first).

use lucent_core::driver::{self, Channel, ChannelMethod, ChannelSolution, Context, Route};
use lucent_core::{
    Capabilities, DirectSolver, Light, ParamDoc, ParamValue, Params, Problem, Solution, SolveError,
    SolveOptions, Solver, SolverEntry, SolverParams, param_docs, resolved_params,
};
use lucent_diffusion::{
    CycleParam, DiffusionSolver, DiscretisationParam, MultigridParams, SmootherParam,
};
use lucent_dom::{DomParams, DomSolver};
use lucent_explicit::{ExplicitSolver, FtcsDiffusionParams, Lattice, P1Params};
use lucent_gpu::{GpuContext, GpuError};
use lucent_lbm::{LbmParams, LbmSolver};

use crate::params::GpuConvectionParams;

/// A GPU backend in the registry.
#[derive(Debug, Clone, PartialEq)]
pub struct GpuSolver {
    name: &'static str,
    backend: Backend,
}

#[derive(Debug, Clone, PartialEq)]
enum Backend {
    Direct(DirectSolver),
    FtcsDiffusion(FtcsDiffusionParams),
    P1(P1Params),
    Convection(GpuConvectionParams),
    Lbm(LbmParams),
    Dom(DomSolver),
    DiffusionMg(MultigridParams),
}

/// A device error as a solve error of `solver`.
pub(crate) fn device_error(solver: &str, e: GpuError) -> SolveError {
    SolveError::Device {
        solver: solver.into(),
        unavailable: matches!(e, GpuError::NoAdapter { .. }),
        reason: e.to_string(),
    }
}

/// The next batch of a march recorded in batches (`gpu-ftcs-p1`, `gpu-lbm`), from the
/// last batch's per-step relative changes: the steps the observed geometric rate predicts
/// to reach `tolerance`, or twice the last batch where no rate below 1 shows; within
/// 1..=`most`.
pub(crate) fn next_batch(changes: &[f64], tolerance: f64, most: usize) -> usize {
    let k = changes.len();
    let (first, last) = (changes[0], changes[k - 1]);
    let rate = if k > 1 && first > 0.0 && last > 0.0 {
        (last / first).powf(1.0 / (k - 1) as f64)
    } else {
        0.0
    };
    if rate > 0.0 && rate < 1.0 && last > tolerance {
        ((tolerance / last).ln() / rate.ln()).ceil().max(1.0) as usize
    } else {
        2 * k
    }
    .clamp(1, most)
}

/// The most cell-steps one submission of a batch of steps may hold on `device`: a
/// submission cannot be interrupted, so Ctrl-C and the time limit (asked between
/// submissions) wait for at most one. A count of cells fixed by the kind of device, not a
/// time, so that batches, and so results, do not depend on the machine's load (batches
/// timed on the first step made two runs of a solve differ).
///
/// * A software device (lavapipe, WARP): 2²² cell-steps, under half a second (P1's step
///   at 64³ measured about 50 ms under load; a batch of 64 steps at 336³ once took 90 s).
/// * A hardware device: 2²⁸, a quarter second at 10⁹ cell-steps per second (a weak
///   integrated GPU on the lattice-Boltzmann step); a data-centre GPU runs it in tens of
///   milliseconds, and a 256³ grid still gets 16 steps per submission, so the wait on
///   each submission's partial sums stays small beside the steps.
///
/// `weight` is the step's cost per cell in units of a scalar stencil update (FTCS 1, P1's
/// four values 2, a lattice of q populations ⌈q/4⌉): the count is divided by it, so that
/// a submission takes about as long for every scheme (D3Q19's batch of 2²² cell-steps took
/// 1.5 s on lavapipe beside another test, and Ctrl-C waited for it).
pub(crate) fn cell_steps_per_submit(device: &GpuContext, weight: usize) -> usize {
    let cell_steps: usize = if device.is_software() {
        1 << 22
    } else {
        1 << 28
    };
    cell_steps / weight.max(1)
}

/// `wanted` steps cut to `most_cell_steps` ([`cell_steps_per_submit`]) on a grid of
/// `cells`, at least one.
pub(crate) fn bounded_batch(wanted: usize, cells: usize, most_cell_steps: usize) -> usize {
    wanted.min(most_cell_steps / cells.max(1)).max(1)
}

/// The shared device, or why there is none.
fn device(solver: &str) -> Result<&'static GpuContext, SolveError> {
    GpuContext::shared().map_err(|e| device_error(solver, e))
}

/// Parameters of the CPU twins that split a solve over ranks; a device solver runs in one
/// process on one device, so it neither lists nor accepts them.
const RANKS_ONLY: [&str; 2] = ["ranks", "decomposition"];

/// `params`, or the refusal of a ranks-only parameter set for a device solver (it was
/// accepted, recorded in the report and ignored).
fn one_device<'a>(params: &'a Params, solver: &str) -> Result<&'a Params, SolveError> {
    match RANKS_ONLY.iter().find(|name| params.0.contains_key(**name)) {
        Some(name) => Err(SolveError::InvalidParameter {
            name: (*name).into(),
            reason: format!(
                "`{solver}` runs on one device in one process and splits over no ranks (the CPU solver without `gpu-` does)"
            ),
        }),
        None => Ok(params),
    }
}

/// The CPU twin's parameters `T` without [`RANKS_ONLY`].
fn device_param_docs<T: SolverParams>() -> Vec<ParamDoc> {
    let mut docs = param_docs::<T>();
    docs.retain(|d| !RANKS_ONLY.contains(&d.name.as_str()));
    docs
}

/// The parameters that run, as `resolved_params`, without [`RANKS_ONLY`].
fn device_resolved<T: SolverParams>(
    params: &Params,
    solver: &str,
) -> Result<serde_json::Value, SolveError> {
    let mut value = resolved_params::<T>(one_device(params, solver)?, solver)?;
    if let serde_json::Value::Object(map) = &mut value {
        for name in RANKS_ONLY {
            map.remove(name);
        }
    }
    Ok(value)
}

impl GpuSolver {
    /// `gpu-direct` ([`DirectSolver`]'s parameters).
    pub const GPU_DIRECT: SolverEntry = SolverEntry {
        name: "gpu-direct",
        summary: "direct on the GPU: uncollided light by exact ray marching, one invocation per cell and light",
        build: |p| {
            Ok(Box::new(GpuSolver {
                name: "gpu-direct",
                backend: Backend::Direct(one_device(p, "gpu-direct")?.parse("gpu-direct")?),
            }))
        },
        params: device_param_docs::<DirectSolver>,
        resolved: |p| device_resolved::<DirectSolver>(p, "gpu-direct"),
    };

    /// `gpu-ftcs-diffusion` ([`FtcsDiffusionParams`]).
    pub const GPU_FTCS_DIFFUSION: SolverEntry = SolverEntry {
        name: "gpu-ftcs-diffusion",
        summary: "ftcs-diffusion on the GPU: FTCS to steady state on diffusion-mg's discrete problem, f64 defect correction",
        build: |p| {
            Ok(Box::new(GpuSolver {
                name: "gpu-ftcs-diffusion",
                backend: Backend::FtcsDiffusion(
                    one_device(p, "gpu-ftcs-diffusion")?.parse("gpu-ftcs-diffusion")?,
                ),
            }))
        },
        params: device_param_docs::<FtcsDiffusionParams>,
        resolved: |p| device_resolved::<FtcsDiffusionParams>(p, "gpu-ftcs-diffusion"),
    };

    /// `gpu-ftcs-p1` ([`P1Params`]).
    pub const GPU_FTCS_P1: SolverEntry = SolverEntry {
        name: "gpu-ftcs-p1",
        summary: "ftcs-p1 on the GPU: Murray's P1 moment system with FTCS, staggered or collocated",
        build: |p| {
            Ok(Box::new(GpuSolver {
                name: "gpu-ftcs-p1",
                backend: Backend::P1(one_device(p, "gpu-ftcs-p1")?.parse("gpu-ftcs-p1")?),
            }))
        },
        params: device_param_docs::<P1Params>,
        resolved: |p| device_resolved::<P1Params>(p, "gpu-ftcs-p1"),
    };

    /// `gpu-convection-diffusion` ([`GpuConvectionParams`]).
    pub const GPU_CONVECTION_DIFFUSION: SolverEntry = SolverEntry {
        name: "gpu-convection-diffusion",
        summary: "Zhang & Ma on the GPU: short-characteristic layer sweeps per light, red-black Gauss-Seidel scattering",
        build: |p| {
            Ok(Box::new(GpuSolver {
                name: "gpu-convection-diffusion",
                backend: Backend::Convection(
                    one_device(p, "gpu-convection-diffusion")?.parse("gpu-convection-diffusion")?,
                ),
            }))
        },
        params: device_param_docs::<GpuConvectionParams>,
        resolved: |p| device_resolved::<GpuConvectionParams>(p, "gpu-convection-diffusion"),
    };

    /// `gpu-lbm` ([`LbmParams`]).
    pub const GPU_LBM: SolverEntry = SolverEntry {
        name: "gpu-lbm",
        summary: "lbm on the GPU: the same lattice, collision and walls, one dispatch per pull step, one buffer per link",
        build: |p| {
            Ok(Box::new(GpuSolver {
                name: "gpu-lbm",
                backend: Backend::Lbm(one_device(p, "gpu-lbm")?.parse("gpu-lbm")?),
            }))
        },
        params: device_param_docs::<LbmParams>,
        resolved: |p| device_resolved::<LbmParams>(p, "gpu-lbm"),
    };

    /// `gpu-dom` (`dom`'s parameters but `storage_level` and `work_pool_mib`, which it
    /// refuses).
    pub const GPU_DOM: SolverEntry = SolverEntry {
        name: "gpu-dom",
        summary: "dom on the GPU: source fill, octant sweeps by cell hyperplanes and scattering product per step; iteration and DSA on the host",
        build: |p| {
            Ok(Box::new(GpuSolver {
                name: "gpu-dom",
                backend: Backend::Dom(DomSolver::from_params_as(
                    one_device(p, "gpu-dom")?,
                    "gpu-dom",
                )?),
            }))
        },
        params: device_param_docs::<DomParams>,
        resolved: |p| device_resolved::<DomParams>(p, "gpu-dom"),
    };

    /// `gpu-diffusion-mg` (`diffusion-mg`'s [`MultigridParams`]; V-cycles with red–black
    /// Gauss–Seidel on the embedded boundary, others refused naming the parameter; full
    /// multigrid first on the device when `full_multigrid` is on, as `diffusion-mg`).
    pub const GPU_DIFFUSION_MG: SolverEntry = SolverEntry {
        name: "gpu-diffusion-mg",
        summary: "diffusion-mg on the GPU: full multigrid, V-cycles and (where the device has f64) the f64 outer iteration on the device",
        build: |p| {
            let params: MultigridParams =
                one_device(p, "gpu-diffusion-mg")?.parse("gpu-diffusion-mg")?;
            let refuse = |name: &str, reason: &str| {
                Err(SolveError::InvalidParameter {
                    name: name.into(),
                    reason: format!("gpu-diffusion-mg runs {reason}"),
                })
            };
            if params.cycle != CycleParam::V {
                return refuse("cycle", "V-cycles only");
            }
            if params.smoother != SmootherParam::GaussSeidel {
                return refuse("smoother", "red–black Gauss–Seidel only");
            }
            if params.discretisation != DiscretisationParam::Embedded {
                return refuse("discretisation", "the embedded boundary only");
            }
            Ok(Box::new(GpuSolver {
                name: "gpu-diffusion-mg",
                backend: Backend::DiffusionMg(params),
            }))
        },
        params: device_param_docs::<MultigridParams>,
        resolved: |p| device_resolved::<MultigridParams>(p, "gpu-diffusion-mg"),
    };

    /// Every GPU entry.
    pub const ENTRIES: [SolverEntry; 7] = [
        Self::GPU_DIRECT,
        Self::GPU_FTCS_DIFFUSION,
        Self::GPU_FTCS_P1,
        Self::GPU_CONVECTION_DIFFUSION,
        Self::GPU_LBM,
        Self::GPU_DOM,
        Self::GPU_DIFFUSION_MG,
    ];

    /// The CPU twin, for its capabilities and its stability checks.
    fn twin(&self) -> Box<dyn Solver> {
        let built = match &self.backend {
            Backend::Direct(d) => return Box::new(*d),
            Backend::Lbm(p) => return Box::new(LbmSolver::new(*p)),
            Backend::Dom(d) => return Box::new(d.clone()),
            Backend::FtcsDiffusion(_) | Backend::DiffusionMg(_) => {
                return Box::new(DiffusionSolver::custom(self.name));
            }
            Backend::P1(_) => (ExplicitSolver::FTCS_P1.build)(&Params::default()),
            Backend::Convection(p) => {
                let mut params = Params::default();
                params
                    .0
                    .insert("scattering".into(), ParamValue::Float(p.scattering));
                (ExplicitSolver::CONVECTION_DIFFUSION.build)(&params)
            }
        };
        built.expect("the CPU twin's defaults are valid")
    }
}

impl Solver for GpuSolver {
    fn name(&self) -> &str {
        self.name
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            // One device, one process.
            ranks: false,
            ..self.twin().capabilities()
        }
    }

    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
        // What the backend cannot handle, and a budget it would exceed, are said before
        // whether a device exists.
        self.admits(problem)?;
        let needed = match &self.backend {
            Backend::Direct(_) => crate::direct::memory_bytes(problem),
            Backend::FtcsDiffusion(_) => crate::ftcs::memory_bytes(problem),
            Backend::P1(_) => crate::p1::memory_bytes(problem),
            Backend::Convection(_) => crate::convection::memory_bytes(problem),
            Backend::Lbm(p) => {
                problem.geometry().voxel_count() as u64
                    * crate::lbm::bytes_per_cell(&LbmSolver::new(*p))
                    * problem.channels() as u64
            }
            // The host's part is `dom`'s own budget check (its driver's).
            Backend::Dom(_) => 0,
            Backend::DiffusionMg(_) => crate::multigrid::memory_bytes(problem),
        };
        if needed > options.memory_budget {
            return Err(SolveError::OverBudget {
                solver: self.name.into(),
                needed,
                budget: options.memory_budget,
            });
        }
        match &self.backend {
            Backend::Direct(params) => {
                let gpu = device(self.name)?;
                let needed = crate::direct::memory_bytes(problem);
                driver::run(self, problem, options, needed, |context| {
                    crate::direct::transport(context, gpu, params, needed, self.name)
                })
            }
            Backend::FtcsDiffusion(params) => {
                if params.step_fraction > 1.0 && !params.allow_unstable {
                    return Err(SolveError::Unstable {
                        solver: self.name.into(),
                        parameter: "step_fraction (of the FTCS bound)".into(),
                        limit: 1.0,
                        requested: params.step_fraction,
                    });
                }
                let gpu = device(self.name)?;
                let volume = problem.geometry().cell_volume();
                let memory = crate::ftcs::memory_bytes(problem);
                let params = *params;
                let name = self.name;
                DiffusionSolver::custom(self.name).solve_with(
                    problem,
                    options,
                    memory,
                    &|d, s, stop| crate::ftcs::steady(gpu, d, s, stop, &params, volume, name),
                )
            }
            Backend::P1(_) => {
                device(self.name)?;
                driver::solve_per_channel(self, self, problem, options).map(|(s, _)| s)
            }
            Backend::Lbm(params) => {
                device(self.name)?;
                let method = crate::lbm::GpuLbm {
                    cpu: LbmSolver::new(*params),
                    name: self.name,
                };
                driver::solve_per_channel(self, &method, problem, options).map(|(s, _)| s)
            }
            Backend::Dom(dom) => {
                let gpu = device(self.name)?;
                let factory: std::sync::Arc<lucent_dom::device::DeviceFactory> =
                    std::sync::Arc::new(move || {
                        Ok(Box::new(crate::dom::GpuTransport::new(
                            gpu,
                            crate::dom::Wavefront::default(),
                        ))
                            as Box<dyn lucent_dom::device::DeviceTransport>)
                    });
                dom.clone()
                    .on_device(self.name, factory)
                    .solve(problem, options)
            }
            Backend::DiffusionMg(params) => {
                let gpu = device(self.name)?;
                let memory = crate::multigrid::memory_bytes(problem);
                let settings = params.settings();
                DiffusionSolver::custom(self.name).solve_with(
                    problem,
                    options,
                    memory,
                    &|d, s, stop| crate::multigrid::steady(gpu, d, s, stop, settings),
                )
            }
            Backend::Convection(params) => {
                let gpu = device(self.name)?;
                let memory = crate::convection::memory_bytes(problem);
                driver::run(self, problem, options, memory, |context| {
                    crate::convection::solve(context, gpu, params, self.name)
                })
            }
        }
    }
}

/// `gpu-ftcs-p1` marches each channel with the lights it takes itself (point lights in
/// the grid and emission), as `ftcs-p1` does.
impl ChannelMethod for GpuSolver {
    type Setup = (Lattice, &'static GpuContext);
    type Extra = ();

    fn stage(&self) -> &'static str {
        "time step"
    }

    fn memory_bytes(&self, problem: &Problem) -> u64 {
        crate::p1::memory_bytes(problem)
    }

    fn setup(&self, context: &Context<'_>) -> Result<Self::Setup, SolveError> {
        Ok((
            lucent_explicit::lattice(context.problem)?,
            device(self.name)?,
        ))
    }

    fn route(&self, _: &Self::Setup, _: &Problem, _: &Light) -> Route {
        Route::Own
    }

    fn solve_channel(
        &self,
        (lattice, gpu): &Self::Setup,
        channel: Channel<'_>,
    ) -> Result<ChannelSolution<()>, SolveError> {
        let Backend::P1(params) = &self.backend else {
            return Err(SolveError::InvalidParameter {
                name: "backend".into(),
                reason: format!("{} is not a per-channel march", self.name),
            });
        };
        let q = lucent_explicit::point_and_emission(&channel);
        let (fluence, record) = crate::p1::march(gpu, lattice, &channel, &q, params, self.name)?;
        Ok(ChannelSolution {
            fluence,
            record,
            extra: (),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `ranks` and `decomposition` of the CPU twins were listed for `gpu-ftcs-diffusion`,
    /// `gpu-ftcs-p1` and `gpu-diffusion-mg`, accepted, recorded in the report and ignored:
    /// every device solver now neither lists nor accepts them, and the error names the
    /// parameter.
    #[test]
    fn no_device_solver_lists_or_accepts_ranks() {
        for entry in GpuSolver::ENTRIES {
            let docs = (entry.params)();
            assert!(
                docs.iter().all(|d| !RANKS_ONLY.contains(&d.name.as_str())),
                "{} lists a ranks parameter",
                entry.name
            );
            let resolved = (entry.resolved)(&Params::default()).unwrap();
            for name in RANKS_ONLY {
                assert!(
                    resolved.get(name).is_none(),
                    "{} records {name}",
                    entry.name
                );
                let mut params = Params::default();
                let value = match name {
                    "ranks" => ParamValue::Int(2),
                    _ => ParamValue::Text("boxes".into()),
                };
                params.0.insert(name.into(), value);
                match (entry.build)(&params) {
                    Err(SolveError::InvalidParameter { name: refused, .. }) => {
                        assert_eq!(refused, name, "{}", entry.name)
                    }
                    Err(other) => panic!("{}: {name}: {other}", entry.name),
                    Ok(_) => panic!("{}: {name} accepted", entry.name),
                }
            }
        }
    }
}
