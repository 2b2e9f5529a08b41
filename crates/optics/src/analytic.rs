//! Closed-form references for cross-checking the solvers.
//!
//! All solutions are of the steady diffusion equation
//! −∇·(D∇φ) + σ_a φ = Q with D = 1/(3σ_t′), σ_tr = √(σ_a/D), and the Robin (extrapolated
//! boundary) condition φ + 2AD ∂φ/∂n = 0 on the outward normal, whose outgoing flux
//! (radiant exitance) is −D ∂φ/∂n = φ/(2A). Sources have unit power unless stated.
//! Formulas, the errata they avoid and the checked values are in docs/reference-cases.md (Mertens):
//! the virtual dipole source sits at z_v = z_r + 4AD above the surface (not the thesis's
//! misprints), and the first-moment source term enters with a minus sign.
//!
//! Two boundary models appear and are named apart: the exact **Robin** condition (sphere,
//! half-space) and the **extrapolated boundary** φ = 0 at distance 2AD outside the surface
//! (dipole, slab). They agree to first order in σ_tr·2AD; the dipole's total reflectance
//! differs from the exact Robin half-space by 0.1% for marble and 32% for ketchup (T5).

use std::f64::consts::PI;

use crate::coefficients::OpticalCoefficients;
use crate::error::{OpticsError, in_range, non_negative};
use crate::fresnel::{Dielectric, DiffuseFresnel};

/// Beer–Lambert transmittance e^{−τ} of an optical depth τ ≥ 0.
pub fn beer_lambert(optical_depth: f64) -> Result<f64, OpticsError> {
    Ok((-non_negative("optical_depth", optical_depth)?).exp())
}

/// Transmittance e^{−σ_t s} of a homogeneous segment of length s (both ≥ 0).
pub fn transmittance(sigma_t: f64, distance: f64) -> Result<f64, OpticsError> {
    beer_lambert(non_negative("sigma_t", sigma_t)? * non_negative("distance", distance)?)
}

/// A medium seen by diffusion theory: its coefficients and the boundary factor A of its
/// surface. Every closed-form solution below is built from one of these.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiffusionMedium {
    coefficients: OpticalCoefficients,
    a: f64,
}

impl DiffusionMedium {
    /// A medium with boundary factor A ≥ 1 (A = 1 for an index-matched boundary).
    pub fn new(coefficients: OpticalCoefficients, a: f64) -> Result<Self, OpticsError> {
        let a = in_range("A", a, "[1, inf)", |a| a >= 1.0)?;
        Ok(Self { coefficients, a })
    }

    /// A medium whose boundary factor comes from its dielectric boundary.
    pub fn with_boundary(
        coefficients: OpticalCoefficients,
        boundary: Dielectric,
        model: DiffuseFresnel,
    ) -> Result<Self, OpticsError> {
        Self::new(coefficients, boundary.boundary_factor(model)?)
    }

    /// The optical coefficients.
    pub fn coefficients(&self) -> &OpticalCoefficients {
        &self.coefficients
    }

    /// The boundary factor A.
    pub fn boundary_factor(&self) -> f64 {
        self.a
    }

    /// The diffusion coefficient D (length).
    pub fn d(&self) -> f64 {
        self.coefficients.diffusion_coefficient()
    }

    /// The effective transport coefficient σ_tr (1/length).
    pub fn sigma_tr(&self) -> f64 {
        self.coefficients.sigma_tr()
    }

    /// The extrapolation distance z_b = 2AD beyond the surface at which φ would vanish.
    pub fn extrapolation_distance(&self) -> f64 {
        2.0 * self.a * self.d()
    }

    /// Depth of the dipole's real source, z_r = 1/σ_t′.
    pub fn z_r(&self) -> f64 {
        self.coefficients.transport_mean_free_path()
    }

    /// Height of the dipole's virtual (negative) source above the surface, z_v = z_r + 4AD.
    pub fn z_v(&self) -> f64 {
        self.z_r() + 2.0 * self.extrapolation_distance()
    }

