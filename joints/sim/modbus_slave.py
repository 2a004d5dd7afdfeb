"""Device side of Modbus RTU: a register image that answers frames the way a drive does.

Rule: the same codec as the host, in device role. A bus object dispatches frames to slaves by
address (broadcast: every slave executes, nobody answers). A slave answers reads and writes from
its register table: unknown addresses -> exception 02, writes to read-only registers -> 02,
values outside a register's documented range -> 03. Block reads may span the gaps between
registers (gaps read 0) as long as the first and last word belong to registers. Subclasses
(emulators) override :meth:`ModbusSlave.on_read` / :meth:`ModbusSlave.on_write` to add
behaviour.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping

from joints.codecs import modbus as mb
from joints.devices.registers import Access, Register, RegisterTable
from joints.errors import CommandError, FrameError

ILLEGAL_FUNCTION = 0x01
ILLEGAL_DATA_ADDRESS = 0x02
ILLEGAL_DATA_VALUE = 0x03
SERVER_DEVICE_FAILURE = 0x04


class ModbusException(Exception):
    """Raised inside a slave to answer with a Modbus exception reply."""

    def __init__(self, code: int, reason: str = "") -> None:
        super().__init__(reason or mb.EXCEPTION_TEXT.get(code, ""))
        self.code = code


class ModbusSlave:
    """A register image for one slave address, validated against a :class:`RegisterTable`."""

    def __init__(self, table: RegisterTable, address: int, *, values: Mapping[str, int] | None = None) -> None:
        self.table = table
        self.address = address
        self.words: dict[int, int] = {}
        #: typed value of every register by name, kept in step with ``words`` (fast reads for emulators)
        self.v: dict[str, int] = {}
        self._read_plans: dict[tuple[int, int], tuple[int, ...]] = {}
        self._by_name = {reg.name: (reg, *reg.type_range) for reg in table}
        for reg in table:
            self._store(reg, reg.default)
        for name, value in (values or {}).items():
            self.set(name, value)
        #: every accepted write as (register name, value), in order (tests, traces)
        self.write_log: list[tuple[str, int]] = []

    # -- typed access for emulators and tests ------------------------------------------------
    def _store(self, reg: Register, value: int) -> None:
        self.v[reg.name] = value
        raw = value & (0xFFFF if reg.words == 1 else 0xFFFFFFFF)
        if reg.words == 1:
            self.words[reg.address] = raw
        else:
            hi, lo = raw >> 16, raw & 0xFFFF
            a, b = (lo, hi) if reg.low_word_first else (hi, lo)
            self.words[reg.address] = a
            self.words[reg.address + 1] = b

    def get(self, key: str | int) -> int:
        """Typed value of a register from the image."""
        if isinstance(key, str):
            value = self.v.get(key)
            if value is not None:
                return value
        reg = self.table.get(key)
        return self.v[reg.name]

    def _refresh(self, reg: Register) -> int:
        """Recompute a register's typed value from its words (after a raw word write)."""
        value = reg.from_words([self.words.get(reg.address + i, 0) for i in range(reg.words)])
        self.v[reg.name] = value
        return value

    def set(self, key: str | int, value: int) -> None:
        """Set a register in the image (no access check: this is the device itself)."""
        entry = self._by_name.get(key) if isinstance(key, str) else None
        if entry is None:
            reg = self.table.get(key)
            entry = self._by_name[reg.name]
        reg, lo, hi = entry
        value = int(value)
        if not lo <= value <= hi:
            # saturate like a drive's status registers would, never wrap silently
            value = max(lo, min(hi, value))
        self.v[reg.name] = value
        if reg.words == 1:
            self.words[reg.address] = value & 0xFFFF
        else:
            self._store(reg, value)

    # -- hooks ------------------------------------------------------------------------------
    def on_read(self, start: int, count: int) -> None:
        """Called before a read is served (refresh status registers here)."""

    def on_write(self, reg: Register, value: int) -> None:
        """Called after a register was written with its full typed value (act on commands here).

        Raise :class:`ModbusException` to refuse; the image is restored then.
        """

    # -- request handling -------------------------------------------------------------------
    def _check_read(self, start: int, count: int) -> None:
        if not 1 <= count <= mb.MAX_READ:
            raise ModbusException(ILLEGAL_DATA_VALUE, f"read count {count}")
        first = self.table.owner(start)
        last = self.table.owner(start + count - 1)
        if first is None or last is None:
            raise ModbusException(ILLEGAL_DATA_ADDRESS)

    def read(self, start: int, count: int) -> tuple[int, ...]:
        self._check_read(start, count)
        self.on_read(start, count)
        plan = self._read_plans.get((start, count))
        if plan is None:
            # addresses that hold data; gaps and write-only command registers read as 0
            plan = self._read_plans[(start, count)] = tuple(
                a if (reg := self.table.owner(a)) is not None and reg.access is not Access.COMMAND else -1
                for a in range(start, start + count)
            )
        words = self.words
        return tuple(words.get(a, 0) if a >= 0 else 0 for a in plan)

    def write(self, start: int, words: tuple[int, ...]) -> None:
        if not 1 <= len(words) <= mb.MAX_WRITE:
            raise ModbusException(ILLEGAL_DATA_VALUE, f"write count {len(words)}")
        touched: list[Register] = []
        for i in range(len(words)):
            reg = self.table.owner(start + i)
            if reg is None or not reg.access.writable:
                raise ModbusException(ILLEGAL_DATA_ADDRESS)
            if not touched or touched[-1] is not reg:
                touched.append(reg)
        saved = dict(self.words)
        saved_v = {reg.name: self.v[reg.name] for reg in touched}
        logged = len(self.write_log)
        for i, w in enumerate(words):
            self.words[start + i] = w
        try:
            # validate every touched register before any is logged or acted on: a refused
            # block write must have no effect at all
            accepted: list[tuple[Register, int]] = []
            for reg in touched:
                value = self._refresh(reg)
                try:
                    reg.check(value)
                except CommandError as exc:
                    raise ModbusException(ILLEGAL_DATA_VALUE, str(exc)) from exc
                accepted.append((reg, value))
            for reg, value in accepted:
                self.write_log.append((reg.name, value))
                self.on_write(reg, value)
        except ModbusException:
            self.words = saved
            self.v.update(saved_v)
            del self.write_log[logged:]
            raise

    def handle(self, request: mb.Request | mb.UnsupportedRequest) -> mb.Reply:
        """Execute a request addressed to this slave and build the reply."""
        try:
            if isinstance(request, (mb.ReadHoldingRegisters, mb.ReadInputRegisters)):
                return mb.ReadRegistersReply(
                    request.slave, request.function, self.read(request.address, request.count)
                )
            if isinstance(request, mb.WriteSingleRegister):
                self.write(request.address, (request.value,))
                return mb.WriteSingleRegisterReply(request.slave, request.address, request.value)
            if isinstance(request, mb.WriteMultipleRegisters):
                self.write(request.address, request.values)
                return mb.WriteMultipleRegistersReply(request.slave, request.address, len(request.values))
            raise ModbusException(ILLEGAL_FUNCTION)
        except ModbusException as exc:
            return mb.ExceptionReply(request.slave, request.function, exc.code)


