"""MKS native codec: framing per function code, both roles, errors, resynchronisation, properties.

Hypothesis properties: (a) every message round-trips byte-exact; (b) valid frames concatenated and
fed byte by byte or in random splits give exactly the original messages; (c) arbitrary bytes (and
frame-like junk) raise only FrameError subclasses, and every message that comes out re-encodes to
bytes found in the input.
"""

from __future__ import annotations

import dataclasses
from itertools import pairwise
from typing import Any

import pytest
from codeckit import h
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from joints.codecs import mks
from joints.codecs.mks import Role
from joints.errors import ChecksumError, EncodeError, FrameError, JointsError

SETTINGS = settings(max_examples=250, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow])

u8 = st.integers(0, 0xFF)
u16 = st.integers(0, 0xFFFF)
u32 = st.integers(0, 0xFFFFFFFF)
i32 = st.integers(-(1 << 31), (1 << 31) - 1)



def decode_all(role: Role, data: bytes, *, flush: bool = True) -> list[Any]:
    codec = mks.MksCodec(role)
    codec.feed(data)
    if flush:
        codec.flush()
    out = []
    while (m := codec.next_message()) is not None:
        out.append(m)
    assert codec.buffered == 0 or not flush
    return out


def decode_one(role: Role, frame: bytes) -> Any:
    msgs = decode_all(role, frame)
    assert len(msgs) == 1, msgs
    return msgs[0]


# ------------------------------------------------------------------------------ checksum


def test_checksum_is_sum8_of_previous_bytes() -> None:
    # Part 4: CRC = (0xFA + 0x01 + 0x80 + 0x00) & 0xFF = 0x17B & 0xFF = 0x7B
    assert mks.checksum(h("FA 01 80 00")) == 0x7B
    assert mks.with_checksum(h("FA 01 80 00")) == h("FA 01 80 00 7B")
    assert mks.checksum_ok(h("FA 01 80 00 7B"))
    assert not mks.checksum_ok(h("FA 01 80 00 7C"))


# ------------------------------------------------------------------------------ encoding


@pytest.mark.parametrize("msg,frame", [
    (mks.ReadEncoderCarry(1), "FA 01 30 2B"),
    (mks.Calibrate(1), "FA 01 80 00 7B"),
    (mks.RunSpeed(1, mks.RunDirection.CCW, 320, 2), "FA 01 F6 01 40 02 34"),
    (mks.RunSpeed(1, mks.RunDirection.CW, 320, 2), "FA 01 F6 81 40 02 B4"),
    (mks.RunRelativePulses(1, mks.RunDirection.CCW, 640, 2, 64000), "FA 01 FD 02 80 02 00 00 FA 00 76"),
    (mks.RunRelativePulses(0x50, mks.RunDirection.CCW, 300, 100, 3200), "FA 50 FD 01 2C 64 00 00 0C 80 64"),
    (mks.RunAbsolutePulses(1, 600, 2, -0x4000), "FA 01 FE 02 58 02 FF FF C0 00 13"),
    (mks.RunAbsoluteAxis(1, 600, 2, 0x4000), "FA 01 F5 02 58 02 00 00 40 00 8C"),
    (mks.SaveCleanSpeedMode(1, 0xC8), "FA 01 FF C8 C2"),
    (mks.EncoderCarryReply(1, -1, 0x2269), "FB 01 30 FF FF FF FF 22 69 B3"),
    (mks.RunReply(1, 0xFD, mks.RunStatus.COMPLETE), "FB 01 FD 02 FB"),
])
def test_encode_manual_frames(msg: Any, frame: str) -> None:
    assert mks.encode(msg) == h(frame)
    role = Role.HOST if frame.startswith("FB") else Role.DEVICE
    assert decode_one(role, h(frame)) == msg


