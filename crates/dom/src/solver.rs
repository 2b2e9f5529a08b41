//! The registry entry `dom`: discrete ordinates on a problem's grid.
//!
//! - Point-like lights (directional, point, spot): their uncollided light is integrated
//!   over each cell ([`lucent_core::uncollided_cells`]: face fluxes by a polar rule next to
//!   a point light, 2×2×2 Gauss points elsewhere), so the first-collision power per cell is
//!   what enters minus what leaves and the light's power is conserved whatever the grid
//!   (point-sampled next to a point light's 1/r², 8–15% of it was lost at 32³–64³). The
//!   collided power C with its mean direction D becomes the source
//!   (σ_s/σ_t)[(C − |D|)/4π + |D| p̄(D̂ → ω_m)]/V at the storage directions (p̄ normalised
//!   and g-corrected as the phase matrix is; the isotropic part is the light that reaches
//!   a cell from many directions, as in the cell holding a point light), which drives the
//!   sweeps (Bernabei's MDOM); the cell-averaged uncollided fluence is added to the sweeps'
//!   fluence. `direct`'s per-light transmittance at cell centres is kept for the renderer's
//!   exact single scattering.
//! - A sky is the sweeps' boundary radiance; emission an isotropic fixed source.
//! - Boundaries: vacuum; Robin (η) as a diffuse reflector of Haskell et al.'s partial-current
//!   reflectance R_eff (0.401 at η = 1.3, 0 when index-matched; a Robin-like condition, not
//!   a Fresnel interface; `Boundary::diffuse_reflectance`); a reflecting (zero-flux
//!   Neumann) box as R = 1.
//! - Output: fluence, and [`lucent_core::OrdinateRadiance`] for the renderer.
//!
//! Parameters: `order` (level-symmetric S_N, default 8; with `family = "octahedral"` the
//! refinement level, default 2), `family` (`level-symmetric` or `octahedral`),
//! `storage_level` (store sources on the octahedral set of this level instead of on the
//! propagation set), `closure` (`diamond`, `step`, `exponential`), `acceleration` (`dsa`
//! or `none`), `anderson` (mixing depth, 2; 0 off), `block` (wavefront block edge, 16).

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

/// One channel's record of a [`DomSolver::solve_with_details`] run.
#[derive(Debug, Clone, PartialEq)]
pub struct DomChannel {
    /// How the source iteration went.
    pub convergence: crate::DomConvergence,
    /// The whole problem's energy balance (W): the lights' power entering the box (or
    /// emitted in it) and volumetric emission as `emitted`, the sky and the boundary's
    /// reflection as `inflow`, Σ σ_a φ V over the returned fluence as `absorbed`, the swept
    /// and the uncollided light leaving the box as `outflow`. It closes to the iteration's
    /// tolerance plus the uncollided cell integrals' accuracy (1e-5 of a point light's
    /// power).
    pub balance: crate::DomBalance,
}

/// `dom`.
#[derive(Debug, Clone, PartialEq)]
pub struct DomSolver {
    octahedral: bool,
    order: usize,
    storage_level: Option<usize>,
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
        if anderson > 16 || !(1..=256).contains(&block) {
            return Err(invalid("anderson/block", "anderson ≤ 16, 1 ≤ block ≤ 256"));
        }
        let solver = Self {
            octahedral,
            order,
            storage_level,
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
            reflecting_neumann_only: true,
            ..Capabilities::default()
        }
    }

    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
        self.solve_with_details(problem, options).map(|(s, _)| s)
    }
}

