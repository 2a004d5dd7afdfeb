"""The ZLAC8015D's per-substep loops over rows of floats: the one implementation its twin runs.

Rule: as :mod:`joints.sim.erob_kernel`. A drive is three rows of a table: the drive's own row
(the one state machine both motors share, the offline watchdog, the drive constants) at ``d``,
then the left channel at ``d + 1`` and the right at ``d + 2`` (ramps, profile generator,
velocity / position / torque loops, current limits, motor model, protections). Functions take
the table and those indices, in the subset of Python numba compiles. The firmware object
(:class:`joints.sim.zlac.ZlacFirmware`) acts on control words and settings in Python, on the same
rows, through the same helpers. The conventions are those of :mod:`joints.sim.zlac`; the state
machine is :data:`joints.devices.zlac.state.TRANSITIONS`. "None" (no ramp reference) is NaN.
"""

from __future__ import annotations

import math
from collections.abc import MutableSequence, Sequence
from types import SimpleNamespace
from typing import Any

from joints.devices.motion import Arrival, move_step, ramp
from joints.devices.zlac.registers import ControlMode, Fault, QuickStopBehaviour
from joints.devices.zlac.state import DriveState
from joints.sim import kernel, rowattr
from joints.sim.erob_kernel import fmax, fmin
from joints.sim.kernel import jitable
from joints.sim.rowattr import Code, Flag, Int, Maybe, Real

Row = MutableSequence[float]
Table = Sequence[Row]

#: this kernel's kind: the code of its rows in :attr:`joints.sim.stepping.Group.adr` (a twin's ``KERNEL``)
KIND = 2
TWO_PI = 2.0 * math.pi
RPM = TWO_PI / 60.0  #: rad/s per r/min
THERMAL_RISE = 60.0  #: K above ambient at the motor's rated current (EST)
THERMAL_TAU = 600.0  #: s, winding time constant (EST)
BEFORE_STEP = Arrival.BEFORE_STEP

STATES = tuple(DriveState)  #: code -> state
DISABLED = float(STATES.index(DriveState.DISABLED))
ENABLED = float(STATES.index(DriveState.ENABLED))
QUICK_STOP = float(STATES.index(DriveState.QUICK_STOP))
FAULT = float(STATES.index(DriveState.FAULT))

VELOCITY = float(ControlMode.VELOCITY)
RELATIVE_POSITION = float(ControlMode.RELATIVE_POSITION)
ABSOLUTE_POSITION = float(ControlMode.ABSOLUTE_POSITION)
TORQUE = float(ControlMode.TORQUE)
QS_WITHOUT_DECELERATION = float(QuickStopBehaviour.QUICK_STOP_WITHOUT_DECELERATION)
QS_STOP = float(QuickStopBehaviour.STOP)
VELOCITY_FOLLOWING_ERROR = int(Fault.VELOCITY_FOLLOWING_ERROR)
POSITION_FOLLOWING_ERROR = int(Fault.POSITION_FOLLOWING_ERROR)
OVER_LOAD = int(Fault.OVER_LOAD)
MOTOR_OVER_TEMPERATURE = int(Fault.MOTOR_OVER_TEMPERATURE)