    /// The diffusion Green's function of an infinite medium: the fluence
    /// φ(r) = P e^{−σ_tr r}/(4π D r) at distance r > 0 from an isotropic point source of
    /// power P.
    pub fn infinite_medium_fluence(&self, power: f64, r: f64) -> Result<f64, OpticsError> {
        let r = in_range("r", r, "(0, inf)", |r| r > 0.0)?;
        Ok(power * (-self.sigma_tr() * r).exp() / (4.0 * PI * self.d() * r))
    }

    /// The classical dipole of Jensen et al. 2001 for this medium's semi-infinite half-space.
    pub fn dipole(&self) -> Dipole {
        Dipole { medium: *self }
    }

    /// A sphere of radius R > 0 with a unit point source at its centre.
    /// Needs σ_a > 0 (without absorption the solution is not of this form).
    pub fn sphere(&self, radius: f64) -> Result<RobinSphere, OpticsError> {
        RobinSphere::new(*self, radius)
    }

    /// A sphere of radius R > 0 with a unit point source at distance `r0` < R from its
    /// centre: the exact Legendre series (Robin condition). Needs σ_a > 0.
    pub fn sphere_off_centre(
        &self,
        radius: f64,
        r0: f64,
    ) -> Result<RobinSphereOffCentre, OpticsError> {
        RobinSphereOffCentre::new(*self, radius, r0)
    }

    /// A half-space z ≥ 0 with a unit plane source at depth z′ ≥ 0. Needs σ_a > 0.
    pub fn half_space(&self, source_depth: f64) -> Result<RobinHalfSpace, OpticsError> {
        RobinHalfSpace::new(*self, source_depth)
    }

    /// A disc of radius R > 0 (2D: an infinite cylinder) with a unit line source on its
    /// axis (Mertens T8, the analogue of Mertens' Figure 4.1). Needs σ_a > 0.
    pub fn disc(&self, radius: f64) -> Result<RobinDisc, OpticsError> {
        RobinDisc::new(*self, radius)
    }

    /// A slab of thickness d > 0 lit by the dipole source at depth z_r, with extrapolated
    /// boundaries (the multipole's model). Needs σ_a > 0.
    pub fn slab(&self, thickness: f64) -> Result<ExtrapolatedSlab, OpticsError> {
        ExtrapolatedSlab::new(*self, thickness)
    }

    fn require_absorption(&self) -> Result<f64, OpticsError> {
        let sigma = self.sigma_tr();
        if sigma > 0.0 {
            Ok(sigma)
        } else {
            Err(OpticsError::OutOfRange {
                name: "sigma_a",
                range: "(0, inf) for this closed form",
                value: self.coefficients.sigma_a(),
            })
        }
    }
}

/// The dipole diffusion profile: a real source α′ at depth z_r and a negative image at
/// height z_v (Jensen et al. 2001; Mertens Table 3.1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dipole {
    medium: DiffusionMedium,
}

impl Dipole {
    /// Diffuse reflectance profile R_d(r) (per unit area, 1/length²) at distance r ≥ 0 from
    /// the point of incidence:
    /// R_d = α′/(4π) [z_r(1 + σ_tr d_r) e^{−σ_tr d_r}/d_r³ + z_v(1 + σ_tr d_v) e^{−σ_tr d_v}/d_v³],
    /// with d_r = √(r² + z_r²), d_v = √(r² + z_v²).
    pub fn reflectance_profile(&self, r: f64) -> f64 {
        let m = &self.medium;
        let sigma = m.sigma_tr();
        let term = |z: f64| {
            let d = (r * r + z * z).sqrt();
            z * (1.0 + sigma * d) * (-sigma * d).exp() / (d * d * d)
        };
        m.coefficients.albedo_reduced() / (4.0 * PI) * (term(m.z_r()) + term(m.z_v()))
    }

    /// Total diffuse reflectance ρ = ∫ 2πr R_d(r) dr = (α′/2)(e^{−σ_tr z_r} + e^{−σ_tr z_v}).
    pub fn total_reflectance(&self) -> f64 {
        let m = &self.medium;
        let sigma = m.sigma_tr();
        0.5 * m.coefficients.albedo_reduced()
            * ((-sigma * m.z_r()).exp() + (-sigma * m.z_v()).exp())
    }

