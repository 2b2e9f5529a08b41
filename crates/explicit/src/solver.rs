//! The registry's explicit solvers, each on a `lucent_core::Problem`:
//!
//! - `ftcs-diffusion`, `jacobi-diffusion`: FTCS and Jacobi on exactly the discrete problem
//!   `diffusion-mg` solves (lucent-diffusion's mapping: reduced-intensity source, Robin
//!   boundaries, embedded surfaces), marched to the stopping tolerance. Parameters
//!   `step_fraction` (of the FTCS bound, 0.9), `omega` (Jacobi, 1), `allow_unstable`. On
//!   a paged medium they run out of core with the same bits (`paged_steady`).
//! - `convection-diffusion`: Zhang & Ma per channel: every directional and point light
//!   marched by convection–absorption (σ_t as the absorption), composed, then the implicit
//!   scattering step with `scattering` = σ̂_s t (length², 0 by default: the uncollided
//!   light only, comparable with `direct`). Parameters `model` (`characteristic`, the
//!   default: short characteristics with exact per-step attenuation, second order and
//!   free of a Courant limit; `conservative`: first-order upwind fluxes; `paper`: Eq. 16
//!   as printed), `courant` (½, for the two upwind models), `sweep` (ordered, layers,
//!   jacobi), `scattering`, `allow_unstable`. The upwind models are first order and
//!   attenuate a cell by 1/(1 + σ_t h) instead of e^{−σ_t h}: 5.6% and 3.3% relative L2
//!   against `direct` at 32×32×48 and 64×64×96 under an oblique sun, where the
//!   characteristic model is second order (docs/validation.md).
//! - `ftcs-p1`: Murray's P1 system with FTCS on a homogeneous medium (σ_a, σ_t′ from the
//!   first cell), zero beyond the box. Parameters `layout` (staggered, collocated),
//!   `step_fraction` (0.9), `allow_unstable`.
//! - `ftcs-ordinates`: FTCS upwind ordinates with isotropic scattering, vacuum edges.
//!   Parameters `order` (level-symmetric S_N, 4), `step_fraction` (0.9), `allow_unstable`.
//!
//! The last two take point lights inside the grid (power 4πI into the cell that holds
//! them) and emission; the fluence they return counts all light. On a paged medium they
//! march with their state in slab pages, with the same bits (`paged_march`).

use std::time::Instant;

use lucent_core::driver::{
    self, Channel, ChannelMethod, ChannelSolution, Context, Outcome, Record, Route,
};
use lucent_core::{
    BoundaryKind, Capabilities, FluenceKind, Light, LightKind, OutputKind, PagedProblem,
    PagedSolution, Problem, Solution, SolveError, SolveOptions, Solver, SolverEntry, param_docs,
    resolved_params,
};
use lucent_diffusion::{Convergence, DiffusionSolution, DiffusionSolver, RanksOf};
use lucent_grid::Grid;
use lucent_optics::PhaseFunction;

use crate::convection::{
    DEFAULT_COURANT, Model, UpwindSettings, compose, courant_bound, propagate,
};
use crate::error::ExplicitError;
use crate::lattice::Lattice;
use crate::params::{
    ConvectionParams, DecompositionParam, FtcsDiffusionParams, JacobiDiffusionParams,
    OrdinatesParams, P1Params,
};
use crate::ranks::{Boxes, Decomposition, iterate_on, iterate_on_threads};
use crate::steady::{Iteration, SteadySettings, ftcs_limit, iterate};

fn invalid(name: &str, reason: impl Into<String>) -> SolveError {
    SolveError::InvalidParameter {
        name: name.into(),
        reason: reason.into(),
    }
}

pub(crate) fn explicit_error(e: ExplicitError) -> SolveError {
    match e {
        ExplicitError::Unstable {
            scheme,
            parameter,
            limit,
            requested,
        } => SolveError::Unstable {
            solver: scheme.into(),
            parameter: parameter.into(),
            limit,
            requested,
        },
        ExplicitError::Invalid(reason) => invalid("problem", reason),
    }
}

/// The explicit schemes' registry entries.
#[derive(Debug, Clone, PartialEq)]
pub struct ExplicitSolver {
    name: &'static str,
    scheme: Scheme,
}

