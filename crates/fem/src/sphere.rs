//! Q1 diffusion on boundary-fitted meshes of star-shaped bodies (a ball, or any embedded
//! object whose surface every ray from its centre crosses once).
//!
//! The cube lattice [−1, 1]³ of n elements per axis is mapped radially,
//! u ↦ c + R(û) ‖u‖_∞ û with û = u/‖u‖₂, so the cube's faces land on the surface
//! r = R(û): for a ball R is the radius, for an embedded SDF it is found by bisection
//! along each boundary vertex's ray. Elements are isoparametric trilinear hexahedra (2×2×2
//! Gauss points, Jacobians per point); the boundary quadrilaterals carry the Robin term
//! ∮ φ v/(2A) (2×2 Gauss on the bilinear surface patch). The bilinear patches approximate
//! a smooth surface to O(h²), so the method stays second order. Multigrid reuses the
//! lattice's trilinear prolongation ([`crate::q1::Q1Multigrid::for_lattice`]).
//!
//! The mapping degrades where R(û) varies fast with û (elongated or nearly non-star
//! bodies): elements shear, and an inverted one is refused with [`FemError::Invalid`].

use glam::{DMat3, DVec3};

use crate::error::FemError;

/// A star-shaped body meshed with `cells` (even) elements per axis.
#[derive(Debug, Clone, PartialEq)]
pub struct StarMesh {
    /// Elements per axis of the underlying lattice (even, so the centre is a vertex).
    pub cells: usize,
    /// The centre the rays start from (length).
    pub centre: DVec3,
    /// Vertex positions, lattice order (x fastest).
    pub vertices: Vec<DVec3>,
}

/// The two-point Gauss–Legendre nodes on [0, 1], ½ ∓ ½/√3.
const GAUSS: [f64; 2] = [0.211_324_865_405_187_1, 0.788_675_134_594_812_9];

/// Trilinear shape functions and their reference gradients at ξ ∈ [0, 1]³ (corner a has
/// offsets (a & 1, a >> 1 & 1, a >> 2)).
fn shape_at(xi: [f64; 3]) -> ([f64; 8], [DVec3; 8]) {
    let bits = |a: usize| [a & 1, (a >> 1) & 1, (a >> 2) & 1];
    let shape = std::array::from_fn(|a| {
        let p = bits(a);
        (0..3)
            .map(|d| if p[d] == 1 { xi[d] } else { 1.0 - xi[d] })
            .product()
    });
    let dshape = std::array::from_fn(|a| {
        let p = bits(a);
        let f = |d: usize| if p[d] == 1 { xi[d] } else { 1.0 - xi[d] };
        let s = |d: usize| if p[d] == 1 { 1.0 } else { -1.0 };
        DVec3::new(s(0) * f(1) * f(2), f(0) * s(1) * f(2), f(0) * f(1) * s(2))
    });
    (shape, dshape)
}

/// One element's geometry at a reference point: shape values, physical gradients and the
/// Jacobian determinant.
struct Point {
    shape: [f64; 8],
    grads: [DVec3; 8],
    position: DVec3,
    det: f64,
}

impl StarMesh {
    /// The ball of radius `radius` around `centre`.
    pub fn ball(cells: usize, centre: DVec3, radius: f64) -> Result<Self, FemError> {
        if !(radius > 0.0 && radius.is_finite()) {
            return Err(FemError::Invalid(format!(
                "ball of radius {radius}: a positive radius"
            )));
        }
        Self::with_radius(cells, centre, |_| Ok(radius))
    }

    /// The body {sdf < 0} seen from `centre` (which must be inside), for rays that leave
    /// it within `reach`: the surface along each boundary vertex's ray is bracketed by
    /// marching in steps of `step` and refined by bisection to 10⁻⁹ of `reach`. A ray that
    /// re-enters the body before `reach` means the body is not star-shaped from `centre`
    /// and is refused.
    pub fn from_sdf(
        cells: usize,
        centre: DVec3,
        sdf: impl Fn(DVec3) -> f64,
        reach: f64,
        step: f64,
    ) -> Result<Self, FemError> {
        let valid = reach.is_finite() && step.is_finite() && step > 0.0 && reach > step;
        if !valid || !centre.is_finite() {
            return Err(FemError::Invalid(format!(
                "reach {reach} and step {step}: finite, 0 < step < reach"
            )));
        }
        let at_centre = sdf(centre);
        if at_centre.is_nan() || at_centre >= 0.0 {
            return Err(FemError::Invalid(format!(
                "the centre {centre} is not inside the body (sdf {at_centre})"
            )));
        }
        Self::with_radius(cells, centre, |dir| {
            let f = |r: f64| sdf(centre + dir * r);
            let (mut lo, mut r) = (0.0, step);
            while r <= reach && f(r) < 0.0 {
                lo = r;
                r += step;
            }
            if r > reach {
                return Err(FemError::Invalid(format!(
                    "the ray from {centre} along {dir} does not leave the body within {reach}"
                )));
            }
            let mut hi = r;
            while hi - lo > 1e-9 * reach {
                let mid = 0.5 * (lo + hi);
                if f(mid) < 0.0 { lo = mid } else { hi = mid }
            }
            let mut s = r + step;
            while s <= reach {
                let v = f(s);
                if v < 0.0 {
                    return Err(FemError::Invalid(format!(
                        "the body is not star-shaped from {centre}: the ray along {dir} \
                         re-enters it at distance {s}"
                    )));
                }
                s += step.max(0.5 * v);
            }
            Ok(0.5 * (lo + hi))
        })
    }

