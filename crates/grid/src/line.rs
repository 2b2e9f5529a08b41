//! Exact line integrals of a grid's trilinear interpolant: the optical depth τ = ∫ σ_t ds
//! that shadows and transmittance need.

use glam::DVec3;

use rayon::prelude::*;

use crate::bricks::BrickLayout;
use crate::dense::Grid;
use crate::error::GridError;
use crate::geometry::GridGeometry;

/// Where [`line_integral_with`] reads the field: the eight values at the corners of a dual
/// cell, cells `lo` to `hi` (each index of `hi` is that of `lo` or one more, both clamped
/// to the grid), in the order `c[dx + 2 dy + 4 dz]`. A dense grid reads its array; a
/// bricked or paged field reads the stored brick of `lo`, whose one-cell apron holds all
/// eight.
pub trait DualCorners {
    /// Why a read can fail (`Infallible` for memory).
    type Error;
    /// The eight corner values.
    fn corners(&mut self, lo: [usize; 3], hi: [usize; 3]) -> Result<[f64; 8], Self::Error>;

    /// A box of cells `[first, last]` (inclusive) holding `cell` — the cell's brick, for
    /// bricked storage — and whether it is empty: every dual cell whose lower corner lies
    /// in the box has eight zero corners (a brick whose stored values, apron included,
    /// are all zero). `None` where the reader knows no such box. The walk crosses empty
    /// boxes without reads or arithmetic (their pieces add exactly nothing, so the
    /// integral keeps its bits) and asks again only when it leaves the box.
    #[inline]
    fn region(&mut self, cell: [usize; 3]) -> Option<([[usize; 3]; 2], bool)> {
        let _ = cell;
        None
    }
}

/// Which bricks of a dense grid are empty for a line walk: brick `id` of the layout is
/// empty when the grid is zero on its cells and on the cells one above them on each axis
/// (clamped), so every dual cell whose lower corner lies in the brick has zero corners.
/// Built in one pass over the grid; [`Grid::line_integral_skipping`] uses it to cross empty
/// space at the cost of the walk's steps alone.
#[derive(Debug, Clone)]
pub struct EmptyBricks {
    layout: BrickLayout,
    empty: Vec<bool>,
}

impl EmptyBricks {
    /// The empty bricks of `grid` cut into `brick`³ bricks (8 or 16 suit most grids).
    pub fn of(grid: &Grid, brick: usize) -> Result<Self, GridError> {
        let geometry = grid.geometry();
        let layout = BrickLayout::new(geometry.dims(), brick)?;
        let dims = geometry.dims();
        let data = grid.data();
        let empty = (0..layout.count())
            .into_par_iter()
            .map(|id| {
                let o = layout.origin(id);
                let e = layout.extent(id);
                // The brick's cells and the upper apron, clamped.
                let end = [0, 1, 2].map(|a| (o[a] + e[a] + 1).min(dims[a]));
                (o[2]..end[2]).all(|k| {
                    (o[1]..end[1]).all(|j| {
                        let row = geometry.index(0, j, k);
                        data[row + o[0]..row + end[0]].iter().all(|&v| v == 0.0)
                    })
                })
            })
            .collect();
        Ok(Self { layout, empty })
    }

    /// The layout the bricks follow.
    pub fn layout(&self) -> &BrickLayout {
        &self.layout
    }

    /// Empty bricks over all bricks.
    pub fn empty_fraction(&self) -> f64 {
        self.empty.iter().filter(|&&e| e).count() as f64 / self.empty.len().max(1) as f64
    }

    /// The cells of the brick holding `cell`, and whether it is empty.
    #[inline]
    pub fn region(&self, cell: [usize; 3]) -> ([[usize; 3]; 2], bool) {
        let (id, _) = self.layout.locate(cell);
        (self.layout.cell_box(id), self.empty[id])
    }
}

/// A dense grid's corners, with its empty bricks where known.
struct DenseCorners<'a> {
    data: &'a [f32],
    geometry: &'a GridGeometry,
    empty: Option<&'a EmptyBricks>,
}

impl DualCorners for DenseCorners<'_> {
    type Error = std::convert::Infallible;

    #[inline]
    fn region(&mut self, cell: [usize; 3]) -> Option<([[usize; 3]; 2], bool)> {
        self.empty.map(|e| e.region(cell))
    }

    #[inline]
    fn corners(&mut self, lo: [usize; 3], hi: [usize; 3]) -> Result<[f64; 8], Self::Error> {
        let at = |i, j, k| f64::from(self.data[self.geometry.index(i, j, k)]);
        Ok([
            at(lo[0], lo[1], lo[2]),
            at(hi[0], lo[1], lo[2]),
            at(lo[0], hi[1], lo[2]),
            at(hi[0], hi[1], lo[2]),
            at(lo[0], lo[1], hi[2]),
            at(hi[0], lo[1], hi[2]),
            at(lo[0], hi[1], hi[2]),
            at(hi[0], hi[1], hi[2]),
        ])
    }
}

