//! NRRD (teem's "nearly raw raster data"): a text header, then the samples, either attached
//! after a blank line or in a detached file named by `data file`.
//!
//! Read: 3D scalar volumes (a leading axis of size 1 is dropped), every NRRD type, `raw`,
//! `gzip` and `ascii` encodings, `endian`, `byte skip` (≥ 0, or −1 for raw data at the end of
//! the file), `line skip`, and placement from `spacings` or diagonal `space directions` plus
//! `space origin` (the centre of the first sample). Written: attached header, `raw` or
//! `gzip`, with `space directions` and `space origin`, so geometry survives a round trip.

use std::io::Write;
use std::path::Path;

use glam::DVec3;

use super::{
    Endian, LoadOptions, ScalarType, checked_voxels, decode, encode, inflate_decode, read_file,
    sibling, split_header, write_file,
};
use crate::dense::Grid;
use crate::error::GridError;

/// Payload encodings of a written file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Encoding {
    /// Uncompressed samples.
    #[default]
    Raw,
    /// gzip-compressed samples.
    Gzip,
}

fn malformed(path: &Path, reason: impl Into<String>) -> GridError {
    GridError::Malformed {
        path: path.to_owned(),
        format: "NRRD",
        reason: reason.into(),
    }
}

/// Reads a `.nrrd` (attached) or `.nhdr` (detached) file.
pub fn read(path: impl AsRef<Path>, options: &LoadOptions) -> Result<Grid, GridError> {
    let path = path.as_ref();
    parse(&read_file(path, options)?, path, options)
}

fn scalar_type(name: &str) -> Option<ScalarType> {
    Some(match name {
        "signed char" | "int8" | "int8_t" => ScalarType::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => ScalarType::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            ScalarType::I16
        }
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => {
            ScalarType::U16
        }
        "int" | "signed int" | "int32" | "int32_t" => ScalarType::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => ScalarType::U32,
        "float" => ScalarType::F32,
        "double" => ScalarType::F64,
        _ => return None,
    })
}

/// What a NRRD header says.
pub(crate) struct Header {
    pub(crate) geometry: crate::GridGeometry,
    pub(crate) scalar: ScalarType,
    pub(crate) endian: Endian,
    pub(crate) voxels: u64,
    /// Payload bytes of `raw` samples.
    pub(crate) expected: u64,
    pub(crate) encoding: String,
    pub(crate) line_skip: usize,
    pub(crate) byte_skip: i64,
    /// The detached data file's name, as written.
    pub(crate) data_file: Option<String>,
}

/// Parses a header (the bytes before the blank line, magic included); `reserve` checks the
/// samples against a budget where the whole-file read checks them (so errors keep their
/// order).
pub(crate) fn header(
    header: &[u8],
    path: &Path,
    reserve: impl Fn(u64, ScalarType) -> Result<(), GridError>,
) -> Result<Header, GridError> {
    let header = std::str::from_utf8(header).map_err(|_| malformed(path, "header is not text"))?;
    let mut fields = std::collections::HashMap::new();
    for line in header.lines().skip(1) {
        let line = line.trim_end_matches('\r');
        if line.starts_with('#') || line.trim().is_empty() || line.contains(":=") {
            continue;
        }
        let (key, value) = line
            .split_once(": ")
            .ok_or_else(|| malformed(path, format!("bad header line `{line}`")))?;
        fields.insert(key.trim().to_ascii_lowercase(), value.trim().to_owned());
    }
    let field = |k: &str| fields.get(k).map(String::as_str);
    let required =
        |k: &'static str| field(k).ok_or_else(|| malformed(path, format!("missing field `{k}`")));

    let type_name = required("type")?;
    let scalar = scalar_type(type_name).ok_or_else(|| GridError::Unsupported {
        path: path.to_owned(),
        what: "NRRD type",
        value: type_name.to_owned(),
    })?;
    let dimension: usize = required("dimension")?
        .parse()
        .map_err(|_| malformed(path, "bad `dimension`"))?;
    let sizes =
        numbers::<usize>(required("sizes")?).ok_or_else(|| malformed(path, "bad `sizes`"))?;
    if sizes.len() != dimension {
        return Err(malformed(
            path,
            format!("{} sizes for dimension {dimension}", sizes.len()),
        ));
    }
    // A leading axis of one sample (a scalar "channel" axis) is dropped.
    let skip_axes = usize::from(dimension == 4 && sizes[0] == 1);
    if dimension - skip_axes != 3 {
        return Err(GridError::Unsupported {
            path: path.to_owned(),
            what: "NRRD dimension",
            value: dimension.to_string(),
        });
    }
    let dims = [sizes[skip_axes], sizes[skip_axes + 1], sizes[skip_axes + 2]];
    let spacing = placement_spacing(
        path,
        field("spacings"),
        field("space directions"),
        skip_axes,
    )?;
    let first_sample = match field("space origin") {
        Some(text) => vector(text).ok_or_else(|| malformed(path, "bad `space origin`"))?,
        None => DVec3::ZERO,
    };
    let geometry = super::geometry(path, "NRRD", dims, spacing, first_sample - 0.5 * spacing)?;

    let voxels = checked_voxels(path, "NRRD", dims)?;
    reserve(voxels, scalar)?;
    let expected = voxels * scalar.size() as u64;
    let endian = match field("endian") {
        Some("big") => Endian::Big,
        Some("little") | None => Endian::Little,
        Some(other) => return Err(malformed(path, format!("bad `endian` {other}"))),
    };
    let encoding = required("encoding")?.to_owned();
    let line_skip: usize = field("line skip")
        .map_or(Ok(0), str::parse)
        .map_err(|_| malformed(path, "bad `line skip`"))?;
    let byte_skip: i64 = field("byte skip")
        .map_or(Ok(0), str::parse)
        .map_err(|_| malformed(path, "bad `byte skip`"))?;
    Ok(Header {
        geometry,
        scalar,
        endian,
        voxels,
        expected,
        encoding,
        line_skip,
        byte_skip,
        data_file: field("data file").or(field("datafile")).map(str::to_owned),
    })
}

