//! What the slab examples share: reading some z-layers or a box of cells of a volume file
//! by positioned reads, `--raw NX,NY,NZ,TYPE`, and agreeing on a step that can fail on one
//! rank.

use std::path::Path;
use std::process::ExitCode;

use lucent_explicit::ranks::Boxes;
use lucent_grid::io::layers::{Layers, Region, read_npy_region, read_nrrd_region, read_raw_region};
use lucent_grid::io::raw::RawLayout;
use lucent_grid::io::{LoadOptions, ScalarType};
use lucent_mpi::Communicator;

/// `--raw NX,NY,NZ,TYPE`: a headerless file's dims and sample type.
pub(crate) fn raw_layout(text: &str) -> Result<RawLayout, String> {
    let parts: Vec<&str> = text.split(',').collect();
    let [x, y, z, kind] = parts[..] else {
        return Err(format!("--raw {text}: NX,NY,NZ,TYPE"));
    };
    let dim = |v: &str| v.parse::<usize>().map_err(|_| format!("--raw: {v}"));
    let scalar = match kind {
        "u8" => ScalarType::U8,
        "u16" => ScalarType::U16,
        "i16" => ScalarType::I16,
        "f32" => ScalarType::F32,
        "f64" => ScalarType::F64,
        other => {
            return Err(format!(
                "--raw: sample type {other} (u8, u16, i16, f32, f64)"
            ));
        }
    };
    Ok(RawLayout::new([dim(x)?, dim(y)?, dim(z)?], scalar))
}

/// Layers `layers` of the volume at `path` (the whole volume's geometry comes with them):
/// a `.raw` with its `raw` layout, a `.npy`, or a raw-encoded NRRD.
pub(crate) fn read(
    path: &Path,
    raw: Option<&RawLayout>,
    layers: std::ops::Range<usize>,
) -> Result<Layers, String> {
    // The header alone first (one cell), for the layers' x and y.
    let [nx, ny, _] = region(path, raw, [0..1, 0..1, 0..1])?.whole.dims();
    let part = region(path, raw, [0..nx, 0..ny, layers])?;
    Ok(Layers {
        whole: part.whole,
        first: part.origin[2],
        grid: part.grid,
    })
}

/// The box of cells `cells` of the volume at `path`, as [`read`] reads layers.
pub(crate) fn region(
    path: &Path,
    raw: Option<&RawLayout>,
    cells: [std::ops::Range<usize>; 3],
) -> Result<Region, String> {
    let options = LoadOptions::default();
    let extension = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    match (raw, extension) {
        (Some(layout), _) => read_raw_region(path, layout, cells, &options),
        (None, "npy") => read_npy_region(path, cells, &options),
        (None, "nrrd" | "nhdr") => read_nrrd_region(path, cells, &options),
        _ => {
            return Err(format!(
                "{}: a .npy or .nrrd, or --raw for a raw file",
                path.display()
            ));
        }
    }
    .map_err(|e| e.to_string())
}

/// `result` on this rank, once every rank has said whether its step worked: a step that
/// failed on one rank (a bad layer, a full disk) stops every rank, none waits forever.
pub(crate) fn agree<T>(
    comm: &(impl Communicator + ?Sized),
    result: Result<T, String>,
) -> Result<T, String> {
    let flags = comm.all_gather(&[if result.is_ok() { 1.0 } else { 0.0 }]);
    let value = result?;
    match flags.iter().position(|&f| f != 1.0) {
        Some(rank) => Err(format!("rank {rank} failed (it says why)")),
        None => Ok(value),
    }
}

