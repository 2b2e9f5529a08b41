//! The cross-check harness: every registered solver on every suite scene its capabilities
//! allow, its fluence compared with a reference under a stated tolerance.
//!
//! The suite lives in `examples/scenes/suite/` with `tolerances.toml` beside it. The
//! reference is the analytic solution where one exists (the marble sphere, Mertens T7),
//! otherwise Monte Carlo (`lucent-mc`) run until its mean relative standard error is below
//! a fifth of the tolerance — counting only uncollided light for solvers whose fluence is
//! uncollided. Monte Carlo references are stored in the suite's `references/` folder
//! (written by `cargo xtask crosscheck`, committed, with their seed fixed), so that the
//! test run never recomputes them; one missing there (a scene changed) is computed and
//! cached under the given folder (`target/`). Each is keyed by the scene's text (a
//! stable FNV-1a hash), the fluence kind, the target error and [`REFERENCE_VERSION`].
//!
//! The error measure: relative L2 over the cells inside the medium where the reference
//! exceeds 10⁻³ of its peak, ‖φ − φ_ref‖₂/‖φ_ref‖₂, and the largest relative error over
//! those cells above 10⁻² of the peak. (Outside the medium the fluence is that of vacuum;
//! shadow edges crossing empty cells would compare centre values with cell averages.)

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::DVec3;
use lucent_core::{FluenceKind, Params, SolveOptions, StopReason};
use lucent_grid::Grid;
use lucent_grid::io::{LoadOptions, ScalarType, npy};
use lucent_mc::{McConfig, estimate};
use lucent_optics::{DiffusionMedium, OpticalCoefficients};
use serde::Deserialize;

use crate::Error;
use crate::scene::{BuiltScene, Scene};

/// One line of `tolerances.toml`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tolerance {
    /// Registered solver name.
    pub solver: String,
    /// Suite scene name (file stem).
    pub scene: String,
    /// Largest accepted relative L2 error.
    pub tolerance: f64,
    /// Solver parameters for this check.
    #[serde(default)]
    pub params: Params,
    /// Why this tolerance.
    pub why: String,
    /// What the run must do: meet the tolerance (the default), or stop with
    /// `DivergedGrowth` (a solver kept to show a method's failure).
    #[serde(default)]
    pub expect: Expect,
    /// Compare with this solver's solution of the scene (default parameters and options)
    /// instead of the scene's analytic or Monte Carlo reference: for a GPU backend and
    /// its CPU twin, where the tolerance is the f32-against-f64 difference.
    #[serde(default)]
    pub twin: Option<String>,
    /// Solve on `factor` times the scene's cells per axis (the medium resampled, as the
    /// pareto sweep refines), against a twin solved on the same cells: the convergence
    /// checks too slow for the default test run, run by `cargo xtask crosscheck
    /// --refined` (skipped otherwise, and said so).
    #[serde(default = "one")]
    pub factor: usize,
    /// Too slow for the default test run (its solve and reference together take seconds
    /// where the others take fractions): `cargo xtask crosscheck` runs it, the test does
    /// not ([`Selection::Quick`]). Every solver and every scene keeps entries that are not
    /// heavy, which `tests/it/cross_check.rs` asserts.
    #[serde(default)]
    pub heavy: bool,
}

/// Which entries of the tolerance table a run takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Selection {
    /// The entries on the scenes' own cells that are not [`Tolerance::heavy`]: the default
    /// test run.
    Quick,
    /// Every entry on the scenes' own cells: `cargo xtask crosscheck`.
    All,
    /// Every entry, the refined convergence checks too: `cargo xtask crosscheck --refined`.
    Refined,
}

/// One entry done: what [`run_with`] tells its progress callback.
#[derive(Debug)]
pub struct Progress<'a> {
    /// Entries done, this one included.
    pub done: usize,
    /// Entries in the table.
    pub total: usize,
    /// Its outcome.
    pub outcome: &'a Outcome,
    /// Wall time of the entry, its reference and twin included, seconds.
    pub seconds: f64,
}

impl std::fmt::Display for Progress<'_> {
    /// `[ 3/95] dom on cloud: 1.23% (tolerance 5.00%) pass, 0.8 s`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let o = self.outcome;
        let width = self.total.to_string().len();
        write!(
            f,
            "[{:>width$}/{}] {} on {}: ",
            self.done, self.total, o.solver, o.scene
        )?;
        match &o.result {
            CheckResult::Compared { comparison, .. } => write!(
                f,
                "{} (tolerance {}) {}, {:.1} s",
                percent(comparison.relative_l2),
                percent(o.tolerance.tolerance),
                if o.passed() { "pass" } else { "FAIL" },
                self.seconds
            ),
            CheckResult::Skipped(reason) => write!(f, "skipped ({reason})"),
        }
    }
}

