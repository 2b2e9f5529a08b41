//! The `lucent` command: render a scene, solve it to a fluence grid, list solvers.
//!
//! `cargo run --release` with no arguments renders the built-in default scene to
//! `lucent.png`. Errors print one line (`lucent: ...`) and exit with status 1; usage errors
//! exit with 2.

// Printing is this binary's job; the lint guards the libraries.
#![allow(clippy::print_stdout)]

use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Instant;

use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use lucent::Error;
use lucent::core::{Progress, Solution, SolveOptions, Solver};
use lucent::grid::io::ScalarType;
use lucent::optics::materials::{JENSEN_2001, LENGTH_UNIT};
use lucent::optics::{Dielectric, DiffuseFresnel, DiffusionMedium};
use lucent::scene::{BuiltScene, Scene};

#[derive(Parser)]
#[command(
    name = "lucent",
    version,
    about = "Light transport in participating media: solve a scene, render a picture."
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// No progress bars.
    #[arg(long, short, global = true)]
    quiet: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Solve a scene and render it to PNG (sRGB) or EXR (linear).
    Render {
        /// Scene file (TOML); the built-in default scene if omitted.
        scene: Option<PathBuf>,
        /// Solver to use instead of the scene's (with default parameters).
        #[arg(long)]
        solver: Option<String>,
        /// Output image, .png or .exr.
        #[arg(short, long, default_value = "lucent.png")]
        output: PathBuf,
        /// Image size WIDTHxHEIGHT instead of the scene's.
        #[arg(long)]
        size: Option<String>,
    },
    /// Solve a scene and write the fluence grid (.npy or .vol) and a JSON report beside it.
    Solve {
        /// Scene file (TOML).
        scene: PathBuf,
        /// Solver to use instead of the scene's (with default parameters).
        #[arg(long)]
        solver: Option<String>,
        /// Output grid, .npy or .vol.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// List the solvers and what they can do.
    Solvers,
    /// Describe a scene: grid, medium, lights, and whether its solver can handle it.
    Info {
        /// Scene file (TOML); the built-in default scene if omitted.
        scene: Option<PathBuf>,
    },
    /// Print the diffusion optics of the measured materials (Jensen et al. 2001).
    Materials,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // Ctrl-C from here on stops a solve cleanly instead of killing the process.
    cancel_flag();
    let result = match cli.command {
        None => render(None, None, Path::new("lucent.png"), None, cli.quiet),
        Some(Command::Render {
            scene,
            solver,
            output,
            size,
        }) => render(scene.as_deref(), solver, &output, size, cli.quiet),
        Some(Command::Solve {
            scene,
            solver,
            output,
        }) => solve_to_file(&scene, solver, &output, cli.quiet),
        Some(Command::Solvers) => list_solvers(),
        Some(Command::Info { scene }) => info(scene.as_deref()),
        Some(Command::Materials) => {
            materials_table(&mut io::stdout().lock()).map_err(|e| match e {
                TableError::Io(e) => Error::Io {
                    path: "<stdout>".into(),
                    reason: e.to_string(),
                },
                TableError::Optics(e) => Error::Optics(e),
            })
        }
    };
    match result {
        // Interrupted: what was computed has been written; the conventional status of a
        // process stopped by SIGINT.
        Ok(()) if interrupted() => ExitCode::from(130),
        Ok(()) => ExitCode::SUCCESS,
        Err(Error::Io { reason, .. }) if reason.contains("Broken pipe") => ExitCode::SUCCESS,
        Err(e) => {
            let _ = writeln!(io::stderr(), "lucent: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The flag a Ctrl-C sets: the solve stops at its next iteration, batch or march and its
/// result is written as usual (its report says `interrupted`); a second Ctrl-C ends the
/// process at once. The handler is installed on first use.
fn cancel_flag() -> Arc<AtomicBool> {
    static FLAG: OnceLock<Arc<AtomicBool>> = OnceLock::new();
    FLAG.get_or_init(|| {
        let flag = Arc::new(AtomicBool::new(false));
        let seen = Arc::clone(&flag);
        // Without a handler (another one installed), Ctrl-C keeps its default: exit.
        let _ = ctrlc::set_handler(move || {
            if seen.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            let _ = writeln!(
                io::stderr(),
                "lucent: interrupted; stopping at the next iteration and writing what was computed (Ctrl-C again to abort)"
            );
        });
        flag
    })
    .clone()
}

/// Whether a Ctrl-C arrived.
fn interrupted() -> bool {
    cancel_flag().load(Ordering::SeqCst)
}

/// Loads a scene (or the default one) and builds it; relative paths start at its folder.
fn load(scene: Option<&Path>) -> Result<(Scene, BuiltScene, String), Error> {
    let (parsed, base, name) = match scene {
        Some(path) => (
            Scene::load(path)?,
            path.parent().unwrap_or(Path::new(".")).to_owned(),
            path.display().to_string(),
        ),
        None => (
            Scene::default_scene()?,
            PathBuf::from("."),
            "built-in default scene".to_owned(),
        ),
    };
    let built = parsed.build(&base)?;
    Ok((parsed, built, name))
}

fn bar(quiet: bool, message: &'static str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(1000).with_message(message);
    bar.set_style(
        ProgressStyle::with_template("{msg:>8} [{bar:40}] {percent:>3}% {elapsed_precise}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar
}

/// The solver `--solver` names (with default parameters when it is not the scene's) or
/// the scene's (with its parameters).
fn build_solver(scene: &Scene, solver: Option<String>) -> Result<Box<dyn Solver>, Error> {
    let registry = lucent::registry();
    Ok(match solver {
        Some(name) if name != scene.solver.name => registry.build(&name, &Default::default())?,
        _ => registry.build(&scene.solver.name, &scene.solver.params)?,
    })
}

fn run_solver(
    scene: &Scene,
    built: &BuiltScene,
    solver: Option<String>,
    quiet: bool,
) -> Result<(Box<dyn Solver>, Solution), Error> {
    let solver = build_solver(scene, solver)?;
    let progress = bar(quiet, "solve");
    let callback = progress.clone();
    let options = SolveOptions {
        progress: Some(Arc::new(move |p: Progress| {
            callback.set_position((p.fraction * 1000.0) as u64)
        })),
        cancel: Some(cancel_flag()),
        ..SolveOptions::default()
    };
    let solution = solver.solve(&built.problem, &options)?;
    progress.finish_and_clear();
    Ok((solver, solution))
}

fn render(
    scene: Option<&Path>,
    solver: Option<String>,
    output: &Path,
    size: Option<String>,
    quiet: bool,
) -> Result<(), Error> {
    let start = Instant::now();
    let (parsed, mut built, name) = load(scene)?;
    if let Some(size) = size {
        let (w, h) = size
            .split_once('x')
            .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
            .ok_or_else(|| Error::Invalid(format!("--size `{size}` is not WIDTHxHEIGHT")))?;
        built.settings.width = w;
        built.settings.height = h;
        built.settings.validate()?;
    }
    // A solver that makes pictures itself (Monte Carlo's camera paths) says so; the rest
    // hand the renderer a fluence.
    let chosen = build_solver(&parsed, solver.clone())?;
    let (solver_name, solve_seconds, image) = if let Some(imager) = chosen.images() {
        let s = built.settings;
        let background = s.background.unwrap_or_else(|| sky_radiance(&built.problem));
        let camera = built.camera;
        camera.validate()?;
        let aspect = s.width as f64 / s.height as f64;
        let progress = bar(quiet, "trace");
        let callback = progress.clone();
        let ray = |u: f64, v: f64| {
            camera
                .ray(u, v, aspect)
                .unwrap_or((glam::DVec3::ZERO, glam::DVec3::Z))
        };
        let report = move |f: f64| callback.set_position((f * 1000.0) as u64);
        let estimate = imager.image(
            &built.problem,
            &lucent::core::ImageRequest {
                width: s.width,
                height: s.height,
                background,
                ray: &ray,
                progress: Some(&report),
            },
        )?;
        progress.finish_and_clear();
        // The per-pixel standard error, linear, beside the picture.
        let error_path = output.with_extension("stderr.exr");
        lucent::render::Image {
            width: estimate.width,
            height: estimate.height,
            pixels: estimate.std_error,
        }
        .write_exr(&error_path)?;
        if !quiet {
            println!(
                "lucent: per-pixel standard error in {}",
                error_path.display()
            );
        }
        let image = lucent::render::Image {
            width: estimate.width,
            height: estimate.height,
            pixels: estimate.radiance,
        };
        (chosen.name().to_owned(), 0.0, image)
    } else {
        let (solver, solution) = run_solver(&parsed, &built, solver, quiet)?;
        let progress = bar(quiet, "render");
        let callback = progress.clone();
        let image = lucent::render::render(
            &built.problem,
            &solution,
            &built.camera,
            &built.settings,
            Some(&move |f: f64| callback.set_position((f * 1000.0) as u64)),
        )?;
        progress.finish_and_clear();
        (solver.name().to_owned(), solution.report.wall_time_s, image)
    };
    image.write(output, built.exposure, built.tone)?;
    if !quiet {
        println!(
            "lucent: rendered {name} with `{solver_name}` to {} ({}×{}) in {:.2} s (solve {solve_seconds:.2} s)",
            output.display(),
            image.width,
            image.height,
            start.elapsed().as_secs_f64(),
        );
    }
    Ok(())
}

/// The sky's radiance per channel (what escaping camera rays see by default).
fn sky_radiance(problem: &lucent::core::Problem) -> [f64; 3] {
    std::array::from_fn(|c| {
        problem
            .lights()
            .iter()
            .filter(|l| matches!(l, lucent::core::Light::Sky { .. }))
            .map(|l| l.spectrum().channel(c))
            .sum()
    })
}

fn solve_to_file(
    scene: &Path,
    solver: Option<String>,
    output: &Path,
    quiet: bool,
) -> Result<(), Error> {
    let (parsed, built, name) = load(Some(scene))?;
    let (solver, solution) = run_solver(&parsed, &built, solver, quiet)?;
    let grids: Vec<&lucent::grid::Grid> = solution.fluence.iter().collect();
    match output
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("npy") => lucent::grid::io::npy::write_channels(output, &grids, ScalarType::F32)?,
        Some("vol") => lucent::grid::io::mitsuba::write(output, &grids)?,
        _ => {
            return Err(Error::Invalid(format!(
                "{}: the fluence is written as .npy or .vol",
                output.display()
            )));
        }
    }
    let report_path = output.with_extension("json");
    let g = built.problem.geometry();
    let report = serde_json::json!({
        "scene": name,
        "solver": solver.name(),
        "params": parsed.solver.params,
        "capabilities": solver.capabilities(),
        "channels": solution.fluence.len(),
        "dims": g.dims(),
        "spacing": g.spacing().to_array(),
        "origin": g.origin().to_array(),
        "fluence": output.file_name().map(|n| n.to_string_lossy().into_owned()),
        "report": solution.report,
    });
    let text = serde_json::to_string_pretty(&report).map_err(|e| Error::Invalid(e.to_string()))?;
    std::fs::write(&report_path, text + "\n").map_err(|e| Error::Io {
        path: report_path.clone(),
        reason: e.to_string(),
    })?;
    if !quiet {
        println!(
            "lucent: solved {name} with `{}` ({:?}) in {:.2} s; fluence {} and report {}",
            solver.name(),
            solution.report.stop_reason,
            solution.report.wall_time_s,
            output.display(),
            report_path.display()
        );
    }
    Ok(())
}

fn list_solvers() -> Result<(), Error> {
    let mut out = io::stdout().lock();
    let io_err = |e: io::Error| Error::Io {
        path: "<stdout>".into(),
        reason: e.to_string(),
    };
    for entry in lucent::registry().entries() {
        let solver = (entry.build)(&Default::default())?;
        let c = solver.capabilities();
        writeln!(out, "{:<16} {}", entry.name, entry.summary).map_err(io_err)?;
        writeln!(
            out,
            "{:<16} anisotropic: {}, heterogeneous: {}, embedded geometry: {}, output: {:?}\n{:<16} boundaries: {:?}\n{:<16} lights: {:?}",
            "", c.anisotropic, c.heterogeneous, c.embedded_geometry, c.output, "", c.boundaries, "", c.lights
        )
        .map_err(io_err)?;
        let params = (entry.params)();
        if params.is_empty() {
            writeln!(out, "{:<16} parameters: none", "").map_err(io_err)?;
        }
        for p in params {
            let setting = format!("{} = {}", p.name, p.default);
            writeln!(out, "{:<16} {setting:<28} {}", "", p.meaning).map_err(io_err)?;
        }
    }
    Ok(())
}

fn info(scene: Option<&Path>) -> Result<(), Error> {
    let (parsed, built, name) = load(scene)?;
    let p = &built.problem;
    let g = p.geometry();
    let s = built.volume.stats();
    let mut out = io::stdout().lock();
    let io_err = |e: io::Error| Error::Io {
        path: "<stdout>".into(),
        reason: e.to_string(),
    };
    let (lo, hi) = g.bounds();
    writeln!(out, "{name}").map_err(io_err)?;
    writeln!(
        out,
        "  grid      {:?} cells of {}, box {} to {}",
        g.dims(),
        g.spacing(),
        lo,
        hi
    )
    .map_err(io_err)?;
    writeln!(
        out,
        "  volume    min {} max {} mean {:.4} non-zero {:.1}%",
        s.min,
        s.max,
        s.mean,
        100.0 * s.nonzero_fraction
    )
    .map_err(io_err)?;
    let sigma = p.medium().sigma_t(0).stats();
    writeln!(
        out,
        "  medium    sigma_t up to {} (channels: {}), phase {:?}",
        sigma.max,
        p.channels(),
        p.medium().phase
    )
    .map_err(io_err)?;
    for light in p.lights() {
        writeln!(out, "  light     {:?} {:?}", light.kind(), light.spectrum()).map_err(io_err)?;
    }
    writeln!(out, "  boundary  {:?}", p.boundary()).map_err(io_err)?;
    let solver = lucent::registry().build(&parsed.solver.name, &parsed.solver.params)?;
    let verdict = match solver.admits(p) {
        Ok(()) => "can solve this scene".to_owned(),
        Err(e) => e.to_string(),
    };
    writeln!(out, "  solver    `{}`: {verdict}", solver.name()).map_err(io_err)?;
    writeln!(
        out,
        "  image     {}×{}, camera {:?}",
        built.settings.width, built.settings.height, built.camera
    )
    .map_err(io_err)?;
    Ok(())
}

#[derive(Debug)]
enum TableError {
    Io(io::Error),
    Optics(lucent::optics::OpticsError),
}

impl From<io::Error> for TableError {
    fn from(e: io::Error) -> Self {
        TableError::Io(e)
    }
}

impl From<lucent::optics::OpticsError> for TableError {
    fn from(e: lucent::optics::OpticsError) -> Self {
        TableError::Optics(e)
    }
}

/// One row per material and channel: reduced albedo, D, σ_tr, z_r, z_v, the dipole's total
/// diffuse reflectance and the exact Robin half-space value it approximates.
fn materials_table(out: &mut impl Write) -> Result<(), TableError> {
    writeln!(
        out,
        "Diffusion optics of Jensen et al. 2001's measured materials (lengths in {LENGTH_UNIT}, Groenhuis A)"
    )?;
    writeln!(
        out,
        "{:<11} {:>2} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}",
        "material", "ch", "albedo'", "D", "sigma_tr", "z_r", "z_v", "R dipole", "R exact", "error"
    )?;
    for material in &JENSEN_2001 {
        let boundary = Dielectric::new(material.eta)?;
        for (channel, name) in ["R", "G", "B"].into_iter().enumerate() {
            let medium = DiffusionMedium::with_boundary(
                material.channel(channel, 0.0)?,
                boundary,
                DiffuseFresnel::Groenhuis,
            )?;
            let dipole = medium.dipole();
            let c = medium.coefficients();
            let rho = dipole.total_reflectance();
            // Spectralon does not absorb: the exact half-space then reflects everything.
            let exact = if c.sigma_a() > 0.0 {
                dipole.total_reflectance_exact()?
            } else {
                1.0
            };
            writeln!(
                out,
                "{:<11} {:>2} {:>9.5} {:>9.5} {:>9.5} {:>9.5} {:>9.5} {:>9.5} {:>9.5} {:>+7.2}%",
                material.name,
                name,
                c.albedo_reduced(),
                medium.d(),
                medium.sigma_tr(),
                medium.z_r(),
                medium.z_v(),
                rho,
                exact,
                100.0 * (rho - exact) / exact
            )?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_job_prints_every_material_with_the_dipole_against_the_exact_half_space() {
        let mut out = Vec::new();
        materials_table(&mut out).expect("the table is written");
        let text = String::from_utf8(out).expect("utf-8");
        // Header, column names, and 12 materials × 3 channels.
        assert_eq!(text.lines().count(), 2 + 36);
        // Marble red: R dipole 0.86654 and the exact Robin half-space 0.86633 (Mertens T4/T5).
        let marble_red = text
            .lines()
            .find(|l| l.starts_with("Marble") && l.contains(" R "))
            .expect("marble row");
        assert!(
            marble_red.contains("0.86654") && marble_red.contains("0.86633"),
            "{marble_red}"
        );
        // Ketchup green is where diffusion fails: the dipole is off by almost a factor of two.
        let ketchup_green = text
            .lines()
            .find(|l| l.starts_with("Ketchup") && l.contains(" G "))
            .expect("ketchup row");
        assert!(ketchup_green.contains("+95."), "{ketchup_green}");
    }
}
