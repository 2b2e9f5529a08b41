//! Fresnel reflection at a smooth dielectric boundary, and the diffuse (cosine-weighted)
//! averages that the diffusion boundary condition needs.
//!
//! η is always a **relative** index, n_transmitted / n_incident. For a medium of index η in
//! air, light arriving from outside sees η, light leaving from inside sees 1/η.
//!
//! The diffusion (Robin, "extrapolated boundary") condition φ + 2AD ∂φ/∂n = 0 uses
//! A = (1 + F_dr) / (1 − F_dr), where F_dr is the medium's *internal* diffuse reflectance
//! F_dr(η) = 2 ∫₀¹ F_r(μ; 1/η) μ dμ, total internal reflection included. Mertens' thesis
//! (L617) prints this integral without the 1/π that makes F_dr ≤ 1; the factor 2 above is
//! the corrected form (docs/reference-cases.md, Mertens).

use crate::error::{OpticsError, in_range, refractive_index};
use crate::integrate::adaptive;

/// Which diffuse Fresnel reflectance to use in A.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DiffuseFresnel {
    /// The exact cosine-weighted integral of the Fresnel equations.
    Exact,
    /// Groenhuis et al.'s fit F_dr ≈ −1.44/η² + 0.71/η + 0.668 + 0.0636η, the form used by
    /// Jensen et al. 2001 and by Mertens; within 0.001 of the exact value for
    /// 1.3 ≤ η ≤ 1.5. Defined for η ≥ 1 only.
    #[default]
    Groenhuis,
    /// Haskell et al. 1994's effective reflection coefficient
    /// R_eff = (R_φ + R_j)/(2 − R_φ + R_j), with R_φ = 2∫₀¹ F_r μ dμ (= F_dr, exact) and
    /// R_j = 3∫₀¹ F_r μ² dμ, both for light inside: the value that matches *both* P1 partial
    /// currents at the surface instead of the cosine-weighted one alone. A = 2.341 at
    /// η = 1.3 (Groenhuis: 2.600). Still a P1 condition: its extrapolation length 2AD is
    /// 5–6% longer than transport's at η = 1.3–1.5 and 6% shorter at η = 1 (see
    /// [`DiffuseFresnel::Milne`]). `dom` uses its R_eff as the reflectance of its diffuse
    /// Robin wall, which is 0 for an index-matched boundary.
    PartialCurrent,
    /// The transport-exact extrapolation length of the Milne problem behind the boundary,
    /// A = 3z_b(η)/2 ([`crate::milne`]): the A whose Robin condition gives diffusion the
    /// interior of transport (A = 1.0657 at η = 1, 2.2119 at 1.3, 2.7895 at 1.4, 3.4457 at
    /// 1.5). lucent's diffusion solvers use it: Monte Carlo through a Fresnel interface at
    /// η = 1.3–1.5 stays within 1.6% of it 3 transport mean free paths inside a marble
    /// sphere, where the partial-current A is 3.2% off (docs/validation.md).
    Milne,
}

/// A smooth boundary with relative refractive index η = n_inside / n_outside.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dielectric {
    eta: f64,
}

impl Dielectric {
    /// A boundary with relative index η > 0 (η = 1 is index-matched: no reflection).
    pub fn new(eta: f64) -> Result<Self, OpticsError> {
        Ok(Self {
            eta: refractive_index(eta)?,
        })
    }

    /// The relative index η.
    pub fn eta(&self) -> f64 {
        self.eta
    }

    /// Unpolarised Fresnel reflectance F_r = (r_∥² + r_⊥²)/2 for light arriving from outside
    /// with cos θ_i = `cos_theta_i` > 0, or from inside when `cos_theta_i` < 0 (the index is
    /// then inverted). Returns 1 under total internal reflection.
    pub fn reflectance(&self, cos_theta_i: f64) -> f64 {
        fresnel_reflectance(cos_theta_i, self.eta)
    }

    /// F_t = 1 − F_r.
    pub fn transmittance(&self, cos_theta_i: f64) -> f64 {
        1.0 - self.reflectance(cos_theta_i)
    }

    /// The cosine-weighted hemispherical transmittance 2 ∫₀¹ F_t(μ; η) μ dμ for diffuse light
    /// arriving from outside (0.9389 for η = 1.3, 0.9082 for η = 1.5).
    pub fn hemispherical_transmittance(&self) -> f64 {
        1.0 - cosine_weighted_reflectance(self.eta)
    }

    /// The internal diffuse reflectance F_dr: the fraction of diffuse light inside that the
    /// boundary reflects back in, by the chosen model (for
    /// [`DiffuseFresnel::PartialCurrent`], the effective coefficient R_eff that plays its
    /// role in A).
    pub fn diffuse_reflectance(&self, model: DiffuseFresnel) -> Result<f64, OpticsError> {
        match model {
            DiffuseFresnel::Exact => Ok(cosine_weighted_reflectance(1.0 / self.eta)),
            DiffuseFresnel::Groenhuis => {
                let eta = in_range("eta", self.eta, "[1, inf) for the Groenhuis fit", |e| {
                    e >= 1.0
                })?;
                Ok(-1.44 / (eta * eta) + 0.71 / eta + 0.668 + 0.0636 * eta)
            }
            DiffuseFresnel::PartialCurrent => {
                let r_phi = cosine_weighted_reflectance(1.0 / self.eta);
                let r_j = cosine_squared_weighted_reflectance(1.0 / self.eta);
                Ok((r_phi + r_j) / (2.0 - r_phi + r_j))
            }
            DiffuseFresnel::Milne => {
                let a = 1.5 * crate::milne::extrapolation_length(self.eta)?;
                Ok((a - 1.0) / (a + 1.0))
            }
        }
    }

