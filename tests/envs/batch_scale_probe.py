"""How a batch's cost per rig scales with its size: the bench's batched row for N = 1, 4, 16, 64, 256 rigs.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/batch_scale_probe.py [N ...]`` runs
:func:`joints.bench.batched_row` (``gym.make_vec("joints/ErobReach-v0", num_envs=N,
vectorization_mode="vector_entry_point")``, the bench's method: 2000 rig steps per block, best of 5, against raw
``mj_step`` of N models timed interleaved) for each N and prints the ratio to raw ``mj_step`` and the overhead per
rig step. Pin it to one core (``taskset -c 1``); compare two checkouts by running each, alternating, with
``PYTHONPATH`` set to the checkout.
"""

from __future__ import annotations

import os
import sys

from joints import bench

SIZES = (1, 4, 16, 64, 256)


def main() -> None:
    sizes = [int(a) for a in sys.argv[1:]] or list(SIZES)
    print(f"load {os.getloadavg()[0]:.1f}")
    for n in sizes:
        ratio, overhead = list(bench.batched_row(steps=2000, raw_steps=20000, repeats=5, rigs=n))
        print(f"N={n:4d}  ratio {ratio.ratio:.3f}  overhead per rig step {overhead.ratio:6.1f} us  ({overhead.detail})")


if __name__ == "__main__":
    main()
