"""Joint: what users hold. SI units, limits and safety on top of a device driver.

Rules:

* Every command is checked against the joint's limits BEFORE anything is sent - raw parameter
  writes of motion targets included; a command outside them raises :class:`~joints.errors.LimitError`
  (naming the joint, the value and the limit) and the motor does not move.
* "Enabled", "fault" and "moving" are what the drive reports. A drive that faulted is reported by
  name (:class:`~joints.devices.faults.Fault`) at the next state read, and ``enable``,
  ``move_to``, ``set_velocity`` and ``set_torque`` refuse to act on it with an error that says how
  to clear it.
* While enabled, the drive's communication watchdog is armed (where it has one) and the configured
  limits are in the drive's own limit parameters (volatile), so the drive stops if the host dies.
  Disabling restores the watchdog setting found before.

Units: position rad, velocity rad/s, acceleration rad/s^2, torque N*m, current A. A joint with a
``lead`` (m of travel per motor turn: a lead screw, a belt) is linear: position m, velocity m/s,
acceleration m/s^2 and force N (``torque`` = motor torque x 2 pi / lead, an ideal screw); its
limits are in the same units. Whatever the drive counts (encoder counts, pulses) stays motor side.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from joints.clock import Clock
from joints.configtypes import Limits, Motion
from joints.devices.faults import Fault
from joints.drivers.base import JointDriver, RawState, Units, slots_maker
from joints.drivers.capabilities import CommunicationWatchdog, DriveLimits, MotionTargets
from joints.errors import CommandError, DeviceFault, LimitError, MotionTimeout, StateError

__all__ = ["Joint", "JointState", "Limits", "Motion"]  # Limits, Motion: joints.configtypes, still importable here


@dataclass(frozen=True, slots=True)
class JointState:
    """One snapshot of a joint in SI units, as the drive reports it."""

    position: float  #: rad (m with a lead)
    velocity: float  #: rad/s (m/s with a lead)
    torque: float  #: N*m (N with a lead; from motor current through the device profile)
    current: float  #: A
    temperature: float  #: degC
    enabled: bool
    moving: bool
    fault: Fault | None  #: the drive's fault by name, None when there is none
    time: float  #: s, on the rig's clock (simulated time in sim)
    raw: RawState | None = field(default=None, repr=False, compare=False)


#: ``JointState(...)`` of every field, positionally (:func:`~joints.drivers.base.slots_maker`: a state per joint per
#: read, at about half the cost of the frozen dataclass's ``__init__``)
_joint_state = slots_maker(JointState)


class Joint:
    """One actuated joint."""

    def __init__(
        self,
        name: str,
        driver: JointDriver,
        *,
        clock: Clock,
        limits: Limits | None = None,
        motion: Motion | None = None,
        offset: float = 0.0,
        direction: int = 1,
        watchdog_ms: int | None = None,
        lead: float | None = None,
    ) -> None:
        if direction not in (1, -1):
            raise CommandError(f"joint {name}: direction must be 1 or -1, got {direction}")
        if lead is not None and not (isinstance(lead, (int, float)) and math.isfinite(lead) and lead > 0):
            raise CommandError(f"joint {name}: lead must be a positive number of metres per motor turn, got {lead!r}")
        self.name = name
        self.driver = driver
        self.clock = clock
        self.limits = limits or Limits()
        self.motion = motion or Motion()
        self.offset = offset  #: rad (m with a lead) added to the device position (user zero)
        self.direction = direction
        #: m of travel per motor turn (None: a rotary joint)
        self.lead = lead
        #: SI position per motor radian: lead / 2 pi for a linear joint, 1 for a rotary one
        self.scale = lead / (2.0 * math.pi) if lead is not None else 1.0
        self._u = ("m", "m/s", "m/s^2", "N") if lead is not None else ("rad", "rad/s", "rad/s^2", "N*m")
        #: the drive's communication watchdog while enabled [ms] (None: leave the drive's setting, 0: off)
        self.watchdog_ms = watchdog_ms
        self._enabled_by_us = False
        self._watchdog_before: int | None = None
        #: the last state read from the drive (None before the first read)
        self.last_state: JointState | None = None
        #: clock time of the last frame exchanged with the drive through this joint
        self.last_contact = -math.inf
        #: move_to profiles already checked: (velocity, acceleration, deceleration) arguments ->
        #: (what they were checked against, their device units)
        self._profiles: dict[tuple[float | None, float | None, float | None],
                             tuple[tuple[Any, ...], tuple[int, int, int]]] = {}
        #: how this joint waits (the rig's sleep: it keeps every drive of the rig fed meanwhile)
        self.sleep: Callable[[float], None] = clock.sleep

    def __repr__(self) -> str:
        return f"Joint({self.name!r}, {self.driver.device}, enabled={self.driver.is_enabled})"

    # -- unit conversion --------------------------------------------------------------------
    @property
    def units(self) -> Units:
        return self.driver.units

    def _to_pos(self, rad: float) -> int:
        return round((rad - self.offset) * self.direction / (self.units.position * self.scale))

    def _from_pos(self, counts: float) -> float:
        return counts * self.units.position * self.scale * self.direction + self.offset

    def _to_vel(self, rad_s: float) -> int:
        return round(rad_s * self.direction / (self.units.velocity * self.scale))

    def _to_current(self, torque: float) -> int:
        """Joint torque [N*m; N with a lead] -> the driver's current units (through the torque constant)."""
        return round(torque * self.scale * self.direction / self.units.torque_constant / self.units.current)

    def _to_acc(self, rad_s2: float) -> int:
        return max(1, round(abs(rad_s2) / (self.units.velocity * self.scale)))

    # -- checks -----------------------------------------------------------------------------
    def _finite(self, what: str, value: float) -> float:
        if type(value) is float and value - value == 0.0:  # the common case: a finite float
            return value
        # numbers.Real also admits numpy scalars (np.float32 from a gymnasium action is no float)
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
            raise CommandError(f"joint {self.name}: {what} must be a finite number, got {value!r}")
        return float(value)

    def _check_position(self, rad: float, what: str = "position") -> None:
        lim = self.limits.position
        if lim is not None and not lim[0] <= rad <= lim[1]:
            u = self._u[0]
            raise LimitError(
                f"joint {self.name}: {what} {rad:.4f} {u} is outside the limits "
                f"[{lim[0]:.4f}, {lim[1]:.4f}] {u}; nothing was sent"
            )

    def _check_velocity(self, v: float, what: str = "velocity") -> None:
        lim = self.limits.velocity
        if lim is not None and abs(v) > lim:
            raise LimitError(
                f"joint {self.name}: {what} {v:.4f} {self._u[1]} exceeds the limit {lim:.4f} {self._u[1]}; "
                "nothing was sent"
            )

    def _check_torque(self, torque: float, what: str = "torque") -> None:
        lim = self.limits.torque
        if lim is not None and abs(torque) > lim:
            raise LimitError(
                f"joint {self.name}: {what} {torque:.3f} {self._u[3]} exceeds the limit {lim:.3f} {self._u[3]}; "
                "nothing was sent"
            )

    def _check_accel(self, a: float, what: str) -> None:
        if a <= 0:
            raise CommandError(f"joint {self.name}: {what} must be > 0 {self._u[2]}, got {a}")
        lim = self.limits.acceleration
        if lim is not None and a > lim:
            raise LimitError(
                f"joint {self.name}: {what} {a:.4f} {self._u[2]} exceeds the limit {lim:.4f}; nothing was sent"
            )

    def _require_enabled(self) -> None:
        if not self.driver.is_enabled:
            raise StateError(f"joint {self.name} is not enabled; call enable() first")

    def _fault_error(self, fault: Fault, doing: str) -> DeviceFault:
        return DeviceFault(f"joint {self.name}", fault.code, fault.text + (f"; {doing} refused" if doing else ""),
                           hint=fault.clears, name=fault.name)

    def _refuse_if_faulted(self, doing: str) -> None:
        """Commands refuse to act on a drive whose last reported state shows a fault."""
        s = self.last_state
        if s is not None and s.fault is not None:
            raise self._fault_error(s.fault, doing)

    def _contact(self) -> None:
        self.last_contact = self.clock.now()

    def note_contact(self, at: float | None = None) -> None:
        """A command reached the drive by another way than this joint's methods (the sim's compiled path,
        :mod:`joints.compiled_path`): :attr:`last_contact` is now (or ``at``, the clock's instant it did)."""
        self.last_contact = self.clock.now() if at is None else at

    # -- power ------------------------------------------------------------------------------
    def enable(self) -> None:
        """Enable the drive (brake releases): arms its watchdog and writes the limits into it.

        Refuses (:class:`~joints.errors.DeviceFault`) while the drive reports a fault. Leaving the
        rig disables it again.
        """
        s = self.state()
        if s.fault is not None:
            raise self._fault_error(s.fault, "enable")
        driver = self.driver
        # Mark first: if the reply to "enable" is lost the drive may be enabled all the same,
        # and leaving the rig must then still try to disable it.
        self._enabled_by_us = True
        if self.watchdog_ms is not None and isinstance(driver, CommunicationWatchdog):
            if self._watchdog_before is None:
                self._watchdog_before = driver.communication_timeout()
            driver.set_communication_timeout(self.watchdog_ms)
        if isinstance(driver, DriveLimits):
            self._apply_drive_limits(driver)
        driver.enable()
        self._contact()

    def _apply_drive_limits(self, driver: DriveLimits) -> None:
        lim = self.limits
        u = self.units
        position = None
        if lim.position is not None:
            a, b = self._to_pos(lim.position[0]), self._to_pos(lim.position[1])
            position = (min(a, b), max(a, b))
        velocity = None if lim.velocity is None else max(1, round(lim.velocity / (u.velocity * self.scale)))
        current = (None if lim.torque is None
                   else max(1, round(lim.torque * self.scale / u.torque_constant / u.current)))
        if position is not None or velocity is not None or current is not None:
            driver.apply_limits(position=position, velocity=velocity, current=current)

    def disable(self) -> None:
        """Disable the drive (brake engages); the watchdog goes back to what it was before enable()."""
        self.driver.disable()
        self._enabled_by_us = False
        self._contact()
        self._restore_watchdog()

    def _restore_watchdog(self) -> None:
        driver = self.driver
        if self._watchdog_before is not None and isinstance(driver, CommunicationWatchdog):
            before, self._watchdog_before = self._watchdog_before, None
            driver.set_communication_timeout(before)

    def driver_reset(self) -> None:
        """The drive was power-cycled (sim reset): it is disabled and holds no settings."""
        self.driver.forget()
        self._enabled_by_us = False
        self._watchdog_before = None
        self.last_state = None

    @property
    def enabled(self) -> bool:
        """Whether the drive is enabled, as it last said (host bookkeeping corrected by every state read)."""
        return self.driver.is_enabled

    # -- motion -----------------------------------------------------------------------------
    def move_to(
        self,
        position: float,
        *,
        velocity: float | None = None,
        acceleration: float | None = None,
        deceleration: float | None = None,
    ) -> None:
        """Move to ``position`` [rad] with the drive's own trapezoidal profile."""
        target, speed, acc, dec = self.position_command(position, velocity, acceleration, deceleration)
        self.driver.move_to(target, speed=speed, acceleration=acc, deceleration=dec)
        self._contact()

    def position_command(
        self,
        position: float,
        velocity: float | None = None,
        acceleration: float | None = None,
        deceleration: float | None = None,
    ) -> tuple[int, int, int, int]:
        """Check a :meth:`move_to` against the limits, the last fault and the enable state; return it in
        device units (target, profile speed, acceleration, deceleration). Nothing is sent."""
        if type(position) is not float or position - position != 0.0:  # not a finite float: _finite decides
            position = self._finite("position", position)
        profile = (velocity, acceleration, deceleration)
        known = self._profiles.get(profile)
        units = self.driver.units
        if known is None or known[0] != (self.motion, self.limits, units, self.direction):
            v = self._finite("velocity", self.motion.velocity if velocity is None else velocity)
            a = self._finite("acceleration", self.motion.acceleration if acceleration is None else acceleration)
            d = self._finite("deceleration", self.motion.deceleration if deceleration is None else deceleration)
            self._check_position(position)
            if v <= 0:
                raise CommandError(f"joint {self.name}: profile velocity must be > 0 {self._u[1]}, got {v}")
            self._check_velocity(v, "profile velocity")
            self._check_accel(a, "acceleration")
            self._check_accel(d, "deceleration")
            known = ((self.motion, self.limits, units, self.direction),
                     (abs(self._to_vel(v)), self._to_acc(a), self._to_acc(d)))
            if len(self._profiles) < 64:  # a checked profile is reused as it is (device units)
                self._profiles[profile] = known
        else:  # the profile was checked before: only the position is new
            lim = self.limits.position
            if lim is not None and not lim[0] <= position <= lim[1]:
                self._check_position(position)  # raises
        last = self.last_state
        if last is not None and last.fault is not None:
            self._refuse_if_faulted("move_to")  # raises
        if not self.driver.is_enabled:
            self._require_enabled()  # raises
        speed, acc, dec = known[1]
        # _to_pos, inlined
        return round((position - self.offset) * self.direction / (units.position * self.scale)), speed, acc, dec

    def move_by(self, delta: float, **kw: float) -> None:
        """Move by ``delta`` [rad] from the present position (checked against the limits)."""
        delta = self._finite("delta", delta)
        here = self.state().position
        self.move_to(here + delta, **kw)

    def velocity_command(self, velocity: float, acceleration: float | None = None) -> tuple[int, int]:
        """Check a velocity command against the limits; return it in device units (velocity, ramp)."""
        if type(velocity) is not float or velocity - velocity != 0.0:  # not a finite float: _finite decides
            velocity = self._finite("velocity", velocity)
        lim = self.limits.velocity
        if lim is not None and abs(velocity) > lim:
            self._check_velocity(velocity)  # raises
        a = self.motion.acceleration if acceleration is None else acceleration
        if type(a) is not float or a - a != 0.0:
            a = self._finite("acceleration", a)
        top = self.limits.acceleration
        if a <= 0 or top is not None and a > top:
            self._check_accel(a, "acceleration")  # raises
        last = self.last_state
        if last is not None and last.fault is not None:
            self._refuse_if_faulted("set_velocity")  # raises
        driver = self.driver
        if not driver.is_enabled:
            self._require_enabled()  # raises
        self.last_contact = self.clock.now()  # _contact
        # _to_vel and _to_acc, inlined
        per = driver.units.velocity * self.scale
        return round(velocity * self.direction / per), max(1, round(abs(a) / per))

    def set_velocity(self, velocity: float, *, acceleration: float | None = None) -> None:
        """Run at ``velocity`` [rad/s] (speed control) until stop() or another command."""
        v, acc = self.velocity_command(velocity, acceleration)
        self.driver.set_velocity(v, acceleration=acc, deceleration=acc)

    def set_torque(self, torque: float) -> None:
        """Apply ``torque`` [N*m] (current control through the device's torque constant)."""
        self.driver.set_current(self.torque_command(torque))
        self._contact()

    def torque_command(self, torque: float) -> int:
        """Check a :meth:`set_torque` against the limit, the last fault and the enable state; return it in the
        driver's current units. Nothing is sent."""
        if type(torque) is not float or torque - torque != 0.0:  # not a finite float: _finite decides
            torque = self._finite("torque", torque)
        lim = self.limits.torque
        if lim is not None and abs(torque) > lim:
            self._check_torque(torque)  # raises
        last = self.last_state
        if last is not None and last.fault is not None:
            self._refuse_if_faulted("set_torque")  # raises
        driver = self.driver
        if not driver.is_enabled:
            self._require_enabled()  # raises
        u = driver.units
        return round(torque * self.scale * self.direction / u.torque_constant / u.current)  # _to_current

    def cycle_target(self, value: float, kind: str) -> int:
        """A cyclic set-point (``Rig.cycle``) in device units, checked against the limits first.

        ``kind``: "position" [rad], "velocity" [rad/s] or "torque" [N*m] (current units for the driver).
        """
        value = self._finite(kind, value)
        if kind == "position":
            self._check_position(value)
            out = self._to_pos(value)
        elif kind == "velocity":
            self._check_velocity(value)
            out = self._to_vel(value)
        elif kind == "torque":
            self._check_torque(value)
            out = self._to_current(value)
        else:
            raise CommandError(f"joint {self.name}: unknown set-point kind {kind!r}")
        self._contact()
        return out

    def stop(self) -> None:
        """Decelerate to standstill with the profile deceleration."""
        self.driver.stop()
        self._contact()

    def emergency_stop(self) -> None:
        """Stop as fast as the drive can (eRob: < 50 ms)."""
        self.driver.emergency_stop()
        self._contact()

    def clear_faults(self) -> None:
        """Clear the drive's fault (then ``enable()`` again)."""
        self.driver.clear_errors()
        self._contact()
        self.last_state = None

    # -- status -----------------------------------------------------------------------------
    def state(self) -> JointState:
        """Read the joint's state (one bus transaction where the device allows)."""
        return self.to_si(self.driver.state())

    def to_si(self, raw: RawState) -> JointState:
        """A drive state in SI units; it becomes :attr:`last_state`."""
        driver = self.driver
        u = driver.units
        scale, direction = self.scale, self.direction
        amps = raw.current * u.current * direction
        fault = raw.fault
        t = raw.time
        # JointState(position, velocity, torque, current, temperature, enabled, moving, fault, time, raw); the
        # position is _from_pos's, each product in the order it is written (the same bits)
        s = _joint_state(raw.position * u.position * scale * direction + self.offset,
                         raw.velocity * u.velocity * scale * direction,
                         amps * u.torque_constant / scale, amps, raw.temperature, raw.enabled, raw.moving,
                         driver.fault(fault) if fault else None, t, raw)
        self.last_state = s
        self.last_contact = t
        return s

    def check(self) -> None:
        """Read the state; raise :class:`DeviceFault` (by name, with what clears it) if the drive reports a fault."""
        s = self.state()
        if s.fault is not None:
            raise self._fault_error(s.fault, "")

    def wait(self, timeout: float = 10.0, *, poll: float = 0.01, until: Callable[[JointState], bool] | None = None) -> JointState:
        """Poll until the joint stops moving (or ``until(state)`` holds); raise on fault/timeout.

        Raises :class:`DeviceFault` when the drive reports a fault and
        :class:`~joints.errors.MotionTimeout` when ``timeout`` [s] passes first.
        """
        timeout = self._finite("timeout", timeout)
        poll = self._finite("poll", poll)
        if timeout < 0 or poll <= 0:
            raise CommandError(f"joint {self.name}: wait() needs timeout >= 0 and poll > 0, got {timeout}, {poll}")
        deadline = self.clock.now() + timeout
        while True:
            s = self.state()
            if s.fault is not None:
                raise self._fault_error(s.fault, "")
            done = until(s) if until is not None else not s.moving
            if done:
                return s
            if self.clock.now() >= deadline:
                raise MotionTimeout(f"joint {self.name}: still moving after {timeout} s")
            self.sleep(poll)

    # -- parameters -------------------------------------------------------------------------
    def read(self, key: str | int) -> int:
        """Read a parameter by manual name or protocol address (device units)."""
        value = self.driver.read(key)
        self._contact()
        return value

    def write(self, key: str | int, value: int, *, confirm: bool = False) -> None:
        """Write a parameter by manual name or address; persistent ones need ``confirm=True``.

        A motion target (a position, speed or current set-point) is checked against the joint's
        limits like the matching command: :class:`~joints.errors.LimitError`, nothing sent.
        """
        driver = self.driver
        if isinstance(driver, MotionTargets):
            name = driver.access.resolve(key)
            target = driver.motion_targets().get(name)
            if target is not None:
                kind, per_unit = target
                self._check_raw_target(name, kind, per_unit, value)
        driver.write(key, value, confirm=confirm)
        self._contact()

    def _check_raw_target(self, name: str, kind: str, per_unit: float, value: int) -> None:
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            return  # the driver's own check gives the error
        what = f"{name} = {value}"
        if kind == "position":
            self._check_position(self._from_pos(float(value)), what)
        elif kind == "relative":
            s = self.last_state or self.state()
            self._check_position(s.position + float(value) * per_unit * self.scale * self.direction, what)
        elif kind == "velocity":
            self._check_velocity(float(value) * per_unit * self.scale, what)
        elif kind == "current":
            self._check_torque(float(value) * per_unit * self.units.torque_constant / self.scale, what)

    def shutdown(self) -> None:
        """Stop and disable if it was enabled through this joint (``enable()`` or a raw write of
        the enable parameter; used when leaving the rig), and restore the watchdog. Best effort."""
        if not (self._enabled_by_us or self.driver.is_enabled):
            self._restore_watchdog()
            return
        try:
            self.driver.stop()
        finally:
            try:
                self.driver.disable()
                self._enabled_by_us = False
            finally:
                self._restore_watchdog()
