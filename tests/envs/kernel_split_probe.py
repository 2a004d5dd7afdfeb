"""Where a steady ErobReach step's compiled call goes: the physics against the drive emulation and the plumbing.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/kernel_split_probe.py [ROUNDS]``
steps ``joints/ErobReach-v0`` (``gym.make`` defaults, seeded actions) into its steady state, captures one steady
step's compiled call (:func:`joints.sim.line_exchange.exchanges`: its rows, state vector, table and the world's
``MjData``) and replays it, each replay from the same saved state (``MjData``, drive table, state vector, step
count restored outside the timed part), alternating these variants in CPU time (``time.thread_time``):

* ``call``: the whole compiled call, as the step makes it (frames, the drive's acts, its substeps);
* ``run``: the same substeps by :func:`joints.sim.stepping._run` (drive loops and physics, no line arithmetic);
* ``mj(numba)``: as many ``mj_step`` calls from a compiled loop by the C address (no drive, no plumbing);
* ``mj(python)``: as many ``mj_step`` calls from Python (the bench's reference);
* ``drive``: the substeps' drive loops alone (``_run`` with physics off: the joint does not move);
* ``call(null)``: the whole call with ``mj_checkPos`` in ``mj_step``'s place (everything but the physics, warm);
* ``dispatch``: ``_run`` of no substep (the call from Python: its arguments' checks);
* ``drive x100``: the drive loops of 100 times as many substeps (their warm cost per substep).

Each variant's best and median per call. ``--in-step [STEPS]`` measures inside the env's own steps instead
(:class:`_InStep`): the call, the call without physics and the physics alone, each right after the step's Python.
Pin it to one core (``taskset -c 1``).
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

import envs  # noqa: F401 - registers the joints envs
from joints.sim import kernel, line_exchange, stepping
from joints.sim.stepping import STEPS


def _null_physics() -> int:
    """The address of MuJoCo's ``mj_checkPos(m, d)`` (next to nothing for one joint): a call with it in
    ``mj_step``'s place runs everything but the physics."""
    import ctypes
    import glob

    lib = ctypes.CDLL(min(glob.glob(os.path.join(os.path.dirname(mujoco.__file__), "libmujoco.so*"))))
    return int(ctypes.cast(lib.mj_checkPos, ctypes.c_void_p).value or 0)


def _mj_loop(n: int, fn: int, m: int, d: int) -> None:
    for _ in range(n):
        kernel.call(fn, m, d)


_mj_loop_compiled = kernel.numba.njit(_mj_loop)


class _Capture:
    """Wraps the compiled ``exchanges``: keeps copies of the arguments of the call made while ``armed``."""

    def __init__(self) -> None:
        self.fn, self.advance = line_exchange.compiled()
        self.armed = False
        self.args: Any = None
        self.steps = 0
        line_exchange._COMPILED[0] = (self, self.advance)

    def __call__(self, *args: Any) -> None:
        if self.armed:
            self.args = [a.copy() if isinstance(a, np.ndarray) else a for a in args]
            self.live = args
            w, worlds = args[3], args[9]
            before = int(worlds[w, STEPS])
            self.fn(*args)
            self.steps = int(worlds[w, STEPS]) - before
            self.armed = False
            return
        self.fn(*args)


class _InStep:
    """Wraps the compiled ``exchanges`` in the env's own steps: by turns, right before the step's call (in the cold
    state the step's Python leaves), times (0) the call itself, (1) the call on copies with ``mj_checkPos`` in
    ``mj_step``'s place (everything but the physics; the world's ``ctrl`` put back), (2) as many ``mj_step`` calls
    from a compiled loop on a spare ``MjData`` copied after the previous call (the physics alone, cold)."""

    def __init__(self, model: Any, data: Any) -> None:
        self.fn, self.advance = line_exchange.compiled()
        line_exchange._COMPILED[0] = (self, self.advance)
        self.model, self.data = model, data
        self.spare = mujoco.MjData(model)
        self.null = _null_physics()
        self.turn = 0
        self.n = 40
        self.got: list[list[float]] = [[], [], []]
        self.on = False

    def __call__(self, *args: Any) -> None:
        tx, out, st, w, mj_step, table, adr, ratio, order, worlds, dts, active = args
        turn = self.turn % 3
        self.turn += 1
        if self.on and turn == 1:
            ctrl = self.data.ctrl.copy()
            a = (tx.copy(), out.copy(), st.copy(), w, self.null, table.copy(), adr, ratio, order, worlds.copy(), dts,
                 active)
            t = time.thread_time()
            self.fn(*a)
            self.got[1].append(time.thread_time() - t)
            self.data.ctrl[:] = ctrl
        elif self.on and turn == 2:
            t = time.thread_time()
            _mj_loop_compiled(self.n, mj_step, self.model._address, self.spare._address)
            self.got[2].append(time.thread_time() - t)
        before = int(worlds[w, STEPS])
        t = time.thread_time()
        self.fn(*args)
        spent = time.thread_time() - t
        if self.on and turn == 0 and int(worlds[w, STEPS]) - before == self.n:
            self.got[0].append(spent)
        mujoco.mj_copyData(self.spare, self.model, self.data)


