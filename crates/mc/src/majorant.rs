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
use lucent_grid::{Grid, GridGeometry, ray_box};

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
    /// axis may stick out of the domain).
    pub fn new(sigma_t: &Grid, factor: usize) -> Self {
        let fine = *sigma_t.geometry();
        let factor = factor.max(1);
        let geometry = fine.coarsened(factor).unwrap_or(fine);
        let [fx, fy, fz] = fine.dims();
        let [cx, cy, cz] = geometry.dims();
        let range = |c: usize, n: usize| {
            c.saturating_mul(factor).saturating_sub(1)..((c + 1) * factor + 1).min(n)
        };
        let mut values = vec![0.0; cx * cy * cz];
        for k in 0..cz {
            for j in 0..cy {
                for i in 0..cx {
                    let mut max = 0.0f32;
                    for kk in range(k, fz) {
                        for jj in range(j, fy) {
                            for ii in range(i, fx) {
                                max = max.max(sigma_t.data()[fine.index(ii, jj, kk)]);
                            }
                        }
                    }
                    values[geometry.index(i, j, k)] = f64::from(max);
                }
            }
        }
        Self {
            geometry,
            values,
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
