//! Where a grid's cells are in the world.

use std::ops::Range;

use glam::DVec3;

use crate::error::GridError;

/// The largest coordinate a grid's box may reach, in scene units: squared distances across
/// it (ray marching, point-light fall-off) stay far from f64's overflow at 1.8·10³⁰⁸.
pub const MAX_COORDINATE: f64 = 1e150;

/// A point or vector for a message: `(0.5, 0.5, 1e308)`, each number as Rust's `{:?}`
/// writes it (shortest round trip, exponent for large and small values).
pub(crate) fn v3(v: DVec3) -> String {
    format!("({:?}, {:?}, {:?})", v.x, v.y, v.z)
}

/// The geometry of a cell-centred grid: `dims` cells of size `spacing` (anisotropic allowed)
/// starting at the corner `origin`, stored x-fastest.
///
/// Cell (i, j, k) covers `origin + [i, i+1)·h_x × [j, j+1)·h_y × [k, k+1)·h_z`; its value
/// lives at the centre `origin + (i + ½, j + ½, k + ½)·h`. The linear index is
/// `i + n_x (j + n_y k)`, so a z-slab of `n_x n_y` values is contiguous.
///
/// Continuous *voxel coordinates* put cell centres on integers: world point p has voxel
/// coordinate (p − origin)/h − ½.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridGeometry {
    dims: [usize; 3],
    spacing: DVec3,
    origin: DVec3,
    /// 1/spacing, so that sampling multiplies instead of dividing.
    inv_spacing: DVec3,
}

impl GridGeometry {
    /// A geometry with at least one cell per axis, finite positive spacing and a finite
    /// origin, its box within ±[`MAX_COORDINATE`]. The cell count must fit in `usize` and in 2⁴⁰ (a terabyte of f32): anything
    /// larger is a corrupt header, not a volume.
    pub fn new(dims: [usize; 3], spacing: DVec3, origin: DVec3) -> Result<Self, GridError> {
        if dims.contains(&0) {
            return Err(GridError::InvalidGeometry(format!(
                "dims {dims:?} must all be at least 1"
            )));
        }
        if voxel_count(dims).is_none_or(|n| n > MAX_VOXELS) {
            return Err(GridError::InvalidGeometry(format!(
                "dims {dims:?} exceed 2^40 cells"
            )));
        }
        if !spacing.is_finite() || spacing.min_element() <= 0.0 {
            return Err(GridError::InvalidGeometry(format!(
                "spacing {} must be finite and positive",
                v3(spacing)
            )));
        }
        if !origin.is_finite() {
            return Err(GridError::InvalidGeometry(format!(
                "origin {} must be finite",
                v3(origin)
            )));
        }
        // Distances and their squares must stay finite everywhere in the box (a spacing
        // of 1e308 puts its far corner at infinity; one of 1e-320 has no finite inverse).
        let n = DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
        let far = origin + spacing * n;
        let reach = origin.abs().max(far.abs()).max_element();
        if !(reach <= MAX_COORDINATE && spacing.recip().is_finite()) {
            return Err(GridError::InvalidGeometry(format!(
                "the box from {} to {} (spacing {}) reaches beyond ±{MAX_COORDINATE:e}, or its spacing has no finite inverse",
                v3(origin),
                v3(far),
                v3(spacing)
            )));
        }
        Ok(Self {
            dims,
            spacing,
            origin,
            inv_spacing: spacing.recip(),
        })
    }

    /// `dims` cells filling the box [`min`, `max`].
    pub fn from_bounds(dims: [usize; 3], min: DVec3, max: DVec3) -> Result<Self, GridError> {
        let extent = max - min;
        let n = DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
        Self::new(dims, extent / n, min)
    }

    /// Cells per axis.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Cell size per axis (scene units).
    pub fn spacing(&self) -> DVec3 {
        self.spacing
    }

