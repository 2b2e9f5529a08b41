//! The one seam between a [`Problem`] and a method's numerics.
//!
//! Every registered solver runs through [`run`]: it asks the solver whether it admits the
//! problem ([`Solver::admits`]: capabilities plus anything solver-specific), validates the
//! options, checks the method's memory estimate against `memory_budget` *before* anything
//! is allocated, installs the thread pool, and turns what the method returns into the
//! [`SolveReport`]. The method sees a [`Context`]: the problem, the options (already on the
//! pool), the stopping rule of the whole solve and the stopping rule of each of its phases
//! (the time budget that is left, progress scaled into the phase's share).
//!
//! Methods that solve each colour channel on its own (diffusion, discrete ordinates, the
//! explicit schemes, finite elements) implement [`ChannelMethod`] and run through
//! [`solve_per_channel`], which also owns what they all did for themselves:
//!
//! - **Sorting the lights** ([`ChannelMethod::route`], [`default_route`]): point lights
//!   inside the medium and volumetric emission are the method's own sources; every other
//!   light (directional, spot, sky, point lights outside the medium) enters as uncollided
//!   light.
//! - **The uncollided light** ([`Uncollided`]): `direct` and the conservative cell
//!   integrals of the lights routed to it, attenuated through the medium only (masked to
//!   the embedded body when there is one), computed once for every channel. Its
//!   cell-averaged fluence is added to the fluence each channel returns.
//! - **Per-channel coefficients** ([`Coefficients`]): σ_t, σ_s = albedo·σ_t,
//!   σ_a = max(σ_t − σ_s, 0) and the diffusion coefficient D = 1/(3σ_t′),
//!   σ_t′ = σ_a + (1 − g)σ_s, with σ_t′ kept at least 10⁻³ of the largest cell's inverse
//!   width so that empty cells do not make D infinite (diffusion is not meant for them).
//! - **The per-channel loop** with one rule for the report ([`Record::worse`]): the
//!   solution reports the channel that stopped worst (diverged before time limit before
//!   iteration limit before converged; among equals, the one that iterated most), and the
//!   peak memory of the most demanding channel.
//!
//! **Progress.** [`run`] hands the method a progress callback whose fraction never
//! decreases and stays below 1 while the method runs; it sends the one report at 1 itself
//! (stage [`Progress::DONE`]) when the method has returned. [`solve_per_channel`] gives
//! the uncollided light the first [`UNCOLLIDED_SHARE`] of the bar and the channels equal
//! shares of the rest.
//!
//! A new solver supplies its capabilities, its memory estimate, its preparation
//! ([`ChannelMethod::setup`]) and its per-channel solve; see ARCHITECTURE.md, "Adding a
//! solver".

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use lucent_grid::Grid;
use lucent_optics::PhaseFunction;
use lucent_paging::PagerStats;

use crate::error::SolveError;
use crate::iteration::Stopping;
use crate::problem::{Boundary, Light, Problem};
use crate::solution::{Angular, Solution};
use crate::solver::{Progress, ProgressFn, SolveOptions, SolveReport, Solver, StopReason};
use crate::uncollided::Uncollided;

/// How one solve (or one channel of it) went: what goes into the [`SolveReport`].
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Iterations run (0 for non-iterative methods).
    pub iterations: usize,
    /// Relative residual per iteration (empty where the method has none).
    pub residuals: Vec<f64>,
    /// Why it stopped.
    pub stop_reason: StopReason,
    /// Bytes of working data at peak as the method counted them (the report keeps the
    /// larger of this and the estimate checked against the budget; 0: no count).
    pub memory_bytes: u64,
    /// What the method's pager did, if it paged working data out of core.
    pub paging: Option<PagerStats>,
}

impl Record {
    /// A non-iterative method's record.
    pub fn exact(memory_bytes: u64) -> Self {
        Self {
            iterations: 0,
            residuals: Vec::new(),
            stop_reason: StopReason::Exact,
            memory_bytes,
            paging: None,
        }
    }

    /// An iterative method's record from its residuals (the first being the initial
    /// residual, so `iterations` is one less than their count).
    pub fn from_residuals(residuals: Vec<f64>, stop_reason: StopReason, memory_bytes: u64) -> Self {
        Self {
            iterations: residuals.len().saturating_sub(1),
            residuals,
            stop_reason,
            memory_bytes,
            paging: None,
        }
    }

