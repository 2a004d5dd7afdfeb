"""Modbus RTU front: a drive's firmware seen through the register image of its Modbus map.

Rule: the same codec as the host, in device role; the firmware is reached only by parameter name
(:class:`~joints.sim.firmware.Firmware`). A :class:`ModbusDeviceBus` dispatches frames to fronts
by slave address (broadcast: every front executes, nobody answers). A :class:`ModbusFront` turns
register reads and writes into firmware reads and writes through a
:class:`~joints.devices.registers.RegisterTable` (address -> name, word order of 32-bit pairs):

* reads: unknown addresses -> exception 02; a block may span the gaps between registers (gaps,
  and write-only command registers, read 0) as long as its first and last word belong to
  registers; a block may start or end inside a 32-bit pair (that word of the pair is served);
  only the parameters in the block are read from the firmware, in one call;
* writes: addresses that are unknown or read-only -> 02; the block's values go to the firmware
  in one atomic call; a single word written into a 32-bit pair merges with the pair's other word;
* firmware refusals map to exception codes (:data:`EXCEPTION_FOR`): unknown / not readable /
  not writable -> 02, out of range / refused in this state -> 03.

A bus holds any :class:`ModbusSlave` (a family whose device is not a flat register file brings its
own front, e.g. :mod:`joints.sim.mks_modbus_front`). A CRC-valid frame whose byte count breaks the
Modbus rules is offered to its slave (:meth:`ModbusSlave.malformed`): a :class:`ModbusFront`
answers exception 03 (an FC16 whose byte count disagrees with its register count), as the Modbus
application protocol requires; a drive whose manual documents such a frame answers it its way.

Every frame addressed to a front (and every broadcast it executes) is reported to the firmware
(:meth:`~joints.sim.firmware.Firmware.frame_received`) before it is served. No register image is
kept: the firmware holds typed values by name, a read packs only its block (plans are cached per
block shape), a write touches only the registers written.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterable, Mapping
from typing import Any, Protocol

from joints.codecs import modbus as mb
from joints.codecs.crc import crc_ok
from joints.devices.registers import Access, Register, RegisterTable
from joints.errors import ByteCountError, FrameError, ParameterRefused, Refusal
from joints.sim.firmware import Firmware

__all__ = [
    "EXCEPTION_FOR",
    "ILLEGAL_DATA_ADDRESS",
    "ILLEGAL_DATA_VALUE",
    "ILLEGAL_FUNCTION",
    "SERVER_DEVICE_FAILURE",
    "ModbusDeviceBus",
    "ModbusException",
    "ModbusFront",
    "ModbusSlave",
]

ILLEGAL_FUNCTION = 0x01
ILLEGAL_DATA_ADDRESS = 0x02
ILLEGAL_DATA_VALUE = 0x03
SERVER_DEVICE_FAILURE = 0x04

#: the Modbus exception code that answers each firmware refusal
EXCEPTION_FOR: Mapping[Refusal, int] = {
    Refusal.UNKNOWN: ILLEGAL_DATA_ADDRESS,
    Refusal.NOT_READABLE: ILLEGAL_DATA_ADDRESS,
    Refusal.NOT_WRITABLE: ILLEGAL_DATA_ADDRESS,
    Refusal.OUT_OF_RANGE: ILLEGAL_DATA_VALUE,
    Refusal.STATE: ILLEGAL_DATA_VALUE,
}

_PLAN_CACHE = 4096  #: (start, count) plans kept per front (a fuzzer cannot grow memory without bound)

#: a read plan: the firmware's prepared read (None: nothing to read); the block packed in one call
#: (values -> big-endian bytes of the block with one pad word each side, then its words), or None
#: where a register has its low word first; and per parameter (index in the padded block, words,
#: low word first) for packing word by word
_ReadPlan = tuple[Callable[[], list[int]] | None, struct.Struct | None, struct.Struct,
                  tuple[tuple[int, int, bool], ...]]
_FORMAT = {"uint16": "H", "int16": "h", "uint32": "I", "int32": "i"}
#: a write plan: per register (name, offset in the block, words, signed, low word first)
_WritePlan = tuple[tuple[str, int, int, bool, bool], ...]


class ModbusSlave(Protocol):
    """What a :class:`ModbusDeviceBus` needs from one slave."""

    @property
    def address(self) -> int: ...

    def handle(self, request: mb.Request | mb.UnsupportedRequest) -> mb.Reply | None:
        """Execute a request addressed to this slave; its reply (None: silence)."""
        ...

    def malformed(self, frame: bytes) -> mb.Reply | None:
        """A CRC-valid frame for this slave whose byte count a Modbus codec rejects; the reply (None: silence)."""
        ...


class ModbusException(Exception):
    """Raised inside a front to answer with a Modbus exception reply."""

    def __init__(self, code: int, reason: str = "") -> None:
        super().__init__(reason or mb.EXCEPTION_TEXT.get(code, ""))
        self.code = code


class ModbusFront:
    """One slave address on a Modbus bus: the register image view of ``firmware``.

    ``address`` is a fixed slave address; or ``node_id`` names the firmware parameter that holds
    it, taken as it was at the firmware's last power-on (a new address takes effect after a
    power cycle, as on the drives).
    """

    def __init__(self, firmware: Firmware, table: RegisterTable, address: int | None = None, *,
                 node_id: str | None = None) -> None:
        if (address is None) == (node_id is None):
            raise ValueError("give the slave address or the name of the parameter that holds it, not both")
        missing = [r.name for r in table if r.name not in firmware.params]
        if missing:
            raise ValueError(f"{table.device} Modbus map: {missing} are not parameters of {firmware!r}")
        self.firmware = firmware
        self.table = table
        self.node_id = node_id
        self._address = address
        self._read_plans: dict[tuple[int, int], _ReadPlan | int] = {}
        self._write_plans: dict[tuple[int, int], _WritePlan | int] = {}

    @classmethod
    def plain(cls, table: RegisterTable, address: int, *, values: Mapping[str, int] | None = None) -> ModbusFront:
        """A front over a firmware without behaviour: a bare register image (scripted slaves, tests)."""
        return cls(Firmware(table.params, values=values), table, address)

    @property
    def address(self) -> int:
        if self.node_id is not None:
            return int(self.firmware.power_on_values[self.node_id])
        assert self._address is not None
        return self._address

    # -- plans (per block shape, cached) --------------------------------------------------------
    def _read_plan(self, start: int, count: int) -> _ReadPlan | int:
        if not 1 <= count <= mb.MAX_READ:
            return ILLEGAL_DATA_VALUE
        table = self.table
        end = start + count
        if table.owner(start) is None or table.owner(end - 1) is None:
            return ILLEGAL_DATA_ADDRESS
        regs = [r for r in table
                if r.address < end and r.address + r.words > start and r.access is not Access.COMMAND]
        try:
            reader = self.firmware.reader([r.name for r in regs]) if regs else None
        except ParameterRefused as exc:
            return EXCEPTION_FOR[exc.reason]
        # the block with one pad word each side (a pair cut by the block's ends): gaps and command
        # registers are pad bytes, which pack as 0
        fmt, a, i = ">", start - 1, 0
        while a < end + 1:
            if i < len(regs) and regs[i].address == a:
                fmt += _FORMAT[regs[i].type]
                a += regs[i].words
                i += 1
            else:
                fmt += "xx"
                a += 1
        packer = None if any(r.low_word_first for r in regs) else struct.Struct(fmt)
        slots = tuple((r.address - start + 1, r.words, r.low_word_first) for r in regs)
        return reader, packer, struct.Struct(f">{count}H"), slots

    def _write_plan(self, start: int, count: int) -> _WritePlan | int:
        if not 1 <= count <= mb.MAX_WRITE:
            return ILLEGAL_DATA_VALUE
        regs: list[Register] = []
        for a in range(start, start + count):
            reg = self.table.owner(a)
            if reg is None or not reg.access.writable:
                return ILLEGAL_DATA_ADDRESS
            if not regs or regs[-1] is not reg:
                regs.append(reg)
        return tuple((r.name, r.address - start, r.words, r.signed, r.low_word_first) for r in regs)

    # -- register access ------------------------------------------------------------------------
    def read(self, start: int, count: int) -> tuple[int, ...]:
        """The words of registers ``start`` .. ``start + count - 1`` (raises :class:`ModbusException`)."""
        plan = self.read_plan(start, count)
        if isinstance(plan, int):
            raise ModbusException(plan)
        reader = plan[0]
        try:
            values = reader() if reader is not None else []
        except ParameterRefused as exc:
            raise ModbusException(EXCEPTION_FOR[exc.reason], str(exc)) from exc
        return self.pack(plan, values, count)

    @staticmethod
    def pack(plan: _ReadPlan, values: list[int], count: int) -> tuple[int, ...]:
        """The ``count`` words of a read by ``plan`` of ``values`` (its firmware read's result)."""
        _reader, packer, words, slots = plan
        if packer is not None:
            try:
                block: tuple[int, ...] = words.unpack_from(packer.pack(*values), 2)
                return block
            except struct.error:  # a value outside its register's type: masked word by word below
                pass
        out = [0] * (count + 2)  # one pad word each side: pairs cut by the block's ends
        for (i, n, low_first), v in zip(slots, values):
            if n == 1:
                out[i] = v & 0xFFFF
            else:
                raw = v & 0xFFFFFFFF
                if low_first:
                    out[i], out[i + 1] = raw & 0xFFFF, raw >> 16
                else:
                    out[i], out[i + 1] = raw >> 16, raw & 0xFFFF
        return tuple(out[1:count + 1])

    def write(self, start: int, words: tuple[int, ...]) -> None:
        """Write ``words`` from ``start`` as one atomic firmware write (raises :class:`ModbusException`)."""
        items = self.items(start, words)
        try:
            self.firmware.write_many(items)
        except ParameterRefused as exc:
            raise ModbusException(EXCEPTION_FOR[exc.reason], str(exc)) from exc

    def items(self, start: int, words: tuple[int, ...]) -> list[tuple[str, int]]:
        """The firmware write (name, value) ``words`` from ``start`` make (raises :class:`ModbusException` for
        addresses no register may be written at); nothing is written."""
        count = len(words)
        plans = self._write_plans
        plan = plans.get((start, count))
        if plan is None:
            if len(plans) >= _PLAN_CACHE:
                plans.clear()
            plan = plans[(start, count)] = self._write_plan(start, count)
        if isinstance(plan, int):
            raise ModbusException(plan)
        items: list[tuple[str, int]] = []
        for name, off, n, signed, low_first in plan:
            if n == 1:
                raw = words[off] & 0xFFFF
                items.append((name, raw - 0x10000 if signed and raw & 0x8000 else raw))
                continue
            if 0 <= off and off + 1 < count:
                a, b = words[off] & 0xFFFF, words[off + 1] & 0xFFFF
            else:  # one word of a pair: merge with the other word as it stands
                now = self.firmware.get(name) & 0xFFFFFFFF
                a, b = (now & 0xFFFF, now >> 16) if low_first else (now >> 16, now & 0xFFFF)
                if off < 0:
                    b = words[0] & 0xFFFF
                else:
                    a = words[off] & 0xFFFF
            hi, lo = (b, a) if low_first else (a, b)
            raw = hi << 16 | lo
            items.append((name, raw - 0x100000000 if signed and raw & 0x80000000 else raw))
        return items

    def read_plan(self, start: int, count: int) -> _ReadPlan | int:
        """The plan :meth:`read` serves ``count`` registers from ``start`` by (an exception code where it
        refuses them), cached as :meth:`read` caches it."""
        plans = self._read_plans
        plan = plans.get((start, count))
        if plan is None:
            if len(plans) >= _PLAN_CACHE:
                plans.clear()
            plan = plans[(start, count)] = self._read_plan(start, count)
        return plan

    def image(self) -> dict[int, int]:
        """The whole register image as {address: word} (every register, commands as last written)."""
        fw = self.firmware
        out: dict[int, int] = {}
        for reg in self.table:
            raw = fw.get(reg.name) & (0xFFFF if reg.words == 1 else 0xFFFFFFFF)
            if reg.words == 1:
                out[reg.address] = raw
            else:
                hi, lo = raw >> 16, raw & 0xFFFF
                out[reg.address], out[reg.address + 1] = (lo, hi) if reg.low_word_first else (hi, lo)
        return out

    def malformed(self, frame: bytes) -> mb.Reply | None:
        """A CRC-valid frame for this slave whose byte count the codec rejects (an FC16 whose byte
        count disagrees with its register count): a frame received, answered with exception 03."""
        self.firmware.frame_received()
        return mb.ExceptionReply(frame[0], frame[1], ILLEGAL_DATA_VALUE)

    def handle(self, request: mb.Request | mb.UnsupportedRequest) -> mb.Reply:
        """Execute a request addressed to this slave and build the reply."""
        self.firmware.frame_received()
        try:
            if isinstance(request, (mb.ReadHoldingRegisters, mb.ReadInputRegisters)):
                return mb.ReadRegistersReply(request.slave, request.function, self.read(request.address, request.count))
            if isinstance(request, mb.WriteSingleRegister):
                self.write(request.address, (request.value,))
                return mb.WriteSingleRegisterReply(request.slave, request.address, request.value)
            if isinstance(request, mb.WriteMultipleRegisters):
                self.write(request.address, request.values)
                return mb.WriteMultipleRegistersReply(request.slave, request.address, len(request.values))
            raise ModbusException(ILLEGAL_FUNCTION)
        except ModbusException as exc:
            return mb.ExceptionReply(request.slave, request.function, exc.code)

    def __repr__(self) -> str:
        return f"ModbusFront({self.firmware!r}, {self.table.device!r}, address={self.address})"


_READS = (mb.ReadHoldingRegisters, mb.ReadInputRegisters)
_REQUESTS = (*_READS, mb.WriteSingleRegister, mb.WriteMultipleRegisters, mb.UnsupportedRequest)


class ModbusDeviceBus:
    """All emulated slaves on one RS485 bus: bytes in, reply bytes out (a loopback/pty peer).

    As a real RTU slave: a frame cut by silence (:meth:`silence`, t3.5) is garbage even if its rest
    arrives later; a corrupt frame gets no answer; a CRC-valid frame for a slave on the bus with an
    unknown function code gets exception 01, an FC16 whose byte count disagrees with its register
    count exception 03; broadcasts and frames for other addresses are never answered. A front
    whose address comes from a parameter (``node_id``) moves to its new address at the next power
    cycle (two fronts on one address: the one added first answers).
    """

    def __init__(self, slaves: Iterable[ModbusSlave] = (), *, trace: Callable[[str, bytes], None] | None = None) -> None:
        self._fronts: list[ModbusSlave] = []
        self._slaves: dict[int, ModbusSlave] = {}
        #: fronts whose address comes from a parameter, with the power-on values it was taken from
        self._watch: list[tuple[Any, object]] = []
        for s in slaves:
            self.add(s)
        self._codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
        self.trace = trace
        self.frame_errors = 0
        #: bus timing: slave address -> its drive's reply turnaround [s] (the world fills it from the profiles)
        self.turnarounds: dict[int, float] = {}
        #: the world whose physics runs between this bus's frames (set by the world): a twin's one-call exchange
        self.world: Any = None

    def add(self, slave: ModbusSlave) -> None:
        address = slave.address
        if address in self.slaves:
            raise ValueError(f"two emulated slaves at address {address}")
        self._fronts.append(slave)
        self._refresh()

    def fused(self, slave: int, line: Any) -> Any:
        """The one-call exchange of the twin at ``slave`` over ``line`` (the host's end of this bus), where its
        firmware offers one (``fused_exchange``, e.g. :mod:`joints.sim.erob_exchange`); None otherwise."""
        front = self.slaves.get(slave)
        make = getattr(getattr(front, "firmware", None), "fused_exchange", None)
        return make(self.world, self, front, line) if self.world is not None and callable(make) else None

    def _refresh(self) -> None:
        by_address: dict[int, ModbusSlave] = {}
        for front in self._fronts:
            by_address.setdefault(front.address, front)
        self._slaves = by_address
        fronts: list[Any] = self._fronts  # a ModbusFront's address may come from its firmware
        self._watch = [(f, f.firmware.power_on_values) for f in fronts if getattr(f, "node_id", None)]

    @property
    def slaves(self) -> dict[int, ModbusSlave]:
        """The fronts by the address each answers on now (a power cycle may have moved one)."""
        for front, seen in self._watch:
            if front.firmware.power_on_values is not seen:
                self._refresh()
                break
        return self._slaves

    def turnaround(self, frame: bytes) -> float | None:
        """The reply turnaround [s] of the drive a frame addresses (a broadcast: the slowest); None: unknown."""
        return self._turnaround(frame[0]) if frame else None

    def message_turnaround(self, msg: Any) -> float | None:
        """:meth:`turnaround` of a request message (the direct path)."""
        return self._turnaround(msg.slave)

    def _turnaround(self, slave: int) -> float | None:
        turns = self.turnarounds
        if slave == 0:
            return max(turns.values(), default=None)
        return turns.get(slave)

    def receive(self, data: bytes) -> bytes:
        """Feed received bytes; return the bytes the addressed slaves send back."""
        self._codec.feed(data)
        return self._serve()

    def silence(self) -> bytes:
        """The line went quiet (t3.5): an incomplete frame is garbage now; returns any replies."""
        self._codec.flush()
        return self._serve()

    def _serve(self) -> bytes:
        codec = self._codec
        out = bytearray()
        while True:
            try:
                msg = codec.next_message()
            except ByteCountError as exc:
                # well framed, CRC valid, counts inconsistent: the addressed slave decides (03 from a ModbusFront)
                answer = self._malformed(exc.data)
                if answer is None:
                    self.frame_errors += 1
                else:
                    out += mb.encode(answer)
                continue
            except FrameError:
                self.frame_errors += 1  # a real slave stays silent on a corrupt frame
                continue
            if msg is None:
                break
            if isinstance(msg, _REQUESTS):
                reply = self.exchange(msg)
                if reply is not None:
                    out += mb.encode(reply)
        return bytes(out)

    def _malformed(self, frame: bytes) -> mb.Reply | None:
        if len(frame) < 4 or frame[0] == 0 or not crc_ok(frame):
            return None  # broadcast or corrupt: silence
        slave = self.slaves.get(frame[0])
        return None if slave is None else slave.malformed(frame)

    def exchange(self, msg: mb.Request | mb.UnsupportedRequest) -> mb.Reply | None:
        """Message-level twin of :meth:`receive` (the sim's direct path: no bytes, no CRC).

        Gives the reply :meth:`receive` would encode - None where the bus stays silent
        (broadcast, no such slave).
        """
        if msg.slave == 0:
            if not isinstance(msg, _READS):
                for s in self.slaves.values():
                    s.handle(msg)
            return None
        slave = self.slaves.get(msg.slave)
        return None if slave is None else slave.handle(msg)


#: the methods a request goes through, as defined here (captured when this module is imported): a one-call
#: exchange (:mod:`joints.sim.erob_exchange`) runs only while none of them is replaced (a test planting replies)
STOCK = ((ModbusDeviceBus, "exchange", ModbusDeviceBus.exchange), (ModbusFront, "handle", ModbusFront.handle),
         (ModbusFront, "read", ModbusFront.read), (ModbusFront, "write", ModbusFront.write),
         (ModbusFront, "items", ModbusFront.items), (ModbusFront, "read_plan", ModbusFront.read_plan))
