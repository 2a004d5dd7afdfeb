"""CAN in process: a timed, lockstep bus medium on the simulated clock, and python-can's ``BusABC`` over it.

Rule: no threads, no wall clock. Time moves only by the clock the medium is bound to (the
simulated world's clock) or, for a medium of its own, by the waits of its nodes. Every frame
occupies the bus for its wire time at the medium's bit rate (:mod:`joints.transports.can_timing`;
worst-case bit stuffing by default), frames waiting for the bus are arbitrated by identifier
(the lowest wins, as the dominant bits do on a real bus; the frames of one python-can node keep
their order, as its controller's transmit queue does),
and the medium counts frames, bits and busy time so the bus load can be measured.

Nodes:

* :class:`LockstepCanBus` - a python-can bus (interface ``joints-sim``, registered through the
  ``can.interface`` entry point): ``can.Bus(interface="joints-sim", channel=...)`` joins the
  medium of that channel (a medium of its own is made for an unknown channel). ``recv`` counts
  its timeout on the simulated clock - waiting IS letting simulated time pass - and returns as
  soon as a frame is delivered; ``recv(None)`` returns None at once when nothing can arrive any
  more (in lockstep nobody else could send).
* peers (:meth:`CanMedium.attach_peer`): in-process devices (the sim's twins) that get every
  delivered frame and answer with frames sent ``latency`` seconds after the frame that caused
  them - or the peer's own ``turnaround(frame)`` where it gives one (the drive's, from its profile).
* a python-can node's ``adapter_latency`` (:meth:`CanMedium.attach`): it sees every frame that
  long after the frame left the wire (the host adapter's receive path; docs/timing.md).
* ``ideal`` media take no time: frames arrive the moment they are sent (``timing = "ideal"``).

Time model. The medium keeps its own time (``now``), exact to the frame edge. Waiting until a
time the clock has not reached yet sleeps the clock (the world steps its physics up to or past
it); frames delivered meanwhile are processed in time order. When the clock moves for another
reason (the host sleeps, :meth:`CanMedium.tick` from the world), the
medium processes its frames up to the clock's time, so a frame in flight reaches its peers at
its own time even while nobody waits on the bus. The world ticks the medium at the end of the substep
that reaches :meth:`CanMedium.next_event` (and after every stretch it runs), not every substep: a bus with
nothing queued costs nothing per substep. A clock that restarts (world reset) drops the
frames in flight and restarts the medium there.
"""

from __future__ import annotations

import itertools
import math
import weakref
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import can

from joints.errors import TransportError
from joints.transports.can_timing import STUFFING, frame_bits
from joints.transports.simclock import ClockDriven, ClockLike

__all__ = ["INTERFACE", "BusLoad", "CanMedium", "ClockLike", "FramePeer", "LockstepCanBus"]

#: the python-can interface name of :class:`LockstepCanBus` (pyproject: ``[project.entry-points."can.interface"]``)
INTERFACE = "joints-sim"


class _OwnClock:
    """A clock that only the medium's waits move (a medium nobody bound to a simulated world)."""

    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self.t += seconds


class FramePeer(Protocol):
    """An in-process device on a medium: every delivered frame in, its answers out."""

    def on_frame(self, frame: can.Message) -> Sequence[can.Message]: ...


# A peer may also have ``fresh_answers = True``: every frame it answers with (or sends by ``send_at``) is a new
# object it never touches again, so the medium may hand it to the one python-can node that receives it (its
# received copy's timestamp, channel and ``is_rx`` set on it) instead of building a copy.


@dataclass(frozen=True, slots=True)
class BusLoad:
    """Traffic on a medium over a time window."""

    frames: int
    bits: int
    busy: float  #: s the bus carried frames
    elapsed: float  #: s of the window
    bitrate: int

    @property
    def load(self) -> float:
        """Busy time / elapsed time (1.0 = saturated)."""
        return self.busy / self.elapsed if self.elapsed > 0 else 0.0

    @property
    def frames_per_second(self) -> float:
        return self.frames / self.elapsed if self.elapsed > 0 else 0.0


