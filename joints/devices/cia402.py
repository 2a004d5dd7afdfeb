"""CiA 402 drive profile: the power state machine, controlword and statusword, modes of operation.

Rule: pure data + pure functions, shared by the host driver (to plan: :func:`path`) and the twin
(to enforce: :func:`next_state`). No protocol, no clock.

Source: CiA 402-2 (v4), sections "Device control" (state machine figure, transitions 0-16,
controlword command table, statusword state table) and "Modes of operation" (0x6060/0x6061,
0x6502 bit positions, mode-specific controlword/statusword bits). The eRunner manual chapter 5
uses the same words: RPDO1 controlword 0x0006 "disable" (fig 5-9: shutdown, OPERATION ENABLED ->
READY TO SWITCH ON), 0x001F "move" in PP (enable operation + new set-point, fig 5-6), 0x002F in
PV/PT/CSP/CSV/CST (enable operation + bit 5, figs 5-15, 5-19, 5-24, 5-28).

Choices where the standard leaves room (assumptions to confirm on a real eRob):

* S1 Fault reset acts on the rising edge of controlword bit 7 (pass ``previous``). While bit 7 is
  set, no other command is decoded (:func:`command_of` returns None unless it is an edge).
* S2 "Switch on + enable operation" (0x000F in READY TO SWITCH ON, transitions 3+4) is accepted by
  :func:`next_state` as CiA 402-2 allows, but :func:`path` never relies on it: a host always goes
  through SWITCHED ON (0x0006, 0x0007, 0x000F), which every drive implements.
* S3 Quick stop option code 0x605A defaults to 2 (CiA 402 default: stop on the quick-stop ramp,
  then SWITCH ON DISABLED). With codes 5..8 the drive stays in QUICK STOP ACTIVE and transition 16
  (enable operation) is allowed; with 0..4 the drive leaves it by itself (:func:`settle`).
* S4 Transitions 0, 1 (self-test done), 12 (quick stop done, codes 0..4) and 14 (fault reaction
  done) are automatic: the drive takes them by itself (:func:`settle`); 13 is the fault event
  (:func:`on_fault`). A controlword that names no transition of the current state changes nothing.
"""

from __future__ import annotations

import enum
from collections import deque
from collections.abc import Iterable, Mapping

from joints.errors import CommandError, PeerProtocolError

__all__ = [
    "AUTOMATIC",
    "COMMAND_WORD",
    "TRANSITIONS",
    "Command",
    "Mode",
    "State",
    "command_of",
    "make_statusword",
    "modes_from_bits",
    "next_state",
    "on_fault",
    "path",
    "settle",
    "state_of",
    "supported_modes_bits",
]


class State(enum.Enum):
    """States of the CiA 402 power state machine."""

    NOT_READY_TO_SWITCH_ON = "NOT READY TO SWITCH ON"
    SWITCH_ON_DISABLED = "SWITCH ON DISABLED"
    READY_TO_SWITCH_ON = "READY TO SWITCH ON"
    SWITCHED_ON = "SWITCHED ON"
    OPERATION_ENABLED = "OPERATION ENABLED"
    QUICK_STOP_ACTIVE = "QUICK STOP ACTIVE"
    FAULT_REACTION_ACTIVE = "FAULT REACTION ACTIVE"
    FAULT = "FAULT"


# --- statusword (0x6041) --------------------------------------------------------------------------

