"""lucent against the packages researchers already trust, in one notebook-like run.

    python examples/python/compare_external.py [--n 48] [--spp 64]

1. **Multigrid against algebraic multigrid on the same matrix.** The marble sphere of
   Mertens' case T7 (R = 10 mm, σ_a = 0.0021/mm, σ_s′ = 2.19/mm, a point source near the
   centre, Robin A from η = 1.3) as a `Problem` built from numpy arrays at n³;
   `lucent.DiffusionSystem` hands over the exact sparse system `diffusion-mg` solves. pyamg
   (Ruge–Stüben AMG as a CG preconditioner) and scipy's CG solve it; lucent's
   geometric multigrid solves it too. Printed: set-up and solve times, iterations, and
   how far the three solutions are apart.
2. **Monte Carlo against Mitsuba 3's volpath.** A suite scene with a grey medium
   (`thin_smoke`): lucent's path-traced camera image (`lucent.render(scene, "mc")`) and
   Mitsuba's render of the same σ_t grid (written with `lucent.write_volume` as a `.vol`,
   placed by `to_world`: Mitsuba maps a grid to the unit cube), the same camera, sun,
   albedo and phase function; compared by z-scores of 8×8-pixel block means with lucent's
   per-pixel standard errors.

Each part runs when its packages are installed (`pip install scipy pyamg mitsuba`) and
says so when they are not.
"""

import argparse
import math
import pathlib
import tempfile
import time

import numpy as np

import lucent

ROOT = pathlib.Path(__file__).resolve().parents[2]


def marble_sphere(n):
    """The marble sphere as arrays: σ_t′ in a box just larger than the sphere, its SDF."""
    half = 10.5
    h = 2 * half / n
    centres = (np.arange(n) + 0.5) * h - half
    z, y, x = np.meshgrid(centres, centres, centres, indexing="ij")
    sdf = np.sqrt(x**2 + y**2 + z**2) - 10.0
    sigma_a, sigma_s = 0.0021, 2.19
    return lucent.Problem(
        np.full((n, n, n), sigma_a + sigma_s, dtype=np.float32),
        sigma_s / (sigma_a + sigma_s),
        spacing=h,
        origin=(-half, -half, -half),
        boundary={"kind": "robin", "eta": 1.3},
        lights=[{"kind": "point", "position": [0.173, -0.091, 0.057], "intensity": 1 / (4 * math.pi)}],
        embedded=sdf.astype(np.float32),
    )


def same_matrix(n):
    print(f"== 1. one diffusion matrix, three solvers (marble sphere at {n}³)")
    system = lucent.DiffusionSystem(marble_sphere(n))
    data, indices, indptr, shape = system.matrix()
    b = system.rhs()
    print(f"   {shape[0]} unknowns, {len(data)} non-zeros")
    ours, cycles, seconds = system.solve_multigrid(rtol=1e-8)
    print(f"   lucent geometric multigrid: {cycles:3d} V-cycles, {seconds * 1e3:8.1f} ms")
    try:
        import scipy.sparse as sp
        import scipy.sparse.linalg as spla
    except ImportError:
        print("   scipy is not installed: pip install scipy pyamg")
        return
    A = sp.csr_matrix((data, indices, indptr), shape=shape)

    def residual(x):
        return np.linalg.norm(A @ x - b) / np.linalg.norm(b)

    print(f"   lucent's relative residual in scipy's product: {residual(ours):.2e}")
    iterations = []
    start = time.perf_counter()
    x_cg, info = spla.cg(A, b, rtol=1e-8, maxiter=20_000, callback=lambda _: iterations.append(1))
    cg_seconds = time.perf_counter() - start
    print(f"   scipy CG:                   {len(iterations):4d} iterations, {cg_seconds * 1e3:8.1f} ms, residual {residual(x_cg):.1e}")
    try:
        import pyamg
    except ImportError:
        print("   pyamg is not installed: pip install pyamg")
        return
    start = time.perf_counter()
    ml = pyamg.ruge_stuben_solver(A)
    setup = time.perf_counter() - start
    residuals = []
    start = time.perf_counter()
    x_amg = ml.solve(b, tol=1e-8, accel="cg", residuals=residuals)
    solve = time.perf_counter() - start
    print(f"   pyamg RS-AMG + CG:          {len(residuals) - 1:4d} iterations, {(setup + solve) * 1e3:8.1f} ms "
          f"(set-up {setup * 1e3:.1f}), residual {residual(x_amg):.1e}")
    for name, x in [("scipy CG", x_cg), ("pyamg", x_amg)]:
        print(f"   ‖lucent − {name}‖/‖{name}‖ = {np.linalg.norm(ours - x) / np.linalg.norm(x):.1e}")


