//! Particle tracing: light leaves the lights, flies by delta tracking, scatters by the
//! phase function, is absorbed by implicit capture and Russian roulette, and leaves its
//! track lengths in the cells it crosses.

use std::f64::consts::PI;

use glam::DVec3;
use lucent_core::{Boundary, Interrupt, Light, Problem, SolveError};
use lucent_grid::{Grid, ray_box};
use lucent_optics::{Dielectric, PhaseFunction};
use rayon::prelude::*;

use crate::majorant::MajorantGrid;
use crate::rng::PathRng;

/// How much to trace.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct McConfig {
    /// Particles per batch and light.
    pub particles: u64,
    /// Independent batches (their spread gives the standard errors; at least 2).
    pub batches: usize,
    /// Seed of every random stream.
    pub seed: u64,
    /// Scattering events after which a path is cut (its energy is counted as truncated).
    pub max_depth: u32,
    /// Fine cells per majorant cell along each axis.
    pub majorant_cells: usize,
    /// Use one global majorant instead of the grid (the reference for tests).
    pub global_majorant: bool,
    /// Camera paths in RGB-extinction media follow one hero channel with spectral MIS
    /// (one path for three channels) instead of one path per channel.
    pub spectral_mis: bool,
}

impl Default for McConfig {
    fn default() -> Self {
        Self {
            particles: 50_000,
            batches: 16,
            seed: 1,
            max_depth: 10_000,
            majorant_cells: 8,
            global_majorant: false,
            spectral_mis: true,
        }
    }
}

/// A batch-averaged quantity and its standard error.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Estimate {
    /// Mean over batches.
    pub mean: f64,
    /// Standard error of the mean.
    pub std_error: f64,
}

/// Where the emitted power went, per channel (W).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EnergyBalance {
    /// Power entering the domain (or emitted inside it).
    pub emitted: Estimate,
    /// Power absorbed in the medium.
    pub absorbed: Estimate,
    /// Power leaving through the boundary.
    pub escaped: Estimate,
    /// Power in paths cut at `max_depth`.
    pub truncated: Estimate,
    /// emitted − absorbed − escaped − truncated, per batch: zero in expectation (Russian
    /// roulette is its only source of noise), the test of the energy balance.
    pub imbalance: Estimate,
}

/// The result of a run.
#[derive(Debug, Clone, PartialEq)]
pub struct McEstimate {
    /// Cell-averaged fluence per channel.
    pub fluence: Vec<Grid>,
    /// Its standard error per cell.
    pub standard_error: Vec<Grid>,
    /// Power accounting per channel.
    pub energy: Vec<EnergyBalance>,
    /// Paths traced.
    pub paths: u64,
    /// Batches run per channel (the fewest, where a time budget stopped groups
    /// differently; `config.batches` unless a time budget stopped the run).
    pub batches: usize,
}

/// Per-batch tallies of one tracing group (the channels sharing one extinction): the track
/// lengths in `fluence` (per member channel and cell) and where the power went.
pub(crate) struct Tally<F> {
    pub(crate) fluence: F,
    pub(crate) emitted: Vec<f64>,
    pub(crate) absorbed: Vec<f64>,
    pub(crate) escaped: Vec<f64>,
    pub(crate) truncated: Vec<f64>,
    /// Every particle of the batch was traced (not stopped by an interrupt part way: such
    /// a batch is dropped, since its tallies are normalised by the whole batch).
    pub(crate) complete: bool,
}

impl<F> Tally<F> {
    fn new(channels: usize, fluence: F) -> Self {
        Self {
            fluence,
            emitted: vec![0.0; channels],
            absorbed: vec![0.0; channels],
            escaped: vec![0.0; channels],
            truncated: vec![0.0; channels],
            complete: true,
        }
    }
}

/// Where a batch leaves its track lengths: dense per-channel arrays in memory, paged
/// bricks out of core. Each cell receives its additions in the path order on either.
pub(crate) trait FluenceTally {
    /// Adds `value` (weight × length) to cell `cell` (x-fastest index) of member channel
    /// `member`.
    fn add(&mut self, member: usize, cell: usize, value: f64);
}

impl FluenceTally for Vec<Vec<f64>> {
    #[inline]
    fn add(&mut self, member: usize, cell: usize, value: f64) {
        self[member][cell] += value;
    }
}

/// What a batch reads of the medium: dense grids in memory, paged fields out of core, with
/// the same trilinear arithmetic (the same bits).
pub(crate) trait MediumSampler {
    /// σ_t of extinction channel `e` at `p` (1/length).
    fn sigma_t(&mut self, e: usize, p: DVec3) -> f64;
    /// The albedo of channel `c` at `p`.
    fn albedo(&mut self, c: usize, p: DVec3) -> f64;
}

