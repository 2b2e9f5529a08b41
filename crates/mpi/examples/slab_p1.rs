//! Murray's P1 by FTCS from an emitting volume on ranks, no rank holding the whole volume:
//! each rank reads its z-layers (or its box of cells, `--boxes`) of the volume as the
//! emission q0 (positioned reads of `.raw`, `.npy` or raw-encoded NRRD), marches P1 with
//! its face neighbours (`lucent_explicit::ranks::march_p1_box`), and writes its cells of
//! the fluence into one `.npy` by positioned writes.
//!
//! ```sh
//! cargo build --profile examples -p lucent-mpi --features mpi --example slab_p1
//! mpirun -n 4 target/examples/examples/slab_p1 "$LUCENT_DATA/nucleon.nrrd" \
//!     --boxes auto -o fluence.npy
//! ```
//!
//! The medium is homogeneous in the volume's box, on cubic cells of `--spacing` (default 1
//! length unit): σ_a = `--sigma-a` and σ_t′ = `--sigma-t-reduced` (per length, defaults 0.3
//! and 2), consistent damping, the staggered layout, zero edges, a time step of 0.9 of the
//! stability bound. q0 = `--scale` × sample (default 0.01 per sample unit). The march stops
//! at a relative change of `--tolerance` (default 1e-6) or after `--max-steps` (default
//! 20 000). `--boxes auto` (the grid of boxes with the least cut area) or `--boxes PX,PY,PZ`
//! splits the volume into boxes instead of z-slabs. `--check`: every rank also reads the
//! whole volume, marches it serially and compares its cells, the steps and every step's
//! change (bits; exit status 1 if they differ), for CI. Without the `mpi` feature,
//! `--ranks N` in-process ranks.

use std::path::PathBuf;
use std::process::ExitCode;

use lucent_core::Stopping;
use lucent_explicit::Lattice;
use lucent_explicit::p1::{Damping, Layout, P1Edges, P1Settings, march};
use lucent_explicit::ranks::{Boxes, march_p1_box};
use lucent_grid::io::layers::{create_npy, write_npy_region};
use lucent_grid::io::raw::RawLayout;
use lucent_mpi::Communicator;

mod slabs;

struct Args {
    volume: PathBuf,
    out: PathBuf,
    raw: Option<RawLayout>,
    scale: f64,
    spacing: f64,
    sigma_a: f64,
    sigma_t_reduced: f64,
    tolerance: f64,
    max_steps: usize,
    check: bool,
    /// `--boxes`: `None` for z-slabs, `Some(None)` for `auto`, or the grid of boxes.
    boxes: Option<Option<[usize; 3]>>,
}

fn parse(args: &[String]) -> Result<Args, String> {
    let value = |name: &str| slabs::value(args, name);
    let number = |name: &str, default: f64| -> Result<f64, String> {
        value(name).map_or(Ok(default), |v| slabs::numbers(&v).map(|n| n[0]))
    };
    let volume = args.first().filter(|a| !a.starts_with('-')).ok_or(
        "usage: slab_p1 VOLUME -o OUT.npy [--raw NX,NY,NZ,TYPE] [--scale S] [--spacing H] \
         [--sigma-a A] [--sigma-t-reduced T] [--tolerance T] [--max-steps N] \
         [--boxes auto|PX,PY,PZ] [--check]",
    )?;
    Ok(Args {
        volume: PathBuf::from(volume),
        out: PathBuf::from(value("-o").ok_or("-o OUT.npy is needed")?),
        raw: value("--raw").map(|t| slabs::raw_layout(&t)).transpose()?,
        scale: number("--scale", 0.01)?,
        spacing: number("--spacing", 1.0)?,
        sigma_a: number("--sigma-a", 0.3)?,
        sigma_t_reduced: number("--sigma-t-reduced", 2.0)?,
        tolerance: number("--tolerance", 1e-6)?,
        max_steps: number("--max-steps", 20_000.0)? as usize,
        check: args.iter().any(|a| a == "--check"),
        boxes: slabs::boxes_arg(args)?,
    })
}

