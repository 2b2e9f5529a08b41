//! # lucent-paging: volumes larger than memory (Bernabei, chapter 5)
//!
//! A 1024³ f32 field is 4 GiB, and a solver needs several. Bernabei's chapter 5 keeps
//! bricks of the volume in a fixed pool with a page table, evicts the not-recently-used
//! ones, writes dirty bricks back, and streams bricks in the order the sweeps visit them.
//! This crate is that machinery, safe Rust throughout:
//!
//! - [`Pager`]: a pool of brick slots under a byte budget, a page table (fresh / stored /
//!   resident), dirty and referenced bits, [`Eviction::Lru`] or [`Eviction::Nru`] (the
//!   clock), dirty write-back, [`Pager::prefetch`] along a streaming order, counters
//!   ([`PagerStats`]: hits, misses, evictions, bytes read and written), and
//!   [`Pager::write_back`] to write chosen bricks behind a sweep with the I/O outside the
//!   lock. Bricks hold f32 values, or any [`Element`] (f64 for solver state whose stopping
//!   test sits below f32 rounding). A brick in use is
//!   *pinned* ([`ReadPin`], [`WritePin`]): pins own a reference to their slot and hold its
//!   lock, so a pinned brick is never evicted and never changes under a reader — with no
//!   `unsafe` (owned lock guards of `parking_lot`).
//! - [`BrickStore`]: where evicted bricks go. [`FileStore`] is an unnamed temporary file
//!   written and read by positioned I/O (why not memory mapping: see [`store`]);
//!   [`MemoryStore`] keeps them in memory.
//! - [`PagedGrid`]: a field on cells stored as the bricks of
//!   [`lucent_grid::BrickLayout`] with their one-cell aprons: constant bricks cost one
//!   number (a sparse cloud costs memory and disk only where it is dense), the others are
//!   paged; per-brick ranges (apron included) bound the trilinear interpolant, so
//!   majorants come from the field. Writes update every stored copy of a cell (the owner
//!   and the neighbours' aprons), so a stencil or a trilinear sample on one stored brick
//!   never sees a stale neighbour.
//! - [`PagedSlabs`]: solver state that needs no apron (iterates, residuals, right-hand
//!   sides; f64 where a stopping test needs it) paged as whole z-slabs, the stencils'
//!   streaming order.
//! - [`for_each_layer`]: a field streamed through a stencil brick layer by brick layer (the
//!   z-slab order), the next layer prefetched on a helper thread.
//! - [`skewed_steps`] and [`skewed_steps_paged`]: time skewing — T steps of a stencil one
//!   slab deep in one pass over the field, each brick moved once per T steps, the result
//!   bit for bit T plain sweeps; the paged pass reads its input ahead on a reader thread
//!   into host buffers: out of core at 95–108 % of the same pass in memory at 1/16
//!   resident (BENCHMARKS.md).
//!
//! ## Units and limits
//!
//! Budgets and counters are bytes; values are f32 as everywhere in lucent. A pager refuses
//! a budget below the working set its user declares ([`PagingError::BudgetTooSmall`],
//! before anything is allocated), and a pin when every slot is pinned
//! ([`PagingError::PoolExhausted`]). A failing backing store is an error
//! ([`PagingError::Io`]) and never loses data: a brick whose write-back failed stays
//! resident and dirty.
//!
//! ## Example
//! ```
//! use std::sync::Arc;
//! use glam::DVec3;
//! use lucent_grid::{BrickLayout, Grid, GridGeometry};
//! use lucent_paging::{Eviction, FileStore, Pager, PagerOptions, PagedGrid};
//!
//! let geometry = GridGeometry::new([40, 24, 33], DVec3::splat(0.1), DVec3::ZERO)?;
//! let blob = Grid::from_fn(geometry, |p| (4.0 - (p - DVec3::splat(1.5)).length_squared()).max(0.0) as f32);
//! // Bricks of 8³ cells, stored with their apron as 10³ values: a pool of 16 of them.
//! let brick_len = BrickLayout::new(geometry.dims(), 8)?.stored_len();
//! let pager = Arc::new(Pager::new(
//!     Box::new(FileStore::create()?),
//!     0,
//!     brick_len,
//!     4,
//!     PagerOptions { budget_bytes: 16 * 4 * brick_len as u64, eviction: Eviction::Nru, fill: 0.0 },
//! )?);
//! let paged = PagedGrid::from_grid(pager.clone(), &blob, 8)?;
//! assert_eq!(paged.to_grid()?, blob); // bit for bit, through the backing file
//! assert!(pager.stats().bytes_read > 0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod error;
mod field;
mod pager;
mod slabs;
pub mod store;
mod stream;

pub use error::PagingError;
pub use field::{BrickView, PagedCorners, PagedGrid, PagedSampler};
pub use pager::{Element, Eviction, Pager, PagerOptions, PagerStats, ReadPin, WritePin};
pub use slabs::PagedSlabs;
pub use store::{BrickStore, FileStore, MemoryStore};
pub use stream::{for_each_layer, skewed_steps, skewed_steps_paged};
