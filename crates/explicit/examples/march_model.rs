//! Where Zhang & Ma's absorption march over boxes stops scaling: the schedule
//! `wavefront::propagate_box` follows on an n³ grid for each grid of boxes given
//! (`wavefront::box_schedule`; nothing is marched), and a cost model from it.
//!
//! ```sh
//! cargo run --release -p lucent-explicit --example march_model -- 1024 1,1,64 8,8,1 4,4,4 32,32,1 1,1,1024
//! ```
//!
//! For each grid of boxes and each march (short characteristics with the light along z,
//! (0.3, −0.2, 1), and along x, (1, 0.3, −0.2); the paper's pass), one line: the frame the
//! schedule chose, its steps, the steps the busiest rank computes in, its messages and
//! bytes, and the model's time
//!
//! T_P = steps / busy × (cells per rank × t_c) + steps × α + bytes / β,
//!
//! with t_c = 0.25 µs per cell (the measured march on one core of dev-2c), α = 2 µs and
//! β = 10 GB/s (a cluster's network): the compute stretched by the pipeline's fill, one
//! latency per step, and the halo's bytes. `speed-up` is n³ t_c / T_P. `schedule` is the
//! wall time this machine took to derive every rank's schedule and count its messages
//! (this example's model); `a rank's plan` the tasks one rank (the middle one) derives
//! before it marches, and the time it took (`wavefront::rank_plan_tasks`): in lock step
//! (planes) its own and its neighbours' tasks, otherwise every rank's.

use glam::DVec3;
use lucent_explicit::convection::Model;
use lucent_explicit::ranks::Boxes;
use lucent_explicit::wavefront::{box_schedule, rank_plan_tasks};

const SECONDS_PER_CELL: f64 = 0.25e-6;
const LATENCY: f64 = 2e-6;
const BANDWIDTH: f64 = 10e9;

#[allow(clippy::print_stdout)]
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let n: usize = args.first().map_or(Ok(256), |a| a.parse())?;
    let grids: Vec<[usize; 3]> = if args.len() > 1 {
        args[1..]
            .iter()
            .map(|g| {
                let v: Vec<usize> = g.split(',').map(str::parse).collect::<Result<_, _>>()?;
                match v[..] {
                    [x, y, z] => Ok([x, y, z]),
                    _ => Err(format!("{g}: PX,PY,PZ").into()),
                }
            })
            .collect::<Result<_, Box<dyn std::error::Error>>>()?
    } else {
        vec![[1, 1, 64], [8, 8, 1], [4, 4, 4]]
    };
    let axis = ["x", "y", "z"];
    println!(
        "{n}³ cells; t_c = {} µs per cell, α = {} µs, β = {} GB/s",
        SECONDS_PER_CELL * 1e6,
        LATENCY * 1e6,
        BANDWIDTH / 1e9
    );
    println!(
        "| boxes | march | A, L, D | rows | order | steps | busy | messages | MB sent | T_P | speed-up | schedule | a rank's plan |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for grid in grids {
        let boxes = Boxes::new([n; 3], grid)?;
        let ranks = boxes.ranks();
        for (name, direction, model) in [
            (
                "characteristic, z",
                DVec3::new(0.3, -0.2, 1.0),
                Model::Characteristic,
            ),
            (
                "characteristic, x",
                DVec3::new(1.0, 0.3, -0.2),
                Model::Characteristic,
            ),
            ("paper", DVec3::new(0.3, -0.2, 1.0), Model::Paper),
        ] {
            let started = std::time::Instant::now();
            let s = box_schedule(&boxes, direction, model)?;
            let scheduled = started.elapsed().as_secs_f64();
            let started = std::time::Instant::now();
            let planned = rank_plan_tasks(&boxes, direction, model, ranks / 2)?;
            let plan_seconds = started.elapsed().as_secs_f64();
            let busiest = (0..ranks).max_by_key(|&r| s.busy[r]).unwrap_or(0);
            let cells = (n * n * n) as f64 / ranks as f64;
            let bytes = 8.0 * s.values.iter().copied().max().unwrap_or(0) as f64;
            let messages = s.messages.iter().copied().max().unwrap_or(0);
            let time = s.steps as f64 / s.busy[busiest].max(1) as f64 * cells * SECONDS_PER_CELL
                + s.steps as f64 * LATENCY
                + bytes / BANDWIDTH;
            println!(
                "| {grid:?} | {name} | {}, {}, {} | {} | {} | {} | {} | {messages} | {:.1} | {:.3} s | {:.0} | {scheduled:.2} s | {planned} tasks, {plan_seconds:.3} s |",
                axis[s.axes[0]],
                axis[s.axes[1]],
                axis[s.axes[2]],
                s.rows,
                if s.plane_major { "planes" } else { "chunks" },
                s.steps,
                s.busy[busiest],
                bytes / 1e6,
                time,
                (n * n * n) as f64 * SECONDS_PER_CELL / time
            );
        }
    }
    Ok(())
}
