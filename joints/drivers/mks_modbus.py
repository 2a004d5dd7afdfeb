"""MKS SERVO42D/57D in Modbus-RTU mode (manual Part 8): the Part 8 requests as the parameter access.

Rule: the procedures are :class:`~joints.drivers.mks.MksDriver`'s, by the same parameter names as
the native protocol, so switching a bus between ``mks-serial`` and ``modbus-rtu`` changes nothing
above the driver. Each parameter lives in one Part 8 request of the map of the drive's firmware profile
(:func:`~joints.devices.mks.modbus.modbus_map`, the twin's too; 0x3B's layout changed in V1.0.7): FC04 reads (one
per quantity; the blocks are command codes, not a register file), FC06 single settings and
commands, FC16 multi-field commands sent whole (the other fields from the image of what was
written). Modbus mode has no completion frames: :meth:`~joints.drivers.mks.MksDriver.wait_motion`
polls 0xF1. The FC16 0x90 home-parameter request is the manual's own frame (3 registers, 5 bytes,
ERRATA DOC-MKS-5), sent as is with :meth:`~joints.link.modbus.ModbusLink.write_pdu`. Native-only
quantities (0x8C respond/active, 0x8D group address, 0x94 'noLimit' homing before V1.0.6) raise
:class:`~joints.errors.RegisterError`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import partial

from joints.clock import Clock
from joints.codecs import modbus as mb
from joints.devices.mks import state as st
from joints.devices.mks.modbus import FC_READ, FC_WRITE_MULTIPLE, FC_WRITE_SINGLE, MksModbusMap, ModbusBlock, modbus_map
from joints.devices.mks.params import model_params
from joints.devices.mks.profile import MksProfile
from joints.devices.params import ParamSet
from joints.devices.quirks import MKS_FAILURE_REPLIES, FirmwareProfile
from joints.drivers.mks import MksAccess, MksDriver, MksHeartbeat
from joints.errors import CommandError, RegisterError
from joints.link.modbus import ModbusLink

__all__ = ["MksModbusAccess", "MksModbusDriver", "MksModbusHeartbeatDriver"]

#: FC06 register data of a failed write (V1.0.6+)
_FAILED = 0xFFFF


class MksModbusAccess(MksAccess):
    """One drive's parameters as Part 8 requests (see the module docstring)."""

    protocol = "modbus-rtu"

    def __init__(self, link: ModbusLink, slave: int, params: ParamSet) -> None:
        super().__init__(params)
        self.link = link
        self.slave = slave

    @property
    def map(self) -> MksModbusMap:
        """The Part 8 map of this drive's firmware profile (the features the driver set)."""
        return modbus_map(self.features)

    def resolve(self, key: str | int) -> str:
        if isinstance(key, int):
            for fc in (FC_READ, FC_WRITE_SINGLE, FC_WRITE_MULTIPLE):
                block = self.map.find(fc, key)
                if block is not None:
                    if len(block.fields) != 1:
                        raise RegisterError(f"{self.params.device}: 0x{key:04X} carries "
                                            f"{', '.join(f.name for f in block.fields)}: name the parameter")
                    return block.fields[0].name
            raise RegisterError(f"{self.params.device}: no Part 8 request at 0x{key:04X}")
        self.require((key,))  # a later firmware's parameter: say which (its map may not reach it either)
        self.map.get(key)
        return key

    def where(self, name: str) -> str:
        f = self.map.get(name)
        return f"FC{f.function:02d} 0x{f.address:04X}"

    def holds_failed_value(self, address: int) -> bool | None:
        """After an FC06 write of 0xFFFF to ``address`` answered with 0xFFFF (the failure reply, V1.0.6+): False
        where the parameter cannot take that value (the answer is the refusal), else None - no Part 8 read
        returns an FC06 setting, so the outcome cannot be told (no FC06 parameter takes 0xFFFF today)."""
        block = self.map.find(FC_WRITE_SINGLE, address)
        if block is None:
            return None  # a register this map does not know: whether it takes 0xFFFF is unknown
        for name, value in block.decode_words((_FAILED,)).items():  # a register may carry flag bits beside a value
            try:
                self.params[name].check(value)
            except CommandError:
                return False
        return None

    def read_version(self, *, retry: bool = True) -> int:
        """FC04 0x0040 (V1.0.9) version word; ``retry=False``: one attempt (a probe)."""
        block = self.map.block_of("version_information")
        reply = self.link.request(mb.ReadInputRegisters(self.slave, block.address, block.count), idempotent=retry)
        if not isinstance(reply, mb.ReadRegistersReply):
            raise CommandError(f"{self.params.device}@{self.slave}: no version reply")
        return block.decode_words(reply.values)["version_information"]

    def read_many(self, names: Sequence[str]) -> dict[str, int]:
        """One FC04 per Part 8 read block."""
        self.require(names)
        blocks: dict[int, ModbusBlock] = {}
        for n in names:
            block = self.map.block_of(n)
            if block.function != FC_READ:
                raise RegisterError(f"{self.params.device}: {n} ({self.where(n)}) cannot be read: the drive does not "
                                    "report it")
            blocks[block.address] = block
        out: dict[str, int] = {}
        for block in blocks.values():
            words = self.link.read_registers(self.slave, block.address, block.count, input_registers=True)
            out.update(block.decode_words(words))
        return {n: out[n] for n in names}

    def write_many(self, values: Mapping[str, int], *, idempotent: bool = True) -> None:
        """One request per block, every field of it sent; all values checked before anything is sent."""
        self.require(values)
        groups: dict[tuple[int, int], dict[str, int]] = {}
        forms: dict[tuple[int, int], ModbusBlock] = {}
        for n, v in values.items():
            block = self.map.block_of(n)
            if block.function == FC_READ:
                raise RegisterError(f"{self.params.device}: {n} is read-only")
            key = (block.function, block.address)
            groups.setdefault(key, {})[n] = v
            if block.count > forms.get(key, block).count or key not in forms:
                forms[key] = block  # a longer form (V1.0.7's timed 0xF6) when one of its own fields is given
        planned = []
        for key, given in groups.items():
            block = forms[key]
            base = self.map.base_of(block)
            if block is not base and not any(given.get(f.name, 0) for f in block.fields
                                             if f.name not in {g.name for g in base.fields}):
                block = base  # its own fields are all 0: the short form says the same
                given = {n: v for n, v in given.items() if n in {g.name for g in base.fields}}
            full = self.merged([f.name for f in block.fields], given)
            block.encode(full)  # range-checked for the wire too
            planned.append((block, full))
        for block, full in planned:
            self.sent(full, partial(self._send, block, full, idempotent))

    def _send(self, block: ModbusBlock, values: Mapping[str, int], idempotent: bool) -> None:
        if block.function == FC_WRITE_SINGLE:
            (word,) = block.words(values)
            if word == _FAILED:  # the failure reply's value: an echo cannot tell success from failure
                raise CommandError(f"{self.params.device}: 0x{word:04X} to 0x{block.address:04X} would be answered "
                                   "like a failed write (V1.0.6+) and none of its values needs it; nothing was sent")
            self.link.write_register(self.slave, block.address, word, idempotent=idempotent)
        elif block.byte_count % 2:  # the manual's own odd frame (0x90): sent exactly as documented
            self.link.write_pdu(self.slave, mb.WRITE_MULTIPLE_REGISTERS, block.request_pdu(values),
                                idempotent=idempotent)
        else:
            self.link.write_registers(self.slave, block.address, block.words(values), idempotent=idempotent)


