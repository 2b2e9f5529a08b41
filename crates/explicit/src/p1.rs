//! Murray's P1 moment system with FTCS (thesis §3.4.2, Eqs. 3.23–3.26; its stability in docs/reference-cases.md):
//!
//! (1/c) ∂φ/∂t = −∇·E − σ_a φ + q,    (1/c) ∂E/∂t = −∇φ/3 − σ_t′ E,
//!
//! marched with forward Euler, r = cΔt/h, damping per step K_φ = cΔt σ_a, K_E = cΔt σ_t′
//! ([`Damping::Consistent`]; the thesis's update uses cΔt σ_t on both, [`Damping::Murray`]).
//!
//! - [`Layout::Collocated`]: φ and E at cell centres, central differences
//!   δf = f_{i+1} − f_{i−1}. A site couples only to sites two cells away, so the odd and
//!   even sub-lattices decouple: from a point source φ stays exactly zero on the sites of
//!   the other parity (the checkerboard of the thesis's Fig. 3.6).
//! - [`Layout::Staggered`]: φ at centres, each E component on the faces normal to it
//!   (MAC/Yee), one-cell differences: the sub-lattices are coupled and the checkerboard is
//!   gone.
//!
//! Stability ([`crate::stability::p1`]): collocated (1 − K_φ)(1 − K_E) + r² ≤ 1, staggered
//! (1 − K_φ)(1 − K_E) + 4r² ≤ 1; the thesis's "K < 1 and r/2 < 1" is not sufficient.
//! Periodic edges (studies) or zero beyond the grid.
//!
//! The step's change norm, ‖φ′ − φ‖ / ‖φ′‖, sums the squares over runs of eight cells
//! along x (each run left to right) and adds the run sums exactly
//! ([`lucent_core::exact::ExactSum`]), as the steady iterations do: any split of the grid
//! into slabs or boxes whose x cuts fall at multiples of eight sums the same runs, so the
//! ranks' history is the serial bits (`docs/ranks.md`).

use std::ops::Range;

use lucent_core::exact::ExactSum;
use lucent_core::{History, StopReason, Stopping};
use rayon::prelude::*;

use crate::error::ExplicitError;
use crate::lattice::{GrowthMonitor, Lattice};
use crate::steady::NORM_RUN;

/// Where the flux lives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Layout {
    /// φ and E at cell centres.
    Collocated,
    /// E_a on the faces normal to axis a (index i: the face between i and i + 1).
    Staggered,
}

/// The damping rates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Damping {
    /// σ_a on φ, σ_t′ on E (Eqs. 3.23–3.24).
    Consistent {
        /// σ_a (1/length).
        sigma_a: f64,
        /// σ_t′ = σ_a + (1 − g)σ_s (1/length).
        sigma_t_reduced: f64,
    },
    /// σ_t on both, as the thesis's update (Eqs. 3.25–3.26) has it.
    Murray {
        /// σ_t (1/length).
        sigma_t: f64,
    },
}

/// The P1 state.
#[derive(Debug, Clone, PartialEq)]
pub struct P1State {
    /// φ per cell.
    pub fluence: Vec<f64>,
    /// E_x, E_y, E_z per cell (collocated) or per face (staggered).
    pub flux: [Vec<f64>; 3],
    /// Steps run.
    pub steps: usize,
    /// The relative change ‖φ′ − φ‖/‖φ′‖ of each step taken (the stopping rule's
    /// residual).
    pub changes: Vec<f64>,
    /// Why it stopped.
    pub stop_reason: StopReason,
}

/// What lies beyond the grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum P1Edges {
    /// Periodic (stability studies).
    #[default]
    Periodic,
    /// φ = 0 and E = 0 beyond the grid (a crude vacuum).
    Zero,
}

/// Settings of [`march`].
#[derive(Debug, Clone, PartialEq)]
pub struct P1Settings {
    /// Grid layout.
    pub layout: Layout,
    /// Damping.
    pub damping: Damping,
    /// cΔt (length).
    pub time_step: f64,
    /// When to stop: the residual is ‖φ′ − φ‖/‖φ′‖ per step (relative tolerance 0: run
    /// every step), `max_iterations` the most steps.
    pub stopping: Stopping,
    /// Beyond the grid.
    pub edges: P1Edges,
    /// Run beyond the von Neumann bound (studies).
    pub allow_unstable: bool,
}

impl P1Settings {
    /// (K_φ, K_E) per step.
    pub fn damping_per_step(&self) -> (f64, f64) {
        match self.damping {
            Damping::Consistent {
                sigma_a,
                sigma_t_reduced,
            } => (self.time_step * sigma_a, self.time_step * sigma_t_reduced),
            Damping::Murray { sigma_t } => (self.time_step * sigma_t, self.time_step * sigma_t),
        }
    }
}