fn run(comm: &(impl Communicator + ?Sized), args: &Args) -> Result<bool, String> {
    let (size, rank) = (comm.size(), comm.rank());
    let dims = slabs::read(&args.volume, args.raw.as_ref(), 0..1)?
        .whole
        .dims();
    let boxes = match args.boxes {
        Some(grid) => slabs::boxes(grid, dims, size)?,
        None => Boxes::new(dims, [1, 1, size]).map_err(|e| e.to_string())?,
    };
    let own = boxes.bounds(rank);
    // Its cells only: P1's source is read where the rank computes.
    let samples = slabs::agree(
        comm,
        slabs::region(&args.volume, args.raw.as_ref(), own.clone()),
    )?;
    let source: Vec<f64> = samples
        .grid
        .data()
        .iter()
        .map(|&s| args.scale * f64::from(s))
        .collect();
    let lattice = Lattice::new(dims, args.spacing).map_err(|e| e.to_string())?;
    let limit = lucent_explicit::stability::p1::largest_step(
        true,
        args.sigma_a,
        args.sigma_t_reduced,
        args.spacing,
    );
    let settings = P1Settings {
        layout: Layout::Staggered,
        damping: Damping::Consistent {
            sigma_a: args.sigma_a,
            sigma_t_reduced: args.sigma_t_reduced,
        },
        time_step: 0.9 * limit,
        stopping: Stopping {
            relative_tolerance: args.tolerance,
            max_iterations: args.max_steps,
            ..Stopping::default()
        },
        edges: P1Edges::Zero,
        allow_unstable: false,
    };
    let started = std::time::Instant::now();
    let state =
        march_p1_box(&lattice, &source, &boxes, &settings, comm).map_err(|e| e.to_string())?;
    let seconds = started.elapsed().as_secs_f64();
    // Every rank has the same stop reason: all of them refuse to write a blown-up field.
    if state.stop_reason.is_diverged() {
        return Err(format!("the march {}", state.stop_reason));
    }
    let created = if rank == 0 {
        create_npy(&args.out, dims).map_err(|e| e.to_string())
    } else {
        Ok(())
    };
    slabs::agree(comm, created)?;
    let values: Vec<f32> = state.fluence.iter().map(|&v| v as f32).collect();
    let written = write_npy_region(&args.out, dims, own.clone(), &values);
    slabs::publish(comm, &args.out, written.map_err(|e| e.to_string()))?;
    if rank == 0 {
        eprintln!(
            "{} steps, {}, {seconds:.3} s; boxes {:?}",
            state.steps,
            state.stop_reason,
            boxes.grid()
        );
    }
    eprintln!("rank {rank} of {size}: read and wrote cells {own:?} of {dims:?}");
    let mut agrees = true;
    if args.check {
        let whole = slabs::read(&args.volume, args.raw.as_ref(), 0..dims[2])?;
        let source: Vec<f64> = whole
            .grid
            .data()
            .iter()
            .map(|&s| args.scale * f64::from(s))
            .collect();
        let serial = march(&lattice, &source, &settings, None).map_err(|e| e.to_string())?;
        let [nx, ny, _] = dims;
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let mine: Vec<f64> = lucent_grid::box_cells(&own)
            .map(|[i, j, k]| serial.fluence[i + nx * (j + ny * k)])
            .collect();
        agrees = bits(&mine) == bits(&state.fluence)
            && bits(&serial.changes) == bits(&state.changes)
            && serial.steps == state.steps
            && serial.stop_reason == state.stop_reason;
        eprintln!(
            "rank {rank}: the serial march's bits on the whole volume: {}",
            if agrees { "yes" } else { "NO" }
        );
    }
    Ok(agrees)
}

fn main() -> ExitCode {
    slabs::main("slab_p1", parse, |comm, args| run(comm, args))
}
