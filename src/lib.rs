//! # lucent: light transport in participating media
//!
//! The facade of the lucent workspace. Each solver and support crate stands alone (pick
//! the one your renderer needs); this crate re-exports them under one roof for the `lucent`
//! command and for users who want everything.
//!
//! | module | crate | what it solves |
//! |---|---|---|
//! | [`optics`] | `lucent-optics` | coefficients, phase functions, spherical quadratures, Fresnel, analytic diffusion references |
//! | [`grid`] | `lucent-grid` | dense and bricked voxel grids, resampling, transfer functions, procedural volumes, volume files |
//!
//! See `ARCHITECTURE.md` at the repository root for the crate map and the data flow
//! volume → medium → problem → solver → solution → image.
//!
//! ```
//! use lucent::optics::{OpticalCoefficients, SphericalQuadrature};
//! let medium = OpticalCoefficients::from_extinction_albedo(2.0, 0.9, 0.5)?;
//! assert!((medium.sigma_t_reduced() - 1.1).abs() < 1e-12);
//! assert_eq!(SphericalQuadrature::octahedral(1)?.len(), 32);
//! # Ok::<(), lucent::optics::OpticsError>(())
//! ```

pub use lucent_grid as grid;
pub use lucent_optics as optics;
