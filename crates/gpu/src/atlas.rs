//! A brick atlas: a paged field's stored bricks in one storage buffer, found through a
//! software page table (WebGPU has no sparse resources).
//!
//! Per brick of lucent-grid's `BrickLayout` the table holds two words: the brick's slot in
//! the atlas, or `CONSTANT_BRICK` for a constant brick, whose value (f32 bits) is the
//! second word. A stored brick keeps its one-cell apron, (B + 2)³ values, so a kernel that
//! reads a cell and its neighbours inside one brick finds them in one slot. Kernels read it
//! with `shaders/sigma_atlas.wgsl`'s pattern. The atlas is filled from the host pager brick
//! by brick (each pinned only while it is copied): a sparse cloud whose dense form is far
//! beyond one binding fits when its non-constant bricks do.

use lucent_paging::{BrickView, PagedGrid};

use crate::context::GpuContext;
use crate::error::GpuError;
use crate::field::{DeviceField, DeviceIndices};

/// The page-table word of a constant brick.
pub const CONSTANT_BRICK: u32 = u32::MAX;

/// A paged field's bricks on the device.
#[derive(Debug)]
pub struct BrickAtlas {
    atlas: DeviceField,
    table: DeviceIndices,
    brick: usize,
    slots: usize,
}

impl BrickAtlas {
    /// Device bytes of `field`'s atlas and table.
    pub fn bytes(field: &PagedGrid) -> u64 {
        let layout = field.layout();
        (field.stored_bricks() * layout.stored_len()) as u64 * 4 + layout.count() as u64 * 8
    }

    /// Uploads `field` (every value finite, and non-negative with `nonnegative`), after
    /// checking the atlas and its table against the adapter's binding limit.
    pub fn upload(
        context: &GpuContext,
        what: &str,
        field: &PagedGrid,
        nonnegative: bool,
    ) -> Result<Self, GpuError> {
        let layout = field.layout();
        let stored = field.stored_bricks();
        context.check_binding(
            &format!("{what} (brick atlas)"),
            (stored.max(1) * layout.stored_len()) as u64 * 4,
        )?;
        context.check_binding(&format!("{what} (page table)"), layout.count() as u64 * 8)?;
        let source = |e: lucent_paging::PagingError| GpuError::Source {
            what: what.to_owned(),
            reason: e.to_string(),
        };
        let mut table = Vec::with_capacity(2 * layout.count());
        let mut values = Vec::with_capacity(stored * layout.stored_len());
        let mut slots = 0;
        for id in 0..layout.count() {
            match field.brick(id).map_err(source)? {
                BrickView::Constant(v) => {
                    if !v.is_finite() || (nonnegative && v < 0.0) {
                        return Err(GpuError::BadInput {
                            what: format!("{what} (constant brick {id})"),
                            index: id,
                            value: v,
                            problem: if v.is_finite() {
                                "negative"
                            } else {
                                "not finite"
                            },
                        });
                    }
                    table.extend([CONSTANT_BRICK, v.to_bits()]);
                }
                BrickView::Paged(pin) => {
                    table.extend([slots as u32, 0]);
                    values.extend_from_slice(&pin);
                    slots += 1;
                }
            }
        }
        if values.is_empty() {
            values.push(0.0);
        }
        Ok(Self {
            atlas: DeviceField::upload(
                context,
                &format!("{what} (brick atlas)"),
                &values,
                nonnegative,
            )?,
            table: DeviceIndices::upload(context, &format!("{what} (page table)"), &table)?,
            brick: layout.brick(),
            slots,
        })
    }

    /// The atlas, for binding.
    pub fn atlas(&self) -> wgpu::BindingResource<'_> {
        self.atlas.binding()
    }

    /// The page table, for binding.
    pub fn table(&self) -> wgpu::BindingResource<'_> {
        self.table.binding()
    }

    /// Brick edge in cells.
    pub fn brick(&self) -> usize {
        self.brick
    }

    /// Bricks stored in the atlas.
    pub fn slots(&self) -> usize {
        self.slots
    }
}
