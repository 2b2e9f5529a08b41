//! Using `lucent-grid` alone: load a volume file (or build the procedural cloud), print its
//! geometry and statistics, brick it, and optionally save it as `.npy` for Python.
//!
//! Run: `cargo run --release -p lucent-grid --example inspect_volume -- [FILE] [--npy OUT.npy]`
//! With no FILE it reads `$LUCENT_DATA/smoke.vdb` (default `../shared/data/volumes`) when
//! present, and a 128³ noise cloud otherwise.

#![allow(clippy::print_stdout)]

use std::path::PathBuf;

use glam::DVec3;
use lucent_grid::io::{self, ScalarType};
use lucent_grid::procedural::NoiseCloud;
use lucent_grid::{BrickedGrid, Grid, GridError, GridGeometry};

fn main() -> Result<(), GridError> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let npy_out = args
        .iter()
        .position(|a| a == "--npy")
        .and_then(|i| args.get(i + 1))
        .map(PathBuf::from);
    let file = args
        .iter()
        .take_while(|a| *a != "--npy")
        .next()
        .map(PathBuf::from)
        .or_else(|| {
            let data = std::env::var_os("LUCENT_DATA")
                .map_or_else(|| PathBuf::from("../shared/data/volumes"), PathBuf::from);
            Some(data.join("smoke.vdb")).filter(|p| p.exists())
        });
    let (name, grid): (String, Grid) = match file {
        Some(path) => (path.display().to_string(), io::read_volume(&path)?),
        None => {
            let geometry = GridGeometry::new([128; 3], DVec3::splat(1.0 / 128.0), DVec3::ZERO)?;
            (
                "procedural noise cloud".into(),
                NoiseCloud::new(7, DVec3::splat(0.5), 0.45).rasterize(geometry)?,
            )
        }
    };
    let g = grid.geometry();
    let s = grid.stats();
    println!("{name}");
    println!(
        "  dims {:?}, spacing {}, box {:?}",
        g.dims(),
        g.spacing(),
        g.bounds()
    );
    println!(
        "  min {} max {} mean {:.6} non-zero {:.1}%",
        s.min,
        s.max,
        s.mean,
        100.0 * s.nonzero_fraction
    );
    let bricks = BrickedGrid::from_dense(&grid, BrickedGrid::DEFAULT_BRICK_SIZE)?;
    println!(
        "  8³ bricks: {} of {} stored, {:.2} MiB vs {:.2} MiB dense",
        bricks.stored_bricks(),
        bricks.brick_dims().iter().product::<usize>(),
        bricks.memory_bytes() as f64 / (1 << 20) as f64,
        bricks.dense_memory_bytes() as f64 / (1 << 20) as f64
    );
    if let Some(out) = npy_out {
        io::npy::write(&out, &grid, ScalarType::F32)?;
        println!("  wrote {} (np.load gives a[z, y, x])", out.display());
    }
    Ok(())
}
