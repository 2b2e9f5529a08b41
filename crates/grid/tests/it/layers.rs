//! Positioned reads of z-layers and boxes of cells (`io::layers`): the layers and boxes of
//! every whole-file read, for random grids, ranges and sample types (raw, npy) and for
//! NRRD attached and detached; a 32 GiB (sparse) volume's two layers and a box under a
//! budget the whole could never fit; positioned writes of layers and boxes that make the
//! whole file; and typed errors for bad ranges, sizes and compressed payloads.

use std::io::Write;

use glam::DVec3;
use lucent_grid::io::layers::{
    read_npy_layers, read_npy_region, read_nrrd_layers, read_nrrd_region, read_raw_layers,
    read_raw_region,
};
use lucent_grid::io::raw::RawLayout;
use lucent_grid::io::{Endian, LoadOptions, ScalarType, npy, nrrd, raw};
use lucent_grid::{Grid, GridError, GridGeometry};
use proptest::prelude::*;

fn grid(dims: [usize; 3], seed: u64) -> Grid {
    let geometry = GridGeometry::new(dims, DVec3::ONE, DVec3::ZERO).unwrap();
    let n = dims.iter().product::<usize>();
    // Small integers: exact in every sample type.
    let data = (0..n)
        .map(|i| (((i as u64 * 2_654_435_761) ^ seed) % 200) as f32)
        .collect();
    Grid::from_vec(geometry, data).unwrap()
}

fn slice(g: &Grid, z: std::ops::Range<usize>) -> Vec<f32> {
    let [nx, ny, _] = g.dims();
    g.data()[z.start * nx * ny..z.end * nx * ny].to_vec()
}