@dataclass(eq=False)
class _Node:
    """One attachment to the medium: a python-can bus (rx queue) or a peer (answers frames)."""

    name: str
    peer: FramePeer | None = None
    latency: float = 0.0  #: a peer's answer delay; a python-can node's adapter latency (frames held that long)
    receive_own: bool = False
    rx: deque[can.Message] = field(default_factory=deque)
    held: deque[tuple[float, can.Message]] = field(default_factory=deque)  #: delivered, not yet seen by the host
    turnaround: Callable[[can.Message], float | None] | None = None  #: a peer's own answer delay per frame
    rx_dropped: int = 0
    rx_limit: int = 100_000
    #: a peer's answers are new frames it never touches again (:attr:`FramePeer.fresh_answers`): one that only
    #: one python-can node receives is handed to it as its received frame, not copied
    fresh: bool = False


@dataclass(eq=False, slots=True)
class _Pending:
    ready: float
    seq: int
    frame: can.Message
    sender: _Node
    key: int = 0  #: :func:`_priority`
    host: bool = False  #: sent by a python-can node (its controller sends its frames in order)


def _priority(frame: can.Message) -> int:
    """Arbitration order as one integer (the lower wins): base identifier, then standard before extended,
    then the extension - ``(base << 19) | (extended << 18) | extension``."""
    ident = frame.arbitration_id
    if frame.is_extended_id:
        return ((ident >> 18) << 19) | (1 << 18) | (ident & 0x3FFFF)
    return ident << 19


_MEDIA: weakref.WeakValueDictionary[str, CanMedium] = weakref.WeakValueDictionary()


