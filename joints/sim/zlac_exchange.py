"""A ZLAC8015D's steady velocity command in one compiled call: what it requests and what the drive does with it.

Rule: it gives what the sim's direct path gives request by request - the host's link on its direct lane
(:class:`~joints.link.lane.LinkLane`), the bus, the :class:`~joints.sim.modbus_front.ModbusFront`, the
firmware's light write (:meth:`~joints.sim.zlac.ZlacFirmware._write_light`) - for the FC16 of the four ramp
times (0x2080) and the FC16 of both target velocities (0x2088): the line and world arithmetic is
:mod:`joints.sim.line_exchange`'s, the drive's act (:func:`act`) the kernel ops of :mod:`joints.sim.zlac_kernel`
its own write path calls (the ramp columns the values :meth:`ZlacFirmware._cache_ramps` computes); afterwards
Python brings the link's counts and the firmware's parameter store to where that path leaves them. A status
read goes with the world's advance to its instant in one call (:meth:`ZlacExchange.read`; a held sleep of the
world, ``World.hold``, runs first, on its own): with the drive's receipt of the frame, its rows as they stand then
(the status block is read from them after the call) and the reply's travel (:func:`status_read`) where the act
is the twin's stock status block.

It runs only in the steady case, checked before anything is sent: numba present, the lane open for every
request, the world running fused, the bus, front, firmware and line the stock ones (nothing replaced, nothing
pending or stale), every value one the firmware takes in its light write and every reply one the host takes as
the plain answer, and no frame of the line's log able to overlap the first request. Anything else returns
False and the caller sends the requests the usual way (tests/sim/test_compiled_zlac.py compares both bit for
bit).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from joints.codecs import modbus as mb
from joints.sim import kernel
from joints.sim import line_exchange as L
from joints.sim import zlac_kernel as Z
from joints.sim.kernel import jitable
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
from joints.sim.stepping import ZLAC
from joints.sim.zlac import ZlacFirmware, _ramp_seconds
from joints.transports.serial_sim import TimedSerialLine

__all__ = ["ZlacExchange", "act", "status_read"]

#: ops (column OP of a transaction row); READ: the status read of a one-call step (:meth:`ZlacExchange.step`)
RAMPS, TARGETS, READ = 0, 1, 2
#: the family's columns of a transaction row (after :mod:`joints.sim.line_exchange`'s): op, four values (ramps:
#: acceleration L/R, deceleration L/R [s]; targets: left, right [r/min]; a read: whether it settles, then 0)
OP, V0, V1, V2, V3 = range(L.ARGS, L.ARGS + 5)


@jitable
def act(table: Any, first: int, t: Any) -> None:
    """The drive (rows from ``first``) acts on a frame (:meth:`ZlacFirmware.frame_received`, then the light
    write's effects)."""
    d = table[first]
    Z.frame(d)
    left = table[first + 1]
    right = table[first + 2]
    if t[OP] == RAMPS:  # ZlacFirmware._cache_ramps of the values just stored
        left[Z.ACC_TIME] = t[V0]
        left[Z.DEC_TIME] = t[V2]
        right[Z.ACC_TIME] = t[V1]
        right[Z.DEC_TIME] = t[V3]
    elif t[OP] == TARGETS and d[Z.D_STATE] == Z.ENABLED and d[Z.D_MODE] == Z.VELOCITY:  # enabled, velocity mode
        Z.set_velocity_target(d, left, t[V0])
        Z.set_velocity_target(d, right, t[V1])


@jitable
def status_read(behind: float, seen: float, settle: bool, first: int, snap: Any, st: Any, w: int, mj_step: int,
                table: Any, adr: Any, ratio: Any, order: Any, worlds: Any, dts: Any, active: Any) -> None:
    """A status read in one call: the line's sleep to the instant the drive acts (``behind``: a held sleep's
    substeps first, :func:`joints.sim.line_exchange.advance`), the drive's frame receipt
    (:meth:`ZlacFirmware.frame_received`) and its three rows as they stand then into ``snap`` (the status block
    is read from them after the call); the reply's travel to ``seen`` booked (``World.book``) and, if ``settle``,
    its physics run (``World.sync``: what the caller's next access to the world runs)."""
    L.advance(behind, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
    Z.frame(table[first])
    for k in range(3):
        snap[k, :] = table[first + k]
    late = seen - st[L.CLOCK]
    if late > 0:  # World.book
        st[L.TARGET] += late
        st[L.BOOKED] = 1.0
        st[L.CLOCK] = st[L.TARGET]
        st[L.SEEN] = st[L.CLOCK]
    if settle:
        L.advance(0.0, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)


# (compiled into step_call: the transactions' own arithmetic, as the one-call exchange runs it)
jitable(L.exchanges)


def step_call(tx: Any, out: Any, snap: Any, st: Any, w: int, mj_step: int, table: Any, adr: Any, ratio: Any,
              order: Any, worlds: Any, dts: Any, active: Any) -> None:
    """A one-call step (:meth:`ZlacExchange.step`): the transactions ``tx`` (the FC16s, the host's hold to the
    env's tick, the status read last: :func:`joints.sim.line_exchange.exchanges`), then the drive's three rows as
    the read found them into ``snap`` (no substep ran since: the reply's travel is booked) and, if the read
    settles, its physics (``World.sync``, as :func:`status_read`'s)."""
    L.exchanges(tx, out, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
    t = tx[tx.shape[0] - 1]
    first = int(t[L.ROW])
    for k in range(3):
        snap[k, :] = table[first + k]
    if t[V0] != 0.0:
        L.advance(0.0, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)


_STATUS_READ: list[Any] = []
_STEP_CALL: list[Any] = []


def _step_call() -> Any:
    """:func:`step_call` compiled (numba), or None without it."""
    if not _STEP_CALL:
        _STEP_CALL.append(kernel.compiled(step_call) if L.compiled()[0] is not None else None)
    return _STEP_CALL[0]


def _status_read() -> Any:
    """:func:`status_read` compiled (numba), or None without it."""
    if not _STATUS_READ:
        _STATUS_READ.append(kernel.compiled(status_read) if L.compiled()[1] is not None else None)
    return _STATUS_READ[0]


#: the line's methods the read's advance assumes, as defined
_LINE = ((TimedSerialLine, "_transact_idle", TimedSerialLine._transact_idle),
         (TimedSerialLine, "_plain_peer", TimedSerialLine._plain_peer))
#: the stock methods the requests would go through (a replaced one - a test planting replies - means no fusion)
_STOCK = ((ModbusDeviceBus, "exchange", ModbusDeviceBus.exchange), (ModbusFront, "handle", ModbusFront.handle),
          (ModbusFront, "write", ModbusFront.write), (ZlacFirmware, "write_many", ZlacFirmware.write_many),
          (ZlacFirmware, "_write_light", ZlacFirmware._write_light), (ZlacFirmware, "on_write", ZlacFirmware.on_write),
          (ZlacFirmware, "frame_received", ZlacFirmware.frame_received),
          (ZlacFirmware, "_cache_ramps", ZlacFirmware._cache_ramps), *_LINE)
#: the stock methods a status read goes through (the bus's act, :meth:`ZlacExchange.read`)
_STOCK_READ = ((ModbusDeviceBus, "exchange", ModbusDeviceBus.exchange), (ModbusFront, "handle", ModbusFront.handle),
               (ModbusFront, "read", ModbusFront.read), (ModbusFront, "read_plan", ModbusFront.read_plan),
               (ModbusFront, "pack", ModbusFront.pack), (ZlacFirmware, "frame_received", ZlacFirmware.frame_received),
               (ZlacFirmware, "reader", ZlacFirmware.reader), (ZlacFirmware, "_read_status", ZlacFirmware._read_status),
               (ZlacFirmware, "_status_of", ZlacFirmware._status_of), *_LINE)


def _world_of(bus: Any, clock: Any) -> Any:
    """The world whose physics runs between ``bus``'s frames (the world's own note on the bus, else the world
    the clock's sleep advances), or None."""
    world = getattr(bus, "world", None)
    if world is None:
        world = getattr(getattr(clock, "_on_sleep", None), "__self__", None)
    from joints.sim.world import World

    return world if isinstance(world, World) else None


#: the two blocks: (start address, words) -> op and the parameters the front makes of its words, in order
_BLOCKS = {(0x2080, 4): (RAMPS, ("acceleration_time_left", "acceleration_time_right", "deceleration_time_left",
                                  "deceleration_time_right")),
           (0x2088, 2): (TARGETS, ("target_velocity_left", "target_velocity_right"))}


class ZlacExchange(L.Carrier):
    """The steady FC16s of one ZLAC8015D twin behind ``lane`` (the host link's direct lane,
    :class:`joints.link.lane.LinkLane`; see the module docstring)."""

    def __init__(self, lane: Any, slave: int) -> None:
        super().__init__(L.OUTS)
        self.lane = lane
        self.slave = slave
        self.reads = 0  #: status reads sent with the world's advance in one call (:meth:`read`)
        #: calls that ran a held sleep's substeps (``World.hold``: the env's period hold) first, in the same call
        self.held = 0
        #: of the reads, those whose drive's act (frame receipt, rows) ran in the call (:meth:`_status_act`)
        self.acts = 0
        self._snap: Any = None
        self._blank: tuple[Any, int] | None = None
        self._world: Any = None
        self._bus: Any = None

    def carried(self) -> tuple[Any, list[Any]] | None:
        """(the world, [the twin]) where every frame to the twin goes over a timed line on the world's clock (which
        settles the world before the twin acts on a frame: ``TimedSerialLine`` over the clock the world binds, or
        this exchange); None otherwise (an untimed transport hands frames to the twin without settling)."""
        lane = self.lane
        line, framing = lane.line, lane.framing
        if line is None or framing is None:
            return None
        bus = framing.peer
        if type(bus) is not ModbusDeviceBus or line.peer is not bus:
            return None
        front = bus.slaves.get(self.slave)
        if type(front) is not ModbusFront or type(front.firmware) is not ZlacFirmware:
            return None
        world = _world_of(bus, line.clock)
        if world is None or line.clock is not world.clock or line._settle is None:
            return None
        return world, [front.firmware]

    def _fused_world(self, line: TimedSerialLine, bus: Any) -> Any:
        """The world between ``bus``'s frames where it runs fused on ``line``'s clock, else None."""
        if self._bus is not bus:
            self._bus, self._world = bus, _world_of(bus, line.clock)
        world = self._world
        return world if world is not None and line.clock is world.clock and L.world_fused(world) else None

    def _parts(self) -> tuple[Any, ModbusFront, ZlacFirmware, TimedSerialLine] | None:
        """(world, front, firmware, line) where they are as the compiled call assumes, else None."""
        lane = self.lane
        line, framing = lane.line, lane.framing
        if line is None or framing is None or not L.stock(_STOCK):
            return None
        bus = framing.peer
        if type(bus) is not ModbusDeviceBus or line.peer is not bus:
            return None
        front = bus.slaves.get(self.slave)
        if type(front) is not ModbusFront:
            return None
        fw = front.firmware
        if type(fw) is not ZlacFirmware or fw.pending or fw._stale or fw._stale_ramps or fw.DELAYED:
            return None
        world = self._fused_world(line, bus)
        return None if world is None else (world, front, fw, line)

    def write(self, requests: Sequence[mb.WriteMultipleRegisters]) -> bool:
        """Send ``requests`` (the ramp FC16 then the target FC16, or the target FC16 alone) as the lane would,
        one after the other; False (nothing sent) where this is not the steady case."""
        fn = L.compiled()[0]
        if fn is None:
            return False
        parts = self._ready()
        if parts is None:
            return False
        world, _, fw, line = parts
        got = self._writes(requests, parts)
        if got is None:
            return False
        rows, made = got
        with self.lane.link._lock, world.lock:
            now = L.clear(line)
            if now is None:
                return False
            self._send_writes(world, fw, rows)
            outs = self.carry(fn, world, line, now, rows)
            self._written(fw, line, rows, outs, made)
        return True

    def _ready(self) -> tuple[Any, ModbusFront, ZlacFirmware, TimedSerialLine] | None:
        """:meth:`_parts` where the lane is idle too (``LinkLane._open`` of each request: the lane's state once)."""
        return self._parts() if self.lane._idle() else None

    def _writes(self, requests: Sequence[mb.WriteMultipleRegisters],
                parts: tuple[Any, ModbusFront, ZlacFirmware, TimedSerialLine]
                ) -> tuple[list[list[float]], list[tuple[Any, Any]]] | None:
        """(the transaction rows of ``requests``, each one's reply and the parameters it stores) where each is plain
        and every value one the twin (``parts``: :meth:`_ready`'s) takes in its light write, else None (nothing
        sent; the rule's check raises before anything is sent, as the lane's)."""
        lane = self.lane
        plain = lane._plain
        for r in requests:
            if not plain(r):
                return None
        _, front, fw, line = parts
        link = lane.link
        framing = lane.framing
        assert framing is not None
        rule = link.rule
        check, is_reply, as_received, turnaround = rule.check, rule.is_reply, framing.as_received, framing._turnaround
        size = framing.size
        limits = fw._limits
        table = front.table
        rows: list[list[float]] = []
        made: list[tuple[Any, list[tuple[str, int]]]] = []
        for r in requests:
            check(r)  # raises EncodeError before anything is sent, as the lane
            words = r.values
            plan = _plan(table, r.address, len(words))
            if plan is None:
                return None
            op, names, signed = plan
            items: list[tuple[str, int]] = []
            for word, name, sign in zip(words, names, signed):  # as ModbusFront.write makes them
                value = word & 0xFFFF
                if sign and value & 0x8000:
                    value -= 0x10000
                writable, lo, hi = limits[name]
                if not (writable and lo <= value <= hi):
                    return None  # refused: the front answers it its way
                items.append((name, value))
            if op == RAMPS:
                values = [_ramp_seconds(v) for _, v in items]
            else:
                values = [float(items[0][1]), float(items[1][1]), 0.0, 0.0]
            reply = mb.WriteMultipleRegistersReply(r.slave, r.address, len(words))
            if as_received(r, reply) is not reply or not is_reply(r, reply):
                return None
            turn = turnaround(r)
            rows.append([ZLAC, 0.0, float(size(r)), line.turnaround if turn is None else turn, float(size(reply)),
                         float(op), *values])
            made.append((reply, items))
        return rows, made

    def _send_writes(self, world: Any, fw: ZlacFirmware, rows: list[list[float]]) -> None:
        """The counts of the FC16 ``rows`` about to go (the line clear), their drive's row set (under the locks)."""
        first = float(self._first_row(world.group, fw))
        for row in rows:
            row[L.ROW] = first
        n = len(rows)
        if world._held:
            self.held += 1
        lane = self.lane
        lane.link.transactions += n
        assert lane.framing is not None
        lane.framing.exchanges += n

    def _written(self, fw: ZlacFirmware, line: TimedSerialLine, rows: Sequence[Sequence[float]],
                 outs: Sequence[Sequence[float]], made: list[tuple[Any, Any]]) -> None:
        """What the FC16 ``rows`` leave once carried (``outs``): the parameter store, the frames, the counts."""
        for _, items in made:
            fw._keep(items)  # the parameter store's part of the light write (its row effects ran)
        L.book(line, rows, outs, [reply for reply, _ in made])
        self.lane.taken += len(rows)
        self.taken += 1

    def steady(self, status: mb.ReadHoldingRegisters) -> Any:
        """Whether a one-call :meth:`step` with the status read ``status`` may run now, asked before its FC16s are
        planned (the lane, line, world and twin as the call assumes, the read's act the twin's stock status block:
        :meth:`_status_act`): what :meth:`step` takes, or None."""
        fn = _step_call()
        if fn is None or not self.lane._open(status):
            return None
        parts = self._ready()
        if parts is None:
            return None
        world, _, fw, _ = parts
        link = self.lane.link
        framing = self.lane.framing
        act = None if framing is None else self._status_act(status, framing.peer)
        if act is None or act[2] is not fw or link.clock is not world.clock or not L.sleeps_held(world):
            return None
        return fn, parts, act

    def step(self, steady: Any, writes: Sequence[mb.WriteMultipleRegisters], status: mb.ReadHoldingRegisters,
             until: float, *, settle: bool = False) -> tuple[Any, float, float] | None:
        """:meth:`write` of ``writes``, the host's wait for the env's tick at clock time ``until`` (``RigEnv.
        _wait_until`` with the world holding the rig's sleep: :func:`joints.sim.line_exchange.hold`) and
        :meth:`read` of ``status`` (``settle`` as there) in ONE compiled call (:func:`step_call`; ``steady``:
        :meth:`steady`'s answer, asked just before): (the reply, what was left to the tick - <= 0: late -, the
        clock after the hold); None (nothing sent) where it is not the steady case."""
        fn, parts, (plan, reader, _) = steady
        world, _, fw, line = parts
        link = self.lane.link
        try:  # the rule's checks raise before anything is sent: the three one by one raise it at its turn
            got = self._writes(writes, parts)
            if got is None:
                return None
            link.rule.check(status)
        except Exception:  # noqa: BLE001 - nothing sent: the caller's own way raises it again
            return None
        rows, made = got
        framing = self.lane.framing
        assert framing is not None
        row = self._read_row(status, line, settle)
        with link._lock, world.lock:
            now = L.clear(line)
            if now is None:
                return None
            self._send_writes(world, fw, rows)
            n = len(rows)
            row[L.ROW] = rows[0][L.ROW]
            outs, (d, left, right) = self._carry_step(fn, world, line, now, [
                *rows, L.hold_row(until), row])
            self._written(fw, line, rows, outs[:n], made)
            h, o = outs[n], outs[n + 1]
            remaining, held = h[L.REMAINING], h[L.CLOCK_AFTER]
            # the status read (read's own way, from the tick on): its counts, its deadline, the reply of the rows
            link.transactions += 1
            deadline = held + link.policy.timeout  # from the request's start (the clock after the hold), as the link's
            framing.exchanges += 1
            if held > outs[n - 1][L.CLOCK_AFTER]:  # the world held the sleep when the read began
                self.held += 1
            raw = mb.ReadRegistersReply(status.slave, status.function,
                                        ModbusFront.pack(plan, reader(d, left, right), status.count))
            L.book(line, (row,), (o,), (raw,))
            self.acts += 1
            self.reads += 1
            return self.lane._finish(status, raw, deadline, True), remaining, held

    def _carry_step(self, fn: Any, world: Any, line: TimedSerialLine, now: float, rows: list[list[float]]
                    ) -> tuple[list[list[float]], list[list[float]]]:
        """:meth:`~joints.sim.line_exchange.Carrier.carry` of a one-call step's ``rows`` by ``fn`` (:func:`step_call`):
        each row's output and the drive's three rows as its status read found them."""
        n = len(rows)
        buffers = self._buffers.get(n)  # (the rows' and outputs' buffers of :meth:`carry`, by count)
        snap = self._snap
        if buffers is None or snap is None:
            import numpy as np

            if buffers is None:
                buffers = self._buffers[n] = (np.zeros((n, L.TX_WIDTH)), np.zeros((n, L.OUTS)))
            if snap is None:
                snap = self._snap = np.zeros((3, Z.WIDTH))
        tx, out = buffers
        tx[:] = rows
        st = self._st
        L.fill(st, world, line, now)
        L.line_back(line, L.fused(fn, world, st, tx, out, snap))
        return out.tolist(), snap.tolist()

    def _read_row(self, request: mb.ReadHoldingRegisters, line: TimedSerialLine, settle: bool) -> list[float]:
        """The transaction row of the status read ``request`` in a one-call step (its reply's size that of a
        reply of its words, kept by the request's identity, as :meth:`read`'s)."""
        framing = self.lane.framing
        assert framing is not None
        size = framing.size
        blank = self._blank
        if blank is None or blank[0] is not request:
            blank = self._blank = (request, size(mb.ReadRegistersReply(request.slave, request.function,
                                                                       (0,) * request.count)))
        turn = framing._turnaround(request)
        return [ZLAC, 0.0, float(size(request)), line.turnaround if turn is None else turn, float(blank[1]),
                float(READ), 1.0 if settle else 0.0, 0.0, 0.0, 0.0]

    def _status_act(self, request: Any, bus: Any) -> tuple[Any, Any, Any] | None:
        """(the front's read plan, the rows' reader, the firmware) where the bus's act on the status read
        ``request`` is the twin's stock status block (frame receipt, then the fast reader:
        :meth:`ZlacFirmware.reader`), so the rows it reads can be taken in the compiled call; else None."""
        if type(request) is not mb.ReadHoldingRegisters or request.slave == 0 or type(bus) is not ModbusDeviceBus \
                or not L.stock(_STOCK_READ):
            return None
        front = bus.slaves.get(request.slave)
        if type(front) is not ModbusFront or type(front.firmware) is not ZlacFirmware:
            return None
        fw = front.firmware
        plan = front.read_plan(request.address, request.count)
        pair = fw.status_reader
        if isinstance(plan, int) or pair is None or plan[0] is not pair[0]:
            return None
        return plan, pair[1], fw

    def read(self, request: mb.ReadHoldingRegisters, *, idempotent: bool = True, settle: bool = False
             ) -> tuple[bool, Any]:
        """``LinkLane.request(request)`` of a status read, the world's advance to the instant the drive acts on
        it in one compiled call: (True, the reply) - or (False, None), nothing sent, where the line or world is
        not as assumed. Where the drive's act is its stock status block (:meth:`_status_act`), the call also takes
        the frame's receipt and the drive's rows then, books the reply's travel and - ``settle``: the caller's
        next access to the world is one that runs booked time (``World.sync``) - runs its physics; the status
        block is read from those rows after the call. Else the act is the bus's own (``framing.peer.exchange``,
        whatever it answers). A reply that is not the plain answer continues as the lane's does (the link's
        attempt and retries)."""
        fn = L.compiled()[1]
        lane = self.lane
        if fn is None or not lane._open(request):
            return False, None
        line, framing = lane.line, lane.framing
        if line is None or framing is None or not L.stock(_LINE):
            return False, None
        world = self._fused_world(line, framing.peer)
        if world is None:
            return False, None
        fast = _status_read()
        act = None if fast is None else self._status_act(request, framing.peer)
        link = lane.link
        link.rule.check(request)  # raises EncodeError before anything is sent
        clock = world.clock
        with link._lock, world.lock:
            now = L.clear(line)  # (the lane's own way calls _sync again: a second call changes nothing)
            if now is None:
                return False, None
            free = line._free
            start = max(now, free["host"])
            link.transactions += 1
            deadline = link.clock.now() + link.policy.timeout  # from the request's start, as the link's
            framing.exchanges += 1
            size = framing.size
            turn = framing._turnaround(request)
            n = size(request)
            end = start + n * line.char_time  # TimedSerialLine._put of the host's frame
            due = end + line.gap + (line.turnaround if turn is None else turn)
            free["host"] = end + line.gap
            line.book_frames([(start, end, due, n, "host", None)])
            behind = due - clock.now()
            st = self._st
            if act is not None:  # the advance, the drive's receipt and rows, the reply's travel: one call
                plan, rows, fw = act
                blank = self._blank  # the reply's characters (of its size alone), kept by the request's identity
                if blank is None or blank[0] is not request:
                    blank = self._blank = (request, size(mb.ReadRegistersReply(request.slave, request.function,
                                                                               (0,) * request.count)))
                m = blank[1]
                d_start = max(due, free["device"])
                d_end = d_start + m * line.char_time
                seen = d_end + line.adapter_latency
                if world._held:
                    self.held += 1
                if self._snap is None:
                    import numpy as np

                    self._snap = np.zeros((3, Z.WIDTH))
                L.fill(st, world, line, now)
                state = L.fused(fast, world, st, behind, seen, settle, self._first_row(world.group, fw), self._snap)
                line._clock_seen = state[L.SEEN]
                d, left, right = self._snap.tolist()
                raw: Any = mb.ReadRegistersReply(request.slave, request.function,
                                                 ModbusFront.pack(plan, rows(d, left, right), request.count))
                line.now = max(line.now, due)
                free["device"] = d_end + line.gap
                line.book_frames([(d_start, d_end, seen, m, "device", raw)])
                self.acts += 1
            else:
                if behind > 0 or world._booked:  # the physics runs to the instant the drive acts (sleep, settle)
                    if world._held:
                        self.held += 1
                    L.fill(st, world, line, now)
                    state = L.fused(fn, world, st, behind)
                    if behind > 0:
                        line._clock_seen = state[L.SEEN]
                raw = framing.peer.exchange(request)  # the drive acts (the lane's act)
                line.now = max(line.now, due)
                if raw is None:
                    self.reads += 1
                    return True, lane._finish(request, raw, deadline, idempotent)
                # the reply (TimedSerialLine._put of the device's frame), booked while it travels
                m = size(raw)
                d_start = max(due, free["device"])
                d_end = d_start + m * line.char_time
                seen = d_end + line.adapter_latency
                free["device"] = d_end + line.gap
                line.book_frames([(d_start, d_end, seen, m, "device", raw)])
                late = seen - clock.now()
                if late > 0:
                    clock.book(late)
                    line._clock_seen = clock.now()
            free["host"] = max(free["host"], seen + line.gap)
            line.now = max(line.now, seen)
            self.reads += 1
            return True, lane._finish(request, raw, deadline, idempotent)


_Plan = tuple[int, tuple[str, ...], tuple[bool, ...]]
#: (id of a register table, start address, words) -> (the table, its plan: op, the parameters the front makes of
#: the words, each word's register is signed - or None where the table does not hold the block's one-word writable
#: registers there); tables are immutable: checked once per table
_PLANS: dict[tuple[int, int, int], tuple[Any, _Plan | None]] = {}


def _plan(table: Any, address: int, words: int) -> _Plan | None:
    """What an FC16 of ``words`` words at ``address`` writes on a front with register ``table``: (op, names, signed)
    of one of the two blocks (:data:`_BLOCKS`), or None (another block, or a table that does not hold it; as
    ``ModbusFront.write`` makes the values: each word masked, a signed register's two's complement)."""
    key = (id(table), address, words)
    known = _PLANS.get(key)
    if known is not None and known[0] is table:
        return known[1]
    block = _BLOCKS.get((address, words))
    plan = None
    if block is not None:
        op, names = block
        regs = [table.owner(address + i) for i in range(words)]
        if all(r is not None and r.name == n and r.words == 1 and r.access.writable for r, n in zip(regs, names)):
            plan = (op, names, tuple(r.signed for r in regs if r is not None))
    _PLANS[key] = (table, plan)
    return plan

