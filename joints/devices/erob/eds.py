"""The eRob's EDS as the twin implements it: ZeroErr's EDS with the listed deviations.

Rule: pure (data in, text out). The objects are :data:`~joints.devices.erob.canopen.EROB_CANOPEN`
(read from ZeroErr's EDS, :mod:`joints.devices.erob.od`); the defaults are the twin's power-on
values where given (``values``: parameter name -> value, e.g. the sim's power-on defaults of a
model), else the table's. The ``[Comments]`` section lists every deviation with its evidence.
"""

from __future__ import annotations

from collections.abc import Mapping

from joints.devices.canopen import EdsObject, EdsVariable, ObjectType, format_eds, parse_eds
from joints.devices.erob.canopen import objects
from joints.devices.erob.od import DEVIATIONS, source
from joints.devices.erob.params import CANOPEN_ENTRIES

__all__ = ["eds_objects", "eds_text", "parse_eds"]


def eds_objects(node: int = 1, values: Mapping[str, int] | None = None) -> list[EdsObject]:
    """The twin's objects as EDS objects (defaults: ``values`` where given, COB-IDs ``$NODEID``-relative)."""
    kinds = {e.index: e.object_type for e in CANOPEN_ENTRIES}
    names = {e.index: e.object_name for e in CANOPEN_ENTRIES}
    limits = {(e.index, e.subindex): (e.low, e.high) for e in CANOPEN_ENTRIES}
    groups: dict[int, list[EdsVariable]] = {}
    for name, o in objects():
        default = o.default_value
        if values is not None and name in values and not o.node_relative:
            default = round(values[name] / o.scale)
        lo, hi = limits[(o.index, o.subindex)]
        groups.setdefault(o.index, []).append(EdsVariable(
            o.index, o.subindex, o.name, int(o.datatype), o.access.value, o.pdo_mappable, default, o.node_relative,
            lo, hi))
    return [EdsObject(index, names[index], ObjectType(kinds[index]), tuple(vs))
            for index, vs in sorted(groups.items())]


def eds_text(node: int = 1, values: Mapping[str, int] | None = None) -> str:
    """The EDS (CiA 306) of the eRob twin at node ``node``."""
    src = source()
    dev = src.get("DeviceInfo", {})
    head = (f"eRob twin of the joints package: ZeroErr's {src['file']} (sha256 {src['sha256'][:16]}...) "
            f"with {len(DEVIATIONS)} deviations:")
    comments = [head, *(str(d) for d in DEVIATIONS)]
    info = [
        ("FileInfo", [("FileName", f"erob_node{node}.eds"), ("FileVersion", "1"), ("FileRevision", "1"),
                      ("EDSVersion", "4.0"), ("Description", "ZeroErr eRob (joints twin), from " + src["file"]),
                      ("CreatedBy", "joints")]),
        ("DeviceInfo", [("VendorName", "ZeroErr"), ("VendorNumber", dev.get("VendorNumber", "0")),
                        ("ProductName", "eRob (joints twin)"), ("ProductNumber", dev.get("ProductNumber", "0")),
                        ("RevisionNumber", dev.get("RevisionNumber", "0")), ("OrderCode", "0"),
                        *((f"BaudRate_{b}", "1" if b == 1000 else "0") for b in (10, 20, 50, 125, 250, 500, 800,
                                                                                 1000)),
                        ("SimpleBootUpMaster", "0"), ("SimpleBootUpSlave", "1"), ("Granularity", "8"),
                        ("DynamicChannelsSupported", "0"), ("CompactPDO", "0"), ("GroupMessaging", "0"),
                        ("NrOfRXPDO", "4"), ("NrOfTXPDO", "4"), ("LSS_Supported", "0")]),
        ("DummyUsage", [(f"Dummy000{i}", "0" if i == 1 else "1") for i in range(1, 8)]),
        ("Comments", [("Lines", str(len(comments))), *((f"Line{i}", c) for i, c in enumerate(comments, 1))]),
    ]
    return format_eds(info, eds_objects(node, values))
