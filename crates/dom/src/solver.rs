//! The registry entry `dom`: discrete ordinates on a problem's grid.
//!
//! - Point-like lights (directional, point, spot) are ray-marched by `direct`; their
//!   first-collision source σ_s E T p̄(ω_l → ω_m) at the storage directions (normalised and
//!   g-corrected as the phase matrix is) drives the sweeps (Bernabei's MDOM), and their
//!   uncollided fluence is added to the sweeps' fluence.
//! - A sky is the sweeps' boundary radiance; emission an isotropic fixed source.
//! - Boundaries: vacuum; Robin (η) as a diffuse reflector of the same partial-current
//!   reflectance R = (A − 1)/(A + 1) as the diffusion solvers' A (a Robin-like condition,
//!   not a Fresnel interface); a reflecting (zero-flux Neumann) box as R = 1.
//! - Output: fluence, and [`lucent_core::OrdinateRadiance`] for the renderer.
//!
//! Parameters: `order` (level-symmetric S_N, default 8; with `family = "octahedral"` the
//! refinement level, default 2), `family` (`level-symmetric` or `octahedral`),
//! `storage_level` (store sources on the octahedral set of this level instead of on the
//! propagation set), `closure` (`diamond`, `step`, `exponential`), `acceleration` (`dsa`
//! or `none`), `anderson` (mixing depth, 2; 0 off), `block` (wavefront block edge, 16),
//! `refine_uncollided` (2: the uncollided light and its first-collision source are
//! averaged over 2³ sub-cells, as the sweeps' cell averages are; 1: cell centres).

use std::time::Instant;

use lucent_core::{
    Angular, Boundary, BoundaryKind, Capabilities, FluenceKind, Light, LightKind, OrdinateRadiance,
    OutputKind, ParamValue, Params, Problem, Solution, SolveError, SolveOptions, SolveReport,
    Solver, SolverEntry, StopReason,
};
use lucent_grid::Grid;
use lucent_optics::SphericalQuadrature;

use crate::angular::Ordinates;
use crate::closure::Closure;
use crate::solve::{Acceleration, DomBoundary, DomProblem, DomSettings, solve};

/// `dom`.
#[derive(Debug, Clone, PartialEq)]
pub struct DomSolver {
    octahedral: bool,
    order: usize,
    storage_level: Option<usize>,
    refine: usize,
    settings: DomSettings,
}

fn invalid(name: &str, reason: impl Into<String>) -> SolveError {
    SolveError::InvalidParameter {
        name: name.into(),
        reason: reason.into(),
    }
}

fn text<'a>(p: &'a Params, name: &str, default: &'a str) -> Result<&'a str, SolveError> {
    match p.0.get(name) {
        None => Ok(default),
        Some(ParamValue::Text(t)) => Ok(t),
        Some(other) => Err(invalid(name, format!("expected text, got {other:?}"))),
    }
}

impl DomSolver {
    /// The registry entry.
    pub const ENTRY: SolverEntry = SolverEntry {
        name: "dom",
        summary: "discrete ordinates: octant wavefront sweeps, first-collision sources, DSA",
        build: |p: &Params| Ok(Box::new(DomSolver::from_params(p)?)),
    };

    /// The solver for registry parameters.
    pub fn from_params(p: &Params) -> Result<Self, SolveError> {
        p.check_known(
            "dom",
            &[
                "order",
                "family",
                "storage_level",
                "closure",
                "acceleration",
                "anderson",
                "block",
                "refine_uncollided",
            ],
        )?;
        let octahedral = match text(p, "family", "level-symmetric")? {
            "level-symmetric" => false,
            "octahedral" => true,
            other => {
                return Err(invalid(
                    "family",
                    format!("{other}: level-symmetric or octahedral"),
                ));
            }
        };
        let order = p.usize_or("order", if octahedral { 2 } else { 8 })?;
        let storage_level = match p.0.get("storage_level") {
            None => None,
            Some(_) => Some(p.usize_or("storage_level", 0)?),
        };
        let closure = match text(p, "closure", "diamond")? {
            "diamond" => Closure::Diamond,
            "step" => Closure::Step,
            "exponential" => Closure::Exponential,
            other => {
                return Err(invalid(
                    "closure",
                    format!("{other}: diamond, step or exponential"),
                ));
            }
        };
        let acceleration = match text(p, "acceleration", "dsa")? {
            "dsa" => Acceleration::Dsa,
            "none" => Acceleration::None,
            other => return Err(invalid("acceleration", format!("{other}: dsa or none"))),
        };
        let anderson = p.usize_or("anderson", 2)?;
        let block = p.usize_or("block", 16)?;
        let refine = p.usize_or("refine_uncollided", 2)?;
        if !(1..=2).contains(&refine) {
            return Err(invalid(
                "refine_uncollided",
                "1 (cell centres) or 2 (cell averages)",
            ));
        }
        if anderson > 16 || !(1..=256).contains(&block) {
            return Err(invalid("anderson/block", "anderson ≤ 16, 1 ≤ block ≤ 256"));
        }
        let solver = Self {
            octahedral,
            order,
            storage_level,
            refine,
            settings: DomSettings {
                closure,
                acceleration,
                anderson,
                block,
            },
        };
        solver.ordinates(lucent_optics::Phase::Isotropic)?;
        Ok(solver)
    }

