//! `cargo xtask bench-lbm [N]`: lattice steps at N³ (128 by default) for both lattices and
//! both streaming patterns, the step's own time (the median step of a 42-step march, each
//! step's end stamped by the progress report, the better of two marches: no set-up or
//! first touch of the populations): million lattice updates per second (cells × steps),
//! GB/s by the step's minimal traffic — every population read and written
//! once (8Q bytes), ρ read and written (8), two coefficients and the source read (12) — and
//! the share of the copy bandwidth measured in the same run.

use lucent::core::Stopping;
use lucent::lbm::{
    Absorption, Blocks, Collision, LatticeProblem, MarchSettings, Streaming, Velocities, Wall,
    march,
};

use crate::bench_diffusion::copy_bandwidth;

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
    // The steps' own time: each step's end is stamped by the stopping rule's progress
    // report, and the median of the step-to-step times over a march (after its first two
    // steps, which first touch the populations) is the step's cost, without set-up or the
    // end's books, and robust to the other tenants' bursts on a shared machine.
    let steps = 42;
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
                blocks: None,
            };
            let mut medians = Vec::new();
            for _ in 0..2 {
                let stamps = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
                let sink = stamps.clone();
                let settings = MarchSettings {
                    stopping: Stopping {
                        progress: Some(std::sync::Arc::new(move |_| {
                            if let Ok(mut s) = sink.lock() {
                                s.push(std::time::Instant::now());
                            }
                        })),
                        ..settings.stopping.clone()
                    },
                    ..settings.clone()
                };
                march(&problem, &settings).map_err(|e| e.to_string())?;
                let stamps = stamps.lock().map_err(|e| e.to_string())?.clone();
                let mut times: Vec<f64> = stamps
                    .windows(2)
                    .skip(2)
                    .map(|w| (w[1] - w[0]).as_secs_f64())
                    .collect();
                times.sort_by(f64::total_cmp);
                medians.push(times[times.len() / 2]);
            }
            let q = velocities.len() as f64;
            let per_step = medians.iter().copied().fold(f64::INFINITY, f64::min);
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
    blockwise()
}

/// Bernabei's blockwise scheduling against the synchronous march: D3Q7 TRT, two arrays,
/// a 32³ box with a source off centre and Robin walls, converged to a residual of 1e-6;
/// iterations (sweeps for blockwise), cell updates and seconds.
fn blockwise() -> Result<(), String> {
    let n = 32;
    let cells = n * n * n;
    let mut source = vec![0.0f32; cells];
    source[n / 3 + n * (n / 2 + n * (n / 4))] = 1.0;
    let problem = LatticeProblem {
        dims: [n; 3],
        first: vec![0.4; cells],
        second: vec![0.02; cells],
        source,
        first_moment: Vec::new(),
        wall: Wall::Robin { a: 1.0657 },
    };
    println!();
    println!("blockwise scheduling ({n}³, D3Q7, TRT, two arrays, to a residual of 1e-6):");
    println!();
    println!(
        "| schedule | iterations | cell updates | seconds | fluence vs synchronous (rel. L2) |"
    );
    println!("|---|---|---|---|---|");
    let mut reference: Option<Vec<f32>> = None;
    for blocks in [
        None,
        Some(Blocks {
            slabs: 8,
            steps_per_visit: 1,
        }),
        Some(Blocks {
            slabs: 8,
            steps_per_visit: 4,
        }),
        Some(Blocks {
            slabs: 16,
            steps_per_visit: 16,
        }),
    ] {
        let settings = MarchSettings {
            velocities: Velocities::D3q7,
            collision: Collision::Trt,
            absorption: Absorption::True,
            streaming: Streaming::TwoArrays,
            stopping: Stopping {
                relative_tolerance: 1e-6,
                max_iterations: 20_000,
                ..Stopping::default()
            },
            blocks,
        };
        let started = std::time::Instant::now();
        let marched = march(&problem, &settings).map_err(|e| e.to_string())?;
        let seconds = started.elapsed().as_secs_f64();
        let updates = marched.steps * blocks.map_or(1, |b| b.steps_per_visit) * cells;
        let difference = match &reference {
            None => "—".to_owned(),
            Some(r) => {
                let (mut d, mut s) = (0.0f64, 0.0f64);
                for (a, b) in marched.fluence.iter().zip(r) {
                    d += (f64::from(*a) - f64::from(*b)).powi(2);
                    s += f64::from(*b).powi(2);
                }
                format!("{:.1e}", (d / s).sqrt())
            }
        };
        let name = match blocks {
            None => "synchronous".to_owned(),
            Some(b) => format!(
                "blocks of {} slabs, {} steps per visit",
                b.slabs, b.steps_per_visit
            ),
        };
        println!(
            "| {name} | {} ({}) | {:.2e} | {seconds:.2} | {difference} |",
            marched.steps, marched.stop_reason, updates as f64
        );
        if reference.is_none() {
            reference = Some(marched.fluence);
        }
    }
    Ok(())
}
