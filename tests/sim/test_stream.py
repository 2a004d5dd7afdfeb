"""The sensors' random stream in a row (:mod:`joints.sim.stream`) is CPython's ``random.Random``, bit for bit, as
Python and compiled; :class:`~joints.sim.sensors.Sensor`'s reads over it are main's reads over ``random.Random``
(:class:`_Reference`, the implementation before the row, kept here), also from inside a compiled function."""

from __future__ import annotations

import math
import random
import zlib
from typing import Any

import numpy as np
import pytest

from joints.sim import kernel, sensors, stream
from joints.sim.sensors import Sensor, SensorModel
from simkit import sensor_reads

#: the row kinds under test: Python (lists) always, compiled (arrays) unless JOINTS_COMPILED=0 or no numba
MODES = sorted({False, kernel.default_mode()})

SEEDS = [0, 1, 7, 2**31, 2**32 - 1, 2**32, 2**32 + 1, 2**64 + 5, 12345678901234567890123456789012345678901234567890,
         -99, zlib.crc32(b"0:erob:1"), zlib.crc32(b"3:zlac:2:left")]

#: the fraction of gauss draws in :func:`_draws` (the others are random())
_GAUSS_EVERY = 3


def _draws(r: Any, n: int) -> list[float]:
    """``n`` draws of ``r``: every third a ``gauss`` (mu, sigma varying), the others ``random()``."""
    out = []
    for k in range(n):
        out.append(r.gauss(0.25 * (k % 5), 0.5 + k % 3) if k % _GAUSS_EVERY == 0 else r.random())
    return out


def _bits(xs: Any) -> bytes:
    return np.asarray(xs, dtype=np.float64).tobytes()


@pytest.mark.parametrize("compiled", MODES)
@pytest.mark.parametrize("seed", SEEDS)
def test_a_seeded_stream_is_random_Random_s(seed: int, compiled: bool) -> None:
    s = stream.Stream(seed, compiled=compiled)
    ref = random.Random(seed)
    assert s.getstate() == ref.getstate()
    assert _bits(_draws(s, 2000)) == _bits(_draws(ref, 2000))  # three twists, gauss cached or not
    assert s.getstate() == ref.getstate()


#: seeds of other kinds than int: each is ``int(n)``'s (a sensor's seed is a crc32, an int)
OTHER_KINDS = [True, 3.7, -2.0, "12", b"12", bytearray(b"-12"), np.int64(9), np.uint32(2**32 - 1), np.float64(2.5)]


@pytest.mark.parametrize("compiled", MODES)
@pytest.mark.parametrize("seed", OTHER_KINDS, ids=repr)
def test_a_seed_is_int_n(seed: Any, compiled: bool) -> None:
    assert stream.Stream(seed, compiled=compiled).getstate() == random.Random(int(seed)).getstate()


@pytest.mark.parametrize("compiled", MODES)
@pytest.mark.parametrize(("seed", "error"), [(None, TypeError), ("abc", ValueError), ([1], TypeError),
                                             (1 + 2j, TypeError), (math.inf, OverflowError), (math.nan, ValueError)])
def test_a_seed_int_refuses_is_refused_as_int_refuses_it(seed: Any, error: type, compiled: bool) -> None:
    with pytest.raises(error):
        int(seed)
    s = stream.Stream(3, compiled=compiled)
    with pytest.raises(error):
        s.seed(seed)
    assert s.getstate() == random.Random(3).getstate()  # the row untouched


def _fill(s: Any, out: Any) -> None:
    """``out`` filled with draws of the stream row ``s`` as :func:`_draws` makes them (compiled in the test)."""
    for k in range(len(out)):
        out[k] = stream.gauss(s, 0.25 * (k % 5), 0.5 + k % 3) if k % _GAUSS_EVERY == 0 else stream.uniform(s)


@pytest.mark.parametrize(("seed", "compiled"), [(0, False)] + [(seed, True) for seed in (0, 2**32 + 1, zlib.crc32(
    b"0:erob:1")) if kernel.default_mode()])
