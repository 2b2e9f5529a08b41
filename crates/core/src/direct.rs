//! `direct`: uncollided light from every light to every cell by exact ray marching.
//!
//! For each light and each cell centre x the optical depth τ = ∫ σ_t ds from the light to x
//! is integrated exactly for the trilinear extinction field ([`Grid::line_integral`]: a DDA
//! over dual cells and a 2-point Gauss rule per piece), and the uncollided fluence is
//!
//! φ_u(x) = Σ_lights E_l(x) e^{−τ_l(x)} + Σ_d w_d L_sky e^{−τ_d(x)},
//!
//! with E_l the unoccluded irradiance (E for a directional light, I/r² for point and spot
//! lights, with r at least half a cell) and the sky integrated over the nested octahedral
//! quadrature (8·4^level directions). This is Zhang & Ma's absorption step done exactly,
//! without their upwind diffusion. The per-light transmittance grids are kept in the
//! solution, so in-scattering is weighted by the phase function exactly (single
//! scattering of the direct light); the sky's part in-scatters isotropically.
//!
//! Cost: O(N) per cell and light (N cells across), so O(N⁴) per light; grey extinction is
//! marched once for all channels. Marching stops at τ = `max_optical_depth` (default 50,
//! where e^{−τ} is below f32's normal range), which makes dense media cheaper.

use glam::DVec3;
use lucent_grid::Grid;
use lucent_optics::SphericalQuadrature;
use rayon::prelude::*;

use crate::error::SolveError;
use crate::problem::{BoundaryKind, Light, LightKind, Problem};
use crate::registry::{Params, SolverEntry, SolverParams, param_docs, resolved_params};
use crate::solution::{Angular, LightTransmittance, Solution};
use crate::solver::{Capabilities, FluenceKind, OutputKind, Progress, SolveOptions, Solver};

/// The exact uncollided-light solver; its fields are its registry parameters.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DirectSolver {
    /// Refinement level of the octahedral sky quadrature (8·4^level directions).
    pub sky_level: usize,
    /// Optical depth at which marching stops.
    pub max_optical_depth: f64,
}

impl Default for DirectSolver {
    fn default() -> Self {
        Self {
            sky_level: 1,
            max_optical_depth: 50.0,
        }
    }
}

impl SolverParams for DirectSolver {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[
        (
            "sky_level",
            "octahedral sky quadrature level, 0 to 4 (8·4^level directions)",
        ),
        (
            "max_optical_depth",
            "optical depth (> 0) beyond which marching stops and light counts as gone",
        ),
    ];

    fn validate(&self) -> Result<(), SolveError> {
        let bad = |name: &str, reason: &str| SolveError::InvalidParameter {
            name: name.into(),
            reason: reason.into(),
        };
        if self.sky_level > 4 {
            return Err(bad("sky_level", "at most 4 (2048 directions)"));
        }
        if self.max_optical_depth.is_nan() || self.max_optical_depth <= 0.0 {
            return Err(bad("max_optical_depth", "must be positive"));
        }
        Ok(())
    }
}

impl DirectSolver {
    /// The registry name.
    pub const NAME: &'static str = "direct";

    /// The registry entry.
    pub const ENTRY: SolverEntry = SolverEntry {
        name: Self::NAME,
        summary: "uncollided light from every light to every cell by exact ray marching (single scattering)",
        build: |params| Ok(Box::new(Self::from_params(params)?)),
        params: param_docs::<Self>,
        resolved: |p| resolved_params::<Self>(p, Self::NAME),
    };

    /// Builds from registry parameters.
    pub fn from_params(params: &Params) -> Result<Self, SolveError> {
        params.parse(Self::NAME)
    }
}

/// Transmittance from `source(x)` to every cell centre x through `sigma_t`.
fn transmittance(sigma_t: &Grid, cutoff: f64, source: impl Fn(DVec3) -> DVec3 + Sync) -> Grid {
    let geometry = *sigma_t.geometry();
    Grid::from_fn(geometry, |x| {
        (-sigma_t.line_integral(source(x), x, cutoff)).exp() as f32
    })
}