class ModbusDeviceBus:
    """All emulated slaves on one RS485 bus: bytes in, reply bytes out (a loopback/pty peer)."""

    def __init__(self, slaves: Iterable[ModbusSlave] = (), *, trace: Callable[[str, bytes], None] | None = None) -> None:
        self.slaves: dict[int, ModbusSlave] = {}
        for s in slaves:
            self.add(s)
        self._codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
        self.trace = trace
        self.frame_errors = 0

    def add(self, slave: ModbusSlave) -> None:
        if slave.address in self.slaves:
            raise ValueError(f"two emulated slaves at address {slave.address}")
        self.slaves[slave.address] = slave

    def receive(self, data: bytes) -> bytes:
        """Feed received bytes; return the bytes the addressed slaves send back."""
        codec = self._codec
        codec.feed(data)
        out = bytearray()
        while True:
            try:
                msg = codec.next_message()
            except FrameError:
                self.frame_errors += 1  # a real slave stays silent on a corrupt frame
                continue
            if msg is None:
                break
            out += self._dispatch(msg)
        return bytes(out)

    def silence(self) -> bytes:
        """The line went quiet (t3.5): drop incomplete garbage."""
        self._codec.flush()
        return self.receive(b"")

    def exchange(self, msg: mb.Request) -> mb.Reply | None:
        """Message-level twin of :meth:`receive` (the sim's direct path: no bytes, no CRC).

        Gives the reply :meth:`receive` would encode - None where the bus stays silent
        (broadcast, no such slave).
        """
        if msg.slave == 0:
            if not isinstance(msg, (mb.ReadHoldingRegisters, mb.ReadInputRegisters)):
                for s in self.slaves.values():
                    s.handle(msg)
            return None
        slave = self.slaves.get(msg.slave)
        return None if slave is None else slave.handle(msg)

    def _dispatch(self, msg: mb.Message) -> bytes:
        if not isinstance(msg, (mb.ReadHoldingRegisters, mb.ReadInputRegisters, mb.WriteSingleRegister, mb.WriteMultipleRegisters, mb.UnsupportedRequest)):
            return b""
        if msg.slave == 0:
            for s in self.slaves.values():
                if not isinstance(msg, (mb.ReadHoldingRegisters, mb.ReadInputRegisters)):
                    s.handle(msg)
            return b""
        slave = self.slaves.get(msg.slave)
        if slave is None:
            return b""
        return mb.encode(slave.handle(msg))
