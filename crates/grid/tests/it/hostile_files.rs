//! Files crafted to make a reader loop, allocate without end, block, or hand on NaN: each
//! must get a typed error naming the file, quickly and in bounded memory. Every case here
//! was a crash, an abort or a hang of an earlier reader (docs/reliability.md).

use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

use lucent_grid::GridError;
use lucent_grid::io::{self, LoadOptions};

/// A minimal OpenVDB header up to the grid descriptors: magic, file version 224, library
/// version, the grid-offsets flag, a UUID and no metadata.
fn vdb_header(grid_count: u32) -> Vec<u8> {
    let mut b = Vec::new();
    b.extend_from_slice(&0x5644_4220u64.to_le_bytes());
    b.extend_from_slice(&224u32.to_le_bytes());
    b.extend_from_slice(&10u32.to_le_bytes());
    b.extend_from_slice(&0u32.to_le_bytes());
    b.push(1);
    b.extend_from_slice(&[b'0'; 36]);
    b.extend_from_slice(&0u32.to_le_bytes());
    b.extend_from_slice(&grid_count.to_le_bytes());
    b
}

fn vdb_string(b: &mut Vec<u8>, s: &str) {
    b.extend_from_slice(&(s.len() as u32).to_le_bytes());
    b.extend_from_slice(s.as_bytes());
}

/// A descriptor whose end offset points back at its own start.
fn looping_descriptor(b: &mut Vec<u8>) {
    let start = b.len() as u64;
    vdb_string(b, "density");
    vdb_string(b, "Tree_float_5_4_3");
    vdb_string(b, "");
    for offset in [0, 0, start] {
        b.extend_from_slice(&offset.to_le_bytes());
    }
    b.extend_from_slice(&[0u8; 64]);
}

/// The error of parsing `bytes`, in less than a second.
fn parse_quickly(bytes: &[u8]) -> GridError {
    let started = Instant::now();
    let result = io::vdb::parse(
        bytes,
        Path::new("crafted.vdb"),
        None,
        &LoadOptions::default(),
    );
    assert!(started.elapsed() < Duration::from_secs(1));
    result.expect_err("a crafted file is refused")
}

#[test]
fn a_vdb_descriptor_that_loops_back_is_refused() {
    // 2³² − 1 descriptors claimed: more than the file could hold.
    let mut b = vdb_header(u32::MAX);
    looping_descriptor(&mut b);
    let e = parse_quickly(&b);
    assert!(matches!(e, GridError::Malformed { .. }), "{e}");
    assert!(e.to_string().contains("crafted.vdb"), "{e}");
    // Two claimed (they fit), the first pointing back at itself: before the fix the same
    // descriptor was pushed again and again until the allocation aborted.
    let mut b = vdb_header(2);
    looping_descriptor(&mut b);
    looping_descriptor(&mut b);
    let e = parse_quickly(&b);
    assert!(
        e.to_string().contains("does not follow its descriptor"),
        "{e}"
    );
}

#[test]
fn a_detached_nrrd_payload_on_a_device_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let header = dir.path().join("zero.nrrd");
    std::fs::write(
        &header,
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 41 41 41\nencoding: raw\ndata file: /dev/zero\n",
    )
    .unwrap();
    let started = Instant::now();
    let e = io::read_volume(&header).unwrap_err();
    assert!(started.elapsed() < Duration::from_secs(1));
    assert!(
        matches!(&e, GridError::NotAFile { path } if path == Path::new("/dev/zero")),
        "{e}"
    );
}

#[cfg(unix)]
#[test]
fn a_fifo_is_refused_without_blocking() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("volume.npy");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if !made.is_ok_and(|s| s.success()) {
        return; // No mkfifo here: nothing to test.
    }
    let e = io::read_volume(&fifo).unwrap_err();
    assert!(matches!(e, GridError::NotAFile { .. }), "{e}");
}

#[test]
fn a_gzip_bomb_is_refused_before_it_is_inflated() {
    // 64 MiB of zeros compress to about 64 kB; the header claims 1024³ bytes.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bomb.nrrd");
    let mut file = std::fs::File::create(&path).unwrap();
    file.write_all(
        b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 1024 1024 1024\nencoding: gzip\n\n",
    )
    .unwrap();
    let mut gz = flate2::write::GzEncoder::new(file, flate2::Compression::best());
    let chunk = vec![0u8; 1 << 20];
    for _ in 0..64 {
        gz.write_all(&chunk).unwrap();
    }
    gz.finish().unwrap();
    // A scene's read budget (3 GiB) is below the 1 GiB payload + 4 GiB of f32 it claims.
    let options = LoadOptions {
        memory_budget: 3 << 30,
    };
    let started = Instant::now();
    let e = io::read_volume_with(&path, &options).unwrap_err();
    assert!(started.elapsed() < Duration::from_secs(1));
    assert!(
        matches!(e, GridError::OverBudget { needed, .. } if needed >= 5 << 30),
        "{e}"
    );
}

#[test]
fn nan_and_infinite_voxels_are_named_not_read_as_zero() {
    let dir = tempfile::tempdir().unwrap();
    let geometry =
        lucent_grid::GridGeometry::new([4, 3, 2], glam::DVec3::ONE, glam::DVec3::ZERO).unwrap();
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut grid = lucent_grid::Grid::filled(geometry, 1.0);
        let index = geometry.index(2, 1, 1);
        grid.data_mut()[index] = bad;
        for name in ["v.npy", "v.vol", "v.nrrd"] {
            let path = dir.path().join(name);
            let written = match name {
                "v.npy" => io::npy::write(&path, &grid, io::ScalarType::F32),
                "v.vol" => io::mitsuba::write(&path, &[&grid]),
                _ => io::nrrd::write(&path, &grid, io::ScalarType::F32, io::nrrd::Encoding::Raw),
            };
            if written.is_err() {
                continue; // A writer may refuse the value itself; then nothing to read.
            }
            let e = io::read_volume(&path).unwrap_err();
            assert!(
                matches!(
                    &e,
                    GridError::NonFinite {
                        cell: [2, 1, 1],
                        ..
                    }
                ),
                "{name} with {bad}: {e}"
            );
            assert!(e.to_string().contains(name), "{e}");
        }
    }
}
