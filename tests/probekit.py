"""What the probes (``tests/*/*_probe.py``, measuring tools, not tests) share: the bench's reference timed the probes'
way, timed blocks of steps and the records their blocks compare."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np


def raw_step(model: Any, n: int) -> float:
    """CPU seconds (``time.thread_time``) per raw ``mj_step`` over ``n`` of them on a fresh MjData, one Python call
    per substep: the bench's reference, timed the probes' way."""
    import mujoco

    data = mujoco.MjData(model)
    step = mujoco.mj_step
    t = time.thread_time()
    for _ in range(n):
        step(model, data)
    return (time.thread_time() - t) / max(n, 1)


def timed_steps(env: Any, obs: Any, actions: Any, profile: Callable[..., Any] | None = None
                ) -> tuple[float, list[Any]]:
    """``env`` stepped through ``actions`` from the observation ``obs`` (reset at each episode's end, neither timed
    nor profiled: the bench's way): the CPU seconds per step (``time.thread_time``) and the record the probes
    compare (observations, rewards, ends); ``profile``: set by ``sys.setprofile`` over the steps."""
    record: list[Any] = [obs.tobytes()]
    spent = 0.0
    sys.setprofile(profile)
    t0 = time.thread_time()
    for a in actions:
        obs, reward, terminated, truncated, _ = env.step(a)
        record.append((obs.tobytes(), reward, terminated, truncated))
        if terminated or truncated:
            spent += time.thread_time() - t0
            sys.setprofile(None)
            obs, _ = env.reset()
            sys.setprofile(profile)
            t0 = time.thread_time()
    spent += time.thread_time() - t0
    sys.setprofile(None)
    return spent / len(actions), record


def timed_vec_steps(vec: Any, actions: Any, profile: Callable[..., Any] | None = None) -> tuple[float, list[Any]]:
    """A batched env (reset by the caller) stepped through ``actions``: the CPU seconds per rig step
    (``time.thread_time``) and each step's (observations, rewards); ``profile``: as :func:`timed_steps`'."""
    got: list[Any] = []
    sys.setprofile(profile)
    t0 = time.thread_time()
    for a in actions:
        obs, reward, *_ = vec.step(a)
        got.append((obs, reward))
    spent = time.thread_time() - t0
    sys.setprofile(None)
    return spent / (len(actions) * vec.num_envs), got


def same_as_first(first: list[Any] | None, got: list[Any]) -> list[Any]:
    """The first block's record (``got`` if there was none yet); asserts ``got`` has its bits."""
    if first is None:
        return got
    assert all(np.array_equal(x[0], y[0]) and np.array_equal(x[1], y[1]) for x, y in zip(got, first))
    return first
