"""Modbus RTU codec unit tests: encoding, range checks, framing, resync, echo, errors."""

from __future__ import annotations

import pytest
from codeckit import drain, h

from joints.codecs import modbus as mb
from joints.codecs.crc import append_crc, crc16_modbus, crc_ok
from joints.errors import (
    ByteCountError,
    ChecksumError,
    EncodeError,
    FrameError,
    JointsError,
    PeerProtocolError,
    RequestError,
)

# ------------------------------------------------------------------------------------- CRC


def test_crc16_modbus_check_value() -> None:
    # CRC-16/MODBUS catalogue check value (CRC RevEng): "123456789" -> 0x4B37
    assert crc16_modbus(b"123456789") == 0x4B37
    assert crc16_modbus(b"") == 0xFFFF
    frame = append_crc(h("02 03 00 66 00 02"))
    assert frame == h("02 03 00 66 00 02 24 27")  # eRob manual 5.x, low byte first
    assert crc_ok(frame) and crc16_modbus(frame) == 0
    assert not crc_ok(h("02 03 00 66 00 02 27 24"))
    assert not crc_ok(b"\x00\x00")


# --------------------------------------------------------------------------------- encoding

ENCODED = [
    # the classic Modbus over serial line example: read 10 holding registers from slave 1
    (mb.ReadHoldingRegisters(1, 0x0000, 10), "01 03 00 00 00 0A C5 CD"),
    (mb.ReadHoldingRegisters(2, 0x0066, 2), "02 03 00 66 00 02 24 27"),
    (mb.ReadInputRegisters(1, 0x0030, 3), "01 04 00 30 00 03 B0 04"),  # MKS 8.1.1
    (mb.WriteSingleRegister(2, 0x0040, 3), "02 06 00 40 00 03 C8 2C"),
    (mb.WriteSingleRegisterReply(2, 0x0040, 3), "02 06 00 40 00 03 C8 2C"),
    (
        mb.WriteMultipleRegisters(2, 0x0043, (0x0007, 0xA120)),
        "02 10 00 43 00 02 04 00 07 A1 20 71 47",
    ),
    (mb.WriteMultipleRegistersReply(2, 0x0043, 2), "02 10 00 43 00 02 B0 2F"),
    (mb.ReadRegistersReply(2, 3, (0x0007, 0xA11F)), "02 03 04 00 07 A1 1F 40 AA"),
    (mb.ReadRegistersReply(2, 3, (1,)), "02 03 02 00 01 3D 84"),
]


@pytest.mark.parametrize(("message", "hex_text"), ENCODED, ids=[f"{type(m).__name__}-{x[:8]}" for m, x in ENCODED])
def test_encode_known_frames(message: mb.Message, hex_text: str) -> None:
    assert mb.encode(message) == h(hex_text)
    assert mb.ModbusRtuCodec.encode(message) == h(hex_text)
    assert mb.encode_pdu(message) == h(hex_text)[1:-2]


def test_encode_exception_reply_and_unsupported_request() -> None:
    exc = mb.ExceptionReply(2, 3, 2)
    frame = mb.encode(exc)
    assert frame[:3] == h("02 83 02") and len(frame) == 5 and crc_ok(frame)
    assert exc.text == "illegal data address"
    assert mb.ExceptionReply(1, 6, 0x7F).text == "unknown exception"

    unsupported = mb.UnsupportedRequest(1, 0x01, h("00 00 00 0A"))
    assert mb.encode(unsupported) == append_crc(h("01 01 00 00 00 0A"))


def test_encode_empty_read_reply_and_limits() -> None:
    assert mb.encode(mb.ReadRegistersReply(1, 3, ())) == append_crc(h("01 03 00"))
    big = mb.ReadRegistersReply(1, 4, tuple(range(mb.MAX_READ)))
    frame = mb.encode(big)
    assert len(frame) == 5 + 2 * mb.MAX_READ and frame[2] == 2 * mb.MAX_READ
    write = mb.WriteMultipleRegisters(1, 0, tuple(range(mb.MAX_WRITE)))
    assert len(mb.encode(write)) == 9 + 2 * mb.MAX_WRITE
    assert len(mb.encode(mb.ReadHoldingRegisters(255, 0xFFFF, mb.MAX_READ))) == 8
    assert mb.encode(mb.WriteSingleRegister(0, 0xFFFF, 0xFFFF))[:6] == h("00 06 FF FF FF FF")


