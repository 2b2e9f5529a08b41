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
//! propagation set), `closure` (`diamond`, `step`, `exponential`), `acceleration` (`dsa`,
//! `tsa` or `none`), `tsa_sweeps` (TSA's S2 sweeps per correction, 2), `anderson` (mixing depth, 2; 0 off), `outer` (`source-iteration`, the
//! default, or `gmres`), `restart` (GMRES restart length, 12), `block` (wavefront block
//! edge, 16), `work_pool_mib` (the sweeps' work paged), `truncation` (`none`, `delta-m`
//! or `delta-eddington`).
//!
//! With a truncation ([`DeltaM`]: Wiscombe 1977) the whole problem is solved in the
//! truncated medium, σ_t′ = σ_t(1 − fω), ω′ = ω(1 − f)/(1 − fω), phase p*: the lights'
//! uncollided light too, so the fraction f of each scattering that barely turns the light
//! travels with it (as delta-M asks; integrating the uncollided light with σ_t and only the
//! sweeps with σ_t′ would put the δ back into the sweeps' first-collision source). The
//! fluence is the total fluence of the truncated problem, which approximates the true
//! one (the error against an untruncated S12 solution is measured in `tests/it/delta_m.rs`).
//! For the renderer, which extinguishes camera rays with σ_t and in-scatters with σ_s, the
//! lights' exact single scattering keeps the true phase function with the truncated
//! transmittance (Nakajima & Tanaka's correction of the single-scattered light), and the
//! ordinates' in-scattered radiance J* stands for the δ part's fL′(ω) too, which the
//! extra extinction fσ_s of the camera ray removes again: exact where the scattered light
//! is nearly isotropic (J* = L′), an error of fσ_s(L′ − J*) per length elsewhere.

use lucent_core::driver::{
    self, Channel, ChannelMethod, ChannelSolution, Coefficients, Context, Record, Route,
};
use lucent_core::{
    Angular, BoundaryKind, Capabilities, FluenceKind, Light, LightKind, OrdinateRadiance,
    OutputKind, Params, Problem, Solution, SolveError, SolveOptions, Solver, SolverEntry,
    Uncollided, param_docs, resolved_params,
};
use lucent_optics::SphericalQuadrature;

use std::sync::Arc;

use crate::DeltaM;
use crate::DomError;
use crate::angular::Ordinates;
use crate::device::DeviceFactory;
use crate::params::{DomParams, Family, Truncation};
use crate::solve::{
    DomBoundary, DomProblem, DomSettings, Outer, PagedWork, SourceIteration, solve,
};

/// One channel's record of a [`DomSolver::solve_with_details`] run.
#[derive(Debug, Clone, PartialEq)]
pub struct DomChannel {
    /// How the source iteration went.
    pub convergence: crate::DomConvergence,
    /// The whole problem's energy balance (W): the lights' power entering the box (or
    /// emitted in it) and volumetric emission as `emitted`, the sky and the boundary's
    /// reflection as `inflow`, Σ σ_a φ V over the returned fluence as `absorbed`, the swept
    /// and the uncollided light leaving the box as `outflow`. It closes to the iteration's
    /// tolerance plus the uncollided cell integrals' accuracy: 1e-5 of a point light's
    /// power near it, round-off in cells from σ_t h = 3/2 (face fluxes); elsewhere, and
    /// for a sun, the 2×2×2 Gauss cell rule's error, of order (σ_t ℓ)⁴/4320 per cell with
    /// ℓ the distance over which the light changes across the cell (large where it enters
    /// a cell through its side), and the difference between the rays' trilinear σ_t and
    /// the cell's constant one where σ_t jumps. Measured (`tests/it/delta_m.rs` and variants
    /// of it, a sun at 24³): 1.4e-5 on a homogeneous cube at σ_t h = 0.5 under a vertical
    /// sun, 1.8e-3 under an oblique one, 7.5e-3 and 1.6e-2 on a sharp-edged cloud (σ_t h ≤
    /// 0.75, oblique and vertical).
    pub balance: crate::DomBalance,
}

/// `dom`.
#[derive(Debug, Clone, PartialEq)]
pub struct DomSolver {
    name: &'static str,
    octahedral: bool,
    order: usize,
    storage_level: Option<usize>,
    settings: DomSettings,
    device: Option<Device>,
    truncation: Truncation,
}

