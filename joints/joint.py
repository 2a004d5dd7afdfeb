"""Joint: what users hold. SI units, limits and safety on top of a device driver.

Rule: every command is checked against the joint's limits BEFORE anything is sent; a command
that fails a check raises :class:`~joints.errors.CommandError` and the motor does not move.
Units: position rad, velocity rad/s, acceleration rad/s^2, torque N*m, current A.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass, field

from joints.clock import Clock
from joints.drivers.base import JointDriver, RawState, Units
from joints.errors import CommandError, DeviceFault, MotionTimeout, StateError


@dataclass(frozen=True, slots=True)
class Limits:
    """User limits of a joint (SI). ``None`` means: only the device's own limits apply."""

    position: tuple[float, float] | None = None  #: [rad, rad]
    velocity: float | None = None  #: rad/s (magnitude)
    torque: float | None = None  #: N*m (magnitude)
    acceleration: float | None = None  #: rad/s^2 (magnitude)


@dataclass(frozen=True, slots=True)
class Motion:
    """Default profile for position moves (SI)."""

    velocity: float = 0.5  #: rad/s
    acceleration: float = 2.0  #: rad/s^2
    deceleration: float = 2.0  #: rad/s^2


@dataclass(frozen=True, slots=True)
class JointState:
    """One snapshot of a joint in SI units."""

    position: float  #: rad
    velocity: float  #: rad/s
    torque: float  #: N*m (from motor current through the device profile)
    current: float  #: A
    temperature: float  #: degC
    enabled: bool
    moving: bool
    fault: int  #: device error code, 0 = none
    time: float  #: s, on the rig's clock (simulated time in sim)
    raw: RawState | None = field(default=None, repr=False, compare=False)


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
    ) -> None:
        if direction not in (1, -1):
            raise CommandError(f"joint {name}: direction must be 1 or -1, got {direction}")
        self.name = name
        self.driver = driver
        self.clock = clock
        self.limits = limits or Limits()
        self.motion = motion or Motion()
        self.offset = offset  #: rad added to the device position (user zero)
        self.direction = direction
        self._enabled_by_us = False

    def __repr__(self) -> str:
        return f"Joint({self.name!r}, {self.driver.device}, enabled={self.driver.is_enabled})"

    # -- unit conversion --------------------------------------------------------------------
    @property
    def units(self) -> Units:
        return self.driver.units

    def _to_pos(self, rad: float) -> int:
        return round((rad - self.offset) * self.direction / self.units.position)

    def _from_pos(self, counts: float) -> float:
        return counts * self.units.position * self.direction + self.offset

    def _to_vel(self, rad_s: float) -> int:
        return round(rad_s * self.direction / self.units.velocity)

    def _to_acc(self, rad_s2: float) -> int:
        return max(1, round(abs(rad_s2) / self.units.velocity))

    # -- checks -----------------------------------------------------------------------------
    def _finite(self, what: str, value: float) -> float:
        # numbers.Real also admits numpy scalars (np.float32 from a gymnasium action is no float)
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
            raise CommandError(f"joint {self.name}: {what} must be a finite number, got {value!r}")
        return float(value)

    def _check_position(self, rad: float) -> None:
        lim = self.limits.position
        if lim is not None and not lim[0] <= rad <= lim[1]:
            raise CommandError(
                f"joint {self.name}: position {rad:.4f} rad is outside the limits "
                f"[{lim[0]:.4f}, {lim[1]:.4f}] rad; nothing was sent"
            )

    def _check_velocity(self, v: float, what: str = "velocity") -> None:
        lim = self.limits.velocity
        if lim is not None and abs(v) > lim:
            raise CommandError(
                f"joint {self.name}: {what} {v:.4f} rad/s exceeds the limit {lim:.4f} rad/s; nothing was sent"
            )

    def _check_accel(self, a: float, what: str) -> None:
        if a <= 0:
            raise CommandError(f"joint {self.name}: {what} must be > 0 rad/s^2, got {a}")
        lim = self.limits.acceleration
        if lim is not None and a > lim:
            raise CommandError(
                f"joint {self.name}: {what} {a:.4f} rad/s^2 exceeds the limit {lim:.4f}; nothing was sent"
            )

    def _require_enabled(self) -> None:
        if not self.driver.is_enabled:
            raise StateError(f"joint {self.name} is not enabled; call enable() first")

    # -- power ------------------------------------------------------------------------------
    def enable(self) -> None:
        """Enable the drive (brake releases). Leaving the rig disables it again."""
        # Mark first: if the reply to "enable" is lost the drive may be enabled all the same,
        # and leaving the rig must then still try to disable it.
        self._enabled_by_us = True
        self.driver.enable()

    def disable(self) -> None:
        """Disable the drive (brake engages)."""
        self.driver.disable()
        self._enabled_by_us = False

    def driver_reset(self) -> None:
        """The drive was power-cycled (sim reset): it is disabled and holds no settings."""
        self.driver.forget()
        self._enabled_by_us = False

    @property
    def enabled(self) -> bool:
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
        position = self._finite("position", position)
        v = self._finite("velocity", self.motion.velocity if velocity is None else velocity)
        a = self._finite("acceleration", self.motion.acceleration if acceleration is None else acceleration)
        d = self._finite("deceleration", self.motion.deceleration if deceleration is None else deceleration)
        self._check_position(position)
        if v <= 0:
            raise CommandError(f"joint {self.name}: profile velocity must be > 0 rad/s, got {v}")
        self._check_velocity(v, "profile velocity")
        self._check_accel(a, "acceleration")
        self._check_accel(d, "deceleration")
        self._require_enabled()
        self.driver.move_to(
            self._to_pos(position),
            speed=abs(self._to_vel(v)),
            acceleration=self._to_acc(a),
            deceleration=self._to_acc(d),
        )

    def move_by(self, delta: float, **kw: float) -> None:
        """Move by ``delta`` [rad] from the present position (checked against the limits)."""
        delta = self._finite("delta", delta)
        here = self.state().position
        self.move_to(here + delta, **kw)

    def velocity_command(self, velocity: float, acceleration: float | None = None) -> tuple[int, int]:
        """Check a velocity command against the limits; return it in device units (velocity, ramp)."""
        velocity = self._finite("velocity", velocity)
        self._check_velocity(velocity)
        a = self._finite("acceleration", self.motion.acceleration if acceleration is None else acceleration)
        self._check_accel(a, "acceleration")
        self._require_enabled()
        return self._to_vel(velocity), self._to_acc(a)

    def set_velocity(self, velocity: float, *, acceleration: float | None = None) -> None:
        """Run at ``velocity`` [rad/s] (speed control) until stop() or another command."""
        v, acc = self.velocity_command(velocity, acceleration)
        self.driver.set_velocity(v, acceleration=acc, deceleration=acc)

    def set_torque(self, torque: float) -> None:
        """Apply ``torque`` [N*m] (current control through the device's torque constant)."""
        torque = self._finite("torque", torque)
        lim = self.limits.torque
        if lim is not None and abs(torque) > lim:
            raise CommandError(
                f"joint {self.name}: torque {torque:.3f} N*m exceeds the limit {lim:.3f} N*m; nothing was sent"
            )
        self._require_enabled()
        amps = torque * self.direction / self.units.torque_constant
        self.driver.set_current(round(amps / self.units.current))

    def stop(self) -> None:
        """Decelerate to standstill with the profile deceleration."""
        self.driver.stop()

    def emergency_stop(self) -> None:
        """Stop as fast as the drive can (eRob: < 50 ms)."""
        self.driver.emergency_stop()

    def clear_faults(self) -> None:
        self.driver.clear_errors()

    # -- status -----------------------------------------------------------------------------
    def state(self) -> JointState:
        """Read the joint's state (one bus transaction where the device allows)."""
        raw = self.driver.state()
        return self.to_si(raw)

    def to_si(self, raw: RawState) -> JointState:
        u = self.units
        amps = raw.current * u.current * self.direction
        return JointState(
            position=self._from_pos(raw.position),
            velocity=raw.velocity * u.velocity * self.direction,
            torque=amps * u.torque_constant,
            current=amps,
            temperature=raw.temperature,
            enabled=raw.enabled,
            moving=raw.moving,
            fault=raw.fault,
            time=raw.time,
            raw=raw,
        )

    def check(self) -> None:
        """Raise :class:`DeviceFault` if the drive reports a fault."""
        s = self.driver.state()
        if s.fault:
            raise DeviceFault(f"joint {self.name}", s.fault, self.driver.fault_text(s.fault))

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
            if s.fault:
                raise DeviceFault(f"joint {self.name}", s.fault, self.driver.fault_text(s.fault))
            done = until(s) if until is not None else not s.moving
            if done:
                return s
            if self.clock.now() >= deadline:
                raise MotionTimeout(f"joint {self.name}: still moving after {timeout} s")
            self.clock.sleep(poll)

    # -- registers --------------------------------------------------------------------------
    def read(self, key: str | int) -> int:
        """Read a register by manual name or address (device units)."""
        return self.driver.read(key)

    def write(self, key: str | int, value: int, *, confirm: bool = False) -> None:
        """Write a register by manual name or address; persistent ones need ``confirm=True``."""
        self.driver.write(key, value, confirm=confirm)

    def shutdown(self) -> None:
        """Stop and disable if it was enabled through this joint (``enable()`` or a raw write of
        the enable register; used when leaving the rig). Best effort."""
        if not (self._enabled_by_us or self.driver.is_enabled):
            return
        try:
            self.driver.stop()
        finally:
            self.driver.disable()
            self._enabled_by_us = False