# -- the drive's row ----------------------------------------------------------------------------------
class DriveColumns(rowattr.Columns):
    """The drive's row, declared once: the ``D_`` index constants below and the drive's attributes
    (:class:`joints.sim.zlac.ZlacFirmware` inherits this class) come from here."""

    PREFIX = "D_"
    time = Real("drive time [s]: the end of the last substep")
    state = Code(STATES, "the drive state (held as its code in :data:`STATES`)")
    last_frame = Real("time of the last received frame [s], -1 = none since power-on")
    offline = Flag("the offline watchdog tripped (until the next enable)")
    ticked = Real("the substep the drive's own tasks last ran for [s] (the second channel of a substep skips them)")
    vmax = Real("maximum motor speed [rad/s] (0x2008)")
    watchdog = Real("communication offline time [s], 0 = off (0x2000)")
    mode = Int("control mode in force (0x200D)")
    sync = Int("synchronous / asynchronous control (0x200F)")
    quick_stop_option = Int("what a quick stop does (0x2011; an invalid value: its default)", const="D_QS_OPTION")
    ramp_reference = Maybe("the speed the ramp times refer to [rad/s]; None (NaN in the row): the move's own",
                           const="D_RAMP_REF")
    ambient = Real("ambient temperature [degC]")
    back_emf_constant = Real("the motors' back-EMF constant [V*s/rad]", const="D_BACK_EMF")
    bus_voltage = Real("DC bus voltage [V]")
    phase_resistance = Real("the motors' phase resistance [ohm]", const="D_PHASE_R")
    motor_rated_current = Real("the motors' rated current [A] (the thermal model's scale)", const="D_MOTOR_RATED")
    connected = Flag("the host counts as connected (software connected status, 0x20AF)")


#: the drive row's index constants, in the declared order (plain ints: numba compiles them in; checked at import)
(D_TIME, D_STATE, D_LAST_FRAME, D_OFFLINE, D_TICKED, D_VMAX, D_WATCHDOG, D_MODE, D_SYNC, D_QS_OPTION,
 D_RAMP_REF, D_AMBIENT, D_BACK_EMF, D_BUS_VOLTAGE, D_PHASE_R, D_MOTOR_RATED, D_CONNECTED) = rowattr.indices(DriveColumns)
DRIVE_COLUMNS = rowattr.names(DriveColumns)


# -- a channel's row -----------------------------------------------------------------------------------
class ChannelColumns(rowattr.Columns):
    """A channel's row (left, right), declared once: the index constants below and the channel's attributes
    (:class:`joints.sim.zlac.ZlacChannel` inherits this class) come from here. Angles are the wheel's."""

    # working state
    fresh = Flag("the next step latches the encoder origin and the loops at q")
    q = Real("wheel angle [rad] seen at the last step")
    qd = Real("wheel speed [rad/s] seen at the last step")
    origin = Real("raw angle [rad] where the position counter reads 0")
    fault = Int("fault bits (error code register 0x20A5 / 0x20A6), 0 = none", const="FAULT_BITS")
    overload_time = Real("how long the current has been above the rated current [s]")
    i_out = Real("motor current [A]")
    temperature = Real("winding [degC]")
    v_ref = Real("speed command of the ramp / profile [rad/s]")
    v_target = Real("velocity-mode ramp target [rad/s]")
    acc_slope = Real("velocity-mode ramp's acceleration [rad/s^2]")
    dec_slope = Real("velocity-mode ramp's deceleration [rad/s^2]")
    p_ref = Real("position command [rad]")
    goal = Real("end point of the present / last move [rad]")
    moving = Flag("a position move is in progress")
    cruise = Real("the move's cruise speed [rad/s]")
    p_acc = Real("the move's acceleration [rad/s^2]")
    p_dec = Real("the move's deceleration [rad/s^2]")
    integ = Real("velocity-loop integral of the speed error [rad]")
    lag = Real("integral of (speed command - speed) [rad], velocity following error")
    i_ref = Real("torque-mode current command after the slope [A]")
    qs_slope = Real("quick stop's deceleration [rad/s^2]")
    # settings (from the parameters)
    cpr = Real("encoder counts per motor revolution (4 x the encoder lines, 0x2030 / 0x2060)")
    counts_per_rad = Real("encoder counts per rad")
    arrival_window = Real("half a count [rad]")
    acc_time = Real("acceleration time [s] (0x2080 / 0x2081)")
    dec_time = Real("deceleration time [s] (0x2082 / 0x2083)")
    qs_time = Real("quick stop's deceleration time [s] (0x2084 / 0x2085)")
    torque_rate = Real("torque-mode current slope [A/s] (0x2086 / 0x2087)")
    rated = Real("rated current [A]")
    peak = Real("peak current [A]: the maximum current, or rated x the overload factor if less")
    overload_limit = Real("how long the current may stay above rated [s], 0 = off")
    follow_limit = Real("following-error limit [rad]")
    wv = Real("velocity-loop bandwidth [rad/s] (vl_kp / 10)")
    wi = Real("velocity-loop integral rate [1/s] (vl_ki / 10)")
    kfv = Real("velocity-loop acceleration feed-forward (vl_kf / 1000)")
    kpp = Real("position-loop gain [1/s] (pl_kp / 10)")
    kfp = Real("position-loop speed feed-forward (pl_kf / 100)")
    poles = Int("motor poles")
    hall_offset = Real("hall offset angle [rad]")
    temp_limit = Real("over-temperature limit [degC], 0 = off")
    target_speed = Real("position mode's cruise speed [rad/s] (0x208E / 0x208F)")
    v_start = Real("initial velocity [rad/s] (cached from 0x2043/0x2073)")
    target_torque = Real("torque mode's target [mA] (0x2090 / 0x2091)")
    # constants
    inertia = Real("J [kg*m^2] the velocity-loop gains are scaled with (tuned for)")
    kt = Real("torque constant [N*m/A]")


