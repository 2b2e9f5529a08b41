//! Diffusion through a volume file on ranks, no rank holding the whole volume or system:
//! each rank reads its z-layers (or its box of cells, `--boxes`) of the volume and the
//! cells beyond its faces (positioned reads of `.raw`, `.npy` or raw-encoded NRRD), builds
//! its cells' rows (`lucent_diffusion::SlabSystem::block`), iterates Jacobi or FTCS to the
//! steady state with its neighbours (`lucent_explicit::ranks::iterate_block`), and writes
//! its cells of the fluence into one `.npy` by positioned writes.
//!
//! ```sh
//! cargo build --profile examples -p lucent-mpi --features mpi --example slab_diffusion
//! mpirun -n 4 target/examples/examples/slab_diffusion "$LUCENT_DATA/nucleon.nrrd" \
//!     --scale 0.05 --boxes auto -o fluence.npy
//! ```
//!
//! The medium fills the volume's box (its cells, its spacing as the file gives it, in cm):
//! σ_t = `--background` + `--scale` × sample (1/cm, defaults 0.1 and 0.02), albedo
//! `--albedo` (default 0.9, isotropic scattering): σ_a = (1 − albedo) σ_t and
//! D = 1/(3 σ_t). A point source of 1 W at `--source X,Y,Z` (fractions of the box,
//! default its centre); Robin faces with boundary factor `--robin A` (default 1, index
//! matched). `--method jacobi` (default, ω = 1), `ftcs` (0.9 of the bound over every
//! rank's rows) or `mg` (the V(2,2) multigrid, each rank building its part of every level
//! from its box of the multigrid's layout: `SlabSystem::solve_multigrid_on_layout`);
//! `--tolerance` (default 1e-4) and `--max-sweeps` (default 20 000; cycles for `mg`).
//! `--boxes auto` (the grid of boxes with the least cut area, `ranks::Boxes::auto`) or
//! `--boxes PX,PY,PZ` splits the volume into boxes instead of z-slabs.
//! `--check`: every rank also reads the whole volume, assembles the whole system, iterates
//! (or, for `mg`, builds the whole hierarchy and solves) it serially and compares its
//! layers and the history (bits; exit status 1 if they differ), for CI. Without the `mpi` feature, `--ranks N` in-process ranks.

use std::path::PathBuf;
use std::process::ExitCode;

use glam::DVec3;
use lucent_core::Stopping;
use lucent_diffusion::slab::{BlockFields, PointShares};
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, Decomposition, DiffusionProblem, Multigrid,
    MultigridSettings, RankLayout, SlabSystem, Sources,
};
use lucent_explicit::ranks::{block_ftcs_limit, iterate_block};
use lucent_explicit::steady::{Iteration, SteadySettings, ftcs_limit, iterate};
use lucent_grid::GridGeometry;
use lucent_grid::io::layers::{create_npy, write_npy_region};
use lucent_grid::io::raw::RawLayout;
use lucent_mpi::Communicator;

mod slabs;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Method {
    Jacobi,
    Ftcs,
    Multigrid,
}

struct Args {
    volume: PathBuf,
    out: PathBuf,
    raw: Option<RawLayout>,
    scale: f64,
    background: f64,
    albedo: f64,
    robin: f64,
    source: DVec3,
    method: Method,
    tolerance: f64,
    max_sweeps: usize,
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
        "usage: slab_diffusion VOLUME -o OUT.npy [--raw NX,NY,NZ,TYPE] [--scale S] \
         [--background B] [--albedo A] [--robin A] [--source X,Y,Z] [--method jacobi|ftcs|mg] \
         [--tolerance T] [--max-sweeps N] [--boxes auto|PX,PY,PZ] [--check]",
    )?;
    let source = match value("--source") {
        Some(text) => match slabs::numbers(&text)?[..] {
            [x, y, z] => DVec3::new(x, y, z),
            _ => return Err(format!("--source {text}: X,Y,Z")),
        },
        None => DVec3::splat(0.5),
    };
    let method = match value("--method").as_deref() {
        None | Some("jacobi") => Method::Jacobi,
        Some("ftcs") => Method::Ftcs,
        Some("mg") => Method::Multigrid,
        Some(other) => return Err(format!("--method {other}: jacobi, ftcs or mg")),
    };
    let boxes = slabs::boxes_arg(args)?;
    let albedo = number("--albedo", 0.9)?;
    if !(0.0..1.0).contains(&albedo) {
        return Err(format!("--albedo {albedo}: in [0, 1)"));
    }
    Ok(Args {
        volume: PathBuf::from(volume),
        out: PathBuf::from(value("-o").ok_or("-o OUT.npy is needed")?),
        raw: value("--raw").map(|t| slabs::raw_layout(&t)).transpose()?,
        scale: number("--scale", 0.02)?,
        background: number("--background", 0.1)?,
        albedo,
        robin: number("--robin", 1.0)?,
        source,
        method,
        tolerance: number("--tolerance", 1e-4)?,
        max_sweeps: number("--max-sweeps", 20_000.0)? as usize,
        check: args.iter().any(|a| a == "--check"),
        boxes,
    })
}

