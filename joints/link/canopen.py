"""CANopen (CiA 301) on the link: SDO request/reply, send-only NMT/SYNC/PDOs, node monitoring.

Rule: the codec's state machines do the protocol (:class:`~joints.codecs.canopen.SdoClient` for
expedited and segmented transfers, :class:`~joints.codecs.canopen.GuardingMaster` for node
guarding); this module waits. An SDO frame to node n (0x600+n) is answered by the next SDO frame
of node n (0x580+n); an abort becomes :class:`~joints.errors.DeviceRejected` with the abort code
and its CiA 301 text. NMT, SYNC, RPDOs and guard requests are sent without a reply. Everything a
node sends by itself - TPDOs, EMCY, heartbeats, boot-ups, guarding replies - is unsolicited:
subscribers get it (the link itself watches heartbeats, boot-ups and guarding replies).

Node monitoring (:class:`NodeMonitor`), evaluated on the link's clock whenever the host asks
(:meth:`CanopenLink.lost`), so it is lockstep in sim:

* heartbeat consumer: armed by the node's first heartbeat after :meth:`CanopenLink.consume`;
  a node silent for longer than the consumer time is lost;
* node guarding: :meth:`CanopenLink.guard` sends the remote frame; the node is lost when the
  reply does not come within the guard timeout or its toggle bit does not alternate;
* a boot-up after the node was set up means it reset (power loss, its own reset): counted, the
  driver decides.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import can

from joints.clock import Clock, MonotonicClock
from joints.codecs import canopen as co
from joints.errors import EncodeError, FrameError, OutcomeUnknown, PeerProtocolError, ReplyTimeout, UnexpectedReply
from joints.link.base import FrameFraming, Link, RetryPolicy, Rule
from joints.link.trace import TraceRecord
from joints.transports.can_timing import CycleLoad, canopen_cycle_load

__all__ = ["CanopenLink", "CanopenRule", "NodeMonitor", "decode_host"]


def decode_host(frame: can.Message) -> co.Message:
    """A received frame as a CANopen message (FrameError if malformed for its service)."""
    if frame.is_error_frame or frame.is_extended_id:
        return co.Other(frame.arbitration_id, bytes(frame.data), frame.is_remote_frame)
    return co.decode(frame)


_SERVER = (co.SdoDownloadInitiateResponse, co.SdoDownloadSegmentResponse, co.SdoUploadInitiateResponse,
           co.SdoUploadSegment)


def _describe(message: Any) -> str:
    if isinstance(message, can.Message):
        try:
            message = co.decode(message)
        except FrameError:
            return f"frame 0x{message.arbitration_id:03X} [{bytes(message.data).hex(' ').upper()}]"
    m = message
    if isinstance(m, co.SdoUploadInitiate):
        return f"node {m.node} SDO read 0x{m.index:04X}:{m.subindex:02X}"
    if isinstance(m, co.SdoDownloadInitiate):
        what = m.data.hex(" ").upper() if m.expedited else f"{m.size} bytes, segmented"
        return f"node {m.node} SDO write 0x{m.index:04X}:{m.subindex:02X} = [{what}]"
    if isinstance(m, co.SdoUploadInitiateResponse):
        return f"node {m.node} SDO value 0x{m.index:04X}:{m.subindex:02X} = [{m.data.hex(' ').upper()}]"
    if isinstance(m, co.SdoDownloadInitiateResponse):
        return f"node {m.node} SDO written 0x{m.index:04X}:{m.subindex:02X}"
    if isinstance(m, co.SdoAbort):
        who = "host" if m.from_client else f"node {m.node}"
        return f"{who} SDO abort 0x{m.index:04X}:{m.subindex:02X} 0x{m.code:08X} ({m.text})"
    if isinstance(m, co.Nmt):
        return f"NMT {m.command.name} node {m.node or 'all'}"
    if isinstance(m, co.Sync):
        return "SYNC" if m.counter is None else f"SYNC {m.counter}"
    if isinstance(m, co.Heartbeat):
        return f"node {m.node} heartbeat {m.state.name}" + (" (toggle)" if m.toggle else "")
    if isinstance(m, co.BootUp):
        return f"node {m.node} boot-up"
    if isinstance(m, co.GuardRequest):
        return f"node {m.node} guard request"
    if isinstance(m, co.Emcy):
        return f"node {m.node} EMCY 0x{m.error_code:04X} ({m.text}), register 0x{m.error_register:02X}"
    if isinstance(m, co.Pdo):
        return f"PDO 0x{m.cob_id:03X} [{m.data.hex(' ').upper()}]" + (" RTR" if m.remote else "")
    return repr(m)


class CanopenRule(Rule[Any]):
    """Requests are frames; only SDO requests (0x600+node) get a reply: the node's next SDO frame."""

    protocol = "canopen"

    def encode(self, message: Any) -> can.Message:
        if isinstance(message, can.Message):
            return message
        return co.encode(message)

    def expects_reply(self, request: Any) -> bool:
        return co.classify(self.encode(request)).kind is co.Kind.SDO_RX

    def is_write(self, request: Any) -> bool:
        frame = self.encode(request)
        return co.classify(frame).kind is co.Kind.SDO_RX and bytes(frame.data)[:1] != b"" \
            and frame.data[0] >> 5 in (0, 1)  # download initiate / segment

    def is_reply(self, request: Any, message: Any) -> bool:
        node = co.classify(self.encode(request)).node
        if isinstance(message, _SERVER):
            return message.node == node
        if isinstance(message, (co.SdoAbort, co.SdoUnsupported)):
            return message.node == node and not message.from_client
        return False

    def describe(self, message: Any) -> str:
        return _describe(message)

    def frame_bytes(self, message: Any) -> bytes:
        try:
            return bytes(self.encode(message).data)
        except EncodeError:
            return b""

    def frame_id(self, message: Any) -> int | None:
        try:
            return int(self.encode(message).arbitration_id)
        except EncodeError:
            return None

    def address(self, message: Any) -> int | None:
        try:
            _kind, node = co.classify(self.encode(message))
        except EncodeError:
            return None
        return node or None

    def is_read(self, request: Any) -> bool:
        frame = self.encode(request)
        return (co.classify(frame).kind is co.Kind.SDO_RX and len(frame.data) > 0
                and frame.data[0] >> 5 in (2, 3))  # upload initiate / segment request

    def parse_request(self, frame: Any) -> Any:
        return co.decode(frame)

    def route_key(self, message: Any) -> object:
        """A PDO's COB-ID (its subscribers are the nodes that mapped it), else the message's class."""
        kind = type(message)
        return message.cob_id if kind is co.Pdo else kind

    def timeout_text(self, request: Any) -> str:
        node = co.classify(self.encode(request)).node
        return (f"node {node} did not answer on 0x{co.SDO_TX_BASE + node:03X}: check the node id, the bit rate, "
                "termination (120 ohm at both ends), power, and that the node is not STOPPED (NMT)")


