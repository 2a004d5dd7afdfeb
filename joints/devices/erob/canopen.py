"""ZeroErr eRob over CANopen (CiA 402): the object dictionary as a map of the eRob parameters.

Rule: pure data. :data:`EROB_CANOPEN` maps each parameter of :data:`~joints.devices.erob.params.EROB_PARAMS`
that CANopen reaches to its object (index, subindex, CiA 301 data type, access, PDO mappability):
a quantity the Modbus table already names keeps that name (``actual_position`` is register
0x0066 and object 0x6064); objects only CANopen has are parameters of ``OTHER_PROTOCOLS``.
Where the CANopen unit differs, the object says so (``unit``, ``scale``: value in the parameter's
unit = raw x scale). The entries carry what an EDS needs (index, subindex, data type code,
access, default, PDO mapping); the defaults are the parameters' defaults (COB-IDs + node id).

Source: eRunner manual v1.7 chapter 5. It uses 0x6060/0x6061 (all modes), 0x6081 profile velocity,
0x6083/0x6084 profile acceleration/deceleration, 0x60FF target velocity, 0x1005 COB-ID SYNC,
0x1006 communication cycle period (figs 5-5..5-40), RPDO1 on 0x200+node with controlword + a
32-bit target (6 bytes, figs 5-6, 5-9, 5-15, 5-19, 5-24, 5-28, 5-30), the panel units cnt, cnt/s,
cnt/s^2, mA, mN*m, and "每次切换运动模式之前都需要先下使能" (disable before every mode change,
section 5.1). It names the vendor's "eRob CANopen and EtherCAT User Manual V1.6" for the rest; that
manual is not in our set, so everything below that chapter 5 does not show is CiA 301/402 and an
assumption to confirm on a real eRob:

* E1 Position, velocity, acceleration and current objects use the Modbus units (count, count/s,
  count/s^2, mA; the eRunner panel shows cnt, cnt/s, cnt/s^2 and mA). CiA 402 itself would give
  0x6078 in per mille of rated current; the eRob is assumed to report mA like its panel.
* E2 0x6071/0x6077 torque: CiA 402 INTEGER16, per mille of rated torque, although eRunner's PT/CST
  panel labels the field mN*m. eRunner's PT/CST RPDO1 ``2F 00 28 00 00 00`` (fig 5-19) fits
  controlword + target torque (16 bits) + 16 bits of padding: that is our RPDO1 for PT/CST.
* E3 0x6068 position window time is in ms (CiA 402); the Modbus register 0x007A is in 0.05 ms.
* E4 Power-on PDO mapping = the CiA 402 pre-defined mapping (RPDO1 controlword; RPDO2 +0x6060;
  RPDO3 +0x607A; RPDO4 +0x60FF; TPDO1 statusword; TPDO2 +0x6061; TPDO3 +0x6064; TPDO4 +0x606C),
  transmission type 255, event timers 0, heartbeat and guarding off (0x1017 = 0x100C = 0). Only
  RPDO1 and TPDO1 are valid: RPDO2..4 repeat the controlword, and a master that sends one of them
  whole for its other object (canopen's ``BaseNode402.op_mode`` does) would also send a stale
  controlword; TPDO2..4 would only add bus load.
* E5 eRunner's own mapping (:data:`ERUNNER_RPDO1`, :data:`ERUNNER_TPDOS`): RPDO1 = controlword +
  the mode's target (PP/CSP 0x607A, PV/CSV 0x60FF, PT/CST 0x6071 + padding, IP 0x60C1:01), applied at
  once in the profile modes (255) and at the next SYNC in the cyclic ones (1). Chapter 5 shows no
  TPDO frame; eRunner's panel shows position, speed, current and status, so TPDO1 = statusword +
  position actual value (6 bytes), TPDO2 = velocity actual value + current actual value (6 bytes),
  both sent on every SYNC (type 1).
* E6 0x6502 supported drive modes = PP, PV, PT, IP, CSP, CSV, CST (the modes of chapter 5; no
  homing): 0x000003CD. Modes of operation power up as 0 (no mode).
* E7 A mode change (0x6060 write) while OPERATION ENABLED is refused with SDO abort 0x08000022
  (chapter 5 requires disabling first; strict on purpose): :func:`mode_change_allowed`.
* E8 0x1006 defaults to 1000 us (chapter 3: "通信周期 ... 默认设置为1000 µs"); 0x1005 to 0x80
  (consumer of SYNC 0x080, as eRunner writes it). 0x603F error code holds the eRob error code
  of :mod:`joints.devices.erob.faults` (same quantity as Modbus 0x0060).
* E10 0x6073 max current is in mA (like E1; CiA 402: per mille of rated current) and 0x6080 max
  motor speed in count/s: the joint's limits go there (the Modbus max_motor_current / max_speed).
* E9 Only the objects above exist; vendor id, product code, revision and serial number read 0.
* E11 No object reports a temperature: chapter 5 shows none, and ZeroErr's EDS for its eDriver
  CANopen slave lists only CiA 301/402 objects (no manufacturer area). The power-stage temperature
  is read over Modbus RTU or the CAN custom protocol.
* E12 Our cyclic feedback (:data:`CYCLIC_TPDO1_CURRENT`): TPDO1 = statusword + position + current
  actual value 0x6078 (8 bytes, every SYNC) where the bus has room for it, eRunner's 6-byte TPDO1
  otherwise (the host's choice, not the drive's).
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass

from joints.devices.cia402 import Mode, State, modes_from_bits
from joints.devices.erob.params import EROB_PARAMS
from joints.devices.params import Access, ParamMap, check_value
from joints.errors import FrameError, RegisterError

__all__ = [
    "CYCLIC_TPDO1_CURRENT",
    "EROB_CANOPEN",
    "ERUNNER_RPDO1",
    "ERUNNER_TPDOS",
    "MODE_CHANGE_REFUSED",
    "OBJECT_NAMES",
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


class DataType(enum.IntEnum):
    """CiA 301 data type codes (the ``DataType`` of an EDS entry) of the types the eRob map uses."""

    BOOLEAN = 0x0001
    INTEGER8 = 0x0002
    INTEGER16 = 0x0003
    INTEGER32 = 0x0004
    UNSIGNED8 = 0x0005
    UNSIGNED16 = 0x0006
    UNSIGNED32 = 0x0007

    @property
    def bits(self) -> int:
        return _BITS[self]

    @property
    def size(self) -> int:
        """Bytes on the wire (SDO)."""
        return max(1, _BITS[self] // 8)

    @property
    def signed(self) -> bool:
        return self in (DataType.INTEGER8, DataType.INTEGER16, DataType.INTEGER32)

    @property
    def param_type(self) -> str:
        """The :data:`~joints.devices.params.TYPES` name of the same range."""
        return _PARAM_TYPE[self]


_BITS = {DataType.BOOLEAN: 1, DataType.INTEGER8: 8, DataType.INTEGER16: 16, DataType.INTEGER32: 32,
         DataType.UNSIGNED8: 8, DataType.UNSIGNED16: 16, DataType.UNSIGNED32: 32}
_PARAM_TYPE = {DataType.BOOLEAN: "bool", DataType.INTEGER8: "int8", DataType.INTEGER16: "int16",
               DataType.INTEGER32: "int32", DataType.UNSIGNED8: "uint8", DataType.UNSIGNED16: "uint16",
               DataType.UNSIGNED32: "uint32"}


class ObjectAccess(enum.Enum):
    """EDS ``AccessType`` values."""

    RO = "ro"
    WO = "wo"
    RW = "rw"
    RWR = "rwr"  #: read-write, mapped to a TPDO
    RWW = "rww"  #: read-write, mapped to an RPDO
    CONST = "const"

    @property
    def readable(self) -> bool:
        return self is not ObjectAccess.WO

    @property
    def writable(self) -> bool:
        return self not in (ObjectAccess.RO, ObjectAccess.CONST)


@dataclass(frozen=True, slots=True, eq=False)
class CanopenObject:
    """One object-dictionary entry; equal (and hashed) by (index, subindex)."""

    index: int
    subindex: int
    datatype: DataType
    access: ObjectAccess
    name: str  #: the CiA 301/402 object name (EDS ParameterName)
    pdo_mappable: bool = False
    node_relative: bool = False  #: the default is the parameter's default + node id (COB-IDs)
    unit: str = ""  #: unit on CANopen when it differs from the parameter's
    scale: float = 1.0  #: value in the parameter's unit = raw x scale

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, CanopenObject):
            return NotImplemented
        return (self.index, self.subindex) == (other.index, other.subindex)

    def __hash__(self) -> int:
        return hash((self.index, self.subindex))

    def __repr__(self) -> str:
        return f"CanopenObject(0x{self.index:04X}:{self.subindex:02X} {self.name!r}, {self.datatype.name})"

    def __str__(self) -> str:
        return f"0x{self.index:04X}:{self.subindex:02X}"

    @property
    def bits(self) -> int:
        return self.datatype.bits

    @property
    def size(self) -> int:
        return self.datatype.size

    @property
    def signed(self) -> bool:
        return self.datatype.signed

    def encode(self, value: object) -> bytes:
        """The SDO bytes of ``value`` (little-endian); :class:`~joints.errors.CommandError` if out of range."""
        v = check_value(self.name, self.datatype.param_type, value, where=f" (0x{self.index:04X}:{self.subindex:02X})")
        return v.to_bytes(self.size, "little", signed=self.signed)

    def decode(self, data: bytes) -> int:
        """The value in SDO/PDO bytes; :class:`~joints.errors.FrameError` if the length is not the type's."""
        if len(data) != self.size:
            raise FrameError(f"0x{self.index:04X}:{self.subindex:02X} ({self.datatype.name}) takes {self.size} "
                             f"bytes, got {len(data)}", data=bytes(data))
        return int.from_bytes(data, "little", signed=self.signed)

    @property
    def mapping_entry(self) -> tuple[int, int, int, bool]:
        """(index, subindex, bits, signed): a PDO mapping entry for the codec."""
        return self.index, self.subindex, self.bits, self.signed

    def default(self, node: int) -> int:
        """Power-on value on node ``node`` (from the parameter; COB-IDs + node id)."""
        value = EROB_PARAMS[name_at(self.index, self.subindex)].default
        return value + node if self.node_relative else value