/// Parses a NRRD header and its payload (attached after the header, or from the detached
/// file relative to `path`).
pub fn parse(bytes: &[u8], path: &Path, options: &LoadOptions) -> Result<Grid, GridError> {
    if !bytes.starts_with(b"NRRD000") {
        return Err(malformed(path, "missing NRRD000x magic"));
    }
    let (header_bytes, attached) = split_header(bytes).unwrap_or((bytes, &[]));
    let Header {
        geometry,
        scalar,
        endian,
        voxels,
        expected,
        encoding,
        line_skip,
        byte_skip,
        data_file,
    } = header(header_bytes, path, |voxels, scalar| {
        options.reserve_voxels(path, voxels, scalar)
    })?;
    let encoding = encoding.as_str();
    let detached;
    let (data_path, mut payload): (&Path, &[u8]) = match data_file.as_deref() {
        Some(name) if name.starts_with("LIST") || name.contains('%') => {
            return Err(GridError::Unsupported {
                path: path.to_owned(),
                what: "multi-file NRRD data",
                value: name.to_owned(),
            });
        }
        Some(name) => {
            let data_path = sibling(path, name);
            detached = (read_file(&data_path, options)?, data_path);
            (&detached.1, &detached.0[..])
        }
        None => (path, attached),
    };
    for _ in 0..line_skip {
        let end = payload
            .iter()
            .position(|&b| b == b'\n')
            .ok_or_else(|| malformed(data_path, "`line skip` past the end"))?;
        payload = &payload[end + 1..];
    }
    let samples =
        match encoding {
            "raw" => {
                if byte_skip == -1 {
                    let start = payload.len().checked_sub(expected as usize).ok_or(
                        GridError::Truncated {
                            path: data_path.to_owned(),
                            what: "raw samples",
                            expected,
                            found: payload.len() as u64,
                        },
                    )?;
                    payload = &payload[start..];
                } else {
                    let skip = usize::try_from(byte_skip)
                        .map_err(|_| malformed(path, "bad `byte skip`"))?;
                    payload = payload.get(skip..).unwrap_or(&[]);
                }
                if (payload.len() as u64) < expected {
                    return Err(GridError::Truncated {
                        path: data_path.to_owned(),
                        what: "raw samples",
                        expected,
                        found: payload.len() as u64,
                    });
                }
                if payload.len() as u64 > expected
                    && !(payload.len() as u64 == expected + 1 && payload.ends_with(b"\n"))
                {
                    return Err(GridError::SizeMismatch {
                        path: data_path.to_owned(),
                        expected,
                        found: payload.len() as u64,
                    });
                }
                decode(&payload[..expected as usize], scalar, endian)
            }
            "gzip" | "gz" => {
                let skip = usize::try_from(byte_skip)
                    .map_err(|_| malformed(path, "`byte skip` -1 needs raw encoding"))?;
                inflate_decode(
                    data_path,
                    payload.get(skip..).unwrap_or(&[]),
                    expected,
                    true,
                    scalar,
                    endian,
                )?
            }
            "ascii" | "text" | "txt" => {
                let text = std::str::from_utf8(payload)
                    .map_err(|_| malformed(data_path, "ascii payload is not text"))?;
                let values: Vec<f32> = text
                    .split_ascii_whitespace()
                    .take(voxels as usize + 1)
                    .map(|t| t.parse::<f64>().map(|v| v as f32))
                    .collect::<Result<_, _>>()
                    .map_err(|_| malformed(data_path, "ascii payload has a non-number"))?;
                if values.len() as u64 != voxels {
                    return Err(GridError::SizeMismatch {
                        path: data_path.to_owned(),
                        expected: voxels,
                        found: values.len() as u64,
                    });
                }
                values
            }
            other => {
                return Err(GridError::Unsupported {
                    path: path.to_owned(),
                    what: "NRRD encoding",
                    value: other.to_owned(),
                });
            }
        };
    super::finite_grid(path, geometry, samples)
}

