//! The ray march of [`crate::render`] on a GPU (`shaders/render.wgsl`, feature `gpu`).
//!
//! One invocation per pixel, one dispatch per channel and band of rows. The kernel is a
//! port of the CPU march: the same jittered step ends, the same per-step exact
//! integration, the same trilinear sampling (clamped to cell centres, the same order of
//! lerps), the same in-scattering (isotropic fluence, per-light transmittance with the
//! phase function, discrete ordinates with the κ-kernel) and emission, and the same
//! opacity cut-off. It differs in arithmetic only: f32 on the device where the CPU sums in
//! f64.
//!
//! Precision: a march of N steps accumulates radiance and transmittance in f32, so each
//! carries a relative rounding error of about N·2⁻²⁴ (10⁻⁵ for the ~200 steps across a
//! 64³ grid at half-cell steps); positions are f32 too, which moves sample points by 10⁻⁷
//! of the box size. On the tests' scenes (every class of solution the renderer reads) the
//! images agree with the CPU's to 2.3·10⁻⁶ of the image's largest value per pixel
//! (asserted at 10⁻⁵). A march that ends at the 10⁻⁴ opacity cut-off one step earlier or
//! later than the CPU's differs by at most 10⁻⁴ of the light behind that point.
//!
//! Limits: the device holds the medium (σ_t and albedo per channel), one isotropic and
//! one emission grid per channel, the lights' transmittance grids and the image (RGB f32).
//! Each binding must fit the adapter's `max_storage_buffer_binding_size` (lavapipe:
//! 128 MiB): lights whose transmittance grids do not fit one binding are split into
//! several passes that add up; a single grid, a discrete-ordinates field (cells ×
//! directions) or an image beyond one binding is refused with the limit's name before
//! anything is allocated.

use glam::DVec3;
use lucent_core::{Angular, Light, Problem, Solution};
use lucent_gpu::{DeviceField, DeviceMedium, GpuContext, GpuError, UniformSlots, groups_2d};
use lucent_grid::Grid;
use lucent_optics::Phase;

use crate::RenderError;
use crate::camera::Camera;
use crate::image_io::Image;
use crate::march::{MarchSetup, RenderSettings};

/// Invocations per workgroup of `render.wgsl` (a ray march diverges: small groups).
const GROUP: u32 = 64;
/// Pixels per dispatch: a band of rows this large keeps one dispatch well inside a
/// desktop driver's watchdog (about 2 s) and gives progress reports.
const BAND_PIXELS: usize = 1 << 16;

/// The uniform block of `render.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct RenderParams {
    dims: [u32; 4],
    image: [u32; 4],
    counts: [u32; 4],
    outputs: [u32; 4],
    channel: [u32; 4],
    origin: [f32; 4],
    inv_spacing: [f32; 4],
    box_lo: [f32; 4],
    box_hi: [f32; 4],
    eye: [f32; 4],
    right: [f32; 4],
    up: [f32; 4],
    forward: [f32; 4],
    background: [f32; 4],
    phase: [f32; 4],
    lighting: [f32; 4],
}

const FLAG_ISO: u32 = 1;
const FLAG_EMISSION: u32 = 2;
const FLAG_ORDINATES: u32 = 4;

fn device(e: GpuError) -> RenderError {
    RenderError::Device {
        unavailable: matches!(e, GpuError::NoAdapter { .. } | GpuError::Unsupported { .. }),
        reason: e.to_string(),
    }
}

fn v4(v: DVec3, w: f32) -> [f32; 4] {
    [v.x as f32, v.y as f32, v.z as f32, w]
}

/// [`crate::render`] on the device of `gpu`: the same image within f32 rounding (see the
/// module's *Precision*). `progress` is called with the fraction of rows done.
///
/// Errors: the CPU renderer's for the camera and the settings; [`RenderError::Device`]
/// for a grid, an ordinates field or an image beyond one of the adapter's bindings (by
/// the limit's name, before allocation), a NaN or infinity in the solution, or a device
/// failure; [`RenderError::Invalid`] for a solution whose grids are not on the problem's.
pub fn render_on_device(
    gpu: &GpuContext,
    problem: &Problem,
    solution: &Solution,
    camera: &Camera,
    settings: &RenderSettings,
    progress: Option<&(dyn Fn(f64) + Sync)>,
) -> Result<Image, RenderError> {
    let split = Split {
        band_pixels: BAND_PIXELS,
        lights_per_pass: None,
    };
    march(gpu, problem, solution, camera, settings, progress, split)
}

