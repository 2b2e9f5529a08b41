//! # lucent-mc: Monte Carlo ground truth
//!
//! Unbiased estimates of the fluence φ = ∫ L dω for the same [`Problem`]s every other solver
//! takes, with a standard error per cell, so that deterministic solvers can be judged.
//!
//! ## Method
//! Light is traced *forward* from the lights (particle tracing): each light emits particles
//! carrying its power (directional: the faces facing the beam, by projected area, power E·A_⊥; point: 4πI;
//! spot: uniform in the outer cone, weighted by the fall-off; sky: πL·A through the box
//! faces, cosine-weighted; emission: cells proposed by the largest neighbouring value, a
//! uniform point, power weighted by the trilinear Q(x) over the proposal). A particle flies by **delta tracking** against a coarse
//! **majorant grid** walked by a 3D DDA (the majorant of a coarse cell bounds the trilinear
//! extinction inside it, so tracking is exact, and thin regions are crossed in long steps;
//! every walk — particle flights, camera paths, shadow rays — is clipped to the grid's box
//! in that one place, since the coarse grid sticks out of it when a dimension is not a
//! multiple of the block size):
//! tentative collisions at rate σ̄, accepted with probability σ_t(x)/σ̄. At a real collision
//! the absorbed share w(1 − α) is tallied and the particle continues with weight wα
//! (implicit capture), scatters by sampling the phase function exactly, and plays Russian
//! roulette once its weight falls below a tenth of its start.
//!
//! The **track-length estimator** φ_cell = (1/V) Σ w ℓ_cell adds every free flight's length
//! inside each cell it crosses (an exact DDA), so every particle informs every cell it
//! passes, not only those it collides in. Independent **batches** give the per-cell standard
//! error. A grey extinction traces every channel at once (RGB albedo and light colours ride
//! on per-channel weights); an RGB extinction is traced with **spectral MIS**: one hero
//! channel per path picks distances and real or null collisions against a shared majorant
//! (the largest of the three extinctions), and every channel is weighted by the balance
//! heuristic over the three heroes — one path instead of three, unbiased; the fluence
//! tallies every piece between tentative collisions with the weights of its start
//! (`tests/it/transport.rs` and `tests/it/camera.rs` check both estimators against per-channel
//! tracing). With embedded geometry the fluence falls back to per-channel tracing.
//!
//! ## Determinism
//! Every path draws from a counter-based stream keyed by (seed, batch, light, path), and
//! batch tallies are summed in batch order: the same seed gives bitwise identical results
//! for any thread count.
//!
//! ## Out of core
//! On a paged medium (`Solver::solve_paged`, Bernabei ch. 5) the same tracer reads σ_t and
//! the albedo brick by brick through the pager, takes its majorant from the bricks' ranges
//! (brick and apron bound the trilinear σ_t: no pass over the medium; `majorant_cells` is
//! then the brick size), and pages its tallies: each batch logs its track lengths and
//! applies them to f64 pages sorted by brick with a stable sort, so every cell receives its
//! additions in path order, and the pages are folded into Σφ and Σφ² in batch order. With
//! bricks of `majorant_cells`³ cells the result has the in-memory solve's bits
//! (`tests/it/paged.rs`). The medium gets half of the memory budget; the tallies' logs and
//! pages the rest.
//!
//! ## Units and limits
//! Scene units, fluence in W/length² for lights in W. The box faces are vacuum boundaries.
//! With embedded geometry (a signed distance grid, negative inside) the medium is the
//! inside of its zero level, found by sphere tracing the trilinear SDF with bisection; a
//! Robin boundary of relative index η there becomes, for transport, a smooth dielectric
//! interface: Fresnel reflection (total internal reflection included) or Snell refraction.
//! Camera paths pick up volumetric emission at every tentative collision (Q(x)/σ̄, with the
//! majorant floored at one per cell wherever something emits, so empty emitting space is
//! seen too). Camera images handle index-matched embedded geometry (the surface only bounds the
//! medium); through a refracting one they would need manifold next-event estimation and
//! are refused. The energy balance (emitted =
//! absorbed + escaped + truncated) holds per path in expectation.
//!
//! ## Example
//! ```
//! use glam::DVec3;
//! use lucent_core::{Boundary, Field, Light, Medium, Problem, Spectrum};
//! use lucent_grid::{Grid, GridGeometry};
//! use lucent_mc::{McConfig, estimate};
//! use lucent_optics::Phase;
//!
//! // A pure absorber lit along +x: the transmitted power is e^{−σ_t L} of the emitted.
//! let geometry = GridGeometry::new([4, 4, 4], DVec3::splat(0.25), DVec3::ZERO)?;
//! let medium = Medium { sigma_t: vec![Grid::filled(geometry, 2.0)], albedo: vec![Field::Constant(0.0)], phase: Phase::Isotropic};
//! let sun = Light::Directional { direction: DVec3::X, irradiance: Spectrum::Grey(1.0) };
//! let problem = Problem::new(geometry, medium, vec![sun], Boundary::Vacuum, None)?;
//! let run = estimate(&problem, &McConfig { particles: 4000, batches: 8, ..Default::default() })?;
//! let e = &run.energy[0];
//! let transmitted = e.escaped.mean / e.emitted.mean;
//! assert!((transmitted - (-2.0f64).exp()).abs() < 0.03);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod camera;
mod majorant;
mod paged;
mod params;
mod rng;
mod solver;
mod transport;

pub use camera::{CameraEstimate, camera_image, camera_image_with_progress};
pub use majorant::MajorantGrid;
pub use params::McParams;
pub use rng::PathRng;
pub use solver::McSolver;
pub use transport::{
    EnergyBalance, Estimate, MAX_OPTICAL_REACH, McConfig, McEstimate, RunControl,
    check_optical_reach, estimate, estimate_with,
};

#[cfg(doc)]
use lucent_core::Problem;
