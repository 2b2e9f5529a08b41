//! `ftcs-p1` and `ftcs-ordinates` on a paged medium (`lucent_core::PagedProblem`): the same
//! time steps as in memory with the state streamed slab by slab.
//!
//! Both schemes are one-slab-deep stencils on a state of k values per cell (P1: φ and E,
//! k = 4; ordinates: one radiance per direction, k = M) updated from the previous state
//! alone. The state lives twice in f64 pages of whole slabs (`lucent_paging::PagedSlabs`):
//! a step reads the old state through a ring of three slabs and writes the new one slab by
//! slab, with the cell update of the in-memory march (`p1::StepCoefficients::cell`,
//! `ordinates::cell_step`) and the step's reductions — the growth monitor's largest value,
//! the change and size norms — added as in memory (P1: runs of eight cells along x, the
//! run sums added exactly; ordinates: in cell order). Then the two swap. So
//! the stopping decisions and the fluence have the in-memory bits
//! (`crates/explicit/tests/it/paged_march.rs`).
//!
//! Sources are the point lights inside the grid (power 4πI into the cell that holds them;
//! a paged problem has no emission), kept as a sparse list. `ftcs-p1` takes a uniform
//! medium (checked from the fields' brick ranges) and reads one cell's coefficients;
//! `ftcs-ordinates` reads σ_t and the albedo slab by slab each step.

use std::collections::BTreeMap;
use std::sync::Arc;

use lucent_core::driver::{Coefficients, Record};
use lucent_core::{
    History, Light, PagedProblem, PagedSolution, Progress, SolveError, SolveOptions, SolveReport,
    StopReason, Stopping, paging_error,
};
use lucent_diffusion::slab::Window;
use lucent_optics::PhaseFunction;
use lucent_paging::{Eviction, FileStore, PagedSlabs, Pager, PagerOptions, PagingError};
use rayon::prelude::*;

use crate::ordinates::{Cell, cell_fluence, cell_step};
use crate::p1::StepCoefficients;
use crate::paged_steady::Ring;
use crate::steady::NORM_RUN;
use lucent_core::exact::ExactSum;

/// Which march, with its registry parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum March {
    /// Murray's P1 moments.
    P1 {
        layout: crate::p1::Layout,
        fraction: f64,
        allow_unstable: bool,
    },
    /// Upwind ordinates with isotropic scattering.
    Ordinates {
        order: usize,
        fraction: f64,
        allow_unstable: bool,
    },
}

/// The fewest pages of state the pool must hold: a pass pins one at a time; two keep the
/// read and the write that follows it resident.
const MIN_PAGES: usize = 2;

/// What [`solve`] needs before any work: the components of its state per cell, the
/// state's dims, the state's pool and the bytes in all: the medium's pool and every paged
/// field's bookkeeping, a pass's slabs (a ring of three old slabs and one new of the
/// state, the medium's slabs, the output's brick layer), and the state's pool in what is
/// left (at least [`MIN_PAGES`] pages).
pub(crate) fn march_needs(
    name: &str,
    march: March,
    problem: &PagedProblem,
    options: &SolveOptions,
) -> Result<(usize, [usize; 3], u64, u64), SolveError> {
    let geometry = *problem.geometry();
    let [nx, ny, nz] = geometry.dims();
    let slab = nx * ny;
    let layout = *problem.layout();
    let channels = problem.channels();
    let medium = problem.medium();
    let components = match march {
        March::P1 { .. } => 4,
        March::Ordinates { order, .. } => {
            lucent_optics::SphericalQuadrature::level_symmetric(order)
                .map_err(|e| SolveError::InvalidParameter {
                    name: "order".into(),
                    reason: e.to_string(),
                })?
                .len()
        }
    };

    // Memory before anything is allocated: the medium's pool and every paged field's
    // bookkeeping, a pass's slabs (a ring of three old slabs and one new of the state, the
    // medium's slabs, the output's brick layer), and the state's pool in what is left.
    let fields = medium.sigma_t.len() + medium.albedo.len() + channels;
    let pool32 = problem.pager().capacity() as u64 * layout.stored_len() as u64 * 4;
    let state_dims = [components * nx, ny, nz];
    let page_bytes = PagedSlabs::<f64>::page_len(state_dims, 1) as u64 * 8;
    let pages = 2 * nz as u64;
    let windows =
        slab as u64 * (4 * components as u64 * 8 + 4 * 4 + 8) + (slab * layout.brick()) as u64 * 4;
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
    Ok((components, state_dims, pool64, needed))
}