    fn with_radius(
        cells: usize,
        centre: DVec3,
        radius: impl Fn(DVec3) -> Result<f64, FemError>,
    ) -> Result<Self, FemError> {
        if cells < 2 || cells % 2 == 1 {
            return Err(FemError::Invalid(format!(
                "{cells} cells per axis: an even count ≥ 2"
            )));
        }
        let n = cells + 1;
        // Radii on the lattice's boundary vertices; interior vertices on the same ray
        // (same û) share them. The ray of vertex u is that of its boundary projection
        // u/‖u‖_∞, and along each ray the mapping is linear in ‖u‖_∞.
        let mut vertices = Vec::with_capacity(n * n * n);
        let mut cache = std::collections::HashMap::new();
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let at = [i, j, k].map(|v| 2 * v as i64 - cells as i64);
                    let inf = at.iter().map(|v| v.abs()).max().unwrap_or(0);
                    if inf == 0 {
                        vertices.push(centre);
                        continue;
                    }
                    // The boundary vertex on this ray, in lowest terms (exact rationals).
                    let g = at.iter().fold(inf, |g, &v| gcd(g, v.unsigned_abs() as i64));
                    let key = at.map(|v| v / g);
                    let u = DVec3::new(at[0] as f64, at[1] as f64, at[2] as f64);
                    let dir = u.normalize();
                    let r = match cache.get(&key) {
                        Some(&r) => r,
                        None => {
                            let r = radius(dir)?;
                            if !(r > 0.0 && r.is_finite()) {
                                return Err(FemError::Invalid(format!(
                                    "radius {r} along {dir}: positive and finite"
                                )));
                            }
                            cache.insert(key, r);
                            r
                        }
                    };
                    vertices.push(centre + dir * (r * inf as f64 / cells as f64));
                }
            }
        }
        Ok(Self {
            cells,
            centre,
            vertices,
        })
    }

    /// Index of lattice vertex (i, j, k).
    pub fn node(&self, at: [usize; 3]) -> usize {
        let n = self.cells + 1;
        at[0] + n * (at[1] + n * at[2])
    }

    /// The centre vertex.
    pub fn centre_node(&self) -> usize {
        let h = self.cells / 2;
        self.node([h, h, h])
    }

    /// The eight vertices of element (i, j, k), corner a at offsets (a & 1, a >> 1 & 1,
    /// a >> 2).
    pub fn element(&self, at: [usize; 3]) -> [usize; 8] {
        std::array::from_fn(|a| {
            self.node([at[0] + (a & 1), at[1] + ((a >> 1) & 1), at[2] + (a >> 2)])
        })
    }

    /// The element's trilinear map at ξ: shape values, reference gradients, the Jacobian
    /// (columns ∂X/∂ξ_d) and the mapped point.
    fn map(&self, ids: &[usize; 8], xi: [f64; 3]) -> ([f64; 8], [DVec3; 8], DMat3, DVec3) {
        let (shape, dshape) = shape_at(xi);
        let mut jac = DMat3::ZERO;
        let mut position = DVec3::ZERO;
        for a in 0..8 {
            let x = self.vertices[ids[a]];
            jac.x_axis += x * dshape[a].x;
            jac.y_axis += x * dshape[a].y;
            jac.z_axis += x * dshape[a].z;
            position += x * shape[a];
        }
        (shape, dshape, jac, position)
    }

    /// Element (i, j, k)'s vertices and its 2×2×2 Gauss points (weight det J/8 each);
    /// an inverted element is an error.
    fn gauss_points(&self, at: [usize; 3]) -> Result<([usize; 8], [Point; 8]), FemError> {
        let ids = self.element(at);
        let mut out = Vec::with_capacity(8);
        for &pz in &GAUSS {
            for &py in &GAUSS {
                for &px in &GAUSS {
                    out.push(
                        self.point(&ids, [px, py, pz]).ok_or_else(|| {
                            FemError::Invalid(format!("inverted element at {at:?}"))
                        })?,
                    );
                }
            }
        }
        let points: [Point; 8] = out
            .try_into()
            .map_err(|_| FemError::Invalid("eight Gauss points".into()))?;
        Ok((ids, points))
    }

    fn point(&self, ids: &[usize; 8], xi: [f64; 3]) -> Option<Point> {
        let (shape, dshape, jac, position) = self.map(ids, xi);
        let det = jac.determinant();
        if det.is_nan() || det <= 0.0 {
            return None;
        }
        let inv_t = jac.inverse().transpose();
        Some(Point {
            shape,
            grads: std::array::from_fn(|a| inv_t * dshape[a]),
            position,
            det,
        })
    }

    /// Assembles ∫D∇φ·∇v + ∫σ_a φ v + ∮ φ v/(2A) with D (length) and σ_a (1/length) from
    /// `coefficients(x)` at each Gauss point x, and Robin factor A.
    pub fn assemble_with(
        &self,
        coefficients: impl Fn(DVec3) -> (f64, f64),
        robin: f64,
    ) -> Result<sprs::CsMat<f64>, FemError> {
        if !(robin >= 1.0 && robin.is_finite()) {
            return Err(FemError::Invalid(format!("Robin factor {robin}: A ≥ 1")));
        }
        let c = self.cells;
        let n = (c + 1).pow(3);
        let mut t = sprs::TriMat::with_capacity((n, n), 64 * c * c * c);
        for k in 0..c {
            for j in 0..c {
                for i in 0..c {
                    let (ids, points) = self.gauss_points([i, j, k])?;
                    let mut local = [[0.0; 8]; 8];
                    for p in &points {
                        let (d, sa) = coefficients(p.position);
                        if !(d > 0.0 && sa >= 0.0 && d.is_finite() && sa.is_finite()) {
                            return Err(FemError::Invalid(format!(
                                "D = {d}, σ_a = {sa} at {}: D > 0, σ_a ≥ 0",
                                p.position
                            )));
                        }
                        let w = p.det / 8.0;
                        for a in 0..8 {
                            for b in 0..8 {
                                local[a][b] += w
                                    * (d * p.grads[a].dot(p.grads[b])
                                        + sa * p.shape[a] * p.shape[b]);
                            }
                        }
                    }
                    for a in 0..8 {
                        for b in 0..8 {
                            t.add_triplet(ids[a], ids[b], local[a][b]);
                        }
                    }
                }
            }
        }
        // Boundary quadrilaterals: the lattice's outer faces.
        let weight = 1.0 / (2.0 * robin);
        for axis in 0..3 {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            for side in [0, c] {
                for fu in 0..c {
                    for fv in 0..c {
                        let ids: [usize; 4] = std::array::from_fn(|q| {
                            let mut at = [0; 3];
                            at[axis] = side;
                            at[u] = fu + (q & 1);
                            at[v] = fv + (q >> 1);
                            self.node(at)
                        });
                        let x: [DVec3; 4] = std::array::from_fn(|q| self.vertices[ids[q]]);
                        let mut local = [[0.0; 4]; 4];
                        for &s in &GAUSS {
                            for &r in &GAUSS {
                                let shape =
                                    [(1.0 - s) * (1.0 - r), s * (1.0 - r), (1.0 - s) * r, s * r];
                                let ds = (x[1] - x[0]) * (1.0 - r) + (x[3] - x[2]) * r;
                                let dr = (x[2] - x[0]) * (1.0 - s) + (x[3] - x[1]) * s;
                                let area = ds.cross(dr).length() / 4.0;
                                for a in 0..4 {
                                    for b in 0..4 {
                                        local[a][b] += weight * area * shape[a] * shape[b];
                                    }
                                }
                            }
                        }
                        for a in 0..4 {
                            for b in 0..4 {
                                t.add_triplet(ids[a], ids[b], local[a][b]);
                            }
                        }
                    }
                }
            }
        }
        Ok(t.to_csr())
    }

    /// Assembles with constant D and σ_a.
    pub fn assemble(
        &self,
        diffusion: f64,
        absorption: f64,
        robin: f64,
    ) -> Result<sprs::CsMat<f64>, FemError> {
        self.assemble_with(|_| (diffusion, absorption), robin)
    }

    /// The load ∫ q v + ∫ 3D Q₁·∇v of a volumetric source q (power/length³) and first
    /// moment Q₁, both from `source(x)` = (q, 3D Q₁) at each Gauss point.
    pub fn load(&self, source: impl Fn(DVec3) -> (f64, DVec3)) -> Result<Vec<f64>, FemError> {
        let c = self.cells;
        let mut b = vec![0.0; (c + 1).pow(3)];
        for k in 0..c {
            for j in 0..c {
                for i in 0..c {
                    let (ids, points) = self.gauss_points([i, j, k])?;
                    for p in &points {
                        let (q, moment) = source(p.position);
                        let w = p.det / 8.0;
                        for a in 0..8 {
                            b[ids[a]] += w * (q * p.shape[a] + moment.dot(p.grads[a]));
                        }
                    }
                }
            }
        }
        Ok(b)
    }

    /// Where `x` lies: the element and the reference coordinates in it. A first guess
    /// inverts the radial mapping (with R(û) interpolated bilinearly between boundary
    /// vertices); Newton's method on the element's trilinear map then finds the exact
    /// reference point, stepping to the neighbouring element while it falls outside. (The
    /// radial mapping has kinks on the cube's diagonal planes, which cross elements: using
    /// it alone would make the located point O(h) wrong there.) Points in the sliver
    /// between the bilinear surface patches and the curved surface get reference
    /// coordinates just outside [0, 1] (extrapolation); `None` farther out.
    pub fn locate(&self, x: DVec3) -> Option<([usize; 3], [f64; 3])> {
        let c = self.cells as f64;
        let d = x - self.centre;
        let r = d.length();
        let lattice = |u: DVec3| {
            let s = (u + 1.0) * (0.5 * c);
            let cell = s.floor().clamp(DVec3::ZERO, DVec3::splat(c - 1.0));
            let xi = s - cell;
            (
                [cell.x as usize, cell.y as usize, cell.z as usize],
                [xi.x, xi.y, xi.z],
            )
        };
        if r == 0.0 {
            return Some(lattice(DVec3::ZERO));
        }
        // The ray's point on the cube's surface, and the boundary radius there.
        let s = d / d.abs().max_element();
        let (cell, xi) = lattice(s);
        let (shape, _) = shape_at(xi);
        let radius: f64 = (0..8)
            .filter(|&a| shape[a] != 0.0)
            .map(|a| {
                let at = [
                    cell[0] + (a & 1),
                    cell[1] + ((a >> 1) & 1),
                    cell[2] + (a >> 2),
                ];
                shape[a] * (self.vertices[self.node(at)] - self.centre).length()
            })
            .sum();
        let (mut cell, mut xi) = lattice(s * (r / radius).min(1.0));
        let outside_tolerance = 1e-9;
        for _move in 0..8 {
            let ids = self.element(cell);
            for _newton in 0..20 {
                let (_, _, jac, position) = self.map(&ids, xi);
                let step = jac.inverse() * (x - position);
                if !step.is_finite() {
                    return None;
                }
                xi = [xi[0] + step.x, xi[1] + step.y, xi[2] + step.z];
                if step.length() < 1e-13 {
                    break;
                }
            }
            // Inside this element, beyond the lattice's edge, or in a neighbour?
            let mut moved = false;
            let mut beyond = 0.0f64;
            for a in 0..3 {
                if xi[a] < -outside_tolerance {
                    if cell[a] == 0 {
                        beyond = beyond.max(-xi[a]);
                        continue;
                    }
                    cell[a] -= 1;
                    xi[a] += 1.0;
                    moved = true;
                } else if xi[a] > 1.0 + outside_tolerance {
                    if cell[a] + 1 == self.cells {
                        beyond = beyond.max(xi[a] - 1.0);
                        continue;
                    }
                    cell[a] += 1;
                    xi[a] -= 1.0;
                    moved = true;
                }
            }
            if !moved {
                // Past the bilinear surface patches by less than half an element: the
                // sliver between them and the curved surface, extrapolated.
                if beyond > 0.5 {
                    return None;
                }
                let edge = |a: usize, v: f64| {
                    let low = if cell[a] == 0 { -0.5 } else { 0.0 };
                    let high = if cell[a] + 1 == self.cells { 1.5 } else { 1.0 };
                    v.clamp(low, high)
                };
                return Some((cell, [edge(0, xi[0]), edge(1, xi[1]), edge(2, xi[2])]));
            }
            xi = xi.map(|v| v.clamp(0.0, 1.0));
        }
        None
    }

    /// Interpolates nodal values `x` at point `p` (trilinear in the located element);
    /// `None` outside the body.
    pub fn interpolate(&self, values: &[f64], p: DVec3) -> Option<f64> {
        let (cell, xi) = self.locate(p)?;
        let ids = self.element(cell);
        let (shape, _) = shape_at(xi);
        Some((0..8).map(|a| shape[a] * values[ids[a]]).sum())
    }
}

fn gcd(a: i64, b: i64) -> i64 {
    if b == 0 { a } else { gcd(b, a % b) }
}
