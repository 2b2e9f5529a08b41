//! Q1 (trilinear) Galerkin finite elements for steady diffusion with heterogeneous
//! coefficients and a Robin boundary, solved by CG preconditioned with geometric multigrid
//! on the element hierarchy:
//!
//! ∫ D ∇φ·∇v + ∫ σ_a φ v + ∮ φ v / (2A) = ∫ Q v   for every trilinear v,
//!
//! the weak form of −∇·(D∇φ) + σ_a φ = Q with φ + 2AD ∂φ/∂n = 0 on the box (A = 1 is
//! vacuum, A → ∞ reflecting). D and σ_a are constant per element (a lucent grid's cells);
//! unknowns are the fluence at the cells' corners. The element matrices are tensor
//! products of the 1-D ones (stiffness (1/h)[[1, −1], [−1, 1]], mass (h/6)[[2, 1], [1, 2]]),
//! so assembly is exact. Second order in L2 for smooth solutions.
//!
//! Multigrid: vertex-centred, nested meshes (n cells become ⌈n/2⌉ per level down to at
//! most 1000 vertices; an odd axis ends in a coarse cell one fine cell wide, so the coarse
//! space stays inside the fine one), prolongation P = trilinear interpolation (exact for
//! nested Q1 spaces), restriction Pᵀ, Galerkin coarse operators PᵀAP (sparse products),
//! symmetric Gauss–Seidel V(ν, ν) cycles, the coarsest level by dense LU factored once: a
//! symmetric positive definite preconditioner, as CG needs.

use crate::error::FemError;
use crate::operator::LinearOperator;
use crate::solvers::{Convergence, DenseLu};
use lucent_core::Stopping;

/// A box of `cells` elements of side `spacing`, low corner `origin`, with D and σ_a per
/// element.
#[derive(Debug, Clone, PartialEq)]
pub struct Q1Problem {
    /// Elements per axis.
    pub cells: [usize; 3],
    /// Element side (length).
    pub spacing: f64,
    /// D per element (length), x fastest.
    pub diffusion: Vec<f64>,
    /// σ_a per element (1/length).
    pub absorption: Vec<f64>,
    /// Robin factor A ≥ 1 on each face of the box (low x, high x, low y, high y, low z,
    /// high z), or `None` for a reflecting face.
    pub robin: [Option<f64>; 6],
}

impl Q1Problem {
    /// Vertices per axis.
    pub fn nodes(&self) -> [usize; 3] {
        self.cells.map(|c| c + 1)
    }

    /// Index of vertex (i, j, k).
    pub fn node(&self, at: [usize; 3]) -> usize {
        let n = self.nodes();
        at[0] + n[0] * (at[1] + n[1] * at[2])
    }

    fn check(&self) -> Result<(), FemError> {
        let count: usize = self.cells.iter().product();
        let ok = self.cells.iter().all(|&c| c >= 1)
            && self.spacing > 0.0
            && self.spacing.is_finite()
            && self.diffusion.len() == count
            && self.absorption.len() == count
            && self.diffusion.iter().all(|d| *d > 0.0 && d.is_finite())
            && self.absorption.iter().all(|s| *s >= 0.0 && s.is_finite())
            && self
                .robin
                .iter()
                .all(|r| r.is_none_or(|a| a >= 1.0 && a.is_finite()));
        if ok {
            Ok(())
        } else {
            Err(FemError::Invalid(
                "Q1 problem: cells ≥ 1, spacing > 0, D > 0 and σ_a ≥ 0 per element, A ≥ 1".into(),
            ))
        }
    }

