"""ZeroErr eRob over Modbus RTU (eRob Modbus manual v1.6): the registers, the slave address, the watchdog.

Rule: the procedures are :class:`~joints.drivers.erob.ErobDriver`'s, by parameter name; this
module adds only what is Modbus's own - the register table as the parameter access (contiguous
settings in one FC16, the status block in one FC03) and the communication watchdog 0x0002.
"""

from __future__ import annotations

from joints.clock import Clock
from joints.devices.erob.params import EROB_PARAMS
from joints.devices.erob.profiles import ErobProfile
from joints.devices.erob.registers import EROB_MODBUS
from joints.drivers.access import ModbusAccess
from joints.drivers.erob import (  # noqa: F401 - re-exported: the Modbus driver's vocabulary
    CMD_START,
    ENABLE_SETTLE,
    ZERO_BASE,
    CalibrationResult,
    ErobDriver,
)
from joints.errors import CommandError
from joints.link.modbus import ModbusLink


class ErobModbusDriver(ErobDriver):
    """One eRob actuator on a Modbus RTU link."""

    watchdog_param = "modbus_communication_timeout_duration"
    table = EROB_MODBUS

    def __init__(
        self,
        link: ModbusLink,
        slave: int,
        *,
        profile: ErobProfile | str | None = None,
        clock: Clock | None = None,
        name: str = "",
    ) -> None:
        if not 1 <= slave <= 247:
            raise CommandError(f"eRob Modbus slave address must be 1..247, got {slave}")
        self.link = link
        self.slave = slave
        super().__init__(ModbusAccess(link, slave, EROB_MODBUS, EROB_PARAMS), profile=profile,
                         clock=clock or link.clock, name=name or f"erob@{slave}")

    def read_block(self, first: str | int, last: str | int) -> dict[str, int]:
        """Read registers ``first``..``last`` in one FC03 and decode them by name."""
        start, count = self.table.span(first, last)
        access = self.access
        assert isinstance(access, ModbusAccess)
        return access.read_block(start, count)

    def set_communication_timeout(self, milliseconds: int) -> None:
        """Modbus Communication Timeout Duration (0x0002): 0 disables, 1..4000 ms -> fault 0xFA2."""
        self._set("modbus_communication_timeout_duration", milliseconds)

    def communication_timeout(self) -> int:
        value = self.read("modbus_communication_timeout_duration")
        self._cache["modbus_communication_timeout_duration"] = value
        return value
