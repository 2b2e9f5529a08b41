//! MetaImage (ITK): a `Key = Value` text header (`.mhd`) with the samples in the file
//! named by `ElementDataFile`, or attached after it (`.mha`, `ElementDataFile = LOCAL`).
//!
//! Read: 3D scalar images of every `MET_` type, `ElementByteOrderMSB` /
//! `BinaryDataByteOrderMSB`, `CompressedData` (zlib), `HeaderSize` (≥ 0 or −1), placement from
//! `ElementSpacing` (or `ElementSize`) and `Offset` / `Origin` / `Position` (the centre of
//! the first sample); an identity `TransformMatrix` only. Written: `.mha` attached or `.mhd`
//! with a `.raw` beside it.

use std::collections::HashMap;
use std::path::Path;

use glam::DVec3;

use super::{
    Endian, LoadOptions, ScalarType, checked_voxels, decode, encode, inflate_decode, read_file,
    sibling, write_file,
};
use crate::dense::Grid;
use crate::error::GridError;

fn malformed(path: &Path, reason: impl Into<String>) -> GridError {
    GridError::Malformed {
        path: path.to_owned(),
        format: "MetaImage",
        reason: reason.into(),
    }
}

/// Reads a `.mhd` or `.mha` file.
pub fn read(path: impl AsRef<Path>, options: &LoadOptions) -> Result<Grid, GridError> {
    let path = path.as_ref();
    parse(&read_file(path, options)?, path, options)
}

fn scalar_type(name: &str) -> Option<ScalarType> {
    Some(match name {
        "MET_UCHAR" => ScalarType::U8,
        "MET_CHAR" => ScalarType::I8,
        "MET_USHORT" => ScalarType::U16,
        "MET_SHORT" => ScalarType::I16,
        "MET_UINT" | "MET_ULONG" => ScalarType::U32,
        "MET_INT" | "MET_LONG" => ScalarType::I32,
        "MET_FLOAT" => ScalarType::F32,
        "MET_DOUBLE" => ScalarType::F64,
        _ => return None,
    })
}

fn type_name(scalar: ScalarType) -> Option<&'static str> {
    Some(match scalar {
        ScalarType::U8 => "MET_UCHAR",
        ScalarType::I8 => "MET_CHAR",
        ScalarType::U16 => "MET_USHORT",
        ScalarType::I16 => "MET_SHORT",
        ScalarType::U32 => "MET_UINT",
        ScalarType::I32 => "MET_INT",
        ScalarType::F32 => "MET_FLOAT",
        ScalarType::F64 => "MET_DOUBLE",
        ScalarType::F16 => return None,
    })
}

