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
import faulthandler, os, signal, sys, time
faulthandler.register(signal.SIGUSR1, all_threads=True)  # the test asks for every thread's stack if we hang
# a program started from a terminal: Ctrl-C raises KeyboardInterrupt, SIGTERM/SIGHUP end it - whatever the
# test runner ignored (a background job ignores SIGINT, nohup SIGHUP, and a child inherits what is ignored)
signal.signal(signal.SIGINT, signal.default_int_handler)
for name in ("SIGTERM", "SIGHUP"):
    if hasattr(signal, name):
        signal.signal(getattr(signal, name), signal.SIG_DFL)
import joints
cfg = {{"backend": "hardware",
        "buses": {{"rs485": {{"protocol": "modbus-rtu", "port": {port!r}, "timeout": 0.2}}}},
        "joints": {{"joint1": {{"device": "erob", "bus": "rs485", "address": 2}}}}}}
how = {how!r}
if how == "never-closed":
    rig = joints.open(cfg)
    rig.joints["joint1"].enable()
    rig.joints["joint1"].wait(timeout=10, until=lambda s: s.enabled)  # see below
    rig.joints["joint1"].set_velocity(1.0)
    rig.joints["joint1"].wait(timeout=10, until=lambda s: s.velocity > 0.95)
    print("ready", rig.joints["joint1"].state().velocity, flush=True)
    sys.stdin.readline()
    sys.exit(0)  # leaves without rig.close(): the atexit hook closes it
with joints.open(cfg) as rig:
    j = rig.joints["joint1"]
    j.enable()
    # the driver waits the manual's 500 ms after enable on this process's clock; the served world's clock lags the
    # wall clock whenever its process waits for a core, and a start that reaches the twin before its 500 ms are
    # over is refused with fault 0x0027 (start while disabled): go on when the drive reports its motor on
    j.wait(timeout=10, until=lambda s: s.enabled)
    j.set_velocity(1.0)
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


def _finish(child: subprocess.Popen[str]) -> str:
    """The child's exit code, stdout and stderr; a child still running first dumps its threads' stacks, then dies."""
    if child.poll() is None and hasattr(signal, "SIGUSR1"):
        child.send_signal(signal.SIGUSR1)  # faulthandler writes every thread's stack to stderr
        try:
            child.wait(timeout=5)
        except subprocess.TimeoutExpired:
            pass
    if child.poll() is None:
        child.kill()
    out, err = child.communicate()
    return f"child exit code {child.returncode}\n--- stdout:\n{out}\n--- stderr:\n{err}"


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
            if line[:1] != ["ready"]:
                pytest.fail(f"the child never got ready (printed {line})\n{_finish(child)}")
            assert float(line[1]) > 0.9, "the child did not get the drive moving"  # rad/s, read by the child
            if how in ("normal", "exception", "never-closed"):
                child.stdin.write("go\n")
                child.stdin.flush()
            else:
                child.send_signal(getattr(signal, how))
            try:
                rc = child.wait(timeout=20)
            except subprocess.TimeoutExpired:
                pytest.fail(f"the child did not leave within 20 s of {how}\n{_finish(child)}")
            left = time.monotonic()
        finally:
            if child.poll() is None:
                child.kill()
        s = _drive_state(port)
        assert time.monotonic() - left < 0.9, "checked too late to tell an orderly stop from the watchdog"
        report = _finish(child)
        assert s["status_of_achieving_position"] == AchieveStatus.MOTOR_OFF, (how, s, report)
        assert s["error_code"] == 0, (how, s, report)  # disabled by the rig, not tripped by the watchdog
        assert s["watchdog"] == 0, (how, s, report)  # and the watchdog as it was before enable()
        if how == "normal" or how == "never-closed":
            assert rc == 0, report
        elif how == "SIGINT":
            assert rc != 0 and "KeyboardInterrupt" in report, report
        elif how in ("SIGTERM", "SIGHUP"):
            assert rc == 128 + getattr(signal, how), report
