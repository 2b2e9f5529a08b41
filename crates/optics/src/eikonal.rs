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

use glam::{DMat3, DVec3};

use crate::error::OpticsError;

/// A refractive-index field: η and its gradient at a point (scene units).
pub trait IndexField: Sync {
    /// η(x) (dimensionless, > 0).
    fn eta(&self, x: DVec3) -> f64;
    /// ∇η(x) (1/length).
    fn gradient(&self, x: DVec3) -> DVec3;
    /// ∇∇η(x) (1/length²), which the ray tube's variational equations need.
    fn hessian(&self, x: DVec3) -> DMat3;
    /// Where ∇η jumps (η continuous, its gradient not: a Luneburg lens's rim), a level
    /// function k(x) whose sign changes across that surface, and ∇k there: (k(x), ∇k(x)).
    /// `None` (the default) for fields whose gradient is continuous. The ray tube picks
    /// up the jump where a ray crosses it (the saltation of its variational equations).
    fn kink(&self, x: DVec3) -> Option<(f64, DVec3)> {
        let _ = x;
        None
    }
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
    fn hessian(&self, _: DVec3) -> DMat3 {
        DMat3::ZERO
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
    fn hessian(&self, _: DVec3) -> DMat3 {
        DMat3::ZERO
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
    fn hessian(&self, x: DVec3) -> DMat3 {
        // ∂ⱼ(−dᵢ/(R²η)) = −δᵢⱼ/(R²η) − dᵢdⱼ/(R⁴η³).
        let d = x - self.centre;
        let r2 = self.radius * self.radius;
        if d.length_squared() < r2 {
            let eta = (2.0 - d.length_squared() / r2).sqrt();
            let outer = DMat3::from_cols(d * d.x, d * d.y, d * d.z);
            DMat3::IDENTITY * (-1.0 / (r2 * eta)) - outer * (1.0 / (r2 * r2 * eta * eta * eta))
        } else {
            DMat3::ZERO
        }
    }
    fn kink(&self, x: DVec3) -> Option<(f64, DVec3)> {
        // The rim r = R, where ∇η jumps from −(x − c)/R² to 0.
        let d = x - self.centre;
        let r2 = self.radius * self.radius;
        Some((d.length_squared() / r2 - 1.0, d * (2.0 / r2)))
    }
}

/// A Gaussian bump of index, η = η₀ + A e^{−|x − c|²/w²}: a smooth graded lens (converging
/// for A > 0, diverging for A < 0), smooth everywhere (no rim, unlike Luneburg's).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaussianBump {
    /// η far from the centre.
    pub eta0: f64,
    /// The bump's height A (η₀ + A at the centre).
    pub amplitude: f64,
    /// Its centre c.
    pub centre: DVec3,
    /// Its width w (length).
    pub width: f64,
}

impl GaussianBump {
    fn bump(&self, x: DVec3) -> (DVec3, f64) {
        let d = x - self.centre;
        (
            d,
            self.amplitude * (-d.length_squared() / (self.width * self.width)).exp(),
        )
    }
}

impl IndexField for GaussianBump {
    fn eta(&self, x: DVec3) -> f64 {
        self.eta0 + self.bump(x).1
    }
    fn gradient(&self, x: DVec3) -> DVec3 {
        let (d, b) = self.bump(x);
        d * (-2.0 * b / (self.width * self.width))
    }
    fn hessian(&self, x: DVec3) -> DMat3 {
        // ∂ⱼ(−2 dᵢ b/w²) = b (−2δᵢⱼ/w² + 4 dᵢdⱼ/w⁴).
        let (d, b) = self.bump(x);
        let w2 = self.width * self.width;
        let outer = DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        DMat3::IDENTITY * (-2.0 * b / w2) + outer * (4.0 * b / (w2 * w2))
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

/// How a ray's neighbours differ from it: the ray tube. For a family of rays x(s; a₁, a₂)
/// with launch parameters a₁, a₂ (an offset on a beam's cross-section, the two angles of
/// a point light's emission), `dx[i]` = ∂x/∂aᵢ and `dv[i]` = ∂v/∂aᵢ at equal arc length,
/// carried by the variational equations of the ray equation,
///
/// d(δx)/ds = δv/η − v (∇η·δx)/η²,    d(δv)/ds = (∇∇η) δx,
///
/// integrated by the same RK4 steps as the ray. The tube's cross-section normal to the
/// ray is |(`dx[0]` × `dx[1]`)·t| per unit of da₁ da₂ (t the unit direction; the part of δx
/// along the ray is a shift along it and drops out), so the flux a tube carries over that
/// cross-section gives the irradiance.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Tube {
    /// ∂x/∂aᵢ (length per unit of aᵢ).
    pub dx: [DVec3; 2],
    /// ∂v/∂aᵢ, v = η dx/ds the optical direction.
    pub dv: [DVec3; 2],
}

impl Tube {
    /// The cross-section normal to the unit direction `t` per unit of da₁ da₂ (signed: it
    /// changes sign where the ray passes a caustic, where neighbouring rays cross).
    pub fn cross_section(&self, t: DVec3) -> f64 {
        self.dx[0].cross(self.dx[1]).dot(t)
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
    /// The ray tube ([`trace_tube`]; zero for [`trace`]).
    pub tube: Tube,
}

/// The state (x, v, and the tube when traced) and its derivative.
#[derive(Clone, Copy)]
struct State {
    x: DVec3,
    v: DVec3,
    tube: Option<Tube>,
}

impl State {
    /// base + k·f, component by component.
    fn plus(self, k: State, f: f64) -> State {
        State {
            x: self.x + k.x * f,
            v: self.v + k.v * f,
            tube: self.tube.zip(k.tube).map(|(a, b)| Tube {
                dx: [a.dx[0] + b.dx[0] * f, a.dx[1] + b.dx[1] * f],
                dv: [a.dv[0] + b.dv[0] * f, a.dv[1] + b.dv[1] * f],
            }),
        }
    }
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
    let tube = s.tube.map(|t| {
        let hessian = field.hessian(s.x);
        let (inv, inv2) = (1.0 / eta, 1.0 / (eta * eta));
        let dx = |i: usize| t.dv[i] * inv - s.v * (gradient.dot(t.dx[i]) * inv2);
        Tube {
            dx: [dx(0), dx(1)],
            dv: [hessian * t.dx[0], hessian * t.dx[1]],
        }
    });
    Ok(State {
        x: s.v / eta,
        v: gradient,
        tube,
    })
}

/// One classical RK4 step of length h.
fn rk4(field: &dyn IndexField, s: State, h: f64) -> Result<State, EikonalError> {
    let k1 = derivative(field, s)?;
    let k2 = derivative(field, s.plus(k1, 0.5 * h))?;
    let k3 = derivative(field, s.plus(k2, 0.5 * h))?;
    let k4 = derivative(field, s.plus(k3, h))?;
    Ok(s.plus(k1, h / 6.0)
        .plus(k2, h / 3.0)
        .plus(k3, h / 3.0)
        .plus(k4, h / 6.0))
}

/// One step of length h by step doubling: RK4 over h and over two halves, the halves'
/// result Richardson-corrected by their difference (fifth-order accurate), and the
/// estimated local error (length). The optical direction is set back to |v| = η after it.
fn doubled_step(
    field: &dyn IndexField,
    state: State,
    h: f64,
    scale: f64,
) -> Result<(State, f64), EikonalError> {
    let full = rk4(field, state, h)?;
    let half = rk4(field, state, 0.5 * h)?;
    let halves = rk4(field, half, 0.5 * h)?;
    // RK4's local error is O(h⁵): the two results differ by about 15/16 of the error of
    // the full step. A direction error δθ moves the ray by δθ per unit of length still to
    // go, so it counts over the features' scale (`scale`, ten largest steps): across a
    // kink of η (a lens's rim) the position is still good when the direction is not.
    let eta_here = field.eta(state.x);
    let turn = (halves.v - full.v).length() / eta_here;
    let error = (halves.x - full.x).length().max(turn * scale) / 15.0;
    let corrected = halves.plus(halves.plus(full, -1.0), 1.0 / 15.0);
    let eta = field.eta(corrected.x);
    Ok((
        State {
            v: corrected.v.normalize_or_zero() * eta,
            ..corrected
        },
        error,
    ))
}

/// Where the step from `before` to `after` crossed a kink of the field (a jump of ∇η),
/// adds the jump to the tube: with the state's derivative F = (v/η, ∇η) jumping by
/// ΔF = (0, [∇η]) across the surface k(x) = 0, the variational solution jumps by
/// ΔF (∇k·δx)/(∇k·v/η) (the saltation matrix of a piecewise smooth flow). The tracer
/// crosses a kink at its smallest step, so both sides' gradients are taken at the step's
/// ends.
fn cross_kink(field: &dyn IndexField, before: &State, after: &mut State) {
    let Some(mut tube) = after.tube else {
        return;
    };
    let (Some((k0, _)), Some((k1, normal))) = (field.kink(before.x), field.kink(after.x)) else {
        return;
    };
    if (k0 < 0.0) == (k1 < 0.0) {
        return;
    }
    let jump = field.gradient(after.x) - field.gradient(before.x);
    let rate = normal.dot(after.v) / field.eta(after.x);
    if rate == 0.0 {
        return;
    }
    for i in 0..2 {
        tube.dv[i] += jump * (normal.dot(tube.dx[i]) / rate);
    }
    after.tube = Some(tube);
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
    visit: impl FnMut(&RayPoint) -> bool,
) -> Result<RayPoint, EikonalError> {
    run(field, start, direction, None, length, settings, visit)
}

/// [`trace`] with the ray tube: `tube` holds ∂x/∂aᵢ and ∂v/∂aᵢ at the start, and every
/// point the tube there (its variational equations integrated by the same steps; the step
/// control watches the ray alone). Needs the field's Hessian.
pub fn trace_tube(
    field: &dyn IndexField,
    start: DVec3,
    direction: DVec3,
    tube: Tube,
    length: f64,
    settings: &RaySettings,
    visit: impl FnMut(&RayPoint) -> bool,
) -> Result<RayPoint, EikonalError> {
    run(field, start, direction, Some(tube), length, settings, visit)
}

/// Continues a traced ray from `point` by one step of exactly `h` (step doubling, as the
/// tracer's steps; the tube if `point` carries one and `with_tube`): for landing on a
/// given place, e.g. the foot of a target's perpendicular inside the last step.
pub fn step_from(
    field: &dyn IndexField,
    point: &RayPoint,
    h: f64,
    with_tube: bool,
    settings: &RaySettings,
) -> Result<RayPoint, EikonalError> {
    let state = State {
        x: point.position,
        v: point.direction * field.eta(point.position),
        tube: with_tube.then_some(point.tube),
    };
    derivative(field, state)?;
    let (mut next, _) = doubled_step(field, state, h, 10.0 * settings.max_step)?;
    cross_kink(field, &state, &mut next);
    Ok(ray_point(&next, point.arc_length + h))
}

fn ray_point(s: &State, arc_length: f64) -> RayPoint {
    RayPoint {
        position: s.x,
        direction: s.v.normalize_or_zero(),
        arc_length,
        tube: s.tube.unwrap_or_default(),
    }
}

fn run(
    field: &dyn IndexField,
    start: DVec3,
    direction: DVec3,
    tube: Option<Tube>,
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
    let mut state = State {
        x: start,
        v: d * eta0,
        tube,
    };
    derivative(field, state)?;
    let mut s = 0.0;
    let mut h = settings.max_step;
    let mut steps = 0usize;
    if !visit(&ray_point(&state, s)) {
        return Ok(ray_point(&state, s));
    }
    while s < length {
        let step = h.min(length - s);
        let (next, error) = doubled_step(field, state, step, 10.0 * settings.max_step)?;
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
        let mut next = next;
        cross_kink(field, &state, &mut next);
        state = next;
        s += step;
        let grow = if error > 0.0 {
            0.9 * (allowed / error).powf(0.2)
        } else {
            4.0
        };
        h = (step * grow.clamp(0.25, 4.0)).clamp(settings.min_step, settings.max_step);
        if !visit(&ray_point(&state, s)) {
            break;
        }
    }
    Ok(ray_point(&state, s))
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
