"""The batched env's step with the rigs' exchanges in compiled calls across the rigs and without them, in one
process: CPU time per rig step for N = 1, 4, 16, 64, 256 rigs.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/rigs_ab_probe.py [N ...]`` runs
``gym.make_vec("joints/ErobReach-v0", num_envs=N, vectorization_mode="vector_entry_point")`` on its batched path
block by block in four settings of the same env: "rig by rig" (``Batch.rigs`` set to None: each rig's command and
state read are its own compiled calls and the rigs sleep together in one call, as before
:class:`joints.CompiledRigs`), "two calls, sleeps together" (every rig's commands in one call, every rig's reads in
another, the sleeps as before), "two calls" (the same, each rig's sleep booked and run in the reads' call,
:meth:`joints.CompiledRigs.joined`) and "one call" (each step whole in one call, :meth:`joints.CompiledRigs.step`;
the two-call settings turn it off by ``Batch._stepping``). Each block is the same seeded uniform actions from the
same reset, timed by ``time.thread_time`` (other processes' load does not count); the blocks alternate (``ROUNDS``
of each) and every block's observations and rewards must be bit-identical to the first's. Prints the best and
median CPU time per rig step of each, the one call's gain over "two calls" and over "rig by rig", and the calls the
one-call setting made. Pin it to one core (``taskset -c 1``).
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


SETTINGS = ("rig by rig", "two calls, sleeps together", "two calls", "one call")


def main() -> None:
    sizes = [int(a) for a in sys.argv[1:]] or list(SIZES)
    print(f"load {os.getloadavg()[0]:.1f}; {ACTION_MODE}; CPU time per rig step, best / median of {ROUNDS} blocks")
    for n in sizes:
        vec = gym.make_vec("joints/ErobReach-v0", num_envs=n, vectorization_mode="vector_entry_point",
                           action_mode=ACTION_MODE)
        u: Any = vec.unwrapped
        batch = u._batch
        rigs = None if batch is None else batch.rigs
        joined = None if batch is None else batch.joined
        stepping = None if batch is None else batch._stepping
        u.batched = True  # (the batched path below BATCH_MIN too, where the default may be rig by rig)
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
                    together = setting.endswith("together")
                    batch.joined = (lambda: False) if together else joined
                    batch._stepping = stepping if setting == "one call" else False
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
        b, t, o = min(times["rig by rig"]), min(times["two calls"]), min(times["one call"])
        line.append(f"us; one call's gain {100 * (t - o) / t:5.1f} % over two calls, {100 * (b - o) / b:5.1f} % over "
                    f"rig by rig (best); calls {calls} in {steps} steps")
        print("  ".join(line), flush=True)


if __name__ == "__main__":
    main()
