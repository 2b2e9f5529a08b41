//! A sparse cloud far larger than its pool, paged through a backing file: build it brick by
//! brick, march rays through it exactly, and print what the pager did.
//!
//! `cargo run --profile examples -p lucent-paging --example page_a_cloud [N] [POOL_KIB]`
//! (defaults 192 and 512: a 192³ field of 27 MiB dense, through a pool of 512 KiB).

// An example reports to the terminal.
#![allow(clippy::print_stdout)]

use std::sync::Arc;

use glam::DVec3;
use lucent_grid::procedural::NoiseCloud;
use lucent_grid::{BrickLayout, GridGeometry};
use lucent_paging::{Eviction, FileStore, PagedGrid, Pager, PagerOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<u64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let n = args.first().copied().unwrap_or(192) as usize;
    let pool_kib = args.get(1).copied().unwrap_or(512);

    let geometry = GridGeometry::new([n; 3], DVec3::splat(1.0 / n as f64), DVec3::ZERO)?;
    let brick = 16;
    let layout = BrickLayout::new(geometry.dims(), brick)?;
    let pager = Arc::new(Pager::new(
        Box::new(FileStore::create()?),
        0,
        layout.stored_len(),
        1,
        PagerOptions {
            budget_bytes: pool_kib << 10,
            eviction: Eviction::Nru,
            fill: 0.0,
        },
    )?);
    // σ_t of a noise cloud (extinction 60 per unit at full density), never dense in memory.
    let cloud = NoiseCloud::new(5, DVec3::splat(0.5), 0.35);
    let sigma_t = PagedGrid::from_fn(pager.clone(), geometry, brick, |c| {
        (60.0 * cloud.density(geometry.cell_centre(c[0], c[1], c[2]))) as f32
    })?;
    println!(
        "{n}³ cells ({} MiB dense), {} of {} bricks stored (the rest are empty space), pool of {} slots",
        (geometry.voxel_count() * 4) >> 20,
        sigma_t.stored_bricks(),
        layout.count(),
        pager.capacity()
    );
    // Transmittance along the diagonal and along an axis through the centre: exact line
    // integrals of the trilinear σ_t, each dual cell read from one stored brick.
    for (a, b) in [
        (DVec3::ZERO, DVec3::ONE),
        (DVec3::new(0.0, 0.5, 0.5), DVec3::new(1.0, 0.5, 0.5)),
    ] {
        let tau = sigma_t.line_integral(a, b, f64::INFINITY)?;
        println!(
            "τ from {a} to {b} = {tau:.4}, transmittance {:.4e}",
            (-tau).exp()
        );
    }
    // The largest σ_t in the cloud's core, from the bricks' ranges alone (no brick read).
    let centre = n / 2;
    println!(
        "majorant of σ_t in the central 8³ cells: {:.3}",
        sigma_t.max_over_cells([centre - 4; 3], [centre + 3; 3])
    );
    let s = pager.stats();
    println!(
        "pager: {} pins (hit rate {:.3}), {} evictions, {} KiB read, {} KiB written",
        s.hits + s.misses,
        s.hit_rate(),
        s.evictions,
        s.bytes_read >> 10,
        s.bytes_written >> 10
    );
    Ok(())
}
