//! Regime indicators: what a problem's medium and lights say, before any solve, about which
//! transport model is accurate enough where.
//!
//! Diffusion is the leading term of the transport equation's expansion in the ratio of the
//! transport mean free path ℓ′ = 1/σ_t′ to the scales of the solution, with
//! σ_t′ = σ_a + σ_s′ and σ_s′ = (1 − g) σ_s (the similarity relation): it holds where light
//! has scattered many times and is many ℓ′ from boundaries, void and sources, and fails in a
//! boundary layer of a few ℓ′, near sources, in thin or absorbing media (reduced albedo
//! α′ = σ_s′/σ_t′ well below 1) and in void (Mertens 2005, ch. 3; Bernabei ch. 2; the
//! boundary layer is Milne's problem, `docs/milne.md`). Uncollided light decays as e^{−τ}
//! with the extinction optical depth τ along the light's path: where τ is small, single
//! scattering of the uncollided light dominates the scattered light.
//!
//! [`Regime::of`] measures these per region (cubes of [`Regime::block`] cells) of one
//! channel:
//!
//! | indicator | what | units |
//! |---|---|---|
//! | `sigma_t_reduced` | mean σ_t′ of the region's medium cells | 1/length |
//! | `reduced_albedo` | α′ = Σ σ_s′ / Σ σ_t′ over the region | – |
//! | `thickness_mfp` | σ̄_t′ × the region's longest side | ℓ′ |
//! | `boundary_mfp` | mean over the medium cells of the reduced optical distance to the nearest box face or void cell along the six axis directions | ℓ′ |
//! | `light_depth` | extinction optical depth from the nearest light to the region's centre (min over lights) | mean free paths |
//! | `source_mfp` | the same path in ℓ′ | ℓ′ |
//! | `empty_fraction` | share of cells that are void (σ_t h < [`VOID_DEPTH`]; outside the problem's embedded body σ_t is taken as 0) | – |
//!
//! and, over the whole problem, g and the same quantities weighted by region
//! ([`Regime::summary`]). Paths to point and spot lights and from distant lights are the
//! exact line integrals of the trilinear field ([`Grid::line_integral`]); the sky's depth is
//! the smallest over the six axis directions to the box; volume emission counts as a
//! source in the regions that emit (depth 0 there). The cost is a few passes over the grid
//! and a few line integrals per region and light: far below any solve.

use glam::DVec3;
use lucent_grid::Grid;
use lucent_optics::PhaseFunction;

use crate::problem::{Light, Problem};

/// Optical depth of one cell (σ_t times its smallest side) below which it counts as void.
pub const VOID_DEPTH: f64 = 1e-3;

/// The optical depth a line integral stops at: e^{−50} is far below anything a solver
/// resolves.
const DEPTH_CUTOFF: f64 = 50.0;

/// The indicators of one region.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegionIndicators {
    /// Mean reduced extinction σ_t′ = σ_a + (1 − g) σ_s of the region's medium cells
    /// (1/length; 0 if it has none).
    pub sigma_t_reduced: f64,
    /// Reduced albedo α′ = Σ σ_s′ / Σ σ_t′ over the region's medium cells (0 if none).
    pub reduced_albedo: f64,
    /// The region's longest side in transport mean free paths: σ̄_t′ × side.
    pub thickness_mfp: f64,
    /// Mean over the medium cells of the reduced optical distance (∫σ_t′ ds along the six
    /// axis directions, the smallest) to the box or to a void cell, in ℓ′ (0 if none).
    pub boundary_mfp: f64,
    /// Extinction optical depth ∫σ_t ds from the nearest light to the region's centre (the
    /// smallest over lights; infinite without lights, capped at 50).
    pub light_depth: f64,
    /// The same paths in transport mean free paths, ∫σ_t′ ds (capped at 50).
    pub source_mfp: f64,
    /// Share of the region's cells that are void (optically, or outside the problem's
    /// embedded body).
    pub empty_fraction: f64,
}

/// Regime indicators of one channel of a problem, per region and overall.
#[derive(Debug, Clone, PartialEq)]
pub struct Regime {
    /// Cells per region side.
    pub block: usize,
    /// Regions along x, y, z (x fastest in [`Regime::regions`]).
    pub dims: [usize; 3],
    /// The phase function's mean cosine g.
    pub g: f64,
    /// Per region.
    pub regions: Vec<RegionIndicators>,
}

