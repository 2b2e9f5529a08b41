//! The `lucent` command: render a scene, solve it to a fluence grid, list solvers.
//!
//! `cargo run --release` with no arguments renders the built-in default scene to
//! `lucent.png`; `lucent [SCENE] [-o out.png] ...` is short for `lucent render ...`.
//! Exit status: 0 done; 1 an error (one line on stderr: bad input, a refused solver, an
//! output that cannot be written); 2 a usage error; 3 the solve ran but did not converge
//! (iteration or time limit); 4 it diverged; 130 interrupted by Ctrl-C (what was computed
//! is written). With 3 and 4 no image or fluence is written, only the JSON report of
//! `solve`, unless `--allow-unconverged` asks for them (the status is then 0).

// Printing is this binary's job; the lint guards the libraries.
#![allow(clippy::print_stdout)]

use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use lucent::Error;
use lucent::core::{ParamValue, Params, Solution, SolveOptions, Solver, StopReason};
use lucent::grid::io::ScalarType;
use lucent::optics::Significant as S;
use lucent::optics::materials::{JENSEN_2001, LENGTH_UNIT};
use lucent::optics::{Dielectric, DiffuseFresnel, DiffusionMedium};
use lucent::progress::Meter;
use lucent::resolution::AngularFamily;
use lucent::scene::{BuiltScene, Scene};

/// A line on stdout that never panics: a full or closed stdout (`> /dev/full`, a pipe
/// whose reader left) loses the line, not the job (`println!` panics on a failed write).
macro_rules! say {
    ($($arg:tt)*) => {{
        let _ = writeln!(io::stdout(), $($arg)*);
    }};
}

/// The solve ran to its end but did not converge (iteration or time limit).
const EXIT_UNCONVERGED: u8 = 3;
/// The solve diverged (a residual that grew without bound, or NaN).
const EXIT_DIVERGED: u8 = 4;
/// Interrupted by Ctrl-C (the conventional 128 + SIGINT).
const EXIT_INTERRUPTED: u8 = 130;

const EXIT_STATUS_HELP: &str = "Exit status: 0 done; 1 error (one line on stderr); 2 usage error; \
3 the solve did not converge (iteration or time limit); 4 it diverged; 130 interrupted by \
Ctrl-C. With 3 and 4 nothing but `solve`'s JSON report is written, unless --allow-unconverged.";

#[derive(Parser)]
#[command(
    name = "lucent",
    version,
    about = "Light transport in participating media: solve a scene, render a picture.",
    after_help = EXIT_STATUS_HELP
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// Without a command: `lucent render` with these arguments.
    #[command(flatten)]
    render: RenderArgs,
    /// No progress bars.
    #[arg(long, short, global = true)]
    quiet: bool,
    /// Check the command line and exit (0, or 2 with the usage error): the docs' commands
    /// are checked with it (`tests/it/tidy.rs`).
    #[arg(long, global = true, hide = true)]
    parse_only: bool,
}

/// Which solver, with which parameters, and what to accept.
#[derive(Args, Clone, Default)]
struct SolverArgs {
    /// Solver to use instead of the scene's (its parameters are the scene's only when it
    /// is the scene's solver).
    #[arg(long)]
    solver: Option<String>,
    /// A solver parameter, KEY=VALUE (repeatable; overrides the scene's; `lucent solvers`
    /// lists them).
    #[arg(long = "param", value_name = "KEY=VALUE")]
    params: Vec<String>,
    /// Write the result even when the solve did not converge or diverged (exit 0, with
    /// a warning).
    #[arg(long)]
    allow_unconverged: bool,
    /// Stop iterating when the residual has fallen to this fraction of its start (default:
    /// the scene's `[solver] tolerance`, else 1e-6).
    #[arg(long, value_name = "RELATIVE")]
    tolerance: Option<f64>,
    /// Stop after this many iterations (cycles, sweeps, time steps, batches).
    #[arg(long, value_name = "N", default_value_t = SolveOptions::default().max_iterations)]
    max_iterations: usize,
    /// Stop after this many seconds of solving.
    #[arg(long, value_name = "SECONDS")]
    time_limit: Option<f64>,
    /// The most memory the job may take: building the scene and the solve (bytes, or
    /// with a unit: 512MiB, 2GiB, 1.5GB). A scene or a solver that would need more is
    /// refused before it allocates, naming the bytes it needs. Default 8GiB.
    #[arg(long, value_name = "SIZE", value_parser = lucent::parse_bytes)]
    memory_budget: Option<u64>,
}

impl SolverArgs {
    /// The job's memory budget (bytes).
    fn budget(&self) -> u64 {
        self.memory_budget
            .unwrap_or(lucent::scene::SCENE_MEMORY_BUDGET)
    }

    /// The solve options these arguments ask for, with the chosen solver's tolerance, a
    /// progress callback and Ctrl-C.
    fn options(
        &self,
        chosen: &Chosen,
        progress: lucent::core::ProgressFn,
    ) -> Result<SolveOptions, Error> {
        let time_budget = match self.time_limit {
            None => None,
            Some(t) if t > 0.0 && t.is_finite() && t < 1e9 => Some(Duration::from_secs_f64(t)),
            Some(t) => {
                return Err(Error::Usage(format!(
                    "--time-limit {t:?}: a positive number of seconds (below 10⁹)"
                )));
            }
        };
        if let Some(t) = self.tolerance
            && !(0.0..1.0).contains(&t)
        {
            return Err(Error::Usage(format!(
                "--tolerance {t:?}: a relative residual, at least 0 and below 1"
            )));
        }
        Ok(SolveOptions {
            relative_tolerance: chosen.tolerance,
            max_iterations: self.max_iterations,
            time_budget,
            memory_budget: self.budget(),
            progress: Some(progress),
            cancel: Some(cancel_flag()),
            ranks: world().cloned(),
            ..SolveOptions::default()
        })
    }
}

