"""Driver in the loop for the ZLAC8015D: ``joints sim serve`` runs the differential drive
(models/zlac_diffdrive.xml) in another process, in real time, and exposes its RS485 bus as a
pseudo-terminal.

* An independent Modbus master (minimalmodbus) drives the emulated ZLAC8015D with the manual's
  velocity-mode sequence: control mode, enable, both target velocities in one FC16, poll the
  actual velocities, stop.
* Our own hardware backend (serial transport on the pty, the wall clock) does the same through
  the Joint / Rig API.

The served world runs on the wall clock (that is its job), so these tests wait for the drive's
own feedback on the bus - never a fixed sleep - in loops with generous upper bounds. Polling also
keeps the drive's communication-offline watchdog (0x2000, 1000 ms by default) fed.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("mujoco")
pytest.importorskip("serial")
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals need POSIX")

import joints

ROOT = Path(__file__).resolve().parents[2]
RPM = 2 * math.pi / 60

CONFIG = """
backend = "{backend}"
[sim]
model = "zlac_diffdrive.xml"
[buses.rs485]
protocol = "modbus-rtu"
port = "{port}"
baudrate = 115200
timeout = 0.5
[joints.left_wheel]
device = "zlac8015d"
bus = "rs485"
address = 1
channel = "left"
limits = {{ velocity = 30.0 }}
motion = {{ acceleration = 50.0 }}
[joints.right_wheel]
device = "zlac8015d"
bus = "rs485"
address = 1
channel = "right"
limits = {{ velocity = 30.0 }}
motion = {{ acceleration = 50.0 }}
"""

# ZLAC8015D registers (manual chapter 4)
CONTROL_MODE, CONTROL_WORD = 0x200D, 0x200E
TARGET_VELOCITY_LEFT = 0x2088  # 0x2089 right; r/min, signed
ACTUAL_VELOCITY_LEFT = 0x20AB  # 0x20AC right; 0.1 r/min, signed
ERROR_CODE_LEFT = 0x20A5  # 0x20A6 right
VELOCITY_MODE, ENABLE, STOP = 3, 0x08, 0x07


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory, sim_server) -> Iterator[tuple[str, Path]]:  # type: ignore[no-untyped-def]
    """``joints sim serve`` of the diff drive; yields (pty port, a hardware config pointing at it)."""
    tmp = tmp_path_factory.mktemp("zlac_serve")
    cfg = tmp / "robot.toml"
    cfg.write_text(CONFIG.format(backend="sim", port="/dev/null"))
    with sim_server(cfg) as port:
        hw = tmp / "hw.toml"
        hw.write_text(CONFIG.format(backend="hardware", port=port))
        yield port, hw


def test_minimalmodbus_master_drives_the_served_zlac(served: tuple[str, Path]) -> None:
    minimalmodbus = pytest.importorskip("minimalmodbus")
    port, _hw = served
    inst = minimalmodbus.Instrument(port, 1, mode=minimalmodbus.MODE_RTU)
    inst.serial.baudrate = 115200
    inst.serial.timeout = 0.5
    inst.clear_buffers_before_each_transaction = True
    try:
        # the manual's velocity-mode example (3.3): mode, ramps, enable, both targets in ONE FC16
        inst.write_register(CONTROL_MODE, VELOCITY_MODE, functioncode=6)
        inst.write_registers(0x2080, [300, 300, 300, 300])  # acceleration / deceleration times L/R [ms]
        inst.write_register(CONTROL_WORD, ENABLE, functioncode=6)
        assert inst.read_register(CONTROL_MODE) == VELOCITY_MODE
        command = (100, -60)  # r/min, left / right
        inst.write_registers(TARGET_VELOCITY_LEFT, [v & 0xFFFF for v in command])  # FC16, both wheels
        assert inst.read_registers(TARGET_VELOCITY_LEFT, 2) == [100, (-60) & 0xFFFF]
        # poll until both wheels run within 3 % of the command (this also feeds the 1 s watchdog)
        deadline = time.monotonic() + 10
        while True:
            raw = inst.read_registers(ACTUAL_VELOCITY_LEFT, 2)
            actual = [(w - 0x10000 if w & 0x8000 else w) / 10.0 for w in raw]  # 0.1 r/min, signed
            if all(abs(a - c) <= 0.03 * abs(c) for a, c in zip(actual, command)):
                break
            assert time.monotonic() < deadline, f"wheels at {actual} r/min, commanded {command}"
        # it holds the speed while we keep talking (the watchdog never trips): poll for 0.5 s more
        # (the ramp ends at 300 ms), the last readings stay within 3 %
        seen = []
        until = time.monotonic() + 0.5
        while time.monotonic() < until:
            seen.append(inst.read_register(ACTUAL_VELOCITY_LEFT, signed=True) / 10.0)
        assert len(seen) >= 10 and all(v == pytest.approx(100, rel=0.03) for v in seen[-10:]), seen
        assert inst.read_registers(ERROR_CODE_LEFT, 2) == [0, 0]
        # stop (0x07): the power stage switches off and the wheels coast down
        inst.write_registers(TARGET_VELOCITY_LEFT, [0, 0])
        inst.write_register(CONTROL_WORD, STOP, functioncode=6)
        assert (inst.read_register(0x20A2) >> 8, inst.read_register(0x20A2) & 0xFF) == (0, 0)  # motor state off
    finally:
        inst.serial.close()


def test_our_hardware_backend_drives_the_served_zlac(served: tuple[str, Path]) -> None:
    _port, hw = served
    t0 = time.monotonic()
    with joints.open(hw) as rig:
        assert rig.backend == "hardware" and rig.world is None
        left, right = rig.joints["left_wheel"], rig.joints["right_wheel"]
        left.enable()
        right.enable()
        rig.set_velocities({"left_wheel": 100 * RPM, "right_wheel": 100 * RPM})  # one FC16
        deadline = time.monotonic() + 10
        while True:
            s = rig.read_states()  # one FC03 for both wheels
            if all(abs(st.velocity - 100 * RPM) <= 0.03 * 100 * RPM for st in s.values()):
                break
            assert time.monotonic() < deadline, s
        rig.set_velocities({"left_wheel": 0.0, "right_wheel": 0.0})
    # leaving the rig stopped and disabled the drive
    assert time.monotonic() - t0 < 15
