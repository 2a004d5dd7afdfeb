"""The sensor model's one-call read (``Sensor.sense``) against its three reads, bit for bit, and the model's
numbers and stream taken apart once (a model or generator set later is the one reads use)."""

from __future__ import annotations

import math
import random
from types import SimpleNamespace
from typing import Any

import pytest

from joints.devices.erob.profiles import profile
from joints.sim import kernel, sensors, stepping
from joints.sim.sensors import IDEAL, Sensor, SensorModel
from simkit import erob_world, sensor_reads

MODELS = [
    SensorModel(),
    SensorModel(velocity_window=0.05, current_noise=0.05, sample_jitter=0.001),  # the ZLAC8015D's kind
    SensorModel(velocity_window=0.002, velocity_noise=0.01, position_noise=1e-4, current_noise=0.02,
                current_resolution=0.01, sample_jitter=5e-4),
    SensorModel(position_noise=1e-3, current_resolution=0.1),
    SensorModel(velocity_noise=0.3),
]



@pytest.mark.parametrize("model", MODELS)
def test_sense_gives_the_three_reads_bits_and_leaves_the_stream_where_they_do(model: SensorModel) -> None:
    apart = Sensor(model, "zlac:1:left", 16384 / (2 * math.pi))
    together = Sensor(model, "zlac:1:left", 16384 / (2 * math.pi))
    for s in (apart, together):
        s.reseed(11)
    for t, q, v, i in sensor_reads(3, 400):
        want = (apart.position(t, q, v), apart.velocity(q, v), apart.current(i))
        got = together.sense(t, q, v, i)
        assert [x.hex() for x in got] == [float(x).hex() for x in want]
        assert together.rng.getstate() == apart.rng.getstate()
        assert repr((together._age, together._age_t)) == repr((apart._age, apart._age_t))


def test_a_model_set_later_is_the_one_reads_use() -> None:
    noisy = SensorModel(velocity_window=0.05, velocity_noise=0.1, position_noise=1e-3, current_noise=0.05,
                        current_resolution=0.01, sample_jitter=1e-3)
    s = Sensor(noisy, "erob:1", 1000.0)
    assert not s.ideal
    s.model = IDEAL
    assert s.ideal and s.model is IDEAL
    before = s.rng.getstate()
    assert s.sense(0.1, 1.25, 3.0, 2.5) == (1.25, 3.0, 2.5)  # exact, no draw
    assert s.rng.getstate() == before
    s.model = noisy.scaled(0.0)  # noise off, the filter and resolution stay
    assert s.current(0.123) == pytest.approx(0.12) and s.rng.getstate() == before


def test_a_generator_set_later_is_the_one_reads_draw_from() -> None:
    model = SensorModel(position_noise=1e-3)
    s = Sensor(model, "mks:1", 1000.0)
    s.rng = random.Random(5)
    ref = random.Random(5)
    assert s.position(0.0, 0.5, 0.0) == 0.5 + ref.gauss(0.0, 1e-3)
    s.reseed(9)  # a new stream, drawn from
    again = Sensor(model, "mks:1", 1000.0)
    again.reseed(9)
    assert s.position(0.0, 0.5, 0.0) == again.position(0.0, 0.5, 0.0)


def test_a_compiled_world_compiles_the_reads_its_twins_make_from_python_before_it_runs(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A Python twin (MKS) makes its reads from Python; making a compiled world compiles them (``stepping._warm``)
    with the types the twin passes, so a served twin's first read never waits for the compiler in the real-time
    loop (seconds on a cold cache: the MKS pty test's retries, docs/speed-log.md). Calls are recorded, not timed."""
    pytest.importorskip("mujoco")
    if not kernel.default_mode():
        pytest.skip("the reads run in Python (no numba, or JOINTS_COMPILED=0)")
    import numba
    from mkskit import axis_config

    import joints

    phase = ["made"]
    calls: dict[str, set[tuple[str, tuple[Any, ...]]]] = {"warm": set(), "made": set()}

    def recorded(name: str, fn: Any) -> Any:
        def call(*args: Any) -> Any:
            calls[phase[-1]].add((name, tuple(numba.typeof(a) for a in args)))
            return fn(*args)
        return call

    warm = stepping._warm

    def warming() -> None:
        phase.append("warm")
        warm()
        phase.pop()

    compiled = sensors.compiled_ops()
    monkeypatch.setitem(kernel._OPS, id(sensors.PY_OPS),
                        SimpleNamespace(**{k: recorded(k, f) for k, f in vars(compiled).items()}))
    monkeypatch.setattr(stepping, "_WARM", [])  # this process's warm done again, recorded
    monkeypatch.setattr(stepping, "_warm", warming)
    with joints.open(axis_config(backend="sim")) as rig:
        joint = rig.joints["carriage"]
        joint.enable()
        joint.driver.read("encoder_addition")
        joint.driver.read("real_time_speed")
    assert {name for name, _ in calls["made"]} >= {"position", "velocity"}  # the MKS twin's reads, from Python
    assert calls["made"] <= calls["warm"]


def test_a_world_reset_with_a_seed_reseeds_every_twin_and_one_without_keeps_it() -> None:
    world = erob_world("erob_arm3.xml", ["joint1", "joint2"], profile("eRob80H100"))
    try:
        twins = sensors.sensors_of(world)
        assert len(twins) == 2
        world.reset(seed=21)
        first = [s.rng.getstate() for s in twins]
        assert first[0] != first[1]  # each twin its own stream
        assert [s.world_seed for s in twins] == [21, 21]
        twins[0].current(1.0)  # a draw, then a reset without a seed: back to the same streams
        world.reset()
        assert [s.rng.getstate() for s in twins] == first
        world.reset(seed=22)
        assert [s.rng.getstate() for s in twins] != first
    finally:
        world.close()