#[derive(Args, Clone)]
struct RenderArgs {
    /// Scene file (TOML); the built-in default scene if omitted.
    scene: Option<PathBuf>,
    #[command(flatten)]
    solver: SolverArgs,
    /// Output image, .png (sRGB) or .exr (linear).
    #[arg(short, long, default_value = "lucent.png")]
    output: PathBuf,
    /// Image size WIDTHxHEIGHT instead of the scene's.
    #[arg(long)]
    size: Option<String>,
    /// March the camera rays on the GPU (wgpu; `WGPU_ADAPTER_NAME` and `WGPU_BACKEND`
    /// pick the adapter): the CPU's image within f32 rounding. The adapter is opened
    /// before solving, so a missing one fails at once.
    #[arg(long)]
    gpu: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Solve a scene and render it to PNG (sRGB) or EXR (linear).
    #[command(after_help = EXIT_STATUS_HELP)]
    Render(RenderArgs),
    /// Solve a scene and write the fluence grid (.npy or .vol) and a JSON report beside it
    /// (and a Monte Carlo solve's per-cell standard error, NAME.stderr.npy or .vol).
    #[command(after_help = EXIT_STATUS_HELP)]
    Solve {
        /// Scene file (TOML).
        scene: PathBuf,
        #[command(flatten)]
        solver: SolverArgs,
        /// Output grid, .npy or .vol.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// List the solvers; with a NAME, what that one handles and its parameters.
    Solvers {
        /// A registered solver (`lucent solvers` lists them).
        name: Option<String>,
    },
    /// Describe a scene: grid, medium, lights, and whether its solver can handle it.
    Info {
        /// Scene file (TOML); the built-in default scene if omitted.
        scene: Option<PathBuf>,
        #[command(flatten)]
        solver: SolverArgs,
    },
    /// Print the diffusion optics of the measured materials (Jensen et al. 2001).
    Materials,
    /// Find the coarsest grid on which the solver meets a discretisation error: it solves
    /// on the scene's grid and on grids 2× and 4× coarser and estimates each one's error
    /// from their differences (Richardson, with the order observed from three levels).
    #[command(after_help = EXIT_STATUS_HELP)]
    Resolution {
        /// Scene file (TOML).
        scene: PathBuf,
        #[command(flatten)]
        solver: SolverArgs,
        /// The relative L2 discretisation error to meet.
        #[arg(long = "error", value_name = "RELATIVE", default_value_t = 0.02)]
        target: f64,
        /// Choose the fewest directions instead of the coarsest grid (`dom`: octahedral
        /// sets of 128, 32 and 8 directions; `hybrid`: S8, S4, S2), on the scene's grid.
        #[arg(long)]
        directions: bool,
    },
}

/// How a job ended, when it ran.
enum Ended {
    Done,
    Unconverged,
    Diverged,
}

/// Mesa's implicit Vulkan layer `VK_LAYER_MESA_device_select` asks Wayland for the
/// default display while the adapters are listed; without a runtime folder
/// (`XDG_RUNTIME_DIR`, which a headless machine lacks) libwayland prints
/// `error: XDG_RUNTIME_DIR is invalid or not set` twice on every GPU run. The layer only
/// orders devices by the display they drive, and wgpu picks its adapter itself, so on a
/// headless machine the layer is told to stand aside (`NODEVICE_SELECT=1`, Mesa's switch)
/// instead of alarming users with errors that are not errors.
#[allow(unsafe_code)]
fn quiet_headless_vulkan() {
    let headless = std::env::var_os("XDG_RUNTIME_DIR").is_none_or(|d| !Path::new(&d).is_dir());
    if headless && std::env::var_os("NODEVICE_SELECT").is_none() {
        // SAFETY: called first thing in `main`, before any thread exists (the Ctrl-C
        // handler, rayon's pool and MPI start later), so nothing reads or writes the
        // environment concurrently.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}

fn main() -> ExitCode {
    quiet_headless_vulkan();
    let cli = match parse_command_line(std::env::args_os()) {
        Ok(cli) => cli,
        Err(e) => e.exit(),
    };
    if cli.parse_only {
        return ExitCode::SUCCESS;
    }
    if let Some(note) = lucent::cap_global_threads() {
        let _ = writeln!(io::stderr(), "lucent: {note}");
    }
    // Under `mpirun` (built with the `mpi` feature) this process is one rank; MPI is
    // finalised when `_mpi` drops, after everything else.
    #[cfg(feature = "mpi")]
    let _mpi = match lucent_mpi::World::initialise() {
        Ok(world) => {
            let ranks: lucent::core::Ranks = Arc::new(world.ranks());
            let _ = WORLD.set(ranks);
            world
        }
        Err(e) => {
            let _ = writeln!(io::stderr(), "lucent: {e}");
            return ExitCode::FAILURE;
        }
    };
    // Only rank 0 speaks and writes.
    let quiet = cli.quiet || !writes();
    // Ctrl-C from here on stops a solve cleanly instead of killing the process.
    cancel_flag();
    let result = match cli.command {
        None => render(&cli.render, quiet),
        Some(Command::Render(args)) => render(&args, quiet),
        Some(Command::Solve {
            scene,
            solver,
            output,
        }) => solve_to_file(&scene, &solver, &output, quiet),
        Some(Command::Solvers { name }) => list_solvers(name.as_deref()).map(|()| Ended::Done),
        Some(Command::Info { scene, solver }) => {
            info(scene.as_deref(), &solver).map(|()| Ended::Done)
        }
        Some(Command::Resolution {
            scene,
            solver,
            target,
            directions,
        }) => resolution(&scene, &solver, target, directions).map(|()| Ended::Done),
        Some(Command::Materials) => materials_table(&mut io::stdout().lock())
            .map(|()| Ended::Done)
            .map_err(|e| match e {
                TableError::Io(e) => Error::Io {
                    path: "<stdout>".into(),
                    reason: e.to_string(),
                },
                TableError::Optics(e) => Error::Optics(e),
            }),
    };
    #[cfg(feature = "mpi")]
    let failed = result.is_err();
    let code: u8 = match result {
        // Interrupted: what was computed has been written.
        Ok(_) if interrupted() => EXIT_INTERRUPTED,
        Ok(Ended::Done) => 0,
        Ok(Ended::Unconverged) => EXIT_UNCONVERGED,
        Ok(Ended::Diverged) => EXIT_DIVERGED,
        Err(Error::Io { reason, .. }) if reason.contains("Broken pipe") => 0,
        // After a Ctrl-C whatever failed (a level of `resolution` stopped short, a solve
        // halted in set-up) failed because of it: the status says interrupted.
        Err(e) if interrupted() => {
            let _ = writeln!(io::stderr(), "lucent: interrupted: {e}");
            EXIT_INTERRUPTED
        }
        Err(e) => {
            // Under mpirun every rank says which it is.
            let who = world().map_or(String::new(), |w| {
                format!(" (rank {} of {})", w.rank(), w.size())
            });
            let _ = writeln!(io::stderr(), "lucent{who}: {e}");
            match e {
                Error::Usage(_) => 2,
                Error::Unconverged { diverged: true, .. } => EXIT_DIVERGED,
                Error::Unconverged { .. } => EXIT_UNCONVERGED,
                // The time limit reached before any result existed.
                Error::Solve(lucent::core::SolveError::Halted {
                    halt: lucent::core::Halt::TimeLimit,
                    ..
                }) => EXIT_UNCONVERGED,
                Error::Solve(lucent::core::SolveError::Halted { .. }) => EXIT_INTERRUPTED,
                _ => 1,
            }
        }
    };
    // An error on this rank may not be the others' (a file one node cannot read): end
    // every rank now instead of finalising MPI, which would wait for ranks that wait for
    // this one.
    #[cfg(feature = "mpi")]
    if failed && code != 0 && world().is_some() {
        _mpi.abort(i32::from(code));
    }
    let status = ExitCode::from(code);
    if std::env::var_os("LUCENT_COUNTERS").is_some() {
        // For tests: proof that bad input was refused before any solving (last line).
        let _ = writeln!(
            io::stderr(),
            "lucent: counters: solves started {}",
            lucent::core::driver::solves_started()
        );
    }
    status
}

/// The command line, with global flags (`-q`) allowed before the subcommand as in cargo
/// and git (`lucent -q solve ...`). Without a subcommand the arguments are `render`'s; with
/// one, `render`'s arguments before it are a usage error.
fn parse_command_line<I, T>(args: I) -> Result<Cli, clap::Error>
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    use clap::parser::ValueSource;
    use clap::{CommandFactory, FromArgMatches};
    let mut command = Cli::command();
    let matches = command.try_get_matches_from_mut(args)?;
    if let Some((name, _)) = matches.subcommand() {
        let given: Vec<String> = matches
            .ids()
            .filter(|id| !matches!(id.as_str(), "quiet" | "parse_only"))
            .filter(|id| matches.value_source(id.as_str()) == Some(ValueSource::CommandLine))
            // Arguments only (a flattened struct is also a group of its arguments' ids).
            .filter_map(|id| command.get_arguments().find(|a| a.get_id() == id))
            .map(|a| match a.get_long() {
                Some(long) => format!("--{long}"),
                None => a.get_id().to_string(),
            })
            .collect();
        if !given.is_empty() {
            return Err(command.error(
                clap::error::ErrorKind::ArgumentConflict,
                format!(
                    "`{}` given before the subcommand `{name}`: put the subcommand first (`lucent {name} ...`)",
                    given.join("`, `")
                ),
            ));
        }
    }
    Cli::from_arg_matches(&matches).map_err(|e| e.format(&mut command))
}

/// The MPI ranks this process is one of (set once, under `mpirun`, by the `mpi` feature).
static WORLD: std::sync::OnceLock<lucent::core::Ranks> = std::sync::OnceLock::new();

/// The ranks this process is one of, if more than itself.
fn world() -> Option<&'static lucent::core::Ranks> {
    WORLD.get().filter(|w| w.size() > 1)
}

/// Whether this process writes outputs and speaks: alone, or rank 0 of a world (every
/// rank holds the whole, identical solution).
fn writes() -> bool {
    world().is_none_or(|w| w.rank() == 0)
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
            let again = seen.swap(true, Ordering::SeqCst);
            // Before a solve there is nothing to keep (reading the scene, building a
            // paged medium): end at once. A second Ctrl-C always ends at once.
            if again || !SOLVING.load(Ordering::SeqCst) {
                lucent::grid::io::atomic::remove_partial_files();
                if !again {
                    let _ = writeln!(io::stderr(), "lucent: interrupted; nothing was solved");
                }
                std::process::exit(i32::from(EXIT_INTERRUPTED));
            }
            let _ = writeln!(
                io::stderr(),
                "lucent: interrupted; stopping within a second and writing what was computed (Ctrl-C again to abort)"
            );
        });
        flag
    })
    .clone()
}