/// The factory of a device's transport steps, compared by identity.
#[derive(Clone)]
struct Device(Arc<DeviceFactory>);

impl std::fmt::Debug for Device {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Device(..)")
    }
}

impl PartialEq for Device {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

fn invalid(name: &str, reason: impl Into<String>) -> SolveError {
    SolveError::InvalidParameter {
        name: name.into(),
        reason: reason.into(),
    }
}

impl DomSolver {
    /// The registry entry ([`DomParams`]).
    pub const ENTRY: SolverEntry = SolverEntry {
        name: "dom",
        summary: "discrete ordinates: octant wavefront sweeps, first-collision sources, DSA",
        build: |p: &Params| Ok(Box::new(DomSolver::from_params(p)?)),
        params: param_docs::<DomParams>,
        resolved: |p| resolved_params::<DomParams>(p, "dom"),
    };

    /// The solver for registry parameters.
    pub fn from_params(p: &Params) -> Result<Self, SolveError> {
        Self::from_params_as(p, "dom")
    }

    /// The solver for registry parameters under the entry name `name` (its errors and
    /// reports say `name`: `gpu-dom` builds its solver so).
    pub fn from_params_as(p: &Params, name: &'static str) -> Result<Self, SolveError> {
        let p: DomParams = p.parse(name)?;
        let octahedral = p.family == Family::Octahedral;
        if octahedral && p.truncation == Truncation::DeltaM {
            return Err(invalid(
                "truncation",
                format!(
                    "delta-m moves the fraction χ_N of a level-symmetric S_N set; with family = \"octahedral\" use delta-eddington (solver `{name}`)"
                ),
            ));
        }
        let solver = Self {
            name,
            device: None,
            truncation: p.truncation,
            octahedral,
            order: p.order.unwrap_or(if octahedral { 2 } else { 8 }),
            storage_level: p.storage_level,
            settings: DomSettings {
                outer: p.outer,
                restart: p.restart,
                closure: p.closure,
                acceleration: p.acceleration,
                tsa_sweeps: p.tsa_sweeps,
                anderson: p.anderson,
                block: p.block,
                paged_work: p.work_pool_mib.map(|mib| PagedWork {
                    pool_bytes: mib.saturating_mul(1 << 20),
                    eviction: lucent_paging::Eviction::Lru,
                }),
            },
        };
        solver.ordinates(lucent_optics::Phase::Isotropic)?;
        Ok(solver)
    }

    /// This solver under the registry name `name` with its transport steps on the devices
    /// `factory` makes, one per channel ([`SourceIteration::on_device`]; `gpu-dom`). The
    /// iteration, its acceleration and its stopping rule stay on the host. Refused at solve
    /// time: `storage_level` and paged work.
    pub fn on_device(self, name: &'static str, factory: Arc<DeviceFactory>) -> Self {
        Self {
            name,
            device: Some(Device(factory)),
            ..self
        }
    }

    /// The truncation of `phase` this solver applies: `None` without one, or where the
    /// phase function has no forward peak at the order (f = 0).
    fn delta_m(&self, phase: lucent_optics::Phase) -> Result<Option<DeltaM>, SolveError> {
        let order = match self.truncation {
            Truncation::None => return Ok(None),
            Truncation::DeltaM => self.order,
            Truncation::DeltaEddington => 2,
        };
        let t = DeltaM::new(phase, order).map_err(|e| invalid("truncation", e.to_string()))?;
        Ok((t.fraction() > 0.0).then_some(t))
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
        self.name
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
        let phase = problem.medium().phase;
        let truncated;
        let problem = match self.delta_m(phase)? {
            Some(t) => {
                let mut p = Problem::new(
                    *problem.geometry(),
                    t.medium(problem.medium()),
                    problem.lights().to_vec(),
                    problem.boundary(),
                    problem.embedded().cloned(),
                )?;
                if let Some(index) = problem.refractive_index() {
                    p = p.with_refractive_index(index.clone())?;
                }
                truncated = p;
                &truncated
            }
            None => problem,
        };
        // A budget too small for the sweeps' work in memory pages it, if the rest fits.
        let paged;
        let solver = match self.paged_for_budget(problem, options.memory_budget) {
            Some(s) => {
                paged = s;
                &paged
            }
            None => self,
        };
        let (mut solution, extras) = driver::solve_per_channel(solver, solver, problem, options)?;
        // The lights' exact single scattering with the true phase function (see above).
        if let Some(Angular::Ordinates(OrdinateRadiance {
            lights: Some(lights),
            ..
        })) = &mut solution.angular
        {
            lights.phase = phase;
        }
        Ok((solution, extras.into_iter().map(|(_, r)| r).collect()))
    }

