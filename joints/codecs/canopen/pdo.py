"""CANopen PDOs (A6): mapping entries, communication parameters, bit packing and the SDO writes that configure a PDO.

Rule: pure.
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

from joints.codecs.canopen.cob import Kind
from joints.errors import EncodeError, FrameError

__all__ = ["DUMMY_BITS", "MAX_PDO_BITS", "PDO_INVALID", "PDO_NO_RTR", "SYNC_PRODUCER", "PdoComm", "PdoMapEntry", "SdoWriteSpec", "pack_pdo", "pdo_configuration_writes", "pdo_disable_writes", "pdo_indices", "pdo_length", "unpack_pdo"]

# --- PDO ---------------------------------------------------------------------------------------------

PDO_INVALID = 1 << 31  #: COB-ID bit 31: PDO does not exist / is not valid
SYNC_PRODUCER = 1 << 30  #: 0x1005 bit 30: the node produces SYNC (CiA 301)
PDO_NO_RTR = 1 << 30  #: COB-ID bit 30: no RTR allowed on this PDO
MAX_PDO_BITS = 64

#: dummy mapping entries (CiA 301 7.4.7.1): data-type index -> bits; they fill a PDO with padding
DUMMY_BITS: Mapping[int, int] = {0x0001: 1, 0x0002: 8, 0x0003: 16, 0x0004: 32, 0x0005: 8, 0x0006: 16, 0x0007: 32}


class PdoMapEntry(NamedTuple):
    """One mapped object: index, subindex, length in bits, and whether its value is signed."""

    index: int  # type: ignore[assignment]  # the object index; shadows tuple.index (unused here)
    subindex: int
    bits: int
    signed: bool = False

    @property
    def value(self) -> int:
        """The mapping parameter value (0x1600.. / 0x1A00.. sub 1..8): index << 16 | subindex << 8 | bits."""
        return self.index << 16 | self.subindex << 8 | self.bits

    @classmethod
    def from_value(cls, value: int, signed: bool = False) -> PdoMapEntry:
        return cls(value >> 16 & 0xFFFF, value >> 8 & 0xFF, value & 0xFF, signed)

    @property
    def is_dummy(self) -> bool:
        return self.index in DUMMY_BITS and self.subindex == 0


@dataclass(frozen=True, slots=True)
class PdoComm:
    """PDO communication parameter (0x1400.. RPDO, 0x1800.. TPDO).

    ``transmission_type``: 0 synchronous acyclic, 1..240 every n-th SYNC, 252/253 RTR only,
    254/255 event-driven. ``inhibit_time`` in 100 us (TPDO only), ``event_timer`` in ms (TPDO:
    period of event transmission; RPDO: deadline). None leaves a field as it is on the node.
    """

    cob_id: int
    transmission_type: int = 255
    inhibit_time: int | None = None
    event_timer: int | None = None
    valid: bool = True
    rtr_allowed: bool = True

    @property
    def cob_id_value(self) -> int:
        """Value of sub-index 1 (bit 31 set = not valid, bit 30 set = no RTR)."""
        return self.cob_id | (0 if self.valid else PDO_INVALID) | (0 if self.rtr_allowed else PDO_NO_RTR)

    @classmethod
    def from_values(cls, cob_id_value: int, transmission_type: int = 255, inhibit_time: int | None = None,
                    event_timer: int | None = None) -> PdoComm:
        return cls(cob_id_value & 0x7FF, transmission_type, inhibit_time, event_timer,
                   not cob_id_value & PDO_INVALID, not cob_id_value & PDO_NO_RTR)


def pdo_length(entries: Iterable[tuple[int, int, int, bool]]) -> int:
    """Mapped length in bits (:class:`~joints.errors.EncodeError` above 64)."""
    bits = sum(e[2] for e in entries)
    if bits > MAX_PDO_BITS:
        raise EncodeError(f"PDO mapping of {bits} bits exceeds {MAX_PDO_BITS}")
    return bits


class _Layout(NamedTuple):
    """A mapping prepared once: per entry (index, subindex, lowest, highest value); its bits; a ``struct`` of the
    whole PDO where every entry is 8, 16, 32 or 64 bits (None: packed bit by bit)."""

    ranges: tuple[tuple[int, int, int, int], ...]
    bits: int
    fixed: struct.Struct | None


_FORMATS = {8: "b", 16: "h", 32: "i", 64: "q"}


@functools.lru_cache(maxsize=256)
def _layout(entries: tuple[tuple[int, int, int, bool], ...]) -> _Layout:
    ranges = tuple((index, subindex, *((-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)))
                   for index, subindex, bits, signed in entries)
    bits = sum(e[2] for e in entries)
    fixed = None
    if all(e[2] in _FORMATS for e in entries):
        fixed = struct.Struct("<" + "".join(_FORMATS[e[2]] if e[3] else _FORMATS[e[2]].upper() for e in entries))
    return _Layout(ranges, bits, fixed)


def pack_pdo(entries: Sequence[tuple[int, int, int, bool]], values: Sequence[int]) -> bytes:
    """PDO data from the values of its mapped objects, in mapping order (dummies take any value, e.g. 0)."""
    if len(entries) != len(values):
        raise EncodeError(f"PDO has {len(entries)} mapped objects, got {len(values)} values")
    layout = _layout(entries if isinstance(entries, tuple) else tuple(entries))
    for (index, subindex, lo, hi), value in zip(layout.ranges, values):
        if not lo <= value <= hi:
            raise EncodeError(f"PDO object 0x{index:04X}:{subindex:02X}: value {value} out of range [{lo}, {hi}]")
    if layout.bits > MAX_PDO_BITS:
        raise EncodeError(f"PDO mapping of {layout.bits} bits exceeds {MAX_PDO_BITS}")
    if layout.fixed is not None:
        try:
            return layout.fixed.pack(*values)
        except struct.error:
            pass  # not an integer: the bit by bit packing says what is wrong
    raw = 0
    offset = 0
    for (_index, _subindex, bits, _signed), value in zip(entries, values):
        raw |= (value & ((1 << bits) - 1)) << offset
        offset += bits
    return raw.to_bytes((offset + 7) // 8, "little")


def pdo_packer(entries: Sequence[tuple[int, int, int, bool]]) -> Callable[[Sequence[int]], bytes]:
    """:func:`pack_pdo` of ``entries`` prepared once, for values already within their entries' ranges (a twin's
    clamped sample): the layout's ``struct`` where it has one, else :func:`pack_pdo` itself (the same bytes)."""
    entries = entries if isinstance(entries, tuple) else tuple(entries)
    layout = _layout(entries)
    fixed = layout.fixed
    if fixed is None or layout.bits > MAX_PDO_BITS:
        return functools.partial(pack_pdo, entries)
    pack = fixed.pack
    count = len(entries)

    def packed(values: Sequence[int]) -> bytes:
        if len(values) == count:
            try:
                return pack(*values)
            except struct.error:
                pass
        return pack_pdo(entries, values)  # it says what is wrong

    return packed


