//! Transport sweeps: the eight octant orders, each a wavefront over blocks of cells.
//!
//! Within an octant every direction has the same three upwind faces, so a cell can be
//! solved once its three upwind neighbours are. The grid is cut into blocks (16³ by
//! default); block (I, J, K), counted from the octant's upwind corner, depends only on the
//! blocks with one index one smaller, so all blocks with I + J + K = w form an independent
//! hyperplane (the sweep3d / KBA wavefront, at block level as in Bernabei §5.3.2, and
//! inside each block the lexicographic order is the cell-level wavefront's topological
//! order). Hyperplanes run in order; the blocks of one run in parallel (rayon), each
//! solving all the octant's directions cell by cell. Per-cell data are kept block by
//! block (one contiguous chunk per block), so each parallel task owns its chunk; faces
//! between blocks are passed as planes.
//!
//! Radiance is carried in f64 through a block and stored in f32 (sources, in-scattered
//! radiance); each cell's contribution to the in-scattered radiance is summed in f64 over
//! an octant's directions before it is added to storage.
//!
//! With storage = propagation directions a block fills its own source S_n = Q_n + σ_s J_n
//! just before it is swept (the sweep input's `source`): no separate pass over the work. The
//! per-direction work can live in f64 pages of a pager ([`WorkPages`], one per octant and
//! block): the same block code in the same order, so the same bits, with the pages of each
//! finished wavefront written back by a helper thread while the next is swept.

use std::sync::Arc;

use lucent_grid::BrickLayout;
use lucent_paging::{Pager, PagingError, WritePin};
use rayon::prelude::*;

use crate::angular::Ordinates;
use crate::closure::{CellClosure, CellDirection, OctantDirections};

/// How cells are grouped into blocks — the bricks of lucent-grid's [`BrickLayout`], the
/// layout the pager and the bricked grid share — and their order in memory: block by block
/// in brick order, each block's cells x fastest in its own extent.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    bricks: BrickLayout,
    starts: Vec<usize>,
}

impl Layout {
    /// Blocks of `block`³ cells (smaller at the high edges) over `dims` cells; `block` is
    /// taken between 1 and [`BrickLayout::MAX_BRICK`], and empty dimensions as 1.
    pub fn new(dims: [usize; 3], block: usize) -> Self {
        let bricks = BrickLayout::new(
            dims.map(|n| n.max(1)),
            block.clamp(1, BrickLayout::MAX_BRICK),
        )
        .expect("dimensions and block size are clamped to valid ones");
        let mut starts = Vec::with_capacity(bricks.count() + 1);
        let mut offset = 0;
        for b in 0..bricks.count() {
            starts.push(offset);
            offset += bricks.extent(b).iter().product::<usize>();
        }
        starts.push(offset);
        Self { bricks, starts }
    }

    /// Cells per axis.
    pub fn dims(&self) -> [usize; 3] {
        self.bricks.dims()
    }

    /// Number of blocks.
    pub fn block_count(&self) -> usize {
        self.starts.len() - 1
    }

    /// Total cells.
    pub fn cells(&self) -> usize {
        self.starts[self.block_count()]
    }

    /// The cells of block `b` in block order.
    pub(crate) fn block_cells(&self, b: usize) -> std::ops::Range<usize> {
        self.starts[b]..self.starts[b + 1]
    }

