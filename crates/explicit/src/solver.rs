//! The registry's explicit solvers, each on a `lucent_core::Problem`:
//!
//! - `ftcs-diffusion`, `jacobi-diffusion`: FTCS and Jacobi on exactly the discrete problem
//!   `diffusion-mg` solves (lucent-diffusion's mapping: reduced-intensity source, Robin
//!   boundaries, embedded surfaces), marched to the stopping tolerance. Parameters
//!   `step_fraction` (of the FTCS bound, 0.9), `omega` (Jacobi, 1), `allow_unstable`.
//! - `convection-diffusion`: Zhang & Ma per channel: every directional and point light
//!   marched by convection–absorption (σ_t as the absorption), composed, then the implicit
//!   scattering step with `scattering` = σ̂_s t (length², 0 by default: the uncollided
//!   light only, comparable with `direct`). Parameters `model` (`characteristic`, the
//!   default: short characteristics with exact per-step attenuation, second order and
//!   free of a Courant limit; `conservative`: first-order upwind fluxes; `paper`: Eq. 16
//!   as printed), `courant` (½, for the two upwind models), `sweep` (ordered, layers,
//!   jacobi), `scattering`, `allow_unstable`. The upwind models are first order and
//!   attenuate a cell by 1/(1 + σ_t h) instead of e^{−σ_t h}: 5.6% and 3.3% relative L2
//!   against `direct` at 32×32×48 and 64×64×96 under an oblique sun, where the
//!   characteristic model is second order (docs/validation.md).
//! - `ftcs-p1`: Murray's P1 system with FTCS on a homogeneous medium (σ_a, σ_t′ from the
//!   first cell), zero beyond the box. Parameters `layout` (staggered, collocated),
//!   `step_fraction` (0.9), `allow_unstable`.
//! - `ftcs-ordinates`: FTCS upwind ordinates with isotropic scattering, vacuum edges.
//!   Parameters `order` (level-symmetric S_N, 4), `step_fraction` (0.9), `allow_unstable`.
//!
//! The last two take point lights inside the grid (power 4πI into the cell that holds
//! them) and emission; the fluence they return counts all light.

use std::time::Instant;

use lucent_core::{
    BoundaryKind, Capabilities, FluenceKind, Light, LightKind, OutputKind, ParamValue, Params,
    Problem, Solution, SolveError, SolveOptions, SolveReport, Solver, SolverEntry, StopReason,
};
use lucent_diffusion::{Convergence, DiffusionSolution, DiffusionSolver};
use lucent_grid::Grid;
use lucent_optics::PhaseFunction;

use crate::convection::{Model, Sweep, UpwindSettings, compose, propagate};
use crate::error::ExplicitError;
use crate::lattice::Lattice;
use crate::steady::{Iteration, SteadySettings, ftcs_limit, iterate};

fn invalid(name: &str, reason: impl Into<String>) -> SolveError {
    SolveError::InvalidParameter {
        name: name.into(),
        reason: reason.into(),
    }
}

fn explicit_error(e: ExplicitError) -> SolveError {
    match e {
        ExplicitError::Unstable {
            scheme,
            parameter,
            limit,
            requested,
        } => SolveError::Unstable {
            solver: scheme.into(),
            parameter: parameter.into(),
            limit,
            requested,
        },
        ExplicitError::Invalid(reason) => invalid("problem", reason),
    }
}

fn flag(params: &Params, name: &str) -> Result<bool, SolveError> {
    match params.0.get(name) {
        None => Ok(false),
        Some(ParamValue::Bool(b)) => Ok(*b),
        Some(other) => Err(invalid(
            name,
            format!("expected true or false, got {other:?}"),
        )),
    }
}

fn text<'a>(params: &'a Params, name: &str, default: &'a str) -> Result<&'a str, SolveError> {
    match params.0.get(name) {
        None => Ok(default),
        Some(ParamValue::Text(t)) => Ok(t),
        Some(other) => Err(invalid(name, format!("expected text, got {other:?}"))),
    }
}

fn fraction(params: &Params) -> Result<f64, SolveError> {
    let f = params.f64_or("step_fraction", 0.9)?;
    if !(f > 0.0 && f.is_finite()) {
        return Err(invalid("step_fraction", "a positive fraction of the bound"));
    }
    Ok(f)
}

