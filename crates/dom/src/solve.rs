//! Source iteration: sweep with the previous in-scattered radiance, rebuild it from the new
//! radiance, optionally accelerate with diffusion, until the scattering source stops
//! changing.

use std::borrow::Cow;
use std::time::Instant;

use lucent_core::StopReason;
use lucent_core::Stopping;
use lucent_grid::GridGeometry;

use rayon::prelude::*;

use crate::anderson::Anderson;
use crate::angular::Ordinates;
use crate::closure::{
    CellDirection, Closure, DiamondClosure, ExponentialClosure, LinearDiamondClosure,
    LinearExponentialClosure, StepClosure,
};
use crate::device::{DeviceTransport, TransportOutput, TransportSetup, TransportStep};
use crate::dsa::Dsa;
use crate::error::DomError;
use crate::gmres::{GmresStep, Iterate, Space, gmres};
use crate::sweep::{CellSource, Layout, SweepInput, SweepOutput, WorkPages, sweep, sweep_paged};

/// Relative source changes below this are near the resolution of f32 storage (32 ε):
/// there the ratio of successive changes is rounding noise, so the contraction measured
/// above it is kept.
const STORAGE_FLOOR: f64 = 32.0 * f32::EPSILON as f64;

/// Incoming light at the domain's faces.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DomBoundary {
    /// Radiance arriving from outside, the same in every inward direction (a uniform
    /// sky; 0 for vacuum), per steradian.
    pub radiance: f64,
    /// Fraction R ∈ [0, 1] of the outgoing partial current sent back in, diffusely
    /// (Lambertian): the internal diffuse reflectance of a mismatched surface (a
    /// Robin-like condition; 0 for vacuum, 1 for a reflecting box).
    pub reflectance: f64,
}

/// A discrete-ordinates problem on a grid, one channel.
#[derive(Debug, Clone, PartialEq)]
pub struct DomProblem {
    /// The grid.
    pub geometry: GridGeometry,
    /// Extinction σ_t per cell (1/length).
    pub sigma_t: Vec<f32>,
    /// Scattering σ_s ≤ σ_t per cell (1/length).
    pub sigma_s: Vec<f32>,
    /// Fixed source per cell and storage direction (power/length³/sr): the first-collision
    /// source of the lights and any emission. Grid order, storage direction fastest.
    pub fixed: Vec<f32>,
    /// The boundary.
    pub boundary: DomBoundary,
}

/// Iteration acceleration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Acceleration {
    /// Plain source iteration (one scattering order per sweep).
    None,
    /// Diffusion synthetic acceleration with `lucent-diffusion`'s multigrid.
    #[default]
    Dsa,
    /// Transport synthetic acceleration of the isotropic and first moments: after each
    /// sweep the error is estimated by an S2 problem (the eight level-symmetric S2
    /// directions, the same phase function matched to its mean cosine g) driven by the
    /// sweep's residual source projected onto P0 and P1, itself solved by
    /// `tsa_sweeps` DSA-accelerated sweeps from zero (a fixed linear map, so a valid
    /// GMRES preconditioner). DSA corrects the isotropic error only, and the first
    /// moments' error is left to contract by about ωg per sweep; S2 carries a current.
    /// Refused where a cell is thicker than σ_t h = 4 (measured to slow or stall there).
    Tsa,
}

/// The outer iteration on the scattering source.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Outer {
    /// Source iteration: one sweep per step, the DSA correction and Anderson mixing (when
    /// set) after it, with the safeguards that drop DSA where it amplifies the error. The
    /// default: with diamond difference (the default closure) it needs fewer sweeps than
    /// GMRES, whose answer the fix-up then has to settle (tests/it/krylov.rs).
    #[default]
    SourceIteration,
    /// Restarted GMRES on the DSA-preconditioned fixed point (the `gmres` module's docs):
    /// one sweep per Krylov iteration, plus one for the right-hand side and one per
    /// restart, with the closure's linear form; then source iteration (with the fix-up,
    /// DSA and mixing as set) from the Krylov solution to the tolerance.
    Gmres,
}

/// How to solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DomSettings {
    /// The outer iteration.
    pub outer: Outer,
    /// GMRES restart length (Krylov vectors kept, each the size of the stored in-scattered
    /// radiance, f32).
    pub restart: usize,
    /// Spatial closure.
    pub closure: Closure,
    /// Acceleration.
    pub acceleration: Acceleration,
    /// Sweeps of the S2 problem per application of [`Acceleration::Tsa`], from zero (each
    /// 8 directions and a DSA correction of three V-cycles).
    pub tsa_sweeps: usize,
    /// Anderson mixing depth on top of the (accelerated) iteration; 0 turns it off. It
    /// starts only once the iteration contracts by more than 0.3 per sweep, and then costs
    /// 2·depth + 2 vectors of the stored in-scattered radiance (f32).
    pub anderson: usize,
    /// Block edge of the wavefront (cells).
    pub block: usize,
    /// Where the sweeps' per-direction work (cells × propagation directions, f64: the
    /// solver's largest array) lives: in memory (`None`), or in a pager of f64 pages
    /// backed by a temporary file, one page per octant and block.
    pub paged_work: Option<PagedWork>,
}

/// The sweeps' work out of core: a pool of `pool_bytes` (at least
/// [`SourceIteration::min_work_pages`] pages) under `eviction`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PagedWork {
    /// Bytes of the page pool.
    pub pool_bytes: u64,
    /// Which page leaves the pool.
    pub eviction: lucent_paging::Eviction,
}

impl Default for DomSettings {
    fn default() -> Self {
        Self {
            outer: Outer::default(),
            restart: 12,
            closure: Closure::default(),
            acceleration: Acceleration::default(),
            tsa_sweeps: 2,
            anderson: 2,
            block: 16,
            paged_work: None,
        }
    }
}

/// Where the sweeps' per-direction work lives.
#[derive(Debug)]
enum Work {
    /// Octant-major in memory: per octant, per block, cells × the octant's directions.
    Memory(Vec<f64>),
    /// The same chunks as pages.
    Paged(WorkPages),
}

/// Energy accounting of a solve (power): at convergence
/// emitted + inflow = absorbed + outflow.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DomBalance {
    /// Emitted by the fixed source.
    pub emitted: f64,
    /// Entering through the boundary (sky and diffuse reflection).
    pub inflow: f64,
    /// Absorbed, Σ σ_a φ V.
    pub absorbed: f64,
    /// Leaving through the boundary.
    pub outflow: f64,
}

impl DomBalance {
    /// |emitted + inflow − absorbed − outflow| / (emitted + inflow).
    pub fn relative_imbalance(&self) -> f64 {
        let input = self.emitted + self.inflow;
        if input == 0.0 {
            return (self.absorbed + self.outflow).abs();
        }
        (input - self.absorbed - self.outflow).abs() / input
    }
}

