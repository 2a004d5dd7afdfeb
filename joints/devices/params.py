"""Parameters: each device family defines its quantities ONCE, and maps them per protocol.

Rule: pure data. A :class:`Param` is a quantity of a drive by the manual's name in snake_case
(type, unit, access, documented range, power-on default, whether writing it is persistent or
dangerous). A :class:`ParamSet` holds every parameter of one family. A :class:`ParamMap` says how
one protocol reaches each parameter (a Modbus register, an eRob CAN custom index/subindex, a
CANopen object, an MKS command code): the same name is the same quantity on every protocol, so
``joint.read("actual_position")`` is the same call over Modbus and over CAN.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from joints.errors import CommandError, RegisterError


class Access(enum.Enum):
    """Access attribute as printed in the manuals."""

    R = "R"  #: read only
    RW = "R/W"  #: read and write
    COMMAND = "Command"  #: write-only command (writing triggers an action)
    W = "W"  #: write-only setting (the drive cannot report it back, e.g. most MKS settings)

    @property
    def readable(self) -> bool:
        return self in (Access.R, Access.RW)

    @property
    def writable(self) -> bool:
        return self is not Access.R


#: integer types -> (minimum, maximum, bytes)
TYPES: Mapping[str, tuple[int, int, int]] = {
    "bool": (0, 1, 1),
    "uint8": (0, 0xFF, 1),
    "int8": (-0x80, 0x7F, 1),
    "uint16": (0, 0xFFFF, 2),
    "int16": (-0x8000, 0x7FFF, 2),
    "uint32": (0, 0xFFFFFFFF, 4),
    "int32": (-0x80000000, 0x7FFFFFFF, 4),
    "int48": (-(1 << 47), (1 << 47) - 1, 6),
}


def check_value(name: str, type_: str, value: object, minimum: int | None = None, maximum: int | None = None,
                unit: str = "", where: str = "") -> int:
    """``value`` as an int within the type's range and the documented bounds, else :class:`CommandError`."""
    if isinstance(value, bool) or not isinstance(value, int):
        if isinstance(value, float) and value.is_integer() or hasattr(value, "__index__") and not isinstance(value, bool):
            value = int(value)
        else:
            raise CommandError(f"{name}: expected an integer, got {value!r}")
    lo, hi, _ = TYPES[type_]
    if minimum is not None:
        lo = max(lo, minimum)
    if maximum is not None:
        hi = min(hi, maximum)
    if not lo <= value <= hi:
        raise CommandError(f"{name}{where}: value {value} out of range [{lo}, {hi}]" + (f" {unit}" if unit else ""))
    return int(value)


@dataclass(frozen=True, slots=True)
class Param:
    """One quantity of a drive, independent of the protocol that reaches it."""

    name: str
    type: str = "uint16"
    access: Access = Access.RW
    unit: str = ""
    description: str = ""
    minimum: int | None = None  #: documented lower bound (inclusive), if any
    maximum: int | None = None  #: documented upper bound (inclusive), if any
    default: int = 0  #: power-on value where the manual gives one
    persistent: bool = False  #: writing it is persistent or dangerous (needs confirmation)
    #: the range :meth:`check` accepts (the type's, narrowed by the documented bounds: ``check_value``'s)
    _lo: int = field(init=False, repr=False, compare=False)
    _hi: int = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.type not in TYPES:
            raise ValueError(f"parameter {self.name}: unknown type {self.type!r} (allowed: {', '.join(TYPES)})")
        lo, hi, _ = TYPES[self.type]
        object.__setattr__(self, "_lo", lo if self.minimum is None else max(lo, self.minimum))
        object.__setattr__(self, "_hi", hi if self.maximum is None else min(hi, self.maximum))

    @property
    def type_range(self) -> tuple[int, int]:
        lo, hi, _ = TYPES[self.type]
        return lo, hi

    @property
    def signed(self) -> bool:
        return self.type.startswith("int")

    def check(self, value: object) -> int:
        """Validate a value for writing; returns it as int or raises :class:`CommandError`."""
        if type(value) is int and self._lo <= value <= self._hi:  # the usual case: what check_value returns
            return value
        return check_value(self.name, self.type, value, self.minimum, self.maximum, self.unit)


