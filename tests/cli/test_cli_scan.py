"""`joints scan` on a CAN bus of twins (in process): every node, its model string, serial number and versions."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("mujoco")

from joints.cli import main

CONFIG = """
backend = "sim"
[sim]
model = "erob_arm3.xml"
[buses.can]
protocol = "erob-can"
[joints.joint1]
device = "erob"
model = "eRob80H100I-BM-18CN"
bus = "can"
address = 3
[joints.joint2]
device = "erob"
model = "eRob110H160T-FHS-18ET"
bus = "can"
address = 17
[joints.joint3]
device = "erob"
model = "eRob70H50"
bus = "can"
address = 127
"""


def test_scan_finds_every_twin_with_its_model(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = tmp_path / "arm.toml"
    cfg.write_text(CONFIG)
    assert main(["scan", "--config", str(cfg), "--bus", "can", "--json"]) == 0  # the whole range 1..127
    found = {f["address"]: f for f in json.loads(capsys.readouterr().out)}
    assert sorted(found) == [3, 17, 127]
    assert found[3]["model"] == "eRob80H100I-BM-18CN"
    assert found[17]["model"] == "eRob110H160T-FHS-18ET" and found[17]["serial"].startswith("110")
    assert found[127]["model"].startswith("eRob70H50")
    for f in found.values():
        assert set(f) == {"bus", "protocol", "device", "address", "model", "serial", "firmware", "details"}
        assert f["device"] == "erob" and f["protocol"] == "erob-can" and f["bus"] == "can" and f["firmware"]


def test_scan_table_shows_versions(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = tmp_path / "arm.toml"
    cfg.write_text(CONFIG)
    assert main(["scan", "--config", str(cfg), "--range", "3"]) == 0
    out = capsys.readouterr().out
    assert "eRob80H100I-BM-18CN" in out and "module_version=MC" in out and "hardware_version=" in out


def test_scan_of_an_empty_range_says_so(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = tmp_path / "arm.toml"
    cfg.write_text(CONFIG)
    assert main(["scan", "--config", str(cfg), "--bus", "can", "--range", "4-6"]) == 1
    assert "nothing answered on can (erob-can, addresses 4-6)" in capsys.readouterr().err


def test_scan_needs_a_bus(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scan"]) == 2
    assert "--port" in capsys.readouterr().err


def test_scan_of_a_serial_bus_probes_addresses_1_to_32_unless_given_a_range(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Without ``--range`` a serial bus is probed at 1..32 (a full 1..247 sweep takes minutes on hardware): drives at
    1 and 32 are found, one at 33 only when asked for (the served test scans a short range over the pty)."""
    from clikit import LIMITS, write_world

    joints = ('[joints.a]\ndevice = "erob"\nbus = "rs485"\naddress = 1\n' + LIMITS
              + '[joints.b]\ndevice = "erob"\nbus = "rs485"\naddress = 32\n' + LIMITS
              + '[joints.m]\ndevice = "mks-servo42d"\nbus = "rs485"\naddress = 33\n')
    cfg = write_world(tmp_path, buses='[buses.rs485]\nprotocol = "modbus-rtu"\n', joints=joints)
    assert main(["scan", "--config", str(cfg), "--json"]) == 0
    assert [(f["address"], f["device"]) for f in json.loads(capsys.readouterr().out)] == [(1, "erob"), (32, "erob")]
    assert main(["scan", "--config", str(cfg), "--json", "--range", "30-40"]) == 0
    assert [(f["address"], f["device"]) for f in json.loads(capsys.readouterr().out)] == [(32, "erob"), (33, "mks")]
