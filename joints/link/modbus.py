"""Modbus RTU on the link: strict request/reply, one outstanding request per bus.

Rule: a reply is accepted only if its slave, function and address/count answer the request;
anything else raises (a reply from another slave is never accepted). Broadcast (slave 0) gets
no reply. A device whose own frame breaks a Modbus rule (the MKS FC16 home-parameter request that
announces 3 registers and 5 bytes, ERRATA DOC-MKS-5) is reached by sending that PDU as an
:class:`~joints.codecs.modbus.UnsupportedRequest`: an FC06/FC16 PDU is a write, answered by the
ordinary write reply to its address (and count). Only reads and writes marked idempotent are retried, so a lost reply to "start" can
never start a motion twice. Frames that arrive while no request is outstanding (a reply too late
for a request that timed out) are unsolicited: logged and traced, never taken as an answer.

Failure replies are per slave: a device that answers a write it refuses with an ordinary-looking
reply - FC06 with register data 0xFFFF, FC16 with register quantity 0 (MKS V1.0.6+: "If write
fails") - is declared by its driver (:meth:`ModbusLink.failure_replies`), and for it such a reply
is :class:`~joints.errors.DeviceRejected` (``code=0``), decided before the echo check. An FC06
write of 0xFFFF itself is answered alike whether taken or refused: the device's own answer decides
(read back, or the register cannot hold 0xFFFF), else :class:`~joints.errors.OutcomeUnknown`.
Other slaves' replies are judged as Modbus has them (a mismatch is :class:`UnexpectedReply`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol

from joints.clock import Clock
from joints.codecs import modbus as mb
from joints.codecs.crc import append_crc, crc_ok
from joints.errors import DeviceRejected, EncodeError, OutcomeUnknown, UnexpectedReply
from joints.link.base import DirectFraming, Framing, Link, RetryPolicy, Rule, StreamFraming, parse_one
from joints.link.trace import TraceRecord
from joints.transports.base import ByteTransport

BROADCAST = 0
_READS = (mb.ReadHoldingRegisters, mb.ReadInputRegisters)
#: 8-byte frames besides the reads: address, function, two words, CRC
_FIXED = (mb.WriteSingleRegister, mb.WriteSingleRegisterReply, mb.WriteMultipleRegistersReply)
#: FC06 register data of a failure reply (FC16's: register quantity 0)
FAILED_VALUE = 0xFFFF
#: after an FC06 write of 0xFFFF to ``address`` answered with 0xFFFF: does the register hold 0xFFFF now?
#: True (taken), False (refused), None (the device cannot tell)
HoldsFailedValue = Callable[[int], "bool | None"]


def _describe(msg: object) -> str:
    return repr(msg).replace("ReadRegistersReply", "Reply")


class ModbusRule(Rule[Any]):
    """The Modbus RTU request/reply rule (see the module docstring)."""

    protocol = "modbus-rtu"

    def __init__(self, *, echo: bool = False) -> None:
        self.echo = echo  #: the RS485 adapter hears its own transmission: skip that copy
        #: slaves that answer refused writes with failure replies (their drivers declare them)
        self.failure_replies: dict[int, HoldsFailedValue] = {}

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
        if isinstance(request, mb.UnsupportedRequest):
            return request.function in (mb.WRITE_SINGLE_REGISTER, mb.WRITE_MULTIPLE_REGISTERS)
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

    def frame_size(self, message: Any) -> int:
        """RTU frame length without encoding (address, function, data, CRC): the direct path's timing."""
        kind = type(message)
        if kind in _READS or kind in _FIXED:
            return 8
        if kind is mb.ReadRegistersReply:
            return 5 + 2 * len(message.values)
        if kind is mb.WriteMultipleRegisters:
            return 9 + 2 * len(message.values)
        if kind is mb.ExceptionReply:
            return 5
        return len(mb.encode(message))

    def address(self, message: Any) -> int | None:
        slave = getattr(message, "slave", None)
        return slave if isinstance(slave, int) and slave != BROADCAST else None

    def is_read(self, request: Any) -> bool:
        return isinstance(request, _READS)

    def complete(self, data: bytes) -> bytes:
        return data if len(data) > 2 and crc_ok(data) else append_crc(data)

    def parse_request(self, frame: Any) -> Any:
        return parse_one(mb.ModbusRtuCodec(mb.Role.DEVICE), frame, "Modbus RTU")

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
        if request.slave in self.failure_replies and _single_write(request) != FAILED_VALUE:
            _failure_reply(request, reply)
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
        elif isinstance(request, mb.UnsupportedRequest) and len(request.pdu) >= 4:
            # a raw write PDU: start address and count (FC16) or value (FC06) lead it, as in every write
            address, second = int.from_bytes(request.pdu[0:2], "big"), int.from_bytes(request.pdu[2:4], "big")
            if isinstance(reply, mb.WriteMultipleRegistersReply) and request.function == mb.WRITE_MULTIPLE_REGISTERS:
                answered = reply.address == address and reply.count == second
            else:
                answered = (isinstance(reply, mb.WriteSingleRegisterReply) and request.function == mb.WRITE_SINGLE_REGISTER
                            and reply.address == address and reply.value == second)
            if answered:
                return True
        raise UnexpectedReply(f"reply {_describe(reply)} does not answer {_describe(request)}")


