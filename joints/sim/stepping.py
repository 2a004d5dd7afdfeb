"""Stepping worlds: every drive of one or more worlds, and their physics, in as few calls as possible.

Rule: one table holds the rows of every kernel-backed twin (:mod:`joints.sim.kernel`) of a group
of worlds (one world, or the N rigs of a batched env); one call of :func:`substep` runs the loops
of all of them for one physics substep, and :func:`run` runs N substeps - loops, then
``mj_step`` of every world - without returning to Python (compiled, with MuJoCo's ``mj_step``
called directly). A world whose drives are not all kernel-backed (a twin that still steps in
Python), or that ticks a timed bus after every substep (CAN), steps substep by substep from
Python instead, with the same kernels. Every path gives the same bits.

Rows are stepped in the order of the world's joints (as the world has always stepped its
drives); each joint's row, MuJoCo addresses and world index are in :attr:`Group.adr`:
``[kind, qpos address, dof address, actuator, world, a, b, c]`` (``a``-``c``: rows a kind's
loops reach besides their own, e.g. a dual-channel drive's shared row).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from joints.sim import erob_kernel, kernel
from joints.sim.kernel import jitable

__all__ = ["CHUNK", "KINDS", "Group", "run", "substep"]

#: kernel kinds: a twin's ``KERNEL`` name -> code in the adr table
KINDS = {"erob": 1}
EROB = 1
KIND, QPOS, DOF, ACT, WORLD, A, B, C = range(8)
ADR_WIDTH = 8
#: substeps per compiled call at most (a KeyboardInterrupt lands between calls)
CHUNK = 20_000


@jitable
def substep(table: Any, adr: Any, order: Any, active: Any, steps: Any, dts: Any, k: int,
            qpos: Any, qvel: Any, ctrl: Any) -> None:
    """The loops of every row in ``order`` whose world is active, for the ``k``-th substep from
    each world's ``steps``; torques into the worlds' ``ctrl``."""
    for j in range(len(order)):
        i = order[j]
        a = adr[i]
        w = a[WORLD]
        if active[w] == 0:
            continue
        dt = dts[w]
        t = (steps[w] + k + 1) * dt
        q = float(qpos[w][a[QPOS]])
        qd = float(qvel[w][a[DOF]])
        kind = a[KIND]
        tau = 0.0
        if kind == EROB:
            tau = erob_kernel.step(table[i], t, dt, q, qd)
        ctrl[w][a[ACT]] = tau


def _run(n: int, table: Any, adr: Any, order: Any, active: Any, steps: Any, dts: Any, qpos: Any, qvel: Any,
         ctrl: Any, models: Any, datas: Any, mj_step: Any) -> None:
    """``n`` substeps of every active world: the loops of all rows, then ``mj_step`` of each world."""
    for k in range(n):
        substep(table, adr, order, active, steps, dts, k, qpos, qvel, ctrl)
        for w in range(len(models)):
            if active[w] != 0:
                mj_step(models[w], datas[w])


run = _run
_substep_compiled = kernel.compiled(substep)
_run_compiled = kernel.compiled(_run)


class Group:
    """The kernel rows of some worlds in one table, stepped together or world by world."""

    def __init__(self, worlds: Sequence[Any], compiled: bool) -> None:
        import numpy as np

        self.worlds = list(worlds)
        self.compiled = compiled
        rows: list[list[float]] = []
        adr: list[list[int]] = []
        self._owners: list[tuple[Any, int]] = []  #: (twin, first row)
        self._row_of: dict[tuple[int, str], int] = {}  #: (world index, joint name) -> row
        for w, world in enumerate(self.worlds):
            seen: dict[int, int] = {}
            for b in world.kernel_joints():
                twin = b.emulator
                first = seen.get(id(twin))
                if first is None:
                    first = seen[id(twin)] = len(rows)
                    for r in twin.kernel_rows():
                        rows.append(r)
                        adr.append([0] * ADR_WIDTH)
                    self._owners.append((twin, first))
                i = first + twin.kernel_row(b.channel)
                adr[i] = [KINDS[twin.KERNEL], b.qadr, b.dadr, b.aid, w, first, 0, 0]
                self._row_of[(w, b.name)] = i
        width = max([len(r) for r in rows], default=1)
        self.table = kernel.rows([r + [0.0] * (width - len(r)) for r in rows] or [[0.0]], compiled)
        self.adr = kernel.rows(adr or [[0] * ADR_WIDTH], compiled, integer=True)
        for twin, first in self._owners:
            twin.adopt(self.table, first)
        self.qpos = kernel.arrays([w.data.qpos for w in self.worlds], compiled)
        self.qvel = kernel.arrays([w.data.qvel for w in self.worlds], compiled)
        self.ctrl = kernel.arrays([w.data.ctrl for w in self.worlds], compiled)
        self.dts = np.array([w.timestep for w in self.worlds]) if compiled else [w.timestep for w in self.worlds]
        self.models = np.array([w.model._address for w in self.worlds], dtype=np.int64)
        self.datas = np.array([w.data._address for w in self.worlds], dtype=np.int64)
        self.mj_step = kernel.mj_step_function() if compiled else None
        self.order: Any = None
        self.replan()

    def replan(self) -> None:
        """Which rows step, in joint order (a world's joints stepped in Python are left out)."""
        order = [self._row_of[(w, b.name)] for w, world in enumerate(self.worlds) for b in world.kernel_joints()
                 if world.kernel_stepped(b)]
        if self.compiled:
            import numpy as np

            self.order = np.array(order, dtype=np.int64)
        else:
            self.order = order

    def _flags(self, worlds: Sequence[int], steps: Sequence[int]) -> tuple[Any, Any]:
        import numpy as np

        active = [0] * len(self.worlds)
        counts = [0] * len(self.worlds)
        for w, s in zip(worlds, steps):
            active[w] = 1
            counts[w] = s
        if self.compiled:
            return np.array(active, dtype=np.int64), np.array(counts, dtype=np.int64)
        return active, counts

    def fused(self, worlds: Sequence[int]) -> bool:
        """Whether ``worlds`` can run N substeps in one compiled call."""
        return self.mj_step is not None and all(self.worlds[w].fusable() for w in worlds)

    def run(self, worlds: Sequence[int], n: int) -> None:
        """``n`` substeps of ``worlds`` (indices) in compiled calls of at most :data:`CHUNK`
        substeps; each world's ``steps`` counts up after every call."""
        while n > 0:
            m = min(n, CHUNK)
            active, steps = self._flags(worlds, [self.worlds[w].steps for w in worlds])
            _run_compiled(m, self.table, self.adr, self.order, active, steps, self.dts, self.qpos,  # type: ignore[misc]
                          self.qvel, self.ctrl, self.models, self.datas, self.mj_step)
            for w in worlds:
                self.worlds[w].steps += m
            n -= m

    def substep(self, worlds: Sequence[int]) -> None:
        """The kernel loops of ``worlds`` for their next substep (torques into ``ctrl``; no physics)."""
        active, steps = self._flags(worlds, [self.worlds[w].steps for w in worlds])
        fn = _substep_compiled if self.compiled else substep
        fn(self.table, self.adr, self.order, active, steps, self.dts, 0,  # type: ignore[misc]
           self.qpos, self.qvel, self.ctrl)
