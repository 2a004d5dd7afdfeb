"""The line and world arithmetic of a one-call exchange: a twin's steady Modbus requests in one compiled call.

Rule: it gives, float by float, what the request-by-request path gives over a timed RS485 line -
:meth:`~joints.transports.serial_sim.TimedSerialLine._transact_idle` (its ``_sync``, the ``_put`` of the host's
frame, the sleep to the instant the drive acts, the ``_put`` of the device's reply) on a world's clock
(``World.advance``/``sync``/``book``: the physics up to each instant the drive acts on a frame, the reply's
travel booked) - with every ``max`` spelled as Python's builtin (``b if b > a else a``: the same on ties and
signed zeros in compiled code). The line, the world and the clock are carried in a state vector (:data:`CLOCK`
...); the transactions are rows naming their family (:data:`KIND`, the kernel kind codes of
:mod:`joints.sim.stepping`) and their drive's row of the table; the family's act (what the drive does with the
frame: :func:`joints.sim.erob_exchange.act`, :func:`joints.sim.zlac_exchange.act`) is called by that kind, as
:func:`joints.sim.stepping.step_row` dispatches kernels. A family keeps only what it requests and what its act
does; the Python here brings the line, the world and the clock back afterwards (:func:`carry`, :func:`fused`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from joints.sim import kernel, stepping
from joints.sim.erob_kernel import fmax  # ``max`` as Python's builtin, in compiled code too
from joints.sim.kernel import jitable
from joints.sim.stepping import EROB, STEPS, ZLAC
from joints.sim.world import SLEEP_STOCK

__all__ = ["HOLD", "Carrier", "advance", "arena_check", "book", "clear", "compiled", "exchanges", "fill", "fused",
           "held_of", "hold", "hold_row", "line_back", "sleeps_held", "stock", "world_back", "world_fused"]

#: columns of the state vector: the clock's time, the world's target time, whether time is booked (1, or
#: :data:`HELD`), the line's time, the time the line last saw on the clock, when the host's / device's UART is
#: free, the line's character time, gap, adapter latency, the world's timestep
CLOCK, TARGET, BOOKED, NOW, SEEN, FREE_HOST, FREE_DEVICE, CHAR, GAP, LATENCY, DT = range(11)
STATE_WIDTH = 11
#: :data:`BOOKED` of a world whose booked time ends with a sleep's (``World.hold``): its substeps run on their own
#: before an advance (as ``World.advance`` runs them), never merged with it
HELD = 2.0
#: columns of a transaction row: the family's kind, its drive's (first) row in the table, request characters,
#: turnaround [s], reply characters; then the family's own from :data:`ARGS`
KIND, ROW, REQUEST, TURN, REPLY = range(5)
ARGS = 5
TX_WIDTH = ARGS + 5
#: columns of an output row: host frame start, end, due; device frame start, end, seen; the clock after the
#: transaction; then the family's own from :data:`OUTS`
H_START, H_END, H_DUE, D_START, D_END, D_SEEN, CLOCK_AFTER = range(7)
OUTS = 7
#: :data:`KIND` of a row that is no transaction but the host's sleep to a tick (:func:`hold`): the tick's time in
#: column :data:`UNTIL`; its output row has what was left to the tick (:data:`REMAINING`, <= 0: late) and the clock
HOLD = -1.0
UNTIL = ARGS
REMAINING = H_START


@jitable
def _due(seconds: float, st: Any, w: int, mj_step: int, table: Any, adr: Any, ratio: Any, order: Any,
         worlds: Any, dts: Any, active: Any) -> None:
    """:meth:`joints.sim.world.World._step_due` of ``World._due(seconds)`` on a fused world without ticks."""
    st[TARGET] += seconds
    dt = st[DT]
    n = math.ceil((st[TARGET] - worlds[w, STEPS] * dt) / dt - 1e-9)
    if n > 0:
        stepping._run(n, 1, mj_step, table, adr, ratio, order, worlds, dts, active)
        worlds[w, STEPS] += n


@jitable
def advance(seconds: float, st: Any, w: int, mj_step: int, table: Any, adr: Any, ratio: Any, order: Any,
            worlds: Any, dts: Any, active: Any) -> None:
    """The line's sleep of ``seconds`` (if > 0: ``World.advance``) to the instant a drive acts on a frame, then
    its settle (``World.sync``: booked time runs first). A sleep's time (``World.hold``, :data:`BOOKED` 2) runs
    on its own first, as ``World.advance`` runs it."""
    if seconds > 0 and st[BOOKED] == HELD:
        st[BOOKED] = 0.0
        _due(0.0, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
    if seconds > 0:
        st[BOOKED] = 0.0
        _due(seconds, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
        st[CLOCK] = st[TARGET]
        st[SEEN] = st[CLOCK]
    if st[BOOKED] != 0.0:
        st[BOOKED] = 0.0
        _due(0.0, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)


@jitable
def hold(until: float, st: Any, o: Any, w: int, mj_step: int, table: Any, adr: Any, ratio: Any, order: Any,
         worlds: Any, dts: Any, active: Any) -> None:
    """The env's wait for its tick at clock time ``until`` (``RigEnv._wait_until``: ``remaining`` left, if > 0
    the rig's sleep of it - ``Rig.sleep`` with no keep-alive due, ``end - now`` from ``end = now + remaining`` -
    as ``World.hold`` books it: an earlier held sleep's substeps first, as ``World.sync`` runs them)."""
    now = st[CLOCK]
    remaining = until - now
    o[REMAINING] = remaining
    if remaining > 0:
        end = now + remaining
        if end > now:
            if st[BOOKED] == HELD:
                st[BOOKED] = 0.0
                _due(0.0, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
            st[TARGET] += end - now
            st[BOOKED] = HELD
            st[CLOCK] = st[TARGET]
    o[CLOCK_AFTER] = st[CLOCK]


def hold_row(until: float) -> list[float]:
    """A :data:`HOLD` row: the host's wait for the env's tick at clock time ``until`` (:func:`hold`)."""
    row = [0.0] * TX_WIDTH
    row[KIND] = HOLD
    row[UNTIL] = until
    return row


def held_of(o: Sequence[float]) -> tuple[float, float]:
    """What a :data:`HOLD` row's output row ``o`` says: (what was left to the tick, <= 0: late; the clock after)."""
    return o[REMAINING], o[CLOCK_AFTER]


def exchanges(tx: Any, out: Any, st: Any, w: int, mj_step: int, table: Any, adr: Any, ratio: Any, order: Any,
              worlds: Any, dts: Any, active: Any) -> None:
    """The transactions ``tx`` (rows of :data:`TX_WIDTH`) in world ``w``, one after the other, as
    ``TimedSerialLine._transact_idle`` carries each: ``st`` (the state vector) in and out, each transaction's
    frame instants (and what its family's act puts there) into ``out``; a :data:`HOLD` row is the host's sleep
    to a tick between them (:func:`hold`)."""
    for k in range(tx.shape[0]):
        t = tx[k]
        o = out[k]
        if t[KIND] == HOLD:
            hold(t[UNTIL], st, o, w, mj_step, table, adr, ratio, order, worlds, dts, active)
            continue
        if k:  # TimedSerialLine._sync: the clock moved without the line (a booked reply)
            c = st[CLOCK]
            if c > st[SEEN]:
                st[SEEN] = c
                st[NOW] = fmax(st[NOW], c)
        start = fmax(st[NOW], st[FREE_HOST])  # TimedSerialLine._put of the host's frame
        end = start + t[REQUEST] * st[CHAR]
        due = end + st[GAP] + t[TURN]
        st[FREE_HOST] = end + st[GAP]
        o[H_START] = start
        o[H_END] = end
        o[H_DUE] = due
        advance(due - st[CLOCK], st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
        if t[KIND] == EROB:  # the drive acts on the frame
            _erob.act(table[int(t[ROW])], t, o)
        elif t[KIND] == ZLAC:
            _zlac.act(table, int(t[ROW]), t)
        st[NOW] = fmax(st[NOW], due)
        start = fmax(due, st[FREE_DEVICE])  # the reply (TimedSerialLine._put of the device's frame), booked
        end = start + t[REPLY] * st[CHAR]
        seen = end + st[LATENCY]
        st[FREE_DEVICE] = end + st[GAP]
        o[D_START] = start
        o[D_END] = end
        o[D_SEEN] = seen
        behind = seen - st[CLOCK]
        if behind > 0:  # World.book
            st[TARGET] += behind
            st[BOOKED] = 1.0
            st[CLOCK] = st[TARGET]
            st[SEEN] = st[CLOCK]
        st[FREE_HOST] = fmax(st[FREE_HOST], seen + st[GAP])
        st[NOW] = fmax(st[NOW], seen)
        o[CLOCK_AFTER] = st[CLOCK]


_COMPILED: list[Any] = []


def compiled() -> tuple[Any, Any]:
    """(:func:`exchanges`, :func:`advance`) compiled (numba), or (None, None) without it (with
    ``JOINTS_COMPILED=0`` the world does not run fused: the steady checks send the requests the usual way)."""
    if not _COMPILED:
        ok = kernel.AVAILABLE and stepping._run_compiled is not None
        _COMPILED.append((kernel.compiled(exchanges), kernel.compiled(advance)) if ok else (None, None))
    return _COMPILED[0]  # type: ignore[no-any-return]


def stock(methods: Sequence[tuple[Any, str, Any]]) -> bool:
    """Whether none of ``methods`` ((class, name, the function as defined)) is replaced (a test planting replies
    turns the one-call exchange off)."""
    for cls, name, fn in methods:
        if getattr(cls, name) is not fn:
            return False
    return True


def sleeps_held(world: Any) -> bool:
    """Whether the clock's sleep is ``world``'s hold as :func:`hold` does it: the world holds sleeps
    (``hold_sleeps``), its clock's sleep goes to it, and the methods on the way are stock."""
    return bool(world.hold_sleeps) and getattr(world.clock, "_on_sleep", None) == world._sleep and stock(SLEEP_STOCK)


def world_fused(world: Any) -> bool:
    """Whether ``world`` runs fused (compiled, every drive a kernel row) with nothing ticking after substeps."""
    group = world.group
    return bool(group.compiled and group.fusable[world.group_index]) and not world._ticks \
        and world._bind == world._bind_seen


def clear(line: Any) -> float | None:
    """The line's time (``_sync``) where no frame of its log can overlap the next request, else None (an edited
    log, or a frame still on the line: the line's own way)."""
    now: float = line._sync()
    if len(line._latest_end) != len(line._log) or line.latest_end() > max(now, line._free["host"]):
        return None
    return now


def fill(st: Any, world: Any, line: Any, now: float) -> None:
    """The state vector of ``world``, its clock and ``line`` (its time ``now``)."""
    free = line._free
    st[:] = (world.clock.now(), world._target, (HELD if world._held else 1.0) if world._booked else 0.0, now,
             line._clock_seen, free["host"], free["device"], line.char_time, line.gap, line.adapter_latency,
             world.timestep)


def fused(fn: Any, world: Any, st: Any, *head: Any) -> list[float]:
    """``fn(*head, st, ...)`` (a compiled entry of this module, ``st`` filled: :func:`fill`) on ``world``'s fused
    table; the world and the clock brought back after (``Group.run``'s arena check too): the state vector."""
    group = world.group
    w = world.group_index
    worlds = group.worlds_table
    worlds[w, STEPS] = world.steps
    order, active = group._plan(world._me)
    try:
        fn(*head, st, w, group.mj_step or 0, group.table, group.adr, group.ratio, order, worlds, group.dts_array,
           active)
    finally:
        state: list[float] = st.tolist()
        world_back(world, int(worlds[w, STEPS]), state)
    arena_check(world)
    return state


def world_back(world: Any, steps: int, state: Sequence[float]) -> None:
    """``world`` and its clock brought back from a call's state vector ``state`` (``steps``: its substeps)."""
    world.steps = steps
    world._target = state[TARGET]
    booked = state[BOOKED]
    world._booked = booked != 0.0
    world._held = booked == HELD
    world.clock.set(state[CLOCK])


def arena_check(world: Any) -> None:
    """``Group.run``'s check after its calls: a world whose MuJoCo arena grew past its group's limit leaves the
    fused path and the group plans again."""
    group = world.group
    if world._data.maxuse_arena > group._arena_limits[world.group_index]:
        world.leave_fused_path()
        group.replan()


def line_back(line: Any, state: Sequence[float]) -> None:
    """``line``'s times brought back from a call's state vector ``state`` (its frames are the caller's to book,
    :func:`book`)."""
    line.now = state[NOW]
    line._clock_seen = state[SEEN]
    free = line._free
    free["host"] = state[FREE_HOST]
    free["device"] = state[FREE_DEVICE]


class Carrier:
    """What a family's one-call exchange keeps: the state vector, the row and output buffers per count, the
    drive's row per group, the calls that ran (:attr:`taken`)."""

    def __init__(self, out_width: int) -> None:
        import numpy as np

        self.taken = 0  #: calls that ran (each of one or more transactions)
        self._out_width = out_width
        self._st = np.zeros(STATE_WIDTH)
        self._buffers: dict[int, tuple[Any, Any]] = {}
        self._group: Any = None
        self._row_at = 0

    def _first_row(self, group: Any, firmware: Any) -> int:
        """``firmware``'s (first) row in ``group``'s table (kept per group: a batch may join the world to another)."""
        if self._group is not group:
            self._row_at = next(first for twin, first in group._owners if twin is firmware)
            self._group = group
        return self._row_at

    def carry(self, fn: Any, world: Any, line: Any, now: float, rows: list[list[float]]) -> list[list[float]]:
        """The transactions ``rows`` over ``line`` (its time ``now``, from :func:`clear`) in ``world`` by ``fn``
        (:func:`exchanges` compiled): each one's output row; the line's times brought back (its frames are the
        caller's to book, :func:`book`)."""
        n = len(rows)
        buffers = self._buffers.get(n)
        if buffers is None:
            import numpy as np

            buffers = self._buffers[n] = (np.zeros((n, TX_WIDTH)), np.zeros((n, self._out_width)))
        tx, out = buffers
        tx[:] = rows
        st = self._st
        fill(st, world, line, now)
        line_back(line, fused(fn, world, st, tx, out))
        return out.tolist()  # type: ignore[no-any-return]


def book(line: Any, rows: Sequence[Sequence[float]], outs: Sequence[Sequence[float]], replies: Sequence[Any]) -> None:
    """Each transaction's two frames into ``line``'s log (``TimedSerialLine.book_frames``)."""
    frames: list[tuple[float, float, float, int, str, Any]] = []
    for t, o, reply in zip(rows, outs, replies):
        frames.append((o[H_START], o[H_END], o[H_DUE], int(t[REQUEST]), "host", None))
        frames.append((o[D_START], o[D_END], o[D_SEEN], int(t[REPLY]), "device", reply))
    line.book_frames(frames)


# the families' acts, dispatched by kind in exchanges (bound here: each family module imports this one)
from joints.sim import erob_exchange as _erob
from joints.sim import zlac_exchange as _zlac
