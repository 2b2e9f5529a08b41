//! Murray's finite-element discretisation of the steady RTE without in-scattering
//! (thesis §3.3, App. A; docs/reference-cases.md):
//!
//! ω·∇L = Q_e − K_t L,  L(x, ω) = Σ_j Σ_l L_{jl} ψ_j(ω) ϕ_l(x),
//!
//! angular basis ψ = {1, ω_x, ω_y, ω_z}, spatial basis the trilinear hat functions ϕ_l of
//! the grid's vertices. Galerkin with ψ_i ϕ_k gives
//!
//! Σ_{jl} [ α_ij · β_kl + K_t γ_ij δ_kl ] L_jl = ∫ψ_i ϕ_k Q_e,
//!
//! α_ij = ∫ψ_iψ_j ω dω (non-zero: α_{0a} = α_{a0} = 4π/3 e_a), γ = ∫ψ_iψ_j dω =
//! diag(4π, 4π/3, 4π/3, 4π/3), β_kl = ∫ϕ_k ∇ϕ_l (the tensor stencil
//! [−½, 0, ½] ⊗ [⅙, ⅔, ⅙] ⊗ [⅙, ⅔, ⅙] h² per derivative axis) and δ_kl = ∫ϕ_kϕ_l
//! ([⅙, ⅔, ⅙]^⊗3 h³). The thesis's 1-D integral ∫ϕ_kϕ′_{k−1} is printed +½; it is −½ (the
//! stencil it then prints is right).
//!
//! Jacobi on this system diverges whatever K_t (docs/reference-cases.md): its iteration matrix's
//! spectral radius is 19/8 = 2.375 once the mass term dominates (K_tΔ ≥ 10: the constant
//! mode flips sign and grows ×19/8 per sweep, since the mass stencil's off-diagonal sum
//! 19/27 exceeds its centre 8/27) and grows like 1/(K_tΔ) below (20.4 at K_tΔ = 0.1).

use std::f64::consts::PI;

use crate::error::FemError;

/// Vertices of the mesh: `nodes` per axis, spacing `h`; periodic or bounded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mesh {
    /// Vertices per axis (cells per axis when periodic, cells + 1 otherwise).
    pub nodes: [usize; 3],
    /// Cell side (length).
    pub spacing: f64,
    /// Wrap around (Fourier analysis, spectral radii) or stop at the box (natural
    /// boundary: the integrals run over the domain only).
    pub periodic: bool,
}

impl Mesh {
    /// Number of vertices.
    pub fn len(&self) -> usize {
        self.nodes.iter().product()
    }

    /// Never empty once validated.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn check(&self) -> Result<(), FemError> {
        let min = if self.periodic { 3 } else { 2 };
        if self.nodes.iter().any(|&n| n < min) || !(self.spacing > 0.0 && self.spacing.is_finite())
        {
            return Err(FemError::Invalid(format!(
                "mesh {:?} with spacing {}: at least {min} vertices per axis, positive spacing",
                self.nodes, self.spacing
            )));
        }
        Ok(())
    }

    fn index(&self, at: [usize; 3]) -> usize {
        at[0] + self.nodes[0] * (at[1] + self.nodes[1] * at[2])
    }
}

/// ∫ϕ_a ϕ_b over a 1-D element of side h, local vertices a, b ∈ {0, 1}.
fn mass_1d(a: usize, b: usize, h: f64) -> f64 {
    if a == b { h / 3.0 } else { h / 6.0 }
}

/// ∫ϕ_a ϕ′_b over a 1-D element: ϕ′_b = ±1/h, ∫ϕ_a = h/2.
fn derivative_1d(_a: usize, b: usize) -> f64 {
    if b == 1 { 0.5 } else { -0.5 }
}

