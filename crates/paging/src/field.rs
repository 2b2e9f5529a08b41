//! A grid stored as bricks of [`BrickLayout`] (with their one-cell aprons), constant bricks
//! as one number, the rest paged through a shared [`Pager`].
//!
//! Writes go through [`PagedGrid::write_slabs`], which updates every stored copy of the
//! cells it writes — the bricks that own them and the aprons of their neighbours — so a
//! reader of one stored brick always sees its neighbours' current values, and the
//! per-brick ranges (over brick and apron: bounds of the trilinear interpolant) stay exact.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use glam::DVec3;
use lucent_grid::{BrickLayout, DualCorners, Grid, GridGeometry};
use rayon::prelude::*;

use crate::error::PagingError;
use crate::pager::{Pager, ReadPin};

/// One brick as it is stored: a constant, or pinned values (brick and apron).
#[derive(Debug)]
pub enum BrickView {
    /// Every value of the brick and its apron.
    Constant(f32),
    /// The (B + 2)³ stored values ([`BrickLayout::stored_index`]).
    Paged(ReadPin),
}

impl BrickView {
    /// The value at local cell `local` (−1 to B on each axis: the apron included).
    #[inline]
    pub fn get(&self, layout: &BrickLayout, local: [isize; 3]) -> f32 {
        match self {
            BrickView::Constant(v) => *v,
            BrickView::Paged(pin) => pin[layout.stored_index(local)],
        }
    }
}

/// A field of f32 values on cells, stored brick by brick through a pager.
#[derive(Debug)]
pub struct PagedGrid {
    geometry: GridGeometry,
    layout: BrickLayout,
    pager: Arc<Pager>,
    /// The pager's number of this field's brick 0.
    first: usize,
    /// Per brick: whether it is in the pager (else constant).
    paged: Vec<AtomicBool>,
    /// Per brick: the constant's bits.
    constant: Vec<AtomicU32>,
    /// Per brick: min and max over the stored brick (apron included), as bits.
    min: Vec<AtomicU32>,
    max: Vec<AtomicU32>,
}

impl PagedGrid {
    /// A field on `geometry` with bricks of `brick`³ cells whose cell values are `value`,
    /// its non-constant bricks written to `pager` (which must page bricks of
    /// (brick + 2)³ values). Bricks are built in parallel, each from its own cells.
    pub fn from_fn(
        pager: Arc<Pager>,
        geometry: GridGeometry,
        brick: usize,
        value: impl Fn([usize; 3]) -> f32 + Sync,
    ) -> Result<Self, PagingError> {
        let layout = BrickLayout::new(geometry.dims(), brick)?;
        if pager.brick_len() != layout.stored_len() {
            return Err(PagingError::Grid(lucent_grid::GridError::Mismatch(
                format!(
                    "the pager pages bricks of {} values; bricks of {brick}³ cells are stored as {}",
                    pager.brick_len(),
                    layout.stored_len()
                ),
            )));
        }
        let count = layout.count();
        let first = pager.add_bricks(count);
        let this = Self {
            geometry,
            layout,
            pager,
            first,
            paged: (0..count).map(|_| AtomicBool::new(false)).collect(),
            constant: (0..count).map(|_| AtomicU32::new(0)).collect(),
            min: (0..count).map(|_| AtomicU32::new(0)).collect(),
            max: (0..count).map(|_| AtomicU32::new(0)).collect(),
        };
        (0..count).into_par_iter().try_for_each(|id| {
            let stored = this.layout.gather(id, &value);
            this.set_range(id, &stored);
            let v0 = stored[0];
            if stored.iter().all(|v| v.to_bits() == v0.to_bits()) {
                this.constant[id].store(v0.to_bits(), Ordering::Relaxed);
            } else {
                this.pager.store_brick(first + id, &stored)?;
                this.paged[id].store(true, Ordering::Release);
            }
            Ok::<_, PagingError>(())
        })?;
        Ok(this)
    }

    /// The field of a dense grid.
    pub fn from_grid(pager: Arc<Pager>, grid: &Grid, brick: usize) -> Result<Self, PagingError> {
        let geometry = *grid.geometry();
        let data = grid.data();
        Self::from_fn(pager, geometry, brick, |c| {
            data[geometry.index(c[0], c[1], c[2])]
        })
    }

