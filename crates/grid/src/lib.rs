//! # lucent-grid: voxel grids, sparse bricks and real volume files
//!
//! The one grid type the solvers sweep, the sparse form that makes empty space free, and the
//! way users bring their own data (CT and MRI scans, simulation output, OpenVDB smoke,
//! Mitsuba grids). This crate knows nothing of light: it stores, moves and reads numbers on
//! cells.
//!
//! ## Conventions
//! - **Cell-centred.** A [`GridGeometry`] has `dims` cells of size `spacing` (anisotropic
//!   allowed) from the corner `origin`; cell (i, j, k) is centred at
//!   `origin + (i + ½, j + ½, k + ½)·spacing`. Lengths are in scene units.
//! - **x-fastest storage**: index `i + n_x (j + n_y k)`; a z-slab is contiguous, and rayon
//!   parallelism goes over z-slabs ([`Grid::slabs_mut`]).
//! - **f32 storage, f64 reductions**, reduced per slab and then in order, so results do not
//!   depend on the thread count.
//! - **Sample-based files** (NRRD, MetaImage, VTK, VDB) put their first sample at the centre
//!   of cell (0, 0, 0); Mitsuba's box is the box the cells fill.
//!
//! ## Contents
//! - [`Grid`]: dense f32 grid; trilinear sampling with clamping (exact for linear fields);
//!   statistics. [`resample`]: 2× restriction (volume-weighted) and constant / trilinear
//!   prolongation (the multigrid transfer operators), and resampling to any resolution.
//! - [`BrickLayout`]: the one brick layout (B³ bricks, stored with a one-cell apron so
//!   stencils and trilinear samples read one brick; z-slab and per-octant wavefront
//!   streaming orders) shared by the bricked grid, the pager and the ordinates' sweeps.
//! - [`BrickedGrid`]: 8³ bricks by default; only non-constant bricks are stored; per-brick
//!   min/max (apron included: a bound of the trilinear interpolant) gives the majorant
//!   grid and `max_over` a box for delta tracking and empty-space skipping; memory
//!   accounted in bytes.
//! - [`transfer`]: piecewise-linear transfer functions (serde) from scalar values to
//!   extinction, albedo and colour.
//! - [`procedural`]: sphere, box, slab and torus SDFs and densities, a Gaussian blob, a
//!   seeded fBm noise cloud.
//! - [`io`]: raw, NRRD, MetaImage, legacy VTK, Mitsuba `.vol`, NumPy `.npy` (read and write)
//!   and OpenVDB (read). Bad files give a [`GridError`] naming the file, before any large
//!   allocation; reads respect [`io::LoadOptions::memory_budget`].
//!
//! ## Example
//! ```
//! use glam::DVec3;
//! use lucent_grid::{BrickedGrid, Grid, GridGeometry};
//! use lucent_grid::procedural::NoiseCloud;
//!
//! let geometry = GridGeometry::new([64, 64, 64], DVec3::splat(1.0 / 64.0), DVec3::ZERO)?;
//! let cloud = NoiseCloud::new(7, DVec3::splat(0.5), 0.45).rasterize(geometry)?;
//! let bricks = BrickedGrid::from_dense(&cloud, 8)?;
//! assert_eq!(bricks.get(10, 20, 30), cloud.get(10, 20, 30));
//! assert!(bricks.memory_bytes() < bricks.dense_memory_bytes());
//! // Linear fields are reproduced exactly by trilinear sampling.
//! let ramp = Grid::from_fn(geometry, |p| (2.0 * p.x + p.z) as f32);
//! let p = DVec3::new(0.31, 0.52, 0.77);
//! assert!((ramp.sample_trilinear(p) - (2.0 * 0.31 + 0.77) as f32).abs() < 1e-6);
//! # Ok::<(), lucent_grid::GridError>(())
//! ```

mod bricked;
mod bricks;
mod dense;
mod error;
mod geometry;
pub mod io;
mod line;
pub mod procedural;
pub mod resample;
pub mod transfer;

pub use bricked::BrickedGrid;
pub use bricks::BrickLayout;
pub use dense::{Grid, GridStats, trilinear_blend, trilinear_cell};
pub use error::GridError;
pub use geometry::{GridGeometry, MAX_COORDINATE, MAX_VOXELS, box_cells, ray_box};
pub use line::{DualCorners, EmptyBricks, line_integral_with};