impl Regime {
    /// The indicators of `channel` (clamped to the problem's channels) of `problem` over
    /// regions of `block`³ cells (at least 1; the last region along an axis may be
    /// shorter).
    pub fn of(problem: &Problem, channel: usize, block: usize) -> Self {
        let block = block.max(1);
        let geometry = *problem.geometry();
        let [nx, ny, nz] = geometry.dims();
        let h = geometry.spacing();
        // Outside an embedded body (SDF ≥ 0) there is no medium: light crosses it
        // without interacting, as in the solvers (`Medium::masked`).
        let masked = problem.embedded().map(|sdf| problem.medium().masked(sdf));
        let medium = masked.as_ref().unwrap_or(problem.medium());
        let g = medium.phase.mean_cosine();
        let sigma_t = medium.sigma_t(channel);
        let albedo = medium.albedo(channel);
        let n = nx * ny * nz;
        let void_depth = VOID_DEPTH / h.min_element();
        // Per cell: σ_t′, σ_s′ and whether it is void.
        let mut reduced = vec![0.0f64; n];
        let mut scattering = vec![0.0f64; n];
        let mut void = vec![false; n];
        for (c, &t) in sigma_t.data().iter().enumerate() {
            let t = f64::from(t);
            let s = f64::from(albedo.at(c)) * t;
            reduced[c] = (t - s) + (1.0 - g) * s;
            scattering[c] = (1.0 - g) * s;
            void[c] = t < void_depth;
        }
        let boundary = boundary_distances(&reduced, &void, [nx, ny, nz], h);
        let reduced_grid = Grid::from_vec(geometry, reduced.iter().map(|&v| v as f32).collect())
            .expect("a field on the problem's own grid");
        let lights = problem.lights();
        let (far, nearest) = crate::direct::light_distances(problem);
        let dims = [nx, ny, nz].map(|m| m.div_ceil(block));
        let mut regions = Vec::with_capacity(dims.iter().product());
        for rk in 0..dims[2] {
            for rj in 0..dims[1] {
                for ri in 0..dims[0] {
                    let lo = [ri, rj, rk].map(|r| r * block);
                    let hi = [
                        (lo[0] + block).min(nx),
                        (lo[1] + block).min(ny),
                        (lo[2] + block).min(nz),
                    ];
                    let (mut cells, mut empty) = (0usize, 0usize);
                    let (mut sum_reduced, mut sum_scattering, mut sum_boundary) = (0.0, 0.0, 0.0);
                    let mut emits = false;
                    for k in lo[2]..hi[2] {
                        for j in lo[1]..hi[1] {
                            for i in lo[0]..hi[0] {
                                let c = i + nx * (j + ny * k);
                                emits |= lights.iter().any(|l| match l {
                                    Light::Emission { grid, .. } => grid.data()[c] > 0.0,
                                    _ => false,
                                });
                                if void[c] {
                                    empty += 1;
                                    continue;
                                }
                                cells += 1;
                                sum_reduced += reduced[c];
                                sum_scattering += scattering[c];
                                sum_boundary += boundary[c];
                            }
                        }
                    }
                    let total = cells + empty;
                    let side = (0..3)
                        .map(|a| (hi[a] - lo[a]) as f64 * h[a])
                        .fold(0.0, f64::max);
                    let mean_reduced = if cells > 0 {
                        sum_reduced / cells as f64
                    } else {
                        0.0
                    };
                    let centre = geometry.origin()
                        + DVec3::new(
                            (lo[0] + hi[0]) as f64 * 0.5 * h.x,
                            (lo[1] + hi[1]) as f64 * 0.5 * h.y,
                            (lo[2] + hi[2]) as f64 * 0.5 * h.z,
                        );
                    let (light_depth, source_mfp) = if emits {
                        (0.0, 0.0)
                    } else {
                        light_paths(lights, sigma_t, &reduced_grid, centre, far, nearest)
                    };
                    regions.push(RegionIndicators {
                        sigma_t_reduced: mean_reduced,
                        reduced_albedo: if sum_reduced > 0.0 {
                            sum_scattering / sum_reduced
                        } else {
                            0.0
                        },
                        thickness_mfp: mean_reduced * side,
                        boundary_mfp: if cells > 0 {
                            sum_boundary / cells as f64
                        } else {
                            0.0
                        },
                        light_depth,
                        source_mfp,
                        empty_fraction: empty as f64 / total.max(1) as f64,
                    });
                }
            }
        }
        Self {
            block,
            dims,
            g,
            regions,
        }
    }

    /// The region holding cell (i, j, k); `None` for a cell outside the grid.
    pub fn region_of(&self, [i, j, k]: [usize; 3]) -> Option<&RegionIndicators> {
        let [rx, ry, rz] = self.dims;
        let b = self.block;
        let [ri, rj, rk] = [i / b, j / b, k / b];
        (ri < rx && rj < ry && rk < rz).then(|| &self.regions[ri + rx * (rj + ry * rk)])
    }