#[derive(Debug, Clone, PartialEq)]
enum Scheme {
    Steady {
        iteration: SteadyKind,
        allow_unstable: bool,
        /// In-process ranks.
        ranks: usize,
        /// How ranks split the grid.
        decomposition: DecompositionParam,
    },
    Convection {
        settings: UpwindSettings,
        scattering: f64,
        /// In-process ranks.
        ranks: usize,
        /// How ranks split the grid.
        decomposition: DecompositionParam,
    },
    P1 {
        layout: crate::p1::Layout,
        fraction: f64,
        allow_unstable: bool,
        /// In-process ranks.
        ranks: usize,
        decomposition: DecompositionParam,
    },
    Ordinates {
        order: usize,
        fraction: f64,
        allow_unstable: bool,
    },
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum SteadyKind {
    Ftcs { fraction: f64 },
    Jacobi { omega: f64 },
}

/// The out-of-core scheme a paged solve runs.
enum PagedPath {
    /// FTCS or Jacobi to steady state, state in slab pages.
    Steady(crate::paged_steady::Kind),
    /// P1 or ordinates in time, state in slab pages.
    March(crate::paged_march::March),
    /// The absorption march plane by plane.
    Convection,
}

impl ExplicitSolver {
    /// Which out-of-core scheme runs for this solver, after the checks every paged solve
    /// makes first (options, one process, the scheme's stability, capabilities: the
    /// medium's values too where `medium`, not on a shell).
    fn paged_path(
        &self,
        problem: &PagedProblem,
        options: &SolveOptions,
        medium: bool,
    ) -> Result<PagedPath, SolveError> {
        options.validate()?;
        let one_process = |ranks: usize| {
            if ranks > 1 || options.ranks.as_ref().is_some_and(|r| r.size() > 1) {
                Err(SolveError::Unsupported {
                    solver: self.name.into(),
                    feature: "ranks out of core: a paged solve runs in one process".into(),
                })
            } else {
                Ok(())
            }
        };
        let path = match self.scheme {
            Scheme::Steady {
                iteration,
                allow_unstable,
                ranks,
                ..
            } => {
                one_process(ranks)?;
                PagedPath::Steady(match iteration {
                    SteadyKind::Ftcs { fraction } => {
                        self.check_fraction(fraction, allow_unstable)?;
                        crate::paged_steady::Kind::Ftcs { fraction }
                    }
                    SteadyKind::Jacobi { omega } => crate::paged_steady::Kind::Jacobi { omega },
                })
            }
            Scheme::P1 {
                layout,
                fraction,
                allow_unstable,
                ranks,
                ..
            } => {
                one_process(ranks)?;
                PagedPath::March(crate::paged_march::March::P1 {
                    layout,
                    fraction,
                    allow_unstable,
                })
            }
            Scheme::Ordinates {
                order,
                fraction,
                allow_unstable,
            } => PagedPath::March(crate::paged_march::March::Ordinates {
                order,
                fraction,
                allow_unstable,
            }),
            Scheme::Convection { ranks, .. } => {
                one_process(ranks)?;
                self.paged_convection()?;
                return Ok(PagedPath::Convection);
            }
        };
        if medium {
            self.capabilities().check_paged(self.name, problem)?;
        } else {
            self.capabilities().check_paged_shape(self.name, problem)?;
        }
        Ok(path)
    }

    /// `ftcs-diffusion` ([`FtcsDiffusionParams`]).
    pub const FTCS_DIFFUSION: SolverEntry = SolverEntry {
        name: "ftcs-diffusion",
        summary: "FTCS to steady state on diffusion-mg's discrete problem (Murray ch. 4)",
        build: |p| {
            let p: FtcsDiffusionParams = p.parse("ftcs-diffusion")?;
            Ok(Box::new(ExplicitSolver {
                name: "ftcs-diffusion",
                scheme: Scheme::Steady {
                    iteration: SteadyKind::Ftcs {
                        fraction: p.step_fraction,
                    },
                    allow_unstable: p.allow_unstable,
                    ranks: p.ranks,
                    decomposition: p.decomposition,
                },
            }))
        },
        params: param_docs::<FtcsDiffusionParams>,
        resolved: |p| resolved_params::<FtcsDiffusionParams>(p, "ftcs-diffusion"),
    };

    /// `jacobi-diffusion` ([`JacobiDiffusionParams`]).
    pub const JACOBI_DIFFUSION: SolverEntry = SolverEntry {
        name: "jacobi-diffusion",
        summary: "Jacobi relaxation of the steady diffusion equation (FTCS at the positivity bound)",
        build: |p| {
            let p: JacobiDiffusionParams = p.parse("jacobi-diffusion")?;
            Ok(Box::new(ExplicitSolver {
                name: "jacobi-diffusion",
                scheme: Scheme::Steady {
                    iteration: SteadyKind::Jacobi { omega: p.omega },
                    allow_unstable: false,
                    ranks: p.ranks,
                    decomposition: p.decomposition,
                },
            }))
        },
        params: param_docs::<JacobiDiffusionParams>,
        resolved: |p| resolved_params::<JacobiDiffusionParams>(p, "jacobi-diffusion"),
    };

