//! `auto`: the cheapest solver expected to meet a requested accuracy, chosen from measured
//! error against time.
//!
//! A user asks for a relative L2 error of the total fluence (`tolerance = 0.02`); `auto`
//! answers with one of the registry's CPU solvers and its knobs (direct light only,
//! diffusion, discrete ordinates of order N, Monte Carlo with a path count, ...), runs it
//! and says in [`lucent_core::SolveReport::choice`] what it ran and why.
//!
//! The choice is a nearest-neighbour rule in regime space over a table of measurements,
//! never hand-tuned numbers:
//!
//! 1. The problem's [`Features`]: its size in transport mean free paths, its absorption
//!    1 − α′ (reduced albedo α′), the phase function's g, the mean reduced optical distance
//!    to the box or void, the σ_t′-weighted mean extinction depth from the lights, the void
//!    share, the boundary's Robin factor A (the refractive mismatch), whether its lights
//!    are point-like (a singular source), and the transport mean free paths one cell spans
//!    (what every grid method's discretisation error grows with): from [`lucent_core::regime::Regime`], averaged over
//!    channels. These are what decides diffusion's error (its boundary layer, its
//!    absorption and source limits), the ordinates' ray effects and the share of uncollided
//!    light.
//! 2. The suite scenes that decide: the nearest in those features ([`Features::distance`],
//!    decades of the scale quantities, so that a factor counts the same everywhere) when the
//!    problem is that scene (closer than [`SAME_SCENE`]); otherwise every scene within
//!    [`NEIGHBOUR_FACTOR`] × the nearest distance + [`NEIGHBOUR_SLACK`], each run counting
//!    with its worst error among them.
//! 3. Their measured points ([`Table`]): every run of [`crate::pareto::runs`], its
//!    wall time and its relative L2 error against the scene's *total* fluence reference
//!    (the error of `direct`'s uncollided fluence too: where scattering is negligible,
//!    direct light alone is the cheapest answer). `cargo xtask pareto` measures them and
//!    writes the table, `docs/pareto/auto.csv`, which is compiled in.
//! 4. The fastest of the nearest scene's runs whose expected error is at most the
//!    tolerance (at most [`UNSEEN_MARGIN`] of it for a problem that is none of the
//!    scenes), whose solver admits the problem ([`Solver::admits`]: `auto` never runs a
//!    solver that refuses it) and whose time, scaled by the problem's cell count over the
//!    scene's, fits the time budget. When none qualifies, the admitted run with the
//!    smallest expected error within the budget runs, and the report says the tolerance
//!    cannot be met, with the error expected.
//!
//! The three constants of step 2 and 4 are the rule's only numbers; they were set by
//! leaving each suite scene out of the table in turn and asking whether the rule's choice
//! from the others meets the tolerance on it (`docs/validation.md` has the outcome: with
//! the nearest scene alone, 14 of 44 such choices missed a tolerance they promised; with
//! the neighbours and the margin, none on the table it was set on). They trade cost for
//! safety on scenes the table has not seen: a measured scene is its own decider and runs
//! at the cost of its fastest meeting run.
//!
//! The GPU twins are not candidates: their table times are the software rasteriser's
//! (lavapipe) on the machine that measured, and their errors are their CPU twins'.
//! The expected error is the deciding scenes': a problem far from every suite scene (the
//! distances are in the report) gets the rule's best guess, and `docs/validation.md`
//! charts how far the guess carries by choosing for each suite scene with that scene's own
//! rows left out of the table.

use std::fmt;
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use lucent_core::regime::Regime;
use lucent_core::{
    Capabilities, Composition, Decision, FluenceKind, Light, Neighbour, OutputKind, ParamValue,
    Params, Problem, Registry, Solution, SolveError, SolveOptions, Solver, SolverEntry,
    SolverParams, param_docs, resolved_params,
};
use lucent_grid::resample::restrict;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::pareto::{Run, runs};

/// The measured table `auto` chooses from: `docs/pareto/auto.csv`, written by
/// `cargo xtask pareto`.
pub const TABLE_CSV: &str = include_str!("../docs/pareto/auto.csv");

/// The columns of [`TABLE_CSV`].
pub const TABLE_HEADER: &str = "scene,cells,size_mfp,absorption,g,boundary_mfp,light_depth,empty,robin,point_lights,cell_depth,solver,setting,seconds,error_total";