    /// The exact total reflectance of the same source in a Robin half-space,
    /// α′ e^{−σ_tr z_r}/(1 + 2ADσ_tr) (Mertens T5): the dipole's error is the difference.
    pub fn total_reflectance_exact(&self) -> Result<f64, OpticsError> {
        let m = &self.medium;
        Ok(m.coefficients.albedo_reduced() * m.half_space(m.z_r())?.exitance())
    }
}

/// A sphere of radius R with a unit isotropic point source at its centre and the Robin
/// condition on its surface (Mertens T7):
/// φ(r) = [e^{−σr}/r + C sinh(σr)/r]/(4πD), C = −(f + 2ADf′)/(g + 2ADg′) at r = R,
/// with f = e^{−σr}/r and g = sinh(σr)/r.
///
/// Internally C sinh(σr) is carried as B(e^{σ(r−R)} − e^{−σ(r+R)}) with B = C e^{σR}/2, so
/// nothing overflows for optically huge spheres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobinSphere {
    medium: DiffusionMedium,
    radius: f64,
    b: f64,
}

impl RobinSphere {
    fn new(medium: DiffusionMedium, radius: f64) -> Result<Self, OpticsError> {
        let radius = in_range("radius", radius, "(0, inf)", |r| r > 0.0)?;
        let sigma = medium.require_absorption()?;
        let zb = medium.extrapolation_distance();
        let r = radius;
        let f = (-sigma * r).exp() / r;
        let df = -(-sigma * r).exp() * (1.0 + sigma * r) / (r * r);
        let (ep, em) = (1.0, (-2.0 * sigma * r).exp()); // e^{σ(r−R)}, e^{−σ(r+R)} at r = R
        let g = (ep - em) / r;
        let dg = (sigma * (ep + em) * r - (ep - em)) / (r * r);
        let b = -(f + zb * df) / (g + zb * dg);
        Ok(Self { medium, radius, b })
    }

    /// The coefficient C of the regular solution sinh(σr)/r (may underflow to 0 for
    /// optically huge spheres, where it no longer matters).
    pub fn coefficient_c(&self) -> f64 {
        2.0 * self.b * (-self.medium.sigma_tr() * self.radius).exp()
    }

    /// Fluence φ(r) for 0 < r ≤ R (1/length²); r = 0 is the source's singularity.
    pub fn fluence(&self, r: f64) -> Result<f64, OpticsError> {
        let r = in_range("r", r, "(0, R]", |r| r > 0.0 && r <= self.radius)?;
        let sigma = self.medium.sigma_tr();
        let regular = (sigma * (r - self.radius)).exp() - (-sigma * (r + self.radius)).exp();
        Ok(((-sigma * r).exp() + self.b * regular) / (4.0 * PI * self.medium.d() * r))
    }

    /// Fraction of the source's power that leaves through the surface, 4πR² φ(R)/(2A).
    pub fn escaped_fraction(&self) -> f64 {
        let phi_r = self.fluence(self.radius).unwrap_or(0.0);
        4.0 * PI * self.radius * self.radius * phi_r / (2.0 * self.medium.a)
    }

    /// Fraction absorbed inside, ∫ σ_a φ dV, in closed form:
    /// 1 − e^{−σR}(1 + σR) + C(σR cosh σR − sinh σR). Escaped + absorbed = 1 is the energy
    /// balance a volumetric solver must reproduce.
    pub fn absorbed_fraction(&self) -> f64 {
        let s = self.medium.sigma_tr() * self.radius;
        let e2 = (-2.0 * s).exp();
        1.0 - (-s).exp() * (1.0 + s) + self.b * (s * (1.0 + e2) - (1.0 - e2))
    }
}

