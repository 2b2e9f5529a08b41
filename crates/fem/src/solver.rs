//! The registry entry `fem-p1-jacobi`: Murray's finite-element system on a problem's grid
//! (vertices at the cell centres, homogeneous K_t = σ_t, natural boundary), solved by
//! Jacobi as the thesis did. It is kept for the stability study: Jacobi diverges on this
//! system for every K_t (spectral radius ≥ 19/8), so the solve ends with
//! `DivergedGrowth` and returns the last finite iterate. Parameter `solver`: `jacobi`
//! (default), or `gmres` to see what the converged system gives.

use glam::DVec3;
use lucent_core::driver::{
    self, Channel, ChannelMethod, ChannelSolution, Coefficients, Context, Record, Route,
};
use lucent_core::{
    BoundaryKind, Capabilities, FluenceKind, Light, LightKind, OutputKind, Params, Problem,
    Solution, SolveError, SolveOptions, Solver, SolverEntry, param_docs,
    point_source_singular_part, resolved_params,
};
use lucent_grid::Grid;
use lucent_optics::PhaseFunction;

use crate::murray::{Mesh, MurraySystem};
use crate::params::{FemDiffusionParams, FemP1Iteration, FemP1Params};
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
            let p: FemP1Params = p.parse("fem-p1-jacobi")?;
            Ok(Box::new(FemP1Solver {
                krylov: p.solver == FemP1Iteration::Gmres,
            }))
        },
        params: param_docs::<FemP1Params>,
        resolved: |p| resolved_params::<FemP1Params>(p, "fem-p1-jacobi"),
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
        driver::solve_per_channel(self, self, problem, options).map(|(s, _)| s)
    }
}

impl ChannelMethod for FemP1Solver {
    type Setup = Mesh;
    type Extra = ();

    fn memory_bytes(&self, problem: &Problem) -> u64 {
        // Assembly goes through element triplets: 8 × 8 blocks of 4 × 4 per element at 24
        // bytes each (24.6 kB per cell), then the CSR matrix of 27 blocks of 4 × 4 per
        // vertex (6.9 kB): 32 kB per cell, against 32.6 measured at 40³
        // (`tests/memory_estimates.rs`).
        problem.geometry().voxel_count() as u64 * (8 * 8 * 16 * 24 + 27 * 16 * 16 + 1024)
    }

    fn setup(&self, context: &Context<'_>) -> Result<Mesh, SolveError> {
        let g = context.problem.geometry();
        Ok(Mesh {
            nodes: g.dims(),
            spacing: g.spacing().x,
            periodic: false,
        })
    }

    fn route(&self, _: &Mesh, _: &Problem, _: &Light) -> Route {
        Route::Own
    }

