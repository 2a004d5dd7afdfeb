"""Benchmark: the gymnasium envs' steps/s and real-time factor, against raw mj_step on the same model.

For each env (and action mode) it prints, all measured in the same run on one core:

* env steps/s of ``env.step`` (unwrapped env, sim backend, resets not timed),
* real-time factor = simulated seconds per wall second (steps/s x dt), goal >= 50 for ErobReach-v0,
* physics substeps/s inside ``env.step`` (steps/s x substeps per step) and the same model's raw
  ``mujoco.mj_step`` loop (fresh MjData) - their ratio, goal >= 0.5,
* for the breakdown: ``World.step`` alone (physics + the emulated drives' loops, no bus traffic).

    python tests/benchmarks/bench_envs.py
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import mujoco
import numpy as np

from envs import ErobArmReachEnv, ErobReachEnv
from joints.bench import median_pair, paired

STEPS = 500  #: env steps per timed block (10 s simulated at 20 ms)
REPEATS = 5
RAW_STEPS = 20000


def _env_seconds(env: Any, actions: np.ndarray) -> float:
    """Wall seconds of STEPS env.step calls (resets after an episode end are not timed)."""
    env.reset(seed=0)
    total = 0.0
    for a in actions:
        t = time.perf_counter()
        _obs, _r, terminated, _trunc, _info = env.step(a)
        total += time.perf_counter() - t
        if terminated:
            env.reset()
    return total


def bench(name: str, env: Any) -> None:
    world = env.rig.world
    rng = np.random.default_rng(0)
    actions = (0.3 * rng.uniform(-1, 1, (STEPS,) + env.action_space.shape)).astype(np.float32)
    raw = mujoco.MjData(world.model)

    def raw_loop() -> float:
        t = time.perf_counter()
        for _ in range(RAW_STEPS):
            mujoco.mj_step(world.model, raw)
        return time.perf_counter() - t

    # in pairs, the reference right after the env block (a burst of load hits both alike); the median pair's
    # figures (the best of each side on its own can pair a fast env block with slow references)
    pairs = paired([lambda: _env_seconds(env, actions), raw_loop], REPEATS)
    t_env, t_raw = pairs[median_pair(len(pairs), lambda i: pairs[i][0] / pairs[i][1])]
    steps_s = STEPS / t_env
    rtf = steps_s * env.dt
    substeps_s = steps_s * env.substeps
    raw_s = RAW_STEPS / t_raw

    def world_loop() -> float:
        t = time.perf_counter()
        world.step(RAW_STEPS // 4)
        return time.perf_counter() - t

    env.reset(seed=0)
    w_pairs = paired([world_loop, raw_loop], REPEATS)
    t_world, t_raw_w = w_pairs[median_pair(len(w_pairs), lambda i: w_pairs[i][0] / w_pairs[i][1])]
    world_s, raw_w = (RAW_STEPS // 4) / t_world, RAW_STEPS / t_raw_w
    env.close()
    print(f"{name:<34} {steps_s:>7.0f} steps/s | real-time factor {rtf:>5.1f}x"
          f"{' (goal >= 50)' if name.startswith('ErobReach-v0') else '             '} | "
          f"substeps/s in env.step {substeps_s:>7.0f} | raw mj_step {raw_s:>7.0f} | "
          f"ratio {substeps_s / raw_s:.2f} (goal >= 0.5) | World.step alone {world_s:>6.0f} "
          f"(ratio {world_s / raw_w:.2f})")


def main() -> None:
    if hasattr(os, "sched_setaffinity"):
        cpu = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})  # one core
    print(f"env steps of {STEPS}, the median of {REPEATS} pairs (env block, reference); raw mj_step loop of {RAW_STEPS}; one core")
    for mode in ("position", "velocity", "torque"):
        bench(f"ErobReach-v0 ({mode})", ErobReachEnv(action_mode=mode))
    for mode in ("position", "torque"):
        bench(f"ErobArmReach-v0 ({mode})", ErobArmReachEnv(action_mode=mode))
    bench("ErobReach-v0 (torque, randomised)", ErobReachEnv(action_mode="torque", domain_randomization=True))


if __name__ == "__main__":
    main()
