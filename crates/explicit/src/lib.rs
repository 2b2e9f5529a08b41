//! Explicit schemes of the seeds, implemented faithfully, with their true stability limits
//! (Murray's thesis ch. 3–4; Zhang & Ma's paper; the checked cases and corrections are in
//! docs/reference-cases.md).
//!
//! | module | scheme | equation | stable for (correct bound) | the paper said |
//! |---|---|---|---|---|
//! | [`ftcs`] | FTCS diffusion (Murray Eq. 4.8) | (1/c)∂φ/∂t = ∇·(D∇φ) − σ_a φ + q | cΔt ≤ 2/(σ_a + 12D/h²) | Eq. 4.9, 2.2–3× smaller |
//! | [`p1`] | FTCS P1 moments, collocated or staggered | (1/c)∂φ/∂t = −∇·E − σ_aφ + q, (1/c)∂E/∂t = −∇φ/3 − σ_t′E | (1−K_φ)(1−K_E) + r² ≤ 1 (staggered 4r²) | K < 1, r/2 < 1 (insufficient) |
//! | [`ordinates`] | FTCS upwind discrete ordinates | (1/c)∂L/∂t + ω·∇L = −σ_t L + (σ_sφ + q)/4π | rS ≤ 1 − K/2 | none |
//! | [`convection`] | upwind convection–absorption (Zhang & Ma Eq. 16) | ∂ρ/∂t = −c u·∇ρ − σ_a ρ | C(\|u\|+\|v\|+\|w\|) ≤ 1 | C ≤ 1 (1D only) |
//! | [`scatter`] | implicit Neumann diffusion (Zhang & Ma Eq. 23) | ∂L/∂t = σ_s∇²L | unconditional (backward Euler) | – |
//! | [`steady`] | FTCS and Jacobi on lucent-diffusion's system | V dφ/dτ = b − Aφ | cΔt ≤ 2V/λ_max(A) | – |
//!
//! Units: lengths in the lattice's unit; c Δt is a length; σ in 1/length; D in length;
//! r = cΔt/h and C = cΔt/Δx are dimensionless. Fields are f64: these are reference and
//! study schemes whose tests measure growth factors to 1% and conservation to 1e-10,
//! which f32 rounding would blur.
//!
//! Out of core (`Solver::solve_paged` on a `lucent_core::PagedProblem`) every registry
//! entry gives the in-memory bits: `convection-diffusion` (its characteristic absorption
//! march, plane by plane), `ftcs-diffusion`/`jacobi-diffusion` (b, φ and r streamed as f64
//! slab pages, the system's rows built slab by slab by `lucent_diffusion::SlabSystem`),
//! `ftcs-p1` and `ftcs-ordinates` (the state twice in f64 slab pages, each step from a ring
//! of three old slabs).
//!
//! On several ranks, [`ranks::iterate_on`] runs `steady`'s FTCS and Jacobi over z-slabs or
//! a Cartesian grid of boxes ([`ranks::Boxes`]; [`ranks::iterate_block`] the same over
//! slabs or boxes from rows each rank builds for its own cells of a box medium, so no rank
//! holds the whole system); their norms sum fixed runs of eight cells along x and add the run
//! sums exactly (`lucent_core::exact`), so the bits do not depend on the split
//! (`docs/ranks.md`);
//! [`ranks::march_p1_on`] the P1 march (zero edges) over z-slabs or boxes, its change norm
//! summed the same way ([`ranks::march_p1_box`] with each rank holding only its box of the
//! source and of the state); and [`wavefront::propagate_on_ranks`]
//! Zhang & Ma's one-pass absorption march of a distant light over z-slabs (a pipelined
//! wavefront where the light crosses the slabs, planes in lock step where it runs along
//! them) or a grid of boxes (the KBA sweep, [`wavefront::propagate_box`]), on any
//! `lucent_core::ranks::Communicator` (threads here, MPI through `lucent-mpi`), with the
//! serial bits on any number of ranks.
//!
//! Every march checks its step against [`stability`] before running and refuses a step
//! beyond the correct bound with [`ExplicitError::Unstable`] unless the study option
//! `allow_unstable` is set; a growth monitor stops a diverging run with
//! `StopReason::DivergedGrowth` and returns the last finite field. No scheme returns NaN
//! or infinity.
//!
//! ```
//! use lucent_explicit::{Lattice, stability};
//! use lucent_explicit::convection::{Light, UpwindSettings, propagate};
//! use glam::DVec3;
//!
//! // Zhang & Ma's T2: axis-aligned light through σ_a = 0.1 per step at C = ½ decays by
//! // (1 − σ_a)/(1 + σ_a) per cell.
//! let lattice = Lattice::new([16, 1, 1], 1.0)?;
//! let light = Light::Distant { direction: DVec3::X, density: 1.0 };
//! let out = propagate(&lattice, &vec![0.1; 16], &light, &UpwindSettings::default())?;
//! let q: f64 = 0.9 / 1.1;
//! assert!((out.density[9] - q.powi(10)).abs() < 1e-9);
//! assert!((stability::upwind::courant_limit(DVec3::ONE.normalize()) - 1.0 / 3f64.sqrt()).abs() < 1e-12);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod convection;
mod error;
pub mod ftcs;
mod lattice;
pub mod ordinates;
pub mod p1;
mod paged;
mod paged_march;
mod paged_steady;
mod params;
pub mod ranks;
pub mod scatter;
mod solver;
pub mod stability;
pub mod steady;
pub mod wavefront;

pub use error::ExplicitError;
pub use lattice::{GrowthMonitor, Lattice};
pub use params::{
    ConvectionParams, DecompositionParam, FtcsDiffusionParams, JacobiDiffusionParams,
    OrdinatesParams, P1Params, SweepParam,
};
pub use solver::{ExplicitSolver, lattice, point_and_emission};
