"""Copy the test data from ../shared (beside the checkout) into tests/data and rewrite MANIFEST.json.

Usage: ``python tests/data/refresh.py [SHARED_DIR]`` (default: the ``shared`` folder next to the
repository). Run it when ../shared/vectors or ../shared/manuals change, then run the tests.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
#: vendored file (relative to tests/data) -> its source (relative to the shared folder)
FILES = {
    "vectors.json": "vectors/vectors.json",
    "ERRATA.md": "vectors/ERRATA.md",
    "manuals/erob-modbus-rtu-manual-v1.6-en.txt": "manuals/erob-modbus-rtu-manual-v1.6-en.txt",
    "manuals/erob-modbus-rtu-manual-v1.3-zh.txt": "manuals/erob-modbus-rtu-manual-v1.3-zh.txt",
    "manuals/erob-erunner-can-canopen-manual-v1.7-zh.txt": "manuals/erob-erunner-can-canopen-manual-v1.7-zh.txt",
    "manuals/mks-servo42d-57d-rs485-manual-v1.0.5.txt": "manuals/mks-servo42d-57d-rs485-manual-v1.0.5.txt",
    "manuals/zlac8015d-rs485-modbus-manual-v1.04.txt": "manuals/zlac8015d-rs485-modbus-manual-v1.04.txt",
}
MANIFEST = HERE / "MANIFEST.json"


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def default_shared() -> Path:
    return REPO.parent / "shared"


def main(argv: list[str]) -> int:
    shared = Path(argv[1]) if len(argv) > 1 else default_shared()
    if not shared.is_dir():
        print(f"no shared folder at {shared}", file=sys.stderr)
        return 1
    manifest = {}
    for dest, src in FILES.items():
        source = shared / src
        target = HERE / dest
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, target)
        manifest[dest] = {"source": src, "sha256": sha256(target)}
    MANIFEST.write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    print(f"copied {len(FILES)} files from {shared} into {HERE}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
