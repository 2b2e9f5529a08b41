//! Finite elements for the RTE and for diffusion (Murray's thesis, chapter 3).
//!
//! - [`murray`]: Murray's discretisation of the steady RTE without in-scattering,
//!   ω·∇L = Q_e − K_t L, Galerkin in the angular basis {1, ω_x, ω_y, ω_z} times trilinear
//!   hat functions: the α, β, γ, δ matrices of docs/reference-cases.md, exactly.
//!   Jacobi on it diverges for every K_t: the iteration matrix's spectral radius is at least
//!   19/8 (the mass matrix's off-diagonal sum 19/27 exceeds its diagonal 8/27), and grows
//!   like 1/(K_tΔ) when streaming dominates. It is a non-symmetric system: Krylov methods
//!   or a direct solve are the sound way to it.
//! - [`solvers`]: Jacobi and Gauss–Seidel on sparse matrices, BiCGSTAB and restarted GMRES
//!   on any [`LinearOperator`], dense LU for small systems; residual histories and PETSc-style
//!   stop reasons.
//! - `fem-p1-jacobi` in the registry ([`FemP1Solver`]): Murray's system by Jacobi, kept
//!   for the stability study (it ends with `DivergedGrowth`).
//!
//! - [`q1`]: Q1 (trilinear) Galerkin diffusion with heterogeneous D and σ_a and a Robin
//!   box, CG preconditioned by geometric multigrid on the element hierarchy (Galerkin
//!   coarse operators): `fem-diffusion` ([`FemDiffusionSolver`]). Second order.
//!
//! - [`sphere`]: the same elements on boundary-fitted meshes of star-shaped bodies (the
//!   cube lattice mapped radially onto the surface), isoparametric, for curved Robin
//!   boundaries (Mertens T7): the ball, and any embedded SDF body through the registry.
//!
//! - [`p1ls`]: the steady P1 system with in-scattering and anisotropy (σ_t′), stabilised
//!   by least squares: SPD, no checkerboard, second order in φ; 4 unknowns per vertex and
//!   CG iterations growing like 1/h are its cost.
//!
//! `fem-diffusion` takes every light (external ones through `direct`'s first-collision
//! sources, like `diffusion-mg`) and is in the cross-check harness and the pareto charts.
//!
//! Tested against Mertens T7 (the ball) and T9 (the Robin half-space, per-face Robin
//! conditions on a column): second order, 0.03% and 0.017% at the finest meshes.
//!
//! With an embedded body, `fem-diffusion` meshes the body alone (it must be star-shaped
//! from the centroid of its inside cells; other shapes are refused with a typed error):
//! 0.55% from T7 at 32³ away from the source, second order, as `diffusion-mg`'s cut cells.
//!
//! Units: lengths in the mesh's unit, K_t in 1/length; the fluence is φ = 4π L_0 (the
//! angular basis's constant coefficient).
//!
//! ```
//! use lucent_fem::murray::{Mesh, MurraySystem};
//! // Mass-dominated (K_t Δ = 10): Jacobi's spectral radius is 19/8.
//! let mesh = Mesh { nodes: [6; 3], spacing: 1.0, periodic: true };
//! let system = MurraySystem::assemble(mesh, 10.0)?;
//! let rho = system.jacobi_spectral_radius(200);
//! assert!((rho / 2.375 - 1.0).abs() < 0.01);
//! # Ok::<(), lucent_fem::FemError>(())
//! ```

mod error;
pub mod murray;
mod operator;
pub mod p1ls;
mod params;
pub mod q1;
mod solver;
pub mod solvers;
pub mod sphere;

pub use error::FemError;
pub use operator::{Dense, LinearOperator};
pub use params::{FemDiffusionParams, FemP1Iteration, FemP1Params};
pub use solver::{FemDiffusionSolver, FemP1Solver};
