//! `mc` on a paged medium (Bernabei, chapter 5): the same particles, the same arithmetic,
//! with σ_t and the albedo read from paged bricks and the track lengths tallied into paged
//! bricks, so that a volume larger than memory is traced within a byte budget.
//!
//! - **Medium.** Each running batch reads σ_t and the albedo through
//!   [`lucent_paging::PagedSampler`]s (one pinned brick per field; the dense grid's
//!   trilinear arithmetic on the brick and its apron).
//! - **Majorant from the bricks.** The majorant grid is the field's per-brick maxima
//!   ([`MajorantGrid::from_brick_maxima`]: brick and apron bound the trilinear interpolant),
//!   read from the pager's ranges without a pass over the medium; with `global_majorant`
//!   their largest. Bricks of `majorant_cells`³ cells give the in-memory tracer's majorant
//!   and so its random decisions: the same bits.
//! - **Tallies.** A batch's track lengths go to pages of an f64 pager of their own (one page
//!   per brick: B³ cells × channels, the running brick pinned), each cell receiving its
//!   additions in path order as in memory. After each round of batches the pages are
//!   folded into the running sums Σφ and Σφ² brick by brick, in batch order (the in-memory
//!   order per cell), and recycled ([`Pager::discard`]); bricks a batch never reached are
//!   skipped, which adds exactly nothing.
//! - **Result.** The mean and its standard error per channel go to paged fields layer by
//!   layer.
//!
//! Errors of the backing store stop a batch at its next path (the first error is kept and
//! returned), never a panic or silent loss. Memory: the medium's pool, the tally pool (the
//! rest of the budget), the majorant (8 bytes per brick) and two brick layers of slabs per
//! channel while the result is written.

use lucent_core::{
    PagedProblem, PagedSolution, Progress, SolveError, SolveOptions, SolveReport, StopReason,
    paging_error,
};
use lucent_grid::{BrickLayout, GridGeometry};
use lucent_paging::{
    Eviction, FileStore, PagedGrid, PagedSampler, Pager, PagerOptions, PagerStats, PagingError,
};
use rayon::prelude::*;

use crate::majorant::MajorantGrid;
use crate::transport::{
    FluenceTally, McConfig, MediumSampler, RunControl, Scene, Tally, trace_batch,
    trace_batch_spectral,
};

/// The medium of a paged problem as one batch reads it.
struct PagedMedium<'a> {
    sigma_t: Vec<PagedSampler<'a>>,
    albedo: Vec<PagedSampler<'a>>,
    error: Option<PagingError>,
}

impl<'a> PagedMedium<'a> {
    fn new(problem: &'a PagedProblem) -> Self {
        let medium = problem.medium();
        Self {
            sigma_t: medium.sigma_t.iter().map(PagedGrid::sampler).collect(),
            albedo: medium.albedo.iter().map(PagedGrid::sampler).collect(),
            error: None,
        }
    }

    fn sample(&mut self, field: usize, albedo: bool, p: glam::DVec3) -> f64 {
        let samplers = if albedo {
            &mut self.albedo
        } else {
            &mut self.sigma_t
        };
        let last = samplers.len() - 1;
        match samplers[field.min(last)].sample_trilinear(p) {
            Ok(v) => f64::from(v),
            Err(e) => {
                // Kept for the batch's end; 0 ends the path's interactions quickly.
                self.error.get_or_insert(e);
                0.0
            }
        }
    }
}

impl MediumSampler for PagedMedium<'_> {
    #[inline]
    fn sigma_t(&mut self, e: usize, p: glam::DVec3) -> f64 {
        self.sample(e, false, p)
    }

    #[inline]
    fn albedo(&mut self, c: usize, p: glam::DVec3) -> f64 {
        self.sample(c, true, p)
    }
}

