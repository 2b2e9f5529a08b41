//! Ray marching through the medium.

use lucent_core::{Light, Problem, Solution};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::RenderError;
use crate::camera::Camera;
use crate::image_io::Image;

/// Image size and marching parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderSettings {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Step length as a fraction of the smallest cell size.
    #[serde(default = "default_step")]
    pub step: f64,
    /// Radiance behind the medium (linear RGB); `None` uses the sky's radiance.
    #[serde(default)]
    pub background: Option<[f64; 3]>,
}

fn default_step() -> f64 {
    0.5
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            width: 640,
            height: 480,
            step: default_step(),
            background: None,
        }
    }
}

impl RenderSettings {
    /// The most pixels an image may have (2²⁶: 8192 × 8192).
    pub const MAX_PIXELS: usize = 1 << 26;
    /// The smallest step, as a fraction of the smallest cell: below it a ray takes more
    /// steps than the picture is worth (a 256³ grid's diagonal is 4.4 × 10⁵ steps).
    pub const MIN_STEP: f64 = 1e-3;

    /// The pixel count, after checking the size (1 to [`Self::MAX_PIXELS`] pixels, the
    /// product computed without overflow), the step ([`Self::MIN_STEP`] to 4 cells) and
    /// the background (finite, ≥ 0).
    pub fn validate(&self) -> Result<usize, RenderError> {
        let pixels = self
            .width
            .checked_mul(self.height)
            .filter(|&p| self.width > 0 && self.height > 0 && p <= Self::MAX_PIXELS)
            .ok_or_else(|| {
                RenderError::Invalid(format!(
                    "image size {}×{} (1 to 2^26 pixels)",
                    self.width, self.height
                ))
            })?;
        if !(self.step >= Self::MIN_STEP && self.step <= 4.0) {
            return Err(RenderError::Invalid(format!(
                "step {} (a fraction of the smallest cell, {} to 4)",
                self.step,
                Self::MIN_STEP
            )));
        }
        if let Some(b) = self.background
            && !b.iter().all(|v| v.is_finite() && *v >= 0.0)
        {
            return Err(RenderError::Invalid(format!(
                "background {b:?} must be finite and ≥ 0"
            )));
        }
        Ok(pixels)
    }
}

/// A per-pixel jitter in [0, 1) from a 32-bit hash of the pixel (deterministic; Wellons's
/// `lowbias32` finaliser). 32-bit so that `shaders/render.wgsl` computes the very same
/// offsets (WGSL has no 64-bit integers), and 24 bits of it so that the value is exact in
/// f32 as in f64.
pub(crate) fn jitter(x: usize, y: usize) -> f64 {
    fn lowbias32(mut h: u32) -> u32 {
        h ^= h >> 16;
        h = h.wrapping_mul(0x7feb_352d);
        h ^= h >> 15;
        h = h.wrapping_mul(0x846c_a68b);
        h ^ (h >> 16)
    }
    let h = lowbias32(x as u32 ^ lowbias32(y as u32));
    f64::from(h >> 8) / f64::from(1u32 << 24)
}

/// What the CPU and the device march share: the box, the step, the channels and what
/// escaping rays see.
pub(crate) struct MarchSetup {
    /// Lower corner of the medium's box (world).
    pub(crate) lo: glam::DVec3,
    /// Upper corner of the medium's box (world).
    pub(crate) hi: glam::DVec3,
    /// Step length (world units).
    pub(crate) step: f64,
    /// Channels marched: the problem's or the solution's, whichever has more.
    pub(crate) channels: usize,
    /// Radiance behind the medium per output colour.
    pub(crate) background: [f64; 3],
    /// Width / height.
    pub(crate) aspect: f64,
    /// Pixels in the image.
    pub(crate) pixels: usize,
}

