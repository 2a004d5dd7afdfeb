"""Several MKS drives on one native bus through the drivers: one long packet moves five twins differently, broadcast
and group commands are not waited for, leaving the rig stops every axis it started (the MKS has no watchdog);
`joints scan` and `joints registers` find and list MKS drives on both protocols."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("mujoco")
pytestmark = pytest.mark.mks_firmware

from mkskit import motor_config, motor_model, open_motor

from joints.cli import main
from joints.config import parse
from joints.devices.mks.state import MotorStatus
from joints.drivers.mks_native import MksNativeDriver, long_packet
from joints.rig import build, sim_world
from joints.transports.serial_sim import TimedSerialLine


def _drivers(rig, n: int) -> list[MksNativeDriver]:  # type: ignore[no-untyped-def]
    out = [rig.joints[f"m{i}"].driver for i in range(1, n + 1)]
    assert all(isinstance(d, MksNativeDriver) for d in out)
    return out


def test_one_long_packet_from_the_drivers_moves_five_twins_differently_and_close_stops_them(tmp_path: Path) -> None:
    rig = open_motor(tmp_path, n=5)
    try:
        drivers = _drivers(rig, 5)
        for j in rig.joints.values():
            j.enable()
        sent = drivers[0].link.transactions
        long_packet([
            (drivers[0], drivers[0].plan_velocity(100, acceleration=2000)),
            (drivers[1], drivers[1].plan_velocity(-200, acceleration=2000)),
            (drivers[2], drivers[2].plan_move_pulses(3200 * 2, speed=300, acceleration=2000)),
            (drivers[3], drivers[3].plan_move_by(-0x4000, speed=300, acceleration=2000)),
            (drivers[4], drivers[4].plan_move_to(0x8000 + 0x2000, speed=600, acceleration=2000)),
        ])
        assert drivers[0].link.transactions == sent + 1  # ONE frame, no reply waited for
        assert [d.describe_running() for d in drivers] == ["speed", "speed", "pulses", "rel_axis", "abs_axis"]
        rig.sleep(2.0)
        speeds = [d.read("real_time_speed") for d in drivers[:2]]
        positions = [d.read("encoder_addition") for d in drivers[2:]]
        # the drive's speed is encoder counts over its 5 ms window (1 count = 0.73 rpm) at the instant read,
        # which the traffic before it moves (V1.0.6's 0x47 at enable, V1.0.9's 0x40)
        assert speeds == pytest.approx([100, -200], abs=1)
        assert positions[0] == pytest.approx(2 * 16384, abs=1)
        assert positions[1] == pytest.approx(-0x4000, abs=1)
        assert positions[2] == pytest.approx(0xA000, abs=1)
        assert all(d.completions == 0 for d in drivers)  # long packets get no completion frames either
    finally:
        rig.close()  # stops and disables every axis this host started (the speed-mode ones included)
    for i in range(1, 6):
        fw = rig.world.drives[f"m{i}"]
        assert fw.motion is None and not fw.enabled


def test_broadcast_and_group_commands_are_not_waited_for(tmp_path: Path) -> None:
    """On the timed half-duplex line a request costs wire time plus the reply; a send-only frame costs nothing
    of the host's time (it is not waited for) and all the addressed twins execute it."""
    cfg = parse(motor_config(motor_model(tmp_path, 3), n=3))
    world = sim_world(cfg)
    line = TimedSerialLine(world.buses["rs485"], baudrate=38400, clock=world.clock)
    rig = build(cfg, transports={"rs485": line}, clock=world.clock, world=world)
    try:
        d1, d2, d3 = _drivers(rig, 3)
        for j in rig.joints.values():
            j.enable()
        d1.set_group_address(0x50)
        d2.set_group_address(0x50)
        t0 = rig.time
        d1.read("real_time_speed")
        assert rig.time - t0 >= line.wire_time(4 + 6)  # a read waits for its reply
        t0 = rig.time
        d1.broadcast(d1.plan_velocity(60, acceleration=0), drivers=[d1, d2, d3])
        assert rig.time == t0  # nothing waited for
        rig.sleep(0.5)
        assert [d.read("real_time_speed") for d in (d1, d2, d3)] == [60, 60, 60]
        t0 = rig.time
        d1.send_group(0x50, d1.plan_velocity(0, acceleration=0), drivers=[d1, d2])
        assert rig.time == t0
        rig.sleep(0.3)
        assert [d.read("real_time_speed") for d in (d1, d2, d3)] == [0, 0, 60]
        assert [d.motor_status() for d in (d1, d2, d3)] == [MotorStatus.STOP, MotorStatus.STOP,
                                                              MotorStatus.FULL_SPEED]
        assert line.collisions == 0
    finally:
        rig.close()
    assert all(not world.drives[f"m{i}"].enabled for i in (1, 2, 3))


@pytest.mark.parametrize("protocol", ["mks-serial", "modbus-rtu"])
def test_scan_finds_mks_drives_on_both_protocols(tmp_path: Path, protocol: str, capsys: pytest.CaptureFixture[str],
                                                 mks_firmware: str) -> None:
    model = motor_model(tmp_path, 2)
    toml = tmp_path / "scan.toml"
    cfg = motor_config(model, n=2, protocol=protocol)
    lines = ['backend = "sim"', "[sim]", f'model = "{model}"', "[buses.rs485]", f'protocol = "{protocol}"',
             'port = "/dev/null"']
    for name, j in cfg["joints"].items():
        lines += [f"[joints.{name}]", 'device = "mks-servo42d"', 'bus = "rs485"', f"address = {j['address']}",
                  f'mjcf_joint = "{j["mjcf_joint"]}"']
    toml.write_text("\n".join(lines) + "\n")
    assert main(["scan", "--config", str(toml), "--bus", "rs485", "--device", "mks-servo42d", "--range", "1-4",
                 "--json"]) == 0
    found = json.loads(capsys.readouterr().out)
    # the bus cannot tell a SERVO42D from a 57D, and the MKS reports no model or serial; the version by 0x40 (V1.0.9)
    firmware, details = (("v1.0.9", {"hardware_version": "S42D_485", "calibrated": True}) if mks_firmware == "v1.0.9"
                         else (f"older than v1.0.9 (no answer to 0x40); configured {mks_firmware}", {}))
    assert found == [{"bus": "rs485", "protocol": protocol, "device": "mks", "address": a, "model": None,
                      "serial": None, "firmware": firmware, "details": details} for a in (1, 2)]


def test_registers_lists_both_mks_maps(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["registers", "--device", "mks-servo42d", "--protocol", "mks-serial"]) == 0
    native = capsys.readouterr().out
    assert "0x0094  home_reverse_angle" in native and "needs --confirm" in native
    assert main(["registers", "--device", "mks-servo57d"]) == 0  # modbus-rtu by default
    modbus = capsys.readouterr().out
    assert "0x0090  home_speed" in modbus and "0x0094  home_reverse_angle" in modbus  # FC16 0x0094 from V1.0.6
    assert "group_address" not in modbus  # 0x8D is native only