/// The tally pages: per brick of the medium's layout one page of B³ cells × `channels`
/// values (member or channel m at `m·B³ + local`). Pages 0..count hold Σφ, count..2·count
/// Σφ², and each running batch `slot` has its own count pages after those.
struct TallyPages {
    pager: Pager<f64>,
    layout: BrickLayout,
    geometry: GridGeometry,
    /// Cells per page and channel: B³.
    cells: usize,
}

impl TallyPages {
    fn sum_page(&self, brick: usize) -> usize {
        brick
    }

    fn square_page(&self, brick: usize) -> usize {
        self.layout.count() + brick
    }

    fn batch_page(&self, slot: usize, brick: usize) -> usize {
        (2 + slot) * self.layout.count() + brick
    }

    /// Index in a page of local cell `local` of a brick.
    fn local_index(&self, local: [usize; 3]) -> usize {
        let b = self.layout.brick();
        local[0] + b * (local[1] + b * local[2])
    }
}

/// One running batch's tally. Track lengths arrive in path order, scattered over the
/// grid; pinning a page per crossing would thrash a small pool. They are logged instead
/// (brick, index in the page, value) and applied when the log is full: sorted by brick
/// with a stable sort, so each cell still receives its additions in path order (the
/// in-memory bits), and each brick touched is pinned once per flush.
struct PagedTally<'a> {
    pages: &'a TallyPages,
    slot: usize,
    log: Vec<(u32, u32, f64)>,
    capacity: usize,
    error: Option<PagingError>,
}

impl PagedTally<'_> {
    /// Applies the log to the batch's pages.
    fn flush(&mut self) {
        if self.log.is_empty() || self.error.is_some() {
            self.log.clear();
            return;
        }
        self.log.sort_by_key(|&(brick, _, _)| brick);
        let pages = self.pages;
        for run in self.log.chunk_by(|a, b| a.0 == b.0) {
            let page = pages.batch_page(self.slot, run[0].0 as usize);
            match pages.pager.write(page) {
                Ok(mut pin) => {
                    for &(_, at, value) in run {
                        pin[at as usize] += value;
                    }
                }
                Err(e) => {
                    self.error = Some(e);
                    break;
                }
            }
        }
        self.log.clear();
    }

    /// Flushes what is left and returns the first error.
    fn finish(mut self) -> Result<(), PagingError> {
        self.flush();
        self.error.map_or(Ok(()), Err)
    }
}

impl FluenceTally for PagedTally<'_> {
    #[inline]
    fn add(&mut self, member: usize, cell: usize, value: f64) {
        let pages = self.pages;
        let [nx, ny, _] = pages.geometry.dims();
        let at = [cell % nx, (cell / nx) % ny, cell / (nx * ny)];
        let (brick, local) = pages.layout.locate(at);
        let index = member * pages.cells + pages.local_index(local);
        self.log.push((brick as u32, index as u32, value));
        if self.log.len() >= self.capacity {
            self.flush();
        }
    }
}

/// Bytes per entry of a tally log: the entry and the stable sort's scratch.
const LOG_ENTRY_BYTES: u64 = 24;

/// What [`estimate_paged`] returns.
pub(crate) struct PagedEstimate {
    pub(crate) fluence: Vec<PagedGrid>,
    pub(crate) standard_error: Vec<PagedGrid>,
    /// Batches run (the fewest over channels).
    pub(crate) batches: usize,
    /// The mean relative standard error of channel 0 over cells above a thousandth of its
    /// peak (the in-memory solve's measure).
    pub(crate) relative_error: f64,
    pub(crate) tally_stats: PagerStats,
    pub(crate) needed: u64,
}

/// Bytes besides the medium's pool and the tally pool: the bookkeeping of the medium and
/// the result fields, the tally table, the majorant and the output layers.
fn overhead_bytes(problem: &PagedProblem, tally_pages: usize) -> u64 {
    let channels = problem.channels();
    let medium = problem.medium();
    let fields = medium.sigma_t.len() + medium.albedo.len() + 2 * channels;
    let layout = problem.layout();
    let [nx, ny, _] = problem.geometry().dims();
    problem.overhead_bytes(fields)
        + tally_pages as u64 * Pager::<f64>::TABLE_BYTES_PER_BRICK
        + layout.count() as u64 * 8
        + 2 * channels as u64 * (nx * ny * layout.brick()) as u64 * 4
}

