"""``joints bench --hardware``: round trips on a real bus, measured here on a served twin that keeps the
real bus's time (``joints sim serve`` in another process, over a pseudo-terminal).

The served twin runs on the wall clock, so these round trips are wall-clock times: each check uses
medians of many transactions and a configured overhead large against scheduling noise (20 ms).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

pytest.importorskip("mujoco")
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals need POSIX")

from joints import bench
from joints.config import load, parse
from joints.errors import ConfigError
from joints.rig import served_timing

LATENCY = 0.020  #: s of adapter latency the served twin emulates

CONFIG = f"""
backend = "sim"
[sim]
model = "erob_stand.xml"
[buses.rs485]
protocol = "modbus-rtu"
port = "/dev/null"
baudrate = 115200
timeout = 0.5
adapter_latency = {LATENCY}
[joints.joint1]
device = "erob"
bus = "rs485"
address = 2
limits = {{ position = [-3.1, 3.1], velocity = 2.0, torque = 20.0 }}
"""


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory, sim_served):  # type: ignore[no-untyped-def]
    cfg = tmp_path_factory.mktemp("served") / "robot.toml"
    cfg.write_text(CONFIG)
    with sim_served(cfg) as s:
        yield cfg, s


def test_bench_reports_the_served_turnaround_plus_adapter_latency(served, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    cfg, s = served
    timing = served_timing(load(cfg))["rs485"]
    expected = timing.turnaround(2) + LATENCY
    reports = bench.measure_hardware(s.hardware, rounds=40, sys_root=tmp_path)
    (r,) = reports
    assert r.failures == 0 and len(r.round_trips(2)) == 40
    # the eRob status block: FC03 of 25 registers (8 bytes), reply 55 bytes, t3.5 between them
    assert r.wire(2) == pytest.approx((8 + 55) * 10 / 115200 + 1.75e-3)
    assert r.overhead(2, 0.1) == pytest.approx(expected, rel=0.10), bench.hardware_report(reports)
    assert r.overhead(2) > 0.9 * expected
    assert not r.warnings  # no latency timer on a pty

    # the overlay: the profile keeps its turnaround, the bus gets the rest; a config that includes it
    # gets the measured adapter latency, and its own keys win over the overlay's
    overlay = tmp_path / "timing.toml"
    overlay.write_text(bench.overlay_text(reports, bench.profile_turnarounds(cfg), per_joint=False))
    own = cfg.read_text().replace(f"adapter_latency = {LATENCY}\n", "")
    (tmp_path / "robot.toml").write_text('timing_overlay = "timing.toml"\n' + own)
    measured = load(tmp_path / "robot.toml").buses["rs485"].adapter_latency
    split = r.adapter_latency(bench.profile_turnarounds(cfg)["rs485"])  # median overhead - the profile's turnaround
    assert measured == pytest.approx(split, abs=1e-6) and split == pytest.approx(r.overhead(2) - timing.turnaround(2))
    (tmp_path / "own.toml").write_text('timing_overlay = "timing.toml"\n' + own.replace(
        'baudrate = 115200', 'baudrate = 115200\nadapter_latency = 0.0005'))
    assert load(tmp_path / "own.toml").buses["rs485"].adapter_latency == 0.0005


def test_latency_timer_warning_from_a_fake_sysfs_tree(served, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    _cfg, s = served
    port = os.path.realpath(s.port("rs485"))
    tty = os.path.basename(port)
    node = tmp_path / "bus" / "usb-serial" / "devices" / tty
    node.mkdir(parents=True)
    (node / "latency_timer").write_text("16\n")
    assert bench.latency_timer(port, tmp_path) == (16, node / "latency_timer")
    (r,) = bench.measure_hardware(s.hardware, rounds=2, sys_root=tmp_path)
    (warning,) = r.warnings or []
    assert "16 ms" in warning and str(node / "latency_timer") in warning
    assert "echo 1" in warning and "udev" in warning and "low_latency" in warning
    assert "WARNING" in bench.hardware_report([r])
    (node / "latency_timer").write_text("1\n")  # lowered: no warning
    (r,) = bench.measure_hardware(s.hardware, rounds=2, sys_root=tmp_path)
    assert not r.warnings


def test_latency_timer_of_a_port_without_one(tmp_path: Path) -> None:
    assert bench.latency_timer("/dev/ttyUSB9", tmp_path) is None


def test_timing_overlay_errors_name_the_overlay_file(tmp_path: Path) -> None:
    base = {"backend": "sim", "buses": {"rs485": {"protocol": "modbus-rtu"}},
            "joints": {"j": {"device": "erob", "bus": "rs485", "address": 1}}}
    bad = tmp_path / "t.toml"
    bad.write_text("[buses.other]\nadapter_latency = 0.001\n")
    with pytest.raises(ConfigError, match=r"t\.toml: \[buses\.other\].*no bus 'other'"):
        parse({**base, "timing_overlay": "t.toml"}, base_dir=tmp_path)
    bad.write_text("[buses.rs485]\nbaudrate = 9600\n")
    with pytest.raises(ConfigError, match=r"\[buses\.rs485\.baudrate\] unknown key"):
        parse({**base, "timing_overlay": "t.toml"}, base_dir=tmp_path)
    with pytest.raises(ConfigError, match="timing overlay not found"):
        parse({**base, "timing_overlay": "none.toml"}, base_dir=tmp_path)
    bad.write_text("[buses.rs485]\nadapter_latency = -1.0\n")
    with pytest.raises(ConfigError, match=r"adapter_latency\] -1.0 is out of range"):
        parse({**base, "timing_overlay": "t.toml"}, base_dir=tmp_path)


CAN_LATENCY = 0.010  #: s of adapter latency the served CAN bus emulates

CAN_CONFIG = f"""
backend = "sim"
[sim]
model = "erob_stand.xml"
[buses.can]
protocol = "erob-can"
interface = "virtual"
bitrate = 1000000
timeout = 0.5
adapter_latency = {CAN_LATENCY}
[joints.joint1]
device = "erob"
bus = "can"
address = 3
limits = {{ position = [-3.1, 3.1], velocity = 2.0, torque = 20.0 }}
"""


def test_bench_over_a_served_can_bus(tmp_path: Path, sim_served) -> None:  # type: ignore[no-untyped-def]
    """The eRob CAN protocol served on udp_multicast: every request frame is held for its bits and the drive's
    turnaround, every reply frame for its bits and the adapter latency; the bench sees their sum."""
    pytest.importorskip("can")
    cfg = tmp_path / "can.toml"
    cfg.write_text(CAN_CONFIG)
    expected = served_timing(load(cfg))["can"].turnaround(3) + CAN_LATENCY
    with sim_served(cfg) as s:
        (r,) = bench.measure_hardware(s.hardware, rounds=15, sys_root=tmp_path)
    assert r.failures == 0 and r.round_trips(3), bench.hardware_report([r])
    assert 100e-6 < r.wire(3) < 400e-6  # a request and its reply frame at 1 Mbit/s
    assert r.overhead(3, 0.1) == pytest.approx(expected, rel=0.10), bench.hardware_report([r])
    assert r.overhead(3) > 0.9 * expected


def test_the_hardware_config_of_served_twins_keeps_the_timing_overlay(tmp_path: Path) -> None:
    from joints.cli.sim import hardware_config

    (tmp_path / "timing.toml").write_text("[buses.rs485]\nadapter_latency = 0.002\n")
    (tmp_path / "robot.toml").write_text('timing_overlay = "timing.toml"\n' + CONFIG.replace(
        f"adapter_latency = {LATENCY}\n", ""))
    elsewhere = tmp_path / "out"
    elsewhere.mkdir()
    (elsewhere / "hw.toml").write_text(hardware_config(tmp_path / "robot.toml", {"rs485": {"bus": "rs485",
                                                                                           "port": "/dev/pts/9"}}))
    hw = load(elsewhere / "hw.toml")
    assert hw.backend == "hardware" and hw.buses["rs485"].adapter_latency == 0.002
