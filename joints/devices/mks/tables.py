"""The MKS maps as listing rows (what ``joints registers`` prints): one row per parameter and protocol.

Rule: pure data, derived from :data:`~joints.devices.mks.native.MKS_NATIVE` and
:data:`~joints.devices.mks.modbus.MKS_MODBUS` (the newest firmware's map); the parameter's own type, access, unit and
persistence, the protocol's address (native: the command code; Modbus: the Part 8 start register).
"""

from __future__ import annotations

from dataclasses import dataclass

from joints.devices.mks.modbus import MKS_MODBUS
from joints.devices.mks.native import MKS_NATIVE
from joints.devices.mks.params import MKS_PARAMS
from joints.devices.params import Access

__all__ = ["TableRow", "modbus_rows", "native_rows"]


@dataclass(frozen=True, slots=True)
class TableRow:
    address: int  #: native command code / Part 8 start register
    name: str
    type: str
    access: Access
    unit: str
    persistent: bool
    where: str  #: the field inside the command or request


def native_rows() -> tuple[TableRow, ...]:
    """Every parameter of the native protocol, by command code."""
    rows = []
    for name, key in MKS_NATIVE.keys.items():
        p = MKS_PARAMS[name]
        rows.append(TableRow(int(key.command), name, p.type, p.access, p.unit, p.persistent, key.field))
    return tuple(sorted(rows, key=lambda r: (r.address, r.name)))


def modbus_rows() -> tuple[TableRow, ...]:
    """Every parameter Part 8 reaches, by start register."""
    rows = []
    for f in MKS_MODBUS:
        p = MKS_PARAMS[f.name]
        rows.append(TableRow(f.address, f.name, p.type, p.access, p.unit, p.persistent,
                             f"FC{f.function:02d} +{f.offset}/{f.size}"))
    return tuple(sorted(rows, key=lambda r: (r.address, r.name)))
