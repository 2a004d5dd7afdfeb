"""gymnasium's SyncVectorEnv and AsyncVectorEnv over the joints envs (the env builds in worker processes)."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")

import envs
from envs import ErobArmReachEnv, ErobReachEnv

STEPS = 30


def _run(vec: gym.vector.VectorEnv, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    obs, _info = vec.reset(seed=seed)
    seen, rewards = [obs], []
    for _ in range(STEPS):
        actions = rng.uniform(-1, 1, vec.action_space.shape).astype(np.float32)
        obs, reward, _term, _trunc, info = vec.step(actions)
        seen.append(obs)
        rewards.append(reward)
        assert "joint1" in info["faults"] and info["faults"]["joint1"].shape == (vec.num_envs,)
    return np.array(seen), np.array(rewards)


@pytest.mark.parametrize("env_id", list(envs.ENV_IDS))
def test_sync_and_async_vector_envs_agree(env_id: str) -> None:
    fns = [functools.partial(gym.make, env_id, action_mode="torque") for _ in range(2)]
    sync = gym.vector.SyncVectorEnv(fns)
    asyn = gym.vector.AsyncVectorEnv(fns)  # the default start method (fork on Linux)
    try:
        assert sync.single_observation_space == asyn.single_observation_space
        s_obs, s_rew = _run(sync, seed=11)
        a_obs, a_rew = _run(asyn, seed=11)
        assert np.array_equal(s_obs, a_obs) and np.array_equal(s_rew, a_rew)
        assert not np.array_equal(s_obs[:, 0], s_obs[:, 1])  # the two envs got different seeds
    finally:
        sync.close()
        asyn.close()


def test_async_vector_env_with_spawned_workers() -> None:
    """Workers that start from scratch (spawn) build the env from its class: nothing is inherited."""
    fns = [functools.partial(ErobReachEnv, action_mode="velocity"),
           functools.partial(ErobReachEnv, action_mode="velocity", domain_randomization=True)]
    vec = gym.vector.AsyncVectorEnv(fns, context="spawn")
    ref = [ErobReachEnv(action_mode="velocity"), ErobReachEnv(action_mode="velocity", domain_randomization=True)]
    try:
        obs, _ = vec.reset(seed=[1, 2])
        expect = np.array([ref[0].reset(seed=1)[0], ref[1].reset(seed=2)[0]])
        assert np.array_equal(obs, expect)
        a = np.array([[0.4], [-0.4]], np.float32)
        for _ in range(10):
            obs, *_ = vec.step(a)
            expect = np.array([ref[0].step(a[0])[0], ref[1].step(a[1])[0]])
        assert np.array_equal(obs, expect)
    finally:
        vec.close()
        for e in ref:
            e.close()


def test_make_vec_by_id() -> None:
    vec = gym.make_vec("joints/ErobArmReach-v0", num_envs=2, vectorization_mode="sync")
    try:
        obs, _ = vec.reset(seed=0)
        assert obs.shape == (2, 18)
        assert isinstance(vec.unwrapped.envs[0].unwrapped, ErobArmReachEnv)
    finally:
        vec.close()


def test_batched_infos_are_add_info_rig_by_rig() -> None:
    """The batch's infos built a key at a time equal _add_info's, rig by rig: the same keys in the same order,
    the same dtypes, shapes and values, nested dicts and their masks included; mixed infos take the rig-by-rig
    way."""
    from envs.vector import JointsVectorEnv

    vec = JointsVectorEnv("envs.reach:ErobReachEnv", 3)
    try:
        def info(k: int) -> dict[str, Any]:
            return {"time": 0.5 * k, "overrun": 0.0, "faults": {"joint1": None if k else "over_current"},
                    "steps": k, "is_success": k == 1, "command": np.array([k, -k], dtype=np.float64),
                    "name": f"rig{k}", "sample": np.float32(k) / 3, "nested": {"a": {"b": k}}}

        infos = [info(k) for k in range(3)]
        want: dict[str, Any] = {}
        for k, i in enumerate(infos):
            want = vec._add_info(want, i, k)
        got = vec._batched_info(infos)
        assert got is not None

        def same(a: Any, b: Any) -> None:
            if isinstance(a, dict):
                assert isinstance(b, dict) and list(a) == list(b)
                for key in a:
                    same(a[key], b[key])
            else:
                assert type(a) is type(b) and a.dtype == b.dtype and a.shape == b.shape
                assert a.tolist() == b.tolist()

        same(got, want)
        assert vec._batched_info([info(0), info(1), {**info(2), "extra": 1}]) is None  # keys differ
        assert vec._batched_info([info(0), info(1), {**info(2), "time": 1}]) is None  # an int among floats
    finally:
        vec.close()
