//! `cargo xtask bench-explicit [N]`: one step of each explicit scheme at N³ (128 by
//! default), best of 5: cell (or cell-direction) updates per second and GB/s by each
//! scheme's minimal traffic, beside the copy bandwidth measured in the same run; and Zhang
//! & Ma's full update for one light (absorption to steady state + one scattering step).

use glam::DVec3;
use lucent::core::Stopping;
use lucent::explicit::Lattice;
use lucent::explicit::convection::{Light, Model, UpwindSettings, propagate};
use lucent::explicit::ftcs::{Edges, FtcsDiffusion, GradientSign, March};
use lucent::explicit::ordinates::{OrdinatesSettings, march as ordinates};
use lucent::explicit::p1::{Damping, Layout, P1Edges, P1Settings, march as p1};
use lucent::explicit::scatter::Scatterer;

use crate::bench_diffusion::{best_of, copy_bandwidth};

/// What a timed run must have done, checked after the timing: `ran(name, steps, expected,
/// result)` refuses a run that failed or stopped short, so a figure never times a refusal
/// (an earlier version timed P1's refusal of an unstable step as if it were 5 steps).
fn ran<T, E: std::fmt::Display>(
    name: &str,
    result: Result<T, E>,
    steps: impl Fn(&T) -> usize,
    expected: usize,
) -> Result<(), String> {
    match result {
        Ok(out) if steps(&out) == expected => Ok(()),
        Ok(out) => Err(format!(
            "{name}: ran {} steps, not {expected}: the figure would not be a step's",
            steps(&out)
        )),
        Err(e) => Err(format!("{name}: {e}")),
    }
}

fn line(name: &str, seconds: f64, updates: f64, bytes_per_update: f64, copy: f64) {
    let gbs = updates * bytes_per_update / seconds / 1e9;
    println!(
        "| {name} | {:.1} ms | {:.0} M/s | {bytes_per_update:.0} | {gbs:.1} | {:.0}% |",
        seconds * 1e3,
        updates / seconds / 1e6,
        100.0 * gbs * 1e9 / copy
    );
}

