"""The MKS commands of firmware V1.0.6-V1.0.9 in the native codec and the Part 8 (Modbus) map: the manuals'
example frames where they print them, round trips byte by byte, and the fields the wire cannot carry."""

from __future__ import annotations

from typing import Any

import pytest

from joints.codecs import mks
from joints.codecs import modbus as mb
from joints.codecs.crc import crc16_modbus
from joints.codecs.mks import Role
from joints.devices.mks.modbus import FC_WRITE_MULTIPLE, MKS_MODBUS
from joints.errors import EncodeError, FrameError


def _decode(role: Role, frame: bytes) -> Any:
    """One frame fed byte by byte (the codec must not need more than the frame, nor decode early)."""
    codec = mks.MksCodec(role)
    for i, b in enumerate(frame):
        codec.feed(bytes((b,)))
        msg = codec.next_message()
        if i < len(frame) - 1:
            assert msg is None, f"decoded after {i + 1} of {len(frame)} bytes"
    assert msg is not None
    return msg


def _modbus_frame(pdu: bytes) -> bytes:
    return pdu + crc16_modbus(pdu).to_bytes(2, "little")


# -- 0x36 write the IO port (V1.0.6) ----------------------------------------------------------------


@pytest.mark.parametrize(("msg", "byte"), [
    (mks.WriteIoPort(1, 1, 1, 1, 0), 0x58),  # b7-b6 OUT2_mask 1, b5-b4 OUT1_mask 1, b3 OUT_2 1, b2 OUT_1 0
    (mks.WriteIoPort(1, 0, 1, 0, 1), 0x14),
    (mks.WriteIoPort(1, 2, 2, 0, 0), 0xA0),
])
def test_write_io_port_packs_masks_and_levels_into_one_byte(msg: mks.WriteIoPort, byte: int) -> None:
    frame = mks.encode(msg)
    assert frame == mks.with_checksum(bytes((0xFA, 0x01, 0x36, byte)))
    assert _decode(Role.DEVICE, frame) == msg
    assert _decode(Role.HOST, mks.encode(mks.SetReply(1, 0x36, mks.SetStatus.SUCCESS))) == \
        mks.SetReply(1, 0x36, mks.SetStatus.SUCCESS)


@pytest.mark.parametrize("bad", [mks.WriteIoPort(1, 3, 0, 0, 0), mks.WriteIoPort(1, 0, 0, 2, 0)])
def test_write_io_port_refuses_what_the_byte_cannot_carry(bad: mks.WriteIoPort) -> None:
    with pytest.raises(EncodeError):
        mks.encode(bad)


@pytest.mark.parametrize("byte", [0xC0, 0x30, 0x01, 0x02])
def test_write_io_port_with_a_mask_of_3_or_reserved_bits_is_rejected(byte: int) -> None:
    with pytest.raises(FrameError):
        _decode(Role.DEVICE, mks.with_checksum(bytes((0xFA, 0x01, 0x36, byte))))


def test_write_io_port_over_modbus_is_fc16_0x36_and_the_manuals_reply() -> None:
    """Modbus 4.2: 01 10 00 36 00 02 04 OUT2_mask OUT2 OUT1_mask OUT1; reply 01 10 00 36 00 02 A1 C6."""
    block = MKS_MODBUS.block(FC_WRITE_MULTIPLE, 0x36)
    words = block.words({"write_io_out2_mask": 1, "write_io_out2": 1, "write_io_out1_mask": 0, "write_io_out1": 0})
    assert words == (0x0101, 0x0000)
    assert mb.encode(mb.WriteMultipleRegistersReply(1, 0x36, 2)) == bytes.fromhex("01 10 00 36 00 02 A1 C6")
    assert _modbus_frame(bytes.fromhex("01 10 00 36 00 02 04 01 01 00 00")) == \
        mb.encode(mb.WriteMultipleRegisters(1, 0x36, words))


# -- 0x9D position-error protection (V1.0.6) --------------------------------------------------------


