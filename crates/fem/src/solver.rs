//! The registry entry `fem-p1-jacobi`: Murray's finite-element system on a problem's grid
//! (vertices at the cell centres, homogeneous K_t = σ_t, natural boundary), solved by
//! Jacobi as the thesis did. It is kept for the stability study: Jacobi diverges on this
//! system for every K_t (spectral radius ≥ 19/8), so the solve ends with
//! `DivergedGrowth` and returns the last finite iterate. Parameter `solver`: `jacobi`
//! (default), or `gmres` to see what the converged system gives.

use std::time::Instant;

use lucent_core::{
    BoundaryKind, Capabilities, FluenceKind, Light, LightKind, OutputKind, ParamValue, Params,
    Problem, Solution, SolveError, SolveOptions, SolveReport, Solver, SolverEntry,
};
use lucent_grid::Grid;

use crate::murray::{Mesh, MurraySystem};
use crate::solvers::{default_stopping, gmres, jacobi};
use crate::sphere::StarMesh;
use lucent_core::Stopping;

/// `fem-p1-jacobi`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FemP1Solver {
    krylov: bool,
}

fn invalid(name: &str, reason: impl Into<String>) -> SolveError {
    SolveError::InvalidParameter {
        name: name.into(),
        reason: reason.into(),
    }
}

impl FemP1Solver {
    /// The registry entry.
    pub const ENTRY: SolverEntry = SolverEntry {
        name: "fem-p1-jacobi",
        summary: "Murray's P1 x trilinear finite elements for the RTE, by Jacobi (diverges: kept for the study)",
        build: |p: &Params| {
            p.check_known("fem-p1-jacobi", &["solver"])?;
            let krylov = match p.0.get("solver") {
                None => false,
                Some(ParamValue::Text(t)) if t == "jacobi" => false,
                Some(ParamValue::Text(t)) if t == "gmres" => true,
                Some(other) => {
                    return Err(invalid("solver", format!("{other:?}: jacobi or gmres")));
                }
            };
            Ok(Box::new(FemP1Solver { krylov }))
        },
    };
}

impl Solver for FemP1Solver {
    fn name(&self) -> &str {
        "fem-p1-jacobi"
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            anisotropic: true,
            heterogeneous: false,
            embedded_geometry: false,
            boundaries: vec![BoundaryKind::Vacuum],
            lights: vec![LightKind::Point, LightKind::Emission],
            output: OutputKind::Fluence,
            fluence: FluenceKind::Uncollided,
            cubic_cells_only: true,
            point_lights_inside_grid: true,
            ..Capabilities::default()
        }
    }

    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
        self.admits(problem)?;
        options.validate()?;
        let started = Instant::now();
        let g = *problem.geometry();
        let h = g.spacing();
        let mesh = Mesh {
            nodes: g.dims(),
            spacing: h.x,
            periodic: false,
        };
        let n = g.voxel_count();
        let bytes = (n as u64) * 4 * 27 * 4 * 16;
        if bytes > options.memory_budget {
            return Err(SolveError::OverBudget {
                solver: self.name().into(),
                needed: bytes,
                budget: options.memory_budget,
            });
        }
        let mut fluence = Vec::new();
        let mut last = None;
        for c in 0..problem.channels() {
            let kt = f64::from(problem.medium().sigma_t(c).data()[0]);
            let system =
                MurraySystem::assemble(mesh, kt).map_err(|e| invalid("problem", e.to_string()))?;
            // ∫ψ_0 ϕ_k Q_e with a lumped mass: 4π Q_k h³ per vertex.
            let mut b = vec![0.0; 4 * n];
            let volume = g.cell_volume();
            for light in problem.lights() {
                match light {
                    Light::Point {
                        position,
                        intensity,
                    } => {
                        let v = g.world_to_voxel(*position).round();
                        let inside = (0..3).all(|a| v[a] >= 0.0 && v[a] < g.dims()[a] as f64);
                        if !inside {
                            return Err(invalid("lights", "point lights must lie inside the grid"));
                        }
                        let k = g.index(v.x as usize, v.y as usize, v.z as usize);
                        b[4 * k] += 4.0 * std::f64::consts::PI * intensity.channel(c);
                    }
                    Light::Emission { grid, scale } => {
                        for (k, e) in grid.data().iter().enumerate() {
                            b[4 * k] += 4.0
                                * std::f64::consts::PI
                                * scale.channel(c)
                                * f64::from(*e)
                                * volume;
                        }
                    }
                    other => return Err(invalid("lights", format!("{:?}", other.kind()))),
                }
            }
            let stopping = Stopping {
                relative_tolerance: options.relative_tolerance,
                max_iterations: options.max_iterations,
                time_budget: options.time_budget,
                progress: options.progress.clone(),
                ..default_stopping()
            };
            let mut x = vec![0.0; 4 * n];
            let convergence = if self.krylov {
                gmres(&system.matrix, &b, &mut x, 60, &stopping)
            } else {
                jacobi(&system.matrix, &b, &mut x, &stopping)
            }
            .map_err(|e| invalid("problem", e.to_string()))?;
            fluence.push(Grid::from_vec(
                g,
                system.fluence(&x).iter().map(|&v| v as f32).collect(),
            )?);
            last = Some(convergence);
        }
        let convergence = last.ok_or_else(|| invalid("problem", "no channel"))?;
        Ok(Solution {
            fluence,
            angular: None,
            standard_error: None,
            report: SolveReport {
                solver: self.name().into(),
                iterations: convergence.residuals.len().saturating_sub(1),
                residual_history: convergence.residuals,
                wall_time_s: started.elapsed().as_secs_f64(),
                peak_memory_bytes: bytes,
                stop_reason: convergence.stop_reason,
            },
        })
    }
}

