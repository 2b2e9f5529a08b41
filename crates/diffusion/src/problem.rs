//! The discrete diffusion problem: cut-cell geometry, coefficients, boundary conditions and
//! sources, assembled into the operator's finest level and a right-hand side; and the
//! energy balance of a solution.
//!
//! Flux form, with E = −D∇φ + 3D Q₁ the diffuse flux (docs/reference-cases.md, sign derived, not the
//! thesis's): ∇·E + σ_a φ = Q₀. Integrated over cell i (volume fraction κ_i, volume V):
//!
//! Σ_f c_f (φ_i − φ_j) + Σ_p F_p + σ_a κ_i V φ_i = κ_i V Q₀ − Σ_f 3 D_f α_f A_f (Q₁·n_f)
//!
//! with F_p the outward flux through boundary patch p (area a, distance δ from the cell's
//! centroid, normal n, q = Q₁·n), from a linear profile along the normal:
//! - Robin φ + 2AD ∂φ/∂n = 6AD q (the P1 partial-current condition with its first-moment
//!   term): F = a (D φ_i + 3Dδ q)/(δ + 2AD);
//! - Dirichlet φ = g: F = a D (φ_i − g)/δ + 3 D a q;
//! - Neumann: F = a j for a given outward flux j.
//!
//! Every term is a flux through a shared face or a boundary patch, so Σ_i of the equations
//! is the global balance: emitted = absorbed + escaped, exactly for the discrete solution.

use glam::DVec3;

use crate::error::DiffusionError;
use crate::geometry::{CellGeometry, Side, face_indices};
use crate::level::Level;
use crate::region::Region;

/// A boundary condition.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Condition {
    /// φ + 2AD ∂φ/∂n = 0 (plus the first-moment source term) with boundary factor A ≥ 1.
    Robin {
        /// The boundary factor A (1 index-matched; see `lucent_core::Boundary::robin_factor`).
        a: f64,
    },
    /// φ = `value` on the boundary.
    Dirichlet {
        /// Fluence on the boundary (W/length²).
        value: f64,
    },
    /// Outward normal flux `flux` (0: reflecting).
    Neumann {
        /// Outward flux (W/length²).
        flux: f64,
    },
}

/// The condition on every part of the boundary: the embedded surface and the six box faces
/// (−x, +x, −y, +y, −z, +z).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Boundaries {
    /// On the embedded surface.
    pub surface: Condition,
    /// On the faces of the grid's box where the medium reaches them.
    pub faces: [Condition; 6],
}

impl Boundaries {
    /// The same condition everywhere.
    pub fn uniform(condition: Condition) -> Self {
        Self {
            surface: condition,
            faces: [condition; 6],
        }
    }

    /// `Ok` if every condition is usable: Robin factors A ≥ 1, finite values.
    pub fn check(&self) -> Result<(), DiffusionError> {
        let mut conditions = vec![self.surface];
        conditions.extend(self.faces);
        for c in conditions {
            let ok = match c {
                Condition::Robin { a } => a.is_finite() && a >= 1.0,
                Condition::Dirichlet { value } => value.is_finite(),
                Condition::Neumann { flux } => flux.is_finite(),
            };
            if !ok {
                return Err(DiffusionError::Invalid(format!(
                    "boundary condition {c:?}: A ≥ 1 and finite values"
                )));
            }
        }
        Ok(())
    }

    /// The condition on `side`.
    pub fn on(&self, side: Side) -> Condition {
        match side {
            Side::Surface => self.surface,
            Side::Box(f) => self.faces[f],
        }
    }
}

/// What is emitted inside the medium.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Sources {
    /// Isotropic source density Q₀ per cell (power/length³), over the medium part of each
    /// cell. Empty: none.
    pub volumetric: Vec<f32>,
    /// First moment Q₁ per cell (power/length³), the directional part of single-scattered
    /// light. Empty: none.
    pub first_moment: Vec<[f32; 3]>,
    /// Isotropic point sources: position and power (W), shared among the eight nearest
    /// cells by trilinear weights (which keeps the source's centroid on the grid).
    pub points: Vec<(DVec3, f64)>,
}

