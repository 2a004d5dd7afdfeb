"""Several rigs' steady eRob requests in ONE compiled call: each rig's transactions as its own one-call exchange.

Rule: a batch of rigs (N single envs in one process, their worlds in one stepping group) gives what each rig's own
:meth:`~joints.sim.erob_exchange.ErobExchange.run` gives, rig after rig: the same rows (built by the exchange's own
``_row`` / ``_read_row``), the same compiled arithmetic (:func:`joints.sim.line_exchange.exchanges` of each rig's
rows on its own state vector, world and plan), the same write-backs (the line, the world, the clock, the
parameter store, the frame log, the counts), only the dispatch is one call and the checks that are the same for
every rig (the stock methods, the compiled entry) are asked once. Worlds are separate models and separate rows of
the group's table, so one rig's physics never sees another's: the order of the rigs in the call changes no bit.

It runs only in the steady case of EVERY rig, checked before anything is sent (each world fused and in the one
group, each line idle, each drive steady, each request a steady one; the caller, :class:`joints.CompiledRigs`,
checks each rig's link lane); otherwise :func:`carry_rigs` returns None and every rig sends its requests its own
way. A world's booked sleep (``World.hold``) runs at the start of its rig's transactions, as in its own call; with
``holds``, each rig's wait for its env's tick is a hold row among its transactions (its own ``run(hold=...)``'s), so
that a whole env step of every rig - commands, wait, reads - is one call (:meth:`joints.CompiledRigs.step`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from joints.codecs import modbus as mb
from joints.sim import erob_exchange as E
from joints.sim import kernel
from joints.sim import line_exchange as L
from joints.sim.kernel import jitable
from joints.sim.line_exchange import CLOCK_AFTER, STATE_WIDTH, TX_WIDTH
from joints.sim.stepping import STEPS

__all__ = ["carry_rigs", "compiled", "rigs_exchanges"]

jitable(L.exchanges)  # compiled into rigs_exchanges (its own compiled entry is unchanged)


def rigs_exchanges(tx: Any, out: Any, st: Any, ws: Any, starts: Any, orders: Any, order_at: Any, mj_step: int,
                   table: Any, adr: Any, ratio: Any, worlds: Any, dts: Any) -> None:
    """Rig ``r``'s transactions ``tx[starts[r]:starts[r + 1]]`` in its world ``ws[r]`` with its state vector
    ``st[r]`` and the rows its world steps ``orders[order_at[r]:order_at[r + 1]]`` (its group plan), as
    :func:`joints.sim.line_exchange.exchanges` carries them, rig after rig."""
    for r in range(ws.shape[0]):
        a = starts[r]
        b = starts[r + 1]
        L.exchanges(tx[a:b], out[a:b], st[r], ws[r], mj_step, table, adr, ratio, orders[order_at[r]:order_at[r + 1]],
                    worlds, dts, ws[r:r + 1])


_COMPILED: list[Any] = []


def compiled() -> Any:
    """:func:`rigs_exchanges` compiled (numba), or None without it (then no batch goes in one call)."""
    if not _COMPILED:
        _COMPILED.append(kernel.compiled(rigs_exchanges) if L.compiled()[0] is not None else None)
    return _COMPILED[0]


def _line_ok(ex: E.ErobExchange) -> bool:
    """The per-line part of ``ErobExchange._line_steady`` (its stock-method check is asked once per batch)."""
    line = ex.line
    if not L.world_fused(ex.world):
        return False
    return not (line._pending or line._cap is not None or line._closed or not line._plain_peer())


class _StatusMaker:
    """The status replies of one read (its request, the front's plan, its registers) made from their values: what a
    line's log keeps of such a reply (a packed reply, :meth:`~joints.transports.serial_sim.TimedSerialLine.book_frames`:
    its values, this one object shared by every step's) - the message the reply itself makes."""

    __slots__ = ("plan", "registers", "request")

    def __init__(self, reply: E.StatusReply) -> None:
        self.request = reply.request
        self.plan = reply.plan
        self.registers = reply.registers

    def fits(self, reply: E.StatusReply) -> bool:
        return reply.request is self.request and reply.plan is self.plan and reply.registers is self.registers

    def __call__(self, values: tuple[int, ...]) -> Any:
        return E.StatusReply(self.request, self.plan, list(values), self.registers).message()


class _Buffers:
    """The call's arrays, kept per (rigs, transactions)."""

    def __init__(self, rigs: int, count: int, out_width: int) -> None:
        import numpy as np

        self.tx = np.zeros((count, TX_WIDTH))
        self.out = np.zeros((count, out_width))
        self.st = np.zeros((rigs, STATE_WIDTH))
        self.ws = np.zeros(rigs, dtype=np.int64)
        self.starts = np.zeros(rigs + 1, dtype=np.int64)
        self.plans: list[Any] = []  #: the plans ``orders`` was built from (by identity)
        self.orders: Any = None
        self.order_at: Any = None
        self.makers: list[_StatusMaker | None] = [None] * rigs  #: per rig, its status replies' (the last read's)


def carry_rigs(requests: Sequence[Sequence[Any]], exchanges: Sequence[Sequence[Any]],
               sizes: Sequence[Callable[[Any], int]], checks: Sequence[Callable[[Any, Any], bool]], lazy: bool,
               buffers: dict[tuple[int, int], Any], holds: Sequence[tuple[int, float]] | None = None
               ) -> list[list[Any]] | None:
    """Rig ``r``'s ``requests[r]`` (each for the drive whose exchange is ``exchanges[r][k]``, all on one line and
    world, each rig's its own) as ``exchanges[r][0].run(requests[r], sizes[r], checks[r], exchanges[r], lazy=lazy,
    hold=holds[r])`` sends them (a reply check is required: every reply is checked before anything is sent; a hold
    comes before one of the rig's requests), every rig in one compiled call: each rig's replies (and, with
    ``holds``, its hold's outcome in its first exchange's ``held``); None (nothing sent) where any rig is not the
    steady case. ``buffers``: the caller's, kept between calls."""
    fn = compiled()
    if fn is None or not L.stock(E._STOCK):
        return None
    group = exchanges[0][0].world.group
    rows: list[list[float]] = []
    made: list[tuple[Any, Any, Any]] = []
    worlds: list[Any] = []
    reads = False
    for r, (reqs, exs, size, check) in enumerate(zip(requests, exchanges, sizes, checks)):
        first = exs[0]
        line, world = first.line, first.world
        if world.group is not group or not _line_ok(first):
            return None
        for ex in exs if len(exs) == 1 else {id(ex): ex for ex in exs}.values():
            if ex.line is not line or ex.world is not world or not ex._drive_steady():
                return None
        if holds is not None and not L.sleeps_held(world):
            return None
        got = first._rows(reqs, exs, size, check, group)
        if got is None:
            return None
        if holds is not None:  # the host's wait for the rig's tick before one of its requests, as in its own run
            assert holds[r][0] < len(reqs), "a rig's hold comes before one of its requests"
            got[0].insert(holds[r][0], L.hold_row(holds[r][1]))
        rows.extend(got[0])
        made.extend(got[1])
        worlds.append(world)
        reads = reads or any(type(q) is mb.ReadHoldingRegisters for q in reqs)
    locks = sorted({id(w): w.lock for w in worlds}.values(), key=id)
    held = 0
    try:
        for lock in locks:
            lock.acquire()
            held += 1
        return _carry_locked(fn, group, requests, exchanges, rows, made, reads, lazy, buffers, holds)
    finally:
        for lock in reversed(locks[:held]):
            lock.release()


def _carry_locked(fn: Any, group: Any, requests: Sequence[Sequence[Any]],
                  exchanges: Sequence[Sequence[Any]], rows: list[list[float]], made: list[tuple[Any, Any, Any]],
                  reads: bool, lazy: bool, buffers: dict[tuple[int, int], Any],
                  holds: Sequence[tuple[int, float]] | None) -> list[list[Any]] | None:
    """:func:`carry_rigs` with every rig's link and world locked, its rows built (``reads``: a status read among
    them; ``holds``: a hold row among each rig's, at its index)."""
    import numpy as np

    plans = []
    filled = []
    ws = []
    starts = [0]
    steps = []
    at = 0
    plan = group._plan
    for reqs, exs in zip(requests, exchanges):  # each rig's line's time (nothing sent where one is not clear)
        first = exs[0]
        line = first.line
        now = L.clear(line)
        if now is None:
            return None
        world = first.world
        vector = [0.0] * STATE_WIDTH
        L.fill(vector, world, line, now)  # (its slice assignment fills a list as it fills a row)
        filled.append(vector)
        ws.append(world.group_index)
        at += len(reqs) if holds is None else len(reqs) + 1
        starts.append(at)
        steps.append(world.steps)
        plans.append(plan(world._me)[0])
    rigs = len(exchanges)
    key = (rigs, len(rows))
    buf = buffers.get(key)
    if buf is None:
        if len(buffers) > 16:
            buffers.clear()
        buf = buffers[key] = _Buffers(rigs, len(rows), E.OUT_WIDTH)
    buf.tx[:] = rows
    st = buf.st
    worlds_table = group.worlds_table
    st[:] = filled
    buf.ws[:] = ws
    buf.starts[:] = starts
    worlds_table[buf.ws, STEPS] = steps
    if len(plans) != len(buf.plans) or any(p is not q for p, q in zip(plans, buf.plans)):
        buf.orders = np.concatenate(plans) if plans else np.zeros(0, dtype=np.int64)
        bounds = np.zeros(rigs + 1, dtype=np.int64)
        np.cumsum([len(p) for p in plans], out=bounds[1:])
        buf.order_at = bounds
        buf.plans = plans
    try:
        fn(buf.tx, buf.out, st, buf.ws, buf.starts, buf.orders, buf.order_at, group.mj_step or 0, group.table, group.adr,
           group.ratio, worlds_table, group.dts_array)
    finally:
        states: list[list[float]] = st.tolist()
        counted: list[int] = worlds_table[buf.ws, STEPS].tolist()
        for r, exs in enumerate(exchanges):  # as line_exchange.fused, rig by rig
            L.world_back(exs[0].world, counted[r], states[r])
    # the output rows as floats: a read's whole row (its status and sensed columns), a write's frame columns only
    out = buf.out
    outs: list[list[float]] = out.tolist() if reads else out[:, :L.OUTS].tolist()
    tx = rows
    makers = buf.makers
    replies_of: list[list[Any]] = []
    k = 0  # the row
    m = 0  # the request
    for r, (reqs, exs) in enumerate(zip(requests, exchanges)):
        first = exs[0]
        L.arena_check(first.world)  # as line_exchange.fused (every world brought back first, as each rig's own)
        line = first.line
        L.line_back(line, states[r])  # as Carrier.carry
        replies: list[Any] = []
        first.clocks = clocks = []
        frames: list[tuple[Any, ...]] = []
        held = -1 if holds is None else k + holds[r][0]
        for req in reqs:  # as ErobExchange.run
            if k == held:  # the hold's row: what was left to the tick, the clock after it
                first.held = L.held_of(outs[k])
                k += 1
            t, o, (ex, a, b) = tx[k], outs[k], made[m]
            k += 1
            m += 1
            if t[E.OP] == E.READ:
                reply = first._status_reply(req, o, a, b, lazy)
            else:
                reply = a
                ex.firmware._keep(b)
            replies.append(reply)
            clocks.append(o[CLOCK_AFTER])
            frames.append((o[L.H_START], o[L.H_END], o[L.H_DUE], int(t[L.REQUEST]), "host", None))
            if type(reply) is E.StatusReply:  # kept by the log as its values (no object per step for the collector)
                maker = makers[r]
                if maker is None or not maker.fits(reply):
                    maker = makers[r] = _StatusMaker(reply)
                frames.append((o[L.D_START], o[L.D_END], o[L.D_SEEN], int(t[L.REPLY]), "device", maker,
                               reply.values))
            else:
                frames.append((o[L.D_START], o[L.D_END], o[L.D_SEEN], int(t[L.REPLY]), "device", reply))
        line.book_frames(frames)
        first.taken += 1
        replies_of.append(replies)
    return replies_of
