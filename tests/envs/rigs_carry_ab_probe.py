"""The batched rigs' one-call Python of two checkouts in one process: CPU time per rig step with the other
checkout's :func:`joints.sim.rigs_exchange.carry_rigs` and ``CompiledRigs._send`` swapped in and out.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/rigs_carry_ab_probe.py OTHER [N ...]``
(``OTHER`` the root of another checkout, e.g. a ``git archive`` of the commit to compare with; both must book the
same wire-trace entries, so the two lines' logs mix) runs ``gym.make_vec("joints/ErobReach-v0", num_envs=N,
vectorization_mode="vector_entry_point")`` block by block with either checkout's functions set on the live batch
(``CompiledRigs._carry`` and the class's ``_send``). Each block is the same seeded uniform actions from the same
reset, timed by ``time.thread_time``; the blocks alternate (``ROUNDS`` of each) and every block's observations and
rewards must be bit-identical to the first's. Prints the best and median CPU time per rig step of each. Pin it to
one core (``taskset -c 1``).
"""

from __future__ import annotations

import os
import sys
from typing import Any

import numpy as np

import envs  # noqa: F401 - registers the joints/ envs

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # tests/, for probekit
from probekit import other_rigs, rigs_vec, same_as_first, timed_vec_steps

from joints import compiled_path as CP
from joints.sim import rigs_exchange as R

ROUNDS = int(os.environ.get("ROUNDS", "8"))


def main() -> None:
    other = sys.argv[1]
    sizes = [int(a) for a in sys.argv[2:]] or [16, 256]
    o_r, o_cp = other_rigs(other)
    versions = {"this": (R.carry_rigs, CP.CompiledRigs._send), "other": (o_r.carry_rigs, o_cp.CompiledRigs._send)}
    print(f"load {os.getloadavg()[0]:.1f}; CPU time per rig step, best / median of {ROUNDS} blocks")
    for n in sizes:
        steps = max(32, 8192 // n)
        vec, rigs, actions = rigs_vec(n, steps)
        times: dict[str, list[float]] = {k: [] for k in versions}
        first: list[Any] | None = None
        for r in range(ROUNDS):
            for tag in (("this", "other") if r % 2 else ("other", "this")):
                carry, send = versions[tag]
                rigs._carry = carry
                CP.CompiledRigs._send = send  # type: ignore[method-assign]
                vec.reset(seed=0)
                before = rigs.taken
                seconds, got = timed_vec_steps(vec, actions)
                times[tag].append(seconds)
                assert rigs.taken - before >= steps, "the one call was not taken"
                first = same_as_first(first, got)
        vec.close()
        line = [f"N={n:4d}"]
        for tag in versions:
            v = np.array(times[tag]) * 1e6
            line.append(f"{tag} {v.min():6.1f} / {np.median(v):6.1f}")
        b, o = min(times["other"]), min(times["this"])
        line.append(f"us; this vs other {100 * (o - b) / b:+5.1f} % (best)")
        print("  ".join(line), flush=True)


if __name__ == "__main__":
    main()
