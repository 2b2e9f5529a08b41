//! Scene files (TOML): everything one experiment needs — volume, medium, lights,
//! boundary, camera, image, solver — in one place. `examples/scenes/` has one documented
//! file per feature; `default.toml` there is the built-in default scene.
//!
//! Paths to volume files are relative to the scene file; a `data:` prefix resolves in
//! `$LUCENT_DATA`, else `../shared/data/volumes` from the working folder, else the first
//! `shared/data/volumes` beside the scene's folder or a parent of it.

use std::path::{Path, PathBuf};

use glam::DVec3;
use lucent_core::{
    Boundary, CellMedium, Field, Light, Medium, PagedProblem, Params, Problem, Spectrum,
};
use lucent_grid::io::raw::RawLayout;
use lucent_grid::io::{self, Endian, LoadOptions, ScalarType};
use lucent_grid::procedural::{NoiseCloud, Shape, gaussian_blob, gaussian_blob_at};
use lucent_grid::transfer::TransferFunction;
use lucent_grid::{Grid, GridGeometry, resample};
use lucent_optics::Phase;
use lucent_render::{Camera, RenderSettings, ToneMap};
use serde::Deserialize;

use crate::Error;

/// The one memory budget of a scene: everything it allocates while being built (the
/// volume file's read, payload and decoded grid together, then every field it derives)
/// stays within it. Solvers have their own, `SolveOptions::memory_budget`.
pub const SCENE_MEMORY_BUDGET: u64 = 8 << 30;

/// The most bytes one scene grid may take under a budget: a scene holds up to eight
/// fields on its grid (the volume, σ_t and albedo per channel, an embedded SDF), an eighth
/// of the budget each (1 GiB, 645³ cells, under the default).
pub fn max_grid_bytes(budget: u64) -> u64 {
    budget / 8
}

/// The registered solvers that solve a procedural scene out of core ([`Solver::pages`]),
/// in registry order.
///
/// [`Solver::pages`]: lucent_core::Solver::pages
pub fn paging_solvers() -> Vec<String> {
    let registry = crate::registry();
    registry
        .entries()
        .iter()
        .filter_map(|entry| {
            let solver = (entry.build)(&Params::default()).ok()?;
            solver.pages().then(|| entry.name.to_owned())
        })
        .collect()
}

/// What reading a volume file may take, its payload and its decoded grid together: three
/// fields' worth (an f64 payload and its f32 grid of the largest field), so that a file
/// claiming more (a decompression bomb, a VDB whose tree spans a huge box) is refused
/// before anything is inflated or allocated.
pub fn max_read_bytes(budget: u64) -> u64 {
    3 * max_grid_bytes(budget)
}

/// The brick edge of a paged scene under `budget`: 16³ cells, or 8³ (4³) where the brick
/// layers a paged solver keeps in memory would take more than a quarter of the budget.
fn default_brick(geometry: &GridGeometry, budget: u64) -> usize {
    let [nx, ny, _] = geometry.dims();
    let layer = |b: usize| (nx * ny * b) as u64 * 4;
    [16, 8, 4]
        .into_iter()
        .find(|&b| 4 * layer(b) <= budget / 4)
        .unwrap_or(4)
}

/// The pager of a paged scene with bricks of `brick`³ cells under `budget`: the pool is
/// the budget less the brick layers the solvers keep in memory and the bookkeeping.
fn paged_pager(
    geometry: &GridGeometry,
    brick: usize,
    budget: u64,
    store: impl FnOnce() -> Result<Box<dyn lucent_paging::BrickStore>, String>,
) -> Result<std::sync::Arc<lucent_paging::Pager>, Error> {
    let invalid = |reason: String| Error::Invalid(reason);
    let [nx, ny, _] = geometry.dims();
    let layer = |b: usize| (nx * ny * b) as u64 * 4;
    let layout = lucent_grid::BrickLayout::new(geometry.dims(), brick)?;
    let bookkeeping = 8 * layout.count() as u64 * 21 + (nx * ny).max(1) as u64 * 40;
    let pool = budget.saturating_sub(4 * layer(brick) + bookkeeping + budget / 16);
    let brick_bytes = layout.stored_len() as u64 * 4;
    let store = store().map_err(invalid)?;
    let pager = lucent_paging::Pager::new(
        store,
        0,
        layout.stored_len(),
        4,
        lucent_paging::PagerOptions {
            budget_bytes: pool.max(4 * brick_bytes),
            eviction: lucent_paging::Eviction::Nru,
            fill: 0.0,
        },
    )
    .map_err(|e| invalid(e.to_string()))?;
    Ok(std::sync::Arc::new(pager))
}

/// The built-in default scene: a procedural cloud lit by a sun-like directional light and a
/// blue sky (`examples/scenes/default.toml`).
pub const DEFAULT_SCENE: &str = include_str!("../examples/scenes/default.toml");

/// A parsed scene file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Where the density comes from.
    pub volume: VolumeSpec,
    /// How density becomes a medium.
    #[serde(default)]
    pub medium: MediumSpec,
    /// The lights.
    #[serde(default)]
    pub lights: Vec<LightSpec>,
    /// The boundary condition.
    #[serde(default)]
    pub boundary: Boundary,
    /// Embedded geometry: the medium is the inside of this shape (its signed distance,
    /// sampled on the grid, is the problem's embedded SDF), and a Robin boundary applies
    /// on its surface.
    #[serde(default)]
    pub embedded: Option<ShapeSpec>,
    /// The medium's refractive index, where it is graded (curved rays: `direct-refractive`).
    #[serde(default)]
    pub refractive_index: Option<IndexSpec>,
    /// The camera (only `render` looks through it); without one, [`framing_camera`]: a
    /// pinhole looking at the box's centre from the front right, above, the whole box in
    /// view.
    #[serde(default)]
    pub camera: Option<Camera>,
    /// Image size and tone mapping.
    #[serde(default)]
    pub image: ImageSpec,
    /// Which solver, with which parameters.
    #[serde(default)]
    pub solver: SolverSpec,
}