impl Solver for DirectSolver {
    fn name(&self) -> &str {
        Self::NAME
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            anisotropic: true,
            heterogeneous: true,
            embedded_geometry: false,
            boundaries: vec![BoundaryKind::Vacuum],
            lights: vec![
                LightKind::Directional,
                LightKind::Point,
                LightKind::Spot,
                LightKind::Sky,
            ],
            output: OutputKind::AngularRadiance,
            fluence: FluenceKind::Uncollided,
            ..Capabilities::default()
        }
    }

    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
        let geometry = *problem.geometry();
        let medium = problem.medium();
        let channels = problem.channels();
        let extinction_channels = medium.sigma_t.len();
        let point_lights: Vec<&Light> = problem
            .lights()
            .iter()
            .filter(|l| !matches!(l, Light::Sky { .. }))
            .collect();
        let sky: Vec<&Light> = problem
            .lights()
            .iter()
            .filter(|l| matches!(l, Light::Sky { .. }))
            .collect();

        // Memory: transmittance per point-like light and extinction channel, fluence and
        // isotropic fluence per channel.
        let grid_bytes = geometry.voxel_count() as u64 * 4;
        let needed =
            grid_bytes * (point_lights.len() * extinction_channels + 2 * channels + 1) as u64;
        crate::driver::run(self, problem, options, needed, |context| {
            self.transport(context, &point_lights, &sky, needed)
        })
    }
}

impl DirectSolver {
    /// The uncollided light of `point_lights` (point-like) and `sky`.
    fn transport(
        &self,
        context: &crate::driver::Context<'_>,
        point_lights: &[&Light],
        sky: &[&Light],
        needed: u64,
    ) -> Result<crate::driver::Outcome, SolveError> {
        let problem = context.problem;
        let geometry = *problem.geometry();
        let medium = problem.medium();

        let (far, min_distance) = light_distances(problem);
        let work = (point_lights.len() + usize::from(!sky.is_empty())) as f64;
        let mut done = 0.0;
        let cutoff = self.max_optical_depth;
        let quadrature = SphericalQuadrature::octahedral(self.sky_level).map_err(|e| {
            SolveError::InvalidParameter {
                name: "sky_level".into(),
                reason: e.to_string(),
            }
        })?;

        let result = {
            // Per-light transmittance, one grid per extinction channel.
            let mut per_light = Vec::with_capacity(point_lights.len());
            for light in point_lights {
                let grids: Vec<Grid> = medium
                    .sigma_t
                    .iter()
                    .map(|sigma_t| {
                        transmittance(sigma_t, cutoff, |x| {
                            light
                                .arrival(x, far, min_distance)
                                .map_or(x, |(_, _, from)| from)
                        })
                    })
                    .collect();
                per_light.push(grids);
                done += 1.0;
                context.report(Progress {
                    stage: "light transmittance",
                    fraction: done / work,
                    iteration: 0,
                    residual: None,
                });
            }
            // Sky: Σ_d w_d e^{−τ_d}, per extinction channel.
            let sky_transmittance: Option<Vec<Grid>> = (!sky.is_empty()).then(|| {
                let sum = medium
                    .sigma_t
                    .iter()
                    .map(|sigma_t| {
                        let mut total = Grid::filled(geometry, 0.0);
                        let directions: Vec<(DVec3, f64)> = quadrature
                            .directions()
                            .iter()
                            .copied()
                            .zip(quadrature.weights().iter().copied())
                            .collect();
                        total.slabs_mut().for_each(|(k, slab)| {
                            let [nx, ny, _] = geometry.dims();
                            for j in 0..ny {
                                for i in 0..nx {
                                    let x = geometry.cell_centre(i, j, k);
                                    let s: f64 = directions
                                        .iter()
                                        .map(|&(d, w)| {
                                            w * (-sigma_t.line_integral(x - d * far, x, cutoff))
                                                .exp()
                                        })
                                        .sum();
                                    slab[i + nx * j] = s as f32;
                                }
                            }
                        });
                        total
                    })
                    .collect();
                context.report(Progress {
                    stage: "sky transmittance",
                    fraction: 1.0,
                    iteration: 0,
                    residual: None,
                });
                sum
            });
            (per_light, sky_transmittance)
        };
        let (per_light, sky_transmittance) = result;
        Ok(uncollided_outcome(
            problem,
            point_lights,
            per_light,
            sky_transmittance,
            needed,
        ))
    }
}

