//! What a solver returns: the fluence, optionally an angular representation, and a report.

use glam::DVec3;
use lucent_grid::Grid;
use lucent_optics::{Phase, PhaseFunction};

use crate::problem::Light;
use crate::solver::SolveReport;

/// Uncollided light from point-like lights (directional, point, spot), kept per light so
/// that in-scattering can weight it by the phase function: the exact single-scattering
/// source. Made by the `direct` solver; later solvers reuse it for their source terms.
#[derive(Debug, Clone, PartialEq)]
pub struct LightTransmittance {
    /// The phase function of the medium.
    pub phase: Phase,
    /// The lights, in the order of `transmittance`.
    pub lights: Vec<Light>,
    /// Transmittance e^{−τ} from each light to every cell centre: `[light][channel]`, one
    /// channel when the extinction is grey.
    pub transmittance: Vec<Vec<Grid>>,
    /// How far away distant lights are placed for ray marching (beyond the domain).
    pub far: f64,
    /// The smallest distance used in a point light's 1/r².
    pub min_distance: f64,
    /// The rest of the fluence, which in-scatters isotropically (the uncollided sky for
    /// `direct`, the scattered fluence for a solver that adds multiple scattering), per
    /// channel.
    pub isotropic_fluence: Vec<Grid>,
    /// Where rays bend (`direct-refractive`): per light, the irradiance and direction the
    /// light's curved ray arrives with at every cell centre, in place of the straight
    /// line's 1/r² and direction. Empty for straight rays.
    pub arrivals: Vec<CurvedArrival>,
}

/// How one light's curved rays arrive at the cell centres, relative to the straight line
/// from the light: where rays are straight the focusing is 1 and both bends are zero, and
/// the in-scattered radiance is `direct`'s. Kept as corrections to the straight line so
/// that interpolating between cell centres keeps the straight part exact (a point light's
/// 1/r² is far from trilinear near it).
#[derive(Debug, Clone, PartialEq)]
pub struct CurvedArrival {
    /// The irradiance the ray tube delivers over the straight line's geometric spreading
    /// ([`Light::spreading`]): 1 for straight rays, above 1 where rays converge. Zero
    /// where no ray arrives.
    pub focusing: Grid,
    /// The direction of travel on arrival minus the straight line's, per component.
    pub bend: [Grid; 3],
    /// The launch direction minus the straight line's (point and spot lights: a spot's
    /// emission is taken toward it), per component; zero for directional lights.
    pub launch_bend: [Grid; 3],
}

impl LightTransmittance {
    /// The uncollided fluence φ_u(x) = Σ_l E_l(x) T_l(x) in `channel`.
    pub fn fluence(&self, channel: usize, x: DVec3) -> f64 {
        self.sum(channel, x, |_| 1.0)
    }

    /// In-scattered radiance toward `omega` (direction of travel after scattering), per
    /// unit σ_s: Σ_l p(ω_l·ω) E_l(x) T_l(x) + φ_iso(x)/(4π).
    pub fn inscattered(&self, channel: usize, x: DVec3, omega: DVec3) -> f64 {
        let iso = &self.isotropic_fluence[channel.min(self.isotropic_fluence.len() - 1)];
        self.sum(channel, x, |w| self.phase.eval(w, omega))
            + f64::from(iso.sample_trilinear(x)) / (4.0 * std::f64::consts::PI)
    }

    /// How light `l` arrives at `x`: its direction of travel and its irradiance per unit
    /// of its spectrum before attenuation (the straight line's, or the curved ray's where
    /// `arrivals` has it); `None` where it does not arrive (behind a spot's cone).
    pub fn arrival(&self, l: usize, x: DVec3) -> Option<(DVec3, f64)> {
        let light = &self.lights[l];
        light
            .arrival(x, self.far, self.min_distance)
            .map(|(w, irradiance, _)| match self.arrivals.get(l) {
                Some(curved) => {
                    let sample = |g: &[Grid; 3]| {
                        DVec3::from_array(g.each_ref().map(|g| f64::from(g.sample_trilinear(x))))
                    };
                    let emission = light
                        .emission_toward((w + sample(&curved.launch_bend)).normalize_or_zero());
                    let focusing = f64::from(curved.focusing.sample_trilinear(x));
                    (
                        (w + sample(&curved.bend)).normalize_or_zero(),
                        emission * light.spreading(x, self.min_distance) * focusing,
                    )
                }
                None => (w, irradiance),
            })
    }

    fn sum(&self, channel: usize, x: DVec3, weight: impl Fn(DVec3) -> f64) -> f64 {
        let mut total = 0.0;
        for (l, (light, grids)) in self.lights.iter().zip(&self.transmittance).enumerate() {
            if let Some((w, irradiance)) = self.arrival(l, x) {
                let t = grids[channel.min(grids.len() - 1)].sample_trilinear(x);
                total += weight(w) * light.spectrum().channel(channel) * irradiance * f64::from(t);
            }
        }
        total
    }
}

