"""Every MKS vector and sequence of the manual against the twin, byte for byte where the reply does not depend
on motion; the 5.2 #16 group example and the 5.7 long packet on buses of several twins; Part 8 frames
(the 0x90 quirk accepted exactly, any other inconsistent count answered with exception 03)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("mujoco")
pytestmark = pytest.mark.mks_firmware

from mkskit import open_motor

from joints.codecs import mks
from joints.codecs import modbus as mb
from joints.codecs.crc import append_crc
from joints.devices.mks.modbus import MKS_MODBUS
from joints.devices.mks.state import WorkMode
from joints.sim import sensors
from testdata import by_id, sequences, vectors

RECORDS = by_id()
NATIVE = vectors("mks-native", "mks-servo42d57d")
MODBUS = vectors("modbus-rtu", "mks-servo42d57d")


def _hex(record: dict[str, Any]) -> bytes:
    return bytes.fromhex(record.get("correct_hex") or record["hex"])


def _serial_twin(rig) -> None:  # type: ignore[no-untyped-def]
    """The manual's 7.1 configuration (Menu -> Mode -> SR_vFOC) on the twin of joint m1."""
    rig.world.drives["m1"].write("work_mode", int(WorkMode.SR_vFOC))


def test_every_native_request_vector_gets_its_documented_reply_form(tmp_path: Path) -> None:
    """Requests to address 1 get exactly one uplink frame: the status of the command (1 = started/success);
    0 (broadcast), groups and long packets get none."""
    requests = [v for v in NATIVE if v["direction"] == "request"]
    assert len(requests) >= 30
    for v in requests:
        with open_motor(tmp_path) as rig:
            _serial_twin(rig)
            bus = rig.world.buses["rs485"]
            frame = _hex(v)
            reply = bus.receive(frame)
            head = frame[0]
            if head == mks.HEAD_LONG or frame[1] != 1:
                assert reply == b"", v["id"]
                continue
            fn = frame[2]
            if fn == 0x30:
                assert len(reply) == 10 and reply[:3] == bytes((0xFB, 1, 0x30)), v["id"]
                continue
            if fn == 0x80:  # calibrate: 0 "calibrating" at once (1 success later)
                assert reply == mks.encode(mks.CalibrationReply(1, mks.CalibrationStatus.CALIBRATING)), v["id"]
                continue
            assert reply == mks.encode(mks.RunReply(1, fn, mks.RunStatus.STARTED) if fn in mks.RUN_REPLY_FUNCTIONS
                                       else mks.SetReply(1, fn, mks.SetStatus.SUCCESS)), v["id"]


def test_7_3_read_encoder_reply_byte_exact(tmp_path: Path) -> None:
    """FB 01 30 FF FF FF FF 22 69 B3: carry -1, value 0x2269 - the shaft placed there, the reply is the manual's."""
    reply = RECORDS["mks-native-7.3-read-encoder-recv"]
    decoded = mks.MksCodec(mks.Role.HOST)
    decoded.feed(_hex(reply))
    msg = decoded.next_message()
    assert isinstance(msg, mks.EncoderCarryReply)
    with open_motor(tmp_path) as rig:
        rig.world.set_joint_positions({"m1": (msg.addition + 0.5) * 2 * math.pi / 16384})
        assert rig.world.buses["rs485"].receive(_hex(RECORDS["mks-native-7.3-read-encoder-send"])) == _hex(reply)


def _sequence(title: str) -> dict[str, Any]:
    return next(s for s in sequences("mks") if s["id"] == title)


def _step(rig, bus, send: str) -> bytes:  # type: ignore[no-untyped-def]
    reply = bus.receive(bytes.fromhex(send))
    return reply


def _unsolicited_until(rig, bus, seconds: float) -> list[tuple[float, bytes]]:  # type: ignore[no-untyped-def]
    out = []
    end = rig.time + seconds
    while rig.time < end:
        rig.sleep(0.01)
        out += bus.take_frames()
    return out