/// Whether a solve has started: from then on Ctrl-C stops it and keeps what it computed;
/// before, Ctrl-C ends the process at once.
static SOLVING: AtomicBool = AtomicBool::new(false);

/// Marks the start of the solve (see [`SOLVING`]).
fn solving() {
    SOLVING.store(true, Ordering::SeqCst);
}

/// Whether a Ctrl-C arrived.
fn interrupted() -> bool {
    cancel_flag().load(Ordering::SeqCst)
}

/// Loads a scene (or the default one) and builds it; relative paths start at its folder.
fn load(scene: Option<&Path>, budget: u64) -> Result<(Scene, BuiltScene, String), Error> {
    let (parsed, base, name) = parse(scene)?;
    let built = parsed.build_within(&base, budget)?;
    Ok((parsed, built, name))
}

/// The scene (the built-in default without a path), the folder its paths are relative to,
/// and its name for messages.
fn parse(scene: Option<&Path>) -> Result<(Scene, PathBuf, String), Error> {
    Ok(match scene {
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
    })
}

/// A progress bar for one job (hidden with `--quiet` or when stderr is not a terminal):
/// the phase and the solver's words, the fraction, and an elapsed time that ticks on its
/// own while nothing reports.
fn bar(quiet: bool, prefix: &'static str) -> (ProgressBar, Arc<Meter>) {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        let bar = ProgressBar::new(1000).with_prefix(prefix);
        bar.set_style(
            ProgressStyle::with_template(
                "{prefix:>6} [{bar:30}] {percent:>3}% {elapsed_precise} {wide_msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar.enable_steady_tick(Duration::from_millis(250));
        bar
    };
    let shown = bar.clone();
    let meter = Meter::new(Arc::new(move |s: &lucent::progress::Shown| {
        shown.set_position(s.permille);
        shown.set_message(s.message.clone());
    }));
    (bar, meter)
}

/// The solver a job runs: `--solver` or the scene's; the scene's parameters only for its
/// own solver (said on stderr when `--solver` leaves them behind); `--param` on top.
struct Chosen {
    solver: Box<dyn Solver>,
    /// Said on stderr just before solving (after every check has passed).
    note: Option<String>,
    /// Said with it unless `--quiet`: what the default solver leaves out.
    advice: Option<String>,
    params: Params,
    resolved: serde_json::Value,
    /// `--tolerance`, else the scene's, else the default.
    tolerance: f64,
}

impl Chosen {
    fn say_note(&self, quiet: bool) {
        if let Some(note) = &self.note {
            let _ = writeln!(io::stderr(), "{note}");
        }
        if let Some(advice) = self.advice.as_ref().filter(|_| !quiet) {
            let _ = writeln!(io::stderr(), "{advice}");
        }
    }
}

fn choose_solver(scene: &Scene, args: &SolverArgs) -> Result<Chosen, Error> {
    let registry = lucent::registry();
    let name = args.solver.as_deref().unwrap_or(&scene.solver.name);
    let entry = registry.entry(name)?;
    let mut note = None;
    let mut advice = None;
    if args.solver.is_none() && scene.solver.defaulted {
        advice = Some(format!(
            "lucent: note: the scene has no [solver]: `{name}` computes the uncollided light only (a render adds single scattering); `--solver dom`, `hybrid` or `auto` add multiple scattering"
        ));
    }
    let mut params = if name == scene.solver.name {
        scene.solver.params.clone()
    } else {
        if !scene.solver.params.0.is_empty() {
            note = Some(format!(
                "lucent: note: the scene's [solver.params] belong to `{}`; `{name}` runs with its defaults{}",
                scene.solver.name,
                if args.params.is_empty() {
                    ""
                } else {
                    " and --param"
                }
            ));
        }
        Params::default()
    };
    for text in &args.params {
        let (key, value) = parse_param(text)?;
        params.0.insert(key, value);
    }
    let solver = (entry.build)(&params)?;
    if let Some(world) = world().filter(|w| w.size() > 1)
        && !solver.capabilities().ranks
    {
        // A feature the solver cannot handle (exit 1, as README says), not a usage error.
        return Err(Error::Solve(lucent::core::SolveError::Unsupported {
            solver: name.into(),
            feature: format!(
                "{} MPI ranks: it runs in one process (diffusion-mg, ftcs-diffusion, jacobi-diffusion, ftcs-p1 and convection-diffusion's ordered characteristic or paper march split over ranks)",
                world.size()
            ),
        }));
    }
    let resolved = (entry.resolved)(&params)?;
    Ok(Chosen {
        solver,
        note,
        advice,
        tolerance: args
            .tolerance
            .or(scene.solver.tolerance)
            .unwrap_or(SolveOptions::default().relative_tolerance),
        params,
        resolved,
    })
}

/// `KEY=VALUE`: the value as TOML would read it (`true`, `3`, `0.5`, `"text"`), or as bare
/// text (`closure=diamond`).
fn parse_param(text: &str) -> Result<(String, ParamValue), Error> {
    let (key, value) = text
        .split_once('=')
        .map(|(k, v)| (k.trim(), v.trim()))
        .filter(|(k, v)| !k.is_empty() && !v.is_empty())
        .ok_or_else(|| Error::Usage(format!("--param `{text}` is not KEY=VALUE")))?;
    let parsed = toml::from_str::<toml::Table>(&format!("v = {value}"))
        .ok()
        .and_then(|mut t| t.remove("v"));
    let value = match parsed {
        Some(toml::Value::Boolean(b)) => ParamValue::Bool(b),
        Some(toml::Value::Integer(i)) => ParamValue::Int(i),
        Some(toml::Value::Float(f)) => ParamValue::Float(f),
        Some(toml::Value::String(s)) => ParamValue::Text(s),
        Some(_) => {
            return Err(Error::Usage(format!(
                "--param `{text}`: a parameter is a boolean, a number or text"
            )));
        }
        None => ParamValue::Text(value.to_owned()),
    };
    Ok((key.to_owned(), value))
}

/// Checks, before anything is solved, that `path` can be written: its extension is one of
/// `extensions` (`kinds` says what they are), it is not a folder, and its folder exists
/// and takes a new file.
fn check_output(path: &Path, extensions: &[&str], kinds: &str) -> Result<(), Error> {
    let fail = |reason: String| Error::Output {
        path: path.to_owned(),
        reason,
    };
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !extension
        .as_deref()
        .is_some_and(|e| extensions.contains(&e))
    {
        return Err(fail(kinds.to_owned()));
    }
    if path.is_dir() {
        return Err(fail("is a folder".into()));
    }
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !folder.is_dir() {
        return Err(fail(format!(
            "the folder {} does not exist",
            folder.display()
        )));
    }
    if path.exists() {
        std::fs::OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(|e| fail(format!("cannot be overwritten: {e}")))?;
    } else {
        let probe = folder.join(format!(".lucent-write-test-{}", std::process::id()));
        std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&probe)
            .map_err(|e| fail(format!("cannot write in {}: {e}", folder.display())))?;
        let _ = std::fs::remove_file(&probe);
    }
    Ok(())
}

