"""How long Modbus RTU frames occupy a serial bus: character times and the t3.5 silence.

Rule: pure arithmetic (no I/O, no clock), the serial twin of :mod:`joints.transports.can_timing`;
results are :class:`~joints.transports.can_timing.CycleLoad` (bit times per cycle), so one planner
reads serial and CAN buses alike.

Modbus over serial line (V1.02, 2.5.1.1): a character is 1 start + 8 data + parity + stop bits (11
bits with parity or two stop bits; 10 with 8N1, which the spec allows only as an option); frames
are separated by a silence of at least 3.5 characters (t3.5), fixed at 1.75 ms above 19200 baud.
A transaction is the request, t3.5, the reply, t3.5. The slave's own turnaround (the time it takes
to start answering) is the drive's: ``turnaround`` here is 0 by default (wire time only); the bus
planner (:func:`joints.bench.plan`) adds each drive's profile turnaround and the host adapter's
latency per transaction (docs/timing.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from joints.transports.can_timing import CycleLoad

__all__ = ["char_bits", "cycle_load", "t35_bits"]


def char_bits(parity: str = "N", stopbits: int = 1) -> int:
    """Bits of one character on the line: start, 8 data, parity (E/O), stop bits."""
    return 1 + 8 + (0 if parity.upper() == "N" else 1) + stopbits


def t35_bits(baudrate: int, parity: str = "N", stopbits: int = 1) -> float:
    """The inter-frame silence t3.5 in bit times: 3.5 characters, or 1.75 ms above 19200 baud."""
    if baudrate > 19200:
        return 1.75e-3 * baudrate
    return 3.5 * char_bits(parity, stopbits)


def cycle_load(frame_bytes: Sequence[int], *, period: float, baudrate: int, parity: str = "N",
               stopbits: int = 1, turnaround: float = 0.0, silence: bool = True) -> CycleLoad:
    """The line's load when frames of ``frame_bytes`` bytes (requests and replies, in order) are sent
    every ``period`` s: each frame's characters plus (``silence``: Modbus RTU, whose frames are
    delimited by it) a t3.5 silence after it, plus ``turnaround`` s per reply (every second frame)."""
    if period <= 0 or baudrate <= 0:
        raise ValueError("the period and the baud rate must be > 0")
    per_char = char_bits(parity, stopbits)
    gap = t35_bits(baudrate, parity, stopbits) if silence else 0.0
    bits = sum(n * per_char + gap for n in frame_bytes) + turnaround * baudrate * (len(frame_bytes) // 2)
    whole = math.ceil(bits)
    return CycleLoad(whole, whole, period, baudrate)
