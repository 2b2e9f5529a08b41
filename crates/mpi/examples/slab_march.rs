//! Zhang & Ma's absorption march through a volume file on ranks, no rank holding the whole
//! volume: each rank reads only the z-layers it needs (`lucent_grid::io::layers`:
//! positioned reads of `.raw`, `.npy` or raw-encoded NRRD), marches its slab
//! (`lucent_explicit::wavefront::propagate_slab`, short characteristics) and writes its
//! layers of ρ into one `.npy` by positioned writes. With `--boxes auto` (the grid of
//! boxes that suits the march: `wavefront::march_boxes`) or `--boxes PX,PY,PZ` each rank
//! reads its box of cells and two more on every side (`wavefront::read_box`), marches it
//! in the KBA sweep (`wavefront::propagate_box`) and writes its box, x-line by x-line.
//!
//! ```sh
//! cargo build --profile examples -p lucent-mpi --features mpi --example slab_march
//! mpirun -n 4 target/examples/examples/slab_march "$LUCENT_DATA/tooth_103x94x161_uint8.raw" \
//!     --raw 103,94,161,u8 --scale 0.02 --direction 0.3,-0.2,1 -o rho.npy
//! ```
//!
//! σ_a = `--scale` × sample per cell side (cells of side 1: a `.raw` is read with unit
//! spacing, a `.npy` has none, an NRRD's spacing must be cubic and is used). The light is
//! distant, of unit density, along `--direction` (default (0.3, −0.2, 1)); `--paper` marches
//! the paper's pass (Eq. 16 at C = ½, σ_a then the absorption per step, in [0, 1]) instead
//! of short characteristics. Each rank prints the cells it read and the bytes it holds.
//! `--check`: every rank also reads the whole volume, marches it serially and compares its
//! cells (bits; exit status 1 if they differ), for CI. Without the `mpi` feature,
//! `--ranks N` in-process ranks.

use std::path::PathBuf;
use std::process::ExitCode;

use glam::DVec3;
use lucent_explicit::Lattice;
use lucent_explicit::convection::{Light, Model, UpwindSettings, propagate};
use lucent_explicit::wavefront::{
    march_boxes, owned_layers, propagate_box, propagate_slab, read_box, read_layers,
};
use lucent_grid::io::layers::{Layers, create_npy, write_npy_region};
use lucent_grid::io::raw::RawLayout;
use lucent_mpi::Communicator;

mod slabs;

struct Args {
    volume: PathBuf,
    out: PathBuf,
    /// A `.raw`'s dims and sample type.
    raw: Option<RawLayout>,
    scale: f64,
    direction: DVec3,
    paper: bool,
    /// `--boxes`: `None` for z-slabs, `Some(None)` for `auto`, or the grid of boxes.
    boxes: Option<Option<[usize; 3]>>,
    check: bool,
}

fn parse(args: &[String]) -> Result<Args, String> {
    let value = |name: &str| slabs::value(args, name);
    let volume = args
        .first()
        .filter(|a| !a.starts_with('-'))
        .ok_or("usage: slab_march VOLUME -o OUT.npy [--raw NX,NY,NZ,TYPE] [--scale S] [--direction X,Y,Z] [--paper] [--boxes auto|PX,PY,PZ] [--check]")?;
    let raw = value("--raw").map(|t| slabs::raw_layout(&t)).transpose()?;
    let direction = match value("--direction") {
        Some(text) => match slabs::numbers(&text)?[..] {
            [x, y, z] => DVec3::new(x, y, z),
            _ => return Err(format!("--direction {text}: X,Y,Z")),
        },
        None => DVec3::new(0.3, -0.2, 1.0),
    };
    Ok(Args {
        volume: PathBuf::from(volume),
        out: PathBuf::from(value("-o").ok_or("-o OUT.npy is needed")?),
        raw,
        scale: value("--scale").map_or(Ok(1.0), |v| slabs::numbers(&v).map(|n| n[0]))?,
        direction,
        paper: args.iter().any(|a| a == "--paper"),
        boxes: slabs::boxes_arg(args)?,
        check: args.iter().any(|a| a == "--check"),
    })
}

/// Layers `layers` of the volume (the whole volume's dims come with them).
fn read(args: &Args, layers: std::ops::Range<usize>) -> Result<Layers, String> {
    slabs::read(&args.volume, args.raw.as_ref(), layers)
}

