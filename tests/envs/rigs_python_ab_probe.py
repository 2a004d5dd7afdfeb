"""The batched rigs' Python of two checkouts in one process, with the compiled calls' own time taken out: CPU time per
rig step of the batch's step (``envs/batch.py``), the rigs' one call (``joints.CompiledRigs``) and its write-back
(:mod:`joints.sim.rigs_exchange`) of either checkout.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/rigs_python_ab_probe.py OTHER [N ...]``
(``OTHER`` the root of another checkout, e.g. a ``git archive`` of the commit to compare with) runs
``gym.make_vec("joints/ErobReach-v0", num_envs=N, vectorization_mode="vector_entry_point")`` block by block with
either checkout's functions set on the live batch (``Batch.begin`` / ``finish``, ``CompiledRigs.command`` /
``states`` / ``_send``, ``CompiledRigs._carry``). Each block is the same seeded uniform actions from the same reset,
timed by ``time.thread_time``, the compiled calls (``rigs_exchanges``, shared by both) timed apart; the blocks
alternate (``ROUNDS`` of each) and every block's observations and rewards must be bit-identical to the first's.
Prints the best and median CPU time per rig step of each, whole and without the compiled calls ("Python"). The
compiled calls' time moves with the load more than the Python does: the "Python" column is the one that resolves a
change of a few us. Pin it to one core (``taskset -c 1``).
"""

from __future__ import annotations

import os
import sys
import time
from typing import Any

import numpy as np

import envs  # noqa: F401 - registers the joints/ envs

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # tests/, for probekit
from probekit import load_as, other_rigs, rigs_vec, same_as_first, timed_vec_steps

from envs import batch as B
from joints import compiled_path as CP
from joints.sim import rigs_exchange as R

ROUNDS = int(os.environ.get("ROUNDS", "8"))
BATCH = ("begin", "finish")
RIGS = ("command", "states", "_send")


class _Timed:
    """The compiled entry with its CPU time summed (:attr:`seconds`)."""

    def __init__(self, fn: Any) -> None:
        self.fn = fn
        self.seconds = 0.0

    def __call__(self, *args: Any) -> None:
        t0 = time.thread_time()
        self.fn(*args)
        self.seconds += time.thread_time() - t0


def _versions(other: str) -> dict[str, tuple[Any, dict[str, Any], dict[str, Any]]]:
    """Per checkout: (its ``carry_rigs``, its ``Batch`` functions, its ``CompiledRigs`` functions)."""
    o_r, o_cp = other_rigs(other)
    o_b = load_as(other, "envs/batch.py", "other_batch")

    def funcs(batch: Any, rigs: Any) -> tuple[dict[str, Any], dict[str, Any]]:
        return ({k: batch.Batch.__dict__[k] for k in BATCH}, {k: rigs.CompiledRigs.__dict__[k] for k in RIGS})

    return {"this": (R.carry_rigs, *funcs(B, CP)), "other": (o_r.carry_rigs, *funcs(o_b, o_cp))}


def main() -> None:
    other = sys.argv[1]
    sizes = [int(a) for a in sys.argv[2:]] or [16, 256]
    versions = _versions(other)
    timed = _Timed(R.compiled())
    R._COMPILED[0] = timed
    print(f"load {os.getloadavg()[0]:.1f}; CPU time per rig step, best / median of {ROUNDS} blocks")
    for n in sizes:
        steps = max(32, 8192 // n)
        vec, rigs, actions = rigs_vec(n, steps)
        whole: dict[str, list[float]] = {k: [] for k in versions}
        python: dict[str, list[float]] = {k: [] for k in versions}
        first: list[Any] | None = None
        buffers: dict[str, dict[Any, Any]] = {k: {} for k in versions}  # each checkout's own call buffers
        for r in range(ROUNDS):
            for tag in (("this", "other") if r % 2 else ("other", "this")):
                carry, batch_fns, rigs_fns = versions[tag]
                rigs._carry = carry
                rigs._buffers = buffers[tag]
                for k, f in batch_fns.items():
                    setattr(B.Batch, k, f)
                for k, f in rigs_fns.items():
                    setattr(CP.CompiledRigs, k, f)
                vec.reset(seed=0)
                before, compiled = rigs.taken, timed.seconds
                seconds, got = timed_vec_steps(vec, actions)
                whole[tag].append(seconds)
                python[tag].append(seconds - (timed.seconds - compiled) / (len(actions) * n))
                assert rigs.taken - before >= steps, "the one call was not taken"
                first = same_as_first(first, got)
        vec.close()
        line = [f"N={n:4d}"]
        for name, times in (("whole", whole), ("Python", python)):
            for tag in versions:
                v = np.array(times[tag]) * 1e6
                line.append(f"{name} {tag} {v.min():6.1f} / {np.median(v):6.1f}")
            b, o = min(times["other"]), min(times["this"])
            line.append(f"({100 * (o - b) / b:+5.1f} % best)")
        print("  ".join(line), flush=True)


if __name__ == "__main__":
    main()
