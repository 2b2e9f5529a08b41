//! Repository automation, run as `cargo xtask <command>` (plain Rust, no shell scripts).
//!
//! Commands:
//! - `ci`: what `.ci/run` checks, in the same order: formatting, clippy with warnings
//!   denied, documentation with warnings denied, then the README's test command.
//! - `doc`: `cargo doc --workspace --no-deps` with rustdoc warnings denied.
//! - `tidy`: the repository's own checks (`tests/it/tidy.rs`): crate docs present, no stray
//!   `dbg!`/`todo!`, every crate listed in ARCHITECTURE.md.
//! - `crosscheck [--refined]`: every solver on every suite scene against its reference
//!   (with `--refined`, the convergence checks on refined grids too); prints the
//!   table and writes `docs/validation.md`. Monte Carlo references are stored in
//!   `examples/scenes/suite/references/` (committed: the test run reads them instead of
//!   computing them); a reference no entry used is removed.
//!
//! - `pareto [--reuse | --redraw] [SCENE...]`: error against wall time for every solver on the suite
//!   scenes (all of them by default), as `docs/pareto/<scene>.svg` and `.csv`; `auto`'s
//!   table and its runs (`--reuse`: from the CSVs already there, re-running only `auto`;
//!   `--redraw`: the charts alone, drawn again from the CSVs, measuring nothing).
//!
//! - `mitsuba [SPP]`: the default cloud and `examples/scenes/box_filling.toml` (a medium
//!   filling a box of odd dimensions) at 256×256 rendered by lucent's Monte Carlo and by
//!   Mitsuba 3 (`pip install mitsuba`; `scalar_rgb` and `llvm_ad_rgb`) with the same camera,
//!   lights, medium, spp and depth; prints the mean difference, per-pixel z-scores and both
//!   renderers' paths per second. Not part of the default test run.
//!
//! - `bench-diffusion [N...]`: lucent-diffusion's multigrid on the marble sphere at N³
//!   (64, 128, 256): time to 1e-8, one smoothing sweep's GB/s beside the copy bandwidth
//!   measured in the same run, pyamg and scipy CG on the same exported matrix, and on a real
//!   GPU the device's V-cycles (`DeviceMultigrid`), all in one run. With `--gpu`: only the
//!   device table, on any adapter (lavapipe: for correctness).
//! - `bench-gpu [N...]`: every GPU backend at N³ (default 64, 128): seconds per step,
//!   cell updates per second and GB/s by byte count, with the adapter's name; on a CPU
//!   implementation (lavapipe) a correctness run only.
//! - `bench-explicit [N]`: one step of each explicit scheme at N³ with updates/s and GB/s
//!   beside the copy bandwidth, and Zhang & Ma's full update for one light.
//! - `bench-fem [N...]`: Q1 finite elements (matrix-based) against the matrix-free finite
//!   volumes on the same box: assembly, bytes per unknown, solve time.
//! - `bench-dom [N] [ORDER] [--gpu]`: a converged discrete-ordinates solve at N³ (128) with
//!   S_ORDER (6: 48 directions), g = 0.6: wall time, sweeps, time per cell-direction and
//!   GB/s; with `--gpu`, `gpu-dom` with its block and its cell wavefront (and `dom` beside
//!   them up to 128³): the device's kernel
//!   time per cell-direction and per converged solve.
//! - `bench-paging [N] [BRICK] [DOM_N]`: an FTCS stencil swept in core and out of core (two
//!   paged fields, 1/16 of their bricks resident, a backing file) at N³ (256) with B³
//!   bricks (16): time per sweep against in core, hit rates, bytes moved, LRU against NRU,
//!   with and without prefetch, time skewing (1–16 steps per pass); then a discrete-
//!   ordinates sweep at DOM_N³ (128, S6) with its per-direction work in memory and paged at
//!   1/16 resident; and whether the results are bit for bit equal.
//! - `paged-solve [SOLVER] [N] [BUDGET_MIB] [BRICK]`: `direct` (or `convection-diffusion`,
//!   `mc`, `ftcs-diffusion`, `jacobi-diffusion`)
//!   on a sparse N³ cloud (256) out of core under a budget (32 MiB) and in memory: wall
//!   time, measured peak resident memory, pager counters, and whether the results are bit
//!   for bit equal.
//! - `bench-lbm [N]`: lattice steps at N³ (128) for D3Q7 and D3Q19, in place and with two
//!   arrays: million lattice updates per second and GB/s beside the copy bandwidth.
//! - `stability`: each explicit scheme's measured blow-up boundary against its theoretical
//!   curves, as `docs/stability/*.svg` and `.csv` (see `docs/stability.md`).

