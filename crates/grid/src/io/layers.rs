//! Some z-layers, or a box of cells, of a volume file, read by positioned reads (`pread`):
//! a rank of a z-slab decomposition or of a grid of boxes reads the header and its own
//! cells' bytes, never the whole volume.
//!
//! Formats whose samples are stored uncompressed with x fastest and z slowest, so that a
//! run of z-layers is one contiguous run of bytes, and a box one run per x-line (merged
//! where they touch: one run per layer for whole x-lines, one in all for whole layers):
//! headerless `.raw` (with its [`RawLayout`]), `.npy` (C order (n_z, n_y, n_x) or Fortran
//! order (n_x, n_y, n_z)), and NRRD with a `raw` payload, attached or detached (`byte
//! skip` ≥ 0 or −1). The file's size is checked against its header (metadata, not a read)
//! exactly as the whole-file readers check it, the budget covers the cells read only, and
//! a non-finite sample among them is refused by its cell, as everywhere.
//!
//! The other way, [`write_npy_layers`] and [`write_npy_region`] write a rank's layers or
//! box of a result into one f32 `.npy` by positioned writes (after [`create_npy`] on one
//! rank).

use std::fs::File;
use std::ops::Range;
use std::path::Path;

use glam::DVec3;

use super::raw::RawLayout;
use super::{Cursor, Endian, LoadOptions, ScalarType, checked_voxels, decode};
use crate::dense::Grid;
use crate::error::GridError;
use crate::geometry::GridGeometry;

/// Layers `first..first + grid.dims()[2]` of a volume.
#[derive(Debug, Clone, PartialEq)]
pub struct Layers {
    /// The whole volume's geometry.
    pub whole: GridGeometry,
    /// The first layer read.
    pub first: usize,
    /// The layers: the whole volume's n_x × n_y, its spacing, its origin moved up by
    /// `first` layers.
    pub grid: Grid,
}

/// A box of cells of a volume (`origin` + the grid's dims, along x, y and z).
#[derive(Debug, Clone, PartialEq)]
pub struct Region {
    /// The whole volume's geometry.
    pub whole: GridGeometry,
    /// The box's first cell along x, y and z.
    pub origin: [usize; 3],
    /// The box: its cells, the whole volume's spacing, its origin moved to the box's
    /// first cell.
    pub grid: Grid,
}

/// What to read: some z-layers, or a box of cells.
#[derive(Debug, Clone)]
enum Pick {
    Layers(Range<usize>),
    Cells([Range<usize>; 3]),
}

impl Region {
    fn into_layers(self) -> Layers {
        Layers {
            whole: self.whole,
            first: self.origin[2],
            grid: self.grid,
        }
    }
}

/// The runs of bytes (offset from the first sample, length) that hold the box `cells` of
/// a volume of `dims` with `size`-byte samples, x fastest, in the box's order; runs that
/// touch are merged (whole x-lines make one run per layer, whole layers one in all).
fn runs(dims: [usize; 3], cells: &[Range<usize>; 3], size: usize) -> Vec<(u64, usize)> {
    let [nx, ny, _] = dims;
    let mut out: Vec<(u64, usize)> = Vec::new();
    for k in cells[2].clone() {
        for j in cells[1].clone() {
            let offset = ((cells[0].start + nx * (j + ny * k)) * size) as u64;
            let len = cells[0].len() * size;
            match out.last_mut() {
                Some((o, l)) if *o + *l as u64 == offset => *l += len,
                _ => out.push((offset, len)),
            }
        }
    }
    out
}

fn io_error(path: &Path) -> impl Fn(std::io::Error) -> GridError + '_ {
    move |source| GridError::Io {
        path: path.to_owned(),
        source,
    }
}

/// `buf.len()` bytes of `file` from `offset`.
fn read_at(file: &File, path: &Path, buf: &mut [u8], offset: u64) -> Result<(), GridError> {
    #[cfg(unix)]
    {
        std::os::unix::fs::FileExt::read_exact_at(file, buf, offset).map_err(io_error(path))
    }
    #[cfg(not(unix))]
    {
        use std::io::{Read, Seek, SeekFrom};
        let mut f = file;
        f.seek(SeekFrom::Start(offset)).map_err(io_error(path))?;
        f.read_exact(buf).map_err(io_error(path))
    }
}