class CanMedium(ClockDriven):
    """The wire of one in-process CAN bus (see the module docstring)."""

    def __init__(self, channel: str | None = None, *, bitrate: int = 1_000_000, stuffing: str = "worst",
                 clock: ClockLike | None = None, register: bool = True, ideal: bool = False) -> None:
        if stuffing not in STUFFING:
            raise ValueError(f"stuffing must be one of {STUFFING}, got {stuffing!r}")
        if not (isinstance(bitrate, int) and bitrate > 0):
            raise ValueError(f"bitrate must be a positive integer (bit/s), got {bitrate!r}")
        self.bitrate = bitrate
        self.stuffing = stuffing
        self.ideal = ideal  #: frames take no time (``timing = "ideal"``)
        self.clock: ClockLike = clock or _OwnClock()
        self.now = self.clock.now()
        self._clock_seen = self.now
        self._see_epoch()
        self._cap: float | None = None  # while we sleep the clock ourselves: process no further than this
        #: the peers send only in answer to the frames they receive, never by themselves at a tick (the eRob
        #: CAN custom protocol's twins): :meth:`receive` may then process frame edges without waiting for them
        self.answers_only = False
        self._ticked = self.now  #: the time of the last tick: where the world's physics stands (lockstep)
        self._delivering: float | None = None  # the time of the frame being delivered (peers answer then)
        self._nodes: list[_Node] = []
        self._delivery_order: tuple[_Node, ...] = ()
        self._peers: tuple[_Node, ...] = ()
        self._handoff = False
        self._pending: list[_Pending] = []
        self._wire: tuple[float, float, _Pending] | None = None  # (start, end, frame) on the bus
        self._free = self.now  # when the bus is idle again
        self._seq = itertools.count()
        self._bits_cache: dict[tuple[Any, ...], int] = {}
        # statistics
        self.frames = 0
        self.bits = 0
        self.handed_over = 0  #: deliveries that handed a peer's fresh answer over instead of a copy
        self.busy = 0.0
        self._mark = (self.now, 0, 0, 0.0)
        self.channel = self._register(channel) if register else (channel or "joints-sim")

    # -- naming ---------------------------------------------------------------------------
    def _register(self, channel: str | None) -> str:
        base = channel or "joints-sim"
        name = base
        for n in itertools.count(2):
            if name not in _MEDIA:
                break
            name = f"{base}#{n}"
        _MEDIA[name] = self
        return name

    @staticmethod
    def named(channel: str | None, **kwargs: Any) -> CanMedium:
        """The medium registered as ``channel`` in this process (a new one if there is none)."""
        if channel is not None:
            medium = _MEDIA.get(str(channel))
            if medium is not None:
                return medium
        return CanMedium(None if channel is None else str(channel), **kwargs)

    # -- attachment -----------------------------------------------------------------------
    def attach(self, name: str, *, receive_own: bool = False, adapter_latency: float = 0.0) -> _Node:
        """Attach a python-can node; it sees each frame ``adapter_latency`` s after the frame ended."""
        if adapter_latency < 0 or not math.isfinite(adapter_latency):
            raise ValueError(f"adapter_latency must be a finite number >= 0, got {adapter_latency!r}")
        node = _Node(name, receive_own=receive_own, latency=adapter_latency)
        self._nodes.append(node)
        self._attached()
        return node

    def attach_peer(self, peer: FramePeer, *, latency: float = 0.0, name: str = "peer") -> _Node:
        """Attach an in-process device: it gets every frame others send and answers after ``latency`` s."""
        if latency < 0 or not math.isfinite(latency):
            raise ValueError(f"latency must be a finite number >= 0, got {latency!r}")
        turnaround = getattr(peer, "turnaround", None)
        node = _Node(name, peer=peer, latency=latency, turnaround=turnaround if callable(turnaround) else None,
                     fresh=getattr(peer, "fresh_answers", False) is True)
        self._nodes.append(node)
        self._attached()
        return node

    def detach(self, node: _Node) -> None:
        self._nodes = [n for n in self._nodes if n is not node]
        self._pending = [p for p in self._pending if p.sender is not node]
        self._attached()

    def _attached(self) -> None:
        """The nodes changed: the snapshot a delivery walks, and the peers among them."""
        self._delivery_order = tuple(self._nodes)
        self._peers = tuple(n for n in self._nodes if n.peer is not None)
        #: a fresh answer of the only peer reaches one python-can node only: it may be handed over as it is
        self._handoff = len(self._peers) == 1 and len(self._nodes) == 2

    # -- time -----------------------------------------------------------------------------
    def bind_clock(self, clock: ClockLike) -> None:
        """Run on ``clock`` from now on (the simulated world's clock); the medium restarts at its time."""
        self.clock = clock
        self._see_epoch()
        self._restart(clock.now())

    def _restart(self, t: float) -> None:
        self._pending.clear()
        self._wire = None
        for n in self._nodes:
            n.rx.clear()
            n.held.clear()
        self.now = self._free = self._clock_seen = self._ticked = t
        self._mark = (t, self.frames, self.bits, self.busy)

    def _sync(self) -> None:
        """Catch up with a clock that moved without us (the host slept) or restarted (reset)."""
        clock = self.clock
        c = clock.now()
        seen = self._epoch_seen
        if (seen is None or getattr(clock, "epoch", None) != seen) and self._restarted(c):
            self._restart(c)
        elif c > self._clock_seen:
            settle = getattr(clock, "settle", None)
            if settle is not None:  # a sleep the world held (``World.hold``): its physics and ticks run first
                settle()
                c = clock.now()
            if c > self._clock_seen:
                self._clock_seen = c
                if c > self.now:
                    self._run(c)
                    self.now = c

    def tick(self, t: float) -> None:
        """The clock reached ``t`` (the world calls this at substep ends, at least at each :meth:`next_event`):
        deliver what is due."""
        if self._epoch_seen is not None and self._restarted(self.clock.now()):
            self._restart(self.clock.now())
        self._ticked = t
        if self._cap is not None:
            t = min(t, self._cap)
        if t > self.now and (self._pending or self._wire is not None):
            self._run(t)
        if self._cap is None and t > self.now:
            self.now = t
            self._clock_seen = max(self._clock_seen, t)

    def _next_event(self) -> float:
        wire = self._wire
        if wire is not None:
            return wire[1]
        pending = self._pending
        if not pending:
            return math.inf
        ready = pending[0].ready if len(pending) == 1 else min([p.ready for p in pending])
        free = self._free
        return max(free, ready)

    def next_event(self) -> float:
        """The earliest ``t`` at which :meth:`tick` has work: a frame starts or ends (``math.inf``: nothing is
        queued or on the wire, or - while the medium sleeps the clock itself - nothing before the instant it
        waits for). Ticks before it only move ``now``, so the world may run the substeps up to it in one
        call and tick once."""
        e = self._next_event()
        cap = self._cap
        return math.inf if cap is not None and e > cap else e

    # -- the wire -------------------------------------------------------------------------
    def _bits(self, frame: can.Message) -> int:
        if self.stuffing == "exact":  # the frame's own bits decide (a remote frame's DLC among them)
            key: tuple[Any, ...] = (frame.arbitration_id, frame.is_extended_id, frame.is_remote_frame, frame.dlc,
                                    bytes(frame.data))
        else:  # the worst-case bound and no stuffing depend on the format and the data length only
            key = (frame.is_extended_id, frame.is_remote_frame, len(frame.data))
        bits = self._bits_cache.get(key)
        if bits is None:
            if len(self._bits_cache) > 4096:
                self._bits_cache.clear()
            bits = self._bits_cache[key] = frame_bits(frame, self.stuffing)
        return bits

    def _run(self, until: float) -> None:
        """Process every bus event up to ``until``: starts (arbitration) and ends (delivery)."""
        pending = self._pending
        while True:
            wire = self._wire
            if wire is None:
                if not pending:
                    return
                free = self._free
                if len(pending) == 1:
                    winner = pending[0]
                    start = max(free, winner.ready)
                    if start > until:
                        return
                    pending.clear()
                else:
                    ready = min([p.ready for p in pending])
                    start = max(free, ready)
                    if start > until:
                        return
                    winner = self._winner(start)
                    pending.remove(winner)
                frame = winner.frame
                bits = self._bits(frame)
                took = 0.0 if self.ideal else bits / self.bitrate
                wire = self._wire = (start, start + took, winner)
                self.frames += 1
                self.bits += bits
                self.busy += took
            end = wire[1]
            if end > until:
                return
            self._wire = None
            self._free = end
            self._deliver(wire[2], end)

    def _winner(self, start: float) -> _Pending:
        """Of the frames that compete for the bus at ``start``, the one that wins arbitration (the lowest
        :func:`_priority`, then the oldest). Competing: a python-can node's oldest ready frame (its
        controller sends in order, so a SYNC queued after RPDOs goes after them), every ready frame of a
        peer (in-process devices, each with its own controller). ``_pending`` is in sending order."""
        best: _Pending | None = None
        hosts: list[_Node] = []
        for p in self._pending:
            if p.ready > start:
                continue
            if p.host:
                if p.sender in hosts:
                    continue  # not its controller's oldest ready frame
                hosts.append(p.sender)
            if best is None or p.key < best.key:  # equal keys: the older (earlier in the list) wins
                best = p
        assert best is not None
        return best

    def _deliver(self, pend: _Pending, t: float) -> None:
        self._delivering = t
        try:
            self._deliver_to_all(pend, t)
        finally:
            self._delivering = None

    def _deliver_to_all(self, pend: _Pending, t: float) -> None:
        frame = pend.frame
        sender = pend.sender
        ideal = self.ideal
        handoff = sender.fresh and self._handoff  # the sender is the only peer, the other node a python-can one
        for node in self._delivery_order:  # the nodes as they are now (a peer may attach or detach meanwhile)
            own = node is sender
            if own and not node.receive_own:
                continue
            peer = node.peer
            if peer is not None:
                if own:
                    continue
                answers = peer.on_frame(frame)
                if answers:
                    turn = node.turnaround(frame) if node.turnaround is not None else None
                    delay = 0.0 if ideal else node.latency if turn is None else turn
                    for answer in answers:
                        self._enqueue(answer, node, t + delay)
                continue
            rx, held = node.rx, node.held
            if len(rx) + len(held) >= node.rx_limit:
                (held if not rx else rx).popleft()
                node.rx_dropped += 1
            if handoff:  # the copy's fields, set on the frame nobody else holds
                msg = frame
                msg.timestamp, msg.channel, msg.is_rx = t, self.channel, True
                self.handed_over += 1
            else:
                msg = can.Message(
                    timestamp=t, arbitration_id=frame.arbitration_id, is_extended_id=frame.is_extended_id,
                    is_remote_frame=frame.is_remote_frame, is_error_frame=frame.is_error_frame, dlc=frame.dlc,
                    data=frame.data, channel=self.channel, is_rx=not own, check=False,
                )
            if node.latency > 0 and not ideal:
                held.append((t + node.latency, msg))  # the host adapter passes it on later
            else:
                rx.append(msg)

    def _enqueue(self, frame: can.Message, sender: _Node, ready: float) -> None:
        if frame.is_fd:
            raise TransportError(f"{self.channel}: CAN FD frames are not supported by the sim's classic CAN bus")
        self._pending.append(_Pending(ready, next(self._seq), frame, sender, _priority(frame), sender.peer is None))

    # -- what nodes do --------------------------------------------------------------------
    def submit(self, node: _Node, frame: can.Message) -> None:
        """``node`` sends ``frame`` now (it goes on the wire when it wins the bus)."""
        self._sync()
        self._enqueue(frame, node, self.now)
        self._run(self.now)

    def send_at(self, node: _Node, frame: can.Message, at: float) -> None:
        """``node`` sends ``frame`` at simulated time ``at`` (not before now): a delayed answer of a peer.

        A peer may call this from :meth:`FramePeer.on_frame` (``at`` then counts from the frame's end).
        """
        if self._delivering is not None:
            self._enqueue(frame, node, max(at, self._delivering))
            return
        self._sync()
        self._enqueue(frame, node, max(at, self.now))
        self._run(self.now)

    def time(self) -> float:
        """The medium's present time: the end of the frame being delivered (a peer answering it), else now."""
        if self._delivering is not None:
            return self._delivering
        self._sync()
        return self.now

    def receive(self, node: _Node, timeout: float | None) -> can.Message | None:
        """The next frame delivered to ``node`` within ``timeout`` s of simulated time (None: none came).

        It waits for each frame edge in turn (the clock sleeps to it: the world steps its physics up to it)
        until a frame reaches the node; an edge where the wait would change nothing but the clock (the
        physics stands there already, or - the peers only answering - it touches no peer) is processed
        without it (:meth:`_skippable`); the waits that remain show the clock the same instants.
        """
        self._sync()
        held, rx = node.held, node.rx
        if timeout is not None and timeout <= 0 and not rx and not (held and held[0][0] <= self.now + 1e-12) \
                and self._next_event() > self.now and self.clock.now() >= self.now:
            return None  # a poll with nothing due: waiting until now would neither sleep nor deliver anything
        deadline = math.inf if timeout is None else self.now + max(timeout, 0.0)
        skipped: float | None = None  # the last edge processed without its wait (the clock shows an earlier time)
        while True:
            while held and held[0][0] <= self.now + 1e-12:
                rx.append(held.popleft()[1])
            if rx:
                return rx.popleft()
            target = edge = self._next_event()
            if held and held[0][0] < target:
                target = held[0][0]
            target = min(target, deadline)
            if target == edge < deadline and self._skippable(edge, held):
                self._run(edge)
                skipped = edge
                if rx:  # it reached the node at once (no adapter latency): the host has it at that instant
                    self._wait_until(edge)
                continue
            if skipped is not None and target > 2.0 * self.clock.now():
                self._wait_until(skipped)  # the clock shows that edge exactly, as the wait for it would
            skipped = None
            if math.isinf(target):
                return None  # nothing in flight: in lockstep nothing can arrive any more
            self._wait_until(target)
            while held and held[0][0] <= self.now + 1e-12:
                rx.append(held.popleft()[1])
            if not rx and target >= deadline:
                return None

    def _skippable(self, edge: float, held: deque[tuple[float, can.Message]]) -> bool:
        """Whether the frame edge at ``edge`` may be processed without sleeping the clock to it, with the same
        outcome as the wait. Always: no frame the host holds becomes due there, and the clock, sleeping from
        where it is to any later instant up to twice its time, shows that instant exactly (``t - c`` is exact
        for ``c <= t <= 2c``: Sterbenz), as it would through the wait. Then either the physics already stands
        at the edge (the last tick came at or after it: the wait would step nothing, every tick up to it has
        run), or the peers only answer (:attr:`answers_only`: no tick adds a frame) and the edge touches no
        peer (an arbitration, or a frame only python-can nodes receive). In lockstep no other node sends
        while this one waits."""
        if self.ideal or math.isinf(edge) or (held and held[0][0] <= edge + 1e-12) or edge > 2.0 * self.clock.now():
            return False
        if edge <= self._ticked:
            return True
        if not self.answers_only:
            return False
        wire = self._wire
        return wire is None or not self._reaches_peer(wire[2].sender)

    def _reaches_peer(self, sender: _Node) -> bool:
        """Whether a frame ``sender`` sends goes to a peer (an in-process device other than the sender)."""
        for n in self._peers:
            if n is not sender:
                return True
        return False

    def idle(self) -> bool:
        """No frame on the wire or waiting for it."""
        return self._wire is None and not self._pending

    # -- statistics -----------------------------------------------------------------------
    def load(self) -> BusLoad:
        """Traffic since the last :meth:`reset_load` (or since the start)."""
        self._sync()
        t0, f0, b0, busy0 = self._mark
        return BusLoad(self.frames - f0, self.bits - b0, self.busy - busy0, self.now - t0, self.bitrate)

    def reset_load(self) -> None:
        self._sync()
        self._mark = (self.now, self.frames, self.bits, self.busy)