BAD_MESSAGES = [
    pytest.param(mb.ReadHoldingRegisters(256, 0, 1), id="slave-256"),
    pytest.param(mb.ReadHoldingRegisters(-1, 0, 1), id="slave-negative"),
    pytest.param(mb.WriteSingleRegister(300, 0, 1), id="write-slave-300"),
    pytest.param(mb.ReadHoldingRegisters(1, 0x10000, 1), id="address-0x10000"),
    pytest.param(mb.ReadInputRegisters(1, -1, 1), id="address-negative"),
    pytest.param(mb.WriteSingleRegister(1, 0x10000, 0), id="write-address-0x10000"),
    pytest.param(mb.WriteMultipleRegisters(1, -5, (1,)), id="fc16-address-negative"),
    pytest.param(mb.ReadHoldingRegisters(1, 0, 0), id="read-count-0"),
    pytest.param(mb.ReadHoldingRegisters(1, 0, mb.MAX_READ + 1), id="read-count-126"),
    pytest.param(mb.ReadInputRegisters(1, 0, -1), id="read-input-count-negative"),
    pytest.param(mb.WriteSingleRegister(1, 0, 0x10000), id="value-0x10000"),
    pytest.param(mb.WriteSingleRegister(1, 0, -1), id="value-negative"),
    pytest.param(mb.WriteSingleRegister(1, 0, True), id="value-bool"),
    pytest.param(mb.WriteSingleRegister(1, 0, 1.0), id="value-float"),  # type: ignore[arg-type]
    pytest.param(mb.WriteMultipleRegisters(1, 0, ()), id="fc16-count-0"),
    pytest.param(mb.WriteMultipleRegisters(1, 0, (0,) * (mb.MAX_WRITE + 1)), id="fc16-count-124"),
    pytest.param(mb.WriteMultipleRegisters(1, 0, (1, 0x10000)), id="fc16-value-0x10000"),
    pytest.param(mb.WriteMultipleRegisters(1, 0, (-1,)), id="fc16-value-negative"),
    pytest.param(mb.ReadRegistersReply(1, 3, (0,) * (mb.MAX_READ + 1)), id="reply-126-values"),
    pytest.param(mb.ReadRegistersReply(1, 3, (0x10000,)), id="reply-value-0x10000"),
    pytest.param(mb.ExceptionReply(1, 3, 256), id="exception-code-256"),
    pytest.param(mb.WriteMultipleRegistersReply(1, 0, 0x10000), id="fc16-reply-count"),
]


@pytest.mark.parametrize("message", BAD_MESSAGES)
def test_encode_error_for_out_of_range_fields(message: mb.Message) -> None:
    with pytest.raises(EncodeError) as info:
        mb.encode(message)
    assert isinstance(info.value, RequestError) and isinstance(info.value, ValueError)
    assert str(info.value)  # says what was expected


def test_encode_error_for_non_message() -> None:
    with pytest.raises(EncodeError):
        mb.encode_pdu("not a message")  # type: ignore[arg-type]


# ------------------------------------------------------------------------------- decoding

REQUESTS: list[mb.Message] = [
    mb.ReadHoldingRegisters(2, 0x0066, 2),
    mb.WriteMultipleRegisters(2, 0x0043, (0x0007, 0xA120)),
    mb.ReadInputRegisters(1, 0x0030, 3),
    mb.WriteSingleRegister(2, 0x0040, 3),
    mb.UnsupportedRequest(1, 0x01, h("00 00 00 0A")),
    mb.WriteMultipleRegisters(17, 0xFFF0, tuple(range(0xFF00, 0xFF00 + mb.MAX_WRITE))),
    mb.UnsupportedRequest(1, 0x0F, h("00 13 00 0A 02 CD 01")),  # FC15 write multiple coils
    mb.ReadHoldingRegisters(0, 0, 1),
]
REPLIES: list[mb.Message] = [
    mb.ReadRegistersReply(2, 3, (0x0007, 0xA11F)),
    mb.WriteSingleRegisterReply(2, 0x0040, 3),
    mb.WriteMultipleRegistersReply(2, 0x0043, 2),
    mb.ExceptionReply(2, 3, 2),
    mb.ReadRegistersReply(1, 4, tuple(range(mb.MAX_READ))),
    mb.ReadRegistersReply(9, 3, ()),
    mb.ExceptionReply(1, 16, 4),
]


