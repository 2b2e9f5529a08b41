//! `cargo xtask bench-paging [N] [BRICK]`: the pager under a stencil, in core and out of
//! core, in one run.
//!
//! The stencil is an FTCS diffusion step on f32 (φ′ = φ + r Σ_nb (φ_nb − φ) − κ φ, the
//! neighbours clamped at the faces: a Neumann box), swept over an N³ smooth cloud (default
//! 256) with φ and φ′ ping-ponged. In core: two dense arrays, rayon over z-slabs. Out of
//! core: two `PagedGrid`s of B³ bricks (default 16) sharing one pager whose pool holds
//! 1/16 of their bricks, backed by an unnamed temporary file (positioned I/O), the input
//! streamed layer by layer (`for_each_layer`) with the next layer prefetched, each layer's
//! output written back with its aprons (`write_slabs`). Reported per configuration (LRU
//! and NRU, with and without prefetch): seconds per sweep, cell updates per second, the
//! ratio to the in-core sweep, hit rate, bytes read and written per sweep; and whether
//! the paged result is bit for bit the in-core one.
//!
//! Then time skewing (`skewed_steps`): 1, 2, 4, 8, 16 and 32 steps per pass, in memory and
//! out of core at 1/16 resident, each against the in-memory pass with the same number of
//! steps and against plain in-memory sweeps of the same slab kernel, the results checked
//! bit for bit against 32 plain sweeps.
//!
//! Then the discrete ordinates' access pattern: the eight octant sweeps over one field in
//! their wavefront orders (`BrickLayout::wavefronts`), each brick pinned for writing once
//! per octant, at 1/16, 1/4 and 1/2 of the bricks resident: the hit rate of LRU and of the
//! NRU clock, which is what decides between them on the sweeps (the stencil's z-slab stream
//! misses on every brick at 1/16 under either).

use std::sync::Arc;
use std::time::Instant;

use glam::DVec3;
use lucent::paging::{
    Eviction, FileStore, PagedGrid, Pager, PagerOptions, PagingError, for_each_layer,
};
use lucent_grid::{BrickLayout, Grid, GridGeometry};
use rayon::prelude::*;

const R: f32 = 0.1;
const KAPPA: f32 = 0.01;
const SWEEPS: usize = 3;
/// Steps per measurement of the time-skewed passes (a multiple of every steps-per-pass
/// measured).
const SKEWED: usize = 32;

/// One FTCS step of the slabs `z0..z1` of a grid of `dims` into `out`, reading `window`,
/// which holds slabs `w0..` (at least z0 − 1 .. z1 + 1 within the grid).
fn step_slabs(dims: [usize; 3], window: &[f32], w0: usize, z0: usize, z1: usize, out: &mut [f32]) {
    let [nx, ny, nz] = dims;
    let plane = nx * ny;
    out.par_chunks_mut(plane)
        .enumerate()
        .for_each(|(dz, slab)| {
            let z = z0 + dz;
            let at = |x: usize, y: usize, z: usize| window[(z - w0) * plane + y * nx + x];
            let (zm, zp) = (z.saturating_sub(1), (z + 1).min(nz - 1));
            for y in 0..ny {
                let (ym, yp) = (y.saturating_sub(1), (y + 1).min(ny - 1));
                for x in 0..nx {
                    let (xm, xp) = (x.saturating_sub(1), (x + 1).min(nx - 1));
                    let c = at(x, y, z);
                    let sum = (at(xm, y, z) - c)
                        + (at(xp, y, z) - c)
                        + (at(x, ym, z) - c)
                        + (at(x, yp, z) - c)
                        + (at(x, y, zm) - c)
                        + (at(x, y, zp) - c);
                    slab[y * nx + x] = c + R * sum - KAPPA * c;
                }
            }
        });
    debug_assert_eq!(out.len(), plane * (z1 - z0));
}