class LockstepCanBus(can.BusABC):
    """A python-can bus on an in-process :class:`CanMedium` (interface ``joints-sim``).

    ``channel`` names the medium (the sim's CAN buses are registered under their device bus's
    channel); ``medium`` passes one directly. ``bitrate`` and ``stuffing`` apply only when the
    channel has no medium yet.
    """

    def __init__(self, channel: Any = None, can_filters: Any = None, *, medium: CanMedium | None = None,
                 receive_own_messages: bool = False, bitrate: int | None = None, stuffing: str = "worst",
                 adapter_latency: float = 0.0, **kwargs: Any) -> None:
        if medium is None:
            medium = CanMedium.named(None if channel is None else str(channel), bitrate=bitrate or 1_000_000,
                                     stuffing=stuffing)
        self.medium = medium
        self.channel = medium.channel
        self.channel_info = f"{INTERFACE} {medium.channel}"
        self._node = medium.attach(self.channel_info, receive_own=receive_own_messages,
                                   adapter_latency=adapter_latency)
        self._can_protocol = can.CanProtocol.CAN_20
        super().__init__(channel=medium.channel, can_filters=can_filters, **kwargs)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self._is_shutdown:
            raise can.CanOperationError(f"{self.channel_info} is shut down")
        if msg.is_fd:
            raise can.CanOperationError(f"{self.channel_info}: classic CAN only, cannot send a CAN FD frame")
        self.medium.submit(self._node, msg)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """The next frame within ``timeout`` s of SIMULATED time (see the module docstring)."""
        if self._is_shutdown:
            raise can.CanOperationError(f"{self.channel_info} is shut down")
        medium = self.medium
        deadline = None if timeout is None else medium.now + max(timeout, 0.0)
        while True:
            left = None if deadline is None else max(deadline - medium.now, 0.0)
            msg = medium.receive(self._node, left)
            if msg is None:
                return None
            if self._filters is None or self._matches_filters(msg):  # no filters: every frame matches
                return msg

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        return self.medium.receive(self._node, 0.0), False

    def shutdown(self) -> None:
        if not self._is_shutdown:
            self.medium.detach(self._node)
        super().shutdown()

    @property
    def load(self) -> Callable[[], BusLoad]:
        return self.medium.load
