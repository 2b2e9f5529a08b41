//! Source iteration: sweep with the previous in-scattered radiance, rebuild it from the new
//! radiance, optionally accelerate with diffusion, until the scattering source stops
//! changing.

use std::time::Instant;

use lucent_core::StopReason;
use lucent_core::Stopping;
use lucent_grid::GridGeometry;

use rayon::prelude::*;

use crate::anderson::Anderson;
use crate::angular::Ordinates;
use crate::closure::{CellDirection, Closure, DiamondClosure, ExponentialClosure, StepClosure};
use crate::dsa::Dsa;
use crate::error::DomError;
use crate::sweep::{Layout, SweepInput, SweepOutput, sweep};

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
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Acceleration {
    /// Plain source iteration (one scattering order per sweep).
    None,
    /// Diffusion synthetic acceleration with `lucent-diffusion`'s multigrid.
    #[default]
    Dsa,
}

/// How to solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DomSettings {
    /// Spatial closure.
    pub closure: Closure,
    /// Acceleration.
    pub acceleration: Acceleration,
    /// Anderson mixing depth on top of the (accelerated) iteration; 0 turns it off. It
    /// starts only once the iteration contracts by more than 0.3 per sweep, and then costs
    /// 2·depth + 2 vectors of the stored in-scattered radiance (f32).
    pub anderson: usize,
    /// Block edge of the wavefront (cells).
    pub block: usize,
}

