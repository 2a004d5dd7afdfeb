"""The twins' sensor noise follows the env's seed (gymnasium's rule: ``reset(seed=...)`` fixes every draw).

The eRob profile's current measurement has 20 mA of noise while current flows, and the observation carries the
torque made from it. With the start pose and the target fixed by ``options`` and the same actions, the seed is
the only thing that differs between runs: ``reset(seed=s)`` must replay the torques bit for bit, another seed
must draw other torques, and so must the next episode and every rig of a batch.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("mujoco")

import envs  # noqa: F401  (registers the joints/ envs)

OPTIONS = {"start": [0.3], "target": [1.0]}
STEPS = 15


def _torques(env: Any, seed: int | None, steps: int = STEPS) -> np.ndarray:
    """The observation's torque column over an episode reset with ``seed`` and driven by fixed actions."""
    obs, _ = env.reset(seed=seed, options=OPTIONS)
    rows = [obs[2]]
    for k in range(steps):
        obs, *_ = env.step(np.array([0.8 if k % 4 < 2 else -0.8], dtype=np.float32))
        rows.append(obs[2])
    return np.array(rows)


@pytest.fixture
def env() -> Any:
    e = gym.make("joints/ErobReach-v0")
    yield e
    e.close()


def test_a_seed_replays_the_sensor_noise_and_another_seed_draws_other_noise(env: Any) -> None:
    first = _torques(env, 1)
    again = _torques(env, 1)
    other = _torques(env, 2)
    assert np.array_equal(first, again)
    assert np.count_nonzero(first != other) > STEPS // 2  # the noise, not one stray sample


def test_each_episode_draws_its_own_sensor_noise(env: Any) -> None:
    first = _torques(env, 5)
    second = _torques(env, None)  # the next episode of the same seeding
    assert np.count_nonzero(first != second) > STEPS // 2
    assert np.array_equal(_torques(env, 5), first)


def test_the_rigs_of_a_batch_draw_their_own_sensor_noise() -> None:
    vec = gym.make_vec("joints/ErobReach-v0", num_envs=2, vectorization_mode="vector_entry_point")
    try:
        vec.reset(seed=7, options=OPTIONS)
        seen = []
        for k in range(STEPS):
            obs, *_ = vec.step(np.full((2, 1), 0.8 if k % 4 < 2 else -0.8, dtype=np.float32))
            seen.append(obs[:, 2].copy())
        torques = np.array(seen)
    finally:
        vec.close()
    assert np.count_nonzero(torques[:, 0] != torques[:, 1]) > STEPS // 2