/// A problem's medium in memory.
struct DenseMedium<'a>(&'a lucent_core::Medium);

impl MediumSampler for DenseMedium<'_> {
    #[inline]
    fn sigma_t(&mut self, e: usize, p: DVec3) -> f64 {
        f64::from(self.0.sigma_t(e).sample_trilinear(p))
    }

    #[inline]
    fn albedo(&mut self, c: usize, p: DVec3) -> f64 {
        f64::from(self.0.albedo(c).sample(p))
    }
}

/// What every batch of a run shares: the box, the phase function, the lights (with the
/// emission samplers) and, in memory, the embedded surface.
pub(crate) struct Scene<'a> {
    pub(crate) geometry: lucent_grid::GridGeometry,
    pub(crate) phase: lucent_optics::Phase,
    pub(crate) lights: Vec<&'a Light>,
    pub(crate) emission: Vec<Option<EmissionCdf>>,
    surface: Option<Interface<'a>>,
}

impl<'a> Scene<'a> {
    /// A problem's scene.
    fn of(problem: &'a Problem) -> Self {
        let lights: Vec<&Light> = problem.lights().iter().collect();
        let emission = lights
            .iter()
            .map(|l| match l {
                Light::Emission { grid, .. } => Some(EmissionCdf::new(grid)),
                _ => None,
            })
            .collect();
        Self {
            geometry: *problem.geometry(),
            phase: problem.medium().phase,
            lights,
            emission,
            surface: problem
                .embedded()
                .map(|sdf| Interface::new(sdf, problem.boundary())),
        }
    }

    /// A scene of point-like lights and the sky in a box with nothing embedded (a paged
    /// problem's).
    pub(crate) fn plain(
        geometry: lucent_grid::GridGeometry,
        phase: lucent_optics::Phase,
        lights: &'a [Light],
    ) -> Self {
        Self {
            geometry,
            phase,
            lights: lights.iter().collect(),
            emission: lights.iter().map(|_| None).collect(),
            surface: None,
        }
    }
}

/// Russian roulette: once the largest weight falls below a tenth of `start`, the path
/// survives with probability (largest / (start/10)) and its weights are divided by it.
/// Returns false when the path ends. Unbiased; it keeps dim paths from costing time.
pub(crate) fn roulette(weights: &mut [f64], start: f64, rng: &mut PathRng) -> bool {
    let strongest = weights.iter().copied().fold(0.0, f64::max);
    if strongest >= 0.1 * start {
        return true;
    }
    let survive = strongest / (0.1 * start);
    if strongest == 0.0 || rng.uniform() >= survive {
        return false;
    }
    for w in weights {
        *w /= survive;
    }
    true
}

fn uniform_sphere(u: [f64; 2]) -> DVec3 {
    let z = 1.0 - 2.0 * u[0];
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * u[1]).sin_cos();
    DVec3::new(r * c, r * s, z)
}

/// Samples a particle leaving `light`: origin, unit direction, and the light's power per
/// unit of its spectrum carried by the particle before dividing by the particle count.
/// Sampling table of a volumetric emission light. The emission between cell centres is the
/// trilinear interpolant of the cell values (as for σ_t), which reaches into cells whose own
/// value is zero; so cells are proposed by the largest value among their 27 neighbours
/// (which bounds the interpolant inside them), a point is drawn uniformly in the cell, and
/// the particle's power is weighted by Q(x)/proposal — unbiased for the trilinear field.
pub(crate) struct EmissionCdf {
    proposal: Vec<f32>,
    cumulative: Vec<f64>,
    /// Σ proposal_i V_i.
    total: f64,
}

impl EmissionCdf {
    pub(crate) fn new(grid: &Grid) -> Self {
        let g = grid.geometry();
        let [nx, ny, nz] = g.dims();
        let volume = g.cell_volume();
        let mut proposal = vec![0f32; g.voxel_count()];
        for (index, p) in proposal.iter_mut().enumerate() {
            let [i, j, k] = g.coords(index);
            for kk in k.saturating_sub(1)..(k + 2).min(nz) {
                for jj in j.saturating_sub(1)..(j + 2).min(ny) {
                    for ii in i.saturating_sub(1)..(i + 2).min(nx) {
                        *p = p.max(grid.data()[g.index(ii, jj, kk)].max(0.0));
                    }
                }
            }
        }
        let mut total = 0.0;
        let cumulative = proposal
            .iter()
            .map(|&q| {
                total += f64::from(q) * volume;
                total
            })
            .collect();
        Self {
            proposal,
            cumulative,
            total,
        }
    }

