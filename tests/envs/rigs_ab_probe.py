"""The batched env's step with the rigs' exchanges in one compiled call across the rigs and without it, in one
process: CPU time per rig step for N = 1, 4, 16, 64, 256 rigs.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/rigs_ab_probe.py [N ...]`` runs
``gym.make_vec("joints/ErobReach-v0", num_envs=N, vectorization_mode="vector_entry_point")`` block by block in two
settings of the same env: "rig by rig" (``Batch.rigs`` set to None: each rig's command and state read are its own
compiled calls and the rigs sleep together in one call, as before :class:`joints.CompiledRigs`), "one call, sleeps
together" (every rig's commands in one call, every rig's reads in another, the sleeps as before) and "one call"
(the same, each rig's sleep booked and run in the read's call, :meth:`joints.CompiledRigs.joined`). Each block is the same seeded uniform actions from the same reset, timed by
``time.thread_time`` (other processes' load does not count); the blocks alternate (``ROUNDS`` of each) and every
block's observations and rewards must be bit-identical to the first's. Prints the best and median CPU time per rig
step of each, and the calls the one-call setting made. Pin it to one core (``taskset -c 1``). At N = 1 the batch
path is off by default (``BATCH_MIN``) and there is nothing to carry across rigs: both settings are the same code.
"""

from __future__ import annotations

import os
import sys
from typing import Any

import gymnasium as gym
import numpy as np

import envs  # noqa: F401 - registers the joints/ envs

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # tests/, for probekit
from probekit import same_as_first, timed_vec_steps

ROUNDS = int(os.environ.get("ROUNDS", "8"))
SIZES = (1, 4, 16, 64, 256)
ACTION_MODE = os.environ.get("MODE", "position")


SETTINGS = ("rig by rig", "one call, sleeps together", "one call")


def main() -> None:
    sizes = [int(a) for a in sys.argv[1:]] or list(SIZES)
    print(f"load {os.getloadavg()[0]:.1f}; {ACTION_MODE}; CPU time per rig step, best / median of {ROUNDS} blocks")
    for n in sizes:
        vec = gym.make_vec("joints/ErobReach-v0", num_envs=n, vectorization_mode="vector_entry_point",
                           action_mode=ACTION_MODE)
        u = vec.unwrapped
        batch = u._batch
        rigs = None if batch is None else batch.rigs
        joined = None if batch is None else batch.joined
        steps = max(16, 4096 // n)
        u.max_episode_steps = None
        actions = np.random.default_rng(0).uniform(-1, 1, (steps, n, 1)).astype(np.float32)
        times: dict[str, list[float]] = {k: [] for k in SETTINGS}
        first: list[Any] | None = None
        calls = 0
        for r in range(ROUNDS):
            order = SETTINGS if r % 2 else SETTINGS[::-1]
            for setting in order:
                if batch is not None:
                    batch.rigs = None if setting == "rig by rig" else rigs
                    batch.joined = joined if setting == "one call" else (lambda: False)  # type: ignore[method-assign]
                vec.reset(seed=0)
                before = 0 if rigs is None else rigs.taken
                seconds, got = timed_vec_steps(vec, actions)
                times[setting].append(seconds)
                if setting == "one call" and rigs is not None:
                    calls = rigs.taken - before
                first = same_as_first(first, got)
        vec.close()
        line = [f"N={n:4d}"]
        for setting in SETTINGS:
            v = np.array(times[setting]) * 1e6
            line.append(f"{setting} {v.min():6.1f} / {np.median(v):6.1f}")
        b, o = min(times["rig by rig"]), min(times["one call"])
        line.append(f"us; gain {100 * (b - o) / b:5.1f} % (best); calls {calls} in {steps} steps")
        print("  ".join(line), flush=True)


if __name__ == "__main__":
    main()