@pytest.mark.parametrize(
    ("role", "messages"), [(mb.Role.DEVICE, REQUESTS), (mb.Role.HOST, REPLIES)], ids=["device", "host"]
)
def test_byte_by_byte_feeding_of_concatenated_frames(role: mb.Role, messages: list[mb.Message]) -> None:
    stream = b"".join(mb.encode(m) for m in messages)
    whole = mb.ModbusRtuCodec(role)
    whole.feed(stream)
    assert drain(whole) == (messages, [])

    codec = mb.ModbusRtuCodec(role)
    got: list[mb.Message] = []
    for i in range(len(stream)):
        codec.feed(stream[i : i + 1])
        got += drain(codec)[0]
    assert got == messages
    assert codec.buffered == 0 and codec.discarded == 0


@pytest.mark.parametrize("chunk", [2, 3, 5, 7, 13])
def test_fixed_chunk_feeding(chunk: int) -> None:
    stream = b"".join(mb.encode(m) for m in REQUESTS)
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    got: list[mb.Message] = []
    for i in range(0, len(stream), chunk):
        codec.feed(stream[i : i + chunk])
        msgs, errors = drain(codec)
        assert not errors
        got += msgs
    assert got == REQUESTS


def test_exception_reply_decode() -> None:
    frame = mb.encode(mb.ExceptionReply(2, 3, 2))
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.expect_reply_to(mb.ReadHoldingRegisters(2, 0x0200, 1))
    codec.feed(frame)
    msg = codec.next_message()
    assert msg == mb.ExceptionReply(slave=2, function=3, code=2)
    assert isinstance(msg, mb.ExceptionReply) and msg.text == "illegal data address"
    assert codec.next_message() is None
    # FC16 "illegal data value"
    codec.feed(append_crc(h("01 90 03")))
    assert codec.next_message() == mb.ExceptionReply(1, 0x10, 3)


def test_read_input_registers_reply() -> None:
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.expect_reply_to(mb.ReadInputRegisters(1, 0x30, 3))
    codec.feed(append_crc(h("01 04 06 00 01 00 02 FF FF")))
    assert codec.next_message() == mb.ReadRegistersReply(1, 4, (1, 2, 0xFFFF))


def test_device_role_unsupported_request_fc01() -> None:
    frame = append_crc(h("01 01 00 13 00 25"))  # read 37 coils from 0x13
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    codec.feed(frame)
    msg = codec.next_message()
    assert msg == mb.UnsupportedRequest(slave=1, function=0x01, pdu=h("00 13 00 25"))
    assert mb.encode(msg) == frame


def test_device_role_unknown_function_code_is_framed_by_its_crc() -> None:
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    codec.feed(append_crc(h("01 2B 0E 01 00")))  # FC43 encapsulated interface: a server answers exception 01
    codec.flush()
    msgs, _ = drain(codec)
    assert msgs == [mb.UnsupportedRequest(1, 0x2B, h("0E 01 00"))]
    assert codec.buffered == 0 and codec.discarded == 0


def test_host_role_does_not_decode_requests_as_replies_of_other_kinds() -> None:
    # a host hears an FC06 request (e.g. its own echo): it has the same shape as the reply
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.feed(mb.encode(mb.WriteSingleRegister(2, 0x40, 3)))
    assert codec.next_message() == mb.WriteSingleRegisterReply(2, 0x40, 3)


# ---------------------------------------------------------------------- resynchronisation


