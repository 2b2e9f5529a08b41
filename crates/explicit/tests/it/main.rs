//! lucent-explicit's integration tests, one binary: `cargo test` runs test binaries one after
//! another, each linked on its own, so one binary per file leaves a core idle behind
//! each file's last long test and links the crate once per file (the repository's
//! `tests/it/main.rs` says more). `cargo test -p lucent-explicit --test it MODULE::` runs
//! one file's tests.

mod blocks;
mod murray;
mod paged;
mod paged_march;
mod paged_steady;
mod ranks;
mod registry;
mod steady;
mod wavefront;
mod zhang_ma;
