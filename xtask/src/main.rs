//! Repository automation, run as `cargo xtask <command>` (plain Rust, no shell scripts).
//!
//! Commands:
//! - `ci`: what `.ci/run` checks, in the same order: formatting, clippy with warnings
//!   denied, documentation with warnings denied, then the README's test command.
//! - `doc`: `cargo doc --workspace --no-deps` with rustdoc warnings denied.
//! - `tidy`: the repository's own checks (`tests/tidy.rs`): crate docs present, no stray
//!   `dbg!`/`todo!`, every crate listed in ARCHITECTURE.md.
//!
//! Later issues add `crosscheck`, `pareto` and the external comparisons here.

use std::process::{Command, ExitCode};

const USAGE: &str = "usage: cargo xtask <ci | doc | tidy>";

fn main() -> ExitCode {
    let command = std::env::args().nth(1);
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