/// A patch of the boundary as the operator sees it on one level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LevelPatch {
    pub(crate) cell: usize,
    pub(crate) area: f64,
    pub(crate) distance: f64,
    pub(crate) normal: DVec3,
    pub(crate) diffusion: f64,
    pub(crate) side: Side,
    /// The cell's width along the normal, Σ|n_a| h_a.
    pub(crate) width: f64,
}

/// The diffusion coefficient of the face between cells of coefficients `a` and `b`: their
/// harmonic mean (0 where either is not positive), so a face's flux is that of the two
/// half-cells in series.
pub(crate) fn face_diffusion(a: f32, b: f32) -> f64 {
    let (da, db) = (f64::from(a), f64::from(b));
    if da <= 0.0 || db <= 0.0 {
        return 0.0;
    }
    2.0 * da * db / (da + db)
}

impl LevelPatch {
    /// The finest level's patch for geometry patch `p` of a cell whose D is `d`, on cells
    /// of size `h`.
    pub(crate) fn fine(p: &crate::geometry::Patch, d: f32, h: DVec3) -> Self {
        Self {
            cell: p.cell,
            area: p.area,
            distance: p.distance,
            normal: p.normal,
            diffusion: f64::from(d),
            side: p.side,
            width: p.normal.abs().dot(h),
        }
    }

    /// The distance used for a Dirichlet value: the cell's unknown may sit outside the
    /// medium (negative distance), where extrapolating to a fixed value would make the
    /// coupling negative; it is kept at least a quarter of the cell's width.
    fn dirichlet_distance(&self) -> f64 {
        self.distance.max(0.25 * self.width)
    }

    /// δ + 2AD for a Robin patch, kept at least AD: an unknown outside the medium by more
    /// than AD (a cell much wider than the diffusion length) would otherwise extrapolate
    /// past the extrapolated boundary.
    fn robin_reach(&self, a: f64) -> f64 {
        let d = self.diffusion;
        (self.distance + 2.0 * a * d).max(a * d)
    }

    /// Coupling of the patch to its cell's value: the diagonal term.
    pub(crate) fn coupling(&self, condition: Condition) -> f64 {
        let d = self.diffusion;
        match condition {
            Condition::Robin { a } => self.area * d / self.robin_reach(a),
            Condition::Dirichlet { .. } => self.area * d / self.dirichlet_distance(),
            Condition::Neumann { .. } => 0.0,
        }
    }

    /// The part of the outward flux that does not depend on φ (boundary data and the
    /// first-moment term q = Q₁·n): it moves to the right-hand side with a minus sign.
    pub(crate) fn data_flux(&self, condition: Condition, q: f64) -> f64 {
        let d = self.diffusion;
        match condition {
            Condition::Robin { a } => {
                self.area * 3.0 * d * (self.robin_reach(a) - 2.0 * a * d) * q / self.robin_reach(a)
            }
            Condition::Dirichlet { value } => {
                -self.area * d * value / self.dirichlet_distance() + 3.0 * d * self.area * q
            }
            Condition::Neumann { flux } => self.area * flux,
        }
    }

    /// Outward power through the patch for cell value φ.
    fn flux(&self, condition: Condition, phi: f64, q: f64) -> f64 {
        self.coupling(condition) * phi + self.data_flux(condition, q)
    }
}

/// One level's operator with what coarsening needs.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LevelData {
    pub(crate) level: Level,
    /// σ_a κ V per cell.
    pub(crate) absorption: Vec<f32>,
    pub(crate) patches: Vec<LevelPatch>,
}

/// [`DiffusionProblem::assemble`]'s result: A φ = b over the cells of the medium.
#[derive(Debug, Clone, PartialEq)]
pub struct AssembledSystem {
    /// The operator, compressed sparse rows.
    pub matrix: sprs::CsMat<f64>,
    /// The right-hand side.
    pub rhs: Vec<f64>,
    /// The grid cell of each unknown.
    pub cells: Vec<usize>,
}