/// The whole volume's dims and cell side, from its first layer's read.
fn shape(args: &Args) -> Result<([usize; 3], f64), String> {
    let first = read(args, 0..1)?;
    let spacing = first.whole.spacing();
    if (spacing - DVec3::splat(spacing.x)).abs().max_element() > 1e-9 * spacing.x {
        return Err(format!("cells of {spacing}: the march needs cubic cells"));
    }
    Ok((first.whole.dims(), spacing.x))
}

fn run(comm: &(impl Communicator + ?Sized), args: &Args) -> Result<bool, String> {
    let (size, rank) = (comm.size(), comm.rank());
    let (dims, spacing) = shape(args)?;
    let lattice = Lattice::new(dims, spacing).map_err(|e| e.to_string())?;
    let [nx, ny, nz] = dims;
    // This rank's cells and the cells it reads: a box of the grid of boxes and HALO cells
    // beyond, or a z-slab and two layers beyond.
    let model = if args.paper {
        Model::Paper
    } else {
        Model::Characteristic
    };
    // `--boxes auto`: the grid that suits the march (an axis whole, the light's first).
    let boxes = match args.boxes {
        None => None,
        Some(None) => {
            Some(march_boxes(dims, size, args.direction, model).map_err(|e| e.to_string())?)
        }
        Some(grid) => Some(slabs::boxes(grid, dims, size)?),
    };
    let (owned, reads) = match &boxes {
        Some(boxes) => (boxes.bounds(rank), read_box(boxes, rank)),
        None => {
            let (owned, reads) = (owned_layers(nz, size, rank), read_layers(nz, size, rank));
            ([0..nx, 0..ny, owned], [0..nx, 0..ny, reads])
        }
    };
    let sigma: Vec<f64> = slabs::agree(
        comm,
        slabs::region(&args.volume, args.raw.as_ref(), reads.clone()),
    )?
    .grid
    .data()
    .iter()
    .map(|&v| args.scale * f64::from(v))
    .collect();
    let light = Light::Distant {
        direction: args.direction,
        density: 1.0,
    };
    let settings = UpwindSettings {
        model,
        ..UpwindSettings::default()
    };
    let rho = match &boxes {
        Some(boxes) => propagate_box(&lattice, &sigma, &light, &settings, boxes, comm),
        None => propagate_slab(&lattice, &sigma, &light, &settings, comm),
    }
    .map_err(|e| e.to_string())?;
    // Rank 0 empties the file, everyone waits (the agreement is the barrier), then each
    // rank writes its layers.
    let created = if rank == 0 {
        create_npy(&args.out, dims).map_err(|e| e.to_string())
    } else {
        Ok(())
    };
    slabs::agree(comm, created)?;
    let values: Vec<f32> = rho.iter().map(|&v| v as f32).collect();
    let written = write_npy_region(&args.out, dims, owned.clone(), &values);
    slabs::publish(comm, &args.out, written.map_err(|e| e.to_string()))?;
    // σ_a and ρ of the cells read (f64), the cells as read (f32), ρ of the owned cells
    // returned and written (f64 and f32).
    let count =
        |cells: &[std::ops::Range<usize>; 3]| cells.iter().map(|r| r.len()).product::<usize>();
    let held = count(&reads) * (8 + 8 + 4) + rho.len() * (8 + 4);
    eprintln!(
        "rank {rank} of {size}: read cells {reads:?} of {dims:?}, wrote {owned:?}; held {:.1} MB \
         (one rank: {:.1} MB)",
        held as f64 / 1e6,
        (lattice.len() * (8 + 8 + 4 + 8 + 4)) as f64 / 1e6
    );
    let mut agrees = true;
    if args.check {
        let whole: Vec<f64> = read(args, 0..dims[2])?
            .grid
            .data()
            .iter()
            .map(|&v| args.scale * f64::from(v))
            .collect();
        let serial = propagate(&lattice, &whole, &light, &settings).map_err(|e| e.to_string())?;
        agrees = lucent_grid::box_cells(&owned)
            .map(|p| serial.density[p[0] + nx * (p[1] + ny * p[2])])
            .zip(&rho)
            .all(|(a, b)| a.to_bits() == b.to_bits());
        eprintln!(
            "rank {rank}: the serial march's bits: {}",
            if agrees { "yes" } else { "NO" }
        );
    }
    Ok(agrees)
}

fn main() -> ExitCode {
    slabs::main("slab_march", parse, |comm, args| run(comm, args))
}
