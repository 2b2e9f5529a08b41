//! The `Solver` trait, what a solver can do, how it is asked, and how it reports.

use std::fmt;
use std::sync::Arc;
use std::time::Duration;

use serde::Serialize;

use crate::error::SolveError;
use crate::problem::{BoundaryKind, LightKind, Problem};
use crate::solution::Solution;

/// What a solver's solution contains.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum OutputKind {
    /// The fluence φ only: the renderer in-scatters σ_s φ/(4π).
    #[default]
    Fluence,
    /// Fluence and an angular representation: the renderer in-scatters phase-weighted.
    AngularRadiance,
}

/// What problems a solver handles. [`Capabilities::check`] turns a mismatch into a clear
/// [`SolveError::Unsupported`]; together with a solver's own [`Solver::admits`] it is every
/// refusal the solver makes, so `lucent info` can say "can solve" exactly when a solve
/// will run.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Capabilities {
    /// Handles a non-isotropic phase function.
    pub anisotropic: bool,
    /// Handles spatially varying coefficients (extinction and albedo).
    pub heterogeneous: bool,
    /// Needs cubic cells (equal spacing on the three axes).
    pub cubic_cells_only: bool,
    /// Takes a Neumann boundary only with zero flux (a reflecting box).
    pub reflecting_neumann_only: bool,
    /// Needs point lights inside the grid's box.
    pub point_lights_inside_grid: bool,
    /// Takes a Robin boundary only on an embedded surface (its interface).
    pub robin_needs_embedded_surface: bool,
    /// Needs absorption somewhere (σ_a > 0) to have a stable or finite solution.
    pub needs_absorption: bool,
    /// Handles an embedded boundary (SDF).
    pub embedded_geometry: bool,
    /// Traces curved rays through a graded refractive index ([`Problem::has_graded_index`]).
    pub graded_index: bool,
    /// Boundary conditions it implements.
    pub boundaries: Vec<BoundaryKind>,
    /// Lights it implements.
    pub lights: Vec<LightKind>,
    /// What its solution holds.
    pub output: OutputKind,
    /// Which light its fluence counts.
    pub fluence: FluenceKind,
    /// Splits its solve over [`SolveOptions::ranks`] (z-slabs over processes); solvers
    /// without it refuse more than one rank.
    pub ranks: bool,
}

/// Which part of the light a solver's fluence counts: what it must be compared with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FluenceKind {
    /// Only light that has not yet scattered (`direct`).
    Uncollided,
    /// All light, every order of scattering.
    #[default]
    Total,
}

