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
//! where e^{−τ} is below f32's normal range), which makes dense media cheaper, and crosses
//! empty bricks (8³ in memory, the pager's bricks out of core) by advancing the walk's
//! crossing times alone, without reading σ_t: a sparse cloud costs its occupied bricks, and
//! every integral keeps its bits (`lucent_grid::EmptyBricks`).

use glam::DVec3;
use lucent_grid::{EmptyBricks, Grid};
use lucent_optics::SphericalQuadrature;
use rayon::prelude::*;

use crate::error::SolveError;
use crate::interrupt::{Halt, Interrupt};
use crate::paged::{PagedProblem, PagedSolution, paging_error};
use crate::problem::{BoundaryKind, Light, LightKind, Problem};
use crate::registry::{Params, SolverEntry, SolverParams, param_docs, resolved_params};
use crate::solution::{Angular, LightTransmittance, Solution};
use crate::solver::{Capabilities, FluenceKind, OutputKind, Progress, SolveOptions, Solver};
use lucent_paging::PagingError;

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

/// Σ_d w_d e^{−τ_d} at cell centre `x` over the sky's directions (of travel) `d` with
/// weights `w`, τ_d = `tau(x − d·far, x)`: the one definition both storages use.
fn sky_sum<E>(
    directions: &[(DVec3, f64)],
    far: f64,
    x: DVec3,
    mut tau: impl FnMut(DVec3, DVec3) -> Result<f64, E>,
) -> Result<f32, E> {
    // `Result`'s sum stops at the first error and otherwise adds as `f64`'s sum does.
    let total: f64 = directions
        .iter()
        .map(|&(d, w)| tau(x - d * far, x).map(|t| w * (-t).exp()))
        .sum::<Result<f64, E>>()?;
    Ok(total as f32)
}

/// The sky's radiance per channel (all sky lights added).
fn sky_radiance(sky: &[&Light], channels: usize) -> Vec<f64> {
    (0..channels)
        .map(|c| sky.iter().map(|l| l.spectrum().channel(c)).sum())
        .collect()
}

/// The sky's isotropic fluence from its transmittance sum `t` and radiance.
fn isotropic_value(t: f32, sky_radiance: f64) -> f32 {
    (f64::from(t) * sky_radiance) as f32
}

/// The uncollided fluence at cell centre `x` in channel `c`: the isotropic part `iso`
/// plus Σ_l s_l(c) E_l(x) T_l(x), `transmittance(l)` giving T_l at the cell.
fn fluence_value(
    iso: f32,
    x: DVec3,
    point_lights: &[&Light],
    c: usize,
    (far, min_distance): (f64, f64),
    transmittance: impl Fn(usize) -> f32,
) -> f32 {
    let mut sum = f64::from(iso);
    for (l, light) in point_lights.iter().enumerate() {
        if let Some((_, irradiance, _)) = light.arrival(x, far, min_distance) {
            sum += light.spectrum().channel(c) * irradiance * f64::from(transmittance(l));
        }
    }
    sum as f32
}

/// Bricks of [`EmptyBricks`] for the in-memory walks: 8³ cells, a small mask (one flag
/// per 512 cells) that still steps over most of the empty space around a cloud.
const EMPTY_BRICK: usize = 8;

/// Transmittance from `source(x)` to every cell centre x through `sigma_t`, whose empty
/// bricks are `empty`.
/// Stops between rows of cells when `interrupt` says so.
fn transmittance(
    sigma_t: &Grid,
    empty: &EmptyBricks,
    cutoff: f64,
    source: impl Fn(DVec3) -> DVec3 + Sync,
    interrupt: &Interrupt,
) -> Result<Grid, Halt> {
    let geometry = *sigma_t.geometry();
    rows_of(geometry, interrupt, |x| {
        (-sigma_t.line_integral_skipping(empty, source(x), x, cutoff)).exp() as f32
    })
}

