"""Faults as values: what a drive reports (or what the host saw), by name, with the manual's text.

Rule: pure data. A :class:`Fault` carries the device's own code, a short name, the manual's text,
what clears it and where the code comes from (the manual's section, or "defined by joints" where
the manuals give no code - e.g. a watchdog trip the host sees but the drive does not report).
Host-defined codes live above 0xFFFF so they never collide with a drive's 16-bit codes.
"""

from __future__ import annotations

from dataclasses import dataclass

#: first code of the host-defined faults (drive codes are 16-bit)
HOST_DEFINED = 0x1_0000
DEFINED_BY_JOINTS = "defined by joints (no code in the manuals)"


@dataclass(frozen=True, slots=True)
class Fault:
    """One fault of one drive."""

    code: int  #: the drive's own code (or a host-defined code >= 0x10000)
    name: str  #: short snake_case name
    text: str  #: the manual's text for it
    clears: str  #: what clears it
    source: str  #: the manual section the code comes from, or DEFINED_BY_JOINTS

    def __str__(self) -> str:
        code = f"0x{self.code:04X}" if self.code < HOST_DEFINED else "host-defined"
        return f"{self.name} ({code}): {self.text}"
