//! The discrete problem of a medium that fills the grid's box, row by row from z-slabs of
//! its coefficients: what [`DiffusionProblem::assemble`](crate::DiffusionProblem::assemble)
//! builds as a whole, for solvers that stream their fields slab by slab (out of core).
//!
//! With no embedded surface every cell is whole (κ = 1, every face open), the boundary
//! patches are the cells' faces on the box, and a row of the operator needs the diffusion
//! coefficient of the cell and its six neighbours only: slabs z − 1, z and z + 1 of D
//! ([`Window`]). Every coefficient is computed by the functions `assemble` uses (the face's
//! harmonic mean, the patches' couplings and data fluxes, the point sources' trilinear
//! weights) and summed in the order `assemble` sums it, so a row and a right-hand side
//! have the bits of the assembled matrix's row and vector (test:
//! `crates/diffusion/tests/it/slab_system.rs`). [`SlabSystem::block`] gathers the rows of a
//! box of cells (a z-slab is a box of whole layers) into a CSR block with the whole grid's
//! column numbers, from the coefficients of that box and the cell beyond each of its faces:
//! what one rank of a decomposition into boxes or slabs iterates without the rest of the
//! volume (test: `crates/diffusion/tests/it/slab_block.rs`).

use std::ops::Range;

use glam::DVec3;
use lucent_grid::{GridGeometry, box_cells};
use sprs::CsMat;

use crate::error::DiffusionError;
use crate::geometry::{box_patch, box_sides};
use crate::problem::{
    Boundaries, Condition, LevelParts, LevelPatch, face_diffusion, point_weights_in,
};

/// Slabs z − 1, z and z + 1 of a field (`None` beyond the box).
#[derive(Debug, Clone, Copy)]
pub struct Window<'a, T> {
    /// Slab z − 1.
    pub below: Option<&'a [T]>,
    /// Slab z.
    pub here: &'a [T],
    /// Slab z + 1.
    pub above: Option<&'a [T]>,
}

impl<T: Copy> Window<'_, T> {
    /// The value at (i, j) of slab z + `dz` (dz ∈ {−1, 0, 1}).
    #[inline]
    fn at(&self, index: usize, dz: isize) -> T {
        match dz {
            -1 => self.below.expect("a slab below")[index],
            1 => self.above.expect("a slab above")[index],
            _ => self.here[index],
        }
    }
}

/// One row of the operator: its non-zero entries as (offset of the column's cell from the
/// row's cell, value), in column order, as the assembled matrix stores them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    entries: [(isize, f64); 7],
    len: usize,
}

impl Row {
    /// The entries, in column order.
    pub fn entries(&self) -> &[(isize, f64)] {
        &self.entries[..self.len]
    }

    /// The diagonal entry.
    pub fn diagonal(&self) -> f64 {
        self.entries()
            .iter()
            .find(|e| e.0 == 0)
            .map_or(0.0, |e| e.1)
    }
}

/// A point source's share of each cell ([`SlabSystem::point_weights`]).
#[derive(Debug, Clone, PartialEq)]
pub struct PointShares {
    /// Power (W).
    pub power: f64,
    /// (cell, weight), weights summing to 1.
    pub weights: Vec<(usize, f64)>,
}

/// The box problem's rows and right-hand side, slab by slab.
#[derive(Debug, Clone, PartialEq)]
pub struct SlabSystem {
    geometry: GridGeometry,
    boundaries: Boundaries,
    face_area: [f64; 3],
}

impl SlabSystem {
    /// The system on `geometry`'s box under `boundaries` (the surface condition is unused:
    /// there is no embedded surface). Conditions are checked as
    /// [`DiffusionProblem::new`](crate::DiffusionProblem::new) checks them.
    pub fn new(geometry: GridGeometry, boundaries: Boundaries) -> Result<Self, DiffusionError> {
        boundaries.check()?;
        let h = geometry.spacing();
        Ok(Self {
            geometry,
            boundaries,
            face_area: [h.y * h.z, h.x * h.z, h.x * h.y],
        })
    }

    /// The grid.
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// The boundary conditions.
    pub fn boundaries(&self) -> &Boundaries {
        &self.boundaries
    }

    /// Whether some face of the box holds the fluence (a Robin or Dirichlet condition):
    /// without that and without absorption the problem has no unique solution.
    pub fn holds(&self) -> bool {
        self.boundaries
            .faces
            .iter()
            .any(|c| !matches!(c, Condition::Neumann { .. }))
    }

