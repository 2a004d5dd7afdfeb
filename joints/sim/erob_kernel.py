"""The eRob's per-substep loops over one row of floats: the one implementation its twin runs.

Rule: everything the drive does between two frames - communication watchdog, slow supervision
(settle timer, stall, thermal), the enable delay, the holding brake, the profile generator of
:mod:`joints.devices.motion`, the position / speed / torque loops, current limits and the
protections - is here, as functions of a row ``s`` (a sequence of floats indexed by the column
constants below), in the subset of Python that numba compiles (:mod:`joints.sim.kernel`). The
firmware object (:class:`joints.sim.erob.ErobFirmware`) keeps its parameters by name and acts on
commands in Python; its working state IS its row, and it calls these same functions for the
helpers it shares with the loops (motor off, faults, the settle timer ...). Integers (state
codes, fault codes, flags) are held as exact floats; "none" (the brake's hold angle) is NaN.

The conventions and choices are those of :mod:`joints.sim.erob`; the state machine is
:data:`joints.devices.erob.state.TRANSITIONS`, turned into a table of state codes here.
"""

from __future__ import annotations

import math
from collections.abc import MutableSequence
from types import SimpleNamespace
from typing import Any

from joints.devices.erob import faults
from joints.devices.erob.registers import COUNTS_PER_REV, AchieveStatus, MotionMode, OperationMode
from joints.devices.erob.state import ENABLE_DELAY, TRANSITIONS, DriveState, Event
from joints.devices.motion import Arrival, move_step, ramp
from joints.sim import kernel, rowattr
from joints.sim.kernel import jitable
from joints.sim.rowattr import Code, Flag, Int, Maybe, Real

Row = MutableSequence[float]

#: this kernel's kind: the code of its rows in :attr:`joints.sim.stepping.Group.adr` (a twin's ``KERNEL``)
KIND = 1

COUNTS_PER_RAD = COUNTS_PER_REV / (2.0 * math.pi)
SUPERVISION_PERIOD = 0.002  #: s between the drive's slow tasks (stall, thermal, settle timer)
ARRIVAL_WINDOW = 1.0  #: counts: a move closer than this at a speed one period can stop has arrived
ON_STEP = Arrival.ON_STEP

FOLLOWING_ERROR = 0x8611
SPEED_ERROR = 0x8400
STALL = 0x7121
POSITION_LIMIT = 0x8612
OVER_TEMPERATURE = 0x4310
RS485_TIMEOUT = float(faults.RS485_TIMEOUT)

# -- state codes and the state machine as a table -------------------------------------------------
STATES = tuple(DriveState)  #: code -> state
EVENTS = tuple(Event)
MOTOR_OFF = float(STATES.index(DriveState.MOTOR_OFF))
ENABLING = float(STATES.index(DriveState.ENABLING))
READY = float(STATES.index(DriveState.READY))
REFUSED_ON = float(STATES.index(DriveState.REFUSED_ON))
FAULT = float(STATES.index(DriveState.FAULT))
EV_PROTECTION = EVENTS.index(Event.PROTECTION)
EV_WATCHDOG = EVENTS.index(Event.WATCHDOG)
EV_MOTION = EVENTS.index(Event.MOTION)
START_WHILE_DISABLED = float(faults.START_WHILE_DISABLED)
#: NEXT[state code][event code] -> next state code, -1 where the event is refused / ignored
NEXT = tuple(tuple(STATES.index(TRANSITIONS[(s, e)]) if (s, e) in TRANSITIONS else -1 for e in EVENTS)
             for s in STATES)

TORQUE = float(OperationMode.TORQUE)
SPEED_MODE = float(OperationMode.SPEED)
POSITION = float(OperationMode.POSITION)
REPETITIVE = float(MotionMode.REPETITIVE)
CONTINUOUS = float(MotionMode.CONTINUOUS)
ABSOLUTE = float(MotionMode.ABSOLUTE)
A_MOTOR_OFF = int(AchieveStatus.MOTOR_OFF)
A_MOTOR_ON = int(AchieveStatus.MOTOR_ON)
A_OPERATION = int(AchieveStatus.OPERATION)
A_WAIT_TIME = int(AchieveStatus.WAIT_TIME)
A_TARGET_REACHED = int(AchieveStatus.TARGET_REACHED)

