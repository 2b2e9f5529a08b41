//! Ctrl-C and the time limit stop every solve within a second, whatever it is doing: set-up
//! (the uncollided light, a hierarchy, an assembly), a sweep, a batch, a paged pass, a
//! device submission. Measured from the signal (the cancel flag set from another thread,
//! or the time budget running out) to the solver's return, on problems sized so that the
//! solve would run ten seconds or more, with the signal sent early (in set-up, 0.2 s after
//! the start) and late (in the iteration: 0.15 s after the solve first reports one, the
//! time limit set from when an earlier run of the same solve did, so that no case waits a
//! fixed second for an iteration that began in a tenth of one).
//!
//! The bound is 1 s of wall time on a loaded 2-core CI machine: every loop that can run
//! for more than ~0.1 s at these sizes checks the signal, so the time to stop is a few of
//! those (the slowest thread's current piece of work, then the write-back of what was
//! computed).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, OnceLock, PoisonError};
use std::time::{Duration, Instant};

use glam::DVec3;
use lucent::core::{
    Boundary, Field, Light, Medium, ParamValue, Params, Problem, SolveError, SolveOptions,
    Spectrum, StopReason,
};
use lucent::grid::{Grid, GridGeometry};
use lucent::optics::Phase;

/// The longest a solve may take to stop after the signal.
const WITHIN: Duration = Duration::from_secs(1);

/// What lights a test problem carries.
#[derive(Clone, Copy, PartialEq)]
enum Lit {
    /// A sun and a point light inside: the uncollided light is set-up work (seconds at
    /// these sizes), so an early signal lands in it.
    Set,
    /// Volume emission only (a point light inside for the solvers that take only point
    /// lights): no uncollided light, the solve goes straight to its iteration, so a late
    /// signal lands in an iteration.
    Iterate,
}

fn point_only(name: &str) -> bool {
    matches!(
        name,
        "ftcs-p1" | "gpu-ftcs-p1" | "ftcs-ordinates" | "fem-p1-jacobi"
    )
}

/// A cloud-like medium on a grid of about `n`³ cubic cells whose sides are no multiple of
/// 8.
fn problem(name: &str, n: usize, lit: Lit) -> Problem {
    let dims = [n + 1, n, n - 1];
    let h = 2.0 / n as f64;
    let geometry = GridGeometry::new(dims, DVec3::splat(h), DVec3::splat(-1.0)).unwrap();
    let sigma_t = if point_only(name) {
        Grid::filled(geometry, 8.0)
    } else {
        Grid::from_fn(geometry, |x| {
            (2.0 + 30.0 * (-3.0 * x.length_squared()).exp()) as f32
        })
    };
    let albedo = if name.ends_with("fem-p1-jacobi") {
        0.0
    } else {
        0.95
    };
    let medium = Medium {
        sigma_t: vec![sigma_t],
        albedo: vec![Field::Constant(albedo)],
        phase: Phase::Isotropic,
    };
    let point = Light::Point {
        position: DVec3::new(0.05, -0.04, 0.03),
        intensity: Spectrum::Grey(1.0),
    };
    let lights = match lit {
        _ if point_only(name) => vec![point],
        Lit::Set => vec![
            Light::Directional {
                direction: DVec3::new(-0.3, -0.4, -0.8).normalize(),
                irradiance: Spectrum::Grey(1.0),
            },
            point,
        ],
        Lit::Iterate if matches!(name, "direct" | "direct-refractive" | "gpu-direct") => {
            vec![point]
        }
        Lit::Iterate => vec![Light::Emission {
            grid: Grid::from_fn(geometry, |x| (-4.0 * x.length_squared()).exp() as f32),
            scale: Spectrum::Grey(1.0),
        }],
    };
    Problem::new(geometry, medium, lights, Boundary::Vacuum, None).unwrap()
}

