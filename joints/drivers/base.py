"""The driver contract: register-level logic of one device family, in the device's own units.

Rule: drivers never touch bytes (they call a link) and never read the wall clock (they are given
a clock). The same driver object runs against hardware and against an emulator. SI units, user
limits and safety policy live one layer up, in :class:`joints.joint.Joint`.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from joints.devices.registers import Register, RegisterTable
from joints.errors import ConfirmationRequired, RegisterError


@dataclass(frozen=True, slots=True)
class Units:
    """How device units map to SI for one joint."""

    position: float  #: rad per position unit (e.g. 2*pi/524288 per count)
    velocity: float  #: rad/s per velocity unit
    current: float  #: A per current unit (e.g. 0.001 for mA)
    torque_constant: float  #: N*m per A at the output

    @staticmethod
    def from_counts(counts_per_rev: int, current_unit: float, torque_constant: float) -> Units:
        rad = 2.0 * math.pi / counts_per_rev
        return Units(rad, rad, current_unit, torque_constant)


@dataclass(frozen=True, slots=True)
class RawState:
    """One status snapshot in device units (what the drive reports)."""

    position: int
    velocity: int
    current: int
    temperature: float
    enabled: bool
    moving: bool
    fault: int  #: device error code, 0 = none
    time: float  #: clock time of the read
    extra: Mapping[str, int] = field(default_factory=dict)


class JointDriver(abc.ABC):
    """One joint on one drive (a dual-channel drive has one driver per channel)."""

    device: str = ""
    table: RegisterTable
    units: Units

    # -- power --
    @abc.abstractmethod
    def enable(self) -> None: ...

    @abc.abstractmethod
    def disable(self) -> None: ...

    # -- motion (device units) --
    @abc.abstractmethod
    def move_to(self, position: int, *, speed: int | None = None, acceleration: int | None = None,
                deceleration: int | None = None) -> None: ...

    @abc.abstractmethod
    def move_by(self, delta: int, *, speed: int | None = None, acceleration: int | None = None,
                deceleration: int | None = None) -> None: ...

    @abc.abstractmethod
    def set_velocity(self, velocity: int, *, acceleration: int | None = None,
                     deceleration: int | None = None) -> None: ...

    @abc.abstractmethod
    def set_current(self, current: int) -> None: ...

    @abc.abstractmethod
    def stop(self) -> None: ...

    @abc.abstractmethod
    def emergency_stop(self) -> None: ...

    @abc.abstractmethod
    def clear_errors(self) -> None: ...

    # -- status --
    @abc.abstractmethod
    def state(self) -> RawState: ...

    @abc.abstractmethod
    def fault_text(self, code: int) -> str: ...

    # -- registers --
    @abc.abstractmethod
    def read(self, key: str | int) -> int: ...

    @abc.abstractmethod
    def write_register(self, reg: Register, value: int) -> None: ...

    def write(self, key: str | int, value: int, *, confirm: bool = False) -> None:
        """Write one register by manual name or address (persistent ones need ``confirm=True``)."""
        reg = self.table.get(key)
        if not reg.access.writable:
            raise RegisterError(
                f"{self.device}: {reg.name} (0x{reg.address:04X}) is read-only; nothing was sent"
            )
        if reg.persistent and not confirm:
            raise ConfirmationRequired(
                f"{self.device}: writing {reg.name} (0x{reg.address:04X}) is persistent or "
                "dangerous; pass confirm=True if you mean it"
            )
        self.write_register(reg, value)

    @property
    @abc.abstractmethod
    def is_enabled(self) -> bool: ...

    def forget(self) -> None:
        """The drive was power-cycled: drop cached settings and count it as disabled."""

    def close(self) -> None:
        """Release driver resources (the bus is closed by the rig)."""
