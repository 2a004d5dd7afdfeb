"""Rig: built from a parsed config on a loopback bus; the ``with`` block keeps the joints safe."""

from __future__ import annotations

import copy
import logging
from pathlib import Path
from typing import Any

import pytest

import joints
from joints.clock import ManualClock
from joints.config import parse
from joints.devices.erob.params import EROB_PARAMS
from joints.devices.erob.registers import EROB_MODBUS, AchieveStatus
from joints.errors import ConfigError, JointsError, ReplyTimeout, TransportError
from joints.joint import JointState
from joints.rig import Rig, build
from joints.sim.firmware import Firmware
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
from joints.transports.loopback import LoopbackTransport

CONFIG: dict[str, Any] = {
    "backend": "hardware",
    "buses": {"rs485": {"protocol": "modbus-rtu", "port": "/dev/ttyUSB0", "timeout": 0.05, "retries": 1}},
    "joints": {
        "shoulder": {"device": "erob", "bus": "rs485", "address": 2, "watchdog_ms": 500,
                     "limits": {"position": [-3.0, 3.0], "velocity": 2.0}},
        "elbow": {"device": "erob", "bus": "rs485", "address": 3},
    },
}


class Drive(Firmware):
    """A parameter store whose achieving-position status follows "Enable the Motor"."""

    def __init__(self, address: int) -> None:
        super().__init__(EROB_PARAMS)
        self.front = ModbusFront(self, EROB_MODBUS, address)

    def on_write(self, name: str, value: int) -> None:
        if name == "enable_the_motor":
            self.set("status_of_achieving_position", AchieveStatus.MOTOR_ON if value else AchieveStatus.MOTOR_OFF)


class Setup:
    def __init__(self, **overrides: Any) -> None:
        data = copy.deepcopy(CONFIG)
        data.update(overrides)
        self.config = parse(data, source="rig.toml")
        self.slaves = {"shoulder": Drive(2), "elbow": Drive(3)}
        self.bus = ModbusDeviceBus(s.front for s in self.slaves.values())
        self.transport = LoopbackTransport(self.bus)
        self.clock = ManualClock()

    def build(self) -> Rig:
        return build(self.config, transports={"rs485": self.transport}, clock=self.clock)

    def log(self, joint: str) -> list[tuple[str, int]]:
        return list(self.slaves[joint].write_log)


@pytest.fixture(autouse=True)
def _no_backend_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("JOINTS_BACKEND", raising=False)


#: leaving the rig: stop, disable, and the watchdog back to what it was before enable() (0: off)
STOP_AND_DISABLE = [("stop_operating", 0), ("enable_the_motor", 0), ("modbus_communication_timeout_duration", 0)]


def test_build_makes_every_joint() -> None:
    s = Setup()
    rig = s.build()
    assert isinstance(rig, Rig)
    assert set(rig.joints) == {"shoulder", "elbow"}
    assert rig.backend == "hardware"
    assert rig.joints["shoulder"].limits.velocity == 2.0
    assert rig.buses["rs485"].transport is s.transport
    assert "shoulder" in repr(rig)
    rig.close()


def test_watchdog_is_armed_while_enabled_and_restored_on_disable() -> None:
    s = Setup()
    with s.build() as rig:
        assert s.log("shoulder") == s.log("elbow") == []  # opening a rig changes nothing on the drives
        rig.joints["shoulder"].enable()
        rig.joints["elbow"].enable()
        assert s.slaves["shoulder"].front.read(0x0002, 1) == (500,)  # watchdog_ms of the config
        assert s.slaves["elbow"].front.read(0x0002, 1) == (1000,)  # the eRob default while enabled
        rig.joints["elbow"].disable()
        assert s.slaves["elbow"].front.read(0x0002, 1) == (0,)  # as found before enable()
        assert s.log("elbow")[-1] == ("modbus_communication_timeout_duration", 0)
    assert s.slaves["shoulder"].front.read(0x0002, 1) == (0,)


def test_enable_writes_the_limits_into_the_drive() -> None:
    s = Setup()
    with s.build() as rig:
        rig.joints["shoulder"].enable()
        drive = s.slaves["shoulder"]
        counts = round(3.0 / (2 * 3.141592653589793 / 524288))
        assert (drive.get("min_position_limit_value"), drive.get("max_position_limit_value")) == (-counts, counts)
        assert drive.get("max_speed") == round(2.0 / (2 * 3.141592653589793 / 524288))
        assert ("save_parameters", 2) not in s.log("shoulder")  # volatile: never saved