    /// Block-ordered data (`per_cell` values per cell) cut into one chunk per block.
    pub(crate) fn block_chunks<'a, T>(
        &self,
        data: &'a mut [T],
        per_cell: usize,
    ) -> Vec<&'a mut [T]> {
        split(data, &self.starts, per_cell)
    }

    fn block_index(&self, c: [usize; 3]) -> usize {
        self.bricks.id(c)
    }

    fn origin(&self, b: usize) -> [usize; 3] {
        self.bricks.origin(b)
    }

    fn extent(&self, b: usize) -> [usize; 3] {
        self.bricks.extent(b)
    }

    /// Grid-order data (`per_cell` values per cell, x fastest) to block order.
    pub fn to_blocks<T: Copy + Send + Sync + Default>(
        &self,
        grid: &[T],
        per_cell: usize,
    ) -> Vec<T> {
        let mut out = vec![T::default(); self.cells() * per_cell];
        let [nx, ny, _] = self.dims();
        // Block by block in parallel: each block's chunk is contiguous.
        let mut chunks = split(&mut out, &self.starts, per_cell);
        chunks.par_iter_mut().enumerate().for_each(|(b, chunk)| {
            let o = self.origin(b);
            let e = self.extent(b);
            for k in 0..e[2] {
                for j in 0..e[1] {
                    for i in 0..e[0] {
                        let local = i + e[0] * (j + e[1] * k);
                        let cell = (o[0] + i) + nx * ((o[1] + j) + ny * (o[2] + k));
                        chunk[local * per_cell..(local + 1) * per_cell]
                            .copy_from_slice(&grid[cell * per_cell..(cell + 1) * per_cell]);
                    }
                }
            }
        });
        out
    }

    /// Block-order data back to grid order.
    pub fn to_grid<T: Copy + Send + Sync + Default>(
        &self,
        blocked: &[T],
        per_cell: usize,
    ) -> Vec<T> {
        let mut out = vec![T::default(); self.cells() * per_cell];
        let [nx, ny, _] = self.dims();
        for b in 0..self.block_count() {
            let o = self.origin(b);
            let e = self.extent(b);
            let chunk = &blocked[self.starts[b] * per_cell..self.starts[b + 1] * per_cell];
            for k in 0..e[2] {
                for j in 0..e[1] {
                    for i in 0..e[0] {
                        let local = i + e[0] * (j + e[1] * k);
                        let cell = (o[0] + i) + nx * ((o[1] + j) + ny * (o[2] + k));
                        out[cell * per_cell..(cell + 1) * per_cell]
                            .copy_from_slice(&chunk[local * per_cell..(local + 1) * per_cell]);
                    }
                }
            }
        }
        out
    }
}

/// Splits block-ordered data into one mutable chunk per block.
fn split<'a, T>(data: &'a mut [T], starts: &[usize], per_cell: usize) -> Vec<&'a mut [T]> {
    let mut chunks = Vec::with_capacity(starts.len() - 1);
    let mut rest = data;
    for w in starts.windows(2) {
        let (head, tail) = rest.split_at_mut((w[1] - w[0]) * per_cell);
        chunks.push(head);
        rest = tail;
    }
    chunks
}

/// The index of a boundary face cell on the domain face normal to `axis`.
fn face_cell(dims: [usize; 3], axis: usize, at: [usize; 3]) -> usize {
    match axis {
        0 => at[1] + dims[1] * at[2],
        1 => at[0] + dims[0] * at[2],
        _ => at[0] + dims[0] * at[1],
    }
}

/// Everything a sweep reads.
#[derive(Clone, Copy)]
pub(crate) struct SweepInput<'a> {
    pub layout: &'a Layout,
    pub ordinates: &'a Ordinates,
    /// Per propagation direction.
    pub geometry: &'a [CellDirection],
    /// Block order.
    pub sigma_t: &'a [f32],
    /// Incoming radiance per boundary face cell on faces (−x, +x, −y, +y, −z, +z); the
    /// same for every incoming direction.
    pub inflow: &'a [Vec<f64>; 6],
    /// Cell widths (length).
    pub spacing: [f64; 3],
    /// The most blocks whose work is held at once (a pager's pool; unbounded in memory).
    pub max_pinned: usize,
    /// With a source, each block's work is filled with S_n = Q_n + σ_s J_n just before the
    /// block is swept (storage directions = propagation directions), so the work is only
    /// written, never read before the sweep; without, the work holds S_n on entry.
    pub source: Option<CellSource<'a>>,
    /// Ctrl-C and the time limit, asked before every wavefront (a sweep of 256³ cells in
    /// 48 directions takes seconds; a wavefront, milliseconds): a halted sweep gives up
    /// and returns `None`, its work part swept.
    pub interrupt: &'a lucent_core::Interrupt,
}

/// What the fused source fill reads, all in block order: the fixed source (`None`: zero,
/// for the homogeneous sweeps of a Krylov iteration) and the in-scattered radiance per
/// cell and storage direction, and σ_s per cell.
#[derive(Clone, Copy)]
pub(crate) struct CellSource<'a> {
    pub fixed: Option<&'a [f32]>,
    pub previous: &'a [f32],
    pub sigma_s: &'a [f32],
    /// Storage directions per cell.
    pub storage: usize,
}

