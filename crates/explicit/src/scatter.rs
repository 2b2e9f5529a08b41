//! Zhang & Ma's scattering step (Eq. 23): ∂L/∂t = σ_s ∇²L with reflecting (Neumann)
//! boundaries, integrated implicitly to time t (the paper: t = 1) by backward Euler,
//! (I − a Δ_h) L^{n+1} = L^n with a = σ_s Δt/Δx², each step solved by red–black
//! Gauss–Seidel in f64 to a relative residual, or by `lucent-diffusion`'s multigrid.
//!
//! The discrete operator conserves Σ L exactly (each face's flux leaves one cell and
//! enters the other; the box's faces carry none), so the mass after a step differs from
//! the mass before only by the solver's residual (Zhang & Ma T12, docs/reference-cases.md). The impulse response of
//! one or several steps adding up to t has per-axis variance exactly 2σ_s t/Δx² cells²
//! (T13). Gauss–Seidel's rate degrades as a grows (Jacobi's spectral radius is
//! 6a/(1 + 6a)): a fixed sweep budget loses energy (T15), so this solves to a tolerance.

use lucent_core::StopReason;
use rayon::prelude::*;

use crate::error::ExplicitError;
use crate::lattice::Lattice;

/// How each implicit step is solved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StepSolver {
    /// Red–black Gauss–Seidel to a relative residual.
    GaussSeidel {
        /// Relative residual ‖L^n − (I − aΔ)L^{n+1}‖ / ‖L^n‖ to reach.
        tolerance: f64,
        /// Most sweeps per step.
        max_sweeps: usize,
    },
    /// `lucent-diffusion`'s multigrid (V(2,2) cycles, mixed precision) to a relative
    /// residual. The field passes through f32 as its source, so mass is kept to about
    /// 1e-7 relative, not to the residual.
    Multigrid {
        /// Relative residual to reach.
        tolerance: f64,
    },
}

impl Default for StepSolver {
    fn default() -> Self {
        StepSolver::GaussSeidel {
            tolerance: 1e-13,
            max_sweeps: 100_000,
        }
    }
}

/// The result of [`diffuse`].
#[derive(Debug, Clone, PartialEq)]
pub struct Diffused {
    /// L at time t.
    pub field: Vec<f64>,
    /// Sweeps (or cycles) over all steps.
    pub iterations: usize,
    /// Why the last step's solve stopped.
    pub stop_reason: StopReason,
}

/// Integrates ∂L/∂t = σ_s ∇²L from `field` for time `time` in `steps` backward-Euler steps.
/// σ_s and t in the lattice's units (σ_s: length²/time, so that a = σ_s Δt/Δx² is
/// dimensionless).
pub fn diffuse(
    lattice: &Lattice,
    field: &[f64],
    sigma_s: f64,
    time: f64,
    steps: usize,
    solver: StepSolver,
) -> Result<Diffused, ExplicitError> {
    lattice.check_field("field", field)?;
    if !(sigma_s >= 0.0 && sigma_s.is_finite() && time >= 0.0 && time.is_finite()) || steps == 0 {
        return Err(ExplicitError::Invalid(format!(
            "σ_s = {sigma_s}, t = {time}, {steps} steps: need σ_s ≥ 0, t ≥ 0, one step or more"
        )));
    }
    let a = sigma_s * time / steps as f64 / lattice.spacing.powi(2);
    let mut current = field.to_vec();
    let mut iterations = 0;
    let mut stop_reason = StopReason::Exact;
    if a == 0.0 {
        return Ok(Diffused {
            field: current,
            iterations,
            stop_reason,
        });
    }
    let scatterer = match solver {
        StepSolver::Multigrid { .. } => Some(Scatterer::new(lattice, a)?),
        StepSolver::GaussSeidel { .. } => None,
    };
    for _ in 0..steps {
        let (next, its, reason) = match (&scatterer, solver) {
            (Some(s), StepSolver::Multigrid { tolerance }) => s.step(&current, tolerance)?,
            (
                _,
                StepSolver::GaussSeidel {
                    tolerance,
                    max_sweeps,
                },
            ) => gauss_seidel_step(lattice, &current, a, tolerance, max_sweeps),
            (None, StepSolver::Multigrid { tolerance }) => {
                Scatterer::new(lattice, a)?.step(&current, tolerance)?
            }
        };
        iterations += its;
        stop_reason = reason;
        current = next;
        if !stop_reason.is_converged() {
            break;
        }
    }
    Ok(Diffused {
        field: current,
        iterations,
        stop_reason,
    })
}

/// (1 + a·faces) x_i − a Σ x_nb for cell g: faces are the neighbours that exist.
fn row(lattice: &Lattice, x: &[f64], g: usize, a: f64) -> (f64, f64) {
    let at = lattice.coords(g);
    let s = lattice.strides();
    let (mut sum, mut faces) = (0.0, 0.0);
    for axis in 0..3 {
        if at[axis] > 0 {
            sum += x[g - s[axis]];
            faces += 1.0;
        }
        if at[axis] + 1 < lattice.dims[axis] {
            sum += x[g + s[axis]];
            faces += 1.0;
        }
    }
    (1.0 + a * faces, a * sum)
}

