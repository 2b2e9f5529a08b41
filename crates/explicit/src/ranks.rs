//! The explicit schemes split over ranks by z-slabs, the same bits on any number of ranks:
//! [`iterate`], FTCS and Jacobi to steady state on an assembled diffusion system (the twin
//! of [`crate::steady::iterate`]), [`iterate_block`], the same from rows each rank builds
//! for its own layers of a medium filling the box (no rank holds the whole system), and
//! [`march_p1`], P1 by FTCS (the twin of [`crate::p1::march`]). For the steady iterations:
//!
//! Each rank owns the unknowns of a run of z-layers (contiguous in the system's order:
//! cells ascend, z slowest), keeps its rows with their columns renumbered into a local
//! vector laid out as [halo below | owned | halo above] — an order-preserving map, so each
//! row's products are summed in the serial order —, and per sweep
//!
//! 1. updates its owned φ from its residual (elementwise, as serially);
//! 2. starts sending the owned values its neighbours' rows read, computes the rows that
//!    read no halo while they travel, then the rows next to the neighbours;
//! 3. sums r² per layer, left to right, and all-gathers the layer sums with each rank's
//!    time-budget and cancel flags; every rank adds the layer sums in z order (the serial
//!    `Layers::norm`) and takes one stopping decision.
//!
//! Deterministic stops (tolerances, iteration limit, divergence) follow from the identical
//! residual; the time budget and cancellation, which differ per rank, travel with the
//! gather, so no rank stops alone.

use crate::ExplicitError;
use crate::steady::{Iteration, Layers, Steady, SteadySettings, gershgorin, row_scale, scale_rows};
use lucent_core::{History, StopReason, Stopping};
use lucent_diffusion::AssembledSystem;
use rayon::prelude::*;
use sprs::CsMat;

/// Why a decomposed solve could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecompositionError {
    /// More ranks than z-layers holding unknowns.
    #[error(
        "{ranks} ranks for {layers} z-layers with unknowns: every rank needs at least one layer"
    )]
    TooManyRanks {
        /// Ranks asked for.
        ranks: usize,
        /// Layers there are.
        layers: usize,
    },
    /// A row reads beyond the neighbouring slabs (slabs thinner than the stencil).
    #[error("rank {rank}: the stencil reaches past the neighbouring slabs (use fewer ranks)")]
    StencilTooWide {
        /// The rank.
        rank: usize,
    },
    /// The ranks' blocks of rows are not consecutive runs of layers from the grid's first
    /// to its last (`iterate_block`).
    #[error(
        "rank {rank}'s block of rows does not follow on from the previous rank's (blocks must be consecutive runs of layers covering the grid)"
    )]
    Blocks {
        /// The first rank whose block is out of place.
        rank: usize,
    },
    /// The system cannot be iterated.
    #[error("the system: {0}")]
    Matrix(String),
    /// The iteration refused the system or its step (`steady::row_scale`).
    #[error(transparent)]
    Scheme(#[from] crate::ExplicitError),
    /// What this march cannot split over ranks (it runs in one process).
    #[error("{0}")]
    Unsupported(String),
    /// A neighbour sent what the plan did not expect (a rank stopped or diverged from the
    /// protocol).
    #[error("rank {rank}: a halo or gather did not match the decomposition")]
    Protocol {
        /// The rank that noticed.
        rank: usize,
    },
}

use lucent_core::ranks::{Communicator, exchange};

/// Which layers (indices into [`Layers::ranges`]) each rank owns: contiguous runs in z,
/// balanced by unknowns (each rank takes layers until it holds its share).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Slabs {
    /// Per rank, [first layer, end layer).
    pub layers: Vec<(usize, usize)>,
}

impl Slabs {
    /// `ranks` slabs of `layers`; every rank gets at least one layer.
    pub fn new(layers: &Layers, ranks: usize) -> Result<Self, DecompositionError> {
        let ranges = layers.ranges();
        if ranks == 0 || ranks > ranges.len() {
            return Err(DecompositionError::TooManyRanks {
                ranks,
                layers: ranges.len(),
            });
        }
        let total = ranges.last().map_or(0, |r| r.2);
        let mut out = Vec::with_capacity(ranks);
        let mut first = 0;
        for rank in 0..ranks {
            let left = ranks - rank;
            // The share of what is left; leave one layer for each rank after this one.
            let target = ranges[first].1 + (total - ranges[first].1).div_ceil(left);
            let mut end = first + 1;
            while end < ranges.len() - (left - 1) && ranges[end - 1].2 < target {
                end += 1;
            }
            if rank == ranks - 1 {
                end = ranges.len();
            }
            out.push((first, end));
            first = end;
        }
        Ok(Self { layers: out })
    }
}