/// What a sweep produces besides the cell-average radiance.
pub(crate) struct SweepOutput {
    /// Scalar flux Σ w ψ̄, block order.
    pub fluence: Vec<f64>,
    /// Outgoing partial current Σ w |ω·n| ψ per boundary face cell, per face.
    pub outflow: [Vec<f64>; 6],
    /// Power entering through the boundary.
    pub inflow_power: f64,
    /// Power leaving through the boundary.
    pub outflow_power: f64,
}

struct BlockResult {
    block: usize,
    planes: [Vec<f64>; 3],
    inflow_power: f64,
}

/// One full sweep (eight octants) with closure `C`. `work` holds, octant by octant (the
/// propagation directions are ordered by octant), per cell (block order) and direction of
/// the octant, the source S_n on entry and the cell-average radiance ψ̄_n on return: each
/// octant's sweep streams through its own contiguous eighth.
pub(crate) fn sweep<C: CellClosure>(
    input: &SweepInput<'_>,
    work: &mut [f64],
) -> Option<SweepOutput> {
    let layout = input.layout;
    let cells = layout.cells();
    // Each octant's eighth of `work`, cut into one chunk per block.
    let mut chunks: Vec<Vec<Option<&mut [f64]>>> = Vec::new();
    let mut rest = work;
    for octant in 0..8 {
        let nd = input.ordinates.octant(octant).len();
        if nd == 0 {
            continue;
        }
        let (head, tail) = rest.split_at_mut(cells * nd);
        chunks.push(
            split(head, &layout.starts, nd)
                .into_iter()
                .map(Some)
                .collect(),
        );
        rest = tail;
    }
    let out = sweep_with::<C, _, std::convert::Infallible>(
        input,
        |slot, block, _| {
            Ok(chunks[slot][block]
                .take()
                .expect("each block's chunk is swept once per octant"))
        },
        |_, _, _| {},
    );
    match out {
        Ok(out) => out,
        Err(never) => match never {},
    }
}

/// [`sweep`] with the per-direction work in pages of a pager ([`WorkPages`]): each block's
/// page of an octant is pinned while the block is swept, the blocks of a wavefront at most
/// as many at a time as the pool holds. A helper thread writes each wavefront's pages
/// back while the next one is swept (so evicting them later costs no I/O) and, when the
/// sweep reads its source from the pages and the pool holds two wavefronts, prefetches
/// the next wavefront's pages. The same arithmetic in the same order as in memory, so the
/// same bits.
pub(crate) fn sweep_paged<C: CellClosure>(
    input: &SweepInput<'_>,
    pages: &WorkPages,
) -> Result<Option<SweepOutput>, PagingError> {
    let widest = (0..8)
        .map(|o| {
            let negative = [o & 1 != 0, o & 2 != 0, o & 4 != 0];
            let planes = input.layout.bricks.wavefronts(negative);
            planes.iter().map(Vec::len).max().unwrap_or(0)
        })
        .max()
        .unwrap_or(0);
    // Prefetch reads pages the sweep will read; a fused fill reads none.
    let capacity = pages.pager.capacity();
    let prefetch = input.source.is_none() && capacity > 2 * widest;
    // Writing behind holds one slot at a time: the sweep pins one page fewer at once,
    // and with a single slot nothing is written behind.
    let write_behind = capacity >= 2;
    let input = &SweepInput {
        max_pinned: input.max_pinned.min(capacity - usize::from(write_behind)),
        ..*input
    };
    enum Job {
        Prefetch(Vec<usize>),
        WriteBack(Vec<usize>),
    }
    std::thread::scope(|scope| {
        let (sender, receiver) = std::sync::mpsc::channel::<Job>();
        let helper = scope.spawn(move || -> Result<(), PagingError> {
            for job in receiver {
                match job {
                    Job::Prefetch(next) => pages.pager.prefetch(next)?,
                    Job::WriteBack(done) => pages.pager.write_back(done)?,
                }
            }
            Ok(())
        });
        let out = sweep_with::<C, _, PagingError>(
            input,
            |slot, block, len| {
                let page = pages.page(slot, block);
                // A fused fill writes the whole block's work: nothing to read first.
                let pin = if input.source.is_some() {
                    pages.pager.overwrite(page)?
                } else {
                    pages.pager.write(page)?
                };
                Ok(Window { pin, len })
            },
            |slot, done, next| {
                if write_behind && !done.is_empty() {
                    let done = done.iter().map(|&b| pages.page(slot, b)).collect();
                    let _ = sender.send(Job::WriteBack(done));
                }
                if prefetch && !next.is_empty() {
                    let next = next.iter().map(|&b| pages.page(slot, b)).collect();
                    let _ = sender.send(Job::Prefetch(next));
                }
            },
        );
        drop(sender);
        match helper.join() {
            Err(panic) => std::panic::resume_unwind(panic),
            Ok(Err(e)) if out.is_ok() => Err(e),
            Ok(_) => out,
        }
    })
}

