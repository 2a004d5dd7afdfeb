"""Sensors as the drives report them: the drive's velocity estimate, current measurement, noise, sample age.

Rule: a twin's physics and loops see the exact state; what a READ returns goes through the drive's
:class:`Sensor` first, applied where the register is read (the twins' read paths). The numbers are the
device profile's (fields below, each with its source in the profile's ``sources``); noise is drawn from
one stream per twin, ``random.Random``'s numbers (:mod:`joints.sim.stream`, its state in the sensor's row),
seeded from the twin's identity (family, address) and the world's seed (:func:`seed`), so a lockstep run
is reproducible and two twins never share a stream. The reads are jitable functions of the sensor's rows
(:func:`sense`): compiled or Python, called from Python or from inside a compiled call, the same bits.

=====================  ===============================================================================
profile field          what the drive does to a reported value
=====================  ===============================================================================
``velocity_window``    s, the drive's velocity estimate: encoder counts moved over the last window,
                       divided by it (the position ``window`` ago taken as ``q - v * window``): exactly
                       0 at rest, quantisation noise of ~one count / window / sqrt(6) when moving,
                       and the window's lag (half of it)
``velocity_noise``     rad/s, std of further noise on the velocity estimate (0 for the drives: their
                       noise is the quantisation; tests raise it)
``position_noise``     rad, std of noise on the position beyond the encoder's own quantisation
``current_noise``      A, std of the current measurement's noise (while current flows: a drive whose
                       bridge is off reports 0)
``current_resolution`` A, step of the drive's current measurement (before the register's own unit)
``sample_jitter``      s, age of a reported status value: uniform in [0, sample_jitter] (the drive
                       samples on its own cycle, not when the request arrives); the position is
                       reported as it was that long ago (to first order: q - v * age)
=====================  ===============================================================================

Quantisation by the register's unit (encoder counts, mA, 0.1 r/min ...) stays the register's.
Turn the models off for a test that needs exact values: ``ideal(world)`` (every twin of a world),
or the joint's profile table (``profile = { velocity_noise = 0.0, ... }``).
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from types import SimpleNamespace
from typing import Any, Protocol

from joints.sim import kernel, stream
from joints.sim.kernel import jitable
from joints.sim.stream import gauss as _gauss
from joints.sim.stream import uniform as _uniform

#: the profile fields of a sensor model (each family's profile has them, with sources)
FIELDS = ("velocity_window", "velocity_noise", "position_noise", "current_noise", "current_resolution",
          "sample_jitter")

__all__ = ["FIELDS", "Draws", "Sensor", "SensorModel", "current", "ideal", "model_of", "numbers", "position",
           "scale", "seed", "sense", "sensors_of", "velocity", "warm"]


@dataclass(frozen=True)
class SensorModel:
    """The numbers of one drive's sensors (see the module docstring); all zero: an ideal sensor."""

    velocity_window: float = 0.0
    velocity_noise: float = 0.0
    position_noise: float = 0.0
    current_noise: float = 0.0
    current_resolution: float = 0.0
    sample_jitter: float = 0.0
    ideal: bool = field(init=False, compare=False)  #: every number 0: reads report the exact values

    def __post_init__(self) -> None:
        for name in FIELDS:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ValueError(f"sensor model {name} must be a finite number >= 0, got {v!r}")
        object.__setattr__(self, "ideal", not any(getattr(self, name) for name in FIELDS))

    def scaled(self, factor: float) -> SensorModel:
        """The noise levels (not the filter, resolution or sample age) times ``factor``."""
        return replace(self, velocity_noise=self.velocity_noise * factor, position_noise=self.position_noise * factor,
                       current_noise=self.current_noise * factor)


#: a model whose every read is exact
IDEAL = SensorModel()


def model_of(profile: Any) -> SensorModel:
    """The sensor model a device profile states (fields it lacks are 0)."""
    return SensorModel(**{name: float(getattr(profile, name, 0.0)) for name in FIELDS})


def _seed(key: str, world_seed: int) -> int:
    return zlib.crc32(f"{world_seed}:{key}".encode())


# -- a sensor's numbers and state as rows: the reads as jitable functions of them ---------------------------

