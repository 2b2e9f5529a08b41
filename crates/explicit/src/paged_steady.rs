//! `ftcs-diffusion` and `jacobi-diffusion` on a paged medium (`lucent_core::PagedProblem`):
//! the same iterations on the same discrete system as in memory, with every field streamed
//! slab by slab.
//!
//! In memory these schemes assemble `diffusion-mg`'s system A φ = b as a sparse matrix (600
//! bytes per cell) and sweep it. Out of core nothing is assembled:
//!
//! 1. the lights that shine from outside the medium become first-collision sources and an
//!    uncollided fluence, paged (`PagedProblem::first_collisions`, the in-memory driver's
//!    arithmetic);
//! 2. per channel, one pass computes D and the diagonal's non-coupling part per cell from
//!    σ_t and the albedo (`driver::Coefficients::at`), point lights inside the medium get
//!    their singular part from a window of cells around them
//!    (`point_source_singular_cells`), and a second pass builds b slab by slab from
//!    windows of three slabs (`lucent_diffusion::SlabSystem`, whose rows and right-hand
//!    side are the assembled matrix's bits);
//! 3. each iteration is one pass over z that updates φ on slab z and the residual
//!    r = b − Aφ on slab z − 1 (a ring of three slabs of the new φ), summing r² over the
//!    runs of eight cells of each x-line and adding the run sums exactly, which is the
//!    in-memory norm (`steady::Layers`).
//!
//! Every value is computed by the in-memory arithmetic in the in-memory order, so the
//! residual history, the stopping decision and the fluence have the in-memory bits
//! (`crates/explicit/tests/it/paged_steady.rs`). The iterates b, φ and r (and D, the diagonal
//! part and Jacobi's scale) live in f64 pages of whole slabs (`lucent_paging::PagedSlabs`)
//! in a pool of their own, under what the budget leaves beside the medium's pool: 40–48
//! bytes per cell paged instead of 600 in memory.
//!
//! What stays out: embedded shapes and emission (a paged problem has neither).

use std::sync::Arc;

use lucent_core::driver::{Coefficients, Record, UNCOLLIDED_SHARE};
use lucent_core::exact::ExactSum;
use lucent_core::{
    History, Light, PagedFirstCollisions, PagedProblem, PagedSolution, Progress, SingularCell,
    SolveError, SolveOptions, SolveReport, Stopping, paging_error, point_source_singular_cells,
    singular_reach,
};
use lucent_diffusion::SlabSystem;
use lucent_diffusion::slab::{PointShares, Window};
use lucent_optics::PhaseFunction;
use lucent_paging::{Eviction, FileStore, PagedGrid, PagedSlabs, Pager, PagerOptions, PagingError};
use rayon::prelude::*;

use lucent_core::exact::add_run_squares;

/// Which iteration, with its parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Kind {
    /// FTCS at `fraction` of the Gershgorin bound.
    Ftcs { fraction: f64 },
    /// Weighted Jacobi.
    Jacobi { omega: f64 },
}

/// Pages of the solver's own pool: one slab each (slabs are the streaming unit).
const SLABS_PER_PAGE: usize = 1;

/// The fewest pages the solver's pool must hold: a pass pins one page at a time; two let
/// a read and the write that follows it stay resident.
const MIN_PAGES: usize = 2;

/// f64 fields per cell in the solver's pool: D, the diagonal's non-coupling part, b, φ, r
/// and, for Jacobi, its scale.
fn state_fields(kind: Kind) -> usize {
    match kind {
        Kind::Ftcs { .. } => 5,
        Kind::Jacobi { .. } => 6,
    }
}

/// Bytes besides the pools: per slab cell, the passes' windows (three slabs of D, φ and
/// each first-moment component, and one of everything else).
const WINDOW_BYTES_PER_SLAB_CELL: u64 = 3 * 4 + 3 * 8 + 9 * 4 + 8 * 8 + 6 * 4;