# -- columns ---------------------------------------------------------------------------------------
class Columns(rowattr.Columns):
    """The eRob's row (one per drive), declared once: the index constants below and the twin's attributes
    (:class:`joints.sim.erob.ErobFirmware` inherits this class) come from here. Counts are the encoder's
    (before the position offset); -1 in a "since"/"until"/"at" column means "not running"."""

    # working state
    time = Real("drive time [s]: the end of the last substep")
    pos = Real("encoder [count], before the offset")
    vel = Real("speed [count/s]")
    p_ref = Real("position reference of the profile generator [count]")
    v_ref = Real("speed reference of the profile generator / speed ramp [count/s]")
    v_cmd = Real("speed command of the position loop (reference + Kp * error), limited [count/s]")
    i_cmd = Real("current command [mA]")
    i_out = Real("output current [mA]")
    integ = Real("speed-loop integral of the speed error [count]")
    mode_speed_target = Real("speed mode's target speed, limited to vmax [count/s]")
    gen_active = Flag("the profile generator: a move is running", const="G_ACTIVE")
    gen_target = Real("the profile generator's target [count]", const="G_TARGET")
    gen_continuous = Flag("the profile generator runs at the profile speed with no target (continuous motion)",
                          const="G_CONTINUOUS")
    gen_stopping = Flag("the profile generator decelerates to a stop", const="G_STOPPING")
    gen_rate = Real("the profile generator's deceleration override (emergency stop) [count/s^2], 0 = none",
                    const="G_RATE")
    repeat_home = Real("repetitive motion: where it started, the leg back's end [count]")
    repeat_leg_to_target = Flag("repetitive motion: the present leg goes to the target (else back home)")
    repeat_stop = Flag("repetitive motion: stop at the end of the present leg (stop_repetitive_motion)")
    dwell_until = Real("repetitive motion: drive time the dwell between legs ends [s], -1 = none")
    in_window_since = Real("drive time the position entered the arrival window (position_reaches_set_precision) [s], -1 = outside")
    peak_since = Real("drive time the current went above the continuous current [s], -1 = below")
    stall_since = Real("drive time the stall condition (struck_current, struck_speed) began [s], -1 = none")
    temperature = Real("power stage [degC]")
    brake_hold = Maybe("where the brake holds [count]; None (NaN in the row): where the joint is when it engages")
    brake_released = Flag("released by command while the motor is off: nothing holds the joint")
    last_frame = Real("drive time of the last frame addressed to the drive [s], -1 = none (watchdog)")
    started = Flag("a start (start_operating) is in force: the settle timer and the repetitive legs run")
    streaming = Flag("a set-point stream drives the position reference (CiA 402 CSP/IP over CANopen, set by a "
                     "protocol front): between set-points the reference moves on at v_ref (linear interpolation)")
    stream_goal = Real("the newest streamed set-point [count]: the reference stops there, never past it")
    sup = Real("drive time since the last slow task (supervision) [s]")
    state = Code(STATES, "the drive state (held as its code in :data:`STATES`)")
    enabled_at = Real("drive time of the last enable [s], -1 = never (the brake's release delay)")
    fault = Int("the latched error code (0x0027 or a fault), 0 = none", const="FAULT_CODE")
    # loop settings (from the parameters, refreshed on every write of one of them)
    mode = Int("the operation mode in force (0x0040)")
    watchdog = Real("communication timeout [s], 0 = off (modbus_communication_timeout_duration)")
    max_position_error = Real("following-error limit [count], 0 = off")
    max_speed_error = Real("speed-error limit [count/s], 0 = off")
    offset = Int("the position offset in force [count] (position_offset)")
    kp = Real("position-loop gain [1/s] (position_loop_gain / 10)")
    kv = Real("speed-loop gain [mA per count/s], from speed_loop_gain and the tuned-for inertia")
    ki = Real("speed-loop integral gain [mA per count], kv / the integral time (speed_loop_integral)")
    kff = Real("acceleration feed-forward [mA per count/s^2], from the tuned-for inertia")
    i_cont = Real("continuous current [mA]")
    i_peak = Real("peak current [mA]")
    i_max = Real("the motor's maximum current [mA]")
    peak_time = Real("how long the peak current may last [s]")
    i_lim = Real("current limit: the smaller of peak and maximum current [mA]")
    brake_k = Real("holding brake stiffness [N*m/rad]")
    brake_c = Real("holding brake damping [N*m*s/rad]")
    brake_hold_torque = Real("torque above which the holding brake slips [N*m]")
    vmax = Real("maximum speed [count/s]")
    amax = Real("maximum acceleration [count/s^2]")
    acc = Real("profile acceleration [count/s^2] (the maximum where the parameter is 0)")
    dec = Real("profile deceleration [count/s^2] (the maximum where the parameter is 0)")
    speed = Real("profile speed, signed [count/s]")
    vprof = Real("profile speed magnitude, limited to vmax [count/s]")
    # constants of the drive
    kt = Real("torque constant at the output [N*m/A]")
    rated_current = Real("rated current [A] (the thermal model's scale)")
    ambient = Real("ambient temperature [degC]")
    # parameters the loops read (kept equal to the firmware's values, in the parameter's own unit)
    motion_mode = Real("motion mode (0x0041)", param=True)
    dwell_time = Real("repetitive motion's dwell [0.05 ms]", param=True)
    target_absolute_position = Real("absolute target [count]", param=True, const="TARGET_ABSOLUTE")
    min_position_limit_value = Real("lower position limit [count]", param=True, const="MIN_LIMIT")
    max_position_limit_value = Real("upper position limit [count]", param=True, const="MAX_LIMIT")
    struck_current = Real("stall detection: current above [mA]", param=True)
    struck_speed = Real("stall detection: speed below [count/s]", param=True)
    struck_time = Real("stall detection: for longer than [0.05 ms]", param=True)
    power_temperature_protection_value = Real("over-temperature limit [degC], 0 = off", param=True,
                                              const="TEMP_PROTECTION")
    target_current = Real("torque mode's target current [mA]", param=True)
    torque_control_mode_max_speed = Real("torque mode's speed limit [count/s]", param=True,
                                         const="TORQUE_MAX_SPEED")
    position_reaches_set_precision = Real("arrival window [count]", param=True, const="PRECISION")
    time_setting_of_achieving_position = Real("settle time in the window [0.05 ms]", param=True,
                                              const="SETTLE_TIME")