    /// The coupling of the face along `axis` between a cell of diffusion coefficient `d`
    /// and the cell below it, of `d_lower` (length, integrated form): as the operator
    /// stores it, in f32.
    #[inline]
    pub fn coupling(&self, axis: usize, d: f32, d_lower: f32) -> f32 {
        let h = self.geometry.spacing();
        (self.face_area[axis] * face_diffusion(d, d_lower) / h[axis]) as f32
    }

    /// The boundary patches of cell `at` (on the box's faces), for its D `d`.
    fn patches(&self, at: [usize; 3], d: f32) -> impl Iterator<Item = LevelPatch> + '_ {
        let h = self.geometry.spacing();
        box_sides(&self.geometry, at).map(move |(axis, end)| {
            LevelPatch::fine(&box_patch(&self.geometry, at, axis, end, 1.0), d, h)
        })
    }

    /// The part of cell `at`'s diagonal that is not a face coupling: σ_a κ V (stored in
    /// f32) plus its boundary patches' couplings, in f32 as the operator stores it.
    pub fn extra(&self, at: [usize; 3], d: f32, sigma_a: f32) -> f32 {
        let volume = self.geometry.cell_volume();
        let absorption = (f64::from(sigma_a) * f64::from(1.0f32) * volume) as f32;
        let mut extra = f64::from(absorption);
        for p in self.patches(at, d) {
            extra += p.coupling(self.boundaries.on(p.side));
        }
        extra as f32
    }

    /// The offsets of cell `at`'s lower and upper neighbour along each axis, `None` beyond
    /// the box.
    #[inline]
    fn neighbours(&self, at: [usize; 3]) -> [[Option<isize>; 2]; 3] {
        let [nx, ny, _] = self.geometry.dims();
        let dims = self.geometry.dims();
        let strides = [1, nx as isize, (nx * ny) as isize];
        std::array::from_fn(|axis| {
            [
                (at[axis] > 0).then_some(-strides[axis]),
                (at[axis] + 1 < dims[axis]).then_some(strides[axis]),
            ]
        })
    }

    /// D at the cell `offset` cells from `index` (in slab z's numbering) in `d`.
    #[inline]
    fn d_at(&self, d: &Window<'_, f32>, index: usize, offset: isize) -> f32 {
        let slab = self.geometry.slab_len() as isize;
        let dz = if offset == slab {
            1
        } else if offset == -slab {
            -1
        } else {
            0
        };
        d.at((index as isize + offset - dz * slab) as usize, dz)
    }

    /// The row of cell `at` (in slab `at[2]`), whose `extra` is [`SlabSystem::extra`], with
    /// D from slabs around it.
    pub fn row(&self, at: [usize; 3], d: &Window<'_, f32>, extra: f32) -> Row {
        let index = at[0] + self.geometry.dims()[0] * at[1];
        self.row_with(at, d.here[index], |_, o| self.d_at(d, index, o), extra)
    }

    /// The row of cell `at` of diffusion coefficient `dc`, `d_near(axis, offset)` giving D
    /// of its neighbour along `axis`, `offset` cells away in the whole grid's numbering.
    #[inline]
    fn row_with(
        &self,
        at: [usize; 3],
        dc: f32,
        d_near: impl Fn(usize, isize) -> f32,
        extra: f32,
    ) -> Row {
        let mut diagonal = f64::from(extra);
        // Column order: −z, −y, −x, the cell, +x, +y, +z.
        let mut off = [None; 6];
        for (axis, [lower, upper]) in self.neighbours(at).into_iter().enumerate() {
            if let Some(o) = lower {
                let c = self.coupling(axis, dc, d_near(axis, o));
                if c > 0.0 {
                    diagonal += f64::from(c);
                    off[2 - axis] = Some((o, -f64::from(c)));
                }
            }
            if let Some(o) = upper {
                let c = self.coupling(axis, d_near(axis, o), dc);
                if c > 0.0 {
                    diagonal += f64::from(c);
                    off[3 + axis] = Some((o, -f64::from(c)));
                }
            }
        }
        let mut row = Row {
            entries: [(0, 0.0); 7],
            len: 0,
        };
        let mut push = |e: (isize, f64)| {
            row.entries[row.len] = e;
            row.len += 1;
        };
        off[..3].iter().flatten().for_each(|&e| push(e));
        push((0, diagonal));
        off[3..].iter().flatten().for_each(|&e| push(e));
        row
    }

    /// A point source of `power` at `position` shared among the cells around it, as the
    /// assembled right-hand side shares it; `None` outside the box.
    pub fn point_weights(&self, position: DVec3, power: f64) -> Option<PointShares> {
        let weights = point_weights_in(&self.geometry, |_| true, position);
        (!weights.is_empty() && position.is_finite() && power.is_finite())
            .then_some(PointShares { power, weights })
    }

    /// The right-hand side of slab `z` into `out` (one slab): the volumetric source `q0`
    /// (slab z), the first moment's face fluxes (`q1`: x, y and z components around slab
    /// z; `None` without a first moment), the boundary patches' data fluxes and the
    /// `points`' shares, each cell's terms in the order the assembled vector adds them.
    pub fn rhs_slab(
        &self,
        z: usize,
        q0: &[f32],
        q1: Option<&[Window<'_, f32>; 3]>,
        d: &Window<'_, f32>,
        points: &[PointShares],
        out: &mut [f64],
    ) {
        let [nx, ny, _] = self.geometry.dims();
        let volume = self.geometry.cell_volume();
        let slab = nx * ny;
        for (index, b) in out.iter_mut().enumerate() {
            let at = [index % nx, index / nx, z];
            let mut value = 0.0f64;
            value += f64::from(q0[index]) * f64::from(1.0f32) * volume;
            let dc = d.here[index];
            if let Some(q1) = q1 {
                let neighbours = self.neighbours(at);
                let component = |axis: usize, offset: isize| {
                    let w = &q1[axis];
                    let dz = if offset == slab as isize {
                        1
                    } else if offset == -(slab as isize) {
                        -1
                    } else {
                        0
                    };
                    f64::from(w.at((index as isize + offset - dz * slab as isize) as usize, dz))
                };
                // Faces below the cell (flux from the lower cell into this one) ...
                for (axis, [lower, _]) in neighbours.iter().enumerate() {
                    if let Some(o) = *lower {
                        let q = 0.5 * (component(axis, 0) + component(axis, o));
                        let flux = 3.0
                            * face_diffusion(dc, self.d_at(d, index, o))
                            * self.face_area[axis]
                            * q;
                        value += flux;
                    }
                }
                // ... then above it, as the faces are visited cell by cell.
                for (axis, [_, upper]) in neighbours.iter().enumerate() {
                    if let Some(o) = *upper {
                        let q = 0.5 * (component(axis, o) + component(axis, 0));
                        let flux = 3.0
                            * face_diffusion(self.d_at(d, index, o), dc)
                            * self.face_area[axis]
                            * q;
                        value -= flux;
                    }
                }
            }
            let q1_here = q1.map(|q1| {
                DVec3::new(
                    f64::from(q1[0].here[index]),
                    f64::from(q1[1].here[index]),
                    f64::from(q1[2].here[index]),
                )
            });
            value = self.boundary_and_points(at, dc, q1_here, points, value);
            *b = value;
        }
    }

    /// `value` (a cell's right-hand side so far) less its boundary patches' data fluxes
    /// (`q1_here`: the first moment in the cell, `None` without one), plus the `points`'
    /// shares of the cell, in the order the assembled vector adds them.
    fn boundary_and_points(
        &self,
        at: [usize; 3],
        dc: f32,
        q1_here: Option<DVec3>,
        points: &[PointShares],
        mut value: f64,
    ) -> f64 {
        for p in self.patches(at, dc) {
            let q = q1_here.map_or(0.0, |q| q.dot(p.normal));
            value -= p.data_flux(self.boundaries.on(p.side), q);
        }
        let [nx, ny, _] = self.geometry.dims();
        let cell = at[0] + nx * (at[1] + ny * at[2]);
        for point in points {
            for &(c, w) in &point.weights {
                if c == cell {
                    value += point.power * w;
                }
            }
        }
        value
    }
}

