"""Derive the eRob object dictionary (a JSON extract) from ZeroErr's EDS.

Usage: ``python tests/data/erob_eds.py [EDS_FILE]`` (default: ``../shared/vendor/erob/ZeroErr Driver_V1.5.eds``
beside the repository). Writes the same extract to ``joints/devices/erob/zeroerr_eds.json`` (what the twin and
the driver read) and ``tests/data/zeroerr_eds.json`` (what the tests compare them with).

The extract keeps only the facts of each object (index, sub-index, name, data type, access, PDO flag,
default, limits) and the file's identity (name, sha256, FileInfo/DeviceInfo): ZeroErr publishes the EDS in
its public repositories without a stated licence for the file, so the file itself is not redistributed.
Parsing is :func:`joints.devices.canopen.parse_eds`; nothing is edited by hand.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
sys.path.insert(0, str(REPO))

from joints.devices.canopen import parse_eds

TARGETS = (REPO / "joints" / "devices" / "erob" / "zeroerr_eds.json", HERE / "zeroerr_eds.json")
INFO_KEYS = {"FileInfo": ("FileName", "FileVersion", "FileRevision", "EDSVersion", "Description", "CreationDate",
                          "ModificationDate", "CreatedBy"),
             "DeviceInfo": ("VendorName", "VendorNumber", "ProductName", "ProductNumber", "RevisionNumber",
                            "NrOfRXPDO", "NrOfTXPDO", "BaudRate_1000")}


def extract(path: Path) -> dict[str, object]:
    raw = path.read_bytes()
    info, objects = parse_eds(raw.decode("latin-1"))
    return {
        "source": {
            "file": path.name,
            "sha256": hashlib.sha256(raw).hexdigest(),
            "where": "ZeroErr's EDS for its eDriver CANopen slave, as published in the public GitHub repositories "
                     "ZeroErrControl/eRob_CANopen_Python and (as ZeroErrDriver.eds) ZeroErrControl/eRob_CANopen_Linux",
            "made_by": "tests/data/erob_eds.py",
            **{section: {k: info[section][k] for k in keys if k in info.get(section, {})}
               for section, keys in INFO_KEYS.items()},
        },
        "objects": [
            {"index": o.index, "name": o.name, "object_type": int(o.object_type),
             "variables": [[v.subindex, v.name, v.datatype, v.access, int(v.pdo_mappable), v.default,
                            int(v.node_relative), v.low, v.high] for v in o.variables]}
            for o in objects
        ],
        "variable_fields": ["subindex", "name", "datatype", "access", "pdo_mappable", "default", "node_relative",
                            "low", "high"],
    }


def dumps(data: dict[str, object]) -> str:
    """One object per line block, one variable per line (diffs stay readable)."""
    head = json.dumps({k: v for k, v in data.items() if k != "objects"}, indent=1, sort_keys=True)
    objs = []
    for o in data["objects"]:  # type: ignore[attr-defined]
        vs = ",\n   ".join(json.dumps(v, ensure_ascii=False) for v in o["variables"])
        objs.append(f' {{"index": {o["index"]}, "name": {json.dumps(o["name"])}, "object_type": {o["object_type"]},'
                    f'\n  "variables": [\n   {vs}]}}')
    return head[:-2] + ',\n "objects": [\n' + ",\n".join(objs) + "\n ]\n}\n"


def main(argv: list[str]) -> int:
    path = Path(argv[1]) if len(argv) > 1 else REPO.parent / "shared" / "vendor" / "erob" / "ZeroErr Driver_V1.5.eds"
    text = dumps(extract(path))
    json.loads(text)  # well-formed
    for target in TARGETS:
        target.write_text(text, encoding="utf-8")
        print(f"wrote {target.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