#: the columns of a model's numbers (:func:`numbers`)
JITTER, POSITION_NOISE, WINDOW, VELOCITY_NOISE, CURRENT_NOISE, RESOLUTION, K, K_WINDOW = range(8)
#: the columns of a sensor's state row after its stream's (:mod:`joints.sim.stream`): the sample age drawn for
#: the present read [s] and the drive time it was drawn at
AGE, AGE_T = stream.WIDTH, stream.WIDTH + 1
STATE_WIDTH = stream.WIDTH + 2


def numbers(model: SensorModel, counts_per_rad: float) -> list[float]:
    """``model``'s numbers as the reads take them (columns :data:`JITTER` ... :data:`K_WINDOW`): with the encoder's
    counts per rad ``k`` and the velocity estimate's divisor ``k * window``."""
    k = float(counts_per_rad)
    return [model.sample_jitter, model.position_noise, model.velocity_window, model.velocity_noise,
            model.current_noise, model.current_resolution, k, k * model.velocity_window]


@jitable
def estimate(m: Any, q: float, v: float) -> float:
    """The drive's velocity estimate without noise: the encoder counts moved over the window (the position
    ``window`` ago taken as ``q - v * window``) divided by it; ``v`` itself without a window or at rest."""
    window: float = m[WINDOW]
    if window and v:
        k: float = m[K]
        divisor: float = m[K_WINDOW]
        return (math.floor(q * k) - math.floor((q - v * window) * k)) / divisor
    return v


@jitable
def quantised(m: Any, i: float) -> float:
    """The current ``i`` in steps of the measurement's resolution (``i`` itself without one)."""
    resolution: float = m[RESOLUTION]
    if resolution:
        return resolution * round(i / resolution)
    return i


@jitable
def sample_age(s: Any, m: Any, t: float) -> float:
    """The age of the values reported at drive time ``t``: one draw per read time (position and velocity of one
    status read share it)."""
    if t != s[AGE_T]:
        s[AGE_T] = t
        s[AGE] = m[JITTER] * _uniform(s)
    age: float = s[AGE]
    return age


@jitable
def position(s: Any, m: Any, t: float, q: float, v: float) -> float:
    """The position [rad] the drive reports at time ``t`` for a joint at ``q`` moving at ``v``."""
    if m[JITTER]:
        q -= v * sample_age(s, m, t)
    if m[POSITION_NOISE]:
        q += _gauss(s, 0.0, m[POSITION_NOISE])
    return q


@jitable
def velocity(s: Any, m: Any, q: float, v: float) -> float:
    """The drive's velocity estimate [rad/s] of a joint at ``q`` moving at ``v``."""
    v = estimate(m, q, v)
    if m[VELOCITY_NOISE]:
        v += _gauss(s, 0.0, m[VELOCITY_NOISE])
    return v


@jitable
def current(s: Any, m: Any, i: float) -> float:
    """The current [A] the drive measures when ``i`` flows."""
    if m[CURRENT_NOISE] and i:
        i += _gauss(s, 0.0, m[CURRENT_NOISE])
    return quantised(m, i)


@jitable
def sense(s: Any, m: Any, t: float, q: float, v: float, i: float) -> tuple[float, float, float]:
    """``(position, velocity, current)`` of a status read of a joint at ``q`` moving at ``v`` with ``i`` flowing:
    the three reads' draws in that order."""
    return position(s, m, t, q, v), velocity(s, m, q, v), current(s, m, i)


#: the reads as Python
PY_OPS = SimpleNamespace(position=position, velocity=velocity, current=current, sense=sense)


def compiled_ops() -> Any:
    """:data:`PY_OPS` compiled (made once per process; :data:`PY_OPS` itself without numba)."""
    return kernel.compiled_ops(PY_OPS)


class Draws(Protocol):
    """What a generator set as :attr:`Sensor.rng` offers (``random.Random`` does)."""

    def random(self) -> float: ...

    def gauss(self, mu: float, sigma: float) -> float: ...