/// The grid side and parameters at which `name` would run ten seconds or more on 2 cores
/// (the iterative solvers never stop: their tolerance is 0).
fn sized(name: &str, lit: Lit) -> (usize, Params) {
    let mut p = Params::default();
    let mut set = |k: &str, v: ParamValue| {
        p.0.insert(k.into(), v);
    };
    let n = match (name.trim_start_matches("gpu-"), lit) {
        ("direct", _) => 160,
        ("direct-refractive", _) => 96,
        ("mc", _) => {
            set("particles", ParamValue::Int(1 << 40));
            set("batches", ParamValue::Int(4));
            48
        }
        // The first Galerkin product of the finite elements' hierarchy cannot be stopped
        // part way: at this size it takes a fraction of a second.
        ("fem-diffusion", _) => 64,
        // The march converges in a few passes (its own tolerance): a grid whose passes
        // take seconds.
        ("convection-diffusion", _) => 144,
        ("fem-p1-jacobi", _) => {
            // Murray's Jacobi diverges on this system (ρ ≥ 19/8) before a late signal.
            set("solver", ParamValue::Text("gmres".into()));
            24
        }
        ("auto", _) => {
            set("tolerance", ParamValue::Float(0.001));
            80
        }
        (_, Lit::Set) => 96,
        (_, Lit::Iterate) => 64,
    };
    (n, p)
}

/// How a stopped solve ended, and how long after the signal.
struct Stopped {
    after_signal: Duration,
    outcome: Result<StopReason, SolveError>,
    /// When the solve first reported an iteration (counted from its start), if it did
    /// before the signal.
    iterating_at: Option<Duration>,
}

/// When to send the signal.
#[derive(Clone, Copy, Debug)]
enum At {
    /// This long after the start (early: inside the set-up of a problem whose set-up takes
    /// seconds).
    After(Duration),
    /// In the iteration: [`SETTLE`] after the solve's first progress report of an
    /// iteration (by Ctrl-C), or at a time budget of `iterating + SETTLE` where `iterating`
    /// is when an earlier run of the same solve first reported one; [`LATE`] after the
    /// start where neither is known (a solver that reports no iterations).
    Iterating(Option<Duration>),
}

/// How long after the first report of an iteration a late signal comes: the solve is then
/// inside its second iteration or later, in the loops that ask the signal most often.
const SETTLE: Duration = Duration::from_millis(150);

/// The late signal of a solve that reports no iteration.
const LATE: Duration = Duration::from_millis(1000);

/// The early signal, inside the set-up of a problem lit by a sun and a point light (the
/// uncollided light takes seconds at these sizes).
const EARLY: Duration = Duration::from_millis(200);

impl At {
    /// The late signal of a solve whose earlier run (`previous`) first reported an
    /// iteration when it did.
    fn after(previous: &Stopped) -> At {
        At::Iterating(previous.iterating_at)
    }
}

/// The machine's cores, shared out among the timed solves of the tests running side by
/// side.
struct Cores(usize);

impl Cores {
    fn state() -> &'static (Mutex<usize>, Condvar) {
        static FREE: OnceLock<(Mutex<usize>, Condvar)> = OnceLock::new();
        FREE.get_or_init(|| (Mutex::new(Self::all()), Condvar::new()))
    }

    /// At least two: a solve of two threads must be able to run.
    fn all() -> usize {
        std::thread::available_parallelism().map_or(2, |n| n.get().max(2))
    }

    /// Waits until `threads` cores (at most all of them) are free, and holds them.
    fn take(threads: usize) -> Cores {
        let wanted = threads.clamp(1, Self::all());
        let (free, freed) = Self::state();
        let mut free = free.lock().unwrap_or_else(PoisonError::into_inner);
        while *free < wanted {
            free = freed.wait(free).unwrap_or_else(PoisonError::into_inner);
        }
        *free -= wanted;
        Cores(wanted)
    }
}

impl Drop for Cores {
    fn drop(&mut self) {
        let (free, freed) = Self::state();
        *free.lock().unwrap_or_else(PoisonError::into_inner) += self.0;
        freed.notify_all();
    }
}