/// How the work is cut: pixels per band, and lights per pass (`None`: as many as one
/// binding holds). Tests cut finer than the adapter needs, to exercise every path.
#[derive(Debug, Clone, Copy)]
struct Split {
    band_pixels: usize,
    lights_per_pass: Option<usize>,
}

fn march(
    gpu: &GpuContext,
    problem: &Problem,
    solution: &Solution,
    camera: &Camera,
    settings: &RenderSettings,
    progress: Option<&(dyn Fn(f64) + Sync)>,
    split: Split,
) -> Result<Image, RenderError> {
    let setup = MarchSetup::new(problem, solution, camera, settings)?;
    let geometry = *problem.geometry();
    let cells = geometry.voxel_count();
    let channels = setup.channels;

    // What the march reads besides the medium, per channel, on the problem's grid.
    let sources = Sources::of(problem, solution, channels)?;
    let bytes = |n: usize| n as u64 * 4;
    // Everything checked against the bindings before the first allocation.
    gpu.check_binding("one grid of the medium", bytes(cells))
        .map_err(device)?;
    gpu.check_binding("the image (RGB f32)", bytes(setup.pixels * 3))
        .map_err(device)?;
    if let Some(ordinates) = &sources.ordinates {
        gpu.check_binding(
            "the discrete-ordinates in-scattered radiance of one channel",
            bytes(cells * ordinates.directions.len()),
        )
        .map_err(device)?;
    }
    let per_binding = split
        .lights_per_pass
        .unwrap_or((gpu.limits().max_storage_buffer_binding_size / bytes(cells)).max(1) as usize);

    let medium = DeviceMedium::upload(gpu, problem).map_err(device)?;
    let unused = DeviceField::zeros(gpu, "unused", 1).map_err(device)?;
    let upload = |what: String, values: &[f32]| {
        DeviceField::upload(gpu, &what, values, false).map_err(device)
    };
    let iso: Vec<Option<DeviceField>> = sources
        .iso
        .iter()
        .enumerate()
        .map(|(c, &g)| {
            g.map(|g| upload(format!("isotropic fluence[{c}]"), g.data()))
                .transpose()
        })
        .collect::<Result<_, _>>()?;
    let emission: Vec<Option<DeviceField>> = sources
        .emission
        .iter()
        .enumerate()
        .map(|(c, g)| {
            g.as_ref()
                .map(|g| upload(format!("emission[{c}]"), g))
                .transpose()
        })
        .collect::<Result<_, _>>()?;
    let ordinates: Vec<Option<DeviceField>> = (0..channels)
        .map(|c| {
            sources
                .ordinates
                .as_ref()
                .map(|o| {
                    upload(
                        format!("ordinates[{c}]"),
                        &o.inscattered[c.min(o.inscattered.len() - 1)],
                    )
                })
                .transpose()
        })
        .collect::<Result<_, _>>()?;

    // The lights' records and their transmittance, grouped so each group fits a binding.
    let lights = sources.lights.map(|l| (&l.lights, &l.transmittance));
    let (light_list, light_grids) = match lights {
        Some((l, t)) => (l.as_slice(), t.as_slice()),
        None => (&[][..], &[][..]),
    };
    let mut records: Vec<[f32; 4]> = sources
        .ordinates
        .map(|o| o.directions.iter().map(|d| v4(*d, 0.0)).collect())
        .unwrap_or_default();
    let first_light_record = records.len() as u32;
    for light in light_list {
        records.extend(light_records(light));
    }
    if records.is_empty() {
        records.push([0.0; 4]);
    }
    let records = DeviceField::upload(gpu, "light records", bytemuck::cast_slice(&records), false)
        .map_err(device)?;
    let groups: Vec<std::ops::Range<usize>> = (0..light_list.len())
        .step_by(per_binding)
        .map(|g| g..(g + per_binding).min(light_list.len()))
        .collect();
    // transmittance[channel][group]: the group's grids of that extinction channel, packed.
    let transmittance: Vec<Vec<DeviceField>> = (0..channels)
        .map(|c| {
            groups
                .iter()
                .map(|range| {
                    let mut packed = Vec::with_capacity(range.len() * cells);
                    for grids in &light_grids[range.clone()] {
                        packed.extend_from_slice(grids[c.min(grids.len() - 1)].data());
                    }
                    upload(format!("light transmittance[{c}]"), &packed)
                })
                .collect()
        })
        .collect::<Result<_, _>>()?;
    let out = DeviceField::zeros(gpu, "image", setup.pixels * 3).map_err(device)?;

    // One uniform slot per band, channel and pass.
    let frame = camera.frame()?;
    let (kind, half) = match *camera {
        Camera::Pinhole { fov, .. } => (0, (0.5 * fov.to_radians()).tan()),
        Camera::Orthographic { height, .. } => (1, 0.5 * height),
    };
    let dims = geometry.dims();
    let h = geometry.spacing();
    let diagonal = (setup.hi - setup.lo).length();
    let max_steps = (diagonal / setup.step).ceil() as u32 + 3;
    let (floor_r2, phase) = (
        sources.min_distance * sources.min_distance,
        phase_params(&problem.medium().phase, sources.phase),
    );
    let rows_per_band = (split.band_pixels / settings.width).max(1);
    let bands: Vec<(usize, usize)> = (0..settings.height)
        .step_by(rows_per_band)
        .map(|row| (row, rows_per_band.min(settings.height - row)))
        .collect();
    let passes = groups.len().max(1);
    let mut slots = Vec::with_capacity(bands.len() * channels * passes);
    for &(row, rows) in &bands {
        let band_pixels = rows * settings.width;
        let groups_xy = groups_2d(gpu, band_pixels as u64, GROUP);
        for c in 0..channels {
            let last_output = if c + 1 == channels { 2 } else { c as u32 };
            for pass in 0..passes {
                let lights = groups.get(pass).map_or(0..0, Clone::clone);
                let mut flags = 0;
                if pass == 0 {
                    for (present, flag) in [
                        (iso[c].is_some(), FLAG_ISO),
                        (emission[c].is_some(), FLAG_EMISSION),
                        (ordinates[c].is_some(), FLAG_ORDINATES),
                    ] {
                        if present {
                            flags |= flag;
                        }
                    }
                }
                slots.push(RenderParams {
                    dims: [dims[0] as u32, dims[1] as u32, dims[2] as u32, groups_xy[0]],
                    image: [
                        settings.width as u32,
                        settings.height as u32,
                        row as u32,
                        band_pixels as u32,
                    ],
                    counts: [
                        lights.len() as u32,
                        sources.ordinates.map_or(0, |o| o.directions.len() as u32),
                        flags,
                        first_light_record + 4 * lights.start as u32,
                    ],
                    outputs: [c as u32, last_output, u32::from(pass > 0), kind],
                    channel: [c as u32, max_steps, 0, 0],
                    origin: v4(geometry.origin(), setup.step as f32),
                    inv_spacing: v4(h.recip(), setup.aspect as f32),
                    box_lo: v4(setup.lo, sources.ordinates.map_or(0.0, |o| o.kernel as f32)),
                    box_hi: v4(setup.hi, 0.0),
                    eye: v4(frame.origin, half as f32),
                    right: v4(frame.right, 0.0),
                    up: v4(frame.up, 0.0),
                    forward: v4(frame.forward, 0.0),
                    background: {
                        let b = setup.background;
                        [b[0] as f32, b[1] as f32, b[2] as f32, 0.0]
                    },
                    phase,
                    lighting: [0.0, floor_r2.max(1e-30) as f32, 0.0, 0.0],
                });
            }
        }
    }
    let uniforms = UniformSlots::new(gpu, "render params", &slots).map_err(device)?;
    let kernel = gpu
        .kernel("render.wgsl", lucent_gpu::shaders::RENDER, "march")
        .map_err(device)?;
    // One bind group per channel and pass (the band only changes the uniform slot).
    let mut binds = Vec::with_capacity(slots.len());
    for (band, _) in bands.iter().enumerate() {
        for c in 0..channels {
            for pass in 0..passes {
                let slot = (band * channels + c) * passes + pass;
                binds.push(
                    kernel
                        .bind(
                            gpu,
                            &[
                                medium.sigma_t[c.min(medium.sigma_t.len() - 1)].binding(),
                                medium.albedo[c.min(medium.albedo.len() - 1)].binding(),
                                field(&iso[c], &unused).binding(),
                                field(&emission[c], &unused).binding(),
                                transmittance[c].get(pass).unwrap_or(&unused).binding(),
                                records.binding(),
                                field(&ordinates[c], &unused).binding(),
                                out.binding(),
                                uniforms.slot(slot),
                            ],
                        )
                        .map_err(device)?,
                );
            }
        }
    }
    let mut rows_done = 0;
    for (band, &(_, rows)) in bands.iter().enumerate() {
        let groups_xy = groups_2d(gpu, (rows * settings.width) as u64, GROUP);
        let per_band = channels * passes;
        gpu.submit_pass("render", |pass| {
            for bind in &binds[band * per_band..(band + 1) * per_band] {
                kernel.dispatch(pass, bind, groups_xy);
            }
        })
        .map_err(device)?;
        gpu.wait().map_err(device)?;
        rows_done += rows;
        if let Some(callback) = progress {
            callback(rows_done as f64 / settings.height as f64);
        }
    }
    let values = out.download(gpu).map_err(device)?;
    Ok(Image {
        width: settings.width,
        height: settings.height,
        pixels: values.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect(),
    })
}

