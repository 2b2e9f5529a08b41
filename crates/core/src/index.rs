//! A medium's refractive index η(x): procedural (uniform, a linear gradient, Luneburg's
//! lens) or from a grid, as the eikonal ray equation of `direct-refractive` reads it
//! ([`lucent_optics::eikonal`]: η, ∇η and ∇∇η at any point).
//!
//! **A grid's η is a cubic B-spline** with the voxel values as control points, clamped
//! beyond the edges: η, ∇η and ∇∇η are continuous (C²). Trilinear η would be cheaper and
//! interpolating, but its gradient jumps at every plane through cell centres: every ray
//! would kink there, RK4 with step control would crawl across each kink at its smallest
//! step, and the ray tube's Hessian would be a sum of delta functions. The B-spline smooths
//! the grid by its [1, 4, 1]/6 weights per axis (a uniform grid keeps its value; a linear
//! ramp is reproduced exactly away from the edges).
//!
//! η is dimensionless and must be positive and finite; ∇η is per unit of the scene's
//! length.

use glam::{DMat3, DVec3};
use lucent_grid::Grid;
use lucent_optics::eikonal::{GaussianBump, IndexField, LinearIndex, Luneburg};

/// A refractive-index field. In scene files (`[refractive_index]`):
/// `{ kind = "uniform", eta = 1.33 }`,
/// `{ kind = "linear", eta0 = 1.0, gradient = [0.2, 0.0, 0.0], origin = [0.0, 0.0, 0.0] }`,
/// `{ kind = "luneburg", centre = [0.5, 0.5, 0.5], radius = 0.4 }`,
/// `{ kind = "gaussian", eta0 = 1.0, amplitude = 0.05, centre = [0.5, 0.5, 0.5], width = 0.2 }`,
/// or a grid of η
/// (`{ kind = "grid", ... }`, read by the scene from a volume file).
#[derive(Debug, Clone, PartialEq)]
pub enum RefractiveIndex {
    /// η everywhere the same: rays are straight.
    Uniform(f64),
    /// η = η₀ + g·(x − origin).
    Linear(LinearIndex),
    /// Luneburg's lens (η = √(2 − (r/R)²) inside, 1 outside).
    Luneburg(Luneburg),
    /// A smooth bump η₀ + A e^{−|x − c|²/w²} (a graded lens).
    Gaussian(GaussianBump),
    /// η from voxel values, a cubic B-spline ([`IndexGrid`]).
    Grid(IndexGrid),
}

impl RefractiveIndex {
    /// Whether rays through it are straight (η the same everywhere).
    pub fn is_uniform(&self) -> bool {
        match self {
            Self::Uniform(_) => true,
            Self::Linear(l) => l.gradient == DVec3::ZERO,
            Self::Luneburg(_) => false,
            Self::Gaussian(g) => g.amplitude == 0.0,
            Self::Grid(g) => g.uniform,
        }
    }

    /// Checks η > 0 and finite over the box `bounds` (every parameter finite; a linear
    /// gradient positive at the box's corners, where its extremes are; a grid's voxels).
    pub fn check(&self, bounds: (DVec3, DVec3)) -> Result<(), String> {
        let positive = |eta: f64, what: &str| {
            if eta.is_finite() && eta > 0.0 {
                Ok(())
            } else {
                Err(format!(
                    "the refractive index must be positive and finite ({what} is {eta})"
                ))
            }
        };
        match self {
            Self::Uniform(eta) => positive(*eta, "η"),
            Self::Linear(l) => {
                if !(l.gradient.is_finite() && l.origin.is_finite()) {
                    return Err(
                        "a linear refractive index needs a finite gradient and origin".into(),
                    );
                }
                let (lo, hi) = bounds;
                for corner in 0..8 {
                    let p = DVec3::new(
                        if corner & 1 == 0 { lo.x } else { hi.x },
                        if corner & 2 == 0 { lo.y } else { hi.y },
                        if corner & 4 == 0 { lo.z } else { hi.z },
                    );
                    positive(l.eta(p), "η at a corner of the box")?;
                }
                Ok(())
            }
            Self::Luneburg(l) => {
                if l.centre.is_finite() && l.radius.is_finite() && l.radius > 0.0 {
                    Ok(())
                } else {
                    Err("a Luneburg lens needs a finite centre and a positive radius".into())
                }
            }
            Self::Gaussian(g) => {
                if !(g.centre.is_finite() && g.width.is_finite() && g.width > 0.0) {
                    return Err(
                        "a Gaussian index needs a finite centre and a positive width".into(),
                    );
                }
                positive(g.eta0, "η₀")?;
                // Its extremes are η₀ and η₀ + A.
                positive(g.eta0 + g.amplitude, "η₀ + A")
            }
            // The B-spline is a convex combination of the voxels: positive where they are.
            Self::Grid(g) => match g.eta.data().iter().find(|v| !(v.is_finite() && **v > 0.0)) {
                Some(v) => positive(f64::from(*v), "a voxel"),
                None => Ok(()),
            },
        }
    }
}