/// Runs `solve` on a pool of `threads` with `options` carrying a fresh cancel flag, and
/// sends the signal `at`: the flag (`time_limit` false) or the time budget running out.
fn stop_with(
    at: At,
    time_limit: bool,
    threads: usize,
    options: SolveOptions,
    solve: impl FnOnce(&SolveOptions) -> Result<StopReason, SolveError> + Send,
) -> Stopped {
    // The tests of this file run side by side: a timed solve holds its threads' worth of
    // cores, so that none shares a core with another's work and measures it.
    let _cores = Cores::take(threads);
    let cancel = Arc::new(AtomicBool::new(false));
    // The first report of an iteration, in nanoseconds from the start (0: none yet).
    let iterating = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let started = Instant::now();
    let report = {
        let iterating = iterating.clone();
        let user = options.progress.clone();
        move |p: lucent::core::Progress| {
            if p.iteration >= 1 {
                let now = started.elapsed().as_nanos().max(1) as u64;
                let _ = iterating.compare_exchange(0, now, Ordering::Relaxed, Ordering::Relaxed);
            }
            if let Some(user) = &user {
                user(p);
            }
        }
    };
    let budget = match at {
        At::After(t) => t,
        At::Iterating(Some(t)) => t + SETTLE,
        At::Iterating(None) => LATE,
    };
    let options = SolveOptions {
        relative_tolerance: 0.0,
        max_iterations: usize::MAX / 2,
        time_budget: time_limit.then_some(budget),
        cancel: Some(cancel.clone()),
        progress: Some(Arc::new(report)),
        // A pool of its own: the tests run side by side, and a solve queued behind
        // another test's work in rayon's global pool would be slow to stop for no fault
        // of its own.
        threads: Some(threads),
        ..options
    };
    let iterating_at = || match iterating.load(Ordering::Relaxed) {
        0 => None,
        t => Some(Duration::from_nanos(t)),
    };
    let (outcome, signalled) = std::thread::scope(|s| {
        let solve = s.spawn(|| solve(&options));
        let mut signalled = started + budget;
        if !time_limit {
            loop {
                if solve.is_finished() {
                    break;
                }
                if let (At::Iterating(_), Some(t)) = (at, iterating_at()) {
                    signalled = signalled.min(started + t + SETTLE);
                }
                if Instant::now() >= signalled {
                    break;
                }
                std::thread::sleep(Duration::from_millis(2));
            }
            signalled = signalled.min(Instant::now());
            cancel.store(true, Ordering::Relaxed);
        }
        (solve.join().unwrap(), signalled)
    });
    let after_signal = Instant::now().saturating_duration_since(signalled);
    Stopped {
        after_signal,
        outcome,
        iterating_at: iterating_at().filter(|&t| started + t <= signalled),
    }
}

/// `name` in memory on its sized problem.
fn stop(name: &str, lit: Lit, at: At, time_limit: bool) -> Stopped {
    let (n, params) = sized(name, lit);
    let solver = lucent::registry().build(name, &params).unwrap();
    let mut problem = problem(name, n, lit);
    if solver.admits(&problem).is_err() {
        // No emission (`convection-diffusion`): a point light inside, its own source.
        problem = Problem::new(
            *problem.geometry(),
            problem.medium().clone(),
            vec![Light::Point {
                position: DVec3::new(0.05, -0.04, 0.03),
                intensity: Spectrum::Grey(1.0),
            }],
            Boundary::Vacuum,
            None,
        )
        .unwrap();
    }
    // One thread: two in-memory solves run side by side, each on a core of its own (the
    // slowest case for stopping: one thread finishes its current piece of work alone).
    stop_with(at, time_limit, 1, SolveOptions::default(), |options| {
        solver
            .solve(&problem, options)
            .map(|s| s.report.stop_reason)
    })
}

/// The signal stopped the solve within [`WITHIN`], and the way it says so: a stop reason
/// naming the signal (what was computed comes back), or [`SolveError::Halted`] (stopped
/// before any result existed). A solve that finished first is a test that proves nothing.
fn assert_stopped(what: &str, s: &Stopped, time_limit: bool) {
    assert!(
        s.after_signal <= WITHIN,
        "{what}: stopped {:.3} s after the signal: {:?}",
        s.after_signal.as_secs_f64(),
        s.outcome
    );
    let by_signal = match &s.outcome {
        Ok(StopReason::Interrupted { .. }) => !time_limit,
        Ok(StopReason::TimeLimit { .. }) => time_limit,
        Err(SolveError::Halted { halt, .. }) => {
            *halt
                == if time_limit {
                    lucent::core::Halt::TimeLimit
                } else {
                    lucent::core::Halt::Interrupted
                }
        }
        _ => false,
    };
    assert!(
        by_signal,
        "{what}: {:?}",
        s.outcome.as_ref().map_err(|e| e.to_string())
    );
}

/// Every phase of `name` in memory: Ctrl-C early (in set-up: the uncollided light, a
/// hierarchy, the first batches), the time limit late (in the iteration), Ctrl-C late.
/// (`auto` runs the solver it chooses, whose own test covers its iteration; its set-up,
/// the regime and the choice, is tested here.)
fn in_memory(name: &str) {
    let case = |phase: &str, lit, at, limit| {
        let what = format!("{name}, {phase}");
        let stopped = stop(name, lit, at, limit);
        assert_stopped(&what, &stopped, limit);
        stopped
    };
    case("Ctrl-C in set-up", Lit::Set, At::After(EARLY), false);
    case("time limit in set-up", Lit::Set, At::After(EARLY), true);
    if name != "auto" {
        let ctrl_c = case("Ctrl-C iterating", Lit::Iterate, At::Iterating(None), false);
        case(
            "time limit iterating",
            Lit::Iterate,
            At::after(&ctrl_c),
            true,
        );
    }
}