    /// `convection-diffusion` ([`ConvectionParams`]).
    pub const CONVECTION_DIFFUSION: SolverEntry = SolverEntry {
        name: "convection-diffusion",
        summary: "Zhang & Ma: upwind convection-absorption per light, then implicit scattering",
        build: |p| {
            let p: ConvectionParams = p.parse("convection-diffusion")?;
            Ok(Box::new(ExplicitSolver {
                name: "convection-diffusion",
                scheme: Scheme::Convection {
                    settings: UpwindSettings {
                        courant: p.courant,
                        model: p.model,
                        sweep: p.sweep.into(),
                        allow_unstable: p.allow_unstable,
                        ..UpwindSettings::default()
                    },
                    scattering: p.scattering,
                    ranks: p.ranks,
                    decomposition: p.decomposition,
                },
            }))
        },
        params: param_docs::<ConvectionParams>,
        resolved: |p| resolved_params::<ConvectionParams>(p, "convection-diffusion"),
    };

    /// `ftcs-p1` ([`P1Params`]).
    pub const FTCS_P1: SolverEntry = SolverEntry {
        name: "ftcs-p1",
        summary: "Murray's P1 moment system with FTCS, staggered or collocated grid",
        build: |p| {
            let p: P1Params = p.parse("ftcs-p1")?;
            Ok(Box::new(ExplicitSolver {
                name: "ftcs-p1",
                scheme: Scheme::P1 {
                    layout: p.layout,
                    fraction: p.step_fraction,
                    allow_unstable: p.allow_unstable,
                    ranks: p.ranks,
                    decomposition: p.decomposition,
                },
            }))
        },
        params: param_docs::<P1Params>,
        resolved: |p| resolved_params::<P1Params>(p, "ftcs-p1"),
    };

    /// `ftcs-ordinates` ([`OrdinatesParams`]).
    pub const FTCS_ORDINATES: SolverEntry = SolverEntry {
        name: "ftcs-ordinates",
        summary: "the unsteady RTE over discrete directions with upwind FTCS (Murray §3.4.1)",
        build: |p| {
            let p: OrdinatesParams = p.parse("ftcs-ordinates")?;
            Ok(Box::new(ExplicitSolver {
                name: "ftcs-ordinates",
                scheme: Scheme::Ordinates {
                    order: p.order,
                    fraction: p.step_fraction,
                    allow_unstable: p.allow_unstable,
                },
            }))
        },
        params: param_docs::<OrdinatesParams>,
        resolved: |p| resolved_params::<OrdinatesParams>(p, "ftcs-ordinates"),
    };

    /// Every entry of this crate.
    pub const ENTRIES: [SolverEntry; 5] = [
        Self::FTCS_DIFFUSION,
        Self::JACOBI_DIFFUSION,
        Self::CONVECTION_DIFFUSION,
        Self::FTCS_P1,
        Self::FTCS_ORDINATES,
    ];
}

/// The lattice of a problem's grid (the capabilities ask for cubic cells).
pub fn lattice(problem: &Problem) -> Result<Lattice, SolveError> {
    let g = problem.geometry();
    let mut l = Lattice::new(g.dims(), g.spacing().x).map_err(explicit_error)?;
    l.origin = g.origin();
    Ok(l)
}

/// Sources of P1 and ordinates in a channel: point lights (4πI into the cell holding them;
/// the capabilities keep them inside the grid) and emission (4π L_e), as power per volume.
pub fn point_and_emission(channel: &Channel<'_>) -> Vec<f64> {
    let g = channel.problem.geometry();
    let mut q: Vec<f64> = channel
        .emission()
        .iter()
        .map(|e| 4.0 * std::f64::consts::PI * e)
        .collect();
    for (position, power) in channel.point_sources() {
        // Cell i spans [i, i + 1) in these coordinates.
        let v = g.world_to_voxel(position) + 0.5;
        let [i, j, k] = [0, 1, 2].map(|a| (v[a].max(0.0) as usize).min(g.dims()[a] - 1));
        q[g.index(i, j, k)] += power / g.cell_volume();
    }
    q
}

impl Solver for ExplicitSolver {
    fn name(&self) -> &str {
        self.name
    }

    fn pages(&self) -> bool {
        !matches!(self.scheme, Scheme::Convection { .. }) || self.paged_convection().is_ok()
    }

    /// Half for the steady schemes and the marches: the other half holds the pool of their
    /// f64 state. All of it for the absorption march, whose planes are its only state.
    fn paged_medium_budget(&self, budget: u64) -> u64 {
        match self.scheme {
            Scheme::Convection { .. } => budget,
            _ => budget / 2,
        }
    }

    fn paged_memory(
        &self,
        problem: &PagedProblem,
        options: &SolveOptions,
    ) -> Result<u64, SolveError> {
        Ok(match self.paged_path(problem, options, false)? {
            PagedPath::Steady(kind) => {
                crate::paged_steady::steady_needs(self.name, kind, problem, options)?.3
            }
            PagedPath::March(march) => {
                crate::paged_march::march_needs(self.name, march, problem, options)?.3
            }
            PagedPath::Convection => crate::paged::convection_needs(self.name, problem, options)?.2,
        })
    }

