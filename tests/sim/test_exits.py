"""Leaving a rig by any path stops and disables what it enabled - checked on a served twin across processes.

A child process opens a hardware rig on the pty of ``joints sim serve``, enables an eRob, runs it in
speed mode and then leaves: normally, by an exception, by Ctrl-C (SIGINT), SIGTERM, SIGHUP, or by
simply ending without ever closing the rig. Afterwards the test reads the served drive itself: it
must be disabled with no fault (an orderly stop, not the watchdog catching a dead host) and its
watchdog set back to what it was before (0).
"""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from contextlib import AbstractContextManager as ContextManager
from pathlib import Path

import pytest

pytest.importorskip("mujoco")
pytest.importorskip("serial")

from joints.clock import MonotonicClock
from joints.devices.erob.registers import AchieveStatus
from joints.drivers.erob_modbus import ErobModbusDriver
from joints.link.modbus import ModbusLink
from joints.transports.serial import SerialTransport

ROOT = Path(__file__).resolve().parents[2]

SERVED = """backend = "sim"
[sim]
model = "erob_stand.xml"
[buses.rs485]
protocol = "modbus-rtu"
[joints.joint1]
device = "erob"
bus = "rs485"
address = 2
"""

CHILD = """
import os, signal, sys, time
import joints
cfg = {{"backend": "hardware",
        "buses": {{"rs485": {{"protocol": "modbus-rtu", "port": {port!r}, "timeout": 0.2}}}},
        "joints": {{"joint1": {{"device": "erob", "bus": "rs485", "address": 2}}}}}}
how = {how!r}
if how == "never-closed":
    rig = joints.open(cfg)
    rig.joints["joint1"].enable(); rig.joints["joint1"].set_velocity(1.0)
    rig.joints["joint1"].wait(timeout=10, until=lambda s: s.velocity > 0.95)
    print("ready", rig.joints["joint1"].state().velocity, flush=True)
    sys.stdin.readline()
    sys.exit(0)  # leaves without rig.close(): the atexit hook closes it
with joints.open(cfg) as rig:
    j = rig.joints["joint1"]
    j.enable(); j.set_velocity(1.0)  # the driver waits the manual's 500 ms after enable itself
    j.wait(timeout=10, until=lambda s: s.velocity > 0.95)  # running at speed
    print("ready", j.state().velocity, flush=True)
    if how == "exception":
        sys.stdin.readline()
        raise RuntimeError("controller bug")
    if how == "normal":
        sys.stdin.readline()
    else:
        while True:
            rig.sleep(0.05)  # waiting is talking: the signal arrives while the rig keeps the drive fed
"""


def _drive_state(port: str) -> dict[str, int]:
    with SerialTransport(port, 115200) as t:
        link = ModbusLink(t, clock=MonotonicClock())
        d = ErobModbusDriver(link, 2, clock=MonotonicClock())
        v = d.access.read_many(["error_code", "status_of_achieving_position", "current_speed"])
        v["watchdog"] = d.read("modbus_communication_timeout_duration")
        return v


@pytest.mark.parametrize("how", ["normal", "exception", "SIGINT", "SIGTERM", "SIGHUP", "never-closed"])
def test_every_way_out_stops_and_disables_the_served_drive(
        how: str, tmp_path: Path, sim_server: Callable[..., ContextManager[str]]) -> None:
    if how == "SIGHUP" and not hasattr(signal, "SIGHUP"):
        pytest.skip("no SIGHUP on this platform")
    config = tmp_path / "served.toml"
    config.write_text(SERVED, encoding="utf-8")
    with sim_server(config) as port:
        script = tmp_path / "child.py"
        script.write_text(textwrap.dedent(CHILD.format(port=port, how=how)), encoding="utf-8")
        child = subprocess.Popen([sys.executable, str(script)], cwd=ROOT, stdin=subprocess.PIPE,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            assert child.stdout is not None and child.stdin is not None
            line = child.stdout.readline().split()
            assert line[:1] == ["ready"], (line, child.stderr.read() if child.poll() is not None else "")
            assert float(line[1]) > 0.9, "the child did not get the drive moving"  # rad/s, read by the child
            if how in ("normal", "exception", "never-closed"):
                child.stdin.write("go\n")
                child.stdin.flush()
            else:
                child.send_signal(getattr(signal, how))
            rc = child.wait(timeout=20)
            left = time.monotonic()
        finally:
            if child.poll() is None:
                child.kill()
        s = _drive_state(port)
        assert time.monotonic() - left < 0.9, "checked too late to tell an orderly stop from the watchdog"
        err = child.stderr.read() if child.stderr else ""
        assert s["status_of_achieving_position"] == AchieveStatus.MOTOR_OFF, (how, s, rc, err)
        assert s["error_code"] == 0, (how, s, err)  # disabled by the rig, not tripped by the watchdog
        assert s["watchdog"] == 0, (how, s)  # and the watchdog as it was before enable()
        if how == "normal" or how == "never-closed":
            assert rc == 0, err
        elif how == "SIGINT":
            assert rc != 0 and "KeyboardInterrupt" in err
        elif how in ("SIGTERM", "SIGHUP"):
            assert rc == 128 + getattr(signal, how), err

