//! NumPy `.npy` arrays, so researchers can load fields in Python with `np.load`.
//!
//! A grid is the C-order array `a[z, y, x]` of shape (n_z, n_y, n_x) (Fortran order, shape
//! (n_x, n_y, n_z), is read too). `.npy` has no geometry: grids read back with unit spacing
//! at the origin.

use std::path::Path;

use glam::DVec3;

use super::{
    Cursor, Endian, LoadOptions, ScalarType, checked_voxels, decode, encode, read_file, write_file,
};
use crate::dense::Grid;
use crate::error::GridError;

const MAGIC: &[u8] = b"\x93NUMPY";

/// Reads a `.npy` file holding a 3D array of a [`ScalarType`].
pub fn read(path: impl AsRef<Path>, options: &LoadOptions) -> Result<Grid, GridError> {
    let path = path.as_ref();
    parse(&read_file(path, options)?, path, options)
}

fn malformed(path: &Path, reason: impl Into<String>) -> GridError {
    GridError::Malformed {
        path: path.to_owned(),
        format: "npy",
        reason: reason.into(),
    }
}

/// What a `.npy` header says: the grid's dims, the samples' type and byte order.
pub(crate) struct Header {
    pub(crate) dims: [usize; 3],
    pub(crate) scalar: ScalarType,
    pub(crate) endian: Endian,
}

/// Reads the header at the cursor (magic, version, dict), leaving it at the array data.
pub(crate) fn header(c: &mut Cursor<'_>, path: &Path) -> Result<Header, GridError> {
    if c.take(6, "magic")? != MAGIC {
        return Err(malformed(path, "missing \\x93NUMPY magic"));
    }
    let major = c.u8("version")?;
    let _minor = c.u8("version")?;
    let header_len = match major {
        1 => u16::from_le_bytes(c.array("header length")?) as usize,
        2 | 3 => c.u32("header length")? as usize,
        v => {
            return Err(GridError::Unsupported {
                path: path.to_owned(),
                what: "npy version",
                value: v.to_string(),
            });
        }
    };
    let header = std::str::from_utf8(c.take(header_len, "header")?)
        .map_err(|_| malformed(path, "header is not text"))?;
    let descr = dict_value(header, "descr").ok_or_else(|| malformed(path, "no 'descr'"))?;
    let descr = descr.trim().trim_matches(|ch| ch == '\'' || ch == '"');
    let (scalar, endian) = parse_descr(descr).ok_or_else(|| GridError::Unsupported {
        path: path.to_owned(),
        what: "npy dtype",
        value: descr.to_owned(),
    })?;
    let fortran = dict_value(header, "fortran_order")
        .ok_or_else(|| malformed(path, "no 'fortran_order'"))?
        .trim()
        == "True";
    let shape_text = dict_value(header, "shape").ok_or_else(|| malformed(path, "no 'shape'"))?;
    let shape: Vec<usize> = shape_text
        .trim()
        .trim_start_matches('(')
        .trim_end_matches(')')
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<usize>()
                .map_err(|_| malformed(path, format!("bad shape {shape_text}")))
        })
        .collect::<Result<_, _>>()?;
    if shape.len() != 3 {
        return Err(GridError::Unsupported {
            path: path.to_owned(),
            what: "array rank",
            value: shape.len().to_string(),
        });
    }
    // Both orders put x fastest and z slowest: C order's (n_z, n_y, n_x) and Fortran
    // order's (n_x, n_y, n_z).
    let dims = if fortran {
        [shape[0], shape[1], shape[2]]
    } else {
        [shape[2], shape[1], shape[0]]
    };
    Ok(Header {
        dims,
        scalar,
        endian,
    })
}

/// Decodes a `.npy` file already in memory.
pub fn parse(bytes: &[u8], path: &Path, options: &LoadOptions) -> Result<Grid, GridError> {
    let mut c = Cursor::new(bytes, path);
    let Header {
        dims,
        scalar,
        endian,
    } = header(&mut c, path)?;
    let voxels = checked_voxels(path, "npy", dims)?;
    options.reserve_voxels(path, voxels, scalar)?;
    let expected = voxels * scalar.size() as u64;
    if (c.remaining() as u64) != expected {
        return Err(GridError::SizeMismatch {
            path: path.to_owned(),
            expected,
            found: c.remaining() as u64,
        });
    }
    let payload = c.take(expected as usize, "array data")?;
    let geometry = super::geometry(path, "npy", dims, DVec3::ONE, DVec3::ZERO)?;
    super::finite_grid(path, geometry, decode(payload, scalar, endian))
}

/// The text after `'key':` in a Python dict literal, up to the next top-level comma.
fn dict_value<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let start = header
        .find(&format!("'{key}'"))
        .or_else(|| header.find(&format!("\"{key}\"")))?
        + key.len()
        + 2;
    let rest = header[start..].trim_start().strip_prefix(':')?;
    let mut depth = 0i32;
    for (i, ch) in rest.char_indices() {
        match ch {
            '(' | '[' => depth += 1,
            ')' | ']' => depth -= 1,
            ',' | '}' if depth <= 0 => return Some(&rest[..i]),
            _ => {}
        }
    }
    None
}