fn one() -> usize {
    1
}

/// What a harness entry requires of its run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Expect {
    /// The fluence's relative L2 error is within the tolerance.
    #[default]
    Tolerance,
    /// The solver stops with `StopReason::DivergedGrowth`; the error of its last finite
    /// iterate is reported, not bounded.
    Diverged,
}

#[derive(Deserialize)]
struct ToleranceFile {
    entry: Vec<Tolerance>,
}

/// A suite scene, built.
#[derive(Debug, Clone)]
pub struct SuiteScene {
    /// File stem.
    pub name: String,
    /// The scene as parsed (to rebuild it at other resolutions).
    pub scene: Scene,
    /// The folder its relative paths start from.
    pub base: PathBuf,
    /// The scene, ready to solve.
    pub built: BuiltScene,
    /// Hash of the file's text (the cache key): [`fnv1a`], stable across Rust versions
    /// and machines, since stored references are named by it.
    pub text_hash: u64,
    /// Where its stored references are: the suite's `references/` folder.
    pub references: PathBuf,
}

/// The version of the Monte Carlo references' recipe (seed, batches, estimator): part of
/// every reference's file name. Bump it when `lucent-mc`'s estimates change (a fix, another
/// random stream), so that no stored reference of the old estimator is read.
pub const REFERENCE_VERSION: u32 = 1;

/// Stored references in `dir` that no longer describe a scene of `scenes`: named after
/// one of them but for another text (the scene changed), or of another
/// [`REFERENCE_VERSION`]. Files of other scenes are left alone.
pub fn stale_references(dir: &Path, scenes: &[SuiteScene]) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let version = format!("-v{REFERENCE_VERSION}.npy");
    entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|path| {
            let name = path.file_name().unwrap_or_default().to_string_lossy();
            scenes.iter().any(|scene| {
                let prefix = format!("{}-", scene.name);
                let hash = format!("-{:016x}-", scene.text_hash);
                let rest = name.strip_prefix(&prefix).unwrap_or_default();
                // `slab-…` is not `slab_thick-…`: the kind follows the name.
                (rest.starts_with("total-") || rest.starts_with("uncollided-"))
                    && !(name.contains(&hash) && name.ends_with(&version))
            })
        })
        .collect()
}

/// The 64-bit FNV-1a hash of `bytes`: a fixed function (unlike `DefaultHasher`), for
/// names that are stored.
pub fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// Reads every scene of a suite folder (all `*.toml` but `tolerances.toml`) and its
/// tolerances.
pub fn load_suite(dir: &Path) -> Result<(Vec<SuiteScene>, Vec<Tolerance>), Error> {
    let scenes = load_scenes(dir)?;
    let tolerance_path = dir.join("tolerances.toml");
    let text = std::fs::read_to_string(&tolerance_path).map_err(|e| Error::Io {
        path: tolerance_path.clone(),
        reason: e.to_string(),
    })?;
    let file: ToleranceFile = toml::from_str(&text).map_err(|e| Error::Scene {
        path: tolerance_path.clone(),
        reason: e.to_string(),
    })?;
    Ok((scenes, file.entry))
}

/// Reads and builds every scene of a folder (all `*.toml` but `tolerances.toml`), by name.
pub fn load_scenes(dir: &Path) -> Result<Vec<SuiteScene>, Error> {
    let io = |path: &Path, e: std::io::Error| Error::Io {
        path: path.to_owned(),
        reason: e.to_string(),
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension().is_some_and(|e| e == "toml")
                && p.file_stem().is_some_and(|s| s != "tolerances")
        })
        .collect();
    files.sort();
    let mut scenes = Vec::new();
    for path in files {
        let text = std::fs::read_to_string(&path).map_err(|e| io(&path, e))?;
        let scene = Scene::parse(&text, &path)?;
        let built = scene.build(path.parent().unwrap_or(Path::new(".")))?;
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let base = path.parent().unwrap_or(Path::new(".")).to_owned();
        scenes.push(SuiteScene {
            name,
            scene,
            base,
            built,
            text_hash: fnv1a(text.as_bytes()),
            references: dir.join("references"),
        });
    }
    Ok(scenes)
}

/// A reference fluence.
#[derive(Debug, Clone)]
pub struct Reference {
    /// Per channel.
    pub fluence: Vec<Grid>,
    /// Cells where the reference is valid (`None`: all).
    pub mask: Option<Vec<bool>>,
    /// `analytic` or `monte carlo`.
    pub kind: String,
    /// Achieved mean relative standard error (0 for analytic references).
    pub relative_std_error: f64,
}