/// `fem-diffusion`: Q1 Galerkin diffusion on the problem's grid (unknowns at the cell
/// corners, D = 1/(3σ_t′) and σ_a per cell), Robin (A from η), vacuum (A at η = 1) or reflecting
/// boxes, solved by multigrid-preconditioned CG. Lights: point lights inside (power 4πI),
/// emission (4π L_e), and every other light through `direct`'s first-collision sources
/// (`lucent_core::Uncollided::first_collision_sources`: Q₀ = σ_s φ_u, Q₁ = g σ_s Σ ω E T, the latter
/// entering the weak form as ∫ 3D Q₁·∇v, whose boundary terms cancel against the Robin
/// condition's). The fluence per cell is the mean of its 8 corners plus φ_u. With an
/// embedded body the elements are fitted to it instead ([`StarMesh::from_sdf`]; Robin or
/// vacuum on its surface) and cell values interpolate the nodal solution at cell centres.
/// Parameter `sweeps` (smoothing sweeps per level, 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FemDiffusionSolver {
    sweeps: usize,
}

impl FemDiffusionSolver {
    /// The registry entry.
    pub const ENTRY: SolverEntry = SolverEntry {
        name: "fem-diffusion",
        summary: "steady diffusion by Q1 Galerkin finite elements, multigrid-preconditioned CG",
        build: |p: &Params| {
            p.check_known("fem-diffusion", &["sweeps"])?;
            let sweeps = p.usize_or("sweeps", 2)?;
            if !(1..=16).contains(&sweeps) {
                return Err(invalid("sweeps", "1 to 16"));
            }
            Ok(Box::new(FemDiffusionSolver { sweeps }))
        },
    };
}