/// `bytes` written into `file` from `offset`.
fn write_at(file: &File, path: &Path, bytes: &[u8], offset: u64) -> Result<(), GridError> {
    #[cfg(unix)]
    {
        std::os::unix::fs::FileExt::write_all_at(file, bytes, offset).map_err(io_error(path))
    }
    #[cfg(not(unix))]
    {
        use std::io::{Seek, SeekFrom, Write};
        let mut f = file;
        f.seek(SeekFrom::Start(offset)).map_err(io_error(path))?;
        f.write_all(bytes).map_err(io_error(path))
    }
}

/// Writes `values` (f32, x fastest) as layers `layers` of the C-order (n_z, n_y, n_x)
/// f32 `.npy` array of `dims`: [`write_npy_region`] of those whole layers.
///
/// # Errors
/// As [`write_npy_region`].
pub fn write_npy_layers(
    path: impl AsRef<Path>,
    dims: [usize; 3],
    layers: Range<usize>,
    values: &[f32],
) -> Result<(), GridError> {
    write_npy_region(path, dims, [0..dims[0], 0..dims[1], layers], values)
}

/// Writes `values` (f32, x fastest) as the box `cells` of the C-order (n_z, n_y, n_x) f32
/// `.npy` array of `dims`, by positioned writes: every rank of a decomposition writes its
/// own cells into one file, and the header, identical from every rank. The cells go into
/// the partial file beside `path` ([`super::atomic::partial_path`]), which is created if
/// it is missing and never truncated, and are `fsync`ed before this returns: one rank
/// creates (or empties) it before the others write ([`create_npy`], then a barrier), and
/// once every rank has written (a barrier) one rank renames it over `path`
/// ([`finish_npy`]). `path` is then the array [`super::npy::write`] would have written,
/// and never a part of it.
///
/// # Errors
/// An empty box or one past the grid, `values` of another length
/// ([`GridError::InvalidParameter`]), and I/O.
pub fn write_npy_region(
    path: impl AsRef<Path>,
    dims: [usize; 3],
    cells: [Range<usize>; 3],
    values: &[f32],
) -> Result<(), GridError> {
    let path = path.as_ref();
    let count: usize = cells.iter().map(ExactSizeIterator::len).product();
    if (0..3).any(|a| cells[a].is_empty() || cells[a].end > dims[a]) || values.len() != count {
        return Err(GridError::InvalidParameter {
            name: "cells",
            reason: format!("{cells:?} of {dims:?} with {} values", values.len()),
        });
    }
    let header = super::npy::header_bytes(dims, 1, ScalarType::F32);
    let partial = super::atomic::partial_path(path);
    let file = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(false)
        .open(&partial)
        .map_err(io_error(path))?;
    write_at(&file, path, &header, 0)?;
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let mut at = 0;
    for (offset, len) in runs(dims, &cells, 4) {
        write_at(
            &file,
            path,
            &bytes[at..at + len],
            header.len() as u64 + offset,
        )?;
        at += len;
    }
    file.sync_data().map_err(io_error(path))
}

/// Creates (or empties) the partial file that [`write_npy_region`] fills for `path`, with
/// its header.
///
/// # Errors
/// I/O.
pub fn create_npy(path: impl AsRef<Path>, dims: [usize; 3]) -> Result<(), GridError> {
    let path = path.as_ref();
    let partial = super::atomic::partial_path(path);
    std::fs::write(&partial, super::npy::header_bytes(dims, 1, ScalarType::F32))
        .map_err(io_error(path))
}

/// Renames the partial file that every rank has filled ([`write_npy_region`]) over
/// `path`: call on one rank, after all have written. `path` appears whole or not at all.
///
/// # Errors
/// I/O (the partial file is then removed).
pub fn finish_npy(path: impl AsRef<Path>) -> Result<(), GridError> {
    let path = path.as_ref();
    super::atomic::publish(&super::atomic::partial_path(path), path).map_err(io_error(path))
}