_I8, _I16, _I32 = DataType.INTEGER8, DataType.INTEGER16, DataType.INTEGER32
_U8, _U16, _U32 = DataType.UNSIGNED8, DataType.UNSIGNED16, DataType.UNSIGNED32
_RO, _RW, _RWW, _RWR = ObjectAccess.RO, ObjectAccess.RW, ObjectAccess.RWW, ObjectAccess.RWR

#: names of the objects that have sub-indexes (EDS RECORD/ARRAY ParameterName)
OBJECT_NAMES: dict[int, str] = {
    0x1018: "Identity object",
    0x607D: "Software position limit",
    0x60C1: "Interpolation data record",
    0x60C2: "Interpolation time period",
}

_KEYS: dict[str, CanopenObject] = {}


def _o(name: str, index: int, subindex: int, datatype: DataType, access: ObjectAccess, object_name: str, *,
       pdo: bool = False, node_relative: bool = False, unit: str = "", scale: float = 1.0) -> None:
    _KEYS[name] = CanopenObject(index, subindex, datatype, access, object_name, pdo, node_relative, unit, scale)


# communication profile (CiA 301)
_o("device_type", 0x1000, 0, _U32, _RO, "Device type")
_o("error_register", 0x1001, 0, _U8, _RO, "Error register", pdo=True)
_o("cob_id_sync", 0x1005, 0, _U32, _RW, "COB-ID SYNC message")
_o("communication_cycle_period", 0x1006, 0, _U32, _RW, "Communication cycle period")
_o("guard_time", 0x100C, 0, _U16, _RW, "Guard time")
_o("life_time_factor", 0x100D, 0, _U8, _RW, "Life time factor")
_o("cob_id_emcy", 0x1014, 0, _U32, _RW, "COB-ID EMCY", node_relative=True)
_o("producer_heartbeat_time", 0x1017, 0, _U16, _RW, "Producer heartbeat time")
_o("identity_highest_subindex", 0x1018, 0, _U8, _RO, "Highest sub-index supported")
_o("vendor_id", 0x1018, 1, _U32, _RO, "Vendor-ID")
_o("product_code", 0x1018, 2, _U32, _RO, "Product code")
_o("revision_number", 0x1018, 3, _U32, _RO, "Revision number")
_o("serial_number", 0x1018, 4, _U32, _RO, "Serial number")
for _n in range(1, 5):
    _c, _m = 0x1400 + _n - 1, 0x1600 + _n - 1
    OBJECT_NAMES[_c] = f"RPDO{_n} communication parameter"
    OBJECT_NAMES[_m] = f"RPDO{_n} mapping parameter"
    _o(f"rpdo{_n}_highest_subindex", _c, 0, _U8, _RO, "Highest sub-index supported")
    _o(f"rpdo{_n}_cob_id", _c, 1, _U32, _RW, "COB-ID used by RPDO", node_relative=True)
    _o(f"rpdo{_n}_transmission_type", _c, 2, _U8, _RW, "Transmission type")
    _o(f"rpdo{_n}_event_timer", _c, 5, _U16, _RW, "Event-timer")
    _o(f"rpdo{_n}_mapped_objects", _m, 0, _U8, _RW, "Number of mapped application objects in PDO")
    for _i in range(1, 9):
        _o(f"rpdo{_n}_mapping_{_i}", _m, _i, _U32, _RW, f"Application object {_i}")