def mitsuba_scene(scene_path, volume, spp, width, height):
    """The scene's Mitsuba twin: the same σ_t grid, camera, sun, albedo and phase."""
    import tomllib

    import mitsuba as mi

    spec = tomllib.loads(scene_path.read_text())
    lo, hi = spec["volume"]["bounds"]
    medium, camera = spec["medium"], spec["camera"]
    phase = medium.get("phase", {"kind": "isotropic"})
    g = phase.get("g", 0.0) if phase["kind"] in ("henyey-greenstein", "isotropic") else None
    if g is None or camera["kind"] != "pinhole":
        raise ValueError("only HG phases and pinhole cameras are exported")
    T = mi.ScalarTransform4f
    centre = [(a + b) / 2 for a, b in zip(lo, hi)]
    half = [(b - a) / 2 for a, b in zip(lo, hi)]
    extent = [b - a for a, b in zip(lo, hi)]
    albedo = medium.get("albedo", 0.9)
    scene = {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": 10_000, "rr_depth": 5},
        "sensor": {
            "type": "perspective",
            "fov": camera.get("fov", 40.0),
            "fov_axis": "y",
            "to_world": T().look_at(origin=camera["position"], target=camera["look_at"], up=camera.get("up", [0, 0, 1])),
            "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "cube": {
            "type": "cube",
            "to_world": T().translate(centre).scale(half),
            "bsdf": {"type": "null"},
            "interior": {
                "type": "heterogeneous",
                "sigma_t": {"type": "gridvolume", "filename": str(volume), "filter_type": "trilinear",
                            "to_world": T().translate(lo).scale(extent)},
                "albedo": {"type": "rgb", "value": albedo if isinstance(albedo, list) else [albedo] * 3},
                "phase": {"type": "hg", "g": g},
                "scale": 1.0,
            },
        },
    }
    for i, light in enumerate(spec.get("lights", [])):
        if light["kind"] == "directional":
            value = light["irradiance"]
            scene[f"light{i}"] = {"type": "directional", "direction": light["direction"],
                                  "irradiance": {"type": "rgb", "value": value if isinstance(value, list) else [value] * 3}}
        else:
            raise ValueError(f"{light['kind']} lights are not exported")
    return mi.load_dict(scene)


def against_mitsuba(scene_name, spp, size=(128, 128)):
    print(f"== 2. lucent's Monte Carlo against Mitsuba 3's volpath ({scene_name}, {spp} paths per pixel)")
    try:
        import mitsuba as mi
    except ImportError:
        print("   mitsuba is not installed: pip install mitsuba")
        return
    mi.set_variant("scalar_rgb")
    path = ROOT / "examples" / "scenes" / "suite" / f"{scene_name}.toml"
    scene = lucent.Scene.load(path)
    problem = scene.problem()
    start = time.perf_counter()
    ours = lucent.render(scene, "mc", size=size, spp=spp, seed=42)
    lucent_seconds = time.perf_counter() - start
    with tempfile.TemporaryDirectory() as tmp:
        volume = pathlib.Path(tmp) / "sigma_t.vol"
        lo, hi = problem.bounds
        lucent.write_volume(volume, problem.sigma_t[0], spacing=problem.spacing, origin=lo)
        twin = mitsuba_scene(path, volume, spp, *size)
        start = time.perf_counter()
        theirs = np.array(mi.render(twin, spp=spp), dtype=np.float32)[:, :, :3]
        mitsuba_seconds = time.perf_counter() - start
    mine, err = ours.radiance, ours.std_error
    print(f"   lucent {lucent_seconds:.1f} s, Mitsuba scalar_rgb {mitsuba_seconds:.1f} s")
    print(f"   mean radiance: lucent {mine.mean():.5f}, Mitsuba {theirs.mean():.5f} "
          f"({(mine.mean() - theirs.mean()) / theirs.mean():+.2%})")
    b = 8
    ny, nx = size[1] // b, size[0] // b
    block = lambda a: a[: ny * b, : nx * b].reshape(ny, b, nx, b, 3).mean((1, 3))
    eb = np.sqrt((err[: ny * b, : nx * b].reshape(ny, b, nx, b, 3) ** 2).sum((1, 3))) / (b * b)
    keep = eb > 1e-6
    # Mitsuba's noise is taken as lucent's (same estimator family, same spp): σ√2.
    z = (block(mine) - block(theirs))[keep] / (eb[keep] * np.sqrt(2.0))
    print(f"   8×8 blocks: mean z {z.mean():+.2f}, rms z {np.sqrt((z**2).mean()):.2f} "
          f"(≈ 1 when the images agree to their noise), {(np.abs(z) > 4).mean():.1%} beyond 4σ")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=48, help="cells per axis of the marble sphere")
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--scene", default="thin_smoke")
    args = parser.parse_args()
    same_matrix(args.n)
    against_mitsuba(args.scene, args.spp)