    /// A point and the weight Q(x)/proposal that corrects for proposing it.
    fn sample(&self, grid: &Grid, rng: &mut PathRng) -> (DVec3, f64) {
        let target = rng.uniform() * self.total;
        let index = self
            .cumulative
            .partition_point(|&c| c <= target)
            .min(self.cumulative.len() - 1);
        let g = grid.geometry();
        let [i, j, k] = g.coords(index);
        let offset = DVec3::new(rng.uniform(), rng.uniform(), rng.uniform());
        let x = g.origin() + (DVec3::new(i as f64, j as f64, k as f64) + offset) * g.spacing();
        let proposal = f64::from(self.proposal[index]);
        let weight = if proposal > 0.0 {
            f64::from(grid.sample_trilinear(x)).max(0.0) / proposal
        } else {
            0.0
        };
        (x, weight)
    }
}

fn emit(
    light: &Light,
    emission: Option<&EmissionCdf>,
    lo: DVec3,
    hi: DVec3,
    rng: &mut PathRng,
) -> Option<(DVec3, DVec3, f64)> {
    match *light {
        Light::Directional { direction, .. } => {
            // Start on the box faces that face the beam, chosen by projected area |n·d| A:
            // every particle enters, and the power is E times the box's projected area.
            let e = hi - lo;
            let areas = [e.y * e.z, e.x * e.z, e.x * e.y];
            let projected: [f64; 3] = std::array::from_fn(|a| areas[a] * direction[a].abs());
            let total: f64 = projected.iter().sum();
            let mut pick = rng.uniform() * total;
            let mut axis = 2;
            for (a, p) in projected.iter().enumerate() {
                if pick < *p {
                    axis = a;
                    break;
                }
                pick -= p;
            }
            let [u, v] = rng.uniform2();
            let mut p = lo + e * DVec3::new(u, v, rng.uniform());
            p[axis] = if direction[axis] > 0.0 {
                lo[axis]
            } else {
                hi[axis]
            };
            // Start a hair outside so that the first clip finds the face.
            Some((p - direction * 1e-9 * e.max_element(), direction, total))
        }
        Light::Point { position, .. } => Some((position, uniform_sphere(rng.uniform2()), 4.0 * PI)),
        Light::Spot {
            position,
            direction,
            outer_angle,
            ..
        } => {
            // Uniform in solid angle inside the outer cone, weighted by the fall-off.
            let cos_outer = outer_angle.cos();
            let [u, v] = rng.uniform2();
            let cos = 1.0 - u * (1.0 - cos_outer);
            let sin = (1.0 - cos * cos).max(0.0).sqrt();
            let (t, b) = direction.any_orthonormal_pair();
            let d = t * (sin * (2.0 * PI * v).cos())
                + b * (sin * (2.0 * PI * v).sin())
                + direction * cos;
            let falloff = light
                .arrival(position + d, 1.0, 0.0)
                .map_or(0.0, |(_, e, _)| e);
            Some((position, d, 2.0 * PI * (1.0 - cos_outer) * falloff))
        }
        Light::Sky { .. } => {
            // Power π L A enters through the boundary of area A: pick a face by area, a point
            // on it, and a cosine-weighted inward direction.
            let e = hi - lo;
            let areas = [
                e.y * e.z,
                e.y * e.z,
                e.x * e.z,
                e.x * e.z,
                e.x * e.y,
                e.x * e.y,
            ];
            let total: f64 = areas.iter().sum();
            let mut pick = rng.uniform() * total;
            let mut face = 5;
            for (f, a) in areas.iter().enumerate() {
                if pick < *a {
                    face = f;
                    break;
                }
                pick -= a;
            }
            let axis = face / 2;
            let [u, v] = rng.uniform2();
            let mut p = lo + e * DVec3::new(u, v, rng.uniform());
            let inward = if face % 2 == 0 { 1.0 } else { -1.0 };
            p[axis] = if face % 2 == 0 { lo[axis] } else { hi[axis] };
            let mut normal = DVec3::ZERO;
            normal[axis] = inward;
            let [a, b] = rng.uniform2();
            let (r, phi) = (a.sqrt(), 2.0 * PI * b);
            let (t1, t2) = normal.any_orthonormal_pair();
            let d =
                t1 * (r * phi.cos()) + t2 * (r * phi.sin()) + normal * (1.0 - a).max(0.0).sqrt();
            // Start a hair outside so that the first clip finds the face.
            Some((p - d * 1e-9 * e.max_element(), d, PI * total))
        }
        Light::Emission { ref grid, .. } => {
            // A point drawn by (bounding) emitted power, an isotropic direction.
            let cdf = emission.filter(|c| c.total > 0.0)?;
            let (origin, weight) = cdf.sample(grid, rng);
            Some((
                origin,
                uniform_sphere(rng.uniform2()),
                4.0 * PI * cdf.total * weight,
            ))
        }
    }
}