def pdo_unpacker(entries: Sequence[tuple[int, int, int, bool]]) -> Callable[[bytes], tuple[int, ...]]:
    """:func:`unpack_pdo` of ``entries`` prepared once (the same values and errors): the layout's ``struct``
    where it has one, else :func:`unpack_pdo` itself."""
    entries = entries if isinstance(entries, tuple) else tuple(entries)
    layout = _layout(entries)
    fixed = layout.fixed
    if fixed is None or layout.bits > MAX_PDO_BITS:
        return functools.partial(unpack_pdo, entries)
    unpack_from, size = fixed.unpack_from, fixed.size

    def unpacked(data: bytes) -> tuple[int, ...]:
        if len(data) < size:
            return unpack_pdo(entries, data)  # it raises the FrameError
        return unpack_from(data)

    return unpacked


def unpack_pdo(entries: Sequence[tuple[int, int, int, bool]], data: bytes) -> tuple[int, ...]:
    """Values of the mapped objects in PDO ``data`` (FrameError if shorter than the mapping)."""
    layout = _layout(entries if isinstance(entries, tuple) else tuple(entries))
    bits = layout.bits
    if bits > MAX_PDO_BITS:
        raise EncodeError(f"PDO mapping of {bits} bits exceeds {MAX_PDO_BITS}")
    if len(data) * 8 < bits:
        raise FrameError(f"PDO of {len(data)} bytes, mapping needs {(bits + 7) // 8}", data=data)
    if layout.fixed is not None:
        return layout.fixed.unpack_from(data)
    raw = int.from_bytes(data, "little")
    out = []
    offset = 0
    for _index, _subindex, n, signed in entries:
        value = raw >> offset & ((1 << n) - 1)
        if signed and value >> (n - 1):
            value -= 1 << n
        out.append(value)
        offset += n
    return tuple(out)


def pdo_indices(kind: Kind) -> tuple[int, int]:
    """(communication parameter index, mapping parameter index) of a PDO, e.g. RPDO1 -> (0x1400, 0x1600)."""
    n = kind.pdo_number - 1
    return (0x1800 + n, 0x1A00 + n) if kind.name.startswith("T") else (0x1400 + n, 0x1600 + n)


#: one SDO write: (index, subindex, value, size in bytes)
SdoWriteSpec = tuple[int, int, int, int]


def pdo_configuration_writes(kind: Kind, comm: PdoComm,
                             entries: Sequence[tuple[int, int, int, bool]]) -> list[SdoWriteSpec]:
    """The SDO writes that configure a PDO (CiA 301 7.5.2.36 procedure), in order: disable it
    (COB-ID bit 31), communication parameters, mapping count 0, the entries, the count, and enable
    it again if ``comm.valid``. Only writes fields that are not None."""
    pdo_length(entries)
    if len(entries) > 8:
        raise EncodeError(f"a PDO maps at most 8 objects (CiA 301 allows 64; the eRob map has 8), got {len(entries)}")
    if not 0 <= comm.transmission_type <= 255:
        raise EncodeError(f"transmission type {comm.transmission_type} out of range [0, 255]")
    comm_index, map_index = pdo_indices(kind)
    writes: list[SdoWriteSpec] = [(comm_index, 1, comm.cob_id_value | PDO_INVALID, 4),
                                  (comm_index, 2, comm.transmission_type, 1)]
    if comm.inhibit_time is not None:
        writes.append((comm_index, 3, comm.inhibit_time, 2))
    if comm.event_timer is not None:
        writes.append((comm_index, 5, comm.event_timer, 2))
    writes.append((map_index, 0, 0, 1))
    writes.extend((map_index, i, PdoMapEntry(*e).value, 4) for i, e in enumerate(entries, 1))
    writes.append((map_index, 0, len(entries), 1))
    if comm.valid:
        writes.append((comm_index, 1, comm.cob_id_value, 4))
    return writes


def pdo_disable_writes(kind: Kind, cob_id: int) -> list[SdoWriteSpec]:
    """The SDO write that switches a PDO off (COB-ID with bit 31 set)."""
    return [(pdo_indices(kind)[0], 1, cob_id | PDO_INVALID, 4)]