/// The trilinear element matrices: mass (8×8) and, per axis, ∫ϕ_a ∂_axis ϕ_b (8×8).
/// Local vertex a = a0 + 2 a1 + 4 a2.
pub fn element_matrices(h: f64) -> ([[f64; 8]; 8], [[[f64; 8]; 8]; 3]) {
    let bits = |a: usize| [a & 1, (a >> 1) & 1, (a >> 2) & 1];
    let mut mass = [[0.0; 8]; 8];
    let mut derivative = [[[0.0; 8]; 8]; 3];
    for a in 0..8 {
        for b in 0..8 {
            let (pa, pb) = (bits(a), bits(b));
            mass[a][b] = (0..3).map(|i| mass_1d(pa[i], pb[i], h)).product();
            for (axis, d) in derivative.iter_mut().enumerate() {
                d[a][b] = (0..3)
                    .map(|i| {
                        if i == axis {
                            derivative_1d(pa[i], pb[i])
                        } else {
                            mass_1d(pa[i], pb[i], h)
                        }
                    })
                    .product();
            }
        }
    }
    (mass, derivative)
}

/// α_ij: ∫ψ_iψ_j ω dω, a 3-vector per (i, j).
pub fn alpha() -> [[[f64; 3]; 4]; 4] {
    let mut a = [[[0.0; 3]; 4]; 4];
    for axis in 0..3 {
        a[0][axis + 1][axis] = 4.0 * PI / 3.0;
        a[axis + 1][0][axis] = 4.0 * PI / 3.0;
    }
    a
}

/// γ_ij = ∫ψ_iψ_j dω.
pub fn gamma() -> [f64; 4] {
    [4.0 * PI, 4.0 * PI / 3.0, 4.0 * PI / 3.0, 4.0 * PI / 3.0]
}

/// The assembled Murray system: 4 unknowns per vertex, index 4·vertex + j.
#[derive(Debug, Clone)]
pub struct MurraySystem {
    /// The mesh.
    pub mesh: Mesh,
    /// The matrix (CSR).
    pub matrix: sprs::CsMat<f64>,
}

impl MurraySystem {
    /// Assembles M + K_t R on `mesh` for extinction `sigma_t` (1/length).
    pub fn assemble(mesh: Mesh, sigma_t: f64) -> Result<Self, FemError> {
        Self::assemble_within(mesh, sigma_t, &lucent_core::Interrupt::never())
    }

