"""The eRob twin over the CAN custom protocol: the manual's sequences byte-exact, errors with appendix 1's
codes, module information from the configured model, and ONE firmware state behind Modbus and CAN."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import can
import pytest

pytest.importorskip("mujoco")

import joints
import simkit
from joints.codecs import erob_can as ec
from joints.codecs import modbus as mb
from joints.devices.erob.can import ModuleConfig, ModuleInfo
from joints.devices.erob.profiles import profile
from joints.devices.erob.registers import AchieveStatus, OperationMode
from joints.sim.erob_can import ErobCanBus, ErobCanFront, identify
from joints.transports.can_sim import LockstepCanBus
from testdata import sequences

#: reads whose value depends on motion: only their shape is compared (value + 0x3E)
MOTION_DEPENDENT = {(0x0002, None), (0x0005, 1), (0x0008, None)}
ENABLE_WAIT = 0.5  #: the 500 ms between "enable" and a motion command (7.4 step 6; Modbus manual 5.2.2)


def can_sequences() -> list[dict[str, Any]]:
    return [s for s in sequences("erunner") if s["id"].startswith("seq-erob-can-")]


class Twin:
    """Three eRobs at nodes 1, 2, 3 on a CAN bus of the 3-joint arm, reached with raw python-can frames."""

    def __init__(self, *, protocol: str = "erob-can", acks: int = 1) -> None:
        p = profile("eRob80H100")
        drives = [simkit.drive(f"joint{i}", i, p, bus="can", protocol=protocol) for i in (1, 2, 3)]
        self.world = simkit.world("erob_arm3.xml", drives)
        self.device: ErobCanBus = self.world.buses["can"]
        for f in self.device.fronts:
            f.acks = acks
        self.bus = LockstepCanBus(medium=self.device.medium)

    def exchange(self, can_id: int, data: bytes, *, replies: int = 1) -> list[can.Message]:
        self.bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        out = []
        while (m := self.bus.recv(0.01)) is not None:
            out.append(m)
        assert len(out) == replies, (hex(can_id), data.hex(" "), out)
        return out

    def firmware(self, node: int) -> Any:
        return self.world.drives[f"joint{node}"]

    def close(self) -> None:
        self.bus.shutdown()


@pytest.fixture
def make_twin() -> Iterator[Callable[..., Twin]]:
    made: list[Twin] = []

    def make(**kw: Any) -> Twin:
        made.append(Twin(**kw))
        return made[-1]

    yield make
    for t in made:
        t.close()


def _hex(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


@pytest.mark.parametrize("seq", can_sequences(), ids=lambda s: s["id"])
def test_sequence_replays_byte_exact(seq: dict[str, Any], make_twin: Callable[..., Twin]) -> None:
    twin = make_twin()
    node = int(seq["steps"][0]["send_can_id"], 16) - ec.REQUEST_BASE
    if seq["id"].startswith("seq-erob-can-fig4-") and any("0x0083" in st["comment"] for st in seq["steps"]):
        # the panel's motion buttons work on an enabled motor (figure 4-5, "enable", came first)
        twin.exchange(ec.REQUEST_BASE + node, _hex("01 00 00 00 00 01"))
        twin.world.advance(ENABLE_WAIT)
    for step in seq["steps"]:
        data = _hex(step["send_hex"])
        request = ec.decode(can.Message(arbitration_id=int(step["send_can_id"], 16), data=data,
                                        is_extended_id=False), ec.Role.DEVICE)
        (reply,) = twin.exchange(int(step["send_can_id"], 16), data)
        assert reply.arbitration_id == ec.REPLY_BASE + node
        if step.get("expect_hex") is None:  # 7.4.5 step 10: the reply row fell off the page
            assert bytes(reply.data) == b"\x3e"
        elif isinstance(request, ec.Read) and (request.index, request.subindex) in MOTION_DEPENDENT:
            assert len(reply.data) == 5 and reply.data[4] == 0x3E, step
        else:
            assert bytes(reply.data) == _hex(step["expect_hex"]), step
        if isinstance(request, ec.Command) and request.index == 0x0100 and request.parameter == 1:
            twin.world.advance(ENABLE_WAIT)


def test_speed_set_point_before_enable_turns_the_motor_once_ready(make_twin: Callable[..., Twin]) -> None:
    """7.4.4: the analog value is written before "enable"; the motor turns at it once enabled (4.2 step 4)."""
    twin = make_twin()
    for data in ("00 4E 00 00 00 02", "01 12 00 00 00 00", "01 FD 00 00 00 00", "00 88 00 00 75 30",
                 "00 89 00 00 75 30", "01 FE 00 00 27 10", "01 00 00 00 00 01"):
        twin.exchange(0x641, _hex(data))
    fw = twin.firmware(1)
    twin.world.advance(0.4)
    assert abs(fw.read("current_speed")) < 50  # brake still releasing: no motion before 500 ms
    twin.world.advance(1.0)  # no frame in between: the held set-point acted when the motor became ready
    assert fw.read("current_speed") == pytest.approx(10000, rel=0.03)
    twin.exchange(0x641, _hex("01 FE 00 00 00 00"))  # 4.2 step 5: stop = analog value 0
    twin.world.advance(1.0)
    assert abs(fw.read("current_speed")) < 50


def test_a_held_set_point_does_not_survive_a_power_cycle(make_twin: Callable[..., Twin]) -> None:
    twin = make_twin()
    for data in ("00 4E 00 00 00 02", "01 FE 00 00 27 10"):  # speed mode, set-point held (motor off)
        twin.exchange(0x641, _hex(data))
    twin.world.reset()
    twin.firmware(1).write("operation_mode", 2)  # speed mode again, not through the CAN front
    twin.exchange(0x641, _hex("01 00 00 00 00 01"))
    twin.world.advance(1.0)
    assert abs(twin.firmware(1).read("current_speed")) < 50


@pytest.mark.parametrize("data,code", [
    ("00 83", 0x0027),  # start while the motor is off (appendix 1 #4)
    ("01 00", 0x0032),  # enable without its parameter (#6)
    ("00 84 00 00 00 01", 0x0033),  # stop with a parameter (#7)
    ("00 E8 00 00 00 00", 0x0033),
])
def test_refusals_carry_appendix_1_codes(data: str, code: int, make_twin: Callable[..., Twin]) -> None:
    twin = make_twin()
    (reply,) = twin.exchange(0x641, _hex(data))
    assert bytes(reply.data) == code.to_bytes(2, "big") + b"\x3e"
    assert twin.firmware(1).read("error_code") == 0  # the reply tells the host; nothing is latched


def test_start_during_the_brake_release_is_refused_then_accepted(make_twin: Callable[..., Twin]) -> None:
    twin = make_twin()
    twin.exchange(0x641, _hex("01 00 00 00 00 01"))
    twin.world.advance(0.2)
    (reply,) = twin.exchange(0x641, _hex("00 83"))
    assert bytes(reply.data) == b"\x00\x27\x3e"
    twin.world.advance(0.3)
    (reply,) = twin.exchange(0x641, _hex("00 83"))
    assert bytes(reply.data) == b"\x3e"


def test_torque_speed_limit_while_enabled_is_0x0016(make_twin: Callable[..., Twin]) -> None:
    twin = make_twin()
    twin.exchange(0x641, _hex("01 00 00 00 00 01"))
    (reply,) = twin.exchange(0x641, _hex("02 04 00 00 27 10"))
    assert bytes(reply.data) == b"\x00\x16\x3e"


@pytest.mark.parametrize("data", ["12 34", "00 01", "00 83 00 01", "00 02 00 00 00 05", "00 33 00 00 00 01",
                                  "00 4E 00 00 00 09", "01 14 00 00 00 02"])
def test_unknown_indexes_read_only_writes_and_bad_values_fail_with_0x80(data: str, make_twin: Callable[..., Twin]) -> None:
    twin = make_twin()
    (reply,) = twin.exchange(0x641, _hex(data))
    assert bytes(reply.data) == b"\x80"


def test_malformed_and_foreign_frames_get_no_answer(make_twin: Callable[..., Twin]) -> None:
    twin = make_twin()
    twin.exchange(0x641, _hex("00 02 00"), replies=0)  # 3 data bytes: no request has that
    twin.exchange(0x5C1, _hex("3e"), replies=0)  # another drive's reply
    twin.exchange(0x644, _hex("00 02"), replies=0)  # no drive at node 4
    assert twin.device.frame_errors == 1


def test_enable_and_disable_acknowledge_as_often_as_configured(make_twin: Callable[..., Twin]) -> None:
    twin = make_twin(acks=6)
    for f in twin.device.fronts:
        f.disable_acks = 5
    assert len(twin.exchange(0x641, _hex("01 00 00 00 00 01"), replies=6)) == 6  # figure 4-21
    assert len(twin.exchange(0x641, _hex("01 00 00 00 00 00"), replies=5)) == 5  # figure 4-7


def test_brake_release_needs_a_brake(make_twin: Callable[..., Twin]) -> None:
    twin = make_twin()
    identify(twin.firmware(2), "eRob80H100I-FM-18CN", serial=2)  # "F": no brake
    (reply,) = twin.exchange(0x642, _hex("01 4F"))
    assert bytes(reply.data) == b"\x01\x4a\x3e"
    (reply,) = twin.exchange(0x641, _hex("01 4F"))  # the default twin has one
    assert bytes(reply.data) == b"\x3e"


def test_brake_release_lets_a_loaded_joint_fall(make_twin: Callable[..., Twin]) -> None:
    twin = make_twin()
    world = twin.world
    world.set_joint_positions({"joint2": 0.0})  # the shoulder holds the arm level: gravity pulls it down
    world.advance(0.5)
    held = world.joint_position("joint2")
    world.advance(0.5)
    assert abs(world.joint_position("joint2") - held) < 1e-3  # the brake holds a disabled joint
    (reply,) = twin.exchange(0x642, _hex("01 4F"))
    assert bytes(reply.data) == b"\x3e"
    world.advance(0.3)
    assert abs(world.joint_position("joint2") - held) > 0.1  # released: a loaded joint falls
    twin.exchange(0x642, _hex("01 00 00 00 00 00"))  # disable: the drive's brake control engages again
    here = world.joint_position("joint2")
    world.advance(0.5)
    assert abs(world.joint_position("joint2") - here) < 0.02


@pytest.mark.parametrize("model", ["eRob70H100I-BM-18EN", "eRob90H120T-BHM-18CT", "eRob142F160BI-FS-18CN",
                                   "eRob110H50BT-BHS-18EN"])
def test_module_information_decodes_to_the_configured_model(model: str) -> None:
    cfg = {"backend": "sim", "sim": {"model": "erob_stand.xml"},
           "buses": {"can": {"protocol": "erob-can"}},
           "joints": {"joint1": {"device": "erob", "model": model, "bus": "can", "address": 9}}}
    with joints.open(cfg) as rig:
        info = rig.joints["joint1"].driver.module_info()
    assert info.model == model
    config = ModuleConfig.from_model(model)
    assert info.serial_number.startswith(f"{config.outer_diameter:03d}")
    assert info.config == config


def test_firmware_older_than_x5061715x_has_no_module_information(make_twin: Callable[..., Twin]) -> None:
    twin = make_twin()
    fw = twin.firmware(1)
    identify(fw, "eRob80H100I-BM-18CN", serial=7, firmware_version=520212171)  # figure 3-6's version
    (reply,) = twin.exchange(0x641, _hex("02 32 00 02"))
    assert bytes(reply.data) == b"\x80"
    (reply,) = twin.exchange(0x641, _hex("00 01 00 04"))
    assert int.from_bytes(reply.data[:4], "big") == 520212171


def test_one_firmware_state_behind_modbus_and_can() -> None:
    """A twin reached over Modbus and over CAN in one run agrees with itself."""
    p = profile("eRob80H100")
    world = simkit.world("erob_stand.xml", [simkit.drive("joint1", 3, p)])
    fw = world.drives["joint1"]
    modbus = world.buses["rs485"]
    can_bus = ErobCanBus([ErobCanFront(fw, 3)], name="same-twin")
    can_bus.bind_clock(world.clock)
    host = LockstepCanBus(medium=can_bus.medium)

    def can_req(msg: ec.Request) -> ec.Reply:
        host.send(ec.encode(msg))
        frame = host.recv(0.01)
        assert frame is not None
        reply = ec.decode(frame, ec.Role.HOST)
        assert not isinstance(reply, (ec.ErrorReply, ec.ReadFailed)), reply
        return reply  # type: ignore[return-value]

    def mb_read(address: int, count: int) -> tuple[int, ...]:
        reply = modbus.exchange(mb.ReadHoldingRegisters(3, address, count))
        assert isinstance(reply, mb.ReadRegistersReply), reply
        return reply.values

    def mb_write(address: int, values: tuple[int, ...]) -> None:
        reply = modbus.exchange(mb.WriteMultipleRegisters(3, address, values))
        assert isinstance(reply, mb.WriteMultipleRegistersReply), reply

    # a setting written over CAN reads back over Modbus, and the other way round
    can_req(ec.Write(3, 0x008A, 70000))  # profile speed
    assert mb_read(0x0047, 2) == (1, 70000 - 65536)
    mb_write(0x0049, (3, 0))  # profile acceleration over Modbus: 196608 count/s^2
    assert can_req(ec.Read(3, 0x0088)) == ec.ValueReply(3, 196608)
    # a ms time over CAN is 0.05 ms over Modbus: the same quantity
    can_req(ec.Write(3, 0x0058, 250))  # struck time 250 ms
    assert mb_read(0x00C9, 1) == (5000,)
    # enable and move over CAN; Modbus sees the same motion, and stops it
    for msg in (ec.Write(3, 0x004E, 3), ec.Write(3, 0x008D, 1), ec.Command(3, 0x0100, 1)):
        can_req(msg)
    world.advance(ENABLE_WAIT)
    assert mb_read(0x0063, 1)[0] == AchieveStatus.MOTOR_ON
    can_req(ec.Write(3, 0x0087, 0))
    can_req(ec.Write(3, 0x0086, 100000))
    can_req(ec.Command(3, 0x0083))
    world.advance(0.3)
    can_pos = can_req(ec.Read(3, 0x0002))
    hi, lo = mb_read(0x0066, 2)
    assert isinstance(can_pos, ec.ValueReply) and can_pos.value == (hi << 16 | lo)
    assert 0 < can_pos.value < 100000
    world.advance(3.0)
    assert can_req(ec.Read(3, 0x010C)) == ec.ValueReply(3, AchieveStatus.TARGET_REACHED)
    assert mb_read(0x0063, 1)[0] == AchieveStatus.TARGET_REACHED
    assert abs(fw.read("actual_position") - 100000) <= fw.read("position_reaches_set_precision")
    # speed mode over Modbus, the analog value over CAN reads what Modbus set going
    modbus.exchange(mb.WriteSingleRegister(3, 0x0040, int(OperationMode.SPEED)))
    mb_write(0x0051, (0, 8000))
    world.advance(1.0)
    speed = can_req(ec.Read(3, 0x0005, 1))
    assert isinstance(speed, ec.ValueReply) and speed.value == pytest.approx(8000, rel=0.03)
    # disabled over Modbus: CAN reports the motor off
    modbus.exchange(mb.WriteSingleRegister(3, 0x00F0, 0))
    assert can_req(ec.Read(3, 0x010C)) == ec.ValueReply(3, AchieveStatus.MOTOR_OFF)


def test_module_info_object_matches_the_front(make_twin: Callable[..., Twin]) -> None:
    twin = make_twin()
    fw = twin.firmware(1)
    info = identify(fw, "eRob70H100I-BM-18EN", serial=1111, hardware_version=1005)
    values = {}
    for name, (index, sub) in {"module_serial": (0x232, 1), "module_model_info": (0x232, 2),
                               "module_configuration": (0x232, 5), "hardware_version": (0x0001, 3)}.items():
        (reply,) = twin.exchange(0x641, index.to_bytes(2, "big") + sub.to_bytes(2, "big"))
        values[name] = int.from_bytes(reply.data[:4], "big")
    got = ModuleInfo.from_values(values)
    assert (got.model, got.serial_number) == ("eRob70H100I-BM-18EN", "07000001111") == (info.model,
                                                                                       info.serial_number)
