//! Q1 diffusion on a ball, with a boundary-fitted mesh: the cube lattice [−1, 1]³ of n
//! elements per axis mapped radially onto the ball of radius R, u ↦ R u ‖u‖_∞/‖u‖₂, so
//! the cube's faces land on the sphere. Elements are isoparametric trilinear hexahedra
//! (2×2×2 Gauss points, Jacobians per point), the boundary quadrilaterals carry the
//! Robin term ∮ φ v/(2A) (2×2 Gauss on the bilinear surface patch). The bilinear patches
//! approximate the sphere to O(h²), so the method stays second order. Multigrid reuses
//! the lattice's trilinear prolongation ([`crate::q1::Q1Multigrid::for_lattice`]).

use glam::{DMat3, DVec3};

use crate::error::FemError;

/// A ball of radius `radius` meshed with `cells` (even) elements per axis.
#[derive(Debug, Clone, PartialEq)]
pub struct BallMesh {
    /// Elements per axis of the underlying lattice (even, so the centre is a vertex).
    pub cells: usize,
    /// Radius (length).
    pub radius: f64,
    /// Vertex positions, lattice order (x fastest).
    pub vertices: Vec<DVec3>,
}

impl BallMesh {
    /// The mapped mesh.
    pub fn new(cells: usize, radius: f64) -> Result<Self, FemError> {
        if cells < 2 || cells % 2 == 1 || !(radius > 0.0 && radius.is_finite()) {
            return Err(FemError::Invalid(format!(
                "ball mesh of {cells} cells, radius {radius}: an even count ≥ 2, a positive radius"
            )));
        }
        let n = cells + 1;
        let mut vertices = Vec::with_capacity(n * n * n);
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let u = DVec3::new(i as f64, j as f64, k as f64) * (2.0 / cells as f64) - 1.0;
                    let l2 = u.length();
                    vertices.push(if l2 == 0.0 {
                        DVec3::ZERO
                    } else {
                        u * (u.abs().max_element() / l2) * radius
                    });
                }
            }
        }
        Ok(Self {
            cells,
            radius,
            vertices,
        })
    }

    /// Index of lattice vertex (i, j, k).
    pub fn node(&self, at: [usize; 3]) -> usize {
        let n = self.cells + 1;
        at[0] + n * (at[1] + n * at[2])
    }

    /// The centre vertex.
    pub fn centre(&self) -> usize {
        let h = self.cells / 2;
        self.node([h, h, h])
    }

    /// Assembles ∫D∇φ·∇v + ∫σ_a φ v + ∮ φ v/(2A) for constant D (length), σ_a (1/length)
    /// and Robin factor A.
    pub fn assemble(
        &self,
        diffusion: f64,
        absorption: f64,
        robin: f64,
    ) -> Result<sprs::CsMat<f64>, FemError> {
        let valid = diffusion > 0.0
            && absorption >= 0.0
            && robin >= 1.0
            && diffusion.is_finite()
            && absorption.is_finite()
            && robin.is_finite();
        if !valid {
            return Err(FemError::Invalid("D > 0, σ_a ≥ 0, A ≥ 1".into()));
        }
        let c = self.cells;
        let n = (c + 1).pow(3);
        let g = 0.5 / 3f64.sqrt();
        let points = [0.5 - g, 0.5 + g];
        let bits = |a: usize| [a & 1, (a >> 1) & 1, (a >> 2) & 1];
        let mut t = sprs::TriMat::with_capacity((n, n), 64 * c * c * c);
        for k in 0..c {
            for j in 0..c {
                for i in 0..c {
                    let ids: [usize; 8] = std::array::from_fn(|a| {
                        let p = bits(a);
                        self.node([i + p[0], j + p[1], k + p[2]])
                    });
                    let x: [DVec3; 8] = std::array::from_fn(|a| self.vertices[ids[a]]);
                    let mut local = [[0.0; 8]; 8];
                    for &pz in &points {
                        for &py in &points {
                            for &px in &points {
                                let xi = [px, py, pz];
                                let shape: [f64; 8] = std::array::from_fn(|a| {
                                    let p = bits(a);
                                    (0..3)
                                        .map(|d| if p[d] == 1 { xi[d] } else { 1.0 - xi[d] })
                                        .product()
                                });
                                let dshape: [DVec3; 8] = std::array::from_fn(|a| {
                                    let p = bits(a);
                                    let f = |d: usize| if p[d] == 1 { xi[d] } else { 1.0 - xi[d] };
                                    let s = |d: usize| if p[d] == 1 { 1.0 } else { -1.0 };
                                    DVec3::new(
                                        s(0) * f(1) * f(2),
                                        f(0) * s(1) * f(2),
                                        f(0) * f(1) * s(2),
                                    )
                                });
                                // J[col d] = ∂X/∂ξ_d.
                                let mut jac = DMat3::ZERO;
                                for a in 0..8 {
                                    jac.x_axis += x[a] * dshape[a].x;
                                    jac.y_axis += x[a] * dshape[a].y;
                                    jac.z_axis += x[a] * dshape[a].z;
                                }
                                let det = jac.determinant();
                                if det <= 0.0 {
                                    return Err(FemError::Invalid(format!(
                                        "inverted element at ({i}, {j}, {k})"
                                    )));
                                }
                                let inv_t = jac.inverse().transpose();
                                let grads: [DVec3; 8] = std::array::from_fn(|a| inv_t * dshape[a]);
                                let w = det / 8.0;
                                for a in 0..8 {
                                    for b in 0..8 {
                                        local[a][b] += w
                                            * (diffusion * grads[a].dot(grads[b])
                                                + absorption * shape[a] * shape[b]);
                                    }
                                }
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
                        for &s in &points {
                            for &r in &points {
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
}