/// Whitespace-separated numbers.
fn numbers<T: std::str::FromStr>(text: &str) -> Option<Vec<T>> {
    text.split_whitespace().map(|t| t.parse().ok()).collect()
}

/// A vector written `(x,y,z)`.
fn vector(text: &str) -> Option<DVec3> {
    let inner = text.trim().strip_prefix('(')?.strip_suffix(')')?;
    let v: Vec<f64> = inner
        .split(',')
        .map(|t| t.trim().parse().ok())
        .collect::<Option<_>>()?;
    (v.len() == 3 && v.iter().all(|x| x.is_finite())).then(|| DVec3::new(v[0], v[1], v[2]))
}

/// Cell size from `spacings` or from diagonal `space directions` (unit spacing if neither).
fn placement_spacing(
    path: &Path,
    spacings: Option<&str>,
    directions: Option<&str>,
    skip: usize,
) -> Result<DVec3, GridError> {
    if let Some(text) = directions {
        let axes: Vec<&str> = text.split_whitespace().collect();
        let axes = axes
            .get(skip..)
            .filter(|a| a.len() == 3)
            .ok_or_else(|| malformed(path, "bad `space directions`"))?;
        let mut spacing = DVec3::ZERO;
        for (a, axis) in axes.iter().enumerate() {
            let v = vector(axis).ok_or_else(|| malformed(path, "bad `space directions`"))?;
            let off_diagonal = (0..3)
                .filter(|&b| b != a)
                .map(|b| v[b].abs())
                .fold(0.0, f64::max);
            if off_diagonal > 1e-9 * v[a].abs() || v[a] <= 0.0 {
                return Err(GridError::Unsupported {
                    path: path.to_owned(),
                    what: "space directions (only positive axis-aligned grids)",
                    value: text.to_owned(),
                });
            }
            spacing[a] = v[a];
        }
        return Ok(spacing);
    }
    match spacings {
        Some(text) => {
            let v: Vec<f64> = numbers(text).ok_or_else(|| malformed(path, "bad `spacings`"))?;
            let v = v
                .get(skip..)
                .filter(|v| v.len() == 3)
                .ok_or_else(|| malformed(path, "bad `spacings`"))?;
            // NaN marks an axis without spacing: take 1.
            Ok(DVec3::new(v[0], v[1], v[2]).map(|s| if s.is_nan() { 1.0 } else { s }))
        }
        None => Ok(DVec3::ONE),
    }
}

/// Writes an attached NRRD with `space directions` and `space origin`.
pub fn write(
    path: impl AsRef<Path>,
    grid: &Grid,
    scalar: ScalarType,
    encoding: Encoding,
) -> Result<(), GridError> {
    let path = path.as_ref();
    let [nx, ny, nz] = grid.dims();
    let h = grid.geometry().spacing();
    let first = grid.geometry().cell_centre(0, 0, 0);
    let type_name = match scalar {
        ScalarType::U8 => "uchar",
        ScalarType::I8 => "signed char",
        ScalarType::U16 => "ushort",
        ScalarType::I16 => "short",
        ScalarType::U32 => "uint",
        ScalarType::I32 => "int",
        ScalarType::F16 => {
            return Err(GridError::Unsupported {
                path: path.to_owned(),
                what: "NRRD type",
                value: "f16".into(),
            });
        }
        ScalarType::F32 => "float",
        ScalarType::F64 => "double",
    };
    let payload = encode(path, grid.data(), scalar, Endian::Little)?;
    let (encoding_name, payload) = match encoding {
        Encoding::Raw => ("raw", payload),
        Encoding::Gzip => {
            let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
            gz.write_all(&payload)
                .and_then(|_| gz.finish())
                .map(|p| ("gzip", p))
                .map_err(|source| GridError::Io {
                    path: path.to_owned(),
                    source,
                })?
        }
    };
    // `{:?}` prints the shortest string that parses back to the same f64.
    let header = format!(
        "NRRD0004\n# written by lucent-grid\ntype: {type_name}\ndimension: 3\nspace: 3D-right-handed\nsizes: {nx} {ny} {nz}\n\
         space directions: ({:?},0,0) (0,{:?},0) (0,0,{:?})\nspace origin: ({:?},{:?},{:?})\nkinds: domain domain domain\n\
         centers: cell cell cell\nendian: little\nencoding: {encoding_name}\n\n",
        h.x, h.y, h.z, first.x, first.y, first.z
    );
    let mut out = header.into_bytes();
    out.extend_from_slice(&payload);
    write_file(path, &out)
}
