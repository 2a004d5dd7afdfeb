"""What the garbage collector costs a run of ``joints/ErobReach-v0`` rigs, and what the lines' frame logs hold.

Not a test (pytest does not collect it): a measuring tool.
``python tests/envs/gc_probe.py RIGS STEPS [WARM]`` builds RIGS rigs (1: ``gym.make``; more: the batched env,
``gym.make_vec(..., vectorization_mode="vector_entry_point")``, as the bench does), steps them WARM steps, then
STEPS steps timed in CPU time (``time.process_time``) with every collection timed by ``gc.callbacks``, and prints:
the CPU time per rig step, the collectors' share of it per generation, the passes, what they collected; the
frames in the simulated lines' logs per rig, the bytes those logs hold per rig (``sys.getsizeof`` of every
object reachable from the log entries, each counted once), and the process's RSS growth per rig.
``GC_PROBE_ENV``: another env id; ``GC_PROBE_CAN=1``: the bench's CAN row of it (one rig); ``GC_PROBE_LOG_KEEP``:
another :data:`~joints.transports.serial_sim.LOG_KEEP` for the run; ``GC_PROBE_DROP_PAYLOADS=1``: booked frames
logged without their replies (not the library's behaviour: what the GC costs when the log holds no reply at all). Pin it to one core (``taskset -c 1``);
compare two checkouts by running each, alternating, with ``PYTHONPATH``. "frames per rig step" is the log's
growth: right only while no trim fell in the timed steps.
"""

from __future__ import annotations

import gc
import os
import sys
import time
from typing import Any

import numpy as np

ENV_ID = "envs:joints/ErobReach-v0"


def _rss() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _log_bytes(lines: list[Any]) -> int:
    """Bytes of everything reachable from the lines' log entries (each object once; classes and modules not)."""
    seen: set[int] = set()
    total = 0
    stack: list[Any] = [e for line in lines for e in (*line._log, *getattr(line, "_replies", ()))]  # booked replies
    total += sum(sys.getsizeof(line._log) + sys.getsizeof(getattr(line, "_replies", ())) + sys.getsizeof(line._latest_end)
                 + 24 * len(line._latest_end) for line in lines)
    while stack:
        o = stack.pop()
        if id(o) in seen or isinstance(o, (type, type(sys))) or callable(o):
            continue
        seen.add(id(o))
        total += sys.getsizeof(o)
        if isinstance(o, (tuple, list)):
            stack.extend(o)
        elif hasattr(o, "__slots__"):
            stack.extend(getattr(o, s) for s in getattr(type(o), "__slots__", ()) if hasattr(o, s))
        elif hasattr(o, "__dict__"):
            stack.extend(vars(o).values())
    return total


def main() -> None:
    import gymnasium as gym

    from joints.transports import serial_sim
    from joints.transports.serial_sim import TimedSerialLine

    if os.environ.get("GC_PROBE_LOG_KEEP"):  # another LOG_KEEP for this run (what a smaller log would cost)
        serial_sim.LOG_KEEP = int(os.environ["GC_PROBE_LOG_KEEP"])
    rigs, steps = int(sys.argv[1]), int(sys.argv[2])
    warm = int(sys.argv[3]) if len(sys.argv) > 3 else 100
    rss0 = _rss()
    if os.environ.get("GC_PROBE_DROP_PAYLOADS"):  # not the library's behaviour: the GC if the log held no reply
        book = TimedSerialLine.book_frames

        def bare(line: TimedSerialLine, frames: list[tuple[float, float, float, int, str, Any]]) -> None:
            book(line, [(*f[:5], None) for f in frames])

        TimedSerialLine.book_frames = bare  # type: ignore[method-assign, assignment]
    env_id = os.environ.get("GC_PROBE_ENV", ENV_ID)
    if os.environ.get("GC_PROBE_CAN"):  # the bench's CAN row of that env (its config on CAN at 1 Mbit/s, 50 Hz)
        from joints import bench

        found = bench._baseline_config(env_id.split(":")[-1])
        assert found is not None and rigs == 1, "a CAN row: one rig of an env the bench has a CAN row of"
        env: Any = gym.make(env_id, config=found[0], control_period=bench.BASELINE_PERIOD)
        print(f"on {found[1]}")
    elif rigs == 1:
        env = gym.make(env_id)
    else:
        env = gym.make_vec(env_id, num_envs=rigs, vectorization_mode="vector_entry_point")
    env.action_space.seed(0)
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
    for _ in range(warm):
        env.step(action)
    lines = [o for o in gc.get_objects() if isinstance(o, TimedSerialLine)]
    frames0 = sum(len(line._log) for line in lines)
    rss1 = _rss()
    spent = [0.0, 0.0, 0.0]
    passes = [0, 0, 0]
    collected = [0]
    started = [0.0]

    def timed(phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            started[0] = time.process_time()
        else:
            g = info["generation"]
            spent[g] += time.process_time() - started[0]
            passes[g] += 1
            collected[0] += info["collected"]

    tracked0 = len(gc.get_objects())
    gc.callbacks.append(timed)
    t0 = time.process_time()
    for _ in range(steps):
        env.step(action)
    total = time.process_time() - t0
    gc.callbacks.remove(timed)
    tracked1 = len(gc.get_objects())
    rss2 = _rss()
    frames1 = sum(len(line._log) for line in lines)
    n = steps * rigs
    us = [s / n * 1e6 for s in spent]
    print(f"load {os.getloadavg()[0]:.1f}  LOG_KEEP {serial_sim.LOG_KEEP}  {rigs} rigs x {steps} steps (after {warm})  "
          f"{len(lines)} lines")
    print(f"  CPU per rig step {total / n * 1e6:7.1f} us; gc gen0 {us[0]:.2f}, gen1 {us[1]:.2f}, gen2 {us[2]:.2f} us "
          f"= {sum(us):.2f} us ({sum(spent) / total:.1%}); passes {passes}, collected {collected[0]}")
    print(f"  frames per rig step {(frames1 - frames0) / n:.2f} (the log's growth); log frames per rig now "
          f"{frames1 / rigs:,.0f}; log bytes per rig {_log_bytes(lines) / rigs / 1e6:.2f} MB "
          f"({_log_bytes(lines) / max(frames1, 1):.0f} B per frame)")
    print(f"  tracked objects {tracked0:,} -> {tracked1:,} ({(tracked1 - tracked0) / rigs:+,.0f} per rig); "
          f"RSS from before the env {(rss2 - rss0) / rigs / 1e6:.2f} MB per rig "
          f"(over the timed steps {(rss2 - rss1) / rigs / 1e6:+.2f})")
    env.close()


if __name__ == "__main__":
    main()