/// How the iteration went.
#[derive(Debug, Clone, PartialEq)]
pub struct DomConvergence {
    /// Relative change of the scattering source after each sweep.
    pub residuals: Vec<f64>,
    /// Why it stopped.
    pub stop_reason: StopReason,
    /// The measured contraction per sweep: the geometric mean of the last five ratios of
    /// successive changes (the spectral radius of source iteration once its slowest mode
    /// dominates), or with Anderson mixing the largest of the last three measured
    /// ‖G(x_k) − G(x_{k−1})‖/‖x_k − x_{k−1}‖ of the unmixed iteration G.
    pub spectral_radius: f64,
    /// Sweeps run.
    pub sweeps: usize,
    /// Wall time of the sweeps alone (s).
    pub sweep_seconds: f64,
    /// Wall time of the source interpolation and scattering products (s).
    pub scatter_seconds: f64,
    /// Wall time of the DSA solves, or with TSA of its S2 problems (s).
    pub dsa_seconds: f64,
    /// Wall time of the Anderson mixing (s).
    pub anderson_seconds: f64,
    /// Wall time of GMRES's vector work (orthogonalisation, combinations, copies of the
    /// iterate) outside the sweeps, products and DSA it calls (s).
    pub krylov_seconds: f64,
    /// Of `sweep_seconds`, the time a device spent in its transport kernels (0 on the
    /// host): the rest is the transfers of the in-scattered radiance.
    pub device_seconds: f64,
    /// Of `device_seconds`, the device's scattering products (0 on the host).
    pub device_scatter_seconds: f64,
    /// The sweep after which DSA (or TSA) was dropped because it amplified the error
    /// (thick cells), if it was.
    pub dsa_abandoned: Option<usize>,
    /// Sweeps of the S2 problem of [`Acceleration::Tsa`] (8 directions each), not
    /// counted in `sweeps`.
    pub low_order_sweeps: usize,
    /// What the pager of the sweeps' work did, when the work was paged.
    pub work_paging: Option<lucent_paging::PagerStats>,
}

/// The solution of one channel.
#[derive(Debug, Clone, PartialEq)]
pub struct DomSolution {
    /// Scalar flux φ = Σ w ψ̄ per cell (grid order; W/length² for the light the sweeps
    /// carry).
    pub fluence: Vec<f64>,
    /// In-scattered radiance per unit σ_s toward each storage direction,
    /// Σ_n w_n p̄(ω_n → ω_m) ψ̄_n, per cell (grid order, storage direction fastest).
    pub inscattered: Vec<f32>,
    /// Convergence history.
    pub convergence: DomConvergence,
    /// Energy balance.
    pub balance: DomBalance,
}

fn validate(problem: &DomProblem, m: usize) -> Result<(), DomError> {
    let n = problem.geometry.voxel_count();
    let bad = |s: String| Err(DomError::Invalid(s));
    if problem.sigma_t.len() != n || problem.sigma_s.len() != n || problem.fixed.len() != n * m {
        return bad(format!(
            "{n} cells and {m} storage directions, but {} σ_t, {} σ_s and {} source values",
            problem.sigma_t.len(),
            problem.sigma_s.len(),
            problem.fixed.len()
        ));
    }
    for (c, (&t, &s)) in problem.sigma_t.iter().zip(&problem.sigma_s).enumerate() {
        if !(t.is_finite() && s.is_finite() && t >= 0.0 && s >= 0.0 && s <= t * (1.0 + 1e-6)) {
            return bad(format!(
                "cell {c}: σ_t = {t}, σ_s = {s}; 0 ≤ σ_s ≤ σ_t, finite"
            ));
        }
    }
    if let Some(v) = problem
        .fixed
        .iter()
        .find(|v| !(v.is_finite() && **v >= 0.0))
    {
        return bad(format!("source value {v}: finite and ≥ 0"));
    }
    let b = problem.boundary;
    if !(b.radiance.is_finite() && b.radiance >= 0.0 && (0.0..=1.0).contains(&b.reflectance)) {
        return bad(format!("boundary {b:?}: radiance ≥ 0, 0 ≤ R ≤ 1"));
    }
    Ok(())
}

/// Solves `problem` on `ordinates`: [`SourceIteration`] run to `stopping`.
pub fn solve(
    problem: &DomProblem,
    ordinates: &Ordinates,
    settings: &DomSettings,
    stopping: &Stopping,
) -> Result<DomSolution, DomError> {
    SourceIteration::new(problem, ordinates, settings)?.run(stopping)
}

/// What [`SourceIteration::sweep_only`] measured.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepOnly {
    /// Scalar flux Σ w ψ̄ of the sweep per cell (grid order).
    pub fluence: Vec<f64>,
    /// Power leaving through the boundary.
    pub outflow_power: f64,
    /// Wall time of the sweep alone (s).
    pub seconds: f64,
    /// What the pager did during the sweep (paged work only).
    pub pager: Option<lucent_paging::PagerStats>,
}

/// Wall time per step of the iteration (s).
#[derive(Debug, Clone, Copy, Default)]
struct Timings {
    sweep: f64,
    scatter: f64,
    dsa: f64,
    anderson: f64,
    krylov: f64,
    device: f64,
    device_scatter: f64,
}

/// What the iteration has seen: the changes, the measured contraction, and the state of
/// the safeguards (DSA dropped when it amplifies the error, mixing once the iteration
/// contracts slowly).
#[derive(Debug, Clone, Default)]
struct Monitor {
    residuals: Vec<f64>,
    spectral_radius: f64,
    first_change: Option<f64>,
    best_change: f64,
    last_improvement: usize,
    contractions: Vec<f64>,
    mixing: bool,
    dsa_abandoned: Option<usize>,
    low_order_sweeps: usize,
}

/// Source iteration on one channel, as a value whose steps are separate: `transport`
/// (the source at the propagation directions, one sweep, the in-scattered radiance; what a
/// GPU sweep replaces), `accelerate` (the diffusion correction; what a Krylov
/// acceleration replaces), the change of the source, and Anderson mixing. [`Self::run`]
/// is the loop that joins them with the stopping rule and the safeguards.
pub struct SourceIteration<'a> {
    /// Borrowed from the caller; owned by the low-order iteration of TSA.
    ordinates: Cow<'a, Ordinates>,
    settings: DomSettings,
    boundary: DomBoundary,
    layout: Layout,
    spacing: [f64; 3],
    /// Per propagation direction.
    geometry: Vec<CellDirection>,
    /// Block order, as are all per-cell arrays below.
    sigma_t: Vec<f32>,
    sigma_s: Vec<f32>,
    fixed: Vec<f32>,
    scattering: ndarray::Array2<f64>,
    interpolation: Option<ndarray::Array2<f64>>,
    octants: Vec<(usize, usize)>,
    half_range: [f64; 3],
    isotropic: Vec<f64>,
    scatters: bool,
    reflects: bool,
    /// The in-scattered radiance the last sweep started from, and the one it produced.
    previous: Vec<f32>,
    inscattered: Vec<f32>,
    /// Cell-average radiance per propagation direction, kept in f64 between the sweep and
    /// the scattering product: at albedo 0.99 light scatters ~100 times, so rounding in
    /// the in-scattered energy is amplified that much in the balance.
    work: Work,
    inflow: [Vec<f64>; 6],
    /// Sweep without the fixed source and the sky (Krylov operator applications).
    homogeneous: bool,
    /// Sweep with the closure's linear form (no positivity fix-up): the Krylov phase.
    linear: bool,
    dsa: Option<Dsa>,
    /// DSA as a fixed number of V-cycles from zero (a linear map, inside GMRES and TSA),
    /// or `None`: to its tolerance.
    fixed_dsa_cycles: Option<usize>,
    /// The S2 iteration of [`Acceleration::Tsa`] (whose own `dsa` corrects it).
    tsa: Option<Box<SourceIteration<'static>>>,
    anderson: Option<Anderson>,
    /// Where the transport steps run when not on the host.
    device: Option<Box<dyn DeviceTransport>>,
    timings: Timings,
    monitor: Monitor,
    /// Ctrl-C and the time limit of the run, asked by every sweep's wavefronts.
    interrupt: lucent_core::Interrupt,
}