// This binary reports to the terminal.
#![allow(clippy::print_stdout)]

mod bench_diffusion;
mod bench_dom;
mod bench_explicit;
mod bench_fem;
mod bench_gpu;
mod bench_lbm;
mod bench_paging;
mod chart;
mod paged_solve;
mod stability;

use std::process::{Command, ExitCode};

const USAGE: &str = "usage: cargo xtask <ci | doc | tidy | crosscheck [--refined] | pareto [--reuse | --redraw] [SCENE...] | mitsuba [SPP] | bench-diffusion [N...] [--gpu] | bench-explicit [N] | bench-gpu [N...] | bench-paging [N] [BRICK] [DOM_N] | paged-solve [SOLVER] [N] [BUDGET_MIB] [BRICK] | bench-fem [N...] | bench-dom [N] [ORDER] [--gpu] | bench-lbm [N] | stability | fuzz [TARGET...] [--runs N] [--seed S]>";

fn main() -> ExitCode {
    let command = std::env::args().nth(1);
    if command.as_deref() == Some("fuzz") {
        return fuzz(std::env::args().skip(2).collect());
    }
    if command.as_deref() == Some("crosscheck") {
        let refined = std::env::args().any(|a| a == "--refined");
        return crosscheck(refined);
    }
    if command.as_deref() == Some("mitsuba") {
        let spp = std::env::args()
            .nth(2)
            .and_then(|s| s.parse().ok())
            .unwrap_or(64);
        return match mitsuba(spp) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("xtask: mitsuba: {e}");
                ExitCode::FAILURE
            }
        };
    }
    if command.as_deref() == Some("bench-explicit") {
        let n = std::env::args()
            .nth(2)
            .and_then(|s| s.parse().ok())
            .unwrap_or(128);
        return match bench_explicit::run(n) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("xtask: bench-explicit: {e}");
                ExitCode::FAILURE
            }
        };
    }
    if command.as_deref() == Some("bench-gpu") {
        let mut sizes: Vec<usize> = std::env::args()
            .skip(2)
            .filter_map(|s| s.parse().ok())
            .collect();
        if sizes.is_empty() {
            sizes = vec![64, 128];
        }
        return match bench_gpu::run(&sizes) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("xtask: bench-gpu: {e}");
                ExitCode::FAILURE
            }
        };
    }
    if command.as_deref() == Some("bench-paging") {
        let args: Vec<usize> = std::env::args()
            .skip(2)
            .filter_map(|s| s.parse().ok())
            .collect();
        let n = args.first().copied().unwrap_or(256);
        let brick = args.get(1).copied().unwrap_or(16);
        let dom_n = args.get(2).copied().unwrap_or(128);
        return match bench_paging::run(n, brick, dom_n) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("xtask: bench-paging: {e}");
                ExitCode::FAILURE
            }
        };
    }
    if command.as_deref() == Some("paged-solve") {
        let rest: Vec<String> = std::env::args().skip(2).collect();
        let solver = rest
            .iter()
            .find(|s| s.parse::<u64>().is_err())
            .cloned()
            .unwrap_or_else(|| "direct".into());
        let args: Vec<u64> = rest.iter().filter_map(|s| s.parse().ok()).collect();
        let n = args.first().copied().unwrap_or(256) as usize;
        let budget = args.get(1).copied().unwrap_or(32);
        let brick = args.get(2).copied().unwrap_or(16) as usize;
        return match paged_solve::run(&solver, n, budget, brick) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("xtask: paged-solve: {e}");
                ExitCode::FAILURE
            }
        };
    }
    if command.as_deref() == Some("bench-fem") {
        let mut sizes: Vec<usize> = std::env::args()
            .skip(2)
            .filter_map(|s| s.parse().ok())
            .collect();
        if sizes.is_empty() {
            sizes = vec![64, 128];
        }
        return match bench_fem::run(&sizes) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("xtask: bench-fem: {e}");
                ExitCode::FAILURE
            }
        };
    }
    if command.as_deref() == Some("bench-lbm") {
        let n = std::env::args()
            .nth(2)
            .and_then(|s| s.parse().ok())
            .unwrap_or(128);
        return match bench_lbm::run(n) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("xtask: bench-lbm: {e}");
                ExitCode::FAILURE
            }
        };
    }
    if command.as_deref() == Some("bench-dom") {
        let gpu = std::env::args().skip(2).any(|a| a == "--gpu");
        let mut args = std::env::args().skip(2).filter_map(|s| s.parse().ok());
        let n = args.next().unwrap_or(128);
        let order = args.next().unwrap_or(6);
        return match bench_dom::run(n, order, gpu) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("xtask: bench-dom: {e}");
                ExitCode::FAILURE
            }
        };
    }
    if command.as_deref() == Some("stability") {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        return match stability::run(&root) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("xtask: stability: {e}");
                ExitCode::FAILURE
            }
        };
    }
    if command.as_deref() == Some("bench-diffusion") {
        let mut sizes: Vec<usize> = std::env::args()
            .skip(2)
            .filter_map(|s| s.parse().ok())
            .collect();
        if sizes.is_empty() {
            sizes = vec![64, 128, 256];
        }
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let gpu = std::env::args().any(|a| a == "--gpu");
        return match bench_diffusion::run(&sizes, &root, gpu) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("xtask: bench-diffusion: {e}");
                ExitCode::FAILURE
            }
        };
    }
    if command.as_deref() == Some("pareto") && std::env::args().any(|a| a == "--redraw") {
        return redraw();
    }
    if command.as_deref() == Some("pareto") {
        let args: Vec<String> = std::env::args().skip(2).collect();
        let reuse = args.iter().any(|a| a == "--reuse");
        return pareto(args.into_iter().filter(|a| a != "--reuse").collect(), reuse);
    }
    if command.as_deref() == Some("ci") {
        return ci();
    }
    let steps: Vec<Vec<&str>> = match command.as_deref() {
        Some("doc") => vec![vec!["doc", "--workspace", "--no-deps"]],
        Some("tidy") => vec![vec![
            "test",
            "--package",
            "lucent",
            "--test",
            "it",
            "tidy::",
        ]],
        _ => {
            eprintln!("{USAGE}");
            return ExitCode::FAILURE;
        }
    };
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned());
    for args in steps {
        eprintln!("xtask: cargo {}", args.join(" "));
        let status = Command::new(&cargo)
            .args(&args)
            .env("RUSTDOCFLAGS", "-D warnings")
            .status();
        match status {
            Ok(s) if s.success() => {}
            Ok(s) => {
                eprintln!("xtask: `cargo {}` failed ({s})", args.join(" "));
                return ExitCode::FAILURE;
            }
            Err(e) => {
                eprintln!("xtask: could not run cargo: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    ExitCode::SUCCESS
}

/// Runs `.ci/run`, the script CI runs: formatting, clippy, rustdoc, the README's test
/// command, the Python bindings under pytest and the MPI checks, installing what they need
/// (lavapipe, python3-venv, OpenMPI; with `sudo` when not root). One script, so that this
/// command cannot drift from CI.
fn ci() -> ExitCode {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    match Command::new("bash").arg(root.join(".ci/run")).status() {
        Ok(s) if s.success() => ExitCode::SUCCESS,
        Ok(s) => {
            eprintln!("xtask: .ci/run failed ({s})");
            ExitCode::FAILURE
        }
        Err(e) => {
            eprintln!("xtask: could not run .ci/run: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Runs the cross-check harness and writes `docs/validation.md`.
fn crosscheck(refined: bool) -> ExitCode {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    if std::env::var_os("LUCENT_DATA").is_none() {
        eprintln!("xtask: LUCENT_DATA not set; the suite's CT scene reads ../shared/data/volumes");
    }
    let started = std::time::Instant::now();
    let selection = if refined {
        lucent::crosscheck::Selection::Refined
    } else {
        lucent::crosscheck::Selection::All
    };
    let outcomes = match lucent::crosscheck::run_with(
        &root.join("examples/scenes/suite"),
        Some(&root.join("examples/scenes/suite/references")),
        selection,
        &mut |progress| eprintln!("xtask: {progress}"),
    ) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("xtask: crosscheck failed: {e}");
            return ExitCode::FAILURE;
        }
    };
    let suite = root.join("examples/scenes/suite");
    if let Ok((scenes, _)) = lucent::crosscheck::load_suite(&suite) {
        for stale in lucent::crosscheck::stale_references(&suite.join("references"), &scenes) {
            eprintln!("xtask: removing the stale reference {}", stale.display());
            let _ = std::fs::remove_file(stale);
        }
    }
    let command = if refined {
        "cargo xtask crosscheck --refined"
    } else {
        "cargo xtask crosscheck"
    };
    let markdown = lucent::crosscheck::validation_markdown(&outcomes, command);
    // auto's section comes from `cargo xtask pareto`: carried over as it is.
    let previous = std::fs::read_to_string(root.join("docs/validation.md")).unwrap_or_default();
    let markdown = match lucent::crosscheck::auto_section_of(&previous) {
        Some(section) => lucent::crosscheck::with_auto_section(&markdown, section),
        None => markdown,
    };
    eprint!("{markdown}");
    eprintln!(
        "xtask: crosscheck took {:.1} s",
        started.elapsed().as_secs_f64()
    );
    if let Err(e) = std::fs::write(root.join("docs/validation.md"), &markdown) {
        eprintln!("xtask: cannot write docs/validation.md: {e}");
        return ExitCode::FAILURE;
    }
    if outcomes.iter().all(|o| o.passed()) {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

/// Draws every chart of `docs/pareto/` again from its CSV and `auto`'s runs, measuring
/// nothing (after a change to the charts alone).
fn redraw() -> ExitCode {
    let out = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/pareto");
    let read = |path: &std::path::Path| {
        std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))
    };
    let run = || -> Result<usize, String> {
        let autos = lucent::pareto::parse_auto_csv(&read(&out.join("auto_runs.csv"))?)?;
        let mut drawn = 0;
        for entry in std::fs::read_dir(&out).map_err(|e| e.to_string())? {
            let path = entry.map_err(|e| e.to_string())?.path();
            let scene = path.file_stem().unwrap_or_default().to_string_lossy();
            if path.extension().is_none_or(|e| e != "csv") || scene.starts_with("auto") {
                continue;
            }
            let points = lucent::pareto::parse_csv(&read(&path)?)?;
            let autos: Vec<_> = autos.iter().filter(|a| a.scene == scene).cloned().collect();
            let svg = chart::Chart::new(&chart::title(&scene), &points, &autos).svg()?;
            let target = path.with_extension("svg");
            std::fs::write(&target, svg).map_err(|e| format!("{}: {e}", target.display()))?;
            drawn += 1;
        }
        Ok(drawn)
    };
    match run() {
        Ok(drawn) => {
            eprintln!("xtask: {drawn} charts drawn again in {}", out.display());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Sweeps every solver on the suite scenes and writes the error-against-time charts, the
/// table `auto` chooses from (`docs/pareto/auto.csv`), `auto`'s own runs on each scene
/// (`docs/pareto/auto_runs.csv`, drawn on the chart too) and their table in
/// `docs/validation.md`.
///
/// With `--reuse` the solvers are not run again: each scene's points are read from its
/// `docs/pareto/<scene>.csv` and only the table's features and `auto`'s runs are measured
/// (for a change to `auto` alone).
fn pareto(only: Vec<String>, reuse: bool) -> ExitCode {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let cache = root.join("examples/scenes/suite/references");
    let out = root.join("docs/pareto");
    let scenes = match lucent::crosscheck::load_suite(&root.join("examples/scenes/suite")) {
        Ok((scenes, _)) => scenes,
        Err(e) => {
            eprintln!("xtask: {e}");
            return ExitCode::FAILURE;
        }
    };
    if let Err(e) = std::fs::create_dir_all(&out) {
        eprintln!("xtask: cannot create {}: {e}", out.display());
        return ExitCode::FAILURE;
    }
    let table_path = out.join("auto.csv");
    let runs_path = out.join("auto_runs.csv");
    let read = |path: &std::path::Path| std::fs::read_to_string(path).unwrap_or_default();
    let mut table = lucent::auto::Table::parse(&read(&table_path)).unwrap_or_default();
    let mut auto_runs = lucent::pareto::parse_auto_csv(&read(&runs_path)).unwrap_or_default();
    let mut swept = Vec::new();
    let write = |path: &std::path::Path, text: &str| {
        std::fs::write(path, text)
            .map_err(|e| eprintln!("xtask: cannot write {}: {e}", path.display()))
    };
    // A scene's points: swept, or read back with `--reuse`; printed.
    let measure = |scene: &lucent::crosscheck::SuiteScene| {
        let measured = if reuse {
            lucent::pareto::reuse(scene, &out, Some(&cache))
        } else {
            lucent::pareto::sweep(scene, Some(&cache))
        };
        match measured {
            Ok(sweep) if sweep.points.is_empty() => {
                eprintln!("xtask: {}: no solver can run it yet", scene.name);
                None
            }
            Ok(sweep) => {
                for p in &sweep.points {
                    eprintln!(
                        "{:<14} {:<7} {:<32} {:>9.3} s {:>8.3}% (total {:>8.3}%)",
                        scene.name,
                        p.solver,
                        p.setting,
                        p.seconds,
                        100.0 * p.error,
                        100.0 * p.error_total
                    );
                }
                Some(sweep)
            }
            Err(e) => {
                eprintln!("xtask: {}: {e}", scene.name);
                None
            }
        }
    };
    // `auto` on a scene with its own rows in `table` (`own`) or not; printed.
    let run_auto = |scene: &lucent::crosscheck::SuiteScene,
                    table: &lucent::auto::Table,
                    sweep: &lucent::pareto::Sweep,
                    own: bool,
                    what: &str| {
        let autos = lucent::pareto::measure_auto(
            scene,
            table,
            sweep,
            &lucent::pareto::AUTO_TOLERANCES,
            &[own],
        )
        .unwrap_or_else(|e| {
            eprintln!("xtask: {}: auto ({what}): {e}", scene.name);
            Vec::new()
        });
        for a in &autos {
            eprintln!(
                "{:<14} auto {:>5.1}% {what}: {} (nearest {}) -> {:.3} s {:.3}% (fastest meeting it: {:?})",
                scene.name,
                100.0 * a.tolerance,
                a.chose,
                a.nearest,
                a.seconds,
                100.0 * a.error_total,
                a.fastest
            );
        }
        autos
    };
    // The chart and the points of a scene.
    let chart = |scene: &lucent::crosscheck::SuiteScene,
                 title: &str,
                 sweep: &lucent::pareto::Sweep,
                 autos: &[lucent::pareto::AutoPoint]| {
        let svg = match chart::Chart::new(title, &sweep.points, autos).svg() {
            Ok(svg) => svg,
            Err(e) => {
                eprintln!("xtask: {}: the chart: {e}", scene.name);
                return Err(());
            }
        };
        let csv = lucent::pareto::csv(&sweep.points);
        [("svg", svg), ("csv", csv)]
            .iter()
            .try_for_each(|(ext, text)| write(&out.join(format!("{}.{ext}", scene.name)), text))
    };
    for scene in scenes
        .iter()
        .filter(|s| only.is_empty() || only.contains(&s.name))
    {
        let Some(sweep) = measure(scene) else {
            continue;
        };
        table = table.with_scene(lucent::pareto::measured_scene(scene, &sweep.points));
        if write(&table_path, &table.to_csv()).is_err() {
            return ExitCode::FAILURE;
        }
        let autos = run_auto(scene, &table, &sweep, true, "own rows");
        auto_runs.retain(|a| a.scene != scene.name);
        auto_runs.extend(autos.iter().cloned());
        if write(&runs_path, &lucent::pareto::auto_csv(&auto_runs)).is_err() {
            return ExitCode::FAILURE;
        }
        if chart(scene, &chart::title(&scene.name), &sweep, &autos).is_err() {
            return ExitCode::FAILURE;
        }
        swept.push((scene, sweep));
    }
    // With every scene measured: each scene's choice with its own rows left out.
    for (scene, sweep) in &swept {
        let autos = run_auto(scene, &table, sweep, false, "left out");
        auto_runs.retain(|a| a.scene != scene.name || a.own_rows);
        auto_runs.extend(autos);
    }
    // Held-out scenes of mixed regime: charted, and `auto` run on them with the whole
    // table, which never holds them.
    let held_out = match lucent::crosscheck::load_scenes(&root.join("examples/scenes/mixed")) {
        Ok(scenes) => scenes,
        Err(e) => {
            eprintln!("xtask: {e}");
            return ExitCode::FAILURE;
        }
    };
    for scene in held_out
        .iter()
        .filter(|s| only.is_empty() || only.contains(&s.name))
    {
        let Some(sweep) = measure(scene) else {
            continue;
        };
        let mut autos = run_auto(scene, &table, &sweep, false, "held out");
        for a in &mut autos {
            a.held_out = true;
        }
        auto_runs.retain(|a| a.scene != scene.name);
        auto_runs.extend(autos.iter().cloned());
        let title = format!(
            "{} (held out): error against time (dev machine)",
            scene.name
        );
        if chart(scene, &title, &sweep, &autos).is_err() {
            return ExitCode::FAILURE;
        }
    }
    if write(&runs_path, &lucent::pareto::auto_csv(&auto_runs)).is_err() {
        return ExitCode::FAILURE;
    }
    // auto's table in docs/validation.md, between its markers (the cross-check keeps it).
    let validation = root.join("docs/validation.md");
    let text = read(&validation);
    // The hybrid on the held-out scenes of mixed regime, from their charts' points.
    let mixed: Vec<(String, Vec<lucent::pareto::Point>)> = held_out
        .iter()
        .filter_map(|scene| {
            let text = read(&out.join(format!("{}.csv", scene.name)));
            lucent::pareto::parse_csv(&text)
                .ok()
                .map(|points| (scene.name.clone(), points))
        })
        .collect();
    let body = format!(
        "{}\n## The hybrid against every single solver on the mixed scenes\n\n\
         `hybrid` (uncollided light exact, up to K scattering orders by S_N sweeps, the rest \
         by multigrid diffusion: docs/hybrid.md) on the held-out scenes of mixed regime, \
         from the same sweep as their charts (`docs/pareto/<scene>.svg`): each of its points \
         against the least error of the total fluence that any single CPU run reached in no \
         more time.\n\n{}",
        lucent::pareto::auto_markdown(&auto_runs),
        lucent::pareto::hybrid_markdown(&mixed)
    );
    let section = lucent::crosscheck::auto_section(&body);
    if write(
        &validation,
        &lucent::crosscheck::with_auto_section(&text, &section),
    )
    .is_err()
    {
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}

/// Renders the default cloud and a medium that fills its box (`examples/scenes/
/// box_filling.toml`, odd dimensions) with lucent's Monte Carlo and with Mitsuba 3, and
/// compares them.
fn mitsuba(spp: usize) -> Result<(), String> {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let cloud = lucent::scene::Scene::default_scene().map_err(|e| e.to_string())?;
    let box_filling = root.join("examples/scenes/box_filling.toml");
    let filling = lucent::scene::Scene::load(&box_filling).map_err(|e| e.to_string())?;
    let mut results = Vec::new();
    for (name, scene) in [("cloud", cloud), ("box_filling", filling)] {
        let json = mitsuba_scene(&root, name, &scene, spp)?;
        results.push(format!("\"{name}\": {json}"));
    }
    println!("{{{}}}", results.join(", "));
    Ok(())
}

/// One scene of [`mitsuba`]: returns its JSON comparison.
fn mitsuba_scene(
    root: &std::path::Path,
    name: &str,
    scene: &lucent::scene::Scene,
    spp: usize,
) -> Result<String, String> {
    use lucent::core::{Field, Light};
    use lucent::optics::Phase;
    let dir = root.join("target/mitsuba").join(name);
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let built = scene.build(root).map_err(|e| e.to_string())?;
    let problem = &built.problem;
    let medium = problem.medium();
    if medium.sigma_t.len() != 1 {
        return Err("only grey extinction is exported".into());
    }
    let albedo: Vec<f64> = (0..3)
        .map(|c| match medium.albedo(c) {
            Field::Constant(v) => Ok(f64::from(*v)),
            Field::Grid(_) => Err("only constant albedo is exported".to_owned()),
        })
        .collect::<Result<_, _>>()?;
    let g = match medium.phase {
        Phase::Isotropic => 0.0,
        Phase::HenyeyGreenstein(hg) => hg.g(),
        other => return Err(format!("phase {other:?} is not exported")),
    };
    let mut lights = Vec::new();
    for light in problem.lights() {
        let value: Vec<f64> = (0..3).map(|c| light.spectrum().channel(c)).collect();
        match light {
            Light::Directional { direction, .. } => lights.push(lucent_json(&[
                ("kind", "\"directional\"".into()),
                ("direction", format!("{:?}", direction.to_array())),
                ("value", format!("{value:?}")),
            ])),
            Light::Sky { .. } => lights.push(lucent_json(&[
                ("kind", "\"sky\"".into()),
                ("value", format!("{value:?}")),
            ])),
            other => return Err(format!("{:?} lights are not exported", other.kind())),
        }
    }
    let (width, height) = (256usize, 256usize);
    let (position, look_at, up, fov) = match built.camera {
        lucent::render::Camera::Pinhole {
            position,
            look_at,
            up,
            fov,
        } => (position, look_at, up, fov),
        _ => return Err("only pinhole cameras are exported".into()),
    };
    // The volume: σ_t as a Mitsuba grid, placed by to_world (Mitsuba ignores the file's box).
    let volume = dir.join("sigma_t.vol");
    lucent::grid::io::mitsuba::write(&volume, &[&medium.sigma_t[0]]).map_err(|e| e.to_string())?;
    // lucent's image, timed.
    let config = lucent::mc::McConfig {
        seed: 42,
        ..Default::default()
    };
    let camera = built.camera;
    let aspect = width as f64 / height as f64;
    let background = std::array::from_fn(|c| {
        problem
            .lights()
            .iter()
            .filter(|l| matches!(l, Light::Sky { .. }))
            .map(|l| l.spectrum().channel(c))
            .sum()
    });
    let start = std::time::Instant::now();
    let estimate =
        lucent::mc::camera_image(problem, width, height, spp, background, &config, |u, v| {
            camera.ray(u, v, aspect).unwrap_or_default()
        })
        .map_err(|e| e.to_string())?;
    let lucent_seconds = start.elapsed().as_secs_f64();
    let image = lucent::render::Image {
        width,
        height,
        pixels: estimate.radiance,
    };
    let stderr = lucent::render::Image {
        width,
        height,
        pixels: estimate.std_error,
    };
    let (image_path, stderr_path) = (dir.join("lucent.f32"), dir.join("lucent_stderr.f32"));
    image
        .write_exr(dir.join("lucent.exr"))
        .map_err(|e| e.to_string())?;
    let raw = |img: &lucent::render::Image| {
        img.pixels
            .iter()
            .flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes()))
            .collect::<Vec<u8>>()
    };
    std::fs::write(&image_path, raw(&image)).map_err(|e| e.to_string())?;
    std::fs::write(&stderr_path, raw(&stderr)).map_err(|e| e.to_string())?;
    let (lo, hi) = problem.geometry().bounds();
    // llvm_ad_rgb needs LLVM 19 (15 and 16 abort or hang at the first render): only with
    // DRJIT_LIBLLVM_PATH pointing at it.
    let variants = if std::env::var_os("DRJIT_LIBLLVM_PATH").is_some() {
        r#"["scalar_rgb", "llvm_ad_rgb"]"#
    } else {
        r#"["scalar_rgb"]"#
    };
    let config_json = format!(
        "{{\"variants\": {variants}, \"width\": {width}, \"height\": {height}, \"spp\": {spp}, \"max_depth\": -1, \
         \"bounds\": [{:?}, {:?}], \"camera\": {{\"position\": {position:?}, \"look_at\": {look_at:?}, \"up\": {up:?}, \"fov\": {fov}}}, \
         \"volume\": {:?}, \"albedo\": {albedo:?}, \"g\": {g}, \"lights\": [{}], \"output_prefix\": {:?}, \
         \"lucent_image\": {:?}, \"lucent_stderr\": {:?}}}",
        lo.to_array(),
        hi.to_array(),
        volume.display().to_string(),
        lights.join(", "),
        dir.join("mitsuba_").display().to_string(),
        image_path.display().to_string(),
        stderr_path.display().to_string()
    );
    let config_path = dir.join("config.json");
    std::fs::write(&config_path, config_json).map_err(|e| e.to_string())?;
    let script = dir.join("render.py");
    std::fs::write(&script, include_str!("mitsuba.py")).map_err(|e| e.to_string())?;
    let output = Command::new("python3")
        .arg(&script)
        .arg(&config_path)
        .output()
        .map_err(|e| format!("python3: {e}"))?;
    if !output.status.success() {
        return Err(format!(
            "the Mitsuba script failed (is `pip install mitsuba` done?):\n{}",
            String::from_utf8_lossy(&output.stderr)
        ));
    }
    let paths = (width * height * spp) as f64;
    eprintln!(
        "{name}: lucent mc: {lucent_seconds:.2} s, {:.0} paths/s",
        paths / lucent_seconds
    );
    Ok(format!(
        "{{\"lucent\": {{\"seconds\": {lucent_seconds}, \"paths_per_second\": {}}}, \"mitsuba\": {}}}",
        paths / lucent_seconds,
        String::from_utf8_lossy(&output.stdout).trim()
    ))
}

/// A tiny JSON object from pre-formatted values.
fn lucent_json(fields: &[(&str, String)]) -> String {
    let inner: Vec<String> = fields
        .iter()
        .map(|(k, v)| format!("\"{k}\": {v}"))
        .collect();
    format!("{{{}}}", inner.join(", "))
}

/// `cargo xtask fuzz [TARGET...] [--runs N] [--seed S]`, or `--write-seeds` to write the
/// libFuzzer harness's starting corpus: the stable mutation harness over
/// `lucent::fuzzing`'s targets (all by default, 10⁶ runs each), starting from their seeds
/// and the committed regression corpus. A crash or a slow input is written to
/// `fuzz/artifacts/<target>/` and fails the command.
fn fuzz(args: Vec<String>) -> ExitCode {
    use lucent::fuzzing::{Target, campaign};
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let (mut runs, mut seed, mut targets) = (1_000_000u64, 1u64, Vec::new());
    let mut args = args.into_iter();
    while let Some(a) = args.next() {
        match a.as_str() {
            "--runs" => runs = args.next().and_then(|v| v.parse().ok()).unwrap_or(runs),
            "--seed" => seed = args.next().and_then(|v| v.parse().ok()).unwrap_or(seed),
            "--write-seeds" => {
                // The starting corpus of the libFuzzer harness: fuzz/corpus/<target>/, the
                // generated seeds and the real files of $LUCENT_DATA.
                for target in Target::ALL {
                    let dir = root.join("fuzz/corpus").join(target.name());
                    let _ = std::fs::create_dir_all(&dir);
                    let all = lucent::fuzzing::seeds(target)
                        .into_iter()
                        .chain(real_files(target));
                    for (i, input) in all.enumerate() {
                        let _ = std::fs::write(dir.join(format!("seed-{i}")), input);
                    }
                }
                println!("wrote fuzz/corpus/<target>/seed-*");
                return ExitCode::SUCCESS;
            }
            name => match Target::from_name(name) {
                Some(t) => targets.push(t),
                None => {
                    eprintln!("xtask: fuzz: unknown target `{name}`");
                    return ExitCode::FAILURE;
                }
            },
        }
    }
    if targets.is_empty() {
        targets = Target::ALL.to_vec();
    }
    println!(
        "| target | executions | accepted | distinct outcomes | crashes | slow (> 1 s) | seconds | executions/s |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut failed = false;
    for target in targets {
        let corpus = root.join("fuzz/regressions").join(target.name());
        let mut extra: Vec<Vec<u8>> = std::fs::read_dir(&corpus)
            .map(|entries| {
                entries
                    .filter_map(|e| e.ok())
                    .filter_map(|e| std::fs::read(e.path()).ok())
                    .collect()
            })
            .unwrap_or_default();
        extra.extend(real_files(target));
        let f = campaign(target, runs, seed, &extra);
        println!(
            "| {} | {} | {} | {} | {} | {} | {:.0} | {:.0} |",
            target.name(),
            f.executions,
            f.accepted,
            f.distinct_outcomes,
            f.crashes.len(),
            f.slow.len(),
            f.seconds,
            f.executions as f64 / f.seconds.max(1e-9)
        );
        let artifacts = root.join("fuzz/artifacts").join(target.name());
        for (i, (input, message)) in f.crashes.iter().enumerate() {
            let _ = std::fs::create_dir_all(&artifacts);
            let _ = std::fs::write(artifacts.join(format!("crash-{i}")), input);
            eprintln!("xtask: fuzz: {} crash {i}: {message}", target.name());
            failed = true;
        }
        for (i, (input, seconds)) in f.slow.iter().enumerate() {
            let _ = std::fs::create_dir_all(&artifacts);
            let _ = std::fs::write(artifacts.join(format!("slow-{i}")), input);
            eprintln!(
                "xtask: fuzz: {} slow input {i}: {seconds:.1} s",
                target.name()
            );
            failed = true;
        }
    }
    if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}

/// The real volumes of `$LUCENT_DATA` (default `../shared/data/volumes`) in `target`'s
/// format, up to 512 kB each (larger ones make every execution slow; `smoke.vdb` is 2.5 MB
/// and the VDB target starts from a minimal file instead).
fn real_files(target: lucent::fuzzing::Target) -> Vec<Vec<u8>> {
    let extensions: &[&str] = match target.name() {
        "nrrd" => &["nrrd", "nhdr"],
        "mhd" => &["mhd", "mha"],
        "vtk" => &["vtk"],
        "vol" => &["vol"],
        "npy" => &["npy"],
        "vdb" => &["vdb"],
        _ => &[],
    };
    let dir = std::env::var_os("LUCENT_DATA").map_or_else(
        || std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/volumes"),
        std::path::PathBuf::from,
    );
    std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|p| {
                    p.extension()
                        .and_then(|x| x.to_str())
                        .is_some_and(|x| extensions.contains(&x))
                })
                .filter(|p| std::fs::metadata(p).is_ok_and(|m| m.len() <= 512 << 10))
                .filter_map(|p| std::fs::read(p).ok())
                .collect()
        })
        .unwrap_or_default()
}
