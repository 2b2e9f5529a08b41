//! Legacy VTK `STRUCTURED_POINTS` files: a text header, then the first `SCALARS` array of
//! the `POINT_DATA`, in `BINARY` (big-endian, as the legacy format prescribes) or `ASCII`.
//!
//! Points become cell centres: `ORIGIN` is the centre of cell (0, 0, 0) and `SPACING` (or
//! the old `ASPECT_RATIO`) the cell size. Arrays after the first are ignored.

use std::path::Path;

use glam::DVec3;

use super::{
    Endian, LoadOptions, ScalarType, checked_voxels, decode, encode, read_file, write_file,
};
use crate::dense::Grid;
use crate::error::GridError;

fn malformed(path: &Path, reason: impl Into<String>) -> GridError {
    GridError::Malformed {
        path: path.to_owned(),
        format: "legacy VTK",
        reason: reason.into(),
    }
}

/// Reads a legacy `.vtk` structured-points file.
pub fn read(path: impl AsRef<Path>, options: &LoadOptions) -> Result<Grid, GridError> {
    let path = path.as_ref();
    parse(&read_file(path, options)?, path, options)
}

fn scalar_type(name: &str) -> Option<ScalarType> {
    Some(match name {
        "unsigned_char" => ScalarType::U8,
        "char" | "signed_char" => ScalarType::I8,
        "unsigned_short" => ScalarType::U16,
        "short" => ScalarType::I16,
        "unsigned_int" | "unsigned_long" => ScalarType::U32,
        "int" | "long" => ScalarType::I32,
        "float" => ScalarType::F32,
        "double" => ScalarType::F64,
        _ => return None,
    })
}

/// Parses a legacy VTK file already in memory.
pub fn parse(bytes: &[u8], path: &Path, options: &LoadOptions) -> Result<Grid, GridError> {
    let mut pos = 0;
    let mut next_line = |what: &'static str| -> Result<&[u8], GridError> {
        if pos >= bytes.len() {
            return Err(GridError::Truncated {
                path: path.to_owned(),
                what,
                expected: 1,
                found: 0,
            });
        }
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |e| pos + e);
        let line = &bytes[pos..end];
        pos = (end + 1).min(bytes.len());
        Ok(line)
    };
    let text = |line: &[u8]| String::from_utf8_lossy(line).trim().to_owned();
    if !text(next_line("version line")?).starts_with("# vtk DataFile") {
        return Err(malformed(path, "missing `# vtk DataFile` line"));
    }
    let _title = next_line("title")?;
    // Old writers (VTK 1.0, as `ironProt.vtk`) put blank lines between header lines.
    let mut format = text(next_line("format")?);
    for _ in 0..8 {
        if !format.is_empty() {
            break;
        }
        format = text(next_line("format")?);
    }
    let binary = match format.to_ascii_uppercase().as_str() {
        "BINARY" => true,
        "ASCII" => false,
        other => {
            return Err(malformed(
                path,
                format!("format `{other}` is neither BINARY nor ASCII"),
            ));
        }
    };
    let (mut dims, mut spacing, mut origin, mut scalar) = (None, DVec3::ONE, DVec3::ZERO, None);
    let mut dataset = false;
    for _ in 0..64 {
        let line = text(next_line("header")?);
        let mut words = line.split_whitespace();
        let keyword = words.next().unwrap_or("").to_ascii_uppercase();
        let rest: Vec<&str> = words.collect();
        let vec3 = |rest: &[&str]| -> Option<DVec3> {
            let v: Vec<f64> = rest.iter().map(|t| t.parse().ok()).collect::<Option<_>>()?;
            (v.len() == 3 && v.iter().all(|x| x.is_finite())).then(|| DVec3::new(v[0], v[1], v[2]))
        };
        match keyword.as_str() {
            "" => {}
            "DATASET" => {
                if rest.first().map(|s| s.to_ascii_uppercase()).as_deref()
                    != Some("STRUCTURED_POINTS")
                {
                    return Err(GridError::Unsupported {
                        path: path.to_owned(),
                        what: "VTK dataset",
                        value: rest.join(" "),
                    });
                }
                dataset = true;
            }
            "DIMENSIONS" => {
                let d: Vec<usize> = rest
                    .iter()
                    .map(|t| t.parse().ok())
                    .collect::<Option<_>>()
                    .ok_or_else(|| malformed(path, "bad DIMENSIONS"))?;
                dims = Some(
                    <[usize; 3]>::try_from(d)
                        .map_err(|_| malformed(path, "DIMENSIONS needs three sizes"))?,
                );
            }
            "SPACING" | "ASPECT_RATIO" => {
                spacing = vec3(&rest).ok_or_else(|| malformed(path, "bad SPACING"))?
            }
            "ORIGIN" => origin = vec3(&rest).ok_or_else(|| malformed(path, "bad ORIGIN"))?,
            "POINT_DATA" => {}
            "SCALARS" => {
                let type_name = rest
                    .get(1)
                    .ok_or_else(|| malformed(path, "SCALARS without a type"))?;
                scalar = Some(
                    scalar_type(type_name).ok_or_else(|| GridError::Unsupported {
                        path: path.to_owned(),
                        what: "VTK scalar type",
                        value: (*type_name).to_owned(),
                    })?,
                );
                if rest.get(2).is_some_and(|n| *n != "1") {
                    return Err(GridError::Unsupported {
                        path: path.to_owned(),
                        what: "VTK component count",
                        value: rest[2].to_owned(),
                    });
                }
            }
            "LOOKUP_TABLE" => break,
            "CELL_DATA"
            | "VECTORS"
            | "NORMALS"
            | "TENSORS"
            | "FIELD"
            | "COLOR_SCALARS"
            | "TEXTURE_COORDINATES" => {
                return Err(GridError::Unsupported {
                    path: path.to_owned(),
                    what: "VTK attribute before the scalars",
                    value: keyword,
                });
            }
            _ => return Err(malformed(path, format!("unexpected line `{line}`"))),
        }
    }
    if !dataset {
        return Err(malformed(path, "no DATASET STRUCTURED_POINTS"));
    }
    let dims = dims.ok_or_else(|| malformed(path, "no DIMENSIONS"))?;
    let scalar = scalar.ok_or_else(|| malformed(path, "no SCALARS before LOOKUP_TABLE"))?;
    let geometry = super::geometry(path, "legacy VTK", dims, spacing, origin - 0.5 * spacing)?;
    let voxels = checked_voxels(path, "legacy VTK", dims)?;
    options.reserve_voxels(path, voxels, scalar)?;
    let payload = &bytes[pos..];
    let samples = if binary {
        let expected = voxels * scalar.size() as u64;
        if (payload.len() as u64) < expected {
            return Err(GridError::Truncated {
                path: path.to_owned(),
                what: "binary scalars",
                expected,
                found: payload.len() as u64,
            });
        }
        decode(&payload[..expected as usize], scalar, Endian::Big)
    } else {
        let text = std::str::from_utf8(payload)
            .map_err(|_| malformed(path, "ASCII scalars are not text"))?;
        let values: Vec<f32> = text
            .split_ascii_whitespace()
            .take(voxels as usize)
            .map(|t| t.parse::<f64>().map(|v| v as f32))
            .collect::<Result<_, _>>()
            .map_err(|_| malformed(path, "ASCII scalars contain a non-number"))?;
        if (values.len() as u64) < voxels {
            return Err(GridError::Truncated {
                path: path.to_owned(),
                what: "ASCII scalars",
                expected: voxels,
                found: values.len() as u64,
            });
        }
        values
    };
    super::finite_grid(path, geometry, samples)
}