/// A progress callback that shows nothing (to check options before a bar exists).
fn meter_free() -> lucent::core::ProgressFn {
    Arc::new(|_| {})
}

/// Runs the chosen solver with a progress bar and Ctrl-C.
fn run_solver(
    chosen: &Chosen,
    built: &BuiltScene,
    args: &SolverArgs,
    quiet: bool,
) -> Result<Solution, Error> {
    chosen.say_note(quiet);
    let (progress, meter) = bar(quiet, "solve");
    let options = args.options(chosen, meter.solver_callback())?;
    solving();
    let solution = chosen.solver.solve(&built.problem, &options);
    progress.finish_and_clear();
    let solution = solution?;
    // A solver that chose another (`auto`) says what it ran and why, in one line.
    if let Some(choice) = &solution.report.choice {
        let _ = writeln!(io::stderr(), "lucent: {choice}");
    }
    let ran = solution
        .report
        .composition
        .as_ref()
        .map_or(chosen.solver.name(), |c| c.solver.as_str());
    if ran.starts_with("gpu-") && !quiet {
        say_if_software_device();
    }
    Ok(solution)
}

/// Says, once per process, that the GPU in use is a software device (lavapipe, WARP):
/// its results are right, its times are not a GPU's.
fn say_if_software_device() {
    static SAID: std::sync::Once = std::sync::Once::new();
    if let Ok(device) = lucent::gpu::GpuContext::shared()
        && device.is_software()
    {
        SAID.call_once(|| {
            let _ = writeln!(
                io::stderr(),
                "lucent: the GPU is a software device ({}): its results are right, its times are not a GPU's",
                device.info().name
            );
        });
    }
}

/// How a solve that stopped for `reason` ends the job; says so on stderr when it did not
/// converge. `Ok(None)`: write the result.
fn verdict(
    solver: &str,
    reason: &StopReason,
    iterations: usize,
    allow: bool,
    what: &str,
) -> Option<Ended> {
    if reason.is_converged() || matches!(reason, StopReason::Interrupted { .. }) {
        return None;
    }
    let ended = if reason.is_diverged() {
        Ended::Diverged
    } else {
        Ended::Unconverged
    };
    let (consequence, outcome) = if allow {
        (format!("{what} written anyway (--allow-unconverged)"), None)
    } else {
        (
            format!("no {what} written (--allow-unconverged writes it anyway)"),
            Some(ended),
        )
    };
    let _ = writeln!(
        io::stderr(),
        "lucent: `{solver}` {reason} after {iterations} iterations; {consequence}"
    );
    outcome
}

fn render(args: &RenderArgs, quiet: bool) -> Result<Ended, Error> {
    let start = Instant::now();
    let (parsed, mut built, name) = load(args.scene.as_deref(), args.solver.budget())?;
    let chosen = choose_solver(&parsed, &args.solver)?;
    // Everything about the output is checked before any solving.
    if let Some(size) = &args.size {
        let (w, h) = size
            .split_once('x')
            .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
            .ok_or_else(|| Error::Output {
                path: args.output.clone(),
                reason: format!("--size `{size}` is not WIDTHxHEIGHT"),
            })?;
        built.settings.width = w;
        built.settings.height = h;
        built.settings.validate().map_err(|e| Error::Output {
            path: args.output.clone(),
            reason: e.to_string(),
        })?;
    }
    let output = &args.output;
    check_output(
        output,
        &["png", "exr"],
        "images are written as .png or .exr (sRGB or linear)",
    )?;
    chosen.solver.admits(&built.problem)?;
    args.solver.options(&chosen, meter_free())?.validate()?;
    let device = if args.gpu {
        if chosen.solver.images().is_some() {
            return Err(Error::Usage(format!(
                "--gpu marches camera rays through a solution; `{}` traces its own camera paths on the CPU",
                chosen.solver.name()
            )));
        }
        let device =
            lucent::gpu::GpuContext::shared().map_err(|e| lucent::render::RenderError::Device {
                unavailable: true,
                reason: e.to_string(),
            })?;
        if !quiet {
            say_if_software_device();
        }
        Some(device)
    } else {
        None
    };
    // A solver that makes pictures itself (Monte Carlo's camera paths) says so; the rest
    // hand the renderer a fluence.
    let ((stage, solve_seconds), image) = if let Some(imager) = chosen.solver.images() {
        let error_path = output.with_extension("stderr.exr");
        check_output(
            &error_path,
            &["exr"],
            "the standard error is written as .exr",
        )?;
        let s = built.settings;
        let background = s
            .background
            .unwrap_or_else(|| lucent::scene::sky_background(&built.problem));
        let camera = built.camera;
        camera.validate()?;
        let aspect = s.width as f64 / s.height as f64;
        chosen.say_note(quiet);
        let (progress, meter) = bar(quiet, "trace");
        let report = meter.fraction_callback("camera paths");
        let ray = |u: f64, v: f64| {
            camera
                .ray(u, v, aspect)
                .unwrap_or((glam::DVec3::ZERO, glam::DVec3::Z))
        };
        solving();
        let traced = Instant::now();
        let estimate = imager.image(
            &built.problem,
            &lucent::core::ImageRequest {
                width: s.width,
                height: s.height,
                background,
                ray: &ray,
                progress: Some(&report),
                interrupt: lucent::core::Interrupt::of(
                    &args.solver.options(&chosen, meter_free())?,
                ),
            },
        );
        progress.finish_and_clear();
        let estimate = estimate?;
        if estimate.rows_traced < estimate.height {
            // Ctrl-C writes what was traced (exit 130); the time limit is a solve that did
            // not finish, as for every solver: exit 3, nothing written unless asked.
            let by_clock = !interrupted();
            if by_clock && !args.solver.allow_unconverged {
                let _ = writeln!(
                    io::stderr(),
                    "lucent: `{}` reached its time limit with {} of {} rows traced; no image written (--allow-unconverged writes it anyway)",
                    chosen.solver.name(),
                    estimate.rows_traced,
                    estimate.height
                );
                return Ok(Ended::Unconverged);
            }
            let _ = writeln!(
                io::stderr(),
                "lucent: stopped: {} of {} rows traced; the others show the background (standard error {} in the .stderr.exr)",
                estimate.rows_traced,
                estimate.height,
                f32::MAX
            );
        }
        // The per-pixel standard error, linear, beside the picture.
        lucent::render::Image {
            width: estimate.width,
            height: estimate.height,
            pixels: estimate.std_error,
        }
        .write_exr(&error_path)?;
        if !quiet {
            say!(
                "lucent: per-pixel standard error in {}",
                error_path.display()
            );
        }
        let image = lucent::render::Image {
            width: estimate.width,
            height: estimate.height,
            pixels: estimate.radiance,
        };
        // The paths are the solve: their time, not 0 (the summary said "solve 0.00 s").
        (("camera paths", traced.elapsed().as_secs_f64()), image)
    } else {
        let solution = run_solver(&chosen, &built, &args.solver, quiet)?;
        if !writes() {
            return Ok(Ended::Done);
        }
        let report = &solution.report;
        if let Some(ended) = verdict(
            chosen.solver.name(),
            &report.stop_reason,
            report.iterations,
            args.solver.allow_unconverged,
            "image",
        ) {
            return Ok(ended);
        }
        let (progress, meter) = bar(quiet, "render");
        let marched = meter.fraction_callback("ray marching");
        let image = match device {
            Some(gpu) => lucent::render::render_on_device(
                gpu,
                &built.problem,
                &solution,
                &built.camera,
                &built.settings,
                Some(&marched),
            ),
            None => lucent::render::render(
                &built.problem,
                &solution,
                &built.camera,
                &built.settings,
                Some(&marched),
            ),
        };
        progress.finish_and_clear();
        (("solve", report.wall_time_s), image?)
    };
    image.write(output, built.exposure, built.tone)?;
    if !quiet {
        say!(
            "lucent: rendered {name} with `{}` to {} ({}×{}{}) in {:.2} s ({stage} {solve_seconds:.2} s)",
            chosen.solver.name(),
            output.display(),
            image.width,
            image.height,
            device.map_or(String::new(), |gpu| format!(
                ", rays marched on {}",
                gpu.info().name
            )),
            start.elapsed().as_secs_f64(),
        );
    }
    Ok(Ended::Done)
}