impl<'a> SourceIteration<'a> {
    /// The iteration's operators and its state before the first sweep (zero scattering
    /// source).
    pub fn new(
        problem: &DomProblem,
        ordinates: &'a Ordinates,
        settings: &'a DomSettings,
    ) -> Result<Self, DomError> {
        Self::build(problem, Cow::Borrowed(ordinates), settings, false)
    }

    /// The same iteration with its transport steps on `device` (a GPU: the module
    /// [`crate::device`]), which receives the iteration's fixed data here. The storage
    /// directions must be the propagation directions and the work in memory.
    pub fn on_device(
        problem: &DomProblem,
        ordinates: &'a Ordinates,
        settings: &'a DomSettings,
        mut device: Box<dyn DeviceTransport>,
    ) -> Result<Self, DomError> {
        if ordinates.interpolation().is_some() {
            return Err(DomError::Invalid(
                "a device sweeps the storage directions: storage_level is not supported".into(),
            ));
        }
        if settings.paged_work.is_some() {
            return Err(DomError::Invalid(
                "a device holds the sweeps' work itself: paged work is not supported".into(),
            ));
        }
        let mut iteration = Self::build(problem, Cow::Borrowed(ordinates), settings, true)?;
        let directions: Vec<[f64; 3]> = ordinates
            .propagation()
            .directions()
            .iter()
            .map(|d| d.to_array())
            .collect();
        let scattering: Vec<f64> = iteration.scattering.iter().copied().collect();
        let octants: [(usize, usize); 8] = std::array::from_fn(|o| {
            let d = ordinates.octant(o);
            (d.first().copied().unwrap_or(0), d.len())
        });
        device.prepare(&TransportSetup {
            layout: &iteration.layout,
            spacing: iteration.spacing,
            directions: &directions,
            weights: ordinates.propagation().weights(),
            octants,
            sigma_t: &iteration.sigma_t,
            scattering: &scattering,
            closure: settings.closure,
        })?;
        iteration.device = Some(device);
        Ok(iteration)
    }

    fn build(
        problem: &DomProblem,
        ordinates: Cow<'a, Ordinates>,
        settings: &DomSettings,
        on_device: bool,
    ) -> Result<Self, DomError> {
        let m = ordinates.storage().len();
        validate(problem, m)?;
        if settings.block == 0 {
            return Err(DomError::Invalid("block size 0".into()));
        }
        if settings.acceleration == Acceleration::Tsa && settings.tsa_sweeps == 0 {
            return Err(DomError::Invalid(
                "TSA with 0 sweeps of its S2 problem".into(),
            ));
        }
        if settings.outer == Outer::Gmres && settings.restart == 0 {
            return Err(DomError::Invalid("GMRES restart length 0".into()));
        }
        let g = problem.geometry;
        let dims = g.dims();
        let h = g.spacing().to_array();
        let layout = Layout::new(dims, settings.block);
        let boundary = problem.boundary;
        let scatters = problem.sigma_s.iter().any(|&s| s > 0.0);
        let dsa = match settings.acceleration {
            Acceleration::Dsa if scatters => Dsa::new(
                g,
                &problem.sigma_t,
                &problem.sigma_s,
                ordinates.effective_g(),
                boundary.reflectance,
            )?,
            _ => None,
        };
        if settings.acceleration == Acceleration::Tsa {
            let thickest = problem.sigma_t.iter().fold(0.0f32, |a, &t| a.max(t));
            let tau = f64::from(thickest) * h.iter().fold(0.0f64, |a, &v| a.max(v));
            if tau > TSA_MAX_CELL_THICKNESS {
                return Err(DomError::Invalid(format!(
                    "acceleration = \"tsa\" in cells up to σ_t h = {tau:.3}: beyond σ_t h = {TSA_MAX_CELL_THICKNESS} its S2 problem's DSA is inconsistent with the sweeps and the iteration slows or stops (measured); use dsa, which source iteration drops where it fails, or gmres"
                )));
            }
        }
        let tsa = match settings.acceleration {
            Acceleration::Tsa if scatters => {
                Some(Box::new(Self::low_order(problem, &ordinates, settings)?))
            }
            _ => None,
        };
        let n_dirs = ordinates.propagation().len();
        let matrix = |v: &[f64], rows: usize, cols: usize| {
            ndarray::Array2::from_shape_vec((rows, cols), v.to_vec())
                .map_err(|e| DomError::Invalid(e.to_string()))
        };
        let interpolation = match ordinates.interpolation() {
            None => None,
            Some(w) => Some(
                matrix(w, n_dirs, m)?
                    .reversed_axes()
                    .as_standard_layout()
                    .into_owned(),
            ),
        };
        let sigma_s = layout.to_blocks(&problem.sigma_s, 1);
        let anderson = (settings.anderson > 0 && scatters).then(|| {
            Anderson::new(
                settings.anderson,
                sigma_s.iter().map(|s| s * s).collect(),
                ordinates
                    .storage()
                    .weights()
                    .iter()
                    .map(|w| *w as f32)
                    .collect(),
            )
        });
        Ok(Self {
            settings: *settings,
            boundary,
            geometry: ordinates
                .propagation()
                .directions()
                .iter()
                .map(|d| CellDirection::new(d.to_array(), h))
                .collect(),
            sigma_t: layout.to_blocks(&problem.sigma_t, 1),
            sigma_s,
            fixed: layout.to_blocks(&problem.fixed, m),
            scattering: matrix(ordinates.scattering(), n_dirs, m)?,
            interpolation,
            // Each octant's (first direction, count): contiguous by construction.
            octants: (0..8)
                .map(|o| ordinates.octant(o))
                .filter(|d| !d.is_empty())
                .map(|d| (d[0], d.len()))
                .collect(),
            half_range: std::array::from_fn(|a| {
                ordinates
                    .propagation()
                    .directions()
                    .iter()
                    .zip(ordinates.propagation().weights())
                    .filter(|(d, _)| d[a] > 0.0)
                    .map(|(d, w)| w * d[a])
                    .sum::<f64>()
                    .max(f64::MIN_POSITIVE)
            }),
            isotropic: ordinates.isotropic_inscatter(),
            scatters,
            reflects: boundary.reflectance > 0.0,
            previous: vec![0.0; layout.cells() * m],
            inscattered: vec![0.0; layout.cells() * m],
            work: match settings.paged_work {
                None if on_device => Work::Memory(Vec::new()),
                None => Work::Memory(vec![0.0; layout.cells() * n_dirs]),
                Some(paged) => {
                    let len = WorkPages::page_len(&layout, &ordinates);
                    let store = lucent_paging::FileStore::create()?;
                    let pager = lucent_paging::Pager::new(
                        Box::new(store),
                        0,
                        len,
                        Self::min_work_pages(),
                        lucent_paging::PagerOptions {
                            budget_bytes: paged.pool_bytes,
                            eviction: paged.eviction,
                            fill: 0.0f64,
                        },
                    )?;
                    Work::Paged(WorkPages::new(
                        &layout,
                        &ordinates,
                        std::sync::Arc::new(pager),
                    )?)
                }
            },
            inflow: std::array::from_fn(|f| {
                let a = f / 2;
                vec![boundary.radiance; dims[(a + 1) % 3] * dims[(a + 2) % 3]]
            }),
            homogeneous: false,
            linear: false,
            dsa,
            fixed_dsa_cycles: (settings.outer == Outer::Gmres).then_some(DSA_CYCLES),
            tsa,
            anderson,
            device: None,
            interrupt: lucent_core::Interrupt::never(),
            spacing: h,
            layout,
            timings: Timings::default(),
            monitor: Monitor {
                best_change: f64::INFINITY,
                ..Monitor::default()
            },
            // Last: the fields above read it.
            ordinates,
        })
    }

