"""MKS SERVO42D/57D drive semantics shared by driver and twin: modes, codes, run state machine, laws.

Rule: pure data and pure functions (no clock, no I/O); the driver uses them to plan and check,
the twin to behave. Source: mks-servo42d-57d-rs485-manual-v1.0.5 (Part 1.4 and 3 #2 work modes,
5.1-5.4 value lists, 6.1 speed and acceleration, 6.2-6.9 run commands and their statuses).

The enums of status/result codes have the same names and values as the codec's
(:mod:`joints.codecs.mks`; the layers may not import each other, a test keeps them equal). They
are ``IntEnum`` so members of both compare equal to each other and to the wire value.

Conventions and choices (where the manual is silent or contradicts itself)
    * Sign: positive speed, encoder counts and axis values are CCW. 0x32 says "CCW: speed > 0",
      0x30 says one turn CCW adds 0x4000 to carry|value, 0x31's example says the same ("after one
      turn CCW, the value (+0x4000) is 0x7FF0"), and the run direction bit 0 (CCW) is the
      examples' "forward". Only the rule line of 0x31 (5.1 #2, repeated in 8.1 #2) says the
      opposite ("after one turn clockwise, the value += 0x4000") - not in ERRATA.md; check on
      hardware.
    * 0x86 ``motor_direction`` only applies to the pulse interface (3 #7 note); serial commands
      carry their own direction.
    * Microstep speed scaling (6.1, printed example): the speed value means rpm at 16, 32 and 64
      microsteps; at any other subdivision the real speed is ``speed * 16 / microsteps`` (8 -> x2,
      128 -> /8). Read literally the law jumps between 64 and 128; that is what the manual prints.
    * The mode's maximum speed (400/1500/3000 rpm) clamps the resulting motor speed.
    * Acceleration (6.1): the speed changes by 1 rpm every ``(256 - acc) * 50 us``; acc = 0 means
      no ramp (the set speed at once). acc = 236 gives 1000 rpm/s.
    * Run state machine: see :func:`step`. Stopping a motor at rest is accepted and completes at
      once; an emergency stop (0xF7) and a locked-rotor trip end a motion without a completion
      frame; a new run command while running replaces the running one without a completion for
      it (0xF5 "real-time update", 0xF6 speed change). The manual says none of this explicitly.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

__all__ = [
    "ANGLE_ERROR_PER_TURN",
    "ENCODER_COUNTS_PER_TURN",
    "FULL_STEPS_PER_TURN",
    "BaudRate",
    "CalibrationStatus",
    "EnActiveLevel",
    "GoBackToZeroStatus",
    "HomeMode",
    "HomeTrigger",
    "IoBit",
    "MotorDirection",
    "MotorStatus",
    "RunDirection",
    "RunEvent",
    "RunState",
    "RunStatus",
    "SetStatus",
    "SpeedModeParameter",
    "Transition",
    "WorkMode",
    "ZeroMode",
    "acc_for_rate",
    "step",
]

FULL_STEPS_PER_TURN = 200  #: 1.8 degree motors only
ENCODER_COUNTS_PER_TURN = 16384  #: 14-bit encoder; 0x30 value range 0..0x3FFF, 0x31 +0x4000 per turn
ANGLE_ERROR_PER_TURN = 51200  #: 0x39: 0..51200 = 0..360 degrees
SPEED_CALIBRATED_MICROSTEPS = (16, 32, 64)  #: 6.1: speed values are rpm at these subdivisions
MAX_SPEED_VALUE = 3000  #: 6.1: speed parameter range 0..3000
MAX_MICROSTEPS = 256


# --- modes and settings -----------------------------------------------------------------------


class WorkMode(enum.IntEnum):
    """0x82 work mode. CR_* = pulse interface (STP/DIR/EN), SR_* = serial interface."""

    CR_OPEN = 0
    CR_CLOSE = 1
    CR_vFOC = 2
    SR_OPEN = 3
    SR_CLOSE = 4
    SR_vFOC = 5

    @property
    def serial(self) -> bool:
        """Serial mode: Part 6 run commands work only here (6 note 1)."""
        return self >= WorkMode.SR_OPEN

    @property
    def closed_loop(self) -> bool:
        """CLOSE and vFOC use the encoder; OPEN runs without it (1.4 note 2)."""
        return self not in (WorkMode.CR_OPEN, WorkMode.SR_OPEN)

    @property
    def foc(self) -> bool:
        """vFOC: current adapts to the load up to Ma; OPEN/CLOSE drive a fixed Ma (1.4)."""
        return self in (WorkMode.CR_vFOC, WorkMode.SR_vFOC)

    @property
    def max_speed(self) -> int:
        """Maximum speed of the mode [rpm] (1.4, 6.1): OPEN 400, CLOSE 1500, vFOC 3000."""
        return _MAX_RPM[self % 3]


_MAX_RPM = (400, 1500, 3000)


class EnActiveLevel(enum.IntEnum):
    """0x85 active level of the En pin."""

    LOW = 0  #: "L" (default)
    HIGH = 1  #: "H"
    HOLD = 2  #: always enabled


class MotorDirection(enum.IntEnum):
    """0x86 Dir, 0x90 HmDir, 0x9A 0_Dir: 0 CW, 1 CCW."""

    CW = 0
    CCW = 1


class RunDirection(enum.IntEnum):
    """Direction bit of 0xF6/0xFD (and the Modbus dir field): 0 CCW ("forward"), 1 CW."""

    CCW = 0
    CW = 1


class BaudRate(enum.IntEnum):
    """0x8A baud rate codes."""

    B9600 = 1
    B19200 = 2
    B25000 = 3
    B38400 = 4  #: default
    B57600 = 5
    B115200 = 6
    B256000 = 7

    @property
    def bps(self) -> int:
        return int(self.name[1:])

    @classmethod
    def from_bps(cls, bps: int) -> BaudRate:
        try:
            return cls[f"B{bps}"]
        except KeyError:
            raise ValueError(f"no MKS baud rate code for {bps} bit/s (allowed: "
                             f"{', '.join(str(b.bps) for b in cls)})") from None


class HomeTrigger(enum.IntEnum):
    """0x90 HmTrig: effective level of the end stop."""

    LOW = 0
    HIGH = 1


class HomeMode(enum.IntEnum):
    """0x94 hm-Mode."""

    LIMITED = 0  #: go home on the limit switch (default)
    NO_LIMIT = 1  #: run with Hm_Ma until blocked, then back by the reverse angle
    SINGLE_LAP = 2  #: V1.0.9 "single lap to zero": to the 0x9A zero within one turn, the axis reset there


class ZeroMode(enum.IntEnum):
    """0x9A 0_Mode: return to zero at power-on."""

    DISABLE = 0
    DIR_MODE = 1  #: in the 0_Dir direction
    NEAR_MODE = 2  #: the shorter way


class SpeedModeParameter(enum.IntEnum):
    """0xFF state: save or clean the speed-mode parameters run at power-on."""

    SAVE = 0xC8
    CLEAN = 0xCA


class IoBit(enum.IntFlag):
    """0x34 IO status bits (IN_2, OUT_1, OUT_2 exist on the 57D only; 2.5)."""

    IN_1 = 0x01  #: home / left limit
    IN_2 = 0x02  #: right limit
    OUT_1 = 0x04  #: stall indication: 0 protected, 1 unprotected
    OUT_2 = 0x08  #: reserved


def holding_current_percent(hold: int) -> int:
    """0x9B code -> percent of the working current: 0 = 10 % ... 8 = 90 % (default 4 = 50 %)."""
    if not 0 <= hold <= 8:
        raise ValueError(f"holding current code must be 0..8, got {hold}")
    return 10 * (hold + 1)


# --- status and result codes (same names and values as joints.codecs.mks) -------------------


class SetStatus(enum.IntEnum):
    FAIL = 0
    SUCCESS = 1
    SUCCESS_UNSAVED = 2  #: 0x83 only (V1.0.7): "Set success without saved"


class RunStatus(enum.IntEnum):
    FAIL = 0
    STARTED = 1
    COMPLETE = 2
    END_LIMIT_STOP = 3
    SYNC_RECEIVED = 5  #: V1.0.8: held for the synchronous execution (0x4A on, 0x4B starts it)


class CalibrationStatus(enum.IntEnum):
    CALIBRATING = 0
    SUCCESS = 1
    FAIL = 2


class GoBackToZeroStatus(enum.IntEnum):
    GOING = 0
    SUCCESS = 1
    FAIL = 2


class MotorStatus(enum.IntEnum):
    """0xF1 (6 from Part 8 #10; 6.2 prints 5 twice, ERRATA DOC-MKS-3)."""

    FAIL = 0
    STOP = 1
    SPEED_UP = 2
    SPEED_DOWN = 3
    FULL_SPEED = 4
    HOMING = 5
    CALIBRATING = 6


def motor_status(current_rpm: float, target_rpm: float, *, homing: bool = False,
                 calibrating: bool = False) -> MotorStatus:
    """What 0xF1 reports for a ramp at ``current_rpm`` heading for ``target_rpm`` (magnitudes)."""
    if calibrating:
        return MotorStatus.CALIBRATING
    if homing:
        return MotorStatus.HOMING
    cur, tgt = abs(current_rpm), abs(target_rpm)
    if cur == 0 and tgt == 0:
        return MotorStatus.STOP
    if cur < tgt:
        return MotorStatus.SPEED_UP
    if cur > tgt:
        return MotorStatus.SPEED_DOWN
    return MotorStatus.FULL_SPEED


# --- run state machine ----------------------------------------------------------------------


class RunState(enum.Enum):
    """Where a drive's motion command stands (one per axis)."""

    IDLE = "idle"  #: nothing run since power-on
    RUNNING = "running"  #: a run command executes (ramping or cruising)
    STOPPING = "stopping"  #: a decelerating stop was accepted, still moving
    COMPLETE = "complete"  #: the motion ended by itself (target reached, home found)
    END_LIMIT_STOPPED = "end_limit_stopped"  #: an end-limit switch ended the motion
    STOPPED = "stopped"  #: a stop, emergency stop or protection ended the motion

    @property
    def moving(self) -> bool:
        return self in (RunState.RUNNING, RunState.STOPPING)


class RunEvent(enum.Enum):
    START = "start"  #: a run command (speed > 0) or go home was accepted
    REJECT = "reject"  #: a run or stop command was refused (status 0)
    STOP = "stop"  #: a decelerating stop (speed 0, acc > 0) was accepted
    STOP_NOW = "stop_now"  #: an immediate stop (speed 0, acc 0) was accepted
    EMERGENCY_STOP = "emergency_stop"  #: 0xF7 was accepted
    ARRIVED = "arrived"  #: the motion ended by itself: target reached, or a stop's ramp reached 0
    END_LIMIT = "end_limit"  #: an end-limit switch ended the motion
    PROTECTION = "protection"  #: the locked-rotor protection released the shaft


@dataclass(frozen=True, slots=True)
class Transition:
    """Result of :func:`step`."""

    state: RunState
    reply: RunStatus | None = None  #: status of the immediate reply (None: the event is no command)
    completion: RunStatus | None = None  #: a completion frame to send now (when "active" is on)


_REST = (RunState.IDLE, RunState.COMPLETE, RunState.END_LIMIT_STOPPED, RunState.STOPPED)


def _table() -> dict[tuple[RunState, RunEvent], Transition]:
    t: dict[tuple[RunState, RunEvent], Transition] = {}
    S, E, R = RunState, RunEvent, RunStatus
    for s in S:
        t[s, E.START] = Transition(S.RUNNING, R.STARTED)
        t[s, E.REJECT] = Transition(s, R.FAIL)
        t[s, E.STOP_NOW] = Transition(S.STOPPED, R.STARTED, R.COMPLETE)
        t[s, E.EMERGENCY_STOP] = Transition(S.STOPPED)
        t[s, E.PROTECTION] = Transition(S.STOPPED)
    for s in _REST:
        t[s, E.STOP] = Transition(S.STOPPED, R.STARTED, R.COMPLETE)
        t[s, E.ARRIVED] = Transition(s)
        t[s, E.END_LIMIT] = Transition(s)
    t[S.RUNNING, E.STOP] = Transition(S.STOPPING, R.STARTED)
    t[S.STOPPING, E.STOP] = Transition(S.STOPPING, R.STARTED)
    t[S.RUNNING, E.ARRIVED] = Transition(S.COMPLETE, None, R.COMPLETE)
    t[S.STOPPING, E.ARRIVED] = Transition(S.STOPPED, None, R.COMPLETE)
    for s in (S.RUNNING, S.STOPPING):
        t[s, E.END_LIMIT] = Transition(S.END_LIMIT_STOPPED, None, R.END_LIMIT_STOP)
    return t


#: (state, event) -> transition: the whole machine as data
TRANSITIONS: dict[tuple[RunState, RunEvent], Transition] = _table()


def step(state: RunState, event: RunEvent) -> Transition:
    """The run state machine: the next state, the reply status a command gets, a completion frame.

    The twin feeds it events from its motion (ARRIVED, END_LIMIT) and the commands it accepts or
    refuses; the driver feeds it the statuses it receives (:func:`event_from_status`).
    """
    return TRANSITIONS[state, event]


def event_from_status(status: RunStatus | int, *, stop: bool = False) -> RunEvent:
    """The event a received status means: 0 REJECT, 1 START (or STOP for a stop command), 2 ARRIVED, 3 END_LIMIT."""
    status = RunStatus(status)
    if status is RunStatus.FAIL:
        return RunEvent.REJECT
    if status is RunStatus.STARTED:
        return RunEvent.STOP if stop else RunEvent.START
    if status is RunStatus.COMPLETE:
        return RunEvent.ARRIVED
    return RunEvent.END_LIMIT


# --- speed, acceleration, microsteps --------------------------------------------------------

_US = 1e-6


def _check_acc(acc: int) -> int:
    if not 0 <= acc <= 255:
        raise ValueError(f"acc must be 0..255, got {acc}")
    return acc


def ramp_interval(acc: int) -> float:
    """Seconds per 1 rpm speed step: ``(256 - acc) * 50 us``; 0.0 for acc = 0 (no ramp)."""
    return 0.0 if _check_acc(acc) == 0 else (256 - acc) * 50 * _US


def acceleration(acc: int) -> float:
    """Acceleration [rpm/s] of ``acc`` (inf for acc = 0). acc = 236 -> 1000 rpm/s."""
    interval = ramp_interval(acc)
    return math.inf if interval == 0.0 else 1.0 / interval


def acc_for_rate(rate: float) -> int:
    """The acc (1..255) whose ramp comes closest to ``rate`` [speed units per second] (inverse of
    :func:`acceleration`); rates beyond acc = 255 (20000/s) give 255, below acc = 1 (78.4/s) give 1."""
    if not rate > 0:
        raise ValueError(f"acceleration rate must be > 0, got {rate}")
    return max(1, min(255, round(256 - 1.0 / (rate * 50 * _US))))


def ramp_time(from_rpm: float, to_rpm: float, acc: int) -> float:
    """Seconds the drive takes to change speed from ``from_rpm`` to ``to_rpm`` (1 rpm per step)."""
    return abs(to_rpm - from_rpm) * ramp_interval(acc)


def ramp_speed(current_rpm: int, target_rpm: int, acc: int, elapsed: float) -> int:
    """Speed [rpm] after ``elapsed`` seconds of ramping from ``current_rpm`` toward ``target_rpm``.

    Discrete like the drive: one 1-rpm step per completed interval (a tiny tolerance absorbs
    float rounding of ``elapsed``); acc = 0 jumps to the target.
    """
    interval = ramp_interval(acc)
    if interval == 0.0 or current_rpm == target_rpm:
        return target_rpm
    steps = math.floor(max(elapsed, 0.0) / interval + 1e-9)
    delta = target_rpm - current_rpm
    return target_rpm if steps >= abs(delta) else current_rpm + (steps if delta > 0 else -steps)


def stopping_distance(rpm: float, acc: int) -> float:
    """Turns travelled while ramping from ``rpm`` to 0 (continuous approximation; 0 for acc = 0)."""
    interval = ramp_interval(acc)
    return abs(rpm) * abs(rpm) * interval / 120.0  # v^2 / (2a), rpm -> rev/s


def effective_rpm(speed: int, microsteps: int) -> float:
    """Motor speed [rpm] a speed value gives at a subdivision (6.1 scaling, before the mode clamp)."""
    if not 1 <= microsteps <= MAX_MICROSTEPS:
        raise ValueError(f"microsteps must be 1..256, got {microsteps}")
    if microsteps in SPEED_CALIBRATED_MICROSTEPS:
        return float(speed)
    return speed * 16.0 / microsteps


def speed_value(rpm: float, microsteps: int) -> int:
    """The speed value to send for ``rpm`` at a subdivision (inverse of :func:`effective_rpm`, rounded)."""
    scale = effective_rpm(1, microsteps)
    return round(abs(rpm) / scale)


def motor_rpm(speed: int, microsteps: int, mode: WorkMode) -> float:
    """The speed the motor runs at: 6.1 scaling, clamped to the work mode's maximum."""
    return min(effective_rpm(speed, microsteps), float(WorkMode(mode).max_speed))


def pulses_per_turn(microsteps: int) -> int:
    """Pulses (microsteps) per motor turn: 200 x microsteps."""
    if not 1 <= microsteps <= MAX_MICROSTEPS:
        raise ValueError(f"microsteps must be 1..256, got {microsteps}")
    return FULL_STEPS_PER_TURN * microsteps


def angle_error_degrees(error: int) -> float:
    """0x39 value -> degrees (51200 per turn)."""
    return error * 360.0 / ANGLE_ERROR_PER_TURN