/// What [`solve`] needs before any work: the lights the scheme takes as its own sources
/// and those that enter as uncollided light (the driver's routing: point lights inside
/// the box are the scheme's own), the state's pool and the bytes in all: the medium's pool
/// and every paged field's bookkeeping, the first collisions' layer, the passes' windows,
/// and the solver's pool in what is left (at least [`MIN_PAGES`] pages).
pub(crate) fn steady_needs(
    name: &str,
    kind: Kind,
    problem: &PagedProblem,
    options: &SolveOptions,
) -> Result<(Vec<Light>, Vec<Light>, u64, u64), SolveError> {
    let geometry = *problem.geometry();
    let [nx, ny, nz] = geometry.dims();
    let slab = nx * ny;
    let layout = *problem.layout();
    let channels = problem.channels();
    let medium = problem.medium();
    // The driver's routing: point lights inside the box are the scheme's own sources;
    // every other light enters as uncollided light.
    let (lo, hi) = geometry.bounds();
    let (own, external): (Vec<Light>, Vec<Light>) =
        problem.lights().iter().cloned().partition(|l| match l {
            Light::Point { position, .. } => position.cmpge(lo).all() && position.cmplt(hi).all(),
            _ => false,
        });

    // Memory, before anything is allocated: the medium's pool and every paged field's
    // bookkeeping, the first collisions' layer, the passes' windows, and the solver's pool
    // in what is left.
    let pointlike = external.iter().filter(|l| l.is_pointlike()).count();
    let extinction = medium.sigma_t.len();
    let moment = medium.phase.mean_cosine() != 0.0 && pointlike > 0;
    let collision_fields = if external.is_empty() {
        0
    } else {
        channels * (2 + if moment { 3 } else { 0 })
            + (pointlike + 1) * extinction
            + 2 * problem.channels_with(&external)
    };
    let fields = medium.sigma_t.len() + medium.albedo.len() + collision_fields + 2 * channels;
    let pool32 = problem.pager().capacity() as u64 * layout.stored_len() as u64 * 4;
    let page_bytes = PagedSlabs::<f64>::page_len(geometry.dims(), SLABS_PER_PAGE) as u64 * 8;
    let pages = state_fields(kind) as u64 * nz.div_ceil(SLABS_PER_PAGE) as u64;
    let windows = (slab as u64) * WINDOW_BYTES_PER_SLAB_CELL
        + if external.is_empty() {
            0
        } else {
            problem.first_collisions_slab_bytes(&external)
        };
    let fixed = pool32
        + problem.overhead_bytes(fields)
        + pages * Pager::<f64>::TABLE_BYTES_PER_BRICK
        + windows;
    let pool64 = options
        .memory_budget
        .saturating_sub(fixed)
        .min(pages * page_bytes);
    if pool64 < MIN_PAGES as u64 * page_bytes {
        return Err(SolveError::OverBudget {
            solver: name.into(),
            needed: fixed + MIN_PAGES as u64 * page_bytes,
            budget: options.memory_budget,
        });
    }
    let needed = fixed + pool64;
    Ok((own, external, pool64, needed))
}