/// A steady diffusion problem on a cut-cell grid.
#[derive(Debug, Clone, PartialEq)]
pub struct DiffusionProblem {
    cells: CellGeometry,
    diffusion: Vec<f32>,
    absorption: Vec<f32>,
    boundaries: Boundaries,
}

impl DiffusionProblem {
    /// A problem with diffusion coefficient D (length) and absorption σ_a (1/length) per
    /// cell. D must be finite and positive and σ_a finite and ≥ 0 in every cell of the
    /// medium; Robin factors ≥ 1, Dirichlet distances positive, all values finite. Without
    /// absorption the boundary must hold the fluence somewhere (Robin or Dirichlet), or the
    /// problem has no unique solution.
    pub fn new(
        cells: CellGeometry,
        diffusion: Vec<f32>,
        absorption: Vec<f32>,
        boundaries: Boundaries,
    ) -> Result<Self, DiffusionError> {
        let n = cells.geometry().voxel_count();
        if diffusion.len() != n || absorption.len() != n {
            return Err(DiffusionError::Invalid(format!(
                "{} cells but {} diffusion and {} absorption values",
                n,
                diffusion.len(),
                absorption.len()
            )));
        }
        for c in 0..n {
            if !cells.is_active(c) {
                continue;
            }
            let (d, s) = (diffusion[c], absorption[c]);
            if !(d.is_finite() && d > 0.0) {
                return Err(DiffusionError::Invalid(format!(
                    "diffusion coefficient {d} in cell {c}: it must be finite and positive"
                )));
            }
            if !(s.is_finite() && s >= 0.0) {
                return Err(DiffusionError::Invalid(format!(
                    "absorption {s} in cell {c}: it must be finite and ≥ 0"
                )));
            }
        }
        boundaries.check()?;
        let absorbs = (0..n).any(|c| cells.is_active(c) && absorption[c] > 0.0);
        let holds = cells
            .patches()
            .iter()
            .any(|p| !matches!(boundaries.on(p.side), Condition::Neumann { .. }) && p.area > 0.0);
        if !absorbs && !holds {
            return Err(DiffusionError::Singular);
        }
        if !(0..n).any(|c| cells.is_active(c)) {
            return Err(DiffusionError::Invalid(
                "no cell of the grid is inside the medium".into(),
            ));
        }
        Ok(Self {
            cells,
            diffusion,
            absorption,
            boundaries,
        })
    }

    /// The cut-cell geometry.
    pub fn cells(&self) -> &CellGeometry {
        &self.cells
    }

    /// D per cell.
    pub fn diffusion(&self) -> &[f32] {
        &self.diffusion
    }

    /// σ_a per cell.
    pub fn absorption(&self) -> &[f32] {
        &self.absorption
    }

    /// The boundary conditions.
    pub fn boundaries(&self) -> &Boundaries {
        &self.boundaries
    }

    fn face_diffusion(&self, a: usize, b: usize) -> f64 {
        face_diffusion(self.diffusion[a], self.diffusion[b])
    }

    fn fine_patches(&self) -> Vec<LevelPatch> {
        let h = self.cells.geometry().spacing();
        self.cells
            .patches()
            .iter()
            .map(|p| LevelPatch::fine(p, self.diffusion[p.cell], h))
            .collect()
    }