    /// The one rule for merging channels' (or phases') records: the record of the one that
    /// stopped worse ([`StopReason::severity`]; among equals the one with more
    /// iterations), with the larger memory of the two and both pagers' counters.
    pub fn worse(self, other: Self) -> Self {
        let memory = self.memory_bytes.max(other.memory_bytes);
        let paging = match (self.paging, other.paging) {
            (Some(a), Some(b)) => Some(a.plus(&b)),
            (a, b) => a.or(b),
        };
        let key = |r: &Self| (r.stop_reason.severity(), r.iterations);
        let mut kept = if key(&other) > key(&self) {
            other
        } else {
            self
        };
        kept.memory_bytes = memory;
        kept.paging = paging;
        kept
    }
}

/// What a method hands back to [`run`].
#[derive(Debug, Clone)]
pub struct Outcome {
    /// Fluence per channel.
    pub fluence: Vec<Grid>,
    /// Angular radiance for the renderer, if the method keeps any.
    pub angular: Option<Angular>,
    /// Per-cell standard error per channel (stochastic methods).
    pub standard_error: Option<Vec<Grid>>,
    /// How it went.
    pub record: Record,
}

/// What a running method sees: the problem, the options and the clock of the whole solve.
pub struct Context<'a> {
    /// The problem being solved.
    pub problem: &'a Problem,
    /// The caller's options, with `threads` cleared: the work already runs on the pool
    /// they asked for.
    pub options: SolveOptions,
    started: Instant,
}

/// The share of the progress bar [`solve_per_channel`] gives the uncollided light (the
/// channels share the rest). A fixed guess: the uncollided light costs 10–90 % of a solve
/// (discrete ordinates on the default scene: 12 %; multigrid diffusion: most of it), so the
/// stage name, not the fraction, says where a solve is.
pub const UNCOLLIDED_SHARE: f64 = 0.25;

/// The largest fraction a report may carry before the solve has returned.
const BEFORE_DONE: f64 = 0.999;

static SOLVES_STARTED: AtomicU64 = AtomicU64::new(0);

/// How many solves [`run`] has started in this process (past admission, option and
/// budget checks): lets a test show that bad input was refused before any solving.
pub fn solves_started() -> u64 {
    SOLVES_STARTED.load(Ordering::Relaxed)
}

/// `callback` with its fractions mapped into [lo, hi].
pub(crate) fn progress_within(callback: ProgressFn, lo: f64, hi: f64) -> ProgressFn {
    Arc::new(move |p: Progress| {
        callback(Progress {
            fraction: lo + (hi - lo) * p.fraction.clamp(0.0, 1.0),
            ..p
        })
    })
}

/// `callback` made monotone and kept below 1 ([`run`] sends the 1 itself).
fn monotone(callback: ProgressFn) -> ProgressFn {
    let seen = Arc::new(AtomicU64::new(0f64.to_bits()));
    Arc::new(move |p: Progress| {
        let f = if p.fraction.is_finite() {
            p.fraction.clamp(0.0, BEFORE_DONE)
        } else {
            0.0
        };
        // Non-negative f64s order as their bits do.
        let before = f64::from_bits(seen.fetch_max(f.to_bits(), Ordering::Relaxed));
        callback(Progress {
            fraction: f.max(before),
            ..p
        })
    })
}

