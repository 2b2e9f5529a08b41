//! Camera images by path tracing: the estimator behind `lucent render --solver mc`.
//!
//! For each pixel, paths start at the camera and fly by delta tracking. At every real
//! collision the light sources are sampled directly (next-event estimation: the direction
//! to each point, spot and directional light, and one uniformly sampled sky direction),
//! with ratio tracking for the shadow ray's transmittance; the path then scatters by phase
//! sampling with implicit capture and Russian roulette. Only camera rays that escape see the
//! background (the sky is counted by next-event estimation alone, so nothing is counted
//! twice). With `max_depth = 1` the estimate is exactly the single-scattering image.

use std::f64::consts::PI;

use glam::DVec3;
use lucent_core::Interrupt;
use lucent_core::{Light, Problem, SolveError};
use lucent_grid::{Grid, ray_box};
use lucent_optics::PhaseFunction;
use rayon::prelude::*;

use crate::majorant::MajorantGrid;
use crate::rng::PathRng;
use crate::transport::{McConfig, roulette};

/// A path-traced image: linear RGB radiance and its standard error per pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraEstimate {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Mean radiance per pixel, rows from the top.
    pub radiance: Vec<[f32; 3]>,
    /// Standard error per pixel, from the spread over samples.
    pub std_error: Vec<[f32; 3]>,
    /// Rows traced (`height` unless cancelled; the others hold the background radiance and
    /// a standard error of `f32::MAX`).
    pub rows_traced: usize,
}

/// Path-traces a `width`×`height` image with `samples` paths per pixel; `ray(u, v)` gives
/// the camera ray (origin, unit direction) through image point (u, v) ∈ [0, 1]² (v down).
/// `background` is the radiance camera rays see when they leave the medium.
#[allow(clippy::too_many_arguments)]
pub fn camera_image(
    problem: &Problem,
    width: usize,
    height: usize,
    samples: usize,
    background: [f64; 3],
    config: &McConfig,
    ray: impl Fn(f64, f64) -> (DVec3, DVec3) + Sync,
) -> Result<CameraEstimate, SolveError> {
    camera_image_with_progress(
        problem,
        width,
        height,
        samples,
        background,
        config,
        ray,
        None,
        &Interrupt::never(),
    )
}

