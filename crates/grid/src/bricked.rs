//! A sparse bricked grid: only bricks whose values vary are stored; constant bricks (empty
//! space above all) cost one number. Each brick also knows the min and max of the trilinear
//! interpolant over its cells, the coarse majorant that Monte Carlo delta tracking and
//! empty-space skipping walk. Bricks are those of [`BrickLayout`], the layout the pager and
//! the ordinates' sweeps share.

use glam::DVec3;
use rayon::prelude::*;

use crate::bricks::BrickLayout;
use crate::dense::Grid;
use crate::error::GridError;
use crate::geometry::GridGeometry;

/// Marks a brick that is stored as a single constant.
const CONSTANT: u32 = u32::MAX;

/// A grid stored as B³ bricks (B a power of two, 8 by default), of which only the
/// non-constant ones hold B³ values.
///
/// Lookups return exactly the values of the dense grid it was built from. Bricks on the
/// upper faces may stick out of the domain; their outside part is padded with the nearest
/// inside value and never returned.
///
/// Per brick, `min`/`max` are taken over the brick *with its one-cell apron*
/// ([`BrickLayout::gather`]): they bound the trilinear interpolant
/// ([`Grid::sample_trilinear`]) everywhere inside the brick's cells, which is what a
/// majorant must do (the interpolant near a brick's face blends in its neighbours).
#[derive(Debug, Clone, PartialEq)]
pub struct BrickedGrid {
    geometry: GridGeometry,
    layout: BrickLayout,
    log2_brick: u32,
    /// Per brick: offset of its values in `pool` (in bricks), or `CONSTANT`.
    slots: Vec<u32>,
    /// Per brick: its value where it is constant (0 otherwise).
    constant: Vec<f32>,
    /// Per brick: smallest and largest value over the brick and its apron.
    min: Vec<f32>,
    max: Vec<f32>,
    /// The stored bricks, B³ values each, x-fastest inside a brick.
    pool: Vec<f32>,
}

impl BrickedGrid {
    /// The default brick edge, as in OpenVDB's and NanoVDB's leaf nodes.
    pub const DEFAULT_BRICK_SIZE: usize = 8;

    /// Bricks a dense grid with bricks of `brick_size`³ cells (a power of two, 1 to 64).
    pub fn from_dense(grid: &Grid, brick_size: usize) -> Result<Self, GridError> {
        if !brick_size.is_power_of_two() || brick_size > 64 {
            return Err(GridError::InvalidParameter {
                name: "brick_size",
                reason: format!("{brick_size} is not a power of two between 1 and 64"),
            });
        }
        let geometry = *grid.geometry();
        let layout = BrickLayout::new(geometry.dims(), brick_size)?;
        let log2_brick = brick_size.trailing_zeros();
        let brick_count = layout.count();
        if brick_count >= CONSTANT as usize {
            return Err(GridError::InvalidParameter {
                name: "brick_size",
                reason: "too many bricks".into(),
            });
        }
        let b = brick_size;
        let value = |c: [usize; 3]| grid.data()[geometry.index(c[0], c[1], c[2])];
        // Per brick, in parallel: its B³ values (padded past the upper faces), the range
        // over the brick and its apron, and whether the values are all one.
        let per_brick: Vec<(Option<Vec<f32>>, f32, f32, f32)> = (0..brick_count)
            .into_par_iter()
            .map(|id| {
                let stored = layout.gather(id, value);
                let lo = stored.iter().copied().fold(f32::INFINITY, f32::min);
                let hi = stored.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                let mut values = Vec::with_capacity(b * b * b);
                for k in 0..b {
                    for j in 0..b {
                        for i in 0..b {
                            let at = [i, j, k].map(|c| c as isize);
                            values.push(stored[layout.stored_index(at)]);
                        }
                    }
                }
                // Bitwise equality keeps −0.0 and NaN payloads exact.
                let first = values[0];
                let constant = values.iter().all(|v| v.to_bits() == first.to_bits());
                ((!constant).then_some(values), first, lo, hi)
            })
            .collect();
        let mut this = Self {
            geometry,
            layout,
            log2_brick,
            slots: vec![CONSTANT; brick_count],
            constant: vec![0.0; brick_count],
            min: Vec::with_capacity(brick_count),
            max: Vec::with_capacity(brick_count),
            pool: Vec::new(),
        };
        for (id, (values, first, lo, hi)) in per_brick.into_iter().enumerate() {
            this.min.push(lo);
            this.max.push(hi);
            match values {
                None => this.constant[id] = first,
                Some(values) => {
                    this.slots[id] = (this.pool.len() >> (3 * log2_brick)) as u32;
                    this.pool.extend_from_slice(&values);
                }
            }
        }
        this.pool.shrink_to_fit();
        Ok(this)
    }

    /// The geometry of the underlying dense grid.
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// The brick layout.
    pub fn layout(&self) -> &BrickLayout {
        &self.layout
    }

