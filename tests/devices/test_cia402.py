"""CiA 402 state machine: statusword coding, controlword commands, every transition, planning.

Cross-checked against the ``canopen`` package's ``State402`` tables where it has them (an
independent transcription of the same standard).
"""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from joints.devices import cia402
from joints.devices.cia402 import AUTOMATIC, COMMAND_WORD, TRANSITIONS, Command, Mode, State
from joints.errors import CommandError, PeerProtocolError

S, C = State, Command

#: CiA 402-2 figure "state machine": every controlled transition with its number
EXPECTED: list[tuple[State, int, State, int]] = [
    (S.SWITCH_ON_DISABLED, 0x06, S.READY_TO_SWITCH_ON, 2),
    (S.READY_TO_SWITCH_ON, 0x07, S.SWITCHED_ON, 3),
    (S.SWITCHED_ON, 0x0F, S.OPERATION_ENABLED, 4),
    (S.OPERATION_ENABLED, 0x07, S.SWITCHED_ON, 5),
    (S.SWITCHED_ON, 0x06, S.READY_TO_SWITCH_ON, 6),
    (S.READY_TO_SWITCH_ON, 0x00, S.SWITCH_ON_DISABLED, 7),
    (S.READY_TO_SWITCH_ON, 0x02, S.SWITCH_ON_DISABLED, 7),
    (S.OPERATION_ENABLED, 0x06, S.READY_TO_SWITCH_ON, 8),
    (S.OPERATION_ENABLED, 0x00, S.SWITCH_ON_DISABLED, 9),
    (S.SWITCHED_ON, 0x00, S.SWITCH_ON_DISABLED, 10),
    (S.SWITCHED_ON, 0x02, S.SWITCH_ON_DISABLED, 10),
    (S.OPERATION_ENABLED, 0x02, S.QUICK_STOP_ACTIVE, 11),
    (S.QUICK_STOP_ACTIVE, 0x00, S.SWITCH_ON_DISABLED, 12),
    (S.FAULT, 0x80, S.SWITCH_ON_DISABLED, 15),
    (S.READY_TO_SWITCH_ON, 0x0F, S.OPERATION_ENABLED, 34),  # "switch on + enable operation", 3 then 4
]


# ---------------------------------------------------------------------------- statusword


@pytest.mark.parametrize("state", list(State))
def test_statusword_of_each_state_decodes_to_it(state: State) -> None:
    for flags in ({}, {"voltage_enabled": False, "remote": False},
                  {"warning": True, "target_reached": True, "internal_limit": True, "bit12": True, "bit13": True}):
        word = cia402.make_statusword(state, **flags)
        assert cia402.state_of(word) is state


@given(st.integers(0, 0xFFFF))
@settings(max_examples=500, deadline=None)
def test_state_coding_is_unambiguous(word: int) -> None:
    matches = [s for s, (mask, value) in cia402.STATUSWORD_PATTERN.items() if word & mask == value]
    assert len(matches) <= 1
    if matches:
        assert cia402.state_of(word) is matches[0]
    else:
        with pytest.raises(PeerProtocolError):
            cia402.state_of(word)


def test_typical_statuswords() -> None:
    assert cia402.state_of(0x0250) is S.SWITCH_ON_DISABLED
    assert cia402.state_of(0x0231) is S.READY_TO_SWITCH_ON
    assert cia402.state_of(0x0233) is S.SWITCHED_ON
    assert cia402.state_of(0x1637) is S.OPERATION_ENABLED
    assert cia402.state_of(0x0217) is S.QUICK_STOP_ACTIVE
    assert cia402.state_of(0x0218) is S.FAULT
    assert cia402.make_statusword(S.OPERATION_ENABLED, target_reached=True) == 0x0637
    assert cia402.target_reached(0x0637) and not cia402.setpoint_acknowledged(0x0637)
    assert cia402.setpoint_acknowledged(0x1237) and cia402.following_error(0x2237)
    assert cia402.is_fault(0x0218) and cia402.has_warning(0x02B7) and cia402.internal_limit_active(0x0A37)


# ---------------------------------------------------------------------------- controlword


def test_command_words_decode_to_their_command() -> None:
    for command, word in COMMAND_WORD.items():
        expected = C.SWITCH_ON if command is C.DISABLE_OPERATION else command
        assert cia402.command_of(word) is expected
        mask, value = cia402.COMMAND_PATTERN[command]
        assert word & mask == value


@given(st.integers(0, 0xFFFF))
@settings(max_examples=500, deadline=None)
def test_every_controlword_without_bit7_is_exactly_one_command(word: int) -> None:
    word &= ~cia402.CW_FAULT_RESET
    command = cia402.command_of(word)
    assert command is not None
    matching = {c for c, (mask, value) in cia402.COMMAND_PATTERN.items()
                if c is not C.FAULT_RESET and word & mask == value}
    assert command in matching
    assert matching <= {command, C.DISABLE_OPERATION, C.SWITCH_ON}