impl<'a> Context<'a> {
    /// This context with its progress mapped into [lo, hi] of its own (a phase of the
    /// solve: the uncollided light, the channel loop).
    pub fn within(&self, lo: f64, hi: f64) -> Context<'a> {
        Context {
            problem: self.problem,
            options: self.options_within(lo, hi),
            started: self.started,
        }
    }

    /// The options with progress mapped into [lo, hi] of this context's, for a nested
    /// solve (its own final report lands at `hi`). Without ranks: a nested solve (the
    /// uncollided light) runs whole in every process.
    pub fn options_within(&self, lo: f64, hi: f64) -> SolveOptions {
        SolveOptions {
            ranks: None,
            progress: self
                .options
                .progress
                .clone()
                .map(|callback| progress_within(callback, lo, hi)),
            time_budget: self.remaining_budget(),
            ..self.options.clone()
        }
    }

    /// The solve's [`crate::Interrupt`]: the caller's cancel flag and the deadline its
    /// time budget set when the solve started, for the method's loops to ask.
    pub fn interrupt(&self) -> crate::Interrupt {
        crate::Interrupt::from_start(&self.options, self.started)
    }

    /// Time since the solve started.
    pub fn elapsed(&self) -> Duration {
        self.started.elapsed()
    }

    /// The time budget that is left (`None`: unbounded).
    pub fn remaining_budget(&self) -> Option<Duration> {
        self.options
            .time_budget
            .map(|t| t.saturating_sub(self.started.elapsed()))
    }

    /// Reports progress to the caller, if they asked for it.
    pub fn report(&self, progress: Progress) {
        self.options.report(progress);
    }

    /// The stopping rule of phase `phase` of `phases` (a channel, a light's march): the
    /// caller's tolerances and iteration limit, the time budget that is left, and progress
    /// mapped into the phase's share [phase/phases, (phase + 1)/phases] of the whole.
    pub fn stopping_for(&self, phase: usize, phases: usize) -> Stopping {
        let mut stopping = Stopping::from_options(&self.options);
        stopping.time_budget = self.remaining_budget();
        stopping.deadline = self
            .options
            .time_budget
            .and_then(|t| self.started.checked_add(t));
        let phases = phases.max(1);
        if phases > 1
            && let Some(callback) = self.options.progress.clone()
        {
            stopping.progress = Some(std::sync::Arc::new(move |p: Progress| {
                callback(Progress {
                    fraction: (phase as f64 + p.fraction) / phases as f64,
                    ..p
                })
            }));
        }
        stopping
    }
}

/// Runs `solver`'s method `body` on `problem`: the admission check, option validation,
/// the memory estimate `memory_bytes` against the budget (before `body` allocates), the
/// thread pool, and the report. Every registered solver's `solve` goes through here.
pub fn run<S, F>(
    solver: &S,
    problem: &Problem,
    options: &SolveOptions,
    memory_bytes: u64,
    body: F,
) -> Result<Solution, SolveError>
where
    S: Solver + ?Sized,
    F: FnOnce(&Context<'_>) -> Result<Outcome, SolveError> + Send,
{
    solver.admits(problem)?;
    options.validate()?;
    if let Some(ranks) = options.ranks.as_ref().filter(|r| r.size() > 1)
        && !solver.capabilities().ranks
    {
        return Err(SolveError::Unsupported {
            solver: solver.name().into(),
            feature: format!(
                "{} ranks: it runs in one process (diffusion-mg, ftcs-diffusion, jacobi-diffusion and ftcs-p1 split over ranks)",
                ranks.size()
            ),
        });
    }
    if memory_bytes > options.memory_budget {
        return Err(SolveError::OverBudget {
            solver: solver.name().into(),
            needed: memory_bytes,
            budget: options.memory_budget,
        });
    }
    let started = Instant::now();
    SOLVES_STARTED.fetch_add(1, Ordering::Relaxed);
    let meter = crate::memory::PeakMeter::start();
    let context = Context {
        problem,
        options: SolveOptions {
            threads: None,
            progress: options.progress.clone().map(monotone),
            ..options.clone()
        },
        started,
    };
    // A nested solve (the uncollided light's `direct`) halted: the solve that halted is
    // this one.
    let outcome = options.install(|| body(&context))?.map_err(|e| match e {
        SolveError::Halted {
            solver: inner,
            stage,
            halt,
        } if inner != solver.name() => SolveError::Halted {
            solver: solver.name().into(),
            stage: format!("{stage} (`{inner}`)"),
            halt,
        },
        other => other,
    })?;
    // No output holds NaN or infinity, whatever the method did.
    let outputs = [
        ("fluence", Some(&outcome.fluence)),
        ("standard error", outcome.standard_error.as_ref()),
    ];
    for (what, grids) in outputs {
        for (channel, grid) in grids.into_iter().flatten().enumerate() {
            if let Some(index) = grid.data().iter().position(|v| !v.is_finite()) {
                return Err(SolveError::NonFiniteOutput {
                    solver: solver.name().into(),
                    what,
                    channel,
                    cell: grid.geometry().coords(index),
                    value: grid.data()[index],
                });
            }
        }
    }
    let record = outcome.record;
    options.report(Progress {
        stage: Progress::DONE,
        fraction: 1.0,
        iteration: record.iterations,
        residual: record.residuals.last().copied(),
    });
    Ok(Solution {
        fluence: outcome.fluence,
        angular: outcome.angular,
        standard_error: outcome.standard_error,
        report: SolveReport {
            solver: solver.name().into(),
            iterations: record.iterations,
            residual_history: record.residuals,
            wall_time_s: started.elapsed().as_secs_f64(),
            // The estimate checked against the budget, or the method's own count if that
            // came out larger.
            peak_memory_bytes: memory_bytes.max(record.memory_bytes),
            stop_reason: record.stop_reason,
            measured_peak_bytes: meter.and_then(|m| m.peak_bytes()),
            paging: record.paging,
            choice: None,
            composition: None,
        },
    })
}

/// Where a light goes in a per-channel method.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Route {
    /// The method takes it as its own source.
    Own,
    /// It enters as uncollided light ([`Uncollided`]): the method sees its first
    /// collisions, and its uncollided fluence is added to the method's.
    Uncollided,
}