def test_position_error_protection_is_the_manuals_example() -> None:
    """RS485 V1.0.9 5.4.2: "send FA 01 9D 01 00 14 36 B0 93, return FB 01 9D 01 9A" (enable, Tim 20, Errors
    14000 = 180 degrees); the V1.0.6 table puts g0Enable in b1 of the same byte."""
    msg = mks.SetPositionErrorProtection(1, 0, 1, 0x14, 0x36B0)
    frame = bytes.fromhex("FA 01 9D 01 00 14 36 B0 93")
    assert mks.encode(msg) == frame
    assert _decode(Role.DEVICE, frame) == msg
    assert _decode(Role.HOST, bytes.fromhex("FB 01 9D 01 9A")) == mks.SetReply(1, 0x9D, mks.SetStatus.SUCCESS)
    both = mks.SetPositionErrorProtection(1, 1, 1, 0x14, 0x36B0)
    assert mks.encode(both)[3] == 0x03 and _decode(Role.DEVICE, mks.encode(both)) == both


def test_position_error_protection_reserved_bits_are_rejected() -> None:
    with pytest.raises(FrameError):
        _decode(Role.DEVICE, mks.with_checksum(bytes.fromhex("FA 01 9D 05 00 14 36 B0")))
    with pytest.raises(EncodeError):
        mks.encode(mks.SetPositionErrorProtection(1, 0, 2, 0, 0))


def test_position_error_protection_over_modbus_is_fc16_0x9d_with_two_flag_bits() -> None:
    """Modbus: 01 10 00 9D 00 03 06 | 00 (b1 g0Enable, b0 pEnable) | Tim | Errs; reply 01 10 00 9D 00 03 11 E6."""
    block = MKS_MODBUS.block(FC_WRITE_MULTIPLE, 0x9D)
    values = {"en_trigger_zero_return": 1, "position_error_protection": 1, "position_error_time": 0x14,
              "position_error_count": 0x36B0}
    assert block.words(values) == (0x0003, 0x0014, 0x36B0)
    assert block.decode_words((0x0001, 0x0014, 0x36B0))["en_trigger_zero_return"] == 0
    assert block.decode_words((0x0002, 0, 0))["en_trigger_zero_return"] == 1
    assert mb.encode(mb.WriteMultipleRegistersReply(1, 0x9D, 3)) == bytes.fromhex("01 10 00 9D 00 03 11 E6")


# -- 0x95 position-reached threshold (V1.0.8) -------------------------------------------------------


def test_position_threshold_frame() -> None:
    """RS485 V1.0.9 5.2.17: FA addr 95 enable values(uint16) CRC; the default 01 00C8 (200)."""
    msg = mks.SetPositionThreshold(1, 1, 200)
    frame = mks.with_checksum(bytes.fromhex("FA 01 95 01 00 C8"))
    assert mks.encode(msg) == frame
    assert _decode(Role.DEVICE, frame) == msg
    assert _decode(Role.HOST, mks.with_checksum(bytes.fromhex("FB 01 95 00"))) == \
        mks.SetReply(1, 0x95, mks.SetStatus.FAIL)
    assert MKS_MODBUS.find(FC_WRITE_MULTIPLE, 0x95) is None  # not in the Modbus-RTU manual


# -- 0x4A / 0x4B synchronous control (V1.0.8) --------------------------------------------------------


def test_sync_frames_of_12_4() -> None:
    """12.4.3 prints "FA 01 4A 01 CRC" and "FA 00 4B CRC" (checksums completed); 0x4B has no reply."""
    assert mks.encode(mks.SetSync(1, 1)) == mks.with_checksum(bytes.fromhex("FA 01 4A 01"))
    assert mks.encode(mks.SyncExecute(0)) == bytes.fromhex("FA 00 4B 45")
    assert _decode(Role.DEVICE, bytes.fromhex("FA 00 4B 45")) == mks.SyncExecute(0)
    assert _decode(Role.DEVICE, mks.with_checksum(bytes.fromhex("FA 05 4A 01"))) == mks.SetSync(5, 1)