def test_sequence_7_4_speed_mode_save_stop_power_cycle(tmp_path: Path) -> None:
    seq = _sequence("seq-mks-native-7.4")
    steps = seq["steps"]
    # the frames go straight to the device bus and its completions are taken there: no timed line in between
    with open_motor(tmp_path, timing="ideal") as rig:
        sensors.ideal(rig.world)  # the manual's speeds exactly (the drive's estimate steps by 0.7 r/min)
        _serial_twin(rig)
        bus = rig.world.buses["rs485"]
        assert bus.receive(bytes.fromhex(steps[0]["send_hex"])) == bytes.fromhex(steps[0]["expect_hex"])
        rig.sleep(4.2)
        assert rig.joints["m1"].driver.read("real_time_speed") == 320  # acc = 2: 320 steps of 12.7 ms = 4.06 s
        # save: 01 at once (start), its 02 (the manual's alternative "success") later
        assert bus.receive(bytes.fromhex(steps[1]["send_hex"])) == bytes.fromhex(steps[1]["expect_hex"])
        assert [f for _t, f in _unsolicited_until(rig, bus, 0.05)] == [bytes.fromhex(steps[1]["expect_hex_alternative"])]
        # stop with acc 2: 01 at once, 02 when it has stopped (~4 s from 320 rpm at 12.7 ms per rpm)
        assert bus.receive(bytes.fromhex(steps[2]["send_hex"])) == bytes.fromhex(steps[2]["expect_hex"])
        t0 = rig.time
        done = _unsolicited_until(rig, bus, 5.0)
        assert [f for _t, f in done] == [bytes.fromhex(steps[2]["expect_hex_alternative"])]
        assert done[0][0] - t0 == pytest.approx(320 * (256 - 2) * 50e-6, abs=0.02)
        # power cycle: the saved speed mode runs again
        assert "Power cycle" in steps[3]["action"]
        rig.reset()
        rig.sleep(5.0)
        assert rig.joints["m1"].driver.read("real_time_speed") == 320


def test_sequence_7_5_position_mode_run_reverse_stop(tmp_path: Path) -> None:
    seq = _sequence("seq-mks-native-7.5")
    steps = seq["steps"]
    # the frames go straight to the device bus and its completions are taken there: no timed line in between
    with open_motor(tmp_path, timing="ideal") as rig:
        _serial_twin(rig)
        bus = rig.world.buses["rs485"]
        # 200 turns forward at 640 rpm, acc 5 (12.55 ms per rpm: 8 s ramps): 01 at once, 02 at the end (~27 s)
        assert bus.receive(bytes.fromhex(steps[0]["send_hex"])) == bytes.fromhex(steps[0]["expect_hex"])
        done = []
        while not done and rig.time < 40:
            done = _unsolicited_until(rig, bus, 1.0)
        assert [f for _t, f in done] == [_hex(RECORDS[steps[0]["extra_responses"][0]])]
        turns = rig.joints["m1"].driver.read("encoder_addition") / 16384
        assert turns == pytest.approx(200, abs=1 / 16384)
        # reverse 1000 turns, then stop with acc 8 while running
        assert bus.receive(bytes.fromhex(steps[1]["send_hex"])) == bytes.fromhex(steps[1]["expect_hex"])
        rig.sleep(1.0)
        assert bus.receive(bytes.fromhex(steps[2]["send_hex"])) == bytes.fromhex(steps[2]["expect_hex"])
        done = _unsolicited_until(rig, bus, 6.0)
        assert [f for _t, f in done] == [_hex(RECORDS[steps[2]["extra_responses"][0]])]


def test_group_example_5_2_16_on_six_twins(tmp_path: Path) -> None:
    """Motors 1-3 in group 0x50, 4-6 in 0x51: the four frames of the manual move the right motors by one
    turn; only the frame to a slave address is answered."""
    frames = [_hex(RECORDS[f"mks-native-5.2.16-group-ex{i}-send"]) for i in range(1, 5)]
    moved_by = [{1}, {1, 2, 3, 4, 5, 6}, {1, 2, 3}, {4, 5, 6}]
    with open_motor(tmp_path, n=6) as rig:
        bus = rig.world.buses["rs485"]
        for i in range(1, 7):
            fw = rig.world.drives[f"m{i}"]
            fw.write("work_mode", int(WorkMode.SR_vFOC))
            fw.write("group_address", 0x50 if i <= 3 else 0x51)
        turns = dict.fromkeys(range(1, 7), 0)
        for frame, who in zip(frames, moved_by):
            reply = bus.receive(frame)
            assert reply == (mks.encode(mks.RunReply(1, 0xFD, mks.RunStatus.STARTED)) if frame[1] == 1 else b"")
            rig.sleep(2.0)
            for i in who:
                turns[i] += 1
            for i in range(1, 7):
                assert rig.joints[f"m{i}"].driver.read("encoder_addition") / 16384 == pytest.approx(turns[i], abs=1e-3)
        # a completion frame only for the command that was answered (the reads delivered it to m1's driver)
        assert [rig.joints[f"m{i}"].driver.completions for i in range(1, 7)] == [1, 0, 0, 0, 0, 0]


