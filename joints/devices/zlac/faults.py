"""ZLAC8015D faults by name: the error-code bits of 0x20A5/0x20A6, and the offline trip the host sees.

Rule: pure data. The bits and their text are the manual's (lines 762-772, 1260-1293); several set
bits make one :class:`~joints.devices.faults.Fault` whose name and text join theirs. The drive has
no error code for its communication-offline quick stop (0x2000): the host sees it as "software
connected status" 0x20AF = 0 and reports the host-defined :data:`OFFLINE`.
"""

from __future__ import annotations

from joints.devices.faults import DEFINED_BY_JOINTS, HOST_DEFINED, Fault
from joints.devices.zlac.registers import Fault as FaultBit
from joints.devices.zlac.registers import describe

SOURCE = "ZLAC8015D manual v1.04, 0x20A5/0x20A6 fault bits"
CLEAR = "clear_faults() (control word 0x06, both wheels), then enable() again"

#: the drive quick-stopped because the host was silent longer than 0x2000 (no error code for it)
OFFLINE_CODE = HOST_DEFINED + 1
OFFLINE = Fault(
    OFFLINE_CODE, "communication_offline",
    "the drive quick-stopped: no frame from the host for longer than the communication offline time (0x2000)",
    "clear_faults(), then enable() again; keep the bus busy (rig.sleep does) more often than the offline time",
    DEFINED_BY_JOINTS)


def fault(code: int) -> Fault | None:
    """The :class:`Fault` of an error-code value (or :data:`OFFLINE_CODE`); None for 0."""
    if not code:
        return None
    if code == OFFLINE_CODE:
        return OFFLINE
    names = [str(FaultBit(bit).name).lower() if bit in FaultBit._value2member_map_ else f"bit_0x{bit:04x}"
             for bit in (1 << i for i in range(16)) if code & bit]
    return Fault(code, "+".join(names), "; ".join(describe(code)), CLEAR, SOURCE)
