//! One call to solve a [`DiffusionProblem`] with a chosen method.

use std::time::Instant;

use crate::error::DiffusionError;
use crate::krylov;
use lucent_core::Stopping;
use lucent_core::ranks::{Alone, Communicator, Threads};

use crate::multigrid::{Convergence, Multigrid, MultigridSettings};
use crate::ranks::{Decomposition, RankLayout};

/// Coarse levels go to fewer ranks below this many cells per rank.
const COARSE: usize = RankLayout::COARSE_CELLS_PER_RANK;
use crate::problem::{Balance, DiffusionProblem, Sources};

/// The iterative method.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    /// Geometric multigrid cycles (the default).
    Multigrid(MultigridSettings),
    /// Conjugate gradients preconditioned by one multigrid cycle.
    MultigridCg(MultigridSettings),
    /// Conjugate gradients with the diagonal (Jacobi) preconditioner.
    ConjugateGradient,
    /// Jacobi iteration with damping ω.
    Jacobi {
        /// Damping in (0, 1].
        omega: f64,
    },
    /// Red–black SOR with factor ω in (0, 2) (1: Gauss–Seidel).
    Sor {
        /// Relaxation factor.
        omega: f64,
    },
}

impl Default for Method {
    fn default() -> Self {
        Method::Multigrid(MultigridSettings::default())
    }
}

/// A solved problem.
#[derive(Debug, Clone, PartialEq)]
pub struct DiffusionSolution {
    /// Fluence φ per cell (W/length²; 0 outside the medium), f64.
    pub fluence: Vec<f64>,
    /// Residual history and stop reason.
    pub convergence: Convergence,
    /// Emitted, absorbed and escaped power.
    pub balance: Balance,
    /// Seconds spent building the operator (and the hierarchy).
    pub setup_seconds: f64,
    /// Seconds spent iterating.
    pub solve_seconds: f64,
    /// Multigrid levels (1 for the single-level methods).
    pub levels: usize,
    /// Bytes of operator and work vectors.
    pub memory_bytes: u64,
}

/// Solves `problem` with `sources` by `method` until `stopping` says so.
pub fn solve(
    problem: &DiffusionProblem,
    sources: &Sources,
    method: Method,
    stopping: &Stopping,
) -> Result<DiffusionSolution, DiffusionError> {
    let started = Instant::now();
    let rhs = problem.rhs(sources)?;
    let fine = problem.fine_level();
    let n = rhs.len();
    let mut phi = vec![0.0f64; n];
    let (convergence, levels, memory, setup) = match method {
        Method::Multigrid(settings) | Method::MultigridCg(settings) => {
            check_sweeps(&settings)?;
            let mg = Multigrid::new(fine, problem.boundaries(), settings);
            let setup = started.elapsed().as_secs_f64();
            let convergence = if matches!(method, Method::Multigrid(_)) {
                mg.solve(&rhs, &mut phi, stopping)
            } else {
                let mut work = mg.preconditioner_work();
                let precondition = |r: &[f64], z: &mut [f64]| mg.precondition(&mut work, r, z);
                if settings.cycle == crate::multigrid::Cycle::K {
                    krylov::flexible_conjugate_gradient(
                        mg.fine(),
                        &rhs,
                        &mut phi,
                        stopping,
                        precondition,
                    )
                } else {
                    krylov::conjugate_gradient(mg.fine(), &rhs, &mut phi, stopping, precondition)
                }
            };
            (
                convergence,
                mg.depth(),
                mg.memory_bytes() + n as u64 * 24,
                setup,
            )
        }
        Method::ConjugateGradient => {
            let setup = started.elapsed().as_secs_f64();
            let level = fine.level;
            let c = krylov::conjugate_gradient(&level, &rhs, &mut phi, stopping, |r, z| {
                z.iter_mut()
                    .zip(r)
                    .zip(&level.inv_diag)
                    .for_each(|((z, r), d)| *z = r * f64::from(*d));
            });
            (c, 1, n as u64 * (20 + 40), setup)
        }
        Method::Jacobi { omega } => {
            if !(omega > 0.0 && omega <= 1.0) {
                return Err(DiffusionError::Invalid(format!(
                    "Jacobi damping {omega} outside (0, 1]"
                )));
            }
            let setup = started.elapsed().as_secs_f64();
            let c = krylov::jacobi(&fine.level, &rhs, &mut phi, omega, stopping);
            (c, 1, n as u64 * (20 + 24), setup)
        }
        Method::Sor { omega } => {
            if !(omega > 0.0 && omega < 2.0) {
                return Err(DiffusionError::Invalid(format!(
                    "SOR factor {omega} outside (0, 2)"
                )));
            }
            let setup = started.elapsed().as_secs_f64();
            let c = krylov::sor(&fine.level, &rhs, &mut phi, omega, stopping);
            (c, 1, n as u64 * (20 + 24), setup)
        }
    };
    let solve_seconds = started.elapsed().as_secs_f64() - setup;
    let balance = problem.balance(sources, &phi);
    Ok(DiffusionSolution {
        fluence: phi,
        convergence,
        balance,
        setup_seconds: setup,
        solve_seconds,
        levels,
        memory_bytes: memory,
    })
}

