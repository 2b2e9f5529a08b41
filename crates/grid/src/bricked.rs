//! A sparse bricked grid: only bricks whose values vary are stored; constant bricks (empty
//! space above all) cost one number. Each brick also knows its min and max, the coarse
//! majorant grid that Monte Carlo delta tracking and empty-space skipping walk.

use rayon::prelude::*;

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
#[derive(Debug, Clone, PartialEq)]
pub struct BrickedGrid {
    geometry: GridGeometry,
    log2_brick: u32,
    brick_dims: [usize; 3],
    /// Per brick: offset of its values in `pool` (in bricks), or `CONSTANT`.
    slots: Vec<u32>,
    /// Per brick: smallest and largest value (equal for constant bricks).
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
        let log2_brick = brick_size.trailing_zeros();
        let brick_dims = geometry.dims().map(|n| n.div_ceil(brick_size));
        let brick_count = brick_dims[0] * brick_dims[1] * brick_dims[2];
        if brick_count >= CONSTANT as usize {
            return Err(GridError::InvalidParameter {
                name: "brick_size",
                reason: "too many bricks".into(),
            });
        }
        let mut this = Self {
            geometry,
            log2_brick,
            brick_dims,
            slots: vec![CONSTANT; brick_count],
            min: vec![0.0; brick_count],
            max: vec![0.0; brick_count],
            pool: Vec::new(),
        };
        let [nx, ny, nz] = geometry.dims();
        let b = brick_size;
        let mut values = vec![0.0f32; b * b * b];
        for bk in 0..brick_dims[2] {
            for bj in 0..brick_dims[1] {
                for bi in 0..brick_dims[0] {
                    for (l, v) in values.iter_mut().enumerate() {
                        let (li, lj, lk) = (l % b, (l / b) % b, l / (b * b));
                        let (i, j, k) = (
                            (bi * b + li).min(nx - 1),
                            (bj * b + lj).min(ny - 1),
                            (bk * b + lk).min(nz - 1),
                        );
                        *v = grid.data()[geometry.index(i, j, k)];
                    }
                    let lo = values.iter().copied().fold(f32::INFINITY, f32::min);
                    let hi = values.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                    let brick = bi + brick_dims[0] * (bj + brick_dims[1] * bk);
                    this.min[brick] = lo;
                    this.max[brick] = hi;
                    // Bitwise equality keeps −0.0 and NaN payloads exact.
                    let constant = values.iter().all(|v| v.to_bits() == values[0].to_bits());
                    if constant {
                        this.min[brick] = values[0];
                        this.max[brick] = values[0];
                    } else {
                        this.slots[brick] = (this.pool.len() >> (3 * log2_brick)) as u32;
                        this.pool.extend_from_slice(&values);
                    }
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

    /// Brick edge length in cells.
    pub fn brick_size(&self) -> usize {
        1 << self.log2_brick
    }

    /// Bricks per axis.
    pub fn brick_dims(&self) -> [usize; 3] {
        self.brick_dims
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
        let brick = (i >> s) + self.brick_dims[0] * ((j >> s) + self.brick_dims[1] * (k >> s));
        let slot = self.slots[brick];
        if slot == CONSTANT {
            return Some(self.min[brick]);
        }
        let local = (i & mask) | (j & mask) << s | (k & mask) << (2 * s);
        Some(self.pool[((slot as usize) << (3 * s)) + local])
    }

    /// (min, max) of brick (bi, bj, bk), or `None` outside the brick grid.
    pub fn brick_range(&self, bi: usize, bj: usize, bk: usize) -> Option<(f32, f32)> {
        let [bx, by, bz] = self.brick_dims;
        (bi < bx && bj < by && bk < bz).then(|| {
            let b = bi + bx * (bj + by * bk);
            (self.min[b], self.max[b])
        })
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

    /// Bytes this grid holds: stored bricks, per-brick slot, min and max.
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.pool.len() * std::mem::size_of::<f32>()
            + self.slots.len() * (std::mem::size_of::<u32>() + 2 * std::mem::size_of::<f32>())
    }

    /// Bytes the same grid takes dense (one f32 per cell), for comparison.
    pub fn dense_memory_bytes(&self) -> usize {
        std::mem::size_of::<Grid>() + self.geometry.voxel_count() * std::mem::size_of::<f32>()
    }
}
