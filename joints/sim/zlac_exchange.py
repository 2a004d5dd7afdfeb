"""One compiled call for a ZLAC8015D's steady velocity command over a timed RS485 line: frames, physics, ops.

Rule: it gives what the sim's direct path gives request by request - the host's link on its direct lane
(:class:`~joints.link.lane.LinkLane`, :meth:`~joints.transports.serial_sim.TimedSerialLine._transact_idle`),
the bus, the :class:`~joints.sim.modbus_front.ModbusFront`, the firmware's light write
(:meth:`~joints.sim.zlac.ZlacFirmware._write_light`) - for the FC16 of the four ramp times (0x2080) and the
FC16 of both target velocities (0x2088): the same frame instants, every float by the same operations, the
same world advances (the physics up to each instant the drive acts on a frame, the reply's travel booked),
the same register effects (the drive's frame and target ops are the kernel ops of
:mod:`joints.sim.zlac_kernel` its own write path calls; the ramp columns are the values
:meth:`ZlacFirmware._cache_ramps` computes), the same counts and replies - in one call: the frame instants
follow from the fixed request and reply sizes, the physics runs to each frame's arrival inside the compiled
call (MuJoCo's ``mj_step`` by address, :mod:`joints.sim.stepping`). Afterwards Python brings the link, the
line, the world, the clock and the firmware's parameter store to where the request-by-request path leaves them.

It runs only in the steady case, checked before anything is sent: numba present, the lane open for every
request, the world running fused (compiled, every drive a kernel row, nothing ticking after substeps), the
bus, front, firmware and line the stock ones (nothing replaced, nothing pending or stale), every value one the
firmware takes in its light write and every reply one the host takes as the plain answer, and no frame of the
line's log able to overlap the first request. Anything else returns None and the caller sends the requests
the usual way. This is the ZLAC8015D's counterpart of the eRob's one-call exchange; both follow the line's
and the world's arithmetic step by step (tests/sim/test_compiled_zlac.py compares the results bit for bit).
"""

# ruff: noqa: PLR1730, FURB136 - the comparisons are the line's own (``max`` of Python and of numba alike on ties)
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from joints.codecs import modbus as mb
from joints.sim import kernel, stepping
from joints.sim import zlac_kernel as Z
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
from joints.sim.zlac import ZlacFirmware, _ramp_seconds
from joints.transports.serial_sim import LOG_KEEP, TimedSerialLine, Transmission

__all__ = ["ZlacExchange"]

#: ops (column OP of a transaction row)
RAMPS, TARGETS = 0, 1
#: columns of a transaction row: op, four values (ramps: acceleration L/R, deceleration L/R [s]; targets:
#: left, right [r/min]), request characters, turnaround [s], reply characters
OP, V0, V1, V2, V3, REQUEST, TURN, REPLY = range(8)
TX_WIDTH = 8
#: columns of the state vector: the clock's time, the world's target time, whether time is booked, the
#: line's time, the time the line last saw on the clock, when the host's / device's UART is free, the line's
#: character time, gap, adapter latency, the world's timestep
CLOCK, TARGET, BOOKED, NOW, SEEN, FREE_HOST, FREE_DEVICE, CHAR, GAP, LATENCY, DT = range(11)
#: columns of an output row: host frame start, end, due; device frame start, end, seen
H_START, H_END, H_DUE, D_START, D_END, D_SEEN = range(6)


#: the world's substeps (:func:`joints.sim.stepping._run`, compiled), called from inside the compiled call
_run_steps: Any = getattr(stepping, "_run_compiled", None)


def _advance(seconds: float, st: Any, w: int, mj_step: int, table: Any, adr: Any, ratio: Any, order: Any,
             worlds: Any, dts: Any, active: Any) -> None:
    """``World._step_due(World._due(seconds))`` of a fused world without ticks (``World.advance``/``sync``)."""
    st[TARGET] += seconds
    dt = st[DT]
    n = math.ceil((st[TARGET] - worlds[w, stepping.STEPS] * dt) / dt - 1e-9)
    if n > 0:
        _run_steps(n, 1, mj_step, table, adr, ratio, order, worlds, dts, active)
        worlds[w, stepping.STEPS] += n


