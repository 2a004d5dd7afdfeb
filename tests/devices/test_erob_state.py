"""The eRob drive state machine (joints.devices.erob.state): table invariants and the walks a driver plans."""

from __future__ import annotations

import pytest

from joints.devices.erob.state import ENABLE_DELAY, ENABLED, TRANSITIONS, DriveState, Event, runs_motion, step

S, E = DriveState, Event
LATCHED = (S.REFUSED_OFF, S.REFUSED_ON, S.FAULT)  #: states with an error code


def walk(state: DriveState, *events: Event) -> DriveState:
    for event in events:
        new = step(state, event)
        assert new is not None, f"{event} refused in {state}"
        state = new
    return state


def test_table_only_names_states_and_events() -> None:
    for (state, event), new in TRANSITIONS.items():
        assert isinstance(state, DriveState) and isinstance(event, Event) and isinstance(new, DriveState)


def test_enable_then_brake_released_is_ready() -> None:
    assert ENABLE_DELAY == 0.5
    assert walk(S.MOTOR_OFF, E.ENABLE) is S.ENABLING
    assert walk(S.MOTOR_OFF, E.ENABLE, E.BRAKE_RELEASED) is S.READY
    assert walk(S.MOTOR_OFF, E.ENABLE, E.ENABLE) is S.ENABLING  # enable again: the timer keeps running
    assert step(S.MOTOR_OFF, E.BRAKE_RELEASED) is None and step(S.READY, E.BRAKE_RELEASED) is None


@pytest.mark.parametrize("state", list(DriveState))
def test_motion_runs_only_when_ready_and_latches_0x0027_elsewhere(state: DriveState) -> None:
    new = step(state, E.MOTION)
    assert new is not None
    if state is S.READY:
        assert runs_motion(state) and new is S.READY
    else:
        assert not runs_motion(state)
        assert new in LATCHED  # refused: the error is latched (or a fault already is)
        assert (new in ENABLED) == (state in ENABLED)  # refusing does not switch the motor


@pytest.mark.parametrize("state", list(DriveState))
def test_disable_always_switches_the_motor_off(state: DriveState) -> None:
    new = step(state, E.DISABLE)
    assert new is not None and new not in ENABLED
    assert (new in LATCHED) == (state in LATCHED)  # disabling clears no error


@pytest.mark.parametrize("state", list(DriveState))
def test_protections_trip_unless_an_error_is_latched_and_the_watchdog_always(state: DriveState) -> None:
    assert step(state, E.PROTECTION) == (None if state in LATCHED else S.FAULT)
    assert step(state, E.WATCHDOG) is S.FAULT


@pytest.mark.parametrize("state", list(DriveState))
def test_clear_errors_unlatches_and_keeps_the_motor(state: DriveState) -> None:
    new = step(state, E.CLEAR)
    assert new is not None and new not in LATCHED
    if state is S.FAULT:
        assert new is S.MOTOR_OFF  # a fault switched the motor off
    else:
        assert (new in ENABLED) == (state in ENABLED)


def test_a_faulted_drive_refuses_enable_until_cleared() -> None:
    assert step(S.FAULT, E.ENABLE) is None
    assert walk(S.FAULT, E.CLEAR, E.ENABLE, E.BRAKE_RELEASED) is S.READY


def test_start_while_enabling_holds_until_clear_errors() -> None:
    state = walk(S.MOTOR_OFF, E.ENABLE, E.MOTION)
    assert state is S.REFUSED_ON
    assert step(state, E.BRAKE_RELEASED) is None  # stays refused when the brake is released
    assert walk(state, E.DISABLE, E.ENABLE) is S.REFUSED_ON  # re-enabling does not clear 0x0027
    assert walk(state, E.CLEAR) is S.ENABLING


def test_enabled_states() -> None:
    assert frozenset({S.ENABLING, S.READY, S.REFUSED_ON}) == ENABLED