class _Drawing:
    """The reads of :data:`PY_OPS` drawing from a generator set by the user (``rng``'s bound methods) instead of
    the row's stream: the same rule, the same order of draws; the sample age is still the row's."""

    def __init__(self, rng: Draws) -> None:
        self.random = rng.random
        self.gauss = rng.gauss

    def position(self, s: Any, m: list[float], t: float, q: float, v: float) -> float:
        if m[JITTER]:
            if t != s[AGE_T]:
                s[AGE_T] = t
                s[AGE] = m[JITTER] * self.random()
            q -= v * float(s[AGE])
        if m[POSITION_NOISE]:
            q += self.gauss(0.0, m[POSITION_NOISE])
        return q

    def velocity(self, s: Any, m: list[float], q: float, v: float) -> float:
        v = estimate(m, q, v)
        if m[VELOCITY_NOISE]:
            v += self.gauss(0.0, m[VELOCITY_NOISE])
        return v

    def current(self, s: Any, m: list[float], i: float) -> float:
        if m[CURRENT_NOISE] and i:
            i += self.gauss(0.0, m[CURRENT_NOISE])
        return quantised(m, i)

    def sense(self, s: Any, m: list[float], t: float, q: float, v: float, i: float) -> tuple[float, float, float]:
        return self.position(s, m, t, q, v), self.velocity(s, m, q, v), self.current(s, m, i)


class Sensor:
    """One drive's sensors: a model, its random stream and the sample age's state.

    The stream is :mod:`joints.sim.stream`'s (``random.Random``'s numbers) in the sensor's state row
    (:data:`STATE_WIDTH` columns, the sample age after the stream's), the model's numbers a row too
    (:func:`numbers`, made when the model is set): each read is one call of the jitable function of the same
    name (:func:`position`, :func:`velocity`, :func:`current`; :func:`sense` gives all three with the same
    draws in the same order), compiled unless ``JOINTS_COMPILED=0`` or numba is missing (rows: arrays or
    lists), so compiled code can make the same reads from the same rows. A generator set as :attr:`rng` (a
    ``random.Random``, or anything with ``random()`` and ``gauss(mu, sigma)``) is drawn from instead, in Python;
    :meth:`reseed` goes back to the row's stream.
    """

    def __init__(self, model: SensorModel, key: str, counts_per_rad: float) -> None:
        self.key = key  #: the twin's identity (family:address) the stream is seeded from
        self.nominal = model  #: the profile's model (:meth:`scale` acts on it)
        self.counts_per_rad = float(counts_per_rad)  #: the encoder the velocity is estimated from
        self.world_seed = 0
        self.stream = stream.Stream(_seed(key, 0), width=STATE_WIDTH)  #: the row's stream
        self.compiled = self.stream.compiled  #: the rows are arrays and the reads run compiled
        self.state: Any = self.stream.state  #: the state row: the stream's, then :data:`AGE`, :data:`AGE_T`
        self.state[AGE_T] = math.nan
        self._ops: Any = compiled_ops() if self.compiled else PY_OPS
        self.rng = self.stream
        self.model = model

    @property
    def rng(self) -> Draws:
        """The random stream: :attr:`stream` (the row's), or a generator set here (drawn from in Python)."""
        return self._rng

    @rng.setter
    def rng(self, rng: Draws) -> None:
        self._rng = rng
        self._reads: Any = self._ops if rng is self.stream else _Drawing(rng)  #: the reads' functions
        if hasattr(self, "_floats"):
            self._bind()

    @property
    def model(self) -> SensorModel:
        """The model reads go through (:func:`ideal` and :func:`scale` set it)."""
        return self._model

    @model.setter
    def model(self, model: SensorModel) -> None:
        self._model = model
        self.ideal = model.ideal  #: every number 0: reads report the exact values
        self._floats = numbers(model, self.counts_per_rad)  #: the numbers as Python floats
        self.numbers: Any = kernel.rows([self._floats], self.compiled)[0]  #: the numbers as the reads take them
        self._bind()

    def _bind(self) -> None:
        """The numbers the present reads take: the row, or Python floats for a generator set by the user."""
        self._m: Any = self.numbers if self._reads is self._ops else self._floats

    @property
    def _age(self) -> float:
        """The sample age drawn for the present read [s]."""
        return float(self.state[AGE])

    @_age.setter
    def _age(self, age: float) -> None:
        self.state[AGE] = age

    @property
    def _age_t(self) -> float:
        """The drive time the sample age was drawn at (NaN: none yet)."""
        return float(self.state[AGE_T])

    @_age_t.setter
    def _age_t(self, t: float) -> None:
        self.state[AGE_T] = t

    def reseed(self, world_seed: int | None = None) -> None:
        """Restart the random stream from ``world_seed`` (None: the last one; a power cycle does this)."""
        if world_seed is not None:
            self.world_seed = int(world_seed)
        self.stream.seed(_seed(self.key, self.world_seed))
        self.rng = self.stream
        self.state[AGE_T] = math.nan

    def position(self, t: float, q: float, v: float) -> float:
        """The position [rad] the drive reports at time ``t`` for a joint at ``q`` moving at ``v``."""
        return self._reads.position(self.state, self._m, t, q, v)  # type: ignore[no-any-return]

    def velocity(self, q: float, v: float) -> float:
        """The drive's velocity estimate [rad/s] of a joint at ``q`` moving at ``v``."""
        return self._reads.velocity(self.state, self._m, q, v)  # type: ignore[no-any-return]

    def current(self, i: float) -> float:
        """The current [A] the drive measures when ``i`` flows."""
        return self._reads.current(self.state, self._m, i)  # type: ignore[no-any-return]

    def sense(self, t: float, q: float, v: float, i: float) -> tuple[float, float, float]:
        """``(position(t, q, v), velocity(q, v), current(i))`` in one call: a status read of a joint at ``q``
        moving at ``v`` with ``i`` flowing, the same draws in the same order (the same bits)."""
        return self._reads.sense(self.state, self._m, t, q, v, i)  # type: ignore[no-any-return]


