//! Volume files: readers for the formats users bring, writers where the format allows.
//!
//! | format | module | read | write |
//! |---|---|---|---|
//! | headerless raw (any [`ScalarType`], either endianness) | [`raw`] | ✓ | ✓ |
//! | NRRD (attached / detached header, raw / gzip) | [`nrrd`] | ✓ | ✓ |
//! | MetaImage `.mhd` / `.mha` (raw / zlib) | [`mhd`] | ✓ | ✓ |
//! | legacy VTK `STRUCTURED_POINTS` (binary / ASCII) | [`vtk`] | ✓ | ✓ |
//! | VTK XML ImageData `.vti` (ascii, base64, raw appended; zlib) and vtk.js `.vti` folders | [`vti`] | ✓ | ✓ (XML) |
//! | Mitsuba `.vol` (1, 3 or 6 channels) | [`mitsuba`] | ✓ | ✓ |
//! | NumPy `.npy` (f32, u8, u16 and more) | [`npy`] | ✓ | ✓ |
//! | OpenVDB float grids (half or full float, uncompressed or zlib) | [`vdb`] | ✓ | – |
//!
//! Conventions: formats that store *samples* (NRRD, MetaImage, VTK, VDB) place the first
//! sample at the file's origin; lucent's grids are cell-centred, so that sample becomes the
//! centre of cell (0, 0, 0) and the grid's corner lies half a cell below it. Mitsuba stores
//! the box the cells fill, which maps directly.
//!
//! Every reader checks sizes against the file and against [`LoadOptions::memory_budget`]
//! *before* allocating, and reports problems as [`GridError`]s that name the file.

pub mod atomic;
pub mod layers;
pub mod mhd;
pub mod mitsuba;
pub mod npy;
pub mod nrrd;
pub mod raw;
pub mod vdb;
pub mod vti;
pub mod vtk;

use std::fs;
use std::io::Read;
use std::path::{Path, PathBuf};

use crate::dense::Grid;
use crate::error::GridError;

/// Limits that apply while reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LoadOptions {
    /// The most bytes a read may allocate for the decoded grid plus its raw payload.
    pub memory_budget: u64,
}

impl Default for LoadOptions {
    /// A budget of 8 GiB.
    fn default() -> Self {
        Self {
            memory_budget: 8 << 30,
        }
    }
}

impl LoadOptions {
    /// Fails with [`GridError::OverBudget`] unless `bytes` fit the budget.
    pub(crate) fn reserve(&self, path: &Path, bytes: u64) -> Result<(), GridError> {
        if bytes > self.memory_budget {
            Err(GridError::OverBudget {
                path: path.to_owned(),
                needed: bytes,
                budget: self.memory_budget,
            })
        } else {
            Ok(())
        }
    }

    /// Budget check for decoding `voxels` samples of `scalar` into f32.
    pub(crate) fn reserve_voxels(
        &self,
        path: &Path,
        voxels: u64,
        scalar: ScalarType,
    ) -> Result<(), GridError> {
        let bytes = voxels.saturating_mul(4 + scalar.size() as u64);
        self.reserve(path, bytes)
    }
}

/// The volume formats [`read_volume`] knows, for messages.
pub const SUPPORTED: &str = ".nrrd/.nhdr, .mhd/.mha, .vtk, .vti (VTK XML ImageData, or a vtk.js folder), .vol (Mitsuba), .npy, .vdb, and headerless .raw with its layout";

/// Reads any supported file by its extension with default options: `.nrrd`/`.nhdr`,
/// `.mhd`/`.mha`, `.vtk`, `.vti` (file or vtk.js folder), `.vol` (single channel), `.npy`,
/// `.vdb` (the first float grid).
/// Headerless raw files need their layout: use [`raw::read`].
pub fn read_volume(path: impl AsRef<Path>) -> Result<Grid, GridError> {
    read_volume_with(path, &LoadOptions::default())
}

