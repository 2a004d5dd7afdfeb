"""Sensors as the drives report them: the drive's velocity estimate, current measurement, noise, sample age.

Rule: a twin's physics and loops see the exact state; what a READ returns goes through the drive's
:class:`Sensor` first, applied where the register is read (the twins' read paths), outside the
compiled kernels, so the bits never depend on the kernel choice. The numbers are the device
profile's (fields below, each with its source in the profile's ``sources``); noise is drawn from
one generator per twin, seeded from the twin's identity (family, address) and the world's seed
(:func:`seed`), so a lockstep run is reproducible and two twins never share a stream.

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
import random
import zlib
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import Any

#: the profile fields of a sensor model (each family's profile has them, with sources)
FIELDS = ("velocity_window", "velocity_noise", "position_noise", "current_noise", "current_resolution",
          "sample_jitter")

__all__ = ["FIELDS", "Sensor", "SensorModel", "ideal", "model_of", "scale", "seed", "sensors_of"]


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


class Sensor:
    """One drive's sensors: a model, its random stream and the velocity filter's state.

    The model's numbers are taken apart once, when the model is set (:attr:`model`), and the stream's draws are
    bound methods of its generator (:attr:`rng`), so a read costs its arithmetic and its draws; :meth:`sense`
    gives a status read's position, velocity and current in one call, drawing exactly what :meth:`position`,
    :meth:`velocity` and :meth:`current` would, in that order.
    """

    def __init__(self, model: SensorModel, key: str, counts_per_rad: float) -> None:
        self.key = key  #: the twin's identity (family:address) the stream is seeded from
        self.nominal = model  #: the profile's model (:meth:`scale` acts on it)
        self.counts_per_rad = float(counts_per_rad)  #: the encoder the velocity is estimated from
        self.world_seed = 0
        self.rng = random.Random(_seed(key, 0))
        self.model = model
        self._age = 0.0  #: the sample age drawn for the present read [s]
        self._age_t = math.nan  #: the drive time it was drawn at

    @property
    def rng(self) -> random.Random:
        """The random stream (a generator set here is drawn from through its bound methods)."""
        return self._rng

    @rng.setter
    def rng(self, rng: random.Random) -> None:
        self._rng = rng
        self._random = rng.random
        self._gauss = rng.gauss

    @property
    def model(self) -> SensorModel:
        """The model reads go through (:func:`ideal` and :func:`scale` set it)."""
        return self._model

    @model.setter
    def model(self, model: SensorModel) -> None:
        self._model = model
        self.ideal = model.ideal  #: every number 0: reads report the exact values
        self._jitter = model.sample_jitter
        self._position_noise = model.position_noise
        self._window = model.velocity_window
        self._velocity_noise = model.velocity_noise
        self._current_noise = model.current_noise
        self._resolution = model.current_resolution
        self._k_window = self.counts_per_rad * model.velocity_window  #: the estimate's divisor, k * window

    def reseed(self, world_seed: int | None = None) -> None:
        """Restart the random stream from ``world_seed`` (None: the last one; a power cycle does this)."""
        if world_seed is not None:
            self.world_seed = int(world_seed)
        self.rng = random.Random(_seed(self.key, self.world_seed))
        self._age_t = math.nan

    def _sample_age(self, t: float) -> float:
        """The age of the values reported at drive time ``t`` (one draw per read time: position and
        velocity of one status read share it)."""
        jitter = self._jitter
        if not jitter:
            return 0.0
        if t != self._age_t:
            self._age_t = t
            self._age = jitter * self._random()
        return self._age

    def position(self, t: float, q: float, v: float) -> float:
        """The position [rad] the drive reports at time ``t`` for a joint at ``q`` moving at ``v``."""
        if self._jitter:
            q -= v * self._sample_age(t)
        if self._position_noise:
            q += self._gauss(0.0, self._position_noise)
        return q

    def velocity(self, q: float, v: float) -> float:
        """The drive's velocity estimate [rad/s] of a joint at ``q`` moving at ``v``."""
        window = self._window
        if window and v:
            k = self.counts_per_rad
            v = (math.floor(q * k) - math.floor((q - v * window) * k)) / self._k_window
        if self._velocity_noise:
            v += self._gauss(0.0, self._velocity_noise)
        return v

    def current(self, i: float) -> float:
        """The current [A] the drive measures when ``i`` flows."""
        if self._current_noise and i:
            i += self._gauss(0.0, self._current_noise)
        resolution = self._resolution
        if resolution:
            i = resolution * round(i / resolution)
        return i

    def sense(self, t: float, q: float, v: float, i: float) -> tuple[float, float, float]:
        """``(position(t, q, v), velocity(q, v), current(i))`` in one call: a status read of a joint at ``q``
        moving at ``v`` with ``i`` flowing, the same draws in the same order (the same bits)."""
        gauss = self._gauss
        jitter = self._jitter
        pos = q
        if jitter:
            if t != self._age_t:
                self._age_t = t
                self._age = jitter * self._random()
            pos -= v * self._age
        if self._position_noise:
            pos += gauss(0.0, self._position_noise)
        window = self._window
        vel = v
        if window and v:
            k = self.counts_per_rad
            vel = (math.floor(q * k) - math.floor((q - v * window) * k)) / self._k_window
        if self._velocity_noise:
            vel += gauss(0.0, self._velocity_noise)
        if self._current_noise and i:
            i += gauss(0.0, self._current_noise)
        resolution = self._resolution
        if resolution:
            i = resolution * round(i / resolution)
        return pos, vel, i


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
