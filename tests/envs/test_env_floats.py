"""The env's per-step arithmetic on plain floats gives numpy's bits (envs.base.clip, command_of, safe_command)."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401 - registers the joints/ envs
from envs.base import clip

EDGES = [0.0, -0.0, 1.0, -1.0, 1e-300, -1e-300, 5e-324, math.inf, -math.inf, 0.5, -0.5, 3.0, -3.0, 2.9999999999999996]


def _bits(x: float) -> bytes:
    return np.float64(x).tobytes()


@pytest.mark.parametrize("low,high", [(-1.0, 1.0), (-3.0, 3.0), (0.5, 2.0), (-35.0, -1e-300)])
def test_clip_is_np_clip_bit_for_bit(low: float, high: float) -> None:
    """Nonzero bounds, as the envs' (a bound of signed zero meets numpy versions' differing tie rules)."""
    rng = np.random.default_rng(0)
    values = EDGES + rng.uniform(-4, 4, 500).tolist() + [math.nan]
    for v in values:
        want = np.clip(np.array([v]), low, high)[0]
        got = clip(v, low, high)
        assert _bits(got) == _bits(want) or (math.isnan(got) and math.isnan(want)), (v, low, high, got, want)


def _reference_command_of(u: Any, action: np.ndarray) -> np.ndarray:
    """The array arithmetic command_of had before it worked on plain floats."""
    a = np.asarray(action, dtype=np.float64).reshape(-1).clip(-1.0, 1.0)
    if u.action_mode == "position":
        lo, hi = u.position_limits[:, 0], u.position_limits[:, 1]
        return (lo + (a + 1.0) * 0.5 * (hi - lo)).clip(lo, hi)  # type: ignore[no-any-return]
    if u.action_mode == "velocity":
        return a * u.velocity_limits  # type: ignore[no-any-return]
    return a * u.torque_limits  # type: ignore[no-any-return]


@pytest.mark.parametrize("mode", ["position", "velocity", "torque"])
@pytest.mark.parametrize("env_id", ["joints/ErobReach-v0", "joints/ErobArmReach-v0"])
def test_command_of_and_the_limit_clip_give_the_array_bits(env_id: str, mode: str) -> None:
    with gym.make(env_id, action_mode=mode) as env:
        u: Any = env.unwrapped
        n = len(u.joints)
        rng = np.random.default_rng(1)
        actions = [rng.uniform(-1.5, 1.5, n) for _ in range(300)] + [np.full(n, v) for v in EDGES if math.isfinite(v)]
        for a in actions:
            assert u.command_of(a).tobytes() == _reference_command_of(u, a).tobytes()
        # before the first state, safe_command is the limit clip alone
        lo, hi = u.position_limits[:, 0], u.position_limits[:, 1]
        cap = {"position": None, "velocity": u.speed_cap, "torque": u.torque_limits}[mode]
        for a in actions:
            c = a * 4.0
            want = np.clip(c, lo, hi) if cap is None else np.clip(c, -cap, cap)
            assert u.safe_command(c).tobytes() == want.tobytes()
        with pytest.raises(ValueError, match="finite"):
            u.safe_command(np.full(n, math.nan))
        with pytest.raises(ValueError, match="one finite value per joint"):
            u.safe_command(np.zeros(n + 1))


def test_braking_speed_of_gives_the_arrays_bits() -> None:
    """The per-joint braking cap on plain floats is braking_speed's arrays, bit for bit, on every branch."""
    from envs.base import braking_speed, braking_speed_of

    rng = np.random.default_rng(3)
    branches = set()
    for _ in range(20000):
        a = float(rng.choice([10.0, 8.0, rng.uniform(0.5, 30.0)]))
        t = float(rng.choice([0.04, 0.1, rng.uniform(0.001, 0.2)]))
        u = float(rng.choice([0.0, -0.0, rng.uniform(-3.0, 3.0), rng.uniform(-0.01, 0.01)]))
        d = float(rng.choice([0.0, -0.0, rng.uniform(-0.2, 3.0), rng.uniform(-1e-3, 1e-2), rng.uniform(0.0, 0.3)]))
        want = braking_speed(np.array([d]), np.array([a]), t, np.array([u]))[0]
        got = braking_speed_of(d, a, t, u)
        assert _bits(got) == _bits(want), (d, a, t, u, got, want)
        branches.add("inf" if math.isinf(got) else "zero" if got == 0.0 else "speed")
    assert branches == {"inf", "zero", "speed"}