/// One rank's rows of the box system ([`SlabSystem::block`]): the rows of a box of cells
/// (a z-slab is the box of whole layers).
#[derive(Debug, Clone, PartialEq)]
pub struct Block {
    /// Its cells along x, y and z. Row i is the i-th of them, x fastest, then y, then z.
    pub cells: [Range<usize>; 3],
    /// Its rows; columns are cells of the whole grid, ascending (the assembled matrix's
    /// entries, bit for bit).
    pub matrix: CsMat<f64>,
    /// Its rows' right-hand side.
    pub rhs: Vec<f64>,
}

impl Block {
    /// The whole grid's cell of each row, in row order.
    pub fn grid_cells(&self, dims: [usize; 3]) -> impl Iterator<Item = usize> + '_ {
        let [nx, ny, _] = dims;
        box_cells(&self.cells).map(move |[i, j, k]| i + nx * (j + ny * k))
    }
}

/// The fields a [`Block`] is built from: D (cm), σ_a (1/cm) and the volumetric source q0
/// (W/cm³) over a box of cells (`dims` cells from `origin`, x fastest), the same box for
/// all three. It covers the block's cells and, for D, the cell beyond each face of the
/// block that the grid has (a slab's fields are its layers and the layer on either side).
#[derive(Debug, Clone, Copy)]
pub struct BlockFields<'a> {
    /// The fields' first cell along x, y and z.
    pub origin: [usize; 3],
    /// Their cells along x, y and z.
    pub dims: [usize; 3],
    /// D per cell.
    pub diffusion: &'a [f32],
    /// σ_a per cell.
    pub absorption: &'a [f32],
    /// q0 per cell.
    pub source: &'a [f32],
}

