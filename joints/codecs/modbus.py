"""Modbus RTU codec, sans-I/O, for both roles (host and device).

Rule: ``encode(message) -> bytes`` is pure; decoding is ``feed(bytes)`` then ``next_message()``
until it returns ``None`` (need more bytes). RTU has no length field, so frames are delimited by
the function code and byte counts. Garbage is skipped byte by byte (resynchronisation); a frame
whose CRC fails raises :class:`~joints.errors.ChecksumError` after its first byte is dropped, so
the caller may keep calling ``next_message()``. ``flush()`` tells the codec the line went silent
(t3.5): an incomplete head is garbage then.

Host role decodes replies (exception replies to every public or user-defined function code, so a
host hears "illegal function" for a code the server lacks); ``expect_reply_to(request)`` lets it
check a reply's byte count against the request (a reply whose byte-count field disagrees with the
frame raises :class:`~joints.errors.ByteCountError`). ``expect_echo(frame)`` skips an RS485 adapter's local echo.
Device role decodes requests; unsupported-but-well-framed function codes come out as
:class:`UnsupportedRequest` so a server can answer "illegal function". A function code the
codec knows no shape for (a public or user-defined code other than 01-06, 15, 16) has no length
field: such a request is delimited by its CRC, the shortest prefix of 4-256 bytes that ends in
its own CRC (an RTU slave delimits frames by the t3.5 silence; the CRC finds the same end without
waiting for it, and a chance match costs an exception reply, never an action). Unassigned
function codes are garbage in both roles.

A header announcing a frame longer than 256 bytes (the RTU maximum, Modbus over serial line
2.5.1.1) is garbage at once: nothing is waited for. ``feed(b"")`` is no news: a line that went
silent stays silent until bytes arrive.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from joints.codecs.crc import crc16_modbus, crc16_valid_prefix
from joints.codecs.echo import echo_length
from joints.errors import ByteCountError, ChecksumError, EncodeError, FrameError

READ_HOLDING_REGISTERS = 0x03
READ_INPUT_REGISTERS = 0x04
WRITE_SINGLE_REGISTER = 0x06
WRITE_MULTIPLE_REGISTERS = 0x10

#: Modbus exception codes (Modbus Application Protocol v1.1b3, 7).
EXCEPTION_TEXT = {
    0x01: "illegal function",
    0x02: "illegal data address",
    0x03: "illegal data value",
    0x04: "server device failure",
    0x05: "acknowledge",
    0x06: "server device busy",
    0x08: "memory parity error",
    0x0A: "gateway path unavailable",
    0x0B: "gateway target device failed to respond",
}

MAX_READ = 125  #: registers per FC03/04 (Modbus spec; the eRob manual allows 127)
MAX_WRITE = 123  #: registers per FC16 (Modbus spec)
MAX_FRAME = 256


class Role(enum.Enum):
    HOST = "host"  #: encodes requests, decodes replies
    DEVICE = "device"  #: decodes requests, encodes replies


# --- messages --------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ReadHoldingRegisters:
    slave: int
    address: int
    count: int
    function = READ_HOLDING_REGISTERS


@dataclass(frozen=True, slots=True)
class ReadInputRegisters:
    slave: int
    address: int
    count: int
    function = READ_INPUT_REGISTERS


@dataclass(frozen=True, slots=True)
class WriteSingleRegister:
    slave: int
    address: int
    value: int
    function = WRITE_SINGLE_REGISTER


@dataclass(frozen=True, slots=True)
class WriteMultipleRegisters:
    slave: int
    address: int
    values: tuple[int, ...]
    function = WRITE_MULTIPLE_REGISTERS


@dataclass(frozen=True, slots=True)
class UnsupportedRequest:
    """A well-framed request with a function code this stack does not implement (device role)."""

    slave: int
    function: int
    pdu: bytes


@dataclass(frozen=True, slots=True)
class ReadRegistersReply:
    """Reply to FC03 or FC04: the register values in order."""

    slave: int
    function: int
    values: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class WriteSingleRegisterReply:
    slave: int
    address: int
    value: int
    function = WRITE_SINGLE_REGISTER


@dataclass(frozen=True, slots=True)
class WriteMultipleRegistersReply:
    slave: int
    address: int
    count: int
    function = WRITE_MULTIPLE_REGISTERS


@dataclass(frozen=True, slots=True)
class ExceptionReply:
    """Exception reply: ``function`` is the request's function code (without the 0x80 bit)."""

    slave: int
    function: int
    code: int

    @property
    def text(self) -> str:
        return EXCEPTION_TEXT.get(self.code, "unknown exception")


