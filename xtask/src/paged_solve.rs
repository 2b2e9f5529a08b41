//! `cargo xtask paged-solve [SOLVER] [N] [BUDGET_MIB] [BRICK]`: SOLVER (`direct`, the
//! default, `convection-diffusion`, `mc`, or the steady `ftcs-diffusion` and
//! `jacobi-diffusion`, stopped after 100 iterations on both paths) on a sparse N³ cloud (default 256; a seeded noise
//! cloud of radius 0.3 in the unit box, mostly empty) lit by a low sun, out of core under a
//! budget of BUDGET_MIB MiB (default 32; the brick pool is
//! what `direct`'s slab buffers and bookkeeping leave of it, bricks of BRICK³ cells,
//! default 16, backed by an unnamed temporary file; the unit box is cut into cubes so
//! `convection-diffusion` takes it),
//! and — where the dense problem fits this machine — in memory: wall time, the peak
//! resident memory the operating system measured for each (`VmHWM`, reset before each),
//! the pager's counters, and whether the fluence (and for `direct` the transmittance) is
//! equal bit for bit. The paged run goes first, so the in-memory run cannot lower its
//! peak. The in-memory run is skipped where its dense fields would not fit this machine.

use std::sync::Arc;
use std::time::Instant;

use glam::DVec3;
use lucent::core::memory::PeakMeter;
use lucent::core::{
    Angular, Boundary, CellMedium, Field, Light, Medium, PagedProblem, Problem, SolveOptions,
    Spectrum,
};
use lucent::paging::{Eviction, FileStore, Pager, PagerOptions};
use lucent_grid::procedural::NoiseCloud;
use lucent_grid::{BrickLayout, GridGeometry};

const DENSITY: f64 = 40.0;