/// A sphere of radius R with a unit point source at distance r₀ from its centre and the
/// Robin condition on its surface:
///
/// φ(x) = [e^{−σ|x − x₀|}/|x − x₀| + Σ_l c_l i_l(σr) P_l(cos γ)]/(4πD),
///
/// γ the angle between x and x₀, i_l, k_l the modified spherical Bessel functions
/// (Abramowitz and Stegun 10.2, k_0(z) = π e^{−z}/(2z)). The free-space part expands as
/// e^{−σ|x − x₀|}/|x − x₀| = (2σ/π) Σ (2l + 1) i_l(σr_<) k_l(σr_>) P_l(cos γ), and each
/// c_l = −(2σ/π)(2l + 1) i_l(σr₀) [k_l + bσk_l′]/[i_l + bσi_l′] at σR (b = 2AD) makes the
/// sum satisfy φ + 2AD ∂φ/∂r = 0 at r = R. The Bessel functions are carried as logarithms
/// (ratios i_l/i_{l−1} by their continued fraction, k_{l+1}/k_l by the upward recurrence),
/// so neither (2l − 1)!! nor e^{σR} overflows; terms are summed until they fall below 10⁻¹⁷
/// of the sum (successive terms shrink by about r r₀/R²). At r₀ = 0 it is [`RobinSphere`].
/// The derivation is in `docs/point-sources.md`.
#[derive(Debug, Clone, PartialEq)]
pub struct RobinSphereOffCentre {
    medium: DiffusionMedium,
    radius: f64,
    r0: f64,
    /// Per l: ln î_l(σr₀) + ln k̂_l(σR) − ln î_l(σR) (î_l = i_l e^{−z}, k̂_l = k_l e^{z}).
    log_weight: Vec<f64>,
    /// Per l: (1 + bσ k_l′/k_l)/(1 + bσ i_l′/i_l) at σR.
    robin: Vec<f64>,
}

/// ln î_l(z) and i_{l+1}/i_l for l = 0..n (continued fraction from far above n).
fn log_bessel_i(n: usize, z: f64) -> (Vec<f64>, Vec<f64>) {
    let start = 2 * n + 60 + (2.0 * z).ceil() as usize;
    // s_l = i_l/i_{l−1} = 1/((2l + 1)/z + s_{l+1}).
    let mut ratio = vec![0.0; start + 2];
    for l in (1..=start).rev() {
        ratio[l] = 1.0 / ((2 * l + 1) as f64 / z + ratio[l + 1]);
    }
    let i0 = if z > 1e-8 {
        (-(-2.0 * z).exp_m1() / (2.0 * z)).ln()
    } else {
        -z
    };
    let mut log = Vec::with_capacity(n + 1);
    log.push(i0);
    for l in 1..=n {
        log.push(log[l - 1] + ratio[l].ln());
    }
    let next = (0..=n).map(|l| ratio[l + 1]).collect();
    (log, next)
}

/// ln k̂_l(z) and k_{l+1}/k_l for l = 0..n (upward recurrence of the ratio).
fn log_bessel_k(n: usize, z: f64) -> (Vec<f64>, Vec<f64>) {
    let mut log = Vec::with_capacity(n + 1);
    let mut next = Vec::with_capacity(n + 1);
    log.push((PI / (2.0 * z)).ln());
    let mut rho = 1.0 + 1.0 / z;
    for l in 0..=n {
        next.push(rho);
        if l < n {
            log.push(log[l] + rho.ln());
        }
        // ρ_{l+1} = 1/ρ_l + (2l + 3)/z.
        rho = 1.0 / rho + (2 * l + 3) as f64 / z;
    }
    (log, next)
}

impl RobinSphereOffCentre {
    /// Most terms kept (a source within 10⁻⁴ R of the surface would need more).
    const MAX_TERMS: usize = 4000;

    fn new(medium: DiffusionMedium, radius: f64, r0: f64) -> Result<Self, OpticsError> {
        let radius = in_range("radius", radius, "(0, inf)", |r| r > 0.0)?;
        let r0 = in_range("r0", r0, "[0, R)", |r| r >= 0.0 && r < radius)?;
        let sigma = medium.require_absorption()?;
        let b = medium.extrapolation_distance();
        let z = sigma * radius;
        // Enough terms that (r₀/R)^l is below 10⁻¹⁸.
        let terms = if r0 > 0.0 {
            ((-41.5 / (r0 / radius).ln()).ceil() as usize + 8).min(Self::MAX_TERMS)
        } else {
            1
        };
        let (log_i_r, i_next) = log_bessel_i(terms, z);
        let (log_k_r, k_next) = log_bessel_k(terms, z);
        let (log_i_0, _) = log_bessel_i(terms, (sigma * r0).max(1e-300));
        let mut log_weight = Vec::with_capacity(terms);
        let mut robin = Vec::with_capacity(terms);
        for l in 0..terms {
            // i_l′/i_l = i_{l+1}/i_l + l/z, k_l′/k_l = −k_{l+1}/k_l + l/z.
            let li = l as f64;
            let di = i_next[l] + li / z;
            let dk = -k_next[l] + li / z;
            robin.push((1.0 + b * sigma * dk) / (1.0 + b * sigma * di));
            log_weight.push(log_i_0[l] + log_k_r[l] - log_i_r[l]);
        }
        Ok(Self {
            medium,
            radius,
            r0,
            log_weight,
            robin,
        })
    }