class ParamSet:
    """Every parameter of one device family, by name."""

    def __init__(self, device: str, params: Iterable[Param]) -> None:
        self.device = device
        self.params: tuple[Param, ...] = tuple(params)
        by_name: dict[str, Param] = {}
        for p in self.params:
            if p.name in by_name:
                raise ValueError(f"{device}: duplicate parameter name {p.name!r}")
            by_name[p.name] = p
        self._by_name = by_name

    def __iter__(self) -> Iterator[Param]:
        return iter(self.params)

    def __len__(self) -> int:
        return len(self.params)

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def __getitem__(self, name: str) -> Param:
        return self.get(name)

    def get(self, name: str) -> Param:
        p = self._by_name.get(name)
        if p is None:
            raise RegisterError(f"{self.device}: no parameter named {name!r}{suggest(name, self._by_name)}")
        return p

    def names(self) -> list[str]:
        return [p.name for p in self.params]

    def extended(self, params: Iterable[Param]) -> ParamSet:
        """A set with more parameters (a protocol that reaches quantities another one does not)."""
        return ParamSet(self.device, (*self.params, *params))

    def __repr__(self) -> str:
        return f"ParamSet({self.device!r}, {len(self.params)} parameters)"


def suggest(key: str, names: Iterable[str]) -> str:
    """"; did you mean a, b?" for names that contain ``key`` (empty if none)."""
    needle = key.lower().replace(" ", "_")
    close = [n for n in names if needle in n][:5]
    return f"; did you mean {', '.join(close)}?" if close else ""


K = TypeVar("K")


@dataclass(frozen=True)
class ParamMap(Generic[K]):
    """How one protocol reaches the parameters of a family: name -> protocol key.

    ``keys`` values are the protocol's own addressing (a Modbus :class:`~joints.devices.registers.Register`,
    a CAN index/subindex, a CANopen object, an MKS command code). Every name must be a parameter
    of ``params``; keys are unique.
    """

    protocol: str
    params: ParamSet
    keys: Mapping[str, K]
    _by_key: Mapping[K, str] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        by_key: dict[K, str] = {}
        for name, key in self.keys.items():
            if name not in self.params:
                raise ValueError(f"{self.protocol} map of {self.params.device}: {name!r} is not a parameter")
            if key in by_key:
                raise ValueError(f"{self.protocol} map of {self.params.device}: {key!r} used by {by_key[key]!r} "
                                 f"and {name!r}")
            by_key[key] = name
        object.__setattr__(self, "_by_key", by_key)

    def __contains__(self, name: object) -> bool:
        return name in self.keys

    def __iter__(self) -> Iterator[str]:
        return iter(self.keys)

    def __len__(self) -> int:
        return len(self.keys)

    def key(self, name: str) -> K:
        """The protocol key of parameter ``name`` (a clear error if this protocol cannot reach it)."""
        try:
            return self.keys[name]
        except KeyError:
            if name in self.params:
                raise RegisterError(f"{self.params.device}: {name!r} cannot be reached over {self.protocol}") from None
            raise RegisterError(f"{self.params.device}: no parameter named {name!r}"
                                f"{suggest(name, self.keys)}") from None

    def name_of(self, key: K) -> str:
        try:
            return self._by_key[key]
        except KeyError:
            raise RegisterError(f"{self.params.device}: nothing at {key!r} over {self.protocol}") from None

    def param(self, name: str) -> Param:
        return self.params.get(name)

    def access(self, name: str) -> Access:
        """The access this protocol gives to ``name`` (a map may narrow the parameter's)."""
        return self.param(name).access

    def unit(self, name: str) -> str:
        """The unit of ``name`` on this protocol (a map may differ from the parameter's)."""
        return self.param(name).unit

    def where(self, name: str) -> str:
        """Where ``name`` lives on this protocol, for people."""
        return str(self.key(name))