def test_garbage_prefix_resync_silently_when_garbage_is_not_a_header() -> None:
    frame = mb.encode(mb.ReadRegistersReply(0x11, 3, (0x1234,)))  # 0x11 is no function code
    for role, message_frame in (
        (mb.Role.HOST, frame),
        (mb.Role.DEVICE, mb.encode(mb.ReadHoldingRegisters(0x11, 0x66, 2))),
    ):
        codec = mb.ModbusRtuCodec(role)
        garbage = h("00 FF 7F 20 55")
        codec.feed(garbage + message_frame)
        msgs, errors = drain(codec)
        assert errors == []
        assert len(msgs) == 1 and mb.encode(msgs[0]) == message_frame
        assert codec.discarded == len(garbage)


@pytest.mark.parametrize("role", [mb.Role.HOST, mb.Role.DEVICE])
@pytest.mark.parametrize(
    "garbage", ["02", "03 03", "FF 02 03", "01 10 00 00 00 01 02", "02 03 04 00", "AA 55 AA 55 AA"]
)
def test_garbage_prefix_resync(role: mb.Role, garbage: str) -> None:
    """Garbage that looks like a header costs at most some ChecksumErrors, then frames decode."""
    frames = (
        [mb.ReadHoldingRegisters(2, 0x66, 2), mb.WriteSingleRegister(2, 0xF0, 1)]
        if role is mb.Role.DEVICE
        else [mb.ReadRegistersReply(2, 3, (7, 0xA11F)), mb.WriteSingleRegisterReply(2, 0xF0, 1)]
    )
    stream = h(garbage) + b"".join(mb.encode(m) for m in frames)
    codec = mb.ModbusRtuCodec(role)
    codec.feed(stream)
    codec.flush()
    msgs, errors = drain(codec)
    assert msgs == frames
    assert all(type(e) in (FrameError, ChecksumError) for e in errors)
    assert codec.buffered == 0
    assert codec.discarded == len(h(garbage))


def test_checksum_error_consumes_then_next_frame_decodes() -> None:
    good = mb.encode(mb.WriteSingleRegister(2, 0x40, 3))
    bad = bytearray(good)
    bad[-1] ^= 0x01
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    codec.feed(bytes(bad) + good)
    with pytest.raises(ChecksumError) as info:
        codec.next_message()
    assert info.value.data == bytes(bad)
    assert isinstance(info.value, PeerProtocolError) and isinstance(info.value, JointsError)
    assert "CRC" in str(info.value)
    msgs, errors = drain(codec)
    assert msgs == [mb.WriteSingleRegister(2, 0x40, 3)]
    assert all(isinstance(e, FrameError) for e in errors)


def test_truncated_frame_then_flush_is_frame_error() -> None:
    frame = mb.encode(mb.WriteMultipleRegisters(1, 0x4F, (0, 0)))
    truncated = frame[:-3]
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    codec.feed(truncated)
    assert codec.next_message() is None  # waits for the rest
    assert codec.buffered == len(truncated)
    codec.flush()
    with pytest.raises(FrameError) as info:
        codec.next_message()
    assert type(info.value) is FrameError
    assert info.value.data == truncated
    assert "truncated" in str(info.value)
    assert codec.buffered == 0 and codec.discarded == len(truncated)
    assert codec.next_message() is None
    # the codec works again after the error; feeding clears the silence
    codec.feed(frame)
    assert codec.next_message() == mb.WriteMultipleRegisters(1, 0x4F, (0, 0))


def test_truncated_reply_then_flush_is_frame_error() -> None:
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.expect_reply_to(mb.ReadHoldingRegisters(2, 0x66, 2))
    codec.feed(mb.encode(mb.ReadRegistersReply(2, 3, (7, 0xA11F)))[:5])
    assert codec.next_message() is None
    codec.flush()
    with pytest.raises(FrameError):
        codec.next_message()


def test_flush_with_a_lone_byte_is_silent() -> None:
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.feed(b"\x02")
    codec.flush()
    assert codec.next_message() is None
    assert codec.buffered == 0


def test_flush_skips_truncated_head_to_a_buffered_valid_frame() -> None:
    good = mb.encode(mb.ReadHoldingRegisters(2, 0x61, 1))
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    # an FC16 head announcing 100 data bytes swallows the following frame until silence
    codec.feed(h("05 10 00 00 00 32 64") + good)
    assert codec.next_message() is None
    codec.flush()
    msgs, errors = drain(codec)
    assert msgs == [mb.ReadHoldingRegisters(2, 0x61, 1)]
    assert errors == []