    /// Fluence at distance `r` ≤ R from the centre and angle γ from the source's direction
    /// (`cos_gamma` = cos γ); the point must not be the source itself.
    pub fn fluence(&self, r: f64, cos_gamma: f64) -> Result<f64, OpticsError> {
        let r = in_range("r", r, "[0, R]", |r| (0.0..=self.radius).contains(&r))?;
        let cos_gamma = in_range("cos_gamma", cos_gamma, "[-1, 1]", |c| c.abs() <= 1.0)?;
        let sigma = self.medium.sigma_tr();
        let distance = (r * r + self.r0 * self.r0 - 2.0 * r * self.r0 * cos_gamma)
            .max(0.0)
            .sqrt();
        if distance == 0.0 {
            return Err(OpticsError::OutOfRange {
                name: "r",
                range: "away from the source",
                value: r,
            });
        }
        let free = (-sigma * distance).exp() / distance;
        let n = self.log_weight.len();
        let (log_i, _) = log_bessel_i(n, (sigma * r).max(1e-300));
        let decay = sigma * (r + self.r0 - 2.0 * self.radius);
        // Σ c_l i_l(σr) P_l(cos γ), Legendre by recurrence.
        let (mut p_prev, mut p) = (1.0, 1.0);
        let mut sum = 0.0;
        for l in 0..n {
            if l == 1 {
                p = cos_gamma;
            } else if l > 1 {
                let next =
                    ((2 * l - 1) as f64 * cos_gamma * p - (l - 1) as f64 * p_prev) / l as f64;
                p_prev = p;
                p = next;
            }
            let magnitude = (self.log_weight[l] + log_i[l] + decay).exp();
            sum -= (2.0 * sigma / PI) * (2 * l + 1) as f64 * magnitude * self.robin[l] * p;
        }
        Ok((free + sum) / (4.0 * PI * self.medium.d()))
    }

    /// Fraction of the source's power that leaves through the surface, ∮ φ(R)/(2A) dA:
    /// only the l = 0 terms survive the surface integral.
    pub fn escaped_fraction(&self) -> f64 {
        let sigma = self.medium.sigma_tr();
        let z = sigma * self.radius;
        let (log_i_r, _) = log_bessel_i(0, z);
        let (log_k_r, _) = log_bessel_k(0, z);
        let (log_i_0, _) = log_bessel_i(0, (sigma * self.r0).max(1e-300));
        let shift = sigma * (self.r0 - self.radius);
        // l = 0 of the free field at r = R > r₀: (2σ/π) i_0(σr₀) k_0(σR).
        let free = (2.0 * sigma / PI) * (log_i_0[0] + log_k_r[0] + shift).exp();
        let regular =
            -(2.0 * sigma / PI) * (self.log_weight[0] + log_i_r[0] + shift).exp() * self.robin[0];
        let phi0 = (free + regular) / (4.0 * PI * self.medium.d());
        4.0 * PI * self.radius * self.radius * phi0 / (2.0 * self.medium.boundary_factor())
    }
}

/// A disc (2D) of radius R with a unit line source at its centre and the Robin condition at
/// r = R (Mertens T8): φ(r) = K₀(σr)/(2πD) + C I₀(σr), C from φ + 2AD φ′ = 0 at R.
/// Valid for any r > 0, also beyond R (the analytic continuation a cut-cell unknown whose
/// centre lies outside the disc represents).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobinDisc {
    medium: DiffusionMedium,
    radius: f64,
    c: f64,
}