/// One rank's rows of the system, renumbered locally.
struct Part {
    /// The owned unknowns [u0, u1) of the global system.
    u0: usize,
    u1: usize,
    /// Global indices of the halo below and above, ascending.
    below: Vec<usize>,
    above: Vec<usize>,
    /// Owned rows, columns in local numbering ([below | owned | above]).
    rows: CsMat<f64>,
    /// Rows that read no halo value (computed while the halo travels), and the others.
    interior: Vec<usize>,
    border: Vec<usize>,
    /// Owned positions (local to the owned block) whose values rank − 1 and rank + 1 read.
    send_below: Vec<usize>,
    send_above: Vec<usize>,
}

fn halo_of(
    a: &CsMat<f64>,
    rows: std::ops::Range<usize>,
    keep: impl Fn(usize) -> bool,
) -> Vec<usize> {
    let mut out: Vec<usize> = rows
        .flat_map(|i| {
            a.outer_view(i)
                .into_iter()
                .flat_map(|r| r.indices().to_vec())
        })
        .filter(|&j| keep(j))
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// Rows `rows` of `a` (columns: global unknowns) with their columns renumbered into a local
/// vector [`below` | the owned unknowns `owned` | `above`] (an order-preserving map, so each
/// row's products are summed in the serial order).
fn renumber(
    a: &CsMat<f64>,
    rows: std::ops::Range<usize>,
    owned: std::ops::Range<usize>,
    below: &[usize],
    above: &[usize],
) -> Result<LocalRows, DecompositionError> {
    let own = owned.len();
    let local = |j: usize| -> usize {
        if j < owned.start {
            below.binary_search(&j).unwrap_or(0)
        } else if j < owned.end {
            below.len() + (j - owned.start)
        } else {
            below.len() + own + above.binary_search(&j).unwrap_or(0)
        }
    };
    let mut indptr = vec![0usize];
    let (mut indices, mut data) = (Vec::new(), Vec::new());
    let (mut interior, mut border) = (Vec::new(), Vec::new());
    for (t, i) in rows.clone().enumerate() {
        let mut reads_halo = false;
        if let Some(row) = a.outer_view(i) {
            for (j, &v) in row.iter() {
                reads_halo |= !owned.contains(&j);
                indices.push(local(j));
                data.push(v);
            }
        }
        indptr.push(indices.len());
        if reads_halo {
            &mut border
        } else {
            &mut interior
        }
        .push(t);
    }
    let width = below.len() + own + above.len();
    let matrix = CsMat::try_new((rows.len(), width), indptr, indices, data)
        .map_err(|e| DecompositionError::Matrix(e.3.to_string()))?;
    Ok(LocalRows {
        matrix,
        interior,
        border,
    })
}

/// [`renumber`]'s rows: the matrix in local columns, and its rows (local) that read no
/// halo value and those that do.
struct LocalRows {
    matrix: CsMat<f64>,
    interior: Vec<usize>,
    border: Vec<usize>,
}

impl Part {
    fn new(
        a: &CsMat<f64>,
        bounds: &[(usize, usize)],
        rank: usize,
    ) -> Result<Self, DecompositionError> {
        let (u0, u1) = bounds[rank];
        let below = halo_of(a, u0..u1, |j| j < u0);
        let above = halo_of(a, u0..u1, |j| j >= u1);
        // The stencil reaches the neighbouring slabs only.
        let lowest = if rank > 0 { bounds[rank - 1].0 } else { 0 };
        let highest = bounds.get(rank + 1).map_or(u1, |b| b.1);
        if below.first().is_some_and(|&j| j < lowest) || above.last().is_some_and(|&j| j >= highest)
        {
            return Err(DecompositionError::StencilTooWide { rank });
        }
        let LocalRows {
            matrix: rows,
            interior,
            border,
        } = renumber(a, u0..u1, u0..u1, &below, &above)?;
        // What the neighbours read of ours: their halos, computed from their rows.
        let send_below = if rank > 0 {
            let (v0, v1) = bounds[rank - 1];
            halo_of(a, v0..v1, |j| (u0..u1).contains(&j))
                .iter()
                .map(|j| j - u0)
                .collect()
        } else {
            Vec::new()
        };
        let send_above = if let Some(&(w0, w1)) = bounds.get(rank + 1) {
            halo_of(a, w0..w1, |j| (u0..u1).contains(&j))
                .iter()
                .map(|j| j - u0)
                .collect()
        } else {
            Vec::new()
        };
        Ok(Self {
            u0,
            u1,
            below,
            above,
            rows,
            interior,
            border,
            send_below,
            send_above,
        })
    }
}

/// The residual b − Aφ of owned row `i` (local), reading the local vector `x`.
fn row_residual(rows: &CsMat<f64>, b: &[f64], x: &[f64], i: usize) -> f64 {
    let ax: f64 = rows
        .outer_view(i)
        .map_or(0.0, |row| row.iter().map(|(j, v)| v * x[j]).sum());
    b[i] - ax
}

/// Iterates `system` (the whole system, as every rank assembles it) from zero to the
/// stopping rule on the ranks of `comm`, each doing its slab's rows; `slab_len` is the
/// grid's n_x·n_y. Returns the whole φ on every rank (gathered at the end) and the
/// residual history: the bits of `lucent_explicit::steady::iterate` on one rank.
/// [`iterate_block`] is the same iteration from rows each rank builds for its own layers.
pub fn iterate(
    system: &AssembledSystem,
    slab_len: usize,
    iteration: Iteration,
    settings: &SteadySettings,
    comm: &(impl Communicator + ?Sized),
) -> Result<Steady, DecompositionError> {
    let a = &system.matrix;
    let n = system.rhs.len();
    let layers = Layers::new(&system.cells, slab_len);
    let slabs = Slabs::new(&layers, comm.size())?;
    let ranges = layers.ranges();
    let bounds: Vec<(usize, usize)> = slabs
        .layers
        .iter()
        .map(|&(l0, l1)| (ranges[l0].1, ranges[l1 - 1].2))
        .collect();
    let rank = comm.rank();
    let part = Part::new(a, &bounds, rank)?;
    let (l0, l1) = slabs.layers[rank];
    let my_layers: Vec<(usize, usize)> = ranges[l0..l1]
        .iter()
        .map(|&(_, s, e)| (s - part.u0, e - part.u0))
        .collect();
    // The serial iteration's checks and per-row scale, then this rank's rows of it.
    let scale = row_scale(system, iteration, settings.allow_unstable)?[part.u0..part.u1].to_vec();
    let counts: Vec<usize> = slabs.layers.iter().map(|&(a, b)| b - a).collect();
    let b = &system.rhs[part.u0..part.u1];
    let (owned, residuals, stop_reason) =
        sweep(&part, b, &scale, &my_layers, &counts, settings, comm)?;
    // The serial rule, on the gathered whole: any non-finite φ zeroes all of it.
    let mut fluence = comm.all_gather(&owned);
    if fluence.len() != n {
        return Err(DecompositionError::Protocol { rank });
    }
    if fluence.iter().any(|v| !v.is_finite()) {
        fluence.fill(0.0);
    }
    Ok(Steady {
        fluence,
        residuals,
        stop_reason,
    })
}

/// The result of [`iterate_block`]: this rank's layers of φ, and the history and stop
/// reason every rank shares.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockSteady {
    /// φ of the block's cells (its layers, in the grid's order).
    pub fluence: Vec<f64>,
    /// Relative residual before each sweep and after the last.
    pub residuals: Vec<f64>,
    /// Why it stopped.
    pub stop_reason: StopReason,
}