@dataclass
class NodeMonitor:
    """What the host knows of one node's liveness (see the module docstring)."""

    node: int
    consumer_time: float = 0.0  #: s; 0 = heartbeats are not consumed
    armed: bool = False  #: a heartbeat came since :meth:`CanopenLink.consume`
    last_heartbeat: float = -math.inf
    state: co.NmtState | None = None
    boot_ups: int = 0
    last_boot_up: float = -math.inf
    guard_timeout: float = 0.0  #: s a guarding reply may take
    guard_sent: float | None = None  #: when the unanswered guard request went out
    guarding: co.GuardingMaster = field(init=False)
    lost: str | None = None  #: why the node counts as lost (None: alive as far as we know)
    lost_at: float | None = None

    def __post_init__(self) -> None:
        self.guarding = co.GuardingMaster(self.node)

    def mark_lost(self, why: str, t: float) -> None:
        if self.lost is None:
            self.lost, self.lost_at = why, t

    def check(self, now: float) -> str | None:
        """Evaluate the timers at ``now``; the reason the node is lost, or None."""
        if self.lost is None:
            if self.armed and self.consumer_time > 0 and now - self.last_heartbeat > self.consumer_time:
                self.mark_lost(f"no heartbeat for {(now - self.last_heartbeat) * 1e3:.0f} ms (consumer time "
                               f"{self.consumer_time * 1e3:.0f} ms)", self.last_heartbeat + self.consumer_time)
            elif self.guard_sent is not None and self.guard_timeout > 0 and now - self.guard_sent > self.guard_timeout:
                self.mark_lost(f"no node-guarding reply within {self.guard_timeout * 1e3:.0f} ms",
                               self.guard_sent + self.guard_timeout)
        return self.lost

    def reset(self) -> None:
        """Forget a loss (after the node was brought up again)."""
        self.lost = self.lost_at = None
        self.armed = False
        self.guard_sent = None
        self.guarding.reset()


