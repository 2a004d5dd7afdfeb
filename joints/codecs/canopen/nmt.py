"""CANopen NMT: commands, node states and the node state machine (CiA 301 7.3.2.2, A7).

Rule: pure.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping

from joints.codecs.canopen.cob import Kind

__all__ = ["AFTER_BOOT_UP", "SERVICES_BY_STATE", "NmtCommand", "NmtState", "nmt_transition"]

# --- NMT -------------------------------------------------------------------------------------


class NmtCommand(enum.IntEnum):
    """NMT command specifiers (CiA 301 7.2.8.3.1)."""

    START = 0x01  #: start remote node -> OPERATIONAL
    STOP = 0x02  #: stop remote node -> STOPPED
    ENTER_PRE_OPERATIONAL = 0x80
    RESET_NODE = 0x81
    RESET_COMMUNICATION = 0x82


class NmtState(enum.IntEnum):
    """NMT states as a node reports them in heartbeats and guarding replies (bits 6..0)."""

    INITIALISING = 0x00  #: boot-up message
    STOPPED = 0x04
    OPERATIONAL = 0x05
    PRE_OPERATIONAL = 0x7F


def nmt_transition(state: NmtState, command: NmtCommand) -> NmtState:
    """The state a node enters on ``command`` (reset -> INITIALISING; it then sends its boot-up and
    goes to PRE-OPERATIONAL by itself, see :data:`AFTER_BOOT_UP`)."""
    if command is NmtCommand.START:
        return NmtState.OPERATIONAL
    if command is NmtCommand.STOP:
        return NmtState.STOPPED
    if command is NmtCommand.ENTER_PRE_OPERATIONAL:
        return NmtState.PRE_OPERATIONAL
    return NmtState.INITIALISING


AFTER_BOOT_UP = NmtState.PRE_OPERATIONAL

_ALWAYS = frozenset({Kind.NMT, Kind.HEARTBEAT, Kind.BOOT_UP, Kind.GUARD_REQUEST})
_PDOS = frozenset(k for k in Kind if k.is_pdo)
_PRE_OP = _ALWAYS | {Kind.SDO_RX, Kind.SDO_TX, Kind.SYNC, Kind.EMCY, Kind.TIME}

#: services a node takes part in, per NMT state (CiA 301 7.3.2.2, table 79)
SERVICES_BY_STATE: Mapping[NmtState, frozenset[Kind]] = {
    NmtState.INITIALISING: frozenset({Kind.BOOT_UP}),
    NmtState.PRE_OPERATIONAL: _PRE_OP,
    NmtState.OPERATIONAL: _PRE_OP | _PDOS,
    NmtState.STOPPED: _ALWAYS,
}