/// The explicit schemes' registry entries.
#[derive(Debug, Clone, PartialEq)]
pub struct ExplicitSolver {
    name: &'static str,
    scheme: Scheme,
}

#[derive(Debug, Clone, PartialEq)]
enum Scheme {
    Steady {
        iteration: SteadyKind,
        allow_unstable: bool,
    },
    Convection {
        settings: UpwindSettings,
        scattering: f64,
    },
    P1 {
        layout: crate::p1::Layout,
        fraction: f64,
        allow_unstable: bool,
    },
    Ordinates {
        order: usize,
        fraction: f64,
        allow_unstable: bool,
    },
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum SteadyKind {
    Ftcs { fraction: f64 },
    Jacobi { omega: f64 },
}

impl ExplicitSolver {
    /// `ftcs-diffusion`.
    pub const FTCS_DIFFUSION: SolverEntry = SolverEntry {
        name: "ftcs-diffusion",
        summary: "FTCS to steady state on diffusion-mg's discrete problem (Murray ch. 4)",
        build: |p| {
            p.check_known("ftcs-diffusion", &["step_fraction", "allow_unstable"])?;
            Ok(Box::new(ExplicitSolver {
                name: "ftcs-diffusion",
                scheme: Scheme::Steady {
                    iteration: SteadyKind::Ftcs {
                        fraction: fraction(p)?,
                    },
                    allow_unstable: flag(p, "allow_unstable")?,
                },
            }))
        },
    };

    /// `jacobi-diffusion`.
    pub const JACOBI_DIFFUSION: SolverEntry = SolverEntry {
        name: "jacobi-diffusion",
        summary: "Jacobi relaxation of the steady diffusion equation (FTCS at the positivity bound)",
        build: |p| {
            p.check_known("jacobi-diffusion", &["omega"])?;
            let omega = p.f64_or("omega", 1.0)?;
            if !(omega > 0.0 && omega <= 1.0) {
                return Err(invalid("omega", "in (0, 1]"));
            }
            Ok(Box::new(ExplicitSolver {
                name: "jacobi-diffusion",
                scheme: Scheme::Steady {
                    iteration: SteadyKind::Jacobi { omega },
                    allow_unstable: false,
                },
            }))
        },
    };

    /// `convection-diffusion`.
    pub const CONVECTION_DIFFUSION: SolverEntry = SolverEntry {
        name: "convection-diffusion",
        summary: "Zhang & Ma: upwind convection-absorption per light, then implicit scattering",
        build: |p| {
            p.check_known(
                "convection-diffusion",
                &["courant", "model", "sweep", "scattering", "allow_unstable"],
            )?;
            let model = match text(p, "model", "characteristic")? {
                "characteristic" => Model::Characteristic,
                "conservative" => Model::Conservative,
                "paper" => Model::Paper,
                other => {
                    return Err(invalid(
                        "model",
                        format!("`{other}`: characteristic, conservative or paper"),
                    ));
                }
            };
            let sweep = match text(p, "sweep", "ordered")? {
                "ordered" => Sweep::Ordered,
                "layers" => Sweep::Layers {
                    iterations: 5,
                    warm_start: true,
                },
                "jacobi" => Sweep::Jacobi,
                other => {
                    return Err(invalid(
                        "sweep",
                        format!("`{other}`: ordered, layers or jacobi"),
                    ));
                }
            };
            let scattering = p.f64_or("scattering", 0.0)?;
            if !(scattering >= 0.0 && scattering.is_finite()) {
                return Err(invalid("scattering", "σ̂_s t ≥ 0 (length²)"));
            }
            Ok(Box::new(ExplicitSolver {
                name: "convection-diffusion",
                scheme: Scheme::Convection {
                    settings: UpwindSettings {
                        courant: p.f64_or("courant", 0.5)?,
                        model,
                        sweep,
                        allow_unstable: flag(p, "allow_unstable")?,
                        ..UpwindSettings::default()
                    },
                    scattering,
                },
            }))
        },
    };

    /// `ftcs-p1`.
    pub const FTCS_P1: SolverEntry = SolverEntry {
        name: "ftcs-p1",
        summary: "Murray's P1 moment system with FTCS, staggered or collocated grid",
        build: |p| {
            p.check_known("ftcs-p1", &["layout", "step_fraction", "allow_unstable"])?;
            let layout = match text(p, "layout", "staggered")? {
                "staggered" => crate::p1::Layout::Staggered,
                "collocated" => crate::p1::Layout::Collocated,
                other => {
                    return Err(invalid(
                        "layout",
                        format!("`{other}`: staggered or collocated"),
                    ));
                }
            };
            Ok(Box::new(ExplicitSolver {
                name: "ftcs-p1",
                scheme: Scheme::P1 {
                    layout,
                    fraction: fraction(p)?,
                    allow_unstable: flag(p, "allow_unstable")?,
                },
            }))
        },
    };