    /// The corner of cell (0, 0, 0).
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// Total number of cells.
    pub fn voxel_count(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// Values in one z-slab, n_x n_y.
    pub fn slab_len(&self) -> usize {
        self.dims[0] * self.dims[1]
    }

    /// Volume of one cell.
    pub fn cell_volume(&self) -> f64 {
        self.spacing.x * self.spacing.y * self.spacing.z
    }

    /// Linear index of cell (i, j, k), x-fastest. The caller keeps indices in range.
    #[inline]
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// (i, j, k) of a linear index.
    #[inline]
    pub fn coords(&self, index: usize) -> [usize; 3] {
        let slab = self.slab_len();
        [
            index % self.dims[0],
            (index % slab) / self.dims[0],
            index / slab,
        ]
    }

    /// World position of the centre of cell (i, j, k).
    #[inline]
    pub fn cell_centre(&self, i: usize, j: usize, k: usize) -> DVec3 {
        self.origin + (DVec3::new(i as f64, j as f64, k as f64) + 0.5) * self.spacing
    }

    /// Continuous voxel coordinate of a world point (cell centres at integers).
    #[inline]
    pub fn world_to_voxel(&self, p: DVec3) -> DVec3 {
        (p - self.origin) * self.inv_spacing - 0.5
    }

    /// World point of a continuous voxel coordinate.
    #[inline]
    pub fn voxel_to_world(&self, v: DVec3) -> DVec3 {
        self.origin + (v + 0.5) * self.spacing
    }

    /// The world-space box covered by the cells: (min corner, max corner).
    pub fn bounds(&self) -> (DVec3, DVec3) {
        (self.origin, self.origin + self.extent())
    }

    /// Size of the box covered by the cells.
    pub fn extent(&self) -> DVec3 {
        DVec3::new(
            self.dims[0] as f64,
            self.dims[1] as f64,
            self.dims[2] as f64,
        ) * self.spacing
    }

    /// The geometry one level coarser: cells `factor` times larger, ⌈n/factor⌉ of them,
    /// same origin (the last coarse cell sticks out when n is not a multiple of `factor`).
    pub fn coarsened(&self, factor: usize) -> Result<Self, GridError> {
        if factor == 0 {
            return Err(GridError::InvalidParameter {
                name: "factor",
                reason: "must be at least 1".into(),
            });
        }
        Self::new(
            self.dims.map(|n| n.div_ceil(factor)),
            self.spacing * factor as f64,
            self.origin,
        )
    }
}

/// The most cells a grid may have: 2⁴⁰.
pub const MAX_VOXELS: usize = 1 << 40;

/// n_x n_y n_z, or `None` on overflow.
pub(crate) fn voxel_count(dims: [usize; 3]) -> Option<usize> {
    dims[0].checked_mul(dims[1])?.checked_mul(dims[2])
}

impl GridGeometry {
    /// Walks the cells that the segment from `a` to `b` crosses, in order, calling
    /// `visit(index, enter, exit)` with each cell's linear index and the distances from `a`
    /// at which the segment enters and leaves it (Amanatides–Woo 3D DDA), until `visit`
    /// returns `false`. Parts of the segment outside the grid's box are skipped.
    /// Track-length estimators, majorant walks and exact line integrals use it.
    pub fn traverse(&self, a: DVec3, b: DVec3, mut visit: impl FnMut(usize, f64, f64) -> bool) {
        let d = b - a;
        let length = d.length();
        if !(length > 0.0 && length.is_finite()) {
            return;
        }
        // In cell coordinates: c = (p − origin)/h, cell i spans [i, i + 1).
        let ca = (a - self.origin) * self.inv_spacing;
        let dc = d * self.inv_spacing;
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for axis in 0..3 {
            let n = self.dims[axis] as f64;
            if dc[axis] == 0.0 {
                if ca[axis] < 0.0 || ca[axis] >= n {
                    return;
                }
            } else {
                let (ta, tb) = (-ca[axis] / dc[axis], (n - ca[axis]) / dc[axis]);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
        }
        if t0 >= t1 {
            return;
        }
        let start = ca + dc * t0;
        let mut cell = [0i64; 3];
        let mut t_next = [f64::INFINITY; 3];
        let mut t_step = [f64::INFINITY; 3];
        let mut step = [0i64; 3];
        for axis in 0..3 {
            let n = self.dims[axis] as i64;
            cell[axis] = (start[axis].floor() as i64).clamp(0, n - 1);
            if dc[axis] > 0.0 {
                step[axis] = 1;
                t_step[axis] = 1.0 / dc[axis];
                t_next[axis] = t0 + ((cell[axis] + 1) as f64 - start[axis]) / dc[axis];
            } else if dc[axis] < 0.0 {
                step[axis] = -1;
                t_step[axis] = -1.0 / dc[axis];
                t_next[axis] = t0 + (cell[axis] as f64 - start[axis]) / dc[axis];
            }
        }
        let mut t = t0;
        loop {
            let axis = if t_next[0] <= t_next[1] && t_next[0] <= t_next[2] {
                0
            } else if t_next[1] <= t_next[2] {
                1
            } else {
                2
            };
            let t_end = t_next[axis].min(t1);
            if t_end > t
                && !visit(
                    self.index(cell[0] as usize, cell[1] as usize, cell[2] as usize),
                    t * length,
                    t_end * length,
                )
            {
                return;
            }
            if t_end >= t1 {
                return;
            }
            t = t_end;
            cell[axis] += step[axis];
            t_next[axis] += t_step[axis];
            if cell[axis] < 0 || cell[axis] >= self.dims[axis] as i64 {
                return;
            }
        }
    }
}

/// The cells (i, j, k) of a box of cells, `cells[a]` along axis a, in storage order: x
/// fastest, then y, then z. The one loop over a box that decompositions share (a rank's
/// box, a face it sends, the rows it builds).
///
/// ```
/// let cells: Vec<[usize; 3]> = lucent_grid::box_cells(&[1..3, 0..2, 5..6]).collect();
/// assert_eq!(cells, [[1, 0, 5], [2, 0, 5], [1, 1, 5], [2, 1, 5]]);
/// assert_eq!(lucent_grid::box_cells(&[0..4, 3..3, 0..9]).count(), 0);
/// ```
pub fn box_cells(cells: &[Range<usize>; 3]) -> impl Iterator<Item = [usize; 3]> + Clone + use<> {
    let [x, y, z] = cells.clone();
    z.flat_map(move |k| {
        let x = x.clone();
        y.clone()
            .flat_map(move |j| x.clone().map(move |i| [i, j, k]))
    })
}

/// The parametric interval [t0, t1] (t ≥ 0) in which the ray `origin + t·dir` lies inside
/// the box [`lo`, `hi`], if it meets it (slab method; axis-parallel rays outside a slab
/// miss). The one ray–box clip that renderers and tracers share.
pub fn ray_box(origin: DVec3, dir: DVec3, lo: DVec3, hi: DVec3) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for a in 0..3 {
        if dir[a] == 0.0 {
            if origin[a] < lo[a] || origin[a] > hi[a] {
                return None;
            }
        } else {
            let (ta, tb) = ((lo[a] - origin[a]) / dir[a], (hi[a] - origin[a]) / dir[a]);
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
    }
    (t0 < t1).then_some((t0, t1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_box_that_reaches_infinity_or_has_no_finite_inverse_spacing_is_refused() {
        let one = DVec3::ONE;
        for (spacing, origin) in [
            (DVec3::new(1.0, 1.0, 1e308), DVec3::ZERO),
            (one * 1e150, DVec3::ZERO),
            (one, DVec3::splat(-2e150)),
            (DVec3::new(1.0, 1e-320, 1.0), DVec3::ZERO),
        ] {
            let refused = GridGeometry::new([4, 4, 4], spacing, origin);
            assert!(
                matches!(refused, Err(GridError::InvalidGeometry(ref m)) if !m.contains("0000000000")),
                "{spacing:?} {origin:?}: {refused:?}"
            );
        }
        // Large but finite boxes stay valid.
        assert!(GridGeometry::new([4, 4, 4], one * 1e140, DVec3::splat(-1e145)).is_ok());
    }
}