impl Solver for FemDiffusionSolver {
    fn name(&self) -> &str {
        "fem-diffusion"
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            anisotropic: true,
            heterogeneous: true,
            embedded_geometry: true,
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
            output: OutputKind::Fluence,
            fluence: FluenceKind::Total,
            cubic_cells_only: true,
            reflecting_neumann_only: true,
            ..Capabilities::default()
        }
    }

    fn admits(&self, problem: &Problem) -> Result<(), SolveError> {
        self.capabilities().check(self.name(), problem)?;
        if let Some(sdf) = problem.embedded() {
            body_mesh(problem, sdf)?;
        }
        Ok(())
    }

    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
        use lucent_optics::PhaseFunction;
        self.admits(problem)?;
        options.validate()?;
        // The assembled Q1 matrix with its Galerkin hierarchy: about 330 bytes per node
        // (BENCHMARKS.md), plus the cell fields.
        let needed = problem.geometry().voxel_count() as u64 * (400 + 32);
        if needed > options.memory_budget {
            return Err(SolveError::OverBudget {
                solver: self.name().into(),
                needed,
                budget: options.memory_budget,
            });
        }
        if let Some(sdf) = problem.embedded() {
            return self.solve_embedded(problem, sdf, options);
        }
        let started = Instant::now();
        let g = *problem.geometry();
        let h = g.spacing();
        // A reflecting box (the capabilities refuse other Neumann fluxes) or Robin.
        let robin = match problem.boundary() {
            lucent_core::Boundary::Neumann { .. } => None,
            b => Some(b.robin_factor().unwrap_or(1.0)),
        };
        let n = g.voxel_count();
        let gbar = problem.medium().phase.mean_cosine();
        // Lights the elements take directly, and the rest through `direct`.
        let inside = |p: glam::DVec3| {
            let v = g.world_to_voxel(p) + 0.5;
            (0..3).all(|a| v[a] >= 0.0 && v[a] <= g.dims()[a] as f64)
        };
        let external: Vec<Light> = problem
            .lights()
            .iter()
            .filter(|l| match l {
                Light::Point { position, .. } => !inside(*position),
                Light::Emission { .. } => false,
                _ => true,
            })
            .cloned()
            .collect();
        let direct = if external.is_empty() {
            None
        } else {
            let p = Problem::new(
                g,
                problem.medium().clone(),
                external,
                lucent_core::Boundary::Vacuum,
                None,
            )?;
            Some(lucent_core::Uncollided::new(&p, options)?)
        };
        let floor = 1e-3 / h.x;
        let mut fluence = Vec::new();
        let mut last = None;
        let mut bytes = 0u64;
        for c in 0..problem.channels() {
            let (mut d, mut sa) = (Vec::with_capacity(n), Vec::with_capacity(n));
            for cell in 0..n {
                let [i, j, k] = g.coords(cell);
                let st = f64::from(problem.medium().sigma_t(c).data()[cell]);
                let ss = f64::from(problem.medium().sigma_s_at(c, g.cell_centre(i, j, k)));
                let a = (st - ss).max(0.0);
                d.push(1.0 / (3.0 * (a + (1.0 - gbar) * ss).max(floor)));
                sa.push(a);
            }
            let q1 = crate::q1::Q1Problem {
                cells: g.dims(),
                spacing: h.x,
                diffusion: d,
                absorption: sa,
                robin: [robin; 6],
            };
            let matrix = q1
                .assemble()
                .map_err(|e| invalid("problem", e.to_string()))?;
            let mut b = vec![0.0; matrix.rows()];
            let origin = g.origin();
            let volume = g.cell_volume();
            if let Some(direct) = &direct {
                let ss: Vec<f32> = (0..n)
                    .map(|cell| {
                        let [i, j, k] = g.coords(cell);
                        problem.medium().sigma_s_at(c, g.cell_centre(i, j, k))
                    })
                    .collect();
                let (scattered, moment) = direct.first_collision_sources(c, &ss, gbar);
                let hh = h.x * h.x / 4.0;
                for cell in 0..n {
                    let [i, j, k] = g.coords(cell);
                    for corner in 0..8 {
                        let p = [corner & 1, (corner >> 1) & 1, corner >> 2];
                        let node = q1.node([i + p[0], j + p[1], k + p[2]]);
                        b[node] += f64::from(scattered[cell]) * volume / 8.0;
                        if let Some(first) = moment.get(cell) {
                            // ∫ 3D Q₁·∇ϕ over the cube: ±h²/4 per axis.
                            let dq = 3.0 * q1.diffusion[cell];
                            let grad: f64 = (0..3)
                                .map(|a| {
                                    let v = f64::from(first[a]);
                                    if p[a] == 1 { v } else { -v }
                                })
                                .sum();
                            b[node] += dq * grad * hh;
                        }
                    }
                }
            }
            let mut singular = vec![0.0f32; n];
            for light in problem.lights() {
                match light {
                    Light::Point {
                        position,
                        intensity,
                    } if inside(*position) => {
                        let power = 4.0 * std::f64::consts::PI * intensity.channel(c);
                        // The singular part analytically where the medium allows (its
                        // smooth remainder's source lumped like emission), else a point.
                        let (d, sa): (Vec<f32>, Vec<f32>) = q1
                            .diffusion
                            .iter()
                            .zip(&q1.absorption)
                            .map(|(&d, &a)| (d as f32, a as f32))
                            .unzip();
                        if let Some(part) = lucent_core::point_source_singular_part(
                            &g,
                            &d,
                            &sa,
                            |_| true,
                            *position,
                            power,
                        ) {
                            // ∫ f ϕ_a over each element by 3×3×3 Gauss points: f varies on
                            // the scale of the cut-off, which lumping would blur.
                            let rule = [
                                (0.5 - 0.5 * 0.6f64.sqrt(), 5.0 / 18.0),
                                (0.5, 8.0 / 18.0),
                                (0.5 + 0.5 * 0.6f64.sqrt(), 5.0 / 18.0),
                            ];
                            for (cell, f) in part.source.iter().enumerate() {
                                if *f == 0.0 {
                                    continue;
                                }
                                let [i, j, k] = g.coords(cell);
                                let corner0 =
                                    origin + glam::DVec3::new(i as f64, j as f64, k as f64) * h;
                                for (x, wx) in rule {
                                    for (y, wy) in rule {
                                        for (z, wz) in rule {
                                            let value = part
                                                .source_at(corner0 + glam::DVec3::new(x, y, z) * h)
                                                * wx
                                                * wy
                                                * wz
                                                * volume;
                                            for corner in 0..8usize {
                                                let o =
                                                    [corner & 1, (corner >> 1) & 1, corner >> 2];
                                                let shape = [x, y, z]
                                                    .iter()
                                                    .zip(o)
                                                    .map(|(t, o)| if o == 1 { *t } else { 1.0 - t })
                                                    .product::<f64>();
                                                b[q1.node([i + o[0], j + o[1], k + o[2]])] +=
                                                    value * shape;
                                            }
                                        }
                                    }
                                }
                            }
                            for (s, v) in singular.iter_mut().zip(&part.fluence) {
                                *s += v;
                            }
                            continue;
                        }
                        let x = *position - origin;
                        let s = q1
                            .point_source(x.to_array(), power)
                            .map_err(|e| invalid("lights", e.to_string()))?;
                        for (b, s) in b.iter_mut().zip(s) {
                            *b += s;
                        }
                    }
                    Light::Emission { grid, scale } => {
                        for (cell, e) in grid.data().iter().enumerate() {
                            let [i, j, k] = g.coords(cell);
                            let q = 4.0 * std::f64::consts::PI * scale.channel(c) * f64::from(*e);
                            for corner in 0..8 {
                                let at =
                                    [i + (corner & 1), j + ((corner >> 1) & 1), k + (corner >> 2)];
                                b[q1.node(at)] += q * volume / 8.0;
                            }
                        }
                    }
                    _ => {}
                }
            }
            bytes = bytes.max((matrix.nnz() * 12 + matrix.rows() * 40) as u64);
            let mg = crate::q1::Q1Multigrid::new(&q1, matrix, self.sweeps);
            let mut x = vec![0.0; b.len()];
            let convergence = mg
                .solve(
                    &b,
                    &mut x,
                    &Stopping {
                        relative_tolerance: options.relative_tolerance,
                        max_iterations: options.max_iterations,
                        time_budget: options.time_budget,
                        progress: options.progress.clone(),
                        ..default_stopping()
                    },
                )
                .map_err(|e| invalid("problem", e.to_string()))?;
            let cells: Vec<f32> = (0..n)
                .map(|cell| {
                    let [i, j, k] = g.coords(cell);
                    let sum: f64 = (0..8)
                        .map(|corner| {
                            x[q1.node([
                                i + (corner & 1),
                                j + ((corner >> 1) & 1),
                                k + (corner >> 2),
                            ])]
                        })
                        .sum();
                    (sum / 8.0) as f32
                })
                .collect();
            let mut total = Grid::from_vec(g, cells)?;
            for (t, v) in total.data_mut().iter_mut().zip(&singular) {
                *t += v;
            }
            if let Some(direct) = &direct {
                for (t, u) in total.data_mut().iter_mut().zip(direct.fluence(c)) {
                    *t += u as f32;
                }
            }
            fluence.push(total);
            last = Some(convergence);
        }
        finish(self.name(), fluence, last, started, bytes)
    }
}

