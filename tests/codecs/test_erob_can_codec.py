"""eRob CAN custom protocol codec: frame layouts of eRunner chapter 7, errors, matching rule."""

from __future__ import annotations

import can
import pytest

from joints.codecs import erob_can as ec
from joints.codecs.erob_can import (
    Ack,
    Command,
    ErrorReply,
    Read,
    ReadFailed,
    Role,
    ValueReply,
    Write,
    answers,
    decode,
    encode,
)
from joints.errors import ByteCountError, EncodeError, FrameError


def frame(can_id: int, hex_data: str, **kw: bool) -> can.Message:
    return can.Message(arbitration_id=can_id, data=bytes.fromhex(hex_data), is_extended_id=False, **kw)


def wire(message: ec.Message) -> tuple[int, str]:
    f = encode(message)
    assert f.is_extended_id is False
    assert f.dlc == len(f.data)
    return f.arbitration_id, bytes(f.data).hex(" ").upper()


# ------------------------------------------------------------------------- layouts (tables 7-1 .. 7-12)


@pytest.mark.parametrize(("message", "can_id", "data"), [
    (Read(1, 0x0002), 0x641, "00 02"),  # table 7-1, 7.4.1 step 11
    (Read(1, 0x0005, 1), 0x641, "00 05 00 01"),  # table 7-2, 7.4.1 step 10
    (Read(127, 0x0232, 8), 0x6BF, "02 32 00 08"),
    (Write(2, 0x008A, 5566), 0x642, "00 8A 00 00 15 BE"),  # table 7-5, figure 4-4
    (Write(2, 0x0087, -10000), 0x642, "00 87 FF FF D8 F0"),  # figure 4-13
    (Write(1, 0x0232, -1, 2), 0x641, "02 32 00 02 FF FF FF FF"),  # table 7-6
    (Command(1, 0x00E8), 0x641, "00 E8"),  # table 7-9 (save)
    (Command(1, 0x0100, 1), 0x641, "01 00 00 00 00 01"),  # table 7-10 (enable)
    (Command(1, 0x0100, 0), 0x641, "01 00 00 00 00 00"),  # table 7-10 (disable)
    (Command(1, 0x014F), 0x641, "01 4F"),
    (Ack(1), 0x5C1, "3E"),  # tables 7-7, 7-11
    (ValueReply(1, 7288391), 0x5C1, "00 6F 36 47 3E"),  # table 7-3
    (ValueReply(1, -2), 0x5C1, "FF FF FF FE 3E"),
    (ErrorReply(1, 0x0027), 0x5C1, "00 27 3E"),  # tables 7-8, 7-12
    (ReadFailed(1), 0x5C1, "80"),  # table 7-4
])
def test_layouts_round_trip(message: ec.Message, can_id: int, data: str) -> None:
    assert wire(message) == (can_id, data)
    role = Role.DEVICE if isinstance(message, (Read, Write, Command)) else Role.HOST
    assert decode(frame(can_id, data), role) == message


def test_two_and_six_byte_frames_are_commands_only_at_command_indexes() -> None:
    assert decode(frame(0x641, "00 83"), Role.DEVICE) == Command(1, 0x83)
    assert decode(frame(0x641, "00 08"), Role.DEVICE) == Read(1, 0x08)
    assert decode(frame(0x641, "01 00 00 00 00 01"), Role.DEVICE) == Command(1, 0x100, 1)
    assert decode(frame(0x641, "01 14 00 00 00 01"), Role.DEVICE) == Write(1, 0x114, 1)  # encoder reset: a write
    assert set(ec.COMMANDS) == {0x83, 0x84, 0xE8, 0x100, 0x14F}


def test_command_of_the_wrong_shape_still_decodes_as_a_command() -> None:
    # the drive answers these with 0x0032 "needs a parameter" / 0x0033 "takes no parameter"
    assert decode(frame(0x641, "01 00"), Role.DEVICE) == Command(1, 0x100)
    assert decode(frame(0x641, "00 83 00 00 00 05"), Role.DEVICE) == Command(1, 0x83, 5)
    assert wire(Command(1, 0x100)) == (0x641, "01 00")
    assert wire(Command(1, 0x83, 5)) == (0x641, "00 83 00 00 00 05")


def test_ids() -> None:
    assert ec.request_id(1) == 0x641 and ec.reply_id(1) == 0x5C1
    assert ec.request_id(127) == 0x6BF and ec.reply_id(127) == 0x63F
    assert ec.decoder_role(0x641) is Role.DEVICE
    assert ec.decoder_role(0x63F) is Role.HOST
    for other in (0x640, 0x5C0, 0x6C0, 0x000, 0x581, 0x700):
        assert ec.decoder_role(other) is None
    # CANopen SDO ids overlap the ranges (0x602 = reply of node 0x42): one protocol per bus
    assert ec.decoder_role(0x602) is Role.HOST
    with pytest.raises(EncodeError):
        ec.request_id(0)
    with pytest.raises(EncodeError):
        ec.reply_id(128)