/// [`render_on_device`] on the process's shared device (`GpuContext::shared`).
pub fn render_gpu(
    problem: &Problem,
    solution: &Solution,
    camera: &Camera,
    settings: &RenderSettings,
    progress: Option<&(dyn Fn(f64) + Sync)>,
) -> Result<Image, RenderError> {
    let gpu = GpuContext::shared().map_err(device)?;
    render_on_device(gpu, problem, solution, camera, settings, progress)
}

/// `f`, or the placeholder bound where a pass reads nothing.
fn field<'a>(f: &'a Option<DeviceField>, unused: &'a DeviceField) -> &'a DeviceField {
    f.as_ref().unwrap_or(unused)
}

/// The solution and the problem's emission, sorted by how the march reads them.
struct Sources<'a> {
    /// Per channel: the grid whose value/(4π) in-scatters isotropically, if any.
    iso: Vec<Option<&'a Grid>>,
    /// Per channel: Σ_e s_e(c) Q_e, if the problem has emission lights.
    emission: Vec<Option<Vec<f32>>>,
    /// The point-like lights with their transmittance, if the solution keeps them.
    lights: Option<&'a lucent_core::LightTransmittance>,
    /// Discrete-ordinate in-scattered radiance, if the solution has it.
    ordinates: Option<&'a lucent_core::OrdinateRadiance>,
    /// The phase function the solution's lights in-scatter with.
    phase: Option<&'a Phase>,
    /// The floor on a point light's distance.
    min_distance: f64,
}

