"""CANopen (CiA 301) codec over python-can frames, sans-I/O, for both sides (master and node).

Rule: pure. Frames are :class:`can.Message` (python-can's frame class; this module is imported only
when a CAN bus is used). ``decode(frame)`` returns a frozen message, ``encode(message)`` a frame;
:func:`classify` says which service a frame belongs to and which node, so a link can route frames
nobody asked for (heartbeats, EMCY, TPDOs) without decoding them. The SDO client and server are
state machines: feed a frame, get the next frame to send or the result. Nothing here reads a clock:
heartbeat and guarding periods, SDO timeouts, event timers and SYNC periods belong to the link or
the twin, which call :meth:`SdoClient.abort` on a timeout.

Source: the eRunner manual v1.7 chapter 5 (NMT stop/reset communication, boot-up on 0x700+node,
expedited SDO on 0x600/0x580+node, COB-ID SYNC 0x1005 = 0x80, communication cycle 0x1006, RPDO1
on 0x200+node, node guarding by remote frames: chapter 6 item 3 "eRunner涉及报文除心跳检测均为数据帧").
Chapter 5 shows only those services; everything else follows CiA 301 v4.2 and is listed here as an
assumption to confirm on a real eRob:

* A1 COB-IDs follow the CiA 301 pre-defined connection set (:func:`classify`); a PDO moved to
  another COB-ID must be routed by the link's own table.
* A2 Node guarding: master sends a remote frame on 0x700+node (DLC 1); the node answers one byte,
  bit 7 a toggle that starts at 0 after NMT reset communication and alternates, bits 6..0 the NMT
  state. A guarding reply has the heartbeat's COB-ID and layout, so :func:`decode` returns
  :class:`Heartbeat` for both (``toggle`` set from bit 7); :class:`GuardingMaster` checks the toggle.
  COB-IDs 0x7E4/0x7E5 (LSS) are classified as the heartbeats of nodes 100/101 (LSS is not used).
* A3 SDO: expedited and segmented transfers only. Block transfer (client command specifiers 5 and
  6) is not implemented: :class:`SdoServer` answers it with abort 0x05040001, :class:`SdoClient`
  never starts one. An expedited transfer without size indication carries 4 data bytes.
  Reserved bytes are ignored on decode and sent as 0; SDO frames must carry 8 data bytes.
* A4 EMCY: 8 bytes (error code LE16, error register 0x1001, 5 manufacturer bytes); shorter frames
  of at least 3 bytes are accepted (missing manufacturer bytes read as 0) because drives differ. Error
  code 0x0000 is "error reset / no error". The eRob's own code meanings belong to
  :mod:`joints.devices.erob.faults`; :func:`emcy_class_text` gives the CiA 301 class only.
* A5 SYNC: DLC 0, or DLC 1 with a counter 1..240 (CiA 301 7.2.5). TIME is classified, not decoded.
* A6 PDO: at most 64 mapped bits, little-endian bit packing in mapping order. A received PDO
  longer than its mapping is accepted (extra bytes ignored); a shorter one is a
  :class:`~joints.errors.FrameError` (CiA 301: "not processed", EMCY 0x8210).
* A7 NMT: the node state machine of CiA 301 7.3.2.2 (:func:`nmt_transition`); after a reset the
  node sends its boot-up (state 0) and is then PRE-OPERATIONAL. Services per state:
  :data:`SERVICES_BY_STATE`.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import can

from joints.errors import DeviceRejected, EncodeError, FrameError, JointsError, ProtocolError, UnexpectedReply

__all__ = [
    "ABORT_TEXT",
    "AFTER_BOOT_UP",
    "ERROR_REGISTER_BITS",
    "SERVICES_BY_STATE",
    "BootUp",
    "Emcy",
    "GuardRequest",
    "GuardingMaster",
    "GuardingSlave",
    "Heartbeat",
    "Kind",
    "Message",
    "Nmt",
    "NmtCommand",
    "NmtState",
    "Other",
    "Pdo",
    "PdoComm",
    "PdoMapEntry",
    "Route",
    "SdoAbort",
    "SdoAbortCode",
    "SdoClient",
    "SdoDone",
    "SdoDownloadInitiate",
    "SdoDownloadInitiateResponse",
    "SdoDownloadSegment",
    "SdoDownloadSegmentResponse",
    "SdoFailed",
    "SdoSend",
    "SdoServer",
    "SdoStep",
    "SdoUnsupported",
    "SdoUploadInitiate",
    "SdoUploadInitiateResponse",
    "SdoUploadSegment",
    "SdoUploadSegmentRequest",
    "Sync",
    "abort_error",
    "abort_text",
    "classify",
    "decode",
    "emcy_class_text",
    "encode",
    "nmt_transition",
    "pack_pdo",
    "pdo_cob_id",
    "pdo_configuration_writes",
    "pdo_disable_writes",
    "pdo_indices",
    "pdo_length",
    "unpack_pdo",
]

MAX_NODE = 127
SDO_SEGMENT = 7  #: data bytes per SDO segment

NMT_ID = 0x000
SYNC_ID = 0x080
EMCY_BASE = 0x080
TIME_ID = 0x100
SDO_TX_BASE = 0x580  #: server -> client (replies)
SDO_RX_BASE = 0x600  #: client -> server (requests)
ERROR_CONTROL_BASE = 0x700  #: boot-up, heartbeat, node guarding
TPDO_BASE = (0x180, 0x280, 0x380, 0x480)
RPDO_BASE = (0x200, 0x300, 0x400, 0x500)


# --- classification --------------------------------------------------------------------------


class Kind(enum.Enum):
    """Service of a frame in the pre-defined connection set (CiA 301 7.3.5)."""

    NMT = "NMT"
    SYNC = "SYNC"
    EMCY = "EMCY"
    TIME = "TIME"
    TPDO1 = "TPDO1"
    TPDO2 = "TPDO2"
    TPDO3 = "TPDO3"
    TPDO4 = "TPDO4"
    RPDO1 = "RPDO1"
    RPDO2 = "RPDO2"
    RPDO3 = "RPDO3"
    RPDO4 = "RPDO4"
    SDO_TX = "SDO tx"  #: node (server) -> master (client): replies
    SDO_RX = "SDO rx"  #: master (client) -> node (server): requests
    BOOT_UP = "boot-up"
    HEARTBEAT = "heartbeat"  #: heartbeat or node-guarding reply (same COB-ID and layout)
    GUARD_REQUEST = "guard request"  #: remote frame on 0x700+node
    UNKNOWN = "unknown"

    @property
    def is_pdo(self) -> bool:
        return self in _PDO_NUMBER

    @property
    def pdo_number(self) -> int:
        """1..4 for a PDO kind (ValueError otherwise)."""
        try:
            return _PDO_NUMBER[self]
        except KeyError:
            raise ValueError(f"{self.value} is not a PDO") from None


_PDO_NUMBER = {Kind.TPDO1: 1, Kind.TPDO2: 2, Kind.TPDO3: 3, Kind.TPDO4: 4,
               Kind.RPDO1: 1, Kind.RPDO2: 2, Kind.RPDO3: 3, Kind.RPDO4: 4}

#: function code (COB-ID >> 7) -> kind, for node ids 1..127
_BY_FUNCTION: tuple[Kind, ...] = (
    Kind.UNKNOWN, Kind.EMCY, Kind.UNKNOWN, Kind.TPDO1, Kind.RPDO1, Kind.TPDO2, Kind.RPDO2, Kind.TPDO3,
    Kind.RPDO3, Kind.TPDO4, Kind.RPDO4, Kind.SDO_TX, Kind.SDO_RX, Kind.UNKNOWN, Kind.HEARTBEAT, Kind.UNKNOWN,
)


class Route(NamedTuple):
    kind: Kind
    node: int  #: 1..127; 0 for NMT, SYNC, TIME and unknown frames


def classify(frame: can.Message) -> Route:
    """Which service ``frame`` belongs to, and which node (never raises)."""
    cob = frame.arbitration_id
    if frame.is_extended_id or cob > 0x7FF:
        return Route(Kind.UNKNOWN, 0)
    node = cob & 0x7F
    if node == 0:
        if cob == NMT_ID:
            return Route(Kind.NMT, 0)
        if cob == SYNC_ID:
            return Route(Kind.SYNC, 0)
        if cob == TIME_ID:
            return Route(Kind.TIME, 0)
        return Route(Kind.UNKNOWN, 0)
    kind = _BY_FUNCTION[cob >> 7]
    if kind is Kind.HEARTBEAT:
        if frame.is_remote_frame:
            return Route(Kind.GUARD_REQUEST, node)
        if frame.dlc == 1 and frame.data[0] == 0:
            return Route(Kind.BOOT_UP, node)
    elif kind is Kind.UNKNOWN:
        return Route(Kind.UNKNOWN, 0)
    return Route(kind, node)


def pdo_cob_id(kind: Kind, node: int) -> int:
    """Pre-defined COB-ID of a PDO of ``node`` (e.g. RPDO1 of node 2 -> 0x202)."""
    _check_node(node)
    n = kind.pdo_number
    return (TPDO_BASE if kind.name.startswith("T") else RPDO_BASE)[n - 1] + node


# --- NMT -------------------------------------------------------------------------------------


class NmtCommand(enum.IntEnum):
    """NMT command specifiers (CiA 301 7.2.8.3.1)."""

    START = 0x01  #: start remote node -> OPERATIONAL
    STOP = 0x02  #: stop remote node -> STOPPED
    ENTER_PRE_OPERATIONAL = 0x80
    RESET_NODE = 0x81
    RESET_COMMUNICATION = 0x82


class NmtState(enum.IntEnum):
    """NMT states as a node reports them in heartbeats and guarding replies (bits 6..0)."""

    INITIALISING = 0x00  #: boot-up message
    STOPPED = 0x04
    OPERATIONAL = 0x05
    PRE_OPERATIONAL = 0x7F


def nmt_transition(state: NmtState, command: NmtCommand) -> NmtState:
    """The state a node enters on ``command`` (reset -> INITIALISING; it then sends its boot-up and
    goes to PRE-OPERATIONAL by itself, see :data:`AFTER_BOOT_UP`)."""
    if command is NmtCommand.START:
        return NmtState.OPERATIONAL
    if command is NmtCommand.STOP:
        return NmtState.STOPPED
    if command is NmtCommand.ENTER_PRE_OPERATIONAL:
        return NmtState.PRE_OPERATIONAL
    return NmtState.INITIALISING


AFTER_BOOT_UP = NmtState.PRE_OPERATIONAL

_ALWAYS = frozenset({Kind.NMT, Kind.HEARTBEAT, Kind.BOOT_UP, Kind.GUARD_REQUEST})
_PDOS = frozenset(k for k in Kind if k.is_pdo)
_PRE_OP = _ALWAYS | {Kind.SDO_RX, Kind.SDO_TX, Kind.SYNC, Kind.EMCY, Kind.TIME}

#: services a node takes part in, per NMT state (CiA 301 7.3.2.2, table 79)
SERVICES_BY_STATE: Mapping[NmtState, frozenset[Kind]] = {
    NmtState.INITIALISING: frozenset({Kind.BOOT_UP}),
    NmtState.PRE_OPERATIONAL: _PRE_OP,
    NmtState.OPERATIONAL: _PRE_OP | _PDOS,
    NmtState.STOPPED: _ALWAYS,
}


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


# --- SDO abort codes ---------------------------------------------------------------------------


class SdoAbortCode(enum.IntEnum):
    """SDO abort codes (CiA 301 v4.2, 7.2.4.3.17)."""

    TOGGLE_BIT_NOT_ALTERNATED = 0x05030000
    TIMEOUT = 0x05040000
    COMMAND_SPECIFIER_INVALID = 0x05040001
    INVALID_BLOCK_SIZE = 0x05040002
    INVALID_SEQUENCE_NUMBER = 0x05040003
    CRC_ERROR = 0x05040004
    OUT_OF_MEMORY = 0x05040005
    UNSUPPORTED_ACCESS = 0x06010000
    READ_WRITE_ONLY = 0x06010001
    WRITE_READ_ONLY = 0x06010002
    OBJECT_DOES_NOT_EXIST = 0x06020000
    CANNOT_BE_MAPPED = 0x06040041
    PDO_LENGTH_EXCEEDED = 0x06040042
    PARAMETER_INCOMPATIBLE = 0x06040043
    INTERNAL_INCOMPATIBILITY = 0x06040047
    HARDWARE_ERROR = 0x06060000
    LENGTH_MISMATCH = 0x06070010
    LENGTH_TOO_HIGH = 0x06070012
    LENGTH_TOO_LOW = 0x06070013
    SUBINDEX_DOES_NOT_EXIST = 0x06090011
    INVALID_VALUE = 0x06090030
    VALUE_TOO_HIGH = 0x06090031
    VALUE_TOO_LOW = 0x06090032
    MAX_LESS_THAN_MIN = 0x06090036
    RESOURCE_NOT_AVAILABLE = 0x060A0023
    GENERAL_ERROR = 0x08000000
    CANNOT_STORE = 0x08000020
    CANNOT_STORE_LOCAL_CONTROL = 0x08000021
    CANNOT_STORE_DEVICE_STATE = 0x08000022
    NO_OBJECT_DICTIONARY = 0x08000023
    NO_DATA_AVAILABLE = 0x08000024


#: abort code -> its meaning (CiA 301 v4.2 table 22, our wording)
ABORT_TEXT: Mapping[int, str] = {
    SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED: "toggle bit not alternated",
    SdoAbortCode.TIMEOUT: "SDO protocol timed out",
    SdoAbortCode.COMMAND_SPECIFIER_INVALID: "client/server command specifier not valid or unknown",
    SdoAbortCode.INVALID_BLOCK_SIZE: "invalid block size (block mode only)",
    SdoAbortCode.INVALID_SEQUENCE_NUMBER: "invalid sequence number (block mode only)",
    SdoAbortCode.CRC_ERROR: "CRC error (block mode only)",
    SdoAbortCode.OUT_OF_MEMORY: "out of memory",
    SdoAbortCode.UNSUPPORTED_ACCESS: "unsupported access to an object",
    SdoAbortCode.READ_WRITE_ONLY: "attempt to read a write-only object",
    SdoAbortCode.WRITE_READ_ONLY: "attempt to write a read-only object",
    SdoAbortCode.OBJECT_DOES_NOT_EXIST: "object does not exist in the object dictionary",
    SdoAbortCode.CANNOT_BE_MAPPED: "object cannot be mapped to the PDO",
    SdoAbortCode.PDO_LENGTH_EXCEEDED: "the number and length of the objects to be mapped would exceed the PDO length",
    SdoAbortCode.PARAMETER_INCOMPATIBLE: "general parameter incompatibility",
    SdoAbortCode.INTERNAL_INCOMPATIBILITY: "general internal incompatibility in the device",
    SdoAbortCode.HARDWARE_ERROR: "access failed due to a hardware error",
    SdoAbortCode.LENGTH_MISMATCH: "data type does not match, length of service parameter does not match",
    SdoAbortCode.LENGTH_TOO_HIGH: "data type does not match, length of service parameter too high",
    SdoAbortCode.LENGTH_TOO_LOW: "data type does not match, length of service parameter too low",
    SdoAbortCode.SUBINDEX_DOES_NOT_EXIST: "sub-index does not exist",
    SdoAbortCode.INVALID_VALUE: "invalid value for parameter (download only)",
    SdoAbortCode.VALUE_TOO_HIGH: "value of parameter written too high (download only)",
    SdoAbortCode.VALUE_TOO_LOW: "value of parameter written too low (download only)",
    SdoAbortCode.MAX_LESS_THAN_MIN: "maximum value is less than minimum value",
    SdoAbortCode.RESOURCE_NOT_AVAILABLE: "resource not available: SDO connection",
    SdoAbortCode.GENERAL_ERROR: "general error",
    SdoAbortCode.CANNOT_STORE: "data cannot be transferred or stored to the application",
    SdoAbortCode.CANNOT_STORE_LOCAL_CONTROL:
        "data cannot be transferred or stored to the application because of local control",
    SdoAbortCode.CANNOT_STORE_DEVICE_STATE:
        "data cannot be transferred or stored to the application because of the present device state",
    SdoAbortCode.NO_OBJECT_DICTIONARY:
        "object dictionary dynamic generation failed or no object dictionary is present",
    SdoAbortCode.NO_DATA_AVAILABLE: "no data available",
}


def abort_text(code: int) -> str:
    return ABORT_TEXT.get(code, "abort code not defined by CiA 301 (manufacturer specific?)")


def abort_error(node: int, index: int, subindex: int, code: int) -> DeviceRejected:
    """The error for an abort received from node ``node`` (code = the abort code)."""
    return DeviceRejected(f"node {node}: SDO 0x{index:04X}:{subindex:02X} aborted with 0x{code:08X} "
                          f"({abort_text(code)})", code=code)


# --- EMCY ----------------------------------------------------------------------------------------

#: CiA 301 table 21 (emergency error code classes) and the CiA 402 additions most drives use.
_EMCY_CLASSES: tuple[tuple[int, int, str], ...] = (
    (0xFFFF, 0x0000, "error reset or no error"),
    (0xFFFF, 0x8110, "CAN overrun (objects lost)"),
    (0xFFFF, 0x8120, "CAN in error passive mode"),
    (0xFFFF, 0x8130, "life guard error or heartbeat error"),
    (0xFFFF, 0x8140, "recovered from bus off"),
    (0xFFFF, 0x8150, "CAN-ID collision"),
    (0xFFFF, 0x8210, "PDO not processed due to length error"),
    (0xFFFF, 0x8220, "PDO length exceeded"),
    (0xFFFF, 0x8240, "unexpected SYNC data length"),
    (0xFFFF, 0x8250, "RPDO timeout"),
    (0xFFFF, 0x8611, "following error"),
    (0xFFFF, 0x8612, "reference limit"),
    (0xFFFF, 0x7121, "motor blocked"),
    (0xFFFF, 0x2310, "continuous over current"),
    (0xFFFF, 0x3210, "DC link over-voltage"),
    (0xFFFF, 0x3220, "DC link under-voltage"),
    (0xFFFF, 0x4310, "drive temperature too high"),
    (0xFF00, 0x8100, "communication"),
    (0xFF00, 0x8200, "protocol error"),
    (0xFF00, 0x8400, "velocity speed controller"),
    (0xFF00, 0x8600, "positioning controller"),
    (0xFF00, 0x2100, "current, device input side"),
    (0xFF00, 0x2200, "current inside the device"),
    (0xFF00, 0x2300, "current, device output side"),
    (0xFF00, 0x3100, "mains voltage"),
    (0xFF00, 0x3200, "voltage inside the device"),
    (0xFF00, 0x3300, "output voltage"),
    (0xFF00, 0x4100, "ambient temperature"),
    (0xFF00, 0x4200, "device temperature"),
    (0xFF00, 0x4300, "drive temperature"),
    (0xFF00, 0x6100, "internal software"),
    (0xFF00, 0x6200, "user software"),
    (0xFF00, 0x6300, "data set"),
    (0xFF00, 0x7100, "motor"),
    (0xFF00, 0x7300, "sensor"),
    (0xFF00, 0xFF00, "device specific"),
    (0xF000, 0x1000, "generic error"),
    (0xF000, 0x2000, "current"),
    (0xF000, 0x3000, "voltage"),
    (0xF000, 0x4000, "temperature"),
    (0xF000, 0x5000, "device hardware"),
    (0xF000, 0x6000, "device software"),
    (0xF000, 0x7000, "additional modules"),
    (0xF000, 0x8000, "monitoring"),
    (0xF000, 0x9000, "external error"),
    (0xF000, 0xF000, "additional functions"),
)

#: error register (0x1001) bits, CiA 301 7.5.2.2
ERROR_REGISTER_BITS: Mapping[int, str] = {
    0: "generic error", 1: "current", 2: "voltage", 3: "temperature", 4: "communication error",
    5: "device profile specific", 6: "reserved", 7: "manufacturer specific",
}


def emcy_class_text(code: int) -> str:
    """The most specific CiA 301/402 class of an EMCY error code."""
    for mask, value, text in _EMCY_CLASSES:
        if code & mask == value:
            return text
    return "unknown error class"


# --- encode / decode -------------------------------------------------------------------------------


def _check_node(node: int, *, broadcast: bool = False) -> None:
    lo = 0 if broadcast else 1
    if not lo <= node <= MAX_NODE:
        raise EncodeError(f"CANopen node id {node} out of range [{lo}, {MAX_NODE}]")


def _check_mux(index: int, subindex: int) -> None:
    if not 0 <= index <= 0xFFFF or not 0 <= subindex <= 0xFF:
        raise EncodeError(f"object 0x{index:X}:{subindex:X} out of range (index 16 bits, subindex 8 bits)")


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
    if isinstance(m, Nmt):
        _check_node(m.node, broadcast=True)
        return _frame(NMT_ID, bytes((NmtCommand(m.command), m.node)))
    if isinstance(m, Heartbeat):
        _check_node(m.node)
        return _frame(ERROR_CONTROL_BASE + m.node, bytes((NmtState(m.state) | (0x80 if m.toggle else 0),)))
    if isinstance(m, BootUp):
        _check_node(m.node)
        return _frame(ERROR_CONTROL_BASE + m.node, b"\x00")
    if isinstance(m, GuardRequest):
        _check_node(m.node)
        return _frame(ERROR_CONTROL_BASE + m.node, remote=True, dlc=1)
    if isinstance(m, Sync):
        if m.counter is None:
            return _frame(SYNC_ID)
        if not 1 <= m.counter <= 240:
            raise EncodeError(f"SYNC counter {m.counter} out of range [1, 240]")
        return _frame(SYNC_ID, bytes((m.counter,)))
    if isinstance(m, Emcy):
        _check_node(m.node)
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
    _check_node(m.node)
    rx, tx = SDO_RX_BASE + m.node, SDO_TX_BASE + m.node
    if isinstance(m, SdoDownloadInitiate | SdoUploadInitiateResponse):
        _check_mux(m.index, m.subindex)
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
        _check_mux(m.index, m.subindex)
        return _sdo_frame(rx, 0x40, m.index, m.subindex, b"")
    if isinstance(m, SdoUploadSegmentRequest):
        return _frame(rx, bytes((0x60 | (0x10 if m.toggle else 0),)) + bytes(7))
    if isinstance(m, SdoDownloadInitiateResponse):
        _check_mux(m.index, m.subindex)
        return _sdo_frame(tx, 0x60, m.index, m.subindex, b"")
    if isinstance(m, SdoDownloadSegmentResponse):
        return _frame(tx, bytes((0x20 | (0x10 if m.toggle else 0),)) + bytes(7))
    if isinstance(m, SdoAbort):
        _check_mux(m.index, m.subindex)
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


# --- node guarding --------------------------------------------------------------------------------


class GuardingSlave:
    """Node side of node guarding: the reply to each :class:`GuardRequest`, toggling bit 7."""

    def __init__(self, node: int) -> None:
        _check_node(node)
        self.node = node
        self._toggle = False

    def reset(self) -> None:
        """NMT reset communication: the next reply has toggle 0 again."""
        self._toggle = False

    def reply(self, state: NmtState) -> can.Message:
        frame = encode(Heartbeat(self.node, state, self._toggle))
        self._toggle = not self._toggle
        return frame


class GuardingMaster:
    """Master side of node guarding: the request frame, and the check of each reply's toggle bit."""

    def __init__(self, node: int) -> None:
        _check_node(node)
        self.node = node
        self._expect = False

    def reset(self) -> None:
        """After NMT reset communication of the node (its toggle restarts at 0)."""
        self._expect = False

    def request(self) -> can.Message:
        return encode(GuardRequest(self.node))

    def check(self, reply: Heartbeat) -> NmtState:
        """The node's state from a guarding reply; :class:`~joints.errors.UnexpectedReply` if the toggle
        bit did not alternate (CiA 301: the master then treats the node as lost)."""
        if reply.node != self.node:
            raise UnexpectedReply(f"guarding reply of node {reply.node}, expected node {self.node}")
        if reply.toggle != self._expect:
            raise UnexpectedReply(f"node {self.node}: guarding toggle bit {int(reply.toggle)}, "
                                  f"expected {int(self._expect)}")
        self._expect = not self._expect
        return reply.state


