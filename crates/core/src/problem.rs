//! The problem every solver solves: a medium on a grid, lights, a boundary.

use glam::DVec3;
use lucent_grid::{Grid, GridGeometry};
use lucent_optics::Phase;

use crate::error::ProblemError;
use crate::spectrum::Spectrum;

/// A scalar field on the problem's grid: one constant or one grid.
#[derive(Debug, Clone, PartialEq)]
pub enum Field {
    /// The same value everywhere.
    Constant(f32),
    /// A value per cell.
    Grid(Grid),
}

impl Field {
    /// The value of cell `index`.
    #[inline]
    pub fn at(&self, index: usize) -> f32 {
        match self {
            Field::Constant(v) => *v,
            Field::Grid(g) => g.data()[index],
        }
    }

    /// The trilinearly interpolated value at a world point.
    #[inline]
    pub fn sample(&self, p: DVec3) -> f32 {
        match self {
            Field::Constant(v) => *v,
            Field::Grid(g) => g.sample_trilinear(p),
        }
    }
}

/// The participating medium: extinction, albedo and phase function per channel.
///
/// `sigma_t` and `albedo` hold one entry for a grey quantity or three for RGB; a quantity
/// with one entry serves every channel. σ_s = albedo·σ_t, σ_a = (1 − albedo)·σ_t.
#[derive(Debug, Clone, PartialEq)]
pub struct Medium {
    /// Extinction σ_t (1/length), per channel.
    pub sigma_t: Vec<Grid>,
    /// Single-scattering albedo in [0, 1], per channel.
    pub albedo: Vec<Field>,
    /// Phase function (the same in every channel). (The boundary's refractive index is
    /// the problem's [`Boundary::Robin`], not the medium's.)
    pub phase: Phase,
}

impl Medium {
    /// The extinction grid of `channel`.
    pub fn sigma_t(&self, channel: usize) -> &Grid {
        &self.sigma_t[channel.min(self.sigma_t.len() - 1)]
    }

    /// The albedo field of `channel`.
    pub fn albedo(&self, channel: usize) -> &Field {
        &self.albedo[channel.min(self.albedo.len() - 1)]
    }

    /// σ_s = albedo·σ_t at a world point (trilinear in both).
    pub fn sigma_s_at(&self, channel: usize, p: DVec3) -> f32 {
        self.albedo(channel).sample(p) * self.sigma_t(channel).sample_trilinear(p)
    }

    /// The medium with σ_t set to zero in the cells where `sdf` ≥ 0 (outside an embedded
    /// body): what light crosses on its way to the body without interacting.
    pub fn masked(&self, sdf: &Grid) -> Self {
        Self {
            sigma_t: self
                .sigma_t
                .iter()
                .map(|g| {
                    let mut g = g.clone();
                    for (v, d) in g.data_mut().iter_mut().zip(sdf.data()) {
                        if *d >= 0.0 {
                            *v = 0.0;
                        }
                    }
                    g
                })
                .collect(),
            ..self.clone()
        }
    }

    /// The same medium on `dims` cells over the same box: every grid resampled
    /// (`lucent_grid::resample::resample`: trilinear to finer grids, box-averaged to
    /// coarser ones), constants kept.
    pub fn resampled(&self, dims: [usize; 3]) -> Result<Self, lucent_grid::GridError> {
        let up = |g: &Grid| lucent_grid::resample::resample(g, dims);
        Ok(Self {
            sigma_t: self.sigma_t.iter().map(up).collect::<Result<_, _>>()?,
            albedo: self
                .albedo
                .iter()
                .map(|a| match a {
                    Field::Constant(v) => Ok(Field::Constant(*v)),
                    Field::Grid(g) => up(g).map(Field::Grid),
                })
                .collect::<Result<_, _>>()?,
            phase: self.phase,
        })
    }
}

