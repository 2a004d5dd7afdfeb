"""The gymnasium envs on the sim backend: API conformance, determinism, reset, limits, faults, rendering."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")

from gymnasium.utils.env_checker import check_env

import envs
import joints
from envs import ErobArmReachEnv, ErobReachEnv
from envs.base import ENABLE_SETTLE

IDS = list(envs.ENV_IDS)
MODES = list(envs.ACTION_MODES)


def _rollout(env: Any, seed: int, steps: int, *, action_seed: int = 7) -> np.ndarray:
    rng = np.random.default_rng(action_seed)
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for _ in range(steps):
        a = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        obs, _r, term, trunc, _info = env.step(a)
        out.append(obs)
        if term or trunc:
            obs, _ = env.reset()
    return np.array(out)


# -- registration and gymnasium's checker -----------------------------------------------------

def test_ids_registered_under_joints_namespace() -> None:
    assert set(IDS) == {"joints/ErobReach-v0", "joints/ErobArmReach-v0"}
    for env_id in IDS:
        spec = gym.spec(env_id)
        assert spec.namespace == "joints" and spec.max_episode_steps == 250


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("env_id", IDS)
def test_check_env(env_id: str, mode: str, gl_unavailable: str, recwarn: pytest.WarningsRecorder) -> None:
    env = gym.make(env_id, action_mode=mode)
    try:
        # the render check builds the env again for each render mode ("human" warns headless)
        check_env(env.unwrapped, skip_render_check=bool(gl_unavailable))
    finally:
        env.close()


def test_docstrings_carry_gymnasium_sections() -> None:
    sections = ["## Description", "## Action Space", "## Observation Space", "## Rewards", "## Starting State",
                "## Episode End", "## Arguments", "## Version History"]
    for cls in (ErobReachEnv, ErobArmReachEnv):
        doc = cls.__doc__ or ""
        assert all(s in doc for s in sections), [s for s in sections if s not in doc]


# -- determinism ------------------------------------------------------------------------------

@pytest.mark.parametrize("dr", [False, True], ids=["nominal", "randomised"])
@pytest.mark.parametrize("env_id,mode", [("joints/ErobReach-v0", "torque"), ("joints/ErobReach-v0", "position"),
                                         ("joints/ErobArmReach-v0", "velocity")])
def test_same_seed_same_actions_identical_200_steps(env_id: str, mode: str, dr: bool) -> None:
    a = gym.make(env_id, action_mode=mode, domain_randomization=dr)
    b = gym.make(env_id, action_mode=mode, domain_randomization=dr)
    try:
        ra = _rollout(a, seed=42, steps=200)
        rb = _rollout(b, seed=42, steps=200)
        assert np.array_equal(ra, rb)  # bit for bit
        # the same env again after other episodes: reset restores everything
        _rollout(a, seed=3, steps=20, action_seed=1)
        assert np.array_equal(_rollout(a, seed=42, steps=200), ra)
        assert not np.array_equal(_rollout(b, seed=43, steps=10), ra[:11])
    finally:
        a.close()
        b.close()


# -- reset ------------------------------------------------------------------------------------

def test_seeded_start_state_and_power_on_drives() -> None:
    env = ErobReachEnv(action_mode="torque")
    try:
        obs, info = env.reset(seed=5)
        # enabled (bus time), then the drive's 500 ms on sim time, then the first read (bus time)
        assert ENABLE_SETTLE < info["time"] < ENABLE_SETTLE + 0.2
        assert info["faults"] == {"joint1": None}
        lo, hi = env.start_range
        assert lo <= obs[0] <= hi and obs[0] != 0.0
        # the brake held the drawn pose while the drive was getting ready
        assert env.rig.world.joint_position("joint1") == pytest.approx(obs[0], abs=1e-4)
        assert obs[3] == env.target and obs[4] == pytest.approx(env.target - obs[0])
        # a different seed draws a different start and target
        obs2, _ = env.reset(seed=6)
        assert obs2[0] != obs[0] and obs2[3] != obs[3]
        # stepping changes the drive's registers; reset gives them back their power-on values
        j = env.rig.joints["joint1"]
        j.write("position_loop_gain", 123)
        for _ in range(5):
            env.step(np.array([0.5], np.float32))
        obs3, info3 = env.reset(seed=5)
        assert np.array_equal(obs3, obs) and info3["time"] == info["time"]
        assert j.read("position_loop_gain") == 500
        assert j.enabled and j.state().enabled
    finally:
        env.close()


def test_reset_options_fix_start_and_target() -> None:
    env = ErobArmReachEnv()
    try:
        obs, _ = env.reset(seed=0, options={"start": [0.2, -0.3, 0.9], "target": [0.3, 0.1, 0.4]})
        assert np.allclose(obs[:3], [0.2, -0.3, 0.9], atol=1e-3)  # the brakes hold the arm (stiff, not rigid)
        assert np.array_equal(obs[12:15], [0.3, 0.1, 0.4])
        with pytest.raises(ValueError, match="start pose"):
            env.reset(options={"start": [0.0, 2.0, 0.0]})  # joint2 limit is 1.2
    finally:
        env.close()


def test_torque_mode_first_step_moves_after_the_enable_delay() -> None:
    env = ErobReachEnv(action_mode="torque")
    try:
        obs0, info0 = env.reset(seed=1, options={"start": [0.0]})
        obs, _r, term, _t, info = env.step(np.array([1.0], np.float32))  # full torque forward
        assert not term and info["faults"]["joint1"] is None  # no "start while disabled" refusal
        assert obs[1] > 0.1 and obs[0] > obs0[0]
        # the tick one period after the first observation, then the state read's bus time
        assert env.dt < info["time"] - info0["time"] < env.dt + env.bus_lag
    finally:
        env.close()


# -- observations, actions, info --------------------------------------------------------------

def test_spaces_units_and_dt() -> None:
    env = ErobReachEnv(control_period=0.05)
    try:
        assert env.dt == 0.05 and env.metadata["render_fps"] == 20
        assert env.action_space.shape == (1,) and env.action_space.dtype == np.float32
        assert np.array_equal(env.observation_space.low, [-3.5, -4.0, -70.0, -3.0, -6.0])
        assert np.array_equal(env.observation_space.high, [3.5, 4.0, 70.0, 3.0, 6.0])
        assert env.command_of([1.0]) == pytest.approx([3.0]) and env.command_of([-1.0]) == pytest.approx([-3.0])
        assert env.action_of(env.command_of([0.25])) == pytest.approx([0.25])
        _, info0 = env.reset(seed=0)
        _, _, _, _, info = env.step(env.action_space.sample())
        assert 0.05 < info["time"] - info0["time"] < 0.05 + env.bus_lag  # the tick, then the read's bus time
        assert env.substeps == 50
        assert {"reward_distance", "reward_action_rate", "distance", "is_success", "faults", "time",
                "limit_violation", "command"} <= set(info)
        assert "fault" not in info  # only when a drive reports one
        arm = ErobArmReachEnv(action_mode="torque")
        try:
            assert arm.observation_space.shape == (18,) and arm.action_space.shape == (3,)
            assert arm.command_of([1, 1, 1]) == pytest.approx([35.0, 35.0, 20.0])
        finally:
            arm.close()
    finally:
        env.close()


def test_reward_terms_sum_to_reward() -> None:
    env = ErobArmReachEnv()
    try:
        env.reset(seed=2)
        for _ in range(10):
            _obs, r, _te, _tr, info = env.step(env.action_space.sample())
            assert r == pytest.approx(info["reward_distance"] + info["reward_action_rate"])
            assert info["reward_distance"] == pytest.approx(-info["distance"])
    finally:
        env.close()


def test_position_mode_reaches_target_with_the_drive_profile() -> None:
    env = ErobReachEnv()
    try:
        env.reset(seed=0, options={"start": [0.0], "target": 1.2})
        a = env.action_of([1.2])
        for _ in range(100):
            obs, _r, term, _t, info = env.step(a)
            assert not term
        assert info["is_success"] and abs(obs[1]) < 0.01
    finally:
        env.close()


def test_limit_violation_terminates_and_stops() -> None:
    env = ErobReachEnv(action_mode="torque")
    try:
        env.reset(seed=0, options={"start": [2.9]})
        for _ in range(50):
            _obs, _r, term, _t, info = env.step(np.array([1.0], np.float32))
            if term:
                break
        assert term and info["limit_violation"] and info["faults"]["joint1"] is None
        assert env.rig.joints["joint1"].read("target_current") == 0  # stopped
    finally:
        env.close()


def test_drive_fault_terminates_with_its_code() -> None:
    env = ErobReachEnv()
    try:
        env.reset(seed=0, options={"start": [0.0]})
        env.rig.joints["joint1"].write("max_position_error", 10)  # 10 counts: any move is a following error
        for _ in range(20):
            _obs, _r, term, _t, info = env.step(env.action_of([2.0]))
            if term:
                break
        assert term and info["faults"]["joint1"] == "following_error"
        fault = info["fault"]
        assert fault["joint"] == "joint1" and fault["name"] == "following_error" and fault["code"] == 0x8611
        assert "max_position_error" in fault["text"] and fault["clears"]
        env.step(env.action_of([2.0]))  # stepping on after the end commands no faulted drive
        _obs, info = env.reset(seed=0)  # a reset power-cycles the drive: the fault is gone
        assert info["faults"]["joint1"] is None and "fault" not in info
        _obs, _r, term, _t, info = env.step(env.action_of([2.0]))
        assert not term and "fault" not in info
    finally:
        env.close()


# -- kinematics -------------------------------------------------------------------------------

def test_forward_kinematics_matches_mujoco_site() -> None:
    cfg = envs.default_config("erob_arm_reach")
    cfg["buses"]["rs485"]["timing"] = "ideal"  # the three reads at one instant (on the wire they are 11 ms apart)
    env = ErobArmReachEnv(config=cfg)
    try:
        world = env.rig.world
        rng = np.random.default_rng(0)
        for _ in range(50):
            q = rng.uniform(-math.pi, math.pi, 3)
            world.set_joint_positions(dict(zip(env.joint_names, q)))
            assert np.allclose(envs.erob_arm3_ee(q), env.end_effector(), atol=1e-9)
        # in the env: ground truth (site) and FK of the measured joint angles agree to encoder resolution
        env.reset(seed=4)
        for _ in range(20):
            env.step(env.action_space.sample())
        measured = np.array([j.state().position for j in env.joints])
        assert np.allclose(env.end_effector(measured), env.end_effector(), atol=1e-4)
    finally:
        env.close()


def test_stand_tip_kinematics() -> None:
    from envs.kinematics import erob_stand_tip

    env = ErobReachEnv()
    try:
        world = env.rig.world
        mj = world.mujoco
        site = mj.mj_name2id(world.model, mj.mjtObj.mjOBJ_SITE, "tip")
        for q in (-2.0, 0.0, 0.7, 3.0):
            world.set_joint_positions({"joint1": q})
            assert np.allclose(erob_stand_tip(q), world.data.site_xpos[site], atol=1e-9)
    finally:
        env.close()


# -- domain randomisation ---------------------------------------------------------------------

def test_domain_randomisation_draws_per_reset_and_restores_nominal() -> None:
    env = ErobReachEnv(domain_randomization=True)
    model = env.rig.world.model
    nominal = (model.dof_frictionloss.copy(), model.dof_damping.copy(), model.dof_armature.copy(),
               model.actuator_gear[:, 0].copy())
    try:
        _, info1 = env.reset(seed=1)
        s1 = info1["randomization"]
        f = s1["joints"]["joint1"]
        dr = env.randomization
        assert dr is not None
        for key in ("position_loop_gain", "speed_loop_gain", "friction", "armature", "torque_constant",
                    "encoder_noise"):
            lo, hi = getattr(dr, key)
            assert lo <= f[key] <= hi
        assert s1["latency"] in (0, 1)
        assert model.dof_frictionloss[0] == pytest.approx(nominal[0][0] * f["friction"])
        assert model.dof_armature[0] == pytest.approx(nominal[2][0] * f["armature"])
        assert model.actuator_gear[0, 0] == pytest.approx(f["torque_constant"])
        j = env.rig.joints["joint1"]
        assert j.read("position_loop_gain") == round(500 * f["position_loop_gain"])
        assert j.read("speed_loop_integral") == round(200 * f["speed_loop_integral"])
        _, info2 = env.reset(seed=2)
        assert info2["randomization"] != s1
        _, info1b = env.reset(seed=1)
        assert info1b["randomization"] == s1
    finally:
        env.close()
    plain = ErobReachEnv()
    try:
        _, info = plain.reset(seed=1)
        assert "randomization" not in info
        m = plain.rig.world.model
        assert np.array_equal(m.dof_frictionloss, nominal[0]) and np.array_equal(m.dof_armature, nominal[2])
    finally:
        plain.close()


def test_latency_delays_actions_by_whole_periods() -> None:
    fixed = {k: (1.0, 1.0) for k in ("position_loop_gain", "speed_loop_gain", "speed_loop_integral", "friction",
                                     "armature", "torque_constant")}
    late = ErobReachEnv(action_mode="torque", domain_randomization={**fixed, "encoder_noise": (0, 0),
                                                                    "latency": (2, 2)})
    now = ErobReachEnv(action_mode="torque")
    try:
        late.reset(seed=0)
        now.reset(seed=0)
        actions = [np.array([v], np.float32) for v in (0.5, -0.3, 0.8, 0.0, 0.2, -0.6)]
        zero = np.zeros(1, np.float32)
        seen_late = [late.step(a)[0] for a in actions]
        seen_now = [now.step(a)[0] for a in [zero, zero] + actions[:-2]]
        assert np.array_equal(np.array(seen_late), np.array(seen_now))
    finally:
        late.close()
        now.close()


def test_encoder_noise_only_on_observed_positions() -> None:
    fixed = {k: (1.0, 1.0) for k in ("position_loop_gain", "speed_loop_gain", "speed_loop_integral", "friction",
                                     "armature", "torque_constant")}
    noisy = ErobReachEnv(domain_randomization={**fixed, "encoder_noise": (0.01, 0.01), "latency": (0, 0)})
    clean = ErobReachEnv()
    try:
        a, _ = noisy.reset(seed=0)
        b, _ = clean.reset(seed=0)
        diffs = []
        for _ in range(20):
            a = noisy.step(np.array([0.3], np.float32))[0]
            b = clean.step(np.array([0.3], np.float32))[0]
            diffs.append(a[0] - b[0])
            assert np.array_equal(a[1:4], b[1:4])  # physics unchanged
        assert 0.003 < float(np.std(diffs)) < 0.03
    finally:
        noisy.close()
        clean.close()


def test_domain_randomisation_rejects_bad_ranges() -> None:
    with pytest.raises(ValueError, match="unknown"):
        envs.DomainRandomization.from_arg({"gravity": (0, 1)})
    with pytest.raises(ValueError, match="friction"):
        envs.DomainRandomization(friction=(2.0, 1.0))
    with pytest.raises(ValueError, match="latency"):
        envs.DomainRandomization(latency=(-1, 0))


# -- construction errors ----------------------------------------------------------------------

def test_bad_arguments_and_configs(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="action_mode"):
        ErobReachEnv(action_mode="current")
    with pytest.raises(ValueError, match="substeps"):
        ErobReachEnv(control_period=0.0205)
    with pytest.raises(ValueError, match="render_mode"):
        ErobReachEnv(render_mode="ascii")
    cfg = envs.default_config("erob_reach")
    del cfg["joints"]["joint1"]["limits"]["torque"]
    with pytest.raises(joints.ConfigError, match="joints.joint1.limits.torque"):
        ErobReachEnv(cfg)
    with pytest.raises(joints.ConfigError, match="exactly one joint"):
        ErobReachEnv(envs.default_config("erob_arm_reach"))
    with pytest.raises(joints.ConfigError, match="three joints"):
        ErobArmReachEnv(envs.default_config("erob_reach"))
    with pytest.raises(ValueError, match="no shipped config"):
        envs.default_config("nope")


def test_config_path_and_dict_give_the_same_env(tmp_path: Path) -> None:
    with envs.config_path("erob_reach") as p:
        text = p.read_text()
    f = tmp_path / "stand.toml"
    f.write_text(text)
    a, b = ErobReachEnv(f), ErobReachEnv(envs.default_config("erob_reach"))
    try:
        assert np.array_equal(_rollout(a, 9, 30), _rollout(b, 9, 30))
    finally:
        a.close()
        b.close()


def test_close_is_idempotent_and_disables() -> None:
    env = ErobReachEnv()
    env.reset(seed=0)
    drive = env.rig.world.drives["joint1"]
    assert drive.enabled
    env.close()
    env.close()
    assert not drive.enabled
    with pytest.raises(RuntimeError, match="closed"):
        env.step(np.zeros(1, np.float32))


# -- rendering --------------------------------------------------------------------------------

@pytest.mark.parametrize("env_id", IDS)
def test_render_rgb_array_headless(env_id: str, gl_unavailable: str) -> None:
    if gl_unavailable:
        pytest.skip(gl_unavailable)
    env = gym.make(env_id, render_mode="rgb_array", width=160, height=120)
    try:
        env.reset(seed=0)
        first = env.render()
        assert first.shape == (120, 160, 3) and first.dtype == np.uint8 and first.std() > 5
        for _ in range(25):
            env.step(env.action_space.sample())
        assert not np.array_equal(env.render(), first)  # the joints moved
    finally:
        env.close()


def test_rendering_does_not_change_the_trajectory(gl_unavailable: str) -> None:
    if gl_unavailable:
        pytest.skip(gl_unavailable)
    a = ErobReachEnv(render_mode="rgb_array", width=64, height=48, action_mode="torque")
    b = ErobReachEnv(action_mode="torque")
    try:
        rng = np.random.default_rng(0)
        oa, _ = a.reset(seed=1)
        ob, _ = b.reset(seed=1)
        for _ in range(20):
            act = rng.uniform(-1, 1, 1).astype(np.float32)
            a.render()
            oa, ob = a.step(act)[0], b.step(act)[0]
            assert np.array_equal(oa, ob)
    finally:
        a.close()
        b.close()


def test_human_mode_without_display_warns_and_steps(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MUJOCO_GL", "egl")
    env = ErobReachEnv(render_mode="human")
    try:
        with pytest.warns(UserWarning, match="shows nothing"):
            env.reset(seed=0)
        assert env.step(env.action_space.sample())[0].shape == (5,)
        assert env.render() is None
    finally:
        env.close()


# -- the hardware code paths, exercised on the in-process emulator ---------------------------

def _as_hardware(env: Any) -> Any:
    """Take the env's hardware branches (reset by moving, FK task terms, rendering twin) while the
    rig stays the lockstep sim - the public Joint API is all those branches use."""
    env.sim = False
    return env


def test_hardware_reset_moves_with_a_safe_profile_and_recovers_from_faults() -> None:
    env = _as_hardware(ErobReachEnv(action_mode="velocity", reset_velocity=0.5, reset_acceleration=1.0))
    rig, j = env.rig, env.rig.joints["joint1"]
    try:
        t0 = rig.time
        obs, info = env.reset(seed=0, options={"start": [0.6], "target": 0.0})
        assert abs(obs[0] - 0.6) <= env.reset_tolerance and abs(obs[1]) < 0.05
        assert info["time"] - t0 >= 0.5 + 0.6 / 0.5  # enable wait + at most 0.5 rad/s
        assert "randomization" not in info and j.read("operation_mode") == 2  # speed mode, zero speed
        # a fault ends the episode; the next reset clears it, enables again and moves
        j.write("max_speed_error", 10)  # count/s: any acceleration is a speed error
        for _ in range(20):
            _obs, _r, term, _t, info = env.step(np.array([1.0], np.float32))
            if term:
                break
        assert term and info["faults"]["joint1"] == "speed_error" and info["fault"]["code"] == 0x8400
        j.write("max_speed_error", 84000)
        obs, info = env.reset(seed=0, options={"start": [-0.4], "target": 0.0})  # clear_faults + enable
        assert info["faults"]["joint1"] is None and abs(obs[0] + 0.4) <= env.reset_tolerance
        _obs, _r, term, _t, info = env.step(np.array([0.5], np.float32))
        assert not term and "fault" not in info and j.state().enabled
    finally:
        env.close()


def test_hardware_task_terms_from_forward_kinematics() -> None:
    env = _as_hardware(ErobArmReachEnv())
    try:
        obs, _ = env.reset(seed=1, options={"start": [0.3, -0.4, 0.8]})
        site = env.rig.world.data.site_xpos[env._site]
        assert np.allclose(obs[9:12], site, atol=1e-4)  # FK of measured angles == MuJoCo's site
    finally:
        env.close()


def test_hardware_rendering_twin_follows_the_measured_angles(gl_unavailable: str) -> None:
    if gl_unavailable:
        pytest.skip(gl_unavailable)
    env = _as_hardware(ErobArmReachEnv(render_mode="rgb_array", width=64, height=48))
    try:
        env.reset(seed=1, options={"start": [0.3, -0.4, 0.8]})
        frame = env.render()
        assert frame is not None and frame.shape == (48, 64, 3)
        assert env._twin is not None
        twin_model, twin_data, _adr = env._twin
        assert twin_model is not env.rig.world.model
        assert np.allclose(twin_data.qpos, env.rig.world.data.qpos, atol=1e-4)
    finally:
        env.close()