impl DomSolver {
    /// [`Solver::solve`], also returning each channel's iteration record (sweeps, timings,
    /// contraction, whether DSA was dropped) and energy balance.
    pub fn solve_with_details(
        &self,
        problem: &Problem,
        options: &SolveOptions,
    ) -> Result<(Solution, Vec<DomChannel>), SolveError> {
        self.admits(problem)?;
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
        // The capabilities refuse a Neumann flux other than 0.
        let reflectance = problem.boundary().diffuse_reflectance().unwrap_or(0.0);
        // Point-like lights through `direct` (uncollided, exact).
        let pointlike: Vec<Light> = problem
            .lights()
            .iter()
            .filter(|l| l.is_pointlike())
            .cloned()
            .collect();
        // Their uncollided light: cell integrals (the sweeps' unknowns are cell averages,
        // and the first collisions must conserve each light's power), and `direct` at cell
        // centres for the renderer's exact single scattering.
        let direct = if pointlike.is_empty() {
            None
        } else {
            let p = Problem::new(g, medium.clone(), pointlike.clone(), Boundary::Vacuum, None)?;
            Some(lucent_core::Uncollided::new(&p, options)?)
        };
        let lights = direct.as_ref().and_then(|d| match &d.direct.angular {
            Some(Angular::Lights(l)) => Some(l.clone()),
            _ => None,
        });
        let stopping = lucent_core::Stopping::from_options(options);
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
            if let Some(direct) = &direct {
                first_collision(&ordinates, direct, c, &g, &sigma_t, &sigma_s, &mut fixed);
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
            let mut total = solution.fluence.clone();
            // The whole problem's balance: the sweeps' own (whose fixed source holds the
            // first collisions) plus the lights' uncollided power in, absorbed and out.
            let mut balance = solution.balance;
            let volume = g.cell_volume();
            let uncollided = direct.as_ref().map_or(Vec::new(), |d| d.fluence(c));
            for (t, u) in total.iter_mut().zip(&uncollided) {
                *t += u;
            }
            let lights_cells = direct.as_ref().map_or(&[][..], |d| &d.cells[..]);
            for (light, cells) in pointlike.iter().zip(lights_cells) {
                let cells = &cells[c.min(cells.len() - 1)];
                let scale = light.spectrum().channel(c);
                let scattered: f64 = cells
                    .collided
                    .iter()
                    .zip(dom.sigma_t.iter().zip(&dom.sigma_s))
                    .filter(|(_, (t, _))| **t > 0.0)
                    .map(|(c, (t, s))| c * f64::from(*s) / f64::from(*t))
                    .sum();
                balance.emitted += scale * (cells.emitted - scattered);
                balance.outflow += scale * cells.escaped;
            }
            balance.absorbed = total
                .iter()
                .zip(dom.sigma_t.iter().zip(&dom.sigma_s))
                .map(|(phi, (t, s))| phi * f64::from(t - s) * volume)
                .sum();
            let total: Vec<f32> = total.iter().map(|v| *v as f32).collect();
            fluence.push(Grid::from_vec(g, total)?);
            inscattered.push(solution.inscattered);
            let conv = solution.convergence;
            records.push(DomChannel {
                convergence: conv.clone(),
                balance,
            });
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

/// Adds each point-like light's first-collision source to `fixed` per cell and storage
/// direction: (σ_s/σ_t)[(C − |D|)/4π + |D| p̄(D̂ → ω_m)]/V, with C the power that first
/// collides in the cell and D its direction-weighted integral ([`lucent_core::UncollidedCells`]).
/// The split keeps C and D exactly: the isotropic part carries no first moment.
fn first_collision(
    ordinates: &Ordinates,
    uncollided: &lucent_core::Uncollided,
    channel: usize,
    geometry: &lucent_grid::GridGeometry,
    sigma_t: &[f32],
    sigma_s: &[f32],
    fixed: &mut [f32],
) {
    use rayon::prelude::*;
    let m = ordinates.storage().len();
    let inv_volume = 1.0 / geometry.cell_volume();
    let isotropic = 1.0 / (4.0 * std::f64::consts::PI);
    // Directional lights have one direction everywhere: their discrete phase once.
    let lights = &uncollided.lights;
    let constant: Vec<Option<Vec<f64>>> = lights
        .iter()
        .map(|l| match l {
            Light::Directional { direction, .. } => Some(ordinates.phase_from(*direction)),
            _ => None,
        })
        .collect();
    fixed.par_chunks_mut(m).enumerate().for_each(|(cell, row)| {
        if sigma_t[cell] <= 0.0 || sigma_s[cell] <= 0.0 {
            return;
        }
        let albedo = f64::from(sigma_s[cell]) / f64::from(sigma_t[cell]);
        for (l, light) in lights.iter().enumerate() {
            let cells = &uncollided.cells[l][channel.min(uncollided.cells[l].len() - 1)];
            let power = cells.collided[cell] * light.spectrum().channel(channel);
            if power <= 0.0 {
                continue;
            }
            let directed = cells.directed[cell] * light.spectrum().channel(channel);
            let beam = directed.length().min(power);
            let spread = (power - beam) * isotropic;
            let scale = albedo * inv_volume;
            let local;
            let phase = match &constant[l] {
                Some(p) => p,
                None if beam > 0.0 => {
                    local = ordinates.phase_from(directed / directed.length());
                    &local
                }
                None => {
                    for v in row.iter_mut() {
                        *v += (scale * spread) as f32;
                    }
                    continue;
                }
            };
            for (v, p) in row.iter_mut().zip(phase) {
                *v += (scale * (spread + beam * p)) as f32;
            }
        }
    });
}