Request = ReadHoldingRegisters | ReadInputRegisters | WriteSingleRegister | WriteMultipleRegisters
Reply = ReadRegistersReply | WriteSingleRegisterReply | WriteMultipleRegistersReply | ExceptionReply
Message = Request | Reply | UnsupportedRequest


# --- encoding --------------------------------------------------------------------------------


def _u8(name: str, v: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 0xFF:
        raise EncodeError(f"{name} must be an integer 0..255, got {v!r}")
    return v


def _u16(name: str, v: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 0xFFFF:
        raise EncodeError(f"{name} must be an integer 0..65535, got {v!r}")
    return v


#: big-endian register packers/unpackers by word count (a frame carries at most 127 words)
_WORDS_BE = [struct.Struct(f">{n}H") for n in range(128)]


def _words_be(n: int) -> struct.Struct:
    return _WORDS_BE[n] if n < 128 else struct.Struct(f">{n}H")


def _plain_u16s(values: tuple[int, ...] | list[int]) -> bytes | None:
    """Fast path of :func:`_words`: exact ints in range packed in one go, else None."""
    for v in values:
        if type(v) is not int:  # bools, floats, int subclasses: the checked path decides
            return None
    try:
        return _words_be(len(values)).pack(*values)
    except struct.error:  # out of range: the checked path raises the EncodeError
        return None


def _words(values: tuple[int, ...] | list[int]) -> bytes:
    fast = _plain_u16s(values)
    if fast is not None:
        return fast
    out = bytearray()
    for i, v in enumerate(values):
        out += _u16(f"value[{i}]", v).to_bytes(2, "big")
    return bytes(out)


def _finish(body: bytes | bytearray) -> bytes:
    return bytes(body) + crc16_modbus(body).to_bytes(2, "little")


_HEAD = struct.Struct(">BBHH")  # slave, function, address, count/value
#: FC16 request bodies (slave, function, address, count, byte count, values) by value count
_FC16 = [struct.Struct(f">BBHHB{n}H") for n in range(MAX_WRITE + 1)]


def encode_pdu(message: Message) -> bytes:
    """The frame without slave address and CRC."""
    if isinstance(message, (ReadHoldingRegisters, ReadInputRegisters)):
        if not 1 <= message.count <= MAX_READ:
            raise EncodeError(f"read count must be 1..{MAX_READ}, got {message.count}")
        return bytes((message.function,)) + _u16("address", message.address).to_bytes(
            2, "big"
        ) + message.count.to_bytes(2, "big")
    if isinstance(message, (WriteSingleRegister, WriteSingleRegisterReply)):
        return (
            bytes((WRITE_SINGLE_REGISTER,))
            + _u16("address", message.address).to_bytes(2, "big")
            + _u16("value", message.value).to_bytes(2, "big")
        )
    if isinstance(message, WriteMultipleRegisters):
        n = len(message.values)
        if not 1 <= n <= MAX_WRITE:
            raise EncodeError(f"write count must be 1..{MAX_WRITE}, got {n}")
        return (
            bytes((WRITE_MULTIPLE_REGISTERS,))
            + _u16("address", message.address).to_bytes(2, "big")
            + n.to_bytes(2, "big")
            + bytes((2 * n,))
            + _words(message.values)
        )
    if isinstance(message, WriteMultipleRegistersReply):
        return (
            bytes((WRITE_MULTIPLE_REGISTERS,))
            + _u16("address", message.address).to_bytes(2, "big")
            + _u16("count", message.count).to_bytes(2, "big")
        )
    if isinstance(message, ReadRegistersReply):
        n = len(message.values)
        if n > MAX_READ:
            raise EncodeError(f"reply carries at most {MAX_READ} registers, got {n}")
        return bytes((_u8("function", message.function), 2 * n)) + _words(message.values)
    if isinstance(message, ExceptionReply):
        return bytes((_u8("function", message.function) | 0x80, _u8("code", message.code)))
    if isinstance(message, UnsupportedRequest):
        return bytes((_u8("function", message.function),)) + message.pdu
    raise EncodeError(f"not a Modbus message: {message!r}")


# Fast paths of the host's hot messages: exactly these types with plain in-range ints give the
# same bytes as the checked path; anything unusual (subclasses, bools, floats, out-of-range
# fields) returns None and goes through the checked path, which encodes it or raises EncodeError.


def _fast_read(m: ReadHoldingRegisters | ReadInputRegisters) -> bytes | None:
    s, a, c = m.slave, m.address, m.count
    if type(s) is not int or type(a) is not int or type(c) is not int:
        return None
    if not (0 <= s <= 0xFF and 0 <= a <= 0xFFFF and 1 <= c <= MAX_READ):
        return None
    body = _HEAD.pack(s, m.function, a, c)
    return body + crc16_modbus(body).to_bytes(2, "little")


def _fast_write_single(m: WriteSingleRegister) -> bytes | None:
    s, a, v = m.slave, m.address, m.value
    if type(s) is not int or type(a) is not int or type(v) is not int:
        return None
    if not (0 <= s <= 0xFF and 0 <= a <= 0xFFFF and 0 <= v <= 0xFFFF):
        return None
    body = _HEAD.pack(s, WRITE_SINGLE_REGISTER, a, v)
    return body + crc16_modbus(body).to_bytes(2, "little")


def _fast_write_multiple(m: WriteMultipleRegisters) -> bytes | None:
    s, a, values = m.slave, m.address, m.values
    n = len(values)
    if type(s) is not int or type(a) is not int or not (0 <= s <= 0xFF and 0 <= a <= 0xFFFF and 1 <= n <= MAX_WRITE):
        return None
    for v in values:
        if type(v) is not int:
            return None
    try:
        body = _FC16[n].pack(s, WRITE_MULTIPLE_REGISTERS, a, n, 2 * n, *values)
    except struct.error:  # a value out of range
        return None
    return body + crc16_modbus(body).to_bytes(2, "little")


#: FC03/FC04 reply bodies (slave, function, byte count, values) by value count
_REPLY_READ = [struct.Struct(f">BBB{n}H") for n in range(MAX_READ + 1)]


def _fast_read_reply(m: ReadRegistersReply) -> bytes | None:
    s, fc, values = m.slave, m.function, m.values
    n = len(values)
    if type(s) is not int or type(fc) is not int or not (0 <= s <= 0xFF and 0 <= fc <= 0xFF and n <= MAX_READ):
        return None
    for v in values:
        if type(v) is not int:
            return None
    try:
        body = _REPLY_READ[n].pack(s, fc, 2 * n, *values)
    except struct.error:  # a value out of range
        return None
    return body + crc16_modbus(body).to_bytes(2, "little")


_FAST_ENCODERS: dict[type, Callable[[Any], bytes | None]] = {
    ReadHoldingRegisters: _fast_read,
    ReadInputRegisters: _fast_read,
    WriteSingleRegister: _fast_write_single,
    WriteMultipleRegisters: _fast_write_multiple,
    ReadRegistersReply: _fast_read_reply,
}


def _plain_read(m: ReadHoldingRegisters | ReadInputRegisters) -> bool:
    s, a, c = m.slave, m.address, m.count
    return (type(s) is int and type(a) is int and type(c) is int
            and 0 <= s <= 0xFF and 0 <= a <= 0xFFFF and 1 <= c <= MAX_READ)


def _plain_write_single(m: WriteSingleRegister) -> bool:
    s, a, v = m.slave, m.address, m.value
    return (type(s) is int and type(a) is int and type(v) is int
            and 0 <= s <= 0xFF and 0 <= a <= 0xFFFF and 0 <= v <= 0xFFFF)


def _plain_write_multiple(m: WriteMultipleRegisters) -> bool:
    s, a, values = m.slave, m.address, m.values
    if not (type(s) is int and type(a) is int and 0 <= s <= 0xFF and 0 <= a <= 0xFFFF
            and 1 <= len(values) <= MAX_WRITE):
        return False
    for v in values:
        if type(v) is not int or not 0 <= v <= 0xFFFF:
            return False
    return True


_PLAIN: dict[type, Callable[[Any], bool]] = {
    ReadHoldingRegisters: _plain_read,
    ReadInputRegisters: _plain_read,
    WriteSingleRegister: _plain_write_single,
    WriteMultipleRegisters: _plain_write_multiple,
}


def check(message: Message) -> None:
    """Raise the :class:`~joints.errors.EncodeError` :func:`encode` would raise, without building
    the frame (a message that passes would encode)."""
    plain = _PLAIN.get(type(message))
    if plain is None or not plain(message):
        encode(message)


def encode(message: Message) -> bytes:
    """Encode any request or reply into a complete RTU frame (address, PDU, CRC low first)."""
    fast = _FAST_ENCODERS.get(type(message))
    if fast is not None:
        frame = fast(message)
        if frame is not None:
            return frame
    return _finish(bytes((_u8("slave", message.slave),)) + encode_pdu(message))


# --- decoding --------------------------------------------------------------------------------


#: the function codes that exist: the public codes the Modbus application protocol assigns
#: (v1.1b3, 5.1) and the user-defined ranges 65-72 and 100-110. A device frames a request with one
#: it does not implement (a server answers 01), a host decodes exception replies to any of them;
#: any other code is garbage.
_EXCEPTION_FCS = frozenset((1, 2, 3, 4, 5, 6, 7, 8, 11, 12, 15, 16, 17, 20, 21, 22, 23, 24, 43,
                            *range(65, 73), *range(100, 111)))
_BYTE_COUNT_REPLY_FCS = frozenset((READ_HOLDING_REGISTERS, READ_INPUT_REGISTERS, 1, 2))
_FIXED_REPLY_FCS = frozenset((WRITE_SINGLE_REGISTER, WRITE_MULTIPLE_REGISTERS, 5, 15))


def _reply_length(buf: bytearray) -> int | None:
    """Frame length of a reply at the head of ``buf``; None = need more; 0 = not a reply."""
    if len(buf) < 2:
        return None
    fc = buf[1]
    if fc & 0x80:
        return 5 if fc & 0x7F in _EXCEPTION_FCS else 0
    if fc in _BYTE_COUNT_REPLY_FCS:
        if len(buf) < 3:
            return None
        return 5 + buf[2]
    if fc in _FIXED_REPLY_FCS:
        return 8
    return 0


def _request_length(buf: bytearray) -> int | None:
    if len(buf) < 2:
        return None
    fc = buf[1]
    if fc in (1, 2, 3, 4, 5, 6):
        return 8
    if fc in (15, 16):
        if len(buf) < 7:
            return None
        return 9 + buf[6]
    return 0


def _unknown_request_length(buf: bytearray) -> int | None:
    """A request whose function code this stack does not know has no length field: it is delimited
    by its CRC (the shortest prefix of 4 .. 256 bytes ending in its own CRC). None: no such prefix
    yet (more may arrive; at silence the head is garbage); 0: none in 256 bytes (garbage)."""
    n = crc16_valid_prefix(buf, 4, MAX_FRAME)
    if n:
        return n
    return 0 if len(buf) >= MAX_FRAME else None


def _decode_reply(frame: bytes, expected: Request | None) -> Reply:
    slave, fc = frame[0], frame[1]
    if fc & 0x80:
        return ExceptionReply(slave, fc & 0x7F, frame[2])
    if fc in (READ_HOLDING_REGISTERS, READ_INPUT_REGISTERS):
        n = frame[2]
        if n % 2:
            raise ByteCountError(f"read reply byte count {n} is odd", data=frame)
        return ReadRegistersReply(slave, fc, _words_be(n >> 1).unpack_from(frame, 3))
    if fc == WRITE_SINGLE_REGISTER or fc == WRITE_MULTIPLE_REGISTERS:  # always 8-byte frames
        _, _, a, b = _HEAD.unpack_from(frame)
        if fc == WRITE_SINGLE_REGISTER:
            return WriteSingleRegisterReply(slave, a, b)
        return WriteMultipleRegistersReply(slave, a, b)
    raise FrameError(f"reply with unsupported function code 0x{fc:02X}", data=frame)


def _decode_request(frame: bytes) -> Request | UnsupportedRequest:
    slave, fc = frame[0], frame[1]
    a = int.from_bytes(frame[2:4], "big")
    b = int.from_bytes(frame[4:6], "big")
    if fc == READ_HOLDING_REGISTERS:
        return ReadHoldingRegisters(slave, a, b)
    if fc == READ_INPUT_REGISTERS:
        return ReadInputRegisters(slave, a, b)
    if fc == WRITE_SINGLE_REGISTER:
        return WriteSingleRegister(slave, a, b)
    if fc == WRITE_MULTIPLE_REGISTERS:
        n = frame[6]
        if n != 2 * b or n % 2:
            raise ByteCountError(
                f"FC16 request for {b} registers carries byte count {n} (expected {2 * b})",
                data=frame,
            )
        return WriteMultipleRegisters(slave, a, _words_be(n >> 1).unpack_from(frame, 7))
    return UnsupportedRequest(slave, fc, frame[2:-2])


#: Interned write replies by their 8 bytes (valid CRC only). An FC16 reply echoes address and
#: count, an FC06 reply the written value, so a host writing the same registers again and again
#: gets the same frames back; messages are frozen, so sharing them is safe.
_WRITE_REPLIES: dict[bytes, Reply] = {}
#: Interned 8-byte requests (FC03, FC04, FC06; valid CRC only) by their bytes: a host polling a
#: block sends the same frame again and again (device role).
_REQUESTS: dict[bytes, Request | UnsupportedRequest] = {}
_FIXED_REQUEST_FCS = frozenset((READ_HOLDING_REGISTERS, READ_INPUT_REGISTERS, WRITE_SINGLE_REGISTER))


class ModbusRtuCodec:
    """Incremental RTU framer/decoder for one end of a bus (see module docstring)."""

    def __init__(self, role: Role = Role.HOST) -> None:
        self.role = role
        self._buf = bytearray()
        self._expected: Request | None = None
        self._echo: bytes | None = None
        self._silent = False
        self.discarded = 0  #: bytes dropped while resynchronising (garbage, bad frames)

    # -- input --
    def feed(self, data: bytes | bytearray) -> None:
        """Append received bytes (nothing received leaves a silent line silent)."""
        if data:
            self._buf += data
            self._silent = False

    def flush(self) -> None:
        """The line went silent: an incomplete frame at the head will never complete."""
        self._silent = True

    def clear(self) -> None:
        """Drop everything buffered and any expectation."""
        self.discarded += len(self._buf)
        self._buf.clear()
        self._expected = None
        self._echo = None

    @property
    def buffered(self) -> int:
        return len(self._buf)

    def expect_reply_to(self, request: Request | None) -> None:
        """Host role: the request now outstanding (checks the reply's byte count against it)."""
        self._expected = request

    def expect_echo(self, frame: bytes) -> None:
        """Skip this exact frame once if it arrives first (RS485 adapter local echo)."""
        self._echo = bytes(frame)

    # -- output --
    @staticmethod
    def encode(message: Message) -> bytes:
        return encode(message)

    def next_message(self) -> Message | None:
        """Next complete message, or None if more bytes are needed.

        Raises a :class:`~joints.errors.FrameError` subclass for a bad frame; the bad bytes are
        consumed first, so calling again continues with what follows.
        """
        buf = self._buf
        while buf:
            if self._echo is not None:
                skip = echo_length(buf, self._echo, self._silent)
                if skip is None:
                    return None
                self._echo = None
                if skip:
                    del buf[:skip]
                    continue
            if self.role is Role.HOST:
                if len(buf) >= 8 and (buf[1] == WRITE_SINGLE_REGISTER or buf[1] == WRITE_MULTIPLE_REGISTERS):
                    # Hot path, same result as the general one below: a write reply is always
                    # 8 bytes and needs no check against the request; a bad CRC falls through.
                    frame = bytes(buf[:8])
                    known = _WRITE_REPLIES.get(frame)
                    if known is not None:  # the same 8 bytes decode to the same (immutable) reply
                        del buf[:8]
                        return known
                    if crc16_modbus(frame) == 0:
                        del buf[:8]
                        slave, fc, a, b = _HEAD.unpack_from(frame)
                        reply: Reply = (WriteSingleRegisterReply(slave, a, b) if fc == WRITE_SINGLE_REGISTER
                                        else WriteMultipleRegistersReply(slave, a, b))
                        if len(_WRITE_REPLIES) >= 512:
                            _WRITE_REPLIES.clear()
                        _WRITE_REPLIES[frame] = reply
                        return reply
                length = self._host_length(buf)
            else:
                if len(buf) >= 8 and buf[1] in _FIXED_REQUEST_FCS:
                    # Hot path, same result as the general one below: a read or FC06 request is
                    # always 8 bytes; a host polling the same block sends the same frame again
                    known_request = _REQUESTS.get(bytes(buf[:8]))
                    if known_request is not None:
                        del buf[:8]
                        return known_request
                length = _request_length(buf)
                if length == 0 and buf[1] in _EXCEPTION_FCS:  # a function code this stack does not know
                    length = _unknown_request_length(buf)
                    if length is None and not self._silent:
                        # no end yet: garbage if a valid frame is already buffered behind it
                        skip = self._next_valid_offset(buf)
                        if skip:
                            del buf[:skip]
                            self.discarded += skip
                            continue
            if length is not None and length > MAX_FRAME:  # can never be a frame: nothing to wait for
                del buf[0]
                self.discarded += 1
                continue
            if length is None or (length and len(buf) < length):
                if not self._silent:
                    return None
                # Silence: the head will never complete. Resync on a later valid frame if one is
                # buffered; otherwise the head was a truncated frame.
                skip = self._next_valid_offset(buf)
                if skip:
                    del buf[:skip]
                    self.discarded += skip
                    continue
                frame = bytes(buf)
                self.discarded += len(buf)
                buf.clear()
                if length:
                    raise FrameError(
                        f"truncated frame: {frame.hex(' ')} has {len(frame)} bytes, its header "
                        f"announces {length}",
                        data=frame,
                    )
                return None
            if length == 0 or length > MAX_FRAME or length < 4:
                del buf[0]
                self.discarded += 1
                continue
            frame = bytes(buf[:length])
            if crc16_modbus(frame) != 0:
                if self.role is Role.HOST and self._expected is not None:
                    err = self._byte_count_mismatch(buf)
                    if err is not None:
                        raise err
                del buf[0]
                self.discarded += 1
                raise ChecksumError(
                    f"CRC mismatch in {frame.hex(' ')}: expected "
                    f"{crc16_modbus(frame[:-2]).to_bytes(2, 'little').hex(' ')}, "
                    f"got {frame[-2:].hex(' ')}",
                    data=frame,
                )
            del buf[:length]
            if self.role is Role.HOST:
                reply = _decode_reply(frame, self._expected)
                self._check_against_expected(reply, frame)
                return reply
            request = _decode_request(frame)
            if length == 8 and frame[1] in _FIXED_REQUEST_FCS:
                if len(_REQUESTS) >= 512:
                    _REQUESTS.clear()
                _REQUESTS[frame] = request
            return request
        return None

    def _next_valid_offset(self, buf: bytearray) -> int:
        """Offset (>0) of the first complete CRC-valid frame after the head, or 0."""
        for off in range(1, len(buf) - 3):
            view = buf[off:]
            n = self._host_length(view) if self.role is Role.HOST else _request_length(view)
            if n and 4 <= n <= len(view) and crc16_modbus(bytes(view[:n])) == 0:
                return off
        return 0

    # -- host helpers --
    def _host_length(self, buf: bytearray) -> int | None:
        exp = self._expected
        if (
            exp is not None
            and isinstance(exp, (ReadHoldingRegisters, ReadInputRegisters))
            and len(buf) >= 3
            and buf[0] == exp.slave
            and buf[1] == exp.function
            and buf[2] != 2 * exp.count
        ):
            # Byte count disagrees with the request: the frame should still be 5 + 2*count long.
            want = 5 + 2 * exp.count
            if len(buf) < want and not self._silent:
                return None
        return _reply_length(buf)

    def _byte_count_mismatch(self, buf: bytearray) -> ByteCountError | None:
        exp = self._expected
        if not isinstance(exp, (ReadHoldingRegisters, ReadInputRegisters)):
            return None
        if len(buf) < 3 or buf[0] != exp.slave or buf[1] != exp.function:
            return None
        want = 5 + 2 * exp.count
        if buf[2] != 2 * exp.count and len(buf) >= want and crc16_modbus(bytes(buf[:want])) == 0:
            frame = bytes(buf[:want])
            del buf[:want]
            self.discarded += want
            return ByteCountError(
                f"reply byte count is {frame[2]} but the frame carries {2 * exp.count} data bytes "
                f"for the {exp.count} registers requested: {frame.hex(' ')}",
                data=frame,
            )
        return None

    def _check_against_expected(self, reply: Reply, frame: bytes) -> None:
        exp = self._expected
        if (
            isinstance(reply, ReadRegistersReply)
            and isinstance(exp, (ReadHoldingRegisters, ReadInputRegisters))
            and reply.slave == exp.slave
            and reply.function == exp.function
            and len(reply.values) != exp.count
        ):
            raise ByteCountError(
                f"asked for {exp.count} registers, reply carries {len(reply.values)}: "
                f"{frame.hex(' ')}",
                data=frame,
            )


# --- the direct path --------------------------------------------------------------------------


_INT = {int}


def _plain_fields(slave: object, address: object, value: object) -> bool:
    return (type(slave) is int and type(address) is int and type(value) is int and 0 <= slave <= 0xFF
            and 0 <= address <= 0xFFFF and 0 <= value <= 0xFFFF)


def _plain_reply(request: object, reply: object) -> bool:
    """Whether ``reply`` crosses the wire unchanged and passes the host's checks against ``request``:
    exactly a reply type with plain in-range ints, whose encoding the host decodes to an equal message."""
    if type(reply) is ReadRegistersReply:
        s, fc, values = reply.slave, reply.function, reply.values
        if (type(s) is not int or type(fc) is not int or type(values) is not tuple or not 0 <= s <= 0xFF
                or (fc != READ_HOLDING_REGISTERS and fc != READ_INPUT_REGISTERS) or not 1 <= len(values) <= MAX_READ):
            return False
        if (isinstance(request, (ReadHoldingRegisters, ReadInputRegisters)) and request.slave == s
                and request.function == fc and request.count != len(values)):
            return False  # the host's byte-count check refuses it
        return set(map(type, values)) == _INT and 0 <= min(values) and max(values) <= 0xFFFF
    if type(reply) is WriteSingleRegisterReply:
        return _plain_fields(reply.slave, reply.address, reply.value)
    if type(reply) is WriteMultipleRegistersReply:
        return _plain_fields(reply.slave, reply.address, reply.count)
    if type(reply) is ExceptionReply:
        s, fc, code = reply.slave, reply.function, reply.code
        return (type(s) is int and type(fc) is int and type(code) is int and 0 <= s <= 0xFF
                and fc in _EXCEPTION_FCS and 0 <= code <= 0xFF)
    return False


def as_received(request: Request | UnsupportedRequest, reply: Reply) -> Reply | FrameError | None:
    """``reply``, sent by a device to a host that sent ``request``, as the host receives it over RTU.

    For the sim's direct path (message objects, no bytes), so that it refuses what the byte path
    refuses: raises the :class:`~joints.errors.EncodeError` the device's :func:`encode` raises for
    a reply it cannot put on the wire; returns the :class:`~joints.errors.FrameError` the host's
    decoder makes of a frame it refuses (a byte count other than the request's, a function code
    no reply has), ``None`` where the frame is garbage to the host, else the (first) decoded reply. A
    plain, well-formed reply (the usual case) is returned as it is, without building its frame.
    """
    if _plain_reply(request, reply):
        return reply
    frame = encode(reply)  # the device's encoder: EncodeError
    codec = ModbusRtuCodec(Role.HOST)
    if isinstance(request, (ReadHoldingRegisters, ReadInputRegisters, WriteSingleRegister, WriteMultipleRegisters)):
        codec.expect_reply_to(request)
    codec.feed(frame)
    codec.flush()  # the line goes silent after the reply
    try:
        return codec.next_message()  # type: ignore[return-value]
    except FrameError as exc:
        return exc