    fn solve_paged(
        &self,
        problem: &PagedProblem,
        options: &SolveOptions,
    ) -> Result<PagedSolution, SolveError> {
        match self.paged_path(problem, options, true)? {
            PagedPath::Steady(kind) => {
                options.install(|| crate::paged_steady::solve(self.name, kind, problem, options))?
            }
            PagedPath::March(march) => {
                options.install(|| crate::paged_march::solve(self.name, march, problem, options))?
            }
            PagedPath::Convection => crate::paged::convection(self.name, problem, options),
        }
    }

    fn capabilities(&self) -> Capabilities {
        let diffusion = DiffusionSolver::custom(self.name).capabilities();
        match &self.scheme {
            // `ranks::iterate_on` splits the iteration over z-slabs or boxes.
            Scheme::Steady { .. } => Capabilities {
                ranks: true,
                ..diffusion
            },
            // `wavefront::propagate_on_ranks` splits the one-pass marches over z-slabs or
            // boxes.
            Scheme::Convection {
                scattering,
                settings,
                ..
            } => Capabilities {
                ranks: settings.sweep == crate::convection::Sweep::Ordered
                    && settings.model != Model::Conservative,
                anisotropic: *scattering == 0.0,
                heterogeneous: true,
                embedded_geometry: false,
                boundaries: vec![BoundaryKind::Vacuum],
                lights: vec![LightKind::Directional, LightKind::Point],
                output: OutputKind::Fluence,
                fluence: if *scattering == 0.0 {
                    FluenceKind::Uncollided
                } else {
                    FluenceKind::Total
                },
                cubic_cells_only: true,
                ..Capabilities::default()
            },
            Scheme::P1 { .. } | Scheme::Ordinates { .. } => Capabilities {
                // `ranks::march_p1_on` splits P1 over z-slabs or boxes.
                ranks: matches!(self.scheme, Scheme::P1 { .. }),
                anisotropic: matches!(self.scheme, Scheme::P1 { .. }),
                heterogeneous: matches!(self.scheme, Scheme::Ordinates { .. }),
                embedded_geometry: false,
                boundaries: vec![BoundaryKind::Vacuum],
                lights: vec![LightKind::Point, LightKind::Emission],
                output: OutputKind::Fluence,
                fluence: FluenceKind::Total,
                cubic_cells_only: true,
                point_lights_inside_grid: true,
                // P1 by FTCS has no stable step without absorption.
                needs_absorption: matches!(self.scheme, Scheme::P1 { .. }),
                ..Capabilities::default()
            },
        }
    }

    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
        match &self.scheme {
            Scheme::Steady {
                iteration,
                allow_unstable,
                ranks,
                decomposition,
            } => {
                if let SteadyKind::Ftcs { fraction } = iteration {
                    self.check_fraction(*fraction, *allow_unstable)?;
                }
                let world = options.ranks.as_ref().filter(|r| r.size() > 1);
                let on = ranks_of(world, *ranks)?;
                let volume = problem.geometry().cell_volume();
                let (iteration, allow_unstable, decomposition) =
                    (*iteration, *allow_unstable, *decomposition);
                let memory = self.memory_bytes(problem);
                // `steady` splits over the world itself.
                let diffusion = DiffusionSolver::custom(self.name).splitting();
                diffusion.solve_with(problem, options, memory, &|d, s, stop| {
                    let how = Steadily {
                        iteration,
                        allow_unstable,
                        decomposition,
                        volume,
                    };
                    steady(d, s, stop, how, on)
                })
            }
            Scheme::Convection {
                settings,
                scattering,
                ranks,
                decomposition,
            } => {
                let world = options.ranks.as_ref().filter(|r| r.size() > 1);
                let on = ranks_of(world, *ranks)?;
                driver::run(
                    self,
                    problem,
                    options,
                    self.memory_bytes(problem),
                    |context| self.convection(context, settings, (*scattering, *decomposition), on),
                )
            }
            Scheme::P1 { .. } | Scheme::Ordinates { .. } => {
                driver::solve_per_channel(self, self, problem, options).map(|(s, _)| s)
            }
        }
    }
}

/// Where a solve runs: on the world's ranks (under `mpirun`), on `ranks` in-process ranks,
/// or alone; both at once is refused.
fn ranks_of(world: Option<&lucent_core::Ranks>, ranks: usize) -> Result<RanksOf<'_>, SolveError> {
    Ok(match (world.filter(|w| w.size() > 1), ranks) {
        (Some(_), 2..) => {
            return Err(invalid(
                "ranks",
                "under mpirun the processes are the ranks: leave ranks at 1",
            ));
        }
        (Some(world), _) => RanksOf::Communicator(world.as_ref()),
        (None, 0 | 1) => RanksOf::Alone,
        (None, count) => RanksOf::Threads(count),
    })
}

