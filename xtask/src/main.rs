//! Repository automation, run as `cargo xtask <command>` (plain Rust, no shell scripts).
//!
//! Commands:
//! - `ci`: what `.ci/run` checks, in the same order: formatting, clippy with warnings
//!   denied, documentation with warnings denied, then the README's test command.
//! - `doc`: `cargo doc --workspace --no-deps` with rustdoc warnings denied.
//! - `tidy`: the repository's own checks (`tests/tidy.rs`): crate docs present, no stray
//!   `dbg!`/`todo!`, every crate listed in ARCHITECTURE.md.
//! - `crosscheck`: every solver on every suite scene against its reference; prints the
//!   table and writes `docs/validation.md`. References are cached in
//!   `target/crosscheck-cache/`.
//!
//! - `pareto [SCENE...]`: error against wall time for every solver on the suite scenes
//!   (all of them by default), as `docs/pareto/<scene>.svg` and `.csv`.
//!
//! Later issues add the external comparisons (Mitsuba, pyamg, scipy) here.

use std::process::{Command, ExitCode};

const USAGE: &str = "usage: cargo xtask <ci | doc | tidy | crosscheck | pareto [SCENE...]>";

fn main() -> ExitCode {
    let command = std::env::args().nth(1);
    if command.as_deref() == Some("crosscheck") {
        return crosscheck();
    }
    if command.as_deref() == Some("pareto") {
        return pareto(std::env::args().skip(2).collect());
    }
    let steps: Vec<Vec<&str>> = match command.as_deref() {
        Some("ci") => vec![
            vec!["fmt", "--all", "--check"],
            vec![
                "clippy",
                "--workspace",
                "--all-targets",
                "--",
                "-D",
                "warnings",
            ],
            vec!["doc", "--workspace", "--no-deps"],
            vec!["test", "--workspace"],
        ],
        Some("doc") => vec![vec!["doc", "--workspace", "--no-deps"]],
        Some("tidy") => vec![vec!["test", "--package", "lucent", "--test", "tidy"]],
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

/// Runs the cross-check harness and writes `docs/validation.md`.
fn crosscheck() -> ExitCode {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    if std::env::var_os("LUCENT_DATA").is_none() {
        eprintln!("xtask: LUCENT_DATA not set; the suite's CT scene reads ../shared/data/volumes");
    }
    let started = std::time::Instant::now();
    let outcomes = match lucent::crosscheck::run(
        &root.join("examples/scenes/suite"),
        Some(&root.join("target/crosscheck-cache")),
    ) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("xtask: crosscheck failed: {e}");
            return ExitCode::FAILURE;
        }
    };
    let markdown = lucent::crosscheck::validation_markdown(&outcomes, "cargo xtask crosscheck");
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

/// Sweeps every solver on the suite scenes and writes the error-against-time charts.
fn pareto(only: Vec<String>) -> ExitCode {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let cache = root.join("target/crosscheck-cache");
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
    for scene in scenes
        .iter()
        .filter(|s| only.is_empty() || only.contains(&s.name))
    {
        let points = match lucent::pareto::sweep(scene, Some(&cache)) {
            Ok(p) => p,
            Err(e) => {
                eprintln!("xtask: {}: {e}", scene.name);
                continue;
            }
        };
        if points.is_empty() {
            eprintln!("xtask: {}: no solver can run it yet", scene.name);
            continue;
        }
        for p in &points {
            eprintln!(
                "{:<14} {:<7} {:<32} {:>9.3} s {:>8.3}%",
                scene.name,
                p.solver,
                p.setting,
                p.seconds,
                100.0 * p.error
            );
        }
        let title = format!("{}: error against time (dev machine)", scene.name);
        let svg = lucent::pareto::svg(&title, &points);
        let csv = lucent::pareto::csv(&points);
        for (ext, text) in [("svg", svg), ("csv", csv)] {
            let path = out.join(format!("{}.{ext}", scene.name));
            if let Err(e) = std::fs::write(&path, text) {
                eprintln!("xtask: cannot write {}: {e}", path.display());
                return ExitCode::FAILURE;
            }
        }
    }
    ExitCode::SUCCESS
}