/// [`read_volume`] with explicit limits.
pub fn read_volume_with(path: impl AsRef<Path>, options: &LoadOptions) -> Result<Grid, GridError> {
    let path = path.as_ref();
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    // A vtk.js folder's index.json is read as its folder.
    let in_vti_folder = path.file_name().is_some_and(|n| n == "index.json")
        && path
            .parent()
            .and_then(Path::extension)
            .is_some_and(|e| e.eq_ignore_ascii_case("vti"));
    if in_vti_folder {
        return vti::read(path, options);
    }
    match ext.as_str() {
        "nrrd" | "nhdr" => nrrd::read(path, options),
        "mhd" | "mha" => mhd::read(path, options),
        "vtk" => vtk::read(path, options),
        "vti" => vti::read(path, options),
        "vol" => mitsuba::read(path, options),
        "npy" => npy::read(path, options),
        "vdb" => vdb::read(path, None, options),
        _ => Err(GridError::Unsupported {
            path: path.to_owned(),
            what: "file extension",
            value: format!("`.{ext}` (lucent reads {SUPPORTED})"),
        }),
    }
}

/// The voxel types the readers decode (always into f32 grids).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ScalarType {
    /// Unsigned 8-bit.
    U8,
    /// Signed 8-bit.
    I8,
    /// Unsigned 16-bit.
    U16,
    /// Signed 16-bit.
    I16,
    /// Unsigned 32-bit (values above 2²⁴ lose precision in f32).
    U32,
    /// Signed 32-bit (likewise).
    I32,
    /// IEEE half precision.
    F16,
    /// IEEE single precision.
    F32,
    /// IEEE double precision (rounded to f32).
    F64,
}

impl ScalarType {
    /// Bytes per sample.
    pub fn size(self) -> usize {
        match self {
            ScalarType::U8 | ScalarType::I8 => 1,
            ScalarType::U16 | ScalarType::I16 | ScalarType::F16 => 2,
            ScalarType::U32 | ScalarType::I32 | ScalarType::F32 => 4,
            ScalarType::F64 => 8,
        }
    }

    /// A short name for messages.
    pub fn name(self) -> &'static str {
        match self {
            ScalarType::U8 => "u8",
            ScalarType::I8 => "i8",
            ScalarType::U16 => "u16",
            ScalarType::I16 => "i16",
            ScalarType::U32 => "u32",
            ScalarType::I32 => "i32",
            ScalarType::F16 => "f16",
            ScalarType::F32 => "f32",
            ScalarType::F64 => "f64",
        }
    }

    /// Whether an f32 value survives conversion to this type and back unchanged.
    fn represents(self, v: f32) -> bool {
        let integral_in =
            |lo: f64, hi: f64| v.fract() == 0.0 && f64::from(v) >= lo && f64::from(v) <= hi;
        match self {
            ScalarType::U8 => integral_in(0.0, 255.0),
            ScalarType::I8 => integral_in(-128.0, 127.0),
            ScalarType::U16 => integral_in(0.0, 65535.0),
            ScalarType::I16 => integral_in(-32768.0, 32767.0),
            ScalarType::U32 => integral_in(0.0, 4_294_967_295.0),
            ScalarType::I32 => integral_in(-2_147_483_648.0, 2_147_483_647.0),
            ScalarType::F16 => {
                half::f16::from_f32(v).to_f32().to_bits() == v.to_bits() || v.is_nan()
            }
            ScalarType::F32 | ScalarType::F64 => true,
        }
    }
}

/// Byte order of multi-byte samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Endian {
    /// Least significant byte first (x86, most files).
    #[default]
    Little,
    /// Most significant byte first (legacy VTK binary, old MetaImage files).
    Big,
}

