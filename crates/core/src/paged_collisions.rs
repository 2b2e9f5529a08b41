//! The first collisions of a paged problem's lights, for solvers that add scattered light
//! out of core (the diffusion-type schemes): what [`crate::Uncollided`] and
//! [`crate::driver::Channel::diffusion_sources`] give in memory, computed slab by slab into
//! paged fields.
//!
//! Per cell and channel, with the lights routed to the uncollided light:
//!
//! - the isotropic source Q₀ = σ_s φ_sky + Σ_l s_l (σ_s/σ_t) C_l/V (power/length³), C_l the
//!   power of light l that first collides in the cell (its conservative cell integral,
//!   `UncollidedCells::collided`);
//! - its first moment Q₁ = g Σ_l s_l (σ_s/σ_t) D_l/V (when g ≠ 0 and a point-like light
//!   shines), D_l the direction-weighted collided power;
//! - the cell-averaged uncollided fluence φ_u = φ_sky + Σ_l s_l φ̄_l, which the solver adds
//!   to its scattered fluence.
//!
//! Each cell's integrals are independent of every other cell's (the faces of cells next to
//! a point light are integrated by the cell itself), so a slab of cells needs σ_t only
//! along its rays, read through the paged field's stored bricks
//! (`lucent_grid::line_integral_with` over [`lucent_paging::PagedCorners`]), and the
//! per-cell arithmetic is the in-memory one, in the same order: the fields hold the bits
//! the in-memory solve feeds its linear solver.

use glam::DVec3;
use lucent_optics::PhaseFunction;
use lucent_paging::{PagedGrid, PagingError};
use rayon::prelude::*;

use crate::direct::DirectSolver;
use crate::driver::Coefficients;
use crate::error::SolveError;
use crate::paged::{PagedProblem, PagedSolution, paging_error};
use crate::problem::Light;
use crate::solver::{Progress, SolveOptions};
use crate::uncollided::{CellValues, Integrator};

/// The first collisions of some of a paged problem's lights, per channel of the problem
/// ([`PagedProblem::first_collisions`]).
#[derive(Debug)]
pub struct PagedFirstCollisions {
    /// Q₀ per channel (power/length³), the f32 value a diffusion solver's volumetric
    /// source holds before its point sources' parts are added.
    pub sources: Vec<PagedGrid>,
    /// Q₁ per channel as x, y and z fields (power/length³); empty when g = 0 or no
    /// point-like light shines (the in-memory sources then have no first moment).
    pub first_moment: Vec<[PagedGrid; 3]>,
    /// The cell-averaged uncollided fluence per channel (W/length²), in f32 as it is added
    /// to a solver's fluence.
    pub fluence: Vec<PagedGrid>,
    /// `direct` on the same lights: per point-like light transmittance and the sky's
    /// isotropic fluence, for the renderer's single scattering.
    pub direct: PagedSolution,
}