def test_run_status_5_is_an_immediate_reply_not_a_completion() -> None:
    """10.1: "status = 5 Data has received for Synchronous mode" - the answer to the run command itself."""
    reply = _decode(Role.HOST, mks.with_checksum(bytes.fromhex("FB 01 F6 05")))
    assert reply == mks.RunReply(1, 0xF6, mks.RunStatus.SYNC_RECEIVED)
    assert not reply.is_completion
    assert mks.RunReply(1, 0xF6, mks.RunStatus.COMPLETE).is_completion
    assert mks.RunReply(1, 0xF6, mks.RunStatus.END_LIMIT_STOP).is_completion


# -- 0xF6 with a run time (V1.0.7) -------------------------------------------------------------------


def test_speed_mode_has_a_short_and_a_long_form() -> None:
    """10.1: FA addr F6 dir|speed speed acc [runTime(4)] CRC; the manual's untimed example stays 7 bytes."""
    assert mks.encode(mks.RunSpeed(1, mks.RunDirection.CCW, 640, 2)) == bytes.fromhex("FA 01 F6 02 80 02 75")
    timed = mks.RunSpeed(1, mks.RunDirection.CCW, 640, 2, 500)
    frame = mks.encode(timed)
    assert frame == mks.with_checksum(bytes.fromhex("FA 01 F6 02 80 02 00 00 01 F4"))
    assert mks.REQUEST_DATA_LENGTH[0xF6] == 3 and mks.REQUEST_LONG_DATA_LENGTH[0xF6] == 7
    codec = mks.MksCodec(Role.DEVICE)
    codec.feed(frame + bytes.fromhex("FA 01 F6 02 80 02 75") + frame)
    assert [codec.next_message() for _ in range(3)] == [timed, mks.RunSpeed(1, mks.RunDirection.CCW, 640, 2), timed]
    with pytest.raises(EncodeError):
        mks.encode(mks.RunSpeed(1, mks.RunDirection.CCW, 640, 2, 0x10000000))


def test_a_short_speed_frame_whose_checksum_could_start_a_run_time_waits_for_silence() -> None:
    """A short frame is taken at once unless its checksum byte (<= 0x0F) could be a runTime's first byte."""
    short = mks.with_checksum(bytes.fromhex("FA 01 F6 00 0A 0B"))  # checksum 0x0E
    assert short[-1] <= 0x0F
    codec = mks.MksCodec(Role.DEVICE)
    codec.feed(short)
    assert codec.next_message() is None  # could still be a long frame
    codec.flush()
    assert codec.next_message() == mks.RunSpeed(1, mks.RunDirection.CCW, 10, 0x0B)
    codec.feed(short + bytes.fromhex("FA 01 F1 EC"))
    assert codec.next_message() == mks.RunSpeed(1, mks.RunDirection.CCW, 10, 0x0B)  # more bytes decided it
    assert codec.next_message() == mks.QueryStatus(1)


def test_a_timed_speed_command_in_a_long_packet_slot() -> None:
    packet = mks.LongPacket((mks.RunSpeed(1, mks.RunDirection.CW, 100, 5, 300), mks.RunSpeed(2, mks.RunDirection.CCW,
                                                                                             100, 5)))
    assert _decode(Role.DEVICE, mks.encode(packet)) == packet


def test_timed_speed_mode_over_modbus_is_fc16_0xf6_with_4_registers() -> None:
    """Modbus 8.1: 01 10 00 F6 00 04 08 dir acc speed runTime (10 ms); the untimed form keeps 2 registers."""
    from joints.devices.mks.modbus import TIMED_SPEED_MODE

    assert MKS_MODBUS.find(FC_WRITE_MULTIPLE, 0xF6).count == 2  # type: ignore[union-attr]
    assert MKS_MODBUS.find(FC_WRITE_MULTIPLE, 0xF6, 4) is TIMED_SPEED_MODE
    assert MKS_MODBUS.block_of("speed_mode_run_time") is TIMED_SPEED_MODE
    words = TIMED_SPEED_MODE.words({"speed_mode_direction": 1, "speed_mode_acc": 2, "speed_mode_speed": 640,
                                    "speed_mode_run_time": 500})
    assert words == (0x0102, 640, 0, 500)


