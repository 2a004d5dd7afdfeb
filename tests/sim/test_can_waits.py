"""The host's waits on a timed CAN bus whose twins only answer: frame edges processed without their waits give
the bits of waiting for each (``CanMedium.answers_only``; ``joints bench``'s eRob CAN row)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")
gym = pytest.importorskip("gymnasium")

import envs  # noqa: F401 - registers the ids
from joints import bench
from joints.transports.can_sim import CanMedium


def _run(action_mode: str, answers_only: bool, monkeypatch: pytest.MonkeyPatch) -> tuple[list[Any], int]:
    """Observations, rewards, physics, clock and bus statistics of 60 steps (with resets), and the waits made."""
    waits = []
    wait = CanMedium._wait_until
    monkeypatch.setattr(CanMedium, "_wait_until", lambda self, t, lazy=False: (waits.append(t), wait(self, t, lazy))[1])
    found = bench._baseline_config("joints/ErobReach-v0")
    assert found is not None and found[1].startswith("erob-can")
    env = gym.make("joints/ErobReach-v0", config=found[0], control_period=bench.BASELINE_PERIOD, action_mode=action_mode,
                   max_episode_steps=25)
    try:
        sim = env.unwrapped.rig.sim
        medium = next(iter(sim.buses.values())).medium
        assert medium.answers_only  # the eRob CAN twins never send by themselves
        medium.answers_only = answers_only
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


@pytest.mark.parametrize("action_mode", ["position", "velocity"])
def test_edges_processed_without_their_waits_give_the_bits_of_waiting_for_each(
        action_mode: str, monkeypatch: pytest.MonkeyPatch) -> None:
    fast, fast_waits = _run(action_mode, True, monkeypatch)
    reference, reference_waits = _run(action_mode, False, monkeypatch)
    assert fast_waits < 0.6 * reference_waits, (fast_waits, reference_waits)  # the short path was taken
    assert len(fast) == len(reference)
    for i, (got, want) in enumerate(zip(fast, reference)):
        assert got == want, f"record {i} differs"
