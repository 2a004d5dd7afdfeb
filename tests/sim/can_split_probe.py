"""Why the bench's eRob CAN row (``joints/ErobReach-v0`` at 20 ms on eRob CAN at 1 Mbit/s) reads lower than its
Modbus row (the shipped 25 Hz on RS485): both envs' steps split into their compiled calls and Python, and the CAN
env at twice the period (40 substeps a step, as many as the Modbus row's) for scale.

Not a test (pytest does not collect it): a measuring tool. ``python tests/sim/can_split_probe.py`` makes the envs
as ``joints bench`` makes them (:func:`joints.bench._baseline_config` for the CAN row, its control period
:data:`joints.bench.BASELINE_PERIOD`), steps each with the same seeded uniform actions in ``BLOCKS`` blocks of
``STEPS`` steps, the envs' blocks alternated, and times (``time.thread_time``) per env step: the whole step,
the compiled calls (each family's compiled ``exchanges``, wrapped), the substeps the world ran (``world.steps``;
the resets' substeps and calls left out) and, right after each block, raw ``mj_step`` on the same model for as
many substeps (the bench's reference). Prints the best and the median block of each env: step, substeps,
compiled calls, Python (the rest), the overhead (step less substeps x raw), the ratio, and the overhead and the
Python a ratio of ``GOAL`` allows; then the Python function calls per step (``sys.setprofile`` over one more
block: Python functions called, C functions called from Python, the most called). Pin it (``taskset -c 1``).
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from collections import Counter
from typing import Any

import gymnasium as gym
import numpy as np

import envs  # noqa: F401 - registers the joints envs
from joints.bench import BASELINE_PERIOD, _baseline_config
from joints.sim import can_exchange, line_exchange

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from probekit import raw_step

BLOCKS = int(os.environ.get("BLOCKS", "7"))
STEPS = int(os.environ.get("STEPS", "300"))
MODE = os.environ.get("MODE", "position")
GOAL = 0.6


class _Timed:
    """A compiled ``exchanges`` wrapped: CPU seconds and calls since :meth:`clear`."""

    def __init__(self, fn: Any) -> None:
        self.fn = fn
        self.seconds = 0.0
        self.calls = 0

    def __call__(self, *args: Any) -> None:
        t = time.thread_time()
        self.fn(*args)
        self.seconds += time.thread_time() - t
        self.calls += 1

    def clear(self) -> None:
        self.seconds = 0.0
        self.calls = 0


def _wrap() -> list[_Timed]:
    """Both families' compiled calls timed (the Modbus one: ``line_exchange``'s; the CAN one: ``can_exchange``'s)."""
    fn, advance = line_exchange.compiled()
    line = _Timed(fn)
    line_exchange._COMPILED[0] = (line, advance)
    can_exchange._compiled()
    can = _Timed(can_exchange._COMPILED[0])
    can_exchange._COMPILED[0] = can
    return [line, can]


def _block(env: Any, actions: Any, timers: list[_Timed]) -> tuple[float, float, float, float, float]:
    """(step, compiled calls, substeps, raw mj_step, calls) per env step of one block."""
    u = env.unwrapped
    env.reset(seed=7)
    world = u.rig.sim
    for t in timers:
        t.clear()
    total = 0.0
    substeps = 0
    clock = time.thread_time
    for a in actions:
        s0 = int(world.steps)
        t0 = clock()
        _o, _r, term, trunc, _i = env.step(a)
        total += clock() - t0
        substeps += int(world.steps) - s0
        if term or trunc:  # (a reset's calls are not the steps')
            kept = [(t.seconds, t.calls) for t in timers]
            env.reset()
            for t, (seconds, calls) in zip(timers, kept):
                t.seconds, t.calls = seconds, calls
    step = total / len(actions)
    sub = substeps / len(actions)
    spent = sum(t.seconds for t in timers) / len(actions)
    calls = sum(t.calls for t in timers) / len(actions)
    return step, spent, sub, raw_step(u.rig.world.model, int(sub * len(actions))), calls


def _profile(env: Any, actions: Any) -> tuple[float, float, Counter[str]]:
    """Python function calls and C calls per env step over ``actions`` (resets left out), the top Python ones."""
    counts = [0, 0]
    names: Counter[str] = Counter()

    def prof(frame: Any, event: str, arg: Any) -> None:
        if event == "call":
            counts[0] += 1
            names[f"{frame.f_code.co_filename.rsplit('/', 2)[-1]}:{frame.f_code.co_name}"] += 1
        elif event == "c_call":
            counts[1] += 1

    env.reset(seed=7)
    n = 0
    for a in actions:
        sys.setprofile(prof)
        _o, _r, term, trunc, _i = env.step(a)
        sys.setprofile(None)
        n += 1
        if term or trunc:
            env.reset()
    return counts[0] / n, counts[1] / n, names


def main() -> None:
    timers = _wrap()
    cfg = _baseline_config("joints/ErobReach-v0")
    assert cfg is not None and cfg[1].startswith("erob-can"), cfg
    made = {"modbus (shipped, 25 Hz)": gym.make("joints/ErobReach-v0", action_mode=MODE),
            "erob-can (20 ms)": gym.make("joints/ErobReach-v0", config=cfg[0], control_period=BASELINE_PERIOD,
                                         action_mode=MODE),
            "erob-can (40 ms)": gym.make("joints/ErobReach-v0", config=cfg[0], control_period=2 * BASELINE_PERIOD,
                                         action_mode=MODE)}
    rng = np.random.default_rng(11)
    blocks: dict[str, list[tuple[float, float, float, float, float]]] = {k: [] for k in made}
    acts = {}
    for name, env in made.items():
        space = env.action_space
        acts[name] = [rng.uniform(space.low, space.high).astype(space.dtype) for _ in range(STEPS)]
        _block(env, acts[name][:50], timers)  # warm
    for _ in range(BLOCKS):
        for name, env in made.items():
            blocks[name].append(_block(env, acts[name], timers))
    for name, got in blocks.items():
        ranked = sorted(got, key=lambda b: b[2] * b[3] / b[0], reverse=True)
        for label, (step, calls, sub, raw, n) in (("best", ranked[0]), ("median", ranked[len(ranked) // 2])):
            physics = sub * raw
            print(f"{name} [{label}]: step {step * 1e6:.1f} us = compiled {calls * 1e6:.1f} ({n:.2f} calls) + "
                  f"Python {(step - calls) * 1e6:.1f}; {sub:.2f} substeps x raw {raw * 1e6:.2f} us = "
                  f"{physics * 1e6:.1f} us; compiled beyond raw physics {(calls - physics) * 1e6:.1f} us; "
                  f"overhead {(step - physics) * 1e6:.1f} us; ratio {physics / step:.3f}; overhead allowed for "
                  f"{GOAL}: {(physics / GOAL - physics) * 1e6:.1f} us, Python {(physics / GOAL - calls) * 1e6:.1f} us")
        print(f"  spread of the step {statistics.pstdev([b[0] for b in got]) / statistics.mean([b[0] for b in got]):.0%}")
    for name, env in made.items():
        py, c, names = _profile(env, acts[name])
        top = ", ".join(f"{k} {v / STEPS:.1f}" for k, v in names.most_common(12))
        print(f"{name}: {py:.1f} Python calls + {c:.1f} C calls per step; top: {top}")
    print(f"load {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