/// A light source. Directions are directions of propagation; all radiometric values are
/// grey or RGB.
#[derive(Debug, Clone, PartialEq)]
pub enum Light {
    /// A distant light (the sun): parallel rays travelling along `direction`, delivering
    /// `irradiance` (W/m²) on a surface facing it.
    Directional {
        /// Unit direction of travel.
        direction: DVec3,
        /// Irradiance normal to the beam.
        irradiance: Spectrum,
    },
    /// An isotropic point light of radiant `intensity` (W/sr).
    Point {
        /// Position.
        position: DVec3,
        /// Radiant intensity.
        intensity: Spectrum,
    },
    /// A spot light: a point light restricted to a cone around `direction`, full intensity
    /// inside `inner_angle`, falling smoothly to zero at `outer_angle` (radians).
    Spot {
        /// Position.
        position: DVec3,
        /// Unit axis of the cone.
        direction: DVec3,
        /// Radiant intensity on the axis.
        intensity: Spectrum,
        /// Half-angle of full intensity.
        inner_angle: f64,
        /// Half-angle beyond which the light is dark.
        outer_angle: f64,
    },
    /// A uniform sky: `radiance` (W/m²/sr) arriving from every direction outside the domain.
    Sky {
        /// Radiance of the sky.
        radiance: Spectrum,
    },
    /// Volumetric emission: radiance `scale`·grid (W/m³/sr) emitted isotropically by every cell.
    Emission {
        /// Emission per cell (on the problem's geometry).
        grid: Grid,
        /// Multiplier (grey or RGB).
        scale: Spectrum,
    },
}

/// What kind a light is, for capability checks and messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum LightKind {
    /// [`Light::Directional`].
    Directional,
    /// [`Light::Point`].
    Point,
    /// [`Light::Spot`].
    Spot,
    /// [`Light::Sky`].
    Sky,
    /// [`Light::Emission`].
    Emission,
}

/// A point or direction as `(x, y, z)`, four significant digits.
pub(crate) struct Triple(pub glam::DVec3);

impl std::fmt::Display for Triple {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use lucent_optics::Significant as S;
        write!(f, "({}, {}, {})", S(self.0.x), S(self.0.y), S(self.0.z))
    }
}

impl std::fmt::Display for Light {
    /// In words with units (lengths in the scene's unit): `directional along (-0.3,
    /// -0.38, -0.8), irradiance (10, 9.3, 8.2) (power/area)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use lucent_optics::Significant as S;
        match self {
            Light::Directional {
                direction,
                irradiance,
            } => write!(
                f,
                "directional along {}, irradiance {irradiance} (power/area)",
                Triple(*direction)
            ),
            Light::Point {
                position,
                intensity,
            } => write!(
                f,
                "point at {}, intensity {intensity} (power/sr)",
                Triple(*position)
            ),
            Light::Spot {
                position,
                direction,
                intensity,
                inner_angle,
                outer_angle,
            } => write!(
                f,
                "spot at {} along {}, intensity {intensity} (power/sr), cone {}° to {}°",
                Triple(*position),
                Triple(*direction),
                S(inner_angle.to_degrees()),
                S(outer_angle.to_degrees())
            ),
            Light::Sky { radiance } => {
                write!(f, "uniform sky, radiance {radiance} (power/(area sr))")
            }
            Light::Emission { scale, .. } => write!(
                f,
                "volume emission, {scale} (power/(volume sr)) per unit of the volume's value"
            ),
        }
    }
}

impl Light {
    /// The light's kind.
    pub fn kind(&self) -> LightKind {
        match self {
            Light::Directional { .. } => LightKind::Directional,
            Light::Point { .. } => LightKind::Point,
            Light::Spot { .. } => LightKind::Spot,
            Light::Sky { .. } => LightKind::Sky,
            Light::Emission { .. } => LightKind::Emission,
        }
    }

    /// Lights that arrive at each point from one point or direction (directional, point,
    /// spot), whose uncollided light `direct` marches; not sky and emission.
    pub fn is_pointlike(&self) -> bool {
        matches!(
            self,
            Light::Directional { .. } | Light::Point { .. } | Light::Spot { .. }
        )
    }

