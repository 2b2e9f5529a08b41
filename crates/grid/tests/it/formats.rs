//! Volume files: write-then-read round trips for every writable format (property tests with
//! random dims, placement and values), and readers that never panic on bad bytes.

use std::path::{Path, PathBuf};

use glam::DVec3;
use lucent_grid::io::nrrd::Encoding;
use lucent_grid::io::raw::RawLayout;
use lucent_grid::io::{self, Endian, LoadOptions, ScalarType};
use lucent_grid::{Grid, GridError, GridGeometry};
use proptest::prelude::*;

/// A grid with random dims, placement and values; integer types get integral values in range.
fn grid_strategy(scalar: ScalarType) -> impl Strategy<Value = Grid> {
    (
        [1usize..=9, 1usize..=9, 1usize..=9],
        [0.01f64..10.0, 0.01f64..10.0, 0.01f64..10.0],
        [-100.0f64..100.0, -100.0f64..100.0, -100.0f64..100.0],
        any::<u64>(),
    )
        .prop_map(move |(dims, h, o, seed)| {
            let geometry =
                GridGeometry::new(dims, DVec3::from_array(h), DVec3::from_array(o)).unwrap();
            let mut state = seed | 1;
            let mut next = move || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                state
            };
            let values = (0..geometry.voxel_count())
                .map(|_| {
                    let r = next();
                    match scalar {
                        ScalarType::U8 => (r % 256) as f32,
                        ScalarType::I8 => (r % 256) as f32 - 128.0,
                        ScalarType::U16 => (r % 65536) as f32,
                        ScalarType::I16 => (r % 65536) as f32 - 32768.0,
                        ScalarType::U32 | ScalarType::I32 => (r % 16_777_216) as f32,
                        ScalarType::F16 => half::f16::from_bits((r % 0x7c00) as u16).to_f32(),
                        ScalarType::F32 | ScalarType::F64 => {
                            f32::from_bits((r % 0x7f80_0000) as u32)
                                * if r & 1 == 0 { 1.0 } else { -1.0 }
                        }
                    }
                })
                .collect();
            Grid::from_vec(geometry, values).unwrap()
        })
}

fn temp_path(dir: &tempfile::TempDir, name: &str) -> PathBuf {
    dir.path().join(name)
}

/// Values bit for bit; the box the cells fill to `tolerance` relative to the largest
/// coordinate (formats store placement as decimal text, exact to a few ulps, or, for
/// Mitsuba, as an f32 box).
fn assert_same(read: &Grid, written: &Grid, tolerance: f64) {
    assert_eq!(read.dims(), written.dims());
    let bits = |g: &Grid| g.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(read), bits(written));
    let (a, b) = (read.geometry().bounds(), written.geometry().bounds());
    let scale = b.0.abs().max(b.1.abs()).max_element();
    for (x, y) in [(a.0, b.0), (a.1, b.1)] {
        assert!(
            (x - y).abs().max_element() <= tolerance * scale,
            "box {a:?} vs {b:?}"
        );
    }
}

