"""joints/DiffDriveGoal-v0: a differential-drive base on one ZLAC8015D to a goal pose.

In sim (lockstep, deterministic): gymnasium's checker, bit-identical rollouts, seeded resets, the
bus traffic per step (one FC16 for both wheel speeds, one FC03 for both wheels), odometry against
the physics, a scripted go-to-goal controller, faults, the arena, domain randomisation and the
hardware code paths (run on the in-process emulator). Then the same controller through
``backend="hardware"`` against ``joints sim serve`` (another process, a real pseudo-terminal, the
wall clock).
"""

from __future__ import annotations

import math
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
import joints
from envs.diffdrive import SIM_SETTLE, DiffDriveGoalEnv, WheelOdometry, default_config, wrap_angle
from joints.link.trace import Trace

ROOT = Path(__file__).resolve().parents[2]
ENV_ID = "joints/DiffDriveGoal-v0"


def _rollout(env: Any, seed: int, steps: int, *, action_seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(action_seed)
    obs, _ = env.reset(seed=seed)
    seen, rewards = [obs], []
    for _ in range(steps):
        obs, r, term, trunc, _info = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
        seen.append(obs)
        rewards.append(r)
        if term or trunc:
            obs, _ = env.reset()
    return np.array(seen), np.array(rewards)


def _drive_to_goal(env: Any, obs: np.ndarray, max_steps: int = 400) -> tuple[int, dict[str, Any], bool]:
    u = env.unwrapped
    info: dict[str, Any] = {}
    for k in range(max_steps):
        obs, _r, term, trunc, info = env.step(u.go_to_goal_action(obs))
        if term or trunc:
            return k + 1, info, bool(term)
    return max_steps, info, False


@pytest.fixture
def env() -> Iterator[DiffDriveGoalEnv]:
    e = DiffDriveGoalEnv()
    try:
        yield e
    finally:
        e.close()


# -- registration, checker, docs ---------------------------------------------------------------

def test_registered_with_the_shipped_config() -> None:
    spec = gym.spec(ENV_ID)
    assert spec.namespace == "joints" and spec.max_episode_steps == 400
    assert ENV_ID in envs.BASE_ENV_IDS
    env = gym.make(ENV_ID)
    try:
        u = env.unwrapped
        assert isinstance(u, DiffDriveGoalEnv) and u.rig.backend == "sim"
        assert u.wheel_names == ["left_wheel", "right_wheel"]
        assert env.action_space.shape == (2,) and env.observation_space.shape == (10,)
        assert u.dt == 0.05 and u.metadata["render_fps"] == 20
        assert u.command_of([1.0, -0.5]) == pytest.approx([10.0, -5.0])
        assert u.action_of(u.command_of([0.25, -0.75])) == pytest.approx([0.25, -0.75])
    finally:
        env.close()
    cfg = default_config()
    assert cfg["joints"]["left_wheel"]["channel"] == "left" and cfg["sim"]["model"] == "zlac_diffdrive.xml"


def test_check_env(gl_unavailable: str, recwarn: pytest.WarningsRecorder) -> None:
    env = gym.make(ENV_ID)
    try:
        check_env(env.unwrapped, skip_render_check=bool(gl_unavailable))
    finally:
        env.close()


def test_docstring_carries_gymnasium_sections() -> None:
    doc = DiffDriveGoalEnv.__doc__ or ""
    for s in ("## Description", "## Action Space", "## Observation Space", "## Rewards", "## Starting State",
              "## Episode End", "## Arguments", "## Version History"):
        assert s in doc, s


def test_sync_and_async_vector_envs_agree() -> None:
    import functools

    fns = [functools.partial(gym.make, ENV_ID) for _ in range(2)]
    out = []
    for vec in (gym.vector.SyncVectorEnv(fns), gym.vector.AsyncVectorEnv(fns)):
        try:
            obs, _ = vec.reset(seed=3)
            seen = [obs]
            for k in range(15):
                obs, _r, _te, _tr, info = vec.step(np.array([[0.5, 0.3], [-0.2, 0.6]], np.float32))
                seen.append(obs)
            assert info["faults"]["left_wheel"].shape == (2,) and info["pose_estimate"].shape == (2, 3)
            out.append(np.array(seen))
        finally:
            vec.close()
    assert np.array_equal(out[0], out[1])


# -- determinism and reset ---------------------------------------------------------------------

@pytest.mark.parametrize("dr", [False, True], ids=["nominal", "randomised"])
def test_same_seed_same_actions_identical_200_steps(dr: bool) -> None:
    a, b = DiffDriveGoalEnv(domain_randomization=dr), DiffDriveGoalEnv(domain_randomization=dr)
    try:
        oa, ra = _rollout(a, seed=42, steps=200)
        ob, rb = _rollout(b, seed=42, steps=200)
        assert np.array_equal(oa, ob) and np.array_equal(ra, rb)  # bit for bit
        assert np.abs(oa[:, :2]).max() > 0.05  # the base did move
        # the same env again after other episodes: reset restores everything
        _rollout(a, seed=3, steps=20, action_seed=1)
        oa2, ra2 = _rollout(a, seed=42, steps=200)
        assert np.array_equal(oa2, oa) and np.array_equal(ra2, ra)
        assert not np.array_equal(_rollout(b, seed=43, steps=10)[0], oa[:11])
    finally:
        a.close()
        b.close()


def test_seeded_reset_draws_the_goal_and_starts_at_rest(env: DiffDriveGoalEnv) -> None:
    obs, info = env.reset(seed=5)
    # power-on, enable (bus time), 0.1 s to settle, the first read (bus time)
    assert SIM_SETTLE < info["time"] < SIM_SETTLE + 0.2
    assert info["faults"] == {"left_wheel": None, "right_wheel": None}
    assert np.array_equal(obs[:4], [0.0, 0.0, 1.0, 0.0])  # the estimate restarts at the origin
    assert np.abs(obs[8:]).max() < 0.05  # wheels at rest
    gx, gy, gth = info["goal"]
    assert 0.5 <= math.hypot(gx, gy) <= 2.0 and -math.pi <= gth < math.pi
    assert obs[4:6] == pytest.approx([gx, gy]) and obs[6:8] == pytest.approx([math.cos(gth), math.sin(gth)])
    assert np.abs(info["true_pose"]).max() < 1e-9  # sim truth in the same (episode) frame
    assert all(j.enabled for j in env.wheels) and env.wheels[0].read("control_mode") == 3  # velocity mode
    _obs2, info2 = env.reset(seed=6)
    assert not np.array_equal(info2["goal"], info["goal"])
    obs3, info3 = env.reset(seed=5)
    assert np.array_equal(obs3, obs) and np.array_equal(info3["goal"], info["goal"])
    _, info4 = env.reset(options={"goal": [1.0, -0.5, 4.0]})
    assert info4["goal"] == pytest.approx([1.0, -0.5, 4.0 - 2 * math.pi])
    with pytest.raises(ValueError, match="goal"):
        env.reset(options={"goal": [1.0, 2.0]})
    with pytest.raises(ValueError, match="arena"):
        env.reset(options={"goal": [5.0, 0.0, 0.0]})


def test_reset_keeps_the_configured_watchdog() -> None:
    """The sim reset power-cycles the drive (0x2000 back to 1000 ms); the env writes the config's again."""
    cfg = default_config()
    for w in cfg["joints"].values():
        w["watchdog_ms"] = 400
    env = DiffDriveGoalEnv(cfg)
    try:
        assert env.watchdog == pytest.approx(0.4)
        env.reset(seed=0)
        assert env.wheels[0].read("communication_offline_time") == 400
    finally:
        env.close()


def test_reward_terms_and_info(env: DiffDriveGoalEnv) -> None:
    env.reset(seed=2, options={"goal": [1.5, 0.0, 0.0]})
    d0 = 1.5
    for _ in range(10):
        _obs, r, term, _tr, info = env.step(np.array([0.6, 0.6], np.float32))
        assert not term
        assert r == pytest.approx(info["reward_progress"] + info["reward_heading"] + info["reward_action"]
                                  + info["reward_success"])
        assert info["reward_progress"] == pytest.approx(10.0 * (d0 - info["distance"]))
        assert info["reward_action"] == pytest.approx(-0.01 * 2 * 0.6**2, rel=1e-6)
        d0 = info["distance"]
    assert info["distance"] < 1.3  # it drove towards the goal
    assert {"is_success", "pose_estimate", "goal", "wheel_velocities", "true_pose", "true_distance", "faults",
            "time", "heading_error", "out_of_arena", "watchdog"} <= set(info)


# -- the bus: one FC16 for both wheels, one FC03 for both -------------------------------------

def test_each_step_sends_both_wheel_speeds_in_one_fc16(env: DiffDriveGoalEnv) -> None:
    env.reset(seed=0)
    trace = Trace()
    env.rig.trace(trace)
    for a in ([0.5, 0.5], [0.5, -0.2], [0.5, -0.2]):
        trace.clear()
        env.step(np.array(a, np.float32))
        tx = [r.data for r in trace if r.direction == "tx"]
        targets = [f for f in tx if f[1] == 0x10 and int.from_bytes(f[2:4], "big") == 0x2088]
        assert len(targets) == 1 and int.from_bytes(targets[0][4:6], "big") == 2  # both wheels, one FC16
        assert not any(f[1] == 0x06 for f in tx)  # no single-register writes
        reads = [f for f in tx if f[1] == 0x03]
        assert len(reads) == 1  # both wheels' state in one FC03
        # at most the ramp times (0x2080-0x2083, one FC16) besides
        assert len(tx) <= 3
    env.rig.trace(None)


# -- odometry ----------------------------------------------------------------------------------

def test_odometry_integrates_wheel_angles() -> None:
    odo = WheelOdometry(0.1, 0.4)
    odo.restart(1.0, 2.0)
    assert odo.update(1.0 + 10.0, 2.0 + 10.0) == pytest.approx((1.0, 0.0, 0.0))  # 1 m straight
    x, y, th = odo.update(11.0 - math.pi, 12.0 + math.pi)  # turn in place: +pi*0.1*2/0.4 = pi/2 ... x2
    assert (x, y) == pytest.approx((1.0, 0.0)) and th == pytest.approx(wrap_angle(math.pi * 0.1 * 2 / 0.4))
    with pytest.raises(ValueError):
        WheelOdometry(0.0, 0.4)


def test_odometry_estimate_follows_the_physics(env: DiffDriveGoalEnv) -> None:
    env.reset(seed=0, options={"goal": [3.0, 0.0, 0.0]})
    for _ in range(30):  # straight ahead, ~0.5 m/s
        _obs, _r, _te, _tr, info = env.step(np.array([0.5, 0.5], np.float32))
    est, true = info["pose_estimate"], info["true_pose"]
    assert true[0] > 0.6 and abs(true[1]) < 0.005 and abs(true[2]) < 0.005
    assert est == pytest.approx(true, abs=0.01)
    for _ in range(20):  # an arc to the left
        _obs, _r, _te, _tr, info = env.step(np.array([0.2, 0.6], np.float32))
    est, true = info["pose_estimate"], info["true_pose"]
    assert true[2] > 0.5
    assert math.hypot(*(est[:2] - true[:2])) < 0.03 and abs(wrap_angle(est[2] - true[2])) < 0.05


# -- the scripted controller -------------------------------------------------------------------

@pytest.mark.parametrize("seed", [0, 1, 4])
def test_scripted_controller_reaches_the_goal_in_sim(seed: int) -> None:
    env = gym.make(ENV_ID)
    try:
        obs, info0 = env.reset(seed=seed)
        steps, info, term = _drive_to_goal(env, obs)
        assert term and info["is_success"], info
        assert steps < 200  # < 10 s
        # and in truth (the estimate drifts by tyre scrub only)
        assert info["true_distance"] < 0.15
        assert abs(wrap_angle(info["goal"][2] - info["true_pose"][2])) < 0.35
        assert info0["distance"] > 0.5
        # the env stopped the wheels at the goal
        env.unwrapped.rig.sleep(0.5)
        assert all(abs(s.velocity) < 0.05 for s in env.unwrapped.rig.read_states().values())
    finally:
        env.close()


# -- episode ends ------------------------------------------------------------------------------

def test_drive_fault_terminates_and_reset_recovers(env: DiffDriveGoalEnv) -> None:
    env.reset(seed=0)
    env.wheels[0].write("position_following_error_threshold_left", 1, confirm=True)  # 10 counts
    for _ in range(20):
        _obs, _r, term, _t, info = env.step(np.array([1.0, 1.0], np.float32))
        if term:
            break
    assert term and info["faults"] == {"left_wheel": "velocity_following_error", "right_wheel": None}  # velocity following error
    assert info["fault"]["joint"] == "left_wheel" and info["fault"]["name"] == "velocity_following_error"
    assert info["fault"]["text"] and info["fault"]["clears"]
    env.step(np.array([1.0, 1.0], np.float32))  # stepping on after the end commands no faulted drive
    _obs, info = env.reset(seed=0)  # sim: power cycle, the fault is gone
    assert info["faults"] == {"left_wheel": None, "right_wheel": None} and "fault" not in info
    _obs, _r, term, _t, info = env.step(np.array([1.0, 1.0], np.float32))
    assert not term and "fault" not in info


def test_leaving_the_arena_terminates_and_stops() -> None:
    env = DiffDriveGoalEnv(arena=1.0, goal_distance=(0.3, 0.5))
    try:
        env.reset(seed=0, options={"goal": [0.0, 0.5, 0.0]})
        for _ in range(100):
            _obs, _r, term, _t, info = env.step(np.array([1.0, 1.0], np.float32))
            if term:
                break
        assert term and info["out_of_arena"] and not info["is_success"]
        assert env.wheels[0].read("target_velocity_left") == 0 == env.wheels[1].read("target_velocity_right")
    finally:
        env.close()


def test_bad_arguments_and_configs() -> None:
    with pytest.raises(ValueError, match="substeps"):
        DiffDriveGoalEnv(control_period=0.0205)
    with pytest.raises(ValueError, match="goal_distance"):
        DiffDriveGoalEnv(goal_distance=(1.0, 0.5))
    with pytest.raises(ValueError, match="render_mode"):
        DiffDriveGoalEnv(render_mode="ascii")
    cfg = default_config()
    del cfg["joints"]["left_wheel"]["limits"]
    with pytest.raises(joints.ConfigError, match="joints.left_wheel.limits.velocity"):
        DiffDriveGoalEnv(cfg)
    with pytest.raises(joints.ConfigError, match="two wheels"):
        DiffDriveGoalEnv(envs.default_config("erob_reach"))


# -- domain randomisation ----------------------------------------------------------------------

def test_domain_randomisation_scales_drive_gains_and_wheel_physics() -> None:
    env = DiffDriveGoalEnv(domain_randomization=True)
    try:
        model = env.rig.world.model
        nominal = model.dof_frictionloss.copy(), model.actuator_gear[:, 0].copy()
        _, info = env.reset(seed=1)
        s = info["randomization"]
        f = s["joints"]["left_wheel"]
        assert env.wheels[0].read("vl_kp_left") == round(500 * f["speed_loop_gain"])
        assert env.wheels[0].read("vl_ki_left") == round(100 * f["speed_loop_integral"])
        j = env.rig.sim.joint("left_wheel")
        assert model.dof_frictionloss[j.dof] == pytest.approx(nominal[0][j.dof] * f["friction"])
        assert model.actuator_gear[j.actuator, 0] == pytest.approx(nominal[1][j.actuator] * f["torque_constant"])
        _, info1 = env.reset(seed=1)
        assert info1["randomization"] == s
    finally:
        env.close()


# -- the hardware code paths, on the in-process emulator ---------------------------------------

def test_hardware_reset_recovers_from_a_fault_and_from_the_offline_watchdog(env: DiffDriveGoalEnv) -> None:
    """The env's hardware branches (no rig.reset, clear faults, re-enable, wait for standstill,
    watchdog detection) while the rig stays the lockstep sim - they use only the public API."""
    env.reset(seed=0)
    env.sim = False  # from here on: the hardware branches
    rig = env.rig
    obs, info = env.reset(seed=0, options={"goal": [1.0, 0.0, 0.0]})
    assert "true_pose" not in info and np.array_equal(obs[:4], [0, 0, 1, 0])
    for _ in range(10):
        obs, *_ = env.step(np.array([0.8, 0.8], np.float32))
    # a fault ends the episode; the next reset clears it, enables again and waits for standstill
    env.wheels[1].write("position_following_error_threshold_right", 1, confirm=True)
    for _ in range(20):
        obs, _r, term, _t, info = env.step(np.array([-1.0, 1.0], np.float32))
        if term:
            break
    assert term and info["faults"]["right_wheel"] == "velocity_following_error"
    env.wheels[1].write("position_following_error_threshold_right", 409, confirm=True)
    obs, info = env.reset(options={"goal": [1.0, 0.0, 0.0]})
    assert info["faults"] == {"left_wheel": None, "right_wheel": None}
    assert np.abs(obs[8:]).max() < 0.05 and np.array_equal(obs[:4], [0, 0, 1, 0])  # at rest, estimate at 0
    obs, *_ = env.step(np.array([0.5, 0.5], np.float32))
    for _ in range(10):
        obs, _r, term, _t, info = env.step(np.array([0.5, 0.5], np.float32))
    assert not term and obs[8] == pytest.approx(5.0, rel=0.03)  # it drives again
    # the host goes quiet longer than the drive's offline time (0x2000, 1000 ms): quick stop.
    # rig.sleep keeps the drive fed, so the silence needs the keep-alive switched off on purpose
    rig.keepalive = False
    rig.sleep(1.5)
    rig.keepalive = True
    obs, _r, term, _t, info = env.step(np.array([0.5, 0.5], np.float32))
    assert term and info["watchdog"] and info["faults"]["left_wheel"] == "communication_offline"
    obs, info = env.reset(options={"goal": [1.0, 0.0, 0.0]})  # re-armed: stop, zero targets, enable
    for _ in range(12):
        obs, _r, term, _t, info = env.step(np.array([0.5, 0.5], np.float32))
    assert not term and obs[8] == pytest.approx(5.0, rel=0.03)


# -- rendering ---------------------------------------------------------------------------------

def test_render_rgb_array_sim_and_hardware_twin(gl_unavailable: str) -> None:
    if gl_unavailable:
        pytest.skip(gl_unavailable)
    env = DiffDriveGoalEnv(render_mode="rgb_array", width=96, height=72)
    try:
        env.reset(seed=0, options={"goal": [1.0, 0.5, 1.0]})
        first = env.render()
        assert first is not None and first.shape == (72, 96, 3) and first.std() > 5
        for _ in range(20):
            env.step(np.array([0.8, 0.4], np.float32))
        assert not np.array_equal(env.render(), first)
        # hardware: a kinematic twin posed from the estimate
        env.sim = False
        env._renderer.close()
        env._renderer = None
        frame = env.render()
        assert frame is not None and env._twin is not None
        _model, data, free, _wheels = env._twin
        assert data.qpos[free:free + 2] == pytest.approx(env.odometry.pose[:2])
    finally:
        env.close()


# -- hardware backend against `joints sim serve` -----------------------------------------------

@pytest.fixture
def served(serve_shipped: Callable[[str], ContextManager[str]]) -> Iterator[str]:
    """``joints sim serve`` of the shipped diff-drive config in another process; yields the pty port."""
    with serve_shipped(envs.diffdrive.CONFIG_NAME) as port:
        yield port


def test_same_controller_through_the_hardware_backend(served: str) -> None:
    cfg = default_config()
    cfg["buses"]["rs485"]["port"] = served
    cfg["buses"]["rs485"]["timeout"] = 0.5
    t0 = time.monotonic()
    env = gym.make(ENV_ID, config=cfg, backend="hardware")
    try:
        u = env.unwrapped
        assert u.rig.backend == "hardware" and u.rig.world is None
        obs, info = env.reset(seed=0, options={"goal": [1.2, 0.4, 0.5]})  # waits for standstill, wall clock
        d0 = info["distance"]
        assert d0 == pytest.approx(math.hypot(1.2, 0.4)) and "true_pose" not in info
        distances = [d0]
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:  # bounded: at most 10 s of wall clock
            obs, _r, term, _trunc, info = env.step(u.go_to_goal_action(obs))
            distances.append(info["distance"])
            assert info["faults"] == {"left_wheel": None, "right_wheel": None}
            if term or info["distance"] < 0.2 * d0:
                assert not term or info["is_success"], info
                break
        assert min(distances) < 0.3 * d0, distances[::10]  # substantial progress towards the goal
        assert info["pose_estimate"][0] > 0.8  # it drove there, by the drive's own feedback
    finally:
        env.close()
    assert time.monotonic() - t0 < 20
