//! `gpu-direct`: `direct` on the device. One invocation per cell and light integrates the
//! optical depth τ from the light to the cell centre exactly for the trilinear σ_t
//! (`shaders/direct.wgsl`, the port of `Grid::line_integral`: a DDA over dual cells, a
//! 2-point Gauss rule per piece) and writes e^{−τ}; the sky's invocations sum
//! w_d e^{−τ_d} over the octahedral directions. The transmittance grids come back to the
//! host, where `lucent_core::uncollided_outcome` — the very code `direct` ends with —
//! turns them into fluence and the per-light [`lucent_core::LightTransmittance`] the
//! renderer weights by the phase function.
//!
//! Storage: σ_t is one dense binding where it fits; beyond the adapter's binding limit it
//! is read from a `lucent_gpu::BrickAtlas` (8³ bricks with their aprons in one buffer, a
//! software page table, constant bricks as one number), so a sparse medium whose dense grid
//! is larger than a binding still runs; the transmittance is computed and downloaded in
//! chunks of at most one binding. Both read the same f32 values with the same arithmetic:
//! the results are bit for bit those of the dense path (tested).
//!
//! Precision: τ is summed in f32 over at most n_x + n_y + n_z pieces, so its relative
//! error is about (pieces)·2⁻²⁴ ≈ 10⁻⁵ at 256³; e^{−τ} then carries an absolute error
//! of τ·10⁻⁵ relative to itself. Against `direct`'s f64 sums the transmittance agrees to
//! 10⁻⁵ relative where τ ≤ 1 (tested), and to 10⁻⁴ up to τ = 10.

use lucent_core::driver::{Context, Outcome};
use lucent_core::{DirectSolver, Light, Problem, Progress, SolveError};
use lucent_gpu::{BrickAtlas, DeviceField, GpuContext, GpuError, UniformSlots, groups_2d, shaders};
use lucent_grid::Grid;
use lucent_optics::SphericalQuadrature;

use crate::solver::device_error;

/// The uniform block of `direct.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct DirectParams {
    dims: [u32; 4],
    origin: [f32; 4],
    spacing: [f32; 4],
    light: [f32; 4],
    kind: [u32; 4],
    chunk: [u32; 4],
}

/// How the kernel reads σ_t.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(not(test), allow(dead_code))] // `Dense` and `Atlas` are chosen by the tests
pub(crate) enum SigmaStorage {
    /// The dense grid in one binding where it fits, else a brick atlas.
    Auto,
    /// One dense binding.
    Dense,
    /// A brick atlas of bricks of this edge.
    Atlas(usize),
}

/// The brick edge of the atlas `gpu-direct` builds when σ_t does not fit one binding.
const ATLAS_BRICK: usize = 8;

/// Bytes of the solve: on the host as `direct` (transmittance per point-like light and
/// extinction channel, fluence and isotropic fluence per channel, the sky's sum), and on
/// the device σ_t per extinction channel and one transmittance grid (a software adapter
/// keeps those in host memory too).
pub(crate) fn memory_bytes(problem: &Problem) -> u64 {
    let grid = problem.geometry().voxel_count() as u64 * 4;
    let extinction = problem.medium().sigma_t.len();
    let point_lights = problem
        .lights()
        .iter()
        .filter(|l| !matches!(l, Light::Sky { .. }))
        .count();
    grid * (point_lights * extinction + 2 * problem.channels() + 1 + extinction + 1) as u64
}

/// The uncollided light of every light of `context`'s problem, marched on `gpu`.
pub(crate) fn transport(
    context: &Context<'_>,
    gpu: &GpuContext,
    params: &DirectSolver,
    needed: u64,
    name: &str,
) -> Result<Outcome, SolveError> {
    transport_with(context, gpu, params, needed, name, SigmaStorage::Auto, None)
}