/// Removes the partial file of `path` (a decomposed write that failed on some rank).
pub fn abandon_npy(path: impl AsRef<Path>) {
    let _ = std::fs::remove_file(super::atomic::partial_path(path.as_ref()));
}

/// Layers `layers` of a raw file of `layout`.
///
/// # Errors
/// An empty range or one past n_z ([`GridError::InvalidParameter`]), a file whose size is
/// not the layout's, the budget, I/O, and non-finite samples.
pub fn read_raw_layers(
    path: impl AsRef<Path>,
    layout: &RawLayout,
    layers: Range<usize>,
    options: &LoadOptions,
) -> Result<Layers, GridError> {
    read_raw(path.as_ref(), layout, Pick::Layers(layers), options).map(Region::into_layers)
}

/// The box of cells `cells` (x, y and z ranges) of a raw file of `layout`.
///
/// # Errors
/// As [`read_raw_layers`], for an empty box or one past the grid.
pub fn read_raw_region(
    path: impl AsRef<Path>,
    layout: &RawLayout,
    cells: [Range<usize>; 3],
    options: &LoadOptions,
) -> Result<Region, GridError> {
    read_raw(path.as_ref(), layout, Pick::Cells(cells), options)
}

fn read_raw(
    path: &Path,
    layout: &RawLayout,
    pick: Pick,
    options: &LoadOptions,
) -> Result<Region, GridError> {
    let whole = super::geometry(path, "raw", layout.dims, layout.spacing, layout.origin)?;
    let file = File::open(path).map_err(io_error(path))?;
    exact_size(&file, path, "raw", &whole, layout.scalar, 0)?;
    positioned(
        &file,
        path,
        "raw",
        whole,
        (layout.scalar, layout.endian),
        0,
        pick,
        options,
    )
}

/// The most bytes a `.npy` header may take (NumPy writes 64 to a few hundred).
const MAX_NPY_HEADER: usize = 1 << 20;

/// Layers `layers` of a `.npy` file (unit spacing at the origin, as [`super::npy::read`]).
///
/// # Errors
/// As [`read_raw_layers`], and a malformed header.
pub fn read_npy_layers(
    path: impl AsRef<Path>,
    layers: Range<usize>,
    options: &LoadOptions,
) -> Result<Layers, GridError> {
    read_npy(path.as_ref(), Pick::Layers(layers), options).map(Region::into_layers)
}

/// The box of cells `cells` of a `.npy` file.
///
/// # Errors
/// As [`read_npy_layers`], for an empty box or one past the grid.
pub fn read_npy_region(
    path: impl AsRef<Path>,
    cells: [Range<usize>; 3],
    options: &LoadOptions,
) -> Result<Region, GridError> {
    read_npy(path.as_ref(), Pick::Cells(cells), options)
}

fn read_npy(path: &Path, pick: Pick, options: &LoadOptions) -> Result<Region, GridError> {
    let file = File::open(path).map_err(io_error(path))?;
    let len = file.metadata().map_err(io_error(path))?.len();
    // Magic (6), version (2) and the header's length (2 or 4), then the header.
    let mut prefix = vec![0u8; (len as usize).min(12)];
    read_at(&file, path, &mut prefix, 0)?;
    let header_len = match prefix.get(6) {
        Some(1) if prefix.len() >= 10 => 10 + u16::from_le_bytes([prefix[8], prefix[9]]) as usize,
        Some(2 | 3) if prefix.len() >= 12 => {
            12 + u32::from_le_bytes([prefix[8], prefix[9], prefix[10], prefix[11]]) as usize
        }
        _ => prefix.len(),
    };
    let header_len = header_len.min(MAX_NPY_HEADER).min(len as usize);
    let mut bytes = vec![0u8; header_len];
    read_at(&file, path, &mut bytes, 0)?;
    let mut c = Cursor::new(&bytes, path);
    let header = super::npy::header(&mut c, path)?;
    let whole = super::geometry(path, "npy", header.dims, DVec3::ONE, DVec3::ZERO)?;
    exact_size(&file, path, "npy", &whole, header.scalar, c.pos as u64)?;
    positioned(
        &file,
        path,
        "npy",
        whole,
        (header.scalar, header.endian),
        c.pos as u64,
        pick,
        options,
    )
}

