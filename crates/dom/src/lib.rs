//! Discrete ordinates with transport sweeps (Bernabei's thesis, chapter 5): the
//! accurate deterministic solver for media where diffusion fails (strongly anisotropic
//! scattering, low albedo, optically thin regions).
//!
//! # What it solves
//!
//! The steady radiative transfer equation for the radiance L(x, ω) (W/length²/sr),
//!
//! ω·∇L + σ_t L = σ_s ∫ p(ω′ → ω) L(x, ω′) dω′ + Q(x, ω),
//!
//! with σ_t, σ_s in 1/length and Q the fixed source per steradian. As in Bernabei's MDOM,
//! the light of point-like lights is not swept: its uncollided part is integrated over each
//! cell (`lucent_core::uncollided_cells`, which conserves the light's power whatever the
//! grid) and enters as the first-collision source Q = σ_s Σ_l p(ω_l → ω) E_l T_l averaged
//! over the cell, so the sweeps carry only scattered light (and sky light and emission,
//! which are smooth in angle) and ray effects stay small.
//!
//! # How
//!
//! - [`angular`]: N propagation directions (level-symmetric S_N or the nested octahedral
//!   family of `lucent-optics`), M ≤ N storage directions with a Sinkhorn-normalised
//!   interpolation (Bernabei's is off by ±15%: docs/reference-cases.md), and a discrete phase
//!   matrix normalised to conserve energy exactly and corrected to the phase function's g.
//! - [`sweep`]: the eight octant sweeps, wavefronts of blocks (I + J + K = const), in
//!   parallel over the blocks of a hyperplane and cell by cell inside each block, each
//!   block filling its own source; the per-direction work in memory or in f64 pages of a
//!   pager ([`WorkPages`], [`SourceIteration::sweep_only`]), bit for bit the same.
//! - [`closure`]: step, diamond difference with the set-to-zero fix-up, and Bernabei's
//!   exponential face-to-face short characteristic (exact as σ_t → 0 and along axes; its
//!   error at σ_t h ≥ 1 is measured in the tests).
//! - [`solve`]: source iteration, stopped on the scattering source's change scaled by the
//!   measured contraction 1/(1 − ρ) (a plain change test stops far too early when
//!   ρ → 1), with diffusion synthetic acceleration on `lucent-diffusion`'s multigrid;
//!   or (`Outer::Gmres`) restarted GMRES on the DSA-preconditioned fixed point, one sweep
//!   per Krylov iteration, with the closures' linear forms (no positivity fix-up), followed
//!   by source-iteration steps with the closure as set. Measured: at albedo 0.95 with the
//!   step closure it needs 14 sweeps at g = 0.6 and 22 at g = 0.9 where DSA alone needs 21
//!   and 36, and half of source iteration's sweeps under a reflecting boundary; with
//!   diamond difference the fix-up's settling after it costs more than it saves, so source
//!   iteration with DSA and Anderson mixing stays the default (tests/it/krylov.rs).
//! - `Acceleration::Tsa`, for either outer iteration: transport synthetic acceleration of
//!   the isotropic and first moments (Ramoné, Adams & Nowak 1997). DSA leaves the first
//!   moments' error, which contracts by about ωg per sweep; after each sweep TSA solves
//!   the error equation (L − σ_s S) e = σ_s (J^{k+½} − J^k) projected onto P0 and P1 on
//!   the eight S2 directions (two DSA-accelerated S2 sweeps from zero, a fixed linear
//!   map) and adds the P1 part of S e to the in-scattered radiance. Measured at albedo
//!   0.95, g = 0.6: 10 sweeps with GMRES and 11 with source iteration where GMRES with
//!   DSA needs 14 and DSA alone 21; at g = 0.9 it saves nothing (the error left is in the
//!   second and higher moments, which S2 cannot carry) and delta-M is what helps. Each S2
//!   sweep costs about a quarter of an S6 sweep plus a DSA correction, so at 128³ source
//!   iteration with TSA (8 sweeps) takes as long as with DSA (12): DSA stays the default,
//!   the more so on a device, where TSA's S2 sweeps would run on the host. In thick
//!   cells it outdoes DSA up to σ_t h = 4 (with diamond at σ_t h = 2 it converges
//!   without mixing where DSA alone is dropped); beyond, its S2 problem's own DSA
//!   amplifies as DSA does, and TSA refuses such cells.
//! - [`device`]: the seam of a device's transport steps (`gpu-dom` in
//!   `lucent-gpu-solvers`): the iteration above runs on the host around them.
//! - Boundaries: vacuum, a uniform incoming radiance (sky), and diffuse reflection of a
//!   fraction R of the outgoing partial current (Robin-like; R = F_dr for a mismatched
//!   index, 1 for a reflecting box).
//! - `dom` in the registry ([`DomSolver`]): fluence plus the in-scattered radiance at the
//!   storage directions, which the renderer evaluates phase-weighted.
//!
//! # Stability and accuracy
//!
//! The sweeps are implicit in space: no step limit. Source iteration contracts like the
//! scattering ratio ω per sweep (ρ → 1 as ω → 1 in thick media). DSA removes that: at
//! albedo 0.999 and σ_t h = 0.67 it reaches 10⁻⁶ in 21 sweeps (12 with Anderson mixing),
//! where plain iteration would need about 390. DSA with lucent-diffusion's cell-centred
//! operator is not consistent with the transport closures: with diamond difference at
//! σ_t h = 2 it amplifies the error and the solver drops it (`dsa_abandoned`); Anderson
//! mixing on top converges there in 14 sweeps, and with the exponential closure at
//! σ_t h = 8 in 52 (all in tests/it/transport.rs). DSA accelerates the isotropic error only:
//! with strongly forward scattering the first-moment error still contracts by about ωg per
//! sweep. Diamond difference is second order in thin cells and needs its fix-up (first order, positive) in thick ones; step is
//! first order and positive; the exponential closure is exact along the axes and for
//! σ_t → 0, and its mean-chord attenuation errs by up to 50% at σ_t h = 5.
//!
//! ```
//! use lucent_dom::{DomBoundary, DomProblem, DomSettings, angular::Ordinates, solve};
//! use lucent_grid::GridGeometry;
//! use lucent_optics::{Phase, SphericalQuadrature};
//!
//! // A 12³ cube of albedo 0.9 glowing uniformly, vacuum outside.
//! let geometry = GridGeometry::from_bounds([12; 3], Default::default(), [1.0; 3].into())?;
//! let ordinates = Ordinates::new(SphericalQuadrature::level_symmetric(4)?, None, Phase::Isotropic)?;
//! let n = geometry.voxel_count();
//! let m = ordinates.storage().len();
//! let problem = DomProblem {
//!     geometry,
//!     sigma_t: vec![10.0; n],
//!     sigma_s: vec![9.0; n],
//!     fixed: vec![1.0; n * m],
//!     boundary: DomBoundary::default(),
//! };
//! let stopping = lucent_core::Stopping { relative_tolerance: 1e-7, ..Default::default() };
//! let solution = solve(&problem, &ordinates, &DomSettings::default(), &stopping)?;
//! assert!(solution.convergence.stop_reason.is_converged(), "{:?}", solution.convergence);
//! assert!(solution.balance.relative_imbalance() < 1e-6, "{:?}", solution.balance);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod anderson;
pub mod angular;
pub mod closure;
mod delta_m;
pub mod device;
mod dsa;
mod error;
mod gmres;
mod params;
mod solve;
mod solver;
pub mod sweep;

pub use closure::Closure;
pub use delta_m::{DeltaM, legendre_moment};
pub use error::DomError;
pub use params::{DomParams, Family};
pub use solve::{
    Acceleration, DomBalance, DomBoundary, DomConvergence, DomProblem, DomSettings, DomSolution,
    Outer, PagedWork, SourceIteration, SweepOnly, solve,
};
pub use solver::{DomChannel, DomSolver, first_sweep_source};
pub use sweep::WorkPages;
