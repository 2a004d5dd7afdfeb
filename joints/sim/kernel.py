"""Compiled where a compiler is available: how the twins' per-substep loops run fast.

Rule: a twin's loops are plain Python functions over rows of a table (one row of floats per drive
or channel: its working state, its loop settings and the parameters the loops read), written in
the subset of Python that numba compiles. With numba installed (the ``fast`` extra) the entry
points are compiled (:func:`compiled`) and the helpers they call are compiled into them
(:func:`jitable`); without it - or with ``JOINTS_JIT=0`` - the very same functions run as Python,
on tables of Python lists instead of numpy arrays (plain floats are what Python is fast with).
Both give the same bits: only IEEE double arithmetic, no fused multiply-add, no fast-math.

MuJoCo's own ``mj_step`` can be called from compiled code (:func:`mj_step_function`): the world
then runs N substeps - every drive's loops and the physics - in one call.
"""

from __future__ import annotations

import ctypes
import glob
import os
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from joints.devices import motion

__all__ = ["AVAILABLE", "compiled", "default_mode", "jitable", "mj_step_function", "rows", "table"]

F = TypeVar("F", bound=Callable[..., Any])

numba: Any
register_jitable: Any
try:  # the optional `fast` extra
    import numba
    from numba.extending import register_jitable
except ImportError:  # pragma: no cover - depends on the install
    numba = None
    register_jitable = None

#: numba is installed (the compiled kernels can be used)
AVAILABLE = numba is not None


def default_mode() -> bool:
    """Whether new worlds run compiled kernels: numba installed and ``JOINTS_JIT`` not ``0``."""
    return AVAILABLE and os.environ.get("JOINTS_JIT", "1") != "0"


def jitable(fn: F) -> F:
    """Mark a helper of a kernel: plain Python when called from Python, compiled into its callers."""
    if register_jitable is not None:
        register_jitable(fn)
    return fn


# the one motion-profile generator: compiled into the kernels that call it
jitable(motion.ramp)
jitable(motion.move_step)


def compiled(fn: F) -> F | None:
    """The compiled version of a kernel entry point (cached on disk), or None without numba."""
    if numba is None:
        return None
    out: Any = numba.njit(cache=True)(fn)
    return out  # type: ignore[no-any-return]


def table(n: int, width: int, compiled_mode: bool) -> Any:
    """A table of ``n`` rows of ``width`` zeros: a float64 array (compiled) or lists (Python)."""
    if compiled_mode:
        import numpy as np

        return np.zeros((n, width))
    return [[0.0] * width for _ in range(n)]


def rows(values: Sequence[Sequence[float]], compiled_mode: bool, *, integer: bool = False) -> Any:
    """``values`` as a table: a 2-D numpy array (compiled; int64 if ``integer``) or lists (Python)."""
    if compiled_mode:
        import numpy as np

        width = len(values[0]) if len(values) else 0
        return np.array(values, dtype=np.int64 if integer else np.float64).reshape(len(values), width)
    return [list(map(int if integer else float, r)) for r in values]


def arrays(items: Sequence[Any], compiled_mode: bool) -> Any:
    """A list of 1-D arrays (one per world: qpos, qvel, ctrl) as compiled code takes it."""
    if compiled_mode and numba is not None:
        from numba.typed import List

        out = List()
        for a in items:
            out.append(a)
        return out
    return list(items)


_MJ_STEP: list[Any] = []


def mj_step_function() -> Any:
    """MuJoCo's ``mj_step(const mjModel*, mjData*)`` as a ctypes function of two addresses, or None.

    It is the library the ``mujoco`` bindings themselves load (the same process-wide copy), so
    ``model._address`` / ``data._address`` of the bindings' objects are valid arguments. None
    where the library file cannot be found next to the bindings.
    """
    if _MJ_STEP:
        return _MJ_STEP[0]
    fn = None
    try:
        import mujoco

        base = os.path.dirname(mujoco.__file__)
        found = sorted(glob.glob(os.path.join(base, "libmujoco.so*")) + glob.glob(os.path.join(base, "libmujoco*.dylib"))
                       + glob.glob(os.path.join(base, "mujoco.dll")))
        if found:
            lib = ctypes.CDLL(found[0])
            fn = lib.mj_step
            fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
            fn.restype = None
    except (ImportError, OSError, AttributeError):  # pragma: no cover - depends on the install
        fn = None
    _MJ_STEP.append(fn)
    return fn
