//! The one brick layout of lucent: how a grid of cells is cut into B³ bricks, how a brick is
//! stored with its one-cell apron, and the orders in which bricks are streamed.
//!
//! Shared by [`crate::BrickedGrid`] (sparse storage with per-brick min/max), the pager of
//! `lucent-paging` (bricks paged through a pool, stored with their apron) and the block
//! sweeps of `lucent-dom` (wavefronts of bricks per octant), so a brick means the same
//! cells everywhere and a streaming order computed for one serves the others.
//!
//! - Brick (I, J, K) holds cells B·(I, J, K) + [0, B)³, clipped at the grid's upper faces
//!   (edge bricks are smaller: [`BrickLayout::extent`]). Bricks are numbered x fastest,
//!   like cells: `I + n_I (J + n_J K)`, which is also the z-slab streaming order.
//! - A *stored* brick is (B + 2)³ values: the brick's cells and a one-cell apron around
//!   them holding copies of the neighbouring cells (clamped to the grid at its faces, the
//!   value [`crate::Grid::sample_trilinear`] reads there), x fastest. A 7-point stencil or a
//!   trilinear sample anywhere inside the brick reads only its stored brick, without
//!   branches; the price is (B + 2)³/B³ in memory (1.42 at B = 16, 1.95 at B = 8).
//! - The min and max over a stored brick (apron included) bound the trilinear
//!   interpolant everywhere in the brick's cells: the majorant a delta tracker needs.

use crate::error::GridError;

/// Cells of a grid cut into bricks of `brick`³ cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BrickLayout {
    dims: [usize; 3],
    brick: usize,
    bricks: [usize; 3],
}

impl BrickLayout {
    /// Apron cells on each side of a stored brick.
    pub const APRON: usize = 1;
    /// The largest brick edge (the ordinates' sweeps take blocks up to 256 cells; stores
    /// of bricks with aprons choose far smaller ones: 66³ f32 values are 1.1 MiB).
    pub const MAX_BRICK: usize = 256;

    /// Bricks of `brick`³ cells (1 to [`Self::MAX_BRICK`]) over `dims` cells (each ≥ 1).
    pub fn new(dims: [usize; 3], brick: usize) -> Result<Self, GridError> {
        if !(1..=Self::MAX_BRICK).contains(&brick) {
            return Err(GridError::InvalidParameter {
                name: "brick_size",
                reason: format!("{brick} is not between 1 and {}", Self::MAX_BRICK),
            });
        }
        if dims.contains(&0) {
            return Err(GridError::InvalidGeometry(format!(
                "dimensions {dims:?} must all be at least 1"
            )));
        }
        Ok(Self {
            dims,
            brick,
            bricks: dims.map(|n| n.div_ceil(brick)),
        })
    }

    /// Cells per axis.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Brick edge in cells.
    pub fn brick(&self) -> usize {
        self.brick
    }

    /// Bricks per axis.
    pub fn bricks(&self) -> [usize; 3] {
        self.bricks
    }

    /// Number of bricks.
    pub fn count(&self) -> usize {
        self.bricks[0] * self.bricks[1] * self.bricks[2]
    }

    /// Brick coordinates (I, J, K) of brick `id`.
    #[inline]
    pub fn coords(&self, id: usize) -> [usize; 3] {
        let [bx, by, _] = self.bricks;
        [id % bx, (id / bx) % by, id / (bx * by)]
    }

    /// The number of brick (I, J, K).
    #[inline]
    pub fn id(&self, coords: [usize; 3]) -> usize {
        coords[0] + self.bricks[0] * (coords[1] + self.bricks[1] * coords[2])
    }

    /// The brick's first cell.
    #[inline]
    pub fn origin(&self, id: usize) -> [usize; 3] {
        self.coords(id).map(|c| c * self.brick)
    }

    /// The brick's cells per axis (B, or fewer at the grid's upper faces).
    #[inline]
    pub fn extent(&self, id: usize) -> [usize; 3] {
        let o = self.origin(id);
        [0, 1, 2].map(|a| self.brick.min(self.dims[a] - o[a]))
    }

