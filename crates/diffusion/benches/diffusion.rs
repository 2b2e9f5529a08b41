//! Criterion benchmarks of lucent-diffusion (filled in below).

fn main() {}
