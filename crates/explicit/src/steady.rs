//! Explicit iterations on lucent-diffusion's discrete problem: FTCS in time and Jacobi
//! relaxation, marched to the steady state, which is then the multigrid's solution of the
//! same system A φ = b ([`lucent_diffusion::DiffusionProblem::assemble`]).
//!
//! - FTCS: V dφ/dτ = b − Aφ (A in integrated form, V the cell volume), φ′ = φ +
//!   (cΔt/V)(b − Aφ); stable for cΔt ≤ 2V/λ_max(A), bounded here by Gershgorin
//!   (λ_max ≤ max_i a_ii + Σ_j |a_ij|), which is exact for the homogeneous box's
//!   checkerboard mode.
//! - Jacobi: φ′ = φ + ω D⁻¹(b − Aφ), ω ∈ (0, 1]: FTCS at the positivity limit
//!   cΔt = V/a_ii, cell by cell (at the positivity bound FTCS is Jacobi: docs/reference-cases.md, Murray).
//!
//! Both converge at rate 1 − O(h²): explicit schemes pay for steady states with
//! thousands of sweeps, which is what the pareto charts show against multigrid.

use lucent_core::exact::ExactSum;
use lucent_core::{History, StopReason, Stopping};
use lucent_diffusion::AssembledSystem;
use rayon::prelude::*;

use crate::error::ExplicitError;

/// Which explicit iteration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Iteration {
    /// FTCS with step cΔt (length) and cell volume V (length³).
    Ftcs {
        /// cΔt.
        time_step: f64,
        /// Cell volume.
        cell_volume: f64,
    },
    /// Weighted Jacobi.
    Jacobi {
        /// Damping in (0, 1].
        omega: f64,
    },
}

/// When to stop.
#[derive(Debug, Clone, PartialEq)]
pub struct SteadySettings {
    /// When to stop, on the relative residual ‖b − Aφ‖/‖b‖ (one sweep, one iteration).
    pub stopping: Stopping,
    /// Run FTCS beyond its bound (studies).
    pub allow_unstable: bool,
}

/// The result of [`iterate`].
#[derive(Debug, Clone, PartialEq)]
pub struct Steady {
    /// φ per unknown of the system.
    pub fluence: Vec<f64>,
    /// Relative residual before each sweep and after the last.
    pub residuals: Vec<f64>,
    /// Why it stopped.
    pub stop_reason: StopReason,
}

/// The FTCS step limit 2V / (max_i a_ii + Σ|a_ij|).
pub fn ftcs_limit(system: &AssembledSystem, cell_volume: f64) -> f64 {
    2.0 * cell_volume / gershgorin(&system.matrix)
}

