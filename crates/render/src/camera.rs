//! Cameras: where each pixel's ray starts and where it goes.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::RenderError;

/// A camera looking from `position` toward `look_at`, with `up` fixing the roll.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Camera {
    /// A pinhole (perspective) camera with a vertical field of view in degrees.
    Pinhole {
        /// Eye position.
        position: [f64; 3],
        /// Point the camera looks at.
        look_at: [f64; 3],
        /// Up direction (need not be orthogonal to the view direction).
        #[serde(default = "default_up")]
        up: [f64; 3],
        /// Vertical field of view, degrees (0, 180).
        #[serde(default = "default_fov")]
        fov: f64,
    },
    /// An orthographic camera whose image is `height` scene units tall.
    Orthographic {
        /// Centre of the image plane.
        position: [f64; 3],
        /// Point the camera looks at (sets the view direction).
        look_at: [f64; 3],
        /// Up direction.
        #[serde(default = "default_up")]
        up: [f64; 3],
        /// Height of the view, scene units.
        height: f64,
    },
}

fn default_up() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

fn default_fov() -> f64 {
    40.0
}

/// The camera's orthonormal frame: right, up, forward.
pub(crate) struct Frame {
    pub(crate) origin: DVec3,
    pub(crate) right: DVec3,
    pub(crate) up: DVec3,
    pub(crate) forward: DVec3,
}

impl std::fmt::Display for Camera {
    /// In words, four significant digits.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use lucent_optics::Significant as S;
        let v = |a: &[f64; 3]| format!("({}, {}, {})", S(a[0]), S(a[1]), S(a[2]));
        match self {
            Camera::Pinhole {
                position,
                look_at,
                up,
                fov,
            } => write!(
                f,
                "pinhole at {} looking at {}, up {}, {}° vertical field of view",
                v(position),
                v(look_at),
                v(up),
                S(*fov)
            ),
            Camera::Orthographic {
                position,
                look_at,
                up,
                height,
            } => write!(
                f,
                "orthographic at {} looking at {}, up {}, {} units tall",
                v(position),
                v(look_at),
                v(up),
                S(*height)
            ),
        }
    }
}

impl Camera {
    pub(crate) fn frame(&self) -> Result<Frame, RenderError> {
        let (position, look_at, up) = match *self {
            Camera::Pinhole {
                position,
                look_at,
                up,
                ..
            }
            | Camera::Orthographic {
                position,
                look_at,
                up,
                ..
            } => (
                DVec3::from_array(position),
                DVec3::from_array(look_at),
                DVec3::from_array(up),
            ),
        };
        let forward = (look_at - position).normalize_or_zero();
        let right = forward.cross(up).normalize_or_zero();
        if !position.is_finite() || forward == DVec3::ZERO || right == DVec3::ZERO {
            return Err(RenderError::Invalid(
                "the camera needs a finite position, a distinct look_at and an up not parallel to the view".into(),
            ));
        }
        Ok(Frame {
            origin: position,
            right,
            up: right.cross(forward),
            forward,
        })
    }

    /// Checks the camera (distinct points, usable up vector, 0 < fov < 180, height > 0).
    pub fn validate(&self) -> Result<(), RenderError> {
        self.frame()?;
        match *self {
            Camera::Pinhole { fov, .. } if !(fov > 0.0 && fov < 180.0) => Err(
                RenderError::Invalid(format!("field of view {fov}° must lie in (0, 180)")),
            ),
            Camera::Orthographic { height, .. } if !(height > 0.0 && height.is_finite()) => Err(
                RenderError::Invalid(format!("orthographic height {height} must be positive")),
            ),
            _ => Ok(()),
        }
    }

    /// The ray through image point (u, v) ∈ [0, 1]² (u to the right, v downward) of an
    /// image with `aspect` = width/height: (origin, unit direction).
    pub fn ray(&self, u: f64, v: f64, aspect: f64) -> Result<(DVec3, DVec3), RenderError> {
        let f = self.frame()?;
        let (sx, sy) = (2.0 * u - 1.0, 1.0 - 2.0 * v);
        Ok(match *self {
            Camera::Pinhole { fov, .. } => {
                let half = (0.5 * fov.to_radians()).tan();
                let d = f.forward + f.right * (sx * half * aspect) + f.up * (sy * half);
                (f.origin, d.normalize())
            }
            Camera::Orthographic { height, .. } => {
                let o =
                    f.origin + f.right * (sx * 0.5 * height * aspect) + f.up * (sy * 0.5 * height);
                (o, f.forward)
            }
        })
    }
}