/// In-scattered radiance stored at a set of directions per cell (discrete ordinates), plus
/// the exact single scattering of point-like lights.
#[derive(Debug, Clone, PartialEq)]
pub struct OrdinateRadiance {
    /// The storage directions ω_m (unit).
    pub directions: Vec<glam::DVec3>,
    /// Concentration κ of the interpolation kernel e^{κ(ω·ω_m − 1)} between them.
    pub kernel: f64,
    /// Per channel: Σ_n w_n p̄(ω_n → ω_m) L_n per cell and storage direction (cell-major,
    /// direction fastest), the in-scattered radiance per unit σ_s of the light the
    /// ordinates carry (W/length²/sr).
    pub inscattered: Vec<Vec<f32>>,
    /// The grid the cells belong to.
    pub geometry: lucent_grid::GridGeometry,
    /// The uncollided light of point-like lights, in-scattered with the exact phase function.
    pub lights: Option<LightTransmittance>,
}

impl OrdinateRadiance {
    /// In-scattered radiance toward `omega` per unit σ_s: the lights' exact part plus the
    /// stored directions, interpolated trilinearly in space and with the normalised kernel
    /// in angle.
    pub fn inscattered(&self, channel: usize, x: DVec3, omega: DVec3) -> f64 {
        let lights = self
            .lights
            .as_ref()
            .map_or(0.0, |l| l.sum(channel, x, |w| l.phase.eval(w, omega)));
        let m = self.directions.len();
        let data = &self.inscattered[channel.min(self.inscattered.len() - 1)];
        let weights: Vec<f64> = self
            .directions
            .iter()
            .map(|d| (self.kernel * (d.dot(omega) - 1.0)).exp())
            .collect();
        let norm: f64 = weights.iter().sum();
        let dims = self.geometry.dims();
        let v = self.geometry.world_to_voxel(x);
        let mut total = 0.0;
        for corner in 0..8 {
            let mut weight = 1.0;
            let mut at = [0usize; 3];
            for a in 0..3 {
                let max = dims[a] as f64 - 1.0;
                let p = v[a].clamp(0.0, max);
                let lo = p.floor().min((max - 1.0).max(0.0));
                let t = p - lo;
                let bit = corner >> a & 1;
                weight *= if bit == 1 { t } else { 1.0 - t };
                at[a] = (lo as usize + bit).min(dims[a] - 1);
            }
            if weight == 0.0 {
                continue;
            }
            let cell = at[0] + dims[0] * (at[1] + dims[1] * at[2]);
            let row = &data[cell * m..(cell + 1) * m];
            let value: f64 = row
                .iter()
                .zip(&weights)
                .map(|(j, w)| f64::from(*j) * w)
                .sum();
            total += weight * value / norm;
        }
        lights + total
    }
}

/// An angular representation of the radiance field.
#[derive(Debug, Clone, PartialEq)]
pub enum Angular {
    /// Per-light transmittance of point-like lights.
    Lights(LightTransmittance),
    /// Discrete-ordinate in-scattered radiance (and the lights' exact part).
    Ordinates(OrdinateRadiance),
}

/// A solver's result.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// The fluence φ = ∫ L dω per channel (one grid for grey problems).
    pub fluence: Vec<Grid>,
    /// The part of the radiance that is kept with its directions, if any.
    pub angular: Option<Angular>,
    /// Per-cell standard error of the fluence, for stochastic solvers (Monte Carlo).
    pub standard_error: Option<Vec<Grid>>,
    /// What happened.
    pub report: SolveReport,
}

impl Solution {
    /// Whether this can be a solution of `problem`: grey or RGB fluence (a grey problem's
    /// solution may carry three channels, which the renderer follows), and every grid
    /// (fluence, standard errors, angular parts) on the problem's geometry. `Err` says what
    /// differs. (A renderer handed the solution of another problem would otherwise sample
    /// it as if it were this one's.)
    pub fn check_fits(&self, problem: &crate::Problem) -> Result<(), String> {
        let geometry = problem.geometry();
        if !matches!(self.fluence.len(), 1 | 3) {
            return Err(format!(
                "the solution has {} fluence channels (1 or 3)",
                self.fluence.len()
            ));
        }
        let mut grids: Vec<&Grid> = self.fluence.iter().collect();
        grids.extend(self.standard_error.iter().flatten());
        let lights = match &self.angular {
            Some(Angular::Lights(l)) => Some(l),
            Some(Angular::Ordinates(o)) => {
                if o.geometry != *geometry {
                    return Err("its ordinates lie on another grid".into());
                }
                o.lights.as_ref()
            }
            None => None,
        };
        if let Some(l) = lights {
            grids.extend(l.transmittance.iter().flatten());
            grids.extend(&l.isotropic_fluence);
        }
        match grids.iter().find(|g| g.geometry() != geometry) {
            Some(g) => Err(format!(
                "its grids are {:?} cells, the problem's {:?}",
                g.dims(),
                geometry.dims()
            )),
            None => Ok(()),
        }
    }

    /// The fluence grid of `channel`.
    pub fn fluence(&self, channel: usize) -> &Grid {
        &self.fluence[channel.min(self.fluence.len() - 1)]
    }

    /// In-scattered radiance ∫ p(ω′·ω) L(x, ω′) dω′ toward `omega` at `x`, per unit σ_s:
    /// from the angular representation where there is one, else φ/(4π) (isotropic).
    pub fn inscattered(&self, channel: usize, x: DVec3, omega: DVec3) -> f64 {
        match &self.angular {
            Some(Angular::Lights(lights)) => lights.inscattered(channel, x, omega),
            Some(Angular::Ordinates(ordinates)) => ordinates.inscattered(channel, x, omega),
            None => {
                f64::from(self.fluence(channel).sample_trilinear(x)) / (4.0 * std::f64::consts::PI)
            }
        }
    }
}
