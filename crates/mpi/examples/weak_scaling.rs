//! One solve split over ranks, checked against one rank, timed per sweep or cycle: the
//! weak-scaling measurement of `BENCHMARKS.md` ("Ranks").
//!
//! ```sh
//! cargo run --profile examples -p lucent-mpi --example weak_scaling -- --ranks 3      # in-process ranks
//! cargo build --profile examples -p lucent-mpi --features mpi --example weak_scaling
//! mpirun -n 2 target/examples/examples/weak_scaling --method mg                     # MPI ranks
//! ```
//!
//! The problem: a heterogeneous diffusion medium in an embedded cylinder along z with a
//! point source, `n_z` = L·ranks layers of S × 5S/6 cells (the same slab per rank;
//! `--layers L`, default 24, `--side S`, default 24). `--method ftcs` (default), `jacobi`
//! (both over z-slabs, or with `--boxes auto` or `--boxes PX,PY,PZ` over a grid of boxes,
//! `lucent_explicit::ranks::Boxes`) or `mg` (`lucent_diffusion::Multigrid::solve_on_layout`,
//! V(2,2) from full multigrid, over z-slabs or `--boxes auto|PX,PY,PZ` for the fine level's
//! grid of boxes, `lucent_diffusion::Decomposition`;
//! `--coarse-cells N` agglomerates coarse levels onto fewer ranks below N cells per rank,
//! default `RankLayout::COARSE_CELLS_PER_RANK`, 0 splits every level as far as it goes);
//! or Zhang & Ma's absorption march of a distant light through heterogeneous absorption on
//! the same grid (`lucent_explicit::wavefront`): `march` (short characteristics) with the
//! light along z (over z-slabs the pipelined wavefront), `march-x` along x (over z-slabs
//! planes in lock step), `march-paper` the paper's pass with the light as for `march`;
//! each over z-slabs or `--boxes` (the KBA sweep, `wavefront::propagate_box`); or
//! `p1`, Murray's P1 by FTCS from a point source on the same grid, 400 steps
//! (`lucent_explicit::ranks::march_p1_on`, z-slabs or `--boxes`).
//! Every rank also solves serially and compares: every method must give the serial bits
//! (the multigrid its φ and residual history).
//! The exit status is 1 otherwise. Rank 0 prints the iterations, the stop reason and the wall
//! time of the split solve (the best of `--repeat R` runs, default 1).

use std::process::ExitCode;
use std::time::Instant;

use glam::DVec3;
use lucent_core::Stopping;
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, Decomposition as MultigridCut, DiffusionProblem,
    Discretisation, Multigrid, MultigridSettings, RankLayout, Sources,
};
use lucent_explicit::ranks::{Boxes, Decomposition, iterate_on, march_p1_on};
use lucent_explicit::steady::{Iteration, SteadySettings, ftcs_limit, iterate as serial};
use lucent_grid::GridGeometry;
use lucent_mpi::Communicator;

#[derive(Clone, Copy, PartialEq)]
enum Method {
    Ftcs,
    Jacobi,
    /// Coarse levels go to fewer ranks below this many cells per rank.
    Multigrid(usize),
    /// The absorption march: short characteristics with the light's dominant axis z
    /// (`Some(true)`) or x, or the paper's pass (`None`).
    March(Option<bool>),
    /// P1 by FTCS.
    P1,
}

struct Run {
    iterations: usize,
    stop: String,
    seconds: f64,
    agrees: bool,
}