#: a channel row's index constants, in the declared order (plain ints: numba compiles them in; checked at import)
(FRESH, Q, QD, ORIGIN, FAULT_BITS, OVERLOAD_TIME, I_OUT, TEMPERATURE, V_REF, V_TARGET, ACC_SLOPE, DEC_SLOPE, P_REF,
 GOAL, MOVING, CRUISE, P_ACC, P_DEC, INTEG, LAG, I_REF, QS_SLOPE, CPR, COUNTS_PER_RAD, ARRIVAL_WINDOW, ACC_TIME,
 DEC_TIME, QS_TIME, TORQUE_RATE, RATED, PEAK, OVERLOAD_LIMIT, FOLLOW_LIMIT, WV, WI, KFV, KPP, KFP, POLES,
 HALL_OFFSET, TEMP_LIMIT, TARGET_SPEED, V_START, TARGET_TORQUE, INERTIA, KT) = rowattr.indices(ChannelColumns)
CHANNEL_COLUMNS = rowattr.names(ChannelColumns)

WIDTH = max(rowattr.bind(globals(), DriveColumns), rowattr.bind(globals(), ChannelColumns))  #: columns of a row


# -- helpers shared with the firmware object ------------------------------------------------------------
@jitable
def reset_loops(c: Row) -> None:
    """Loops and generators to rest at the present state (enable, mode change, power off)."""
    # the speed command starts at the measured speed; below the initial velocity
    # (0x2043/0x2073, default 1 r/min) that is standstill
    qd = c[QD]
    v0 = qd if abs(qd) >= c[V_START] else 0.0
    c[V_REF] = v0
    c[V_TARGET] = v0
    c[ACC_SLOPE] = math.inf
    c[DEC_SLOPE] = math.inf
    c[P_REF] = c[Q]
    c[GOAL] = c[Q]
    c[MOVING] = 0.0
    c[CRUISE] = 0.0
    c[P_ACC] = math.inf
    c[P_DEC] = math.inf
    c[INTEG] = 0.0
    c[LAG] = 0.0
    c[I_REF] = 0.0
    c[QS_SLOPE] = math.inf


@jitable
def begin_quick_stop(d: Row, c: Row, option: float, was_running: bool) -> None:
    """Enter quick stop: ramp the speed command to 0 per 0x2011."""
    start = c[V_REF] if was_running and d[D_MODE] != TORQUE else c[QD]
    c[MOVING] = 0.0
    c[V_REF] = start
    if option == QS_WITHOUT_DECELERATION:
        c[QS_SLOPE] = math.inf
    else:
        t = c[DEC_TIME] if option == QS_STOP else c[QS_TIME]
        ref = d[D_RAMP_REF]
        c[QS_SLOPE] = (abs(start) if math.isnan(ref) else ref) / t


