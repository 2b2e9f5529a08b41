"""Type stubs of the compiled module `lucent._lucent` (re-exported by `lucent`).

Grids are numpy arrays ``a[z, y, x]`` of shape (n_z, n_y, n_x); channels stack in front.
"""

import os
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Path = Union[str, "os.PathLike[str]"]
_Vec3 = Tuple[float, float, float]
_Floats = npt.ArrayLike
_Progress = Callable[[str, float, int, Optional[float]], Any]
_Target = Union["Problem", "Scene"]

class Scene:
    """A scene: volume, medium, lights, boundary, camera, image and solver, as in a scene
    file (``examples/scenes/`` documents every key)."""

    @staticmethod
    def load(path: _Path) -> "Scene":
        """Reads a scene file (TOML); relative volume paths start from its folder."""
    @staticmethod
    def from_toml(text: str, base: Optional[_Path] = None) -> "Scene":
        """Parses scene text; relative volume paths start from ``base`` (default ``.``)."""
    @staticmethod
    def from_dict(scene: Mapping[str, Any], base: Optional[_Path] = None) -> "Scene":
        """A scene from a dict with the file's structure; ``None`` values count as not given."""
    @staticmethod
    def default() -> "Scene":
        """The built-in default scene (what ``cargo run --release`` renders)."""
    @property
    def solver(self) -> str:
        """The scene's solver (``[solver] name``)."""
    @property
    def solver_params(self) -> Dict[str, Any]:
        """The scene's ``[solver.params]``, as given."""
    @property
    def tolerance(self) -> Optional[float]:
        """The scene's ``[solver] tolerance`` (relative residual), or ``None``."""
    @property
    def name(self) -> str:
        """The scene's file, or what it was made from."""
    def problem(self, memory_budget: Optional[int] = None) -> "Problem":
        """Builds the problem (reads the volume, maps it to a medium) within
        ``memory_budget`` bytes (default 8 GiB)."""

class Problem:
    """A light-transport problem: a medium on a grid, lights, a boundary, an optional
    embedded body."""

    def __init__(
        self,
        sigma_t: _Floats,
        albedo: Union[float, Sequence[float], _Floats, None] = None,
        *,
        spacing: Union[float, Sequence[float], None] = None,
        origin: Union[float, Sequence[float], None] = None,
        phase: Union[float, str, Mapping[str, Any], None] = None,
        lights: Optional[Sequence[Mapping[str, Any]]] = None,
        boundary: Union[str, Mapping[str, Any], None] = None,
        embedded: Optional[_Floats] = None,
        emission: Optional[_Floats] = None,
        memory_budget: Optional[int] = None,
    ) -> None:
        """``sigma_t`` (1/length): (n_z, n_y, n_x) or (3, n_z, n_y, n_x), float32 or
        float64, finite, ≥ 0. ``albedo``: a number (default 0.9), three numbers, or an
        array like ``sigma_t``, in [0, 1]. ``spacing``: cell size, one number or (x, y, z)
        (default 1); ``origin``: the corner of cell (0, 0, 0). ``phase``: a mean cosine g
        (Henyey–Greenstein), ``"isotropic"``, ``"rayleigh"`` or a dict as in a scene file.
        ``lights``: dicts as in a scene file. ``boundary``: ``"vacuum"`` or a dict
        (``{"kind": "robin", "eta": 1.3}``). ``embedded``: the signed distance of an
        embedded body (negative inside). ``emission``: the grid emission lights scale.
        Arrays are read by index whatever their memory layout (C, Fortran, transposed,
        strided, broadcast). Bad arrays raise ``ValueError`` naming the argument; an array
        over an eighth of ``memory_budget`` (default 8 GiB; three eighths for RGB) raises
        ``MemoryError`` before anything is copied."""
    @property
    def dims(self) -> Tuple[int, int, int]:
        """Cells per axis, (n_x, n_y, n_z)."""
    @property
    def shape(self) -> Tuple[int, int, int]:
        """One field's numpy shape, (n_z, n_y, n_x)."""
    def on_grid(self, dims: Tuple[int, int, int]) -> "Problem":
        """The same problem on ``dims`` = (n_x, n_y, n_z) cells over the same box, every
        grid resampled (for convergence studies)."""
    @property
    def spacing(self) -> _Vec3: ...
    @property
    def origin(self) -> _Vec3: ...
    @property
    def bounds(self) -> Tuple[_Vec3, _Vec3]: ...
    @property
    def channels(self) -> int:
        """1 (grey) or 3 (RGB)."""
    @property
    def sigma_t(self) -> npt.NDArray[np.float32]:
        """(channels of σ_t, n_z, n_y, n_x)."""
    @property
    def albedo(self) -> npt.NDArray[np.float32]:
        """(channels of albedo, n_z, n_y, n_x)."""
    @property
    def embedded(self) -> Optional[npt.NDArray[np.float32]]: ...
    @property
    def volume(self) -> Optional[npt.NDArray[np.float32]]:
        """The scalar volume a scene's medium was mapped from; for a problem made from
        arrays, its ``emission`` grid, or ``None``."""
    @property
    def boundary(self) -> str: ...
    @property
    def lights(self) -> List[str]:
        """The lights' kinds."""