/// `solve`'s JSON report: what was solved, how, on which grid, where the fluence went
/// (`None` when it was not written) and the solver's report.
fn solve_report(
    name: &str,
    chosen: &Chosen,
    args: &SolverArgs,
    g: &lucent::grid::GridGeometry,
    channels: usize,
    fluence: Option<&Path>,
    report: &lucent::core::SolveReport,
) -> serde_json::Value {
    // What ran: the solver asked for, or the one `auto` chose, with its parameters (the
    // parts of a composition are in `report.composition`).
    let ran = match &report.composition {
        Some(c) => serde_json::json!({ "solver": c.solver, "params": c.params }),
        None => serde_json::json!({ "solver": chosen.solver.name(), "params": chosen.resolved }),
    };
    serde_json::json!({
        "scene": name,
        "solver": chosen.solver.name(),
        "params": chosen.resolved,
        "params_given": chosen.params,
        "ran": ran,
        "options": {
            "tolerance": chosen.tolerance,
            "max_iterations": args.max_iterations,
            "time_limit_s": args.time_limit,
            // MPI processes the solve was split over (1: this one alone).
            "mpi_ranks": world().map_or(1, |w| w.size()),
        },
        "capabilities": chosen.solver.capabilities(),
        "channels": channels,
        "dims": g.dims(),
        "spacing": g.spacing().to_array(),
        "origin": g.origin().to_array(),
        "fluence": file_name(fluence),
        "converged": report.stop_reason.is_converged(),
        "report": report,
    })
}

/// The file name of `path` for a report (null for none).
fn file_name(path: Option<&Path>) -> serde_json::Value {
    path.and_then(Path::file_name)
        .map(|n| n.to_string_lossy().into_owned())
        .into()
}

/// Writes `report` as pretty JSON to `path`, whole or not at all.
fn write_report(path: &Path, report: &serde_json::Value) -> Result<(), Error> {
    let io = |e: &dyn std::fmt::Display| Error::Io {
        path: path.to_owned(),
        reason: e.to_string(),
    };
    let text = serde_json::to_string_pretty(report).map_err(|e| io(&e))?;
    lucent::grid::io::atomic::write_with(path, |f| f.write_all((text + "\n").as_bytes()))
        .map_err(|e| io(&e))
}

/// `solve` on a paged medium ([`Scene::build_paged`]): the fluence streamed slab by slab
/// into a `.npy` file (f32, channels first), and the report with the pager's counters.
fn solve_paged_to_file(
    parsed: &Scene,
    name: &str,
    chosen: &Chosen,
    args: &SolverArgs,
    output: &Path,
    quiet: bool,
) -> Result<Ended, Error> {
    let is_npy = output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npy"));
    if !is_npy {
        return Err(Error::Output {
            path: output.to_owned(),
            reason: "a fluence solved out of core is written as .npy (streamed slab by slab)"
                .into(),
        });
    }
    let options = args.options(chosen, meter_free())?;
    options.validate()?;
    // The medium gets its share of the budget, the solver pages its own data in the rest;
    // a budget that cannot do is refused before the medium is built.
    let problem = parsed.build_paged_for(chosen.solver.as_ref(), &options)?;
    chosen.say_note(quiet);
    let (progress, meter) = bar(quiet, "solve");
    let options = args.options(chosen, meter.solver_callback())?;
    solving();
    let solution = chosen.solver.solve_paged(&problem, &options);
    progress.finish_and_clear();
    let solution = solution?;
    let g = problem.geometry();
    let channels = solution.fluence.len();
    let stop = &solution.report.stop_reason;
    let ended = verdict(
        chosen.solver.name(),
        stop,
        solution.report.iterations,
        args.allow_unconverged,
        "fluence",
    );
    let standard_error = (ended.is_none() && !solution.standard_error.is_empty())
        .then(|| standard_error_path(output));
    if ended.is_none() {
        lucent::grid::io::npy::write_f32_slabs(output, g.dims(), channels, |c, z, out| {
            solution.fluence[c].read_slabs(z, z + 1, out)
        })?;
        if let Some(path) = &standard_error {
            let errors = &solution.standard_error;
            lucent::grid::io::npy::write_f32_slabs(path, g.dims(), errors.len(), |c, z, out| {
                errors[c].read_slabs(z, z + 1, out)
            })?;
        }
    }
    let report_path = output.with_extension("json");
    let mut report = solve_report(
        name,
        chosen,
        args,
        g,
        channels,
        ended.is_none().then_some(output),
        &solution.report,
    );
    report["options"]["memory_budget"] = args.budget().into();
    report["storage"] = "paged".into();
    report["brick"] = problem.layout().brick().into();
    report["standard_error"] = file_name(standard_error.as_deref());
    write_report(&report_path, &report)?;
    if let Some(ended) = ended {
        return Ok(ended);
    }
    if !quiet {
        let p = &solution.paging;
        let errors = standard_error.map_or_else(String::new, |p| {
            format!(", its standard error per cell {}", p.display())
        });
        say!(
            "lucent: solved {name} with `{}` out of core ({} MiB budget, a pool of {} bricks of {}³ cells): {}, {:.2} s, {} pins at a hit rate of {:.3}, {} MiB read and {} MiB written; fluence {}{errors} and report {}",
            chosen.solver.name(),
            args.budget() >> 20,
            p.slots,
            problem.layout().brick(),
            solution.report.stop_reason,
            solution.report.wall_time_s,
            p.hits + p.misses,
            p.hit_rate(),
            p.bytes_read >> 20,
            p.bytes_written >> 20,
            output.display(),
            report_path.display()
        );
    }
    Ok(Ended::Done)
}

