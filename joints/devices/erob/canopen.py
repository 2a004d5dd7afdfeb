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