    /// Calls `f(cell, lower neighbour, axis, open area)` for every interior face with a
    /// non-zero aperture.
    fn open_faces(&self, mut f: impl FnMut(usize, usize, usize, f64)) {
        let g = self.cells.geometry();
        let dims = g.dims();
        let [nx, ny, nz] = dims;
        let h = g.spacing();
        let strides = [1, nx, nx * ny];
        let face_area = [h.y * h.z, h.x * h.z, h.x * h.y];
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let c = g.index(i, j, k);
                    let at = [i, j, k];
                    let faces = face_indices(dims, i, j, k);
                    for axis in 0..3 {
                        let alpha = f64::from(self.cells.apertures(axis)[faces[axis][0]]);
                        if at[axis] > 0 && alpha > 0.0 {
                            f(c, c - strides[axis], axis, alpha * face_area[axis]);
                        }
                    }
                }
            }
        }
    }

    fn first_moment_along(&self, sources: &Sources, p: &LevelPatch) -> f64 {
        if sources.first_moment.is_empty() {
            0.0
        } else {
            DVec3::from(sources.first_moment[p.cell].map(f64::from)).dot(p.normal)
        }
    }

    /// The finest level: face couplings, absorption and patches.
    pub(crate) fn fine_level(&self) -> LevelData {
        let g = *self.cells.geometry();
        let dims = g.dims();
        let h = g.spacing();
        let n = g.voxel_count();
        let mut couplings = [vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]];
        // Unknowns sit at cell centres, so every face flux spans exactly h.
        self.open_faces(|c, other, axis, area| {
            couplings[axis][c] = (area * self.face_diffusion(c, other) / h[axis]) as f32;
        });
        let volume = g.cell_volume();
        let absorption: Vec<f32> = (0..n)
            .map(|c| {
                f64::from(self.absorption[c]) * f64::from(self.cells.volume_fraction()[c]) * volume
            })
            .map(|v| v as f32)
            .collect();
        let patches = self.fine_patches();
        finish_level(dims, h, couplings, absorption, patches, &self.boundaries)
    }

    /// The operator as a sparse matrix over the cells of the medium, with the right-hand
    /// side for `sources`: the system the matrix-free solvers solve, for other solvers
    /// (scipy, pyamg) to solve too. Symmetric positive definite; entries in the integrated
    /// form (length units of D·h). `cells[u]` is the grid cell of unknown `u`.
    pub fn assemble(&self, sources: &Sources) -> Result<AssembledSystem, DiffusionError> {
        let level = self.fine_level().level;
        let rhs = self.rhs(sources)?;
        let n = level.len();
        let cells: Vec<usize> = (0..n).filter(|&c| level.inv_diag[c] != 0.0).collect();
        let mut unknown = vec![usize::MAX; n];
        for (u, &c) in cells.iter().enumerate() {
            unknown[c] = u;
        }
        let [nx, ny, _] = level.dims;
        let strides = [1, nx, nx * ny];
        let mut triplets = sprs::TriMat::with_capacity((cells.len(), cells.len()), 7 * cells.len());
        for (u, &c) in cells.iter().enumerate() {
            let at = [c % nx, (c / nx) % ny, c / (nx * ny)];
            let mut diagonal = f64::from(level.extra[c]);
            for axis in 0..3 {
                let faces = [
                    (at[axis] > 0).then(|| (level.couplings[axis][c], c - strides[axis])),
                    (at[axis] + 1 < level.dims[axis]).then(|| {
                        let other = c + strides[axis];
                        (level.couplings[axis][other], other)
                    }),
                ];
                for (coupling, other) in faces.into_iter().flatten() {
                    if coupling > 0.0 && unknown[other] != usize::MAX {
                        diagonal += f64::from(coupling);
                        triplets.add_triplet(u, unknown[other], -f64::from(coupling));
                    }
                }
            }
            triplets.add_triplet(u, u, diagonal);
        }
        Ok(AssembledSystem {
            matrix: triplets.to_csr(),
            rhs: cells.iter().map(|&c| rhs[c]).collect(),
            cells,
        })
    }

    /// The right-hand side of the integrated equations for `sources`, with the boundary
    /// data (Dirichlet values, Neumann fluxes, first-moment terms).
    pub fn rhs(&self, sources: &Sources) -> Result<Vec<f64>, DiffusionError> {
        let g = *self.cells.geometry();
        let n = g.voxel_count();
        let volume = g.cell_volume();
        let kappa = self.cells.volume_fraction();
        for (name, len) in [
            ("volumetric", sources.volumetric.len()),
            ("first_moment", sources.first_moment.len()),
        ] {
            if len != 0 && len != n {
                return Err(DiffusionError::Invalid(format!(
                    "{name} source has {len} values for {n} cells"
                )));
            }
        }
        let mut b = vec![0.0f64; n];
        for (c, q) in sources.volumetric.iter().enumerate() {
            if !q.is_finite() {
                return Err(DiffusionError::Invalid(format!("source {q} in cell {c}")));
            }
            b[c] += f64::from(*q) * f64::from(kappa[c]) * volume;
        }
        if !sources.first_moment.is_empty() {
            if sources
                .first_moment
                .iter()
                .flatten()
                .any(|v| !v.is_finite())
            {
                return Err(DiffusionError::Invalid("non-finite first moment".into()));
            }
            let q1 = |c: usize| DVec3::from(sources.first_moment[c].map(f64::from));
            self.open_faces(|c, other, axis, area| {
                // Flux 3 D_f Q₁·ê through the face from `other` into `c`.
                let q = 0.5 * (q1(c)[axis] + q1(other)[axis]);
                let flux = 3.0 * self.face_diffusion(c, other) * area * q;
                b[other] -= flux;
                b[c] += flux;
            });
        }
        for p in self.fine_patches() {
            let q = self.first_moment_along(sources, &p);
            b[p.cell] -= p.data_flux(self.boundaries.on(p.side), q);
        }
        for &(position, power) in &sources.points {
            if !(position.is_finite() && power.is_finite()) {
                return Err(DiffusionError::Invalid(format!(
                    "point source {power} W at {position}"
                )));
            }
            let weights = point_weights(self, position);
            if weights.is_empty() {
                return Err(DiffusionError::Invalid(format!(
                    "point source at {position} is outside the medium"
                )));
            }
            for (c, w) in weights {
                b[c] += power * w;
            }
        }
        Ok(b)
    }

    /// Emitted, absorbed and escaped power of a solution φ for `sources` (escaped per side).
    pub fn balance(&self, sources: &Sources, fluence: &[f64]) -> Balance {
        let g = *self.cells.geometry();
        let volume = g.cell_volume();
        let kappa = self.cells.volume_fraction();
        let mut emitted: f64 = sources
            .volumetric
            .iter()
            .zip(kappa)
            .map(|(q, k)| f64::from(*q) * f64::from(*k) * volume)
            .sum();
        emitted += sources.points.iter().map(|p| p.1).sum::<f64>();
        let absorbed: f64 = fluence
            .iter()
            .enumerate()
            .map(|(c, phi)| f64::from(self.absorption[c]) * f64::from(kappa[c]) * volume * phi)
            .sum();
        let mut surface = 0.0;
        let mut faces = 0.0;
        for (p, flux) in self
            .cells
            .patches()
            .iter()
            .zip(self.patch_fluxes(sources, fluence))
        {
            match p.side {
                Side::Surface => surface += flux,
                Side::Box(_) => faces += flux,
            }
        }
        Balance {
            emitted,
            absorbed,
            escaped_surface: surface,
            escaped_box: faces,
        }
    }

    /// Outward power through each boundary patch (in the order of
    /// [`CellGeometry::patches`]); divided by the patch's area it is the radiant exitance.
    pub fn patch_fluxes(&self, sources: &Sources, fluence: &[f64]) -> Vec<f64> {
        self.fine_patches()
            .iter()
            .map(|p| {
                let q = self.first_moment_along(sources, p);
                p.flux(self.boundaries.on(p.side), fluence[p.cell], q)
            })
            .collect()
    }

    /// The fluence on each boundary patch from the Robin or Dirichlet relation (the value
    /// the linear profile reaches on the surface).
    pub fn surface_fluence(&self, sources: &Sources, fluence: &[f64]) -> Vec<f64> {
        let fluxes = self.patch_fluxes(sources, fluence);
        self.cells
            .patches()
            .iter()
            .zip(fluxes)
            .map(|(p, flux)| match self.boundaries.on(p.side) {
                Condition::Robin { a } => 2.0 * a * flux / p.area,
                Condition::Dirichlet { value } => value,
                Condition::Neumann { .. } => fluence[p.cell],
            })
            .collect()
    }
}