/// The largest Gershgorin row sum max_i Σ_j |a_ij| of `rows` (each row summed in its
/// stored order): the bound on λ_max behind [`ftcs_limit`], for the whole system or, on
/// ranks, for one rank's rows (the maximum over ranks is exact, whatever the split).
pub fn gershgorin(rows: &sprs::CsMat<f64>) -> f64 {
    rows.outer_iterator()
        .map(|row| row.iter().map(|(_, v)| v.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

/// Iterates from zero to the stopping rule on a grid of `dims` cells. Norms are summed by
/// runs of [`NORM_RUN`] cells along x ([`Layers`]), the same bits however the grid is
/// split over ranks (`crate::ranks`).
pub fn iterate(
    system: &AssembledSystem,
    dims: [usize; 3],
    iteration: Iteration,
    settings: &SteadySettings,
) -> Result<Steady, ExplicitError> {
    let a = &system.matrix;
    let b = &system.rhs;
    let n = b.len();
    let scale = row_scale(system, iteration, settings.allow_unstable)?;
    let layers = Layers::new(&system.cells, dims);
    let b_norm = layers.norm(b).max(f64::MIN_POSITIVE);
    let mut phi = vec![0.0f64; n];
    let mut r = b.clone();
    let mut history = History::start();
    let mut relative = 1.0;
    loop {
        if let Some(stop_reason) = history.record(&settings.stopping, relative, relative * b_norm) {
            if phi.iter().any(|v| !v.is_finite()) {
                phi.fill(0.0);
            }
            return Ok(Steady {
                fluence: phi,
                residuals: history.into_residuals(),
                stop_reason,
            });
        }
        phi.par_iter_mut()
            .zip(r.par_iter())
            .zip(scale.par_iter())
            .for_each(|((p, r), s)| *p += s * r);
        // r = b − Aφ by rows (CSR).
        r.par_iter_mut().enumerate().for_each(|(i, ri)| {
            let row = a.outer_view(i);
            let ax: f64 = row.map_or(0.0, |row| row.iter().map(|(j, v)| v * phi[j]).sum());
            *ri = b[i] - ax;
        });
        relative = layers.norm(&r) / b_norm;
    }
}

/// Cells along x in one run of a norm (`lucent_core::exact::NORM_RUN`, shared with the
/// multigrid's norm): here a run is the *unknowns* among one x-line's cells [8k, 8k + 8).
pub use lucent_core::exact::NORM_RUN;

/// The unknowns of an assembled system by z-layer, and the runs of [`NORM_RUN`] cells
/// their norms sum (see there): the norm does not depend on how the grid is split over
/// ranks or threads.
#[derive(Debug, Clone, PartialEq)]
pub struct Layers {
    /// Unknown ranges [start, end) per non-empty layer, in z order, with the layer's z.
    ranges: Vec<(usize, usize, usize)>,
    /// Unknown ranges [start, end) of the norm's runs, ascending.
    runs: Vec<(usize, usize)>,
}

impl Layers {
    /// The layers and runs of `cells` (each unknown's flat cell, ascending) on a grid of
    /// `dims` cells.
    pub fn new(cells: &[usize], dims: [usize; 3]) -> Self {
        let (nx, slab_len) = (dims[0].max(1), (dims[0] * dims[1]).max(1));
        let mut ranges: Vec<(usize, usize, usize)> = Vec::new();
        for (u, &c) in cells.iter().enumerate() {
            let z = c / slab_len;
            match ranges.last_mut() {
                Some((layer, _, end)) if *layer == z => *end = u + 1,
                _ => ranges.push((z, u, u + 1)),
            }
        }
        Self {
            ranges,
            runs: norm_runs(cells.iter().copied(), nx),
        }
    }

    /// (z, start, end) of every non-empty layer, in z order.
    pub fn ranges(&self) -> &[(usize, usize, usize)] {
        &self.ranges
    }

    /// The norm's runs of unknowns, [start, end), ascending.
    pub fn runs(&self) -> &[(usize, usize)] {
        &self.runs
    }

    /// ‖v‖₂: Σ v² by [`squares`] over the runs.
    pub fn norm(&self, v: &[f64]) -> f64 {
        squares(v, &self.runs).value().sqrt()
    }
}

/// The norm's runs of `cells` (flat cells of a grid `nx` wide, ascending), as [start, end)
/// positions: consecutive entries in the same x-line and the same [8k, 8k + 8) of it.
pub fn norm_runs(cells: impl Iterator<Item = usize>, nx: usize) -> Vec<(usize, usize)> {
    let nx = nx.max(1);
    let mut runs: Vec<(usize, usize)> = Vec::new();
    let mut last = None;
    for (u, c) in cells.enumerate() {
        let run = (c / nx, (c % nx) / NORM_RUN);
        match runs.last_mut() {
            Some((_, end)) if last == Some(run) => *end = u + 1,
            _ => runs.push((u, u + 1)),
        }
        last = Some(run);
    }
    runs
}

/// Σ v² over `runs` of `v`, each run left to right, the run sums added exactly (in
/// parallel, any order: the same bits).
pub fn squares(v: &[f64], runs: &[(usize, usize)]) -> ExactSum {
    runs.par_chunks(1024)
        .map(|runs| {
            runs.iter()
                .map(|&(s, e)| v[s..e].iter().map(|x| x * x).sum::<f64>())
                .collect::<ExactSum>()
        })
        .reduce(ExactSum::new, |mut a, b| {
            a.merge(&b);
            a
        })
}

/// The scale s_i of each row's residual in φ ← φ + s r: cΔt/V for FTCS (refused beyond
/// its Gershgorin bound unless `allow_unstable`), ω/a_ii for Jacobi (ω in (0, 1]); checks
/// the diagonal is positive. Shared with the decomposed iteration (`lucent-mpi`), so both
/// refuse and scale alike.
pub fn row_scale(
    system: &AssembledSystem,
    iteration: Iteration,
    allow_unstable: bool,
) -> Result<Vec<f64>, ExplicitError> {
    let a = &system.matrix;
    let n = system.rhs.len();
    let diagonal: Vec<f64> = (0..n)
        .map(|i| a.get(i, i).copied().unwrap_or(0.0))
        .collect();
    scale_rows(&diagonal, gershgorin(a), iteration, allow_unstable)
}

/// [`row_scale`] from the rows' diagonal and the largest Gershgorin sum max_i Σ_j |a_ij|
/// of the whole system (a rank with some rows passes the maximum over every rank's).
pub fn scale_rows(
    diagonal: &[f64],
    gershgorin: f64,
    iteration: Iteration,
    allow_unstable: bool,
) -> Result<Vec<f64>, ExplicitError> {
    if diagonal.iter().any(|&d| d <= 0.0) {
        return Err(ExplicitError::Invalid(
            "the system has a non-positive diagonal".into(),
        ));
    }
    Ok(match iteration {
        Iteration::Ftcs {
            time_step,
            cell_volume,
        } => {
            let limit = 2.0 * cell_volume / gershgorin;
            if !(time_step > 0.0 && time_step.is_finite()) {
                return Err(ExplicitError::Invalid(format!("time step {time_step}")));
            }
            if time_step > limit * (1.0 + 1e-12) && !allow_unstable {
                return Err(ExplicitError::Unstable {
                    scheme: "FTCS diffusion",
                    parameter: "cΔt",
                    limit,
                    requested: time_step,
                });
            }
            vec![time_step / cell_volume; diagonal.len()]
        }
        Iteration::Jacobi { omega } => {
            if !(omega > 0.0 && omega <= 1.0) {
                return Err(ExplicitError::Invalid(format!(
                    "Jacobi damping {omega} outside (0, 1]"
                )));
            }
            diagonal.iter().map(|d| omega / d).collect()
        }
    })
}