    /// `ftcs-ordinates`.
    pub const FTCS_ORDINATES: SolverEntry = SolverEntry {
        name: "ftcs-ordinates",
        summary: "the unsteady RTE over discrete directions with upwind FTCS (Murray §3.4.1)",
        build: |p| {
            p.check_known(
                "ftcs-ordinates",
                &["order", "step_fraction", "allow_unstable"],
            )?;
            let order = p.usize_or("order", 4)?;
            if !(2..=16).contains(&order) || order % 2 == 1 {
                return Err(invalid("order", "an even S_N order from 2 to 16"));
            }
            Ok(Box::new(ExplicitSolver {
                name: "ftcs-ordinates",
                scheme: Scheme::Ordinates {
                    order,
                    fraction: fraction(p)?,
                    allow_unstable: flag(p, "allow_unstable")?,
                },
            }))
        },
    };

    /// Every entry of this crate.
    pub const ENTRIES: [SolverEntry; 5] = [
        Self::FTCS_DIFFUSION,
        Self::JACOBI_DIFFUSION,
        Self::CONVECTION_DIFFUSION,
        Self::FTCS_P1,
        Self::FTCS_ORDINATES,
    ];
}

/// The lattice of a problem's grid (cubic cells only).
fn lattice(problem: &Problem) -> Result<Lattice, SolveError> {
    let g = problem.geometry();
    let h = g.spacing();
    if (h.x - h.y).abs() > 1e-9 * h.x || (h.x - h.z).abs() > 1e-9 * h.x {
        return Err(invalid(
            "grid",
            format!("cubic cells needed, spacing {h:?}"),
        ));
    }
    let mut l = Lattice::new(g.dims(), h.x).map_err(explicit_error)?;
    l.origin = g.origin();
    Ok(l)
}

/// Sources of P1 and ordinates for channel c: point lights (4πI into their cell) and
/// emission (4π L_e), as power per volume.
fn point_and_emission(problem: &Problem, c: usize) -> Result<Vec<f64>, SolveError> {
    let g = problem.geometry();
    let mut q = vec![0.0; g.voxel_count()];
    for light in problem.lights() {
        match light {
            Light::Point {
                position,
                intensity,
            } => {
                // Cell i spans [i, i + 1) in these coordinates.
                let v = g.world_to_voxel(*position) + 0.5;
                let dims = g.dims();
                let inside = (0..3).all(|a| v[a] >= 0.0 && v[a] < dims[a] as f64);
                if !inside {
                    return Err(invalid(
                        "lights",
                        "point lights must lie inside the grid for this solver",
                    ));
                }
                q[g.index(v.x as usize, v.y as usize, v.z as usize)] +=
                    4.0 * std::f64::consts::PI * intensity.channel(c) / g.cell_volume();
            }
            Light::Emission { grid, scale } => {
                for (q, e) in q.iter_mut().zip(grid.data()) {
                    *q += 4.0 * std::f64::consts::PI * scale.channel(c) * f64::from(*e);
                }
            }
            other => {
                return Err(invalid("lights", format!("{:?} lights", other.kind())));
            }
        }
    }
    Ok(q)
}

impl Solver for ExplicitSolver {
    fn name(&self) -> &str {
        self.name
    }

