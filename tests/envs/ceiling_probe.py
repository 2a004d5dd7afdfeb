"""How far Python leaves an env from its ratio goal: the step split into its compiled calls and the rest.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/ceiling_probe.py [ID ...]``
(default ``joints/ErobReach-v0``) makes each env by ``gym.make`` (its defaults, gymnasium's wrappers included),
steps it with uniform random actions (seed 0) in ``BLOCKS`` identical blocks and times, in CPU seconds
(``time.thread_time``), the whole step and each call of the one-call exchange
(:func:`joints.sim.line_exchange.exchanges`, where the physics of a steady step runs), counting the substeps the
world ran. After each block it times raw ``mj_step`` on the same model (one Python call per substep, the bench's
reference) and prints per env step:

* the step (a reset at an episode's end not timed, as the bench times), and its compiled calls (frames, drive
  kernels and physics in one call each);
* the rest: Python, split into the one-call exchanges' own (``LinkLane.exchange`` of each joint's lane, less the
  compiled calls inside: the steady checks, rows, the state vector, the world's bring-back, the frames booked)
  and everything else (the joints' checks and states, the env's own step, gymnasium's wrappers);
* the ratio with no Python at all (the substeps' raw ``mj_step`` over the compiled calls): the ceiling;
* the Python a step may keep for a ratio goal (``GOAL``): the substeps' raw ``mj_step`` / goal less the calls.

Then, for an env whose steady step is one call of its eRobs' rows (``joints/ErobReach-v0``, ``ErobArmReach-v0``:
each joint's target and start, the hold, each joint's status read), the skeleton: a bound, not the library's
semantics. A second env of the id is stepped into its steady state, one steady compiled call is captured, and a bare
``gym.Env`` under gymnasium's wrappers (as ``gym.make`` puts them) replays it step after step in its own world: the
action checked and clipped, its targets set into the captured rows, the hold moved to the next tick, the one call,
the state read from its output rows, an observation array, a reward and an info dict. It keeps no check, counts,
frame log, firmware store or joint state: its Python is what a step whose every check and piece of bookkeeping lived
in compiled code would still spend, so its ratio is what such a design could reach on this machine.

``rigs:N`` as an ID: the bench's batched row of N rigs (``gym.make_vec("joints/ErobReach-v0", num_envs=N,
vectorization_mode="vector_entry_point")``, episodes unlimited) per rig step, its compiled call the batch's one
(:func:`joints.sim.rigs_exchange.rigs_exchanges`); then its skeleton: one steady call of the batch captured and
replayed, every rig's target, hold and state by array operations across the rigs, observations and rewards as
arrays.

Each block's raw reference is timed right after its steps; the best block (the highest ratio, the least
disturbed by load) and the median one. Gymnasium's ``Reacher-v5`` (no drive emulation) is timed
the same way for scale: its whole overhead is Python. Pin it to one core (``taskset -c 1``).
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from collections.abc import Callable
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
        stepping = 0.0
        t = time.thread_time()
        for a in actions:
            _, _, terminated, truncated, _ = env.step(a)
            if terminated or truncated:  # a reset is not timed (the bench's method), its compiled calls not counted
                stepping += time.thread_time() - t
                if calls is None:
                    env.reset()
                else:
                    kept = calls.seconds, calls.substeps, calls.lane_seconds
                    env.reset()
                    calls.seconds, calls.substeps, calls.lane_seconds = kept
                t = time.thread_time()
        step = (stepping + time.thread_time() - t) / PER_BLOCK
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
            split = f" (the exchanges' own {(lanes - calls) * 1e6:.0f} us, everything else " \
                    f"{(step - lanes) * 1e6:.0f} us)" if lanes else ""  # (the skeleton has no lanes)
            line += f"; compiled calls {calls * 1e6:.0f} us, the rest (Python) {(step - calls) * 1e6:.0f} us" \
                    f"{split}; ratio with no Python {physics / calls:.2f}; Python left for {GOAL}: " \
                    f"{(physics / GOAL - calls) * 1e6:.0f} us"
        else:
            line += f"; overhead (all Python) {(step - physics) * 1e6:.0f} us"
        print(line)
    spread = statistics.pstdev([b[0] for b in blocks]) / statistics.mean([b[0] for b in blocks])
    print(f"  ({BLOCKS} blocks, step time spread {spread:.0%})")


def _skeleton(env_id: str, calls: _Calls) -> Any:
    """The skeleton of ``env_id`` (see the module docstring) under gymnasium's wrappers, or None where its steady
    step is not one call of its eRobs' rows (each joint's target and start, the hold, each joint's read)."""
    from gymnasium.wrappers import OrderEnforcing, PassiveEnvChecker, TimeLimit

    from joints.sim import erob_exchange

    captured: list[tuple[Any, ...]] = []
    fn = calls.fn

    def capture(*args: Any) -> None:
        captured.append(args)
        fn(*args)

    line_exchange._COMPILED[0] = (capture, calls.advance)
    source = gym.make(env_id)
    try:
        source.reset(seed=0)
        source.action_space.seed(0)
        for _ in range(30):
            source.step(source.action_space.sample())
    finally:
        line_exchange._COMPILED[0] = (calls, calls.advance)
    if not captured:
        return None
    tx, out, st = (a.copy() for a in captured[-1][:3])
    w, rest = captured[-1][3], captured[-1][4:]
    kinds = tx[:, line_exchange.KIND].tolist()
    ops = tx[:, erob_exchange.OP].tolist()
    k = (len(kinds) - 1) // 3  # joints: k x (target, start), the hold, k x read
    if len(kinds) != 3 * k + 1 or kinds[2 * k] != line_exchange.HOLD or \
            ops[:2 * k] != [erob_exchange.TARGET_POSITION, erob_exchange.START] * k or \
            ops[2 * k + 1:] != [erob_exchange.READ] * k:
        return None
    u: Any = source.unwrapped
    period, at = u.control_period, erob_exchange.STATUS_AT
    scales = [1.0 / j.units.position for j in u.joints]
    low, high = u.observation_space.low.tolist(), u.observation_space.high.tolist()
    rest_of_row = [0.0] * (len(low) - 3 * k)

    class Skeleton(gym.Env):
        observation_space = u.observation_space
        action_space = u.action_space

        def __init__(self) -> None:
            self.tick = u.tick_time(0)
            self.prev = [0.0] * k
            self.model = u.rig.world.model  # (the reference's)
            self.source = source  # its world: the source env is not stepped again

        def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[Any, dict[str, Any]]:
            super().reset(seed=seed)
            return np.zeros(self.observation_space.shape, dtype=self.observation_space.dtype), {}

        def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
            values = []
            for i, v in enumerate(action.tolist()):
                if v - v != 0.0:
                    raise ValueError("action must be finite")
                v = v if -1.0 <= v <= 1.0 else (-1.0 if v < -1.0 else 1.0)
                values.append(v)
                tx[2 * i, erob_exchange.VALUE] = tx[2 * i + 1, erob_exchange.VALUE] = float(round(v * scales[i]))
            self.tick += period
            tx[2 * k, line_exchange.UNTIL] = self.tick
            calls(tx, out, st, w, *rest)
            o = out[2 * k + 1:].tolist()
            positions = [r[at] / c for r, c in zip(o, scales)]
            row = positions + [r[at + 1] / c for r, c in zip(o, scales)] + [r[at + 2] * 1e-3 for r in o] + rest_of_row
            obs = np.array([lo if x < lo else hi if x > hi else x  # noqa: FURB136 - as the env clamps
                            for x, lo, hi in zip(row, low, high)])
            change = sum((v - p) * (v - p) for v, p in zip(values, self.prev))
            self.prev = values
            reward = -sum(abs(x) for x in positions) - 0.01 * change
            info = {"time": st[line_exchange.CLOCK], "overrun": 0.0, "faults": dict.fromkeys(u.joint_names),
                    "limit_violation": False}
            return obs, reward, False, False, info

    assert source.spec is not None and source.spec.max_episode_steps is not None
    return PassiveEnvChecker(OrderEnforcing(TimeLimit(Skeleton(), source.spec.max_episode_steps)))


