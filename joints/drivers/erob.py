"""ZeroErr eRob: the procedures of the eRob manuals (Modbus manual v1.6 chapters 5 and 7), by parameter name.

Rule: every high-level call writes the parameters the manual's steps write, in the manual's order
(contiguous settings batched into one transaction where the protocol allows), and honours the
manual's 500 ms between "enable" and the first motion command by waiting on the injected clock.
Writes whose repetition could move the motor twice ("start operating") are never retried. The
procedures name parameters, not addresses: each protocol (Modbus RTU here; the CAN custom
protocol and CANopen) supplies a :class:`~joints.drivers.access.ParamAccess` and, where the drive
differs by protocol, a small subclass.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from joints.clock import Clock, MonotonicClock
from joints.devices.erob import faults
from joints.devices.erob.profiles import DEFAULT_MODEL, ErobProfile
from joints.devices.erob.profiles import profile as lookup_profile
from joints.devices.erob.registers import (
    COUNTS_PER_REV,
    AchieveStatus,
    MotionMode,
    MotionStatus,
    OperationMode,
)
from joints.devices.faults import Fault
from joints.drivers.access import ParamAccess
from joints.drivers.base import JointDriver, RawState, Units, raw_state, sampled_at
from joints.errors import ConfirmationRequired, DeviceFault, OutcomeUnknown, StateError

#: The manual: "After issuing the motor enable command, please wait for 500ms before issuing the
#: start motion command."
ENABLE_SETTLE = 0.5
#: Chapter 7: the calibrated zero sits at the middle of the single-turn range.
ZERO_BASE = 262144
#: Values the manual's examples write to command registers (ERRATA DOC-EROB-EN-5).
CMD_START = 1
CMD_STOP = 0
CMD_EMERGENCY_STOP = 1
CMD_STOP_REPETITIVE = 0
CMD_CLEAR_ERRORS = 1
CMD_SAVE = 2
CMD_RESET_ENCODER = 2
#: the status values :meth:`ErobDriver.state_from` compares with, as plain ints (an enum compare costs more)
_MOTOR_OFF, _OPERATION, _STOP = int(AchieveStatus.MOTOR_OFF), int(AchieveStatus.OPERATION), int(MotionStatus.STOP)
#: what :meth:`ErobDriver.state` reads (the Modbus status block 0x0060..0x0078: one FC03)
STATUS_NAMES = (
    "error_code", "motion_status", "status_of_achieving_position", "given_position", "actual_position",
    "position_error", "given_speed", "current_speed", "speed_error", "given_current", "motor_current",
    "bus_voltage", "part_of_power_temperature",
)


@dataclass(frozen=True, slots=True)
class CalibrationResult:
    """Outcome of :meth:`ErobDriver.calibrate_zero`."""

    actual_position: int  #: position read before the offset was applied [count]
    position_offset: int  #: the offset written (262144 - actual) [count]
    saved: bool  #: whether save_parameters was issued (power-cycle the drive afterwards)


class ErobDriver(JointDriver):
    """One eRob actuator, over whichever protocol ``access`` speaks."""

    device = "erob"
    #: the parameter that arms the drive's communication watchdog on this protocol (ms; 0 = off)
    watchdog_param: str | None = None
    #: what a lost "start" reply is checked against (motion_status, status_of_achieving_position and,
    #: where the protocol reaches it, given_position)
    start_check_names: tuple[str, ...] = STATUS_NAMES

    def __init__(
        self,
        access: ParamAccess,
        *,
        profile: ErobProfile | str | None = None,
        clock: Clock | None = None,
        name: str = "",
    ) -> None:
        self.access = access
        if profile is None:
            profile = DEFAULT_MODEL
        self.profile = lookup_profile(profile) if isinstance(profile, str) else profile
        self.clock: Clock = clock or MonotonicClock()
        self.name = name or "erob"
        self.units = Units.from_counts(COUNTS_PER_REV, 0.001, self.profile.torque_constant)
        self._enabled = False
        self._enabled_at: float | None = None
        self._cache: dict[str, int] = {}  # last values we wrote (skip redundant setup writes)

    # -- parameter primitives ----------------------------------------------------------------
    def write_param(self, name: str, value: int, *, idempotent: bool = True) -> None:
        self.access.write(name, value, idempotent=idempotent)
        self._cache[name] = int(value)
        if name == "enable_the_motor":
            self._note_enable(bool(value))

    def _set(self, name: str, value: int, *, force: bool = False) -> None:
        """Write a setting unless we know the drive already holds it."""
        if force or self._cache.get(name) != value:
            self.write_param(name, value)

    def _set_many(self, values: dict[str, int]) -> None:
        """Write settings in as few transactions as the protocol allows (skipped if all are cached)."""
        if not values or all(self._cache.get(k) == v for k, v in values.items()):
            return
        self.access.write_many(values)
        self._cache.update(values)

    def _command(self, name: str, value: int) -> None:
        """Write a command: never retried, never cached."""
        self.write_param(name, value, idempotent=False)
        self._cache.pop(name, None)

    def _validate(self, **values: int | None) -> None:
        """Range-check every value of a command before its first write (nothing sent on error)."""
        cache = self._cache
        for name, value in values.items():
            if value is not None and cache.get(name) != value:  # what the drive holds was checked
                self.params[name].check(value)

    def forget(self) -> None:
        """Forget cached settings and the enable state (after a power cycle or an external tool)."""
        self._cache.clear()
        self._note_enable(False)

    # -- power ------------------------------------------------------------------------------
    def _note_enable(self, on: bool) -> None:
        self._enabled = on
        self._enabled_at = self.clock.now() if on else None

    @property
    def is_enabled(self) -> bool:
        return self._enabled

    def enable(self) -> None:
        """Control source "none" (Modbus), then Enable the Motor (brake releases)."""
        self._set("control_source", 0)
        self._command("enable_the_motor", 1)
        self._note_enable(True)

    def disable(self) -> None:
        """Enable the Motor = 0: the motor is disabled and the brake engages."""
        self._command("enable_the_motor", 0)
        self._note_enable(False)

    def _settled(self) -> bool:
        """Enabled, and the manual's 500 ms after "enable" are over (a motion command needs no wait)."""
        return self._enabled and self._enabled_at is not None and self._enabled_at + ENABLE_SETTLE - self.clock.now() <= 0

    def _holds(self, settings: Mapping[str, int]) -> bool:
        """Whether the drive holds every one of ``settings`` (the values we last wrote)."""
        cache = self._cache
        for name, value in settings.items():
            if cache.get(name) != value:
                return False
        return True

    def _settle_after_enable(self) -> None:
        """Wait until 500 ms after "enable"; with the watchdog on, keep the bus alive meanwhile."""
        if not self._enabled or self._enabled_at is None:
            raise StateError(f"{self.name}: the motor is not enabled; call enable() first")
        watchdog = self._cache.get(self.watchdog_param, 0) * 1e-3 if self.watchdog_param else 0.0
        while True:
            wait = self._enabled_at + ENABLE_SETTLE - self.clock.now()
            if wait <= 0:
                return
            chunk = min(wait, watchdog / 2) if watchdog > 0 else wait
            self.clock.sleep(chunk)
            if watchdog > 0 and self.clock.now() < self._enabled_at + ENABLE_SETTLE:
                self.read("error_code")  # a frame resets the drive's communication timeout

    def _operation_mode(self, mode: OperationMode) -> None:
        self._set("operation_mode", int(mode))

    # -- position control (5.1) -------------------------------------------------------------
    def _profile(self, speed: int | None, acceleration: int | None, deceleration: int | None) -> dict[str, int]:
        out: dict[str, int] = {}
        if speed is not None:
            out["profile_speed"] = speed
        if acceleration is not None:
            out["profile_acceleration"] = acceleration
        if deceleration is not None:
            out["profile_deceleration"] = deceleration
        return out

    def configure_position(
        self,
        motion: MotionMode,
        *,
        speed: int | None = None,
        acceleration: int | None = None,
        deceleration: int | None = None,
        dwell: int | None = None,
        clear_relative: bool = False,
    ) -> None:
        """Steps before "enable" in 5.1.x: position mode, control source, motion mode, profile.

        Profile speed/acceleration/deceleration (0x0047..0x004C) go in one FC16 when all three
        are given; ``clear_relative`` writes Target Relative Position = 0 (5.1.1 step 7).
        """
        head, tail = self._position_settings(motion, dwell, clear_relative)
        for name, value in head.items():
            self._set(name, value)
        self._set_many(self._profile(speed, acceleration, deceleration))
        for name, value in tail.items():
            self._set(name, value)

    @staticmethod
    def _position_settings(motion: MotionMode, dwell: int | None = None,
                           clear_relative: bool = False) -> tuple[dict[str, int], dict[str, int]]:
        """What :meth:`configure_position` writes one by one, before and after the profile (in order)."""
        head = {"operation_mode": int(OperationMode.POSITION), "control_source": 0, "motion_mode": int(motion)}
        tail: dict[str, int] = {}
        if dwell is not None:
            tail["dwell_time"] = dwell
        if clear_relative:
            tail["target_relative_position"] = 0
        return head, tail

    #: what :meth:`move_to` (absolute) writes around its profile: ``_position_settings(ABSOLUTE, clear_relative=True)``,
    #: built once (a pure function of constants)
    _STEADY_HEAD, _STEADY_TAIL = _position_settings(MotionMode.ABSOLUTE, clear_relative=True)
    #: the settings speed and torque control write before their set-point (besides the ramps)
    _SPEED_SETTINGS: Mapping[str, int] = {"operation_mode": int(OperationMode.SPEED), "control_source": 0}
    _TORQUE_SETTINGS: Mapping[str, int] = {"operation_mode": int(OperationMode.TORQUE), "control_source": 0}

    # -- the steady case (the sim's compiled path, joints.compiled_path) ----------------------
    #: the same settings as (name, value) pairs, for the steady checks' one pass
    _STEADY_SETUP = (*_STEADY_HEAD.items(), *_STEADY_TAIL.items())
    _SPEED_SETUP = tuple(_SPEED_SETTINGS.items())
    _TORQUE_SETUP = tuple(_TORQUE_SETTINGS.items())

    def steady_move(self, speed: int, acceleration: int, deceleration: int) -> bool:
        """Whether :meth:`move_to` with this profile now writes nothing but its target and "start": the drive
        holds the setup and the profile, and the 500 ms after "enable" are over."""
        if not self._settled():
            return False
        get = self._cache.get
        for name, value in self._STEADY_SETUP:
            if get(name) != value:
                return False
        return (get("profile_speed") == speed and get("profile_acceleration") == acceleration
                and get("profile_deceleration") == deceleration)

    def steady_velocity(self, acceleration: int, deceleration: int) -> bool:
        """Whether :meth:`set_velocity` with these ramps now writes nothing but its target speed."""
        if not self._settled():
            return False
        get = self._cache.get
        for name, value in self._SPEED_SETUP:
            if get(name) != value:
                return False
        return get("profile_acceleration") == acceleration and get("profile_deceleration") == deceleration

    def steady_current(self) -> bool:
        """Whether :meth:`set_current` now writes nothing but its target current."""
        if not self._settled():
            return False
        get = self._cache.get
        for name, value in self._TORQUE_SETUP:
            if get(name) != value:
                return False
        return True

    #: the range checks a command makes before its first write (:meth:`_validate` itself, not a call of it: one
    #: keyword packing, not two)
    validate = _validate

    def note_written(self, name: str, value: int) -> None:
        """``value`` was written to ``name`` by another way than :meth:`write_param` (the compiled path)."""
        self._cache[name] = int(value)

    def configure_velocity(self, *, acceleration: int | None = None, deceleration: int | None = None) -> None:
        """Steps before "enable" in 5.2.2: speed mode, control source, ramps, target speed 0."""
        self._operation_mode(OperationMode.SPEED)
        self._set("control_source", 0)
        self._set_many(self._profile(None, acceleration, deceleration))
        self._set("target_speed", 0, force=True)

    def configure_torque(self, *, max_speed: int | None = None) -> None:
        """Steps before "enable" in 5.3.2: torque mode, control source, speed limit, current 0."""
        self._operation_mode(OperationMode.TORQUE)
        self._set("control_source", 0)
        if max_speed is not None:
            self.set_torque_speed_limit(max_speed)
        self._set("target_current", 0, force=True)

    def move_to(
        self,
        position: int,
        *,
        speed: int | None = None,
        acceleration: int | None = None,
        deceleration: int | None = None,
    ) -> None:
        """Move Absolute (5.1.1): relative value 0, target absolute position, start."""
        profile = self._profile(speed, acceleration, deceleration)
        if self._holds(profile):  # the drive holds this profile: nothing of it to check or write
            self._validate(target_absolute_position=position)
            self.configure_position(MotionMode.ABSOLUTE, clear_relative=True)
        else:
            self._validate(target_absolute_position=position, **profile)
            self.configure_position(MotionMode.ABSOLUTE, speed=speed, acceleration=acceleration,
                                    deceleration=deceleration, clear_relative=True)
        self._settle_after_enable()
        self._set("target_absolute_position", position, force=True)
        self._start(position)

    def move_by(
        self,
        delta: int,
        *,
        speed: int | None = None,
        acceleration: int | None = None,
        deceleration: int | None = None,
    ) -> None:
        """Move Relative (5.1.2): motion mode 1 with a target relative position, start."""
        self._validate(target_relative_position=delta, profile_speed=speed,
                       profile_acceleration=acceleration, profile_deceleration=deceleration)
        self.configure_position(MotionMode.ABSOLUTE, speed=speed, acceleration=acceleration, deceleration=deceleration)
        self._settle_after_enable()
        self._set("target_relative_position", delta, force=True)
        self._start(None)

    def move_continuous(self, speed: int, *, acceleration: int | None = None, deceleration: int | None = None) -> None:
        """Move Continuous (5.1.3): signed profile speed, start; stop() ends it."""
        self._validate(profile_speed=speed, profile_acceleration=acceleration, profile_deceleration=deceleration)
        self.configure_position(MotionMode.CONTINUOUS, speed=speed, acceleration=acceleration, deceleration=deceleration)
        self._settle_after_enable()
        self._start(None)

    def move_repetitive(
        self,
        position: int,
        *,
        speed: int | None = None,
        acceleration: int | None = None,
        deceleration: int | None = None,
        dwell: int | None = None,
    ) -> None:
        """Move Repetitive (5.1.4): dwell time [0.05 ms], target absolute position, start."""
        self._validate(target_absolute_position=position, profile_speed=speed, dwell_time=dwell,
                       profile_acceleration=acceleration, profile_deceleration=deceleration)
        self.configure_position(
            MotionMode.REPETITIVE, speed=speed, acceleration=acceleration, deceleration=deceleration, dwell=dwell
        )
        self._settle_after_enable()
        self._set("target_absolute_position", position, force=True)
        self._start(position)

    def _start(self, target: int | None) -> None:
        """Start Operating, never sent twice blindly: if its reply is lost, read back whether the drive
        started (moving, or its setpoint already at ``target``) and send it again only if it did not."""
        try:
            self._command("start_operating", CMD_START)
        except OutcomeUnknown as exc:
            self.start_unknown(target, exc)

    def start_unknown(self, target: int | None, exc: OutcomeUnknown) -> None:
        """The "Start Operating" write got no intact answer (``exc``): read back whether the drive started and send it
        again only if it did not (see :meth:`_start`)."""
        v = self.access.read_many(self.start_check_names)
        started = (v["motion_status"] != MotionStatus.STOP
                   or v["status_of_achieving_position"] in (AchieveStatus.OPERATION, AchieveStatus.WAIT_TIME)
                   or (target is not None and v.get("given_position") == target))
        if started:
            return
        if target is None and v["status_of_achieving_position"] == AchieveStatus.TARGET_REACHED:
            raise exc  # a short relative move may have run and ended already: unknown, do not repeat it
        self._command("start_operating", CMD_START)

    def stop_repetitive(self) -> None:
        """Stop Repetitive Motion (0x00F4): return to the start or stop at the target."""
        self._command("stop_repetitive_motion", CMD_STOP_REPETITIVE)

    # -- speed control (5.2) ----------------------------------------------------------------
    def set_velocity(self, velocity: int, *, acceleration: int | None = None, deceleration: int | None = None) -> None:
        """Speed control: mode 2, profile acceleration/deceleration, target speed [count/s]."""
        self._validate(target_speed=velocity, profile_acceleration=acceleration, profile_deceleration=deceleration)
        for name, value in self._SPEED_SETTINGS.items():
            self._set(name, value)
        self._set_many(self._profile(None, acceleration, deceleration))
        self._settle_after_enable()
        self._set("target_speed", velocity, force=True)

    # -- torque control (5.3) ---------------------------------------------------------------
    def set_torque_speed_limit(self, speed: int) -> None:
        """Torque Control Mode Max. Speed (0x00D8) [count/s]; the drive accepts it only disabled."""
        if self._enabled and self._cache.get("torque_control_mode_max_speed") != speed:
            raise StateError(
                f"{self.name}: the torque-mode speed limit can only be changed while disabled "
                "(eRunner manual, index 0x204); disable() first"
            )
        self._set("torque_control_mode_max_speed", speed)

    def set_current(self, current: int) -> None:
        """Torque control: mode 1, target current [mA] (negative = reverse torque)."""
        self._validate(target_current=current)
        for name, value in self._TORQUE_SETTINGS.items():
            self._set(name, value)
        self._settle_after_enable()
        self._set("target_current", current, force=True)

    # -- stopping ---------------------------------------------------------------------------
    def stop(self) -> None:
        """Stop Operating: decelerate with the profile deceleration (speed/torque targets zeroed)."""
        mode = self._cache.get("operation_mode")
        if mode == OperationMode.SPEED:
            self._set("target_speed", 0, force=True)
        elif mode == OperationMode.TORQUE:
            self._set("target_current", 0, force=True)
        self._command("stop_operating", CMD_STOP)

    def emergency_stop(self) -> None:
        """Emergency Stop (0x00F3): stops within 50 ms (hard deceleration)."""
        self._command("emergency_stop", CMD_EMERGENCY_STOP)

    def clear_errors(self) -> None:
        self._command("clear_errors", CMD_CLEAR_ERRORS)

    # -- status -----------------------------------------------------------------------------
    def state(self) -> RawState:
        """The drive's status in as few transactions as the protocol allows (Modbus: ONE FC03), stamped at the
        middle of its transaction (the drive sampled it between request and reply: :func:`sampled_at`)."""
        t0 = self.clock.now()
        v = self.access.read_many(STATUS_NAMES)
        return self.state_from(v, sampled_at(t0, self.clock.now()))

    def state_from(self, v: Mapping[str, int], t: float) -> RawState:
        """The state from status values read at ``t`` (at least error_code, motion_status,
        status_of_achieving_position, actual_position, current_speed, motor_current,
        part_of_power_temperature)."""
        achieve = v["status_of_achieving_position"]
        enabled = achieve != _MOTOR_OFF
        if not enabled and self._enabled:
            settling = self._enabled_at is not None and t - self._enabled_at < ENABLE_SETTLE + 0.1
            if v["error_code"] or not settling:
                # The drive disabled itself (fault, watchdog). During the 500 ms after "enable" it
                # reports "motor off" while the brake releases: that is not a disable.
                self._note_enable(False)
        # RawState(position, velocity, current, temperature, enabled, moving, fault, time, extra)
        return raw_state(v["actual_position"], v["current_speed"], v["motor_current"],
                         float(v["part_of_power_temperature"]), enabled,
                         v["motion_status"] != _STOP or achieve == _OPERATION, v["error_code"], t, v)

    def fault_text(self, code: int) -> str:
        return faults.describe(code).text

    def fault(self, code: int) -> Fault | None:
        return faults.fault(code)

    def check_fault(self) -> None:
        """Raise :class:`DeviceFault` if the drive reports an error code."""
        code = self.read("error_code")
        if code:
            info = faults.describe(code)
            raise DeviceFault(self.name, code, info.text, hint=info.hint, name=info.name)

    def motion_targets(self) -> dict[str, tuple[str, float]]:
        """Motion set-points, for the joint's checks of raw writes."""
        rad = self.units.position
        return {"target_absolute_position": ("position", rad), "target_relative_position": ("relative", rad),
                "profile_speed": ("velocity", rad), "target_speed": ("velocity", rad),
                "torque_control_mode_max_speed": ("velocity", rad), "target_current": ("current", 0.001)}

    # -- limits the drive enforces itself -----------------------------------------------------
    def apply_limits(self, *, position: tuple[int, int] | None = None, velocity: int | None = None,
                     current: int | None = None) -> None:
        """Software position limits (0x00BD/0x00BF, count incl. offset), max speed (count/s) and motor
        current (mA) into the drive's RAM, so it enforces them if the host dies (not saved)."""
        if position is not None:
            self._set_many({"min_position_limit_value": position[0], "max_position_limit_value": position[1]})
        if velocity is not None:
            self._set("max_speed", max(1, min(velocity, self.params["max_speed"].type_range[1])))
        if current is not None:
            self._set("max_motor_current", max(1, min(current, self.params["max_motor_current"].type_range[1])))

    # -- persistent operations (need confirmation) ------------------------------------------
    def save_parameters(self, *, confirm: bool = False) -> None:
        """Save Parameters (0x00F7): writes flash (~3 s); do not power off meanwhile."""
        if not confirm:
            raise ConfirmationRequired(
                f"{self.name}: save_parameters writes the drive's flash; pass confirm=True and "
                "keep power on for at least 3 s afterwards"
            )
        self._command("save_parameters", CMD_SAVE)

    def reset_output_encoder(self, *, confirm: bool = False) -> None:
        """Reset Output Encoder (0x00F9): clears the multi-turn count."""
        if not confirm:
            raise ConfirmationRequired(
                f"{self.name}: reset_output_encoder clears the multi-turn position; pass confirm=True"
            )
        self._command("reset_output_encoder", CMD_RESET_ENCODER)

    def calibrate_zero(self, *, multi_turn: bool = False, save: bool = True, confirm: bool = False) -> CalibrationResult:
        """Zero Position Calibration (chapter 7): make the present position read 262144.

        Steps: disable; (multi-turn: reset output encoder); position offset := 0 and verify;
        read the actual position; offset := 262144 - actual and verify; save parameters.
        The new zero takes effect after a power cycle of the drive.
        """
        if not confirm:
            raise ConfirmationRequired(
                f"{self.name}: zero calibration rewrites the position offset"
                + (" and resets the multi-turn encoder" if multi_turn else "")
                + (" and saves to flash" if save else "")
                + "; pass confirm=True"
            )
        self.disable()
        if multi_turn:
            self.reset_output_encoder(confirm=True)
        self.write_param("position_offset", 0)
        if self.read("position_offset") != 0:
            raise StateError(f"{self.name}: position offset did not read back as 0")
        actual = self.read("actual_position")
        if not 0 <= actual < COUNTS_PER_REV:
            raise StateError(
                f"{self.name}: actual position {actual} is outside 0..{COUNTS_PER_REV - 1} with a zero "
                "offset; for a multi-turn module use multi_turn=True"
            )
        offset = ZERO_BASE - actual
        self.write_param("position_offset", offset)
        got = self.read("position_offset")
        if got != offset:
            raise StateError(f"{self.name}: position offset reads back {got}, wrote {offset}")
        if save:
            self.save_parameters(confirm=True)
        return CalibrationResult(actual, offset, save)