/// The far distance of directional lights and the nearest distance of point lights
/// (half the smallest cell side) that `direct` — and its GPU twin — use for `problem`.
pub fn light_distances(problem: &Problem) -> (f64, f64) {
    let geometry = problem.geometry();
    let (lo, hi) = geometry.bounds();
    (
        4.0 * (hi - lo).length() + 1.0,
        0.5 * geometry.spacing().min_element(),
    )
}

/// `direct`'s outcome from the transmittance grids: per point-like light (one grid per
/// extinction channel, in `point_lights`' order) and, where the problem has a sky,
/// Σ_d w_d e^{−τ_d} per extinction channel. Shared with `gpu-direct`, which computes the
/// same grids on the device, so both hand the renderer the same [`Solution`].
pub fn uncollided_outcome(
    problem: &Problem,
    point_lights: &[&Light],
    per_light: Vec<Vec<Grid>>,
    sky_transmittance: Option<Vec<Grid>>,
    needed: u64,
) -> crate::driver::Outcome {
    let geometry = *problem.geometry();
    let medium = problem.medium();
    let channels = problem.channels();
    let (far, min_distance) = light_distances(problem);
    let sky: Vec<&Light> = problem
        .lights()
        .iter()
        .filter(|l| matches!(l, Light::Sky { .. }))
        .collect();

    // Fluence per channel: point-like lights (irradiance × transmittance) plus the sky.
    let sky_radiance: Vec<f64> = (0..channels)
        .map(|c| sky.iter().map(|l| l.spectrum().channel(c)).sum())
        .collect();
    let isotropic_fluence: Vec<Grid> = (0..channels)
        .map(|c| match &sky_transmittance {
            Some(t) => t[c.min(t.len() - 1)].map(|v| (f64::from(v) * sky_radiance[c]) as f32),
            None => Grid::filled(geometry, 0.0),
        })
        .collect();
    let fluence: Vec<Grid> = (0..channels)
        .map(|c| {
            let mut phi = isotropic_fluence[c].clone();
            phi.slabs_mut().for_each(|(k, slab)| {
                let [nx, ny, _] = geometry.dims();
                for j in 0..ny {
                    for i in 0..nx {
                        let x = geometry.cell_centre(i, j, k);
                        let index = i + nx * j + nx * ny * k;
                        let mut sum = f64::from(slab[i + nx * j]);
                        for (light, grids) in point_lights.iter().zip(&per_light) {
                            if let Some((_, irradiance, _)) = light.arrival(x, far, min_distance) {
                                let t = grids[c.min(grids.len() - 1)].data()[index];
                                sum += light.spectrum().channel(c) * irradiance * f64::from(t);
                            }
                        }
                        slab[i + nx * j] = sum as f32;
                    }
                }
            });
            phi
        })
        .collect();

    let angular = LightTransmittance {
        phase: medium.phase,
        lights: point_lights.iter().map(|&l| l.clone()).collect(),
        transmittance: per_light,
        far,
        min_distance,
        isotropic_fluence,
    };
    crate::driver::Outcome {
        fluence,
        angular: Some(Angular::Lights(angular)),
        standard_error: None,
        record: crate::driver::Record::exact(needed),
    }
}
