"""Firmware-quirk profiles (issue 24): per device and firmware version, data shared by the driver (workaround)
and the twin (reproduction), selected by the joint's ``firmware`` key. The ZLAC8015D's 0x200F polarity
(ERRATA DOC-ZLAC-1) end to end."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import pytest

from joints.config import parse
from joints.devices.quirks import DEFAULT_FIRMWARE, FIRMWARES, QUIRKS, ZLAC_SYNC_FLAG_AS_EXAMPLES, firmware_profile
from joints.devices.zlac.registers import ZLAC8015D, is_synchronous, sync_flag
from joints.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[2]
ERRATA = (ROOT / "tests" / "data" / "ERRATA.md").read_text(encoding="utf-8")
SYNC = ZLAC8015D["synchronous_asynchronous_control_status"].name


def base(firmware: str | None = None) -> dict[str, Any]:
    data: dict[str, Any] = tomllib.loads((ROOT / "joints" / "configs" / "zlac_diffdrive.toml").read_text())
    data["sim"]["direct"] = False
    for j in data["joints"].values():
        j["limits"] = {"velocity": 10.0, "position": [-100.0, 100.0]}
        if firmware is not None:
            j["firmware"] = firmware
    return data


def test_quirks_are_data_that_name_their_errata() -> None:
    for q in QUIRKS.values():
        assert q.errata in ERRATA, q
        assert q.behaviour and q.workaround
    for (family, name), prof in FIRMWARES.items():
        assert prof.family == family and prof.firmware == name and prof.quirks <= set(QUIRKS)
        assert all(QUIRKS[q].family == family for q in prof.quirks)
    for family, name in DEFAULT_FIRMWARE.items():
        assert (family, name) in FIRMWARES
    assert firmware_profile("zlac8015d").quirks == {ZLAC_SYNC_FLAG_AS_EXAMPLES}  # the default: as before
    assert firmware_profile("erob").quirks == frozenset()  # no known quirks: an empty default


def test_sync_flag_follows_the_firmware() -> None:
    examples, table = frozenset({ZLAC_SYNC_FLAG_AS_EXAMPLES}), frozenset()
    assert (sync_flag(True, examples), sync_flag(False, examples)) == (1, 0)  # section 3.2 examples
    assert (sync_flag(True, table), sync_flag(False, table)) == (0, 1)  # the chapter-4 table
    for quirks in (examples, table):
        assert is_synchronous(sync_flag(True, quirks), quirks) and not is_synchronous(sync_flag(False, quirks), quirks)


def test_firmware_key_is_validated_by_name() -> None:
    data = base("v9.99")
    with pytest.raises(ConfigError, match=r"joints\.left_wheel\.firmware") as e:
        parse(data)
    assert set(e.value.allowed or ()) == {"examples", "register-table"}
    erob = {"buses": {"b": {"protocol": "modbus-rtu"}},
            "joints": {"j": {"device": "erob", "bus": "b", "address": 1, "firmware": "examples"}}}
    with pytest.raises(ConfigError, match="no firmware profile"):
        parse(erob)
    assert parse(base("register-table")).joints["left_wheel"].firmware == "register-table"


def _sync_move(firmware: str | None, twin_quirks: frozenset[str] | None = None) -> tuple[Any, list[int], float]:
    """Both wheels enabled, one synchronous position move; the twin's 0x200F writes and how far the left wheel
    turned. ``twin_quirks`` replaces the twin's firmware (a drive whose firmware is not the configured one)."""
    pytest.importorskip("mujoco")
    import joints

    with joints.open(base(firmware)) as rig:
        twin = rig.sim.drives["left_wheel"]
        if twin_quirks is not None:
            twin.quirks = twin_quirks
        for j in rig.joints.values():
            j.enable()
        rig.sleep(0.3)
        drive = rig.joints["left_wheel"].driver.drive
        q0 = rig.sim.joint_position("left_wheel")
        drive.move_both(4096, 4096)
        rig.sleep(2.0)
        writes = [v for n, v in twin.write_log if n == SYNC]
        return twin, writes, rig.sim.joint_position("left_wheel") - q0


def test_default_firmware_writes_the_examples_flag_and_the_twin_moves_both_wheels() -> None:
    twin, writes, moved = _sync_move(None)
    assert writes == [1] and moved > 1.0 and not twin.ignored


def test_register_table_firmware_writes_the_tables_flag_and_its_twin_moves_both_wheels() -> None:
    twin, writes, moved = _sync_move("register-table")
    assert twin.quirks == frozenset() and writes == [0] and moved > 1.0 and not twin.ignored


def test_the_workaround_matters_a_driver_for_the_other_firmware_does_not_start_the_wheels() -> None:
    twin, writes, moved = _sync_move("register-table", twin_quirks=frozenset({ZLAC_SYNC_FLAG_AS_EXAMPLES}))
    assert writes == [0] and abs(moved) < 1e-3
    assert any("START_SYNC in asynchronous control" in text for _, text in twin.ignored)


def test_the_served_twin_has_the_configured_firmware(tmp_path: Path) -> None:
    pytest.importorskip("mujoco")
    from joints.rig import sim_world

    world = sim_world(parse(base("register-table")))
    assert world.drives["left_wheel"].quirks == frozenset()
    assert sim_world(parse(base())).drives["left_wheel"].quirks == {ZLAC_SYNC_FLAG_AS_EXAMPLES}
