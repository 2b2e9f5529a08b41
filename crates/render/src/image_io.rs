//! Linear RGB images, tone mapping, and PNG / EXR output.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::RenderError;

/// The curve from exposed linear radiance to display values in [0, 1].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ToneMap {
    /// Clip at 1.
    Clamp,
    /// x/(1 + x).
    Reinhard,
    /// Narkowicz's fit of the ACES filmic curve.
    #[default]
    Aces,
}

impl ToneMap {
    fn apply(self, x: f64) -> f64 {
        let x = x.max(0.0);
        match self {
            ToneMap::Clamp => x.min(1.0),
            ToneMap::Reinhard => x / (1.0 + x),
            ToneMap::Aces => {
                ((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)).clamp(0.0, 1.0)
            }
        }
    }
}

/// A linear-radiance RGB image, rows top to bottom.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Linear RGB per pixel, row-major from the top-left.
    pub pixels: Vec<[f32; 3]>,
}

/// The sRGB transfer function (IEC 61966-2-1).
fn srgb_encode(linear: f64) -> f64 {
    if linear <= 0.003_130_8 {
        12.92 * linear
    } else {
        1.055 * linear.powf(1.0 / 2.4) - 0.055
    }
}

impl Image {
    /// 8-bit sRGB after multiplying by 2^`exposure` and applying `tone`.
    pub fn to_srgb8(&self, exposure: f64, tone: ToneMap) -> Vec<u8> {
        let scale = exposure.exp2();
        self.pixels
            .iter()
            .flat_map(|p| {
                p.map(|c| {
                    (srgb_encode(tone.apply(f64::from(c) * scale)) * 255.0 + 0.5).clamp(0.0, 255.0)
                        as u8
                })
            })
            .collect()
    }

    /// Mean linear luminance (Rec. 709 weights), for tests and exposure.
    pub fn mean_luminance(&self) -> f64 {
        let sum: f64 = self
            .pixels
            .iter()
            .map(|p| 0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2]))
            .sum();
        sum / self.pixels.len().max(1) as f64
    }

    /// Writes an 8-bit sRGB PNG, whole or not at all (encoded in memory, then written
    /// beside the target and renamed over it: `lucent_grid::io::atomic`).
    pub fn write_png(
        &self,
        path: impl AsRef<Path>,
        exposure: f64,
        tone: ToneMap,
    ) -> Result<(), RenderError> {
        let path = path.as_ref();
        let fail = |reason: String| RenderError::Write {
            path: path.to_owned(),
            reason,
        };
        let (w, h) = (
            u32::try_from(self.width).map_err(|e| fail(e.to_string()))?,
            u32::try_from(self.height).map_err(|e| fail(e.to_string()))?,
        );
        let mut encoded = std::io::Cursor::new(Vec::new());
        image::write_buffer_with_format(
            &mut encoded,
            &self.to_srgb8(exposure, tone),
            w,
            h,
            image::ColorType::Rgb8,
            image::ImageFormat::Png,
        )
        .map_err(|e| fail(e.to_string()))?;
        write_whole(path, encoded.get_ref())
    }

    /// Writes a linear f32 RGB OpenEXR file (no tone mapping: the radiance itself), whole
    /// or not at all.
    pub fn write_exr(&self, path: impl AsRef<Path>) -> Result<(), RenderError> {
        use exr::prelude::{Image as ExrImage, SpecificChannels, Vec2, WritableImage};
        let path = path.as_ref();
        let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
            let p = self.pixels[y * self.width + x];
            (p[0], p[1], p[2])
        });
        let mut encoded = std::io::Cursor::new(Vec::new());
        ExrImage::from_channels((self.width, self.height), channels)
            .write()
            .to_buffered(&mut encoded)
            .map_err(|e| RenderError::Write {
                path: path.to_owned(),
                reason: e.to_string(),
            })?;
        write_whole(path, encoded.get_ref())
    }

    /// Writes PNG or EXR by the extension (`.png`, `.exr`).
    pub fn write(
        &self,
        path: impl AsRef<Path>,
        exposure: f64,
        tone: ToneMap,
    ) -> Result<(), RenderError> {
        let path = path.as_ref();
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref()
        {
            Some("png") => self.write_png(path, exposure, tone),
            Some("exr") => self.write_exr(path),
            _ => Err(RenderError::Write {
                path: path.to_owned(),
                reason: "the image must end in .png or .exr".into(),
            }),
        }
    }
}

/// `bytes` as the file `path`, whole or not at all.
fn write_whole(path: &Path, bytes: &[u8]) -> Result<(), RenderError> {
    use std::io::Write;
    lucent_grid::io::atomic::write_with(path, |f| f.write_all(bytes)).map_err(|e| {
        RenderError::Write {
            path: path.to_owned(),
            reason: e.to_string(),
        }
    })
}