impl PagedProblem {
    /// The first collisions of `lights` (some of the problem's; all must shine from
    /// outside the medium or be point-like or the sky: they travel in straight lines
    /// through it) for a solver named `solver`, per channel of the whole problem. Progress
    /// goes to `options` (`direct`'s march first, then the cell integrals).
    pub fn first_collisions(
        &self,
        solver: &str,
        lights: &[Light],
        options: &SolveOptions,
    ) -> Result<PagedFirstCollisions, SolveError> {
        let err = |e| paging_error(solver, e);
        let geometry = *self.geometry();
        let [nx, ny, nz] = geometry.dims();
        let medium = self.medium();
        let channels = self.channels();
        let extinction = medium.sigma_t.len();
        let g = medium.phase.mean_cosine();
        let floor = Coefficients::reduced_floor_of(&geometry);
        let volume = geometry.cell_volume();
        let cutoff = DirectSolver::default().max_optical_depth;

        let interrupt = crate::Interrupt::of(options);
        let direct = DirectSolver::default().transport_paged(
            self,
            lights,
            &options.progress_within(0.0, 0.5),
        )?;
        let pointlike: Vec<&Light> = lights.iter().filter(|l| l.is_pointlike()).collect();
        let integrators: Vec<Integrator<'_>> = pointlike
            .iter()
            .filter_map(|l| Integrator::new(&geometry, l))
            .collect();
        let moment = g != 0.0 && !pointlike.is_empty();
        let new_fields = |count: usize| -> Result<Vec<PagedGrid>, SolveError> {
            (0..count).map(|_| self.new_field().map_err(err)).collect()
        };
        let sources = new_fields(channels)?;
        let fluence = new_fields(channels)?;
        let first_moment: Vec<[PagedGrid; 3]> = if moment {
            (0..channels)
                .map(|_| Ok([self.new_field()?, self.new_field()?, self.new_field()?]))
                .collect::<Result<_, PagingError>>()
                .map_err(err)?
        } else {
            Vec::new()
        };
        let iso = &direct.isotropic_fluence;

        let mut sigma_t = vec![Vec::new(); extinction];
        let mut albedo = vec![Vec::new(); medium.albedo.len()];
        let mut sky = Vec::new();
        // Slab by slab (the layer of cells a pass holds is one slab: the cell integrals
        // of every light take 40 bytes a cell).
        for z0 in 0..nz {
            let z1 = z0 + 1;
            let n = nx * ny;
            for (field, slabs) in medium.sigma_t.iter().zip(&mut sigma_t) {
                slabs.resize(n, 0.0);
                field.read_slabs(z0, z1, slabs).map_err(err)?;
            }
            for (field, slabs) in medium.albedo.iter().zip(&mut albedo) {
                slabs.resize(n, 0.0);
                field.read_slabs(z0, z1, slabs).map_err(err)?;
            }
            // Per light and extinction channel, the slab's cell integrals.
            let cells: Vec<Vec<Vec<CellValues>>> = integrators
                .iter()
                .map(|integrator| {
                    medium
                        .sigma_t
                        .iter()
                        .zip(&sigma_t)
                        .map(|(field, sigma)| {
                            slab_cells(integrator, field, sigma, z0, cutoff, &interrupt)
                        })
                        .collect::<Result<Vec<_>, PagingError>>()
                })
                .collect::<Result<_, _>>()
                .map_err(err)?;
            interrupt.check(solver, "the paged uncollided light's cell integrals")?;
            for c in 0..channels {
                let e = c.min(extinction - 1);
                let (sigma, alb) = (&sigma_t[e], &albedo[c.min(albedo.len() - 1)]);
                let has_sky = !iso.is_empty();
                if has_sky {
                    sky.resize(n, 0.0);
                    iso[c.min(iso.len() - 1)]
                        .read_slabs(z0, z1, &mut sky)
                        .map_err(err)?;
                }
                let colours: Vec<f64> = pointlike.iter().map(|l| l.spectrum().channel(c)).collect();
                let per_cell: Vec<CellSources> = (0..n)
                    .into_par_iter()
                    .map(|i| {
                        let [s, _, _] = Coefficients::at(sigma[i], alb[i], g, floor);
                        // `Uncollided::first_collision_sources`, cell i.
                        let mut q0 = if has_sky {
                            f64::from(sky[i]) * f64::from(s)
                        } else {
                            0.0
                        };
                        let mut q1 = DVec3::ZERO;
                        for (l, colour) in colours.iter().enumerate() {
                            if sigma[i] <= 0.0 {
                                continue;
                            }
                            let scale = colour / volume;
                            let values = &cells[l][e][i];
                            let ratio = f64::from(s) / f64::from(sigma[i]);
                            q0 += scale * ratio * values.collided;
                            if moment {
                                q1 += values.directed * (g * scale * ratio);
                            }
                        }
                        // `Channel::diffusion_sources` (no emission on a paged problem) and
                        // the f32 the diffusion solvers store.
                        let source = (0.0 + f64::from(q0 as f32)) as f32;
                        // `Uncollided::fluence`, cell i, as the driver adds it.
                        let mut phi = if has_sky { f64::from(sky[i]) } else { 0.0 };
                        for (l, colour) in colours.iter().enumerate() {
                            phi += colour * cells[l][e][i].fluence;
                        }
                        CellSources {
                            source,
                            moment: q1.as_vec3().to_array(),
                            fluence: phi as f32,
                        }
                    })
                    .collect();
                let column = |f: &dyn Fn(&CellSources) -> f32| -> Vec<f32> {
                    per_cell.iter().map(f).collect()
                };
                sources[c]
                    .write_slabs(z0, &column(&|v| v.source))
                    .map_err(err)?;
                fluence[c]
                    .write_slabs(z0, &column(&|v| v.fluence))
                    .map_err(err)?;
                if moment {
                    for (axis, field) in first_moment[c].iter().enumerate() {
                        field
                            .write_slabs(z0, &column(&|v| v.moment[axis]))
                            .map_err(err)?;
                    }
                }
            }
            options.report(Progress {
                stage: "uncollided light",
                fraction: 0.5 + 0.5 * z1 as f64 / nz as f64,
                iteration: 0,
                residual: None,
            });
        }
        Ok(PagedFirstCollisions {
            sources,
            first_moment,
            fluence,
            direct,
        })
    }

