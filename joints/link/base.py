"""The link: the one place for waiting on a bus, the same for every protocol.

Rule: a link owns one transport (through a :class:`Framing`) and one clock, and has two paths.
:meth:`Link.request` sends a frame and waits for the frame that the protocol's :class:`Rule`
accepts as its reply (timeouts, retries of idempotent requests, echo skipping by rule);
:meth:`Link.send` sends frames that get no reply (broadcast, NMT, SYNC, PDOs, MKS group and long
packets). Every other received frame is unsolicited: it goes to the subscribers whose predicate
accepts it or, when nobody subscribed, to a bounded log (:attr:`Link.unsolicited`) and the trace.
Nothing is dropped silently. One lock per bus: two threads never interleave their frames.
"""

from __future__ import annotations

import abc
import functools
import logging
import threading
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from joints.clock import Clock, MonotonicClock
from joints.errors import FrameError, OutcomeUnknown, PeerProtocolError, ReplyTimeout
from joints.link.trace import TraceRecord

log = logging.getLogger("joints.link")

M = TypeVar("M")  #: a decoded message of the protocol
#: frames a link keeps for nobody (no subscriber matched); the oldest go first, and are counted
UNSOLICITED_LOG = 1000


@dataclass(frozen=True, slots=True)
class RetryPolicy:
    timeout: float = 0.1  #: seconds to wait for a complete reply
    retries: int = 2  #: extra attempts for idempotent requests after a timeout, corrupt or wrong reply
    #: after a failed attempt, frames arriving within this many seconds are late replies and are
    #: discarded before anything else is sent (None: the timeout)
    late: float | None = None


_UNKNOWN: dict[type[Exception], type[OutcomeUnknown]] = {ReplyTimeout: OutcomeUnknown}


def outcome_unknown(cause: Exception, message: str) -> OutcomeUnknown:
    """The error for a write with no intact answer: an :class:`~joints.errors.OutcomeUnknown` that is
    also of ``cause``'s type (a corrupt reply stays a :class:`~joints.errors.ChecksumError`, a wrong
    one an :class:`~joints.errors.UnexpectedReply`), so callers catching either see it."""
    kind = type(cause)
    cls = _UNKNOWN.get(kind)
    if cls is None:
        cls = OutcomeUnknown if issubclass(kind, OutcomeUnknown) else type(
            f"OutcomeUnknown{kind.__name__}", (OutcomeUnknown, kind), {"__module__": __name__})
        _UNKNOWN[kind] = cls
    error = cls(message)
    for name, value in vars(cause).items():  # the cause's fields (a frame error's bytes ...)
        setattr(error, name, value)
    return error


class Framing(abc.ABC, Generic[M]):
    """How messages cross one transport: frames out, decoded messages (or framing errors) in."""

    transport: Any  #: the transport underneath (closed by the rig)

    @abc.abstractmethod
    def write(self, message: Any, frame: Any) -> None:
        """Send ``frame`` (the encoded ``message``)."""

    @abc.abstractmethod
    def receive(self, deadline: float, *, settle: bool = True) -> M | FrameError | None:
        """The next complete message, or a framing error, arriving by ``deadline`` (clock time).

        ``None``: nothing complete by then. With ``settle`` the line counts as silent once the
        time is up, so a frame that stopped half-way becomes a :class:`FrameError`; without it a
        partial frame stays buffered (it may still be arriving).
        """

    def discard(self) -> None:
        """Drop a partial frame at the head of the input (before a new request)."""

    def close(self) -> None:
        self.transport.close()

    @property
    def name(self) -> str:
        return str(getattr(self.transport, "name", type(self.transport).__name__))