# ------------------------------------------------------------------------------------ encode errors


@pytest.mark.parametrize("message", [
    Read(0, 2), Read(128, 2), Read(True, 2), Read(1, -1), Read(1, 0x10000), Read(1, 5, 0x10000),
    Write(1, 0x86, 0x80000000), Write(1, 0x86, -0x80000001), Write(1, 0x86, 1.0),  # type: ignore[arg-type]
    Read(1, 0x83), Write(1, 0x100, 1),  # command indexes: send a Command
    Command(1, 0x86), Command(1, 0x100, 1 << 31),
    ValueReply(1, 1 << 31), ErrorReply(1, 0x10000), Ack(0),
])
def test_encode_refuses_out_of_range_fields(message: ec.Message) -> None:
    with pytest.raises(EncodeError):
        encode(message)


def test_encode_refuses_foreign_objects() -> None:
    with pytest.raises(EncodeError):
        encode("00 02")  # type: ignore[arg-type]


# ------------------------------------------------------------------------------------ decode errors


@pytest.mark.parametrize("data", ["", "00", "00 02 00", "00 02 00 01 00", "01 00 00 00 00 00 00",
                                  "00 00 00 00 00 00 00 00 00"])
def test_request_of_wrong_length(data: str) -> None:
    with pytest.raises(ByteCountError):
        decode(frame(0x641, data), Role.DEVICE)


@pytest.mark.parametrize("data", ["", "00 3E", "00 6F 36 47", "00 00 00 00 00 3E", "00 00 00 00 00 00 00 3E"])
def test_reply_of_wrong_length(data: str) -> None:
    with pytest.raises(ByteCountError):
        decode(frame(0x5C1, data), Role.HOST)


@pytest.mark.parametrize("data", ["36", "2E", "00", "00 27 80", "00 6F 36 47 80", "00 6F 36 47 00"])
def test_reply_with_unknown_terminator(data: str) -> None:
    with pytest.raises(FrameError) as info:
        decode(frame(0x5C1, data), Role.HOST)
    assert not isinstance(info.value, ByteCountError)
    assert info.value.data == bytes.fromhex(data)


@pytest.mark.parametrize(("can_id", "role"), [
    (0x641, Role.HOST), (0x5C1, Role.DEVICE), (0x5C0, Role.HOST), (0x640, Role.DEVICE),
    (0x640 + 128, Role.DEVICE), (0x5C0 + 128, Role.HOST), (0x581, Role.HOST), (0x000, Role.DEVICE),
])
def test_wrong_id_range(can_id: int, role: Role) -> None:
    data = "3E" if role is Role.HOST else "00 02"
    with pytest.raises(FrameError, match="not a (reply|request) id"):
        decode(frame(can_id, data), role)


def test_extended_remote_error_and_fd_frames_are_refused() -> None:
    with pytest.raises(FrameError, match="extended"):
        decode(can.Message(arbitration_id=0x5C1, data=b"\x3e", is_extended_id=True), Role.HOST)
    with pytest.raises(FrameError, match="remote"):
        decode(can.Message(arbitration_id=0x641, is_extended_id=False, is_remote_frame=True, dlc=2), Role.DEVICE)
    with pytest.raises(FrameError, match="error"):
        decode(can.Message(arbitration_id=0x5C1, is_extended_id=False, is_error_frame=True), Role.HOST)
    with pytest.raises(FrameError, match="FD"):
        decode(can.Message(arbitration_id=0x5C1, data=b"\x3e", is_extended_id=False, is_fd=True), Role.HOST)


def test_dlc_disagreeing_with_data_is_a_byte_count_error() -> None:
    f = frame(0x641, "00 02")
    f.dlc = 4
    with pytest.raises(ByteCountError, match="DLC"):
        decode(f, Role.DEVICE)


# ------------------------------------------------------------------------------------------ answers


def test_answers_by_node_and_shape() -> None:
    read, write, cmd = Read(3, 0x02), Write(3, 0x86, 0), Command(3, 0x83)
    assert answers(read, ValueReply(3, 5))
    assert not answers(read, Ack(3))
    assert answers(write, Ack(3)) and answers(cmd, Ack(3))
    assert not answers(write, ValueReply(3, 5)) and not answers(cmd, ValueReply(3, 0))
    for request in (read, write, cmd):
        assert answers(request, ErrorReply(3, 0x16))
        assert answers(request, ReadFailed(3))
        for reply in (Ack(4), ValueReply(4, 1), ErrorReply(4, 0x16), ReadFailed(4)):
            assert not answers(request, reply)


def test_messages_are_frozen_and_hashable() -> None:
    m = Write(1, 0x86, 5)
    with pytest.raises(AttributeError):
        m.value = 6  # type: ignore[misc]
    assert len({Read(1, 2), Read(1, 2), Read(1, 2, 0)}) == 2