/// The box `cells` of `g`, x fastest.
fn boxed(g: &Grid, cells: &[std::ops::Range<usize>; 3]) -> Vec<f32> {
    let [nx, ny, _] = g.dims();
    let mut out = Vec::new();
    for k in cells[2].clone() {
        for j in cells[1].clone() {
            let row = nx * (j + ny * k);
            out.extend_from_slice(&g.data()[row + cells[0].start..row + cells[0].end]);
        }
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]
    #[test]
    fn boxes_are_the_whole_reads_boxes(
        dims in (1usize..13, 1usize..11, 1usize..9),
        cuts in proptest::collection::vec((0.0f64..1.0, 0.0f64..1.0), 3),
        seed in any::<u64>(),
        scalar in prop::sample::select(vec![ScalarType::U8, ScalarType::I16, ScalarType::F32, ScalarType::F64]),
        big_endian in any::<bool>(),
    ) {
        let dims = [dims.0, dims.1, dims.2];
        let cells: [std::ops::Range<usize>; 3] = std::array::from_fn(|a| {
            let (u, v) = ((cuts[a].0 * dims[a] as f64) as usize, (cuts[a].1 * dims[a] as f64) as usize);
            u.min(v)..(u.max(v) + 1).min(dims[a])
        });
        let g = grid(dims, seed);
        let dir = tempfile::tempdir().unwrap();
        let options = LoadOptions::default();

        let npy_path = dir.path().join("v.npy");
        npy::write(&npy_path, &g, scalar).unwrap();
        let whole = npy::read(&npy_path, &options).unwrap();
        let part = read_npy_region(&npy_path, cells.clone(), &options).unwrap();
        prop_assert_eq!(part.whole, *whole.geometry());
        prop_assert_eq!(part.origin, cells.clone().map(|r| r.start));
        prop_assert_eq!(part.grid.dims(), cells.clone().map(|r| r.len()));
        prop_assert_eq!(part.grid.data(), &boxed(&whole, &cells)[..]);

        let endian = if big_endian { Endian::Big } else { Endian::Little };
        let raw_path = dir.path().join("v.raw");
        raw::write(&raw_path, &g, scalar, endian).unwrap();
        let layout = RawLayout {
            dims,
            scalar,
            endian,
            spacing: DVec3::new(0.5, 0.25, 2.0),
            origin: DVec3::new(-1.0, 3.0, 7.0),
        };
        let whole = raw::read(&raw_path, &layout, &options).unwrap();
        let part = read_raw_region(&raw_path, &layout, cells.clone(), &options).unwrap();
        prop_assert_eq!(part.grid.data(), &boxed(&whole, &cells)[..]);
        let corner = DVec3::new(cells[0].start as f64, cells[1].start as f64, cells[2].start as f64);
        prop_assert_eq!(part.grid.geometry().origin(), layout.origin + corner * layout.spacing);
        prop_assert_eq!(part.grid.geometry().spacing(), layout.spacing);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]
    #[test]
    fn layers_are_the_whole_reads_layers(
        nx in 1usize..13, ny in 1usize..11, nz in 1usize..17,
        a in 0usize..17, b in 0usize..17, seed in any::<u64>(),
        scalar in prop::sample::select(vec![ScalarType::U8, ScalarType::I16, ScalarType::U16, ScalarType::F32, ScalarType::F64]),
        big_endian in any::<bool>(),
    ) {
        let (k0, k1) = (a.min(b) % nz, (a.max(b) % nz) + 1);
        prop_assume!(k0 < k1);
        let g = grid([nx, ny, nz], seed);
        let dir = tempfile::tempdir().unwrap();
        let options = LoadOptions::default();

        let npy_path = dir.path().join("v.npy");
        npy::write(&npy_path, &g, scalar).unwrap();
        let whole = npy::read(&npy_path, &options).unwrap();
        let part = read_npy_layers(&npy_path, k0..k1, &options).unwrap();
        prop_assert_eq!(part.whole, *whole.geometry());
        prop_assert_eq!(part.first, k0);
        prop_assert_eq!(part.grid.dims(), [nx, ny, k1 - k0]);
        prop_assert_eq!(part.grid.data(), &slice(&whole, k0..k1)[..]);
        prop_assert_eq!(part.grid.geometry().origin().z, k0 as f64);

        let endian = if big_endian { Endian::Big } else { Endian::Little };
        let raw_path = dir.path().join("v.raw");
        raw::write(&raw_path, &g, scalar, endian).unwrap();
        let layout = RawLayout {
            dims: [nx, ny, nz],
            scalar,
            endian,
            spacing: DVec3::new(0.5, 0.25, 2.0),
            origin: DVec3::new(-1.0, 3.0, 7.0),
        };
        let whole = raw::read(&raw_path, &layout, &options).unwrap();
        let part = read_raw_layers(&raw_path, &layout, k0..k1, &options).unwrap();
        prop_assert_eq!(part.grid.data(), &slice(&whole, k0..k1)[..]);
        prop_assert_eq!(part.grid.geometry().origin(), DVec3::new(-1.0, 3.0, 7.0 + 2.0 * k0 as f64));
        prop_assert_eq!(part.grid.geometry().spacing(), layout.spacing);
    }
}

#[test]
fn two_layers_of_a_32_gib_volume_read_within_a_small_budget() {
    // A sparse .npy of 1024 × 1024 × 8192 f32 (32 GiB, no disk used): the whole read is
    // refused by a 64 MiB budget; two layers (8 MiB) are read, and are the zeros there.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("huge.npy");
    let dict = "{'descr': '<f4', 'fortran_order': False, 'shape': (8192, 1024, 1024), }";
    let mut header = dict.to_owned();
    while !(10 + header.len() + 1).is_multiple_of(64) {
        header.push(' ');
    }
    header.push('\n');
    let mut file = std::fs::File::create(&path).unwrap();
    file.write_all(b"\x93NUMPY\x01\x00").unwrap();
    file.write_all(&(header.len() as u16).to_le_bytes())
        .unwrap();
    file.write_all(header.as_bytes()).unwrap();
    let data_offset = 10 + header.len() as u64;
    file.set_len(data_offset + 4 * 1024 * 1024 * 8192).unwrap();
    drop(file);
    let options = LoadOptions {
        memory_budget: 64 << 20,
    };
    assert!(matches!(
        npy::read(&path, &options),
        Err(GridError::OverBudget { .. })
    ));
    let part = read_npy_layers(&path, 4000..4002, &options).unwrap();
    assert_eq!(part.whole.dims(), [1024, 1024, 8192]);
    assert_eq!(part.grid.dims(), [1024, 1024, 2]);
    assert!(part.grid.data().iter().all(|&v| v == 0.0));
    // Ten layers (40 MiB of f32 plus their samples) do not fit: the budget is per read.
    assert!(matches!(
        read_npy_layers(&path, 0..10, &options),
        Err(GridError::OverBudget { .. })
    ));
    // A box of 128 × 128 × 256 cells through all the volume's depth (16 MiB): one
    // positioned read per x-line.
    let part = read_npy_region(&path, [512..640, 0..128, 4000..4256], &options).unwrap();
    assert_eq!(part.grid.dims(), [128, 128, 256]);
    assert_eq!(part.origin, [512, 0, 4000]);
    assert!(part.grid.data().iter().all(|&v| v == 0.0));
}

