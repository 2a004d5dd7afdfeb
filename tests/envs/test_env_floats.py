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