impl FemDiffusionSolver {
    /// The embedded body {sdf < 0} on a boundary-fitted mesh ([`StarMesh::from_sdf`] from
    /// the centroid of its inside cells; the body must be star-shaped from there), D and σ_a
    /// sampled trilinearly at every Gauss point, Robin (A from η) or vacuum (A at η = 1) on its
    /// surface. External lights are attenuated through the body only (σ_t set to zero
    /// outside), as `diffusion-mg` does; cells outside the body get φ_u alone.
    fn solve_embedded(
        &self,
        problem: &Problem,
        sdf: &Grid,
        options: &SolveOptions,
    ) -> Result<Solution, SolveError> {
        use glam::DVec3;
        use lucent_optics::PhaseFunction;
        let started = Instant::now();
        let g = *problem.geometry();
        let n = g.voxel_count();
        let robin = problem.boundary().robin_factor().unwrap_or(1.0);
        let (mesh, cells, h) = body_mesh(problem, sdf)?;
        let sample = |p: DVec3| f64::from(sdf.sample_trilinear(p));
        let inside = |p: DVec3| sample(p) < 0.0 && mesh.locate(p).is_some();
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
            let medium = problem.medium();
            let masked = medium.masked(sdf);
            let p = Problem::new(g, masked, external, lucent_core::Boundary::Vacuum, None)?;
            Some(lucent_core::Uncollided::new(&p, options)?)
        };