/// Decodes `bytes` (exactly `count` samples) into f32.
pub(crate) fn decode(bytes: &[u8], scalar: ScalarType, endian: Endian) -> Vec<f32> {
    macro_rules! conv {
        ($t:ty, $n:expr) => {
            bytes
                .chunks_exact($n)
                .map(|c| {
                    let a: [u8; $n] = c.try_into().unwrap_or([0; $n]);
                    (match endian {
                        Endian::Little => <$t>::from_le_bytes(a),
                        Endian::Big => <$t>::from_be_bytes(a),
                    }) as f32
                })
                .collect()
        };
    }
    match scalar {
        ScalarType::U8 => bytes.iter().map(|&b| f32::from(b)).collect(),
        ScalarType::I8 => bytes.iter().map(|&b| f32::from(b as i8)).collect(),
        ScalarType::U16 => conv!(u16, 2),
        ScalarType::I16 => conv!(i16, 2),
        ScalarType::U32 => conv!(u32, 4),
        ScalarType::I32 => conv!(i32, 4),
        ScalarType::F32 => conv!(f32, 4),
        ScalarType::F64 => conv!(f64, 8),
        ScalarType::F16 => bytes
            .chunks_exact(2)
            .map(|c| {
                let a = [c[0], c[1]];
                match endian {
                    Endian::Little => half::f16::from_le_bytes(a),
                    Endian::Big => half::f16::from_be_bytes(a),
                }
                .to_f32()
            })
            .collect(),
    }
}

/// Encodes values as `scalar`, refusing (with the first offending voxel) any value the type
/// cannot hold exactly: writers never lose data silently.
pub(crate) fn encode(
    path: &Path,
    values: &[f32],
    scalar: ScalarType,
    endian: Endian,
) -> Result<Vec<u8>, GridError> {
    // No file lucent writes holds NaN or an infinity (readers refuse them too).
    if let Some(index) = values.iter().position(|v| !v.is_finite()) {
        return Err(GridError::NonFinite {
            path: path.to_owned(),
            index,
            cell: [index, 0, 0],
            value: values[index],
        });
    }
    if let Some(index) = values.iter().position(|&v| !scalar.represents(v)) {
        return Err(GridError::Lossy {
            path: path.to_owned(),
            index,
            value: values[index],
            target: scalar.name(),
        });
    }
    let mut out = Vec::with_capacity(values.len() * scalar.size());
    macro_rules! put {
        ($v:expr) => {
            match endian {
                Endian::Little => out.extend_from_slice(&$v.to_le_bytes()),
                Endian::Big => out.extend_from_slice(&$v.to_be_bytes()),
            }
        };
    }
    for &v in values {
        match scalar {
            ScalarType::U8 => out.push(v as u8),
            ScalarType::I8 => out.push(v as i8 as u8),
            ScalarType::U16 => put!(v as u16),
            ScalarType::I16 => put!(v as i16),
            ScalarType::U32 => put!(v as u32),
            ScalarType::I32 => put!(v as i32),
            ScalarType::F16 => put!(half::f16::from_f32(v)),
            ScalarType::F32 => put!(v),
            ScalarType::F64 => put!(f64::from(v)),
        }
    }
    Ok(out)
}

/// Reads a whole file, naming it in the error, within the budget. Only regular files:
/// a device such as `/dev/zero` reports no length and never ends, a FIFO blocks.
pub(crate) fn read_file(path: &Path, options: &LoadOptions) -> Result<Vec<u8>, GridError> {
    let io = |source| GridError::Io {
        path: path.to_owned(),
        source,
    };
    let metadata = fs::metadata(path).map_err(io)?;
    if !metadata.is_file() {
        return Err(GridError::NotAFile {
            path: path.to_owned(),
        });
    }
    let len = metadata.len();
    options.reserve(path, len)?;
    let mut bytes = Vec::new();
    // At most what the metadata promised (plus one byte to notice a file that grew).
    fs::File::open(path)
        .map_err(io)?
        .take(len.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(io)?;
    if bytes.len() as u64 != len {
        return Err(GridError::SizeMismatch {
            path: path.to_owned(),
            expected: len,
            found: bytes.len() as u64,
        });
    }
    Ok(bytes)
}

/// The grid of decoded `samples`, refusing the first non-finite one by its cell: a NaN in a
/// volume file is an error naming the file and the voxel, never silently zero.
pub(crate) fn finite_grid(
    path: &Path,
    geometry: crate::GridGeometry,
    samples: Vec<f32>,
) -> Result<Grid, GridError> {
    check_finite(path, &geometry, &samples)?;
    Grid::from_vec(geometry, samples)
}

/// The first non-finite value of `samples` as a [`GridError::NonFinite`].
pub(crate) fn check_finite(
    path: &Path,
    geometry: &crate::GridGeometry,
    samples: &[f32],
) -> Result<(), GridError> {
    match samples.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(index) => Err(GridError::NonFinite {
            path: path.to_owned(),
            index,
            cell: geometry.coords(index),
            value: samples[index],
        }),
    }
}