/// The parameters of `auto`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AutoParams {
    /// The relative L2 error of the total fluence to meet.
    pub tolerance: f64,
}

impl Default for AutoParams {
    fn default() -> Self {
        Self { tolerance: 0.02 }
    }
}

impl SolverParams for AutoParams {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[(
        "tolerance",
        "the relative L2 error of the total fluence to meet, in (0, 1) (0.02: two per cent)",
    )];

    fn validate(&self) -> Result<(), SolveError> {
        if !(self.tolerance > 0.0 && self.tolerance < 1.0) {
            return Err(SolveError::InvalidParameter {
                name: "tolerance".into(),
                reason: format!(
                    "{} is not a relative error in (0, 1) (0.02 is two per cent)",
                    self.tolerance
                ),
            });
        }
        Ok(())
    }
}

/// Where a problem lies in regime space: what decides which model is accurate enough.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Features {
    /// The box's longest side times the medium's mean σ_t′: its size in transport mean free
    /// paths.
    pub size_mfp: f64,
    /// 1 − α′ over the medium (σ_a / σ_t′): how much a transport mean free path absorbs.
    pub absorption: f64,
    /// The phase function's mean cosine.
    pub g: f64,
    /// Mean reduced optical distance from the medium to the box or void, ℓ′.
    pub boundary_mfp: f64,
    /// σ_t′-weighted mean extinction depth from the nearest light (mean free paths, capped
    /// at 50).
    pub light_depth: f64,
    /// Share of the box that is void.
    pub empty: f64,
    /// The boundary's Robin factor A (1 without refractive mismatch).
    pub robin: f64,
    /// Share of the lights that are point or spot lights.
    pub point_lights: f64,
    /// σ_t′-weighted mean of σ_t′ h (h the largest cell side): how many transport mean
    /// free paths one cell spans where the light interacts. Grid methods need it below
    /// about one; Monte Carlo does not care.
    pub cell_depth: f64,
}

impl Features {
    /// The features of `problem`, averaged over its channels.
    pub fn of(problem: &Problem) -> Self {
        let g = problem.geometry();
        let largest = g.dims().into_iter().max().unwrap_or(1);
        let block = largest.div_ceil(32).max(8);
        let side = g.extent().max_element();
        let channels = problem.channels().max(1);
        // One channel on this thread: waking the pool costs more than a small grid's
        // indicators.
        let regimes: Vec<Regime> = if channels == 1 {
            vec![Regime::of(problem, 0, block)]
        } else {
            (0..channels)
                .into_par_iter()
                .map(|c| Regime::of(problem, c, block))
                .collect()
        };
        let h = g.spacing().max_element();
        let mut sum = [0.0f64; 6];
        let mut phase_g = 0.0;
        for regime in &regimes {
            let summary = regime.summary();
            let weight: f64 = regime.regions.iter().map(|r| r.sigma_t_reduced).sum();
            let depth = if weight > 0.0 {
                regime
                    .regions
                    .iter()
                    .map(|r| r.sigma_t_reduced * r.light_depth.min(50.0))
                    .sum::<f64>()
                    / weight
            } else {
                0.0
            };
            sum[0] += summary.sigma_t_reduced * side;
            sum[1] += 1.0 - summary.reduced_albedo;
            sum[2] += summary.boundary_mfp;
            sum[3] += depth;
            sum[4] += summary.empty_fraction;
            sum[5] += if weight > 0.0 {
                regime
                    .regions
                    .iter()
                    .map(|r| r.sigma_t_reduced * r.sigma_t_reduced * h)
                    .sum::<f64>()
                    / weight
            } else {
                0.0
            };
            phase_g += regime.g;
        }
        let n = channels as f64;
        let lights = problem.lights();
        let point = lights
            .iter()
            .filter(|l| matches!(l, Light::Point { .. } | Light::Spot { .. }))
            .count();
        Self {
            size_mfp: sum[0] / n,
            absorption: sum[1] / n,
            g: phase_g / n,
            boundary_mfp: sum[2] / n,
            light_depth: sum[3] / n,
            empty: sum[4] / n,
            robin: problem.boundary().robin_factor().unwrap_or(1.0),
            point_lights: point as f64 / lights.len().max(1) as f64,
            cell_depth: sum[5] / n,
        }
    }