    /// The angular sets for `phase`.
    fn ordinates(&self, phase: lucent_optics::Phase) -> Result<Ordinates, SolveError> {
        let quadrature = |e: lucent_optics::OpticsError| invalid("order", e.to_string());
        let propagation = if self.octahedral {
            SphericalQuadrature::octahedral(self.order)
        } else {
            SphericalQuadrature::level_symmetric(self.order)
        }
        .map_err(quadrature)?;
        let storage = self
            .storage_level
            .map(SphericalQuadrature::octahedral)
            .transpose()
            .map_err(|e| invalid("storage_level", e.to_string()))?;
        Ordinates::new(propagation, storage, phase)
            .map_err(|e| invalid("storage_level", e.to_string()))
    }
}

impl Solver for DomSolver {
    fn name(&self) -> &str {
        "dom"
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            anisotropic: true,
            heterogeneous: true,
            embedded_geometry: false,
            boundaries: vec![
                BoundaryKind::Vacuum,
                BoundaryKind::Robin,
                BoundaryKind::Neumann,
            ],
            lights: vec![
                LightKind::Directional,
                LightKind::Point,
                LightKind::Spot,
                LightKind::Sky,
                LightKind::Emission,
            ],
            output: OutputKind::AngularRadiance,
            fluence: FluenceKind::Total,
        }
    }

    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
        self.solve_with_details(problem, options).map(|(s, _)| s)
    }
}

impl DomSolver {
    /// [`Solver::solve`], also returning each channel's iteration record (sweeps, timings,
    /// contraction, whether DSA was dropped).
    pub fn solve_with_details(
        &self,
        problem: &Problem,
        options: &SolveOptions,
    ) -> Result<(Solution, Vec<crate::DomConvergence>), SolveError> {
        self.capabilities().check(self.name(), problem)?;
        options.validate()?;
        let started = Instant::now();
        let g = *problem.geometry();
        let n = g.voxel_count();
        let medium = problem.medium();
        let ordinates = self.ordinates(medium.phase)?;
        let m = ordinates.storage().len();
        let channels = problem.channels();
        let anderson_vectors = 2 * self.settings.anderson + 2;
        let bytes = (n * m * 4 * (3 + anderson_vectors) + n * 40) as u64 * channels as u64;
        if bytes > options.memory_budget {
            return Err(SolveError::OverBudget {
                solver: self.name().into(),
                needed: bytes,
                budget: options.memory_budget,
            });
        }
        let reflectance = match problem.boundary() {
            Boundary::Vacuum => 0.0,
            Boundary::Neumann { flux: 0.0 } => 1.0,
            Boundary::Neumann { .. } => {
                return Err(invalid(
                    "boundary",
                    "only a reflecting (zero-flux) Neumann box",
                ));
            }
            b => {
                let a = b.robin_factor().unwrap_or(1.0);
                (a - 1.0) / (a + 1.0)
            }
        };
        // Point-like lights through `direct` (uncollided, exact).
        let pointlike: Vec<Light> = problem
            .lights()
            .iter()
            .filter(|l| {
                matches!(
                    l,
                    Light::Directional { .. } | Light::Point { .. } | Light::Spot { .. }
                )
            })
            .cloned()
            .collect();
        // The sweeps give cell averages; so that the uncollided part is one too, `direct`
        // runs on a grid refined `refine` times and is averaged back (its values are
        // exact at points: at cell centres they differ from cell averages by O(1) across
        // shadow edges and near sources).
        let direct = if pointlike.is_empty() {
            None
        } else {
            let fine_medium = if self.refine == 1 {
                medium.clone()
            } else {
                medium.resampled(g.dims().map(|d| d * self.refine))?
            };
            let fine = *fine_medium.sigma_t(0).geometry();
            let p = Problem::new(fine, fine_medium, pointlike, Boundary::Vacuum, None)?;
            Some(lucent_core::DirectSolver::default().solve(&p, options)?)
        };
        let lights = direct.as_ref().and_then(|d| match &d.angular {
            Some(Angular::Lights(l)) => Some(l.clone()),
            _ => None,
        });
        let stopping = lucent_diffusion::Stopping {
            relative_tolerance: options.relative_tolerance,
            absolute_tolerance: options.absolute_tolerance,
            max_iterations: options.max_iterations,
            time_budget: options.time_budget,
        };
        let mut fluence = Vec::with_capacity(channels);
        let mut inscattered = Vec::with_capacity(channels);
        let mut report: Option<(Vec<f64>, StopReason)> = None;
        let mut records = Vec::with_capacity(channels);
        for c in 0..channels {
            let sigma_t: Vec<f32> = medium.sigma_t(c).data().to_vec();
            let sigma_s: Vec<f32> = (0..n)
                .map(|cell| {
                    let [i, j, k] = g.coords(cell);
                    medium
                        .sigma_s_at(c, g.cell_centre(i, j, k))
                        .min(sigma_t[cell])
                })
                .collect();
            let mut fixed = vec![0.0f32; n * m];
            let mut sky = 0.0;
            for light in problem.lights() {
                match light {
                    Light::Emission { grid, scale } => {
                        let s = scale.channel(c);
                        for (row, e) in fixed.chunks_mut(m).zip(grid.data()) {
                            let q = (s * f64::from(*e)) as f32;
                            row.iter_mut().for_each(|v| *v += q);
                        }
                    }
                    Light::Sky { radiance } => sky += radiance.channel(c),
                    _ => {}
                }
            }
            if let (Some(l), Some(d)) = (&lights, &direct) {
                let fine = *d.fluence(c).geometry();
                first_collision(&ordinates, l, &fine, self.refine, c, medium, &mut fixed);
            }
            let dom = DomProblem {
                geometry: g,
                sigma_t,
                sigma_s,
                fixed,
                boundary: DomBoundary {
                    radiance: sky,
                    reflectance,
                },
            };
            let solution = solve(&dom, &ordinates, &self.settings, &stopping)
                .map_err(|e| invalid("problem", e.to_string()))?;
            let mut total: Vec<f32> = solution.fluence.iter().map(|v| *v as f32).collect();
            if let Some(d) = &direct {
                let uncollided = match self.refine {
                    1 => d.fluence(c).clone(),
                    _ => lucent_grid::resample::restrict(d.fluence(c)),
                };
                for (t, u) in total.iter_mut().zip(uncollided.data()) {
                    *t += u;
                }
            }
            fluence.push(Grid::from_vec(g, total)?);
            inscattered.push(solution.inscattered);
            let conv = solution.convergence;
            records.push(conv.clone());
            let replace = match &report {
                None => true,
                Some((_, reason)) => reason.is_converged() && !conv.stop_reason.is_converged(),
            };
            if replace {
                report = Some((conv.residuals, conv.stop_reason));
            }
        }
        let (residuals, stop_reason) = report.ok_or_else(|| invalid("problem", "no channel"))?;
        let solution = Solution {
            fluence,
            angular: Some(Angular::Ordinates(OrdinateRadiance {
                directions: ordinates.storage().directions().to_vec(),
                kernel: ordinates.kernel(),
                inscattered,
                geometry: g,
                lights,
            })),
            standard_error: None,
            report: SolveReport {
                solver: self.name().into(),
                iterations: residuals.len(),
                residual_history: residuals,
                wall_time_s: started.elapsed().as_secs_f64(),
                peak_memory_bytes: bytes,
                stop_reason,
            },
        };
        Ok((solution, records))
    }
}