    /// The light's spectrum (irradiance, intensity, radiance or emission scale).
    pub fn spectrum(&self) -> Spectrum {
        match self {
            Light::Directional { irradiance, .. } => *irradiance,
            Light::Point { intensity, .. } | Light::Spot { intensity, .. } => *intensity,
            Light::Sky { radiance } => *radiance,
            Light::Emission { scale, .. } => *scale,
        }
    }

    /// For lights that arrive at `x` from one direction: the unit direction of travel of
    /// that light at `x`, the unoccluded irradiance it delivers there (normal to the
    /// beam, per unit of the light's spectrum) and the point it comes from (or a point
    /// `far` away for distant lights). Distances to point and spot lights are taken as at
    /// least `min_distance`, which keeps the 1/r² of a light sitting on a cell centre finite.
    /// `None` for sky and emission.
    pub fn arrival(&self, x: DVec3, far: f64, min_distance: f64) -> Option<(DVec3, f64, DVec3)> {
        let floor = (min_distance * min_distance).max(1e-300);
        match *self {
            Light::Directional { direction, .. } => Some((direction, 1.0, x - direction * far)),
            Light::Point { position, .. } => {
                let d = x - position;
                let r2 = d.length_squared();
                let w = if r2 > 0.0 { d / r2.sqrt() } else { DVec3::Z };
                Some((w, 1.0 / r2.max(floor), position))
            }
            Light::Spot {
                position,
                direction,
                ..
            } => {
                let d = x - position;
                let r2 = d.length_squared();
                let w = if r2 > 0.0 { d / r2.sqrt() } else { direction };
                Some((w, self.emission_toward(w) / r2.max(floor), position))
            }
            Light::Sky { .. } | Light::Emission { .. } => None,
        }
    }

    /// The geometric spreading of a light's irradiance at `x`, per unit of its spectrum
    /// and emission: 1 for a directional light, 1/max(r², min_distance²) for point and spot
    /// lights (r from the light to `x`); 0 for the others. [`Light::arrival`]'s irradiance
    /// is this times [`Light::emission_toward`] its direction.
    pub fn spreading(&self, x: DVec3, min_distance: f64) -> f64 {
        let floor = (min_distance * min_distance).max(1e-300);
        match *self {
            Light::Directional { .. } => 1.0,
            Light::Point { position, .. } | Light::Spot { position, .. } => {
                1.0 / (x - position).length_squared().max(floor)
            }
            Light::Sky { .. } | Light::Emission { .. } => 0.0,
        }
    }

    /// The relative intensity a point or spot light emits toward the unit direction `w`
    /// (1 for a point light; for a spot, 1 inside the inner cone, 0 outside the outer one,
    /// a smoothstep in the cosine between). 1 for directional lights, 0 for the others.
    pub fn emission_toward(&self, w: DVec3) -> f64 {
        match *self {
            Light::Directional { .. } | Light::Point { .. } => 1.0,
            Light::Spot {
                direction,
                inner_angle,
                outer_angle,
                ..
            } => {
                let cos = w.dot(direction);
                let (ci, co) = (inner_angle.cos(), outer_angle.cos());
                if cos >= ci {
                    1.0
                } else if cos <= co {
                    0.0
                } else {
                    // Smoothstep between the outer and inner cone.
                    let t = (cos - co) / (ci - co);
                    t * t * (3.0 - 2.0 * t)
                }
            }
            Light::Sky { .. } | Light::Emission { .. } => 0.0,
        }
    }
}

/// The condition at the domain boundary. In scene files: `{ kind = "vacuum" }`,
/// `{ kind = "robin", eta = 1.3 }`, `{ kind = "dirichlet", value = 0.0 }`,
/// `{ kind = "neumann", flux = 0.0 }`.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Deserialize)]
#[serde(from = "BoundaryToml")]
pub enum Boundary {
    /// Nothing comes in; light leaves freely (index-matched).
    #[default]
    Vacuum,
    /// The diffusion Robin condition φ + 2AD ∂φ/∂n = 0 with A from the relative index η
    /// ([`Boundary::robin_factor`]). Transport solvers treat it as a smooth dielectric
    /// interface of index η.
    Robin {
        /// Relative refractive index.
        eta: f64,
    },
    /// A fixed fluence on the boundary.
    Dirichlet {
        /// The boundary fluence.
        value: f64,
    },
    /// A fixed normal flux through the boundary (0 = reflecting).
    Neumann {
        /// Outward normal flux.
        flux: f64,
    },
}

