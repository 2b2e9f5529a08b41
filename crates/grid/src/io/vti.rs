//! VTK image data, `.vti`, in its two shapes:
//!
//! - **VTK XML ImageData files** (ParaView's native volume format): `<ImageData
//!   WholeExtent Origin Spacing>` with one `<Piece>`, whose first `PointData` array (the
//!   one its `Scalars` attribute names, else the first) or, without point data, first
//!   `CellData` array is read. The array may be `ascii`, inline `binary` (base64) or
//!   `appended` (`raw` or `base64` encoding), uncompressed or compressed by
//!   `vtkZLibDataCompressor` (VTK's block header: block count, block size, last block
//!   size, then each block's compressed size), with `UInt32` or `UInt64` headers, in either
//!   byte order.
//! - **vtk.js's HttpDataSet folders** (`NAME.vti/index.json` and the arrays under
//!   `data/`, gzip-compressed or not): `extent`, `spacing`, `origin` and the
//!   `pointData` scalars.
//!
//! Placement follows the legacy VTK reader: a point sample becomes the centre of a cell,
//! the sample at extent (i₀, j₀, k₀) lying at `Origin + (i₀, j₀, k₀)·Spacing`; cell data
//! fill the cells between the points. A `Direction` matrix is **not applied**: lucent's
//! grids are axis-aligned, so a rotated image is read in its own index frame (as Mitsuba
//! reads `.vol` files into the unit cube). Multi-component arrays are refused.
//!
//! Only the writer of the XML form exists here ([`write()`], raw appended data, optionally
//! zlib-compressed); vtk.js folders are read only.

use std::path::{Path, PathBuf};

use glam::DVec3;

use super::{
    Endian, LoadOptions, ScalarType, checked_voxels, decode, encode, finite_grid, geometry,
    read_file, write_file,
};
use crate::dense::Grid;
use crate::error::GridError;

const XML: &str = "VTK XML ImageData";
const VTKJS: &str = "vtk.js HttpDataSet";

fn malformed(path: &Path, format: &'static str, reason: impl Into<String>) -> GridError {
    GridError::Malformed {
        path: path.to_owned(),
        format,
        reason: reason.into(),
    }
}

/// Reads a `.vti`: a vtk.js folder (or its `index.json`), or a VTK XML ImageData file.
pub fn read(path: impl AsRef<Path>, options: &LoadOptions) -> Result<Grid, GridError> {
    let path = path.as_ref();
    if path.is_dir() {
        read_vtkjs(&path.join("index.json"), options)
    } else if path.file_name().is_some_and(|n| n == "index.json") {
        read_vtkjs(path, options)
    } else {
        parse_xml(&read_file(path, options)?, path, options)
    }
}

/// The scalar type of a VTK XML `type` attribute.
fn xml_type(name: &str) -> Option<ScalarType> {
    Some(match name {
        "Int8" | "Char" => ScalarType::I8,
        "UInt8" | "UnsignedChar" => ScalarType::U8,
        "Int16" | "Short" => ScalarType::I16,
        "UInt16" | "UnsignedShort" => ScalarType::U16,
        "Int32" | "Int" => ScalarType::I32,
        "UInt32" | "UnsignedInt" => ScalarType::U32,
        "Float32" | "Float" => ScalarType::F32,
        "Float64" | "Double" => ScalarType::F64,
        _ => return None,
    })
}

/// The scalar type of a vtk.js `dataType`.
fn vtkjs_type(name: &str) -> Option<ScalarType> {
    Some(match name {
        "Int8Array" => ScalarType::I8,
        "Uint8Array" | "Uint8ClampedArray" => ScalarType::U8,
        "Int16Array" => ScalarType::I16,
        "Uint16Array" => ScalarType::U16,
        "Int32Array" => ScalarType::I32,
        "Uint32Array" => ScalarType::U32,
        "Float32Array" => ScalarType::F32,
        "Float64Array" => ScalarType::F64,
        _ => return None,
    })
}

