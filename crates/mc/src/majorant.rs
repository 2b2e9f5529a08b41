//! The coarse majorant grid: an upper bound of the extinction per coarse cell, walked by a
//! DDA so that delta tracking takes long steps through thin regions (pbrt-v4's approach:
//! Pharr, Jakob and Humphreys, *Physically Based Rendering*, 4th ed., §11.4 and §14.1).
//!
//! **The medium ends at the box.** A coarse grid of ⌈n/f⌉ cells per axis sticks out of the
//! fine grid's box when n is not a multiple of f, and the trilinear σ_t sampled there is the
//! edge-clamped value of the boundary cells: a phantom layer of up to f − 1 cells. Every walk
//! is therefore clipped to the fine grid's box here, once, so that no caller — the fluence
//! tracer, camera paths, shadow rays — can see medium outside it.

use glam::DVec3;
use lucent_grid::{BrickLayout, Grid, GridGeometry, ray_box};
use rayon::prelude::*;

use crate::transport::McConfig;

/// Per coarse cell, the largest extinction the trilinear medium takes inside it.
///
/// The trilinear interpolant inside a box never exceeds the largest of the cell values it
/// interpolates, so the bound of a coarse cell is the maximum over the fine cells whose
/// centres lie within one fine cell of it (the clamped boundary half-cells included).
#[derive(Debug, Clone, PartialEq)]
pub struct MajorantGrid {
    geometry: GridGeometry,
    values: Vec<f64>,
    /// The fine grid's box: the medium's extent, to which every walk is clipped.
    domain: (DVec3, DVec3),
}

impl MajorantGrid {
    /// Majorants over blocks of `factor`³ fine cells (`factor` ≥ 1; the last block of an
    /// axis may stick out of the domain): the blocks are the bricks of lucent-grid's
    /// [`BrickLayout`], and a block's bound is the maximum over its stored brick — its cells
    /// and their one-cell apron, the cells whose values the interpolant inside the block
    /// blends ([`BrickLayout::gather`], clamped at the faces).
    pub fn new(sigma_t: &Grid, factor: usize) -> Self {
        let fine = *sigma_t.geometry();
        let factor = factor.clamp(1, BrickLayout::MAX_BRICK);
        let layout = match BrickLayout::new(fine.dims(), factor) {
            Ok(layout) => layout,
            // A valid grid always has a layout; fall back to the global bound regardless.
            Err(_) => return Self::global(sigma_t),
        };
        let data = sigma_t.data();
        let value = |c: [usize; 3]| data[fine.index(c[0], c[1], c[2])];
        let maxima: Vec<f32> = (0..layout.count())
            .into_par_iter()
            .map(|id| layout.gather(id, value).into_iter().fold(0.0f32, f32::max))
            .collect();
        Self::from_brick_maxima(fine, &layout, &maxima)
    }

    /// Majorants from per-brick maxima a field already holds — a `BrickedGrid`'s or a paged
    /// field's ranges (`lucent_grid::BrickedGrid::brick_maxima`, the pager's
    /// `PagedGrid::brick_range`), taken over brick and apron — so a bricked or paged medium
    /// needs no pass of its own. `maxima[id]` bounds brick `id` of `layout` on `fine`.
    pub fn from_brick_maxima(fine: GridGeometry, layout: &BrickLayout, maxima: &[f32]) -> Self {
        let geometry = fine.coarsened(layout.brick()).unwrap_or(fine);
        debug_assert_eq!(geometry.dims(), layout.bricks());
        Self {
            geometry,
            values: maxima.iter().map(|&m| f64::from(m.max(0.0))).collect(),
            domain: fine.bounds(),
        }
    }

    /// The majorant `config` asks for: one global bound with `global_majorant`, otherwise
    /// blocks of `majorant_cells`³ fine cells. The fluence tracer and camera paths both
    /// build theirs here.
    pub fn for_config(sigma_t: &Grid, config: &McConfig) -> Self {
        if config.global_majorant {
            Self::global(sigma_t)
        } else {
            Self::new(sigma_t, config.majorant_cells)
        }
    }

    /// One majorant for the whole domain (the largest extinction): the global-majorant
    /// reference that local majorants must agree with.
    pub fn global(sigma_t: &Grid) -> Self {
        let max = sigma_t.stats().max;
        let g = *sigma_t.geometry();
        let (lo, hi) = g.bounds();
        let geometry = GridGeometry::from_bounds([1, 1, 1], lo, hi).unwrap_or(g);
        Self {
            geometry,
            values: vec![f64::from(max.max(0.0))],
            domain: (lo, hi),
        }
    }

