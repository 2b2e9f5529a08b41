//! Exact line integrals of a grid's trilinear interpolant: the optical depth τ = ∫ σ_t ds
//! that shadows and transmittance need.

use glam::DVec3;

use crate::dense::Grid;
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
}

/// A dense grid's corners.
struct DenseCorners<'a> {
    data: &'a [f32],
    geometry: &'a GridGeometry,
}

impl DualCorners for DenseCorners<'_> {
    type Error = std::convert::Infallible;

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
        loop {
            let axis = if t_next[0] <= t_next[1] && t_next[0] <= t_next[2] {
                0
            } else if t_next[1] <= t_next[2] {
                1
            } else {
                2
            };
            let t_end = t_next[axis].min(t1);
            if t_end > t {
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