class Cancel:
    """A token that stops running solves at their next iteration (``set()`` from any
    thread); the solve returns what it computed, with stop reason ``interrupted``."""

    def __init__(self) -> None: ...
    def set(self) -> None: ...
    def clear(self) -> None: ...
    @property
    def is_set(self) -> bool: ...

class Solution:
    """A solve's result."""

    @property
    def fluence(self) -> npt.NDArray[np.float32]:
        """φ = ∫ L dω, (channels, n_z, n_y, n_x)."""
    @property
    def standard_error(self) -> Optional[npt.NDArray[np.float32]]:
        """Monte Carlo's per-cell standard error, like ``fluence``."""
    @property
    def report(self) -> Dict[str, Any]:
        """``solver``, ``iterations``, ``residual_history``, ``wall_time_s``,
        ``peak_memory_bytes``, ``measured_peak_bytes``, ``stop_reason``
        (``{"reason": ..., "residual": ...}``), ``paging``, ``choice``, ``params``."""
    @property
    def stop_reason(self) -> str:
        """``exact``, ``converged-relative``, ``converged-absolute``, ``sampled``,
        ``iteration-limit``, ``time-limit``, ``interrupted``, ``diverged-non-finite`` or
        ``diverged-growth``."""
    @property
    def message(self) -> str:
        """Why it stopped, in words."""
    @property
    def converged(self) -> bool: ...
    @property
    def diverged(self) -> bool: ...
    @property
    def interrupted(self) -> bool: ...
    @property
    def iterations(self) -> int: ...
    @property
    def residual_history(self) -> npt.NDArray[np.float64]: ...
    @property
    def wall_time_s(self) -> float: ...
    @property
    def peak_memory_bytes(self) -> int: ...
    @property
    def spacing(self) -> _Vec3: ...
    @property
    def origin(self) -> _Vec3: ...

class Solver:
    """A registered solver with its typed parameters (``lucent.solvers()`` lists them)."""

    def __init__(self, name: str, params: Optional[Mapping[str, Any]] = None, **kwargs: Any) -> None: ...
    @property
    def name(self) -> str: ...
    @property
    def params(self) -> Dict[str, Any]:
        """Every parameter it runs with, defaults filled in."""
    def capabilities(self) -> Dict[str, Any]: ...
    def check(self, problem: _Target) -> None:
        """Raises ``UnsupportedError`` unless it can solve ``problem``."""
    def solve(
        self,
        problem: _Target,
        *,
        rtol: Optional[float] = None,
        atol: float = 0.0,
        max_iterations: int = 10000,
        time_limit: Optional[float] = None,
        threads: Optional[int] = None,
        memory_budget: Optional[int] = None,
        cancel: Optional[Cancel] = None,
        progress: Optional[_Progress] = None,
    ) -> Solution: ...

def solve(
    problem: _Target,
    solver: Optional[str] = None,
    *,
    params: Optional[Mapping[str, Any]] = None,
    rtol: Optional[float] = None,
    atol: float = 0.0,
    max_iterations: int = 10000,
    time_limit: Optional[float] = None,
    threads: Optional[int] = None,
    memory_budget: Optional[int] = None,
    cancel: Optional[Cancel] = None,
    progress: Optional[_Progress] = None,
    **kwargs: Any,
) -> Solution:
    """Solves ``problem`` with ``solver`` and its parameters as keywords. A scene without
    ``solver`` runs its own solver, parameters and tolerance (``lucent solve SCENE``'s
    bits). The GIL is released; Ctrl-C stops the solve (``interrupted``)."""

def solvers() -> List[Dict[str, Any]]:
    """Every solver: ``name``, ``summary``, ``params`` (name, default, meaning),
    ``capabilities``."""

class Volume:
    """A volume file's values with their geometry."""

    @property
    def data(self) -> npt.NDArray[np.float32]:
        """(n_z, n_y, n_x), or (channels, n_z, n_y, n_x) for a multi-channel ``.vol``."""
    @property
    def channels(self) -> int: ...
    @property
    def dims(self) -> Tuple[int, int, int]: ...
    @property
    def spacing(self) -> _Vec3: ...
    @property
    def origin(self) -> _Vec3:
        """The corner of cell (0, 0, 0): half a cell below the file's first sample."""
    @property
    def bounds(self) -> Tuple[_Vec3, _Vec3]: ...
    @property
    def name(self) -> Optional[str]:
        """The grid's name in an OpenVDB file."""

