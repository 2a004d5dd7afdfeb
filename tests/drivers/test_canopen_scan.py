"""A CANopen scan finds any node - by its SDO answer, or by its heartbeat when it answers no SDO (STOPPED) - and
reports what it says it is, leaving out what it refuses; nothing is written, no NMT command is sent."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("mujoco")

import joints
from joints.cli import main
from joints.codecs import canopen as co
from joints.drivers.canopen_scan import scan
from simkit import served_can

CONFIG = """
backend = "sim"
[sim]
model = "erob_arm3.xml"
[buses.can]
protocol = "canopen"
[joints.joint1]
device = "erob"
bus = "can"
address = 3
[joints.joint2]
device = "erob"
bus = "can"
address = 5
[joints.joint3]
device = "erob"
bus = "can"
address = 127
"""


def config(tmp_path: Path) -> Path:
    cfg = tmp_path / "arm.toml"
    cfg.write_text(CONFIG)
    return cfg


def test_scan_finds_nodes_by_sdo_and_a_stopped_one_by_its_heartbeat(tmp_path: Path) -> None:
    with joints.open(config(tmp_path)) as rig:
        link: Any = rig.buses["can"].link
        link.sdo_download(5, 0x1017, 0, (50).to_bytes(2, "little"))  # node 5: heartbeat every 50 ms ...
        link.nmt(co.NmtCommand.STOP, 5)  # ... and STOPPED: no SDO any more
        link.poll(0.01)
        sent: list[str] = []
        rig.trace(lambda r: sent.append(r.meaning) if r.direction == "tx" else None)
        found = {r["address"]: r for r in scan(link, range(1, 8), listen=0.2)}
        rig.trace(None)
    assert sorted(found) == [3, 5]
    three, five = found[3], found[5]
    assert three["device_type"] == "0x00420192" and three["profile"] == 402  # ZeroErr's EDS
    assert three["vendor_id"] == "0x5A65726F" and "serial_number" not in three  # 0x1018:00 = 3
    assert three["modes"] == ["csp", "cst", "csv", "ip", "pp", "pt", "pv"]
    assert three["state"] == "SWITCH ON DISABLED" and three["error_code"] == "0x0000"
    assert "device_name" not in three and "software_version" not in three  # refused (0x06020000): left out
    assert five == {"address": 5, "nmt": "STOPPED", "sdo": "no answer (NMT STOPPED?)"}
    writes = [m for m in sent if "SDO write" in m or m.startswith("NMT")]
    assert writes == [], writes  # read-only: uploads (and aborts of unanswered ones) only
    assert any("SDO read 0x1000:00" in m for m in sent)


def test_cli_scan_of_a_canopen_sim_config(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scan", "--config", str(config(tmp_path)), "--bus", "can", "--json"]) == 0  # the whole range
    found = {f["address"]: f for f in json.loads(capsys.readouterr().out)}
    assert sorted(found) == [3, 5, 127]
    for f in found.values():
        d = f["details"]
        assert f["device"] is None and f["protocol"] == "canopen"  # any CANopen node: the bus does not say its make
        assert d["profile"] == 402 and d["state"] == "SWITCH ON DISABLED" and "pp" in d["modes"]
        assert d["nmt"] == "PRE_OPERATIONAL (boot-up)"  # heard powering on while the scan listened


def test_cli_scan_of_an_empty_canopen_range_says_so(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scan", "--config", str(config(tmp_path)), "--bus", "can", "--range", "6-9"]) == 1
    assert "nothing answered on can (canopen, addresses 6-9)" in capsys.readouterr().err


@pytest.mark.skipif(sys.platform == "win32", reason="udp_multicast serving is tested on POSIX")
def test_cli_scan_finds_the_nodes_of_a_served_config(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`joints sim serve` in another process, `joints scan` here over its udp_multicast channel."""
    pytest.importorskip("msgpack")
    with served_can(config(tmp_path)) as line:
        rc = main(["scan", "--interface", line["interface"], "--channel", line["channel"], "--udp-port",
                   str(line["udp_port"]), "--protocol", "canopen", "--range", "1-6", "--timeout", "0.2",
                   "--listen", "0.1", "--json"])
    assert rc == 0
    found = json.loads(capsys.readouterr().out)
    assert [f["address"] for f in found] == [3, 5]
    assert all(f["details"]["device_type"] == "0x00420192" and f["details"]["state"] == "SWITCH ON DISABLED"
               for f in found)
