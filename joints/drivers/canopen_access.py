"""Generic CANopen parameter access: a node's objects by SDO, under parameter names.

Rule: the protocol half of a CANopen driver. A :class:`~joints.devices.params.ParamMap` of
:class:`~joints.devices.canopen.CanopenObject` says which object carries which parameter; reads and
writes go through the link's SDO client; values are checked before anything is sent. The map is a
device family's table, or :func:`map_from_eds` reads a vendor's EDS (a drive's dictionary as its
maker states it) and keeps, of the family's parameters, those the file has - with the file's data
types and access.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from joints.codecs import canopen as co
from joints.devices.canopen import CanopenObject, DataType, ObjectAccess, parse_eds
from joints.devices.params import ParamMap
from joints.drivers.access import ParamAccess
from joints.errors import CommandError, ConfigError, RegisterError

__all__ = ["CanopenAccess", "map_from_eds"]

_WHERE = re.compile(r"(?:0x)?([0-9a-fA-F]{4})(?:[:/.sub]+(0x[0-9a-fA-F]+|\d+))?")


class CanopenAccess(ParamAccess):
    """Parameters of one node as CANopen objects, by SDO (expedited; segmented above 4 bytes).

    ``cmap``: parameter name -> object (the device family's table, or one read from an EDS:
    :func:`map_from_eds`). Keys "0x6064", "0x607D:1", "607D/2" name objects by address."""

    protocol = "canopen"

    def __init__(self, link: Any, node: int, cmap: ParamMap[CanopenObject]) -> None:
        if type(node) is not int or not 1 <= node <= co.MAX_NODE:
            raise CommandError(f"CANopen node id must be 1..{co.MAX_NODE}, got {node!r}")
        self.link = link
        self.node = node
        self.map = cmap
        self.params = cmap.params
        self._at = {(o.index, o.subindex): n for n, o in cmap.keys.items()}
        self._indices = {i for i, _s in self._at}

    def name_at(self, index: int, subindex: int) -> str:
        """The parameter at ``index:subindex`` (:class:`~joints.errors.RegisterError`: 0x06020000 vs
        0x06090011 in words)."""
        try:
            return self._at[(index, subindex)]
        except KeyError:
            what = "sub-index" if index in self._indices else "object"
            raise RegisterError(f"{self.params.device}: no CANopen {what} 0x{index:04X}:{subindex:02X}") from None

    def resolve(self, key: str | int) -> str:
        if isinstance(key, int):
            return self.name_at(key, 0)
        if key in self.map:
            return key
        m = _WHERE.fullmatch(key.strip())
        if m is not None:  # "0x6064", "0x607D:1", "607D/2"
            index = int(m.group(1), 16)
            sub = 0 if m.group(2) is None else int(m.group(2), 0)
            return self.name_at(index, sub)
        self.map.key(key)  # unknown, or not reachable over CANopen
        return key

    def where(self, name: str) -> str:
        o = self.map.key(name)
        return f"0x{o.index:04X}:{o.subindex:02X}"

    def read(self, name: str) -> int:
        o = self.map.key(name)
        raw = o.decode(self.link.sdo_upload(self.node, o.index, o.subindex))
        return round(raw * o.scale) if o.scale != 1.0 else raw

    def encode(self, name: str, value: int) -> tuple[CanopenObject, bytes]:
        """The object and SDO bytes of ``value`` (checked: nothing is sent on error)."""
        o = self.map.key(name)
        self.params[name].check(value)
        raw = round(value / o.scale) if o.scale != 1.0 else value
        return o, o.encode(raw)

    def write(self, name: str, value: int, *, idempotent: bool = True) -> None:
        o, data = self.encode(name, value)
        self.link.sdo_download(self.node, o.index, o.subindex, data, idempotent=idempotent)

    def write_many(self, values: Mapping[str, int], *, idempotent: bool = True) -> None:
        encoded = [self.encode(n, v) for n, v in values.items()]  # every value checked first
        for o, data in encoded:
            self.link.sdo_download(self.node, o.index, o.subindex, data, idempotent=idempotent)


def map_from_eds(path: str | Path, family: ParamMap[CanopenObject]) -> ParamMap[CanopenObject]:
    """The family's parameters at the objects an EDS file states, with the file's data types and access.

    A parameter of ``family`` whose object the file lacks is not reachable through the result; an
    object of the file the family does not name is left out. :class:`ConfigError` if the file is
    not an EDS."""
    p = Path(path)
    try:
        _info, objects = parse_eds(p.read_bytes().decode("latin-1"))
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{p}: not a readable EDS ({exc})", file=str(p)) from None
    at = {(o.index, o.subindex): (n, o) for n, o in family.keys.items()}
    keys: dict[str, CanopenObject] = {}
    for obj in objects:
        for v in obj.variables:
            found = at.get((v.index, v.subindex))
            if found is None:
                continue
            name, ours = found
            try:
                datatype, access = DataType(v.datatype), ObjectAccess(v.access)
            except ValueError:
                continue  # a type the family's objects never have (a string, a domain)
            keys[name] = CanopenObject(v.index, v.subindex, datatype, access, v.name, v.pdo_mappable,
                                       v.node_relative, ours.unit, ours.scale,
                                       ours.default_value if v.default is None else v.default)
    return ParamMap(family.protocol, family.params, keys)