def test_clip_to_is_np_clip_between_array_bounds_bit_for_bit() -> None:
    """Array bounds give the bound on a tie (``-0.0`` for ``0.0`` against ``-0.0``), unlike a scalar bound."""
    from envs.base import clip_to

    rng = np.random.default_rng(4)
    bounds = [0.0, -0.0, 1.0, -1.0, math.inf, -math.inf, 2.5, -2.5]
    for v in EDGES + rng.uniform(-4, 4, 200).tolist() + [math.nan]:
        for lo in bounds:
            for hi in bounds:
                if lo > hi:
                    continue
                want = np.clip(np.array([v]), np.array([lo]), np.array([hi]))[0]
                got = clip_to(v, lo, hi)
                assert _bits(got) == _bits(want) or (math.isnan(got) and math.isnan(want)), (v, lo, hi, got, want)
    assert _bits(clip_to(0.0, -0.0, 1.0)) == _bits(-0.0)  # the case that tells the two rules apart


def test_the_action_change_of_one_joint_is_np_dot_of_its_difference() -> None:
    rng = np.random.default_rng(5)
    for a, b in rng.uniform(-1, 1, (20000, 2)).tolist() + [(0.0, -0.0), (-0.0, 0.0), (1.0, -1.0), (1e-300, 0.0)]:
        d = np.array([a]) - np.array([b])
        assert _bits((a - b) * (a - b)) == _bits(float(np.dot(d, d)))


def test_erob_arm3_clears_answers_as_the_bound() -> None:
    """The shield's early-exit test is ``erob_arm3_clearance_bound(q2, q3) - less - 1e-9 >= need`` for every
    input, thresholds at the bound itself and one ulp either side included."""
    from envs.kinematics import BOUND_SLACK, erob_arm3_clearance_bound, erob_arm3_clears

    rng = np.random.default_rng(6)
    passed = failed = 0
    for q2, q3 in rng.uniform(-3.3, 3.3, (20000, 2)).tolist():
        bound = erob_arm3_clearance_bound(q2, q3)
        for less in (0.0, 0.013, 0.1):
            edge = bound - less - BOUND_SLACK
            for need in (0.02, edge, float(np.nextafter(edge, 1.0)), float(np.nextafter(edge, -1.0))):
                want = bound - less - BOUND_SLACK >= need
                assert erob_arm3_clears(q2, q3, less, need) == want, (q2, q3, less, need)
                passed += want
                failed += not want
    assert passed > 10000 and failed > 10000


def test_erob_arm3_clears_per_link_bound_holds_over_the_box() -> None:
    """With ``less_upper`` (the upper arm's and the elbow's own motion over a box of poses, ARM3_UPPER * |dq2|
    / 2 from its centre) the early-exit test still only passes where every pose of the box keeps the gap
    (checked on a 0.01 rad grid of the sampled clearance), and it passes for boxes the single bound leaves to
    halving."""
    from envs.kinematics import ARM3_FORE, ARM3_REACH, ARM3_UPPER, erob_arm3_clearance, erob_arm3_clears

    rng = np.random.default_rng(8)
    need = 0.02
    tighter = checked = 0
    for _ in range(3000):
        q2, q3 = rng.uniform(-1.6, 1.6), rng.uniform(-2.4, 2.4)
        h2, h3 = rng.uniform(0.0, 0.15, 2).tolist()
        less, upper = ARM3_REACH * h2 + ARM3_FORE * h3, ARM3_UPPER * h2
        split = erob_arm3_clears(q2, q3, less, need, upper)
        one = erob_arm3_clears(q2, q3, less, need)
        assert split or not one  # never stricter than the single bound
        if split:
            a2 = np.linspace(q2 - h2, q2 + h2, max(2, math.ceil(2 * h2 / 0.01) + 1))
            a3 = np.linspace(q3 - h3, q3 + h3, max(2, math.ceil(2 * h3 / 0.01) + 1))
            assert float(erob_arm3_clearance(a2[:, None], a3[None, :]).min()) >= need, (q2, q3, h2, h3)
            checked += 1
            tighter += not one
    assert checked > 500 and tighter > 100, (checked, tighter)


