"""Emulated ZeroErr eRob drive: the register image of the Modbus manual plus the drive's own loops.

Rule: the emulator IS the drive. It answers Modbus frames from its register image (through
:class:`~joints.sim.modbus_slave.ModbusSlave`), acts on writes as the manual says the drive does,
and every physics substep closes its own loops - profile generator -> position loop (0x0030) ->
speed loop (0x0031/0x0032) -> current limits -> torque = current x torque constant - from the
registers it holds. It returns a torque for the joint; it never sets a position. No wall clock:
time advances only through :meth:`ErobEmulator.step`.

Conventions the manuals leave open (documented emulator choices):

* Gains: ``position_loop_gain`` is Kp in 0.1 /s (speed command = Kp x position error);
  ``speed_loop_gain`` is the speed-loop bandwidth in rad/s (torque = J x bandwidth x speed
  error, J = the joint's inertia seen by the drive); ``speed_loop_integral`` is the integral time
  constant in 0.1 ms. The speed loop adds the profile's acceleration as feedforward
  (current = J x a_ref / kt), so the integral does not have to carry the ramps.
* Torque-mode max speed (0x00D8) = 0 means "no limit but max_speed" (the manual's 5.3.2 sets 0 and
  the motor still turns, ERRATA DOC-EROB-EN-6).
* Min/max position limit with min >= max means "no software limits".
* Fault codes not in our manuals use the CiA 402 error codes (following error 0x8611, speed error
  0x8400, stall 0x7121, software position limit 0x8612, over-temperature 0x4310); the RS485
  watchdog is the manual's 0xFA2; start while the motor is off is the eRunner code 0x0027.
* "Enable" releases the brake and the motor is ready 500 ms later (the manual's wait); a start,
  speed or current command before that is refused with 0x0027 and nothing moves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from joints.codecs import modbus as mb
from joints.devices.erob import faults
from joints.devices.erob.profiles import ErobProfile
from joints.devices.erob.registers import (
    COUNTS_PER_REV,
    EROB_MODBUS,
    AchieveStatus,
    MotionMode,
    MotionStatus,
    OperationMode,
)
from joints.devices.registers import Register
from joints.sim.modbus_slave import ILLEGAL_DATA_VALUE, ModbusException, ModbusSlave

COUNTS_PER_RAD = COUNTS_PER_REV / (2.0 * math.pi)
ENABLE_DELAY = 0.5  #: s from "enable" to motor ready (manual: wait 500 ms before start)
ESTOP_TIME = 0.04  #: s, emergency stop decelerates within this (manual: < 50 ms)
#: registers whose values _cache_settings() turns into loop constants (a write to any other
#: register, e.g. a target, does not need the recomputation)
_CACHED_SETTINGS = frozenset((
    "position_offset", "position_loop_gain", "speed_loop_gain", "speed_loop_integral",
    "continuous_current", "peak_current", "max_motor_current", "peak_current_time", "max_speed",
    "max_acceleration", "profile_acceleration", "profile_deceleration", "profile_speed",
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
    """Text of a fault the emulator can raise (manual codes first, then the CiA 402 ones)."""
    if code in faults.FAULTS:
        return faults.FAULTS[code].text
    return EMULATOR_FAULTS.get(code, faults.describe(code).text)


def power_on_defaults(profile: ErobProfile, address: int) -> dict[str, int]:
    """Register values after power-on of a factory-fresh drive of this variant."""
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


#: Registers kept over a power cycle when saved (settings, not status or commands).
_SETTINGS = tuple(r.name for r in EROB_MODBUS if r.access.value == "R/W")


@dataclass
class _Profile:
    """State of the trapezoidal profile generator (counts, count/s)."""

    active: bool = False
    target: float = 0.0
    continuous: bool = False  #: run at profile speed until stopped
    stopping: bool = False  #: decelerating to standstill (stop command)
    rate: float = 0.0  #: deceleration override (emergency stop)


class ErobEmulator(ModbusSlave):
    """One emulated eRob on a Modbus bus, coupled to one simulated joint."""

    def __init__(
        self,
        profile: ErobProfile,
        address: int,
        *,
        inertia: float | None = None,
        multi_turn: bool = True,
        ambient: float = 30.0,
    ) -> None:
        self.profile = profile
        self.multi_turn = multi_turn
        self.ambient = ambient
        self.inertia = inertia if inertia is not None else profile.armature  #: J the drive tunes for
        self.kt = profile.torque_constant
        self.time = 0.0
        self._saved: dict[str, int] = {}
        self._defaults = power_on_defaults(profile, address)
        super().__init__(EROB_MODBUS, address, values=self._defaults)
        self._reset_state()

    # -- power-on state ---------------------------------------------------------------------
    def _reset_state(self) -> None:
        self.enabled = False
        self.enabled_at = -1.0
        self.fault = 0
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
        self.last_frame = -1.0
        self.started = False
        self._sup = 0.0
        self._cache_settings()

    def power_cycle(self) -> None:
        """Simulated power off/on: saved settings survive, everything else is power-on default."""
        pos = self.pos
        for reg in self.table:
            self._store(reg, 0)
        for name, value in self._defaults.items():
            self.set(name, value)
        for name, value in self._saved.items():
            self.set(name, value)
        self.address = self.v["modbus_address"]
        self._reset_state()
        # absolute encoder: a single-turn module keeps only the angle within one turn
        self.pos = pos if self.multi_turn else pos % COUNTS_PER_REV
        self.p_ref = self.pos
        self.write_log.clear()

    # -- typed helpers ----------------------------------------------------------------------
    def _cache_settings(self) -> None:
        g = self.get
        self.offset = g("position_offset")
        self.kp = g("position_loop_gain") / 10.0
        bw = float(g("speed_loop_gain"))
        ti = g("speed_loop_integral") * 1e-4
        # torque per (count/s) of speed error -> current per (count/s) in mA
        self.kv = self.inertia * bw / COUNTS_PER_RAD / self.kt * 1000.0
        self.ki = self.kv / ti if ti > 0 else 0.0
        self.kff = self.inertia / COUNTS_PER_RAD / self.kt * 1000.0  # mA per count/s^2
        self.i_cont = float(g("continuous_current"))
        self.i_peak = float(max(g("peak_current"), 1))
        self.i_max = float(max(g("max_motor_current"), 1))
        self.peak_time = g("peak_current_time") * 1e-3
        self.i_lim = min(self.i_peak, self.i_max)
        # holding brake: ~100 Hz stiffness against the drive's own inertia, damping ratio 0.7,
        # slipping above twice the rated torque
        self.brake_k = self.inertia * 400.0**2 / 4
        self.brake_c = 2.0 * 0.7 * math.sqrt(self.brake_k * self.inertia)
        self.brake_hold_torque = 2.0 * self.profile.rated_torque
        self.vmax = float(max(g("max_speed"), 1))
        self.amax = float(max(g("max_acceleration"), 1))
        # profile registers as floats for the per-substep loops (refreshed on every settings write)
        self.acc = float(g("profile_acceleration")) or self.amax
        self.dec = float(g("profile_deceleration")) or self.amax
        self.speed = float(g("profile_speed"))
        self.vprof = min(abs(self.speed), self.vmax)

    def place(self, q: float) -> None:
        """The joint is at ``q`` [rad] and at rest (start state, reset): encoder, setpoint and brake follow."""
        self.pos = self.p_ref = q * COUNTS_PER_RAD
        self.vel = self.v_ref = 0.0
        self.brake_hold = self.pos

    def counts(self) -> int:
        """Actual position register value: encoder counts + position offset."""
        return round(self.pos) + self.offset

    # -- Modbus side ------------------------------------------------------------------------
    def handle(self, request: mb.Request | mb.UnsupportedRequest) -> mb.Reply:
        self.last_frame = self.time
        return super().handle(request)

    def on_read(self, start: int, count: int) -> None:
        self._publish()

    def on_write(self, reg: Register, value: int) -> None:
        name = reg.name
        if reg.access.value == "R/W":
            if name == "torque_control_mode_max_speed" and self.enabled:
                raise ModbusException(ILLEGAL_DATA_VALUE, "torque-mode max speed only while disabled")
            if name in _CACHED_SETTINGS:
                self._cache_settings()
            if name == "target_speed" and self._mode() == OperationMode.SPEED:
                self._speed_command(value)
            elif name == "target_current" and self._mode() == OperationMode.TORQUE and value:
                self._ready_or_refuse()
            elif name == "operation_mode":
                self._change_mode()
            return
        # commands
        if name == "enable_the_motor":
            if value:
                self._enable()
            else:
                self._disable()
        elif name == "start_operating":
            self._start()
        elif name == "stop_operating":
            self._stop(self.v["profile_deceleration"])
        elif name == "emergency_stop":
            self._stop(max(abs(self.v_ref) / ESTOP_TIME, float(self.v["profile_deceleration"])))
            self.mode_speed_target = 0.0
            self.set("target_current", 0)
        elif name == "stop_repetitive_motion":
            self.repeat_stop = True
        elif name == "clear_errors":
            if value:
                self.fault = 0
                self.set("error_code", 0)
        elif name == "save_parameters":
            self._saved = {n: self.get(n) for n in _SETTINGS}
        elif name == "reset_output_encoder":
            self.pos = self.pos % COUNTS_PER_REV
            self.p_ref = self.pos

    def _mode(self) -> int:
        return self.v["operation_mode"]

    def _raise_fault(self, code: int) -> None:
        if self.fault:
            return
        self.fault = code
        self.set("error_code", code)
        self._disable()

    def _ready(self) -> bool:
        return self.enabled and not self.fault and self.time >= self.enabled_at + ENABLE_DELAY - 1e-9

    def _ready_or_refuse(self) -> bool:
        if self._ready():
            return True
        # Not enabled / brake not released yet: no motion, the error is visible.
        self.set("error_code", faults.START_WHILE_DISABLED)
        self.fault = self.fault or faults.START_WHILE_DISABLED
        return False

    def _enable(self) -> None:
        if self.fault and self.fault != faults.START_WHILE_DISABLED:
            return  # a faulted drive does not enable until errors are cleared
        if not self.enabled:
            self.enabled = True
            self.enabled_at = self.time
            self.p_ref = self.pos
            self.v_ref = 0.0
            self.integ = 0.0
            self.gen = _Profile()
            self.brake_hold = None

    def _disable(self) -> None:
        self.enabled = False
        self.gen = _Profile()
        self.v_ref = 0.0
        self.mode_speed_target = 0.0
        self.i_cmd = self.i_out = 0.0
        self.integ = 0.0
        self.started = False
        self.brake_hold = self.pos

    def _change_mode(self) -> None:
        self.gen = _Profile()
        self.integ = 0.0
        self.p_ref = self.pos
        self.v_ref = self.vel if self.enabled else 0.0
        self.mode_speed_target = 0.0
        self.started = False

    def _clamp_target(self, target: float) -> float:
        lo = self.v["min_position_limit_value"] - self.offset
        hi = self.v["max_position_limit_value"] - self.offset
        if lo < hi:
            return min(max(target, lo), hi)
        return target

    def _start(self) -> None:
        if self._mode() != OperationMode.POSITION:
            return
        if not self._ready_or_refuse():
            return
        motion = self.v["motion_mode"]
        g = self.gen
        g.stopping = False
        g.rate = 0.0
        self.started = True
        self.in_window_since = -1.0
        if motion == MotionMode.CONTINUOUS:
            g.active, g.continuous = True, True
        elif motion == MotionMode.ABSOLUTE:
            rel = self.v["target_relative_position"]
            if rel:
                g.target = self._clamp_target(self.p_ref + rel)
            else:
                g.target = self._clamp_target(self.v["target_absolute_position"] - self.offset)
            g.active, g.continuous = True, False
        elif motion == MotionMode.REPETITIVE:
            self.repeat_home = self.p_ref
            self.repeat_leg_to_target = True
            self.repeat_stop = False
            g.target = self._clamp_target(self.v["target_absolute_position"] - self.offset)
            g.active, g.continuous = True, False
        else:
            self.set("error_code", 0x0030)
            self.started = False

    def _stop(self, decel: float) -> None:
        g = self.gen
        if self._mode() == OperationMode.TORQUE:
            # no speed profile in torque mode: the current command goes to zero
            self.set("target_current", 0)
            return
        if self._mode() == OperationMode.SPEED:
            self.mode_speed_target = 0.0
            self.set("target_speed", 0)
        if g.active or self.v_ref:
            g.active, g.continuous, g.stopping = True, False, True
            g.rate = float(decel)
        self.repeat_stop = True

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

        Control loops run every substep; supervision (watchdog, stall, temperature, the settle
        timer of 0x007A) every :data:`SUPERVISION_PERIOD` of drive time; the communication
        watchdog every substep.
        """
        self.time = t
        self.pos = q * COUNTS_PER_RAD
        self.vel = qd * COUNTS_PER_RAD
        v = self.v
        wd = v["modbus_communication_timeout_duration"]
        if wd and self.last_frame >= 0 and t - self.last_frame > wd * 1e-3:
            if self.fault != faults.RS485_TIMEOUT:
                self.fault = 0
                self._raise_fault(faults.RS485_TIMEOUT)
            self.last_frame = -1.0
        self._sup += dt
        if self._sup >= SUPERVISION_PERIOD - 1e-12:
            self._supervise(self._sup)
            self._sup = 0.0
        if not self.enabled or self.fault or t < self.enabled_at + ENABLE_DELAY - 1e-9:
            if self.enabled and (not self.fault or self.fault == faults.START_WHILE_DISABLED):
                self.p_ref = self.pos  # brake still releasing (or start refused): hold here
            return self._brake_torque(q, qd)
        mode = v["operation_mode"]
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
                lim = v["max_position_error"]
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
            slim = v["max_speed_error"]
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
        if self.enabled and self.started and self.v["operation_mode"] == OperationMode.POSITION:
            self._achieve(self._moving())  # the settle timer of 0x007A runs on the drive, not on reads
        self._stall(period)
        self._thermal(period, self.i_out if self.enabled else 0.0)

    def _brake_torque(self, q: float, qd: float) -> float:
        """Holding brake: a stiff spring-damper to where it engaged, limited to the rated torque x 2."""
        self.v_ref = 0.0
        self.i_cmd = self.i_out = 0.0
        if self.brake_hold is None:
            self.brake_hold = self.pos
        tau = -self.brake_k * (self.pos - self.brake_hold) / COUNTS_PER_RAD - self.brake_c * qd
        hold = self.brake_hold_torque
        return max(-hold, min(hold, tau))

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
        target = float(self.v["target_current"])
        vlim = min(float(self.v["torque_control_mode_max_speed"]) or self.vmax, self.vmax)
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
                # keep the limiter's integral where it would take over smoothly (anti-windup)
                self.integ = min(self.integ, (abs(target) - self.kv * e) / self.ki)
        i = sgn * mag
        lim = self._current_limit(dt, i)
        return max(-lim, min(lim, i))

    def _speed_ramp(self, dt: float) -> None:
        target = self.mode_speed_target
        v = self.v_ref
        accel = self.acc
        decel = self.dec
        speeding_up = abs(target) > abs(v) and (v == 0 or (v > 0) == (target > 0))
        rate = accel if speeding_up else decel
        g = self.gen
        if g.stopping:  # Stop Operating / Emergency Stop: to standstill with the stop's deceleration
            target, rate = 0.0, g.rate or decel
        dv = target - v
        step = rate * dt
        v = target if abs(dv) <= step else v + math.copysign(step, dv)
        self.p_ref += 0.5 * (self.v_ref + v) * dt
        self.v_ref = v
        if g.stopping and v == 0.0:
            self.gen = _Profile()

    def _profile_step(self, dt: float) -> None:
        g = self.gen
        v = self.v_ref
        if not g.active:
            if self.dwell_until >= 0:
                if self.time >= self.dwell_until:
                    self.dwell_until = -1.0
                    self._next_repetitive_leg()
                return
            return
        accel = self.acc
        decel = g.rate or self.dec
        vmax = self.vprof
        if g.stopping:
            dv = -v
            step = decel * dt
            new_v = 0.0 if abs(dv) <= step else v + math.copysign(step, dv)
            self.p_ref += 0.5 * (v + new_v) * dt
            self.v_ref = new_v
            if new_v == 0.0:
                g.active = False
                g.stopping = False
                self.started = False
                self.dwell_until = -1.0
            return
        if g.continuous:
            target_v = math.copysign(vmax, self.speed) if self.speed else 0.0
            dv = target_v - v
            rate = accel if abs(target_v) > abs(v) else decel
            step = rate * dt
            new_v = target_v if abs(dv) <= step else v + math.copysign(step, dv)
            self.p_ref += 0.5 * (v + new_v) * dt
            self.v_ref = new_v
            return
        s = g.target - self.p_ref
        if s == 0.0 and v == 0.0:
            self._leg_done()
            return
        direction = 1.0 if s > 0 else -1.0
        # fastest speed from which we can still stop at the target with the deceleration, for
        # this discrete step: new_v^2 = 2*decel*(|s| - (v + new_v)/2*dt) (the continuous
        # sqrt(2*decel*|s|) runs ahead of the curve and ends the move early with a speed jump)
        h = decel * dt
        v_here = abs(v) if v * direction > 0 else 0.0
        disc = h * h + 4.0 * (2.0 * decel * abs(s) - h * v_here)
        v_allow = 0.5 * (math.sqrt(disc) - h) if disc > 0.0 else 0.0
        v_des = direction * min(vmax, v_allow)
        dv = v_des - v
        speeding_up = abs(v_des) > abs(v) and v * v_des >= 0
        step = (accel if speeding_up else decel) * dt
        new_v = v_des if abs(dv) <= step else v + math.copysign(step, dv)
        ds = 0.5 * (v + new_v) * dt
        if abs(ds) >= abs(s) or (abs(s) < 1.0 and abs(new_v) <= decel * dt):
            self.p_ref = g.target
            self.v_ref = 0.0
            self._leg_done()
            return
        self.p_ref += ds
        self.v_ref = new_v

    def _leg_done(self) -> None:
        g = self.gen
        g.active = False
        if self.v["motion_mode"] == MotionMode.REPETITIVE and self.started and not self.repeat_stop:
            self.dwell_until = self.time + self.v["dwell_time"] * 5e-5
        else:
            self.started = self.v["motion_mode"] != MotionMode.REPETITIVE and self.started

    def _next_repetitive_leg(self) -> None:
        if self.repeat_stop:
            return
        self.repeat_leg_to_target = not self.repeat_leg_to_target
        g = self.gen
        g.target = (
            self._clamp_target(self.v["target_absolute_position"] - self.offset)
            if self.repeat_leg_to_target
            else self.repeat_home
        )
        g.active, g.continuous, g.stopping = True, False, False

    def _stall(self, dt: float) -> None:
        sc, ss, st = self.v["struck_current"], self.v["struck_speed"], self.v["struck_time"]
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
        lim = self.v["power_temperature_protection_value"]
        if lim and self.temperature > lim:
            self._raise_fault(OVER_TEMPERATURE)

    # -- status registers -------------------------------------------------------------------
    def _publish(self) -> None:
        s = self.set
        off = self.offset
        s("actual_position", self.counts())
        s("given_position", round(self.p_ref) + off)
        s("position_error", round(self.p_ref - self.pos))
        s("given_speed", round(self.v_cmd if self.enabled else 0.0))
        s("current_speed", round(self.vel))
        s("speed_error", round((self.v_cmd - self.vel) if self.enabled else 0.0))
        s("given_current", round(self.i_cmd))
        s("motor_current", round(self.i_out))
        s("part_of_power_temperature", round(self.temperature))
        s("torque_sensor_value", round(self.i_out * self.kt))
        s("error_code", self.fault)
        moving = self._moving()
        if self.repeat_stop and self.v["motion_mode"] == MotionMode.REPETITIVE and self.gen.active:
            s("motion_status", int(MotionStatus.STOP_REPETITIVE))
        else:
            s("motion_status", int(MotionStatus.MOVING if moving else MotionStatus.STOP))
        s("status_of_achieving_position", int(self._achieve(moving)))

    def _moving(self) -> bool:
        return self.gen.active or self.dwell_until >= 0 or (self.enabled and abs(self.v_ref) > 0.5)

    def _achieve(self, moving: bool) -> AchieveStatus:
        if not self.enabled or self.fault and self.fault != faults.START_WHILE_DISABLED:
            return AchieveStatus.MOTOR_OFF
        if not self._ready():
            return AchieveStatus.MOTOR_OFF
        if self._mode() != OperationMode.POSITION or not self.started:
            return AchieveStatus.OPERATION if moving else AchieveStatus.MOTOR_ON
        if moving:
            self.in_window_since = -1.0
            return AchieveStatus.OPERATION
        window = self.v["position_reaches_set_precision"]
        if abs(self.gen.target - self.pos) <= window:
            if self.in_window_since < 0:
                self.in_window_since = self.time
            if self.time - self.in_window_since >= self.v["time_setting_of_achieving_position"] * 5e-5:
                return AchieveStatus.TARGET_REACHED
            return AchieveStatus.WAIT_TIME
        self.in_window_since = -1.0
        return AchieveStatus.WAIT_TIME
