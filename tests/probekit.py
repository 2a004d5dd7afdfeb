"""What the A/B probes (``tests/*/*_ab_probe.py``, measuring tools, not tests) share: loading another
checkout's module under another name, so both versions run in one process."""

from __future__ import annotations

import importlib.util
import os
import sys
import time
from typing import Any

import numpy as np


def load_as(root: str, rel: str, name: str) -> Any:
    """The module at ``root``/``rel`` (another checkout's file), imported as ``name``."""
    spec = importlib.util.spec_from_file_location(name, os.path.join(root, rel))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


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


def timed_steps(env: Any, obs: Any, actions: Any) -> tuple[float, list[Any]]:
    """``env`` stepped through ``actions`` from the observation ``obs`` (reset at each episode's end): the CPU
    seconds per step (``time.thread_time``) and the record the probes compare (observations, rewards, ends)."""
    record: list[Any] = [obs.tobytes()]
    t0 = time.thread_time()
    for a in actions:
        obs, reward, terminated, truncated, _ = env.step(a)
        record.append((obs.tobytes(), reward, terminated, truncated))
        if terminated or truncated:
            obs, _ = env.reset()
    return (time.thread_time() - t0) / len(actions), record


def timed_vec_steps(vec: Any, actions: Any) -> tuple[float, list[Any]]:
    """A batched env (reset by the caller) stepped through ``actions``: the CPU seconds per rig step
    (``time.thread_time``) and each step's (observations, rewards)."""
    got: list[Any] = []
    t0 = time.thread_time()
    for a in actions:
        obs, reward, *_ = vec.step(a)
        got.append((obs, reward))
    return (time.thread_time() - t0) / (len(actions) * vec.num_envs), got


def same_as_first(first: list[Any] | None, got: list[Any]) -> list[Any]:
    """The first block's record (``got`` if there was none yet); asserts ``got`` has its bits."""
    if first is None:
        return got
    assert all(np.array_equal(x[0], y[0]) and np.array_equal(x[1], y[1]) for x, y in zip(got, first))
    return first


def other_rigs(root: str) -> tuple[Any, Any]:
    """(``root``'s ``joints.sim.rigs_exchange``, its ``joints.compiled_path``) loaded beside this checkout's, the
    rigs' compiled kernel this checkout's (compiled here first: the other module would compile its own, minutes,
    and cache it under its probe name)."""
    from joints.sim import rigs_exchange

    other = load_as(root, "joints/sim/rigs_exchange.py", "other_rigs_exchange")
    rigs_exchange.compiled()
    other._COMPILED = rigs_exchange._COMPILED
    return other, load_as(root, "joints/compiled_path.py", "other_compiled_path")


def rigs_vec(n: int, steps: int) -> tuple[Any, Any, Any]:
    """(``n`` batched ``joints/ErobReach-v0`` rigs, their ``CompiledRigs``, ``steps`` x ``n`` seeded uniform actions),
    the episodes unlimited."""
    import gymnasium as gym

    vec = gym.make_vec("joints/ErobReach-v0", num_envs=n, vectorization_mode="vector_entry_point")
    u: Any = vec.unwrapped
    rigs = u._batch.rigs
    assert rigs is not None
    u.max_episode_steps = None
    return vec, rigs, np.random.default_rng(0).uniform(-1, 1, (steps, n, 1)).astype(np.float32)