def in_step(steps: int) -> None:
    """The split measured inside the env's steps (:class:`_InStep`)."""
    env = gym.make("joints/ErobReach-v0")
    env.reset(seed=0)
    u: Any = env.unwrapped
    world = u.rig.world
    probe = _InStep(world.model, world.data)
    env.action_space.seed(0)
    for _ in range(60):
        env.step(env.action_space.sample())
    probe.on = True
    for _ in range(steps):
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        if term or trunc:
            env.reset()
    print(f"in the env's steps ({steps}; each piece timed every third step, right before the step's call; "
          f"{probe.n} substeps), CPU us:")
    for label, times in zip(("call", "call(null)", "mj(numba) spare"), probe.got):
        print(f"  {label:16s} best {min(times) * 1e6:7.1f}  median {statistics.median(times) * 1e6:7.1f}  "
              f"p25 {np.percentile(times, 25) * 1e6:7.1f}  ({len(times)} calls)")
    print(f"load {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    env.close()


def main(rounds: int) -> None:
    cap = _Capture()
    env = gym.make("joints/ErobReach-v0")
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(60):
        env.step(env.action_space.sample())
    cap.armed = True
    env.step(env.action_space.sample())
    assert cap.args is not None and cap.steps > 0
    tx, _out, st, w, mj_step, table, adr, ratio, order, worlds, dts, active = cap.args
    live = cap.live
    u: Any = env.unwrapped
    world = u.rig.world
    model, data = world.model, world.data
    assert worlds[w, 2] == data._address
    saved = mujoco.MjData(model)
    n = cap.steps
    # the state before the captured call: the data as it was then is gone; take the data now and the call's
    # inputs (the physics cost hardly depends on where the joint is: no contacts)
    mujoco.mj_copyData(saved, model, data)
    lt, lst, lworlds = live[5], live[2], live[9]

    def restore() -> None:
        mujoco.mj_copyData(data, model, saved)
        lt[:] = table
        lst[:] = st
        lworlds[:] = worlds

    m_adr, d_adr = model._address, data._address
    run: Any = stepping._run_compiled
    py_step = mujoco.mj_step

    def v_call() -> None:
        cap.fn(tx.copy(), live[1], lst, w, mj_step, lt, adr, ratio, order, lworlds, dts, active)

    def v_run() -> None:
        run(n, 1, mj_step, lt, adr, ratio, order, lworlds, dts, active)

    def v_drive() -> None:
        run(n, 0, mj_step, lt, adr, ratio, order, lworlds, dts, active)

    def v_mj_numba() -> None:
        _mj_loop_compiled(n, mj_step, m_adr, d_adr)

    def v_mj_python() -> None:
        for _ in range(n):
            py_step(model, data)

    null = _null_physics()

    def v_call_null() -> None:
        cap.fn(tx.copy(), live[1], lst, w, null, lt, adr, ratio, order, lworlds, dts, active)

    def v_dispatch() -> None:
        run(0, 1, mj_step, lt, adr, ratio, order, lworlds, dts, active)

    long = 100 * n

    def v_drive_long() -> None:
        run(long, 0, mj_step, lt, adr, ratio, order, lworlds, dts, active)

    variants = {"call": v_call, "run": v_run, "mj(numba)": v_mj_numba, "mj(python)": v_mj_python, "drive": v_drive,
                "call(null)": v_call_null, "dispatch": v_dispatch, "drive x100": v_drive_long}
    scratch = np.ones(1 << 18)  # 2 MiB: touched after each restore with COLD=1 (the L1/L2 a step's Python evicts)
    cold = os.environ.get("COLD") == "1"
    for fn in variants.values():  # compiled and warm
        restore()
        fn()
    got: dict[str, list[float]] = {k: [] for k in variants}
    for _ in range(rounds):
        for name, fn in variants.items():
            restore()
            if cold:
                scratch += 1.0
            t = time.thread_time()
            fn()
            got[name].append(time.thread_time() - t)
    print(f"steady call: {len(tx)} rows, {n} substeps; {rounds} rounds, variants alternated, CPU us per call "
          f"(per substep){'; caches evicted before each call' if cold else ''}")
    for name, times in got.items():
        best, med = min(times), statistics.median(times)
        k = long if name == "drive x100" else n
        print(f"  {name:11s} best {best * 1e6:7.1f} ({best / k * 1e6:.3f})  median {med * 1e6:7.1f} "
              f"({med / k * 1e6:.3f})  p25 {np.percentile(times, 25) * 1e6:7.1f}  p75 {np.percentile(times, 75) * 1e6:7.1f}")
    b = {k: min(v) for k, v in got.items()}
    md = {k: statistics.median(v) for k, v in got.items()}
    for label, x in (("best", b), ("median", md)):
        print(f"  [{label}] call - mj(numba) {(x['call'] - x['mj(numba)']) * 1e6:.1f} us; run - mj(numba) "
              f"{(x['run'] - x['mj(numba)']) * 1e6:.1f}; call - run {(x['call'] - x['run']) * 1e6:.1f}; "
              f"mj(python) - mj(numba) {(x['mj(python)'] - x['mj(numba)']) * 1e6:.1f}")
    print(f"load {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    env.close()


if __name__ == "__main__":
    if sys.argv[1:2] == ["--in-step"]:
        in_step(int(sys.argv[2]) if len(sys.argv) > 2 else 6000)
    else:
        main(int(sys.argv[1]) if len(sys.argv) > 1 else 2000)