/// A refractive-index field η(x) (dimensionless) through the medium.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum IndexSpec {
    /// The same η everywhere (rays stay straight).
    Uniform {
        /// η.
        eta: f64,
    },
    /// η = η₀ + g·(x − origin).
    Linear {
        /// η at `origin`.
        eta0: f64,
        /// ∇η (1/length).
        gradient: [f64; 3],
        /// Where η = η₀ (default the world origin).
        #[serde(default)]
        origin: [f64; 3],
    },
    /// Luneburg's lens: η = √(2 − (r/R)²) inside the sphere, 1 outside.
    Luneburg {
        /// Centre.
        centre: [f64; 3],
        /// Radius R.
        radius: f64,
    },
    /// A Gaussian bump η₀ + A e^{−|x − c|²/w²}.
    Gaussian {
        /// η far away (default 1).
        #[serde(default = "one")]
        eta0: f64,
        /// The bump's height A.
        amplitude: f64,
        /// Centre c.
        centre: [f64; 3],
        /// Width w.
        width: f64,
    },
    /// η = base + scale · the scene's volume (before the medium mapping), per voxel, as
    /// a cubic B-spline: e.g. heat shimmer, η falling where hot smoke is dense.
    Volume {
        /// η where the volume is 0.
        base: f64,
        /// dη per unit of the volume's value.
        scale: f64,
    },
}

impl IndexSpec {
    /// The index on the scene's `volume`.
    fn to_index(self, volume: &Grid) -> lucent_core::RefractiveIndex {
        use lucent_core::RefractiveIndex as R;
        use lucent_optics::eikonal::{GaussianBump, LinearIndex, Luneburg};
        let v = |a: [f64; 3]| DVec3::from_array(a);
        match self {
            IndexSpec::Uniform { eta } => R::Uniform(eta),
            IndexSpec::Linear {
                eta0,
                gradient,
                origin,
            } => R::Linear(LinearIndex {
                eta0,
                gradient: v(gradient),
                origin: v(origin),
            }),
            IndexSpec::Luneburg { centre, radius } => R::Luneburg(Luneburg {
                centre: v(centre),
                radius,
            }),
            IndexSpec::Gaussian {
                eta0,
                amplitude,
                centre,
                width,
            } => R::Gaussian(GaussianBump {
                eta0,
                amplitude,
                centre: v(centre),
                width,
            }),
            IndexSpec::Volume { base, scale } => R::Grid(lucent_core::IndexGrid::new(
                volume.map(|d| (base + scale * f64::from(d)) as f32),
            )),
        }
    }
}

/// Where the scalar volume comes from.
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum VolumeSpec {
    /// A seeded fBm noise cloud filling a ball in the box.
    Cloud {
        /// Cells per axis.
        resolution: [usize; 3],
        /// The box [min, max].
        bounds: [[f64; 3]; 2],
        /// Noise seed.
        #[serde(default)]
        seed: u64,
        /// Density offset (larger: thinner, more broken cloud).
        #[serde(default)]
        threshold: Option<f64>,
    },
    /// A shape's density (1 inside, 0 outside, linear edge of width `edge`).
    Shape {
        /// Cells per axis.
        resolution: [usize; 3],
        /// The box [min, max].
        bounds: [[f64; 3]; 2],
        /// The shape.
        shape: ShapeSpec,
        /// Width of the soft edge (scene units).
        #[serde(default)]
        edge: f64,
    },
    /// A Gaussian blob of peak 1.
    Blob {
        /// Cells per axis.
        resolution: [usize; 3],
        /// The box [min, max].
        bounds: [[f64; 3]; 2],
        /// Centre.
        centre: [f64; 3],
        /// Standard deviation.
        sigma: f64,
    },
    /// A volume file; `.raw` files need `raw`.
    File {
        /// Path (relative to the scene file, or `data:NAME` in `$LUCENT_DATA`).
        path: String,
        /// Layout of a headerless raw file.
        #[serde(default)]
        raw: Option<RawSpec>,
        /// Resample to this resolution.
        #[serde(default)]
        resolution: Option<[usize; 3]>,
        /// Place the volume in this box instead of where the file puts it (after `up`).
        #[serde(default)]
        bounds: Option<[[f64; 3]; 2]>,
        /// The file's up axis: `"y"` for volumes authored Y-up (Houdini, Maya, OpenVDB's
        /// convention: the default for `.vdb`), turned so that their up is lucent's z
        /// (a point (x, y, z) of the file lands at (x, −z, y)); `"z"` keeps the file's axes
        /// (the default for every other format).
        #[serde(default)]
        up: Option<UpAxis>,
    },
}

/// The up axis of a volume file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum UpAxis {
    /// Y-up (Houdini, Maya, OpenVDB).
    Y,
    /// Z-up (lucent, Blender, 3ds Max; medical volumes' slice axis).
    Z,
}

/// A procedural shape.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ShapeSpec {
    /// A ball.
    Sphere {
        /// Centre.
        centre: [f64; 3],
        /// Radius.
        radius: f64,
    },
    /// An axis-aligned box.
    Box {
        /// Minimum corner.
        min: [f64; 3],
        /// Maximum corner.
        max: [f64; 3],
    },
    /// A torus around the z axis.
    Torus {
        /// Centre.
        centre: [f64; 3],
        /// Ring radius.
        major: f64,
        /// Tube radius.
        minor: f64,
    },
    /// A slab between two parallel planes.
    Slab {
        /// Plane normal.
        normal: [f64; 3],
        /// Mid-plane offset along the normal.
        offset: f64,
        /// Thickness.
        thickness: f64,
    },
}

/// Layout of a headerless raw file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSpec {
    /// Cells per axis.
    pub dims: [usize; 3],
    /// `u8`, `i8`, `u16`, `i16`, `u32`, `i32`, `f32` or `f64`.
    #[serde(rename = "type")]
    pub scalar: String,
    /// Big-endian samples.
    #[serde(default)]
    pub big_endian: bool,
    /// Cell size.
    #[serde(default)]
    pub spacing: Option<[f64; 3]>,
}

/// How the scalar volume becomes a medium.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MediumSpec {
    /// σ_t = density × value (1/length) when there is no transfer function.
    #[serde(default = "one")]
    pub density: f64,
    /// Single-scattering albedo (grey or RGB) when there is no transfer function.
    #[serde(default = "default_albedo")]
    pub albedo: Spectrum,
    /// Per-channel multiplier of the extinction (coloured media such as ketchup).
    #[serde(default)]
    pub extinction_color: Option<[f64; 3]>,
    /// A transfer function (replaces `density` and `albedo`).
    #[serde(default)]
    pub transfer: Option<TransferFunction>,
    /// The phase function.
    #[serde(default)]
    pub phase: PhaseSpec,
}

