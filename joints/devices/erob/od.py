"""The eRob's CANopen object dictionary: ZeroErr's EDS (as data) + the listed deviations.

Rule: pure data. The objects, sub-indices, data types, access, PDO flags and defaults are read from
``zeroerr_eds.json``, derived from ZeroErr's ``ZeroErr Driver_V1.5.eds`` by ``tests/data/erob_eds.py``
(the extract keeps the facts, not the file: its licence is not stated). What the twin does
otherwise is one list, :data:`DEVIATIONS`, each with its evidence; it is applied here, exported
in the EDS comments (:mod:`joints.devices.erob.eds`) and listed in ``docs/canopen-eds.md``.

Each object is a parameter of :data:`~joints.devices.erob.params.EROB_PARAMS`: a quantity the
Modbus table already names keeps that name (:data:`BINDING`: 0x6064 is ``actual_position``, as
register 0x0066); the other objects are named from the EDS (snake case of the object name, plus
the sub-index name for a sub-index) and are stored values unless the twin computes them.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, replace
from functools import cache
from importlib import resources
from typing import Any

__all__ = ["BINDING", "DEVIATIONS", "OBJECT_NAMES", "Deviation", "OdEntry", "entries", "source", "vendor_entries"]

DATA_FILE = "zeroerr_eds.json"


@dataclass(frozen=True, slots=True)
class OdEntry:
    """One object (sub-index) of the dictionary."""

    name: str  #: the parameter name
    index: int
    subindex: int
    object_name: str  #: the EDS ParameterName of the object (of the record for a sub-index)
    object_type: int  #: 7 VAR, 8 ARRAY, 9 RECORD
    entry_name: str  #: the EDS ParameterName of this sub-index
    datatype: int
    access: str
    pdo_mappable: bool
    default: int | None  #: None: the EDS states none (the twin's value is its firmware's)
    node_relative: bool
    low: int | None = None
    high: int | None = None


@dataclass(frozen=True, slots=True)
class Deviation:
    """Where the twin differs from ZeroErr's EDS, and why."""

    index: int
    subindex: int
    field: str  #: "default", "access", "pdo_mappable", "datatype", "object_type" (of the whole object)
    vendor: object
    twin: object
    evidence: str

    def __str__(self) -> str:
        def fmt(v: object) -> str:
            if self.field == "datatype" and isinstance(v, int):
                return {0x0003: "INTEGER16", 0x0004: "INTEGER32"}.get(v, f"0x{v:04X}")
            if isinstance(v, int) and not isinstance(v, bool) and abs(v) > 9:
                return f"-0x{-v:X}" if v < 0 else f"0x{v:X}"
            return str(v)
        return (f"0x{self.index:04X}:{self.subindex:02X} {self.field}: EDS {fmt(self.vendor)}, twin {fmt(self.twin)}"
                f" - {self.evidence}")