    /// Bytes of the sweeps' per-direction work per channel (cells × propagation
    /// directions, f64).
    fn work_bytes(&self, problem: &Problem) -> u64 {
        let n = self
            .ordinates(problem.medium().phase)
            .map_or(0, |o| o.propagation().len());
        problem.geometry().voxel_count() as u64 * n as u64 * 8
    }

    /// This solver with its work paged, when `budget` is below what it needs in memory
    /// but holds everything else and a pool of at least the minimal pages: the pool takes
    /// what the budget leaves (at most the work itself). `None` when the work is paged
    /// already, fits, or cannot be made to fit.
    fn paged_for_budget(&self, problem: &Problem, budget: u64) -> Option<Self> {
        if self.settings.paged_work.is_some() || self.device.is_some() {
            return None;
        }
        // As the driver counts it: the channels' own data and the per-channel fields.
        let dense = ChannelMethod::memory_bytes(self, problem)
            .saturating_add(driver::per_channel_bytes(problem));
        if dense <= budget {
            return None;
        }
        let channels = problem.channels() as u64;
        let work = self.work_bytes(problem);
        let rest = dense - work * channels;
        let ordinates = self.ordinates(problem.medium().phase).ok()?;
        let layout = crate::sweep::Layout::new(problem.geometry().dims(), self.settings.block);
        let page = crate::sweep::WorkPages::page_len(&layout, &ordinates) as u64 * 8;
        let minimum = page * SourceIteration::min_work_pages() as u64;
        let pool = (budget.checked_sub(rest)? / channels.max(1)).min(work);
        (pool >= minimum && pool < work).then(|| Self {
            settings: DomSettings {
                paged_work: Some(PagedWork {
                    pool_bytes: pool,
                    eviction: lucent_paging::Eviction::Lru,
                }),
                ..self.settings
            },
            ..self.clone()
        })
    }
}

/// The fixed source of a channel's first sweep, per cell and storage direction of
/// `ordinates` (grid order, direction fastest; power/length³/sr): the channel's emission,
/// isotropic, and its uncollided light's first collisions projected onto the directions
/// with the discrete phase function (`Uncollided::project_first_collisions`).
pub fn first_sweep_source(channel: &Channel<'_>, ordinates: &Ordinates) -> Vec<f32> {
    let m = ordinates.storage().len();
    let mut fixed = vec![0.0f32; channel.problem.geometry().voxel_count() * m];
    for (row, e) in fixed.chunks_mut(m).zip(channel.emission()) {
        row.iter_mut().for_each(|v| *v += e as f32);
    }
    if let Some(uncollided) = channel.uncollided {
        uncollided.project_first_collisions(
            channel.index,
            &channel.coefficients.sigma_s,
            m,
            &|d| ordinates.phase_from(d),
            &mut fixed,
        );
    }
    fixed
}

impl ChannelMethod for DomSolver {
    type Setup = Ordinates;

    fn stage(&self) -> &'static str {
        "source iteration"
    }

    /// The in-scattered radiance per storage direction (taken for the renderer) and the
    /// channel's record.
    type Extra = (Vec<f32>, DomChannel);

    fn memory_bytes(&self, problem: &Problem) -> u64 {
        let m = self
            .ordinates(problem.medium().phase)
            .map_or(0, |o| o.storage().len());
        // Beyond the iterate's two: GMRES keeps up to `restart` basis vectors and five
        // more (right-hand side, solution, the new direction, the image of the last
        // application, the restart's residual); mixing 2·depth + 2.
        let extra_vectors = match self.settings.outer {
            Outer::Gmres => self.settings.restart + 5,
            Outer::SourceIteration => 2 * self.settings.anderson + 2,
        };
        let n = problem.geometry().voxel_count();
        // The sweeps' work: in memory, or its page pool; on a device the work is the
        // device's, and the host holds the source it uploads (cells × N, f32).
        let work = match self.settings.paged_work {
            None if self.device.is_some() => self.work_bytes(problem) / 2,
            None => self.work_bytes(problem),
            Some(paged) => paged.pool_bytes.min(self.work_bytes(problem)),
        };
        // A truncated problem is a copy of the medium: an extinction and an albedo grid
        // per channel.
        let truncated = match self.truncation {
            Truncation::None => 0,
            _ => n * 8,
        };
        ((n * m * 4 * (3 + extra_vectors) + n * 40 + truncated) as u64 + work)
            * problem.channels() as u64
    }