/// The usual routing: emission, and point lights inside the medium (inside the grid's box
/// and, with an embedded body, inside it), are the method's own; every other light is
/// uncollided.
pub fn default_route(problem: &Problem, light: &Light) -> Route {
    match light {
        Light::Emission { .. } => Route::Own,
        Light::Point { position, .. } if in_medium(problem, *position) => Route::Own,
        _ => Route::Uncollided,
    }
}

/// Whether `p` lies in the problem's medium: inside the grid's box (half-open, as cells
/// are) and inside the embedded body if there is one.
pub fn in_medium(problem: &Problem, p: glam::DVec3) -> bool {
    let (lo, hi) = problem.geometry().bounds();
    p.cmpge(lo).all()
        && p.cmplt(hi).all()
        && problem
            .embedded()
            .is_none_or(|sdf| sdf.sample_trilinear(p) < 0.0)
}

/// A channel's coefficients per cell (f32, in the grid's storage order).
#[derive(Debug, Clone, PartialEq)]
pub struct Coefficients {
    /// Extinction σ_t (1/length).
    pub sigma_t: Vec<f32>,
    /// Scattering σ_s = albedo·σ_t (1/length).
    pub sigma_s: Vec<f32>,
    /// Absorption σ_a = max(σ_t − σ_s, 0) (1/length).
    pub sigma_a: Vec<f32>,
    /// Diffusion coefficient D = 1/(3σ_t′) (length), σ_t′ = σ_a + (1 − g)σ_s floored at
    /// 10⁻³ of the largest cell's inverse width.
    pub diffusion: Vec<f32>,
}

impl Coefficients {
    /// The coefficients of `channel` of `problem`'s medium.
    pub fn of(problem: &Problem, channel: usize) -> Self {
        let medium = problem.medium();
        let g = medium.phase.mean_cosine();
        let floor = Self::reduced_floor(problem);
        let sigma_t = medium.sigma_t(channel).data().to_vec();
        let albedo = medium.albedo(channel);
        let n = sigma_t.len();
        let (mut sigma_s, mut sigma_a, mut diffusion) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        for c in 0..n {
            [sigma_s[c], sigma_a[c], diffusion[c]] = Self::at(sigma_t[c], albedo.at(c), g, floor);
        }
        Self {
            sigma_t,
            sigma_s,
            sigma_a,
            diffusion,
        }
    }

    /// σ_s, σ_a and D of one cell from its σ_t and albedo (f32, as stored), the phase
    /// function's mean cosine `g` and the floor of σ_t′: the one per-cell definition, for
    /// [`Coefficients::of`] and for the solvers that compute coefficients brick by brick
    /// out of core.
    #[inline]
    pub fn at(sigma_t: f32, albedo: f32, g: f64, floor: f64) -> [f32; 3] {
        let s = (albedo * sigma_t).min(sigma_t);
        let (a, d) = Self::absorption_and_diffusion(f64::from(sigma_t), f64::from(s), g, floor);
        [s, a as f32, d as f32]
    }

    /// The floor of σ_t′ in `problem`: 10⁻³ of the largest cell's inverse width.
    pub fn reduced_floor(problem: &Problem) -> f64 {
        Self::reduced_floor_of(problem.geometry())
    }

    /// [`Coefficients::reduced_floor`] of a grid.
    pub fn reduced_floor_of(geometry: &lucent_grid::GridGeometry) -> f64 {
        1e-3 / geometry.spacing().max_element()
    }

