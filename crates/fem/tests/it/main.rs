//! lucent-fem's integration tests, one binary: `cargo test` runs test binaries one after
//! another, each linked on its own, so one binary per file leaves a core idle behind
//! each file's last long test and links the crate once per file (the repository's
//! `tests/it/main.rs` says more). `cargo test -p lucent-fem --test it MODULE::` runs
//! one file's tests.

mod murray;
mod p1ls;
mod q1;
mod registry;
mod sphere;
