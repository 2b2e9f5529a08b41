//! The explicit schemes split over ranks, the same bits on any number of ranks:
//! [`iterate`] and [`iterate_on`], FTCS and Jacobi to steady state on an assembled
//! diffusion system (the twin of [`crate::steady::iterate`]) over z-slabs or a Cartesian
//! grid of boxes ([`Decomposition`]); [`iterate_block`], the same from rows each rank
//! builds for its own layers or box of a medium filling the grid's box (no rank holds the
//! whole system); and [`march_p1_on`], P1 by FTCS over z-slabs or boxes (the twin of
//! [`crate::p1::march`]; [`march_p1`] the slab case).
//! For the steady iterations:
//!
//! Each rank owns the unknowns of its cells (a slab's layers, or a box's cells) and keeps
//! their rows with the columns renumbered into a local vector [owned | halo], the halo
//! grouped by the rank that owns it. A row's products stay in their stored (global column)
//! order, so each row's sum has the serial bits. Per sweep, each rank
//!
//! 1. updates its owned φ from its residual (elementwise, as serially);
//! 2. sends each neighbour the owned values its rows read (non-blocking), computes the
//!    rows that read no halo while they travel, receives, then computes the rest;
//! 3. sums r² over its runs of eight cells along x (each run left to right, as serially)
//!    into an exact accumulator, and all-reduces the accumulators with each rank's
//!    time-budget and cancel flags (`lucent_core::ranks::all_reduce`: log₂P messages); the merged sum is the serial norm's exact sum
//!    (`steady::Layers`), so every rank takes the serial stopping decision.
//!
//! Deterministic stops (tolerances, iteration limit, divergence) follow from the identical
//! residual; the time budget and cancellation, which differ per rank, travel with the
//! gather, so no rank stops alone.
//!
//! Boxes beat slabs on many ranks: a slab's halo is two whole layers however thin the
//! slab, a box's shrinks with its faces (`docs/ranks.md` has the model), and z-slabs stop
//! at n_z ranks.

use crate::ExplicitError;
use crate::steady::{
    Iteration, Layers, NORM_RUN, Steady, SteadySettings, gershgorin, norm_runs, row_scale,
    scale_rows, squares,
};
use lucent_core::exact::ExactSum;
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
    /// A grid of boxes that does not fit the cells or the ranks.
    #[error(
        "a {grid:?} grid of boxes on {dims:?} cells for {ranks} ranks: it needs one box per rank, and each box a cell in y and z and a run of {NORM_RUN} cells in x"
    )]
    BoxGrid {
        /// Boxes along x, y and z (all ones when no grid was given and none fits).
        grid: [usize; 3],
        /// The grid's cells.
        dims: [usize; 3],
        /// Ranks there are.
        ranks: usize,
    },
    /// A row reads beyond the neighbouring slabs (slabs thinner than the stencil).
    #[error("rank {rank}: the stencil reaches past the neighbouring slabs (use fewer ranks)")]
    StencilTooWide {
        /// The rank.
        rank: usize,
    },
    /// The ranks' blocks of rows do not form a grid of boxes covering the grid in rank
    /// order (`iterate_block`).
    #[error(
        "rank {rank}'s block of rows is out of place: the ranks' blocks must be a grid of boxes covering the grid, box (i, j, k) on rank i + p_x (j + p_y k), cut in x at multiples of {NORM_RUN}"
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

use lucent_core::ranks::{Communicator, all_reduce, all_reduce_sums, exchange_among};
use lucent_grid::box_cells;

/// A box of cells: its ranges along x, y and z.
type Cells = [std::ops::Range<usize>; 3];

/// Copies the values of the cells `cells` from `src`, which holds the box `from` (x
/// fastest), into `dst`, which holds the box `to`: one slice per x-line.
pub(crate) fn copy_cells(src: &[f64], from: &Cells, dst: &mut [f64], to: &Cells, cells: &Cells) {
    let offset = |b: &Cells, y: usize, z: usize| {
        (cells[0].start - b[0].start)
            + b[0].len() * ((y - b[1].start) + b[1].len() * (z - b[2].start))
    };
    let run = cells[0].len();
    for z in cells[2].clone() {
        for y in cells[1].clone() {
            let (a, b) = (offset(from, y, z), offset(to, y, z));
            dst[b..b + run].copy_from_slice(&src[a..a + run]);
        }
    }
}

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

/// A Cartesian grid of p_x × p_y × p_z boxes over a grid's cells; the box (i, j, k) is
/// rank i + p_x (j + p_y k). The cuts are as even as they can be, those in x at multiples
/// of [`NORM_RUN`] so that each of the norm's runs lies in one box (what keeps the bits).
/// Boxes split cells, not unknowns: boxes outside an embedded shape hold fewer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Boxes {
    dims: [usize; 3],
    /// Per axis, the p + 1 cut positions from 0 to n.
    cuts: [Vec<usize>; 3],
}

impl Boxes {
    /// `grid` = [p_x, p_y, p_z] boxes over `dims` cells.
    ///
    /// # Errors
    /// [`DecompositionError::BoxGrid`] if an axis has no boxes, or more than its cells
    /// (in x, its runs of [`NORM_RUN`]).
    pub fn new(dims: [usize; 3], grid: [usize; 3]) -> Result<Self, DecompositionError> {
        let units = Self::units(dims);
        if (0..3).any(|a| grid[a] == 0 || grid[a] > units[a]) {
            return Err(DecompositionError::BoxGrid {
                grid,
                dims,
                ranks: grid.iter().product(),
            });
        }
        let cuts = std::array::from_fn(|a| {
            let width = if a == 0 { NORM_RUN } else { 1 };
            (0..=grid[a])
                .map(|k| (k * units[a] / grid[a] * width).min(dims[a]))
                .collect()
        });
        Ok(Self { dims, cuts })
    }

