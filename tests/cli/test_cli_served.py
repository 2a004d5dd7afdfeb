"""Every command against served twins of every family and protocol (`joints sim serve` in another process).

The world of conftest.py is served once for the module; the commands run here as a user runs them,
on the hardware config that `sim serve --hardware-config` wrote (the buses are the served ptys and
udp_multicast channels). The served world runs on the wall clock: waits poll the drives' own state.
"""

from __future__ import annotations

import json
import os
import select
import sys
import time
from pathlib import Path
from typing import Any

import pytest

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="serving needs POSIX ptys")

import joints
from joints.cli import main

MOVERS = ["a", "l", "m", "n", "c", "o"]  # one joint of every family x protocol
NOT_DISABLED = {"m", "n"}  # the MKS twins power on enabled (EN pin active): a one-shot leaves them as found
#: s a wall-clock wait may take before it fails: it only bounds a failure (a joint starts or stops in well under a
#: second), with room for the seconds a loaded machine can hold a process back (clikit.BUSES)
STALL = 30.0


def run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    rc = main([str(a) for a in args])
    c = capsys.readouterr()
    return rc, c.out, c.err


def state(served: Any, capsys: pytest.CaptureFixture[str], joint: str) -> dict[str, Any]:
    rc, out, err = run(capsys, "state", served.hardware, joint, "--json")
    assert rc == 0, err
    result: dict[str, Any] = json.loads(out)
    return result


def world_passes(served: Any, seconds: float) -> None:
    """Wait until the served world's own clock has advanced ``seconds`` (however fast it runs here)."""
    t0 = served.command("status")["time"]
    deadline = time.monotonic() + 20 + 10 * seconds
    while served.command("status")["time"] - t0 < seconds:
        assert time.monotonic() < deadline, "the served world does not advance"
        time.sleep(0.02)  # poll interval


def test_hardware_config_points_at_the_served_buses(served: Any) -> None:
    from joints.config import load

    cfg = load(served.hardware)
    assert cfg.backend == "hardware"
    assert cfg.buses["rs485"].port == served.lines["rs485"]["port"]
    assert cfg.buses["co"].udp_port == served.lines["co"]["udp_port"]
    assert set(cfg.joints) == {"a", "b", "l", "r", "m", "n", "c", "o"}