class Rule(abc.ABC, Generic[M]):
    """What one protocol says about requests and replies (Modbus RTU, MKS native, CAN ...)."""

    protocol: str = ""

    @abc.abstractmethod
    def encode(self, message: Any) -> Any:
        """The frame for ``message``; raises :class:`~joints.errors.EncodeError` before anything is sent."""

    def check(self, message: Any) -> None:
        """Raise what :meth:`encode` would raise for ``message``, without building the frame (the
        direct path, which carries no bytes)."""
        self.encode(message)

    @abc.abstractmethod
    def expects_reply(self, request: Any) -> bool:
        """Whether ``request`` gets a reply (broadcasts and send-only frames do not)."""

    def is_write(self, request: Any) -> bool:
        """Whether ``request`` changes the drive (a timed-out write has an unknown outcome)."""
        return False

    @abc.abstractmethod
    def is_reply(self, request: Any, message: M) -> bool:
        """Whether ``message`` answers ``request``.

        True: it is the reply. False: it is not for this request (an unsolicited frame; the link
        keeps waiting). Raises :class:`~joints.errors.DeviceRejected` for a refusal and
        :class:`~joints.errors.UnexpectedReply` for a frame that can only be a wrong answer.
        """

    def before_send(self, framing: Framing[M], request: Any, frame: Any) -> None:
        """Prepare the framing for this request's reply (expected length, adapter echo ...)."""

    def describe(self, message: Any) -> str:
        return repr(message)

    def frame_bytes(self, message: Any) -> bytes:
        """The wire bytes of a received message, for the trace."""
        return b""

    def frame_size(self, message: Any) -> int:
        """Characters ``message``'s frame takes on a byte stream (the direct path is timed as its bytes)."""
        return len(self.frame_bytes(message))

    def frame_id(self, message: Any) -> int | None:
        """The CAN identifier of a message's frame, for the trace (None on byte streams)."""
        return None

    def address(self, message: Any) -> int | None:
        """The node / slave address a message is for or from, for the trace (None: broadcast, none)."""
        return None

    def is_read(self, request: Any) -> bool:
        """Whether ``request`` only reads (changes nothing on the drive): raw-frame tools send it unconfirmed."""
        return False

    def complete(self, data: bytes) -> bytes:
        """A raw host frame typed without its checksum/CRC gets it appended; one ending in a valid one is kept."""
        return data

    def parse_request(self, frame: Any) -> Any:
        """The request in a raw host frame (bytes with their checksum, or a CAN frame), for raw-frame tools.

        Raises :class:`~joints.errors.FrameError` for a frame that is not a request of this protocol.
        """
        raise FrameError(f"{self.protocol or type(self).__name__}: raw frames cannot be parsed")

    def timeout_text(self, request: Any) -> str:
        """What to check when ``request`` got no reply."""
        return "check wiring, address, bit rate and that the device is powered"

    def route_key(self, message: M) -> object:
        """A hashable key of a received message: a subscriber is offered only the messages whose key its ``only``
        lists (:meth:`Link.subscribe`); None: no key (every subscriber is asked)."""
        return None


@dataclass(eq=False)
class Subscription(Generic[M]):
    """Unsolicited frames for which ``predicate`` holds go to ``callback`` (see :meth:`Link.subscribe`)."""

    predicate: Callable[[M], bool]
    callback: Callable[[M], None]
    link: Link[M] | None = None
    #: the route keys (:meth:`Rule.route_key`) of every frame ``predicate`` can accept (None: any frame); a
    #: frame with another key is not offered to it, one whose key the rule cannot tell always is
    only: frozenset[object] | None = None

    def cancel(self) -> None:
        if self.link is not None:
            self.link._subscriptions = [s for s in self.link._subscriptions if s is not self]
            self.link._routes.clear()
            self.link = None