def test_a_long_run_of_draws_is_random_Random_s(seed: int, compiled: bool) -> None:
    """120 000 draws (40 000 gauss interleaved with random()): 400 twists; compiled: drawn inside a compiled loop."""
    n = 120_000
    s = stream.Stream(seed, compiled=compiled)
    if compiled:
        fill = kernel.numba.njit(_fill)
        out = np.zeros(n)
        fill(s.state, out)
        assert fill.signatures  # the compiled loop ran
        got = out
    else:
        got = _draws(s, n)
    ref = random.Random(seed)
    assert _bits(got) == _bits(_draws(ref, n))
    assert s.getstate() == ref.getstate()


@pytest.mark.parametrize("compiled", MODES)
def test_states_pass_between_the_stream_and_random_Random(compiled: bool) -> None:
    s = stream.Stream(5, compiled=compiled)
    ref = random.Random(5)
    s.gauss(0.0, 1.0)
    ref.gauss(0.0, 1.0)  # a gauss value cached in both
    state = s.getstate()
    assert state == ref.getstate() and state[2] is not None
    other = random.Random()
    other.setstate(state)
    assert _bits(_draws(other, 1000)) == _bits(_draws(s, 1000))
    s.setstate(ref.getstate())
    assert _bits(_draws(s, 1000)) == _bits(_draws(ref, 1000))
    s.seed(5)  # seeding drops the cached value
    assert s.getstate() == random.Random(5).getstate()
    for bad in [(2, state[1], None), (3, state[1][:-1], None), (3, (*state[1][:-1], 625), None),
                (3, (-1, *state[1][1:]), None)]:
        with pytest.raises(ValueError):
            s.setstate(bad)  # type: ignore[arg-type]


# -- the sensors -----------------------------------------------------------------------------------------------

class _Reference:
    """main's Sensor (before the row): a model's reads drawing from ``random.Random`` through its bound methods."""

    def __init__(self, model: SensorModel, key: str, counts_per_rad: float, world_seed: int) -> None:
        self.rng = random.Random(zlib.crc32(f"{world_seed}:{key}".encode()))
        self.m = model
        self.k = counts_per_rad
        self.age = 0.0
        self.age_t = math.nan

    def position(self, t: float, q: float, v: float) -> float:
        m = self.m
        if m.sample_jitter:
            if t != self.age_t:
                self.age_t = t
                self.age = m.sample_jitter * self.rng.random()
            q -= v * self.age
        if m.position_noise:
            q += self.rng.gauss(0.0, m.position_noise)
        return q

    def velocity(self, q: float, v: float) -> float:
        window = self.m.velocity_window
        if window and v:
            k = self.k
            v = (math.floor(q * k) - math.floor((q - v * window) * k)) / (k * window)
        if self.m.velocity_noise:
            v += self.rng.gauss(0.0, self.m.velocity_noise)
        return v

    def current(self, i: float) -> float:
        if self.m.current_noise and i:
            i += self.rng.gauss(0.0, self.m.current_noise)
        if self.m.current_resolution:
            i = self.m.current_resolution * round(i / self.m.current_resolution)
        return i

    def sense(self, t: float, q: float, v: float, i: float) -> tuple[float, float, float]:
        return self.position(t, q, v), self.velocity(q, v), self.current(i)


MODELS = [
    SensorModel(velocity_window=0.001, current_noise=0.02),  # the eRob's
    SensorModel(velocity_window=0.05, current_noise=0.05, sample_jitter=0.001),  # the ZLAC8015D's
    SensorModel(velocity_window=0.005, sample_jitter=0.0005),  # the MKS's
    SensorModel(velocity_window=0.002, velocity_noise=0.01, position_noise=1e-4, current_noise=0.02,
                current_resolution=0.01, sample_jitter=5e-4),
    SensorModel(position_noise=1e-3, current_resolution=0.1),
    SensorModel(velocity_noise=0.3),
]
COUNTS = [524288 / (2 * math.pi), 16384 / (2 * math.pi), 4096 / (2 * math.pi)]


def _sensor(model: SensorModel, counts: float, compiled: bool, monkeypatch: pytest.MonkeyPatch) -> Sensor:
    monkeypatch.setenv(kernel.SWITCH, "1" if compiled else "0")
    s = Sensor(model, "erob:3", counts)
    assert s.compiled == compiled
    s.reseed(4)
    return s