#: the columns' index constants, in the declared order (plain ints: numba compiles them in; checked at import)
(TIME, POS, VEL, P_REF, V_REF, V_CMD, I_CMD, I_OUT, INTEG, MODE_SPEED_TARGET, G_ACTIVE, G_TARGET, G_CONTINUOUS,
 G_STOPPING, G_RATE, REPEAT_HOME, REPEAT_LEG_TO_TARGET, REPEAT_STOP, DWELL_UNTIL, IN_WINDOW_SINCE, PEAK_SINCE,
 STALL_SINCE, TEMPERATURE, BRAKE_HOLD, BRAKE_RELEASED, LAST_FRAME, STARTED, STREAMING, STREAM_GOAL, SUP, STATE,
 ENABLED_AT, FAULT_CODE, MODE, WATCHDOG, MAX_POSITION_ERROR, MAX_SPEED_ERROR, OFFSET, KP, KV, KI, KFF, I_CONT, I_PEAK,
 I_MAX, PEAK_TIME, I_LIM, BRAKE_K, BRAKE_C, BRAKE_HOLD_TORQUE, VMAX, AMAX, ACC, DEC, SPEED, VPROF, KT, RATED_CURRENT,
 AMBIENT, MOTION_MODE, DWELL_TIME, TARGET_ABSOLUTE, MIN_LIMIT, MAX_LIMIT, STRUCK_CURRENT, STRUCK_SPEED, STRUCK_TIME,
 TEMP_PROTECTION, TARGET_CURRENT, TORQUE_MAX_SPEED, PRECISION, SETTLE_TIME) = rowattr.indices(Columns)
WIDTH = rowattr.bind(globals(), Columns)  #: columns of an eRob row
COLUMNS = rowattr.names(Columns)
#: the parameters the loops read: name -> its column (kept equal to the firmware's values by name)
PARAMS = rowattr.params(Columns)


# -- helpers shared with the firmware object --------------------------------------------------------
@jitable
def fmin(a: float, b: float) -> float:
    """``min(a, b)`` exactly as Python's builtin (the first unless the second is smaller)."""
    return b if b < a else a  # noqa: FURB136 - spelled out: the same in compiled code


@jitable
def fmax(a: float, b: float) -> float:
    """``max(a, b)`` exactly as Python's builtin."""
    return b if b > a else a  # noqa: FURB136 - spelled out: the same in compiled code


@jitable
def is_enabled(state: float) -> bool:
    """The state code is one of ENABLED (brake released or releasing)."""
    return state == ENABLING or state == READY or state == REFUSED_ON


@jitable
def gen_clear(s: Row) -> None:
    """The profile generator at rest (no move, no stop ramp)."""
    s[G_ACTIVE] = 0.0
    s[G_TARGET] = 0.0
    s[G_CONTINUOUS] = 0.0
    s[G_STOPPING] = 0.0
    s[G_RATE] = 0.0


