"""How long a classic CAN frame occupies the bus: bits on the wire, with bit stuffing.

Rule: pure arithmetic on python-can frames (``arbitration_id``, ``is_extended_id``,
``is_remote_frame``, ``dlc``, ``data``); no I/O, no clock. Used by the sim's timed medium
(:mod:`joints.transports.can_sim`) and the CAN benchmark.

A classic data frame with ``n`` data bytes has these bits (ISO 11898-1):

=========================  ========  ========
field                      standard  extended
=========================  ========  ========
SOF                        1         1
arbitration (id, RTR/SRR,  13        32
IDE, extended id, RTR)
control (r0/r1, DLC)       5         6
data                       8n        8n
CRC                        15        15
CRC delimiter, ACK slot,   10        10
ACK delimiter, EOF (7)
intermission (IFS)         3         3
total, no stuffing         47 + 8n   67 + 8n
=========================  ========  ========

Bit stuffing inserts a complementary bit after five equal bits, over SOF .. CRC
(``g + 8n`` bits with ``g`` = 34 standard, 54 extended). Worst case (the bound used by
schedulability analysis, Davis et al. 2007): one stuff bit per four bits after the first,
``floor((g + 8n - 1) / 4)``. So the worst-case frame is ``47 + 8n + floor((33 + 8n) / 4)``
bits standard (135 bits for 8 bytes) and ``67 + 8n + floor((53 + 8n) / 4)`` extended.
:func:`stuff_bits` with ``exact=True`` counts the stuff bits of the actual frame instead
(the CRC-15 computed as the standard says). A remote frame carries no data bits.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["STUFFING", "CycleLoad", "canopen_cycle_load", "cycle_load", "frame_bits", "frame_time", "stuff_bits",
           "unstuffed_bits"]

#: the stuffing models :func:`frame_bits` knows: worst-case bound, exact count, none
STUFFING = ("worst", "exact", "none")

_CRC15_POLY = 0x4599


def _data_len(frame: Any) -> int:
    return 0 if frame.is_remote_frame else len(frame.data)


def unstuffed_bits(frame: Any) -> int:
    """Bits of the frame without stuffing, intermission included (47 + 8n standard, 67 + 8n extended)."""
    return (67 if frame.is_extended_id else 47) + 8 * _data_len(frame)


def _stuffed_region(frame: Any) -> list[int]:
    """The bits from SOF to the end of the CRC, as sent (before stuffing)."""
    bits: list[int] = [0]  # SOF (dominant)

    def put(value: int, width: int) -> None:
        bits.extend((value >> i) & 1 for i in range(width - 1, -1, -1))

    rtr = 1 if frame.is_remote_frame else 0
    dlc = frame.dlc if frame.is_remote_frame else len(frame.data)
    if frame.is_extended_id:
        put(frame.arbitration_id >> 18, 11)
        put(1, 1)  # SRR (recessive)
        put(1, 1)  # IDE (recessive: extended)
        put(frame.arbitration_id & 0x3FFFF, 18)
        put(rtr, 1)
        put(0, 2)  # r1, r0
    else:
        put(frame.arbitration_id, 11)
        put(rtr, 1)
        put(0, 2)  # IDE (dominant: standard), r0
    put(dlc, 4)
    if not frame.is_remote_frame:
        for byte in bytes(frame.data):
            put(byte, 8)
    crc = 0
    for b in bits:
        crc_next = b ^ ((crc >> 14) & 1)
        crc = (crc << 1) & 0x7FFF
        if crc_next:
            crc ^= _CRC15_POLY
    put(crc, 15)
    return bits


def stuff_bits(frame: Any, *, exact: bool = False) -> int:
    """Stuff bits of the frame: the worst-case bound, or (``exact``) those its bits need."""
    if not exact:
        g = 54 if frame.is_extended_id else 34
        return (g + 8 * _data_len(frame) - 1) // 4
    count = 0
    run = 0
    last = -1
    for b in _stuffed_region(frame):
        if b == last:
            run += 1
        else:
            last, run = b, 1
        if run == 5:
            count += 1
            last, run = 1 - b, 1  # the stuff bit is complementary and starts the next run
    return count


def frame_bits(frame: Any, stuffing: str = "worst") -> int:
    """Bits the frame occupies on the bus (intermission included) under a stuffing model of :data:`STUFFING`."""
    if stuffing == "none":
        return unstuffed_bits(frame)
    if stuffing == "worst":
        return unstuffed_bits(frame) + stuff_bits(frame)
    if stuffing == "exact":
        return unstuffed_bits(frame) + stuff_bits(frame, exact=True)
    raise ValueError(f"stuffing must be one of {STUFFING}, got {stuffing!r}")


def frame_time(frame: Any, bitrate: float, stuffing: str = "worst") -> float:
    """Seconds the frame occupies a bus of ``bitrate`` bit/s."""
    return frame_bits(frame, stuffing) / bitrate


@dataclass(frozen=True, slots=True)
class CycleLoad:
    """Bus load of one cyclic exchange (:func:`cycle_load`, :func:`canopen_cycle_load`; a serial bus's
    :func:`joints.transports.serial_timing.cycle_load`): bit times per cycle on a bus of ``bitrate``."""

    bits_best: int  #: bits per cycle without stuffing
    bits_worst: int  #: bits per cycle with the worst-case stuffing bound
    period: float  #: s
    bitrate: int

    @property
    def best(self) -> float:
        """Load without stuffing (1.0 = the whole period)."""
        return self.bits_best / (self.bitrate * self.period)

    @property
    def worst(self) -> float:
        """Load with worst-case stuffing: the bound a schedule must fit."""
        return self.bits_worst / (self.bitrate * self.period)

    @property
    def fits(self) -> bool:
        """Every frame of a cycle is on the wire within the period, whatever the stuffing."""
        return self.worst <= 1.0

    @property
    def max_rate(self) -> float:
        """The highest cycle rate [Hz] at which the cycle still fits (worst case)."""
        return self.bitrate / self.bits_worst if self.bits_worst else float("inf")


class _Frame:
    """A stand-in frame for the formulas (standard id, data frame of ``size`` bytes)."""

    def __init__(self, cob_id: int, size: int) -> None:
        self.arbitration_id = cob_id
        self.is_extended_id = False
        self.is_remote_frame = False
        self.data = bytes(size)
        self.dlc = size


def canopen_cycle_load(nodes: int | Sequence[int], *, rpdo_bytes: Sequence[int] = (6,),
                       tpdo_bytes: Sequence[int] = (6,), sync_period: float = 0.001, bitrate: int = 1_000_000,
                       sync_bytes: int = 0, extra_frames: Sequence[int] = ()) -> CycleLoad:
    """The bus load of a CANopen SYNC cycle and whether it fits (worst-case bit stuffing).

    Per cycle: one SYNC (``sync_bytes`` data: 0, or 1 with a counter), and for every node one frame
    per entry of ``rpdo_bytes`` (host -> node) and of ``tpdo_bytes`` (node -> host), each of that
    many data bytes (the PDO mapping's length); ``extra_frames`` adds other frames per cycle by
    data length. ``nodes``: a count or the node ids. eRunner's mapping (RPDO1 controlword + 32-bit
    target, TPDO1 statusword + position: 6 + 6 bytes) at 1 kHz on 1 Mbit/s: 3 nodes 62-75 %,
    4 nodes 81-98 %, 5 nodes 100-121 % (without - with worst-case stuffing).
    """
    ids = list(range(1, nodes + 1)) if isinstance(nodes, int) else list(nodes)
    frames = [_Frame(0x080, sync_bytes)]
    for node in ids:
        frames += [_Frame(0x200 + node, n) for n in rpdo_bytes]
        frames += [_Frame(0x180 + node, n) for n in tpdo_bytes]
    frames += [_Frame(0x7FF, n) for n in extra_frames]
    return cycle_load(frames, period=sync_period, bitrate=bitrate)


def cycle_load(frames: Sequence[Any | int], *, period: float, bitrate: int) -> CycleLoad:
    """The bus load of the ``frames`` sent every ``period`` s on a bus of ``bitrate`` bit/s, and whether
    they fit: python-can frames, or data lengths (standard-id data frames of that many bytes). The one
    capacity formula of the CAN buses: CANopen's SYNC cycle (:func:`canopen_cycle_load`), the eRob CAN
    protocol's request/reply pairs and ``joints bench``'s bus planner use it."""
    if period <= 0 or bitrate <= 0:
        raise ValueError("the period and the bitrate must be > 0")
    made = [_Frame(0x7FF, f) if isinstance(f, int) else f for f in frames]
    for f in made:
        if not f.is_remote_frame and not 0 <= len(f.data) <= 8:
            raise ValueError(f"a classic CAN frame carries 0..8 data bytes, got {len(f.data)}")
    return CycleLoad(sum(frame_bits(f, "none") for f in made), sum(frame_bits(f, "worst") for f in made),
                     period, bitrate)