/// [`camera_image`], calling `progress` with the fraction of rows done and stopping when
/// `interrupt` halts (Ctrl-C, the time limit; asked every pixel): the row being traced is
/// given up, and rows not traced whole hold the background radiance and a standard error
/// of `f32::MAX`; [`CameraEstimate::rows_traced`] counts the rest.
#[allow(clippy::too_many_arguments)]
pub fn camera_image_with_progress(
    problem: &Problem,
    width: usize,
    height: usize,
    samples: usize,
    background: [f64; 3],
    config: &McConfig,
    ray: impl Fn(f64, f64) -> (DVec3, DVec3) + Sync,
    progress: Option<&(dyn Fn(f64) + Sync)>,
    interrupt: &Interrupt,
) -> Result<CameraEstimate, SolveError> {
    let rows_done = std::sync::atomic::AtomicUsize::new(0);
    crate::transport::check_optical_reach(problem)?;
    // Sizes multiply without overflow: at most 2^26 pixels and 2^36 paths in all (hours
    // on two cores); more is refused before anything runs.
    let pixel_count = width
        .checked_mul(height)
        .filter(|&p| width > 0 && height > 0 && p <= 1 << 26);
    let paths = pixel_count.and_then(|p| p.checked_mul(samples));
    if pixel_count.is_none() || samples < 2 || paths.is_none_or(|p| p > 1 << 36) {
        return Err(SolveError::InvalidParameter {
            name: "image".into(),
            reason: format!(
                "{width}×{height} pixels with {samples} samples (1 to 2^26 pixels, at least 2 samples, at most 2^36 paths)"
            ),
        });
    }
    if problem.embedded().is_some()
        && matches!(problem.boundary(), lucent_core::Boundary::Robin { eta } if eta != 1.0)
    {
        // Light from point-like sources reaches a camera path through a refracting surface
        // only along one specular chain, which next-event estimation cannot sample.
        return Err(SolveError::Unsupported {
            solver: "mc".into(),
            feature: "camera images through a refracting embedded surface (needs manifold next-event estimation)".into(),
        });
    }
    let medium = problem.medium();
    let channels = problem.channels();
    // Emission is picked up at tentative collisions (Q/σ̄ each), so the majorant must be
    // positive wherever something emits, even in empty space: floor it at one per cell.
    let floor = 1.0 / problem.geometry().spacing().min_element();
    let emits: Vec<bool> = (0..problem.geometry().voxel_count())
        .map(|i| {
            problem
                .lights()
                .iter()
                .any(|l| matches!(l, Light::Emission { grid, .. } if grid.data()[i] > 0.0))
        })
        .collect();
    let floored = |g: &Grid| {
        let mut out = g.clone();
        for (v, &e) in out.data_mut().iter_mut().zip(&emits) {
            if e {
                *v = v.max(floor as f32);
            }
        }
        out
    };
    let majorants: Vec<MajorantGrid> = medium
        .sigma_t
        .iter()
        .map(|s| MajorantGrid::for_config(&floored(s), config))
        .collect();
    let groups: Vec<(usize, Vec<usize>)> = if medium.sigma_t.len() == 1 {
        vec![(0, (0..channels).collect())]
    } else {
        (0..3).map(|c| (c, vec![c])).collect()
    };
    // RGB extinction: one path for all three channels with hero-channel MIS over a shared
    // majorant (unless switched off, for comparison with per-channel tracing).
    let spectral = (medium.sigma_t.len() == 3 && config.spectral_mis).then(|| {
        let mut max = medium.sigma_t[0].clone();
        for other in &medium.sigma_t[1..] {
            for (m, v) in max.data_mut().iter_mut().zip(other.data()) {
                *m = m.max(*v);
            }
        }
        MajorantGrid::for_config(&floored(&max), config)
    });
    let mut radiance = vec![[0f32; 3]; width * height];
    let mut std_error = vec![[0f32; 3]; width * height];
    radiance
        .par_chunks_mut(width)
        .zip(std_error.par_chunks_mut(width))
        .enumerate()
        .for_each(|(y, (row, row_err))| {
            let unknown = |row: &mut [[f32; 3]], row_err: &mut [[f32; 3]]| {
                for (r, e) in row.iter_mut().zip(row_err.iter_mut()) {
                    *r = background.map(|b| b as f32);
                    *e = [f32::MAX; 3];
                }
            };
            for x in 0..width {
                // A row of a dense cloud at 64 paths a pixel takes a second or more.
                if interrupt.halted() {
                    unknown(row, row_err);
                    return;
                }
                let pixel = (y * width + x) as u64;
                let mut sum = [0f64; 3];
                let mut sum_sq = [0f64; 3];
                for s in 0..samples {
                    let mut rng = PathRng::new(config.seed, pixel, s as u64);
                    let [jx, jy] = rng.uniform2();
                    let (origin, dir) = ray(
                        (x as f64 + jx) / width as f64,
                        (y as f64 + jy) / height as f64,
                    );
                    let mut value = [0f64; 3];
                    if let Some(majorant) = &spectral {
                        value = trace_path_spectral(
                            problem, majorant, background, config, origin, dir, &mut rng,
                        );
                    } else {
                        for (extinction, members) in &groups {
                            let path = trace_path(
                                problem,
                                &medium.sigma_t[*extinction],
                                &majorants[*extinction],
                                members,
                                background,
                                config,
                                origin,
                                dir,
                                &mut rng,
                            );
                            for (m, &c) in members.iter().enumerate() {
                                value[c] = path[m];
                            }
                        }
                    }
                    for c in 0..3 {
                        let v = value[c.min(channels - 1)];
                        sum[c] += v;
                        sum_sq[c] += v * v;
                    }
                }
                let n = samples as f64;
                for c in 0..3 {
                    let mean = sum[c] / n;
                    let var = ((sum_sq[c] / n - mean * mean) * n / (n - 1.0)).max(0.0);
                    row[x][c] = mean as f32;
                    row_err[x][c] = (var / n).sqrt() as f32;
                }
            }
            let done = rows_done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            if let Some(callback) = progress {
                callback(done as f64 / height as f64);
            }
        });
    Ok(CameraEstimate {
        width,
        height,
        radiance,
        std_error,
        rows_traced: rows_done.into_inner(),
    })
}

/// The volumetric emission Σ scale·Q(x) of the problem's emission lights in `channel`
/// (W/m³/sr).
#[inline]
fn emitted(problem: &Problem, channel: usize, x: DVec3) -> f64 {
    problem
        .lights()
        .iter()
        .map(|l| match l {
            Light::Emission { grid, scale } => {
                scale.channel(channel) * f64::from(grid.sample_trilinear(x))
            }
            _ => 0.0,
        })
        .sum()
}

/// σ_t at `x`, zero outside the embedded geometry (an index-matched embedded surface only
/// says where the medium is).
#[inline]
fn extinction(sigma_t: &Grid, embedded: Option<&Grid>, x: DVec3) -> f64 {
    if embedded.is_some_and(|sdf| sdf.sample_trilinear(x) >= 0.0) {
        0.0
    } else {
        f64::from(sigma_t.sample_trilinear(x))
    }
}

