"""Parameter access: how a driver reads and writes one drive's parameters over its protocol.

Rule: drivers speak in parameter names (the family's :class:`~joints.devices.params.ParamSet`);
a :class:`ParamAccess` turns them into the protocol's transactions on a link, in as few as the
protocol allows (one Modbus FC03 for a contiguous block, one FC16 for contiguous settings). No
bytes here: the link and codec do the I/O. Each protocol adds one access class.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping, Sequence
from typing import Any

from joints.codecs import modbus as mb
from joints.devices.params import Param, ParamSet
from joints.devices.registers import RegisterTable
from joints.errors import CommandError, RegisterError


class ParamAccess(abc.ABC):
    """One drive's parameters over one protocol."""

    params: ParamSet
    protocol: str = ""

    @abc.abstractmethod
    def resolve(self, key: str | int) -> str:
        """The parameter name for a name or a protocol address (raises :class:`RegisterError`)."""

    @abc.abstractmethod
    def where(self, name: str) -> str:
        """Where the parameter lives on this protocol, for people (``0x0066``, ``0x6064:00`` ...)."""

    @abc.abstractmethod
    def read(self, name: str) -> int: ...

    def read_many(self, names: Sequence[str]) -> dict[str, int]:
        """Several parameters (at least ``names``), in as few transactions as the protocol allows."""
        return {n: self.read(n) for n in names}

    @abc.abstractmethod
    def write(self, name: str, value: int, *, idempotent: bool = True) -> None:
        """Write one parameter (range-checked first); ``idempotent=False`` for commands: never retried."""

    def write_many(self, values: Mapping[str, int], *, idempotent: bool = True) -> None:
        """Several settings, in as few transactions as the protocol allows (each checked before any is sent)."""
        for n, v in values.items():
            self.params[n].check(v)
        for n, v in values.items():
            self.write(n, v, idempotent=idempotent)

    def param(self, key: str | int) -> Param:
        return self.params[self.resolve(key)]


class ModbusAccess(ParamAccess):
    """Parameters as Modbus RTU holding registers of one slave (FC03 / FC06 / FC16)."""

    protocol = "modbus-rtu"

    def __init__(self, link: Any, slave: int, table: RegisterTable, params: ParamSet | None = None) -> None:
        self.link = link
        self.slave = slave
        self.table = table
        self.params = params or table.params
        self._plans: dict[tuple[str, ...], tuple[tuple[int, int], ...]] = {}

    def resolve(self, key: str | int) -> str:
        if isinstance(key, str) and key in self.params and key not in self.table:
            raise RegisterError(f"{self.params.device}: {key!r} cannot be reached over Modbus RTU")
        return self.table.get(key).name

    def where(self, name: str) -> str:
        return f"0x{self.table[name].address:04X}"  # a 32-bit pair is addressed at its Hi word

    def read(self, name: str) -> int:
        reg = self.table[name]
        return reg.from_words(self.link.read_registers(self.slave, reg.address, reg.words))

    def read_block(self, start: int, count: int) -> dict[str, int]:
        """Every register wholly inside ``count`` words from ``start``, in one FC03."""
        return self.table.decode_block(start, self.link.read_registers(self.slave, start, count))

    def read_many(self, names: Sequence[str]) -> dict[str, int]:
        plan = self.block_plan(names)
        if len(plan) == 1:  # one block: its decoded registers as they come
            return self.read_block(*plan[0])
        out: dict[str, int] = {}
        for start, count in plan:
            out.update(self.read_block(start, count))
        return out

    def _plan(self, names: Sequence[str]) -> tuple[tuple[int, int], ...]:
        """Blocks of at most 125 words covering the registers (gaps inside a block are read too)."""
        regs = sorted({self.table[n].address: self.table[n] for n in names}.values(), key=lambda r: r.address)
        blocks: list[tuple[int, int]] = []
        for reg in regs:
            end = reg.address + reg.words
            if blocks and end - blocks[-1][0] <= 125 and reg.address - (blocks[-1][0] + blocks[-1][1]) <= 8:
                blocks[-1] = (blocks[-1][0], end - blocks[-1][0])
            else:
                blocks.append((reg.address, reg.words))
        return tuple(blocks)

    def write(self, name: str, value: int, *, idempotent: bool = True) -> None:
        self.link.request(self.write_request(name, value), idempotent=idempotent)

    def write_request(self, name: str, value: int) -> mb.Request:
        """The request :meth:`write` sends (range-checked): FC06 for one word, FC16 for a 32-bit pair."""
        reg = self.table.get(name)
        words = reg.to_words(value)
        if len(words) == 1:
            return mb.WriteSingleRegister(self.slave, reg.address, words[0])
        return mb.WriteMultipleRegisters(self.slave, reg.address, tuple(words))

    def block_plan(self, names: Sequence[str]) -> tuple[tuple[int, int], ...]:
        """The FC03 blocks (start, count) :meth:`read_many` reads for ``names`` (cached)."""
        key = names if type(names) is tuple else tuple(names)
        plan = self._plans.get(key)
        if plan is None:
            plan = self._plans[key] = self._plan(names)
        return plan

    def write_many(self, values: Mapping[str, int], *, idempotent: bool = True) -> None:
        """One FC16 when the registers are contiguous, else one write each (all checked first)."""
        try:
            start, words = self.table.encode_block(values)
        except CommandError:
            for n, v in values.items():
                self.table[n].check(v)
            for n, v in values.items():
                self.write(n, v, idempotent=idempotent)
            return
        self.link.write_registers(self.slave, start, words, idempotent=idempotent)
