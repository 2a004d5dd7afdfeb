"""CANopen messages: one frozen class per service frame, and encode/decode between them and python-can frames.

Rule: pure. ``decode(frame)`` returns a message, ``encode(message)`` a frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import can

from joints.codecs.canopen.abort import abort_text
from joints.codecs.canopen.cob import (
    EMCY_BASE,
    ERROR_CONTROL_BASE,
    MAX_NODE,
    NMT_ID,
    SDO_RX_BASE,
    SDO_SEGMENT,
    SDO_TX_BASE,
    SYNC_ID,
    Kind,
    check_mux,
    check_node,
    classify,
)
from joints.codecs.canopen.emcy import emcy_class_text
from joints.codecs.canopen.nmt import NmtCommand, NmtState
from joints.errors import EncodeError, FrameError

__all__ = ["BootUp", "Emcy", "GuardRequest", "Heartbeat", "Message", "Nmt", "Other", "Pdo", "SdoAbort", "SdoDownloadInitiate", "SdoDownloadInitiateResponse", "SdoDownloadSegment", "SdoDownloadSegmentResponse", "SdoRequest", "SdoResponse", "SdoUnsupported", "SdoUploadInitiate", "SdoUploadInitiateResponse", "SdoUploadSegment", "SdoUploadSegmentRequest", "Sync", "decode", "encode"]

# --- messages ---------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Nmt:
    """NMT module control on COB-ID 0: ``node`` 0 addresses every node."""

    command: NmtCommand
    node: int


@dataclass(frozen=True, slots=True)
class BootUp:
    node: int


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """Heartbeat, or node-guarding reply (``toggle`` = bit 7; always False in a heartbeat)."""

    node: int
    state: NmtState
    toggle: bool = False


@dataclass(frozen=True, slots=True)
class GuardRequest:
    """Node-guarding remote frame from the master."""

    node: int


@dataclass(frozen=True, slots=True)
class Sync:
    counter: int | None = None  #: 1..240 when the SYNC carries a counter


@dataclass(frozen=True, slots=True)
class Emcy:
    node: int
    error_code: int  #: 0x0000 = error reset / no error
    error_register: int  #: object 0x1001
    manufacturer: bytes = bytes(5)

    @property
    def text(self) -> str:
        """CiA 301 class of the error code (the eRob's own meaning: devices.erob.faults)."""
        return emcy_class_text(self.error_code)


@dataclass(frozen=True, slots=True)
class Pdo:
    """A PDO as it came (unpack its data with :func:`unpack_pdo` and the mapping)."""

    cob_id: int
    data: bytes
    remote: bool = False  #: a remote transmission request for a TPDO


@dataclass(frozen=True, slots=True)
class Other:
    """A frame of a service this codec does not decode (TIME, LSS, foreign COB-IDs)."""

    cob_id: int
    data: bytes
    remote: bool = False
    extended: bool = False  #: a 29-bit identifier (not CANopen, which uses 11-bit ones: CiA 301 7.3.3)


# SDO, client -> server (COB-ID 0x600 + node)


@dataclass(frozen=True, slots=True)
class SdoDownloadInitiate:
    """Write request. Expedited: ``data`` holds the 1..4 bytes. Segmented: ``data`` is empty and
    ``size`` the total byte count (None if not indicated)."""

    node: int
    index: int
    subindex: int
    data: bytes = b""
    expedited: bool = True
    size: int | None = None


@dataclass(frozen=True, slots=True)
class SdoDownloadSegment:
    node: int
    toggle: bool
    data: bytes
    last: bool


@dataclass(frozen=True, slots=True)
class SdoUploadInitiate:
    """Read request."""

    node: int
    index: int
    subindex: int


@dataclass(frozen=True, slots=True)
class SdoUploadSegmentRequest:
    node: int
    toggle: bool


# SDO, server -> client (COB-ID 0x580 + node)


@dataclass(frozen=True, slots=True)
class SdoDownloadInitiateResponse:
    node: int
    index: int
    subindex: int


@dataclass(frozen=True, slots=True)
class SdoDownloadSegmentResponse:
    node: int
    toggle: bool


@dataclass(frozen=True, slots=True)
class SdoUploadInitiateResponse:
    """Read reply. Expedited: ``data`` holds the value bytes. Segmented: ``data`` is empty and
    ``size`` the byte count to follow (None if not indicated)."""

    node: int
    index: int
    subindex: int
    data: bytes = b""
    expedited: bool = True
    size: int | None = None


@dataclass(frozen=True, slots=True)
class SdoUploadSegment:
    node: int
    toggle: bool
    data: bytes
    last: bool


# SDO, both directions


@dataclass(frozen=True, slots=True)
class SdoAbort:
    node: int
    index: int
    subindex: int
    code: int
    from_client: bool  #: True: on 0x600+node (master aborts); False: on 0x580+node (node aborts)

    @property
    def text(self) -> str:
        return abort_text(self.code)


@dataclass(frozen=True, slots=True)
class SdoUnsupported:
    """An SDO frame of a service this codec does not implement (block transfer, unknown specifier)."""

    node: int
    command: int
    from_client: bool
    raw: bytes


SdoRequest = SdoDownloadInitiate | SdoDownloadSegment | SdoUploadInitiate | SdoUploadSegmentRequest
SdoResponse = (SdoDownloadInitiateResponse | SdoDownloadSegmentResponse | SdoUploadInitiateResponse
               | SdoUploadSegment)
Message = (Nmt | BootUp | Heartbeat | GuardRequest | Sync | Emcy | Pdo | Other | SdoRequest | SdoResponse
           | SdoAbort | SdoUnsupported)


def _frame(cob: int, data: bytes | bytearray = b"", *, remote: bool = False, dlc: int | None = None,
           extended: bool = False) -> can.Message:
    if remote:
        return can.Message(arbitration_id=cob, is_extended_id=extended, is_remote_frame=True,
                           dlc=0 if dlc is None else dlc)
    return can.Message(arbitration_id=cob, is_extended_id=extended, data=bytes(data))


def _sdo_frame(cob: int, command: int, index: int, subindex: int, tail: bytes) -> can.Message:
    return _frame(cob, bytes((command, index & 0xFF, index >> 8, subindex)) + tail.ljust(4, b"\x00"))


def _expedited_bits(data: bytes, size: int | None) -> int:
    """n, e, s bits of an initiate frame (bits 3..0)."""
    return 0x02 | (((4 - len(data)) << 2) | 0x01 if size is not None else 0)


def encode(message: Message) -> can.Message:
    """The frame of ``message`` (raises :class:`~joints.errors.EncodeError` on out-of-range fields)."""
    m = message
    if type(m) is Pdo and not m.remote and 0 <= m.cob_id <= 0x7FF and len(m.data) <= 8:  # the cyclic frames first
        return _frame(m.cob_id, m.data, extended=False)
    if type(m) is Sync and m.counter is None:
        return _frame(SYNC_ID)
    if isinstance(m, Nmt):
        check_node(m.node, broadcast=True)
        return _frame(NMT_ID, bytes((NmtCommand(m.command), m.node)))
    if isinstance(m, Heartbeat):
        check_node(m.node)
        return _frame(ERROR_CONTROL_BASE + m.node, bytes((NmtState(m.state) | (0x80 if m.toggle else 0),)))
    if isinstance(m, BootUp):
        check_node(m.node)
        return _frame(ERROR_CONTROL_BASE + m.node, b"\x00")
    if isinstance(m, GuardRequest):
        check_node(m.node)
        return _frame(ERROR_CONTROL_BASE + m.node, remote=True, dlc=1)
    if isinstance(m, Sync):
        if m.counter is None:
            return _frame(SYNC_ID)
        if not 1 <= m.counter <= 240:
            raise EncodeError(f"SYNC counter {m.counter} out of range [1, 240]")
        return _frame(SYNC_ID, bytes((m.counter,)))
    if isinstance(m, Emcy):
        check_node(m.node)
        if not 0 <= m.error_code <= 0xFFFF or not 0 <= m.error_register <= 0xFF or len(m.manufacturer) > 5:
            raise EncodeError(f"EMCY fields out of range: {m!r}")
        return _frame(EMCY_BASE + m.node, m.error_code.to_bytes(2, "little") + bytes((m.error_register,))
                      + m.manufacturer.ljust(5, b"\x00"))
    if isinstance(m, Pdo | Other):
        extended = isinstance(m, Other) and m.extended
        if not 0 <= m.cob_id <= (0x1FFFFFFF if extended else 0x7FF) or len(m.data) > 8:
            raise EncodeError(f"frame out of range: COB-ID 0x{m.cob_id:X}, {len(m.data)} bytes")
        if m.remote:
            return _frame(m.cob_id, remote=True, dlc=len(m.data), extended=extended)
        return _frame(m.cob_id, m.data, extended=extended)
    return _encode_sdo(m)


def _encode_sdo(m: SdoRequest | SdoResponse | SdoAbort | SdoUnsupported) -> can.Message:
    check_node(m.node)
    rx, tx = SDO_RX_BASE + m.node, SDO_TX_BASE + m.node
    if isinstance(m, SdoDownloadInitiate | SdoUploadInitiateResponse):
        check_mux(m.index, m.subindex)
        cob, base = (rx, 0x20) if isinstance(m, SdoDownloadInitiate) else (tx, 0x40)
        if m.expedited:
            if not 1 <= len(m.data) <= 4 or (m.size is not None and m.size != len(m.data)):
                raise EncodeError(f"expedited SDO carries 1..4 bytes (size = their count), got {m!r}")
            return _sdo_frame(cob, base | _expedited_bits(m.data, m.size), m.index, m.subindex, m.data)
        if m.data:
            raise EncodeError("a segmented SDO initiate carries no data (send it in segments)")
        if m.size is None:
            return _sdo_frame(cob, base, m.index, m.subindex, b"")
        if not 0 <= m.size <= 0xFFFFFFFF:
            raise EncodeError(f"SDO size {m.size} out of range")
        return _sdo_frame(cob, base | 0x01, m.index, m.subindex, m.size.to_bytes(4, "little"))
    if isinstance(m, SdoDownloadSegment | SdoUploadSegment):
        if len(m.data) > SDO_SEGMENT:
            raise EncodeError(f"SDO segment carries at most 7 bytes, got {len(m.data)}")
        cob = rx if isinstance(m, SdoDownloadSegment) else tx
        command = (0x10 if m.toggle else 0) | ((SDO_SEGMENT - len(m.data)) << 1) | (0x01 if m.last else 0)
        return _frame(cob, bytes((command,)) + m.data.ljust(SDO_SEGMENT, b"\x00"))
    if isinstance(m, SdoUploadInitiate):
        check_mux(m.index, m.subindex)
        return _sdo_frame(rx, 0x40, m.index, m.subindex, b"")
    if isinstance(m, SdoUploadSegmentRequest):
        return _frame(rx, bytes((0x60 | (0x10 if m.toggle else 0),)) + bytes(7))
    if isinstance(m, SdoDownloadInitiateResponse):
        check_mux(m.index, m.subindex)
        return _sdo_frame(tx, 0x60, m.index, m.subindex, b"")
    if isinstance(m, SdoDownloadSegmentResponse):
        return _frame(tx, bytes((0x20 | (0x10 if m.toggle else 0),)) + bytes(7))
    if isinstance(m, SdoAbort):
        check_mux(m.index, m.subindex)
        if not 0 <= m.code <= 0xFFFFFFFF:
            raise EncodeError(f"SDO abort code {m.code} out of range")
        return _sdo_frame(rx if m.from_client else tx, 0x80, m.index, m.subindex, m.code.to_bytes(4, "little"))
    if isinstance(m, SdoUnsupported):
        if len(m.raw) != 8:
            raise EncodeError("an unsupported SDO frame is kept as its 8 raw bytes")
        return _frame(rx if m.from_client else tx, m.raw)
    raise EncodeError(f"not a CANopen message: {m!r}")


def decode(frame: can.Message) -> Message:
    """The message in ``frame``; :class:`~joints.errors.FrameError` if it is malformed for its service."""
    data = bytes(frame.data)
    if frame.dlc > 8 or len(data) > 8:
        raise FrameError(f"CAN frame 0x{frame.arbitration_id:X} with {max(frame.dlc, len(data))} data bytes "
                         "(a classic CAN frame carries at most 8)", data=data)
    kind, node = classify(frame)
    if frame.is_remote_frame and kind is not Kind.GUARD_REQUEST:
        if kind.is_pdo:
            return Pdo(frame.arbitration_id, bytes(frame.dlc), remote=True)
        if kind is Kind.UNKNOWN or kind is Kind.TIME:
            return Other(frame.arbitration_id, bytes(frame.dlc), remote=True, extended=frame.is_extended_id)
        raise FrameError(f"remote frame on {kind.value} COB-ID 0x{frame.arbitration_id:X}")
    if kind.is_pdo:
        return Pdo(frame.arbitration_id, data)
    if kind is Kind.SDO_RX or kind is Kind.SDO_TX:
        return _decode_sdo(node, data, from_client=kind is Kind.SDO_RX)
    if kind is Kind.HEARTBEAT or kind is Kind.BOOT_UP:
        if len(data) != 1:
            raise FrameError(f"heartbeat of node {node} with {len(data)} bytes (expected 1)", data=data)
        if data[0] == 0:
            return BootUp(node)
        try:
            state = NmtState(data[0] & 0x7F)
        except ValueError:
            raise FrameError(f"heartbeat of node {node}: unknown NMT state 0x{data[0] & 0x7F:02X}",
                             data=data) from None
        return Heartbeat(node, state, bool(data[0] & 0x80))
    if kind is Kind.GUARD_REQUEST:
        return GuardRequest(node)
    if kind is Kind.NMT:
        if len(data) != 2:
            raise FrameError(f"NMT frame with {len(data)} bytes (expected 2)", data=data)
        try:
            command = NmtCommand(data[0])
        except ValueError:
            raise FrameError(f"unknown NMT command specifier 0x{data[0]:02X}", data=data) from None
        if data[1] > MAX_NODE:
            raise FrameError(f"NMT for node {data[1]} (node ids are 0..127)", data=data)
        return Nmt(command, data[1])
    if kind is Kind.SYNC:
        if not data:
            return Sync()
        if len(data) != 1 or not 1 <= data[0] <= 240:
            raise FrameError(f"SYNC with data {data.hex(' ')} (expected none or a counter 1..240)", data=data)
        return Sync(data[0])
    if kind is Kind.EMCY:
        if len(data) < 3:
            raise FrameError(f"EMCY of node {node} with {len(data)} bytes (expected 8)", data=data)
        return Emcy(node, int.from_bytes(data[:2], "little"), data[2], data[3:].ljust(5, b"\x00"))
    return Other(frame.arbitration_id, data, extended=frame.is_extended_id)


def _decode_sdo(node: int, data: bytes, *, from_client: bool) -> Message:
    if len(data) != 8:
        raise FrameError(f"SDO frame of node {node} with {len(data)} bytes (expected 8)", data=data)
    command = data[0]
    cs = command >> 5
    index = data[1] | data[2] << 8
    subindex = data[3]
    if cs == 4:
        return SdoAbort(node, index, subindex, int.from_bytes(data[4:], "little"), from_client)
    if from_client:
        if cs == 1:
            return _decode_initiate(SdoDownloadInitiate, node, index, subindex, command, data)
        if cs == 0:
            return SdoDownloadSegment(node, bool(command & 0x10), data[1:8 - ((command >> 1) & 7)],
                                      bool(command & 0x01))
        if cs == 2:
            return SdoUploadInitiate(node, index, subindex)
        if cs == 3:
            return SdoUploadSegmentRequest(node, bool(command & 0x10))
    else:
        if cs == 3:
            return SdoDownloadInitiateResponse(node, index, subindex)
        if cs == 1:
            return SdoDownloadSegmentResponse(node, bool(command & 0x10))
        if cs == 2:
            return _decode_initiate(SdoUploadInitiateResponse, node, index, subindex, command, data)
        if cs == 0:
            return SdoUploadSegment(node, bool(command & 0x10), data[1:8 - ((command >> 1) & 7)],
                                    bool(command & 0x01))
    return SdoUnsupported(node, command, from_client, data)


def _decode_initiate(cls: type[SdoDownloadInitiate | SdoUploadInitiateResponse], node: int, index: int,
                     subindex: int, command: int, data: bytes) -> SdoDownloadInitiate | SdoUploadInitiateResponse:
    expedited, sized = bool(command & 0x02), bool(command & 0x01)
    if expedited:
        if sized:
            value = data[4:8 - ((command >> 2) & 3)]
            return cls(node, index, subindex, value, True, len(value))
        return cls(node, index, subindex, data[4:8], True, None)
    return cls(node, index, subindex, b"", False, int.from_bytes(data[4:], "little") if sized else None)