    /// The coordinates distances are measured in: decades of the scale quantities (so a
    /// factor of ten counts one, wherever it lies), the bounded ones as they are.
    fn coordinates(&self) -> [f64; 9] {
        [
            (1.0 + self.size_mfp).log10(),
            self.absorption.max(1e-4).log10(),
            self.g,
            (1.0 + self.boundary_mfp).log10(),
            (1.0 + self.light_depth).log10(),
            self.empty,
            self.robin.max(1e-3).log10(),
            self.point_lights,
            (1.0 + self.cell_depth).log10(),
        ]
    }

    /// Euclidean distance in [`Features`] coordinates.
    pub fn distance(&self, other: &Features) -> f64 {
        self.coordinates()
            .iter()
            .zip(other.coordinates())
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt()
    }
}

/// One suite scene of the table: its features and cell count.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredScene {
    /// The suite scene's name.
    pub name: String,
    /// Its cell count (times are scaled by the problem's over this).
    pub cells: usize,
    /// Its regime.
    pub features: Features,
    /// Its measured points.
    pub points: Vec<Measured>,
}

/// One measured run on a suite scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Measured {
    /// The run's curve ([`Run::label`]).
    pub label: String,
    /// The run's setting ([`Run::setting`]).
    pub setting: String,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Relative L2 error against the scene's total fluence.
    pub error_total: f64,
}

/// The table `auto` chooses from.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Table {
    /// Per suite scene.
    pub scenes: Vec<MeasuredScene>,
}

/// Splits one CSV line, honouring double quotes (`""` inside quotes is a quote).
pub(crate) fn split_csv(line: &str) -> Vec<String> {
    let mut fields = vec![String::new()];
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '"' if quoted && chars.peek() == Some(&'"') => {
                chars.next();
                fields.last_mut().unwrap().push('"');
            }
            '"' => quoted = !quoted,
            ',' if !quoted => fields.push(String::new()),
            c => fields.last_mut().unwrap().push(c),
        }
    }
    fields
}

/// A CSV field, quoted when it holds a comma or a quote.
pub fn csv_field(text: &str) -> String {
    if text.contains([',', '"']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_owned()
    }
}

impl Table {
    /// Parses the CSV [`Table::to_csv`] writes.
    pub fn parse(text: &str) -> Result<Self, String> {
        let mut lines = text.lines().filter(|l| !l.trim().is_empty());
        match lines.next() {
            Some(h) if h.trim() == TABLE_HEADER => {}
            other => {
                return Err(format!(
                    "the auto table's header is {other:?}, not `{TABLE_HEADER}`"
                ));
            }
        }
        let mut table = Table::default();
        for (n, line) in lines.enumerate() {
            let f = split_csv(line);
            if f.len() != 15 {
                return Err(format!(
                    "auto table row {}: {} fields, not 15",
                    n + 2,
                    f.len()
                ));
            }
            let num = |i: usize| -> Result<f64, String> {
                f[i].trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| format!("auto table row {}: `{}` is not a number", n + 2, f[i]))
            };
            let features = Features {
                size_mfp: num(2)?,
                absorption: num(3)?,
                g: num(4)?,
                boundary_mfp: num(5)?,
                light_depth: num(6)?,
                empty: num(7)?,
                robin: num(8)?,
                point_lights: num(9)?,
                cell_depth: num(10)?,
            };
            let point = Measured {
                label: f[11].clone(),
                setting: f[12].clone(),
                seconds: num(13)?,
                error_total: num(14)?,
            };
            match table.scenes.iter_mut().find(|s| s.name == f[0]) {
                Some(scene) => scene.points.push(point),
                None => table.scenes.push(MeasuredScene {
                    name: f[0].clone(),
                    cells: num(1)? as usize,
                    features,
                    points: vec![point],
                }),
            }
        }
        Ok(table)
    }

    /// The table compiled in ([`TABLE_CSV`]).
    pub fn builtin() -> &'static Table {
        static TABLE: OnceLock<Table> = OnceLock::new();
        // A test parses the committed file, so this cannot fail on a built binary.
        TABLE.get_or_init(|| Table::parse(TABLE_CSV).unwrap_or_default())
    }

    /// The table as CSV, scenes in their order.
    pub fn to_csv(&self) -> String {
        let mut out = format!("{TABLE_HEADER}\n");
        for s in &self.scenes {
            let f = &s.features;
            for p in &s.points {
                out.push_str(&format!(
                    "{},{},{:.4},{:.5},{:.3},{:.4},{:.4},{:.4},{:.4},{:.3},{:.4},{},{},{:.6},{:.6}\n",
                    csv_field(&s.name),
                    s.cells,
                    f.size_mfp,
                    f.absorption,
                    f.g,
                    f.boundary_mfp,
                    f.light_depth,
                    f.empty,
                    f.robin,
                    f.point_lights,
                    f.cell_depth,
                    csv_field(&p.label),
                    csv_field(&p.setting),
                    p.seconds,
                    p.error_total
                ));
            }
        }
        out
    }

    /// This table with `scene` added, or replacing the scene of its name.
    pub fn with_scene(&self, scene: MeasuredScene) -> Table {
        let mut table = self.clone();
        match table.scenes.iter_mut().find(|s| s.name == scene.name) {
            Some(s) => *s = scene,
            None => table.scenes.push(scene),
        }
        table
    }

    /// This table without the scene named `name` (to see how the rule does on a scene it
    /// has not measured).
    pub fn without(&self, name: &str) -> Table {
        Table {
            scenes: self
                .scenes
                .iter()
                .filter(|s| s.name != name)
                .cloned()
                .collect(),
        }
    }
}