/// What [`steady`] runs: the iteration, its step check, how ranks split the grid, and the
/// cell volume.
#[derive(Clone, Copy)]
struct Steadily {
    iteration: SteadyKind,
    allow_unstable: bool,
    decomposition: DecompositionParam,
    volume: f64,
}

/// FTCS or Jacobi to steady state on one channel's assembled diffusion system.
fn steady(
    d: &lucent_diffusion::DiffusionProblem,
    s: &lucent_diffusion::Sources,
    stop: &lucent_core::Stopping,
    how: Steadily,
    on: RanksOf<'_>,
) -> Result<DiffusionSolution, lucent_diffusion::DiffusionError> {
    let Steadily {
        iteration,
        allow_unstable,
        decomposition,
        volume,
    } = how;
    let t0 = Instant::now();
    let system = d.assemble(s)?;
    let kind = match iteration {
        SteadyKind::Ftcs { fraction } => Iteration::Ftcs {
            time_step: fraction * ftcs_limit(&system, volume),
            cell_volume: volume,
        },
        SteadyKind::Jacobi { omega } => Iteration::Jacobi { omega },
    };
    let setup = t0.elapsed().as_secs_f64();
    let settings = SteadySettings {
        stopping: stop.clone(),
        allow_unstable,
    };
    let dims = d.cells().geometry().dims();
    let ranks_error = |e: crate::ranks::DecompositionError| {
        lucent_diffusion::DiffusionError::Ranks(e.to_string())
    };
    let split = |ranks: usize| -> Result<Decomposition, lucent_diffusion::DiffusionError> {
        Ok(match decomposition {
            DecompositionParam::Slabs => Decomposition::Slabs,
            DecompositionParam::Boxes => {
                Decomposition::Boxes(Boxes::auto(dims, ranks).map_err(ranks_error)?)
            }
        })
    };
    let out = match on {
        RanksOf::Alone => iterate(&system, dims, kind, &settings)
            .map_err(|e| lucent_diffusion::DiffusionError::Invalid(e.to_string()))?,
        RanksOf::Communicator(comm) => {
            let decomposition = split(comm.size())?;
            iterate_on(&system, dims, &decomposition, kind, &settings, comm).map_err(ranks_error)?
        }
        RanksOf::Threads(count) => {
            let decomposition = split(count)?;
            iterate_on_threads(&system, dims, &decomposition, kind, &settings, count)
                .map_err(ranks_error)?
        }
    };
    let mut fluence = vec![0.0; d.cells().geometry().voxel_count()];
    for (&c, v) in system.cells.iter().zip(&out.fluence) {
        fluence[c] = *v;
    }
    let balance = d.balance(s, &fluence);
    Ok(DiffusionSolution {
        convergence: Convergence {
            residuals: out.residuals,
            stop_reason: out.stop_reason,
        },
        balance,
        setup_seconds: setup,
        solve_seconds: t0.elapsed().as_secs_f64() - setup,
        levels: 1,
        memory_bytes: (system.matrix.nnz() * 16 + fluence.len() * 32) as u64,
        fluence,
    })
}

impl ExplicitSolver {
    /// f64 working fields per cell: for the steady schemes the assembled system as it is
    /// built (triplets of 24 bytes and the CSR matrix of 16 bytes per non-zero, 7 per row,
    /// the diffusion problem's fields and 6 vectors: 600 bytes, against 590 measured by
    /// `tests/memory_estimates.rs`), two fields per light and four more for convection (and
    /// two per extra in-process rank), φ
    /// and E twice for P1, the radiance of every direction twice for ordinates.
    fn memory_bytes(&self, problem: &Problem) -> u64 {
        let n = problem.geometry().voxel_count() as u64;
        let per_cell = match &self.scheme {
            Scheme::Steady { .. } => 600,
            // In-process ranks hold a field and its gather each.
            Scheme::Convection { ranks, .. } => {
                8 * (6 + 2 * problem.lights().len() as u64 + 2 * (*ranks as u64).saturating_sub(1))
            }
            Scheme::P1 { .. } => 8 * 2 * 4 * 2,
            Scheme::Ordinates { order, .. } => 8 * 2 * (order * (order + 2)) as u64 + 32,
        };
        n * per_cell * problem.channels() as u64
    }

