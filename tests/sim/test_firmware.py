"""The protocol-free firmware (joints.sim.firmware) and the twins built on it, reached by parameter name."""

from __future__ import annotations

import ast
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

from joints.devices.erob.profiles import profile
from joints.devices.erob.registers import AchieveStatus
from joints.devices.params import Access, Param, ParamSet
from joints.devices.zlac.profile import HubMotorProfile
from joints.errors import JointsError, ParameterRefused, Refusal
from joints.sim import firmware as firmware_module
from joints.sim.erob import ErobFirmware
from joints.sim.firmware import Firmware
from joints.sim.zlac import ZlacFirmware

ROOT = Path(__file__).resolve().parents[2]

PARAMS = ParamSet("toy", (
    Param("mode", "uint16", minimum=1, maximum=3, default=1),
    Param("target", "int32"),
    Param("speed", "int16", Access.R),
    Param("go", "uint16", Access.COMMAND),
    Param("node_id", "uint16", minimum=1, maximum=127, default=1),
))


class Toy(Firmware):
    """Refuses a target while in mode 3; ``speed`` is computed; counts hook calls."""

    def __init__(self) -> None:
        super().__init__(PARAMS, values={"node_id": 5})
        self.speed = 0
        self.reads: list[tuple[str, ...]] = []
        self.acted: list[tuple[str, int]] = []
        self.computed["speed"] = lambda: self.speed

    def check_write(self, name: str, value: int) -> None:
        if name == "target" and self.values["mode"] == 3:
            raise ParameterRefused(Refusal.STATE, name, "not in mode 3")

    def on_write(self, name: str, value: int) -> None:
        self.acted.append((name, value))

    def on_read(self, names: Sequence[str]) -> None:
        self.reads.append(tuple(names))


def refusal(fn: object, *args: object) -> Refusal:
    with pytest.raises(ParameterRefused) as info:
        fn(*args)  # type: ignore[operator]
    assert isinstance(info.value, JointsError)
    return info.value.reason


# ------------------------------------------------------------------------------- the base


def test_defaults_values_and_unknown_power_on_values() -> None:
    fw = Toy()
    assert fw.values == {"mode": 1, "target": 0, "speed": 0, "go": 0, "node_id": 5}
    assert fw.power_on_values["node_id"] == 5
    with pytest.raises(JointsError):
        Firmware(PARAMS, values={"nope": 1})


def test_writes_are_validated_stored_logged_and_acted_on() -> None:
    fw = Toy()
    fw.write("target", -7)
    fw.write_many([("mode", 2), ("go", 1)])
    assert fw.get("target") == -7 and fw.get("mode") == 2
    assert fw.write_log == fw.acted == [("target", -7), ("mode", 2), ("go", 1)]
    fw.write("target", np.int64(9))  # integers of any kind, as a host script might pass
    fw.write("target", 10.0)  # type: ignore[arg-type]
    assert fw.get("target") == 10 and type(fw.values["target"]) is int


def test_refusal_reasons() -> None:
    fw = Toy()
    assert refusal(fw.write, "nope", 1) is Refusal.UNKNOWN
    assert refusal(fw.write, "speed", 1) is Refusal.NOT_WRITABLE
    assert refusal(fw.write, "mode", 4) is Refusal.OUT_OF_RANGE
    assert refusal(fw.write, "target", 1 << 40) is Refusal.OUT_OF_RANGE
    assert refusal(fw.write, "target", 1.5) is Refusal.OUT_OF_RANGE  # not an integer
    assert refusal(fw.read, "go") is Refusal.NOT_READABLE
    assert refusal(fw.read, "nope") is Refusal.UNKNOWN
    fw.write("mode", 3)
    assert refusal(fw.write, "target", 1) is Refusal.STATE


def test_a_refused_block_changes_nothing() -> None:
    fw = Toy()
    fw.write("mode", 3)
    before, log = dict(fw.values), list(fw.write_log)
    # the first item is valid, the second refused in this state: neither takes effect
    assert refusal(fw.write_many, [("node_id", 9), ("target", 1)]) is Refusal.STATE
    assert refusal(fw.write_many, [("node_id", 9), ("mode", 0)]) is Refusal.OUT_OF_RANGE
    assert fw.values == before and fw.write_log == log and fw.acted == [("mode", 3)]