    /// A field of one value everywhere (no brick stored).
    pub fn filled(
        pager: Arc<Pager>,
        geometry: GridGeometry,
        brick: usize,
        value: f32,
    ) -> Result<Self, PagingError> {
        // Every brick constant, its range the value: what `from_fn` would find, without
        // evaluating a cell (a 384³ field is built in microseconds, not a second).
        let layout = BrickLayout::new(geometry.dims(), brick)?;
        if pager.brick_len() != layout.stored_len() {
            return Self::from_fn(pager, geometry, brick, |_| value);
        }
        let count = layout.count();
        let first = pager.add_bricks(count);
        let bits = || {
            (0..count)
                .map(|_| AtomicU32::new(value.to_bits()))
                .collect()
        };
        Ok(Self {
            geometry,
            layout,
            pager,
            first,
            paged: (0..count).map(|_| AtomicBool::new(false)).collect(),
            constant: bits(),
            min: bits(),
            max: bits(),
        })
    }

    /// The geometry.
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// The brick layout.
    pub fn layout(&self) -> &BrickLayout {
        &self.layout
    }

    /// The pager.
    pub fn pager(&self) -> &Arc<Pager> {
        &self.pager
    }

    /// The pager's number of brick `id` of this field (for prefetch orders).
    pub fn pager_brick(&self, id: usize) -> usize {
        self.first + id
    }

    /// Bricks stored in the pager (the others are constants).
    pub fn stored_bricks(&self) -> usize {
        self.paged
            .iter()
            .filter(|p| p.load(Ordering::Relaxed))
            .count()
    }

    /// Bytes the field keeps in memory besides the pool: per brick a flag, a constant and
    /// a range.
    pub fn resident_overhead_bytes(&self) -> u64 {
        self.layout.count() as u64 * Self::BYTES_PER_BRICK
    }

    /// Bytes of per-brick bookkeeping a field keeps in memory: the paged flag (1), the
    /// constant (4) and the range (8).
    pub const BYTES_PER_BRICK: u64 = 13;

    fn check_brick(&self, id: usize) -> Result<(), PagingError> {
        if id < self.layout.count() {
            Ok(())
        } else {
            Err(PagingError::NoSuchBrick {
                brick: id,
                count: self.layout.count(),
            })
        }
    }

    /// Brick `id` pinned for writing, a constant brick turned into a stored one first.
    fn write_pin(&self, id: usize) -> Result<crate::pager::WritePin, PagingError> {
        if self.paged[id].load(Ordering::Acquire) {
            return self.pager.write(self.first + id);
        }
        let mut pin = self.pager.overwrite(self.first + id)?;
        pin.fill(f32::from_bits(self.constant[id].load(Ordering::Relaxed)));
        self.paged[id].store(true, Ordering::Release);
        Ok(pin)
    }

    /// Brick `id` as stored (pinned while the view lives, if paged).
    pub fn brick(&self, id: usize) -> Result<BrickView, PagingError> {
        self.check_brick(id)?;
        if self.paged[id].load(Ordering::Acquire) {
            Ok(BrickView::Paged(self.pager.read(self.first + id)?))
        } else {
            Ok(BrickView::Constant(f32::from_bits(
                self.constant[id].load(Ordering::Relaxed),
            )))
        }
    }

    /// The value of cell `cell` (pins its brick for the call: for tests and sparse
    /// lookups; solvers read whole bricks or slabs).
    pub fn get(&self, cell: [usize; 3]) -> Result<f32, PagingError> {
        let dims = self.geometry.dims();
        if (0..3).any(|a| cell[a] >= dims[a]) {
            return Err(PagingError::Shape(format!(
                "cell {cell:?} is outside the {dims:?} grid"
            )));
        }
        let (id, local) = self.layout.locate(cell);
        Ok(self.brick(id)?.get(&self.layout, local.map(|c| c as isize)))
    }

    /// (min, max) over brick `id` and its apron — bounds of the trilinear interpolant in
    /// the brick's cells — or `None` for a brick the field does not have.
    pub fn brick_range(&self, id: usize) -> Option<(f32, f32)> {
        (id < self.layout.count()).then(|| {
            (
                f32::from_bits(self.min[id].load(Ordering::Relaxed)),
                f32::from_bits(self.max[id].load(Ordering::Relaxed)),
            )
        })
    }

    /// The one value of every cell, if the field is uniform (every brick's range, apron
    /// included, is that value alone): from the ranges, no brick is read.
    pub fn uniform_value(&self) -> Option<f32> {
        let first = self.brick_range(0)?.0;
        (0..self.layout.count())
            .all(|id| self.brick_range(id) == Some((first, first)))
            .then_some(first)
    }

