//! The registry entry `lbm`: the lattice on a problem's grid, through the core driver.
//!
//! Per channel the driver hands the diffusion coefficient D = 1/(3σ_t′) and σ_a per cell
//! (`driver::Coefficients`, D's floor included), the lights' first-collision sources Q₀ and
//! Q₁ (`Channel::diffusion_sources`: the uncollided light of every light that shines from
//! outside the medium, the sky's included, and emission), and the point lights inside the
//! medium (power 4πI into the cell that holds them). They become lattice units (D/h, σ_a h,
//! Q h) and the lattice marches to steady state; the driver adds the uncollided fluence.
//! The box's condition is the diffusion solvers' (`lucent_diffusion::conditions`: Robin
//! with the Milne or the index-mismatched A, Dirichlet, Neumann) at the half-links.

use lucent_core::driver::{self, Channel, ChannelMethod, ChannelSolution, Context, Record};
use lucent_core::{
    Angular, Boundary, BoundaryKind, Capabilities, FluenceKind, LightKind, OutputKind, Params,
    Problem, Solution, SolveError, SolveOptions, Solver, SolverEntry, Uncollided, param_docs,
    resolved_params,
};
use lucent_grid::Grid;
use lucent_optics::PhaseFunction;

use crate::march::{Collision, LatticeProblem, MarchSettings, Streaming, Wall, march};
use crate::params::LbmParams;

/// `lbm`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LbmSolver {
    params: LbmParams,
}

/// The wall of a problem's boundary for `collision`, in lattice units: the diffusion
/// solvers' conditions at the half-links for the relaxation collisions; for Geist's
/// collision the physical wall (nothing enters a vacuum, a Robin interface reflects its
/// diffuse reflectance, a reflecting box everything), and Dirichlet or a Neumann flux as
/// for the others.
pub fn wall(boundary: Boundary, collision: Collision) -> Wall {
    if collision == Collision::Geist
        && let Some(reflectance) = boundary.diffuse_reflectance()
    {
        return Wall::Reflect { reflectance };
    }
    match boundary {
        Boundary::Vacuum | Boundary::Robin { .. } => Wall::Robin {
            a: boundary.robin_factor().unwrap_or(1.0),
        },
        Boundary::Dirichlet { value } => Wall::Dirichlet { value },
        Boundary::Neumann { flux } => Wall::Neumann { flux },
    }
}

impl LbmSolver {
    /// The registry entry ([`LbmParams`]).
    pub const ENTRY: SolverEntry = SolverEntry {
        name: "lbm",
        summary: "Lattice-Boltzmann lighting (D3Q7/D3Q19, TRT matched to diffusion, AA streaming; Geist, Bernabei ch. 4)",
        build: |p: &Params| Ok(Box::new(LbmSolver::from_params(p)?)),
        params: param_docs::<LbmParams>,
        resolved: |p| resolved_params::<LbmParams>(p, "lbm"),
    };

    /// The solver with `params`.
    pub fn new(params: LbmParams) -> Self {
        Self { params }
    }