/// Where the samples sit: dims, spacing and the centre of cell (0, 0, 0), from a whole
/// extent (point indices), origin and spacing, for point or cell data.
fn placement(
    path: &Path,
    format: &'static str,
    extent: [i64; 6],
    origin: DVec3,
    spacing: DVec3,
    cell_data: bool,
) -> Result<([usize; 3], DVec3, DVec3), GridError> {
    let mut dims = [0usize; 3];
    let mut first = DVec3::ZERO;
    for a in 0..3 {
        let (lo, hi) = (extent[2 * a], extent[2 * a + 1]);
        let points = hi
            .checked_sub(lo)
            .and_then(|d| d.checked_add(1))
            .filter(|&n| n >= 1)
            .ok_or_else(|| malformed(path, format, format!("extent {extent:?}")))?;
        // Cell data: the cells between the points (a flat axis keeps one cell).
        let n = if cell_data {
            (points - 1).max(1)
        } else {
            points
        };
        dims[a] = usize::try_from(n).map_err(|_| malformed(path, format, "extent"))?;
        let offset = if cell_data && points > 1 { 0.5 } else { 0.0 };
        first[a] = origin[a] + (lo as f64 + offset) * spacing[a];
    }
    if !(spacing.cmpgt(DVec3::ZERO).all() && spacing.is_finite() && first.is_finite()) {
        return Err(malformed(
            path,
            format,
            format!("spacing {spacing} and origin {origin} must be finite, spacing positive"),
        ));
    }
    checked_voxels(path, format, dims)?;
    Ok((dims, spacing, first))
}

/// The grid of `samples` whose cell (0, 0, 0) is centred at `first`.
fn grid_at(
    path: &Path,
    format: &'static str,
    dims: [usize; 3],
    spacing: DVec3,
    first: DVec3,
    samples: Vec<f32>,
) -> Result<Grid, GridError> {
    let g = geometry(path, format, dims, spacing, first - 0.5 * spacing)?;
    finite_grid(path, g, samples)
}

// ---------------------------------------------------------------------------------------
// vtk.js HttpDataSet

fn read_vtkjs(index: &Path, options: &LoadOptions) -> Result<Grid, GridError> {
    let text = read_file(index, options)?;
    let json: serde_json::Value = serde_json::from_slice(&text)
        .map_err(|e| malformed(index, VTKJS, format!("index.json: {e}")))?;
    let numbers = |key: &str, n: usize| -> Result<Vec<f64>, GridError> {
        let values: Option<Vec<f64>> = json[key]
            .as_array()
            .map(|a| a.iter().map(serde_json::Value::as_f64).collect())
            .and_then(|v: Option<Vec<f64>>| v.filter(|v| v.len() == n));
        values.ok_or_else(|| malformed(index, VTKJS, format!("`{key}` is not {n} numbers")))
    };
    if json["vtkClass"] != "vtkImageData" {
        return Err(GridError::Unsupported {
            path: index.to_owned(),
            what: "vtk.js data set",
            value: json["vtkClass"].to_string(),
        });
    }
    let e = numbers("extent", 6)?;
    let extent: [i64; 6] = std::array::from_fn(|i| e[i] as i64);
    if e.iter().any(|v| v.fract() != 0.0 || v.abs() > 1e12) {
        return Err(malformed(index, VTKJS, format!("extent {e:?}")));
    }
    let spacing = numbers("spacing", 3)?;
    let origin = numbers("origin", 3).unwrap_or_else(|_| vec![0.0; 3]);
    let arrays = json["pointData"]["arrays"]
        .as_array()
        .filter(|a| !a.is_empty())
        .ok_or_else(|| malformed(index, VTKJS, "no point data arrays"))?;
    // The active scalars, else the first array.
    let array = arrays
        .iter()
        .find(|a| a["data"]["ref"]["registration"] == "setScalars")
        .unwrap_or(&arrays[0]);
    let data = &array["data"];
    let components = data["numberOfComponents"].as_u64().unwrap_or(1);
    if components != 1 {
        return Err(GridError::Unsupported {
            path: index.to_owned(),
            what: "number of components",
            value: components.to_string(),
        });
    }
    let type_name = data["dataType"].as_str().unwrap_or("");
    let scalar = vtkjs_type(type_name).ok_or_else(|| GridError::Unsupported {
        path: index.to_owned(),
        what: "voxel type",
        value: type_name.to_owned(),
    })?;
    let endian = match data["ref"]["encode"].as_str() {
        None | Some("LittleEndian") => Endian::Little,
        Some("BigEndian") => Endian::Big,
        Some(other) => {
            return Err(GridError::Unsupported {
                path: index.to_owned(),
                what: "encoding",
                value: other.to_owned(),
            });
        }
    };
    let id = data["ref"]["id"]
        .as_str()
        .filter(|id| !id.is_empty() && !id.contains(['/', '\\']) && *id != "..")
        .ok_or_else(|| malformed(index, VTKJS, "the array has no `ref.id`"))?;
    let basepath = data["ref"]["basepath"].as_str().unwrap_or("data");
    if Path::new(basepath).is_absolute() || basepath.split(['/', '\\']).any(|c| c == "..") {
        return Err(malformed(
            index,
            VTKJS,
            format!("basepath `{basepath}` leaves the folder"),
        ));
    }
    let (dims, spacing, first) = placement(
        index,
        VTKJS,
        extent,
        DVec3::from_slice(&origin),
        DVec3::from_slice(&spacing),
        false,
    )?;
    let voxels = checked_voxels(index, VTKJS, dims)?;
    if let Some(size) = data["size"].as_u64()
        && size != voxels
    {
        return Err(malformed(
            index,
            VTKJS,
            format!("the array holds {size} values; the extent needs {voxels}"),
        ));
    }
    let expected = voxels * scalar.size() as u64;
    options.reserve_voxels(index, voxels, scalar)?;
    let folder = index.parent().unwrap_or(Path::new(".")).join(basepath);
    let gz: PathBuf = folder.join(format!("{id}.gz"));
    let samples = if gz.is_file() {
        let compressed = read_file(&gz, options)?;
        super::inflate_decode(&gz, &compressed, expected, true, scalar, endian)?
    } else {
        let plain = folder.join(id);
        let bytes = read_file(&plain, options)?;
        if bytes.len() as u64 != expected {
            return Err(GridError::SizeMismatch {
                path: plain,
                expected,
                found: bytes.len() as u64,
            });
        }
        decode(&bytes, scalar, endian)
    };
    grid_at(index, VTKJS, dims, spacing, first, samples)
}