/// [`iterate`] from the rows of a medium that fills the box, each rank holding only its
/// own: `block` is this rank's layers' rows and right-hand side
/// (`lucent_diffusion::SlabSystem::block`, built from its layers of the coefficients and
/// D's layer on either side), `slab_len` the grid's n_x·n_y. The blocks of ranks 0, 1, …
/// must be consecutive runs of layers from the first to the last. No rank holds more than
/// its rows, four vectors of its layers and a halo layer each side; the ranks learn what
/// to send each other from one exchange of the columns their rows read, and agree on the
/// checks (the diagonal, the FTCS bound from the largest Gershgorin sum of all rows, a
/// stencil that reaches no further than the neighbours, a missing layer) before the first
/// sweep, so a bad block stops every rank with the same error. On return each rank holds
/// its layers of φ (zeroed, on every rank, if any is not finite, as the serial rule does);
/// they and the history are the bits of `steady::iterate` on the assembled whole.
///
/// # Errors
/// [`DecompositionError::Scheme`] for what the serial iteration refuses (a non-positive
/// diagonal, an FTCS step beyond the bound, a damping outside (0, 1]);
/// [`DecompositionError::Blocks`] for blocks that are not consecutive runs of layers
/// covering the grid; [`DecompositionError::StencilTooWide`] for rows that read past the
/// neighbouring blocks (or rows and right-hand side that do not fit the block's layers); a
/// rank that left the protocol.
pub fn iterate_block(
    block: &lucent_diffusion::slab::Block,
    slab_len: usize,
    iteration: Iteration,
    settings: &SteadySettings,
    comm: &(impl Communicator + ?Sized),
) -> Result<BlockSteady, DecompositionError> {
    let rank = comm.rank();
    let slab = slab_len.max(1);
    let a = &block.matrix;
    let own = a.rows();
    let u0 = block.layers.start * slab;
    let u1 = u0 + own;
    let lengths_fit = own == block.layers.len() * slab && block.rhs.len() == own;
    // The columns this block reads beyond its rows, as global indices.
    let below = halo_of(a, 0..own, |j| j < u0);
    let above = halo_of(a, 0..own, |j| j >= u1);
    let encode = |v: &[usize]| -> Vec<f64> { v.iter().map(|&j| j as f64).collect() };
    // Tell each neighbour what this block reads of it; learn what it reads of this one.
    let (wants_below, wants_above) = {
        let (b, a, ()) = exchange(comm, &encode(&below), &encode(&above), || ());
        (b, a)
    };
    let decode = |v: &[f64]| -> Option<Vec<usize>> {
        v.iter()
            .map(|&j| {
                let whole = j >= 0.0 && j.fract() == 0.0;
                let j = j as usize;
                (whole && (u0..u1).contains(&j)).then(|| j - u0)
            })
            .collect()
    };
    let (send_below, send_above) = (decode(&wants_below), decode(&wants_above));
    // Reads past the ends, or requests for cells this block does not hold, or holes
    // between neighbouring blocks: the blocks do not join up.
    let reads_past = (rank == 0 && !below.is_empty())
        || (rank + 1 == comm.size() && !above.is_empty())
        || below.first().is_some_and(|&j| j + slab < u0)
        || above.last().is_some_and(|&j| j >= u1 + slab);
    let too_wide = !lengths_fit || reads_past || send_below.is_none() || send_above.is_none();
    let diagonal: Vec<f64> = (0..own)
        .map(|i| a.get(i, u0 + i).copied().unwrap_or(0.0))
        .collect();
    let layer_count = block.layers.len() as f64;
    let agreed = comm.all_gather(&[
        f64::from(u8::from(too_wide)),
        f64::from(u8::from(diagonal.iter().any(|&d| d <= 0.0))),
        gershgorin(a),
        block.layers.start as f64,
        layer_count,
    ]);
    if agreed.len() != 5 * comm.size() {
        return Err(DecompositionError::Protocol { rank });
    }
    let flags: Vec<&[f64]> = agreed.chunks(5).collect();
    // Consecutive blocks from the first layer to the last.
    let mut next = 0.0;
    for (r, f) in flags.iter().enumerate() {
        if f[3] != next || f[4] < 1.0 {
            return Err(DecompositionError::Blocks { rank: r });
        }
        next = f[3] + f[4];
    }
    if next != (a.cols() / slab) as f64 {
        return Err(DecompositionError::Blocks {
            rank: comm.size() - 1,
        });
    }
    if let Some(r) = flags.iter().position(|f| f[0] != 0.0) {
        return Err(DecompositionError::StencilTooWide { rank: r });
    }
    if flags.iter().any(|f| f[1] != 0.0) {
        return Err(ExplicitError::Invalid("the system has a non-positive diagonal".into()).into());
    }
    let largest = flags.iter().map(|f| f[2]).fold(0.0, f64::max);
    let scale = scale_rows(&diagonal, largest, iteration, settings.allow_unstable)?;
    let LocalRows {
        matrix: rows,
        interior,
        border,
    } = renumber(a, 0..own, u0..u1, &below, &above)?;
    let part = Part {
        u0,
        u1,
        below,
        above,
        rows,
        interior,
        border,
        send_below: send_below.unwrap_or_default(),
        send_above: send_above.unwrap_or_default(),
    };
    let my_layers: Vec<(usize, usize)> = (0..block.layers.len())
        .map(|t| (t * slab, (t + 1) * slab))
        .collect();
    let counts: Vec<usize> = flags.iter().map(|f| f[4] as usize).collect();
    let (mut fluence, residuals, stop_reason) = sweep(
        &part, &block.rhs, &scale, &my_layers, &counts, settings, comm,
    )?;
    // The serial rule: any non-finite φ anywhere zeroes all of it.
    let finite = f64::from(u8::from(fluence.iter().all(|v| v.is_finite())));
    let all = comm.all_gather(&[finite]);
    if all.len() != comm.size() {
        return Err(DecompositionError::Protocol { rank });
    }
    if all.contains(&0.0) {
        fluence.fill(0.0);
    }
    Ok(BlockSteady {
        fluence,
        residuals,
        stop_reason,
    })
}

