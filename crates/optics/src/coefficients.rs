//! Optical coefficients of a medium at one point, and the quantities diffusion theory
//! derives from them.

use crate::error::{OpticsError, anisotropy, in_range, non_negative};

/// Absorption σ_a, scattering σ_s (both in inverse scene units) and the mean cosine g of
/// the phase function, validated on construction.
///
/// All derived quantities follow from these three:
///
/// | quantity | formula | unit |
/// |---|---|---|
/// | extinction σ_t | σ_a + σ_s | 1/length |
/// | single-scattering albedo | σ_s / σ_t | – |
/// | reduced scattering σ_s′ | (1 − g) σ_s | 1/length |
/// | reduced extinction σ_t′ | σ_a + σ_s′ | 1/length |
/// | reduced albedo α′ | σ_s′ / σ_t′ | – |
/// | diffusion coefficient D | 1 / (3 σ_t′) | length |
/// | effective transport σ_tr | √(3 σ_a σ_t′) = √(σ_a / D) | 1/length |
///
/// A vacuum (σ_t = 0) is allowed: its albedo is defined as 0, its mean free paths and its
/// diffusion coefficient are `f64::INFINITY`. Nothing derived is ever NaN.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OpticalCoefficients {
    sigma_a: f64,
    sigma_s: f64,
    g: f64,
}

impl OpticalCoefficients {
    /// From absorption σ_a ≥ 0, scattering σ_s ≥ 0 (1/length) and anisotropy g ∈ (−1, 1).
    pub fn new(sigma_a: f64, sigma_s: f64, g: f64) -> Result<Self, OpticsError> {
        Ok(Self {
            sigma_a: non_negative("sigma_a", sigma_a)?,
            sigma_s: non_negative("sigma_s", sigma_s)?,
            g: anisotropy("g", g)?,
        })
    }

    /// From extinction σ_t ≥ 0 (1/length), single-scattering albedo ∈ [0, 1] and g ∈ (−1, 1).
    pub fn from_extinction_albedo(sigma_t: f64, albedo: f64, g: f64) -> Result<Self, OpticsError> {
        let sigma_t = non_negative("sigma_t", sigma_t)?;
        let albedo = in_range("albedo", albedo, "[0, 1]", |a| (0.0..=1.0).contains(&a))?;
        Self::new((1.0 - albedo) * sigma_t, albedo * sigma_t, g)
    }

    /// From absorption σ_a and *reduced* scattering σ_s′ = (1 − g) σ_s, the form in which
    /// measured materials are published (Jensen et al. 2001), and the anisotropy g ∈ (−1, 1)
    /// that unfolds σ_s = σ_s′ / (1 − g). Pass g = 0 when only σ_s′ is known: diffusion
    /// results depend on σ_s′ alone.
    pub fn from_reduced(sigma_a: f64, sigma_s_reduced: f64, g: f64) -> Result<Self, OpticsError> {
        let sigma_s_reduced = non_negative("sigma_s_reduced", sigma_s_reduced)?;
        let g = anisotropy("g", g)?;
        Self::new(sigma_a, sigma_s_reduced / (1.0 - g), g)
    }

    /// Absorption coefficient σ_a (1/length).
    pub fn sigma_a(&self) -> f64 {
        self.sigma_a
    }

    /// Scattering coefficient σ_s (1/length).
    pub fn sigma_s(&self) -> f64 {
        self.sigma_s
    }

    /// Mean cosine g of the phase function.
    pub fn g(&self) -> f64 {
        self.g
    }

    /// Extinction coefficient σ_t = σ_a + σ_s (1/length).
    pub fn sigma_t(&self) -> f64 {
        self.sigma_a + self.sigma_s
    }

    /// Single-scattering albedo σ_s / σ_t (0 for a vacuum).
    pub fn albedo(&self) -> f64 {
        ratio_or_zero(self.sigma_s, self.sigma_t())
    }

    /// Reduced scattering coefficient σ_s′ = (1 − g) σ_s (1/length).
    pub fn sigma_s_reduced(&self) -> f64 {
        (1.0 - self.g) * self.sigma_s
    }

    /// Reduced extinction coefficient σ_t′ = σ_a + σ_s′ (1/length).
    pub fn sigma_t_reduced(&self) -> f64 {
        self.sigma_a + self.sigma_s_reduced()
    }

    /// Reduced albedo α′ = σ_s′ / σ_t′ (0 for a vacuum).
    pub fn albedo_reduced(&self) -> f64 {
        ratio_or_zero(self.sigma_s_reduced(), self.sigma_t_reduced())
    }