fn one() -> f64 {
    1.0
}

fn default_albedo() -> Spectrum {
    Spectrum::Grey(0.9)
}

impl Default for MediumSpec {
    fn default() -> Self {
        Self {
            density: 1.0,
            albedo: default_albedo(),
            extinction_color: None,
            transfer: None,
            phase: PhaseSpec::Isotropic {},
        }
    }
}

/// A phase function.
///
/// The keyless kinds are tables of no keys (`Isotropic {}`), so that a stray key beside
/// them is refused (serde lets extra keys through an internally tagged unit variant).
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum PhaseSpec {
    /// Isotropic.
    Isotropic {},
    /// Henyey–Greenstein with mean cosine `g`.
    HenyeyGreenstein {
        /// Mean cosine.
        g: f64,
    },
    /// Two Henyey–Greenstein lobes.
    DoubleHenyeyGreenstein {
        /// First lobe's mean cosine.
        g1: f64,
        /// Second lobe's mean cosine.
        g2: f64,
        /// First lobe's weight.
        weight: f64,
    },
    /// Rayleigh.
    Rayleigh {},
}

impl Default for PhaseSpec {
    fn default() -> Self {
        Self::Isotropic {}
    }
}

impl PhaseSpec {
    /// The phase function (its parameters checked).
    pub fn to_phase(self) -> Result<Phase, Error> {
        let invalid = |e: lucent_optics::OpticsError| Error::Invalid(e.to_string());
        Ok(match self {
            PhaseSpec::Isotropic {} => Phase::Isotropic,
            PhaseSpec::HenyeyGreenstein { g } => Phase::henyey_greenstein(g).map_err(invalid)?,
            PhaseSpec::DoubleHenyeyGreenstein { g1, g2, weight } => {
                Phase::double_henyey_greenstein(g1, g2, weight).map_err(invalid)?
            }
            PhaseSpec::Rayleigh {} => Phase::Rayleigh,
        })
    }
}

/// A light. Angles in degrees; directions need not be normalised.
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum LightSpec {
    /// A distant light travelling along `direction`.
    Directional {
        /// Direction of travel.
        direction: [f64; 3],
        /// Irradiance across the beam.
        irradiance: Spectrum,
    },
    /// A point light.
    Point {
        /// Position.
        position: [f64; 3],
        /// Radiant intensity (W/sr).
        intensity: Spectrum,
    },
    /// A spot light.
    Spot {
        /// Position.
        position: [f64; 3],
        /// Axis of the cone.
        direction: [f64; 3],
        /// Radiant intensity on the axis.
        intensity: Spectrum,
        /// Half-angle of full intensity, degrees.
        inner_angle: f64,
        /// Half-angle of darkness, degrees.
        outer_angle: f64,
    },
    /// A uniform sky.
    Sky {
        /// Radiance.
        radiance: Spectrum,
    },
    /// Emission proportional to the volume's values.
    Emission {
        /// Radiance per unit length per unit of volume value.
        scale: Spectrum,
    },
}

impl LightSpec {
    /// The light: directions normalised, angles in radians; an emission light takes its
    /// grid from `volume` (none: refused, as for a paged scene).
    pub fn to_light(&self, volume: Option<&Grid>) -> Result<Light, Error> {
        let invalid = |reason: String| Error::Invalid(reason);
        let unit = |v: [f64; 3], what: &str| -> Result<DVec3, Error> {
            let d = DVec3::from_array(v);
            let n = d.normalize_or_zero();
            if n == DVec3::ZERO || !n.is_finite() {
                Err(invalid(format!("{what} {v:?} is not a direction")))
            } else {
                Ok(n)
            }
        };
        Ok(match self {
            LightSpec::Directional {
                direction,
                irradiance,
            } => Light::Directional {
                direction: unit(*direction, "light direction")?,
                irradiance: *irradiance,
            },
            LightSpec::Point {
                position,
                intensity,
            } => Light::Point {
                position: DVec3::from_array(*position),
                intensity: *intensity,
            },
            LightSpec::Spot {
                position,
                direction,
                intensity,
                inner_angle,
                outer_angle,
            } => Light::Spot {
                position: DVec3::from_array(*position),
                direction: unit(*direction, "spot direction")?,
                intensity: *intensity,
                inner_angle: inner_angle.to_radians(),
                outer_angle: outer_angle.to_radians(),
            },
            LightSpec::Sky { radiance } => Light::Sky {
                radiance: *radiance,
            },
            LightSpec::Emission { scale } => match volume {
                Some(volume) => Light::Emission {
                    grid: volume.map(|v| v.max(0.0)),
                    scale: *scale,
                },
                None => {
                    return Err(invalid(
                        "emission lights need the volume in memory (a paged scene has none)".into(),
                    ));
                }
            },
        })
    }
}

/// Image size, exposure and tone mapping.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageSpec {
    /// Width in pixels.
    #[serde(default = "default_width")]
    pub width: usize,
    /// Height in pixels.
    #[serde(default = "default_height")]
    pub height: usize,
    /// Exposure in stops.
    #[serde(default)]
    pub exposure: f64,
    /// Tone curve.
    #[serde(default)]
    pub tone: ToneMap,
    /// Ray-marching step as a fraction of the smallest cell.
    #[serde(default = "default_step")]
    pub step: f64,
    /// Background radiance (default: the sky's).
    #[serde(default)]
    pub background: Option<[f64; 3]>,
}

fn default_width() -> usize {
    640
}
fn default_height() -> usize {
    480
}
fn default_step() -> f64 {
    0.5
}

impl Default for ImageSpec {
    fn default() -> Self {
        Self {
            width: 640,
            height: 480,
            exposure: 0.0,
            tone: ToneMap::Aces,
            step: 0.5,
            background: None,
        }
    }
}

/// The solver to run.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolverSpec {
    /// Registry name.
    #[serde(default = "default_solver")]
    pub name: String,
    /// Its parameters.
    #[serde(default)]
    pub params: Params,
    /// The relative residual to stop at (`None`: `SolveOptions`'s 1e-6); the command
    /// line's `--tolerance` overrides it.
    #[serde(default)]
    pub tolerance: Option<f64>,
    /// Whether the scene had no `[solver]` table (this is the default, `direct`: the
    /// command says what that leaves out).
    #[serde(skip)]
    pub defaulted: bool,
}