def test_frame_lengths_follow_the_function_code() -> None:
    """Data length per code, per direction: the frame length table of the module docstring."""
    expected_request = {**{c: 0 for c in (0x30, 0x31, 0x32, 0x33, 0x34, 0x39, 0x3A, 0x3B, 0x3D, 0x3E, 0x3F, 0x40,
                                          0x41, 0x47, 0x48, 0x91, 0x92, 0xF1, 0xF7, 0x35)},
                        **{c: 1 for c in (0x80, 0x82, 0x84, 0x85, 0x86, 0x87, 0x88, 0x89, 0x8A, 0x8B, 0x8D, 0x8E,
                                          0x8F, 0x9B, 0x9E, 0xF3, 0xFF)},
                        0x83: 2, 0x8C: 2, 0xF6: 3, 0x98: 4, 0x9A: 4, 0x90: 5, 0x46: 34, 0x01: 3,
                        **{c: 7 for c in (0x94, 0xF4, 0xF5, 0xFD, 0xFE)},
                        0x36: 1, 0x9D: 5, 0x95: 3, 0x4A: 1, 0x4B: 0, 0x50: 1,
                        0x96: 8, 0x97: 8, 0x00: 1, 0x42: 0, 0x99: 5, 0x9F: 1}  # V1.0.6-V1.0.9: tests/codecs/test_mks_v109_commands.py
    assert dict(mks.REQUEST_DATA_LENGTH) == expected_request
    expected_reply = {c: 1 for c in expected_request if c != 0x00} | {0x30: 6, 0x31: 6, 0x32: 2, 0x33: 4, 0x39: 4, 0x40: 4,
                                                         0x47: 34, 0x48: 28, 0x01: 2, 0x35: 6}
    assert dict(mks.REPLY_DATA_LENGTH) == expected_reply
    assert max(expected_request.values()) + 4 == mks.MAX_DOWNLINK_FRAME
    assert max(expected_reply.values()) + 4 == mks.MAX_UPLINK_FRAME


def test_long_packet_is_52_bytes_and_pads_missing_slots() -> None:
    pkt = mks.LongPacket((mks.RunSpeed(1, mks.RunDirection.CCW, 50, 10),))
    assert len(pkt.commands) == 5 and pkt.commands[1:] == (None,) * 4
    frame = mks.encode(pkt)
    assert len(frame) == mks.LONG_PACKET_LENGTH == 52
    assert frame[:11] == h("FC 01 F6 00 32 0A 00 00 00 00 00") and frame[11:51] == bytes(40)
    assert decode_one(Role.DEVICE, frame) == pkt


def test_long_packet_first_slot_for_an_address_wins() -> None:
    first, second = mks.QueryStatus(2), mks.EmergencyStop(2)
    pkt = mks.LongPacket((mks.QueryStatus(1), first, second, mks.GoHome(0x50)))
    assert pkt.command_for(2) is first
    assert pkt.command_for(3, 0x50) == mks.GoHome(0x50)
    assert pkt.command_for(9) is None


def test_long_packet_slot_with_unknown_code_keeps_its_8_bytes() -> None:
    unknown = mks.UnknownRequest(7, 0x51, bytes(range(1, 9)))
    pkt = mks.LongPacket((mks.QueryStatus(3), unknown))
    assert decode_one(Role.DEVICE, mks.encode(pkt)) == pkt


@pytest.mark.parametrize("bad", [
    mks.RunSpeed(1, mks.RunDirection.CCW, 0x1000, 2),  # 12-bit speed
    mks.RunSpeed(1, 2, 100, 2),  # type: ignore[arg-type]
    mks.RunSpeed(1, mks.RunDirection.CCW, 100, 256),
    mks.RunRelativePulses(1, mks.RunDirection.CW, 100, 2, -1),
    mks.RunRelativePulses(1, mks.RunDirection.CW, 100, 2, 1 << 32),
    mks.RunAbsoluteAxis(1, 100, 2, 1 << 31),
    mks.RunAbsolutePulses(1, 1.5, 2, 0),  # type: ignore[arg-type]
    mks.ReadSpeed(256),
    mks.ReadSpeed(True),
    mks.SetSubdivision(1, 0),
    mks.SetSubdivision(1, 257),
    mks.SetWorkingCurrent(1, 0x10000),
    mks.SetWorkMode(1, -1),
    mks.SetReply(1, 0xFD, mks.SetStatus.SUCCESS),  # a run command is answered by RunReply
    mks.RunReply(1, 0x82, mks.RunStatus.STARTED),
    mks.SetReply(1, 0x82, 7),  # type: ignore[arg-type]
    mks.MotorStatusReply(1, 9),  # type: ignore[arg-type]
    mks.EnPinReply(1, 2),  # type: ignore[arg-type]
    mks.EncoderAdditionReply(1, 1 << 47),
    mks.UnknownRequest(1, 0x30, b""),  # a known code
    mks.UnknownRequest(1, 0x51, bytes(8)),  # longer than any downlink frame
    mks.LongPacket(tuple(mks.QueryStatus(i) for i in range(6))),
    mks.LongPacket((mks.UnknownRequest(0, 0x00, bytes(8)),)),  # reads as an empty slot
    mks.LongPacket((mks.UnknownRequest(1, 0x51, bytes(9)),)),
    "not a message",
])
def test_encode_refuses_what_the_wire_cannot_carry(bad: Any) -> None:
    with pytest.raises(EncodeError):
        mks.encode(bad)