/// Gauss–Legendre abscissa ±1/√3 on [−1, 1] (the 2-point rule is exact for cubics).
const GAUSS: f64 = 0.577_350_269_189_625_8;

impl Grid {
    /// ∫ f ds along the segment from `a` to `b` (world units), where f is the grid's
    /// trilinear interpolant with clamping ([`Grid::sample_trilinear`]) inside the grid's box
    /// and zero outside it.
    ///
    /// Exact up to round-off: the segment is cut where it crosses the planes through cell
    /// centres (a 3D DDA over the *dual* cells), inside each piece the interpolant restricted
    /// to the line is a cubic in the arc length, and the 2-point Gauss rule integrates it
    /// exactly. The walk stops early once the integral exceeds `cutoff` (pass
    /// `f64::INFINITY` for none); for transmittance e^{−τ}, τ = 50 is already below f32's
    /// smallest normal number.
    pub fn line_integral(&self, a: DVec3, b: DVec3, cutoff: f64) -> f64 {
        let mut corners = DenseCorners {
            data: self.data(),
            geometry: self.geometry(),
            empty: None,
        };
        match line_integral_with(self.geometry(), a, b, cutoff, &mut corners) {
            Ok(total) => total,
            Err(never) => match never {},
        }
    }

    /// [`Grid::line_integral`], crossing the bricks that `empty` (built from this grid)
    /// marks empty without reading them: the same bits, faster through empty space.
    ///
    /// # Panics
    /// If `empty` was built for a grid of other dimensions.
    pub fn line_integral_skipping(
        &self,
        empty: &EmptyBricks,
        a: DVec3,
        b: DVec3,
        cutoff: f64,
    ) -> f64 {
        assert_eq!(
            empty.layout.dims(),
            self.geometry().dims(),
            "EmptyBricks of another grid"
        );
        let mut corners = DenseCorners {
            data: self.data(),
            geometry: self.geometry(),
            empty: Some(empty),
        };
        match line_integral_with(self.geometry(), a, b, cutoff, &mut corners) {
            Ok(total) => total,
            Err(never) => match never {},
        }
    }
}

