"""lucent: light transport in participating media, from Python.

>>> import lucent
>>> scene = lucent.Scene.load("examples/scenes/suite/slab.toml")   # doctest: +SKIP
>>> solution = lucent.solve(scene, "diffusion-mg", cycle="w")       # doctest: +SKIP
>>> solution.fluence.shape, solution.report["stop_reason"]          # doctest: +SKIP

Grids are numpy arrays ``a[z, y, x]`` of shape (n_z, n_y, n_x), channels in front;
solutions are float32 as lucent computes them, bit for bit the Rust API's.
"""

from . import analytic, stability
from ._errors import (
    DeviceError,
    InvalidInputError,
    LucentError,
    LucentIOError,
    OverBudgetError,
    SceneError,
    SolveError,
    UnsupportedError,
    VolumeError,
)
from ._lucent import (
    Cancel,
    DiffusionSystem,
    Problem,
    Rendering,
    Scene,
    Solution,
    Solver,
    Volume,
    __version__,
    read_raw,
    read_vdb,
    read_volume,
    render,
    solve,
    solvers,
    write_volume,
)

__all__ = [
    "Cancel",
    "DiffusionSystem",
    "Problem",
    "Rendering",
    "Scene",
    "Solution",
    "Solver",
    "Volume",
    "__version__",
    "analytic",
    "read_raw",
    "read_vdb",
    "read_volume",
    "render",
    "solve",
    "solvers",
    "stability",
    "write_volume",
    "DeviceError",
    "InvalidInputError",
    "LucentError",
    "LucentIOError",
    "OverBudgetError",
    "SceneError",
    "SolveError",
    "UnsupportedError",
    "VolumeError",
]