/// The first `len` values of a pinned page.
struct Window {
    pin: WritePin<f64>,
    len: usize,
}

impl std::ops::Deref for Window {
    type Target = [f64];
    fn deref(&self) -> &[f64] {
        &self.pin[..self.len]
    }
}

impl std::ops::DerefMut for Window {
    fn deref_mut(&mut self) -> &mut [f64] {
        &mut self.pin[..self.len]
    }
}

/// The octant sweeps, each block's work for an octant taken from `chunk(octant slot,
/// block, length)` (the octant slot counts non-empty octants) when its wavefront comes;
/// `between(octant slot, done, next)` is told, as each wavefront starts, the blocks of the
/// one just swept (their work released) and of the next.
fn sweep_with<C, G, E>(
    input: &SweepInput<'_>,
    mut chunk: impl FnMut(usize, usize, usize) -> Result<G, E>,
    mut between: impl FnMut(usize, &[usize], &[usize]),
) -> Result<Option<SweepOutput>, E>
where
    C: CellClosure,
    G: std::ops::DerefMut<Target = [f64]> + Send,
{
    let layout = input.layout;
    let dims = layout.dims();
    let mut fluence = vec![0.0f64; layout.cells()];
    let mut outflow: [Vec<f64>; 6] = std::array::from_fn(|f| {
        let a = f / 2;
        vec![0.0; dims[(a + 1) % 3] * dims[(a + 2) % 3]]
    });
    let mut inflow_power = 0.0;
    let mut outflow_power = 0.0;
    let weights = input.ordinates.propagation().weights();
    let directions = input.ordinates.propagation().directions();
    let h = input.spacing;
    let volume = h[0] * h[1] * h[2];
    let mut slot = 0;
    for octant in 0..8 {
        let dirs = input.ordinates.octant(octant);
        if dirs.is_empty() {
            continue;
        }
        let nd = dirs.len();
        let negative = [octant & 1 != 0, octant & 2 != 0, octant & 4 != 0];
        let mut phi_chunks: Vec<Option<&mut [f64]>> = split(&mut fluence, &layout.starts, 1)
            .into_iter()
            .map(Some)
            .collect();
        let mut planes: Vec<Option<[Vec<f64>; 3]>> = vec![None; layout.block_count()];
        let nb = layout.bricks.bricks();
        let wavefronts = layout.bricks.wavefronts(negative);
        for (w, plane) in wavefronts.iter().enumerate() {
            if input.interrupt.halted() {
                return Ok(None);
            }
            let done = if w > 0 { &wavefronts[w - 1][..] } else { &[] };
            let next = wavefronts.get(w + 1).map_or(&[][..], |n| &n[..]);
            between(slot, done, next);
            // The blocks of one hyperplane, counted from the octant's upwind corner, in
            // batches of at most `input.max_pinned` (a pager's pool).
            for batch in plane.chunks(input.max_pinned.max(1)) {
                let mut tasks = Vec::new();
                for &b in batch {
                    let coords = layout.bricks.coords(b);
                    if let Some(p) = phi_chunks[b].take() {
                        let len = (layout.starts[b + 1] - layout.starts[b]) * nd;
                        tasks.push((b, coords, chunk(slot, b, len)?, p));
                    }
                }
                let results: Vec<BlockResult> = tasks
                    .into_par_iter()
                    .map(|(b, coords, mut j, p)| {
                        let upwind: [Option<&[Vec<f64>; 3]>; 3] = std::array::from_fn(|a| {
                            let edge = if negative[a] {
                                coords[a] + 1 == nb[a]
                            } else {
                                coords[a] == 0
                            };
                            if edge {
                                return None;
                            }
                            let mut c = coords;
                            if negative[a] {
                                c[a] += 1
                            } else {
                                c[a] -= 1
                            }
                            planes[layout.block_index(c)].as_ref()
                        });
                        block_sweep::<C>(input, b, dirs, negative, upwind, &mut j, p)
                    })
                    .collect();
                for r in results {
                    // What leaves through the downstream domain faces.
                    let o = layout.origin(r.block);
                    let e = layout.extent(r.block);
                    for a in 0..3 {
                        let at_edge = if negative[a] {
                            o[a] == 0
                        } else {
                            o[a] + e[a] == dims[a]
                        };
                        if !at_edge {
                            continue;
                        }
                        let face = 2 * a + usize::from(!negative[a]);
                        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
                        let area = volume / h[a];
                        for v in 0..e[c] {
                            for u in 0..e[b] {
                                let mut local = [0; 3];
                                local[b] = u;
                                local[c] = v;
                                let slot = plane_index(a, e, local);
                                let mut current = 0.0;
                                for (d, &n) in dirs.iter().enumerate() {
                                    current += weights[n]
                                        * directions[n][a].abs()
                                        * r.planes[a][slot * nd + d];
                                }
                                let at = [o[0] + local[0], o[1] + local[1], o[2] + local[2]];
                                outflow[face][face_cell(dims, a, at)] += current;
                                outflow_power += current * area;
                            }
                        }
                    }
                    inflow_power += r.inflow_power;
                    planes[r.block] = Some(r.planes);
                }
            }
        }
        if let Some(last) = wavefronts.last() {
            between(slot, last, &[]);
        }
        slot += 1;
    }
    Ok(Some(SweepOutput {
        fluence,
        outflow,
        inflow_power,
        outflow_power,
    }))
}

