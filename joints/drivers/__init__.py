"""Drivers: parameter-level logic per device family and protocol (same code for hardware and twin).

Which driver serves which device on which protocol is the registry's business (:mod:`joints.registry`).
"""

from __future__ import annotations

from joints.drivers.access import ModbusAccess, ParamAccess
from joints.drivers.base import JointDriver, RawState, Units

__all__ = ["JointDriver", "ModbusAccess", "ParamAccess", "RawState", "Units"]