    /// Bytes [`PagedProblem::first_collisions`] holds besides the pool and the fields'
    /// bookkeeping: one slab of the medium, the cell integrals of every point-like light
    /// and extinction channel on it, and the outputs' slab.
    pub fn first_collisions_slab_bytes(&self, lights: &[Light]) -> u64 {
        let [nx, ny, _] = self.geometry().dims();
        let cells = (nx * ny) as u64;
        let medium = self.medium();
        let pointlike = lights.iter().filter(|l| l.is_pointlike()).count() as u64;
        let integrals =
            pointlike * medium.sigma_t.len() as u64 * std::mem::size_of::<CellValues>() as u64;
        cells * (4 * (medium.sigma_t.len() + medium.albedo.len() + 1) as u64 + integrals + 2 * 24)
    }
}

/// One cell's sources and uncollided fluence in one channel.
struct CellSources {
    source: f32,
    moment: [f32; 3],
    fluence: f32,
}

/// The cell integrals of the cells of slab z0 (whose σ_t at cell centres is
/// `sigma`) for one light, τ read from `field`.
fn slab_cells(
    integrator: &Integrator<'_>,
    field: &PagedGrid,
    sigma: &[f32],
    z0: usize,
    cutoff: f64,
    interrupt: &crate::Interrupt,
) -> Result<Vec<CellValues>, PagingError> {
    let geometry = *field.geometry();
    let [nx, ny, _] = geometry.dims();
    let zero = CellValues {
        fluence: 0.0,
        collided: 0.0,
        directed: DVec3::ZERO,
    };
    let mut out = vec![zero; sigma.len()];
    out.par_chunks_mut(nx)
        .enumerate()
        .try_for_each(|(row, cells)| {
            // A slab of cell integrals takes seconds at 1024²: asked per row (the caller
            // asks again after the slab).
            if interrupt.halted() {
                return Ok(());
            }
            let (j, k) = (row % ny, z0 + row / ny);
            let mut corners = field.corners();
            let mut tau =
                |a, b| lucent_grid::line_integral_with(&geometry, a, b, cutoff, &mut corners);
            for (i, cell) in cells.iter_mut().enumerate() {
                let sigma = f64::from(sigma[row * nx + i]);
                *cell = integrator.cell([i, j, k], sigma, &mut tau)?;
            }
            Ok::<(), PagingError>(())
        })?;
    Ok(out)
}
