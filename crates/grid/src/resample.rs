//! Moving values between resolutions: 2× restriction and prolongation (the transfer
//! operators of geometric multigrid) and resampling to any target resolution.

use glam::DVec3;
use rayon::prelude::*;

use crate::dense::Grid;
use crate::error::GridError;
use crate::geometry::GridGeometry;

/// The 2× coarser grid whose cells hold the volume-weighted average of the fine cells they
/// cover (cells of equal volume, so the plain mean of the 1–8 children that exist; the last
/// coarse cell of an odd axis covers one fine layer and sticks out of the domain).
///
/// Conserves the integral Σ vᵢ Vᵢ exactly when every axis is even.
pub fn restrict(fine: &Grid) -> Grid {
    let fine_geometry = *fine.geometry();
    let [fx, fy, fz] = fine_geometry.dims();
    let coarse_geometry = fine_geometry.coarsened(2).unwrap_or(fine_geometry);
    let [cx, cy, _] = coarse_geometry.dims();
    let data = fine.data();
    let mut coarse = Grid::filled(coarse_geometry, 0.0);
    coarse.slabs_mut().for_each(|(k, slab)| {
        for j in 0..cy {
            for i in 0..cx {
                let mut sum = 0.0f64;
                let mut count = 0u32;
                for kk in 2 * k..(2 * k + 2).min(fz) {
                    for jj in 2 * j..(2 * j + 2).min(fy) {
                        for ii in 2 * i..(2 * i + 2).min(fx) {
                            sum += f64::from(data[fine_geometry.index(ii, jj, kk)]);
                            count += 1;
                        }
                    }
                }
                slab[i + cx * j] = (sum / f64::from(count)) as f32;
            }
        }
    });
    coarse
}

/// Checks that `fine` is the geometry that [`restrict`] coarsens to `coarse`.
fn check_refinement(coarse: &GridGeometry, fine: &GridGeometry) -> Result<(), GridError> {
    let expected = fine.coarsened(2)?;
    let same = expected.dims() == coarse.dims()
        && (expected.spacing() - coarse.spacing()).abs().max_element()
            <= 1e-12 * coarse.spacing().max_element()
        && (expected.origin() - coarse.origin()).abs().max_element()
            <= 1e-12 * coarse.extent().max_element();
    if same {
        Ok(())
    } else {
        Err(GridError::Mismatch(format!(
            "fine geometry {:?} does not coarsen to the coarse grid {:?}",
            fine.dims(),
            coarse.dims()
        )))
    }
}

/// Piecewise-constant prolongation: every fine cell takes its parent's value.
/// `restrict(prolong_constant(c)) == c` for any field.
pub fn prolong_constant(coarse: &Grid, fine_geometry: GridGeometry) -> Result<Grid, GridError> {
    check_refinement(coarse.geometry(), &fine_geometry)?;
    let [fx, fy, _] = fine_geometry.dims();
    let mut fine = Grid::filled(fine_geometry, 0.0);
    fine.slabs_mut().for_each(|(k, slab)| {
        for j in 0..fy {
            for i in 0..fx {
                slab[i + fx * j] = coarse.data()[coarse.geometry().index(i / 2, j / 2, k / 2)];
            }
        }
    });
    Ok(fine)
}

