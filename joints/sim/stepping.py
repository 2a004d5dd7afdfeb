"""Stepping worlds: every drive of one or more worlds, and their physics, in as few calls as possible.

Rule: one table holds the rows of every kernel-backed twin (:mod:`joints.sim.kernel`) of a group
of worlds (one world, or the N rigs of a batched env). :func:`step_row` is the one dispatch from
a row to its drive's loops. Compiled, :meth:`Group.run` runs N substeps of some of the worlds -
their rows' loops, then MuJoCo's ``mj_step`` of each of them - without returning to Python, reading
the joints from and writing the torques into the worlds' ``MjData`` by address. A call touches only
the rows and worlds it steps (a plan per set of worlds, kept), so stepping one rig of N costs what
stepping a lone rig does. Without a compiler
(or for a world whose drives are not all kernel rows, or that ticks a timed CAN bus after every
substep) the world steps substep by substep from Python: :func:`substep` runs the same rows
through the same :func:`step_row`. Every path gives the same bits.

Rows are stepped in the order of the worlds' joints (as a world has always stepped its drives);
each stepped row's kind, MuJoCo addresses, world and its twin's first row are in :attr:`Group.adr`
(columns :data:`KIND` ... :data:`FIRST`); each world's addresses and
step count in :attr:`Group.worlds_table` (columns :data:`STEPS` ... :data:`NU`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from joints.sim import erob_kernel, kernel, sensors, zlac_kernel
from joints.sim.kernel import jitable

__all__ = ["CHUNK", "KINDS", "Group", "has_kernel", "step_row", "substep"]

#: the kernel kinds (each kernel module's ``KIND``; a kernel-backed twin's ``KERNEL`` is one of them: the twin a
#: device family of :mod:`joints.registry` builds says which kernel it runs, nothing here names a device)
EROB, ZLAC = erob_kernel.KIND, zlac_kernel.KIND
KINDS = (EROB, ZLAC)
#: columns of :attr:`Group.adr`, one row per kernel row: its kind (its twin's ``KERNEL``), the MuJoCo addresses of
#: its joint (``qpos``, ``qvel`` and ``ctrl`` index), its world, and the first of its twin's rows (a ZLAC
#: channel's loops read the drive's row there)
KIND, QPOS, DOF, ACT, WORLD, FIRST = range(6)
ADR_WIDTH = 6
#: columns of :attr:`Group.worlds_table`
STEPS, MODEL, DATA, QPOS_AT, NQ, QVEL_AT, NV, CTRL_AT, NU = range(9)
WORLD_WIDTH = 9
#: substeps per compiled call at most (a KeyboardInterrupt lands between calls)
CHUNK = 50
#: a world whose MuJoCo arena was ever this full leaves the fused path for good: inside the compiled call
#: an mju_error (arena overflow with many contacts) would end the process; the per-substep path raises
#: mujoco.FatalError instead, which the rig's exit handling survives
ARENA_GUARD = 0.25


def has_kernel(twin: Any) -> bool:
    """Whether ``twin`` runs its loops as kernel rows (its ``KERNEL`` is one of :data:`KINDS`)."""
    return getattr(twin, "KERNEL", None) in KINDS


@jitable
def step_row(table: Any, adr: Any, i: int, t: float, dt: float, q: float, qd: float) -> float:
    """The loops of row ``i`` (its kind's kernel) for the substep ending at ``t``: the torque."""
    a = adr[i]
    kind = a[KIND]
    if kind == EROB:
        return erob_kernel.step(table[i], t, dt, q, qd)
    if kind == ZLAC:  # a channel row; the drive's row is its twin's first
        first = a[FIRST]
        return zlac_kernel.step(table, first, i - first - 1, t, dt, q, qd)
    return 0.0


def substep(table: Any, adr: Any, ratio: Sequence[float], order: Any, steps: Sequence[int],
            dts: Sequence[float], qpos: Sequence[Any], qvel: Sequence[Any], ctrl: Sequence[Any]) -> None:
    """One substep of the rows in ``order`` (Python: the worlds' arrays)."""
    for i in order:
        a = adr[i]
        w = a[WORLD]
        dt = dts[w]
        t = (steps[w] + 1) * dt
        r = ratio[i]
        ctrl[w][a[ACT]] = step_row(table, adr, i, t, dt, float(qpos[w][a[QPOS]]) * r, float(qvel[w][a[DOF]]) * r)


@jitable
def _run(n: int, physics: int, mj_step: int, table: Any, adr: Any, ratio: Any, order: Any, worlds: Any,
         dts: Any, active: Any) -> None:
    """``n`` substeps of the ``active`` worlds: the loops of the rows in ``order`` (theirs), then
    (``physics``) each active world's ``mj_step`` (compiled only: the worlds' arrays are reached by address)."""
    at, call = kernel.f64_at, kernel.call  # cells by pointer and 2-D indexing: no array view made per substep
    for k in range(n):
        for j in range(len(order)):
            i = order[j]
            w = adr[i, WORLD]
            dt = dts[w]
            t = (worlds[w, STEPS] + k + 1) * dt
            r = ratio[i]
            q = at(worlds[w, QPOS_AT])[adr[i, QPOS]] * r
            qd = at(worlds[w, QVEL_AT])[adr[i, DOF]] * r
            at(worlds[w, CTRL_AT])[adr[i, ACT]] = step_row(table, adr, i, t, dt, q, qd)
        if physics:
            for j in range(len(active)):
                w = active[j]
                call(mj_step, worlds[w, MODEL], worlds[w, DATA])


_run_compiled = kernel.compiled(_run) if kernel.AVAILABLE else None
_WARM: list[bool] = []


def _warm() -> None:
    """Every compiled kernel ready once per process (see :func:`joints.sim.erob_kernel.warm`)."""
    if not _WARM:
        erob_kernel.warm()
        zlac_kernel.warm()
        sensors.warm()  # the twins' reads from Python
        _WARM.append(True)


class Group:
    """The kernel rows of some worlds in one table, stepped together or world by world."""

    def __init__(self, worlds: Sequence[Any], compiled: bool) -> None:
        import numpy as np

        self.worlds = list(worlds)
        self.compiled = compiled and _run_compiled is not None
        rows: list[list[float]] = []
        adr: list[list[int]] = []
        ratio: list[float] = []
        self._owners: list[tuple[Any, int]] = []  #: (twin, first row)
        self._watches: dict[tuple[tuple[int, int], ...], Any] = {}  #: run_watching's cells as (row, column) pairs
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
                        ratio.append(1.0)
                    self._owners.append((twin, first))
                i = first + twin.kernel_row(b.channel)
                adr[i] = [twin.KERNEL, b.qadr, b.dadr, b.aid, w, first]
                ratio[i] = b.ratio  # motor rad per joint unit (a slide on a lead screw)
                self._row_of[(w, b.name)] = i
        width = max([len(r) for r in rows], default=1)
        self.table = kernel.rows([r + [0.0] * (width - len(r)) for r in rows] or [[0.0]], self.compiled)
        self.adr = kernel.rows(adr or [[0] * ADR_WIDTH], self.compiled, integer=True)
        self.ratio: Any = np.array(ratio or [1.0]) if self.compiled else (ratio or [1.0])
        for twin, first in self._owners:
            twin.adopt(self.table, first)
        self.dts = [w.timestep for w in self.worlds]
        #: per world, the arena use (bytes) above which it leaves the fused path (:data:`ARENA_GUARD`)
        self._arena_limits = [ARENA_GUARD * w.model.narena for w in self.worlds]
        #: the Python path's per-substep inputs, kept: step counts and the worlds' arrays (views of each
        #: world's one MjData)
        self._steps = [0] * len(self.worlds)
        self._arrays = ([w.data.qpos for w in self.worlds], [w.data.qvel for w in self.worlds],
                        [w.data.ctrl for w in self.worlds])
        self.mj_step = kernel.mj_step_address() if self.compiled else None
        if self.compiled:
            table = []
            for world in self.worlds:
                m, d = world.model, world.data
                table.append([0, m._address, d._address, d.qpos.ctypes.data, m.nq, d.qvel.ctypes.data, m.nv,
                              d.ctrl.ctypes.data, m.nu])
            self.worlds_table = np.array(table, dtype=np.int64).reshape(len(self.worlds), WORLD_WIDTH)
            self.dts_array = np.array(self.dts)
        self.order: Any = None
        self.fusable: list[bool] = []
        self._world_order: list[list[int]] = []  #: per world, its stepped rows in joint order
        #: per set of worlds stepped together: (the rows they step, the worlds) as the compiled call takes them
        self._plans: dict[tuple[int, ...], tuple[Any, Any]] = {}
        self.replan()
        if self.compiled:
            _warm()
            order, active = self._plan((0,))
            _run_compiled(0, 0, 0, self.table, self.adr, self.ratio, order,  # type: ignore[misc]
                          self.worlds_table, self.dts_array, active)  # compiled now, not in the first (paced) step

    def replan(self) -> None:
        """Which rows step, in joint order (a world's joints stepped in Python are left out), and
        which worlds can run N substeps in one call."""
        import numpy as np

        self._world_order = [[self._row_of[(w, b.name)] for b in world.kernel_joints() if world.kernel_stepped(b)]
                             for w, world in enumerate(self.worlds)]
        order = [i for rows in self._world_order for i in rows]
        self.order = np.array(order, dtype=np.int64) if self.compiled else order
        self._plans.clear()
        self.fusable = [self.mj_step is not None and w.fusable() for w in self.worlds]

    def _plan(self, worlds: tuple[int, ...]) -> tuple[Any, Any]:
        """The rows ``worlds`` (ascending indices) step, in joint order, and the worlds, as the stepping takes
        them (int64 arrays compiled, lists in Python); kept until the next :meth:`replan`."""
        plan = self._plans.get(worlds)
        if plan is None:
            order = [i for w in worlds for i in self._world_order[w]]
            if self.compiled:
                import numpy as np

                plan = (np.array(order, dtype=np.int64), np.array(worlds, dtype=np.int64))
            else:
                plan = (order, list(worlds))
            if len(self._plans) >= 256 + len(self.worlds):  # each world alone and a few sets of a batch; bounded
                self._plans.clear()
            self._plans[worlds] = plan
        return plan

    def run(self, worlds: Sequence[int], n: int) -> None:
        """``n`` substeps of ``worlds`` (indices, all fusable) in compiled calls of at most
        :data:`CHUNK` substeps; each world's ``steps`` counts up after every call."""
        table = self.worlds_table
        all_worlds = self.worlds
        active = tuple(worlds)
        plan = self._plans.get(active)
        order, indices = self._plan(active) if plan is None else plan
        mj_step, rows, adr, ratio, dts = self.mj_step or 0, self.table, self.adr, self.ratio, self.dts_array
        limits = self._arena_limits  # as World.arena_crowded(ARENA_GUARD), without a call per world
        while n > 0:
            m = min(n, CHUNK)
            for w in active:
                table[w, STEPS] = all_worlds[w].steps
            _run_compiled(m, 1, mj_step, rows, adr, ratio, order, table, dts, indices)  # type: ignore[misc]
            for w in active:
                all_worlds[w].steps += m
            n -= m
            crowded: list[int] = []
            for w in active:
                if all_worlds[w].data.maxuse_arena > limits[w]:
                    crowded.append(w)
            if crowded:
                for w in crowded:
                    all_worlds[w].leave_fused_path()
                self.replan()
                for w in crowded:  # the rest of their substeps one by one, where errors raise
                    all_worlds[w].step(n)
                active = tuple(w for w in active if w not in crowded)
                if not active:
                    return
                order, indices = self._plan(active)

    def substep(self, worlds: Sequence[int]) -> None:
        """The kernel loops of ``worlds`` for their next substep (torques into ``ctrl``; no physics)."""
        order, indices = self._plan(tuple(worlds))
        if self.compiled:
            table = self.worlds_table
            for w in worlds:
                table[w, STEPS] = self.worlds[w].steps
            _run_compiled(1, 0, 0, self.table, self.adr, self.ratio, order, table,  # type: ignore[misc]
                          self.dts_array, indices)
            return
        steps = self._steps
        for w in worlds:
            steps[w] = self.worlds[w].steps
        substep(self.table, self.adr, self.ratio, order, steps, self.dts, *self._arrays)

    def run_watching(self, world: int, n: int, cells: Sequence[tuple[Any, int]]) -> int:
        """Up to ``n`` substeps of world ``world`` (fusable) as :meth:`run` steps them, ending after the first
        substep at whose end one of ``cells`` (twin, column of the twin's first row) is non-zero (a fault the
        loops tripped: a CANopen front reports it at that substep). Returns the substeps run (fewer than ``n``
        also where the arena guard took the world off the fused path)."""
        key = tuple((id(twin), column) for twin, column in cells)
        watch = self._watches.get(key)
        if watch is None:  # the rows are the group's for its life: one array per set of cells
            import numpy as np

            firsts = {id(twin): first for twin, first in self._owners}
            watch = self._watches[key] = np.array([[firsts[id(twin)], column] for twin, column in cells],
                                                  dtype=np.int64).reshape(-1, 2)
        order, indices = self._plan((world,))
        table = self.worlds_table
        w = self.worlds[world]
        done = 0
        while done < n:
            m = min(n - done, CHUNK)
            table[world, STEPS] = w.steps
            ran = int(_run_watch_compiled(m, self.mj_step or 0, self.table, self.adr,  # type: ignore[misc]
                                          self.ratio, order, table, self.dts_array, indices, watch))
            w.steps += ran
            done += ran
            if w.data.maxuse_arena > self._arena_limits[world]:
                w.leave_fused_path()
                self.replan()
                return done
            if ran < m:
                return done  # a watched cell turned non-zero
        return done


jitable(_run)  # also compiled into _run_watch


def _run_watch(n: int, mj_step: int, table: Any, adr: Any, ratio: Any, order: Any, worlds: Any, dts: Any,
               active: Any, watch: Any) -> int:
    """:func:`_run` (physics on) one substep at a time inside one compiled call, ending after the first substep
    at whose end ``table[row, column]`` of a ``watch`` pair is non-zero; returns the substeps run (the active
    worlds' ``worlds[w, STEPS]`` count them)."""
    for k in range(n):
        _run(1, 1, mj_step, table, adr, ratio, order, worlds, dts, active)
        for j in range(len(active)):
            worlds[active[j], STEPS] += 1
        for j in range(len(watch)):
            if table[watch[j, 0], watch[j, 1]] != 0.0:
                return k + 1
    return n


_run_watch_compiled = kernel.compiled(_run_watch) if kernel.AVAILABLE else None