    /// The stiffness + mass + Robin matrix (CSR, symmetric positive definite), built row by
    /// row in parallel: a vertex's row holds its ≤ 27 neighbours (in index order), each
    /// entry summed over the ≤ 8 elements (and ≤ 3 Robin faces) the two vertices share.
    /// Equal to [`Q1Problem::assemble_by_triplets`] (tested) and far faster.
    pub fn assemble(&self) -> Result<sprs::CsMat<f64>, FemError> {
        use rayon::prelude::*;
        self.check()?;
        let h = self.spacing;
        let m1 = |a: usize, b: usize| if a == b { h / 3.0 } else { h / 6.0 };
        let (mass, stiffness) = element_matrices(h);
        let nodes = self.nodes();
        let cells = self.cells;
        let n: usize = nodes.iter().product();
        let rows: Vec<Vec<(usize, f64)>> = (0..n)
            .into_par_iter()
            .map(|v| {
                let at = [
                    v % nodes[0],
                    (v / nodes[0]) % nodes[1],
                    v / (nodes[0] * nodes[1]),
                ];
                let mut row = Vec::with_capacity(27);
                for dk in -1i64..=1 {
                    for dj in -1i64..=1 {
                        for di in -1i64..=1 {
                            let d = [di, dj, dk];
                            let w: [i64; 3] = std::array::from_fn(|a| at[a] as i64 + d[a]);
                            if (0..3).any(|a| w[a] < 0 || w[a] >= nodes[a] as i64) {
                                continue;
                            }
                            let mut value = 0.0;
                            // Elements with low corner e containing both: e_a ∈ {at_a − 1, at_a}
                            // ∩ {w_a − 1, w_a}, inside the box.
                            for ek in at[2].saturating_sub(1)..=at[2] {
                                for ej in at[1].saturating_sub(1)..=at[1] {
                                    for ei in at[0].saturating_sub(1)..=at[0] {
                                        let e = [ei, ej, ek];
                                        let inside = (0..3).all(|a| {
                                            e[a] < cells[a]
                                                && (w[a] - e[a] as i64) >= 0
                                                && (w[a] - e[a] as i64) <= 1
                                        });
                                        if !inside {
                                            continue;
                                        }
                                        let la = (at[0] - e[0])
                                            | ((at[1] - e[1]) << 1)
                                            | ((at[2] - e[2]) << 2);
                                        let lb = (w[0] as usize - e[0])
                                            | ((w[1] as usize - e[1]) << 1)
                                            | ((w[2] as usize - e[2]) << 2);
                                        let id = e[0] + cells[0] * (e[1] + cells[1] * e[2]);
                                        value += self.diffusion[id] * stiffness[la][lb]
                                            + self.absorption[id] * mass[la][lb];
                                    }
                                }
                            }
                            // Robin faces both lie on: ∮ over the shared boundary quads.
                            for axis in 0..3 {
                                for (high, side) in [0, cells[axis]].into_iter().enumerate() {
                                    let Some(a_factor) = self.robin[2 * axis + high] else {
                                        continue;
                                    };
                                    if at[axis] != side || w[axis] as usize != side {
                                        continue;
                                    }
                                    let (u, t) = ((axis + 1) % 3, (axis + 2) % 3);
                                    let mut face = 0.0;
                                    for fu in at[u].saturating_sub(1)..=at[u] {
                                        for ft in at[t].saturating_sub(1)..=at[t] {
                                            let ok = fu < cells[u]
                                                && ft < cells[t]
                                                && (0..=1).contains(&(w[u] - fu as i64))
                                                && (0..=1).contains(&(w[t] - ft as i64));
                                            if ok {
                                                face += m1(at[u] - fu, w[u] as usize - fu)
                                                    * m1(at[t] - ft, w[t] as usize - ft);
                                            }
                                        }
                                    }
                                    value += face / (2.0 * a_factor);
                                }
                            }
                            let col = w[0] as usize
                                + nodes[0] * (w[1] as usize + nodes[1] * w[2] as usize);
                            row.push((col, value));
                        }
                    }
                }
                row
            })
            .collect();
        let mut indptr = Vec::with_capacity(n + 1);
        indptr.push(0);
        let (mut indices, mut data) = (Vec::new(), Vec::new());
        for row in rows {
            for (c, v) in row {
                indices.push(c);
                data.push(v);
            }
            indptr.push(indices.len());
        }
        Ok(sprs::CsMat::new((n, n), indptr, indices, data))
    }