SW_READY_TO_SWITCH_ON = 1 << 0
SW_SWITCHED_ON = 1 << 1
SW_OPERATION_ENABLED = 1 << 2
SW_FAULT = 1 << 3
SW_VOLTAGE_ENABLED = 1 << 4
SW_QUICK_STOP = 1 << 5  #: 0 = quick stop is being executed
SW_SWITCH_ON_DISABLED = 1 << 6
SW_WARNING = 1 << 7
SW_REMOTE = 1 << 9  #: controlword is processed
SW_TARGET_REACHED = 1 << 10
SW_INTERNAL_LIMIT = 1 << 11
# bits 12 and 13 depend on the mode of operation
SW_SETPOINT_ACKNOWLEDGE = 1 << 12  #: PP: the new set-point was taken
SW_SPEED_ZERO = 1 << 12  #: PV: speed is 0
SW_IP_ACTIVE = 1 << 12  #: IP: interpolation active
SW_HOMING_ATTAINED = 1 << 12  #: HM
SW_TARGET_FOLLOWED = 1 << 12  #: CSP/CSV/CST: the drive follows the target value
SW_FOLLOWING_ERROR = 1 << 13  #: PP/CSP
SW_MAX_SLIPPAGE = 1 << 13  #: PV
SW_HOMING_ERROR = 1 << 13  #: HM

#: state -> (mask, value) of the statusword (CiA 402-2 table "state coding")
STATUSWORD_PATTERN: Mapping[State, tuple[int, int]] = {
    State.NOT_READY_TO_SWITCH_ON: (0x4F, 0x00),
    State.SWITCH_ON_DISABLED: (0x4F, 0x40),
    State.READY_TO_SWITCH_ON: (0x6F, 0x21),
    State.SWITCHED_ON: (0x6F, 0x23),
    State.OPERATION_ENABLED: (0x6F, 0x27),
    State.QUICK_STOP_ACTIVE: (0x6F, 0x07),
    State.FAULT_REACTION_ACTIVE: (0x4F, 0x0F),
    State.FAULT: (0x4F, 0x08),
}


def state_of(statusword: int) -> State:
    """The state a statusword reports (:class:`~joints.errors.PeerProtocolError` if it codes none)."""
    for state, (mask, value) in STATUSWORD_PATTERN.items():
        if statusword & mask == value:
            return state
    raise PeerProtocolError(f"statusword 0x{statusword:04X} codes no CiA 402 state")


def make_statusword(state: State, *, voltage_enabled: bool = True, warning: bool = False, remote: bool = True,
                    target_reached: bool = False, internal_limit: bool = False, bit12: bool = False,
                    bit13: bool = False) -> int:
    """A statusword as a drive in ``state`` reports it (for the twin). Bit 5 (quick stop) is 1 except
    in QUICK STOP ACTIVE (and 0 in the states whose pattern leaves it free); bit 4 is reported only
    where the power stage can be on."""
    word = STATUSWORD_PATTERN[state][1]
    if voltage_enabled and state not in (State.NOT_READY_TO_SWITCH_ON, State.SWITCH_ON_DISABLED):
        word |= SW_VOLTAGE_ENABLED
    for flag, bit in ((warning, SW_WARNING), (remote, SW_REMOTE), (target_reached, SW_TARGET_REACHED),
                      (internal_limit, SW_INTERNAL_LIMIT), (bit12, 1 << 12), (bit13, 1 << 13)):
        if flag:
            word |= bit
    return word


def is_fault(statusword: int) -> bool:
    return bool(statusword & SW_FAULT)


def target_reached(statusword: int) -> bool:
    return bool(statusword & SW_TARGET_REACHED)


def setpoint_acknowledged(statusword: int) -> bool:
    """PP: bit 12, the drive took the new set-point (host then clears controlword bit 4)."""
    return bool(statusword & SW_SETPOINT_ACKNOWLEDGE)


def following_error(statusword: int) -> bool:
    """PP/CSP: bit 13."""
    return bool(statusword & SW_FOLLOWING_ERROR)


def has_warning(statusword: int) -> bool:
    return bool(statusword & SW_WARNING)


def internal_limit_active(statusword: int) -> bool:
    return bool(statusword & SW_INTERNAL_LIMIT)


# --- controlword (0x6040) --------------------------------------------------------------------------

