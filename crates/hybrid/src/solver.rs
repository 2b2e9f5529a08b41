//! `hybrid` in the registry: the collision-order split of the crate docs as a
//! [`ChannelMethod`] (the driver sorts the lights and integrates their uncollided light).

use lucent_core::driver::{self, Channel, ChannelMethod, ChannelSolution, Coefficients, Context};
use lucent_core::{
    Angular, BoundaryKind, Capabilities, Composition, FluenceKind, Light, LightKind, OutputKind,
    Params, Part, Problem, Solution, SolveError, SolveOptions, Solver, SolverEntry, Uncollided,
    param_docs, resolved_params,
};
use lucent_diffusion::{CellGeometry, DiffusionProblem, Method, MultigridParams, Sources};
use lucent_dom::angular::Ordinates;
use lucent_dom::{Closure, DomBalance, DomBoundary, DomError, DomProblem, DomSettings};
use lucent_grid::Grid;
use lucent_optics::SphericalQuadrature;

use crate::params::HybridParams;

/// The whole problem's energy balance of one channel (W): what entered (the lights' power
/// entering the box or emitted in it, volumetric emission, the sky and the boundary's
/// reflection into the sweeps) against what was absorbed (Σ σ_a φ V over the returned
/// fluence) and what left the box (uncollided, swept and diffused light).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HybridBalance {
    /// The lights' power entering the box or emitted in it, and volumetric emission.
    pub emitted: f64,
    /// Entering the sweeps through the boundary: the sky and diffuse reflection.
    pub inflow: f64,
    /// Σ σ_a φ V over the total fluence.
    pub absorbed: f64,
    /// Leaving the box: uncollided, swept and (the diffusion part's exitance) diffused.
    pub outflow: f64,
}

impl HybridBalance {
    /// |emitted + inflow − absorbed − outflow| / (emitted + inflow).
    pub fn relative_imbalance(&self) -> f64 {
        let input = self.emitted + self.inflow;
        let residual = (input - self.absorbed - self.outflow).abs();
        if input > 0.0 {
            residual / input
        } else {
            residual
        }
    }
}

/// One channel's record of a [`HybridSolver::solve_with_details`] run.
#[derive(Debug, Clone, PartialEq)]
pub struct HybridChannel {
    /// Each sweep's own balance, order by order: its source's power (`emitted`), the
    /// boundary's (`inflow`), the power that collides in it (`absorbed`: the sweeps do not
    /// scatter, so every collision counts) and what leaves the box.
    pub sweeps: Vec<DomBalance>,
    /// After each sweep, the power of the next order's source handed to diffusion (W): 0
    /// but after the last sweep (`orders`, or the first whose scattered power is below the
    /// solve's relative tolerance of the first order's). The next sweep's source and this
    /// add up to the scattered part of the sweep's collisions.
    pub handed: Vec<f64>,
    /// The diffusion part's balance: the power of the source handed to it (the scattered
    /// part of the last sweep's collisions) against what it absorbs and lets escape.
    pub diffusion: lucent_diffusion::Balance,
    /// Transport sweeps run, over all orders (one per order, more where a reflecting
    /// boundary makes an order iterate).
    pub sweeps_run: usize,
    /// V-cycles of the diffusion part.
    pub cycles: usize,
    /// Share of the scattered power that diffusion carried: the diffusion source's power
    /// over the first sweep's source and inflow (0: the sweeps carried everything).
    pub diffused_share: f64,
    /// The whole problem's balance.
    pub balance: HybridBalance,
}

/// `hybrid`: uncollided light exact, `orders` scattering orders by transport sweeps,
/// the rest by multigrid diffusion (the crate docs).
#[derive(Debug, Clone, PartialEq)]
pub struct HybridSolver {
    order: usize,
    orders: usize,
    settings: DomSettings,
}

impl Default for HybridSolver {
    fn default() -> Self {
        Self::from_hybrid_params(HybridParams::default())
    }
}

fn invalid(name: &str, reason: impl Into<String>) -> SolveError {
    SolveError::InvalidParameter {
        name: name.into(),
        reason: reason.into(),
    }
}

fn dom_error(e: DomError) -> SolveError {
    match e {
        DomError::Halted(halt) => SolveError::Halted {
            solver: "hybrid".into(),
            stage: "a scattering order's sweep".into(),
            halt,
        },
        e => invalid("problem", e.to_string()),
    }
}

impl HybridSolver {
    /// The registry entry ([`HybridParams`]).
    pub const ENTRY: SolverEntry = SolverEntry {
        name: "hybrid",
        summary: "uncollided light exact, first scattering orders by transport sweeps, the rest by multigrid diffusion",
        build: |p: &Params| Ok(Box::new(HybridSolver::from_params(p)?)),
        params: param_docs::<HybridParams>,
        resolved: |p| resolved_params::<HybridParams>(p, "hybrid"),
    };