        let gbar = problem.medium().phase.mean_cosine();
        let floor = 1e-3 / h;
        let medium = problem.medium();
        let coefficients = |c: usize, p: DVec3| {
            let st = f64::from(medium.sigma_t(c).sample_trilinear(p));
            let ss = f64::from(medium.sigma_s_at(c, p));
            let a = (st - ss).max(0.0);
            (1.0 / (3.0 * (a + (1.0 - gbar) * ss).max(floor)), a)
        };
        let mut fluence = Vec::new();
        let mut last = None;
        let mut bytes = 0u64;
        for c in 0..problem.channels() {
            let matrix = mesh
                .assemble_with(|p| coefficients(c, p), robin)
                .map_err(|e| invalid("embedded", e.to_string()))?;
            // Volumetric sources: emission and first-collision sources, sampled
            // trilinearly from the grid at every Gauss point.
            let mut q0 = vec![0.0f32; n];
            for light in &emission {
                if let Light::Emission { grid, scale } = light {
                    let s = 4.0 * std::f64::consts::PI * scale.channel(c);
                    for (q, e) in q0.iter_mut().zip(grid.data()) {
                        *q += (s * f64::from(*e)) as f32;
                    }
                }
            }
            let mut moment = [vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]];
            if let Some(direct) = &direct {
                let ss: Vec<f32> = (0..n)
                    .map(|cell| {
                        let [i, j, k] = g.coords(cell);
                        medium.sigma_s_at(c, g.cell_centre(i, j, k))
                    })
                    .collect();
                let (scattered, first) = direct.first_collision_sources(c, &ss, gbar);
                for (q, s) in q0.iter_mut().zip(scattered) {
                    *q += s;
                }
                for (cell, f) in first.iter().enumerate() {
                    for a in 0..3 {
                        moment[a][cell] = f[a];
                    }
                }
            }
            // Point sources: the singular part analytically where the medium around them is
            // homogeneous and whole (the remainder's smooth source joins q0), else points.
            let mut singular = vec![0.0f32; n];
            let mut regularised = vec![false; points.len()];
            let mut parts: Vec<lucent_core::SingularPart> = Vec::new();
            {
                let (d, sa): (Vec<f32>, Vec<f32>) = (0..n)
                    .map(|cell| {
                        let [i, j, k] = g.coords(cell);
                        let (d, a) = coefficients(c, g.cell_centre(i, j, k));
                        (d as f32, a as f32)
                    })
                    .unzip();
                let half_diagonal = 0.5 * 3f64.sqrt() * h;
                let whole = |cell: usize| f64::from(sdf.data()[cell]) < -half_diagonal;
                for (l, light) in points.iter().enumerate() {
                    if let Light::Point {
                        position,
                        intensity,
                    } = light
                    {
                        let power = 4.0 * std::f64::consts::PI * intensity.channel(c);
                        if let Some(part) = lucent_core::point_source_singular_part(
                            &g, &d, &sa, whole, *position, power,
                        ) {
                            for (s, v) in singular.iter_mut().zip(&part.fluence) {
                                *s += v;
                            }
                            regularised[l] = true;
                            parts.push(part);
                        }
                    }
                }
            }
            let q0 = Grid::from_vec(g, q0)?;
            let moment = moment.map(|m| Grid::from_vec(g, m));
            let [mx, my, mz] = moment;
            let (mx, my, mz) = (mx?, my?, mz?);
            let with_moment = direct.is_some();
            let mut b = mesh
                .load(|p| {
                    // The remainders' sources exactly at the Gauss points: they vary on the
                    // scale of the cut-off, which trilinear cell values would blur.
                    let q = f64::from(q0.sample_trilinear(p))
                        + parts.iter().map(|part| part.source_at(p)).sum::<f64>();
                    if !with_moment {
                        return (q, DVec3::ZERO);
                    }
                    let first = DVec3::new(
                        f64::from(mx.sample_trilinear(p)),
                        f64::from(my.sample_trilinear(p)),
                        f64::from(mz.sample_trilinear(p)),
                    );
                    (q, 3.0 * coefficients(c, p).0 * first)
                })
                .map_err(|e| invalid("embedded", e.to_string()))?;
            for (light, _) in points.iter().zip(&regularised).filter(|(_, r)| !**r) {
                if let Light::Point {
                    position,
                    intensity,
                } = light
                {
                    let (cell, xi) = mesh
                        .locate(*position)
                        .ok_or_else(|| invalid("lights", "a point light outside the mesh"))?;
                    let power = 4.0 * std::f64::consts::PI * intensity.channel(c);
                    let ids = mesh.element(cell);
                    for (a, id) in ids.iter().enumerate() {
                        let w = [a & 1, (a >> 1) & 1, a >> 2]
                            .iter()
                            .zip(xi)
                            .map(|(&o, t)| if o == 1 { t } else { 1.0 - t })
                            .product::<f64>();
                        b[*id] += power * w;
                    }
                }
            }
            bytes = bytes.max((matrix.nnz() * 12 + matrix.rows() * 40) as u64);
            let mg = crate::q1::Q1Multigrid::for_lattice([cells; 3], matrix, self.sweeps);
            let mut x = vec![0.0; b.len()];
            let convergence = mg
                .solve(
                    &b,
                    &mut x,
                    &Stopping {
                        relative_tolerance: options.relative_tolerance,
                        max_iterations: options.max_iterations,
                        time_budget: options.time_budget,
                        progress: options.progress.clone(),
                        ..default_stopping()
                    },
                )
                .map_err(|e| invalid("problem", e.to_string()))?;
            let mut total = Grid::from_vec(
                g,
                (0..n)
                    .map(|cell| {
                        let [i, j, k] = g.coords(cell);
                        let p = g.cell_centre(i, j, k);
                        match sdf.data()[cell] < 0.0 {
                            true => mesh.interpolate(&x, p).unwrap_or(0.0) as f32 + singular[cell],
                            false => 0.0,
                        }
                    })
                    .collect(),
            )?;
            if let Some(direct) = &direct {
                for (t, u) in total.data_mut().iter_mut().zip(direct.fluence(c)) {
                    *t += u as f32;
                }
            }
            fluence.push(total);
            last = Some(convergence);
        }
        finish(self.name(), fluence, last, started, bytes)
    }
}