macro_rules! in_memory_tests {
    ($($test:ident: $name:literal,)*) => {
        $(
            #[test]
            fn $test() {
                in_memory($name);
            }
        )*
    };
}

in_memory_tests! {
    direct_stops_in_memory: "direct",
    direct_refractive_stops_in_memory: "direct-refractive",
    mc_stops_in_memory: "mc",
    diffusion_mg_stops_in_memory: "diffusion-mg",
    diffusion_mgcg_stops_in_memory: "diffusion-mgcg",
    diffusion_cg_stops_in_memory: "diffusion-cg",
    diffusion_sor_stops_in_memory: "diffusion-sor",
    diffusion_jacobi_stops_in_memory: "diffusion-jacobi",
    ftcs_diffusion_stops_in_memory: "ftcs-diffusion",
    jacobi_diffusion_stops_in_memory: "jacobi-diffusion",
    convection_diffusion_stops_in_memory: "convection-diffusion",
    ftcs_p1_stops_in_memory: "ftcs-p1",
    ftcs_ordinates_stops_in_memory: "ftcs-ordinates",
    fem_p1_jacobi_stops_in_memory: "fem-p1-jacobi",
    fem_diffusion_stops_in_memory: "fem-diffusion",
    dom_stops_in_memory: "dom",
    lbm_stops_in_memory: "lbm",
    hybrid_stops_in_memory: "hybrid",
    auto_stops_in_memory: "auto",
}

/// Every registered solver is in the list above (or is a device twin, tested below).
#[test]
fn every_cpu_solver_has_its_stop_test() {
    let source = include_str!("stops.rs");
    for entry in lucent::registry().entries() {
        if entry.name.starts_with("gpu-") {
            continue;
        }
        assert!(
            source.contains(&format!("_stops_in_memory: \"{}\"", entry.name)),
            "{} has no stop test",
            entry.name
        );
    }
}
/// Every CPU solver, for the survey.
fn cpu_solvers() -> Vec<String> {
    lucent::registry()
        .entries()
        .iter()
        .map(|e| e.name.to_owned())
        .filter(|n| !n.starts_with("gpu-"))
        .collect()
}

/// `LUCENT_STOP_SURVEY=1 cargo test --test stops survey -- --nocapture`: the time each
/// solver takes to stop, early and late, by Ctrl-C and by the time limit.
#[test]
fn survey() {
    if std::env::var_os("LUCENT_STOP_SURVEY").is_none() {
        return;
    }
    let only = std::env::var("LUCENT_STOP_ONLY").ok();
    for name in cpu_solvers() {
        if only
            .as_deref()
            .is_some_and(|o| !o.split(',').any(|x| x == name))
        {
            continue;
        }
        let times: Vec<f64> = std::env::var("LUCENT_STOP_AT")
            .ok()
            .map(|t| t.split(',').filter_map(|x| x.parse().ok()).collect())
            .unwrap_or_else(|| vec![0.2, 2.0]);
        for (at, limit) in times.iter().flat_map(|&t| [(t, false), (t, true)]) {
            let lit = if at < 1.0 { Lit::Set } else { Lit::Iterate };
            let s = stop(&name, lit, At::After(Duration::from_secs_f64(at)), limit);
            eprintln!(
                "{name:<22} {} at {at:>4} s: stopped {:>7.3} s after the signal: {:?}",
                if limit { "time limit" } else { "ctrl-c    " },
                s.after_signal.as_secs_f64(),
                s.outcome
                    .map(|r| format!("{r:?}"))
                    .map_err(|e| e.to_string())
            );
        }
    }
}