CW_SWITCH_ON = 1 << 0
CW_ENABLE_VOLTAGE = 1 << 1
CW_QUICK_STOP = 1 << 2  #: 0 = execute quick stop
CW_ENABLE_OPERATION = 1 << 3
CW_FAULT_RESET = 1 << 7
CW_HALT = 1 << 8
# bits 4..6 and 9 depend on the mode of operation
CW_NEW_SETPOINT = 1 << 4  #: PP: rising edge = take the new target
CW_CHANGE_SET_IMMEDIATELY = 1 << 5  #: PP: 1 = abort the running move for the new one
CW_RELATIVE = 1 << 6  #: PP: 1 = target is relative
CW_CHANGE_ON_SETPOINT = 1 << 9  #: PP
CW_ENABLE_IP = 1 << 4  #: IP: enable interpolation
CW_HOMING_START = 1 << 4  #: HM


class Command(enum.Enum):
    """Device control commands (CiA 402-2 controlword command table)."""

    SHUTDOWN = "shutdown"
    SWITCH_ON = "switch on"  #: same bits as DISABLE_OPERATION (0x0007); the state tells them apart
    DISABLE_OPERATION = "disable operation"
    ENABLE_OPERATION = "enable operation"
    DISABLE_VOLTAGE = "disable voltage"
    QUICK_STOP = "quick stop"
    FAULT_RESET = "fault reset"


#: the word a host sends for each command (mode bits 4..6, 8, 9 zero)
COMMAND_WORD: Mapping[Command, int] = {
    Command.SHUTDOWN: 0x0006,
    Command.SWITCH_ON: 0x0007,
    Command.DISABLE_OPERATION: 0x0007,
    Command.ENABLE_OPERATION: 0x000F,
    Command.DISABLE_VOLTAGE: 0x0000,
    Command.QUICK_STOP: 0x0002,
    Command.FAULT_RESET: 0x0080,
}

#: command -> (mask, value) of its controlword bits (bits 7, 3, 2, 1, 0); fault reset is the 0->1 edge of bit 7
COMMAND_PATTERN: Mapping[Command, tuple[int, int]] = {
    Command.SHUTDOWN: (0x87, 0x06),
    Command.SWITCH_ON: (0x8F, 0x07),
    Command.DISABLE_OPERATION: (0x8F, 0x07),
    Command.ENABLE_OPERATION: (0x8F, 0x0F),
    Command.DISABLE_VOLTAGE: (0x82, 0x00),
    Command.QUICK_STOP: (0x86, 0x02),
    Command.FAULT_RESET: (0x80, 0x80),
}


def command_of(controlword: int, previous: int | None = None) -> Command | None:
    """The command a controlword carries. ``previous`` is the controlword before it (None: treat bit 7
    as an edge). 0x0007 decodes as SWITCH_ON (= DISABLE_OPERATION; :func:`next_state` knows both)."""
    if controlword & CW_FAULT_RESET:
        if previous is None or not previous & CW_FAULT_RESET:
            return Command.FAULT_RESET
        return None
    if not controlword & CW_ENABLE_VOLTAGE:
        return Command.DISABLE_VOLTAGE
    if not controlword & CW_QUICK_STOP:
        return Command.QUICK_STOP
    if not controlword & CW_SWITCH_ON:
        return Command.SHUTDOWN
    return Command.ENABLE_OPERATION if controlword & CW_ENABLE_OPERATION else Command.SWITCH_ON


_S = State
_C = Command