def test_clear_drops_buffer_and_expectations() -> None:
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.expect_reply_to(mb.ReadHoldingRegisters(2, 0x66, 2))
    codec.expect_echo(mb.encode(mb.ReadHoldingRegisters(2, 0x66, 2)))
    codec.feed(h("02 03 04"))
    codec.clear()
    assert codec.buffered == 0 and codec.discarded == 3
    # no echo expectation or request any more: a one-register reply is fine
    reply = mb.ReadRegistersReply(2, 3, (5,))
    codec.feed(mb.encode(reply))
    assert codec.next_message() == reply


# ------------------------------------------------------------------------------ byte count


def test_fc16_request_byte_count_disagreeing_with_quantity() -> None:
    frame = append_crc(h("01 10 00 43 00 02 02 00 07"))  # 2 registers, 2 data bytes
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    codec.feed(frame)
    with pytest.raises(ByteCountError) as info:
        codec.next_message()
    assert info.value.data == frame
    assert codec.buffered == 0


def test_odd_reply_byte_count() -> None:
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.feed(append_crc(h("02 03 03 00 01 02")))
    with pytest.raises(ByteCountError):
        codec.next_message()


def test_reply_byte_count_field_wrong_but_frame_has_requested_data() -> None:
    # eRob manual 7.2 step 5: byte count printed 02 for 4 data bytes, CRC over the bad frame
    request = mb.ReadHoldingRegisters(2, 0x66, 2)
    frame = h("02 03 02 00 00 27 10 5B 0F")
    assert crc_ok(frame)
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.expect_reply_to(request)
    for i in range(len(frame)):  # also when it trickles in: wait for the full 9 bytes
        codec.feed(frame[i : i + 1])
        if i < len(frame) - 1:
            assert codec.next_message() is None
    with pytest.raises(ByteCountError) as info:
        codec.next_message()
    assert info.value.data == frame
    assert codec.buffered == 0


def test_self_consistent_reply_with_too_few_registers() -> None:
    request = mb.ReadHoldingRegisters(2, 0x66, 2)
    short = mb.encode(mb.ReadRegistersReply(2, 3, (7,)))
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.expect_reply_to(request)
    codec.feed(short)
    assert codec.next_message() is None  # might still be the 9-byte reply
    codec.flush()
    with pytest.raises(ByteCountError):
        codec.next_message()
    # without an expectation the same frame is a valid one-register reply
    plain = mb.ModbusRtuCodec(mb.Role.HOST)
    plain.feed(short)
    assert plain.next_message() == mb.ReadRegistersReply(2, 3, (7,))


def test_reply_from_another_slave_is_not_checked_against_the_request() -> None:
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.expect_reply_to(mb.ReadHoldingRegisters(2, 0x66, 2))
    other = mb.ReadRegistersReply(3, 3, (1,))
    codec.feed(mb.encode(other))
    assert codec.next_message() == other  # the link decides it is unexpected


# ------------------------------------------------------------------------------------- echo


def test_echo_is_skipped_before_the_reply() -> None:
    request = mb.ReadHoldingRegisters(2, 0x66, 2)
    reply = mb.ReadRegistersReply(2, 3, (7, 0xA11F))
    echo = mb.encode(request)
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.expect_reply_to(request)
    codec.expect_echo(echo)
    codec.feed(echo + mb.encode(reply))
    assert drain(codec) == ([reply], [])
    assert codec.discarded == 0


def test_echo_skipped_when_fed_byte_by_byte() -> None:
    request = mb.WriteMultipleRegisters(2, 0x43, (7, 0xA120))
    reply = mb.WriteMultipleRegistersReply(2, 0x43, 2)
    stream = mb.encode(request) + mb.encode(reply)
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.expect_reply_to(request)
    codec.expect_echo(mb.encode(request))
    got: list[mb.Message] = []
    for i in range(len(stream)):
        codec.feed(stream[i : i + 1])
        msgs, errors = drain(codec)
        assert not errors
        got += msgs
    assert got == [reply]


