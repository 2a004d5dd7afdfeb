"""CPython's random stream with its state in a row, so that compiled code can draw the very numbers
``random.Random`` would.

Rule: a stream is MT19937 (Matsumoto and Nishimura's generator, as CPython's ``random`` module runs it) whose
624 words, index and :meth:`random.Random.gauss` cache live in one row of floats (:data:`WIDTH` columns; a
list with the words as ints in Python). The functions below are jitable (:func:`joints.sim.kernel.jitable`):
plain Python when called from Python, compiled into the kernels that call them; both give the bits of
``random.Random(n)``:

- :func:`uniform` is ``random()``: two words, ``(a * 2**26 + b) / 2**53`` of their top 27 and 26 bits;
- :func:`gauss` is ``gauss(mu, sigma)``: Box-Muller of two ``random()``, the second value cached for the next
  call, ``mu + z * sigma`` (the expressions in CPython's order: ``math`` is the same libm compiled or not).

:class:`Stream` offers a row as a ``random.Random`` does (``random``, ``gauss``, ``seed``, ``getstate``,
``setstate``, states interchangeable with ``random.Random``'s). Seeding is Python's only: ``Stream.seed(n)`` puts
``random.Random(int(n))``'s words in the row (a seed is set when a twin is made or reset, never inside a compiled
call).
"""

from __future__ import annotations

import functools
import math
import random
from array import array
from types import SimpleNamespace
from typing import Any

from joints.sim import kernel
from joints.sim.kernel import jitable

__all__ = ["CACHED", "GAUSS", "INDEX", "WIDTH", "N", "Stream", "gauss", "twist", "uniform", "word"]

N = 624  #: MT19937's words
_M = 397  #: the recurrence's middle term
INDEX = N  #: the column of the next word's index (N: twist first)
GAUSS = N + 1  #: the column of gauss's cached second value
CACHED = N + 2  #: the column that is 1.0 while that value is cached
WIDTH = N + 3  #: a stream's columns

_MATRIX = 0x9908B0DF  #: the twist's matrix A (its last row)
_UPPER = 0x80000000  #: the top bit of a word
_LOWER = 0x7FFFFFFF  #: the other 31
_MASK = 0xFFFFFFFF
_TWOPI = 2.0 * math.pi
_SCALE = 1.0 / 9007199254740992.0  #: 2**-53
_WORD = "L"  #: an unsigned C type of at least 32 bits: a state's words as a buffer (numpy converts it at C speed)


@jitable
def twist(s: Any) -> None:
    """The next 624 words from the present ones (MT19937's recurrence, in place), the index back to 0."""
    for k in range(N):
        j = k + 1 if k + 1 < N else 0
        m = k + _M if k + _M < N else k + _M - N
        y = (int(s[k]) & _UPPER) | (int(s[j]) & _LOWER)
        x = int(s[m]) ^ (y >> 1)
        if y & 1:
            x ^= _MATRIX
        s[k] = x
    s[INDEX] = 0


@jitable
def word(s: Any) -> int:
    """The stream's next 32-bit word (tempered); the words are twisted first when all 624 are used."""
    k = int(s[INDEX])
    if k >= N:
        twist(s)
        k = 0
    s[INDEX] = k + 1
    y = int(s[k])
    y ^= y >> 11
    y ^= (y << 7) & 0x9D2C5680
    y ^= (y << 15) & 0xEFC60000
    return y ^ (y >> 18)


@jitable
def uniform(s: Any) -> float:
    """``random.random()``: a float in [0, 1) from two words (53 random bits)."""
    a = word(s) >> 5
    b = word(s) >> 6
    return (a * 67108864.0 + b) * _SCALE