/// Where the power of a point source goes: trilinear weights over the eight cell centres
/// around it, renormalised over the cells in the medium.
fn point_weights(problem: &DiffusionProblem, position: DVec3) -> Vec<(usize, f64)> {
    point_weights_in(
        problem.cells.geometry(),
        |c| problem.cells.is_active(c),
        position,
    )
}

/// The cells a point source at `position` is shared among (the eight nearest cell centres
/// that are `active`, by trilinear weights renormalised to 1), each cell once.
pub(crate) fn point_weights_in(
    g: &lucent_grid::GridGeometry,
    active: impl Fn(usize) -> bool,
    position: DVec3,
) -> Vec<(usize, f64)> {
    let v = g.world_to_voxel(position);
    let dims = g.dims();
    let base = v.floor();
    let t = v - base;
    let mut out = Vec::with_capacity(8);
    for corner in 0..8 {
        let offset = [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1];
        let mut at = [0usize; 3];
        let mut w = 1.0;
        let mut inside = true;
        for a in 0..3 {
            let idx = base[a] as i64 + offset[a] as i64;
            let idx = idx.clamp(0, dims[a] as i64 - 1);
            at[a] = idx as usize;
            w *= if offset[a] == 1 { t[a] } else { 1.0 - t[a] };
            inside &= v[a] > -0.5 && v[a] < dims[a] as f64 - 0.5;
        }
        if !inside || w == 0.0 {
            continue;
        }
        let c = g.index(at[0], at[1], at[2]);
        if active(c) {
            match out.iter_mut().find(|(cell, _)| *cell == c) {
                Some((_, weight)) => *weight += w,
                None => out.push((c, w)),
            }
        }
    }
    let total: f64 = out.iter().map(|p| p.1).sum();
    if total > 0.0 {
        for p in &mut out {
            p.1 /= total;
        }
    }
    out
}

