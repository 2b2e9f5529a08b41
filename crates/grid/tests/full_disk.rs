//! Every writer onto a full disk: an error, the older file at the target intact, and no
//! partial file left beside it.
//!
//! A full disk is simulated with the file-size limit (`RLIMIT_FSIZE`, `ulimit -f`): past it
//! a write fails with `EFBIG` (`SIGXFSZ` ignored), as it fails with `ENOSPC` on a full
//! file system, partway through the file. The limit is the process's, so the writes run in
//! a child: this test binary again, under `sh -c 'ulimit -f ...'`, running only
//! [`writers_under_a_file_size_limit`] (which does nothing in a normal run).

#![cfg(unix)]

use std::path::Path;
use std::process::Command;

use glam::DVec3;
use lucent_grid::io::{self, Endian, ScalarType};
use lucent_grid::{Grid, GridError, GridGeometry};

/// Set in the child that runs under the limit.
const CHILD: &str = "LUCENT_FULL_DISK_CHILD";

/// The limit, in the shell's 512-byte blocks: 64 KiB, far below what each writer writes
/// (a 40 × 36 × 32 f32 grid is 184 KiB) and far above any header.
const LIMIT_BLOCKS: u32 = 128;

#[test]
fn every_writer_onto_a_full_disk_keeps_the_older_file_and_leaves_nothing_partial() {
    let dir = tempfile::tempdir().unwrap();
    let exe = std::env::current_exe().unwrap();
    let out = Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -f {LIMIT_BLOCKS}; trap '' XFSZ; exec \"$0\" writers_under_a_file_size_limit --exact --nocapture --test-threads=1"
        ))
        .arg(&exe)
        .env(CHILD, dir.path())
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{text}");
    // The child ran the writers (not a filtered-out no-op).
    assert!(text.contains("writers checked: 12"), "{text}");
}

/// In the child: each writer fails with an I/O error, and the target and the folder are
/// as they were.
#[test]
fn writers_under_a_file_size_limit() {
    let Some(dir) = std::env::var_os(CHILD) else {
        return;
    };
    let dir = Path::new(&dir);
    let geometry = GridGeometry::new([40, 36, 32], DVec3::splat(0.5), DVec3::ZERO).unwrap();
    let values = (0..geometry.voxel_count())
        .map(|i| (i % 977) as f32 * 0.25)
        .collect();
    let grid = Grid::from_vec(geometry, values).unwrap();
    let dims = grid.dims();
    type Writer<'a> = Box<dyn Fn(&Path) -> Result<(), GridError> + 'a>;
    let writers: Vec<(&str, Writer<'_>)> = vec![
        (
            "npy",
            Box::new(|p| io::npy::write(p, &grid, ScalarType::F32)),
        ),
        (
            "npy",
            Box::new(|p| io::npy::write_channels(p, &[&grid, &grid], ScalarType::F32)),
        ),
        (
            "npy",
            Box::new(|p| {
                io::npy::write_f32_slabs(p, dims, 1, |_, z, out: &mut [f32]| {
                    let n = out.len();
                    out.copy_from_slice(&grid.data()[z * n..(z + 1) * n]);
                    Ok::<(), String>(())
                })
            }),
        ),
        (
            "raw",
            Box::new(|p| io::raw::write(p, &grid, ScalarType::F32, Endian::Little)),
        ),
        (
            "nrrd",
            Box::new(|p| io::nrrd::write(p, &grid, ScalarType::F32, io::nrrd::Encoding::Raw)),
        ),
        // A header and its `.raw` payload beside it: neither may be left.
        (
            "mhd",
            Box::new(|p| io::mhd::write(p, &grid, ScalarType::F32)),
        ),
        (
            "mha",
            Box::new(|p| io::mhd::write(p, &grid, ScalarType::F32)),
        ),
        (
            "vtk",
            Box::new(|p| io::vtk::write(p, &grid, ScalarType::F32)),
        ),
        (
            "vti",
            Box::new(|p| io::vti::write(p, &grid, ScalarType::F32, false)),
        ),
        ("vol", Box::new(|p| io::mitsuba::write(p, &[&grid]))),
        (
            "vol",
            Box::new(|p| io::mitsuba::write(p, &[&grid, &grid, &grid])),
        ),
        (
            "npy",
            // A decomposed write: ranks fill the shared partial file, one publishes it.
            Box::new(|p| {
                io::layers::create_npy(p, dims)?;
                let n = dims[0] * dims[1];
                let written = (0..dims[2]).try_for_each(|z| {
                    io::layers::write_npy_layers(
                        p,
                        dims,
                        z..z + 1,
                        &grid.data()[z * n..(z + 1) * n],
                    )
                });
                if written.is_err() {
                    io::layers::abandon_npy(p);
                }
                written?;
                io::layers::finish_npy(p)
            }),
        ),
    ];
    let mut expected: Vec<String> = Vec::new();
    for (i, (extension, write)) in writers.iter().enumerate() {
        let name = format!("out{i}.{extension}");
        let target = dir.join(&name);
        std::fs::write(&target, b"an older file").unwrap();
        expected.push(name);
        expected.sort();
        let result = write(&target);
        assert!(
            matches!(result, Err(GridError::Io { .. })),
            "writer {i} (.{extension}): {result:?}"
        );
        assert_eq!(
            std::fs::read(&target).unwrap(),
            b"an older file",
            "writer {i} (.{extension}) touched the target"
        );
        let mut found: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        found.sort();
        assert_eq!(found, expected, "writer {i} (.{extension}) left a file");
    }
    eprintln!("writers checked: {}", writers.len());
}