fn default_solver() -> String {
    "direct".into()
}

impl Default for SolverSpec {
    fn default() -> Self {
        Self {
            name: default_solver(),
            params: Params::default(),
            tolerance: None,
            defaulted: true,
        }
    }
}

/// A value per cell centre (a procedural volume, brick by brick).
type CellFn = Box<dyn Fn(DVec3) -> f32 + Sync>;

/// A scene ready to solve and render.
#[derive(Debug, Clone)]
pub struct BuiltScene {
    /// The problem.
    pub problem: Problem,
    /// The camera.
    pub camera: Camera,
    /// Image settings.
    pub settings: RenderSettings,
    /// Exposure in stops.
    pub exposure: f64,
    /// Tone curve.
    pub tone: ToneMap,
    /// The scalar volume before the medium mapping.
    pub volume: Grid,
}

impl Scene {
    /// Parses scene text; `origin` names it in errors and anchors relative paths.
    pub fn parse(text: &str, origin: &Path) -> Result<Self, Error> {
        toml::from_str(text).map_err(|e| {
            let mut reason = light_missing_key(text, &e)
                .or_else(|| pinpoint(text, &e))
                .unwrap_or_else(|| e.to_string());
            if let Some(hint) = missing_key_hint(text, &e) {
                reason = format!("{}\n{hint}", reason.trim_end());
            }
            Error::Scene {
                path: origin.to_owned(),
                reason,
            }
        })
    }

    /// Reads and parses a scene file (a regular file of at most 16 MiB: a scene is a few
    /// hundred lines; a device or FIFO could block or never end).
    pub fn load(path: &Path) -> Result<Self, Error> {
        use std::io::Read;
        const MAX_SCENE_BYTES: u64 = 16 << 20;
        let fail = |reason: String| Error::Io {
            path: path.to_owned(),
            reason,
        };
        let metadata = std::fs::metadata(path).map_err(|e| fail(e.to_string()))?;
        if !metadata.is_file() {
            return Err(fail(
                "not a regular file (devices, FIFOs and folders are not read)".into(),
            ));
        }
        if metadata.len() > MAX_SCENE_BYTES {
            return Err(fail(format!(
                "{} bytes: a scene file is at most {MAX_SCENE_BYTES} bytes",
                metadata.len()
            )));
        }
        let mut text = String::new();
        std::fs::File::open(path)
            .and_then(|f| f.take(MAX_SCENE_BYTES).read_to_string(&mut text))
            .map_err(|e| fail(e.to_string()))?;
        Self::parse(&text, path)
    }

    /// The built-in default scene.
    pub fn default_scene() -> Result<Self, Error> {
        Self::parse(DEFAULT_SCENE, Path::new("<built-in default scene>"))
    }

    /// Builds the problem, camera and image settings within [`SCENE_MEMORY_BUDGET`];
    /// `base` is the folder that relative volume paths start from.
    pub fn build(&self, base: &Path) -> Result<BuiltScene, Error> {
        self.build_within(base, SCENE_MEMORY_BUDGET)
    }

    /// [`Scene::build`] within `memory_budget` bytes for everything the scene allocates.
    pub fn build_within(&self, base: &Path, memory_budget: u64) -> Result<BuiltScene, Error> {
        let invalid = |reason: String| Error::Invalid(reason);
        let volume = self.load_volume(base, memory_budget)?;
        let geometry = *volume.geometry();
        let m = &self.medium;
        let (sigma_t_base, albedo): (Grid, Vec<Field>) = match &m.transfer {
            Some(tf) => {
                let grids = tf.apply(&volume);
                let albedo = match grids.color {
                    Some(rgb) => rgb
                        .into_iter()
                        .map(|c| Field::Grid(multiply(&grids.albedo, &c)))
                        .collect(),
                    None => vec![Field::Grid(grids.albedo)],
                };
                (grids.sigma_t, albedo)
            }
            None => {
                if !(m.density.is_finite() && m.density >= 0.0) {
                    return Err(invalid(format!(
                        "medium.density {} must be finite and ≥ 0",
                        m.density
                    )));
                }
                let albedo = (0..m.albedo.channels())
                    .map(|c| Field::Constant(m.albedo.channel(c) as f32))
                    .collect();
                (
                    volume.map(|v| (f64::from(v.max(0.0)) * m.density) as f32),
                    albedo,
                )
            }
        };
        let sigma_t = match m.extinction_color {
            Some(rgb) => rgb
                .iter()
                .map(|&s| sigma_t_base.map(|v| (f64::from(v) * s) as f32))
                .collect(),
            None => vec![sigma_t_base],
        };
        let phase = self.phase()?;
        let medium = Medium {
            sigma_t,
            albedo,
            phase,
        };
        let lights = self.lights(Some(&volume))?;
        let boundary = self.boundary;
        let embedded = match self.embedded {
            Some(spec) => Some(to_shape(spec).sdf_grid(geometry)?),
            None => None,
        };
        let mut problem = Problem::new(geometry, medium, lights, boundary, embedded)?;
        if let Some(index) = self.refractive_index {
            problem = problem.with_refractive_index(index.to_index(&volume))?;
        }
        let camera = self
            .camera
            .unwrap_or_else(|| framing_camera(geometry.origin(), geometry.extent()));
        camera.validate()?;
        let i = self.image;
        let settings = RenderSettings {
            width: i.width,
            height: i.height,
            step: i.step,
            background: i.background,
        };
        settings.validate()?;
        if !i.exposure.is_finite() || i.exposure.abs() > 64.0 {
            return Err(Error::Invalid(format!(
                "exposure {} stops (finite, within ±64)",
                i.exposure
            )));
        }
        Ok(BuiltScene {
            problem,
            camera,
            settings,
            exposure: i.exposure,
            tone: i.tone,
            volume,
        })
    }

    /// The phase function the scene names.
    fn phase(&self) -> Result<Phase, Error> {
        self.medium.phase.to_phase()
    }

    /// The scene's lights; emission takes its grid from `volume` (none: emission refused).
    fn lights(&self, volume: Option<&Grid>) -> Result<Vec<Light>, Error> {
        self.lights.iter().map(|l| l.to_light(volume)).collect()
    }

