"""Record and replay (issue 24): a run's bus frames replay in a fresh process against fresh twins built from the
recorded configuration with no reply difference; against perturbed twins the differences are reported by
frame and quantity. Serial buses in the documented JSON-lines format, CAN buses in python-can's log format."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("mujoco")

import joints
from joints.config import parse
from joints.errors import ConfigError
from joints.s2r.record import config_table, load, record, replay

ROOT = Path(__file__).resolve().parents[2]


def config(protocol: str = "modbus-rtu", **sim: Any) -> dict[str, Any]:
    # an ideal bus: the replay gives each recorded frame to the twins at its recorded (host) time
    return {"sim": {"model": "erob_pendulum.xml", **sim}, "buses": {"bus": {"protocol": protocol, "timing": "ideal"}},
            "joints": {"joint1": {"device": "erob", "bus": "bus", "address": 1, "model": "eRob80H100",
                                  "limits": {"position": [-1.2, 1.2], "velocity": 3.0, "torque": 40.0},
                                  "motion": {"velocity": 1.0, "acceleration": 4.0, "deceleration": 4.0}}}}


def scripted_run(rig: joints.Rig) -> None:
    """Enable, a position move, a speed run and a torque step, polling the state throughout."""
    j = rig.joints["joint1"]
    j.enable()
    rig.sleep(0.6)
    j.move_to(0.5)
    for _ in range(80):
        j.state()
        rig.sleep(0.01)
    j.set_velocity(-0.4)
    for _ in range(40):
        j.state()
        rig.sleep(0.01)
    j.set_torque(6.0)
    for _ in range(40):
        j.state()
        rig.sleep(0.005)


def recorded(tmp_path: Path, protocol: str = "modbus-rtu") -> Path:
    rig = joints.open(config(protocol))
    rec = record(rig, tmp_path / "run.jsonl")
    try:
        scripted_run(rig)
    finally:
        rig.close()  # the shutdown frames (stop, disable) are part of the run
        rec.close()
    return tmp_path / "run.jsonl"


def joints_cli(*args: str) -> subprocess.CompletedProcess[str]:
    """``python -m joints ...`` in a fresh process."""
    return subprocess.run([sys.executable, "-m", "joints", *args], check=False, capture_output=True, text=True,
                          cwd=ROOT, timeout=300)


def test_serial_recording_is_the_documented_json_lines(tmp_path: Path) -> None:
    path = recorded(tmp_path)
    lines = path.read_text().splitlines()
    header = json.loads(lines[0])
    assert header["joints_recording"] == 1 and header["clock"] == "sim" and header["origin"] == 0.0
    assert header["buses"] == {"bus": {"protocol": "modbus-rtu", "medium": "serial"}}
    frames = [json.loads(x) for x in lines[1:]]
    assert {f["dir"] for f in frames} == {"tx", "rx"} and {f["bus"] for f in frames} == {"bus"}
    assert frames[0]["dir"] == "tx" and frames[0]["data"] == "01 03 00 60 00 19 84 1E"  # the first status read
    times = [f["t"] for f in frames]
    assert times == sorted(times) and times[-1] > 1.5
    # the recorded configuration builds the same rig
    cfg = parse(header["config"], backend="sim")
    assert cfg.joints["joint1"].limits.position == (-1.2, 1.2) and cfg.buses["bus"].protocol == "modbus-rtu"


def test_replay_in_a_fresh_process_has_no_difference_and_a_perturbed_twin_shows_them(tmp_path: Path) -> None:
    path = recorded(tmp_path)
    same = joints_cli("replay", str(path), "--report", str(tmp_path / "same.json"))
    assert same.returncode == 0, same.stderr
    report = json.loads((tmp_path / "same.json").read_text())
    assert report["identical"] and report["differing"] == 0 and report["exchanges"] > 150
    assert " 0 differ" in same.stdout

    diff = joints_cli("replay", str(path), "--perturb", "joint1:armature=1.4,coulomb_friction=2,viscous_friction=1.5,"
                      "torque_constant=0.9,command_delay=0.002", "--report", str(tmp_path / "diff.json"))
    assert diff.returncode == 1, diff.stderr
    report = json.loads((tmp_path / "diff.json").read_text())
    assert not report["identical"] and report["differing"] > 50
    assert report["perturbations"]["joint1"]["armature"] == 1.4
    by_q = report["by_quantity"]
    for q in ("joint1.actual_position", "joint1.current_speed", "joint1.motor_current"):  # motion and current
        assert by_q[q]["frames"] > 10 and by_q[q]["max_abs"] > 0, q
    first = report["differences"][0]
    assert first["request"].startswith("01 03 00 60") and first["recorded"] != first["replayed"]
    assert first["quantities"] and all(a != b for a, b in first["quantities"].values())
    assert all(d["index"] >= 0 and d["bus"] == "bus" for d in report["differences"])
    assert "joint1.actual_position" in diff.stdout and "frame " in diff.stdout


def test_can_recording_is_a_python_can_log_and_replays_identically(tmp_path: Path) -> None:
    can = pytest.importorskip("can")
    path = recorded(tmp_path, "erob-can")
    header = json.loads(path.read_text().splitlines()[0])
    log = tmp_path / header["buses"]["bus"]["log"]
    assert log.name == "run.bus.log" and len(path.read_text().splitlines()) == 1  # CAN frames live in the log
    msgs = list(can.LogReader(str(log)))
    assert {m.is_rx for m in msgs} == {True, False}
    assert {m.arbitration_id for m in msgs if not m.is_rx} == {0x641} and {m.arbitration_id for m in msgs if m.is_rx} == {0x5C1}
    same = joints_cli("replay", str(path))
    assert same.returncode == 0, same.stdout + same.stderr
    report = replay(path, perturb={"joint1": {"armature": 1.4, "coulomb_friction": 2.0}})
    assert not report.identical
    assert {"joint1.actual_position", "joint1.motor_current"} <= set(report.by_quantity())


def test_direct_path_cannot_be_recorded(tmp_path: Path) -> None:
    with joints.open(config(direct=True)) as rig, pytest.raises(ConfigError, match="direct"):
        record(rig, tmp_path / "x.jsonl")


def test_config_table_reads_back_to_the_same_config() -> None:
    cfg = parse(config())
    again = parse(config_table(cfg))
    assert again.joints == cfg.joints and again.buses == cfg.buses and again.sim == cfg.sim


def test_not_a_recording_is_a_clear_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"hello": 1}\n')
    with pytest.raises(ConfigError, match="not a joints recording"):
        load(bad)
    assert joints_cli("replay", str(bad)).returncode == 2
