//! The registry's diffusion solvers: `diffusion-mg` and, on the same operator, the baselines
//! `diffusion-cg`, `diffusion-mgcg`, `diffusion-sor` and `diffusion-jacobi`.
//!
//! From a `lucent_core::Problem`, per channel: σ_s = albedo·σ_t, σ_a = σ_t − σ_s,
//! σ_t′ = σ_a + (1 − g)σ_s, D = 1/(3σ_t′) (σ_t′ is kept at least 10⁻³ of a cell's inverse
//! width, so empty cells do not make D infinite; diffusion is not meant for them anyway).
//! The medium is the embedded SDF's inside when there is one, else the whole box.
//!
//! Sources:
//! - point lights inside the medium are diffusion point sources of power 4πI (the Green's
//!   function T7 is built on);
//! - emission lights are a volumetric Q₀ = 4π L_e;
//! - every other light (directional, spot, sky, point lights outside) enters as the
//!   reduced-intensity source: the uncollided fluence φ_u of `direct` (straight lines
//!   through the medium only, no refraction or Fresnel loss at entry, as in Mertens'
//!   pipeline) scatters into Q₀ = σ_s φ_u and Q₁ = g σ_s Σ_l φ_u,l ω_l. The solution's
//!   fluence is φ_u + φ_d, and its angular part keeps the per-light transmittance so the
//!   renderer phase-weights single scattering.
//!
//! Boundaries: Robin (A = `Boundary::robin_factor`, the transport-exact extrapolation
//! length of the Milne problem), Vacuum (Robin at η = 1: A = 1.0657), Dirichlet,
//! Neumann; the same on the embedded surface and the box.

use std::time::Instant;

use glam::DVec3;
use lucent_core::{
    Angular, Boundary, BoundaryKind, Capabilities, FluenceKind, Light, LightKind, Medium,
    OutputKind, Params, Problem, Solution, SolveError, SolveOptions, SolveReport, Solver,
    SolverEntry, StopReason,
};
use lucent_grid::Grid;
use lucent_optics::PhaseFunction;

use crate::geometry::{CellGeometry, Discretisation};
use crate::multigrid::{Cycle, MultigridSettings, Smoother};
use crate::problem::{Boundaries, Condition, DiffusionProblem, Sources};
use crate::solve::{Method, solve};
use lucent_core::Stopping;

/// A diffusion solver as the registry builds it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiffusionSolver {
    name: &'static str,
    method: Method,
    discretisation: Discretisation,
}

const MG_PARAMS: &[&str] = &[
    "cycle",
    "pre_sweeps",
    "post_sweeps",
    "smoother",
    "full_multigrid",
    "discretisation",
];

fn invalid(name: &str, reason: impl Into<String>) -> SolveError {
    SolveError::InvalidParameter {
        name: name.into(),
        reason: reason.into(),
    }
}

fn text<'a>(params: &'a Params, name: &str, default: &'a str) -> Result<&'a str, SolveError> {
    match params.0.get(name) {
        None => Ok(default),
        Some(lucent_core::ParamValue::Text(t)) => Ok(t),
        Some(other) => Err(invalid(name, format!("expected text, got {other:?}"))),
    }
}

fn discretisation(params: &Params) -> Result<Discretisation, SolveError> {
    match text(params, "discretisation", "embedded")? {
        "embedded" => Ok(Discretisation::EmbeddedBoundary),
        "staircase" => Ok(Discretisation::Staircase),
        other => Err(invalid(
            "discretisation",
            format!("`{other}`: embedded or staircase"),
        )),
    }
}

fn multigrid_settings(params: &Params) -> Result<MultigridSettings, SolveError> {
    let cycle = match text(params, "cycle", "v")? {
        "v" | "V" => Cycle::V,
        "w" | "W" => Cycle::W,
        "f" | "F" => Cycle::F,
        other => return Err(invalid("cycle", format!("`{other}`: v, w or f"))),
    };
    let smoother = match text(params, "smoother", "gauss-seidel")? {
        "gauss-seidel" => Smoother::RedBlackGaussSeidel,
        "jacobi" => Smoother::Jacobi { omega: 6.0 / 7.0 },
        other => {
            return Err(invalid(
                "smoother",
                format!("`{other}`: gauss-seidel or jacobi"),
            ));
        }
    };
    let full_multigrid = match params.0.get("full_multigrid") {
        None => true,
        Some(lucent_core::ParamValue::Bool(b)) => *b,
        Some(other) => return Err(invalid("full_multigrid", format!("{other:?}"))),
    };
    let pre_sweeps = params.usize_or("pre_sweeps", 2)?;
    let post_sweeps = params.usize_or("post_sweeps", 2)?;
    if pre_sweeps + post_sweeps == 0 || pre_sweeps.max(post_sweeps) > 64 {
        return Err(invalid("pre_sweeps", "1 to 64 sweeps in all"));
    }
    Ok(MultigridSettings {
        cycle,
        smoother,
        pre_sweeps,
        post_sweeps,
        full_multigrid,
        ..MultigridSettings::default()
    })
}