impl Capabilities {
    /// `Ok` if `solver` (with these capabilities) can solve `problem`.
    pub fn check(&self, solver: &str, problem: &Problem) -> Result<(), SolveError> {
        let unsupported = |feature: String| {
            Err(SolveError::Unsupported {
                solver: solver.to_owned(),
                feature,
            })
        };
        let boundary = problem.boundary().kind();
        if !self.boundaries.contains(&boundary) {
            return unsupported(format!(
                "a {boundary:?} boundary (it handles {:?})",
                self.boundaries
            ));
        }
        if let Some(light) = problem
            .lights()
            .iter()
            .find(|l| !self.lights.contains(&l.kind()))
        {
            return unsupported(format!(
                "{:?} lights (it handles {:?})",
                light.kind(),
                self.lights
            ));
        }
        if !self.embedded_geometry && problem.embedded().is_some() {
            return unsupported("embedded geometry".into());
        }
        if !self.graded_index && problem.has_graded_index() {
            return unsupported(
                "a graded refractive index (curved rays: `direct-refractive` traces them)".into(),
            );
        }
        let phase = problem.medium().phase;
        if !self.anisotropic && !matches!(phase, lucent_optics::Phase::Isotropic) {
            return unsupported(format!("an anisotropic phase function ({phase:?})"));
        }
        let medium = problem.medium();
        if !self.heterogeneous {
            let constant = |g: &lucent_grid::Grid| g.data().windows(2).all(|w| w[0] == w[1]);
            if !medium.sigma_t.iter().all(constant) {
                return unsupported("a heterogeneous medium".into());
            }
            let uniform = |f: &crate::problem::Field| match f {
                crate::problem::Field::Constant(_) => true,
                crate::problem::Field::Grid(g) => constant(g),
            };
            if !medium.albedo.iter().all(uniform) {
                return unsupported("a heterogeneous albedo".into());
            }
        }
        let h = problem.geometry().spacing();
        if self.cubic_cells_only
            && ((h.x - h.y).abs() > 1e-9 * h.x || (h.x - h.z).abs() > 1e-9 * h.x)
        {
            return unsupported(format!("non-cubic cells ({} × {} × {})", h.x, h.y, h.z));
        }
        if let crate::problem::Boundary::Neumann { flux } = problem.boundary()
            && self.reflecting_neumann_only
            && flux != 0.0
        {
            return unsupported(format!(
                "a Neumann boundary with flux {flux} (only a reflecting box, flux 0)"
            ));
        }
        if self.robin_needs_embedded_surface
            && matches!(problem.boundary(), crate::problem::Boundary::Robin { .. })
            && problem.embedded().is_none()
        {
            return unsupported(
                "a Robin boundary without embedded geometry (its interface is the embedded surface)"
                    .into(),
            );
        }
        if self.point_lights_inside_grid {
            let (lo, hi) = problem.geometry().bounds();
            for light in problem.lights() {
                if let crate::problem::Light::Point { position, .. }
                | crate::problem::Light::Spot { position, .. } = light
                    && !(position.cmpge(lo).all() && position.cmplt(hi).all())
                {
                    return unsupported(format!("a point light outside the grid (at {position})"));
                }
            }
        }
        if self.needs_absorption {
            let absorbs = (0..problem.channels()).all(|c| {
                let sigma_t = medium.sigma_t(c);
                let g = *sigma_t.geometry();
                sigma_t.data().iter().enumerate().any(|(i, &t)| {
                    let [a, b, d] = g.coords(i);
                    let x = g.cell_centre(a, b, d);
                    f64::from(t) > f64::from(medium.sigma_s_at(c, x)) * (1.0 + 1e-6)
                })
            });
            if !absorbs {
                return unsupported("a medium without absorption".into());
            }
        }
        Ok(())
    }
}

impl Capabilities {
    /// [`Capabilities::check_paged`] without what only the medium's values can say
    /// (whether it absorbs): for a [`crate::PagedProblem::shell`], whose medium is zero.
    pub fn check_paged_shape(
        &self,
        solver: &str,
        problem: &crate::PagedProblem,
    ) -> Result<(), SolveError> {
        Capabilities {
            needs_absorption: false,
            ..self.clone()
        }
        .check_paged(solver, problem)
    }