    /// The boxes between `cuts` along each axis: per axis the cut positions from 0 to the
    /// grid's cells, ascending (so box (i, j, k) spans `cuts[0][i]..cuts[0][i + 1]` in x,
    /// and so on), for grids cut unevenly (by the load of each part, or by how a volume
    /// was written). The cuts inside x fall at multiples of [`NORM_RUN`], so that each of
    /// the norm's runs lies in one box.
    ///
    /// # Errors
    /// [`DecompositionError::BoxGrid`] for cuts that do not start at 0, end at the grid's
    /// cells, or rise strictly, or an x cut inside the grid off a multiple of [`NORM_RUN`].
    pub fn from_cuts(dims: [usize; 3], cuts: [Vec<usize>; 3]) -> Result<Self, DecompositionError> {
        let fits = (0..3).all(|a| {
            let c = &cuts[a];
            c.len() >= 2
                && c[0] == 0
                && c[c.len() - 1] == dims[a]
                && c.windows(2).all(|w| w[0] < w[1])
                && (a > 0 || c[1..c.len() - 1].iter().all(|x| x.is_multiple_of(NORM_RUN)))
        });
        if !fits {
            let grid: [usize; 3] = std::array::from_fn(|a| cuts[a].len().saturating_sub(1));
            return Err(DecompositionError::BoxGrid {
                grid,
                dims,
                ranks: grid.iter().product(),
            });
        }
        Ok(Self { dims, cuts })
    }

    /// The grid of `ranks` boxes over `dims` with the least cut area (the halo each sweep
    /// sends), ties going to more cuts in z, then in y (boxes of whole x-lines and layers
    /// send contiguous runs). Like `MPI_Dims_create`, but weighing the grid's own shape.
    ///
    /// # Errors
    /// [`DecompositionError::BoxGrid`] (grid [1, 1, 1]) if no grid of `ranks` boxes fits.
    pub fn auto(dims: [usize; 3], ranks: usize) -> Result<Self, DecompositionError> {
        Self::least_cut(dims, ranks, |_| true)
    }

    /// [`Boxes::auto`] among the grids that leave at least one of the axes `whole` uncut
    /// (what a sweep pipelines best: Zhang & Ma's march over boxes,
    /// `wavefront::march_boxes`).
    ///
    /// # Errors
    /// [`DecompositionError::BoxGrid`] (grid [1, 1, 1]) if no such grid fits.
    pub fn auto_leaving_whole(
        dims: [usize; 3],
        ranks: usize,
        whole: &[usize],
    ) -> Result<Self, DecompositionError> {
        Self::least_cut(dims, ranks, |grid| whole.iter().any(|&a| grid[a] == 1))
    }

    /// The grid of `ranks` boxes with the least cut area among those `admit` takes.
    fn least_cut(
        dims: [usize; 3],
        ranks: usize,
        admit: impl Fn([usize; 3]) -> bool,
    ) -> Result<Self, DecompositionError> {
        let units = Self::units(dims);
        let divisors = |n: usize| (1..=n).rev().filter(move |p| n.is_multiple_of(*p));
        let mut best: Option<([usize; 3], usize)> = None;
        for pz in divisors(ranks) {
            for py in divisors(ranks / pz) {
                let grid = [ranks / pz / py, py, pz];
                if (0..3).any(|a| grid[a] > units[a]) || !admit(grid) {
                    continue;
                }
                let [nx, ny, nz] = dims;
                let area =
                    (grid[0] - 1) * ny * nz + (grid[1] - 1) * nx * nz + (grid[2] - 1) * nx * ny;
                if best.is_none_or(|(_, least)| area < least) {
                    best = Some((grid, area));
                }
            }
        }
        match best {
            Some((grid, _)) => Self::new(dims, grid),
            None => Err(DecompositionError::BoxGrid {
                grid: [1, 1, 1],
                dims,
                ranks,
            }),
        }
    }

    /// What an axis can be cut into: x's runs, y's and z's cells.
    fn units(dims: [usize; 3]) -> [usize; 3] {
        [dims[0].div_ceil(NORM_RUN), dims[1], dims[2]]
    }

    /// The grid's cells.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Boxes along x, y and z.
    pub fn grid(&self) -> [usize; 3] {
        self.cuts.clone().map(|c| c.len() - 1)
    }

    /// How many boxes (ranks).
    pub fn ranks(&self) -> usize {
        self.grid().iter().product()
    }

    /// The cells of box `rank` along each axis.
    pub fn bounds(&self, rank: usize) -> [std::ops::Range<usize>; 3] {
        let at = self.position(rank);
        std::array::from_fn(|a| self.cuts[a][at[a]]..self.cuts[a][at[a] + 1])
    }

    /// Box `rank`'s place (i, j, k) in the grid of boxes.
    fn position(&self, rank: usize) -> [usize; 3] {
        let [px, py, _] = self.grid();
        [rank % px, (rank / px) % py, rank / (px * py)]
    }

    /// These boxes, if they are a grid of `dims` cells for `ranks` ranks.
    pub(crate) fn fitting(
        &self,
        dims: [usize; 3],
        ranks: usize,
    ) -> Result<&Self, DecompositionError> {
        if self.ranks() != ranks || self.dims != dims {
            return Err(DecompositionError::BoxGrid {
                grid: self.grid(),
                dims,
                ranks,
            });
        }
        Ok(self)
    }

    /// The whole field, on every rank, from each rank's `mine`: the values of its box, x
    /// fastest (one all-gather).
    ///
    /// # Errors
    /// [`DecompositionError::Protocol`] if the ranks' parts do not add up to the grid.
    pub(crate) fn gather(
        &self,
        mine: &[f64],
        comm: &(impl Communicator + ?Sized),
    ) -> Result<Vec<f64>, DecompositionError> {
        let [nx, ny, nz] = self.dims;
        let all = comm.all_gather(mine);
        if all.len() != nx * ny * nz || comm.size() != self.ranks() {
            return Err(DecompositionError::Protocol { rank: comm.rank() });
        }
        let mut whole = vec![0.0; all.len()];
        let grid = [0..nx, 0..ny, 0..nz];
        let mut first = 0;
        for r in 0..self.ranks() {
            let cells = self.bounds(r);
            let len = cells.iter().map(|c| c.len()).product::<usize>();
            copy_cells(&all[first..first + len], &cells, &mut whole, &grid, &cells);
            first += len;
        }
        Ok(whole)
    }