def _address(request: Any) -> int | None:
    if isinstance(request, mb.UnsupportedRequest):
        return int.from_bytes(request.pdu[0:2], "big") if len(request.pdu) >= 2 else None
    return getattr(request, "address", None)


def _single_write(request: Any) -> int | None:
    """The value of an FC06 write (also one sent as a raw PDU), else None."""
    if isinstance(request, mb.WriteSingleRegister):
        return request.value
    if isinstance(request, mb.UnsupportedRequest) and request.function == mb.WRITE_SINGLE_REGISTER \
            and len(request.pdu) == 4:
        return int.from_bytes(request.pdu[2:4], "big")
    return None


def _failure_reply(request: Any, reply: Any) -> None:
    """A write answered at its own address with register data 0xFFFF (FC06) or register quantity 0
    (FC16), by a slave declared to answer refusals so: :class:`~joints.errors.DeviceRejected` with
    ``code=0``, like a native MKS status 0."""
    address = _address(request)
    failed = (isinstance(reply, mb.WriteSingleRegisterReply) and request.function == mb.WRITE_SINGLE_REGISTER
              and reply.address == address and reply.value == FAILED_VALUE) or (
        isinstance(reply, mb.WriteMultipleRegistersReply) and request.function == mb.WRITE_MULTIPLE_REGISTERS
        and reply.address == address and reply.count == 0)
    if failed:
        raise DeviceRejected(f"slave {request.slave} refused {_describe(request)}: failure reply {_describe(reply)} "
                             "(the write failed)", code=0, function=request.function)


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
                                 else DirectFraming(peer, transport, mb.as_received))
        rule = ModbusRule(echo=echo)
        super().__init__(framing, rule, policy=policy, clock=clock, trace=trace, name=name)
        self.echo = echo
        self._failure_replies = rule.failure_replies

    def failure_replies(self, slave: int, holds: HoldsFailedValue) -> None:
        """Declare that ``slave`` answers a write it refuses with FC06 register data 0xFFFF / FC16 register
        quantity 0 (its driver knows, from its family and firmware). ``holds(address)`` decides an FC06
        write of 0xFFFF answered with 0xFFFF: True taken, False refused, None cannot tell."""
        self._failure_replies[slave] = holds

    def request(self, request: Any, *, idempotent: bool = False) -> Any:
        """:meth:`Link.request`; an FC06 write of 0xFFFF to a slave with failure replies is decided by
        the slave's ``holds`` (see :meth:`failure_replies`)."""
        reply = super().request(request, idempotent=idempotent)
        holds = self._failure_replies.get(getattr(request, "slave", None))  # type: ignore[arg-type]
        if holds is None or _single_write(request) != FAILED_VALUE:
            return reply
        address = _address(request)
        assert address is not None
        held = holds(address)
        if held is None:
            raise OutcomeUnknown(f"slave {request.slave} answered {_describe(request)} with {_describe(reply)}, which "
                                 "is also its failure reply, and cannot report the register: the write's outcome is "
                                 "unknown - read back what matters before acting on it")
        if not held:
            raise DeviceRejected(f"slave {request.slave} refused {_describe(request)}: failure reply "
                                 f"{_describe(reply)} (0x{address:04X} does not hold 0xFFFF)", code=0,
                                 function=mb.WRITE_SINGLE_REGISTER)
        return reply

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

    def write_pdu(self, slave: int, function: int, pdu: bytes, *, idempotent: bool = True) -> None:
        """Send a write PDU exactly as given (after the function code): a device's own frame that breaks a
        Modbus rule, such as the MKS FC16 0x90 request (3 registers, 5 bytes); the reply is the normal one."""
        self.request(mb.UnsupportedRequest(slave, function, bytes(pdu)), idempotent=idempotent)


__all__ = ["BROADCAST", "FAILED_VALUE", "HoldsFailedValue", "MessagePeer", "ModbusLink", "ModbusRule", "RetryPolicy"]
