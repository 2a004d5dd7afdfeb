"""Modbus RTU framing at the edges the reliability harness found (issue 18).

* silence is silence: ``feed(b"")`` after ``flush()`` leaves the line silent (nothing arrived);
* a request with a function code the stack does not know is delimited by its CRC and comes out as
  :class:`~joints.codecs.modbus.UnsupportedRequest` (a server answers "illegal function");
* a header announcing more than 256 bytes (the RTU maximum) is garbage at once: nothing is waited for.
"""

from __future__ import annotations

import pytest
from codeckit import drain, h

from joints.codecs import modbus as mb
from joints.codecs.crc import append_crc


@pytest.mark.parametrize("role", list(mb.Role))
def test_feeding_nothing_after_silence_keeps_the_line_silent(role: mb.Role) -> None:
    codec = mb.ModbusRtuCodec(role)
    codec.feed(h("02 10 00 43 00 02"))  # a request / reply head that stopped half-way
    assert codec.next_message() is None
    codec.flush()
    codec.feed(b"")  # no bytes arrived: still silent
    msgs, _ = drain(codec)
    assert msgs == [] and codec.buffered == 0


def test_unknown_function_code_is_framed_by_its_crc() -> None:
    frame = append_crc(h("01 2B 0E 01 00"))  # FC43 read device identification
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    codec.feed(frame)
    assert codec.next_message() == mb.UnsupportedRequest(1, 0x2B, h("0E 01 00"))
    assert mb.encode(mb.UnsupportedRequest(1, 0x2B, h("0E 01 00"))) == frame
    assert codec.buffered == 0


def test_unknown_function_code_split_then_followed_by_a_frame() -> None:
    diag = append_crc(h("02 08 00 00 A5 37"))  # FC08 diagnostics, return query data
    read = mb.encode(mb.ReadHoldingRegisters(2, 0x40, 1))
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    codec.feed(diag[:4])
    assert codec.next_message() is None  # may still be arriving
    codec.feed(diag[4:] + read)
    msgs, errors = drain(codec)
    assert msgs == [mb.UnsupportedRequest(2, 0x08, h("00 00 A5 37")), mb.ReadHoldingRegisters(2, 0x40, 1)]
    assert errors == []


def test_unknown_function_garbage_is_dropped_at_silence() -> None:
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    codec.feed(h("02 41 12 34 56"))  # no CRC-valid prefix: never a frame
    assert codec.next_message() is None
    codec.flush()
    msgs, _ = drain(codec)
    assert msgs == [] and codec.buffered == 0


@pytest.mark.parametrize("role,head", [(mb.Role.DEVICE, "02 10 00 00 00 7C F8"),  # 9 + 248 bytes
                                       (mb.Role.HOST, "02 03 FC")])  # 5 + 252 bytes
def test_a_header_announcing_more_than_256_bytes_is_rejected_at_once(role: mb.Role, head: str) -> None:
    # (slave 0x11 is no function code, so the head's last byte and the frame's first make no header)
    follow: mb.Message = (mb.ReadHoldingRegisters(0x11, 0x40, 1) if role is mb.Role.DEVICE
                          else mb.WriteSingleRegisterReply(0x11, 0x40, 1))
    codec = mb.ModbusRtuCodec(role)
    codec.feed(h(head) + mb.encode(follow))
    msgs, _ = drain(codec)  # no silence needed: the head can never be a frame
    assert msgs == [follow]
    assert codec.buffered == 0