    /// The boxes that touch box `rank` at a face, edge or corner, ascending.
    fn adjacent(&self, rank: usize) -> Vec<usize> {
        let [px, py, pz] = self.grid();
        let [i, j, k] = self.position(rank);
        let near = |c: usize, p: usize| c.saturating_sub(1)..(c + 2).min(p);
        let mut out = Vec::new();
        for z in near(k, pz) {
            for y in near(j, py) {
                for x in near(i, px) {
                    let q = x + px * (y + py * z);
                    if q != rank {
                        out.push(q);
                    }
                }
            }
        }
        out
    }

    /// The box (rank) holding cell `c` (flat index, x fastest).
    pub fn rank_of(&self, c: usize) -> usize {
        let [nx, ny, _] = self.dims;
        let at = [c % nx, (c / nx) % ny, c / (nx * ny)];
        let [px, py, _] = self.grid();
        let index = |a: usize| self.cuts[a].partition_point(|&cut| cut <= at[a]) - 1;
        index(0) + px * (index(1) + py * index(2))
    }
}

/// How [`iterate_on`] splits the grid over ranks.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum Decomposition {
    /// z-slabs balanced by unknowns ([`Slabs`]); at most one rank per layer.
    #[default]
    Slabs,
    /// A Cartesian grid of boxes, one per rank.
    Boxes(Boxes),
}

/// One rank's rows of the system, renumbered into its local vector x = [owned | halo].
struct Part {
    /// Owned unknowns (the first `own` entries of x).
    own: usize,
    /// Halo entries after them, grouped by the owning rank in `receives`' order.
    halo: usize,
    rows: LocalRows,
    /// (rank, owned positions that rank's rows read), ascending by rank.
    sends: Vec<(usize, Vec<usize>)>,
    /// (rank, how many of the halo's values it sends), ascending by rank: consecutive
    /// blocks of the halo.
    receives: Vec<(usize, usize)>,
    /// The norm's runs of owned unknowns, [start, end) in owned positions.
    runs: Vec<(usize, usize)>,
}

/// Owned rows in local columns: compressed rows, each row's entries in their stored
/// (global) order, which is the serial order of its products.
struct LocalRows {
    indptr: Vec<usize>,
    indices: Vec<usize>,
    data: Vec<f64>,
    /// Rows that read no halo value (computed while the halo travels), and the others.
    interior: Vec<usize>,
    border: Vec<usize>,
}

impl LocalRows {
    /// Rows `rows` of `a` (global columns), each column mapped by `local` to (its place in
    /// x, whether it is a halo value).
    fn new(
        a: &CsMat<f64>,
        rows: impl Iterator<Item = usize>,
        local: impl Fn(usize) -> (usize, bool),
    ) -> Self {
        let mut out = Self {
            indptr: vec![0],
            indices: Vec::new(),
            data: Vec::new(),
            interior: Vec::new(),
            border: Vec::new(),
        };
        for (t, i) in rows.enumerate() {
            let mut reads_halo = false;
            if let Some(row) = a.outer_view(i) {
                for (j, &v) in row.iter() {
                    let (at, halo) = local(j);
                    reads_halo |= halo;
                    out.indices.push(at);
                    out.data.push(v);
                }
            }
            out.indptr.push(out.indices.len());
            if reads_halo {
                out.border.push(t);
            } else {
                out.interior.push(t);
            }
        }
        out
    }

    /// The residual b_i − (Ax)_i of row `i`, reading the local vector `x`.
    fn residual(&self, b: &[f64], x: &[f64], i: usize) -> f64 {
        let (s, e) = (self.indptr[i], self.indptr[i + 1]);
        let ax: f64 = self.indices[s..e]
            .iter()
            .zip(&self.data[s..e])
            .map(|(&j, v)| v * x[j])
            .sum();
        b[i] - ax
    }
}

/// Groups sorted (rank, value) pairs by rank.
fn by_rank(pairs: &[(usize, usize)]) -> Vec<(usize, Vec<usize>)> {
    let mut out: Vec<(usize, Vec<usize>)> = Vec::new();
    for &(rank, v) in pairs {
        match out.last_mut() {
            Some((r, values)) if *r == rank => values.push(v),
            _ => out.push((rank, vec![v])),
        }
    }
    out
}

impl Part {
    /// Rank `rank`'s part of the whole system `a`, each unknown's rank in `owner` and its
    /// cell in `cells` (a grid `nx` wide). Every rank holds `a`, so each finds by itself
    /// what it receives (the columns its rows read elsewhere) and what it sends (its
    /// unknowns the other ranks' rows read): the two sides of each message agree.
    fn from_system(
        a: &CsMat<f64>,
        cells: &[usize],
        owner: &[usize],
        rank: usize,
        nx: usize,
    ) -> Self {
        let n = owner.len();
        let owned: Vec<usize> = (0..n).filter(|&u| owner[u] == rank).collect();
        let (indptr, indices) = (a.proper_indptr(), a.indices());
        let columns = |i: usize| indices[indptr[i]..indptr[i + 1]].iter().copied();
        // (owner, column) of what this rank's rows read elsewhere: the halo, in order.
        let mut halo: Vec<(usize, usize)> = owned
            .iter()
            .flat_map(|&i| columns(i))
            .filter(|&j| owner[j] != rank)
            .map(|j| (owner[j], j))
            .collect();
        halo.sort_unstable();
        halo.dedup();
        // (reader, column) of this rank's unknowns other ranks' rows read.
        let mut wanted: Vec<(usize, usize)> = (0..n)
            .into_par_iter()
            .filter(|&i| owner[i] != rank)
            .flat_map_iter(|i| {
                columns(i)
                    .filter(|&j| owner[j] == rank)
                    .map(move |j| (owner[i], j))
            })
            .collect();
        wanted.sort_unstable();
        wanted.dedup();
        let own = owned.len();
        let place = |j: usize| owned.binary_search(&j).unwrap_or(0);
        let rows = LocalRows::new(a, owned.iter().copied(), |j| {
            if owner[j] == rank {
                (place(j), false)
            } else {
                (own + halo.binary_search(&(owner[j], j)).unwrap_or(0), true)
            }
        });
        let sends = by_rank(&wanted)
            .into_iter()
            .map(|(r, js)| (r, js.into_iter().map(place).collect()))
            .collect();
        let receives = by_rank(&halo)
            .into_iter()
            .map(|(r, js)| (r, js.len()))
            .collect();
        Self {
            own,
            halo: halo.len(),
            rows,
            sends,
            receives,
            runs: norm_runs(owned.iter().map(|&u| cells[u]), nx),
        }
    }
}