    /// σ_a = max(σ_t − σ_s, 0) and D = 1/(3 max(σ_a + (1 − g)σ_s, floor)) at one point:
    /// the one definition, for methods that sample coefficients between cell centres.
    pub fn absorption_and_diffusion(sigma_t: f64, sigma_s: f64, g: f64, floor: f64) -> (f64, f64) {
        let a = (sigma_t - sigma_s).max(0.0);
        (a, 1.0 / (3.0 * (a + (1.0 - g) * sigma_s).max(floor)))
    }
}

/// One channel as a [`ChannelMethod`] solves it.
pub struct Channel<'a> {
    /// The channel's index.
    pub index: usize,
    /// The problem.
    pub problem: &'a Problem,
    /// Its coefficients per cell (owned: a method may move them into its own problem).
    pub coefficients: Coefficients,
    /// The lights routed to the method ([`Route::Own`]).
    pub lights: &'a [Light],
    /// The uncollided light of the other lights, if any.
    pub uncollided: Option<&'a Uncollided>,
    /// When to stop: the caller's rule, the budget left, progress in this channel's share.
    pub stopping: Stopping,
}

impl Channel<'_> {
    /// The emitted radiance L_e of the method's emission lights in this channel, per cell
    /// (power per volume per steradian); zeros without emission.
    pub fn emission(&self) -> Vec<f64> {
        let mut emitted = vec![0.0; self.problem.geometry().voxel_count()];
        for light in self.lights {
            if let Light::Emission { grid, scale } = light {
                let s = scale.channel(self.index);
                for (q, e) in emitted.iter_mut().zip(grid.data()) {
                    *q += s * f64::from(*e);
                }
            }
        }
        emitted
    }

    /// The volumetric sources of a diffusion-type method in this channel: Q₀ = 4π L_e of
    /// its emission plus the uncollided light's first collisions
    /// ([`Uncollided::first_collision_sources`], power per volume), and their first
    /// moment Q₁ (empty without uncollided light or when g = 0).
    pub fn diffusion_sources(&self) -> (Vec<f64>, Vec<[f32; 3]>) {
        let four_pi = 4.0 * std::f64::consts::PI;
        let mut q0: Vec<f64> = self.emission().iter().map(|e| four_pi * e).collect();
        let Some(uncollided) = self.uncollided else {
            return (q0, Vec::new());
        };
        let g = self.problem.medium().phase.mean_cosine();
        let (scattered, first) =
            uncollided.first_collision_sources(self.index, &self.coefficients.sigma_s, g);
        for (q, s) in q0.iter_mut().zip(scattered) {
            *q += f64::from(s);
        }
        (q0, first)
    }

    /// The method's point lights in this channel: position and power 4πI.
    pub fn point_sources(&self) -> Vec<(glam::DVec3, f64)> {
        self.lights
            .iter()
            .filter_map(|light| match light {
                Light::Point {
                    position,
                    intensity,
                } => Some((
                    *position,
                    4.0 * std::f64::consts::PI * intensity.channel(self.index),
                )),
                _ => None,
            })
            .collect()
    }

    /// The sky radiance in this channel of the method's sky lights (0 without one).
    pub fn sky_radiance(&self) -> f64 {
        self.lights
            .iter()
            .map(|light| match light {
                Light::Sky { radiance } => radiance.channel(self.index),
                _ => 0.0,
            })
            .sum()
    }
}

/// What a [`ChannelMethod`] returns for one channel.
#[derive(Debug, Clone)]
pub struct ChannelSolution<E> {
    /// The fluence the method computed, per cell, without the uncollided light's (the
    /// driver adds it).
    pub fluence: Vec<f32>,
    /// How the channel's solve went.
    pub record: Record,
    /// Whatever else the method keeps per channel (for its angular output or its own
    /// diagnostics).
    pub extra: E,
}

/// A method that solves each channel on its own: what it supplies to
/// [`solve_per_channel`].
pub trait ChannelMethod: Sync {
    /// What every channel shares (meshes, cell geometry, angular sets), built once.
    type Setup: Sync;
    /// What each channel keeps besides its fluence.
    type Extra: Send;

    /// Bytes the whole solve needs at peak, estimated before anything is allocated.
    fn memory_bytes(&self, problem: &Problem) -> u64;