@jitable
def motor_off(s: Row) -> None:
    """Disable / fault: the loops stop and the brake engages where the joint is."""
    gen_clear(s)
    s[V_REF] = 0.0
    s[STREAMING] = 0.0
    s[MODE_SPEED_TARGET] = 0.0
    s[I_CMD] = 0.0
    s[I_OUT] = 0.0
    s[INTEG] = 0.0
    s[STARTED] = 0.0
    s[BRAKE_HOLD] = s[POS]
    s[BRAKE_RELEASED] = 0.0


@jitable
def raise_fault(s: Row, code: float) -> None:
    """A protection tripped: FAULT with ``code``, unless an error is latched already."""
    new = NEXT[int(s[STATE])][EV_PROTECTION]
    if new < 0:
        return
    s[FAULT_CODE] = code
    s[STATE] = float(new)
    motor_off(s)


@jitable
def ready(s: Row) -> bool:
    """Motor on and brake released (the enable delay ends here if it has passed)."""
    state = s[STATE]
    if state == READY:
        return True
    if state == ENABLING and s[TIME] >= s[ENABLED_AT] + ENABLE_DELAY - 1e-9:
        s[STATE] = READY  # transition(ENABLING, BRAKE_RELEASED)
        return True
    return False


@jitable
def moving(s: Row) -> bool:
    if s[G_ACTIVE] != 0.0 or s[DWELL_UNTIL] >= 0:
        return True
    return is_enabled(s[STATE]) and abs(s[V_REF]) > 0.5


@jitable
def achieve(s: Row, is_moving: bool) -> int:
    """``status_of_achieving_position`` now; runs the settle timer."""
    if not ready(s):
        return A_MOTOR_OFF
    if s[MODE] != POSITION or s[STARTED] == 0.0:
        return A_OPERATION if is_moving else A_MOTOR_ON
    if is_moving:
        s[IN_WINDOW_SINCE] = -1.0
        return A_OPERATION
    if abs(s[G_TARGET] - s[POS]) <= s[PRECISION]:
        if s[IN_WINDOW_SINCE] < 0:
            s[IN_WINDOW_SINCE] = s[TIME]
        if s[TIME] - s[IN_WINDOW_SINCE] >= s[SETTLE_TIME] * 5e-5:
            return A_TARGET_REACHED
        return A_WAIT_TIME
    s[IN_WINDOW_SINCE] = -1.0
    return A_WAIT_TIME


@jitable
def clamp_target(s: Row, target: float) -> float:
    """A target inside the software position limits (min >= max: no limits)."""
    lo = s[MIN_LIMIT] - s[OFFSET]
    hi = s[MAX_LIMIT] - s[OFFSET]
    if lo < hi:
        return fmin(fmax(target, lo), hi)
    return target


@jitable
def round_half_even(x: float) -> int:
    """``round(x)`` exactly as Python's builtin (ties to even), in compiled code too."""
    r = math.floor(x)
    d = x - r
    if d > 0.5 or (d == 0.5 and r % 2 != 0):
        r += 1
    return int(r)


# -- register ops: what a write of a motion command does to the row (the firmware object's writes and the
# -- one-call exchange of joints.sim.erob_exchange both call these: the semantics live here once) ------
@jitable
def frame(s: Row) -> None:
    """A frame addressed to the drive arrived (the communication watchdog's food)."""
    s[LAST_FRAME] = s[TIME]


@jitable
def ready_or_refuse(s: Row) -> bool:
    """A motion command: True if the drive is ready; else nothing moves, the state machine sees the refused
    motion and the error 0x0027 latches (unless an error is latched already)."""
    if ready(s):
        return True
    new = NEXT[int(s[STATE])][EV_MOTION]
    if new >= 0:
        s[STATE] = float(new)
    if s[FAULT_CODE] == 0.0:
        s[FAULT_CODE] = START_WHILE_DISABLED
    return False