# --- SDO client and server ----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SdoSend:
    """Send ``frame``, then feed the reply."""

    frame: can.Message


@dataclass(frozen=True, slots=True)
class SdoDone:
    """The transfer finished: ``data`` is the uploaded value (empty for a download)."""

    data: bytes = b""


@dataclass(frozen=True, slots=True)
class SdoFailed:
    """The transfer ended with ``error``: send ``frame`` (our abort) if set, then raise ``error``.

    ``error`` is :class:`~joints.errors.DeviceRejected` (code = abort code) when the node aborted,
    a :class:`~joints.errors.PeerProtocolError` when its reply broke the protocol.
    """

    error: ProtocolError
    frame: can.Message | None = None


SdoStep = SdoSend | SdoDone | SdoFailed

_IDLE, _DOWNLOAD, _DOWNLOAD_SEGMENTS, _UPLOAD, _UPLOAD_SEGMENTS = range(5)


class SdoClient:
    """Master side of one node's SDO channel (expedited and segmented transfers).

    ``upload``/``download`` return the first frame to send; :meth:`feed` takes each reply (frames
    on 0x580+node) and returns what to do next. One transfer at a time.
    """

    def __init__(self, node: int) -> None:
        _check_node(node)
        self.node = node
        self.tx_cob_id = SDO_TX_BASE + node  #: where replies come from
        self._state = _IDLE
        self._index = 0
        self._subindex = 0
        self._toggle = False
        self._data = b""  #: download: what remains to send; upload: what came so far
        self._size: int | None = None
        self._last_sent = False

    @property
    def busy(self) -> bool:
        return self._state != _IDLE

    def _start(self, index: int, subindex: int) -> None:
        if self.busy:
            raise ProtocolError(f"node {self.node}: an SDO transfer on 0x{self._index:04X}:{self._subindex:02X} "
                                "is still running (one transfer at a time)")
        _check_mux(index, subindex)
        self._index, self._subindex, self._toggle = index, subindex, False

    def upload(self, index: int, subindex: int) -> can.Message:
        """Start reading ``index:subindex``."""
        self._start(index, subindex)
        self._state, self._data, self._size = _UPLOAD, b"", None
        return encode(SdoUploadInitiate(self.node, index, subindex))

    def download(self, index: int, subindex: int, data: bytes, *, segmented: bool = False) -> can.Message:
        """Start writing ``data`` to ``index:subindex`` (expedited when it fits in 4 bytes)."""
        if not data:
            raise EncodeError("an SDO download needs at least one byte")
        self._start(index, subindex)
        self._state = _DOWNLOAD
        if len(data) <= 4 and not segmented:
            self._data = b""
            return encode(SdoDownloadInitiate(self.node, index, subindex, bytes(data), True, len(data)))
        self._data = bytes(data)
        return encode(SdoDownloadInitiate(self.node, index, subindex, b"", False, len(data)))

    def abort(self, code: int = SdoAbortCode.TIMEOUT) -> can.Message | None:
        """End the running transfer (e.g. on a timeout): the abort frame to send, or None if idle."""
        if not self.busy:
            return None
        self._state = _IDLE
        return encode(SdoAbort(self.node, self._index, self._subindex, code, True))

    def _fail(self, error: ProtocolError, code: int | None) -> SdoFailed:
        frame = None
        if code is not None:
            frame = encode(SdoAbort(self.node, self._index, self._subindex, code, True))
        self._state = _IDLE
        return SdoFailed(error, frame)

    def _protocol_error(self, text: str, code: int) -> SdoFailed:
        return self._fail(UnexpectedReply(f"node {self.node}: SDO 0x{self._index:04X}:{self._subindex:02X}: {text}"),
                          code)

    def feed(self, frame: can.Message) -> SdoStep:
        """The next step after reply ``frame``.

        A frame that is not on 0x580+node, or one that comes while no transfer runs, raises
        :class:`~joints.errors.UnexpectedReply` and changes nothing (the link routes by COB-ID).
        """
        if frame.arbitration_id != self.tx_cob_id or frame.is_remote_frame:
            raise UnexpectedReply(f"node {self.node}: frame 0x{frame.arbitration_id:X} is not an SDO reply "
                                  f"(expected 0x{self.tx_cob_id:X})")
        if not self.busy:
            raise UnexpectedReply(f"node {self.node}: SDO reply while no transfer runs")
        try:
            reply = decode(frame)
        except FrameError as exc:
            return self._fail(exc, SdoAbortCode.COMMAND_SPECIFIER_INVALID)
        if isinstance(reply, SdoAbort):
            self._state = _IDLE
            return SdoFailed(abort_error(self.node, reply.index, reply.subindex, reply.code))
        state = self._state
        if state == _DOWNLOAD:
            if not isinstance(reply, SdoDownloadInitiateResponse):
                return self._protocol_error(f"expected a download response, got {type(reply).__name__}",
                                            SdoAbortCode.COMMAND_SPECIFIER_INVALID)
            if (reply.index, reply.subindex) != (self._index, self._subindex):
                return self._protocol_error(f"download response for 0x{reply.index:04X}:{reply.subindex:02X}",
                                            SdoAbortCode.GENERAL_ERROR)
            if not self._data:
                self._state = _IDLE
                return SdoDone()
            self._state = _DOWNLOAD_SEGMENTS
            return SdoSend(self._next_segment())
        if state == _DOWNLOAD_SEGMENTS:
            if not isinstance(reply, SdoDownloadSegmentResponse):
                return self._protocol_error(f"expected a segment response, got {type(reply).__name__}",
                                            SdoAbortCode.COMMAND_SPECIFIER_INVALID)
            if reply.toggle != self._toggle:
                return self._protocol_error("segment response toggle bit not alternated",
                                            SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED)
            self._toggle = not self._toggle
            if self._last_sent:
                self._state = _IDLE
                return SdoDone()
            return SdoSend(self._next_segment())
        if state == _UPLOAD:
            if not isinstance(reply, SdoUploadInitiateResponse):
                return self._protocol_error(f"expected an upload response, got {type(reply).__name__}",
                                            SdoAbortCode.COMMAND_SPECIFIER_INVALID)
            if (reply.index, reply.subindex) != (self._index, self._subindex):
                return self._protocol_error(f"upload response for 0x{reply.index:04X}:{reply.subindex:02X}",
                                            SdoAbortCode.GENERAL_ERROR)
            if reply.expedited:
                self._state = _IDLE
                return SdoDone(reply.data)
            self._state, self._size, self._data = _UPLOAD_SEGMENTS, reply.size, b""
            return SdoSend(encode(SdoUploadSegmentRequest(self.node, self._toggle)))
        # _UPLOAD_SEGMENTS
        if not isinstance(reply, SdoUploadSegment):
            return self._protocol_error(f"expected an upload segment, got {type(reply).__name__}",
                                        SdoAbortCode.COMMAND_SPECIFIER_INVALID)
        if reply.toggle != self._toggle:
            return self._protocol_error("upload segment toggle bit not alternated",
                                        SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED)
        self._data += reply.data
        if self._size is not None and len(self._data) > self._size:
            return self._protocol_error(f"{len(self._data)} bytes uploaded, {self._size} indicated",
                                        SdoAbortCode.LENGTH_TOO_HIGH)
        if not reply.last:
            self._toggle = not self._toggle
            return SdoSend(encode(SdoUploadSegmentRequest(self.node, self._toggle)))
        if self._size is not None and len(self._data) != self._size:
            return self._protocol_error(f"{len(self._data)} bytes uploaded, {self._size} indicated",
                                        SdoAbortCode.LENGTH_TOO_LOW)
        self._state = _IDLE
        return SdoDone(self._data)

    def _next_segment(self) -> can.Message:
        chunk, self._data = self._data[:SDO_SEGMENT], self._data[SDO_SEGMENT:]
        self._last_sent = not self._data
        return encode(SdoDownloadSegment(self.node, self._toggle, chunk, self._last_sent))