impl RobinDisc {
    fn new(medium: DiffusionMedium, radius: f64) -> Result<Self, OpticsError> {
        let radius = in_range("radius", radius, "(0, inf)", |r| r > 0.0)?;
        let sigma = medium.require_absorption()?;
        let d = medium.d();
        let zb = medium.extrapolation_distance();
        let x = sigma * radius;
        let source = 1.0 / (2.0 * PI * d);
        let c = -source * (bessel_k0(x) - zb * sigma * bessel_k1(x))
            / (bessel_i0(x) + zb * sigma * bessel_i1(x));
        Ok(Self { medium, radius, c })
    }

    /// Fluence φ(r) for r > 0 (1/length per unit source strength per length).
    pub fn fluence(&self, r: f64) -> Result<f64, OpticsError> {
        let r = in_range("r", r, "(0, inf)", |r| r > 0.0)?;
        let x = self.medium.sigma_tr() * r;
        Ok(bessel_k0(x) / (2.0 * PI * self.medium.d()) + self.c * bessel_i0(x))
    }

    /// Fraction of the source's power that leaves through the rim, 2πR φ(R)/(2A).
    pub fn escaped_fraction(&self) -> f64 {
        let phi = self.fluence(self.radius).unwrap_or(0.0);
        2.0 * PI * self.radius * phi / (2.0 * self.medium.a)
    }
}

/// Modified Bessel function I₀ (Abramowitz & Stegun 9.8.1–9.8.2, |ε| < 2e-7 relative).
fn bessel_i0(x: f64) -> f64 {
    let ax = x.abs();
    if ax < 3.75 {
        let t = (x / 3.75).powi(2);
        1.0 + t
            * (3.5156229
                + t * (3.0899424
                    + t * (1.2067492 + t * (0.2659732 + t * (0.0360768 + t * 0.0045813)))))
    } else {
        let t = 3.75 / ax;
        (ax.exp() / ax.sqrt())
            * (0.39894228
                + t * (0.01328592
                    + t * (0.00225319
                        + t * (-0.00157565
                            + t * (0.00916281
                                + t * (-0.02057706
                                    + t * (0.02635537 + t * (-0.01647633 + t * 0.00392377))))))))
    }
}

/// Modified Bessel function I₁ (A&S 9.8.3–9.8.4).
fn bessel_i1(x: f64) -> f64 {
    let ax = x.abs();
    let v = if ax < 3.75 {
        let t = (x / 3.75).powi(2);
        ax * (0.5
            + t * (0.87890594
                + t * (0.51498869
                    + t * (0.15084934 + t * (0.02658733 + t * (0.00301532 + t * 0.00032411))))))
    } else {
        let t = 3.75 / ax;
        (ax.exp() / ax.sqrt())
            * (0.39894228
                + t * (-0.03988024
                    + t * (-0.00362018
                        + t * (0.00163801
                            + t * (-0.01031555
                                + t * (0.02282967
                                    + t * (-0.02895312 + t * (0.01787654 - t * 0.00420059))))))))
    };
    if x < 0.0 { -v } else { v }
}

/// Modified Bessel function K₀ for x > 0 (A&S 9.8.5–9.8.6).
fn bessel_k0(x: f64) -> f64 {
    if x <= 2.0 {
        let t = x * x / 4.0;
        -(x / 2.0).ln() * bessel_i0(x)
            + (-0.57721566
                + t * (0.42278420
                    + t * (0.23069756
                        + t * (0.03488590 + t * (0.00262698 + t * (0.00010750 + t * 0.0000074))))))
    } else {
        let t = 2.0 / x;
        ((-x).exp() / x.sqrt())
            * (1.25331414
                + t * (-0.07832358
                    + t * (0.02189568
                        + t * (-0.01062446
                            + t * (0.00587872 + t * (-0.00251540 + t * 0.00053208))))))
    }
}

/// Modified Bessel function K₁ for x > 0 (A&S 9.8.7–9.8.8).
fn bessel_k1(x: f64) -> f64 {
    if x <= 2.0 {
        let t = x * x / 4.0;
        (x / 2.0).ln() * bessel_i1(x)
            + (1.0 / x)
                * (1.0
                    + t * (0.15443144
                        + t * (-0.67278579
                            + t * (-0.18156897
                                + t * (-0.01919402 + t * (-0.00110404 - t * 0.00004686))))))
    } else {
        let t = 2.0 / x;
        ((-x).exp() / x.sqrt())
            * (1.25331414
                + t * (0.23498619
                    + t * (-0.03655620
                        + t * (0.01504268
                            + t * (-0.00780353 + t * (0.00325614 - t * 0.00068245))))))
    }
}

