"""Modbus RTU on the link: strict request/reply, one outstanding request per bus.

Rule: a reply is accepted only if its slave, function and address/count answer the request;
anything else raises (a reply from another slave is never accepted). Broadcast (slave 0) gets
no reply. Only reads and writes marked idempotent are retried, so a lost reply to "start" can
never start a motion twice. Frames that arrive while no request is outstanding (a reply too late
for a request that timed out) are unsolicited: logged and traced, never taken as an answer.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol

from joints.clock import Clock
from joints.codecs import modbus as mb
from joints.errors import DeviceRejected, EncodeError, UnexpectedReply
from joints.link.base import DirectFraming, Framing, Link, RetryPolicy, Rule, StreamFraming
from joints.link.trace import TraceRecord
from joints.transports.base import ByteTransport

BROADCAST = 0
_READS = (mb.ReadHoldingRegisters, mb.ReadInputRegisters)


def _describe(msg: object) -> str:
    return repr(msg).replace("ReadRegistersReply", "Reply")


class ModbusRule(Rule[Any]):
    """The Modbus RTU request/reply rule (see the module docstring)."""

    protocol = "modbus-rtu"

    def __init__(self, *, echo: bool = False) -> None:
        self.echo = echo  #: the RS485 adapter hears its own transmission: skip that copy

    def encode(self, message: Any) -> bytes:
        frame = mb.encode(message)
        if message.slave == BROADCAST and isinstance(message, _READS):
            raise EncodeError(f"a read cannot be broadcast (slave 0 never answers): {_describe(message)}")
        return frame

    def check(self, message: Any) -> None:
        mb.check(message)
        if message.slave == BROADCAST and isinstance(message, _READS):
            raise EncodeError(f"a read cannot be broadcast (slave 0 never answers): {_describe(message)}")

    def expects_reply(self, request: Any) -> bool:
        return request.slave != BROADCAST  # type: ignore[no-any-return]

    def is_write(self, request: Any) -> bool:
        return isinstance(request, (mb.WriteSingleRegister, mb.WriteMultipleRegisters))

    def before_send(self, framing: Framing[Any], request: Any, frame: Any) -> None:
        if isinstance(framing, StreamFraming):
            framing.codec.expect_reply_to(request)
            if self.echo:
                framing.codec.expect_echo(frame)

    def describe(self, message: Any) -> str:
        return _describe(message)

    def frame_bytes(self, message: Any) -> bytes:
        return mb.encode(message)

    def timeout_text(self, request: Any) -> str:
        return (f"slave {request.slave} did not answer: check wiring, slave address, baud rate and that the "
                "device is powered")

    def is_reply(self, request: Any, reply: Any) -> bool:
        if reply.slave != request.slave:
            raise UnexpectedReply(
                f"asked slave {request.slave}, got a reply from slave {reply.slave}: {_describe(reply)}"
            )
        if isinstance(reply, mb.ExceptionReply):
            if reply.function != request.function:
                raise UnexpectedReply(
                    f"exception reply for function 0x{reply.function:02X} to a 0x{request.function:02X} request"
                )
            where = getattr(request, "address", None)
            raise DeviceRejected(
                f"slave {request.slave} rejected {_describe(request)}: exception 0x{reply.code:02X} ({reply.text})"
                + (f" at address 0x{where:04X}" if where is not None else ""),
                code=reply.code,
                function=reply.function,
            )
        if isinstance(request, _READS):
            if (isinstance(reply, mb.ReadRegistersReply) and reply.function == request.function
                    and len(reply.values) == request.count):
                return True
        elif isinstance(request, mb.WriteSingleRegister):
            if (isinstance(reply, mb.WriteSingleRegisterReply) and reply.address == request.address
                    and reply.value == request.value):
                return True
        elif (isinstance(request, mb.WriteMultipleRegisters) and isinstance(reply, mb.WriteMultipleRegistersReply)
              and reply.address == request.address and reply.count == len(request.values)):
            return True
        raise UnexpectedReply(f"reply {_describe(reply)} does not answer {_describe(request)}")


class MessagePeer(Protocol):
    """An in-process Modbus bus that answers message objects (the emulated drives)."""

    def exchange(self, msg: mb.Request) -> mb.Reply | None: ...


class ModbusLink(Link[Any]):
    """Host side of a Modbus RTU bus, with the register operations drivers use."""

    def __init__(
        self,
        transport: ByteTransport,
        *,
        policy: RetryPolicy | None = None,
        echo: bool = False,
        clock: Clock | None = None,
        trace: Callable[[TraceRecord], None] | None = None,
        name: str = "modbus",
        peer: MessagePeer | None = None,
    ) -> None:
        """``peer`` (sim): hand requests to an in-process bus as objects (the direct path, no bytes)."""
        from joints.clock import MonotonicClock

        clock = clock or MonotonicClock()
        framing: Framing[Any] = (StreamFraming(transport, mb.ModbusRtuCodec(mb.Role.HOST), clock) if peer is None
                                 else DirectFraming(peer, transport))
        super().__init__(framing, ModbusRule(echo=echo), policy=policy, clock=clock, trace=trace, name=name)
        self.echo = echo

    def read_registers(self, slave: int, address: int, count: int, *, input_registers: bool = False) -> tuple[int, ...]:
        """FC03 (or FC04) read of ``count`` registers from ``address``."""
        req: mb.Request = (mb.ReadInputRegisters(slave, address, count) if input_registers
                           else mb.ReadHoldingRegisters(slave, address, count))
        reply = self.request(req, idempotent=True)
        assert isinstance(reply, mb.ReadRegistersReply)
        return reply.values

    def write_register(self, slave: int, address: int, value: int, *, idempotent: bool = True) -> None:
        """FC06 write of one register (value 0..0xFFFF)."""
        self.request(mb.WriteSingleRegister(slave, address, value), idempotent=idempotent)

    def write_registers(self, slave: int, address: int, values: Sequence[int], *, idempotent: bool = True) -> None:
        """FC16 write of consecutive registers."""
        self.request(mb.WriteMultipleRegisters(slave, address, tuple(values)), idempotent=idempotent)


__all__ = ["BROADCAST", "MessagePeer", "ModbusLink", "ModbusRule", "RetryPolicy"]
