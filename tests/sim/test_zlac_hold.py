"""joints/DiffDriveGoal-v0's period hold and the next status read in one compiled call: the compiled path books the
world's sleeps (``World.hold``) where the ZLAC8015D's one-call exchange carries every frame to the world's one
twin over a timed line (:meth:`joints.sim.zlac_exchange.ZlacExchange.carried`), and the exchange runs the held
sleep's substeps first, on their own. The bits against the driver path and ``JOINTS_COMPILED=0``:
tests/sim/test_compiled_zlac.py."""

from __future__ import annotations

from typing import Any

import pytest

pytest.importorskip("mujoco")

import gymnasium as gym
import numpy as np

import envs  # noqa: F401 - registers the joints/ envs
import joints
from envs.diffdrive import default_config
from joints.sim import kernel, stepping, zlac_exchange
from joints.sim import line_exchange as L

ENV = "joints/DiffDriveGoal-v0"


def _calls_per_step(monkeypatch: pytest.MonkeyPatch, hold: bool | None, steps: int = 30) -> dict[str, float]:
    """Compiled calls per env step: the world's own (``Group.run``), the one-call exchanges (the FC16s), the
    read's advance, the status read's, the one-call step's (``ZlacExchange.step``); and the reads that ran a held
    sleep first."""
    calls = {"run": 0, "exchanges": 0, "advance": 0, "status": 0, "step": 0}
    run = stepping.Group.run
    exchanges, advance = L.compiled()
    status = zlac_exchange._status_read()
    step = zlac_exchange._step_call()

    def counted_run(self: Any, *a: Any, **k: Any) -> Any:
        calls["run"] += 1
        return run(self, *a, **k)

    def counted_exchanges(*a: Any) -> None:
        calls["exchanges"] += 1
        exchanges(*a)

    def counted_advance(*a: Any) -> None:
        calls["advance"] += 1
        advance(*a)

    def counted_status(*a: Any) -> None:
        calls["status"] += 1
        status(*a)

    def counted_step(*a: Any) -> None:
        calls["step"] += 1
        step(*a)

    monkeypatch.setattr(stepping.Group, "run", counted_run)
    monkeypatch.setattr(zlac_exchange, "_status_read", lambda: counted_status)
    monkeypatch.setattr(zlac_exchange, "_step_call", lambda: counted_step)
    monkeypatch.setattr(L, "compiled", lambda: (counted_exchanges, counted_advance))
    env = gym.make(ENV)
    u: Any = env.unwrapped
    if hold is not None:
        u.rig.sim.hold_sleeps = hold
    try:
        env.reset(seed=2)
        exchange = u.compiled_path._steppers[0].exchange
        held, acts = exchange.held, exchange.acts
        for k in calls:
            calls[k] = 0
        space: Any = env.action_space
        rng = np.random.default_rng(5)
        for _ in range(steps):
            _, _, terminated, truncated, _ = env.step(rng.uniform(space.low, space.high).astype(space.dtype))
            assert not (terminated or truncated)
        out = {k: v / steps for k, v in calls.items()}
        out["held"] = (exchange.held - held) / steps
        out["acts"] = (exchange.acts - acts) / steps
        return out
    finally:
        env.close()


def test_a_diffdrive_step_runs_one_compiled_call(monkeypatch: pytest.MonkeyPatch) -> None:
    """The command's FC16s, the period hold, the status read's advance, the drive's receipt of the frame and the
    reply's travel (which the info's true pose would run) in one call (the one-call step,
    tests/envs/test_diffdrive_step.py) - three with the hold stepped at once (the FC16s, the world's own run of the
    sleep, the status read; two before the one-call step, four before the held sleeps)."""
    if not kernel.default_mode():
        pytest.skip("the compiled stepping is off (JOINTS_COMPILED=0 or no numba)")
    held = _calls_per_step(monkeypatch, None)
    assert held == {"run": 0.0, "exchanges": 0.0, "advance": 0.0, "status": 0.0, "step": 1.0, "held": 1.0,
                    "acts": 1.0}
    eager = _calls_per_step(monkeypatch, False)
    assert eager == {"run": 1.0, "exchanges": 1.0, "advance": 0.0, "status": 1.0, "step": 0.0, "held": 0.0,
                     "acts": 1.0}


def _ideal() -> dict[str, Any]:
    cfg = default_config()
    cfg["buses"]["rs485"]["timing"] = "ideal"
    return cfg


