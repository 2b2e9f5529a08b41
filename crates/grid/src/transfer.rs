//! Transfer functions: how a scalar volume (CT density, simulation output) becomes a
//! medium, by piecewise-linear maps from the scalar value to extinction, albedo and colour.

use serde::{Deserialize, Serialize};

use crate::dense::Grid;
use crate::error::GridError;

/// A piecewise-linear function through control points (x strictly increasing), constant
/// beyond the first and last point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "Vec<[f64; 2]>", into = "Vec<[f64; 2]>")]
pub struct PiecewiseLinear {
    points: Vec<[f64; 2]>,
}

impl PiecewiseLinear {
    /// Control points `[x, y]`: at least one, all finite, x strictly increasing.
    pub fn new(points: Vec<[f64; 2]>) -> Result<Self, GridError> {
        let bad = |reason: String| GridError::InvalidParameter {
            name: "control points",
            reason,
        };
        if points.is_empty() {
            return Err(bad("need at least one control point".into()));
        }
        if let Some(p) = points
            .iter()
            .find(|p| !p[0].is_finite() || !p[1].is_finite())
        {
            return Err(bad(format!("{p:?} is not finite")));
        }
        if let Some(w) = points.windows(2).find(|w| w[1][0] <= w[0][0]) {
            return Err(bad(format!(
                "x must increase strictly, but {} follows {}",
                w[1][0], w[0][0]
            )));
        }
        Ok(Self { points })
    }

    /// A constant function.
    pub fn constant(y: f64) -> Result<Self, GridError> {
        Self::new(vec![[0.0, y]])
    }

    /// The control points.
    pub fn points(&self) -> &[[f64; 2]] {
        &self.points
    }

    /// f(x); NaN maps to the first point's value.
    pub fn eval(&self, x: f64) -> f64 {
        let p = &self.points;
        let upper = p.partition_point(|q| q[0] <= x);
        if upper == 0 || x.is_nan() {
            return p[0][1];
        }
        if upper == p.len() {
            return p[p.len() - 1][1];
        }
        let ([x0, y0], [x1, y1]) = (p[upper - 1], p[upper]);
        y0 + (y1 - y0) * (x - x0) / (x1 - x0)
    }

    fn y_range(&self) -> (f64, f64) {
        self.points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p[1]), hi.max(p[1]))
            })
    }
}

impl TryFrom<Vec<[f64; 2]>> for PiecewiseLinear {
    type Error = GridError;
    fn try_from(points: Vec<[f64; 2]>) -> Result<Self, GridError> {
        Self::new(points)
    }
}

impl From<PiecewiseLinear> for Vec<[f64; 2]> {
    fn from(f: PiecewiseLinear) -> Self {
        f.points
    }
}

/// Maps a scalar volume to a medium:
/// σ_t(x) = `density_scale` · `extinction`(v(x)), albedo(x) = `albedo`(v(x)) ∈ [0, 1], and
/// optionally an RGB scattering colour per channel ∈ [0, 1] (grey media leave it out and
/// cost one channel).
///
/// In a scene file (TOML):
/// ```toml
/// density_scale = 20.0                         # 1/length at extinction 1
/// extinction = [[0.0, 0.0], [80.0, 0.0], [255.0, 1.0]]
/// albedo = [[0.0, 0.9]]
/// color = { red = [[0.0, 1.0]], green = [[0.0, 0.8]], blue = [[0.0, 0.6]] }
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "TransferFunctionSpec")]
pub struct TransferFunction {
    density_scale: f64,
    extinction: PiecewiseLinear,
    albedo: PiecewiseLinear,
    color: Option<ColorRamp>,
}

/// Per-channel colour ramps.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColorRamp {
    /// Red channel.
    pub red: PiecewiseLinear,
    /// Green channel.
    pub green: PiecewiseLinear,
    /// Blue channel.
    pub blue: PiecewiseLinear,
}

/// The unvalidated form that deserialisation reads.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TransferFunctionSpec {
    density_scale: f64,
    extinction: PiecewiseLinear,
    albedo: PiecewiseLinear,
    #[serde(default)]
    color: Option<ColorRamp>,
}

impl TryFrom<TransferFunctionSpec> for TransferFunction {
    type Error = GridError;
    fn try_from(s: TransferFunctionSpec) -> Result<Self, GridError> {
        Self::new(s.density_scale, s.extinction, s.albedo, s.color)
    }
}

/// The grids a transfer function produces.
#[derive(Debug, Clone, PartialEq)]
pub struct MediumGrids {
    /// Extinction σ_t (1/length).
    pub sigma_t: Grid,
    /// Single-scattering albedo.
    pub albedo: Grid,
    /// RGB scattering colour, when the transfer function has one.
    pub color: Option<[Grid; 3]>,
}

impl TransferFunction {
    /// Validates: `density_scale` ≥ 0 and finite, extinction ≥ 0, albedo and colour in [0, 1].
    pub fn new(
        density_scale: f64,
        extinction: PiecewiseLinear,
        albedo: PiecewiseLinear,
        color: Option<ColorRamp>,
    ) -> Result<Self, GridError> {
        let bad = |name, reason: String| GridError::InvalidParameter { name, reason };
        if !density_scale.is_finite() || density_scale < 0.0 {
            return Err(bad(
                "density_scale",
                format!("{density_scale} must be finite and non-negative"),
            ));
        }
        if extinction.y_range().0 < 0.0 {
            return Err(bad(
                "extinction",
                "control values must be non-negative".into(),
            ));
        }
        let unit = |f: &PiecewiseLinear| {
            let (lo, hi) = f.y_range();
            lo >= 0.0 && hi <= 1.0
        };
        if !unit(&albedo) {
            return Err(bad("albedo", "control values must lie in [0, 1]".into()));
        }
        if color
            .as_ref()
            .is_some_and(|c| ![&c.red, &c.green, &c.blue].into_iter().all(unit))
        {
            return Err(bad("color", "control values must lie in [0, 1]".into()));
        }
        Ok(Self {
            density_scale,
            extinction,
            albedo,
            color,
        })
    }

    /// σ_t for a scalar value.
    pub fn sigma_t(&self, value: f64) -> f64 {
        self.density_scale * self.extinction.eval(value)
    }

    /// Albedo for a scalar value.
    pub fn albedo(&self, value: f64) -> f64 {
        self.albedo.eval(value)
    }

    /// Applies the maps to every cell of a scalar volume.
    pub fn apply(&self, volume: &Grid) -> MediumGrids {
        fn map(volume: &Grid, f: impl Fn(f64) -> f64 + Sync) -> Grid {
            volume.map(|v| f(f64::from(v)) as f32)
        }
        MediumGrids {
            sigma_t: map(volume, |v| self.sigma_t(v)),
            albedo: map(volume, |v| self.albedo(v)),
            color: self.color.as_ref().map(|c| {
                [
                    map(volume, |v| c.red.eval(v)),
                    map(volume, |v| c.green.eval(v)),
                    map(volume, |v| c.blue.eval(v)),
                ]
            }),
        }
    }
}