    /// [`Capabilities::check`] for a paged problem (which has no embedded geometry and no
    /// emission): the same verdicts, uniformity taken from the fields' brick ranges and the
    /// absorption test made slab by slab.
    pub fn check_paged(
        &self,
        solver: &str,
        problem: &crate::PagedProblem,
    ) -> Result<(), SolveError> {
        let unsupported = |feature: String| {
            Err(SolveError::Unsupported {
                solver: solver.to_owned(),
                feature,
            })
        };
        let boundary = problem.boundary().kind();
        if !self.boundaries.contains(&boundary) {
            return unsupported(format!(
                "a {boundary:?} boundary (it handles {:?})",
                self.boundaries
            ));
        }
        if let Some(light) = problem
            .lights()
            .iter()
            .find(|l| !self.lights.contains(&l.kind()))
        {
            return unsupported(format!(
                "{:?} lights (it handles {:?})",
                light.kind(),
                self.lights
            ));
        }
        let medium = problem.medium();
        let phase = medium.phase;
        if !self.anisotropic && !matches!(phase, lucent_optics::Phase::Isotropic) {
            return unsupported(format!("an anisotropic phase function ({phase:?})"));
        }
        if !self.heterogeneous {
            if !medium.sigma_t.iter().all(|f| f.uniform_value().is_some()) {
                return unsupported("a heterogeneous medium".into());
            }
            if !medium.albedo.iter().all(|f| f.uniform_value().is_some()) {
                return unsupported("a heterogeneous albedo".into());
            }
        }
        let h = problem.geometry().spacing();
        if self.cubic_cells_only
            && ((h.x - h.y).abs() > 1e-9 * h.x || (h.x - h.z).abs() > 1e-9 * h.x)
        {
            return unsupported(format!("non-cubic cells ({} × {} × {})", h.x, h.y, h.z));
        }
        if let crate::problem::Boundary::Neumann { flux } = problem.boundary()
            && self.reflecting_neumann_only
            && *flux != 0.0
        {
            return unsupported(format!(
                "a Neumann boundary with flux {flux} (only a reflecting box, flux 0)"
            ));
        }
        if self.robin_needs_embedded_surface
            && matches!(problem.boundary(), crate::problem::Boundary::Robin { .. })
        {
            return unsupported(
                "a Robin boundary without embedded geometry (its interface is the embedded surface)"
                    .into(),
            );
        }
        if self.point_lights_inside_grid {
            let (lo, hi) = problem.geometry().bounds();
            for light in problem.lights() {
                if let crate::problem::Light::Point { position, .. }
                | crate::problem::Light::Spot { position, .. } = light
                    && !(position.cmpge(lo).all() && position.cmplt(hi).all())
                {
                    return unsupported(format!("a point light outside the grid (at {position})"));
                }
            }
        }
        if self.needs_absorption {
            let [nx, ny, nz] = problem.geometry().dims();
            let (mut sigma, mut albedo) = (vec![0.0f32; nx * ny], vec![0.0f32; nx * ny]);
            for c in 0..problem.channels() {
                let sigma_t = &medium.sigma_t[c.min(medium.sigma_t.len() - 1)];
                let alb = &medium.albedo[c.min(medium.albedo.len() - 1)];
                let mut absorbs = false;
                for z in 0..nz {
                    let read = sigma_t
                        .read_slabs(z, z + 1, &mut sigma)
                        .and_then(|()| alb.read_slabs(z, z + 1, &mut albedo));
                    if let Err(e) = read {
                        return Err(crate::paged::paging_error(solver, e));
                    }
                    absorbs |= sigma
                        .iter()
                        .zip(&albedo)
                        .any(|(&t, &a)| f64::from(t) > f64::from(a * t) * (1.0 + 1e-6));
                    if absorbs {
                        break;
                    }
                }
                if !absorbs {
                    return unsupported("a medium without absorption".into());
                }
            }
        }
        Ok(())
    }
}

/// Progress of a running solve, passed to [`SolveOptions::progress`].
///
/// Through [`crate::driver::run`] (every registered solver) the fraction the caller sees
/// never decreases and reaches 1 once, in the last report, sent when the solve is done
/// (stage [`Progress::DONE`]); the phases of a solve (the uncollided light, each channel)
/// have their shares of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// What the solver is doing, in words for a person: `uncollided light`,
    /// `source iteration`, `V-cycle`, `batch`, ...
    pub stage: &'static str,
    /// Fraction done in [0, 1] (iterative solvers: an estimate from the residual).
    pub fraction: f64,
    /// Iterations so far (0 for direct methods).
    pub iteration: usize,
    /// Current relative residual, if the solver has one.
    pub residual: Option<f64>,
}

impl Progress {
    /// The stage of the last report of a finished solve.
    pub const DONE: &'static str = "done";
}

impl fmt::Display for Progress {
    /// `source iteration 7, residual 3.0e-4`; `uncollided light`; `batch 12`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.stage)?;
        if self.stage == Self::DONE {
            return Ok(());
        }
        if self.iteration > 0 {
            write!(f, " {}", self.iteration)?;
        }
        if let Some(r) = self.residual.filter(|r| r.is_finite()) {
            write!(f, ", residual {r:.1e}")?;
        }
        Ok(())
    }
}

/// A progress callback.
pub type ProgressFn = Arc<dyn Fn(Progress) + Send + Sync>;

/// How a solve is asked to run.
#[derive(Clone)]
pub struct SolveOptions {
    /// Stop when the residual falls below this fraction of the initial one.
    pub relative_tolerance: f64,
    /// Stop when the residual falls below this absolute value.
    pub absolute_tolerance: f64,
    /// Stop after this many iterations.
    pub max_iterations: usize,
    /// Stop after this much wall time.
    pub time_budget: Option<Duration>,
    /// Worker threads (`None`: rayon's global pool).
    pub threads: Option<usize>,
    /// The most bytes the solver may allocate.
    pub memory_budget: u64,
    /// Called as the solve advances.
    pub progress: Option<ProgressFn>,
    /// Set by the caller (a Ctrl-C handler) to stop the solve at its next iteration, batch
    /// or march with what it has computed ([`StopReason::Interrupted`]).
    pub cancel: Option<Arc<std::sync::atomic::AtomicBool>>,
    /// The ranks this process is one of (`lucent-mpi`'s `Mpi` under `mpirun`): solvers
    /// whose [`Capabilities::ranks`] is set split their solve over them, every rank calling
    /// with the same problem and getting the same solution; others refuse more than one
    /// rank. `None`: this process alone.
    pub ranks: Option<Ranks>,
}