def test_long_packet_cannot_nest() -> None:
    inner = mks.LongPacket(())
    with pytest.raises(EncodeError):
        mks.encode(mks.LongPacket((inner,)))  # type: ignore[arg-type]


def test_subdivision_256_travels_as_zero() -> None:
    assert mks.encode(mks.SetSubdivision(1, 256)) == mks.with_checksum(h("FA 01 84 00"))
    assert decode_one(Role.DEVICE, mks.with_checksum(h("FA 01 84 00"))) == mks.SetSubdivision(1, 256)
    assert decode_one(Role.DEVICE, mks.with_checksum(h("FA 01 84 10"))) == mks.SetSubdivision(1, 16)


# ------------------------------------------------------------------------------ typed fields


def test_packed_fields_decode_to_typed_values() -> None:
    m = decode_one(Role.DEVICE, h("FA 01 FD 82 80 08 00 30 D4 00 06"))
    assert m == mks.RunRelativePulses(1, mks.RunDirection.CW, 640, 8, 3_200_000)
    assert isinstance(m.direction, mks.RunDirection) and not m.is_stop
    assert decode_one(Role.DEVICE, h("FA 01 FD 00 00 00 00 00 00 00 F8")).is_stop
    add = decode_one(Role.HOST, mks.encode(mks.EncoderAdditionReply(1, -0x10)))
    assert add.value == -0x10
    carry = decode_one(Role.HOST, h("FB 01 30 FF FF FF FF 22 69 B3"))
    assert (carry.carry, carry.value, carry.addition) == (-1, 0x2269, 0x2269 - 0x4000)
    err = mks.AngleErrorReply(1, 51200 // 360 * 9)
    assert err.degrees == pytest.approx(9 * 142 * 360 / 51200)
    io = mks.IoStatusReply(1, 0b0101)
    assert (io.in_1, io.in_2, io.out_1, io.out_2) == (True, False, True, False)


def test_run_replies_share_one_type_and_completion_is_the_status() -> None:
    started = decode_one(Role.HOST, h("FB 01 FD 01 FA"))
    done = decode_one(Role.HOST, h("FB 01 FD 02 FB"))
    limit = decode_one(Role.HOST, mks.with_checksum(h("FB 01 F5 03")))
    assert type(started) is type(done) is type(limit) is mks.RunReply
    assert [r.status for r in (started, done, limit)] == [mks.RunStatus.STARTED, mks.RunStatus.COMPLETE,
                                                           mks.RunStatus.END_LIMIT_STOP]
    assert [r.is_completion for r in (started, done, limit)] == [False, True, True]
    assert not decode_one(Role.HOST, mks.with_checksum(h("FB 01 FD 00"))).is_completion
    home = decode_one(Role.HOST, mks.with_checksum(h("FB 01 91 02")))
    assert home == mks.RunReply(1, 0x91, mks.RunStatus.COMPLETE)
    cal = [decode_one(Role.HOST, mks.with_checksum(bytes((0xFB, 1, 0x80, s)))) for s in (0, 1, 2)]
    assert [c.is_completion for c in cal] == [False, True, True]


def test_every_function_code_has_a_request_and_a_reply_type() -> None:
    # (0x00's reply is headed by the code of the parameter it read: tests/codecs/test_mks_v109_commands.py)
    assert set(mks.REQUEST_TYPES) - {0x00} == set(mks.REPLY_TYPES)
    for code, cls in mks.REQUEST_TYPES.items():
        assert getattr(cls, "function") == code  # noqa: B009
    for code in mks.SET_REPLY_FUNCTIONS:
        assert mks.REPLY_TYPES[code] is mks.SetReply
    for code in mks.RUN_REPLY_FUNCTIONS:
        assert mks.REPLY_TYPES[code] is mks.RunReply
    assert mks.RUN_REPLY_FUNCTIONS == {0x91, 0xF4, 0xF5, 0xF6, 0xFD, 0xFE, 0xFF}


# ------------------------------------------------------------------------------ decoding errors


def test_checksum_error_drops_one_byte_then_resynchronises() -> None:
    good = h("FB 01 FD 01 FA")
    codec = mks.MksCodec(Role.HOST)
    codec.feed(h("FB 01 FD 01 00") + good)  # (a last byte FB would start "FB FB 01 ..": a 0x01 reply's head)
    with pytest.raises(ChecksumError) as info:
        codec.next_message()
    assert info.value.data == h("FB 01 FD 01 00")
    assert codec.next_message() == mks.RunReply(1, 0xFD, mks.RunStatus.STARTED)
    assert codec.next_message() is None and codec.buffered == 0


@pytest.mark.parametrize("role,frame", [
    (Role.HOST, "FB 01 82 02"),  # SetStatus has no 2
    (Role.HOST, "FB 01 FD 04"),  # RunStatus has no 4
    (Role.HOST, "FB 01 F1 07"),  # MotorStatus 0..6
    (Role.HOST, "FB 01 3A 02"),  # En pin 0/1
    (Role.HOST, "FB 01 3E 05"),  # protection 0/1
    (Role.HOST, "FB 01 80 03"),  # calibration 0..2
    (Role.DEVICE, "FA 01 F6 41 40 02"),  # reserved bit b6 set
    (Role.DEVICE, "FA 01 FD 10 00 02 00 00 00 01"),  # reserved bit b4 set
    (Role.DEVICE, "FA 01 80 01"),  # calibrate data byte must be 00
])
def test_checksum_valid_frame_with_undocumented_fields_is_consumed_and_rejected(role: Role, frame: str) -> None:
    bad = mks.with_checksum(h(frame))
    follow = h("FB 01 F6 01 F3") if role is Role.HOST else h("FA 01 30 2B")
    codec = mks.MksCodec(role)
    codec.feed(bad + follow)
    with pytest.raises(FrameError) as info:
        codec.next_message()
    assert not isinstance(info.value, ChecksumError)
    assert info.value.data == bad
    nxt = codec.next_message()
    assert nxt is not None and mks.encode(nxt) == follow


def test_long_packet_with_nonzero_padding_is_rejected() -> None:
    frame = bytearray(mks.encode(mks.LongPacket((mks.QueryStatus(1),))))
    frame[5] = 0x01  # padding after "01 F1"
    frame[-1] = mks.checksum(frame[:-1])
    with pytest.raises(FrameError, match="padding"):
        decode_all(Role.DEVICE, bytes(frame))


def test_truncated_frame_at_silence() -> None:
    codec = mks.MksCodec(Role.DEVICE)
    codec.feed(h("FA 01 FD 02 80 05 00 09 C4 00"))  # printed without checksum (manual 7.5)
    assert codec.next_message() is None  # waits for the 11th byte
    codec.flush()
    with pytest.raises(FrameError, match="truncated"):
        codec.next_message()
    assert codec.buffered == 0 and codec.next_message() is None


def test_silence_skips_a_truncated_head_to_a_later_valid_frame() -> None:
    # 9 bytes: the 0x30 head announces 10, so at silence the codec looks for a later valid frame
    assert decode_all(Role.HOST, h("FB 01 30 00") + h("FB 01 F6 01 F3")) == [
        mks.RunReply(1, 0xF6, mks.RunStatus.STARTED)]


def test_a_frame_completing_a_truncated_head_costs_a_checksum_error_then_resyncs() -> None:
    codec = mks.MksCodec(Role.HOST)
    codec.feed(h("FB 01 30 00 00") + h("FB 01 F6 01 F3"))  # exactly 10 bytes: looks complete
    with pytest.raises(ChecksumError):
        codec.next_message()
    assert codec.next_message() == mks.RunReply(1, 0xF6, mks.RunStatus.STARTED)


def test_garbage_and_other_direction_are_skipped() -> None:
    garbage = h("00 FF 13 FA 37 FC")
    reply = h("FB 01 30 FF FF FF FF 22 69 B3")
    request = h("FA 01 30 2B")
    codec = mks.MksCodec(Role.HOST)
    codec.feed(garbage + request + reply)
    assert codec.next_message() == mks.EncoderCarryReply(1, -1, 0x2269)
    assert codec.discarded == len(garbage) + len(request)
    dev = decode_all(Role.DEVICE, h("00 11 FB 01 F6 01 F3") + request)
    assert dev == [mks.ReadEncoderCarry(1)]


def test_echo_is_skipped_once() -> None:
    request = h("FA 01 FD 02 80 05 00 09 C4 00 4C")
    codec = mks.MksCodec(Role.HOST)
    codec.expect_echo(request)
    for b in request + h("FB 01 FD 01 FA"):
        codec.feed(bytes((b,)))
    assert codec.next_message() == mks.RunReply(1, 0xFD, mks.RunStatus.STARTED)
    assert codec.next_message() is None


def test_clear_drops_buffered_bytes() -> None:
    codec = mks.MksCodec(Role.HOST)
    codec.feed(h("FB 01 30 00"))
    codec.clear()
    assert codec.buffered == 0 and codec.discarded == 4
    assert codec.next_message() is None


# ------------------------------------------------------------------------------ unknown codes


def test_device_frames_unknown_codes_by_their_checksum() -> None:
    frame = mks.with_checksum(h("FA 01 51 11 22"))
    assert decode_all(Role.DEVICE, frame + h("FA 01 F1 EC")) == [
        mks.UnknownRequest(1, 0x51, h("11 22")), mks.QueryStatus(1)]
    assert mks.encode(mks.UnknownRequest(1, 0x51, h("11 22"))) == frame


def test_device_waits_for_an_unknown_code_then_gives_up_at_eleven_bytes() -> None:
    codec = mks.MksCodec(Role.DEVICE)
    codec.feed(h("FA 01 51 00 01"))  # no checksum match yet: might still come
    assert codec.next_message() is None and codec.buffered == 5
    codec.feed(h("02 03 04 05 06 07"))  # 11 bytes, no length 4..11 matched: garbage
    assert codec.next_message() is None
    assert codec.discarded >= 1


def test_device_drops_unknown_code_at_silence() -> None:
    codec = mks.MksCodec(Role.DEVICE)
    codec.feed(h("FA 01 51 00 01"))
    codec.flush()
    assert codec.next_message() is None
    assert codec.buffered == 0 and codec.discarded == 5


def test_host_skips_unknown_codes_without_waiting() -> None:
    codec = mks.MksCodec(Role.HOST)
    codec.feed(h("FB 01 51") + h("FB 01 F6 01 F3"))
    assert codec.next_message() == mks.RunReply(1, 0xF6, mks.RunStatus.STARTED)
    assert codec.discarded == 3


# ------------------------------------------------------------------------------ strategies

_FIELD = {
    "address": u8,
    "current": u16,
    "reverse_angle": u32,
    "microsteps": st.integers(1, 256),
    "pulses": u32,
    "abs_pulses": i32,
    "rel_axis": i32,
    "abs_axis": i32,
    "times": u32,
    "code": u8,
    "params": st.binary(min_size=mks.ALL_PARAMETERS_SIZE, max_size=mks.ALL_PARAMETERS_SIZE),
}
_WIDE_SPEED = {mks.SetHomeParameters, mks.RunAbsolutePulses, mks.RunRelativeAxis, mks.RunAbsoluteAxis}
#: fields of the V1.0.6-V1.0.9 commands narrower or wider than a byte (tests/codecs/test_mks_v109_commands.py)
_NARROW: dict[tuple[type, str], st.SearchStrategy[Any]] = {
    **{(mks.WriteIoPort, n): st.integers(0, 2) for n in ("out2_mask", "out1_mask")},
    **{(mks.WriteIoPort, n): st.integers(0, 1) for n in ("out2", "out1")},
    **{(mks.SetPositionErrorProtection, n): st.integers(0, 1) for n in ("en_zero_return", "enable")},
    **{(mks.SetPositionErrorProtection, n): u16 for n in ("time", "errors")},
    (mks.SetPositionThreshold, "values"): u16,
    (mks.SetWorkingCurrent, "unsaved"): st.integers(0, 1),
    (mks.GoHome, "mode"): st.integers(0, 1),
    (mks.UserId, "id"): st.integers(0, 0xFFFFFFFF),  # (the read's short frame is tested on its own)
}


def _request_strategy(cls: type) -> st.SearchStrategy[Any]:
    kwargs: dict[str, st.SearchStrategy[Any]] = {}
    for f in dataclasses.fields(cls):
        if (cls, f.name) in _NARROW:
            kwargs[f.name] = _NARROW[cls, f.name]
        elif f.name == "direction" and cls in (mks.RunSpeed, mks.RunRelativePulses):
            kwargs[f.name] = st.sampled_from(mks.RunDirection)
        elif f.name == "times" and cls is mks.SetTimedReturn:
            kwargs[f.name] = u16
        elif f.name == "speed":
            kwargs[f.name] = (u16 if cls in _WIDE_SPEED else u8 if cls is mks.SetZeroMode
                              else st.integers(0, mks.SPEED_FIELD_MAX))
        else:
            kwargs[f.name] = _FIELD.get(f.name, u8)
    return st.builds(cls, **kwargs)


requests = st.one_of([_request_strategy(c) for c in mks.REQUEST_TYPES.values()])
#: what fits a 10-byte long-packet slot (0x46's 34 data bytes do not)
slot_requests = st.one_of([_request_strategy(c) for c in mks.REQUEST_TYPES.values() if c is not mks.WriteAllParameters])
#: codes no request type of the codec has (0x46-0x48 became known with V1.0.6)
unknown_codes = st.integers(0x42, 0x7F).filter(lambda c: c not in mks.REQUEST_TYPES)
long_packets = st.builds(
    lambda cmds: mks.LongPacket(tuple(cmds)),
    st.lists(st.none() | slot_requests | st.builds(mks.UnknownRequest, u8, unknown_codes,
                                              st.binary(min_size=8, max_size=8)), max_size=5),
)
downlink = st.one_of(requests, long_packets)

replies = st.one_of(
    st.builds(mks.EncoderCarryReply, u8, i32, u16),
    st.builds(mks.EncoderAdditionReply, u8, st.integers(-(1 << 47), (1 << 47) - 1)),
    st.builds(mks.SpeedReply, u8, st.integers(-0x8000, 0x7FFF)),
    st.builds(mks.PulsesReply, u8, i32),
    st.builds(mks.IoStatusReply, u8, u8),
    st.builds(mks.AngleErrorReply, u8, i32),
    st.builds(mks.EnPinReply, u8, st.booleans()),
    st.builds(mks.GoBackToZeroStatusReply, u8, st.sampled_from(mks.GoBackToZeroStatus)),
    st.builds(mks.ProtectionStateReply, u8, st.booleans()),
    st.builds(mks.CalibrationReply, u8, st.sampled_from(mks.CalibrationStatus)),
    st.builds(mks.MotorStatusReply, u8, st.sampled_from(mks.MotorStatus)),
    st.builds(mks.SetReply, u8, st.sampled_from(sorted(mks.SET_REPLY_FUNCTIONS)),
              st.sampled_from((mks.SetStatus.FAIL, mks.SetStatus.SUCCESS))),
    st.builds(mks.SetReply, u8, st.just(0x83), st.just(mks.SetStatus.SUCCESS_UNSAVED)),  # 0x83 only (V1.0.7)
    st.builds(mks.RunReply, u8, st.sampled_from(sorted(mks.RUN_REPLY_FUNCTIONS)), st.sampled_from(mks.RunStatus)),
    st.builds(mks.VersionReply, u8, u32),
    st.builds(mks.TimedReturnReply, u8, u8, st.sampled_from(mks.SetStatus)),
    st.builds(mks.RawEncoderReply, u8, st.integers(-(1 << 47), (1 << 47) - 1)),
    st.builds(mks.AllParametersReply, u8, st.binary(min_size=mks.ALL_PARAMETERS_SIZE,
                                                   max_size=mks.ALL_PARAMETERS_SIZE)),
    st.builds(mks.AllStatusReply, u8, st.binary(min_size=mks.ALL_STATUS_SIZE, max_size=mks.ALL_STATUS_SIZE)),
)


def _split(data: st.DataObject, n: int) -> list[int]:
    cuts = data.draw(st.lists(st.integers(0, n), max_size=12), label="cuts")
    return sorted(set(cuts) | {0, n})


def _run(role: Role, stream: bytes, cuts: list[int]) -> tuple[list[Any], list[FrameError]]:
    codec = mks.MksCodec(role)
    msgs: list[Any] = []
    errors: list[FrameError] = []

    def drain() -> None:
        for _ in range(4 * len(stream) + 10):
            try:
                m = codec.next_message()
            except JointsError as exc:  # anything else fails the test
                assert isinstance(exc, FrameError)
                errors.append(exc)
                continue
            if m is None:
                return
            msgs.append(m)
        raise AssertionError("codec made no progress")

    for a, b in pairwise(cuts):
        codec.feed(stream[a:b])
        drain()
    codec.flush()
    drain()
    assert codec.buffered == 0
    return msgs, errors


# ------------------------------------------------------------------------------ properties


@SETTINGS
@given(msg=downlink)
def test_requests_round_trip(msg: Any) -> None:
    frame = mks.encode(msg)
    assert mks.checksum_ok(frame)
    assert decode_one(Role.DEVICE, frame) == msg


@SETTINGS
@given(msg=replies)
def test_replies_round_trip(msg: Any) -> None:
    frame = mks.encode(msg)
    assert frame[0] == mks.HEAD_UPLINK and len(frame) == 4 + mks.REPLY_DATA_LENGTH[frame[2]]
    assert decode_one(Role.HOST, frame) == msg


@SETTINGS
@given(msgs=st.lists(downlink, max_size=6), data=st.data())
def test_device_stream_in_random_splits(msgs: list[Any], data: st.DataObject) -> None:
    stream = b"".join(mks.encode(m) for m in msgs)
    got, errors = _run(Role.DEVICE, stream, _split(data, len(stream)))
    assert got == msgs and not errors


@SETTINGS
@given(msgs=st.lists(replies, max_size=8), data=st.data())
def test_host_stream_in_random_splits(msgs: list[Any], data: st.DataObject) -> None:
    stream = b"".join(mks.encode(m) for m in msgs)
    got, errors = _run(Role.HOST, stream, _split(data, len(stream)))
    assert got == msgs and not errors


@SETTINGS
@given(msgs=st.lists(st.one_of(downlink, replies), min_size=1, max_size=6))
def test_byte_by_byte_equals_all_at_once(msgs: list[Any]) -> None:
    stream = b"".join(mks.encode(m) for m in msgs)
    for role in (Role.HOST, Role.DEVICE):
        whole, _ = _run(role, stream, [0, len(stream)])
        bytewise, _ = _run(role, stream, list(range(len(stream) + 1)))
        assert bytewise == whole


replies_types = (mks.EncoderCarryReply, mks.EncoderAdditionReply, mks.SpeedReply, mks.PulsesReply,
                 mks.IoStatusReply, mks.AngleErrorReply, mks.EnPinReply, mks.GoBackToZeroStatusReply,
                 mks.ProtectionStateReply, mks.CalibrationReply, mks.MotorStatusReply, mks.SetReply, mks.RunReply,
                 mks.VersionReply, mks.AllParametersReply, mks.AllStatusReply, mks.TimedReturnReply,
                 mks.RawEncoderReply)

ROLES = st.sampled_from([Role.HOST, Role.DEVICE])
frame_like = st.lists(
    st.one_of(
        st.binary(max_size=16),
        downlink.map(mks.encode),
        replies.map(mks.encode),
        st.tuples(st.sampled_from([0xFA, 0xFB, 0xFC]), u8, u8, st.binary(max_size=9))
        .map(lambda t: mks.with_checksum(bytes(t[:3]) + t[3])),
    ),
    max_size=8,
).map(b"".join)


def _assert_reencodes_into(msg: Any, stream: bytes) -> None:
    frame = mks.encode(msg)
    assert mks.checksum_ok(frame)
    assert frame in stream


@SETTINGS
@given(stream=st.binary(max_size=300), role=ROLES, data=st.data())
def test_random_bytes_only_raise_frame_errors(stream: bytes, role: Role, data: st.DataObject) -> None:
    msgs, _ = _run(role, stream, _split(data, len(stream)))
    for m in msgs:
        _assert_reencodes_into(m, stream)


@SETTINGS
@given(stream=frame_like, role=ROLES, data=st.data())
def test_frame_like_junk_only_raises_frame_errors(stream: bytes, role: Role, data: st.DataObject) -> None:
    msgs, _ = _run(role, stream, _split(data, len(stream)))
    for m in msgs:
        _assert_reencodes_into(m, stream)
        assert isinstance(m, replies_types) == (role is Role.HOST)