/// Below this regime distance a problem is taken to be the measured scene itself.
pub const SAME_SCENE: f64 = 0.05;

/// The measured scenes that vote on a problem that is none of them: those within
/// `NEIGHBOUR_FACTOR` × the nearest distance + [`NEIGHBOUR_SLACK`].
pub const NEIGHBOUR_FACTOR: f64 = 2.0;

/// See [`NEIGHBOUR_FACTOR`].
pub const NEIGHBOUR_SLACK: f64 = 0.2;

/// The share of the tolerance a run's expected error may take on a problem that is none of
/// the measured scenes: the rest covers the Monte Carlo references' own noise (1% relative)
/// and the spread of a sampled run's error between scenes.
pub const UNSEEN_MARGIN: f64 = 0.8;

/// What `auto` runs on a problem, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Choice {
    /// The tolerance asked for.
    pub tolerance: f64,
    /// The measured scenes that decided, nearest first, with their regime distances
    /// ([`Features::distance`]): the nearest alone when the problem is that scene (closer
    /// than [`SAME_SCENE`]), else every one within [`NEIGHBOUR_FACTOR`] × the nearest
    /// distance + [`NEIGHBOUR_SLACK`].
    pub neighbours: Vec<(String, f64)>,
    /// The expected error a run may have to be chosen: the tolerance on a measured scene,
    /// [`UNSEEN_MARGIN`] of it on any other.
    pub error_limit: f64,
    /// The run chosen (solver, parameters, grid refinement, iteration tolerance).
    pub run: Run,
    /// Its largest error on the deciding scenes that measured it.
    pub expected_error: f64,
    /// Its time on the nearest scene scaled to the problem's cell count, seconds.
    pub expected_seconds: f64,
    /// The problem's cell count over the nearest scene's: Monte Carlo's paths are scaled
    /// by it where it exceeds 1 ([`Choice::params`]).
    pub cells_ratio: f64,
    /// Whether it is expected to meet the tolerance; when not, no admitted run within the
    /// time budget was measured to, and this one came closest.
    pub meets: bool,
    /// Whether the time budget ruled out runs that would have met the tolerance.
    pub budget_bound: bool,
    /// Faster runs meeting the tolerance whose solver refused the problem.
    pub refused: usize,
}