def test_erunner_words() -> None:
    """eRunner chapter 5: 0x06 disable (fig 5-9), 0x1F PP move (fig 5-6), 0x2F other modes (figs 5-15.., 5-28)."""
    assert cia402.command_of(0x0006) is C.SHUTDOWN
    assert cia402.command_of(0x001F) is C.ENABLE_OPERATION
    assert cia402.command_of(0x002F) is C.ENABLE_OPERATION
    assert 0x001F & cia402.CW_NEW_SETPOINT and not 0x001F & cia402.CW_CHANGE_SET_IMMEDIATELY
    assert 0x002F & cia402.CW_CHANGE_SET_IMMEDIATELY
    assert cia402.next_state(S.OPERATION_ENABLED, 0x001F) is S.OPERATION_ENABLED
    assert cia402.next_state(S.OPERATION_ENABLED, 0x0006) is S.READY_TO_SWITCH_ON


def test_fault_reset_acts_on_the_rising_edge_only() -> None:
    assert cia402.command_of(0x80, previous=0x00) is C.FAULT_RESET
    assert cia402.command_of(0x80, previous=0x80) is None
    assert cia402.command_of(0x86, previous=0x80) is None  # bit 7 held: nothing else is decoded
    assert cia402.next_state(S.FAULT, 0x80, previous=0x80) is S.FAULT
    assert cia402.next_state(S.FAULT, 0x80, previous=0x06) is S.SWITCH_ON_DISABLED
    for state in State:
        if state is not S.FAULT:
            assert cia402.next_state(state, 0x80) is state


# ---------------------------------------------------------------------------- transitions


@pytest.mark.parametrize("start,word,end,number", EXPECTED)
def test_every_controlled_transition(start: State, word: int, end: State, number: int) -> None:
    assert cia402.next_state(start, word) is end
    command = cia402.command_of(word)
    assert command is not None
    if start is S.OPERATION_ENABLED and command is C.SWITCH_ON:
        command = C.DISABLE_OPERATION
    assert TRANSITIONS[(start, command)] == (end, number)
    # mode-specific bits (4..6, 8, 9) do not change the transition
    assert cia402.next_state(start, word | 0x0370 if not word & 0x80 else word) is end


def test_transition_table_is_exactly_the_expected_one_plus_16() -> None:
    listed = {(s, n) for s, _w, _e, n in EXPECTED}
    assert {(s, n) for (s, _c), (_e, n) in TRANSITIONS.items()} == listed | {(S.QUICK_STOP_ACTIVE, 16)}


def test_transition_16_depends_on_the_quick_stop_option_code() -> None:
    assert cia402.next_state(S.QUICK_STOP_ACTIVE, 0x0F) is S.QUICK_STOP_ACTIVE  # default 2
    for code in (5, 6, 7, 8):
        assert cia402.next_state(S.QUICK_STOP_ACTIVE, 0x0F, quick_stop_option_code=code) is S.OPERATION_ENABLED
    assert cia402.settle(S.QUICK_STOP_ACTIVE) is S.SWITCH_ON_DISABLED
    assert cia402.settle(S.QUICK_STOP_ACTIVE, quick_stop_option_code=6) is S.QUICK_STOP_ACTIVE


@pytest.mark.parametrize("state", list(State))
@pytest.mark.parametrize("command", list(Command))
def test_commands_outside_the_table_change_nothing(state: State, command: Command) -> None:
    word = COMMAND_WORD[command]
    expected = {(s, w): e for s, w, e, _n in EXPECTED}
    assert cia402.next_state(state, word) is expected.get((state, word), state)


def test_automatic_transitions_and_faults() -> None:
    assert AUTOMATIC[S.NOT_READY_TO_SWITCH_ON] == (S.SWITCH_ON_DISABLED, 1)
    assert AUTOMATIC[S.FAULT_REACTION_ACTIVE] == (S.FAULT, 14)
    assert cia402.settle(S.NOT_READY_TO_SWITCH_ON) is S.SWITCH_ON_DISABLED
    assert cia402.settle(S.FAULT_REACTION_ACTIVE) is S.FAULT
    assert cia402.settle(S.OPERATION_ENABLED) is S.OPERATION_ENABLED
    for state in State:
        assert cia402.on_fault(state) is (S.FAULT if state is S.FAULT else S.FAULT_REACTION_ACTIVE)


# ---------------------------------------------------------------------------- path


def _walk(start: State, words: list[int], code: int) -> State:
    state = cia402.settle(start, quick_stop_option_code=code) if start in (
        S.NOT_READY_TO_SWITCH_ON, S.FAULT_REACTION_ACTIVE) else start
    previous = 0
    for word in words:
        state = cia402.next_state(state, word, previous, quick_stop_option_code=code)
        previous = word
    return state


@pytest.mark.parametrize("code", [2, 6])
@pytest.mark.parametrize("start", list(State))
@pytest.mark.parametrize("goal", [s for s in State if s in cia402.COMMANDABLE])
def test_path_reaches_every_commandable_state_from_every_state(start: State, goal: State, code: int) -> None:
    words = cia402.path(start, goal, quick_stop_option_code=code)
    assert _walk(start, words, code) is goal
    assert len(words) <= 5
    # never the 3+4 shortcut: a host always passes SWITCHED ON
    state = start
    for word in words:
        assert not (state is S.READY_TO_SWITCH_ON and word == 0x0F)
        state = cia402.next_state(cia402.settle(state) if state in (S.NOT_READY_TO_SWITCH_ON,
                                                                    S.FAULT_REACTION_ACTIVE) else state,
                                  word, quick_stop_option_code=code)