    /// The boundary factor A = (1 + F_dr)/(1 − F_dr) of the Robin condition
    /// φ + 2AD ∂φ/∂n = 0 (the extrapolation distance is 2AD; A = 1 when index-matched for
    /// the P1 models, 1.0657 for [`DiffuseFresnel::Milne`]).
    pub fn boundary_factor(&self, model: DiffuseFresnel) -> Result<f64, OpticsError> {
        if model == DiffuseFresnel::Milne {
            return Ok(1.5 * crate::milne::extrapolation_length(self.eta)?);
        }
        let f_dr = self.diffuse_reflectance(model)?;
        Ok((1.0 + f_dr) / (1.0 - f_dr))
    }
}

fn fresnel_reflectance(cos_theta_i: f64, eta: f64) -> f64 {
    let (cos_i, eta) = if cos_theta_i < 0.0 {
        (-cos_theta_i, 1.0 / eta)
    } else {
        (cos_theta_i, eta)
    };
    let cos_i = cos_i.min(1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let r_parallel = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perpendicular = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (r_parallel * r_parallel + r_perpendicular * r_perpendicular)
}

/// 2 ∫₀¹ F_r(μ; η) μ dμ, with the total-internal-reflection range (F_r = 1 for
/// μ < μ_c = √(1 − η²) when η < 1) integrated in closed form so that the adaptive rule never
/// straddles the kink at the critical angle.
fn cosine_weighted_reflectance(eta: f64) -> f64 {
    let mu_c = if eta < 1.0 {
        (1.0 - eta * eta).sqrt()
    } else {
        0.0
    };
    mu_c * mu_c
        + adaptive(
            |mu| 2.0 * fresnel_reflectance(mu, eta) * mu,
            mu_c,
            1.0,
            1e-14,
            0.0,
        )
}

/// 3 ∫₀¹ F_r(μ; η) μ² dμ, the current-weighted reflectance of Haskell et al. 1994, with the
/// total-internal-reflection range in closed form as in [`cosine_weighted_reflectance`].
fn cosine_squared_weighted_reflectance(eta: f64) -> f64 {
    let mu_c = if eta < 1.0 {
        (1.0 - eta * eta).sqrt()
    } else {
        0.0
    };
    mu_c * mu_c * mu_c
        + adaptive(
            |mu| 3.0 * fresnel_reflectance(mu, eta) * mu * mu,
            mu_c,
            1.0,
            1e-14,
            0.0,
        )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_incidence_and_grazing_limits() {
        let d = Dielectric::new(1.5).unwrap();
        // ((η − 1)/(η + 1))² = 0.04 at normal incidence, 1 at grazing incidence.
        assert!((d.reflectance(1.0) - 0.04).abs() < 1e-15);
        assert!((d.reflectance(0.0) - 1.0).abs() < 1e-12);
        // From inside beyond the critical angle (sin θ > 1/1.5): total internal reflection.
        assert_eq!(d.reflectance(-0.5), 1.0);
        // Index-matched boundaries do not reflect.
        assert!(Dielectric::new(1.0).unwrap().reflectance(0.3).abs() < 1e-16);
    }

    #[test]
    fn partial_current_boundary_factor_matches_haskell() {
        // Haskell et al. 1994 (JOSA A 11, 2727), Table 1: R_eff = 0.493 at n = 1.4; and
        // independent midpoint sums (4·10⁵ points) give A = 2.340532 at 1.3, 3.627933 at 1.5.
        let r = |eta: f64| {
            Dielectric::new(eta)
                .unwrap()
                .diffuse_reflectance(DiffuseFresnel::PartialCurrent)
                .unwrap()
        };
        let a = |eta: f64| {
            Dielectric::new(eta)
                .unwrap()
                .boundary_factor(DiffuseFresnel::PartialCurrent)
                .unwrap()
        };
        assert!((r(1.4) - 0.493).abs() < 0.5e-3);
        assert!((a(1.3) - 2.340532).abs() < 2e-6);
        assert!((a(1.5) - 3.627933).abs() < 2e-6);
        assert!((a(1.0) - 1.0).abs() < 1e-12, "index-matched: A = 1");
        // The boundary is always less reflective for the current than Groenhuis' F_dr says.
        let b = Dielectric::new(1.3).unwrap();
        assert!(a(1.3) < b.boundary_factor(DiffuseFresnel::Groenhuis).unwrap());
    }

    #[test]
    fn bad_index_is_refused() {
        assert!(Dielectric::new(0.0).is_err());
        assert!(Dielectric::new(f64::NAN).is_err());
        assert!(
            Dielectric::new(0.8)
                .unwrap()
                .diffuse_reflectance(DiffuseFresnel::Groenhuis)
                .is_err()
        );
        assert!(
            Dielectric::new(0.8)
                .unwrap()
                .diffuse_reflectance(DiffuseFresnel::Exact)
                .is_ok()
        );
    }
}