/// What a scene file writes: [`Boundary`] with `vacuum` as a table of no keys, so that a
/// stray key beside `kind = "vacuum"` is refused like any other unknown key (serde lets
/// extra keys through an internally tagged unit variant).
#[derive(serde::Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
enum BoundaryToml {
    Vacuum {},
    Robin { eta: f64 },
    Dirichlet { value: f64 },
    Neumann { flux: f64 },
}

impl From<BoundaryToml> for Boundary {
    fn from(b: BoundaryToml) -> Self {
        match b {
            BoundaryToml::Vacuum {} => Boundary::Vacuum,
            BoundaryToml::Robin { eta } => Boundary::Robin { eta },
            BoundaryToml::Dirichlet { value } => Boundary::Dirichlet { value },
            BoundaryToml::Neumann { flux } => Boundary::Neumann { flux },
        }
    }
}

impl std::fmt::Display for Boundary {
    /// In words, four significant digits.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use lucent_optics::Significant as S;
        match *self {
            Boundary::Vacuum => f.write_str("vacuum (index-matched: nothing comes back)"),
            Boundary::Robin { eta } => write!(f, "Robin, relative refractive index {}", S(eta)),
            Boundary::Dirichlet { value } => {
                write!(f, "Dirichlet, fluence {} on the boundary", S(value))
            }
            Boundary::Neumann { flux } => write!(f, "Neumann, outward flux {}", S(flux)),
        }
    }
}

/// What kind a boundary is, for capability checks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum BoundaryKind {
    /// [`Boundary::Vacuum`].
    Vacuum,
    /// [`Boundary::Robin`].
    Robin,
    /// [`Boundary::Dirichlet`].
    Dirichlet,
    /// [`Boundary::Neumann`].
    Neumann,
}

impl Boundary {
    /// The boundary's kind.
    pub fn kind(&self) -> BoundaryKind {
        match self {
            Boundary::Vacuum => BoundaryKind::Vacuum,
            Boundary::Robin { .. } => BoundaryKind::Robin,
            Boundary::Dirichlet { .. } => BoundaryKind::Dirichlet,
            Boundary::Neumann { .. } => BoundaryKind::Neumann,
        }
    }

    /// The boundary factor A of the diffusion solvers' Robin condition φ + 2AD ∂φ/∂n = 0
    /// for a [`Boundary::Robin`] of index η and for [`Boundary::Vacuum`] (η = 1): the
    /// transport-exact extrapolation length of the Milne problem, A = 3z_b(η)/2
    /// ([`lucent_optics::DiffuseFresnel::Milne`]; 1.0657 at η = 1, 2.2119 at 1.3, 2.7895
    /// at 1.4), which gives diffusion the interior that Monte Carlo through a Fresnel
    /// interface has (the P1 conditions' A, Marshak's 1 and Haskell's partial-current
    /// 2.341 at 1.3, misplace the extrapolated boundary by 5–6%). `None` for the other
    /// kinds.
    pub fn robin_factor(&self) -> Option<f64> {
        let eta = match *self {
            Boundary::Robin { eta } => eta,
            Boundary::Vacuum => 1.0,
            _ => return None,
        };
        lucent_optics::Dielectric::new(eta)
            .and_then(|d| d.boundary_factor(lucent_optics::DiffuseFresnel::Milne))
            .ok()
    }

