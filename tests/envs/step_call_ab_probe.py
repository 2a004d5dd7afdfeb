"""An env step in one compiled call against the same step in three (the command, the wait, the read), alternated
in one process.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/step_call_ab_probe.py [ENV_ID MODE
...]`` (default: ErobReach and ErobArmReach in every action mode) makes two of the env by ``gym.make`` (gymnasium's
wrappers included); on the second, ``CompiledPath.step`` answers None, so each of its steps goes the way it went
before the one-call step (:meth:`envs.base.JointsEnv.step`'s fallback). Each block is ``STEPS`` steps of the same
seeded uniform actions from the same reset (resets at episode ends not timed), the two alternating for ``ROUNDS``
rounds; every block's observations, rewards and ends must be bit-identical. Prints per step the best and median CPU
time (``time.thread_time``) of each, their difference, and raw ``mj_step``'s time on the env's model measured right
after each block (the period's substeps times that, over the step: the ratio ``joints bench`` reports). Pin it to one core
(``taskset -c 1``).
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

import envs  # noqa: F401 - registers the joints/ envs

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from probekit import same_as_first, timed_steps

ROUNDS = int(os.environ.get("ROUNDS", "8"))
STEPS = int(os.environ.get("STEPS", "300"))
CASES = [("joints/ErobReach-v0", m) for m in ("position", "velocity", "torque")] + \
    [("joints/ErobArmReach-v0", m) for m in ("position", "velocity", "torque")]


def _raw_step(model: Any, n: int = 2000) -> float:
    """CPU seconds of one raw ``mj_step`` on ``model`` (best of 3 runs of ``n``)."""
    data = mujoco.MjData(model)
    best = float("inf")
    for _ in range(3):
        t0 = time.thread_time()
        for _ in range(n):
            mujoco.mj_step(model, data)
        best = min(best, (time.thread_time() - t0) / n)
    return best


def run(env_id: str, mode: str) -> None:
    made = []
    for split in (False, True):
        env = gym.make(env_id, action_mode=mode)
        u: Any = env.unwrapped
        if split:
            u.compiled_path.step = lambda *args, **kwargs: None
        made.append(env)
    actions = np.random.default_rng(0).uniform(-1.0, 1.0, (STEPS, *np.shape(made[0].action_space.sample()))).astype(
        np.float32)
    times: list[list[float]] = [[], []]
    raws: list[float] = []
    first = None
    for _ in range(ROUNDS):
        for k, env in enumerate(made):
            obs, _ = env.reset(seed=1)
            u = env.unwrapped
            dt, record = timed_steps(env, obs, actions)
            first = same_as_first(first, [(np.frombuffer(r[0] if isinstance(r, tuple) else r), np.array(
                r[1:] if isinstance(r, tuple) else [])) for r in record])
            times[k].append(dt)
            raws.append(_raw_step(u.model))
    taken = made[0].unwrapped.compiled_path.steps_taken  # type: ignore[attr-defined]
    raw = min(raws)
    u = made[0].unwrapped
    n = u.control_period / u.model.opt.timestep  # substeps per step (the overrun-free step's)
    one, three = (min(t) for t in times)
    one_m, three_m = (statistics.median(t) for t in times)
    print(f"{env_id} {mode}: one call {one * 1e6:.1f} / {one_m * 1e6:.1f} us, three {three * 1e6:.1f} / "
          f"{three_m * 1e6:.1f} us (best / median), saved {(three - one) * 1e6:.1f} / {(three_m - one_m) * 1e6:.1f} "
          f"us; raw mj_step {raw * 1e6:.2f} us x {n:.1f} substeps: ratio {n * raw / one:.2f} vs {n * raw / three:.2f}"
          f" (best); one-call steps {taken}; load {os.getloadavg()[0]:.1f}", flush=True)
    for env in made:
        env.close()


if __name__ == "__main__":
    args = sys.argv[1:]
    for env_id, mode in (list(zip(args[::2], args[1::2])) if args else CASES):
        run(env_id, mode)