/// The analytic reference of a scene, if it has one: the marble sphere (T7) with the
/// scene's boundary index and its Milne A
/// ([`lucent_core::Boundary::robin_factor`]), valid at least three transport mean free
/// paths from the source and from the boundary (where diffusion is meant to hold).
fn analytic(scene: &SuiteScene) -> Option<Reference> {
    if !scene.name.starts_with("marble_sphere") {
        return None;
    }
    let problem = &scene.built.problem;
    let g = *problem.geometry();
    let a = problem.boundary().robin_factor().unwrap_or(1.0);
    let coefficients = OpticalCoefficients::from_extinction_albedo(2.1921, 0.999042, 0.0).ok()?;
    let medium = DiffusionMedium::new(coefficients, a).ok()?;
    let radius = 10.0;
    let sphere = medium.sphere(radius).ok()?;
    let margin = 3.0 * medium.z_r();
    let grid = Grid::from_fn(g, |p| {
        sphere
            .fluence(p.length().max(1e-9))
            .map_or(0.0, |v| v as f32)
    });
    let mask = (0..g.voxel_count())
        .map(|index| {
            let [i, j, k] = g.coords(index);
            let r = (g.cell_centre(i, j, k) - DVec3::ZERO).length();
            r >= margin && r <= radius - margin
        })
        .collect();
    Some(Reference {
        fluence: vec![grid],
        mask: Some(mask),
        kind: "analytic".into(),
        relative_std_error: 0.0,
    })
}

/// The reference's own expected relative L2 error, √Σσ²/√Σφ² over the compared cells: the
/// same measure the comparison uses.
fn relative_error(fluence: &Grid, std_error: &Grid, mask: &[bool]) -> f64 {
    let peak = fluence.stats().max;
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for ((p, e), m) in fluence.data().iter().zip(std_error.data()).zip(mask) {
        if *m && *p > 1e-3 * peak {
            num += f64::from(*e) * f64::from(*e);
            den += f64::from(*p) * f64::from(*p);
        }
    }
    if den > 0.0 { (num / den).sqrt() } else { 0.0 }
}

/// Cells inside the medium (σ_t > 0): where solvers are compared. Outside it the fluence
/// is that of vacuum, and shadow edges crossing empty cells make centre values and cell
/// averages differ by O(1) without saying anything about a solver.
fn medium_mask(scene: &SuiteScene) -> Vec<bool> {
    let problem = &scene.built.problem;
    let g = problem.geometry();
    let near = 1.5 * g.spacing().max_element();
    let lights: Vec<DVec3> = problem
        .lights()
        .iter()
        .filter_map(|l| match l {
            lucent_core::Light::Point { position, .. } => Some(*position),
            _ => None,
        })
        .collect();
    problem
        .medium()
        .sigma_t(0)
        .data()
        .iter()
        .enumerate()
        .map(|(index, &s)| {
            // Next to a point light the reference's cell average of a 1/r² (or, scattered,
            // 1/r) singularity and a solver's centre value differ by O(1), whatever the
            // solver: those cells say nothing about it.
            let [i, j, k] = g.coords(index);
            let x = g.cell_centre(i, j, k);
            s > 0.0 && lights.iter().all(|p| (x - *p).length() > near)
        })
        .collect()
}

/// The reference for `scene` and fluence `kind`: analytic if there is one, else Monte Carlo
/// to a mean relative standard error of `target`, cached in `cache` when given.
pub fn reference(
    scene: &SuiteScene,
    kind: FluenceKind,
    target: f64,
    cache: Option<&Path>,
) -> Result<Reference, Error> {
    if let Some(r) = analytic(scene).filter(|_| kind == FluenceKind::Total) {
        return Ok(r);
    }
    let tag = match kind {
        FluenceKind::Uncollided => "uncollided",
        FluenceKind::Total => "total",
    };
    let channels = scene.built.problem.channels();
    let mask = medium_mask(scene);
    let name = format!(
        "{}-{tag}-{:016x}-{:.0e}-v{REFERENCE_VERSION}.npy",
        scene.name, scene.text_hash, target
    );
    let stored = scene.references.join(&name);
    let file = cache.map(|dir| dir.join(&name));
    let found = std::iter::once(&stored)
        .chain(file.as_ref())
        .find(|p| p.exists());
    if let Some(path) = found {
        let grid = npy::read(path, &LoadOptions::default())?
            .with_geometry(*scene.built.problem.geometry())?;
        if channels == 1 {
            return Ok(Reference {
                fluence: vec![grid],
                mask: Some(mask),
                kind: if *path == stored {
                    "monte carlo (stored)".into()
                } else {
                    "monte carlo (cached)".into()
                },
                relative_std_error: target,
            });
        }
    }
    let mut config = McConfig {
        particles: 4000,
        batches: 16,
        seed: 0xC0FFEE,
        ..Default::default()
    };
    if kind == FluenceKind::Uncollided {
        // Stop every path at its first collision: only first flights are tallied.
        config.max_depth = 1;
    }
    loop {
        let run = estimate(&scene.built.problem, &config)?;
        let achieved = relative_error(&run.fluence[0], &run.standard_error[0], &mask);
        if achieved <= target || config.particles >= 4_096_000 {
            if let (Some(path), 1) = (&file, channels) {
                if let Some(dir) = path.parent() {
                    let _ = std::fs::create_dir_all(dir);
                }
                npy::write(path, &run.fluence[0], ScalarType::F32)?;
            }
            return Ok(Reference {
                fluence: run.fluence,
                mask: Some(mask),
                kind: "monte carlo".into(),
                relative_std_error: achieved,
            });
        }
        // Error falls as 1/√N: jump straight to the particle count that should reach it.
        let factor = ((achieved / target).powi(2) * 1.2).clamp(2.0, 64.0);
        config.particles = ((config.particles as f64 * factor) as u64).min(4_096_000);
    }
}