#: (index, subindex) -> the parameter it is (names the Modbus table or the firmware already uses)
BINDING: dict[tuple[int, int], str] = {
    (0x1000, 0): "device_type",
    (0x1001, 0): "error_register",
    (0x1005, 0): "cob_id_sync",
    (0x1006, 0): "communication_cycle_period",
    (0x100C, 0): "guard_time",
    (0x100D, 0): "life_time_factor",
    (0x1014, 0): "cob_id_emcy",
    (0x1017, 0): "producer_heartbeat_time",
    (0x1018, 0): "identity_highest_subindex",
    (0x1018, 1): "vendor_id",
    (0x1018, 2): "product_code",
    (0x1018, 3): "revision_number",
    (0x2205, 0): "analog_input",
    (0x22A2, 0): "part_of_power_temperature",  # Modbus 0x0078 (E11)
    (0x603F, 0): "error_code",
    (0x6040, 0): "controlword",
    (0x6041, 0): "statusword",
    (0x6060, 0): "modes_of_operation",
    (0x6061, 0): "modes_of_operation_display",
    (0x6062, 0): "given_position",
    (0x6064, 0): "actual_position",
    (0x6065, 0): "max_position_error",
    (0x6067, 0): "position_reaches_set_precision",
    (0x6068, 0): "time_setting_of_achieving_position",
    (0x606B, 0): "given_speed",
    (0x606C, 0): "current_speed",
    (0x6071, 0): "target_torque",
    (0x6077, 0): "torque_actual_value",
    (0x6078, 0): "motor_current",
    (0x6079, 0): "bus_voltage",
    (0x607A, 0): "target_absolute_position",
    (0x607D, 0): "software_position_limit_highest_subindex",
    (0x607D, 1): "min_position_limit_value",
    (0x607D, 2): "max_position_limit_value",
    (0x6080, 0): "max_speed",
    (0x6081, 0): "profile_speed",
    (0x6083, 0): "profile_acceleration",
    (0x6084, 0): "profile_deceleration",
    (0x6085, 0): "quick_stop_deceleration",
    (0x60C0, 0): "interpolation_sub_mode_select",
    (0x60C1, 0): "interpolation_data_record_highest_subindex",
    (0x60C1, 1): "interpolation_data_record_1",
    (0x60C1, 2): "interpolation_data_record_2",
    (0x60C2, 0): "interpolation_time_period_highest_subindex",
    (0x60C2, 1): "interpolation_time_period_value",
    (0x60C2, 2): "interpolation_time_index",
    (0x60F4, 0): "position_error",
    (0x60FF, 0): "target_speed",
    (0x6502, 0): "supported_drive_modes",
}
for _n in range(1, 5):
    for _kind, _comm, _map in (("rpdo", 0x1400, 0x1600), ("tpdo", 0x1800, 0x1A00)):
        BINDING[(_comm + _n - 1, 0)] = f"{_kind}{_n}_highest_subindex"
        BINDING[(_comm + _n - 1, 1)] = f"{_kind}{_n}_cob_id"
        BINDING[(_comm + _n - 1, 2)] = f"{_kind}{_n}_transmission_type"
        BINDING[(_comm + _n - 1, 3)] = f"{_kind}{_n}_inhibit_time"
        BINDING[(_comm + _n - 1, 5)] = f"{_kind}{_n}_event_timer"
        BINDING[(_map + _n - 1, 0)] = f"{_kind}{_n}_mapped_objects"
        for _i in range(1, 9):
            BINDING[(_map + _n - 1, _i)] = f"{_kind}{_n}_mapping_{_i}"

_IP = "eRunner manual v1.7 section 5.7 runs interpolated position mode (0x6060 = 7, fig 5-38)"
#: every difference of the twin from ZeroErr's EDS (checked against the export by the tests)
DEVIATIONS: tuple[Deviation, ...] = (
    *(Deviation(0x1400 + n, 0, "default", 4, 5, "the EDS lists sub-indices 1, 2, 3 and 5 of this record: the "
                "highest sub-index supported is 5 (CiA 301); the file's own value contradicts its listing")
      for n in range(4)),
    *(Deviation(0x1800 + n, 0, "default", 4, 5, "as for 0x1400: the EDS lists sub-index 5 (event timer)")
      for n in range(4)),
    Deviation(0x606B, 0, "access", "rww", "ro", "the velocity demand value is the drive's own output (CiA 402: "
              "ro; the same quantity is the read-only Modbus register 0x006C given speed): a write is refused with "
              "0x06010002"),
    Deviation(0x607D, 1, "default", -0x80000000, 0, "the same firmware as over Modbus (registers 0x00BD/0x00BF, "
              "listed without defaults in Modbus manual v1.6): the twin powers up with 0/0, which it takes as no "
              "software limit (min >= max, an assumption); the EDS's full range means the same: no limit"),
    Deviation(0x607D, 2, "default", 0x7FFFFFFF, 0, "as 0x607D:01"),
    *(Deviation(i, 0, "default", v, f"the model's {what} (sim.erob.power_on_defaults)",
                f"the same firmware as over Modbus (one set of power-on values for every protocol); {v} is a "
                "generic eDriver default: on a 524288-count output turn it is at most 0.02 rev/s (or rev/s^2)")
      for i, v, what in ((0x6081, 10000, "max speed / 4"), (0x6083, 200, "max speed per s"),
                         (0x6084, 200, "max speed per s"))),
    *(Deviation(i, 0, "object_type", "ARRAY (0x8)", "RECORD (0x9)",
                "CiA 301 defines the PDO mapping parameter as a RECORD; with ZeroErr's ARRAY the canopen package's "
                "PdoMap.save() writes no mapping entry (it iterates the array's current length, which it has just "
                "set to 0), so a remap by canopen's PDO API fails (0x06040041) with the vendor file")
      for i in (*range(0x1600, 0x1604), *range(0x1A00, 0x1A04))),
    Deviation(0x6502, 0, "default", 0x38D, 0x3CD, f"bit 6 (IP) set: {_IP}; the EDS has 0x60C0-0x60C2 too"),
    Deviation(0x60C1, 1, "datatype", 0x0003, 0x0004,
              f"INTEGER32: {_IP} with absolute set-points in cnt (\"motor moves to the interpolation value in absolute "
              "displacement\"); a 524288-count turn does not fit INTEGER16"),
)

