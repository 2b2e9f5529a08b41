//! Mitsuba 3's binary `.vol` grid (docs/reference-cases.md), little-endian:
//!
//! | bytes | content |
//! |---|---|
//! | 0–2 | `VOL` |
//! | 3 | version 3 |
//! | 4–7 | encoding, i32 = 1 (float32, the only one) |
//! | 8–19 | x, y, z resolution, i32 |
//! | 20–23 | channels, i32 |
//! | 24–47 | bounding box, 6 × f32 (min xyz, max xyz) |
//! | 48– | f32 data, `data[((z·ny + y)·nx + x)·channels + c]` |
//!
//! The box is the region the cells fill. Mitsuba maps the grid to the unit cube and ignores
//! the box unless told otherwise; lucent uses the box when it is finite and non-degenerate
//! and falls back to the unit cube otherwise (`torus_sdfgrid.vol` stores denormal garbage).

use std::path::Path;

use glam::DVec3;

use super::{
    Cursor, Endian, LoadOptions, ScalarType, checked_voxels, decode, read_file, write_file,
};
use crate::dense::Grid;
use crate::error::GridError;
use crate::geometry::GridGeometry;

/// Reads a single-channel `.vol` file.
pub fn read(path: impl AsRef<Path>, options: &LoadOptions) -> Result<Grid, GridError> {
    let path = path.as_ref();
    let mut channels = read_channels(path, options)?;
    if channels.len() != 1 {
        return Err(GridError::Unsupported {
            path: path.to_owned(),
            what: "channel count for a scalar grid (use mitsuba::read_channels)",
            value: channels.len().to_string(),
        });
    }
    Ok(channels.remove(0))
}

/// Reads every channel of a `.vol` file, one grid per channel.
pub fn read_channels(
    path: impl AsRef<Path>,
    options: &LoadOptions,
) -> Result<Vec<Grid>, GridError> {
    let path = path.as_ref();
    parse(&read_file(path, options)?, path, options)
}

/// Decodes a `.vol` file already in memory.
pub fn parse(bytes: &[u8], path: &Path, options: &LoadOptions) -> Result<Vec<Grid>, GridError> {
    let malformed = |reason: String| GridError::Malformed {
        path: path.to_owned(),
        format: "Mitsuba .vol",
        reason,
    };
    let mut c = Cursor::new(bytes, path);
    if c.take(3, "magic")? != b"VOL" {
        return Err(malformed("missing VOL magic".into()));
    }
    let version = c.u8("version")?;
    if version != 3 {
        return Err(GridError::Unsupported {
            path: path.to_owned(),
            what: "vol version",
            value: version.to_string(),
        });
    }
    let encoding = c.i32("encoding")?;
    if encoding != 1 {
        return Err(GridError::Unsupported {
            path: path.to_owned(),
            what: "vol encoding",
            value: encoding.to_string(),
        });
    }
    let mut dims = [0usize; 3];
    for d in &mut dims {
        let v = c.i32("resolution")?;
        *d = usize::try_from(v).map_err(|_| malformed(format!("negative resolution {v}")))?;
    }
    let channels = c.i32("channels")?;
    let channels = usize::try_from(channels)
        .ok()
        .filter(|&n| (1..=64).contains(&n))
        .ok_or_else(|| malformed(format!("{channels} channels")))?;
    let mut bbox = [0f32; 6];
    for b in &mut bbox {
        *b = c.f32("bounding box")?;
    }
    let voxels = checked_voxels(path, "Mitsuba .vol", dims)?;
    let samples = voxels.saturating_mul(channels as u64);
    options.reserve_voxels(path, samples, ScalarType::F32)?;
    let expected = samples.saturating_mul(4);
    if c.remaining() as u64 != expected {
        return Err(GridError::SizeMismatch {
            path: path.to_owned(),
            expected,
            found: c.remaining() as u64,
        });
    }
    let (min, max) = (
        DVec3::new(bbox[0].into(), bbox[1].into(), bbox[2].into()),
        DVec3::new(bbox[3].into(), bbox[4].into(), bbox[5].into()),
    );
    let usable = min.is_finite() && max.is_finite() && (max - min).min_element() > 1e-30;
    let (min, max) = if usable {
        (min, max)
    } else {
        (DVec3::ZERO, DVec3::ONE)
    };
    let geometry =
        GridGeometry::from_bounds(dims, min, max).map_err(|e| malformed(e.to_string()))?;
    let values = decode(
        c.take(expected as usize, "voxel data")?,
        ScalarType::F32,
        Endian::Little,
    );
    (0..channels)
        .map(|ch| {
            super::finite_grid(
                path,
                geometry,
                values.iter().skip(ch).step_by(channels).copied().collect(),
            )
        })
        .collect()
}

/// Writes one or more channels (all on the same geometry) as a `.vol` file with the grid's
/// box.
pub fn write(path: impl AsRef<Path>, channels: &[&Grid]) -> Result<(), GridError> {
    let path = path.as_ref();
    let first = channels
        .first()
        .ok_or_else(|| GridError::InvalidParameter {
            name: "channels",
            reason: "need at least one grid".into(),
        })?;
    if channels.iter().any(|g| g.geometry() != first.geometry()) {
        return Err(GridError::Mismatch(
            "all channels of a .vol file share one geometry".into(),
        ));
    }
    // No file lucent writes holds NaN or an infinity.
    for grid in channels {
        super::check_finite(path, grid.geometry(), grid.data())?;
    }
    let dims = first.dims();
    let to_i32 = |n: usize| {
        i32::try_from(n)
            .map_err(|_| GridError::Mismatch(format!("{n} does not fit the format's i32")))
    };
    let (min, max) = first.geometry().bounds();
    let mut out = Vec::with_capacity(48 + 4 * first.data().len() * channels.len());
    out.extend_from_slice(b"VOL\x03");
    out.extend_from_slice(&1i32.to_le_bytes());
    for d in dims {
        out.extend_from_slice(&to_i32(d)?.to_le_bytes());
    }
    out.extend_from_slice(&to_i32(channels.len())?.to_le_bytes());
    for v in [min.x, min.y, min.z, max.x, max.y, max.z] {
        out.extend_from_slice(&(v as f32).to_le_bytes());
    }
    for index in 0..first.data().len() {
        for grid in channels {
            out.extend_from_slice(&grid.data()[index].to_le_bytes());
        }
    }
    write_file(path, &out)
}
