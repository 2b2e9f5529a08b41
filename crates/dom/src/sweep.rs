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

use lucent_grid::BrickLayout;
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
pub(crate) fn sweep<C: CellClosure>(input: &SweepInput<'_>, work: &mut [f64]) -> SweepOutput {
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
    for octant in 0..8 {
        let dirs = input.ordinates.octant(octant);
        if dirs.is_empty() {
            continue;
        }
        let nd = dirs.len();
        let negative = [octant & 1 != 0, octant & 2 != 0, octant & 4 != 0];
        let first = dirs[0];
        let cells = layout.cells();
        let octant_work = &mut work[cells * first..cells * (first + nd)];
        let mut work_chunks: Vec<Option<&mut [f64]>> = split(octant_work, &layout.starts, nd)
            .into_iter()
            .map(Some)
            .collect();
        let mut phi_chunks: Vec<Option<&mut [f64]>> = split(&mut fluence, &layout.starts, 1)
            .into_iter()
            .map(Some)
            .collect();
        let mut planes: Vec<Option<[Vec<f64>; 3]>> = vec![None; layout.block_count()];
        let nb = layout.bricks.bricks();
        for plane in layout.bricks.wavefronts(negative) {
            // The blocks of one hyperplane, counted from the octant's upwind corner.
            let mut tasks = Vec::new();
            for b in plane {
                let coords = layout.bricks.coords(b);
                if let (Some(j), Some(p)) = (work_chunks[b].take(), phi_chunks[b].take()) {
                    tasks.push((b, coords, j, p));
                }
            }
            let results: Vec<BlockResult> = tasks
                .into_par_iter()
                .map(|(b, coords, j, p)| {
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
                    block_sweep::<C>(input, b, dirs, negative, upwind, j, p)
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
    SweepOutput {
        fluence,
        outflow,
        inflow_power,
        outflow_power,
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