/// Runs it.
pub(crate) fn run(
    solver_name: &str,
    n: usize,
    budget_mib: u64,
    brick: usize,
) -> Result<(), String> {
    let registry = lucent::registry();
    // `mc` takes the bricks as its majorant blocks (as it does on the paged medium), so
    // that both runs trace the same paths; 20 000 particles in 4 batches.
    let mut params = lucent::core::Params::default();
    if solver_name == "mc" {
        for (key, value) in [
            ("majorant_cells", brick as i64),
            ("particles", 20_000),
            ("batches", 4),
        ] {
            params
                .0
                .insert(key.into(), lucent::core::ParamValue::Int(value));
        }
    }
    let solver = registry
        .build(solver_name, &params)
        .map_err(|e| e.to_string())?;
    if !solver.pages() {
        return Err(format!("`{solver_name}` does not run out of core"));
    }
    let geometry = GridGeometry::new([n; 3], DVec3::splat(1.0 / n as f64), DVec3::ZERO)
        .map_err(|e| e.to_string())?;
    let cloud = NoiseCloud::new(11, DVec3::splat(0.5), 0.3);
    let sigma = |p: DVec3| (DENSITY * cloud.density(p)) as f32;
    let albedo = |_: DVec3| 0.9f32;
    let lights = vec![Light::Directional {
        direction: DVec3::new(0.35, 0.2, -0.9).normalize(),
        irradiance: Spectrum::Grey(1.0),
    }];
    let budget = budget_mib << 20;
    let layout = BrickLayout::new(geometry.dims(), brick).map_err(|e| e.to_string())?;
    let dense_bytes = geometry.voxel_count() as u64 * 4;
    // What the solver holds besides the pool: three layers of slabs (`direct`: a light's
    // transmittance, the isotropic fluence and the fluence of one brick layer) and the
    // bookkeeping of six fields; the absorption march also holds its planes (two of ρ and
    // σ_a in f64, one in f32). The pool gets the rest.
    let layer_bytes = (n * n * brick) as u64 * 4;
    let planes = if solver_name == "direct" {
        0
    } else {
        (n * n) as u64 * 36
    };
    let overhead = 3 * layer_bytes + 6 * layout.count() as u64 * 21 + planes;
    // The medium's share of the budget (`mc` keeps half for its tallies' pool).
    let share = solver.paged_medium_budget(budget);
    let pool = share.saturating_sub(overhead + (budget >> 4));
    if pool < 4 * layout.stored_len() as u64 * 4 {
        return Err(format!(
            "a budget of {budget_mib} MiB leaves no pool beside {} MiB of slab buffers: smaller bricks or a larger budget",
            overhead >> 20
        ));
    }
    println!(
        "{solver_name}, {n}³ sparse cloud, one sun; dense f32 fields {} MiB each; budget {budget_mib} MiB, pool {} MiB of {brick}³ bricks (stored {}³)",
        dense_bytes >> 20,
        pool >> 20,
        brick + 2
    );

    // Out of core.
    let meter = PeakMeter::start();
    let start = Instant::now();
    let pager = Arc::new(
        Pager::new(
            Box::new(FileStore::create().map_err(|e| e.to_string())?),
            0,
            layout.stored_len(),
            1,
            PagerOptions {
                budget_bytes: pool,
                eviction: Eviction::Nru,
                fill: 0.0,
            },
        )
        .map_err(|e| e.to_string())?,
    );
    let paged = PagedProblem::from_fn(
        pager.clone(),
        geometry,
        brick,
        CellMedium {
            sigma_t: vec![&sigma],
            albedo: vec![&albedo],
            phase: lucent::optics::Phase::Isotropic,
        },
        lights.clone(),
        Boundary::Vacuum,
    )
    .map_err(|e| e.to_string())?;
    let built = start.elapsed().as_secs_f64();
    let stored = paged.medium().sigma_t[0].stored_bricks();
    // The steady schemes need thousands of sweeps on a cloud with empty space (its D is
    // the floor's): both paths stop after the same 100, which is what is compared.
    let steady = matches!(solver_name, "ftcs-diffusion" | "jacobi-diffusion");
    let iterations = if steady {
        100
    } else {
        SolveOptions::default().max_iterations
    };
    let options = SolveOptions {
        memory_budget: budget,
        max_iterations: iterations,
        ..SolveOptions::default()
    };
    let solution = solver
        .solve_paged(&paged, &options)
        .map_err(|e| e.to_string())?;
    let paged_seconds = start.elapsed().as_secs_f64();
    let paged_peak = meter.and_then(|m| m.peak_bytes());
    let s = solution.paging;
    println!("| run | wall s | peak RSS MiB | notes |");
    println!("|---|---|---|---|");
    println!(
        "| paged | {paged_seconds:.1} (build {built:.1}) | {} | {}; σ_t: {stored} of {} bricks stored; pins {} (hit rate {:.3}), evictions {}, {:.0} MiB read, {:.0} MiB written |",
        paged_peak.map_or("?".into(), |b| format!(
            "{:.0}",
            b as f64 / (1 << 20) as f64
        )),
        solution.report.stop_reason,
        layout.count(),
        s.hits + s.misses,
        s.hit_rate(),
        s.evictions,
        s.bytes_read as f64 / (1 << 20) as f64,
        s.bytes_written as f64 / (1 << 20) as f64,
    );

    // In memory, where it fits comfortably (the explicit march holds f64 fields).
    // (the steady schemes assemble a sparse matrix: 600 bytes a cell).
    let dense_factor = if steady { 150 } else { 12 };
    if dense_bytes * dense_factor > 16 << 30 {
        println!(
            "| in memory | — | — | not run: the dense problem needs more than this machine should give a test |"
        );
        return Ok(());
    }
    let meter = PeakMeter::start();
    let start = Instant::now();
    let medium = Medium {
        sigma_t: vec![lucent_grid::Grid::from_fn(geometry, sigma)],
        albedo: vec![Field::Constant(0.9)],
        phase: lucent::optics::Phase::Isotropic,
    };
    let problem = Problem::new(geometry, medium, lights, Boundary::Vacuum, None)
        .map_err(|e| e.to_string())?;
    let memory = solver
        .solve(
            &problem,
            &SolveOptions {
                max_iterations: iterations,
                ..SolveOptions::default()
            },
        )
        .map_err(|e| e.to_string())?;
    let memory_seconds = start.elapsed().as_secs_f64();
    let memory_peak = meter.and_then(|m| m.peak_bytes());
    let bits = |g: &lucent_grid::Grid| g.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    let same_fluence = bits(&solution.fluence[0].to_grid().map_err(|e| e.to_string())?)
        == bits(&memory.fluence[0])
        && solution.report.residual_history == memory.report.residual_history;
    // `direct` keeps its lights' transmittance (compared too); the explicit march keeps
    // none, on both paths.
    let same_transmittance = match &memory.angular {
        Some(Angular::Lights(l)) => Some(
            bits(
                &solution.transmittance[0][0]
                    .to_grid()
                    .map_err(|e| e.to_string())?,
            ) == bits(&l.transmittance[0][0]),
        ),
        _ if solution.transmittance.is_empty() => None,
        _ => Some(false),
    };
    println!(
        "| in memory | {memory_seconds:.1} | {} | fluence bit for bit equal: {}; transmittance: {} |",
        memory_peak.map_or("?".into(), |b| format!(
            "{:.0}",
            b as f64 / (1 << 20) as f64
        )),
        if same_fluence { "yes" } else { "NO" },
        match same_transmittance {
            Some(true) => "yes",
            Some(false) => "NO",
            None => "none kept",
        },
    );
    if !same_fluence || same_transmittance == Some(false) {
        return Err("the paged solve differs from the in-memory one".into());
    }
    Ok(())
}