class MksModbusDriver(MksDriver):
    """One MKS axis on a Modbus RTU bus (the drive with 0x8E Modbus on)."""

    access: MksModbusAccess

    def __init__(
        self,
        link: ModbusLink,
        slave: int,
        *,
        device: str = "mks-servo42d",
        profile: MksProfile | str | None = None,
        clock: Clock | None = None,
        name: str = "",
        work_mode: int = st.WorkMode.SR_vFOC,
        microsteps: int | None = None,
        firmware: FirmwareProfile | str | None = None,
    ) -> None:
        if not 1 <= slave <= 247:
            raise CommandError(f"MKS Modbus slave address must be 1..247, got {slave}")
        self.link = link
        self.slave = slave
        super().__init__(MksModbusAccess(link, slave, model_params(device)), device=device, profile=profile,
                         clock=clock or link.clock, name=name or f"{device}@{slave}", work_mode=work_mode,
                         microsteps=microsteps, firmware=firmware)
        if MKS_FAILURE_REPLIES in self.firmware.features:
            link.failure_replies(slave, self.access.holds_failed_value)


class MksModbusHeartbeatDriver(MksHeartbeat, MksModbusDriver):
    """An MKS axis in Modbus mode whose firmware (V1.0.9) has the heartbeat protection: the watchdog capability."""