/// Where a multigrid solve runs: here, on the ranks of a communicator, or on in-process
/// ranks (threads joined by channels, sharing one hierarchy).
#[derive(Clone, Copy)]
pub enum RanksOf<'a> {
    /// This process alone, on the decomposition's arithmetic (one slab): the history the
    /// other variants give (the serial [`solve`] may differ in its last bits).
    Alone,
    /// The ranks of a communicator, this process one of them.
    Communicator(&'a (dyn Communicator + Send + Sync)),
    /// This many in-process ranks.
    Threads(usize),
}

/// [`solve`] by `Method::Multigrid(settings)` split over `ranks` cut as `decomposition`
/// ([`Multigrid::solve_on_layout`]): every rank gets the whole solution, the same bits on
/// any number of ranks and either decomposition. `memory_bytes` counts one rank's hierarchy
/// and its work vectors (per in-process rank, the work vectors again).
pub fn solve_on_ranks(
    problem: &DiffusionProblem,
    sources: &Sources,
    settings: MultigridSettings,
    stopping: &Stopping,
    ranks: RanksOf<'_>,
    decomposition: Decomposition,
) -> Result<DiffusionSolution, DiffusionError> {
    let started = Instant::now();
    let rhs = problem.rhs(sources)?;
    check_sweeps(&settings)?;
    let mg = Multigrid::new(problem.fine_level(), problem.boundaries(), settings);
    let setup = started.elapsed().as_secs_f64();
    let n = rhs.len();
    // The ranks together hold each cell once in their boxes (and a halo around them): the
    // operator copied (5 f32 fields) with b, x and the smoothers' scratch (3 f32) on
    // every level (8/7 of the fine one), and the right-hand side, φ and r in f64; each
    // rank also keeps the whole φ it returns.
    let boxes = n as u64 * (32 * 8 / 7 + 24);
    let per_rank = n as u64 * 8;
    let (phi, convergence, count) = match ranks {
        RanksOf::Alone | RanksOf::Communicator(_) => {
            let mut phi = vec![0.0f64; n];
            let c = match ranks {
                RanksOf::Communicator(comm) => {
                    let layout = mg.layout(comm.size(), COARSE, decomposition)?;
                    mg.solve_on_layout(&rhs, &mut phi, stopping, comm, layout)
                }
                _ => mg.solve_on_ranks(&rhs, &mut phi, stopping, &Alone),
            }?;
            (phi, c, 1)
        }
        RanksOf::Threads(count) => {
            let (mg, rhs) = (&mg, &rhs);
            let layout = mg.layout(count, COARSE, decomposition)?;
            let mut results = Threads::run(count, |comm| {
                let mut phi = vec![0.0f64; rhs.len()];
                mg.solve_on_layout(rhs, &mut phi, stopping, comm, layout.clone())
                    .map(|c| (phi, c))
            })
            .into_iter()
            .map(|r| {
                r.unwrap_or_else(|| Err(DiffusionError::Ranks("a rank's thread panicked".into())))
            })
            .collect::<Result<Vec<_>, _>>()?;
            // Every rank holds the whole, identical result: keep rank 0's.
            let (phi, c) = results.swap_remove(0);
            (phi, c, count as u64)
        }
    };
    let solve_seconds = started.elapsed().as_secs_f64() - setup;
    let balance = problem.balance(sources, &phi);
    Ok(DiffusionSolution {
        fluence: phi,
        convergence,
        balance,
        setup_seconds: setup,
        solve_seconds,
        levels: mg.depth(),
        memory_bytes: mg.memory_bytes() + boxes + count * per_rank,
    })
}

pub(crate) fn check_sweeps(settings: &MultigridSettings) -> Result<(), DiffusionError> {
    if settings.pre_sweeps + settings.post_sweeps == 0 {
        return Err(DiffusionError::Invalid(
            "multigrid needs at least one smoothing sweep".into(),
        ));
    }
    if let crate::multigrid::Smoother::Jacobi { omega } = settings.smoother
        && !(omega > 0.0 && omega <= 1.0)
    {
        return Err(DiffusionError::Invalid(format!(
            "Jacobi smoother damping {omega} outside (0, 1]"
        )));
    }
    Ok(())
}