    /// Diffusion coefficient D = 1 / (3 σ_t′) (length); infinite for a vacuum.
    pub fn diffusion_coefficient(&self) -> f64 {
        1.0 / (3.0 * self.sigma_t_reduced())
    }

    /// Effective transport coefficient σ_tr = √(3 σ_a σ_t′) (1/length), the inverse
    /// diffusion length; called σ_e in Mertens' thesis.
    pub fn sigma_tr(&self) -> f64 {
        (3.0 * self.sigma_a * self.sigma_t_reduced()).sqrt()
    }

    /// Mean free path 1 / σ_t (length); infinite for a vacuum.
    pub fn mean_free_path(&self) -> f64 {
        1.0 / self.sigma_t()
    }

    /// Transport mean free path ℓ′ = 1 / σ_t′ (length): the depth at which the dipole
    /// places its real source. Infinite for a vacuum.
    pub fn transport_mean_free_path(&self) -> f64 {
        1.0 / self.sigma_t_reduced()
    }

    /// Diffusion length 1 / σ_tr (length); infinite without absorption.
    pub fn diffusion_length(&self) -> f64 {
        1.0 / self.sigma_tr()
    }

    /// The same medium with every coefficient multiplied by `factor` > 0: converts between
    /// length units (coefficients in mm⁻¹ with `factor = 10` become cm⁻¹).
    pub fn scaled(&self, factor: f64) -> Result<Self, OpticsError> {
        let factor = in_range("factor", factor, "(0, inf)", |f| f > 0.0)?;
        Self::new(self.sigma_a * factor, self.sigma_s * factor, self.g)
    }
}

fn ratio_or_zero(num: f64, den: f64) -> f64 {
    if den > 0.0 { num / den } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constructors_agree() {
        let a = OpticalCoefficients::new(0.1, 0.9, 0.5).unwrap();
        let b = OpticalCoefficients::from_extinction_albedo(1.0, 0.9, 0.5).unwrap();
        let c = OpticalCoefficients::from_reduced(0.1, 0.45, 0.5).unwrap();
        for other in [b, c] {
            assert!((a.sigma_a() - other.sigma_a()).abs() < 1e-15);
            assert!((a.sigma_s() - other.sigma_s()).abs() < 1e-15);
        }
        assert!((a.sigma_t_reduced() - 0.55).abs() < 1e-15);
        assert!((a.albedo_reduced() - 0.45 / 0.55).abs() < 1e-15);
        assert!((a.diffusion_coefficient() - 1.0 / 1.65).abs() < 1e-15);
        assert!((a.sigma_tr() - (3.0f64 * 0.1 * 0.55).sqrt()).abs() < 1e-15);
    }

    #[test]
    fn bad_input_is_refused_with_the_parameter_named() {
        assert_eq!(
            OpticalCoefficients::new(-1.0, 1.0, 0.0),
            Err(OpticsError::Negative {
                name: "sigma_a",
                value: -1.0
            })
        );
        assert!(matches!(
            OpticalCoefficients::new(1.0, f64::NAN, 0.0),
            Err(OpticsError::NotFinite {
                name: "sigma_s",
                ..
            })
        ));
        assert!(matches!(
            OpticalCoefficients::new(1.0, f64::INFINITY, 0.0),
            Err(OpticsError::NotFinite {
                name: "sigma_s",
                ..
            })
        ));
        assert!(matches!(
            OpticalCoefficients::new(1.0, 1.0, 1.0),
            Err(OpticsError::OutOfRange { name: "g", .. })
        ));
        assert!(matches!(
            OpticalCoefficients::from_extinction_albedo(1.0, 1.5, 0.0),
            Err(OpticsError::OutOfRange { name: "albedo", .. })
        ));
        assert!(matches!(
            OpticalCoefficients::from_reduced(0.1, -2.0, 0.0),
            Err(OpticsError::Negative {
                name: "sigma_s_reduced",
                ..
            })
        ));
    }

    #[test]
    fn vacuum_derives_no_nan() {
        let v = OpticalCoefficients::new(0.0, 0.0, 0.0).unwrap();
        assert_eq!(v.albedo(), 0.0);
        assert_eq!(v.albedo_reduced(), 0.0);
        assert_eq!(v.mean_free_path(), f64::INFINITY);
        assert_eq!(v.diffusion_coefficient(), f64::INFINITY);
        assert_eq!(v.sigma_tr(), 0.0);
        assert_eq!(v.diffusion_length(), f64::INFINITY);
    }
}
