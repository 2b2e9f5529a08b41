//! `cargo xtask bench-lbm [N]`: lattice steps at N³ (128 by default) for both lattices and
//! both streaming patterns, best of 3 runs of 20 steps: million lattice updates per second
//! (cells × steps), GB/s by the step's minimal traffic — every population read and written
//! once (8Q bytes), ρ read and written (8), two coefficients and the source read (12) — and
//! the share of the copy bandwidth measured in the same run.

use lucent::core::Stopping;
use lucent::lbm::{
    Absorption, Collision, LatticeProblem, MarchSettings, Streaming, Velocities, Wall, march,
};

use crate::bench_diffusion::{best_of, copy_bandwidth};

/// Runs the benchmark.
pub(crate) fn run(n: usize) -> Result<(), String> {
    let cells = n * n * n;
    let (serial, parallel) = copy_bandwidth();
    println!(
        "# cargo xtask bench-lbm ({n}³, {} threads)",
        rayon::current_num_threads()
    );
    println!();
    println!(
        "copy bandwidth (256 MiB f32, read + write): {:.1} GB/s on all threads, {:.1} on one",
        parallel / 1e9,
        serial / 1e9
    );
    println!();
    println!(
        "| lattice | streaming | memory per cell | ms per step | MLUPS | bytes per update | GB/s | of copy |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut source = vec![0.0f32; cells];
    source[cells / 2 + n * n / 2 + n / 2] = 1.0;
    let problem = LatticeProblem {
        dims: [n; 3],
        first: vec![0.8; cells],
        second: vec![0.01; cells],
        source,
        first_moment: Vec::new(),
        wall: Wall::Robin { a: 1.0657 },
    };
    let steps = 20;
    for velocities in [Velocities::D3q7, Velocities::D3q19] {
        for streaming in [Streaming::InPlace, Streaming::TwoArrays] {
            let settings = MarchSettings {
                velocities,
                collision: Collision::Trt,
                absorption: Absorption::True,
                streaming,
                stopping: Stopping {
                    relative_tolerance: 0.0,
                    max_iterations: steps,
                    ..Stopping::default()
                },
            };
            let mut error = None;
            let seconds = best_of(3, || {
                if let Err(e) = march(&problem, &settings) {
                    error = Some(e.to_string());
                }
            });
            if let Some(e) = error {
                return Err(e);
            }
            let q = velocities.len() as f64;
            let per_step = seconds / steps as f64;
            let updates = cells as f64 / per_step;
            let bytes = 8.0 * q + 20.0;
            let gbs = updates * bytes / 1e9;
            let copies = match streaming {
                Streaming::InPlace => 1.0,
                Streaming::TwoArrays => 2.0,
            };
            println!(
                "| {velocities:?} | {streaming:?} | {:.0} B | {:.1} | {:.1} | {bytes:.0} | {gbs:.2} | {:.0} % |",
                4.0 * q * copies + 16.0,
                per_step * 1e3,
                updates / 1e6,
                100.0 * gbs * 1e9 / parallel
            );
        }
    }
    Ok(())
}