@jitable
def quick_stop(table: Any, first: int) -> None:
    """The drive enters quick stop (both channels)."""
    d = table[first]
    was = d[D_STATE] == ENABLED
    d[D_STATE] = QUICK_STOP
    option = d[D_QS_OPTION]
    begin_quick_stop(d, table[first + 1], option, was)
    begin_quick_stop(d, table[first + 2], option, was)


@jitable
def frame(d: Row) -> None:
    """A frame addressed to the drive arrived (the offline watchdog's food; the host counts as connected again
    unless the watchdog tripped)."""
    d[D_LAST_FRAME] = d[D_TIME]
    if d[D_OFFLINE] == 0.0:
        d[D_CONNECTED] = 1.0


@jitable
def set_velocity_target(d: Row, c: Row, rpm: float) -> None:
    """Velocity-mode target ``rpm`` [r/min] written: clamp it to the maximum motor speed and start the ramp
    to it from the present speed command (see :mod:`joints.sim.zlac`); the same target again changes nothing."""
    vmax = d[D_VMAX]
    target = rpm * RPM
    if not target < vmax:  # max(-vmax, min(vmax, target)) as Python computes it (no NaN here)
        target = vmax
    if not target > -vmax:
        target = -vmax
    if target == c[V_TARGET]:
        return
    c[V_TARGET] = target
    v = c[V_REF]
    ref = d[D_RAMP_REF]
    if not math.isnan(ref):  # a fixed-slope reference (ramp_reference_rpm)
        c[ACC_SLOPE] = ref / c[ACC_TIME]
        c[DEC_SLOPE] = ref / c[DEC_TIME]
    elif v * target > 0.0:
        if abs(target) >= abs(v):
            c[ACC_SLOPE] = (abs(target) - abs(v)) / c[ACC_TIME]
        else:
            c[DEC_SLOPE] = (abs(v) - abs(target)) / c[DEC_TIME]
    else:
        c[DEC_SLOPE] = abs(v) / c[DEC_TIME]
        c[ACC_SLOPE] = abs(target) / c[ACC_TIME]


@jitable
def raise_fault(d: Row, c: Row, bit: int) -> None:
    """A channel detected a fault: set its bit, switch both motors off (every state leads to FAULT)."""
    c[FAULT_BITS] = float(int(c[FAULT_BITS]) | bit)
    d[D_STATE] = FAULT


@jitable
def tick(table: Any, first: int, t: float) -> None:
    """Drive-level work once per substep (the first channel step with a new ``t``)."""
    d = table[first]
    if t == d[D_TICKED]:  # the other channel of the same substep (time may restart on a reset)
        return
    d[D_TICKED] = t
    d[D_TIME] = t
    wd = d[D_WATCHDOG]
    if wd > 0.0 and d[D_LAST_FRAME] >= 0.0 and d[D_STATE] == ENABLED and t - d[D_LAST_FRAME] > wd + 1e-9:
        d[D_OFFLINE] = 1.0
        d[D_CONNECTED] = 0.0
        quick_stop(table, first)  # transition(ENABLED, Event.OFFLINE)


# -- the loops ----------------------------------------------------------------------------------------
@jitable
def _thermal(d: Row, c: Row, dt: float, i: float) -> bool:
    if dt > 0.0:
        r = i / d[D_MOTOR_RATED]
        rise = THERMAL_RISE * (r * r)
        c[TEMPERATURE] += (d[D_AMBIENT] + rise - c[TEMPERATURE]) * fmin(1.0, dt / THERMAL_TAU)
    if c[TEMP_LIMIT] > 0.0 and c[TEMPERATURE] > c[TEMP_LIMIT]:
        raise_fault(d, c, MOTOR_OVER_TEMPERATURE)
        return False
    return True