impl fmt::Display for Choice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let pct = |v: f64| format!("{:.2}%", 100.0 * v);
        let what = format!("`{}` ({})", self.run.label, self.run.setting);
        let scenes = match self.neighbours.as_slice() {
            [(name, d)] if *d < SAME_SCENE => format!("this suite scene, {name}"),
            [(name, d)] => {
                format!("the nearest suite scene in regime, {name} (regime distance {d:.2})")
            }
            many => format!(
                "the suite scenes nearest in regime (regime distance), {}",
                many.iter()
                    .map(|(n, d)| format!("{n} ({d:.2})"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        };
        let refused = if self.refused > 0 {
            format!(
                "; {} faster run{} that would meet it refused this problem",
                self.refused,
                if self.refused == 1 { "" } else { "s" }
            )
        } else {
            String::new()
        };
        let scaled = if self.run.solver == lucent_mc::McSolver::NAME && self.cells_ratio > 1.0 {
            format!(
                ", its paths scaled ×{:.1} to this problem's cell count",
                self.cells_ratio
            )
        } else {
            String::new()
        };
        let refused = format!("{scaled}{refused}");
        // On a scene it has not measured, a run must come within `UNSEEN_MARGIN` of the
        // tolerance: say so, or "cannot meet 5 % … with 4.29 %" reads as a contradiction.
        let limit = self.error_limit;
        let margin = if limit < self.tolerance {
            format!(
                " (at most {} measured: a margin of {:.0} % for a scene not in the suite)",
                pct(limit),
                100.0 * (1.0 - limit / self.tolerance)
            )
        } else {
            String::new()
        };
        if self.meets {
            write!(
                f,
                "auto chose {what}: the fastest measured to meet {}{margin} on {scenes}, with at most {} there; expected {:.3} s here{refused}",
                pct(self.tolerance),
                pct(self.expected_error),
                self.expected_seconds
            )
        } else {
            write!(
                f,
                "auto cannot meet {}{margin}{}: the best measured on {scenes} is {what} with {}; running it (expected {:.3} s here){refused}",
                pct(self.tolerance),
                if self.budget_bound {
                    " within the time budget"
                } else {
                    ""
                },
                pct(self.expected_error),
                self.expected_seconds
            )
        }
    }
}

impl Choice {
    /// The chosen run's parameters, as `auto` runs them: the table's, with a Monte Carlo
    /// run's paths scaled by [`Choice::cells_ratio`] where the problem has more cells than
    /// the scene it was measured on. The track-length estimate of a cell's fluence has a
    /// relative standard error ∝ √(cells / paths) (the track length a path leaves in a cell
    /// falls with the cell's volume), so keeping the paths per cell keeps the error the
    /// table measured; the time grows by the same ratio, as the expected time says. Grid
    /// solvers' knobs (orders, tolerances, refinement factors) carry over unscaled.
    pub fn params(&self) -> Result<Params, SolveError> {
        let mut params: Params =
            toml::from_str(&self.run.params).map_err(|e| SolveError::InvalidParameter {
                name: "auto".into(),
                reason: format!("the table's run `{}`: {e}", self.run.params),
            })?;
        if let Some(paths) = self.scaled_paths(&params) {
            params.0.insert("particles".into(), ParamValue::Int(paths));
        }
        Ok(params)
    }

    /// A Monte Carlo run's particles per batch scaled to the problem's cells, if scaled.
    fn scaled_paths(&self, params: &Params) -> Option<i64> {
        if self.run.solver != lucent_mc::McSolver::NAME || self.cells_ratio <= 1.0 {
            return None;
        }
        match params.0.get("particles") {
            Some(ParamValue::Int(n)) => Some((*n as f64 * self.cells_ratio).ceil() as i64),
            _ => None,
        }
    }

    /// The report's fields for this choice: the solver and parameters that ran, their
    /// parts (those of `inner`, the chosen solver's own composition, as `hybrid`'s) and the
    /// numbers of the decision.
    pub fn composition(
        &self,
        registry: &Registry,
        inner: Option<Composition>,
    ) -> Result<Composition, SolveError> {
        let params = (registry.entry(self.run.solver)?.resolved)(&self.params()?)?;
        Ok(Composition {
            solver: self.run.solver.into(),
            params,
            parts: inner.map(|c| c.parts).unwrap_or_default(),
            decision: Some(Decision {
                tolerance: self.tolerance,
                error_limit: self.error_limit,
                expected_error: self.expected_error,
                expected_seconds: self.expected_seconds,
                meets: self.meets,
                budget_bound: self.budget_bound,
                neighbours: self
                    .neighbours
                    .iter()
                    .map(|(scene, d)| Neighbour {
                        scene: scene.clone(),
                        regime_distance: *d,
                    })
                    .collect(),
            }),
        })
    }

    /// The nearest measured scene.
    pub fn nearest(&self) -> &str {
        &self.neighbours[0].0
    }
}

/// Chooses what to run on `problem` for `tolerance` within `budget` from `table`, building
/// candidates from `registry` (module docs).
pub fn choose(
    problem: &Problem,
    tolerance: f64,
    budget: Option<Duration>,
    table: &Table,
    registry: &Registry,
) -> Result<Choice, SolveError> {
    choose_without(problem, tolerance, budget, table, registry, &[])
}

/// [`choose`] with the runs in `skip` ruled out (runs that were tried and could not run:
/// over the memory budget, too much work).
pub fn choose_without(
    problem: &Problem,
    tolerance: f64,
    budget: Option<Duration>,
    table: &Table,
    registry: &Registry,
    skip: &[Run],
) -> Result<Choice, SolveError> {
    let features = Features::of(problem);
    choose_from(problem, &features, tolerance, budget, table, registry, skip)
}

/// [`choose_without`] with the problem's features already computed (a solve that tries
/// several runs computes them once).
fn choose_from(
    problem: &Problem,
    features: &Features,
    tolerance: f64,
    budget: Option<Duration>,
    table: &Table,
    registry: &Registry,
    skip: &[Run],
) -> Result<Choice, SolveError> {
    let mut by_distance: Vec<(f64, &MeasuredScene)> = table
        .scenes
        .iter()
        .map(|s| (features.distance(&s.features), s))
        .collect();
    by_distance.sort_by(|a, b| a.0.total_cmp(&b.0));
    let Some(&(nearest_distance, nearest)) = by_distance.first() else {
        return Err(SolveError::Unsupported {
            solver: AutoSolver::NAME.into(),
            feature: "this problem: its table of measured runs is empty".into(),
        });
    };
    let seen = nearest_distance < SAME_SCENE;
    let reach = NEIGHBOUR_FACTOR * nearest_distance + NEIGHBOUR_SLACK;
    let deciding: Vec<(f64, &MeasuredScene)> = by_distance
        .iter()
        .copied()
        .take_while(|(d, _)| !seen && *d <= reach)
        .collect();
    let deciding = if seen {
        vec![(nearest_distance, nearest)]
    } else {
        deciding
    };
    let limit = if seen {
        tolerance
    } else {
        UNSEEN_MARGIN * tolerance
    };
    let scale = problem.geometry().voxel_count() as f64 / nearest.cells.max(1) as f64;
    let all = runs();
    // Candidates: the nearest scene's measured CPU runs that still exist, fastest first,
    // each with its worst error on the deciding scenes that measured it.
    let mut candidates: Vec<(Run, f64, f64)> = nearest
        .points
        .iter()
        .filter(|p| !p.label.starts_with("gpu-"))
        .filter_map(|p| {
            let run = all
                .iter()
                .find(|r| r.label == p.label && r.setting == p.setting)
                .filter(|r| !skip.contains(r))?;
            let worst = deciding
                .iter()
                .filter_map(|(_, s)| {
                    s.points
                        .iter()
                        .find(|q| q.label == p.label && q.setting == p.setting)
                })
                .map(|q| q.error_total)
                .fold(p.error_total, f64::max);
            Some((run.clone(), worst, p.seconds * scale))
        })
        .collect();
    candidates.sort_by(|a, b| a.2.total_cmp(&b.2));
    // Whether each candidate's solver admits the problem, asked at most once per candidate.
    let admitted_once: Vec<std::cell::OnceCell<bool>> = candidates
        .iter()
        .map(|_| std::cell::OnceCell::new())
        .collect();
    let admits = |i: usize| -> bool {
        *admitted_once[i].get_or_init(|| {
            let run = &candidates[i].0;
            toml::from_str::<Params>(&run.params).is_ok_and(|params| {
                registry
                    .build(run.solver, &params)
                    .is_ok_and(|s| s.admits(problem).is_ok())
            })
        })
    };
    let fits = |seconds: f64| budget.is_none_or(|b| seconds <= b.as_secs_f64());
    let choice = |(run, error, seconds): &(Run, f64, f64), meets, budget_bound, refused| Choice {
        tolerance,
        error_limit: limit,
        neighbours: deciding.iter().map(|(d, s)| (s.name.clone(), *d)).collect(),
        run: run.clone(),
        expected_error: *error,
        expected_seconds: *seconds,
        cells_ratio: scale,
        meets,
        budget_bound,
        refused,
    };
    let mut refused = 0;
    let mut budget_bound = false;
    for (i, c) in candidates.iter().enumerate() {
        if c.1 > limit {
            continue;
        }
        if !admits(i) {
            refused += 1;
            continue;
        }
        if !fits(c.2) {
            budget_bound = true;
            continue;
        }
        return Ok(choice(c, true, false, refused));
    }
    let admitted: Vec<&(Run, f64, f64)> = candidates
        .iter()
        .enumerate()
        .filter(|&(i, _)| admits(i))
        .map(|(_, c)| c)
        .collect();
    let best = admitted
        .iter()
        .filter(|c| fits(c.2))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        // Nothing fits the budget: the fastest, which stops at the budget with what it has.
        .or_else(|| admitted.first())
        .ok_or_else(|| SolveError::Unsupported {
            solver: AutoSolver::NAME.into(),
            feature: format!(
                "this problem: no solver measured on the nearest suite scene, {}, admits it",
                nearest.name
            ),
        })?;
    Ok(choice(best, false, budget_bound, 0))
}

/// The `auto` solver (module docs).
#[derive(Debug, Clone)]
pub struct AutoSolver {
    tolerance: f64,
    table: Option<Arc<Table>>,
}

impl AutoSolver {
    /// The registry name.
    pub const NAME: &'static str = "auto";

    /// The registry entry ([`AutoParams`]).
    pub const ENTRY: SolverEntry = SolverEntry {
        name: Self::NAME,
        summary: "the cheapest solver measured to meet a tolerance on the nearest suite scene in regime space; says what it chose and why",
        build: |params| Ok(Box::new(Self::from_params(params)?)),
        params: param_docs::<AutoParams>,
        resolved: |p| resolved_params::<AutoParams>(p, Self::NAME),
    };

    /// Builds from registry parameters.
    pub fn from_params(params: &Params) -> Result<Self, SolveError> {
        let p: AutoParams = params.parse(Self::NAME)?;
        Ok(Self::new(p.tolerance))
    }

    /// `auto` for `tolerance` with the compiled-in table.
    pub fn new(tolerance: f64) -> Self {
        Self {
            tolerance,
            table: None,
        }
    }

    /// `auto` choosing from `table` instead of the compiled-in one.
    pub fn with_table(tolerance: f64, table: Table) -> Self {
        Self {
            tolerance,
            table: Some(Arc::new(table)),
        }
    }

    fn table(&self) -> &Table {
        self.table.as_deref().unwrap_or_else(|| Table::builtin())
    }

    /// What it would run on `problem` within `budget`.
    pub fn choose(
        &self,
        problem: &Problem,
        budget: Option<Duration>,
    ) -> Result<Choice, SolveError> {
        choose(
            problem,
            self.tolerance,
            budget,
            self.table(),
            &crate::registry(),
        )
    }
}

/// `problem` on `factor` times as many cells per axis, for a run measured refined.
fn refined(problem: &Problem, factor: usize) -> Result<Problem, SolveError> {
    let dims = problem.geometry().dims().map(|n| n * factor);
    crate::resolution::on_grid(problem, dims).map_err(|e| match e {
        crate::Error::Grid(e) => SolveError::Grid(e),
        crate::Error::Problem(e) => SolveError::Problem(e),
        other => SolveError::Unsupported {
            solver: AutoSolver::NAME.into(),
            feature: format!("a refined grid: {other}"),
        },
    })
}

impl Solver for AutoSolver {
    fn name(&self) -> &str {
        Self::NAME
    }

    /// The union of what its candidates handle (what it refuses is what all of them
    /// refuse: [`Solver::admits`] asks them).
    fn capabilities(&self) -> Capabilities {
        let registry = crate::registry();
        let mut all = Capabilities {
            cubic_cells_only: true,
            reflecting_neumann_only: true,
            point_lights_inside_grid: true,
            robin_needs_embedded_surface: true,
            needs_absorption: true,
            output: OutputKind::Fluence,
            fluence: FluenceKind::Total,
            ..Capabilities::default()
        };
        for entry in registry.entries() {
            if entry.name == Self::NAME || entry.name.starts_with("gpu-") {
                continue;
            }
            let Ok(solver) = registry.build(entry.name, &Params::default()) else {
                continue;
            };
            let c = solver.capabilities();
            all.anisotropic |= c.anisotropic;
            all.heterogeneous |= c.heterogeneous;
            all.cubic_cells_only &= c.cubic_cells_only;
            all.reflecting_neumann_only &= c.reflecting_neumann_only;
            all.point_lights_inside_grid &= c.point_lights_inside_grid;
            all.robin_needs_embedded_surface &= c.robin_needs_embedded_surface;
            all.needs_absorption &= c.needs_absorption;
            all.embedded_geometry |= c.embedded_geometry;
            all.graded_index |= c.graded_index;
            for b in c.boundaries {
                if !all.boundaries.contains(&b) {
                    all.boundaries.push(b);
                }
            }
            for l in c.lights {
                if !all.lights.contains(&l) {
                    all.lights.push(l);
                }
            }
        }
        all
    }

    fn admits(&self, problem: &Problem) -> Result<(), SolveError> {
        self.choose(problem, None).map(|_| ())
    }

    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
        self.solve_with_choice(problem, options).map(|(s, _)| s)
    }
}