fn parse_descr(descr: &str) -> Option<(ScalarType, Endian)> {
    let split = descr
        .len()
        .checked_sub(2)
        .filter(|&n| descr.is_char_boundary(n))?;
    let (order, code) = descr.split_at(split);
    let endian = match order {
        "<" | "|" | "=" => Endian::Little,
        ">" => Endian::Big,
        _ => return None,
    };
    let scalar = match code {
        "u1" => ScalarType::U8,
        "i1" => ScalarType::I8,
        "u2" => ScalarType::U16,
        "i2" => ScalarType::I16,
        "u4" => ScalarType::U32,
        "i4" => ScalarType::I32,
        "f2" => ScalarType::F16,
        "f4" => ScalarType::F32,
        "f8" => ScalarType::F64,
        _ => return None,
    };
    Some((scalar, endian))
}

fn descr(scalar: ScalarType) -> &'static str {
    match scalar {
        ScalarType::U8 => "|u1",
        ScalarType::I8 => "|i1",
        ScalarType::U16 => "<u2",
        ScalarType::I16 => "<i2",
        ScalarType::U32 => "<u4",
        ScalarType::I32 => "<i4",
        ScalarType::F16 => "<f2",
        ScalarType::F32 => "<f4",
        ScalarType::F64 => "<f8",
    }
}

/// Writes the grid as a C-order (n_z, n_y, n_x) array of `scalar` (format version 1.0,
/// header padded to 64 bytes as NumPy does). Values the type cannot hold exactly are refused.
pub fn write(path: impl AsRef<Path>, grid: &Grid, scalar: ScalarType) -> Result<(), GridError> {
    write_channels(path, &[grid], scalar)
}

/// The magic, version, length and header of a C-order array of `channels` grids of `dims`
/// (a 3D array for one channel), padded to a multiple of 64 bytes.
pub(crate) fn header_bytes(dims: [usize; 3], channels: usize, scalar: ScalarType) -> Vec<u8> {
    let [nx, ny, nz] = dims;
    let shape = if channels == 1 {
        format!("({nz}, {ny}, {nx})")
    } else {
        format!("({channels}, {nz}, {ny}, {nx})")
    };
    let mut header = format!(
        "{{'descr': '{}', 'fortran_order': False, 'shape': {shape}, }}",
        descr(scalar)
    );
    // magic (6) + version (2) + length (2) + header + '\n' must be a multiple of 64.
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat(unpadded.next_multiple_of(64) - unpadded));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out
}

/// Writes `channels` f32 grids of `dims` (as [`write_channels`] lays them out) without
/// holding more than one slab: `slab(channel, z, out)` fills slab `z` of a channel, x
/// fastest. For fields that live out of core (a paged fluence). An error of `slab` ends
/// the write and is returned as an I/O error naming the file. The file appears whole or
/// not at all ([`super::atomic`]).
pub fn write_f32_slabs<E: std::fmt::Display>(
    path: impl AsRef<Path>,
    dims: [usize; 3],
    channels: usize,
    mut slab: impl FnMut(usize, usize, &mut [f32]) -> Result<(), E>,
) -> Result<(), GridError> {
    use std::io::Write;
    let path = path.as_ref();
    let io = |source: std::io::Error| GridError::Io {
        path: path.to_owned(),
        source,
    };
    let mut out = super::atomic::AtomicFile::create(path).map_err(io)?;
    out.write_all(&header_bytes(dims, channels.max(1), ScalarType::F32))
        .map_err(io)?;
    let [nx, ny, nz] = dims;
    let mut values = vec![0f32; nx * ny];
    let mut bytes = Vec::with_capacity(nx * ny * 4);
    for channel in 0..channels.max(1) {
        for z in 0..nz {
            slab(channel, z, &mut values).map_err(|e| io(std::io::Error::other(e.to_string())))?;
            bytes.clear();
            for v in &values {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
            out.write_all(&bytes).map_err(io)?;
        }
    }
    out.commit().map_err(io)
}

/// Writes one grid as a 3D array, or several grids on one geometry (RGB fluence) as a
/// C-order (channels, n_z, n_y, n_x) array.
pub fn write_channels(
    path: impl AsRef<Path>,
    grids: &[&Grid],
    scalar: ScalarType,
) -> Result<(), GridError> {
    let path = path.as_ref();
    let grid = grids.first().ok_or_else(|| GridError::InvalidParameter {
        name: "grids",
        reason: "need at least one".into(),
    })?;
    if grids.iter().any(|g| g.geometry() != grid.geometry()) {
        return Err(GridError::Mismatch(
            "all channels of an .npy array share one geometry".into(),
        ));
    }
    let header = header_bytes(grid.dims(), grids.len(), scalar);
    let mut out =
        Vec::with_capacity(header.len() + grids.len() * grid.data().len() * scalar.size());
    out.extend_from_slice(&header);
    for g in grids {
        out.extend_from_slice(&encode(path, g.data(), scalar, Endian::Little)?);
    }
    write_file(path, &out)
}