/// The same FTCS step on one slab z from the slabs below, at and above it (clamped at the
/// faces by the caller): the arithmetic of [`step_slabs`] cell for cell, rows in parallel.
fn step_one_slab(dims: [usize; 3], slabs: [&[f32]; 3], out: &mut [f32]) {
    let [nx, ny, _] = dims;
    let [below, at, above] = slabs;
    out.par_chunks_mut(nx).enumerate().for_each(|(y, row)| {
        let (ym, yp) = (y.saturating_sub(1), (y + 1).min(ny - 1));
        for (x, o) in row.iter_mut().enumerate() {
            let (xm, xp) = (x.saturating_sub(1), (x + 1).min(nx - 1));
            let c = at[y * nx + x];
            let sum = (at[y * nx + xm] - c)
                + (at[y * nx + xp] - c)
                + (at[ym * nx + x] - c)
                + (at[yp * nx + x] - c)
                + (below[y * nx + x] - c)
                + (above[y * nx + x] - c);
            *o = c + R * sum - KAPPA * c;
        }
    });
}

/// A pager of f32 bricks of `len` values over a fresh backing file, with a pool of
/// `slots` bricks.
fn file_pager(len: usize, slots: usize, eviction: Eviction) -> Result<Pager, PagingError> {
    Pager::new(
        Box::new(FileStore::create()?),
        0,
        len,
        1,
        PagerOptions {
            budget_bytes: (slots * len * 4) as u64,
            eviction,
            fill: 0.0f32,
        },
    )
}