/// The ranks a solve runs on ([`SolveOptions::ranks`]).
pub type Ranks = Arc<dyn crate::ranks::Communicator + Send + Sync>;

impl Default for SolveOptions {
    fn default() -> Self {
        Self {
            relative_tolerance: 1e-6,
            absolute_tolerance: 0.0,
            max_iterations: 10_000,
            time_budget: None,
            threads: None,
            memory_budget: 8 << 30,
            progress: None,
            cancel: None,
            ranks: None,
        }
    }
}

impl fmt::Debug for SolveOptions {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("SolveOptions")
            .field("relative_tolerance", &self.relative_tolerance)
            .field("absolute_tolerance", &self.absolute_tolerance)
            .field("max_iterations", &self.max_iterations)
            .field("time_budget", &self.time_budget)
            .field("threads", &self.threads)
            .field("memory_budget", &self.memory_budget)
            .field("progress", &self.progress.as_ref().map(|_| "callback"))
            .field("cancel", &self.cancel)
            .field(
                "ranks",
                &self
                    .ranks
                    .as_ref()
                    .map(|r| format!("rank {} of {}", r.rank(), r.size())),
            )
            .finish()
    }
}

impl SolveOptions {
    /// The most worker threads a solve may ask for: a pool of more would cost more to
    /// start than any solve here gains.
    pub const MAX_THREADS: usize = 1024;

    /// Checks the numbers (a relative tolerance in [0, 1), an absolute one finite and
    /// ≥ 0, at least one iteration, 1 to [`Self::MAX_THREADS`] threads).
    pub fn validate(&self) -> Result<(), SolveError> {
        let bad = |name: &str, reason: &str| {
            Err(SolveError::InvalidParameter {
                name: name.into(),
                reason: reason.into(),
            })
        };
        // A relative residual of 1 is where every iteration starts: a tolerance of 1 or
        // more would call the initial guess converged.
        if !(0.0..1.0).contains(&self.relative_tolerance) {
            return bad(
                "relative_tolerance",
                "must be at least 0 and below 1 (a fraction of the initial residual)",
            );
        }
        if !(self.absolute_tolerance >= 0.0 && self.absolute_tolerance.is_finite()) {
            return bad("absolute_tolerance", "must be finite and ≥ 0");
        }
        if self.max_iterations == 0 {
            return bad("max_iterations", "must be at least 1");
        }
        if self
            .threads
            .is_some_and(|n| !(1..=Self::MAX_THREADS).contains(&n))
        {
            return bad("threads", "1 to 1024");
        }
        Ok(())
    }

    /// These options with progress mapped into [lo, hi] of the caller's bar: for a phase
    /// of a solve (its own final report lands at `hi`).
    pub fn progress_within(&self, lo: f64, hi: f64) -> SolveOptions {
        SolveOptions {
            progress: self
                .progress
                .clone()
                .map(|callback| crate::driver::progress_within(callback, lo, hi)),
            ..self.clone()
        }
    }

    /// Runs `f` on a pool of `threads` workers, or on rayon's global pool.
    pub fn install<T: Send>(&self, f: impl FnOnce() -> T + Send) -> Result<T, SolveError> {
        match self.threads {
            None => Ok(f()),
            Some(n) => rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map(|pool| pool.install(f))
                .map_err(|e| SolveError::InvalidParameter {
                    name: "threads".into(),
                    reason: e.to_string(),
                }),
        }
    }

    /// Whether the caller has asked the solve to stop.
    pub fn cancelled(&self) -> bool {
        self.cancel
            .as_ref()
            .is_some_and(|c| c.load(std::sync::atomic::Ordering::Relaxed))
    }

