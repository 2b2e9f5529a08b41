"""The volume readers from Python: each format's values and geometry, checked across
formats that hold the same data, against the same file read as raw, and against numpy."""

import numpy as np
import pytest

import lucent


def test_nrrd_equals_its_raw_payload(data_dir):
    """nucleon.nrrd is a detached header over nucleon.raw (41³ u8): the same values."""
    nrrd = lucent.read_volume(data_dir / "nucleon.nrrd")
    raw = lucent.read_raw(data_dir / "nucleon.raw", (41, 41, 41), "uint8")
    assert nrrd.dims == (41, 41, 41) and nrrd.data.dtype == np.float32
    np.testing.assert_array_equal(nrrd.data, raw.data)
    # The file's bytes, x fastest, are numpy's C order of (z, y, x).
    payload = np.fromfile(data_dir / "nucleon.raw", dtype=np.uint8).reshape(41, 41, 41)
    np.testing.assert_array_equal(raw.data, payload.astype(np.float32))
    # Samples at the cell centres: the first sample at the file's origin (0) puts the
    # grid's corner half a cell below it.
    assert nrrd.spacing == (1.0, 1.0, 1.0)
    assert nrrd.origin == (-0.5, -0.5, -0.5)


def test_metaimage_geometry_and_values(data_dir):
    head = lucent.read_volume(data_dir / "HeadMRVolume.mhd")
    assert head.dims == (48, 62, 42) and head.data.shape == (42, 62, 48)
    assert head.spacing == (4.0, 4.0, 4.0)
    payload = np.fromfile(data_dir / "HeadMRVolume.raw", dtype=np.uint8).reshape(42, 62, 48)
    np.testing.assert_array_equal(head.data, payload.astype(np.float32))
    lo, hi = head.bounds
    assert np.allclose(np.subtract(hi, lo), (4 * 48, 4 * 62, 4 * 42))


def test_every_format_reads(data_dir):
    """One file of each kind: finite values, positive extent, a plausible range."""
    for name in ["ironProt.vtk", "headsq.vti", "LIDC2.vti", "smoke.vdb", "sigmat.vol", "albedo.vol", "volume.vol"]:
        volume = lucent.read_volume(data_dir / name)
        data = volume.data
        assert np.isfinite(data).all(), name
        assert data.max() > data.min(), name
        assert all(s > 0 for s in volume.spacing), name
        assert data.shape[-3:] == tuple(reversed(volume.dims)), name
    smoke = lucent.read_vdb(data_dir / "smoke.vdb")
    assert smoke.name  # the grid's name in the file


def test_npy_round_trip_with_the_solvers_output(tmp_path):
    """numpy's own .npy file reads back as the same array (unit spacing at the origin)."""
    values = np.random.default_rng(3).random((5, 6, 7)).astype(np.float32)
    np.save(tmp_path / "v.npy", values)
    volume = lucent.read_volume(tmp_path / "v.npy")
    np.testing.assert_array_equal(volume.data, values)
    assert volume.origin == (0.0, 0.0, 0.0) and volume.spacing == (1.0, 1.0, 1.0)
    # Big-endian int16 raw with a placement.
    values16 = (np.arange(5 * 6 * 7) - 100).astype(">i2").reshape(5, 6, 7)
    values16.tofile(tmp_path / "v.raw")
    raw = lucent.read_raw(
        tmp_path / "v.raw", (5, 6, 7), "int16", byteorder="big", spacing=(0.5, 1, 2), origin=(1, 2, 3)
    )
    np.testing.assert_array_equal(raw.data, values16.astype(np.float32))
    assert raw.spacing == (0.5, 1.0, 2.0) and raw.origin == (1.0, 2.0, 3.0)
    assert raw.bounds[1] == (1 + 0.5 * 7, 2 + 6.0, 3 + 2.0 * 5)


def test_a_file_claiming_more_than_the_budget_is_refused(data_dir):
    with pytest.raises(lucent.OverBudgetError):
        lucent.read_volume(data_dir / "HeadMRVolume.mhd", memory_budget=1000)


def test_the_scene_volume_is_the_files(root, data_dir):
    """A scene's volume, read through its transfer function's input, is the reader's."""
    scene = lucent.Scene.load(root / "examples" / "scenes" / "suite" / "ct_tooth.toml")
    volume = scene.problem().volume
    assert volume.shape == (32, 19, 21)  # the scene resamples the tooth to 21×19×32
    tooth = lucent.read_raw(data_dir / "tooth_103x94x161_uint8.raw", (161, 94, 103), "uint8")
    assert abs(float(volume.mean()) - float(tooth.data.mean())) < 0.05 * float(tooth.data.mean())


def test_written_volumes_read_back_to_the_same_values_and_box(tmp_path):
    values = np.random.default_rng(5).random((6, 5, 7)).astype(np.float32)
    spacing, origin = (0.5, 0.25, 2.0), (-1.0, 3.0, 0.5)
    for extension in ["vol", "nrrd", "mhd", "vtk", "vti"]:
        path = tmp_path / f"v.{extension}"
        lucent.write_volume(path, values, spacing=spacing, origin=origin)
        back = lucent.read_volume(path)
        np.testing.assert_array_equal(back.data, values, err_msg=extension)
        np.testing.assert_allclose(back.spacing, spacing, rtol=1e-12, err_msg=extension)
        np.testing.assert_allclose(back.origin, origin, rtol=1e-12, atol=1e-12, err_msg=extension)
    rgb = np.stack([values, 2 * values, 3 * values])
    lucent.write_volume(tmp_path / "rgb.vol", rgb)
    np.testing.assert_array_equal(lucent.read_volume(tmp_path / "rgb.vol").data, rgb)
    with pytest.raises(ValueError, match="only a Mitsuba .vol"):
        lucent.write_volume(tmp_path / "rgb.nrrd", rgb)
    with pytest.raises(ValueError, match="lucent writes"):
        lucent.write_volume(tmp_path / "v.png", values)