const ALL_TYPES: [ScalarType; 9] = [
    ScalarType::U8,
    ScalarType::I8,
    ScalarType::U16,
    ScalarType::I16,
    ScalarType::U32,
    ScalarType::I32,
    ScalarType::F16,
    ScalarType::F32,
    ScalarType::F64,
];

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn raw_round_trips(
        (scalar, grid) in (0usize..9).prop_flat_map(|i| (Just(ALL_TYPES[i]), grid_strategy(ALL_TYPES[i]))),
        big in any::<bool>(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let path = temp_path(&dir, "v.raw");
        let endian = if big { Endian::Big } else { Endian::Little };
        io::raw::write(&path, &grid, scalar, endian).unwrap();
        let g = grid.geometry();
        let layout = RawLayout { dims: g.dims(), scalar, endian, spacing: g.spacing(), origin: g.origin() };
        let back = io::raw::read(&path, &layout, &LoadOptions::default()).unwrap();
        assert_same(&back, &grid, 0.0);
    }

    #[test]
    fn npy_round_trips_f32(grid in grid_strategy(ScalarType::F32)) {
        let dir = tempfile::tempdir().unwrap();
        let path = temp_path(&dir, "v.npy");
        io::npy::write(&path, &grid, ScalarType::F32).unwrap();
        let back = io::npy::read(&path, &LoadOptions::default()).unwrap();
        // .npy keeps no geometry: values and dims only.
        prop_assert_eq!(back.dims(), grid.dims());
        prop_assert!(back.data().iter().zip(grid.data()).all(|(a, b)| a.to_bits() == b.to_bits()));
    }

    #[test]
    fn npy_round_trips_u8(grid in grid_strategy(ScalarType::U8)) {
        let dir = tempfile::tempdir().unwrap();
        let path = temp_path(&dir, "v.npy");
        io::npy::write(&path, &grid, ScalarType::U8).unwrap();
        let back = io::npy::read(&path, &LoadOptions::default()).unwrap();
        prop_assert_eq!(back.data(), grid.data());
    }

    #[test]
    fn npy_round_trips_u16(grid in grid_strategy(ScalarType::U16)) {
        let dir = tempfile::tempdir().unwrap();
        let path = temp_path(&dir, "v.npy");
        io::npy::write(&path, &grid, ScalarType::U16).unwrap();
        let back = io::npy::read(&path, &LoadOptions::default()).unwrap();
        prop_assert_eq!(back.data(), grid.data());
    }

    #[test]
    fn nrrd_round_trips(grid in grid_strategy(ScalarType::F32), gzip in any::<bool>()) {
        let dir = tempfile::tempdir().unwrap();
        let path = temp_path(&dir, "v.nrrd");
        io::nrrd::write(&path, &grid, ScalarType::F32, if gzip { Encoding::Gzip } else { Encoding::Raw }).unwrap();
        // Placement is written with shortest round-trip decimals; the corner is recomputed
        // from the first sample's centre, so allow a few ulps.
        assert_same(&io::read_volume(&path).unwrap(), &grid, 1e-14);
    }

    #[test]
    fn nrrd_round_trips_integers(grid in grid_strategy(ScalarType::I16)) {
        let dir = tempfile::tempdir().unwrap();
        let path = temp_path(&dir, "v.nrrd");
        io::nrrd::write(&path, &grid, ScalarType::I16, Encoding::Raw).unwrap();
        assert_same(&io::read_volume(&path).unwrap(), &grid, 1e-14);
    }

    #[test]
    fn metaimage_round_trips(grid in grid_strategy(ScalarType::F32), attached in any::<bool>()) {
        let dir = tempfile::tempdir().unwrap();
        let path = temp_path(&dir, if attached { "v.mha" } else { "v.mhd" });
        io::mhd::write(&path, &grid, ScalarType::F32).unwrap();
        assert_same(&io::read_volume(&path).unwrap(), &grid, 1e-14);
    }

    #[test]
    fn vtk_round_trips(grid in grid_strategy(ScalarType::U16)) {
        let dir = tempfile::tempdir().unwrap();
        let path = temp_path(&dir, "v.vtk");
        io::vtk::write(&path, &grid, ScalarType::U16).unwrap();
        assert_same(&io::read_volume(&path).unwrap(), &grid, 1e-14);
    }

    #[test]
    fn vtk_round_trips_floats(grid in grid_strategy(ScalarType::F32)) {
        let dir = tempfile::tempdir().unwrap();
        let path = temp_path(&dir, "v.vtk");
        io::vtk::write(&path, &grid, ScalarType::F32).unwrap();
        assert_same(&io::read_volume(&path).unwrap(), &grid, 1e-14);
    }

    #[test]
    fn mitsuba_round_trips(grid in grid_strategy(ScalarType::F32), channels in 1usize..=3) {
        let dir = tempfile::tempdir().unwrap();
        let path = temp_path(&dir, "v.vol");
        let others: Vec<Grid> = (1..channels).map(|c| grid.map(|v| v * c as f32)).collect();
        let mut all = vec![&grid];
        all.extend(others.iter());
        // Doubling a value near f32::MAX overflows: a non-finite sample is never written.
        if others.iter().any(|g| g.data().iter().any(|v| !v.is_finite())) {
            let refused = io::mitsuba::write(&path, &all);
            prop_assert!(matches!(refused, Err(GridError::NonFinite { .. })), "{:?}", refused);
            return Ok(());
        }
        io::mitsuba::write(&path, &all).unwrap();
        let back = io::mitsuba::read_channels(&path, &LoadOptions::default()).unwrap();
        prop_assert_eq!(back.len(), channels);
        // The box is stored in f32: within 2⁻²⁴ of the largest coordinate.
        for (b, w) in back.iter().zip(&all) {
            assert_same(b, w, 1e-6);
        }
    }
}

