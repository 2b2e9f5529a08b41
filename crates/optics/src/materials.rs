//! Measured optical properties of real materials.
//!
//! [`JENSEN_2001`] is the table of Jensen, Marschner, Levoy and Hanrahan, *A Practical Model
//! for Subsurface Light Transport* (SIGGRAPH 2001), as tabulated in pbrt's
//! `SubsurfaceParameterTable` (Jensen et al. 2001, Table 1).
//! Values are per channel (R, G, B) in **mm⁻¹**, measured with η = 1.3. The paper gives
//! reduced scattering only, so the coefficients built here use g = 0 unless a g is given:
//! diffusion depends on σ_s′ alone, but a transport solver needs the real g.
//!
//! Use it as test fixtures and as scene materials; Ketchup's green and blue channels
//! (reduced albedo 0.067 and 0.020) are built-in cases where diffusion must fail.

use crate::coefficients::OpticalCoefficients;
use crate::error::{OpticsError, in_range};

/// The length unit of the measured coefficients: millimetres (coefficients in mm⁻¹).
pub const LENGTH_UNIT: &str = "mm";

/// One measured material: reduced scattering and absorption per RGB channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredMaterial {
    /// Name as in the paper's table.
    pub name: &'static str,
    /// Reduced scattering σ_s′ (mm⁻¹), R, G, B.
    pub sigma_s_reduced: [f64; 3],
    /// Absorption σ_a (mm⁻¹), R, G, B.
    pub sigma_a: [f64; 3],
    /// Relative refractive index the measurement assumed.
    pub eta: f64,
}

impl MeasuredMaterial {
    /// Looks a material up by name, ignoring case (`"marble"`, `"Skin1"`).
    pub fn by_name(name: &str) -> Result<&'static MeasuredMaterial, OpticsError> {
        JENSEN_2001
            .iter()
            .find(|m| m.name.eq_ignore_ascii_case(name))
            .ok_or_else(|| OpticsError::UnknownMaterial(name.to_owned()))
    }

    /// Coefficients of one channel (0 = R, 1 = G, 2 = B) in mm⁻¹, with anisotropy g
    /// (σ_s = σ_s′/(1 − g)).
    pub fn channel(&self, channel: usize, g: f64) -> Result<OpticalCoefficients, OpticsError> {
        let c = in_range("channel", channel as f64, "{0, 1, 2}", |c| c < 3.0)? as usize;
        OpticalCoefficients::from_reduced(self.sigma_a[c], self.sigma_s_reduced[c], g)
    }

    /// All three channels in scene units of `mm_per_scene_unit` millimetres
    /// (1 for scenes in mm, 10 for cm, 1000 for m).
    pub fn rgb(
        &self,
        g: f64,
        mm_per_scene_unit: f64,
    ) -> Result<[OpticalCoefficients; 3], OpticsError> {
        let c = |i| self.channel(i, g)?.scaled(mm_per_scene_unit);
        Ok([c(0)?, c(1)?, c(2)?])
    }
}

const fn material(
    name: &'static str,
    sigma_s_reduced: [f64; 3],
    sigma_a: [f64; 3],
) -> MeasuredMaterial {
    MeasuredMaterial {
        name,
        sigma_s_reduced,
        sigma_a,
        eta: 1.3,
    }
}

/// Jensen et al. 2001, Figure 5: reduced scattering and absorption in mm⁻¹, η = 1.3.
pub const JENSEN_2001: [MeasuredMaterial; 12] = [
    material("Apple", [2.29, 2.39, 1.97], [0.0030, 0.0034, 0.046]),
    material("Chicken1", [0.15, 0.21, 0.38], [0.015, 0.077, 0.19]),
    material("Chicken2", [0.19, 0.25, 0.32], [0.018, 0.088, 0.20]),
    material("Cream", [7.38, 5.47, 3.15], [0.0002, 0.0028, 0.0163]),
    material("Ketchup", [0.18, 0.07, 0.03], [0.061, 0.97, 1.45]),
    material("Marble", [2.19, 2.62, 3.00], [0.0021, 0.0041, 0.0071]),
    material("Potato", [0.68, 0.70, 0.55], [0.0024, 0.0090, 0.12]),
    material("Skimmilk", [0.70, 1.22, 1.90], [0.0014, 0.0025, 0.0142]),
    material("Skin1", [0.74, 0.88, 1.01], [0.032, 0.17, 0.48]),
    material("Skin2", [1.09, 1.59, 1.79], [0.013, 0.070, 0.145]),
    material("Spectralon", [11.6, 20.4, 14.9], [0.0, 0.0, 0.0]),
    material("Wholemilk", [2.55, 3.21, 3.77], [0.0011, 0.0024, 0.014]),
];
