"""The env's own Python per step: what an env step takes beyond the rig's calls, exclusive.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/own_step_probe.py`` makes each
env by ``gym.make(id)`` (its defaults, gymnasium's wrappers included) and times ``env.step`` with uniform
random actions (seed 0), less the time inside the rig's work: the compiled path's command and state calls,
``rig.sleep``, ``rig.read_states`` / ``rig.set_velocities``, the world's physics catching up
(``world.sync``) and the stop commands when an episode ends (``_safe_stop``). What is left is the env's own
step: action checks and scaling, the safety cap and shield, observation, reward, info, termination (and
gymnasium's wrappers). Best of ``BLOCKS`` identical blocks (same seed, same actions; resets not timed), so
a burst of load on a shared machine does not count; the arm's shield is also shown alone. Then the batched
env (``gym.make_vec(..., vectorization_mode="vector_entry_point")``) per rig step, less the rigs' work (the
batch's one-call command and state read, :class:`joints.CompiledRigs`, where it has them) and
``joints.sleep_together``. Pin it to one core (``taskset -c 1``); compare two checkouts by running the probe of
each, alternating, with ``PYTHONPATH`` set to the checkout.

Environment: ``OWN_CLOCK=thread`` times by this thread's CPU time (``time.thread_time``: a machine shared with
other work does not count its preemptions; default ``perf_counter``); ``OWN_ONLY=Reach,16`` runs only the
cases whose line contains one of those words (an env id's part, a mode, a rig count).
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

import envs
import joints

BLOCKS = 8
STEPS = 250
CASES = [("joints/ErobReach-v0", mode) for mode in ("position", "velocity", "torque")] + \
        [("joints/ErobArmReach-v0", mode) for mode in ("position", "velocity", "torque")] + \
        [("joints/DiffDriveGoal-v0", None)]
RIGS = (16, 256)

clock = time.thread_time if os.environ.get("OWN_CLOCK") == "thread" else time.perf_counter
ONLY = [w for w in os.environ.get("OWN_ONLY", "").split(",") if w]


def _wanted(label: str) -> bool:
    return not ONLY or any(w in label for w in ONLY)
spent = {"rig": 0.0, "shield": 0.0}


def _timed(fn: Callable[..., Any], key: str) -> Callable[..., Any]:
    def timed(*args: Any, **kwargs: Any) -> Any:
        t = clock()
        try:
            return fn(*args, **kwargs)
        finally:
            spent[key] += clock() - t
    return timed


def _instrument(u: Any) -> None:
    """Count the rig's work of the env ``u`` (and its shield) in ``spent``."""
    compiled = getattr(u, "compiled_path", None)
    if compiled is not None:
        compiled.command = _timed(compiled.command, "rig")
        compiled.states = _timed(compiled.states, "rig")
    rig = u.rig
    for name in ("sleep", "read_states", "set_velocities"):
        if hasattr(rig, name):
            setattr(rig, name, _timed(getattr(rig, name), "rig"))
    if rig.sim is not None:
        rig.sim.sync = _timed(rig.sim.sync, "rig")
    if hasattr(u, "_safe_stop"):
        u._safe_stop = _timed(u._safe_stop, "rig")
    if isinstance(u, envs.JointsEnv) and type(u)._shield is not envs.JointsEnv._shield:
        u._shield = _timed(u._shield, "shield")


def single(env_id: str, mode: str | None) -> tuple[float, float]:
    """(own, shield) seconds per step, best of BLOCKS."""
    env = gym.make(env_id, **({} if mode is None else {"action_mode": mode}))
    _instrument(env.unwrapped)
    actions = np.random.default_rng(0).uniform(-1, 1, (STEPS, *env.action_space.shape)).astype(np.float32)
    best = (np.inf, np.inf)
    try:
        for _ in range(BLOCKS):
            env.reset(seed=0)
            spent["rig"] = spent["shield"] = total = 0.0
            for a in actions:
                t = clock()
                _obs, _r, terminated, truncated, _info = env.step(a)
                total += clock() - t
                if terminated or truncated:
                    rig, shield = spent["rig"], spent["shield"]
                    env.reset()
                    spent["rig"], spent["shield"] = rig, shield
            best = min(best, ((total - spent["rig"]) / STEPS, spent["shield"] / STEPS))
    finally:
        env.close()
    return best


def batched(rigs: int) -> float:
    """Own seconds per rig step of ``rigs`` batched ErobReach rigs, best of BLOCKS // 2."""
    vec = gym.make_vec("joints/ErobReach-v0", num_envs=rigs, vectorization_mode="vector_entry_point")
    for e in vec.unwrapped.envs:
        _instrument(e)
    batch = vec.unwrapped._batch
    one_call = None if batch is None else batch.rigs  # every rig's command (and state read) in one compiled call
    if one_call is not None:
        one_call.command, one_call.states = _timed(one_call.command, "rig"), _timed(one_call.states, "rig")
    together = joints.sleep_together
    joints.sleep_together = _timed(together, "rig")
    batches = max(4, 1024 // rigs)
    actions = np.random.default_rng(0).uniform(-1, 1, (batches, *vec.action_space.shape)).astype(np.float32)
    best = np.inf
    try:
        for _ in range(BLOCKS // 2):
            vec.reset(seed=0)
            spent["rig"] = total = 0.0
            for a in actions:
                t = clock()
                vec.step(a)
                total += clock() - t
            best = min(best, (total - spent["rig"]) / (batches * rigs))
    finally:
        joints.sleep_together = together
        vec.close()
    return float(best)


def main() -> None:
    print(f"Python {sys.version.split()[0]}, load {os.getloadavg()[0]:.1f}; us per step, best of {BLOCKS} x {STEPS}"
          f" ({clock.__name__})")
    for env_id, mode in CASES:
        if not _wanted(f"{env_id} {mode or ''}"):
            continue
        own, shield = single(env_id, mode)
        print(f"{env_id:26s} {mode or '':9s} own {own * 1e6:6.1f}" + (f"  (shield {shield * 1e6:5.1f})" if shield else ""))
    for n in RIGS:
        if not _wanted(f"{n} rigs"):
            continue
        print(f"{n:3d} rigs batched (ErobReach) own {batched(n) * 1e6:6.1f} per rig step")


if __name__ == "__main__":
    main()
