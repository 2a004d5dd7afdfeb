"""The ZLAC8015D control-word state machine (joints.devices.zlac.state), per the manual's lines 852-868."""

from __future__ import annotations

import pytest

from joints.devices.zlac.registers import ControlWord
from joints.devices.zlac.state import ENERGISED, TRANSITIONS, DriveState, Event, command, step

S, W = DriveState, ControlWord
STARTS = (W.START_SYNC, W.START_LEFT, W.START_RIGHT)


def test_control_word_values_are_the_manuals() -> None:
    assert {int(w) for w in ControlWord} == {0x05, 0x06, 0x07, 0x08, 0x10, 0x11, 0x12}
    assert command(0x08) is W.ENABLE and command(0x10) is W.START_SYNC
    assert command(0x09) is None and command(0) is None  # in the register's range, not a command


def test_table_only_names_states_words_and_events() -> None:
    for (state, trigger), new in TRANSITIONS.items():
        assert isinstance(state, DriveState) and isinstance(trigger, (ControlWord, Event))
        assert isinstance(new, DriveState)


@pytest.mark.parametrize("state", [S.DISABLED, S.ENABLED, S.QUICK_STOP])
def test_enable_and_stop_outside_fault(state: DriveState) -> None:
    assert step(state, W.ENABLE) is S.ENABLED
    assert step(state, W.STOP) is S.DISABLED


def test_fault_ignores_enable_and_stop_until_clear_faults() -> None:
    assert step(S.FAULT, W.ENABLE) is None and step(S.FAULT, W.STOP) is None
    assert step(S.FAULT, W.CLEAR_FAULT) is S.DISABLED


@pytest.mark.parametrize("state", list(DriveState))
def test_quick_stop_only_while_enabled(state: DriveState) -> None:
    assert step(state, W.QUICK_STOP) == (S.QUICK_STOP if state is S.ENABLED else None)


@pytest.mark.parametrize("state", list(DriveState))
def test_starts_only_while_enabled(state: DriveState) -> None:
    for word in STARTS:
        assert step(state, word) == (S.ENABLED if state is S.ENABLED else None)


@pytest.mark.parametrize("state", list(DriveState))
def test_clear_faults_is_accepted_everywhere_and_any_fault_wins(state: DriveState) -> None:
    assert step(state, W.CLEAR_FAULT) == (S.DISABLED if state is S.FAULT else state)
    assert step(state, Event.FAULT) is S.FAULT


@pytest.mark.parametrize("state", list(DriveState))
def test_offline_watchdog_quick_stops_only_an_enabled_drive(state: DriveState) -> None:
    assert step(state, Event.OFFLINE) == (S.QUICK_STOP if state is S.ENABLED else None)


def test_energised_states() -> None:
    assert frozenset({S.ENABLED, S.QUICK_STOP}) == ENERGISED
