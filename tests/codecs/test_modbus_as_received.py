"""``as_received``: a reply as the host receives it over RTU, for the sim's direct path - the same
result as encoding it (device role) and decoding the frame (host role, expecting the request)."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from joints.codecs import modbus as mb
from joints.errors import EncodeError, FrameError


def over_the_wire(request: Any, reply: Any) -> Any:
    """The byte path: the device's encoder, then the host's decoder (its first message or error)."""
    try:
        frame = mb.encode(reply)
    except EncodeError as exc:
        return ("raises", type(exc), str(exc))
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.expect_reply_to(request)
    codec.feed(frame)
    codec.flush()
    try:
        return codec.next_message()
    except FrameError as exc:
        return ("refused", type(exc), str(exc))


def direct(request: Any, reply: Any) -> Any:
    try:
        got = mb.as_received(request, reply)
    except EncodeError as exc:
        return ("raises", type(exc), str(exc))
    return ("refused", type(got), str(got)) if isinstance(got, FrameError) else got


# mostly plain values, some outside what a field holds
byte = st.one_of(st.integers(0, 255), st.integers(-2, 300), st.sampled_from([3, 4, 6, 16, 0x55, 0x83]))
word = st.one_of(st.integers(0, 0xFFFF), st.sampled_from([-1, -0x10000, 0x10000, 1.5, True]))
requests = st.one_of(
    st.builds(mb.ReadHoldingRegisters, st.integers(1, 3), st.integers(0, 0xFFFF), st.integers(1, 125)),
    st.builds(mb.ReadInputRegisters, st.integers(1, 3), st.integers(0, 0xFFFF), st.integers(1, 125)),
    st.builds(mb.WriteSingleRegister, st.integers(1, 3), st.integers(0, 0xFFFF), st.integers(0, 0xFFFF)),
)


@st.composite
def exchanges(draw: st.DrawFn) -> tuple[Any, Any]:
    """A request and a reply that mostly answers it (its slave, function, register count), sometimes not."""
    request = draw(requests)
    slave = draw(st.sampled_from([request.slave] * 4 + [1, 2, 3, 0, 255, 256, -1, 2.0]))
    function = draw(st.sampled_from([request.function] * 4 + [3, 4, 6, 16, 0x55, 0x83, -1, 300]))
    count = getattr(request, "count", 1)
    n = draw(st.sampled_from([count] * 3 + [count + 1, max(count - 1, 0), 0, 125, 126]))
    values = draw(st.lists(st.integers(0, 0xFFFF), min_size=n, max_size=n))
    if values and draw(st.integers(0, 2)) == 0:  # one value a register cannot hold
        values[draw(st.integers(0, n - 1))] = draw(st.sampled_from([-1, -0x10000, 0x10000, 1.5, True]))
    reply = draw(st.one_of(
        st.just(mb.ReadRegistersReply(slave, function, tuple(values))),
        st.builds(mb.WriteSingleRegisterReply, st.just(slave), word, word),
        st.builds(mb.WriteMultipleRegistersReply, st.just(slave), word, word),
        st.builds(mb.ExceptionReply, st.just(slave), st.just(function), byte),
    ))
    return request, reply


@settings(max_examples=300)
@given(exchanges())
def test_as_received_is_the_byte_path(exchange: tuple[Any, Any]) -> None:
    request, reply = exchange
    assert direct(request, reply) == over_the_wire(request, reply)


def test_a_plain_reply_is_passed_as_it_is() -> None:
    request = mb.ReadHoldingRegisters(1, 0x60, 2)
    reply = mb.ReadRegistersReply(1, 3, (1, 0xFFFF))
    assert mb.as_received(request, reply) is reply
    write = mb.WriteSingleRegisterReply(1, 0x30, 500)
    assert mb.as_received(mb.WriteSingleRegister(1, 0x30, 500), write) is write


def test_the_issues_case_raises_the_encoders_error() -> None:
    with pytest.raises(EncodeError, match="65536"):
        mb.as_received(mb.ReadHoldingRegisters(1, 0x60, 1), mb.ReadRegistersReply(1, 3, (65536,)))
