"""The batched env's step with this checkout's batch path and another checkout's, in one process: CPU time per
rig step for N = 1, 4, 16, 64, 256 rigs.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/batch_ab_probe.py OTHER [N ...]``
(``OTHER`` the root of another checkout, e.g. a ``git archive`` of the commit to compare with) runs
``gym.make_vec("joints/ErobReach-v0", num_envs=N, vectorization_mode="vector_entry_point")`` block by block in two
settings: "rig by rig" (the batch path off: ``JointsVectorEnv.batched = False``; OTHER's ``advance_together``;
the group's plan cache bounded at 256 plans, as before) and "batched" (this checkout's). Each block is the same
seeded uniform actions from the same reset, timed by ``time.thread_time`` (other processes' load does not count);
the blocks alternate (``ROUNDS`` of each) and every block's observations and rewards must be bit-identical to the
first's. Prints the best and median CPU time per rig step of each. Pin it to one core (``taskset -c 1``).
``STUB=1``: the rigs' I/O stubbed (each rig's compiled command a no-op, its state read the last states read,
``joints.sleep_together`` a no-op), so what is timed is the envs' own per-step Python (bits not compared).
"""

from __future__ import annotations

import os
import sys
from typing import Any

import gymnasium as gym
import numpy as np

import envs  # noqa: F401 - registers the joints/ envs

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # tests/, for probekit
from probekit import load_as, same_as_first, timed_vec_steps

import joints
from joints.sim import stepping
from joints.sim import world as W

ROUNDS = int(os.environ.get("ROUNDS", "8"))
STUB = os.environ.get("STUB") == "1"
SIZES = (1, 4, 16, 64, 256)


def main() -> None:
    other = sys.argv[1]
    sizes = [int(a) for a in sys.argv[2:]] or list(SIZES)
    old_advance = load_as(other, "joints/sim/world.py", "other_world").advance_together
    new_advance, new_plan = W.advance_together, stepping.Group._plan

    def old_plan(self: Any, worlds: tuple[int, ...]) -> Any:  # the plan cache as it was: cleared at 256 plans
        if worlds not in self._plans and len(self._plans) >= 256:
            self._plans.clear()
        return new_plan(self, worlds)

    print(f"load {os.getloadavg()[0]:.1f}; CPU time per rig step, best / median of {ROUNDS} blocks")
    for n in sizes:
        vec = gym.make_vec("joints/ErobReach-v0", num_envs=n, vectorization_mode="vector_entry_point")
        u = vec.unwrapped
        if STUB:
            vec.reset(seed=0)
            u.max_episode_steps = None
            for e in u.envs:
                last = e.compiled_path.states()
                e.compiled_path.command = lambda *args, **kwargs: None
                e.compiled_path.states = lambda last=last, **kwargs: last
            joints.sleep_together = lambda *args: None
        steps = max(8, 2048 // n)
        actions = np.random.default_rng(0).uniform(-1, 1, (steps, n, 1)).astype(np.float32)
        times: dict[bool, list[float]] = {False: [], True: []}
        first: list[Any] | None = None
        for r in range(ROUNDS):
            for batched in ((True, False) if r % 2 else (False, True)):
                u.batched = batched
                W.advance_together = new_advance if batched else old_advance
                stepping.Group._plan = new_plan if batched else old_plan  # type: ignore[method-assign]
                vec.reset(seed=0)
                seconds, got = timed_vec_steps(vec, actions)
                times[batched].append(seconds)
                if STUB:
                    continue
                first = same_as_first(first, got)
        W.advance_together, stepping.Group._plan = new_advance, new_plan  # type: ignore[method-assign]
        vec.close()
        line = [f"N={n:4d}"]
        for batched, label in ((False, "rig by rig"), (True, "batched")):
            v = np.array(times[batched]) * 1e6
            line.append(f"{label} {v.min():6.1f} / {np.median(v):6.1f} us")
        print("  ".join(line))


if __name__ == "__main__":
    main()