/// Writes a whole file, naming it in the error: whole or not at all ([`atomic`]).
pub(crate) fn write_file(path: &Path, bytes: &[u8]) -> Result<(), GridError> {
    use std::io::Write;
    atomic::write_with(path, |f| f.write_all(bytes)).map_err(|source| GridError::Io {
        path: path.to_owned(),
        source,
    })
}

/// Inflates a zlib (`gzip = false`) or gzip stream that must decode to exactly `expected`
/// bytes; never inflates more than `expected + 1` (no decompression bombs).
pub(crate) fn inflate(
    path: &Path,
    compressed: &[u8],
    expected: u64,
    gzip: bool,
) -> Result<Vec<u8>, GridError> {
    let mut out = Vec::new();
    let limit = expected.saturating_add(1);
    let result = if gzip {
        flate2::read::MultiGzDecoder::new(compressed)
            .take(limit)
            .read_to_end(&mut out)
    } else {
        flate2::read::ZlibDecoder::new(compressed)
            .take(limit)
            .read_to_end(&mut out)
    };
    result.map_err(|e| GridError::Malformed {
        path: path.to_owned(),
        format: if gzip { "gzip" } else { "zlib" },
        reason: e.to_string(),
    })?;
    if out.len() as u64 != expected {
        return Err(GridError::SizeMismatch {
            path: path.to_owned(),
            expected,
            found: out.len() as u64,
        });
    }
    Ok(out)
}

/// Inflates a zlib (`gzip = false`) or gzip stream of `expected` bytes of `scalar`
/// samples and decodes it as it goes, a megabyte at a time: the inflated payload never
/// exists whole (the peak is the compressed bytes and the decoded grid), and no more than
/// `expected` bytes are ever inflated (no decompression bombs).
pub(crate) fn inflate_decode(
    path: &Path,
    compressed: &[u8],
    expected: u64,
    gzip: bool,
    scalar: ScalarType,
    endian: Endian,
) -> Result<Vec<f32>, GridError> {
    let mut reader: Box<dyn Read + '_> = if gzip {
        Box::new(flate2::read::MultiGzDecoder::new(compressed))
    } else {
        Box::new(flate2::read::ZlibDecoder::new(compressed))
    };
    let size = scalar.size();
    let mut out = Vec::with_capacity(usize::try_from(expected).unwrap_or(0) / size);
    let mut chunk = vec![0u8; (1 << 20) / size * size];
    let (mut pending, mut total) = (0usize, 0u64);
    loop {
        let n = reader
            .read(&mut chunk[pending..])
            .map_err(|e| GridError::Malformed {
                path: path.to_owned(),
                format: if gzip { "gzip" } else { "zlib" },
                reason: e.to_string(),
            })?;
        if n == 0 {
            break;
        }
        pending += n;
        total += n as u64;
        if total > expected {
            break;
        }
        let whole = pending / size * size;
        out.extend(decode(&chunk[..whole], scalar, endian));
        chunk.copy_within(whole..pending, 0);
        pending -= whole;
    }
    if total != expected {
        return Err(GridError::SizeMismatch {
            path: path.to_owned(),
            expected,
            found: total,
        });
    }
    Ok(out)
}

