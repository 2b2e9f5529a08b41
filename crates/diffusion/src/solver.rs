//! The registry's diffusion solvers: `diffusion-mg` and, on the same operator, the baselines
//! `diffusion-cg`, `diffusion-mgcg`, `diffusion-sor` and `diffusion-jacobi`.
//!
//! They run through `lucent_core::driver` as a per-channel method: the driver supplies
//! each channel's σ_s, σ_a and D = 1/(3σ_t′) (with its floor, `driver::Coefficients`), the
//! point lights and emission, and the other lights' uncollided light; this maps them to
//! the discrete problem. The medium is the embedded SDF's inside when there is one, else
//! the whole box.
//!
//! Sources:
//! - point lights inside the medium are diffusion point sources of power 4πI (the Green's
//!   function T7 is built on);
//! - emission lights are a volumetric Q₀ = 4π L_e;
//! - every other light (directional, spot, sky, point lights outside) enters as the
//!   reduced-intensity source: the uncollided fluence φ_u of `direct` (straight lines
//!   through the medium only, no refraction or Fresnel loss at entry, as in Mertens'
//!   pipeline) scatters into Q₀ = σ_s φ_u and Q₁ = g σ_s Σ_l φ_u,l ω_l. The solution's
//!   fluence is φ_u + φ_d, and its angular part keeps the per-light transmittance so the
//!   renderer phase-weights single scattering.
//!
//! Boundaries: Robin (A = `Boundary::robin_factor`, the transport-exact extrapolation
//! length of the Milne problem), Vacuum (Robin at η = 1: A = 1.0657), Dirichlet,
//! Neumann; the same on the embedded surface and the box.

use lucent_core::driver::{
    self, Channel, ChannelMethod, ChannelSolution, Coefficients, Context, Record,
};
use lucent_core::{
    Angular, Boundary, BoundaryKind, Capabilities, FluenceKind, LightKind, OutputKind, Problem,
    Solution, SolveError, SolveOptions, Solver, SolverEntry, Uncollided,
    point_source_singular_part,
};
use lucent_core::{param_docs, resolved_params};

use crate::params::{CgParams, DecompositionParam, JacobiParams, MultigridParams, SorParams};
use crate::ranks::Decomposition;
use lucent_grid::Grid;

use crate::geometry::{CellGeometry, Discretisation};
use crate::multigrid::{Cycle, MultigridSettings, Smoother};
use crate::problem::{Boundaries, Condition, DiffusionProblem, Sources};
use crate::solve::{Method, RanksOf, solve, solve_on_ranks};
use lucent_core::Stopping;

/// A diffusion solver as the registry builds it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiffusionSolver {
    name: &'static str,
    method: Method,
    discretisation: Discretisation,
    /// In-process ranks (`diffusion-mg`'s `ranks`).
    ranks: usize,
    /// How the ranks cut the grid (`diffusion-mg`'s `decomposition`).
    decomposition: Decomposition,
    /// Whether it splits over ranks (`diffusion-mg` only: its linear solve is
    /// `Multigrid::solve_on_ranks`; [`DiffusionSolver::custom`]'s are the caller's).
    splits: bool,
}

fn invalid(name: &str, reason: impl Into<String>) -> SolveError {
    SolveError::InvalidParameter {
        name: name.into(),
        reason: reason.into(),
    }
}

impl DiffusionSolver {
    /// `diffusion-mg`: multigrid cycles ([`MultigridParams`]).
    pub const MULTIGRID: SolverEntry = SolverEntry {
        name: "diffusion-mg",
        summary: "steady diffusion, embedded-boundary finite volumes, geometric multigrid (Mertens ch. 4)",
        build: |p| {
            let p: MultigridParams = p.parse("diffusion-mg")?;
            Ok(Box::new(DiffusionSolver {
                name: "diffusion-mg",
                method: Method::Multigrid(p.settings()),
                discretisation: p.discretisation.into(),
                ranks: p.ranks,
                decomposition: p.decomposition.decomposition(),
                splits: true,
            }))
        },
        params: param_docs::<MultigridParams>,
        resolved: |p| resolved_params::<MultigridParams>(p, "diffusion-mg"),
    };