#[test]
fn writers_refuse_values_the_type_cannot_hold() {
    let dir = tempfile::tempdir().unwrap();
    let geometry = GridGeometry::new([2, 1, 1], DVec3::ONE, DVec3::ZERO).unwrap();
    let grid = Grid::from_vec(geometry, vec![1.0, 300.0]).unwrap();
    let path = temp_path(&dir, "v.npy");
    match io::npy::write(&path, &grid, ScalarType::U8) {
        Err(GridError::Lossy {
            index: 1, value, ..
        }) => assert_eq!(value, 300.0),
        other => panic!("expected a lossy-write error, got {other:?}"),
    }
    let fractional = Grid::from_vec(geometry, vec![1.5, 2.0]).unwrap();
    assert!(matches!(
        io::raw::write(&path, &fractional, ScalarType::U16, Endian::Little),
        Err(GridError::Lossy { index: 0, .. })
    ));
}

/// A valid small file of each format, as bytes, with its parser.
type Parser = fn(&[u8], &Path) -> Result<(), GridError>;

fn samples() -> Vec<(&'static str, Vec<u8>, Parser)> {
    let dir = tempfile::tempdir().unwrap();
    let geometry = GridGeometry::new(
        [3, 4, 5],
        DVec3::new(0.5, 1.0, 2.0),
        DVec3::new(1.0, -2.0, 3.0),
    )
    .unwrap();
    let grid = Grid::from_fn(geometry, |p| (p.x + p.y * p.z) as f32);
    let write = |name: &str, f: &dyn Fn(&Path)| {
        let p = dir.path().join(name);
        f(&p);
        std::fs::read(&p).unwrap()
    };
    vec![
        (
            "nrrd",
            write("a.nrrd", &|p| {
                io::nrrd::write(p, &grid, ScalarType::F32, Encoding::Raw).unwrap()
            }),
            |b, p| io::nrrd::parse(b, p, &LoadOptions::default()).map(drop),
        ),
        (
            "nrrd-gzip",
            write("b.nrrd", &|p| {
                io::nrrd::write(p, &grid, ScalarType::F32, Encoding::Gzip).unwrap()
            }),
            |b, p| io::nrrd::parse(b, p, &LoadOptions::default()).map(drop),
        ),
        (
            "mha",
            write("a.mha", &|p| {
                io::mhd::write(p, &grid, ScalarType::F32).unwrap()
            }),
            |b, p| io::mhd::parse(b, p, &LoadOptions::default()).map(drop),
        ),
        (
            "vtk",
            write("a.vtk", &|p| {
                io::vtk::write(p, &grid, ScalarType::F32).unwrap()
            }),
            |b, p| io::vtk::parse(b, p, &LoadOptions::default()).map(drop),
        ),
        (
            "vol",
            write("a.vol", &|p| io::mitsuba::write(p, &[&grid]).unwrap()),
            |b, p| io::mitsuba::parse(b, p, &LoadOptions::default()).map(drop),
        ),
        (
            "npy",
            write("a.npy", &|p| {
                io::npy::write(p, &grid, ScalarType::F32).unwrap()
            }),
            |b, p| io::npy::parse(b, p, &LoadOptions::default()).map(drop),
        ),
        ("vdb", b"\x20BDV\0\0\0\0\xde\0\0\0".to_vec(), |b, p| {
            io::vdb::parse(b, p, None, &LoadOptions::default()).map(drop)
        }),
        ("raw", vec![0u8; 60], |b, p| {
            io::raw::parse(
                b,
                p,
                &RawLayout::new([3, 4, 5], ScalarType::U8),
                &LoadOptions::default(),
            )
            .map(drop)
        }),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_bytes_never_panic_a_reader(bytes in prop::collection::vec(any::<u8>(), 0..512), which in 0usize..8) {
        let (_, _, parse) = samples()[which];
        let _ = parse(&bytes, Path::new("random.bin"));
    }

    #[test]
    fn mutated_headers_never_panic_a_reader(which in 0usize..8, edits in prop::collection::vec((0usize..400, any::<u8>()), 1..6), cut in 0usize..800) {
        let (_, mut bytes, parse) = samples().swap_remove(which);
        for (pos, value) in edits {
            let n = bytes.len();
            bytes[pos % n] = value;
        }
        bytes.truncate(cut.max(1));
        let _ = parse(&bytes, Path::new("mutated.bin"));
    }
}

#[test]
fn bad_files_get_typed_errors_naming_the_file() {
    let path = Path::new("broken.nrrd");
    let opts = LoadOptions::default();
    // Truncated payload.
    let truncated = b"NRRD0004\ntype: float\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n0123";
    match io::nrrd::parse(truncated, path, &opts) {
        Err(
            e @ GridError::Truncated {
                expected: 32,
                found: 4,
                ..
            },
        ) => assert!(e.to_string().contains("broken.nrrd")),
        other => panic!("expected a truncation error, got {other:?}"),
    }
    // A header that claims 10¹² voxels is refused before any allocation.
    let absurd =
        b"NRRD0004\ntype: float\ndimension: 3\nsizes: 10000 10000 10000\nencoding: raw\n\n";
    assert!(
        matches!(
            io::nrrd::parse(absurd, path, &opts),
            Err(GridError::OverBudget { .. })
        ),
        "10^12 voxels"
    );
    let overflow =
        b"NRRD0004\ntype: float\ndimension: 3\nsizes: 18446744073709551615 2 2\nencoding: raw\n\n";
    assert!(matches!(
        io::nrrd::parse(overflow, path, &opts),
        Err(GridError::Malformed { .. })
    ));
    // Unknown type.
    let unknown = b"NRRD0004\ntype: quaternion\ndimension: 3\nsizes: 1 1 1\nencoding: raw\n\n";
    assert!(matches!(
        io::nrrd::parse(unknown, path, &opts),
        Err(GridError::Unsupported { .. })
    ));
    // Dims that do not match the payload.
    let mismatch =
        b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n0123456789";
    assert!(matches!(
        io::nrrd::parse(mismatch, path, &opts),
        Err(GridError::SizeMismatch {
            expected: 8,
            found: 10,
            ..
        })
    ));
    // The same checks in the binary formats.
    let mut vol = b"VOL\x03".to_vec();
    for v in [1i32, 10000, 10000, 10000, 1] {
        vol.extend_from_slice(&v.to_le_bytes());
    }
    vol.extend_from_slice(&[0u8; 24]);
    assert!(matches!(
        io::mitsuba::parse(&vol, Path::new("huge.vol"), &opts),
        Err(GridError::OverBudget { .. })
    ));
    let npy_header = "{'descr': '<f4', 'fortran_order': False, 'shape': (10000, 10000, 10000), }\n";
    let mut npy = b"\x93NUMPY\x01\x00".to_vec();
    npy.extend_from_slice(&(npy_header.len() as u16).to_le_bytes());
    npy.extend_from_slice(npy_header.as_bytes());
    assert!(matches!(
        io::npy::parse(&npy, Path::new("huge.npy"), &opts),
        Err(GridError::OverBudget { .. })
    ));
    // Missing detached data files name the file that is missing.
    let detached = b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: nowhere.raw\n";
    match io::nrrd::parse(detached, Path::new("/tmp/x.nhdr"), &opts) {
        Err(GridError::Io { path, .. }) => assert!(path.ends_with("nowhere.raw")),
        other => panic!("expected an I/O error naming the data file, got {other:?}"),
    }
}

#[test]
fn npy_written_slab_by_slab_is_the_same_file() {
    let g = GridGeometry::new([5, 4, 3], DVec3::splat(0.5), DVec3::ZERO).unwrap();
    let grids: Vec<Grid> = (0..3)
        .map(|c| {
            Grid::from_fn(g, move |p| {
                (p.x + 10.0 * p.y + 100.0 * p.z + c as f64) as f32
            })
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    for channels in [1, 3] {
        let whole = dir.path().join(format!("whole{channels}.npy"));
        let slabs = dir.path().join(format!("slabs{channels}.npy"));
        let refs: Vec<&Grid> = grids.iter().take(channels).collect();
        lucent_grid::io::npy::write_channels(&whole, &refs, ScalarType::F32).unwrap();
        lucent_grid::io::npy::write_f32_slabs(&slabs, g.dims(), channels, |c, z, out| {
            out.copy_from_slice(&grids[c].data()[z * 20..(z + 1) * 20]);
            Ok::<_, String>(())
        })
        .unwrap();
        assert_eq!(
            std::fs::read(&whole).unwrap(),
            std::fs::read(&slabs).unwrap()
        );
    }
    // A failing source is an error naming the file, not a panic.
    let bad = dir.path().join("bad.npy");
    let e = lucent_grid::io::npy::write_f32_slabs(&bad, g.dims(), 1, |_, _, _| Err("disk gone"))
        .unwrap_err();
    assert!(
        e.to_string().contains("bad.npy") && e.to_string().contains("disk gone"),
        "{e}"
    );
}
