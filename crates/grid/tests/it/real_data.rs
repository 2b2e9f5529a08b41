//! Every real file of the shared test data loads with the dims, min, max and mean that its
//! README lists (numpy on the decoded values).
//!
//! The folder is `$LUCENT_DATA`, by default `../shared/data/volumes` from the workspace
//! root. When `LUCENT_DATA` is set (CI sets it) a missing folder or file fails the test;
//! when it is not set and the default folder is absent, the tests print why and skip.

use std::path::PathBuf;

use glam::DVec3;
use lucent_grid::io::raw::RawLayout;
use lucent_grid::io::{self, LoadOptions, ScalarType};
use lucent_grid::{BrickedGrid, Grid, GridError};

fn data_dir() -> Option<PathBuf> {
    match std::env::var_os("LUCENT_DATA") {
        Some(dir) => {
            let dir = PathBuf::from(dir);
            assert!(
                dir.is_dir(),
                "LUCENT_DATA = {} is not a folder",
                dir.display()
            );
            Some(dir)
        }
        None => {
            let dir =
                PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/volumes");
            if dir.is_dir() {
                Some(dir)
            } else {
                eprintln!(
                    "skipping: LUCENT_DATA is not set and {} does not exist",
                    dir.display()
                );
                None
            }
        }
    }
}

/// |actual − printed| within half a unit of the last of `digits` significant digits.
fn assert_printed(actual: f64, printed: f64, digits: i32, what: &str) {
    let unit = if printed == 0.0 {
        1e-12
    } else {
        10f64.powi(printed.abs().log10().floor() as i32 - (digits - 1))
    };
    assert!(
        (actual - printed).abs() <= 0.5 * unit * (1.0 + 1e-9),
        "{what}: {actual} vs README {printed}"
    );
}

/// Checks dims and the README's (min, max, mean); the mean is printed with 6 significant
/// digits.
fn check(
    name: &str,
    grid: &Grid,
    dims: [usize; 3],
    min: f64,
    max: f64,
    mean: f64,
    mean_digits: i32,
) {
    assert_eq!(grid.dims(), dims, "{name}: dims");
    let s = grid.stats();
    assert_printed(f64::from(s.min), min, 6, &format!("{name} min"));
    assert_printed(f64::from(s.max), max, 6, &format!("{name} max"));
    assert_printed(s.mean, mean, mean_digits, &format!("{name} mean"));
}

fn raw(
    dir: &std::path::Path,
    file: &str,
    dims: [usize; 3],
    scalar: ScalarType,
) -> Result<Grid, GridError> {
    io::raw::read(
        dir.join(file),
        &RawLayout::new(dims, scalar),
        &LoadOptions::default(),
    )
}

#[test]
fn headerless_raw_volumes() {
    let Some(dir) = data_dir() else { return };
    let neghip = raw(
        &dir,
        "neghip_64x64x64_uint8.raw",
        [64, 64, 64],
        ScalarType::U8,
    )
    .unwrap();
    check("neghip", &neghip, [64, 64, 64], 0.0, 255.0, 18.4028, 6);
    let tooth = raw(
        &dir,
        "tooth_103x94x161_uint8.raw",
        [103, 94, 161],
        ScalarType::U8,
    )
    .unwrap();
    check("tooth", &tooth, [103, 94, 161], 0.0, 255.0, 103.165, 6);
    let walnut = raw(&dir, "walnut.raw", [128, 96, 114], ScalarType::U16).unwrap();
    check("walnut", &walnut, [128, 96, 114], 0.0, 22526.0, 2050.94, 6);
    let bucky = raw(&dir, "Bucky.raw", [32, 32, 32], ScalarType::U8).unwrap();
    check("Bucky", &bucky, [32, 32, 32], 0.0, 255.0, 35.8498, 6);
    // The wrong dims are refused before reading: the payload does not match.
    let wrong = raw(&dir, "Bucky.raw", [32, 32, 33], ScalarType::U8);
    assert!(
        matches!(
            wrong,
            Err(GridError::SizeMismatch {
                expected: 33792,
                found: 32768,
                ..
            })
        ),
        "{wrong:?}"
    );
}

#[test]
fn nucleon_through_its_detached_nrrd_header() {
    let Some(dir) = data_dir() else { return };
    let nucleon = io::read_volume(dir.join("nucleon.nrrd")).unwrap();
    check("nucleon", &nucleon, [41, 41, 41], 0.0, 249.0, 39.3977, 6);
    assert_eq!(nucleon.geometry().spacing(), DVec3::ONE);
    // The raw file read directly agrees voxel for voxel.
    let direct = raw(&dir, "nucleon.raw", [41, 41, 41], ScalarType::U8).unwrap();
    assert_eq!(nucleon.data(), direct.data());
}

#[test]
fn legacy_vtk_and_metaimage() {
    let Some(dir) = data_dir() else { return };
    let iron = io::read_volume(dir.join("ironProt.vtk")).unwrap();
    check("ironProt", &iron, [68, 68, 68], 0.0, 255.0, 13.1383, 6);
    let head = io::read_volume(dir.join("HeadMRVolume.mhd")).unwrap();
    check("HeadMRVolume", &head, [48, 62, 42], 0.0, 255.0, 24.4682, 6);
    assert_eq!(head.geometry().spacing(), DVec3::splat(4.0));
}