    /// The solver for registry parameters.
    pub fn from_params(p: &Params) -> Result<Self, SolveError> {
        let params: HybridParams = p.parse("hybrid")?;
        Ok(Self::from_hybrid_params(params))
    }

    /// The solver for validated parameters.
    fn from_hybrid_params(p: HybridParams) -> Self {
        Self {
            order: p.order,
            orders: p.orders,
            settings: DomSettings {
                closure: p.closure,
                block: p.block,
                // The sweeps do not scatter: nothing to accelerate or mix.
                acceleration: lucent_dom::Acceleration::None,
                anderson: 0,
                ..DomSettings::default()
            },
        }
    }

    /// This solver with `orders` scattering orders swept (1 to 64).
    pub fn with_orders(self, orders: usize) -> Result<Self, SolveError> {
        HybridParams {
            orders,
            ..self.params()
        }
        .validate_into()
    }

    /// This solver with the sweeps' S_N `order` (even, 2 to 16).
    pub fn with_order(self, order: usize) -> Result<Self, SolveError> {
        HybridParams {
            order,
            ..self.params()
        }
        .validate_into()
    }

    /// This solver with the sweeps' `closure`.
    pub fn with_closure(self, closure: Closure) -> Self {
        Self {
            settings: DomSettings {
                closure,
                ..self.settings
            },
            ..self
        }
    }

    fn params(&self) -> HybridParams {
        HybridParams {
            order: self.order,
            closure: self.settings.closure,
            orders: self.orders,
            block: self.settings.block,
        }
    }

    /// The angular sets for `phase`: the S_N set, stored on itself.
    fn ordinates(&self, phase: lucent_optics::Phase) -> Result<Ordinates, SolveError> {
        let set = SphericalQuadrature::level_symmetric(self.order)
            .map_err(|e| invalid("order", e.to_string()))?;
        Ordinates::new(set, None, phase).map_err(|e| invalid("order", e.to_string()))
    }

    /// [`Solver::solve`], also returning each channel's balances and how much the
    /// diffusion part carried.
    pub fn solve_with_details(
        &self,
        problem: &Problem,
        options: &SolveOptions,
    ) -> Result<(Solution, Vec<HybridChannel>), SolveError> {
        let (mut solution, extras) = driver::solve_per_channel(self, self, problem, options)?;
        let channels: Vec<HybridChannel> = extras.into_iter().map(|(_, c)| c).collect();
        let composition = self.composition(problem, &channels);
        solution.report.choice = Some(describe(&composition));
        solution.report.composition = Some(composition);
        Ok((solution, channels))
    }

    /// The report's fields for a solve whose channels went as `channels`: the uncollided
    /// light (where a point-like light has one), the orders swept and the diffused rest,
    /// each with its iterations; the rest with its source's power over the first order's
    /// (the largest over channels).
    fn composition(&self, problem: &Problem, channels: &[HybridChannel]) -> Composition {
        let json = |v: serde_json::Result<serde_json::Value>| v.unwrap_or(serde_json::Value::Null);
        let params = self.params();
        let swept = channels.iter().map(|c| c.sweeps.len()).max().unwrap_or(0);
        let diffused = channels
            .iter()
            .map(|c| c.diffused_share)
            .fold(0.0f64, f64::max);
        let mut parts = Vec::new();
        if problem.lights().iter().any(Light::is_pointlike) {
            parts.push(Part {
                computes: "uncollided light".into(),
                method: "direct's exact cell integrals".into(),
                params: serde_json::Value::Object(Default::default()),
                iterations: 0,
                share: None,
            });
        }
        parts.push(Part {
            computes: match swept {
                1 => "scattering order 1".into(),
                k => format!("scattering orders 1-{k}"),
            },
            method: format!("S{} transport sweeps, one order each", params.order),
            // Every one of `hybrid`'s own parameters is the sweeps'.
            params: json(serde_json::to_value(params)),
            iterations: channels.iter().map(|c| c.sweeps_run).sum(),
            share: None,
        });
        parts.push(Part {
            computes: "the rest".into(),
            method: "diffusion-mg".into(),
            params: json(serde_json::to_value(MultigridParams::default())),
            iterations: channels.iter().map(|c| c.cycles).sum(),
            share: Some(diffused),
        });
        Composition {
            solver: "hybrid".into(),
            params: json(serde_json::to_value(params)),
            parts,
            decision: None,
        }
    }
}

/// `composition` in one line for people.
fn describe(composition: &Composition) -> String {
    let parts: Vec<String> = composition
        .parts
        .iter()
        .map(|p| {
            let share = p.share.map_or(String::new(), |s| {
                format!(", its source {:.1} % of the first order's", 100.0 * s)
            });
            format!(
                "{} by {} ({} iterations{share})",
                p.computes, p.method, p.iterations
            )
        })
        .collect();
    format!("hybrid ran {}", parts.join("; "))
}