    fn solve_channel(
        &self,
        mesh: &Mesh,
        channel: Channel<'_>,
    ) -> Result<ChannelSolution<()>, SolveError> {
        let g = *channel.problem.geometry();
        let n = g.voxel_count();
        // Homogeneous (the capabilities ask for it): any cell's K_t.
        let kt = f64::from(channel.coefficients.sigma_t[0]);
        let interrupt = channel.stopping.interrupt(std::time::Instant::now());
        let system = MurraySystem::assemble_within(*mesh, kt, &interrupt).map_err(|e| match e {
            crate::FemError::Halted(halt) => SolveError::Halted {
                solver: self.name().into(),
                stage: "the assembly".into(),
                halt,
            },
            e => invalid("problem", e.to_string()),
        })?;
        interrupt.check(self.name(), "the assembly")?;
        // ∫ψ_0 ϕ_k Q_e with a lumped mass: 4π Q_k h³ per vertex (vertices at cell centres).
        let mut b = vec![0.0; 4 * n];
        for (k, e) in channel.emission().iter().enumerate() {
            b[4 * k] += 4.0 * std::f64::consts::PI * e * g.cell_volume();
        }
        for (position, power) in channel.point_sources() {
            let v = g.world_to_voxel(position).round();
            let [i, j, k] = [0, 1, 2].map(|a| (v[a].max(0.0) as usize).min(g.dims()[a] - 1));
            b[4 * g.index(i, j, k)] += power;
        }
        // Jacobi on this system must be seen to blow up, not merely stall.
        let stopping = Stopping {
            divergence: default_stopping().divergence,
            ..channel.stopping
        };
        let mut x = vec![0.0; 4 * n];
        let convergence = if self.krylov {
            gmres(&system.matrix, &b, &mut x, 60, &stopping)
        } else {
            jacobi(&system.matrix, &b, &mut x, &stopping)
        }
        .map_err(|e| invalid("problem", e.to_string()))?;
        Ok(ChannelSolution {
            fluence: system.fluence(&x).iter().map(|&v| v as f32).collect(),
            record: Record::from_residuals(convergence.residuals, convergence.stop_reason, 0),
            extra: (),
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
            let p: FemDiffusionParams = p.parse("fem-diffusion")?;
            Ok(Box::new(FemDiffusionSolver { sweeps: p.sweeps }))
        },
        params: param_docs::<FemDiffusionParams>,
        resolved: |p| resolved_params::<FemDiffusionParams>(p, "fem-diffusion"),
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
        driver::solve_per_channel(self, self, problem, options).map(|(s, _)| s)
    }
}

/// What every channel of `fem-diffusion` shares: the grid's own lattice of elements, or
/// the mesh fitted to the embedded body.
pub enum FemSetup {
    /// Elements on the grid's cells, unknowns at their corners.
    Grid,
    /// The boundary-fitted mesh of the embedded body.
    Body {
        /// The mesh.
        mesh: StarMesh,
        /// Its cells per axis.
        cells: usize,
    },
}

impl ChannelMethod for FemDiffusionSolver {
    type Setup = FemSetup;
    type Extra = ();

    fn stage(&self) -> &'static str {
        "CG iteration"
    }

    fn memory_bytes(&self, problem: &Problem) -> u64 {
        // The assembled Q1 matrix (27 non-zeros per row), the triplets it is built from,
        // its Galerkin hierarchy and the sparse prolongations' triplets: measured at 1030
        // bytes per cell at 48³ and 1420 at 96³ (`tests/memory_estimates.rs`; the finest
        // level's share grows with the grid), 330 for the matrices alone (BENCHMARKS.md).
        problem.geometry().voxel_count() as u64 * 1600
    }

    fn setup(&self, context: &Context<'_>) -> Result<FemSetup, SolveError> {
        Ok(match context.problem.embedded() {
            Some(sdf) => {
                let (mesh, cells, _) = body_mesh(context.problem, sdf)?;
                FemSetup::Body { mesh, cells }
            }
            None => FemSetup::Grid,
        })
    }

    /// With a body, a point light is the elements' own only where the mesh reaches it.
    fn route(&self, setup: &FemSetup, problem: &Problem, light: &Light) -> Route {
        match (setup, light) {
            (FemSetup::Body { mesh, .. }, Light::Point { position, .. })
                if mesh.locate(*position).is_none() =>
            {
                Route::Uncollided
            }
            _ => driver::default_route(problem, light),
        }
    }

    fn solve_channel(
        &self,
        setup: &FemSetup,
        channel: Channel<'_>,
    ) -> Result<ChannelSolution<()>, SolveError> {
        let (fluence, convergence, bytes) = match setup {
            FemSetup::Grid => self.grid_channel(&channel)?,
            FemSetup::Body { mesh, cells } => self.body_channel(mesh, *cells, &channel)?,
        };
        Ok(ChannelSolution {
            fluence,
            record: Record::from_residuals(convergence.residuals, convergence.stop_reason, bytes),
            extra: (),
        })
    }
}

impl FemDiffusionSolver {
    /// The multigrid-preconditioned CG's stopping rule: the channel's, diverging at 10⁸.
    fn stopping(channel: &Channel<'_>) -> Stopping {
        Stopping {
            divergence: default_stopping().divergence,
            ..channel.stopping.clone()
        }
    }

