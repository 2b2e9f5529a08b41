//! The `mc` solver: the registry face of [`crate::estimate`].

use lucent_core::driver::{self, Outcome, Record};
use lucent_core::{
    BoundaryKind, Capabilities, FluenceKind, ImageEstimate, ImageRequest, ImageSolver, LightKind,
    OutputKind, PagedProblem, PagedSolution, Params, Problem, Progress, Solution, SolveError,
    SolveOptions, Solver, SolverEntry, StopReason, param_docs, resolved_params,
};

use crate::params::McParams;
use crate::transport::{McConfig, RunControl, estimate_with};

/// Monte Carlo particle tracing as a [`Solver`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct McSolver {
    /// What to trace.
    pub config: McConfig,
    /// Paths per pixel for camera images.
    pub samples_per_pixel: usize,
}

impl Default for McSolver {
    fn default() -> Self {
        Self {
            config: McConfig::default(),
            samples_per_pixel: 64,
        }
    }
}

impl McSolver {
    /// What every paged solve checks first: the options and a vacuum box.
    fn check_paged(
        &self,
        problem: &PagedProblem,
        options: &SolveOptions,
    ) -> Result<(), SolveError> {
        options.validate()?;
        if !matches!(problem.boundary(), lucent_core::Boundary::Vacuum) {
            return Err(SolveError::Unsupported {
                solver: Self::NAME.into(),
                feature: format!("a {} boundary on a paged medium", problem.boundary()),
            });
        }
        Ok(())
    }

    /// The registry name.
    pub const NAME: &'static str = "mc";

    /// The registry entry ([`McParams`]).
    pub const ENTRY: SolverEntry = SolverEntry {
        name: Self::NAME,
        summary: "Monte Carlo particle tracing (delta tracking, track-length fluence with standard errors): the ground truth",
        build: |params| Ok(Box::new(Self::from_params(params)?)),
        params: param_docs::<McParams>,
        resolved: |p| resolved_params::<McParams>(p, Self::NAME),
    };

    /// Builds from registry parameters.
    pub fn from_params(params: &Params) -> Result<Self, SolveError> {
        let p: McParams = params.parse(Self::NAME)?;
        Ok(Self {
            config: McConfig {
                particles: p.particles,
                batches: p.batches,
                seed: p.seed,
                max_depth: p.max_depth,
                majorant_cells: p.majorant_cells,
                global_majorant: p.global_majorant,
                ..McConfig::default()
            },
            samples_per_pixel: p.spp,
        })
    }
}

impl Solver for McSolver {
    fn name(&self) -> &str {
        Self::NAME
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            anisotropic: true,
            heterogeneous: true,
            embedded_geometry: true,
            boundaries: vec![BoundaryKind::Vacuum, BoundaryKind::Robin],
            lights: vec![
                LightKind::Directional,
                LightKind::Point,
                LightKind::Spot,
                LightKind::Sky,
                LightKind::Emission,
            ],
            output: OutputKind::Fluence,
            fluence: FluenceKind::Total,
            robin_needs_embedded_surface: true,
            ..Capabilities::default()
        }
    }

    fn images(&self) -> Option<&dyn ImageSolver> {
        Some(self)
    }

    fn pages(&self) -> bool {
        true
    }

    /// Half: the other half holds the tallies' pool, which a paged solve takes from what
    /// the budget leaves beside the medium's pool.
    fn paged_medium_budget(&self, budget: u64) -> u64 {
        budget / 2
    }

    fn paged_memory(
        &self,
        problem: &PagedProblem,
        options: &SolveOptions,
    ) -> Result<u64, SolveError> {
        self.check_paged(problem, options)?;
        options.install(|| crate::paged::paged_memory(problem, options))?
    }

    fn solve_paged(
        &self,
        problem: &PagedProblem,
        options: &SolveOptions,
    ) -> Result<PagedSolution, SolveError> {
        self.check_paged(problem, options)?;
        options.install(|| crate::paged::solve_paged(self, problem, options))?
    }

    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
        let voxels = problem.geometry().voxel_count() as u64;
        let channels = problem.channels() as u64;
        let threads = options.threads.unwrap_or_else(rayon::current_num_threads) as u64;
        // Per running batch one f64 tally per channel, plus the f64 sums and the f32 results.
        let needed = voxels * channels * (8 * threads + 16 + 8);
        driver::run(self, problem, options, needed, |context| {
            // Progress after every round of batches; the time budget stops new rounds.
            let report = |done: usize, total: usize| {
                context.report(Progress {
                    stage: "batch",
                    fraction: done as f64 / total.max(1) as f64,
                    iteration: done,
                    residual: None,
                })
            };
            // Something to show before the first round of batches ends (dense media: tens
            // of seconds).
            report(0, self.config.batches);
            let control = RunControl {
                progress: Some(&report),
                interrupt: context.interrupt(),
            };
            let result = estimate_with(problem, &self.config, &control)?;
            // The achieved accuracy: the mean relative standard error over cells holding
            // more than a thousandth of the peak fluence.
            let phi = result.fluence[0].data();
            let peak = phi.iter().copied().fold(0.0f32, f32::max);
            let (sum, count) = phi
                .iter()
                .zip(result.standard_error[0].data())
                .filter(|(p, _)| **p > 1e-3 * peak)
                .fold((0.0, 0usize), |(s, n), (p, e)| {
                    (s + f64::from(*e / *p), n + 1)
                });
            let relative = if count > 0 { sum / count as f64 } else { 0.0 };
            Ok(Outcome {
                fluence: result.fluence,
                angular: None,
                standard_error: Some(result.standard_error),
                record: Record {
                    iterations: result.batches,
                    residuals: Vec::new(),
                    // Every batch asked for ran, or the time budget stopped the run early.
                    stop_reason: if result.batches < self.config.batches {
                        control
                            .interrupt
                            .halt()
                            .unwrap_or(lucent_core::Halt::TimeLimit)
                            .stop_reason(relative)
                    } else {
                        StopReason::Sampled {
                            relative_error: relative,
                        }
                    },
                    memory_bytes: needed,
                    paging: None,
                },
            })
        })
    }
}

impl ImageSolver for McSolver {
    /// Path-traced with next-event estimation, `samples_per_pixel` paths per pixel
    /// ([`crate::camera_image`]).
    fn image(
        &self,
        problem: &Problem,
        request: &ImageRequest<'_>,
    ) -> Result<ImageEstimate, SolveError> {
        self.admits(problem)?;
        let estimate = crate::camera_image_with_progress(
            problem,
            request.width,
            request.height,
            self.samples_per_pixel,
            request.background,
            &self.config,
            request.ray,
            request.progress,
            &request.interrupt,
        )?;
        Ok(ImageEstimate {
            width: estimate.width,
            height: estimate.height,
            radiance: estimate.radiance,
            std_error: estimate.std_error,
            rows_traced: estimate.rows_traced,
        })
    }
}