    fn storage(&self) -> usize {
        self.ordinates.storage().len()
    }

    /// The S2 iteration of [`Acceleration::Tsa`] for `problem`: the same cells, the
    /// phase function of `ordinates` on the eight S2 directions, the boundary's
    /// reflectance without its sky, DSA with a fixed number of V-cycles, the closure's
    /// linear form.
    fn low_order(
        problem: &DomProblem,
        ordinates: &Ordinates,
        settings: &DomSettings,
    ) -> Result<SourceIteration<'static>, DomError> {
        let s2 = Ordinates::new(
            lucent_optics::SphericalQuadrature::level_symmetric(2)?,
            None,
            *ordinates.phase(),
        )?;
        let problem = DomProblem {
            geometry: problem.geometry,
            sigma_t: problem.sigma_t.clone(),
            sigma_s: problem.sigma_s.clone(),
            fixed: vec![0.0; problem.geometry.voxel_count() * s2.storage().len()],
            boundary: DomBoundary {
                radiance: 0.0,
                reflectance: problem.boundary.reflectance,
            },
        };
        let settings = DomSettings {
            // Never run: only stepped. `Gmres` makes its DSA a fixed number of V-cycles.
            outer: Outer::Gmres,
            acceleration: Acceleration::Dsa,
            anderson: 0,
            paged_work: None,
            ..*settings
        };
        let mut low = SourceIteration::build(&problem, Cow::Owned(s2), &settings, false)?;
        low.linear = true;
        low.fixed_dsa_cycles = Some(DSA_CYCLES);
        Ok(low)
    }

    /// Bytes of the per-direction work of the sweeps (cells × propagation directions,
    /// f64), wherever it lives: what paging it saves.
    pub fn work_bytes(&self) -> u64 {
        (self.layout.cells() * self.ordinates.propagation().len()) as u64 * 8
    }

    /// Bytes of one page of paged work: one block's cells times one octant's directions.
    pub fn work_page_bytes(&self) -> u64 {
        WorkPages::page_len(&self.layout, &self.ordinates) as u64 * 8
    }

    /// The fewest pages a pool of paged work may hold: the scattering product reads a
    /// block's eight octant pages at once on every thread, and the sweep writes behind
    /// with one more.
    pub fn min_work_pages() -> usize {
        8 * rayon::current_num_threads() + 2
    }

    /// What the pager of paged work did so far (`None` in memory).
    pub fn work_pager_stats(&self) -> Option<lucent_paging::PagerStats> {
        match &self.work {
            Work::Memory(_) => None,
            Work::Paged(pages) => Some(pages.pager().stats()),
        }
    }

    /// One transport sweep of the current source (the fixed source plus σ_s times the
    /// in-scattered radiance of the last transport step; none before the first), for
    /// studies of its cost, with the work where the settings put it: in memory or paged
    /// (each block's page of an octant pinned while the block is swept), by the same
    /// arithmetic in the same order, so with the same bits. The iteration does not
    /// advance.
    pub fn sweep_only(&mut self) -> Result<SweepOnly, DomError> {
        if self.device.is_some() {
            return Err(DomError::Invalid(
                "sweep_only times the host's sweep: this iteration runs on a device".into(),
            ));
        }
        self.source()?;
        let before = self.work_pager_stats();
        let start = Instant::now();
        let out = self.sweep()?;
        let seconds = start.elapsed().as_secs_f64();
        let pager = self
            .work_pager_stats()
            .zip(before)
            .map(|(after, before)| after.since(&before));
        Ok(SweepOnly {
            fluence: self.layout.to_grid(&out.fluence, 1),
            outflow_power: out.outflow_power,
            seconds,
            pager,
        })
    }

    /// The source at the propagation directions where it is not filled inside the sweep:
    /// interpolated from the storage directions, block by block.
    fn source(&mut self) -> Result<(), DomError> {
        let Some(transposed) = &self.interpolation else {
            return Ok(());
        };
        let cells = self.layout.cells();
        let m = transposed.nrows();
        let fixed = (!self.homogeneous).then_some(self.fixed.as_slice());
        let (previous, sigma_s) = (&self.previous, &self.sigma_s);
        let layout = &self.layout;
        for (slot, &(first, count)) in self.octants.iter().enumerate() {
            let columns =
                transposed.slice_axis(ndarray::Axis(1), ndarray::Slice::from(first..first + count));
            let block = |b: usize, out: &mut [f64]| {
                let range = layout.block_cells(b);
                interpolate_block(fixed, previous, sigma_s, m, range, &columns, out);
            };
            match &mut self.work {
                Work::Memory(work) => {
                    let octant = &mut work[cells * first..cells * (first + count)];
                    layout
                        .block_chunks(octant, count)
                        .into_par_iter()
                        .enumerate()
                        .for_each(|(b, out)| block(b, out));
                }
                Work::Paged(pages) => {
                    (0..layout.block_count()).into_par_iter().try_for_each(
                        |b| -> Result<(), DomError> {
                            let mut pin = pages.pager().overwrite(pages.page(slot, b))?;
                            let n = layout.block_cells(b).len() * count;
                            block(b, &mut pin[..n]);
                            Ok(())
                        },
                    )?;
                }
            }
        }
        Ok(())
    }

    /// One sweep of the work, wherever it lives.
    fn sweep(&mut self) -> Result<SweepOutput, DomError> {
        let input = SweepInput {
            layout: &self.layout,
            ordinates: &self.ordinates,
            geometry: &self.geometry,
            sigma_t: &self.sigma_t,
            inflow: &self.inflow,
            spacing: self.spacing,
            max_pinned: match &self.work {
                Work::Memory(_) => usize::MAX,
                Work::Paged(pages) => pages.pager().capacity(),
            },
            // The sweep fills the source itself when storage and propagation agree.
            source: self.interpolation.is_none().then(|| CellSource {
                fixed: (!self.homogeneous).then_some(self.fixed.as_slice()),
                previous: &self.previous,
                sigma_s: &self.sigma_s,
                storage: self.ordinates.storage().len(),
            }),
            interrupt: &self.interrupt,
        };
        let (closure, linear) = (self.settings.closure, self.linear);
        let swept = match &mut self.work {
            Work::Memory(work) => match (closure, linear) {
                (Closure::Step, _) => sweep::<StepClosure>(&input, work),
                (Closure::Diamond, false) => sweep::<DiamondClosure>(&input, work),
                (Closure::Diamond, true) => sweep::<LinearDiamondClosure>(&input, work),
                (Closure::Exponential, false) => sweep::<ExponentialClosure>(&input, work),
                (Closure::Exponential, true) => sweep::<LinearExponentialClosure>(&input, work),
            },
            Work::Paged(pages) => match (closure, linear) {
                (Closure::Step, _) => sweep_paged::<StepClosure>(&input, pages)?,
                (Closure::Diamond, false) => sweep_paged::<DiamondClosure>(&input, pages)?,
                (Closure::Diamond, true) => sweep_paged::<LinearDiamondClosure>(&input, pages)?,
                (Closure::Exponential, false) => sweep_paged::<ExponentialClosure>(&input, pages)?,
                (Closure::Exponential, true) => {
                    sweep_paged::<LinearExponentialClosure>(&input, pages)?
                }
            },
        };
        swept.ok_or_else(|| {
            DomError::Halted(
                self.interrupt
                    .halt()
                    .unwrap_or(lucent_core::Halt::Interrupted),
            )
        })
    }

    /// The in-scattered radiance J = Ψ̄ B from the swept work, block by block.
    fn scatter(&mut self) -> Result<(), DomError> {
        let cells = self.layout.cells();
        let m = self.scattering.ncols();
        let (layout, octants, b) = (&self.layout, &self.octants, &self.scattering);
        let out = layout.block_chunks(&mut self.inscattered, m);
        match &self.work {
            Work::Memory(work) => {
                out.into_par_iter().enumerate().for_each(|(block, out)| {
                    let range = layout.block_cells(block);
                    let chunks: Vec<&[f64]> = octants
                        .iter()
                        .map(|&(first, count)| {
                            &work[cells * first..cells * (first + count)]
                                [range.start * count..range.end * count]
                        })
                        .collect();
                    scatter_block(&chunks, octants, b, out);
                });
            }
            Work::Paged(pages) => {
                out.into_par_iter().enumerate().try_for_each(
                    |(block, out)| -> Result<(), DomError> {
                        let n = layout.block_cells(block).len();
                        let pins = (0..octants.len())
                            .map(|slot| pages.pager().read(pages.page(slot, block)))
                            .collect::<Result<Vec<_>, _>>()?;
                        let chunks: Vec<&[f64]> = pins
                            .iter()
                            .zip(octants)
                            .map(|(pin, &(_, count))| &pin[..n * count])
                            .collect();
                        scatter_block(&chunks, octants, b, out);
                        Ok(())
                    },
                )?;
            }
        }
        Ok(())
    }

    /// One transport step: the source at the propagation directions,
    /// S_n = W (Q + σ_s J) (W = 1 when storage is propagation), swept once with the
    /// boundary's inflow, and the in-scattered radiance toward each storage direction
    /// J = Ψ̄ (w p̄), one product of the (cells × N) radiance with the (N × M) scattering
    /// matrix.
    fn transport(&mut self) -> Result<SweepOutput, DomError> {
        if self.device.is_some() {
            return self.transport_on_device();
        }
        let t = Instant::now();
        // With storage = propagation the source is filled block by block inside the sweep
        // (one pass less over the work); with interpolation, here.
        self.source()?;
        self.timings.scatter += t.elapsed().as_secs_f64();
        let t = Instant::now();
        let out = self.sweep()?;
        self.timings.sweep += t.elapsed().as_secs_f64();
        let t = Instant::now();
        self.scatter()?;
        self.timings.scatter += t.elapsed().as_secs_f64();
        Ok(out)
    }

    /// [`Self::transport`] on the device: the whole step there, counted as sweep time; the
    /// boundary's powers from its currents and the inflow, as the host's sweep adds them.
    fn transport_on_device(&mut self) -> Result<SweepOutput, DomError> {
        let t = Instant::now();
        let device = self.device.as_mut().expect("called on a device iteration");
        let step = TransportStep {
            inscattered: &self.previous,
            sigma_s: &self.sigma_s,
            fixed: (!self.homogeneous).then_some(self.fixed.as_slice()),
            linear: self.linear,
            inflow: &self.inflow,
        };
        let TransportOutput {
            fluence,
            outflow,
            kernel_seconds,
            scatter_seconds,
        } = device.transport(&step, &mut self.inscattered)?;
        self.timings.sweep += t.elapsed().as_secs_f64();
        self.timings.device += kernel_seconds;
        self.timings.device_scatter += scatter_seconds;
        let h = self.spacing;
        let area = |a: usize| h[(a + 1) % 3] * h[(a + 2) % 3];
        let directions = self.ordinates.propagation().directions();
        let weights = self.ordinates.propagation().weights();
        let (mut inflow_power, mut outflow_power) = (0.0, 0.0);
        for f in 0..6 {
            let a = f / 2;
            // Face 2a is entered by the directions with ω_a > 0, face 2a + 1 by ω_a < 0.
            let entering: f64 = directions
                .iter()
                .zip(weights)
                .filter(|(d, _)| if f % 2 == 0 { d[a] > 0.0 } else { d[a] < 0.0 })
                .map(|(d, w)| w * d[a].abs())
                .sum();
            inflow_power += entering * area(a) * self.inflow[f].iter().sum::<f64>();
            outflow_power += area(a) * outflow[f].iter().sum::<f64>();
        }
        Ok(SweepOutput {
            fluence,
            outflow,
            inflow_power,
            outflow_power,
        })
    }

    /// The diffusion synthetic correction of the sweep's fluence and in-scattered
    /// radiance, from σ_s(φ^{k+½} − φ^k) with φ^k = Σ_m w_m J_m of the source just swept;
    /// `false` when it could not be applied (a non-finite correction).
    fn accelerate(&mut self, out: &mut SweepOutput) -> Result<bool, DomError> {
        if self.tsa.is_some() {
            return self.accelerate_transport(out);
        }
        let Some(solver) = &self.dsa else {
            return Ok(true);
        };
        let t = Instant::now();
        let m = self.storage();
        let weights = self.ordinates.storage().weights();
        let residual: Vec<f32> = out
            .fluence
            .par_iter()
            .zip(self.previous.par_chunks(m))
            .zip(self.sigma_s.par_iter())
            .map(|((new, row), s)| {
                let old: f64 = row
                    .iter()
                    .zip(weights)
                    .map(|(j, w)| f64::from(*j) * w)
                    .sum();
                (f64::from(*s) * (new - old)) as f32
            })
            .collect();
        let f = if residual.iter().all(|r| r.is_finite()) {
            let layout = &self.layout;
            // Inside GMRES the correction must be a fixed linear map: a fixed number of
            // V-cycles from zero, not a tolerance.
            let cycles = self.fixed_dsa_cycles;
            layout.to_blocks(&solver.correction(layout.to_grid(&residual, 1), cycles)?, 1)
        } else {
            vec![f64::NAN]
        };
        let applied = f.iter().all(|v| v.is_finite());
        if applied {
            let four_pi = 4.0 * std::f64::consts::PI;
            let isotropic = &self.isotropic;
            out.fluence
                .par_iter_mut()
                .zip(self.inscattered.par_chunks_mut(m))
                .zip(f.par_iter())
                .for_each(|((phi, row), f)| {
                    *phi += f;
                    for (j, iso) in row.iter_mut().zip(isotropic) {
                        *j = (f64::from(*j) + f * iso / four_pi) as f32;
                    }
                });
        }
        self.timings.dsa += t.elapsed().as_secs_f64();
        Ok(applied)
    }

    /// The transport synthetic correction ([`Acceleration::Tsa`]). The sweep solved
    /// L ψ^{k+½} = q + σ_s J^k; the exact ψ solves L ψ = q + σ_s S ψ, so the error
    /// e = ψ − ψ^{k+½} solves (L − σ_s S) e = σ_s (J^{k+½} − J^k), the new in-scattered
    /// radiance minus the one swept. Its right-hand side's isotropic and first moments,
    /// r₀ = Σ w ΔJ and r₁ = Σ w ω ΔJ per cell, become the S2 problem's source
    /// σ_s (r₀ + 3 ω·r₁)/4π (exact on S2, whose Σ w ω ωᵀ is 4π/3 I), `tsa_sweeps`
    /// accelerated S2 sweeps from zero estimate e, and the fluence gains its scalar flux
    /// e₀ and every storage direction of J the P1 expansion (c₀ + 3 ω·c₁)/4π of the S2
    /// in-scattered radiance (the moments of S e). `false` when the correction is not
    /// finite.
    fn accelerate_transport(&mut self, out: &mut SweepOutput) -> Result<bool, DomError> {
        let t = Instant::now();
        let four_pi = 4.0 * std::f64::consts::PI;
        let m = self.storage();
        let set = self.ordinates.storage();
        let (dirs, weights) = (set.directions(), set.weights());
        let low = self.tsa.as_mut().expect("called with TSA");
        let lm = low.storage();
        let low_set = low.ordinates.storage().clone();
        let (low_dirs, low_weights) = (low_set.directions(), low_set.weights());
        low.fixed
            .par_chunks_mut(lm)
            .zip(self.inscattered.par_chunks(m))
            .zip(self.previous.par_chunks(m))
            .zip(self.sigma_s.par_iter())
            .for_each(|(((q, new), old), s)| {
                let (mut r0, mut r1) = (0.0, glam::DVec3::ZERO);
                for k in 0..m {
                    let d = weights[k] * (f64::from(new[k]) - f64::from(old[k]));
                    r0 += d;
                    r1 += d * dirs[k];
                }
                let s = f64::from(*s) / four_pi;
                for (q, w) in q.iter_mut().zip(low_dirs) {
                    *q = (s * (r0 + 3.0 * r1.dot(*w))) as f32;
                }
            });
        low.previous.fill(0.0);
        low.inflow.iter_mut().for_each(|f| f.fill(0.0));
        let mut error = Vec::new();
        for _ in 0..self.settings.tsa_sweeps {
            let mut step = low.transport()?;
            if !low.accelerate(&mut step)? || step.fluence.iter().any(|v| !v.is_finite()) {
                self.timings.dsa += t.elapsed().as_secs_f64();
                return Ok(false);
            }
            low.inflow = low.reflected_inflow(&step);
            std::mem::swap(&mut low.previous, &mut low.inscattered);
            error = step.fluence;
            self.monitor.low_order_sweeps += 1;
        }
        out.fluence
            .par_iter_mut()
            .zip(self.inscattered.par_chunks_mut(m))
            .zip(low.previous.par_chunks(lm))
            .zip(error.par_iter())
            .for_each(|(((phi, row), low_row), e0)| {
                *phi += e0;
                let (mut c0, mut c1) = (0.0, glam::DVec3::ZERO);
                for ((j, w), d) in low_row.iter().zip(low_weights).zip(low_dirs) {
                    let wj = w * f64::from(*j);
                    c0 += wj;
                    c1 += wj * *d;
                }
                for (j, d) in row.iter_mut().zip(dirs) {
                    *j = (f64::from(*j) + (c0 + 3.0 * c1.dot(*d)) / four_pi) as f32;
                }
            });
        self.timings.dsa += t.elapsed().as_secs_f64();
        Ok(true)
    }

    /// The scattering source's change, ‖σ_s ΔJ‖/‖σ_s J‖ over cells and storage
    /// directions, and the reflected inflow's (updating the inflow from the sweep's
    /// outgoing current).
    fn source_change(&mut self, out: &SweepOutput) -> f64 {
        let m = self.storage();
        let weights = self.ordinates.storage().weights();
        // Sums over chunks of cells in parallel, added in chunk order: the same bits
        // whatever the threads did (a work-stealing reduction is not).
        let (num, den) = self
            .inscattered
            .par_chunks(ROWS * m)
            .zip(self.previous.par_chunks(ROWS * m))
            .zip(self.sigma_s.par_chunks(ROWS))
            .map(|((new, old), sigma_s)| {
                let (mut num, mut den) = (0.0, 0.0);
                for ((new, old), s) in new.chunks(m).zip(old.chunks(m)).zip(sigma_s) {
                    let s2 = f64::from(*s).powi(2);
                    if s2 > 0.0 {
                        for q in 0..m {
                            let (a, b) = (f64::from(new[q]), f64::from(old[q]));
                            num += s2 * weights[q] * (a - b) * (a - b);
                            den += s2 * weights[q] * a * a;
                        }
                    }
                }
                (num, den)
            })
            .collect::<Vec<_>>()
            .into_iter()
            .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
        let mut change = if den > 0.0 { (num / den).sqrt() } else { 0.0 };
        if self.reflects {
            let boundary = self.boundary;
            let (mut num, mut den) = (0.0f64, 0.0f64);
            for f in 0..6 {
                let axis = f / 2;
                for (old, out) in self.inflow[f].iter_mut().zip(&out.outflow[f]) {
                    // Diffuse return of R times the outgoing partial current, normalised by
                    // the set's own half-range moment Σ_in w|ω_a| so that exactly R of the
                    // current comes back (Σ w|μ| over a hemisphere is π only in the limit).
                    let new =
                        boundary.radiance + boundary.reflectance * out / self.half_range[axis];
                    num += (new - *old).powi(2);
                    den += new * new;
                    *old = new;
                }
            }
            if den > 0.0 {
                change = change.max((num / den).sqrt());
            }
        }
        change
    }

    /// Drops DSA and restarts the iteration from zero (plain source iteration, still
    /// mixed).
    fn drop_dsa(&mut self, iteration: usize) {
        self.dsa = None;
        self.tsa = None;
        self.monitor.dsa_abandoned = Some(iteration);
        self.previous.fill(0.0);
        if let Some(a) = self.anderson.as_mut() {
            a.reset();
        }
    }

    /// Anderson mixing of the new source with the previous ones, once the iteration
    /// contracts slowly (by more than 0.3 per sweep: where DSA alone converges fast it
    /// would only cost memory traffic); with mixing the contraction of the underlying map
    /// is measured directly and the largest of the last three bounds the error.
    fn mix(&mut self, change: f64) {
        let monitor = &mut self.monitor;
        if !monitor.mixing && monitor.residuals.len() >= 2 {
            let ratio = change / monitor.residuals[monitor.residuals.len() - 2];
            monitor.mixing = self.anderson.is_some() && (self.dsa.is_none() || ratio > 0.3);
        }
        let t = Instant::now();
        if let Some(a) = self.anderson.as_mut().filter(|_| monitor.mixing)
            && let Some(c) = a
                .step(&self.previous, &mut self.inscattered)
                .filter(|_| change > STORAGE_FLOOR)
        {
            monitor.contractions.push(c);
            let recent = &monitor.contractions[monitor.contractions.len().saturating_sub(3)..];
            monitor.spectral_radius = recent.iter().copied().fold(0.0, f64::max);
        }
        self.timings.anderson += t.elapsed().as_secs_f64();
    }

    /// Solves to `stopping` with the settings' outer iteration: [`Outer::Gmres`] where
    /// anything scatters or reflects (else one sweep is the answer), source iteration
    /// otherwise.
    pub fn run(mut self, stopping: &Stopping) -> Result<DomSolution, DomError> {
        self.interrupt = stopping.interrupt(Instant::now());
        if self.settings.outer == Outer::Gmres && (self.scatters || self.reflects) {
            self.run_gmres(stopping)
        } else {
            self.run_source_iteration(stopping)
        }
    }

    /// The reflected inflow of a sweep's outgoing current, plus the sky unless the step
    /// is homogeneous: I = L_sky + R J⁺ / Σ_in w|ω_a|.
    fn reflected_inflow(&self, out: &SweepOutput) -> [Vec<f64>; 6] {
        let b = self.boundary;
        let sky = if self.homogeneous { 0.0 } else { b.radiance };
        std::array::from_fn(|f| {
            let axis = f / 2;
            out.outflow[f]
                .iter()
                .map(|j| sky + b.reflectance * j / self.half_range[axis])
                .collect()
        })
    }

    /// One DSA-accelerated source-iteration step H(x) from the iterate `x` (the
    /// in-scattered radiance and the inflow), with or without the fixed source and sky:
    /// the new iterate and the sweep's output.
    fn map(&mut self, x: &Iterate, homogeneous: bool) -> Result<(Iterate, SweepOutput), DomError> {
        self.homogeneous = homogeneous;
        let stepped = self.step_from(x);
        self.homogeneous = false;
        stepped
    }

    fn step_from(&mut self, x: &Iterate) -> Result<(Iterate, SweepOutput), DomError> {
        self.previous.copy_from_slice(&x.inscattered);
        self.inflow.clone_from(&x.inflow);
        let mut out = self.transport()?;
        if !self.accelerate(&mut out)? || out.fluence.iter().any(|v| !v.is_finite()) {
            return Err(DomError::NotFinite(
                "the transport sweep or its DSA correction inside GMRES".into(),
            ));
        }
        let inflow = self.reflected_inflow(&out);
        Ok((
            Iterate {
                inscattered: self.inscattered.clone(),
                inflow,
            },
            out,
        ))
    }

    /// GMRES on the DSA-preconditioned fixed point x = H(x) = c + M x (the `gmres`
    /// module), with the closure's linear form: c is one step from zero with the sources,
    /// each Krylov iteration one homogeneous step. Source iteration with the closure as
    /// set (its positivity fix-up) then goes on from the Krylov solution to `stopping`: one
    /// step where the fix-up changes nothing, which confirms the answer, and it settles
    /// what the fix-up changes where it does.
    fn run_gmres(mut self, stopping: &Stopping) -> Result<DomSolution, DomError> {
        let started = Instant::now();
        let zero = Iterate {
            inscattered: vec![0.0; self.previous.len()],
            inflow: std::array::from_fn(|f| vec![0.0; self.inflow[f].len()]),
        };
        self.linear = true;
        let (c, _) = self.map(&zero, false)?;
        let cells = self.sigma_s.len().max(1) as f64;
        let cell_weight: Vec<f64> = self.sigma_s.iter().map(|s| f64::from(*s).powi(2)).collect();
        let mean = cell_weight.iter().sum::<f64>() / cells;
        let space = Space {
            // Without scattering only the reflected inflow is iterated: weight it as is.
            inflow_weight: 4.0 * std::f64::consts::PI * if mean > 0.0 { mean } else { 1.0 },
            cell_weight,
            direction_weight: self.ordinates.storage().weights().to_vec(),
        };
        // The right-hand side's sweep counts as the first, with the residual of x = 0.
        let mut residuals = vec![1.0];
        let restart = self.settings.restart;
        let (before, t) = (self.timings, Instant::now());
        let solved = {
            let this = &mut self;
            gmres(
                &space,
                &c,
                restart,
                |v| this.map(v, true).map(|(mv, _)| mv),
                |k, step: GmresStep| {
                    residuals.push(step.relative);
                    stopping
                        .verdict(k + 1, step.relative, step.absolute, 1.0, started)
                        .is_some()
                },
            )?
        };
        let inside = (self.timings.sweep - before.sweep)
            + (self.timings.scatter - before.scatter)
            + (self.timings.dsa - before.dsa);
        self.timings.krylov += (t.elapsed().as_secs_f64() - inside).max(0.0);
        self.linear = false;
        self.previous.copy_from_slice(&solved.inscattered);
        self.inflow = solved.inflow;
        // The source iteration's safeguards count from here: DSA has not stalled (the
        // Krylov iteration's sweeps are not its history).
        self.monitor.last_improvement = residuals.len();
        self.monitor.residuals = residuals;
        self.run_source_iteration(stopping)
    }

    /// Iterates to `stopping`: transport, acceleration, the change of the source, the
    /// safeguards, the stopping rule, mixing.
    fn run_source_iteration(mut self, stopping: &Stopping) -> Result<DomSolution, DomError> {
        let started = Instant::now();
        // The last whole iterate's sweep, for a sweep that Ctrl-C or the time limit stops
        // part way: the solution is then that iterate's.
        let mut previous: Option<SweepOutput> = None;
        let (stop_reason, last) = loop {
            let mut out = match self.transport() {
                Err(DomError::Halted(halt)) if previous.is_some() => {
                    // `mix` and the swap made `previous` the in-scattered radiance of
                    // the last iterate: back where `finish` reads it.
                    std::mem::swap(&mut self.previous, &mut self.inscattered);
                    let residual = self.monitor.residuals.last().copied().unwrap_or(1.0);
                    break (
                        halt.stop_reason(residual),
                        previous.take().expect("checked above"),
                    );
                }
                other => other?,
            };
            let iteration = self.monitor.residuals.len() + 1;
            if out.fluence.iter().any(|v| !v.is_finite()) {
                break (StopReason::DivergedNonFinite { iteration }, out);
            }
            if !self.accelerate(&mut out)? {
                self.drop_dsa(iteration);
                self.monitor.residuals.push(f64::NAN);
                continue;
            }
            let change = self.source_change(&out);
            if let Some(verdict) = self.judge(iteration, change, stopping, started) {
                match verdict {
                    Verdict::Stop(reason) => break (reason, out),
                    Verdict::DropDsa => continue,
                }
            }
            self.mix(change);
            std::mem::swap(&mut self.previous, &mut self.inscattered);
            previous = Some(out);
        };
        Ok(self.finish(stop_reason, last))
    }

    /// Records `change` and decides: stop (with the reason), drop DSA and restart, or go
    /// on (`None`).
    fn judge(
        &mut self,
        iteration: usize,
        change: f64,
        stopping: &Stopping,
        started: Instant,
    ) -> Option<Verdict> {
        let monitor = &mut self.monitor;
        monitor.residuals.push(change);
        // Contraction per sweep, averaged over the last five.
        let residuals = &monitor.residuals;
        let back = residuals.len().saturating_sub(6);
        let span = residuals.len() - 1 - back;
        if !monitor.mixing && span > 0 && residuals[back] > 0.0 && change > STORAGE_FLOOR {
            // Below the floor the ratios are rounding noise: keep the last measured one.
            monitor.spectral_radius = (change / residuals[back]).powf(1.0 / span as f64);
        }
        if !self.scatters && !self.reflects {
            return Some(Verdict::Stop(StopReason::ConvergedAbsolute {
                residual: 0.0,
            }));
        }
        if !change.is_finite() {
            return Some(Verdict::Stop(StopReason::DivergedNonFinite { iteration }));
        }
        // Inconsistent DSA can amplify errors in optically thick cells (see `dsa`): when
        // the change has grown tenfold over the best one seen, or has not halved in 16
        // sweeps while still above 1%, it is dropped and the iteration restarts from zero
        // without it (plain source iteration, still mixed).
        let stalled = iteration >= monitor.last_improvement + 16 && change > 1e-2;
        if self.dsa.is_some() && iteration >= 3 && (change > 10.0 * monitor.best_change || stalled)
        {
            self.drop_dsa(iteration);
            let monitor = &mut self.monitor;
            monitor.contractions.clear();
            monitor.mixing = false;
            monitor.best_change = f64::INFINITY;
            monitor.last_improvement = iteration;
            return Some(Verdict::DropDsa);
        }
        if change < 0.5 * monitor.best_change {
            monitor.last_improvement = iteration;
        }
        monitor.best_change = monitor.best_change.min(change);
        let first = *monitor.first_change.get_or_insert(change);
        // Without DSA the change per sweep underestimates the distance to the fixed point
        // by 1/(1 − ρ), ρ the source iteration's contraction (≈ the albedo in thick
        // media): a plain change test would stop far from it. With DSA the slow modes are
        // removed and the change itself is the error estimate (as in DSA codes; the
        // energy balance tests check it).
        let remaining = if change <= 1e-3 * stopping.relative_tolerance {
            // Not moving at all: even at ρ = 0.999 what is left is below the tolerance.
            change
        } else if iteration < 3 || self.dsa.is_some() {
            change
        } else if monitor.spectral_radius < 1.0 {
            change / (1.0 - monitor.spectral_radius)
        } else {
            f64::INFINITY
        };
        // The one stopping rule, on the estimated error (the change while no contraction is
        // measured yet, which may then not count as converged).
        let estimate = if remaining.is_finite() {
            remaining
        } else {
            change
        };
        match stopping.verdict(iteration, estimate, change, first, started) {
            Some(StopReason::ConvergedRelative { .. }) if !remaining.is_finite() => None,
            Some(reason) => Some(Verdict::Stop(reason)),
            None => None,
        }
    }

    /// The solution from the last sweep: fluence and in-scattered radiance in grid order,
    /// the convergence record, the energy balance.
    fn finish(self, stop_reason: StopReason, last: SweepOutput) -> DomSolution {
        let work_paging = self.work_pager_stats();
        let m = self.storage();
        let weights = self.ordinates.storage().weights();
        let volume = self.spacing.iter().product::<f64>();
        let emitted: f64 = self
            .fixed
            .chunks(m)
            .map(|row| {
                row.iter()
                    .zip(weights)
                    .map(|(q, w)| f64::from(*q) * w)
                    .sum::<f64>()
            })
            .sum::<f64>()
            * volume;
        let absorbed: f64 = last
            .fluence
            .iter()
            .zip(self.sigma_t.iter().zip(&self.sigma_s))
            .map(|(phi, (t, s))| phi * f64::from(t - s).max(0.0))
            .sum::<f64>()
            * volume;
        let (monitor, timings) = (self.monitor, self.timings);
        DomSolution {
            fluence: self.layout.to_grid(&last.fluence, 1),
            inscattered: self.layout.to_grid(&self.inscattered, m),
            convergence: DomConvergence {
                sweeps: monitor.residuals.len(),
                residuals: monitor.residuals,
                stop_reason,
                spectral_radius: monitor.spectral_radius,
                sweep_seconds: timings.sweep,
                scatter_seconds: timings.scatter,
                dsa_seconds: timings.dsa,
                anderson_seconds: timings.anderson,
                krylov_seconds: timings.krylov,
                device_seconds: timings.device,
                device_scatter_seconds: timings.device_scatter,
                dsa_abandoned: monitor.dsa_abandoned,
                low_order_sweeps: monitor.low_order_sweeps,
                work_paging,
            },
            balance: DomBalance {
                emitted,
                inflow: last.inflow_power,
                absorbed,
                outflow: last.outflow_power,
            },
        }
    }
}

