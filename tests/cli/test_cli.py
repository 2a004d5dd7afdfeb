"""The ``joints`` command: table listing, version, helpful errors, register read/write on a rig."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

import joints
from joints.cli import main
from joints.clock import ManualClock
from joints.config import RigConfig, load
from joints.devices.erob.params import EROB_PARAMS
from joints.devices.erob.registers import EROB_MODBUS
from joints.rig import Rig, build
from joints.sim.firmware import Firmware
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
from joints.transports.loopback import LoopbackTransport

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def _no_backend_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("JOINTS_BACKEND", raising=False)


def hardware_toml(tmp_path: Path, port: str) -> Path:
    path = tmp_path / "robot.toml"
    path.write_text(
        'backend = "hardware"\n\n'
        f'[buses.rs485]\nprotocol = "modbus-rtu"\nport = "{port}"\n\n'
        '[joints.shoulder]\ndevice = "erob"\nbus = "rs485"\naddress = 2\n',
        encoding="utf-8",
    )
    return path


def test_registers_prints_the_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["registers"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert len(lines) == len(EROB_MODBUS)
    row = next(line for line in lines if "target_absolute_position" in line)
    assert row.startswith("0x0043") and "int32" in row and "count" in row
    assert any(line.startswith("0x0060") and "error_code" in line for line in lines)


def test_version_exits_0(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert joints.__version__ in capsys.readouterr().out


def test_no_command_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main([])
    assert info.value.code == 2
    assert "usage" in capsys.readouterr().err


def test_state_with_missing_port_is_a_bus_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    port = str(tmp_path / "ttyNOPE0")
    assert main(["state", str(hardware_toml(tmp_path, port))]) == 1  # exit 1: device or bus error
    captured = capsys.readouterr()
    assert captured.out == ""
    err = captured.err
    assert err.startswith("joints: error: ")
    assert port in err and "cannot open serial port" in err
    assert "Traceback" not in err


def test_state_with_missing_config_returns_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["state", str(tmp_path / "nope.toml")]) == 2
    err = capsys.readouterr().err
    assert "nope.toml" in err and "not found" in err


def test_state_with_bad_config_names_the_key(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = hardware_toml(tmp_path, "/dev/ttyUSB0")
    path.write_text(path.read_text().replace("address = 2", "address = 300"))
    assert main(["state", str(path)]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "[joints.shoulder.address]" in err and "1..247" in err


def test_python_dash_m_joints_help() -> None:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.run([sys.executable, "-m", "joints", "--help"], capture_output=True, text=True,
                          cwd=ROOT, env=env, timeout=60, check=False)
    assert proc.returncode == 0, proc.stderr
    assert "usage: joints" in proc.stdout
    for command in ("scan", "state", "read", "write", "registers"):
        assert command in proc.stdout


# --- read / write on a rig (joints.open replaced by a loopback rig) -----------------------------


class Drive(Firmware):
    def __init__(self, address: int) -> None:
        super().__init__(EROB_PARAMS)
        self.address = address


@pytest.fixture
def loopback(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[Path, Drive]:
    """A config file whose rig runs on a loopback bus with one scripted drive."""
    path = hardware_toml(tmp_path, "/dev/ttyUSB0")
    drive = Drive(2)

    def fake_open(config: Any, *, backend: str | None = None) -> Rig:
        cfg = config if isinstance(config, RigConfig) else load(config, backend=backend)
        return build(cfg, transports={"rs485": LoopbackTransport(ModbusDeviceBus([ModbusFront(drive, EROB_MODBUS, drive.address)]))}, clock=ManualClock())

    monkeypatch.setattr(joints, "open", fake_open)
    return path, drive


def test_read_by_name_and_address(loopback: tuple[Path, Drive], capsys: pytest.CaptureFixture[str]) -> None:
    path, drive = loopback
    drive.set("actual_position", -1234)
    drive.set("profile_speed", 777)
    assert main(["read", str(path), "shoulder", "actual_position", "0x0047"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert rows == [
        {"joint": "shoulder", "register": "actual_position", "address": "0x0066", "value": -1234, "unit": "count"},
        {"joint": "shoulder", "register": "profile_speed", "address": "0x0047", "value": 777, "unit": "count/s"},
    ]


def test_state_prints_json_lines(loopback: tuple[Path, Drive], capsys: pytest.CaptureFixture[str]) -> None:
    path, drive = loopback
    drive.set("actual_position", 262144)
    assert main(["state", str(path)]) == 0
    (row,) = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert row["joint"] == "shoulder"
    assert row["position"] == pytest.approx(3.141592653589793)
    assert row["enabled"] is False


def test_write_hex_value(loopback: tuple[Path, Drive]) -> None:
    path, drive = loopback
    assert main(["write", str(path), "shoulder", "profile_speed", "0x2710"]) == 0
    assert drive.write_log == [("profile_speed", 10000)]


def test_persistent_write_needs_confirm(loopback: tuple[Path, Drive], capsys: pytest.CaptureFixture[str]) -> None:
    path, drive = loopback
    assert main(["write", str(path), "shoulder", "modbus_baud_rate", "4"]) == 2
    assert "confirm" in capsys.readouterr().err
    assert drive.write_log == []
    assert main(["write", str(path), "shoulder", "modbus_baud_rate", "4", "--confirm"]) == 0
    assert drive.write_log == [("modbus_baud_rate", 4)]


def test_unknown_joint_returns_2(loopback: tuple[Path, Drive], capsys: pytest.CaptureFixture[str]) -> None:
    path, _ = loopback
    assert main(["read", str(path), "elbow", "actual_position"]) == 2
    err = capsys.readouterr().err
    assert "'elbow'" in err and "'shoulder'" in err and "Traceback" not in err


def test_unknown_register_returns_2(loopback: tuple[Path, Drive], capsys: pytest.CaptureFixture[str]) -> None:
    path, _ = loopback
    assert main(["read", str(path), "shoulder", "actual_postion"]) == 2
    assert "actual_postion" in capsys.readouterr().err


def test_bad_write_value_is_a_usage_error(loopback: tuple[Path, Drive], capsys: pytest.CaptureFixture[str]) -> None:
    path, drive = loopback
    with pytest.raises(SystemExit) as info:
        main(["write", str(path), "shoulder", "profile_speed", "fast"])
    assert info.value.code == 2
    assert "'fast'" in capsys.readouterr().err
    assert drive.write_log == []


def test_read_only_write_returns_2(loopback: tuple[Path, Drive], capsys: pytest.CaptureFixture[str]) -> None:
    path, drive = loopback
    assert main(["write", str(path), "shoulder", "actual_position", "1"]) == 2
    assert "read-only" in capsys.readouterr().err
    assert drive.write_log == []


# --- frame monitor and custom frames on an emulated bus ---------------------------------------

SIM_TOML = """
backend = "sim"
[sim]
model = "erob_stand.xml"
[buses.rs485]
protocol = "modbus-rtu"
[joints.joint1]
device = "erob"
bus = "rs485"
address = 2
"""


def test_monitor_prints_and_exports_frames(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    pytest.importorskip("mujoco")
    cfg = tmp_path / "sim.toml"
    cfg.write_text(SIM_TOML)
    out = tmp_path / "frames.csv"
    assert main(["monitor", str(cfg), "--duration", "0.3", "--period", "0.1", "--export", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "02 03 00 60 00 19 84 2D" in printed and "ReadHoldingRegisters" in printed
    rows = out.read_text().splitlines()
    assert rows[0] == "time,direction,bus,ident,node,data,meaning" and len(rows) == 1 + 6  # 3 polls x (tx, rx)


def test_send_custom_frame_adds_crc_and_refuses_unconfirmed_writes(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    pytest.importorskip("mujoco")
    cfg = tmp_path / "sim.toml"
    cfg.write_text(SIM_TOML)
    assert main(["send", str(cfg), "rs485", "02 03 00 66 00 02"]) == 0
    assert "02 03 00 66 00 02 24 27" in capsys.readouterr().out
    assert main(["send", str(cfg), "rs485", "02 06 00 F0 00 01"]) == 2
    assert "--confirm" in capsys.readouterr().err
    assert main(["send", str(cfg), "rs485", "02 06 00 F0 00 01", "--confirm"]) == 0
    assert main(["send", str(cfg), "rs485", "02 03 00 66 00 02 00 00"]) == 2  # bad CRC, not silently fixed