    /// [`MurraySystem::assemble`], asking `interrupt` before every layer of vertices
    /// ([`FemError::Halted`]: 64³ elements take seconds).
    ///
    /// Row by row: each vertex gathers the 4×4 blocks of its (at most 8) elements for its
    /// (at most 27) neighbours and writes its four rows sorted, so the CSR matrix is built
    /// in place, z-layers of vertices in parallel. (Element triplets sorted into CSR at the
    /// end, [`MurraySystem::assemble_by_elements`], spent 0.6 s at 24³ in one sort that
    /// nothing could interrupt.)
    pub fn assemble_within(
        mesh: Mesh,
        sigma_t: f64,
        interrupt: &lucent_core::Interrupt,
    ) -> Result<Self, FemError> {
        use rayon::prelude::*;
        mesh.check()?;
        if !(sigma_t >= 0.0 && sigma_t.is_finite()) {
            return Err(FemError::Invalid(format!("K_t = {sigma_t}: must be ≥ 0")));
        }
        let (mass, derivative) = element_matrices(mesh.spacing);
        let (alpha, gamma) = (alpha(), gamma());
        // The streaming block of local vertices (a, b): Σ_axis α_ij,axis ∂_axis[a][b].
        let mut streaming = [[[[0.0f64; 4]; 4]; 8]; 8];
        for (a, row) in streaming.iter_mut().enumerate() {
            for (b, block) in row.iter_mut().enumerate() {
                for (i, line) in block.iter_mut().enumerate() {
                    for (j, v) in line.iter_mut().enumerate() {
                        *v = (0..3)
                            .map(|ax| alpha[i][j][ax] * derivative[ax][a][b])
                            .sum();
                    }
                }
            }
        }
        let nodes = mesh.nodes;
        let cells: [usize; 3] = std::array::from_fn(|a| {
            if mesh.periodic {
                nodes[a]
            } else {
                nodes[a] - 1
            }
        });
        // The cells along an axis holding vertex coordinate v, with v's local offset in
        // each (1: v is the cell's upper vertex).
        let owners = |axis: usize, v: usize| -> [Option<(usize, usize)>; 2] {
            std::array::from_fn(|offset| {
                let cell = if mesh.periodic {
                    Some((v + nodes[axis] - offset) % nodes[axis])
                } else {
                    v.checked_sub(offset).filter(|&c| c < cells[axis])
                };
                cell.map(|c| (c, offset))
            })
        };
        /// A layer's rows in CSR pieces: each row's length, its columns and values.
        type Layer = (Vec<usize>, Vec<usize>, Vec<f64>);
        /// A neighbour's 4×4 block and which of its entries an element touched.
        type Block = (usize, [[f64; 4]; 4], [[bool; 4]; 4]);
        let layers: Vec<Result<Layer, FemError>> = (0..nodes[2])
            .into_par_iter()
            .map(|z| {
                if let Some(halt) = interrupt.halt() {
                    return Err(FemError::Halted(halt));
                }
                let rows_here = 4 * nodes[0] * nodes[1];
                let mut lengths = Vec::with_capacity(rows_here);
                let mut indices = Vec::with_capacity(rows_here * 27 * 4);
                let mut data = Vec::with_capacity(rows_here * 27 * 4);
                // One vertex's blocks per neighbour (at most 27) and which entries an
                // element touched (the element triplets' structure), reused.
                let mut blocks: Vec<Block> = Vec::with_capacity(27);
                for y in 0..nodes[1] {
                    for x in 0..nodes[0] {
                        blocks.clear();
                        for (cz, oz) in owners(2, z).into_iter().flatten() {
                            for (cy, oy) in owners(1, y).into_iter().flatten() {
                                for (cx, ox) in owners(0, x).into_iter().flatten() {
                                    let a = ox + 2 * oy + 4 * oz;
                                    for b in 0..8 {
                                        let at = [cx + (b & 1), cy + ((b >> 1) & 1), cz + (b >> 2)];
                                        let l =
                                            mesh.index(std::array::from_fn(|i| at[i] % nodes[i]));
                                        let slot = match blocks.iter().position(|r| r.0 == l) {
                                            Some(slot) => slot,
                                            None => {
                                                blocks.push((l, [[0.0; 4]; 4], [[false; 4]; 4]));
                                                blocks.len() - 1
                                            }
                                        };
                                        let (_, block, touched) = &mut blocks[slot];
                                        for i in 0..4 {
                                            block[i][i] += sigma_t * gamma[i] * mass[a][b];
                                            touched[i][i] = true;
                                            for j in 0..4 {
                                                let v = streaming[a][b][i][j];
                                                if v != 0.0 {
                                                    block[i][j] += v;
                                                    touched[i][j] = true;
                                                }
                                            }
                                        }
                                    }
                                }
                            }
                        }
                        blocks.sort_unstable_by_key(|r| r.0);
                        for i in 0..4 {
                            let before = indices.len();
                            for (l, block, touched) in &blocks {
                                for j in 0..4 {
                                    if touched[i][j] {
                                        indices.push(4 * l + j);
                                        data.push(block[i][j]);
                                    }
                                }
                            }
                            lengths.push(indices.len() - before);
                        }
                    }
                }
                Ok((lengths, indices, data))
            })
            .collect();
        let n = mesh.len();
        let mut indptr = Vec::with_capacity(4 * n + 1);
        let (mut indices, mut data) = (Vec::new(), Vec::new());
        indptr.push(0);
        for layer in layers {
            let (lengths, layer_indices, layer_data) = layer?;
            for length in lengths {
                indptr.push(indptr[indptr.len() - 1] + length);
            }
            if indices.is_empty() {
                // The first layer's arrays, grown in place by the others.
                let total = layer_indices.len() * nodes[2];
                indices = layer_indices;
                data = layer_data;
                indices.reserve(total.saturating_sub(indices.len()));
                data.reserve(total.saturating_sub(data.len()));
            } else {
                indices.extend(layer_indices);
                data.extend(layer_data);
            }
        }
        let matrix = sprs::CsMat::try_new((4 * n, 4 * n), indptr, indices, data)
            .map_err(|(_, _, _, e)| FemError::Invalid(format!("Murray's matrix: {e}")))?;
        Ok(Self { mesh, matrix })
    }