    /// The coarse geometry.
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// The majorant of the coarse cell containing world point `p` (0 outside).
    pub fn at(&self, p: DVec3) -> f64 {
        let c = ((p - self.geometry.origin()) / self.geometry.spacing()).floor();
        let [nx, ny, nz] = self.geometry.dims();
        if c.x < 0.0
            || c.y < 0.0
            || c.z < 0.0
            || c.x >= nx as f64
            || c.y >= ny as f64
            || c.z >= nz as f64
        {
            return 0.0;
        }
        self.values[self
            .geometry
            .index(c.x as usize, c.y as usize, c.z as usize)]
    }

    /// Walks the ray `origin + t·dir` (unit `dir`) for t ∈ [0, t_max] ∩ the fine grid's box
    /// through the coarse cells, calling `visit(t_enter, t_exit, majorant)` in order until it
    /// returns `false`. Nothing outside the box is visited.
    pub fn walk(
        &self,
        origin: DVec3,
        dir: DVec3,
        t_max: f64,
        mut visit: impl FnMut(f64, f64, f64) -> bool,
    ) {
        let Some((t_in, t_out)) = ray_box(origin, dir, self.domain.0, self.domain.1) else {
            return;
        };
        let (t_in, t_out) = (t_in.max(0.0), t_out.min(t_max));
        if t_in >= t_out {
            return;
        }
        let values = &self.values;
        // `traverse` measures distances from the start of the segment it is given.
        self.geometry.traverse(
            origin + dir * t_in,
            origin + dir * t_out,
            |index, enter, exit| visit(t_in + enter, t_in + exit, values[index]),
        );
    }

    /// Tentative collisions along `origin + t·dir` for t ∈ [`t_start`, `t_end`]: points of a
    /// Poisson process with the local majorant σ̄ as its rate, in order, each passed to
    /// `visit(t, σ̄, rng)` until it returns `false`. Delta tracking, ratio tracking and the
    /// null-collision estimators are all built on this one walk.
    pub fn tentative_collisions(
        &self,
        origin: DVec3,
        dir: DVec3,
        t_start: f64,
        t_end: f64,
        rng: &mut crate::rng::PathRng,
        mut visit: impl FnMut(f64, f64, &mut crate::rng::PathRng) -> bool,
    ) {
        self.walk(origin, dir, t_end, |t0, t1, sigma_max| {
            if sigma_max <= 0.0 || t1 <= t_start {
                return true;
            }
            let mut t = t0.max(t_start);
            loop {
                t -= (1.0 - rng.uniform()).ln() / sigma_max;
                if t >= t1 {
                    return true;
                }
                if !visit(t, sigma_max, rng) {
                    return false;
                }
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lucent_grid::BrickedGrid;

    /// A sparse, rough medium on a grid that is no multiple of the blocks.
    fn medium() -> Grid {
        let g = GridGeometry::new([21, 14, 17], DVec3::new(0.1, 0.07, 0.12), DVec3::ZERO).unwrap();
        Grid::from_fn(g, |p| {
            let r = (p - DVec3::new(1.0, 0.5, 1.0)).length();
            if r > 0.6 {
                0.0
            } else {
                (5.0 * (13.0 * p.x).sin().abs() + 1.0 / (0.1 + r)) as f32
            }
        })
    }

    #[test]
    fn block_bounds_are_the_maxima_over_each_block_and_its_neighbour_cells() {
        // The definition, by brute force: the maximum over fine cells within one cell of
        // the block (clamped to the grid), floored at zero.
        let sigma = medium();
        let fine = *sigma.geometry();
        let [fx, fy, fz] = fine.dims();
        for factor in [1, 3, 4, 8, 40] {
            let m = MajorantGrid::new(&sigma, factor);
            let [cx, cy, cz] = m.geometry().dims();
            let range = |c: usize, n: usize| {
                c.saturating_mul(factor).saturating_sub(1)..((c + 1) * factor + 1).min(n)
            };
            for k in 0..cz {
                for j in 0..cy {
                    for i in 0..cx {
                        let mut want = 0.0f32;
                        for kk in range(k, fz) {
                            for jj in range(j, fy) {
                                for ii in range(i, fx) {
                                    want = want.max(sigma.data()[fine.index(ii, jj, kk)]);
                                }
                            }
                        }
                        assert_eq!(
                            m.values[m.geometry().index(i, j, k)],
                            f64::from(want),
                            "factor {factor}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn a_bricked_fields_ranges_give_the_same_majorants_without_a_pass() {
        let sigma = medium();
        for factor in [2, 4, 8] {
            let bricked = BrickedGrid::from_dense(&sigma, factor).unwrap();
            let from_field = MajorantGrid::from_brick_maxima(
                *sigma.geometry(),
                bricked.layout(),
                bricked.brick_maxima(),
            );
            assert_eq!(from_field, MajorantGrid::new(&sigma, factor));
        }
    }
}
