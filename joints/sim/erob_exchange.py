"""An eRob's steady Modbus requests in one compiled call: what they request and what the drive does with them.

Rule: it gives what the sim's direct path gives request by request (the host's link over
:meth:`~joints.transports.serial_sim.TimedSerialLine._transact_idle`, the bus, the
:class:`~joints.sim.modbus_front.ModbusFront`, the firmware): the line and world arithmetic is
:mod:`joints.sim.line_exchange`'s, the drive's act (:func:`act`) the kernel ops of :mod:`joints.sim.erob_kernel`
the firmware's own writes call (target+start, target speed, target current, the status read); afterwards
Python brings the firmware's parameter store to where that path leaves it and makes a read's reply. The
requests of several drives on one line (a rig's eRobs) go in one call too, each acting on its own row.

It runs only in the steady case, checked before anything is sent: the world runs fused (compiled, every
drive a kernel row, nothing ticking after substeps), the line is idle and its peer acts only on host
frames, the bus, front and firmware are the stock ones (nothing replaced, nothing pending, no command
delay), every write one the firmware accepts (a plain reply), the read one of the status block. Anything
else returns None and the caller sends the requests its usual way. ``tests/sim/test_compiled_path.py``
compares both.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from joints.codecs import modbus as mb
from joints.devices.registers import Access, Register
from joints.errors import ParameterRefused
from joints.sim import erob, modbus_front
from joints.sim import erob_kernel as K
from joints.sim import line_exchange as L
from joints.sim.erob import ErobFirmware, _StatusRead
from joints.sim.kernel import jitable
from joints.sim.line_exchange import CLOCK_AFTER, ROW, TURN
from joints.sim.modbus_front import ModbusDeviceBus, ModbusException, ModbusFront
from joints.sim.stepping import EROB
from joints.transports import serial_sim
from joints.transports.serial_sim import TimedSerialLine

__all__ = ["ErobExchange", "StatusReply", "act", "prepare"]

#: ops (column OP of a transaction row): what the drive does with the frame
READ, TARGET_POSITION, START, TARGET_SPEED, TARGET_CURRENT = range(5)
#: the parameter each write op stores
OP_OF = {"target_absolute_position": TARGET_POSITION, "start_operating": START, "target_speed": TARGET_SPEED,
         "target_current": TARGET_CURRENT}
#: the family's columns of a transaction row (after :mod:`joints.sim.line_exchange`'s): op, value, motion mode,
#: target relative position, repetitive (a read's status argument)
OP, VALUE, MOTION, RELATIVE, REPETITIVE = range(L.ARGS, L.ARGS + 5)
#: the family's columns of an output row: a read's status, then the row's columns its sensors saw
STATUS_AT = L.OUTS
SENSED = (K.TIME, K.POS, K.VEL, K.I_OUT)
SENSED_AT = STATUS_AT + len(K.STATUS_NAMES)
OUT_WIDTH = SENSED_AT + len(SENSED)


@jitable
def act(s: Any, t: Any, out: Any) -> None:
    """The drive (row ``s``) acts on a frame: its watchdog is fed, then the op (the firmware's own writes call
    the same)."""
    K.frame(s)
    op = t[OP]
    if op == READ:
        K.status_out(s, s, t[REPETITIVE] != 0.0, out, STATUS_AT)
    elif op == TARGET_POSITION:
        s[K.TARGET_ABSOLUTE] = t[VALUE]
    elif op == START:
        K.start(s, t[MOTION], t[RELATIVE], t[VALUE])
    elif op == TARGET_SPEED:
        K.target_speed(s, t[VALUE])
    else:
        K.target_current(s, t[VALUE])


def _compiled() -> Any:
    """The one-call exchange (:func:`joints.sim.line_exchange.exchanges`) compiled (numba), or None without it."""
    return L.compiled()[0]


#: the stock methods the requests would go through, captured when their modules were imported (a replaced one -
#: a test planting replies - means no one-call exchange)
_STOCK = (*modbus_front.STOCK, *serial_sim.STOCK, *erob.STOCK)


@dataclass(slots=True, eq=False)
class _Shape:
    """What requests of one shape (kind, slave, address, size) have in common."""

    op: int
    name: str  #: the parameter a write stores
    request: int  #: characters of the request
    reply: int  #: characters of the reply
    made: Any  #: a write's reply (an FC06's for its first value); a read's reply with every word 0
    extra: Any  #: a read's plan (:meth:`ModbusFront.read_plan`); a write's limits (writable, lowest, highest)
    #: a read's registers, in block order, whose values its words pack (``ModbusFront.pack``: each by its type,
    #: high word first, every register within the block), or None where they are not that
    registers: tuple[Register, ...] | None = None
    #: a read's values not kept within their register's type by the read itself: (index, lowest, highest)
    loose: tuple[tuple[int, int, int], ...] = ()
    #: the reply check that took :attr:`made` for a request of this shape (asked once per check: the lane's stock
    #: check, the same object every call, answers it by the shape alone - :meth:`joints.link.lane.LinkLane.exchange`)
    checked: Any = None


class StatusReply(serial_sim.Deferred):
    """The reply to a status read known by its values (``values``: the typed values of ``registers``, in block
    order, each an int within its register's type, as :meth:`ErobExchange.run` checked): the words are
    ``ModbusFront.pack``'s of them, and the :class:`~joints.codecs.modbus.ReadRegistersReply` is made only when
    asked (:meth:`message`: the line's log, a host that decodes words), once."""

    __slots__ = ("_message", "plan", "registers", "request", "values")

    def __init__(self, request: Any, plan: Any, values: list[int], registers: tuple[Register, ...]) -> None:
        self.request = request
        self.plan = plan
        self.values = values
        self.registers = registers
        self._message: mb.ReadRegistersReply | None = None

    def message(self) -> mb.ReadRegistersReply:
        """The reply as the front makes it (``ReadRegistersReply`` of the packed words)."""
        made = self._message
        if made is None:
            r = self.request
            made = self._message = mb.ReadRegistersReply(r.slave, r.function,
                                                         ModbusFront.pack(self.plan, self.values, r.count))
        return made


class ErobExchange(L.Carrier):
    """The steady requests of one eRob twin (``front`` on ``bus``) over ``line``, in ``world`` (see the module
    docstring)."""

    def __init__(self, world: Any, bus: ModbusDeviceBus, front: ModbusFront, line: TimedSerialLine) -> None:
        super().__init__(OUT_WIDTH)
        self.world = world
        self.bus = bus
        self.front = front
        self.firmware: ErobFirmware = front.firmware  # type: ignore[assignment]
        self.line = line
        self.slave = front.address
        self._shapes: dict[tuple[Any, ...], _Shape | None] = {}
        self._read: tuple[Any, _Shape] | None = None  #: the last status read request and its shape
        #: the clock after each transaction of the last :meth:`run` (the host's per-joint instants)
        self.clocks: list[float] = []
        #: of the last :meth:`run` with a hold: what was left to the tick (<= 0: late) and the clock after the hold
        self.held = (0.0, 0.0)

    def _steady(self) -> bool:
        """Whether the world, line, bus, front and firmware are as the compiled call assumes (checked first)."""
        return self._line_steady() and self._drive_steady()

    def _line_steady(self) -> bool:
        """Whether the world and the line are as the compiled call assumes, and every method the requests would
        go through is the stock one (once per call, for all the drives on the line)."""
        line = self.line
        if not L.world_fused(self.world):
            return False
        if line._pending or line._cap is not None or line._closed or not line._plain_peer():
            return False
        return L.stock(_STOCK)

    def _drive_steady(self) -> bool:
        """Whether this drive's bus, front and firmware are as the compiled call assumes (per drive and call)."""
        fw = self.firmware
        if fw.pending or fw.command_delay > 0 or type(fw) is not ErobFirmware or type(self.front) is not ModbusFront:
            return False
        bus = self.bus
        return self.line.peer is bus and bus.slaves.get(self.slave) is self.front

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
            registers, loose = self._packed(request.address, request.count, plan)
            return _Shape(READ, "", size(request), size(blank), blank, plan, registers, loose)
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

    def _packed(self, start: int, count: int, plan: Any) -> tuple[tuple[Register, ...] | None,
                                                                   tuple[tuple[int, int, int], ...]]:
        """(the registers, the loose values) of a status read of ``count`` words from ``start`` served by ``plan``
        (see :class:`_Shape`): the registers the front's plan packs (``ModbusFront._read_plan``: those in the
        block that are not commands, in address order), where they are the reader's names, each wholly in the
        block and packed in one call (no low word first); the values the reader saturates to a range outside
        their register's type, or does not saturate, are checked per read."""
        reader, packer = plan[0], plan[1]
        end = start + count
        regs = tuple(r for r in self.front.table
                     if r.address < end and r.address + r.words > start and r.access is not Access.COMMAND)
        if packer is None or tuple(r.name for r in regs) != reader.names or any(
                r.address < start or r.address + r.words > end for r in regs):
            return None, ()
        loose: list[tuple[int, int, int]] = []
        for k, ((i, _name, lo, hi), reg) in enumerate(zip(reader.entries, regs)):
            rlo, rhi = reg.type_range
            if i < 0 or lo < rlo or rhi < hi:
                loose.append((k, rlo, rhi))
        return regs, tuple(loose)

    def _row(self, request: Any, shape: _Shape, written: dict[str, int], check: Callable[[Any, Any], bool] | None
             ) -> tuple[list[float], Any, Any] | None:
        """The transaction row of a write ``request``, its reply and the firmware's items it stores; None where it
        is not a steady request now (a read's row: :meth:`_read_row`)."""
        fw = self.firmware
        op = shape.op
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
        if check is not None and (reply is not shape.made or shape.checked is not check):
            if not check(request, reply):  # a reply the host would not take as the plain answer
                return None
            if reply is shape.made:
                shape.checked = check
        values = fw.values
        written[name] = value
        if op == START:
            target = written.get("target_absolute_position", values["target_absolute_position"])
        else:
            target = value
        return ([EROB, 0.0, shape.request, 0.0, shape.reply, op, float(target),
                 float(written.get("motion_mode", values["motion_mode"])),
                 float(written.get("target_relative_position", values["target_relative_position"])), 0.0],
                reply, items)

    def _read_row(self, request: Any, size: Callable[[Any], int], check: Callable[[Any, Any], bool] | None
                  ) -> tuple[list[float], tuple[Any, _Shape]] | None:
        """The transaction row of a status read and (the front's plan for it, its shape); None where it is not a
        steady request now (``request``: the same FC03 object step after step, its shape kept by identity; the
        words a read packs are plain: a blank reply of its size stands for them in ``check``, asked once per
        shape and check, :attr:`_Shape.checked`)."""
        last = self._read
        if last is None or last[0] is not request:
            got = self._shape(request, size)
            if got is None or got.op != READ:
                return None
            last = self._read = (request, got)
        shape = last[1]
        plan = self.front.read_plan(request.address, request.count)  # the front's own, as it serves it now
        if plan is not shape.extra:  # the front planned it again (its cache was cleared): its shape again
            if isinstance(plan, int) or not isinstance(plan[0], _StatusRead):
                return None
            got = self._shapes[(mb.ReadHoldingRegisters, request.slave, request.address, request.count)] = \
                self._make_shape(request, size)
            if got is None:
                return None
            shape = got
            self._read = (request, got)
        if check is not None and shape.checked is not check:
            if not check(request, shape.made):
                return None
            shape.checked = check
        reader: Any = plan[0]
        return [EROB, 0.0, shape.request, 0.0, shape.reply, READ, 0.0, 0.0, 0.0, float(reader.repetitive())], \
            (plan, shape)

    @staticmethod
    def _status_reply(request: Any, o: Sequence[float], plan: Any, shape: _Shape, lazy: bool) -> Any:
        """The reply to the status read ``request`` whose kernel values and sensed columns are in the output row
        ``o``: a :class:`StatusReply` where ``lazy`` and its values are proven to be the words' (every value an
        int within its register's type), else the ``ReadRegistersReply``."""
        values = plan[0].finish_row(o, STATUS_AT)
        reply = StatusReply(request, plan, values, shape.registers)  # type: ignore[arg-type]
        if not lazy or shape.registers is None:
            return reply.message()
        for k, lo, hi in shape.loose:
            v = values[k]
            if type(v) is not int or not lo <= v <= hi:
                return reply.message()
        return reply

    def _rows(self, requests: Sequence[Any], exchanges: Sequence[ErobExchange] | None,
              size: Callable[[Any], int], check: Callable[[Any, Any], bool] | None, group: Any
              ) -> tuple[list[list[float]], list[Any]] | None:
        """The transaction rows of ``requests`` over this exchange's line (``exchanges``: per request, the
        exchange of its drive; None: this one's) and, per request, (its exchange, a write's reply and firmware
        items | a read's plan and shape); None where one is not a steady request now (see :meth:`run`)."""
        line = self.line
        rows: list[list[float]] = []
        made: list[Any] = []
        written: dict[int, dict[str, int]] = {}
        extra: Any
        ex = self
        for k, r in enumerate(requests):
            if exchanges is not None:
                ex = exchanges[k]
            if type(r) is mb.ReadHoldingRegisters:
                got = ex._read_row(r, size, check)
                if got is None:
                    return None
                row, extra = got
            else:
                shape = ex._shape(r, size)
                if shape is None or shape.op == READ:
                    return None
                wrote = ex._row(r, shape, written.setdefault(id(ex), {}), check)
                if wrote is None:
                    return None
                row, *extra = wrote
            turn = ex.bus.message_turnaround(r)
            row[TURN] = line.turnaround if turn is None else turn
            row[ROW] = float(ex._first_row(group, ex.firmware))
            rows.append(row)
            made.append((ex, *extra))
        return rows, made

    def run(self, requests: Sequence[Any], size: Callable[[Any], int], check: Callable[[Any, Any], bool] | None,
            exchanges: Sequence[ErobExchange] | None = None, *, lazy: bool = False,
            hold: tuple[int, float] | None = None) -> list[Any] | None:
        """The replies to ``requests`` (sent one after the other), each as the bus gives it, once the host would
        have received it; None (nothing sent) where this is not the steady case. ``size``: a message's
        characters on the line; ``check(request, reply)``: whether the host takes the reply as the plain answer
        (asked before anything is sent; a read's with its words 0; None: the caller checks the replies after);
        ``exchanges``: per request, the exchange of the drive it is for (default: this one's; all on this one's
        line and world: a rig's eRobs on one bus go in one call); ``lazy``: a status read's reply may be a
        :class:`StatusReply` (its values by register; the message made when asked); ``hold`` (index, tick): the
        host's wait for the env's tick at that clock time before the request at that index (``RigEnv._wait_until``
        with the world holding the rig's sleep: :func:`joints.sim.line_exchange.hold`), what was left to the tick
        and the clock after it then in :attr:`held`."""
        fn = _compiled()
        if fn is None or not self._line_steady():
            return None
        line, world = self.line, self.world
        if exchanges is None:
            if not self._drive_steady():
                return None
        else:
            for ex in {id(ex): ex for ex in exchanges}.values():
                if ex.line is not line or ex.world is not world or not ex._drive_steady():
                    return None
        if hold is not None and not L.sleeps_held(world):
            return None
        got = self._rows(requests, exchanges, size, check, world.group)
        if got is None:
            return None
        rows, made = got
        if hold is not None:
            rows.insert(hold[0], L.hold_row(hold[1]))
        with world.lock:
            now = L.clear(line)
            if now is None:
                return None
            outs = self.carry(fn, world, line, now, rows)
            if hold is not None:
                del rows[hold[0]]
                self.held = L.held_of(outs.pop(hold[0]))
            replies: list[Any] = []
            self.clocks = clocks = []
            frames: list[tuple[float, float, float, int, str, Any]] = []
            for r, t, o, (ex, a, b) in zip(requests, rows, outs, made):
                if t[OP] == READ:
                    reply = self._status_reply(r, o, a, b, lazy)
                else:
                    reply = a
                    ex.firmware._keep(b)  # the parameter store's part (the row's ran in the call)
                replies.append(reply)
                clocks.append(o[CLOCK_AFTER])
                frames.append((o[L.H_START], o[L.H_END], o[L.H_DUE], int(t[L.REQUEST]), "host", None))
                frames.append((o[L.D_START], o[L.D_END], o[L.D_SEEN], int(t[L.REPLY]), "device", reply))
            line.book_frames(frames)  # (joints.sim.line_exchange.book, in the same pass)
        self.taken += 1
        return replies

    @staticmethod
    def carry_rigs(*args: Any, **kwargs: Any) -> list[list[Any]] | None:
        """Several rigs' :meth:`run` in one compiled call (:func:`joints.sim.rigs_exchange.carry_rigs`)."""
        from joints.sim.rigs_exchange import carry_rigs

        return carry_rigs(*args, **kwargs)


def prepare(world: Any, bus: Any, front: Any, line: Any) -> ErobExchange | None:
    """The one-call exchange of the eRob twin behind ``front`` on ``bus`` of ``world`` over ``line`` (the host's
    transport of that bus), or None where that is not an eRob's Modbus front over a timed line on the world's
    clock."""
    if not isinstance(bus, ModbusDeviceBus) or not isinstance(line, TimedSerialLine) or line.clock is not world.clock:
        return None
    if type(front) is not ModbusFront or type(front.firmware) is not ErobFirmware:
        return None
    return ErobExchange(world, bus, front, line)
