"""MKS twins served by `joints sim serve` on a real pseudo-terminal, reached by our hardware driver and by an
independent Modbus master. The served world runs on the wall clock, so these tests wait for the drive's own
status (bounded), never a fixed sleep."""

from __future__ import annotations

import json
import select
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("mujoco")
pytest.importorskip("serial")
# The served process is told the profile (it has its own default). These wall-clock tests run on the oldest and the
# newest profile, whose behaviour differs for them (no version, no watchdog / 0x40 and the heartbeat); V1.0.6's
# additions (0x47 at enable, Modbus failure replies) are exercised in process.
pytestmark = [pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals need POSIX"),
              pytest.mark.mks_firmware("v1.0.5", "v1.0.9")]

from mkskit import axis_config

import joints
from joints.codecs import mks
from joints.link.trace import Trace

ROOT = Path(__file__).resolve().parents[2]


def _toml(cfg: dict[str, object]) -> str:
    """A small TOML writer for the configs of mkskit (tables of scalars, lists and inline tables)."""
    def value(v: object) -> str:
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + " }"
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, bool):
            return "true" if v else "false"
        return json.dumps(v)

    lines = [f"backend = {value(cfg['backend'])}", "[sim]"]
    lines += [f"{k} = {value(v)}" for k, v in cfg["sim"].items()]  # type: ignore[attr-defined]
    for section in ("buses", "joints"):
        for name, table in cfg[section].items():  # type: ignore[attr-defined]
            lines.append(f"[{section}.{name}]")
            lines += [f"{k} = {value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


@pytest.fixture
def served_native(tmp_path: Path, sim_server, mks_firmware: str) -> Iterator[str]:  # type: ignore[no-untyped-def]
    cfg = tmp_path / "axis.toml"
    cfg.write_text(_toml(axis_config(firmware=mks_firmware)))
    with sim_server(cfg) as port:
        yield port


def _hardware(port: str, protocol: str = "mks-serial") -> dict[str, object]:
    return axis_config(backend="hardware", port=port, protocol=protocol, timeout=0.5)


def test_move_in_active_mode_over_a_pty_completion_arrives_while_the_encoder_is_polled(served_native: str,
                                                                                       mks_firmware: str) -> None:
    trace = Trace()
    with joints.open(_hardware(served_native)) as rig:
        assert rig.backend == "hardware"
        rig.trace(trace)
        j = rig.joints["carriage"]
        d = j.driver
        j.enable()
        start = d.read("encoder_addition")
        d.move_pulses(3200 * 2, speed=120, acceleration=1000)  # 2 turns = 16 mm at 120 rpm: ~1 s
        reply = d.access.last_reply
        assert reply == mks.RunReply(1, 0xFD, mks.RunStatus.STARTED)  # status 1 at once
        polls = []
        deadline = time.monotonic() + 10
        while not d.motion_complete:
            polls.append(d.read("encoder_addition"))  # keeps polling while it runs
            assert time.monotonic() < deadline, "no completion frame"
        assert d.completion == mks.RunReply(1, 0xFD, mks.RunStatus.COMPLETE)  # status 2 at the end
        rig.trace(None)
        assert len(polls) > 20 and polls[0] < polls[-1]
        assert abs(d.read("encoder_addition") - start - 2 * 16384) <= 2
        link = d.link
        assert link.retries_used == 0 and link.late_discarded == 0 and not link.unsolicited
    records = list(trace)
    print("\nwire trace (first 8 and last 6 frames):")
    for r in records[:8] + records[-6:]:
        print(r)
    assert not any("error" in r.meaning for r in records)
    tx = [r for r in records if r.direction == "tx"]
    rx = [r for r in records if r.direction == "rx"]
    completions = [r for r in rx if "unsolicited" in r.meaning]
    assert len(completions) == 1 and "COMPLETE" in completions[0].meaning
    assert sum(r.data[2] == 0x40 for r in tx) == 1  # the version probe, once: a drive before V1.0.9 leaves it
    assert len(rx) == len(tx) - (mks_firmware != "v1.0.9") + 1  # unanswered; all else answered, plus the completion
    moves = [r for r in tx if r.data[2] == 0xFD]
    assert [r.data for r in moves] == [mks.encode(mks.RunRelativePulses(1, mks.RunDirection.CCW, 120,
                                                                        d.acc_for(1000), 6400))]


def test_independent_modbus_master_drives_the_served_modbus_mode_twin(tmp_path: Path, sim_server,  # type: ignore[no-untyped-def]
                                                                       mks_firmware: str) -> None:
    minimalmodbus = pytest.importorskip("minimalmodbus")
    cfg = tmp_path / "modbus.toml"
    cfg.write_text(_toml(axis_config(protocol="modbus-rtu", firmware=mks_firmware)))
    with sim_server(cfg) as port:
        inst = minimalmodbus.Instrument(port, 1, mode=minimalmodbus.MODE_RTU)
        inst.serial.baudrate = 38400
        inst.serial.timeout = 0.5
        inst.clear_buffers_before_each_transaction = True
        try:
            inst.write_register(0x82, 5, functioncode=6)  # SR_vFOC (8.2 #5)
            inst.write_register(0xF3, 1, functioncode=6)  # enable (8.2 #19)
            # 8.3.7 position mode4: acc, speed, absAxis Hi, Lo -> one turn
            inst.write_registers(0xF5, [2, 300, 0x0000, 0x4000])
            deadline = time.monotonic() + 10
            while inst.read_register(0xF1, functioncode=4) & 0xFF != 1:  # 8.1 #10 motor status: stop
                assert time.monotonic() < deadline, "still running"
            words = inst.read_registers(0x31, 3, functioncode=4)  # 8.1 #2 int48 encoder addition
            value = (words[0] << 32) | (words[1] << 16) | words[2]
            assert abs(value - 0x4000) <= 2
            assert inst.read_register(0x32, functioncode=4, signed=True) == 0
        finally:
            inst.serial.close()


CLIENT = """
import sys, time, joints
sys.path.insert(0, {tests!r})
from mkskit import axis_config
cfg = axis_config(backend="hardware", port={port!r}, timeout=0.5, firmware={firmware!r})
rig = joints.open(cfg)
j = rig.joints["carriage"]
j.enable()
j.set_velocity(-0.004, acceleration=0.05)  # speed mode toward the low end: 30 rpm, 8 s of travel
deadline = time.monotonic() + 10
while abs(j.state().velocity) < 0.0039:
    assert time.monotonic() < deadline
print("RUNNING", j.state().velocity, flush=True)
while True:  # the process dies here, the axis still running
    time.sleep(0.05)
"""


def test_sigterm_to_a_process_whose_axis_runs_in_speed_mode_leaves_the_axis_stopped(served_native: str,
                                                                                    mks_firmware: str) -> None:
    script = CLIENT.format(tests=str(ROOT / "tests"), port=served_native, firmware=mks_firmware)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 30)
        assert ready and proc.stdout is not None
        line = proc.stdout.readline()
        assert line.startswith("RUNNING"), (line, proc.stderr.read() if proc.stderr else "")
    finally:
        proc.terminate()  # SIGTERM
        rc = proc.wait(timeout=20)
    assert rc == 128 + signal.SIGTERM, proc.stderr.read() if proc.stderr else rc  # Terminated, after closing
    # the twin, read from here: not turning, nothing running
    with joints.open(_hardware(served_native)) as rig:
        d = rig.joints["carriage"].driver
        deadline = time.monotonic() + 5
        while d.read("real_time_speed") != 0:
            assert time.monotonic() < deadline, "the axis keeps turning"
        while d.motor_status() != 1:
            assert time.monotonic() < deadline, "the axis is not reported stopped"
        # disabled on the way out, the shaft coasts to rest below the speed register's 1 rpm
        # (273 counts/s): at rest = no count change for 0.1 s, then it must stay there
        first, since = d.read("encoder_addition"), time.monotonic()
        while time.monotonic() - since < 0.1:
            assert time.monotonic() < deadline, "the axis does not come to rest"
            if abs((now := d.read("encoder_addition")) - first) > 1:
                first, since = now, time.monotonic()
        t0 = time.monotonic()
        while time.monotonic() - t0 < 0.3:
            assert abs(d.read("encoder_addition") - first) <= 2  # and stays where it stopped