impl AutoSolver {
    /// [`Solver::solve`], also returning the choice that ran (after a memory-budget
    /// fallback, the run that could run).
    pub fn solve_with_choice(
        &self,
        problem: &Problem,
        options: &SolveOptions,
    ) -> Result<(Solution, Choice), SolveError> {
        let start = Instant::now();
        options.validate()?;
        let registry = crate::registry();
        // Runs that could not run here (over the memory budget, too much work): the next
        // run expected to meet the tolerance is tried without them, and the line says so.
        // Once none is left the first refusal is the error: it names what the cheapest
        // run meeting the tolerance needs. (A choice that already cannot meet it is the
        // closest run; nothing worse is tried after it.)
        let mut skipped: Vec<(Run, SolveError)> = Vec::new();
        let features = Features::of(problem);
        loop {
            let skip: Vec<Run> = skipped.iter().map(|(r, _)| r.clone()).collect();
            let next = choose_from(
                problem,
                &features,
                self.tolerance,
                options.time_budget,
                self.table(),
                &registry,
                &skip,
            );
            let choice = match (next, skipped.is_empty()) {
                (Ok(c), true) => c,
                (Err(e), true) => return Err(e),
                (Ok(c), false) if c.meets => c,
                (_, false) => return Err(skipped.swap_remove(0).1),
            };
            match run_choice(&choice, problem, options, start) {
                Err(e @ (SolveError::OverBudget { .. } | SolveError::TooMuchWork { .. }))
                    if choice.meets =>
                {
                    skipped.push((choice.run.clone(), e));
                }
                Err(e) => return Err(e),
                Ok(mut solution) => {
                    let mut line = choice.to_string();
                    for (run, e) in &skipped {
                        line.push_str(&format!(
                            "; `{}` ({}) could not run: {e}",
                            run.label, run.setting
                        ));
                    }
                    solution.report.solver = Self::NAME.into();
                    solution.report.choice = Some(line);
                    let inner = solution.report.composition.take();
                    solution.report.composition = Some(choice.composition(&registry, inner)?);
                    solution.report.wall_time_s = start.elapsed().as_secs_f64();
                    return Ok((solution, choice));
                }
            }
        }
    }
}

