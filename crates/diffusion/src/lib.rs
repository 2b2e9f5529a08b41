//! Steady diffusion of light with an embedded boundary, solved by geometric multigrid
//! (Mertens 2005, chapter 4; docs/reference-cases.md).
//!
//! # What it solves
//!
//! −∇·(D∇φ) + σ_a φ = Q₀ − 3∇·(D Q₁) in the medium Ω, for the fluence φ (W/length²), with
//! D = 1/(3σ_t′) (length), σ_t′ = σ_a + (1 − g)σ_s, σ_a (1/length), an isotropic source
//! density Q₀ and first moment Q₁ (W/length³). The Q₁ sign is the one derived from the P1
//! moment equations (Jensen et al. 2001, eq. 6); Mertens' thesis prints it reversed
//! (derived, not the thesis's: docs/reference-cases.md).
//!
//! Boundaries, on an embedded surface given by a signed distance function and on the
//! grid's box, each with its own condition:
//! - Robin φ + 2AD ∂φ/∂n = 6AD Q₁·n (the extrapolated boundary; A ≥ 1 from the relative
//!   index, `lucent_core::Boundary::robin_factor`), exitance φ/(2A);
//! - Dirichlet φ = g; Neumann (given outward flux, 0 reflecting).
//!
//! # How
//!
//! Cell-centred finite volumes on cut cells ([`geometry`]): volume fractions, face
//! apertures and boundary facets from the SDF, the Robin flux substituted into the facet
//! (Johansen & Colella 1998; Schwartz et al. 2006). The equations are kept in integrated
//! form (multiplied by the cell volume), so A is a symmetric M-matrix, conservation is exact
//! (emitted = absorbed + escaped to solver tolerance) and **tiny cut cells need no special
//! treatment**: their rows shrink with them, there is no explicit time step for them to
//! limit, and the implicit solvers converge regardless (no cell merging, no small-cell
//! CFL). [`Discretisation::Staircase`] is the plain finite-difference alternative, to
//! reproduce Mertens' Figure 4.1.
//!
//! Solvers ([`Method`]): matrix-free geometric multigrid (V, W, F and K cycles, full
//! multigrid, red–black Gauss–Seidel or weighted Jacobi smoothers, rediscretised coarse
//! operators, f32 cycles on an f64 correction), and on the same operator the baselines
//! Jacobi, red–black SOR, Jacobi-preconditioned CG and multigrid-preconditioned CG
//! (flexible CG under the K-cycle).
//!
//! Jumps of D: where the coarse levels cannot see a jump inside a coarse cell, plain V-cycles
//! slow to 0.6–0.8 per cycle. The K-cycle (two flexible-CG steps per coarse level, Notay &
//! Vassilevski 2008) as the preconditioner of flexible CG reaches 1e-8 in 6–14 iterations on
//! jumps of 10³ (balls, tilted layers, random blocks a few coarse cells wide; tested).
//!
//! On several ranks (processes under MPI, or threads), `Multigrid::solve_on_ranks` runs
//! the same cycles over z-slabs or a Cartesian grid of boxes ([`Decomposition`]) with
//! one-cell halos, and agglomerates the coarse levels
//! onto fewer ranks as they shrink, down to rank 0 for the coarsest ([`RankLayout`]); φ
//! and the history are [`Multigrid::solve`]'s bits on any rank count (both sum their
//! norms over runs of eight cells along x, added exactly). Every rank builds the whole
//! hierarchy there; for a medium that fills the box,
//! [`SlabSystem::solve_multigrid_on_layout`] builds each rank's part of every level from
//! its own box of the medium and returns φ on that box, with the same bits: no rank holds
//! the whole volume, hierarchy or solution.
//!
//! For solvers that stream their fields slab by slab (out of core), [`slab`] gives the
//! same system row by row for a medium that fills the box: the assembled matrix's rows and
//! right-hand side, bit for bit, from slabs of D, σ_a and the sources.
//!
//! # Accuracy and limits
//!
//! Second order in h away from sources (point sources are spread over eight cells by
//! trilinear weights). Diffusion itself holds a few transport mean free paths from
//! sources and boundaries in media with α′ ≈ 1. Implicit: no stability limit on h.
//!
//! ```
//! use glam::DVec3;
//! use lucent_diffusion::{Boundaries, CellGeometry, Condition, Discretisation,
//!     DiffusionProblem, Method, Sources, solve};
//! use lucent_core::Stopping;
//! use lucent_grid::GridGeometry;
//!
//! // A marble sphere of radius 5 mm with a unit point source at its centre.
//! let grid = GridGeometry::from_bounds([24; 3], DVec3::splat(-6.0), DVec3::splat(6.0))?;
//! let cells = CellGeometry::from_sdf(grid, |p| p.length() - 5.0, Discretisation::EmbeddedBoundary)?;
//! let n = grid.voxel_count();
//! let (sigma_a, sigma_s_reduced) = (0.0021f32, 2.19f32);
//! let d = 1.0 / (3.0 * (sigma_a + sigma_s_reduced));
//! let problem = DiffusionProblem::new(cells, vec![d; n], vec![sigma_a; n],
//!     Boundaries::uniform(Condition::Robin { a: 2.341 }))?;
//! let sources = Sources { points: vec![(DVec3::new(0.1, 0.05, -0.02), 1.0)], ..Sources::default() };
//! let solution = solve(&problem, &sources, Method::default(), &Stopping::default())?;
//! assert!(solution.convergence.stop_reason.is_converged());
//! assert!(solution.balance.relative_imbalance() < 1e-6);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod error;
pub mod geometry;
mod krylov;
mod level;
mod multigrid;
mod params;
mod problem;
mod ranks;
mod region;
pub mod slab;
mod solve;
mod solver;

pub use error::DiffusionError;
pub use geometry::{CellGeometry, Discretisation, Patch, Side};
pub use krylov::optimal_sor_factor;
pub use multigrid::{
    Convergence, Cycle, LevelOperator, Multigrid, MultigridSettings, Prolongation, Smoother,
};
pub use params::{
    CgParams, CycleParam, DecompositionParam, DiscretisationParam, JacobiParams, MAX_RANKS,
    MultigridParams, RANKS, SmootherParam, SorParams, check_ranks,
};
pub use problem::{AssembledSystem, Balance, Boundaries, Condition, DiffusionProblem, Sources};
pub use ranks::{BoxSolution, Decomposition, RankLayout, Stage};
pub use region::Region;
pub use slab::SlabSystem;
pub use solve::{DiffusionSolution, Method, RanksOf, solve, solve_on_ranks};
pub use solver::{DiffusionSolver, LinearSolve, conditions};
