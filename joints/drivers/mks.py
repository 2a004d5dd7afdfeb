"""MKS SERVO42D/57D closed-loop steppers: the procedures of the manual (Parts 5 and 6), by parameter name.

Rule: one driver for both protocols. Every procedure names parameters of
:data:`~joints.devices.mks.params.MKS_PARAMS`; the native protocol
(:mod:`joints.drivers.mks_native`) and Modbus-RTU mode (:mod:`joints.drivers.mks_modbus`) supply
the :class:`~joints.drivers.access.ParamAccess` and what only they have (completion frames, long
packets, broadcast and group addresses natively; the 0x90 frame over Modbus).

Units (device side, the :class:`~joints.drivers.base.Units` of the joint): position in encoder
counts (16384 per motor turn, the "axis" of 0xF4/0xF5 and 0x31), velocity in motor rpm, current in
mA. Pulses (microsteps, 200 x subdivision per turn) are a second position unit of their own
(0xFD/0xFE, 0x33): :meth:`MksDriver.move_pulses`. Positive is CCW everywhere (0x32 "CCW: speed >
0", 0x30 "one turn CCW, +0x4000"; the run direction bit 0 = CCW).

Speed and acceleration (6.1): a speed *value* is rpm at 16/32/64 microsteps and ``value x 16 /
microsteps`` rpm otherwise; the driver converts motor rpm to the value for the subdivision it set.
acc: the speed value changes by 1 every ``(256 - acc) x 50 us``; acc 0 = no ramp. A requested
acceleration [rpm/s] becomes the nearest acc (:func:`~joints.devices.mks.state.acc_for_rate`);
deceleration is the same acc (the drive has one). Speeds above the work mode's maximum (400 / 1500
/ 3000 rpm) are clamped by the drive.

What the driver sets before motion (``enable``): the work mode (serial commands need SR_*; default
SR_vFOC), the subdivision it computes speeds with (the one given; else the drive's where 0x47
reports it - V1.0.6+ native - else 16) and, natively, respond and active on (0x8C 1 1: completion
frames). Settings the drive cannot report are written once per session and remembered (the access
keeps an image of what was written; 0x47 fills it with what the drive holds).

Firmware (``firmware`` of the joint, :mod:`joints.devices.quirks`; default the newest, V1.0.9)
    The driver uses a later firmware's commands only where its profile has them (others raise
    :class:`~joints.errors.RegisterError` naming the firmware needed). Before the first enable
    (or watchdog or identity call) it asks the drive: with V1.0.9 it reads 0x40 and refuses
    (:class:`~joints.errors.ConfigError`, key ``firmware``) a drive that reports another version
    or does not answer 0x40 at all (older than V1.0.9); with an older profile it asks 0x40 once
    (no retry) and refuses a drive that answers it. :meth:`MksDriver.identity` reports what 0x40
    says. Modbus writes that fail are answered by V1.0.6+ with FC06 data 0xFFFF / FC16 quantity
    0: :class:`~joints.errors.DeviceRejected` (code 0), as the native status 0.

Safety
    * Before firmware V1.0.9 the MKS has NO communication watchdog: a speed-mode axis keeps
      turning if the host dies. V1.0.9's heartbeat protection (0x98) is the watchdog:
      :class:`MksHeartbeat` drivers (what the registry builds for a V1.0.9 joint) arm it while
      the joint is enabled (:class:`~joints.drivers.capabilities.CommunicationWatchdog`) and the
      rig's waits feed it. Leaving a :class:`~joints.rig.Rig` stops (:meth:`MksDriver.stop`: the running mode's own stop
      command, speed mode's 0xF6 speed 0 when the mode is unknown) and disables every axis this
      host enabled; prefer position moves (they end by themselves) where a target is known.
    * A run command is never sent twice blindly: when its reply is lost the driver reads the motor
      status (and the position for absolute targets) and sends it again only if the drive did not
      start it; a relative move whose outcome cannot be told raises
      :class:`~joints.errors.OutcomeUnknown`.
    * Dangerous commands (0x80 calibrate, 0x8A baud rate, 0x8B address, 0x8E Modbus on/off, 0x9A
      0_Mode, 0xFF C8 save speed mode, 0x3F restore defaults, 0x41 restart, 0x92 set zero) need
      ``confirm=True`` and send nothing without it.
    * The locked-rotor protection (0x88; the drive releases the shaft) is the one fault the drive
      reports (0x3E): :data:`LOCKED_ROTOR` by name; ``clear_errors`` releases it (0x3D).

The MKS reports no current and no temperature: states carry current 0 and temperature NaN.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import TypeVar

from joints.clock import Clock, MonotonicClock
from joints.devices.faults import DEFINED_BY_JOINTS, HOST_DEFINED, Fault
from joints.devices.mks import state as st
from joints.devices.mks.native import OPTIONAL_FIELDS
from joints.devices.mks.params import FEATURE_OF, VALUE_FEATURE_OF
from joints.devices.mks.profile import MksProfile
from joints.devices.mks.profile import profile as lookup_profile
from joints.devices.params import ParamSet
from joints.devices.quirks import MKS_FIRMWARES, MKS_TIMED_SPEED, MKS_VERSION, FirmwareProfile, firmware_profile
from joints.drivers.access import ParamAccess
from joints.drivers.base import JointDriver, RawState, Units
from joints.errors import (
    CommandError,
    ConfigError,
    ConfirmationRequired,
    DeviceRejected,
    MotionTimeout,
    OutcomeUnknown,
    PeerProtocolError,
    RegisterError,
    ReplyTimeout,
)

__all__ = ["DEFAULT_ACC", "DEFAULT_SPEED", "HARDWARE", "LOCKED_ROTOR", "RUN_GROUPS", "STATUS_NAMES", "MksAccess",
           "MksDriver", "MksHeartbeat", "firmware_text"]

#: the fault the drive reports (0x3E = 1), as a host-defined code (the MKS has no fault codes)
LOCKED_ROTOR = HOST_DEFINED | 0x3E
DEFAULT_SPEED = 60  #: rpm, when a move gives none
DEFAULT_ACC = 236  #: 1000 speed units/s: a stop from a speed above 1000 rpm never uses acc 0 (6.5 note)
#: what :meth:`MksDriver.state` reads (one transaction each: the MKS has no block read)
STATUS_NAMES = ("encoder_addition", "real_time_speed", "motor_status", "protection_state", "en_pin_status")
#: run mode -> (speed, acc, target) parameter names of its command
RUN_GROUPS: Mapping[str, tuple[str, str, str]] = {
    "speed": ("speed_mode_speed", "speed_mode_acc", "speed_mode_direction"),
    "pulses": ("position_mode1_speed", "position_mode1_acc", "position_mode1_pulses"),
    "abs_pulses": ("position_mode2_speed", "position_mode2_acc", "position_mode2_abs_pulses"),
    "rel_axis": ("position_mode3_speed", "position_mode3_acc", "position_mode3_rel_axis"),
    "abs_axis": ("position_mode4_speed", "position_mode4_acc", "position_mode4_abs_axis"),
}
_MODE_OF = {name: mode for mode, names in RUN_GROUPS.items() for name in names}
_MODE_OF["position_mode1_direction"] = "pulses"
_COUNTS = st.ENCODER_COUNTS_PER_TURN
_RPM = 2.0 * math.pi / 60.0
#: 0x40 hardware version -> board (manual V1.0.9 5.1.11)
HARDWARE: Mapping[int, str] = {1: "S42D_485", 2: "S42D_CAN", 3: "S57D_485", 4: "S57D_CAN", 5: "S28D_RS485",
                               6: "S28D_CAN", 7: "S35D_RS485", 8: "S35D_CAN"}


def firmware_text(version: Sequence[int]) -> str:
    """(1, 0, 9) -> "v1.0.9" (the config's spelling)."""
    return "v" + ".".join(str(v) for v in version)


T = TypeVar("T")

class MksAccess(ParamAccess):
    """What both MKS protocols' accesses share: the image of what this host wrote.

    Most MKS settings cannot be read back, and a command that carries several parameters (0x8C,
    0x90, 0x94, 0x9A, the run commands) sends all of its fields: the ones not given go with the
    value last written (or the parameter's default). The image records every field sent, also when
    the reply was lost (the drive may hold them), never when the drive refused them.
    """

    def __init__(self, params: ParamSet) -> None:
        self.params = params
        self.image: dict[str, int] = {}
        #: the firmware's added commands this drive has (joints.devices.quirks; the driver sets them)
        self.features: frozenset[str] = firmware_profile("mks").features

    def require(self, names: Sequence[str] | Mapping[str, int]) -> None:
        """Refuse parameters, and values (given a mapping), of a later firmware than this drive's profile
        (nothing is sent)."""
        for n in names:
            feature = FEATURE_OF.get(n)
            if isinstance(names, Mapping) and feature is None:
                feature = VALUE_FEATURE_OF.get((n, int(names[n])))
                what = f"{n} = {names[n]}"
            else:
                what = n
            if feature is not None and feature not in self.features:
                newer = [f for f in MKS_FIRMWARES if feature in firmware_profile("mks", f).features]
                raise RegisterError(f"{self.params.device}: {what} needs firmware {newer[0]} or later (the joint's "
                                    f"firmware key names an older one)")

    def forget(self) -> None:
        """The drive was power-cycled or restored: nothing written is known any more."""
        self.image.clear()

    def merged(self, names: Sequence[str], given: Mapping[str, int]) -> dict[str, int]:
        """Every field of one command: ``given`` values, else the image, else the defaults (range-checked)."""
        out: dict[str, int] = {}
        for n in names:  # a later firmware's optional field not given: 0, the command's older form
            value = given[n] if n in given else 0 if n in OPTIONAL_FIELDS else self.image.get(n, self.params[n].default)
            out[n] = self.params[n].check(value)
        return out

    def remember(self, values: Mapping[str, int]) -> None:
        self.image.update(values)

    def sent(self, values: Mapping[str, int], send: Callable[[], T]) -> T:
        """Run ``send`` (one frame carrying ``values``) and keep ``values`` in the image if the drive
        took them or may have (no intact answer), never if it refused them."""
        try:
            out = send()
        except (OutcomeUnknown, PeerProtocolError):
            self.remember(values)  # the drive may have taken them
            raise
        self.remember(values)
        return out

    def read(self, name: str) -> int:
        return self.read_many((name,))[name]

    def read_version(self, *, retry: bool = True) -> int:
        """0x40 version word (V1.0.9); ``retry=False``: one attempt. Each protocol's access implements it."""
        raise NotImplementedError

    def write(self, name: str, value: int, *, idempotent: bool = True) -> None:
        self.write_many({name: value}, idempotent=idempotent)


class MksDriver(JointDriver):
    """One MKS SERVO42D/57D axis, over whichever protocol ``access`` speaks (see the module docstring)."""

    access: MksAccess

    def __init__(
        self,
        access: MksAccess,
        *,
        device: str = "mks-servo42d",
        profile: MksProfile | str | None = None,
        clock: Clock | None = None,
        name: str = "",
        work_mode: int = st.WorkMode.SR_vFOC,
        microsteps: int | None = None,
        firmware: FirmwareProfile | str | None = None,
    ) -> None:
        self.access = access
        #: the drive's firmware profile (its added commands; joints.devices.quirks)
        self.firmware = firmware if isinstance(firmware, FirmwareProfile) else firmware_profile("mks", firmware)
        access.features = self.firmware.features
        self._verified = False
        self.device = device
        self.profile = lookup_profile(profile or device) if not isinstance(profile, MksProfile) else profile
        self.clock: Clock = clock or MonotonicClock()
        self.name = name or device
        if not st.WorkMode(work_mode).serial:
            raise CommandError(f"{self.name}: serial commands need an SR_* work mode (3, 4, 5), got "
                               f"{st.WorkMode(work_mode).name}")
        self.work_mode = st.WorkMode(work_mode)
        #: the subdivision the driver computes with: the one given, else the drive's (where it can tell:
        #: 0x47, V1.0.6+ native), else 16 - written at enable unless the drive holds it already
        self.microsteps = int(self.params["microsteps"].check(16 if microsteps is None else microsteps))
        self.microsteps_given = microsteps is not None
        rad = 2.0 * math.pi / _COUNTS
        self.units = Units(rad, _RPM, 0.001, self.profile.torque_constant)
        self._enabled = False
        self._running: str | None = None  #: the run mode started last (None: none known to run)
        self._last_acc = 0
        self._last_rpm = 0.0
        self._sent_at = -math.inf
        self._sent_count = 0  #: completion frames received when the last run command went out
        self.completions = 0  #: completion frames received (active mode, native protocol)

    # -- parameter primitives ----------------------------------------------------------------
    @property
    def image(self) -> Mapping[str, int]:
        """What this host wrote (the settings the drive cannot report)."""
        return self.access.image

    def written(self, name: str) -> int | None:
        """The value last written to a write-only setting (None if this host has not written it)."""
        return self.image.get(name)

    def write_param(self, name: str, value: int, *, idempotent: bool = True) -> None:
        """Write one parameter (its command's other fields go along from the image); keeps the driver's
        bookkeeping (enable, subdivision, work mode, the running mode)."""
        mode = _MODE_OF.get(name)
        self.access.write(name, value, idempotent=idempotent and mode is None)
        self._noted(name, int(value))

    def _noted(self, name: str, value: int) -> None:
        if name == "motor_enable":
            self._enabled = bool(value)
        elif name == "microsteps":
            self.microsteps = value
        elif name == "work_mode":
            self.work_mode = st.WorkMode(value)
        elif name == "emergency_stop":
            self._running = None
        mode = _MODE_OF.get(name)
        if mode is not None:
            speed = self.image.get(RUN_GROUPS[mode][0], 0)
            self._running = mode if speed else None
            self._sent_at = self.clock.now()
            self._sent_count = self.completions

    def _set(self, name: str, value: int) -> None:
        """Write a setting unless this host already wrote that value."""
        if self.image.get(name) != value:
            self.write_param(name, value)

    def _confirm(self, what: str, confirm: bool) -> None:
        if not confirm:
            raise ConfirmationRequired(f"{self.name}: {what}; pass confirm=True if you mean it (nothing was sent)")

    def forget(self) -> None:
        """The drive was power-cycled: drop the image of written settings; count it as disabled."""
        self.access.forget()
        self._enabled = False
        self._running = None

    # -- firmware -----------------------------------------------------------------------------
    def read_version(self, *, retry: bool = True) -> int | None:
        """0x40 version word (V1.0.9), None if the drive does not answer it (an older firmware)."""
        try:
            return self.access.read_version(retry=retry)
        except (ReplyTimeout, DeviceRejected, PeerProtocolError):
            return None

    def verify_firmware(self) -> None:
        """Check once that the drive runs the configured firmware (see the module docstring); raises
        :class:`~joints.errors.ConfigError` (key ``firmware``) naming both versions."""
        if self._verified:
            return
        expected = firmware_text(self.firmware.version)
        has_version = MKS_VERSION in self.firmware.features
        word = self.read_version(retry=has_version)
        if word is None and has_version:
            raise ConfigError(f"{self.name}: the drive does not answer 0x40 (read version), so its firmware is "
                              f"older than {expected}: set the joint's firmware to the drive's (its screen's "
                              "About page shows it)", key="firmware", allowed=MKS_FIRMWARES[:-1])
        if word is not None:
            reported = firmware_text(((word >> 16) & 0xFF, (word >> 8) & 0xFF, word & 0xFF))
            if reported != expected:
                raise ConfigError(f"{self.name}: the drive reports firmware {reported}, the config says {expected}: "
                                  "set the joint's firmware to the drive's", key="firmware", allowed=MKS_FIRMWARES)
        self._verified = True

    def identity(self) -> dict[str, object]:
        """What 0x40 reports (V1.0.9): firmware, hardware board, calibration; older firmware: said so."""
        word = self.read_version(retry=MKS_VERSION in self.firmware.features)
        if word is None:
            return {"firmware_version": f"older than v1.0.9 (no answer to 0x40); configured {self.firmware.firmware}"}
        hardware = (word >> 24) & 0x0F
        return {"firmware_version": firmware_text(((word >> 16) & 0xFF, (word >> 8) & 0xFF, word & 0xFF)),
                "hardware_version": HARDWARE.get(hardware, str(hardware)), "calibrated": bool(word >> 28)}

    # -- units --------------------------------------------------------------------------------
    def speed_value(self, rpm: float) -> int:
        """The 6.1 speed value for ``rpm`` at this driver's subdivision (0 stops: callers keep moves >= 1)."""
        return st.speed_value(rpm, self.microsteps)

    def acc_for(self, acceleration: int | None) -> int:
        """acc for an acceleration [rpm/s] (None: :data:`DEFAULT_ACC`; 0: no ramp)."""
        if acceleration is None:
            return DEFAULT_ACC
        if acceleration <= 0:
            return 0
        return st.acc_for_rate(acceleration / st.effective_rpm(1, self.microsteps))

    @property
    def pulses_per_turn(self) -> int:
        return st.pulses_per_turn(self.microsteps)

    # -- power ----------------------------------------------------------------------------------
    @property
    def is_enabled(self) -> bool:
        return self._enabled

    def prepare(self) -> None:
        """Settings the procedures rely on: serial work mode and subdivision (written once)."""
        self._set("work_mode", int(self.work_mode))
        self._set("microsteps", self.microsteps)

    def enable(self) -> None:
        """Check the firmware (once), serial work mode, subdivision, then 0xF3 enable."""
        self.verify_firmware()
        self.prepare()
        self.write_param("motor_enable", 1)

    def disable(self) -> None:
        """0xF3 disable: the drive releases the shaft."""
        self.write_param("motor_enable", 0)
        self._running = None

    # -- motion -------------------------------------------------------------------------------
    def _move_values(self, mode: str, target: int, speed: int | None, acceleration: int | None,
                     target_name: str | None = None) -> dict[str, int]:
        rpm = float(DEFAULT_SPEED if speed is None else abs(speed))
        speed_name, acc_name, default_target = RUN_GROUPS[mode]
        values = {speed_name: max(1, self.speed_value(rpm)), acc_name: self.acc_for(acceleration),
                  target_name or default_target: target}
        self._last_rpm, self._last_acc = rpm, values[acc_name]
        return values

    def move_to(self, position: int, *, speed: int | None = None, acceleration: int | None = None,
                deceleration: int | None = None) -> None:
        """Position mode4 (0xF5): to the absolute axis ``position`` [counts]; updates a running 0xF5 move."""
        self._run("abs_axis", self._move_values("abs_axis", position, speed, acceleration), absolute=position)

    def move_by(self, delta: int, *, speed: int | None = None, acceleration: int | None = None,
                deceleration: int | None = None) -> None:
        """Position mode3 (0xF4): by ``delta`` counts relative to the present axis."""
        self._run("rel_axis", self._move_values("rel_axis", delta, speed, acceleration))

    def move_pulses(self, pulses: int, *, speed: int | None = None, acceleration: int | None = None) -> None:
        """Position mode1 (0xFD): ``pulses`` microsteps (signed: + CCW) relative to the present position."""
        values = self._move_values("pulses", abs(pulses), speed, acceleration)
        values["position_mode1_direction"] = int(st.RunDirection.CCW if pulses >= 0 else st.RunDirection.CW)
        self._run("pulses", values)

    def move_to_pulses(self, pulses: int, *, speed: int | None = None, acceleration: int | None = None) -> None:
        """Position mode2 (0xFE): to the absolute pulse position ``pulses``."""
        self._run("abs_pulses", self._move_values("abs_pulses", pulses, speed, acceleration))

    def set_velocity(self, velocity: int, *, acceleration: int | None = None,
                     deceleration: int | None = None, run_time: float | None = None) -> None:
        """Speed mode (0xF6): ``velocity`` rpm, + CCW (0 = a decelerated stop with the same acc).

        ``run_time`` [s] (V1.0.7+, profile v1.0.9; both protocols): the drive stops by itself after it
        (sent in 10 ms units, at least one), decelerating with the same acc, and reports "run complete"."""
        acc = self.acc_for(acceleration)
        value = self.speed_value(abs(velocity))
        if value == 0 and velocity:
            value = 1  # a tiny non-zero command still runs (the value 0 would be a stop)
        values = {"speed_mode_direction": int(st.RunDirection.CCW if velocity >= 0 else st.RunDirection.CW),
                  "speed_mode_speed": value, "speed_mode_acc": acc}
        if run_time is not None:
            units = max(1, round(run_time / 0.01))
            if run_time <= 0 or units > 0x0FFFFFFF:
                raise CommandError(f"{self.name}: run_time must be > 0 s and at most 0x0FFFFFFF x 10 ms, got {run_time}")
            values["speed_mode_run_time"] = units
        self._last_rpm, self._last_acc = float(abs(velocity)), acc
        self._run("speed", self._untimed(values))

    def _untimed(self, values: dict[str, int]) -> dict[str, int]:
        """A speed-mode command without a run time says so where the firmware has one (the image's last run
        time must not ride along)."""
        if "speed_mode_speed" in values and MKS_TIMED_SPEED in self.firmware.features:
            values.setdefault("speed_mode_run_time", 0)
        return values

    def set_current(self, current: int) -> None:
        raise CommandError(f"{self.name}: the MKS has no torque/current mode over the serial interface "
                           "(working current 0x83 is a limit, not a command); use speed or position control")

    def stop(self) -> None:
        """Decelerated stop of the running mode (its own command with speed 0; speed mode's 0xF6 when the
        mode is unknown), with the last acc - never acc 0 above 1000 rpm (manual 6.5 note)."""
        mode = self._running if self._running is not None and self._running in RUN_GROUPS else "speed"
        acc = self._last_acc or (DEFAULT_ACC if self._last_rpm > 1000 else 0)
        speed_name, acc_name, target_name = RUN_GROUPS[mode]
        values = {speed_name: 0, acc_name: acc, target_name: 0}  # the manual's stop frames: dir 0, target 0
        if mode == "pulses":
            values["position_mode1_direction"] = 0
        self.access.write_many(self._untimed(values), idempotent=True)  # a stop may be repeated: it starts nothing
        self._running = None

    def stop_now(self) -> None:
        """Immediate stop of the running mode (its stop command with acc 0). The manual advises against it above
        1000 rpm (6.5-6.9 notes): :meth:`stop` decelerates."""
        mode = self._running if self._running is not None and self._running in RUN_GROUPS else "speed"
        speed_name, acc_name, target_name = RUN_GROUPS[mode]
        values = {speed_name: 0, acc_name: 0, target_name: 0}
        if mode == "pulses":
            values["position_mode1_direction"] = 0
        self.access.write_many(self._untimed(values), idempotent=True)
        self._running = None

    def emergency_stop(self) -> None:
        """0xF7: stop at once (not from above 1000 rpm if avoidable: the manual's note)."""
        self.write_param("emergency_stop", 1, idempotent=False)

    def clear_errors(self) -> None:
        """0x3D: release the locked-rotor protection."""
        self.write_param("release_protection", 1, idempotent=False)

    def _command_run(self, values: dict[str, int]) -> None:
        self.access.write_many(values, idempotent=False)
        for name, value in values.items():
            self._noted(name, value)

    def _run(self, mode: str, values: dict[str, int], *, absolute: int | None = None) -> None:
        """Send a run command; if its reply is lost, find out whether the drive took it before sending again."""
        for name, value in values.items():
            self.params[name].check(value)
        sent_at = self.clock.now()
        try:
            self._command_run(values)
            return
        except (OutcomeUnknown, PeerProtocolError) as exc:
            outcome = exc
        if self._accepted(mode, absolute, sent_at):
            for name, value in values.items():
                self._noted(name, value)
            return
        if absolute is None and mode != "speed":
            raise OutcomeUnknown(f"{self.name}: the reply to a relative move was lost and the drive is not moving "
                                 "now: it may have run already; read the position before sending it again") \
                from outcome
        self._command_run(values)  # the drive did not take it: one more time

    def _accepted(self, mode: str, absolute: int | None, since: float) -> bool:
        """After a lost reply: does the drive run (or has it run) the command?"""
        status = self.access.read("motor_status")
        if status not in (st.MotorStatus.STOP, st.MotorStatus.FAIL):
            return True
        if self.completed_since(since):
            return True
        if absolute is not None:
            name = "encoder_addition" if mode == "abs_axis" else "number_of_pulses"
            return abs(self.access.read(name) - absolute) <= 1
        return False

    def completed_since(self, since: float) -> bool:
        """Whether a completion frame arrived after ``since`` (protocols without them: False)."""
        return False

    # -- waiting --------------------------------------------------------------------------------
    def wait_motion(self, timeout: float = 30.0, *, poll: float = 0.01) -> st.MotorStatus:
        """Wait until the motor stops (reads 0xF1 every ``poll`` s); returns the status read last."""
        deadline = self.clock.now() + timeout
        while True:
            status = st.MotorStatus(self.access.read("motor_status"))
            if status is st.MotorStatus.STOP:
                self._running = None
                return status
            if self.clock.now() >= deadline:
                raise MotionTimeout(f"{self.name}: still running after {timeout} s (status {status.name})")
            self.clock.sleep(poll)

    # -- status -------------------------------------------------------------------------------
    def state(self) -> RawState:
        v = self.access.read_many(STATUS_NAMES)
        protected = bool(v["protection_state"])
        enabled = bool(v["en_pin_status"]) and not protected
        if not enabled:
            self._enabled = False
        moving = v["motor_status"] not in (st.MotorStatus.STOP, st.MotorStatus.FAIL)
        if not moving and self._running != "speed":
            self._running = None
        return RawState(position=v["encoder_addition"], velocity=v["real_time_speed"], current=math.nan,
                        temperature=math.nan, enabled=enabled, moving=moving,
                        fault=LOCKED_ROTOR if protected else 0, time=self.clock.now(), extra=v)

    def motor_status(self) -> st.MotorStatus:
        """0xF1 query."""
        return st.MotorStatus(self.access.read("motor_status"))

    def fault_text(self, code: int) -> str:
        if code == LOCKED_ROTOR:
            return ("motor shaft locked-rotor protection: the position error stayed too large (manual 3 #9, 5.2 #9; "
                    "or the position-error protection 0x9D, V1.0.6+); the drive released the shaft")
        return f"unknown MKS fault code 0x{code:X}"

    def fault(self, code: int) -> Fault | None:
        if not code:
            return None
        if code == LOCKED_ROTOR:
            return Fault(code, "locked_rotor_protection", self.fault_text(code),
                         "remove the blockage, then clear_faults() (0x3D release) and enable() again",
                         f"0x3E protection state (manual 5.1 #10); code {DEFINED_BY_JOINTS}")
        return super().fault(code)

    def protection_state(self) -> bool:
        """0x3E: the locked-rotor protection released the shaft."""
        return bool(self.access.read("protection_state"))

    def motion_targets(self) -> dict[str, tuple[str, float]]:
        """Motion set-points among the parameters, for the joint's checks of raw writes (SI per unit,
        motor side). Pulse targets of 0xFD count in the direction last written; 0xFE's are not listed
        (their zero is the pulse counter's, not the axis)."""
        rad = self.units.position
        per_value = st.effective_rpm(1, self.microsteps) * _RPM
        pulse = 2.0 * math.pi / self.pulses_per_turn
        sign = -1.0 if self.image.get("position_mode1_direction") == st.RunDirection.CW else 1.0
        out = {"position_mode4_abs_axis": ("position", rad), "position_mode3_rel_axis": ("relative", rad),
               "position_mode1_pulses": ("relative", sign * pulse),
               "working_current": ("current", 0.001)}
        for name in ("speed_mode_speed", "position_mode1_speed", "position_mode2_speed", "position_mode3_speed",
                     "position_mode4_speed", "home_speed"):
            out[name] = ("velocity", per_value)
        return out

    # -- limits the drive enforces itself -----------------------------------------------------
    def apply_limits(self, *, position: tuple[int, int] | None = None, velocity: int | None = None,
                     current: int | None = None) -> None:
        """The working current (0x83, mA) is the drive's torque limit; it has no speed or position limit
        parameters (end-stop switches only), so those stay with the joint's checks."""
        self.verify_firmware()  # before the first setting is written (what the drive holds is read there)
        if current is not None:
            top = round(self.profile.max_working_current * 1000)
            self._set("working_current", max(0, min(current, top)))

    # -- settings -------------------------------------------------------------------------------
    def set_work_mode(self, mode: int) -> None:
        """0x82 work mode (serial motion needs SR_OPEN 3, SR_CLOSE 4 or SR_vFOC 5)."""
        self.write_param("work_mode", int(mode))

    def set_working_current(self, milliamps: int, *, save: bool = True) -> None:
        """0x83 working current Ma [mA] (42D 0-3000, 57D 0-5200). ``save=False`` (V1.0.7+, profile v1.0.9; both
        protocols): change it now, while running, without saving it (the drive answers status 2)."""
        if save:
            self.write_param("working_current", milliamps)
        else:
            self.access.write_many({"working_current": milliamps, "working_current_unsaved": 1})

    def set_holding_current(self, code: int) -> None:
        """0x9B holding current: 0 = 10 % ... 8 = 90 % of Ma (OPEN/CLOSE modes)."""
        self.write_param("holding_current", code)

    def set_microsteps(self, microsteps: int) -> None:
        """0x84 subdivision 1-256 (speeds and pulses scale with it: 6.1)."""
        self.write_param("microsteps", microsteps)

    def set_direction(self, direction: int) -> None:
        """0x86 direction of the pulse interface (0 CW, 1 CCW); serial commands carry their own."""
        self.write_param("motor_direction", direction)

    def set_en_level(self, level: int) -> None:
        """0x85 En pin active level: 0 low, 1 high, 2 always enabled."""
        self.write_param("en_active_level", level)

    def set_locked_rotor_protection(self, on: bool) -> None:
        """0x88 locked-rotor protection on/off."""
        self.write_param("locked_rotor_protection", int(on))

    def release_protection(self) -> None:
        """0x3D release the locked-rotor protection."""
        self.clear_errors()

    def write_io(self, *, out1: int | None = None, out2: int | None = None) -> None:
        """0x36 (V1.0.6+; Modbus FC16 0x0036): set OUT_1 / OUT_2 to 0 or 1; a port given None is not written.
        Read the levels back with ``read("io_status")`` (bit2 OUT_1, bit3 OUT_2)."""
        if out1 is None and out2 is None:
            raise CommandError(f"{self.name}: write_io needs out1 and/or out2 (0 or 1)")
        self.access.write_many({"write_io_out1_mask": 0 if out1 is None else 1, "write_io_out1": out1 or 0,
                                "write_io_out2_mask": 0 if out2 is None else 1, "write_io_out2": out2 or 0},
                               idempotent=True)

    def set_pulse_divider(self, period: int | None, *, start_high: bool = False) -> None:
        """0x99 (V1.0.9, 57D only; Modbus FC16 0x0099): OUT_2 becomes a pulse divider output that toggles once
        every ``period`` pulses (microsteps: 3200 at 16 microsteps = once per turn), starting low (or high);
        None (sent as 0) turns it off. The manual: below 100 there is no divider output."""
        if period is not None and not 100 <= period <= 0xFFFFFFFF:
            raise CommandError(f"{self.name}: 0x99 divPeriod {period}: 100..4294967295 pulses (below 100 the drive "
                               "gives no divider output; use None to turn it off)")
        self.access.write_many({"pulse_divider_level": int(start_high), "pulse_divider_period": period or 0})

    def set_in1_mode(self, output: bool, *, confirm: bool = False) -> None:
        """0x9F (V1.0.9, 28D/35D/42D only, native only): IN_1 as an output (written by ``write_io(out1=...)``,
        0x36 bit 2, whatever its mask) or back to an input (the default). As an output IN_1 reads no switch, so
        the home / left limit switch wired to it stops working (unless 0x9E remaps it to En): ``output=True``
        needs ``confirm=True``."""
        if output:
            self._confirm("0x9F makes IN_1 an output: a home or limit switch wired to it is no longer read", confirm)
        self.access.write_many({"in1_port_mode": int(output)})

    def set_position_error_protection(self, on: bool, *, window: float = 0.3, error: float = math.pi,
                                      en_zero_return: bool = False, confirm: bool = False) -> None:
        """0x9D (V1.0.6+; Modbus FC16 0x009D): protect (release the shaft, 0x3E = 1) when the position error
        stays above ``error`` [rad, motor side] for ``window`` [s] (sent as Tim = window / 15 ms and Errors =
        28000 per turn). ``en_zero_return`` (g0Enable) makes the motor MOVE to its 0_Mode zero on an En pulse
        instead of at power-on: it needs ``confirm=True``. Release with ``clear_errors()`` (0x3D)."""
        if en_zero_return:
            self._confirm("0x9D g0Enable makes the motor move to its zero point on an En pulse", confirm)
        tim = round(window / 0.015)
        errors = round(abs(error) * 28000 / (2.0 * math.pi))
        if not (0 <= tim <= 0xFFFF and 0 <= errors <= 0xFFFF):
            raise CommandError(f"{self.name}: 0x9D window {window} s -> Tim {tim}, error {error} rad -> Errors "
                               f"{errors}: each must fit 0..65535 (15 ms and 1/28000 turn per unit)")
        self.access.write_many({"en_trigger_zero_return": int(en_zero_return), "position_error_protection": int(on),
                                "position_error_time": tim, "position_error_count": errors})

    def set_position_threshold(self, threshold: float | None) -> None:
        """0x95 (V1.0.8+, native only): a position move completes only while its error is below ``threshold``
        [rad, motor side; sent as 65536 per turn, the drive's default 200 = 1.1 degrees]; None switches the
        check off."""
        values = 0 if threshold is None else round(abs(threshold) * 65536 / (2.0 * math.pi))
        if values > 0xFFFF:
            raise CommandError(f"{self.name}: 0x95 threshold {threshold} rad is more than a turn (65535 max)")
        self.access.write_many({"position_threshold_enable": int(threshold is not None),
                                "position_threshold": values if threshold is not None else self.params[
                                    "position_threshold"].default})

    def read_parameter(self, key: str | int) -> dict[str, int]:
        """0x00 (V1.0.8+): read back the setting(s) of the set command that carries ``key``. The Modbus-RTU
        manual has no such request: over Modbus it raises :class:`RegisterError`."""
        raise RegisterError(f"{self.name}: reading a configuration parameter (0x00) is native-protocol only; the "
                            "Modbus-RTU manual has no such request")

    def read_pid(self, mode: str) -> tuple[int, int, int, int]:
        """Kp, Ki, Kd, Kv of 0x96 (``mode="vfoc"``) / 0x97 (``"close"``), read back by 0x00 (V1.0.8+, native)."""
        if mode not in ("vfoc", "close"):
            raise CommandError(f"{self.name}: PID mode must be 'vfoc' (0x96) or 'close' (0x97), got {mode!r}")
        values = self.read_parameter(f"{mode}_kp")
        kp, ki, kd, kv = (values[f"{mode}_{k}"] for k in ("kp", "ki", "kd", "kv"))
        return kp, ki, kd, kv

    def set_pid(self, mode: str, kp: int, ki: int, kd: int, kv: int, *, confirm: bool = False) -> None:
        """0x96 (``mode="vfoc"``) / 0x97 (``"close"``) PID parameters, 0-1024 each (V1.0.8+; Modbus FC16
        0x0096 / 0x0097). The manual advises against changing the factory tuning ("to avoid damaging the
        motor"): needs ``confirm=True``. The twin keeps them but its servo is its own model (docs)."""
        if mode not in ("vfoc", "close"):
            raise CommandError(f"{self.name}: PID mode must be 'vfoc' (0x96) or 'close' (0x97), got {mode!r}")
        self._confirm(f"0x{0x96 if mode == 'vfoc' else 0x97:02X} changes the factory PID tuning", confirm)
        self.access.write_many({f"{mode}_kp": kp, f"{mode}_ki": ki, f"{mode}_kd": kd, f"{mode}_kv": kv})

    def enter_iap_boot(self, *, confirm: bool = False) -> None:
        """0x50 01 (V1.0.8+; Modbus FC06 0x0050 = 1): the drive restarts into its IAP boot loader and waits for a
        firmware file (MKS's upgrade tool and file format, not joints): this joint is lost until the upgrade
        ends or the drive is power-cycled. Needs ``confirm=True``."""
        self._confirm("0x50 01 restarts the drive into its firmware-upgrade boot loader (the joint is lost until "
                      "an upgrade or a power cycle)", confirm)
        self.write_param("iap_control", 1, idempotent=False)
        self.forget()

    def set_iap_silent(self, on: bool, *, confirm: bool = False) -> None:
        """0x50 02 / 03 (V1.0.8+): the silent state, where the drive hears nothing but 0x50 - not even a stop
        (entering it needs ``confirm=True``; use it on the drives that are not being upgraded)."""
        if on:
            self._confirm("0x50 02 makes the drive deaf to every command but 0x50, stops included", confirm)
        self.access.require(("iap_control",))
        if on:  # no answer is lost here: the drive answers 0x50 before it falls silent
            self.write_param("iap_control", 2, idempotent=True)
        else:
            self.write_param("iap_control", 3, idempotent=True)

    def set_home(self, *, trigger_level: int = 0, direction: int = 0, speed: int = 60, end_limit: int = 0) -> None:
        """0x90 home parameters: end-stop level (0 low), home direction (0 CW, 1 CCW), speed [rpm], EndLimit."""
        self.access.write_many({"home_trigger_level": trigger_level, "home_direction": direction,
                                "home_speed": self.speed_value(speed), "end_limit": end_limit})

    def set_nolimit_home(self, *, reverse_angle: int = 0x2000, mode: int = 1, current: int | None = None) -> None:
        """0x94 'noLimit' homing: back off ``reverse_angle`` counts after the stall, hm-Mode (0 switch, 1 no switch,
        2 single lap to zero from V1.0.9), Hm_Ma [mA] (default the model's). Over Modbus FC16 0x0094, from
        firmware V1.0.6. Mode 2 on an older profile: ``RegisterError`` naming v1.0.9, nothing sent."""
        ma = round(self.profile.default_home_current * 1000) if current is None else current
        self.access.write_many({"home_reverse_angle": reverse_angle, "home_mode": mode, "home_current": ma})

    def go_home(self) -> None:
        """0x91 go home (limit switch, or 'noLimit' per 0x94); the end comes as a completion / status 1."""
        self.write_param("go_home", 1, idempotent=False)
        self._sent_count = self.completions
        self._running = "home"
        self._sent_at = self.clock.now()

    def coordinate_home(self) -> None:
        """0x91 goZeroMode 01 / FC06 0x0091 = 2 (V1.0.9): run to the coordinate zero point (the one the last
        origin homing, 0x92 or the single-turn zero set) at HmSpeed, without a search; ends like go home."""
        self.access.write_many({"go_home": 1, "go_home_mode": 1}, idempotent=False)
        self._sent_count = self.completions
        self._running = "home"
        self._sent_at = self.clock.now()

    def set_limit_remap(self, on: bool) -> None:
        """0x9E limit port remap (left -> En, right -> Dir; serial modes)."""
        self.write_param("limit_port_remap", int(on))

    def set_zero(self, *, confirm: bool = False) -> None:
        """0x92 make the present axis zero (the encoder and pulse positions restart at 0)."""
        self._confirm("0x92 sets the present axis to zero (every stored position changes meaning)", confirm)
        self.write_param("set_current_axis_to_zero", 1, idempotent=False)

    def set_zero_mode(self, mode: int, *, set_zero: int = 1, speed: int = 2, direction: int = 0,
                      confirm: bool = False) -> None:
        """0x9A 0_Mode: 0 disable, 1 DirMode, 2 NearMode - the motor MOVES at power-on to the zero point."""
        self._confirm("0x9A 0_Mode makes the motor move by itself at every power-on", confirm)
        self.access.write_many({"zero_mode": mode, "zero_mode_set_zero": set_zero, "zero_mode_speed": speed,
                                "zero_mode_direction": direction})

    def save_speed_mode(self, *, confirm: bool = False) -> None:
        """0xFF C8: save the speed-mode parameters - the motor then RUNS by itself at every power-on."""
        self._confirm("0xFF C8 saves the speed mode: the motor will run by itself at every power-on", confirm)
        self.write_param("save_clean_speed_mode_parameter", st.SpeedModeParameter.SAVE, idempotent=False)

    def clean_speed_mode(self) -> None:
        """0xFF CA: clean the saved speed-mode parameters (no run at power-on)."""
        self.write_param("save_clean_speed_mode_parameter", st.SpeedModeParameter.CLEAN, idempotent=False)

    def restore_defaults(self, *, confirm: bool = False) -> None:
        """0x3F restore the default parameters: the drive reboots and must be calibrated again."""
        self._confirm("0x3F restores the factory parameters (the drive reboots and needs calibrating)", confirm)
        self.write_param("restore_default_parameters", 1, idempotent=False)
        self.forget()

    def restart(self, *, confirm: bool = False) -> None:
        """0x41 restart the drive (it releases the shaft while it reboots)."""
        self._confirm("0x41 restarts the drive (the shaft is released while it reboots)", confirm)
        self.write_param("restart_motor", 1, idempotent=False)
        self.forget()

    def calibrate(self, *, confirm: bool = False) -> None:
        """0x80 calibrate the encoder: the shaft MOVES; the motor must be unloaded."""
        self._confirm("0x80 calibration turns the shaft (the motor must be unloaded)", confirm)
        self.write_param("calibrate", 1, idempotent=False)

    def set_baud_rate(self, code: int, *, confirm: bool = False) -> None:
        """0x8A baud rate code (1 9600 ... 7 256000): the host loses the drive until it follows."""
        self._confirm("0x8A changes the drive's baud rate: this bus loses it until its baud rate follows", confirm)
        self.write_param("baud_rate", code)

    def set_address(self, address: int, *, confirm: bool = False) -> None:
        """0x8B slave address: the host loses the drive at the old address."""
        self._confirm("0x8B changes the drive's address: this joint loses it", confirm)
        self.write_param("slave_address", address)

    def set_modbus(self, on: bool, *, confirm: bool = False) -> None:
        """0x8E Modbus-RTU on/off: the drive switches protocol (this bus loses it)."""
        self._confirm("0x8E switches the drive's protocol: this bus loses it", confirm)
        self.write_param("modbus_rtu", int(on))

    def close(self) -> None:
        """Nothing to release (subclasses drop their subscriptions)."""

    def describe_running(self) -> str | None:
        """The run mode this host started last and believes running (None: none)."""
        return self._running


class MksHeartbeat:
    """V1.0.9's heartbeat protection (0x98) as the communication watchdog (mixed into the MKS drivers of
    a V1.0.9 joint, so ``isinstance(driver, CommunicationWatchdog)`` holds only for them).

    The drive cannot report the time it holds: :meth:`communication_timeout` is what this host wrote,
    else the power-on default 0 (off).
    """

    def set_communication_timeout(self: MksDriver, milliseconds: int) -> None:  # type: ignore[misc]
        """0x98 heartbeat protection time [ms]; 0 switches it off."""
        self.verify_firmware()
        self.write_param("heartbeat_protection_time", milliseconds)

    def communication_timeout(self: MksDriver) -> int:  # type: ignore[misc]
        self.verify_firmware()
        return self.image.get("heartbeat_protection_time", 0)