    /// One channel on the grid's own elements: Robin (A from η), vacuum (A at η = 1) or a
    /// reflecting box; the fluence per cell is the mean of its 8 corners.
    fn grid_channel(
        &self,
        channel: &Channel<'_>,
    ) -> Result<(Vec<f32>, crate::solvers::Convergence, u64), SolveError> {
        let problem = channel.problem;
        let g = *problem.geometry();
        let h = g.spacing();
        let n = g.voxel_count();
        // A reflecting box (the capabilities refuse other Neumann fluxes) or Robin.
        let robin = match problem.boundary() {
            lucent_core::Boundary::Neumann { .. } => None,
            b => Some(b.robin_factor().unwrap_or(1.0)),
        };
        let widen = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<f64>>();
        let q1 = crate::q1::Q1Problem {
            cells: g.dims(),
            spacing: h.x,
            diffusion: widen(&channel.coefficients.diffusion),
            absorption: widen(&channel.coefficients.sigma_a),
            robin: [robin; 6],
        };
        let interrupt = channel.stopping.interrupt(std::time::Instant::now());
        let set_up = |stage: &str| interrupt.check(self.name(), stage);
        set_up("the assembly")?;
        let matrix = q1
            .assemble()
            .map_err(|e| invalid("problem", e.to_string()))?;
        set_up("the load")?;
        // Emission and first collisions: Q₀ lumped, the first moment in the weak form.
        let (q0, moment) = channel.diffusion_sources();
        let mut b = q1.cell_load(&q0, &moment);
        // Point sources: the singular part analytically where the medium allows (its
        // smooth remainder integrated per element by Gauss points), else a point.
        let mut singular = vec![0.0f32; n];
        let origin = g.origin();
        let Coefficients {
            diffusion: d,
            sigma_a: sa,
            ..
        } = &channel.coefficients;
        for (position, power) in channel.point_sources() {
            match point_source_singular_part(&g, d, sa, |_| true, position, power) {
                Some(part) => {
                    for (cell, f) in part.source.iter().enumerate() {
                        if *f != 0.0 {
                            q1.add_element_source(&mut b, cell, |x| {
                                part.source_at(origin + DVec3::from_array(x))
                            });
                        }
                    }
                    for (s, v) in singular.iter_mut().zip(&part.fluence) {
                        *s += v;
                    }
                }
                None => {
                    let s = q1
                        .point_source((position - origin).to_array(), power)
                        .map_err(|e| invalid("lights", e.to_string()))?;
                    for (b, s) in b.iter_mut().zip(s) {
                        *b += s;
                    }
                }
            }
        }
        let bytes = (matrix.nnz() * 12 + matrix.rows() * 40) as u64;
        let mg =
            crate::q1::Q1Multigrid::for_lattice_within(q1.cells, matrix, self.sweeps, &interrupt)
                .map_err(|halt| SolveError::Halted {
                solver: self.name().into(),
                stage: "the multigrid hierarchy".into(),
                halt,
            })?;
        let mut x = vec![0.0; b.len()];
        let convergence = mg
            .solve(&b, &mut x, &Self::stopping(channel))
            .map_err(|e| invalid("problem", e.to_string()))?;
        let fluence = q1
            .cell_means(&x)
            .iter()
            .zip(&singular)
            .map(|(m, s)| *m as f32 + s)
            .collect();
        Ok((fluence, convergence, bytes))
    }

