"""Property tests of the Modbus RTU codec (hypothesis).

(a) arbitrary bytes, split arbitrarily, never raise anything but ``JointsError`` subclasses, and
    every message that comes out re-encodes to a CRC-valid frame found in the input;
(b) valid frames concatenated and split arbitrarily decode to exactly the original messages;
(c) one flipped bit in a valid frame never yields a message that is not a CRC-valid substring of
    the input (CRC-16 detects every single-bit error).
"""

from __future__ import annotations

from itertools import pairwise

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from joints.codecs import modbus as mb
from joints.codecs.crc import append_crc, crc_ok
from joints.errors import EncodeError, FrameError, JointsError

SETTINGS = settings(
    max_examples=300,
    deadline=None,
    database=None,  # no .hypothesis directory in the work tree
    suppress_health_check=[HealthCheck.too_slow],
)

u8 = st.integers(0, 0xFF)
u16 = st.integers(0, 0xFFFF)


def words(lo: int, hi: int) -> st.SearchStrategy[tuple[int, ...]]:
    return st.lists(u16, min_size=lo, max_size=hi).map(tuple)


# --------------------------------------------------------------------------- message strategies

requests = st.one_of(
    st.builds(mb.ReadHoldingRegisters, u8, u16, st.integers(1, mb.MAX_READ)),
    st.builds(mb.ReadInputRegisters, u8, u16, st.integers(1, mb.MAX_READ)),
    st.builds(mb.WriteSingleRegister, u8, u16, u16),
    st.builds(mb.WriteMultipleRegisters, u8, u16, words(1, 20)),
    st.builds(mb.WriteMultipleRegisters, u8, u16, words(mb.MAX_WRITE, mb.MAX_WRITE)),
    # well-framed requests of function codes the stack does not implement
    st.builds(mb.UnsupportedRequest, u8, st.sampled_from([1, 2, 5]), st.binary(min_size=4, max_size=4)),
    st.builds(
        lambda s, a, q, data: mb.UnsupportedRequest(
            s, 15, a.to_bytes(2, "big") + q.to_bytes(2, "big") + bytes((len(data),)) + data
        ),
        u8,
        u16,
        u16,
        st.binary(max_size=20),
    ),
)

replies = st.one_of(
    st.builds(mb.ReadRegistersReply, u8, st.sampled_from([3, 4]), words(0, 20)),
    st.builds(mb.ReadRegistersReply, u8, st.sampled_from([3, 4]), words(mb.MAX_READ, mb.MAX_READ)),
    st.builds(mb.WriteSingleRegisterReply, u8, u16, u16),
    st.builds(mb.WriteMultipleRegistersReply, u8, u16, u16),
    st.builds(mb.ExceptionReply, u8, st.sampled_from([1, 2, 3, 4, 5, 6, 15, 16, 0x17]), u8),
)

ROLES = st.sampled_from([mb.Role.HOST, mb.Role.DEVICE])

#: bytes with a valid CRC and a plausible header: they reach the decoders, not just the framer
crc_valid_junk = st.one_of(
    st.binary(min_size=1, max_size=30).map(append_crc),
    st.tuples(
        u8,
        st.sampled_from([1, 2, 3, 4, 5, 6, 15, 16, 0x81, 0x83, 0x86, 0x90, 0x97]),
        st.binary(max_size=12),
    ).map(lambda t: append_crc(bytes((t[0], t[1])) + t[2])),
)

chunks = st.lists(
    st.one_of(
        st.binary(max_size=24),
        crc_valid_junk,
        requests.map(mb.encode),
        replies.map(mb.encode),
    ),
    max_size=8,
).map(b"".join)


def _split_points(data: st.DataObject, n: int) -> list[int]:
    cuts = data.draw(st.lists(st.integers(0, n), max_size=12), label="cuts")
    return sorted(set(cuts) | {0, n})


