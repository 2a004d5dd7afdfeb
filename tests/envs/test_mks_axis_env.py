"""joints/MksAxisPosition-v0: gymnasium's checker, determinism, limits, and the scripted PD policy reaching the
goal in sim and - unchanged - through the hardware backend against `joints sim serve` (a real pty, wall clock)."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager as ContextManager
from pathlib import Path
from typing import Any

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")

from gymnasium.utils.env_checker import check_env

import envs
from envs.mks_axis import MksAxisPositionEnv
from joints.cli.tomlout import dumps

pytestmark = pytest.mark.mks_firmware
ENV_ID = "joints/MksAxisPosition-v0"


def test_registered_with_docs() -> None:
    assert ENV_ID in envs.AXIS_ENV_IDS and gym.spec(ENV_ID).max_episode_steps == 200
    doc = MksAxisPositionEnv.__doc__ or ""
    for section in ("## Description", "## Action Space", "## Observation Space", "## Rewards", "## Starting State",
                    "## Episode End", "## Arguments", "## Version History"):
        assert section in doc


@pytest.mark.parametrize("mode", ["velocity", "position"])
def test_check_env(mode: str, gl_unavailable: str, recwarn: pytest.WarningsRecorder) -> None:
    env = gym.make(ENV_ID, action_mode=mode)
    try:
        check_env(env.unwrapped, skip_render_check=bool(gl_unavailable))
    finally:
        env.close()


def test_torque_mode_is_refused_the_mks_has_none() -> None:
    with pytest.raises(ValueError, match="no torque mode"):
        gym.make(ENV_ID, action_mode="torque")


def _rollout(env: Any, seed: int, steps: int) -> np.ndarray:
    rng = np.random.default_rng(5)
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for _ in range(steps):
        obs, _r, term, trunc, _i = env.step(rng.uniform(-1, 1, (1,)).astype(np.float32))
        out.append(obs)
        if term or trunc:
            obs, _ = env.reset()
    return np.array(out)


def test_same_seed_same_actions_identical() -> None:
    a, b = gym.make(ENV_ID), gym.make(ENV_ID)
    try:
        assert np.array_equal(_rollout(a, 7, 60), _rollout(b, 7, 60))
    finally:
        a.close()
        b.close()


def test_observation_is_metres_from_the_encoder_through_the_lead() -> None:
    env = gym.make(ENV_ID)
    try:
        obs, info = env.reset(seed=0, options={"start": 0.012, "goal": -0.03})
        u = env.unwrapped
        assert obs[0] == pytest.approx(0.012, abs=1e-6) and obs[2] == -0.03
        assert obs[0] == pytest.approx(u.rig.world.joint_position("carriage"), abs=1e-6)
        assert info["distance"] == pytest.approx(0.042, abs=1e-6)
    finally:
        env.close()


def pd_reach(env: Any, *, start: float, goal: float, max_steps: int = 200) -> tuple[bool, int, np.ndarray]:
    obs, _ = env.reset(seed=0, options={"start": start, "goal": goal})
    u = env.unwrapped
    for k in range(max_steps):
        obs, _r, term, _trunc, info = env.step(u.pd_action(obs))
        assert not term, info
        if info["is_success"]:
            return True, k + 1, obs
    return False, max_steps, obs


@pytest.mark.parametrize("mode", ["velocity", "position"])
def test_pd_policy_reaches_the_goal_in_sim(mode: str) -> None:
    env = gym.make(ENV_ID, action_mode=mode)
    try:
        ok, steps, obs = pd_reach(env, start=-0.01, goal=0.04)
        assert ok and steps < 60, obs
        assert abs(env.unwrapped.rig.world.joint_position("carriage") - 0.04) < 0.001
    finally:
        env.close()


def test_full_speed_towards_the_end_stops_inside_the_limits() -> None:
    """Velocity actions slow down near a limit so the drive's ramp stops the carriage inside it."""
    env = gym.make(ENV_ID)
    try:
        for sign in (1.0, -1.0):
            env.reset(seed=0, options={"start": -sign * 0.05, "goal": 0.0})
            for _ in range(60):
                obs, _r, term, _t, info = env.step(np.array([sign], dtype=np.float32))  # full speed toward the end
                assert not term and -0.06 <= obs[0] <= 0.06
            assert abs(obs[0] - sign * 0.06) < 0.002 and abs(obs[1]) < 1e-3 and abs(info["command"]) < 1e-3
    finally:
        env.close()


def test_leaving_the_limits_terminates_and_stops_the_axis() -> None:
    env = gym.make(ENV_ID)
    u = env.unwrapped
    try:
        env.reset(seed=0, options={"start": 0.05, "goal": 0.0})
        env.step(np.array([0.0], dtype=np.float32))
        u.rig.sim.set_joint_positions({"carriage": 0.068})  # pushed past the limit from outside
        _obs, _r, term, _t, info = env.step(np.array([1.0], dtype=np.float32))
        assert term and info["limit_violation"] and "fault" not in info
        u.rig.sleep(1.0)
        assert abs(u.joint.state().velocity) < 1e-3
    finally:
        env.close()


@pytest.fixture
def served(tmp_path: Path, sim_server: Callable[[Path], ContextManager[str]], mks_firmware: str) -> Iterator[str]:
    """``joints sim serve`` of the shipped MksAxisPosition config with the test's firmware profile (the served
    process has its own default) in another process; yields the pty port."""
    pytest.importorskip("serial")
    cfg = envs.default_config("mks_axis")
    cfg["joints"]["carriage"]["firmware"] = mks_firmware
    path = tmp_path / "served.toml"
    path.write_text(dumps(cfg))
    with sim_server(path) as port:
        yield port


@pytest.mark.mks_firmware("v1.0.5", "v1.0.9")  # wall clock: the profiles without and with 0x40 and the heartbeat
def test_same_pd_policy_reaches_the_goal_through_the_hardware_backend(served: str) -> None:
    cfg = envs.default_config("mks_axis")
    cfg["buses"]["rs485"]["port"] = served
    cfg["buses"]["rs485"]["timeout"] = 0.5
    t0 = time.monotonic()
    env = gym.make(ENV_ID, config=cfg, backend="hardware")
    try:
        u = env.unwrapped
        assert u.rig.backend == "hardware" and u.rig.world is None
        ok, _steps, obs = pd_reach(env, start=-0.01, goal=0.04)  # reset moves to the start on the wall clock
        assert ok, obs
        assert abs(obs[0] - 0.04) < 0.001
    finally:
        env.close()
    assert time.monotonic() - t0 < 30