    fn capabilities(&self) -> Capabilities {
        let diffusion = DiffusionSolver::custom(self.name).capabilities();
        match &self.scheme {
            Scheme::Steady { .. } => diffusion,
            Scheme::Convection { scattering, .. } => Capabilities {
                anisotropic: *scattering == 0.0,
                heterogeneous: true,
                embedded_geometry: false,
                boundaries: vec![BoundaryKind::Vacuum],
                lights: vec![LightKind::Directional, LightKind::Point],
                output: OutputKind::Fluence,
                fluence: if *scattering == 0.0 {
                    FluenceKind::Uncollided
                } else {
                    FluenceKind::Total
                },
                cubic_cells_only: true,
                ..Capabilities::default()
            },
            Scheme::P1 { .. } | Scheme::Ordinates { .. } => Capabilities {
                anisotropic: matches!(self.scheme, Scheme::P1 { .. }),
                heterogeneous: matches!(self.scheme, Scheme::Ordinates { .. }),
                embedded_geometry: false,
                boundaries: vec![BoundaryKind::Vacuum],
                lights: vec![LightKind::Point, LightKind::Emission],
                output: OutputKind::Fluence,
                fluence: FluenceKind::Total,
                cubic_cells_only: true,
                point_lights_inside_grid: true,
                // P1 by FTCS has no stable step without absorption.
                needs_absorption: matches!(self.scheme, Scheme::P1 { .. }),
                ..Capabilities::default()
            },
        }
    }

    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
        self.admits(problem)?;
        options.validate()?;
        // f64 working fields per cell: the assembled system (about 8 rows of 12 bytes and
        // 6 vectors) for the steady schemes, two fields per light for convection, φ and E
        // twice for P1, the radiance of every direction twice for ordinates.
        let n = problem.geometry().voxel_count() as u64;
        let per_cell = match &self.scheme {
            Scheme::Steady { .. } => 8 * 12 + 6 * 8,
            Scheme::Convection { .. } => 8 * (3 + 2 * problem.lights().len() as u64),
            Scheme::P1 { .. } => 8 * 2 * 4 * 2,
            Scheme::Ordinates { order, .. } => 8 * 2 * (order * (order + 2)) as u64 + 32,
        };
        let needed = n * per_cell * problem.channels() as u64;
        if needed > options.memory_budget {
            return Err(SolveError::OverBudget {
                solver: self.name.into(),
                needed,
                budget: options.memory_budget,
            });
        }
        let started = Instant::now();
        match &self.scheme {
            Scheme::Steady {
                iteration,
                allow_unstable,
            } => {
                if let SteadyKind::Ftcs { fraction } = iteration
                    && *fraction > 1.0
                    && !allow_unstable
                {
                    // The bound is computed per system below; as a fraction of it, 1.
                    return Err(SolveError::Unstable {
                        solver: self.name.into(),
                        parameter: "step_fraction (of the FTCS bound)".into(),
                        limit: 1.0,
                        requested: *fraction,
                    });
                }
                let volume = problem.geometry().cell_volume();
                let (iteration, allow_unstable) = (*iteration, *allow_unstable);
                DiffusionSolver::custom(self.name).solve_with(problem, options, &|d, s, stop| {
                    let t0 = Instant::now();
                    let system = d.assemble(s)?;
                    let kind = match iteration {
                        SteadyKind::Ftcs { fraction } => Iteration::Ftcs {
                            time_step: fraction * ftcs_limit(&system, volume),
                            cell_volume: volume,
                        },
                        SteadyKind::Jacobi { omega } => Iteration::Jacobi { omega },
                    };
                    let setup = t0.elapsed().as_secs_f64();
                    let settings = SteadySettings {
                        stopping: stop.clone(),
                        allow_unstable,
                    };
                    let out = iterate(&system, kind, &settings)
                        .map_err(|e| lucent_diffusion::DiffusionError::Invalid(e.to_string()))?;
                    let mut fluence = vec![0.0; d.cells().geometry().voxel_count()];
                    for (&c, v) in system.cells.iter().zip(&out.fluence) {
                        fluence[c] = *v;
                    }
                    let balance = d.balance(s, &fluence);
                    Ok(DiffusionSolution {
                        convergence: Convergence {
                            residuals: out.residuals,
                            stop_reason: out.stop_reason,
                        },
                        balance,
                        setup_seconds: setup,
                        solve_seconds: t0.elapsed().as_secs_f64() - setup,
                        levels: 1,
                        memory_bytes: (system.matrix.nnz() * 16 + fluence.len() * 32) as u64,
                        fluence,
                    })
                })
            }
            Scheme::Convection {
                settings,
                scattering,
            } => {
                // The caller's time budget bounds every light's march, and its progress
                // callback hears every pass.
                let settings = UpwindSettings {
                    stopping: lucent_core::Stopping {
                        time_budget: options.time_budget,
                        progress: options.progress.clone(),
                        ..settings.stopping.clone()
                    },
                    ..settings.clone()
                };
                self.convection(problem, options, &settings, *scattering, started)
            }
            Scheme::P1 {
                layout,
                fraction,
                allow_unstable,
            } => self.p1(
                problem,
                options,
                *layout,
                *fraction,
                *allow_unstable,
                started,
            ),
            Scheme::Ordinates {
                order,
                fraction,
                allow_unstable,
            } => self.ordinates(
                problem,
                options,
                *order,
                *fraction,
                *allow_unstable,
                started,
            ),
        }
    }
}

