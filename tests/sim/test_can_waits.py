"""The host's waits on a timed CAN bus: frame edges processed without their waits (``CanMedium._skippable``) give
the bits of waiting for each, on ``joints bench``'s CAN rows (eRob CAN: the twins only answer; CANopen: they also
send by themselves)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")
gym = pytest.importorskip("gymnasium")

import envs  # noqa: F401 - registers the ids
from joints import bench
from joints.transports.can_sim import CanMedium


def _run(env_id: str, action_mode: str, skip: bool, monkeypatch: pytest.MonkeyPatch) -> tuple[list[Any], int]:
    """Observations, rewards, physics, clock and bus statistics of 60 steps (with resets), and the waits made."""
    waits = []
    wait = CanMedium._wait_until
    monkeypatch.setattr(CanMedium, "_wait_until", lambda self, t, lazy=False: (waits.append(t), wait(self, t, lazy))[1])
    found = bench._baseline_config(env_id)
    assert found is not None
    env = gym.make(env_id, config=found[0], control_period=bench.BASELINE_PERIOD, action_mode=action_mode,
                   max_episode_steps=25)
    try:
        sim = env.unwrapped.rig.sim
        medium = next(iter(sim.buses.values())).medium
        assert medium.answers_only is found[1].startswith("erob-can")  # eRob CAN twins never send by themselves
        if not skip:  # the reference: a wait for every edge
            monkeypatch.setattr(medium, "_skippable", lambda edge, held: False)
        rng = np.random.default_rng(2)
        obs, _ = env.reset(seed=4)
        out: list[Any] = [obs.tobytes()]
        for _ in range(60):
            obs, r, term, trunc, info = env.step(rng.uniform(env.action_space.low, env.action_space.high))
            out.append((obs.tobytes(), r, term, trunc, info["time"], sim.steps, sim.clock.now(), sim.data.qpos.tobytes(),
                        sim.data.qvel.tobytes(), medium.frames, medium.bits, medium.busy, medium.now))
            if term or trunc:
                out.append(env.reset()[0].tobytes())
        return out, len(waits)
    finally:
        env.close()
        monkeypatch.undo()


@pytest.mark.parametrize(("env_id", "action_mode", "fewer"), [("joints/ErobReach-v0", "position", 0.6),
                                                             ("joints/ErobReach-v0", "velocity", 0.6),
                                                             ("joints/ErobArmReach-v0", "position", 0.9)])
def test_edges_processed_without_their_waits_give_the_bits_of_waiting_for_each(
        env_id: str, action_mode: str, fewer: float, monkeypatch: pytest.MonkeyPatch) -> None:
    fast, fast_waits = _run(env_id, action_mode, True, monkeypatch)
    reference, reference_waits = _run(env_id, action_mode, False, monkeypatch)
    assert fast_waits < fewer * reference_waits, (fast_waits, reference_waits)  # the short path was taken
    assert len(fast) == len(reference)
    for i, (got, want) in enumerate(zip(fast, reference)):
        assert got == want, f"record {i} differs"