#[test]
fn mitsuba_grids() {
    let Some(dir) = data_dir() else { return };
    let volume = io::read_volume(dir.join("volume.vol")).unwrap();
    check(
        "volume.vol",
        &volume,
        [44, 45, 53],
        0.0,
        1.84961,
        0.10835,
        5,
    );
    let sigmat = io::read_volume(dir.join("sigmat.vol")).unwrap();
    check("sigmat.vol", &sigmat, [16, 16, 16], 0.0, 5.0, 0.609157, 6);
    // The README's statistics for the RGB albedo grid are over all three channels.
    let albedo =
        io::mitsuba::read_channels(dir.join("albedo.vol"), &LoadOptions::default()).unwrap();
    assert_eq!(albedo.len(), 3);
    let mean = albedo.iter().map(|g| g.stats().mean).sum::<f64>() / 3.0;
    assert_printed(mean, 0.402019, 6, "albedo.vol mean");
    assert!(
        io::read_volume(dir.join("albedo.vol")).is_err(),
        "a 3-channel grid is not a scalar grid"
    );
    // The torus SDF's box is denormal garbage: the unit cube is used instead.
    let torus = io::read_volume(dir.join("torus_sdfgrid.vol")).unwrap();
    check(
        "torus_sdfgrid.vol",
        &torus,
        [40, 40, 40],
        -4.0,
        23.0982,
        8.91606,
        6,
    );
    assert_eq!(torus.geometry().bounds(), (DVec3::ZERO, DVec3::ONE));
}

#[test]
fn houdini_smoke_vdb() {
    let Some(dir) = data_dir() else { return };
    let smoke = io::vdb::read_volume(dir.join("smoke.vdb"), None, &LoadOptions::default()).unwrap();
    assert_eq!(smoke.name, "density");
    assert!(smoke.half_float);
    assert_eq!(smoke.active_voxels, 1_049_275);
    assert_eq!(smoke.active_bbox, ([1, 2, 1], [111, 223, 112]));
    check(
        "smoke.vdb",
        &smoke.grid,
        [111, 222, 112],
        0.0,
        5.71484,
        0.0621397,
        6,
    );
    assert_printed(smoke.grid.geometry().spacing().x, 0.47619, 5, "voxel size");

    // Empty space is free: the bricked form needs less memory than dense.
    let bricks = BrickedGrid::from_dense(&smoke.grid, 8).unwrap();
    assert_eq!(bricks.to_dense(), smoke.grid);
    eprintln!(
        "smoke.vdb bricked: {} bytes vs dense {} bytes ({} of {} bricks stored)",
        bricks.memory_bytes(),
        bricks.dense_memory_bytes(),
        bricks.stored_bricks(),
        bricks.brick_dims().iter().product::<usize>()
    );
    assert!(bricks.memory_bytes() < bricks.dense_memory_bytes());
}

#[test]
fn a_tiny_budget_is_refused_before_reading() {
    let Some(dir) = data_dir() else { return };
    let tight = LoadOptions {
        memory_budget: 1 << 16,
    };
    for file in ["smoke.vdb", "tooth_103x94x161_uint8.raw"] {
        let result = if file.ends_with(".raw") {
            io::raw::read(
                dir.join(file),
                &RawLayout::new([103, 94, 161], ScalarType::U8),
                &tight,
            )
        } else {
            io::read_volume_with(dir.join(file), &tight)
        };
        assert!(
            matches!(result, Err(GridError::OverBudget { .. })),
            "{file}: {result:?}"
        );
    }
}

#[test]
fn mutated_smoke_vdb_never_panics() {
    // The synthetic fuzz cases in formats.rs cannot reach deep into a VDB tree; mutating the
    // real file can. Corrupt a few bytes of the topology and buffers, and cut the file short.
    use rand::{Rng, SeedableRng};
    let Some(dir) = data_dir() else { return };
    let original = std::fs::read(dir.join("smoke.vdb")).unwrap();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(222);
    let options = LoadOptions {
        memory_budget: 1 << 28,
    };
    for case in 0..48 {
        let mut bytes = original.clone();
        for _ in 0..rng.random_range(1..5) {
            // Half the edits in the header and topology (first 64 KiB), half anywhere.
            let limit = if case % 2 == 0 { 65_536 } else { bytes.len() };
            let pos = rng.random_range(0..limit);
            bytes[pos] = rng.random();
        }
        if case % 3 == 0 {
            bytes.truncate(rng.random_range(0..bytes.len()));
        }
        let _ = io::vdb::parse(
            &bytes,
            std::path::Path::new("smoke-mutated.vdb"),
            None,
            &options,
        );
    }
}

#[test]
fn both_vtkjs_vti_folders_load_with_their_readme_statistics() {
    // README: headsq 64 x 64 x 93 int16, min 0, max 3926, mean 507.687, non-zero 0.8462,
    // spacing 3.2 3.2 1.5; LIDC2 256 x 256 x 133 uint8, min 0, max 255, mean 7.05451,
    // non-zero 0.1639, spacing 1.40625 1.40625 2.5. Both by folder and by index.json.
    let Some(dir) = data_dir() else { return };
    for (name, dims, max, mean, nonzero, spacing) in [
        (
            "headsq.vti",
            [64, 64, 93],
            3926.0,
            507.687,
            0.8462,
            DVec3::new(3.2, 3.2, 1.5),
        ),
        (
            "LIDC2.vti",
            [256, 256, 133],
            255.0,
            7.05451,
            0.1639,
            DVec3::new(1.40625, 1.40625, 2.5),
        ),
    ] {
        for path in [dir.join(name), dir.join(name).join("index.json")] {
            let grid = io::read_volume(&path).unwrap_or_else(|e| panic!("{e}"));
            check(name, &grid, dims, 0.0, max, mean, 6);
            assert_printed(grid.stats().nonzero_fraction, nonzero, 4, name);
            assert!((grid.geometry().spacing() - spacing).abs().max_element() < 1e-12);
            // Point samples are cell centres: the first sits at the origin (0, 0, 0).
            assert!((grid.geometry().cell_centre(0, 0, 0)).abs().max_element() < 1e-12);
        }
    }
}
