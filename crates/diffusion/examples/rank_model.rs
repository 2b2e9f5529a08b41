//! The cost model of the multigrid on ranks (`BENCHMARKS.md`, "Multigrid on ranks"): for a
//! cube of n³ cells on P ranks, over z-slabs and over boxes, the stages `RankLayout` gives
//! and the time of one V(2,2) cycle on the critical path (the largest box), from a few
//! machine constants. Nothing is solved: it prints the model for the layouts the solver
//! would use.
//!
//! ```sh
//! cargo run --release -p lucent-diffusion --example rank_model -- 1024 64 256 1024
//! ```
//!
//! The terms, per cycle: compute t_c × (the largest box's cells) summed over levels; on
//! each split level 9 halo exchanges (a colour of each of the four sweeps, one before the
//! restriction) of one cell layer across each face with a neighbour, as f64, of which what
//! the colour's sweep of the inner cells does not hide is paid, and 9 · 2α of latency per
//! cut axis (slabs: one; boxes: up to three); at each stage boundary the
//! right-hand side down and the correction up, 2 · (2α + a coarse owner's share / B); and
//! the norm's all-reduce, recursive doubling of one exact accumulator (71 words, 568
//! bytes): ⌊log₂P⌋ rounds, two more where P is not a power of two, α + 568/B each.

use lucent_diffusion::{Cycle, Decomposition, RankLayout};

/// Seconds per cell, level and V(2,2) cycle on one core (measured: 22 ns per fine cell and
/// cycle over the hierarchy's 8/7).
const T_CELL: f64 = 19e-9;
/// Network bandwidth (bytes/s) and latency (s).
const BANDWIDTH: f64 = 10e9;
const LATENCY: f64 = 2e-6;

fn levels(n: usize) -> Vec<[usize; 3]> {
    // Multigrid::build coarsens while every axis keeps four cells or more.
    let mut dims = vec![[n; 3]];
    while dims.last().is_some_and(|d| d[0] / 2 >= 4) {
        let d = dims[dims.len() - 1].map(|n| n.div_ceil(2));
        dims.push(d);
    }
    dims
}

#[allow(clippy::print_stdout)] // An example: its report is its output.
fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let (n, ranks) = match args.split_first() {
        Some((&n, ranks)) if !ranks.is_empty() => (n, ranks.to_vec()),
        _ => (1024, vec![64, 256, 1024]),
    };
    let dims = levels(n);
    let cells = |l: usize| dims[l].iter().product::<usize>() as f64;
    let serial: f64 = (0..dims.len()).map(|l| cells(l) * T_CELL).sum();
    println!(
        "{n}³, {} levels: one core {:.2} s per cycle",
        dims.len(),
        serial
    );
    for p in ranks {
        for decomposition in [Decomposition::Slabs, Decomposition::Boxes] {
            let layout = match RankLayout::with(
                &dims,
                p,
                Cycle::V,
                RankLayout::COARSE_CELLS_PER_RANK,
                decomposition,
            ) {
                Ok(layout) => layout,
                Err(e) => {
                    eprintln!("rank_model: {e}");
                    continue;
                }
            };
            let m = model(&layout, &dims);
            let total = m.iter().sum::<f64>();
            let [compute, halo, latency, hand_over, norm] = m;
            let stages: Vec<String> = layout
                .stages
                .iter()
                .map(|s| {
                    let last = s.first_level + s.levels - 1;
                    let [px, py, pz] = s.grid();
                    let on = if px * py == 1 {
                        format!("{}", s.ranks())
                    } else {
                        format!("{px}×{py}×{pz}")
                    };
                    if last == s.first_level {
                        format!("{on}×L{last}")
                    } else {
                        format!("{on}×L{}–{last}", s.first_level)
                    }
                })
                .collect();
            println!(
                "{p} ranks, {decomposition:?} [{}]: compute {:.1} ms, halo {:.2} ms, latency {:.2} ms, \
                 hand-overs {:.2} ms, norm {:.3} ms; {:.1} ms per cycle, {:.0}× one core ({:.0} % of {p})",
                stages.join(", "),
                compute * 1e3,
                halo * 1e3,
                latency * 1e3,
                hand_over * 1e3,
                norm * 1e3,
                total * 1e3,
                serial / total,
                100.0 * serial / total / p as f64
            );
        }
    }
}

/// Seconds per V(2,2) cycle of `layout` over levels of `dims`: compute, halo bandwidth not
/// hidden, halo latency, hand-overs, the norm.
fn model(layout: &RankLayout, dims: &[[usize; 3]]) -> [f64; 5] {
    let cells = |l: usize| dims[l].iter().product::<usize>() as f64;
    let (mut compute, mut halo, mut latency, mut hand_over) = (0.0, 0.0, 0.0, 0.0);
    for stage in &layout.stages {
        let q = stage.ranks() as f64;
        let grid = stage.grid();
        for l in stage.first_level..stage.first_level + stage.levels {
            if stage.ranks() == 1 {
                compute += cells(l) * T_CELL;
                continue;
            }
            // The largest box: the critical path.
            let side = |a: usize| (dims[l][a] as f64 / grid[a] as f64).ceil();
            let box_cells = side(0) * side(1) * side(2);
            compute += box_cells * T_CELL;
            // Faces across each cut axis, both sides (an inner box's).
            let cut: Vec<usize> = (0..3).filter(|&a| grid[a] > 1).collect();
            let face_cells: f64 = cut.iter().map(|&a| 2.0 * box_cells / side(a)).sum();
            let message = face_cells * 8.0 / BANDWIDTH;
            // One colour's sweep of the inner cells: half of them, a ninth of a cycle's
            // work per cell.
            let inner: f64 = (0..3)
                .map(|a| {
                    if grid[a] > 1 {
                        (side(a) - 2.0).max(0.0)
                    } else {
                        side(a)
                    }
                })
                .product();
            let hidden = inner * T_CELL / 9.0 / 2.0;
            halo += 9.0 * (message - hidden).max(0.0);
            latency += 9.0 * 2.0 * cut.len() as f64 * LATENCY;
        }
        if stage.first_level > 0 {
            let share = cells(stage.first_level) / q;
            hand_over += 2.0 * (2.0 * LATENCY + share * 8.0 / BANDWIDTH);
        }
    }
    let p = layout.stages[0].ranks().max(1);
    let power = usize::BITS - 1 - p.leading_zeros();
    let rounds = f64::from(power) + if p.is_power_of_two() { 0.0 } else { 2.0 };
    let norm = rounds * (LATENCY + 568.0 / BANDWIDTH);
    [compute, halo, latency, hand_over, norm]
}
