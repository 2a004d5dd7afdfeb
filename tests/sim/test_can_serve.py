"""Driver in the loop over CAN: `joints sim serve` in another process on udp_multicast, our hardware driver here.

The served world runs on the wall clock, so these tests wait for the drive's own status on the bus - never a
fixed sleep - with generous upper bounds.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("mujoco")
pytest.importorskip("msgpack")
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="udp_multicast serving is tested on POSIX")

import joints
from joints.cli import main
from simkit import ROOT, served_can

SIM = """
backend = "sim"
[sim]
model = "erob_stand.xml"
[buses.can]
protocol = "erob-can"
[joints.joint1]
device = "erob"
model = "eRob90H120I-BHM-18CT"
bus = "can"
address = 5
"""

HARDWARE = """
backend = "hardware"
[buses.can]
protocol = "erob-can"
interface = "{interface}"
channel = "{channel}"
udp_port = {udp_port}
timeout = 0.25
[joints.joint1]
device = "erob"
model = "eRob90H120"
bus = "can"
address = 5
limits = {{ position = [-3.1, 3.1], velocity = 2.0, torque = 30.0 }}
"""


@pytest.fixture
def hardware_config(tmp_path: Path) -> Iterator[tuple[Path, dict[str, Any]]]:
    sim = tmp_path / "sim.toml"
    sim.write_text(SIM)
    with served_can(sim) as line:
        assert line["bus"] == "can" and line["interface"] == "udp_multicast"
        assert line["channel"].startswith("ff01:") and isinstance(line["udp_port"], int)
        hw = tmp_path / "hw.toml"
        hw.write_text(HARDWARE.format(**line))
        yield hw, line


def test_hardware_driver_runs_the_served_twin_over_udp_multicast(hardware_config: tuple[Path, dict[str, Any]]) -> None:
    hw, _line = hardware_config
    t0 = time.monotonic()
    with joints.open(hw) as rig:
        assert rig.backend == "hardware"
        j = rig.joints["joint1"]
        j.enable()
        j.move_to(0.6, velocity=1.0, acceleration=4.0, deceleration=4.0)
        reached = j.wait(timeout=20, poll=0.02, until=lambda s: j.read("status_of_achieving_position") == 4)
        assert reached.position == pytest.approx(0.6, abs=math.radians(0.1))
        j.set_velocity(0.5, acceleration=5.0)
        running = j.wait(timeout=10, poll=0.02, until=lambda s: abs(s.velocity - 0.5) < 0.02)
        assert running.moving and running.fault is None
        j.stop()
        stopped = j.wait(timeout=10, poll=0.02, until=lambda s: abs(s.velocity) < 0.01)
        assert stopped.enabled
        j.disable()
        assert rig.buses["can"].transport.echoes_dropped > 0  # udp_multicast echoed our requests: filtered
    assert time.monotonic() - t0 < 60


def test_scan_finds_the_served_node_with_its_model(hardware_config: tuple[Path, dict[str, Any]],
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    _hw, line = hardware_config
    rc = main(["scan", "--interface", line["interface"], "--channel", line["channel"], "--udp-port",
               str(line["udp_port"]), "--range", "3-7", "--timeout", "0.2", "--json"])
    assert rc == 0
    found = json.loads(capsys.readouterr().out)
    assert [f["address"] for f in found] == [5]
    assert found[0]["model"] == "eRob90H120I-BHM-18CT" and found[0]["serial"].startswith("090")
    assert found[0]["device"] == "erob" and found[0]["protocol"] == "erob-can" and found[0]["firmware"]


def test_serve_refuses_a_physical_interface(tmp_path: Path) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text(SIM.replace('protocol = "erob-can"', 'protocol = "erob-can"\ninterface = "socketcan"\n'
                                                          'channel = "can0"'))
    proc = subprocess.run([sys.executable, "-m", "joints", "sim", "serve", str(cfg)], capture_output=True, text=True,
                          cwd=ROOT, timeout=60, check=False)
    assert proc.returncode == 2
    assert "refusing to serve" in proc.stderr and "real CAN interface" in proc.stderr and "vcan" in proc.stderr
    assert "[buses.can.interface]" in proc.stderr
