//! Headerless raw volumes: the layout (dims, voxel type, byte order, placement) comes from
//! the caller, because the file has none. The payload must be exactly dims × sample size.

use std::path::Path;

use glam::DVec3;

use super::{
    Endian, LoadOptions, ScalarType, checked_voxels, decode, encode, read_file, write_file,
};
use crate::dense::Grid;
use crate::error::GridError;

/// What a raw file holds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawLayout {
    /// Cells per axis, x fastest in the file.
    pub dims: [usize; 3],
    /// Voxel type.
    pub scalar: ScalarType,
    /// Byte order.
    pub endian: Endian,
    /// Cell size.
    pub spacing: DVec3,
    /// Corner of cell (0, 0, 0).
    pub origin: DVec3,
}

impl RawLayout {
    /// Little-endian samples on a unit-spaced grid at the origin.
    pub fn new(dims: [usize; 3], scalar: ScalarType) -> Self {
        Self {
            dims,
            scalar,
            endian: Endian::Little,
            spacing: DVec3::ONE,
            origin: DVec3::ZERO,
        }
    }
}

/// Reads a raw file.
pub fn read(
    path: impl AsRef<Path>,
    layout: &RawLayout,
    options: &LoadOptions,
) -> Result<Grid, GridError> {
    let path = path.as_ref();
    let voxels = checked_voxels(path, "raw", layout.dims)?;
    options.reserve_voxels(path, voxels, layout.scalar)?;
    let expected = voxels * layout.scalar.size() as u64;
    let found = std::fs::metadata(path)
        .map_err(|source| GridError::Io {
            path: path.to_owned(),
            source,
        })?
        .len();
    if found != expected {
        return Err(GridError::SizeMismatch {
            path: path.to_owned(),
            expected,
            found,
        });
    }
    parse(&read_file(path, options)?, path, layout, options)
}

/// Decodes raw bytes already in memory (`path` only names them in errors).
pub fn parse(
    bytes: &[u8],
    path: &Path,
    layout: &RawLayout,
    options: &LoadOptions,
) -> Result<Grid, GridError> {
    let geometry = super::geometry(path, "raw", layout.dims, layout.spacing, layout.origin)?;
    let voxels = checked_voxels(path, "raw", layout.dims)?;
    options.reserve_voxels(path, voxels, layout.scalar)?;
    let expected = voxels * layout.scalar.size() as u64;
    if bytes.len() as u64 != expected {
        return Err(GridError::SizeMismatch {
            path: path.to_owned(),
            expected,
            found: bytes.len() as u64,
        });
    }
    super::finite_grid(path, geometry, decode(bytes, layout.scalar, layout.endian))
}

/// Writes the grid's values as `scalar` samples; fails with [`GridError::Lossy`] if a value
/// does not fit the type exactly. The geometry is not stored (raw files have no header).
pub fn write(
    path: impl AsRef<Path>,
    grid: &Grid,
    scalar: ScalarType,
    endian: Endian,
) -> Result<(), GridError> {
    let path = path.as_ref();
    write_file(path, &encode(path, grid.data(), scalar, endian)?)
}