def test_normal_exit_stops_and_disables_enabled_joints_only() -> None:
    s = Setup()
    with s.build() as rig:
        rig.joints["shoulder"].enable()
        rig.joints["shoulder"].move_to(1.0)
        assert s.slaves["shoulder"].get("status_of_achieving_position") == AchieveStatus.MOTOR_ON
    assert s.log("shoulder")[-3:] == STOP_AND_DISABLE
    assert s.slaves["shoulder"].get("status_of_achieving_position") == AchieveStatus.MOTOR_OFF
    assert s.log("elbow") == []  # never enabled: not touched
    with pytest.raises(TransportError):  # the bus was closed
        s.transport.write(b"\x00")


def test_exception_inside_stops_disables_and_propagates() -> None:
    s = Setup()
    with pytest.raises(RuntimeError, match="controller bug"), s.build() as rig:
        rig.joints["shoulder"].enable()
        rig.joints["shoulder"].set_velocity(0.5)
        raise RuntimeError("controller bug")
    log = s.log("shoulder")
    assert log[-3:] == STOP_AND_DISABLE
    assert ("target_speed", 0) in log[log.index(("enable_the_motor", 1)):]  # speed mode: target zeroed
    assert s.log("elbow") == []


def test_keyboard_interrupt_inside_also_disables() -> None:
    s = Setup()
    with pytest.raises(KeyboardInterrupt), s.build() as rig:
        rig.joints["elbow"].enable()
        raise KeyboardInterrupt
    assert s.log("elbow")[-3:] == STOP_AND_DISABLE


def test_disabled_again_inside_is_not_touched_on_exit() -> None:
    s = Setup()
    with s.build() as rig:
        rig.joints["elbow"].enable()
        rig.joints["elbow"].disable()
        before = s.log("elbow")
    assert s.log("elbow") == before


def test_enabled_by_raw_register_write_is_disabled_on_exit() -> None:
    s = Setup()
    with s.build() as rig:
        rig.joints["elbow"].write("enable_the_motor", 1)
    assert s.log("elbow")[-2:] == STOP_AND_DISABLE[:2]  # no watchdog to restore: enable() never armed it


def test_on_exit_none_leaves_joints_enabled() -> None:
    s = Setup(on_exit="none")
    with s.build() as rig:
        rig.joints["shoulder"].enable()
    assert s.log("shoulder")[-1] == ("enable_the_motor", 1)
    assert s.slaves["shoulder"].get("status_of_achieving_position") == AchieveStatus.MOTOR_ON


def test_on_exit_stop_stops_but_leaves_enabled() -> None:
    s = Setup(on_exit="stop")
    with s.build() as rig:
        rig.joints["shoulder"].enable()
    assert s.log("shoulder")[-1] == ("stop_operating", 0)
    assert s.slaves["shoulder"].get("status_of_achieving_position") == AchieveStatus.MOTOR_ON
    assert s.log("elbow") == []


def test_one_failing_joint_does_not_keep_the_others_enabled() -> None:
    s = Setup()
    rig = s.build()
    rig.joints["shoulder"].enable()
    rig.joints["elbow"].enable()
    del s.bus.slaves[2]  # the shoulder drive stops answering
    with pytest.raises(JointsError, match="errors while closing the rig") as info:
        rig.close()
    assert isinstance(info.value.__cause__, ReplyTimeout)
    assert s.log("elbow")[-3:] == STOP_AND_DISABLE


def test_shutdown_error_does_not_hide_the_original_exception(caplog: pytest.LogCaptureFixture) -> None:
    s = Setup()
    with caplog.at_level(logging.ERROR, logger="joints"), pytest.raises(ZeroDivisionError), s.build() as rig:
        rig.joints["shoulder"].enable()
        rig.joints["elbow"].enable()
        del s.bus.slaves[2]
        raise ZeroDivisionError("controller bug")
    assert s.log("elbow")[-3:] == STOP_AND_DISABLE
    assert "shoulder" in caplog.text


def test_lost_enable_reply_still_disables_on_exit() -> None:
    s = Setup()
    lost: list[bytes] = []

    def flaky(data: bytes) -> bytes:
        reply = s.bus.receive(data)
        if data[0] == 3 and data[1] == 0x06 and data[2:4] == b"\x00\xf0" and not lost:
            lost.append(data)  # the drive enabled, but the reply is lost
            return b""
        return reply

    s.transport.attach(flaky)
    with pytest.raises(ReplyTimeout), s.build() as rig:
        rig.joints["elbow"].enable()
    assert s.log("elbow")[-2:] == STOP_AND_DISABLE[1:]


def test_close_is_idempotent() -> None:
    s = Setup()
    rig = s.build()
    rig.joints["shoulder"].enable()
    rig.close()
    n = len(s.log("shoulder"))
    rig.close()
    assert len(s.log("shoulder")) == n


