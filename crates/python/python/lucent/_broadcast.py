"""Element-wise evaluation of the compiled numerics over broadcast numpy arrays."""

from typing import Dict

import numpy as np

from . import _lucent


def evaluate(name: str, arguments: Dict[str, object]) -> "np.ndarray | float":
    """``name`` at every element of the broadcast ``arguments`` (name -> array-like):
    a float for scalar inputs, else an array of the broadcast shape."""
    arrays = []
    for key, value in arguments.items():
        array = np.asarray(value)
        if array.dtype.kind not in "biuf":
            raise _errors().InvalidInputError(
                f"`{key}`: dtype {array.dtype} is not a real number"
            )
        arrays.append(array.astype(np.float64, copy=False))
    try:
        broadcast = np.broadcast_arrays(*arrays)
    except ValueError as e:
        raise _errors().InvalidInputError(
            f"{name}: the arguments {list(arguments)} do not broadcast: {e}"
        ) from None
    shape = broadcast[0].shape if broadcast else ()
    columns = [np.ascontiguousarray(a).reshape(-1) for a in broadcast]
    out = _lucent._evaluate(name, columns, list(arguments))
    if shape == ():
        return float(out[0])
    return out.reshape(shape)


def _errors():
    from . import _errors as errors

    return errors
