"""Solves from Python equal the Rust API's bit for bit, and a Problem made from numpy
arrays is the problem the scene builds."""

import json
import subprocess

import numpy as np
import pytest

import lucent

# (suite scene, solver, parameters): every class of solver (exact marching, Monte Carlo,
# discrete ordinates, multigrid with an embedded body, Lattice-Boltzmann, explicit time
# stepping, the hybrid, finite elements) over grey and RGB media, sun, point and sky
# lights, vacuum and Robin boundaries.
CASES = [
    ("slab", None, {}),
    ("slab", "dom", {}),
    ("ketchup_green", "diffusion-mg", {}),
    ("anisotropic", "mc", {"particles": 2000, "batches": 4}),
    ("cloud", "lbm", {}),
    ("thin_smoke", "hybrid", {"orders": 2}),
    ("marble_sphere", "diffusion-mg", {"cycle": "w"}),
    ("marble_sphere_eta15", "mc", {"particles": 1000, "batches": 2}),
    ("point_inside", "ftcs-diffusion", {}),
    ("absorber_point", "fem-diffusion", {}),
    ("ct_tooth", "dom", {}),
    ("touching_faces", "convection-diffusion", {}),
]


def cli_solve(lucent_bin, scene, solver, params, out):
    command = [str(lucent_bin), "solve", str(scene), "-o", str(out), "--quiet"]
    if solver:
        command += ["--solver", solver]
    for key, value in params.items():
        command += ["--param", f"{key}={value}"]
    subprocess.run(command, check=True, capture_output=True)
    return np.load(out), json.loads(out.with_suffix(".json").read_text())


@pytest.mark.parametrize("scene,solver,params", CASES)
def test_solve_equals_the_command_line_bit_for_bit(
    root, lucent_bin, tmp_path, scene, solver, params
):
    path = root / "examples" / "scenes" / "suite" / f"{scene}.toml"
    reference, report = cli_solve(lucent_bin, path, solver, params, tmp_path / "phi.npy")
    solution = lucent.solve(lucent.Scene.load(path), solver, **params)
    fluence = solution.fluence
    assert fluence.dtype == np.float32
    assert fluence.shape[1:] == reference.shape[-3:]
    # Bit for bit: the same code on the same f32 values (NaN-safe, -0.0-aware).
    assert np.array_equal(
        fluence.reshape(reference.shape).view(np.uint32), reference.view(np.uint32)
    )
    ours = solution.report
    theirs = report["report"]
    assert ours["iterations"] == theirs["iterations"]
    assert ours["residual_history"] == theirs["residual_history"]
    assert ours["stop_reason"] == theirs["stop_reason"]
    assert ours["params"] == report["params"]
    assert solution.converged


def test_problem_from_arrays_is_the_scenes_problem(root):
    """The marble sphere's σ_t, albedo and embedded SDF as arrays, its point light and
    Robin boundary as arguments: multigrid gives the scene's bits."""
    scene = lucent.Scene.load(root / "examples" / "scenes" / "suite" / "marble_sphere.toml")
    built = scene.problem()
    made = lucent.Problem(
        built.sigma_t.astype(np.float64),  # float64 is read as f32: the same values
        built.albedo,
        spacing=built.spacing,
        origin=built.origin,
        lights=[{"kind": "point", "position": [0, 0, 0], "intensity": 0.07957747154594767}],
        boundary={"kind": "robin", "eta": 1.3},
        embedded=built.embedded,
    )
    assert made.shape == built.shape and made.channels == built.channels
    np.testing.assert_array_equal(made.sigma_t, built.sigma_t)
    np.testing.assert_array_equal(made.embedded, built.embedded)
    ours = lucent.solve(made, "diffusion-mg")
    theirs = lucent.solve(built, "diffusion-mg")
    assert np.array_equal(ours.fluence, theirs.fluence)