// ---------------------------------------------------------------------------------------
// VTK XML

/// One start tag: its name and attributes (entities in values are not expanded: VTK's
/// numeric attributes have none).
struct Tag<'a> {
    name: &'a str,
    attributes: Vec<(&'a str, &'a str)>,
    /// Where the text after the tag starts.
    end: usize,
}

impl<'a> Tag<'a> {
    fn get(&self, key: &str) -> Option<&'a str> {
        self.attributes
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, v)| *v)
    }
}

/// The start tags of `text` (comments, declarations and end tags skipped) up to the end or
/// to `<AppendedData`, whose tag is the last one returned.
fn tags<'a>(text: &'a str, path: &Path) -> Result<Vec<Tag<'a>>, GridError> {
    let bad = |reason: &str| malformed(path, XML, reason.to_owned());
    let mut out = Vec::new();
    let mut pos = 0;
    while let Some(start) = text[pos..].find('<').map(|s| pos + s) {
        let rest = &text[start..];
        if rest.starts_with("<!--") {
            pos = start
                + rest
                    .find("-->")
                    .ok_or_else(|| bad("unterminated comment"))?
                + 3;
            continue;
        }
        let close = rest.find('>').ok_or_else(|| bad("unterminated tag"))?;
        pos = start + close + 1;
        if rest.starts_with("</") || rest.starts_with("<?") || rest.starts_with("<!") {
            continue;
        }
        let inner = rest[1..close].trim_end_matches('/');
        let name_end = inner
            .find(|c: char| c.is_whitespace())
            .unwrap_or(inner.len());
        let name = &inner[..name_end];
        let mut attributes = Vec::new();
        let mut a = &inner[name_end..];
        loop {
            a = a.trim_start();
            if a.is_empty() {
                break;
            }
            let eq = a
                .find('=')
                .ok_or_else(|| bad("attribute without a value"))?;
            let key = a[..eq].trim();
            let after = a[eq + 1..].trim_start();
            let quote = after
                .chars()
                .next()
                .filter(|c| *c == '"' || *c == '\'')
                .ok_or_else(|| bad("unquoted attribute"))?;
            let value_end = after[1..]
                .find(quote)
                .ok_or_else(|| bad("unterminated attribute"))?;
            attributes.push((key, &after[1..1 + value_end]));
            a = &after[value_end + 2..];
        }
        let appended = name == "AppendedData";
        out.push(Tag {
            name,
            attributes,
            end: pos,
        });
        if appended {
            break;
        }
    }
    Ok(out)
}