/// Runs `choice` on `problem` with `options` (its iteration tolerance and limit over
/// theirs, the time left of their budget since `start`), on the refined grid restricted
/// back where the run was refined.
fn run_choice(
    choice: &Choice,
    problem: &Problem,
    options: &SolveOptions,
    start: Instant,
) -> Result<Solution, SolveError> {
    let solver = crate::registry().build(choice.run.solver, &choice.params()?)?;
    let fine = match choice.run.factor {
        1 => None,
        factor => Some(refined(problem, factor)?),
    };
    let run_options = choice.run.options(&SolveOptions {
        time_budget: options
            .time_budget
            .map(|b| b.saturating_sub(start.elapsed())),
        ..options.clone()
    });
    let mut solution = solver.solve(fine.as_ref().unwrap_or(problem), &run_options)?;
    // Back onto the problem's cells: box averages of the refined cells.
    let mut factor = choice.run.factor;
    while factor > 1 {
        solution.fluence = solution.fluence.iter().map(restrict).collect();
        solution.standard_error = solution
            .standard_error
            .map(|e| e.iter().map(restrict).collect());
        factor /= 2;
    }
    Ok(solution)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_fields_round_trip_through_quotes() {
        let fields = ["plain", "1x cells, 8 sky", "say \"hi\", then", ""];
        let line: Vec<String> = fields.iter().map(|f| csv_field(f)).collect();
        assert_eq!(split_csv(&line.join(",")), fields);
    }

    #[test]
    fn a_table_round_trips_and_bad_rows_are_named() {
        let table = Table::parse(TABLE_CSV).expect("the committed table parses");
        assert_eq!(Table::parse(&table.to_csv()).unwrap(), table);
        let bad = format!("{TABLE_HEADER}\ncloud,1,x,0,0,0,0,0,1,0,0,mc,8000 paths,0.1,0.2\n");
        assert!(Table::parse(&bad).unwrap_err().contains("row 2"));
        assert!(Table::parse("a,b\n").unwrap_err().contains("header"));
    }
}