/// Where the power goes, for a solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Balance {
    /// Power emitted by the sources (W).
    pub emitted: f64,
    /// Power absorbed in the medium, ∫ σ_a φ dV.
    pub absorbed: f64,
    /// Power leaving through the embedded surface.
    pub escaped_surface: f64,
    /// Power leaving through the box's faces.
    pub escaped_box: f64,
}

impl Balance {
    /// |emitted − absorbed − escaped| / emitted.
    pub fn relative_imbalance(&self) -> f64 {
        (self.emitted - self.absorbed - self.escaped_surface - self.escaped_box).abs()
            / self.emitted.abs().max(f64::MIN_POSITIVE)
    }
}

/// Builds the diagonal from couplings, absorption and patch couplings.
pub(crate) fn finish_level(
    dims: [usize; 3],
    spacing: DVec3,
    couplings: [Vec<f32>; 3],
    absorption: Vec<f32>,
    patches: Vec<LevelPatch>,
    boundaries: &Boundaries,
) -> LevelData {
    let [nx, ny, nz] = dims;
    let n = nx * ny * nz;
    let strides = [1, nx, nx * ny];
    let mut extra: Vec<f64> = absorption.iter().map(|&a| f64::from(a)).collect();
    for p in &patches {
        extra[p.cell] += p.coupling(boundaries.on(p.side));
    }
    let mut diag = extra.clone();
    for c in 0..n {
        let at = [c % nx, (c / nx) % ny, c / (nx * ny)];
        for axis in 0..3 {
            let low = f64::from(couplings[axis][c]);
            diag[c] += low;
            if at[axis] + 1 < dims[axis] {
                diag[c] += f64::from(couplings[axis][c + strides[axis]]);
            }
        }
    }
    let diag32: Vec<f32> = diag.iter().map(|&d| d as f32).collect();
    let inv_diag = diag
        .iter()
        .map(|&d| if d > 0.0 { (1.0 / d) as f32 } else { 0.0 })
        .collect();
    LevelData {
        level: Level::new(
            dims,
            spacing,
            couplings,
            diag32,
            extra.iter().map(|&e| e as f32).collect(),
            inv_diag,
        ),
        absorption,
        patches,
    }
}

