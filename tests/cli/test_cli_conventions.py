"""Conventions every command keeps: --help with an example, exit codes, JSON, closed pipes, parse-time checks.

Also the commands that need no served world: plot, replay, sim view (headless), and the in-process
sim backend for the rest.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import pytest
from clikit import joints_cmd

import joints
from joints.cli import build_parser, main


def run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    rc = main([str(a) for a in args])
    c = capsys.readouterr()
    return rc, c.out, c.err


def _leaves(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()) -> list[tuple[tuple[str, ...], Any]]:
    out = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out += _leaves(sub, (*path, name))
    return out or [(path, parser)]


COMMANDS = _leaves(build_parser())


def test_every_command_is_listed() -> None:
    names = {" ".join(p) for p, _ in COMMANDS}
    assert {"scan", "info", "watch", "move", "jog", "enable", "disable", "stop", "clear", "monitor", "replay", "send",
            "params dump", "params load", "params diff", "plot", "sim serve", "sim view", "state", "read", "write",
            "registers"} <= names


@pytest.mark.parametrize("path", [p for p, _ in COMMANDS], ids=[" ".join(p) for p, _ in COMMANDS])
def test_every_command_has_help_with_an_example(path: tuple[str, ...], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main([*path, "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "example:" in out and "joints " + path[0] in out.split("example:")[1]


def _groups(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    out = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            out += [path] if path else []
            for name, sub in action.choices.items():
                out += _groups(sub, (*path, name))
    return out


GROUPS = _groups(build_parser())


def test_command_groups_are_found() -> None:
    assert {("params",), ("sim",)} <= set(GROUPS)


@pytest.mark.parametrize("path", GROUPS, ids=[" ".join(p) for p in GROUPS])
def test_every_command_group_has_help_with_an_example(path: tuple[str, ...],
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main([*path, "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "example:" in out and "joints " + " ".join(path) + " " in out.split("example:")[1]


@pytest.mark.parametrize("args", [
    ["monitor", "x.toml", "--duration", "-1"],
    ["watch", "x.toml", "--period", "0"],
    ["jog", "x.toml", "j", "--velocity", "1", "--duration", "-1"],
    ["move", "x.toml", "j", "nan"],
    ["scan", "--port", "/dev/null", "--timeout", "-0.1"],
    ["scan", "--port", "/dev/null", "--range", "9-3"],
    ["sim", "serve", "x.toml", "--realtime-factor", "0"],
])
def test_numbers_are_checked_when_parsing(args: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(args)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "usage:" in err and "Traceback" not in err


def test_unknown_export_extension_names_the_allowed_ones(sim_config: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["monitor", str(sim_config), "--export", str(tmp_path / "x.xlsx")])
    err = capsys.readouterr().err
    assert info.value.code == 2 and "'.xlsx'" in err and ".csv" in err and ".jsonl" in err and ".blf" in err
    cfg = sim_config
    rc, _, err = run(capsys, "monitor", cfg, "--bus", "rs485", "--export", tmp_path / "x.asc")
    assert rc == 2 and "cannot hold RS485 frames" in err and ".csv" in err
    rc, _, err = run(capsys, "monitor", cfg, "--bus", "rs485", "--listen")
    assert rc == 2 and "CAN" in err


@pytest.mark.parametrize("tail", ["true", "head -1"])
def test_registers_survives_a_closed_pipe(tail: str) -> None:
    proc = joints_cmd("registers", "--device", "erob", shell_tail=tail)
    assert proc.returncode == 0
    assert proc.stderr == ""
    if tail.startswith("head"):
        assert proc.stdout.startswith("0x0000  modbus_address")


@pytest.mark.parametrize("args", [["monitor", "{cfg}", "--duration", "0"], ["watch", "{cfg}", "a"],
                                  ["state", "{cfg}"]])
def test_endless_output_ends_quietly_when_the_reader_goes(args: list[str], sim_config: Path) -> None:
    proc = joints_cmd(*(a.format(cfg=sim_config) for a in args), shell_tail="head -1", timeout=120)
    assert proc.returncode == 0 and proc.stderr == "" and len(proc.stdout.splitlines()) == 1


def test_help_survives_a_closed_pipe() -> None:
    proc = joints_cmd("--help", shell_tail="head -1")
    assert proc.returncode == 0 and proc.stderr == "" and proc.stdout.startswith("usage: joints")


@pytest.mark.parametrize("device,protocol,first", [("erob", "canopen", "0x1000:00"), ("erob", "erob-can", "0x0001/3"),
                                                    ("zlac8015d", None, "0x2000"), ("mks-servo42d", "mks-serial",
                                                                                    "0x0030")])
def test_registers_of_every_map(device: str, protocol: str | None, first: str,
                                capsys: pytest.CaptureFixture[str]) -> None:
    args = ["registers", "--device", device] + (["--protocol", protocol] if protocol else [])
    rc, out, _ = run(capsys, *args)
    assert rc == 0 and out.startswith(first)
    rc, out, _ = run(capsys, *args, "--json")
    rows = json.loads(out)
    assert rc == 0 and rows[0]["where"] == first and {"name", "type", "access", "unit", "persistent"} <= set(rows[0])


# --- the in-process sim backend --------------------------------------------------------------------


@pytest.fixture
def sim(sim_config: Path) -> Path:
    return sim_config


def test_read_only_commands_print_json(sim: Path, capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    for args in (["state", sim, "--json"], ["watch", sim, "a", "--samples", "2", "--json"],
                 ["monitor", sim, "--bus", "co", "--duration", "0.05", "--json"]):
        rc, out, err = run(capsys, *args)
        assert rc == 0, err
        assert [json.loads(line) for line in out.splitlines()]
    for args in (["info", sim, "l", "--json"], ["scan", "--config", sim, "--bus", "can", "--range", "6", "--json"],
                 ["params", "dump", sim, "c", "--json"], ["send", sim, "--bus", "mks", "FA 05 F1", "--json"],
                 ["registers", "--json"]):
        rc, out, err = run(capsys, *args)
        assert rc == 0, err
        json.loads(out)


def test_a_refusal_names_the_confirm_flag(sim: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc, _, err = run(capsys, "write", sim, "a", "modbus_baud_rate", "3")
    assert rc == 2 and "--confirm" in err and "confirm=True" not in err


HW = ('backend = "hardware"\n[buses.rs485]\nprotocol = "modbus-rtu"\nport = "{port}"\n'
      '[joints.a]\ndevice = "erob"\nbus = "rs485"\naddress = 1\n')


def test_a_bus_error_exits_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = tmp_path / "hw.toml"
    cfg.write_text(HW.format(port=tmp_path / "ttyNOPE"))
    rc, out, err = run(capsys, "state", cfg)
    assert rc == 1 and "cannot open serial port" in err and out == ""


def test_mode_choice_comes_from_the_registry(sim: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc, _, err = run(capsys, "move", sim, "a", "0.1", "--mode", "csp")
    assert rc == 2 and "no modes to choose from" in err
    rc, _, err = run(capsys, "move", sim, "o", "0.1", "--mode", "fast")
    assert rc == 2 and "pp, pv, pt, csp, csv, cst, ip" in err


def test_cyclic_modes_stream_set_points(sim: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, err = run(capsys, "move", sim, "o", "0.3", "--mode", "csp", "--json")
    assert rc == 0, err
    assert json.loads(out)["position"] == pytest.approx(0.3, abs=0.01)
    rc, out, err = run(capsys, "jog", sim, "o", "--velocity", "0.5", "--duration", "0.5", "--mode", "csv", "--json")
    assert rc == 0, err
    assert json.loads(out)["position"] > 0.1


def test_other_cia402_modes(sim: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, err = run(capsys, "move", sim, "o", "0.2", "--mode", "ip", "--json")
    assert rc == 0, err
    assert json.loads(out)["position"] == pytest.approx(0.2, abs=0.01)
    for mode in ("pt", "cst"):  # a torque well above the joint's static friction
        start = json.loads(run(capsys, "state", sim, "o")[1])["position"]
        rc, out, err = run(capsys, "jog", sim, "o", "--torque", "15", "--duration", "1", "--mode", mode, "--json")
        assert rc == 0, (mode, err)
        assert json.loads(out)["position"] - start > 0.05
    rc, _, err = run(capsys, "jog", sim, "o", "--velocity", "0.5", "--mode", "cst")
    assert rc == 2 and "--torque" in err


@pytest.mark.mks_firmware
def test_mks_pulse_moves(sim: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, err = run(capsys, "move", sim, "n", "1600", "--pulses", "--relative", "--json")
    assert rc == 0, err
    assert json.loads(out)["position"] == pytest.approx(3.14159, abs=0.01)  # 1600 of 3200 pulses: half a turn
    rc, _, err = run(capsys, "move", sim, "a", "1600", "--pulses")
    assert rc == 2 and "no pulse position modes" in err


@pytest.mark.mks_firmware
def test_send_of_a_refused_fc06_0xffff_to_the_mks_reports_the_refusal(sim: Path, mks_firmware: str,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """0xFFFF to 0x83 (working current) of the MKS at 4: refused by every profile (V1.0.6+: the failure reply, whose
    data equal the value sent; V1.0.5: exception 03), never reported as written."""
    rc, out, err = run(capsys, "send", sim, "--bus", "rs485", "04 06 00 83 FF FF", "--confirm")
    assert rc == 1 and "slave 4 re" in err, (rc, out, err)  # "refused" / "rejected"
    assert ("failure reply" in err) == (mks_firmware != "v1.0.5") != ("exception 0x03" in err)
    with joints.open(sim) as rig:  # the eRobs (1, 2) and the ZLAC (3) on the same bus declare no failure replies
        assert set(rig.buses["rs485"].link.rule.failure_replies) == ({4} if mks_firmware != "v1.0.5" else set())


def test_replay_of_a_recorded_log_gives_the_same_replies(sim: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    for bus, ext in (("rs485", ".jsonl"), ("can", ".asc")):
        log = tmp_path / f"run-{bus}{ext}"
        assert run(capsys, "monitor", sim, "--bus", bus, "--duration", "0.3", "--export", log, "--quiet")[0] == 0
        rc, out, _ = run(capsys, "replay", log, sim, "--bus", bus)
        assert rc == 0 and " 0 different" in out
    log = tmp_path / "run-rs485.jsonl"
    lines = log.read_text().splitlines()
    row = json.loads(lines[1])  # the first reply: change one byte of the recorded value
    data = bytearray.fromhex(row["data"])
    data[4] ^= 0x01
    row["data"] = data.hex(" ").upper()
    lines[1] = json.dumps(row)
    log.write_text("\n".join(lines) + "\n")
    rc, out, _ = run(capsys, "replay", log, sim, "--bus", "rs485", "--json")
    results = json.loads(out)
    assert rc == 1 and results[0]["same"] is False and all(r["same"] for r in results[1:])


def test_replay_on_hardware_needs_confirm(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "x.jsonl"
    log.write_text("")
    cfg = tmp_path / "hw.toml"
    cfg.write_text(HW.format(port="/dev/null"))
    rc, _, err = run(capsys, "replay", log, cfg)
    assert rc == 2 and "--confirm" in err


# --- plot ----------------------------------------------------------------------------------------


def _png_ok(path: Path) -> None:
    import numpy as np
    from matplotlib import image

    img = image.imread(str(path))
    assert img.shape[0] >= 300 and img.shape[1] >= 600
    assert float(np.std(img[..., :3])) > 0.01  # not blank
    assert len(np.unique(img[..., :3].reshape(-1, 3), axis=0)) > 20


def test_plot_a_state_trace(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("matplotlib")
    import math

    trace = tmp_path / "trace.jsonl"
    trace.write_text("".join(json.dumps({"joint": j, "time": t / 100, "position": math.sin(t / 10 + k),
                                         "velocity": math.cos(t / 10 + k), "current": 0.1 * t, "torque": None}) + "\n"
                             for t in range(100) for k, j in enumerate(("a", "b"))))
    png = tmp_path / "trace.png"
    rc, _, err = run(capsys, "plot", trace, "-o", png)
    assert rc == 0, err
    _png_ok(png)


def test_plot_a_monitor_log(sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("matplotlib")
    log = tmp_path / "frames.csv"
    assert run(capsys, "monitor", sim, "--bus", "rs485", "--duration", "0.5", "--export", log, "--quiet")[0] == 0
    for extra in ([], ["--config", sim, "--param", "actual_position", "--param", "motor_temperature"]):
        png = tmp_path / f"frames{len(extra)}.png"
        rc, _, err = run(capsys, "plot", log, "-o", png, *extra)
        assert rc == 0, err
        _png_ok(png)
    rc, _, err = run(capsys, "plot", log, "-o", tmp_path / "x.jpg")
    assert rc == 2 and ".png" in err


# --- sim serve / view ------------------------------------------------------------------------------


def test_sim_view_needs_a_display(sim: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    if not sys.platform.startswith("linux"):
        pytest.skip("the display check is Linux's")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    rc, _, err = run(capsys, "sim", "view", sim)
    assert rc == 2 and "needs a display" in err


def test_sim_view_syncs_the_viewer_while_serving(sim: Path, monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    if sys.platform == "win32":
        pytest.skip("serving needs POSIX")
    pytest.importorskip("serial")
    pytest.importorskip("msgpack")
    from joints.cli import sim as sim_cli

    class Viewer:
        def __init__(self, world: Any) -> None:
            self.world = world
            self.syncs = 0
            self.closed = False

        def is_running(self) -> bool:
            return self.syncs < 20

        def sync(self) -> None:
            self.syncs += 1

        def close(self) -> None:
            self.closed = True

    made: list[Viewer] = []

    def launch(world: Any) -> Viewer:
        made.append(Viewer(world))
        return made[-1]

    monkeypatch.setattr(sim_cli, "launch_viewer", launch)
    rc, out, _ = run(capsys, "sim", "view", sim)
    assert rc == 0
    (viewer,) = made
    assert viewer.syncs == 20 and viewer.closed and viewer.world.model is not None
    assert {json.loads(line)["bus"] for line in out.splitlines()} == {"rs485", "mks", "can", "co"}


def test_sim_serve_binds_a_serial_port_name(sim: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    if sys.platform == "win32":
        pytest.skip("serving needs POSIX")
    pytest.importorskip("serial")
    pytest.importorskip("msgpack")
    import threading

    from joints.cli import sim as sim_cli
    from joints.sim import serve as serve_mod

    link = tmp_path / "ttyJOINTS0"
    seen: dict[str, Any] = {}
    real = serve_mod.serve

    def serve(world: Any, buses: Any, **kw: Any) -> None:
        stop = threading.Event()
        ready = kw.pop("on_ready")

        def on_ready(lines: Any) -> None:
            ready(lines)
            seen["lines"] = lines
            seen["target"] = link.resolve()
            stop.set()
        real(world, buses, stop=stop, on_ready=on_ready, **{k: v for k, v in kw.items() if k != "stop"})

    monkeypatch.setattr(serve_mod, "serve", serve)
    rc = main(["sim", "serve", str(sim), "--bind", f"rs485={link}", "--realtime-factor", "2", "--verbose",
               "--hardware-config", str(tmp_path / "hw.toml")])
    capsys.readouterr()
    assert rc == 0 and sim_cli is not None
    assert seen["lines"]["rs485"]["port"] == str(link) and str(seen["target"]).startswith("/dev/")
    assert not link.exists()  # removed when serving ends
    assert f'port = "{link}"' in (tmp_path / "hw.toml").read_text()
