//! # lucent-core: the problem, the `Solver` trait, solutions, and the `direct` solver
//!
//! One trait joins every solver in lucent. A [`Problem`] is a medium on a cell-centred grid
//! (extinction σ_t, albedo, phase function), lights, a boundary condition
//! and optional embedded geometry. A [`Solver`] declares its [`Capabilities`] and turns a
//! problem into a [`Solution`]: the fluence φ = ∫ L dω per channel, optionally an angular
//! representation for phase-weighted in-scattering, and a [`SolveReport`] that says why it
//! stopped ([`StopReason`], in the manner of PETSc's KSP reasons). The [`Registry`] builds
//! solvers by name with [`Params`].
//!
//! ## Units and conventions
//! - Lengths in scene units, σ_t in 1/length; σ_s = albedo·σ_t, σ_a = (1 − albedo)·σ_t.
//! - The medium between cell centres is the trilinear interpolant of the cell values
//!   (clamped at the boundary, zero outside the box) — the same field the renderer samples.
//! - Radiometry: directional lights give irradiance E (W/m²) across the beam, point and
//!   spot lights intensity I (W/sr), the sky radiance L (W/m²/sr), emission W/m³/sr.
//!   Directions are directions of travel.
//! - Colour: every quantity is grey or RGB ([`Spectrum`]); a problem has one channel when
//!   everything is grey and costs one solve; otherwise three independent channels.
//!
//! ## Iterating
//! Every iterative method in lucent stops by one rule, [`Stopping`] with its [`History`]:
//! a non-finite residual (diverged), the relative then the absolute tolerance (converged),
//! growth past `divergence` × the initial residual (diverged), the iteration limit, the
//! time budget — in that order, each ending in its [`StopReason`].
//!
//! ## Driving a solver
//! Every registered solver runs through the [`driver`]: admission, option validation, the
//! memory estimate before allocation, the thread pool, progress and the time budget, and
//! the report. Methods that solve channel by channel implement [`driver::ChannelMethod`];
//! the driver then also sorts the lights, computes their uncollided light once, derives
//! each channel's coefficients (D = 1/(3σ_t′) with its floor, written once) and merges the
//! channels' reports by one rule.
//!
//! ## Solvers here
//! - [`DirectSolver`] (`direct`): uncollided light by exact ray marching of the optical
//!   depth; keeps per-light transmittance for exact single scattering. Later solvers use it
//!   for their source terms.
//!
//! ## Example
//! ```
//! use glam::DVec3;
//! use lucent_core::{Boundary, DirectSolver, Field, Light, Medium, Problem, SolveOptions, Solver, Spectrum};
//! use lucent_grid::{Grid, GridGeometry};
//! use lucent_optics::Phase;
//!
//! // A homogeneous slab of σ_t = 2 lit along +x.
//! let geometry = GridGeometry::new([16, 4, 4], DVec3::splat(0.125), DVec3::ZERO)?;
//! let medium = Medium {
//!     sigma_t: vec![Grid::filled(geometry, 2.0)],
//!     albedo: vec![Field::Constant(0.5)],
//!     phase: Phase::Isotropic,
//! };
//! let sun = Light::Directional { direction: DVec3::X, irradiance: Spectrum::Grey(1.0) };
//! let problem = Problem::new(geometry, medium, vec![sun], Boundary::Vacuum, None)?;
//! let solution = DirectSolver::default().solve(&problem, &SolveOptions::default())?;
//! // The last cell centre is 1.9375 deep: φ = e^{−2·1.9375}.
//! let phi = solution.fluence(0).get(15, 2, 2).unwrap();
//! assert!((f64::from(phi) - (-2.0f64 * 1.9375).exp()).abs() < 1e-6);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod direct;
pub mod driver;
mod error;
pub mod exact;
mod index;
mod interrupt;
mod iteration;
pub mod memory;
mod paged;
mod paged_collisions;
mod problem;
pub mod ranks;
pub mod reduce;
mod refractive;
pub mod regime;
mod registry;
mod singular;
mod solution;
mod solver;
mod spectrum;
mod uncollided;

pub use direct::{DirectSolver, light_distances, uncollided_outcome};
pub use error::{ProblemError, SolveError};
pub use index::{IndexGrid, RefractiveIndex};
pub use interrupt::{Halt, Interrupt};
pub use iteration::{History, Stopping};
pub use lucent_paging::PagerStats;
pub use paged::{CellMedium, PagedMedium, PagedProblem, PagedSolution, Storage, paging_error};
pub use paged_collisions::PagedFirstCollisions;
pub use problem::{Boundary, BoundaryKind, Field, Light, LightKind, Medium, Problem};
pub use refractive::DirectRefractiveSolver;
pub use registry::{
    ParamDoc, ParamValue, Params, Registry, SolverEntry, SolverParams, param_docs, resolved_params,
};
pub use singular::{
    SingularCell, SingularPart, point_source_singular_cells, point_source_singular_part,
    singular_reach,
};
pub use solution::{Angular, CurvedArrival, LightTransmittance, OrdinateRadiance, Solution};
pub use solver::{
    Capabilities, Composition, Decision, FluenceKind, ImageEstimate, ImageRequest, ImageSolver,
    Neighbour, OutputKind, Part, Progress, ProgressFn, Ranks, SolveOptions, SolveReport, Solver,
    StopReason,
};
pub use spectrum::Spectrum;
pub use uncollided::{Uncollided, UncollidedCells, uncollided_cells, uncollided_cells_within};