fn gauss_seidel_step(
    lattice: &Lattice,
    rhs: &[f64],
    a: f64,
    tolerance: f64,
    max_sweeps: usize,
) -> (Vec<f64>, usize, StopReason) {
    let n = lattice.len();
    let slab = lattice.dims[0] * lattice.dims[1];
    let norm = rhs
        .iter()
        .map(|v| v * v)
        .sum::<f64>()
        .sqrt()
        .max(f64::MIN_POSITIVE);
    let mut x = rhs.to_vec();
    let mut next = vec![0.0; n];
    let started = std::time::Instant::now();
    for sweep in 1..=max_sweeps {
        // Each colour reads only the other, so computing it into `next` from `x` and
        // copying the other colour is exactly Gauss–Seidel.
        for colour in [0, 1] {
            let current = &x;
            next.par_chunks_mut(slab).enumerate().for_each(|(k, out)| {
                for (l, o) in out.iter_mut().enumerate() {
                    let g = k * slab + l;
                    let at = lattice.coords(g);
                    *o = if (at[0] + at[1] + at[2]) % 2 == colour {
                        let (diag, off) = row(lattice, current, g, a);
                        (rhs[g] + off) / diag
                    } else {
                        current[g]
                    };
                }
            });
            std::mem::swap(&mut x, &mut next);
        }
        let residual = (0..n)
            .into_par_iter()
            .map(|g| {
                let (diag, off) = row(lattice, &x, g, a);
                let r = rhs[g] - (diag * x[g] - off);
                r * r
            })
            .sum::<f64>()
            .sqrt()
            / norm;
        let stopping = lucent_core::Stopping {
            relative_tolerance: tolerance,
            max_iterations: max_sweeps,
            ..lucent_core::Stopping::default()
        };
        if let Some(reason) = stopping.verdict(sweep, residual, residual * norm, 1.0, started) {
            return (x, sweep, reason);
        }
    }
    (x, 0, StopReason::Exact)
}

/// The multigrid hierarchy of one backward-Euler step, built once and reused for every
/// step and every frame with the same grid and a = σ_s Δt/Δx² (what an interactive
/// renderer keeps between transfer-function edits).
#[derive(Debug, Clone)]
pub struct Scatterer {
    multigrid: lucent_diffusion::Multigrid,
    volume: f64,
    cells: usize,
}

impl Scatterer {
    /// The hierarchy for (I − aΔ_h) on `lattice` with reflecting walls.
    pub fn new(lattice: &Lattice, a: f64) -> Result<Self, ExplicitError> {
        use lucent_diffusion::{
            Boundaries, CellGeometry, Condition, DiffusionProblem, Multigrid, MultigridSettings,
        };
        let invalid = |e: &dyn std::fmt::Display| ExplicitError::Invalid(e.to_string());
        if !(a > 0.0 && a.is_finite()) {
            return Err(ExplicitError::Invalid(format!("a = {a}: must be positive")));
        }
        let h = lattice.spacing;
        let dims = lattice.dims;
        let grid = lucent_grid::GridGeometry::from_bounds(
            dims,
            lattice.origin,
            lattice.origin + glam::DVec3::from_array(dims.map(|n| n as f64)) * h,
        )
        .map_err(|e| invalid(&e))?;
        let n = lattice.len();
        // −∇·(D∇x) + x = L with D = a h², integrated over cells of volume h³.
        let problem = DiffusionProblem::new(
            CellGeometry::full_box(grid),
            vec![(a * h * h) as f32; n],
            vec![1.0; n],
            Boundaries::uniform(Condition::Neumann { flux: 0.0 }),
        )
        .map_err(|e| invalid(&e))?;
        Ok(Self {
            multigrid: Multigrid::build(&problem, MultigridSettings::default())
                .map_err(|e| invalid(&e))?,
            volume: h * h * h,
            cells: n,
        })
    }

    /// One step from `field` to a relative residual `tolerance`.
    pub fn step(
        &self,
        field: &[f64],
        tolerance: f64,
    ) -> Result<(Vec<f64>, usize, StopReason), ExplicitError> {
        if field.len() != self.cells {
            return Err(ExplicitError::Invalid(format!(
                "{} values for {} cells",
                field.len(),
                self.cells
            )));
        }
        let rhs: Vec<f64> = field.iter().map(|v| v * self.volume).collect();
        let mut out = field.to_vec();
        let stopping = lucent_core::Stopping {
            relative_tolerance: tolerance,
            ..lucent_core::Stopping::default()
        };
        let c = self.multigrid.solve(&rhs, &mut out, &stopping);
        Ok((out, c.iterations(), c.stop_reason))
    }
}