def _run(
    codec: mb.ModbusRtuCodec,
    stream: bytes,
    cuts: list[int],
    flush_at: set[int] = frozenset(),  # type: ignore[assignment]
) -> tuple[list[mb.Message], list[JointsError]]:
    """Feed ``stream`` in pieces, draining after each; flush (silence) where told and at the end."""
    msgs: list[mb.Message] = []
    errors: list[JointsError] = []

    def drain() -> None:
        for _ in range(10 * len(stream) + 10):
            try:
                msg = codec.next_message()
            except JointsError as exc:  # anything else fails the test
                assert isinstance(exc, FrameError)
                errors.append(exc)
                continue
            if msg is None:
                return
            msgs.append(msg)
        raise AssertionError("codec made no progress")

    for a, b in pairwise(cuts):
        codec.feed(stream[a:b])
        drain()
        if b in flush_at:
            codec.flush()
            drain()
    codec.flush()
    drain()
    assert codec.buffered == 0, "silence must leave nothing buffered"
    return msgs, errors


def _assert_reencodes_into(msg: mb.Message, role: mb.Role, fed: bytes) -> None:
    try:
        frame = mb.encode(msg)
    except EncodeError:
        # The one asymmetry: a device decodes a request with a quantity the encoder refuses to
        # send (0, or more than the Modbus maximum) so that a server can answer exception 03.
        assert role is mb.Role.DEVICE
        if isinstance(msg, (mb.ReadHoldingRegisters, mb.ReadInputRegisters)):
            assert not 1 <= msg.count <= mb.MAX_READ
        else:
            assert isinstance(msg, mb.WriteMultipleRegisters) and len(msg.values) == 0
        return
    assert crc_ok(frame)
    assert frame in fed
    if role is mb.Role.DEVICE:
        assert isinstance(
            msg,
            (
                mb.ReadHoldingRegisters,
                mb.ReadInputRegisters,
                mb.WriteSingleRegister,
                mb.WriteMultipleRegisters,
                mb.UnsupportedRequest,
            ),
        )
    else:
        assert isinstance(
            msg,
            (mb.ReadRegistersReply, mb.WriteSingleRegisterReply, mb.WriteMultipleRegistersReply, mb.ExceptionReply),
        )


# ------------------------------------------------------------------------------------ (a)


@SETTINGS
@given(stream=st.binary(max_size=300), role=ROLES, data=st.data())
def test_random_bytes_only_raise_joints_errors(stream: bytes, role: mb.Role, data: st.DataObject) -> None:
    codec = mb.ModbusRtuCodec(role)
    cuts = _split_points(data, len(stream))
    msgs, _ = _run(codec, stream, cuts, set(data.draw(st.lists(st.sampled_from(cuts), max_size=3))))
    for msg in msgs:
        _assert_reencodes_into(msg, role, stream)


@SETTINGS
@given(
    stream=chunks,
    role=ROLES,
    expected=st.none() | requests.filter(lambda r: not isinstance(r, mb.UnsupportedRequest)),
    echo=st.booleans(),
    data=st.data(),
)
def test_frame_like_bytes_only_raise_joints_errors(
    stream: bytes, role: mb.Role, expected: mb.Request | None, echo: bool, data: st.DataObject
) -> None:
    """Garbage mixed with CRC-valid junk and real frames, with the host's expectations set."""
    codec = mb.ModbusRtuCodec(role)
    if role is mb.Role.HOST and expected is not None:
        codec.expect_reply_to(expected)
        if echo:
            codec.expect_echo(mb.encode(expected))
            stream = mb.encode(expected) + stream
    cuts = _split_points(data, len(stream))
    msgs, _ = _run(codec, stream, cuts, set(data.draw(st.lists(st.sampled_from(cuts), max_size=3))))
    for msg in msgs:
        _assert_reencodes_into(msg, role, stream)
    accounted = sum(len(mb.encode(m)) for m in msgs if _encodable(m))
    assert accounted <= len(stream)


def _encodable(msg: mb.Message) -> bool:
    try:
        mb.encode(msg)
    except EncodeError:
        return False
    return True