/// Runs the benchmark.
pub(crate) fn run(n: usize, brick: usize, dom_n: usize) -> Result<(), String> {
    let err = |e: PagingError| e.to_string();
    let geometry = GridGeometry::new([n; 3], DVec3::splat(1.0 / n as f64), DVec3::ZERO)
        .map_err(|e| e.to_string())?;
    let dims = geometry.dims();
    let initial = Grid::from_fn(geometry, |p| {
        (1.0 + (7.0 * p.x).sin() * (5.0 * p.y).cos() * (3.0 * p.z).sin()) as f32
    });
    let cells = (n * n * n) as f64;

    // In core: the reference result and time.
    let mut a = initial.data().to_vec();
    let mut b = vec![0f32; a.len()];
    let start = Instant::now();
    for _ in 0..SWEEPS {
        step_slabs(dims, &a, 0, 0, n, &mut b);
        std::mem::swap(&mut a, &mut b);
    }
    let in_core = start.elapsed().as_secs_f64() / SWEEPS as f64;
    let reference = a;
    println!(
        "N = {n}, bricks of {brick}³ stored as {}³ (apron), {} sweeps; in core: {:.3} s per sweep, {:.3e} cell updates/s",
        brick + 2,
        SWEEPS,
        in_core,
        cells / in_core
    );
    println!(
        "| eviction | prefetch | resident | s per sweep | cell updates/s | vs in core | hit rate | MB read per sweep | MB written per sweep | bit-identical |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let layout = BrickLayout::new(dims, brick).map_err(|e| e.to_string())?;
    for eviction in [Eviction::Lru, Eviction::Nru] {
        for prefetch in [false, true] {
            // 1/16 of both fields' bricks resident.
            let slots = (2 * layout.count() / 16).max(8);
            let pager = Arc::new(file_pager(layout.stored_len(), slots, eviction).map_err(err)?);
            let mut fields = [
                PagedGrid::from_grid(pager.clone(), &initial, brick).map_err(err)?,
                PagedGrid::filled(pager.clone(), geometry, brick, 0.0).map_err(err)?,
            ];
            let before = pager.stats();
            let start = Instant::now();
            for _ in 0..SWEEPS {
                let [input, output] = &fields;
                let mut layer_out = Vec::new();
                for_each_layer(input, &[output], prefetch, |layer, z_lo, window| {
                    let z0 = layer * brick;
                    let z1 = (z0 + brick).min(n);
                    layer_out.resize(n * n * (z1 - z0), 0.0);
                    step_slabs(dims, window, z_lo, z0, z1, &mut layer_out);
                    output.write_slabs(z0, &layer_out)
                })
                .map_err(err)?;
                fields.swap(0, 1);
            }
            let seconds = start.elapsed().as_secs_f64() / SWEEPS as f64;
            let after = pager.stats();
            let result = fields[0].to_grid().map_err(err)?;
            let identical = result
                .data()
                .iter()
                .zip(&reference)
                .all(|(x, y)| x.to_bits() == y.to_bits());
            let pins = (after.hits - before.hits) + (after.misses - before.misses);
            println!(
                "| {eviction:?} | {prefetch} | {:.1} % ({slots} of {} bricks) | {seconds:.3} | {:.3e} | {:.0} % | {:.3} | {:.0} | {:.0} | {} |",
                100.0 * slots as f64 / (2 * layout.count()) as f64,
                2 * layout.count(),
                cells / seconds,
                100.0 * in_core / seconds,
                (after.hits - before.hits) as f64 / pins.max(1) as f64,
                (after.bytes_read - before.bytes_read) as f64 / SWEEPS as f64 / 1e6,
                (after.bytes_written - before.bytes_written) as f64 / SWEEPS as f64 / 1e6,
                if identical { "yes" } else { "NO" }
            );
            if !identical {
                return Err("the paged sweep differs from the in-core one".into());
            }
        }
    }
    println!();
    println!(
        "Time skewing (`skewed_steps`, {SKEWED} steps per measurement, the slab kernel `step_one_slab`):"
    );
    println!(
        "| storage | steps per pass | resident | s per step | cell updates/s | vs in core, same steps per pass | vs in core, plain sweeps | hit rate | MB read per step | MB written per step | bit-identical |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    // The plain sweeps' result for SKEWED steps.
    let mut a = initial.data().to_vec();
    let mut b = vec![0f32; a.len()];
    for _ in 0..SKEWED {
        step_slabs(dims, &a, 0, 0, n, &mut b);
        std::mem::swap(&mut a, &mut b);
    }
    let reference = a;
    let identical = |x: &[f32]| {
        x.iter()
            .zip(&reference)
            .all(|(p, q)| p.to_bits() == q.to_bits())
    };
    let plane = n * n;
    let skews = [1, 2, 4, 8, 16, SKEWED];
    // In core: the same pipeline over dense arrays (one step per pass is a plain sweep
    // slab by slab).
    let mut in_core_skewed = Vec::new();
    for steps in skews {
        let mut a = initial.data().to_vec();
        let mut b = vec![0f32; a.len()];
        let start = Instant::now();
        for _ in 0..SKEWED / steps {
            lucent::paging::skewed_steps(
                dims,
                steps,
                |z, slab| {
                    slab.copy_from_slice(&a[z * plane..(z + 1) * plane]);
                    Ok(())
                },
                |z, slab| {
                    b[z * plane..(z + 1) * plane].copy_from_slice(slab);
                    Ok(())
                },
                |_, _, slabs, out| step_one_slab(dims, slabs, out),
            )
            .map_err(err)?;
            std::mem::swap(&mut a, &mut b);
        }
        let seconds = start.elapsed().as_secs_f64() / SKEWED as f64;
        if !identical(&a) {
            return Err("the skewed in-core pass differs from the plain sweeps".into());
        }
        in_core_skewed.push(seconds);
    }
    let plain = in_core_skewed[0];
    for (&steps, &core) in skews.iter().zip(&in_core_skewed) {
        println!(
            "| in core | {steps} | all | {core:.4} | {:.3e} | 100 % | {:.0} % | – | – | – | yes |",
            cells / core,
            100.0 * plain / core,
        );
    }
    for (&steps, &core) in skews.iter().zip(&in_core_skewed) {
        // Out of core: 1/16 of both fields' bricks resident, LRU, prefetch where the pool
        // has room for it (three brick layers; at 1/16 of 16 layers it has two, and
        // `skewed_steps_paged` leaves prefetch off).
        let slots = (2 * layout.count() / 16).max(8);
        let pager = Arc::new(file_pager(layout.stored_len(), slots, Eviction::Lru).map_err(err)?);
        let mut fields = [
            PagedGrid::from_grid(pager.clone(), &initial, brick).map_err(err)?,
            PagedGrid::filled(pager.clone(), geometry, brick, 0.0).map_err(err)?,
        ];
        let before = pager.stats();
        let start = Instant::now();
        for _ in 0..SKEWED / steps {
            let [input, output] = &fields;
            lucent::paging::skewed_steps_paged(input, output, steps, true, |_, _, slabs, out| {
                step_one_slab(dims, slabs, out)
            })
            .map_err(err)?;
            fields.swap(0, 1);
        }
        let seconds = start.elapsed().as_secs_f64() / SKEWED as f64;
        let moved = pager.stats().since(&before);
        let result = fields[0].to_grid().map_err(err)?;
        println!(
            "| paged | {steps} | {:.1} % ({slots} of {} bricks) | {seconds:.4} | {:.3e} | {:.0} % | {:.0} % | {:.3} | {:.0} | {:.0} | {} |",
            100.0 * slots as f64 / (2 * layout.count()) as f64,
            2 * layout.count(),
            cells / seconds,
            100.0 * core / seconds,
            100.0 * plain / seconds,
            moved.hit_rate(),
            moved.bytes_read as f64 / SKEWED as f64 / 1e6,
            moved.bytes_written as f64 / SKEWED as f64 / 1e6,
            if identical(result.data()) {
                "yes"
            } else {
                "NO"
            }
        );
        if !identical(result.data()) {
            return Err("the skewed paged pass differs from the plain sweeps".into());
        }
    }
    println!();
    println!(
        "Octant sweeps (8 wavefront orders, each brick written once per octant), one field of {} bricks:",
        layout.count()
    );
    println!("| resident | LRU hit rate | NRU hit rate | LRU evictions | NRU evictions |");
    println!("|---|---|---|---|---|");
    for fraction in [16, 4, 2] {
        let slots = (layout.count() / fraction).max(4);
        let mut row = Vec::new();
        for eviction in [Eviction::Lru, Eviction::Nru] {
            let pager = Arc::new(file_pager(layout.stored_len(), slots, eviction).map_err(err)?);
            let field = PagedGrid::from_grid(pager.clone(), &initial, brick).map_err(err)?;
            let before = pager.stats();
            for octant in 0..8 {
                let negative = [octant & 1 != 0, octant & 2 != 0, octant & 4 != 0];
                for plane in layout.wavefronts(negative) {
                    for id in plane {
                        let mut pin = pager.write(field.pager_brick(id)).map_err(err)?;
                        pin[0] += 1.0;
                    }
                }
            }
            row.push(pager.stats().since(&before));
        }
        println!(
            "| 1/{fraction} ({slots} bricks) | {:.3} | {:.3} | {} | {} |",
            row[0].hit_rate(),
            row[1].hit_rate(),
            row[0].evictions,
            row[1].evictions
        );
    }
    dom_sweep(dom_n)
}

/// One discrete-ordinates sweep (S6, 48 directions, HG g = 0.6, albedo 0.95, 16³ blocks)
/// of a noise cloud at N³ with its per-direction work in memory, then paged with 1/16 of
/// its pages resident under LRU and NRU (a backing file): seconds per sweep, the ratio,
/// hit rate, bytes moved, and whether fluence and outflow are bit for bit equal.
fn dom_sweep(n: usize) -> Result<(), String> {
    use lucent::dom::angular::Ordinates;
    use lucent::dom::{DomBoundary, DomProblem, DomSettings, PagedWork, SourceIteration};
    let err = |e: &dyn std::fmt::Display| e.to_string();
    let geometry =
        GridGeometry::from_bounds([n; 3], DVec3::ZERO, DVec3::ONE).map_err(|e| err(&e))?;
    let cloud = lucent_grid::procedural::NoiseCloud::new(7, DVec3::splat(0.5), 0.45);
    let density = cloud.rasterize(geometry).map_err(|e| err(&e))?;
    let peak = density.stats().max.max(f32::MIN_POSITIVE);
    let sigma_t: Vec<f32> = density.data().iter().map(|v| v * 64.0 / peak).collect();
    let ordinates = Ordinates::new(
        lucent::optics::SphericalQuadrature::level_symmetric(6).map_err(|e| err(&e))?,
        None,
        lucent::optics::Phase::henyey_greenstein(0.6).map_err(|e| err(&e))?,
    )
    .map_err(|e| err(&e))?;
    let m = ordinates.storage().len();
    let problem = DomProblem {
        geometry,
        sigma_s: sigma_t.iter().map(|s| 0.95 * s).collect(),
        fixed: sigma_t
            .iter()
            .flat_map(|s| std::iter::repeat_n(0.1 * s, m))
            .collect(),
        sigma_t,
        boundary: DomBoundary {
            radiance: 0.2,
            reflectance: 0.0,
        },
    };
    let settings = DomSettings::default();
    let mut iteration =
        SourceIteration::new(&problem, &ordinates, &settings).map_err(|e| err(&e))?;
    let cell_directions = (n * n * n * ordinates.propagation().len()) as f64;
    println!();
    println!(
        "Discrete-ordinates sweep at {n}³, S6 ({} directions), 16³ blocks, work {:.0} MB (f64):",
        ordinates.propagation().len(),
        iteration.work_bytes() as f64 / 1e6
    );
    println!(
        "| work | resident | s per sweep (best of 3) | ns per cell-direction | vs in memory | hit rate | MB read / written per sweep | bit-identical |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut best = f64::INFINITY;
    let mut reference = None;
    for _ in 0..3 {
        let r = iteration.sweep_only().map_err(|e| err(&e))?;
        best = best.min(r.seconds);
        reference = Some(r);
    }
    let reference = reference.expect("three sweeps ran");
    println!(
        "| in memory | all | {best:.3} | {:.2} | 100 % | – | – | – |",
        best / cell_directions * 1e9
    );
    let page = iteration.work_page_bytes();
    let pages_total = iteration.work_bytes().div_ceil(page);
    let slots = (pages_total / 16).max(SourceIteration::min_work_pages() as u64);
    for eviction in [Eviction::Lru, Eviction::Nru] {
        let paged = DomSettings {
            paged_work: Some(PagedWork {
                pool_bytes: slots * page,
                eviction,
            }),
            ..settings
        };
        let mut iteration =
            SourceIteration::new(&problem, &ordinates, &paged).map_err(|e| err(&e))?;
        let mut seconds = f64::INFINITY;
        let mut last = None;
        for _ in 0..3 {
            let r = iteration.sweep_only().map_err(|e| err(&e))?;
            seconds = seconds.min(r.seconds);
            last = Some(r);
        }
        let last = last.expect("three sweeps ran");
        let stats = last.pager.unwrap_or_default();
        let identical = last.outflow_power.to_bits() == reference.outflow_power.to_bits()
            && last
                .fluence
                .iter()
                .zip(&reference.fluence)
                .all(|(a, b)| a.to_bits() == b.to_bits());
        println!(
            "| paged, {eviction:?} | {:.1} % ({slots} of {pages_total} pages) | {seconds:.3} | {:.2} | {:.0} % | {:.3} | {:.0} / {:.0} | {} |",
            100.0 * slots as f64 / pages_total as f64,
            seconds / cell_directions * 1e9,
            100.0 * best / seconds,
            stats.hit_rate(),
            stats.bytes_read as f64 / 1e6,
            stats.bytes_written as f64 / 1e6,
            if identical { "yes" } else { "NO" }
        );
        if !identical {
            return Err("the paged sweep differs from the in-memory one".into());
        }
    }
    Ok(())
}