@jitable
def start(s: Row, motion: float, relative: float, target: float) -> None:
    """Start Operating (0x00F2) in position mode with ``motion_mode`` ``motion``, ``target_relative_position``
    ``relative`` and ``target_absolute_position`` ``target`` (counts incl. offset)."""
    if s[MODE] != POSITION:
        return
    if not ready_or_refuse(s):
        return
    s[G_STOPPING] = 0.0
    s[G_RATE] = 0.0
    s[STARTED] = 1.0
    s[IN_WINDOW_SINCE] = -1.0
    if motion == CONTINUOUS:
        s[G_ACTIVE] = 1.0
        s[G_CONTINUOUS] = 1.0
    elif motion == ABSOLUTE:
        if relative != 0.0:
            s[G_TARGET] = clamp_target(s, s[P_REF] + relative)
        else:
            s[G_TARGET] = clamp_target(s, target - s[OFFSET])
        s[G_ACTIVE] = 1.0
        s[G_CONTINUOUS] = 0.0
    elif motion == REPETITIVE:
        s[REPEAT_HOME] = s[P_REF]
        s[REPEAT_LEG_TO_TARGET] = 1.0
        s[REPEAT_STOP] = 0.0
        s[G_TARGET] = clamp_target(s, target - s[OFFSET])
        s[G_ACTIVE] = 1.0
        s[G_CONTINUOUS] = 0.0
    else:  # the parameter's range (0-2) keeps other values out
        s[STARTED] = 0.0


@jitable
def target_speed(s: Row, value: float) -> None:
    """A write of ``target_speed`` (0x0044, count/s): in speed mode the ramp's target (a nonzero one is a motion
    command: refused unless ready; it ends a stop ramp in progress)."""
    if s[MODE] != SPEED_MODE:
        return
    if value != 0.0 and not ready_or_refuse(s):
        return
    if value != 0.0:
        gen_clear(s)
    vmax = s[VMAX]
    s[MODE_SPEED_TARGET] = fmax(-vmax, fmin(vmax, value))


@jitable
def target_current(s: Row, value: float) -> None:
    """A write of ``target_current`` (0x00E4, mA): the torque loop's target (a nonzero one in torque mode is a
    motion command: refused unless ready)."""
    s[TARGET_CURRENT] = value
    if s[MODE] == TORQUE and value != 0.0:
        ready_or_refuse(s)


#: the status values :func:`status` computes, in its order (the Modbus status block 0x0060-0x0078
#: and the torque sensor)
STATUS_NAMES = ("error_code", "motion_status", "status_of_achieving_position", "given_position", "actual_position",
                "position_error", "given_speed", "current_speed", "speed_error", "given_current", "motor_current",
                "part_of_power_temperature", "torque_sensor_value")
STOP_REPETITIVE = 3  #: motion_status: stopping a repetitive motion


@jitable
def status(s: Row, repetitive: bool) -> tuple[int, int, int, int, int, int, int, int, int, int, int, int, int]:
    """Every value of :data:`STATUS_NAMES` now (runs the settle timer, as reading 0x0063 does);
    ``repetitive``: the motion mode is repetitive."""
    is_moving = moving(s)
    if s[REPEAT_STOP] != 0.0 and repetitive and s[G_ACTIVE] != 0.0:
        motion = STOP_REPETITIVE
    else:
        motion = 1 if is_moving else 0
    reached = achieve(s, is_moving)
    offset = int(s[OFFSET])
    on = is_enabled(s[STATE])
    return (int(s[FAULT_CODE]), motion, reached, round_half_even(s[P_REF]) + offset,
            round_half_even(s[POS]) + offset, round_half_even(s[P_REF] - s[POS]),
            round_half_even(s[V_CMD] if on else 0.0), round_half_even(s[VEL]),
            round_half_even((s[V_CMD] - s[VEL]) if on else 0.0), round_half_even(s[I_CMD]),
            round_half_even(s[I_OUT]), round_half_even(s[TEMPERATURE]), round_half_even(s[I_OUT] * s[KT]))


#: the row's columns a read's sensors see (what :func:`status_out` writes after the status values)
SENSED = (TIME, POS, VEL, I_OUT)


@jitable
def status_out(s: Row, r: Row, repetitive: bool, o: Row, at: int) -> None:
    """A status read's output row: :func:`status` of ``r`` (the drive's row ``s`` itself, or a copy of it where the
    read must leave no trace) at ``o[at:]``, then ``s``'s :data:`SENSED` columns (the one-call exchanges'
    read, Modbus and CAN alike)."""
    values = status(r, repetitive)
    for k in range(len(values)):
        o[at + k] = values[k]
    n = at + len(values)
    o[n] = s[TIME]
    o[n + 1] = s[POS]
    o[n + 2] = s[VEL]
    o[n + 3] = s[I_OUT]