#[test]
fn bad_ranges_and_sizes_are_typed_errors() {
    let dir = tempfile::tempdir().unwrap();
    let g = grid([5, 4, 6], 7);
    let path = dir.path().join("v.npy");
    npy::write(&path, &g, ScalarType::F32).unwrap();
    let options = LoadOptions::default();
    for range in [3..3, 5..7, 6..7] {
        let e = read_npy_layers(&path, range.clone(), &options).unwrap_err();
        assert!(
            matches!(e, GridError::InvalidParameter { name: "layers", .. }),
            "{range:?}: {e}"
        );
    }
    // A truncated file is refused before anything is read, as by the whole read.
    let bytes = std::fs::read(&path).unwrap();
    let cut = dir.path().join("cut.npy");
    std::fs::write(&cut, &bytes[..bytes.len() - 4]).unwrap();
    assert!(matches!(
        read_npy_layers(&cut, 0..1, &options),
        Err(GridError::SizeMismatch { .. })
    ));
    let raw_path = dir.path().join("v.raw");
    raw::write(&raw_path, &g, ScalarType::U8, Endian::Little).unwrap();
    let wrong = RawLayout::new([5, 4, 7], ScalarType::U8);
    assert!(matches!(
        read_raw_layers(&raw_path, &wrong, 0..2, &options),
        Err(GridError::SizeMismatch { .. })
    ));
    // A NaN in the layers is refused by its cell; outside them it is not read.
    // (The writers refuse NaN: patch one into layer 5's bytes.)
    let mut bytes = std::fs::read(&path).unwrap();
    let data_offset = bytes.len() - 4 * 5 * 4 * 6;
    let at = data_offset + 4 * (5 * 4 * 5 + 3);
    bytes[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let nan_path = dir.path().join("nan.npy");
    std::fs::write(&nan_path, &bytes).unwrap();
    assert!(matches!(
        read_npy_layers(&nan_path, 4..6, &options),
        Err(GridError::NonFinite { .. })
    ));
    assert!(read_npy_layers(&nan_path, 0..5, &options).is_ok());
}

#[test]
fn nrrd_layers_attached_and_detached_are_the_whole_reads_layers() {
    let dir = tempfile::tempdir().unwrap();
    let options = LoadOptions::default();
    let geometry = GridGeometry::new(
        [7, 5, 9],
        DVec3::new(0.5, 0.25, 2.0),
        DVec3::new(-1.0, 3.0, 7.0),
    )
    .unwrap();
    let g = Grid::from_vec(geometry, grid([7, 5, 9], 3).data().to_vec()).unwrap();
    // Attached, as lucent writes it.
    let attached = dir.path().join("v.nrrd");
    nrrd::write(&attached, &g, ScalarType::U16, nrrd::Encoding::Raw).unwrap();
    let whole = nrrd::read(&attached, &options).unwrap();
    for range in [0..9, 2..5, 8..9] {
        let part = read_nrrd_layers(&attached, range.clone(), &options).unwrap();
        assert_eq!(part.whole, *whole.geometry());
        assert_eq!(part.grid.data(), &slice(&whole, range.clone())[..]);
        let z = whole.geometry().origin().z + 2.0 * range.start as f64;
        assert!((part.grid.geometry().origin().z - z).abs() < 1e-12);
    }
    // Detached, big-endian floats at the end of a data file that starts with junk
    // (`byte skip: -1`).
    let mut data = b"junk before the samples".to_vec();
    for v in whole.data() {
        data.extend_from_slice(&v.to_be_bytes());
    }
    std::fs::write(dir.path().join("v.raw"), &data).unwrap();
    let nhdr = dir.path().join("v.nhdr");
    std::fs::write(
        &nhdr,
        "NRRD0004\ntype: float\ndimension: 3\nsizes: 7 5 9\nspacings: 0.5 0.25 2\nendian: big\nencoding: raw\nbyte skip: -1\ndata file: v.raw\n",
    )
    .unwrap();
    let whole_detached = nrrd::read(&nhdr, &options).unwrap();
    let part = read_nrrd_layers(&nhdr, 3..7, &options).unwrap();
    assert_eq!(part.grid.data(), &slice(&whole_detached, 3..7)[..]);
    assert_eq!(part.grid.data(), &slice(&whole, 3..7)[..]);
    // A compressed payload cannot be read in part.
    let gz = dir.path().join("v.gz.nrrd");
    nrrd::write(&gz, &g, ScalarType::F32, nrrd::Encoding::Gzip).unwrap();
    assert!(matches!(
        read_nrrd_layers(&gz, 0..2, &options),
        Err(GridError::Unsupported { .. })
    ));
    // A payload one sample short is truncated, as for the whole read.
    let short = dir.path().join("short.raw");
    std::fs::write(&short, &data[..data.len() - 4]).unwrap();
    let nhdr_short = dir.path().join("short.nhdr");
    std::fs::write(
        &nhdr_short,
        "NRRD0004\ntype: float\ndimension: 3\nsizes: 7 5 9\nendian: big\nencoding: raw\nbyte skip: 23\ndata file: short.raw\n",
    )
    .unwrap();
    assert!(matches!(
        read_nrrd_layers(&nhdr_short, 0..2, &options),
        Err(GridError::Truncated { .. })
    ));
    assert!(nrrd::read(&nhdr_short, &options).is_err());
}

/// Layers written by positioned writes, in any order, make the file the whole write
/// makes, byte for byte; a bad range is refused.
#[test]
fn positioned_npy_writes_make_the_whole_file() {
    use lucent_grid::io::atomic::partial_path;
    use lucent_grid::io::layers::{create_npy, finish_npy, write_npy_layers};
    let dir = std::env::temp_dir().join(format!("lucent-npy-layers-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for dims in [[5, 3, 7], [1, 1, 1], [9, 4, 2]] {
        let g = grid(dims, 11);
        let whole = dir.join("whole.npy");
        let parts = dir.join("parts.npy");
        npy::write(&whole, &g, ScalarType::F32).unwrap();
        // A longer partial file left behind is emptied first.
        std::fs::write(partial_path(&parts), vec![7u8; 10_000]).unwrap();
        // An older file at the target stays until the new one is whole.
        std::fs::write(&parts, b"older").unwrap();
        create_npy(&parts, dims).unwrap();
        let nz = dims[2];
        let cuts = [0, nz / 3, nz / 3 + nz / 2, nz];
        // Last slab first: the order of the ranks' writes does not matter.
        for w in cuts.windows(2).rev().filter(|w| w[0] < w[1]) {
            write_npy_layers(&parts, dims, w[0]..w[1], &slice(&g, w[0]..w[1])).unwrap();
            assert_eq!(std::fs::read(&parts).unwrap(), b"older");
        }
        finish_npy(&parts).unwrap();
        assert!(!partial_path(&parts).exists());
        assert_eq!(
            std::fs::read(&parts).unwrap(),
            std::fs::read(&whole).unwrap()
        );
        assert!(matches!(
            write_npy_layers(&parts, dims, 0..nz + 1, &[]),
            Err(GridError::InvalidParameter { .. })
        ));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn nrrd_boxes_and_bad_boxes() {
    let dir = tempfile::tempdir().unwrap();
    let options = LoadOptions::default();
    let geometry = GridGeometry::new(
        [7, 5, 9],
        DVec3::new(0.5, 0.25, 2.0),
        DVec3::new(-1.0, 3.0, 7.0),
    )
    .unwrap();
    let g = Grid::from_vec(geometry, grid([7, 5, 9], 5).data().to_vec()).unwrap();
    let path = dir.path().join("v.nrrd");
    nrrd::write(&path, &g, ScalarType::F32, nrrd::Encoding::Raw).unwrap();
    let whole = nrrd::read(&path, &options).unwrap();
    for cells in [
        [0..7, 0..5, 0..9],
        [2..5, 1..4, 3..8],
        [6..7, 4..5, 8..9],
        [0..7, 2..3, 0..9],
    ] {
        let part = read_nrrd_region(&path, cells.clone(), &options).unwrap();
        assert_eq!(part.grid.data(), &boxed(&whole, &cells)[..], "{cells:?}");
    }
    // Empty, past the grid.
    for cells in [[0..0, 0..5, 0..9], [0..8, 0..5, 0..9], [0..7, 0..5, 9..10]] {
        assert!(matches!(
            read_nrrd_region(&path, cells, &options),
            Err(GridError::InvalidParameter { .. })
        ));
    }
    // A NaN inside the box is named by its cell in the whole volume; outside the box it
    // is not read.
    let mut data = g.data().to_vec();
    let (i, j, k) = (3, 2, 6);
    data[i + 7 * (j + 5 * k)] = f32::NAN;
    let mut bytes = Vec::new();
    for v in &data {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    let raw_path = dir.path().join("nan.raw");
    std::fs::write(&raw_path, &bytes).unwrap();
    let layout = RawLayout::new([7, 5, 9], ScalarType::F32);
    match read_raw_region(&raw_path, &layout, [2..5, 1..4, 5..8], &options) {
        Err(GridError::NonFinite { index, cell, .. }) => {
            assert_eq!((index, cell), (i + 7 * (j + 5 * k), [i, j, k]));
        }
        other => panic!("{other:?}"),
    }
    assert!(read_raw_region(&raw_path, &layout, [4..7, 0..5, 0..9], &options).is_ok());
}

/// Boxes written by positioned writes, in any order, make the file the whole write makes,
/// byte for byte; a bad box is refused.
#[test]
fn positioned_npy_box_writes_make_the_whole_file() {
    use lucent_grid::io::layers::{create_npy, finish_npy, write_npy_region};
    let dir = tempfile::tempdir().unwrap();
    for dims in [[19, 6, 5], [1, 1, 1], [8, 3, 2]] {
        let g = grid(dims, 13);
        let whole = dir.path().join("whole.npy");
        let parts = dir.path().join("parts.npy");
        npy::write(&whole, &g, ScalarType::F32).unwrap();
        create_npy(&parts, dims).unwrap();
        let cut = |n: usize| [0, n / 2, n].to_vec();
        let (xs, ys, zs) = (cut(dims[0]), cut(dims[1]), cut(dims[2]));
        let mut boxes = Vec::new();
        for z in zs.windows(2).filter(|w| w[0] < w[1]) {
            for y in ys.windows(2).filter(|w| w[0] < w[1]) {
                for x in xs.windows(2).filter(|w| w[0] < w[1]) {
                    boxes.push([x[0]..x[1], y[0]..y[1], z[0]..z[1]]);
                }
            }
        }
        // The last box first: the order of the ranks' writes does not matter.
        for cells in boxes.into_iter().rev() {
            write_npy_region(&parts, dims, cells.clone(), &boxed(&g, &cells)).unwrap();
        }
        finish_npy(&parts).unwrap();
        assert_eq!(
            std::fs::read(&parts).unwrap(),
            std::fs::read(&whole).unwrap(),
            "{dims:?}"
        );
        assert!(matches!(
            write_npy_region(&parts, dims, [0..1, 0..1, 0..1], &[1.0, 2.0]),
            Err(GridError::InvalidParameter { .. })
        ));
    }
}