    /// One channel on the body's boundary-fitted mesh: D and σ_a sampled trilinearly at
    /// every Gauss point, Robin (A from η) or vacuum (A at η = 1) on its surface; cell
    /// values interpolate the nodal solution at cell centres, zero outside the body (where
    /// the driver adds the uncollided light alone).
    fn body_channel(
        &self,
        mesh: &StarMesh,
        cells: usize,
        channel: &Channel<'_>,
    ) -> Result<(Vec<f32>, crate::solvers::Convergence, u64), SolveError> {
        let problem = channel.problem;
        let sdf = problem
            .embedded()
            .ok_or_else(|| invalid("embedded", "a body mesh without a body"))?;
        let g = *problem.geometry();
        let n = g.voxel_count();
        let c = channel.index;
        let robin = problem.boundary().robin_factor().unwrap_or(1.0);
        let medium = problem.medium();
        let gbar = medium.phase.mean_cosine();
        let floor = Coefficients::reduced_floor(problem);
        let coefficients = |p: DVec3| {
            let (a, d) = Coefficients::absorption_and_diffusion(
                f64::from(medium.sigma_t(c).sample_trilinear(p)),
                f64::from(medium.sigma_s_at(c, p)),
                gbar,
                floor,
            );
            (d, a)
        };
        let matrix = mesh
            .assemble_with(coefficients, robin)
            .map_err(|e| invalid("embedded", e.to_string()))?;
        // Volumetric sources: emission and first-collision sources, sampled trilinearly
        // from the grid at every Gauss point.
        let (q0, first) = channel.diffusion_sources();
        let q0: Vec<f32> = q0.iter().map(|&q| q as f32).collect();
        let mut moment = [vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]];
        for (cell, f) in first.iter().enumerate() {
            for a in 0..3 {
                moment[a][cell] = f[a];
            }
        }
        // Point sources: the singular part analytically where the medium around them is
        // homogeneous and whole (the remainder's smooth source joins q0), else points.
        let mut singular = vec![0.0f32; n];
        let mut parts = Vec::new();
        let mut points = Vec::new();
        let half_diagonal = 0.5 * 3f64.sqrt() * g.spacing().max_element();
        let whole = |cell: usize| f64::from(sdf.data()[cell]) < -half_diagonal;
        let Coefficients {
            diffusion: d,
            sigma_a: sa,
            ..
        } = &channel.coefficients;
        for (position, power) in channel.point_sources() {
            match point_source_singular_part(&g, d, sa, whole, position, power) {
                Some(part) => {
                    for (s, v) in singular.iter_mut().zip(&part.fluence) {
                        *s += v;
                    }
                    parts.push(part);
                }
                None => points.push((position, power)),
            }
        }
        let q0 = Grid::from_vec(g, q0)?;
        let [mx, my, mz] = moment.map(|m| Grid::from_vec(g, m));
        let (mx, my, mz) = (mx?, my?, mz?);
        let with_moment = channel.uncollided.is_some();
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
                (q, 3.0 * coefficients(p).0 * first)
            })
            .map_err(|e| invalid("embedded", e.to_string()))?;
        for (position, power) in points {
            let (cell, xi) = mesh
                .locate(position)
                .ok_or_else(|| invalid("lights", "a point light outside the mesh"))?;
            for (a, id) in mesh.element(cell).iter().enumerate() {
                let w = [a & 1, (a >> 1) & 1, a >> 2]
                    .iter()
                    .zip(xi)
                    .map(|(&o, t)| if o == 1 { t } else { 1.0 - t })
                    .product::<f64>();
                b[*id] += power * w;
            }
        }
        let bytes = (matrix.nnz() * 12 + matrix.rows() * 40) as u64;
        let mg = crate::q1::Q1Multigrid::for_lattice([cells; 3], matrix, self.sweeps);
        let mut x = vec![0.0; b.len()];
        let convergence = mg
            .solve(&b, &mut x, &Self::stopping(channel))
            .map_err(|e| invalid("problem", e.to_string()))?;
        let fluence = (0..n)
            .map(|cell| {
                let [i, j, k] = g.coords(cell);
                let p = g.cell_centre(i, j, k);
                match sdf.data()[cell] < 0.0 {
                    true => mesh.interpolate(&x, p).unwrap_or(0.0) as f32 + singular[cell],
                    false => 0.0,
                }
            })
            .collect();
        Ok((fluence, convergence, bytes))
    }
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
