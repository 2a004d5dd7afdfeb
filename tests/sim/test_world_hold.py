"""The clock's sleep books its time (``World.hold``): the physics runs later, on its own, before anything reads
or acts on it, with the substeps an eager ``World.advance`` runs - the same trajectory, clock and frames."""

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


def _eager(world: Any) -> None:
    """The clock's sleep as it was: ``World.advance`` at once."""
    world.clock.bind(world.advance, on_book=world.book, on_settle=world.sync)


ACCESS: dict[str, Callable[[Any], object]] = {
    "data": lambda w: w.data.qpos[0],
    "time": lambda w: w.time,
    "drives": lambda w: w.drives,
    "step": lambda w: w.step(0),
}


@pytest.mark.parametrize("what", list(ACCESS))
def test_a_sleep_books_its_time_and_an_access_runs_it(what: str) -> None:
    with joints.open(_arm()) as rig:
        world = rig.sim
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
        _eager(eager.sim)
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