# -- the loops --------------------------------------------------------------------------------------
@jitable
def _brake_torque(s: Row, q: float, qd: float) -> float:
    """Holding brake: a stiff spring-damper to where it engaged, limited to the rated torque x 2."""
    s[V_REF] = 0.0
    s[I_CMD] = 0.0
    s[I_OUT] = 0.0
    if s[BRAKE_RELEASED] != 0.0:
        return 0.0
    at = s[BRAKE_HOLD]
    if math.isnan(at):  # none: engage where the joint is now
        at = s[POS]
        s[BRAKE_HOLD] = at
    tau = -s[BRAKE_K] * (s[POS] - at) / COUNTS_PER_RAD - s[BRAKE_C] * qd
    hold = s[BRAKE_HOLD_TORQUE]
    if tau > hold:
        return hold
    if tau < -hold:
        return -hold
    return tau


@jitable
def _current_limit(s: Row, dt: float, i: float) -> float:
    peak = fmin(s[I_PEAK], s[I_MAX])
    if abs(i) > s[I_CONT] and s[PEAK_TIME] > 0:
        if s[PEAK_SINCE] < 0:
            s[PEAK_SINCE] = s[TIME]
        if s[TIME] - s[PEAK_SINCE] > s[PEAK_TIME]:
            return s[I_CONT]
    else:
        s[PEAK_SINCE] = -1.0
    return peak


@jitable
def _torque_loop(s: Row, dt: float) -> float:
    """Current = target current, capped by a PI speed limiter at the torque-mode max speed."""
    target = s[TARGET_CURRENT]
    vmax = s[VMAX]
    mode_max = s[TORQUE_MAX_SPEED]
    vlim = fmin(mode_max if mode_max != 0.0 else vmax, vmax)
    s[V_REF] = s[VEL]
    s[P_REF] = s[POS]
    if target == 0.0:
        s[INTEG] = 0.0
        return 0.0
    sgn = 1.0 if target > 0 else -1.0
    e = vlim - sgn * s[VEL]  # > 0 while below the limit in the commanded direction
    cap = s[KV] * e + s[KI] * s[INTEG]  # magnitude the speed limiter allows
    if abs(target) >= cap:
        mag = cap
        s[INTEG] += e * dt
    else:
        mag = abs(target)
        if s[KI] != 0.0:
            # keep the limiter's integral where it would take over smoothly (anti-windup), but
            # never below 0 while the proportional part alone allows more than the target: a cap
            # held exactly at the target clipped every rise of the command (a joint accelerating
            # lowers e), by ~20 % of the accelerating torque every other substep
            s[INTEG] = fmin(s[INTEG], fmax(0.0, (abs(target) - s[KV] * e) / s[KI]))
    i = sgn * mag
    lim = _current_limit(s, dt, i)
    return fmax(-lim, fmin(lim, i))


@jitable
def _speed_ramp(s: Row, dt: float) -> None:
    v = s[V_REF]
    stopping = s[G_STOPPING] != 0.0
    if stopping:  # Stop Operating / Emergency Stop: to standstill with the stop's deceleration
        rate = s[G_RATE]
        new_v = ramp(v, 0.0, s[ACC], rate if rate != 0.0 else s[DEC], dt)
    else:
        new_v = ramp(v, s[MODE_SPEED_TARGET], s[ACC], s[DEC], dt)
    s[P_REF] += 0.5 * (v + new_v) * dt
    s[V_REF] = new_v
    if stopping and new_v == 0.0:
        gen_clear(s)


@jitable
def _leg_done(s: Row) -> None:
    s[G_ACTIVE] = 0.0
    repetitive = s[MOTION_MODE] == REPETITIVE
    if repetitive and s[STARTED] != 0.0 and s[REPEAT_STOP] == 0.0:
        s[DWELL_UNTIL] = s[TIME] + s[DWELL_TIME] * 5e-5
    else:
        s[STARTED] = 1.0 if (not repetitive and s[STARTED] != 0.0) else 0.0


@jitable
def _next_repetitive_leg(s: Row) -> None:
    if s[REPEAT_STOP] != 0.0:
        return
    to_target = s[REPEAT_LEG_TO_TARGET] == 0.0
    s[REPEAT_LEG_TO_TARGET] = 1.0 if to_target else 0.0
    if to_target:
        s[G_TARGET] = clamp_target(s, s[TARGET_ABSOLUTE] - s[OFFSET])
    else:
        s[G_TARGET] = s[REPEAT_HOME]
    s[G_ACTIVE] = 1.0
    s[G_CONTINUOUS] = 0.0
    s[G_STOPPING] = 0.0