def test_known_paths() -> None:
    assert cia402.path(S.SWITCH_ON_DISABLED, S.OPERATION_ENABLED) == [0x06, 0x07, 0x0F]
    assert cia402.path(S.FAULT, S.OPERATION_ENABLED) == [0x80, 0x06, 0x07, 0x0F]
    assert cia402.path(S.OPERATION_ENABLED, S.READY_TO_SWITCH_ON) == [0x06]  # eRunner's "disable"
    assert cia402.path(S.OPERATION_ENABLED, S.SWITCH_ON_DISABLED) == [0x00]
    assert cia402.path(S.QUICK_STOP_ACTIVE, S.OPERATION_ENABLED) == [0x00, 0x06, 0x07, 0x0F]
    assert cia402.path(S.QUICK_STOP_ACTIVE, S.OPERATION_ENABLED, quick_stop_option_code=6) == [0x0F]
    assert cia402.path(S.SWITCH_ON_DISABLED, S.QUICK_STOP_ACTIVE) == [0x06, 0x07, 0x0F, 0x02]
    assert cia402.path(S.FAULT_REACTION_ACTIVE, S.SWITCH_ON_DISABLED) == [0x80]
    assert cia402.path(S.NOT_READY_TO_SWITCH_ON, S.SWITCH_ON_DISABLED) == []
    assert cia402.path(S.FAULT, S.FAULT) == []


@pytest.mark.parametrize("goal", [S.FAULT, S.FAULT_REACTION_ACTIVE, S.NOT_READY_TO_SWITCH_ON])
def test_path_refuses_states_only_the_drive_enters(goal: State) -> None:
    with pytest.raises(CommandError, match="cannot be entered"):
        cia402.path(S.OPERATION_ENABLED, goal)


# ---------------------------------------------------------------------------- modes


def test_modes() -> None:
    assert [int(m) for m in (Mode.PP, Mode.PV, Mode.PT, Mode.HM, Mode.IP, Mode.CSP, Mode.CSV, Mode.CST)] == [
        1, 3, 4, 6, 7, 8, 9, 10]
    assert {m for m in Mode if m.cyclic} == {Mode.CSP, Mode.CSV, Mode.CST, Mode.IP}
    every = [m for m in Mode if m is not Mode.NO_MODE]
    assert cia402.modes_from_bits(cia402.supported_modes_bits(every)) == frozenset(every)
    assert cia402.supported_modes_bits([Mode.PP, Mode.CSP]) == 0x81
    assert cia402.supported_modes_bits([Mode.NO_MODE]) == 0


# ---------------------------------------------------------------------------- canopen's State402


@pytest.fixture(scope="module")
def p402() -> Any:
    return pytest.importorskip("canopen.profiles.p402")


def test_their_statusword_masks_are_ours(p402: Any) -> None:
    theirs = p402.State402.SW_MASK
    assert {State(name): pattern for name, pattern in theirs.items()} == dict(cia402.STATUSWORD_PATTERN)


def test_their_transition_table_agrees_with_ours(p402: Any) -> None:
    for (start, end), word in p402.State402.TRANSITIONTABLE.items():
        if start == "START":
            continue
        if State(start) in AUTOMATIC and word == 0 and State(start) is not S.QUICK_STOP_ACTIVE:
            assert AUTOMATIC[State(start)][0] is State(end)  # transitions 1 and 14: the drive's own
            continue
        code = 6 if (start, end) == ("QUICK STOP ACTIVE", "OPERATION ENABLED") else 2  # their 16 assumes 5..8
        assert cia402.next_state(State(start), word, quick_stop_option_code=code) is State(end), (start, end)


def test_their_way_to_operation_enabled_works_on_our_drive(p402: Any) -> None:
    """BaseNode402's planner (direct transition, else next_state_indirect) walked over our next_state."""
    table, indirect = p402.State402.TRANSITIONTABLE, p402.State402.next_state_indirect
    for start in State:
        state = cia402.settle(start)
        for _ in range(6):
            if state is S.OPERATION_ENABLED:
                break
            target = "OPERATION ENABLED" if (state.value, "OPERATION ENABLED") in table else indirect(state.value)
            state = cia402.next_state(state, table[(state.value, target)])
        assert state is S.OPERATION_ENABLED, start


def test_their_operation_modes_are_ours(p402: Any) -> None:
    om = p402.OperationMode
    for mode in Mode:
        assert om.CODE2NAME[int(mode)]  # every code of ours is known to them
        if mode is not Mode.NO_MODE:
            assert om.SUPPORTED[om.CODE2NAME[int(mode)]] == 1 << cia402.SUPPORTED_MODE_BIT[mode]