# -- 0x50 IAP control (V1.0.8) -------------------------------------------------------------------------


def test_iap_control_frames() -> None:
    """RS485 5.6: FA addr 50 cmd CRC (the silent state broadcast "FA 00 50 02 CRC"); Modbus 3.6:
    01 06 00 50 00 cmd, the reply to cmd 01 is 01 06 00 50 00 01 48 1B."""
    assert mks.encode(mks.IapControl(0, 2)) == mks.with_checksum(bytes.fromhex("FA 00 50 02"))
    assert _decode(Role.DEVICE, mks.encode(mks.IapControl(1, 1))) == mks.IapControl(1, 1)
    assert _decode(Role.HOST, mks.with_checksum(bytes.fromhex("FB 01 50 01"))) == \
        mks.SetReply(1, 0x50, mks.SetStatus.SUCCESS)
    block = MKS_MODBUS.block(0x06, 0x50)
    assert block.words({"iap_control": 1}) == (1,)
    assert mb.encode(mb.WriteSingleRegisterReply(1, 0x50, 1)) == bytes.fromhex("01 06 00 50 00 01 48 1B")


# -- 0x96 / 0x97 PID parameters (V1.0.8) ---------------------------------------------------------------


def test_pid_frames_and_the_modbus_reply() -> None:
    """RS485 5.3: FA addr 96 Kp Ki Kd Kv CRC (uint16 each); Modbus 3.3.1 reply 01 10 00 96 00 04 21 E6."""
    msg = mks.SetVfocPid(1, 0xDC, 0x64, 0x10E, 0x140)
    frame = mks.with_checksum(bytes.fromhex("FA 01 96 00 DC 00 64 01 0E 01 40"))
    assert mks.encode(msg) == frame and _decode(Role.DEVICE, frame) == msg
    assert _decode(Role.DEVICE, mks.encode(mks.SetClosePid(2, 0xC8, 0x50, 0xFA, 0x12C))) == \
        mks.SetClosePid(2, 0xC8, 0x50, 0xFA, 0x12C)
    assert mb.encode(mb.WriteMultipleRegistersReply(1, 0x96, 4)) == bytes.fromhex("01 10 00 96 00 04 21 E6")
    assert MKS_MODBUS.block(FC_WRITE_MULTIPLE, 0x97).words(
        {"close_kp": 0xC8, "close_ki": 0x50, "close_kd": 0xFA, "close_kv": 0x12C}) == (0xC8, 0x50, 0xFA, 0x12C)


# -- 0x83 while running, not saved (V1.0.7) -------------------------------------------------------------


def test_working_current_has_a_saved_and_an_unsaved_form() -> None:
    """RS485 5.2.3: FA addr 83 current [00] CRC - the trailing 00 means "without saving"; status 2 answers it
    and no other set command."""
    saved, unsaved = mks.SetWorkingCurrent(1, 1600), mks.SetWorkingCurrent(1, 1600, 1)
    assert mks.encode(saved) == mks.with_checksum(bytes.fromhex("FA 01 83 06 40"))
    assert mks.encode(unsaved) == mks.with_checksum(bytes.fromhex("FA 01 83 06 40 00"))
    codec = mks.MksCodec(Role.DEVICE)
    codec.feed(mks.encode(unsaved) + mks.encode(saved) + mks.encode(unsaved))
    assert [codec.next_message() for _ in range(3)] == [unsaved, saved, unsaved]
    assert _decode(Role.HOST, mks.with_checksum(bytes.fromhex("FB 01 83 02"))) == \
        mks.SetReply(1, 0x83, mks.SetStatus.SUCCESS_UNSAVED)
    with pytest.raises(FrameError):
        _decode(Role.HOST, mks.with_checksum(bytes.fromhex("FB 01 82 02")))
    with pytest.raises(EncodeError):
        mks.encode(mks.SetReply(1, 0x82, mks.SetStatus.SUCCESS_UNSAVED))