fn parse_numbers<T: std::str::FromStr, const N: usize>(
    path: &Path,
    what: &str,
    text: Option<&str>,
) -> Result<[T; N], GridError> {
    let text = text.ok_or_else(|| malformed(path, XML, format!("no `{what}`")))?;
    let values: Vec<T> = text
        .split_whitespace()
        .map(str::parse)
        .collect::<Result<_, _>>()
        .map_err(|_| malformed(path, XML, format!("`{what}` = \"{text}\"")))?;
    values
        .try_into()
        .map_err(|_| malformed(path, XML, format!("`{what}` needs {N} numbers: \"{text}\"")))
}

/// Decodes standard base64 (whitespace ignored, `=` padding optional).
fn base64_decode(text: &[u8], path: &Path) -> Result<Vec<u8>, GridError> {
    let mut out = Vec::with_capacity(text.len() / 4 * 3);
    let (mut acc, mut bits) = (0u32, 0u32);
    for &c in text {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            b'=' | b' ' | b'\n' | b'\r' | b'\t' => continue,
            _ => return Err(malformed(path, XML, "invalid base64")),
        };
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}

/// The base64 text at the start of `raw`: up to the next tag, whitespace removed.
fn base64_text(raw: &[u8]) -> Vec<u8> {
    raw.iter()
        .take_while(|&&c| c != b'<')
        .copied()
        .filter(|c| !c.is_ascii_whitespace())
        .collect()
}

/// Characters of base64 that encode `bytes` bytes (with padding).
fn base64_chars(bytes: usize) -> usize {
    bytes.div_ceil(3) * 4
}

/// How a binary block is framed: the header's integer width, byte order, compression.
#[derive(Clone, Copy)]
struct Framing {
    header: usize,
    endian: Endian,
    zlib: bool,
}

impl Framing {
    fn int(&self, bytes: &[u8]) -> u64 {
        match (self.header, self.endian) {
            (8, Endian::Little) => u64::from_le_bytes(bytes[..8].try_into().unwrap_or([0; 8])),
            (8, Endian::Big) => u64::from_be_bytes(bytes[..8].try_into().unwrap_or([0; 8])),
            (_, Endian::Little) => {
                u64::from(u32::from_le_bytes(bytes[..4].try_into().unwrap_or([0; 4])))
            }
            (_, Endian::Big) => {
                u64::from(u32::from_be_bytes(bytes[..4].try_into().unwrap_or([0; 4])))
            }
        }
    }
}