    /// Reports progress if a callback is set.
    pub fn report(&self, progress: Progress) {
        if let Some(callback) = &self.progress {
            callback(progress);
        }
    }
}

/// Why a solver stopped, in the manner of PETSc's KSP converged reasons.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "reason", rename_all = "kebab-case")]
pub enum StopReason {
    /// A non-iterative method finished: the result is exact up to its discretisation.
    Exact,
    /// The residual fell below the relative tolerance.
    ConvergedRelative {
        /// Final relative residual.
        residual: f64,
    },
    /// The residual fell below the absolute tolerance.
    ConvergedAbsolute {
        /// Final residual.
        residual: f64,
    },
    /// A stochastic method ran every sample it was asked for: the result is an unbiased
    /// estimate whose accuracy is its standard error, not a residual.
    Sampled {
        /// The mean relative standard error over the cells that hold light.
        relative_error: f64,
    },
    /// The iteration limit was reached first.
    IterationLimit {
        /// Relative residual when stopped.
        residual: f64,
    },
    /// The time budget ran out first.
    TimeLimit {
        /// Relative residual when stopped.
        residual: f64,
    },
    /// The caller interrupted the solve ([`SolveOptions::cancel`]): the result is what
    /// was computed so far.
    Interrupted {
        /// Relative residual when stopped.
        residual: f64,
    },
    /// A NaN or infinity appeared.
    DivergedNonFinite {
        /// The iteration at which it appeared.
        iteration: usize,
    },
    /// The residual grew beyond any hope of convergence.
    DivergedGrowth {
        /// Growth of the residual over its initial value.
        growth: f64,
        /// The iteration at which the solver gave up.
        iteration: usize,
    },
}

impl StopReason {
    /// How badly a solve stopped, for merging the reports of several channels or phases:
    /// 0 exact, 1 converged, 2 iteration limit, 3 time limit, 4 interrupted, 5 diverged by
    /// growth, 6 not finite.
    pub fn severity(&self) -> u8 {
        match self {
            StopReason::Exact => 0,
            StopReason::ConvergedRelative { .. }
            | StopReason::ConvergedAbsolute { .. }
            | StopReason::Sampled { .. } => 1,
            StopReason::IterationLimit { .. } => 2,
            StopReason::TimeLimit { .. } => 3,
            StopReason::Interrupted { .. } => 4,
            StopReason::DivergedGrowth { .. } => 5,
            StopReason::DivergedNonFinite { .. } => 6,
        }
    }

    /// Whether the solution can be trusted (exact, converged, or every sample taken).
    pub fn is_converged(&self) -> bool {
        matches!(
            self,
            StopReason::Exact
                | StopReason::ConvergedRelative { .. }
                | StopReason::ConvergedAbsolute { .. }
                | StopReason::Sampled { .. }
        )
    }

    /// Whether the solve blew up (a residual that grew without bound, or NaN/infinity).
    pub fn is_diverged(&self) -> bool {
        matches!(
            self,
            StopReason::DivergedGrowth { .. } | StopReason::DivergedNonFinite { .. }
        )
    }
}

impl fmt::Display for StopReason {
    /// In words, for a person: `converged to a relative residual of 8.2e-9`,
    /// `stopped at the iteration limit with a relative residual of 4.1e-2`, ...
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StopReason::Exact => {
                f.write_str("finished (a direct method: exact up to its discretisation)")
            }
            StopReason::ConvergedRelative { residual } => {
                write!(f, "converged to a relative residual of {residual:.1e}")
            }
            StopReason::ConvergedAbsolute { residual } => {
                write!(f, "converged to an absolute residual of {residual:.1e}")
            }
            StopReason::Sampled { relative_error } => write!(
                f,
                "took every sample asked for (mean relative standard error {relative_error:.1e})"
            ),
            StopReason::IterationLimit { residual } => write!(
                f,
                "did not converge: stopped at the iteration limit with a relative residual of {residual:.1e}"
            ),
            StopReason::TimeLimit { residual } => write!(
                f,
                "did not converge: ran out of time with a relative residual of {residual:.1e}"
            ),
            StopReason::Interrupted { residual } => write!(
                f,
                "was interrupted with a relative residual of {residual:.1e}"
            ),
            StopReason::DivergedNonFinite { iteration } => {
                write!(f, "diverged: NaN or infinity at iteration {iteration}")
            }
            StopReason::DivergedGrowth { growth, iteration } => write!(
                f,
                "diverged: the residual grew {growth:.1e}-fold by iteration {iteration}"
            ),
        }
    }
}

