"""Issue 32: physics only where it is needed. A wait in which nothing acts on a drive (a reply travelling to
the host) books the time on the clock; the physics catches up - in one compiled call with what follows -
before anything reads or writes it or a twin (World.model / data / drives / time, a medium handing a frame
to a drive). The trajectories are those of stepping at once (tests/sim/test_twin_golden.py)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

pytest.importorskip("mujoco")

import joints
from envs.configs import default_config
from joints.sim import stepping


def _arm() -> dict[str, Any]:
    cfg = default_config("erob_arm_reach")
    cfg["sim"]["direct"] = True
    return cfg


def _behind(world: Any, clock: Any) -> bool:
    """Whether the physics stands behind the host's clock (``steps`` reads no property: it never syncs)."""
    return bool(world.steps * world.timestep < clock.now() - 1e-12)


def test_a_reply_in_flight_books_time_without_physics() -> None:
    with joints.open(_arm()) as rig:
        world = rig.sim
        rig.read_states()
        assert _behind(world, rig.clock)  # the last reply travelled to the host: booked, not stepped
        rig.read_states()  # the next request acts on the drives: the physics caught up first
        assert world.time - world.timestep < rig.time <= world.time


ACCESS: dict[str, Callable[[Any], object]] = {
    "data": lambda w: w.data.qpos[0],
    "model": lambda w: w.model.opt.timestep,
    "drives": lambda w: w.drives,
    "time": lambda w: w.time,
    "joint_position": lambda w: w.joint_position("joint1"),
}


@pytest.mark.parametrize("what", list(ACCESS))
def test_every_access_to_the_physics_or_a_twin_runs_the_booked_time_first(what: str) -> None:
    with joints.open(_arm()) as rig:
        world = rig.sim
        rig.read_states()
        assert _behind(world, rig.clock)
        ACCESS[what](world)
        assert not _behind(world, rig.clock)
        assert world.steps * world.timestep - world.timestep < rig.time


@pytest.mark.parametrize("one_call", [True, False])
def test_an_env_step_runs_one_compiled_call(monkeypatch: pytest.MonkeyPatch, one_call: bool) -> None:
    """ErobReach-v0: three transactions (the drive acts on each request) and the period hold in ONE compiled call
    (``CompiledPath.step``: the target write and start, the hold, the status read), where every frame instant once
    stepped the physics in a call of its own (seven). Without the one-call step, two: the command's writes in one
    (the one-call exchange, joints.sim.erob_exchange), the hold (``World.hold``: booked, its substeps run on their
    own at the start of the next call) with the status read in the other."""
    import gymnasium as gym
    import numpy as np

    import envs  # noqa: F401 - registers the ids
    from joints.sim import erob_exchange, kernel

    if not kernel.default_mode():
        pytest.skip("the compiled stepping is off (JOINTS_COMPILED=0 or no numba)")
    calls = [0]
    exchanges = [0]
    run = stepping.Group.run
    compiled = erob_exchange._compiled()

    def counted(self: Any, *a: Any, **k: Any) -> Any:
        calls[0] += 1
        return run(self, *a, **k)

    def exchange(*a: Any) -> None:
        exchanges[0] += 1
        compiled(*a)

    monkeypatch.setattr(stepping.Group, "run", counted)
    monkeypatch.setattr(erob_exchange, "_compiled", lambda: exchange)
    if not one_call:
        monkeypatch.setattr(joints.CompiledPath, "step", lambda self, *args, **kwargs: None)
    env = gym.make("joints/ErobReach-v0")
    try:
        env.reset(seed=1)
        rng = np.random.default_rng(0)
        space = env.action_space
        calls[0] = exchanges[0] = 0
        for _ in range(20):
            env.step(rng.uniform(space.low, space.high).astype(space.dtype))
        assert calls[0] == 0  # the hold runs in the read's call
        assert exchanges[0] == (1 if one_call else 2) * 20  # the step; or the command, the read
    finally:
        env.close()