/// The per-direction work of the sweeps in a pager of f64 pages, one page per (non-empty
/// octant, block): a block's cells × the octant's directions, cell-major as in memory
/// (pages of the smaller edge blocks use a prefix).
#[derive(Debug)]
pub struct WorkPages {
    pager: Arc<Pager<f64>>,
    first: usize,
    blocks: usize,
}

impl WorkPages {
    /// Values per page for `layout` and `ordinates`: the largest block's cells times the
    /// largest octant's directions.
    pub fn page_len(layout: &Layout, ordinates: &Ordinates) -> usize {
        let block = layout.bricks.brick().pow(3);
        let nd = (0..8).map(|o| ordinates.octant(o).len()).max().unwrap_or(0);
        block * nd
    }

    /// Pages for `layout` and `ordinates` in `pager` (whose bricks must be
    /// [`WorkPages::page_len`] long), all fresh.
    pub fn new(
        layout: &Layout,
        ordinates: &Ordinates,
        pager: Arc<Pager<f64>>,
    ) -> Result<Self, PagingError> {
        let len = Self::page_len(layout, ordinates);
        if pager.brick_len() != len {
            return Err(PagingError::Shape(format!(
                "pages of {} values for work pages of {len}",
                pager.brick_len()
            )));
        }
        let octants = (0..8).filter(|&o| !ordinates.octant(o).is_empty()).count();
        let blocks = layout.block_count();
        let first = pager.add_bricks(octants * blocks);
        Ok(Self {
            pager,
            first,
            blocks,
        })
    }

    /// The pager.
    pub fn pager(&self) -> &Arc<Pager<f64>> {
        &self.pager
    }

    pub(crate) fn page(&self, slot: usize, block: usize) -> usize {
        self.first + slot * self.blocks + block
    }
}

/// Index of a cell's slot in the plane normal to `axis` of a block of extent `e`.
#[inline]
fn plane_index(axis: usize, e: [usize; 3], local: [usize; 3]) -> usize {
    match axis {
        0 => local[1] + e[1] * local[2],
        1 => local[0] + e[0] * local[2],
        _ => local[0] + e[0] * local[1],
    }
}

