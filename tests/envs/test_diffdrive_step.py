"""joints/DiffDriveGoal-v0's one-call step: both wheels' command, the wait for the tick and the status read in ONE
call of the ZLAC8015D twin's exchange (``CompiledPath.step`` -> ``_ZlacModbus.step`` -> ``ZlacExchange.step``) give
the bits of the same three done one after the other (the stepper's ``step`` answering None: the env's split path).

Each run is asserted to have taken the path it is about (``CompiledPath.steps_taken``), the one-call run's steps
with and without a ramp FC16, a step it declined (the env's fallback) and an episode end among them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")

import envs  # noqa: F401 - registers the joints/ envs
from joints import compiled_path
from joints.sim import kernel
from joints.sim.zlac_exchange import ZlacExchange

ENV = "joints/DiffDriveGoal-v0"
#: the one-call run's steps its stepper declines (the env then commands, waits and reads one by one)
DECLINED = (7, 8, 41)


def _info(info: dict[str, Any]) -> list[tuple[str, Any]]:
    return [(k, (v.dtype.str, v.tobytes()) if isinstance(v, np.ndarray) else repr(v)) for k, v in sorted(info.items())]


class _Seen:
    """What the one-call exchange was asked: the FC16s of each one-call step (wrapped, not replaced)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, *, decline: tuple[int, ...] = ()) -> None:
        self.writes: list[int] = []
        self.asked = 0
        step, own = ZlacExchange.step, compiled_path._ZlacModbus.step

        def counted(ex: ZlacExchange, steady: Any, writes: Any, *args: Any, **kwargs: Any) -> Any:
            got = step(ex, steady, writes, *args, **kwargs)
            if got is not None:
                self.writes.append(len(writes))
            return got

        def declining(s: Any, *args: Any) -> Any:
            self.asked += 1
            return None if self.asked - 1 in decline else own(s, *args)

        monkeypatch.setattr(ZlacExchange, "step", counted)
        monkeypatch.setattr(compiled_path._ZlacModbus, "step", declining)


def _run(steps: int = 120, **kwargs: Any) -> dict[str, Any]:
    env = gym.make(ENV, arena=0.7, goal_distance=(0.2, 0.5), **kwargs)
    u: Any = env.unwrapped
    try:
        out: dict[str, Any] = {"steps": [], "resets": 0}
        obs, info = env.reset(seed=5)
        out["reset"] = (obs.tobytes(), _info(info))
        rng = np.random.default_rng(6)
        action = np.zeros(2, dtype=np.float32)
        for i in range(steps):
            if i % 7 == 2:  # the left wheel's speed kept: its ramp times stay, the right one's change
                action = np.array([action[0], rng.uniform(-1.2, 1.2)], dtype=np.float32)
            elif i % 5 != 3:  # (every fifth step the last action again: the ramps stay, the target FC16 alone)
                action = rng.uniform(-1.2, 1.2, 2).astype(np.float32)  # some beyond [-1, 1]: clipped
            obs, reward, terminated, truncated, info = env.step(action)
            out["steps"].append((obs.tobytes(), reward, terminated, truncated, _info(info),
                                 [(repr(j.last_state), repr(j.last_state.raw), j.last_contact)
                                  for j in u.rig.joints.values()]))
            if terminated or truncated:
                out["resets"] += 1
                obs, info = env.reset()
                out["steps"].append(("reset", obs.tobytes(), _info(info)))
        cp = u.compiled_path
        link = next(iter(u.rig.joints.values())).driver.access.link
        out["transactions"] = (link.transactions, link.framing.exchanges, link.retries_used)
        out["frames"] = [(tx.start, tx.end, tx.due, tx.size, tx.side, repr(tx.payload)) for tx in link.transport.log]
        twins = [f for b in u.rig.sim.buses.values() for f in b.slaves.values()]
        out["images"] = [tuple(sorted(f.image().items())) for f in twins]
        out["rows"] = [np.array(f.firmware.kernel_rows()).tobytes() for f in twins]
        out["write_log"] = [list(f.firmware.write_log) for f in twins]
        world = u.rig.sim
        out["time"] = (u.rig.time, world.steps, world._target, world._booked, world._held,
                       world.data.qpos.tobytes(), world.data.qvel.tobytes())
        out["overruns"] = (u.overruns, u.overrun_time)
        ex = cp._steppers[0].exchange
        out["counts"] = (cp.taken, cp.lane_taken, ex.taken, ex.reads, ex.acts, ex.held)
        out["steps_taken"] = cp.steps_taken
        return out
    finally:
        env.close()


_COMPARED = ("reset", "steps", "transactions", "frames", "images", "rows", "write_log", "time", "overruns", "counts")