for _n in range(1, 5):
    _c, _m = 0x1800 + _n - 1, 0x1A00 + _n - 1
    OBJECT_NAMES[_c] = f"TPDO{_n} communication parameter"
    OBJECT_NAMES[_m] = f"TPDO{_n} mapping parameter"
    _o(f"tpdo{_n}_highest_subindex", _c, 0, _U8, _RO, "Highest sub-index supported")
    _o(f"tpdo{_n}_cob_id", _c, 1, _U32, _RW, "COB-ID used by TPDO", node_relative=True)
    _o(f"tpdo{_n}_transmission_type", _c, 2, _U8, _RW, "Transmission type")
    _o(f"tpdo{_n}_inhibit_time", _c, 3, _U16, _RW, "Inhibit time")
    _o(f"tpdo{_n}_event_timer", _c, 5, _U16, _RW, "Event timer")
    _o(f"tpdo{_n}_sync_start_value", _c, 6, _U8, _RW, "SYNC start value")
    _o(f"tpdo{_n}_mapped_objects", _m, 0, _U8, _RW, "Number of mapped application objects in PDO")
    for _i in range(1, 9):
        _o(f"tpdo{_n}_mapping_{_i}", _m, _i, _U32, _RW, f"Application object {_i}")

# device profile (CiA 402); names from the Modbus table where the quantity is the same
_o("error_code", 0x603F, 0, _U16, _RO, "Error code", pdo=True)
_o("controlword", 0x6040, 0, _U16, _RWW, "Controlword", pdo=True)
_o("statusword", 0x6041, 0, _U16, _RO, "Statusword", pdo=True)
_o("quick_stop_option_code", 0x605A, 0, _I16, _RW, "Quick stop option code")
_o("modes_of_operation", 0x6060, 0, _I8, _RWW, "Modes of operation", pdo=True)
_o("modes_of_operation_display", 0x6061, 0, _I8, _RO, "Modes of operation display", pdo=True)
_o("given_position", 0x6062, 0, _I32, _RO, "Position demand value", pdo=True)
_o("actual_position", 0x6064, 0, _I32, _RO, "Position actual value", pdo=True)
_o("max_position_error", 0x6065, 0, _U32, _RW, "Following error window")
_o("position_reaches_set_precision", 0x6067, 0, _U32, _RW, "Position window")
_o("time_setting_of_achieving_position", 0x6068, 0, _U16, _RW, "Position window time", unit="ms", scale=20.0)
_o("given_speed", 0x606B, 0, _I32, _RO, "Velocity demand value", pdo=True)
_o("current_speed", 0x606C, 0, _I32, _RO, "Velocity actual value", pdo=True)
_o("target_torque", 0x6071, 0, _I16, _RWW, "Target torque", pdo=True)
_o("max_motor_current", 0x6073, 0, _U16, _RW, "Max current")
_o("torque_actual_value", 0x6077, 0, _I16, _RO, "Torque actual value", pdo=True)
_o("motor_current", 0x6078, 0, _I16, _RO, "Current actual value", pdo=True)
_o("bus_voltage", 0x6079, 0, _U32, _RO, "DC link circuit voltage", pdo=True)
_o("target_absolute_position", 0x607A, 0, _I32, _RWW, "Target position", pdo=True)
_o("software_position_limit_highest_subindex", 0x607D, 0, _U8, _RO, "Highest sub-index supported")
_o("min_position_limit_value", 0x607D, 1, _I32, _RW, "Min position limit")
_o("max_position_limit_value", 0x607D, 2, _I32, _RW, "Max position limit")
_o("max_speed", 0x6080, 0, _U32, _RW, "Max motor speed")
_o("profile_speed", 0x6081, 0, _U32, _RWW, "Profile velocity", pdo=True)
_o("profile_acceleration", 0x6083, 0, _U32, _RWW, "Profile acceleration", pdo=True)
_o("profile_deceleration", 0x6084, 0, _U32, _RWW, "Profile deceleration", pdo=True)
_o("quick_stop_deceleration", 0x6085, 0, _U32, _RW, "Quick stop deceleration")
_o("interpolation_sub_mode_select", 0x60C0, 0, _I16, _RW, "Interpolation sub mode select")
_o("interpolation_data_record_highest_subindex", 0x60C1, 0, _U8, _RO, "Highest sub-index supported")
_o("interpolation_data_record_1", 0x60C1, 1, _I32, _RWW, "1st set-point", pdo=True)
_o("interpolation_time_period_highest_subindex", 0x60C2, 0, _U8, _RO, "Highest sub-index supported")
_o("interpolation_time_period_value", 0x60C2, 1, _U8, _RW, "Interpolation time period value")
_o("interpolation_time_index", 0x60C2, 2, _I8, _RW, "Interpolation time index")
_o("position_error", 0x60F4, 0, _I32, _RO, "Following error actual value", pdo=True)
_o("target_speed", 0x60FF, 0, _I32, _RWW, "Target velocity", pdo=True)
_o("supported_drive_modes", 0x6502, 0, _U32, _RO, "Supported drive modes")

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