impl DiffusionSolver {
    /// `diffusion-mg`: multigrid cycles. Parameters: `cycle` (v, w, f), `pre_sweeps`,
    /// `post_sweeps` (2, 2), `smoother` (gauss-seidel, jacobi), `full_multigrid` (true),
    /// `discretisation` (embedded, staircase).
    pub const MULTIGRID: SolverEntry = SolverEntry {
        name: "diffusion-mg",
        summary: "steady diffusion, embedded-boundary finite volumes, geometric multigrid (Mertens ch. 4)",
        build: |p| {
            p.check_known("diffusion-mg", MG_PARAMS)?;
            Ok(Box::new(DiffusionSolver {
                name: "diffusion-mg",
                method: Method::Multigrid(multigrid_settings(p)?),
                discretisation: discretisation(p)?,
            }))
        },
    };

    /// `diffusion-mgcg`: CG preconditioned by one multigrid cycle (same parameters).
    pub const MULTIGRID_CG: SolverEntry = SolverEntry {
        name: "diffusion-mgcg",
        summary: "steady diffusion, multigrid-preconditioned conjugate gradients",
        build: |p| {
            p.check_known("diffusion-mgcg", MG_PARAMS)?;
            let mut settings = multigrid_settings(p)?;
            settings.full_multigrid = false;
            Ok(Box::new(DiffusionSolver {
                name: "diffusion-mgcg",
                method: Method::MultigridCg(settings),
                discretisation: discretisation(p)?,
            }))
        },
    };

    /// `diffusion-cg`: Jacobi-preconditioned CG. Parameter: `discretisation`.
    pub const CONJUGATE_GRADIENT: SolverEntry = SolverEntry {
        name: "diffusion-cg",
        summary: "steady diffusion, Jacobi-preconditioned conjugate gradients (baseline)",
        build: |p| {
            p.check_known("diffusion-cg", &["discretisation"])?;
            Ok(Box::new(DiffusionSolver {
                name: "diffusion-cg",
                method: Method::ConjugateGradient,
                discretisation: discretisation(p)?,
            }))
        },
    };

    /// `diffusion-sor`: red–black SOR. Parameters: `omega` (1.9), `discretisation`.
    pub const SOR: SolverEntry = SolverEntry {
        name: "diffusion-sor",
        summary: "steady diffusion, red-black successive over-relaxation (baseline)",
        build: |p| {
            p.check_known("diffusion-sor", &["omega", "discretisation"])?;
            Ok(Box::new(DiffusionSolver {
                name: "diffusion-sor",
                method: Method::Sor {
                    omega: p.f64_or("omega", 1.9)?,
                },
                discretisation: discretisation(p)?,
            }))
        },
    };

    /// `diffusion-jacobi`: Jacobi iteration. Parameters: `omega` (1), `discretisation`.
    pub const JACOBI: SolverEntry = SolverEntry {
        name: "diffusion-jacobi",
        summary: "steady diffusion, Jacobi iteration (baseline)",
        build: |p| {
            p.check_known("diffusion-jacobi", &["omega", "discretisation"])?;
            Ok(Box::new(DiffusionSolver {
                name: "diffusion-jacobi",
                method: Method::Jacobi {
                    omega: p.f64_or("omega", 1.0)?,
                },
                discretisation: discretisation(p)?,
            }))
        },
    };

    /// Every entry.
    pub const ENTRIES: [SolverEntry; 5] = [
        Self::MULTIGRID,
        Self::MULTIGRID_CG,
        Self::CONJUGATE_GRADIENT,
        Self::SOR,
        Self::JACOBI,
    ];
}

fn conditions(boundary: Boundary) -> Boundaries {
    Boundaries::uniform(match boundary {
        Boundary::Vacuum | Boundary::Robin { .. } => Condition::Robin {
            a: boundary.robin_factor().unwrap_or(1.0),
        },
        Boundary::Dirichlet { value } => Condition::Dirichlet { value },
        Boundary::Neumann { flux } => Condition::Neumann { flux },
    })
}

