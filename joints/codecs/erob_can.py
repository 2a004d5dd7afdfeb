"""ZeroErr eRob CAN custom protocol codec, sans-I/O, for both roles (host and drive).

Source: eRunner user manual v1.7 (zh), chapter 7 (tables 7-1 .. 7-12) and the 7.4 examples.
Rule: pure. A frame is python-can's ``can.Message`` (standard 11-bit id, classic CAN, data only);
``encode(message) -> can.Message`` and ``decode(frame, role) -> message`` never touch a bus or a
clock. This module imports python-can, so only CAN code paths import it.

Identifiers (node = the drive's CAN address, 1..127; the manual gives no range, 1..127 is the
CAN node-id range, eRunner scans 1..64 by default, section 3)::

    request  host -> drive   0x640 + node
    reply    drive -> host   0x5C0 + node

Request data, by length (index and subindex 2 bytes big-endian, value 4 bytes big-endian int32)::

    2  index                      Read (7.1.1, table 7-1)  | Command, no parameter (7.3.1, table 7-9)
    4  index subindex             Read with subindex (table 7-2)
    6  index value                Write (7.2.1, table 7-5) | Command with parameter (table 7-10)
    8  index subindex value       Write with subindex (table 7-6)

A 2- or 6-byte frame is a :class:`Command` exactly when its index is one of the command table
7.5.2 (:data:`COMMANDS`: 0x0083 start, 0x0084 stop, 0x00E8 save, 0x0100 enable, 0x014F brake
release), else a :class:`Read`/:class:`Write`; the wire does not say which. A command frame of the
wrong shape (0x0100 without parameter, 0x0083 with one) still decodes as a :class:`Command`, so a
drive can answer it with error 0x0032/0x0033 (appendix 1). An action triggered by writing a
parameter (0x0114 load-side encoder reset, table 7.5.1) is a :class:`Write`.

Reply data::

    1  3E                 Ack: write or command accepted (tables 7-7, 7-11)
    1  80                 ReadFailed: a read failed (table 7-4; no error code)
    3  code(2) 3E         ErrorReply: write/command refused, code from appendix 1 (tables 7-8, 7-12)
    5  value(4) 3E        ValueReply: the value read (table 7-3)

Matching a reply to its request (:func:`answers`): a reply echoes nothing but the node, in its
CAN id (0x5C0 + node); it carries neither index, subindex nor value. So a reply answers a request
when the node is the same and its shape fits: a :class:`ValueReply` answers a :class:`Read`; an
:class:`Ack` answers a :class:`Write` or :class:`Command`; an :class:`ErrorReply` or
:class:`ReadFailed` answers any request (the manual is inconsistent about which error shape a
read gets, ERRATA DOC-EROB-CAN-1, and an error must never be taken for a lost reply). Hence only
one request per node may be outstanding, and the reply to a timed-out request can be taken for
the answer to the next one: a link should drain a node's late replies before its next request.
Drives send several 0x3E for one enable/disable (figures 4-7, 4-21: five and six acks).

Malformed frames raise :class:`~joints.errors.FrameError` subclasses: a data length the role does
not allow is a :class:`~joints.errors.ByteCountError`; an id outside the role's range (or an
extended id, a remote or error frame) and an unknown reply terminator byte are
:class:`~joints.errors.FrameError`. Values are signed int32 on the wire and in messages (the manual
prints every value as int32); unsigned 32-bit quantities are converted by the parameter map
(:mod:`joints.devices.erob.can`).

Errata relied on (tests/data/ERRATA.md): ``erob-can-7.4.1-step11-recv`` (a read reply printed
without its 0x3E terminator, 4 bytes: rejected as a ByteCountError), ``erob-can-7.4.1-step14-send``
and ``erob-can-7.4.3-step11-send`` (disable printed with 7 data bytes: rejected as a
ByteCountError; the corrected frame has 6), DOC-EROB-CAN-1 (error reply shapes, above).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import can

from joints.codecs.modbus import Role
from joints.errors import ByteCountError, EncodeError, FrameError

__all__ = [
    "ACK",
    "COMMANDS",
    "NODE_MAX",
    "NODE_MIN",
    "READ_FAILED",
    "REPLY_BASE",
    "REQUEST_BASE",
    "Ack",
    "Command",
    "ErrorReply",
    "Message",
    "Read",
    "ReadFailed",
    "Reply",
    "Request",
    "Role",
    "ValueReply",
    "Write",
    "answers",
    "decode",
    "decoder_role",
    "encode",
    "reply_id",
    "request_id",
]

REQUEST_BASE = 0x640  #: host -> drive: 0x640 + node (7.1.1)
REPLY_BASE = 0x5C0  #: drive -> host: 0x5C0 + node (7.1.2)
NODE_MIN = 1
NODE_MAX = 127
ACK = 0x3E  #: success terminator (7.1.2 "结束符 3E")
READ_FAILED = 0x80  #: a failed read's only byte (table 7-4)

#: The command table 7.5.2: index -> whether the command takes a 4-byte parameter.
COMMANDS: dict[int, bool] = {
    0x0083: False,  # start motion
    0x0084: False,  # stop motion
    0x00E8: False,  # save parameters
    0x0100: True,  # motor enable (0 = disable, 1 = enable)
    0x014F: False,  # release brake
}

_INT32_MIN = -0x80000000
_INT32_MAX = 0x7FFFFFFF


# --- messages --------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Read:
    """Read a value (tables 7-1, 7-2); answered by :class:`ValueReply`."""

    node: int
    index: int
    subindex: int | None = None


@dataclass(frozen=True, slots=True)
class Write:
    """Write a signed 32-bit value (tables 7-5, 7-6); answered by :class:`Ack`."""

    node: int
    index: int
    value: int
    subindex: int | None = None


@dataclass(frozen=True, slots=True)
class Command:
    """A command of table 7.5.2, with or without its 4-byte parameter; answered by :class:`Ack`."""

    node: int
    index: int
    parameter: int | None = None


@dataclass(frozen=True, slots=True)
class Ack:
    """0x3E: the write or command was accepted."""

    node: int


@dataclass(frozen=True, slots=True)
class ValueReply:
    """The value read (signed int32) followed by 0x3E."""

    node: int
    value: int


@dataclass(frozen=True, slots=True)
class ErrorReply:
    """Error code (appendix 1, see :mod:`joints.devices.erob.can` for the text) followed by 0x3E."""

    node: int
    code: int


@dataclass(frozen=True, slots=True)
class ReadFailed:
    """0x80 alone: a read failed (table 7-4); no code."""

    node: int


Request = Read | Write | Command
Reply = Ack | ValueReply | ErrorReply | ReadFailed
Message = Request | Reply


def request_id(node: int) -> int:
    """CAN id of a request to ``node``."""
    return REQUEST_BASE + _node(node)


def reply_id(node: int) -> int:
    """CAN id of a reply from ``node``."""
    return REPLY_BASE + _node(node)


def decoder_role(arbitration_id: int) -> Role | None:
    """Which role decodes a frame with this id: DEVICE for requests, HOST for replies, None if neither."""
    if REQUEST_BASE + NODE_MIN <= arbitration_id <= REQUEST_BASE + NODE_MAX:
        return Role.DEVICE
    if REPLY_BASE + NODE_MIN <= arbitration_id <= REPLY_BASE + NODE_MAX:
        return Role.HOST
    return None


def answers(request: Request, reply: Reply) -> bool:
    """Whether ``reply`` is the answer to ``request`` (see the module docstring for the rule)."""
    if reply.node != request.node:
        return False
    if isinstance(reply, (ErrorReply, ReadFailed)):
        return True
    if isinstance(reply, ValueReply):
        return isinstance(request, Read)
    return isinstance(request, (Write, Command))  # Ack


# --- encoding --------------------------------------------------------------------------------


def _node(node: int) -> int:
    if type(node) is not int or not NODE_MIN <= node <= NODE_MAX:
        raise EncodeError(f"eRob CAN: node must be an integer {NODE_MIN}..{NODE_MAX}, got {node!r}")
    return node


def _u16(name: str, v: int) -> int:
    if type(v) is not int or not 0 <= v <= 0xFFFF:
        raise EncodeError(f"eRob CAN: {name} must be an integer 0..0xFFFF, got {v!r}")
    return v


def _i32(name: str, v: int) -> int:
    if type(v) is not int or not _INT32_MIN <= v <= _INT32_MAX:
        raise EncodeError(f"eRob CAN: {name} must be a signed 32-bit integer, got {v!r}")
    return v


_H = struct.Struct(">H")
_HH = struct.Struct(">HH")
_HI = struct.Struct(">Hi")
_HHI = struct.Struct(">HHi")
_I = struct.Struct(">i")
_ACK_DATA = bytes((ACK,))
_READ_FAILED_DATA = bytes((READ_FAILED,))


def _frame(arbitration_id: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=arbitration_id, is_extended_id=False, data=data)


def _not_a_command(m: Read | Write) -> None:
    if m.subindex is None and m.index in COMMANDS:
        kind = "Read" if isinstance(m, Read) else "Write"
        raise EncodeError(f"eRob CAN: index 0x{m.index:04X} is a command (table 7.5.2); send a Command, not a {kind}")


def encode(message: Message) -> can.Message:
    """The CAN frame of a request or reply (see the module docstring for the layouts)."""
    if isinstance(message, Read):
        _not_a_command(message)
        index = _u16("index", message.index)
        if message.subindex is None:
            data = _H.pack(index)
        else:
            data = _HH.pack(index, _u16("subindex", message.subindex))
        return _frame(request_id(message.node), data)
    if isinstance(message, Write):
        _not_a_command(message)
        index = _u16("index", message.index)
        value = _i32("value", message.value)
        if message.subindex is None:
            data = _HI.pack(index, value)
        else:
            data = _HHI.pack(index, _u16("subindex", message.subindex), value)
        return _frame(request_id(message.node), data)
    if isinstance(message, Command):
        index = _u16("index", message.index)
        if index not in COMMANDS:
            raise EncodeError(f"eRob CAN: 0x{index:04X} is not a command of table 7.5.2 "
                              f"({', '.join(f'0x{c:04X}' for c in COMMANDS)}); use Read/Write")
        if message.parameter is None:
            data = _H.pack(index)
        else:
            data = _HI.pack(index, _i32("parameter", message.parameter))
        return _frame(request_id(message.node), data)
    if isinstance(message, Ack):
        return _frame(reply_id(message.node), _ACK_DATA)
    if isinstance(message, ValueReply):
        return _frame(reply_id(message.node), _I.pack(_i32("value", message.value)) + _ACK_DATA)
    if isinstance(message, ErrorReply):
        return _frame(reply_id(message.node), _H.pack(_u16("code", message.code)) + _ACK_DATA)
    if isinstance(message, ReadFailed):
        return _frame(reply_id(message.node), _READ_FAILED_DATA)
    raise EncodeError(f"not an eRob CAN message: {message!r}")


# --- decoding --------------------------------------------------------------------------------


def _describe(frame: can.Message) -> str:
    return f"0x{frame.arbitration_id:03X} [{bytes(frame.data).hex(' ').upper()}]"


def _decode_request(node: int, data: bytes, frame: can.Message) -> Request:
    n = len(data)
    if n == 2:
        (index,) = _H.unpack(data)
        return Command(node, index) if index in COMMANDS else Read(node, index)
    if n == 6:
        index, value = _HI.unpack(data)
        return Command(node, index, value) if index in COMMANDS else Write(node, index, value)
    if n == 4:
        index, sub = _HH.unpack(data)
        return Read(node, index, sub)
    if n == 8:
        index, sub, value = _HHI.unpack(data)
        return Write(node, index, value, sub)
    raise ByteCountError(f"eRob CAN request {_describe(frame)}: {n} data bytes; a request has 2 (read/command), "
                         f"4 (read with subindex), 6 (write/command with parameter) or 8 (write with subindex)",
                         data=data)


def _decode_reply(node: int, data: bytes, frame: can.Message) -> Reply:
    n = len(data)
    if n == 1:
        if data[0] == ACK:
            return Ack(node)
        if data[0] == READ_FAILED:
            return ReadFailed(node)
        raise FrameError(f"eRob CAN reply {_describe(frame)}: a 1-byte reply is 0x3E (ok) or 0x80 (read failed)",
                         data=data)
    if n not in (3, 5):
        raise ByteCountError(f"eRob CAN reply {_describe(frame)}: {n} data bytes; a reply has 1 (0x3E/0x80), "
                             f"3 (error code + 0x3E) or 5 (value + 0x3E)", data=data)
    if data[-1] != ACK:
        raise FrameError(f"eRob CAN reply {_describe(frame)}: ends in 0x{data[-1]:02X}, expected the terminator 0x3E",
                         data=data)
    if n == 5:
        return ValueReply(node, _I.unpack_from(data)[0])
    return ErrorReply(node, _H.unpack_from(data)[0])


def decode(frame: can.Message, role: Role) -> Message:
    """The message of a frame: requests in the DEVICE role, replies in the HOST role.

    Raises a :class:`~joints.errors.FrameError` subclass for a frame that is not a well-formed
    message of this protocol in that role (see the module docstring).
    """
    data = bytes(frame.data)
    if frame.is_extended_id or frame.is_remote_frame or frame.is_error_frame or frame.is_fd:
        kind = ("an extended-id" if frame.is_extended_id else "a remote" if frame.is_remote_frame
                else "an error" if frame.is_error_frame else "a CAN FD")
        raise FrameError(f"eRob CAN: {kind} frame (0x{frame.arbitration_id:X}) is not part of the protocol",
                         data=data)
    if frame.dlc != len(data):
        raise ByteCountError(f"eRob CAN frame {_describe(frame)}: DLC {frame.dlc} but {len(data)} data bytes",
                             data=data)
    if role is Role.HOST:
        node = frame.arbitration_id - REPLY_BASE
        if not NODE_MIN <= node <= NODE_MAX:
            raise FrameError(f"eRob CAN: 0x{frame.arbitration_id:03X} is not a reply id "
                             f"(0x{REPLY_BASE + NODE_MIN:03X}..0x{REPLY_BASE + NODE_MAX:03X})", data=data)
        return _decode_reply(node, data, frame)
    node = frame.arbitration_id - REQUEST_BASE
    if not NODE_MIN <= node <= NODE_MAX:
        raise FrameError(f"eRob CAN: 0x{frame.arbitration_id:03X} is not a request id "
                         f"(0x{REQUEST_BASE + NODE_MIN:03X}..0x{REQUEST_BASE + NODE_MAX:03X})", data=data)
    return _decode_request(node, data, frame)
