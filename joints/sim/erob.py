"""The eRob's firmware: the drive's own behaviour, by parameter name, without a protocol.

Rule: the firmware IS the drive. It holds the eRob's parameters
(:data:`~joints.devices.erob.params.EROB_PARAMS`, the names of the Modbus manual's registers), acts
on writes as the manual says the drive does, runs the drive state machine of
:mod:`joints.devices.erob.state`, and every physics substep closes its own loops - profile
generator (:mod:`joints.devices.motion`) -> position loop (``position_loop_gain``) -> speed loop
(``speed_loop_gain`` / ``speed_loop_integral``) -> current limits -> torque = current x torque
constant. It returns a torque for the joint; it never sets a position. Status values
(``actual_position``, ``motion_status`` ...) are computed when a front reads them. Protocol
fronts reach it by name (:class:`~joints.sim.firmware.Firmware`); the Modbus front
(:mod:`joints.sim.modbus_front`) serves it over the register table
:data:`~joints.devices.erob.registers.EROB_MODBUS` at the address ``modbus_address`` held at
power-on. No wall clock: time advances only through :meth:`ErobFirmware.step`.

Conventions the manuals leave open (documented firmware choices):

* Gains: ``position_loop_gain`` is Kp in 0.1 /s (speed command = Kp x position error);
  ``speed_loop_gain`` is the speed-loop bandwidth in rad/s (torque = J x bandwidth x speed
  error, J = the joint's inertia seen by the drive); ``speed_loop_integral`` is the integral time
  constant in 0.1 ms. The speed loop adds the profile's acceleration as feedforward
  (current = J x a_ref / kt), so the integral does not have to carry the ramps.
* Torque-mode max speed (0x00D8) = 0 means "no limit but max_speed" (the manual's 5.3.2 sets 0 and
  the motor still turns, ERRATA DOC-EROB-EN-6). Writing it while enabled is refused (Modbus
  exception 03).
* Min/max position limit with min >= max means "no software limits".
* Fault codes not in our manuals use the CiA 402 error codes (following error 0x8611, speed error
  0x8400, stall 0x7121, software position limit 0x8612, over-temperature 0x4310); the RS485
  watchdog is the manual's 0xFA2; start while the motor is off is the eRunner code 0x0027.
* "Enable" releases the brake and the motor is ready 500 ms later (the manual's wait); a start,
  speed or current command before that is refused with 0x0027 and nothing moves (the state
  machine of :mod:`joints.devices.erob.state`).
* The settle timer of ``status_of_achieving_position`` (``time_setting_of_achieving_position``)
  runs in the drive's slow task and when that status is read; reading other parameters does not
  touch it.
* Continuous motion (motion mode 0) ramps with the acceleration whenever the profile speed is
  faster than the present speed, a reversal included (speed mode decelerates to the reversal).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from joints.devices.erob import faults
from joints.devices.erob.params import EROB_PARAMS
from joints.devices.erob.profiles import ErobProfile
from joints.devices.erob.registers import (
    COUNTS_PER_REV,
    AchieveStatus,
    MotionMode,
    MotionStatus,
    OperationMode,
)
from joints.devices.erob.state import ENABLE_DELAY, ENABLED, DriveState, Event
from joints.devices.erob.state import step as transition
from joints.devices.motion import Arrival, move_step, ramp
from joints.errors import ParameterRefused, Refusal
from joints.sim.firmware import Firmware

__all__ = [
    "COUNTS_PER_RAD",
    "EMULATOR_FAULTS",
    "ENABLE_DELAY",
    "FOLLOWING_ERROR",
    "OVER_TEMPERATURE",
    "POSITION_LIMIT",
    "SPEED_ERROR",
    "STALL",
    "ErobFirmware",
    "fault_text",
    "power_on_defaults",
]

COUNTS_PER_RAD = COUNTS_PER_REV / (2.0 * math.pi)
ESTOP_TIME = 0.04  #: s, emergency stop decelerates within this (manual: < 50 ms)
#: parameters whose values _cache_settings() turns into loop constants (a write to any other
#: parameter, e.g. a target, does not need the recomputation)
_CACHED_SETTINGS = frozenset((
    "position_offset", "position_loop_gain", "speed_loop_gain", "speed_loop_integral",
    "continuous_current", "peak_current", "max_motor_current", "peak_current_time", "max_speed",
    "max_acceleration", "profile_acceleration", "profile_deceleration", "profile_speed",
    "modbus_communication_timeout_duration", "max_position_error", "max_speed_error",
))
_TORQUE = int(OperationMode.TORQUE)
_SPEED = int(OperationMode.SPEED)
SUPERVISION_PERIOD = 0.002  #: s between the drive's slow tasks (stall, thermal, settle timer)

FOLLOWING_ERROR = 0x8611
SPEED_ERROR = 0x8400
STALL = 0x7121
POSITION_LIMIT = 0x8612
OVER_TEMPERATURE = 0x4310

EMULATOR_FAULTS = {
    FOLLOWING_ERROR: "position following error above max_position_error (0x00B9)",
    SPEED_ERROR: "speed error above max_speed_error (0x00BB)",
    STALL: "motor stalled (struck current/speed/time, 0x00C5-0x00C9)",
    POSITION_LIMIT: "position outside min/max position limit (0x00BD/0x00BF)",
    OVER_TEMPERATURE: "power stage above power_temperature_protection_value (0x00D1)",
}


def fault_text(code: int) -> str:
    """Text of a fault the twin can raise (manual codes first, then the CiA 402 ones)."""
    if code in faults.FAULTS:
        return faults.FAULTS[code].text
    return EMULATOR_FAULTS.get(code, faults.describe(code).text)


def power_on_defaults(profile: ErobProfile, address: int) -> dict[str, int]:
    """Parameter values after power-on of a factory-fresh drive of this variant."""
    max_speed = round(profile.max_speed * COUNTS_PER_RAD)
    cont = round(profile.rated_current * 1000)
    peak = round(max(profile.peak_current, profile.rated_current) * 1000)
    return {
        "modbus_address": address,
        "modbus_baud_rate": 4,
        "modbus_communication_timeout_duration": 0,
        "position_loop_gain": 500,  # Kp = 50 /s
        "speed_loop_gain": 200,  # bandwidth 200 rad/s
        "speed_loop_integral": 200,  # Ti = 20 ms
        "operation_mode": int(OperationMode.POSITION),
        "motion_mode": int(MotionMode.ABSOLUTE),
        "control_source": 0,
        "profile_speed": max_speed // 4,
        "profile_acceleration": max_speed,
        "profile_deceleration": max_speed,
        "dwell_time": 20000,  # 1 s
        "position_reaches_set_precision": 100,
        "time_setting_of_achieving_position": 200,  # 10 ms
        "continuous_current": cont,
        "peak_current": peak,
        "peak_current_time": 1000,
        "max_speed": max_speed,
        "max_acceleration": 10 * max_speed,
        "max_position_error": 10484,
        "max_speed_error": 84000,
        "min_position_limit_value": 0,
        "max_position_limit_value": 0,
        "max_phase_current": round(peak * 1.2),
        "max_motor_current": round(peak * 1.1),
        "struck_current": round(cont * 1.2),
        "struck_speed": 500,
        "struck_time": 20000,  # 1 s
        "min_permissible_bus_voltage": 44000,
        "max_permissible_bus_voltage": 55000,
        "power_temperature_protection_value": 85,
        "torque_control_mode_max_speed": 0,
        "bus_voltage": 48000,
        "part_of_power_temperature": 30,
        "status_of_achieving_position": int(AchieveStatus.MOTOR_OFF),
    }


#: Parameters kept over a power cycle when saved: the R/W settings (not status or commands), those
#: only the CAN custom protocol reaches (node id, jerk, ...) included.
_SETTINGS = tuple(p.name for p in EROB_PARAMS if p.access.value == "R/W")
_POSITION = int(OperationMode.POSITION)
_READY, _ENABLING, _REFUSED_ON = DriveState.READY, DriveState.ENABLING, DriveState.REFUSED_ON
ARRIVAL_WINDOW = 1.0  #: counts: a move closer than this at a speed one period can stop has arrived
_ON_STEP = Arrival.ON_STEP


@dataclass
class _Profile:
    """State of the trapezoidal profile generator (counts, count/s)."""

    active: bool = False
    target: float = 0.0
    continuous: bool = False  #: run at profile speed until stopped
    stopping: bool = False  #: decelerating to standstill (stop command)
    rate: float = 0.0  #: deceleration override (emergency stop)



class ErobFirmware(Firmware):
    """One eRob's firmware, coupled to one simulated joint.

    ``address`` is the power-on value of ``modbus_address``; ``inertia`` the J the drive's gains
    are tuned for (default: the profile's rotor inertia at the output).
    """

    #: motion commands: the drive acts on them ``command_delay`` (the profile's) after they arrive
    DELAYED = frozenset((
        "target_current", "target_speed", "start_operating", "stop_operating", "emergency_stop",
        "stop_repetitive_motion",
    ))

    def __init__(
        self,
        profile: ErobProfile,
        address: int = 1,
        *,
        inertia: float | None = None,
        multi_turn: bool = True,
        ambient: float = 30.0,
    ) -> None:
        super().__init__(EROB_PARAMS, values=power_on_defaults(profile, address))
        self.profile = profile
        self.multi_turn = multi_turn
        self.ambient = ambient
        self.inertia = inertia if inertia is not None else profile.armature  #: J the drive tunes for
        self.kt = profile.torque_constant
        self.command_delay = profile.command_delay
        self.time = 0.0
        self.computed.update({
            "actual_position": self.counts,
            "given_position": lambda: round(self.p_ref) + self.offset,
            "position_error": lambda: round(self.p_ref - self.pos),
            "given_speed": lambda: round(self.v_cmd if self.state in ENABLED else 0.0),
            "current_speed": lambda: round(self.vel),
            "speed_error": lambda: round((self.v_cmd - self.vel) if self.state in ENABLED else 0.0),
            "given_current": lambda: round(self.i_cmd),
            "motor_current": lambda: round(self.i_out),
            "part_of_power_temperature": lambda: round(self.temperature),
            "torque_sensor_value": lambda: round(self.i_out * self.kt),
            "error_code": lambda: self.fault,
            "motion_status": self._motion_status,
            "status_of_achieving_position": lambda: int(self._achieve(self._moving())),
        })
        self._commands = {
            "enable_the_motor": self._enable_command,
            "start_operating": self._start,
            "stop_operating": lambda value: self._stop(self.values["profile_deceleration"]),
            "emergency_stop": self._emergency_stop,
            "stop_repetitive_motion": self._stop_repetitive,
            "clear_errors": self._clear_errors,
            "save_parameters": lambda value: self.save(_SETTINGS),
            "release_brake": self._release_brake,
            "reset_output_encoder": self._reset_output_encoder,
        }
        self._reset_state()

    # -- power-on state ---------------------------------------------------------------------
    def _reset_state(self) -> None:
        self.state = DriveState.MOTOR_OFF
        self.enabled_at = -1.0
        self.fault = 0  #: the latched error code (0x0027 or a fault), 0 = none
        self.pos = 0.0  # counts (encoder, before offset)
        self.vel = 0.0  # count/s
        self.p_ref = 0.0  # counts (setpoint, before offset)
        self.v_ref = 0.0  # count/s
        self.v_cmd = 0.0
        self.i_cmd = 0.0  # mA
        self.i_out = 0.0  # mA
        self.integ = 0.0
        self.mode_speed_target = 0.0
        self.gen = _Profile()
        self.repeat_home = 0.0
        self.repeat_leg_to_target = True
        self.repeat_stop = False
        self.dwell_until = -1.0
        self.in_window_since = -1.0
        self.peak_since = -1.0
        self.stall_since = -1.0
        self.temperature = self.ambient
        self.brake_hold: float | None = None
        self.brake_released = False  #: released by command while the motor is off: nothing holds the joint
        self.last_frame = -1.0
        self.started = False
        #: a set-point stream drives the position reference (CiA 402 CSP/IP over CANopen): between
        #: set-points the reference moves on at v_ref (linear interpolation); set by a protocol front
        self.streaming = False
        self._sup = 0.0
        self._cache_settings()

    def power_cycle(self) -> None:
        """Simulated power off/on: saved settings survive, everything else is power-on default."""
        pos = self.pos
        super().power_cycle()
        self._reset_state()
        # absolute encoder: a single-turn module keeps only the angle within one turn
        self.pos = pos if self.multi_turn else pos % COUNTS_PER_REV
        self.p_ref = self.pos

    @property
    def enabled(self) -> bool:
        """The motor is enabled (brake released or releasing)."""
        return self.state in ENABLED

    # -- typed helpers ----------------------------------------------------------------------
    def _cache_settings(self) -> None:
        g = self.values
        self.mode = g["operation_mode"]
        self.watchdog = g["modbus_communication_timeout_duration"] * 1e-3  # s, 0 = off
        self.max_position_error = g["max_position_error"]
        self.max_speed_error = g["max_speed_error"]
        self.offset = g["position_offset"]
        self.kp = g["position_loop_gain"] / 10.0
        bw = float(g["speed_loop_gain"])
        ti = g["speed_loop_integral"] * 1e-4
        # torque per (count/s) of speed error -> current per (count/s) in mA
        self.kv = self.inertia * bw / COUNTS_PER_RAD / self.kt * 1000.0
        self.ki = self.kv / ti if ti > 0 else 0.0
        self.kff = self.inertia / COUNTS_PER_RAD / self.kt * 1000.0  # mA per count/s^2
        self.i_cont = float(g["continuous_current"])
        self.i_peak = float(max(g["peak_current"], 1))
        self.i_max = float(max(g["max_motor_current"], 1))
        self.peak_time = g["peak_current_time"] * 1e-3
        self.i_lim = min(self.i_peak, self.i_max)
        # holding brake: ~100 Hz stiffness against the drive's own inertia, damping ratio 0.7,
        # slipping above twice the rated torque
        self.brake_k = self.inertia * 400.0**2 / 4
        self.brake_c = 2.0 * 0.7 * math.sqrt(self.brake_k * self.inertia)
        self.brake_hold_torque = 2.0 * self.profile.rated_torque
        self.vmax = float(max(g["max_speed"], 1))
        self.amax = float(max(g["max_acceleration"], 1))
        # profile parameters as floats for the per-substep loops (refreshed on every settings write)
        self.acc = float(g["profile_acceleration"]) or self.amax
        self.dec = float(g["profile_deceleration"]) or self.amax
        self.speed = float(g["profile_speed"])
        self.vprof = min(abs(self.speed), self.vmax)

    def gain_params(self, channel: str | None = None) -> dict[str, str]:
        """The loop-gain parameters (for domain randomisation: joints.sim.world.World.perturb)."""
        return {"position": "position_loop_gain", "speed": "speed_loop_gain", "integral": "speed_loop_integral"}

    def place(self, q: float) -> None:
        """The joint is at ``q`` [rad] and at rest (start state, reset): encoder, setpoint and brake follow."""
        self.pos = self.p_ref = q * COUNTS_PER_RAD
        self.vel = self.v_ref = 0.0
        self.brake_hold = self.pos

    def counts(self) -> int:
        """Actual position value: encoder counts + position offset."""
        return round(self.pos) + self.offset

    # -- what the fronts call ---------------------------------------------------------------
    def frame_received(self) -> None:
        self.last_frame = self.time

    def check_write(self, name: str, value: int) -> None:
        if name == "torque_control_mode_max_speed" and self.state in ENABLED:
            raise ParameterRefused(Refusal.STATE, name, "torque-mode max speed only while disabled")

    def on_write(self, name: str, value: int) -> None:
        command = self._commands.get(name)
        if command is not None:
            command(value)
        elif name in _CACHED_SETTINGS:
            self._cache_settings()
        elif name == "target_speed":
            if self.mode == _SPEED:
                self._speed_command(value)
        elif name == "target_current":
            if self.mode == _TORQUE and value:
                self._ready_or_refuse()
        elif name == "operation_mode":
            self.mode = value
            self._change_mode()

    # -- state machine ----------------------------------------------------------------------
    def _ready(self) -> bool:
        state = self.state
        if state is _READY:
            return True
        if state is _ENABLING and self.time >= self.enabled_at + ENABLE_DELAY - 1e-9:
            self.state = _READY  # transition(ENABLING, BRAKE_RELEASED)
            return True
        return False

    def _ready_or_refuse(self) -> bool:
        if self._ready():
            return True
        # Not enabled / brake not released yet: no motion, the error is visible.
        self.state = transition(self.state, Event.MOTION) or self.state
        self.fault = self.fault or faults.START_WHILE_DISABLED
        return False

    def _raise_fault(self, code: int) -> None:
        new = transition(self.state, Event.PROTECTION)
        if new is None:  # an error is latched already
            return
        self.fault = code
        self.state = new
        self._motor_off()

    def _enable_command(self, value: int) -> None:
        if value:
            self._enable()
        else:
            self.state = transition(self.state, Event.DISABLE) or self.state
            self._motor_off()

    def _enable(self) -> None:
        state = self.state
        new = transition(state, Event.ENABLE)
        if new is None:
            return  # a faulted drive does not enable until errors are cleared
        self.state = new
        if state not in ENABLED:
            self.enabled_at = self.time
            self.p_ref = self.pos
            self.v_ref = 0.0
            self.integ = 0.0
            self.gen = _Profile()
            self.brake_hold = None
            self.brake_released = False

    def ready(self) -> bool:
        """The motor is on and its brake released: motion commands act now (for protocol fronts)."""
        return self._ready()

    def trip(self, code: int) -> None:
        """A protection a protocol front supervises (CANopen life guarding) trips with ``code``."""
        self._raise_fault(code)

    def _release_brake(self, value: int) -> None:
        """Release the holding brake of a motor that is off (CAN 0x014F): the joint moves freely until
        the next enable or disable hands the brake back to the drive."""
        if self.state not in ENABLED:
            self.brake_released = True

    def _motor_off(self) -> None:
        """Disable / fault: the loops stop and the brake engages where the joint is."""
        self.gen = _Profile()
        self.v_ref = 0.0
        self.streaming = False
        self.mode_speed_target = 0.0
        self.i_cmd = self.i_out = 0.0
        self.integ = 0.0
        self.started = False
        self.brake_hold = self.pos
        self.brake_released = False

    def _clear_errors(self, value: int) -> None:
        if value:
            self.fault = 0
            self.state = transition(self.state, Event.CLEAR) or self.state

    # -- commands ---------------------------------------------------------------------------
    def _change_mode(self) -> None:
        self.gen = _Profile()
        self.integ = 0.0
        self.p_ref = self.pos
        self.v_ref = self.vel if self.state in ENABLED else 0.0
        self.mode_speed_target = 0.0
        self.started = False

    def _clamp_target(self, target: float) -> float:
        lo = self.values["min_position_limit_value"] - self.offset
        hi = self.values["max_position_limit_value"] - self.offset
        if lo < hi:
            return min(max(target, lo), hi)
        return target

    def _start(self, value: int) -> None:
        v = self.values
        if self.mode != _POSITION:
            return
        if not self._ready_or_refuse():
            return
        motion = v["motion_mode"]
        g = self.gen
        g.stopping = False
        g.rate = 0.0
        self.started = True
        self.in_window_since = -1.0
        if motion == MotionMode.CONTINUOUS:
            g.active, g.continuous = True, True
        elif motion == MotionMode.ABSOLUTE:
            rel = v["target_relative_position"]
            if rel:
                g.target = self._clamp_target(self.p_ref + rel)
            else:
                g.target = self._clamp_target(v["target_absolute_position"] - self.offset)
            g.active, g.continuous = True, False
        elif motion == MotionMode.REPETITIVE:
            self.repeat_home = self.p_ref
            self.repeat_leg_to_target = True
            self.repeat_stop = False
            g.target = self._clamp_target(v["target_absolute_position"] - self.offset)
            g.active, g.continuous = True, False
        else:  # the parameter's range (0-2) keeps other values out
            self.started = False

    def _stop(self, decel: float) -> None:
        g = self.gen
        mode = self.mode
        if mode == _TORQUE:
            # no speed profile in torque mode: the current command goes to zero
            self.values["target_current"] = 0
            return
        if mode == _SPEED:
            self.mode_speed_target = 0.0
            self.values["target_speed"] = 0
        if g.active or self.v_ref:
            g.active, g.continuous, g.stopping = True, False, True
            g.rate = float(decel)
        self.repeat_stop = True

    def _emergency_stop(self, value: int) -> None:
        self._stop(max(abs(self.v_ref) / ESTOP_TIME, float(self.values["profile_deceleration"])))
        self.mode_speed_target = 0.0
        self.values["target_current"] = 0

    def _stop_repetitive(self, value: int) -> None:
        self.repeat_stop = True

    def _reset_output_encoder(self, value: int) -> None:
        self.pos = self.pos % COUNTS_PER_REV
        self.p_ref = self.pos

    def _speed_command(self, value: int) -> None:
        if value and not self._ready_or_refuse():
            return
        if value:
            self.gen = _Profile()  # a new speed command ends a stop ramp in progress
        self.mode_speed_target = float(max(-self.vmax, min(self.vmax, value)))

    # -- physics side -----------------------------------------------------------------------
    def step(self, t: float, dt: float, q: float, qd: float) -> float:
        """Run the drive's loops for the substep ending at ``t`` (length ``dt``) with the joint at
        ``q`` [rad], ``qd`` [rad/s]; return the motor torque at the output [N*m].

        Control loops run every substep; supervision (stall, temperature, the settle timer of
        0x007A) every :data:`SUPERVISION_PERIOD` of drive time; the communication watchdog every
        substep.
        """
        self.time = t
        self.pos = q * COUNTS_PER_RAD
        self.vel = qd * COUNTS_PER_RAD
        wd = self.watchdog
        if wd and self.last_frame >= 0 and t - self.last_frame > wd:
            if self.fault != faults.RS485_TIMEOUT:  # the watchdog's code replaces a latched one
                self.fault = faults.RS485_TIMEOUT
                self.state = transition(self.state, Event.WATCHDOG) or DriveState.FAULT
                self._motor_off()
            self.last_frame = -1.0
        self._sup += dt
        if self._sup >= SUPERVISION_PERIOD - 1e-12:
            self._supervise(self._sup)
            self._sup = 0.0
        state = self.state
        if state is not _READY:
            if state is _ENABLING and t >= self.enabled_at + ENABLE_DELAY - 1e-9:
                self.state = _READY  # transition(ENABLING, BRAKE_RELEASED)
            else:
                if state is _ENABLING or state is _REFUSED_ON:
                    self.p_ref = self.pos  # brake still releasing (or start refused): hold here
                return self._brake_torque(q, qd)
        mode = self.mode
        if mode == _TORQUE:
            i = self._torque_loop(dt)
        else:
            v_prev = self.v_ref
            pos, vel = self.pos, self.vel
            if mode == _SPEED:
                self._speed_ramp(dt)
                v_ref = v_cmd = self.v_ref
            else:
                self._profile_step(dt)
                v_ref = self.v_ref
                err = self.p_ref - pos
                v_cmd = v_ref + self.kp * err
                lim = self.max_position_error
                if lim and abs(err) > lim:
                    self._raise_fault(FOLLOWING_ERROR)
                    return self._brake_torque(q, qd)
            vmax = self.vmax
            if v_cmd > vmax:
                v_cmd = vmax
            elif v_cmd < -vmax:
                v_cmd = -vmax
            self.v_cmd = v_cmd
            e = v_cmd - vel
            slim = self.max_speed_error
            if slim and abs(v_ref - vel) > slim:
                self._raise_fault(SPEED_ERROR)
                return self._brake_torque(q, qd)
            # PI speed loop plus acceleration feedforward (the current the profile's own
            # acceleration needs, J x a / kt): without it the integral has to carry every ramp
            # and the joint overshoots when a ramp ends (an emergency stop bounced back ~8 %)
            i = self.kv * e + self.ki * self.integ + self.kff * (v_ref - v_prev) / dt
            if -self.i_cont <= i <= self.i_cont:  # common case: within the continuous current
                self.peak_since = -1.0
                lim_i = self.i_lim
            else:
                lim_i = self._current_limit(dt, i)
            if -lim_i < i < lim_i:
                self.integ += e * dt  # anti-windup: integrate only while unsaturated
            elif i > lim_i:
                i = lim_i
            else:
                i = -lim_i
        self.i_cmd = i
        self.i_out = i
        return i * 1e-3 * self.kt

    def _supervise(self, period: float) -> None:
        """The drive's slow tasks: settle timer, stall and thermal protection."""
        state = self.state
        on = state is _READY or state is _ENABLING or state is _REFUSED_ON  # in ENABLED (no enum hash per substep)
        if on and self.started and self.mode == _POSITION:
            self._achieve(self._moving())  # the settle timer of 0x007A runs on the drive
        self._stall(period)
        self._thermal(period, self.i_out if on else 0.0)

    def _brake_torque(self, q: float, qd: float) -> float:
        """Holding brake: a stiff spring-damper to where it engaged, limited to the rated torque x 2."""
        self.v_ref = 0.0
        self.i_cmd = self.i_out = 0.0
        if self.brake_released:
            return 0.0
        at = self.brake_hold
        if at is None:
            at = self.brake_hold = self.pos
        tau = -self.brake_k * (self.pos - at) / COUNTS_PER_RAD - self.brake_c * qd
        hold = self.brake_hold_torque
        if tau > hold:
            return hold
        if tau < -hold:
            return -hold
        return tau

    def _current_limit(self, dt: float, i: float) -> float:
        peak = min(self.i_peak, self.i_max)
        if abs(i) > self.i_cont and self.peak_time > 0:
            if self.peak_since < 0:
                self.peak_since = self.time
            if self.time - self.peak_since > self.peak_time:
                return self.i_cont
        else:
            self.peak_since = -1.0
        return peak

    def _torque_loop(self, dt: float) -> float:
        """Current = target current, capped by a PI speed limiter at the torque-mode max speed."""
        v = self.values
        target = float(v["target_current"])
        vlim = min(float(v["torque_control_mode_max_speed"]) or self.vmax, self.vmax)
        self.v_ref = self.vel
        self.p_ref = self.pos
        if target == 0.0:
            self.integ = 0.0
            return 0.0
        sgn = 1.0 if target > 0 else -1.0
        e = vlim - sgn * self.vel  # > 0 while below the limit in the commanded direction
        cap = self.kv * e + self.ki * self.integ  # magnitude the speed limiter allows
        if abs(target) >= cap:
            mag = cap
            self.integ += e * dt
        else:
            mag = abs(target)
            if self.ki:
                # keep the limiter's integral where it would take over smoothly (anti-windup), but
                # never below 0 while the proportional part alone allows more than the target: a cap
                # held exactly at the target clipped every rise of the command (a joint accelerating
                # lowers e), by ~20 % of the accelerating torque every other substep
                self.integ = min(self.integ, max(0.0, (abs(target) - self.kv * e) / self.ki))
        i = sgn * mag
        lim = self._current_limit(dt, i)
        return max(-lim, min(lim, i))

    def _speed_ramp(self, dt: float) -> None:
        g = self.gen
        v = self.v_ref
        if g.stopping:  # Stop Operating / Emergency Stop: to standstill with the stop's deceleration
            new_v = ramp(v, 0.0, self.acc, g.rate or self.dec, dt)
        else:
            new_v = ramp(v, self.mode_speed_target, self.acc, self.dec, dt)
        self.p_ref += 0.5 * (v + new_v) * dt
        self.v_ref = new_v
        if g.stopping and new_v == 0.0:
            self.gen = _Profile()

    def _profile_step(self, dt: float) -> None:
        g = self.gen
        if not g.active:
            if self.streaming:
                self.p_ref += self.v_ref * dt  # between two streamed set-points
                return
            if self.dwell_until >= 0 and self.time >= self.dwell_until:
                self.dwell_until = -1.0
                self._next_repetitive_leg()
            return
        v = self.v_ref
        decel = g.rate or self.dec
        if g.stopping:
            new_v = ramp(v, 0.0, self.acc, decel, dt)
            self.p_ref += 0.5 * (v + new_v) * dt
            self.v_ref = new_v
            if new_v == 0.0:
                g.active = False
                g.stopping = False
                self.started = False
                self.dwell_until = -1.0
            return
        if g.continuous:
            target_v = math.copysign(self.vprof, self.speed) if self.speed else 0.0
            # the acceleration whenever the target is faster than the present speed, even on a
            # reversal (speed mode decelerates to the reversal): kept as calibrated
            rate = self.acc if abs(target_v) > abs(v) else decel
            new_v = ramp(v, target_v, rate, rate, dt)
            self.p_ref += 0.5 * (v + new_v) * dt
            self.v_ref = new_v
            return
        self.p_ref, self.v_ref, arrived = move_step(self.p_ref, v, g.target, self.vprof, self.acc, decel, dt,
                                                    ARRIVAL_WINDOW, _ON_STEP)
        if arrived:
            self._leg_done()

    def _leg_done(self) -> None:
        g = self.gen
        g.active = False
        repetitive = self.values["motion_mode"] == MotionMode.REPETITIVE
        if repetitive and self.started and not self.repeat_stop:
            self.dwell_until = self.time + self.values["dwell_time"] * 5e-5
        else:
            self.started = not repetitive and self.started

    def _next_repetitive_leg(self) -> None:
        if self.repeat_stop:
            return
        self.repeat_leg_to_target = not self.repeat_leg_to_target
        g = self.gen
        g.target = (
            self._clamp_target(self.values["target_absolute_position"] - self.offset)
            if self.repeat_leg_to_target
            else self.repeat_home
        )
        g.active, g.continuous, g.stopping = True, False, False

    def _stall(self, dt: float) -> None:
        v = self.values
        sc, ss, st = v["struck_current"], v["struck_speed"], v["struck_time"]
        if sc and st and abs(self.i_out) > sc and abs(self.vel) < ss:
            if self.stall_since < 0:
                self.stall_since = self.time
            elif self.time - self.stall_since > st * 5e-5:
                self.stall_since = -1.0
                self._raise_fault(STALL)
        else:
            self.stall_since = -1.0

    def _thermal(self, dt: float, i_ma: float) -> None:
        # first-order model: rated current gives +40 K at steady state, time constant 300 s
        rise = 40.0 * (i_ma * 1e-3 / self.profile.rated_current) ** 2
        self.temperature += (self.ambient + rise - self.temperature) * dt / 300.0
        lim = self.values["power_temperature_protection_value"]
        if lim and self.temperature > lim:
            self._raise_fault(OVER_TEMPERATURE)

    # -- status values (computed when read) -------------------------------------------------
    def _motion_status(self) -> int:
        if self.repeat_stop and self.values["motion_mode"] == MotionMode.REPETITIVE and self.gen.active:
            return int(MotionStatus.STOP_REPETITIVE)
        return int(MotionStatus.MOVING if self._moving() else MotionStatus.STOP)

    def _moving(self) -> bool:
        if self.gen.active or self.dwell_until >= 0:
            return True
        state = self.state
        return (state is _READY or state is _ENABLING or state is _REFUSED_ON) and abs(self.v_ref) > 0.5

    def _achieve(self, moving: bool) -> AchieveStatus:
        if not self._ready():
            return AchieveStatus.MOTOR_OFF
        if self.mode != _POSITION or not self.started:
            return AchieveStatus.OPERATION if moving else AchieveStatus.MOTOR_ON
        if moving:
            self.in_window_since = -1.0
            return AchieveStatus.OPERATION
        window = self.values["position_reaches_set_precision"]
        if abs(self.gen.target - self.pos) <= window:
            if self.in_window_since < 0:
                self.in_window_since = self.time
            if self.time - self.in_window_since >= self.values["time_setting_of_achieving_position"] * 5e-5:
                return AchieveStatus.TARGET_REACHED
            return AchieveStatus.WAIT_TIME
        self.in_window_since = -1.0
        return AchieveStatus.WAIT_TIME
