//! lucent-grid's integration tests, one binary: `cargo test` runs test binaries one after
//! another, each linked on its own, so one binary per file leaves a core idle behind
//! each file's last long test and links the crate once per file (the repository's
//! `tests/it/main.rs` says more). `cargo test -p lucent-grid --test it MODULE::` runs
//! one file's tests.
//!
//! `tests/full_disk.rs` stays a binary of its own: it re-runs its own binary under `ulimit -f`, naming one test.

mod formats;
mod grid_ops;
mod hostile_files;
mod layers;
mod line_integral;
mod media;
mod real_data;
mod vti;
