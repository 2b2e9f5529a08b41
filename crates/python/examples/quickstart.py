"""lucent from Python, alone: a problem from numpy arrays, two solvers, an analytic check.

    pip install ./crates/python && python crates/python/examples/quickstart.py

A purely absorbing slab under a normal sun has the fluence E e^{−σ_t z} (Beer–Lambert):
`direct` gets it to f32 rounding. With scattering, discrete ordinates and multigrid
diffusion are compared with Monte Carlo.
"""

import numpy as np

import lucent

n, sigma_t = 32, 4.0
sun = {"kind": "directional", "direction": [0, 0, 1], "irradiance": 1.0}
slab = np.full((n, 8, 8), sigma_t, dtype=np.float32)  # (n_z, n_y, n_x), cells of 1/n

absorber = lucent.Problem(slab, albedo=0.0, spacing=1.0 / n, lights=[sun])
phi = lucent.solve(absorber, "direct").fluence[0, :, 4, 4]
z = (np.arange(n) + 0.5) / n
print(f"direct vs Beer-Lambert: max relative error {np.abs(phi / np.exp(-sigma_t * z) - 1).max():.1e}")

scattering = lucent.Problem(slab, albedo=0.95, spacing=1.0 / n, lights=[sun], phase=0.5)
reference = lucent.solve(scattering, "mc", particles=200_000).fluence
for solver, params in [("dom", {"order": 8}), ("diffusion-mg", {})]:
    solution = lucent.solve(scattering, solver, rtol=1e-6, **params)
    error = np.linalg.norm(solution.fluence - reference) / np.linalg.norm(reference)
    print(f"{solver:13s} {solution.wall_time_s * 1e3:7.1f} ms, {solution.stop_reason}, "
          f"{error:.1%} from Monte Carlo")