/// [`transport`] with σ_t read as `storage` says and the output computed in chunks of at
/// most `chunk_cells` cells (else as many as one binding holds).
pub(crate) fn transport_with(
    context: &Context<'_>,
    gpu: &GpuContext,
    params: &DirectSolver,
    needed: u64,
    name: &str,
    storage: SigmaStorage,
    chunk_cells: Option<usize>,
) -> Result<Outcome, SolveError> {
    let problem = context.problem;
    let geometry = *problem.geometry();
    let medium = problem.medium();
    let err = |e| device_error(name, e);
    let point_lights: Vec<&Light> = problem
        .lights()
        .iter()
        .filter(|l| !matches!(l, Light::Sky { .. }))
        .collect();
    let has_sky = problem
        .lights()
        .iter()
        .any(|l| matches!(l, Light::Sky { .. }));
    let quadrature = SphericalQuadrature::octahedral(params.sky_level).map_err(|e| {
        SolveError::InvalidParameter {
            name: "sky_level".into(),
            reason: e.to_string(),
        }
    })?;
    let cells = geometry.voxel_count();
    // σ_t in one binding where it fits (or as asked), else as a brick atlas: a sparse
    // medium whose dense grid is beyond the binding limit still runs. Everything is
    // checked before the first allocation.
    let dense_fits = gpu.check_binding("σ_t", cells as u64 * 4);
    let brick = match storage {
        SigmaStorage::Dense => {
            dense_fits.map_err(err)?;
            None
        }
        SigmaStorage::Auto if dense_fits.is_ok() => None,
        SigmaStorage::Auto => Some(ATLAS_BRICK),
        SigmaStorage::Atlas(b) => Some(b),
    };
    let sigma = match brick {
        None => Sigma::Dense(
            medium
                .sigma_t
                .iter()
                .enumerate()
                .map(|(c, g)| DeviceField::from_grid(gpu, &format!("sigma_t[{c}]"), g, true))
                .collect::<Result<_, _>>()
                .map_err(err)?,
        ),
        Some(b) => Sigma::Atlas(
            medium
                .sigma_t
                .iter()
                .enumerate()
                .map(|(c, g)| atlas_of(gpu, &format!("sigma_t[{c}]"), g, b))
                .collect::<Result<_, _>>()
                .map_err(err)?,
        ),
    };
    let kernel = match brick {
        None => gpu.kernel("direct.wgsl", shaders::DIRECT, "transmit"),
        Some(_) => gpu.kernel(
            "direct.wgsl + sigma_atlas.wgsl",
            shaders::DIRECT_ATLAS,
            "transmit",
        ),
    }
    .map_err(err)?;
    let sky_directions: Vec<[f32; 4]> = if has_sky {
        quadrature
            .directions()
            .iter()
            .zip(quadrature.weights())
            .map(|(d, w)| [d.x as f32, d.y as f32, d.z as f32, *w as f32])
            .collect()
    } else {
        vec![[0.0; 4]]
    };
    let sky = DeviceField::upload(
        gpu,
        "sky directions",
        bytemuck::cast_slice(&sky_directions),
        false,
    )
    .map_err(err)?;
    // The output in chunks of whole cells, each within one binding.
    let per_binding = (gpu.limits().max_storage_buffer_binding_size / 4).max(1) as usize;
    let chunk = chunk_cells
        .unwrap_or(per_binding)
        .clamp(1, per_binding)
        .min(cells);
    let chunks: Vec<(usize, usize)> = (0..cells)
        .step_by(chunk)
        .map(|first| (first, chunk.min(cells - first)))
        .collect();
    let out = DeviceField::zeros(gpu, "transmittance", chunk).map_err(err)?;

    let dims = geometry.dims();
    let base = DirectParams {
        dims: [dims[0] as u32, dims[1] as u32, dims[2] as u32, 0],
        origin: {
            let o = geometry.origin();
            [
                o.x as f32,
                o.y as f32,
                o.z as f32,
                params.max_optical_depth as f32,
            ]
        },
        spacing: {
            let h = geometry.spacing();
            [h.x as f32, h.y as f32, h.z as f32, 0.0]
        },
        light: [0.0; 4],
        kind: [0, 0, brick.unwrap_or(0) as u32, 0],
        chunk: [0; 4],
    };
    // One slot per point-like light, then the sky; each repeated per chunk.
    let mut per_light: Vec<DirectParams> = point_lights
        .iter()
        .map(|light| {
            let (kind, v) = match light {
                Light::Directional { direction, .. } => (0, direction.normalize()),
                Light::Point { position, .. } | Light::Spot { position, .. } => (1, *position),
                _ => (1, glam::DVec3::ZERO),
            };
            DirectParams {
                light: [v.x as f32, v.y as f32, v.z as f32, 0.0],
                kind: [kind, 0, base.kind[2], 0],
                ..base
            }
        })
        .collect();
    per_light.push(DirectParams {
        kind: [
            2,
            sky_directions.len() as u32 * u32::from(has_sky),
            base.kind[2],
            0,
        ],
        ..base
    });
    let mut slots = Vec::with_capacity(per_light.len() * chunks.len());
    for light in &per_light {
        for &(first, len) in &chunks {
            let groups = groups_2d(gpu, len as u64, 64);
            slots.push(DirectParams {
                dims: [base.dims[0], base.dims[1], base.dims[2], groups[0]],
                chunk: [first as u32, len as u32, 0, 0],
                ..*light
            });
        }
    }
    let uniforms = UniformSlots::new(gpu, "direct params", &slots).map_err(err)?;

    let work = (point_lights.len() + usize::from(has_sky)).max(1) as f64;
    let mut done = 0.0;
    // One dispatch per light, extinction channel and chunk, one download each.
    let march = |light: usize, channel: usize| -> Result<Grid, SolveError> {
        let mut values = Vec::with_capacity(cells);
        for (n, &(_, len)) in chunks.iter().enumerate() {
            let slot = uniforms.slot(light * chunks.len() + n);
            let bind = match &sigma {
                Sigma::Dense(fields) => kernel.bind(
                    gpu,
                    &[
                        fields[channel].binding(),
                        sky.binding(),
                        out.binding(),
                        slot,
                    ],
                ),
                Sigma::Atlas(atlases) => kernel.bind(
                    gpu,
                    &[
                        atlases[channel].atlas(),
                        sky.binding(),
                        out.binding(),
                        slot,
                        atlases[channel].table(),
                    ],
                ),
            }
            .map_err(err)?;
            let groups = groups_2d(gpu, len as u64, 64);
            gpu.submit_pass("gpu-direct", |pass| kernel.dispatch(pass, &bind, groups))
                .map_err(err)?;
            values.extend(out.download_prefix(gpu, len).map_err(err)?);
        }
        Grid::from_vec(geometry, values).map_err(|e| SolveError::InvalidParameter {
            name: "grid".into(),
            reason: e.to_string(),
        })
    };
    let mut per_light = Vec::with_capacity(point_lights.len());
    for slot in 0..point_lights.len() {
        let grids = (0..medium.sigma_t.len())
            .map(|c| march(slot, c))
            .collect::<Result<Vec<_>, _>>()?;
        per_light.push(grids);
        done += 1.0;
        context.report(Progress {
            stage: "light transmittance",
            fraction: done / work,
            iteration: 0,
            residual: None,
        });
    }
    let sky_transmittance = if has_sky {
        let grids = (0..medium.sigma_t.len())
            .map(|c| march(point_lights.len(), c))
            .collect::<Result<Vec<_>, _>>()?;
        context.report(Progress {
            stage: "sky transmittance",
            fraction: 1.0,
            iteration: 0,
            residual: None,
        });
        Some(grids)
    } else {
        None
    };
    Ok(lucent_core::uncollided_outcome(
        problem,
        &point_lights,
        per_light,
        sky_transmittance,
        needed,
    ))
}