impl<'a> Sources<'a> {
    fn of(problem: &Problem, solution: &'a Solution, channels: usize) -> Result<Self, RenderError> {
        let geometry = problem.geometry();
        let on_grid = |g: &Grid, what: &str| {
            if g.geometry() == geometry {
                Ok(())
            } else {
                Err(RenderError::Invalid(format!(
                    "the solution's {what} is not on the problem's grid"
                )))
            }
        };
        let pick = |grids: &'a [Grid], c: usize| grids.get(c.min(grids.len().max(1) - 1));
        let (iso, lights, ordinates): (Vec<Option<&Grid>>, _, _) = match &solution.angular {
            None => (
                (0..channels).map(|c| pick(&solution.fluence, c)).collect(),
                None,
                None,
            ),
            Some(Angular::Lights(l)) => (
                (0..channels)
                    .map(|c| pick(&l.isotropic_fluence, c))
                    .collect(),
                Some(l),
                None,
            ),
            Some(Angular::Ordinates(o)) => {
                if o.geometry != *geometry {
                    return Err(RenderError::Invalid(
                        "the solution's discrete ordinates are not on the problem's grid".into(),
                    ));
                }
                if o.directions.is_empty() || o.inscattered.is_empty() {
                    return Err(RenderError::Invalid(
                        "the solution's discrete ordinates hold no directions".into(),
                    ));
                }
                (vec![None; channels], o.lights.as_ref(), Some(o))
            }
        };
        if lights.is_some_and(|l| !l.arrivals.is_empty()) {
            return Err(RenderError::Invalid(
                "the solution's light arrives along curved rays (direct-refractive), which the GPU renderer does not read: render on the CPU".into(),
            ));
        }
        for g in iso.iter().flatten() {
            on_grid(g, "fluence")?;
        }
        if let Some(l) = lights {
            for grids in &l.transmittance {
                if grids.is_empty() {
                    return Err(RenderError::Invalid(
                        "a light of the solution has no transmittance grid".into(),
                    ));
                }
                for g in grids {
                    on_grid(g, "light transmittance")?;
                }
            }
            if l.transmittance.len() != l.lights.len() {
                return Err(RenderError::Invalid(
                    "the solution's lights and transmittance grids differ in number".into(),
                ));
            }
        }
        let glow: Vec<(&Grid, &lucent_core::Spectrum)> = problem
            .lights()
            .iter()
            .filter_map(|l| match l {
                Light::Emission { grid, scale } => Some((grid, scale)),
                _ => None,
            })
            .collect();
        let emission = (0..channels)
            .map(|c| {
                (!glow.is_empty()).then(|| {
                    (0..geometry.voxel_count())
                        .map(|i| {
                            glow.iter()
                                .map(|(g, s)| s.channel(c) * f64::from(g.data()[i]))
                                .sum::<f64>() as f32
                        })
                        .collect()
                })
            })
            .collect();
        Ok(Self {
            iso,
            emission,
            lights,
            ordinates,
            phase: lights.map(|l| &l.phase),
            min_distance: lights.map_or(0.0, |l| l.min_distance),
        })
    }
}

