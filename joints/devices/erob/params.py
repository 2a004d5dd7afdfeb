"""The eRob's parameters, defined once for every protocol that reaches the drive.

Rule: the Modbus manual's chapter-4 table (:data:`joints.devices.erob.registers.EROB_MODBUS`) is
the base: each of its registers is one parameter by the same name. Quantities that only the CAN
custom protocol or CANopen reach are added here as :class:`~joints.devices.params.Param` entries,
so every protocol map (Modbus register, CAN index, CANopen object) names the same quantities.
"""

from __future__ import annotations

from joints.devices.erob.registers import EROB_MODBUS
from joints.devices.params import Param, ParamSet

#: quantities no Modbus register carries (added by the CAN custom protocol and CANopen maps)
OTHER_PROTOCOLS: tuple[Param, ...] = ()

EROB_PARAMS: ParamSet = EROB_MODBUS.params.extended(OTHER_PROTOCOLS)
