//! The steady P1 moment system with in-scattering and anisotropy, by least-squares finite
//! elements — the stabilised way to Murray's P1 system:
//!
//! ∇·E + σ_a φ = q,   ∇φ/3 + σ_t′ E = 0,   σ_t′ = σ_a + (1 − g)σ_s,
//!
//! with φ and E_x, E_y, E_z all trilinear (Q1) at the vertices, found by minimising
//!
//! J = ‖∇·E + σ_a φ − q‖² + 3‖∇φ/3 + σ_t′E‖² + ∮ (E·n − φ/(2A))²
//!
//! (A = ∞: the last term is ∮ (E·n)², a reflecting box). Why least squares: Galerkin on the
//! first-order system couples odd and even vertices only through central differences, the
//! checkerboard of Murray's FTCS and of his finite elements; least squares gives a
//! symmetric positive-definite system whose minimiser has no such mode, solved here by
//! Jacobi-preconditioned CG. Its cost against the primal diffusion elements: 4 unknowns
//! per vertex instead of 1, 16× the matrix entries, and CG iterations growing like 1/h.

use crate::error::FemError;
use crate::solvers::Convergence;
use lucent_core::Stopping;

/// A P1 problem on a box of `cells` elements of side `spacing`, constant coefficients.
#[derive(Debug, Clone, PartialEq)]
pub struct P1LeastSquares {
    /// Elements per axis.
    pub cells: [usize; 3],
    /// Element side (length).
    pub spacing: f64,
    /// σ_a (1/length).
    pub sigma_a: f64,
    /// σ_t′ (1/length).
    pub sigma_t_reduced: f64,
    /// Robin factor A on the box, `None`: reflecting.
    pub robin: Option<f64>,
}

impl P1LeastSquares {
    fn node(&self, at: [usize; 3]) -> usize {
        let n = self.cells.map(|c| c + 1);
        at[0] + n[0] * (at[1] + n[1] * at[2])
    }

