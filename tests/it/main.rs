//! lucent's end-to-end tests, one test binary (rust-analyzer's and matklad's layout: every
//! file under `tests/` of its own is a separate binary, linked against the whole tree, and
//! `cargo test` runs binaries one after another, so a binary whose last test is long holds
//! one core idle). Here the modules' tests share one pool of test threads and one link.
//!
//! Two files stay binaries of their own, because they measure their process: `stops.rs`
//! (how long a solve takes to stop after a signal, on cores it shares out itself) and
//! `memory_estimates.rs` (the process's peak resident set during a solve).
//!
//! `cargo test --test it MODULE::` runs one module, e.g. `cargo test --test it cli::`.

mod auto;
mod bad_input;
mod cli;
mod cross_check;
mod fuzz_regressions;
mod mc_vs_direct;
mod paged_contract;
mod point_sources;
mod progress;
mod ranks;
mod reproducible;
mod resolution;
mod solver_contract;
mod tidy;
