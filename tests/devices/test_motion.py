"""The one motion-profile generator (joints.devices.motion): ramps and trapezoidal moves."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from joints.devices.motion import Arrival, move_step, ramp

DT = 1e-3


def run_ramp(v: float, target: float, acc: float, dec: float, *, pause: bool = False,
             steps: int = 100000) -> list[float]:
    out = [v]
    for _ in range(steps):
        v = ramp(v, target, acc, dec, DT, pause_at_zero=pause)
        out.append(v)
        if v == target:
            break
    return out


def run_move(goal: float, cruise: float, acc: float, dec: float, arrival: Arrival, *, p: float = 0.0,
             v: float = 0.0, window: float = 1.0, steps: int = 100000) -> list[tuple[float, float]]:
    out = [(p, v)]
    for _ in range(steps):
        p, v, arrived = move_step(p, v, goal, cruise, acc, dec, DT, window, arrival)
        out.append((p, v))
        if arrived:
            return out
    raise AssertionError("the move never arrived")


# -------------------------------------------------------------------------------------- ramp


def test_ramp_up_takes_speed_over_acceleration() -> None:
    trace = run_ramp(0.0, 100.0, 1000.0, 50.0)
    assert trace[-1] == 100.0
    assert len(trace) - 1 == 100  # 100 / 1000 s in 1 ms periods
    assert all(b - a == pytest.approx(1.0) for a, b in itertools.pairwise(trace))


def test_ramp_down_uses_deceleration_and_never_overshoots() -> None:
    trace = run_ramp(100.0, 30.0, 1000.0, 20000.0)
    assert trace[1] == pytest.approx(80.0)  # 20000 * 1 ms
    assert trace[-1] == 30.0 and min(trace) == 30.0
    assert len(trace) - 1 == 4


def test_reversal_through_zero_or_pausing_at_zero() -> None:
    # 0.5 away from zero with a 2.0 deceleration step: straight through, or stop at 0 first
    assert ramp(0.5, -10.0, 1000.0, 2000.0, DT) == pytest.approx(-1.5)
    assert ramp(0.5, -10.0, 1000.0, 2000.0, DT, pause_at_zero=True) == 0.0
    # from standstill the acceleration applies
    assert ramp(0.0, -10.0, 1000.0, 2000.0, DT, pause_at_zero=True) == pytest.approx(-1.0)
    # a reversal decelerates (to zero) before it accelerates
    trace = run_ramp(5.0, -5.0, 1000.0, 5000.0, pause=True)
    assert trace[:3] == [5.0, 0.0, -1.0]


def test_infinite_slope_is_a_step_and_equal_target_holds() -> None:
    assert ramp(3.0, -7.0, math.inf, math.inf, DT) == -7.0
    assert ramp(-7.0, -7.0, 1.0, 1.0, DT) == -7.0
    assert ramp(0.0, 0.0, 1.0, 1.0, DT) == 0.0


@settings(max_examples=200, deadline=None)
@given(v=st.floats(-1e4, 1e4), target=st.floats(-1e4, 1e4), acc=st.floats(1.0, 1e7), dec=st.floats(1.0, 1e7),
       pause=st.booleans())
def test_ramp_moves_towards_target_by_at_most_one_slope_step(v: float, target: float, acc: float, dec: float,
                                                              pause: bool) -> None:
    new = ramp(v, target, acc, dec, DT, pause_at_zero=pause)
    assert abs(new - v) <= max(acc, dec) * DT * (1 + 1e-12) + 4 * math.ulp(max(abs(v), abs(new)))
    assert abs(target - new) <= abs(target - v) + 1e-9  # never further from the target
    if pause and v * target < 0:
        assert new * v >= 0  # does not cross zero in the period it reaches it


# ------------------------------------------------------------------------------------ move


@pytest.mark.parametrize("arrival", list(Arrival))
def test_trapezoid_timing_and_exact_arrival(arrival: Arrival) -> None:
    goal, cruise, acc, dec = 10000.0, 2000.0, 4000.0, 8000.0
    trace = run_move(goal, cruise, acc, dec, arrival)
    assert trace[-1] == (goal, 0.0)
    seconds = (len(trace) - 1) * DT
    ideal = goal / cruise + cruise / (2 * acc) + cruise / (2 * dec)  # 5.375 s
    assert seconds == pytest.approx(ideal, abs=3 * DT)
    speeds = [v for _, v in trace]
    assert max(speeds) == pytest.approx(cruise) and min(speeds) >= 0.0
    positions = [p for p, _ in trace]
    assert all(b >= a for a, b in itertools.pairwise(positions))  # never backwards, never past the goal
    assert max(positions) == goal


@pytest.mark.parametrize("arrival", list(Arrival))
def test_short_move_is_a_triangle(arrival: Arrival) -> None:
    goal, cruise, acc = -100.0, 1e6, 10000.0
    trace = run_move(goal, cruise, acc, acc, arrival)
    peak = max(abs(v) for _, v in trace)
    assert peak == pytest.approx(math.sqrt(acc * abs(goal)), rel=0.02)  # never reaches cruise
    assert (len(trace) - 1) * DT == pytest.approx(2 * math.sqrt(abs(goal) / acc), abs=3 * DT)
    assert trace[-1] == (goal, 0.0)


def test_move_started_in_the_wrong_direction_turns_back() -> None:
    trace = run_move(1000.0, 500.0, 2000.0, 2000.0, Arrival.ON_STEP, v=-400.0)
    assert min(p for p, _ in trace) < 0.0 < trace[-1][0] == 1000.0


def test_arrival_rules_differ_only_near_the_goal() -> None:
    # inside the window at a speed one period can stop: BEFORE_STEP snaps at once
    assert move_step(0.0, 0.5, 0.4, 10.0, 100.0, 1000.0, DT, 0.5, Arrival.BEFORE_STEP) == (0.4, 0.0, True)
    p, v, arrived = move_step(0.0, 0.5, 0.4, 10.0, 100.0, 1000.0, DT, 0.5, Arrival.ON_STEP)
    assert (p, v, arrived) == (0.4, 0.0, True)  # ON_STEP: the new speed can stop in the window too
    far = move_step(0.0, 0.0, 100.0, 10.0, 100.0, 1000.0, DT, 0.5, Arrival.BEFORE_STEP)
    assert far == move_step(0.0, 0.0, 100.0, 10.0, 100.0, 1000.0, DT, 0.5, Arrival.ON_STEP)
    assert not far[2] and far[1] == pytest.approx(0.1)


@settings(max_examples=60, deadline=None)
@given(goal=st.floats(-2000.0, 2000.0).filter(lambda g: abs(g) > 1.0), cruise=st.floats(100.0, 1e5),
       acc=st.floats(100.0, 1e6), dec=st.floats(100.0, 1e6), arrival=st.sampled_from(list(Arrival)))
def test_every_move_from_rest_arrives_without_overshoot(goal: float, cruise: float, acc: float, dec: float,
                                                        arrival: Arrival) -> None:
    trace = run_move(goal, cruise, acc, dec, arrival, steps=100_000)
    assert trace[-1] == (goal, 0.0)
    sign = 1.0 if goal > 0 else -1.0
    assert all(sign * p <= sign * goal + 1e-9 for p, _ in trace)
    assert all(abs(v) <= cruise * (1 + 1e-12) for _, v in trace)


def _assert_speed_steps(trace: list[tuple[float, float]], slope_step: float) -> None:
    """Speed changes by at most one slope step per period; the final snap to rest by at most two
    (the move arrives at a speed one more period could stop)."""
    steps = [abs(b[1] - a[1]) for a, b in itertools.pairwise(trace)]
    assert max(steps[:-1], default=0.0) <= slope_step * (1 + 1e-9)
    assert steps[-1] <= 2 * slope_step * (1 + 1e-9)


@pytest.mark.parametrize("arrival", list(Arrival))
@pytest.mark.parametrize("new_goal", [950.0, 900.0, 800.0, 700.0])
def test_goal_moved_inside_the_stopping_distance_overshoots_without_a_speed_jump(arrival: Arrival,
                                                                                 new_goal: float) -> None:
    """A new goal closer than the stopping distance (a target changed mid-move): the setpoint
    decelerates past it and comes back; its speed never changes by more than one slope step
    (it used to snap to the goal at rest: a jump of the whole cruise speed in one period)."""
    cruise, acc, dec = 2000.0, 4000.0, 4000.0  # stopping distance from cruise: 500
    p, v = 0.0, 0.0
    while p < 600.0:  # cruising towards 10000
        p, v, _ = move_step(p, v, 10000.0, cruise, acc, dec, DT, 1.0, arrival)
    assert v == pytest.approx(cruise)
    trace = run_move(new_goal, cruise, acc, dec, arrival, p=p, v=v)
    assert trace[-1] == (new_goal, 0.0)
    _assert_speed_steps(trace, dec * DT)
    stop_at = p + v * v / (2 * dec)
    assert max(q for q, _ in trace) == pytest.approx(stop_at, abs=cruise * DT)  # overshoot: where it could stop
    assert min(v for _, v in trace) < 0.0  # and back


@settings(max_examples=60, deadline=None)
@given(goal=st.floats(-5000.0, 5000.0), v0=st.floats(-3000.0, 3000.0), arrival=st.sampled_from(list(Arrival)))
def test_any_goal_from_any_speed_arrives_with_bounded_speed_steps(goal: float, v0: float, arrival: Arrival) -> None:
    cruise, acc, dec = 3000.0, 5000.0, 8000.0
    trace = run_move(goal, cruise, acc, dec, arrival, v=v0)
    assert trace[-1] == (goal, 0.0)
    _assert_speed_steps(trace, max(acc, dec) * DT)
