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
//! `crates/diffusion/tests/slab_system.rs`). [`SlabSystem::block`] gathers a run of
//! layers' rows into a CSR block with the whole grid's column numbers, what one rank of a
//! z-slab decomposition iterates without the rest of the volume (test:
//! `crates/diffusion/tests/slab_block.rs`).

use std::ops::Range;

use glam::DVec3;
use lucent_grid::GridGeometry;
use sprs::CsMat;

use crate::error::DiffusionError;
use crate::geometry::{box_patch, box_sides};
use crate::problem::{Boundaries, Condition, LevelPatch, face_diffusion, point_weights_in};

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
        let [nx, _, _] = self.geometry.dims();
        let index = at[0] + nx * at[1];
        let dc = d.here[index];
        let mut diagonal = f64::from(extra);
        // Column order: −z, −y, −x, the cell, +x, +y, +z.
        let mut off = [None; 6];
        for (axis, [lower, upper]) in self.neighbours(at).into_iter().enumerate() {
            if let Some(o) = lower {
                let c = self.coupling(axis, dc, self.d_at(d, index, o));
                if c > 0.0 {
                    diagonal += f64::from(c);
                    off[2 - axis] = Some((o, -f64::from(c)));
                }
            }
            if let Some(o) = upper {
                let c = self.coupling(axis, self.d_at(d, index, o), dc);
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
            for p in self.patches(at, dc) {
                let q = match q1 {
                    Some(q1) => DVec3::new(
                        f64::from(q1[0].here[index]),
                        f64::from(q1[1].here[index]),
                        f64::from(q1[2].here[index]),
                    )
                    .dot(p.normal),
                    None => 0.0,
                };
                value -= p.data_flux(self.boundaries.on(p.side), q);
            }
            let cell = index + slab * z;
            for point in points {
                for &(c, w) in &point.weights {
                    if c == cell {
                        value += point.power * w;
                    }
                }
            }
            *b = value;
        }
    }
}

/// One rank's rows of the box system ([`SlabSystem::block`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Block {
    /// Its z-layers.
    pub layers: Range<usize>,
    /// Row i is the row of cell `layers.start · n_x n_y + i`; columns are cells of the
    /// whole grid, ascending (the assembled matrix's entries, bit for bit).
    pub matrix: CsMat<f64>,
    /// Its rows' right-hand side.
    pub rhs: Vec<f64>,
}

/// The fields a [`Block`] is built from: layers `first..` of D (cm), σ_a (1/cm) and the
/// volumetric source q0 (W/cm³), each a whole number of z-layers, the same number.
#[derive(Debug, Clone, Copy)]
pub struct BlockFields<'a> {
    /// The grid layer the fields start at.
    pub first: usize,
    /// D per cell.
    pub diffusion: &'a [f32],
    /// σ_a per cell.
    pub absorption: &'a [f32],
    /// q0 per cell.
    pub source: &'a [f32],
}

impl SlabSystem {
    /// The rows and right-hand side of z-layers `layers` (without a first moment), from
    /// the fields of those layers and, for D, the layer on either side that the box has:
    /// what one rank of a z-slab decomposition builds without the rest of the volume. The
    /// coefficients are checked as [`DiffusionProblem::new`](crate::DiffusionProblem::new)
    /// checks them (D finite and positive, σ_a finite and ≥ 0; q0 finite).
    ///
    /// # Errors
    /// [`DiffusionError::Invalid`] for fields that are not whole layers, do not cover the
    /// layers the block reads, or hold a value the problem refuses (named by its cell).
    pub fn block(
        &self,
        layers: Range<usize>,
        fields: BlockFields<'_>,
        points: &[PointShares],
    ) -> Result<Block, DiffusionError> {
        let [nx, ny, nz] = self.geometry.dims();
        let slab = nx * ny;
        let BlockFields {
            first,
            diffusion: d,
            absorption: sigma_a,
            source: q0,
        } = fields;
        let held = d.len() / slab.max(1);
        let reads = layers.start.saturating_sub(1)..(layers.end + 1).min(nz);
        if layers.is_empty()
            || layers.end > nz
            || d.len() % slab != 0
            || sigma_a.len() != d.len()
            || q0.len() != d.len()
            || first > reads.start
            || first + held < reads.end
        {
            return Err(DiffusionError::Invalid(format!(
                "fields of {}, {} and {} values from layer {first} for the rows of layers \
                 {layers:?}, which read D on layers {reads:?} of slabs of {slab} cells",
                d.len(),
                sigma_a.len(),
                q0.len()
            )));
        }
        let at = |k: usize| (k - first) * slab..(k - first + 1) * slab;
        for k in reads.clone() {
            for (i, &v) in d[at(k)].iter().enumerate() {
                if !(v.is_finite() && v > 0.0) {
                    return Err(DiffusionError::Invalid(format!(
                        "diffusion coefficient {v} in cell {}: it must be finite and positive",
                        k * slab + i
                    )));
                }
            }
        }
        for k in layers.clone() {
            for (i, (&s, &q)) in sigma_a[at(k)].iter().zip(&q0[at(k)]).enumerate() {
                let cell = k * slab + i;
                if !(s.is_finite() && s >= 0.0) {
                    return Err(DiffusionError::Invalid(format!(
                        "absorption {s} in cell {cell}: it must be finite and ≥ 0"
                    )));
                }
                if !q.is_finite() {
                    return Err(DiffusionError::Invalid(format!(
                        "source {q} in cell {cell}: it must be finite"
                    )));
                }
            }
        }
        let rows = layers.len() * slab;
        let mut indptr = Vec::with_capacity(rows + 1);
        indptr.push(0);
        let mut indices = Vec::with_capacity(7 * rows);
        let mut data = Vec::with_capacity(7 * rows);
        let mut rhs = vec![0.0f64; rows];
        for (t, k) in layers.clone().enumerate() {
            let window = Window {
                below: (k > 0).then(|| &d[at(k - 1)]),
                here: &d[at(k)],
                above: (k + 1 < nz).then(|| &d[at(k + 1)]),
            };
            let (sigma, here) = (&sigma_a[at(k)], window.here);
            for index in 0..slab {
                let cell = k * slab + index;
                let position = [index % nx, index / nx, k];
                let extra = self.extra(position, here[index], sigma[index]);
                for &(offset, value) in self.row(position, &window, extra).entries() {
                    indices.push((cell as isize + offset) as usize);
                    data.push(value);
                }
                indptr.push(indices.len());
            }
            self.rhs_slab(
                k,
                &q0[at(k)],
                None,
                &window,
                points,
                &mut rhs[t * slab..(t + 1) * slab],
            );
        }
        let matrix = CsMat::try_new((rows, slab * nz), indptr, indices, data)
            .map_err(|e| DiffusionError::Invalid(format!("a block's rows: {}", e.3)))?;
        Ok(Block {
            layers,
            matrix,
            rhs,
        })
    }
}