    /// `diffusion-mgcg`: CG preconditioned by one multigrid cycle (same parameters).
    pub const MULTIGRID_CG: SolverEntry = SolverEntry {
        name: "diffusion-mgcg",
        summary: "steady diffusion, multigrid-preconditioned conjugate gradients",
        build: |p| {
            let p: MultigridParams = p.parse("diffusion-mgcg")?;
            if p.ranks != 1 {
                return Err(invalid(
                    "ranks",
                    "diffusion-mgcg runs in one process (diffusion-mg splits over ranks)",
                ));
            }
            if p.decomposition != DecompositionParam::Slabs {
                return Err(invalid(
                    "decomposition",
                    "diffusion-mgcg runs in one process (diffusion-mg splits over ranks)",
                ));
            }
            let mut settings = p.settings();
            settings.full_multigrid = false;
            Ok(Box::new(DiffusionSolver {
                name: "diffusion-mgcg",
                method: Method::MultigridCg(settings),
                discretisation: p.discretisation.into(),
                ranks: 1,
                decomposition: Decomposition::Slabs,
                splits: false,
            }))
        },
        params: param_docs::<MultigridParams>,
        resolved: |p| resolved_params::<MultigridParams>(p, "diffusion-mgcg"),
    };

    /// `diffusion-cg`: Jacobi-preconditioned CG ([`CgParams`]).
    pub const CONJUGATE_GRADIENT: SolverEntry = SolverEntry {
        name: "diffusion-cg",
        summary: "steady diffusion, Jacobi-preconditioned conjugate gradients (baseline)",
        build: |p| {
            let p: CgParams = p.parse("diffusion-cg")?;
            Ok(Box::new(DiffusionSolver {
                name: "diffusion-cg",
                method: Method::ConjugateGradient,
                discretisation: p.discretisation.into(),
                ranks: 1,
                decomposition: Decomposition::Slabs,
                splits: false,
            }))
        },
        params: param_docs::<CgParams>,
        resolved: |p| resolved_params::<CgParams>(p, "diffusion-cg"),
    };

    /// `diffusion-sor`: red–black SOR ([`SorParams`]).
    pub const SOR: SolverEntry = SolverEntry {
        name: "diffusion-sor",
        summary: "steady diffusion, red-black successive over-relaxation (baseline)",
        build: |p| {
            let p: SorParams = p.parse("diffusion-sor")?;
            Ok(Box::new(DiffusionSolver {
                name: "diffusion-sor",
                method: Method::Sor { omega: p.omega },
                discretisation: p.discretisation.into(),
                ranks: 1,
                decomposition: Decomposition::Slabs,
                splits: false,
            }))
        },
        params: param_docs::<SorParams>,
        resolved: |p| resolved_params::<SorParams>(p, "diffusion-sor"),
    };

    /// `diffusion-jacobi`: Jacobi iteration ([`JacobiParams`]).
    pub const JACOBI: SolverEntry = SolverEntry {
        name: "diffusion-jacobi",
        summary: "steady diffusion, Jacobi iteration (baseline)",
        build: |p| {
            let p: JacobiParams = p.parse("diffusion-jacobi")?;
            Ok(Box::new(DiffusionSolver {
                name: "diffusion-jacobi",
                method: Method::Jacobi { omega: p.omega },
                discretisation: p.discretisation.into(),
                ranks: 1,
                decomposition: Decomposition::Slabs,
                splits: false,
            }))
        },
        params: param_docs::<JacobiParams>,
        resolved: |p| resolved_params::<JacobiParams>(p, "diffusion-jacobi"),
    };

    /// Every entry.
    pub const ENTRIES: [SolverEntry; 5] = [
        Self::MULTIGRID,
        Self::MULTIGRID_CG,
        Self::CONJUGATE_GRADIENT,
        Self::SOR,
        Self::JACOBI,
    ];
}

/// The discrete conditions of a problem's boundary on every face (and the embedded
/// surface): Robin with `Boundary::robin_factor` for vacuum and Robin, Dirichlet and
/// Neumann as given.
pub fn conditions(boundary: Boundary) -> Boundaries {
    Boundaries::uniform(match boundary {
        Boundary::Vacuum | Boundary::Robin { .. } => Condition::Robin {
            a: boundary.robin_factor().unwrap_or(1.0),
        },
        Boundary::Dirichlet { value } => Condition::Dirichlet { value },
        Boundary::Neumann { flux } => Condition::Neumann { flux },
    })
}