@jitable
def gauss(s: Any, mu: float, sigma: float) -> float:
    """``random.gauss(mu, sigma)``: the cached value if there is one, else two new ones (Box-Muller), the second
    cached."""
    if s[CACHED]:
        s[CACHED] = 0.0
        z: float = s[GAUSS]
    else:
        x2pi = uniform(s) * _TWOPI
        g2rad = math.sqrt(-2.0 * math.log(1.0 - uniform(s)))
        z = math.cos(x2pi) * g2rad
        s[GAUSS] = math.sin(x2pi) * g2rad
        s[CACHED] = 1.0
    return mu + z * sigma


@functools.lru_cache(maxsize=1024)
def _seeded(n: int) -> array[int]:
    """``random.Random(n)``'s words (``random.seed(n)``'s state) as a buffer, made once per seed: a world's reset
    reseeds each twin with the seed it had."""
    return array(_WORD, random.Random(n).getstate()[1])


#: the stream's functions as Python
PY_OPS = SimpleNamespace(word=word, uniform=uniform, gauss=gauss)


def compiled_ops() -> Any:
    """:data:`PY_OPS` compiled (made once per process; :data:`PY_OPS` itself without numba)."""
    return kernel.compiled_ops(PY_OPS)


def ops_for(compiled: bool) -> Any:
    """The stream's functions for a row of that kind: compiled for an array, Python for a list."""
    return compiled_ops() if compiled else PY_OPS


def row(width: int, compiled: bool) -> Any:
    """A row of ``width`` zeros (``width >= WIDTH``): a float64 array (compiled) or a list (Python)."""
    if width < WIDTH:
        raise ValueError(f"a stream's row has at least {WIDTH} columns, got {width}")
    return kernel.table(1, width, compiled)[0]


class Stream:
    """A :class:`random.Random` of the row ``state`` (its first :data:`WIDTH` columns; the rest are the owner's):
    the same numbers, the same ``getstate()``. ``compiled``: the row is an array and the draws from Python run
    compiled (default: :func:`joints.sim.kernel.default_mode`)."""

    def __init__(self, n: int = 0, *, compiled: bool | None = None, width: int = WIDTH) -> None:
        self.compiled = kernel.default_mode() if compiled is None else bool(compiled)
        self.state: Any = row(width, self.compiled)  #: the row the functions above draw from
        self.ops: Any = ops_for(self.compiled)  #: those functions, compiled or Python
        self.seed(n)

    def seed(self, n: int) -> None:
        """``random.seed(int(n))`` (``n``: anything ``int()`` takes): CPython's own initialisation's words put in
        the row, the gauss cache dropped."""
        self._put(_seeded(int(n)), None)

    def random(self) -> float:
        """``random.random()``."""
        return float(self.ops.uniform(self.state))

    def gauss(self, mu: float = 0.0, sigma: float = 1.0) -> float:
        """``random.gauss(mu, sigma)``."""
        return float(self.ops.gauss(self.state, float(mu), float(sigma)))

    def getstate(self) -> tuple[int, tuple[int, ...], float | None]:
        """The state as ``random.Random.getstate()`` gives it (either class's ``setstate`` takes it)."""
        s = self.state
        words = tuple(int(x) for x in s[:INDEX + 1])
        return 3, words, float(s[GAUSS]) if s[CACHED] else None

    def setstate(self, state: tuple[int, tuple[int, ...], float | None]) -> None:
        """Continue from ``state`` (:meth:`getstate`'s, or a ``random.Random``'s)."""
        version, words, cached = state
        if version != 3 or len(words) != N + 1 or not all(isinstance(w, int) and 0 <= w <= _MASK for w in words) \
                or words[INDEX] > N:
            raise ValueError("invalid state for a random stream (random.Random's version 3 expected)")
        self._put(array(_WORD, words), cached)

    def _put(self, words: array[int], cached: float | None) -> None:
        """The row from a valid state's words (one slice: an array's at C speed, a list's as ints) and gauss
        cache."""
        s = self.state
        s[:INDEX + 1] = words
        s[GAUSS] = 0.0 if cached is None else float(cached)
        s[CACHED] = 0.0 if cached is None else 1.0
