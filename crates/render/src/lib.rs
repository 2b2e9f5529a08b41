//! # lucent-render: images from solutions
//!
//! Turns a [`Problem`] and its [`Solution`] into a picture by marching camera rays through
//! the medium and integrating the volume rendering equation
//!
//! L(x, ω) = ∫₀^d T(s) [σ_s(s) L_s(s, −ω) + Q_e(s)] ds + T(d) L_bg,  T(s) = e^{−∫₀^s σ_t},
//!
//! where the in-scattered radiance L_s = ∫ p L dω′ comes from the solution
//! ([`Solution::inscattered`]: phase-weighted where the solution is angular, σ_s φ/(4π)
//! otherwise) and Q_e from the problem's emission lights. Each step of length Δ takes the
//! medium and the source as constant and integrates them exactly:
//! ΔL = T·S·(1 − e^{−σ_t Δ})/σ_t, T ← T·e^{−σ_t Δ}, which stays stable for any σ_t Δ.
//! Steps are half the smallest cell by default, with a per-pixel jittered start so that
//! the remaining error shows as fine noise rather than banding; each channel's march ends
//! where the box ends or its transmittance has fallen below 10⁻⁴.
//!
//! With the feature `gpu`, [`render_gpu`] and [`render_on_device`] run the same march on
//! a GPU through `lucent-gpu` (`shaders/render.wgsl`, one invocation per pixel): the same
//! image within f32 rounding (10⁻⁵ of the image's peak, tested against [`render`] on
//! every kind of solution).
//!
//! Units: radiance in the units of the lights (W/m²/sr for unit irradiance). Images are
//! linear RGB; [`Image::to_srgb8`] applies exposure (in stops), a tone curve and the sRGB
//! transfer function. Output: 8-bit sRGB PNG (`image` crate) and linear f32 EXR (`exr`).
//!
//! **Architecture invariant:** the only crate that knows about cameras and pixels; it never
//! solves anything, it only reads solutions.
//!
//! ## Example
//! ```
//! use lucent_render::{Camera, Image, ToneMap};
//! // A pinhole camera's centre ray points at its target.
//! let camera = Camera::Pinhole { position: [0.0, -4.0, 0.0], look_at: [0.0; 3], up: [0.0, 0.0, 1.0], fov: 40.0 };
//! let (origin, direction) = camera.ray(0.5, 0.5, 4.0 / 3.0)?;
//! assert_eq!(origin.y, -4.0);
//! assert!((direction.y - 1.0).abs() < 1e-12);
//! // Linear radiance 0.5 is sRGB code 188 without tone compression.
//! let image = Image { width: 1, height: 1, pixels: vec![[0.5; 3]] };
//! assert_eq!(image.to_srgb8(0.0, ToneMap::Clamp), vec![188, 188, 188]);
//! # Ok::<(), lucent_render::RenderError>(())
//! ```

mod camera;
#[cfg(feature = "gpu")]
mod gpu;
mod image_io;
mod march;

pub use camera::Camera;
#[cfg(feature = "gpu")]
pub use gpu::{render_gpu, render_on_device};
pub use image_io::{Image, ToneMap};
pub use march::{RenderSettings, render};

#[cfg(doc)]
use lucent_core::{Problem, Solution};
use thiserror::Error;

/// Why an image could not be made or written.
#[derive(Debug, Error)]
pub enum RenderError {
    /// Invalid camera or settings.
    #[error("invalid render setting: {0}")]
    Invalid(String),
    /// The GPU march could not run: no adapter, a grid or image beyond one of the
    /// adapter's limits (named), a value the device must not see, or a device failure.
    #[error("GPU render: {reason}")]
    Device {
        /// What went wrong, from the GPU layer.
        reason: String,
        /// Whether the cause is the absence of a usable adapter (so a harness may skip).
        unavailable: bool,
    },
    /// Writing the file failed.
    #[error("{path}: {reason}")]
    Write {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        reason: String,
    },
}
