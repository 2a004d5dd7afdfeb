"""CANopen COB-IDs: the pre-defined connection set (CiA 301) and the routing of a frame to its service and node (A1).

Rule: pure.
"""

from __future__ import annotations

import enum
from typing import NamedTuple

import can

from joints.errors import EncodeError

__all__ = ["EMCY_BASE", "ERROR_CONTROL_BASE", "MAX_NODE", "NMT_ID", "RPDO_BASE", "SDO_RX_BASE", "SDO_SEGMENT", "SDO_TX_BASE", "SYNC_ID", "TIME_ID", "TPDO_BASE", "Kind", "Route", "classify", "pdo_cob_id"]

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
        return self._value_ in _PDO_VALUES  # by the value: a str hashes in C, an enum member in Python

    @property
    def pdo_number(self) -> int:
        """1..4 for a PDO kind (ValueError otherwise)."""
        try:
            return _PDO_NUMBER[self]
        except KeyError:
            raise ValueError(f"{self.value} is not a PDO") from None


_PDO_NUMBER = {Kind.TPDO1: 1, Kind.TPDO2: 2, Kind.TPDO3: 3, Kind.TPDO4: 4,
               Kind.RPDO1: 1, Kind.RPDO2: 2, Kind.RPDO3: 3, Kind.RPDO4: 4}
_PDO_VALUES = frozenset(k.value for k in _PDO_NUMBER)

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
        return _UNKNOWN
    route = _ROUTES[cob] if cob >= 0 else _route(cob)
    if route is None:  # 0x700 + node: heartbeat, boot-up or guard request, by the frame
        node = cob & 0x7F
        if frame.is_remote_frame:
            return Route(Kind.GUARD_REQUEST, node)
        if frame.dlc == 1 and frame.data[0] == 0:
            return Route(Kind.BOOT_UP, node)
        return Route(Kind.HEARTBEAT, node)
    return route


def _route(cob: int) -> Route | None:
    """The route of a standard COB-ID (None: the 0x700 + node range, where the frame decides)."""
    node = cob & 0x7F
    if node == 0:
        if cob == NMT_ID:
            return Route(Kind.NMT, 0)
        if cob == SYNC_ID:
            return Route(Kind.SYNC, 0)
        if cob == TIME_ID:
            return Route(Kind.TIME, 0)
        return _UNKNOWN
    kind = _BY_FUNCTION[cob >> 7]
    if kind is Kind.HEARTBEAT:
        return None
    if kind is Kind.UNKNOWN:
        return _UNKNOWN
    return Route(kind, node)


_UNKNOWN = Route(Kind.UNKNOWN, 0)
#: the route of every standard COB-ID, computed once (:func:`classify` looks it up)
_ROUTES: tuple[Route | None, ...] = tuple(_route(cob) for cob in range(0x800))


def pdo_cob_id(kind: Kind, node: int) -> int:
    """Pre-defined COB-ID of a PDO of ``node`` (e.g. RPDO1 of node 2 -> 0x202)."""
    check_node(node)
    n = kind.pdo_number
    return (TPDO_BASE if kind.name.startswith("T") else RPDO_BASE)[n - 1] + node


def check_node(node: int, *, broadcast: bool = False) -> None:
    lo = 0 if broadcast else 1
    if not lo <= node <= MAX_NODE:
        raise EncodeError(f"CANopen node id {node} out of range [{lo}, {MAX_NODE}]")


def check_mux(index: int, subindex: int) -> None:
    if not 0 <= index <= 0xFFFF or not 0 <= subindex <= 0xFF:
        raise EncodeError(f"object 0x{index:X}:{subindex:X} out of range (index 16 bits, subindex 8 bits)")