/// Parses a MetaImage header and its payload.
pub fn parse(bytes: &[u8], path: &Path, options: &LoadOptions) -> Result<Grid, GridError> {
    let mut fields = HashMap::new();
    let mut pos = 0;
    let mut data_file = None;
    while pos < bytes.len() {
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |e| pos + e);
        let line = std::str::from_utf8(&bytes[pos..end])
            .map_err(|_| malformed(path, "header is not text"))?;
        pos = (end + 1).min(bytes.len());
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let (key, value) = line
            .split_once('=')
            .ok_or_else(|| malformed(path, format!("bad header line `{line}`")))?;
        let (key, value) = (key.trim().to_owned(), value.trim().to_owned());
        if key == "ElementDataFile" {
            data_file = Some(value);
            break; // the last header field; attached data follows
        }
        fields.insert(key, value);
        if fields.len() > 256 {
            return Err(malformed(path, "more than 256 header fields"));
        }
    }
    let data_file = data_file.ok_or_else(|| malformed(path, "no ElementDataFile"))?;
    let field = |k: &str| fields.get(k).map(String::as_str);
    let required =
        |k: &'static str| field(k).ok_or_else(|| malformed(path, format!("missing `{k}`")));
    let triple = |k: &str| -> Result<Option<DVec3>, GridError> {
        field(k)
            .map(|t| {
                let v: Vec<f64> = t
                    .split_whitespace()
                    .map(str::parse)
                    .collect::<Result<_, _>>()
                    .map_err(|_| malformed(path, format!("bad `{k}`")))?;
                if v.len() == 3 && v.iter().all(|x| x.is_finite()) {
                    Ok(DVec3::new(v[0], v[1], v[2]))
                } else {
                    Err(malformed(path, format!("bad `{k}`")))
                }
            })
            .transpose()
    };

    if required("NDims")? != "3" {
        return Err(GridError::Unsupported {
            path: path.to_owned(),
            what: "MetaImage NDims",
            value: required("NDims")?.to_owned(),
        });
    }
    if let Some(channels) = field("ElementNumberOfChannels").filter(|c| *c != "1") {
        return Err(GridError::Unsupported {
            path: path.to_owned(),
            what: "channel count",
            value: channels.to_owned(),
        });
    }
    let dims_v: Vec<usize> = required("DimSize")?
        .split_whitespace()
        .map(str::parse)
        .collect::<Result<_, _>>()
        .map_err(|_| malformed(path, "bad `DimSize`"))?;
    let dims: [usize; 3] = dims_v
        .try_into()
        .map_err(|_| malformed(path, "`DimSize` needs three sizes"))?;
    let element = required("ElementType")?;
    let scalar = scalar_type(element).ok_or_else(|| GridError::Unsupported {
        path: path.to_owned(),
        what: "MetaImage ElementType",
        value: element.to_owned(),
    })?;
    if let Some(m) = field("TransformMatrix") {
        let identity = m
            .split_whitespace()
            .map(str::parse::<f64>)
            .collect::<Result<Vec<_>, _>>()
            .is_ok_and(|v| v == [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
        if !identity {
            return Err(GridError::Unsupported {
                path: path.to_owned(),
                what: "TransformMatrix (only identity)",
                value: m.to_owned(),
            });
        }
    }
    let spacing = triple("ElementSpacing")?
        .or(triple("ElementSize")?)
        .unwrap_or(DVec3::ONE);
    let first = triple("Offset")?
        .or(triple("Origin")?)
        .or(triple("Position")?)
        .unwrap_or(DVec3::ZERO);
    let geometry = super::geometry(path, "MetaImage", dims, spacing, first - 0.5 * spacing)?;
    let msb = field("ElementByteOrderMSB")
        .or(field("BinaryDataByteOrderMSB"))
        .unwrap_or("False");
    let endian = if msb.eq_ignore_ascii_case("true") {
        Endian::Big
    } else {
        Endian::Little
    };
    let compressed = field("CompressedData").is_some_and(|c| c.eq_ignore_ascii_case("true"));
    let header_size: i64 = field("HeaderSize")
        .map_or(Ok(0), str::parse)
        .map_err(|_| malformed(path, "bad `HeaderSize`"))?;

    let voxels = checked_voxels(path, "MetaImage", dims)?;
    options.reserve_voxels(path, voxels, scalar)?;
    let expected = voxels * scalar.size() as u64;
    let detached;
    let (data_path, payload): (&Path, &[u8]) = if data_file == "LOCAL" {
        (path, &bytes[pos..])
    } else if data_file.starts_with("LIST") || data_file.contains('%') {
        return Err(GridError::Unsupported {
            path: path.to_owned(),
            what: "multi-file MetaImage data",
            value: data_file,
        });
    } else {
        let p = sibling(path, &data_file);
        detached = (read_file(&p, options)?, p);
        (&detached.1, &detached.0[..])
    };
    let samples = if compressed {
        inflate_decode(data_path, payload, expected, false, scalar, endian)?
    } else {
        let start = match header_size {
            -1 => payload.len().saturating_sub(expected as usize),
            n => usize::try_from(n).map_err(|_| malformed(path, "bad `HeaderSize`"))?,
        };
        let data = payload.get(start..).unwrap_or(&[]);
        if (data.len() as u64) < expected {
            return Err(GridError::Truncated {
                path: data_path.to_owned(),
                what: "samples",
                expected,
                found: data.len() as u64,
            });
        }
        if data.len() as u64 != expected {
            return Err(GridError::SizeMismatch {
                path: data_path.to_owned(),
                expected,
                found: data.len() as u64,
            });
        }
        decode(data, scalar, endian)
    };
    super::finite_grid(path, geometry, samples)
}

/// Writes `path` as `.mha` (samples attached) when its extension is `mha`, otherwise as a
/// `.mhd` header with the samples in a `.raw` file of the same stem beside it.
pub fn write(path: impl AsRef<Path>, grid: &Grid, scalar: ScalarType) -> Result<(), GridError> {
    let path = path.as_ref();
    let element = type_name(scalar).ok_or_else(|| GridError::Unsupported {
        path: path.to_owned(),
        what: "MetaImage type",
        value: "f16".into(),
    })?;
    let [nx, ny, nz] = grid.dims();
    let h = grid.geometry().spacing();
    let first = grid.geometry().cell_centre(0, 0, 0);
    let payload = encode(path, grid.data(), scalar, Endian::Little)?;
    let attached = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mha"));
    let raw_path = path.with_extension("raw");
    let data_file = if attached {
        "LOCAL".to_owned()
    } else {
        raw_path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "data.raw".into())
    };
    let header = format!(
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\nCompressedData = False\n\
         TransformMatrix = 1 0 0 0 1 0 0 0 1\nOffset = {:?} {:?} {:?}\nElementSpacing = {:?} {:?} {:?}\nDimSize = {nx} {ny} {nz}\n\
         ElementType = {element}\nElementDataFile = {data_file}\n",
        first.x, first.y, first.z, h.x, h.y, h.z
    );
    if attached {
        let mut out = header.into_bytes();
        out.extend_from_slice(&payload);
        write_file(path, &out)
    } else {
        write_file(&raw_path, &payload)?;
        write_file(path, header.as_bytes())
    }
}
