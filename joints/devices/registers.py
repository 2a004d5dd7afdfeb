"""Typed register tables: one :class:`Register` per manual register, shared by driver and emulator.

Rule: pure data. A 32-bit Hi/Lo pair is ONE entry at its Hi address with ``type`` int32/uint32,
Hi word first on the wire (unless the table says otherwise). Names are the manual's in snake_case.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from joints.devices.params import Access, Param, ParamMap, ParamSet, check_value, suggest
from joints.errors import CommandError, RegisterError

__all__ = ["Access", "Register", "RegisterTable", "snake_name"]


_RANGES = {
    "uint16": (0, 0xFFFF, 1),
    "int16": (-0x8000, 0x7FFF, 1),
    "uint32": (0, 0xFFFFFFFF, 2),
    "int32": (-0x80000000, 0x7FFFFFFF, 2),
}

_NAME_RE = re.compile(r"[^0-9a-zA-Z]+")


def snake_name(definition: str) -> str:
    """Manual definition -> register name: drop "(Hi)"/"(Lo)", runs of non-alphanumerics -> "_".

    >>> snake_name("Max. Speed (Hi)")
    'max_speed'
    """
    text = re.sub(r"\((Hi|Lo|hi|lo|H|L)\)", "", definition)
    return _NAME_RE.sub("_", text).strip("_").lower()


@dataclass(frozen=True, slots=True)
class Register:
    """One register (or 32-bit register pair) of a device."""

    address: int
    name: str
    type: str = "uint16"  #: uint16 | int16 | uint32 | int32
    access: Access = Access.RW
    unit: str = ""
    description: str = ""
    minimum: int | None = None  #: documented lower bound (inclusive), if any
    maximum: int | None = None  #: documented upper bound (inclusive), if any
    default: int = 0  #: power-on value where the manual gives one
    persistent: bool = False  #: writing it is persistent/dangerous (needs confirmation)
    low_word_first: bool = False  #: word order of 32-bit pairs (eRob/ZLAC: Hi first)
    words: int = field(init=False, repr=False, compare=False)  #: 16-bit registers spanned (1 or 2)
    signed: bool = field(init=False, repr=False, compare=False)
    #: the range :meth:`check` accepts (the type's, narrowed by the documented bounds)
    _lo: int = field(init=False, repr=False, compare=False)
    _hi: int = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.type not in _RANGES:
            raise ValueError(f"register {self.name}: unknown type {self.type!r}")
        lo, hi, words = _RANGES[self.type]
        object.__setattr__(self, "words", words)
        object.__setattr__(self, "signed", self.type.startswith("int"))
        object.__setattr__(self, "_lo", lo if self.minimum is None else max(lo, self.minimum))
        object.__setattr__(self, "_hi", hi if self.maximum is None else min(hi, self.maximum))

    @property
    def type_range(self) -> tuple[int, int]:
        lo, hi, _ = _RANGES[self.type]
        return lo, hi

    def check(self, value: object) -> int:
        """Validate a value for writing; returns it as int or raises :class:`CommandError`."""
        if type(value) is int and self._lo <= value <= self._hi:  # the usual case: what check_value returns
            return value
        return check_value(self.name, self.type, value, self.minimum, self.maximum, self.unit,
                           f" (0x{self.address:04X})")

    @property
    def param(self) -> Param:
        """The protocol-neutral parameter this register carries."""
        return Param(self.name, self.type, self.access, self.unit, self.description, self.minimum,
                     self.maximum, self.default, self.persistent)

    def to_words(self, value: int) -> tuple[int, ...]:
        """Encode a value into its 16-bit words in wire order (range-checked)."""
        value = self.check(value)
        if self.words == 1:
            return (value & 0xFFFF,)
        raw = value & 0xFFFFFFFF
        hi, lo = raw >> 16, raw & 0xFFFF
        return (lo, hi) if self.low_word_first else (hi, lo)

    def from_words(self, words: Sequence[int]) -> int:
        """Decode the register's words (wire order) into its typed value."""
        if len(words) != self.words:
            raise ValueError(f"{self.name}: expected {self.words} words, got {len(words)}")
        if self.words == 1:
            raw = words[0] & 0xFFFF
            if self.signed and raw & 0x8000:
                raw -= 0x10000
            return raw
        a, b = words[0] & 0xFFFF, words[1] & 0xFFFF
        hi, lo = (b, a) if self.low_word_first else (a, b)
        raw = (hi << 16) | lo
        if self.signed and raw & 0x80000000:
            raw -= 0x100000000
        return raw


