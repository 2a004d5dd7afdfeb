"""The eRob CANopen driver on ZeroErr's EDS (or the twin's export) as its object dictionary (issue 31)."""

from __future__ import annotations

from pathlib import Path

import pytest
from edskit import vendor_eds

import joints
from joints.config import load
from joints.devices.erob.eds import eds_text
from joints.devices.erob.profiles import profile
from joints.drivers.canopen_sync import SyncCycle
from joints.drivers.erob_canopen import ErobCanopenDriver
from joints.errors import ConfigError, RegisterError
from joints.link.canopen import CanopenLink
from joints.sim.erob import ErobFirmware
from joints.sim.erob_canopen import CanopenFront, ErobCanopenBus
from joints.transports.can import PythonCanTransport
from joints.transports.can_sim import LockstepCanBus


def bus() -> tuple[CanopenLink, ErobCanopenBus]:
    device = ErobCanopenBus()
    device.add(CanopenFront(ErobFirmware(profile("eRob80H100"), 2), 2))
    link = CanopenLink(PythonCanTransport(LockstepCanBus(medium=device.medium)), clock=device.medium.clock,
                       bus_clock=True)
    device.tick(0.001)
    return link, device


def test_driver_on_zeroerrs_eds_reads_temperature_and_vendor_objects(tmp_path: Path) -> None:
    link, device = bus()
    d = ErobCanopenDriver(link, 2, mode="pp", heartbeat_ms=0, eds=vendor_eds(tmp_path / "zeroerr.eds"))
    d.bring_up()
    fw = device.front(2).firmware
    fw.temperature = 52.4
    state = d.state()
    assert state.temperature == 52.0 == fw.read("part_of_power_temperature")  # 0x22A2 = Modbus 0x0078, degC
    assert d.read("0x6099:1") == 100  # the file's homing speed default, read back from the twin
    assert d.access.map.key("interpolation_data_record_1").datatype.name == "INTEGER16"  # the file's type
    with pytest.raises(RegisterError, match="0x6073"):
        d.read("0x6073")  # not in the file


def test_ip_on_zeroerrs_eds_is_refused_the_twins_export_is_taken(tmp_path: Path) -> None:
    """ZeroErr's EDS types 0x60C1:01 INTEGER16: an IP set-point in counts does not fit; refused before
    anything is sent, naming the object. The twin's export (the listed deviation) is taken."""
    link, _device = bus()
    with pytest.raises(ConfigError, match="0x60C1:01"):
        ErobCanopenDriver(link, 2, mode="ip", heartbeat_ms=0, eds=vendor_eds(tmp_path / "zeroerr.eds"))
    exported = tmp_path / "twin.eds"
    exported.write_text(eds_text(2), encoding="utf-8")
    d = ErobCanopenDriver(link, 2, mode="ip", heartbeat_ms=0, eds=exported)
    assert d.access.map.key("interpolation_data_record_1").datatype.name == "INTEGER32"


@pytest.mark.parametrize("mode", ["pp", "pv", "pt", "csp", "csv", "cst"])
def test_every_mode_but_ip_takes_zeroerrs_eds(mode: str, tmp_path: Path) -> None:
    link, _device = bus()
    d = ErobCanopenDriver(link, 2, mode=mode, heartbeat_ms=0, eds=vendor_eds(tmp_path / "zeroerr.eds"))
    assert d.access.map.key("statusword").index == 0x6041


def test_a_file_that_is_no_eds_is_a_config_error(tmp_path: Path) -> None:
    link, _device = bus()
    bad = tmp_path / "x.eds"
    bad.write_text("[FileInfo]\nFileName=x\n")
    with pytest.raises(ConfigError, match="not a readable EDS"):
        ErobCanopenDriver(link, 2, eds=bad)


def test_the_sync_cycle_is_held_by_the_link() -> None:
    link, _device = bus()
    a = SyncCycle.of(link, 0.002)
    assert SyncCycle.of(link, 0.001) is a is link.sync_cycle and a.period == 0.002
    d = ErobCanopenDriver(link, 2, mode="csp", heartbeat_ms=0, cycle=SyncCycle.of(link, 0.002))
    assert d.group is a and d in a.drivers


def test_the_joint_key_eds_names_the_file_relative_to_the_config(tmp_path: Path) -> None:
    """``eds = "path"`` on a CANopen joint: resolved against the config file's directory and handed to
    the driver, which then reads the file's objects (temperature at 0x22A2, the homing speed default)."""
    (tmp_path / "vendor").mkdir()
    vendor_eds(tmp_path / "vendor" / "zeroerr.eds")
    (tmp_path / "rig").mkdir()
    config = tmp_path / "rig" / "robot.toml"
    config.write_text('backend = "sim"\n[sim]\nmodel = "erob_arm3.xml"\n'
                      '[buses.can]\nprotocol = "canopen"\n'
                      '[joints.joint1]\ndevice = "erob"\nbus = "can"\naddress = 1\nmode = "pp"\n'
                      'eds = "../vendor/zeroerr.eds"\n'
                      '[joints.joint2]\ndevice = "erob"\nbus = "can"\naddress = 2\nmode = "pp"\n', encoding="utf-8")
    cfg = load(config)
    assert Path(cfg.joints["joint1"].eds or "") == tmp_path / "rig" / ".." / "vendor" / "zeroerr.eds"
    assert cfg.joints["joint2"].eds is None
    with joints.open(cfg) as rig:
        on_file, built_in = rig.joints["joint1"].driver, rig.joints["joint2"].driver
        assert on_file.access.map.key("interpolation_data_record_1").datatype.name == "INTEGER16"  # the file's
        assert built_in.access.map.key("interpolation_data_record_1").datatype.name == "INTEGER32"
        assert on_file.read("0x6099:1") == 100  # the file's homing speed default, read back from the twin
        assert rig.joints["joint1"].state().temperature == rig.joints["joint2"].state().temperature


def test_a_missing_eds_file_is_a_config_error_at_load(tmp_path: Path) -> None:
    config = tmp_path / "robot.toml"
    config.write_text('backend = "sim"\n[buses.can]\nprotocol = "canopen"\n'
                      '[joints.j]\ndevice = "erob"\nbus = "can"\naddress = 1\neds = "zeroerr.eds"\n',
                      encoding="utf-8")
    with pytest.raises(ConfigError, match="does not exist: give the path of the drive's EDS file") as info:
        load(config)
    assert info.value.key == "joints.j.eds" and str(tmp_path / "zeroerr.eds") in str(info.value)
    vendor_eds(tmp_path / "zeroerr.eds")
    assert load(config).joints["j"].eds == str(tmp_path / "zeroerr.eds")


def test_eds_on_a_joint_without_an_object_dictionary_is_refused(tmp_path: Path) -> None:
    vendor_eds(tmp_path / "zeroerr.eds")
    config = tmp_path / "robot.toml"
    config.write_text('backend = "sim"\n[buses.rs485]\nprotocol = "modbus-rtu"\nport = "/dev/null"\n'
                      '[joints.j]\ndevice = "erob"\nbus = "rs485"\naddress = 1\neds = "zeroerr.eds"\n',
                      encoding="utf-8")
    with pytest.raises(ConfigError, match="only a CANopen joint") as info:
        load(config)
    assert info.value.key == "joints.j.eds"