/// Adds σ_s Σ_l E_l T_l p̄(ω_l → ω_m) per cell and storage direction to `fixed`, averaged
/// over the `factor`³ sub-cells of `fine` (the grid the transmittance is on) in each cell.
fn first_collision(
    ordinates: &Ordinates,
    lights: &lucent_core::LightTransmittance,
    fine: &lucent_grid::GridGeometry,
    factor: usize,
    channel: usize,
    medium: &lucent_core::Medium,
    fixed: &mut [f32],
) {
    use rayon::prelude::*;
    let m = ordinates.storage().len();
    let [fx, fy, _] = fine.dims();
    let coarse = fine.dims().map(|d| d / factor);
    let share = 1.0 / (factor * factor * factor) as f64;
    // Directional lights have one direction everywhere: their discrete phase once.
    let constant: Vec<Option<Vec<f64>>> = lights
        .lights
        .iter()
        .map(|l| match l {
            Light::Directional { direction, .. } => Some(ordinates.phase_from(*direction)),
            _ => None,
        })
        .collect();
    fixed.par_chunks_mut(m).enumerate().for_each(|(cell, row)| {
        let [i, j, k] = [
            cell % coarse[0],
            (cell / coarse[0]) % coarse[1],
            cell / (coarse[0] * coarse[1]),
        ];
        for sub in 0..factor * factor * factor {
            let (a, b, c) = (
                sub % factor,
                (sub / factor) % factor,
                sub / (factor * factor),
            );
            let (fi, fj, fk) = (factor * i + a, factor * j + b, factor * k + c);
            let x = fine.cell_centre(fi, fj, fk);
            let s = f64::from(medium.sigma_s_at(channel, x));
            if s == 0.0 {
                continue;
            }
            let index = fi + fx * (fj + fy * fk);
            for (l, light) in lights.lights.iter().enumerate() {
                let Some((w, e, _)) = light.arrival(x, lights.far, lights.min_distance) else {
                    continue;
                };
                let grids = &lights.transmittance[l];
                let t = f64::from(grids[channel.min(grids.len() - 1)].data()[index]);
                let power = share * s * e * t * light.spectrum().channel(channel);
                if power == 0.0 {
                    continue;
                }
                let local;
                let p = match &constant[l] {
                    Some(p) => p,
                    None => {
                        local = ordinates.phase_from(w);
                        &local
                    }
                };
                for (v, p) in row.iter_mut().zip(p) {
                    *v += (power * p) as f32;
                }
            }
        }
    });
}