    /// Builds what every channel shares.
    fn setup(&self, context: &Context<'_>) -> Result<Self::Setup, SolveError>;

    /// What one of its iterations is called in progress reports (`source iteration`,
    /// `V-cycle`, `time step`); `iteration` by default.
    fn stage(&self) -> &'static str {
        "iteration"
    }

    /// Where `light` goes ([`default_route`] unless the method says otherwise).
    fn route(&self, setup: &Self::Setup, problem: &Problem, light: &Light) -> Route {
        let _ = setup;
        default_route(problem, light)
    }

    /// Solves one channel.
    fn solve_channel(
        &self,
        setup: &Self::Setup,
        channel: Channel<'_>,
    ) -> Result<ChannelSolution<Self::Extra>, SolveError>;

    /// The angular radiance the renderer gets, from the channels' extras (which it may
    /// take) and the uncollided light; `None` by default.
    fn angular(
        &self,
        setup: &Self::Setup,
        problem: &Problem,
        extras: &mut [Self::Extra],
        uncollided: Option<Uncollided>,
    ) -> Result<Option<Angular>, SolveError> {
        let _ = (setup, problem, extras, uncollided);
        Ok(None)
    }
}

/// What [`solve_per_channel`] itself holds at peak, on top of the method's estimate: one
/// channel's [`Coefficients`] (16 bytes per cell), the fluence of every channel (4), and
/// the uncollided light of every point-like light and the sky as if all were routed to it:
/// `direct`'s transmittance per light and extinction channel and its fluences, and each
/// point-like light's cell integrals (40 bytes per cell and extinction channel).
pub fn per_channel_bytes(problem: &Problem) -> u64 {
    let cells = problem.geometry().voxel_count() as u64;
    let channels = problem.channels() as u64;
    let extinction = problem.medium().sigma_t.len() as u64;
    let pointlike = problem.lights().iter().filter(|l| l.is_pointlike()).count() as u64;
    let direct = 4 * (pointlike * extinction + 2 * channels + 1);
    cells.saturating_mul(16 + 4 * channels + direct + 40 * pointlike * extinction)
}