/// Ratio-tracking transmittance along `origin + t·dir`, t ∈ [0, t_max].
fn ratio_transmittance(
    sigma_t: &Grid,
    embedded: Option<&Grid>,
    majorant: &MajorantGrid,
    origin: DVec3,
    dir: DVec3,
    t_max: f64,
    rng: &mut PathRng,
) -> f64 {
    let mut transmittance = 1.0;
    majorant.tentative_collisions(origin, dir, 0.0, t_max, rng, |t, sigma_max, rng| {
        transmittance *= 1.0 - extinction(sigma_t, embedded, origin + dir * t) / sigma_max;
        if transmittance < 1e-3 {
            // Russian roulette on faint shadow rays.
            if rng.uniform() >= 0.5 {
                transmittance = 0.0;
                return false;
            }
            transmittance *= 2.0;
        }
        true
    });
    transmittance
}

/// One camera path for the channels in `members`; returns their radiance.
#[allow(clippy::too_many_arguments)]
fn trace_path(
    problem: &Problem,
    sigma_t: &Grid,
    majorant: &MajorantGrid,
    members: &[usize],
    background: [f64; 3],
    config: &McConfig,
    origin: DVec3,
    dir: DVec3,
    rng: &mut PathRng,
) -> Vec<f64> {
    let geometry = problem.geometry();
    let (lo, hi) = geometry.bounds();
    let medium = problem.medium();
    let phase = medium.phase;
    let far = 4.0 * (hi - lo).length() + 1.0;
    let mut throughput = vec![1.0f64; members.len()];
    let mut result = vec![0.0f64; members.len()];
    let (mut pos, mut dir) = (origin, dir);
    let mut depth = 0u32;
    loop {
        let Some((t_in, t_out)) = ray_box(pos, dir, lo, hi) else {
            if depth == 0 {
                for (m, &c) in members.iter().enumerate() {
                    result[m] += background[c];
                }
            }
            return result;
        };
        let mut collision = None;
        majorant.tentative_collisions(pos, dir, t_in, t_out, rng, |t, sigma_max, rng| {
            // Emission: each tentative point contributes Q(x)/σ̄ (unbiased for ∫ T Q ds).
            for (m, &c) in members.iter().enumerate() {
                let q = emitted(problem, c, pos + dir * t);
                if q > 0.0 {
                    result[m] += throughput[m] * q / sigma_max;
                }
            }
            if rng.uniform() * sigma_max < extinction(sigma_t, problem.embedded(), pos + dir * t) {
                collision = Some(t);
                return false;
            }
            true
        });
        let Some(t) = collision else {
            if depth == 0 {
                for (m, &c) in members.iter().enumerate() {
                    result[m] += background[c];
                }
            }
            return result;
        };
        pos += dir * t;
        // Implicit capture: the scattered fraction continues.
        for (m, &c) in members.iter().enumerate() {
            throughput[m] *= f64::from(medium.albedo(c).sample(pos)).clamp(0.0, 1.0);
        }
        // Next-event estimation toward every light (radiance toward the camera, so the
        // scattered light travels along −dir).
        let toward_eye = -dir;
        for light in problem.lights() {
            let Some((w_light, irradiance, distance)) = next_event(light, pos, far, rng) else {
                continue;
            };
            let p = phase.eval(w_light, toward_eye);
            if p <= 0.0 {
                continue;
            }
            let shadow = ratio_transmittance(
                sigma_t,
                problem.embedded(),
                majorant,
                pos,
                -w_light,
                distance,
                rng,
            );
            if shadow > 0.0 {
                for (m, &c) in members.iter().enumerate() {
                    result[m] +=
                        throughput[m] * p * irradiance * light.spectrum().channel(c) * shadow;
                }
            }
        }
        depth += 1;
        if depth >= config.max_depth {
            return result;
        }
        if !roulette(&mut throughput, 1.0, rng) {
            return result;
        }
        dir = phase.sample(dir, rng.uniform2()).omega_out;
    }
}