/// [`Grid::line_integral`] of the field on `g` whose values `corners` reads: the same walk
/// and the same arithmetic whatever the storage, so a dense and a paged field give the same
/// bits.
pub fn line_integral_with<C: DualCorners>(
    g: &GridGeometry,
    a: DVec3,
    b: DVec3,
    cutoff: f64,
    corners: &mut C,
) -> Result<f64, C::Error> {
    {
        let dims = g.dims();
        // Work in voxel coordinates, where cell centres are integers: v = (p − o)/h − ½.
        let va = g.world_to_voxel(a);
        let vb = g.world_to_voxel(b);
        let dv = vb - va;
        let length = (b - a).length();
        if length == 0.0 || !length.is_finite() {
            return Ok(0.0);
        }
        // Clip t ∈ [0, 1] to the box −½ ≤ v ≤ n − ½.
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for axis in 0..3 {
            let (lo, hi) = (-0.5, dims[axis] as f64 - 0.5);
            if dv[axis] == 0.0 {
                if va[axis] < lo || va[axis] > hi {
                    return Ok(0.0);
                }
            } else {
                let (ta, tb) = ((lo - va[axis]) / dv[axis], (hi - va[axis]) / dv[axis]);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
        }
        if t0 >= t1 {
            return Ok(0.0);
        }
        // DDA over dual cells: index c ∈ [−1, n − 1] spans v ∈ [c, c + 1].
        let start = va + dv * t0;
        let mut cell = [0i64; 3];
        let mut t_next = [f64::INFINITY; 3];
        let mut t_step = [f64::INFINITY; 3];
        let mut step = [0i64; 3];
        for axis in 0..3 {
            let n = dims[axis] as i64;
            cell[axis] = (start[axis].floor() as i64).clamp(-1, n - 1);
            if dv[axis] > 0.0 {
                step[axis] = 1;
                t_step[axis] = 1.0 / dv[axis];
                t_next[axis] = t0 + ((cell[axis] + 1) as f64 - start[axis]) / dv[axis];
            } else if dv[axis] < 0.0 {
                step[axis] = -1;
                t_step[axis] = -1.0 / dv[axis];
                t_next[axis] = t0 + (cell[axis] as f64 - start[axis]) / dv[axis];
            }
        }
        let clamp = |c: i64, n: usize| c.clamp(0, n as i64 - 1) as usize;
        let mut t = t0;
        let mut total = 0.0;
        // The region of the brick the walk is in, and whether it is empty (its dual cells
        // add nothing): empty regions are crossed by advancing the DDA's crossing times
        // alone, axis by axis, with the additions the cell-by-cell walk would make (the
        // same bits), and without reading the field.
        let mut region: Option<([[usize; 3]; 2], bool)> = None;
        let holds = |b: &[[usize; 3]; 2], c: [usize; 3]| {
            (b[0][0]..=b[1][0]).contains(&c[0])
                && (b[0][1]..=b[1][1]).contains(&c[1])
                && (b[0][2]..=b[1][2]).contains(&c[2])
        };
        loop {
            let lo = [0, 1, 2].map(|a| clamp(cell[a], dims[a]));
            if !region.as_ref().is_some_and(|(b, _)| holds(b, lo)) {
                region = corners.region(lo).filter(|(b, _)| holds(b, lo));
            }
            let empty = matches!(region, Some((_, true)));
            if let Some((b, true)) = region {
                match skip_empty(&b, dims, &mut cell, &mut t_next, &t_step, &step, t1) {
                    Skip::Leaves => {}
                    Skip::Ends => return Ok(total),
                }
            }
            let axis = if t_next[0] <= t_next[1] && t_next[0] <= t_next[2] {
                0
            } else if t_next[1] <= t_next[2] {
                1
            } else {
                2
            };
            let t_end = t_next[axis].min(t1);
            if t_end > t && !empty {
                // The eight cell values at the corners of this dual cell.
                let lo = [0, 1, 2].map(|a| clamp(cell[a], dims[a]));
                let hi = [0, 1, 2].map(|a| clamp(cell[a] + 1, dims[a]));
                let c = corners.corners(lo, hi)?;
                let origin = DVec3::new(cell[0] as f64, cell[1] as f64, cell[2] as f64);
                let value = |tt: f64| {
                    let u = (va + dv * tt - origin).clamp(DVec3::ZERO, DVec3::ONE);
                    let x0 = c[0] + (c[1] - c[0]) * u.x;
                    let x1 = c[2] + (c[3] - c[2]) * u.x;
                    let x2 = c[4] + (c[5] - c[4]) * u.x;
                    let x3 = c[6] + (c[7] - c[6]) * u.x;
                    let y0 = x0 + (x1 - x0) * u.y;
                    let y1 = x2 + (x3 - x2) * u.y;
                    y0 + (y1 - y0) * u.z
                };
                let (mid, half) = (0.5 * (t + t_end), 0.5 * (t_end - t));
                total += half * length * (value(mid - GAUSS * half) + value(mid + GAUSS * half));
                if total > cutoff {
                    return Ok(total);
                }
            }
            if t_end >= t1 {
                return Ok(total);
            }
            t = t_end;
            cell[axis] += step[axis];
            t_next[axis] += t_step[axis];
            if cell[axis] < -1 || cell[axis] > dims[axis] as i64 - 1 {
                return Ok(total);
            }
        }
    }
}

/// How a crossing of an empty region ends.
enum Skip {
    /// The walk's next crossing leaves the region (the DDA stands just before it).
    Leaves,
    /// The segment ends inside the region (nothing more to add).
    Ends,
}

/// Advances the DDA through the empty region `b` (cells whose clamped lower corner is in
/// `b`) up to the crossing that leaves it: the crossings are the walk's own (each axis's
/// crossing times are the same running sums), taken in the walk's order (by time, ties to
/// the lower axis), so the walk goes on from the state it would have reached cell by cell.
#[inline]
fn skip_empty(
    b: &[[usize; 3]; 2],
    dims: [usize; 3],
    cell: &mut [i64; 3],
    t_next: &mut [f64; 3],
    t_step: &[f64; 3],
    step: &[i64; 3],
    t1: f64,
) -> Skip {
    // Crossings per axis that stay in the region, and the time of the one that leaves.
    let mut inside = [0i64; 3];
    let mut leave = [f64::INFINITY; 3];
    for a in 0..3 {
        // Dual cells −1 and n − 1 clamp to cells 0 and n − 1.
        let first = if b[0][a] == 0 { -1 } else { b[0][a] as i64 };
        let last = b[1][a] as i64;
        debug_assert!(
            first <= cell[a] && cell[a] <= last,
            "{cell:?} outside {b:?} of {dims:?}"
        );
        inside[a] = match step[a] {
            1 => last - cell[a],
            -1 => cell[a] - first,
            _ => continue,
        };
        let mut t = t_next[a];
        for _ in 0..inside[a] {
            t += t_step[a];
        }
        leave[a] = t;
    }
    let exit = if leave[0] <= leave[1] && leave[0] <= leave[2] {
        0
    } else if leave[1] <= leave[2] {
        1
    } else {
        2
    };
    let t_exit = leave[exit];
    if t_exit.min(t1) >= t1 {
        return Skip::Ends;
    }
    // Every crossing ordered before the leaving one.
    for a in 0..3 {
        let mut taken = 0;
        while taken < inside[a] && (t_next[a] < t_exit || (t_next[a] == t_exit && a < exit)) {
            t_next[a] += t_step[a];
            cell[a] += step[a];
            taken += 1;
        }
    }
    Skip::Leaves
}