/// Where a stochastic solver's per-cell standard error goes: beside the fluence, in its
/// format, `NAME.stderr.EXT` (as `render` writes `NAME.stderr.exr` beside an image).
fn standard_error_path(output: &Path) -> PathBuf {
    let extension = output
        .extension()
        .map_or_else(String::new, |e| e.to_string_lossy().into_owned());
    output.with_extension(format!("stderr.{extension}"))
}

fn solve_to_file(
    scene: &Path,
    args: &SolverArgs,
    output: &Path,
    quiet: bool,
) -> Result<Ended, Error> {
    let (parsed, base, name) = parse(Some(scene))?;
    let chosen = choose_solver(&parsed, args)?;
    check_output(
        output,
        &["npy", "vol"],
        "the fluence is written as .npy or .vol (NumPy or Mitsuba)",
    )?;
    let report_path = output.with_extension("json");
    check_output(&report_path, &["json"], "the report is written as .json")?;
    // Dense fields beyond the budget: out of core, where the solver can run so.
    if !parsed.fits_in_memory(args.budget()) && parsed.pageable() && chosen.solver.pages() {
        return solve_paged_to_file(&parsed, &name, &chosen, args, output, quiet);
    }
    let built = parsed.build_within(&base, args.budget())?;
    chosen.solver.admits(&built.problem)?;
    args.options(&chosen, meter_free())?.validate()?;
    let solution = run_solver(&chosen, &built, args, quiet)?;
    if !writes() {
        return Ok(Ended::Done);
    }
    let stop = &solution.report.stop_reason;
    let ended = verdict(
        chosen.solver.name(),
        stop,
        solution.report.iterations,
        args.allow_unconverged,
        "fluence",
    );
    if ended.is_none() {
        let grids: Vec<&lucent::grid::Grid> = solution.fluence.iter().collect();
        let is_npy = output
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("npy"));
        let write = |path: &Path, grids: &[&lucent::grid::Grid]| {
            if is_npy {
                lucent::grid::io::npy::write_channels(path, grids, ScalarType::F32)
            } else {
                lucent::grid::io::mitsuba::write(path, grids)
            }
        };
        write(output, &grids)?;
        if let Some(errors) = &solution.standard_error {
            let errors: Vec<&lucent::grid::Grid> = errors.iter().collect();
            write(&standard_error_path(output), &errors)?;
        }
    }
    let standard_error =
        (ended.is_none() && solution.standard_error.is_some()).then(|| standard_error_path(output));
    // The report is written either way: it says why the solve stopped.
    let mut report = solve_report(
        &name,
        &chosen,
        args,
        built.problem.geometry(),
        solution.fluence.len(),
        ended.is_none().then_some(output),
        &solution.report,
    );
    report["standard_error"] = file_name(standard_error.as_deref());
    write_report(&report_path, &report)?;
    if let Some(ended) = ended {
        return Ok(ended);
    }
    if !quiet {
        let ranks = match world().map_or(1, |w| w.size()) {
            1 => String::new(),
            n => format!(" on {n} MPI ranks"),
        };
        let errors = standard_error.map_or_else(String::new, |p| {
            format!(", its standard error per cell {}", p.display())
        });
        say!(
            "lucent: solved {name} with `{}`{ranks}: {stop}, {:.2} s; fluence {}{errors} and report {}",
            chosen.solver.name(),
            solution.report.wall_time_s,
            output.display(),
            report_path.display()
        );
    }
    Ok(Ended::Done)
}

fn list_solvers(name: Option<&str>) -> Result<(), Error> {
    let mut out = io::stdout().lock();
    let io_err = |e: io::Error| Error::Io {
        path: "<stdout>".into(),
        reason: e.to_string(),
    };
    let registry = lucent::registry();
    let Some(name) = name else {
        // One line each, the summaries aligned after the longest name.
        let width = registry
            .entries()
            .iter()
            .map(|e| e.name.len())
            .max()
            .unwrap_or(0);
        for entry in registry.entries() {
            writeln!(out, "{:<width$}  {}", entry.name, entry.summary).map_err(io_err)?;
        }
        writeln!(
            out,
            "\n`lucent solvers NAME`: what one solver handles, its parameters and their defaults"
        )
        .map_err(io_err)?;
        return Ok(());
    };
    let entry = registry.entry(name)?;
    let solver = (entry.build)(&Default::default())?;
    let c = solver.capabilities();
    let list = |items: Vec<String>| items.join(", ");
    let rows = [
        ("anisotropic", yes_no(c.anisotropic).to_owned()),
        ("heterogeneous", yes_no(c.heterogeneous).to_owned()),
        ("embedded geometry", yes_no(c.embedded_geometry).to_owned()),
        ("graded index", yes_no(c.graded_index).to_owned()),
        ("output", kebab(&c.output)),
        ("boundaries", list(c.boundaries.iter().map(kebab).collect())),
        ("lights", list(c.lights.iter().map(kebab).collect())),
        ("out of core", yes_no(solver.pages()).to_owned()),
        ("MPI ranks", yes_no(c.ranks).to_owned()),
    ];
    writeln!(out, "{}: {}\n", entry.name, entry.summary).map_err(io_err)?;
    for (what, value) in rows {
        writeln!(out, "  {what:<18} {value}").map_err(io_err)?;
    }
    let params = (entry.params)();
    if params.is_empty() {
        writeln!(out, "\n  parameters: none").map_err(io_err)?;
        return Ok(());
    }
    writeln!(out, "\n  parameters (--param KEY=VALUE; default shown):").map_err(io_err)?;
    let settings: Vec<String> = params
        .iter()
        .map(|p| format!("{} = {}", p.name, p.default))
        .collect();
    let width = settings
        .iter()
        .map(|s| s.chars().count())
        .max()
        .unwrap_or(0);
    for (setting, p) in settings.iter().zip(&params) {
        let pad = width - setting.chars().count();
        writeln!(out, "  {setting}{:pad$}  {}", "", p.meaning).map_err(io_err)?;
    }
    Ok(())
}

fn yes_no(b: bool) -> &'static str {
    if b { "yes" } else { "no" }
}

/// A serialisable enum as its kebab-case name (`directional`, `robin`).
fn kebab<T: serde::Serialize>(value: &T) -> String {
    match serde_json::to_value(value) {
        Ok(serde_json::Value::String(s)) => s,
        Ok(other) => other.to_string(),
        Err(_) => "?".into(),
    }
}