    /// Brick edge length in cells.
    pub fn brick_size(&self) -> usize {
        1 << self.log2_brick
    }

    /// Bricks per axis.
    pub fn brick_dims(&self) -> [usize; 3] {
        self.layout.bricks()
    }

    /// Number of bricks that store values (the rest are constant).
    pub fn stored_bricks(&self) -> usize {
        self.pool.len() >> (3 * self.log2_brick)
    }

    /// Value of cell (i, j, k), or `None` outside the grid.
    #[inline]
    pub fn get(&self, i: usize, j: usize, k: usize) -> Option<f32> {
        let [nx, ny, nz] = self.geometry.dims();
        if i >= nx || j >= ny || k >= nz {
            return None;
        }
        let s = self.log2_brick;
        let mask = (1 << s) - 1;
        let [bx, by, _] = self.layout.bricks();
        let brick = (i >> s) + bx * ((j >> s) + by * (k >> s));
        let slot = self.slots[brick];
        if slot == CONSTANT {
            return Some(self.constant[brick]);
        }
        let local = (i & mask) | (j & mask) << s | (k & mask) << (2 * s);
        Some(self.pool[((slot as usize) << (3 * s)) + local])
    }

    /// (min, max) over brick (bi, bj, bk) and its apron — bounds of the trilinear
    /// interpolant in the brick's cells — or `None` outside the brick grid.
    pub fn brick_range(&self, bi: usize, bj: usize, bk: usize) -> Option<(f32, f32)> {
        let [bx, by, bz] = self.layout.bricks();
        (bi < bx && bj < by && bk < bz).then(|| {
            let b = bi + bx * (bj + by * bk);
            (self.min[b], self.max[b])
        })
    }

    /// Per brick, the maximum over the brick and its apron (a bound of the trilinear
    /// interpolant in the brick), in brick order.
    pub fn brick_maxima(&self) -> &[f32] {
        &self.max
    }

    /// The coarse majorant grid: one cell per brick holding the brick's maximum, on the
    /// geometry coarsened by the brick size (covering the bricks that stick out too).
    pub fn majorant_grid(&self) -> Grid {
        // Coarsening a valid geometry by a factor ≥ 1 cannot fail; its dims are brick_dims.
        let geometry = self
            .geometry
            .coarsened(self.brick_size())
            .unwrap_or(self.geometry);
        Grid::from_parts(geometry, self.max.clone())
    }

    /// An upper bound of the trilinear interpolant over the world box `lo..hi` (a ray
    /// segment's bounding box, a majorant cell): the largest brick maximum among the bricks
    /// whose cells the box touches. The box is clipped to the grid (outside it the
    /// interpolant repeats the face values, which the face bricks' ranges include); a box
    /// that misses the grid entirely gets the bound of the nearest bricks. NaN corners
    /// give the whole grid's maximum.
    pub fn max_over(&self, lo: DVec3, hi: DVec3) -> f32 {
        let dims = self.geometry.dims();
        let cell = |p: DVec3| {
            let v = self.geometry.world_to_voxel(p) + 0.5;
            [0, 1, 2].map(|a| {
                let c = v[a].floor();
                if c.is_nan() {
                    0
                } else {
                    c.clamp(0.0, (dims[a] - 1) as f64) as usize
                }
            })
        };
        let (a, b) = if lo.is_nan() || hi.is_nan() {
            ([0; 3], dims.map(|n| n - 1))
        } else {
            (cell(lo.min(hi)), cell(lo.max(hi)))
        };
        self.max_over_cells(a, b)
    }

    /// The largest brick maximum among the bricks holding cells `lo..=hi` (clamped).
    pub fn max_over_cells(&self, lo: [usize; 3], hi: [usize; 3]) -> f32 {
        self.layout
            .bricks_in_box(lo, hi)
            .map(|id| self.max[id])
            .fold(f32::NEG_INFINITY, f32::max)
    }

    /// The dense grid back, bit for bit.
    pub fn to_dense(&self) -> Grid {
        let [nx, ny, _] = self.geometry.dims();
        let mut grid = Grid::filled(self.geometry, 0.0);
        grid.slabs_mut().for_each(|(k, slab)| {
            for j in 0..ny {
                for i in 0..nx {
                    slab[i + nx * j] = self.get(i, j, k).unwrap_or(0.0);
                }
            }
        });
        grid
    }

    /// Bytes this grid holds: stored bricks, per-brick slot, constant, min and max.
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.pool.len() * std::mem::size_of::<f32>()
            + self.slots.len() * (std::mem::size_of::<u32>() + 3 * std::mem::size_of::<f32>())
    }

    /// Bytes the same grid takes dense (one f32 per cell), for comparison.
    pub fn dense_memory_bytes(&self) -> usize {
        std::mem::size_of::<Grid>() + self.geometry.voxel_count() * std::mem::size_of::<f32>()
    }
}