/// The FTCS step bound of the system whose rows the ranks' blocks hold, on every rank:
/// 2V / max_i Σ_j |a_ij| over all of them (`steady::ftcs_limit` of the assembled whole,
/// the same bits), for choosing the step of [`iterate_block`].
///
/// # Errors
/// [`DecompositionError::Protocol`] if a rank left the protocol.
pub fn block_ftcs_limit(
    block: &lucent_diffusion::slab::Block,
    cell_volume: f64,
    comm: &(impl Communicator + ?Sized),
) -> Result<f64, DecompositionError> {
    let all = comm.all_gather(&[gershgorin(&block.matrix)]);
    if all.len() != comm.size() {
        return Err(DecompositionError::Protocol { rank: comm.rank() });
    }
    Ok(2.0 * cell_volume / all.into_iter().fold(0.0, f64::max))
}

/// The sweeps from zero: this rank's owned φ, the residual history and the stop reason.
/// `b` and `scale` are the owned rows'; `my_layers` the owned unknowns' ranges per layer
/// (local), `counts` every rank's number of layers.
fn sweep(
    part: &Part,
    b: &[f64],
    scale: &[f64],
    my_layers: &[(usize, usize)],
    counts: &[usize],
    settings: &SteadySettings,
    comm: &(impl Communicator + ?Sized),
) -> Result<(Vec<f64>, Vec<f64>, StopReason), DecompositionError> {
    let rank = comm.rank();
    let own = part.u1 - part.u0;
    // Deterministic stops from the shared residual; the clock and the cancel flag are
    // each rank's own and travel with the layer sums.
    let shared = Stopping {
        time_budget: None,
        cancel: None,
        progress: if rank == 0 {
            settings.stopping.progress.clone()
        } else {
            None
        },
        ..settings.stopping.clone()
    };
    let mut history = History::start();
    let started = std::time::Instant::now();
    let local_flags = || -> [f64; 2] {
        let s = &settings.stopping;
        [
            f64::from(u8::from(
                s.time_budget.is_some_and(|t| started.elapsed() >= t),
            )),
            f64::from(u8::from(
                s.cancel
                    .as_ref()
                    .is_some_and(|c| c.load(std::sync::atomic::Ordering::Relaxed)),
            )),
        ]
    };
    // Layer sums of squares of v (owned), gathered with flags: (norm, any time, any cancel).
    let gather = |v: &[f64]| -> Result<(f64, bool, bool), DecompositionError> {
        let mut local = local_flags().to_vec();
        local.extend(
            my_layers
                .par_iter()
                .map(|&(s, e)| v[s..e].iter().map(|x| x * x).sum::<f64>())
                .collect::<Vec<f64>>(),
        );
        let all = comm.all_gather(&local);
        if all.len() != counts.iter().map(|c| c + 2).sum::<usize>() {
            return Err(DecompositionError::Protocol { rank });
        }
        let (mut sum, mut time, mut cancel, mut at) = (0.0f64, false, false, 0);
        for &c in counts {
            time |= all[at] != 0.0;
            cancel |= all[at + 1] != 0.0;
            for s in &all[at + 2..at + 2 + c] {
                sum += s;
            }
            at += 2 + c;
        }
        Ok((sum.sqrt(), time, cancel))
    };
    let (b_norm, mut time_up, mut cancelled) = gather(b)?;
    let b_norm = b_norm.max(f64::MIN_POSITIVE);
    let (nb, na) = (part.below.len(), part.above.len());
    let mut x = vec![0.0f64; nb + own + na];
    let mut r = b.to_vec();
    let mut relative = 1.0;
    let stop_reason = loop {
        if let Some(reason) = history.record(&shared, relative, relative * b_norm) {
            break reason;
        }
        if time_up {
            break StopReason::TimeLimit { residual: relative };
        }
        if cancelled {
            break StopReason::Interrupted { residual: relative };
        }
        x[nb..nb + own]
            .par_iter_mut()
            .zip(r.par_iter())
            .zip(scale.par_iter())
            .for_each(|((p, r), s)| *p += s * r);
        let owned = &x[nb..nb + own];
        let to_below: Vec<f64> = part.send_below.iter().map(|&i| owned[i]).collect();
        let to_above: Vec<f64> = part.send_above.iter().map(|&i| owned[i]).collect();
        let xs = &x;
        let (from_below, from_above, interior) = exchange(comm, &to_below, &to_above, || {
            part.interior
                .par_iter()
                .map(|&i| row_residual(&part.rows, b, xs, i))
                .collect::<Vec<f64>>()
        });
        if from_below.len() != nb || from_above.len() != na {
            return Err(DecompositionError::Protocol { rank });
        }
        x[..nb].copy_from_slice(&from_below);
        x[nb + own..].copy_from_slice(&from_above);
        for (&i, v) in part.interior.iter().zip(interior) {
            r[i] = v;
        }
        let xs = &x;
        let border: Vec<f64> = part
            .border
            .par_iter()
            .map(|&i| row_residual(&part.rows, b, xs, i))
            .collect();
        for (&i, v) in part.border.iter().zip(border) {
            r[i] = v;
        }
        let (norm, t, c) = gather(&r)?;
        relative = norm / b_norm;
        time_up = t;
        cancelled = c;
    };
    Ok((
        x[nb..nb + own].to_vec(),
        history.into_residuals(),
        stop_reason,
    ))
}

