//! `cargo xtask bench-diffusion [N...]`: lucent-diffusion's multigrid on the marble sphere
//! (Mertens T7: R = 10 mm, point source, Robin A = 2.341, embedded boundary) at N³ (64,
//! 128 and 256 by default), against the machine's copy bandwidth measured in the same run,
//! and side by side with pyamg (Ruge–Stüben AMG + CG) and scipy CG on the same matrix,
//! exported as NumPy arrays, when `python3 -c "import pyamg, scipy"` works; then, when the
//! adapter is a real GPU, the device's V-cycles (`DeviceMultigrid`) at the same sizes, all
//! in one run.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::DVec3;
use lucent::core::Stopping;
use lucent::diffusion::{
    Boundaries, CellGeometry, Condition, DiffusionProblem, Discretisation, Method, Multigrid,
    MultigridSettings, Sources, solve,
};
use lucent_grid::GridGeometry;
use rayon::prelude::*;

/// The benchmark sphere at n³.
fn sphere(n: usize) -> Result<(DiffusionProblem, Sources), String> {
    let err = |e: &dyn std::fmt::Display| e.to_string();
    let grid = GridGeometry::from_bounds([n; 3], DVec3::splat(-10.5), DVec3::splat(10.5))
        .map_err(|e| err(&e))?;
    let centre = DVec3::new(0.173, -0.091, 0.057);
    let cells = CellGeometry::from_sdf(
        grid,
        |p| (p - centre).length() - 10.0,
        Discretisation::EmbeddedBoundary,
    )
    .map_err(|e| err(&e))?;
    let (sigma_a, sigma_s) = (0.0021f32, 2.19f32);
    let d = 1.0 / (3.0 * (sigma_a + sigma_s));
    let count = grid.voxel_count();
    let problem = DiffusionProblem::new(
        cells,
        vec![d; count],
        vec![sigma_a; count],
        Boundaries::uniform(Condition::Robin { a: 2.341 }),
    )
    .map_err(|e| err(&e))?;
    let sources = Sources {
        points: vec![(centre, 1.0)],
        ..Sources::default()
    };
    Ok((problem, sources))
}