/// One block, all directions of one octant, cell by cell in upwind-first order.
#[allow(clippy::too_many_arguments)]
fn block_sweep<C: CellClosure>(
    input: &SweepInput<'_>,
    b: usize,
    dirs: &[usize],
    negative: [bool; 3],
    upwind: [Option<&[Vec<f64>; 3]>; 3],
    work: &mut [f64],
    fluence: &mut [f64],
) -> BlockResult {
    let layout = input.layout;
    let dims = layout.dims();
    let o = layout.origin(b);
    let e = layout.extent(b);
    let nd = dirs.len();
    let start = layout.starts[b];
    let weights = input.ordinates.propagation().weights();
    let directions = input.ordinates.propagation().directions();
    let h = input.spacing;
    let volume = h[0] * h[1] * h[2];
    let mut inflow_power = 0.0;
    if let Some(source) = &input.source {
        // S_n = Q_n + σ_s J_n for this block and octant, as `fill` computes it.
        let (first, m) = (dirs[0], source.storage);
        for (local, row) in work.chunks_mut(nd).enumerate() {
            let cell = start + local;
            let s = f64::from(source.sigma_s[cell]);
            let at = cell * m + first;
            let previous = &source.previous[at..at + nd];
            match source.fixed {
                Some(fixed) => {
                    for ((w, q), j) in row.iter_mut().zip(&fixed[at..at + nd]).zip(previous) {
                        *w = f64::from(*q) + s * f64::from(*j);
                    }
                }
                None => {
                    for (w, j) in row.iter_mut().zip(previous) {
                        *w = s * f64::from(*j);
                    }
                }
            }
        }
    }

    // Incoming planes: the upwind block's outgoing plane, or the domain's inflow.
    let mut incoming = |a: usize| -> Vec<f64> {
        let (bb, cc) = ((a + 1) % 3, (a + 2) % 3);
        let size = e[bb] * e[cc];
        match upwind[a] {
            Some(p) => p[a].clone(),
            None => {
                let face = 2 * a + usize::from(negative[a]);
                let mut plane = vec![0.0; size * nd];
                let area = volume / h[a];
                for v in 0..e[cc] {
                    for u in 0..e[bb] {
                        let mut local = [0; 3];
                        local[bb] = u;
                        local[cc] = v;
                        let at = [o[0] + local[0], o[1] + local[1], o[2] + local[2]];
                        let value = input.inflow[face][face_cell(dims, a, at)];
                        if value == 0.0 {
                            continue;
                        }
                        let slot = plane_index(a, e, local);
                        for (d, &n) in dirs.iter().enumerate() {
                            plane[slot * nd + d] = value;
                            inflow_power += weights[n] * directions[n][a].abs() * area * value;
                        }
                    }
                }
                plane
            }
        }
    };
    let mut plane_x = incoming(0);
    let mut plane_y = incoming(1);
    let mut plane_z = incoming(2);

    // The octant's directions are contiguous (see `Ordinates`).
    let first = dirs[0];
    let octant = OctantDirections::new(
        &input.geometry[first..first + nd],
        &weights[first..first + nd],
    );
    let mut x_face = vec![0.0f64; nd];
    for kk in 0..e[2] {
        let k = if negative[2] { e[2] - 1 - kk } else { kk };
        for jj in 0..e[1] {
            let j = if negative[1] { e[1] - 1 - jj } else { jj };
            let xs = (j + e[1] * k) * nd;
            x_face.copy_from_slice(&plane_x[xs..xs + nd]);
            for ii in 0..e[0] {
                let i = if negative[0] { e[0] - 1 - ii } else { ii };
                let local = i + e[0] * (j + e[1] * k);
                let sigma_t = f64::from(input.sigma_t[start + local]);
                let row = &mut work[local * nd..(local + 1) * nd];
                let ys = (i + e[0] * k) * nd;
                let zs = (i + e[0] * j) * nd;
                let py = &mut plane_y[ys..ys + nd];
                let pz = &mut plane_z[zs..zs + nd];
                fluence[local] += C::solve_cell(&octant, sigma_t, row, [&mut x_face, py, pz]);
            }
            plane_x[xs..xs + nd].copy_from_slice(&x_face);
        }
    }
    BlockResult {
        block: b,
        planes: [plane_x, plane_y, plane_z],
        inflow_power,
    }
}