/// The medium's coefficients in one channel: (D, σ_a, σ_s) per cell.
fn coefficients(medium: &Medium, channel: usize, floor: f64) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let g = medium.phase.mean_cosine();
    let sigma_t = medium.sigma_t(channel).data();
    let albedo = medium.albedo(channel);
    let n = sigma_t.len();
    let (mut d, mut sa, mut ss) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    for c in 0..n {
        let t = f64::from(sigma_t[c]);
        let s = f64::from(albedo.at(c)) * t;
        let a = (t - s).max(0.0);
        let reduced = (a + (1.0 - g) * s).max(floor);
        d[c] = (1.0 / (3.0 * reduced)) as f32;
        sa[c] = a as f32;
        ss[c] = s as f32;
    }
    (d, sa, ss)
}

impl Solver for DiffusionSolver {
    fn name(&self) -> &str {
        self.name
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            anisotropic: true,
            heterogeneous: true,
            embedded_geometry: true,
            boundaries: vec![
                BoundaryKind::Vacuum,
                BoundaryKind::Robin,
                BoundaryKind::Dirichlet,
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
            ..Capabilities::default()
        }
    }

    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
        let method = self.method;
        self.solve_with(problem, options, &|diffusion, sources, stopping| {
            solve(diffusion, sources, method, stopping)
        })
    }
}

/// A linear solve of one channel's discrete problem: what [`DiffusionSolver::solve_with`]
/// plugs in.
pub type LinearSolve<'a> = dyn Fn(
        &DiffusionProblem,
        &Sources,
        &Stopping,
    ) -> Result<crate::DiffusionSolution, crate::DiffusionError>
    + 'a;

impl DiffusionSolver {
    /// A solver named `name` that maps problems as the diffusion solvers do (embedded
    /// boundary) and leaves the linear solve to [`DiffusionSolver::solve_with`]: for other
    /// crates' iterations on the same discrete problem (`lucent-explicit`'s FTCS and Jacobi).
    pub const fn custom(name: &'static str) -> Self {
        Self {
            name,
            method: Method::Multigrid(MultigridSettings {
                cycle: Cycle::V,
                smoother: Smoother::RedBlackGaussSeidel,
                pre_sweeps: 2,
                post_sweeps: 2,
                full_multigrid: true,
                prolongation: crate::multigrid::Prolongation::Constant,
            }),
            discretisation: Discretisation::EmbeddedBoundary,
        }
    }