def test_a_pose_that_falls_short_has_a_sampled_gap_below_the_need() -> None:
    """erob_arm3_falls_short is only True where erob_arm3_clearance (the grid's value) is below ``need``, and
    it is True for most poses that are clearly below."""
    from envs.kinematics import erob_arm3_clearance, erob_arm3_falls_short

    rng = np.random.default_rng(7)
    q = rng.uniform(-3.3, 3.3, (20000, 2))
    gap = erob_arm3_clearance(q[:, 0], q[:, 1])
    for need in (0.02, 0.0, 0.1):
        short = np.array([erob_arm3_falls_short(a, b, need) for a, b in q.tolist()])
        assert np.all(gap[short] < need)
        assert short[gap < need - 1e-6].mean() == 1.0  # a sample point below the need is found
        assert short.sum() > 1000


def _reference_safe_command(u: Any, command: np.ndarray) -> np.ndarray:
    """safe_command as the arrays computed it before it went to plain floats (the shield's loop included)."""
    from envs.base import LIMIT_INSET, braking_speed

    lo, hi = u.position_limits[:, 0], u.position_limits[:, 1]
    if u.action_mode == "position":
        c = np.clip(command, lo, hi)
    else:
        cap = u.speed_cap if u.action_mode == "velocity" else u.torque_limits
        c = np.clip(command, -cap, cap)
    if u.action_mode == "torque":
        return c  # type: ignore[no-any-return]
    if u.action_mode == "velocity":
        p = np.array([s.position for s in u._states])
        v = np.array([s.velocity for s in u._states])
        a, dt = u.profile_acceleration, u.control_period + u.bus_lag
        np.clip(c, -braking_speed(p - (lo + LIMIT_INSET), a, dt, -v), braking_speed(hi - LIMIT_INSET - p, a, dt, v),
                out=c)
    if len(u.joints) == 1:
        return c  # type: ignore[no-any-return]
    out = c
    for hold in ((), (1,), (2,), (1, 2)):
        out = c.copy()
        for i in hold:
            s = u._states[i]
            stop = s.position + s.velocity * abs(s.velocity) / (2.0 * u.profile_deceleration[i])
            out[i] = 0.0 if u.action_mode == "velocity" else float(np.clip(stop, *u.position_limits[i]))
        if u.keeps_clearance(*u._reach(out)):
            return out  # type: ignore[no-any-return]
    return out  # type: ignore[no-any-return]


