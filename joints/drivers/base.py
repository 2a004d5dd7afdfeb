"""The driver contract: parameter-level logic of one device family, in the device's own units.

Rule: drivers never touch bytes (they call a :class:`~joints.drivers.access.ParamAccess`, which
calls a link) and never read the wall clock (they are given a clock). They speak in parameter
names, so one family's logic serves every protocol that reaches the same parameters. The same
driver object runs against hardware and against a twin. SI units, user limits and safety policy
live one layer up, in :class:`joints.joint.Joint`. Optional abilities (a shared status read,
synchronous multi-channel commands, a communication watchdog) are the typed protocols of
:mod:`joints.drivers.capabilities`.
"""

from __future__ import annotations

import abc
import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, TypeVar

from joints.devices.faults import Fault
from joints.devices.params import Param, ParamSet
from joints.drivers.access import ParamAccess
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


_T = TypeVar("_T")


def slots_maker(cls: type[_T]) -> Callable[..., _T]:
    """A function making an instance of the frozen slots dataclass ``cls`` from ALL its fields, positionally, in
    their order: the same object as ``cls(...)`` (no ``__post_init__``, defaults not applied), each field set by its
    slot's descriptor - what the generated ``__init__`` does through ``object.__setattr__``, at about half the
    cost (a state is made per joint per read)."""
    names = [f.name for f in dataclasses.fields(cls)]  # type: ignore[arg-type]
    if hasattr(cls, "__post_init__") or "__slots__" not in cls.__dict__ or any(n.startswith("_") for n in names):
        raise TypeError(f"slots_maker: {cls.__name__} is not a plain slots dataclass")
    scope: dict[str, Any] = {"_new": object.__new__, "_cls": cls}
    lines = [f"def make({', '.join(names)}):", "    o = _new(_cls)"]
    for i, n in enumerate(names):
        scope[f"_set{i}"] = cls.__dict__[n].__set__
        lines.append(f"    _set{i}(o, {n})")
    lines.append("    return o")
    exec("\n".join(lines), scope)  # noqa: S102 - generated from the class's own field names, as dataclasses does
    make: Callable[..., _T] = scope["make"]
    make.__doc__ = f"{cls.__name__}({', '.join(names)}), every field given"
    return make


def sampled_at(sent: float, received: float) -> float:
    """When a status read between ``sent`` (before its request) and ``received`` (after its reply) was
    sampled: the drive samples after the request has arrived and before it answers, an instant the
    host cannot see; the middle of the transaction is off by at most half of it and lies inside it."""
    return 0.5 * (sent + received)


@dataclass(frozen=True, slots=True)
class RawState:
    """One status snapshot in device units (what the drive reports)."""

    position: int
    velocity: int
    current: float  #: NaN where the protocol does not report it
    temperature: float  #: NaN where the protocol does not report it
    enabled: bool
    moving: bool
    fault: int  #: device error code, 0 = none
    time: float  #: clock time of the sample: the middle of its transaction (:func:`sampled_at`)
    extra: Mapping[str, int] = field(default_factory=dict)


#: ``RawState(position, velocity, current, temperature, enabled, moving, fault, time, extra)``, every field given
#: (:func:`slots_maker`: the status read's per-joint object, at about half the cost)
raw_state = slots_maker(RawState)


class JointDriver(abc.ABC):
    """One joint on one drive (a dual-channel drive has one driver per channel)."""

    device: str = ""
    name: str = ""
    access: ParamAccess
    units: Units

    @property
    def params(self) -> ParamSet:
        """The family's parameters (by manual name), as this driver's protocol reaches them."""
        return self.access.params

    @property
    def protocol(self) -> str:
        return self.access.protocol

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

    def fault(self, code: int) -> Fault | None:
        """The drive's fault for an error code (None for 0); drivers give each code its name."""
        if not code:
            return None
        return Fault(code, "drive_error", self.fault_text(code), "clear the fault, then enable again", self.device)

    # -- parameters --
    def describe(self, key: str | int) -> tuple[Param, str]:
        """The parameter for a name or protocol address, and where it lives on this protocol."""
        name = self.access.resolve(key)
        return self.params[name], self.access.where(name)

    def read(self, key: str | int) -> int:
        """Read one parameter by manual name (or protocol address)."""
        name = self.access.resolve(key)
        p = self.params[name]
        if not p.access.readable:
            raise RegisterError(f"{self.device}: {name} ({self.access.where(name)}) cannot be read "
                                f"({p.access.value}); nothing was sent")
        return self.access.read(name)

    def write(self, key: str | int, value: int, *, confirm: bool = False) -> None:
        """Write one parameter by manual name or address (persistent ones need ``confirm=True``)."""
        name = self.access.resolve(key)
        p = self.params[name]
        if not p.access.writable:
            raise RegisterError(f"{self.device}: {name} ({self.access.where(name)}) is read-only; nothing was sent")
        if p.persistent and not confirm:
            raise ConfirmationRequired(
                f"{self.device}: writing {name} ({self.access.where(name)}) is persistent or dangerous; "
                "pass confirm=True if you mean it"
            )
        self.write_param(name, value)

    def write_param(self, name: str, value: int) -> None:
        """Write a parameter the driver may track (range-checked; subclasses note what they write)."""
        self.access.write(name, value)

    @property
    @abc.abstractmethod
    def is_enabled(self) -> bool: ...

    def forget(self) -> None:
        """The drive was power-cycled: drop cached settings and count it as disabled."""

    def close(self) -> None:
        """Release driver resources (the bus is closed by the rig)."""