/// What [`estimate_paged`] sizes before any work.
pub(crate) struct PagedNeeds {
    /// Cells of a brick (a tally page's cells).
    cells: usize,
    /// The tallies' smallest pool.
    min_pool: u64,
    /// Tally pages the pager numbers.
    tally_pages: usize,
    /// Bytes besides the tallies' pool: the medium's pool and every bookkeeping.
    fixed: u64,
}

/// The memory a paged Monte Carlo solve needs under `options.memory_budget`: the medium's
/// pager must hold every running batch's pins (σ_t and albedo per channel), and the rest of
/// the budget must hold the tallies' smallest pool (at least one page per running batch
/// and three per folding thread, and the logs). Depends on the problem's shape only.
pub(crate) fn paged_needs(
    problem: &PagedProblem,
    options: &SolveOptions,
) -> Result<PagedNeeds, SolveError> {
    let name = crate::McSolver::NAME;
    let layout = *problem.layout();
    let medium = problem.medium();
    let channels = problem.channels();
    let count = layout.count();
    let threads = rayon::current_num_threads().max(1);
    // The medium's pager must hold every running batch's pins (σ_t and albedo per channel).
    let pins = threads * (medium.sigma_t.len() + medium.albedo.len());
    if problem.pager().capacity() < pins {
        return Err(SolveError::OverBudget {
            solver: name.into(),
            needed: pins as u64 * layout.stored_len() as u64 * 4,
            budget: problem.pager().capacity() as u64 * layout.stored_len() as u64 * 4,
        });
    }
    // Tallies: the rest of the budget, at least one page per running batch and three per
    // folding thread.
    let cells = layout.brick().pow(3);
    let page_bytes = (cells * channels) as u64 * 8;
    let tally_pages = (2 + threads) * count;
    let medium_pool = problem.pager().capacity() as u64 * layout.stored_len() as u64 * 4;
    let fixed = medium_pool + overhead_bytes(problem, tally_pages);
    let min_pool = 3 * threads as u64 * page_bytes + threads as u64 * 1024 * LOG_ENTRY_BYTES;
    if fixed + min_pool > options.memory_budget {
        return Err(SolveError::OverBudget {
            solver: name.into(),
            needed: fixed + min_pool,
            budget: options.memory_budget,
        });
    }
    Ok(PagedNeeds {
        cells,
        min_pool,
        tally_pages,
        fixed,
    })
}

/// The bytes [`paged_needs`] finds at the least: the fixed part and the tallies' smallest
/// pool.
pub(crate) fn paged_memory(
    problem: &PagedProblem,
    options: &SolveOptions,
) -> Result<u64, SolveError> {
    let needs = paged_needs(problem, options)?;
    Ok(needs.fixed + needs.min_pool)
}