    /// The fraction of the outgoing partial current that a [`Boundary::Robin`] wall of
    /// index η returns diffusely into the medium, Haskell et al.'s R_eff
    /// ([`lucent_optics::DiffuseFresnel::PartialCurrent`]; 0 at η = 1, 0.401 at 1.3), for
    /// transport solvers that model the interface as a diffuse reflector; 0 for a vacuum,
    /// 1 for a reflecting (zero-flux Neumann) box. `None` for the other kinds.
    pub fn diffuse_reflectance(&self) -> Option<f64> {
        match *self {
            Boundary::Vacuum => Some(0.0),
            Boundary::Neumann { flux: 0.0 } => Some(1.0),
            Boundary::Robin { eta } => lucent_optics::Dielectric::new(eta)
                .and_then(|d| d.diffuse_reflectance(lucent_optics::DiffuseFresnel::PartialCurrent))
                .ok(),
            _ => None,
        }
    }
}

/// A complete light-transport problem. Build it with [`Problem::new`], which validates it.
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    geometry: GridGeometry,
    medium: Medium,
    lights: Vec<Light>,
    boundary: Boundary,
    embedded: Option<Grid>,
    refractive_index: Option<crate::RefractiveIndex>,
}

impl Problem {
    /// Validates and assembles a problem: every grid on `geometry`, σ_t ≥ 0 and finite,
    /// albedo in [0, 1], one or three channels everywhere, finite unit light directions,
    /// valid spectra, an SDF on the same geometry.
    pub fn new(
        geometry: GridGeometry,
        medium: Medium,
        lights: Vec<Light>,
        boundary: Boundary,
        embedded: Option<Grid>,
    ) -> Result<Self, ProblemError> {
        let bad = |what: &str| Err(ProblemError(what.to_owned()));
        let on_grid = |g: &Grid| g.geometry() == &geometry;
        if medium.sigma_t.is_empty() || medium.albedo.is_empty() {
            return bad("the medium needs an extinction and an albedo");
        }
        for list in [medium.sigma_t.len(), medium.albedo.len()] {
            if list != 1 && list != 3 {
                return bad("medium quantities need one (grey) or three (RGB) channels");
            }
        }
        for g in &medium.sigma_t {
            if !on_grid(g) {
                return bad("an extinction grid is not on the problem's geometry");
            }
            if let Some(v) = g.data().iter().find(|v| !v.is_finite() || **v < 0.0) {
                return bad(&format!(
                    "extinction must be finite and non-negative, found {v}"
                ));
            }
        }
        for a in &medium.albedo {
            let in_unit = |v: &f32| (0.0..=1.0).contains(v);
            match a {
                Field::Constant(v) if !in_unit(v) => {
                    return bad(&format!("albedo {v} is outside [0, 1]"));
                }
                Field::Grid(g) if !on_grid(g) => {
                    return bad("an albedo grid is not on the problem's geometry");
                }
                Field::Grid(g) if !g.data().iter().all(in_unit) => {
                    return bad("albedo values must lie in [0, 1]");
                }
                _ => {}
            }
        }
        for light in &lights {
            if !light.spectrum().is_valid() {
                return bad("light spectra must be finite, non-negative and at most 1e30");
            }
            let unit = |d: DVec3| d.is_finite() && (d.length() - 1.0).abs() < 1e-9;
            let ok = match light {
                Light::Directional { direction, .. } => unit(*direction),
                Light::Point { position, .. } => position.is_finite(),
                Light::Spot {
                    position,
                    direction,
                    inner_angle,
                    outer_angle,
                    ..
                } => {
                    position.is_finite()
                        && unit(*direction)
                        && *inner_angle >= 0.0
                        && inner_angle <= outer_angle
                        && *outer_angle <= std::f64::consts::PI
                }
                Light::Sky { .. } => true,
                Light::Emission { grid, .. } => {
                    on_grid(grid) && grid.data().iter().all(|v| v.is_finite() && *v >= 0.0)
                }
            };
            if !ok {
                return bad(&format!(
                    "invalid {:?} light (unit directions, finite positions, 0 ≤ inner ≤ outer ≤ π, emission on the grid)",
                    light.kind()
                ));
            }
        }
        match boundary {
            Boundary::Robin { eta } if !(eta.is_finite() && eta > 0.0) => {
                return bad("Robin boundary needs a positive η");
            }
            Boundary::Dirichlet { value } if !value.is_finite() => {
                return bad("Dirichlet value must be finite");
            }
            Boundary::Neumann { flux } if !flux.is_finite() => {
                return bad("Neumann flux must be finite");
            }
            _ => {}
        }
        if embedded.as_ref().is_some_and(|g| !on_grid(g)) {
            return bad("the embedded SDF is not on the problem's geometry");
        }
        Ok(Self {
            geometry,
            medium,
            lights,
            boundary,
            embedded,
            refractive_index: None,
        })
    }