impl ExplicitSolver {
    fn report(
        &self,
        started: Instant,
        iterations: usize,
        residual_history: Vec<f64>,
        stop_reason: StopReason,
        bytes: u64,
    ) -> SolveReport {
        SolveReport {
            solver: self.name.into(),
            iterations,
            residual_history,
            wall_time_s: started.elapsed().as_secs_f64(),
            peak_memory_bytes: bytes,
            stop_reason,
        }
    }

    fn convection(
        &self,
        problem: &Problem,
        options: &SolveOptions,
        settings: &UpwindSettings,
        scattering: f64,
        started: Instant,
    ) -> Result<Solution, SolveError> {
        let l = lattice(problem)?;
        let geometry = *problem.geometry();
        let (mut iterations, mut stop) = (0, StopReason::Exact);
        let mut fluence = Vec::new();
        // One march per light and channel.
        let marches = (problem.channels() * problem.lights().len()).max(1);
        let mut marched = 0usize;
        for c in 0..problem.channels() {
            let sigma_t: Vec<f64> = problem
                .medium()
                .sigma_t(c)
                .data()
                .iter()
                .map(|&v| f64::from(v))
                .collect();
            let absorption: Vec<f64> = match settings.model {
                Model::Conservative | Model::Characteristic => sigma_t,
                // The paper's per-step absorption: the opacity of one step cΔt = C h.
                Model::Paper => sigma_t
                    .iter()
                    .map(|s| 1.0 - (-s * settings.courant * l.spacing).exp())
                    .collect(),
            };
            let mut fields = Vec::new();
            for light in problem.lights() {
                let (light, colour) = match light {
                    Light::Directional {
                        direction,
                        irradiance,
                    } => (
                        crate::convection::Light::Distant {
                            direction: *direction,
                            density: 1.0,
                        },
                        irradiance.channel(c),
                    ),
                    Light::Point {
                        position,
                        intensity,
                    } => (
                        crate::convection::Light::Point {
                            position: *position,
                            density: 1.0,
                            falloff: None,
                        },
                        intensity.channel(c),
                    ),
                    other => return Err(invalid("lights", format!("{:?}", other.kind()))),
                };
                let out = propagate(&l, &absorption, &light, settings).map_err(explicit_error)?;
                iterations += out.iterations;
                marched += 1;
                options.report(lucent_core::Progress {
                    fraction: marched as f64 / marches as f64,
                    iteration: iterations,
                    residual: out.residuals.last().copied(),
                });
                if !out.stop_reason.is_converged() {
                    stop = out.stop_reason.clone();
                }
                fields.push((out.density, vec![colour]));
            }
            let mut total = compose(&fields)
                .map_err(explicit_error)?
                .pop()
                .unwrap_or_else(|| vec![0.0; l.len()]);
            if scattering > 0.0 {
                let out = crate::scatter::diffuse(
                    &l,
                    &total,
                    scattering,
                    1.0,
                    1,
                    crate::scatter::StepSolver::Multigrid { tolerance: 1e-8 },
                )
                .map_err(explicit_error)?;
                total = out.field;
            }
            fluence.push(Grid::from_vec(
                geometry,
                total.iter().map(|&v| v as f32).collect(),
            )?);
        }
        let bytes = (l.len() * 8 * 4) as u64;
        Ok(Solution {
            fluence,
            angular: None,
            standard_error: None,
            report: self.report(started, iterations, Vec::new(), stop, bytes),
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn p1(
        &self,
        problem: &Problem,
        options: &SolveOptions,
        layout: crate::p1::Layout,
        fraction: f64,
        allow_unstable: bool,
        started: Instant,
    ) -> Result<Solution, SolveError> {
        let l = lattice(problem)?;
        let g = problem.medium().phase.mean_cosine();
        let mut fluence = Vec::new();
        let mut last = (0, StopReason::Exact);
        for c in 0..problem.channels() {
            let sigma_t = f64::from(problem.medium().sigma_t(c).data()[0]);
            let sigma_s = f64::from(
                problem
                    .medium()
                    .sigma_s_at(c, problem.geometry().cell_centre(0, 0, 0)),
            );
            let (sigma_a, reduced) = (sigma_t - sigma_s, sigma_t - g * sigma_s);
            let q = point_and_emission(problem, c)?;
            let limit = |dt: f64| {
                let (kp, ke) = (dt * sigma_a, dt * reduced);
                match layout {
                    crate::p1::Layout::Collocated => crate::stability::p1::collocated_limit(kp, ke),
                    crate::p1::Layout::Staggered => crate::stability::p1::staggered_limit(kp, ke),
                }
            };
            // The largest stable cΔt: r(cΔt) = cΔt/h must not exceed limit(cΔt); bisect.
            let (mut lo, mut hi) = (0.0, 2.0 / reduced.max(1e-12));
            for _ in 0..100 {
                let mid = 0.5 * (lo + hi);
                if mid / l.spacing <= limit(mid) {
                    lo = mid
                } else {
                    hi = mid
                }
            }
            let settings = crate::p1::P1Settings {
                layout,
                damping: crate::p1::Damping::Consistent {
                    sigma_a,
                    sigma_t_reduced: reduced,
                },
                time_step: fraction * lo,
                stopping: lucent_core::Stopping::from_options(options),
                edges: crate::p1::P1Edges::Zero,
                allow_unstable,
            };
            if lo <= 0.0 {
                return Err(invalid(
                    "medium",
                    "P1 FTCS has no stable step without absorption",
                ));
            }
            let out = crate::p1::march(&l, &q, &settings, None).map_err(explicit_error)?;
            last = (out.steps, out.stop_reason);
            fluence.push(Grid::from_vec(
                *problem.geometry(),
                out.fluence.iter().map(|&v| v as f32).collect(),
            )?);
        }
        Ok(Solution {
            fluence,
            angular: None,
            standard_error: None,
            report: self.report(
                started,
                last.0,
                Vec::new(),
                last.1,
                (l.len() * 8 * 8) as u64,
            ),
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn ordinates(
        &self,
        problem: &Problem,
        options: &SolveOptions,
        order: usize,
        fraction: f64,
        allow_unstable: bool,
        started: Instant,
    ) -> Result<Solution, SolveError> {
        let l = lattice(problem)?;
        let quadrature = lucent_optics::SphericalQuadrature::level_symmetric(order)
            .map_err(|e| invalid("order", e.to_string()))?;
        let s_max = quadrature
            .directions()
            .iter()
            .map(|d| d.abs().element_sum())
            .fold(0.0, f64::max);
        let mut fluence = Vec::new();
        let mut last = (0, Vec::new(), StopReason::Exact);
        for c in 0..problem.channels() {
            let geometry = problem.geometry();
            let sigma_t: Vec<f64> = problem
                .medium()
                .sigma_t(c)
                .data()
                .iter()
                .map(|&v| f64::from(v))
                .collect();
            let sigma_s: Vec<f64> = (0..geometry.voxel_count())
                .map(|cell| {
                    let [i, j, k] = geometry.coords(cell);
                    f64::from(
                        problem
                            .medium()
                            .sigma_s_at(c, geometry.cell_centre(i, j, k)),
                    )
                })
                .collect();
            let q = point_and_emission(problem, c)?;
            let k_max = sigma_t.iter().fold(0.0f64, |a, &b| a.max(b));
            // r ≤ (1 − K/2)/S with K = cΔt σ_t: cΔt ≤ h / (S + h σ_t/2).
            let step = l.spacing / (s_max + 0.5 * l.spacing * k_max);
            let settings = crate::ordinates::OrdinatesSettings {
                time_step: fraction * step,
                stopping: lucent_core::Stopping::from_options(options),
                allow_unstable,
            };
            let out = crate::ordinates::march(&l, &quadrature, &sigma_t, &sigma_s, &q, &settings)
                .map_err(explicit_error)?;
            last = (out.steps, out.residuals, out.stop_reason);
            fluence.push(Grid::from_vec(
                *geometry,
                out.fluence.iter().map(|&v| v as f32).collect(),
            )?);
        }
        let bytes = (l.len() * quadrature.len() * 16) as u64;
        Ok(Solution {
            fluence,
            angular: None,
            standard_error: None,
            report: self.report(started, last.0, last.1, last.2, bytes),
        })
    }
}