/// A bounds-checked little cursor over a byte buffer: every read that would run past the
/// end is a [`GridError::Truncated`] naming what was being read.
pub(crate) struct Cursor<'a> {
    pub(crate) bytes: &'a [u8],
    pub(crate) pos: usize,
    pub(crate) path: &'a Path,
}

impl<'a> Cursor<'a> {
    pub(crate) fn new(bytes: &'a [u8], path: &'a Path) -> Self {
        Self {
            bytes,
            pos: 0,
            path,
        }
    }

    pub(crate) fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], GridError> {
        let available = self.bytes.len() - self.pos;
        if n > available {
            return Err(GridError::Truncated {
                path: self.path.to_owned(),
                what,
                expected: n as u64,
                found: available as u64,
            });
        }
        let slice = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(slice)
    }

    pub(crate) fn array<const N: usize>(
        &mut self,
        what: &'static str,
    ) -> Result<[u8; N], GridError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N, what)?);
        Ok(a)
    }

    pub(crate) fn u8(&mut self, what: &'static str) -> Result<u8, GridError> {
        Ok(self.array::<1>(what)?[0])
    }

    pub(crate) fn u32(&mut self, what: &'static str) -> Result<u32, GridError> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }

    pub(crate) fn i32(&mut self, what: &'static str) -> Result<i32, GridError> {
        Ok(i32::from_le_bytes(self.array(what)?))
    }

    pub(crate) fn u64(&mut self, what: &'static str) -> Result<u64, GridError> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }

    pub(crate) fn i64(&mut self, what: &'static str) -> Result<i64, GridError> {
        Ok(i64::from_le_bytes(self.array(what)?))
    }

    pub(crate) fn f32(&mut self, what: &'static str) -> Result<f32, GridError> {
        Ok(f32::from_le_bytes(self.array(what)?))
    }

    pub(crate) fn f64(&mut self, what: &'static str) -> Result<f64, GridError> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }

    pub(crate) fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }
}

/// Splits a text header from its payload at the first blank line (`\n\n` or `\r\n\r\n`).
pub(crate) fn split_header(bytes: &[u8]) -> Option<(&[u8], &[u8])> {
    let lf = bytes
        .windows(2)
        .position(|w| w == b"\n\n")
        .map(|p| (p, p + 2));
    let crlf = bytes
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .map(|p| (p, p + 4));
    let (end, start) = match (lf, crlf) {
        (Some(a), Some(b)) => {
            if a.0 <= b.0 {
                a
            } else {
                b
            }
        }
        (a, b) => a.or(b)?,
    };
    Some((&bytes[..end], &bytes[start..]))
}

/// Resolves a detached data file named in a header relative to the header's folder.
pub(crate) fn sibling(header: &Path, name: &str) -> PathBuf {
    let name = Path::new(name.trim());
    if name.is_absolute() {
        name.to_owned()
    } else {
        header.parent().unwrap_or(Path::new(".")).join(name)
    }
}

/// Product of dims with overflow and sanity checks, for headers.
pub(crate) fn checked_voxels(
    path: &Path,
    format: &'static str,
    dims: [usize; 3],
) -> Result<u64, GridError> {
    crate::geometry::voxel_count(dims)
        .filter(|&n| n > 0 && n <= crate::geometry::MAX_VOXELS)
        .map(|n| n as u64)
        .ok_or_else(|| GridError::Malformed {
            path: path.to_owned(),
            format,
            reason: format!("dimensions {dims:?} are zero or absurdly large"),
        })
}

/// A geometry from a file's header; an invalid one is a malformed file, named.
pub(crate) fn geometry(
    path: &Path,
    format: &'static str,
    dims: [usize; 3],
    spacing: glam::DVec3,
    origin: glam::DVec3,
) -> Result<crate::geometry::GridGeometry, GridError> {
    crate::geometry::GridGeometry::new(dims, spacing, origin).map_err(|e| GridError::Malformed {
        path: path.to_owned(),
        format,
        reason: e.to_string(),
    })
}