/// After every rank has written its cells of `out` into the shared partial file
/// (`written`): rank 0 renames it over `out` when all succeeded, or removes it when any
/// failed, so that `out` is the whole array or untouched, never a part of it.
pub(crate) fn publish(
    comm: &(impl Communicator + ?Sized),
    out: &std::path::Path,
    written: Result<(), String>,
) -> Result<(), String> {
    let agreed = agree(comm, written);
    let finished = if comm.rank() != 0 {
        Ok(())
    } else if agreed.is_ok() {
        lucent_grid::io::layers::finish_npy(out).map_err(|e| e.to_string())
    } else {
        lucent_grid::io::layers::abandon_npy(out);
        Ok(())
    };
    agreed?;
    agree(comm, finished)
}

/// The value after `name` in `args`.
pub(crate) fn value(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .cloned()
}

/// `--boxes`: `None` for z-slabs, `Some(None)` for `auto`, or the grid of boxes.
pub(crate) fn boxes_arg(args: &[String]) -> Result<Option<Option<[usize; 3]>>, String> {
    Ok(match value(args, "--boxes").as_deref() {
        None => None,
        Some("auto") => Some(None),
        Some(text) => match numbers(text)?[..] {
            [x, y, z] if [x, y, z].iter().all(|v| *v >= 1.0 && v.fract() == 0.0) => {
                Some(Some([x as usize, y as usize, z as usize]))
            }
            _ => return Err(format!("--boxes {text}: auto or PX,PY,PZ")),
        },
    })
}

/// The grid of boxes `grid` (`None`: the one that cuts least) over `dims` cells for
/// `ranks` ranks.
pub(crate) fn boxes(
    grid: Option<[usize; 3]>,
    dims: [usize; 3],
    ranks: usize,
) -> Result<Boxes, String> {
    let boxes = match grid {
        Some(grid) => Boxes::new(dims, grid),
        None => Boxes::auto(dims, ranks),
    }
    .map_err(|e| e.to_string())?;
    if boxes.ranks() != ranks {
        return Err(format!(
            "--boxes {:?}: {} boxes for {ranks} ranks",
            boxes.grid(),
            boxes.ranks()
        ));
    }
    Ok(boxes)
}

/// `text` as comma-separated numbers.
pub(crate) fn numbers(text: &str) -> Result<Vec<f64>, String> {
    text.split(',')
        .map(|v| v.trim().parse().map_err(|_| format!("not a number: {v}")))
        .collect()
}

/// A slab example's `main`: parses the arguments, runs on the ranks of `mpirun` (feature
/// `mpi`) or on `--ranks N` in-process ranks (default 2), and exits 0 when every rank
/// reports agreement, 1 when one does not or a rank fails, 2 for bad arguments.
pub(crate) fn main<A: Sync>(
    name: &str,
    parse: fn(&[String]) -> Result<A, String>,
    run: impl Fn(&dyn Communicator, &A) -> Result<bool, String> + Sync,
) -> ExitCode {
    let raw: Vec<String> = std::env::args().skip(1).collect();
    let args = match parse(&raw) {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{name}: {e}");
            return ExitCode::from(2);
        }
    };
    match on_ranks(&raw, &args, run) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("{name}: {e}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(feature = "mpi")]
fn on_ranks<A: Sync>(
    _: &[String],
    args: &A,
    run: impl Fn(&dyn Communicator, &A) -> Result<bool, String> + Sync,
) -> Result<bool, String> {
    let world = lucent_mpi::World::initialise().map_err(|e| e.to_string())?;
    run(&world.ranks(), args)
}

#[cfg(not(feature = "mpi"))]
fn on_ranks<A: Sync>(
    raw: &[String],
    args: &A,
    run: impl Fn(&dyn Communicator, &A) -> Result<bool, String> + Sync,
) -> Result<bool, String> {
    let ranks: usize = value(raw, "--ranks")
        .and_then(|v| v.parse().ok())
        .unwrap_or(2);
    lucent_mpi::Threads::run(ranks, |comm| run(comm, args))
        .into_iter()
        .map(|r| r.ok_or_else(|| "a rank panicked".to_owned())?)
        .try_fold(true, |all, r| r.map(|same| all && same))
}