/// The grid of `value` at every cell centre, in parallel over z-slabs, asking `interrupt`
/// before each row of cells (a row of ray marches takes milliseconds even at 512³).
fn rows_of(
    geometry: lucent_grid::GridGeometry,
    interrupt: &Interrupt,
    value: impl Fn(DVec3) -> f32 + Sync,
) -> Result<Grid, Halt> {
    let mut grid = Grid::filled(geometry, 0.0);
    let [nx, ny, _] = geometry.dims();
    grid.slabs_mut().for_each(|(k, slab)| {
        for j in 0..ny {
            if interrupt.halted() {
                return;
            }
            for i in 0..nx {
                slab[i + nx * j] = value(geometry.cell_centre(i, j, k));
            }
        }
    });
    match interrupt.halt() {
        Some(halt) => Err(halt),
        None => Ok(grid),
    }
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

    fn pages(&self) -> bool {
        true
    }

    fn paged_memory(
        &self,
        problem: &PagedProblem,
        options: &SolveOptions,
    ) -> Result<u64, SolveError> {
        Self::paged_needs(problem, problem.lights(), options)
    }

    fn solve_paged(
        &self,
        problem: &PagedProblem,
        options: &SolveOptions,
    ) -> Result<PagedSolution, SolveError> {
        self.validate()?;
        options.validate()?;
        if !matches!(problem.boundary(), crate::Boundary::Vacuum) {
            return Err(SolveError::Unsupported {
                solver: Self::NAME.into(),
                feature: format!("a {} boundary", problem.boundary()),
            });
        }
        options.install(|| self.transport_paged(problem, problem.lights(), options))?
    }

    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
        let geometry = *problem.geometry();
        let medium = problem.medium();
        let channels = problem.channels();
        let extinction_channels = medium.sigma_t.len();
        let (point_lights, sky) = split_lights(problem.lights());

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
    /// The bytes `direct` needs on the paged `problem` for `lights`: the pool, the
    /// bookkeeping of every field (the medium's and the results: transmittance per light
    /// and extinction channel, isotropic fluence and fluence per channel), and one layer
    /// of slabs per field read or written at once. Depends on the problem's shape only (a
    /// [`PagedProblem::shell`] gives the same answer), so a budget is refused before the
    /// medium is built.
    ///
    /// # Errors
    /// [`SolveError::OverBudget`] when it exceeds `options.memory_budget`.
    pub(crate) fn paged_needs(
        problem: &PagedProblem,
        lights: &[Light],
        options: &SolveOptions,
    ) -> Result<u64, SolveError> {
        let [nx, ny, _] = problem.geometry().dims();
        let layout = *problem.layout();
        let medium = problem.medium();
        let channels = problem.channels_with(lights);
        let (point_lights, sky) = split_lights(lights);
        let extinction = medium.sigma_t.len();
        let outputs = point_lights.len() * extinction
            + usize::from(!sky.is_empty()) * extinction
            + 2 * channels;
        let fields = medium.sigma_t.len() + medium.albedo.len() + outputs;
        let layer_bytes = (nx * ny * layout.brick()) as u64 * 4;
        let pool = problem.pager().capacity() as u64 * layout.stored_len() as u64 * 4;
        let needed =
            pool + problem.overhead_bytes(fields) + layer_bytes * (point_lights.len() + 2) as u64;
        if needed > options.memory_budget {
            return Err(SolveError::OverBudget {
                solver: Self::NAME.into(),
                needed,
                budget: options.memory_budget,
            });
        }
        Ok(needed)
    }

    /// `direct` on a paged medium: per light and extinction channel a paged transmittance
    /// field, computed brick layer by brick layer (each cell's τ read through the paged σ_t
    /// with the same walk and arithmetic as in memory), then the isotropic fluence and the
    /// fluence layer by layer from those fields with the same per-cell formulas: the bits
    /// of [`Solver::solve`] on the same medium.
    /// `lights` stand for the problem's own (the uncollided light of some of them, for a
    /// solver that adds scattered light).
    pub(crate) fn transport_paged(
        &self,
        problem: &PagedProblem,
        lights: &[Light],
        options: &SolveOptions,
    ) -> Result<PagedSolution, SolveError> {
        let started = std::time::Instant::now();
        let meter = crate::memory::PeakMeter::start();
        let before = problem.pager().stats();
        let err = |e| paging_error(Self::NAME, e);
        let geometry = *problem.geometry();
        let [nx, ny, nz] = geometry.dims();
        let layout = *problem.layout();
        let b = layout.brick();
        let medium = problem.medium();
        let channels = problem.channels_with(lights);
        let (point_lights, sky) = split_lights(lights);
        let (far, min_distance) = distances(&geometry);
        let cutoff = self.max_optical_depth;
        let directions = sky_directions(self.sky_level)?;

        let extinction = medium.sigma_t.len();
        let outputs = point_lights.len() * extinction
            + usize::from(!sky.is_empty()) * extinction
            + 2 * channels;
        let needed = Self::paged_needs(problem, lights, options)?;

        let interrupt = Interrupt::of(options);
        let halted = |stage: &'static str| interrupt.check(Self::NAME, stage);
        let layers = layout.bricks()[2];
        let total_layers = (layers * (outputs.max(1))) as f64;
        let mut layers_done = 0.0;
        let mut report = |stage: &'static str| {
            layers_done += 1.0;
            options.report(Progress {
                stage,
                fraction: (layers_done / total_layers).min(0.999),
                iteration: 0,
                residual: None,
            });
        };
        // Fills `out` layer by layer with `value(corners, centre)` per cell, τ read from
        // `sigma_t`.
        let march =
            |sigma_t: &lucent_paging::PagedGrid,
             out: &lucent_paging::PagedGrid,
             value: &(
                  dyn Fn(&mut lucent_paging::PagedCorners<'_>, DVec3) -> Result<f32, PagingError>
                      + Sync
              ),
             report: &mut dyn FnMut()|
             -> Result<(), SolveError> {
                let mut buffer = Vec::new();
                for layer in 0..layers {
                    let z0 = layer * b;
                    let z1 = (z0 + b).min(nz);
                    buffer.resize(nx * ny * (z1 - z0), 0.0);
                    buffer
                        .par_chunks_mut(nx)
                        .enumerate()
                        .try_for_each(|(row, cells)| {
                            // A row of ray marches takes milliseconds; a layer of them,
                            // minutes at 1024³: the interrupt is asked per row.
                            if interrupt.halted() {
                                return Ok(());
                            }
                            let (j, k) = (row % ny, z0 + row / ny);
                            let mut corners = sigma_t.corners();
                            for (i, cell) in cells.iter_mut().enumerate() {
                                *cell = value(&mut corners, geometry.cell_centre(i, j, k))?;
                            }
                            Ok::<_, PagingError>(())
                        })
                        .map_err(err)?;
                    halted("the paged transmittance")?;
                    out.write_slabs(z0, &buffer).map_err(err)?;
                    report();
                }
                Ok(())
            };

        let mut transmittance = Vec::with_capacity(point_lights.len());
        for light in &point_lights {
            let mut grids = Vec::with_capacity(extinction);
            for sigma_t in &medium.sigma_t {
                let out = problem.new_field().map_err(err)?;
                march(
                    sigma_t,
                    &out,
                    &|corners, x| {
                        let from = light
                            .arrival(x, far, min_distance)
                            .map_or(x, |(_, _, from)| from);
                        let tau =
                            lucent_grid::line_integral_with(&geometry, from, x, cutoff, corners)?;
                        Ok((-tau).exp() as f32)
                    },
                    &mut || report("light transmittance"),
                )?;
                grids.push(out);
            }
            transmittance.push(grids);
        }
        let sky_transmittance = if sky.is_empty() {
            None
        } else {
            let mut sums = Vec::with_capacity(extinction);
            for sigma_t in &medium.sigma_t {
                let out = problem.new_field().map_err(err)?;
                march(
                    sigma_t,
                    &out,
                    &|corners, x| {
                        sky_sum(&directions, far, x, |a, b| {
                            lucent_grid::line_integral_with(&geometry, a, b, cutoff, corners)
                        })
                    },
                    &mut || report("sky transmittance"),
                )?;
                sums.push(out);
            }
            Some(sums)
        };

        // The isotropic fluence and the fluence, layer by layer from the fields above.
        let sky_radiance = sky_radiance(&sky, channels);
        let mut isotropic = Vec::with_capacity(channels);
        let mut fluence = Vec::with_capacity(channels);
        for c in 0..channels {
            let iso = problem.new_field().map_err(err)?;
            let phi = problem.new_field().map_err(err)?;
            let mut iso_slabs = Vec::new();
            let mut t_slabs: Vec<Vec<f32>> = vec![Vec::new(); point_lights.len()];
            for layer in 0..layers {
                halted("the paged fluence")?;
                let z0 = layer * b;
                let z1 = (z0 + b).min(nz);
                let n = nx * ny * (z1 - z0);
                iso_slabs.resize(n, 0.0);
                match &sky_transmittance {
                    Some(t) => {
                        t[c.min(t.len() - 1)]
                            .read_slabs(z0, z1, &mut iso_slabs)
                            .map_err(err)?;
                        iso_slabs
                            .par_iter_mut()
                            .for_each(|v| *v = isotropic_value(*v, sky_radiance[c]));
                        iso.write_slabs(z0, &iso_slabs).map_err(err)?;
                    }
                    None => iso_slabs.fill(0.0),
                }
                for (l, slabs) in t_slabs.iter_mut().enumerate() {
                    slabs.resize(n, 0.0);
                    let grids = &transmittance[l];
                    grids[c.min(grids.len() - 1)]
                        .read_slabs(z0, z1, slabs)
                        .map_err(err)?;
                }
                let mut out = vec![0.0f32; n];
                out.par_chunks_mut(nx).enumerate().for_each(|(row, cells)| {
                    let (j, k) = (row % ny, z0 + row / ny);
                    for (i, cell) in cells.iter_mut().enumerate() {
                        let index = row * nx + i;
                        *cell = fluence_value(
                            iso_slabs[index],
                            geometry.cell_centre(i, j, k),
                            &point_lights,
                            c,
                            (far, min_distance),
                            |l| t_slabs[l][index],
                        );
                    }
                });
                if let Some(index) = out.iter().position(|v| !v.is_finite()) {
                    let [i, j, k] = [index % nx, (index / nx) % ny, z0 + index / (nx * ny)];
                    return Err(SolveError::NonFiniteOutput {
                        solver: Self::NAME.into(),
                        what: "fluence",
                        channel: c,
                        cell: [i, j, k],
                        value: out[index],
                    });
                }
                phi.write_slabs(z0, &out).map_err(err)?;
                report("fluence");
            }
            isotropic.push(iso);
            fluence.push(phi);
        }
        let after = problem.pager().stats();
        options.report(Progress {
            stage: Progress::DONE,
            fraction: 1.0,
            iteration: 0,
            residual: None,
        });
        Ok(PagedSolution {
            fluence,
            standard_error: Vec::new(),
            transmittance,
            isotropic_fluence: isotropic,
            report: crate::solver::SolveReport {
                solver: Self::NAME.into(),
                iterations: 0,
                residual_history: Vec::new(),
                wall_time_s: started.elapsed().as_secs_f64(),
                peak_memory_bytes: needed,
                measured_peak_bytes: meter.and_then(|m| m.peak_bytes()),
                stop_reason: crate::solver::StopReason::Exact,
                paging: Some(after.since(&before)),
                choice: None,
                composition: None,
            },
            paging: after.since(&before),
        })
    }

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
        let directions = sky_directions(self.sky_level)?;
        let interrupt = context.interrupt();
        let halted = |stage: &'static str| {
            move |halt| SolveError::Halted {
                solver: Self::NAME.into(),
                stage: stage.into(),
                halt,
            }
        };

        // Empty space is stepped over unread; the integrals keep their bits.
        let empty = medium
            .sigma_t
            .iter()
            .map(|sigma_t| EmptyBricks::of(sigma_t, EMPTY_BRICK))
            .collect::<Result<Vec<_>, _>>()?;
        let result = {
            // Per-light transmittance, one grid per extinction channel.
            let mut per_light = Vec::with_capacity(point_lights.len());
            for light in point_lights {
                let grids: Vec<Grid> = medium
                    .sigma_t
                    .iter()
                    .zip(&empty)
                    .map(|(sigma_t, empty)| {
                        transmittance(
                            sigma_t,
                            empty,
                            cutoff,
                            |x| {
                                light
                                    .arrival(x, far, min_distance)
                                    .map_or(x, |(_, _, from)| from)
                            },
                            &interrupt,
                        )
                    })
                    .collect::<Result<_, _>>()
                    .map_err(halted("a light's transmittance"))?;
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
            let sky_transmittance: Option<Vec<Grid>> = if sky.is_empty() {
                None
            } else {
                let sum = medium
                    .sigma_t
                    .iter()
                    .zip(&empty)
                    .map(|(sigma_t, empty)| {
                        rows_of(geometry, &interrupt, |x| {
                            let tau = |a, b| {
                                Ok::<_, std::convert::Infallible>(
                                    sigma_t.line_integral_skipping(empty, a, b, cutoff),
                                )
                            };
                            match sky_sum(&directions, far, x, tau) {
                                Ok(v) => v,
                                Err(never) => match never {},
                            }
                        })
                    })
                    .collect::<Result<_, _>>()
                    .map_err(halted("the sky's transmittance"))?;
                context.report(Progress {
                    stage: "sky transmittance",
                    fraction: 1.0,
                    iteration: 0,
                    residual: None,
                });
                Some(sum)
            };
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
    distances(problem.geometry())
}

/// [`light_distances`] of a grid: the one definition both storages use.
fn distances(geometry: &lucent_grid::GridGeometry) -> (f64, f64) {
    let (lo, hi) = geometry.bounds();
    (
        4.0 * (hi - lo).length() + 1.0,
        0.5 * geometry.spacing().min_element(),
    )
}

/// The sky's directions of travel with their quadrature weights (`sky_level`).
pub(crate) fn sky_directions(sky_level: usize) -> Result<Vec<(DVec3, f64)>, SolveError> {
    let quadrature =
        SphericalQuadrature::octahedral(sky_level).map_err(|e| SolveError::InvalidParameter {
            name: "sky_level".into(),
            reason: e.to_string(),
        })?;
    Ok(quadrature
        .directions()
        .iter()
        .copied()
        .zip(quadrature.weights().iter().copied())
        .collect())
}

/// A problem's lights split into point-like ones (directional, point, spot: everything but
/// the sky) and the sky.
fn split_lights(lights: &[Light]) -> (Vec<&Light>, Vec<&Light>) {
    lights.iter().partition(|l| !matches!(l, Light::Sky { .. }))
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
    let (_, sky) = split_lights(problem.lights());

    // Fluence per channel: point-like lights (irradiance × transmittance) plus the sky.
    let sky_radiance = sky_radiance(&sky, channels);
    let isotropic_fluence: Vec<Grid> = (0..channels)
        .map(|c| match &sky_transmittance {
            Some(t) => t[c.min(t.len() - 1)].map(|v| isotropic_value(v, sky_radiance[c])),
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
                        slab[i + nx * j] = fluence_value(
                            slab[i + nx * j],
                            x,
                            point_lights,
                            c,
                            (far, min_distance),
                            |l| {
                                let grids = &per_light[l];
                                grids[c.min(grids.len() - 1)].data()[index]
                            },
                        );
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
        arrivals: Vec::new(),
    };
    crate::driver::Outcome {
        fluence,
        angular: Some(Angular::Lights(angular)),
        standard_error: None,
        record: crate::driver::Record::exact(needed),
    }
}