#: (state, command) -> (next state, CiA 402 transition number); what a drive does
TRANSITIONS: Mapping[tuple[State, Command], tuple[State, int]] = {
    (_S.SWITCH_ON_DISABLED, _C.SHUTDOWN): (_S.READY_TO_SWITCH_ON, 2),
    (_S.READY_TO_SWITCH_ON, _C.SWITCH_ON): (_S.SWITCHED_ON, 3),
    (_S.READY_TO_SWITCH_ON, _C.ENABLE_OPERATION): (_S.OPERATION_ENABLED, 34),  # 3 then 4 (S2)
    (_S.SWITCHED_ON, _C.ENABLE_OPERATION): (_S.OPERATION_ENABLED, 4),
    (_S.OPERATION_ENABLED, _C.DISABLE_OPERATION): (_S.SWITCHED_ON, 5),
    (_S.SWITCHED_ON, _C.SHUTDOWN): (_S.READY_TO_SWITCH_ON, 6),
    (_S.READY_TO_SWITCH_ON, _C.DISABLE_VOLTAGE): (_S.SWITCH_ON_DISABLED, 7),
    (_S.READY_TO_SWITCH_ON, _C.QUICK_STOP): (_S.SWITCH_ON_DISABLED, 7),
    (_S.OPERATION_ENABLED, _C.SHUTDOWN): (_S.READY_TO_SWITCH_ON, 8),
    (_S.OPERATION_ENABLED, _C.DISABLE_VOLTAGE): (_S.SWITCH_ON_DISABLED, 9),
    (_S.SWITCHED_ON, _C.DISABLE_VOLTAGE): (_S.SWITCH_ON_DISABLED, 10),
    (_S.SWITCHED_ON, _C.QUICK_STOP): (_S.SWITCH_ON_DISABLED, 10),
    (_S.OPERATION_ENABLED, _C.QUICK_STOP): (_S.QUICK_STOP_ACTIVE, 11),
    (_S.QUICK_STOP_ACTIVE, _C.DISABLE_VOLTAGE): (_S.SWITCH_ON_DISABLED, 12),
    (_S.FAULT, _C.FAULT_RESET): (_S.SWITCH_ON_DISABLED, 15),
    (_S.QUICK_STOP_ACTIVE, _C.ENABLE_OPERATION): (_S.OPERATION_ENABLED, 16),  # quick stop option code 5..8 only
}

#: transitions a drive takes by itself: 1 (self-test done), 14 (fault reaction done), 12 (quick stop done)
AUTOMATIC: Mapping[State, tuple[State, int]] = {
    _S.NOT_READY_TO_SWITCH_ON: (_S.SWITCH_ON_DISABLED, 1),
    _S.FAULT_REACTION_ACTIVE: (_S.FAULT, 14),
    _S.QUICK_STOP_ACTIVE: (_S.SWITCH_ON_DISABLED, 12),
}

DEFAULT_QUICK_STOP_OPTION_CODE = 2  #: object 0x605A, CiA 402 default


def _holds_quick_stop(quick_stop_option_code: int) -> bool:
    return 5 <= quick_stop_option_code <= 8


def next_state(state: State, controlword: int, previous: int | None = None, *,
               quick_stop_option_code: int = DEFAULT_QUICK_STOP_OPTION_CODE) -> State:
    """The state a drive in ``state`` enters on ``controlword`` (unchanged if it names no transition)."""
    command = command_of(controlword, previous)
    if command is None:
        return state
    if command is Command.SWITCH_ON and state is State.OPERATION_ENABLED:
        command = Command.DISABLE_OPERATION
    target = TRANSITIONS.get((state, command))
    if target is None:
        return state
    if target[1] == 16 and not _holds_quick_stop(quick_stop_option_code):
        return state
    return target[0]


def settle(state: State, *, quick_stop_option_code: int = DEFAULT_QUICK_STOP_OPTION_CODE) -> State:
    """The state a drive reaches by itself from ``state`` once its internal action is done
    (self-test, fault reaction, quick stop ramp); the same state where nothing is automatic."""
    if state is State.QUICK_STOP_ACTIVE and _holds_quick_stop(quick_stop_option_code):
        return state
    auto = AUTOMATIC.get(state)
    return state if auto is None else settle(auto[0], quick_stop_option_code=quick_stop_option_code)


def on_fault(state: State) -> State:
    """Transition 13: a fault occurs (FAULT stays FAULT)."""
    return state if state is State.FAULT else State.FAULT_REACTION_ACTIVE


#: states a host can command the drive into (the others are entered only by the drive itself)
COMMANDABLE: frozenset[State] = frozenset({
    State.SWITCH_ON_DISABLED, State.READY_TO_SWITCH_ON, State.SWITCHED_ON, State.OPERATION_ENABLED,
    State.QUICK_STOP_ACTIVE,
})