def test_scan_lists_the_five_serial_drives_with_device_and_address(served: Any,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    # a served world keeps the real bus's time (about 10 ms per status read at 115200 bd), but a loaded machine
    # delays a reply by up to ~1 s (clikit.BUSES): a drive that answers that late is not found, so the timeout is
    # 1 s. Every empty address waits it out (each family's probe): addresses 1-5 hold the five drives and an empty
    # one on each bus; the default range 1-32 is test_cli_scan's (in process)
    rc, out, err = run(capsys, "scan", "--config", served.hardware, "--bus", "rs485", "--bus", "mks", "--json",
                       "--timeout", "1.0", "--range", "1-5")
    assert rc == 0, err
    found = json.loads(out)
    assert [(f["bus"], f["address"], f["device"]) for f in found] == [
        ("rs485", 1, "erob"), ("rs485", 2, "erob"), ("rs485", 3, "zlac8015d"), ("rs485", 4, "mks"), ("mks", 5, "mks")]
    for f in found:
        assert set(f) == {"bus", "protocol", "device", "address", "model", "serial", "firmware", "details"}
        assert f["model"] is None and f["serial"] is None  # no such registers: null, never from the config
    assert {f["address"]: f["firmware"] for f in found}[3].startswith("0x")  # ZLAC 0x20A0
    assert {f["address"]: f["firmware"] for f in found}[1] is None


def test_scan_finds_the_can_nodes_with_what_they_report(served: Any, capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, err = run(capsys, "scan", "--config", served.hardware, "--bus", "can", "--bus", "co", "--range", "1-8",
                       "--timeout", "0.1", "--json")
    assert rc == 0, err
    found = {(f["bus"], f["address"]): f for f in json.loads(out)}
    assert set(found) == {("can", 6), ("co", 7)}
    custom, canopen = found[("can", 6)], found[("co", 7)]
    assert custom["device"] == "erob" and custom["model"].startswith("eRob") and custom["serial"] and custom["firmware"]
    # CANopen's own scan finds any node: its make is not on the bus (device null), its identity is
    # ZeroErr's EDS: 0x1018:00 = 3, no serial number object; the identity is vendor, product and revision
    assert canopen["device"] is None and canopen["serial"] is None and canopen["model"] is None
    assert canopen["details"]["vendor_id"] == "0x5A65726F" and canopen["details"]["product_code"] == "0x26483052"
    assert canopen["details"]["profile"] == 402 and "pp" in canopen["details"]["modes"]


def test_scan_baud_list_reports_the_rate(served: Any, capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, _ = run(capsys, "scan", "--port", served.port("rs485"), "--baudrate", "9600,115200", "--range", "1-2",
                     "--json", "--timeout", "0.2")
    assert rc == 0
    found = json.loads(out)
    assert [(f["baudrate"], f["address"]) for f in found] == [(9600, 1), (9600, 2), (115200, 1), (115200, 2)]


def test_info_of_every_joint(served: Any, capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, err = run(capsys, "info", served.hardware, "--json")
    assert rc == 0, err
    infos = {d["joint"]: d for d in json.loads(out)}
    assert set(infos) == {"a", "b", "l", "r", "m", "n", "c", "o"}
    for name, d in infos.items():
        assert d["fault"] is None and d["parameters"], name
    assert infos["c"]["model"].startswith("eRob") and infos["c"]["serial"]
    assert infos["a"]["model"] is None and infos["a"]["firmware"] is None
    assert infos["l"]["firmware"].startswith("0x")
    params_a = {p["name"]: p["value"] for p in infos["a"]["parameters"]}
    assert params_a["modbus_address"] == 1 and "max_speed" in params_a
    params_n = {p["name"]: p["value"] for p in infos["n"]["parameters"]}
    assert params_n["working_current"] == "not readable" and isinstance(params_n["motor_status"], int)
    rc, out, _ = run(capsys, "info", served.hardware, "a")
    assert rc == 0 and "modbus_communication_timeout_duration" in out and "what to do" not in out


def test_state_read_and_watch_give_json(served: Any, capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, _ = run(capsys, "state", served.hardware, "--json")
    assert rc == 0 and len([json.loads(line) for line in out.splitlines()]) == 8
    rc, out, _ = run(capsys, "read", served.hardware, "o", "statusword", "actual_position")
    assert rc == 0 and [json.loads(line)["register"] for line in out.splitlines()] == ["statusword", "actual_position"]
    rc, out, _ = run(capsys, "watch", served.hardware, "a", "n", "c", "--samples", "2", "--json", "--period", "0.05",
                     "--param", "error_code")
    rows = [json.loads(line) for line in out.splitlines()]
    assert rc == 0 and [r["joint"] for r in rows] == ["a", "n", "c", "a", "n", "c"]
    assert rows[0]["error_code"] == 0 and rows[1]["error_code"] is None  # the MKS has no error code


@pytest.mark.parametrize("joint", MOVERS)
def test_move_reaches_the_target_and_leaves_the_drive_as_found(served: Any, joint: str, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    before = tmp_path / "before.toml"
    assert run(capsys, "params", "dump", served.hardware, joint, "-o", before)[0] == 0
    start = state(served, capsys, joint)
    rc, out, err = run(capsys, "move", served.hardware, joint, "0.25", "--relative", "--json", "--timeout", "20")
    assert rc == 0, err
    result = json.loads(out)
    assert result["position"] == pytest.approx(start["position"] + 0.25, abs=0.01)
    assert result["enabled"] is (joint in NOT_DISABLED) and not result["moving"] and result["held"] is False
    rc, out, _ = run(capsys, "params", "diff", served.hardware, joint, before)
    changed = [line for line in out.splitlines() if not line.startswith(("rpdo", "tpdo"))]
    assert rc == 0 and changed == []  # limits, profile, mode, watchdog put back (a PDO map an operational node
    #                                   refuses to change back aside)


@pytest.mark.parametrize("joint", MOVERS)
def test_jog_runs_then_stops(served: Any, joint: str, capsys: pytest.CaptureFixture[str]) -> None:
    start = state(served, capsys, joint)
    rc, out, err = run(capsys, "jog", served.hardware, joint, "--velocity", "0.4", "--duration", "0.8", "--json")
    assert rc == 0, err
    result = json.loads(out)
    assert result["position"] - start["position"] > 0.05
    assert not result["moving"] and result["enabled"] is (joint in NOT_DISABLED)
    world_passes(served, 0.3)
    later = state(served, capsys, joint)
    assert later["position"] == pytest.approx(result["position"], abs=0.02)  # stopped: not left in speed mode


def test_limits_from_the_config_are_enforced(served: Any, capsys: pytest.CaptureFixture[str]) -> None:
    rc, _, err = run(capsys, "move", served.hardware, "a", "5")
    assert rc == 2 and "outside the limits" in err and "nothing was sent" in err
    rc, _, err = run(capsys, "jog", served.hardware, "c", "--velocity", "3")
    assert rc == 2 and "exceeds the limit" in err


def test_enable_holds_with_the_watchdog_off_then_disable(served: Any, capsys: pytest.CaptureFixture[str]) -> None:
    assert run(capsys, "write", served.hardware, "a", "modbus_communication_timeout_duration", "500")[0] == 0
    rc, _, err = run(capsys, "enable", served.hardware, "a")
    assert rc == 0 and "watchdog OFF" in err and "joints disable" in err
    rc, out, _ = run(capsys, "read", served.hardware, "a", "modbus_communication_timeout_duration")
    assert json.loads(out)["value"] == 0
    world_passes(served, 1.0)  # twice the 500 ms the watchdog had: nothing fed it, it holds all the same
    assert state(served, capsys, "a")["enabled"] is True
    rc, _, err = run(capsys, "disable", served.hardware, "a")
    assert rc == 0, err
    assert state(served, capsys, "a")["enabled"] is False


@pytest.mark.parametrize("joint", MOVERS)
def test_stop_from_a_fresh_process_stops_a_joint_another_program_left_running(
        served: Any, joint: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Another program set the joint running and went away (``on_exit = "none"``, no watchdog):
    ``joints stop`` must stop it, with nothing of its own set up on that drive."""
    text = served.hardware.read_text(encoding="utf-8").replace(f"[joints.{joint}]\n",
                                                               f"[joints.{joint}]\nwatchdog_ms = 0\n")
    other = tmp_path / "other.toml"
    other.write_text('on_exit = "none"\n' + text, encoding="utf-8")
    with joints.open(other) as rig:
        j = rig.joints[joint]
        j.enable()
        j.set_velocity(0.4)
        deadline = time.monotonic() + STALL
        while abs(j.state().velocity) < 0.3:
            assert time.monotonic() < deadline, "the joint did not start"
    assert abs(state(served, capsys, joint)["velocity"]) > 0.3  # still running: the other program left it so
    try:
        rc, _, err = run(capsys, "stop", served.hardware, joint)
        assert rc == 0, err
        deadline = time.monotonic() + STALL
        while abs(state(served, capsys, joint)["velocity"]) > 0.02:
            assert time.monotonic() < deadline, f"joints stop left {joint} running"
    finally:
        run(capsys, "disable", served.hardware, joint)


def test_stop_and_clear_every_joint(served: Any, capsys: pytest.CaptureFixture[str]) -> None:
    """Both commands accept a joint of every family and protocol at once and leave each standing, unfaulted
    (stopping a running joint: the test above; clear refuses a fault that stays: cmd_clear's check)."""
    assert run(capsys, "stop", served.hardware, *MOVERS)[0] == 0
    rc, _, err = run(capsys, "clear", served.hardware, *MOVERS)
    assert rc == 0, err
    for joint in MOVERS:
        s = state(served, capsys, joint)
        assert s["fault"] is None and abs(s["velocity"]) < 0.02, (joint, s)


def _frames(out: str) -> list[tuple[int, bytes]]:
    rows = [json.loads(line) for line in out.splitlines()]
    return [(int(r["ident"], 16), bytes.fromhex(r["data"])) for r in rows]


@pytest.mark.parametrize("ext", [".asc", ".blf"])
def test_can_monitor_log_reads_back_with_python_can(served: Any, ext: str, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    import can

    log = tmp_path / f"frames{ext}"
    rc, out, err = run(capsys, "monitor", served.hardware, "--bus", "can", "--duration", "0.3", "--period", "0.1",
                       "--json", "--export", log)
    assert rc == 0, err
    shown = _frames(out)
    assert len(shown) >= 6
    back = [(m.arbitration_id, bytes(m.data)) for m in can.LogReader(str(log))]
    assert back == shown
    assert {i for i, _ in back} == {0x646, 0x5C6}  # node 6: requests 0x640+6, replies 0x5C0+6


def test_modbus_monitor_csv_has_one_row_per_frame(served: Any, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    import csv

    log = tmp_path / "frames.csv"
    rc, out, err = run(capsys, "monitor", served.hardware, "--bus", "rs485", "--duration", "0.3", "--json",
                       "--export", log)
    assert rc == 0, err
    shown = [json.loads(line) for line in out.splitlines()]
    with log.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(shown) > 0
    assert [(r["time"], r["direction"], r["data"]) for r in rows] == [
        (str(s["time"]), s["direction"], s["data"]) for s in shown]
    assert {r["direction"] for r in rows} == {"tx", "rx"} and {r["node"] for r in rows} == {"1", "2", "3", "4"}


def test_replay_a_log_against_the_served_twins(served: Any, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "frames.jsonl"
    assert run(capsys, "monitor", served.hardware, "--bus", "mks", "--duration", "0.3", "--export", log,
               "--quiet")[0] == 0
    rc, _, err = run(capsys, "replay", log, served.hardware, "--bus", "mks")
    assert rc == 2 and "--confirm" in err  # a hardware config: the log may write
    rc, out, err = run(capsys, "replay", log, served.hardware, "--bus", "mks", "--confirm", "--json")
    results = json.loads(out)
    assert results and all(r["same"] for r in results), results  # the axis stands still: the same replies


def test_monitor_filters_by_node_and_kind(served: Any, capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, _ = run(capsys, "monitor", served.hardware, "--bus", "rs485", "--duration", "0.2", "--json",
                     "--node", "3", "--direction", "tx")
    rows = [json.loads(line) for line in out.splitlines()]
    assert rc == 0 and rows and all(r["node"] == 3 and r["direction"] == "tx" for r in rows)
    rc, out, _ = run(capsys, "monitor", served.hardware, "--bus", "co", "--duration", "0.2", "--json", "--kind", "sdo")
    rows = [json.loads(line) for line in out.splitlines()]
    assert rc == 0 and rows and all("SDO" in r["meaning"] for r in rows)


@pytest.mark.parametrize("bus,frame,reply", [
    ("rs485", "01 03 00 60 00 01", "Reply(slave=1"),  # Modbus RTU: the CRC is appended
    ("mks", "FA 05 F1", "MotorStatusReply(address=5"),  # MKS native: the checksum is appended
    ("can", "646#0002", "node 6 value"),  # eRob CAN: read index 0x0002
    ("co", "607#4041600000000000", "SDO value 0x6041:00"),  # CANopen SDO upload
])
def test_send_a_raw_read_on_every_protocol(served: Any, bus: str, frame: str, reply: str,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, err = run(capsys, "send", served.hardware, "--bus", bus, frame)
    assert rc == 0, err
    assert reply in out and "<-" in out


def test_send_refuses_unconfirmed_writes(served: Any, capsys: pytest.CaptureFixture[str]) -> None:
    for bus, frame in (("rs485", "02 06 00 47 00 10"), ("co", "607#2B40600006000000"), ("mks", "FA 05 F3 01")):
        rc, _, err = run(capsys, "send", served.hardware, "--bus", bus, frame)
        assert rc == 2 and "--confirm" in err and "confirm=True" not in err


def test_params_dump_load_diff_keeps_the_second_drives_address(served: Any, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    hw = served.hardware
    saved_b = tmp_path / "b-before.toml"
    assert run(capsys, "params", "dump", hw, "b", "-o", saved_b)[0] == 0
    assert run(capsys, "write", hw, "a", "profile_speed", "12345")[0] == 0
    assert run(capsys, "write", hw, "a", "position_loop_gain", "321")[0] == 0
    dump = tmp_path / "a.toml"
    assert run(capsys, "params", "dump", hw, "a", "-o", dump)[0] == 0
    rc, out, _ = run(capsys, "params", "load", hw, "b", dump)  # dry run: shows, writes nothing
    assert rc == 0 and "profile_speed" in out and "dry run" in out
    assert json.loads(run(capsys, "read", hw, "b", "profile_speed")[1])["value"] != 12345
    rc, out, err = run(capsys, "params", "load", hw, "b", dump, "--apply")
    assert rc == 0, err
    rc, out, _ = run(capsys, "params", "diff", hw, "b", dump)
    assert rc == 0 and out == ""
    assert json.loads(run(capsys, "read", hw, "b", "modbus_address")[1])["value"] == 2  # kept its own address
    rc, out, _ = run(capsys, "params", "diff", hw, "b", dump, "--include-identity")
    assert "modbus_address: 2 (drive) != 1 (a.toml)" in out
    rc, _, err = run(capsys, "params", "load", hw, "b", dump, "--include-identity", "--apply")
    assert rc == 2 and "--confirm" in err
    # put a and b back
    assert run(capsys, "params", "load", hw, "a", saved_b, "--apply")[0] == 0
    assert run(capsys, "params", "load", hw, "b", saved_b, "--apply")[0] == 0


def test_params_dump_reads_write_only_settings_by_0x47(served: Any, capsys: pytest.CaptureFixture[str]) -> None:
    # the MKS twins run the default firmware v1.0.9: 0x47 reports the settings single commands cannot
    # (a v1.0.5 drive lists them as "not readable": tests/sim/test_mks_blocks.py)
    rc, out, _ = run(capsys, "params", "dump", served.hardware, "n", "--json")
    data = json.loads(out)
    assert rc == 0 and data["settings"]["working_current"] == 3200  # the SERVO57D's default
    assert data["identity"]["slave_address"] == 5
    assert "zero_mode_set_zero" in data["not_readable"]  # 0x47 reads it as "Reserved (FF)"
    assert isinstance(data["status"]["motor_status"], int)
    rc, out, _ = run(capsys, "params", "dump", served.hardware, "o", "--json")
    data = json.loads(out)
    assert data["settings"]["profile_speed"] > 0 and "controlword" in data["live"]


def test_power_cycle_a_served_twin(served: Any, capsys: pytest.CaptureFixture[str]) -> None:
    hw = served.hardware
    assert run(capsys, "write", hw, "b", "profile_speed", "777")[0] == 0
    answer = served.command("power-cycle b")
    assert answer["power_cycled"] == ["b"]
    assert json.loads(run(capsys, "read", hw, "b", "profile_speed")[1])["value"] == 65536  # power-on default
    assert served.command("power-cycle nope")["error"].startswith("[power-cycle] no joint named 'nope'")


def _read_until(fd: int, done: Any, timeout: float) -> bytes:
    buf = b""
    end = time.monotonic() + timeout
    while time.monotonic() < end and not done(buf):
        ready, _, _ = select.select([fd], [], [], 0.1)
        if ready:
            try:
                chunk = os.read(fd, 65536)
            except OSError:  # the child closed the terminal
                break
            if not chunk:
                break
            buf += chunk
    return buf


def test_watch_under_a_pseudo_terminal_redraws_and_quits_on_q(served: Any, capsys: pytest.CaptureFixture[str]) -> None:
    import pty
    import subprocess

    from clikit import ROOT

    hw = served.hardware
    watchdog = json.loads(run(capsys, "read", hw, "a", "modbus_communication_timeout_duration")[1])["value"]
    before = state(served, capsys, "a")
    master, slave = pty.openpty()
    env = dict(os.environ, TERM="xterm", COLUMNS="140", LINES="40")
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.Popen([sys.executable, "-m", "joints", "watch", str(hw), "a", "n", "c", "--period", "0.05"],
                            stdin=slave, stdout=slave, stderr=slave, cwd=ROOT, env=env, start_new_session=True)
    os.close(slave)
    try:
        shown = _read_until(master, lambda b: b.count(b"q: quit") >= 4, 60)
        assert shown.count(b"q: quit") >= 4, shown[-2000:]
        assert b"\x1b[" in shown  # redrawn in place: cursor movements, not new lines
        assert all(name in shown for name in (b" a ", b" n ", b" c "))
        os.write(master, b"q")
        _read_until(master, lambda b: proc.poll() is not None, 15)
        assert proc.wait(timeout=15) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(master)
    after = state(served, capsys, "a")
    assert not after["enabled"] and not after["moving"] and after["position"] == pytest.approx(before["position"])
    assert json.loads(run(capsys, "read", hw, "a", "modbus_communication_timeout_duration")[1])["value"] == watchdog