@pytest.mark.mks_firmware("v1.0.5", "v1.0.9")  # 33 s simulated; no profile's additions take part: the two ends
def test_long_packet_5_7_moves_five_twins_differently_and_nobody_answers(tmp_path: Path) -> None:
    packet = _hex(RECORDS["mks-native-5.7-longpacket-send"])
    assert len(packet) == 52
    with open_motor(tmp_path, n=5) as rig:
        sensors.ideal(rig.world)  # the manual's speeds exactly
        bus = rig.world.buses["rs485"]
        for i in range(1, 6):
            rig.world.drives[f"m{i}"].write("work_mode", int(WorkMode.SR_vFOC))
        assert bus.receive(packet) == b""
        rig.sleep(3.0)
        speed = {i: rig.joints[f"m{i}"].driver.read("real_time_speed") for i in range(1, 6)}
        assert speed[1] == 50 and speed[2] == -100  # speed mode forward 0x32 / reverse 0x64
        assert 0 < speed[3] < speed[4] < speed[5]  # still ramping with acc 2 / 0x64 / 0xC8
        rig.sleep(30.0)
        pos = {i: rig.joints[f"m{i}"].driver.read("encoder_addition") / 16384 for i in range(3, 6)}
        assert pos[3] == pytest.approx(100, abs=1e-3)  # 0xFD 320000 pulses at 16 microsteps
        assert pos[4] == pytest.approx(100, abs=1e-3)  # 0xF4 relAxis 0x190000
        assert pos[5] == pytest.approx(50, abs=1e-3)  # 0xF5 absAxis 0xC8000
        assert bus.take_unsolicited() == b""  # no completion frames either


# --- Part 8 ---------------------------------------------------------------------------------------


def _modbus_rig(tmp_path: Path):  # type: ignore[no-untyped-def]
    return open_motor(tmp_path, protocol="modbus-rtu")


def test_every_part8_request_vector_is_answered_byte_exact(tmp_path: Path) -> None:
    requests = [v for v in MODBUS if v["direction"] == "request"]
    assert len(requests) >= 17
    for v in requests:  # a fresh drive each (8.2.2 restores the factory protocol: native)
        with _modbus_rig(tmp_path) as rig:
            rig.world.drives["m1"].write("work_mode", int(WorkMode.SR_vFOC))
            bus = rig.world.buses["rs485"]
            frame = _hex(v)
            reply = bus.receive(frame)
            if frame[1] == 0x04:
                count = frame[5]
                assert reply[:3] == bytes((1, 4, 2 * count)) and len(reply) == 5 + 2 * count, v["id"]
            else:
                expect = next(r for r in MODBUS if r.get("pair") == v["id"])
                assert reply == _hex(expect), v["id"]


@pytest.mark.parametrize("vid,values", [
    ("mks-modbus-8.2.20-recv", {"home_trigger_level": 0, "home_direction": 1, "home_speed": 60, "end_limit": 0}),
    ("mks-modbus-8.2.22-recv", {"zero_mode": 0, "zero_mode_set_zero": 0, "zero_mode_speed": 2,
                                "zero_mode_direction": 0}),
    ("mks-modbus-8.3.3.1-recv", {"speed_mode_direction": 0, "speed_mode_acc": 2, "speed_mode_speed": 320}),
    ("mks-modbus-8.3.3.2-recv", {"speed_mode_direction": 0, "speed_mode_acc": 2, "speed_mode_speed": 0}),
    ("mks-modbus-8.3.4.1-recv", {"position_mode1_direction": 0, "position_mode1_acc": 2, "position_mode1_speed": 320,
                                 "position_mode1_pulses": 3200}),
    ("mks-modbus-8.3.4.2-recv", {"position_mode1_direction": 0, "position_mode1_acc": 2, "position_mode1_speed": 0,
                                 "position_mode1_pulses": 0}),
    ("mks-modbus-8.3.5.1-recv", {"position_mode2_acc": 2, "position_mode2_speed": 600, "position_mode2_abs_pulses": 0x4000}),
    ("mks-modbus-8.3.5.2-recv", {"position_mode2_acc": 2, "position_mode2_speed": 0, "position_mode2_abs_pulses": 0}),
    ("mks-modbus-8.3.6.1-recv", {"position_mode3_acc": 2, "position_mode3_speed": 600, "position_mode3_rel_axis": 0x4000}),
    ("mks-modbus-8.3.6.2-recv", {"position_mode3_acc": 2, "position_mode3_speed": 0, "position_mode3_rel_axis": 0}),
    ("mks-modbus-8.3.7.1-recv", {"position_mode4_acc": 2, "position_mode4_speed": 600, "position_mode4_abs_axis": 0x4000}),
    ("mks-modbus-8.3.7.2-recv", {"position_mode4_acc": 2, "position_mode4_speed": 0, "position_mode4_abs_axis": 0}),
])
def test_part8_fc16_replies_byte_exact(tmp_path: Path, vid: str, values: dict[str, int]) -> None:
    with _modbus_rig(tmp_path) as rig:
        rig.world.drives["m1"].write("work_mode", int(WorkMode.SR_vFOC))
        bus = rig.world.buses["rs485"]
        block = MKS_MODBUS.block_of(next(iter(values)))
        frame = append_crc(bytes((1, 0x10)) + block.request_pdu(values))
        assert bus.receive(frame) == _hex(RECORDS[vid])


