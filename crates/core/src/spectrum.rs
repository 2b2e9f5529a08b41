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

    /// Whether every component is finite and ≥ 0.
    pub fn is_valid(&self) -> bool {
        let ok = |v: f64| v.is_finite() && v >= 0.0;
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

impl Default for Spectrum {
    fn default() -> Self {
        Spectrum::Grey(0.0)
    }
}