class _RigsCalls:
    """The batch's one compiled call (:func:`joints.sim.rigs_exchange.rigs_exchanges`), timed: CPU seconds and
    substeps (all rigs') of the calls since :meth:`clear`; :attr:`captured` the last call's arguments."""

    def __init__(self) -> None:
        from joints.sim import rigs_exchange

        self.fn = rigs_exchange.compiled()
        assert self.fn is not None, "the batch's call is not compiled (numba missing or JOINTS_COMPILED=0)"
        rigs_exchange._COMPILED[0] = self
        self.seconds = 0.0
        self.substeps = 0
        self.captured: tuple[Any, ...] = ()

    def __call__(self, *args: Any) -> None:
        ws, worlds = args[3], args[11]
        before = int(worlds[ws, STEPS].sum())
        self.captured = args
        t = time.thread_time()
        self.fn(*args)
        self.seconds += time.thread_time() - t
        self.substeps += int(worlds[ws, STEPS].sum()) - before

    def clear(self) -> None:
        self.seconds = 0.0
        self.substeps = 0


def _rigs_blocks(vec: Any, n: int, model: Any, calls: _RigsCalls, step: Callable[[Any], Any] | None = None
                 ) -> list[tuple[float, float, float, float, float]]:
    """:func:`_blocks` of a batch of ``n`` rigs, per rig step (``step``: instead of ``vec.step``), at least 1,200
    rig steps a block; the episodes unlimited (no resets)."""
    got = []
    rng = np.random.default_rng(0)
    steps = max(10, 4 * PER_BLOCK // n)
    for _ in range(BLOCKS):
        actions = rng.uniform(-1.0, 1.0, (steps, n, 1)).astype(np.float32)
        calls.clear()
        go = step or vec.step
        t = time.thread_time()
        for a in actions:
            go(a)
        rig_step = (time.thread_time() - t) / (steps * n)
        sub = calls.substeps / (steps * n)
        got.append((rig_step, calls.seconds / (steps * n), sub, raw_step(model, int(sub * PER_BLOCK)), 0.0))
    return got


def _rigs(n: int) -> None:
    """The batch of ``n`` rigs of ``joints/ErobReach-v0`` (the bench's batched rows) per rig step, then its skeleton:
    one steady call of the batch captured and replayed, every rig's target set, hold moved and state read by
    array operations across the rigs, under no wrapper (as the vector env is made), observations and rewards as
    arrays - what a batch step whose per-rig work lived in compiled code or in array operations could reach."""
    from joints.sim import erob_exchange as E

    calls = _RigsCalls()
    vec: Any = gym.make_vec("joints/ErobReach-v0", num_envs=n, vectorization_mode="vector_entry_point")
    vec.unwrapped.max_episode_steps = None
    vec.reset(seed=0)
    u: Any = vec.unwrapped
    one: Any = u.envs[0]
    model = one.rig.world.model
    _report(f"{n} rigs, per rig step", _rigs_blocks(vec, n, model, calls), compiled=True)
    tx, out, st = (a.copy() for a in calls.captured[:3])
    rest = calls.captured[3:]
    starts = rest[1][:n + 1].copy()
    first = starts[:-1]
    if not (np.diff(starts) == 4).all() or not (tx[first + 2, line_exchange.KIND] == line_exchange.HOLD).all() or \
            not (tx[first, E.OP] == E.TARGET_POSITION).all() or not (tx[first + 3, E.OP] == E.READ).all():
        print(f"{n} rigs: no skeleton (a rig's steady step is not one eRob's four rows)")
        return
    period, scale, at = one.control_period, 1.0 / one.joints[0].units.position, E.STATUS_AT
    low, high = u.single_observation_space.low, u.single_observation_space.high
    width = len(low)

    def step(actions: Any) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        a = np.asarray(actions, dtype=np.float64)[:, 0]
        if not np.isfinite(a).all():
            raise ValueError("actions must be finite")
        a = np.clip(a, -1.0, 1.0)
        targets = np.round(a * scale)
        tx[first, E.VALUE] = targets
        tx[first + 1, E.VALUE] = targets
        tx[first + 2, line_exchange.UNTIL] += period
        calls(tx, out, st, *rest)
        o = out[first + 3]
        obs = np.zeros((n, width))
        obs[:, 0] = o[:, at] / scale
        obs[:, 1] = o[:, at + 1] / scale
        obs[:, 2] = o[:, at + 2] * 1e-3
        np.clip(obs, low, high, out=obs)
        reward = -np.abs(obs[:, 0]) - 0.01 * a * a
        done = np.zeros(n, dtype=bool)
        return obs, reward, done, done, {}

    _report(f"{n} rigs skeleton, per rig step", _rigs_blocks(vec, n, model, calls, step), compiled=True)
    vec.close()


def main(ids: list[str]) -> None:
    calls = _Calls()
    for env_id in ids:
        if env_id.startswith("rigs:"):
            _rigs(int(env_id[5:]))
            continue
        env = gym.make(env_id)
        env.reset(seed=0)
        calls.lanes(env)
        u: Any = env.unwrapped
        _report(env_id, _blocks(env, u.rig.world.model, calls), compiled=True)
        env.close()
        skeleton = _skeleton(env_id, calls)
        if skeleton is None:
            print(f"{env_id}: no skeleton (its steady step is not one call of its eRobs' target, start, hold and "
                  "read rows)")
            continue
        _report(f"{env_id} skeleton", _blocks(skeleton, skeleton.unwrapped.model, calls), compiled=True)
    ref = gym.make("Reacher-v5")
    reacher: Any = ref.unwrapped
    _report("Reacher-v5", _blocks(ref, reacher.model, None), compiled=False)
    ref.close()
    print(f"load {' '.join(f'{x:.2f}' for x in os.getloadavg())}, numpy {np.__version__}")


if __name__ == "__main__":
    main(sys.argv[1:] or ["joints/ErobReach-v0"])