    /// The brick's first and last cells (inclusive).
    #[inline]
    pub fn cell_box(&self, id: usize) -> [[usize; 3]; 2] {
        let o = self.origin(id);
        let e = self.extent(id);
        [o, [0, 1, 2].map(|a| o[a] + e[a] - 1)]
    }

    /// The brick holding cell `cell` and the cell's coordinates inside it.
    #[inline]
    pub fn locate(&self, cell: [usize; 3]) -> (usize, [usize; 3]) {
        let b = self.brick;
        (
            self.id(cell.map(|c| c / b)),
            [cell[0] % b, cell[1] % b, cell[2] % b],
        )
    }

    /// Values per axis of a stored brick: B + 2 (the apron).
    #[inline]
    pub fn stored_edge(&self) -> usize {
        self.brick + 2 * Self::APRON
    }

    /// Values in a stored brick: (B + 2)³.
    #[inline]
    pub fn stored_len(&self) -> usize {
        self.stored_edge().pow(3)
    }

    /// Index in a stored brick of local cell `local` (each coordinate from −1, the apron
    /// below, to B, the apron above).
    #[inline]
    pub fn stored_index(&self, local: [isize; 3]) -> usize {
        let e = self.stored_edge();
        let at = |c: isize| (c + Self::APRON as isize) as usize;
        at(local[0]) + e * (at(local[1]) + e * at(local[2]))
    }

    /// The stored brick `id` of a grid whose cell (i, j, k) has value `value([i, j, k])`:
    /// the brick's cells and the apron, clamped to the grid (cells past the upper faces of
    /// an edge brick repeat the last cell too, so the whole stored brick is defined).
    pub fn gather(&self, id: usize, value: impl Fn([usize; 3]) -> f32) -> Vec<f32> {
        let o = self.origin(id);
        let e = self.stored_edge();
        let mut out = Vec::with_capacity(self.stored_len());
        for k in 0..e {
            let z = clamp_cell(o[2], k, self.dims[2]);
            for j in 0..e {
                let y = clamp_cell(o[1], j, self.dims[1]);
                for i in 0..e {
                    out.push(value([clamp_cell(o[0], i, self.dims[0]), y, z]));
                }
            }
        }
        out
    }

    /// The brick ids in z-slab order (x fastest): the streaming order of stencils that go
    /// over the grid slab by slab.
    pub fn slab_order(&self) -> impl Iterator<Item = usize> + '_ {
        0..self.count()
    }

    /// The bricks that hold cells of slabs z ∈ [z0, z1).
    pub fn bricks_of_slabs(&self, z0: usize, z1: usize) -> std::ops::Range<usize> {
        let per_layer = self.bricks[0] * self.bricks[1];
        let k0 = z0 / self.brick;
        let k1 = z1.div_ceil(self.brick).min(self.bricks[2]);
        k0 * per_layer..k1.max(k0) * per_layer
    }

    /// The wavefronts of a sweep along octant `negative` (per axis, whether the directions
    /// go toward lower indices): hyperplane w holds the bricks with I′ + J′ + K′ = w, the
    /// coordinates counted from the octant's upwind corner. Every brick of hyperplane w
    /// depends only on bricks of hyperplane w − 1, so one hyperplane's bricks can be
    /// swept in parallel; the concatenation is the ordinates' streaming order.
    pub fn wavefronts(&self, negative: [bool; 3]) -> Vec<Vec<usize>> {
        let [bx, by, bz] = self.bricks;
        let mut planes = vec![Vec::new(); bx + by + bz - 2];
        for id in 0..self.count() {
            let c = self.coords(id);
            let upwind = |a: usize| {
                if negative[a] {
                    self.bricks[a] - 1 - c[a]
                } else {
                    c[a]
                }
            };
            planes[upwind(0) + upwind(1) + upwind(2)].push(id);
        }
        planes
    }

    /// The bricks that hold cells of the box `lo..=hi` (cell indices, clamped to the grid).
    pub fn bricks_in_box(
        &self,
        lo: [usize; 3],
        hi: [usize; 3],
    ) -> impl Iterator<Item = usize> + '_ {
        let b = self.brick;
        let lo_b: [usize; 3] = [0, 1, 2].map(|a| lo[a].min(self.dims[a] - 1) / b);
        let hi_b: [usize; 3] = [0, 1, 2].map(|a| hi[a].min(self.dims[a] - 1) / b);
        (lo_b[2]..=hi_b[2]).flat_map(move |k| {
            (lo_b[1]..=hi_b[1])
                .flat_map(move |j| (lo_b[0]..=hi_b[0]).map(move |i| self.id([i, j, k])))
        })
    }
}