/// A level's operator before its diagonal is formed: what [`finish_level`] takes, on a
/// whole level or on a frame (a box of the level's cells held as a grid of its own).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LevelParts {
    /// The cells' dimensions.
    pub(crate) dims: [usize; 3],
    /// The cells' size (length).
    pub(crate) spacing: DVec3,
    /// Coupling through each cell's low x, y and z face.
    pub(crate) couplings: [Vec<f32>; 3],
    /// σ_a κ V per cell.
    pub(crate) absorption: Vec<f32>,
    /// Boundary patches, sorted by cell and side; `cell` in the grid's own indices.
    pub(crate) patches: Vec<LevelPatch>,
}

impl LevelParts {
    /// Zero couplings and absorption and no patches on `dims` cells.
    pub(crate) fn zeros(dims: [usize; 3], spacing: DVec3) -> Self {
        let n = dims.iter().product();
        Self {
            dims,
            spacing,
            couplings: [vec![0.0; n], vec![0.0; n], vec![0.0; n]],
            absorption: vec![0.0; n],
            patches: Vec::new(),
        }
    }

    /// The diagonal formed: the level's operator.
    pub(crate) fn finish(self, boundaries: &Boundaries) -> LevelData {
        finish_level(
            self.dims,
            self.spacing,
            self.couplings,
            self.absorption,
            self.patches,
            boundaries,
        )
    }
}

/// The dimensions and cell size of the level above a level of `dims` cells of size
/// `spacing`: every axis with more than one cell halved, rounding up.
pub(crate) fn coarse_shape(dims: [usize; 3], spacing: DVec3) -> ([usize; 3], DVec3) {
    let coarse = dims.map(|n| if n == 1 { 1 } else { n.div_ceil(2) });
    let scale = DVec3::from_array(dims.map(|n| if n == 1 { 1.0 } else { 2.0 }));
    (coarse, spacing * scale)
}

/// The next coarser level by rediscretisation on the coarsened geometry: couplings through a
/// coarse face are half the sum of the fine couplings on it (the fine faces' conductances in
/// parallel, over twice the distance), absorption sums, and boundary patches merge per cell
/// and side, each fine patch's plane measured from the coarse cell's centre.
pub(crate) fn coarsen(fine: &LevelData, boundaries: &Boundaries) -> LevelData {
    let (dims, _) = coarse_shape(fine.level.dims, fine.level.spacing);
    let whole = Region::new(dims.map(|n| 0..n));
    coarsen_in(
        (&fine.level, &fine.absorption, &fine.patches),
        fine.level.dims,
        [0; 3],
        [0; 3],
        dims,
        &whole,
    )
    .finish(boundaries)
}

