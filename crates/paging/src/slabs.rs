//! Solver state paged as whole z-slabs: the layout for fields that a stencil reads in the
//! z-slab streaming order and that need no apron (iterates, residuals, right-hand sides;
//! f64 where a stopping test sits below f32 rounding).
//!
//! A [`PagedSlabs`] cuts an nx × ny × nz field into pages of `slabs_per_page` whole
//! slabs, each page one brick of its [`Pager`] (so several fields share one pool and one
//! budget), and moves slabs in and out of caller buffers. A slab is contiguous in a page,
//! so a read or write is one copy; a page that holds one slab is overwritten without
//! being loaded.

use std::sync::Arc;

use crate::error::PagingError;
use crate::pager::{Element, Pager};

/// A field of `T` on an nx × ny × nz grid, paged in pages of whole z-slabs.
#[derive(Debug)]
pub struct PagedSlabs<T: Element = f64> {
    pager: Arc<Pager<T>>,
    /// The pager's number of this field's page 0.
    first: usize,
    dims: [usize; 3],
    slabs_per_page: usize,
}

impl<T: Element> PagedSlabs<T> {
    /// Values per page for `slabs_per_page` slabs of a grid of `dims`: the `brick_len` of
    /// the pager such fields share.
    pub fn page_len(dims: [usize; 3], slabs_per_page: usize) -> usize {
        dims[0] * dims[1] * slabs_per_page.max(1)
    }

    /// A field on a grid of `dims` in `pager`, whose bricks hold a whole number of slabs
    /// (its pages are new bricks of the pager, all fresh: they read as its fill).
    pub fn new(pager: Arc<Pager<T>>, dims: [usize; 3]) -> Result<Self, PagingError> {
        let slab = dims[0] * dims[1];
        if slab == 0 || dims[2] == 0 {
            return Err(PagingError::Shape(format!(
                "paged slabs of an empty grid {dims:?}"
            )));
        }
        if !pager.brick_len().is_multiple_of(slab) {
            return Err(PagingError::Shape(format!(
                "pages of {} values do not hold whole slabs of {slab}",
                pager.brick_len()
            )));
        }
        let slabs_per_page = pager.brick_len() / slab;
        let pages = dims[2].div_ceil(slabs_per_page);
        let first = pager.add_bricks(pages);
        Ok(Self {
            pager,
            first,
            dims,
            slabs_per_page,
        })
    }

    /// The grid's dimensions.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Values per slab.
    pub fn slab_len(&self) -> usize {
        self.dims[0] * self.dims[1]
    }

    /// The pager.
    pub fn pager(&self) -> &Arc<Pager<T>> {
        &self.pager
    }

    /// The page holding slab `z` and the slab's offset in it.
    fn locate(&self, z: usize, len: usize) -> Result<(usize, usize), PagingError> {
        if z >= self.dims[2] || len != self.slab_len() {
            return Err(PagingError::Shape(format!(
                "slab {z} ({len} values) of a field of {} slabs of {}",
                self.dims[2],
                self.slab_len()
            )));
        }
        let page = self.first + z / self.slabs_per_page;
        Ok((page, (z % self.slabs_per_page) * self.slab_len()))
    }

    /// Forgets every value: the field reads as the pager's fill again, its pages freed
    /// without a write-back (state reused for another solve). Fails while a page is pinned.
    pub fn clear(&self) -> Result<(), PagingError> {
        for page in 0..self.dims[2].div_ceil(self.slabs_per_page) {
            self.pager.discard(self.first + page)?;
        }
        Ok(())
    }

    /// Copies slab `z` into `out` (one slab's values).
    pub fn read_slab(&self, z: usize, out: &mut [T]) -> Result<(), PagingError> {
        let (page, offset) = self.locate(z, out.len())?;
        let pin = self.pager.read(page)?;
        out.copy_from_slice(&pin[offset..offset + out.len()]);
        Ok(())
    }

    /// Writes `data` (one slab's values) as slab `z`.
    pub fn write_slab(&self, z: usize, data: &[T]) -> Result<(), PagingError> {
        let (page, offset) = self.locate(z, data.len())?;
        let mut pin = if self.slabs_per_page == 1 {
            self.pager.overwrite(page)?
        } else {
            self.pager.write(page)?
        };
        pin[offset..offset + data.len()].copy_from_slice(data);
        Ok(())
    }
}