@pytest.mark.parametrize("randomized", [False, True])
def test_the_one_call_step_gives_the_split_steps_bits(randomized: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """The one-call step (with three steps declined) against the split path (every step declined): the same
    observations, rewards, infos, joint states, transactions, frames, register images, kernel rows, clock and
    physics, counts; domain randomisation adds a bus latency (the action queue) and sensor noise."""
    with monkeypatch.context() as m:
        seen = _Seen(m, decline=DECLINED)
        one = _run(domain_randomization=randomized)
    with monkeypatch.context() as m:
        m.setattr(compiled_path._ZlacModbus, "step", lambda s, *a: None)
        split = _run(domain_randomization=randomized)
    assert split["steps_taken"] == 0
    if kernel.default_mode():
        assert one["steps_taken"] == seen.asked - len(DECLINED) > 100  # every step but the declined (and none refused)
        assert 1 in seen.writes and 2 in seen.writes  # steps with the ramp FC16 and without
    else:  # JOINTS_COMPILED=0: the world does not hold sleeps, so no step goes in one call
        assert one["steps_taken"] == 0
    assert one["resets"] >= 1  # an episode ended (out of the arena) and began again on the way
    for key in _COMPARED:
        assert one[key] == split[key], key


def _manual(one_call: bool, settle: bool, steps: int = 40) -> dict[str, Any]:
    """The compiled path driven by hand, the reads with ``settle``: each step the one-call step or the command,
    the wait for the tick (``RigEnv._wait_until``) and the read one after the other."""
    env = gym.make(ENV)
    u: Any = env.unwrapped
    try:
        env.reset(seed=2)
        cp, rig = u.compiled_path, u.rig
        out: dict[str, Any] = {"states": [repr(cp.states(settle=settle))]}
        rng = np.random.default_rng(3)
        tick = rig.time
        for _ in range(steps):
            cmd = rng.uniform(-8.0, 8.0, 2).tolist()
            tick += 0.05
            got = cp.step("velocity", cmd, None, tick, rig) if one_call else None
            if got is None:
                cp.command("velocity", cmd)
                remaining = tick - rig.time
                if remaining > 0:
                    rig.sleep(remaining)
                got = cp.states(settle=settle), remaining
            world = rig.sim
            out["states"].append((repr(got[0]), got[1], rig.time, world.steps, world._target, world._booked))
        link = u.wheels[0].driver.access.link
        out["frames"] = [(tx.start, tx.end, tx.due, tx.size, tx.side) for tx in link.transport.log]
        out["transactions"] = link.transactions
        out["qpos"] = rig.sim.data.qpos.tobytes()  # (the physics run to the booked time)
        out["steps_taken"] = cp.steps_taken
        return out
    finally:
        env.close()


@pytest.mark.parametrize("settle", [False, True])
def test_the_step_reads_as_the_callers_last_read_settles(settle: bool) -> None:
    """``_ZlacModbus.step``'s read settles as the caller's own reads do (``states(settle=...)``: unsettled, the
    reply's travel stays booked for the next access): the bits of the command, the wait and the read."""
    one = _manual(True, settle)
    split = _manual(False, settle)
    assert split["steps_taken"] == 0
    assert one["steps_taken"] == (40 if kernel.default_mode() else 0)
    if kernel.default_mode():
        assert [s[-1] for s in one["states"][1:]] == [not settle] * 40  # booked after the read unless it settled
    for key in ("states", "frames", "transactions", "qpos"):
        assert one[key] == split[key], key


def test_not_the_steady_case_sends_nothing() -> None:
    """The stepper declines, nothing sent: another action mode, a command its checks refuse (the command's own
    way raises it), a drive out of velocity mode; the rig's sleep with a keep-alive read due (CompiledPath.step)."""
    env = gym.make(ENV)
    u: Any = env.unwrapped
    try:
        env.reset(seed=2)
        cp, rig = u.compiled_path, u.rig
        stepper = cp._steppers[0]
        link = u.wheels[0].driver.access.link
        before = (link.transactions, rig.time, len(link.transport.log))
        tick = rig.time + 0.05
        assert stepper.step("torque", [0.1, 0.1], tick) is None
        assert stepper.step("velocity", [1e9, 0.0], tick) is None
        with pytest.raises(Exception):  # noqa: B017 - whatever the joint's own check raises
            cp.command("velocity", [1e9, 0.0])
        assert cp.step("velocity", [1.0, 1.0], None, rig.time + 0.3, rig) is None  # a keep-alive falls due first
        mode = stepper.drive.state.mode
        stepper.drive.state.mode = None  # (the drive's mode unknown: the command would write it first)
        try:
            assert stepper.step("velocity", [1.0, 1.0], tick) is None
        finally:
            stepper.drive.state.mode = mode
        assert (link.transactions, rig.time, len(link.transport.log)) == before
        assert cp.steps_taken == 0
        if kernel.default_mode():
            assert cp.step("velocity", [1.0, 1.0], None, tick, rig) is not None and cp.steps_taken == 1
    finally:
        env.close()