/// Traces `config.particles` particles per light and batch and returns the batch-averaged
/// fluence with standard errors and the energy balance.
pub fn estimate(problem: &Problem, config: &McConfig) -> Result<McEstimate, SolveError> {
    estimate_with(problem, config, &RunControl::default())
}

/// What a caller may ask of a run while it goes: progress after every round of batches,
/// and an interrupt (Ctrl-C, the time limit) that stops it within a few milliseconds:
/// every batch asks it every 64 paths, a batch it stops is dropped, and the estimate is
/// made of the batches traced whole (at least two, for the standard errors: with fewer
/// the run ends in [`SolveError::Halted`]).
#[derive(Default)]
pub struct RunControl<'a> {
    /// Called with (batches done, batches asked for), over every tracing group.
    pub progress: Option<&'a (dyn Fn(usize, usize) + Sync)>,
    /// What stops the run.
    pub interrupt: Interrupt,
}

/// Paths between two looks at the interrupt (a path in a dense medium: microseconds).
pub(crate) const PATHS_PER_CHECK: u64 = 64;

/// The most tentative collisions delta tracking may need to cross the box once
/// (the largest σ_t times the box's diagonal).
pub const MAX_OPTICAL_REACH: f64 = 1e6;

/// Refuses a medium so thick that delta tracking could not finish: crossing the box takes
/// about max σ_t × diagonal tentative collisions per flight, and a path makes many flights.
/// At 10⁶ (a box a million mean free paths across) light is diffuse long before it gets
/// anywhere, and the diffusion solvers are the tool.
pub fn check_optical_reach(problem: &Problem) -> Result<(), SolveError> {
    let peak = problem
        .medium()
        .sigma_t
        .iter()
        .flat_map(|g| g.data().iter())
        .fold(0.0f64, |m, &v| m.max(f64::from(v)));
    check_reach(problem.geometry(), peak)
}

/// [`check_optical_reach`] for the largest extinction `peak` on `geometry` (a paged
/// medium's comes from its bricks' ranges).
pub(crate) fn check_reach(
    geometry: &lucent_grid::GridGeometry,
    peak: f64,
) -> Result<(), SolveError> {
    let (lo, hi) = geometry.bounds();
    let reach = peak * (hi - lo).length();
    if reach > MAX_OPTICAL_REACH {
        return Err(SolveError::TooMuchWork {
            solver: "mc".into(),
            what: "the tentative collisions to cross the box once (largest σ_t × diagonal)".into(),
            estimate: reach,
            limit: MAX_OPTICAL_REACH,
            advice: "a medium this optically thick is diffusive: use a diffusion solver".into(),
        });
    }
    Ok(())
}