/// Particle tracing on a paged problem within `budget` bytes: the in-memory estimator's
/// results (the same bits where the bricks have `majorant_cells`³ cells) as paged fields.
pub(crate) fn estimate_paged(
    problem: &PagedProblem,
    config: &McConfig,
    control: &RunControl<'_>,
    options: &SolveOptions,
) -> Result<PagedEstimate, SolveError> {
    let name = crate::McSolver::NAME;
    let err = |e| paging_error(name, e);
    if config.batches < 2 || config.particles == 0 || config.max_depth == 0 {
        return Err(SolveError::InvalidParameter {
            name: "mc".into(),
            reason: "needs ≥ 2 batches, ≥ 1 particle and max_depth ≥ 1".into(),
        });
    }
    let geometry = *problem.geometry();
    let layout = *problem.layout();
    let medium = problem.medium();
    let channels = problem.channels();
    let count = layout.count();
    // The majorants from the bricks' ranges.
    let extinction_max = |e: usize| -> Vec<f32> {
        (0..count)
            .map(|id| medium.sigma_t[e].brick_range(id).map_or(0.0, |r| r.1))
            .collect()
    };
    let peak = (0..medium.sigma_t.len())
        .flat_map(extinction_max)
        .fold(0.0f32, f32::max);
    crate::transport::check_reach(&geometry, f64::from(peak))?;
    let majorant_of = |maxima: Vec<f32>| {
        if config.global_majorant {
            let max = maxima.iter().copied().fold(0.0f32, f32::max);
            MajorantGrid::from_brick_maxima(geometry, &layout, &vec![max; count])
        } else {
            MajorantGrid::from_brick_maxima(geometry, &layout, &maxima)
        }
    };

    let threads = rayon::current_num_threads().max(1);
    let PagedNeeds {
        cells,
        tally_pages,
        fixed,
        ..
    } = paged_needs(problem, options)?;
    // Up to half of the rest for the tallies' logs (one per running batch; 16 bytes an
    // entry and half that again for the stable sort's buffer; 2²⁰ entries amortise a
    // brick's pin over hundreds of additions), the rest for their pages.
    let rest = options.memory_budget - fixed;
    let log_capacity = ((rest / 2 / LOG_ENTRY_BYTES) as usize / threads).clamp(1024, 1 << 20);
    let pool = rest - (log_capacity * threads) as u64 * LOG_ENTRY_BYTES;
    let pages = TallyPages {
        pager: Pager::new(
            Box::new(FileStore::create().map_err(err)?),
            tally_pages,
            cells * channels,
            3 * threads,
            PagerOptions {
                budget_bytes: pool,
                eviction: Eviction::Lru,
                fill: 0.0f64,
            },
        )
        .map_err(err)?,
        layout,
        geometry,
        cells,
    };
    let needed = fixed + pool;

    // Tracing groups as in memory.
    const SPECTRAL: usize = usize::MAX;
    let spectral = medium.sigma_t.len() == 3 && config.spectral_mis;
    let groups: Vec<(usize, Vec<usize>)> = if medium.sigma_t.len() == 1 {
        vec![(0, (0..channels).collect())]
    } else if spectral {
        vec![(SPECTRAL, vec![0, 1, 2])]
    } else {
        (0..3).map(|c| (c, vec![c])).collect()
    };
    let scene = Scene::plain(geometry, medium.phase, problem.lights());
    let inv_volume = 1.0 / geometry.cell_volume();
    let batch_ids: Vec<usize> = (0..config.batches).collect();
    let mut done = vec![0usize; channels];
    let total = config.batches * groups.len();
    let traced = std::sync::atomic::AtomicUsize::new(0);
    for (extinction, members) in &groups {
        let majorant = if *extinction == SPECTRAL {
            let per_channel: Vec<Vec<f32>> = (0..3).map(extinction_max).collect();
            majorant_of(
                (0..count)
                    .map(|id| per_channel.iter().map(|m| m[id]).fold(0.0f32, f32::max))
                    .collect(),
            )
        } else {
            majorant_of(extinction_max(*extinction))
        };
        let mut ran = 0;
        for chunk in batch_ids.chunks(threads) {
            if control.interrupt.halted() {
                break;
            }
            let whole: Vec<bool> = chunk
                .par_iter()
                .enumerate()
                .map(|(slot, &batch)| {
                    let mut sampler = PagedMedium::new(problem);
                    let tally = PagedTally {
                        pages: &pages,
                        slot,
                        log: Vec::with_capacity(log_capacity),
                        capacity: log_capacity,
                        error: None,
                    };
                    let tally: Tally<PagedTally<'_>> = if *extinction == SPECTRAL {
                        trace_batch_spectral(
                            &scene,
                            &mut sampler,
                            &majorant,
                            config,
                            batch as u64,
                            tally,
                            &control.interrupt,
                        )
                    } else {
                        trace_batch(
                            &scene,
                            &mut sampler,
                            *extinction,
                            &majorant,
                            members,
                            config,
                            batch as u64 + 1000 * *extinction as u64,
                            tally,
                            &control.interrupt,
                        )
                    };
                    let now = traced.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                    if let Some(progress) = control.progress {
                        progress(now, total);
                    }
                    let Tally {
                        fluence, complete, ..
                    } = tally;
                    let tallied = fluence.finish();
                    sampler.error.map_or(tallied, Err).map(|()| complete)
                })
                .collect::<Result<Vec<bool>, PagingError>>()
                .map_err(err)?;
            // Fold the round's tallies brick by brick, batches in order.
            (0..count)
                .into_par_iter()
                .try_for_each(|brick| -> Result<(), PagingError> {
                    // A batch an interrupt stopped part way is dropped.
                    let (touched, dropped): (Vec<usize>, Vec<usize>) = (0..chunk.len())
                        .filter(|&slot| !pages.pager.is_fresh(pages.batch_page(slot, brick)))
                        .partition(|&slot| whole[slot]);
                    for slot in dropped {
                        pages.pager.discard(pages.batch_page(slot, brick))?;
                    }
                    if touched.is_empty() {
                        return Ok(());
                    }
                    let mut sum = pages.pager.write(pages.sum_page(brick))?;
                    let mut square = pages.pager.write(pages.square_page(brick))?;
                    for slot in touched {
                        let page = pages.batch_page(slot, brick);
                        let tally = pages.pager.read(page)?;
                        for (m, &c) in members.iter().enumerate() {
                            let from = &tally[m * cells..(m + 1) * cells];
                            let to = c * cells..(c + 1) * cells;
                            for ((s, q), &t) in
                                sum[to.clone()].iter_mut().zip(&mut square[to]).zip(from)
                            {
                                let phi = t * inv_volume;
                                *s += phi;
                                *q += phi * phi;
                            }
                        }
                        drop(tally);
                        pages.pager.discard(page)?;
                    }
                    Ok(())
                })
                .map_err(err)?;
            ran += whole.iter().filter(|&&w| w).count();
        }
        if let Some(halt) = control.interrupt.halt().filter(|_| ran < 2) {
            return Err(SolveError::Halted {
                solver: name.into(),
                stage: "its first two batches (the least a standard error needs)".into(),
                halt,
            });
        }
        for &c in members {
            done[c] = ran;
        }
    }

    // The mean and its standard error, layer by layer into paged fields.
    let [nx, ny, nz] = geometry.dims();
    let b = layout.brick();
    let mut fluence = Vec::with_capacity(channels);
    let mut standard_error = Vec::with_capacity(channels);
    for _ in 0..channels {
        fluence.push(problem.new_field().map_err(err)?);
        standard_error.push(problem.new_field().map_err(err)?);
    }
    // Channel 0's peak first: the relative error counts cells above a thousandth of it.
    let mut peak = 0.0f32;
    let b0 = done[0].max(1) as f64;
    for brick in 0..count {
        let sums = pages.pager.read(pages.sum_page(brick)).map_err(err)?;
        peak = sums[..cells]
            .iter()
            .fold(peak, |p, &s| p.max((s / b0) as f32));
    }
    let (mut relative_sum, mut relative_count) = (0.0f64, 0usize);
    for layer in 0..layout.bricks()[2] {
        let (z0, z1) = (layer * b, (layer * b + b).min(nz));
        let n = nx * ny * (z1 - z0);
        let mut mean = vec![vec![0f32; n]; channels];
        let mut error = vec![vec![0f32; n]; channels];
        for by in 0..layout.bricks()[1] {
            for bx in 0..layout.bricks()[0] {
                let brick = layout.id([bx, by, layer]);
                let sums = pages.pager.read(pages.sum_page(brick)).map_err(err)?;
                let squares = pages.pager.read(pages.square_page(brick)).map_err(err)?;
                let [ox, oy, oz] = layout.origin(brick);
                let [ex, ey, ez] = layout.extent(brick);
                for c in 0..channels {
                    let batches = done[c].max(1) as f64;
                    for k in 0..ez {
                        for j in 0..ey {
                            for i in 0..ex {
                                let at = c * cells + pages.local_index([i, j, k]);
                                let (s, s2) = (sums[at], squares[at]);
                                let cell = (ox + i) + nx * ((oy + j) + ny * (oz + k - z0));
                                mean[c][cell] = (s / batches) as f32;
                                error[c][cell] = standard_error_of(s, s2, batches) as f32;
                            }
                        }
                    }
                }
            }
        }
        // In x-fastest order, as the in-memory measure adds them.
        for (p, e) in mean[0].iter().zip(&error[0]) {
            if *p > 1e-3 * peak {
                relative_sum += f64::from(*e / *p);
                relative_count += 1;
            }
        }
        for c in 0..channels {
            fluence[c].write_slabs(z0, &mean[c]).map_err(err)?;
            standard_error[c].write_slabs(z0, &error[c]).map_err(err)?;
        }
    }
    Ok(PagedEstimate {
        fluence,
        standard_error,
        batches: done.iter().copied().min().unwrap_or(0).max(1),
        relative_error: if relative_count > 0 {
            relative_sum / relative_count as f64
        } else {
            0.0
        },
        tally_stats: pages.pager.stats(),
        needed,
    })
}