/// A procedural cloud (or, for `Lit::Iterate`, a point light inside a homogeneous
/// medium) as a scene file gives it, on a grid of about `n`³ cubic cells.
fn scene(n: usize, lit: Lit) -> lucent::scene::Scene {
    let h = 2.0 / n as f64;
    let (x, y, z) = ((n + 1) as f64 * h, n as f64 * h, (n - 1) as f64 * h);
    let lights = match lit {
        Lit::Set => {
            "[[lights]]\nkind = \"directional\"\ndirection = [-0.3, -0.4, -0.86]\nirradiance = 1.0\n[[lights]]\nkind = \"point\"\nposition = [1.05, 0.96, 1.03]\nintensity = 1.0\n"
        }
        Lit::Iterate => {
            "[[lights]]\nkind = \"point\"\nposition = [1.05, 0.96, 1.03]\nintensity = 1.0\n"
        }
    };
    let volume = match lit {
        Lit::Set => "kind = \"cloud\"\nseed = 3\nthreshold = 0.2",
        Lit::Iterate => {
            "kind = \"shape\"\nshape = { type = \"box\", min = [-1.0, -1.0, -1.0], max = [9.0, 9.0, 9.0] }"
        }
    };
    let text = format!(
        "[volume]\n{volume}\nresolution = [{}, {n}, {}]\nbounds = [[0, 0, 0], [{x}, {y}, {z}]]\n[medium]\ndensity = 20.0\nalbedo = 0.95\n{lights}[camera]\nkind = \"pinhole\"\nposition = [5, 1, 1]\nlook_at = [1, 1, 1]\n",
        n + 1,
        n - 1
    );
    lucent::scene::Scene::parse(&text, std::path::Path::new("stops.toml")).unwrap()
}

/// `name` out of core: the medium paged under a budget of an eighth of its dense fields.
fn stop_paged(name: &str, n: usize, lit: Lit, at: At, time_limit: bool) -> Stopped {
    let solver = lucent::registry().build(name, &Params::default()).unwrap();
    let scene = scene(n, lit);
    let options = SolveOptions {
        memory_budget: 64 << 20,
        ..SolveOptions::default()
    };
    let problem = scene.build_paged_for(solver.as_ref(), &options).unwrap();
    stop_with(at, time_limit, 2, options, |options| {
        solver
            .solve_paged(&problem, options)
            .map(|s| s.report.stop_reason)
    })
}

/// Every solver that pages, out of core: Ctrl-C and the time limit in set-up (the paged
/// uncollided light and first collisions, the first batches) and in the iteration (a
/// paged pass).
#[test]
fn every_paging_solver_stops_out_of_core() {
    let registry = lucent::registry();
    let mut tested = 0;
    for entry in registry.entries() {
        let solver = registry.build(entry.name, &Params::default()).unwrap();
        if !solver.pages() {
            continue;
        }
        let name = entry.name;
        // What each takes out of core: `convection-diffusion` distant lights only, the
        // moment schemes a point light inside only.
        let (set_up, iterates) = match name {
            "direct" => (Lit::Set, None),
            "mc" => (Lit::Set, None),
            "convection-diffusion" => (Lit::Set, None),
            "ftcs-p1" | "ftcs-ordinates" => (Lit::Iterate, Some(Lit::Iterate)),
            _ => (Lit::Set, Some(Lit::Iterate)),
        };
        let n = match name {
            "direct" | "convection-diffusion" => 128,
            "mc" => 64,
            _ => 96,
        };
        for (phase, lit, at) in [
            ("set-up", Some(set_up), At::After(EARLY)),
            ("iteration", iterates, At::Iterating(None)),
        ] {
            let Some(lit) = lit else { continue };
            // Ctrl-C first: the time limit's late signal follows its first iteration.
            let mut at = at;
            for limit in [false, true] {
                let what = format!(
                    "{name} out of core, {} in {phase}",
                    if limit { "time limit" } else { "Ctrl-C" }
                );
                let stopped = if name == "convection-diffusion" {
                    // Distant lights only: the sun of the cloud, without the point light.
                    stop_paged_sun_only(name, n, at, limit)
                } else {
                    stop_paged(name, n, lit, at, limit)
                };
                if let At::Iterating(_) = at {
                    at = At::after(&stopped);
                }
                assert_stopped(&what, &stopped, limit);
            }
        }
        tested += 1;
    }
    assert!(tested >= 7, "{tested} solvers page");
}

/// [`stop_paged`] on the cloud lit by its sun alone.
fn stop_paged_sun_only(name: &str, n: usize, at: At, time_limit: bool) -> Stopped {
    let solver = lucent::registry().build(name, &Params::default()).unwrap();
    let mut scene = scene(n, Lit::Set);
    scene.lights.truncate(1);
    let options = SolveOptions {
        memory_budget: 64 << 20,
        ..SolveOptions::default()
    };
    let problem = scene.build_paged_for(solver.as_ref(), &options).unwrap();
    stop_with(at, time_limit, 2, options, |options| {
        solver
            .solve_paged(&problem, options)
            .map(|s| s.report.stop_reason)
    })
}

