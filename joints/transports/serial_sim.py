"""A half-duplex RS485 line in process, on the simulated clock: frames take their wire time, collisions corrupt.

Rule: no threads, no wall clock. The line is a :class:`~joints.transports.base.ByteTransport` for
the host and a byte peer (an emulated device bus: ``receive(bytes) -> bytes``, ``silence()``) on the
other side, both on one clock (the simulated world's: sleeping it steps the physics).

Time model (docs/timing.md):

* every character takes ``bits_per_char / baudrate`` seconds (start, 8 data, parity, stop bits);
  a frame occupies the line from its first to its last character, then its sender keeps the line
  quiet for ``gap`` seconds (Modbus RTU: t3.5, which ends the frame for the receiver; 0 for
  protocols without a silence rule); each side's UART sends its frames one after the other;
* the device acts on a host frame - a read samples its state, a write takes effect - and starts
  its answer ``turnaround`` seconds after the frame ended (gap included): the drive's own number
  (the peer's ``turnaround(frame)``, from the device profile), else the line's default; frames it
  sends by itself (:class:`TimedFrames`: MKS completion frames at the moment the motion ended)
  go out at their own time;
* the host sees a device frame ``adapter_latency`` seconds after it ended (the USB adapter's and
  the host's share of a transaction: the host's codec knows where a frame ends, so it does not wait
  for the silence after it), and keeps the line quiet for ``gap`` from then before its next frame
  (as :class:`~joints.transports.serial.SerialTransport` does);
* the line keeps its own exact time (like :class:`~joints.transports.can_sim.CanMedium`): waiting
  sleeps the clock, the world steps whole physics substeps (so a frame instant sees the physics
  of the substep that ends at or after it), but bus time is never rounded to substeps; a wait in
  which nothing acts on a drive (a reply travelling to the host) only books the time on the clock
  (``clock.book``), and the line settles the clock (``clock.settle``: the physics catches up)
  before the device side acts;
* RS485 is half duplex and neither side listens before talking: when a host frame and a device
  frame overlap in time BOTH arrive corrupted (every byte inverted - the receivers' codecs see
  garbage and checksum errors), and :attr:`TimedSerialLine.collisions` counts it;
* ``read(timeout)`` waits on the clock - waiting IS letting simulated time pass - and returns as
  soon as a frame has arrived (at the latest when the time is up);
* :meth:`TimedSerialLine.transact` and :meth:`TimedSerialLine.post` carry the sim's direct path
  (message objects, no bytes) over the same timing: a frame of the same size takes the same time;
* a device side that ticks with the world (:class:`Ticking`, e.g. the MKS device bus) lets the line
  run after every physics substep, so frames arrive on time while the host does something else (a
  broadcast is executed while the host sleeps); otherwise the line runs at the host's reads and writes.

:attr:`TimedSerialLine.log` keeps the transmissions (time, side, bytes, corrupted): the wire trace, its
latest :attr:`TimedSerialLine.log_keep` frames at least (:data:`LOG_KEEP`, 1,000, unless set on the line) and
those of the last second (older ones go in batches, once they can overlap no new frame). A kept frame costs
memory (~230 bytes): keep more only where the trace is read (docs/speed.md). The frames a one-call exchange books
(:meth:`TimedSerialLine.book_frames`) are kept as tuples of plain values (the collector untracks them: its passes do
not walk them step after step), their replies apart (shared reply objects by reference, a packed reply as its
values), made :class:`Transmission` objects when the log is read.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

from joints.errors import TransportError
from joints.transports.base import ByteTransport
from joints.transports.simclock import ClockDriven, ClockLike

__all__ = ["Deferred", "LinePeer", "Ticking", "TimedFrames", "TimedSerialLine", "Transmission"]

#: s the line waits at most in one step while nothing is on it (frames a device sends by itself are
#: picked up at least this often)
IDLE_STEP = 0.001
#: transmissions :attr:`TimedSerialLine.log` keeps at least (at most about twice as many beyond those of the last
#: second): a long run's memory stays flat; a line's own :attr:`TimedSerialLine.log_keep` starts at this
LOG_KEEP = 1_000


class LinePeer(Protocol):
    """The device side: bytes in, the bytes it answers out."""

    def receive(self, data: bytes) -> bytes: ...

    def silence(self) -> bytes: ...


@runtime_checkable
class TimedFrames(Protocol):
    """A device side that also sends frames by itself, each at its own time."""

    def take_frames(self, now: float | None = None) -> list[tuple[float, bytes]]:
        """Frames sent by ``now``: (time the first character went out, bytes), oldest first."""
        ...


@runtime_checkable
class Ticking(Protocol):
    """A device side that runs on the simulated clock and calls back after every physics substep."""

    def on_tick(self, callback: Callable[[float], None]) -> None: ...


@dataclass(eq=False)
class Transmission:
    """One frame on the line."""

    start: float
    end: float
    side: str  #: "host" or "device"
    data: bytes
    corrupted: bool = False
    delivered: bool = False
    due: float = 0.0  #: when the receiver acts on it (host frame) or sees it (device frame)
    size: int = 0  #: characters (a direct-path frame carries no bytes)
    #: direct path: a host frame's action (returns the reply message or None), a device frame's receiver
    handler: Callable[..., Any] | None = None
    payload: Any = None  #: direct path: the reply message a device frame carries

    def __str__(self) -> str:
        arrow = "->" if self.side == "host" else "<-"
        bad = "  COLLISION" if self.corrupted else ""
        what = self.data.hex(" ").upper() if self.data or not self.size else f"<{self.size} bytes: {self.payload!r}>"
        return f"{self.start * 1000:10.3f} ms {arrow} {what}{bad}"


class Deferred:
    """A direct-path reply known by what it carries, made as its message only when asked (:meth:`message`, once:
    the same object every time). A frame booked by :meth:`TimedSerialLine.book_frames` may carry one: the log
    holds its message, made when the log is read."""

    __slots__ = ()

    def message(self) -> Any:
        raise NotImplementedError


def _garbled(data: bytes) -> bytes:
    return bytes(b ^ 0xFF for b in data)


class TimedSerialLine(ByteTransport, ClockDriven):
    """The host's end of a simulated half-duplex RS485 line (see the module docstring)."""

    def __init__(self, peer: Any, *, baudrate: int, clock: ClockLike, turnaround: float = 0.0,
                 adapter_latency: float = 0.0, gap: float = 0.0, bits_per_char: int = 10) -> None:
        for what, v in (("turnaround", turnaround), ("adapter_latency", adapter_latency), ("gap", gap)):
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{what} must be a finite number of seconds >= 0, got {v!r}")
        if baudrate <= 0:
            raise ValueError(f"baudrate must be > 0, got {baudrate}")
        self.peer = peer
        self._peer_seen: Any = None  #: the peer whose :class:`TimedFrames` check is in ``_peer_timed``
        self._peer_timed = False
        self._peer_plain_seen: Any = None  #: the peer whose check is in ``_peer_plain`` (:meth:`_plain_peer`)
        self._peer_plain = False
        self.clock = clock
        self.baudrate = baudrate
        self.char_time = bits_per_char / baudrate
        self.turnaround = turnaround  #: s, the device's default (a peer that knows its drives' wins)
        self.adapter_latency = adapter_latency
        self.gap = gap
        self._log: list[Transmission] = []
        self._keep = LOG_KEEP
        self._trim_at = 2 * LOG_KEEP  #: the log's length that makes it trimmed
        #: the log's first entry that may still be a booked frame's tuple (:meth:`book_frames`)
        self._raw_from = 0
        #: the replies of the booked frames still tuples, in log order (see :meth:`book_frames`)
        self._replies: list[Any] = []
        #: per logged frame, the latest end of it and every frame logged before it since the epoch: a new
        #: frame's overlap check stops where nothing older can reach it
        self._latest_end: list[float] = []
        self._epoch = 0  #: the first frame of the line's present timeline (after the clock last went back)
        self.collisions = 0
        self._pending: list[Transmission] = []  #: on the line, not yet acted on / seen
        self._rx = bytearray()
        self._free = {"host": -math.inf, "device": -math.inf}  #: when each side's UART is free again
        self._closed = False
        self.now = clock.now()  #: the line's exact time (the clock may be up to a substep ahead)
        self._clock_seen = self.now
        self._see_epoch()
        self._cap: float | None = None  #: while the line sleeps the clock itself: run no further than this
        self._turnaround_of: Callable[[bytes], float | None] | None = getattr(peer, "turnaround", None)
        if not callable(self._turnaround_of):
            self._turnaround_of = None
        if isinstance(peer, Ticking):
            peer.on_tick(self._tick)
        #: the clock's "the physics catches up" (a world that books waits lazily): before the device side acts
        self._settle: Callable[[], None] | None = getattr(clock, "settle", None)

    @property
    def name(self) -> str:
        return f"TimedSerialLine({self.baudrate} bd)"

    @property
    def log_keep(self) -> int:
        """Transmissions :attr:`log` keeps at least (at most about twice as many beyond those of the last second;
        :data:`LOG_KEEP` unless set)."""
        return self._keep

    @log_keep.setter
    def log_keep(self, n: int) -> None:
        if n < 1:
            raise ValueError(f"log_keep must be >= 1 (the latest frame stays), got {n!r}")
        self._keep = n
        self._trim_at = 2 * n

    @property
    def log(self) -> list[Transmission]:
        """The transmissions, oldest first (see the module docstring)."""
        if self._raw_from < len(self._log):
            self._materialize()
        return self._log

    def book_frames(self, frames: Sequence[tuple[Any, ...]]) -> None:
        """Frames a one-call exchange carried, each ``(start, end, due, size, side, reply)`` or ``(start, end, due,
        size, side, make, values)`` (a packed reply: ``make(values)`` is its message, ``make`` one object for many
        replies, ``values`` ints), delivered, none overlapping another frame - its caller checked that:
        logged as :meth:`_put` logs them (the latest-end bookkeeping, the trimming), made :class:`Transmission`
        objects when the log is read (a :class:`Deferred` reply: its message).

        Rule: a booked frame holds no object the garbage collector tracks, so a long log costs the collector nothing
        step after step: its entry is ``(start, end, due, size, side, mark, *values)``, ``mark`` None (no reply),
        True (the reply is the next of :attr:`_replies`) or False (a packed reply: ``make`` is the next of
        :attr:`_replies`, its values follow - flat, as a tuple in a tuple keeps the outer one tracked);
        :attr:`_replies` holds the booked entries' replies in log order, by reference (a shared reply adds no
        object)."""
        log: list[Any] = self._log
        latest = self._latest_end
        replies = self._replies
        epoch = self._epoch
        for item in frames:
            end = item[1]
            latest.append(max(end, latest[-1]) if len(log) > epoch else end)
            reply = item[5]
            if reply is not None:
                replies.append(reply)
                item = item[:5] + (False, *item[6]) if len(item) > 6 else (*item[:5], True)
            log.append(item)
            if len(log) > self._trim_at:
                self._trim(item[0])
                epoch = self._epoch

    def latest_end(self) -> float:
        """The latest end of any frame of the present timeline (-inf: none)."""
        latest = self._latest_end
        return latest[-1] if len(self._log) > self._epoch and latest else -math.inf

    def _materialize(self) -> None:
        """Booked frames (:meth:`book_frames`) become transmissions."""
        log: list[Any] = self._log
        replies = iter(self._replies)
        for k in range(self._raw_from, len(log)):
            item = log[k]
            if type(item) is tuple:
                start, end, due, size, side, mark = item[:6]
                payload = None
                if mark is not None:
                    payload = next(replies)
                    if mark is False:  # a packed reply: made of its values
                        payload = payload(item[6:])
                    elif isinstance(payload, Deferred):
                        payload = payload.message()
                log[k] = Transmission(start, end, side, b"", delivered=True, due=due, size=size, payload=payload)
        self._replies.clear()
        self._raw_from = len(log)

    def wire_time(self, n: int) -> float:
        """Seconds ``n`` characters occupy the line."""
        return n * self.char_time

    # -- time ---------------------------------------------------------------------------------------
    def _tick(self, t: float) -> None:
        if self._closed:
            return
        if self._epoch_seen is not None and self._restarted(self.clock.now()):
            self._new_timeline(self.clock.now())
        if self._cap is not None:
            t = min(t, self._cap)
        if t > self.now:
            self._run(t)
            if self._cap is None:
                self.now = t
                self._clock_seen = max(self._clock_seen, t)

    def _sync(self) -> float:
        """Catch up with a clock that moved without the line (the host slept) or restarted (a reset)."""
        c = self.clock.now()
        if self._restarted(c):
            self._new_timeline(c)
        elif c > self._clock_seen:
            self._clock_seen = c
            if c > self.now:
                self._run(c)
                self.now = c
        return self.now

    def _new_timeline(self, c: float) -> None:
        """The clock restarted at ``c`` (a reset): what was in flight is gone."""
        self._pending.clear()
        self._rx.clear()
        self._free = {"host": -math.inf, "device": -math.inf}
        self._epoch = len(self._log)  # frames of the old timeline never overlap the new one's
        self.now = self._clock_seen = c

    # -- the line ---------------------------------------------------------------------------------
    def _device_turnaround(self, data: bytes) -> float:
        of = self._turnaround_of
        got = of(data) if of is not None and data else None
        return self.turnaround if got is None else got

    def _put(self, side: str, at: float, data: bytes, *, size: int | None = None, turnaround: float | None = None,
             handler: Callable[..., Any] | None = None, payload: Any = None, pend: bool = True) -> Transmission:
        n = len(data) if size is None else size
        start = max(at, self._free[side])
        end = start + n * self.char_time  # wire_time(n)
        if side == "host":
            due = end + self.gap + (self._device_turnaround(data) if turnaround is None else turnaround)
        else:
            due = end + self.adapter_latency
        tx = Transmission(start, end, side, data if type(data) is bytes else bytes(data), due=due, size=n, handler=handler, payload=payload)
        self._free[side] = end + self.gap
        log: list[Any] = self._log  # (booked frames become transmissions where the search reaches them)
        latest = self._latest_end
        if len(latest) != len(log):  # the log was edited from outside: check every frame of it from now on
            latest[:] = [math.inf] * len(log)
            self._epoch = min(self._epoch, len(log))
        for k in range(len(log) - 1, self._epoch - 1, -1):
            if latest[k] <= start:
                break  # no frame up to this one ends after the new one starts: none of them overlaps it
            other = log[k]
            if type(other) is tuple:
                self._materialize()
                other = log[k]
            if other.end <= start - 1.0:
                break  # older than any frame still able to overlap
            if other.side != side and other.start < tx.end and start < other.end:
                if not (other.corrupted and tx.corrupted):
                    self.collisions += 1
                other.corrupted = tx.corrupted = True
        latest.append(max(end, latest[-1]) if len(log) > self._epoch else end)
        log.append(tx)
        if pend:
            self._pending.append(tx)
        if len(log) > self._trim_at:
            self._trim(start)
        return tx

    def _trim(self, start: float) -> None:
        """The oldest frames go, all but the latest ``log_keep``, once none of them can overlap a new frame (one
        starting at ``start`` or later): those of the present timeline that ended a second before ``start``."""
        log, latest, epoch = self._log, self._latest_end, self._epoch
        keep = self._keep
        cut = len(log) - keep
        if cut > epoch and latest[cut - 1] > start - 1.0:  # (latest: the running latest end since the epoch)
            cut = bisect.bisect_right(latest, start - 1.0, epoch, cut)
        if cut > 0:
            if self._replies:  # the replies of the booked entries that go
                raw: list[Any] = log[self._raw_from:cut]
                gone = sum(1 for item in raw if type(item) is tuple and item[5] is not None)
                del self._replies[:gone]
            del log[:cut], latest[:cut]
            self._epoch = max(0, epoch - cut)
            self._raw_from = max(0, self._raw_from - cut)
        self._trim_at = len(log) + keep  # (beyond keep, the frames of the last second): the next waits for keep more

    def _run(self, until: float) -> None:
        """Everything that happens on the line up to ``until`` (the clock's time), in time order."""
        pending = self._pending
        limit = until + 1e-12
        while True:
            peer = self.peer
            if peer is not self._peer_seen:  # a Protocol isinstance costs ~60 us: once per peer
                self._peer_seen, self._peer_timed = peer, isinstance(peer, TimedFrames)
            settle = self._settle
            if self._peer_timed:
                if settle is not None:
                    settle()
                for at, data in peer.take_frames(until):
                    self._put("device", at, data)
            tx = None  # the earliest due frame (the first of equals)
            for p in pending:
                if p.due <= limit and (tx is None or p.due < tx.due):
                    tx = p
            if tx is None:
                return
            pending.remove(tx)
            tx.delivered = True
            if tx.side == "device":
                # the host saw it now; its next frame keeps the gap from here (its own t3.5)
                self._free["host"] = max(self._free["host"], tx.due + self.gap)
                if tx.handler is not None:  # the direct path: the reply message reaches the host
                    tx.handler(tx.payload)
                else:
                    self._rx += _garbled(tx.data) if tx.corrupted else tx.data
                continue
            if settle is not None:  # the drive acts now: on the physics of the substep that reaches now
                settle()
            if tx.handler is not None:  # the direct path: the drive acts on the message now
                reply, size, receiver = tx.handler()
                if reply is not None:
                    self._put("device", tx.due, b"", size=size, handler=receiver, payload=reply)
                continue
            data = _garbled(tx.data) if tx.corrupted else tx.data
            reply_bytes = peer.receive(data) + peer.silence()  # the line is quiet after a frame
            if reply_bytes:
                self._put("device", tx.due, reply_bytes)

    def _next_due(self) -> float | None:
        return min((tx.due for tx in self._pending), default=None)

    def _quiet_until(self, t: float) -> bool:
        """Whether nothing acts on a drive up to ``t`` (no host frame due, no device sending by itself): a wait
        until ``t`` needs the clock, not the physics (the world books it: :meth:`joints.clock.ManualClock.book`)."""
        if self._peer_timed:
            return False
        limit = t + 1e-12
        return not any(p.side == "host" and p.due <= limit for p in self._pending)

    # -- the direct path (message objects, the same time as their bytes) ---------------------------
    def transact(self, size: int, act: Callable[[], Any], reply_size: Callable[[Any], int],
                 turnaround: float | None = None) -> Any:
        """Send a request of ``size`` characters now; the device acts on it (``act()``: its reply message or
        None) when the byte path's device would; returns the reply once the host would have received it
        (None at once after the device acted if it stays silent)."""
        if self._closed:
            raise TransportError("serial line is closed")
        got: list[Any] = []

        def action() -> tuple[Any, int, Callable[[Any], None]]:
            reply = act()
            got.append(None)
            return reply, (reply_size(reply) if reply is not None else 0), got.append

        now = self._sync()
        if not self._pending and self._cap is None and self._plain_peer():
            return self._transact_idle(now, size, act, reply_size, turnaround)
        self._run(now)
        tx = self._put("host", now, b"", size=size, turnaround=turnaround, handler=action)
        self._wait_until(tx.due)
        while len(got) < 2:
            nxt = self._next_due()
            if got == [None] and (nxt is None or not any(p.side == "device" and p.handler is not None
                                                         for p in self._pending)):
                return None  # the device stays silent
            assert nxt is not None
            self._wait_until(nxt, self._quiet_until(nxt))
        return got[1]

    def _plain_peer(self) -> bool:
        """Whether the peer acts only when a host frame reaches it (neither :class:`TimedFrames` nor
        :class:`Ticking`): on an idle line its transaction is :meth:`_transact_idle`'s."""
        peer = self.peer
        if peer is not self._peer_plain_seen:  # a Protocol isinstance costs ~60 us: once per peer
            self._peer_plain_seen = peer
            self._peer_plain = not isinstance(peer, (TimedFrames, Ticking))
        return self._peer_plain

    def _transact_idle(self, now: float, size: int, act: Callable[[], Any], reply_size: Callable[[Any], int],
                       turnaround: float | None) -> Any:
        """:meth:`transact` on an idle line (nothing pending, a peer that acts only on host frames): the same
        frames, instants, clock calls and order of events as :meth:`_run` gives them, without its search.

        Rule: every float is computed by the same operations as the general path (``_put``, ``_wait_until``),
        so both give the same bits (tests/transports/test_serial_sim.py compares them).
        """
        clock = self.clock
        tx = self._put("host", now, b"", size=size, turnaround=turnaround)  # pending while the clock sleeps
        due = tx.due
        behind = due - clock.now()
        if behind > 0:  # the physics runs to the instant the drive acts (_wait_until)
            self._cap = due
            try:
                clock.sleep(behind)
            finally:
                self._cap = None
            self._clock_seen = clock.now()
        self._pending.remove(tx)
        tx.delivered = True
        settle = self._settle
        if settle is not None:  # the drive acts now: on the physics of the substep that reaches now
            settle()
        reply = act()
        self.now = max(self.now, due)
        if reply is None:  # the device stays silent
            return None
        rx = self._put("device", due, b"", size=reply_size(reply), payload=reply, pend=False)
        seen = rx.due
        behind = seen - clock.now()
        if behind > 0:  # nothing acts on a drive while the reply travels: booked, no physics (_wait_until, lazy)
            self._cap = seen
            try:
                book = getattr(clock, "book", None)
                if book is not None:
                    book(behind)
                else:
                    clock.sleep(behind)
            finally:
                self._cap = None
            self._clock_seen = clock.now()
        rx.delivered = True
        free = self._free
        free["host"] = max(free["host"], seen + self.gap)  # the host's own t3.5 from when it saw the reply
        self.now = max(self.now, seen)
        return reply

    def post(self, size: int, act: Callable[[], Any], reply_size: Callable[[Any], int],
             receiver: Callable[[Any], None], turnaround: float | None = None) -> None:
        """Send a request of ``size`` characters that waits for nothing (a broadcast): the device acts on it
        (``act()``) when the byte path's device would; a reply nobody waited for goes to ``receiver``."""
        if self._closed:
            raise TransportError("serial line is closed")

        def action() -> tuple[Any, int, Callable[[Any], None]]:
            reply = act()
            return reply, (reply_size(reply) if reply is not None else 0), receiver

        now = self._sync()
        self._run(now)
        self._put("host", now, b"", size=size, turnaround=turnaround, handler=action)

    def wait(self, timeout: float) -> None:
        """Let ``timeout`` s pass on the line (the direct path waiting for a reply that does not come)."""
        if timeout > 0:
            self._wait_until(self._sync() + timeout)

    # -- ByteTransport ----------------------------------------------------------------------------
    def write(self, data: bytes) -> None:
        if self._closed:
            raise TransportError("serial line is closed")
        now = self._sync()
        self._run(now)
        self._put("host", now, data)

    def read(self, timeout: float) -> bytes:
        if self._closed:
            raise TransportError("serial line is closed")
        deadline = self._sync() + max(timeout, 0.0)
        while True:
            now = self.now
            self._run(now)
            if self._rx:
                data = bytes(self._rx)
                self._rx.clear()
                return data
            if now >= deadline - 1e-12:
                return b""
            nxt = self._next_due()
            until = min(deadline, nxt if nxt is not None and nxt > now else now + IDLE_STEP)
            self._wait_until(until, self._quiet_until(until))

    def reset_input(self) -> None:
        self._rx.clear()

    def close(self) -> None:
        self._closed = True

    def trace(self) -> str:
        """The wire trace: every transmission, one per line."""
        return "\n".join(str(tx) for tx in self.log)


#: the methods a transaction goes through, as defined here (captured when this module is imported): a one-call
#: exchange (:mod:`joints.sim.erob_exchange`) runs only while none of them is replaced
STOCK = ((TimedSerialLine, "_transact_idle", TimedSerialLine._transact_idle),
         (TimedSerialLine, "_plain_peer", TimedSerialLine._plain_peer), (TimedSerialLine, "_put", TimedSerialLine._put),
         (TimedSerialLine, "transact", TimedSerialLine.transact))
