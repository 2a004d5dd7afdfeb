"""The batched vector env (N rigs in one process, stepped together) is gymnasium's SyncVectorEnv of N
``gym.make(id)`` envs: same spaces, observations, rewards, terminations, truncations, infos and
autoreset, for the same seeds."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")

from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode

import envs
import joints
from envs.vector import JointsVectorEnv
from joints.sim import kernel

N = 3
#: how the worlds run their drives' kernels: compiled (fused calls across the rigs) and as plain Python
KERNELS = ["compiled", "python"] if kernel.AVAILABLE else ["python"]


@pytest.fixture(params=KERNELS)
def kernels(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """Worlds built in this test run their kernels ``request.param`` (``JOINTS_COMPILED``)."""
    monkeypatch.setenv(kernel.SWITCH, "1" if request.param == "compiled" else "0")
    monkeypatch.delenv(kernel.OLD_SWITCH, raising=False)
    return str(request.param)
CASES = [
    ("joints/ErobReach-v0", {"max_episode_steps": 25}),
    ("joints/ErobReach-v0", {"action_mode": "torque", "domain_randomization": True, "max_episode_steps": 40}),
    ("joints/ErobArmReach-v0", {"domain_randomization": True, "max_episode_steps": 30}),
    ("joints/DiffDriveGoal-v0", {"max_episode_steps": 20}),
]


def _same(a: Any, b: Any, where: str) -> None:
    if isinstance(a, tuple):
        assert isinstance(b, tuple) and len(a) == len(b), (where, a, b)
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{where}[{i}]")
    elif isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), (where, list(a), list(b))
        for k in a:
            _same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape, (where, a, b)
        if a.dtype == object:
            for x, y in zip(a, b):
                _same(x, y, where)
        else:
            assert np.array_equal(a, b), (where, a, b)
    else:
        assert a == b, (where, a, b)


def _pair(env_id: str, kwargs: dict[str, Any], mode: AutoresetMode) -> tuple[Any, Any]:
    vec = gym.make_vec(env_id, num_envs=N, vectorization_mode="vector_entry_point", autoreset_mode=mode, **kwargs)
    ref = gym.make_vec(env_id, num_envs=N, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode},
                       **kwargs)
    return vec, ref


@pytest.mark.parametrize(("env_id", "kwargs"), CASES)
def test_batched_env_is_a_sync_vector_env_of_single_envs(env_id: str, kwargs: dict[str, Any], kernels: str) -> None:
    vec, ref = _pair(env_id, kwargs, AutoresetMode.NEXT_STEP)
    try:
        assert isinstance(vec.unwrapped, JointsVectorEnv)
        assert {e.rig.sim.compiled for e in vec.unwrapped.envs} == {kernels == "compiled"}
        assert vec.single_observation_space == ref.single_observation_space
        assert vec.single_action_space == ref.single_action_space
        assert vec.observation_space == ref.observation_space and vec.action_space == ref.action_space
        assert vec.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
        _same(vec.reset(seed=7), ref.reset(seed=7), "reset")
        rng = np.random.default_rng(3)
        ends = 0
        for k in range(60):
            a = rng.uniform(vec.action_space.low, vec.action_space.high).astype(vec.action_space.dtype)
            got, want = vec.step(a), ref.step(a)
            _same(got, want, f"step {k}")
            ends += int(got[2].sum() + got[3].sum())
        assert ends >= 1  # autoreset was exercised
        # every rig's drives and physics are stepped in one table (one call per advance)
        groups = {id(e.rig.sim.group) for e in vec.unwrapped.envs}
        assert len(groups) == 1
    finally:
        vec.close()
        ref.close()


def test_same_step_autoreset_and_partial_reset(kernels: str) -> None:
    vec, ref = _pair("joints/ErobReach-v0", {"max_episode_steps": 7}, AutoresetMode.SAME_STEP)
    try:
        _same(vec.reset(seed=1), ref.reset(seed=1), "reset")
        rng = np.random.default_rng(0)
        finals = 0
        for k in range(16):
            a = rng.uniform(-1, 1, (N, 1)).astype(np.float32)
            got, want = vec.step(a), ref.step(a)
            _same(got, want, f"step {k}")
            finals += int("final_obs" in got[4])
        assert finals == 2  # truncated after 7 and 14 steps: reset in the same step
        mask = np.array([True, False, True])
        _same(vec.reset(seed=[4, None, 6], options={"reset_mask": mask}),
              ref.reset(seed=[4, None, 6], options={"reset_mask": mask}), "masked reset")
        a = np.zeros((N, 1), np.float32)
        _same(vec.step(a), ref.step(a), "after masked reset")
    finally:
        vec.close()
        ref.close()


def test_domain_randomisation_differs_per_rig_and_is_seeded() -> None:
    vec = envs.make_vector_env("joints/ErobReach-v0", N, domain_randomization=True)
    try:
        _obs, info = vec.reset(seed=0)
        armature = [float(m.dof_armature[0]) for m in vec.models]
        assert len(set(armature)) == N  # one model per rig
        assert info["_randomization"].all()
        vec.reset(seed=0)
        assert [float(m.dof_armature[0]) for m in vec.models] == armature
    finally:
        vec.close()


def test_step_before_reset_and_bad_arguments() -> None:
    with pytest.raises(ValueError, match="num_envs"):
        JointsVectorEnv("envs.reach:ErobReachEnv", 0)
    vec = envs.make_vector_env("joints/ErobReach-v0", 2)
    try:
        with pytest.raises(gym.error.ResetNeeded):
            vec.step(np.zeros((2, 1), np.float32))
        vec.reset(seed=0)
        with pytest.raises(ValueError, match="rows"):
            vec.step(np.zeros((3, 1), np.float32))
        with pytest.raises(ValueError, match="seeds"):
            vec.reset(seed=[1, 2, 3])
    finally:
        vec.close()


def test_sleep_together_is_each_rig_sleeping_in_turn() -> None:
    cfg = envs.default_config("erob_reach")
    rigs = [joints.open(cfg) for _ in range(2)]
    alone = joints.open(cfg)
    try:
        for r in (*rigs, alone):
            j = r.joints["joint1"]
            j.enable()
            r.sleep(0.6)
            j.set_velocity(1.5)
        before = [r.time for r in rigs]  # enabling and commanding took bus time (issue 29)
        joints.sleep_together(rigs, [0.25, 0.4])
        alone.sleep(0.4)
        dt = rigs[0].sim.timestep  # the world steps whole substeps
        assert rigs[0].time - before[0] == pytest.approx(0.25, abs=dt)
        assert rigs[1].time - before[1] == pytest.approx(0.4, abs=dt)
        assert rigs[1].time == alone.time
        assert np.array_equal(rigs[1].sim.data.qpos, alone.sim.data.qpos)
        assert rigs[1].joints["joint1"].state().position == alone.joints["joint1"].state().position
        with pytest.raises(ValueError):
            joints.sleep_together(rigs, [0.1])
    finally:
        for r in (*rigs, alone):
            r.close()


@pytest.mark.parametrize("env_id", ["joints/ErobReach-v0", "joints/DiffDriveGoal-v0"])
def test_single_env_still_passes_check_env(env_id: str) -> None:
    env = gym.make(env_id)
    try:
        check_env(env.unwrapped, skip_render_check=True)
    finally:
        env.close()
