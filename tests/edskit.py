"""ZeroErr's EDS for the tests: the extract in tests/data/zeroerr_eds.json (made by tests/data/erob_eds.py)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from joints.devices.canopen import EdsObject, EdsVariable, ObjectType, format_eds

DATA = Path(__file__).resolve().parent / "data" / "zeroerr_eds.json"


def vendor() -> dict[str, Any]:
    """The extract: {"source": ..., "objects": [{"index", "name", "object_type", "variables": [...]}]}."""
    data: dict[str, Any] = json.loads(DATA.read_text(encoding="utf-8"))
    return data


def vendor_eds(path: Path) -> Path:
    """ZeroErr's EDS (the extract's facts) as an EDS file again, as a user hands it to a tool."""
    objs = [EdsObject(o["index"], o["name"], ObjectType(o["object_type"]),
                      tuple(EdsVariable(o["index"], *v[:4], bool(v[4]), v[5], bool(v[6]), v[7], v[8])
                            for v in o["variables"]))
            for o in vendor()["objects"]]
    path.write_text(format_eds([("DeviceInfo", [("VendorName", "ZEROERR CONTROL")])], objs), encoding="utf-8")
    return path
