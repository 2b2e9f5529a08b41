"""Bad input is a Python exception with lucent's message, naming the argument."""

import numpy as np
import pytest

import lucent

GOOD = np.ones((4, 5, 6), dtype=np.float32)


@pytest.mark.parametrize(
    "argument,value,message",
    [
        ("sigma_t", np.ones((4, 5, 6), dtype=np.int32), "dtype int32 is not floating point"),
        ("sigma_t", np.ones((4, 5, 6), dtype=np.complex64), "is not floating point"),
        ("sigma_t", np.ones((5, 6)), r"shape \(5, 6\)"),
        ("sigma_t", np.ones((2, 4, 5, 6)), r"shape \(2, 4, 5, 6\)"),
        ("sigma_t", np.ones((0, 5, 6)), "empty axis"),
        ("sigma_t", np.where(np.arange(120).reshape(4, 5, 6) == 37, np.nan, 1.0), r"NaN at index \(1, 1, 1\)"),
        ("sigma_t", np.full((4, 5, 6), np.inf), "inf at index"),
        ("sigma_t", np.full((4, 5, 6), 1e300), "inf at index"),  # beyond f32
        ("sigma_t", -GOOD, "extinction must be ≥ 0"),
        ("albedo", np.ones((4, 5, 7), dtype=np.float32), "does not match the grid"),
        ("albedo", np.full((4, 5, 6), 1.5, dtype=np.float32), "outside \\[0, 1\\]"),
        ("albedo", np.ones((4, 5, 6), dtype=np.uint8), "not floating point"),
        ("embedded", np.ones((4, 5), dtype=np.float32), r"shape \(4, 5\)"),
        ("embedded", np.full((4, 5, 6), np.nan, dtype=np.float32), "NaN at index"),
        ("emission", np.ones((3, 5, 6), dtype=np.float32), "does not match the grid"),
        ("spacing", (1.0, 2.0), "2 numbers"),
        ("spacing", -1.0, "spacing"),
        ("lights", [{"kind": "laser"}], "lights\\[0\\]"),
        ("lights", [{"kind": "directional", "direction": [0, 0, 0], "irradiance": 1.0}], "not a direction"),
        ("boundary", "mirror", "boundary"),
        ("phase", 1.5, "phase"),
    ],
)
def test_bad_problem_arguments_raise_value_error_naming_them(argument, value, message):
    kwargs = {"sigma_t": GOOD}
    kwargs[argument] = value
    with pytest.raises(ValueError, match=message) as caught:
        lucent.Problem(**kwargs)
    assert isinstance(caught.value, lucent.InvalidInputError)
    assert f"`{argument}" in str(caught.value)


def test_bad_solver_arguments():
    problem = lucent.Problem(GOOD, 0.5)
    with pytest.raises(ValueError, match="unknown solver `nope`; available: direct"):
        lucent.solve(problem, "nope")
    with pytest.raises(ValueError, match="invalid parameter `order`"):
        lucent.solve(problem, "dom", order="eight")
    with pytest.raises(ValueError, match="invalid parameter `bogus`.*expected one of"):
        lucent.Solver("dom", bogus=1)
    with pytest.raises(ValueError, match="time_limit"):
        lucent.solve(problem, "dom", time_limit=-1.0)
    with pytest.raises(ValueError, match="threads"):
        lucent.solve(problem, "dom", threads=0)
    with pytest.raises(ValueError, match="problem"):
        lucent.solve("not a problem", "dom")
    with pytest.raises(ValueError, match="name a solver"):
        lucent.solve(problem)
    with pytest.raises(lucent.OverBudgetError, match="over the memory budget"):
        lucent.solve(problem, "dom", memory_budget=1000)


def test_bad_scenes_and_files(tmp_path):
    with pytest.raises(lucent.SceneError, match="line 1"):
        lucent.Scene.from_toml("volume = [")
    with pytest.raises(lucent.SceneError, match="bad scene: missing field `volume`"):
        lucent.Scene.from_dict({})
    with pytest.raises(OSError) as caught:
        lucent.Scene.load(tmp_path / "missing.toml")
    assert isinstance(caught.value, lucent.LucentError)
    with pytest.raises(OSError):
        lucent.read_volume(tmp_path / "missing.nrrd")
    (tmp_path / "bad.nrrd").write_bytes(b"NRRD0004\ntype: nonsense\n\n")
    with pytest.raises(lucent.VolumeError):
        lucent.read_volume(tmp_path / "bad.nrrd")
    with pytest.raises(ValueError, match="`dtype`"):
        lucent.read_raw(tmp_path / "x.raw", (2, 2, 2), "float128")
    with pytest.raises(ValueError, match="unsupported|extension"):
        lucent.read_volume(tmp_path / "x.xyz")