    /// The whole problem's indicators: means over the regions that hold medium, weighted
    /// by their σ_t′ (where the light interacts), the smallest light depth and source
    /// distance, the largest thickness, and the void share of all regions.
    pub fn summary(&self) -> RegionIndicators {
        let weight: f64 = self.regions.iter().map(|r| r.sigma_t_reduced).sum();
        let mean = |f: fn(&RegionIndicators) -> f64| {
            if weight > 0.0 {
                self.regions
                    .iter()
                    .map(|r| r.sigma_t_reduced * f(r))
                    .sum::<f64>()
                    / weight
            } else {
                0.0
            }
        };
        let medium: Vec<&RegionIndicators> = self
            .regions
            .iter()
            .filter(|r| r.empty_fraction < 1.0)
            .collect();
        RegionIndicators {
            sigma_t_reduced: if medium.is_empty() {
                0.0
            } else {
                medium.iter().map(|r| r.sigma_t_reduced).sum::<f64>() / medium.len() as f64
            },
            reduced_albedo: mean(|r| r.reduced_albedo),
            thickness_mfp: self
                .regions
                .iter()
                .map(|r| r.thickness_mfp)
                .fold(0.0, f64::max),
            boundary_mfp: mean(|r| r.boundary_mfp),
            light_depth: medium
                .iter()
                .map(|r| r.light_depth)
                .fold(f64::INFINITY, f64::min),
            source_mfp: medium
                .iter()
                .map(|r| r.source_mfp)
                .fold(f64::INFINITY, f64::min),
            empty_fraction: self.regions.iter().map(|r| r.empty_fraction).sum::<f64>()
                / self.regions.len().max(1) as f64,
        }
    }
}

/// Per cell, the smallest reduced optical distance ∫σ_t′ ds along the six axis directions
/// from the cell's centre to the box or to the nearest void cell (0 for void cells).
fn boundary_distances(reduced: &[f64], void: &[bool], dims: [usize; 3], h: DVec3) -> Vec<f64> {
    let [nx, ny, nz] = dims;
    let mut distance = vec![f64::INFINITY; reduced.len()];
    let strides = [1, nx, nx * ny];
    let lengths = [nx, ny, nz];
    for axis in 0..3 {
        let (stride, len, step) = (strides[axis], lengths[axis], h[axis]);
        // Every line along `axis`: its first cell's index, over the other two axes.
        let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
        let starts = (0..lengths[a])
            .flat_map(|u| (0..lengths[b]).map(move |v| u * strides[a] + v * strides[b]));
        for start in starts {
            for forward in [true, false] {
                let mut depth = 0.0;
                for t in 0..len {
                    let c = start + stride * if forward { t } else { len - 1 - t };
                    if void[c] {
                        distance[c] = 0.0;
                        depth = 0.0;
                        continue;
                    }
                    let half = 0.5 * reduced[c] * step;
                    distance[c] = distance[c].min(depth + half);
                    depth += 2.0 * half;
                }
            }
        }
    }
    distance
}

/// The extinction depth and reduced depth from the nearest light to `centre`: the
/// smallest over the lights of the line integrals of σ_t and σ_t′ along the path (for the
/// sky, along the six axis directions to the box); both infinite without lights that
/// arrive along paths.
fn light_paths(
    lights: &[Light],
    sigma_t: &Grid,
    reduced: &Grid,
    centre: DVec3,
    far: f64,
    nearest: f64,
) -> (f64, f64) {
    let mut best = (f64::INFINITY, f64::INFINITY);
    let mut path = |from: DVec3| {
        let depth = sigma_t.line_integral(from, centre, DEPTH_CUTOFF);
        let mfp = reduced.line_integral(from, centre, DEPTH_CUTOFF);
        best = (best.0.min(depth), best.1.min(mfp));
    };
    for light in lights {
        match light {
            Light::Sky { .. } => {
                for axis in [
                    DVec3::X,
                    DVec3::NEG_X,
                    DVec3::Y,
                    DVec3::NEG_Y,
                    DVec3::Z,
                    DVec3::NEG_Z,
                ] {
                    path(centre + axis * far);
                }
            }
            Light::Emission { .. } => {}
            _ => {
                if let Some((_, _, from)) = light.arrival(centre, far, nearest) {
                    path(from);
                }
            }
        }
    }
    (best.0.min(DEPTH_CUTOFF), best.1.min(DEPTH_CUTOFF))
}
