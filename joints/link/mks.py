"""The MKS SERVO42D/57D native RS485 protocol on the link: immediate replies and unsolicited completions.

Rule (manual Parts 4-6, 5.2 #13 and #16, 5.7):

* A request gets at most one *immediate* reply, matched by slave address AND function code.
* Completion frames - a run command's later status 2 (complete) or 3 (end-limit stop), go home's
  and save/clean's later 2, calibrate's later 1/2 (:attr:`~joints.codecs.mks.RunReply.is_completion`)
  - are never a reply: they arrive while other traffic goes on and go to the subscribers
  (:meth:`MksLink.subscribe_completions`) or the link's unsolicited log. So is every other frame
  that does not answer the outstanding request (another drive's late reply, say): the link keeps
  waiting for its own reply instead of failing.
* Broadcast (address 0), group addresses (0x8D) and long packets (0xFC) are send-only: nobody
  answers and nothing is waited for. With respond off (0x8C respond = 0) a drive does not answer
  its run commands (0xF4, 0xF5, 0xF6, 0xFD, 0xFE), while every query still answers. The link
  learns both from the driver (:meth:`MksLink.note_respond`, :meth:`MksLink.note_group`), which
  tells it after the drive confirmed the setting.
* 0x00 read a configuration parameter (V1.0.8): the reply is headed by the parameter's code and has its
  length, so the rule tells the host codec which request is open (:meth:`MksRule.before_send`) and
  matches the reply by that code. 0x42 user ID (V1.0.9): a read is answered by the ID, a write by a
  status; the codec is told the same way.
* Timed returns (V1.0.9 0x01): the drive sends a read's reply every n ms, unasked; one that does
  not answer the outstanding request goes to the subscribers (:meth:`MksLink.subscribe_returns`).
* A status 0 ("set fail", "run fail", "query fail") is the drive's refusal:
  :class:`~joints.errors.DeviceRejected` with ``code=0`` and the function code.
* Only reads are retried (the driver marks them idempotent); a run command whose reply was lost
  is never sent again by the link (:class:`~joints.errors.OutcomeUnknown` instead).

Choice where the manual is silent: the immediate reply of calibrate (0x80) is "0 calibrating";
its 1/2 arrive later and count as completions.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from joints.clock import Clock, MonotonicClock
from joints.codecs import mks
from joints.errors import DeviceRejected, EncodeError
from joints.link.base import Framing, Link, RetryPolicy, Rule, StreamFraming, Subscription, parse_one
from joints.link.trace import TraceRecord
from joints.transports.base import ByteTransport

__all__ = ["BROADCAST", "RUN_FUNCTIONS", "MksLink", "MksRule", "is_completion"]

BROADCAST = mks.BROADCAST
#: Part 6 run commands: 0x8C respond = 0 silences their replies
RUN_FUNCTIONS = frozenset((0xF4, 0xF5, 0xF6, 0xFD, 0xFE))
#: requests that change nothing on the drive (5.1 reads and the 0xF1 query)
_READS = (mks.ReadEncoderCarry, mks.ReadEncoderAddition, mks.ReadSpeed, mks.ReadPulses, mks.ReadIoStatus,
          mks.ReadAngleError, mks.ReadEnPin, mks.ReadGoBackToZeroStatus, mks.ReadProtectionState, mks.QueryStatus,
          mks.ReadVersion, mks.ReadAllParameters, mks.ReadAllStatus, mks.ReadRawEncoder, mks.ReadParameter)
_REPLIES = (mks.EncoderCarryReply, mks.EncoderAdditionReply, mks.SpeedReply, mks.PulsesReply, mks.IoStatusReply,
            mks.AngleErrorReply, mks.EnPinReply, mks.GoBackToZeroStatusReply, mks.ProtectionStateReply,
            mks.CalibrationReply, mks.MotorStatusReply, mks.SetReply, mks.RunReply, mks.VersionReply,
            mks.AllParametersReply, mks.AllStatusReply, mks.TimedReturnReply,
            mks.RawEncoderReply, mks.ParameterReply, mks.UserIdReply)


def is_completion(message: Any) -> bool:
    """A frame that ends a command later (status 2/3 of a run, 1/2 of calibrate), never a reply."""
    return isinstance(message, (mks.RunReply, mks.CalibrationReply)) and message.is_completion


class MksRule(Rule[Any]):
    """The native MKS request/reply rule (see the module docstring)."""

    protocol = "mks-serial"

    def __init__(self, *, echo: bool = False) -> None:
        self.echo = echo  #: the RS485 adapter hears its own transmission: skip that copy
        self.silent: set[int] = set()  #: slaves with respond off: their run commands get no reply
        self.all_silent = False  #: a broadcast 0x8C switched respond off everywhere
        self.group_of: dict[int, int] = {}  #: slave -> its group address (0x8D)

    @property
    def groups(self) -> frozenset[int]:
        return frozenset(self.group_of.values())

    def encode(self, message: Any) -> bytes:
        if isinstance(message, _REPLIES):
            raise EncodeError(f"a host does not send replies: {message!r}")
        return mks.encode(message)

    def _responds(self, address: int) -> bool:
        return not (self.all_silent or address in self.silent)

    def expects_reply(self, request: Any) -> bool:
        if isinstance(request, (mks.LongPacket, mks.UnknownRequest)):
            return False
        address = request.address
        if address == BROADCAST or address in self.group_of.values():
            return False
        return request.function not in RUN_FUNCTIONS or self._responds(address)

    def is_write(self, request: Any) -> bool:
        return not isinstance(request, _READS)

    def before_send(self, framing: Framing[Any], request: Any, frame: Any) -> None:
        if isinstance(framing, StreamFraming):
            if self.echo:
                framing.codec.expect_echo(frame)
            # 0x00 (V1.0.8): its reply is headed by the parameter's code, with that parameter's length; 0x42
            # (V1.0.9): a read is answered by the ID, a write by a status
            framing.codec.expect_reply(None if isinstance(request, mks.ReadParameter)
                                       and request.code not in mks.PARAMETER_CODES else request)

    def describe(self, message: Any) -> str:
        return repr(message)

    def frame_bytes(self, message: Any) -> bytes:
        return mks.encode(message)

    def address(self, message: Any) -> int | None:
        address = getattr(message, "address", None)
        return address if isinstance(address, int) and address != BROADCAST else None

    def is_read(self, request: Any) -> bool:
        return isinstance(request, _READS)

    def complete(self, data: bytes) -> bytes:
        return data if len(data) > 2 and mks.checksum_ok(data) else mks.with_checksum(data)

    def parse_request(self, frame: Any) -> Any:
        return parse_one(mks.MksCodec(mks.Role.DEVICE), frame, "MKS")

    def timeout_text(self, request: Any) -> str:
        return (f"slave {request.address} did not answer: check wiring, slave address, baud rate, that the drive "
                "is powered and speaks the native protocol (0x8E Modbus off), and 0x8C respond")

    def is_reply(self, request: Any, message: Any) -> bool:
        if not isinstance(message, _REPLIES) or is_completion(message):
            return False
        if isinstance(request, mks.ReadParameter) != isinstance(message, mks.ParameterReply):
            return False
        function = request.code if isinstance(request, mks.ReadParameter) else request.function
        if message.address != request.address or message.function != function:
            return False  # not for this request: unsolicited (a late reply of another exchange)
        status = getattr(message, "status", None)
        if isinstance(message, (mks.SetReply, mks.RunReply, mks.MotorStatusReply, mks.TimedReturnReply)) and status == 0:
            raise DeviceRejected(f"slave {request.address} refused {request!r}: status 0 (fail)", code=0,
                                 function=request.function)
        return True


class MksLink(Link[Any]):
    """Host side of a native MKS bus, with the bus-level operations (broadcast, groups, long packets)."""

    rule: MksRule

    def __init__(
        self,
        transport: ByteTransport,
        *,
        policy: RetryPolicy | None = None,
        echo: bool = False,
        clock: Clock | None = None,
        trace: Callable[[TraceRecord], None] | None = None,
        name: str = "mks",
    ) -> None:
        clock = clock or MonotonicClock()
        framing: Framing[Any] = StreamFraming(transport, mks.MksCodec(mks.Role.HOST), clock)
        super().__init__(framing, MksRule(echo=echo), policy=policy, clock=clock, trace=trace, name=name)
        self.echo = echo

    # -- what the drives on this bus were told (the driver reports confirmed settings) -------------
    def note_respond(self, address: int, respond: bool) -> None:
        """Slave ``address`` now answers (or not) its run commands (0x8C); 0 = every slave."""
        if address == BROADCAST:
            self.rule.all_silent = not respond
            self.rule.silent.clear()
        elif respond:
            self.rule.silent.discard(address)
        else:
            self.rule.silent.add(address)

    def note_group(self, address: int, group: int) -> None:
        """Slave ``address`` now also listens to the group address ``group`` (0x8D); 0 = none."""
        if group:
            self.rule.group_of[address] = group
        else:
            self.rule.group_of.pop(address, None)

    # -- send-only frames ---------------------------------------------------------------------------
    def broadcast(self, request: Any) -> None:
        """Send ``request`` to every drive (address 0): all execute, none answers, nothing is waited for."""
        self.send(_readdress(request, BROADCAST))

    def send_group(self, group: int, request: Any) -> None:
        """Send ``request`` to a group address (0x8D): the group executes, nobody answers."""
        if group not in self.rule.group_of.values():
            raise EncodeError(f"{group} (0x{group:02X}) is no group address on bus {self.name}; set it with 0x8D first "
                              f"(known: {sorted(self.rule.groups)})")
        self.send(_readdress(request, group))

    def send_long_packet(self, commands: Sequence[Any]) -> None:
        """One 0xFC long data package: up to five commands for different slaves (5.7); nobody answers."""
        if len(commands) > mks.LONG_PACKET_SLOTS:
            raise EncodeError(f"a long packet holds at most {mks.LONG_PACKET_SLOTS} commands, got {len(commands)}")
        addresses = [c.address for c in commands]
        if len(set(addresses)) != len(addresses):
            raise EncodeError(f"a long packet executes only the first command per slave; addresses {addresses} "
                              "repeat")
        self.send(mks.LongPacket(tuple(commands)))

    def subscribe_completions(self, address: int, callback: Callable[[Any], None]) -> Subscription[Any]:
        """Deliver the completion frames of slave ``address`` to ``callback``."""
        return self.subscribe(lambda m: is_completion(m) and m.address == address, callback)

    def subscribe_returns(self, address: int, code: int, callback: Callable[[Any], None]) -> Subscription[Any]:
        """Deliver the timed returns (V1.0.9 0x01) of read command ``code`` from slave ``address`` - that
        read's replies arriving unasked - to ``callback``."""
        return self.subscribe(lambda m: isinstance(m, _REPLIES) and not is_completion(m) and m.address == address
                              and m.function == code, callback)


def _readdress(request: Any, address: int) -> Any:
    from dataclasses import replace

    if isinstance(request, mks.LongPacket):
        raise EncodeError("a long packet has no address of its own")
    return replace(request, address=address)