/// [`coarsen`] for the coarse cells `region` (cells of the coarse grid) alone, from a frame
/// of the fine level: `fine` (its operator, absorption and patches) holds the fine level's
/// cells from `fine_origin` on (a level of
/// `level_dims` cells), the result the coarse cells from `coarse_origin` on, `coarse_dims`
/// of them. Each cell of `region` is the same sums in the same order as the whole level's
/// coarsening makes it, and its patches merge in the order the whole level's do (the
/// frame's cells keep the level's order), so a rank that holds a box and its children
/// coarsens it to the whole level's bits. Every child of a cell of `region` must lie in the
/// fine frame; cells of the coarse frame outside `region` stay zero, without patches.
pub(crate) fn coarsen_in(
    (lv, fine_absorption, fine_patches): (&Level, &[f32], &[LevelPatch]),
    level_dims: [usize; 3],
    fine_origin: [usize; 3],
    coarse_origin: [usize; 3],
    coarse_dims: [usize; 3],
    region: &Region,
) -> LevelParts {
    let [nx, ny, _] = lv.dims;
    let (_, spacing) = coarse_shape(level_dims, lv.spacing);
    let [cx, cy, _] = coarse_dims;
    let mut parts = LevelParts::zeros(coarse_dims, spacing);
    let fine_index = |at: [usize; 3]| {
        let [i, j, k] = std::array::from_fn(|a| at[a] - fine_origin[a]);
        i + nx * (j + ny * k)
    };
    for kc in region.axes[2].clone() {
        for jc in region.axes[1].clone() {
            for ic in region.axes[0].clone() {
                let at = [ic, jc, kc];
                let [li, lj, lk] = std::array::from_fn(|a| at[a] - coarse_origin[a]);
                let c = li + cx * (lj + cy * lk);
                let mut sums = [0.0f64; 3];
                let mut absorbed = 0.0f64;
                let children = |a: usize| 2 * at[a]..(2 * at[a] + 2).min(level_dims[a]);
                for k in children(2) {
                    for j in children(1) {
                        for i in children(0) {
                            let f = fine_index([i, j, k]);
                            absorbed += f64::from(fine_absorption[f]);
                            let fa = [i, j, k];
                            for axis in 0..3 {
                                if fa[axis] == 2 * at[axis] && at[axis] > 0 {
                                    sums[axis] += f64::from(lv.couplings[axis][f]);
                                }
                            }
                        }
                    }
                }
                parts.absorption[c] = absorbed as f32;
                for axis in 0..3 {
                    parts.couplings[axis][c] = (0.5 * sums[axis]) as f32;
                }
            }
        }
    }
    // Merge patches per coarse cell and side.
    let mut merged: std::collections::HashMap<(usize, Side), [f64; 6]> =
        std::collections::HashMap::new();
    for p in fine_patches {
        // The patch's cell in the level, and its parent.
        let local = [p.cell % nx, (p.cell / nx) % ny, p.cell / (nx * ny)];
        let at: [usize; 3] = std::array::from_fn(|a| local[a] + fine_origin[a]);
        let parent: [usize; 3] = at.map(|v| v / 2);
        if !(0..3).all(|a| region.axes[a].contains(&parent[a])) {
            continue;
        }
        let [pi, pj, pk] = std::array::from_fn(|a| parent[a] - coarse_origin[a]);
        // The patch's plane seen from the coarse centre: d_c = d + n·(x_fine − x_coarse).
        let offset = DVec3::from_array(std::array::from_fn(|a| match (level_dims[a], at[a] % 2) {
            (1, _) => 0.0,
            (_, 0) => -0.5,
            _ => 0.5,
        })) * lv.spacing;
        let extra = p.normal.dot(offset);
        let e = merged
            .entry((pi + cx * (pj + cy * pk), p.side))
            .or_insert([0.0; 6]);
        e[0] += p.area;
        e[1] += p.area * (p.distance + extra);
        e[2] += p.area * p.diffusion;
        e[3] += p.area * p.normal.x;
        e[4] += p.area * p.normal.y;
        e[5] += p.area * p.normal.z;
    }
    parts.patches = merged
        .into_iter()
        .filter(|(_, e)| e[0] > 0.0)
        .map(|((cell, side), e)| {
            let normal = DVec3::new(e[3], e[4], e[5]);
            let normal = normal.normalize_or_zero();
            LevelPatch {
                cell,
                area: e[0],
                distance: e[1] / e[0],
                normal,
                diffusion: e[2] / e[0],
                side,
                width: normal.abs().dot(spacing),
            }
        })
        .collect();
    parts.patches.sort_by_key(|p| (p.cell, p.side));
    parts
}