/// σ_t on the device, per extinction channel.
enum Sigma {
    Dense(Vec<DeviceField>),
    Atlas(Vec<BrickAtlas>),
}

/// `grid` as a brick atlas of `brick`³ bricks, built through the host pager (bricks in
/// memory: the problem is in memory already; a pool of 64 bricks).
fn atlas_of(
    gpu: &GpuContext,
    what: &str,
    grid: &Grid,
    brick: usize,
) -> Result<BrickAtlas, GpuError> {
    let source = |e: lucent_paging::PagingError| GpuError::Source {
        what: what.to_owned(),
        reason: e.to_string(),
    };
    let layout =
        lucent_grid::BrickLayout::new(grid.dims(), brick).map_err(|e| GpuError::Source {
            what: what.to_owned(),
            reason: e.to_string(),
        })?;
    // The atlas's size first (one pass over the bricks, nothing stored): a dense medium
    // too large for one binding is refused by the limit's name before any copy is made.
    let geometry = *grid.geometry();
    let value = |c: [usize; 3]| grid.data()[geometry.index(c[0], c[1], c[2])];
    let stored = {
        use rayon::prelude::*;
        (0..layout.count())
            .into_par_iter()
            .filter(|&id| {
                let values = layout.gather(id, value);
                values.iter().any(|v| v.to_bits() != values[0].to_bits())
            })
            .count()
    };
    gpu.check_binding(
        &format!("{what} (brick atlas of {stored} stored bricks)"),
        (stored * layout.stored_len()) as u64 * 4,
    )?;
    let pager = std::sync::Arc::new(
        lucent_paging::Pager::new(
            Box::new(lucent_paging::MemoryStore::default()),
            0,
            layout.stored_len(),
            1,
            lucent_paging::PagerOptions {
                budget_bytes: 64 * 4 * layout.stored_len() as u64,
                eviction: lucent_paging::Eviction::Lru,
                fill: 0.0,
            },
        )
        .map_err(source)?,
    );
    let field = lucent_paging::PagedGrid::from_grid(pager, grid, brick).map_err(source)?;
    BrickAtlas::upload(gpu, what, &field, true)
}