class Link(Generic[M]):
    """Host side of one bus: request/reply by rule, send-only frames, subscriptions."""

    def __init__(
        self,
        framing: Framing[M],
        rule: Rule[M],
        *,
        policy: RetryPolicy | None = None,
        clock: Clock | None = None,
        trace: Callable[[TraceRecord], None] | None = None,
        name: str = "bus",
    ) -> None:
        self.framing = framing
        self.rule = rule
        self.policy = policy or RetryPolicy()
        self.clock: Clock = clock or MonotonicClock()
        self.trace = trace
        self.name = name
        self._lock = threading.RLock()
        self._subscriptions: list[Subscription[M]] = []
        self._routes: dict[object, tuple[Subscription[M], ...]] = {}  #: route key -> the subscribers offered it
        #: unsolicited frames nobody subscribed to (bounded; :attr:`unsolicited_dropped` counts overflow)
        self.unsolicited: deque[tuple[float, M]] = deque(maxlen=UNSOLICITED_LOG)
        self.unsolicited_dropped = 0
        self.transactions = 0  #: frames sent (requests and send-only)
        self.retries_used = 0
        self.callback_errors = 0
        self.late_discarded = 0  #: frames discarded as late replies after a failed attempt
        #: requests go to an in-process peer as objects (no frame is built unless traced)
        self._direct: DirectFraming[M] | None = framing if isinstance(framing, DirectFraming) else None
        if self._direct is not None:
            self._direct.size = rule.frame_size  # timed as the byte path's frames

    @property
    def transport(self) -> Any:
        return self.framing.transport

    # -- the two paths ----------------------------------------------------------------------
    def request(self, request: Any, *, idempotent: bool = False) -> M | None:
        """Send ``request`` and return its reply (None if the protocol gives it none).

        Only ``idempotent`` requests are sent again after a timeout, a corrupt reply or a reply
        that does not answer them, so a lost reply to a command can never execute it twice.
        After each failed attempt the link waits out late replies (:attr:`RetryPolicy.late`)
        and discards them, so a late reply never answers a later request. A write with no intact
        answer - none came, or it came corrupt, or something else came - raises
        :class:`~joints.errors.OutcomeUnknown` (see :func:`outcome_unknown`): the drive may have
        executed it. A refusal (:class:`~joints.errors.DeviceRejected`) is an answer.
        """
        if self._direct is not None and self.trace is None:  # no bytes to carry or to trace: checks only
            self.rule.check(request)  # raises EncodeError before anything is sent
            frame = None
        else:
            frame = self.rule.encode(request)  # raises EncodeError before anything is sent
        with self._lock:
            return self._attempts(request, frame, idempotent)

    def _attempts(self, request: Any, frame: Any, idempotent: bool, failed: Exception | None = None) -> M | None:
        """The attempts of :meth:`request` (with the bus lock held), and its error when all fail; ``failed``:
        the first attempt was made elsewhere (:class:`~joints.link.lane.LinkLane`) and failed so."""
        attempts = 1 + (self.policy.retries if idempotent else 0)
        last: Exception | None = failed
        for attempt in range(0 if failed is None else 1, attempts):
            if attempt:
                self.retries_used += 1
            try:
                return self._once(request, frame)
            except (ReplyTimeout, PeerProtocolError) as exc:
                last = exc
                self._discard_late()
        assert last is not None
        tried = f" (after {attempts} attempts)" if attempts > 1 else ""
        if self.rule.is_write(request):  # no intact answer: the drive may have executed it
            raise outcome_unknown(last, f"{last}{tried}; the write's outcome is unknown: the drive may have "
                                        "executed it - read back what matters before sending it again") from last
        if tried and isinstance(last, ReplyTimeout):
            raise ReplyTimeout(f"{last}{tried}") from last
        raise last

    def send(self, message: Any) -> None:
        """Send a frame that gets no reply (nothing is waited for)."""
        frame = self.rule.encode(message)
        with self._lock:
            self._drain()
            self.transactions += 1
            if self.trace is not None:
                self._record("tx", self._bytes(frame), self.rule.describe(message), self._ident(frame),
                             self.rule.address(message))
            self.framing.write(message, frame)

    # -- unsolicited frames -----------------------------------------------------------------
    def subscribe(self, predicate: Callable[[M], bool], callback: Callable[[M], None], *,
                  only: Iterable[object] | None = None) -> Subscription[M]:
        """Deliver every unsolicited frame for which ``predicate`` holds to ``callback``.

        Callbacks run in the thread that reads the bus (during a request, :meth:`poll` or
        :meth:`wait_for`); an exception in one is logged and counted, never raised into the bus.
        ``only``: the route keys (:meth:`Rule.route_key`) of every frame ``predicate`` can accept, so a
        frame of another key is not offered to it (the subscribers of a key are listed once, not scanned
        per frame); None: every frame.
        """
        sub = Subscription(predicate, callback, self, None if only is None else frozenset(only))
        with self._lock:
            self._subscriptions.append(sub)
            self._routes.clear()
        return sub

    def poll(self, timeout: float = 0.0) -> int:
        """Read what arrives within ``timeout`` s and deliver it; returns the number of frames."""
        with self._lock:
            deadline = self.clock.now() + max(timeout, 0.0)
            n = 0
            while True:
                got = self.framing.receive(deadline, settle=timeout > 0)
                if got is None:
                    return n
                n += 1
                self._unsolicited(got)

    def wait_for(self, predicate: Callable[[M], bool], timeout: float) -> M:
        """Wait for an unsolicited frame for which ``predicate`` holds (others are delivered as usual)."""
        with self._lock:
            deadline = self.clock.now() + timeout
            while True:
                got = self.framing.receive(deadline)
                if got is None:
                    raise ReplyTimeout(f"{self.name}: the awaited frame did not arrive within {timeout:g} s")
                if not isinstance(got, FrameError) and predicate(got):
                    self._trace_rx(got, "")
                    return got
                self._unsolicited(got)

    def close(self) -> None:
        self.framing.close()

    # -- internals --------------------------------------------------------------------------
    def _once(self, request: Any, frame: Any) -> M | None:
        rule, framing = self.rule, self.framing
        direct = self._direct if self.trace is None else None
        if direct is None or direct.pending():
            self._drain()
        self.transactions += 1
        if self.trace is not None:
            if frame is None:  # tracing started after the request was checked
                frame = rule.encode(request)
            self._record("tx", self._bytes(frame), rule.describe(request), self._ident(frame),
                         rule.address(request))
        rule.before_send(framing, request, frame)
        timeout = self.policy.timeout
        deadline = self.clock.now() + timeout  # from the request's start, on either path
        if direct is not None:  # the reply comes back as an object: a matching one needs no more waiting
            expects = rule.expects_reply(request)
            reply = direct.exchange(request, expects)
            if (reply is not None and not isinstance(reply, FrameError) and expects
                    and rule.is_reply(request, reply)):
                return reply
            direct.put(reply)  # what the byte path would receive next
        else:
            framing.write(request, frame)
        if not rule.expects_reply(request):
            return None
        return self._await_reply(request, deadline)

    def _await_reply(self, request: Any, deadline: float) -> M:
        """The rest of an attempt once its request is out: the frames up to ``deadline`` until the reply
        (others are unsolicited; a garbled one is kept as the error if no reply comes)."""
        rule, framing = self.rule, self.framing
        error: FrameError | None = None
        while True:
            got = framing.receive(deadline)
            if got is None:
                break
            if isinstance(got, FrameError):
                self._record("rx", got.data, f"error: {got}")
                error = error or got
                continue
            if rule.is_reply(request, got):
                if self.trace is not None:
                    self._trace_rx(got, "")
                return got
            self._unsolicited(got)
        if error is not None:
            raise error
        raise ReplyTimeout(
            f"{self.name}: no reply to {rule.describe(request)} within {self.policy.timeout * 1000:.0f} ms on "
            f"{framing.name}; {rule.timeout_text(request)}"
        )

    def _discard_late(self) -> None:
        """After a failed attempt: frames arriving within the late window are discarded (traced)."""
        late = self.policy.timeout if self.policy.late is None else self.policy.late
        framing = self.framing
        deadline = self.clock.now() + late
        while True:
            got = framing.receive(deadline, settle=False)
            if got is None:
                break
            if isinstance(got, FrameError):
                self._record("rx", got.data, f"late, discarded: error: {got}")
            elif self.trace is not None:
                self._trace_rx(got, "late, discarded")
            self.late_discarded += 1
        framing.discard()

    def _drain(self) -> None:
        """Deliver complete frames that arrived before a request; drop a partial one."""
        framing = self.framing
        while True:
            got = framing.receive(self.clock.now(), settle=False)
            if got is None:
                break
            self._unsolicited(got)
        framing.discard()

    def _unsolicited(self, got: M | FrameError) -> None:
        if isinstance(got, FrameError):
            self._record("rx", got.data, f"error: {got}")
            return
        claimed = False
        key = self.rule.route_key(got)
        if key is None:
            subs = tuple(self._subscriptions)
        else:
            found = self._routes.get(key)
            if found is None:
                found = self._routes[key] = tuple(s for s in self._subscriptions if s.only is None or key in s.only)
            subs = found
        for sub in subs:
            try:
                if sub.predicate(got):
                    claimed = True
                    sub.callback(got)
            except Exception:
                self.callback_errors += 1
                log.exception("%s: subscriber failed on %s", self.name, self.rule.describe(got))
        if self.trace is not None:
            self._trace_rx(got, "unsolicited" if claimed else "unsolicited, unclaimed")
        if not claimed:
            if len(self.unsolicited) == self.unsolicited.maxlen:
                self.unsolicited_dropped += 1
            self.unsolicited.append((self.clock.now(), got))

    def _trace_rx(self, msg: M, note: str) -> None:
        if self.trace is not None:
            rule = self.rule
            text = rule.describe(msg)
            self._record("rx", rule.frame_bytes(msg), f"{note}: {text}" if note else text, rule.frame_id(msg),
                         rule.address(msg))

    @staticmethod
    def _bytes(frame: Any) -> bytes:
        if isinstance(frame, (bytes, bytearray)):
            return bytes(frame)
        data = getattr(frame, "data", b"")
        return bytes(data)

    @staticmethod
    def _ident(frame: Any) -> int | None:
        ident = getattr(frame, "arbitration_id", None)
        return ident if isinstance(ident, int) else None

    def _record(self, direction: str, data: bytes, meaning: str, ident: int | None = None,
                node: int | None = None) -> None:
        if self.trace is not None:
            try:
                self.trace(TraceRecord(self.clock.now(), direction, self.name, data, meaning, ident, node))
            except Exception:  # noqa: BLE001, S110 - tracing must not break the bus
                pass