/// The paged solve.
pub(crate) fn solve(
    name: &str,
    kind: Kind,
    problem: &PagedProblem,
    options: &SolveOptions,
) -> Result<PagedSolution, SolveError> {
    let started = std::time::Instant::now();
    let meter = lucent_core::memory::PeakMeter::start();
    let before = problem.pager().stats();
    let err = |e| paging_error(name, e);
    let geometry = *problem.geometry();
    let channels = problem.channels();
    let invalid = |reason: String| SolveError::InvalidParameter {
        name: "problem".into(),
        reason,
    };

    let (own, external, pool64, needed) = steady_needs(name, kind, problem, options)?;
    let system = SlabSystem::new(geometry, lucent_diffusion::conditions(*problem.boundary()))
        .map_err(|e| invalid(e.to_string()))?;
    let state = Arc::new(
        Pager::new(
            Box::new(FileStore::create().map_err(err)?),
            0,
            PagedSlabs::<f64>::page_len(geometry.dims(), SLABS_PER_PAGE),
            MIN_PAGES,
            PagerOptions {
                budget_bytes: pool64,
                eviction: Eviction::Lru,
                fill: 0.0f64,
            },
        )
        .map_err(err)?,
    );

    let collisions = if external.is_empty() {
        None
    } else {
        Some(problem.first_collisions(
            name,
            &external,
            &options.progress_within(0.0, UNCOLLIDED_SHARE),
        )?)
    };
    let start = if collisions.is_some() {
        UNCOLLIDED_SHARE
    } else {
        0.0
    };
    let stage = match kind {
        Kind::Ftcs { .. } => "time step",
        Kind::Jacobi { .. } => "Jacobi sweep",
    };
    let mut fluence = Vec::with_capacity(channels);
    let mut isotropic = Vec::with_capacity(channels);
    let mut record: Option<Record> = None;
    for c in 0..channels {
        let share = (1.0 - start) / channels as f64;
        let mut stopping = Stopping::from_options(
            &options.progress_within(start + c as f64 * share, start + (c + 1) as f64 * share),
        );
        stopping.time_budget = options
            .time_budget
            .map(|t| t.saturating_sub(started.elapsed()));
        let stopping = stopping.with_stage(stage);
        let channel = Channel {
            name,
            index: c,
            kind,
            problem,
            system: &system,
            state: &state,
            collisions: collisions.as_ref(),
            own: &own,
        };
        let (phi, scattered, rec) = channel.solve(&stopping)?;
        fluence.push(phi);
        isotropic.push(scattered);
        record = Some(match record {
            None => rec,
            Some(r) => r.worse(rec),
        });
    }
    let record = record.unwrap_or_else(|| Record::exact(0));
    let paging = problem.pager().stats().since(&before).plus(&state.stats());
    options.report(Progress {
        stage: Progress::DONE,
        fraction: 1.0,
        iteration: record.iterations,
        residual: record.residuals.last().copied(),
    });
    // The renderer's angular part, as in memory: `direct`'s transmittance, and the
    // scattered fluence plus the sky's in-scattering isotropically (only where some light
    // came in as uncollided light).
    let (transmittance, isotropic_fluence) = match collisions {
        Some(PagedFirstCollisions { direct, .. }) => (direct.transmittance, isotropic),
        None => (Vec::new(), Vec::new()),
    };
    Ok(PagedSolution {
        fluence,
        standard_error: Vec::new(),
        transmittance,
        isotropic_fluence,
        report: SolveReport {
            solver: name.into(),
            iterations: record.iterations,
            residual_history: record.residuals,
            wall_time_s: started.elapsed().as_secs_f64(),
            peak_memory_bytes: needed,
            measured_peak_bytes: meter.and_then(|m| m.peak_bytes()),
            stop_reason: record.stop_reason,
            paging: Some(paging),
            choice: None,
            composition: None,
        },
        paging,
    })
}

/// One channel's solve.
struct Channel<'a> {
    name: &'a str,
    index: usize,
    kind: Kind,
    problem: &'a PagedProblem,
    system: &'a SlabSystem,
    state: &'a Arc<Pager<f64>>,
    collisions: Option<&'a PagedFirstCollisions>,
    own: &'a [Light],
}

/// A slab of a paged f32 field, or zeros where there is no field.
fn read_slab(field: Option<&PagedGrid>, z: usize, out: &mut [f32]) -> Result<(), PagingError> {
    match field {
        Some(f) => f.read_slabs(z, z + 1, out),
        None => {
            out.fill(0.0);
            Ok(())
        }
    }
}

/// A ring of the slabs z − 1, z, z + 1 of a field, read from pages as a pass comes.
pub(crate) struct Ring<T> {
    pub(crate) slabs: [Vec<T>; 3],
    /// The slab held in `slabs[i]`, if any.
    pub(crate) held: [Option<usize>; 3],
}

impl<T: Copy + Default> Ring<T> {
    pub(crate) fn new(len: usize) -> Self {
        Self {
            slabs: std::array::from_fn(|_| vec![T::default(); len]),
            held: [None; 3],
        }
    }

    /// Makes slab `z` held (reading it with `read` if it is not), returning its index.
    pub(crate) fn hold(
        &mut self,
        z: usize,
        read: &mut impl FnMut(usize, &mut [T]) -> Result<(), PagingError>,
    ) -> Result<usize, PagingError> {
        let slot = z % 3;
        if self.held[slot] != Some(z) {
            read(z, &mut self.slabs[slot])?;
            self.held[slot] = Some(z);
        }
        Ok(slot)
    }