/// (D, σ_a) of samples.
fn coefficients(args: &Args, samples: &[f32]) -> (Vec<f32>, Vec<f32>) {
    samples
        .iter()
        .map(|&s| {
            let sigma_t = args.background + args.scale * f64::from(s);
            (
                (1.0 / (3.0 * sigma_t)) as f32,
                ((1.0 - args.albedo) * sigma_t) as f32,
            )
        })
        .unzip()
}

fn run(comm: &(impl Communicator + ?Sized), args: &Args) -> Result<bool, String> {
    let (size, rank) = (comm.size(), comm.rank());
    let geometry = slabs::read(&args.volume, args.raw.as_ref(), 0..1)?.whole;
    if args.method == Method::Multigrid {
        return run_multigrid(comm, args, geometry);
    }
    let dims = geometry.dims();
    let [nx, ny, nz] = dims;
    // This rank's cells: a box of the grid of boxes, or a z-slab of whole layers.
    let owned: [std::ops::Range<usize>; 3] = match args.boxes {
        Some(grid) => slabs::boxes(grid, dims, size)?.bounds(rank),
        None => {
            if size > nz {
                return Err(format!(
                    "{size} ranks for {nz} layers: one layer per rank at least"
                ));
            }
            [0..nx, 0..ny, rank * nz / size..(rank + 1) * nz / size]
        }
    };
    // Its cells and the cells beyond its faces (D's neighbours).
    let reads: [std::ops::Range<usize>; 3] =
        std::array::from_fn(|a| owned[a].start.saturating_sub(1)..(owned[a].end + 1).min(dims[a]));
    let samples = slabs::agree(
        comm,
        slabs::region(&args.volume, args.raw.as_ref(), reads.clone()),
    )?;
    let (d, sigma_a) = coefficients(args, samples.grid.data());
    let q0 = vec![0.0f32; d.len()];
    let boundaries = Boundaries::uniform(Condition::Robin { a: args.robin });
    let (lo, hi) = geometry.bounds();
    let point = (lo + (hi - lo) * args.source, 1.0);
    let built = SlabSystem::new(geometry, boundaries)
        .and_then(|system| {
            let shares: Vec<PointShares> =
                system.point_weights(point.0, point.1).into_iter().collect();
            let fields = BlockFields {
                origin: samples.origin,
                dims: samples.grid.dims(),
                diffusion: &d,
                absorption: &sigma_a,
                source: &q0,
            };
            system.block(owned.clone(), fields, &shares)
        })
        .map_err(|e| e.to_string());
    let block = slabs::agree(comm, built)?;
    let volume = geometry.cell_volume();
    let iteration = if args.method == Method::Ftcs {
        let limit = block_ftcs_limit(&block, volume, comm).map_err(|e| e.to_string())?;
        Iteration::Ftcs {
            time_step: 0.9 * limit,
            cell_volume: volume,
        }
    } else {
        Iteration::Jacobi { omega: 1.0 }
    };
    let settings = SteadySettings {
        stopping: Stopping {
            relative_tolerance: args.tolerance,
            max_iterations: args.max_sweeps,
            ..Stopping::default()
        },
        allow_unstable: false,
    };
    let started = std::time::Instant::now();
    let steady =
        iterate_block(&block, dims, iteration, &settings, comm).map_err(|e| e.to_string())?;
    let seconds = started.elapsed().as_secs_f64();
    // Every rank has the same stop reason: all of them refuse to write a blown-up field.
    if steady.stop_reason.is_diverged() {
        return Err(format!("the iteration {}", steady.stop_reason));
    }
    let created = if rank == 0 {
        create_npy(&args.out, dims).map_err(|e| e.to_string())
    } else {
        Ok(())
    };
    slabs::agree(comm, created)?;
    let values: Vec<f32> = steady.fluence.iter().map(|&v| v as f32).collect();
    let written = write_npy_region(&args.out, dims, owned.clone(), &values);
    slabs::publish(comm, &args.out, written.map_err(|e| e.to_string()))?;
    // The block (CSR: 7 entries of 16 bytes per row, an index per row, the right-hand
    // side), the samples and coefficients read (f32 × 4), and the iteration's vectors (φ
    // with its halo, r, b and the scale: f64 × 4; the halo at most the cells read less
    // the box's).
    let rows = block.matrix.rows();
    let read = samples.grid.data().len();
    let held = block.matrix.nnz() * 16 + rows * 16 + read * 16 + read * 32;
    if rank == 0 {
        eprintln!(
            "{} sweeps, {}, {seconds:.3} s",
            steady.residuals.len() - 1,
            steady.stop_reason
        );
    }
    eprintln!(
        "rank {rank} of {size}: read cells {reads:?} of {dims:?}, wrote {owned:?}; held {:.1} MB",
        held as f64 / 1e6
    );
    let mut agrees = true;
    if args.check {
        let whole = slabs::read(&args.volume, args.raw.as_ref(), 0..nz)?;
        let (d, sigma_a) = coefficients(args, whole.grid.data());
        let problem =
            DiffusionProblem::new(CellGeometry::full_box(geometry), d, sigma_a, boundaries)
                .map_err(|e| e.to_string())?;
        let sources = Sources {
            points: vec![point],
            ..Sources::default()
        };
        let system = problem.assemble(&sources).map_err(|e| e.to_string())?;
        let iteration = match iteration {
            Iteration::Ftcs { cell_volume, .. } => Iteration::Ftcs {
                time_step: 0.9 * ftcs_limit(&system, cell_volume),
                cell_volume,
            },
            jacobi => jacobi,
        };
        let serial = iterate(&system, dims, iteration, &settings).map_err(|e| e.to_string())?;
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let mine: Vec<f64> = block.grid_cells(dims).map(|c| serial.fluence[c]).collect();
        agrees = bits(&mine) == bits(&steady.fluence)
            && bits(&serial.residuals) == bits(&steady.residuals)
            && serial.stop_reason == steady.stop_reason;
        eprintln!(
            "rank {rank}: the serial iteration's bits on the assembled whole ({:.1} MB of matrix): {}",
            (system.matrix.nnz() * 16) as f64 / 1e6,
            if agrees { "yes" } else { "NO" }
        );
    }
    Ok(agrees)
}

