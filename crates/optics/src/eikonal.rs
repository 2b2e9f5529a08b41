//! Rays in a medium whose refractive index η(x) varies smoothly: the eikonal ray equation
//! (Bernabei, thesis ch. 4, Eqs. 4.1–4.2, after Ihrke et al.)
//!
//! d/ds (η dx/ds) = ∇η,
//!
//! with s the arc length. As a first-order system in the position x and the *optical
//! direction* v = η dx/ds (|v| = η):
//!
//! dx/ds = v/η(x),    dv/ds = ∇η(x).
//!
//! Bernabei's kernel (his Fig. 4.4) updates v += δ ∇η/η, which is not Eq. 4.2: on a
//! Luneburg lens the equation focuses parallel rays within 10⁻³ R, the kernel misses by a
//! few hundredths of R. The equation is what is integrated here.
//!
//! **Scheme.** Classical fourth-order Runge–Kutta in s with step doubling: each step of
//! length h is also taken as two steps of h/2, their difference estimates the local error
//! (the half-step result, Richardson-extrapolated, is kept: fifth-order accurate), and the
//! step grows or shrinks to keep the error per step below `tolerance × h` (an error per unit
//! length, so the error at the end of a ray of length L is about `tolerance × L`). After
//! each step |v| is set back to η(x) (the invariant the exact flow keeps), so round-off
//! cannot drift into the speed. With ∇η = 0 every step is an exact straight segment.
//!
//! **Limits.** η must be positive and finite and ∇η finite wherever the ray goes
//! ([`EikonalError::BadIndex`] otherwise); a jump in η is a surface, handled by Fresnel
//! and Snell ([`crate::Dielectric`]), not by this equation; a kink (a jump in ∇η, as at a
//! Luneburg lens's rim) is crossed at the smallest step (`min_step`), where RK4's error,
//! the jump times the step, is negligible.

use glam::DVec3;

use crate::error::OpticsError;

/// A refractive-index field: η and its gradient at a point (scene units).
pub trait IndexField: Sync {
    /// η(x) (dimensionless, > 0).
    fn eta(&self, x: DVec3) -> f64;
    /// ∇η(x) (1/length).
    fn gradient(&self, x: DVec3) -> DVec3;
}

/// A uniform index: rays are straight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UniformIndex(pub f64);

impl IndexField for UniformIndex {
    fn eta(&self, _: DVec3) -> f64 {
        self.0
    }
    fn gradient(&self, _: DVec3) -> DVec3 {
        DVec3::ZERO
    }
}

/// η = η₀ + g·(x − origin): a linear gradient. Rays in it are catenaries in the plane of
/// their start direction and g (the component of v across g is conserved).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearIndex {
    /// η at `origin`.
    pub eta0: f64,
    /// ∇η (1/length).
    pub gradient: DVec3,
    /// Where η = η₀.
    pub origin: DVec3,
}

impl IndexField for LinearIndex {
    fn eta(&self, x: DVec3) -> f64 {
        self.eta0 + self.gradient.dot(x - self.origin)
    }
    fn gradient(&self, _: DVec3) -> DVec3 {
        self.gradient
    }
}

/// Luneburg's lens: η = √(2 − (r/R)²) inside the sphere of radius R, 1 outside. Parallel
/// rays entering it meet at the point of its rim opposite their direction of arrival.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Luneburg {
    /// The lens's centre.
    pub centre: DVec3,
    /// Its radius (length).
    pub radius: f64,
}

impl IndexField for Luneburg {
    fn eta(&self, x: DVec3) -> f64 {
        let r2 = (x - self.centre).length_squared() / (self.radius * self.radius);
        if r2 < 1.0 { (2.0 - r2).sqrt() } else { 1.0 }
    }
    fn gradient(&self, x: DVec3) -> DVec3 {
        let d = x - self.centre;
        let r2 = d.length_squared() / (self.radius * self.radius);
        if r2 < 1.0 {
            -d / (self.radius * self.radius * (2.0 - r2).sqrt())
        } else {
            DVec3::ZERO
        }
    }
}