def test_the_0x90_quirk_is_accepted_exactly_and_recorded_other_counts_get_exception_03(tmp_path: Path) -> None:
    with _modbus_rig(tmp_path) as rig:
        fw = rig.world.drives["m1"]
        bus = rig.world.buses["rs485"]
        front = next(iter(bus.slaves.values()))
        quirk = append_crc(bytes.fromhex("01 10 00 90 00 03 05 01 00 00 78 01"))  # 3 registers, 5 bytes
        assert bus.receive(quirk) == _hex(RECORDS["mks-modbus-8.2.20-recv"])
        assert (fw.values["home_trigger_level"], fw.values["home_speed"], fw.values["end_limit"]) == (1, 120, 1)
        assert front.quirks == [(MKS_MODBUS.block(0x10, 0x90).title, quirk[2:-2])]
        exception_03 = mb.encode(mb.ExceptionReply(1, 0x10, 3))
        for bad in ("01 10 00 90 00 03 06 01 00 00 78 01 00",  # the "correct" Modbus form of it: not the drive's
                    "01 10 00 F6 00 03 06 00 02 01 40 00 00",  # speed mode with 3 registers
                    "01 10 00 F6 00 02 05 00 02 01 40 00",  # byte count 5 for 2 registers
                    "01 10 00 90 00 02 05 01 00 00 78 01"):  # 0x90 with 2 registers, 5 bytes
            assert bus.receive(append_crc(bytes.fromhex(bad))) == exception_03, bad
        assert len(front.quirks) == 1
        assert bus.receive(append_crc(bytes.fromhex("01 03 00 31 00 03"))) == mb.encode(mb.ExceptionReply(1, 3, 1))
        assert bus.receive(append_crc(bytes.fromhex("01 04 00 31 00 02"))) == mb.encode(mb.ExceptionReply(1, 4, 3))
        assert bus.receive(append_crc(bytes.fromhex("01 04 00 35 00 01"))) == mb.encode(mb.ExceptionReply(1, 4, 2))


def test_part8_refusals_native_mode_and_range(tmp_path: Path, mks_firmware: str) -> None:
    with open_motor(tmp_path, protocol="modbus-rtu", joint={"firmware": mks_firmware}) as rig:
        bus = rig.world.buses["rs485"]
        # the twin is in CR_vFOC (factory): a run command cannot execute; 10000 mA is out of range.
        # V1.0.5 documents no failure reply (exceptions 04 / 03, our choice); V1.0.6+ answer FC16 with
        # register quantity 0 and FC06 with register data 0xFFFF ("If write fails")
        run = append_crc(bytes((1, 0x10)) + MKS_MODBUS.block(0x10, 0xF6).request_pdu(
            {"speed_mode_direction": 0, "speed_mode_acc": 2, "speed_mode_speed": 100}))
        current = append_crc(bytes.fromhex("01 06 00 83 27 10"))
        if mks_firmware == "v1.0.5":
            assert bus.receive(run) == mb.encode(mb.ExceptionReply(1, 0x10, 4))
            assert bus.receive(current) == mb.encode(mb.ExceptionReply(1, 6, 3))
        else:
            assert bus.receive(run) == append_crc(bytes.fromhex("01 10 00 F6 00 00"))
            assert bus.receive(current) == append_crc(bytes.fromhex("01 06 00 83 FF FF"))
        # a request the protocol rejects stays an exception on every firmware: unknown register, wrong count
        assert bus.receive(append_crc(bytes.fromhex("01 06 00 99 00 01"))) == mb.encode(mb.ExceptionReply(1, 6, 2))
        assert bus.receive(append_crc(bytes.fromhex("01 04 00 F1 00 02"))) == mb.encode(mb.ExceptionReply(1, 4, 3))
        rig.world.drives["m1"].write("modbus_rtu", 0)  # the drive now speaks the native protocol only
        assert bus.receive(append_crc(bytes.fromhex("01 04 00 F1 00 01"))) == b""