impl HybridParams {
    fn validate_into(self) -> Result<HybridSolver, SolveError> {
        lucent_core::SolverParams::validate(&self)?;
        Ok(HybridSolver::from_hybrid_params(self))
    }
}

impl Solver for HybridSolver {
    fn name(&self) -> &str {
        "hybrid"
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

/// Σ_m w_m s_m and Σ_m w_m ω_m s_m of one cell's source row `s` on `set`.
fn moments(set: &SphericalQuadrature, row: &[f32]) -> (f64, glam::DVec3) {
    let mut zeroth = 0.0;
    let mut first = glam::DVec3::ZERO;
    for ((s, w), d) in row.iter().zip(set.weights()).zip(set.directions()) {
        let ws = w * f64::from(*s);
        zeroth += ws;
        first += *d * ws;
    }
    (zeroth, first)
}

impl ChannelMethod for HybridSolver {
    type Setup = Ordinates;
    /// The scattered fluence (sweeps and diffusion, for the renderer) and the record.
    type Extra = (Grid, HybridChannel);

    fn stage(&self) -> &'static str {
        "sweep and V-cycle"
    }

    fn memory_bytes(&self, problem: &Problem) -> u64 {
        let n = problem.geometry().voxel_count() as u64;
        let directions = (self.order * (self.order + 2)) as u64;
        // Per cell: the sweep's source, its in-scattered radiance and the next order's
        // source (f32 per direction), the sweep's work (f64 per direction), and the
        // diffusion part's operator and work vectors as `diffusion-mg` counts them.
        let sweep = directions * (3 * 4 + 8) + 40;
        let diffusion = 4 * 14 + 8 * 4 + 24;
        n * (sweep + diffusion) * problem.channels() as u64
    }

    fn setup(&self, context: &Context<'_>) -> Result<Ordinates, SolveError> {
        self.ordinates(context.problem.medium().phase)
    }

    /// Point-like lights through their uncollided light (exact, conservative cell
    /// integrals); the sky and emission are the first sweep's own.
    fn route(&self, _: &Ordinates, _: &Problem, light: &Light) -> driver::Route {
        if light.is_pointlike() {
            driver::Route::Uncollided
        } else {
            driver::Route::Own
        }
    }

    fn solve_channel(
        &self,
        ordinates: &Ordinates,
        channel: Channel<'_>,
    ) -> Result<ChannelSolution<Self::Extra>, SolveError> {
        let problem = channel.problem;
        let geometry = *problem.geometry();
        let n = geometry.voxel_count();
        let set = ordinates.storage();
        let m = set.len();
        let c = channel.index;
        // Order 1's source: emission (isotropic) and the lights' first collisions,
        // projected onto the directions with the discrete phase function, as `dom`'s.
        let sky = channel.sky_radiance();
        let fixed = lucent_dom::first_sweep_source(&channel, ordinates);
        let Coefficients {
            sigma_t,
            sigma_s,
            sigma_a,
            diffusion: d,
        } = channel.coefficients;
        // The capabilities refuse a Neumann flux other than 0.
        let reflectance = problem.boundary().diffuse_reflectance().unwrap_or(0.0);
        let mut streaming = DomProblem {
            geometry,
            sigma_t,
            // The sweeps carry one order each: no scattering inside them.
            sigma_s: vec![0.0; n],
            fixed,
            boundary: DomBoundary {
                radiance: sky,
                reflectance,
            },
        };
        let mut swept = vec![0.0f64; n];
        let mut sweeps = Vec::with_capacity(self.orders);
        let mut handed = Vec::with_capacity(self.orders);
        let mut sweeps_run = 0;
        let mut unconverged = None;
        let volume = geometry.cell_volume();
        // The diffusion part's source, gathered order by order.
        let mut q0 = vec![0.0f64; n];
        let mut q1 = vec![glam::DVec3::ZERO; n];
        let mut first_input = 0.0;
        for order in 1..=self.orders {
            let solution =
                lucent_dom::solve(&streaming, ordinates, &self.settings, &channel.stopping)
                    .map_err(dom_error)?;
            // Only a reflecting boundary makes a sweep iterate (on the light it sends back
            // in); a sweep that stopped short of its tolerance is the solve's stop.
            let stop = &solution.convergence.stop_reason;
            if !stop.is_converged() {
                unconverged = Some(driver::Record::from_residuals(
                    solution.convergence.residuals.clone(),
                    stop.clone(),
                    0,
                ));
            }
            sweeps_run += solution.convergence.sweeps;
            for (s, v) in swept.iter_mut().zip(&solution.fluence) {
                *s += v;
            }
            if order == 1 {
                first_input = solution.balance.emitted + solution.balance.inflow;
            }
            sweeps.push(solution.balance);
            // The next order's source: σ_s times the in-scattered radiance toward each
            // direction (the discrete phase matrix conserves the scattered power).
            let mut power = 0.0;
            for ((row, inscattered), s) in streaming
                .fixed
                .chunks_mut(m)
                .zip(solution.inscattered.chunks(m))
                .zip(&sigma_s)
            {
                for (f, i) in row.iter_mut().zip(inscattered) {
                    *f = s * i;
                }
                power += moments(set, row).0 * volume;
            }
            // The sky enters once.
            streaming.boundary.radiance = 0.0;
            // After the last order, or once what is left is below the tolerance of the
            // first order's power, diffusion takes the rest.
            let done =
                order == self.orders || power <= channel.stopping.relative_tolerance * first_input;
            if done {
                for (cell, row) in streaming.fixed.chunks(m).enumerate() {
                    let (zeroth, first) = moments(set, row);
                    q0[cell] += zeroth;
                    q1[cell] += first;
                }
                handed.push(power);
                break;
            }
            handed.push(0.0);
        }
        let q0: Vec<f32> = q0.iter().map(|&v| v as f32).collect();
        let q1: Vec<[f32; 3]> = q1.iter().map(|v| v.as_vec3().to_array()).collect();
        let cells = CellGeometry::full_box(geometry);
        let tail = DiffusionProblem::new(
            cells,
            d,
            sigma_a.clone(),
            lucent_diffusion::conditions(problem.boundary()),
        )
        .map_err(|e| invalid("problem", e.to_string()))?;
        let sources = Sources {
            volumetric: q0,
            first_moment: q1,
            points: Vec::new(),
        };
        let diffused = lucent_diffusion::solve(
            &tail,
            &sources,
            Method::Multigrid(MultigridParams::default().settings()),
            &channel.stopping,
        )
        .map_err(|e| invalid("problem", e.to_string()))?;
        let scattered: Vec<f32> = swept
            .iter()
            .zip(&diffused.fluence)
            .map(|(s, t)| (s + t) as f32)
            .collect();

        // The whole problem's balance, as `dom` keeps it: the lights' power that enters
        // the box replaces the first collisions' scattered part in what was emitted.
        let mut balance = HybridBalance {
            emitted: sweeps.first().map_or(0.0, |b| b.emitted),
            inflow: sweeps.iter().map(|b| b.inflow).sum(),
            absorbed: 0.0,
            outflow: sweeps.iter().map(|b| b.outflow).sum::<f64>()
                + diffused.balance.escaped_box
                + diffused.balance.escaped_surface,
        };
        let mut total: Vec<f64> = scattered.iter().map(|&v| f64::from(v)).collect();
        if let Some(uncollided) = channel.uncollided {
            for (t, u) in total.iter_mut().zip(uncollided.fluence(c)) {
                *t += u;
            }
            let (entering, escaped) = uncollided.balance_terms(c, &sigma_s);
            balance.emitted += entering;
            balance.outflow += escaped;
        }
        balance.absorbed = total
            .iter()
            .zip(&sigma_a)
            .map(|(phi, a)| phi * f64::from(*a) * volume)
            .sum();
        let diffused_share = if first_input > 0.0 {
            diffused.balance.emitted / first_input
        } else {
            0.0
        };
        let conv = diffused.convergence;
        let cycles = conv.residuals.len().saturating_sub(1);
        let mut record = driver::Record::from_residuals(
            conv.residuals.clone(),
            conv.stop_reason.clone(),
            diffused.memory_bytes,
        );
        if let Some(sweep) = unconverged {
            record = record.worse(sweep);
        }
        record.iterations = cycles + sweeps_run;
        let fluence_grid = Grid::from_vec(geometry, scattered.clone())?;
        Ok(ChannelSolution {
            // The driver adds the uncollided fluence.
            fluence: scattered,
            record,
            extra: (
                fluence_grid,
                HybridChannel {
                    sweeps,
                    handed,
                    diffusion: diffused.balance,
                    sweeps_run,
                    cycles,
                    diffused_share,
                    balance,
                },
            ),
        })
    }

    /// `direct`'s per-light transmittance for exact single scattering in the renderer,
    /// and the scattered fluence in-scattering isotropically (as the diffusion solvers
    /// give it).
    fn angular(
        &self,
        _: &Ordinates,
        _: &Problem,
        extras: &mut [Self::Extra],
        uncollided: Option<Uncollided>,
    ) -> Result<Option<Angular>, SolveError> {
        let mut scattered: Vec<Grid> = extras
            .iter_mut()
            .map(|(g, _)| std::mem::replace(g, Grid::filled(*g.geometry(), 0.0)))
            .collect();
        Ok(uncollided.and_then(|u| u.into_angular(&mut scattered)))
    }
}
