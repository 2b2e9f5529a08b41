//! The dense grid every solver sweeps: f32 values on a cell-centred, x-fastest layout.

use glam::DVec3;
use rayon::prelude::*;

use crate::error::GridError;
use crate::geometry::GridGeometry;

/// A dense scalar grid: one f32 per cell of its [`GridGeometry`].
///
/// Storage is a plain `Vec<f32>`, x-fastest, so hot loops run on slices with explicit
/// strides and rayon splits the work into z-slabs ([`Grid::slabs`], [`Grid::slabs_mut`]).
/// Reductions accumulate in f64, per slab and then over slabs in order, so their result is
/// the same for any number of threads.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    geometry: GridGeometry,
    data: Vec<f32>,
}

/// Summary statistics of a grid, reduced in f64.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridStats {
    /// Smallest value.
    pub min: f32,
    /// Largest value.
    pub max: f32,
    /// Mean over all cells.
    pub mean: f64,
    /// Fraction of cells that are not zero.
    pub nonzero_fraction: f64,
}

impl Grid {
    /// A grid with every cell set to `value`.
    pub fn filled(geometry: GridGeometry, value: f32) -> Self {
        Self {
            geometry,
            data: vec![value; geometry.voxel_count()],
        }
    }

    /// A grid over existing values (x-fastest); the length must match the geometry.
    pub fn from_vec(geometry: GridGeometry, data: Vec<f32>) -> Result<Self, GridError> {
        if data.len() != geometry.voxel_count() {
            return Err(GridError::Mismatch(format!(
                "{} values for a grid of {:?} = {} cells",
                data.len(),
                geometry.dims(),
                geometry.voxel_count()
            )));
        }
        Ok(Self { geometry, data })
    }

    /// For callers that built `data` from `geometry` themselves (lengths agree by
    /// construction).
    pub(crate) fn from_parts(geometry: GridGeometry, data: Vec<f32>) -> Self {
        debug_assert_eq!(data.len(), geometry.voxel_count());
        Self { geometry, data }
    }

    /// A grid whose cells take `f(centre)` at their world-space centres, filled in parallel
    /// over z-slabs.
    pub fn from_fn(geometry: GridGeometry, f: impl Fn(DVec3) -> f32 + Sync) -> Self {
        let mut grid = Self::filled(geometry, 0.0);
        let [nx, ny, _] = geometry.dims();
        grid.slabs_mut().for_each(|(k, slab)| {
            for j in 0..ny {
                for i in 0..nx {
                    slab[i + nx * j] = f(geometry.cell_centre(i, j, k));
                }
            }
        });
        grid
    }

    /// The geometry.
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// Cells per axis.
    pub fn dims(&self) -> [usize; 3] {
        self.geometry.dims()
    }

    /// All values, x-fastest.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// All values, mutable.
    pub fn data_mut(&mut self) -> &mut [f32] {
        &mut self.data
    }

    /// The values, giving up the geometry.
    pub fn into_vec(self) -> Vec<f32> {
        self.data
    }

    /// Value of cell (i, j, k), or `None` outside the grid.
    pub fn get(&self, i: usize, j: usize, k: usize) -> Option<f32> {
        let [nx, ny, nz] = self.dims();
        (i < nx && j < ny && k < nz).then(|| self.data[self.geometry.index(i, j, k)])
    }

    /// Sets cell (i, j, k); returns false (and changes nothing) outside the grid.
    pub fn set(&mut self, i: usize, j: usize, k: usize, value: f32) -> bool {
        let [nx, ny, nz] = self.dims();
        let inside = i < nx && j < ny && k < nz;
        if inside {
            let index = self.geometry.index(i, j, k);
            self.data[index] = value;
        }
        inside
    }

    /// The z-slabs in parallel: `(k, values of slab k)`.
    pub fn slabs(&self) -> impl IndexedParallelIterator<Item = (usize, &[f32])> {
        self.data.par_chunks(self.geometry.slab_len()).enumerate()
    }

    /// The z-slabs in parallel, mutable: `(k, values of slab k)`.
    pub fn slabs_mut(&mut self) -> impl IndexedParallelIterator<Item = (usize, &mut [f32])> {
        let len = self.geometry.slab_len();
        self.data.par_chunks_mut(len).enumerate()
    }

    /// Trilinear interpolation at a world point, with clamping: points outside the cell
    /// centres take the value of the nearest boundary face (no extrapolation, no wrap).
    /// Reproduces any field that is linear in x, y and z exactly between cell centres.
    pub fn sample_trilinear(&self, p: DVec3) -> f32 {
        let [nx, ny, nz] = self.dims();
        let (lo, t) = trilinear_cell(self.dims(), self.geometry.world_to_voxel(p));
        // One base index and three strides (0 along an axis of a single cell).
        let base = self.geometry.index(lo[0], lo[1], lo[2]);
        let sx = usize::from(nx > 1);
        let sy = if ny > 1 { nx } else { 0 };
        let sz = if nz > 1 { nx * ny } else { 0 };
        let d = &self.data;
        let at = |offset: usize| f64::from(d[base + offset]);
        trilinear_blend(
            [
                at(0),
                at(sx),
                at(sy),
                at(sy + sx),
                at(sz),
                at(sz + sx),
                at(sz + sy),
                at(sz + sy + sx),
            ],
            t,
        )
    }