    /// Bytes of one dense f32 field on the scene's grid, where the scene states its
    /// resolution (procedural volumes, or a file resampled to a resolution); `None` where
    /// only reading the file tells.
    pub fn field_bytes(&self) -> Option<u64> {
        let resolution = match &self.volume {
            VolumeSpec::Cloud { resolution, .. }
            | VolumeSpec::Shape { resolution, .. }
            | VolumeSpec::Blob { resolution, .. } => *resolution,
            VolumeSpec::File { resolution, .. } => (*resolution)?,
        };
        resolution
            .iter()
            .try_fold(4u64, |bytes, &n| bytes.checked_mul(n as u64))
    }

    /// Whether [`Scene::build_paged`] takes the scene: a procedural volume mapped by a
    /// density, no embedded shape, no emission light.
    pub fn pageable(&self) -> bool {
        !matches!(self.volume, VolumeSpec::File { .. })
            && self.medium.transfer.is_none()
            && self.embedded.is_none()
            && !self
                .lights
                .iter()
                .any(|l| matches!(l, LightSpec::Emission { .. }))
    }

    /// Whether the scene's dense fields fit `budget` ([`Scene::build_within`]'s check).
    pub fn fits_in_memory(&self, budget: u64) -> bool {
        self.field_bytes()
            .is_none_or(|bytes| bytes <= max_grid_bytes(budget))
    }

    /// The scene as a problem whose medium is paged ([`PagedProblem`]), for a job whose
    /// dense fields exceed `budget`: σ_t and the albedo are evaluated cell by cell, brick
    /// by brick (never as a dense grid), with the same arithmetic [`Scene::build_within`]
    /// uses, into a pager backed by an unnamed temporary file in the system's temporary
    /// folder (`TMPDIR`). Bricks of 16³ cells, or 8³ (4³) where the brick layers a paged
    /// solver keeps in memory would take more than a quarter of the budget; the pool is
    /// the budget less those layers and the bookkeeping. Procedural volumes only (cloud,
    /// shape, blob) with a density (no transfer function), no emission, no embedded shape.
    pub fn build_paged(&self, budget: u64) -> Result<PagedProblem, Error> {
        self.build_paged_with(budget, None)
    }