    /// The window around slab `z` of a field of `nz` slabs (all three must be held).
    pub(crate) fn window(&self, z: usize, nz: usize) -> Window<'_, T> {
        Window {
            below: (z > 0).then(|| self.slabs[(z - 1) % 3].as_slice()),
            here: &self.slabs[z % 3],
            above: (z + 1 < nz).then(|| self.slabs[(z + 1) % 3].as_slice()),
        }
    }

    /// Holds slabs z − 1 ..= z + 1 that exist.
    pub(crate) fn hold_around(
        &mut self,
        z: usize,
        nz: usize,
        read: &mut impl FnMut(usize, &mut [T]) -> Result<(), PagingError>,
    ) -> Result<(), PagingError> {
        for w in z.saturating_sub(1)..(z + 2).min(nz) {
            self.hold(w, read)?;
        }
        Ok(())
    }
}

impl Channel<'_> {
    fn err(&self, e: PagingError) -> SolveError {
        paging_error(self.name, e)
    }

    fn invalid(&self, reason: String) -> SolveError {
        SolveError::InvalidParameter {
            name: "problem".into(),
            reason,
        }
    }

    /// The channel's coefficients of slab `z`: (σ_s, σ_a, D) per cell.
    fn coefficients(
        &self,
        z: usize,
        sigma: &mut [f32],
        albedo: &mut [f32],
    ) -> Result<(), PagingError> {
        let medium = self.problem.medium();
        let c = self.index;
        medium.sigma_t[c.min(medium.sigma_t.len() - 1)].read_slabs(z, z + 1, sigma)?;
        medium.albedo[c.min(medium.albedo.len() - 1)].read_slabs(z, z + 1, albedo)
    }

    /// Solves the channel: its fluence and scattered-plus-sky fluence (paged), and how the
    /// iteration went.
    fn solve(&self, stopping: &Stopping) -> Result<(PagedGrid, PagedGrid, Record), SolveError> {
        let geometry = *self.problem.geometry();
        let [nx, ny, nz] = geometry.dims();
        let slab = nx * ny;
        let g = self.problem.medium().phase.mean_cosine();
        let floor = Coefficients::reduced_floor_of(&geometry);
        let err = |e| self.err(e);
        let new_slabs = || PagedSlabs::<f64>::new(self.state.clone(), geometry.dims()).map_err(err);
        let d_pages = new_slabs()?;
        let extra_pages = new_slabs()?;
        // Ctrl-C and the time limit, asked every slab: a pass over 512³ cells through the
        // pager takes seconds.
        let interrupt = stopping.interrupt(std::time::Instant::now());
        let halted = || interrupt.check(self.name, "the paged set-up passes");

        // Pass 1: D and the diagonal's non-coupling part, cell by cell.
        let (mut sigma, mut albedo) = (vec![0.0f32; slab], vec![0.0f32; slab]);
        let mut absorbs = false;
        let (mut d64, mut extra64) = (vec![0.0f64; slab], vec![0.0f64; slab]);
        for z in 0..nz {
            halted()?;
            self.coefficients(z, &mut sigma, &mut albedo).map_err(err)?;
            for index in 0..slab {
                let [_, a, d] = Coefficients::at(sigma[index], albedo[index], g, floor);
                if !(d.is_finite() && d > 0.0 && a.is_finite() && a >= 0.0) {
                    return Err(self.invalid(format!(
                        "diffusion coefficient {d} or absorption {a} in cell {}",
                        index + z * slab
                    )));
                }
                absorbs |= a > 0.0;
                d64[index] = f64::from(d);
                extra64[index] = f64::from(self.system.extra([index % nx, index / nx, z], d, a));
            }
            d_pages.write_slab(z, &d64).map_err(err)?;
            extra_pages.write_slab(z, &extra64).map_err(err)?;
        }
        if !absorbs && !self.system.holds() {
            return Err(self.invalid(
                "the diffusion problem is singular: no absorption and no boundary that holds the fluence"
                    .into(),
            ));
        }

        // The scheme's own point lights: singular parts where the medium around them
        // allows, else point sources, as in memory.
        let (singular, points) = self.point_lights()?;

        // Pass 2: b (and r = b, φ = 0), the Gershgorin bound and the diagonals.
        let b_pages = new_slabs()?;
        let r_pages = new_slabs()?;
        let phi_pages = new_slabs()?;
        let scale_pages = match self.kind {
            Kind::Jacobi { .. } => Some(new_slabs()?),
            Kind::Ftcs { .. } => None,
        };
        let collisions = self.collisions;
        let c = self.index;
        let sources = collisions.map(|k| &k.sources[c]);
        let moment = collisions.and_then(|k| k.first_moment.get(c));
        let mut d_ring: Ring<f32> = Ring::new(slab);
        let mut q1_rings: [Ring<f32>; 3] = std::array::from_fn(|_| Ring::new(slab));
        let mut read_d = |z: usize, out: &mut [f32]| {
            d_pages.read_slab(z, &mut d64)?;
            for (o, v) in out.iter_mut().zip(&d64) {
                *o = *v as f32;
            }
            Ok(())
        };
        let mut q0 = vec![0.0f32; slab];
        let mut b = vec![0.0f64; slab];
        let mut scale = vec![0.0f64; slab];
        let mut b_squares = ExactSum::new();
        let mut gershgorin = 0.0f64;
        for z in 0..nz {
            halted()?;
            d_ring.hold_around(z, nz, &mut read_d).map_err(err)?;
            read_slab(sources, z, &mut q0).map_err(err)?;
            for part in &singular {
                for cell in part.iter().filter(|s| s.cell / slab == z) {
                    q0[cell.cell % slab] += cell.source;
                }
            }
            if let Some(index) = q0.iter().position(|q| !q.is_finite()) {
                return Err(self.invalid(format!(
                    "source {} in cell {}",
                    q0[index],
                    index + z * slab
                )));
            }
            if let Some(fields) = moment {
                for (ring, field) in q1_rings.iter_mut().zip(fields) {
                    ring.hold_around(z, nz, &mut |w, out: &mut [f32]| {
                        field.read_slabs(w, w + 1, out)
                    })
                    .map_err(err)?;
                    if ring.slabs[z % 3].iter().any(|v| !v.is_finite()) {
                        return Err(self.invalid("non-finite first moment".into()));
                    }
                }
            }
            let d = d_ring.window(z, nz);
            let q1 = moment.map(|_| [0, 1, 2].map(|a| q1_rings[a].window(z, nz)));
            self.system
                .rhs_slab(z, &q0, q1.as_ref(), &d, &points, &mut b);
            extra_pages.read_slab(z, &mut extra64).map_err(err)?;
            for index in 0..slab {
                let row = self
                    .system
                    .row([index % nx, index / nx, z], &d, extra64[index] as f32);
                let diagonal = row.diagonal();
                if diagonal <= 0.0 {
                    return Err(self
                        .invalid("FTCS diffusion: the system has a non-positive diagonal".into()));
                }
                gershgorin =
                    gershgorin.max(row.entries().iter().map(|(_, v)| v.abs()).sum::<f64>());
                if let Kind::Jacobi { omega } = self.kind {
                    scale[index] = omega / diagonal;
                }
            }
            // By runs, as the in-memory norm sums (`steady::Layers`).
            add_run_squares(&b, nx, &mut b_squares);
            b_pages.write_slab(z, &b).map_err(err)?;
            r_pages.write_slab(z, &b).map_err(err)?;
            if let Some(pages) = &scale_pages {
                pages.write_slab(z, &scale).map_err(err)?;
            }
        }
        let b_norm = b_squares.value().sqrt().max(f64::MIN_POSITIVE);
        let volume = geometry.cell_volume();
        let step_scale = match self.kind {
            Kind::Ftcs { fraction } => Some(fraction * (2.0 * volume / gershgorin) / volume),
            Kind::Jacobi { omega } => {
                if !(omega > 0.0 && omega <= 1.0) {
                    return Err(self.invalid(format!("Jacobi damping {omega} outside (0, 1]")));
                }
                None
            }
        };

        // The iteration: φ ← φ + s r on slab z, then r ← b − Aφ on slab z − 1.
        let mut history = History::start();
        let mut relative = 1.0;
        let mut finite = true;
        let mut phi_ring: Ring<f64> = Ring::new(slab);
        let (mut r, mut rows_b) = (vec![0.0f64; slab], vec![0.0f64; slab]);
        let stop_reason = loop {
            if let Some(stop) = history.record(stopping, relative, relative * b_norm) {
                break stop;
            }
            phi_ring.held = [None; 3];
            let mut r_squares = ExactSum::new();
            finite = true;
            let mut whole = true;
            for z in 0..=nz {
                // A pass stopped part way leaves φ updated on the slabs it reached (a
                // partial step, as good an iterate as the last) and the residual of the
                // last whole pass; the stopping rule then says why.
                if interrupt.halted() {
                    whole = false;
                    break;
                }
                if z < nz {
                    // φ on slab z.
                    let slot = z % 3;
                    phi_pages
                        .read_slab(z, &mut phi_ring.slabs[slot])
                        .map_err(err)?;
                    r_pages.read_slab(z, &mut r).map_err(err)?;
                    if let Some(pages) = &scale_pages {
                        pages.read_slab(z, &mut scale).map_err(err)?;
                    }
                    let phi = &mut phi_ring.slabs[slot];
                    match step_scale {
                        Some(s) => phi
                            .par_iter_mut()
                            .zip(r.par_iter())
                            .for_each(|(p, r)| *p += s * r),
                        None => phi
                            .par_iter_mut()
                            .zip(r.par_iter())
                            .zip(scale.par_iter())
                            .for_each(|((p, r), s)| *p += s * r),
                    }
                    finite &= phi.iter().all(|v| v.is_finite());
                    phi_ring.held[slot] = Some(z);
                    phi_pages.write_slab(z, phi).map_err(err)?;
                }
                if z >= 1 {
                    // r on slab z − 1, from the new φ of slabs z − 2 ..= z.
                    let w = z - 1;
                    d_ring.hold_around(w, nz, &mut read_d).map_err(err)?;
                    b_pages.read_slab(w, &mut rows_b).map_err(err)?;
                    extra_pages.read_slab(w, &mut extra64).map_err(err)?;
                    let d = d_ring.window(w, nz);
                    let phi = phi_ring.window(w, nz);
                    let system = self.system;
                    r.par_chunks_mut(nx).enumerate().for_each(|(j, row_r)| {
                        for (i, ri) in row_r.iter_mut().enumerate() {
                            let index = i + nx * j;
                            let row = system.row([i, j, w], &d, extra64[index] as f32);
                            let ax: f64 = row
                                .entries()
                                .iter()
                                .map(|&(o, v)| v * phi_at(&phi, slab, index, o))
                                .sum();
                            *ri = rows_b[index] - ax;
                        }
                    });
                    add_run_squares(&r, nx, &mut r_squares);
                    r_pages.write_slab(w, &r).map_err(err)?;
                }
            }
            if whole {
                relative = r_squares.value().sqrt() / b_norm;
            }
        };
        let record = Record::from_residuals(history.into_residuals(), stop_reason, 0);

        // The fluence: the scattered φ (zeros if it is not finite, as in memory) plus the
        // singular parts and the uncollided light; and the scattered fluence plus the sky's
        // for the renderer.
        let out = self.problem.new_field().map_err(err)?;
        let iso = self.problem.new_field().map_err(err)?;
        let uncollided = collisions.map(|k| &k.fluence[c]);
        let sky = collisions.and_then(|k| {
            let iso = &k.direct.isotropic_fluence;
            iso.get(c.min(iso.len().saturating_sub(1)))
        });
        let layout = *self.problem.layout();
        let brick = layout.brick();
        let mut phi = vec![0.0f64; slab];
        let mut extra32 = vec![0.0f32; slab];
        for layer in 0..layout.bricks()[2] {
            let (z0, z1) = (layer * brick, (layer * brick + brick).min(nz));
            let mut total = vec![0.0f32; slab * (z1 - z0)];
            let mut scattered = vec![0.0f32; slab * (z1 - z0)];
            for z in z0..z1 {
                let range = (z - z0) * slab..(z - z0 + 1) * slab;
                phi_pages.read_slab(z, &mut phi).map_err(err)?;
                let mut singular_fluence = vec![0.0f32; slab];
                for part in &singular {
                    for cell in part.iter().filter(|s| s.cell / slab == z) {
                        singular_fluence[cell.cell % slab] += cell.fluence;
                    }
                }
                read_slab(uncollided, z, &mut extra32).map_err(err)?;
                for (k, index) in range.clone().enumerate() {
                    let s = if finite { phi[k] as f32 } else { 0.0 };
                    scattered[index] = s;
                    total[index] = s + singular_fluence[k];
                    if uncollided.is_some() {
                        total[index] += extra32[k];
                    }
                }
                if let Some(k) = total[range.clone()].iter().position(|v| !v.is_finite()) {
                    return Err(SolveError::NonFiniteOutput {
                        solver: self.name.into(),
                        what: "fluence",
                        channel: c,
                        cell: [k % nx, k / nx, z],
                        value: total[range.start + k],
                    });
                }
                if let Some(sky) = sky {
                    sky.read_slabs(z, z + 1, &mut extra32).map_err(err)?;
                    for (s, v) in scattered[range].iter_mut().zip(&extra32) {
                        *s += v;
                    }
                }
            }
            out.write_slabs(z0, &total).map_err(err)?;
            iso.write_slabs(z0, &scattered).map_err(err)?;
        }
        Ok((out, iso, record))
    }

    /// The own point lights of this channel: each one's singular part where the medium is
    /// homogeneous around it, else its shares as a point source.
    fn point_lights(&self) -> Result<(Vec<Vec<SingularCell>>, Vec<PointShares>), SolveError> {
        let geometry = *self.problem.geometry();
        let dims = geometry.dims();
        let g = self.problem.medium().phase.mean_cosine();
        let floor = Coefficients::reduced_floor_of(&geometry);
        let medium = self.problem.medium();
        let c = self.index;
        let (mut singular, mut points) = (Vec::new(), Vec::new());
        for light in self.own {
            let Light::Point {
                position,
                intensity,
            } = light
            else {
                continue;
            };
            let power = 4.0 * std::f64::consts::PI * intensity.channel(c);
            // Coefficients of the cells within reach of the light, read once.
            let reach = singular_reach(&geometry);
            let h = geometry.spacing();
            let range = |a: usize| {
                let lo = ((position[a] - reach - geometry.origin()[a]) / h[a])
                    .floor()
                    .max(0.0) as usize;
                let hi = (((position[a] + reach - geometry.origin()[a]) / h[a])
                    .ceil()
                    .max(0.0) as usize)
                    .min(dims[a]);
                lo..hi.max(lo)
            };
            let [rx, ry, rz] = [range(0), range(1), range(2)];
            let window = [rx.len(), ry.len(), rz.len()];
            let mut coefficients = vec![[0.0f32; 2]; window[0] * window[1] * window[2]];
            for (w, slot) in coefficients.iter_mut().enumerate() {
                let at = [
                    rx.start + w % window[0],
                    ry.start + (w / window[0]) % window[1],
                    rz.start + w / (window[0] * window[1]),
                ];
                let sigma = medium.sigma_t[c.min(medium.sigma_t.len() - 1)]
                    .get(at)
                    .map_err(|e| self.err(e))?;
                let albedo = medium.albedo[c.min(medium.albedo.len() - 1)]
                    .get(at)
                    .map_err(|e| self.err(e))?;
                let [_, a, d] = Coefficients::at(sigma, albedo, g, floor);
                *slot = [d, a];
            }
            let local = |cell: usize| {
                let [i, j, k] = geometry.coords(cell);
                (i - rx.start) + window[0] * ((j - ry.start) + window[1] * (k - rz.start))
            };
            match point_source_singular_cells(
                &geometry,
                |cell| coefficients[local(cell)][0],
                |cell| coefficients[local(cell)][1],
                |_| true,
                *position,
                power,
            ) {
                Some((_, cells)) => singular.push(cells),
                None => {
                    points.push(self.system.point_weights(*position, power).ok_or_else(|| {
                        self.invalid(format!("point source at {position} is outside the medium"))
                    })?)
                }
            }
        }
        Ok((singular, points))
    }
}

/// φ at the cell `offset` cells from `index` of the window's middle slab.
#[inline]
fn phi_at(phi: &Window<'_, f64>, slab: usize, index: usize, offset: isize) -> f64 {
    let s = slab as isize;
    if offset == s {
        phi.above.expect("a slab above")[index]
    } else if offset == -s {
        phi.below.expect("a slab below")[index]
    } else {
        phi.here[(index as isize + offset) as usize]
    }
}
