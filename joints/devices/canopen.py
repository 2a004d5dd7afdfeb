"""CiA 301 object dictionaries: data types, access, one object, and the EDS text format (CiA 306).

Rule: pure data + pure functions (text in, data out; data in, text out), shared by every CANopen
device family. A device package says which objects its drive has (the eRob reads ZeroErr's EDS,
:mod:`joints.devices.erob.canopen`); this module knows only the standard.
"""

from __future__ import annotations

import configparser
import enum
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from joints.devices.params import check_value
from joints.errors import FrameError

__all__ = ["CanopenObject", "DataType", "EdsObject", "EdsVariable", "ObjectAccess", "ObjectType", "format_eds",
           "parse_eds"]


class DataType(enum.IntEnum):
    """CiA 301 data type codes (the ``DataType`` of an EDS entry) of the integer types."""

    BOOLEAN = 0x0001
    INTEGER8 = 0x0002
    INTEGER16 = 0x0003
    INTEGER32 = 0x0004
    UNSIGNED8 = 0x0005
    UNSIGNED16 = 0x0006
    UNSIGNED32 = 0x0007

    @property
    def bits(self) -> int:
        return _BITS[self]

    @property
    def size(self) -> int:
        """Bytes on the wire (SDO)."""
        return max(1, _BITS[self] // 8)

    @property
    def signed(self) -> bool:
        return self in (DataType.INTEGER8, DataType.INTEGER16, DataType.INTEGER32)

    @property
    def param_type(self) -> str:
        """The :data:`~joints.devices.params.TYPES` name of the same range."""
        return _PARAM_TYPE[self]


_BITS = {DataType.BOOLEAN: 1, DataType.INTEGER8: 8, DataType.INTEGER16: 16, DataType.INTEGER32: 32,
         DataType.UNSIGNED8: 8, DataType.UNSIGNED16: 16, DataType.UNSIGNED32: 32}
_PARAM_TYPE = {DataType.BOOLEAN: "bool", DataType.INTEGER8: "int8", DataType.INTEGER16: "int16",
               DataType.INTEGER32: "int32", DataType.UNSIGNED8: "uint8", DataType.UNSIGNED16: "uint16",
               DataType.UNSIGNED32: "uint32"}


class ObjectAccess(enum.Enum):
    """EDS ``AccessType`` values."""

    RO = "ro"
    WO = "wo"
    RW = "rw"
    RWR = "rwr"  #: read-write, mapped to a TPDO
    RWW = "rww"  #: read-write, mapped to an RPDO
    CONST = "const"

    @property
    def readable(self) -> bool:
        return self is not ObjectAccess.WO

    @property
    def writable(self) -> bool:
        return self not in (ObjectAccess.RO, ObjectAccess.CONST)


class ObjectType(enum.IntEnum):
    """EDS ``ObjectType`` codes."""

    VAR = 0x7
    ARRAY = 0x8
    RECORD = 0x9


@dataclass(frozen=True, slots=True, eq=False)
class CanopenObject:
    """One object-dictionary entry; equal (and hashed) by (index, subindex)."""

    index: int
    subindex: int
    datatype: DataType
    access: ObjectAccess
    name: str  #: the object's name (EDS ParameterName)
    pdo_mappable: bool = False
    node_relative: bool = False  #: the default is ``default_value`` + node id (COB-IDs, ``$NODEID+``)
    unit: str = ""  #: unit on CANopen when it differs from the parameter's
    scale: float = 1.0  #: value in the parameter's unit = raw x scale
    default_value: int = 0  #: power-on value (without the node id of a node-relative object)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, CanopenObject):
            return NotImplemented
        return (self.index, self.subindex) == (other.index, other.subindex)

    def __hash__(self) -> int:
        return hash((self.index, self.subindex))

    def __repr__(self) -> str:
        return f"CanopenObject(0x{self.index:04X}:{self.subindex:02X} {self.name!r}, {self.datatype.name})"

    def __str__(self) -> str:
        return f"0x{self.index:04X}:{self.subindex:02X}"

    @property
    def bits(self) -> int:
        return self.datatype.bits

    @property
    def size(self) -> int:
        return self.datatype.size

    @property
    def signed(self) -> bool:
        return self.datatype.signed

    @property
    def value_range(self) -> tuple[int, int]:
        bits = self.bits
        return (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if self.signed else (0, (1 << bits) - 1)

    def encode(self, value: object) -> bytes:
        """The SDO bytes of ``value`` (little-endian); :class:`~joints.errors.CommandError` if out of range."""
        v = check_value(self.name, self.datatype.param_type, value, where=f" (0x{self.index:04X}:{self.subindex:02X})")
        return v.to_bytes(self.size, "little", signed=self.signed)

    def decode(self, data: bytes) -> int:
        """The value in SDO/PDO bytes; :class:`~joints.errors.FrameError` if the length is not the type's."""
        if len(data) != self.size:
            raise FrameError(f"0x{self.index:04X}:{self.subindex:02X} ({self.datatype.name}) takes {self.size} "
                             f"bytes, got {len(data)}", data=bytes(data))
        return int.from_bytes(data, "little", signed=self.signed)

    @property
    def mapping_entry(self) -> tuple[int, int, int, bool]:
        """(index, subindex, bits, signed): a PDO mapping entry for the codec."""
        return self.index, self.subindex, self.bits, self.signed

    def default(self, node: int) -> int:
        """Power-on value on node ``node`` (COB-IDs + node id)."""
        return self.default_value + node if self.node_relative else self.default_value


# --- EDS (CiA 306) ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class EdsVariable:
    """One variable of an EDS as the file states it (``default`` None: the file gives none)."""

    index: int
    subindex: int
    name: str
    datatype: int
    access: str
    pdo_mappable: bool
    default: int | None
    node_relative: bool = False
    low: int | None = None
    high: int | None = None


@dataclass(frozen=True, slots=True)
class EdsObject:
    """One object of an EDS: a VAR (one variable, sub-index 0) or an ARRAY/RECORD of sub-indices."""

    index: int
    name: str
    object_type: ObjectType
    variables: tuple[EdsVariable, ...]


_SECTION = re.compile(r"([0-9A-Fa-f]{4})(?:sub([0-9A-Fa-f]{1,2}))?")
_NODEID = re.compile(r"\$NODEID\s*\+\s*(\S+)", re.IGNORECASE)


def _int(text: str) -> int:
    text = text.strip()
    if text.lower().startswith("0x"):
        return int(text, 16)
    return int(text, 10) if text.lstrip("-").isdigit() else int(text, 0)


def _default(text: str | None) -> tuple[int | None, bool]:
    if text is None or not text.strip():
        return None, False
    m = _NODEID.fullmatch(text.strip())
    if m is not None:
        return _int(m.group(1)), True
    return _int(text), False


def _variable(index: int, subindex: int, sec: configparser.SectionProxy) -> EdsVariable:
    default, relative = _default(sec.get("DefaultValue"))
    low, high = sec.get("LowLimit"), sec.get("HighLimit")
    return EdsVariable(index, subindex, sec.get("ParameterName", "").strip(), _int(sec.get("DataType", "0")),
                       sec.get("AccessType", "rw").strip().lower(), sec.get("PDOMapping", "0").strip() not in ("", "0"),
                       default, relative, None if not low else _int(low), None if not high else _int(high))


def parse_eds(text: str) -> tuple[dict[str, dict[str, str]], list[EdsObject]]:
    """An EDS file's info sections (``FileInfo``, ``DeviceInfo``, ...) and its objects by index.

    Raises :class:`ValueError` on a file that is not an EDS (no object sections)."""
    cp = configparser.ConfigParser(interpolation=None, strict=False)
    cp.optionxform = str  # type: ignore[assignment,method-assign]
    cp.read_string(text)
    info: dict[str, dict[str, str]] = {}
    objs: dict[int, configparser.SectionProxy] = {}
    subs: dict[int, dict[int, configparser.SectionProxy]] = {}
    for name in cp.sections():
        m = _SECTION.fullmatch(name)
        if m is None:
            info[name] = dict(cp[name])
            continue
        index = int(m.group(1), 16)
        if m.group(2) is None:
            objs[index] = cp[name]
        else:
            subs.setdefault(index, {})[int(m.group(2), 16)] = cp[name]
    if not objs:
        raise ValueError("not an EDS: no object sections ([1000], [6041], ...)")
    out = []
    for index in sorted(objs):
        sec = objs[index]
        kind = ObjectType(_int(sec.get("ObjectType", "0x7")))
        if kind is ObjectType.VAR:
            variables: tuple[EdsVariable, ...] = (_variable(index, 0, sec),)
        else:
            variables = tuple(_variable(index, s, subs.get(index, {})[s]) for s in sorted(subs.get(index, {})))
        out.append(EdsObject(index, sec.get("ParameterName", "").strip(), kind, variables))
    return info, out


def _hex(value: int, width: int = 0) -> str:
    return f"0x{value:0{width}X}" if value >= 0 else str(value)


def format_eds(info: Sequence[tuple[str, Sequence[tuple[str, str]]]], objects: Iterable[EdsObject]) -> str:
    """EDS text (CiA 306): the info sections as given, then ``MandatoryObjects``/``OptionalObjects``/
    ``ManufacturerObjects`` lists and one section per object and sub-index."""
    objs = sorted(objects, key=lambda o: o.index)
    lines: list[str] = []
    for section, items in info:
        lines.append(f"[{section}]")
        lines.extend(f"{k}={v}" for k, v in items)
        lines.append("")
    mandatory = [o for o in objs if o.index in (0x1000, 0x1001, 0x1018)]
    optional = [o for o in objs if o not in mandatory and (0x1000 <= o.index < 0x2000 or o.index >= 0x6000)]
    manufacturer = [o for o in objs if 0x2000 <= o.index < 0x6000]
    for title, group in (("MandatoryObjects", mandatory), ("OptionalObjects", optional),
                         ("ManufacturerObjects", manufacturer)):
        lines.append(f"[{title}]")
        lines.append(f"SupportedObjects={len(group)}")
        lines.extend(f"{i}=0x{o.index:04X}" for i, o in enumerate(group, 1))
        lines.append("")
    for o in objs:
        lines.append(f"[{o.index:04X}]")
        lines.append(f"ParameterName={o.name}")
        lines.append(f"ObjectType=0x{int(o.object_type):X}")
        if o.object_type is ObjectType.VAR:
            lines.extend(_variable_lines(o.variables[0]))
            lines.append("")
            continue
        lines.append(f"SubNumber={len(o.variables)}")
        lines.append("")
        for v in o.variables:
            lines.append(f"[{o.index:04X}sub{v.subindex:X}]")
            lines.append(f"ParameterName={v.name}")
            lines.append("ObjectType=0x7")
            lines.extend(_variable_lines(v))
            lines.append("")
    return "\n".join(lines)


def _variable_lines(v: EdsVariable) -> list[str]:
    out = [f"DataType=0x{v.datatype:04X}", f"AccessType={v.access}"]
    if v.default is not None:
        out.append(f"DefaultValue=$NODEID+{_hex(v.default)}" if v.node_relative else f"DefaultValue={_hex(v.default)}")
    out.append(f"PDOMapping={int(v.pdo_mappable)}")
    if v.low is not None:
        out.append(f"LowLimit={_hex(v.low)}")
    if v.high is not None:
        out.append(f"HighLimit={_hex(v.high)}")
    return out