    /// The same matrix through element-by-element triplets (the reference the fast
    /// assembly is tested against).
    pub fn assemble_by_triplets(&self) -> Result<sprs::CsMat<f64>, FemError> {
        self.check()?;
        let h = self.spacing;
        let m1 = |a: usize, b: usize| if a == b { h / 3.0 } else { h / 6.0 };
        let bits = |a: usize| [a & 1, (a >> 1) & 1, (a >> 2) & 1];
        let (mass, stiffness) = element_matrices(h);
        let nodes = self.nodes();
        let n: usize = nodes.iter().product();
        let [cx, cy, cz] = self.cells;
        let mut t = sprs::TriMat::with_capacity((n, n), 64 * cx * cy * cz);
        for k in 0..cz {
            for j in 0..cy {
                for i in 0..cx {
                    let e = i + cx * (j + cy * k);
                    let (d, sa) = (self.diffusion[e], self.absorption[e]);
                    let vertex = |a: usize| {
                        let p = bits(a);
                        self.node([i + p[0], j + p[1], k + p[2]])
                    };
                    for a in 0..8 {
                        for b in 0..8 {
                            t.add_triplet(
                                vertex(a),
                                vertex(b),
                                d * stiffness[a][b] + sa * mass[a][b],
                            );
                        }
                    }
                }
            }
        }
        // ∮ φ v /(2A) on each Robin face: the 2-D mass of every boundary quad.
        for axis in 0..3 {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            for (high, side) in [0, self.cells[axis]].into_iter().enumerate() {
                let Some(a_factor) = self.robin[2 * axis + high] else {
                    continue;
                };
                let w = 1.0 / (2.0 * a_factor);
                {
                    for fu in 0..self.cells[u] {
                        for fv in 0..self.cells[v] {
                            for a in 0..4 {
                                for b in 0..4 {
                                    let corner = |c: usize| {
                                        let mut at = [0; 3];
                                        at[axis] = side;
                                        at[u] = fu + (c & 1);
                                        at[v] = fv + (c >> 1);
                                        self.node(at)
                                    };
                                    let value = w * m1(a & 1, b & 1) * m1(a >> 1, b >> 1);
                                    t.add_triplet(corner(a), corner(b), value);
                                }
                            }
                        }
                    }
                }
            }
        }
        Ok(t.to_csr())
    }

    /// ∫Q v for a volumetric source density `q(x)` (x relative to the box's low corner), by
    /// 2×2×2-point Gauss quadrature per element.
    pub fn load(&self, q: impl Fn([f64; 3]) -> f64) -> Vec<f64> {
        let nodes = self.nodes();
        let mut b = vec![0.0; nodes.iter().product()];
        let h = self.spacing;
        let g = 0.5 / 3f64.sqrt();
        let points = [0.5 - g, 0.5 + g];
        let [cx, cy, cz] = self.cells;
        for k in 0..cz {
            for j in 0..cy {
                for i in 0..cx {
                    for &pz in &points {
                        for &py in &points {
                            for &px in &points {
                                let x = [
                                    (i as f64 + px) * h,
                                    (j as f64 + py) * h,
                                    (k as f64 + pz) * h,
                                ];
                                let value = q(x) * h * h * h / 8.0;
                                for c in 0..8 {
                                    let p = [c & 1, (c >> 1) & 1, (c >> 2) & 1];
                                    let f = [px, py, pz];
                                    let w: f64 = (0..3)
                                        .map(|a| if p[a] == 1 { f[a] } else { 1.0 - f[a] })
                                        .product();
                                    b[self.node([i + p[0], j + p[1], k + p[2]])] += value * w;
                                }
                            }
                        }
                    }
                }
            }
        }
        b
    }

    /// ∫Q₀ v + ∫ 3D Q₁·∇v for volumetric sources given per element: Q₀ (power/volume)
    /// lumped to the 8 corners, and the first moment Q₁ (empty or one per element), whose
    /// weak-form term over a cube is ±h²/4 per axis times 3D Q₁ (its boundary terms cancel
    /// against the Robin condition's).
    pub fn cell_load(&self, q0: &[f64], moment: &[[f32; 3]]) -> Vec<f64> {
        let mut b = vec![0.0; self.nodes().iter().product()];
        let h = self.spacing;
        let (volume, hh) = (h * h * h, h * h / 4.0);
        let [nx, ny, _] = self.cells;
        for (cell, q) in q0.iter().enumerate() {
            let (i, j, k) = (cell % nx, (cell / nx) % ny, cell / (nx * ny));
            for corner in 0..8 {
                let o = [corner & 1, (corner >> 1) & 1, corner >> 2];
                let node = self.node([i + o[0], j + o[1], k + o[2]]);
                b[node] += q * volume / 8.0;
                if let Some(first) = moment.get(cell) {
                    let grad: f64 = (0..3)
                        .map(|a| {
                            let v = f64::from(first[a]);
                            if o[a] == 1 { v } else { -v }
                        })
                        .sum();
                    b[node] += 3.0 * self.diffusion[cell] * grad * hh;
                }
            }
        }
        b
    }