/// What happened during a solve.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SolveReport {
    /// The solver's name.
    pub solver: String,
    /// Iterations run (0 for non-iterative methods).
    pub iterations: usize,
    /// Relative residual after each iteration.
    pub residual_history: Vec<f64>,
    /// Wall time of the solve, in seconds.
    pub wall_time_s: f64,
    /// Bytes the solver allocated for its working data and result, at peak: its own
    /// estimate, checked against the budget before anything was allocated.
    pub peak_memory_bytes: u64,
    /// The peak resident memory the operating system measured during the solve, above
    /// what was resident before it ([`crate::memory::PeakMeter`]; the whole process's, so
    /// it includes anything running beside the solve); `None` where it cannot be measured.
    pub measured_peak_bytes: Option<u64>,
    /// Why it stopped.
    pub stop_reason: StopReason,
    /// What the pager did, where the solver paged working data out of core (`dom`'s
    /// sweeps under a tight memory budget): hits, misses, evictions, bytes moved.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub paging: Option<lucent_paging::PagerStats>,
    /// What a solver that chooses among others (`auto`) or composes them (`hybrid`) ran
    /// and why, in one line for people; `None` for every solver that runs one method.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub choice: Option<String>,
    /// The same as fields: the solver and parameters that ran, the parts they were made
    /// of and, for `auto`, the numbers it decided on; `None` where `choice` is.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub composition: Option<Composition>,
}

/// What a choosing or composing solver ran ([`SolveReport::composition`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Composition {
    /// The registered solver that ran (for `auto`, the one it chose; for `hybrid`,
    /// `hybrid`).
    pub solver: String,
    /// Its parameters as they ran, defaults included.
    pub params: serde_json::Value,
    /// What it was made of, in the order they ran (empty for a solver of one method).
    pub parts: Vec<Part>,
    /// Why `auto` chose it; `None` for a solver that composes without choosing.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub decision: Option<Decision>,
}

/// One part of a composed solve ([`Composition::parts`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Part {
    /// What it computes: `"uncollided light"`, `"scattering orders 1-4"`, `"the rest"`.
    pub computes: String,
    /// The method that computed it (`direct`'s cell integrals, `dom`'s sweeps,
    /// `diffusion-mg`).
    pub method: String,
    /// Its parameters as they ran.
    pub params: serde_json::Value,
    /// Iterations it took (sweeps, V-cycles), summed over channels.
    pub iterations: usize,
    /// Its source's power over the first scattering order's source power (0 to 1): how
    /// much of the scattered light it carried; `None` where not a single number.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub share: Option<f64>,
}

/// The numbers `auto` decided on ([`Composition::decision`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Decision {
    /// The relative error asked for (0.02: 2 %).
    pub tolerance: f64,
    /// The expected error a run may have to be chosen: the tolerance on a measured scene,
    /// less a margin for noise and spread on any other.
    pub error_limit: f64,
    /// The chosen run's largest measured error on the deciding scenes.
    pub expected_error: f64,
    /// Its measured time scaled to this problem's cell count, seconds.
    pub expected_seconds: f64,
    /// Whether it is expected to meet `error_limit`.
    pub meets: bool,
    /// Whether the time budget ruled out runs that would have met it.
    pub budget_bound: bool,
    /// The measured scenes that decided, nearest first.
    pub neighbours: Vec<Neighbour>,
}

/// A measured scene that decided `auto`'s choice ([`Decision::neighbours`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Neighbour {
    /// The suite scene's name.
    pub scene: String,
    /// Its distance from the problem in regime: Euclidean, over features such as the
    /// logarithms of absorption and optical depths, the anisotropy g and the share of empty
    /// cells (`lucent::auto::Features`); below 0.05 it is taken as the same scene.
    pub regime_distance: f64,
}

/// A light-transport solver: one obvious way to be called.
pub trait Solver: Send + Sync {
    /// The registry name (`direct`, `diffusion-mg`, ...).
    fn name(&self) -> &str;

    /// What problems it handles.
    fn capabilities(&self) -> Capabilities;