@jitable
def _off(d: Row, c: Row, dt: float) -> float:
    c[I_OUT] = 0.0
    c[OVERLOAD_TIME] = 0.0
    reset_loops(c)
    _thermal(d, c, dt, 0.0)
    return 0.0


@jitable
def _track_lag(d: Row, c: Row, dt: float) -> bool:
    c[LAG] += (c[V_REF] - c[QD]) * dt
    if abs(c[LAG]) > c[FOLLOW_LIMIT]:
        raise_fault(d, c, VELOCITY_FOLLOWING_ERROR)
        return False
    return True


@jitable
def _limit_pos(d: Row, c: Row) -> float:
    """Positive current magnitude limit [A] at the present speed."""
    peak = c[PEAK]
    qd = c[QD]
    if qd > 0.0:
        emf = d[D_BACK_EMF] * abs(qd)
        return fmin(peak, fmax(0.0, (d[D_BUS_VOLTAGE] - emf) / d[D_PHASE_R]))
    return peak


@jitable
def _limit_neg(d: Row, c: Row) -> float:
    """Negative current magnitude limit [A] at the present speed."""
    peak = c[PEAK]
    qd = c[QD]
    if qd < 0.0:
        emf = d[D_BACK_EMF] * abs(qd)
        return fmin(peak, fmax(0.0, (d[D_BUS_VOLTAGE] - emf) / d[D_PHASE_R]))
    return peak


@jitable
def _speed_loop(d: Row, c: Row, v_cmd: float, a_ff: float, dt: float) -> float:
    """PI velocity loop + acceleration feed-forward -> current [A], limited, anti-windup."""
    e = v_cmd - c[QD]
    j = c[INERTIA]
    i = j * (c[WV] * e + c[WV] * c[WI] * c[INTEG] + a_ff) / c[KT]
    hi = _limit_pos(d, c)
    lo = _limit_neg(d, c)
    if i > hi:
        i = hi
    elif i < -lo:
        i = -lo
    else:
        c[INTEG] += e * dt  # integrate only while unsaturated
    return i


@jitable
def _torque(d: Row, c: Row, dt: float) -> float:
    target = c[TARGET_TORQUE] * 1e-3
    rate = c[TORQUE_RATE]
    if rate > 0.0:
        step = rate * dt
        diff = target - c[I_REF]
        c[I_REF] = target if abs(diff) <= step else c[I_REF] + math.copysign(step, diff)
    else:
        c[I_REF] = target
    i = c[I_REF]
    if i != 0.0:
        sgn = 1.0 if i > 0 else -1.0
        cap = c[INERTIA] * c[WV] * (d[D_VMAX] - sgn * c[QD]) / c[KT]
        i = sgn * fmin(abs(i), fmax(0.0, cap))
    hi = _limit_pos(d, c)
    lo = _limit_neg(d, c)
    return fmax(-lo, fmin(hi, i))


@jitable
def _protect(d: Row, c: Row, dt: float, i: float) -> bool:
    if c[OVERLOAD_LIMIT] > 0.0 and abs(i) > c[RATED]:
        c[OVERLOAD_TIME] += dt
        if c[OVERLOAD_TIME] > c[OVERLOAD_LIMIT] + 1e-9:
            raise_fault(d, c, OVER_LOAD)
            return False
    else:
        c[OVERLOAD_TIME] = 0.0
    return _thermal(d, c, dt, i)