    /// Adds ∫ f v over element `cell` to `b`, by 3×3×3 Gauss points: for a source that
    /// varies within an element (a point source's smooth remainder near its cut-off),
    /// which lumping would blur. `f` takes coordinates relative to the box's low corner.
    pub fn add_element_source(&self, b: &mut [f64], cell: usize, f: impl Fn([f64; 3]) -> f64) {
        let rule = [
            (0.5 - 0.5 * 0.6f64.sqrt(), 5.0 / 18.0),
            (0.5, 8.0 / 18.0),
            (0.5 + 0.5 * 0.6f64.sqrt(), 5.0 / 18.0),
        ];
        let h = self.spacing;
        let [nx, ny, _] = self.cells;
        let at = [cell % nx, (cell / nx) % ny, cell / (nx * ny)];
        for (x, wx) in rule {
            for (y, wy) in rule {
                for (z, wz) in rule {
                    let t = [x, y, z];
                    let value = f(std::array::from_fn(|a| (at[a] as f64 + t[a]) * h))
                        * wx
                        * wy
                        * wz
                        * h
                        * h
                        * h;
                    for corner in 0..8usize {
                        let o = [corner & 1, (corner >> 1) & 1, corner >> 2];
                        let shape: f64 = (0..3)
                            .map(|a| if o[a] == 1 { t[a] } else { 1.0 - t[a] })
                            .product();
                        b[self.node([at[0] + o[0], at[1] + o[1], at[2] + o[2]])] += value * shape;
                    }
                }
            }
        }
    }

    /// The mean of each element's 8 corner values of the nodal field `x`: its cell value.
    pub fn cell_means(&self, x: &[f64]) -> Vec<f64> {
        let [nx, ny, nz] = self.cells;
        (0..nx * ny * nz)
            .map(|cell| {
                let (i, j, k) = (cell % nx, (cell / nx) % ny, cell / (nx * ny));
                (0..8)
                    .map(|c| x[self.node([i + (c & 1), j + ((c >> 1) & 1), k + (c >> 2)])])
                    .sum::<f64>()
                    / 8.0
            })
            .collect()
    }

    /// ∫Q v for a point source of power `power` at `x` (trilinear weights on its element's
    /// vertices), coordinates relative to the box's low corner.
    pub fn point_source(&self, x: [f64; 3], power: f64) -> Result<Vec<f64>, FemError> {
        let nodes = self.nodes();
        let mut b = vec![0.0; nodes.iter().product()];
        let v: [f64; 3] = std::array::from_fn(|a| x[a] / self.spacing);
        if (0..3).any(|a| !(v[a] >= 0.0 && v[a] <= self.cells[a] as f64)) {
            return Err(FemError::Invalid(format!(
                "point source at {x:?} is outside the box"
            )));
        }
        let base: [usize; 3] =
            std::array::from_fn(|a| (v[a].floor() as usize).min(self.cells[a] - 1));
        let f: [f64; 3] = std::array::from_fn(|a| v[a] - base[a] as f64);
        for c in 0..8 {
            let p = [c & 1, (c >> 1) & 1, (c >> 2) & 1];
            let w: f64 = (0..3)
                .map(|a| if p[a] == 1 { f[a] } else { 1.0 - f[a] })
                .product();
            b[self.node([base[0] + p[0], base[1] + p[1], base[2] + p[2]])] += power * w;
        }
        Ok(b)
    }
}

/// The trilinear element's mass ∫ϕ_aϕ_b and stiffness ∫∇ϕ_a·∇ϕ_b on a cube of side h,
/// local vertex a = a₀ + 2a₁ + 4a₂: tensor products of the 1-D (h/6)[[2, 1], [1, 2]] and
/// (1/h)[[1, −1], [−1, 1]].
fn element_matrices(h: f64) -> ([[f64; 8]; 8], [[f64; 8]; 8]) {
    let m1 = |a: usize, b: usize| if a == b { h / 3.0 } else { h / 6.0 };
    let s1 = |a: usize, b: usize| if a == b { 1.0 / h } else { -1.0 / h };
    let bits = |a: usize| [a & 1, (a >> 1) & 1, (a >> 2) & 1];
    let mut mass = [[0.0; 8]; 8];
    let mut stiffness = [[0.0; 8]; 8];
    for a in 0..8 {
        for b in 0..8 {
            let (pa, pb) = (bits(a), bits(b));
            mass[a][b] = (0..3).map(|i| m1(pa[i], pb[i])).product();
            stiffness[a][b] = (0..3)
                .map(|axis| {
                    (0..3)
                        .map(|i| {
                            if i == axis {
                                s1(pa[i], pb[i])
                            } else {
                                m1(pa[i], pb[i])
                            }
                        })
                        .product::<f64>()
                })
                .sum();
        }
    }
    (mass, stiffness)
}