/// What one FTCS step of P1 needs besides the state: the layout, the damping per step
/// (K_φ, K_E), r = cΔt/h and cΔt.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct StepCoefficients {
    pub(crate) layout: Layout,
    pub(crate) k_phi: f64,
    pub(crate) k_flux: f64,
    pub(crate) r: f64,
    pub(crate) dt: f64,
}

/// The growth monitor of a march from a state whose largest magnitude is `initial` with
/// sources of largest magnitude `source`: a stable run stays below the initial state plus
/// every step's source.
pub(crate) fn growth_monitor(initial: f64, source: f64, settings: &P1Settings) -> GrowthMonitor {
    GrowthMonitor {
        reference: initial
            + source * settings.time_step * settings.stopping.max_iterations.min(1 << 40) as f64
            + f64::MIN_POSITIVE,
        factor: 1e6,
    }
}

impl StepCoefficients {
    /// The step of `settings` on cells of width `spacing`, checked: a positive finite
    /// time step, damping rates ≥ 0, and (unless `allow_unstable`) r within the layout's
    /// von Neumann bound and K ≤ 2.
    pub(crate) fn checked(settings: &P1Settings, spacing: f64) -> Result<Self, ExplicitError> {
        let dt = settings.time_step;
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(ExplicitError::Invalid(format!("time step {dt}")));
        }
        let (k_phi, k_flux) = settings.damping_per_step();
        if !(k_phi >= 0.0 && k_flux >= 0.0) {
            return Err(ExplicitError::Invalid("damping rates must be ≥ 0".into()));
        }
        let r = dt / spacing;
        let limit = match settings.layout {
            Layout::Collocated => crate::stability::p1::collocated_limit(k_phi, k_flux),
            Layout::Staggered => crate::stability::p1::staggered_limit(k_phi, k_flux),
        };
        let unstable = r > limit * (1.0 + 1e-12) || k_phi > 2.0 || k_flux > 2.0;
        if unstable && !settings.allow_unstable {
            return Err(ExplicitError::Unstable {
                scheme: "P1 FTCS",
                parameter: "r = cΔt/h",
                limit: limit * spacing,
                requested: dt,
            });
        }
        Ok(Self {
            layout: settings.layout,
            k_phi,
            k_flux,
            r,
            dt,
        })
    }

    /// One step at one cell of source `q`: (φ′, E′_x, E′_y, E′_z) from `value(c, axis,
    /// offset)`, component c (0: φ, 1–3: E along x, y, z) of the cell `offset` ∈ {−1, 0, 1}
    /// cells away along `axis` (0 beyond a zero edge). The one definition of the update,
    /// for the in-memory march and the paged one.
    #[inline]
    pub(crate) fn cell(&self, q: f64, value: impl Fn(usize, usize, isize) -> f64) -> [f64; 4] {
        let divergence: f64 = (0..3)
            .map(|a| match self.layout {
                Layout::Collocated => 0.5 * (value(1 + a, a, 1) - value(1 + a, a, -1)),
                Layout::Staggered => value(1 + a, a, 0) - value(1 + a, a, -1),
            })
            .sum();
        let phi = value(0, 0, 0);
        let mut out = [
            (1.0 - self.k_phi) * phi - self.r * divergence + self.dt * q,
            0.0,
            0.0,
            0.0,
        ];
        for a in 0..3 {
            let gradient = match self.layout {
                Layout::Collocated => 0.5 * (value(0, a, 1) - value(0, a, -1)),
                Layout::Staggered => value(0, a, 1) - phi,
            };
            out[1 + a] = (1.0 - self.k_flux) * value(1 + a, a, 0) - self.r * gradient / 3.0;
        }
        out
    }
}