/// Errors of a fluence against a reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Comparison {
    /// Relative L2 over cells above 10⁻³ of the reference peak.
    pub relative_l2: f64,
    /// Largest relative error over cells above 10⁻² of the peak.
    pub max_relative: f64,
}

/// Compares `fluence` with `reference`, channel by channel (the worst channel counts).
pub fn compare(fluence: &[Grid], reference: &Reference) -> Comparison {
    let mut worst = Comparison {
        relative_l2: 0.0,
        max_relative: 0.0,
    };
    for (c, r) in reference.fluence.iter().enumerate() {
        let f = &fluence[c.min(fluence.len() - 1)];
        let peak = r.stats().max;
        let (mut num, mut den, mut max) = (0.0f64, 0.0f64, 0.0f64);
        for (index, (&a, &b)) in f.data().iter().zip(r.data()).enumerate() {
            if reference.mask.as_ref().is_some_and(|m| !m[index]) || b <= 1e-3 * peak {
                continue;
            }
            let d = f64::from(a) - f64::from(b);
            num += d * d;
            den += f64::from(b) * f64::from(b);
            if b > 1e-2 * peak {
                max = max.max(d.abs() / f64::from(b));
            }
        }
        let l2 = if den > 0.0 { (num / den).sqrt() } else { 0.0 };
        worst.relative_l2 = worst.relative_l2.max(l2);
        worst.max_relative = worst.max_relative.max(max);
    }
    worst
}

/// The outcome of one (solver, scene) check.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// Solver name.
    pub solver: String,
    /// Scene name.
    pub scene: String,
    /// The tolerance and its reason.
    pub tolerance: Tolerance,
    /// What happened.
    pub result: CheckResult,
}

/// A check's result.
#[derive(Debug, Clone)]
pub enum CheckResult {
    /// Solved and compared.
    Compared {
        /// The errors.
        comparison: Comparison,
        /// Solve time, seconds.
        seconds: f64,
        /// The reference's kind.
        reference: String,
        /// The reference's own relative standard error.
        reference_error: f64,
        /// For stochastic solvers, the run's own expected relative L2 error.
        solution_error: Option<f64>,
        /// Why the solver stopped.
        stop_reason: StopReason,
    },
    /// The solver cannot handle the scene (its capabilities say why).
    Skipped(String),
}

impl Outcome {
    /// Whether the check passed (skips pass: capabilities decide what is checked).
    pub fn passed(&self) -> bool {
        match &self.result {
            CheckResult::Compared {
                comparison,
                stop_reason,
                ..
            } => match self.tolerance.expect {
                Expect::Tolerance => comparison.relative_l2 <= self.tolerance.tolerance,
                Expect::Diverged => matches!(stop_reason, StopReason::DivergedGrowth { .. }),
            },
            CheckResult::Skipped(_) => true,
        }
    }
}

/// Runs the [`Selection::Quick`] entries of the suite's tolerance table; the others are
/// reported as skipped.
pub fn run(suite: &Path, cache: Option<&Path>) -> Result<Vec<Outcome>, Error> {
    run_with(suite, cache, Selection::Quick, &mut |_| {})
}