def read_volume(path: _Path, *, memory_budget: Optional[int] = None) -> Volume:
    """``.nrrd``/``.nhdr``, ``.mhd``/``.mha``, ``.vtk``, ``.vti`` (or a vtk.js folder),
    ``.vol``, ``.npy``, ``.vdb``, by extension. A read may take three eighths of
    ``memory_budget`` (default 8 GiB: 3 GiB), the ``lucent`` command's rule; a file
    claiming more (a decompression bomb, a VDB spanning a huge box) raises
    ``MemoryError`` before anything is inflated."""

def read_raw(
    path: _Path,
    shape: Tuple[int, int, int],
    dtype: str,
    *,
    byteorder: str = "little",
    spacing: _Vec3 = (1.0, 1.0, 1.0),
    origin: _Vec3 = (0.0, 0.0, 0.0),
    memory_budget: Optional[int] = None,
) -> Volume:
    """A headerless raw file of ``shape`` = (n_z, n_y, n_x) samples, x fastest."""

def read_vdb(path: _Path, grid: Optional[str] = None, *, memory_budget: Optional[int] = None) -> Volume:
    """The OpenVDB float grid called ``grid`` (default the first)."""

def write_volume(
    path: _Path,
    data: _Floats,
    *,
    spacing: Union[float, Sequence[float], None] = None,
    origin: Union[float, Sequence[float], None] = None,
    memory_budget: Optional[int] = None,
) -> None:
    """Writes float32 cells as ``.vol`` (several channels allowed), ``.npy``, ``.nrrd``,
    ``.mhd``, ``.vtk`` or ``.vti``; ``read_volume`` reads them back to the same values
    and box (``.npy`` has no geometry). The file appears whole or not at all: it is
    written beside the target and renamed over it when complete."""

class Rendering:
    """A rendered image; ``numpy.asarray(rendering)`` is its linear radiance."""

    @property
    def radiance(self) -> npt.NDArray[np.float32]:
        """Linear RGB, (height, width, 3)."""
    @property
    def std_error(self) -> Optional[npt.NDArray[np.float32]]: ...
    @property
    def solution(self) -> Optional[Solution]: ...
    @property
    def rows_traced(self) -> int: ...
    def srgb(self, exposure: Optional[float] = None, tone: Optional[str] = None) -> npt.NDArray[np.uint8]:
        """8-bit sRGB as ``lucent render`` writes its PNG (the scene's exposure and tone
        curve unless given: ``aces``, ``reinhard``, ``clamp``)."""
    def __array__(self, dtype: Any = None, copy: Optional[bool] = None) -> npt.NDArray[Any]: ...

def render(
    scene: Scene,
    solver: Optional[str] = None,
    *,
    solution: Optional[Solution] = None,
    size: Optional[Tuple[int, int]] = None,
    params: Optional[Mapping[str, Any]] = None,
    rtol: Optional[float] = None,
    atol: float = 0.0,
    max_iterations: int = 10000,
    time_limit: Optional[float] = None,
    threads: Optional[int] = None,
    memory_budget: Optional[int] = None,
    cancel: Optional[Cancel] = None,
    progress: Optional[_Progress] = None,
    **kwargs: Any,
) -> Rendering:
    """Solves (unless ``solution`` is given) and renders ``scene``; ``size`` = (width,
    height)."""

class DiffusionSystem:
    """One channel's discrete diffusion system A φ = b as ``diffusion-mg`` builds it."""

    def __init__(self, problem: Problem, channel: int = 0) -> None: ...
    def matrix(
        self,
    ) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], npt.NDArray[np.int64], Tuple[int, int]]:
        """(data, indices, indptr, shape) of A in CSR."""
    def rhs(self) -> npt.NDArray[np.float64]: ...
    def cells(self) -> npt.NDArray[np.int64]:
        """The flat grid cell (x fastest) of each unknown."""
    @property
    def dims(self) -> Tuple[int, int, int]: ...
    def solve_multigrid(
        self, rtol: float = 1e-8, max_cycles: int = 200
    ) -> Tuple[npt.NDArray[np.float64], int, float]:
        """lucent's multigrid on this system: (φ per unknown, cycles, seconds)."""

def _evaluate(
    name: str, columns: List[npt.NDArray[np.float64]], arguments: List[str]
) -> npt.NDArray[np.float64]: ...
