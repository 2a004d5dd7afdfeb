"""Configuration: parse() and load() accept a good file and name file, key and allowed values on errors."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest

from joints.config import BusConfig, JointConfig, RigConfig, load, parse
from joints.errors import ConfigError
from joints.joint import Limits, Motion

GOOD_TOML = """\
backend = "hardware"
on_exit = "disable"

[sim]
model = "erob_stand.xml"
timestep = 0.002

[buses.rs485]
protocol = "modbus-rtu"
port = "/dev/ttyUSB0"
baudrate = 115200
timeout = 0.05
retries = 1

[joints.shoulder]
device = "erob"
model = "eRob80H100"
bus = "rs485"
address = 2
limits = { position = [-3.1, 3.1], velocity = 2.0, torque = 20.0 }
motion = { velocity = 0.5, acceleration = 2.0, deceleration = 3.0 }
watchdog_ms = 500
offset = 0.25
direction = -1
profile = { efficiency = 0.6 }

[joints.elbow]
device = "erob"
bus = "rs485"
address = 3
"""


def good() -> dict[str, Any]:
    """The parsed form of a good hardware config (a fresh copy per test)."""
    return copy.deepcopy({
        "backend": "hardware",
        "buses": {"rs485": {"protocol": "modbus-rtu", "port": "/dev/ttyUSB0"}},
        "joints": {
            "shoulder": {"device": "erob", "bus": "rs485", "address": 2,
                         "limits": {"position": [-3.1, 3.1], "velocity": 2.0, "torque": 20.0}},
            "elbow": {"device": "erob", "bus": "rs485", "address": 3},
        },
    })


@pytest.fixture(autouse=True)
def _no_backend_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("JOINTS_BACKEND", raising=False)


def write(tmp_path: Path, text: str, name: str = "robot.toml") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def config_error(data: dict[str, Any], **kw: Any) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        parse(data, source="rig.toml", **kw)
    return info.value


# --- good configs -----------------------------------------------------------------------------


def test_load_good_hardware_config(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD_TOML)
    cfg = load(path)
    assert isinstance(cfg, RigConfig)
    assert cfg.backend == "hardware"
    assert cfg.source == str(path)
    assert cfg.base_dir == tmp_path.resolve()
    assert cfg.on_exit == "disable"
    assert cfg.sim.model == "erob_stand.xml" and cfg.sim.timestep == 0.002 and cfg.sim.realtime is False
    assert cfg.buses["rs485"] == BusConfig(name="rs485", protocol="modbus-rtu", port="/dev/ttyUSB0",
                                           baudrate=115200, timeout=0.05, retries=1, backend="hardware")
    sh = cfg.joints["shoulder"]
    assert isinstance(sh, JointConfig)
    assert (sh.device, sh.bus, sh.address, sh.model) == ("erob", "rs485", 2, "eRob80H100")
    assert sh.limits == Limits(position=(-3.1, 3.1), velocity=2.0, torque=20.0)
    assert sh.motion == Motion(velocity=0.5, acceleration=2.0, deceleration=3.0)
    assert sh.watchdog_ms == 500 and sh.offset == 0.25 and sh.direction == -1
    assert dict(sh.profile) == {"efficiency": 0.6}
    assert sh.mjcf_joint == "shoulder"  # defaults to the joint name
    el = cfg.joints["elbow"]
    assert el.limits == Limits() and el.motion == Motion() and el.direction == 1 and el.watchdog_ms is None
    assert list(cfg.joints) == ["shoulder", "elbow"]


def test_parse_good_dict_has_defaults() -> None:
    cfg = parse(good())
    assert cfg.source == "<dict>"
    bus = cfg.buses["rs485"]
    assert (bus.baudrate, bus.parity, bus.stopbits, bus.retries, bus.echo) == (115200, "N", 1, 2, False)
    assert cfg.on_exit == "disable"


def test_backend_defaults_to_sim() -> None:
    data = good()
    del data["backend"]
    assert parse(data).backend == "sim"


def test_backend_override_by_argument(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD_TOML)
    assert load(path, backend="sim").backend == "sim"
    assert parse(good(), backend="sim").backend == "sim"


def test_backend_override_by_env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("JOINTS_BACKEND", "sim")
    assert load(write(tmp_path, GOOD_TOML)).backend == "sim"
    assert parse(good()).backend == "sim"


def test_backend_argument_wins_over_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("JOINTS_BACKEND", "sim")
    data = good()
    data["backend"] = "sim"
    assert parse(data, backend="hardware").backend == "hardware"


def test_bad_backend_env_names_the_variable(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("JOINTS_BACKEND", "simulation")
    err = config_error(good())
    assert "JOINTS_BACKEND" in str(err)
    assert "'simulation'" in str(err)
    assert "'sim'" in str(err) and "'hardware'" in str(err)


def test_bad_backend_argument() -> None:
    err = config_error(good(), backend="bogus")
    assert "'bogus'" in str(err) and "'sim', 'hardware'" in str(err)


def test_bad_backend_in_file_is_reported_even_when_overridden(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD_TOML.replace('backend = "hardware"', 'backend = "hardwre"'))
    with pytest.raises(ConfigError) as info:
        load(path, backend="sim")
    msg = str(info.value)
    assert str(path) in msg and "[backend]" in msg and "'hardwre'" in msg and "'hardware'" in msg


# --- each error names the file, the key and what is allowed -----------------------------------


def test_unknown_top_level_key(tmp_path: Path) -> None:
    path = write(tmp_path, "bakend = 'sim'\n" + GOOD_TOML)
    with pytest.raises(ConfigError) as info:
        load(path)
    err = info.value
    msg = str(err)
    assert str(path) in msg
    assert "[bakend]" in msg and "unknown key" in msg
    for allowed in ("'backend'", "'sim'", "'buses'", "'joints'", "'on_exit'"):
        assert allowed in msg
    assert (err.file, err.key) == (str(path), "bakend")


def test_unknown_bus_key(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD_TOML.replace("baudrate = 115200", "baud = 115200"))
    with pytest.raises(ConfigError) as info:
        load(path)
    msg = str(info.value)
    assert str(path) in msg and "[buses.rs485.baud]" in msg
    assert "'baudrate'" in msg and "'port'" in msg and "'protocol'" in msg


def test_bad_protocol() -> None:
    data = good()
    data["buses"]["rs485"]["protocol"] = "modbus-tcp"
    err = config_error(data)
    msg = str(err)
    assert msg.startswith("rig.toml: ")
    assert "[buses.rs485.protocol]" in msg and "'modbus-tcp'" in msg
    for p in ("'modbus-rtu'", "'mks-serial'", "'erob-can'", "'canopen'"):
        assert p in msg


def test_missing_protocol() -> None:
    data = good()
    del data["buses"]["rs485"]["protocol"]
    msg = str(config_error(data))
    assert "[buses.rs485.protocol]" in msg and "required" in msg and "'modbus-rtu'" in msg


def test_missing_port_for_hardware() -> None:
    data = good()
    del data["buses"]["rs485"]["port"]
    msg = str(config_error(data))
    assert "rig.toml" in msg and "[buses.rs485.port]" in msg
    assert "required" in msg and "hardware" in msg and "/dev/ttyUSB0" in msg


def test_port_not_required_for_sim() -> None:
    data = good()
    data["backend"] = "sim"
    del data["buses"]["rs485"]["port"]
    cfg = parse(data)
    assert cfg.backend == "sim" and cfg.buses["rs485"].port is None


def test_port_required_when_overridden_to_hardware() -> None:
    data = good()
    data["backend"] = "sim"
    del data["buses"]["rs485"]["port"]
    assert "[buses.rs485.port]" in str(config_error(data, backend="hardware"))


def test_unknown_device() -> None:
    data = good()
    data["joints"]["shoulder"]["device"] = "erob2"
    msg = str(config_error(data))
    assert "rig.toml" in msg and "[joints.shoulder.device]" in msg and "'erob2'" in msg
    for d in ("'erob'", "'zlac8015d'", "'mks-servo42d'", "'mks-servo57d'"):
        assert d in msg


def test_joint_on_undefined_bus() -> None:
    data = good()
    data["joints"]["elbow"]["bus"] = "can0"
    err = config_error(data)
    msg = str(err)
    assert "[joints.elbow.bus]" in msg and "'can0'" in msg and "[buses]" in msg
    assert "'rs485'" in msg  # the buses that are defined
    assert err.key == "joints.elbow.bus"


def test_joint_bus_of_wrong_type_is_a_config_error() -> None:
    data = good()
    data["joints"]["elbow"]["bus"] = ["rs485"]  # unhashable: must not crash with TypeError
    assert "[joints.elbow.bus]" in str(config_error(data))


def test_duplicate_address_on_one_bus() -> None:
    data = good()
    data["joints"]["elbow"]["address"] = 2
    err = config_error(data)
    msg = str(err)
    assert "[joints.elbow.address]" in msg
    assert "address 2" in msg and "'rs485'" in msg and "'shoulder'" in msg


def test_channel_does_not_hide_a_duplicate_address_on_a_single_channel_drive() -> None:
    data = good()
    data["joints"]["elbow"]["address"] = 2
    data["joints"]["elbow"]["channel"] = "left"
    assert "[joints.elbow.address]" in str(config_error(data))


def test_same_address_on_two_buses_is_fine() -> None:
    data = good()
    data["buses"]["rs485b"] = {"protocol": "modbus-rtu", "port": "/dev/ttyUSB1"}
    data["joints"]["elbow"].update(bus="rs485b", address=2)
    cfg = parse(data)
    assert cfg.joints["elbow"].address == cfg.joints["shoulder"].address == 2


@pytest.mark.parametrize("address", [0, 248, -1, 1000])
def test_address_out_of_range(address: int) -> None:
    data = good()
    data["joints"]["shoulder"]["address"] = address
    err = config_error(data)
    msg = str(err)
    assert "[joints.shoulder.address]" in msg and "out of range" in msg and "1..247" in msg
    assert err.key == "joints.shoulder.address"


@pytest.mark.parametrize("address", [1, 247])
def test_address_bounds_are_allowed(address: int) -> None:
    data = good()
    data["joints"]["shoulder"]["address"] = address
    assert parse(data).joints["shoulder"].address == address


@pytest.mark.parametrize("address", [2.5, "2", True])
def test_address_not_an_integer(address: object) -> None:
    data = good()
    data["joints"]["shoulder"]["address"] = address
    assert "[joints.shoulder.address]" in str(config_error(data))


def test_missing_address() -> None:
    data = good()
    del data["joints"]["shoulder"]["address"]
    assert "[joints.shoulder.address] is required" in str(config_error(data))


@pytest.mark.parametrize("position", [[1.0, -1.0], [1.0, 1.0], [1.0], [0, 1, 2], "0..1", [0, "1"],
                                      [float("nan"), 1.0], [True, 2]])
def test_position_limits_need_min_below_max(position: object) -> None:
    data = good()
    data["joints"]["shoulder"]["limits"]["position"] = position
    msg = str(config_error(data))
    assert "[joints.shoulder.limits.position]" in msg and "min < max" in msg


def test_position_limits_in_toml(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD_TOML.replace("position = [-3.1, 3.1]", "position = [3.1, -3.1]"))
    with pytest.raises(ConfigError) as info:
        load(path)
    msg = str(info.value)
    assert str(path) in msg and "[joints.shoulder.limits.position]" in msg and "[3.1, -3.1]" in msg


@pytest.mark.parametrize("key", ["velocity", "torque", "acceleration"])
@pytest.mark.parametrize("value", [-1.0, 0.0])
def test_non_positive_limits(key: str, value: float) -> None:
    data = good()
    data["joints"]["shoulder"]["limits"][key] = value
    msg = str(config_error(data))
    assert f"[joints.shoulder.limits.{key}]" in msg and "must be > 0" in msg


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_non_finite_limits(value: float) -> None:
    data = good()
    data["joints"]["shoulder"]["limits"]["velocity"] = value
    msg = str(config_error(data))
    assert "[joints.shoulder.limits.velocity]" in msg and "finite" in msg


def test_non_finite_offset_in_toml(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD_TOML.replace("offset = 0.25", "offset = nan"))
    with pytest.raises(ConfigError) as info:
        load(path)
    assert "[joints.shoulder.offset]" in str(info.value)


def test_unknown_limits_key() -> None:
    data = good()
    data["joints"]["shoulder"]["limits"]["jerk"] = 1.0
    msg = str(config_error(data))
    assert "[joints.shoulder.limits.jerk]" in msg and "'velocity'" in msg and "'position'" in msg


@pytest.mark.parametrize("direction", [2, 0, True, "1"])
def test_direction_must_be_plus_or_minus_one(direction: object) -> None:
    data = good()
    data["joints"]["shoulder"]["direction"] = direction
    msg = str(config_error(data))
    assert "[joints.shoulder.direction]" in msg and "(allowed: 1, -1)" in msg


@pytest.mark.parametrize("device,protocol", [("zlac8015d", "canopen"), ("mks-servo42d", "canopen"),
                                             ("zlac8015d", "erob-can")])
def test_unsupported_device_protocol_pair(device: str, protocol: str) -> None:
    data = good()
    data["buses"]["rs485"]["protocol"] = protocol
    if protocol != "modbus-rtu":
        data["buses"]["rs485"]["interface"] = "socketcan"
    data["joints"]["shoulder"]["device"] = device
    if device == "zlac8015d":
        data["joints"]["shoulder"]["channel"] = "left"
    msg = str(config_error(data))
    assert "'zlac8015d on modbus-rtu'" in msg
    assert "rig.toml" in msg and "[joints.shoulder.device]" in msg
    assert "not supported yet" in msg and repr(device) in msg and repr(protocol) in msg
    assert "'erob on modbus-rtu'" in msg  # what is supported


def test_unknown_joint_key() -> None:
    data = good()
    data["joints"]["shoulder"]["adress"] = 2
    msg = str(config_error(data))
    assert "[joints.shoulder.adress]" in msg and "'address'" in msg


def test_bad_on_exit() -> None:
    data = good()
    data["on_exit"] = "brake"
    msg = str(config_error(data))
    assert "[on_exit]" in msg and "'disable', 'stop', 'none'" in msg


def test_no_joints() -> None:
    data = good()
    data["joints"] = {}
    assert "[joints]" in str(config_error(data))


def test_table_expected() -> None:
    data = good()
    data["buses"]["rs485"] = "modbus-rtu"
    assert "[buses.rs485] expected a table" in str(config_error(data))


def test_echo_must_be_boolean() -> None:
    data = good()
    data["buses"]["rs485"]["echo"] = "false"  # bool("false") would be True
    assert "[buses.rs485.echo]" in str(config_error(data))


def test_one_sided_range_message() -> None:
    data = good()
    data["sim"] = {"timestep": 0.5}
    msg = str(config_error(data))
    assert "[sim.timestep]" in msg and "<= 0.01" in msg and "None" not in msg


@pytest.mark.parametrize("watchdog", [-1, 4001])
def test_watchdog_range(watchdog: int) -> None:
    data = good()
    data["joints"]["shoulder"]["watchdog_ms"] = watchdog
    msg = str(config_error(data))
    assert "[joints.shoulder.watchdog_ms]" in msg and "0..4000" in msg


# --- files ------------------------------------------------------------------------------------


def test_invalid_toml_syntax(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD_TOML.replace('protocol = "modbus-rtu"', 'protocol = modbus-rtu'))
    with pytest.raises(ConfigError) as info:
        load(path)
    msg = str(info.value)
    assert str(path) in msg and "not valid TOML" in msg
    assert "line" in msg  # tomllib says where
    assert info.value.file == str(path)


def test_file_not_found(tmp_path: Path) -> None:
    path = tmp_path / "missing.toml"
    with pytest.raises(ConfigError) as info:
        load(path)
    assert "not found" in str(info.value) and "missing.toml" in str(info.value)
    assert info.value.file == str(path)


def test_directory_instead_of_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as info:
        load(tmp_path)
    assert str(tmp_path) in str(info.value)


def test_binary_file(tmp_path: Path) -> None:
    path = tmp_path / "robot.toml"
    path.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ConfigError) as info:
        load(path)
    assert str(path) in str(info.value)


def test_config_error_is_a_value_error_with_fields() -> None:
    data = good()
    data["joints"]["shoulder"]["direction"] = 2
    err = config_error(data)
    assert isinstance(err, ValueError)
    assert (err.file, err.key, err.allowed) == ("rig.toml", "joints.shoulder.direction", (1, -1))


# --- the config's types and the registry's answers ------------------------------------------------


def test_config_types_are_the_leaf_modules_and_stay_importable_where_they_were() -> None:
    import joints
    from joints import config, configtypes, joint

    assert config.BusConfig is configtypes.BusConfig and config.JointConfig is configtypes.JointConfig
    assert config.RigConfig is configtypes.RigConfig and config.SimConfig is configtypes.SimConfig
    assert joint.Limits is configtypes.Limits is joints.Limits and joint.Motion is configtypes.Motion is joints.Motion
    cfg = parse(good())
    assert isinstance(cfg, configtypes.RigConfig) and isinstance(cfg.joints["shoulder"].limits, configtypes.Limits)


@pytest.mark.parametrize("protocol", ["modbus-rtu", "mks-serial"])
def test_every_serial_protocol_needs_a_port_on_hardware(protocol: str) -> None:
    """The registry's medium decides, not a list of names: both serial protocols need the port."""
    data = good()
    data["buses"]["rs485"] = {"protocol": protocol}
    data["joints"] = {"axis": {"device": "mks-servo42d", "bus": "rs485", "address": 1}}
    assert "[buses.rs485.port] is required" in str(config_error(data))
    data["backend"] = "sim"
    assert parse(data).buses["rs485"].port is None


@pytest.mark.parametrize("protocol,allowed", [("canopen", True), ("erob-can", False), ("modbus-rtu", False)])
def test_sync_period_only_where_the_protocol_has_a_sync(protocol: str, allowed: bool) -> None:
    data = {"backend": "sim", "buses": {"b": {"protocol": protocol, "sync_period": 0.002}},
            "joints": {"j": {"device": "erob", "bus": "b", "address": 1}}}
    if allowed:
        assert parse(data).buses["b"].sync_period == 0.002
    else:
        msg = str(config_error(data))
        assert "[buses.b.sync_period]" in msg and "only for a protocol with cyclic modes" in msg