/// One camera path for an RGB extinction: distances and real/null decisions follow a hero
/// channel drawn per path, every channel's contribution is weighted by the balance
/// heuristic over the three possible heroes (spectral MIS, as pbrt-v4 does). `f` holds each
/// channel's path throughput and `p` the path's probability under each hero, both divided
/// by the mean of `p` after every event, so that `f` is the MIS-weighted estimate itself.
fn trace_path_spectral(
    problem: &Problem,
    majorant: &MajorantGrid,
    background: [f64; 3],
    config: &McConfig,
    origin: DVec3,
    dir: DVec3,
    rng: &mut PathRng,
) -> [f64; 3] {
    let geometry = problem.geometry();
    let (lo, hi) = geometry.bounds();
    let medium = problem.medium();
    let phase = medium.phase;
    let far = 4.0 * (hi - lo).length() + 1.0;
    let hero = ((rng.uniform() * 3.0) as usize).min(2);
    let sigma = |x: DVec3| -> [f64; 3] {
        std::array::from_fn(|c| extinction(medium.sigma_t(c), problem.embedded(), x))
    };
    let mut f = [1.0f64; 3];
    let mut p = [1.0f64; 3];
    let mut result = [0.0f64; 3];
    let (mut pos, mut dir) = (origin, dir);
    let mut depth = 0u32;
    let normalise = |f: &mut [f64; 3], p: &mut [f64; 3]| {
        let mean = (p[0] + p[1] + p[2]) / 3.0;
        if mean > 0.0 {
            for c in 0..3 {
                f[c] /= mean;
                p[c] /= mean;
            }
        }
    };
    loop {
        let escape = |f: &[f64; 3], result: &mut [f64; 3]| {
            if depth == 0 {
                for c in 0..3 {
                    result[c] += f[c] * background[c];
                }
            }
        };
        let Some((t_in, t_out)) = ray_box(pos, dir, lo, hi) else {
            escape(&f, &mut result);
            return result;
        };
        let mut collision = None;
        majorant.tentative_collisions(pos, dir, t_in, t_out, rng, |t, sigma_max, rng| {
            for c in 0..3 {
                let q = emitted(problem, c, pos + dir * t);
                if q > 0.0 {
                    result[c] += f[c] * q / sigma_max;
                }
            }
            let s = sigma(pos + dir * t);
            let real = rng.uniform() * sigma_max < s[hero];
            for c in 0..3 {
                let q = (s[c] / sigma_max).min(1.0);
                let factor = if real { q } else { 1.0 - q };
                f[c] *= factor;
                p[c] *= factor;
            }
            normalise(&mut f, &mut p);
            if real {
                collision = Some(t);
                return false;
            }
            true
        });
        let Some(t) = collision else {
            escape(&f, &mut result);
            return result;
        };
        pos += dir * t;
        for c in 0..3 {
            f[c] *= f64::from(medium.albedo(c).sample(pos)).clamp(0.0, 1.0);
        }
        let toward_eye = -dir;
        for light in problem.lights() {
            let Some((w_light, irradiance, distance)) = next_event(light, pos, far, rng) else {
                continue;
            };
            let phase_value = phase.eval(w_light, toward_eye);
            if phase_value <= 0.0 {
                continue;
            }
            // Ratio tracking against the shared majorant is unbiased for every channel.
            let mut shadow = [1.0f64; 3];
            majorant.tentative_collisions(pos, -w_light, 0.0, distance, rng, |t, sigma_max, _| {
                let s = sigma(pos - w_light * t);
                for c in 0..3 {
                    shadow[c] *= 1.0 - (s[c] / sigma_max).min(1.0);
                }
                if shadow.iter().all(|&v| v < 1e-6) {
                    return false;
                }
                true
            });
            for c in 0..3 {
                result[c] +=
                    f[c] * phase_value * irradiance * light.spectrum().channel(c) * shadow[c];
            }
        }
        depth += 1;
        if depth >= config.max_depth {
            return result;
        }
        if !roulette(&mut f, 1.0, rng) {
            return result;
        }
        dir = phase.sample(dir, rng.uniform2()).omega_out;
    }
}

/// Samples the light's direction at `pos` for next-event estimation: the unit direction the
/// light travels, its irradiance per unit of its spectrum divided by the sampling pdf, and
/// the distance to march the shadow ray. Sky: one uniform direction (pdf 1/4π). `None` for
/// emission and for points a spot light does not reach.
fn next_event(light: &Light, pos: DVec3, far: f64, rng: &mut PathRng) -> Option<(DVec3, f64, f64)> {
    match light {
        Light::Sky { .. } => {
            let [u, v] = rng.uniform2();
            let z = 1.0 - 2.0 * u;
            let r = (1.0 - z * z).max(0.0).sqrt();
            Some((
                DVec3::new(r * (2.0 * PI * v).cos(), r * (2.0 * PI * v).sin(), z),
                4.0 * PI,
                far,
            ))
        }
        Light::Emission { .. } => None,
        _ => light
            .arrival(pos, far, 0.0)
            .filter(|&(_, e, _)| e > 0.0)
            .map(|(w, e, from)| (w, e, (pos - from).length())),
    }
}