impl MarchSetup {
    /// Checks the camera and the settings, and sets the march up.
    pub(crate) fn new(
        problem: &Problem,
        solution: &Solution,
        camera: &Camera,
        settings: &RenderSettings,
    ) -> Result<Self, RenderError> {
        camera.validate()?;
        let pixels = settings.validate()?;
        solution.check_fits(problem).map_err(|why| {
            RenderError::Invalid(format!(
                "the solution does not belong to the problem: {why}"
            ))
        })?;
        let geometry = problem.geometry();
        let (lo, hi) = geometry.bounds();
        let sky: [f64; 3] = std::array::from_fn(|c| {
            problem
                .lights()
                .iter()
                .filter(|l| matches!(l, Light::Sky { .. }))
                .map(|l| l.spectrum().channel(c))
                .sum()
        });
        Ok(Self {
            lo,
            hi,
            step: settings.step * geometry.spacing().min_element(),
            channels: problem.channels().max(solution.fluence.len()),
            background: settings.background.unwrap_or(sky),
            aspect: settings.width as f64 / settings.height as f64,
            pixels,
        })
    }
}

/// A channel's march ends where its transmittance has fallen below this: what lies
/// behind adds at most 10⁻⁴ of its own radiance.
pub(crate) const OPAQUE: f64 = 1e-4;

/// Renders `solution` of `problem` through `camera`. `progress` is called with the fraction
/// of rows done.
pub fn render(
    problem: &Problem,
    solution: &Solution,
    camera: &Camera,
    settings: &RenderSettings,
    progress: Option<&(dyn Fn(f64) + Sync)>,
) -> Result<Image, RenderError> {
    let setup = MarchSetup::new(problem, solution, camera, settings)?;
    let (lo, hi, step, channels) = (setup.lo, setup.hi, setup.step, setup.channels);
    let medium = problem.medium();
    let emission: Vec<&Light> = problem
        .lights()
        .iter()
        .filter(|l| matches!(l, Light::Emission { .. }))
        .collect();
    let rows_done = std::sync::atomic::AtomicUsize::new(0);

    let mut pixels = vec![[0f32; 3]; setup.pixels];
    pixels
        .par_chunks_mut(settings.width)
        .enumerate()
        .try_for_each(|(y, row)| -> Result<(), RenderError> {
            for (x, pixel) in row.iter_mut().enumerate() {
                let u = (x as f64 + 0.5) / settings.width as f64;
                let v = (y as f64 + 0.5) / settings.height as f64;
                let (origin, dir) = camera.ray(u, v, setup.aspect)?;
                let mut radiance = [0f64; 3];
                let mut transmittance = [1f64; 3];
                if let Some((t0, t1)) = lucent_grid::ray_box(origin, dir, lo, hi) {
                    // Step ends at t0 + step·(jitter + k), k = 0, 1, …: the first step is a
                    // jittered partial one. Each channel stops where it has become opaque.
                    let start = t0 + step * jitter(x, y);
                    let mut previous = t0;
                    let mut k = 0.0;
                    while previous < t1 && transmittance[..channels].iter().any(|&t| t > OPAQUE) {
                        let end = (start + k * step).min(t1);
                        let ds = end - previous;
                        let p = origin + dir * (0.5 * (previous + end));
                        for c in 0..channels {
                            if transmittance[c] <= OPAQUE {
                                continue;
                            }
                            let sigma_t = f64::from(medium.sigma_t(c).sample_trilinear(p));
                            let sigma_s = f64::from(medium.albedo(c).sample(p)) * sigma_t;
                            let mut source = if sigma_s > 0.0 {
                                sigma_s * solution.inscattered(c, p, -dir)
                            } else {
                                0.0
                            };
                            for light in &emission {
                                if let Light::Emission { grid, scale } = light {
                                    source +=
                                        scale.channel(c) * f64::from(grid.sample_trilinear(p));
                                }
                            }
                            let attenuation = (-sigma_t * ds).exp();
                            let weight = if sigma_t * ds > 1e-6 {
                                (1.0 - attenuation) / sigma_t
                            } else {
                                ds
                            };
                            radiance[c] += transmittance[c] * source * weight;
                            transmittance[c] *= attenuation;
                        }
                        previous = end;
                        k += 1.0;
                    }
                }
                let rgb: [f64; 3] = std::array::from_fn(|c| {
                    let c_in = c.min(channels - 1);
                    radiance[c_in] + transmittance[c_in] * setup.background[c]
                });
                *pixel = rgb.map(|v| v as f32);
            }
            let done = rows_done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            if let Some(callback) = progress {
                callback(done as f64 / settings.height as f64);
            }
            Ok(())
        })?;
    Ok(Image {
        width: settings.width,
        height: settings.height,
        pixels,
    })
}