_UNITS = {"communication_cycle_period": "us", "guard_time": "ms", "producer_heartbeat_time": "ms",
          "target_torque": "0.1 %", "torque_actual_value": "0.1 %"}


def _snake(text: str) -> str:
    return re.sub(r"[^0-9a-z]+", "_", text.lower()).strip("_")


@cache
def _data() -> dict[str, Any]:
    text = resources.files("joints.devices.erob").joinpath(DATA_FILE).read_text(encoding="utf-8")
    data: dict[str, Any] = json.loads(text)
    return data


def source() -> dict[str, Any]:
    """The extract's source (file name, sha256, FileInfo, DeviceInfo)."""
    return dict(_data()["source"])


@cache
def vendor_entries(taken: frozenset[str] = frozenset()) -> tuple[OdEntry, ...]:
    """The objects as ZeroErr's EDS states them (no deviation applied), named; a name derived from the EDS
    that another quantity of the drive already has (``taken``, e.g. Modbus ``position_offset`` is not CiA
    0x60B0) is prefixed ``canopen_``."""
    out: list[OdEntry] = []
    seen: set[str] = set()
    for obj in _data()["objects"]:
        index, oname, otype = obj["index"], obj["name"], obj["object_type"]
        for sub, name, dt, access, pdo, default, rel, low, high in obj["variables"]:
            pname = BINDING.get((index, sub))
            if pname is None:
                pname = _snake(oname) if otype == 7 else f"{_snake(oname)}_{_snake(name)}"
                if pname in seen:
                    pname = f"{pname}_{sub}"
                if pname in taken:
                    pname = f"canopen_{pname}"
            seen.add(pname)
            out.append(OdEntry(pname, index, sub, oname, otype, name, dt, access, bool(pdo), default, bool(rel),
                               low, high))
    return tuple(out)


@cache
def entries(taken: frozenset[str] = frozenset()) -> tuple[OdEntry, ...]:
    """The twin's objects: the EDS with :data:`DEVIATIONS` applied, by index and sub-index."""
    changes: dict[tuple[int, int], dict[str, object]] = {}
    records = {d.index for d in DEVIATIONS if d.field == "object_type"}
    for d in DEVIATIONS:
        if d.field != "object_type":
            changes.setdefault((d.index, d.subindex), {})[d.field] = d.twin
    out = []
    for e in vendor_entries(taken):
        change = changes.get((e.index, e.subindex))
        e = replace(e, **change) if change else e  # type: ignore[arg-type]
        out.append(replace(e, object_type=9) if e.index in records else e)
    return tuple(out)


def unit(name: str) -> str:
    return _UNITS.get(name, "")


#: names of the objects that have sub-indices (EDS ARRAY/RECORD ParameterName)
OBJECT_NAMES: dict[int, str] = {e.index: e.object_name for e in vendor_entries() if e.object_type != 7}
#: parameter names of the objects :data:`BINDING` names (the others are named from the EDS)
BOUND: frozenset[str] = frozenset(BINDING.values())
