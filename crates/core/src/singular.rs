//! The singular part of a point source in a diffusion solve, taken out analytically.
//!
//! A point source of power P in −∇·(D∇φ) + σ_a φ = P δ(x − x₀) makes φ behave like
//! P/(4πD r) next to it, which no grid resolves: a finite-volume or finite-element solution
//! is O(1) wrong in the cells next to the source, and two discretisations disagree there
//! (1.75% relative L2 and 12.8% in the worst cell between `diffusion-mg` and
//! `fem-diffusion` at 64³ for a point in a Robin sphere). Where the medium is homogeneous
//! (D₀, σ_a0) in a ball of radius ρ around x₀, the free-space Green's function
//! G₀ = P e^{−κr}/(4πD₀ r), κ = √(σ_a0/D₀), solves the equation exactly inside it; with a
//! smooth cut-off χ(r) (1 for r ≤ ρ/2, 0 beyond ρ, C²) the field G̃ = χG₀ vanishes at the
//! boundary, and
//!
//! φ = G̃ + u,  −∇·(D∇u) + σ_a u = f,  f = D₀ [2χ′G₀′ + G₀(χ″ + 2χ′/r)],
//!
//! with u under the problem's own boundary conditions. f is smooth and lives in the shell
//! ρ/10 < r < ρ, so u is smooth and every second-order discretisation gets it to O(h²);
//! G̃ is added exactly at the cell centres. ∫ f dV = P − σ_a0 ∫ G̃ dV: the power the
//! remainder carries is what G̃ does not absorb, so the energy balance is kept.
//!
//! ρ is the largest of 24, 23, …, 3 cell widths for which every cell the ball touches is
//! wholly inside the medium (no cut cell, no box face) with D and σ_a equal to the source
//! cell's (to 10⁻⁶); below three cells the cut-off would not be resolved and the caller
//! keeps the plain point source. The derivation is in `docs/point-sources.md`.

use glam::DVec3;
use lucent_grid::GridGeometry;

/// The singular part of one point source on a grid. Finite-volume solvers take the cell
/// values; finite elements evaluate [`SingularPart::source_at`] at their quadrature points.
#[derive(Debug, Clone, PartialEq)]
pub struct SingularPart {
    /// Per cell, the remainder's source f averaged over the cell (power/length³): add it to
    /// the volumetric source in place of the point source.
    pub source: Vec<f32>,
    /// Per cell, G̃ at the cell centre (in the cell holding the source, its cell average):
    /// add it to the remainder's solution.
    pub fluence: Vec<f32>,
    /// The ball's radius ρ (length).
    pub radius: f64,
    position: DVec3,
    d0: f64,
    kappa: f64,
    power: f64,
}

impl SingularPart {
    /// G₀ = P e^{−κr}/(4πD₀ r) and dG₀/dr.
    fn green(&self, r: f64) -> (f64, f64) {
        let scale = self.power / (4.0 * std::f64::consts::PI * self.d0);
        let e = (-self.kappa * r).exp();
        (scale * e / r, -scale * e * (1.0 + self.kappa * r) / (r * r))
    }

    /// The remainder's source f at `x` (power/length³; zero outside the shell).
    pub fn source_at(&self, x: DVec3) -> f64 {
        let r = (x - self.position).length();
        let (_, c1, c2) = cutoff(r, self.radius);
        if c1 == 0.0 && c2 == 0.0 {
            return 0.0;
        }
        let (g, dg) = self.green(r);
        self.d0 * (2.0 * c1 * dg + g * (c2 + 2.0 * c1 / r))
    }

    /// G̃ = χ G₀ at `x` (infinite at the source itself).
    pub fn fluence_at(&self, x: DVec3) -> f64 {
        let r = (x - self.position).length();
        cutoff(r, self.radius).0 * self.green(r).0
    }
}

/// The largest ball radius tried, in cells: the wider the cut-off's shell, the smoother
/// the remainder's source, which no discretisation then blurs.
const MAX_CELLS: usize = 24;

/// Where the cut-off starts, as a fraction of ρ.
const INNER: f64 = 0.1;

/// C² cut-off: χ(r) = 1 − s(t), t = (r − ρ/10)/(0.9ρ) clamped to [0, 1], s the quintic
/// smootherstep; returns (χ, χ′, χ″). The wider the shell, the smoother f: with the shell
/// from ρ/2 instead, `fem-diffusion` met the series 5× worse next to it at 64³.
fn cutoff(r: f64, radius: f64) -> (f64, f64, f64) {
    let inner = INNER * radius;
    let half = radius - inner;
    let t = (r - inner) / half;
    if t <= 0.0 {
        return (1.0, 0.0, 0.0);
    }
    if t >= 1.0 {
        return (0.0, 0.0, 0.0);
    }
    let s = t * t * t * (10.0 + t * (-15.0 + 6.0 * t));
    let ds = 30.0 * t * t * (1.0 - t) * (1.0 - t);
    let dds = 60.0 * t * (1.0 - t) * (1.0 - 2.0 * t);
    (1.0 - s, -ds / half, -dds / (half * half))
}

/// The singular part of a point source of `power` at `position`, for per-cell diffusion
/// coefficient `d` and absorption `sigma_a`; `whole(cell)` says a cell lies wholly inside
/// the medium (no embedded surface crosses it). `None` where the medium is not
/// homogeneous over three cells around the source (the caller keeps the point source).
pub fn point_source_singular_part(
    geometry: &GridGeometry,
    d: &[f32],
    sigma_a: &[f32],
    whole: impl Fn(usize) -> bool,
    position: DVec3,
    power: f64,
) -> Option<SingularPart> {
    let (mut part, cells) =
        point_source_singular_cells(geometry, |c| d[c], |c| sigma_a[c], whole, position, power)?;
    let n = geometry.voxel_count();
    part.source = vec![0.0f32; n];
    part.fluence = vec![0.0f32; n];
    for cell in cells {
        part.source[cell.cell] = cell.source;
        part.fluence[cell.cell] = cell.fluence;
    }
    Some(part)
}

