"""ZLAC8015D over Modbus RTU: one drive, two hub motors (left/right), one control mode.

Rule: a :class:`ZlacDrive` owns what belongs to the drive - the control mode (0x200D), the
synchronous/asynchronous flag (0x200F), the control word (0x200E) and the one FC03 status read of
both wheels; each wheel is a :class:`ZlacChannelDriver` (a :class:`JointDriver`). Asking one
channel for a mode while its sibling is enabled in another mode is an error that says so.
Synchronous commands are one FC16 (both target velocities at 0x2088-0x2089, both torques at
0x2090-0x2091, both positions at 0x208A-0x208D).

Units used towards :class:`~joints.joint.Joint`: position in encoder counts (4 x the encoder lines
the drive is set to per turn: 0x2030/0x2060, 1024 lines = 4096 counts by default), velocity
in 0.1 r/min (the feedback unit; commands are rounded to the register's 1 r/min), current in mA
(feedback 0.1 A is scaled to mA). 0x200F follows the drive's firmware profile
(:mod:`joints.devices.quirks`): by default the manual's EXAMPLES (1 = synchronous,
0 = asynchronous; the register table says the opposite, ERRATA DOC-ZLAC-1).

What the drive is set to (:meth:`ZlacDrive.identify`, once, before the first status read or
enable): the encoder lines of both motors (0x2030, 0x2060) are read and each wheel counts 4 x its
motor's lines per turn. A config that names ``encoder_lines`` in the joint's profile and disagrees
with the drive is refused (:class:`~joints.errors.ConfigError` naming both numbers; a wrong count
would scale every position and speed); a config silent on it takes the drive's.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from joints.clock import Clock, MonotonicClock
from joints.devices.faults import Fault
from joints.devices.quirks import firmware_profile
from joints.devices.zlac import faults as zf
from joints.devices.zlac import registers as zr
from joints.drivers.access import ModbusAccess
from joints.drivers.base import JointDriver, RawState, Units, sampled_at
from joints.errors import CommandError, ConfigError, ConfirmationRequired, StateError
from joints.link.modbus import ModbusLink

SIDES = ("left", "right")
#: status block read in ONE FC03: motor state (0x20A2) .. software connected status (0x20AF)
STATUS_START = 0x20A2
STATUS_WORDS = 0x20AF - 0x20A2 + 1
#: the velocity and torque targets of both wheels (0x2088..0x2091 with the position targets between)
_TARGETS = ("target_velocity_left", "target_velocity_right", "target_torque_left", "target_torque_right")
#: per side: its target velocity, acceleration time and deceleration time (velocity_plan's names)
_VELOCITY_NAMES = {side: (f"target_velocity_{side}", f"acceleration_time_{side}", f"deceleration_time_{side}")
                   for side in SIDES}
_VELOCITY = int(zr.ControlMode.VELOCITY)
#: the four ramp times in address order (0x2080 .. 0x2083: one FC16)
RAMP_NAMES = ("acceleration_time_left", "acceleration_time_right", "deceleration_time_left", "deceleration_time_right")
#: both target velocities in address order (0x2088, 0x2089: one FC16)
TARGET_NAMES = ("target_velocity_left", "target_velocity_right")
_CHECK_LEFT = zr.ZLAC8015D["target_velocity_left"].check
_CHECK_RIGHT = zr.ZLAC8015D["target_velocity_right"].check


def ramp_time_ms(delta_rpm: float, rpm_per_s: float) -> int:
    """Acceleration/deceleration-time register value [ms] for a speed change of ``delta_rpm`` at
    ``rpm_per_s``: the ramp time is the time the drive takes to reach the commanded speed (the
    manual gives no other reference speed; joints.sim.zlac follows the same reading)."""
    if rpm_per_s <= 0:
        raise CommandError(f"ramp rate must be > 0 r/min/s, got {rpm_per_s}")
    return max(0, min(32767, round(abs(delta_rpm) / rpm_per_s * 1000.0)))


@dataclass
class _DriveState:
    mode: int | None = None
    sync: int | None = None
    enabled: set[str] = field(default_factory=set)
    channel_mode: dict[str, int] = field(default_factory=dict)


class ZlacDrive:
    """One ZLAC8015D on a Modbus link: the state both wheels share (a drive group of two channels)."""

    table = zr.ZLAC8015D
    channels = SIDES

    def __init__(self, link: ModbusLink, slave: int, *, clock: Clock | None = None, name: str = "",
                 quirks: frozenset[str] | None = None) -> None:
        if not 1 <= slave <= 127:
            raise CommandError(f"ZLAC8015D RS485 node id must be 1..127, got {slave}")
        #: the drive's firmware quirks (joints.devices.quirks); default: the family's default firmware
        self.quirks = quirks if quirks is not None else firmware_profile("zlac8015d").quirks
        self.link = link
        self.slave = slave
        self.clock: Clock = clock or link.clock or MonotonicClock()
        self.name = name or f"zlac8015d@{slave}"
        self.state = _DriveState()
        self.offline = False  #: the drive quick-stopped because the host went silent (until enabled again)
        self.commanded = False  #: this host has written the control word since it opened the drive
        self.adopted = False  #: found enabled by another program (its mode is read before changing it)
        self.access = ModbusAccess(link, slave, self.table)
        self._cache: dict[str, int] = {}
        #: side -> the encoder lines the drive is set to (0x2030/0x2060), read once (None: not yet)
        self.lines: dict[str, int] | None = None
        self._channels: list[ZlacChannelDriver] = []

    def identify(self) -> None:
        """Read once what the drive is set to (encoder lines of both motors) and tell the wheels."""
        if self.lines is not None:
            return
        values = self.access.read_many(("encoder_line_left", "encoder_line_right"))
        lines = {side: values[f"encoder_line_{side}"] for side in SIDES}
        for channel in self._channels:
            channel.use_lines(lines[channel.side])  # raises if the config contradicts the drive
        self.lines = lines

    # -- parameters --
    def write_param(self, name: str, value: int, *, idempotent: bool = True) -> None:
        self.access.write(name, value, idempotent=idempotent)
        self._cache[name] = int(value)

    def remember(self, name: str, value: int) -> None:
        """Note a value the drive holds (read back), so redundant writes of it are skipped."""
        self._cache[name] = value

    def written(self, name: str, default: int) -> int:
        """The last value this host wrote to ``name`` (``default`` if it wrote none)."""
        return self._cache.get(name, default)

    def set(self, name: str, value: int, *, force: bool = False) -> None:
        if force or self._cache.get(name) != value:
            self.write_param(name, value)

    def set_block(self, values: Mapping[str, int]) -> None:
        """Several contiguous registers in one FC16."""
        self.access.write_many(values)
        self._cache.update(values)

    def note_written(self, values: Mapping[str, int]) -> None:
        """``values`` were written by another way than :meth:`set_block` (the compiled path)."""
        self._cache.update(values)

    def control(self, word: zr.ControlWord) -> None:
        """Write the control word (commands are never retried). From then on this host knows the state
        it put the drive in; before, "enabled" is taken from the drive's status."""
        self.commanded = True
        self.write_param("control_word", int(word), idempotent=False)
        self._cache.pop("control_word", None)

    def forget(self) -> None:
        self._cache.clear()
        self.lines = None
        self.state = _DriveState()
        self.offline = False
        self.commanded = False
        self.adopted = False

    # -- mode ownership --
    def require_mode(self, side: str, mode: zr.ControlMode) -> None:
        """Put the drive in ``mode`` for ``side`` unless the sibling is enabled in another mode."""
        other = "right" if side == "left" else "left"
        st = self.state
        if st.mode is None and self.adopted:  # enabled by another program: the mode is the drive's
            st.mode = self.access.read("control_mode")
            self._cache["control_mode"] = st.mode
        if other in st.enabled and st.mode is not None and st.mode != int(mode):
            raise StateError(
                f"{self.name}: the control mode belongs to the drive - the {other} wheel is enabled in "
                f"{zr.ControlMode(st.mode).name} mode, so the {side} wheel cannot use {mode.name}; "
                f"disable the {other} wheel first or command both in {zr.ControlMode(st.mode).name}"
            )
        if st.mode != int(mode):
            self.set("control_mode", int(mode), force=True)
            st.mode = int(mode)
        st.channel_mode[side] = int(mode)

    def set_sync(self, synchronous: bool) -> None:
        value = zr.sync_flag(synchronous, self.quirks)  # the firmware's meaning of 0x200F (DOC-ZLAC-1)
        if self.state.sync != value:
            self.set("synchronous_asynchronous_control_status", value, force=True)
            self.state.sync = value

    def configure(
        self,
        mode: zr.ControlMode,
        *,
        acceleration_ms: tuple[int, int] | None = None,
        deceleration_ms: tuple[int, int] | None = None,
        position_speed_rpm: tuple[int, int] | None = None,
        torque_rate: tuple[int, int] | None = None,
        synchronous: bool | None = None,
    ) -> None:
        """The manual's initialisation (3.1/3.2/3.4), before "enable": [sync flag,] control mode,
        acceleration time L/R, deceleration time L/R, position-mode speed L/R or torque rate L/R."""
        if self.state.enabled and self.state.mode not in (None, int(mode)):
            raise StateError(f"{self.name}: cannot change the control mode while a wheel is enabled; disable first")
        if synchronous is not None:
            self.set_sync(synchronous)
        self.set("control_mode", int(mode), force=True)
        self.state.mode = int(mode)
        pairs = (("acceleration_time", acceleration_ms), ("deceleration_time", deceleration_ms),
                 ("target_speed", position_speed_rpm), ("torque_rate", torque_rate))
        for stem, pair in pairs:
            if pair is not None:
                self.set(f"{stem}_left", pair[0])
                self.set(f"{stem}_right", pair[1])

    def stop(self) -> None:
        """Control word STOP (0x07): both motors stop (the manual's "Stop" in every example)."""
        self.control(zr.ControlWord.STOP)
        self.state.enabled.clear()

    # -- power --
    def energised(self, status: Mapping[str, int]) -> bool:
        """Whether the drive says both motors are on and the host is connected (0x20A2, 0x20AF)."""
        return (status["motor_state"] == 0x0101 and status["software_connected_status"] != 0
                and not status["error_code_left"] and not status["error_code_right"])

    def enable(self, side: str) -> None:
        """Enable the drive (both motors) - after zeroing any velocity or torque target left in
        the registers, so that enabling never restarts an old command (e.g. after a fault).

        Whether the drive is already on is what the drive says (one status read), not what this
        host remembers: a drive that quick-stopped on its own is enabled again."""
        self.identify()
        if self.state.enabled and not self.energised(self.read_status()):
            self.state.enabled.clear()  # it switched itself off (offline trip, fault)
        if not self.state.enabled:
            targets = self.access.read_many(_TARGETS)  # 0x2088..0x2091: one FC03
            for pair in (("target_velocity_left", "target_velocity_right"), ("target_torque_left", "target_torque_right")):
                if any(targets[n] for n in pair):
                    self.set_block({n: 0 for n in pair})
                else:
                    self._cache.update({n: 0 for n in pair})
            self.control(zr.ControlWord.ENABLE)
            self.offline = False
        self.state.enabled.add(side)

    def disable(self, side: str) -> None:
        """The drive has one enable for both motors: it is disabled when no wheel is in use."""
        self.state.enabled.discard(side)
        if not self.state.enabled:
            self.control(zr.ControlWord.STOP)

    # -- synchronous commands (one FC16) --
    def set_velocities(self, left: int, right: int) -> None:
        """Both target velocities [r/min] in one FC16 (velocity mode)."""
        self._need_both("set_velocities")
        for side in SIDES:
            self.require_mode(side, zr.ControlMode.VELOCITY)
        self.set_block({"target_velocity_left": left, "target_velocity_right": right})

    def set_channel_velocities(self, commands: Mapping[str, tuple[int, int]]) -> None:
        """Rig.set_velocities: side -> (velocity [0.1 r/min], ramp [0.1 r/min/s]); ramps as needed,
        then both targets in one FC16."""
        ramps, targets = self.velocity_plan(commands)
        if ramps is not None:
            self.set_block(ramps)  # 0x2080..0x2083 are contiguous: one FC16
        self.set_block(targets)

    def velocity_plan(self, commands: Mapping[str, tuple[int, int]]) -> tuple[dict[str, int] | None, dict[str, int]]:
        """What :meth:`set_channel_velocities` writes, after its checks and the mode (which it sets if needed):
        (the four ramp times if they change, else None; both target velocities [r/min])."""
        ramps, targets = self.velocity_words(commands["left"], commands["right"])
        return (None if ramps is None else dict(zip(RAMP_NAMES, ramps))), dict(zip(TARGET_NAMES, targets))

    def velocity_words(self, left: tuple[int, int], right: tuple[int, int]
                       ) -> tuple[tuple[int, int, int, int] | None, tuple[int, int]]:
        """:meth:`velocity_plan` of ``left``, ``right`` = (velocity [0.1 r/min], ramp [0.1 r/min/s]) as register
        values in address order: (the four ramp times of :data:`RAMP_NAMES` if they change, else None; both
        target velocities of :data:`TARGET_NAMES`). The checks, the mode and the ramp rule in one place (the
        compiled path sends these words without the names)."""
        cache = self._cache
        rpm_l, rpm_r = round(left[0] / 10.0), round(right[0] / 10.0)
        _CHECK_LEFT(rpm_l)
        _CHECK_RIGHT(rpm_r)
        self._need_both("set_velocities")
        st = self.state
        out = []
        for side, rpm, ramp in (("left", rpm_l, left[1]), ("right", rpm_r, right[1])):
            if st.mode == _VELOCITY:  # require_mode's steady case: the mode is the drive's already
                st.channel_mode[side] = _VELOCITY
            else:
                self.require_mode(side, zr.ControlMode.VELOCITY)
            target, acc, dec = _VELOCITY_NAMES[side]
            last = cache.get(target, 0)
            if rpm != last:
                t = ramp_time_ms(rpm - last, ramp / 10.0)
                out.append((t, t))
            else:
                out.append((cache.get(acc, 500), cache.get(dec, 500)))
        (acc_l, dec_l), (acc_r, dec_r) = out
        ramps = (acc_l, acc_r, dec_l, dec_r)  # 0x2080 .. 0x2083
        get = cache.get
        changed = (get("acceleration_time_left") != acc_l or get("acceleration_time_right") != acc_r
                   or get("deceleration_time_left") != dec_l or get("deceleration_time_right") != dec_r)
        return (ramps if changed else None), (rpm_l, rpm_r)

    def note_words(self, names: tuple[str, ...], values: tuple[int, ...]) -> None:
        """:meth:`note_written` of ``values`` of the registers ``names`` (the compiled path's FC16s)."""
        cache = self._cache
        for n, v in zip(names, values):
            cache[n] = v

    def set_torques(self, left: int, right: int) -> None:
        """Both target torques [mA] in one FC16 (torque mode)."""
        self._need_both("set_torques")
        for side in SIDES:
            self.require_mode(side, zr.ControlMode.TORQUE)
        self.set_block({"target_torque_left": left, "target_torque_right": right})

    def move_both(self, left: int, right: int, *, absolute: bool = True) -> None:
        """Both target positions [counts] in one FC16, then start both (synchronous position mode)."""
        self._need_both("move_both")
        mode = zr.ControlMode.ABSOLUTE_POSITION if absolute else zr.ControlMode.RELATIVE_POSITION
        for side in SIDES:
            self.require_mode(side, mode)
        self.set_sync(True)
        self.set_block({"target_position_left": left, "target_position_right": right})
        self.control(zr.ControlWord.START_SYNC)

    def _need_both(self, what: str) -> None:
        enabled = self.state.enabled
        if "left" in enabled and "right" in enabled:
            return
        missing = [s for s in SIDES if s not in enabled]
        if missing:
            raise StateError(f"{self.name}: {what} needs both wheels enabled ({', '.join(missing)} is not)")

    # -- status --
    def read_status(self) -> dict[str, int]:
        """Both wheels' status in ONE FC03 (motor state .. actual torque right)."""
        self.identify()
        return self.access.read_block(STATUS_START, STATUS_WORDS)