    /// `Ok` if [`Solver::solve`] will run on `problem` (it may still fail for lack of
    /// memory or with a bad option): the capabilities' check plus anything specific to the
    /// solver and its parameters. `solve` calls it first, so the two cannot disagree.
    fn admits(&self, problem: &Problem) -> Result<(), SolveError> {
        self.capabilities().check(self.name(), problem)
    }

    /// Solves `problem`. Fails only when the solve cannot run (unsupported feature, bad
    /// option, over budget); a solve that ran returns its [`SolveReport`] with the reason it
    /// stopped.
    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError>;

    /// The solver's way of making pictures directly, if it has one (Monte Carlo's camera
    /// paths); `None` for solvers whose fluence the renderer ray-marches.
    fn images(&self) -> Option<&dyn ImageSolver> {
        None
    }

    /// Whether [`Solver::solve_paged`] runs (out of core), rather than refusing.
    fn pages(&self) -> bool {
        false
    }

    /// The part of a memory budget that a paged problem's medium (its pool and slabs) may
    /// take when this solver runs out of core; the rest is the solver's own paged working
    /// data. All of it by default: the medium's pool is the solver's working set.
    fn paged_medium_budget(&self, budget: u64) -> u64 {
        budget
    }

    /// The bytes [`Solver::solve_paged`] needs on `problem` under `options.memory_budget`,
    /// or [`SolveError::OverBudget`]: the check `solve_paged` makes first, from the
    /// problem's shape alone (geometry, bricks, pool, channels, lights), so that a caller
    /// can refuse a budget on a [`crate::PagedProblem::shell`] before building the medium.
    fn paged_memory(
        &self,
        problem: &crate::PagedProblem,
        options: &SolveOptions,
    ) -> Result<u64, SolveError> {
        let _ = (problem, options);
        Err(SolveError::Unsupported {
            solver: self.name().into(),
            feature: "a paged (out-of-core) medium: it needs its fields in memory".into(),
        })
    }

    /// Solves a problem whose medium is paged ([`crate::PagedProblem`]), giving the bits
    /// [`Solver::solve`] gives on the same medium in memory. Solvers that need their
    /// fields in memory refuse with [`SolveError::Unsupported`] (the default).
    fn solve_paged(
        &self,
        problem: &crate::PagedProblem,
        options: &SolveOptions,
    ) -> Result<crate::PagedSolution, SolveError> {
        let _ = (problem, options);
        Err(SolveError::Unsupported {
            solver: self.name().into(),
            feature: "a paged (out-of-core) medium: it needs its fields in memory".into(),
        })
    }
}

/// What a picture asks of an [`ImageSolver`]: its size and the camera's rays. The camera
/// stays in `lucent-render`; this sees only the ray through each image point.
pub struct ImageRequest<'a> {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Radiance of camera rays that leave the medium (linear RGB).
    pub background: [f64; 3],
    /// The camera ray (origin, unit direction) through image point (u, v) ∈ [0, 1]², v down.
    pub ray: &'a (dyn Fn(f64, f64) -> (glam::DVec3, glam::DVec3) + Sync),
    /// Called with the fraction of the picture done.
    pub progress: Option<&'a (dyn Fn(f64) + Sync)>,
    /// Ctrl-C and the time limit: once it halts, the row being traced is given up and no
    /// new one starts: the picture comes back with the rows traced whole
    /// ([`ImageEstimate::rows_traced`]). Asked every pixel.
    pub interrupt: crate::Interrupt,
}

/// A radiance image with its per-pixel standard error (linear RGB, rows from the top).
#[derive(Debug, Clone, PartialEq)]
pub struct ImageEstimate {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Mean radiance per pixel.
    pub radiance: Vec<[f32; 3]>,
    /// Its standard error.
    pub std_error: Vec<[f32; 3]>,
    /// Rows traced: `height` unless the request was interrupted. A row not traced holds the
    /// background radiance and a standard error of `f32::MAX` (unknown).
    pub rows_traced: usize,
}

/// A solver that estimates the radiance along camera rays itself instead of handing the
/// renderer a fluence.
pub trait ImageSolver {
    /// The picture `request` asks for.
    fn image(
        &self,
        problem: &Problem,
        request: &ImageRequest<'_>,
    ) -> Result<ImageEstimate, SolveError>;
}