/// What [`SourceIteration::judge`] decides when it does not go on.
enum Verdict {
    Stop(StopReason),
    DropDsa,
}

const ROWS: usize = 1024;

/// The thickest cell (σ_t times the largest cell width) [`Acceleration::Tsa`] accepts.
/// Measured on a homogeneous 16³ cube at albedo 0.99, S4, g = 0.6 (tests/it/krylov.rs): up
/// to σ_t h = 4 TSA takes fewer sweeps than DSA with every closure (diamond at σ_t h = 2:
/// 14 without mixing where DSA alone is dropped); at σ_t h = 8 (exponential closure)
/// source iteration with TSA drops it or stalls, and GMRES with TSA needs 142 sweeps
/// against 14 with DSA: the S2 problem's own DSA amplifies there as DSA does.
pub(crate) const TSA_MAX_CELL_THICKNESS: f64 = 4.0;

/// V-cycles of the DSA correction inside GMRES: a fixed count keeps the preconditioned
/// operator linear. Eight instead of three changed no sweep count of tests/it/krylov.rs
/// (measured): the correction's accuracy is not what limits the Krylov iteration.
const DSA_CYCLES: usize = 3;

/// J = Ψ̄ B for one block, B the (N × M) scattering matrix: `chunks` holds per octant the
/// block's cells × the octant's directions; per chunk of up to `ROWS` cells the radiance is
/// gathered into one (rows × N) matrix (in cache) and multiplied once (ndarray's matrix
/// product: matrixmultiply's SIMD kernels), in f64, stored in f32 into `out` (cells × M).
fn scatter_block(
    chunks: &[&[f64]],
    octants: &[(usize, usize)],
    b: &ndarray::Array2<f64>,
    out: &mut [f32],
) {
    let (n, m) = (b.nrows(), b.ncols());
    for (chunk, out) in out.chunks_mut(ROWS * m).enumerate() {
        let rows = out.len() / m;
        let start = chunk * ROWS;
        let mut a = ndarray::Array2::<f64>::zeros((rows, n));
        for (psi, &(first, count)) in chunks.iter().zip(octants) {
            let block = &psi[start * count..(start + rows) * count];
            for (r, mut row) in a.rows_mut().into_iter().enumerate() {
                for d in 0..count {
                    row[first + d] = block[r * count + d];
                }
            }
        }
        let mut c = ndarray::Array2::<f64>::zeros((rows, m));
        ndarray::linalg::general_mat_mul(1.0, &a, b, 0.0, &mut c);
        for (o, v) in out.iter_mut().zip(c.iter()) {
            *o = *v as f32;
        }
    }
}