impl std::fmt::Display for RefractiveIndex {
    /// In words, four significant digits (lengths in the scene's unit).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use crate::problem::Triple;
        use lucent_optics::Significant as S;
        match self {
            Self::Uniform(eta) => write!(f, "uniform, η = {}", S(*eta)),
            Self::Linear(l) => write!(
                f,
                "linear, η = {} at {}, gradient {} per unit length",
                S(l.eta0),
                Triple(l.origin),
                Triple(l.gradient)
            ),
            Self::Luneburg(l) => write!(
                f,
                "Luneburg lens of radius {} at {}",
                S(l.radius),
                Triple(l.centre)
            ),
            Self::Gaussian(g) => write!(
                f,
                "Gaussian bump, η = {} + {} e^(−r²/w²), w = {}, at {}",
                S(g.eta0),
                S(g.amplitude),
                S(g.width),
                Triple(g.centre)
            ),
            Self::Grid(g) => {
                let (lo, hi) = g
                    .eta
                    .data()
                    .iter()
                    .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
                write!(
                    f,
                    "a grid of η from {} to {} (cubic B-spline)",
                    S(f64::from(lo)),
                    S(f64::from(hi))
                )
            }
        }
    }
}

impl IndexField for RefractiveIndex {
    fn eta(&self, x: DVec3) -> f64 {
        match self {
            Self::Uniform(eta) => *eta,
            Self::Linear(l) => l.eta(x),
            Self::Luneburg(l) => l.eta(x),
            Self::Gaussian(g) => g.eta(x),
            Self::Grid(g) => g.eta(x),
        }
    }
    fn gradient(&self, x: DVec3) -> DVec3 {
        match self {
            Self::Uniform(_) => DVec3::ZERO,
            Self::Linear(l) => l.gradient(x),
            Self::Luneburg(l) => l.gradient(x),
            Self::Gaussian(g) => g.gradient(x),
            Self::Grid(g) => g.gradient(x),
        }
    }
    fn kink(&self, x: DVec3) -> Option<(f64, DVec3)> {
        match self {
            Self::Luneburg(l) => l.kink(x),
            _ => None,
        }
    }
    fn hessian(&self, x: DVec3) -> DMat3 {
        match self {
            Self::Uniform(_) => DMat3::ZERO,
            Self::Linear(l) => l.hessian(x),
            Self::Luneburg(l) => l.hessian(x),
            Self::Gaussian(g) => g.hessian(x),
            Self::Grid(g) => g.hessian(x),
        }
    }
}

/// η from a grid of voxel values as a cubic B-spline (see the module's docs).
#[derive(Debug, Clone, PartialEq)]
pub struct IndexGrid {
    eta: Grid,
    uniform: bool,
}

impl IndexGrid {
    /// η with `eta`'s voxel values as the B-spline's control points.
    pub fn new(eta: Grid) -> Self {
        let uniform = eta.data().windows(2).all(|w| w[0] == w[1]);
        Self { eta, uniform }
    }

    /// The control points.
    pub fn grid(&self) -> &Grid {
        &self.eta
    }

    /// Σ c_ijk wᵢ(x) wⱼ(y) w_k(z) with the weights (or their derivatives) `weights`
    /// gives per axis: value, gradient or Hessian by choosing the derivative order per axis.
    fn sum(&self, x: DVec3, orders: [usize; 3]) -> f64 {
        let geometry = self.eta.geometry();
        let dims = geometry.dims();
        let v = geometry.world_to_voxel(x);
        let inv = 1.0 / geometry.spacing();
        let mut base = [0i64; 3];
        let mut w = [[0.0f64; 4]; 3];
        for a in 0..3 {
            let floor = v[a].floor();
            base[a] = floor as i64 - 1;
            w[a] = bspline_weights(v[a] - floor, orders[a]);
            // d/dx = (1/h) d/du per derivative order.
            let scale = inv[a].powi(orders[a] as i32);
            for wi in &mut w[a] {
                *wi *= scale;
            }
        }
        let data = self.eta.data();
        let clamp = |i: i64, n: usize| i.clamp(0, n as i64 - 1) as usize;
        let mut total = 0.0;
        for (k, wk) in w[2].iter().enumerate() {
            let z = clamp(base[2] + k as i64, dims[2]);
            for (j, wj) in w[1].iter().enumerate() {
                let y = clamp(base[1] + j as i64, dims[1]);
                let row = dims[0] * (y + dims[1] * z);
                let mut line = 0.0;
                for (i, wi) in w[0].iter().enumerate() {
                    line += wi * f64::from(data[row + clamp(base[0] + i as i64, dims[0])]);
                }
                total += wk * wj * line;
            }
        }
        total
    }
}

