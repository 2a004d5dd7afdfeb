"""Compiled where a compiler is available: how the twins' per-substep loops run fast.

Rule: a twin's loops are plain Python functions over rows of a table (one row of floats per drive
or channel: its working state, its loop settings and the parameters the loops read), written in
the subset of Python that numba compiles. With numba installed (the ``compiled`` extra; ``fast``, its older
name, still installs it) the entry points are compiled (:func:`compiled`; a twin's helpers once per process:
:func:`compiled_ops`) and the helpers they call are compiled into them (:func:`jitable`, numba's word for
such a helper); without it - or with ``JOINTS_COMPILED=0`` (the older ``JOINTS_JIT=0`` too), or
``World(compiled=False)`` - the very same functions run as Python,
on tables of Python lists instead of numpy arrays (plain floats are what Python is fast with).
Both give the same bits: only IEEE double arithmetic, no fused multiply-add, no fast-math.

MuJoCo's own ``mj_step`` can be called from compiled code (:func:`mj_step_address`, :func:`call`): the world
then runs N substeps - every drive's loops and the physics - in one call.
"""

from __future__ import annotations

import ctypes
import glob
import importlib
import os
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from joints.devices import motion

__all__ = ["AVAILABLE", "arrays", "call", "compiled", "compiled_ops", "default_mode", "f64_at", "jitable", "mj_step_address", "rows",
           "table"]

F = TypeVar("F", bound=Callable[..., Any])


def _load(name: str) -> Any:
    try:
        return importlib.import_module(name)
    except ImportError:  # pragma: no cover - depends on the install
        return None


numba: Any = _load("numba")  # the optional `compiled` extra
_extending: Any = _load("numba.extending") if numba is not None else None
register_jitable: Any = _extending.register_jitable if _extending is not None else None

#: numba is installed (the compiled kernels can be used)
AVAILABLE = numba is not None


#: the environment variable that turns the compiled path off (``0``) for new worlds; :data:`OLD_SWITCH`, its
#: earlier name, is still read when it is unset
SWITCH = "JOINTS_COMPILED"
OLD_SWITCH = "JOINTS_JIT"


def default_mode() -> bool:
    """Whether new worlds run compiled kernels: numba installed and ``JOINTS_COMPILED`` (or, unset, the old
    ``JOINTS_JIT``) not ``0``."""
    value = os.environ.get(SWITCH)
    if value is None:
        value = os.environ.get(OLD_SWITCH, "1")
    return AVAILABLE and value != "0"


def jitable(fn: F) -> F:
    """Mark a helper of a kernel: plain Python when called from Python, compiled into its callers."""
    if register_jitable is not None:
        register_jitable(fn)
    return fn


# the one motion-profile generator: compiled into the kernels that call it
jitable(motion.ramp)
jitable(motion.move_step)


#: the sources compiled into the kernels: numba's on-disk cache checks only the file of the
#: function it caches, so the cache lives in a directory named by a hash of all of them
_SOURCES = ("joints/sim/kernel.py", "joints/sim/erob_kernel.py", "joints/sim/zlac_kernel.py",
            "joints/sim/stepping.py", "joints/sim/line_exchange.py", "joints/sim/erob_exchange.py",
            "joints/sim/zlac_exchange.py", "joints/sim/stream.py", "joints/sim/sensors.py", "joints/devices/motion.py")


def cache_dir() -> str:
    """Where the compiled kernels are cached: ``$NUMBA_CACHE_DIR`` (or ``$XDG_CACHE_HOME``, else
    ``~/.cache``) ``/joints-kernels-<hash of the kernel sources and numba's version>``."""
    import hashlib
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    digest = hashlib.sha256(str(getattr(numba, "__version__", "")).encode())
    for name in _SOURCES:
        try:
            digest.update((root / name).read_bytes())
        except OSError:  # pragma: no cover - an unusual install: the version still separates caches
            digest.update(name.encode())
    base = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"))
    return os.path.join(base, f"joints-kernels-{digest.hexdigest()[:16]}")


def compiled(fn: F) -> F | None:
    """The compiled version of a kernel entry point (cached on disk in :func:`cache_dir`), or None
    without numba."""
    if numba is None:
        return None
    if not _CACHE_DIR:
        _CACHE_DIR.append(cache_dir())
    before = numba.config.CACHE_DIR
    numba.config.CACHE_DIR = _CACHE_DIR[0]
    try:  # the cache's place is fixed when caching is enabled: the user's setting is back right after
        out: Any = numba.njit(cache=True)(fn)
    finally:
        numba.config.CACHE_DIR = before
    return out  # type: ignore[no-any-return]


_CACHE_DIR: list[str] = []


def compiled_ops(py_ops: Any) -> Any:
    """A twin's helpers ``py_ops`` (a namespace of kernel functions) compiled, made once per namespace, or
    ``py_ops`` itself without numba."""
    ops = _OPS.get(id(py_ops))
    if ops is None:
        ops = _OPS[id(py_ops)] = type(py_ops)(**{k: compiled(fn) for k, fn in vars(py_ops).items()}) \
            if AVAILABLE else py_ops
    return ops


_OPS: dict[int, Any] = {}


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


def _f64_at(typingctx: Any, address: Any) -> Any:
    types = numba.types
    sig = types.CPointer(types.float64)(types.int64)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        return builder.inttoptr(args[0], context.get_value_type(types.CPointer(types.float64)))

    return sig, codegen


def _call_pp(typingctx: Any, function: Any, a: Any, b: Any) -> Any:
    ir = importlib.import_module("llvmlite.ir")
    types = numba.types
    sig = types.void(types.int64, types.int64, types.int64)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        ptr = ir.IntType(8).as_pointer()
        fn = builder.inttoptr(args[0], ir.FunctionType(ir.VoidType(), [ptr, ptr]).as_pointer())
        builder.call(fn, [builder.inttoptr(args[1], ptr), builder.inttoptr(args[2], ptr)])
        return context.get_dummy_value()

    return sig, codegen


def _call(function: int, a: int, b: int) -> None:
    """Call the C function ``void f(void*, void*)`` at address ``function`` (compiled code only)."""
    call_pp(function, a, b)


f64_at: Any = None
call_pp: Any = None
call: Any = None
if numba is not None:
    f64_at = _extending.intrinsic(_f64_at)
    call_pp = _extending.intrinsic(_call_pp)
    call = compiled(_call)


_MJ_STEP: list[int | None] = []


def mj_step_address() -> int | None:
    """The address of MuJoCo's ``mj_step(const mjModel*, mjData*)``, or None.

    It is in the library the ``mujoco`` bindings themselves load (the same process-wide copy), so
    ``model._address`` / ``data._address`` of the bindings' objects are valid arguments (through
    :func:`call`). None where the library file cannot be found next to the bindings.
    """
    if _MJ_STEP:
        return _MJ_STEP[0]
    fn: int | None = None
    try:
        import mujoco

        base = os.path.dirname(mujoco.__file__)
        found = sorted(glob.glob(os.path.join(base, "libmujoco.so*")) + glob.glob(os.path.join(base, "libmujoco*.dylib"))
                       + glob.glob(os.path.join(base, "mujoco.dll")))
        if found:
            lib = ctypes.CDLL(found[0])
            fn = int(ctypes.cast(lib.mj_step, ctypes.c_void_p).value or 0) or None
    except (ImportError, OSError, AttributeError):  # pragma: no cover - depends on the install
        fn = None
    _MJ_STEP.append(fn)
    return fn