/// `--method mg`: the multigrid's layout names each rank's box; the rank reads it and the
/// cells beyond its faces, builds its part of the hierarchy from them alone
/// (`SlabSystem::solve_multigrid_on_layout`), solves with the others and writes its box.
fn run_multigrid(
    comm: &(impl Communicator + ?Sized),
    args: &Args,
    geometry: GridGeometry,
) -> Result<bool, String> {
    let (size, rank) = (comm.size(), comm.rank());
    let dims = geometry.dims();
    let boundaries = Boundaries::uniform(Condition::Robin { a: args.robin });
    let system = SlabSystem::new(geometry, boundaries).map_err(|e| e.to_string())?;
    let settings = MultigridSettings::default();
    let decomposition = match args.boxes {
        None => Decomposition::Slabs,
        Some(None) => Decomposition::Boxes,
        Some(Some(grid)) => Decomposition::Grid(grid),
    };
    let layout = system
        .multigrid_layout(
            &settings,
            size,
            RankLayout::COARSE_CELLS_PER_RANK,
            decomposition,
        )
        .map_err(|e| e.to_string())?;
    let owned = layout.owned(rank, 0);
    // Its cells and the cells beyond its faces (D's neighbours); nothing on a rank the fine
    // level leaves out.
    let reads = owned.grown(1, dims);
    let samples = if owned.is_empty() {
        Ok(None)
    } else {
        slabs::region(&args.volume, args.raw.as_ref(), reads.axes.clone()).map(Some)
    };
    let samples = slabs::agree(comm, samples)?;
    let (d, sigma_a) = samples.as_ref().map_or((Vec::new(), Vec::new()), |s| {
        coefficients(args, s.grid.data())
    });
    let q0 = vec![0.0f32; d.len()];
    let fields = BlockFields {
        origin: samples.as_ref().map_or([0; 3], |s| s.origin),
        dims: samples.as_ref().map_or([0; 3], |s| s.grid.dims()),
        diffusion: &d,
        absorption: &sigma_a,
        source: &q0,
    };
    let (lo, hi) = geometry.bounds();
    let point = (lo + (hi - lo) * args.source, 1.0);
    let shares: Vec<PointShares> = system.point_weights(point.0, point.1).into_iter().collect();
    let stopping = Stopping {
        relative_tolerance: args.tolerance,
        max_iterations: args.max_sweeps,
        ..Stopping::default()
    };
    let started = std::time::Instant::now();
    let solved = system
        .solve_multigrid_on_layout(fields, &shares, settings, &stopping, comm, layout.clone())
        .map_err(|e| e.to_string())?;
    let seconds = started.elapsed().as_secs_f64();
    if solved.convergence.stop_reason.is_diverged() {
        return Err(format!("the multigrid {}", solved.convergence.stop_reason));
    }
    let created = if rank == 0 {
        create_npy(&args.out, dims).map_err(|e| e.to_string())
    } else {
        Ok(())
    };
    slabs::agree(comm, created)?;
    let written = if owned.is_empty() {
        Ok(())
    } else {
        let values: Vec<f32> = solved.fluence.iter().map(|&v| v as f32).collect();
        write_npy_region(&args.out, dims, solved.cells.clone(), &values).map_err(|e| e.to_string())
    };
    slabs::publish(comm, &args.out, written)?;
    let history = &solved.convergence;
    if rank == 0 {
        let grids: Vec<[usize; 3]> = layout.stages.iter().map(|s| s.grid()).collect();
        eprintln!(
            "{} cycles, {}, {seconds:.3} s; stages' grids of boxes {grids:?}",
            history.iterations(),
            history.stop_reason
        );
    }
    eprintln!(
        "rank {rank} of {size}: read cells {:?} of {dims:?}, wrote {:?}",
        reads.axes, owned.axes
    );
    let mut agrees = true;
    if args.check {
        let whole = slabs::read(&args.volume, args.raw.as_ref(), 0..dims[2])?;
        let (d, sigma_a) = coefficients(args, whole.grid.data());
        let problem =
            DiffusionProblem::new(CellGeometry::full_box(geometry), d, sigma_a, boundaries)
                .map_err(|e| e.to_string())?;
        let sources = Sources {
            points: vec![point],
            ..Sources::default()
        };
        let rhs = problem.rhs(&sources).map_err(|e| e.to_string())?;
        let mg = Multigrid::build(&problem, settings).map_err(|e| e.to_string())?;
        let mut phi = vec![0.0; rhs.len()];
        let serial = mg.solve(&rhs, &mut phi, &stopping);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let [nx, ny, _] = dims;
        let mut mine = Vec::with_capacity(owned.cells());
        for k in owned.z() {
            for j in owned.y() {
                mine.extend(owned.x().map(|i| phi[i + nx * (j + ny * k)]));
            }
        }
        agrees = bits(&mine) == bits(&solved.fluence) && serial == *history;
        eprintln!(
            "rank {rank}: the serial multigrid's bits on the assembled whole: {}",
            if agrees { "yes" } else { "NO" }
        );
    }
    Ok(agrees)
}

fn main() -> ExitCode {
    slabs::main("slab_diffusion", parse, |comm, args| run(comm, args))
}