@jitable
def step(table: Any, first: int, side: int, t: float, dt: float, q: float, qd: float) -> float:
    """Run channel ``side`` (0 left, 1 right) of the drive at row ``first`` for the substep ending at
    ``t`` (length ``dt``) with the wheel at ``q`` [rad], ``qd`` [rad/s]; return the motor torque at the
    wheel [N*m]."""
    tick(table, first, t)
    d = table[first]
    c = table[first + 1 + side]
    if c[FRESH] != 0.0:
        # first substep after power-on: the counter starts at 0 here; commands that came
        # before it were taken relative to the unknown angle (0), shift them to the real one
        c[FRESH] = 0.0
        delta = q - c[Q]
        c[ORIGIN] = q
        c[P_REF] += delta
        c[GOAL] += delta
    c[Q] = q
    c[QD] = qd
    state = d[D_STATE]
    if state == DISABLED or state == FAULT or dt <= 0.0:
        return _off(d, c, dt)
    mode = d[D_MODE]
    if state == QUICK_STOP:
        v_prev = c[V_REF]
        c[V_REF] = ramp(v_prev, 0.0, math.inf, c[QS_SLOPE], dt, True)
        if not _track_lag(d, c, dt):
            return _off(d, c, dt)
        i = _speed_loop(d, c, c[V_REF], (c[V_REF] - v_prev) / dt, dt)
    elif mode == VELOCITY:
        v_prev = c[V_REF]
        c[V_REF] = ramp(c[V_REF], c[V_TARGET], c[ACC_SLOPE], c[DEC_SLOPE], dt, True)
        if not _track_lag(d, c, dt):
            return _off(d, c, dt)
        i = _speed_loop(d, c, c[V_REF], c[KFV] * (c[V_REF] - v_prev) / dt, dt)
    elif mode == RELATIVE_POSITION or mode == ABSOLUTE_POSITION:
        v_prev = c[V_REF]
        if c[MOVING] != 0.0:
            p, v, arrived = move_step(c[P_REF], c[V_REF], c[GOAL], c[CRUISE], c[P_ACC], c[P_DEC], dt,
                                      c[ARRIVAL_WINDOW], BEFORE_STEP)
            c[P_REF] = p
            c[V_REF] = v
            c[MOVING] = 0.0 if arrived else 1.0
        err = c[P_REF] - q
        if abs(err) > c[FOLLOW_LIMIT]:
            raise_fault(d, c, POSITION_FOLLOWING_ERROR)
            return _off(d, c, dt)
        v_cmd = c[KFP] * c[V_REF] + c[KPP] * err
        i = _speed_loop(d, c, v_cmd, c[KFV] * c[KFP] * (c[V_REF] - v_prev) / dt, dt)
    elif mode == TORQUE:
        i = _torque(d, c, dt)
    else:  # control mode 0 "undefined": energised, no command
        i = 0.0
    c[I_OUT] = i
    if not _protect(d, c, dt, i):
        return _off(d, c, dt)
    out: float = i * c[KT]
    return out


#: the helpers the firmware object calls, as Python (rows that are lists)
PY_OPS = SimpleNamespace(reset_loops=reset_loops, begin_quick_stop=begin_quick_stop, quick_stop=quick_stop,
                         tick=tick, step=step, set_velocity_target=set_velocity_target,
                         frame=frame)
def compiled_ops() -> Any:
    """The same helpers compiled (rows of a numpy table), or :data:`PY_OPS` without numba."""
    return kernel.compiled_ops(PY_OPS)


def warm() -> None:
    """Compile (or load from the disk cache) every compiled helper now, on scratch rows (see
    :func:`joints.sim.erob_kernel.warm`)."""
    ops = compiled_ops()
    if ops is PY_OPS:
        return
    import numpy as np

    t = np.ones((3, WIDTH))  # no zero a loop divides by
    t[0, D_RAMP_REF] = math.nan
    t[0, D_STATE] = DISABLED
    ops.reset_loops(t[1])
    ops.set_velocity_target(t[0], t[1], 1.0)
    ops.frame(t[0])
    ops.begin_quick_stop(t[0], t[1], 5.0, False)
    ops.quick_stop(t, 0)
    ops.tick(t, 0, 0.001)
    ops.step(t, 0, 0, 0.001, 0.0, 0.0, 0.0)  # dt 0: the motors-off path