@pytest.mark.parametrize("compiled", MODES)
@pytest.mark.parametrize("counts", COUNTS)
@pytest.mark.parametrize("model", MODELS)
def test_a_sensor_s_reads_are_main_s(model: SensorModel, counts: float, compiled: bool,
                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """``sense`` and the three reads alone, 1500 reads each: the same bits and the same stream after."""
    s = _sensor(model, counts, compiled, monkeypatch)
    ref = _Reference(model, "erob:3", counts, 4)
    for n, (t, q, v, i) in enumerate(sensor_reads(COUNTS.index(counts), 3000)):
        if n % 2:
            got, want = s.sense(t, q, v, i), ref.sense(t, q, v, i)
        else:
            got = (s.position(t, q, v), s.velocity(q, v), s.current(i))
            want = (ref.position(t, q, v), ref.velocity(q, v), ref.current(i))
        assert _bits(got) == _bits(want), (n, got, want)
    assert s.rng.getstate() == ref.rng.getstate()
    assert repr((s._age, s._age_t)) == repr((ref.age, ref.age_t))


@pytest.mark.parametrize("compiled", MODES)
def test_a_generator_set_as_rng_is_drawn_from_and_reseed_goes_back_to_the_row(
        compiled: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    model = MODELS[3]
    s = _sensor(model, COUNTS[0], compiled, monkeypatch)
    ref = _Reference(model, "erob:3", COUNTS[0], 4)
    mine = s.rng.getstate()
    s.rng = ref_rng = random.Random(21)
    ref.rng = random.Random(21)
    for t, q, v, i in sensor_reads(8, 300):
        assert _bits(s.sense(t, q, v, i)) == _bits(ref.sense(t, q, v, i))
    assert ref_rng.getstate() == ref.rng.getstate()  # the user's generator was drawn from
    assert s.stream.getstate() == mine  # the row's stream was not
    s.reseed()
    assert s.rng is s.stream and s.rng.getstate() == random.Random(zlib.crc32(b"4:erob:3")).getstate()


@pytest.mark.parametrize("compiled", MODES)
def test_a_sensor_s_world_seed_is_int_world_seed(compiled: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """What ``reseed`` takes: anything ``int()`` takes (None: the last seed); the stream is ``random.Random`` of
    the crc32 of ``int(world_seed)`` and the key."""
    s = _sensor(MODELS[0], COUNTS[0], compiled, monkeypatch)
    want = random.Random(zlib.crc32(b"4:erob:3")).getstate()
    for world_seed in (None, 4, "4", 4.9, np.int64(4), None):
        s.stream.gauss()
        s.reseed(world_seed)
        assert s.world_seed == 4 and s.stream.getstate() == want
    for bad, error in (("x", ValueError), ([4], TypeError)):
        with pytest.raises(error):
            s.reseed(bad)  # type: ignore[arg-type]


def _sense_all(s: Any, m: Any, reads: Any, out: Any) -> None:
    """Every read of ``reads`` (rows t, q, v, i) through :func:`joints.sim.sensors.sense` (compiled in the test)."""
    for k in range(reads.shape[0]):
        p, v, c = sensors.sense(s, m, reads[k, 0], reads[k, 1], reads[k, 2], reads[k, 3])
        out[k, 0] = p
        out[k, 1] = v
        out[k, 2] = c


@pytest.mark.skipif(not kernel.default_mode(), reason="compiled code off (JOINTS_COMPILED=0 or no numba)")
@pytest.mark.parametrize("model", MODELS)
def test_reads_made_inside_a_compiled_function_are_main_s(model: SensorModel,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """The next step's shape: a compiled call reading the sensor's rows itself gives main's reads and leaves the
    sensor where main's leaves it (the Python reads after it continue the same stream)."""
    s = _sensor(model, COUNTS[1], True, monkeypatch)
    ref = _Reference(model, "erob:3", COUNTS[1], 4)
    reads = np.array(sensor_reads(2, 2000))
    out = np.zeros((len(reads), 3))
    inside = kernel.numba.njit(_sense_all)
    inside(s.state, s.numbers, reads, out)
    assert inside.signatures  # the compiled loop ran
    assert _bits(out) == _bits([ref.sense(*r) for r in reads.tolist()])
    assert s.rng.getstate() == ref.rng.getstate()
    for t, q, v, i in sensor_reads(9, 200):
        assert _bits(s.sense(t, q, v, i)) == _bits(ref.sense(t, q, v, i))