/// Trilinear prolongation: fine cell centres sit a quarter of a coarse cell from the coarse
/// centres, so each fine value is the tensor product of the 1D weights (¾, ¼) toward its
/// nearest coarse neighbours. At the domain boundary the missing neighbour is extrapolated
/// linearly (2u₀ − u₁), so every field linear in x, y, z is reproduced exactly, and
/// `restrict(prolong_trilinear(c)) == c` for such fields (given at least two coarse cells
/// per axis: along an axis of one coarse cell the prolonged field is constant).
pub fn prolong_trilinear(coarse: &Grid, fine_geometry: GridGeometry) -> Result<Grid, GridError> {
    check_refinement(coarse.geometry(), &fine_geometry)?;
    let cg = *coarse.geometry();
    let [cx, cy, cz] = cg.dims();
    let [fx, fy, _] = fine_geometry.dims();
    let c = coarse.data();
    // Per fine index along one axis: the two coarse indices and weights; an index of
    // `usize::MAX` marks the extrapolated ghost (handled by `value`).
    let taps = |n_fine: usize, n_coarse: usize| -> Vec<[(isize, f64); 2]> {
        (0..n_fine)
            .map(|f| {
                let parent = (f / 2) as isize;
                let neighbour = if f % 2 == 0 { parent - 1 } else { parent + 1 };
                if n_coarse == 1 {
                    [(parent, 1.0), (parent, 0.0)]
                } else {
                    [(parent, 0.75), (neighbour, 0.25)]
                }
            })
            .collect()
    };
    let (tx, ty, tz) = (
        taps(fx, cx),
        taps(fy, cy),
        taps(fine_geometry.dims()[2], cz),
    );
    // Value at a coarse index along each axis, extrapolating linearly one cell beyond.
    let value = |i: isize, j: isize, k: isize| -> f64 {
        let axis = |v: isize, n: usize| -> [(usize, f64); 2] {
            if v < 0 {
                [(0, 2.0), (1.min(n - 1), -1.0)]
            } else if v as usize >= n {
                [(n - 1, 2.0), (n.saturating_sub(2), -1.0)]
            } else {
                [(v as usize, 1.0), (v as usize, 0.0)]
            }
        };
        let mut sum = 0.0;
        for (ii, wi) in axis(i, cx) {
            for (jj, wj) in axis(j, cy) {
                for (kk, wk) in axis(k, cz) {
                    let w = wi * wj * wk;
                    if w != 0.0 {
                        sum += w * f64::from(c[cg.index(ii, jj, kk)]);
                    }
                }
            }
        }
        sum
    };
    let mut fine = Grid::filled(fine_geometry, 0.0);
    fine.slabs_mut().for_each(|(k, slab)| {
        for j in 0..fy {
            for i in 0..fx {
                let mut sum = 0.0;
                for &(ci, wi) in &tx[i] {
                    for &(cj, wj) in &ty[j] {
                        for &(ck, wk) in &tz[k] {
                            let w = wi * wj * wk;
                            if w != 0.0 {
                                sum += w * value(ci, cj, ck);
                            }
                        }
                    }
                }
                slab[i + fx * j] = sum as f32;
            }
        }
    });
    Ok(fine)
}

/// The grid resampled to `dims` cells over the same world box.
///
/// Each target cell averages trilinear samples of the source at an s_x × s_y × s_z lattice
/// of points inside it, s = ⌈source cells per target cell⌉ per axis: a box filter when
/// downsampling (no aliasing of thin features), plain trilinear interpolation when
/// upsampling.
pub fn resample(grid: &Grid, dims: [usize; 3]) -> Result<Grid, GridError> {
    let (min, max) = grid.geometry().bounds();
    let target = GridGeometry::from_bounds(dims, min, max)?;
    let src = grid.dims();
    let s: [usize; 3] = std::array::from_fn(|a| src[a].div_ceil(dims[a]).max(1));
    let h = target.spacing();
    let inv = 1.0 / (s[0] * s[1] * s[2]) as f64;
    let mut out = Grid::filled(target, 0.0);
    out.slabs_mut().for_each(|(k, slab)| {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let corner = target.origin() + DVec3::new(i as f64, j as f64, k as f64) * h;
                let mut sum = 0.0f64;
                for c in 0..s[2] {
                    for b in 0..s[1] {
                        for a in 0..s[0] {
                            let offset = DVec3::new(
                                (a as f64 + 0.5) / s[0] as f64,
                                (b as f64 + 0.5) / s[1] as f64,
                                (c as f64 + 0.5) / s[2] as f64,
                            );
                            sum += f64::from(grid.sample_trilinear(corner + offset * h));
                        }
                    }
                }
                slab[i + dims[0] * j] = (sum * inv) as f32;
            }
        }
    });
    Ok(out)
}