impl BlockFields<'_> {
    /// Cell `p` of the grid in the fields (it must lie in their box).
    #[inline]
    fn index(&self, [i, j, k]: [usize; 3]) -> usize {
        let [ox, oy, oz] = self.origin;
        (i - ox) + self.dims[0] * ((j - oy) + self.dims[1] * (k - oz))
    }
}

impl SlabSystem {
    /// Checks that `fields` cover the cells a block of `cells` reads and hold values the
    /// problem accepts ([`SlabSystem::block`]'s errors).
    fn check_fields(
        &self,
        cells: &[Range<usize>; 3],
        fields: &BlockFields<'_>,
    ) -> Result<(), DiffusionError> {
        let dims = self.geometry.dims();
        let [nx, ny, _] = dims;
        let BlockFields {
            origin,
            dims: held,
            diffusion: d,
            absorption: sigma_a,
            source: q0,
        } = *fields;
        let reads: [Range<usize>; 3] = std::array::from_fn(|a| {
            cells[a].start.saturating_sub(1)..(cells[a].end + 1).min(dims[a])
        });
        let count = held.iter().try_fold(1usize, |n, &h| n.checked_mul(h));
        let fits = (0..3).all(|a| {
            !cells[a].is_empty()
                && cells[a].end <= dims[a]
                && origin[a] <= reads[a].start
                && origin[a].saturating_add(held[a]) >= reads[a].end
        });
        if !fits || count != Some(d.len()) || sigma_a.len() != d.len() || q0.len() != d.len() {
            return Err(DiffusionError::Invalid(format!(
                "fields of {}, {} and {} values on {held:?} cells from {origin:?} for the \
                 rows of cells {cells:?} of a {dims:?} grid, which read D on {reads:?}",
                d.len(),
                sigma_a.len(),
                q0.len()
            )));
        }
        let at = |p: [usize; 3]| fields.index(p);
        let cell = |[i, j, k]: [usize; 3]| i + nx * (j + ny * k);
        for p in box_cells(&reads) {
            let v = d[at(p)];
            if !(v.is_finite() && v > 0.0) {
                return Err(DiffusionError::Invalid(format!(
                    "diffusion coefficient {v} in cell {}: it must be finite and positive",
                    cell(p)
                )));
            }
        }
        for p in box_cells(cells) {
            let (s, q) = (sigma_a[at(p)], q0[at(p)]);
            if !(s.is_finite() && s >= 0.0) {
                return Err(DiffusionError::Invalid(format!(
                    "absorption {s} in cell {}: it must be finite and ≥ 0",
                    cell(p)
                )));
            }
            if !q.is_finite() {
                return Err(DiffusionError::Invalid(format!(
                    "source {q} in cell {}: it must be finite",
                    cell(p)
                )));
            }
        }
        Ok(())
    }

    /// The right-hand side of the box of cells `cells` (without a first moment), in the
    /// box's order, from `fields` (checked as [`SlabSystem::block`] checks them).
    ///
    /// # Errors
    /// As [`SlabSystem::block`].
    pub fn block_rhs(
        &self,
        cells: &[Range<usize>; 3],
        fields: &BlockFields<'_>,
        points: &[PointShares],
    ) -> Result<Vec<f64>, DiffusionError> {
        self.check_fields(cells, fields)?;
        Ok(box_cells(cells)
            .map(|p| self.cell_rhs(p, fields, points))
            .collect())
    }

    /// The right-hand side of cell `p` (without a first moment) from `fields`, which hold
    /// it: the volumetric source, the boundary patches' data and the points' shares, in
    /// the order the assembled vector adds them.
    fn cell_rhs(&self, p: [usize; 3], fields: &BlockFields<'_>, points: &[PointShares]) -> f64 {
        let at = fields.index(p);
        let source = f64::from(fields.source[at]) * f64::from(1.0f32) * self.geometry.cell_volume();
        self.boundary_and_points(p, fields.diffusion[at], None, points, 0.0 + source)
    }

