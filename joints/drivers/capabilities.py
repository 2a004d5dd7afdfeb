"""Optional driver abilities as typed protocols (checked with ``isinstance``, never by probing names).

Rule: a capability is a small Protocol; a driver has it by implementing its methods. The rig and
the CLI ask ``isinstance(driver, Capability)`` and use the typed methods.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol, runtime_checkable

from joints.drivers.base import RawState


@runtime_checkable
class DriveGroup(Protocol):
    """One drive with several channels (joints): one status read serves them all."""

    def read_status(self) -> Mapping[str, int]:
        """The status of every channel, in one transaction where the protocol allows."""
        ...


@runtime_checkable
class SyncVelocityGroup(DriveGroup, Protocol):
    """A multi-channel drive that takes every channel's velocity in one command."""

    channels: tuple[str, ...]

    def set_channel_velocities(self, commands: Mapping[str, tuple[int, int]]) -> None:
        """channel -> (velocity, acceleration) in the drivers' units, sent together."""
        ...


@runtime_checkable
class GroupedChannel(Protocol):
    """A joint that is one channel of a :class:`DriveGroup`."""

    channel: str

    @property
    def group(self) -> DriveGroup: ...

    def state_from(self, status: Mapping[str, int], time: float) -> RawState:
        """This channel's state from a status read of its group."""
        ...


@runtime_checkable
class SampleGroup(Protocol):
    """The drives of one bus that one broadcast samples together (CANopen: a SYNC)."""

    def read_states(self, members: Sequence[Any]) -> Mapping[Any, RawState]:
        """The states of ``members`` (drivers of the group) from one sample instant."""
        ...


@runtime_checkable
class SampledTogether(Protocol):
    """A joint whose state is best read with the others of its :class:`SampleGroup` (one sample for all)."""

    @property
    def sample_group(self) -> SampleGroup: ...


@runtime_checkable
class SetpointGroup(Protocol):
    """The drives of one bus whose position set-points one broadcast acknowledges together (CANopen PP: each
    drive's RPDO, then one SYNC that every drive answers with its statusword)."""

    def move_together(self, moves: Mapping[Any, tuple[int, int, int, int]]) -> None:
        """driver -> (target, profile speed, acceleration, deceleration) in the drivers' units; each checked
        before anything is sent."""
        ...


@runtime_checkable
class MovedTogether(Protocol):
    """A joint whose position set-point is best sent with the others of its :class:`SetpointGroup`."""

    @property
    def setpoint_group(self) -> SetpointGroup: ...


@runtime_checkable
class CommunicationWatchdog(Protocol):
    """A drive that stops (or faults) when the host stays silent longer than a set time."""

    def set_communication_timeout(self, milliseconds: int) -> None:
        """0 switches the watchdog off."""
        ...

    def communication_timeout(self) -> int:
        """The watchdog time the drive holds now [ms] (0 = off)."""
        ...


@runtime_checkable
class DriveLimits(Protocol):
    """A drive with its own limit parameters: the joint writes its configured limits there (volatile)."""

    def apply_limits(self, *, position: tuple[int, int] | None = None, velocity: int | None = None,
                     current: int | None = None) -> None:
        """Position range, speed magnitude and current magnitude in the driver's units (None: leave it)."""
        ...


@runtime_checkable
class MotionTargets(Protocol):
    """A driver that says which parameters are motion set-points, so raw writes obey the joint's limits."""

    def motion_targets(self) -> Mapping[str, tuple[str, float]]:
        """name -> (kind, SI per unit); kind is "position" (absolute, driver position units), "relative"
        (a distance: rad per unit), "velocity" (rad/s per unit) or "current" (A per unit)."""
        ...


@runtime_checkable
class Identity(Protocol):
    """A drive that reports what it is (model, serial number, versions), e.g. for ``joints scan``."""

    def identity(self) -> dict[str, object]:
        """JSON-friendly facts by name; an ability the drive's firmware lacks is said, not guessed."""
        ...


@runtime_checkable
class PassiveState(Protocol):
    """A driver that can read the drive's state without changing anything on it.

    For tools that only look (``joints state``/``watch``/``info``): where :meth:`JointDriver.state`
    configures the drive first (CANopen: NMT, PDO mapping, mode of operation), this reads only.
    """

    def observe(self) -> RawState:
        """The state as the drive reports it, with no side effect on the drive."""
        ...


@runtime_checkable
class PulseMoves(Protocol):
    """A drive with a second position unit of its own (MKS: microstep pulses, position modes 1 and 2)."""

    def move_pulses(self, pulses: int, *, speed: int | None = None, acceleration: int | None = None) -> None:
        """Relative move by ``pulses`` (signed)."""
        ...

    def move_to_pulses(self, pulses: int, *, speed: int | None = None, acceleration: int | None = None) -> None:
        """Absolute move to the pulse position ``pulses``."""
        ...


@runtime_checkable
class SaveParameters(Protocol):
    """A drive whose settings are volatile until a save command stores them (persistent: needs confirmation)."""

    def save_parameters(self, *, confirm: bool = False) -> None: ...


@runtime_checkable
class CycleGroup(Protocol):
    """The cyclic exchange of one bus (CANopen: every joint's RPDO, one SYNC, that cycle's TPDOs)."""

    period: float  #: s between two cycles
    late: int  #: feedback frames that missed their cycle

    def send(self, targets: Mapping[object, int]) -> None:
        """Wait until the cycle is due (the rig's clock), then send each driver's set-point and the SYNC."""
        ...

    def collect(self) -> Mapping[object, RawState]:
        """This cycle's feedback per driver (returns as soon as all came, at the latest at the period's end)."""
        ...


@runtime_checkable
class CyclicJoint(Protocol):
    """A joint driven by cyclic set-points through its bus's :class:`CycleGroup` (``Rig.cycle``)."""

    @property
    def cycle_kind(self) -> str:
        """What one set-point is: "position", "velocity" or "torque" (raises if the mode is not cyclic)."""
        ...

    @property
    def group(self) -> CycleGroup: ...