def test_working_current_unsaved_over_modbus_is_bit_15() -> None:
    """Modbus 3.2.3: "If the highest bit of Current is 1, only the current value will be changed, and it will
    not be saved"."""
    block = MKS_MODBUS.block(0x06, 0x83)
    assert block.words({"working_current": 1600, "working_current_unsaved": 1}) == (0x8640,)
    assert block.words({"working_current": 1600, "working_current_unsaved": 0}) == (0x0640,)
    assert block.decode_words((0x8640,)) == {"working_current": 1600, "working_current_unsaved": 1}


# -- 0x3B: one status or two (V1.0.7) -------------------------------------------------------------------


def test_go_back_to_zero_reply_with_one_or_two_statuses_decodes_at_every_address() -> None:
    """RS485 5.1.8: FB addr 3B status1 status2 CRC (V1.0.7+) or FB addr 3B status CRC (before); the host tells
    them apart by the values (statuses are 0-2), at once or, for a few addresses, at the next byte / silence."""
    z = mks.GoBackToZeroStatus
    waited = set()
    for address in range(1, 256):
        for s1 in z:
            short = mks.GoBackToZeroStatusReply(address, s1)
            for s2 in z:
                long = mks.GoBackToZeroStatusReply(address, s1, s2)
                codec = mks.MksCodec(Role.HOST)
                codec.feed(mks.encode(long) + mks.encode(short) + mks.encode(long))
                codec.flush()
                assert [codec.next_message() for _ in range(3)] == [long, short, long]
            codec = mks.MksCodec(Role.HOST)
            codec.feed(mks.encode(short))
            if codec.next_message() is None:  # ambiguous: could be the head of a two-status reply
                waited.add(address)
                codec.flush()
                assert codec.next_message() == short
    assert waited == set(range(0xC8, 0xCD))  # (0xFB + addr + 0x3B + status) & 0xFF <= 2


# -- 0x91 goZeroMode (V1.0.9): coordinate homing ------------------------------------------------------


def test_coordinate_homing_frames_are_the_manuals_examples() -> None:
    """RS485 V1.0.9 7.7 ``FA 01 91 01 8D``; 7.3.6: ``FA 01 91 8C`` and ``FA 01 91 00 8C`` are the same origin
    homing; Modbus V1.0.9 5.7 ``01 06 00 91 00 02 59 E6`` (goZeroMode 2), 5.3.6's reply ``01 06 00 91 00 01 19 E7``
    (goZeroMode 1)."""
    assert mks.encode(mks.GoHome(1, 1)) == bytes.fromhex("FA 01 91 01 8D")
    assert mks.encode(mks.GoHome(1)) == bytes.fromhex("FA 01 91 8C")
    assert _decode(Role.DEVICE, bytes.fromhex("FA 01 91 01 8D")) == mks.GoHome(1, 1)
    assert _decode(Role.DEVICE, bytes.fromhex("FA 01 91 00 8C")) == mks.GoHome(1, 0)
    codec = mks.MksCodec(Role.DEVICE)
    codec.feed(bytes.fromhex("FA 01 91 8C"))
    codec.flush()  # the short frame at silence
    assert codec.next_message() == mks.GoHome(1, 0)
    block = MKS_MODBUS.block_of("go_home_mode")
    assert _modbus_frame(bytes((1, 6)) + (0x91).to_bytes(2, "big")
                         + block.words({"go_home": 1, "go_home_mode": 1})[0].to_bytes(2, "big")) == \
        bytes.fromhex("01 06 00 91 00 02 59 E6")
    assert block.words({"go_home": 1, "go_home_mode": 0}) == (1,)
    assert _modbus_frame(bytes.fromhex("01 06 00 91 00 01")) == bytes.fromhex("01 06 00 91 00 01 19 E7")
    assert block.decode_words([2]) == {"go_home": 1, "go_home_mode": 1}


