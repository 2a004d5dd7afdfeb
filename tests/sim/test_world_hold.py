"""The clock's sleep books its time (``World.hold``, where ``World.hold_sleeps``): the physics runs later, on its
own, before anything reads or acts on it, with the substeps an eager ``World.advance`` runs - the same
trajectory, clock and frames. The compiled path turns it on only where every drive is behind a timed line."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

pytest.importorskip("mujoco")

import joints
from envs.configs import default_config
from joints.sim.world import advance_together


def _arm() -> dict[str, Any]:
    cfg = default_config("erob_arm_reach")
    cfg["sim"]["direct"] = True
    return cfg


def _behind(world: Any, clock: Any) -> bool:
    """Whether the physics stands behind the host's clock (``steps`` reads no property: it never syncs)."""
    return bool(world.steps * world.timestep < clock.now() - 1e-12)


def _lazy(rig: Any) -> Any:
    """The rig, its world's sleeps booked (``World.hold``; the compiled path sets it where every drive is behind
    a timed line)."""
    rig.sim.hold_sleeps = True
    return rig


ACCESS: dict[str, Callable[[Any], object]] = {
    "data": lambda w: w.data.qpos[0],
    "time": lambda w: w.time,
    "drives": lambda w: w.drives,
    "buses": lambda w: w.buses,  # its fronts reach the twins
    "step": lambda w: w.step(0),
}


@pytest.mark.parametrize("what", list(ACCESS))
def test_a_sleep_books_its_time_and_an_access_runs_it(what: str) -> None:
    with joints.open(_arm()) as rig:
        world = _lazy(rig).sim
        rig.read_states()
        world.sync()
        rig.sleep(0.0123)
        assert _behind(world, rig.clock) and world._held  # booked, not stepped
        ACCESS[what](world)
        assert not _behind(world, rig.clock) and not world._held
        assert world.time - world.timestep < rig.time <= world.time


def _script(rig: Any, with_world: Callable[[Any], None]) -> list[Any]:
    """Commands, sleeps and reads (the driver path), then ``with_world`` right after a sleep: the bits."""
    world = rig.sim
    out: list[Any] = []
    for k in range(6):
        for i, j in enumerate(rig.joints.values()):
            j.move_to(0.1 * (k + 1) * (-1) ** i)
        rig.sleep(0.0137 + 0.001 * k)
        if k == 3:
            with_world(world)
        states = rig.read_states()
        out.append([(s.position, s.velocity, s.torque, s.time) for s in states.values()])
        out.append((world.steps, rig.clock.now()))
    world.sync()
    out.append((world.steps, rig.clock.now(), world.data.qpos.tobytes(), world.data.qvel.tobytes()))
    return out


AFTER_SLEEP: dict[str, Callable[[Any], None]] = {
    "nothing": lambda w: None,
    "advance": lambda w: w.advance(0.00071),
    "book": lambda w: w.book(0.00043),
    "advance_together": lambda w: advance_together([w], [0.00093]),
    "sleep": lambda w: w.clock.sleep(0.0021),
}


@pytest.mark.parametrize("after", list(AFTER_SLEEP))
def test_a_booked_sleep_gives_the_eager_sleeps_bits(after: str) -> None:
    with joints.open(_arm()) as lazy, joints.open(_arm()) as eager:
        _lazy(lazy)
        for rig in (lazy, eager):
            for j in rig.joints.values():
                j.enable()
            rig.sleep(0.6)
        got = _script(lazy, AFTER_SLEEP[after])
        want = _script(eager, AFTER_SLEEP[after])
        assert got == want
        assert _frames(lazy) == _frames(eager)


def _frames(rig: Any) -> list[tuple[float, float, float]]:
    """Every frame instant on the rig's line."""
    line = next(iter(rig.joints.values())).driver.access.link.framing.transport
    return [(t.start, t.end, t.due) for t in line.log]


@pytest.mark.parametrize(("env_id", "compiled", "held"), [
    ("joints/ErobReach-v0", True, True), ("joints/ErobArmReach-v0", True, True),
    ("joints/ErobReach-v0", False, False), ("joints/DiffDriveGoal-v0", True, True),
    ("joints/DiffDriveGoal-v0", False, False)])
def test_the_compiled_path_books_the_sleeps_of_the_worlds_it_carries(env_id: str, compiled: bool, held: bool) -> None:
    import gymnasium as gym

    import envs  # noqa: F401 - registers the ids
    from joints.sim import kernel

    env = gym.make(env_id, compiled_path=compiled)
    try:
        env.reset(seed=0)
        assert env.unwrapped.rig.sim.hold_sleeps is (held and kernel.default_mode())  # type: ignore[attr-defined]
    finally:
        env.close()


def test_an_ideal_bus_keeps_sleeps_eager() -> None:
    """An untimed transport hands frames to the drives without settling the world: its sleeps step at once."""
    cfg = {"backend": "sim", "sim": {"model": "erob_stand.xml", "timestep": 0.001, "direct": True},
           "buses": {"bus": {"protocol": "modbus-rtu", "timing": "ideal"}},
           "joints": {"joint1": {"device": "erob", "model": "eRob80H100", "bus": "bus", "address": 2}}}
    with joints.open(cfg) as rig:
        assert joints.CompiledPath.build(list(rig.joints.values())) is not None
        assert not rig.sim.hold_sleeps
        rig.sleep(0.05)
        assert not _behind(rig.sim, rig.clock)


def test_a_drive_outside_the_compiled_path_keeps_sleeps_eager() -> None:
    """A drive of the world on an untimed bus, not one of the compiled path's joints: its frames reach it without
    settling the world, so the sleeps stay eager; with every drive in the compiled path they are booked."""
    cfg = _arm()
    cfg["buses"]["side"] = {"protocol": "modbus-rtu", "timing": "ideal"}
    cfg["joints"]["joint3"]["bus"] = "side"
    with joints.open(cfg) as rig:
        timed = [rig.joints["joint1"], rig.joints["joint2"]]
        assert joints.CompiledPath.build(timed) is not None
        assert not rig.sim.hold_sleeps
    with joints.open(_arm()) as rig:
        assert joints.CompiledPath.build(list(rig.joints.values())) is not None
        assert rig.sim.hold_sleeps is rig.sim.compiled