#: read(index, subindex) -> the object's bytes (little-endian); raise DeviceRejected(code=abort code) to refuse
SdoRead = Callable[[int, int], bytes]
#: write(index, subindex, data); raise DeviceRejected(code=abort code) to refuse
SdoWrite = Callable[[int, int, bytes], None]


class SdoServer:
    """Node side of the SDO channel: answers each request frame (0x600+node) from an object dictionary.

    ``read``/``write`` reach the dictionary; they refuse by raising
    :class:`~joints.errors.DeviceRejected` with the abort code as ``code`` (any other
    :class:`~joints.errors.JointsError` becomes abort 0x08000000). A segmented download is written
    once, whole, after its last segment. Gate by NMT state before feeding (not in STOPPED).
    """

    def __init__(self, node: int, read: SdoRead, write: SdoWrite) -> None:
        _check_node(node)
        self.node = node
        self.rx_cob_id = SDO_RX_BASE + node  #: where requests come from
        self._read = read
        self._write = write
        self.reset()

    def reset(self) -> None:
        """Forget a transfer in progress (NMT reset, or the twin's own SDO timeout)."""
        self._state = _IDLE
        self._index = 0
        self._subindex = 0
        self._toggle = False
        self._data = b""
        self._size: int | None = None

    def _abort(self, code: int, index: int | None = None, subindex: int | None = None) -> can.Message:
        frame = encode(SdoAbort(self.node, self._index if index is None else index,
                                self._subindex if subindex is None else subindex, code, False))
        self.reset()
        return frame

    def feed(self, frame: can.Message) -> can.Message | None:
        """The reply to request ``frame`` (None when nothing is to be sent, e.g. after a client abort)."""
        if frame.arbitration_id != self.rx_cob_id or frame.is_remote_frame:
            return None
        try:
            request = decode(frame)
        except FrameError:
            return self._abort(SdoAbortCode.COMMAND_SPECIFIER_INVALID)
        if isinstance(request, SdoAbort):
            self.reset()
            return None
        if isinstance(request, SdoUploadInitiate):
            return self._upload(request.index, request.subindex)
        if isinstance(request, SdoDownloadInitiate):
            return self._download(request)
        if isinstance(request, SdoUploadSegmentRequest):
            if self._state != _UPLOAD_SEGMENTS:
                return self._abort(SdoAbortCode.COMMAND_SPECIFIER_INVALID)
            if request.toggle != self._toggle:
                return self._abort(SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED)
            chunk, self._data = self._data[:SDO_SEGMENT], self._data[SDO_SEGMENT:]
            last = not self._data
            reply = encode(SdoUploadSegment(self.node, self._toggle, chunk, last))
            self._toggle = not self._toggle
            if last:
                self.reset()
            return reply
        if isinstance(request, SdoDownloadSegment):
            if self._state != _DOWNLOAD_SEGMENTS:
                return self._abort(SdoAbortCode.COMMAND_SPECIFIER_INVALID)
            if request.toggle != self._toggle:
                return self._abort(SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED)
            self._data += request.data
            if self._size is not None and len(self._data) > self._size:
                return self._abort(SdoAbortCode.LENGTH_TOO_HIGH)
            reply = encode(SdoDownloadSegmentResponse(self.node, self._toggle))
            self._toggle = not self._toggle
            if not request.last:
                return reply
            if self._size is not None and len(self._data) != self._size:
                return self._abort(SdoAbortCode.LENGTH_TOO_LOW)
            failed = self._call_write(self._index, self._subindex, self._data)
            if failed is not None:
                return failed
            self.reset()
            return reply
        # block transfer, unknown specifiers, or a server frame on our request COB-ID
        return self._abort(SdoAbortCode.COMMAND_SPECIFIER_INVALID, *_mux_of(frame))

    def _upload(self, index: int, subindex: int) -> can.Message:
        self.reset()
        try:
            data = bytes(self._read(index, subindex))
        except DeviceRejected as exc:
            return self._abort(exc.code, index, subindex)
        except JointsError:
            return self._abort(SdoAbortCode.GENERAL_ERROR, index, subindex)
        if 1 <= len(data) <= 4:
            return encode(SdoUploadInitiateResponse(self.node, index, subindex, data, True, len(data)))
        self._state, self._index, self._subindex, self._data = _UPLOAD_SEGMENTS, index, subindex, data
        return encode(SdoUploadInitiateResponse(self.node, index, subindex, b"", False, len(data)))

    def _download(self, request: SdoDownloadInitiate) -> can.Message:
        self.reset()
        index, subindex = request.index, request.subindex
        if request.expedited:
            failed = self._call_write(index, subindex, request.data)
            return failed if failed is not None else encode(SdoDownloadInitiateResponse(self.node, index, subindex))
        self._state, self._index, self._subindex, self._size = _DOWNLOAD_SEGMENTS, index, subindex, request.size
        return encode(SdoDownloadInitiateResponse(self.node, index, subindex))

    def _call_write(self, index: int, subindex: int, data: bytes) -> can.Message | None:
        try:
            self._write(index, subindex, data)
        except DeviceRejected as exc:
            return self._abort(exc.code, index, subindex)
        except JointsError:
            return self._abort(SdoAbortCode.GENERAL_ERROR, index, subindex)
        return None


