"""lucent's exceptions. Each carries the Rust error's message unchanged; each also derives
from the builtin a Python user would catch (``ValueError``, ``OSError``, ``MemoryError``)."""


class LucentError(Exception):
    """Anything lucent refused or could not do."""


class InvalidInputError(LucentError, ValueError):
    """A bad argument: an array of the wrong shape or dtype or with NaN, an unknown solver
    or parameter, a value out of range. The message names the argument."""


class SceneError(LucentError, ValueError):
    """A scene file, text or dict that is not a valid scene (with line and column for
    TOML)."""


class VolumeError(LucentError, ValueError):
    """A volume file that is malformed, truncated, or of a kind lucent does not read."""


class LucentIOError(LucentError, OSError):
    """A file that cannot be read or written."""


class UnsupportedError(LucentError):
    """The solver cannot handle this problem (a boundary, light, embedded body or graded
    index it does not implement); the message says which."""


class OverBudgetError(LucentError, MemoryError):
    """The job would allocate more than its memory budget (checked before allocating)."""


class DeviceError(LucentError):
    """No GPU adapter, or the device failed."""


class SolveError(LucentError):
    """Anything else a solve refused (a non-finite output, too much work)."""


__all__ = [
    "LucentError",
    "InvalidInputError",
    "SceneError",
    "VolumeError",
    "LucentIOError",
    "UnsupportedError",
    "OverBudgetError",
    "DeviceError",
    "SolveError",
]
