"""The ZeroErr eRob CAN custom protocol on the link: requests on 0x640+node, replies on 0x5C0+node.

Rule: a reply carries nothing but its node (eRunner 7.1-7.3): no index, no sequence number. So
a reply is accepted when :func:`joints.codecs.erob_can.answers` says its node and shape fit the
request - a value for a read, 0x3E for a write or command; an error reply (code of appendix 1)
or a failed read (0x80) raises :class:`~joints.errors.DeviceRejected` with the manual's text.
One request per node is outstanding at a time (the link's lock makes it one per bus).

Frames that cannot be the answer are unsolicited (delivered to subscribers, else logged), never
an answer: replies of other nodes, a 0x3E while a read waits, a value while a write waits, and
frames that are not eRob replies at all (:class:`OtherFrame`: another host's requests, CANopen
traffic sharing the bus, remote and error frames).

Late replies. Shapes tell a value from an acknowledgement, but not one acknowledgement from
another, nor one value from another. Two cases make a late reply possible, and the link keeps
each from answering a later request:

* "Enable"/"disable" (command 0x0100) is acknowledged more than once: the monitor figures of
  chapter 4 show six 0x3E for one enable (4-21, 4-27) and five for one disable (4-7), all in the
  same millisecond; the 7.4 tables print one. After 0x0100 the node is *unsynchronised*: before
  its next write or command the link reads ``error_code`` (0x001F) as a fence. A read is never
  answered by 0x3E, so the extra acknowledgements arriving first are unsolicited, and the
  fence's value proves they are all in (a node answers in order). A read is its own fence.
* A request that timed out (or got a corrupt frame) may still be answered. The link waits out
  late replies after every failed attempt (:attr:`~joints.link.base.RetryPolicy.late`) and
  discards them, and the node is unsynchronised: its next write or command is fenced as above.
  A value later than the timeout plus the late window cannot be told from an answer to a later
  read: a device fault the protocol gives no means to detect.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import can

from joints.clock import Clock, MonotonicClock
from joints.codecs import erob_can as ec
from joints.errors import DeviceRejected, PeerProtocolError, ReplyTimeout
from joints.link.base import FrameFraming, Link, RetryPolicy, Rule
from joints.link.trace import TraceRecord

__all__ = ["FENCE_INDEX", "MULTI_ACK_COMMANDS", "ErobCanLink", "ErobCanRule", "OtherFrame", "decode_host"]

#: commands that are acknowledged more than once (chapter 4 monitor figures)
MULTI_ACK_COMMANDS = frozenset({0x0100})
#: what the fence reads: error code (always readable, 7.5.1)
FENCE_INDEX = 0x001F


@dataclass(frozen=True, slots=True)
class OtherFrame:
    """A frame on the bus that is not an eRob reply (other hosts' requests, other protocols)."""

    frame: can.Message

    def __repr__(self) -> str:
        f = self.frame
        kind = " remote" if f.is_remote_frame else " error" if f.is_error_frame else ""
        ident = f"0x{f.arbitration_id:08X}" if f.is_extended_id else f"0x{f.arbitration_id:03X}"
        return f"OtherFrame({ident}{kind} [{bytes(f.data).hex(' ').upper()}])"


def decode_host(frame: can.Message) -> ec.Reply | OtherFrame:
    """A received frame: an eRob reply (FrameError if malformed) or :class:`OtherFrame`."""
    if (frame.is_extended_id or frame.is_remote_frame or frame.is_error_frame
            or ec.decoder_role(frame.arbitration_id) is not ec.Role.HOST):
        return OtherFrame(frame)
    return ec.decode(frame, ec.Role.HOST)  # type: ignore[return-value]


def _describe(message: Any) -> str:
    if isinstance(message, ec.Read):
        sub = "" if message.subindex is None else f"/{message.subindex}"
        return f"node {message.node} read 0x{message.index:04X}{sub}"
    if isinstance(message, ec.Write):
        sub = "" if message.subindex is None else f"/{message.subindex}"
        return f"node {message.node} write 0x{message.index:04X}{sub} = {message.value}"
    if isinstance(message, ec.Command):
        par = "" if message.parameter is None else f"({message.parameter})"
        return f"node {message.node} command 0x{message.index:04X}{par}"
    if isinstance(message, ec.ValueReply):
        return f"node {message.node} value {message.value}"
    if isinstance(message, ec.Ack):
        return f"node {message.node} ok (3E)"
    if isinstance(message, ec.ErrorReply):
        return f"node {message.node} error 0x{message.code:04X}"
    if isinstance(message, ec.ReadFailed):
        return f"node {message.node} failed (80)"
    return repr(message)


class ErobCanRule(Rule[Any]):
    """The eRob CAN custom-protocol request/reply rule (see the module docstring)."""

    protocol = "erob-can"

    def __init__(self, error_text: Callable[[int], tuple[str, str]] | None = None) -> None:
        #: code -> (text, hint) of appendix 1 (the device layer's table; the link cannot import it)
        self.error_text = error_text

    def encode(self, message: Any) -> can.Message:
        return ec.encode(message)

    def expects_reply(self, request: Any) -> bool:
        return True

    def is_write(self, request: Any) -> bool:
        return isinstance(request, (ec.Write, ec.Command))

    def is_reply(self, request: Any, message: Any) -> bool:
        if isinstance(message, OtherFrame) or not ec.answers(request, message):
            return False
        if isinstance(message, ec.ErrorReply):
            text, hint = self.error_text(message.code) if self.error_text else ("(see appendix 1)", "")
            raise DeviceRejected(f"{_describe(request)} refused: error 0x{message.code:04X} {text}"
                                 + (f" - {hint}" if hint else ""), code=message.code)
        if isinstance(message, ec.ReadFailed):
            raise DeviceRejected(f"{_describe(request)} failed: the drive answered 0x80 (table 7-4: the read "
                                 "failed; the index/subindex may not exist on this drive or firmware)",
                                 code=ec.READ_FAILED)
        return True

    def describe(self, message: Any) -> str:
        return _describe(message)

    def frame_bytes(self, message: Any) -> bytes:
        if isinstance(message, OtherFrame):
            return bytes(message.frame.data)
        return bytes(ec.encode(message).data)

    def frame_id(self, message: Any) -> int | None:
        if isinstance(message, OtherFrame):
            return int(message.frame.arbitration_id)
        return int(ec.encode(message).arbitration_id)

    def address(self, message: Any) -> int | None:
        node = getattr(message, "node", None)
        return node if isinstance(node, int) else None

    def is_read(self, request: Any) -> bool:
        return isinstance(request, ec.Read)

    def parse_request(self, frame: Any) -> Any:
        return ec.decode(frame, ec.Role.DEVICE)

    def timeout_text(self, request: Any) -> str:
        return (f"node {request.node} did not answer on 0x{ec.REPLY_BASE + request.node:03X}: check the node id, "
                "that the bus runs at 1 Mbit/s, termination (120 ohm at both ends), wiring and power")


class ErobCanLink(Link[Any]):
    """Host side of an eRob CAN custom-protocol bus (see the module docstring)."""

    def __init__(
        self,
        transport: Any,
        *,
        policy: RetryPolicy | None = None,
        clock: Clock | None = None,
        trace: Callable[[TraceRecord], None] | None = None,
        name: str = "erob-can",
        error_text: Callable[[int], tuple[str, str]] | None = None,
    ) -> None:
        """``error_text``: code -> (text, hint) for error replies (the registry passes appendix 1's)."""
        clock = clock or MonotonicClock()
        super().__init__(FrameFraming(transport, decode_host, clock), ErobCanRule(error_text), policy=policy,
                         clock=clock, trace=trace, name=name)
        self._unsynced: set[int] = set()  #: nodes that may still send acknowledgements: fence first
        self.fences = 0  #: fence reads sent

    def _once(self, request: Any, frame: Any) -> Any:
        node = request.node
        if node in self._unsynced and not isinstance(request, ec.Read):
            self._fence(node)
        reply = self._guarded(request, frame)
        if isinstance(reply, ec.ValueReply):
            self._unsynced.discard(node)
        elif isinstance(request, ec.Command) and request.index in MULTI_ACK_COMMANDS:
            self._unsynced.add(node)
        return reply

    def _guarded(self, request: Any, frame: Any) -> Any:
        try:
            return super()._once(request, frame)
        except (ReplyTimeout, PeerProtocolError):
            self._unsynced.add(request.node)  # a late answer may still come: fence before the next write
            raise

    def _fence(self, node: int) -> None:
        fence = ec.Read(node, FENCE_INDEX)
        self.fences += 1
        try:
            self._guarded(fence, ec.encode(fence))
        except (ReplyTimeout, PeerProtocolError):
            self._discard_late()
            raise
        self._unsynced.discard(node)

    def resync(self, node: int) -> None:
        """Treat ``node`` as unsynchronised (e.g. after sending it raw frames outside the link)."""
        with self._lock:
            self._unsynced.add(node)