def test_computed_values_are_computed_when_read_and_saturate() -> None:
    fw = Toy()
    fw.speed = 123
    assert fw.read_many(["mode", "speed"]) == [1, 123]
    fw.speed = 10**9  # int16: saturates, never wraps
    assert fw.read("speed") == 0x7FFF and fw.get("speed") == 0x7FFF
    fw.speed = -(10**9)
    assert fw.read("speed") == -0x8000
    assert fw.reads == [("mode", "speed"), ("speed",), ("speed",)]  # on_read once per request


def test_prepared_reader_checks_once() -> None:
    fw = Toy()
    read = fw.reader(["speed", "target"])
    fw.speed, fw.values["target"] = 4, -2
    assert read() == [4, -2]
    assert refusal(fw.reader, ["speed", "go"]) is Refusal.NOT_READABLE


def test_set_saturates_and_is_not_a_bus_write() -> None:
    fw = Toy()
    fw.set("target", 1 << 40)
    assert fw.get("target") == 0x7FFFFFFF and fw.write_log == []
    assert refusal(fw.set, "nope", 1) is Refusal.UNKNOWN


def test_power_cycle_keeps_saved_settings_and_latches_power_on_values() -> None:
    fw = Toy()
    fw.write("mode", 2)
    fw.write("node_id", 7)
    fw.save(["mode"])
    fw.write("mode", 3)
    assert fw.power_on_values["node_id"] == 5  # a new node id waits for the power cycle
    fw.power_cycle()
    assert fw.get("mode") == 2 and fw.get("node_id") == 5 and fw.write_log == []
    assert fw.power_on_values == fw.values


def test_write_log_is_bounded() -> None:
    fw = Toy()
    for i in range(firmware_module.WRITE_LOG_LIMIT + 1):
        fw.write("target", i % 1000)
    assert len(fw.write_log) <= firmware_module.WRITE_LOG_LIMIT
    assert fw.write_log[-1] == ("target", firmware_module.WRITE_LOG_LIMIT % 1000)


# ------------------------------------------------------------------------------ the twins


@pytest.mark.parametrize("module", ["firmware", "erob", "zlac"])
def test_firmware_modules_import_no_protocol(module: str) -> None:
    tree = ast.parse((ROOT / "joints" / "sim" / f"{module}.py").read_text())
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)} | {
        a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert not {m for m in imported if m and (m.startswith("joints.codecs") or "modbus" in m)}


def test_erob_status_is_computed_on_read_never_per_substep() -> None:
    fw = ErobFirmware(profile("eRob80H100"), 2)
    calls: dict[str, int] = {}
    for name, fn in list(fw.computed.items()):
        def counted(name: str = name, fn: object = fn) -> int:
            calls[name] = calls.get(name, 0) + 1
            return fn()  # type: ignore[operator,no-any-return]
        fw.computed[name] = counted
    fw.write("enable_the_motor", 1)
    for k in range(1, 1001):
        fw.step(k * 1e-3, 1e-3, 0.0, 0.0)
    assert calls == {}
    assert fw.read_many(["status_of_achieving_position", "actual_position"]) == [AchieveStatus.MOTOR_ON, 0]
    assert calls == {"status_of_achieving_position": 1, "actual_position": 1}


def test_erob_refuses_torque_mode_speed_limit_while_enabled() -> None:
    fw = ErobFirmware(profile("eRob80H100"), 2)
    fw.write("torque_control_mode_max_speed", 1000)
    fw.write("enable_the_motor", 1)
    assert refusal(fw.write, "torque_control_mode_max_speed", 2000) is Refusal.STATE
    assert fw.get("torque_control_mode_max_speed") == 1000


def test_erob_frame_received_feeds_the_watchdog() -> None:
    fw = ErobFirmware(profile("eRob80H100"), 2)
    fw.write("modbus_communication_timeout_duration", 100)  # ms
    fw.frame_received()
    for k in range(1, 101):
        fw.step(k * 1e-3, 1e-3, 0.0, 0.0)
    assert fw.fault == 0
    fw.frame_received()
    for k in range(101, 203):
        fw.step(k * 1e-3, 1e-3, 0.0, 0.0)
    assert fw.read("error_code") == 0x0FA2


def test_zlac_names_and_refusal_by_name() -> None:
    fw = ZlacFirmware(HubMotorProfile(), 3)
    assert fw.power_on_values["rs485_node_id"] == 3
    fw.write("control_mode", 2)  # absolute position: targets within +-0x3FFFFFFF
    assert refusal(fw.write, "target_position_left", 0x40000000) is Refusal.OUT_OF_RANGE
    fw.write("control_word", 8)
    assert fw.read_many(["motor_state", "error_code_left"]) == [0x0101, 0]