@pytest.mark.parametrize("mode", ["position", "velocity", "torque"])
@pytest.mark.parametrize("env_id", ["joints/ErobReach-v0", "joints/ErobArmReach-v0"])
def test_each_step_gives_the_array_formulas_bits(env_id: str, mode: str) -> None:
    """Along an episode of random actions: the safe command, the observation and the reward are what the array
    formulas give for the same state (the observation's clip, the task terms, np.dot of the action change)."""
    with gym.make(env_id, action_mode=mode) as env:
        u: Any = env.unwrapped
        n = len(u.joints)
        env.reset(seed=3)
        rng = np.random.default_rng(8)
        prev = u._prev_action.copy()
        held: set[tuple[int, ...]] = set()  # the joints the arm's shield stopped, per step
        low, high = (-1.2, 1.2) if n == 1 else ([-1.2, 0.2, -1.2], [1.2, 1.2, 1.2])  # the arm: shoulder mostly down
        for _ in range(80):
            action = rng.uniform(low, high, n).astype(np.float32)
            a = np.asarray(action, dtype=np.float64).clip(-1.0, 1.0)
            want_cmd = _reference_safe_command(u, _reference_command_of(u, a))
            got_cmd = u.safe_command(u.command_of(a))
            assert got_cmd.tobytes() == want_cmd.tobytes()
            if n == 3 and mode == "position":
                free = np.clip(_reference_command_of(u, a), u.position_limits[:, 0], u.position_limits[:, 1])
                held.add(tuple(i for i in (1, 2) if want_cmd[i] != free[i]))
            obs, reward, terminated, _truncated, info = env.step(action)
            assert info["command"].tobytes() == want_cmd.tobytes()
            if terminated:  # the joints were stopped since (the physics moved on): nothing to recompute from
                env.reset()
                prev = u._prev_action.copy()
                continue
            states = u._states
            pos = np.array([s.position for s in states])
            if n == 1:
                task = np.array([u.target, u.target - pos[0]])
                distance = abs(u.target - float(pos[0]))
            else:
                ee = np.array(u.rig.world.data.site_xpos[u._site])
                task = np.concatenate([ee, u.target, u.target - ee])
                d = u.target - ee
                distance = math.sqrt(d.dot(d))
            raw = np.concatenate([pos, [s.velocity for s in states], [s.torque for s in states], task])
            want_obs = np.minimum(np.maximum(raw, u.observation_space.low), u.observation_space.high)
            assert obs.tobytes() == want_obs.tobytes()
            change = a - prev
            want_reward = -distance + -u.action_rate_weight * float(np.dot(change, change))
            assert _bits(reward) == _bits(want_reward)
            assert _bits(info["distance"]) == _bits(distance)
            prev = a
        if n == 3 and mode == "position":
            assert held >= {(), (1,), (2,)}, held  # the shield's variants were compared too


KINDS = {
    "float32": lambda x: x.astype(np.float32),
    "float64": lambda x: x.astype(np.float64),
    "float16": lambda x: x.astype(np.float16),
    "longdouble": lambda x: x.astype(np.longdouble),
    "int64": lambda x: np.rint(x * 2).astype(np.int64),
    "float64 view": lambda x: np.repeat(x.astype(np.float64), 2)[::2],  # not contiguous
}


@pytest.mark.parametrize("kind", list(KINDS))
@pytest.mark.parametrize("env_id", ["joints/ErobReach-v0", "joints/ErobArmReach-v0"])
def test_an_action_of_any_numeric_array_gives_the_bits_of_its_float64_values(env_id: str, kind: str) -> None:
    """begin_step reads a float array's own floats (float32 and float16 widen exactly) and converts anything else
    with np.asarray(float64): either way the bits of the same values given as a list of Python floats (the
    float64 conversion's), step for step - observation, reward, the command sent - and the same errors."""
    make = KINDS[kind]
    rng = np.random.default_rng(5)
    with gym.make(env_id) as env:
        n = env.action_space.shape[0]
        actions = [make(rng.uniform(-1.3, 1.3, n)) for _ in range(30)]
        runs = []
        for as_list in (False, True):
            env.reset(seed=4)
            run = []
            for a in actions:
                given = np.asarray(a, dtype=np.float64).tolist() if as_list else a
                obs, reward, terminated, truncated, info = env.step(given)
                run.append((obs.tobytes(), _bits(reward), terminated, truncated, info["command"].tobytes()))
            runs.append(run)
        assert runs[0] == runs[1]
        bad = make(np.full(n, 0.5))
        if bad.dtype.kind == "f":
            bad = bad.copy()
            bad[0] = np.nan
            for given in (bad, np.asarray(bad, dtype=np.float64).tolist()):
                with pytest.raises(ValueError, match="action must be finite"):
                    env.step(given)
        for given in (make(np.zeros(n + 1)), np.zeros(n + 1).tolist()):
            with pytest.raises(ValueError, match=rf"action shape \({n + 1},\) != \({n},\)"):
                env.step(given)
