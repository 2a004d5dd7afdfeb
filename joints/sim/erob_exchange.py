"""One compiled call for an eRob's steady Modbus requests over a timed RS485 line: frames, physics, register ops.

Rule: it gives what the sim's direct path gives request by request (the host's link over
:meth:`~joints.transports.serial_sim.TimedSerialLine._transact_idle`, the bus, the
:class:`~joints.sim.modbus_front.ModbusFront`, the firmware) - the same frame instants, every float by the
same operations, the same world advances (the physics up to each instant the drive acts on a frame, the
reply's travel booked), the same register semantics (the firmware's own writes call the same kernel ops of
:mod:`joints.sim.erob_kernel`), the same replies - in one call: the frame instants are computed up front
from the fixed request and reply sizes, the physics runs to each frame's arrival inside the compiled call
(MuJoCo's ``mj_step`` by address, :mod:`joints.sim.stepping`), the ops act on the drive's row there.
Afterwards Python brings the line, the world, the clock and the firmware's parameter store to where the
request-by-request path leaves them. The requests of several drives on one line (a rig's eRobs) go in one call
too, each acting on its own row.

It runs only in the steady case, checked before anything is sent: the world runs fused (compiled, every
drive a kernel row, nothing ticking after substeps), the line is idle and its peer acts only on host
frames, the bus, front and firmware are the stock ones (nothing replaced, nothing pending, no command
delay), every write one the firmware accepts (a plain reply), the read one of the status block. Anything
else returns None and the caller sends the requests its usual way. ``tests/sim/test_compiled_path.py``
compares both.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from joints.codecs import modbus as mb
from joints.errors import ParameterRefused
from joints.sim import erob, kernel, modbus_front, stepping
from joints.sim import erob_kernel as K
from joints.sim.erob import ErobFirmware, _StatusRead
from joints.sim.kernel import jitable
from joints.sim.modbus_front import ModbusDeviceBus, ModbusException, ModbusFront
from joints.transports import serial_sim
from joints.transports.serial_sim import TimedSerialLine

__all__ = ["ErobExchange", "prepare"]

#: ops (column OP of a transaction row): what the drive does with the frame
READ, TARGET_POSITION, START, TARGET_SPEED, TARGET_CURRENT = range(5)
#: the parameter each write op stores
OP_OF = {"target_absolute_position": TARGET_POSITION, "start_operating": START, "target_speed": TARGET_SPEED,
         "target_current": TARGET_CURRENT}
#: columns of a transaction row: op, value, request characters, turnaround [s], reply characters, motion
#: mode, target relative position, repetitive (a read's status argument), the drive's row in the table
OP, VALUE, REQUEST, TURN, REPLY, MOTION, RELATIVE, REPETITIVE, ROW = range(9)
TX_WIDTH = 9
#: columns of the state vector (in and out): the clock's time, the world's target time, whether time is
#: booked, the line's time, the time the line last saw on the clock, when the host's / device's UART is
#: free, the line's character time, gap, adapter latency, the world's timestep
CLOCK, TARGET, BOOKED, NOW, SEEN, FREE_HOST, FREE_DEVICE, CHAR, GAP, LATENCY, DT = range(11)
STATE_WIDTH = 11
#: columns of an output row: host frame start, end, due; device frame start, end, seen; the clock after the
#: transaction; then a read's status
H_START, H_END, H_DUE, D_START, D_END, D_SEEN, CLOCK_AFTER = range(7)
STATUS_AT = 7
#: then the row's columns a read's sensors see (what they stood at when the drive read them)
SENSED = (K.TIME, K.POS, K.VEL, K.I_OUT)
SENSED_AT = STATUS_AT + len(K.STATUS_NAMES)
OUT_WIDTH = SENSED_AT + len(SENSED)


@jitable
def _advance(seconds: float, st: Any, w: int, mj_step: int, table: Any, adr: Any, ratio: Any, order: Any,
             worlds: Any, dts: Any, active: Any) -> None:
    """:meth:`joints.sim.world.World._step_due` of ``World._due(seconds)`` on a fused world without ticks."""
    st[TARGET] += seconds
    dt = st[DT]
    n = math.ceil((st[TARGET] - worlds[w, stepping.STEPS] * dt) / dt - 1e-9)
    if n > 0:
        stepping._run(n, 1, mj_step, table, adr, ratio, order, worlds, dts, active)
        worlds[w, stepping.STEPS] += n


@jitable
def _act(s: Any, t: Any, out: Any) -> None:
    """The drive acts on a frame: its watchdog is fed, then the op (the firmware's own writes call the same)."""
    K.frame(s)
    op = t[OP]
    if op == READ:
        values = K.status(s, t[REPETITIVE] != 0.0)
        for k in range(len(values)):
            out[STATUS_AT + k] = values[k]
        out[SENSED_AT] = s[K.TIME]
        out[SENSED_AT + 1] = s[K.POS]
        out[SENSED_AT + 2] = s[K.VEL]
        out[SENSED_AT + 3] = s[K.I_OUT]
    elif op == TARGET_POSITION:
        s[K.TARGET_ABSOLUTE] = t[VALUE]
    elif op == START:
        K.start(s, t[MOTION], t[RELATIVE], t[VALUE])
    elif op == TARGET_SPEED:
        K.target_speed(s, t[VALUE])
    else:
        K.target_current(s, t[VALUE])


def exchanges(tx: Any, st: Any, out: Any, w: int, mj_step: int, table: Any, adr: Any, ratio: Any,
              order: Any, worlds: Any, dts: Any, active: Any) -> None:
    """The transactions ``tx`` (rows of :data:`TX_WIDTH`, each naming its drive's row of ``table``) in world ``w``,
    one after the other, as :meth:`~joints.transports.serial_sim.TimedSerialLine._transact_idle` carries each:
    ``st`` (the state vector) in and out, each transaction's frame instants (and a read's status) into ``out``."""
    for k in range(tx.shape[0]):
        t = tx[k]
        o = out[k]
        s = table[int(t[ROW])]
        if k:  # TimedSerialLine._sync: the clock moved without the line (a booked reply)
            c = st[CLOCK]
            if c > st[SEEN]:
                st[SEEN] = c
                st[NOW] = K.fmax(st[NOW], c)
        now = st[NOW]
        # the request (TimedSerialLine._put of the host's frame)
        start = K.fmax(now, st[FREE_HOST])  # every max as Python's builtin (K.fmax)
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
        _act(s, t, o)
        st[NOW] = K.fmax(st[NOW], due)
        # the reply (TimedSerialLine._put of the device's frame), booked while it travels (World.book)
        start = K.fmax(due, st[FREE_DEVICE])
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
        st[FREE_HOST] = K.fmax(st[FREE_HOST], seen + st[GAP])
        st[NOW] = K.fmax(st[NOW], seen)
        o[CLOCK_AFTER] = st[CLOCK]


_COMPILED: list[Any] = []


def _compiled() -> Any:
    """:func:`exchanges` compiled (numba), or None without it."""
    if not _COMPILED:
        _COMPILED.append(kernel.compiled(exchanges) if kernel.AVAILABLE else None)
    return _COMPILED[0]


#: the stock methods the requests would go through, captured when their modules were imported (a replaced one -
#: a test planting replies - means no one-call exchange)
_STOCK = (*modbus_front.STOCK, *serial_sim.STOCK, *erob.STOCK)


def _stock() -> bool:
    for cls, name, fn in _STOCK:
        if getattr(cls, name) is not fn:
            return False
    return True


@dataclass(frozen=True, slots=True)
class _Shape:
    """What requests of one shape (kind, slave, address, size) have in common."""

    op: int
    name: str  #: the parameter a write stores
    request: int  #: characters of the request
    reply: int  #: characters of the reply
    made: Any  #: a write's reply (an FC06's for its first value); a read's reply with every word 0
    extra: Any  #: a read's plan (:meth:`ModbusFront.read_plan`); a write's limits (writable, lowest, highest)


class ErobExchange:
    """The steady requests of one eRob twin (``front`` on ``bus``) over ``line``, in ``world`` (see the module
    docstring)."""

    def __init__(self, world: Any, bus: ModbusDeviceBus, front: ModbusFront, line: TimedSerialLine) -> None:
        self.world = world
        self.bus = bus
        self.front = front
        self.firmware: ErobFirmware = front.firmware  # type: ignore[assignment]
        self.line = line
        self.slave = front.address
        self.taken = 0  #: calls that ran (each of one or more transactions)
        self._group: Any = None
        self._row_at = 0
        self._shapes: dict[tuple[Any, ...], _Shape | None] = {}
        import numpy as np

        self._st = np.zeros(STATE_WIDTH)
        self._outs: dict[int, Any] = {}
        self._txs: dict[int, Any] = {}
        #: the clock after each transaction of the last :meth:`run` (the host's per-joint instants)
        self.clocks: list[float] = []

    def _steady(self) -> bool:
        """Whether the world, line, bus, front and firmware are as the compiled call assumes (checked first)."""
        world, line, fw = self.world, self.line, self.firmware
        group = world.group
        if not (group.compiled and group.fusable[world.group_index]) or world._ticks or world._bind != world._bind_seen:
            return False
        if line._pending or line._cap is not None or line._closed or line.peer is not self.bus or not line._plain_peer():
            return False
        if fw.pending or fw.command_delay > 0 or type(fw) is not ErobFirmware or type(self.front) is not ModbusFront:
            return False
        return self.bus.slaves.get(self.slave) is self.front and _stock()

    def _row_index(self, group: Any) -> int:
        """The firmware's row in ``group``'s table (kept per group: a batch may join the world to another)."""
        if self._group is not group:
            self._row_at = next(first for twin, first in group._owners if twin is self.firmware)
            self._group = group
        return self._row_at

    def _shape(self, request: Any, size: Callable[[Any], int]) -> _Shape | None:
        """What stays the same for requests like ``request`` (kept per shape); None: not one of the steady ones."""
        kind = type(request)
        if kind is mb.ReadHoldingRegisters:
            key: tuple[Any, ...] = (kind, request.slave, request.address, request.count)
        elif kind is mb.WriteMultipleRegisters:
            key = (kind, request.slave, request.address, len(request.values))
        elif kind is mb.WriteSingleRegister:
            key = (kind, request.slave, request.address)
        else:
            return None
        shapes = self._shapes
        if key not in shapes:
            shapes[key] = self._make_shape(request, size) if request.slave == self.slave else None
        return shapes[key]

    def _make_shape(self, request: Any, size: Callable[[Any], int]) -> _Shape | None:
        front, fw = self.front, self.firmware
        if type(request) is mb.ReadHoldingRegisters:
            plan = front.read_plan(request.address, request.count)
            if isinstance(plan, int) or not isinstance(plan[0], _StatusRead):
                return None
            blank = mb.ReadRegistersReply(request.slave, request.function, (0,) * request.count)
            return _Shape(READ, "", size(request), size(blank), blank, plan)
        if type(request) is mb.WriteMultipleRegisters:
            words = request.values
            reply: Any = mb.WriteMultipleRegistersReply(request.slave, request.address, len(words))
        else:
            words = (request.value,)
            reply = mb.WriteSingleRegisterReply(request.slave, request.address, request.value)
        try:
            items = front.items(request.address, words)
        except ModbusException:
            return None
        op = OP_OF.get(items[0][0]) if len(items) == 1 else None
        limits = fw._limits.get(items[0][0])
        if op is None or limits is None or not limits[0]:
            return None
        return _Shape(op, items[0][0], size(request), size(reply), reply, limits)

    def _row(self, request: Any, shape: _Shape, written: dict[str, int], check: Callable[[Any, Any], bool] | None
             ) -> tuple[list[float], Any, Any] | None:
        """The transaction row of ``request``, its reply (None for a read: made after the call) and what the
        Python side finishes it with; None where it is not a steady request now."""
        fw = self.firmware
        op = shape.op
        if op == READ:
            plan = self.front.read_plan(request.address, request.count)  # the front's own, as it serves it now
            if isinstance(plan, int) or not isinstance(plan[0], _StatusRead) or (
                    check is not None and not check(request, shape.made)):
                return None  # (the words a read packs are plain: a blank reply of its size stands for them)
            return [READ, 0.0, shape.request, 0.0, shape.reply, 0.0, 0.0, float(plan[0].repetitive()), 0.0], None, plan
        if type(request) is mb.WriteMultipleRegisters:
            reply: Any = shape.made
            items = self.front.items(request.address, request.values)
        else:
            value = request.value
            reply = shape.made if shape.made.value == value else \
                mb.WriteSingleRegisterReply(request.slave, request.address, value)
            items = self.front.items(request.address, (value,))
        name, value = items[0]
        _, lo, hi = shape.extra
        if type(value) is not int or not lo <= value <= hi:
            return None
        try:
            fw.check_write(name, value)
        except ParameterRefused:  # refused: the front answers it its way
            return None
        if check is not None and not check(request, reply):  # a reply the host would not take as the plain answer
            return None
        values = fw.values
        written[name] = value
        if op == START:
            target = written.get("target_absolute_position", values["target_absolute_position"])
        else:
            target = value
        return ([op, float(target), shape.request, 0.0, shape.reply,
                 float(written.get("motion_mode", values["motion_mode"])),
                 float(written.get("target_relative_position", values["target_relative_position"])), 0.0, 0.0],
                reply, items)

    def run(self, requests: Sequence[Any], size: Callable[[Any], int], check: Callable[[Any, Any], bool] | None,
            exchanges: Sequence[ErobExchange] | None = None) -> list[Any] | None:
        """The replies to ``requests`` (sent one after the other), each as the bus gives it, once the host would
        have received it; None (nothing sent) where this is not the steady case. ``size``: a message's
        characters on the line; ``check(request, reply)``: whether the host takes the reply as the plain answer
        (asked before anything is sent; a read's with its words 0; None: the caller checks the replies after);
        ``exchanges``: per request, the exchange of the drive it is for (default: this one's; all on this one's
        line and world: a rig's eRobs on one bus go in one call)."""
        fn = _compiled()
        if fn is None:
            return None
        line, world = self.line, self.world
        mine = [self] * len(requests) if exchanges is None else exchanges
        rows: list[list[float]] = []
        made: list[tuple[Any, Any]] = []
        written: dict[int, dict[str, int]] = {}
        steady: set[int] = set()
        group = world.group
        for ex, r in zip(mine, requests):
            if id(ex) not in steady:
                if ex.line is not line or ex.world is not world or not ex._steady():
                    return None
                steady.add(id(ex))
            shape = ex._shape(r, size)
            if shape is None:
                return None
            got = ex._row(r, shape, written.setdefault(id(ex), {}), check)
            if got is None:
                return None
            turn = ex.bus.message_turnaround(r)
            row = got[0]
            row[TURN] = line.turnaround if turn is None else turn
            row[ROW] = float(ex._row_index(group))
            rows.append(row)
            made.append((got[1], got[2]))
        clock = world.clock
        with world.lock:
            now = line._sync()
            free = line._free
            if len(line._latest_end) != len(line._log) or line.latest_end() > max(now, free["host"]):
                return None  # an edited log, or a frame that may overlap the first request: the line's own way
            w = world.group_index
            table = group.worlds_table
            table[w, stepping.STEPS] = world.steps
            st = self._st
            st[:] = (clock.now(), world._target, 1.0 if world._booked else 0.0, now, line._clock_seen,
                     free["host"], free["device"], line.char_time, line.gap, line.adapter_latency, world.timestep)
            n = len(rows)
            tx = self._tx(n)
            tx[:] = rows
            out = self._out(n)
            order, active = group._plan(world._me)
            try:
                fn(tx, st, out, w, group.mj_step or 0, group.table, group.adr, group.ratio, order, table,
                   group.dts_array, active)
            finally:
                world.steps = int(table[w, stepping.STEPS])
                state = st.tolist()
                world._target = state[TARGET]
                world._booked = state[BOOKED] != 0.0
                clock.set(state[CLOCK])
            if world._data.maxuse_arena > group._arena_limits[w]:  # as Group.run after its calls
                world.leave_fused_path()
                group.replan()
            line.now = state[NOW]
            line._clock_seen = state[SEEN]
            free["host"] = state[FREE_HOST]
            free["device"] = state[FREE_DEVICE]
            replies: list[Any] = []
            frames: list[tuple[float, float, float, int, str, Any]] = []
            self.clocks = clocks = []
            for ex, r, t, o, (reply, extra) in zip(mine, requests, rows, out.tolist(), made):
                if t[OP] == READ:
                    plan = extra
                    values = plan[0].finish(list(map(int, o[STATUS_AT:SENSED_AT])), dict(zip(SENSED, o[SENSED_AT:])))
                    reply = mb.ReadRegistersReply(r.slave, r.function, ModbusFront.pack(plan, values, r.count))
                else:
                    ex.firmware._keep(extra)  # the parameter store's part (the row's ran in the call)
                frames.append((o[H_START], o[H_END], o[H_DUE], int(t[REQUEST]), "host", None))
                frames.append((o[D_START], o[D_END], o[D_SEEN], int(t[REPLY]), "device", reply))
                replies.append(reply)
                clocks.append(o[CLOCK_AFTER])
            line.book_frames(frames)
        self.taken += 1
        return replies

    def _out(self, n: int) -> Any:
        out = self._outs.get(n)
        if out is None:
            import numpy as np

            out = self._outs[n] = np.zeros((n, OUT_WIDTH))
        return out

    def _tx(self, n: int) -> Any:
        tx = self._txs.get(n)
        if tx is None:
            import numpy as np

            tx = self._txs[n] = np.zeros((n, TX_WIDTH))
        return tx


def prepare(world: Any, bus: Any, front: Any, line: Any) -> ErobExchange | None:
    """The one-call exchange of the eRob twin behind ``front`` on ``bus`` of ``world`` over ``line`` (the host's
    transport of that bus), or None where that is not an eRob's Modbus front over a timed line on the world's
    clock."""
    if not isinstance(bus, ModbusDeviceBus) or not isinstance(line, TimedSerialLine) or line.clock is not world.clock:
        return None
    if type(front) is not ModbusFront or type(front.firmware) is not ErobFirmware:
        return None
    return ErobExchange(world, bus, front, line)