/// The coarse lattice of `fine` cells per axis: ⌈n/2⌉ cells whose vertices are the fine
/// vertices 0, 2, 4, … and the last one, n. An odd axis ends in a coarse cell one fine
/// cell wide, so every coarse cell is a union of fine cells and the coarse trilinear space
/// lies inside the fine one (nested: the Galerkin operator is exact on any lattice).
fn coarsened(fine: [usize; 3]) -> [usize; 3] {
    fine.map(|n| n.div_ceil(2))
}

/// Trilinear prolongation from the vertices of [`coarsened`]`(fine)` to those of `fine`
/// cells per axis.
fn prolongation(fine: [usize; 3]) -> sprs::CsMat<f64> {
    let coarse = coarsened(fine);
    let cn = coarse.map(|c| c + 1);
    let fv = fine.map(|c| c + 1);
    let nf: usize = fv.iter().product();
    let nc: usize = cn.iter().product();
    // Per axis and fine vertex: the coarse vertices it interpolates and their weights. An
    // even fine index (and the last vertex of an odd axis) sits on a coarse vertex, an odd
    // one halfway between two.
    let weights: [Vec<[(usize, f64); 2]>; 3] = std::array::from_fn(|a| {
        (0..fv[a])
            .map(|f| {
                if f == fine[a] {
                    [(coarse[a], 1.0), (coarse[a], 0.0)]
                } else if f % 2 == 0 {
                    [(f / 2, 1.0), (f / 2, 0.0)]
                } else {
                    [(f / 2, 0.5), (f / 2 + 1, 0.5)]
                }
            })
            .collect()
    });
    let mut t = sprs::TriMat::with_capacity((nf, nc), 8 * nf);
    for k in 0..fv[2] {
        for j in 0..fv[1] {
            for i in 0..fv[0] {
                let row = i + fv[0] * (j + fv[1] * k);
                for &(x, wx) in &weights[0][i] {
                    for &(y, wy) in &weights[1][j] {
                        for &(z, wz) in &weights[2][k] {
                            let w = wx * wy * wz;
                            if w != 0.0 {
                                t.add_triplet(row, x + cn[0] * (y + cn[1] * z), w);
                            }
                        }
                    }
                }
            }
        }
    }
    t.to_csr()
}

/// The Q1 multigrid hierarchy: operators from fine to coarse and the prolongations.
#[derive(Debug, Clone)]
pub struct Q1Multigrid {
    operators: Vec<sprs::CsMat<f64>>,
    prolongations: Vec<sprs::CsMat<f64>>,
    /// The coarsest operator's LU factors, computed once (`None` if it is singular to
    /// working precision: the coarsest level is then smoothed instead).
    coarsest: Option<DenseLu>,
    sweeps: usize,
}

impl Q1Multigrid {
    /// Builds the hierarchy of `problem`'s matrix `a` (Galerkin coarse operators) down to a
    /// level of at most 1000 vertices; odd axes coarsen too (a last coarse cell one fine
    /// cell wide).
    pub fn new(problem: &Q1Problem, a: sprs::CsMat<f64>, sweeps: usize) -> Self {
        Self::for_lattice(problem.cells, a, sweeps)
    }

    /// The hierarchy of a matrix on the vertices of a lattice of `cells` elements per axis
    /// (vertex (i, j, k) at index i + (n_x + 1)(j + (n_y + 1) k)), whatever the elements'
    /// shapes: prolongation is trilinear in the lattice's coordinates (exact for nested
    /// meshes, a good preconditioner for mapped ones).
    pub fn for_lattice(cells: [usize; 3], a: sprs::CsMat<f64>, sweeps: usize) -> Self {
        match Self::build(cells, a, sweeps, || Ok::<(), std::convert::Infallible>(())) {
            Ok(mg) => mg,
            Err(never) => match never {},
        }
    }