    /// The problem with a refractive index η(x) through its medium, checked positive and
    /// finite over the box. Only solvers that trace curved rays take a graded index
    /// ([`crate::Capabilities::graded_index`]; `direct-refractive`); a uniform one leaves
    /// every ray straight and every solver as it was.
    pub fn with_refractive_index(
        mut self,
        index: crate::RefractiveIndex,
    ) -> Result<Self, ProblemError> {
        index.check(self.geometry.bounds()).map_err(ProblemError)?;
        self.refractive_index = Some(index);
        Ok(self)
    }

    /// The medium's refractive index, if the problem has one (none: η = 1, straight rays).
    pub fn refractive_index(&self) -> Option<&crate::RefractiveIndex> {
        self.refractive_index.as_ref()
    }

    /// Whether rays bend in this problem (a refractive index that is not uniform).
    pub fn has_graded_index(&self) -> bool {
        self.refractive_index
            .as_ref()
            .is_some_and(|n| !n.is_uniform())
    }

    /// The grid geometry (the domain).
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// The medium.
    pub fn medium(&self) -> &Medium {
        &self.medium
    }

    /// The lights.
    pub fn lights(&self) -> &[Light] {
        &self.lights
    }

    /// The boundary condition.
    pub fn boundary(&self) -> Boundary {
        self.boundary
    }

    /// The embedded geometry's signed distance grid, if any (negative inside the object).
    pub fn embedded(&self) -> Option<&Grid> {
        self.embedded.as_ref()
    }

    /// Channels to solve: 1 if the medium and every light are grey, else 3.
    pub fn channels(&self) -> usize {
        let medium = self.medium.sigma_t.len().max(self.medium.albedo.len());
        self.lights
            .iter()
            .map(|l| l.spectrum().channels())
            .fold(medium, usize::max)
    }

    /// A 64-bit digest of everything that defines the problem (geometry, every field's
    /// bits, phase function, lights, boundary, embedded body, refractive index): equal
    /// problems have equal fingerprints, and a solution kept with its problem's can be
    /// checked against the problem it is later used with.
    pub fn fingerprint(&self) -> u64 {
        use std::hash::{DefaultHasher, Hasher};
        let mut h = DefaultHasher::new();
        let mut bytes = Vec::with_capacity(4096);
        let mut grid = |h: &mut DefaultHasher, g: &Grid| {
            h.write_usize(g.data().len());
            for chunk in g.data().chunks(1024) {
                bytes.clear();
                bytes.extend(chunk.iter().flat_map(|v| v.to_bits().to_le_bytes()));
                h.write(&bytes);
            }
        };
        h.write(format!("{:?}", self.geometry).as_bytes());
        for g in &self.medium.sigma_t {
            grid(&mut h, g);
        }
        for a in &self.medium.albedo {
            match a {
                Field::Constant(v) => h.write_u32(v.to_bits()),
                Field::Grid(g) => grid(&mut h, g),
            }
        }
        if let Some(g) = &self.embedded {
            grid(&mut h, g);
        }
        for light in &self.lights {
            match light {
                Light::Emission { grid: g, scale } => {
                    grid(&mut h, g);
                    h.write(format!("emission {scale:?}").as_bytes());
                }
                other => h.write(format!("{other:?}").as_bytes()),
            }
        }
        let described = format!(
            "{:?}|{:?}|{:?}",
            self.medium.phase, self.boundary, self.refractive_index
        );
        h.write(described.as_bytes());
        h.finish()
    }
}