/// The payload of one binary array of `expected` bytes. `raw` holds its bytes from the
/// start of its header; `base64`: whether they are base64 text (for compressed data the
/// header and the blocks are encoded separately, as VTK writes them).
fn binary_payload(
    path: &Path,
    raw: &[u8],
    base64: bool,
    framing: Framing,
    expected: u64,
) -> Result<Vec<u8>, GridError> {
    let truncated = |what: &'static str, need: u64, found: usize| GridError::Truncated {
        path: path.to_owned(),
        what,
        expected: need,
        found: found as u64,
    };
    let h = framing.header;
    if !framing.zlib {
        let bytes = if base64 {
            let text = base64_text(raw);
            let chars =
                base64_chars(h.saturating_add(usize::try_from(expected).unwrap_or(usize::MAX)));
            base64_decode(&text[..chars.min(text.len())], path)?
        } else {
            raw.to_vec()
        };
        if bytes.len() < h {
            return Err(truncated("array header", h as u64, bytes.len()));
        }
        let size = framing.int(&bytes[..h]);
        if size != expected {
            return Err(GridError::SizeMismatch {
                path: path.to_owned(),
                expected,
                found: size,
            });
        }
        let body = &bytes[h..];
        if (body.len() as u64) < expected {
            return Err(truncated("array data", expected, body.len()));
        }
        return Ok(body[..expected as usize].to_vec());
    }
    // Compressed: [blocks][block size][last block size][compressed size × blocks].
    let (header, rest): (Vec<u8>, Vec<u8>) = if base64 {
        let text = base64_text(raw);
        let first = base64_decode(&text[..base64_chars(h).min(text.len())], path)?;
        if first.len() < h {
            return Err(truncated("compression header", h as u64, first.len()));
        }
        let blocks = usize::try_from(framing.int(&first)).unwrap_or(usize::MAX);
        if blocks > 1 << 24 {
            return Err(malformed(path, XML, format!("{blocks} compressed blocks")));
        }
        let header_chars = base64_chars(h * (3 + blocks));
        if text.len() < header_chars {
            return Err(truncated(
                "compression header",
                header_chars as u64,
                text.len(),
            ));
        }
        let header = base64_decode(&text[..header_chars], path)?;
        let compressed: u64 = header
            .chunks_exact(h)
            .skip(3)
            .map(|c| framing.int(c))
            .fold(0u64, u64::saturating_add);
        let chars = base64_chars(usize::try_from(compressed).unwrap_or(usize::MAX));
        let end = header_chars.saturating_add(chars).min(text.len());
        (header, base64_decode(&text[header_chars..end], path)?)
    } else {
        if raw.len() < h {
            return Err(truncated("compression header", h as u64, raw.len()));
        }
        let blocks = usize::try_from(framing.int(raw)).unwrap_or(usize::MAX);
        if blocks > 1 << 24 || raw.len() < h * (3 + blocks) {
            return Err(truncated(
                "compression header",
                (h as u64).saturating_mul(3 + blocks as u64),
                raw.len(),
            ));
        }
        (
            raw[..h * (3 + blocks)].to_vec(),
            raw[h * (3 + blocks)..].to_vec(),
        )
    };
    let ints: Vec<u64> = header.chunks_exact(h).map(|c| framing.int(c)).collect();
    if ints.len() < 3 {
        return Err(truncated("compression header", 3 * h as u64, header.len()));
    }
    let (blocks, block_size, last) = (ints[0] as usize, ints[1], ints[2]);
    if ints.len() < 3 + blocks {
        return Err(truncated(
            "compression header",
            (3 + blocks) as u64,
            ints.len(),
        ));
    }
    let total = match blocks {
        0 => 0,
        n => {
            let last = if last == 0 { block_size } else { last };
            (n as u64 - 1)
                .saturating_mul(block_size)
                .saturating_add(last)
        }
    };
    if total != expected {
        return Err(GridError::SizeMismatch {
            path: path.to_owned(),
            expected,
            found: total,
        });
    }
    let mut out = Vec::with_capacity(usize::try_from(expected).unwrap_or(0));
    let mut at = 0usize;
    for b in 0..blocks {
        let size = usize::try_from(ints[3 + b]).unwrap_or(usize::MAX);
        let block = rest.get(at..at.saturating_add(size)).ok_or_else(|| {
            truncated(
                "compressed block",
                size as u64,
                rest.len() - at.min(rest.len()),
            )
        })?;
        at += size;
        let want = if b + 1 == blocks {
            total - (blocks as u64 - 1) * block_size
        } else {
            block_size
        };
        out.extend(super::inflate(path, block, want, false)?);
    }
    Ok(out)
}