impl Solver for DiffusionSolver {
    fn name(&self) -> &str {
        self.name
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            anisotropic: true,
            heterogeneous: true,
            embedded_geometry: true,
            boundaries: vec![
                BoundaryKind::Vacuum,
                BoundaryKind::Robin,
                BoundaryKind::Dirichlet,
                BoundaryKind::Neumann,
            ],
            lights: vec![
                LightKind::Directional,
                LightKind::Point,
                LightKind::Spot,
                LightKind::Sky,
                LightKind::Emission,
            ],
            output: OutputKind::AngularRadiance,
            fluence: FluenceKind::Total,
            // Lights outside enter as first-collision sources along curved rays
            // (`Uncollided::curved`); the scattered light diffuses as in a uniform index.
            graded_index: true,
            // The multigrid splits over z-slabs or boxes (`Multigrid::solve_on_layout`).
            ranks: self.splits,
            ..Capabilities::default()
        }
    }

    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
        let method = self.method;
        let world = options.ranks.as_ref().filter(|r| r.size() > 1);
        if world.is_some() && self.ranks > 1 {
            return Err(invalid(
                "ranks",
                "under mpirun the processes are the ranks: leave ranks at 1",
            ));
        }
        // Per cell and channel: the hierarchy's f32 fields (14, with the coarse levels'
        // 1/7) and f64 vectors (4), and the cut-cell geometry (volume and aperture
        // fractions, 24 bytes). Measured (`tests/memory_estimates.rs`): 162 bytes per cell
        // in all with the driver's share.
        let cells = problem.geometry().voxel_count() as u64;
        // In-process ranks share the hierarchy; between them they hold each cell once in
        // their boxes (the operator and work vectors, 61 bytes per cell) and each keeps the
        // whole φ it returns (`solve_on_ranks`).
        let split = if self.ranks > 1 {
            cells * 61 + (self.ranks as u64 - 1) * cells * 8
        } else {
            0
        };
        let memory = (cells * (4 * 14 + 8 * 4 + 24) + split) * problem.channels() as u64;
        let decomposition = self.decomposition;
        let ranks = match (world, self.ranks) {
            (Some(world), _) => RanksOf::Communicator(world.as_ref()),
            (None, 1) => RanksOf::Alone,
            (None, count) => RanksOf::Threads(count),
        };
        self.solve_with(
            problem,
            options,
            memory,
            &|diffusion, sources, stopping| match (method, ranks) {
                (_, RanksOf::Alone) => solve(diffusion, sources, method, stopping),
                (Method::Multigrid(settings), ranks) => {
                    solve_on_ranks(diffusion, sources, settings, stopping, ranks, decomposition)
                }
                _ => solve(diffusion, sources, method, stopping),
            },
        )
    }
}

/// A linear solve of one channel's discrete problem: what [`DiffusionSolver::solve_with`]
/// plugs in.
pub type LinearSolve<'a> = dyn Fn(
        &DiffusionProblem,
        &Sources,
        &Stopping,
    ) -> Result<crate::DiffusionSolution, crate::DiffusionError>
    + Sync
    + 'a;

impl DiffusionSolver {
    /// A solver named `name` that maps problems as the diffusion solvers do (embedded
    /// boundary) and leaves the linear solve to [`DiffusionSolver::solve_with`]: for other
    /// crates' iterations on the same discrete problem (`lucent-explicit`'s FTCS and Jacobi).
    pub const fn custom(name: &'static str) -> Self {
        Self {
            name,
            method: Method::Multigrid(MultigridSettings {
                cycle: Cycle::V,
                smoother: Smoother::RedBlackGaussSeidel,
                pre_sweeps: 2,
                post_sweeps: 2,
                full_multigrid: true,
                prolongation: crate::multigrid::Prolongation::Constant,
            }),
            discretisation: Discretisation::EmbeddedBoundary,
            ranks: 1,
            decomposition: Decomposition::Slabs,
            splits: false,
        }
    }

    /// This solver with its linear solve declared to split over `SolveOptions::ranks`
    /// itself (the caller's `linear` reads them): [`Capabilities::ranks`] is set.
    pub const fn splitting(self) -> Self {
        Self {
            splits: true,
            ..self
        }
    }

    /// Solves `problem` as [`Solver::solve`] does, with `linear` solving each channel's
    /// discrete problem A φ = b (sources mapped, reduced-intensity source included) in at
    /// most `memory_bytes` for the whole solve.
    pub fn solve_with(
        &self,
        problem: &Problem,
        options: &SolveOptions,
        memory_bytes: u64,
        linear: &LinearSolve<'_>,
    ) -> Result<Solution, SolveError> {
        let method = Channels {
            stage: match self.name() {
                "diffusion-mg" | "gpu-diffusion-mg" => "V-cycle",
                "diffusion-mgcg" | "diffusion-cg" => "CG iteration",
                "diffusion-sor" => "SOR sweep",
                name if name.contains("ftcs") => "time step",
                _ => "Jacobi sweep",
            },
            discretisation: self.discretisation,
            memory_bytes,
            linear,
        };
        driver::solve_per_channel(self, &method, problem, options).map(|(s, _)| s)
    }
}

