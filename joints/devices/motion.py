"""The motion-profile generator every twin uses (and a driver may plan with): linear speed ramps
and the discrete-time trapezoidal move.

Rule: pure math on floats in any consistent unit (counts and count/s, or rad and rad/s); no
state, no clock - the caller owns position, speed and time and calls one step per control
period ``dt``. Every function returns new values and changes nothing.

* :func:`ramp` - the speed command one period later on a linear ramp towards ``target``: the
  acceleration applies while the speed magnitude grows in the same direction (or from
  standstill), the deceleration otherwise. On a reversal the speed either goes straight through
  zero within the period (``pause_at_zero=False``, the eRob twin) or stops at zero for the rest
  of the period and accelerates from there on the next one (``pause_at_zero=True``, the ZLAC
  twin, whose ramp times are "to standstill, then to the target").
* :func:`move_step` - one period of a point-to-point move: the fastest speed from which the
  deceleration can still stop at the goal *in this discrete step*,
  ``v_new^2 = 2*dec*(|s| - (v + v_new)/2*dt)`` (the continuous ``sqrt(2*dec*|s|)`` runs ahead of
  the curve and ends the move early with a speed jump), capped at the cruise speed and reached
  with the acceleration / deceleration; positions integrate trapezoidally. When the move arrives
  the generator snaps to the goal at rest. A goal that moved closer than the stopping distance
  (a new target while moving) is never "arrived at" at speed: the move decelerates past it and
  comes back, so the speed changes by at most one slope step per period (plus the final snap
  from a speed one period could stop) whatever the goal does - a drive's speed supervision never
  sees a jump its own profile made. Two arrival rules exist because the two twins were calibrated
  with them (kept so their trajectories stay identical; a move from rest arrives as before):

  - :attr:`Arrival.ON_STEP` (eRob): after stepping, the step would reach or pass the goal, or the
    goal is closer than ``window``, and the new speed could stop within one period;
  - :attr:`Arrival.BEFORE_STEP` (ZLAC): before stepping, the goal is closer than ``window`` and
    the present speed could stop within one period; after stepping, the step reaches the goal
    without reversing at a speed that could stop within one period.
"""

from __future__ import annotations

import enum
from math import copysign, sqrt

__all__ = ["Arrival", "move_step", "ramp"]


class Arrival(enum.Enum):
    """When a point-to-point move counts as arrived (see the module docstring)."""

    ON_STEP = "on step"
    BEFORE_STEP = "before step"


def ramp(v: float, target: float, acc: float, dec: float, dt: float, pause_at_zero: bool = False) -> float:
    """The speed one period ``dt`` later, ramping from ``v`` towards ``target``.

    ``acc`` / ``dec`` are slopes (speed per second, > 0; ``math.inf`` = a step); the target is reached
    exactly, never overshot.
    """
    if v == target:
        return target
    if v == 0.0 or (target * v > 0.0 and abs(target) >= abs(v)):  # speeding up (or holding)
        step = acc * dt
        return target if abs(target - v) <= step else v + copysign(step, target - v)
    step = dec * dt
    if pause_at_zero:
        floor = target if target * v > 0.0 else 0.0
        return floor if abs(v - floor) <= step else v - copysign(step, v)
    return target if abs(target - v) <= step else v + copysign(step, target - v)


def move_step(p: float, v: float, goal: float, cruise: float, acc: float, dec: float, dt: float,
              window: float, arrival: Arrival) -> tuple[float, float, bool]:
    """One period of a trapezoidal move from ``p`` at speed ``v`` to ``goal``.

    ``cruise`` is the speed limit (magnitude), ``acc`` / ``dec`` the slopes, ``window`` the
    arrival distance of ``arrival``. Returns ``(position, speed, arrived)``; once arrived, the
    position is ``goal`` and the speed 0.
    """
    s = goal - p
    dist = abs(s)
    h = dec * dt  # the speed one period of deceleration removes
    before = arrival is _BEFORE_STEP
    if before and dist < window and abs(v) <= h:
        return goal, 0.0, True
    if s > 0:
        direction = 1.0
        v_here = v if v > 0 else 0.0  # speed towards the goal
    else:
        direction = -1.0
        v_here = -v if v < 0 else 0.0
    # fastest speed from which the deceleration still stops at the goal in discrete steps
    disc = h * h + 4.0 * (2.0 * dec * dist - h * v_here)
    v_allow = 0.5 * (sqrt(disc) - h) if disc > 0.0 else 0.0
    speed = min(cruise, v_allow)
    v_des = speed if direction > 0 else -speed
    dv = v_des - v
    step = acc * dt if abs(speed) > abs(v) and v * v_des >= 0.0 else h  # speeding up: the acceleration
    new_v = v_des if abs(dv) <= step else v + copysign(step, dv)
    ds = 0.5 * (v + new_v) * dt
    # a step that reaches the goal arrives only at a speed one period can stop; faster (the goal
    # moved closer than the stopping distance) the setpoint runs past it, decelerating, and
    # comes back: a new goal never makes the setpoint speed jump
    stoppable = abs(new_v) <= h
    if before:
        if abs(ds) >= dist and new_v * direction >= 0.0 and stoppable:
            return goal, 0.0, True
    elif (abs(ds) >= dist or dist < window) and stoppable:
        return goal, 0.0, True
    return p + ds, new_v, False


_BEFORE_STEP = Arrival.BEFORE_STEP