/// [`estimate`] under a [`RunControl`]; [`McEstimate::batches`] says how many batches ran
/// (fewer than asked when the time budget stopped the run).
pub fn estimate_with(
    problem: &Problem,
    config: &McConfig,
    control: &RunControl<'_>,
) -> Result<McEstimate, SolveError> {
    if config.batches < 2
        || config.particles == 0
        || config.max_depth == 0
        || config.majorant_cells == 0
    {
        return Err(SolveError::InvalidParameter {
            name: "mc".into(),
            reason: "needs ≥ 2 batches, ≥ 1 particle, max_depth ≥ 1 and majorant_cells ≥ 1".into(),
        });
    }
    check_optical_reach(problem)?;
    let geometry = *problem.geometry();
    let medium = problem.medium();
    let channels = problem.channels();
    let voxels = geometry.voxel_count();
    let scene = Scene::of(problem);
    // Tracing groups: one per extinction grid; a grey extinction carries every channel, and
    // an RGB one too with spectral MIS (`SPECTRAL` marks that group).
    const SPECTRAL: usize = usize::MAX;
    let spectral = medium.sigma_t.len() == 3 && config.spectral_mis && problem.embedded().is_none();
    let groups: Vec<(usize, Vec<usize>)> = if medium.sigma_t.len() == 1 {
        vec![(0, (0..channels).collect())]
    } else if spectral {
        vec![(SPECTRAL, vec![0, 1, 2])]
    } else {
        (0..3).map(|c| (c, vec![c])).collect()
    };
    let mut sum = vec![vec![0.0f64; voxels]; channels];
    let mut sum_sq = vec![vec![0.0f64; voxels]; channels];
    let mut energy_sums = vec![[[0.0f64; 2]; 5]; channels];
    let batch_ids: Vec<usize> = (0..config.batches).collect();
    let group_size = rayon::current_num_threads().max(1);
    // Batches run per channel (a time budget can stop a group early).
    let mut done = vec![0usize; channels];
    let total = config.batches * groups.len();
    let mut finished = 0usize;
    let traced = std::sync::atomic::AtomicUsize::new(0);
    for (extinction, members) in &groups {
        let max_extinction;
        let sigma_t = if *extinction == SPECTRAL {
            // The shared majorant bounds all three channels.
            let mut max = medium.sigma_t[0].clone();
            for other in &medium.sigma_t[1..] {
                for (m, v) in max.data_mut().iter_mut().zip(other.data()) {
                    *m = m.max(*v);
                }
            }
            max_extinction = max;
            &max_extinction
        } else {
            medium.sigma_t(*extinction)
        };
        let majorant = MajorantGrid::for_config(sigma_t, config);
        let mut ran = 0;
        for chunk in batch_ids.chunks(group_size) {
            if control.interrupt.halted() {
                break;
            }
            let tallies: Vec<Tally<Vec<Vec<f64>>>> = chunk
                .par_iter()
                .map(|&batch| {
                    let fluence = vec![vec![0.0f64; voxels]; members.len()];
                    let mut medium = DenseMedium(medium);
                    let tally = if *extinction == SPECTRAL {
                        trace_batch_spectral(
                            &scene,
                            &mut medium,
                            &majorant,
                            config,
                            batch as u64,
                            fluence,
                            &control.interrupt,
                        )
                    } else {
                        trace_batch(
                            &scene,
                            &mut medium,
                            *extinction,
                            &majorant,
                            members,
                            config,
                            batch as u64 + 1000 * *extinction as u64,
                            fluence,
                            &control.interrupt,
                        )
                    };
                    // One report per batch, as each finishes.
                    let now = traced.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                    if let Some(progress) = control.progress {
                        progress(now, total);
                    }
                    tally
                })
                .collect();
            // Accumulate in batch order: the result does not depend on the thread count.
            // A batch an interrupt stopped part way is dropped.
            let whole = tallies.iter().filter(|t| t.complete).count();
            for tally in tallies.into_iter().filter(|t| t.complete) {
                for (m, &c) in members.iter().enumerate() {
                    let inv_volume = 1.0 / geometry.cell_volume();
                    for (v, &t) in tally.fluence[m].iter().enumerate() {
                        let phi = t * inv_volume;
                        sum[c][v] += phi;
                        sum_sq[c][v] += phi * phi;
                    }
                    let imbalance = tally.emitted[m]
                        - tally.absorbed[m]
                        - tally.escaped[m]
                        - tally.truncated[m];
                    for (q, value) in [
                        tally.emitted[m],
                        tally.absorbed[m],
                        tally.escaped[m],
                        tally.truncated[m],
                        imbalance,
                    ]
                    .into_iter()
                    .enumerate()
                    {
                        energy_sums[c][q][0] += value;
                        energy_sums[c][q][1] += value * value;
                    }
                }
            }
            ran += whole;
            finished += whole;
        }
        if let Some(halt) = control.interrupt.halt().filter(|_| ran < 2) {
            return Err(SolveError::Halted {
                solver: "mc".into(),
                stage: "its first two batches (the least a standard error needs)".into(),
                halt,
            });
        }
        for &c in members {
            done[c] = ran;
        }
    }
    let batches = done.iter().copied().min().unwrap_or(0).max(1);
    let stats_for = |c: usize| {
        let b = done[c].max(1) as f64;
        move |s: f64, s2: f64| {
            let mean = s / b;
            let var = ((s2 / b - mean * mean) * b / (b - 1.0).max(1.0)).max(0.0);
            Estimate {
                mean,
                std_error: (var / b).sqrt(),
            }
        }
    };
    let fluence = (0..channels)
        .map(|c| {
            let b = done[c].max(1) as f64;
            Grid::from_vec(geometry, sum[c].iter().map(|&s| (s / b) as f32).collect())
        })
        .collect::<Result<Vec<_>, _>>()?;
    let standard_error = (0..channels)
        .map(|c| {
            let stat = stats_for(c);
            Grid::from_vec(
                geometry,
                sum[c]
                    .iter()
                    .zip(&sum_sq[c])
                    .map(|(&s, &s2)| stat(s, s2).std_error as f32)
                    .collect(),
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    let energy = energy_sums
        .iter()
        .enumerate()
        .map(|(c, e)| {
            let stat = stats_for(c);
            EnergyBalance {
                emitted: stat(e[0][0], e[0][1]),
                absorbed: stat(e[1][0], e[1][1]),
                escaped: stat(e[2][0], e[2][1]),
                truncated: stat(e[3][0], e[3][1]),
                imbalance: stat(e[4][0], e[4][1]),
            }
        })
        .collect();
    let paths = config.particles * scene.lights.len() as u64 * finished as u64;
    Ok(McEstimate {
        fluence,
        standard_error,
        energy,
        paths,
        batches,
    })
}

/// One batch of one tracing group: every light emits `config.particles` particles.
/// `extinction` is the group's extinction channel; the fluence goes to `fluence`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn trace_batch<M: MediumSampler, F: FluenceTally>(
    scene: &Scene<'_>,
    medium: &mut M,
    extinction: usize,
    majorant: &MajorantGrid,
    members: &[usize],
    config: &McConfig,
    batch: u64,
    fluence: F,
    interrupt: &Interrupt,
) -> Tally<F> {
    let geometry = scene.geometry;
    let (lo, hi) = geometry.bounds();
    let phase = scene.phase;
    let mut tally = Tally::new(members.len(), fluence);
    let n = config.particles as f64;
    let surface = scene.surface.as_ref();
    for (l, light) in scene.lights.iter().enumerate() {
        for path in 0..config.particles {
            if path % PATHS_PER_CHECK == 0 && interrupt.halted() {
                tally.complete = false;
                return tally;
            }
            let mut rng = PathRng::new(config.seed, batch, (l as u64) << 40 | path);
            let Some((mut pos, mut dir, power)) =
                emit(light, scene.emission[l].as_ref(), lo, hi, &mut rng)
            else {
                continue;
            };
            let mut weight: Vec<f64> = members
                .iter()
                .map(|&c| light.spectrum().channel(c) * power / n)
                .collect();
            if weight.iter().all(|&w| w == 0.0) {
                continue;
            }
            let mut entered = false;
            let initial = weight.iter().copied().fold(0.0, f64::max);
            let mut depth = 0;
            let mut crossings = 0u32;
            loop {
                let Some((t_in, t_out)) = ray_box(pos, dir, lo, hi) else {
                    if entered {
                        for (m, w) in weight.iter().enumerate() {
                            tally.escaped[m] += w;
                        }
                    }
                    break;
                };
                if !entered {
                    entered = true;
                    for (m, w) in weight.iter().enumerate() {
                        tally.emitted[m] += w;
                    }
                }
                // With embedded geometry the flight also ends where it meets the surface,
                // and only the inside holds medium.
                let inside = surface.is_none_or(|s| s.inside(pos));
                let t_surface = surface.and_then(|s| s.hit(pos, dir, t_in, t_out, inside));
                let t_stop = t_surface.unwrap_or(t_out);
                // Delta tracking between t_in and t_stop.
                let mut collision = None;
                if inside {
                    majorant.tentative_collisions(
                        pos,
                        dir,
                        t_in,
                        t_stop,
                        &mut rng,
                        |t, sigma_max, rng| {
                            let sigma = medium.sigma_t(extinction, pos + dir * t);
                            if rng.uniform() * sigma_max < sigma {
                                collision = Some(t);
                                return false;
                            }
                            true
                        },
                    );
                }
                let t_end = collision.unwrap_or(t_stop);
                // Track-length estimator: w·ℓ in every cell the free flight crosses.
                geometry.traverse(pos + dir * t_in, pos + dir * t_end, |index, enter, exit| {
                    for (m, w) in weight.iter().enumerate() {
                        tally.fluence.add(m, index, w * (exit - enter));
                    }
                    true
                });
                let Some(t) = collision else {
                    if let (Some(s), Some(t)) = (surface, t_surface) {
                        // At the interface: Fresnel reflection or refraction, then fly on.
                        crossings += 1;
                        if crossings > 100_000 {
                            // A path trapped at the surface (round-off in the SDF): cut it.
                            for (m, w) in weight.iter().enumerate() {
                                tally.truncated[m] += w;
                            }
                            break;
                        }
                        let (p, d) = s.interact(pos + dir * t, dir, rng.uniform());
                        pos = p;
                        dir = d;
                        continue;
                    }
                    for (m, w) in weight.iter().enumerate() {
                        tally.escaped[m] += w;
                    }
                    break;
                };
                pos += dir * t;
                // Implicit capture: the absorbed share is tallied, the rest scatters on.
                for (m, &c) in members.iter().enumerate() {
                    let albedo = medium.albedo(c, pos).clamp(0.0, 1.0);
                    tally.absorbed[m] += weight[m] * (1.0 - albedo);
                    weight[m] *= albedo;
                }
                depth += 1;
                if depth >= config.max_depth {
                    for (m, w) in weight.iter().enumerate() {
                        tally.truncated[m] += w;
                    }
                    break;
                }
                // Russian roulette once a path carries less than a tenth of its start.
                if !roulette(&mut weight, initial, &mut rng) {
                    break;
                }
                dir = phase.sample(dir, rng.uniform2()).omega_out;
            }
        }
    }
    tally
}

/// One batch for an RGB extinction with spectral MIS: one hero channel per particle decides
/// distances and real or null collisions against the shared majorant; `f` is each channel's
/// weight and `p` the path's probability under each hero, renormalised so that the mean of
/// `p` is 1 (the balance heuristic over the three heroes). The track-length tally adds
/// every piece between tentative collisions with the weights of the path up to its start:
/// the next tentative point is drawn from the shared majorant, the same for every channel,
/// so no weight is owed for it.
pub(crate) fn trace_batch_spectral<M: MediumSampler, F: FluenceTally>(
    scene: &Scene<'_>,
    medium: &mut M,
    majorant: &MajorantGrid,
    config: &McConfig,
    batch: u64,
    fluence: F,
    interrupt: &Interrupt,
) -> Tally<F> {
    let geometry = scene.geometry;
    let (lo, hi) = geometry.bounds();
    let phase = scene.phase;
    let mut tally = Tally::new(3, fluence);
    let n = config.particles as f64;
    for (l, light) in scene.lights.iter().enumerate() {
        for path in 0..config.particles {
            if path % PATHS_PER_CHECK == 0 && interrupt.halted() {
                tally.complete = false;
                return tally;
            }
            let mut rng = PathRng::new(config.seed, batch + 5000, (l as u64) << 40 | path);
            let Some((mut pos, mut dir, power)) =
                emit(light, scene.emission[l].as_ref(), lo, hi, &mut rng)
            else {
                continue;
            };
            let hero = ((rng.uniform() * 3.0) as usize).min(2);
            let mut f: [f64; 3] = std::array::from_fn(|c| light.spectrum().channel(c) * power / n);
            let mut p = [1.0f64; 3];
            if f.iter().all(|&w| w == 0.0) {
                continue;
            }
            let initial = f.iter().copied().fold(0.0, f64::max);
            let mut entered = false;
            let mut depth = 0;
            'path: loop {
                let Some((t_in, t_out)) = ray_box(pos, dir, lo, hi) else {
                    if entered {
                        for c in 0..3 {
                            tally.escaped[c] += f[c];
                        }
                    }
                    break;
                };
                if !entered {
                    entered = true;
                    for c in 0..3 {
                        tally.emitted[c] += f[c];
                    }
                }
                // Walk tentative collisions; tally each piece, then apply its event.
                let mut start = t_in;
                let mut collision = None;
                majorant.tentative_collisions(
                    pos,
                    dir,
                    t_in,
                    t_out,
                    &mut rng,
                    |t, sigma_max, rng| {
                        let piece = (pos + dir * start, pos + dir * t);
                        geometry.traverse(piece.0, piece.1, |index, enter, exit| {
                            for c in 0..3 {
                                tally.fluence.add(c, index, f[c] * (exit - enter));
                            }
                            true
                        });
                        start = t;
                        let x = pos + dir * t;
                        let s: [f64; 3] = std::array::from_fn(|c| medium.sigma_t(c, x));
                        let real = rng.uniform() * sigma_max < s[hero];
                        for c in 0..3 {
                            let q = (s[c] / sigma_max).min(1.0);
                            let factor = if real { q } else { 1.0 - q };
                            f[c] *= factor;
                            p[c] *= factor;
                        }
                        // Keep the mean of p at 1: f is then the balance-heuristic weight.
                        let mean = (p[0] + p[1] + p[2]) / 3.0;
                        if mean > 0.0 {
                            for c in 0..3 {
                                f[c] /= mean;
                                p[c] /= mean;
                            }
                        }
                        if real {
                            collision = Some(t);
                            return false;
                        }
                        true
                    },
                );
                let Some(t) = collision else {
                    geometry.traverse(
                        pos + dir * start,
                        pos + dir * t_out,
                        |index, enter, exit| {
                            for c in 0..3 {
                                tally.fluence.add(c, index, f[c] * (exit - enter));
                            }
                            true
                        },
                    );
                    for c in 0..3 {
                        tally.escaped[c] += f[c];
                    }
                    break;
                };
                pos += dir * t;
                // The real-collision factor σ_c/σ̄ is in f already; the scattered share is
                // the albedo of σ_c, the rest is absorbed.
                for c in 0..3 {
                    let albedo = medium.albedo(c, pos).clamp(0.0, 1.0);
                    tally.absorbed[c] += f[c] * (1.0 - albedo);
                    f[c] *= albedo;
                }
                depth += 1;
                if depth >= config.max_depth {
                    for c in 0..3 {
                        tally.truncated[c] += f[c];
                    }
                    break 'path;
                }
                if !roulette(&mut f, initial, &mut rng) {
                    break 'path;
                }
                dir = phase.sample(dir, rng.uniform2()).omega_out;
            }
        }
    }
    tally
}

/// The embedded surface (the zero level of a signed distance grid, negative inside) and the
/// refractive index jump across it: a Robin boundary of index η is, for transport, a smooth
/// dielectric interface of relative index η; a vacuum boundary an index-matched one.
struct Interface<'a> {
    sdf: &'a Grid,
    dielectric: Option<Dielectric>,
    /// Nudge off the surface after an interaction.
    epsilon: f64,
    /// The shortest sphere-tracing step (an eighth of a cell: grazing rays stay cheap; a
    /// surface crossed twice within it is missed, which the trilinear SDF cannot resolve
    /// anyway).
    min_step: f64,
}