/// Cell `origin + stored − 1` clamped to [0, n).
#[inline]
fn clamp_cell(origin: usize, stored: usize, n: usize) -> usize {
    (origin + stored)
        .saturating_sub(BrickLayout::APRON)
        .min(n - 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bricks_cover_every_cell_once_on_grids_that_are_not_multiples() {
        for (dims, b) in [
            ([13, 9, 11], 4),
            ([1, 17, 5], 8),
            ([16, 16, 16], 16),
            ([3, 2, 7], 1),
        ] {
            let layout = BrickLayout::new(dims, b).unwrap();
            let mut seen = vec![0u8; dims[0] * dims[1] * dims[2]];
            for id in layout.slab_order() {
                let (o, e) = (layout.origin(id), layout.extent(id));
                for k in 0..e[2] {
                    for j in 0..e[1] {
                        for i in 0..e[0] {
                            let cell = [o[0] + i, o[1] + j, o[2] + k];
                            assert_eq!(layout.locate(cell), (id, [i, j, k]));
                            seen[cell[0] + dims[0] * (cell[1] + dims[1] * cell[2])] += 1;
                        }
                    }
                }
            }
            assert!(seen.iter().all(|&s| s == 1), "{dims:?} / {b}");
        }
    }

    #[test]
    fn stored_bricks_hold_their_neighbours_clamped_at_the_faces() {
        let dims = [10, 7, 5];
        let layout = BrickLayout::new(dims, 4).unwrap();
        let value = |c: [usize; 3]| (c[0] + 100 * c[1] + 10_000 * c[2]) as f32;
        for id in 0..layout.count() {
            let stored = layout.gather(id, value);
            assert_eq!(stored.len(), 6 * 6 * 6);
            let o = layout.origin(id).map(|v| v as isize);
            for k in -1..=4isize {
                for j in -1..=4isize {
                    for i in -1..=4isize {
                        let cell = [o[0] + i, o[1] + j, o[2] + k];
                        let clamped =
                            [0, 1, 2].map(|a| cell[a].clamp(0, dims[a] as isize - 1) as usize);
                        assert_eq!(stored[layout.stored_index([i, j, k])], value(clamped));
                    }
                }
            }
        }
    }

    #[test]
    fn wavefronts_respect_every_octants_dependencies() {
        let layout = BrickLayout::new([20, 9, 13], 4).unwrap();
        for octant in 0..8 {
            let negative = [octant & 1 != 0, octant & 2 != 0, octant & 4 != 0];
            let planes = layout.wavefronts(negative);
            let mut plane_of = vec![usize::MAX; layout.count()];
            for (w, plane) in planes.iter().enumerate() {
                for &id in plane {
                    plane_of[id] = w;
                }
            }
            assert!(plane_of.iter().all(|&w| w != usize::MAX));
            // The upwind neighbour along each axis is exactly one hyperplane earlier.
            for id in 0..layout.count() {
                let c = layout.coords(id);
                for a in 0..3 {
                    let up = if negative[a] {
                        (c[a] + 1 < layout.bricks()[a]).then(|| c[a] + 1)
                    } else {
                        c[a].checked_sub(1)
                    };
                    if let Some(u) = up {
                        let mut n = c;
                        n[a] = u;
                        assert_eq!(plane_of[layout.id(n)] + 1, plane_of[id]);
                    }
                }
            }
        }
    }

    #[test]
    fn bad_layouts_are_refused() {
        assert!(BrickLayout::new([4, 4, 4], 0).is_err());
        assert!(BrickLayout::new([4, 4, 4], 257).is_err());
        assert!(BrickLayout::new([4, 0, 4], 2).is_err());
    }
}