def _act(table: Any, first: int, t: Any) -> None:
    """The drive acts on a frame (:meth:`ZlacFirmware.frame_received`, then the light write's effects)."""
    d = table[first]
    Z.frame(d)
    left = table[first + 1]
    right = table[first + 2]
    if t[OP] == RAMPS:  # ZlacFirmware._cache_ramps of the values just stored
        left[Z.ACC_TIME] = t[V0]
        left[Z.DEC_TIME] = t[V2]
        right[Z.ACC_TIME] = t[V1]
        right[Z.DEC_TIME] = t[V3]
    elif d[Z.D_STATE] == Z.ENABLED and d[Z.D_MODE] == Z.VELOCITY:  # enabled, velocity mode
        Z.set_velocity_target(d, left, t[V0])
        Z.set_velocity_target(d, right, t[V1])


def exchanges(tx: Any, st: Any, out: Any, first: int, w: int, mj_step: int, table: Any, adr: Any, ratio: Any,
              order: Any, worlds: Any, dts: Any, active: Any) -> None:
    """The transactions ``tx`` (rows of :data:`TX_WIDTH`) of the drive whose rows start at ``first`` of ``table``
    in world ``w``, one after the other, as ``TimedSerialLine._transact_idle`` carries each: ``st`` (the state
    vector) in and out, each transaction's frame instants into ``out``."""
    for k in range(tx.shape[0]):
        t = tx[k]
        o = out[k]
        if k:  # TimedSerialLine._sync: the clock moved without the line (a booked reply)
            c = st[CLOCK]
            if c > st[SEEN]:
                st[SEEN] = c
                if c > st[NOW]:
                    st[NOW] = c
        now = st[NOW]
        free = st[FREE_HOST]  # TimedSerialLine._put of the host's frame
        start = free if free > now else now
        end = start + t[REQUEST] * st[CHAR]
        due = end + st[GAP] + t[TURN]
        st[FREE_HOST] = end + st[GAP]
        o[H_START] = start
        o[H_END] = end
        o[H_DUE] = due
        behind = due - st[CLOCK]
        if behind > 0:  # the physics runs to the instant the drive acts (World.advance)
            st[BOOKED] = 0.0
            _advance(behind, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
            st[CLOCK] = st[TARGET]
            st[SEEN] = st[CLOCK]
        if st[BOOKED] != 0.0:  # World.sync: booked time runs before the drive acts
            st[BOOKED] = 0.0
            _advance(0.0, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
        _act(table, first, t)
        if due > st[NOW]:
            st[NOW] = due
        free = st[FREE_DEVICE]  # the reply (TimedSerialLine._put of the device's frame), booked (World.book)
        start = free if free > due else due
        end = start + t[REPLY] * st[CHAR]
        seen = end + st[LATENCY]
        st[FREE_DEVICE] = end + st[GAP]
        o[D_START] = start
        o[D_END] = end
        o[D_SEEN] = seen
        behind = seen - st[CLOCK]
        if behind > 0:
            st[TARGET] += behind
            st[BOOKED] = 1.0
            st[CLOCK] = st[TARGET]
            st[SEEN] = st[CLOCK]
        gapped = seen + st[GAP]
        if gapped > st[FREE_HOST]:
            st[FREE_HOST] = gapped
        if seen > st[NOW]:
            st[NOW] = seen


def advance(seconds: float, st: Any, w: int, mj_step: int, table: Any, adr: Any, ratio: Any, order: Any,
            worlds: Any, dts: Any, active: Any) -> None:
    """The line's sleep of ``seconds`` (if > 0: ``World.advance``) to the instant a drive acts on a frame, then
    its settle (``World.sync``: booked time runs), on the state vector of a fused world without ticks."""
    if seconds > 0:
        st[BOOKED] = 0.0
        _advance(seconds, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
        st[CLOCK] = st[TARGET]
        st[SEEN] = st[CLOCK]
    if st[BOOKED] != 0.0:
        st[BOOKED] = 0.0
        _advance(0.0, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)


_COMPILED: list[Any] = []
_ADVANCE: list[Any] = []


def _compiled() -> Any:
    """:func:`exchanges` compiled (numba), or None without it (or with ``JOINTS_COMPILED=0``: the world then
    does not run fused, and the steady check sends the requests the usual way)."""
    if not _COMPILED:
        if kernel.AVAILABLE and _run_steps is not None:
            kernel.jitable(_advance)
            kernel.jitable(_act)
            _COMPILED.append(kernel.compiled(exchanges))
            _ADVANCE.append(kernel.compiled(advance))
        else:  # pragma: no cover - depends on the install
            _COMPILED.append(None)
            _ADVANCE.append(None)
    return _COMPILED[0]


#: the stock methods the requests would go through (a replaced one - a test planting replies - means no fusion)
_STOCK = ((ModbusDeviceBus, "exchange", ModbusDeviceBus.exchange), (ModbusFront, "handle", ModbusFront.handle),
          (ModbusFront, "write", ModbusFront.write), (ZlacFirmware, "write_many", ZlacFirmware.write_many),
          (ZlacFirmware, "_write_light", ZlacFirmware._write_light), (ZlacFirmware, "on_write", ZlacFirmware.on_write),
          (ZlacFirmware, "frame_received", ZlacFirmware.frame_received),
          (ZlacFirmware, "_cache_ramps", ZlacFirmware._cache_ramps),
          (TimedSerialLine, "_transact_idle", TimedSerialLine._transact_idle),
          (TimedSerialLine, "_plain_peer", TimedSerialLine._plain_peer))


_TRANSACT_IDLE = TimedSerialLine._transact_idle
_PLAIN_PEER = TimedSerialLine._plain_peer


def _stock() -> bool:
    return all(getattr(cls, name) is fn for cls, name, fn in _STOCK)


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


class ZlacExchange:
    """The steady FC16s of one ZLAC8015D twin behind ``lane`` (the host link's direct lane,
    :class:`joints.link.lane.LinkLane`; see the module docstring)."""

    def __init__(self, lane: Any, slave: int) -> None:
        self.lane = lane
        self.slave = slave
        self.taken = 0  #: calls that ran (each of one or two transactions)
        self.reads = 0  #: status reads sent with the world's advance in one call (:meth:`read`)
        self._group: Any = None
        self._first = 0
        self._world: Any = None
        self._bus: Any = None
        self._st: Any = None

    def _parts(self) -> tuple[Any, ModbusFront, ZlacFirmware, TimedSerialLine] | None:
        """(world, front, firmware, line) where they are as the compiled call assumes, else None."""
        lane = self.lane
        line, framing = lane.line, lane.framing
        if line is None or framing is None or not _stock():
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
        if self._bus is not bus:
            self._bus, self._world = bus, _world_of(bus, line.clock)
        world = self._world
        if world is None or line.clock is not world.clock or world._ticks or world._bind != world._bind_seen:
            return None
        group = world.group
        if not (group.compiled and group.fusable[world.group_index]):
            return None
        return world, front, fw, line

    def _row_first(self, group: Any, fw: ZlacFirmware) -> int:
        """The firmware's first row in ``group``'s table (kept per group: a batch may join the world to another)."""
        if self._group is not group:
            self._first = next(first for twin, first in group._owners if twin is fw)
            self._group = group
        return self._first

    def write(self, requests: Sequence[mb.WriteMultipleRegisters]) -> bool:
        """Send ``requests`` (the ramp FC16 then the target FC16, or the target FC16 alone) as the lane would,
        one after the other; False (nothing sent) where this is not the steady case."""
        fn = _COMPILED[0] if _COMPILED else _compiled()
        if fn is None:
            return False
        lane = self.lane
        for r in requests:
            if not lane._open(r):
                return False
        parts = self._parts()
        if parts is None:
            return False
        world, front, fw, line = parts
        link = lane.link
        framing = lane.framing
        assert framing is not None
        rule = link.rule
        size = framing.size
        limits = fw._limits
        rows: list[list[float]] = []
        made: list[tuple[Any, list[tuple[str, int]]]] = []
        for r in requests:
            rule.check(r)  # raises EncodeError before anything is sent, as the lane
            words = r.values
            block = _BLOCKS.get((r.address, len(words)))
            if block is None:
                return False
            op, names = block
            items = _items(front, r, names)
            if items is None:
                return False
            for name, value in items:
                writable, lo, hi = limits[name]
                if not (writable and lo <= value <= hi):
                    return False  # refused: the front answers it its way
            if op == RAMPS:
                values = [_ramp_seconds(v) for _, v in items]
            else:
                values = [float(items[0][1]), float(items[1][1]), 0.0, 0.0]
            reply = mb.WriteMultipleRegistersReply(r.slave, r.address, len(words))
            if framing.as_received(r, reply) is not reply or not rule.is_reply(r, reply):
                return False
            turn = framing._turnaround(r)
            rows.append([float(op), *values, float(size(r)), line.turnaround if turn is None else turn,
                         float(size(reply))])
            made.append((reply, items))
        import numpy as np

        clock = world.clock
        with link._lock, world.lock:
            now = line._sync()
            log, latest = line.log, line._latest_end
            free = line._free
            start = max(now, free["host"])
            if len(latest) != len(log) or (len(log) > line._epoch and latest[-1] > start):
                return False  # an edited log, or a frame that may overlap the first request: the lane's own way
            group = world.group
            w = world.group_index
            table = group.worlds_table
            table[w, stepping.STEPS] = world.steps
            st = np.array([clock.now(), world._target, 1.0 if world._booked else 0.0, now, line._clock_seen,
                           free["host"], free["device"], line.char_time, line.gap, line.adapter_latency,
                           world.timestep])
            n = len(rows)
            tx = np.array(rows)
            out = np.zeros((n, 6))
            order, active = group._plan(world._me)
            first = self._row_first(group, fw)
            link.transactions += n
            framing.exchanges += n
            try:
                fn(tx, st, out, first, w, group.mj_step or 0, group.table, group.adr, group.ratio, order, table,
                   group.dts_array, active)
            finally:
                world.steps = int(table[w, stepping.STEPS])
                clock_now, target, booked, line_now, seen, free_host, free_device = st.tolist()[:7]
                world._target = target
                world._booked = booked != 0.0
                clock.set(clock_now)
            if world._data.maxuse_arena > group._arena_limits[w]:  # as Group.run after its calls
                world.leave_fused_path()
                group.replan()
            line.now = line_now
            line._clock_seen = seen
            free["host"] = free_host
            free["device"] = free_device
            for t, o, (reply, items) in zip(rows, out.tolist(), made):
                fw._keep(items)  # the parameter store's part of the light write (its row effects ran)
                _log(line, Transmission(o[H_START], o[H_END], "host", b"", delivered=True, due=o[H_DUE],
                                        size=int(t[REQUEST])))
                _log(line, Transmission(o[D_START], o[D_END], "device", b"", delivered=True, due=o[D_SEEN],
                                        size=int(t[REPLY]), payload=reply))
            lane.taken += n
        self.taken += 1
        return True

    def _timing(self) -> tuple[Any, TimedSerialLine] | None:
        """(world, line) where the line and the world are as the read's fused advance assumes, else None."""
        lane = self.lane
        line, framing = lane.line, lane.framing
        if line is None or framing is None:
            return None
        if TimedSerialLine._transact_idle is not _TRANSACT_IDLE or TimedSerialLine._plain_peer is not _PLAIN_PEER:
            return None
        bus = framing.peer
        if self._bus is not bus:
            self._bus, self._world = bus, _world_of(bus, line.clock)
        world = self._world
        if world is None or line.clock is not world.clock or world._ticks or world._bind != world._bind_seen:
            return None
        group = world.group
        if not (group.compiled and group.fusable[world.group_index]):
            return None
        return world, line

    def read(self, request: mb.ReadHoldingRegisters, *, idempotent: bool = True) -> tuple[bool, Any]:
        """``LinkLane.request(request)`` of a status read, the world's advance to the instant the drive acts on
        it in one compiled call: (True, the reply) - or (False, None), nothing sent, where the line or world is
        not as assumed. The drive's act is the bus's own (``framing.peer.exchange``, whatever it answers); a
        reply that is not the plain answer continues as the lane's does (the link's attempt and retries)."""
        fn = _ADVANCE[0] if _ADVANCE else (_compiled(), _ADVANCE[0])[1]
        lane = self.lane
        if fn is None or not lane._open(request):
            return False, None
        timing = self._timing()
        if timing is None:
            return False, None
        world, line = timing
        link = lane.link
        framing = lane.framing
        assert framing is not None
        rule = link.rule
        rule.check(request)  # raises EncodeError before anything is sent
        clock = world.clock
        with link._lock, world.lock:
            now = line._sync()  # (the lane's own way calls it again: a second call changes nothing)
            log, latest = line.log, line._latest_end
            free = line._free
            start = max(now, free["host"])
            if len(latest) != len(log) or (len(log) > line._epoch and latest[-1] > start):
                return False, None  # an edited log, or a frame that may overlap the request: the lane's own way
            link.transactions += 1
            deadline = link.clock.now() + link.policy.timeout  # from the request's start, as the link's
            framing.exchanges += 1
            size = framing.size
            turn = framing._turnaround(request)
            n = size(request)
            end = start + n * line.char_time  # TimedSerialLine._put of the host's frame
            due = end + line.gap + (line.turnaround if turn is None else turn)
            free["host"] = end + line.gap
            _log(line, Transmission(start, end, "host", b"", delivered=True, due=due, size=n))
            behind = due - clock.now()
            if behind > 0 or world._booked:  # the physics runs to the instant the drive acts (sleep, settle)
                group = world.group
                w = world.group_index
                table = group.worlds_table
                table[w, stepping.STEPS] = world.steps
                st = self._st
                if st is None:
                    import numpy as np

                    st = self._st = np.zeros(11)
                st[CLOCK] = clock.now()
                st[TARGET] = world._target
                st[BOOKED] = 1.0 if world._booked else 0.0
                st[SEEN] = line._clock_seen
                st[DT] = world.timestep
                order, active = group._plan(world._me)
                try:
                    fn(behind, st, w, group.mj_step or 0, group.table, group.adr, group.ratio, order, table,
                       group.dts_array, active)
                finally:
                    world.steps = int(table[w, stepping.STEPS])
                    world._target = float(st[TARGET])
                    world._booked = bool(st[BOOKED])
                    clock.set(float(st[CLOCK]))
                if behind > 0:
                    line._clock_seen = float(st[SEEN])
                if world._data.maxuse_arena > group._arena_limits[w]:  # as Group.run after its calls
                    world.leave_fused_path()
                    group.replan()
            raw = framing.peer.exchange(request)  # the drive acts (the lane's act)
            line.now = max(line.now, due)
            if raw is not None:  # the reply (TimedSerialLine._put of the device's frame), booked while it travels
                m = size(raw)
                d_start = max(due, free["device"])
                d_end = d_start + m * line.char_time
                seen = d_end + line.adapter_latency
                free["device"] = d_end + line.gap
                _log(line, Transmission(d_start, d_end, "device", b"", delivered=True, due=seen, size=m, payload=raw))
                behind = seen - clock.now()
                if behind > 0:
                    clock.book(behind)
                    line._clock_seen = clock.now()
                free["host"] = max(free["host"], seen + line.gap)
                line.now = max(line.now, seen)
            self.reads += 1
            return True, lane_finish(lane, request, raw, deadline, idempotent)


#: (register table, start address) -> each word's register is signed, or None where the table does not hold the
#: block's one-word writable registers there (tables are immutable: checked once)
_SIGNED: dict[tuple[int, int], tuple[bool, ...] | None] = {}


def _items(front: ModbusFront, request: mb.WriteMultipleRegisters, names: tuple[str, ...]
           ) -> list[tuple[str, int]] | None:
    """The firmware write (name, value) of an FC16 of one-word registers ``names`` (as ``ModbusFront.write``
    makes it: each word masked, a signed register's two's complement); None where the front's table does not
    hold exactly those registers there."""
    table = front.table
    key = (id(table), request.address)
    if key not in _SIGNED:
        regs = [table.owner(request.address + i) for i in range(len(names))]
        ok = all(r is not None and r.name == n and r.words == 1 and r.access.writable for r, n in zip(regs, names))
        _SIGNED[key] = tuple(r.signed for r in regs if r is not None) if ok else None
    signed = _SIGNED[key]
    if signed is None:
        return None
    out: list[tuple[str, int]] = []
    for word, name, sign in zip(request.values, names, signed):
        raw = word & 0xFFFF
        out.append((name, raw - 0x10000 if sign and raw & 0x8000 else raw))
    return out


def lane_finish(lane: Any, request: Any, raw: Any, deadline: float, idempotent: bool) -> Any:
    """The rest of the lane's request once the peer's reply ``raw`` (None: silence) reached the host
    (``LinkLane.request`` after its transaction: the plain answer is returned, anything else is the link's)."""
    from joints.errors import FrameError, PeerProtocolError, ReplyTimeout

    link, framing = lane.link, lane.framing
    reply = None if raw is None else framing.as_received(request, raw)
    try:  # as the link's attempt: a reply the rule refuses (another slave's) fails the attempt
        if reply is not None and not isinstance(reply, FrameError) and link.rule.is_reply(request, reply):
            lane.taken += 1
            return reply
        framing.put(reply)  # not the plain answer: the rest of the attempt and the retries are the link's
        return link._await_reply(request, deadline)
    except (ReplyTimeout, PeerProtocolError) as exc:
        link._discard_late()
        return link._attempts(request, None, idempotent, failed=exc)


def _log(line: TimedSerialLine, tx: Transmission) -> None:
    """The log's part of ``TimedSerialLine._put`` for a frame that overlaps none (checked before)."""
    log, latest = line.log, line._latest_end
    latest.append(max(tx.end, latest[-1]) if len(log) > line._epoch else tx.end)
    log.append(tx)
    if len(log) > 2 * LOG_KEEP:
        cut = len(log) - LOG_KEEP
        if cut <= line._epoch or latest[cut - 1] <= tx.start - 1.0:
            del log[:cut], latest[:cut]
            line._epoch = max(0, line._epoch - cut)