impl<'a> Interface<'a> {
    fn new(sdf: &'a Grid, boundary: Boundary) -> Self {
        let dielectric = match boundary {
            Boundary::Robin { eta } if eta != 1.0 => Dielectric::new(eta).ok(),
            _ => None,
        };
        let g = sdf.geometry();
        Self {
            sdf,
            dielectric,
            epsilon: 1e-6 * g.extent().max_element(),
            min_step: 0.125 * g.spacing().min_element(),
        }
    }

    fn distance(&self, p: DVec3) -> f64 {
        f64::from(self.sdf.sample_trilinear(p))
    }

    fn inside(&self, p: DVec3) -> bool {
        self.distance(p) < 0.0
    }

    /// The first t in (t0, t1) where the ray crosses the surface from the side it is on:
    /// sphere tracing on the trilinear distance (steps of 0.9|d|, at least ε), then
    /// bisection on the bracketing step.
    fn hit(&self, o: DVec3, d: DVec3, t0: f64, t1: f64, inside: bool) -> Option<f64> {
        let side = |t: f64| {
            let v = self.distance(o + d * t);
            if inside { v >= 0.0 } else { v <= 0.0 }
        };
        let mut t = t0;
        while t < t1 {
            let step = (0.9 * self.distance(o + d * t).abs()).max(self.min_step);
            let next = (t + step).min(t1);
            if side(next) {
                let (mut a, mut b) = (t, next);
                for _ in 0..48 {
                    let m = 0.5 * (a + b);
                    if side(m) { b = m } else { a = m }
                }
                return Some(b);
            }
            if next >= t1 {
                break;
            }
            t = next;
        }
        None
    }