class CanopenLink(Link[Any]):
    """Host side of a CANopen bus (see the module docstring)."""

    def __init__(
        self,
        transport: Any,
        *,
        policy: RetryPolicy | None = None,
        clock: Clock | None = None,
        trace: Callable[[TraceRecord], None] | None = None,
        name: str = "canopen",
        bus_clock: bool = False,
    ) -> None:
        clock = clock or MonotonicClock()
        super().__init__(FrameFraming(transport, self._decode, clock), CanopenRule(), policy=policy, clock=clock,
                         trace=trace, name=name)
        #: frames are stamped on the clock's own time base (the sim's timed bus, exact to the frame
        #: edge while the physics clock moves in whole substeps): bus time is the last frame's stamp
        self.bus_clock = bus_clock
        self._stamp = clock.now()
        #: the clock's restarts (a sim reset: a new ``epoch`` of :class:`joints.clock.ManualClock`) the link has
        #: seen: the bus time starts again at the clock's time (who keeps bus time, e.g. the SYNC cycle, compares)
        self.restarts = 0
        self._epoch = getattr(clock, "epoch", None)
        self.monitors: dict[int, NodeMonitor] = {}
        self._clients: dict[int, co.SdoClient] = {}
        self.sdo_transfers = 0
        #: the bus's SYNC period from its config (s; None: the joints' or the default 1 ms)
        self.sync_period: float | None = None
        #: the bus's SYNC cycle, shared by its drivers (joints.drivers.canopen_sync.SyncCycle.of)
        self.sync_cycle: object | None = None
        #: the bus's bit rate (bit/s; from its config) for bus-load decisions
        self.bitrate = 1_000_000
        self.subscribe(lambda m: isinstance(m, (co.Heartbeat, co.BootUp)), self._error_control,
                       only=(co.Heartbeat, co.BootUp))

    def _decode(self, frame: can.Message) -> co.Message:
        if self.bus_clock:
            if self._epoch is not None and self.clock.epoch != self._epoch:  # type: ignore[attr-defined]
                self._restart()
            if frame.timestamp > self._stamp:
                self._stamp = float(frame.timestamp)
        return decode_host(frame)

    def _restart(self) -> None:
        """The clock restarted (a new epoch): bus time starts again at the clock's time, as at construction
        (the medium dropped what was in flight at the same restart)."""
        self._epoch = self.clock.epoch  # type: ignore[attr-defined]
        self._stamp = self.clock.now()
        self.restarts += 1

    def bus_now(self) -> float:
        """The bus's present time: the clock, or (sim) where the timed bus is (it may lag a coarse clock);
        after a restart of the clock (a new epoch), from the clock's new time on."""
        if self._epoch is not None and self.clock.epoch != self._epoch:  # type: ignore[attr-defined]
            self._restart()
        return max(self._stamp, self.clock.now()) if not self.bus_clock else self._stamp

    def poll(self, timeout: float = 0.0) -> int:
        start = self.bus_now()
        n = super().poll(timeout)
        if self.bus_clock and timeout > 0:  # the timed bus ran the whole timeout
            self._stamp = max(self._stamp, start + timeout)
        return n

    def wait_for(self, predicate: Callable[[Any], bool], timeout: float) -> Any:
        start = self.bus_now()
        try:
            return super().wait_for(predicate, timeout)
        except ReplyTimeout:
            if self.bus_clock:
                self._stamp = max(self._stamp, start + timeout)
            raise

    def deliver_until(self, done: Callable[[], bool], timeout: float) -> bool:
        """Deliver what arrives to the subscribers (unsolicited frames, none taken as a reply) until ``done()``
        holds or ``timeout`` s passed; whether it holds."""
        start = self.bus_now()
        with self._lock:
            deadline = self.clock.now() + timeout
            while not done():
                got = self.framing.receive(deadline)
                if got is None:
                    if self.bus_clock:
                        self._stamp = max(self._stamp, start + timeout)
                    return False
                self._unsolicited(got)
        return True

    def wait_bus(self, until: float) -> None:
        """Let the bus run until ``until`` (bus time), delivering what arrives."""
        left = until - self.bus_now()
        if left > 0:
            self.poll(left)
        if self.bus_clock:
            self._stamp = max(self._stamp, until)

    # -- SDO ------------------------------------------------------------------------------------
    def _client(self, node: int) -> co.SdoClient:
        client = self._clients.get(node)
        if client is None:
            client = self._clients[node] = co.SdoClient(node)
        return client

    def sdo_upload(self, node: int, index: int, subindex: int) -> bytes:
        """Read ``index:subindex`` of ``node`` (expedited or segmented): the object's bytes."""
        client = self._client(node)
        with self._lock:
            return self._transfer(client, client.upload(index, subindex), first_idempotent=True)

    def sdo_download(self, node: int, index: int, subindex: int, data: bytes, *, idempotent: bool = True) -> None:
        """Write ``data`` to ``index:subindex`` of ``node`` (expedited up to 4 bytes, else segmented)."""
        client = self._client(node)
        with self._lock:
            first = client.download(index, subindex, data)
            self._transfer(client, first, first_idempotent=idempotent and len(data) <= 4)

    def _transfer(self, client: co.SdoClient, frame: can.Message, *, first_idempotent: bool) -> bytes:
        self.sdo_transfers += 1
        idempotent = first_idempotent
        while True:
            try:
                reply: Any = self.request(frame, idempotent=idempotent)
            except (ReplyTimeout, OutcomeUnknown, PeerProtocolError):
                abort = client.abort(co.SdoAbortCode.TIMEOUT)
                if abort is not None:
                    self.send(abort)
                raise
            idempotent = False  # a segment is never sent twice (its toggle bit)
            step = client.feed(co.encode(reply))
            if isinstance(step, co.SdoSend):
                frame = step.frame
                continue
            if isinstance(step, co.SdoDone):
                return step.data
            if step.frame is not None:
                self.send(step.frame)
            raise step.error

    # -- send-only services ---------------------------------------------------------------------
    def nmt(self, command: co.NmtCommand, node: int = 0) -> None:
        """An NMT command to ``node`` (0 = every node)."""
        self.send(co.Nmt(command, node))
        if command in (co.NmtCommand.RESET_NODE, co.NmtCommand.RESET_COMMUNICATION):
            for m in self.monitors.values():
                if node in (0, m.node):
                    m.guarding.reset()

    def cycle_load(self, nodes: Sequence[int], *, rpdo_bytes: Sequence[int], tpdo_bytes: Sequence[int],
                   period: float) -> CycleLoad:
        """The load of a SYNC cycle of ``nodes`` on this bus (its bit rate; worst-case stuffing bounds ``fits``)."""
        return canopen_cycle_load(list(nodes), rpdo_bytes=rpdo_bytes, tpdo_bytes=tpdo_bytes, sync_period=period,
                                  bitrate=self.bitrate)

    def sync(self, counter: int | None = None) -> None:
        self.send(co.Sync(counter))

    def send_pdo(self, cob_id: int, data: bytes) -> None:
        self.send(co.Pdo(cob_id, data))

    # -- node monitoring ------------------------------------------------------------------------
    def monitor(self, node: int) -> NodeMonitor:
        m = self.monitors.get(node)
        if m is None:
            m = self.monitors[node] = NodeMonitor(node)
        return m

    def consume(self, node: int, consumer_time: float) -> None:
        """Consume ``node``'s heartbeat: lost when silent longer than ``consumer_time`` s (0 = stop consuming).

        Armed only by the node's next heartbeat."""
        m = self.monitor(node)
        m.consumer_time = consumer_time
        m.armed = False

    def guard(self, node: int, timeout: float) -> None:
        """Send a node-guarding request; the reply must come within ``timeout`` s (checked by :meth:`lost`)."""
        m = self.monitor(node)
        self.poll(0.0)
        if m.guard_sent is not None:  # the last request is still unanswered: its timeout decides
            m.check(self.clock.now())
            return
        m.guard_timeout = timeout
        m.guard_sent = self.clock.now()
        self.send(co.GuardRequest(node))

    def stop_guarding(self, node: int) -> None:
        m = self.monitor(node)
        m.guard_sent = None
        m.guard_timeout = 0.0

    def lost(self, node: int) -> str | None:
        """Why ``node`` counts as lost at the clock's present time (None: alive); reads what arrived first."""
        self.poll(0.0)
        m = self.monitors.get(node)
        return None if m is None else m.check(self.clock.now())

    def _error_control(self, msg: co.Heartbeat | co.BootUp) -> None:
        m = self.monitor(msg.node)
        now = self.clock.now()
        if isinstance(msg, co.BootUp):
            m.boot_ups += 1
            m.last_boot_up = now
            m.state = co.AFTER_BOOT_UP
            m.guarding.reset()
            return
        m.state = msg.state
        if m.guard_sent is not None:
            # a guarding reply (heartbeats are off while guarding: CiA 301); a heartbeat's toggle is 0
            try:
                m.guarding.check(msg)
            except UnexpectedReply as exc:
                m.mark_lost(str(exc), now)
            m.guard_sent = None
            return
        m.last_heartbeat = now
        if m.consumer_time > 0:
            m.armed = True