/// S = (Q + σ_s J) Wᵀ for the cells `range` (block order; Q = 0 without `fixed`) and one
/// octant's columns of the transposed interpolation matrix (M × count), into `out`
/// (cells × count), per chunk of up to `ROWS` cells one matrix product.
fn interpolate_block(
    fixed: Option<&[f32]>,
    previous: &[f32],
    sigma_s: &[f32],
    m: usize,
    range: std::ops::Range<usize>,
    columns: &ndarray::ArrayView2<'_, f64>,
    out: &mut [f64],
) {
    let count = columns.ncols();
    for (chunk, w) in out.chunks_mut(ROWS * count).enumerate() {
        let rows = w.len() / count;
        let start = range.start + chunk * ROWS;
        let mut a = ndarray::Array2::<f64>::zeros((rows, m));
        for (r, mut row) in a.rows_mut().into_iter().enumerate() {
            let cell = start + r;
            let s = f64::from(sigma_s[cell]);
            for (c, v) in row.iter_mut().enumerate() {
                let q = fixed.map_or(0.0, |f| f64::from(f[cell * m + c]));
                *v = q + s * f64::from(previous[cell * m + c]);
            }
        }
        let mut c = ndarray::ArrayViewMut2::from_shape((rows, count), w).expect("rows × count");
        ndarray::linalg::general_mat_mul(1.0, &a, columns, 0.0, &mut c);
    }
}