/// The 4 records of a point-like light (see `render.wgsl`).
fn light_records(light: &Light) -> [[f32; 4]; 4] {
    let spectrum = light.spectrum();
    let rgb = [
        spectrum.channel(0) as f32,
        spectrum.channel(1) as f32,
        spectrum.channel(2) as f32,
        0.0,
    ];
    match *light {
        Light::Directional { direction, .. } => [v4(direction, 0.0), [0.0; 4], [0.0; 4], rgb],
        Light::Spot {
            position,
            direction,
            inner_angle,
            outer_angle,
            ..
        } => [
            v4(position, 2.0),
            v4(direction, 0.0),
            [inner_angle.cos() as f32, outer_angle.cos() as f32, 0.0, 0.0],
            rgb,
        ],
        Light::Point { position, .. } => [v4(position, 1.0), [0.0; 4], [0.0; 4], rgb],
        // Sky and emission never carry transmittance grids; a record of zero spectrum.
        Light::Sky { .. } | Light::Emission { .. } => {
            [[0.0, 0.0, 1.0, 0.0], [0.0; 4], [0.0; 4], [0.0; 4]]
        }
    }
}

/// (g₁, g₂, weight of the first lobe, Rayleigh) of the phase function the lights
/// in-scatter with (the solution's, else the medium's).
fn phase_params(medium: &Phase, solution: Option<&Phase>) -> [f32; 4] {
    match solution.unwrap_or(medium) {
        Phase::Isotropic => [0.0, 0.0, 1.0, 0.0],
        Phase::HenyeyGreenstein(hg) => [hg.g() as f32, hg.g() as f32, 1.0, 0.0],
        Phase::DoubleHenyeyGreenstein(d) => {
            let (g1, g2, weight) = d.lobes();
            [g1 as f32, g2 as f32, weight as f32, 0.0]
        }
        Phase::Rayleigh => [0.0, 0.0, 1.0, 1.0],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lucent_core::{
        Boundary, Field, LightTransmittance, Medium, SolveReport, Spectrum, StopReason,
    };
    use lucent_grid::GridGeometry;

    /// Cutting the image into bands of a few rows (a band ending mid-row) and the lights
    /// into one pass each gives the image of one band and one pass, to f32 rounding: the
    /// passes add their radiance in another order (relative 10⁻⁶; 10⁻⁵ allowed).
    #[test]
    fn bands_and_light_passes_add_up_to_one_march() {
        let Some(gpu) = lucent_gpu::context_or_skip("bands_and_light_passes_add_up_to_one_march")
        else {
            return;
        };
        let g = GridGeometry::new([7, 10, 6], DVec3::splat(0.1), DVec3::ZERO).unwrap();
        let sigma = Grid::from_fn(g, |p| (1.0 + 3.0 * p.x + 2.0 * p.y * p.z) as f32);
        let lights: Vec<Light> = (0..3)
            .map(|i| Light::Point {
                position: DVec3::new(-0.5 + 0.6 * i as f64, 1.5, 0.8),
                intensity: Spectrum::Grey(1.0 + i as f64),
            })
            .collect();
        let medium = Medium {
            sigma_t: vec![sigma],
            albedo: vec![Field::Constant(0.7)],
            phase: Phase::henyey_greenstein(0.3).unwrap(),
        };
        let problem = Problem::new(g, medium, lights.clone(), Boundary::Vacuum, None).unwrap();
        let solution = Solution {
            fluence: vec![Grid::filled(g, 1.0)],
            angular: Some(Angular::Lights(LightTransmittance {
                phase: Phase::henyey_greenstein(0.3).unwrap(),
                transmittance: (0..3)
                    .map(|i| {
                        vec![Grid::from_fn(g, move |p| {
                            (-(p.x + 0.3 * i as f64)).exp() as f32
                        })]
                    })
                    .collect(),
                lights,
                far: 100.0,
                min_distance: 0.05,
                isotropic_fluence: vec![Grid::filled(g, 0.5)],
                arrivals: Vec::new(),
            })),
            standard_error: None,
            report: SolveReport {
                solver: "test".into(),
                iterations: 0,
                residual_history: vec![],
                wall_time_s: 0.0,
                peak_memory_bytes: 0,
                measured_peak_bytes: None,
                paging: None,
                choice: None,
                composition: None,
                stop_reason: StopReason::Exact,
            },
        };
        let camera = Camera::Pinhole {
            position: [1.5, -1.5, 1.2],
            look_at: [0.35, 0.5, 0.3],
            up: [0.0, 0.0, 1.0],
            fov: 45.0,
        };
        let settings = RenderSettings {
            width: 19,
            height: 13,
            step: 0.5,
            background: Some([0.1, 0.2, 0.3]),
        };
        let whole = Split {
            band_pixels: BAND_PIXELS,
            lights_per_pass: None,
        };
        let cut = Split {
            band_pixels: 50,
            lights_per_pass: Some(1),
        };
        let reports = std::sync::Mutex::new(Vec::new());
        let record = |f: f64| reports.lock().unwrap().push(f);
        let one = march(&gpu, &problem, &solution, &camera, &settings, None, whole).unwrap();
        let many = march(
            &gpu,
            &problem,
            &solution,
            &camera,
            &settings,
            Some(&record),
            cut,
        )
        .unwrap();
        let peak = one.pixels.iter().flatten().fold(0f32, |m, v| m.max(*v));
        assert!(peak > 0.0);
        for (a, b) in one.pixels.iter().zip(&many.pixels) {
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() <= 1e-5 * peak, "{a:?} vs {b:?}");
            }
        }
        // 50 pixels of 19 make bands of 2 rows: 7 bands, progress ending at 1.
        let reports = reports.into_inner().unwrap();
        assert_eq!(reports.len(), 7);
        assert_eq!(reports.last(), Some(&1.0));
    }
}
