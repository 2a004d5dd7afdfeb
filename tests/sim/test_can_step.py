"""The eRob CAN env step in one call (``ErobCanStep.step`` by ``CompiledPath.step``) gives the bits of the same env
with it off (the command, the env's wait for its tick and the state read one after the other, each its own call).

``joints/ErobReach-v0`` at 20 ms on the eRob CAN custom protocol at 1 Mbit/s (``joints bench``'s CAN row), in each
action mode, runs the same seeded actions twice: with the one-call step, and with ``ErobCanStep.step`` answering
None (nothing sent: the env's own three). Over 120 steps (2.4 s: temperature reads made and skipped by the call's
own test of the clock), with a late tick (an overrun: no hold), a set-point the drive is no longer ready for (held
inside the call: the call stops before the wait) or a start it refuses, and a fault that makes the exchange refuse
the step: observations, rewards, infos, ends, every joint's state and contact, the medium's time and counters, the
world and its clock, the firmware's store, write log and row, the front's counts and the link's must be equal; the
one-call step must have been taken on one run (``steps_taken``) and never on the other.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401 - registers the joints/ envs
from joints.bench import _baseline_config
from joints.codecs import erob_can as ec
from joints.drivers.erob_can_steady import ErobCanStep
from joints.errors import DeviceRejected, UnexpectedReply
from joints.sim import erob_kernel as K
from joints.sim import kernel

PERIOD = 0.02
STEPS = 120

pytestmark = pytest.mark.skipif(not kernel.default_mode(), reason="the one-call step needs the compiled world")


def _config() -> dict[str, Any]:
    found = _baseline_config("joints/ErobReach-v0")
    assert found is not None and found[1].startswith("erob-can"), found
    config: dict[str, Any] = found[0]
    return config


def _enc(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return v.dtype.str, v.shape, v.tobytes()
    if isinstance(v, dict):
        return [(k, _enc(x)) for k, x in v.items()]
    return repr(v)


def _state(u: Any) -> list[Any]:
    """Every bit of the rig the step touches: world and clock, medium, bus and fronts, firmware, joint, link."""
    world = u.rig.sim
    bus = next(iter(world.buses.values()))
    medium = bus.medium
    out: list[Any] = [(world.steps, world._target, world._booked, world._held, world.clock.now()),
                      (medium.now, medium._free, medium._clock_seen, medium._ticked, medium.frames, medium.bits,
                       medium.busy, repr(medium._seq)), (bus._last_tick, [(f.requests, f.held) for f in bus.fronts])]
    for f in bus.fronts:
        fw = f.firmware
        out.append((sorted(fw.values.items()), list(fw.write_log), np.asarray(fw._row, dtype=float).tobytes(),
                    fw.sensor.rng.getstate()))
    for j in u.joints:
        d = j.driver
        out.append((repr(j.last_state), j.last_contact, j.enabled, sorted(d._cache.items()), d._temperature,
                    d.link.transactions, d.link.fences, sorted(d.link._unsynced)))
    return out


def _run(mode: str, one_call: bool, monkeypatch: pytest.MonkeyPatch, plant: Any = None) -> dict[str, Any]:
    """The env's run (``plant(k, u)`` before step ``k``), recorded step by step."""
    with monkeypatch.context() as m:
        if not one_call:
            m.setattr(ErobCanStep, "step", lambda self, mode, values, tick: None)
        env = gym.make("joints/ErobReach-v0", config=_config(), control_period=PERIOD, action_mode=mode)
        u: Any = env.unwrapped
        try:
            (stepper,) = u.compiled_path._steppers
            apart = []  # steps whose call stopped before the wait (a set-point held): waited and read after it
            waited = stepper._wait_and_read
            stepper._wait_and_read = lambda tick: apart.append(tick) or waited(tick)
            obs, info = env.reset(seed=3)
            rec: list[Any] = [(_enc(obs), _enc(info))]
            rng = np.random.default_rng(5)
            temps = {stepper.driver._temperature}  # (the time of each temperature read)
            for k in range(STEPS):
                if plant is not None:
                    plant(k, u)
                action = rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32)
                try:
                    obs, reward, terminated, truncated, info = env.step(action)
                except DeviceRejected as exc:
                    rec.append(("refused", str(exc), exc.code, _state(u)))
                    break
                rec.append((_enc(obs), reward, terminated, truncated, _enc(info), _state(u)))
                temps.add(stepper.driver._temperature)
                if terminated or truncated:
                    obs, info = env.reset()
                    rec.append(("reset", _enc(obs), _enc(info), _state(u)))
            rec.append((_state(u), u.overruns, u.overrun_time))
            return {"rec": rec, "taken": u.compiled_path.steps_taken, "apart": len(apart), "temperatures": temps}
        finally:
            env.close()


def _same(mode: str, monkeypatch: pytest.MonkeyPatch, plant: Any = None) -> dict[str, Any]:
    off = _run(mode, False, monkeypatch, plant)
    on = _run(mode, True, monkeypatch, plant)
    assert off["taken"] == 0
    assert on["taken"] > 0
    for k, (a, b) in enumerate(zip(on["rec"], off["rec"], strict=True)):
        assert a == b, k
    return on