fn problem(
    ranks: usize,
    layers_per_rank: usize,
    side: usize,
) -> Result<(DiffusionProblem, Sources, [usize; 3]), String> {
    let dims = [side, side * 5 / 6, layers_per_rank * ranks];
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
    Ok((problem, sources, dims))
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// The best wall time of `repeat` runs of `solve`, and its last result.
fn best_of<T, E: ToString>(
    repeat: usize,
    mut solve: impl FnMut() -> Result<T, E>,
) -> Result<(T, f64), String> {
    let mut best = f64::INFINITY;
    let mut last = None;
    for _ in 0..repeat.max(1) {
        let start = Instant::now();
        last = Some(solve().map_err(|e| e.to_string())?);
        best = best.min(start.elapsed().as_secs_f64());
    }
    Ok((last.ok_or("no run")?, best))
}

/// How FTCS and Jacobi split the grid: z-slabs, or `--boxes auto` (the grid of boxes
/// that cuts least) or `--boxes PX,PY,PZ`.
fn decomposition(
    boxes: Option<&str>,
    dims: [usize; 3],
    ranks: usize,
) -> Result<Decomposition, String> {
    let grid = match boxes {
        None => return Ok(Decomposition::Slabs),
        Some("auto") => Boxes::auto(dims, ranks),
        Some(spec) => match spec
            .split(',')
            .map(str::parse)
            .collect::<Result<Vec<usize>, _>>()
            .as_deref()
        {
            Ok(&[px, py, pz]) => Boxes::new(dims, [px, py, pz]),
            _ => return Err(format!("--boxes {spec}: auto or PX,PY,PZ")),
        },
    };
    grid.map(Decomposition::Boxes).map_err(|e| e.to_string())
}

/// Rank 0 says how the grid is split.
fn announce(comm: &(impl Communicator + ?Sized), decomposition: &Decomposition) {
    if comm.rank() == 0 {
        match decomposition {
            Decomposition::Slabs => eprintln!("z-slabs"),
            Decomposition::Boxes(b) => eprintln!("boxes: {:?} (x, y, z)", b.grid()),
        }
    }
}

fn run(
    comm: &(impl Communicator + ?Sized),
    method: Method,
    layers_per_rank: usize,
    side: usize,
    repeat: usize,
    boxes: Option<&str>,
) -> Result<Run, String> {
    if let Method::March(along_z) = method {
        return march(comm, along_z, layers_per_rank, side, repeat, boxes);
    }
    if method == Method::P1 {
        return p1(comm, layers_per_rank, side, repeat, boxes);
    }
    let (problem, sources, dims) = problem(comm.size(), layers_per_rank, side)?;
    if let Method::Multigrid(coarse_cells) = method {
        let cut = match boxes {
            None => MultigridCut::Slabs,
            Some("auto") => MultigridCut::Boxes,
            Some(spec) => match spec
                .split(',')
                .map(|v| v.parse::<usize>())
                .collect::<Result<Vec<_>, _>>()
                .as_deref()
            {
                Ok(&[px, py, pz]) => MultigridCut::Grid([px, py, pz]),
                _ => return Err(format!("--boxes {spec}: auto or PX,PY,PZ")),
            },
        };
        let stopping = Stopping {
            relative_tolerance: 1e-10,
            max_iterations: 100,
            ..Stopping::default()
        };
        let rhs = problem.rhs(&sources).map_err(|e| e.to_string())?;
        let mg =
            Multigrid::build(&problem, MultigridSettings::default()).map_err(|e| e.to_string())?;
        let layout = mg
            .layout(comm.size(), coarse_cells, cut)
            .map_err(|e| e.to_string())?;
        if comm.rank() == 0 {
            let stages: Vec<String> = layout
                .stages
                .iter()
                .map(|s| {
                    let [px, py, pz] = s.grid();
                    let on = if px * py == 1 {
                        format!("{}", s.ranks())
                    } else {
                        format!("{px}×{py}×{pz}")
                    };
                    match s.levels {
                        1 => format!("{on} × level {}", s.first_level),
                        n => format!("{on} × levels {}–{}", s.first_level, s.first_level + n - 1),
                    }
                })
                .collect();
            eprintln!("multigrid stages: {}", stages.join(", "));
        }
        let mut phi = vec![0.0; rhs.len()];
        let (split, seconds) = best_of(repeat, || {
            mg.solve_on_layout(&rhs, &mut phi, &stopping, comm, layout.clone())
        })?;
        let mut alone = vec![0.0; rhs.len()];
        let reference = mg.solve(&rhs, &mut alone, &stopping);
        return Ok(Run {
            iterations: split.iterations(),
            stop: split.stop_reason.to_string(),
            seconds,
            agrees: bits(&phi) == bits(&alone)
                && bits(&split.residuals) == bits(&reference.residuals)
                && split.stop_reason.is_converged(),
        });
    }
    let system = problem.assemble(&sources).map_err(|e| e.to_string())?;
    let volume = problem.cells().geometry().cell_volume();
    let iteration = match method {
        Method::Jacobi => Iteration::Jacobi { omega: 1.0 },
        _ => Iteration::Ftcs {
            time_step: 0.9 * ftcs_limit(&system, volume),
            cell_volume: volume,
        },
    };
    let settings = SteadySettings {
        stopping: Stopping {
            relative_tolerance: 1e-6,
            max_iterations: 100_000,
            ..Stopping::default()
        },
        allow_unstable: false,
    };
    let decomposition = decomposition(boxes, dims, comm.size())?;
    announce(comm, &decomposition);
    let (split, seconds) = best_of(repeat, || {
        iterate_on(&system, dims, &decomposition, iteration, &settings, comm)
    })?;
    let reference = serial(&system, dims, iteration, &settings).map_err(|e| e.to_string())?;
    Ok(Run {
        iterations: split.residuals.len() - 1,
        stop: split.stop_reason.to_string(),
        seconds,
        agrees: bits(&split.fluence) == bits(&reference.fluence)
            && bits(&split.residuals) == bits(&reference.residuals),
    })
}

/// The absorption march on the grid of [`problem`], σ_a between 0 and 4/length varying
/// cell to cell (the paper's per-step absorption between 0 and 0.8), against the serial
/// march: short characteristics with the light's dominant axis z or x
/// (`along_z`), or the paper's pass (`None`, the light as along z).
fn march(
    comm: &(impl Communicator + ?Sized),
    along_z: Option<bool>,
    layers_per_rank: usize,
    side: usize,
    repeat: usize,
    boxes: Option<&str>,
) -> Result<Run, String> {
    use lucent_explicit::convection::{Light, Model, UpwindSettings, propagate};
    let dims = [side, side * 5 / 6, layers_per_rank * comm.size()];
    let lattice =
        lucent_explicit::Lattice::new(dims, 6.0 / side as f64).map_err(|e| e.to_string())?;
    let top = if along_z.is_some() { 4.0 } else { 0.8 };
    let sigma: Vec<f64> = (0..lattice.len() as u64)
        .map(|c| top * (c.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 54) as f64 / 1023.0)
        .collect();
    let direction = if along_z != Some(false) {
        DVec3::new(0.3, -0.2, 1.0)
    } else {
        DVec3::new(1.0, 0.3, -0.2)
    };
    let light = Light::Distant {
        direction,
        density: 1.0,
    };
    let settings = UpwindSettings {
        model: if along_z.is_some() {
            Model::Characteristic
        } else {
            Model::Paper
        },
        ..UpwindSettings::default()
    };
    // `--boxes auto`: the grid that suits the march (an axis whole, the light's first).
    let decomposition = match boxes {
        Some("auto") => Decomposition::Boxes(
            lucent_explicit::wavefront::march_boxes(dims, comm.size(), direction, settings.model)
                .map_err(|e| e.to_string())?,
        ),
        _ => decomposition(boxes, dims, comm.size())?,
    };
    announce(comm, &decomposition);
    let (split, seconds) = best_of(repeat, || {
        lucent_explicit::wavefront::propagate_on_ranks(
            &lattice,
            &sigma,
            &light,
            &settings,
            &decomposition,
            comm,
        )
    })?;
    let reference = propagate(&lattice, &sigma, &light, &settings).map_err(|e| e.to_string())?;
    Ok(Run {
        iterations: split.iterations,
        stop: split.stop_reason.to_string(),
        seconds,
        agrees: bits(&split.density) == bits(&reference.density),
    })
}

/// P1 by FTCS (staggered, consistent damping, 0.9 of the stable step) for 400 steps from
/// a point source on the grid of [`problem`], against the serial march.
fn p1(
    comm: &(impl Communicator + ?Sized),
    layers_per_rank: usize,
    side: usize,
    repeat: usize,
    boxes: Option<&str>,
) -> Result<Run, String> {
    use lucent_explicit::p1::{Damping, Layout, P1Edges, P1Settings, march as serial_march};
    let dims = [side, side * 5 / 6, layers_per_rank * comm.size()];
    let h = 6.0 / side as f64;
    let lattice = lucent_explicit::Lattice::new(dims, h).map_err(|e| e.to_string())?;
    let mut source = vec![0.0; lattice.len()];
    source[dims[0] / 3 + dims[0] * (dims[1] / 2 + dims[1] * (dims[2] / 2))] = 1.0;
    let (sigma_a, reduced) = (0.3, 2.0);
    let step = lucent_explicit::stability::p1::largest_step(true, sigma_a, reduced, h);
    let settings = P1Settings {
        layout: Layout::Staggered,
        damping: Damping::Consistent {
            sigma_a,
            sigma_t_reduced: reduced,
        },
        time_step: 0.9 * step,
        stopping: Stopping {
            relative_tolerance: 0.0,
            max_iterations: 400,
            ..Stopping::default()
        },
        edges: P1Edges::Zero,
        allow_unstable: false,
    };
    let decomposition = decomposition(boxes, dims, comm.size())?;
    let (split, seconds) = best_of(repeat, || {
        march_p1_on(&lattice, &source, &decomposition, &settings, comm)
    })?;
    let started = Instant::now();
    let reference = serial_march(&lattice, &source, &settings, None).map_err(|e| e.to_string())?;
    if comm.rank() == 0 {
        // The serial march's own cell loop, for comparison with one rank's.
        eprintln!(
            "serial p1::march: {:.1} µs per step",
            started.elapsed().as_secs_f64() * 1e6 / reference.steps.max(1) as f64
        );
    }
    Ok(Run {
        iterations: split.steps,
        stop: split.stop_reason.to_string(),
        seconds,
        agrees: bits(&split.fluence) == bits(&reference.fluence)
            && (0..3).all(|a| bits(&split.flux[a]) == bits(&reference.flux[a]))
            && split.stop_reason == reference.stop_reason,
    })
}

fn report(
    comm: &(impl Communicator + ?Sized),
    method: Method,
    layers: usize,
    side: usize,
    repeat: usize,
    boxes: Option<&str>,
) -> Result<bool, String> {
    let out = run(comm, method, layers, side, repeat, boxes)?;
    if comm.rank() == 0 {
        let dims = [side, side * 5 / 6, layers * comm.size()];
        let what = match method {
            Method::Multigrid(_) => ["cycles", "cycle"],
            Method::Jacobi | Method::Ftcs => ["sweeps", "sweep"],
            Method::March(_) => ["passes", "pass"],
            Method::P1 => ["steps", "step"],
        };
        eprintln!(
            "{} ranks, {}×{}×{} cells: {} {}, {}, {:.4} s split ({:.1} µs per {}); the bits of one rank's: {}",
            comm.size(),
            dims[0],
            dims[1],
            dims[2],
            out.iterations,
            what[0],
            out.stop,
            out.seconds,
            out.seconds * 1e6 / out.iterations.max(1) as f64,
            what[1],
            if out.agrees { "yes" } else { "NO" }
        );
    }
    Ok(out.agrees)
}

fn value<T: std::str::FromStr>(args: &[String], name: &str) -> Option<T> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let layers = value(&args, "--layers").unwrap_or(24);
    let side = value(&args, "--side").unwrap_or(24);
    let repeat = value(&args, "--repeat").unwrap_or(1);
    let method = match value::<String>(&args, "--method").as_deref() {
        None | Some("ftcs") => Method::Ftcs,
        Some("jacobi") => Method::Jacobi,
        Some("mg") => Method::Multigrid(
            value(&args, "--coarse-cells").unwrap_or(RankLayout::COARSE_CELLS_PER_RANK),
        ),
        Some("march") => Method::March(Some(true)),
        Some("march-x") => Method::March(Some(false)),
        Some("march-paper") => Method::March(None),
        Some("p1") => Method::P1,
        Some(other) => {
            eprintln!(
                "weak_scaling: --method {other}: ftcs, jacobi, mg, march, march-x, march-paper or p1"
            );
            return ExitCode::from(2);
        }
    };
    let boxes = value::<String>(&args, "--boxes");
    match run_on_ranks(&args, method, layers, side, repeat, boxes.as_deref()) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("weak_scaling: {e}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(feature = "mpi")]
fn run_on_ranks(
    _: &[String],
    method: Method,
    layers: usize,
    side: usize,
    repeat: usize,
    boxes: Option<&str>,
) -> Result<bool, String> {
    let world = lucent_mpi::World::initialise().map_err(|e| e.to_string())?;
    report(&world.ranks(), method, layers, side, repeat, boxes)
}

#[cfg(not(feature = "mpi"))]
fn run_on_ranks(
    args: &[String],
    method: Method,
    layers: usize,
    side: usize,
    repeat: usize,
    boxes: Option<&str>,
) -> Result<bool, String> {
    let ranks: usize = value(args, "--ranks").unwrap_or(2);
    let worlds = lucent_mpi::Threads::world(ranks);
    std::thread::scope(|scope| {
        let runs: Vec<_> = worlds
            .into_iter()
            .map(|comm| scope.spawn(move || report(&comm, method, layers, side, repeat, boxes)))
            .collect();
        runs.into_iter()
            .map(|r| r.join().map_err(|_| "a rank panicked".to_owned())?)
            .try_fold(true, |all, r| r.map(|same| all && same))
    })
}
