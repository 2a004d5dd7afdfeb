"""The real bus's time for served twins (``joints sim serve``): when a request acts and when its reply leaves.

Rule: pure arithmetic on times the caller passes in (the serving loop's wall clock); no clock,
no I/O. A pseudo-terminal or a udp_multicast channel carries bytes at once, so the serving loop
holds each request and each reply for the time the real bus would take (per bus, one transaction
after the other, as on a half-duplex line):

* the request occupies the line for its wire time from the moment it was read (or from when the
  line is free again): serial characters at the configured baud rate and framing, CAN frames with
  worst-case bit stuffing (the planner's numbers, :mod:`joints.transports.serial_timing`,
  :mod:`joints.transports.can_timing`);
* it has *arrived* at its end, plus the t3.5 silence on Modbus RTU (an RTU slave knows its frame
  is complete only after it); the MKS protocol and CAN have no silence rule;
* the drive acts - executes it, samples the state it reports - ``turnaround`` s after arrival;
* its reply occupies the line for its wire time (a Modbus RTU frame is followed by t3.5 before the
  next one may start), and reaches the host ``adapter_latency`` s after its last bit: the host
  adapter's delay, put on the reply path (a USB-serial adapter's latency timer holds received
  bytes; its transmit delay is small), once per transaction.

So one transaction takes ``wire + turnaround + adapter_latency`` from the host's write to the last
byte of the reply, where ``wire`` is request + t3.5 + reply on Modbus RTU (request + reply
elsewhere); ``joints bench --hardware`` measures the same sum on a real bus. The host then keeps
the t3.5 silence after the reply before its next request (:class:`~joints.transports.serial.
SerialTransport` does), so a host loop runs at the planner's cycle: two t3.5 per transaction, as
the in-process line counts them. ``timing = "ideal"`` holds nothing.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from joints.transports import can_timing, serial_timing

__all__ = ["BusTiming", "ServedLine", "substeps_to"]


def substeps_to(instant: float, now: float, timestep: float) -> int:
    """Whole physics substeps from world time ``now`` to the one that ends at or after ``instant`` (0: reached).

    A served request acts on that substep's world, as on the in-process line (never on an earlier one:
    a command does not take effect, nor is a state sampled, before its instant).
    """
    return max(0, math.ceil((instant - now) / timestep - 1e-6))


@dataclass(frozen=True)
class BusTiming:
    """How long frames of one served bus take (s); ``ideal``: they take no time."""

    medium: str  #: "serial" | "can"
    char_time: float = 0.0  #: serial: s per character (start, data, parity, stop bits)
    silence: float = 0.0  #: s of silence after every frame (Modbus RTU: t3.5), 0 elsewhere
    bitrate: int = 1_000_000  #: CAN: bit/s
    adapter_latency: float = 0.0
    turnarounds: Mapping[int, float] = field(default_factory=dict)  #: drive address / CAN node -> turnaround
    ideal: bool = False

    @classmethod
    def serial(cls, *, baudrate: int, parity: str = "N", stopbits: int = 1, rtu: bool = True,
               adapter_latency: float = 0.0, turnarounds: Mapping[int, float] | None = None,
               ideal: bool = False) -> BusTiming:
        """A serial bus (``rtu``: frames delimited by the t3.5 silence)."""
        silence = serial_timing.t35_bits(baudrate, parity, stopbits) / baudrate if rtu else 0.0
        return cls("serial", serial_timing.char_bits(parity, stopbits) / baudrate, silence,
                   adapter_latency=adapter_latency, turnarounds=dict(turnarounds or {}), ideal=ideal)

    @classmethod
    def can(cls, *, bitrate: int, adapter_latency: float = 0.0, turnarounds: Mapping[int, float] | None = None,
            ideal: bool = False) -> BusTiming:
        return cls("can", bitrate=bitrate, adapter_latency=adapter_latency, turnarounds=dict(turnarounds or {}),
                   ideal=ideal)

    def bytes_time(self, n: int) -> float:
        """s ``n`` characters occupy a serial line."""
        return n * self.char_time

    def frame_time(self, frame: Any) -> float:
        """s a CAN frame occupies the bus (worst-case stuffing, as the planner counts it)."""
        return can_timing.frame_time(frame, self.bitrate)

    def turnaround(self, address: int | None) -> float:
        """The turnaround of the drive at ``address`` (the slowest drive of the bus for a broadcast / unknown)."""
        if address is not None and address in self.turnarounds:
            return self.turnarounds[address]
        return max(self.turnarounds.values(), default=0.0)

    def transaction(self, request: float, reply: float, address: int | None = None) -> float:
        """s from the host's write to the last byte of the reply reaching it (``request``/``reply``: wire s)."""
        if self.ideal:
            return 0.0
        return request + self.silence + self.turnaround(address) + reply + self.adapter_latency


class ServedLine:
    """One served bus on the serving loop's clock: when requests act and replies leave (see the module)."""

    def __init__(self, timing: BusTiming, *, scale: float = 1.0) -> None:
        if not scale > 0:
            raise ValueError(f"scale must be > 0, got {scale!r}")
        self.timing = timing
        self.scale = scale  #: wall s per bus s (1 / the realtime factor)
        self.free = -math.inf  #: when the line is free for the next frame

    def request(self, now: float, wire: float, address: int | None = None) -> float:
        """A request of ``wire`` s read at ``now``: the time the addressed drive acts on it."""
        t = self.timing
        if t.ideal:
            return now
        start = max(now, self.free)
        arrived = start + (wire + t.silence) * self.scale
        self.free = arrived
        return arrived + t.turnaround(address) * self.scale

    def sent(self, end: float) -> float:
        """A frame a drive sent by itself (a heartbeat, an event TPDO) whose last bit left the wire at ``end``
        (its wire time was counted where it was sent): the time it reaches the host; the line was busy until then."""
        t = self.timing
        if t.ideal:
            return end
        self.free = max(self.free, end + t.silence * self.scale)
        return end + t.adapter_latency * self.scale

    def reply(self, at: float, wire: float) -> float:
        """A reply of ``wire`` s the drive sends at ``at``: the time it reaches the host."""
        t = self.timing
        if t.ideal:
            return at
        start = max(at, self.free)
        end = start + wire * self.scale
        self.free = end + t.silence * self.scale
        return end + t.adapter_latency * self.scale