/// The cubic B-spline's four weights at fraction t ∈ [0, 1) (control points floor − 1 to
/// floor + 2), or their first or second derivatives in t.
fn bspline_weights(t: f64, order: usize) -> [f64; 4] {
    let s = 1.0 - t;
    match order {
        0 => [
            s * s * s / 6.0,
            (3.0 * t * t * t - 6.0 * t * t + 4.0) / 6.0,
            (-3.0 * t * t * t + 3.0 * t * t + 3.0 * t + 1.0) / 6.0,
            t * t * t / 6.0,
        ],
        1 => [
            -0.5 * s * s,
            0.5 * (3.0 * t * t - 4.0 * t),
            0.5 * (-3.0 * t * t + 2.0 * t + 1.0),
            0.5 * t * t,
        ],
        _ => [s, 3.0 * t - 2.0, 1.0 - 3.0 * t, t],
    }
}

impl IndexField for IndexGrid {
    fn eta(&self, x: DVec3) -> f64 {
        if self.uniform {
            return f64::from(self.eta.data()[0]);
        }
        self.sum(x, [0, 0, 0])
    }
    fn gradient(&self, x: DVec3) -> DVec3 {
        if self.uniform {
            return DVec3::ZERO;
        }
        DVec3::new(
            self.sum(x, [1, 0, 0]),
            self.sum(x, [0, 1, 0]),
            self.sum(x, [0, 0, 1]),
        )
    }
    fn hessian(&self, x: DVec3) -> DMat3 {
        if self.uniform {
            return DMat3::ZERO;
        }
        let xy = self.sum(x, [1, 1, 0]);
        let xz = self.sum(x, [1, 0, 1]);
        let yz = self.sum(x, [0, 1, 1]);
        DMat3::from_cols(
            DVec3::new(self.sum(x, [2, 0, 0]), xy, xz),
            DVec3::new(xy, self.sum(x, [0, 2, 0]), yz),
            DVec3::new(xz, yz, self.sum(x, [0, 0, 2])),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lucent_grid::GridGeometry;

    /// The B-spline's derivatives are the derivatives of its value (central differences,
    /// h = 1e-5 cells: truncation ~1e-10, rounding ~1e-11 relative; asserted 1e-6), and a
    /// linear ramp of voxels is reproduced exactly inside (the cubic B-spline reproduces
    /// linear functions).
    #[test]
    fn grid_index_derivatives_and_linear_reproduction() {
        let geometry = GridGeometry::new([9, 7, 8], DVec3::splat(0.1), DVec3::ZERO).unwrap();
        let wavy = Grid::from_fn(geometry, |p| {
            (1.3 + 0.1 * (7.0 * p.x).sin() * (5.0 * p.y).cos() + 0.05 * p.z) as f32
        });
        let index = IndexGrid::new(wavy);
        let x = DVec3::new(0.43, 0.37, 0.41);
        let h = 1e-6;
        for a in 0..3 {
            let e = DVec3::AXES[a] * h;
            let fd = (index.eta(x + e) - index.eta(x - e)) / (2.0 * h);
            let g = index.gradient(x)[a];
            assert!((fd - g).abs() < 1e-6 * (1.0 + g.abs()), "∂{a}: {g} vs {fd}");
            let fd2 = (index.gradient(x + e) - index.gradient(x - e)) / (2.0 * h);
            let column = index.hessian(x).col(a);
            assert!(
                (fd2 - column).length() < 1e-5 * (1.0 + column.length()),
                "H col {a}"
            );
        }
        let ramp = IndexGrid::new(Grid::from_fn(geometry, |p| (1.0 + 0.5 * p.x) as f32));
        let inside = DVec3::new(0.41, 0.33, 0.4);
        assert!((ramp.eta(inside) - (1.0 + 0.5 * 0.41)).abs() < 1e-6);
        assert!((ramp.gradient(inside) - DVec3::new(0.5, 0.0, 0.0)).length() < 1e-5);
    }
}