@pytest.mark.parametrize("byte", [0x02, 0xFF])
def test_coordinate_homing_mode_other_than_0_or_1_is_not_taken(byte: int) -> None:
    with pytest.raises(EncodeError):
        mks.encode(mks.GoHome(1, 2))
    codec = mks.MksCodec(Role.DEVICE)
    codec.feed(mks.with_checksum(bytes((0xFA, 0x01, 0x91, byte))))
    codec.flush()
    with pytest.raises(FrameError):
        codec.next_message()


# -- 0x00 read a configuration parameter (V1.0.8) ------------------------------------------------------


def _host_expecting(request: mks.ReadParameter, frame: bytes) -> Any:
    codec = mks.MksCodec(Role.HOST)
    codec.expect_reply(request)
    for i, b in enumerate(frame):
        codec.feed(bytes((b,)))
        msg = codec.next_message()
        if i < len(frame) - 1:
            assert msg is None, f"decoded after {i + 1} of {len(frame)} bytes"
    return msg


def test_read_parameter_frames_are_the_manuals_example() -> None:
    """RS485 V1.0.9 5.1.10: ``FA 01 00 82 7D`` reads the work mode, ``FB 01 82 05 83`` answers 5 (SR_vFOC)."""
    request = mks.ReadParameter(1, 0x82)
    assert mks.encode(request) == bytes.fromhex("FA 01 00 82 7D")
    assert _decode(Role.DEVICE, bytes.fromhex("FA 01 00 82 7D")) == request
    reply = _host_expecting(request, bytes.fromhex("FB 01 82 05 83"))
    assert reply == mks.ParameterReply(1, 0x82, b"\x05")
    assert mks.encode(reply) == bytes.fromhex("FB 01 82 05 83")
    assert mks.parameter_request(reply) == mks.SetWorkMode(1, 5)
    with pytest.raises(FrameError):  # without the open request, the same bytes are a set reply of status 5
        _decode(Role.HOST, bytes.fromhex("FB 01 82 05 83"))


@pytest.mark.parametrize(("code", "param", "request_"), [
    (0x83, bytes.fromhex("04 D2"), mks.SetWorkingCurrent(1, 1234)),
    (0x96, bytes.fromhex("00 DC 00 64 01 0E 01 40"), mks.SetVfocPid(1, 0xDC, 0x64, 0x10E, 0x140)),
])
def test_read_parameter_reply_has_the_parameters_length(code: int, param: bytes, request_: Any) -> None:
    frame = mks.with_checksum(bytes((0xFB, 0x01, code)) + param)
    reply = _host_expecting(mks.ReadParameter(1, code), frame)
    assert reply == mks.ParameterReply(1, code, param)
    assert mks.parameter_request(reply) == request_


@pytest.mark.parametrize("code", [0x82, 0x83, 0x96])
def test_read_parameter_ff_ff_is_not_readable(code: int) -> None:
    frame = mks.with_checksum(bytes((0xFB, 0x01, code, 0xFF, 0xFF)))
    codec = mks.MksCodec(Role.HOST)
    codec.expect_reply(mks.ReadParameter(1, code))
    codec.feed(frame)
    codec.flush()
    assert codec.next_message() == mks.ParameterReply(1, code, None)
    assert mks.encode(mks.ParameterReply(1, code, None)) == frame


def test_read_parameter_expectation_is_for_one_reply_and_one_address() -> None:
    codec = mks.MksCodec(Role.HOST)
    codec.expect_reply(mks.ReadParameter(1, 0x83))
    codec.feed(mks.encode(mks.SetReply(2, 0x83, mks.SetStatus.SUCCESS)))  # another drive's set reply
    assert codec.next_message() == mks.SetReply(2, 0x83, mks.SetStatus.SUCCESS)
    codec.feed(mks.with_checksum(bytes.fromhex("FB 01 83 04 D2")))
    assert codec.next_message() == mks.ParameterReply(1, 0x83, bytes.fromhex("04 D2"))
    codec.feed(mks.encode(mks.SetReply(1, 0x83, mks.SetStatus.SUCCESS)))  # the next one is a set reply again
    assert codec.next_message() == mks.SetReply(1, 0x83, mks.SetStatus.SUCCESS)
    with pytest.raises(EncodeError):
        codec.expect_reply(mks.ReadParameter(1, 0x31))  # a read, not a set command's parameter


