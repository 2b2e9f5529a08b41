//! Grey or RGB quantities: a grey scene stays one channel and costs one solve.

use serde::{Deserialize, Serialize};

/// A non-negative quantity that is either the same in every channel (grey) or given per
/// RGB channel. In scene files: a number or `[r, g, b]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Spectrum {
    /// One value for all channels.
    Grey(f64),
    /// Red, green, blue.
    Rgb([f64; 3]),
}

impl Spectrum {
    /// Channels this quantity needs: 1 for grey, 3 for RGB.
    pub fn channels(&self) -> usize {
        match self {
            Spectrum::Grey(_) => 1,
            Spectrum::Rgb(_) => 3,
        }
    }

    /// The value in `channel` (a grey value answers every channel).
    pub fn channel(&self, channel: usize) -> f64 {
        match self {
            Spectrum::Grey(v) => *v,
            Spectrum::Rgb(c) => c[channel.min(2)],
        }
    }

    /// The largest component a light may have (10³⁰): fluences are stored in f32
    /// (largest 3.4 × 10³⁸), and a light brighter than this could overflow them to
    /// infinity where it concentrates (a point light's 1/r² next to it, sums over lights
    /// and channels).
    pub const MAX: f64 = 1e30;

    /// Whether every component is finite, non-negative and at most [`Self::MAX`].
    pub fn is_valid(&self) -> bool {
        let ok = |v: f64| v.is_finite() && (0.0..=Self::MAX).contains(&v);
        match self {
            Spectrum::Grey(v) => ok(*v),
            Spectrum::Rgb(c) => c.iter().all(|&v| ok(v)),
        }
    }

    /// Whether every component is 0.
    pub fn is_black(&self) -> bool {
        (0..self.channels()).all(|c| self.channel(c) == 0.0)
    }
}

impl std::fmt::Display for Spectrum {
    /// `0.9` (grey) or `(10, 9.3, 8.2)` (red, green, blue), four significant digits.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use lucent_optics::Significant as S;
        match self {
            Spectrum::Grey(v) => write!(f, "{}", S(*v)),
            Spectrum::Rgb([r, g, b]) => write!(f, "({}, {}, {})", S(*r), S(*g), S(*b)),
        }
    }
}

impl Default for Spectrum {
    fn default() -> Self {
        Spectrum::Grey(0.0)
    }
}