/// Refuses a file that is not `offset` plus `whole`'s samples long (as the whole-file
/// readers do).
fn exact_size(
    file: &File,
    path: &Path,
    format: &'static str,
    whole: &GridGeometry,
    scalar: ScalarType,
    offset: u64,
) -> Result<(), GridError> {
    let voxels = checked_voxels(path, format, whole.dims())?;
    let expected = offset + voxels * scalar.size() as u64;
    let found = file.metadata().map_err(io_error(path))?.len();
    if found != expected {
        return Err(GridError::SizeMismatch {
            path: path.to_owned(),
            expected,
            found,
        });
    }
    Ok(())
}

/// The most bytes a NRRD header may take before its blank line.
const MAX_NRRD_HEADER: u64 = 1 << 20;

/// Layers `layers` of a NRRD volume (`.nrrd` attached or `.nhdr` detached) whose samples
/// are `raw`-encoded, with its placement, as [`super::nrrd::read`] gives the whole.
///
/// # Errors
/// As [`read_raw_layers`]; [`GridError::Unsupported`] for a compressed or text payload or
/// a `line skip` (which only a read of the lines before the samples can resolve).
pub fn read_nrrd_layers(
    path: impl AsRef<Path>,
    layers: Range<usize>,
    options: &LoadOptions,
) -> Result<Layers, GridError> {
    read_nrrd(path.as_ref(), Pick::Layers(layers), options).map(Region::into_layers)
}

/// The box of cells `cells` of a raw-encoded NRRD volume, with its placement.
///
/// # Errors
/// As [`read_nrrd_layers`], for an empty box or one past the grid.
pub fn read_nrrd_region(
    path: impl AsRef<Path>,
    cells: [Range<usize>; 3],
    options: &LoadOptions,
) -> Result<Region, GridError> {
    read_nrrd(path.as_ref(), Pick::Cells(cells), options)
}

fn read_nrrd(path: &Path, pick: Pick, options: &LoadOptions) -> Result<Region, GridError> {
    let malformed = |reason: &str| GridError::Malformed {
        path: path.to_owned(),
        format: "NRRD",
        reason: reason.to_owned(),
    };
    let unsupported = |what: &'static str, value: String| GridError::Unsupported {
        path: path.to_owned(),
        what,
        value,
    };
    let file = File::open(path).map_err(io_error(path))?;
    let len = file.metadata().map_err(io_error(path))?.len();
    let mut prefix = vec![0u8; len.min(MAX_NRRD_HEADER) as usize];
    read_at(&file, path, &mut prefix, 0)?;
    if !prefix.starts_with(b"NRRD000") {
        return Err(malformed("missing NRRD000x magic"));
    }
    let (header_bytes, attached_at) = match super::split_header(&prefix) {
        Some((h, rest)) => (h, (prefix.len() - rest.len()) as u64),
        None if len <= MAX_NRRD_HEADER => (&prefix[..], len),
        None => return Err(malformed("no blank line ends the header within 1 MiB")),
    };
    let header = super::nrrd::header(header_bytes, path, |_, _| Ok(()))?;
    if header.encoding != "raw" {
        return Err(unsupported(
            "NRRD encoding for positioned reads",
            header.encoding.clone(),
        ));
    }
    if header.line_skip != 0 {
        return Err(unsupported(
            "NRRD `line skip` for positioned reads",
            header.line_skip.to_string(),
        ));
    }
    let (data_path, data, base) = match header.data_file.as_deref() {
        Some(name) if name.starts_with("LIST") || name.contains('%') => {
            return Err(unsupported("multi-file NRRD data", name.to_owned()));
        }
        Some(name) => {
            let data_path = super::sibling(path, name);
            let data = File::open(&data_path).map_err(io_error(&data_path))?;
            (data_path, data, 0)
        }
        None => (path.to_owned(), file, attached_at),
    };
    let data_len = data.metadata().map_err(io_error(&data_path))?.len();
    let expected = header.expected;
    let truncated = |found: u64| GridError::Truncated {
        path: data_path.clone(),
        what: "raw samples",
        expected,
        found,
    };
    let start = if header.byte_skip == -1 {
        data_len
            .checked_sub(expected)
            .filter(|&s| s >= base)
            .ok_or_else(|| truncated(data_len.saturating_sub(base)))?
    } else {
        let skip = u64::try_from(header.byte_skip).map_err(|_| malformed("bad `byte skip`"))?;
        base.saturating_add(skip)
    };
    let present = data_len.saturating_sub(start);
    if present < expected {
        return Err(truncated(present));
    }
    // One byte more is allowed when it is a final newline, as the whole read allows it.
    if present > expected {
        let mut last = [0u8];
        read_at(&data, &data_path, &mut last, data_len - 1)?;
        if present != expected + 1 || last != *b"\n" {
            return Err(GridError::SizeMismatch {
                path: data_path.clone(),
                expected,
                found: present,
            });
        }
    }
    debug_assert_eq!(header.voxels * header.scalar.size() as u64, expected);
    positioned(
        &data,
        &data_path,
        "NRRD",
        header.geometry,
        (header.scalar, header.endian),
        start,
        pick,
        options,
    )
}