#: s a steady command takes on the wire in each mode (a target and "start"; a set-point), for :func:`_late`
COMMAND = {"position": 0.00232, "velocity": 0.00118, "torque": 0.00118}


def _late(mode: str) -> Any:
    """Before step 40 the host is 25 ms late (a tick missed: an overrun, no wait); before step 70, 5 ms (a
    shorter wait); before steps 80-89, late so much that the wait is 0.1, 0.2, ... 0.9 substeps (a wait that
    may end before the physics' next substep: nothing due when the read's call runs it)."""

    def plant(k: int, u: Any) -> None:
        if k == 40:
            u.rig.sleep(0.025)
        elif k == 70:
            u.rig.sleep(0.005)
        elif 80 <= k < 90:
            wait = (k - 79) * 0.1 * u.rig.sim.timestep
            u.rig.sleep(u.tick_time(1) - u.rig.time - COMMAND[mode] - wait)

    return plant


@pytest.mark.parametrize("mode", ["position", "velocity", "torque"])
def test_the_one_call_step_gives_the_bits_of_the_three_calls(mode: str, monkeypatch: pytest.MonkeyPatch) -> None:
    on = _same(mode, monkeypatch, _late(mode))
    assert on["taken"] == STEPS  # every step in one call (the temperature reads, the late ticks among them)
    assert on["rec"][-1][1] == 1  # the one overrun
    assert on["apart"] == 0
    assert len(on["temperatures"]) >= 3  # read at the reset and by the step calls once a second


def _trip(k: int, u: Any) -> None:
    """After step 30 the drive faults (under-voltage, planted): the exchange refuses a nonzero set-point to a
    drive not READY and the host's start is refused (position): the env's own way from there."""
    if k == 30:
        fw = next(iter(u.rig.sim.buses.values())).fronts[0].firmware
        fw.trip(0x0008)


@pytest.mark.parametrize("mode", ["position", "velocity", "torque"])
def test_a_fault_falls_back_to_the_env_s_own_way(mode: str, monkeypatch: pytest.MonkeyPatch) -> None:
    on = _same(mode, monkeypatch, _trip)
    assert 30 <= on["taken"] < STEPS + 2


def _watchdog(k: int, u: Any) -> None:
    """Step 12's command reaches the drive after a substep in which its watchdog trips (as in
    test_can_exchange.py): the front holds the set-point, the bus ticks every substep - the world does not hold
    the sleep; the call stops before the wait and the step waits and reads after it."""
    if k == 12:
        world = u.rig.sim
        dt = world.timestep
        u.rig.sleep(world.steps * dt + dt - 5e-5 - world.clock.now())
        fw = next(iter(world.buses.values())).fronts[0].firmware
        fw._row[K.WATCHDOG] = 1e-300


@pytest.mark.parametrize("mode", ["velocity", "torque"])
def test_a_set_point_held_in_the_call_is_waited_for_and_read_after_it(mode: str,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    on = _same(mode, monkeypatch, _watchdog)
    assert on["apart"] == 1


def test_a_start_refused_in_the_call_raises_as_the_command_does(monkeypatch: pytest.MonkeyPatch) -> None:
    def plant(k: int, u: Any) -> None:
        if k == 12:
            next(iter(u.rig.sim.buses.values())).fronts[0].firmware.write("enable_the_motor", 0)

    on = _same("position", monkeypatch, plant)
    assert on["rec"][-2][0] == "refused" and on["rec"][-2][2] == 0x0027 and on["taken"] == 12


def test_a_refusal_from_another_node_raises_unexpected_reply() -> None:
    """A fault of the emulator's call (the start refused by another node) is a typed error at the step."""
    env = gym.make("joints/ErobReach-v0", config=_config(), control_period=PERIOD)
    u: Any = env.unwrapped
    try:
        env.reset(seed=3)
        (stepper,) = u.compiled_path._steppers
        call = stepper.exchange.step

        def misrouted(commands: Any, *args: Any) -> Any:
            got = call(commands, *args)
            return type(got)(got.done, ec.ErrorReply(commands[-1].node + 1, 0x0027), got.after, got.read)

        for _ in range(3):
            env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        stepper.exchange.step = misrouted
        with pytest.raises(UnexpectedReply, match="does not answer it"):
            env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    finally:
        env.close()


def test_a_replaced_world_hold_leaves_the_steps_to_the_env(monkeypatch: pytest.MonkeyPatch) -> None:
    """The one call mirrors the clock's sleep as the stock world holds it: a replaced ``World.hold`` (or a world
    that does not hold sleeps) sends nothing by it - the env's own three calls go through the replacement."""
    from joints.sim.world import World

    held: list[float] = []
    hold = World.hold

    def counted(self: World, seconds: float) -> None:
        held.append(seconds)
        hold(self, seconds)

    monkeypatch.setattr(World, "hold", counted)
    env = gym.make("joints/ErobReach-v0", config=_config(), control_period=PERIOD)
    u: Any = env.unwrapped
    try:
        env.reset(seed=3)
        for _ in range(5):
            env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        (stepper,) = u.compiled_path._steppers
        assert u.compiled_path.steps_taken == 0 and stepper.exchange.steps == 0 and len(held) >= 5
    finally:
        env.close()