/// The half-space z ≥ 0 with a unit plane source at depth z′ and the Robin condition at
/// z = 0 (Mertens T9):
/// φ(z) = [e^{−σ|z−z′|} − ((1 − 2ADσ)/(1 + 2ADσ)) e^{−σ(z+z′)}]/(2Dσ).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobinHalfSpace {
    medium: DiffusionMedium,
    source_depth: f64,
}

impl RobinHalfSpace {
    fn new(medium: DiffusionMedium, source_depth: f64) -> Result<Self, OpticsError> {
        medium.require_absorption()?;
        Ok(Self {
            medium,
            source_depth: non_negative("source_depth", source_depth)?,
        })
    }

    /// Fluence φ(z) at depth z ≥ 0 (1/length per unit source strength).
    pub fn fluence(&self, z: f64) -> Result<f64, OpticsError> {
        let z = non_negative("z", z)?;
        let (d, sigma, zb) = (
            self.medium.d(),
            self.medium.sigma_tr(),
            self.medium.extrapolation_distance(),
        );
        let reflection = (1.0 - zb * sigma) / (1.0 + zb * sigma);
        let zp = self.source_depth;
        Ok(
            ((-sigma * (z - zp).abs()).exp() - reflection * (-sigma * (z + zp)).exp())
                / (2.0 * d * sigma),
        )
    }

    /// Radiant exitance through the surface, φ(0)/(2A) = e^{−σz′}/(1 + 2ADσ).
    pub fn exitance(&self) -> f64 {
        self.fluence(0.0).unwrap_or(0.0) / (2.0 * self.medium.a)
    }
}

/// A slab 0 ≤ z ≤ d with the dipole's unit source at depth ℓ = z_r and φ = 0 on both
/// *extrapolated* boundaries, a distance z_b = 2AD outside each face (the approximation the
/// dipole and the Donner–Jensen multipole make, not the exact Robin condition), integrated
/// over the plane (Mertens T10):
/// R = α′ cosh(σz_b) sinh(σ(d + z_b − ℓ))/sinh(σ(d + 2z_b)),
/// T = α′ cosh(σz_b) sinh(σ(ℓ + z_b))/sinh(σ(d + 2z_b)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExtrapolatedSlab {
    medium: DiffusionMedium,
    thickness: f64,
}

impl ExtrapolatedSlab {
    fn new(medium: DiffusionMedium, thickness: f64) -> Result<Self, OpticsError> {
        medium.require_absorption()?;
        Ok(Self {
            medium,
            thickness: in_range("thickness", thickness, "(0, inf)", |d| d > 0.0)?,
        })
    }

    /// Total diffuse reflectance of the slab.
    pub fn total_reflectance(&self) -> f64 {
        let zb = self.medium.extrapolation_distance();
        self.total(self.thickness + zb - self.medium.z_r())
    }

    /// Total diffuse transmittance of the slab.
    pub fn total_transmittance(&self) -> f64 {
        let zb = self.medium.extrapolation_distance();
        self.total(self.medium.z_r() + zb)
    }

    /// α′ cosh(σz_b) sinh(σx)/sinh(σ(d + 2z_b)), written with exponentials of non-positive
    /// arguments only.
    fn total(&self, x: f64) -> f64 {
        let m = &self.medium;
        let sigma = m.sigma_tr();
        let zb = m.extrapolation_distance();
        let y = self.thickness + 2.0 * zb;
        // cosh(σz_b) sinh(σx)/sinh(σy) = ½(1 + e^{−2σz_b})(1 − e^{−2σx})/(1 − e^{−2σy}) · e^{σ(z_b + x − y)}
        let ratio = 0.5 * (1.0 + (-2.0 * sigma * zb).exp()) * (1.0 - (-2.0 * sigma * x).exp())
            / (1.0 - (-2.0 * sigma * y).exp())
            * (sigma * (zb + x - y)).exp();
        m.coefficients.albedo_reduced() * ratio
    }
}