    /// The largest brick maximum over the bricks holding cells `lo..=hi` (clamped): a
    /// majorant of the trilinear interpolant there, from the ranges alone (no brick is
    /// read).
    pub fn max_over_cells(&self, lo: [usize; 3], hi: [usize; 3]) -> f32 {
        self.layout
            .bricks_in_box(lo, hi)
            .map(|id| f32::from_bits(self.max[id].load(Ordering::Relaxed)))
            .fold(f32::NEG_INFINITY, f32::max)
    }

    fn set_range(&self, id: usize, stored: &[f32]) {
        let lo = stored.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = stored.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        self.min[id].store(lo.to_bits(), Ordering::Relaxed);
        self.max[id].store(hi.to_bits(), Ordering::Relaxed);
    }

    /// Slabs z ∈ [z0, z1) into `out` (x fastest, n_x n_y (z1 − z0) values), each value
    /// from the brick that owns it.
    pub fn read_slabs(&self, z0: usize, z1: usize, out: &mut [f32]) -> Result<(), PagingError> {
        let [nx, ny, nz] = self.geometry.dims();
        if !(z0 <= z1 && z1 <= nz && out.len() == nx * ny * (z1 - z0)) {
            return Err(PagingError::Shape(format!(
                "read_slabs: slabs {z0}..{z1} of a grid of {nz} into {} values",
                out.len()
            )));
        }
        let plane = nx * ny;
        for id in self.layout.bricks_of_slabs(z0, z1) {
            let view = self.brick(id)?;
            let o = self.layout.origin(id);
            let e = self.layout.extent(id);
            for k in o[2].max(z0)..(o[2] + e[2]).min(z1) {
                for j in 0..e[1] {
                    let row = (k - z0) * plane + (o[1] + j) * nx + o[0];
                    let local = |i: usize| [i as isize, j as isize, (k - o[2]) as isize];
                    match &view {
                        BrickView::Constant(v) => out[row..row + e[0]].fill(*v),
                        BrickView::Paged(pin) => {
                            let start = self.layout.stored_index(local(0));
                            out[row..row + e[0]].copy_from_slice(&pin[start..start + e[0]]);
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// The window a 7-point stencil on brick layer `layer` (the slabs its bricks own)
    /// reads: slabs max(z₀ − 1, 0) .. min(z₀ + B + 1, n_z), taken from that layer's stored
    /// bricks alone (the slabs above and below are their aprons). Returns the first slab's
    /// z and the values (x fastest).
    pub fn read_layer_window(&self, layer: usize) -> Result<(usize, Vec<f32>), PagingError> {
        let [nx, ny, nz] = self.geometry.dims();
        if layer >= self.layout.bricks()[2] {
            return Err(PagingError::Shape(format!(
                "brick layer {layer} of {}",
                self.layout.bricks()[2]
            )));
        }
        let b = self.layout.brick();
        let z_lo = (layer * b).saturating_sub(1);
        let z_hi = (layer * b + b + 1).min(nz);
        let mut out = vec![0.0; nx * ny * (z_hi - z_lo)];
        let plane = nx * ny;
        let [bx, by, _] = self.layout.bricks();
        for bj in 0..by {
            for bi in 0..bx {
                let id = self.layout.id([bi, bj, layer]);
                let view = self.brick(id)?;
                let o = self.layout.origin(id);
                let e = self.layout.extent(id);
                for z in z_lo..z_hi {
                    let lk = z as isize - o[2] as isize;
                    for j in 0..e[1] {
                        let row = (z - z_lo) * plane + (o[1] + j) * nx + o[0];
                        match &view {
                            BrickView::Constant(v) => out[row..row + e[0]].fill(*v),
                            BrickView::Paged(pin) => {
                                let start = self.layout.stored_index([0, j as isize, lk]);
                                out[row..row + e[0]].copy_from_slice(&pin[start..start + e[0]]);
                            }
                        }
                    }
                }
            }
        }
        Ok((z_lo, out))
    }

    /// Writes brick layer `layer` whole from `window`, the slabs a stencil on it reads
    /// (z_lo = max(z₀ − 1, 0) .. min(z₀ + B + 1, n_z), as [`PagedGrid::read_layer_window`]
    /// returns them): every stored value of the layer's bricks — cells and aprons — comes
    /// from the window, so the bricks are overwritten without being read first. The cells'
    /// other copies (the aprons of the layers below and above) are written when those
    /// layers are, from their own windows: a field written layer by layer this way is
    /// consistent, and each brick moves once.
    pub fn write_layer_window(
        &self,
        layer: usize,
        z_lo: usize,
        window: &[f32],
    ) -> Result<(), PagingError> {
        let [nx, ny, nz] = self.geometry.dims();
        let b = self.layout.brick();
        let plane = nx * ny;
        let expected_lo = (layer * b).saturating_sub(1);
        let z_hi = (layer * b + b + 1).min(nz);
        if layer >= self.layout.bricks()[2]
            || z_lo != expected_lo
            || window.len() != plane * (z_hi - z_lo)
        {
            return Err(PagingError::Shape(format!(
                "write_layer_window: layer {layer} of {} from slab {z_lo} with {} values \
                 (expects slabs {expected_lo}..{z_hi})",
                self.layout.bricks()[2],
                window.len()
            )));
        }
        let edge = self.layout.stored_edge();
        let [bx, by, _] = self.layout.bricks();
        let ids: Vec<usize> = (0..by)
            .flat_map(|bj| (0..bx).map(move |bi| [bi, bj, layer]))
            .map(|c| self.layout.id(c))
            .collect();
        ids.par_iter().try_for_each(|&id| {
            let o = self.layout.origin(id);
            let cell = |a: usize, s: usize, n: usize| (o[a] + s).saturating_sub(1).min(n - 1);
            let mut pin = self.pager.overwrite(self.first + id)?;
            self.paged[id].store(true, Ordering::Release);
            for sk in 0..edge {
                let z = cell(2, sk, nz);
                for sj in 0..edge {
                    let y = cell(1, sj, ny);
                    let at = sk * edge * edge + sj * edge;
                    let row = (z - z_lo) * plane + y * nx;
                    for si in 0..edge {
                        pin[at + si] = window[row + cell(0, si, nx)];
                    }
                }
            }
            self.set_range(id, &pin);
            Ok::<_, PagingError>(())
        })
    }

    /// Writes slabs z ∈ [z0, z0 + n) from `data` (x fastest) into every stored copy of
    /// their cells: the owning bricks and the neighbours' aprons (clamped copies at the
    /// grid's faces included). Constant bricks that change become paged; bricks whose
    /// stored values all become one value stay paged (a later rebuild may fold them).
    pub fn write_slabs(&self, z0: usize, data: &[f32]) -> Result<(), PagingError> {
        let [nx, ny, nz] = self.geometry.dims();
        let plane = nx * ny;
        if !(data.len().is_multiple_of(plane) && z0 + data.len() / plane <= nz) {
            return Err(PagingError::Shape(format!(
                "write_slabs: {} values from slab {z0} are not whole slabs inside a grid of {nz}",
                data.len()
            )));
        }
        let z1 = z0 + data.len() / plane;
        if z1 == z0 {
            return Ok(());
        }
        let b = self.layout.brick();
        let edge = self.layout.stored_edge();
        // Layers whose stored z range [o − 1, o + B] meets [z0, z1); and, at the top face,
        // the layer whose clamped apron repeats slab n_z − 1.
        let first_layer = z0.saturating_sub(1) / b;
        let last_layer = (z1 / b).min(self.layout.bricks()[2] - 1);
        let [bx, by, _] = self.layout.bricks();
        let ids: Vec<usize> = (first_layer..=last_layer)
            .flat_map(|bk| (0..by).flat_map(move |bj| (0..bx).map(move |bi| [bi, bj, bk])))
            .map(|c| self.layout.id(c))
            .collect();
        ids.par_iter().try_for_each(|&id| {
            let o = self.layout.origin(id);
            // Stored positions s (0..edge) map to clamped cells (o + s − 1).
            let cell = |a: usize, s: usize, n: usize| (o[a] + s).saturating_sub(1).min(n - 1);
            let touched: Vec<usize> = (0..edge)
                .filter(|&s| (z0..z1).contains(&cell(2, s, nz)))
                .collect();
            if touched.is_empty() {
                return Ok(());
            }
            let mut pin = self.write_pin(id)?;
            for &sk in &touched {
                let z = cell(2, sk, nz);
                for sj in 0..edge {
                    let y = cell(1, sj, ny);
                    let at = sk * edge * edge + sj * edge;
                    let row = (z - z0) * plane + y * nx;
                    for si in 0..edge {
                        pin[at + si] = data[row + cell(0, si, nx)];
                    }
                }
            }
            self.set_range(id, &pin);
            Ok::<_, PagingError>(())
        })
    }

    /// ∫ f ds from `a` to `b` for the field's trilinear interpolant:
    /// [`Grid::line_integral`] on the paged storage, bit for bit the dense result (the same
    /// walk and arithmetic; each dual cell's corners come from one stored brick, the last
    /// one staying pinned while the walk is inside it).
    pub fn line_integral(&self, a: DVec3, b: DVec3, cutoff: f64) -> Result<f64, PagingError> {
        lucent_grid::line_integral_with(&self.geometry, a, b, cutoff, &mut self.corners())
    }

    /// A reader of trilinear samples ([`PagedSampler`]).
    pub fn sampler(&self) -> PagedSampler<'_> {
        PagedSampler {
            field: self,
            current: None,
        }
    }

    /// A reader of dual-cell corners for [`lucent_grid::line_integral_with`].
    pub fn corners(&self) -> PagedCorners<'_> {
        PagedCorners {
            field: self,
            current: None,
        }
    }

    /// Plane `index` across `axis` (the cells whose coordinate along `axis` is `index`)
    /// into `out`, the cell with coordinates (c_b, c_d) along the other two axes
    /// (b = axis + 1, d = axis + 2, mod 3) at `c_b + n_b c_d`: for axis z the slab, x
    /// fastest.
    pub fn read_plane(
        &self,
        axis: usize,
        index: usize,
        out: &mut [f32],
    ) -> Result<(), PagingError> {
        let dims = self.geometry.dims();
        let (b, d) = ((axis + 1) % 3, (axis + 2) % 3);
        if !(axis < 3 && index < dims[axis] && out.len() == dims[b] * dims[d]) {
            return Err(PagingError::Shape(format!(
                "read_plane: plane {index} across axis {axis} of {dims:?} into {} values",
                out.len()
            )));
        }
        let brick = self.layout.brick();
        let bricks = self.layout.bricks();
        for kd in 0..bricks[d] {
            for kb in 0..bricks[b] {
                let mut coords = [0; 3];
                coords[axis] = index / brick;
                coords[b] = kb;
                coords[d] = kd;
                let id = self.layout.id(coords);
                let view = self.brick(id)?;
                let (o, e) = (self.layout.origin(id), self.layout.extent(id));
                for jd in 0..e[d] {
                    for jb in 0..e[b] {
                        let mut local = [0isize; 3];
                        local[axis] = (index - o[axis]) as isize;
                        local[b] = jb as isize;
                        local[d] = jd as isize;
                        out[(o[b] + jb) + dims[b] * (o[d] + jd)] = view.get(&self.layout, local);
                    }
                }
            }
        }
        Ok(())
    }

    /// Writes plane `index` across `axis` from `data` (positions as in
    /// [`PagedGrid::read_plane`]) into every stored copy of its cells, as
    /// [`PagedGrid::write_slabs`] does for slabs.
    pub fn write_plane(&self, axis: usize, index: usize, data: &[f32]) -> Result<(), PagingError> {
        let dims = self.geometry.dims();
        let (b, d) = ((axis + 1) % 3, (axis + 2) % 3);
        if !(axis < 3 && index < dims[axis] && data.len() == dims[b] * dims[d]) {
            return Err(PagingError::Shape(format!(
                "write_plane: {} values as plane {index} across axis {axis} of {dims:?}",
                data.len()
            )));
        }
        let brick = self.layout.brick();
        let edge = self.layout.stored_edge();
        let bricks = self.layout.bricks();
        // Brick layers along `axis` whose stored range [o − 1, o + B] (clamped) holds it.
        let first = index.saturating_sub(1) / brick;
        let last = ((index + 1) / brick).min(bricks[axis] - 1);
        let mut ids = Vec::new();
        for ka in first..=last {
            for kd in 0..bricks[d] {
                for kb in 0..bricks[b] {
                    let mut coords = [0; 3];
                    coords[axis] = ka;
                    coords[b] = kb;
                    coords[d] = kd;
                    ids.push(self.layout.id(coords));
                }
            }
        }
        ids.par_iter().try_for_each(|&id| {
            let o = self.layout.origin(id);
            let cell = |a: usize, s: usize| (o[a] + s).saturating_sub(1).min(dims[a] - 1);
            let touched: Vec<usize> = (0..edge).filter(|&s| cell(axis, s) == index).collect();
            if touched.is_empty() {
                return Ok(());
            }
            let mut pin = self.write_pin(id)?;
            let stride = [1, edge, edge * edge];
            for &sa in &touched {
                for sd in 0..edge {
                    let row = cell(d, sd) * dims[b];
                    for sb in 0..edge {
                        let at = sa * stride[axis] + sb * stride[b] + sd * stride[d];
                        pin[at] = data[row + cell(b, sb)];
                    }
                }
            }
            self.set_range(id, &pin);
            Ok::<_, PagingError>(())
        })
    }

    /// The whole field as a dense grid (for tests and fields that fit).
    pub fn to_grid(&self) -> Result<Grid, PagingError> {
        let [nx, ny, nz] = self.geometry.dims();
        let mut data = vec![0.0; nx * ny * nz];
        self.read_slabs(0, nz, &mut data)?;
        Ok(Grid::from_vec(self.geometry, data)?)
    }
}

/// Dual-cell corners of a [`PagedGrid`], read from the stored brick of the lower corner
/// (its apron holds the upper ones); the brick last read stays pinned.
#[derive(Debug)]
pub struct PagedCorners<'a> {
    field: &'a PagedGrid,
    current: Option<(usize, BrickView)>,
}

impl DualCorners for PagedCorners<'_> {
    type Error = PagingError;

    /// The cell's brick; empty when its range (apron included) is [0, 0], as the
    /// constant bricks of empty space are: crossed without a pin.
    #[inline]
    fn region(&mut self, cell: [usize; 3]) -> Option<([[usize; 3]; 2], bool)> {
        let layout = &self.field.layout;
        let (id, _) = layout.locate(cell);
        let (min, max) = self.field.brick_range(id)?;
        Some((layout.cell_box(id), min == 0.0 && max == 0.0))
    }

    #[inline]
    fn corners(&mut self, lo: [usize; 3], hi: [usize; 3]) -> Result<[f64; 8], PagingError> {
        let layout = &self.field.layout;
        let (id, _) = layout.locate(lo);
        let view = match &self.current {
            Some((current, view)) if *current == id => view,
            _ => {
                // Unpin the old brick before pinning the next (a pool of one suffices).
                self.current = None;
                &self.current.insert((id, self.field.brick(id)?)).1
            }
        };
        let o = layout.origin(id);
        let local = |c: [usize; 3]| [0, 1, 2].map(|a| c[a] as isize - o[a] as isize);
        let at = |c: [usize; 3]| f64::from(view.get(layout, local(c)));
        Ok([
            at(lo),
            at([hi[0], lo[1], lo[2]]),
            at([lo[0], hi[1], lo[2]]),
            at([hi[0], hi[1], lo[2]]),
            at([lo[0], lo[1], hi[2]]),
            at([hi[0], lo[1], hi[2]]),
            at([lo[0], hi[1], hi[2]]),
            at(hi),
        ])
    }
}

/// Trilinear samples of a [`PagedGrid`] with the bits of [`Grid::sample_trilinear`] on the
/// same values: the eight corners come from the stored brick of the lower corner (its apron
/// holds the upper ones, clamped copies at the faces), blended by the dense grid's own
/// arithmetic ([`lucent_grid::trilinear_blend`]). The brick last read stays pinned, so a
/// path sampling along a flight pins once per brick it enters.
#[derive(Debug)]
pub struct PagedSampler<'a> {
    field: &'a PagedGrid,
    current: Option<(usize, BrickView)>,
}

impl PagedSampler<'_> {
    /// The field's trilinear interpolant at world point `p` (clamped at the faces).
    #[inline]
    pub fn sample_trilinear(&mut self, p: DVec3) -> Result<f32, PagingError> {
        let field = self.field;
        let layout = &field.layout;
        let (lo, t) =
            lucent_grid::trilinear_cell(field.geometry.dims(), field.geometry.world_to_voxel(p));
        let (id, local) = layout.locate(lo);
        let view = match &self.current {
            Some((current, view)) if *current == id => view,
            _ => {
                self.current = None;
                &self.current.insert((id, field.brick(id)?)).1
            }
        };
        if let BrickView::Constant(v) = view {
            return Ok(lucent_grid::trilinear_blend([f64::from(*v); 8], t));
        }
        let [x, y, z] = local.map(|c| c as isize);
        let at =
            |dx: isize, dy: isize, dz: isize| f64::from(view.get(layout, [x + dx, y + dy, z + dz]));
        Ok(lucent_grid::trilinear_blend(
            [
                at(0, 0, 0),
                at(1, 0, 0),
                at(0, 1, 0),
                at(1, 1, 0),
                at(0, 0, 1),
                at(1, 0, 1),
                at(0, 1, 1),
                at(1, 1, 1),
            ],
            t,
        ))
    }
}