def warm() -> None:
    """Compile (or load from the disk cache) the reads now, as a twin calls them from Python (see
    :func:`joints.sim.erob_kernel.warm`): otherwise a served twin's first read of each kind waits for the compiler
    in the real-time loop (seconds on a cold cache: far past a host's reply timeout)."""
    sensor = Sensor(SensorModel(), "warm", 1.0)
    if sensor._reads is PY_OPS:
        return
    sensor.position(0.0, 0.0, 0.0)
    sensor.velocity(0.0, 0.0)
    sensor.current(0.0)
    sensor.sense(0.0, 0.0, 0.0, 0.0)


def sensors_of(world: Any) -> list[Sensor]:
    """Every twin's sensor in ``world`` (a :class:`joints.sim.world.World`), once each."""
    seen: dict[int, Sensor] = {}
    for twin in world.drives.values():
        for s in getattr(twin, "sensors", ()):
            seen.setdefault(id(s), s)
    return list(seen.values())


def _each(world: Any, names: Iterable[str] | None) -> list[Sensor]:
    if names is None:
        return sensors_of(world)
    out: dict[int, Sensor] = {}
    for name in names:
        twin = world.drives[name]
        for s in getattr(twin, "sensors", ()):
            out.setdefault(id(s), s)
    return list(out.values())


def seed(world: Any, world_seed: int) -> None:
    """Reseed every twin's sensor of ``world`` from ``world_seed`` (each twin its own stream)."""
    for s in sensors_of(world):
        s.reseed(int(world_seed))


def ideal(world: Any, on: bool = True, *, joints: Iterable[str] | None = None) -> None:
    """Ideal sensors (exact values, register quantisation only) for every twin of ``world`` (or
    ``joints``); ``on=False`` restores the profiles' models."""
    for s in _each(world, joints):
        s.model = SensorModel() if on else s.nominal


def scale(world: Any, factor: float, *, joints: Iterable[str] | None = None,
          model: SensorModel | None = None) -> None:
    """The sensors' noise levels at ``factor`` x the profile's (domain randomisation; tests sweeping the
    noise); ``model``: use that model instead of the profile's before scaling."""
    if not (math.isfinite(factor) and factor >= 0):
        raise ValueError(f"sensor noise factor must be >= 0, got {factor!r}")
    for s in _each(world, joints):
        s.model = (model or s.nominal).scaled(factor)
