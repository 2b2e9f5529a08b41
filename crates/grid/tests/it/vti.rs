//! VTK XML ImageData `.vti` files: every encoding VTK's own writer produces (fixtures in
//! `tests/data/vti/`, written by `make_fixtures.py` with VTK 9.7's vtkXMLImageDataWriter),
//! lucent's writer read back, and broken files refused with a typed error.

use std::path::{Path, PathBuf};

use glam::DVec3;
use lucent_grid::io::{self, LoadOptions, ScalarType};
use lucent_grid::{Grid, GridError, GridGeometry};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/vti")
        .join(name)
}

/// The fixtures' image: value i + 10 j + 100 k at index (i, j, k) of `dims`.
fn expected(dims: [usize; 3]) -> Vec<f32> {
    let mut v = Vec::new();
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                v.push((i + 10 * j + 100 * k) as f32);
            }
        }
    }
    v
}

#[test]
fn every_encoding_of_vtks_writer_reads_the_same_image() {
    // Point data 5 x 4 x 3, origin (1, 2, 3), spacing (0.5, 0.25, 2): the sample at index
    // (i, j, k) is the centre of cell (i, j, k), so cell (0, 0, 0) is centred at the
    // origin. Values are small integers: equal exactly.
    for name in [
        "ascii.vti",
        "binary.vti",
        "binary_zlib.vti",
        "appended_raw.vti",
        "appended_raw_zlib.vti",
        "appended_base64_zlib.vti",
    ] {
        let grid = io::read_volume(fixture(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(grid.dims(), [5, 4, 3], "{name}");
        assert_eq!(
            grid.geometry().spacing(),
            DVec3::new(0.5, 0.25, 2.0),
            "{name}"
        );
        assert_eq!(
            grid.geometry().cell_centre(0, 0, 0),
            DVec3::new(1.0, 2.0, 3.0),
            "{name}"
        );
        assert_eq!(grid.data(), expected([5, 4, 3]).as_slice(), "{name}");
    }
}

#[test]
fn cell_data_fill_the_cells_between_the_points() {
    // 5 x 4 x 3 points hold 4 x 3 x 2 cells; cell (0, 0, 0) spans the first points.
    let grid = io::read_volume(fixture("cell_data_float.vti")).unwrap();
    assert_eq!(grid.dims(), [4, 3, 2]);
    assert_eq!(grid.geometry().origin(), DVec3::new(1.0, 2.0, 3.0));
    assert_eq!(grid.data(), expected([4, 3, 2]).as_slice());
}

#[test]
fn lucents_writer_round_trips_raw_and_compressed() {
    // Odd dimensions (not multiples of 8), a non-trivial origin, f32 and u16.
    let dir = tempfile::tempdir().unwrap();
    let g = GridGeometry::new(
        [7, 5, 9],
        DVec3::new(0.3, 0.2, 0.7),
        DVec3::new(-1.0, 0.5, 2.0),
    )
    .unwrap();
    let mut grid = Grid::filled(g, 0.0);
    for (index, v) in grid.data_mut().iter_mut().enumerate() {
        let [i, j, k] = g.coords(index);
        *v = (i * 3 + j * 7 + k * 11) as f32 * 0.5;
    }
    for (scalar, compress) in [
        (ScalarType::F32, false),
        (ScalarType::F32, true),
        (ScalarType::F64, true),
        (ScalarType::U16, true),
    ] {
        let path = dir
            .path()
            .join(format!("x_{compress}_{}.vti", scalar.name()));
        let source = if scalar == ScalarType::U16 {
            grid.map(|v| v.round())
        } else {
            grid.clone()
        };
        io::vti::write(&path, &source, scalar, compress).unwrap();
        let back = io::read_volume(&path).unwrap();
        assert_eq!(back.dims(), source.dims());
        assert!((back.geometry().origin() - g.origin()).abs().max_element() < 1e-12);
        assert!(
            (back.geometry().spacing() - g.spacing())
                .abs()
                .max_element()
                < 1e-12
        );
        assert_eq!(
            back.data(),
            source.data(),
            "{scalar:?}, compressed {compress}"
        );
    }
}

#[test]
fn broken_files_are_typed_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = std::fs::read(fixture("appended_raw_zlib.vti")).unwrap();
    let text = String::from_utf8_lossy(&good).into_owned();
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("truncated", good[..good.len() - 60].to_vec()),
        (
            "wrong type",
            text.replace("type=\"ImageData\"", "type=\"PolyData\"")
                .into_bytes(),
        ),
        (
            "lz4",
            good.windows(21)
                .position(|w| w == b"vtkZLibDataCompressor")
                .map(|p| {
                    [
                        &good[..p],
                        b"vtkLZ4DataCompressor".as_slice(),
                        &good[p + 21..],
                    ]
                    .concat()
                })
                .unwrap(),
        ),
        ("empty", Vec::new()),
        ("not xml", b"hello".to_vec()),
        (
            "huge extent",
            text.replace(
                "WholeExtent=\"0 4 0 3 0 2\"",
                "WholeExtent=\"0 4000000 0 3000000 0 2000000\"",
            )
            .into_bytes(),
        ),
    ];
    for (what, bytes) in cases {
        let path = dir.path().join("broken.vti");
        std::fs::write(&path, &bytes).unwrap();
        let err = io::read_volume_with(
            &path,
            &LoadOptions {
                memory_budget: 1 << 30,
            },
        )
        .expect_err(what);
        assert!(err.to_string().contains("broken.vti"), "{what}: {err}");
        assert!(
            !matches!(err, GridError::Io { .. }),
            "{what}: a format error, not I/O: {err}"
        );
    }
}

#[test]
fn an_unknown_extension_lists_the_formats_lucent_reads() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("volume.xyz");
    std::fs::write(&path, b"x").unwrap();
    let err = io::read_volume(&path).unwrap_err().to_string();
    for format in [
        ".nrrd", ".mhd", ".vtk", ".vti", ".vol", ".npy", ".vdb", ".raw",
    ] {
        assert!(err.contains(format), "{format} missing from: {err}");
    }
}