/// The per-channel method behind every diffusion solver: the driver hands it each
/// channel's coefficients, its point lights and emission, and the other lights' uncollided
/// light; it maps them to a [`DiffusionProblem`] and its [`Sources`] and calls `linear`.
struct Channels<'a, 'b> {
    stage: &'static str,
    discretisation: Discretisation,
    memory_bytes: u64,
    linear: &'a LinearSolve<'b>,
}

impl ChannelMethod for Channels<'_, '_> {
    type Setup = CellGeometry;

    fn stage(&self) -> &'static str {
        self.stage
    }

    /// The scattered fluence (without the singular parts and the uncollided light): what
    /// in-scatters isotropically in the renderer.
    type Extra = Grid;

    fn memory_bytes(&self, _: &Problem) -> u64 {
        self.memory_bytes
    }

    fn setup(&self, context: &Context<'_>) -> Result<CellGeometry, SolveError> {
        let geometry = *context.problem.geometry();
        match context.problem.embedded() {
            Some(sdf) => CellGeometry::from_sdf(
                geometry,
                |p| f64::from(sdf.sample_trilinear(p)),
                self.discretisation,
            )
            .map_err(|e| invalid("embedded", e.to_string())),
            None => Ok(CellGeometry::full_box(geometry)),
        }
    }

    fn solve_channel(
        &self,
        cells: &CellGeometry,
        channel: Channel<'_>,
    ) -> Result<ChannelSolution<Grid>, SolveError> {
        let problem = channel.problem;
        let geometry = *problem.geometry();
        let n = geometry.voxel_count();
        let Coefficients {
            sigma_a,
            diffusion: d,
            ..
        } = &channel.coefficients;
        let boundaries = conditions(problem.boundary());
        let diffusion =
            DiffusionProblem::new(cells.clone(), d.clone(), sigma_a.clone(), boundaries)
                .map_err(|e| invalid("problem", e.to_string()))?;
        let mut sources = Sources::default();
        // Emission and the other lights' first collisions.
        let (q0, first_moment) = channel.diffusion_sources();
        let mut q0: Vec<f32> = q0.iter().map(|&q| q as f32).collect();
        sources.first_moment = first_moment;
        // Point sources: their singular part G̃ analytically where the medium around them
        // allows (the remainder's smooth source goes into q0), else as points.
        let mut singular = vec![0.0f32; n];
        let whole = |cell: usize| cells.volume_fraction()[cell] >= 1.0;
        for (position, power) in channel.point_sources() {
            match point_source_singular_part(&geometry, d, sigma_a, whole, position, power) {
                Some(part) => {
                    for (q, f) in q0.iter_mut().zip(&part.source) {
                        *q += f;
                    }
                    for (g, p) in singular.iter_mut().zip(&part.fluence) {
                        *g += p;
                    }
                }
                None => sources.points.push((position, power)),
            }
        }
        sources.volumetric = q0;
        let solution = (self.linear)(&diffusion, &sources, &channel.stopping)
            .map_err(|e| invalid("problem", e.to_string()))?;
        let scattered: Vec<f32> = solution.fluence.iter().map(|&v| v as f32).collect();
        let fluence = scattered
            .iter()
            .zip(&singular)
            .map(|(s, g)| s + g)
            .collect();
        let conv = solution.convergence;
        Ok(ChannelSolution {
            fluence,
            record: Record::from_residuals(conv.residuals, conv.stop_reason, solution.memory_bytes),
            extra: Grid::from_vec(geometry, scattered)?,
        })
    }

    /// `direct`'s per-light transmittance for exact single scattering, with the scattered
    /// fluence (plus the sky's uncollided fluence) in-scattering isotropically.
    fn angular(
        &self,
        _: &CellGeometry,
        _: &Problem,
        scattered: &mut [Grid],
        uncollided: Option<Uncollided>,
    ) -> Result<Option<Angular>, SolveError> {
        Ok(uncollided.and_then(|u| u.into_angular(scattered)))
    }
}