class StreamFraming(Framing[M]):
    """Messages over a byte stream (serial port, pseudo-terminal, in-process loopback) via a sans-I/O codec."""

    def __init__(self, transport: Any, codec: Any, clock: Clock) -> None:
        self.transport = transport
        self.codec = codec
        self.clock = clock

    def write(self, message: Any, frame: Any) -> None:
        self.transport.write(frame)

    def receive(self, deadline: float, *, settle: bool = True) -> M | FrameError | None:
        codec = self.codec
        settled = False
        while True:
            try:
                msg = codec.next_message()
            except FrameError as exc:
                return exc
            if msg is not None:
                return msg  # type: ignore[no-any-return]
            if settled:
                return None
            chunk = self.transport.read(max(deadline - self.clock.now(), 0.0))
            if chunk:
                codec.feed(chunk)
                continue
            if not settle:
                return None
            codec.flush()  # silence until the deadline: a partial frame will not complete
            settled = True

    def discard(self) -> None:
        self.codec.clear()


class DirectFraming(Framing[M]):
    """The sim's direct path: request objects go to an in-process peer, replies come back as objects.

    Rule: identical results to the byte path (the link still encodes every request, so an
    illegal one raises the same error before anything happens), with no bytes on the way. Each
    reply passes ``as_received(request, reply)``, the protocol codec's account of what the host
    receives when the peer sends it: it raises the device encoder's error for a reply the byte
    path could not send and returns the host decoder's :class:`~joints.errors.FrameError` for one
    it would refuse, so the direct path refuses what the byte path refuses.
    Over a timed line (the sim's :class:`~joints.transports.serial_sim.TimedSerialLine`: it has
    ``transact``) each message takes the simulated time its frame would (:meth:`Rule.frame_size`
    characters, the drive's turnaround, the adapter's latency); over an untimed transport, none.
    """

    def __init__(self, peer: Any, transport: Any, as_received: Callable[[Any, M], M | FrameError | None]) -> None:
        self.peer = peer
        self.transport = transport
        self.as_received = as_received
        self._queue: deque[M | FrameError] = deque()
        self.exchanges = 0  #: requests answered on the fast path (:meth:`exchange`: no frame built)
        #: characters a message's frame takes (the link sets it to its rule's :meth:`Rule.frame_size`)
        self.size: Callable[[Any], int] = lambda message: 0
        self._line: Any = transport if callable(getattr(transport, "transact", None)) else None
        turnaround = getattr(peer, "message_turnaround", None)
        self._turnaround: Callable[[Any], float | None] = turnaround if callable(turnaround) else (lambda m: None)

    def write(self, message: Any, frame: Any) -> None:
        self.put(self._timed(message, True))

    def exchange(self, message: Any, expects_reply: bool = True) -> M | FrameError | None:
        """The peer's reply to ``message`` as the host receives it (None: silence), not queued; on a timed
        line, once the host would have received it (a message that expects none is sent and not waited for)."""
        self.exchanges += 1
        return self._timed(message, expects_reply)

    def _timed(self, message: Any, expects_reply: bool) -> M | FrameError | None:
        line = self._line
        act = functools.partial(self.peer.exchange, message)
        if line is None:
            return self._received(message, act())
        if expects_reply:  # the frame's time is the sent reply's; what the host makes of it comes after
            return self._received(message, line.transact(self.size(message), act, self.size, self._turnaround(message)))
        line.post(self.size(message), act, self.size, lambda reply: self.put(self._received(message, reply)),
                  self._turnaround(message))
        return None

    def _received(self, message: Any, reply: M | None) -> M | FrameError | None:
        return None if reply is None else self.as_received(message, reply)

    def put(self, reply: M | FrameError | None) -> None:
        """Queue ``reply`` to be received (None: nothing)."""
        if reply is not None:
            self._queue.append(reply)

    def pending(self) -> bool:
        """Replies are waiting to be received."""
        return bool(self._queue)

    def receive(self, deadline: float, *, settle: bool = True) -> M | FrameError | None:
        line = self._line
        if not self._queue and line is not None:  # waiting is letting simulated time pass, as on the wire
            line.wait(deadline - line.clock.now())
        return self._queue.popleft() if self._queue else None


class FrameFraming(Framing[M]):
    """Messages over a frame transport (CAN): one transport frame decodes to one message."""

    def __init__(self, transport: Any, decode: Callable[[Any], M], clock: Clock) -> None:
        self.transport = transport
        self.decode = decode
        self.clock = clock

    def write(self, message: Any, frame: Any) -> None:
        self.transport.send(frame)

    def receive(self, deadline: float, *, settle: bool = True) -> M | FrameError | None:
        frame = self.transport.recv(max(deadline - self.clock.now(), 0.0))
        if frame is None:
            return None
        try:
            return self.decode(frame)
        except FrameError as exc:
            return exc


def parse_one(codec: Any, frame: Any, what: str) -> Any:
    """The one request ``frame`` holds, decoded by a fresh stream ``codec`` (a whole frame, nothing
    left over); :class:`~joints.errors.FrameError` otherwise. For rules that replay raw frames."""
    data = bytes(frame)
    codec.feed(data)
    codec.flush()
    msg = codec.next_message()
    if msg is None or codec.buffered:
        raise FrameError(f"not one {what} request: {data.hex(' ').upper()}", data=data)
    return msg
