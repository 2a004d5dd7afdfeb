"""Ticks only where they have work: a world whose timed buses and delayed drives announce their next event
runs the substeps before it in one compiled call, with the bits of ticking every substep."""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")
gym = pytest.importorskip("gymnasium")

import envs  # registers the joints/ ids
from joints.bench import _baseline_config
from joints.sim import kernel, stepping

MODES = ["compiled", "per-substep", "python"] if kernel.AVAILABLE else ["python"]


def _make(monkeypatch: pytest.MonkeyPatch, mode: str, on_can: bool) -> Any:
    monkeypatch.setenv("JOINTS_COMPILED", "0" if mode == "python" else "1")
    if on_can:  # eRob CAN custom protocol at 1 Mbit/s, 20 ms: the bench's baseline bus
        found = _baseline_config("joints/ErobReach-v0")
        assert found is not None and found[1].startswith("erob-can"), found
        env = gym.make("joints/ErobReach-v0", config=found[0], control_period=0.02)
    else:
        env = gym.make("joints/ErobReach-v0")
    world = env.unwrapped.rig.world
    if mode == "per-substep":
        world.leave_fused_path()
        world.group.replan()
    return env, world


def _run(monkeypatch: pytest.MonkeyPatch, mode: str, on_can: bool, delay: float, steps: int = 60) -> tuple[str, int]:
    env, world = _make(monkeypatch, mode, on_can)
    try:
        out = [env.reset(seed=3)[0]]
        if delay:  # a drive that acts on motion commands late: its tick announces the pending write's time
            world.perturb("joint1", command_delay=delay)
        assert (world.group.compiled and world.group.fusable[world.group_index]) == (mode == "compiled"), mode
        rng = np.random.default_rng(3)
        for _ in range(steps):
            obs, reward, terminated, truncated, _info = env.step(rng.uniform(-1, 1, env.action_space.shape))
            out += [obs, np.array([reward])]
            if terminated or truncated:
                out.append(env.reset()[0])
        return hashlib.sha256(np.concatenate(out).tobytes()).hexdigest(), world.steps
    finally:
        env.close()


@pytest.mark.parametrize(("on_can", "delay"), [(True, 0.0), (False, 0.0035), (True, 0.0021)])
def test_fused_to_the_next_event_gives_the_bits_of_ticking_every_substep(monkeypatch: pytest.MonkeyPatch,
                                                                        on_can: bool, delay: float) -> None:
    got = {mode: _run(monkeypatch, mode, on_can, delay) for mode in MODES}
    assert len(set(got.values())) == 1, got


def test_a_can_bus_with_nothing_queued_costs_nothing_per_substep(monkeypatch: pytest.MonkeyPatch) -> None:
    if not kernel.AVAILABLE:
        pytest.skip("numba is not installed: no fused compiled calls")
    env, world = _make(monkeypatch, "compiled", on_can=True)
    try:
        env.reset(seed=0)
        env.step(np.zeros(env.action_space.shape))
        bus = next(iter(world.buses.values()))
        assert bus.medium.idle()
        ticks = []
        tick = bus.medium.tick
        monkeypatch.setattr(bus.medium, "tick", lambda t: (ticks.append(t), tick(t)))
        runs = []
        run = world.group.run
        monkeypatch.setattr(world.group, "run", lambda worlds, n: (runs.append(n), run(worlds, n)))
        before = world.steps
        env.unwrapped.rig.sleep(0.1)
        world.sync()  # (the compiled path's world may hold the sleep: World.hold; its physics runs at the next use)
        assert world.steps - before == 100
        assert runs == [100] and ticks == [world.time], (runs, ticks)  # one call, one tick at its end
    finally:
        env.close()


def test_rigs_sleeping_together_tick_their_announced_events_as_each_alone() -> None:
    import joints
    from joints.sim.world import join

    cfg = envs.default_config("erob_reach")
    rigs = [joints.open(cfg) for _ in range(3)]
    alone = joints.open(cfg)
    try:
        for r in (*rigs, alone):
            r.joints["joint1"].enable()
            r.sleep(0.6)
        for r in (rigs[1], alone):  # motion commands act 50 ms after they arrive: a pending write to tick
            r.sim.perturb("joint1", command_delay=0.05)
        for r in (*rigs, alone):
            r.joints["joint1"].set_velocity(1.5)
        assert rigs[1].sim.drives["joint1"].pending and alone.sim.drives["joint1"].pending
        assert all(r._keepalive_due()[0] > r.time + 0.2 for r in rigs)  # no rig sleeps on its own for its watchdog
        joints.sleep_together(rigs, [0.1, 0.2, 0.05])
        alone.sleep(0.2)
        group = join([r.sim for r in rigs])
        on = kernel.default_mode()  # (the rigs were opened with the default: compiled unless JOINTS_COMPILED=0)
        assert group.compiled == on and all(group.fusable) == on
        assert rigs[1].time == alone.time
        assert np.array_equal(rigs[1].sim.data.qpos, alone.sim.data.qpos)
        assert np.array_equal(rigs[1].sim.data.qvel, alone.sim.data.qvel)
        assert rigs[1].joints["joint1"].state().position == alone.joints["joint1"].state().position
        order, worlds = group._plan((1,))  # what one rig's call steps: its rows and its world, no other
        assert list(worlds) == [1] and {int(group.adr[i][stepping.WORLD]) for i in order} == {1}
    finally:
        for r in (*rigs, alone):
            r.close()