/// [`iterate_on`] over z-slabs ([`Decomposition::Slabs`]).
///
/// # Errors
/// As [`iterate_on`].
pub fn iterate(
    system: &AssembledSystem,
    dims: [usize; 3],
    iteration: Iteration,
    settings: &SteadySettings,
    comm: &(impl Communicator + ?Sized),
) -> Result<Steady, DecompositionError> {
    iterate_on(
        system,
        dims,
        &Decomposition::Slabs,
        iteration,
        settings,
        comm,
    )
}

/// Iterates `system` (the whole system, as every rank assembles it, on a grid of `dims`
/// cells) from zero to the stopping rule on the ranks of `comm`, each doing the rows of
/// its part of `decomposition`. Returns the whole φ on every rank (gathered at the end)
/// and the residual history: the bits of `lucent_explicit::steady::iterate` on one rank,
/// whatever the decomposition. [`iterate_block`] is the same iteration from rows each
/// rank builds for its own layers.
///
/// # Errors
/// [`DecompositionError::Scheme`] for what the serial iteration refuses;
/// [`DecompositionError::TooManyRanks`] for more slabs than layers with unknowns;
/// [`DecompositionError::BoxGrid`] for boxes of another grid or rank count;
/// [`DecompositionError::Matrix`] for a system whose sizes do not agree or whose cells lie
/// beyond `dims`; a rank that left the protocol.
pub fn iterate_on(
    system: &AssembledSystem,
    dims: [usize; 3],
    decomposition: &Decomposition,
    iteration: Iteration,
    settings: &SteadySettings,
    comm: &(impl Communicator + ?Sized),
) -> Result<Steady, DecompositionError> {
    let a = &system.matrix;
    let n = system.rhs.len();
    let size = comm.size();
    if a.rows() != n || a.cols() != n || system.cells.len() != n || !a.is_csr() {
        return Err(DecompositionError::Matrix(format!(
            "a {}×{} matrix for {n} right-hand sides and {} cells",
            a.rows(),
            a.cols(),
            system.cells.len()
        )));
    }
    let cells_in_grid: usize = dims.iter().product();
    if let Some(&c) = system.cells.iter().find(|&&c| c >= cells_in_grid) {
        return Err(DecompositionError::Matrix(format!(
            "an unknown in cell {c}, beyond the {dims:?} grid"
        )));
    }
    let owner: Vec<usize> = match decomposition {
        Decomposition::Slabs => {
            let layers = Layers::new(&system.cells, dims);
            let slabs = Slabs::new(&layers, size)?;
            let ranges = layers.ranges();
            let mut owner = vec![0; n];
            for (rank, &(l0, l1)) in slabs.layers.iter().enumerate() {
                owner[ranges[l0].1..ranges[l1 - 1].2].fill(rank);
            }
            owner
        }
        Decomposition::Boxes(boxes) => {
            boxes.fitting(dims, size)?;
            system.cells.iter().map(|&c| boxes.rank_of(c)).collect()
        }
    };
    let rank = comm.rank();
    let part = Part::from_system(a, &system.cells, &owner, rank, dims[0].max(1));
    // The serial iteration's checks and per-row scale, then this rank's rows of it.
    let scale_all = row_scale(system, iteration, settings.allow_unstable)?;
    let mine =
        |v: &[f64]| -> Vec<f64> { (0..n).filter(|&u| owner[u] == rank).map(|u| v[u]).collect() };
    let (scale, b) = (mine(&scale_all), mine(&system.rhs));
    let (owned, residuals, stop_reason) = sweep(&part, &b, &scale, settings, comm)?;
    // The ranks' φ in rank order, each rank's unknowns ascending: back to the global order.
    let gathered = comm.all_gather(&owned);
    if gathered.len() != n {
        return Err(DecompositionError::Protocol { rank });
    }
    let mut next = vec![0usize; size];
    for &o in &owner {
        next[o] += 1;
    }
    let mut at = 0;
    for count in &mut next {
        let start = at;
        at += *count;
        *count = start;
    }
    let mut fluence: Vec<f64> = owner
        .iter()
        .map(|&o| {
            next[o] += 1;
            gathered[next[o] - 1]
        })
        .collect();
    // The serial rule, on the gathered whole: any non-finite φ zeroes all of it.
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

/// [`iterate_on`] from the rows of a medium that fills the box, each rank holding only its
/// own: `block` is this rank's box of cells' rows and right-hand side
/// (`lucent_diffusion::SlabSystem::block`, built from its cells of the coefficients and
/// D's cells beyond its faces), `dims` the grid's cells. The ranks' boxes must form a grid
/// of boxes covering the grid, box (i, j, k) on rank i + p_x (j + p_y k) and the x cuts at
/// multiples of [`NORM_RUN`] (z-slabs, consecutive runs of whole layers on ranks 0, 1, …,
/// are the grid 1 × 1 × P; any cuts, not only [`Boxes::new`]'s). No rank holds more than
/// its rows, four vectors of its cells and their halo. The ranks learn the grid of boxes
/// from one gather of their bounds, and what to send each other from one exchange, with
/// each box that touches theirs, of the columns their rows read; they agree on the checks
/// (the diagonal, the FTCS bound from the largest Gershgorin sum of all rows, a stencil
/// that reaches no further than the touching boxes) before the first sweep, so a bad
/// block stops every rank with the same error. On return each rank holds φ of its cells
/// (zeroed, on every rank, if any is not finite, as the serial rule does); they and the
/// history are the bits of `steady::iterate` on the assembled whole.
///
/// # Errors
/// [`DecompositionError::Scheme`] for what the serial iteration refuses (a non-positive
/// diagonal, an FTCS step beyond the bound, a damping outside (0, 1]);
/// [`DecompositionError::Blocks`] for blocks that do not form such a grid of boxes;
/// [`DecompositionError::StencilTooWide`] for rows that read past the touching boxes (or
/// rows and right-hand side that do not fit the block's cells); a rank that left the
/// protocol.
pub fn iterate_block(
    block: &lucent_diffusion::slab::Block,
    dims: [usize; 3],
    iteration: Iteration,
    settings: &SteadySettings,
    comm: &(impl Communicator + ?Sized),
) -> Result<BlockSteady, DecompositionError> {
    let (rank, size) = (comm.rank(), comm.size());
    let a = &block.matrix;
    let own = a.rows();
    let grid_cells: usize = dims.iter().product();
    let in_grid = (0..3).all(|k| block.cells[k].start < block.cells[k].end)
        && (0..3).all(|k| block.cells[k].end <= dims[k]);
    let lengths_fit = in_grid
        && own
            == block
                .cells
                .iter()
                .map(ExactSizeIterator::len)
                .product::<usize>()
        && block.rhs.len() == own
        && a.cols() == grid_cells
        && a.is_csr();
    let cells: Vec<usize> = if lengths_fit {
        block.grid_cells(dims).collect()
    } else {
        Vec::new()
    };
    let diagonal: Vec<f64> = cells
        .iter()
        .enumerate()
        .map(|(i, &c)| a.get(i, c).copied().unwrap_or(0.0))
        .collect();
    // Every rank's bounds, whether its rows fit them, a non-positive diagonal, and its
    // largest Gershgorin sum.
    let mut local: Vec<f64> = block
        .cells
        .iter()
        .flat_map(|r| [r.start as f64, r.end as f64])
        .collect();
    local.extend([
        f64::from(u8::from(!lengths_fit)),
        f64::from(u8::from(diagonal.iter().any(|&d| d <= 0.0))),
        gershgorin(a),
    ]);
    const WORDS: usize = 9;
    let agreed = comm.all_gather(&local);
    if agreed.len() != WORDS * size {
        return Err(DecompositionError::Protocol { rank });
    }
    let flags: Vec<&[f64]> = agreed.chunks(WORDS).collect();
    let boxes = boxes_of(&flags, dims)?;
    if let Some(r) = flags.iter().position(|f| f[6] != 0.0) {
        return Err(DecompositionError::StencilTooWide { rank: r });
    }
    if flags.iter().any(|f| f[7] != 0.0) {
        return Err(ExplicitError::Invalid("the system has a non-positive diagonal".into()).into());
    }
    let largest = flags.iter().map(|f| f[8]).fold(0.0, f64::max);
    let scale = scale_rows(&diagonal, largest, iteration, settings.allow_unstable)?;
    // The columns read beyond this box, by (owning rank, column), and the boxes that touch
    // this one: the only ones a row may read.
    let place = |j: usize| cells.binary_search(&j).ok();
    let mut halo: Vec<(usize, usize)> = a
        .indices()
        .iter()
        .filter(|&&j| place(j).is_none())
        .map(|&j| (boxes.rank_of(j), j))
        .collect();
    halo.sort_unstable();
    halo.dedup();
    let adjacent = boxes.adjacent(rank);
    let mut too_wide = halo.iter().any(|(q, _)| adjacent.binary_search(q).is_err());
    // Tell each touching box what this one reads of it; learn what it reads of this one.
    let requests: Vec<Vec<f64>> = adjacent
        .iter()
        .map(|&q| {
            halo.iter()
                .filter(|(owner, _)| *owner == q)
                .map(|&(_, j)| j as f64)
                .collect()
        })
        .collect();
    let outgoing: Vec<(usize, &[f64])> = adjacent
        .iter()
        .zip(&requests)
        .map(|(&q, v)| (q, v.as_slice()))
        .collect();
    let (wanted, ()) = exchange_among(comm, &outgoing, &adjacent, || ());
    let mut sends = Vec::new();
    for (&q, asked) in adjacent.iter().zip(&wanted) {
        let at: Option<Vec<usize>> = asked
            .iter()
            .map(|&j| {
                let whole = j >= 0.0 && j.fract() == 0.0;
                whole.then(|| place(j as usize)).flatten()
            })
            .collect();
        match at {
            Some(at) if !at.is_empty() => sends.push((q, at)),
            Some(_) => {}
            None => too_wide = true,
        }
    }
    let all = comm.all_gather(&[f64::from(u8::from(too_wide))]);
    if all.len() != size {
        return Err(DecompositionError::Protocol { rank });
    }
    if let Some(r) = all.iter().position(|&f| f != 0.0) {
        return Err(DecompositionError::StencilTooWide { rank: r });
    }
    // x = [owned | halo grouped by owning rank, ascending].
    let rows = LocalRows::new(a, 0..own, |j| match place(j) {
        Some(i) => (i, false),
        None => {
            let at = halo.binary_search(&(boxes.rank_of(j), j)).unwrap_or(0);
            (own + at, true)
        }
    });
    let receives = by_rank(&halo)
        .into_iter()
        .map(|(q, js)| (q, js.len()))
        .collect();
    let part = Part {
        own,
        halo: halo.len(),
        rows,
        sends,
        receives,
        runs: norm_runs(cells.iter().copied(), dims[0]),
    };
    let (mut fluence, residuals, stop_reason) = sweep(&part, &block.rhs, &scale, settings, comm)?;
    // The serial rule: any non-finite φ anywhere zeroes all of it.
    let finite = f64::from(u8::from(fluence.iter().all(|v| v.is_finite())));
    let all = comm.all_gather(&[finite]);
    if all.len() != size {
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

/// The grid of boxes the ranks' gathered bounds (the first six words of each rank's
/// entry: x, y and z as start, end) form, or the first rank whose box is out of place.
fn boxes_of(bounds: &[&[f64]], dims: [usize; 3]) -> Result<Boxes, DecompositionError> {
    let whole = |v: f64| (v >= 0.0 && v.fract() == 0.0).then_some(v as usize);
    let mut cuts: [Vec<usize>; 3] = Default::default();
    for (a, axis) in cuts.iter_mut().enumerate() {
        for (r, b) in bounds.iter().enumerate() {
            axis.push(whole(b[2 * a]).ok_or(DecompositionError::Blocks { rank: r })?);
        }
        axis.push(dims[a]);
        axis.sort_unstable();
        axis.dedup();
    }
    let out_of_place = |r: usize| DecompositionError::Blocks { rank: r };
    // Cuts that are not a grid's: blame the first box that starts off a multiple of the
    // norm's run in x (or else the first).
    let off_run = || {
        let r = bounds
            .iter()
            .position(|b| whole(b[0]).is_some_and(|x| !x.is_multiple_of(NORM_RUN) && x != dims[0]));
        out_of_place(r.unwrap_or(0))
    };
    let boxes = Boxes::from_cuts(dims, cuts).map_err(|_| off_run())?;
    if boxes.ranks() != bounds.len() {
        return Err(out_of_place(bounds.len().min(boxes.ranks())));
    }
    for (r, b) in bounds.iter().enumerate() {
        let expected = boxes.bounds(r);
        let agrees = (0..3).all(|a| {
            whole(b[2 * a]) == Some(expected[a].start)
                && whole(b[2 * a + 1]) == Some(expected[a].end)
        });
        if !agrees {
            return Err(out_of_place(r));
        }
    }
    Ok(boxes)
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
/// `b` and `scale` are the owned rows'.
fn sweep(
    part: &Part,
    b: &[f64],
    scale: &[f64],
    settings: &SteadySettings,
    comm: &(impl Communicator + ?Sized),
) -> Result<(Vec<f64>, Vec<f64>, StopReason), DecompositionError> {
    let rank = comm.rank();
    let own = part.own;
    // Deterministic stops from the shared residual; the clock and the cancel flag are
    // each rank's own and travel with the sums.
    let shared = Stopping {
        time_budget: None,
        cancel: None,
        // The deadline too: each rank's clock travels with the reduced flags;
        // asked alone, ranks would stop at different steps and wait on each other.
        deadline: None,
        progress: if rank == 0 {
            settings.stopping.progress.clone()
        } else {
            None
        },
        ..settings.stopping.clone()
    };
    let mut history = History::start();
    let started = std::time::Instant::now();
    // Σ v² (owned) over this rank's runs, all-reduced with the flags: (norm, any time,
    // any cancel). The merged accumulators are the exact sum of all runs, in any order.
    let gather = |v: &[f64]| -> Result<(f64, bool, bool), DecompositionError> {
        let flags = settings.stopping.local_flags(started);
        let (flags, sums) = all_reduce_sums(comm, &flags, &[squares(v, &part.runs)])
            .ok_or(DecompositionError::Protocol { rank })?;
        Ok((sums[0].value().sqrt(), flags[0], flags[1]))
    };
    let (b_norm, mut time_up, mut cancelled) = gather(b)?;
    let b_norm = b_norm.max(f64::MIN_POSITIVE);
    let mut x = vec![0.0f64; own + part.halo];
    let mut r = b.to_vec();
    let from: Vec<usize> = part.receives.iter().map(|&(q, _)| q).collect();
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
        x[..own]
            .par_iter_mut()
            .zip(r.par_iter())
            .zip(scale.par_iter())
            .for_each(|((p, r), s)| *p += s * r);
        let outgoing: Vec<(usize, Vec<f64>)> = part
            .sends
            .iter()
            .map(|(q, at)| (*q, at.iter().map(|&i| x[i]).collect()))
            .collect();
        let sends: Vec<(usize, &[f64])> =
            outgoing.iter().map(|(q, v)| (*q, v.as_slice())).collect();
        let xs = &x;
        let (received, interior) = exchange_among(comm, &sends, &from, || {
            part.rows
                .interior
                .par_iter()
                .map(|&i| part.rows.residual(b, xs, i))
                .collect::<Vec<f64>>()
        });
        let mut at = own;
        for (values, &(_, count)) in received.iter().zip(&part.receives) {
            if values.len() != count {
                return Err(DecompositionError::Protocol { rank });
            }
            x[at..at + count].copy_from_slice(values);
            at += count;
        }
        for (&i, v) in part.rows.interior.iter().zip(interior) {
            r[i] = v;
        }
        let xs = &x;
        let border: Vec<f64> = part
            .rows
            .border
            .par_iter()
            .map(|&i| part.rows.residual(b, xs, i))
            .collect();
        for (&i, v) in part.rows.border.iter().zip(border) {
            r[i] = v;
        }
        let (norm, t, c) = gather(&r)?;
        relative = norm / b_norm;
        time_up = t;
        cancelled = c;
    };
    x.truncate(own);
    Ok((x, history.into_residuals(), stop_reason))
}

/// [`iterate_on`] on `ranks` in-process ranks (threads joined by channels, sharing
/// `system`): rank 0's result, which every rank holds.
///
/// # Errors
/// As [`iterate_on`].
pub fn iterate_on_threads(
    system: &AssembledSystem,
    dims: [usize; 3],
    decomposition: &Decomposition,
    iteration: Iteration,
    settings: &SteadySettings,
    ranks: usize,
) -> Result<Steady, DecompositionError> {
    on_threads(ranks, |comm| {
        iterate_on(system, dims, decomposition, iteration, settings, comm)
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

/// [`march_p1_on`] over z-slabs ([`Decomposition::Slabs`]: layers r·n_z/P..(r+1)·n_z/P).
///
/// # Errors
/// As [`march_p1_on`].
pub fn march_p1(
    lattice: &crate::Lattice,
    source: &[f64],
    settings: &crate::p1::P1Settings,
    comm: &(impl Communicator + ?Sized),
) -> Result<crate::p1::P1State, DecompositionError> {
    march_p1_on(lattice, source, &Decomposition::Slabs, settings, comm)
}

/// [`crate::p1::march`] from zero, split over the ranks of `comm` by `decomposition`
/// (z-slabs of layers r·n_z/P..(r+1)·n_z/P, or a grid of boxes): [`march_p1_box`] on each
/// rank's box of `source`, then the whole state gathered on every rank: the serial bits on
/// any number of ranks and any decomposition.
///
/// # Errors
/// As [`march_p1_box`]; more slabs than layers.
pub fn march_p1_on(
    lattice: &crate::Lattice,
    source: &[f64],
    decomposition: &Decomposition,
    settings: &crate::p1::P1Settings,
    comm: &(impl Communicator + ?Sized),
) -> Result<crate::p1::P1State, DecompositionError> {
    lattice.check_field("source", source)?;
    let (size, dims) = (comm.size(), lattice.dims);
    let boxes = match decomposition {
        Decomposition::Slabs => {
            if size == 0 || size > dims[2] {
                return Err(DecompositionError::TooManyRanks {
                    ranks: size,
                    layers: dims[2],
                });
            }
            Boxes::new(dims, [1, 1, size])?
        }
        Decomposition::Boxes(boxes) => boxes.fitting(dims, size)?.clone(),
    };
    let [nx, ny, _] = dims;
    let mine: Vec<f64> = box_cells(&boxes.bounds(comm.rank()))
        .map(|p| source[p[0] + nx * (p[1] + ny * p[2])])
        .collect();
    let part = march_p1_box(lattice, &mine, &boxes, settings, comm)?;
    let gathered = |f: &[f64]| boxes.gather(f, comm);
    Ok(crate::p1::P1State {
        fluence: gathered(&part.fluence)?,
        flux: [
            gathered(&part.flux[0])?,
            gathered(&part.flux[1])?,
            gathered(&part.flux[2])?,
        ],
        steps: part.steps,
        changes: part.changes,
        stop_reason: part.stop_reason,
    })
}

/// [`crate::p1::march`] from zero over the grid of boxes `boxes` (one per rank of `comm`),
/// each rank holding only its box: `source` is q over `boxes.bounds(rank)` (x fastest, as
/// a rank reads it from a volume), and the state returned is φ and E over that box. Per
/// step each rank sends the cells of (φ, E) on each face it shares with another box to
/// that box, steps the cells that read no halo while they travel, then the rest; the
/// growth monitor's largest values and finiteness, the exact change and size sums of its
/// norm's runs, and the time and cancel flags are all-reduced, and every rank takes the
/// serial decision (the source's largest magnitude, which the monitor starts from, is
/// all-reduced too). A rank holds eight f64 fields of its box grown by a cell; its box of
/// the result is the serial march's bits, and the steps, changes and stop reason are the
/// serial march's on every rank.
///
/// # Errors
/// The serial march's refusals ([`DecompositionError::Scheme`], on every rank: a rank
/// whose part of the source is refused names the cell, the others name that rank);
/// periodic edges on more than one rank (the decomposition has no wrap-around
/// neighbours); boxes of another grid or rank count; a rank that left the protocol.
pub fn march_p1_box(
    lattice: &crate::Lattice,
    source: &[f64],
    boxes: &Boxes,
    settings: &crate::p1::P1Settings,
    comm: &(impl Communicator + ?Sized),
) -> Result<crate::p1::P1State, DecompositionError> {
    use crate::p1::{
        P1Edges, P1State, Region, StepCoefficients, box_runs, change_norms, change_sums,
        growth_monitor, step_box,
    };
    use std::ops::Range;
    let (size, rank) = (comm.size(), comm.rank());
    let dims = lattice.dims;
    let boxes = boxes.fitting(dims, size)?.clone();
    let own = boxes.bounds(rank);
    // This rank's part of the source: its length and values, then everyone's verdict and
    // the largest magnitude (1 + the rank that refused, the highest when several did).
    let checked = if source.len() != own.iter().map(Range::len).product::<usize>() {
        Err(format!("{} values for the cells {own:?}", source.len()))
    } else {
        match source
            .iter()
            .zip(box_cells(&own))
            .find(|(v, _)| !v.is_finite())
        {
            Some((v, [i, j, k])) => Err(format!("{v} in cell {}", i + dims[0] * (j + dims[1] * k))),
            None => Ok(()),
        }
    };
    let largest = source.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    let failed = if checked.is_err() {
        rank as f64 + 1.0
    } else {
        0.0
    };
    let agreed = all_reduce(comm, &[failed, largest], |acc, part| {
        acc[0] = acc[0].max(part[0]);
        acc[1] = acc[1].max(part[1]);
        part.len() == 2
    })
    .ok_or(DecompositionError::Protocol { rank })?;
    checked.map_err(|why| {
        DecompositionError::Scheme(crate::ExplicitError::Invalid(format!("source: {why}")))
    })?;
    if agreed[0] != 0.0 {
        return Err(DecompositionError::Scheme(crate::ExplicitError::Invalid(
            format!(
                "rank {} refused its part of the source (it says why)",
                agreed[0] - 1.0
            ),
        )));
    }
    let largest = agreed[1];
    let step_of = StepCoefficients::checked(settings, lattice.spacing)?;
    if size > 1 && settings.edges == P1Edges::Periodic {
        return Err(DecompositionError::Scheme(crate::ExplicitError::Invalid(
            "periodic edges do not split over ranks (no wrap-around neighbours): use zero edges"
                .into(),
        )));
    }
    // The box this rank holds: its own grown by a cell where the grid goes on.
    let origin: [usize; 3] = std::array::from_fn(|a| own[a].start.saturating_sub(1));
    let held: [usize; 3] = std::array::from_fn(|a| (own[a].end + 1).min(dims[a]) - origin[a]);
    let len: usize = held.iter().product();
    let region = Region { dims, origin, held };
    let place = |p: [usize; 3]| region.place(p);
    let mut local_source = vec![0.0; len];
    for (p, &q) in box_cells(&own).zip(source) {
        local_source[place(p)] = q;
    }
    // The boxes sharing a face with this one: (rank, the cells sent, the halo received).
    let at = boxes.position(rank);
    let grid = boxes.grid();
    let mut faces: Vec<(usize, Cells, Cells)> = Vec::new();
    for a in 0..3 {
        for upper in [false, true] {
            if (!upper && at[a] == 0) || (upper && at[a] + 1 == grid[a]) {
                continue;
            }
            let mut q = at;
            q[a] = if upper { at[a] + 1 } else { at[a] - 1 };
            let (mut send, mut receive) = (own.clone(), own.clone());
            let (s, e) = (own[a].start, own[a].end);
            (send[a], receive[a]) = if upper {
                (e - 1..e, e..e + 1)
            } else {
                (s..s + 1, s - 1..s)
            };
            faces.push((q[0] + grid[0] * (q[1] + grid[1] * q[2]), send, receive));
        }
    }
    // The cells that read no halo: the box less a cell on each side it shares.
    let inner: [Range<usize>; 3] = std::array::from_fn(|a| {
        let shared = |upper: bool| {
            faces
                .iter()
                .any(|(_, _, r)| r[a] != own[a] && (r[a].start >= own[a].end) == upper)
        };
        let s = own[a].start + usize::from(shared(false));
        let e = own[a].end - usize::from(shared(true));
        s..e.max(s)
    });
    let inner_empty = inner.iter().any(|r| r.is_empty());
    let step_cells = |now: (&[f64], &[Vec<f64>; 3]),
                      next: (&mut [f64], &mut [Vec<f64>; 3]),
                      cells: &Cells,
                      skip: Option<&Cells>| {
        step_box(
            &step_of,
            settings.edges,
            &region,
            now,
            next,
            &local_source,
            cells,
            skip,
        );
    };
    let runs = box_runs(origin, held, &own);
    let monitor = growth_monitor(0.0, largest, settings);
    let shared = Stopping {
        time_budget: None,
        cancel: None,
        // The deadline too: each rank's clock travels with the reduced flags;
        // asked alone, ranks would stop at different steps and wait on each other.
        deadline: None,
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
    let from: Vec<usize> = faces.iter().map(|f| f.0).collect();
    let words = 10 + 2 * ExactSum::WORDS;
    let mut step = 0;
    let stop_reason = loop {
        step += 1;
        // Each face's cells of φ, then E_x, E_y, E_z.
        let outgoing: Vec<Vec<f64>> = faces
            .iter()
            .map(|(_, send, _)| {
                std::iter::once(&phi)
                    .chain(&flux)
                    .flat_map(|f| box_cells(send).map(|p| f[place(p)]))
                    .collect()
            })
            .collect();
        let sends: Vec<(usize, &[f64])> = faces
            .iter()
            .zip(&outgoing)
            .map(|(f, v)| (f.0, v.as_slice()))
            .collect();
        let (received, ()) = exchange_among(comm, &sends, &from, || {
            if !inner_empty {
                step_cells((&phi, &flux), (&mut next_phi, &mut next_flux), &inner, None);
            }
        });
        for ((_, _, receive), values) in faces.iter().zip(&received) {
            let count = box_cells(receive).count();
            if values.len() != 4 * count {
                return Err(DecompositionError::Protocol { rank });
            }
            let mut values = values.iter();
            for f in std::iter::once(&mut phi).chain(&mut flux) {
                for p in box_cells(receive) {
                    f[place(p)] = *values.next().unwrap_or(&0.0);
                }
            }
        }
        let skip = (!inner_empty).then_some(&inner);
        step_cells((&phi, &flux), (&mut next_phi, &mut next_flux), &own, skip);
        // [time, cancel, finite ×4, largest ×4, Σ change² words, Σ size² words].
        let mut local: Vec<f64> = (settings.stopping.local_flags(started))
            .map(|f| f64::from(u8::from(f)))
            .to_vec();
        // Per field, over its owned cells (the runs): finite, and the largest magnitude.
        let new = [&next_phi, &next_flux[0], &next_flux[1], &next_flux[2]];
        for f in new {
            let finite = runs
                .iter()
                .all(|&(s, e)| f[s..e].iter().all(|x| x.is_finite()));
            local.push(f64::from(u8::from(finite)));
        }
        for f in new {
            let largest = runs.iter().fold(0.0f64, |a, &(s, e)| {
                f[s..e].iter().fold(a, |a, b| a.max(b.abs()))
            });
            local.push(largest);
        }
        let (change, size_sum) = change_sums(&next_phi, &phi, &runs);
        local.extend(change.to_words());
        local.extend(size_sum.to_words());
        // Any time or cancel flag, every field finite, the largest values, the exact sums.
        let all = all_reduce(comm, &local, |acc, other| {
            for f in 0..2 {
                acc[f] = acc[f].max(other[f]);
            }
            for f in 2..6 {
                acc[f] = acc[f].min(other[f]);
            }
            for f in 6..10 {
                acc[f] = acc[f].max(other[f]);
            }
            let (change, size) = acc[10..].split_at_mut(ExactSum::WORDS);
            let (other_change, other_size) = other[10..].split_at(ExactSum::WORDS);
            ExactSum::merge_words(change, other_change) && ExactSum::merge_words(size, other_size)
        })
        .filter(|all| all.len() == words)
        .ok_or(DecompositionError::Protocol { rank })?;
        let (time_up, cancelled) = (all[0] != 0.0, all[1] != 0.0);
        let finite: [bool; 4] = std::array::from_fn(|f| all[2 + f] != 0.0);
        let largest: [f64; 4] = std::array::from_fn(|f| all[6 + f]);
        let (c, s) = all[10..].split_at(ExactSum::WORDS);
        let part = |w: &[f64]| ExactSum::from_words(w).ok_or(DecompositionError::Protocol { rank });
        let (change, size_sum) = (part(c)?, part(s)?);
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
        let (change, last_change) = change_norms(&change, &size_sum);
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
    let mine = |f: &[f64]| -> Vec<f64> { box_cells(&own).map(|p| f[place(p)]).collect() };
    Ok(P1State {
        fluence: mine(&phi),
        flux: [mine(&flux[0]), mine(&flux[1]), mine(&flux[2])],
        steps: step,
        changes: history.into_residuals(),
        stop_reason,
    })
}

/// [`march_p1_on`] on `ranks` in-process ranks: rank 0's state, which every rank holds.
///
/// # Errors
/// As [`march_p1_on`].
pub fn march_p1_on_threads(
    lattice: &crate::Lattice,
    source: &[f64],
    decomposition: &Decomposition,
    settings: &crate::p1::P1Settings,
    ranks: usize,
) -> Result<crate::p1::P1State, DecompositionError> {
    on_threads(ranks, |comm| {
        march_p1_on(lattice, source, decomposition, settings, comm)
    })
}