/// The paged solve.
pub(crate) fn solve(
    name: &str,
    march: March,
    problem: &PagedProblem,
    options: &SolveOptions,
) -> Result<PagedSolution, SolveError> {
    let started = std::time::Instant::now();
    let meter = lucent_core::memory::PeakMeter::start();
    let before = problem.pager().stats();
    let err = |e| paging_error(name, e);
    let geometry = *problem.geometry();
    let [nx, ny, nz] = geometry.dims();
    let slab = nx * ny;
    let layout = *problem.layout();
    let channels = problem.channels();
    let medium = problem.medium();
    let invalid = |reason: String| SolveError::InvalidParameter {
        name: "problem".into(),
        reason,
    };
    let h = geometry.spacing().x;
    let (components, state_dims, pool64, needed) = march_needs(name, march, problem, options)?;
    let state = Arc::new(
        Pager::new(
            Box::new(FileStore::create().map_err(err)?),
            0,
            PagedSlabs::<f64>::page_len(state_dims, 1),
            MIN_PAGES,
            PagerOptions {
                budget_bytes: pool64,
                eviction: Eviction::Lru,
                fill: 0.0f64,
            },
        )
        .map_err(err)?,
    );
    let mut now = PagedSlabs::<f64>::new(state.clone(), state_dims).map_err(err)?;
    let mut next = PagedSlabs::<f64>::new(state.clone(), state_dims).map_err(err)?;

    let mut fluence = Vec::with_capacity(channels);
    let mut record: Option<Record> = None;
    for c in 0..channels {
        let share = 1.0 / channels as f64;
        let mut stopping = Stopping::from_options(
            &options.progress_within(c as f64 * share, (c + 1) as f64 * share),
        );
        stopping.time_budget = options
            .time_budget
            .map(|t| t.saturating_sub(started.elapsed()));
        let stopping = stopping.with_stage("time step");
        now.clear().map_err(err)?;
        next.clear().map_err(err)?;
        let sources = point_sources(problem, c);
        if let Some((cell, q)) = sources.iter().find(|(_, q)| !q.is_finite()) {
            return Err(invalid(format!("source: {q} in cell {cell}")));
        }
        let channel = Channel {
            problem,
            index: c,
            components,
            sources: &sources,
            interrupt: stopping.interrupt(std::time::Instant::now()),
        };
        let rec = match march {
            March::P1 {
                layout,
                fraction,
                allow_unstable,
            } => {
                // Uniform (the capabilities ask for it): any cell's coefficients.
                let sigma_t = medium.sigma_t[c.min(medium.sigma_t.len() - 1)]
                    .uniform_value()
                    .ok_or_else(|| invalid("a heterogeneous medium".into()))?;
                let albedo = medium.albedo[c.min(medium.albedo.len() - 1)]
                    .uniform_value()
                    .ok_or_else(|| invalid("a heterogeneous albedo".into()))?;
                let g = medium.phase.mean_cosine();
                let floor = Coefficients::reduced_floor_of(&geometry);
                let [sigma_s, _, _] = Coefficients::at(sigma_t, albedo, g, floor);
                let settings = crate::solver::p1_settings(
                    [sigma_t, sigma_s],
                    g,
                    h,
                    (layout, fraction, allow_unstable),
                    stopping,
                )?;
                channel.p1(&settings, &mut now, &mut next)?
            }
            March::Ordinates {
                order,
                fraction,
                allow_unstable,
            } => {
                // The largest σ_t from the bricks' ranges (aprons hold copies of cells).
                let sigma_t = &medium.sigma_t[c.min(medium.sigma_t.len() - 1)];
                let k_max = (0..layout.count())
                    .filter_map(|id| sigma_t.brick_range(id))
                    .fold(0.0f64, |a, (_, hi)| a.max(f64::from(hi)));
                let (quadrature, settings) = crate::solver::ordinates_settings(
                    order,
                    k_max,
                    h,
                    (fraction, allow_unstable),
                    stopping,
                )?;
                channel.ordinates(&quadrature, k_max, &settings, &mut now, &mut next)?
            }
        };
        // The fluence of the state the march ended on, in f32.
        let out = problem.new_field().map_err(err)?;
        let mut state_slab = vec![0.0f64; components * slab];
        let b = layout.brick();
        for layer in 0..layout.bricks()[2] {
            let (z0, z1) = (layer * b, (layer * b + b).min(nz));
            let mut values = vec![0.0f32; slab * (z1 - z0)];
            for z in z0..z1 {
                now.read_slab(z, &mut state_slab).map_err(err)?;
                let row = &mut values[(z - z0) * slab..(z - z0 + 1) * slab];
                channel.fluence_of(&state_slab, march, row);
                if let Some(k) = row.iter().position(|v| !v.is_finite()) {
                    return Err(SolveError::NonFiniteOutput {
                        solver: name.into(),
                        what: "fluence",
                        channel: c,
                        cell: [k % nx, k / nx, z],
                        value: row[k],
                    });
                }
            }
            out.write_slabs(z0, &values).map_err(err)?;
        }
        fluence.push(out);
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
    Ok(PagedSolution {
        fluence,
        standard_error: Vec::new(),
        transmittance: Vec::new(),
        isotropic_fluence: Vec::new(),
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

/// The point lights of channel `c` as sources per cell (power per volume), in the cells
/// that hold them, added in the lights' order: the in-memory `point_and_emission`.
fn point_sources(problem: &PagedProblem, c: usize) -> BTreeMap<usize, f64> {
    let g = problem.geometry();
    let mut q = BTreeMap::new();
    for light in problem.lights() {
        if let Light::Point {
            position,
            intensity,
        } = light
        {
            let power = 4.0 * std::f64::consts::PI * intensity.channel(c);
            let v = g.world_to_voxel(*position) + 0.5;
            let [i, j, k] = [0, 1, 2].map(|a| (v[a].max(0.0) as usize).min(g.dims()[a] - 1));
            *q.entry(g.index(i, j, k)).or_insert(0.0) += power / g.cell_volume();
        }
    }
    q
}

/// One channel's march.
struct Channel<'a> {
    problem: &'a PagedProblem,
    index: usize,
    components: usize,
    sources: &'a BTreeMap<usize, f64>,
    /// Ctrl-C and the time limit, asked every slab of a pass.
    interrupt: lucent_core::Interrupt,
}

/// A step's computation of slab z: `(z, old slabs around it, its sources, new slab)`.
type SlabStep<'a> =
    dyn FnMut(usize, &Window<'_, f64>, &[f64], &mut [f64]) -> Result<(), PagingError> + 'a;

/// The neighbours of cell (i, j) of a window of slabs of `k` values per cell: per axis the
/// block below and above (`None` beyond the grid).
#[inline]
fn blocks<'w>(
    window: &Window<'w, f64>,
    [nx, ny]: [usize; 2],
    k: usize,
    i: usize,
    j: usize,
) -> [[Option<&'w [f64]>; 2]; 3] {
    let cell = |slab: &'w [f64], index: usize| &slab[index * k..(index + 1) * k];
    let index = i + nx * j;
    [
        [
            (i > 0).then(|| cell(window.here, index - 1)),
            (i + 1 < nx).then(|| cell(window.here, index + 1)),
        ],
        [
            (j > 0).then(|| cell(window.here, index - nx)),
            (j + 1 < ny).then(|| cell(window.here, index + nx)),
        ],
        [
            window.below.map(|s| cell(s, index)),
            window.above.map(|s| cell(s, index)),
        ],
    ]
}

/// What a step's pass found: per monitored field (in the order the in-memory march checks
/// them) whether it is finite and its largest magnitude, and the step's sums.
#[derive(Debug, Default)]
struct Sums {
    finite: Vec<bool>,
    largest: Vec<f64>,
    change: f64,
}

impl Sums {
    fn new(fields: usize) -> Self {
        Self {
            finite: vec![true; fields],
            largest: vec![0.0; fields],
            change: 0.0,
        }
    }

    fn see(&mut self, field: usize, v: f64) {
        if !v.is_finite() {
            self.finite[field] = false;
        } else {
            self.largest[field] = self.largest[field].max(v.abs());
        }
    }

    /// The growth monitor's verdict, field by field in order.
    fn verdict(&self, monitor: &crate::GrowthMonitor, step: usize) -> Option<StopReason> {
        self.finite
            .iter()
            .zip(&self.largest)
            .find_map(|(&finite, &largest)| {
                if finite {
                    monitor.check_largest(largest, step)
                } else {
                    Some(StopReason::DivergedNonFinite { iteration: step })
                }
            })
    }
}

impl Channel<'_> {
    /// Slab `z`'s sources (power per volume per cell).
    fn source_slab(&self, z: usize, out: &mut [f64]) {
        let slab = out.len();
        out.fill(0.0);
        for (&cell, &q) in self.sources.range(z * slab..(z + 1) * slab) {
            out[cell - z * slab] = q;
        }
    }

    /// One step: the new state from the old slab by slab, `compute(z, window, sources,
    /// out)` computing slab z, `reduce(old, new)` seeing each slab in order.
    fn pass(
        &self,
        now: &PagedSlabs<f64>,
        next: &PagedSlabs<f64>,
        ring: &mut Ring<f64>,
        compute: &mut SlabStep<'_>,
        reduce: &mut dyn FnMut(&[f64], &[f64]),
    ) -> Result<Option<lucent_core::Halt>, PagingError> {
        let [_, _, nz] = self.problem.geometry().dims();
        let slab = now.slab_len() / self.components;
        let mut q = vec![0.0f64; slab];
        let mut out = vec![0.0f64; now.slab_len()];
        ring.held = [None; 3];
        for z in 0..nz {
            // Stopped part way, `now` still holds the last whole step.
            if let Some(halt) = self.interrupt.halt() {
                return Ok(Some(halt));
            }
            ring.hold_around(z, nz, &mut |w, buffer: &mut [f64]| now.read_slab(w, buffer))?;
            self.source_slab(z, &mut q);
            let window = ring.window(z, nz);
            compute(z, &window, &q, &mut out)?;
            reduce(window.here, &out);
            next.write_slab(z, &out)?;
        }
        Ok(None)
    }

    /// P1 from zero: [`crate::p1::march`] with zero edges, paged.
    fn p1(
        &self,
        settings: &crate::p1::P1Settings,
        now: &mut PagedSlabs<f64>,
        next: &mut PagedSlabs<f64>,
    ) -> Result<Record, SolveError> {
        let err = |e| paging_error("ftcs-p1", e);
        let [nx, ny, _] = self.problem.geometry().dims();
        let step_of = StepCoefficients::checked(settings, self.problem.geometry().spacing().x)
            .map_err(crate::solver::explicit_error)?;
        let largest_source = self.sources.values().fold(0.0f64, |a, b| a.max(b.abs()));
        let monitor = crate::p1::growth_monitor(0.0, largest_source, settings);
        let mut ring = Ring::new(now.slab_len());
        let mut history = History::start();
        let mut step = 0;
        let mut compute = |_z: usize, window: &Window<'_, f64>, q: &[f64], out: &mut [f64]| {
            out.par_chunks_mut(4 * nx).enumerate().for_each(|(j, row)| {
                for (i, o) in row.chunks_mut(4).enumerate() {
                    let index = i + nx * j;
                    let here = &window.here[4 * index..4 * index + 4];
                    let around = blocks(window, [nx, ny], 4, i, j);
                    let value = |component: usize, axis: usize, offset: isize| {
                        if offset == 0 {
                            here[component]
                        } else {
                            around[axis][usize::from(offset > 0)].map_or(0.0, |b| b[component])
                        }
                    };
                    o.copy_from_slice(&step_of.cell(q[index], value));
                }
            });
            Ok(())
        };
        loop {
            step += 1;
            let mut sums = Sums::new(4);
            let (mut change, mut size) = (ExactSum::new(), ExactSum::new());
            let halted = self
                .pass(now, next, &mut ring, &mut compute, &mut |old, new| {
                    for n in new.chunks(4) {
                        for (field, v) in n.iter().enumerate() {
                            sums.see(field, *v);
                        }
                    }
                    // The norm's runs of eight cells along x, each left to right, the run
                    // sums added exactly (as `p1::march` sums them).
                    let line = 4 * nx;
                    for (o, n) in old.chunks(line).zip(new.chunks(line)) {
                        for (o, n) in o.chunks(4 * NORM_RUN).zip(n.chunks(4 * NORM_RUN)) {
                            let (c, z) = o
                                .chunks(4)
                                .zip(n.chunks(4))
                                .fold((0.0, 0.0), |(c, z), (o, n)| {
                                    (c + (n[0] - o[0]).powi(2), z + n[0] * n[0])
                                });
                            change.add(c);
                            size.add(z);
                        }
                    }
                })
                .map_err(err)?;
            if let Some(halt) = halted {
                let changes = history.residuals().to_vec();
                let last = changes.last().copied().unwrap_or(1.0);
                return Ok(p1_record(
                    self.problem,
                    step - 1,
                    halt.stop_reason(last),
                    changes,
                ));
            }
            if let Some(stop_reason) = sums.verdict(&monitor, step) {
                let changes = history.residuals().to_vec();
                return Ok(p1_record(self.problem, step, stop_reason, changes));
            }
            let (change, last_change) = crate::p1::change_norms(&change, &size);
            std::mem::swap(now, next);
            if let Some(stop_reason) =
                history.record_step(&settings.stopping, step, last_change, change.sqrt())
            {
                let changes = history.into_residuals();
                return Ok(p1_record(self.problem, step, stop_reason, changes));
            }
        }
    }

    /// Upwind ordinates from zero: [`crate::ordinates::march`], paged.
    fn ordinates(
        &self,
        quadrature: &lucent_optics::SphericalQuadrature,
        sigma_t_max: f64,
        settings: &crate::ordinates::OrdinatesSettings,
        now: &mut PagedSlabs<f64>,
        next: &mut PagedSlabs<f64>,
    ) -> Result<Record, SolveError> {
        let err = |e| paging_error("ftcs-ordinates", e);
        let geometry = *self.problem.geometry();
        let [nx, ny, _] = geometry.dims();
        let medium = self.problem.medium();
        let c = self.index;
        let m = self.components;
        let r = crate::ordinates::checked_ratio(
            quadrature,
            sigma_t_max,
            settings,
            geometry.spacing().x,
        )
        .map_err(crate::solver::explicit_error)?;
        let dt = settings.time_step;
        let (dirs, weights) = (quadrature.directions(), quadrature.weights());
        // Σ q² in cell order: the sparse sources' squares in order (zeros add nothing).
        let q_norm = self
            .sources
            .values()
            .map(|q| q * q)
            .sum::<f64>()
            .sqrt()
            .max(f64::MIN_POSITIVE);
        let largest_source = self.sources.values().fold(0.0f64, |a, b| a.max(b.abs()));
        let monitor = crate::ordinates::growth_monitor(largest_source, settings);
        let g = medium.phase.mean_cosine();
        let floor = Coefficients::reduced_floor_of(&geometry);
        let slab = nx * ny;
        let mut sigma_t = vec![0.0f32; slab];
        let mut albedo = vec![0.0f32; slab];
        let mut coefficients = vec![(0.0f64, 0.0f64); slab];
        let mut ring = Ring::new(now.slab_len());
        let mut history = History::start();
        let mut step = 0;
        let stop_reason = loop {
            step += 1;
            let mut sums = Sums::new(1);
            // The medium slab by slab, read as the pass comes to it.
            let mut compute = |z: usize, window: &Window<'_, f64>, q: &[f64], out: &mut [f64]| {
                medium.sigma_t[c.min(medium.sigma_t.len() - 1)].read_slabs(
                    z,
                    z + 1,
                    &mut sigma_t,
                )?;
                medium.albedo[c.min(medium.albedo.len() - 1)].read_slabs(z, z + 1, &mut albedo)?;
                for ((o, t), a) in coefficients.iter_mut().zip(&sigma_t).zip(&albedo) {
                    let [s, _, _] = Coefficients::at(*t, *a, g, floor);
                    *o = (f64::from(*t), f64::from(s));
                }
                let coefficients = &coefficients;
                out.par_chunks_mut(m * nx).enumerate().for_each(|(j, row)| {
                    for (i, o) in row.chunks_mut(m).enumerate() {
                        let index = i + nx * j;
                        let here = &window.here[m * index..m * (index + 1)];
                        let (sigma_t, sigma_s) = coefficients[index];
                        let cell = Cell {
                            sigma_t,
                            sigma_s,
                            source: q[index],
                            phi: cell_fluence(here, weights),
                        };
                        cell_step(
                            dirs,
                            dt,
                            r,
                            &cell,
                            here,
                            &blocks(window, [nx, ny], m, i, j),
                            o,
                        );
                    }
                });
                Ok(())
            };
            let halted = self
                .pass(now, next, &mut ring, &mut compute, &mut |old, new| {
                    for (o, n) in old.chunks(m).zip(new.chunks(m)) {
                        for v in n {
                            sums.see(0, *v);
                        }
                        let change = cell_fluence(n, weights) - cell_fluence(o, weights);
                        sums.change += change * change;
                    }
                })
                .map_err(err)?;
            if let Some(halt) = halted {
                step -= 1;
                break halt.stop_reason(history.last().min(1.0));
            }
            if let Some(stop_reason) = sums.verdict(&monitor, step) {
                break stop_reason;
            }
            let change = sums.change.sqrt();
            let residual = change / (dt * q_norm);
            std::mem::swap(now, next);
            if let Some(stop_reason) =
                history.record_step(&settings.stopping, step, residual, change)
            {
                break stop_reason;
            }
        };
        Ok(Record {
            iterations: step,
            residuals: history.into_residuals(),
            stop_reason,
            memory_bytes: (geometry.voxel_count() * m * 16) as u64,
            paging: None,
        })
    }

    /// The fluence (f32) of a slab of the state.
    fn fluence_of(&self, state: &[f64], march: March, out: &mut [f32]) {
        let k = self.components;
        match march {
            March::P1 { .. } => {
                for (o, cell) in out.iter_mut().zip(state.chunks(k)) {
                    *o = cell[0] as f32;
                }
            }
            March::Ordinates { order, .. } => {
                let quadrature = lucent_optics::SphericalQuadrature::level_symmetric(order)
                    .expect("checked before the march");
                for (o, cell) in out.iter_mut().zip(state.chunks(k)) {
                    *o = cell_fluence(cell, quadrature.weights()) as f32;
                }
            }
        }
    }
}

/// P1's record, as the in-memory march reports it: the history is every step's relative
/// change of φ (`P1State::changes`).
fn p1_record(
    problem: &PagedProblem,
    steps: usize,
    stop_reason: StopReason,
    changes: Vec<f64>,
) -> Record {
    let mut record = Record::exact((problem.geometry().voxel_count() * 8 * 8) as u64);
    record.iterations = steps;
    record.stop_reason = stop_reason;
    record.residuals = changes;
    record
}