    /// Reflects or refracts a particle that reached the surface at `p` travelling along `d`;
    /// returns the new position (nudged off the surface) and direction.
    fn interact(&self, p: DVec3, d: DVec3, u: f64) -> (DVec3, DVec3) {
        let h = 0.5 * self.sdf.geometry().spacing().min_element();
        let gradient = DVec3::new(
            self.distance(p + DVec3::X * h) - self.distance(p - DVec3::X * h),
            self.distance(p + DVec3::Y * h) - self.distance(p - DVec3::Y * h),
            self.distance(p + DVec3::Z * h) - self.distance(p - DVec3::Z * h),
        );
        let n = gradient.normalize_or_zero();
        let Some(dielectric) = self.dielectric.filter(|_| n != DVec3::ZERO) else {
            return (p + d * self.epsilon, d);
        };
        let cos = d.dot(n); // > 0: leaving the object
        let reflect = u < dielectric.reflectance(-cos);
        let out = if reflect {
            d - n * (2.0 * cos)
        } else {
            // Snell: ratio n_incident / n_transmitted, normal facing the incident side.
            let (ratio, facing) = if cos > 0.0 {
                (dielectric.eta(), -n)
            } else {
                (1.0 / dielectric.eta(), n)
            };
            let cos_i = -d.dot(facing);
            let sin2_t = ratio * ratio * (1.0 - cos_i * cos_i);
            (d * ratio + facing * (ratio * cos_i - (1.0 - sin2_t).max(0.0).sqrt())).normalize()
        };
        (p + out * self.epsilon, out)
    }
}
