"""The audit table of docs/mks-firmware.md (the V1.0.6-V1.0.9 commands) against the code: a built native code is
a command of the codec, a built Modbus request is in the newest profile's map and absent from the map of a
profile without it, and every test the table names exists."""

from __future__ import annotations

import re
from pathlib import Path

from joints.codecs import mks
from joints.devices.mks.modbus import MKS_MODBUS, MKS_MODBUS_OF
from joints.devices.mks.native import Command

ROOT = Path(__file__).resolve().parents[2]
TEXT = (ROOT / "docs" / "mks-firmware.md").read_text(encoding="utf-8")
AUDIT = TEXT[TEXT.index("## Audit"):TEXT.index("## Not built yet")]
ROWS = [[c.strip() for c in line.strip().strip("|").split("|")] for line in AUDIT.splitlines()
        if line.startswith("| ") and not line.startswith("| command")]
TESTS = "\n".join(p.read_text(encoding="utf-8") for p in (ROOT / "tests").rglob("test_mks*.py"))
FUNCTION = {"FC04": 0x04, "FC06": 0x06, "FC16": 0x10}


def _codes(cell: str) -> list[int]:
    """The native codes of a cell ("0x96, 0x97"); none for "-" or a note in parentheses (an older command)."""
    return [] if cell.startswith("(") else [int(c, 16) for c in re.findall(r"0x([0-9A-F]{2})", cell)]


def test_the_table_has_every_added_command() -> None:
    assert len(ROWS) >= 24 and all(len(r) == 6 for r in ROWS), ROWS
    codes = {c for r in ROWS if r[4] == "yes" for c in _codes(r[2])}
    added = {0x35, 0x36, 0x46, 0x47, 0x48, 0x9D, 0x3B, 0x83, 0xF6, 0x00, 0x95, 0x96, 0x97, 0x4A, 0x4B, 0x50, 0x40,
             0x42, 0x98, 0x01, 0x91, 0x99, 0x9F, 0x94}
    assert codes == added


def test_each_built_row_is_in_the_code_and_its_tests_exist() -> None:
    for command, firmware, native, modbus, built, tests in ROWS:
        if built != "yes":
            assert built == "no" and tests == "-", command
            continue
        for code in _codes(native):
            assert code in set(Command) and code in mks.REQUEST_DATA_LENGTH, (command, hex(code))
        for fc, address in re.findall(r"(FC\d\d) 0x([0-9A-F]{4})", modbus):
            assert MKS_MODBUS.find(FUNCTION[fc], int(address, 16)) is not None, (command, fc, address)
        names = re.findall(r"`(test_\w+)`", tests)
        assert names, command
        for name in names:
            assert re.search(rf"^def {name}\(", TESTS, re.MULTILINE), (command, name)
        assert firmware in ("V1.0.6", "V1.0.7", "V1.0.8", "V1.0.9"), command


def test_a_modbus_request_only_a_later_firmware_has_is_in_its_profiles_maps() -> None:
    """FC16 0x0094 (V1.0.6) is absent from the v1.0.5 map; FC04 0x003B reads two statuses from V1.0.7."""
    assert MKS_MODBUS_OF["v1.0.5"].find(0x10, 0x94) is None
    assert MKS_MODBUS_OF["v1.0.6"].find(0x10, 0x94) is not None
    assert [len(MKS_MODBUS_OF[fw].block(0x04, 0x3B).fields) for fw in ("v1.0.5", "v1.0.6", "v1.0.9")] == [1, 1, 2]