/// Why a ray could not be traced.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EikonalError {
    /// The index field gave η ≤ 0 or a non-finite η or ∇η on the ray's way.
    #[error(
        "the refractive index is {eta} (gradient {gradient}) at {at}: it must be positive and finite"
    )]
    BadIndex {
        /// Where.
        at: DVec3,
        /// η there.
        eta: f64,
        /// ∇η there.
        gradient: DVec3,
    },
    /// The settings or the start are unusable.
    #[error(transparent)]
    Settings(#[from] OpticsError),
    /// The ray took more than [`MAX_STEPS`] steps (a field that keeps the step at its
    /// smallest).
    #[error(
        "the ray took more than {steps} steps, at {at}: the index field keeps the step at its smallest"
    )]
    TooManySteps {
        /// Where.
        at: DVec3,
        /// The limit.
        steps: usize,
    },
}

/// The most accepted steps of one ray.
pub const MAX_STEPS: usize = 10_000_000;

/// How accurately and how far to trace.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RaySettings {
    /// Allowed local error per unit length of path (dimensionless), e.g. 1e-8.
    pub tolerance: f64,
    /// The first step's length and the largest step (length).
    pub max_step: f64,
    /// The smallest step before giving up (length).
    pub min_step: f64,
}

impl RaySettings {
    /// Settings for features of size `scale` (a cell, a lens radius): steps of at most a
    /// tenth of it, the given tolerance.
    pub fn for_scale(scale: f64, tolerance: f64) -> Self {
        Self {
            tolerance,
            max_step: 0.1 * scale,
            min_step: 1e-9 * scale,
        }
    }

    fn check(&self) -> Result<(), OpticsError> {
        for (name, value) in [
            ("tolerance", self.tolerance),
            ("max_step", self.max_step),
            ("min_step", self.min_step),
        ] {
            if !value.is_finite() {
                return Err(OpticsError::NotFinite { name, value });
            }
            if value <= 0.0 {
                return Err(OpticsError::OutOfRange {
                    name,
                    range: "(0, ∞)",
                    value,
                });
            }
        }
        if self.min_step > self.max_step {
            return Err(OpticsError::OutOfRange {
                name: "min_step",
                range: "(0, max_step]",
                value: self.min_step,
            });
        }
        Ok(())
    }
}

/// A point on a traced ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayPoint {
    /// Position.
    pub position: DVec3,
    /// Unit direction of travel dx/ds.
    pub direction: DVec3,
    /// Arc length from the start.
    pub arc_length: f64,
}

/// The state (x, v) and its derivative.
#[derive(Clone, Copy)]
struct State {
    x: DVec3,
    v: DVec3,
}

fn derivative(field: &dyn IndexField, s: State) -> Result<State, EikonalError> {
    let eta = field.eta(s.x);
    let gradient = field.gradient(s.x);
    if !(eta > 0.0 && eta.is_finite() && gradient.is_finite()) {
        return Err(EikonalError::BadIndex {
            at: s.x,
            eta,
            gradient,
        });
    }
    Ok(State {
        x: s.v / eta,
        v: gradient,
    })
}

/// One classical RK4 step of length h.
fn rk4(field: &dyn IndexField, s: State, h: f64) -> Result<State, EikonalError> {
    let at = |base: State, k: State, f: f64| State {
        x: base.x + k.x * f,
        v: base.v + k.v * f,
    };
    let k1 = derivative(field, s)?;
    let k2 = derivative(field, at(s, k1, 0.5 * h))?;
    let k3 = derivative(field, at(s, k2, 0.5 * h))?;
    let k4 = derivative(field, at(s, k3, h))?;
    Ok(State {
        x: s.x + (k1.x + 2.0 * k2.x + 2.0 * k3.x + k4.x) * (h / 6.0),
        v: s.v + (k1.v + 2.0 * k2.v + 2.0 * k3.v + k4.v) * (h / 6.0),
    })
}

