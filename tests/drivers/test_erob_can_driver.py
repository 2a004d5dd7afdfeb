"""The eRob driver over the CAN custom protocol, against the twin: procedures, status, confirm-gated commands."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import pytest

pytest.importorskip("mujoco")

import joints
from joints.codecs import erob_can as ec
from joints.devices.erob.registers import COUNTS_PER_REV, AchieveStatus
from joints.drivers.erob_can import CAN_STATUS_NAMES, TEMPERATURE_PERIOD, ErobCanDriver
from joints.errors import CommandError, ConfirmationRequired, RegisterError
from joints.link.trace import Trace
from joints.sim.erob_can import identify


def config(**joint: Any) -> dict[str, Any]:
    return {"backend": "sim", "sim": {"model": "erob_stand.xml"},
            "buses": {"can": {"protocol": "erob-can"}},
            "joints": {"joint1": {"device": "erob", "model": "eRob80H100", "bus": "can", "address": 4, **joint}}}


@pytest.fixture
def rig() -> Iterator[joints.Rig]:
    with joints.open(config(limits={"position": [-3.0, 3.0], "velocity": 3.0, "torque": 30.0})) as r:
        yield r


def driver_of(rig: joints.Rig) -> ErobCanDriver:
    d = rig.joints["joint1"].driver
    assert isinstance(d, ErobCanDriver)
    return d


def sent(trace: Trace) -> list[str]:
    return [r.meaning for r in trace if r.direction == "tx"]


def test_move_to_speed_and_torque_through_the_joint_api(rig: joints.Rig) -> None:
    j = rig.joints["joint1"]
    j.enable()
    j.move_to(0.5, velocity=1.0, acceleration=5.0, deceleration=5.0)
    s = j.wait(timeout=10)
    assert s.position == pytest.approx(0.5, abs=math.radians(0.05))
    assert s.enabled and not s.moving and s.fault is None
    j.set_velocity(-0.8, acceleration=5.0)
    rig.sleep(1.0)
    assert j.state().velocity == pytest.approx(-0.8, rel=0.03)
    j.stop()
    s = j.wait(timeout=5, until=lambda s: not s.moving and abs(s.velocity) < 0.012)
    assert s.enabled and s.fault is None
    j.set_torque(2.0)
    rig.sleep(0.2)
    assert j.state().torque == pytest.approx(2.0, rel=0.1)
    j.set_torque(0.0)
    j.disable()
    assert not j.state().enabled


def test_speed_mode_writes_the_analog_set_point(rig: joints.Rig) -> None:
    j = rig.joints["joint1"]
    trace = Trace()
    rig.trace(trace)
    j.enable()
    j.set_velocity(0.5)
    text = sent(trace)
    assert "node 4 write 0x004E = 2" in text and "node 4 write 0x01FD = 0" in text
    counts = round(0.5 / (2 * math.pi / COUNTS_PER_REV))
    assert text[-1] == f"node 4 write 0x01FE = {counts}"
    j.stop()
    assert sent(trace)[-2:] == ["node 4 write 0x01FE = 0", "node 4 command 0x0084"]


def test_state_reads_six_values_and_the_temperature_once_a_second(rig: joints.Rig) -> None:
    j = rig.joints["joint1"]
    link = rig.buses["can"].link
    before = link.transactions
    j.state()
    assert link.transactions - before == len(CAN_STATUS_NAMES) + 1
    before = link.transactions
    s = j.state()
    assert link.transactions - before == len(CAN_STATUS_NAMES)
    assert s.temperature == pytest.approx(30, abs=2)
    rig.sleep(TEMPERATURE_PERIOD)
    before = link.transactions
    j.state()
    assert link.transactions - before == len(CAN_STATUS_NAMES) + 1


def test_read_states_of_three_joints() -> None:
    cfg = {"backend": "sim", "sim": {"model": "erob_arm3.xml"}, "buses": {"can": {"protocol": "erob-can"}},
           "joints": {f"joint{i}": {"device": "erob", "bus": "can", "address": i} for i in (1, 2, 3)}}
    with joints.open(cfg) as rig:
        link = rig.buses["can"].link
        rig.read_states()
        before = link.transactions
        states = rig.read_states()
        assert list(states) == ["joint1", "joint2", "joint3"]
        assert link.transactions - before == 3 * len(CAN_STATUS_NAMES)  # one request per value: the minimum


@pytest.mark.parametrize("call", [
    lambda d: d.save_parameters(),
    lambda d: d.release_brake(),
    lambda d: d.reset_output_encoder(),
    lambda d: d.set_node_id(9),
    lambda d: d.write("save_parameters", 0),
    lambda d: d.write("release_brake", 0),
    lambda d: d.write("reset_output_encoder", 1),
    lambda d: d.write("can_address", 9),
    lambda d: d.write(0x0043, 9),
    lambda d: d.write("0x014F", 0),
], ids=["save", "brake", "encoder", "node_id", "raw-save", "raw-brake", "raw-encoder", "raw-node", "raw-0x43",
        "raw-0x14F"])
def test_confirm_gated_commands_refuse_and_send_nothing(rig: joints.Rig, call: Any) -> None:
    d = driver_of(rig)
    link = rig.buses["can"].link
    trace = Trace()
    rig.trace(trace)
    before = link.transactions
    with pytest.raises(ConfirmationRequired):
        call(d)
    assert link.transactions == before and len(trace) == 0


def test_confirmed_commands_send_the_manuals_frames(rig: joints.Rig) -> None:
    d = driver_of(rig)
    trace = Trace()
    rig.trace(trace)
    d.save_parameters(confirm=True)
    d.release_brake(confirm=True)
    d.reset_output_encoder(confirm=True)
    d.set_node_id(9, confirm=True)
    assert sent(trace) == ["node 4 command 0x00E8", "node 4 command 0x014F", "node 4 write 0x0114 = 1",
                           "node 4 write 0x0043 = 9"]


def test_node_id_change_takes_effect_after_save_and_power_cycle(rig: joints.Rig) -> None:
    d = driver_of(rig)
    d.set_node_id(9, confirm=True)
    d.save_parameters(confirm=True)
    assert d.read("actual_position") is not None  # still node 4 until the power cycle
    rig.world.reset()
    node9 = ErobCanDriver(rig.buses["can"].link, 9, clock=rig.clock)
    assert node9.read("can_address") == 9


def test_module_info_and_identity(rig: joints.Rig) -> None:
    d = driver_of(rig)
    ident = d.identity()
    assert ident["model"] == "eRob80H100I-BM-18CN"  # the configured size/ratio, default fittings
    assert str(ident["serial_number"]).startswith("080")
    fw = rig.world.drives["joint1"]
    identify(fw, "eRob80H100I-BM-18CN", serial=3, firmware_version=520212171)
    trace = Trace()
    rig.trace(trace)
    with pytest.raises(CommandError, match="not supported by firmware 520212171"):
        d.module_info()
    assert not any("0x0232" in m for m in sent(trace))  # asked for the versions only
    assert "not supported" in str(d.identity()["module_info"])


def test_parameters_by_index_and_can_only_access(rig: joints.Rig) -> None:
    d = driver_of(rig)
    assert d.describe(0x0002)[0].name == "actual_position"
    assert d.describe("0x0005/1")[0].name == "current_speed"
    assert d.describe(0x0005)[0].name == "current_speed"  # the index's only subindex
    with pytest.raises(RegisterError, match="subindexes"):
        d.describe(0x0001)
    with pytest.raises(RegisterError, match="cannot be reached over erob-can"):
        d.read("given_position")  # Modbus only
    with pytest.raises(RegisterError, match="read-only over CAN"):
        d.write("continuous_current", 1000)  # R/W over Modbus, RO over CAN (7.5.1)
    assert d.read("struck_time") == 20000  # 1000 ms over CAN = 20000 x 0.05 ms, the Modbus unit


def test_clear_faults_is_disable_then_enable_works_again(rig: joints.Rig) -> None:
    j = rig.joints["joint1"]
    fw = rig.world.drives["joint1"]
    j.enable()
    rig.sleep(0.6)
    fw._raise_fault(0x8611)  # a following error
    s = j.state()
    assert s.fault is not None and not s.enabled
    with pytest.raises(joints.errors.DeviceFault):
        j.enable()
    j.clear_faults()  # over CAN: disable (appendix 1 #4)
    assert j.state().fault is None
    j.enable()
    rig.sleep(0.6)
    assert j.state().raw.extra["status_of_achieving_position"] == AchieveStatus.MOTOR_ON  # type: ignore[union-attr]


def test_zero_calibration_is_refused_over_can(rig: joints.Rig) -> None:
    link = rig.buses["can"].link
    before = link.transactions
    with pytest.raises(CommandError, match="Modbus RTU"):
        driver_of(rig).calibrate_zero(confirm=True)
    assert link.transactions == before


def test_emergency_stop_halts_within_about_50_ms(rig: joints.Rig) -> None:
    j = rig.joints["joint1"]
    j.enable()
    j.set_velocity(2.0, acceleration=20.0)
    rig.sleep(0.5)
    assert j.state().velocity > 1.9
    j.emergency_stop()
    t0 = rig.time
    while abs(j.state().velocity) >= 0.05:
        assert rig.time - t0 < 0.06, "still turning 60 ms after the emergency stop"
        rig.sleep(0.002)


def test_requests_are_the_protocols() -> None:
    # the access turns names into the messages of 7.1-7.3
    from joints.drivers.erob_can import ErobCanAccess

    access = ErobCanAccess(object(), 7)
    assert access.message("enable_the_motor", 1) == ec.Command(7, 0x0100, 1)
    assert access.message("start_operating", 1) == ec.Command(7, 0x0083)
    assert access.message("dwell_time", 20000) == ec.Write(7, 0x0093, 1000)
    assert access.message("profile_speed", -5566) == ec.Write(7, 0x008A, -5566)
    with pytest.raises(CommandError, match="whole number"):
        access.message("dwell_time", 19999)
    with pytest.raises(CommandError):
        ErobCanAccess(object(), 128)


def test_six_acknowledgements_of_enable_never_answer_later_writes(rig: joints.Rig) -> None:
    """Figures 4-21 / 4-7: six 0x3E for one enable, five for one disable; the moves still work."""
    for front in rig.world.buses["can"].fronts:
        front.acks, front.disable_acks = 6, 5
    link = rig.buses["can"].link
    j = rig.joints["joint1"]
    j.enable()
    j.move_to(0.3, velocity=1.0, acceleration=5.0, deceleration=5.0)
    assert j.wait(timeout=10).position == pytest.approx(0.3, abs=math.radians(0.05))
    j.disable()
    j.enable()
    j.move_to(-0.2, velocity=1.0, acceleration=5.0, deceleration=5.0)
    assert j.wait(timeout=10).position == pytest.approx(-0.2, abs=math.radians(0.05))
    extra = [m for _, m in link.unsolicited if isinstance(m, ec.Ack)]
    assert len(extra) == 5 + 4 + 5  # every surplus acknowledgement went to the unsolicited log


def _manual_writes(seq_id: str) -> list[bytes]:
    """The request frames of a 7.4 sequence that change the drive (reads left out)."""
    from testdata import sequences

    (seq,) = [s for s in sequences("erunner") if s["id"] == seq_id]
    out = []
    for step in seq["steps"]:
        data = bytes.fromhex(step["send_hex"].replace(" ", ""))
        if len(data) in (6, 8) or data in (b"\x00\x83", b"\x00\x84", b"\x00\xe8", b"\x01\x4f"):
            out.append(data)
    return out


def _procedure(seq_id: str, d: ErobCanDriver, rig: joints.Rig) -> None:
    from joints.devices.erob.registers import MotionMode

    if seq_id == "seq-erob-can-7.4.1":
        d.configure_position(MotionMode.ABSOLUTE, speed=10000, acceleration=10000, deceleration=10000)
        d.enable()
        d.move_to(262144, speed=10000, acceleration=10000, deceleration=10000)
    elif seq_id == "seq-erob-can-7.4.2":
        d.configure_position(MotionMode.ABSOLUTE, speed=10000, acceleration=10000, deceleration=10000)
        d.enable()
        d.move_by(10000)
    elif seq_id == "seq-erob-can-7.4.3":
        d.enable()
        d.move_continuous(10000, acceleration=30000, deceleration=30000)
    elif seq_id == "seq-erob-can-7.4.4":
        d.configure_velocity(acceleration=30000, deceleration=30000)
        d.enable()
        d.set_velocity(10000, acceleration=30000, deceleration=30000)
    else:
        d.configure_torque(max_speed=10000)
        d.enable()
        d.set_current(1000)
    rig.sleep(0.2)
    d.state()
    if seq_id in ("seq-erob-can-7.4.1", "seq-erob-can-7.4.2", "seq-erob-can-7.4.3"):
        d.stop()
    d.disable()


@pytest.mark.parametrize("seq_id", [f"seq-erob-can-7.4.{i}" for i in range(1, 6)])
def test_procedures_send_the_manuals_frames(seq_id: str) -> None:
    """Every write and command of a 7.4 example is sent by the driver's procedure for that mode (node 1)."""
    with joints.open(config(address=1)) as rig:
        d = driver_of(rig)
        trace = Trace()
        rig.trace(trace)
        _procedure(seq_id, d, rig)
        sent_frames = [r.data for r in trace if r.direction == "tx"]
        manual = _manual_writes(seq_id)
        missing = [m.hex(" ") for m in manual if m not in sent_frames]
        assert not missing, missing
        # the motion command comes after its targets, the disable last
        assert sent_frames[-1] == manual[-1] == bytes.fromhex("010000000000")
        if b"\x00\x83" in manual:
            start = sent_frames.index(b"\x00\x83")
            assert all(sent_frames.index(m) < start for m in manual[:manual.index(b"\x00\x83")])


def test_stop_repetitive_is_refused_over_can(rig: joints.Rig) -> None:
    with pytest.raises(CommandError, match="use stop"):
        driver_of(rig).stop_repetitive()


def test_repetitive_motion_of_the_position_panel(rig: joints.Rig) -> None:
    """Chapter 4's "repetitive" box: motion mode 2 with the dwell time (ms over CAN, 0.05 ms as a parameter)."""
    d = driver_of(rig)
    trace = Trace()
    rig.trace(trace)
    d.enable()
    target = round(0.3 / (2 * math.pi / COUNTS_PER_REV))
    d.move_repetitive(target, speed=100000, acceleration=400000, deceleration=400000, dwell=4000)
    assert "node 4 write 0x0093 = 200" in sent(trace)  # 4000 x 0.05 ms = 200 ms
    seen = []
    for _ in range(40):
        rig.sleep(0.1)
        seen.append(d.state().position)
    assert max(seen) > target - 200 and min(seen) < 200  # went out and came back
    d.stop()
    rig.sleep(1.0)
    assert not d.state().moving