/// Best of `runs` wall times of `f`, seconds.
pub(crate) fn best_of(runs: usize, mut f: impl FnMut()) -> f64 {
    (0..runs)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Copy bandwidth (bytes read + written per second) of a 256 MiB f32 buffer: single
/// thread and over rayon's pool.
pub(crate) fn copy_bandwidth() -> (f64, f64) {
    let n = 64 << 20;
    let src: Vec<f32> = (0..n).map(|i| i as f32).collect();
    let mut dst = vec![0.0f32; n];
    let bytes = 2.0 * 4.0 * n as f64;
    let serial = best_of(5, || dst.copy_from_slice(&src));
    let parallel = best_of(5, || {
        dst.par_chunks_mut(1 << 16)
            .zip(src.par_chunks(1 << 16))
            .for_each(|(d, s)| d.copy_from_slice(s));
    });
    std::hint::black_box(&dst);
    (bytes / serial, bytes / parallel)
}

/// Writes a 1-D little-endian NumPy array.
fn write_npy(path: &Path, descr: &str, bytes: &[u8], len: usize) -> Result<(), String> {
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': ({len},), }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(bytes);
    std::fs::write(path, out).map_err(|e| format!("{}: {e}", path.display()))
}

fn f64_bytes(v: impl IntoIterator<Item = f64>) -> Vec<u8> {
    v.into_iter().flat_map(f64::to_le_bytes).collect()
}

fn i64_bytes(v: impl IntoIterator<Item = usize>) -> Vec<u8> {
    v.into_iter()
        .flat_map(|x| (x as i64).to_le_bytes())
        .collect()
}

/// Exports the system and lucent's solution for the Python side.
fn export(
    dir: &Path,
    problem: &DiffusionProblem,
    sources: &Sources,
    fluence: &[f64],
) -> Result<(), String> {
    std::fs::create_dir_all(dir).map_err(|e| e.to_string())?;
    let system = problem.assemble(sources).map_err(|e| e.to_string())?;
    let m = &system.matrix;
    let rows = system.rhs.len();
    let indptr: Vec<usize> = m.indptr().raw_storage().to_vec();
    write_npy(&dir.join("indptr.npy"), "<i8", &i64_bytes(indptr), rows + 1)?;
    write_npy(
        &dir.join("indices.npy"),
        "<i8",
        &i64_bytes(m.indices().iter().copied()),
        m.nnz(),
    )?;
    write_npy(
        &dir.join("data.npy"),
        "<f8",
        &f64_bytes(m.data().iter().copied()),
        m.nnz(),
    )?;
    write_npy(
        &dir.join("rhs.npy"),
        "<f8",
        &f64_bytes(system.rhs.iter().copied()),
        rows,
    )?;
    let ours = system.cells.iter().map(|&c| fluence[c]);
    write_npy(&dir.join("lucent.npy"), "<f8", &f64_bytes(ours), rows)
}

/// Runs the benchmark: lucent's CPU multigrid, then pyamg and scipy on the same matrices
/// (up to 128³), then the device's (`DeviceMultigrid`) when the adapter is a real GPU, all
/// in one run. `gpu_only` (`--gpu`) runs just the device table, on any adapter (on a CPU
/// implementation, for correctness).
pub(crate) fn run(sizes: &[usize], root: &Path, gpu_only: bool) -> Result<(), String> {
    println!("# cargo xtask bench-diffusion");
    println!();
    if gpu_only {
        return run_gpu(sizes);
    }
    let solves = run_cpu(sizes, root)?;
    for (n, dir, lucent) in solves {
        let Some(dir) = dir else { continue };
        python_row(root, n, &dir, lucent)?;
    }
    println!();
    match lucent::gpu::GpuContext::shared() {
        Ok(context) if !context.is_software() => run_gpu(sizes),
        Ok(context) => {
            println!(
                "GPU: the adapter ({}) is a CPU implementation; not timed (`--gpu` runs the device table for correctness)",
                context.describe()
            );
            Ok(())
        }
        Err(e) => {
            println!("GPU: no adapter ({e})");
            Ok(())
        }
    }
}

/// lucent's setup and solve seconds at one size.
#[derive(Clone, Copy)]
struct Timing {
    setup: f64,
    solve: f64,
}

/// The CPU table; returns per size where its system was exported for pyamg (when Python
/// has pyamg and scipy, up to 128³) and lucent's timing.
fn run_cpu(sizes: &[usize], root: &Path) -> Result<Vec<(usize, Option<PathBuf>, Timing)>, String> {
    let threads = rayon::current_num_threads();
    println!(
        "{threads} threads; copy: a 256 MiB f32 copy on all threads (bytes read + written), \
         best of 5, measured just before each row's sweep; sweep: {} bytes per cell it visits (the rows' spans over the medium), best of 30",
        Multigrid::SWEEP_BYTES_PER_CELL
    );
    println!();
    println!(
        "| n³ | levels | cycles | final residual | setup s | solve s (best of 10; 3 above 128³) | cells swept | sweep ms | sweep GB/s | copy GB/s (1 thread) | sweep / copy |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let python = Command::new("python3")
        .args(["-c", "import pyamg, scipy"])
        .status()
        .is_ok_and(|s| s.success());
    let mut solves = Vec::new();
    for &n in sizes {
        let (problem, sources) = sphere(n)?;
        let stopping = Stopping::default();
        let method = Method::Multigrid(MultigridSettings::default());
        let mut best: Option<lucent::diffusion::DiffusionSolution> = None;
        // This machine's neighbours make single runs vary by ±30 %: the best of several.
        for _ in 0..if n <= 128 { 10 } else { 3 } {
            let s = solve(&problem, &sources, method, &stopping).map_err(|e| e.to_string())?;
            if best
                .as_ref()
                .is_none_or(|b| s.solve_seconds < b.solve_seconds)
            {
                best = Some(s);
            }
        }
        let best = best.ok_or("no run")?;
        let mg =
            Multigrid::build(&problem, MultigridSettings::default()).map_err(|e| e.to_string())?;
        let cells = mg.fine_cells();
        let b: Vec<f32> = (0..cells).map(|i| (i % 7) as f32 * 1e-3).collect();
        let mut x = vec![0.0f32; cells];
        let (serial, parallel) = copy_bandwidth();
        let sweep = best_of(30, || mg.smoothing_sweep(&b, &mut x).unwrap_or(()));
        // The bytes of the cells the sweep visits (the rows' spans over the medium).
        let swept = mg.swept_cells() as u64;
        let gbs = (Multigrid::SWEEP_BYTES_PER_CELL * swept) as f64 / sweep / 1e9;
        println!(
            "| {n}³ | {} | {} | {:.1e} | {:.3} | {:.3} | {:.0}% | {:.2} | {:.1} | {:.1} ({:.1}) | {:.0}% |",
            best.levels,
            best.convergence.iterations(),
            best.convergence
                .residuals
                .last()
                .copied()
                .unwrap_or(f64::NAN),
            best.setup_seconds,
            best.solve_seconds,
            100.0 * swept as f64 / cells as f64,
            sweep * 1e3,
            gbs,
            parallel / 1e9,
            serial / 1e9,
            100.0 * gbs * 1e9 / parallel,
        );
        let dir = if python && n <= 128 {
            let dir = root.join(format!("target/bench-diffusion/sphere{n}"));
            export(&dir, &problem, &sources, &best.fluence)?;
            Some(dir)
        } else {
            None
        };
        let timing = Timing {
            setup: best.setup_seconds,
            solve: best.solve_seconds,
        };
        solves.push((n, dir, timing));
    }
    println!();
    if !python {
        println!("pyamg/scipy: not run (`pip install pyamg scipy` to compare)");
    }
    Ok(solves)
}

/// pyamg and scipy on the exported system at n³, and pyamg's set-up + solve over lucent's
/// solve (the ratio) and over lucent's set-up + solve.
fn python_row(root: &Path, n: usize, dir: &Path, lucent: Timing) -> Result<(), String> {
    let script = root.join("xtask/src/pyamg_bench.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg(dir)
        .output()
        .map_err(|e| e.to_string())?;
    if !out.status.success() {
        return Err(format!(
            "pyamg_bench.py at {n}³: {}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    let text = String::from_utf8_lossy(&out.stdout);
    print!("{n}³: {text}");
    // The pyamg line's "total T s".
    let pyamg_total = text
        .lines()
        .find(|l| l.contains("pyamg") && l.contains("total "))
        .and_then(|l| l.split("total ").nth(1))
        .and_then(|t| t.split(' ').next())
        .and_then(|t| t.parse::<f64>().ok());
    if let Some(total) = pyamg_total {
        println!(
            "  pyamg's set-up + solve over lucent's solve: {:.0}×; over lucent's set-up + solve: {:.0}×",
            total / lucent.solve,
            total / (lucent.setup + lucent.solve)
        );
    }
    Ok(())
}

/// With `--gpu`, per size: one V(2,2) cycle from zero on the device (`DeviceMultigrid`,
/// the hierarchy uploaded once) against the host's same cycle (milliseconds, best of 5
/// after a warm-up; the device's includes writing b and reading x back; the largest
/// difference over the host's peak); the solve to 1e-8 (full multigrid, then cycles) with
/// the outer iteration on the device (best of 3; its kernels alone by timestamps) and on
/// the host, and the host's own solve; then each kernel on the finest level alone
/// (timestamps, 20 dispatches) with its compulsory bytes and GB/s.
fn run_gpu(sizes: &[usize]) -> Result<(), String> {
    use lucent::gpu_solvers::{DeviceMultigrid, OuterIteration};
    let err = |e: &dyn std::fmt::Display| e.to_string();
    let context = lucent::gpu::GpuContext::shared().map_err(|e| err(&e))?;
    println!("adapter: {}", context.describe());
    if context.is_software() {
        println!("a CPU implementation: this is a correctness run, not a measure of GPU speed");
    }
    println!();
    println!(
        "| n³ | levels | coarsest on the device | host cycle ms ({} threads) | device cycle ms (b up, x down) | of which kernels ms | cycle difference / peak | device solve, outer iteration on the device: cycles, ms (kernels ms by timestamps; rhs up and φ down ms) | outer iteration on the host: cycles, ms | host solve: cycles, ms | solutions apart / peak |",
        rayon::current_num_threads()
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let mut kernel_rows = Vec::new();
    for &n in sizes {
        let (problem, sources) = sphere(n)?;
        // diffusion-mg's defaults: full multigrid first (on the device for the device's
        // solve), then V(2,2) cycles.
        let host = Multigrid::build(&problem, MultigridSettings::default()).map_err(|e| err(&e))?;
        let cells = host.fine_cells();
        let rhs = problem.rhs(&sources).map_err(|e| err(&e))?;
        let stopping = Stopping::default();
        let b: Vec<f32> = (0..cells).map(|i| 1.0 + (i % 7) as f32 * 1e-3).collect();
        let mut expected = Vec::new();
        let host_ms = best_of(5, || {
            expected = host.cycle_from_zero(&b).unwrap_or_default();
        }) * 1e3;
        let mut device = DeviceMultigrid::new(context, &host).map_err(|e| err(&e))?;
        let mut got = device.cycle_from_zero(&b).map_err(|e| err(&e))?;
        let mut failed = None;
        let mut kernels = f64::INFINITY;
        let device_ms = best_of(5, || match device.cycle_from_zero(&b) {
            Ok(x) => {
                got = x;
                kernels = kernels.min(device.last_kernel_seconds().unwrap_or(f64::NAN));
            }
            Err(e) => failed = Some(e.to_string()),
        }) * 1e3;
        let peak = expected.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let difference = got
            .iter()
            .zip(&expected)
            .fold(0.0f32, |m, (a, e)| m.max((a - e).abs()))
            / peak;
        // The solve with the outer iteration where the device puts it (on the device
        // where it has f64), then on the host.
        let mut solve = |outer: OuterIteration, runs: usize| {
            let mut phi = vec![0.0; cells];
            let mut row = String::from("–");
            if device.set_outer_iteration(outer).is_err() {
                return (row, phi);
            }
            let mut cycles = 0;
            let mut solve_kernels = f64::INFINITY;
            let mut transfers = f64::INFINITY;
            let ms = best_of(runs, || {
                phi.fill(0.0);
                match device.solve(&rhs, &mut phi, &stopping) {
                    Ok(c) => {
                        cycles = c.iterations();
                        solve_kernels =
                            solve_kernels.min(device.last_kernel_seconds().unwrap_or(f64::NAN));
                        transfers =
                            transfers.min(device.last_transfer_seconds().unwrap_or(f64::NAN));
                    }
                    Err(e) => failed = Some(e.to_string()),
                }
            }) * 1e3;
            row = match outer {
                OuterIteration::Device => format!(
                    "{cycles}, {ms:.1} ({:.1}; transfers {:.1})",
                    solve_kernels * 1e3,
                    transfers * 1e3
                ),
                OuterIteration::Host => format!("{cycles}, {ms:.1}"),
            };
            (row, phi)
        };
        let (on_device, phi) = solve(OuterIteration::Device, 3);
        let (on_host_outer, _) = solve(OuterIteration::Host, 1);
        if let Some(e) = failed {
            return Err(e);
        }
        let mut host_cycles = 0;
        let mut host_phi = vec![0.0; cells];
        let host_solve_ms = best_of(1, || {
            host_phi.fill(0.0);
            host_cycles = host.solve(&rhs, &mut host_phi, &stopping).iterations();
        }) * 1e3;
        let host_peak = host_phi.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let apart = phi
            .iter()
            .zip(&host_phi)
            .fold(0.0f64, |m, (a, e)| m.max((a - e).abs()))
            / host_peak;
        println!(
            "| {n}³ | {} | {} | {host_ms:.2} | {device_ms:.2} | {:.2} | {difference:.1e} | {on_device} | {on_host_outer} | {host_cycles}, {host_solve_ms:.1} | {apart:.1e} |",
            host.depth(),
            if device.coarsest_on_device() {
                "yes"
            } else {
                "no"
            },
            kernels * 1e3,
        );
        if let Some(timings) = device.time_fine_kernels(20).map_err(|e| err(&e))? {
            for t in timings {
                kernel_rows.push(format!(
                    "| {n}³ | {} | {:.3} | {:.3} | {:.0} MB | {:.0} | {:.0} |",
                    t.name,
                    t.seconds * 1e3,
                    t.wall_seconds * 1e3,
                    t.bytes / 1e6,
                    t.bytes / t.seconds / 1e9,
                    t.bytes / t.wall_seconds / 1e9
                ));
            }
        }
    }
    if !kernel_rows.is_empty() {
        println!();
        println!("each kernel on the finest level alone (20 dispatches in one pass, timestamps):");
        println!();
        println!(
            "| n³ | kernel | ms per dispatch (timestamps) | ms per dispatch (host clock, submit and wait included) | compulsory bytes | GB/s by them (timestamps) | GB/s (host clock) |"
        );
        println!("|---|---|---|---|---|---|---|");
        for row in kernel_rows {
            println!("{row}");
        }
    }
    Ok(())
}

use std::process::Command;