    /// Solves `problem` as [`Solver::solve`] does, with `linear` solving each channel's
    /// discrete problem A φ = b (sources mapped, reduced-intensity source included).
    pub fn solve_with(
        &self,
        problem: &Problem,
        options: &SolveOptions,
        linear: &LinearSolve<'_>,
    ) -> Result<Solution, SolveError> {
        self.admits(problem)?;
        options.validate()?;
        let started = Instant::now();
        let geometry = *problem.geometry();
        let n = geometry.voxel_count();
        let channels = problem.channels();
        let bytes = n as u64 * (4 * 14 + 8 * 4) * channels as u64;
        if bytes > options.memory_budget {
            return Err(SolveError::OverBudget {
                solver: self.name.into(),
                needed: bytes,
                budget: options.memory_budget,
            });
        }
        let sdf = problem.embedded();
        let cells = match sdf {
            Some(grid) => CellGeometry::from_sdf(
                geometry,
                |p| f64::from(grid.sample_trilinear(p)),
                self.discretisation,
            )
            .map_err(|e| invalid("embedded", e.to_string()))?,
            None => CellGeometry::full_box(geometry),
        };
        let inside = |p: DVec3| sdf.is_none_or(|g| g.sample_trilinear(p) < 0.0);

        // Lights: diffusion point sources, emission, and the rest through `direct`.
        let (mut points, mut emission, mut external) = (Vec::new(), Vec::new(), Vec::new());
        for light in problem.lights() {
            match light {
                Light::Point { position, .. } if inside(*position) => points.push(light),
                Light::Emission { .. } => emission.push(light),
                _ => external.push(light.clone()),
            }
        }
        let direct = if external.is_empty() {
            None
        } else {
            // Straight-line attenuation through the medium only.
            let medium = problem.medium();
            let masked = match sdf {
                Some(s) => medium.masked(s),
                None => medium.clone(),
            };
            let p = Problem::new(geometry, masked, external, Boundary::Vacuum, None)?;
            Some(lucent_core::Uncollided::new(&p, options)?)
        };

        let floor = 1e-3 / geometry.spacing().max_element();
        let boundaries = conditions(problem.boundary());
        let stopping = Stopping::from_options(options);
        let g = problem.medium().phase.mean_cosine();
        let mut fluence = Vec::with_capacity(channels);
        let mut scattered = Vec::with_capacity(channels);
        let mut report: Option<(usize, Vec<f64>, StopReason)> = None;
        let mut memory = 0u64;
        for c in 0..channels {
            let (d, sa, ss) = coefficients(problem.medium(), c, floor);
            let diffusion = DiffusionProblem::new(cells.clone(), d.clone(), sa.clone(), boundaries)
                .map_err(|e| invalid("problem", e.to_string()))?;
            let mut sources = Sources::default();
            let mut q0 = vec![0.0f32; n];
            // Point sources: their singular part G̃ analytically where the medium around
            // them allows (the remainder's smooth source goes into q0), else as points.
            let mut singular = vec![0.0f32; n];
            for light in &points {
                if let Light::Point {
                    position,
                    intensity,
                } = light
                {
                    let power = 4.0 * std::f64::consts::PI * intensity.channel(c);
                    let whole = |cell: usize| cells.volume_fraction()[cell] >= 1.0;
                    match lucent_core::point_source_singular_part(
                        &geometry, &d, &sa, whole, *position, power,
                    ) {
                        Some(part) => {
                            for (q, f) in q0.iter_mut().zip(&part.source) {
                                *q += f;
                            }
                            for (g, p) in singular.iter_mut().zip(&part.fluence) {
                                *g += p;
                            }
                        }
                        None => sources.points.push((*position, power)),
                    }
                }
            }
            for light in &emission {
                if let Light::Emission { grid, scale } = light {
                    let s = 4.0 * std::f64::consts::PI * scale.channel(c);
                    for (q, e) in q0.iter_mut().zip(grid.data()) {
                        *q += (s * f64::from(*e)) as f32;
                    }
                }
            }
            if let Some(direct) = &direct {
                let (scattered, first) = direct.first_collision_sources(c, &ss, g);
                for (q, s) in q0.iter_mut().zip(scattered) {
                    *q += s;
                }
                sources.first_moment = first;
            }
            sources.volumetric = q0;
            let solution = linear(&diffusion, &sources, &stopping)
                .map_err(|e| invalid("problem", e.to_string()))?;
            memory = memory.max(solution.memory_bytes);
            let scattered_grid = Grid::from_vec(
                geometry,
                solution.fluence.iter().map(|&v| v as f32).collect(),
            )?;
            let mut total = scattered_grid.clone();
            for (t, g) in total.data_mut().iter_mut().zip(&singular) {
                *t += g;
            }
            if let Some(direct) = &direct {
                for (t, v) in total.data_mut().iter_mut().zip(direct.fluence(c)) {
                    *t += v as f32;
                }
            }
            fluence.push(total);
            scattered.push(scattered_grid);
            let conv = solution.convergence;
            let replace = match &report {
                None => true,
                Some((_, _, reason)) => reason.is_converged() && !conv.stop_reason.is_converged(),
            };
            if replace {
                report = Some((conv.iterations(), conv.residuals, conv.stop_reason));
            }
        }
        let angular = direct.and_then(|d| match d.direct.angular {
            Some(Angular::Lights(mut lights)) => {
                lights.isotropic_fluence = scattered
                    .iter()
                    .enumerate()
                    .map(|(c, s)| {
                        let mut s = s.clone();
                        if let Some(iso) = lights.isotropic_fluence.get(c) {
                            for (a, b) in s.data_mut().iter_mut().zip(iso.data()) {
                                *a += b;
                            }
                        }
                        s
                    })
                    .collect();
                Some(Angular::Lights(lights))
            }
            // `direct` keeps per-light transmittance only.
            Some(Angular::Ordinates(_)) | None => None,
        });
        let (iterations, residual_history, stop_reason) =
            report.unwrap_or((0, Vec::new(), StopReason::Exact));
        Ok(Solution {
            fluence,
            angular,
            standard_error: None,
            report: SolveReport {
                solver: self.name.into(),
                iterations,
                residual_history,
                wall_time_s: started.elapsed().as_secs_f64(),
                peak_memory_bytes: memory,
                stop_reason,
            },
        })
    }
}