@jitable
def _profile_step(s: Row, dt: float) -> None:
    if s[G_ACTIVE] == 0.0:
        if s[STREAMING] != 0.0:  # between two streamed set-points, up to the newest and no further
            step = s[V_REF] * dt
            rest = s[STREAM_GOAL] - s[P_REF]
            if rest == 0.0:
                s[V_REF] = 0.0  # at the newest set-point since the last substep: hold there
            elif (step > 0.0 and step >= rest) or (step < 0.0 and step <= rest):
                s[P_REF] = s[STREAM_GOAL]  # arrives (the speed stands until the next substep)
            else:
                s[P_REF] += step
            return
        if s[DWELL_UNTIL] >= 0 and s[TIME] >= s[DWELL_UNTIL]:
            s[DWELL_UNTIL] = -1.0
            _next_repetitive_leg(s)
        return
    v = s[V_REF]
    rate = s[G_RATE]
    decel = rate if rate != 0.0 else s[DEC]
    if s[G_STOPPING] != 0.0:
        new_v = ramp(v, 0.0, s[ACC], decel, dt)
        s[P_REF] += 0.5 * (v + new_v) * dt
        s[V_REF] = new_v
        if new_v == 0.0:
            s[G_ACTIVE] = 0.0
            s[G_STOPPING] = 0.0
            s[STARTED] = 0.0
            s[DWELL_UNTIL] = -1.0
        return
    if s[G_CONTINUOUS] != 0.0:
        speed = s[SPEED]
        target_v = math.copysign(s[VPROF], speed) if speed != 0.0 else 0.0
        # the acceleration whenever the target is faster than the present speed, even on a
        # reversal (speed mode decelerates to the reversal): kept as calibrated
        slope = s[ACC] if abs(target_v) > abs(v) else decel
        new_v = ramp(v, target_v, slope, slope, dt)
        s[P_REF] += 0.5 * (v + new_v) * dt
        s[V_REF] = new_v
        return
    p, new_v, arrived = move_step(s[P_REF], v, s[G_TARGET], s[VPROF], s[ACC], decel, dt, ARRIVAL_WINDOW, ON_STEP)
    s[P_REF] = p
    s[V_REF] = new_v
    if arrived:
        _leg_done(s)


@jitable
def _stall(s: Row, dt: float) -> None:
    sc, ss, st = s[STRUCK_CURRENT], s[STRUCK_SPEED], s[STRUCK_TIME]
    if sc != 0.0 and st != 0.0 and abs(s[I_OUT]) > sc and abs(s[VEL]) < ss:
        if s[STALL_SINCE] < 0:
            s[STALL_SINCE] = s[TIME]
        elif s[TIME] - s[STALL_SINCE] > st * 5e-5:
            s[STALL_SINCE] = -1.0
            raise_fault(s, STALL)
    else:
        s[STALL_SINCE] = -1.0


@jitable
def _thermal(s: Row, dt: float, i_ma: float) -> None:
    # first-order model: rated current gives +40 K at steady state, time constant 300 s
    r = i_ma * 1e-3 / s[RATED_CURRENT]
    rise = 40.0 * (r * r)
    s[TEMPERATURE] += (s[AMBIENT] + rise - s[TEMPERATURE]) * dt / 300.0
    lim = s[TEMP_PROTECTION]
    if lim != 0.0 and s[TEMPERATURE] > lim:
        raise_fault(s, OVER_TEMPERATURE)


@jitable
def _supervise(s: Row, period: float) -> None:
    """The drive's slow tasks: settle timer, stall and thermal protection."""
    on = is_enabled(s[STATE])
    if on and s[STARTED] != 0.0 and s[MODE] == POSITION:
        achieve(s, moving(s))  # the settle timer of 0x007A runs on the drive
    _stall(s, period)
    _thermal(s, period, s[I_OUT] if on else 0.0)