    /// [`Scene::build_paged`] for `solver` under `options`, refused before any work when
    /// the budget cannot do: the solver's memory for the scene's shape
    /// ([`lucent_core::Solver::paged_memory`] on a [`PagedProblem::shell`], whose medium
    /// is never evaluated) is checked for bricks of 16³, 8³ and 4³ cells (the default
    /// first), the first that fits is built, and when none fits the error names the
    /// smallest budget that would do. (Building the medium of a 384³ cloud takes tens of
    /// seconds; it was once built and then refused.)
    pub fn build_paged_for(
        &self,
        solver: &dyn lucent_core::Solver,
        options: &lucent_core::SolveOptions,
    ) -> Result<PagedProblem, Error> {
        let budget = options.memory_budget;
        let geometry = self.paged_geometry()?;
        let medium_budget = solver.paged_medium_budget(budget);
        let first = default_brick(&geometry, medium_budget);
        let bricks = std::iter::once(first).chain([16, 8, 4].into_iter().filter(|&b| b != first));
        // A shell holds the medium's per-brick bookkeeping (never its values); one whose
        // bookkeeping alone is over the budget tried, or over what a refusal may spend
        // (the caller's budget, at least 1 GiB), is not built: it cannot fit, or the
        // search for the smallest budget stops there.
        let shell_cap = options.memory_budget.max(1 << 30);
        let medium_fields =
            self.medium.extinction_color.map_or(1, |c| c.len()) + self.medium.albedo.channels();
        let fits =
            |brick: usize, budget: u64| -> Result<Result<u64, lucent_core::SolveError>, Error> {
                let count = lucent_grid::BrickLayout::new(geometry.dims(), brick)?.count() as u64;
                let bookkeeping =
                    count * medium_fields as u64 * lucent_paging::PagedGrid::BYTES_PER_BRICK;
                if bookkeeping > budget.min(shell_cap) {
                    return Ok(Err(lucent_core::SolveError::OverBudget {
                        solver: solver.name().into(),
                        needed: bookkeeping,
                        budget,
                    }));
                }
                let shell = self.paged_shell(solver.paged_medium_budget(budget), brick)?;
                let options = lucent_core::SolveOptions {
                    memory_budget: budget,
                    ..options.clone()
                };
                Ok(solver.paged_memory(&shell, &options))
            };
        let mut refusal = None;
        for brick in bricks.clone() {
            match fits(brick, budget)? {
                Ok(_) => return self.build_paged_with(medium_budget, Some(brick)),
                Err(lucent_core::SolveError::OverBudget { .. }) => {}
                Err(other) => {
                    refusal.get_or_insert(other);
                }
            }
        }
        if let Some(other) = refusal {
            return Err(other.into());
        }
        // No brick fits: the smallest budget that would, by bisection on each brick (the
        // need grows more slowly than the budget: the pool takes a share of it).
        let mut smallest = u64::MAX;
        let ceiling = shell_cap.saturating_mul(64);
        for brick in bricks {
            let (mut lo, mut hi) = (budget, budget.saturating_mul(2).max(1 << 20));
            while hi < ceiling && fits(brick, hi)?.is_err() {
                lo = hi;
                hi = hi.saturating_mul(2);
            }
            if hi >= ceiling {
                continue;
            }
            // Within 1 %: the answer is advice, not a bound to the byte.
            while hi - lo > hi / 100 {
                let mid = lo + (hi - lo) / 2;
                if fits(brick, mid)?.is_ok() {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            smallest = smallest.min(hi);
        }
        Err(Error::PagedBudget {
            solver: solver.name().into(),
            budget,
            smallest: (smallest < u64::MAX).then_some(smallest),
        })
    }

    /// The geometry of a paged build, and the checks that need nothing built.
    pub fn paged_geometry(&self) -> Result<GridGeometry, Error> {
        let (resolution, bounds) = match &self.volume {
            VolumeSpec::Cloud {
                resolution, bounds, ..
            }
            | VolumeSpec::Shape {
                resolution, bounds, ..
            }
            | VolumeSpec::Blob {
                resolution, bounds, ..
            } => (*resolution, *bounds),
            VolumeSpec::File { .. } => {
                return Err(Error::Invalid(
                    "a paged scene needs a procedural volume (cloud, shape, blob): volume files are read whole"
                        .into(),
                ));
            }
        };
        Ok(GridGeometry::from_bounds(
            resolution,
            DVec3::from_array(bounds[0]),
            DVec3::from_array(bounds[1]),
        )?)
    }

    /// The paged problem's shape with a zero medium ([`PagedProblem::shell`]): its pager
    /// in memory, nothing evaluated.
    fn paged_shell(&self, budget: u64, brick: usize) -> Result<PagedProblem, Error> {
        let geometry = self.paged_geometry()?;
        let pager = paged_pager(&geometry, brick, budget, || {
            Ok(Box::new(lucent_paging::MemoryStore::default())
                as Box<dyn lucent_paging::BrickStore>)
        })?;
        let m = &self.medium;
        Ok(PagedProblem::shell(
            pager,
            geometry,
            brick,
            m.extinction_color.map_or(1, |c| c.len()),
            m.albedo.channels(),
            self.phase()?,
            self.lights(None)?,
            self.boundary,
        )?)
    }

    /// [`Scene::build_paged`] with bricks of `brick`³ cells (`None`: the default choice).
    fn build_paged_with(&self, budget: u64, brick: Option<usize>) -> Result<PagedProblem, Error> {
        let invalid = |reason: String| Error::Invalid(reason);
        if self.medium.transfer.is_some() {
            return Err(invalid(
                "a paged scene maps density by `medium.density`, not a transfer function".into(),
            ));
        }
        if self.embedded.is_some() {
            return Err(invalid("a paged scene has no embedded shape".into()));
        }
        if self.refractive_index.is_some() {
            return Err(invalid(
                "a paged scene has no refractive index (curved rays run in memory)".into(),
            ));
        }
        let m = &self.medium;
        if !(m.density.is_finite() && m.density >= 0.0) {
            return Err(invalid(format!(
                "medium.density {} must be finite and ≥ 0",
                m.density
            )));
        }
        let tiny = |bounds: [[f64; 3]; 2]| {
            GridGeometry::from_bounds(
                [1, 1, 1],
                DVec3::from_array(bounds[0]),
                DVec3::from_array(bounds[1]),
            )
        };
        // The volume's value at a cell centre, validated as the dense build validates it.
        let (resolution, bounds, value): ([usize; 3], [[f64; 3]; 2], CellFn) = match &self.volume {
            VolumeSpec::Cloud {
                resolution,
                bounds,
                seed,
                threshold,
            } => {
                let g = GridGeometry::from_bounds(
                    *resolution,
                    DVec3::from_array(bounds[0]),
                    DVec3::from_array(bounds[1]),
                )?;
                let (lo, hi) = g.bounds();
                let mut cloud =
                    NoiseCloud::new(*seed, 0.5 * (lo + hi), 0.48 * (hi - lo).min_element());
                if let Some(t) = threshold {
                    cloud.threshold = *t;
                }
                cloud.rasterize(tiny(*bounds)?)?;
                (
                    *resolution,
                    *bounds,
                    Box::new(move |p| cloud.density(p) as f32),
                )
            }
            VolumeSpec::Shape {
                resolution,
                bounds,
                shape,
                edge,
            } => {
                let shape = to_shape(*shape);
                shape.density_grid(tiny(*bounds)?, *edge)?;
                let edge = *edge;
                (
                    *resolution,
                    *bounds,
                    Box::new(move |p| shape.density_at(p, edge)),
                )
            }
            VolumeSpec::Blob {
                resolution,
                bounds,
                centre,
                sigma,
            } => {
                let centre = DVec3::from_array(*centre);
                gaussian_blob(tiny(*bounds)?, centre, *sigma)?;
                let sigma = *sigma;
                (
                    *resolution,
                    *bounds,
                    Box::new(move |p| gaussian_blob_at(p, centre, sigma)),
                )
            }
            VolumeSpec::File { .. } => {
                return Err(invalid(
                    "a paged scene needs a procedural volume (cloud, shape, blob): volume files are read whole"
                        .into(),
                ));
            }
        };
        let geometry = GridGeometry::from_bounds(
            resolution,
            DVec3::from_array(bounds[0]),
            DVec3::from_array(bounds[1]),
        )?;
        let lights = self.lights(None)?;
        let base = move |p: DVec3| (f64::from(value(p).max(0.0)) * m.density) as f32;
        let scales: Vec<f64> = match m.extinction_color {
            Some(rgb) => rgb.to_vec(),
            None => vec![],
        };
        let sigma_fns: Vec<Box<dyn Fn(DVec3) -> f32 + Sync + '_>> = if scales.is_empty() {
            vec![Box::new(&base)]
        } else {
            scales
                .iter()
                .map(|&s| {
                    let base = &base;
                    Box::new(move |p: DVec3| (f64::from(base(p)) * s) as f32)
                        as Box<dyn Fn(DVec3) -> f32 + Sync>
                })
                .collect()
        };
        let albedos: Vec<f32> = (0..m.albedo.channels())
            .map(|c| m.albedo.channel(c) as f32)
            .collect();
        let albedo_fns: Vec<Box<dyn Fn(DVec3) -> f32 + Sync>> = albedos
            .iter()
            .map(|&a| Box::new(move |_: DVec3| a) as Box<dyn Fn(DVec3) -> f32 + Sync>)
            .collect();

        let brick = brick.unwrap_or_else(|| default_brick(&geometry, budget));
        let pager = paged_pager(&geometry, brick, budget, || {
            lucent_paging::FileStore::create()
                .map(|s| Box::new(s) as Box<dyn lucent_paging::BrickStore>)
                .map_err(|e| e.to_string())
        })?;
        Ok(PagedProblem::from_fn(
            pager,
            geometry,
            brick,
            CellMedium {
                sigma_t: sigma_fns.iter().map(|f| f.as_ref()).collect(),
                albedo: albedo_fns.iter().map(|f| f.as_ref()).collect(),
                phase: self.phase()?,
            },
            lights,
            self.boundary,
        )?)
    }

    fn load_volume(&self, base: &Path, budget: u64) -> Result<Grid, Error> {
        // A scene builds a handful of grids of this size (volume, σ_t and albedo per channel,
        // per-light transmittance): refuse resolutions that could not fit before allocating.
        let geometry = |resolution: [usize; 3],
                        bounds: [[f64; 3]; 2]|
         -> Result<GridGeometry, Error> {
            let g = GridGeometry::from_bounds(
                resolution,
                DVec3::from_array(bounds[0]),
                DVec3::from_array(bounds[1]),
            )?;
            let bytes = g.voxel_count() as u64 * 4;
            if bytes > max_grid_bytes(budget) {
                let out_of_core = match &self.volume {
                    VolumeSpec::File { .. } => String::new(),
                    _ => format!(
                        "; `lucent solve` solves this procedural scene out of core with {}, and `lucent info` describes it; `render` and the other solvers build it in memory",
                        paging_solvers()
                            .iter()
                            .map(|n| format!("`{n}`"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                };
                return Err(Error::OverBudget(format!(
                    "a {resolution:?} grid needs {bytes} bytes per field; a scene holds up to 8 fields, so a memory budget of {budget} bytes allows {} per field in memory (--memory-budget sets it){out_of_core}",
                    max_grid_bytes(budget)
                )));
            }
            Ok(g)
        };
        Ok(match &self.volume {
            VolumeSpec::Cloud {
                resolution,
                bounds,
                seed,
                threshold,
            } => {
                let g = geometry(*resolution, *bounds)?;
                let (lo, hi) = g.bounds();
                let mut cloud =
                    NoiseCloud::new(*seed, 0.5 * (lo + hi), 0.48 * (hi - lo).min_element());
                if let Some(t) = threshold {
                    cloud.threshold = *t;
                }
                cloud.rasterize(g)?
            }
            VolumeSpec::Shape {
                resolution,
                bounds,
                shape,
                edge,
            } => {
                let shape = to_shape(*shape);
                shape.density_grid(geometry(*resolution, *bounds)?, *edge)?
            }
            VolumeSpec::Blob {
                resolution,
                bounds,
                centre,
                sigma,
            } => gaussian_blob(
                geometry(*resolution, *bounds)?,
                DVec3::from_array(*centre),
                *sigma,
            )?,
            VolumeSpec::File {
                path,
                raw,
                resolution,
                bounds,
                up,
            } => {
                let path = resolve(base, path);
                let read_budget = LoadOptions {
                    memory_budget: max_read_bytes(budget),
                };
                let mut grid = match raw {
                    Some(r) => {
                        let scalar = scalar_type(&r.scalar).ok_or_else(|| {
                            Error::Invalid(format!("unknown raw type `{}`", r.scalar))
                        })?;
                        let mut layout = RawLayout::new(r.dims, scalar);
                        layout.endian = if r.big_endian {
                            Endian::Big
                        } else {
                            Endian::Little
                        };
                        if let Some(s) = r.spacing {
                            layout.spacing = DVec3::from_array(s);
                        }
                        io::raw::read(&path, &layout, &read_budget)?
                    }
                    None => io::read_volume_with(&path, &read_budget)?,
                };
                // The file's own grid is a scene field too.
                geometry(grid.dims(), [[0.0; 3], [1.0; 3]])?;
                let is_vdb = path
                    .extension()
                    .is_some_and(|e| e.eq_ignore_ascii_case("vdb"));
                let default_up = if is_vdb { UpAxis::Y } else { UpAxis::Z };
                if up.unwrap_or(default_up) == UpAxis::Y {
                    grid = grid.y_up_to_z_up();
                }
                if let Some(b) = bounds {
                    grid = grid.clone().with_geometry(geometry(grid.dims(), *b)?)?;
                }
                if let Some(r) = resolution {
                    geometry(*r, [[0.0; 3], [1.0; 3]])?;
                    grid = resample::resample(&grid, *r)?;
                }
                grid
            }
        })
    }
}

/// A TOML error that serde could only pin to a whole table (internally tagged enums such
/// as `[volume]`, `[[lights]]` and `phase` buffer their fields and lose the spans), moved
/// to the line of the key it is about: the unknown key, or the key whose value has the
/// wrong type. `None` when the error already points at a key or the key is not found.
fn pinpoint(text: &str, error: &toml::de::Error) -> Option<String> {
    let span = error.span()?;
    let lines: Vec<&str> = text.lines().collect();
    let start_line = text.get(..span.start)?.matches('\n').count();
    let header = lines.get(start_line)?.trim_start();
    let inline = text.get(span.clone())?.trim_start().starts_with('{');
    if !header.starts_with('[') && !inline {
        return None;
    }
    let message = error.message();
    // The lines the table spans: an inline table's own text, or a section up to the next.
    let section: Vec<(usize, &str)> = if inline {
        let first = start_line;
        let last = text.get(..span.end)?.matches('\n').count();
        (first..=last).map(|l| (l, lines[l])).collect()
    } else {
        lines
            .iter()
            .enumerate()
            .skip(start_line + 1)
            .take_while(|(_, l)| !l.trim_start().starts_with('['))
            .map(|(n, l)| (n, *l))
            .collect()
    };
    let between = |m: &str, open: &str, close: char| -> Option<String> {
        let at = m.find(open)? + open.len();
        Some(m[at..].split(close).next()?.to_owned())
    };
    // Where in the section: `key =` for an unknown key, the value's text for a bad type.
    let (line, column) = if let Some(key) = between(message, "unknown field `", '`') {
        section.iter().find_map(|(n, l)| {
            let column = find_key(l, &key)?;
            Some((*n, column))
        })?
    } else if message.starts_with("invalid type:") || message.starts_with("invalid value:") {
        let shown = between(message, "\"", '"')
            .map(|v| format!("\"{v}\""))
            .or_else(|| between(message, "`", '`'))?;
        section.iter().find_map(|(n, l)| {
            let eq = l.find('=')?;
            let column = l[eq..].find(shown.as_str())? + eq;
            Some((*n, column))
        })?
    } else {
        return None;
    };
    let number = line + 1;
    let gutter = " ".repeat(number.to_string().len());
    Some(format!(
        "TOML parse error at line {number}, column {}\n{gutter} |\n{number} | {}\n{gutter} | {}^\n{message}\n",
        column + 1,
        lines[line],
        " ".repeat(column)
    ))
}

/// A key missing from one of several `[[lights]]`: the reader points at the first
/// `[[lights]]` header whichever light lacks it, so each light is read again on its own to
/// find the one, and the error points at its header.
fn light_missing_key(text: &str, error: &toml::de::Error) -> Option<String> {
    let message = error.message();
    if !message.starts_with("missing field") {
        return None;
    }
    let span = error.span()?;
    let header = text.get(span.start..)?.lines().next()?.trim();
    if header != "[[lights]]" {
        return None;
    }
    let table: toml::Table = toml::from_str(text).ok()?;
    let lights = table.get("lights")?.as_array()?;
    let index = lights.iter().position(|light| {
        light
            .clone()
            .try_into::<LightSpec>()
            .is_err_and(|e| e.to_string().contains(message))
    })?;
    let (line, shown) = text
        .lines()
        .enumerate()
        .filter(|(_, l)| l.trim() == "[[lights]]")
        .nth(index)?;
    let number = line + 1;
    let gutter = " ".repeat(number.to_string().len());
    Some(format!(
        "TOML parse error at line {number}, column 1\n{gutter} |\n{number} | {shown}\n{gutter} | {}\n{message} (light {} of {})\n",
        "^".repeat(shown.len()),
        index + 1,
        lights.len()
    ))
}

/// What a "missing field" error means in a scene's words: the table that lacks the key
/// (the reader points at the table's header, or at the file's start for a top-level key)
/// and where the keys are listed.
fn missing_key_hint(text: &str, error: &toml::de::Error) -> Option<String> {
    let field = error
        .message()
        .strip_prefix("missing field `")?
        .split('`')
        .next()?;
    let header = error
        .span()
        .and_then(|span| text.get(span.start..))
        .and_then(|rest| rest.lines().next())
        .map(str::trim)
        .filter(|line| line.starts_with('['));
    Some(match (field, header) {
        ("volume", _) => "a scene needs a `[volume]` table: where its density comes from (docs/scene-format.md lists every table and key)".to_owned(),
        (field, Some(header)) => format!(
            "`{header}` needs `{field}` (docs/scene-format.md lists each table's keys and defaults)"
        ),
        (field, None) => format!(
            "the table needs `{field}` (docs/scene-format.md lists each table's keys and defaults)"
        ),
    })
}

/// The column of `key` as a key (`key =`, `key=`, or `, key =` in an inline table) in `line`.
fn find_key(line: &str, key: &str) -> Option<usize> {
    let mut from = 0;
    while let Some(at) = line[from..].find(key).map(|a| a + from) {
        let before = line[..at].trim_end();
        let after = line[at + key.len()..].trim_start();
        let starts = before.is_empty() || before.ends_with(',') || before.ends_with('{');
        if starts && after.starts_with('=') {
            return Some(at);
        }
        from = at + key.len();
    }
    None
}

fn to_shape(spec: ShapeSpec) -> Shape {
    match spec {
        ShapeSpec::Sphere { centre, radius } => Shape::Sphere {
            centre: DVec3::from_array(centre),
            radius,
        },
        ShapeSpec::Box { min, max } => Shape::Box {
            min: DVec3::from_array(min),
            max: DVec3::from_array(max),
        },
        ShapeSpec::Torus {
            centre,
            major,
            minor,
        } => Shape::Torus {
            centre: DVec3::from_array(centre),
            major,
            minor,
        },
        ShapeSpec::Slab {
            normal,
            offset,
            thickness,
        } => Shape::Slab {
            normal: DVec3::from_array(normal),
            offset,
            thickness,
        },
    }
}

fn multiply(a: &Grid, b: &Grid) -> Grid {
    let mut out = a.clone();
    for (o, v) in out.data_mut().iter_mut().zip(b.data()) {
        *o *= v;
    }
    out
}

fn scalar_type(name: &str) -> Option<ScalarType> {
    Some(match name {
        "u8" => ScalarType::U8,
        "i8" => ScalarType::I8,
        "u16" => ScalarType::U16,
        "i16" => ScalarType::I16,
        "u32" => ScalarType::U32,
        "i32" => ScalarType::I32,
        "f32" => ScalarType::F32,
        "f64" => ScalarType::F64,
        _ => return None,
    })
}

/// The radiance behind the medium when a scene sets no `[image] background`: the sum of
/// its sky lights' radiance (linear RGB; black without a sky).
pub fn sky_background(problem: &Problem) -> [f64; 3] {
    std::array::from_fn(|c| {
        problem
            .lights()
            .iter()
            .filter(|l| matches!(l, Light::Sky { .. }))
            .map(|l| l.spectrum().channel(c))
            .sum()
    })
}

/// The camera of a scene without `[camera]`: a pinhole with a 40° field of view and +z up,
/// looking at the centre of the box `origin`..`origin + extent` from the front right
/// (+x, −y) and above, far enough that the box's circumscribed sphere fills the view's
/// height.
pub fn framing_camera(origin: DVec3, extent: DVec3) -> Camera {
    let centre = origin + 0.5 * extent;
    let radius = 0.5 * extent.length();
    let fov: f64 = 40.0;
    let distance = radius / (0.5 * fov).to_radians().sin();
    let towards_eye = DVec3::new(1.0, -0.8, 0.45).normalize();
    Camera::Pinhole {
        position: (centre + distance * towards_eye).to_array(),
        look_at: centre.to_array(),
        up: [0.0, 0.0, 1.0],
        fov,
    }
}

/// The folder of shared test volumes: `$LUCENT_DATA`, or `../shared/data/volumes`.
pub fn data_dir() -> PathBuf {
    std::env::var_os("LUCENT_DATA")
        .map_or_else(|| PathBuf::from("../shared/data/volumes"), PathBuf::from)
}

fn resolve(base: &Path, path: &str) -> PathBuf {
    match path.strip_prefix("data:") {
        Some(name) => data_dir_for(base).join(name),
        None => base.join(path),
    }
}

/// The folder of shared volumes for a scene in `base`: `$LUCENT_DATA`; else
/// `../shared/data/volumes` from the working folder where it exists; else the first
/// `shared/data/volumes` beside the scene's folder or one of its parents (a scene in a
/// clone's `examples/scenes/` finds the data beside the clone from any working folder);
/// else [`data_dir`], which the missing file's error then names.
fn data_dir_for(base: &Path) -> PathBuf {
    let default = data_dir();
    if std::env::var_os("LUCENT_DATA").is_some() || default.is_dir() {
        return default;
    }
    let base = std::fs::canonicalize(base).unwrap_or_else(|_| base.to_owned());
    base.ancestors()
        .map(|folder| folder.join("shared/data/volumes"))
        .find(|candidate| candidate.is_dir())
        .unwrap_or(default)
}