fn info(scene: Option<&Path>, args: &SolverArgs) -> Result<(), Error> {
    let (parsed, base, name) = parse(scene)?;
    if parsed.pageable() && !parsed.fits_in_memory(args.budget()) {
        return info_paged(&parsed, &name, args);
    }
    let built = parsed.build_within(&base, args.budget())?;
    let p = &built.problem;
    let g = p.geometry();
    let s = built.volume.stats();
    let mut out = io::stdout().lock();
    let io_err = |e: io::Error| Error::Io {
        path: "<stdout>".into(),
        reason: e.to_string(),
    };
    writeln!(out, "{name}\n{}", grid_line(g)).map_err(io_err)?;
    writeln!(
        out,
        "  volume    values {} to {}, mean {}, {}% of cells non-zero",
        S(f64::from(s.min)),
        S(f64::from(s.max)),
        S(s.mean),
        S(100.0 * s.nonzero_fraction)
    )
    .map_err(io_err)?;
    let medium = p.medium();
    // One line when every channel shares σ_t and albedo (a grey medium under coloured light).
    let distinct = medium.sigma_t.len().max(medium.albedo.len());
    for c in 0..distinct {
        let albedo = match medium.albedo(c) {
            lucent::core::Field::Constant(a) => (*a, *a),
            lucent::core::Field::Grid(grid) => {
                let a = grid.stats();
                (a.min, a.max)
            }
        };
        let line = medium_line(c, distinct, &medium.sigma_t(c).stats(), albedo);
        writeln!(out, "{line}").map_err(io_err)?;
    }
    writeln!(out, "  phase     {}", medium.phase).map_err(io_err)?;
    for c in 0..distinct {
        let label = if distinct > 1 {
            format!("regime {}", ["R", "G", "B"].get(c).copied().unwrap_or("?"))
        } else {
            "regime".to_owned()
        };
        writeln!(out, "  {label:<10}{}", regime_line(p, c)).map_err(io_err)?;
    }
    for light in p.lights() {
        writeln!(out, "  light     {light}").map_err(io_err)?;
    }
    writeln!(out, "  boundary  {}", p.boundary()).map_err(io_err)?;
    if let Some(index) = p.refractive_index() {
        writeln!(out, "  index     {index}").map_err(io_err)?;
    }
    if p.embedded().is_some() {
        writeln!(
            out,
            "  embedded  a body given by its signed distance (the medium is its inside)"
        )
        .map_err(io_err)?;
    }
    let chosen = choose_solver(&parsed, args)?;
    let verdict = match chosen.solver.admits(p) {
        Ok(()) => "can solve this scene".to_owned(),
        Err(e) => e.to_string(),
    };
    writeln!(out, "  solver    `{}`: {verdict}", chosen.solver.name()).map_err(io_err)?;
    writeln!(
        out,
        "  image     {} × {} pixels, {}",
        built.settings.width, built.settings.height, built.camera
    )
    .map_err(io_err)?;
    Ok(())
}

/// `info`'s grid line: cells, their size and the box.
fn grid_line(g: &lucent::grid::GridGeometry) -> String {
    let (lo, hi) = g.bounds();
    let v = |a: glam::DVec3| format!("({}, {}, {})", S(a.x), S(a.y), S(a.z));
    let [nx, ny, nz] = g.dims();
    let h = g.spacing();
    let cells = if h.x == h.y && h.y == h.z {
        format!("cubic cells of {}", S(h.x))
    } else {
        format!("cells of {} × {} × {}", S(h.x), S(h.y), S(h.z))
    };
    format!(
        "  grid      {nx} × {ny} × {nz} {cells}, box {} to {} (scene units)",
        v(lo),
        v(hi)
    )
}

