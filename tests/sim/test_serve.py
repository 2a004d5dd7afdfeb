"""Driver in the loop: `joints sim serve` in another process, reached over a real pseudo-terminal.

The served world runs on the wall clock (that is its job), so these tests wait for the drive's own
status on the bus - never a fixed sleep - with generous upper bounds.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("mujoco")
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals need POSIX")

import joints

CONFIG = """
backend = "{backend}"
[sim]
model = "erob_stand.xml"
[buses.rs485]
protocol = "modbus-rtu"
port = "{port}"
baudrate = 115200
timeout = 0.5
[joints.joint1]
device = "erob"
bus = "rs485"
address = 2
limits = {{ position = [-3.1, 3.1], velocity = 2.0, torque = 20.0 }}
"""


@pytest.fixture
def served(tmp_path: Path, sim_server) -> Iterator[tuple[str, Path]]:  # type: ignore[no-untyped-def]
    cfg = tmp_path / "robot.toml"
    cfg.write_text(CONFIG.format(backend="sim", port="/dev/null"))
    with sim_server(cfg) as port:
        hw = tmp_path / "hw.toml"
        hw.write_text(CONFIG.format(backend="hardware", port=port))
        yield port, hw


def _script(rig: joints.Rig) -> float:
    """The same user script for both backends: enable, move, wait for 'target reached' and standstill, read."""
    j = rig.joints["joint1"]
    j.write("position_reaches_set_precision", 20)
    j.enable()
    j.move_to(0.8, velocity=1.0, acceleration=4.0, deceleration=4.0)
    j.wait(timeout=20, poll=0.02, until=lambda s: j.read("status_of_achieving_position") == 4)
    # settled: the drive's own speed feedback is below one count per millisecond
    return j.wait(timeout=5, poll=0.02, until=lambda s: abs(s.velocity) < 0.012).position


def test_same_script_sim_and_served_hardware_agree(served: tuple[str, Path], tmp_path: Path) -> None:
    _port, hw = served
    sim_cfg = tmp_path / "sim.toml"
    sim_cfg.write_text(CONFIG.format(backend="sim", port="/dev/ttyUSB0"))
    with joints.open(sim_cfg) as rig:
        assert rig.backend == "sim"
        in_process = _script(rig)
    t0 = time.monotonic()
    with joints.open(hw) as rig:
        assert rig.backend == "hardware"
        over_pty = _script(rig)
    assert time.monotonic() - t0 < 30
    assert abs(in_process - 0.8) < math.radians(0.1)
    assert abs(over_pty - in_process) < math.radians(0.1), (in_process, over_pty)


def test_minimalmodbus_master_drives_served_erob(served: tuple[str, Path]) -> None:
    minimalmodbus = pytest.importorskip("minimalmodbus")
    port, _hw = served
    inst = minimalmodbus.Instrument(port, 2, mode=minimalmodbus.MODE_RTU)
    inst.serial.baudrate = 115200
    inst.serial.timeout = 0.5
    inst.clear_buffers_before_each_transaction = True
    try:
        big = minimalmodbus.BYTEORDER_BIG  # Hi word first, as the eRob manual
        inst.write_register(0x0040, 3, functioncode=6)  # position control
        inst.write_register(0x0041, 1, functioncode=6)  # move absolute
        inst.write_long(0x0047, 100000, signed=True, byteorder=big)  # profile speed
        inst.write_long(0x0049, 400000, signed=True, byteorder=big)  # acceleration
        inst.write_long(0x004B, 400000, signed=True, byteorder=big)  # deceleration
        inst.write_long(0x0045, 0, signed=True, byteorder=big)  # relative 0
        inst.write_register(0x00F0, 1, functioncode=6)  # enable
        deadline = time.monotonic() + 5
        while inst.read_register(0x0063) != 1:  # wait for "motor on" (the manual's 500 ms)
            assert time.monotonic() < deadline
        inst.write_long(0x0043, 131072, signed=True, byteorder=big)  # quarter turn
        inst.write_register(0x00F1, 1, functioncode=6)  # start
        deadline = time.monotonic() + 15
        while inst.read_register(0x0063) != 4:
            assert time.monotonic() < deadline, "target not reached"
        pos = inst.read_long(0x0066, signed=True, byteorder=big)
        assert abs(pos - 131072) <= 100
        inst.write_register(0x00F0, 0, functioncode=6)
        assert inst.read_register(0x0063) == 0
    finally:
        inst.serial.close()