/// Parses a VTK XML ImageData file already in memory.
pub fn parse_xml(bytes: &[u8], path: &Path, options: &LoadOptions) -> Result<Grid, GridError> {
    // The XML part ends where raw appended data begins (binary, not text).
    let appended_at = find(bytes, b"<AppendedData");
    let xml_end = appended_at.map_or(bytes.len(), |a| {
        find(&bytes[a..], b">").map_or(bytes.len(), |e| a + e + 1)
    });
    let text = std::str::from_utf8(&bytes[..xml_end])
        .map_err(|_| malformed(path, XML, "the XML is not UTF-8"))?;
    let tags = tags(text, path)?;
    let file = tags
        .iter()
        .find(|t| t.name == "VTKFile")
        .ok_or_else(|| malformed(path, XML, "no <VTKFile> element"))?;
    if file.get("type") != Some("ImageData") {
        return Err(GridError::Unsupported {
            path: path.to_owned(),
            what: "VTK XML data set",
            value: file.get("type").unwrap_or("none").to_owned(),
        });
    }
    let endian = match file.get("byte_order") {
        None | Some("LittleEndian") => Endian::Little,
        Some("BigEndian") => Endian::Big,
        Some(other) => {
            return Err(GridError::Unsupported {
                path: path.to_owned(),
                what: "byte order",
                value: other.to_owned(),
            });
        }
    };
    let header = match file.get("header_type") {
        None | Some("UInt32") => 4,
        Some("UInt64") => 8,
        Some(other) => {
            return Err(GridError::Unsupported {
                path: path.to_owned(),
                what: "header type",
                value: other.to_owned(),
            });
        }
    };
    let zlib = match file.get("compressor") {
        None | Some("") => false,
        Some("vtkZLibDataCompressor") => true,
        Some(other) => {
            return Err(GridError::Unsupported {
                path: path.to_owned(),
                what: "compressor",
                value: other.to_owned(),
            });
        }
    };
    let framing = Framing {
        header,
        endian,
        zlib,
    };
    let image = tags
        .iter()
        .find(|t| t.name == "ImageData")
        .ok_or_else(|| malformed(path, XML, "no <ImageData> element"))?;
    let extent: [i64; 6] = parse_numbers(path, "WholeExtent", image.get("WholeExtent"))?;
    let origin: [f64; 3] = parse_numbers(path, "Origin", image.get("Origin").or(Some("0 0 0")))?;
    let spacing: [f64; 3] = parse_numbers(path, "Spacing", image.get("Spacing").or(Some("1 1 1")))?;
    if tags.iter().filter(|t| t.name == "Piece").count() > 1 {
        return Err(GridError::Unsupported {
            path: path.to_owned(),
            what: "layout",
            value: "several pieces (write the image as one piece)".into(),
        });
    }
    // The array: PointData's active scalars (else its first), else CellData's first.
    let section = |name: &str| -> Option<(usize, Option<&str>)> {
        tags.iter()
            .position(|t| t.name == name)
            .map(|i| (i, tags[i].get("Scalars")))
    };
    let arrays_after = |start: usize| -> Vec<&Tag<'_>> {
        tags[start + 1..]
            .iter()
            .take_while(|t| t.name == "DataArray")
            .collect()
    };
    let mut chosen = None;
    for (name, cell_data) in [("PointData", false), ("CellData", true)] {
        if let Some((i, active)) = section(name) {
            let arrays = arrays_after(i);
            let pick = active
                .and_then(|a| arrays.iter().find(|t| t.get("Name") == Some(a)).copied())
                .or_else(|| arrays.first().copied());
            if let Some(array) = pick {
                chosen = Some((array, cell_data));
                break;
            }
        }
    }
    let (array, cell_data) =
        chosen.ok_or_else(|| malformed(path, XML, "no DataArray in PointData or CellData"))?;
    let components = array.get("NumberOfComponents").unwrap_or("1");
    if components.trim() != "1" {
        return Err(GridError::Unsupported {
            path: path.to_owned(),
            what: "number of components",
            value: components.to_owned(),
        });
    }
    let type_name = array.get("type").unwrap_or("");
    let scalar = xml_type(type_name).ok_or_else(|| GridError::Unsupported {
        path: path.to_owned(),
        what: "voxel type",
        value: type_name.to_owned(),
    })?;
    let (dims, spacing, first) = placement(
        path,
        XML,
        extent,
        DVec3::from_array(origin),
        DVec3::from_array(spacing),
        cell_data,
    )?;
    let voxels = checked_voxels(path, XML, dims)?;
    options.reserve_voxels(path, voxels, scalar)?;
    let expected = voxels * scalar.size() as u64;
    let samples = match array.get("format").unwrap_or("ascii") {
        "ascii" => {
            let body = &text[array.end..];
            let body = &body[..body.find('<').unwrap_or(body.len())];
            let values: Vec<f32> = body
                .split_whitespace()
                .map(|v| v.parse::<f64>().map(|v| v as f32))
                .collect::<Result<_, _>>()
                .map_err(|_| malformed(path, XML, "a value of the ascii array is not a number"))?;
            if values.len() as u64 != voxels {
                return Err(GridError::SizeMismatch {
                    path: path.to_owned(),
                    expected: voxels,
                    found: values.len() as u64,
                });
            }
            values
        }
        "binary" => {
            let payload = binary_payload(
                path,
                &bytes[array.end..xml_end.max(array.end)],
                true,
                framing,
                expected,
            )?;
            decode(&payload, scalar, endian)
        }
        "appended" => {
            let appended = tags
                .last()
                .filter(|t| t.name == "AppendedData")
                .ok_or_else(|| {
                    malformed(path, XML, "format=\"appended\" without <AppendedData>")
                })?;
            let offset: usize = array
                .get("offset")
                .and_then(|o| o.trim().parse().ok())
                .ok_or_else(|| malformed(path, XML, "an appended array without `offset`"))?;
            // The data start after the `_` that follows the tag.
            let after = &bytes[appended.end..];
            let underscore = after
                .iter()
                .position(|&b| b == b'_')
                .ok_or_else(|| malformed(path, XML, "no `_` before the appended data"))?;
            let data = &after[underscore + 1..];
            let start = data.get(offset..).ok_or_else(|| GridError::Truncated {
                path: path.to_owned(),
                what: "appended data",
                expected: offset as u64,
                found: data.len() as u64,
            })?;
            let base64 = match appended.get("encoding").unwrap_or("raw") {
                "raw" => false,
                "base64" => true,
                other => {
                    return Err(GridError::Unsupported {
                        path: path.to_owned(),
                        what: "appended data encoding",
                        value: other.to_owned(),
                    });
                }
            };
            let payload = binary_payload(path, start, base64, framing, expected)?;
            decode(&payload, scalar, endian)
        }
        other => {
            return Err(GridError::Unsupported {
                path: path.to_owned(),
                what: "array format",
                value: other.to_owned(),
            });
        }
    };
    grid_at(path, XML, dims, spacing, first, samples)
}

fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

/// Writes `grid` as a VTK XML ImageData file: its cells as point data (the inverse of
/// [`read`]), one `Float32`-or-`scalar` array `density`, raw appended data with a `UInt64`
/// header, zlib-compressed in blocks of 32 KiB when `compress` is set.
pub fn write(
    path: impl AsRef<Path>,
    grid: &Grid,
    scalar: ScalarType,
    compress: bool,
) -> Result<(), GridError> {
    let path = path.as_ref();
    let g = grid.geometry();
    let [nx, ny, nz] = g.dims();
    let h = g.spacing();
    let first = g.origin() + 0.5 * h;
    let type_name = match scalar {
        ScalarType::I8 => "Int8",
        ScalarType::U8 => "UInt8",
        ScalarType::I16 => "Int16",
        ScalarType::U16 => "UInt16",
        ScalarType::I32 => "Int32",
        ScalarType::U32 => "UInt32",
        ScalarType::F16 | ScalarType::F32 => "Float32",
        ScalarType::F64 => "Float64",
    };
    let scalar = if scalar == ScalarType::F16 {
        ScalarType::F32
    } else {
        scalar
    };
    let payload = encode(path, grid.data(), scalar, Endian::Little)?;
    let mut data = Vec::new();
    if compress {
        use std::io::Write;
        const BLOCK: usize = 32 << 10;
        let blocks: Vec<Vec<u8>> = payload
            .chunks(BLOCK)
            .map(|chunk| {
                let mut z =
                    flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
                z.write_all(chunk)
                    .and_then(|()| z.finish())
                    .map_err(|source| GridError::Io {
                        path: path.to_owned(),
                        source,
                    })
            })
            .collect::<Result<_, _>>()?;
        let last = payload.len() - (blocks.len().max(1) - 1) * BLOCK;
        for v in [blocks.len(), BLOCK, last] {
            data.extend_from_slice(&(v as u64).to_le_bytes());
        }
        for b in &blocks {
            data.extend_from_slice(&(b.len() as u64).to_le_bytes());
        }
        for b in &blocks {
            data.extend_from_slice(b);
        }
    } else {
        data.extend_from_slice(&(payload.len() as u64).to_le_bytes());
        data.extend_from_slice(&payload);
    }
    let compressor = if compress {
        " compressor=\"vtkZLibDataCompressor\""
    } else {
        ""
    };
    let mut out = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\"{compressor}>\n  <ImageData WholeExtent=\"0 {} 0 {} 0 {}\" Origin=\"{} {} {}\" Spacing=\"{} {} {}\">\n    <Piece Extent=\"0 {} 0 {} 0 {}\">\n      <PointData Scalars=\"density\">\n        <DataArray type=\"{type_name}\" Name=\"density\" format=\"appended\" offset=\"0\"/>\n      </PointData>\n    </Piece>\n  </ImageData>\n  <AppendedData encoding=\"raw\">\n   _",
        nx - 1, ny - 1, nz - 1, first.x, first.y, first.z, h.x, h.y, h.z, nx - 1, ny - 1, nz - 1
    )
    .into_bytes();
    out.extend_from_slice(&data);
    out.extend_from_slice(b"\n  </AppendedData>\n</VTKFile>\n");
    write_file(path, &out)
}