def _mux_of(frame: can.Message) -> tuple[int, int]:
    data = bytes(frame.data).ljust(4, b"\x00")
    return data[1] | data[2] << 8, data[3]


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


def pack_pdo(entries: Sequence[tuple[int, int, int, bool]], values: Sequence[int]) -> bytes:
    """PDO data from the values of its mapped objects, in mapping order (dummies take any value, e.g. 0)."""
    if len(entries) != len(values):
        raise EncodeError(f"PDO has {len(entries)} mapped objects, got {len(values)} values")
    raw = 0
    offset = 0
    for (index, subindex, bits, signed), value in zip(entries, values):
        lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
        if not lo <= value <= hi:
            raise EncodeError(f"PDO object 0x{index:04X}:{subindex:02X}: value {value} out of range [{lo}, {hi}]")
        raw |= (value & ((1 << bits) - 1)) << offset
        offset += bits
    if offset > MAX_PDO_BITS:
        raise EncodeError(f"PDO mapping of {offset} bits exceeds {MAX_PDO_BITS}")
    return raw.to_bytes((offset + 7) // 8, "little")


def unpack_pdo(entries: Sequence[tuple[int, int, int, bool]], data: bytes) -> tuple[int, ...]:
    """Values of the mapped objects in PDO ``data`` (FrameError if shorter than the mapping)."""
    bits = pdo_length(entries)
    if len(data) * 8 < bits:
        raise FrameError(f"PDO of {len(data)} bytes, mapping needs {(bits + 7) // 8}", data=data)
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