/// Solves `problem` with a per-channel `method` on behalf of `solver` (whose name,
/// capabilities and admission check apply): everything [`run`] does, then the method's
/// setup, the lights sorted by [`ChannelMethod::route`], their uncollided light, and the
/// channel loop. Returns the solution and each channel's extra.
pub fn solve_per_channel<S, M>(
    solver: &S,
    method: &M,
    problem: &Problem,
    options: &SolveOptions,
) -> Result<(Solution, Vec<M::Extra>), SolveError>
where
    S: Solver + ?Sized,
    M: ChannelMethod,
{
    let mut extras = Vec::new();
    let solution = run(
        solver,
        problem,
        options,
        method
            .memory_bytes(problem)
            .saturating_add(per_channel_bytes(problem)),
        |context| {
            let setup = method.setup(context)?;
            let (mut own, mut external) = (Vec::new(), Vec::new());
            for light in problem.lights() {
                match method.route(&setup, problem, light) {
                    Route::Own => own.push(light.clone()),
                    Route::Uncollided => external.push(light.clone()),
                }
            }
            let uncollided = if external.is_empty() {
                None
            } else {
                // Through the medium only: straight lines, or curved rays where the
                // problem's refractive index is graded (`Uncollided::curved`).
                let medium = match problem.embedded() {
                    Some(sdf) => problem.medium().masked(sdf),
                    None => problem.medium().clone(),
                };
                let mut p = Problem::new(
                    *problem.geometry(),
                    medium,
                    external,
                    Boundary::Vacuum,
                    None,
                )?;
                if let Some(index) = problem.refractive_index() {
                    p = p.with_refractive_index(index.clone())?;
                }
                let mut options = context.options_within(0.0, UNCOLLIDED_SHARE);
                if let Some(callback) = options.progress.take() {
                    // Its `done` is not the solve's.
                    options.progress = Some(Arc::new(move |p: Progress| {
                        callback(Progress {
                            stage: if p.stage == Progress::DONE {
                                "uncollided light"
                            } else {
                                p.stage
                            },
                            ..p
                        })
                    }));
                }
                Some(Uncollided::new(&p, &options)?)
            };
            let start = if uncollided.is_some() {
                UNCOLLIDED_SHARE
            } else {
                0.0
            };
            let context = &context.within(start, 1.0);
            let channels = problem.channels();
            let mut fluence = Vec::with_capacity(channels);
            let mut record: Option<Record> = None;
            for c in 0..channels {
                let solved = method.solve_channel(
                    &setup,
                    Channel {
                        index: c,
                        problem,
                        coefficients: Coefficients::of(problem, c),
                        lights: &own,
                        uncollided: uncollided.as_ref(),
                        stopping: context.stopping_for(c, channels).with_stage(method.stage()),
                    },
                )?;
                let mut total = solved.fluence;
                if let Some(u) = &uncollided {
                    for (t, v) in total.iter_mut().zip(u.fluence(c)) {
                        *t += v as f32;
                    }
                }
                fluence.push(Grid::from_vec(*problem.geometry(), total)?);
                record = Some(match record {
                    None => solved.record,
                    Some(r) => r.worse(solved.record),
                });
                extras.push(solved.extra);
            }
            let angular = method.angular(&setup, problem, &mut extras, uncollided)?;
            Ok(Outcome {
                fluence,
                angular,
                standard_error: None,
                record: record.unwrap_or_else(|| Record::exact(0)),
            })
        },
    )?;
    Ok((solution, extras))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(stop_reason: StopReason, iterations: usize, memory_bytes: u64) -> Record {
        Record {
            iterations,
            residuals: vec![1.0; iterations + 1],
            stop_reason,
            memory_bytes,
            paging: None,
        }
    }

    /// A solver whose method returns NaN in one cell.
    struct Broken;

    impl Solver for Broken {
        fn name(&self) -> &str {
            "broken"
        }
        fn capabilities(&self) -> crate::Capabilities {
            crate::Capabilities {
                boundaries: vec![crate::BoundaryKind::Vacuum],
                lights: vec![crate::LightKind::Directional],
                heterogeneous: true,
                ..Default::default()
            }
        }
        fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
            run(self, problem, options, 0, |context| {
                let mut phi = Grid::filled(*context.problem.geometry(), 1.0);
                phi.data_mut()[5] = f32::NAN;
                Ok(Outcome {
                    fluence: vec![phi],
                    angular: None,
                    standard_error: None,
                    record: Record::exact(0),
                })
            })
        }
    }

    #[test]
    fn no_solution_leaves_the_driver_with_a_non_finite_value() {
        let geometry =
            lucent_grid::GridGeometry::new([4, 2, 2], glam::DVec3::ONE, glam::DVec3::ZERO).unwrap();
        let medium = crate::Medium {
            sigma_t: vec![Grid::filled(geometry, 1.0)],
            albedo: vec![crate::Field::Constant(0.5)],
            phase: lucent_optics::Phase::Isotropic,
        };
        let sun = Light::Directional {
            direction: glam::DVec3::Z,
            irradiance: crate::Spectrum::Grey(1.0),
        };
        let problem = Problem::new(geometry, medium, vec![sun], Boundary::Vacuum, None).unwrap();
        match Broken.solve(&problem, &SolveOptions::default()) {
            Err(SolveError::NonFiniteOutput { cell, what, .. }) => {
                assert_eq!((cell, what), ([1, 1, 0], "fluence"));
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn the_worse_record_is_kept_whatever_the_order() {
        let converged = record(StopReason::ConvergedRelative { residual: 1e-7 }, 30, 10);
        let limited = record(StopReason::IterationLimit { residual: 1e-3 }, 20, 5);
        let diverged = record(
            StopReason::DivergedGrowth {
                growth: 1e7,
                iteration: 3,
            },
            3,
            1,
        );
        for (a, b, kept) in [
            (&converged, &limited, &limited),
            (&limited, &converged, &limited),
            (&limited, &diverged, &diverged),
            (&diverged, &converged, &diverged),
        ] {
            let merged = a.clone().worse(b.clone());
            assert_eq!(merged.stop_reason, kept.stop_reason);
            assert_eq!(merged.memory_bytes, a.memory_bytes.max(b.memory_bytes));
        }
        // Equals: the one that iterated more.
        let longer = record(StopReason::ConvergedRelative { residual: 1e-7 }, 40, 1);
        assert_eq!(converged.clone().worse(longer.clone()).iterations, 40);
        assert_eq!(longer.worse(converged).iterations, 40);
    }
}
