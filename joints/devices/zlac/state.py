"""The ZLAC8015D's one drive state machine (both motors share it): states, control-word transitions.

Rule: pure data and a pure step function, shared by the twin (to enforce) and a driver (to plan).
:func:`step` says which state a control word (0x200E) or a drive-internal event leads to, or
``None`` when the drive ignores it in that state (the write is still acknowledged). What a
transition *does* to the motors (ramps, loops) is the firmware's business.

Manual: zlac8015d-rs485-modbus-manual-v1.04, control word lines 852-868 (0x08 enable, 0x07 stop,
0x05 quick stop, 0x06 clear faults, 0x10/0x11/0x12 start). Choices where the manual is silent
(documented in :mod:`joints.sim.zlac` too):

* Quick stop (0x05) acts only while enabled; the drive stays in QUICK_STOP (energised, holding
  zero speed) until enable (0x08) or stop (0x07) - the CiA 402 quick-stop options 5/6/7.
* Stop (0x07) and enable (0x08) are ignored while faulted: clear faults (0x06) first, which leads
  to DISABLED. Clear faults is accepted in every state.
* Start commands (0x10-0x12) are accepted only while enabled (the firmware then checks the
  control mode and the synchronous/asynchronous setting).
* Any fault (either channel) leads to FAULT from every state; the communication-offline watchdog
  (0x2000) acts only while enabled and leads to QUICK_STOP.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping

from joints.devices.zlac.registers import ControlWord

__all__ = ["ENERGISED", "TRANSITIONS", "DriveState", "Event", "command", "step"]


class DriveState(enum.Enum):
    """State of the drive's one state machine (both motors)."""

    DISABLED = "disabled"  #: power stage off: after power-on, stop (0x07) or clear faults
    ENABLED = "enabled"  #: operation enabled (0x08)
    QUICK_STOP = "quick stop"  #: ramping to / holding zero speed (0x05 or the offline watchdog)
    FAULT = "fault"  #: a channel faulted; power stage off until clear faults (0x06)


class Event(enum.Enum):
    """Drive-internal events (not control words)."""

    FAULT = "fault"  #: a channel's protection tripped
    OFFLINE = "offline"  #: no frame for longer than the communication offline time (0x2000)


#: states in which the power stage is on
ENERGISED = frozenset({DriveState.ENABLED, DriveState.QUICK_STOP})

_D, _E, _Q, _F = DriveState.DISABLED, DriveState.ENABLED, DriveState.QUICK_STOP, DriveState.FAULT
_START = (ControlWord.START_SYNC, ControlWord.START_LEFT, ControlWord.START_RIGHT)

#: (state, control word or event) -> next state; a missing pair is ignored in that state
TRANSITIONS: Mapping[tuple[DriveState, ControlWord | Event], DriveState] = {
    **{(s, ControlWord.ENABLE): _E for s in (_D, _E, _Q)},
    **{(s, ControlWord.STOP): _D for s in (_D, _E, _Q)},
    (_E, ControlWord.QUICK_STOP): _Q,
    **{(s, ControlWord.CLEAR_FAULT): (_D if s is _F else s) for s in DriveState},
    **{(_E, word): _E for word in _START},
    **{(s, Event.FAULT): _F for s in DriveState},
    (_E, Event.OFFLINE): _Q,
}

_WORDS: Mapping[int, ControlWord] = {int(w): w for w in ControlWord}


def command(value: int) -> ControlWord | None:
    """The control word a value of 0x200E is, or None (the value is not a command)."""
    return _WORDS.get(value)


def step(state: DriveState, trigger: ControlWord | Event) -> DriveState | None:
    """The state ``trigger`` leads to from ``state``, or None if the drive ignores it there."""
    return TRANSITIONS.get((state, trigger))
