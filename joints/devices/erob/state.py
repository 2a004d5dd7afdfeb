"""The eRob's drive state: motor off, enabling (brake releasing), ready, command refused, fault.

Rule: pure data and a pure step function, shared by the twin (to enforce) and a driver (to plan).
:func:`step` says which state an event leads to; ``None`` means the drive refuses or ignores it
there. The error code that goes with a state (0x0027, a protection's code) is data the firmware
keeps beside the state.

Sources and choices (the Modbus manual v1.6 gives the commands, not the state machine):

* "Enable the Motor" (0x00F0 = 1) releases the holding brake; the manual's examples wait 500 ms
  before "Start Operating" (0x00F1). ENABLING lasts that long (:data:`ENABLE_DELAY`), then
  BRAKE_RELEASED leads to READY. Enable while enabled changes nothing (the timer keeps running).
* A motion command - start, a non-zero target speed in speed mode or target current in torque
  mode - is accepted only in READY. Anywhere else it is refused with the eRunner manual's code
  0x0027 "cannot start motion while the motor is off" (appendix 1 #4), which latches: the drive
  holds still (REFUSED_OFF / REFUSED_ON) until "Clear Errors" (0x00F6), though it may still be
  enabled and disabled meanwhile.
* A protection (following error, speed error, stall, position limit, over-temperature) leads from
  any state without a latched error to FAULT, which switches the motor off; while 0x0027 or a
  fault is latched a second protection is not reported. The RS485 watchdog (0x0002, code 0xFA2)
  leads to FAULT from every state and replaces a latched code.
* In FAULT the drive refuses "Enable" until "Clear Errors", which leads to MOTOR_OFF.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping

__all__ = ["ENABLED", "ENABLE_DELAY", "TRANSITIONS", "DriveState", "Event", "runs_motion", "step"]

ENABLE_DELAY = 0.5  #: s from "enable" to motor ready (manual: wait 500 ms before start)


class DriveState(enum.Enum):
    """State of the drive (the error code that goes with REFUSED_* / FAULT is kept beside it)."""

    MOTOR_OFF = "motor off"  #: disabled, brake holds
    ENABLING = "enabling"  #: enabled, holding brake releasing (ENABLE_DELAY)
    READY = "ready"  #: motor on: start, speed and current commands run
    REFUSED_OFF = "refused, motor off"  #: 0x0027 latched, disabled
    REFUSED_ON = "refused, enabled"  #: 0x0027 latched, enabled: holds still until clear errors
    FAULT = "fault"  #: a protection tripped: motor off until clear errors


class Event(enum.Enum):
    """What moves the state: commands of the host and the drive's own timers and protections."""

    ENABLE = "enable"  #: 0x00F0 = 1
    DISABLE = "disable"  #: 0x00F0 = 0
    BRAKE_RELEASED = "brake released"  #: ENABLE_DELAY after enable
    MOTION = "motion command"  #: start operating, target speed / current
    PROTECTION = "protection"  #: following/speed error, stall, limit, over-temperature
    WATCHDOG = "watchdog"  #: RS485 communication timeout
    CLEAR = "clear errors"  #: 0x00F6


#: states in which the motor is enabled (brake released or releasing)
ENABLED = frozenset({DriveState.ENABLING, DriveState.READY, DriveState.REFUSED_ON})

_OFF, _ING, _RDY = DriveState.MOTOR_OFF, DriveState.ENABLING, DriveState.READY
_ROFF, _RON, _F = DriveState.REFUSED_OFF, DriveState.REFUSED_ON, DriveState.FAULT
_E = Event

#: (state, event) -> next state; a missing pair means the event is refused / ignored there. A
#: motion command outside READY is refused and latches 0x0027 (its entries lead to REFUSED_*).
TRANSITIONS: Mapping[tuple[DriveState, Event], DriveState] = {
    (_OFF, _E.ENABLE): _ING, (_ING, _E.ENABLE): _ING, (_RDY, _E.ENABLE): _RDY,
    (_ROFF, _E.ENABLE): _RON, (_RON, _E.ENABLE): _RON,
    (_OFF, _E.DISABLE): _OFF, (_ING, _E.DISABLE): _OFF, (_RDY, _E.DISABLE): _OFF,
    (_ROFF, _E.DISABLE): _ROFF, (_RON, _E.DISABLE): _ROFF, (_F, _E.DISABLE): _F,
    (_ING, _E.BRAKE_RELEASED): _RDY,
    (_RDY, _E.MOTION): _RDY, (_OFF, _E.MOTION): _ROFF, (_ING, _E.MOTION): _RON,
    (_ROFF, _E.MOTION): _ROFF, (_RON, _E.MOTION): _RON, (_F, _E.MOTION): _F,
    (_OFF, _E.PROTECTION): _F, (_ING, _E.PROTECTION): _F, (_RDY, _E.PROTECTION): _F,
    **{(s, _E.WATCHDOG): _F for s in DriveState},
    (_OFF, _E.CLEAR): _OFF, (_ING, _E.CLEAR): _ING, (_RDY, _E.CLEAR): _RDY,
    (_ROFF, _E.CLEAR): _OFF, (_RON, _E.CLEAR): _ING, (_F, _E.CLEAR): _OFF,
}


def step(state: DriveState, event: Event) -> DriveState | None:
    """The state ``event`` leads to from ``state``; None where the drive refuses / ignores it."""
    return TRANSITIONS.get((state, event))


def runs_motion(state: DriveState) -> bool:
    """Whether a motion command runs in ``state`` (else it is refused with 0x0027)."""
    return state is DriveState.READY