/// Runs the `selection` of the suite's tolerance table (the rest reported as skipped,
/// saying who runs them), telling `progress` as each entry is done.
pub fn run_with(
    suite: &Path,
    cache: Option<&Path>,
    selection: Selection,
    progress: &mut dyn FnMut(&Progress<'_>),
) -> Result<Vec<Outcome>, Error> {
    let (scenes, tolerances) = load_suite(suite)?;
    let registry = crate::registry();
    let mut outcomes = Vec::new();
    let total = tolerances.len();
    let mut started = Instant::now();
    let mut tell = |outcomes: &Vec<Outcome>| {
        if let Some(outcome) = outcomes.last() {
            progress(&Progress {
                done: outcomes.len(),
                total,
                outcome,
                seconds: started.elapsed().as_secs_f64(),
            });
        }
        started = Instant::now();
    };
    for entry in tolerances {
        tell(&outcomes);
        let scene = scenes
            .iter()
            .find(|s| s.name == entry.scene)
            .ok_or_else(|| {
                Error::Invalid(format!(
                    "tolerances.toml names scene `{}`, which is not in the suite",
                    entry.scene
                ))
            })?;
        let solver = registry.build(&entry.solver, &entry.params)?;
        let capabilities = solver.capabilities();
        if entry.factor == 0 || (entry.factor > 1 && entry.twin.is_none()) {
            return Err(Error::Invalid(format!(
                "tolerances.toml: {} on {}: factor {} (a refined check needs factor ≥ 2 and a twin solved on the same cells)",
                entry.solver, entry.scene, entry.factor
            )));
        }
        if entry.heavy && entry.factor == 1 && selection == Selection::Quick {
            outcomes.push(Outcome {
                solver: entry.solver.clone(),
                scene: entry.scene.clone(),
                result: CheckResult::Skipped(
                    "heavy for the default test run: `cargo xtask crosscheck` runs it".into(),
                ),
                tolerance: entry,
            });
            continue;
        }
        if entry.factor > 1 && selection != Selection::Refined {
            outcomes.push(Outcome {
                solver: entry.solver.clone(),
                scene: entry.scene.clone(),
                result: CheckResult::Skipped(format!(
                    "a refined check ({}x cells per axis): `cargo xtask crosscheck --refined` runs it",
                    entry.factor
                )),
                tolerance: entry,
            });
            continue;
        }
        let fine;
        let problem = if entry.factor == 1 {
            &scene.built.problem
        } else {
            fine = crate::pareto::refined(scene, entry.factor)?;
            &fine
        };
        let start = Instant::now();
        let solved = match solver.admits(problem) {
            Err(e) => Err(e),
            Ok(()) => solver.solve(problem, &SolveOptions::default()),
        };
        let seconds = start.elapsed().as_secs_f64();
        let result = match solved {
            Err(e) if crate::device_missing(&e) => CheckResult::Skipped(e.to_string()),
            Err(e @ lucent_core::SolveError::Unsupported { .. }) => {
                CheckResult::Skipped(e.to_string())
            }
            Err(e) => return Err(e.into()),
            Ok(solution) => {
                let reference = match &entry.twin {
                    Some(twin) => {
                        let solution = registry
                            .build(twin, &Params::default())?
                            .solve(problem, &SolveOptions::default())?;
                        Reference {
                            fluence: solution.fluence,
                            mask: None,
                            kind: format!("twin `{twin}`"),
                            relative_std_error: 0.0,
                        }
                    }
                    None => reference(scene, capabilities.fluence, entry.tolerance / 5.0, cache)?,
                };
                let mask = reference
                    .mask
                    .clone()
                    .unwrap_or_else(|| vec![true; scene.built.problem.geometry().voxel_count()]);
                let solution_error = solution
                    .standard_error
                    .as_ref()
                    .map(|se| relative_error(&solution.fluence[0], &se[0], &mask));
                CheckResult::Compared {
                    comparison: compare(&solution.fluence, &reference),
                    seconds,
                    reference: reference.kind.clone(),
                    reference_error: reference.relative_std_error,
                    solution_error,
                    stop_reason: solution.report.stop_reason,
                }
            }
        };
        outcomes.push(Outcome {
            solver: entry.solver.clone(),
            scene: entry.scene.clone(),
            tolerance: entry,
            result,
        });
    }
    tell(&outcomes);
    Ok(outcomes)
}

/// A fraction as a percentage: two decimals down to 0.01 %, two significant digits below
/// (the GPU twins' rows compare at 10⁻⁵).
fn percent(fraction: f64) -> String {
    let p = 100.0 * fraction;
    if p == 0.0 || p >= 0.01 {
        format!("{p:.2}%")
    } else {
        format!("{p:.1e}%")
    }
}

/// The validation table as Markdown (`docs/validation.md`).
pub fn validation_markdown(outcomes: &[Outcome], command: &str) -> String {
    let mut out = String::from(
        "# Validation\n\nEvery solver against a reference on the suite scenes of `examples/scenes/suite/`, \
         with the tolerance and the reason for it from `tolerances.toml`. Errors: relative L2 of the fluence over \
         cells above 10⁻³ of the reference's peak, and the largest relative error over cells above 10⁻².\n\n",
    );
    out.push_str(&format!("Generated by `{command}`.\n\n"));
    out.push_str("| solver | scene | reference | tolerance | relative L2 | max relative | own noise | solve time | verdict | why this tolerance |\n");
    out.push_str("|---|---|---|---|---|---|---|---|---|---|\n");
    for o in outcomes {
        let why = o.tolerance.why.replace('|', "/");
        match &o.result {
            CheckResult::Compared {
                comparison,
                seconds,
                reference,
                reference_error,
                solution_error,
                stop_reason,
            } => out.push_str(&format!(
                "| {} | {} | {}{} | {} | {} | {} | {} | {:.2} s | {} | {} |\n",
                o.solver,
                o.scene,
                reference,
                if o.tolerance.twin.is_some() {
                    String::new()
                } else {
                    format!(" (±{:.2}%)", 100.0 * reference_error)
                },
                percent(o.tolerance.tolerance),
                percent(comparison.relative_l2),
                percent(comparison.max_relative),
                solution_error.map_or("–".to_owned(), |e| format!("±{:.2}%", 100.0 * e)),
                seconds,
                match (o.tolerance.expect, o.passed()) {
                    (Expect::Tolerance, true) => "pass".to_owned(),
                    (Expect::Diverged, true) =>
                        format!("pass (diverged as required: {stop_reason:?})"),
                    (_, false) => format!("FAIL ({stop_reason:?})"),
                },
                why
            )),
            CheckResult::Skipped(reason) => out.push_str(&format!(
                "| {} | {} | – | {} | – | – | – | – | skipped: {} | {} |\n",
                o.solver,
                o.scene,
                percent(o.tolerance.tolerance),
                reason,
                why
            )),
        }
    }
    out.push_str(MARBLE_NOTE);
    out.push_str(DOM_NOTE);
    out.push_str(POINT_NOTE);
    out.push_str(CONVECTION_NOTE);
    out.push_str(&elsewhere_note());
    out
}

/// The registered solvers that have no row in the suite's table, and where each is
/// checked instead (a test keeps every registered solver in the table or here).
pub const CHECKED_ELSEWHERE: &[(&str, &str)] = &[
    (
        "direct-refractive",
        "curved rays through a graded refractive index, which no suite scene has: with a uniform index it gives `direct`'s fluence to 2e-5 relative on boxes of several shapes; through a graded index a beam keeps its flux across every cell-centre plane to 1e-4 (measured 1.3e-6); a Luneburg lens focuses a beam on its far rim (`crates/core/tests/it/refractive.rs`)",
    ),
    (
        "auto",
        "runs another registered solver, chosen from measurements: measured against the fastest single solver on every suite scene (\"`auto` against the fastest single solver\" below)",
    ),
];

/// The section on [`CHECKED_ELSEWHERE`].
fn elsewhere_note() -> String {
    let mut out = String::from(
        "\n## Solvers without rows in the table\n\nEvery registered solver has rows above or is here, with where it is checked instead.\n\n",
    );
    for (solver, why) in CHECKED_ELSEWHERE {
        out.push_str(&format!("- `{solver}`: {why}.\n"));
    }
    out
}

/// What the discrete-ordinates solver shows about ray effects and closures.
const DOM_NOTE: &str = "
## Discrete ordinates: ray effects and closures

`dom` against the Monte Carlo reference (total fluence, relative L2), from the error-against-time
sweep of `cargo xtask pareto` (docs/pareto/*.csv, measured 2026-11-23 on the dev machine,
tolerance 1e-4, diamond difference unless stated). The lights' uncollided part is exact
(integrated over each cell, `lucent_core::uncollided_cells`), so what changes with N is the
scattered light's angular discretisation: on the g = 0.8 blob, whose forward peak the low
orders cannot resolve, the error falls by a factor 15 from S2 to S12; on the cloud (g = 0.5, sun and sky) and the slab it falls
until the spatial error and the reference's own noise (0.6%) remain.

| scene | S2 (8) | S4 (24) | S8 (80) | S12 (168) | S8 step | S8 exponential | diffusion-mg |
|---|---|---|---|---|---|---|---|
| anisotropic (g = 0.8) | 17.2% | 8.4% | 1.69% | 1.15% | 2.92% | 1.89% | 18.9% |
| cloud (g = 0.5) | 4.10% | 2.45% | 2.23% | 2.21% | 3.96% | 2.82% | 36.8% |
| slab (isotropic) | 4.53% | 2.29% | 1.65% | 1.48% | 2.48% | 1.70% | 6.0% |

- **Ray effects.** With the first-collision source computed exactly for each light (MDOM), the
  swept light is already once scattered and smooth in angle; what remains of the ray effect is
  the low orders' inability to represent a g = 0.8 lobe (S2's 8 directions are 55° apart).
- **Closures.** Step differencing is first order and smears (false scattering): twice diamond's
  error at S8. Bernabei's exponential face-to-face scheme attenuates with the mean chord, which
  errs by several per cent per cell at σ_t h ≈ 1 (crates/dom/tests/it/closure.rs), so at these
  resolutions it sits between the two.
- **Iterations** (crates/dom/tests/it/transport.rs). DSA with `lucent-diffusion`'s cell-centred
  operator takes albedo 0.999 at σ_t h = 0.67 to 10⁻⁶ in 21 sweeps (12 with Anderson mixing);
  plain source iteration would need about 390. At σ_t h = 2 with diamond difference this
  inconsistent DSA amplifies errors and is dropped (the solver reports `dsa_abandoned`), while
  with Anderson mixing on top it converges in 14 sweeps.
";

/// Point lights inside the medium: what each solver carries into it.
const POINT_NOTE: &str = "
## Point lights inside the medium

Suite scene `point_inside` (a point light in a box-filling scattering medium of odd
dimensions) compares every solver that takes point lights, away from the 1.5 cells around
the light where centre values and cell averages of a 1/r² field differ by O(1).

- **First collisions conserve the light's power** (`lucent_core::uncollided_cells`,
  docs/first-collision.md). `dom` sampled the uncollided light at cell centres next to the
  singularity and lost its power: for a unit light in a 30-mean-free-path box of albedo 0.95
  it absorbed 0.637, 0.798, 0.888 at 16³, 32³, 64³ against 0.986; now 0.9864, 0.9858,
  0.9857, with emitted = absorbed + escaped within 1.3·10⁻⁵ at every resolution
  (crates/dom/tests/it/transport.rs). The diffusion solvers and `fem-diffusion` take the same
  cell integrals for lights outside their medium.
- **The diffusion solvers' point sources** have their singular part taken analytically
  (docs/point-sources.md). In a Robin sphere with the source 4.2 mm off centre at 64³,
  `diffusion-mg` is 3.7·10⁻⁴ from the exact series and `fem-diffusion` 1.2·10⁻³; they agree
  within 0.78% in every cell outside the source's (tests/it/point_sources.rs), where they
  differed by 1.75% (12.8% in the worst cell) with the source as a cell or nodal load. On
  the marble sphere `diffusion-mg` went from 1.0% to 0.08%.
";

/// Zhang & Ma's convection step: the seed's upwind scheme against short characteristics.
const CONVECTION_NOTE: &str = "
## Convection: upwind against short characteristics

`convection-diffusion` against `direct` (exact) under an oblique sun (−0.3, −0.4, −0.8) on a
purely absorbing medium, relative L2 at 16×16×24, 32×32×48, 64×64×96
(crates/explicit/tests/it/registry.rs):

| medium | model | 16 | 32 | 64 | observed order |
|---|---|---|---|---|---|
| smooth blob | characteristic (default) | 7.2e-3 | 2.1e-3 | 5.6e-4 | 1.7, 1.9 |
| smooth blob | conservative upwind | 5.9e-2 | 3.4e-2 | 1.9e-2 | 0.8, 0.9 |
| smooth blob | paper (Zhang & Ma Eq. 16) | 5.6e-2 | 3.3e-2 | 1.8e-2 | 0.8, 0.9 |
| layered, filling the box | characteristic (default) | 2.1e-2 | 1.1e-2 | 5.6e-3 | 0.9, 0.9 |
| layered, filling the box | conservative upwind | 6.8e-2 | 4.5e-2 | 2.8e-2 | 0.6, 0.7 |
| layered, filling the box | paper (Zhang & Ma Eq. 16) | 6.7e-2 | 4.5e-2 | 2.8e-2 | 0.6, 0.7 |

- The upwind models (the seed's, kept as `model = \"paper\"`, and its conservative form) are
  first order and attenuate a cell by 1/(1 + σh) instead of e^{−σh}.
- Short characteristics (`model = \"characteristic\"`, the default) trace each cell's ray back
  to the previous plane of cell centres (or to the box where it enters), interpolate there
  with a monotone biquadratic (limited to the bracketing values), and attenuate exactly:
  second order where the field is smooth. Where light enters a box-filling medium through
  its edges the field has kinks, which every local scheme resolves only to first order; the
  characteristic model's error there is a third to a fifth of the upwind models'.
";

/// What the marble sphere shows about diffusion, with the measurements behind it.
const MARBLE_NOTE: &str = "
## Marble sphere: transport against diffusion

Monte Carlo (a Fresnel interface on the embedded sphere: reflection, refraction, total
internal reflection) against the analytic diffusion solution (Mertens T7) with the Robin
condition, as the ratio of fluences averaged over 1 mm shells (measured 2026-11-23 on the
dev machine with the suite scene and `McConfig { particles: 8000, batches: 8 }`; `cargo test
--release --test it fresnel` asserts the compared shells within 2.5% at 4000 paths
per batch for η = 1, 1.3, 1.4 and 1.5). The diffusion solvers' A is the transport-exact
extrapolation length of the Milne problem, A = 3z_b(η)/2 (docs/milne.md); the P1 boundary
factors (Marshak's 1, Haskell's partial currents, Groenhuis' fit) misplace the extrapolated
boundary by 5–6%:

| η, A | 1–2 | 2–3 | 3–4 | 4–5 | 5–6 | 6–7 | 7–8 | 8–9 | 9–10 mm |
|---|---|---|---|---|---|---|---|---|---|
| 1.0, Milne 1.0657 | 1.003 | 0.995 | 0.994 | 0.994 | 0.993 | 0.993 | 0.995 | 0.992 | 0.969 |
| 1.3, Milne 2.2119 | 1.002 | 0.994 | 0.993 | 0.992 | 0.991 | 0.990 | 0.989 | 0.985 | 0.960 |
| 1.4, Milne 2.7895 | 1.002 | 0.994 | 0.993 | 0.992 | 0.991 | 0.990 | 0.989 | 0.984 | 0.955 |
| 1.5, Milne 3.4457 | 1.002 | 0.994 | 0.993 | 0.992 | 0.992 | 0.990 | 0.990 | 0.987 | 0.953 |
| 1.4, partial current 2.9485 | 1.001 | 0.993 | 0.991 | 0.989 | 0.987 | 0.983 | 0.979 | 0.968 | 0.924 |

The compared region is 3 transport mean free paths (1.37 mm) from the source and from the
surface, r = 1.37–8.63 mm.

- **Near the source** (r < 3 transport mean free paths) diffusion is not meant to hold: the
  point source's first flights are ballistic, and the innermost cells' Monte Carlo averages
  of a 1/r singularity are compared with its values at cell centres (19% in the first shell).
- **Which A.** With the Milne A the profile is flat to within 1% of its interior level for
  every index; with the partial-current A it falls by 2.5% toward the surface for every
  mismatched index. Monte Carlo was right; the P1 boundary factor was the approximation.
  The uniform 0.6% below 1 is the transport/diffusion difference at albedo 0.999 plus cell
  averages against centre values.
- **Within a transport mean free path of the surface** (the last shell) no Robin condition
  holds: the radiance there is far from linearly anisotropic.
";

/// The line that opens `auto`'s section of `docs/validation.md`.
const AUTO_BEGIN: &str = "<!-- auto: written by cargo xtask pareto -->";
/// The line that closes it.
const AUTO_END: &str = "<!-- auto: end -->";

/// `auto`'s section of `docs/validation.md` around `table` (from
/// [`crate::pareto::auto_markdown`]), between its markers.
pub fn auto_section(table: &str) -> String {
    format!(
        "{AUTO_BEGIN}\n## `auto` against the fastest single solver\n\n\
         Measured by `cargo xtask pareto` in the same run as each scene's chart \
         (`docs/pareto/<scene>.svg`, the `auto` curve; data in `docs/pareto/auto_runs.csv`): \
         `auto` at each tolerance with the table of measurements holding the scene's own rows, \
         its error against the scene's total-fluence reference, its wall time (the choice \
         included) over that of the fastest single run of the sweep that meets the \
         tolerance (each the least of three runs timed in turn, the sweep's own run \
         counting for the single one), and, \
         to show how the rule carries to scenes it has not measured, its choice with the \
         scene's rows left out of the table (the nearest other scene's measurements decide). \
         \"no (said so)\": the tolerance was reported as unreachable and the closest run \
         was made.\n\n{table}\n{AUTO_END}\n"
    )
}

/// The `auto` section of `text`, markers included, if it has one.
pub fn auto_section_of(text: &str) -> Option<&str> {
    let start = text.find(AUTO_BEGIN)?;
    let end = text[start..].find(AUTO_END)? + start + AUTO_END.len();
    Some(text[start..end].trim_end())
}

/// `text` with its `auto` section replaced by `section`, or `section` appended.
pub fn with_auto_section(text: &str, section: &str) -> String {
    match auto_section_of(text) {
        Some(old) => text.replacen(old, section.trim_end(), 1),
        None => format!("{}\n\n{}\n", text.trim_end(), section.trim_end()),
    }
}