/// [`iterate`] on `ranks` in-process ranks (threads joined by channels, sharing `system`):
/// rank 0's result, which every rank holds.
pub fn iterate_on_threads(
    system: &AssembledSystem,
    slab_len: usize,
    iteration: Iteration,
    settings: &SteadySettings,
    ranks: usize,
) -> Result<Steady, DecompositionError> {
    on_threads(ranks, |comm| {
        iterate(system, slab_len, iteration, settings, comm)
    })
}

/// Runs `solve` on `ranks` in-process ranks and returns rank 0's result, or the first
/// rank's error (a rank whose thread panicked: [`DecompositionError::Protocol`]).
pub(crate) fn on_threads<T: Send>(
    ranks: usize,
    solve: impl Fn(&lucent_core::ranks::Threads) -> Result<T, DecompositionError> + Sync,
) -> Result<T, DecompositionError> {
    let mut results = lucent_core::ranks::Threads::run(ranks, solve)
        .into_iter()
        .enumerate()
        .map(|(rank, r)| r.unwrap_or(Err(DecompositionError::Protocol { rank })))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(results.swap_remove(0))
}

/// [`crate::p1::march`] from zero, split over the ranks of `comm` by z-layers (balanced by
/// count): per step each rank sends its first and last layer of (φ, E) to its neighbours,
/// steps its inner layers while they travel, then its two edge layers; the growth
/// monitor's largest values and finiteness, the change and size sums per layer, and the
/// time and cancel flags are all-gathered, and every rank takes the serial decision. A
/// rank holds the state of its layers and one halo layer each side only (eight f64 fields
/// of (owned + 2) layers); the whole state is gathered on every rank at the end, the
/// serial bits on any number of ranks.
///
/// # Errors
/// The serial march's refusals ([`DecompositionError::Scheme`]); periodic edges on more
/// than one rank (the decomposition has no wrap-around neighbours); more ranks than
/// layers; a rank that left the protocol.
pub fn march_p1(
    lattice: &crate::Lattice,
    source: &[f64],
    settings: &crate::p1::P1Settings,
    comm: &(impl Communicator + ?Sized),
) -> Result<crate::p1::P1State, DecompositionError> {
    use crate::p1::{P1Edges, P1State, StepCoefficients, growth_monitor, layer_norms, step_layers};
    lattice.check_field("source", source)?;
    let step_of = StepCoefficients::checked(settings, lattice.spacing)?;
    let (size, rank) = (comm.size(), comm.rank());
    let [nx, ny, nz] = lattice.dims;
    if size == 0 || size > nz {
        return Err(DecompositionError::TooManyRanks {
            ranks: size,
            layers: nz,
        });
    }
    if size > 1 && settings.edges == P1Edges::Periodic {
        return Err(DecompositionError::Scheme(crate::ExplicitError::Invalid(
            "periodic edges do not split over ranks (no wrap-around neighbours): use zero edges"
                .into(),
        )));
    }
    let bounds: Vec<(usize, usize)> = (0..size)
        .map(|r| (r * nz / size, (r + 1) * nz / size))
        .collect();
    let (k0, k1) = bounds[rank];
    let slab = nx * ny;
    let n = lattice.len();
    // This rank's layers and one halo layer each side within the grid: all it holds of
    // the state (cell g of the grid at g − first).
    let (lo, hi) = (k0.saturating_sub(1), (k1 + 1).min(nz));
    let (first, len) = (lo * slab, (hi - lo) * slab);
    let local_source = &source[first..first + len];
    let largest = source.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    let monitor = growth_monitor(0.0, largest, settings);
    let shared = Stopping {
        time_budget: None,
        cancel: None,
        progress: if rank == 0 {
            settings.stopping.progress.clone()
        } else {
            None
        },
        ..settings.stopping.clone()
    };
    let started = std::time::Instant::now();
    let mut history = History::start();
    let fields = || {
        (
            vec![0.0; len],
            [vec![0.0; len], vec![0.0; len], vec![0.0; len]],
        )
    };
    let ((mut phi, mut flux), (mut next_phi, mut next_flux)) = (fields(), fields());
    // The layers that read no halo (stepped while the halos travel), and the others.
    let (inner, edges) = if k1 - k0 <= 2 {
        (k0..k0, (k0..k1).map(|k| k..k + 1).collect::<Vec<_>>())
    } else {
        (k0 + 1..k1 - 1, vec![k0..k0 + 1, k1 - 1..k1])
    };
    let layer = |fields: (&[f64], &[Vec<f64>; 3]), k: usize| -> Vec<f64> {
        let range = (k - lo) * slab..(k - lo + 1) * slab;
        let mut out = fields.0[range.clone()].to_vec();
        for f in fields.1 {
            out.extend_from_slice(&f[range.clone()]);
        }
        out
    };
    let counts: Vec<usize> = bounds.iter().map(|&(a, b)| b - a).collect();
    let mut step = 0;
    let stop_reason = loop {
        step += 1;
        let to_below = if rank > 0 {
            layer((&phi, &flux), k0)
        } else {
            Vec::new()
        };
        let to_above = if rank + 1 < size {
            layer((&phi, &flux), k1 - 1)
        } else {
            Vec::new()
        };
        let (from_below, from_above, ()) = exchange(comm, &to_below, &to_above, || {
            step_layers(
                lattice,
                &step_of,
                settings.edges,
                (&phi, &flux),
                (&mut next_phi, &mut next_flux),
                (local_source, first),
                inner.clone(),
            );
        });
        for (received, k, present) in [
            (from_below, k0.wrapping_sub(1), rank > 0),
            (from_above, k1, rank + 1 < size),
        ] {
            if !present {
                continue;
            }
            if received.len() != 4 * slab {
                return Err(DecompositionError::Protocol { rank });
            }
            let range = (k - lo) * slab..(k - lo + 1) * slab;
            phi[range.clone()].copy_from_slice(&received[..slab]);
            for (a, f) in flux.iter_mut().enumerate() {
                f[range.clone()].copy_from_slice(&received[(a + 1) * slab..(a + 2) * slab]);
            }
        }
        for edge in &edges {
            step_layers(
                lattice,
                &step_of,
                settings.edges,
                (&phi, &flux),
                (&mut next_phi, &mut next_flux),
                (local_source, first),
                edge.clone(),
            );
        }
        // [time, cancel, finite ×4, largest ×4, (change, size) per layer].
        let owned = (k0 - lo) * slab..(k1 - lo) * slab;
        let mut local = vec![
            f64::from(u8::from(
                settings
                    .stopping
                    .time_budget
                    .is_some_and(|t| started.elapsed() >= t),
            )),
            f64::from(u8::from(
                settings
                    .stopping
                    .cancel
                    .as_ref()
                    .is_some_and(|c| c.load(std::sync::atomic::Ordering::Relaxed)),
            )),
        ];
        let fields = [&next_phi, &next_flux[0], &next_flux[1], &next_flux[2]];
        for f in fields {
            local.push(f64::from(u8::from(
                f[owned.clone()].iter().all(|v| v.is_finite()),
            )));
        }
        for f in fields {
            local.push(f[owned.clone()].iter().fold(0.0f64, |a, b| a.max(b.abs())));
        }
        for (c, s) in layer_norms(&next_phi, &phi, slab, k0 - lo..k1 - lo) {
            local.extend([c, s]);
        }
        let all = comm.all_gather(&local);
        if all.len() != counts.iter().map(|c| 10 + 2 * c).sum::<usize>() {
            return Err(DecompositionError::Protocol { rank });
        }
        let (mut time_up, mut cancelled) = (false, false);
        let (mut finite, mut largest) = ([true; 4], [0.0f64; 4]);
        let (mut change, mut size_sum) = (0.0, 0.0);
        let mut at = 0;
        for &c in &counts {
            time_up |= all[at] != 0.0;
            cancelled |= all[at + 1] != 0.0;
            for f in 0..4 {
                finite[f] &= all[at + 2 + f] != 0.0;
                largest[f] = largest[f].max(all[at + 6 + f]);
            }
            for pair in all[at + 10..at + 10 + 2 * c].chunks(2) {
                change += pair[0];
                size_sum += pair[1];
            }
            at += 10 + 2 * c;
        }
        // The serial monitor's order: φ, then E_x, E_y, E_z.
        let stop = (0..4).find_map(|f| {
            if finite[f] {
                monitor.check_largest(largest[f], step)
            } else {
                Some(StopReason::DivergedNonFinite { iteration: step })
            }
        });
        if let Some(stop) = stop {
            break stop;
        }
        let last_change = if size_sum > 0.0 {
            (change / size_sum).sqrt()
        } else {
            change.sqrt()
        };
        std::mem::swap(&mut phi, &mut next_phi);
        std::mem::swap(&mut flux, &mut next_flux);
        if let Some(reason) = history.record_step(&shared, step, last_change, change.sqrt()) {
            break reason;
        }
        if time_up {
            break StopReason::TimeLimit {
                residual: last_change,
            };
        }
        if cancelled {
            break StopReason::Interrupted {
                residual: last_change,
            };
        }
    };
    let owned = (k0 - lo) * slab..(k1 - lo) * slab;
    let gathered = |f: &[f64]| -> Result<Vec<f64>, DecompositionError> {
        let whole = comm.all_gather(&f[owned.clone()]);
        if whole.len() != n {
            return Err(DecompositionError::Protocol { rank });
        }
        Ok(whole)
    };
    Ok(P1State {
        fluence: gathered(&phi)?,
        flux: [
            gathered(&flux[0])?,
            gathered(&flux[1])?,
            gathered(&flux[2])?,
        ],
        steps: step,
        stop_reason,
    })
}

/// [`march_p1`] on `ranks` in-process ranks: rank 0's state, which every rank holds.
pub fn march_p1_on_threads(
    lattice: &crate::Lattice,
    source: &[f64],
    settings: &crate::p1::P1Settings,
    ranks: usize,
) -> Result<crate::p1::P1State, DecompositionError> {
    on_threads(ranks, |comm| march_p1(lattice, source, settings, comm))
}