    fn setup(&self, context: &Context<'_>) -> Result<Ordinates, SolveError> {
        self.ordinates(context.problem.medium().phase)
    }

    /// Point-like lights through their uncollided light (cell integrals, so that first
    /// collisions conserve each light's power, and `direct` at cell centres for the
    /// renderer); the sky and emission are the sweeps' own.
    fn route(&self, _: &Ordinates, _: &Problem, light: &Light) -> Route {
        if light.is_pointlike() {
            Route::Uncollided
        } else {
            Route::Own
        }
    }

    fn solve_channel(
        &self,
        ordinates: &Ordinates,
        channel: Channel<'_>,
    ) -> Result<ChannelSolution<Self::Extra>, SolveError> {
        let problem = channel.problem;
        let g = *problem.geometry();
        let c = channel.index;
        let sky = channel.sky_radiance();
        let fixed = first_sweep_source(&channel, ordinates);
        let Coefficients {
            sigma_t, sigma_s, ..
        } = channel.coefficients;
        // The capabilities refuse a Neumann flux other than 0.
        let reflectance = problem.boundary().diffuse_reflectance().unwrap_or(0.0);
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
        let solution = match &self.device {
            None => solve(&dom, ordinates, &self.settings, &channel.stopping),
            Some(Device(factory)) => factory().and_then(|device| {
                SourceIteration::on_device(&dom, ordinates, &self.settings, device)?
                    .run(&channel.stopping)
            }),
        }
        .map_err(|e| match e {
            DomError::Device(reason) => SolveError::Device {
                solver: self.name.into(),
                unavailable: false,
                reason,
            },
            DomError::Halted(halt) => SolveError::Halted {
                solver: self.name.into(),
                stage: "the first transport sweep".into(),
                halt,
            },
            e => invalid("problem", e.to_string()),
        })?;
        // The whole problem's balance: the sweeps' own (whose fixed source holds the first
        // collisions) plus the lights' uncollided power in, absorbed and out.
        let mut balance = solution.balance;
        let mut total = solution.fluence.clone();
        if let Some(uncollided) = channel.uncollided {
            for (t, u) in total.iter_mut().zip(uncollided.fluence(c)) {
                *t += u;
            }
            let (entering, escaped) = uncollided.balance_terms(c, &dom.sigma_s);
            balance.emitted += entering;
            balance.outflow += escaped;
        }
        let volume = g.cell_volume();
        balance.absorbed = total
            .iter()
            .zip(dom.sigma_t.iter().zip(&dom.sigma_s))
            .map(|(phi, (t, s))| phi * f64::from(t - s) * volume)
            .sum();
        let conv = solution.convergence;
        Ok(ChannelSolution {
            // The driver adds the uncollided fluence.
            fluence: solution.fluence.iter().map(|&v| v as f32).collect(),
            record: Record {
                iterations: conv.residuals.len(),
                residuals: conv.residuals.clone(),
                stop_reason: conv.stop_reason.clone(),
                memory_bytes: 0,
                paging: conv.work_paging,
            },
            extra: (
                solution.inscattered,
                DomChannel {
                    convergence: conv,
                    balance,
                },
            ),
        })
    }

    fn angular(
        &self,
        ordinates: &Ordinates,
        problem: &Problem,
        extras: &mut [Self::Extra],
        uncollided: Option<Uncollided>,
    ) -> Result<Option<Angular>, SolveError> {
        // `direct`'s per-light transmittance at cell centres for exact single scattering.
        let lights = uncollided.and_then(|u| match u.direct.angular {
            Some(Angular::Lights(l)) => Some(l),
            _ => None,
        });
        Ok(Some(Angular::Ordinates(OrdinateRadiance {
            directions: ordinates.storage().directions().to_vec(),
            kernel: ordinates.kernel(),
            inscattered: extras.iter_mut().map(|(s, _)| std::mem::take(s)).collect(),
            geometry: *problem.geometry(),
            lights,
        })))
    }
}
