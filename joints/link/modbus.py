"""Modbus RTU link: one outstanding request per bus, replies matched, timeouts and retries.

Rule: a reply is accepted only if its slave, function and address/count answer the request;
anything else raises (a reply from another slave is never accepted). Broadcast (slave 0) gets
no reply. Only reads and writes marked idempotent are retried, so a lost reply to "start" can
never start a motion twice.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

from joints.clock import Clock, MonotonicClock
from joints.codecs import modbus as mb
from joints.errors import (
    DeviceRejected,
    EncodeError,
    FrameError,
    PeerProtocolError,
    ReplyTimeout,
    UnexpectedReply,
)
from joints.link.trace import TraceRecord
from joints.transports.base import ByteTransport

BROADCAST = 0


@dataclass(frozen=True, slots=True)
class RetryPolicy:
    timeout: float = 0.1  #: seconds to wait for a complete reply
    retries: int = 2  #: extra attempts for idempotent requests after a timeout or corrupt reply


def _describe(msg: object) -> str:
    return repr(msg).replace("ReadRegistersReply", "Reply")


class ModbusLink:
    """Host side of a Modbus RTU bus."""

    def __init__(
        self,
        transport: ByteTransport,
        *,
        policy: RetryPolicy | None = None,
        echo: bool = False,
        clock: Clock | None = None,
        trace: Callable[[TraceRecord], None] | None = None,
        name: str = "modbus",
    ) -> None:
        self.transport = transport
        self.policy = policy or RetryPolicy()
        self.echo = echo
        self.clock: Clock = clock or MonotonicClock()
        self.trace = trace
        self.name = name
        self._codec = mb.ModbusRtuCodec(mb.Role.HOST)
        self._lock = threading.RLock()
        self.transactions = 0
        self.retries_used = 0

    # -- public register operations --------------------------------------------------------
    def read_registers(self, slave: int, address: int, count: int, *, input_registers: bool = False) -> tuple[int, ...]:
        """FC03 (or FC04) read of ``count`` registers from ``address``."""
        req: mb.Request = (
            mb.ReadInputRegisters(slave, address, count)
            if input_registers
            else mb.ReadHoldingRegisters(slave, address, count)
        )
        reply = self.transact(req, idempotent=True)
        assert isinstance(reply, mb.ReadRegistersReply)
        return reply.values

    def write_register(self, slave: int, address: int, value: int, *, idempotent: bool = True) -> None:
        """FC06 write of one register (value 0..0xFFFF)."""
        self.transact(mb.WriteSingleRegister(slave, address, value), idempotent=idempotent)

    def write_registers(self, slave: int, address: int, values: Sequence[int], *, idempotent: bool = True) -> None:
        """FC16 write of consecutive registers."""
        self.transact(mb.WriteMultipleRegisters(slave, address, tuple(values)), idempotent=idempotent)

    # -- the transaction -------------------------------------------------------------------
    def transact(self, request: mb.Request, *, idempotent: bool = False) -> mb.Reply | None:
        """Send ``request`` and return its matching reply (None for broadcast)."""
        frame = mb.encode(request)  # raises EncodeError before anything is sent
        if request.slave == BROADCAST and isinstance(request, (mb.ReadHoldingRegisters, mb.ReadInputRegisters)):
            raise EncodeError(f"{self.name}: a read cannot be broadcast (slave 0 never answers): {_describe(request)}")
        attempts = 1 + (self.policy.retries if idempotent else 0)
        with self._lock:
            last: Exception | None = None
            for attempt in range(attempts):
                if attempt:
                    self.retries_used += 1
                try:
                    return self._once(request, frame)
                except (ReplyTimeout, PeerProtocolError) as exc:
                    if isinstance(exc, UnexpectedReply):
                        raise
                    last = exc
            assert last is not None
            if attempts > 1 and isinstance(last, ReplyTimeout):
                raise ReplyTimeout(f"{last} (after {attempts} attempts)") from last
            raise last

    def _record(self, direction: str, data: bytes, meaning: str) -> None:
        if self.trace is not None:
            try:
                self.trace(TraceRecord(self.clock.now(), direction, self.name, data, meaning))
            except Exception:  # noqa: BLE001, S110 - tracing must not break the bus
                pass

    def _once(self, request: mb.Request, frame: bytes) -> mb.Reply | None:
        codec = self._codec
        codec.clear()
        self.transport.reset_input()
        self.transactions += 1
        if self.trace is not None:
            self._record("tx", frame, _describe(request))
        self.transport.write(frame)
        if request.slave == BROADCAST:
            return None
        codec.expect_reply_to(request)
        if self.echo:
            codec.expect_echo(frame)
        timeout = self.policy.timeout
        deadline = self.clock.now() + timeout
        error: FrameError | None = None
        flushed = False
        while True:
            try:
                msg = codec.next_message()
            except FrameError as exc:
                self._record("rx", exc.data, f"error: {exc}")
                error = error or exc
                continue
            if msg is not None:
                if self.trace is not None:
                    self._record("rx", mb.encode(msg), _describe(msg))
                return self._match(request, msg)
            if flushed:
                break
            remaining = deadline - self.clock.now()
            chunk = self.transport.read(remaining) if remaining > 0 else b""
            if chunk:
                codec.feed(chunk)
                continue
            # Silence until the deadline: whatever is buffered will not complete.
            codec.flush()
            flushed = True
        if error is not None:
            raise error
        raise ReplyTimeout(
            f"{self.name}: no reply from slave {request.slave} to {_describe(request)} "
            f"within {timeout * 1000:.0f} ms on {self.transport.name}; check wiring, slave "
            "address, baud rate and that the device is powered"
        )

    @staticmethod
    def _match(request: mb.Request, reply: mb.Message) -> mb.Reply:
        if reply.slave != request.slave:
            raise UnexpectedReply(
                f"asked slave {request.slave}, got a reply from slave {reply.slave}: {_describe(reply)}"
            )
        if isinstance(reply, mb.ExceptionReply):
            if reply.function != request.function:
                raise UnexpectedReply(
                    f"exception reply for function 0x{reply.function:02X} to a "
                    f"0x{request.function:02X} request"
                )
            where = getattr(request, "address", None)
            raise DeviceRejected(
                f"slave {request.slave} rejected {_describe(request)}: exception "
                f"0x{reply.code:02X} ({reply.text})"
                + (f" at address 0x{where:04X}" if where is not None else ""),
                code=reply.code,
                function=reply.function,
            )
        if isinstance(request, (mb.ReadHoldingRegisters, mb.ReadInputRegisters)):
            if (isinstance(reply, mb.ReadRegistersReply) and reply.function == request.function
                    and len(reply.values) == request.count):
                return reply
        elif isinstance(request, mb.WriteSingleRegister):
            if (
                isinstance(reply, mb.WriteSingleRegisterReply)
                and reply.address == request.address
                and reply.value == request.value
            ):
                return reply
        elif (
            isinstance(request, mb.WriteMultipleRegisters)
            and isinstance(reply, mb.WriteMultipleRegistersReply)
            and reply.address == request.address
            and reply.count == len(request.values)
        ):
            return reply
        raise UnexpectedReply(f"reply {_describe(reply)} does not answer {_describe(request)}")


class MessagePeer(Protocol):
    """An in-process Modbus bus that answers message objects (the emulated drives)."""

    def exchange(self, msg: mb.Request) -> mb.Reply | None: ...


class DirectModbusLink(ModbusLink):
    """The sim's direct path: requests go to the emulated bus as message objects, no bytes.

    Rule: identical results to the byte path - the same validation (every request is still
    encoded, so an illegal one raises the same EncodeError before anything happens), the same
    reply matching and errors, the same trace records (frames are encoded only when tracing).
    """

    def __init__(self, peer: MessagePeer, transport: ByteTransport, **kw: object) -> None:
        super().__init__(transport, **kw)  # type: ignore[arg-type]
        self.peer = peer

    def _once(self, request: mb.Request, frame: bytes) -> mb.Reply | None:
        self.transactions += 1
        if self.trace is not None:
            self._record("tx", frame, _describe(request))
        reply = self.peer.exchange(request)
        if request.slave == BROADCAST:
            return None
        if reply is None:
            raise ReplyTimeout(
                f"{self.name}: no reply from slave {request.slave} to {_describe(request)} "
                f"(no emulated drive at that address)"
            )
        if self.trace is not None:
            self._record("rx", mb.encode(reply), _describe(reply))
        return self._match(request, reply)
