"""A half-duplex RS485 line in process, on the simulated clock: frames take their wire time, collisions corrupt.

Rule: no threads, no wall clock. The line is a :class:`~joints.transports.base.ByteTransport` for
the host and a byte peer (an emulated device bus: ``receive(bytes) -> bytes``, ``silence()``) on the
other side, both on one clock (the simulated world's: sleeping it steps the physics).

Time model:

* every character takes ``bits_per_char / baudrate`` seconds (10 bits: start, 8 data, stop); a
  frame occupies the line from its first to its last character; each side's UART sends its frames
  one after the other;
* the device gets a host frame when its last character has arrived and answers ``latency`` seconds
  later; frames it sends by itself (:class:`TimedFrames`: MKS completion frames at the moment the
  motion ended) go out at their own time;
* RS485 is half duplex and neither side listens before talking: when a host frame and a device
  frame overlap in time BOTH arrive corrupted (every byte inverted - the receivers' codecs see
  garbage and checksum errors), and :attr:`TimedSerialLine.collisions` counts it;
* ``read(timeout)`` waits on the clock - waiting IS letting simulated time pass - and returns as
  soon as a frame has arrived (at the latest when the time is up);
* a device side that ticks with the world (:class:`Ticking`, e.g. the MKS device bus) lets the line
  run after every physics substep, so frames arrive on time while the host does something else (a
  broadcast is executed while the host sleeps); otherwise the line runs at the host's reads and writes.

:attr:`TimedSerialLine.log` keeps every transmission (time, side, bytes, corrupted): the wire trace.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

from joints.errors import TransportError
from joints.transports.base import ByteTransport

__all__ = ["LinePeer", "Ticking", "TimedFrames", "TimedSerialLine", "Transmission"]

#: s the line waits at most in one step while nothing is on it (frames a device sends by itself are
#: picked up at least this often)
IDLE_STEP = 0.001


class ClockLike(Protocol):
    def now(self) -> float: ...

    def sleep(self, seconds: float) -> None: ...


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


@dataclass
class Transmission:
    """One frame on the line."""

    start: float
    end: float
    side: str  #: "host" or "device"
    data: bytes
    corrupted: bool = False
    delivered: bool = False

    def __str__(self) -> str:
        arrow = "->" if self.side == "host" else "<-"
        bad = "  COLLISION" if self.corrupted else ""
        return f"{self.start * 1000:10.3f} ms {arrow} {self.data.hex(' ').upper()}{bad}"


def _garbled(data: bytes) -> bytes:
    return bytes(b ^ 0xFF for b in data)


class TimedSerialLine(ByteTransport):
    """The host's end of a simulated half-duplex RS485 line (see the module docstring)."""

    def __init__(self, peer: Any, *, baudrate: int, clock: ClockLike, latency: float = 0.0005,
                 bits_per_char: int = 10) -> None:
        if baudrate <= 0 or latency < 0:
            raise ValueError(f"baudrate must be > 0 and latency >= 0, got {baudrate}, {latency}")
        self.peer = peer
        self.clock = clock
        self.baudrate = baudrate
        self.char_time = bits_per_char / baudrate
        self.latency = latency
        self.log: list[Transmission] = []
        self.collisions = 0
        self._pending: list[Transmission] = []  #: on the line, not yet arrived
        self._rx = bytearray()
        self._free = {"host": -math.inf, "device": -math.inf}  #: when each side's UART is free again
        self._closed = False
        if isinstance(peer, Ticking):
            peer.on_tick(self._tick)

    def _tick(self, t: float) -> None:
        if not self._closed:
            self._run(t)

    @property
    def name(self) -> str:
        return f"TimedSerialLine({self.baudrate} bd)"

    def wire_time(self, n: int) -> float:
        """Seconds ``n`` characters occupy the line."""
        return n * self.char_time

    # -- the line ---------------------------------------------------------------------------------
    def _put(self, side: str, at: float, data: bytes) -> Transmission:
        start = max(at, self._free[side])
        tx = Transmission(start, start + self.wire_time(len(data)), side, bytes(data))
        self._free[side] = tx.end
        for other in reversed(self.log):
            if other.end <= start - 1.0:
                break  # older than any frame still able to overlap
            if other.side != side and other.start < tx.end and start < other.end:
                if not (other.corrupted and tx.corrupted):
                    self.collisions += 1
                other.corrupted = tx.corrupted = True
        self.log.append(tx)
        self._pending.append(tx)
        return tx

    def _run(self, until: float) -> None:
        """Everything that happens on the line up to ``until`` (the clock's time), in time order."""
        while True:
            peer = self.peer
            if isinstance(peer, TimedFrames):
                for at, data in peer.take_frames(until):
                    self._put("device", at, data)
            due = [tx for tx in self._pending if tx.end <= until + 1e-12]
            if not due:
                return
            tx = min(due, key=lambda x: x.end)
            self._pending.remove(tx)
            tx.delivered = True
            data = _garbled(tx.data) if tx.corrupted else tx.data
            if tx.side == "device":
                self._rx += data
                continue
            reply = peer.receive(data) + peer.silence()  # the line is quiet after a frame
            if reply:
                self._put("device", tx.end + self.latency, reply)

    def _next_arrival(self) -> float | None:
        return min((tx.end for tx in self._pending), default=None)

    # -- ByteTransport ----------------------------------------------------------------------------
    def write(self, data: bytes) -> None:
        if self._closed:
            raise TransportError("serial line is closed")
        now = self.clock.now()
        self._run(now)
        self._put("host", now, data)

    def read(self, timeout: float) -> bytes:
        if self._closed:
            raise TransportError("serial line is closed")
        clock = self.clock
        deadline = clock.now() + max(timeout, 0.0)
        while True:
            now = clock.now()
            self._run(now)
            if self._rx:
                data = bytes(self._rx)
                self._rx.clear()
                return data
            if now >= deadline - 1e-12:
                return b""
            nxt = self._next_arrival()
            wait = min(deadline, nxt if nxt is not None and nxt > now else now + IDLE_STEP) - now
            clock.sleep(max(wait, 1e-9))

    def reset_input(self) -> None:
        self._rx.clear()

    def close(self) -> None:
        self._closed = True

    def trace(self) -> str:
        """The wire trace: every transmission, one per line."""
        return "\n".join(str(tx) for tx in self.log)