/// Runs up to `settings.stopping.max_iterations` FTCS steps from zero with source `q` (fluence per length per
/// step unit) on a periodic grid, or from `initial` (φ, E) when given.
pub fn march(
    lattice: &Lattice,
    source: &[f64],
    settings: &P1Settings,
    initial: Option<(Vec<f64>, [Vec<f64>; 3])>,
) -> Result<P1State, ExplicitError> {
    lattice.check_field("source", source)?;
    let step_of = StepCoefficients::checked(settings, lattice.spacing)?;
    let n = lattice.len();
    let (mut phi, mut flux) = match initial {
        Some((p, f)) => {
            lattice.check_field("initial fluence", &p)?;
            for e in &f {
                lattice.check_field("initial flux", e)?;
            }
            (p, f)
        }
        None => (vec![0.0; n], [vec![0.0; n], vec![0.0; n], vec![0.0; n]]),
    };
    let largest = |v: &[f64]| v.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    let monitor = growth_monitor(
        largest(&phi) + flux.iter().map(|f| largest(f)).fold(0.0, f64::max),
        largest(source),
        settings,
    );
    let mut history = History::start();
    let mut step = 0;
    let [nx, ny, nz] = lattice.dims;
    let whole = [0..nx, 0..ny, 0..nz];
    let region = Region {
        dims: lattice.dims,
        origin: [0; 3],
        held: lattice.dims,
    };
    let runs = box_runs([0; 3], lattice.dims, &whole);
    let (mut next_phi, mut next_flux) = (vec![0.0; n], [vec![0.0; n], vec![0.0; n], vec![0.0; n]]);
    loop {
        step += 1;
        step_box(
            &step_of,
            settings.edges,
            &region,
            (&phi, &flux),
            (&mut next_phi, &mut next_flux),
            source,
            &whole,
            None,
        );
        let stop = monitor
            .check(&next_phi, step)
            .or_else(|| next_flux.iter().find_map(|f| monitor.check(f, step)));
        if let Some(stop_reason) = stop {
            return Ok(P1State {
                fluence: phi,
                flux,
                steps: step,
                changes: history.residuals().to_vec(),
                stop_reason,
            });
        }
        let (change, size) = change_sums(&next_phi, &phi, &runs);
        let (change, last_change) = change_norms(&change, &size);
        std::mem::swap(&mut phi, &mut next_phi);
        std::mem::swap(&mut flux, &mut next_flux);
        if let Some(stop_reason) =
            history.record_step(&settings.stopping, step, last_change, change.sqrt())
        {
            return Ok(P1State {
                fluence: phi,
                flux,
                steps: step,
                changes: history.residuals().to_vec(),
                stop_reason,
            });
        }
    }
}

/// Fields held over a box of a grid's cells: `held` cells from `origin` (x fastest), of a
/// grid of `dims` (a rank's box grown by a cell; the whole grid in one process).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Region {
    /// The whole grid's cells.
    pub dims: [usize; 3],
    /// The first cell held.
    pub origin: [usize; 3],
    /// The cells held along each axis.
    pub held: [usize; 3],
}

impl Region {
    /// Where cell `p` (grid coordinates) lies in the held fields.
    #[inline]
    pub(crate) fn place(&self, p: [usize; 3]) -> usize {
        (p[0] - self.origin[0])
            + self.held[0] * ((p[1] - self.origin[1]) + self.held[1] * (p[2] - self.origin[2]))
    }
}