def test_an_untimed_bus_keeps_the_diffdrive_sleeps_eager() -> None:
    """An ideal (untimed) transport hands frames to the twin without settling the world: the exchange carries
    nothing, the world's sleeps step at once."""
    with gym.make(ENV, config=_ideal()) as env:
        u: Any = env.unwrapped
        env.reset(seed=0)
        assert u.compiled_path is not None
        assert u.compiled_path._steppers[0].carried() is None
        assert not u.rig.sim.hold_sleeps
        env.step(np.zeros(2, dtype=np.float32))
        world = u.rig.sim
        u.rig.sleep(0.05)
        assert world.steps * world.timestep >= u.rig.clock.now() - 1e-12  # stepped, not booked


def test_the_timed_bus_carries_the_world_and_its_one_twin() -> None:
    with gym.make(ENV) as env:
        u: Any = env.unwrapped
        env.reset(seed=0)
        carried = u.compiled_path._steppers[0].carried()
        assert carried is not None and carried[0] is u.rig.sim
        assert carried[1] == u.rig.sim.emulators()
        assert u.rig.sim.hold_sleeps is u.rig.sim.compiled


def test_a_sleep_after_a_held_sleep_runs_the_held_one_on_its_own() -> None:
    """``World.hold`` after a held sleep: the held sleep's substeps run first, as ``World.advance`` runs them (the
    lane's sleep to a frame's instant after the env's period hold, where the one-call exchange declines)."""
    with joints.open(default_config()) as lazy, joints.open(default_config()) as eager:
        lazy.sim.hold_sleeps = True
        for rig in (lazy, eager):
            rig.sleep(0.0123)
        lazy.sim.hold(0.0004)
        assert lazy.sim.steps == eager.sim.steps  # the first sleep ran, on its own
        eager.sim.advance(0.0004)
        lazy.sim.sync()
        assert (lazy.sim.steps, lazy.clock.now()) == (eager.sim.steps, eager.clock.now())


def _rig_script(compiled: bool, settle: bool) -> tuple[list[Any], int]:
    """Both wheels' commands, sleeps and reads on DiffDriveGoal-v0's rig - by the compiled path (its status read
    with or without ``settle``) or by the rig's own methods - then a sleep or a command right after the read (booked
    time merged with what follows): states, substeps, clock, frames and physics; and the reads whose act ran in the
    compiled call."""
    env = gym.make(ENV, compiled_path=compiled)
    try:
        u: Any = env.unwrapped
        env.reset(seed=7)
        rig, world = u.rig, u.rig.sim
        before = u.compiled_path._steppers[0].exchange.acts if compiled else 0
        names = u.wheel_names
        rng = np.random.default_rng(3)
        out: list[Any] = []
        for k in range(24):
            speeds = rng.uniform(-8.0, 8.0, 2).tolist()
            if compiled:
                u.compiled_path.command("velocity", speeds)
            else:
                rig.set_velocities(dict(zip(names, speeds)))
            rig.sleep(0.05 - 0.0007 * k)
            if compiled:
                states = u.compiled_path.states(settle=settle and k % 3 == 0)
            else:
                read = rig.read_states()
                states = [read[n] for n in names]
            out.append([(repr(s), repr(s.raw)) for s in states])
            if k % 3 == 0:  # the world read right after (settle: the reply's travel ran in the read's call)
                out.append(world.data.qpos.tobytes())
            out.append((world.steps, rig.clock.now()))
            if k % 3 == 1:
                rig.sleep(0.0031)  # the reply's travel merged with the next sleep
        world.sync()
        line = u.wheels[0].driver.access.link.framing.transport
        out.append([(t.start, t.end, t.due) for t in line.log])
        out.append((world.steps, rig.clock.now(), world.data.qpos.tobytes(), world.data.qvel.tobytes()))
        acts = u.compiled_path._steppers[0].exchange.acts - before if compiled else 0
        return out, acts
    finally:
        env.close()


@pytest.mark.parametrize("settle", [False, True])
def test_the_compiled_status_read_gives_the_rigs_bits(settle: bool) -> None:
    """The status read whose drive's act runs in the compiled call, with the reply's travel booked (``settle``
    False) or run in the call where the next access settles the world anyway: the rig's own methods' bits."""
    got, acts = _rig_script(True, settle)
    want, _ = _rig_script(False, settle)
    assert got == want
    assert acts == (24 if kernel.default_mode() else 0)