/// The solution of `fem-diffusion` from the channels' fluence and the last channel's
/// convergence.
fn finish(
    name: &str,
    fluence: Vec<Grid>,
    last: Option<crate::solvers::Convergence>,
    started: Instant,
    bytes: u64,
) -> Result<Solution, SolveError> {
    let convergence = last.ok_or_else(|| invalid("problem", "no channel"))?;
    Ok(Solution {
        fluence,
        angular: None,
        standard_error: None,
        report: SolveReport {
            solver: name.into(),
            iterations: convergence.residuals.len().saturating_sub(1),
            residual_history: convergence.residuals,
            wall_time_s: started.elapsed().as_secs_f64(),
            peak_memory_bytes: bytes,
            stop_reason: convergence.stop_reason,
        },
    })
}

/// The boundary-fitted mesh of a problem's embedded body, with its cells per axis and the
/// grid's largest spacing: what `fem-diffusion` solves on, and every way it can refuse a
/// body (a Neumann condition on it, a body that covers no cell centre or is not star-shaped
/// from its centroid).
fn body_mesh(problem: &Problem, sdf: &Grid) -> Result<(StarMesh, usize, f64), SolveError> {
    use glam::DVec3;
    if matches!(problem.boundary(), lucent_core::Boundary::Neumann { .. }) {
        return Err(SolveError::Unsupported {
            solver: "fem-diffusion".into(),
            feature: "a Neumann condition on an embedded body (it takes Robin or vacuum)".into(),
        });
    }
    let g = *problem.geometry();
    // The body's centroid and extent from its inside cells.
    let (mut sum, mut count) = (DVec3::ZERO, 0usize);
    let (mut lo, mut hi) = (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN));
    for (cell, d) in sdf.data().iter().enumerate() {
        if *d < 0.0 {
            let [i, j, k] = g.coords(cell);
            let p = g.cell_centre(i, j, k);
            sum += p;
            count += 1;
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    if count == 0 {
        return Err(SolveError::Unsupported {
            solver: "fem-diffusion".into(),
            feature: "an embedded body that covers no cell centre".into(),
        });
    }
    let h = g.spacing().max_element();
    let extent = (hi - lo).max_element() + 2.0 * h;
    // Lattice cells: the grid's spacing across the body, a multiple of 8 (three multigrid
    // levels at least).
    let cells = ((extent / h / 8.0).ceil() as usize).max(1) * 8;
    let sample = |p: DVec3| f64::from(sdf.sample_trilinear(p));
    let reach = (g.extent()).length();
    let mesh =
        StarMesh::from_sdf(cells, sum / count as f64, sample, reach, 0.25 * h).map_err(|e| {
            SolveError::Unsupported {
                solver: "fem-diffusion".into(),
                feature: format!("this embedded body: {e}"),
            }
        })?;
    Ok((mesh, cells, h))
}