@jitable
def step(s: Row, t: float, dt: float, q: float, qd: float) -> float:
    """Run the drive's loops for the substep ending at ``t`` (length ``dt``) with the joint at
    ``q`` [rad], ``qd`` [rad/s]; return the motor torque at the output [N*m].

    Control loops run every substep; supervision (stall, temperature, the settle timer of
    0x007A) every :data:`SUPERVISION_PERIOD` of drive time; the communication watchdog every
    substep.
    """
    s[TIME] = t
    pos = q * COUNTS_PER_RAD
    vel = qd * COUNTS_PER_RAD
    s[POS] = pos
    s[VEL] = vel
    wd = s[WATCHDOG]
    if wd != 0.0 and s[LAST_FRAME] >= 0 and t - s[LAST_FRAME] > wd:
        if s[FAULT_CODE] != RS485_TIMEOUT:  # the watchdog's code replaces a latched one
            s[FAULT_CODE] = RS485_TIMEOUT
            new = NEXT[int(s[STATE])][EV_WATCHDOG]
            s[STATE] = float(new) if new >= 0 else FAULT
            motor_off(s)
        s[LAST_FRAME] = -1.0
    s[SUP] += dt
    if s[SUP] >= SUPERVISION_PERIOD - 1e-12:
        _supervise(s, s[SUP])
        s[SUP] = 0.0
    state = s[STATE]
    if state != READY:
        if state == ENABLING and t >= s[ENABLED_AT] + ENABLE_DELAY - 1e-9:
            s[STATE] = READY  # transition(ENABLING, BRAKE_RELEASED)
        else:
            if state == ENABLING or state == REFUSED_ON:
                s[P_REF] = s[POS]  # brake still releasing (or start refused): hold here
            return _brake_torque(s, q, qd)
    mode = s[MODE]
    if mode == TORQUE:
        i = _torque_loop(s, dt)
    else:
        v_prev = s[V_REF]
        if mode == SPEED_MODE:
            _speed_ramp(s, dt)
            v_ref = s[V_REF]
            v_cmd = v_ref
        else:
            _profile_step(s, dt)
            v_ref = s[V_REF]
            err = s[P_REF] - pos
            v_cmd = v_ref + s[KP] * err
            lim = s[MAX_POSITION_ERROR]
            if lim != 0.0 and abs(err) > lim:
                raise_fault(s, FOLLOWING_ERROR)
                return _brake_torque(s, q, qd)
        vmax = s[VMAX]
        if v_cmd > vmax:
            v_cmd = vmax
        elif v_cmd < -vmax:
            v_cmd = -vmax
        s[V_CMD] = v_cmd
        e = v_cmd - vel
        slim = s[MAX_SPEED_ERROR]
        if slim != 0.0 and abs(v_ref - vel) > slim:
            raise_fault(s, SPEED_ERROR)
            return _brake_torque(s, q, qd)
        # PI speed loop plus acceleration feedforward (the current the profile's own
        # acceleration needs, J x a / kt): without it the integral has to carry every ramp
        # and the joint overshoots when a ramp ends (an emergency stop bounced back ~8 %)
        i = s[KV] * e + s[KI] * s[INTEG] + s[KFF] * (v_ref - v_prev) / dt
        i_cont = s[I_CONT]
        if -i_cont <= i <= i_cont:  # common case: within the continuous current
            s[PEAK_SINCE] = -1.0
            lim_i = s[I_LIM]
        else:
            lim_i = _current_limit(s, dt, i)
        if -lim_i < i < lim_i:
            s[INTEG] += e * dt  # anti-windup: integrate only while unsaturated
        elif i > lim_i:
            i = lim_i
        else:
            i = -lim_i
    s[I_CMD] = i
    s[I_OUT] = i
    return i * 1e-3 * s[KT]


#: the helpers the firmware object calls, as Python (rows that are lists)
PY_OPS = SimpleNamespace(achieve=achieve, moving=moving, ready=ready, motor_off=motor_off, raise_fault=raise_fault,
                         gen_clear=gen_clear, clamp_target=clamp_target, step=step,
                         status=status, ready_or_refuse=ready_or_refuse, start=start, target_speed=target_speed,
                         target_current=target_current)
def compiled_ops() -> Any:
    """The same helpers compiled (rows that are numpy arrays), or :data:`PY_OPS` without numba."""
    return kernel.compiled_ops(PY_OPS)


def warm() -> None:
    """Compile (or load from the disk cache) every compiled helper now, on a scratch row, so that no
    call later - in a real-time served world - waits for the compiler."""
    ops = compiled_ops()
    if ops is PY_OPS:
        return
    import numpy as np

    s = np.ones((1, WIDTH))[0]  # no zero a loop divides by
    s[STATE] = MOTOR_OFF
    s[SUP] = 0.0
    s[BRAKE_HOLD] = math.nan
    ops.achieve(s, ops.moving(s))
    ops.ready(s)
    ops.motor_off(s)
    ops.raise_fault(s, 0.0)
    ops.gen_clear(s)
    ops.clamp_target(s, 0.0)
    ops.status(s, False)
    ops.ready_or_refuse(s)
    ops.start(s, 1.0, 0.0, 0.0)
    ops.target_speed(s, 0.0)
    ops.target_current(s, 0.0)
    ops.step(s, 0.001, 0.001, 0.0, 0.0)