    /// Σ values, in f64.
    pub fn sum(&self) -> f64 {
        let per_slab: Vec<f64> = self
            .slabs()
            .map(|(_, s)| s.iter().map(|&v| f64::from(v)).sum())
            .collect();
        per_slab.iter().sum()
    }

    /// Min, max, mean and non-zero fraction, in one parallel pass.
    pub fn stats(&self) -> GridStats {
        let per_slab: Vec<(f32, f32, f64, usize)> = self
            .slabs()
            .map(|(_, s)| {
                s.iter().fold(
                    (f32::INFINITY, f32::NEG_INFINITY, 0.0, 0),
                    |(lo, hi, sum, nz), &v| {
                        (
                            lo.min(v),
                            hi.max(v),
                            sum + f64::from(v),
                            nz + usize::from(v != 0.0),
                        )
                    },
                )
            })
            .collect();
        let (min, max, sum, nonzero) = per_slab.iter().fold(
            (f32::INFINITY, f32::NEG_INFINITY, 0.0, 0),
            |(a, b, c, d), &(lo, hi, s, n)| (a.min(lo), b.max(hi), c + s, d + n),
        );
        let count = self.data.len() as f64;
        GridStats {
            min,
            max,
            mean: sum / count,
            nonzero_fraction: nonzero as f64 / count,
        }
    }

    /// The same volume with its y axis made the z axis: a volume authored Y-up (Houdini,
    /// Maya, OpenVDB's convention) seen Z-up (lucent's, as Blender's): a point (x, y, z)
    /// of the file goes to (x, −z, y), a right-handed rotation of a quarter turn about x,
    /// as Blender's importers do. Cell centres map onto cell centres; the box rotates
    /// with them.
    pub fn y_up_to_z_up(&self) -> Self {
        let g = self.geometry();
        let [nx, ny, nz] = g.dims();
        let h = g.spacing();
        let (lo, hi) = g.bounds();
        let geometry = GridGeometry::new(
            [nx, nz, ny],
            DVec3::new(h.x, h.z, h.y),
            DVec3::new(lo.x, -hi.z, lo.y),
        )
        .unwrap_or(*g);
        let source = self.data();
        let mut data = vec![0.0f32; source.len()];
        // New cell (i, j', k') is old (i, nz − 1 − j', k').
        for (k_new, slab) in data.chunks_mut(nx * nz).enumerate() {
            for (j_new, row) in slab.chunks_mut(nx).enumerate() {
                let old = (nz - 1 - j_new) * nx * ny + k_new * nx;
                row.copy_from_slice(&source[old..old + nx]);
            }
        }
        Self::from_vec(geometry, data).unwrap_or_else(|_| self.clone())
    }

    /// A new grid with `f` applied to every value.
    pub fn map(&self, f: impl Fn(f32) -> f32 + Sync) -> Self {
        Self {
            geometry: self.geometry,
            data: self.data.par_iter().map(|&v| f(v)).collect(),
        }
    }

    /// The same values on a new geometry with the same dims (re-placing or re-scaling a
    /// volume read from a file).
    pub fn with_geometry(self, geometry: GridGeometry) -> Result<Self, GridError> {
        if geometry.dims() != self.dims() {
            return Err(GridError::Mismatch(format!(
                "dims {:?} vs {:?}",
                geometry.dims(),
                self.dims()
            )));
        }
        Ok(Self {
            geometry,
            data: self.data,
        })
    }
}

/// The lower corner cell and the weights of [`Grid::sample_trilinear`] at continuous voxel
/// coordinates `v` (cell centres at integers) on a grid of `dims` cells: the corners are
/// `lo + {0, 1}³`, where the upper index of an axis of one cell is that cell again. Any
/// storage that reads the same eight values and blends them with [`trilinear_blend`] gets
/// the dense grid's bits.
#[inline]
pub fn trilinear_cell(dims: [usize; 3], v: DVec3) -> ([usize; 3], [f64; 3]) {
    let (i0, tx) = axis_lerp(v.x, dims[0]);
    let (j0, ty) = axis_lerp(v.y, dims[1]);
    let (k0, tz) = axis_lerp(v.z, dims[2]);
    ([i0, j0, k0], [tx, ty, tz])
}

/// The trilinear blend of the eight corner values `c[dx + 2 dy + 4 dz]` with weights `t`,
/// in f64, rounded to f32 once.
#[inline]
pub fn trilinear_blend(c: [f64; 8], t: [f64; 3]) -> f32 {
    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let c00 = lerp(c[0], c[1], t[0]);
    let c10 = lerp(c[2], c[3], t[0]);
    let c01 = lerp(c[4], c[5], t[0]);
    let c11 = lerp(c[6], c[7], t[0]);
    lerp(lerp(c00, c10, t[1]), lerp(c01, c11, t[1]), t[2]) as f32
}

/// Lower cell index and weight for a clamped linear interpolation along one axis of `n`
/// cells at continuous voxel coordinate `v`.
#[inline]
fn axis_lerp(v: f64, n: usize) -> (usize, f64) {
    if n == 1 || v.is_nan() {
        return (0, 0.0);
    }
    // After clamping v ≥ 0, truncation is floor (and needs no libm call).
    let v = v.clamp(0.0, (n - 1) as f64);
    let i0 = (v as usize).min(n - 2);
    (i0, v - i0 as f64)
}
