//! FTCS diffusion to steady state split over ranks, checked bit for bit against one rank.
//!
//! ```sh
//! cargo run --profile examples -p lucent-mpi --example ftcs_ranks -- 3          # 3 in-process ranks
//! cargo build --profile examples -p lucent-mpi --features mpi --example ftcs_ranks
//! mpirun -n 2 target/examples/examples/ftcs_ranks                                # 2 MPI ranks
//! ```
//!
//! The problem: a heterogeneous diffusion medium in an embedded cylinder along z with a point
//! source, `n_z` = L·ranks layers of S × 5S/6 cells (weak scaling: the same slab per rank;
//! `--layers L`, default 24, and `--side S`, default 24). Every rank also runs the serial iteration on the
//! whole system and compares: the exit status is 1 unless the bits agree. Rank 0 prints the
//! sweeps, the stop reason and the wall time of the decomposed solve.

use std::process::ExitCode;
use std::time::Instant;

use glam::DVec3;
use lucent_core::Stopping;
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, DiffusionProblem, Discretisation, Sources,
};
use lucent_explicit::steady::{Iteration, SteadySettings, ftcs_limit, iterate as serial};
use lucent_grid::GridGeometry;
use lucent_mpi::Communicator;

fn run(comm: &impl Communicator, layers_per_rank: usize, side: usize) -> Result<bool, String> {
    let dims = [side, side * 5 / 6, layers_per_rank * comm.size()];
    let h = 6.0 / side as f64;
    let half = DVec3::new(3.0, 0.5 * h * dims[1] as f64, 0.5 * h * dims[2] as f64);
    let grid = GridGeometry::from_bounds(dims, -half, half).map_err(|e| e.to_string())?;
    // A cylinder along z: every layer holds the same unknowns, so each rank the same work.
    let radius = half.x.min(half.y) * 0.9;
    let cells = CellGeometry::from_sdf(
        grid,
        |p| p.truncate().length() - radius,
        Discretisation::EmbeddedBoundary,
    )
    .map_err(|e| e.to_string())?;
    let n = grid.voxel_count();
    let d: Vec<f32> = (0..n).map(|c| 0.1 + 0.1 * ((c * 7) % 5) as f32).collect();
    let problem = DiffusionProblem::new(
        cells,
        d,
        vec![0.05; n],
        Boundaries::uniform(Condition::Robin { a: 2.2 }),
    )
    .map_err(|e| e.to_string())?;
    let sources = Sources {
        points: vec![(DVec3::new(0.2, -0.1, 0.3), 1.0)],
        ..Sources::default()
    };
    let system = problem.assemble(&sources).map_err(|e| e.to_string())?;
    let volume = grid.cell_volume();
    let iteration = Iteration::Ftcs {
        time_step: 0.9 * ftcs_limit(&system, volume),
        cell_volume: volume,
    };
    let settings = SteadySettings {
        stopping: Stopping {
            relative_tolerance: 1e-6,
            max_iterations: 100_000,
            ..Stopping::default()
        },
        allow_unstable: false,
    };
    let slab = dims[0] * dims[1];
    let start = Instant::now();
    let decomposed = lucent_mpi::steady::iterate(&system, slab, iteration, &settings, comm)
        .map_err(|e| e.to_string())?;
    let seconds = start.elapsed().as_secs_f64();
    let reference = serial(&system, slab, iteration, &settings).map_err(|e| e.to_string())?;
    let same = decomposed
        .fluence
        .iter()
        .map(|v| v.to_bits())
        .eq(reference.fluence.iter().map(|v| v.to_bits()))
        && decomposed
            .residuals
            .iter()
            .map(|v| v.to_bits())
            .eq(reference.residuals.iter().map(|v| v.to_bits()));
    if comm.rank() == 0 {
        eprintln!(
            "{} ranks, {}×{}×{} cells ({} unknowns): {} sweeps, {}, {:.3} s decomposed ({:.1} µs per sweep); bits {} the serial iteration's",
            comm.size(),
            dims[0],
            dims[1],
            dims[2],
            system.rhs.len(),
            decomposed.residuals.len() - 1,
            decomposed.stop_reason,
            seconds,
            seconds * 1e6 / (decomposed.residuals.len() - 1).max(1) as f64,
            if same { "equal" } else { "DIFFER FROM" }
        );
    }
    Ok(same)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let layers = args
        .iter()
        .position(|a| a == "--layers")
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(24);
    let side = args
        .iter()
        .position(|a| a == "--side")
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(24);
    let result = run_on_ranks(&args, layers, side);
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("ftcs_ranks: {e}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(feature = "mpi")]
fn run_on_ranks(_: &[String], layers: usize, side: usize) -> Result<bool, String> {
    let universe = mpi::initialize().ok_or("MPI could not be initialised")?;
    run(&lucent_mpi::Mpi::new(universe.world()), layers, side)
}

#[cfg(not(feature = "mpi"))]
fn run_on_ranks(args: &[String], layers: usize, side: usize) -> Result<bool, String> {
    let ranks: usize = args.first().and_then(|v| v.parse().ok()).unwrap_or(2);
    let worlds = lucent_mpi::Threads::world(ranks);
    std::thread::scope(|scope| {
        let runs: Vec<_> = worlds
            .into_iter()
            .map(|comm| scope.spawn(move || run(&comm, layers, side)))
            .collect();
        runs.into_iter()
            .map(|r| r.join().map_err(|_| "a rank panicked".to_owned())?)
            .try_fold(true, |all, r| r.map(|same| all && same))
    })
}