/// Traces a ray from `start` along `direction` (normalised here) for an arc length of
/// `length`, calling `visit` at the start and after every accepted step; `visit`
/// returning `false` stops the trace there. Returns the last point.
pub fn trace(
    field: &dyn IndexField,
    start: DVec3,
    direction: DVec3,
    length: f64,
    settings: &RaySettings,
    mut visit: impl FnMut(&RayPoint) -> bool,
) -> Result<RayPoint, EikonalError> {
    settings.check()?;
    let d = direction.normalize_or_zero();
    if d == DVec3::ZERO || !start.is_finite() {
        return Err(OpticsError::NotFinite {
            name: "ray start or direction",
            value: f64::NAN,
        }
        .into());
    }
    if !(length >= 0.0 && length.is_finite()) {
        return Err(OpticsError::OutOfRange {
            name: "length",
            range: "[0, ∞)",
            value: length,
        }
        .into());
    }
    let eta0 = field.eta(start);
    derivative(
        field,
        State {
            x: start,
            v: d * eta0,
        },
    )?;
    let mut state = State {
        x: start,
        v: d * eta0,
    };
    let point = |s: &State, arc_length: f64| RayPoint {
        position: s.x,
        direction: s.v.normalize_or_zero(),
        arc_length,
    };
    let mut s = 0.0;
    let mut h = settings.max_step;
    let mut steps = 0usize;
    if !visit(&point(&state, s)) {
        return Ok(point(&state, s));
    }
    while s < length {
        let step = h.min(length - s);
        let full = rk4(field, state, step)?;
        let half = rk4(field, state, 0.5 * step)?;
        let halves = rk4(field, half, 0.5 * step)?;
        // RK4's local error is O(h⁵): the two results differ by about 15/16 of the
        // error of the full step. A direction error δθ moves the ray by δθ per unit of
        // length still to go, so it counts over the features' scale (ten largest steps):
        // across a kink of η (a lens's rim) the position is still good when the direction
        // is not.
        let eta_here = field.eta(state.x);
        let turn = (halves.v - full.v).length() / eta_here;
        let error = (halves.x - full.x)
            .length()
            .max(turn * 10.0 * settings.max_step)
            / 15.0;
        // Per unit length, above the rounding of the position (without that floor a
        // straight stretch after the smallest step would never grow again).
        let allowed = settings.tolerance * step
            + 64.0 * f64::EPSILON * (state.x.length() + settings.max_step);
        if error > allowed && step > settings.min_step {
            // Shrink, down to the smallest step, which is taken whatever its error: a kink
            // of η (a jump of ∇η) costs RK4 an error of the jump times the step, which no
            // step meets per unit length, and the smallest step makes it negligible.
            h = (step * 0.9 * (allowed / error).powf(0.2))
                .max(0.25 * step)
                .max(settings.min_step);
            continue;
        }
        steps += 1;
        if steps > MAX_STEPS {
            return Err(EikonalError::TooManySteps {
                at: state.x,
                steps: MAX_STEPS,
            });
        }
        // Richardson: the halves' result corrected by the estimated error.
        let x = halves.x + (halves.x - full.x) / 15.0;
        let v = halves.v + (halves.v - full.v) / 15.0;
        let eta = field.eta(x);
        state = State {
            x,
            v: v.normalize_or_zero() * eta,
        };
        s += step;
        let grow = if error > 0.0 {
            0.9 * (allowed / error).powf(0.2)
        } else {
            4.0
        };
        h = (step * grow.clamp(0.25, 4.0)).clamp(settings.min_step, settings.max_step);
        if !visit(&point(&state, s)) {
            break;
        }
    }
    Ok(point(&state, s))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_settings_and_indices_are_errors() {
        let settings = RaySettings::for_scale(1.0, 1e-8);
        let bad = RaySettings {
            min_step: 2.0,
            ..settings
        };
        assert!(
            trace(&UniformIndex(1.0), DVec3::ZERO, DVec3::X, 1.0, &bad, |_| {
                true
            })
            .is_err()
        );
        assert!(
            trace(
                &UniformIndex(1.0),
                DVec3::ZERO,
                DVec3::ZERO,
                1.0,
                &settings,
                |_| true
            )
            .is_err()
        );
        assert!(matches!(
            trace(
                &UniformIndex(-1.0),
                DVec3::ZERO,
                DVec3::X,
                1.0,
                &settings,
                |_| true
            ),
            Err(EikonalError::BadIndex { .. })
        ));
        // η falls to zero on the way.
        let falling = LinearIndex {
            eta0: 1.0,
            gradient: DVec3::new(-1.0, 0.0, 0.0),
            origin: DVec3::ZERO,
        };
        assert!(matches!(
            trace(&falling, DVec3::ZERO, DVec3::X, 2.0, &settings, |_| true),
            Err(EikonalError::BadIndex { .. })
        ));
    }
}