def test_problem_from_arrays_matches_the_analytic_slab():
    """A homogeneous absorber under a normal sun, built from arrays: `direct`'s fluence is
    E e^{−σ_t z} at the cell centres, to f32 rounding (1e-5 over 24 cells)."""
    for n, sigma, irradiance in [(24, 3.0, 2.0), (17, 0.5, 1.0)]:
        h = 1.0 / n
        problem = lucent.Problem(
            np.full((n, 3, 5), sigma, dtype=np.float32),
            0.0,
            spacing=h,
            origin=(0.0, 0.0, 0.0),
            lights=[{"kind": "directional", "direction": [0, 0, 1], "irradiance": irradiance}],
        )
        phi = lucent.solve(problem, "direct").fluence[0, :, 1, 2]
        centres = (np.arange(n) + 0.5) * h
        np.testing.assert_allclose(phi, irradiance * np.exp(-sigma * centres), rtol=1e-5)


def test_unsupported_problems_raise_the_solvers_message(root):
    """The CLI's refusal, as `UnsupportedError`, word for word."""
    scene = lucent.Scene.load(root / "examples" / "scenes" / "suite" / "ct_tooth.toml")
    with pytest.raises(lucent.UnsupportedError, match="cannot handle non-cubic cells"):
        lucent.solve(scene, "convection-diffusion")
    cloud = lucent.Scene.load(root / "examples" / "scenes" / "suite" / "cloud.toml")
    with pytest.raises(lucent.UnsupportedError, match="cannot handle Sky lights"):
        lucent.Solver("convection-diffusion").check(cloud)


def test_solver_objects_and_the_registry(root):
    names = [s["name"] for s in lucent.solvers()]
    assert {"direct", "mc", "diffusion-mg", "dom", "lbm", "hybrid", "auto"} <= set(names)
    for entry in lucent.solvers():
        for param in entry["params"]:
            assert param["meaning"], (entry["name"], param["name"])
    solver = lucent.Solver("dom", order=8, closure="step")
    assert solver.params["order"] == 8 and solver.params["closure"] == "step"
    scene = lucent.Scene.load(root / "examples" / "scenes" / "suite" / "slab.toml")
    a = solver.solve(scene)
    b = lucent.solve(scene, "dom", order=8, closure="step")
    assert np.array_equal(a.fluence, b.fluence)
    assert a.residual_history.dtype == np.float64
    assert len(a.residual_history) == a.iterations


def test_scene_from_dict_and_text_equal_the_file(root):
    text = (root / "examples" / "scenes" / "suite" / "slab.toml").read_text()
    from_text = lucent.solve(lucent.Scene.from_toml(text), "dom")
    try:
        import tomllib
    except ImportError:  # Python < 3.11
        pytest.skip("tomllib is Python 3.11+")
    as_dict = tomllib.loads(text)
    from_dict = lucent.solve(lucent.Scene.from_dict(as_dict), "dom")
    assert np.array_equal(from_text.fluence, from_dict.fluence)
    with pytest.raises(lucent.SceneError, match="unknown field"):
        lucent.Scene.from_dict({**as_dict, "volumes": {}})


def test_on_grid_resamples_for_convergence_studies(root):
    """The same dims give the same bits; coarse grids converge to the fine solution at the
    scheme's second order (multigrid diffusion on the marble sphere: measured 6.6% at 8³
    and 1.7% at 16³ against 32³, a ratio of 3.9; asserted > 3, order > 1.58)."""
    problem = lucent.Scene.load(root / "examples" / "scenes" / "suite" / "marble_sphere.toml").problem()
    same = problem.on_grid(problem.dims)
    assert np.array_equal(lucent.solve(same, "diffusion-mg").fluence, lucent.solve(problem, "diffusion-mg").fluence)
    fine = lucent.solve(problem, "diffusion-mg").fluence[0]
    errors = []
    for n in (8, 16):
        coarse = problem.on_grid((n, n, n))
        assert coarse.shape == (n, n, n) and coarse.bounds == problem.bounds
        phi = lucent.solve(coarse, "diffusion-mg").fluence[0]
        # Box-average the fine solution onto the coarse cells.
        k = 32 // n
        averaged = fine.reshape(n, k, n, k, n, k).mean(axis=(1, 3, 5))
        inside = coarse.embedded[...] < -2 * coarse.spacing[0]  # away from the surface
        errors.append(np.linalg.norm((phi - averaged)[inside]) / np.linalg.norm(averaged[inside]))
    assert errors[1] < errors[0] / 3, errors
    with pytest.raises(ValueError, match="`dims`"):
        problem.on_grid((0, 4, 4))