def test_fc06_echo_equals_reply() -> None:
    """FC06: the echo and the reply are the same 8 bytes; the first is skipped, the second kept."""
    request = mb.WriteSingleRegister(2, 0x40, 3)
    frame = mb.encode(request)
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.expect_reply_to(request)
    codec.expect_echo(frame)
    codec.feed(frame)
    assert codec.next_message() is None  # only the echo so far
    assert codec.buffered == 0
    codec.feed(frame)
    assert codec.next_message() == mb.WriteSingleRegisterReply(2, 0x40, 3)
    assert codec.next_message() is None

    # both at once, and split in the middle of the second copy
    for split in (0, 3, 8, 11, 16):
        codec = mb.ModbusRtuCodec(mb.Role.HOST)
        codec.expect_reply_to(request)
        codec.expect_echo(frame)
        stream = frame + frame
        codec.feed(stream[:split])
        first = drain(codec)[0]
        codec.feed(stream[split:])
        assert first + drain(codec)[0] == [mb.WriteSingleRegisterReply(2, 0x40, 3)]


def test_echo_expectation_dropped_when_reply_comes_without_echo() -> None:
    request = mb.ReadHoldingRegisters(2, 0x66, 2)
    reply = mb.ReadRegistersReply(2, 3, (7, 0xA11F))
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.expect_reply_to(request)
    codec.expect_echo(mb.encode(request))
    codec.feed(mb.encode(reply))
    assert codec.next_message() == reply


def test_partial_echo_then_silence_is_not_skipped_forever() -> None:
    request = mb.ReadHoldingRegisters(2, 0x66, 2)
    echo = mb.encode(request)
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.expect_reply_to(request)
    codec.expect_echo(echo)
    codec.feed(echo[:4])
    assert codec.next_message() is None
    assert codec.buffered == 4  # held: could still be the echo
    codec.flush()
    msgs, _ = drain(codec)
    assert msgs == []
    assert codec.buffered == 0


# ------------------------------------------------------------- device-side quantity checks


def test_device_decodes_out_of_range_quantities_that_the_encoder_refuses() -> None:
    """A server must see "read 0 registers" to answer exception 03, so the device role decodes
    it; the encoder (host side) refuses to send it. This is the one decode/encode asymmetry."""
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    codec.feed(append_crc(h("01 03 00 00 00 00")) + append_crc(h("01 04 00 00 00 7E")))
    codec.feed(append_crc(h("01 10 00 00 00 00 00")))  # FC16 with zero registers
    msgs, errors = drain(codec)
    assert errors == []
    assert msgs == [
        mb.ReadHoldingRegisters(1, 0, 0),
        mb.ReadInputRegisters(1, 0, mb.MAX_READ + 1),
        mb.WriteMultipleRegisters(1, 0, ()),
    ]
    for msg in msgs:
        with pytest.raises(EncodeError):
            mb.encode(msg)


def test_frames_longer_than_rtu_maximum_are_garbage() -> None:
    # FC16 announcing 124 registers (248 data bytes): 257-byte frame > 256 -> never a frame
    body = h("01 10 00 00 00 7C F8") + bytes(248)
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    codec.feed(append_crc(body))
    codec.flush()
    msgs, _ = drain(codec)
    assert msgs == []
    assert codec.buffered == 0


def test_write_replies_are_interned_but_never_for_a_bad_crc() -> None:
    frame = mb.encode(mb.WriteMultipleRegistersReply(7, 0x0047, 2))
    first = mb.ModbusRtuCodec(mb.Role.HOST)
    first.feed(frame)
    a = first.next_message()
    second = mb.ModbusRtuCodec(mb.Role.HOST)
    second.feed(frame)
    b = second.next_message()
    assert a == mb.WriteMultipleRegistersReply(7, 0x0047, 2) and a is b
    bad = frame[:-1] + bytes([frame[-1] ^ 0x01])
    third = mb.ModbusRtuCodec(mb.Role.HOST)
    third.feed(bad)
    with pytest.raises(ChecksumError):
        third.next_message()