class ZlacChannelDriver(JointDriver):
    """One wheel of a ZLAC8015D (``side`` = "left" | "right")."""

    device = "zlac8015d"
    table = zr.ZLAC8015D

    def __init__(self, drive: ZlacDrive, side: str, *, profile: Any, name: str = "",
                 encoder_lines: int | None = None) -> None:
        """``encoder_lines``: what the config says the motor has (None: silent - the drive's setting is used)."""
        if side not in SIDES:
            raise CommandError(f"ZLAC8015D channel must be 'left' or 'right', got {side!r}")
        self.drive = drive
        self.side = side
        self.channel = side
        self.access = drive.access
        self.profile = profile
        self.name = name or f"{drive.name}:{side}"
        self.encoder_lines = encoder_lines
        #: this wheel's status parameters: error code, actual position, velocity, torque
        self._status = tuple(f"{stem}_{side}" for stem in ("error_code", "actual_motor_position", "actual_velocity",
                                                             "actual_torque"))
        self._byte = 8 if side == "left" else 0  #: the shift of this wheel's byte in the status's two-wheel words
        lines = encoder_lines or int(getattr(profile, "encoder_lines", zr.COUNTS_PER_REV // 4))
        self.units = self._units(lines)  # until the drive told its own (ZlacDrive.identify)
        drive._channels.append(self)
        if drive.lines is not None:
            self.use_lines(drive.lines[side])

    def _units(self, lines: int) -> Units:
        return Units(2.0 * math.pi / (4 * lines), 2.0 * math.pi / 60.0 * 0.1, 0.001,
                     float(self.profile.torque_constant))

    @property
    def counts_per_rev(self) -> int:
        """Encoder counts per wheel turn (4 x the lines; the drive's once it was read)."""
        return round(2.0 * math.pi / self.units.position)

    def use_lines(self, lines: int) -> None:
        """The drive says this motor's encoder has ``lines`` (0x2030/0x2060): count 4 x lines per turn, or
        refuse a config that names another number."""
        register = "0x2030" if self.side == "left" else "0x2060"
        if lines <= 0:
            raise ConfigError(f"{self.name}: the drive reports {lines} encoder lines ({register}); set the motor's "
                              "line count on the drive", key="profile.encoder_lines")
        if self.encoder_lines is not None and self.encoder_lines != lines:
            raise ConfigError(f"{self.name}: the config says encoder_lines = {self.encoder_lines} "
                              f"({4 * self.encoder_lines} counts/rev), the drive is set to {lines} lines ({register}: "
                              f"{4 * lines} counts/rev); remove the key to use the drive's, or set the drive",
                              key="profile.encoder_lines", allowed=(lines,))
        self.units = self._units(lines)

    def _r(self, stem: str) -> str:
        return f"{stem}_{self.side}"

    @property
    def group(self) -> ZlacDrive:
        """Both wheels share one drive: one status read (Rig.read_states), one velocity FC16."""
        return self.drive

    def identity(self) -> dict[str, object]:
        """The software version (0x20A0), the one identity register of the drive (no model, no serial
        number), and the encoder lines this wheel's motor is set to (0x2030/0x2060)."""
        self.drive.identify()
        lines = self.drive.lines[self.side] if self.drive.lines is not None else None
        return {"firmware_version": f"0x{self.access.read('software_version'):04X}", "encoder_lines": lines,
                "counts_per_rev": self.counts_per_rev}

    def write_param(self, name: str, value: int) -> None:
        self.drive.write_param(name, value)

    @property
    def is_enabled(self) -> bool:
        return self.side in self.drive.state.enabled

    def forget(self) -> None:
        self.drive.forget()

    # -- power --
    def enable(self) -> None:
        self.drive.enable(self.side)

    def disable(self) -> None:
        self._zero_target()
        self.drive.disable(self.side)

    def _require_enabled(self) -> None:
        if not self.is_enabled:
            raise StateError(f"{self.name}: the wheel is not enabled; call enable() first")

    def _zero_target(self) -> None:
        mode = self.drive.state.mode
        if self.is_enabled and mode == zr.ControlMode.VELOCITY:
            self.drive.set(self._r("target_velocity"), 0, force=True)
        elif self.is_enabled and mode == zr.ControlMode.TORQUE:
            self.drive.set(self._r("target_torque"), 0, force=True)

    def _ramps(self, delta_rpm: float, acceleration: int | None, deceleration: int | None) -> None:
        """Acceleration/deceleration [0.1 r/min per s] for a change of ``delta_rpm`` -> ramp times [ms]."""
        if delta_rpm == 0:
            return
        if acceleration is not None:
            self.drive.set(self._r("acceleration_time"), ramp_time_ms(delta_rpm, acceleration / 10.0))
        if deceleration is not None:
            self.drive.set(self._r("deceleration_time"), ramp_time_ms(delta_rpm, deceleration / 10.0))

    # -- velocity mode --
    def set_velocity(self, velocity: int, *, acceleration: int | None = None, deceleration: int | None = None) -> None:
        """Target velocity (0.1 r/min, rounded to the register's 1 r/min), asynchronous per wheel."""
        rpm = round(velocity / 10.0)
        self.table[self._r("target_velocity")].check(rpm)
        self._require_enabled()
        self.drive.require_mode(self.side, zr.ControlMode.VELOCITY)
        last = self.drive.written(self._r("target_velocity"), 0)
        self._ramps(rpm - last, acceleration, deceleration)
        self.drive.set(self._r("target_velocity"), rpm, force=True)

    # -- position modes --
    def _position(self, counts: int, mode: zr.ControlMode, speed: int | None, acceleration: int | None,
                  deceleration: int | None) -> None:
        self.table[self._r("target_position")].check(counts)
        rpm = None if speed is None else max(1, min(1000, round(abs(speed) / 10.0)))
        self._require_enabled()
        self.drive.require_mode(self.side, mode)
        self.drive.set_sync(False)
        self._ramps(rpm or self.drive.written(self._r("target_speed"), 120), acceleration, deceleration)
        if rpm is not None:
            self.drive.set(self._r("target_speed"), rpm)
        self.drive.set(self._r("target_position"), counts, force=True)
        self.drive.control(zr.ControlWord.START_LEFT if self.side == "left" else zr.ControlWord.START_RIGHT)

    def move_to(self, position: int, *, speed: int | None = None, acceleration: int | None = None,
                deceleration: int | None = None) -> None:
        """Absolute position mode (counts), start this wheel (asynchronous)."""
        self._position(position, zr.ControlMode.ABSOLUTE_POSITION, speed, acceleration, deceleration)

    def move_by(self, delta: int, *, speed: int | None = None, acceleration: int | None = None,
                deceleration: int | None = None) -> None:
        """Relative position mode (counts), start this wheel (asynchronous)."""
        self._position(delta, zr.ControlMode.RELATIVE_POSITION, speed, acceleration, deceleration)

    # -- torque mode --
    def set_current(self, current: int) -> None:
        """Target torque [mA] of this wheel (torque mode; the torque rate register sets the slope)."""
        self.table[self._r("target_torque")].check(current)
        self._require_enabled()
        self.drive.require_mode(self.side, zr.ControlMode.TORQUE)
        self.drive.set(self._r("target_torque"), current, force=True)

    def set_torque_rate(self, ma_per_s: int) -> None:
        self.drive.set(self._r("torque_rate"), ma_per_s)

    # -- stopping --
    def stop(self) -> None:
        """Velocity/torque: this wheel's target to 0 (ramped). Position: control word STOP (both wheels)."""
        mode = self.drive.state.mode
        if mode in (zr.ControlMode.VELOCITY, zr.ControlMode.TORQUE):
            self._zero_target()
        elif self.is_enabled:
            self.drive.control(zr.ControlWord.STOP)
            self.drive.state.enabled.clear()

    def emergency_stop(self) -> None:
        """Quick stop (control word 0x05, both wheels, reaction per 0x2011)."""
        self.drive.control(zr.ControlWord.QUICK_STOP)

    def clear_errors(self) -> None:
        """Clear faults (0x06, both wheels; also acknowledges an offline trip). The drive is then
        disabled and needs "enable" (0x08)."""
        self.drive.control(zr.ControlWord.CLEAR_FAULT)
        self.drive.state.enabled.clear()
        self.drive.offline = False

    # -- status --
    def state(self) -> RawState:
        t0 = self.drive.clock.now()
        v = self.drive.read_status()
        return self.state_from(v, sampled_at(t0, self.drive.clock.now()))

    def state_from(self, v: Mapping[str, int], t: float) -> RawState:
        """This wheel's part of a status block read by :meth:`ZlacDrive.read_status`.

        "Enabled" is what the drive says: its motor is on (0x20A2), the host is connected
        (0x20AF) and no wheel faulted. A drive that quick-stopped because the host went silent
        (0x20AF = 0 while this host had it enabled) reports :data:`~joints.devices.zlac.faults.OFFLINE`.
        """
        side = self.side
        drive = self.drive
        enabled = drive.state.enabled
        error, position, velocity, torque = self._status
        fault = v[error]
        was_enabled = side in enabled
        if v["error_code_left"] or v["error_code_right"]:
            # a fault switches BOTH motors off (one state machine): the drive disabled itself
            enabled.clear()
        elif not drive.commanded and drive.energised(v) and not enabled:
            # this host has sent no control word yet and the drive is on (enabled by another program
            # or process): it is enabled - both motors, one state machine - in the drive's mode
            enabled.update(SIDES)
            drive.adopted = True
        elif enabled and v["software_connected_status"] == 0:
            enabled.clear()  # offline trip: the drive quick-stopped on its own
            drive.offline = True
        if not fault and drive.offline and (was_enabled or not enabled):
            fault = zf.OFFLINE_CODE
        shift = self._byte  # this wheel's byte of the two-wheel words (left: the high byte)
        running = (v["motor_state"] >> shift) & 0xFF
        temp = (v["motor_temperature"] >> shift) & 0xFF
        speed = v[velocity]
        return RawState(
            position=v[position],
            velocity=speed,
            current=v[torque] * 100,  # 0.1 A -> mA
            temperature=float(temp),
            enabled=side in enabled and bool(running),
            moving=bool(running) and speed != 0,
            fault=fault,
            time=t,
            extra=dict(v),
        )

    def fault_text(self, code: int) -> str:
        f = zf.fault(code)
        return f.text if f is not None else "no fault"

    def fault(self, code: int) -> Fault | None:
        return zf.fault(code)

    def motion_targets(self) -> dict[str, tuple[str, float]]:
        """Motion set-points of both wheels, for the joint's checks of raw writes."""
        rpm = 2.0 * math.pi / 60.0
        position = "position" if self.drive.state.mode == zr.ControlMode.ABSOLUTE_POSITION else "relative"
        out: dict[str, tuple[str, float]] = {}
        for side in SIDES:
            out[f"target_velocity_{side}"] = ("velocity", rpm)
            out[f"target_speed_{side}"] = ("velocity", rpm)
            out[f"target_torque_{side}"] = ("current", 0.001)
            out[f"target_position_{side}"] = (position, self.units.position)
        return out

    def apply_limits(self, *, position: tuple[int, int] | None = None, velocity: int | None = None,
                     current: int | None = None) -> None:
        """Maximum motor speed 0x2008 (r/min, the drive's: the larger of the two wheels' limits) and this
        wheel's maximum current (0.1 A); the ZLAC has no position limits."""
        if velocity is not None:
            rpm = max(1, min(1000, math.ceil(abs(velocity) / 10.0)))
            other = self.drive.written("maximum_motor_speed", 0) if self.drive.state.enabled else 0
            self.drive.set("maximum_motor_speed", max(rpm, other))
        if current is not None:
            name = self._r("maximum_current")
            self.drive.set(name, max(1, min(self.table[name].type_range[1], math.ceil(abs(current) / 100.0))))

    # -- watchdog and persistent operations --
    def set_communication_timeout(self, milliseconds: int) -> None:
        """Communication offline time (0x2000) [ms]: the drive stops when the host goes quiet."""
        self.drive.set("communication_offline_time", milliseconds)

    def communication_timeout(self) -> int:
        value = self.drive.access.read("communication_offline_time")
        self.drive.remember("communication_offline_time", value)
        return value

    def reset_zero_point(self, *, confirm: bool = False) -> None:
        """Absolute position mode: the present position becomes zero (0x2006)."""
        if not confirm:
            raise ConfirmationRequired(f"{self.name}: resetting the zero point moves the position reference; pass confirm=True")
        self.drive.write_param("in_absolute_position_control_reset_the_zero_point", 1 if self.side == "left" else 2)

    def clear_feedback_position(self, *, confirm: bool = False) -> None:
        """Clear the feedback position of both wheels (0x2005)."""
        if not confirm:
            raise ConfirmationRequired(f"{self.name}: clearing the feedback position resets both wheels' counts; pass confirm=True")
        self.drive.write_param("clear_feedback_position", 1)