impl Default for DomSettings {
    fn default() -> Self {
        Self {
            closure: Closure::default(),
            acceleration: Acceleration::default(),
            anderson: 2,
            block: 16,
        }
    }
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
    /// Wall time of the DSA solves (s).
    pub dsa_seconds: f64,
    /// Wall time of the Anderson mixing (s).
    pub anderson_seconds: f64,
    /// The sweep after which DSA was dropped because it amplified the error (thick
    /// cells), if it was.
    pub dsa_abandoned: Option<usize>,
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

/// Solves `problem` on `ordinates`.
pub fn solve(
    problem: &DomProblem,
    ordinates: &Ordinates,
    settings: &DomSettings,
    stopping: &Stopping,
) -> Result<DomSolution, DomError> {
    let started = Instant::now();
    let m = ordinates.storage().len();
    validate(problem, m)?;
    if settings.block == 0 {
        return Err(DomError::Invalid("block size 0".into()));
    }
    let g = problem.geometry;
    let dims = g.dims();
    let h = g.spacing().to_array();
    let volume = h[0] * h[1] * h[2];
    let layout = Layout::new(dims, settings.block);
    let geometry: Vec<CellDirection> = ordinates
        .propagation()
        .directions()
        .iter()
        .map(|d| CellDirection::new(d.to_array(), h))
        .collect();
    let sigma_t = layout.to_blocks(&problem.sigma_t, 1);
    let sigma_s = layout.to_blocks(&problem.sigma_s, 1);
    let fixed = layout.to_blocks(&problem.fixed, m);
    let mut previous = vec![0.0f32; layout.cells() * m];
    let boundary = problem.boundary;
    let mut inflow: [Vec<f64>; 6] = std::array::from_fn(|f| {
        let a = f / 2;
        vec![boundary.radiance; dims[(a + 1) % 3] * dims[(a + 2) % 3]]
    });
    let scatters = problem.sigma_s.iter().any(|&s| s > 0.0);
    let reflects = boundary.reflectance > 0.0;
    let mut dsa = match settings.acceleration {
        Acceleration::Dsa if scatters => Dsa::new(
            g,
            &problem.sigma_t,
            &problem.sigma_s,
            ordinates.effective_g(),
            boundary.reflectance,
        )?,
        _ => None,
    };
    let isotropic = ordinates.isotropic_inscatter();
    let storage_weights = ordinates.storage().weights();
    let n_dirs = ordinates.propagation().len();
    let matrix = |v: &[f64], rows: usize, cols: usize| {
        ndarray::Array2::from_shape_vec((rows, cols), v.to_vec())
            .map_err(|e| DomError::Invalid(e.to_string()))
    };
    let scattering = matrix(ordinates.scattering(), n_dirs, m)?;
    let interpolation = match ordinates.interpolation() {
        None => None,
        Some(w) => Some(
            matrix(w, n_dirs, m)?
                .reversed_axes()
                .as_standard_layout()
                .into_owned(),
        ),
    };
    // Cell-average radiance per propagation direction, kept in f64 between the sweep and
    // the scattering product: at albedo 0.99 light scatters ~100 times, so rounding in
    // the in-scattered energy is amplified that much in the balance.
    let mut work = vec![0.0f64; layout.cells() * n_dirs];
    // Each octant's (first direction, count): contiguous by construction of `Ordinates`.
    let octants: Vec<(usize, usize)> = (0..8)
        .map(|o| ordinates.octant(o))
        .filter(|d| !d.is_empty())
        .map(|d| (d[0], d.len()))
        .collect();
    let mut inscattered = vec![0.0f32; layout.cells() * m];
    let half_range: [f64; 3] = std::array::from_fn(|a| {
        ordinates
            .propagation()
            .directions()
            .iter()
            .zip(ordinates.propagation().weights())
            .filter(|(d, _)| d[a] > 0.0)
            .map(|(d, w)| w * d[a])
            .sum::<f64>()
            .max(f64::MIN_POSITIVE)
    });

    let mut anderson = (settings.anderson > 0 && scatters).then(|| {
        Anderson::new(
            settings.anderson,
            sigma_s.iter().map(|s| s * s).collect(),
            storage_weights.iter().map(|w| *w as f32).collect(),
        )
    });
    let mut residuals: Vec<f64> = Vec::new();
    let mut sweep_seconds = 0.0;
    let (mut scatter_seconds, mut dsa_seconds, mut anderson_seconds) = (0.0, 0.0, 0.0);
    let mut spectral_radius = 0.0;
    let mut first_change = None;
    let mut best_change = f64::INFINITY;
    let mut dsa_abandoned = None;
    let mut last_improvement = 0;
    let mut contractions: Vec<f64> = Vec::new();
    let mut mixing = false;
    let (stop_reason, last): (StopReason, SweepOutput) = loop {
        // The source at the propagation directions, S_n = W (Q + σ_s J) (W = 1 when
        // storage is propagation).
        let t = Instant::now();
        match &interpolation {
            None => fill(&fixed, &previous, &sigma_s, &octants, &mut work),
            Some(transposed) => {
                interpolate(&fixed, &previous, &sigma_s, &octants, transposed, &mut work);
            }
        }
        scatter_seconds += t.elapsed().as_secs_f64();
        let input = SweepInput {
            layout: &layout,
            ordinates,
            geometry: &geometry,
            sigma_t: &sigma_t,
            inflow: &inflow,
            spacing: h,
        };
        let t = Instant::now();
        let mut out = match settings.closure {
            Closure::Step => sweep::<StepClosure>(&input, &mut work),
            Closure::Diamond => sweep::<DiamondClosure>(&input, &mut work),
            Closure::Exponential => sweep::<ExponentialClosure>(&input, &mut work),
        };
        // In-scattered radiance toward each storage direction: J = Ψ̄ (w p̄), one product
        // of the (cells × N) radiance with the (N × M) scattering matrix.
        sweep_seconds += t.elapsed().as_secs_f64();
        let t = Instant::now();
        scatter(&work, &octants, &scattering, &mut inscattered);
        scatter_seconds += t.elapsed().as_secs_f64();
        let iteration = residuals.len() + 1;
        if out.fluence.iter().any(|v| !v.is_finite()) {
            break (StopReason::DivergedNonFinite { iteration }, out);
        }
        let t = Instant::now();
        let mut dsa_failed = false;
        if let Some(solver) = &dsa {
            // σ_s(φ^{k+½} − φ^k), with φ^k = Σ_m w_m J_m of the source just swept.
            let residual: Vec<f32> = out
                .fluence
                .iter()
                .zip(previous.chunks(m))
                .zip(&sigma_s)
                .map(|((new, row), s)| {
                    let old: f64 = row
                        .iter()
                        .zip(storage_weights)
                        .map(|(j, w)| f64::from(*j) * w)
                        .sum();
                    (f64::from(*s) * (new - old)) as f32
                })
                .collect();
            let f = if residual.iter().all(|r| r.is_finite()) {
                layout.to_blocks(&solver.correction(layout.to_grid(&residual, 1))?, 1)
            } else {
                vec![f64::NAN]
            };
            if f.iter().all(|v| v.is_finite()) {
                let four_pi = 4.0 * std::f64::consts::PI;
                for (cell, f) in f.iter().enumerate() {
                    out.fluence[cell] += f;
                    let row = &mut inscattered[cell * m..(cell + 1) * m];
                    for (j, iso) in row.iter_mut().zip(&isotropic) {
                        *j = (f64::from(*j) + f * iso / four_pi) as f32;
                    }
                }
            } else {
                dsa_failed = true;
            }
        }
        dsa_seconds += t.elapsed().as_secs_f64();
        if dsa_failed {
            abandon(
                &mut dsa,
                &mut dsa_abandoned,
                iteration,
                &mut previous,
                &mut anderson,
            );
            residuals.push(f64::NAN);
            continue;
        }
        // The scattering source's change, ‖σ_s ΔJ‖/‖σ_s J‖ over cells and storage
        // directions, and the reflected inflow's.
        let (num, den) = inscattered
            .par_chunks(m)
            .zip(previous.par_chunks(m))
            .zip(sigma_s.par_iter())
            .map(|((new, old), s)| {
                let s2 = f64::from(*s).powi(2);
                let (mut num, mut den) = (0.0, 0.0);
                if s2 > 0.0 {
                    for q in 0..m {
                        let (a, b) = (f64::from(new[q]), f64::from(old[q]));
                        num += s2 * storage_weights[q] * (a - b) * (a - b);
                        den += s2 * storage_weights[q] * a * a;
                    }
                }
                (num, den)
            })
            .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
        let mut change = if den > 0.0 { (num / den).sqrt() } else { 0.0 };
        if reflects {
            let (mut num, mut den) = (0.0f64, 0.0f64);
            for f in 0..6 {
                let axis = f / 2;
                for (old, out) in inflow[f].iter_mut().zip(&out.outflow[f]) {
                    // Diffuse return of R times the outgoing partial current, normalised by
                    // the set's own half-range moment Σ_in w|ω_a| so that exactly R of the
                    // current comes back (Σ w|μ| over a hemisphere is π only in the limit).
                    let new = boundary.radiance + boundary.reflectance * out / half_range[axis];
                    num += (new - *old).powi(2);
                    den += new * new;
                    *old = new;
                }
            }
            if den > 0.0 {
                change = change.max((num / den).sqrt());
            }
        }
        residuals.push(change);
        // Contraction per sweep, averaged over the last five.
        let back = residuals.len().saturating_sub(6);
        let span = residuals.len() - 1 - back;
        if !mixing && span > 0 && residuals[back] > 0.0 && change > STORAGE_FLOOR {
            // Below the floor the ratios are rounding noise: keep the last measured one.
            spectral_radius = (change / residuals[back]).powf(1.0 / span as f64);
        }
        if !scatters && !reflects {
            break (StopReason::ConvergedAbsolute { residual: 0.0 }, out);
        }
        if !change.is_finite() {
            break (StopReason::DivergedNonFinite { iteration }, out);
        }
        // Inconsistent DSA can amplify errors in optically thick cells (see `dsa`): when
        // the change has grown tenfold over the best one seen, or has not halved in 16
        // sweeps while still above 1%, it is dropped and the iteration restarts from zero without it (plain
        // source iteration, still mixed).
        let stalled = iteration >= last_improvement + 16 && change > 1e-2;
        if dsa.is_some() && iteration >= 3 && (change > 10.0 * best_change || stalled) {
            abandon(
                &mut dsa,
                &mut dsa_abandoned,
                iteration,
                &mut previous,
                &mut anderson,
            );
            contractions.clear();
            mixing = false;
            best_change = f64::INFINITY;
            last_improvement = iteration;
            continue;
        }
        if change < 0.5 * best_change {
            last_improvement = iteration;
        }
        best_change = best_change.min(change);
        let first = *first_change.get_or_insert(change);
        // Without DSA the change per sweep underestimates the distance to the fixed point
        // by 1/(1 − ρ), ρ the source iteration's contraction (≈ the albedo in thick
        // media): a plain change test would stop far from it. With DSA the slow modes are
        // removed and the change itself is the error estimate (as in DSA codes; the
        // energy balance tests check it).
        let remaining = if change <= 1e-3 * stopping.relative_tolerance {
            // Not moving at all: even at ρ = 0.999 what is left is below the tolerance.
            change
        } else if iteration < 3 || dsa.is_some() {
            change
        } else if spectral_radius < 1.0 {
            change / (1.0 - spectral_radius)
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
            Some(StopReason::ConvergedRelative { .. }) if !remaining.is_finite() => {}
            Some(reason) => break (reason, out),
            None => {}
        }
        // Mixing starts once the iteration contracts slowly (by more than 0.3 per sweep):
        // where DSA alone converges fast it would only cost memory traffic.
        if !mixing && residuals.len() >= 2 {
            let ratio = change / residuals[residuals.len() - 2];
            mixing = anderson.is_some() && (dsa.is_none() || ratio > 0.3);
        }
        let t = Instant::now();
        if let Some(a) = anderson.as_mut().filter(|_| mixing) {
            // With mixing, the contraction of the underlying map is measured directly;
            // the largest of the last three (above the storage floor) bounds the error.
            if let Some(c) = a
                .step(&previous, &mut inscattered)
                .filter(|_| change > STORAGE_FLOOR)
            {
                contractions.push(c);
                let recent = &contractions[contractions.len().saturating_sub(3)..];
                spectral_radius = recent.iter().copied().fold(0.0, f64::max);
            }
        }
        anderson_seconds += t.elapsed().as_secs_f64();
        std::mem::swap(&mut previous, &mut inscattered);
    };
    let emitted: f64 = fixed
        .chunks(m)
        .map(|row| {
            row.iter()
                .zip(storage_weights)
                .map(|(q, w)| f64::from(*q) * w)
                .sum::<f64>()
        })
        .sum::<f64>()
        * volume;
    let absorbed: f64 = last
        .fluence
        .iter()
        .zip(sigma_t.iter().zip(&sigma_s))
        .map(|(phi, (t, s))| phi * f64::from(t - s).max(0.0))
        .sum::<f64>()
        * volume;
    Ok(DomSolution {
        fluence: layout.to_grid(&last.fluence, 1),
        inscattered: layout.to_grid(&inscattered, m),
        convergence: DomConvergence {
            sweeps: residuals.len(),
            residuals,
            stop_reason,
            spectral_radius,
            sweep_seconds,
            scatter_seconds,
            dsa_seconds,
            anderson_seconds,
            dsa_abandoned,
        },
        balance: DomBalance {
            emitted,
            inflow: last.inflow_power,
            absorbed,
            outflow: last.outflow_power,
        },
    })
}

/// Drops DSA and restarts the iteration from zero.
fn abandon(
    dsa: &mut Option<Dsa>,
    abandoned: &mut Option<usize>,
    iteration: usize,
    previous: &mut [f32],
    anderson: &mut Option<Anderson>,
) {
    *dsa = None;
    *abandoned = Some(iteration);
    previous.fill(0.0);
    if let Some(a) = anderson.as_mut() {
        a.reset();
    }
}

const ROWS: usize = 1024;

/// The octant-major block of `work` for octant (first, count): cells × count.
fn octant_rows(cells: usize, (first, count): (usize, usize)) -> std::ops::Range<usize> {
    cells * first..cells * (first + count)
}

/// S_n = Q_n + σ_s J_n when storage is propagation (octant-major `work`).
fn fill(
    fixed: &[f32],
    previous: &[f32],
    sigma_s: &[f32],
    octants: &[(usize, usize)],
    work: &mut [f64],
) {
    let cells = sigma_s.len();
    let m = fixed.len() / cells.max(1);
    for &(first, count) in octants {
        work[octant_rows(cells, (first, count))]
            .par_chunks_mut(count)
            .enumerate()
            .for_each(|(cell, w)| {
                let s = f64::from(sigma_s[cell]);
                let at = cell * m + first;
                for (d, w) in w.iter_mut().enumerate() {
                    *w = f64::from(fixed[at + d]) + s * f64::from(previous[at + d]);
                }
            });
    }
}

/// J = Ψ̄ B, B the (N × M) scattering matrix: per block of cells the octant-major radiance
/// is gathered into one (rows × N) matrix (in cache) and multiplied once (ndarray's matrix
/// product: matrixmultiply's SIMD kernels), in f64, stored in f32.
fn scatter(psi: &[f64], octants: &[(usize, usize)], b: &ndarray::Array2<f64>, out: &mut [f32]) {
    let (n, m) = (b.nrows(), b.ncols());
    let cells = out.len() / m.max(1);
    out.par_chunks_mut(ROWS * m)
        .enumerate()
        .for_each(|(chunk, out)| {
            let rows = out.len() / m;
            let start = chunk * ROWS;
            let mut a = ndarray::Array2::<f64>::zeros((rows, n));
            for &(first, count) in octants {
                let block =
                    &psi[octant_rows(cells, (first, count))][start * count..(start + rows) * count];
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
        });
}

/// S = (Q + σ_s J) Wᵀ per cell, Wᵀ the (M × N) transposed interpolation matrix, into the
/// octant-major `work`.
fn interpolate(
    fixed: &[f32],
    previous: &[f32],
    sigma_s: &[f32],
    octants: &[(usize, usize)],
    transposed: &ndarray::Array2<f64>,
    work: &mut [f64],
) {
    let cells = sigma_s.len();
    let m = transposed.nrows();
    // Per octant: rows of cells in parallel chunks, each forming its (rows × M) sources.
    for &(first, count) in octants {
        let columns =
            transposed.slice_axis(ndarray::Axis(1), ndarray::Slice::from(first..first + count));
        work[octant_rows(cells, (first, count))]
            .par_chunks_mut(ROWS * count)
            .enumerate()
            .for_each(|(chunk, w)| {
                let rows = w.len() / count;
                let start = chunk * ROWS;
                let mut a = ndarray::Array2::<f64>::zeros((rows, m));
                for (r, mut row) in a.rows_mut().into_iter().enumerate() {
                    let cell = start + r;
                    let s = f64::from(sigma_s[cell]);
                    for (c, v) in row.iter_mut().enumerate() {
                        *v = f64::from(fixed[cell * m + c]) + s * f64::from(previous[cell * m + c]);
                    }
                }
                let mut c =
                    ndarray::ArrayViewMut2::from_shape((rows, count), w).expect("rows × count");
                ndarray::linalg::general_mat_mul(1.0, &a, &columns, 0.0, &mut c);
            });
    }
}