/// Reads the cells `pick` of the samples stored from `offset` of `file` as `whole`'s
/// cells (the file's size checked by the caller).
#[allow(clippy::too_many_arguments)]
fn positioned(
    file: &File,
    path: &Path,
    format: &'static str,
    whole: GridGeometry,
    (scalar, endian): (ScalarType, Endian),
    offset: u64,
    pick: Pick,
    options: &LoadOptions,
) -> Result<Region, GridError> {
    let dims = whole.dims();
    let cells = match pick {
        Pick::Layers(layers) => {
            if layers.is_empty() || layers.end > dims[2] {
                return Err(GridError::InvalidParameter {
                    name: "layers",
                    reason: format!("{layers:?} of a volume of {} z-layers", dims[2]),
                });
            }
            [0..dims[0], 0..dims[1], layers]
        }
        Pick::Cells(cells) => {
            if (0..3).any(|a| cells[a].is_empty() || cells[a].end > dims[a]) {
                return Err(GridError::InvalidParameter {
                    name: "cells",
                    reason: format!("{cells:?} of a volume of {dims:?} cells"),
                });
            }
            cells
        }
    };
    let count: [usize; 3] = std::array::from_fn(|a| cells[a].len());
    let voxels = count.iter().product::<usize>();
    options.reserve_voxels(path, voxels as u64, scalar)?;
    let mut bytes = vec![0u8; voxels * scalar.size()];
    let mut at = 0;
    for (start, len) in runs(dims, &cells, scalar.size()) {
        read_at(file, path, &mut bytes[at..at + len], offset + start)?;
        at += len;
    }
    let origin: [usize; 3] = std::array::from_fn(|a| cells[a].start);
    let corner = DVec3::new(origin[0] as f64, origin[1] as f64, origin[2] as f64);
    let geometry = super::geometry(
        path,
        format,
        count,
        whole.spacing(),
        whole.origin() + corner * whole.spacing(),
    )?;
    let samples = decode(&bytes, scalar, endian);
    // A non-finite sample is named by its cell in the whole volume.
    if let Some(index) = samples.iter().position(|v| !v.is_finite()) {
        let local = geometry.coords(index);
        let cell: [usize; 3] = std::array::from_fn(|a| origin[a] + local[a]);
        return Err(GridError::NonFinite {
            path: path.to_owned(),
            index: cell[0] + dims[0] * (cell[1] + dims[1] * cell[2]),
            cell,
            value: samples[index],
        });
    }
    Ok(Region {
        whole,
        origin,
        grid: Grid::from_vec(geometry, samples)?,
    })
}