/// Runs the benchmark.
pub(crate) fn run(n: usize) -> Result<(), String> {
    let err = |e: &dyn std::fmt::Display| e.to_string();
    let lattice = Lattice::new([n; 3], 1.0).map_err(|e| err(&e))?;
    let cells = lattice.len();
    let (serial, parallel) = copy_bandwidth();
    println!(
        "# cargo xtask bench-explicit ({n}³, {} threads)",
        rayon::current_num_threads()
    );
    println!();
    println!(
        "copy bandwidth (256 MiB f32, read + write): {:.1} GB/s on all threads, {:.1} on one",
        parallel / 1e9,
        serial / 1e9
    );
    println!();
    println!("| step | time | updates/s | bytes/update | GB/s | of copy |");
    println!("|---|---|---|---|---|---|");
    // FTCS diffusion: φ read (and neighbours from cache), D, σ_a, q read, φ′ written (f64).
    let d = vec![0.2; cells];
    let sa = vec![0.01; cells];
    let q = vec![0.0; cells];
    let problem = FtcsDiffusion {
        lattice,
        diffusion: &d,
        absorption: &sa,
        source: &q,
        sign: GradientSign::Conservative,
        edges: Edges::Periodic,
    };
    let initial: Vec<f64> = (0..cells).map(|i| (i % 13) as f64).collect();
    let march = March {
        time_step: 0.5 * problem.time_step_limit(),
        stopping: Stopping {
            relative_tolerance: 0.0,
            max_iterations: 10,
            ..Stopping::default()
        },
        allow_unstable: false,
        initial: Some(initial.clone()),
    };
    let mut check = Ok(());
    let t = best_of(5, || {
        check = ran("ftcs-diffusion", problem.march(&march), |o| o.steps, 10);
    }) / 10.0;
    check?;
    line(
        "ftcs-diffusion, per step of 10 (residual included)",
        t,
        cells as f64,
        40.0,
        parallel,
    );
    // P1 (staggered): φ and 3 E read and written, q read; 0.9 of the stable step (with
    // Murray's damping σ_t damps both φ and E). The initial state is copied before each
    // run's clock starts (the march's own next fields, allocated and first touched, are
    // inside it: what a caller pays).
    let sigma_t = 0.1;
    let stable = lucent::explicit::stability::p1::largest_step(true, sigma_t, sigma_t, 1.0);
    let settings = P1Settings {
        layout: Layout::Staggered,
        damping: Damping::Murray { sigma_t },
        time_step: 0.9 * stable,
        stopping: Stopping {
            relative_tolerance: 0.0,
            max_iterations: 10,
            ..Stopping::default()
        },
        edges: P1Edges::Periodic,
        allow_unstable: false,
    };
    let start = (
        initial.clone(),
        [initial.clone(), initial.clone(), initial.clone()],
    );
    let mut best = f64::INFINITY;
    for _ in 0..5 {
        let state = start.clone();
        let clock = std::time::Instant::now();
        let out = p1(&lattice, &q, &settings, Some(state));
        best = best.min(clock.elapsed().as_secs_f64());
        ran("ftcs-p1", out, |o| o.steps, 10)?;
    }
    let t = best / 10.0;
    line(
        "ftcs-p1 staggered, per step of 10",
        t,
        cells as f64,
        72.0,
        parallel,
    );
    // Ordinates, S4 (24 directions): L read and written per cell-direction.
    let quadrature =
        lucent::optics::SphericalQuadrature::level_symmetric(4).map_err(|e| err(&e))?;
    let m = quadrature.len();
    let st = vec![0.1; cells];
    let ss = vec![0.05; cells];
    let mut source = vec![0.0; cells];
    source[cells / 2] = 1.0;
    let settings = OrdinatesSettings {
        time_step: 0.3,
        stopping: Stopping {
            relative_tolerance: 0.0,
            max_iterations: 3,
            ..Stopping::default()
        },
        allow_unstable: false,
    };
    let mut check = Ok(());
    let t = best_of(3, || {
        let out = ordinates(&lattice, &quadrature, &st, &ss, &source, &settings);
        check = ran("ftcs-ordinates", out, |o| o.steps, 3);
    }) / 3.0;
    check?;
    line(
        "ftcs-ordinates S4, per step of 3 (cell-direction updates)",
        t,
        (cells * m) as f64,
        16.0,
        parallel,
    );
    // Zhang & Ma: one light, absorption to steady state (ordered sweep: exact in one pass).
    let absorption: Vec<f64> = (0..cells)
        .map(|c| if (c / 97) % 5 == 0 { 0.05 } else { 0.0 })
        .collect();
    let light = Light::Distant {
        direction: DVec3::new(0.4, -0.3, 1.0).normalize(),
        density: 1.0,
    };
    let mut rho = Vec::new();
    let mut check = Ok(());
    let t_abs = best_of(5, || {
        match propagate(&lattice, &absorption, &light, &UpwindSettings::default()) {
            Ok(out) if out.stop_reason.is_converged() => rho = out.density,
            Ok(out) => check = Err(format!("zhang-ma absorption: {}", out.stop_reason)),
            Err(e) => check = Err(format!("zhang-ma absorption: {e}")),
        }
    });
    check?;
    line(
        "zhang-ma absorption, one light to steady state",
        t_abs,
        cells as f64,
        24.0,
        parallel,
    );
    // The characteristic model (the registry's default): the exact attenuation along
    // short characteristics, one pass plane by plane.
    let characteristic = UpwindSettings {
        model: Model::Characteristic,
        ..UpwindSettings::default()
    };
    let mut check = Ok(());
    let t_char = best_of(5, || {
        let out = propagate(&lattice, &absorption, &light, &characteristic);
        // One pass, plane by plane.
        check = ran("zhang-ma characteristic", out, |o| o.iterations, 1);
    });
    check?;
    line(
        "zhang-ma absorption, characteristic model (the registry's default)",
        t_char,
        cells as f64,
        24.0,
        parallel,
    );
    let scatterer = Scatterer::new(&lattice, 1.0).map_err(|e| err(&e))?;
    let mut cycles = Ok(0);
    let t_sc = best_of(5, || {
        cycles = scatterer
            .step(&rho, 1e-4)
            .map(|(_, c, _)| c)
            .map_err(|e| format!("zhang-ma scattering step: {e}"));
    });
    let cycles = cycles?;
    println!(
        "| zhang-ma scattering step (a = 1, multigrid to 1e-4, {cycles} cycles; hierarchy kept) | {:.1} ms | | | | |",
        t_sc * 1e3
    );
    println!(
        "| **zhang-ma full update, one light** | **{:.1} ms** | | | | |",
        (t_abs + t_sc) * 1e3
    );
    Ok(())
}