/// One FTCS step of the cells `cells` (less those of `skip`): `next` (φ, E) from `now`,
/// fields and `source` held over `region`; a cell's neighbour beyond the grid is zero or
/// wraps round (`edges`; wrapping needs the whole axis held). The one cell loop of the
/// march, in one process and on ranks, in parallel over z-layers (each cell's update is
/// independent: the same bits on any number of threads).
#[allow(clippy::too_many_arguments)]
pub(crate) fn step_box(
    step_of: &StepCoefficients,
    edges: P1Edges,
    region: &Region,
    (phi, flux): (&[f64], &[Vec<f64>; 3]),
    (next_phi, next_flux): (&mut [f64], &mut [Vec<f64>; 3]),
    source: &[f64],
    cells: &[Range<usize>; 3],
    skip: Option<&[Range<usize>; 3]>,
) {
    let Region { dims, origin, held } = *region;
    let stride = [1, held[0], held[0] * held[1]];
    let layer = stride[2];
    let [f0, f1, f2] = next_flux;
    // In parallel over the held layers (each writes only its own cells).
    next_phi
        .par_chunks_mut(layer)
        .zip(f0.par_chunks_mut(layer))
        .zip(f1.par_chunks_mut(layer))
        .zip(f2.par_chunks_mut(layer))
        .enumerate()
        .filter(|(t, _)| cells[2].contains(&(origin[2] + t)))
        .for_each(|(t, (((next_phi, f0), f1), f2))| {
            let k = origin[2] + t;
            let first = t * layer;
            // Cells whose six neighbours are all in the grid read them at fixed strides
            // (no edge rule to apply); the rest, by the general reader below.
            let inner_layer = k > 0 && k + 1 < dims[2];
            let fields = [phi, &flux[0][..], &flux[1][..], &flux[2][..]];
            let strides = stride.map(|s| s as isize);
            for j in cells[1].clone() {
                let skipped = skip
                    .filter(|s| s[1].contains(&j) && s[2].contains(&k))
                    .map_or(0..0, |s| s[0].clone());
                let inner = if inner_layer && j > 0 && j + 1 < dims[1] {
                    1..dims[0] - 1
                } else {
                    0..0
                };
                // The held row's first cell, at x = origin[0].
                let row = region.place([origin[0], j, k]);
                let mut write = |l: usize, out: [f64; 4]| {
                    let at = l - first;
                    next_phi[at] = out[0];
                    f0[at] = out[1];
                    f1[at] = out[2];
                    f2[at] = out[3];
                };
                let x = &cells[0];
                // The row's cells less the skipped ones: up to two runs.
                let runs = [
                    x.start..skipped.start.clamp(x.start, x.end),
                    skipped.end.clamp(x.start, x.end)..x.end,
                ];
                for run in runs {
                    // Each run: general cells, inner cells, general cells.
                    let from = inner.start.clamp(run.start, run.end);
                    let to = inner.end.clamp(from, run.end);
                    for i in (run.start..from).chain(to..run.end) {
                        let p = [i, j, k];
                        let l = row + (i - origin[0]);
                        write(
                            l,
                            step_of.cell(source[l], |component, axis, offset| {
                                let field = fields[component];
                                if offset == 0 {
                                    return field[l];
                                }
                                let n = dims[axis] as isize;
                                let to = p[axis] as isize + offset;
                                let moved = match edges {
                                    P1Edges::Periodic => to.rem_euclid(n),
                                    P1Edges::Zero if (0..n).contains(&to) => to,
                                    P1Edges::Zero => return 0.0,
                                } as usize;
                                field[l + (moved - origin[axis]) * stride[axis]
                                    - (p[axis] - origin[axis]) * stride[axis]]
                            }),
                        );
                    }
                    for l in row + (from - origin[0])..row + (to - origin[0]) {
                        write(
                            l,
                            step_of.cell(source[l], |component, axis, offset| {
                                fields[component][l.wrapping_add_signed(offset * strides[axis])]
                            }),
                        );
                    }
                }
            }
        });
}

/// The norm's runs of the box of cells `cells` in fields that hold the box of `held`
/// cells from `origin` (x fastest): each x-line of `cells` cut where the whole grid's x is
/// a multiple of [`NORM_RUN`], as [start, end) positions in the fields.
pub(crate) fn box_runs(
    origin: [usize; 3],
    held: [usize; 3],
    cells: &[Range<usize>; 3],
) -> Vec<(usize, usize)> {
    let mut runs = Vec::new();
    for k in cells[2].clone() {
        for j in cells[1].clone() {
            let line = held[0] * ((j - origin[1]) + held[1] * (k - origin[2]));
            let mut x = cells[0].start;
            while x < cells[0].end {
                let end = ((x / NORM_RUN + 1) * NORM_RUN).min(cells[0].end);
                runs.push((line + x - origin[0], line + end - origin[0]));
                x = end;
            }
        }
    }
    runs
}

/// (Σ (φ′ − φ)², Σ φ′²) over `runs` of `next` and `now`, each run left to right, the run
/// sums added exactly.
pub(crate) fn change_sums(
    next: &[f64],
    now: &[f64],
    runs: &[(usize, usize)],
) -> (ExactSum, ExactSum) {
    // In parallel over blocks of runs: each run's sums are the same f64 sums, and the
    // exact accumulators merge in any order to the same bits.
    runs.par_chunks(1024)
        .map(|runs| {
            let (mut change, mut size) = (ExactSum::new(), ExactSum::new());
            for &(s, e) in runs {
                let (c, z) = next[s..e]
                    .iter()
                    .zip(&now[s..e])
                    .fold((0.0, 0.0), |(c, z), (a, b)| {
                        (c + (a - b).powi(2), z + a * a)
                    });
                change.add(c);
                size.add(z);
            }
            (change, size)
        })
        .reduce(
            || (ExactSum::new(), ExactSum::new()),
            |(mut c, mut z), (c2, z2)| {
                c.merge(&c2);
                z.merge(&z2);
                (c, z)
            },
        )
}

/// (Σ (φ′ − φ)², the step's relative change ‖φ′ − φ‖ / ‖φ′‖, or the absolute one while
/// φ′ is zero) from the exact sums of squares.
pub(crate) fn change_norms(change: &ExactSum, size: &ExactSum) -> (f64, f64) {
    let (change, size) = (change.value(), size.value());
    let relative = if size > 0.0 {
        (change / size).sqrt()
    } else {
        change.sqrt()
    };
    (change, relative)
}