    /// Zhang & Ma: every light marched by convection–absorption per channel (one phase of
    /// the progress and the time budget per march), composed, then the implicit
    /// scattering step.
    fn convection(
        &self,
        context: &Context<'_>,
        settings: &UpwindSettings,
        (scattering, decomposition): (f64, DecompositionParam),
        on: RanksOf<'_>,
    ) -> Result<Outcome, SolveError> {
        let problem = context.problem;
        let l = lattice(problem)?;
        // Boxes per light: the grid that leaves an axis whole, the light's axis first
        // (`wavefront::march_boxes`: the sweep is then pipelined across every cut).
        let split =
            |ranks: usize, light: &crate::convection::Light| -> Result<Decomposition, SolveError> {
                if decomposition == DecompositionParam::Slabs {
                    return Ok(Decomposition::Slabs);
                }
                let boxes = match *light {
                    crate::convection::Light::Distant { direction, .. } => {
                        crate::wavefront::march_boxes(l.dims, ranks, direction, settings.model)
                    }
                    crate::convection::Light::Point { .. } => Boxes::auto(l.dims, ranks),
                };
                Ok(Decomposition::Boxes(
                    boxes.map_err(|e| self.decomposition_error(e))?,
                ))
            };
        let geometry = *problem.geometry();
        let mut record = Record::exact((l.len() * 8 * 4) as u64);
        let mut fluence = Vec::new();
        let marches = (problem.channels() * problem.lights().len()).max(1);
        for c in 0..problem.channels() {
            let sigma_t: Vec<f64> = problem
                .medium()
                .sigma_t(c)
                .data()
                .iter()
                .map(|&v| f64::from(v))
                .collect();
            let mut fields = Vec::new();
            for (i, light) in problem.lights().iter().enumerate() {
                let (light, colour) = match light {
                    Light::Directional {
                        direction,
                        irradiance,
                    } => (
                        crate::convection::Light::Distant {
                            direction: *direction,
                            density: 1.0,
                        },
                        irradiance.channel(c),
                    ),
                    Light::Point {
                        position,
                        intensity,
                    } => (
                        crate::convection::Light::Point {
                            position: *position,
                            density: 1.0,
                            falloff: None,
                        },
                        intensity.channel(c),
                    ),
                    other => return Err(invalid("lights", format!("{:?}", other.kind()))),
                };
                // The paper's per-step absorption is the opacity of one step cΔt = C h, so
                // its Courant number (given, or the light's bound where that is below ½)
                // comes first.
                let courant = settings.courant.unwrap_or_else(|| {
                    DEFAULT_COURANT.min(courant_bound(&l, &light, settings.model, &sigma_t))
                });
                let absorption: Vec<f64> = match settings.model {
                    Model::Conservative | Model::Characteristic => sigma_t.clone(),
                    Model::Paper => sigma_t
                        .iter()
                        .map(|s| 1.0 - (-s * courant * l.spacing).exp())
                        .collect(),
                };
                // The march's own tolerance; the caller's budget and progress.
                let phase = context.stopping_for(c * problem.lights().len() + i, marches);
                let settings = UpwindSettings {
                    courant: Some(courant),
                    stopping: lucent_core::Stopping {
                        time_budget: phase.time_budget,
                        deadline: phase.deadline,
                        progress: phase.progress,
                        cancel: phase.cancel,
                        ..settings.stopping.clone()
                    },
                    ..settings.clone()
                };
                let out = match on {
                    RanksOf::Alone => {
                        propagate(&l, &absorption, &light, &settings).map_err(explicit_error)?
                    }
                    RanksOf::Communicator(comm) => crate::wavefront::propagate_on_ranks(
                        &l,
                        &absorption,
                        &light,
                        &settings,
                        &split(comm.size(), &light)?,
                        comm,
                    )
                    .map_err(|e| self.decomposition_error(e))?,
                    RanksOf::Threads(count) => crate::wavefront::propagate_on_threads(
                        &l,
                        &absorption,
                        &light,
                        &settings,
                        &split(count, &light)?,
                        count,
                    )
                    .map_err(|e| self.decomposition_error(e))?,
                };
                context.report(lucent_core::Progress {
                    stage: "light march",
                    fraction: (c * problem.lights().len() + i + 1) as f64 / marches as f64,
                    iteration: out.iterations,
                    residual: out.residuals.last().copied(),
                });
                let mut march = Record::from_residuals(Vec::new(), out.stop_reason.clone(), 0);
                march.iterations = out.iterations;
                record = record.worse(march);
                // Each light's field is stored in f32, as every field in lucent (and as the
                // out-of-core march stores it), before the lights are composed in f64.
                let stored: Vec<f64> = out.density.iter().map(|&v| f64::from(v as f32)).collect();
                fields.push((stored, vec![colour]));
            }
            let mut total = compose(&fields)
                .map_err(explicit_error)?
                .pop()
                .unwrap_or_else(|| vec![0.0; l.len()]);
            if scattering > 0.0 {
                let out = crate::scatter::diffuse(
                    &l,
                    &total,
                    scattering,
                    1.0,
                    1,
                    crate::scatter::StepSolver::Multigrid { tolerance: 1e-8 },
                )
                .map_err(explicit_error)?;
                total = out.field;
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
}

impl ExplicitSolver {
    /// A decomposed march's error: the scheme's own as the serial march gives it, a march
    /// that cannot split as unsupported, the rest (ranks against layers, a broken
    /// protocol) as the `ranks` asked for.
    fn decomposition_error(&self, e: crate::ranks::DecompositionError) -> SolveError {
        use crate::ranks::DecompositionError as E;
        match e {
            E::Scheme(e) => explicit_error(e),
            E::Unsupported(feature) => SolveError::Unsupported {
                solver: self.name.into(),
                feature,
            },
            other => invalid("ranks", other.to_string()),
        }
    }

    /// FTCS's step as a fraction of its bound: at most 1 unless `allow_unstable`.
    fn check_fraction(&self, fraction: f64, allow_unstable: bool) -> Result<(), SolveError> {
        if fraction > 1.0 && !allow_unstable {
            // The bound is computed per system; as a fraction of it, 1.
            return Err(SolveError::Unstable {
                solver: self.name.into(),
                parameter: "step_fraction (of the FTCS bound)".into(),
                limit: 1.0,
                requested: fraction,
            });
        }
        Ok(())
    }

    /// `Ok` where this entry runs out of core: `convection-diffusion` with the
    /// characteristic model, ordered sweeps and no scattering step (the one-pass
    /// absorption march, plane by plane); else why not.
    fn paged_convection(&self) -> Result<(), SolveError> {
        let unsupported = |feature: &str| SolveError::Unsupported {
            solver: self.name.into(),
            feature: feature.into(),
        };
        match &self.scheme {
            Scheme::Convection {
                settings,
                scattering,
                ..
            } => {
                if settings.model != Model::Characteristic {
                    Err(unsupported(
                        "a paged medium with the upwind models (only `model = \"characteristic\"` marches plane by plane)",
                    ))
                } else if settings.sweep != crate::convection::Sweep::Ordered {
                    Err(unsupported(
                        "a paged medium with layer or Jacobi sweeps (only ordered sweeps march plane by plane)",
                    ))
                } else if *scattering > 0.0 {
                    Err(unsupported(
                        "a paged medium with a scattering step (its implicit solve needs the field in memory)",
                    ))
                } else {
                    Ok(())
                }
            }
            _ => Err(unsupported(
                "a paged (out-of-core) medium: it needs its fields in memory",
            )),
        }
    }
}

/// P1 and ordinates march each channel with the lights they take themselves.
impl ChannelMethod for ExplicitSolver {
    /// The lattice, and the ranks of `SolveOptions::ranks` when there are several.
    type Setup = (Lattice, Option<lucent_core::Ranks>);
    type Extra = ();

    fn stage(&self) -> &'static str {
        match self.scheme {
            Scheme::Steady {
                iteration: SteadyKind::Jacobi { .. },
                ..
            } => "Jacobi sweep",
            Scheme::Convection { .. } => "light march",
            _ => "time step",
        }
    }

    fn memory_bytes(&self, problem: &Problem) -> u64 {
        ExplicitSolver::memory_bytes(self, problem)
    }

    fn setup(&self, context: &Context<'_>) -> Result<Self::Setup, SolveError> {
        let world = context.options.ranks.clone().filter(|r| r.size() > 1);
        Ok((lattice(context.problem)?, world))
    }

    fn route(&self, _: &Self::Setup, _: &Problem, _: &Light) -> Route {
        Route::Own
    }

    fn solve_channel(
        &self,
        (l, world): &Self::Setup,
        channel: Channel<'_>,
    ) -> Result<ChannelSolution<()>, SolveError> {
        let q = point_and_emission(&channel);
        let (fluence, record) = match &self.scheme {
            Scheme::P1 {
                layout,
                fraction,
                allow_unstable,
                ranks,
                decomposition,
            } => {
                let on = ranks_of(world.as_ref(), *ranks)?;
                let how = (*layout, *fraction, *allow_unstable, *decomposition);
                p1(l, &channel, &q, how, on)?
            }
            Scheme::Ordinates {
                order,
                fraction,
                allow_unstable,
            } => ordinates(l, &channel, &q, *order, *fraction, *allow_unstable)?,
            _ => return Err(invalid("scheme", "not a per-channel march")),
        };
        Ok(ChannelSolution {
            fluence: fluence.iter().map(|&v| v as f32).collect(),
            record,
            extra: (),
        })
    }
}

/// Murray's P1 system by FTCS on one channel of a homogeneous medium, at `fraction` of
/// the largest stable step.
fn p1(
    l: &Lattice,
    channel: &Channel<'_>,
    q: &[f64],
    (layout, fraction, allow_unstable, decomposition): (
        crate::p1::Layout,
        f64,
        bool,
        DecompositionParam,
    ),
    on: RanksOf<'_>,
) -> Result<(Vec<f64>, Record), SolveError> {
    let g = channel.problem.medium().phase.mean_cosine();
    // Homogeneous (the capabilities ask for it): any cell's coefficients.
    let coefficients = &channel.coefficients;
    let settings = p1_settings(
        [coefficients.sigma_t[0], coefficients.sigma_s[0]],
        g,
        l.spacing,
        (layout, fraction, allow_unstable),
        channel.stopping.clone(),
    )?;
    let ranks_error = |e: crate::ranks::DecompositionError| invalid("ranks", e.to_string());
    let split = |ranks: usize| -> Result<Decomposition, SolveError> {
        Ok(match decomposition {
            DecompositionParam::Slabs => Decomposition::Slabs,
            DecompositionParam::Boxes => {
                Decomposition::Boxes(Boxes::auto(l.dims, ranks).map_err(ranks_error)?)
            }
        })
    };
    let out = match on {
        RanksOf::Alone => crate::p1::march(l, q, &settings, None).map_err(explicit_error)?,
        RanksOf::Communicator(comm) => {
            let decomposition = split(comm.size())?;
            crate::ranks::march_p1_on(l, q, &decomposition, &settings, comm).map_err(ranks_error)?
        }
        RanksOf::Threads(count) => {
            let decomposition = split(count)?;
            crate::ranks::march_p1_on_threads(l, q, &decomposition, &settings, count)
                .map_err(ranks_error)?
        }
    };
    let mut record = Record::exact((l.len() * 8 * 8) as u64);
    record.iterations = out.steps;
    record.stop_reason = out.stop_reason;
    // The history: every step's relative change of φ, as the paged march records it.
    record.residuals = out.changes;
    Ok((out.fluence, record))
}

/// The registry's P1 march on a homogeneous medium of σ_t and σ_s (as stored) with phase
/// mean cosine `g`: consistent damping, zero edges, `fraction` of the largest stable step
/// of the layout; refused without absorption (no stable step).
pub(crate) fn p1_settings(
    [sigma_t, sigma_s]: [f32; 2],
    g: f64,
    spacing: f64,
    (layout, fraction, allow_unstable): (crate::p1::Layout, f64, bool),
    stopping: lucent_core::Stopping,
) -> Result<crate::p1::P1Settings, SolveError> {
    let (sigma_t, sigma_s) = (f64::from(sigma_t), f64::from(sigma_s));
    let (sigma_a, reduced) = (sigma_t - sigma_s, sigma_t - g * sigma_s);
    let lo = crate::stability::p1::largest_step(
        layout == crate::p1::Layout::Staggered,
        sigma_a,
        reduced,
        spacing,
    );
    if lo <= 0.0 {
        return Err(invalid(
            "medium",
            "P1 FTCS has no stable step without absorption",
        ));
    }
    Ok(crate::p1::P1Settings {
        layout,
        damping: crate::p1::Damping::Consistent {
            sigma_a,
            sigma_t_reduced: reduced,
        },
        time_step: fraction * lo,
        stopping,
        edges: crate::p1::P1Edges::Zero,
        allow_unstable,
    })
}

/// The registry's ordinates march: the level-symmetric set of `order` and `fraction` of
/// the positivity bound for the largest σ_t `sigma_t_max`.
pub(crate) fn ordinates_settings(
    order: usize,
    sigma_t_max: f64,
    spacing: f64,
    (fraction, allow_unstable): (f64, bool),
    stopping: lucent_core::Stopping,
) -> Result<
    (
        lucent_optics::SphericalQuadrature,
        crate::ordinates::OrdinatesSettings,
    ),
    SolveError,
> {
    let quadrature = lucent_optics::SphericalQuadrature::level_symmetric(order)
        .map_err(|e| invalid("order", e.to_string()))?;
    let s_max = quadrature
        .directions()
        .iter()
        .map(|d| d.abs().element_sum())
        .fold(0.0, f64::max);
    let step = crate::stability::ordinates::largest_step(s_max, sigma_t_max, spacing);
    let settings = crate::ordinates::OrdinatesSettings {
        time_step: fraction * step,
        stopping,
        allow_unstable,
    };
    Ok((quadrature, settings))
}

/// Upwind FTCS ordinates on one channel at `fraction` of the positivity bound.
fn ordinates(
    l: &Lattice,
    channel: &Channel<'_>,
    q: &[f64],
    order: usize,
    fraction: f64,
    allow_unstable: bool,
) -> Result<(Vec<f64>, Record), SolveError> {
    let widen = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<f64>>();
    let sigma_t = widen(&channel.coefficients.sigma_t);
    let sigma_s = widen(&channel.coefficients.sigma_s);
    let k_max = sigma_t.iter().fold(0.0f64, |a, &b| a.max(b));
    let (quadrature, settings) = ordinates_settings(
        order,
        k_max,
        l.spacing,
        (fraction, allow_unstable),
        channel.stopping.clone(),
    )?;
    let out = crate::ordinates::march(l, &quadrature, &sigma_t, &sigma_s, q, &settings)
        .map_err(explicit_error)?;
    let record = Record {
        iterations: out.steps,
        residuals: out.residuals,
        stop_reason: out.stop_reason,
        memory_bytes: (l.len() * quadrature.len() * 16) as u64,
        paging: None,
    };
    Ok((out.fluence, record))
}