/// The standard error of a batch mean from the sums of φ and φ² over `b` batches (the
/// in-memory estimator's formula).
fn standard_error_of(s: f64, s2: f64, b: f64) -> f64 {
    let mean = s / b;
    let var = ((s2 / b - mean * mean) * b / (b - 1.0).max(1.0)).max(0.0);
    (var / b).sqrt()
}

/// `mc` on a paged problem: [`estimate_paged`] with the solve's report.
pub(crate) fn solve_paged(
    solver: &crate::McSolver,
    problem: &PagedProblem,
    options: &SolveOptions,
) -> Result<PagedSolution, SolveError> {
    let started = std::time::Instant::now();
    let meter = lucent_core::memory::PeakMeter::start();
    let before = problem.pager().stats();
    let report = |done: usize, total: usize| {
        options.report(Progress {
            stage: "batch",
            fraction: done as f64 / total.max(1) as f64,
            iteration: done,
            residual: None,
        })
    };
    report(0, solver.config.batches);
    let control = RunControl {
        progress: Some(&report),
        interrupt: lucent_core::Interrupt::of(options),
    };
    let estimate = estimate_paged(problem, &solver.config, &control, options)?;
    let relative = estimate.relative_error;
    let stop_reason = if estimate.batches < solver.config.batches {
        control
            .interrupt
            .halt()
            .unwrap_or(lucent_core::Halt::TimeLimit)
            .stop_reason(relative)
    } else {
        StopReason::Sampled {
            relative_error: relative,
        }
    };
    let paging = problem
        .pager()
        .stats()
        .since(&before)
        .plus(&estimate.tally_stats);
    options.report(Progress {
        stage: Progress::DONE,
        fraction: 1.0,
        iteration: estimate.batches,
        residual: None,
    });
    Ok(PagedSolution {
        fluence: estimate.fluence,
        standard_error: estimate.standard_error,
        transmittance: Vec::new(),
        isotropic_fluence: Vec::new(),
        report: SolveReport {
            solver: crate::McSolver::NAME.into(),
            iterations: estimate.batches,
            residual_history: Vec::new(),
            wall_time_s: started.elapsed().as_secs_f64(),
            peak_memory_bytes: estimate.needed,
            measured_peak_bytes: meter.and_then(|m| m.peak_bytes()),
            stop_reason,
            paging: Some(paging),
            choice: None,
            composition: None,
        },
        paging,
    })
}