/// `lucent info` of a procedural scene over the memory budget, which `lucent solve` can
/// page. Up to [`STATISTICS_CELLS`] cells the medium is built as `solve` builds it (brick
/// by brick under the budget) and read back a few slabs at a time for its statistics;
/// beyond, the scene is described from its file (evaluating 10¹¹ cells would take hours).
/// What needs the scene in memory (the regime estimate, the camera) is named instead.
fn info_paged(parsed: &Scene, name: &str, args: &SolverArgs) -> Result<(), Error> {
    let budget = args.budget();
    let g = parsed.paged_geometry()?;
    let field_bytes = g.voxel_count() as u64 * 4;
    let over_budget = format!(
        "{field_bytes} bytes per field, over the {} a field may take in memory under --memory-budget {budget}",
        lucent::scene::max_grid_bytes(budget)
    );
    let mut lines = Vec::new();
    let pages = if g.voxel_count() > STATISTICS_CELLS {
        let albedo = match parsed.medium.albedo {
            lucent::core::Spectrum::Grey(a) => S(a).to_string(),
            lucent::core::Spectrum::Rgb([r, gr, b]) => format!("[{}, {}, {}]", S(r), S(gr), S(b)),
        };
        lines.push(format!(
            "  memory    {over_budget}; out of core the medium takes {field_bytes} bytes on disk per field"
        ));
        lines.push(format!(
            "  medium    sigma_t = {} × the volume's value per unit, albedo {albedo} (statistics not computed: {} cells, over the {STATISTICS_CELLS} that info evaluates)",
            S(parsed.medium.density),
            g.voxel_count(),
        ));
        lines.push(format!("  phase     {}", parsed.medium.phase.to_phase()?));
        for light in &parsed.lights {
            lines.push(format!("  light     {}", light.to_light(None)?));
        }
        lines.push(format!("  boundary  {}", parsed.boundary));
        "`lucent solve` would page this scene, evaluating the medium brick by brick (Ctrl-C or --time-limit stop it)"
    } else {
        let problem = parsed.build_paged(budget)?;
        lines.push(format!(
            "  memory    {over_budget}: paged in bricks of {}³ cells",
            problem.layout().brick()
        ));
        let medium = problem.medium();
        let channels = medium.sigma_t.len().max(medium.albedo.len());
        for c in 0..channels {
            let sigma = paged_stats(&medium.sigma_t[c.min(medium.sigma_t.len() - 1)], budget)?;
            let a = paged_stats(&medium.albedo[c.min(medium.albedo.len() - 1)], budget)?;
            lines.push(medium_line(c, channels, &sigma, (a.min, a.max)));
        }
        lines.push(format!("  phase     {}", medium.phase));
        lines.push(
            "  regime    not estimated out of core (it samples the medium in memory)".to_owned(),
        );
        for light in problem.lights() {
            lines.push(format!("  light     {light}"));
        }
        lines.push(format!("  boundary  {}", problem.boundary()));
        "`lucent solve` pages this scene (the fluence streamed to a .npy file)"
    };
    let chosen = choose_solver(parsed, args)?;
    let verdict = if chosen.solver.pages() {
        pages.to_owned()
    } else {
        format!(
            "needs the scene in memory; `lucent solve --solver NAME` pages it with {}",
            lucent::scene::paging_solvers()
                .iter()
                .map(|n| format!("`{n}`"))
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    lines.push(format!("  solver    `{}`: {verdict}", chosen.solver.name()));
    lines.push(format!(
        "  image     `lucent render` needs the scene in memory: --memory-budget {} or more",
        8 * field_bytes
    ));
    let mut out = io::stdout().lock();
    writeln!(out, "{name}\n{}\n{}", grid_line(&g), lines.join("\n")).map_err(|e| Error::Io {
        path: "<stdout>".into(),
        reason: e.to_string(),
    })
}

/// `info`'s medium line of extinction channel `c` of `channels`: σ_t's peak and mean, and
/// the albedo's range (one value where it is uniform).
fn medium_line(
    c: usize,
    channels: usize,
    sigma: &lucent::grid::GridStats,
    (albedo_min, albedo_max): (f32, f32),
) -> String {
    let albedo = if albedo_min == albedo_max {
        S(f64::from(albedo_min)).to_string()
    } else {
        format!(
            "{} to {} per cell",
            S(f64::from(albedo_min)),
            S(f64::from(albedo_max))
        )
    };
    let label = if channels > 1 {
        format!("medium {}", ["R", "G", "B"].get(c).copied().unwrap_or("?"))
    } else {
        "medium".to_owned()
    };
    format!(
        "  {label:<10}sigma_t up to {} per unit (mean {}), albedo {albedo}",
        S(f64::from(sigma.max)),
        S(sigma.mean)
    )
}

/// Beyond this many cells `lucent info` does not evaluate a paged medium for its
/// statistics (256³: about a second).
const STATISTICS_CELLS: usize = 1 << 24;

/// Minimum, maximum and mean of a paged field, read a few z-slabs at a time (at most a
/// sixteenth of `budget` in memory).
fn paged_stats(
    field: &lucent::paging::PagedGrid,
    budget: u64,
) -> Result<lucent::grid::GridStats, Error> {
    let [nx, ny, nz] = field.geometry().dims();
    let plane = nx * ny;
    let slabs = ((budget / 16 / 4) as usize / plane).clamp(1, nz);
    let (mut min, mut max, mut sum, mut nonzero) = (f32::INFINITY, f32::NEG_INFINITY, 0.0f64, 0);
    let mut buffer = vec![0.0f32; slabs * plane];
    for z0 in (0..nz).step_by(slabs) {
        let z1 = (z0 + slabs).min(nz);
        let chunk = &mut buffer[..(z1 - z0) * plane];
        field
            .read_slabs(z0, z1, chunk)
            .map_err(|e| Error::from(lucent::core::paging_error("info", e)))?;
        for &v in chunk.iter() {
            min = min.min(v);
            max = max.max(v);
            sum += f64::from(v);
            nonzero += usize::from(v != 0.0);
        }
    }
    let cells = (plane * nz) as f64;
    Ok(lucent::grid::GridStats {
        min,
        max,
        mean: sum / cells,
        nonzero_fraction: nonzero as f64 / cells,
    })
}

/// `lucent resolution`: the levels solved, their estimated errors and the one chosen.
/// Where `lucent resolution`'s order came from, in words.
fn order_source(observed: bool) -> &'static str {
    if observed {
        "observed from three levels"
    } else {
        "nominal: three levels did not show one"
    }
}

fn resolution(scene: &Path, args: &SolverArgs, target: f64, directions: bool) -> Result<(), Error> {
    if !(target > 0.0 && target < 1.0) {
        return Err(Error::Usage(format!(
            "--error {target:?}: a relative error between 0 and 1"
        )));
    }
    let (parsed, built, name) = load(Some(scene), args.budget())?;
    let chosen = choose_solver(&parsed, args)?;
    chosen.solver.admits(&built.problem)?;
    let mut options = args.options(&chosen, meter_free())?;
    // The iteration's own error must stay far below the discretisation's it measures.
    options.relative_tolerance = options.relative_tolerance.min(target * 1e-3);
    options.validate()?;
    let mut out = io::stdout().lock();
    let io_err = |e: io::Error| Error::Io {
        path: "<stdout>".into(),
        reason: e.to_string(),
    };
    if directions {
        let registry = lucent::registry();
        let Some(family) = AngularFamily::of(&registry, chosen.solver.name(), &chosen.params)?
        else {
            return Err(Error::Usage(format!(
                "--directions: `{}` has no angular family to choose from (dom, hybrid)",
                chosen.solver.name()
            )));
        };
        solving();
        let choice = lucent::resolution::fewest_directions_meeting(
            &built.problem,
            &family,
            target,
            &options,
        )?;
        writeln!(
            out,
            "{name}: `{}` to a relative angular error of {}",
            chosen.solver.name(),
            S(target)
        )
        .map_err(io_err)?;
        for (i, level) in choice.levels.iter().enumerate() {
            writeln!(
                out,
                "  {} directions ({}): estimated error {}, solved in {} s{}",
                level.directions,
                level.setting,
                S(level.estimated_error),
                S(level.seconds),
                if i == choice.chosen {
                    "  <- chosen"
                } else {
                    ""
                }
            )
            .map_err(io_err)?;
        }
        writeln!(
            out,
            "  order {} in the angular spacing ({})",
            S(choice.order),
            order_source(choice.observed)
        )
        .map_err(io_err)?;
        let level = &choice.levels[choice.chosen];
        return if choice.met {
            writeln!(out, "chosen: {} directions meet it", level.directions).map_err(io_err)
        } else {
            writeln!(
                out,
                "not met: even {} directions are estimated at {}",
                level.directions,
                S(level.estimated_error)
            )
            .map_err(io_err)
        };
    }
    solving();
    let choice = lucent::resolution::coarsest_meeting(
        &built.problem,
        chosen.solver.as_ref(),
        target,
        &options,
    )?;
    writeln!(
        out,
        "{name}: `{}` to a relative error of {}",
        chosen.solver.name(),
        S(target)
    )
    .map_err(io_err)?;
    for (i, level) in choice.levels.iter().enumerate() {
        let [nx, ny, nz] = level.dims;
        writeln!(
            out,
            "  {nx} × {ny} × {nz} cells ({}× coarser): estimated error {}, solved in {} s{}",
            level.coarsening,
            S(level.estimated_error),
            S(level.seconds),
            if i == choice.chosen {
                "  <- chosen"
            } else {
                ""
            }
        )
        .map_err(io_err)?;
    }
    writeln!(
        out,
        "  order {} ({})",
        S(choice.order),
        order_source(choice.observed)
    )
    .map_err(io_err)?;
    match choice.needed_refinement(target) {
        None => {
            let [nx, ny, nz] = choice.levels[choice.chosen].dims;
            writeln!(out, "chosen: {nx} × {ny} × {nz} cells meet it").map_err(io_err)?;
        }
        Some(factor) => writeln!(
            out,
            "not met: the scene's grid would need about {}× as many cells per axis",
            S(factor)
        )
        .map_err(io_err)?,
    }
    Ok(())
}

/// Transport mean free paths from the box, void and the lights beyond which a region
/// counts as deep: diffusion's boundary layer (Milne's problem, an extrapolation length of
/// 0.71 ℓ′) and its error near a source decay within one or two ℓ′.
const DEEP_MFP: f64 = 3.0;

/// One line of `lucent info` on the regime of channel `c`, from
/// [`lucent::core::regime::Regime`] over regions of at least 8³ cells (at most 32 per
/// axis, so the line costs little beside loading the scene).
fn regime_line(problem: &lucent::core::Problem, c: usize) -> String {
    use lucent::core::regime::Regime;
    let largest = problem.geometry().dims().into_iter().max().unwrap_or(1);
    let regime = Regime::of(problem, c, largest.div_ceil(32).max(8));
    let summary = regime.summary();
    let medium: Vec<_> = regime
        .regions
        .iter()
        .filter(|r| r.empty_fraction < 1.0)
        .collect();
    let deep = medium
        .iter()
        .filter(|r| r.boundary_mfp >= DEEP_MFP && r.source_mfp >= DEEP_MFP)
        .count();
    format!(
        "reduced albedo {} (g {}), regions up to {} transport mean free paths across, on average {} from the box or void, the light {} extinction lengths deep at the most shaded; {}% of the medium's regions at least {} from the box, void and the lights; {}% of all cells void",
        S(summary.reduced_albedo),
        S(regime.g),
        S(summary.thickness_mfp),
        S(summary.boundary_mfp),
        S(medium.iter().map(|r| r.light_depth).fold(0.0, f64::max)),
        S(100.0 * deep as f64 / medium.len().max(1) as f64),
        S(DEEP_MFP),
        S(100.0 * summary.empty_fraction),
    )
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