def _packed_plan(plan: Sequence[tuple[str, int, int, bool, bool]],
                 count: int) -> tuple[tuple[str, ...], struct.Struct, struct.Struct] | None:
    """A block decoded in one struct call: the words packed big-endian, unpacked by register type
    (gaps skipped); None if a register has its low word first."""
    if any(low_first for *_, low_first in plan):
        return None
    fmt, at = ">", 0
    for _name, i, n, signed, _low in sorted(plan, key=lambda p: p[1]):
        code = ("h" if signed else "H") if n == 1 else ("i" if signed else "I")
        fmt += "xx" * (i - at) + code
        at = i + n
    fmt += "xx" * (count - at)
    names = tuple(name for name, *_ in sorted(plan, key=lambda p: p[1]))
    return names, struct.Struct(f">{count}H"), struct.Struct(fmt)


@dataclass(frozen=True)
class RegisterTable:
    """An immutable, indexed collection of registers of one device family."""

    device: str
    registers: tuple[Register, ...]
    _by_name: Mapping[str, Register] = field(init=False, repr=False, compare=False)
    _by_address: Mapping[int, Register] = field(init=False, repr=False, compare=False)
    _word_owner: Mapping[int, Register] = field(init=False, repr=False, compare=False)
    _plans: dict[tuple[int, int], tuple[tuple[str, int, int, bool, bool], ...]] = field(
        init=False, repr=False, compare=False, default_factory=dict)
    #: per block shape: (names, words packer, values unpacker), None where a pair is low word first
    _packed: dict[tuple[int, int], tuple[tuple[str, ...], struct.Struct, struct.Struct] | None] = field(
        init=False, repr=False, compare=False, default_factory=dict)

    def __post_init__(self) -> None:
        by_name: dict[str, Register] = {}
        by_addr: dict[int, Register] = {}
        owner: dict[int, Register] = {}
        for reg in self.registers:
            if reg.name in by_name:
                raise ValueError(f"{self.device}: duplicate register name {reg.name!r}")
            by_name[reg.name] = reg
            for a in range(reg.address, reg.address + reg.words):
                if a in owner:
                    raise ValueError(
                        f"{self.device}: 0x{a:04X} used by both {owner[a].name} and {reg.name}"
                    )
                owner[a] = reg
            by_addr[reg.address] = reg
        object.__setattr__(self, "_by_name", by_name)
        object.__setattr__(self, "_by_address", by_addr)
        object.__setattr__(self, "_word_owner", owner)

    def __iter__(self) -> Iterator[Register]:
        return iter(self.registers)

    def __len__(self) -> int:
        return len(self.registers)

    def __contains__(self, key: object) -> bool:
        return key in self._by_name or key in self._by_address

    def __getitem__(self, key: str | int | Register) -> Register:
        return self.get(key)

    def get(self, key: str | int | Register) -> Register:
        """Look a register up by name, by (start) address, or pass a Register through."""
        if type(key) is str:  # the hot path (drivers by name): one dict lookup
            reg = self._by_name.get(key)
            if reg is not None:
                return reg
        if isinstance(key, Register):
            return key
        if isinstance(key, str):
            reg = self._by_name.get(key)
            if reg is None:
                raise RegisterError(f"{self.device}: no register named {key!r}{suggest(key, self._by_name)}")
            return reg
        if isinstance(key, int) and not isinstance(key, bool):
            reg = self._by_address.get(key)
            if reg is None:
                owner = self._word_owner.get(key)
                if owner is not None:
                    raise RegisterError(
                        f"{self.device}: 0x{key:04X} is the second word of {owner.name} "
                        f"(0x{owner.address:04X}, {owner.type}); address the pair at its Hi word"
                    )
                raise RegisterError(f"{self.device}: no register at address 0x{key:04X}")
            return reg
        raise RegisterError(f"{self.device}: register key must be a name or address, got {key!r}")

    def owner(self, address: int) -> Register | None:
        """The register a single 16-bit address belongs to (either word of a pair)."""
        return self._word_owner.get(address)

    def span(self, first: str | int, last: str | int) -> tuple[int, int]:
        """(start address, word count) covering registers ``first`` .. ``last`` inclusive."""
        a, b = self.get(first), self.get(last)
        return a.address, b.address + b.words - a.address

    def decode_block(self, start: int, words: Sequence[int]) -> dict[str, int]:
        """Decode a contiguous block read starting at ``start`` into {name: value}.

        Registers only partly covered, and gaps, are skipped.
        """
        plan = self._plans.get((start, len(words)))
        if plan is None:
            end = start + len(words)
            plan = tuple(
                (reg.name, reg.address - start, reg.words, reg.signed, reg.low_word_first)
                for reg in self.registers
                if reg.address >= start and reg.address + reg.words <= end
            )
            self._plans[(start, len(words))] = plan
            self._packed[(start, len(words))] = _packed_plan(plan, len(words))
        packed = self._packed[(start, len(words))]
        if packed is not None:  # one struct call each way (words out of 0..0xFFFF: the loop below)
            names, as_words, as_values = packed
            try:
                return dict(zip(names, as_values.unpack(as_words.pack(*words))))
            except struct.error:
                pass
        out: dict[str, int] = {}
        for name, i, n, signed, low_first in plan:
            if n == 1:
                raw = words[i] & 0xFFFF
                out[name] = raw - 0x10000 if signed and raw & 0x8000 else raw
            else:
                a, b = words[i] & 0xFFFF, words[i + 1] & 0xFFFF
                raw = (b << 16 | a) if low_first else (a << 16 | b)
                out[name] = raw - 0x100000000 if signed and raw & 0x80000000 else raw
        return out

    def encode_block(self, values: Mapping[Any, int]) -> tuple[int, list[int]]:
        """Encode several registers that form one contiguous block -> (start, words)."""
        regs = sorted((self.get(k) for k in values), key=lambda r: r.address)
        if not regs:
            raise CommandError("encode_block: no registers given")
        start = regs[0].address
        words: list[int] = []
        expect = start
        raw = {self.get(k).name: v for k, v in values.items()}
        for reg in regs:
            if reg.address != expect:
                raise CommandError(
                    f"{self.device}: registers are not contiguous at 0x{expect:04X} "
                    f"(next is {reg.name} at 0x{reg.address:04X})"
                )
            words.extend(reg.to_words(raw[reg.name]))
            expect = reg.address + reg.words
        return start, words

    def names(self) -> list[str]:
        return [r.name for r in self.registers]

    @property
    def params(self) -> ParamSet:
        """The parameters these registers carry (one per register, by the same name)."""
        cached = self.__dict__.get("_params")
        if cached is None:
            cached = ParamSet(self.device, (r.param for r in self.registers))
            object.__setattr__(self, "_params", cached)
        return cached

    def as_map(self, params: ParamSet | None = None) -> ParamMap[Register]:
        """This table as the Modbus RTU map of ``params`` (default: its own parameters)."""
        return ParamMap("modbus-rtu", params or self.params, {r.name: r for r in self.registers})

    @staticmethod
    def build(device: str, registers: Iterable[Register]) -> RegisterTable:
        return RegisterTable(device, tuple(sorted(registers, key=lambda r: r.address)))
