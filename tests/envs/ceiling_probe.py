"""How far Python leaves an env from its ratio goal: the step split into its compiled calls and the rest.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/ceiling_probe.py [ID ...]``
(default ``joints/ErobReach-v0``) makes each env by ``gym.make`` (its defaults, gymnasium's wrappers included),
steps it with uniform random actions (seed 0) in ``BLOCKS`` identical blocks and times, in CPU seconds
(``time.thread_time``), the whole step and each call of the one-call exchange
(:func:`joints.sim.line_exchange.exchanges`, where the physics of a steady step runs), counting the substeps the
world ran. After each block it times raw ``mj_step`` on the same model (one Python call per substep, the bench's
reference) and prints per env step:

* the step, and its compiled calls (frames, drive kernels and physics in one call each);
* the rest: Python, split into the one-call exchanges' own (``LinkLane.exchange`` of each joint's lane, less the
  compiled calls inside: the steady checks, rows, the state vector, the world's bring-back, the frames booked)
  and everything else (the joints' checks and states, the env's own step, gymnasium's wrappers);
* the ratio with no Python at all (the substeps' raw ``mj_step`` over the compiled calls): the ceiling;
* the Python a step may keep for a ratio goal (``GOAL``): the substeps' raw ``mj_step`` / goal less the calls.

Each block's raw reference is timed right after its steps; the best block (the highest ratio, the least
disturbed by load) and the median one. Gymnasium's ``Reacher-v5`` (no drive emulation) is timed
the same way for scale: its whole overhead is Python. Pin it to one core (``taskset -c 1``).
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from typing import Any

import gymnasium as gym
import numpy as np

import envs  # noqa: F401 - registers the joints envs
from joints.sim import line_exchange
from joints.sim.stepping import STEPS

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from probekit import raw_step

BLOCKS = 7
PER_BLOCK = 300
GOAL = 0.6


class _Calls:
    """The one-call exchange, timed: CPU seconds and substeps of the calls since :meth:`clear`, and CPU seconds in
    the lanes' ``exchange`` (:meth:`lanes`) around them."""

    def __init__(self) -> None:
        self.fn, self.advance = line_exchange.compiled()
        assert self.fn is not None, "the one-call exchange is not compiled (numba missing or JOINTS_COMPILED=0)"
        self.seconds = 0.0
        self.substeps = 0
        self.lane_seconds = 0.0
        line_exchange._COMPILED[0] = (self, self.advance)

    def lanes(self, env: Any) -> None:
        """Time ``exchange`` of every lane of ``env``'s compiled path (an instance attribute over the method)."""
        path = getattr(env.unwrapped, "compiled_path", None)
        lanes = {id(s.lane): s.lane for s in (path._steppers if path is not None else []) if hasattr(s, "lane")}
        for lane in lanes.values():
            lane.exchange = self._timed(lane.exchange)

    def _timed(self, exchange: Any) -> Any:
        def timed(*args: Any, **kwargs: Any) -> Any:
            t = time.thread_time()
            try:
                return exchange(*args, **kwargs)
            finally:
                self.lane_seconds += time.thread_time() - t
        return timed

    def __call__(self, tx: Any, out: Any, st: Any, w: int, *rest: Any) -> None:
        worlds = rest[5]
        before = worlds[w, STEPS]
        t = time.thread_time()
        self.fn(tx, out, st, w, *rest)
        self.seconds += time.thread_time() - t
        self.substeps += int(worlds[w, STEPS] - before)

    def clear(self) -> None:
        self.seconds = 0.0
        self.substeps = 0
        self.lane_seconds = 0.0


def _blocks(env: Any, model: Any, calls: _Calls | None) -> list[tuple[float, float, float, float, float]]:
    """Per block: (step, compiled calls, substeps, raw ``mj_step``, lanes' exchanges) per env step, the raw
    reference timed right after the block's steps (as many substeps), so that both see the same load; the same
    seeded actions each block."""
    got = []
    for _ in range(BLOCKS):
        env.reset(seed=0)
        env.action_space.seed(0)
        actions = [env.action_space.sample() for _ in range(PER_BLOCK)]
        if calls is not None:
            calls.clear()
        t = time.thread_time()
        for a in actions:
            _, _, terminated, truncated, _ = env.step(a)
            if terminated or truncated:
                env.reset()
        step = (time.thread_time() - t) / PER_BLOCK
        if calls is None:
            sub, spent, lanes = float(env.unwrapped.frame_skip), 0.0, 0.0
        else:
            sub, spent, lanes = calls.substeps / PER_BLOCK, calls.seconds / PER_BLOCK, calls.lane_seconds / PER_BLOCK
        got.append((step, spent, sub, raw_step(model, int(sub * PER_BLOCK)), lanes))
    return got


def _report(name: str, blocks: list[tuple[float, float, float, float, float]], compiled: bool) -> None:
    """The best block (the highest ratio) and the median one."""
    ranked = sorted(blocks, key=lambda b: b[2] * b[3] / b[0], reverse=True)
    for label, (step, calls, sub, raw, lanes) in (("best", ranked[0]), ("median", ranked[len(ranked) // 2])):
        physics = sub * raw
        line = f"{name} [{label}]: step {step * 1e6:.0f} us, {sub:.2f} substeps x raw {raw * 1e6:.2f} us = " \
               f"{physics * 1e6:.0f} us, ratio {physics / step:.2f}"
        if compiled:
            line += f"; compiled calls {calls * 1e6:.0f} us, the rest (Python) {(step - calls) * 1e6:.0f} us " \
                    f"(the exchanges' own {(lanes - calls) * 1e6:.0f} us, everything else " \
                    f"{(step - lanes) * 1e6:.0f} us); ratio with no Python {physics / calls:.2f}; Python left " \
                    f"for {GOAL}: {(physics / GOAL - calls) * 1e6:.0f} us"
        else:
            line += f"; overhead (all Python) {(step - physics) * 1e6:.0f} us"
        print(line)
    spread = statistics.pstdev([b[0] for b in blocks]) / statistics.mean([b[0] for b in blocks])
    print(f"  ({BLOCKS} blocks of {PER_BLOCK} steps, step time spread {spread:.0%})")


def main(ids: list[str]) -> None:
    calls = _Calls()
    for env_id in ids:
        env = gym.make(env_id)
        env.reset(seed=0)
        calls.lanes(env)
        u: Any = env.unwrapped
        _report(env_id, _blocks(env, u.rig.world.model, calls), compiled=True)
        env.close()
    ref = gym.make("Reacher-v5")
    reacher: Any = ref.unwrapped
    _report("Reacher-v5", _blocks(ref, reacher.model, None), compiled=False)
    ref.close()
    print(f"load {' '.join(f'{x:.2f}' for x in os.getloadavg())}, numpy {np.__version__}")


if __name__ == "__main__":
    main(sys.argv[1:] or ["joints/ErobReach-v0"])