    /// The same matrix as [`MurraySystem::assemble`] by the textbook route: every
    /// element's 8×8 blocks of 4×4 as triplets, summed and sorted into CSR at the end
    /// (the reference the row assembly is tested against; several times slower).
    pub fn assemble_by_elements(mesh: Mesh, sigma_t: f64) -> Result<Self, FemError> {
        mesh.check()?;
        if !(sigma_t >= 0.0 && sigma_t.is_finite()) {
            return Err(FemError::Invalid(format!("K_t = {sigma_t}: must be ≥ 0")));
        }
        let (mass, derivative) = element_matrices(mesh.spacing);
        let (alpha, gamma) = (alpha(), gamma());
        let n = mesh.len();
        let cells: [usize; 3] = std::array::from_fn(|a| {
            if mesh.periodic {
                mesh.nodes[a]
            } else {
                mesh.nodes[a] - 1
            }
        });
        let mut triplets = sprs::TriMat::with_capacity((4 * n, 4 * n), 4 * n * 27 * 4);
        for cz in 0..cells[2] {
            for cy in 0..cells[1] {
                for cx in 0..cells[0] {
                    let vertex = |a: usize| {
                        let at = [cx + (a & 1), cy + ((a >> 1) & 1), cz + ((a >> 2) & 1)];
                        mesh.index(std::array::from_fn(|i| at[i] % mesh.nodes[i]))
                    };
                    for a in 0..8 {
                        let k = vertex(a);
                        for b in 0..8 {
                            let l = vertex(b);
                            for i in 0..4 {
                                triplets.add_triplet(
                                    4 * k + i,
                                    4 * l + i,
                                    sigma_t * gamma[i] * mass[a][b],
                                );
                                for j in 0..4 {
                                    let streaming: f64 = (0..3)
                                        .map(|ax| alpha[i][j][ax] * derivative[ax][a][b])
                                        .sum();
                                    if streaming != 0.0 {
                                        triplets.add_triplet(4 * k + i, 4 * l + j, streaming);
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        Ok(Self {
            mesh,
            matrix: triplets.to_csr(),
        })
    }

    /// The right-hand side of an isotropic point source of strength `q` at vertex `at`:
    /// ∫ψ_0 ϕ_k Q_e = 4π q at that vertex.
    pub fn point_source(&self, at: [usize; 3], q: f64) -> Vec<f64> {
        let mut b = vec![0.0; self.matrix.rows()];
        b[4 * self.mesh.index(at)] = 4.0 * PI * q;
        b
    }

    /// The fluence φ = 4π L_0 at each vertex.
    pub fn fluence(&self, solution: &[f64]) -> Vec<f64> {
        solution.chunks(4).map(|l| 4.0 * PI * l[0]).collect()
    }

    /// The spectral radius of the Jacobi iteration matrix I − D⁻¹A, by power iteration
    /// (`iterations` steps, at least 2, from a fixed pseudo-random start; the geometric
    /// mean growth of the last half).
    pub fn jacobi_spectral_radius(&self, iterations: usize) -> f64 {
        let iterations = iterations.max(2);
        let a = &self.matrix;
        let n = a.rows();
        let diagonal: Vec<f64> = (0..n)
            .map(|i| a.get(i, i).copied().unwrap_or(1.0))
            .collect();
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut x: Vec<f64> = (0..n)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect();
        let mut ax = vec![0.0; n];
        let mut log_growth = 0.0;
        let half = iterations / 2;
        for it in 0..iterations {
            crate::operator::LinearOperator::apply(a, &x, &mut ax);
            for i in 0..n {
                x[i] -= ax[i] / diagonal[i];
            }
            let norm = crate::operator::norm(&x);
            if it >= half {
                log_growth += norm.ln();
            }
            for v in &mut x {
                *v /= norm;
            }
        }
        (log_growth / (iterations - half) as f64).exp()
    }
}
