"""The ZLAC8015D's firmware: one dual-channel hub-servo drive (two motors), without a protocol.

Rule: the firmware IS the drive. It holds the drive's parameters (the names of the Modbus
register table :data:`~joints.devices.zlac.registers.ZLAC8015D`), acts on writes as the manual
says the drive does, runs the one drive state machine of :mod:`joints.devices.zlac.state`, and
every physics substep each channel closes its own loops - ramp / profile generator
(:mod:`joints.devices.motion`) -> position loop -> velocity loop -> current limits -> torque =
current x torque constant - from the parameters it holds. Status values (positions, speeds,
currents, error codes, motor/hall/temperature words) are computed when a front reads them. The
Modbus front (:mod:`joints.sim.modbus_front`) serves it at the address ``rs485_node_id`` held at
power-on. :attr:`ZlacFirmware.left` and :attr:`ZlacFirmware.right` are the two channels; the
world calls ``left.step(t, dt, q, qd)`` and ``right.step(t, dt, q, qd)`` every substep with the
same ``t`` and applies the returned wheel torque. The firmware never writes positions. No wall
clock: time advances only through ``step``.

Manual: ``../shared/manuals/zlac8015d-rs485-modbus-manual-v1.04.txt`` (OCR text, 1-based lines
below), corrected by ``../shared/vectors/ERRATA.md`` (DOC-ZLAC-1..7).

Semantics taken from the manual
-------------------------------
* Control word 0x200E (lines 852-868; 312-316, 400-408): 0x08 enable, 0x07 stop, 0x05 quick stop,
  0x06 clear faults, 0x10 start both wheels / 0x11 start left / 0x12 start right (position modes).
  ONE state machine for both motors (there is one control word). Control mode 0x200D (lines
  831-846) is shared too: 1 relative position, 2 absolute position, 3 velocity, 4 torque.
* Stop 0x07: 0x2012 "Stop control" says "Stop (switch to ready to switch on)" (lines 918-926),
  i.e. the power stage switches off and the wheels coast (friction only). 0x2012 = 0 ("Invalid")
  is treated the same. The community drivers' "disable" writes 0x07 as well.
* Quick stop 0x05 follows 0x2011 "Quick stop control" (lines 900-912): 5 = stop with the normal
  deceleration time (0x2082/0x2083), 6 = quick stop with the quick-stop deceleration time
  (0x2084/0x2085, default 10 ms, lines 1092-1097), 7 = quick stop without deceleration time
  (speed command 0 at once, the velocity loop brakes at the current limit). The codes are the CiA 402 quick-stop
  option codes 5/6/7, which all STAY in "quick stop active": the motors remain energised and hold
  zero speed until enable (0x08) resumes operation or stop (0x07) switches them off. Set-points
  written meanwhile are stored but not executed.
* Clear faults 0x06 (lines 744-777) clears both error-code registers 0x20A5/0x20A6; the drive is
  then disabled and needs 0x08. A fault whose cause persists (over-temperature) comes back.
* Synchronous/asynchronous 0x200F follows the firmware profile (:mod:`joints.devices.quirks`,
  joint key ``firmware``): by default the EXAMPLES (ERRATA DOC-ZLAC-1): 0 = asynchronous
  (lines 457-462: each wheel started with 0x11/0x12), 1 = synchronous (line 566: both started
  with 0x10); the ``register-table`` firmware takes the table's 0 = synchronous, 1 = asynchronous.
* Acceleration / deceleration time 0x2080-0x2083 (lines 318-329, 416-426, 1080-1091): the manual
  gives only "Acceleration time", unit ms, range 0-32767 ms, default 500, in the velocity-mode
  table next to the target velocity and in the position-mode table next to the target speed. No
  reference speed is named anywhere (0x2008 "Maximum motor speed", line 813, is a separate
  protection limit and is never linked to the ramp times). The firmware therefore reads the
  register literally as the **duration of the ramp to the commanded speed**:

  - velocity mode: writing a new target velocity (0x2088/0x2089) starts a linear ramp from the
    present speed command that arrives at the target exactly ``acceleration time`` later when
    the speed magnitude grows, ``deceleration time`` later when it shrinks; a reversal first
    decelerates to 0 in the deceleration time, then accelerates to the target in the
    acceleration time. 0 r/min -> 100 r/min with 500 ms takes 500 ms, and so does 0 -> 300 r/min.
    Re-writing the SAME target does not restart the ramp; a different target does (from the
    speed command at that moment). Changing a ramp time takes effect with the next target.
  - position modes: the move accelerates from standstill to the target speed 0x208E/0x208F in
    the acceleration time and decelerates from it to standstill in the deceleration time
    (trapezoid; triangular when the distance is too short).
  - 0 ms means "as fast as possible" (taken as 1 ms, the register's resolution).

  If hardware shows a fixed-slope semantics instead (time for 0 -> some reference speed), pass
  ``ramp_reference_rpm=...`` (e.g. 1000 for 0x2008's default): every ramp then has the slope
  ``ramp_reference_rpm / time``.
  The ramp shape is linear (the facts file calls the ramp "S-curve", the manual does not; the
  time to the target, which the register sets, is the same).
* Target velocity 0x2088/0x2089 (r/min, +-3000, lines 330-335) is clamped to 0x2008 (max motor
  speed, default 1000 r/min); one FC16 write of 0x2088-0x2089 sets both wheels (line 391).
* Position modes: target position 0x208A/0x208C (int32 counts, high word first; relative
  +-0x7FFFFFFF, absolute +-0x3FFFFFFF, lines 427-440 - an absolute-mode write outside the latter
  is refused with exception 03); target speed 0x208E/0x208F (1-1000 r/min, lines 441-446).
  A relative move goes ``target`` counts from the end point of the previous move (from the
  position at enable if there was none), so repeated relative moves do not accumulate error; an
  absolute move goes to ``target`` counts of the feedback-position frame (see 0x2005/0x2006).
  Target speed and ramp times are latched at the start command.
* Torque mode: target torque 0x2090/0x2091 in mA (+-30000), reached with the torque slope
  0x2086/0x2087 in mA/s (lines 646-660; default printed "300ms", DOC-ZLAC-5, read as 300 mA/s).
  Slope 0 = step. The speed is capped at 0x2008 (the current is reduced near it).
* Feedback (lines 1193-1368): actual position 0x20A7/0x20A9 int32 counts (4 x encoder lines
  0x2030/0x2060 per turn; the incremental counter starts at 0 at power-on), actual velocity
  0x20AB/0x20AC in 0.1 r/min, actual torque (current) 0x20AD/0x20AE in 0.1 A, error codes
  0x20A5/0x20A6 (:class:`~joints.devices.zlac.registers.Fault` bits), DC voltage 0x20A1 in 0.01 V,
  motor state 0x20A2 / hall state 0x20A3 / motor temperature 0x20A4 (1 degC) packed high byte =
  left, low byte = right.
* 0x2005 clear feedback position (lines 798-802; 1 = clear; the table allows 0-1: both wheels) and
  0x2006 reset the zero point (lines 803-807: 1 left, 2 right, 3 printed "right" again -> both,
  DOC-ZLAC-4) make the present position read 0 and become the zero of absolute targets. They move
  nothing, act at once and read back 0 ("Not saved").
* 0x2000 communication offline time (lines 782-785, ms, default 1000): with the motors energised
  and no frame received for longer than this, the drive treats the host as offline and performs a
  quick stop per 0x2011 (above), so the robot stops and holds; it does not restart until an
  enable. The fault list (lines 760-772) has no communication bit, so no error code is set; the
  trip is visible as 0x20AF "software connected status" = 0 (see conventions) and as
  :attr:`ZlacFirmware.offline`.
* 0x2010 = 1 stores the RW settings (they survive :meth:`ZlacFirmware.power_cycle`); 0x2009 = 1
  restores the factory settings; 0x2007 = 1 (saved) enables the motors at power-on; a new RS485
  node id 0x2001 takes effect after a power cycle.

Firmware conventions (the manual leaves these open)
---------------------------------------------------
* Gains (units are not printed): Vl Kp 0x203C/0x206C is the velocity-loop bandwidth in 0.1 rad/s
  (default 500 -> 50 rad/s): current = J x Kp x speed error / kt, J = the inertia the drive is
  tuned for = the wheel's own inertia at the joint (``inertia_left``/``inertia_right``: rotor +
  wheel body, i.e. MuJoCo's joint-space diagonal incl. armature; default the rotor,
  :attr:`HubMotorProfile.armature`) + the vehicle's share :attr:`HubMotorProfile.load_inertia`
  (a wheel joint's mass-matrix diagonal never contains the vehicle, which acts through the
  contacts; a real drive's fixed default gains assume a vehicle too). For a wheel in the air
  use a profile with ``load_inertia=0``;
  Vl Ki 0x203D/0x206D is the integral corner in 0.1 rad/s (default 100 -> 10 rad/s); Vl Kf
  0x203E/0x206E is the acceleration feed-forward in 0.1 % of J x a (default 500 -> 50 %). Pl Kp
  0x203F/0x206F is the position gain in 0.1 /s (default 100 -> 10 /s); Pl Kf 0x2040/0x2070 is the
  velocity feed-forward in % (default 50 -> 50 %). The current loop (Cl Kp/Ki), the smoothing
  factors, the velocity observer and the position-mode initial velocity are not modelled (ideal
  current loop: the motor current is the current command). The velocity-mode initial velocity
  0x2043/0x2073 (default 1 r/min) is only the standstill threshold: when a ramp starts from the
  measured speed (enable, mode change), a speed below it counts as 0.
* Current limits: peak = min(maximum current 0x2034/0x2064, rated current 0x2033/0x2063 x
  overload factor 0x2032/0x2062 / 100) (factor 0 = no factor limit); in the motoring direction
  also the back-EMF limit (bus voltage - ke x speed) / phase resistance, so the wheel cannot
  exceed the motor's no-load speed at the bus voltage.
* Faults (any fault switches BOTH motors off - one state machine - and sets the bit in the
  faulty channel's error code):
  - OVER_LOAD 0x0008: current above the rated current 0x2033 continuously for longer than the
    overload protection time 0x2035 (x 10 ms; 0 = no overload protection).
  - POSITION_FOLLOWING_ERROR 0x0020 (position modes): |position command - position| above the
    threshold 0x2036/0x2066 x 10 counts.
  - VELOCITY_FOLLOWING_ERROR 0x0040 (velocity mode and quick stop): the integral of the speed
    error (the position lag behind the speed command) above the same threshold 0x2036 x 10
    counts (a blocked wheel at 100 r/min trips after ~0.6 s). There is no other threshold
    register for it.
  - MOTOR_OVER_TEMPERATURE 0x0400: first-order winding model, +60 K at the motor's own rated
    current (:attr:`HubMotorProfile.motor_rated_current`), time constant 600 s, above the
    threshold 0x2046/0x2076 (0.1 degC).
  Other bits (voltage, hall, EEPROM ...) are never raised: the supply is ideal.
* Start commands: 0x10 starts both wheels only in synchronous mode, 0x11/0x12 start one wheel
  only in asynchronous mode; a start in the other coupling, outside the position modes or while
  the drive is not enabled is acknowledged (echo) and does nothing (recorded in
  :attr:`ZlacFirmware.ignored`). "Synchronous" starts both moves in the same substep; each wheel
  uses its own target, speed and ramp times.
* Enabling (0x08) in velocity mode ramps from the present speed to the target velocity registers
  as they stand (write 0 first if the wheels must stay still); in torque mode the current ramps
  from 0 to the target torque. Enable while enabled changes nothing; enable while faulted is
  ignored.
* Unprinted power-on values: 0x2011 = 6 (quick stop with the quick-stop deceleration time, whose
  registers 0x2084/0x2085 exist for it), 0x2012 = 1 (stop), 0x2014 = 1 (the table's range is
  1-3), 0x20A1 = the profile's bus voltage, 0x20A0 software version = 0.
* 0x20AF "software connected status" (line 1368, value meaning illegible): 0 at power-on, 1 once
  a frame was received, 0 again after an offline trip until the next enable command.
* 0x20A2 motor state: 1 while the channel's power stage is on (enabled or quick stop).
* 0x2005 accepts only 1 (the table); if it is ever widened, 2 = right and 3 = both, as 0x2006 and
  as community drivers use it.
* The stored settings (0x2010) are every RW register except commands (0x200E, 0x2005, 0x2006,
  0x2009, 0x2010) and the set-points 0x2088-0x2091 (target speeds 0x208E/0x208F are kept).
  0x2009 = 1 restores the power-on values in the image and forgets the stored settings.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

from joints.devices.quirks import firmware_profile
from joints.devices.registers import Access
from joints.devices.zlac.profile import HubMotorProfile
from joints.devices.zlac.registers import (
    ZLAC8015D,
    ControlMode,
    ControlWord,
    Fault,
    QuickStopBehaviour,
    is_synchronous,
)
from joints.devices.zlac.state import ENERGISED, DriveState, Event, command
from joints.devices.zlac.state import step as transition
from joints.errors import ParameterRefused, Refusal
from joints.sim import zlac_kernel as Z
from joints.sim.firmware import Firmware
from joints.sim.sensors import Sensor, model_of

__all__ = [
    "ABSOLUTE_TARGET_LIMIT",
    "DriveState",
    "ZlacChannel",
    "ZlacFirmware",
    "power_on_defaults",
]

TWO_PI = 2.0 * math.pi
RPM = TWO_PI / 60.0  #: rad/s per r/min
MIN_RAMP_TIME = 1e-3  #: s; a ramp time of 0 ms is taken as 1 ms
ABSOLUTE_TARGET_LIMIT = 0x3FFFFFFF  #: absolute-mode target position range (lines 432, 439)

THERMAL_RISE = Z.THERMAL_RISE
THERMAL_TAU = Z.THERMAL_TAU

#: 120-degree hall code of each 60-degree electrical sector.
_HALL_SEQUENCE = (1, 3, 2, 6, 4, 5)

#: Parameters that are commands or set-points, never stored by 0x2010.
_NOT_STORED = frozenset({
    "control_word",
    "clear_feedback_position",
    "in_absolute_position_control_reset_the_zero_point",
    "register_parameter_settings",
    "whether_store_rw_register_to_eeprom",
    "target_velocity_left",
    "target_velocity_right",
    "target_position_left",
    "target_position_right",
    "target_torque_left",
    "target_torque_right",
})
_SETTINGS = tuple(r.name for r in ZLAC8015D if r.access is Access.RW and r.name not in _NOT_STORED)
#: writes that act (or read loop constants) rather than only store a setting: loop settings written
#: before them in the same block are turned into loop constants first
_ACTING = frozenset({
    "control_word", "control_mode", "target_velocity_left", "target_velocity_right", "target_position_left",
    "target_position_right", "target_torque_left", "target_torque_right", "clear_feedback_position",
    "in_absolute_position_control_reset_the_zero_point", "whether_store_rw_register_to_eeprom",
    "register_parameter_settings", "maximum_motor_speed",
})
#: the ramp-time settings: a block of only these and the target velocities refreshes just the ramp columns
#: (:meth:`ZlacFirmware.write_many`)
_RAMPS = frozenset(f"{stem}_{side}" for stem in ("acceleration_time", "deceleration_time") for side in ("left", "right"))
#: target velocity register -> channel index (0 left, 1 right)
_TARGET_VELOCITY = {"target_velocity_left": 0, "target_velocity_right": 1}
_LIGHT = _RAMPS | frozenset(_TARGET_VELOCITY)
#: the status block a host reads in one FC03 (0x20A2 .. 0x20AF), served by :meth:`ZlacFirmware.reader` in one call
_STATUS = ("motor_state", "hall_state", "motor_temperature", "error_code_left", "error_code_right",
           "actual_motor_position_left", "actual_motor_position_right", "actual_velocity_left",
           "actual_velocity_right", "actual_torque_left", "actual_torque_right", "software_connected_status")
_ENERGISED_CODES = frozenset(float(Z.STATES.index(s)) for s in ENERGISED)


def power_on_defaults(profile: HubMotorProfile, address: int) -> dict[str, int]:
    """Parameter values after power-on of a factory-fresh drive with this motor on both channels."""
    rated = min(150, round(profile.rated_current * 10))
    peak = min(300, round(profile.max_current * 10))
    values: dict[str, int] = {
        "rs485_node_id": address,
        "maximum_motor_speed": max(1, min(1000, round(profile.max_speed_rpm))),
        "quick_stop_control": int(QuickStopBehaviour.QUICK_STOP_WITH_DECELERATION),
        "stop_control": 1,
        "halt_control": 1,
        "dc_voltage": round(profile.bus_voltage * 100),
    }
    for side in ("left", "right"):
        values[f"encoder_line_{side}"] = profile.encoder_lines
        values[f"poles_of_motor_{side}"] = max(4, min(64, profile.pole_pairs))
        values[f"rated_current_{side}"] = rated
        values[f"maximum_current_{side}"] = peak
    return values


def _ramp_seconds(ms: int) -> float:
    return max(ms * 1e-3, MIN_RAMP_TIME)


class ZlacChannel(Z.ChannelColumns):
    """One motor channel of the drive: its loops, motor model and protections.

    Its working state is row ``first + 1 + side`` of the drive's table (the loops are
    :func:`joints.sim.zlac_kernel.step`); the attributes below are columns of that row.
    """

    def __init__(self, drive: ZlacFirmware, side: str, inertia: float) -> None:
        if inertia <= 0 or not math.isfinite(inertia):
            raise ValueError(f"{side} channel: inertia must be positive and finite, got {inertia!r}")
        self.drive = drive
        self.side = side
        self.index = 0 if side == "left" else 1  #: 0 left, 1 right
        self.reg = {key: f"{key}_{side}" for key in (
            "encoder_line", "hall_offset_angle", "overload_factor", "rated_current", "maximum_current",
            "overload_protection_time", "position_following_error_threshold", "vl_kp", "vl_ki", "vl_kf",
            "pl_kp", "pl_kf", "poles_of_motor", "over_temperature_threshold", "acceleration_time",
            "deceleration_time", "deceleration_time_of_quick_stop", "torque_rate", "target_velocity",
            "target_position", "target_speed", "target_torque", "error_code", "actual_motor_position",
            "actual_velocity", "actual_torque", "initial_velocity_velocity_mode",
        )}
        self._bind(drive._table, drive._first)
        self.inertia = float(inertia)  #: J [kg*m^2] the velocity-loop gains are scaled with (tuned for)
        self.kt = drive.profile.torque_constant
        #: the channel's sensors (joints.sim.sensors): what a read of position, velocity and current reports
        self.sensor = Sensor(model_of(drive.profile), f"zlac:{drive.values['rs485_node_id']}:{side}",
                             4 * drive.profile.encoder_lines / TWO_PI)
        self.temperature = drive.ambient
        self.v_start = RPM  #: initial velocity [rad/s] (cached from 0x2043/0x2073)
        self.reset_power()

    def _bind(self, table: Any, first: int) -> None:
        self._row: Any = table[first + 1 + self.index]
        plain = isinstance(self._row, list)
        self._get: Callable[[int], float] = self._row.__getitem__ if plain else self._row.item
        #: the row's values as Python floats (the list itself, or a numpy row's ``tolist``)
        self._values: Callable[[], list[float]] = (lambda: table[first + 1 + self.index]) if plain else self._row.tolist

    # the row's columns are attributes of the channel: declared once, in :class:`joints.sim.zlac_kernel.ChannelColumns`

    # -- state ----------------------------------------------------------------------------
    def reset_power(self) -> None:
        """Power-on state (the physical angle is latched at the next step)."""
        s = self._row
        s[Z.FRESH] = 1.0
        s[Z.Q] = 0.0
        s[Z.QD] = 0.0
        s[Z.ORIGIN] = 0.0
        s[Z.FAULT_BITS] = 0.0
        s[Z.OVERLOAD_TIME] = 0.0
        s[Z.I_OUT] = 0.0
        # the winding starts at ambient (as the eRob firmware's power cycle): a World.reset must
        # not carry heat from one episode into the next
        s[Z.TEMPERATURE] = self.drive.ambient
        self.reset_loops()

    def reset_loops(self) -> None:
        """Loops and generators to rest at the present state (enable, mode change, power off)."""
        self.drive._k.reset_loops(self._row)

    # -- settings cache --------------------------------------------------------------------
    def cache(self) -> None:
        v = self.drive.values
        r = self.reg
        s = self._row
        cpr = 4 * max(v[r["encoder_line"]], 1)
        counts_per_rad = cpr / TWO_PI
        s[Z.CPR] = float(cpr)
        s[Z.COUNTS_PER_RAD] = counts_per_rad
        s[Z.ARRIVAL_WINDOW] = 0.5 / counts_per_rad  #: half a count [rad]
        s[Z.ACC_TIME] = _ramp_seconds(v[r["acceleration_time"]])
        s[Z.DEC_TIME] = _ramp_seconds(v[r["deceleration_time"]])
        s[Z.QS_TIME] = _ramp_seconds(v[r["deceleration_time_of_quick_stop"]])
        s[Z.TORQUE_RATE] = v[r["torque_rate"]] * 1e-3  # A/s
        rated = v[r["rated_current"]] * 0.1
        s[Z.RATED] = rated
        i_max = v[r["maximum_current"]] * 0.1
        factor = v[r["overload_factor"]]
        s[Z.PEAK] = min(i_max, rated * factor / 100.0) if factor else i_max
        s[Z.OVERLOAD_LIMIT] = v[r["overload_protection_time"]] * 0.01
        s[Z.FOLLOW_LIMIT] = v[r["position_following_error_threshold"]] * 10 / counts_per_rad
        s[Z.WV] = v[r["vl_kp"]] * 0.1
        s[Z.WI] = v[r["vl_ki"]] * 0.1
        s[Z.KFV] = v[r["vl_kf"]] * 1e-3
        s[Z.KPP] = v[r["pl_kp"]] * 0.1
        s[Z.KFP] = v[r["pl_kf"]] * 1e-2
        s[Z.POLES] = float(v[r["poles_of_motor"]])
        s[Z.HALL_OFFSET] = math.radians(v[r["hall_offset_angle"]])
        s[Z.TEMP_LIMIT] = v[r["over_temperature_threshold"]] * 0.1
        s[Z.TARGET_SPEED] = v[r["target_speed"]] * RPM
        s[Z.V_START] = v[r["initial_velocity_velocity_mode"]] * RPM
        s[Z.TARGET_TORQUE] = float(v[r["target_torque"]])

    # -- conversions (each also from the row's values as a list, ``r``: one read of the row per status read) --
    def counts(self) -> int:
        """Actual position value [counts] (as the channel's sensor reports it)."""
        return self._counts(self._values(), self.drive.time)

    def _counts(self, r: Sequence[float], t: float) -> int:
        q = r[Z.Q]
        sensor = self.sensor
        if not sensor.ideal:
            q = sensor.position(t, q, r[Z.QD])
        return round((q - r[Z.ORIGIN]) * r[Z.COUNTS_PER_RAD])

    def _sensed(self, r: Sequence[float], t: float) -> tuple[int, int, int]:
        """``(_counts(r, t), _velocity_status(r), _current_status(r))``: one call of the sensor (the same draws in
        the same order, :meth:`~joints.sim.sensors.Sensor.sense`)."""
        q, v, i = r[Z.Q], r[Z.QD], r[Z.I_OUT]
        sensor = self.sensor
        if not sensor.ideal:
            q, v, i = sensor.sense(t, q, v, i)
        return round((q - r[Z.ORIGIN]) * r[Z.COUNTS_PER_RAD]), round(v / RPM * 10), round(i * 10)

    def rpm(self) -> float:
        return float(self._get(Z.QD)) / RPM

    def velocity_status(self) -> int:
        """Actual velocity value [0.1 r/min]: the drive's estimate."""
        return self._velocity_status(self._values())

    def _velocity_status(self, r: Sequence[float]) -> int:
        v = r[Z.QD]
        sensor = self.sensor
        if not sensor.ideal:
            v = sensor.velocity(r[Z.Q], v)
        return round(v / RPM * 10)

    def current_status(self) -> int:
        """Actual torque (current) value [0.1 A], as the drive measures it."""
        return self._current_status(self._values())

    def _current_status(self, r: Sequence[float]) -> int:
        i = r[Z.I_OUT]
        sensor = self.sensor
        if not sensor.ideal:
            i = sensor.current(i)
        return round(i * 10)

    def error_status(self) -> int:
        """Error code value (:class:`~joints.devices.zlac.registers.Fault` bits)."""
        return int(self._get(Z.FAULT_BITS))

    # -- commands (from the drive) ---------------------------------------------------------
    def set_velocity_target(self, rpm: int) -> None:
        """Velocity-mode target changed: start the ramp to it (see the module docstring;
        :func:`joints.sim.zlac_kernel.set_velocity_target`)."""
        self.drive._k.set_velocity_target(self.drive._drow, self._row, float(rpm))

    def start_move(self, absolute: bool) -> bool:
        """Position-mode start: latch target, speed and ramps; False if the target is refused."""
        value = self.drive.values[self.reg["target_position"]]
        if absolute:
            if abs(value) > ABSOLUTE_TARGET_LIMIT:
                return False
            self.goal = self.origin + value / self.counts_per_rad
        else:
            self.goal = self.goal + value / self.counts_per_rad
        self.cruise = min(self.target_speed, self.drive.vmax)
        ref = self.drive.ramp_reference
        base = ref if ref is not None else self.cruise
        self.p_acc = base / self.acc_time
        self.p_dec = base / self.dec_time
        self.moving = True
        return True

    def begin_quick_stop(self, option: int, was_running: bool) -> None:
        """Enter quick stop: ramp the speed command to 0 per 0x2011."""
        self.drive._k.begin_quick_stop(self.drive._drow, self._row, float(option), was_running)

    def clear_position(self) -> None:
        """0x2005 / 0x2006: the present position reads 0 and is the zero of absolute targets."""
        self._row[Z.ORIGIN] = self._row[Z.Q]

    def place(self, q: float) -> None:
        """The wheel is at ``q`` [rad] and at rest (start state, reset): the encoder sees it, the
        loops rest there. Right after power-on the position counter reads 0 there; later the
        counter follows the move (an incremental encoder counts a wheel turned by hand)."""
        if self.fresh:
            self.origin = q
        self.q = q
        self.qd = 0.0
        self.reset_loops()

    # -- physics side ----------------------------------------------------------------------
    def step(self, t: float, dt: float, q: float, qd: float) -> float:
        """Run this channel's loops for the substep ending at ``t`` (length ``dt``) with the wheel
        at ``q`` [rad], ``qd`` [rad/s]; return the motor torque at the wheel [N*m]
        (:func:`joints.sim.zlac_kernel.step`; a world steps all rows at once)."""
        drive = self.drive
        return float(drive._k.step(drive._table, drive._first, self.index, t, dt, q, qd))

    def hall(self) -> int:
        return self._hall(self._values())

    @staticmethod
    def _hall(r: Sequence[float]) -> int:
        angle = (r[Z.Q] * int(r[Z.POLES]) + r[Z.HALL_OFFSET]) % TWO_PI
        return _HALL_SEQUENCE[min(5, int(angle / (TWO_PI / 6)))]

    @property
    def energised(self) -> bool:
        return self.drive.state in ENERGISED


class ZlacFirmware(Firmware, Z.DriveColumns):
    """One ZLAC8015D's firmware: two hub motors, ``left`` and ``right``, one state machine.

    ``address`` is the power-on value of ``rs485_node_id``.
    """

    def __init__(
        self,
        profile: HubMotorProfile,
        address: int = 1,
        *,
        inertia_left: float | None = None,
        inertia_right: float | None = None,
        ambient: float = 25.0,
        ramp_reference_rpm: float | None = None,
        quirks: frozenset[str] | None = None,
    ) -> None:
        super().__init__(ZLAC8015D.params, values=power_on_defaults(profile, address))
        self._batch = 0  #: inside write_many: 1, 2 for a block of only ramp times and target velocities
        self._stale = False  #: settings written whose loop constants are not computed yet
        self._stale_ramps = False  #: (a block of ramps and targets) ramp times written, their columns not yet
        #: the status block's fast reader and the same on rows (:meth:`reader`), or None
        self.status_reader: tuple[Callable[[], list[int]], Callable[..., list[int]]] | None = None
        #: the firmware's quirks (joints.devices.quirks); default: the family's default firmware
        self.quirks = quirks if quirks is not None else firmware_profile("zlac8015d").quirks
        self.profile = profile
        self._bind_rows([[0.0] * Z.WIDTH for _ in range(3)], 0)
        self.ambient = float(ambient)
        self.ramp_reference = ramp_reference_rpm * RPM if ramp_reference_rpm else None
        d = self._drow
        d[Z.D_BACK_EMF] = float(profile.back_emf_constant)
        d[Z.D_BUS_VOLTAGE] = float(profile.bus_voltage)
        d[Z.D_PHASE_R] = float(profile.phase_resistance)
        d[Z.D_MOTOR_RATED] = float(profile.motor_rated_current)
        self.time = 0.0
        #: (time, text) of commands that were acknowledged but did nothing
        self.ignored: list[tuple[float, str]] = []
        own = profile.armature
        load = profile.load_inertia
        self.left = ZlacChannel(self, "left", (inertia_left if inertia_left is not None else own) + load)
        self.right = ZlacChannel(self, "right", (inertia_right if inertia_right is not None else own) + load)
        self.channels = (self.left, self.right)
        self.sensors = (self.left.sensor, self.right.sensor)
        for ch in self.channels:
            r = ch.reg
            self.computed[r["actual_motor_position"]] = ch.counts
            self.computed[r["actual_velocity"]] = ch.velocity_status
            self.computed[r["actual_torque"]] = ch.current_status
            self.computed[r["error_code"]] = ch.error_status
        left, right = self.left, self.right
        self.computed["motor_state"] = lambda: _pack(int(left.energised), int(right.energised))
        self.computed["hall_state"] = lambda: _pack(left.hall(), right.hall())
        self.computed["motor_temperature"] = lambda: _pack(round(left.temperature), round(right.temperature))
        self.computed["software_connected_status"] = lambda: int(self._dget(Z.D_CONNECTED))
        #: what the status block's parameters are computed by (the one-call reader serves them while they are)
        self._status_fns = tuple(self.computed[n] for n in _STATUS)
        self._power_on()

    # -- the rows ----------------------------------------------------------------------------------
    #: the kernel rows this twin steps (see :mod:`joints.sim.stepping`): drive, left, right
    KERNEL = Z.KIND

    def _bind_rows(self, table: Any, first: int) -> None:
        self._table: Any = table
        self._first = first
        self._drow: Any = table[first]
        self._row = self._drow  #: the drive's row, as its column attributes read it (``_get`` too)
        if isinstance(self._drow, list):
            self._dget: Callable[[int], float] = self._drow.__getitem__
            self._k: Any = Z.PY_OPS
        else:  # numpy rows: Python floats out, the helpers compiled
            self._dget = self._drow.item
            self._k = Z.compiled_ops()
        self._get = self._dget
        for ch in getattr(self, "channels", ()):
            ch._bind(table, first)

    def velocity_exchange(self, lane: Any, slave: int) -> Any:
        """The one-call exchange of a host's steady velocity command to this twin at ``slave`` over ``lane`` (the
        host link's direct lane): :class:`joints.sim.zlac_exchange.ZlacExchange` (it checks at every call that
        the twin, its bus and world are as it assumes, else the lane sends the requests its usual way)."""
        from joints.sim.zlac_exchange import ZlacExchange

        return ZlacExchange(lane, slave)

    def kernel_rows(self) -> list[list[float]]:
        """The twin's rows as they stand: the drive, the left channel, the right channel."""
        return [[float(x) for x in self._table[self._first + k]] for k in range(3)]

    def adopt(self, table: Any, first: int) -> None:
        """Run on rows ``first`` .. ``first + 2`` of ``table`` from now on (their state copied there)."""
        for k, values in enumerate(self.kernel_rows()):
            row = table[first + k]
            for i, x in enumerate(values):
                row[i] = x
        self._bind_rows(table, first)

    def kernel_row(self, channel: str | None) -> int:
        """Which of the twin's rows steps ``channel``'s joint."""
        return 1 + self.channel(channel or "left").index

    # the drive row's columns are attributes of the drive: declared once, in
    # :class:`joints.sim.zlac_kernel.DriveColumns`

    # -- power -------------------------------------------------------------------------------
    def _power_on(self) -> None:
        self.state = DriveState.DISABLED
        self.last_frame = -1.0
        self.offline = False
        d = self._drow
        d[Z.D_TICKED] = -math.inf
        d[Z.D_CONNECTED] = 0.0
        self._cache()
        for ch in self.channels:
            ch.reset_power()
        if self.values["driver_state"] == 1:  # saved "enabled at power-on"
            self._enable()

    def power_cycle(self) -> None:
        """Simulated power off/on: stored settings survive, everything else is power-on default.

        The incremental position counters restart at 0 at the wheels' present angle; a new
        ``rs485_node_id`` takes effect now.
        """
        for sensor in self.sensors:  # the sensors' noise restarts with the drive: a world reset is reproducible
            sensor.reseed()
        super().power_cycle()
        self.ignored.clear()
        self._power_on()

    def gain_params(self, channel: str | None) -> dict[str, str]:
        """A channel's loop-gain parameters (for domain randomisation: joints.sim.world.World.perturb)."""
        side = channel or "left"
        return {"position": f"pl_kp_{side}", "speed": f"vl_kp_{side}", "integral": f"vl_ki_{side}"}

    def channel(self, name: str) -> ZlacChannel:
        """The ``"left"`` or ``"right"`` channel."""
        if name == "left":
            return self.left
        if name == "right":
            return self.right
        raise KeyError(f"ZLAC8015D channel must be 'left' or 'right', got {name!r}")

    # -- settings cache ----------------------------------------------------------------------
    def _cache(self) -> None:
        self._stale = False
        self._stale_ramps = False
        v = self.values
        d = self._drow
        d[Z.D_VMAX] = max(v["maximum_motor_speed"], 1) * RPM
        d[Z.D_WATCHDOG] = v["communication_offline_time"] * 1e-3
        d[Z.D_MODE] = float(v["control_mode"])
        d[Z.D_SYNC] = float(v["synchronous_asynchronous_control_status"])
        option = v["quick_stop_control"]
        default = int(QuickStopBehaviour.QUICK_STOP_WITH_DECELERATION)
        d[Z.D_QS_OPTION] = float(option if option in (5, 6, 7) else default)
        for ch in getattr(self, "channels", ()):
            ch.cache()

    def _cache_ramps(self) -> None:
        """The ramp-time columns of both channels from the values (what :meth:`_cache` computes for them)."""
        self._stale_ramps = False
        v = self.values
        for ch in self.channels:
            r, s = ch.reg, ch._row
            s[Z.ACC_TIME] = _ramp_seconds(v[r["acceleration_time"]])
            s[Z.DEC_TIME] = _ramp_seconds(v[r["deceleration_time"]])

    # -- what the fronts call ------------------------------------------------------------------
    def reader(self, names: Sequence[str]) -> Callable[[], list[int]]:
        """As :meth:`Firmware.reader`; the status block (0x20A2 .. 0x20AF), while its parameters are
        computed as this class computes them, in one call (:meth:`_read_status`: the same values, in the
        same order)."""
        generic = super().reader(names)
        if (tuple(names) != _STATUS or type(self).on_read is not Firmware.on_read
                or any(self.computed.get(n) is not f for n, f in zip(_STATUS, self._status_fns))):
            return generic
        los = tuple(self._type_range[n][0] for n in _STATUS)
        his = tuple(self._type_range[n][1] for n in _STATUS)
        status, status_of = self._read_status, self._status_of

        def read() -> list[int]:  # saturate, never wrap (as the generic reader)
            return [lo if v < lo else hi if v > hi else v for v, lo, hi in zip(status(), los, his)]  # noqa: FURB136

        def read_rows(d: Sequence[float], lv: Sequence[float], rv: Sequence[float]) -> list[int]:
            """``read()`` of the drive's rows ``d``, ``lv``, ``rv`` as they stood when the drive acted on the frame
            (:mod:`joints.sim.zlac_exchange`'s compiled status read: the same values, the same draws)."""
            values = status_of(d[Z.D_TIME], d[Z.D_STATE], d[Z.D_CONNECTED], lv, rv)
            return [lo if v < lo else hi if v > hi else v for v, lo, hi in zip(values, los, his)]  # noqa: FURB136

        #: the status block's fast reader and its twin on rows taken in a compiled call (where both are this class's)
        stock = type(self)._read_status is ZlacFirmware._read_status and type(self)._status_of is \
            ZlacFirmware._status_of and "_read_status" not in vars(self) and "_status_of" not in vars(self)
        self.status_reader = (read, read_rows) if stock else None
        return read

    def _read_status(self) -> list[int]:
        """The status block's values (:data:`_STATUS` order), each as its ``computed`` function gives it (the same
        channel conversions, each channel's row read once; every sensor draws in the order its own reads would:
        each channel's sensor is its own stream, so one call per channel gives the same bits)."""
        d = self._dget
        return self._status_of(float(d(Z.D_TIME)), d(Z.D_STATE), d(Z.D_CONNECTED), self.left._values(),
                               self.right._values())

    def _status_of(self, t: float, state: float, connected: float, lv: Sequence[float], rv: Sequence[float]
                   ) -> list[int]:
        """:meth:`_read_status` of the drive row's time, state and connection and the channels' rows ``lv``,
        ``rv``."""
        left, right = self.left, self.right
        e = 1 if state in _ENERGISED_CODES else 0
        l_counts, l_velocity, l_current = left._sensed(lv, t)
        r_counts, r_velocity, r_current = right._sensed(rv, t)
        return [
            _pack(e, e),
            _pack(left._hall(lv), right._hall(rv)),
            _pack(round(lv[Z.TEMPERATURE]), round(rv[Z.TEMPERATURE])),
            int(lv[Z.FAULT_BITS]),
            int(rv[Z.FAULT_BITS]),
            l_counts,
            r_counts,
            l_velocity,
            r_velocity,
            l_current,
            r_current,
            int(connected),
        ]

    def frame_received(self) -> None:
        Z.PY_OPS.frame(self._drow)  # :func:`joints.sim.zlac_kernel.frame` (as Python: two row writes)

    def check_write(self, name: str, value: int) -> None:
        if (name == "target_position_left" or name == "target_position_right") and (
                self.mode == ControlMode.ABSOLUTE_POSITION and abs(value) > ABSOLUTE_TARGET_LIMIT):
            raise ParameterRefused(Refusal.OUT_OF_RANGE, name, f"absolute target {value} outside +-0x3FFFFFFF")

    def write_many(self, items: Sequence[tuple[str, int]]) -> None:
        """As :meth:`Firmware.write_many`; loop settings written in one block are turned into loop
        constants once, before anything that uses them (a later command of the block, a substep). A block of
        only ramp times and target velocities (a host's velocity command) refreshes only the ramp-time
        columns, all that it can change (:meth:`_cache_ramps`), in one pass (:meth:`_write_light`)."""
        if self._write_light(items):
            return
        self._batch = 2
        for name, _ in items:
            if name not in _LIGHT:
                self._batch = 1
                break
        try:
            super().write_many(items)
        finally:
            self._batch = 0
            if self._stale:
                self._cache()
            elif self._stale_ramps:
                self._cache_ramps()

    def _write_light(self, items: Sequence[tuple[str, int]]) -> bool:
        """:meth:`write_many` of a light block (only ramp times and target velocities: a host's velocity command)
        where nothing else can happen: every value an int the firmware accepts, nothing pending or stale, this
        class's own hooks. The same validation, store, log and effects in order as the general way (the ramp
        columns refreshed before a target that follows them, :meth:`ZlacChannel.set_velocity_target` for each
        target while enabled in velocity mode); False (nothing done) where that is not the case."""
        if type(self) is not ZlacFirmware or self.pending or self._stale or self._stale_ramps or self.DELAYED:
            return False
        limits = self._limits
        checked: list[tuple[str, int]] = []
        for name, value in items:
            if name not in _LIGHT or type(value) is not int:
                return False
            writable, lo, hi = limits[name]
            if not (writable and lo <= value <= hi):
                return False  # the general way refuses it
            checked.append((name, value))
        self._keep(checked)
        d = self._dget
        running = d(Z.D_STATE) == Z.ENABLED and d(Z.D_MODE) == Z.VELOCITY
        stale = False
        for name, value in checked:
            side = _TARGET_VELOCITY.get(name)
            if side is None:  # a ramp time: its column before the next target, or at the end
                stale = True
                continue
            if stale:
                self._cache_ramps()
                stale = False
            if running:
                self.channels[side].set_velocity_target(value)
        if stale:
            self._cache_ramps()
        return True

    def on_write(self, name: str, value: int) -> None:
        if name in _ACTING:  # settings written earlier in this block: in force first
            if self._stale:
                self._cache()
            elif self._stale_ramps:  # only ramp times (a light block): all that _cache would change
                self._cache_ramps()
        side = _TARGET_VELOCITY.get(name)
        if side is not None:
            d = self._dget
            if d(Z.D_STATE) == Z.ENABLED and d(Z.D_MODE) == Z.VELOCITY:  # enabled, velocity mode
                self.channels[side].set_velocity_target(value)
            return
        if self._batch == 2 and name in _RAMPS:  # a light block: only the ramp columns are stale
            self._stale_ramps = True
            return
        if name == "control_word":
            self._command(value)
            return
        if name == "control_mode":
            self._cache()
            self._mode_changed()
            return
        if name in ("target_torque_left", "target_torque_right"):
            (self.left if name.endswith("left") else self.right)._row[Z.TARGET_TORQUE] = float(value)
            return
        if name in ("target_position_left", "target_position_right"):
            return
        v = self.values
        if name == "clear_feedback_position":
            if value:
                for ch in self._sides(value, both_for_one=True):
                    ch.clear_position()
                v[name] = 0
            return
        if name == "in_absolute_position_control_reset_the_zero_point":
            if value:
                for ch in self._sides(value, both_for_one=False):
                    ch.clear_position()
                v[name] = 0
            return
        if name == "whether_store_rw_register_to_eeprom":
            if value == 1:
                self.save(_SETTINGS)
            v[name] = 0
            return
        if name == "register_parameter_settings":
            if value == 1:
                for n in _SETTINGS:
                    v[n] = self.defaults[n]
                self.saved = {}
                self._cache()
                self._mode_changed()
            v[name] = 0
            return
        if name == "maximum_motor_speed":
            self._cache()
            if self.state is DriveState.ENABLED and self.mode == ControlMode.VELOCITY:
                for ch in self.channels:  # a lower cap clamps the present targets
                    ch.set_velocity_target(v[ch.reg["target_velocity"]])
            return
        if self._batch:
            self._stale = True
        else:
            self._cache()

    def _sides(self, value: int, *, both_for_one: bool) -> tuple[ZlacChannel, ...]:
        if value == 1:
            return self.channels if both_for_one else (self.left,)
        if value == 2:
            return (self.right,)
        if value == 3:
            return self.channels
        return ()

    def _ignore(self, text: str) -> None:
        self.ignored.append((self.time, text))

    # -- the control word (state machine of joints.devices.zlac.state) ---------------------------
    def _command(self, value: int) -> None:
        word = command(value)
        if word is None:
            self._ignore(f"control word 0x{value:02X} is not a command")
            return
        state = self.state
        new = transition(state, word)
        if new is None:
            if word is ControlWord.ENABLE:
                self._ignore("enable while faulted (clear faults first)")
            elif word is not ControlWord.STOP:  # stop while faulted: nothing to stop
                what = "quick stop" if word is ControlWord.QUICK_STOP else word.name
                self._ignore(f"{what} while {state.value}")
            return
        if word is ControlWord.ENABLE:
            self._enable()
        elif word is ControlWord.STOP:
            self.state = new
            for ch in self.channels:
                ch.reset_loops()
        elif word is ControlWord.QUICK_STOP:
            self._quick_stop()
        elif word is ControlWord.CLEAR_FAULT:
            for ch in self.channels:
                ch.fault = 0
                ch.overload_time = 0.0
            self.state = new
        else:
            self._start(word)

    def _enable(self) -> None:
        state = self.state
        new = transition(state, ControlWord.ENABLE)
        if new is None:
            self._ignore("enable while faulted (clear faults first)")
            return
        if state is DriveState.ENABLED:
            return
        self.state = new
        self.offline = False
        if self.last_frame >= 0.0:
            self._drow[Z.D_CONNECTED] = 1.0
        for ch in self.channels:
            ch.reset_loops()
            if self.mode == ControlMode.VELOCITY:
                ch.set_velocity_target(self.values[ch.reg["target_velocity"]])

    def _quick_stop(self) -> None:
        self._k.quick_stop(self._table, self._first)

    def _mode_changed(self) -> None:
        if self.state is not DriveState.ENABLED:
            return
        for ch in self.channels:
            ch.reset_loops()
            if self.mode == ControlMode.VELOCITY:
                ch.set_velocity_target(self.values[ch.reg["target_velocity"]])

    def _start(self, word: ControlWord) -> None:
        if self.mode not in (ControlMode.RELATIVE_POSITION, ControlMode.ABSOLUTE_POSITION):
            self._ignore(f"{word.name} outside the position modes (control mode {self.mode})")
            return
        sync = is_synchronous(self.sync, self.quirks)  # DOC-ZLAC-1: the meaning depends on the firmware
        if word is ControlWord.START_SYNC:
            if not sync:
                self._ignore(f"START_SYNC in asynchronous control (0x200F = {self.sync})")
                return
            targets: tuple[ZlacChannel, ...] = self.channels
        else:
            if sync:
                self._ignore(f"{word.name} in synchronous control (0x200F = {self.sync})")
                return
            targets = (self.left,) if word is ControlWord.START_LEFT else (self.right,)
        absolute = self.mode == ControlMode.ABSOLUTE_POSITION
        for ch in targets:
            if not ch.start_move(absolute):
                self._ignore(f"{word.name}: {ch.side} absolute target outside +-0x3FFFFFFF")

    def raise_fault(self, ch: ZlacChannel, bit: Fault) -> None:
        """A channel detected a fault: set its bit, switch both motors off."""
        ch.fault |= int(bit)
        self.state = transition(self.state, Event.FAULT) or DriveState.FAULT

    def set(self, name: str, value: int) -> None:
        super().set(name, value)
        self._cache()

    # -- physics side --------------------------------------------------------------------------
    def tick(self, t: float) -> None:
        """Drive-level work once per substep (the first channel step with a new ``t``)."""
        self._k.tick(self._table, self._first, t)

    def step_both(
        self, t: float, dt: float, q_left: float, qd_left: float, q_right: float, qd_right: float
    ) -> tuple[float, float]:
        """Both channels for one substep: ``(torque_left, torque_right)`` [N*m]."""
        return self.left.step(t, dt, q_left, qd_left), self.right.step(t, dt, q_right, qd_right)


def _pack(left: int, right: int) -> int:
    """Two status bytes in one word: high byte = left, low byte = right (each saturated to 0-255)."""
    return (max(0, min(255, left)) << 8) | max(0, min(255, right))