def test_sleep_advances_the_manual_clock() -> None:
    s = Setup()
    with s.build() as rig:
        t0 = rig.time
        rig.sleep(0.25)
        assert s.clock.now() == pytest.approx(t0 + 0.25)
        assert rig.time == pytest.approx(t0 + 0.25)
        rig.sleep(0)
        assert rig.time == pytest.approx(t0 + 0.25)


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf")])
def test_sleep_rejects_bad_durations(bad: float) -> None:
    s = Setup()
    with s.build() as rig:
        with pytest.raises(ValueError):
            rig.sleep(bad)
        assert rig.time == 0.0


def test_read_states_returns_every_joint() -> None:
    s = Setup()
    s.slaves["elbow"].set("actual_position", 262144)
    with s.build() as rig:
        rig.joints["shoulder"].enable()
        states = rig.read_states()
    assert set(states) == {"shoulder", "elbow"}
    assert all(isinstance(v, JointState) for v in states.values())
    assert states["shoulder"].enabled and not states["elbow"].enabled
    assert states["elbow"].position == pytest.approx(3.141592653589793)


def test_trace_records_every_frame() -> None:
    s = Setup()
    records: list[Any] = []
    with s.build() as rig:
        rig.trace(records.append)
        rig.joints["elbow"].state()
        rig.trace(None)
        rig.joints["elbow"].state()
    assert [r.direction for r in records] == ["tx", "rx"]


def test_build_closes_transports_when_a_joint_cannot_be_built() -> None:
    data = copy.deepcopy(CONFIG)
    data["joints"]["elbow"]["model"] = "eRob81H100"
    cfg = parse(data, source="rig.toml")
    t = LoopbackTransport(ModbusDeviceBus([Drive(2).front, Drive(3).front]))
    with pytest.raises(ConfigError) as info:
        build(cfg, transports={"rs485": t}, clock=ManualClock())
    msg = str(info.value)
    assert "rig.toml" in msg and "[joints.elbow.model]" in msg and "eRob80H100" in msg
    with pytest.raises(TransportError):
        t.write(b"\x00")


def test_bad_profile_override_names_file_and_key() -> None:
    data = copy.deepcopy(CONFIG)
    data["joints"]["elbow"]["profile"] = {"efficency": 0.6}
    cfg = parse(data, source="rig.toml")
    with pytest.raises(ConfigError) as info:
        build(cfg, transports={"rs485": LoopbackTransport(ModbusDeviceBus([Drive(2).front, Drive(3).front]))},
              clock=ManualClock())
    msg = str(info.value)
    assert "rig.toml" in msg and "[joints.elbow.profile.efficency]" in msg and "'efficiency'" in msg


# --- joints.open ------------------------------------------------------------------------------


def _hardware_config(port: str) -> dict[str, Any]:
    data = copy.deepcopy(CONFIG)
    data["buses"]["rs485"]["port"] = port
    return data


def test_open_missing_port_raises_transport_error_naming_it(tmp_path: Path) -> None:
    port = str(tmp_path / "ttyNOPE0")
    with pytest.raises(TransportError) as info:
        joints.open(_hardware_config(port))
    assert port in str(info.value)
    assert "cannot open serial port" in str(info.value)


def test_open_toml_with_missing_port(tmp_path: Path) -> None:
    port = str(tmp_path / "ttyNOPE1")
    path = tmp_path / "robot.toml"
    path.write_text(
        'backend = "hardware"\n'
        f'[buses.rs485]\nprotocol = "modbus-rtu"\nport = "{port}"\n'
        '[joints.shoulder]\ndevice = "erob"\nbus = "rs485"\naddress = 2\n'
    )
    with pytest.raises(TransportError, match="ttyNOPE1"):
        joints.open(path)
    with pytest.raises(TransportError, match="ttyNOPE1"):
        joints.open(str(path))


def test_open_bogus_backend_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="'bogus'") as info:
        joints.open(copy.deepcopy(CONFIG), backend="bogus")
    assert "'sim', 'hardware'" in str(info.value)


def test_open_parsed_config_with_bogus_backend() -> None:
    with pytest.raises(ConfigError):
        joints.open(parse(copy.deepcopy(CONFIG)), backend="bogus")


def test_open_sim_config_as_hardware_without_port_is_a_config_error() -> None:
    data = copy.deepcopy(CONFIG)
    data["backend"] = "sim"
    del data["buses"]["rs485"]["port"]
    cfg = parse(data, source="rig.toml")
    with pytest.raises(ConfigError) as info:
        joints.open(cfg, backend="hardware")
    msg = str(info.value)
    assert "rig.toml" in msg and "[buses.rs485.port]" in msg