    /// [`Q1Multigrid::for_lattice`], asking `interrupt` before every level's Galerkin
    /// product (the finest, about 7/8 of the work, is one sparse product that cannot be
    /// stopped part way).
    pub fn for_lattice_within(
        cells: [usize; 3],
        a: sprs::CsMat<f64>,
        sweeps: usize,
        interrupt: &lucent_core::Interrupt,
    ) -> Result<Self, lucent_core::Halt> {
        Self::build(cells, a, sweeps, || interrupt.halt().map_or(Ok(()), Err))
    }

    /// The hierarchy, `check` asked before every level.
    fn build<E>(
        cells: [usize; 3],
        a: sprs::CsMat<f64>,
        sweeps: usize,
        mut check: impl FnMut() -> Result<(), E>,
    ) -> Result<Self, E> {
        let mut operators = vec![a];
        let mut prolongations = Vec::new();
        let mut cells = cells;
        // Halve (odd axes too, see `coarsened`) while an axis has two cells or more.
        while operators[operators.len() - 1].rows() > 1000 && cells.iter().any(|&c| c >= 2) {
            check()?;
            let coarse = coarsened(cells);
            let p = prolongation(cells);
            let pt = p.transpose_view().to_csr();
            let fine = &operators[operators.len() - 1];
            let ap = fine * &p;
            let ac = &pt * &ap;
            operators.push(ac.to_csr());
            prolongations.push(p);
            cells = coarse;
        }
        check()?;
        let coarsest = DenseLu::factor(&operators[operators.len() - 1]).ok();
        Ok(Self {
            operators,
            prolongations,
            coarsest,
            sweeps: sweeps.max(1),
        })
    }

    /// Levels.
    pub fn depth(&self) -> usize {
        self.operators.len()
    }

    fn smooth(a: &sprs::CsMat<f64>, b: &[f64], x: &mut [f64], forward: bool) {
        let n = a.rows();
        let mut sweep = |i: usize| {
            if let Some(row) = a.outer_view(i) {
                let (mut off, mut diag) = (0.0, 0.0);
                for (j, v) in row.iter() {
                    if j == i {
                        diag = *v;
                    } else {
                        off += v * x[j];
                    }
                }
                if diag != 0.0 {
                    x[i] = (b[i] - off) / diag;
                }
            }
        };
        if forward {
            (0..n).for_each(&mut sweep);
        } else {
            (0..n).rev().for_each(&mut sweep);
        }
    }

    fn cycle(&self, level: usize, b: &[f64], x: &mut [f64]) {
        let a = &self.operators[level];
        if level + 1 == self.operators.len() {
            match &self.coarsest {
                Some(lu) => x.copy_from_slice(&lu.solve(b)),
                None => {
                    for _ in 0..50 {
                        Self::smooth(a, b, x, true);
                        Self::smooth(a, b, x, false);
                    }
                }
            }
            return;
        }
        for _ in 0..self.sweeps {
            Self::smooth(a, b, x, true);
        }
        let mut r = vec![0.0; b.len()];
        a.apply(x, &mut r);
        for (r, b) in r.iter_mut().zip(b) {
            *r = b - *r;
        }
        let p = &self.prolongations[level];
        let nc = p.cols();
        let mut rc = vec![0.0; nc];
        for (i, row) in p.outer_iterator().enumerate() {
            for (j, w) in row.iter() {
                rc[j] += w * r[i];
            }
        }
        let mut ec = vec![0.0; nc];
        self.cycle(level + 1, &rc, &mut ec);
        let mut e = vec![0.0; b.len()];
        p.apply(&ec, &mut e);
        for (x, e) in x.iter_mut().zip(&e) {
            *x += e;
        }
        for _ in 0..self.sweeps {
            Self::smooth(a, b, x, false);
        }
    }

    /// CG on level 0 preconditioned by one V-cycle per iteration, from `x` (an error if
    /// the sizes of `b` and `x` are not the finest level's).
    pub fn solve(
        &self,
        b: &[f64],
        x: &mut [f64],
        stopping: &Stopping,
    ) -> Result<Convergence, FemError> {
        crate::solvers::conjugate_gradient(&self.operators[0], b, x, stopping, |r, z| {
            self.cycle(0, r, z)
        })
    }
}
