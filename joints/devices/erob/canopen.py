"""ZeroErr eRob over CANopen (CiA 402): the object dictionary as a map of the eRob parameters.

Rule: pure data. :data:`EROB_CANOPEN` maps each eRob parameter CANopen reaches to its object
(:class:`~joints.devices.canopen.CanopenObject`). The objects - sub-indices, data types, access,
PDO flags, defaults - are ZeroErr's EDS ("ZeroErr Driver_V1.5.eds", read as data by
:mod:`joints.devices.erob.od`, with its listed deviations); a quantity the Modbus table already
names keeps that name (``actual_position`` is register 0x0066 and object 0x6064), the other objects
are parameters named from the EDS. Where the CANopen unit differs, the object says so (``unit``,
``scale``: value in the parameter's unit = raw x scale). The EDS export is :mod:`joints.devices.erob.eds`.

Sources: ZeroErr's EDS (objects); the eRunner manual v1.7 chapter 5 (what eRunner writes: 0x6060/
0x6061, 0x6081/0x6083/0x6084, 0x60FF, 0x1005 = 0x80, 0x1006, RPDO1 = controlword + a 32-bit target,
the panel units cnt, cnt/s, cnt/s^2, mA, mN*m, "disable before every mode change", section 5.1).
What neither says is an assumption to confirm on a real eRob. E1-E12, revised against the EDS
(docs/canopen-eds.md):

* E1 (stands) Position, velocity, acceleration and current objects use the Modbus units (count,
  count/s, count/s^2, mA): the EDS gives no units.
* E2 (stands) 0x6071/0x6077 INTEGER16 (the EDS agrees) in per mille of rated torque; eRunner's
  PT/CST RPDO1 ``2F 00 28 00 00 00`` (fig 5-19) = controlword + target torque + 16 bits of padding.
* E3 (stands; type corrected) 0x6068 position window time is INTEGER16 (EDS) in ms; the Modbus
  register 0x007A is in 0.05 ms.
* E4 (replaced by the EDS) Power-on PDO mapping: RPDO1 controlword; RPDO2 + 0x607A; RPDO3 + 0x60FF;
  RPDO4 empty; TPDO1 statusword; TPDO2 + 0x6064; TPDO3 + 0x606C; TPDO4 empty; transmission type
  255; only PDO1 valid (COB-ID bit 31 set on 2..4). First run: a master that uses RPDO2/TPDO2
  enables them first (0x1401:01 without bit 31); heartbeat and guarding off (0x1017 = 0x100C = 0).
* E5 (stands) eRunner's own mapping (:data:`ERUNNER_RPDO1`, :data:`ERUNNER_TPDOS`): RPDO1 =
  controlword + the mode's target, TPDO1 = statusword + position, TPDO2 = velocity + current.
* E6 (deviation kept) 0x6502 = 0x3CD: the EDS says 0x38D (no IP bit); the eRunner manual 5.7 runs
  IP mode. 0x60C1:01 is INTEGER32 (the EDS: INTEGER16) for the same reason. Modes power up as 0.
* E7 (stands, no evidence) A mode change (0x6060 write) while OPERATION ENABLED is refused with SDO
  abort 0x08000022 (section 5.1 requires disabling first): :func:`mode_change_allowed`. The firmware
  profile ``mode-change-while-enabled`` (``firmware = "..."`` on the joint) accepts it instead.
* E8 (corrected) 0x1006 powers up 0 (the EDS; eRunner writes 1000 us, its default setting); 0x1005
  0x80 (the EDS agrees). 0x603F holds the eRob error code (same quantity as Modbus 0x0060).
* E9 (replaced by the EDS) The objects are the EDS's; identity: vendor 0x5A65726F, product
  0x26483052, revision 0x00020111, 0x1018:00 = 3 (no serial number object).
* E10 (wrong) 0x6073 max current is not in the EDS: the driver refuses a torque limit over CANopen.
  0x6080 max motor speed in count/s (the joint's speed limit).
* E11 (wrong) 0x22A2 Drive Temperature (UNSIGNED16) is the power-stage temperature, assumed in degC:
  the same quantity as Modbus 0x0078 (``part_of_power_temperature``).
* E12 (stands) Our cyclic feedback (:data:`CYCLIC_TPDO1_CURRENT`): statusword + position + current
  0x6078 (8 bytes) where the bus has room, eRunner's 6-byte TPDO1 otherwise (the host's choice).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from joints.devices.canopen import CanopenObject, DataType, ObjectAccess
from joints.devices.cia402 import Mode, State, modes_from_bits
from joints.devices.erob.od import OBJECT_NAMES
from joints.devices.erob.params import CANOPEN_ENTRIES, EROB_PARAMS
from joints.devices.params import Access, ParamMap
from joints.errors import RegisterError

__all__ = [
    "CYCLIC_TPDO1_CURRENT",
    "EROB_CANOPEN",
    "ERUNNER_RPDO1",
    "ERUNNER_TPDOS",
    "MODE_CHANGE_REFUSED",
    "OBJECT_NAMES",
    "QUICK_STOP_OPTION_CODE",
    "SUPPORTED_MODES",
    "TARGET_PARAM",
    "CanopenObject",
    "DataType",
    "ObjectAccess",
    "PdoConfig",
    "mode_change_allowed",
    "name_at",
    "objects",
]


#: CANopen unit and scale where they differ from the parameter's (E3)
_SCALED: dict[str, tuple[str, float]] = {"time_setting_of_achieving_position": ("ms", 20.0)}


def _objects() -> dict[str, CanopenObject]:
    out = {}
    for e in CANOPEN_ENTRIES:
        unit, scale = _SCALED.get(e.name, ("", 1.0))
        default = round(EROB_PARAMS[e.name].default / scale)
        out[e.name] = CanopenObject(e.index, e.subindex, DataType(e.datatype), ObjectAccess(e.access), e.entry_name,
                                    e.pdo_mappable, e.node_relative, unit, scale, default)
    return out


_KEYS = _objects()

EROB_CANOPEN: ParamMap[CanopenObject] = ParamMap("canopen", EROB_PARAMS, dict(_KEYS))
"""Parameter name -> CANopen object, for every eRob parameter CANopen reaches."""

_BY_ADDRESS: dict[tuple[int, int], str] = {(o.index, o.subindex): name for name, o in _KEYS.items()}


def name_at(index: int, subindex: int) -> str:
    """The parameter at ``index:subindex`` (:class:`~joints.errors.RegisterError` if none)."""
    try:
        return _BY_ADDRESS[(index, subindex)]
    except KeyError:
        raise RegisterError(f"erob: no CANopen object 0x{index:04X}:{subindex:02X}") from None


def has_index(index: int) -> bool:
    """Whether the dictionary has object ``index`` (any sub-index): abort 0x06020000 vs 0x06090011."""
    return any(i == index for i, _ in _BY_ADDRESS)


def objects() -> list[tuple[str, CanopenObject]]:
    """Every (parameter name, object), by index and sub-index (the order of an EDS)."""
    return sorted(_KEYS.items(), key=lambda kv: (kv[1].index, kv[1].subindex))


# --- modes --------------------------------------------------------------------------------------

#: 0x6502 default, the modes of chapter 5 (E6)
SUPPORTED_MODES: frozenset[Mode] = modes_from_bits(EROB_PARAMS["supported_drive_modes"].default)

#: the parameter each mode's target is written to
TARGET_PARAM: Mapping[Mode, str] = {
    Mode.PP: "target_absolute_position",
    Mode.CSP: "target_absolute_position",
    Mode.PV: "target_speed",
    Mode.CSV: "target_speed",
    Mode.PT: "target_torque",
    Mode.CST: "target_torque",
    Mode.IP: "interpolation_data_record_1",
}

#: 0x605A is not in ZeroErr's EDS: the quick stop reacts as CiA 402's default option code 2 (stop on
#: the quick-stop ramp, then SWITCH ON DISABLED; S3 of joints.devices.cia402)
QUICK_STOP_OPTION_CODE = 2
MODE_CHANGE_REFUSED = 0x08000022  #: SDO abort for a 0x6060 write in OPERATION ENABLED (E7)


def mode_change_allowed(state: State) -> bool:
    """Whether the eRob takes a new mode of operation in ``state`` (not while OPERATION ENABLED, E7)."""
    return state is not State.OPERATION_ENABLED


# --- PDO configurations ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class PdoConfig:
    """A PDO mapping as data: parameters in mapping order (an int = that many bits of padding)."""

    kind: str  #: "RPDO" or "TPDO"
    number: int  #: 1..4
    objects: tuple[str | int, ...]
    transmission_type: int = 255
    event_timer: int | None = None
    inhibit_time: int | None = None

    def __post_init__(self) -> None:
        if self.kind not in ("RPDO", "TPDO") or not 1 <= self.number <= 4:
            raise ValueError(f"PDO {self.kind}{self.number}: kind is RPDO/TPDO, number 1..4")
        if self.bits > 64:
            raise ValueError(f"{self.kind}{self.number}: {self.bits} bits mapped (at most 64)")

    @property
    def entries(self) -> tuple[tuple[int, int, int, bool], ...]:
        """(index, subindex, bits, signed) per mapped object; padding as CiA 301 dummy entries."""
        out = []
        for item in self.objects:
            if isinstance(item, int):
                out.append((_DUMMY[item], 0, item, False))
            else:
                out.append(EROB_CANOPEN.key(item).mapping_entry)
        return tuple(out)

    @property
    def bits(self) -> int:
        return sum(e[2] for e in self.entries)

    @property
    def size(self) -> int:
        """Data bytes of the PDO frame."""
        return (self.bits + 7) // 8

    @property
    def communication_index(self) -> int:
        return (0x1400 if self.kind == "RPDO" else 0x1800) + self.number - 1

    @property
    def mapping_index(self) -> int:
        return (0x1600 if self.kind == "RPDO" else 0x1A00) + self.number - 1

    def cob_id(self, node: int) -> int:
        """Pre-defined COB-ID on node ``node`` (without the not-valid bit)."""
        return (EROB_PARAMS[f"{self.kind.lower()}{self.number}_cob_id"].default & 0x7FF) + node


_DUMMY = {8: 0x0005, 16: 0x0006, 32: 0x0007}  #: padding bits -> CiA 301 dummy (UNSIGNED8/16/32)

#: eRunner's RPDO1 per mode: controlword + the mode's 32-bit target slot (6 bytes; E2, E5)
ERUNNER_RPDO1: Mapping[Mode, PdoConfig] = {
    mode: PdoConfig("RPDO", 1, ("controlword", TARGET_PARAM[mode], *((16,) if mode in (Mode.PT, Mode.CST) else ())),
                    1 if mode.cyclic else 255)
    for mode in (Mode.PP, Mode.PV, Mode.PT, Mode.CSP, Mode.CSV, Mode.CST, Mode.IP)
}

#: eRunner's TPDOs (E5): status + position, speed + current, on every SYNC
ERUNNER_TPDOS: tuple[PdoConfig, ...] = (
    PdoConfig("TPDO", 1, ("statusword", "actual_position"), 1),
    PdoConfig("TPDO", 2, ("current_speed", "motor_current"), 1),
)


#: the cyclic modes' TPDO1 with the motor current (E12): 8 bytes, on every SYNC
CYCLIC_TPDO1_CURRENT = PdoConfig("TPDO", 1, ("statusword", "actual_position", "motor_current"), 1)


def power_on_pdo(kind: str, number: int) -> PdoConfig:
    """The power-on mapping of a PDO, read from the parameter defaults (E4)."""
    prefix = f"{kind.lower()}{number}"
    count = EROB_PARAMS[f"{prefix}_mapped_objects"].default
    names = []
    for i in range(1, count + 1):
        value = EROB_PARAMS[f"{prefix}_mapping_{i}"].default
        names.append(name_at(value >> 16, value >> 8 & 0xFF))
    return PdoConfig(kind, number, tuple(names), EROB_PARAMS[f"{prefix}_transmission_type"].default)


def access_of(access: Access) -> ObjectAccess:
    """The object access that matches a parameter access (R -> ro, RW -> rw, W/Command -> wo)."""
    return {Access.R: ObjectAccess.RO, Access.RW: ObjectAccess.RW}.get(access, ObjectAccess.WO)
