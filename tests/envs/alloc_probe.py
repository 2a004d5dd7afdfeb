"""What the garbage collector does inside a batched step: passes, tracked allocations and their sites.

Not a test (pytest does not collect it): a measuring tool.
``python tests/envs/alloc_probe.py RIGS STEPS [WARM] [ROUNDS]`` builds RIGS rigs of ``joints/ErobReach-v0`` (the
batched env, as the bench makes it), steps them WARM steps with uniform random actions, then:

1. ROUNDS rounds of STEPS steps each, alternating the collector on and ``gc.disable()`` (this probe's own
   process-wide state, never a library's), CPU time per rig step (``time.process_time``) and, with it on, the passes
   per generation (``gc.callbacks``) and their timed cost;
2. with the collector off: the tracked objects a step leaves behind (``gc.get_count()[0]``'s growth: the net
   allocations of GC-tracked containers, what a young pass counts) by type (``gc.get_objects(0)``), and by
   allocation site (``tracemalloc``, the lines whose net allocated blocks grew over a step).

Pin it to one core (``taskset -c 1``); compare checkouts by running each with ``PYTHONPATH``.
"""

from __future__ import annotations

import collections
import gc
import os
import statistics
import sys
import time
import tracemalloc
from typing import Any

import numpy as np

ENV_ID = "envs:joints/ErobReach-v0"


def main() -> None:
    import gymnasium as gym

    rigs, steps = int(sys.argv[1]), int(sys.argv[2])
    warm = int(sys.argv[3]) if len(sys.argv) > 3 else 200
    rounds = int(sys.argv[4]) if len(sys.argv) > 4 else 6
    env: Any = gym.make_vec(os.environ.get("ALLOC_PROBE_ENV", ENV_ID), num_envs=rigs,
                            vectorization_mode="vector_entry_point")
    env.action_space.seed(0)
    env.reset(seed=0)
    actions = [env.action_space.sample() for _ in range(64)]
    for i in range(warm):
        env.step(actions[i % 64])
    if os.environ.get("ALLOC_PROBE_FREEZE"):  # a user's choice, not a library's: the built envs out of every pass
        gc.collect()
        gc.freeze()
    if os.environ.get("ALLOC_PROBE_THRESHOLD"):  # a user's choice: another young threshold (e.g. 10000)
        gc.set_threshold(int(os.environ["ALLOC_PROBE_THRESHOLD"]), *gc.get_threshold()[1:])
    print(f"freeze {bool(os.environ.get('ALLOC_PROBE_FREEZE'))} ({gc.get_freeze_count():,} objects)  "
          f"load {os.getloadavg()[0]:.1f}  {rigs} rigs, {rounds} rounds of {steps} steps (after {warm})  "
          f"thresholds {gc.get_threshold()}")

    # 1. collector on / off, alternated
    passes = [0, 0, 0]
    spent = [0.0, 0.0, 0.0]
    started = [0.0]

    def timed(phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            started[0] = time.process_time()
        else:
            spent[info["generation"]] += time.process_time() - started[0]
            passes[info["generation"]] += 1

    on: list[float] = []
    off: list[float] = []
    n = steps * rigs
    k = 0
    for r in range(rounds):
        for mode in ("on", "off") if r % 2 == 0 else ("off", "on"):
            if mode == "off":
                gc.disable()
            else:
                gc.callbacks.append(timed)
            t0 = time.process_time()
            for _ in range(steps):
                env.step(actions[k % 64])
                k += 1
            t = (time.process_time() - t0) / n * 1e6
            if mode == "off":
                gc.enable()
                off.append(t)
            else:
                gc.callbacks.remove(timed)
                on.append(t)
    nr = rounds * n
    print(f"  CPU per rig step: collector on {min(on):.1f} best / {statistics.median(on):.1f} median, "
          f"off {min(off):.1f} / {statistics.median(off):.1f} us; on - off (median) "
          f"{statistics.median(on) - statistics.median(off):+.1f} us")
    print(f"  passes per 1000 rig steps (collector on): gen0 {passes[0] / nr * 1e3:.2f}, gen1 {passes[1] / nr * 1e3:.3f}, "
          f"gen2 {passes[2] / nr * 1e3:.4f}; timed per rig step gen0 {spent[0] / nr * 1e6:.2f}, "
          f"gen1 {spent[1] / nr * 1e6:.2f}, gen2 {spent[2] / nr * 1e6:.2f} us")

    if os.environ.get("ALLOC_PROBE_WHO"):  # what the young generations hold when a gen-1 pass starts (promoted)
        held: collections.Counter[str] = collections.Counter()
        where: collections.Counter[str] = collections.Counter()
        seen = [0]

        def who(phase: str, info: dict[str, Any]) -> None:
            if phase == "start" and info["generation"] == 1:
                seen[0] += 1
                objs = gc.get_objects(0) + gc.get_objects(1)
                held.update(type(o).__qualname__ for o in objs if gc.is_tracked(o))
                f = sys._getframe(1)
                where.update([f"{os.path.relpath(f.f_code.co_filename)}:{f.f_code.co_name}"])

        gc.callbacks.append(who)
        for _ in range(steps * 2):
            env.step(actions[k % 64])
            k += 1
        gc.callbacks.remove(who)
        print(f"  held by generations 0+1 at a gen-1 pass (mean of {seen[0]}): " + ", ".join(
            f"{name} {c / max(seen[0], 1):.0f}" for name, c in held.most_common(14)))
        print(f"  interrupted: {dict(where.most_common(6))}")

    # 2. tracked allocations that a step leaves (collector off; net of the step's own frees)
    gc.collect()
    gc.disable()
    grow = []
    for _ in range(20):
        c0 = gc.get_count()[0]
        env.step(actions[k % 64])
        k += 1
        grow.append(gc.get_count()[0] - c0)
    print(f"  net tracked allocations per rig step (gen-0 count growth): {statistics.median(grow) / rigs:.1f} "
          f"(median of 20 steps; per step {statistics.median(grow)})")
    gc.collect()
    env.step(actions[k % 64])
    k += 1
    kinds = collections.Counter(type(o).__qualname__ for o in gc.get_objects(0))
    print("  left by one step, by type (per rig): " + ", ".join(
        f"{name} {c / rigs:.1f}" for name, c in kinds.most_common(12)))
    tracemalloc.start(1)
    for _ in range(3):
        env.step(actions[k % 64])
        k += 1
    s0 = tracemalloc.take_snapshot()
    for _ in range(5):
        env.step(actions[k % 64])
        k += 1
    s1 = tracemalloc.take_snapshot()
    tracemalloc.stop()
    print("  allocation sites whose blocks grew over 5 steps (blocks per rig step; all allocations, tracked or not):")
    for d in s1.compare_to(s0, "lineno")[:18]:
        if d.count_diff <= 0:
            continue
        fr = d.traceback[0]
        print(f"    {d.count_diff / 5 / rigs:6.2f}  {os.path.relpath(fr.filename)}:{fr.lineno}")
    gc.enable()
    env.close()


if __name__ == "__main__":
    np.set_printoptions(precision=3)
    main()