#: single-step host commands tried by :func:`path`, in preference order (never the 3+4 shortcut, S2)
_PLAN_COMMANDS = (Command.FAULT_RESET, Command.DISABLE_VOLTAGE, Command.SHUTDOWN, Command.SWITCH_ON,
                  Command.ENABLE_OPERATION, Command.QUICK_STOP)


def path(from_state: State, to_state: State, *,
         quick_stop_option_code: int = DEFAULT_QUICK_STOP_OPTION_CODE) -> list[int]:
    """The controlwords a host sends to bring a drive from ``from_state`` to ``to_state``.

    From NOT READY TO SWITCH ON or FAULT REACTION ACTIVE the host first waits for the drive's own
    transition (:func:`settle`); the words start from there. Shortest path through single CiA 402
    transitions; :class:`~joints.errors.CommandError` for a target no controlword reaches.
    """
    if from_state is to_state:
        return []
    if to_state not in COMMANDABLE:
        raise CommandError(f"CiA 402: {to_state.value} cannot be entered by a controlword")
    start = from_state
    if start in (State.NOT_READY_TO_SWITCH_ON, State.FAULT_REACTION_ACTIVE):
        start = settle(start, quick_stop_option_code=quick_stop_option_code)
    seen = {start}
    queue: deque[tuple[State, list[int]]] = deque([(start, [])])
    while queue:
        state, words = queue.popleft()
        if state is to_state:
            return words
        for command in _PLAN_COMMANDS:
            if state is State.READY_TO_SWITCH_ON and command is Command.ENABLE_OPERATION:
                continue  # the 3+4 shortcut (S2)
            word = COMMAND_WORD[command]
            nxt = next_state(state, word, quick_stop_option_code=quick_stop_option_code)
            if nxt is state or nxt in seen:
                continue
            seen.add(nxt)
            queue.append((nxt, [*words, word]))
    raise CommandError(f"CiA 402: no controlword path from {from_state.value} to {to_state.value}")


# --- modes of operation (0x6060 / 0x6061 / 0x6502) ----------------------------------------------


class Mode(enum.IntEnum):
    """Modes of operation (values of 0x6060/0x6061)."""

    NO_MODE = 0
    PP = 1  #: profile position
    VL = 2  #: velocity (frequency-converter mode; not an eRob mode)
    PV = 3  #: profile velocity
    PT = 4  #: profile torque
    HM = 6  #: homing
    IP = 7  #: interpolated position
    CSP = 8  #: cyclic synchronous position
    CSV = 9  #: cyclic synchronous velocity
    CST = 10  #: cyclic synchronous torque

    @property
    def cyclic(self) -> bool:
        """A mode whose targets come once per SYNC cycle (CSP, CSV, CST, IP)."""
        return self in _CYCLIC_MODES


_CYCLIC_MODES = frozenset((Mode.CSP, Mode.CSV, Mode.CST, Mode.IP))  #: :attr:`Mode.cyclic` (asked per frame)


#: bit of each mode in "supported drive modes" 0x6502
SUPPORTED_MODE_BIT: Mapping[Mode, int] = {
    Mode.PP: 0, Mode.VL: 1, Mode.PV: 2, Mode.PT: 3, Mode.HM: 5, Mode.IP: 6, Mode.CSP: 7, Mode.CSV: 8, Mode.CST: 9,
}


def supported_modes_bits(modes: Iterable[Mode]) -> int:
    """The 0x6502 value for a set of modes."""
    bits = 0
    for mode in modes:
        if mode is Mode.NO_MODE:
            continue
        bits |= 1 << SUPPORTED_MODE_BIT[mode]
    return bits


def modes_from_bits(value: int) -> frozenset[Mode]:
    """The modes a 0x6502 value advertises."""
    return frozenset(mode for mode, bit in SUPPORTED_MODE_BIT.items() if value >> bit & 1)