/// The solvers that split over ranks, on two in-process ranks: any rank's signal stops
/// every rank (the flags travel with the norms), in set-up and in the iteration.
#[test]
fn every_ranked_solver_stops_on_two_ranks() {
    // `convection-diffusion` splits its one-pass absorption march over ranks, which runs
    // its pass to the end (the ranks go in lock step; no flag is reduced inside a pass):
    // docs/reliability.md lists it among the steps that can take longer.
    for name in [
        "diffusion-mg",
        "ftcs-diffusion",
        "jacobi-diffusion",
        "ftcs-p1",
    ] {
        let (n, _) = sized(name, Lit::Iterate);
        let mut params = Params::default();
        params.0.insert("ranks".into(), ParamValue::Int(2));
        let solver = lucent::registry().build(name, &params).unwrap();
        for (phase, lit, at) in [
            ("set-up", Lit::Set, At::After(EARLY)),
            ("iteration", Lit::Iterate, At::Iterating(None)),
        ] {
            let mut problem = problem(name, n, lit);
            if solver.admits(&problem).is_err() {
                problem = problem_with_point(&problem);
            }
            // Ctrl-C first: the time limit's late signal follows its first iteration.
            let mut at = at;
            for limit in [false, true] {
                let what = format!(
                    "{name} on 2 ranks, {} in {phase}",
                    if limit { "time limit" } else { "Ctrl-C" }
                );
                let stopped = stop_with(at, limit, 2, SolveOptions::default(), |options| {
                    solver
                        .solve(&problem, options)
                        .map(|s| s.report.stop_reason)
                });
                if let At::Iterating(_) = at {
                    at = At::after(&stopped);
                }
                // The march of a sun is one pass: over before a late signal.
                if stopped.after_signal.is_zero()
                    && matches!(stopped.outcome, Ok(ref r) if r.is_converged())
                {
                    continue;
                }
                assert_stopped(&what, &stopped, limit);
            }
        }
    }
}

/// `problem` lit by a point light inside instead.
fn problem_with_point(problem: &Problem) -> Problem {
    Problem::new(
        *problem.geometry(),
        problem.medium().clone(),
        vec![Light::Point {
            position: DVec3::new(0.05, -0.04, 0.03),
            intensity: Spectrum::Grey(1.0),
        }],
        Boundary::Vacuum,
        None,
    )
    .unwrap()
}

/// The device twins (on lavapipe in CI): a submission cannot be interrupted, so batches
/// are sized to a quarter of a second of device time and the signal is asked between
/// them. Skipped where no adapter exists outside CI.
#[test]
fn every_device_solver_stops() {
    let ci = std::env::var("CI").is_ok_and(|v| v == "true" || v == "1");
    if !ci && lucent::gpu::GpuContext::shared().is_err() {
        eprintln!("skipped: no GPU adapter");
        return;
    }
    for entry in lucent::registry().entries() {
        let name = entry.name;
        if !name.starts_with("gpu-") {
            continue;
        }
        let solver = lucent::registry().build(name, &Params::default()).unwrap();
        // One device transport of `gpu-dom` is one submission that cannot be stopped part
        // way (14 s at 64³ on lavapipe): a grid where it takes a fraction of a second.
        let n = if name == "gpu-dom" { 20 } else { 64 };
        for (phase, lit, at) in [
            ("set-up", Lit::Set, At::After(EARLY)),
            ("iteration", Lit::Iterate, At::Iterating(None)),
        ] {
            let mut problem = problem(name, n, lit);
            if solver.admits(&problem).is_err() {
                problem = problem_with_point(&problem);
            }
            if solver.admits(&problem).is_err() {
                continue;
            }
            // Ctrl-C first: the time limit's late signal follows its first iteration.
            let mut at = at;
            for limit in [false, true] {
                let what = format!(
                    "{name}, {} in {phase}",
                    if limit { "time limit" } else { "Ctrl-C" }
                );
                let stopped = stop_with(at, limit, 2, SolveOptions::default(), |options| {
                    solver
                        .solve(&problem, options)
                        .map(|s| s.report.stop_reason)
                });
                if let At::Iterating(_) = at {
                    at = At::after(&stopped);
                }
                // A device solve that finished before the signal proves nothing here but
                // is no failure: lavapipe's speed varies with the machine.
                if matches!(stopped.outcome, Ok(ref r) if r.is_converged()) {
                    continue;
                }
                assert_stopped(&what, &stopped, limit);
            }
        }
    }
}
