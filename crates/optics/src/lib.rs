//! # lucent-optics: how light meets a participating medium at one point
//!
//! Everything a light-transport solver needs to know about the medium *locally*, and the
//! closed-form solutions every solver is checked against. No grids, no files, no solvers.
//!
//! ## Units and conventions
//! - Lengths are in **scene units** and coefficients in **inverse scene units**; the crate
//!   never assumes a unit. The measured table ([`materials::JENSEN_2001`]) is in mm⁻¹ and
//!   converts with [`MeasuredMaterial::rgb`].
//! - Directions are unit vectors of **propagation**; phase functions take the direction of
//!   travel before and after scattering, cos θ = ω_in·ω_out, g > 0 forward.
//! - Phase functions are densities per steradian **normalised to 1** over the sphere.
//!   (Murray's seed prints Henyey–Greenstein without 1/(4π); lucent never uses that form.)
//! - Radiance L (W m⁻² sr⁻¹), fluence φ = ∫_{4π} L dω (W m⁻²), flux vector E = ∫ L ω dω.
//! - Everything is computed in `f64`: this crate defines references, not hot loops.
//!
//! ## Equations
//! The radiative transfer equation for radiance L(x, ω), with σ_t = σ_a + σ_s:
//!
//! ω·∇L = −σ_t L + σ_s ∫_{4π} p(ω′·ω) L(x, ω′) dω′ + Q.
//!
//! Its diffusion (P1) limit for φ, with the reduced coefficients σ_s′ = (1 − g)σ_s,
//! σ_t′ = σ_a + σ_s′, D = 1/(3σ_t′) and σ_tr = √(3σ_a σ_t′):
//!
//! −∇·(D∇φ) + σ_a φ = Q₀ − 3∇·(D Q₁),
//!
//! (the sign of the first-moment term is printed wrongly in Mertens' thesis, see
//! docs/reference-cases.md), with the Robin boundary condition
//! φ + 2AD ∂φ/∂n = 0, A = (1 + F_dr)/(1 − F_dr), whose exitance is φ/(2A).
//!
//! ## Contents
//! - [`OpticalCoefficients`]: σ_a, σ_s, g, validated, and everything derived from them.
//! - [`phase`]: the [`PhaseFunction`] trait (evaluate, sample exactly, mean cosine,
//!   Legendre moments) for isotropic, Henyey–Greenstein, double Henyey–Greenstein and
//!   Rayleigh scattering, and the [`Phase`] enum that dispatches them without trait objects.
//! - [`quadrature`]: spherical quadratures (level-symmetric S_N, nested octahedral,
//!   Fibonacci) whose weights sum to 4π.
//! - [`fresnel`]: dielectric Fresnel reflectance, diffuse reflectance F_dr (exact and the
//!   Groenhuis fit), the boundary factor A.
//! - [`analytic`]: Beer–Lambert, the infinite-medium Green's function, the dipole R_d(r),
//!   and exact Robin solutions for a sphere, a half-space and a slab.
//! - [`materials`]: Jensen et al. 2001's measured table.
//! - [`integrate`]: the Gauss–Legendre and adaptive Gauss–Kronrod rules used above.
//! - [`eikonal`]: rays through a varying refractive index (d/ds(η dx/ds) = ∇η, RK4 with
//!   step control; uniform, linear and Luneburg indices).
//!
//! ## Stability and validity limits
//! - |g| < 1 everywhere (|g| = 1 is a delta function); Henyey–Greenstein sampling and
//!   evaluation stay accurate up to |g| = 1 − 1e-6.
//! - Diffusion results (the [`analytic`] module) need σ_s′ ≫ σ_a and distances beyond a
//!   transport mean free path from sources; the closed forms themselves are exact solutions
//!   of the diffusion equation and need σ_a > 0.
//!
//! Every constructor refuses negative, NaN or infinite input with an [`OpticsError`].
//!
//! ## Example
//! ```
//! use glam::DVec3;
//! use lucent_optics::{Dielectric, DiffuseFresnel, DiffusionMedium, MeasuredMaterial, Phase, PhaseFunction};
//!
//! // Marble's red channel (mm⁻¹) behind an η = 1.3 surface.
//! let marble = MeasuredMaterial::by_name("marble")?.channel(0, 0.0)?;
//! let medium = DiffusionMedium::with_boundary(marble, Dielectric::new(1.3)?, DiffuseFresnel::Groenhuis)?;
//! assert!((medium.d() - 0.152061).abs() < 1e-6);
//! assert!((medium.dipole().total_reflectance() - 0.86654).abs() < 1e-5);
//!
//! // A forward-scattering lobe, sampled exactly: the pdf is the phase function.
//! let phase = Phase::henyey_greenstein(0.8)?;
//! let s = phase.sample(DVec3::Z, [0.3, 0.7]);
//! assert!((s.pdf - phase.eval(DVec3::Z, s.omega_out)).abs() < 1e-12);
//!
//! // Bad input is a typed error, not a NaN.
//! assert!(lucent_optics::OpticalCoefficients::new(-1.0, 1.0, 0.0).is_err());
//! # Ok::<(), lucent_optics::OpticsError>(())
//! ```

pub mod analytic;
mod coefficients;
pub mod eikonal;
mod error;
pub mod fresnel;
pub mod integrate;
pub mod materials;
pub mod milne;
pub mod phase;
pub mod quadrature;
mod significant;

pub use analytic::{DiffusionMedium, RobinDisc};
pub use coefficients::OpticalCoefficients;
pub use error::OpticsError;
pub use fresnel::{Dielectric, DiffuseFresnel};
pub use materials::MeasuredMaterial;
pub use phase::{Phase, PhaseFunction, PhaseSample};
pub use quadrature::SphericalQuadrature;
pub use significant::Significant;