/// One cell of a [`SingularPart`] (what its dense vectors hold at `cell`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SingularCell {
    /// The cell's index in the grid.
    pub cell: usize,
    /// The remainder's source f averaged over the cell (power/length³).
    pub source: f32,
    /// G̃ at the cell centre (the cell average in the source's cell).
    pub fluence: f32,
}

/// How far from a point source [`point_source_singular_cells`] reads coefficients: every
/// cell it asks `d`, `sigma_a` and `whole` about has its centre within this distance of
/// the source, or is the source's cell (for readers that fetch a window of cells first).
pub fn singular_reach(geometry: &GridGeometry) -> f64 {
    let h = geometry.spacing();
    MAX_CELLS as f64 * h.max_element() + 0.5 * h.length()
}

/// [`point_source_singular_part`] with the coefficients read cell by cell (`d(cell)`,
/// `sigma_a(cell)`, for cells within [`singular_reach`] only) and the part's cells listed
/// instead of stored densely: the same values, for solvers whose coefficients are paged.
/// The returned part's `source` and `fluence` are empty; the cells come in index order.
pub fn point_source_singular_cells(
    geometry: &GridGeometry,
    d: impl Fn(usize) -> f32,
    sigma_a: impl Fn(usize) -> f32,
    whole: impl Fn(usize) -> bool,
    position: DVec3,
    power: f64,
) -> Option<(SingularPart, Vec<SingularCell>)> {
    let h = geometry.spacing();
    let v = (position - geometry.origin()) / h;
    let dims = geometry.dims();
    if (0..3).any(|a| !(v[a] >= 0.0 && v[a] < dims[a] as f64)) || !(power.is_finite()) {
        return None;
    }
    let source_cell = geometry.index(v.x as usize, v.y as usize, v.z as usize);
    let (d0, sa0) = (f64::from(d(source_cell)), f64::from(sigma_a(source_cell)));
    if !(d0 > 0.0 && sa0 >= 0.0) {
        return None;
    }
    let (lo, hi) = geometry.bounds();
    let wall = (0..3)
        .map(|a| (position[a] - lo[a]).min(hi[a] - position[a]))
        .fold(f64::INFINITY, f64::min);
    let cell = h.max_element();
    let half_diagonal = 0.5 * h.length();
    let same = |c: usize| {
        whole(c)
            && (f64::from(d(c)) - d0).abs() <= 1e-6 * d0
            && (f64::from(sigma_a(c)) - sa0).abs() <= 1e-6 * sa0.max(1e-30)
    };
    // The cells whose box may meet a ball of `reach` about the source.
    let range = |a: usize, reach: f64| {
        let lo = ((position[a] - reach - geometry.origin()[a]) / h[a])
            .floor()
            .max(0.0) as usize;
        let hi =
            (((position[a] + reach - geometry.origin()[a]) / h[a]).ceil() as usize).min(dims[a]);
        lo..hi
    };
    let radius = (3..=MAX_CELLS)
        .rev()
        .map(|k| k as f64 * cell)
        .find(|&radius| {
            if radius > wall {
                return false;
            }
            // Every cell whose box meets the ball.
            let reach = radius + half_diagonal;
            range(2, reach).all(|k| {
                range(1, reach).all(|j| {
                    range(0, reach).all(|i| {
                        let c = geometry.index(i, j, k);
                        (geometry.cell_centre(i, j, k) - position).length() > reach || same(c)
                    })
                })
            })
        })?;
    let part = SingularPart {
        source: Vec::new(),
        fluence: Vec::new(),
        radius,
        position,
        d0,
        kappa: (sa0 / d0).sqrt(),
        power,
    };
    let mut cells = Vec::new();
    let g = 0.5 / 3f64.sqrt();
    let reach = radius + half_diagonal;
    for k in range(2, reach) {
        for j in range(1, reach) {
            for i in range(0, reach) {
                let index = geometry.index(i, j, k);
                let centre = geometry.cell_centre(i, j, k);
                let r = (centre - position).length();
                if r > reach {
                    continue;
                }
                // f by 2×2×2 Gauss points (smooth in the shell).
                let mut f = 0.0;
                for corner in 0..8 {
                    let offset = DVec3::new(
                        if corner & 1 == 0 { -g } else { g },
                        if corner & 2 == 0 { -g } else { g },
                        if corner & 4 == 0 { -g } else { g },
                    );
                    f += 0.125 * part.source_at(centre + offset * h);
                }
                let fluence = if index == source_cell {
                    // The cell average of G₀ (χ = 1 there): 16³ sub-cell centres, the
                    // singular sub-cell's share floored at its half width (relative error
                    // about 1/256).
                    let m = 16;
                    let mut sum = 0.0;
                    let floor = 0.5 * h.min_element() / m as f64;
                    for sub in 0..m * m * m {
                        let (a, b, c) = (sub % m, (sub / m) % m, sub / (m * m));
                        let x = centre
                            + (DVec3::new(a as f64, b as f64, c as f64) + 0.5 - 0.5 * m as f64)
                                / m as f64
                                * h;
                        sum += part.green((x - position).length().max(floor)).0;
                    }
                    (sum / (m * m * m) as f64) as f32
                } else {
                    part.fluence_at(centre) as f32
                };
                cells.push(SingularCell {
                    cell: index,
                    source: f as f32,
                    fluence,
                });
            }
        }
    }
    Some((part, cells))
}