    /// Builds from registry parameters.
    pub fn from_params(params: &Params) -> Result<Self, SolveError> {
        Ok(Self {
            params: params.parse("lbm")?,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &LbmParams {
        &self.params
    }

    /// The lattice problem of one channel (lattice units).
    pub fn lattice_problem(&self, channel: &Channel<'_>) -> LatticeProblem {
        let problem = channel.problem;
        let g = *problem.geometry();
        let h = g.spacing().x;
        let c = &channel.coefficients;
        let (mut q0, first_moment) = channel.diffusion_sources();
        for (position, power) in channel.point_sources() {
            let v = g.world_to_voxel(position) + 0.5;
            let [i, j, k] = [0, 1, 2].map(|a| (v[a].max(0.0) as usize).min(g.dims()[a] - 1));
            q0[g.index(i, j, k)] += power / g.cell_volume();
        }
        let (first, second) = match self.params.collision {
            Collision::Trt | Collision::Bgk => (
                c.diffusion
                    .iter()
                    .map(|&d| (f64::from(d) / h) as f32)
                    .collect(),
                c.sigma_a
                    .iter()
                    .map(|&a| (f64::from(a) * h) as f32)
                    .collect(),
            ),
            Collision::Geist => {
                // The transport approximation for an anisotropic phase function: isotropic
                // scattering of (1 − g)σ_s, interacting (1 − g)σ_s + σ_a.
                let gbar = problem.medium().phase.mean_cosine();
                c.sigma_t
                    .iter()
                    .zip(&c.sigma_s)
                    .map(|(&t, &s)| {
                        let reduced_s = (1.0 - gbar) * f64::from(s);
                        let reduced_t = (f64::from(t) - gbar * f64::from(s)).max(reduced_s);
                        let kt = 1.0 - (-reduced_t * h).exp();
                        let ks = if reduced_t > 0.0 {
                            kt * reduced_s / reduced_t
                        } else {
                            0.0
                        };
                        (kt as f32, ks as f32)
                    })
                    .unzip()
            }
        };
        LatticeProblem {
            dims: g.dims(),
            first,
            second,
            source: q0.iter().map(|&q| (q * h) as f32).collect(),
            first_moment: first_moment
                .iter()
                .map(|m| m.map(|v| (f64::from(v) * h) as f32))
                .collect(),
            wall: wall(problem.boundary(), self.params.collision),
        }
    }

    /// The march's settings from the parameters, stopping by `stopping`.
    pub fn settings(&self, stopping: lucent_core::Stopping) -> MarchSettings {
        MarchSettings {
            velocities: self.params.lattice,
            collision: self.params.collision,
            absorption: self.params.absorption,
            streaming: self.params.streaming,
            stopping,
            blocks: (self.params.block_slabs > 0).then_some(crate::march::Blocks {
                slabs: self.params.block_slabs,
                steps_per_visit: self.params.block_steps,
            }),
        }
    }

    /// Bytes per cell: the populations (twice for two arrays), ρ, two coefficients and the
    /// source with its first moment, in f32.
    pub fn bytes_per_cell(&self) -> u64 {
        let q = self.params.lattice.len() as u64;
        let copies = match self.params.streaming {
            Streaming::InPlace => 1,
            Streaming::TwoArrays => 2,
        };
        4 * (q * copies + 1 + 2 + 4)
    }
}

impl Solver for LbmSolver {
    fn name(&self) -> &str {
        "lbm"
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            anisotropic: true,
            heterogeneous: true,
            embedded_geometry: false,
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
            cubic_cells_only: true,
            // Lights outside enter as first-collision sources along curved rays
            // (`Uncollided::curved`); the lattice's scattered light as in a uniform index.
            graded_index: true,
            ..Capabilities::default()
        }
    }

    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
        driver::solve_per_channel(self, self, problem, options).map(|(s, _)| s)
    }
}

impl ChannelMethod for LbmSolver {
    type Setup = ();
    /// The scattered fluence (the renderer's isotropic in-scattering).
    type Extra = Grid;

    fn stage(&self) -> &'static str {
        "lattice step"
    }

    fn memory_bytes(&self, problem: &Problem) -> u64 {
        problem.geometry().voxel_count() as u64 * self.bytes_per_cell() * problem.channels() as u64
    }

    fn setup(&self, _: &Context<'_>) -> Result<(), SolveError> {
        Ok(())
    }

    fn solve_channel(
        &self,
        _: &(),
        channel: Channel<'_>,
    ) -> Result<ChannelSolution<Grid>, SolveError> {
        let geometry = *channel.problem.geometry();
        let lattice = self.lattice_problem(&channel);
        let marched = march(&lattice, &self.settings(channel.stopping.clone()))
            .map_err(|e| e.into_solve_error("lbm"))?;
        let n = geometry.voxel_count() as u64;
        Ok(ChannelSolution {
            fluence: marched.fluence.clone(),
            record: Record::from_residuals(
                marched.residuals,
                marched.stop_reason,
                n * self.bytes_per_cell(),
            ),
            extra: Grid::from_vec(geometry, marched.fluence)?,
        })
    }

    fn angular(
        &self,
        _: &(),
        _: &Problem,
        scattered: &mut [Grid],
        uncollided: Option<Uncollided>,
    ) -> Result<Option<Angular>, SolveError> {
        Ok(uncollided.and_then(|u| u.into_angular(scattered)))
    }
}