#[cfg(test)]
mod tests {
    use glam::DVec3;
    use lucent_core::{Angular, Boundary, Field, Medium, Solution, SolveOptions, Spectrum, driver};
    use lucent_grid::GridGeometry;
    use lucent_optics::Phase;

    use super::*;
    use crate::GpuSolver;

    fn solve(problem: &Problem, storage: SigmaStorage, chunk: Option<usize>) -> Option<Solution> {
        let gpu = lucent_gpu::context_or_skip("gpu-direct storage").map(Box::new)?;
        let gpu: &'static GpuContext = Box::leak(gpu);
        let solver = (GpuSolver::GPU_DIRECT.build)(&Default::default()).unwrap();
        let params = DirectSolver::default();
        let needed = memory_bytes(problem);
        Some(
            driver::run(
                solver.as_ref(),
                problem,
                &SolveOptions::default(),
                needed,
                |context| {
                    transport_with(context, gpu, &params, needed, "gpu-direct", storage, chunk)
                },
            )
            .unwrap(),
        )
    }

    /// σ_t from a brick atlas (bricks of 4 and 8 cells on a grid of 13 × 9 × 11, half of
    /// it empty so constant and stored bricks both occur) and an output computed in chunks
    /// of 97 cells give the dense binding's result bit for bit: the kernel reads the same
    /// f32 values and does the same arithmetic.
    #[test]
    fn an_atlas_and_chunks_give_the_dense_result_bit_for_bit() {
        let geometry =
            GridGeometry::new([13, 9, 11], DVec3::new(0.1, 0.12, 0.09), DVec3::ZERO).unwrap();
        let sigma = Grid::from_fn(geometry, |p| {
            if p.x < 0.6 {
                0.0
            } else {
                (2.0 + 5.0 * (3.0 * p.y).sin().abs() + p.z) as f32
            }
        });
        let medium = Medium {
            sigma_t: vec![sigma],
            albedo: vec![Field::Constant(0.8)],
            phase: Phase::Isotropic,
        };
        let lights = vec![
            Light::Point {
                position: DVec3::new(-0.3, 0.5, 0.4),
                intensity: Spectrum::Grey(1.0),
            },
            Light::Directional {
                direction: DVec3::new(-0.6, 0.3, -0.74).normalize(),
                irradiance: Spectrum::Grey(2.0),
            },
            Light::Sky {
                radiance: Spectrum::Grey(0.5),
            },
        ];
        let problem = Problem::new(geometry, medium, lights, Boundary::Vacuum, None).unwrap();
        let Some(dense) = solve(&problem, SigmaStorage::Dense, None) else {
            return;
        };
        let bits = |s: &Solution| -> Vec<u32> {
            let mut out: Vec<u32> = s.fluence[0].data().iter().map(|v| v.to_bits()).collect();
            if let Some(Angular::Lights(l)) = &s.angular {
                for grids in &l.transmittance {
                    out.extend(grids[0].data().iter().map(|v| v.to_bits()));
                }
                out.extend(l.isotropic_fluence[0].data().iter().map(|v| v.to_bits()));
            }
            out
        };
        let reference = bits(&dense);
        assert!(dense.fluence[0].data().iter().any(|&v| v > 0.0));
        for (storage, chunk) in [
            (SigmaStorage::Atlas(4), None),
            (SigmaStorage::Atlas(8), Some(97)),
            (SigmaStorage::Dense, Some(100)),
        ] {
            let other = solve(&problem, storage, chunk).unwrap();
            assert!(bits(&other) == reference, "{storage:?} chunks {chunk:?}");
        }
    }
}