/// Writes a BINARY legacy VTK file (big-endian samples of `scalar`).
pub fn write(path: impl AsRef<Path>, grid: &Grid, scalar: ScalarType) -> Result<(), GridError> {
    let path = path.as_ref();
    let type_name = match scalar {
        ScalarType::U8 => "unsigned_char",
        ScalarType::I8 => "char",
        ScalarType::U16 => "unsigned_short",
        ScalarType::I16 => "short",
        ScalarType::U32 => "unsigned_int",
        ScalarType::I32 => "int",
        ScalarType::F32 => "float",
        ScalarType::F64 => "double",
        ScalarType::F16 => {
            return Err(GridError::Unsupported {
                path: path.to_owned(),
                what: "VTK type",
                value: "f16".into(),
            });
        }
    };
    let [nx, ny, nz] = grid.dims();
    let h = grid.geometry().spacing();
    let o = grid.geometry().cell_centre(0, 0, 0);
    let header = format!(
        "# vtk DataFile Version 3.0\nwritten by lucent-grid\nBINARY\nDATASET STRUCTURED_POINTS\nDIMENSIONS {nx} {ny} {nz}\n\
         SPACING {:?} {:?} {:?}\nORIGIN {:?} {:?} {:?}\nPOINT_DATA {}\nSCALARS values {type_name} 1\nLOOKUP_TABLE default\n",
        h.x,
        h.y,
        h.z,
        o.x,
        o.y,
        o.z,
        grid.data().len()
    );
    let mut out = header.into_bytes();
    out.extend_from_slice(&encode(path, grid.data(), scalar, Endian::Big)?);
    out.push(b'\n');
    write_file(path, &out)
}