    /// The normal matrix and right-hand side for a source density q(x) (x from the box's
    /// low corner). Unknown 4·vertex + c: c = 0 for φ, 1 + i for E_i.
    pub fn assemble(
        &self,
        q: impl Fn([f64; 3]) -> f64,
    ) -> Result<(sprs::CsMat<f64>, Vec<f64>), FemError> {
        let ok = self.cells.iter().all(|&c| c >= 1)
            && self.spacing > 0.0
            && self.sigma_a >= 0.0
            && self.sigma_t_reduced > 0.0
            && self.robin.is_none_or(|a| a >= 1.0);
        if !ok {
            return Err(FemError::Invalid(
                "P1 least squares: cells ≥ 1, h > 0, σ_a ≥ 0, σ_t′ > 0, A ≥ 1".into(),
            ));
        }
        let h = self.spacing;
        let (sa, st) = (self.sigma_a, self.sigma_t_reduced);
        let n: usize = self.cells.iter().map(|c| c + 1).product();
        let g = 0.5 / 3f64.sqrt();
        let points = [0.5 - g, 0.5 + g];
        let bits = |a: usize| [a & 1, (a >> 1) & 1, (a >> 2) & 1];
        let [cx, cy, cz] = self.cells;
        let mut t = sprs::TriMat::with_capacity((4 * n, 4 * n), 1024 * cx * cy * cz);
        let mut rhs = vec![0.0; 4 * n];
        for k in 0..cz {
            for j in 0..cy {
                for i in 0..cx {
                    let ids: [usize; 8] = std::array::from_fn(|a| {
                        let p = bits(a);
                        self.node([i + p[0], j + p[1], k + p[2]])
                    });
                    let mut local = [[0.0; 32]; 32];
                    let mut load = [0.0; 32];
                    for &pz in &points {
                        for &py in &points {
                            for &px in &points {
                                let xi = [px, py, pz];
                                let w = h * h * h / 8.0;
                                let mut l1 = [0.0; 32];
                                let mut l2 = [[0.0; 32]; 3];
                                for a in 0..8 {
                                    let p = bits(a);
                                    let f = |d: usize| if p[d] == 1 { xi[d] } else { 1.0 - xi[d] };
                                    let s = |d: usize| if p[d] == 1 { 1.0 / h } else { -1.0 / h };
                                    let value = f(0) * f(1) * f(2);
                                    let grad = [
                                        s(0) * f(1) * f(2),
                                        f(0) * s(1) * f(2),
                                        f(0) * f(1) * s(2),
                                    ];
                                    l1[4 * a] = sa * value;
                                    for d in 0..3 {
                                        l1[4 * a + 1 + d] = grad[d];
                                        l2[d][4 * a] = grad[d] / 3.0;
                                        l2[d][4 * a + 1 + d] = st * value;
                                    }
                                }
                                let x = [
                                    (i as f64 + px) * h,
                                    (j as f64 + py) * h,
                                    (k as f64 + pz) * h,
                                ];
                                let qx = q(x);
                                for r in 0..32 {
                                    load[r] += w * qx * l1[r];
                                    for c in 0..32 {
                                        let mut v = l1[r] * l1[c];
                                        for l in &l2 {
                                            v += 3.0 * l[r] * l[c];
                                        }
                                        local[r][c] += w * v;
                                    }
                                }
                            }
                        }
                    }
                    for r in 0..32 {
                        let gr = 4 * ids[r / 4] + r % 4;
                        rhs[gr] += load[r];
                        for c in 0..32 {
                            if local[r][c] != 0.0 {
                                t.add_triplet(gr, 4 * ids[c / 4] + c % 4, local[r][c]);
                            }
                        }
                    }
                }
            }
        }
        // Boundary: ∮ (E·n − φ/(2A))² on the six faces (2×2 Gauss per quad).
        let phi_weight = self.robin.map_or(0.0, |a| 1.0 / (2.0 * a));
        for axis in 0..3 {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            for (side, normal) in [(0usize, -1.0), (self.cells[axis], 1.0)] {
                for fu in 0..self.cells[u] {
                    for fv in 0..self.cells[v] {
                        let ids: [usize; 4] = std::array::from_fn(|c| {
                            let mut at = [0; 3];
                            at[axis] = side;
                            at[u] = fu + (c & 1);
                            at[v] = fv + (c >> 1);
                            self.node(at)
                        });
                        for &s in &points {
                            for &r in &points {
                                let shape =
                                    [(1.0 - s) * (1.0 - r), s * (1.0 - r), (1.0 - s) * r, s * r];
                                let mut lb = [0.0; 16];
                                for c in 0..4 {
                                    lb[4 * c] = -phi_weight * shape[c];
                                    lb[4 * c + 1 + axis] = normal * shape[c];
                                }
                                let w = h * h / 4.0;
                                for a in 0..16 {
                                    for b in 0..16 {
                                        let value = w * lb[a] * lb[b];
                                        if value != 0.0 {
                                            t.add_triplet(
                                                4 * ids[a / 4] + a % 4,
                                                4 * ids[b / 4] + b % 4,
                                                value,
                                            );
                                        }
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        Ok((t.to_csr(), rhs))
    }

    /// Jacobi-preconditioned CG on the normal system, from zero (an error if the sizes of
    /// `matrix` and `rhs` differ).
    pub fn solve(
        matrix: &sprs::CsMat<f64>,
        rhs: &[f64],
        stopping: &Stopping,
    ) -> Result<(Vec<f64>, Convergence), FemError> {
        let diagonal: Vec<f64> = (0..rhs.len())
            .map(|i| {
                matrix
                    .get(i, i)
                    .copied()
                    .filter(|d| *d > 0.0)
                    .unwrap_or(1.0)
            })
            .collect();
        let mut x = vec![0.0; rhs.len()];
        let convergence =
            crate::solvers::conjugate_gradient(matrix, rhs, &mut x, stopping, |r, z| {
                for ((z, r), d) in z.iter_mut().zip(r).zip(&diagonal) {
                    *z = r / d;
                }
            });
        Ok((x, convergence?))
    }
}