# -- 0x42 user ID (V1.0.9) -------------------------------------------------------------------------------


def test_user_id_read_and_write_forms() -> None:
    """RS485 V1.0.9 5.1.12: ``FA addr 42 chk`` reads, ``FA addr 42 ID[4] chk`` writes; the read's reply
    carries the ID, the write's a status."""
    assert mks.encode(mks.UserId(1)) == bytes.fromhex("FA 01 42 3D")
    write = mks.with_checksum(bytes.fromhex("FA 01 42 12 34 56 78"))
    assert mks.encode(mks.UserId(1, 0x12345678)) == write
    codec = mks.MksCodec(Role.DEVICE)
    codec.feed(bytes.fromhex("FA 01 42 3D"))
    codec.flush()  # the short form at silence
    assert codec.next_message() == mks.UserId(1)
    codec.feed(write)
    assert codec.next_message() == mks.UserId(1, 0x12345678)
    host = mks.MksCodec(Role.HOST)
    host.expect_reply(mks.UserId(1))
    reply = mks.encode(mks.UserIdReply(1, 0x12345678))
    assert reply == mks.with_checksum(bytes.fromhex("FB 01 42 12 34 56 78"))
    host.feed(reply)
    assert host.next_message() == mks.UserIdReply(1, 0x12345678)
    host.expect_reply(mks.UserId(1, 5))
    host.feed(mks.encode(mks.SetReply(1, 0x42, mks.SetStatus.SUCCESS)))
    assert host.next_message() == mks.SetReply(1, 0x42, mks.SetStatus.SUCCESS)


# -- 0x99 pulse divider output, 0x9F IN_1 port mode (V1.0.9; the manual prints no example frame) ------------


def test_pulse_divider_0x99_is_divlevel_and_a_uint32_divperiod() -> None:
    msg = mks.SetPulseDivider(1, 1, 3200)  # 6.4: "FA addr 99[H] divLevel divPeriod CRC", bytes 5-8 the period
    frame = mks.encode(msg)
    assert frame == mks.with_checksum(bytes.fromhex("FA 01 99 01 00 00 0C 80"))
    assert _decode(Role.DEVICE, frame) == msg
    assert _decode(Role.HOST, mks.with_checksum(bytes.fromhex("FB 01 99 01"))) == \
        mks.SetReply(1, 0x99, mks.SetStatus.SUCCESS)
    with pytest.raises(EncodeError):
        mks.encode(mks.SetPulseDivider(1, 0, 1 << 32))
    # Modbus-RTU V1.0.9 4.3: FC16 0x0099, 3 registers: divLevel (bytes 1-2), divPeriod (bytes 3-6)
    block = MKS_MODBUS.block(FC_WRITE_MULTIPLE, 0x99)
    assert block.words({"pulse_divider_level": 1, "pulse_divider_period": 3200}) == (1, 0, 3200)
    reply = bytes.fromhex("01 10 00 99 00 03")
    assert crc16_modbus(reply).to_bytes(2, "little") == bytes.fromhex("50 27")  # the manual's reply frame


def test_in1_port_mode_0x9f_is_one_byte() -> None:
    msg = mks.SetIn1PortMode(1, 1)  # 6.2: "FA addr 9FH type CRC"
    frame = mks.encode(msg)
    assert frame == mks.with_checksum(bytes.fromhex("FA 01 9F 01"))
    assert _decode(Role.DEVICE, frame) == msg
    assert _decode(Role.HOST, mks.with_checksum(bytes.fromhex("FB 01 9F 00"))) == \
        mks.SetReply(1, 0x9F, mks.SetStatus.FAIL)
    assert MKS_MODBUS.find(FC_WRITE_MULTIPLE, 0x9F) is None and MKS_MODBUS.find(0x06, 0x9F) is None  # native only