    /// The finest level's couplings, absorption and boundary patches on a frame of the grid
    /// (`frame_dims` cells from `frame_origin`), as
    /// [`DiffusionProblem::fine_level`](crate::DiffusionProblem) makes them for the whole
    /// grid: the couplings of every face both of whose cells `fields` hold, the absorption
    /// and patches of the cells `cells` (which `fields` must hold, checked beforehand).
    pub(crate) fn frame_parts(
        &self,
        cells: &[Range<usize>; 3],
        fields: &BlockFields<'_>,
        frame_origin: [usize; 3],
        frame_dims: [usize; 3],
    ) -> LevelParts {
        let h = self.geometry.spacing();
        let mut parts = LevelParts::zeros(frame_dims, h);
        let [fx, fy, _] = frame_dims;
        let local = |p: [usize; 3]| {
            (p[0] - frame_origin[0])
                + fx * ((p[1] - frame_origin[1]) + fy * (p[2] - frame_origin[2]))
        };
        let frame: [Range<usize>; 3] =
            std::array::from_fn(|a| frame_origin[a]..frame_origin[a] + frame_dims[a]);
        let held: [Range<usize>; 3] =
            std::array::from_fn(|a| fields.origin[a]..fields.origin[a] + fields.dims[a]);
        for p in box_cells(&frame) {
            if !(0..3).all(|a| held[a].contains(&p[a])) {
                continue;
            }
            let d = fields.diffusion[fields.index(p)];
            for axis in 0..3 {
                let mut below = p;
                below[axis] = below[axis].wrapping_sub(1);
                if p[axis] > 0 && held[axis].contains(&below[axis]) {
                    parts.couplings[axis][local(p)] =
                        self.coupling(axis, d, fields.diffusion[fields.index(below)]);
                }
            }
        }
        let volume = self.geometry.cell_volume();
        for p in box_cells(cells) {
            let at = fields.index(p);
            parts.absorption[local(p)] =
                (f64::from(fields.absorption[at]) * f64::from(1.0f32) * volume) as f32;
            for mut patch in self.patches(p, fields.diffusion[at]) {
                patch.cell = local(p);
                parts.patches.push(patch);
            }
        }
        parts
    }

    /// The rows and right-hand side of the box of cells `cells` (without a first moment),
    /// from the fields of that box and, for D, the cell beyond each face that the grid has:
    /// what one rank of a decomposition into boxes (or z-slabs) builds without the rest of
    /// the volume. The coefficients are checked as
    /// [`DiffusionProblem::new`](crate::DiffusionProblem::new) checks them (D finite and
    /// positive over the box grown by a cell, σ_a finite and ≥ 0, q0 finite over the box).
    ///
    /// # Errors
    /// [`DiffusionError::Invalid`] for an empty box or one beyond the grid, fields that do
    /// not cover the cells the block reads or whose lengths are not their box's, or a
    /// value the problem refuses (named by its cell).
    pub fn block(
        &self,
        cells: [Range<usize>; 3],
        fields: BlockFields<'_>,
        points: &[PointShares],
    ) -> Result<Block, DiffusionError> {
        self.check_fields(&cells, &fields)?;
        let dims = self.geometry.dims();
        let [nx, ny, _] = dims;
        let (d, sigma_a) = (fields.diffusion, fields.absorption);
        // A cell's place in the fields, and in the whole grid.
        let at = |p: [usize; 3]| fields.index(p);
        let cell = |[i, j, k]: [usize; 3]| i + nx * (j + ny * k);
        let rows: usize = cells.iter().map(ExactSizeIterator::len).product();
        let mut indptr = Vec::with_capacity(rows + 1);
        indptr.push(0);
        let mut indices = Vec::with_capacity(7 * rows);
        let mut data = Vec::with_capacity(7 * rows);
        let mut rhs = Vec::with_capacity(rows);
        for p in box_cells(&cells) {
            let (c, dc) = (cell(p), d[at(p)]);
            let d_near = |axis: usize, offset: isize| {
                let mut q = p;
                q[axis] = q[axis].wrapping_add_signed(offset.signum());
                d[at(q)]
            };
            let extra = self.extra(p, dc, sigma_a[at(p)]);
            for &(offset, value) in self.row_with(p, dc, d_near, extra).entries() {
                indices.push((c as isize + offset) as usize);
                data.push(value);
            }
            indptr.push(indices.len());
            rhs.push(self.cell_rhs(p, &fields, points));
        }
        let matrix = CsMat::try_new((rows, nx * ny * dims[2]), indptr, indices, data)
            .map_err(|e| DiffusionError::Invalid(format!("a block's rows: {}", e.3)))?;
        Ok(Block { cells, matrix, rhs })
    }
}