# ------------------------------------------------------------------------------------ (b)


@SETTINGS
@given(
    role_messages=st.one_of(
        st.tuples(st.just(mb.Role.DEVICE), st.lists(requests, min_size=1, max_size=6)),
        st.tuples(st.just(mb.Role.HOST), st.lists(replies, min_size=1, max_size=6)),
    ),
    data=st.data(),
)
def test_valid_frames_split_randomly_decode_exactly(
    role_messages: tuple[mb.Role, list[mb.Message]], data: st.DataObject
) -> None:
    role, messages = role_messages
    stream = b"".join(mb.encode(m) for m in messages)
    codec = mb.ModbusRtuCodec(role)
    # silence may only fall between frames (t3.5 marks frame ends on a real line)
    ends, pos = set(), 0
    for m in messages:
        pos += len(mb.encode(m))
        ends.add(pos)
    flush_at = set(data.draw(st.lists(st.sampled_from(sorted(ends)), max_size=3)))
    cuts = sorted(set(_split_points(data, len(stream))) | flush_at)
    msgs, errors = _run(codec, stream, cuts, flush_at)
    assert errors == []
    assert msgs == messages
    assert codec.discarded == 0


@SETTINGS
@given(messages=st.lists(replies, min_size=1, max_size=4), data=st.data())
def test_host_with_matching_expectations_decodes_each_reply(messages: list[mb.Message], data: st.DataObject) -> None:
    """One transaction at a time, each reply fed in random pieces after its request."""
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    for reply in messages:
        request: mb.Request | None = None
        if isinstance(reply, mb.ReadRegistersReply) and reply.values:
            cls = mb.ReadHoldingRegisters if reply.function == 3 else mb.ReadInputRegisters
            request = cls(reply.slave, 0, len(reply.values))
        codec.clear()
        codec.expect_reply_to(request)
        frame = mb.encode(reply)
        msgs, errors = _run(codec, frame, _split_points(data, len(frame)))
        assert (msgs, errors) == ([reply], [])


# ------------------------------------------------------------------------------------ (c)


@SETTINGS
@given(
    role_message=st.one_of(
        st.tuples(st.just(mb.Role.DEVICE), requests),
        st.tuples(st.just(mb.Role.HOST), replies),
    ),
    before=st.booleans(),
    after=st.booleans(),
    data=st.data(),
)
def test_single_bit_flip_is_never_accepted(
    role_message: tuple[mb.Role, mb.Message], before: bool, after: bool, data: st.DataObject
) -> None:
    role, message = role_message
    frame = mb.encode(message)
    bit = data.draw(st.integers(0, 8 * len(frame) - 1), label="bit")
    flipped = bytearray(frame)
    flipped[bit // 8] ^= 1 << (bit % 8)
    flipped = bytes(flipped)
    assert not crc_ok(flipped)  # CRC-16 catches every single-bit error

    neighbour = (
        mb.encode(mb.ReadHoldingRegisters(7, 0x0066, 2))
        if role is mb.Role.DEVICE
        else mb.encode(mb.WriteSingleRegisterReply(7, 0x00F0, 1))
    )
    stream = (neighbour if before else b"") + flipped + (neighbour if after else b"")
    codec = mb.ModbusRtuCodec(role)
    expect = role is mb.Role.HOST and data.draw(st.booleans(), label="expect")
    if expect and isinstance(message, mb.ReadRegistersReply) and message.values:
        codec.expect_reply_to(mb.ReadHoldingRegisters(message.slave, 0, len(message.values)))
    msgs, _ = _run(codec, stream, _split_points(data, len(stream)))

    for msg in msgs:
        _assert_reencodes_into(msg, role, stream)
        if _encodable(msg) and mb.encode(msg) == neighbour:
            continue
        assert msg != message
        if _encodable(msg):
            assert mb.encode(msg) != flipped
    if before:
        assert msgs and mb.encode(msgs[0]) == neighbour  # what came before is unaffected
