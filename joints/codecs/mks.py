"""MKS SERVO42D/57D native RS485 protocol codec, sans-I/O, for both roles (host and device).

Rule: ``encode(message) -> bytes`` is pure; decoding is ``feed(bytes)`` then ``next_message()``
until it returns ``None`` (need more bytes). Same object model as :mod:`joints.codecs.modbus`:
frozen messages, resynchronisation by dropping one byte, ``flush()`` when the line went silent,
``clear()``. Source: mks-servo42d-57d-rs485-manual-v1.0.5, Part 4 (frame), Part 5 (parameter
commands), Part 6 (run commands), 5.7 (long data package).

Frames (every multi-byte field big-endian; ``chk`` = sum of all previous bytes & 0xFF)::

    downlink   FA addr code data... chk        host -> drive          (decoded in Role.DEVICE)
    uplink     FB addr code data... chk        drive -> host          (decoded in Role.HOST)
    long       FC [addr code data 0...]x5 chk  host -> drives, 52 B   (decoded in Role.DEVICE)

Frame length = 4 + the data length, which the head, the role and the function code determine
(the frame has no length field):

* downlink (FA): 0 data bytes for 0x30-0x34, 0x39-0x3B, 0x3D-0x3F, 0x40, 0x41, 0x91, 0x92, 0xF1,
  0xF7; 1 for 0x80, 0x82, 0x84-0x8B, 0x8D-0x8F, 0x9B, 0x9E, 0xF3, 0xFF; 2 for 0x83, 0x8C; 3 for
  0xF6; 4 for 0x98, 0x9A; 5 for 0x90; 7 for 0x94, 0xF4, 0xF5, 0xFD, 0xFE (:data:`REQUEST_DATA_LENGTH`).
* uplink (FB): 6 data bytes for 0x30 and 0x31, 2 for 0x32, 4 for 0x33, 0x39 and 0x40, 1 (a status
  byte) for every other command (:data:`REPLY_DATA_LENGTH`).

Commands of later firmware (manual V1.0.9; a drive before it does not answer them): 0x40 read
version information (5.1.11; reply: calibration status in b7-b4 and hardware version in b3-b0 of
byte 4, firmware version in bytes 5-7 - read as major, minor, patch, our reading), 0x98 heartbeat
protection time (5.2.16; uint32 ms, 0 = off; answered by a set status); 0x9D sets the position-error protection (5 data bytes: b1 g0Enable En-triggered zero
return and b0 enable, reserved b7-b2; uint16 Tim, uint16 Errors; set status). V1.0.8's 0x95 sets
the position-reached threshold (enable byte, uint16 values; set status); 0x4A sets the synchronization
flag (1 byte; set status) and 0x4B (no data, address 0, never answered) starts the held run commands,
which a drive with the flag on answers with run status 5. 0x50 IAP control (1 byte cmd; set status). 0x96 / 0x97
PID parameters (4 x uint16; set status). V1.0.9's 0x99 pulse divider output (divLevel byte, uint32
divPeriod) and 0x9F IN_1 port mode (1 byte), both answered by a set status. Manual V1.0.6 added 0x46
write all configuration parameters (34 data bytes; set status), 0x47 read all configuration
parameters and 0x48 read all status parameters (replies of 34 and 28 data bytes): the codec keeps
their data as bytes (``params``), :mod:`joints.devices.mks.blocks` names the fields; 0x35 reads the
raw accumulated encoder value (int48 like 0x31); 0x36 writes the IO port (1 data byte: b7-b6
OUT2_mask, b5-b4 OUT1_mask, b3 OUT_2, b2 OUT_1, b1-b0 zero; a mask of 3 or a reserved bit set is a
:class:`~joints.errors.FrameError`; set status). V1.0.9's
0x01 (5.1.9) asks the drive to send one read command's reply every ``times`` ms (0 stops it):
request code + uint16 times, reply code + status; the periodic frames are that command's ordinary
replies (FB addr code param chk), arriving unsolicited.
* The 0x3B reply carries one status (before V1.0.7) or two (single-turn, then homing): told apart by
  the values (statuses are 0-2, see :func:`_zero_status_length`).
* Two forms (V1.0.7): 0xF6 carries 3 data bytes, or 7 with a runTime; 0x83 2, or 3 with a trailing 00
  (the current changed while running, not saved; answered with status 2, which no other set command
  has); 0x91 none, or 1 goZeroMode (V1.0.9: 00 origin homing, as without it; 01 coordinate homing);
  0x42 none (read the user ID) or 4 (write it) (:data:`REQUEST_LONG_DATA_LENGTH`).
* Replies the request decides (host role, :meth:`MksCodec.expect_reply`, told by the link): 0x00's
  (V1.0.8) is headed by the code of the parameter read, with that set command's data (or FF FF, "not
  readable"): :class:`ParameterReply`; 0x42's is the 4-byte ID after a read, a set status after a write.
  The device side takes the long form when its frame is there, checksum-valid and plausible (runTime
  <= 0x0FFFFFFF: the next frame's head FA/FB/FC can never pass as its first byte), else the short
  one: at once when its checksum byte cannot be a runTime's first byte (above 0x0F: 15 in 16 frames),
  else at silence or once more bytes arrived (the twins' lines report silence after every frame).
* long packet (FC): always 52 bytes: five 10-byte slots, each an ordinary command without head
  and checksum (address, code, data) padded with zeros; an all-zero slot is an unused slot (None).

Unknown function codes
    Device role: an FA frame with a code the manual does not define is delimited by its checksum:
    the shortest length from 4 to 11 bytes (the longest fixed command frame) whose last byte is the
    checksum of the bytes before it. It comes out as :class:`UnknownRequest` (a twin ignores it;
    the drive's firmware does not document an answer). With no match in 11 bytes, or at silence,
    the FA byte is garbage. Checksum-8 makes this a guess: 1 in 256 per candidate length matches
    by chance. In a long-packet slot an unknown command's data is the whole 8-byte remainder.
    Host role: an FB frame with an unknown code cannot answer anything a host sent, so its head
    byte is skipped as garbage (no waiting on a length nobody knows).

Errors
    A checksum mismatch on a frame of known length drops its first byte and raises
    :class:`~joints.errors.ChecksumError`: call ``next_message()`` again to resynchronise. Bytes
    that cannot start a frame of the codec's direction (other heads, the other direction's frames,
    unknown host-side codes) are skipped silently and counted in :attr:`MksCodec.discarded`. A
    checksum-valid frame whose fields break the manual (an undocumented status or boolean value,
    reserved bits of the speed field set, a calibrate data byte other than 00, non-zero padding
    in a long-packet slot) is consumed whole and raises :class:`~joints.errors.FrameError`. At
    silence an incomplete frame is dropped (raising ``FrameError`` "truncated" when no valid frame
    follows it in the buffer, like the Modbus codec).

Addresses
    ``address`` is the frame's address byte as sent: 0 is the broadcast address
    (:data:`BROADCAST`), 1-255 a slave *or* a group address (0x8D). Both look the same on the
    wire; which addresses are groups is bus configuration, not codec business. Broadcast, group
    and long-packet frames get no reply (manual 5.2 #16, 5.7 note 5, Part 4).

Typed fields
    Requests keep setting values as the raw integers of the manual (a twin judges them and answers
    "set fail"); only packed fields are unpacked: direction bit + 12-bit speed (0xF6, 0xFD),
    uint32 pulses (0xFD), int32 absolute pulses / axis (0xFE, 0xF4, 0xF5), and the subdivision
    byte. Replies carry typed values: int32 carry + uint16 value (0x30), int48 addition (0x31),
    int16 rpm, int32 pulses, int32 angle error (51200 per turn), and status/result codes as Enums.
    Run commands (0xF4, 0xF5, 0xF6, 0xFD, 0xFE, 0x91 go home, 0xFF save/clean) all answer with
    :class:`RunReply`: the immediate reply (0 fail / 1 started) and a later completion frame
    (2 complete / 3 end-limit stop) differ only in :class:`RunStatus`; :attr:`RunReply.is_completion`
    tells them apart for a link rule.

Choices where the manual is silent or inconsistent
    * Subdivision (0x84) is one byte "micstep(00~FF)" but the drive supports 1-256: the byte 0x00
      carries 256 (the only way to send it); :class:`SetSubdivision` holds the microstep count.
    * The 0xF6/0xFD speed field is 12 bits (0-4095 on the wire); the manual's range is 0-3000.
      The codec encodes what the wire can carry; ranges are the parameters' business
      (:mod:`joints.devices.mks.params`). Speeds above the mode's maximum are clamped by the drive.
    * Run statuses are accepted for every run command although the manual lists 3 (end-limit
      stop) only for the position modes and 2 for the speed mode only after a stop: the meaning
      of each value is the same for all of them.
    * Encoder value (0x30) outside 0..0x3FFF and reserved IO bits are passed through, not rejected
      (measurements, no ambiguity).
    * The 0xF1 status 5/6 follows Part 8 (5 homing, 6 calibrating); 6.2 prints 5 twice (ERRATA
      DOC-MKS-3). 0x33 pulses are int32 as in 5.1 (Part 8 says uint32, DOC-MKS-4).
    * The 0x32 reply carries function code 0x32 like every reply echoes its request's code (the
      5.1 table prints 31, DOC-MKS-2).
    * 0xFF save/clean and a 0xF6 stop answer 0 fail / 1 start / 2 success (6.5 tables), although
      7.4 calls the 01 replies "successful" (DOC-MKS-12; vectors mks-native-7.4-step2/3-recv).
    * Frames printed without checksum (Part 7 examples, the "CRC" placeholders of 5.x) are
      completed with :func:`with_checksum`; the 50-byte long-packet log line of 5.7 lacks two
      padding bytes (ERRATA mks-native-5.7-longpacket-log-send): a long packet is always 52 bytes.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar

from joints.codecs.echo import echo_length
from joints.codecs.modbus import Role
from joints.errors import ChecksumError, EncodeError, FrameError

__all__ = [
    "BROADCAST",
    "HEAD_DOWNLINK",
    "HEAD_LONG",
    "HEAD_UPLINK",
    "LONG_PACKET_LENGTH",
    "REPLY_DATA_LENGTH",
    "REPLY_TYPES",
    "REQUEST_DATA_LENGTH",
    "REQUEST_TYPES",
    "CalibrationStatus",
    "GoBackToZeroStatus",
    "MksCodec",
    "MotorStatus",
    "Role",
    "RunDirection",
    "RunStatus",
    "SetStatus",
    "checksum",
    "checksum_ok",
    "encode",
    "parameter_request",
    "with_checksum",
]

HEAD_DOWNLINK = 0xFA  #: host -> drive
HEAD_UPLINK = 0xFB  #: drive -> host
HEAD_LONG = 0xFC  #: long data package, host -> drives
BROADCAST = 0  #: every drive executes, none answers
LONG_PACKET_SLOTS = 5
LONG_PACKET_SLOT = 10
LONG_PACKET_LENGTH = 1 + LONG_PACKET_SLOTS * LONG_PACKET_SLOT + 1  #: 52
MIN_FRAME = 4  #: head, address, code, checksum
MAX_DOWNLINK_FRAME = 38  #: 0x46 (V1.0.6)
MAX_UPLINK_FRAME = 38  #: 0x47 (V1.0.6)
#: the longest frame an unknown code is searched for (the longest fixed command frame: 0x94, 0xF4, 0xF5, 0xFD, 0xFE)
MAX_UNKNOWN_FRAME = 11
SPEED_FIELD_MAX = 0x0FFF  #: 12-bit speed of 0xF6/0xFD
ENCODER_COUNTS_PER_TURN = 0x4000  #: encoder value range of one turn (0x30, 0x31)
ANGLE_ERROR_PER_TURN = 51200  #: 0x39: 0..51200 = 0..360 degrees


def checksum(data: bytes | bytearray | memoryview) -> int:
    """CHECKSUM-8: the sum of ``data`` & 0xFF (manual Part 4)."""
    return sum(data) & 0xFF


def with_checksum(body: bytes | bytearray) -> bytes:
    """``body`` followed by its checksum (completes a frame printed without one)."""
    return bytes(body) + bytes((sum(body) & 0xFF,))


def checksum_ok(frame: bytes | bytearray | memoryview) -> bool:
    """True if the last byte is the checksum of the bytes before it."""
    return len(frame) >= 2 and sum(frame[:-1]) & 0xFF == frame[-1]


# --- status and result codes ----------------------------------------------------------------


class SetStatus(enum.IntEnum):
    """Reply of the set commands (5.2-5.6), 0x3D release, 0xF3 enable, 0xF7 emergency stop."""

    FAIL = 0
    SUCCESS = 1
    SUCCESS_UNSAVED = 2  #: 0x83 only (V1.0.7): the working current changed, not saved


class RunStatus(enum.IntEnum):
    """Reply and completion status of run commands (6.5-6.9), 0x91 go home, 0xFF save/clean."""

    FAIL = 0  #: run / stop / home / save failed
    STARTED = 1  #: run starting, stop starting, go home start, save start (immediate reply)
    COMPLETE = 2  #: run complete, stop complete, go home success, save success (later frame)
    END_LIMIT_STOP = 3  #: an end-limit switch stopped the motion (later frame)
    SYNC_RECEIVED = 5  #: V1.0.8 (0x4A on): "Data has received for Synchronous mode" - held until 0x4B (immediate)


class CalibrationStatus(enum.IntEnum):
    """Reply of 0x80 calibrate (5.2 #1)."""

    CALIBRATING = 0
    SUCCESS = 1
    FAIL = 2


class GoBackToZeroStatus(enum.IntEnum):
    """Reply of 0x3B: the power-on 0_Mode return (5.1 #8)."""

    GOING = 0
    SUCCESS = 1
    FAIL = 2


class MotorStatus(enum.IntEnum):
    """Reply of 0xF1 query (6.2 #1; 6 from Part 8 #10, ERRATA DOC-MKS-3)."""

    FAIL = 0  #: query fail
    STOP = 1
    SPEED_UP = 2
    SPEED_DOWN = 3
    FULL_SPEED = 4
    HOMING = 5
    CALIBRATING = 6


class RunDirection(enum.IntEnum):
    """Direction bit of 0xF6/0xFD: "dir: the value range is 0/1 (CCW/CW)" (6.5, 6.6)."""

    CCW = 0  #: "forward" in the manual's examples; positive speed (0x32)
    CW = 1  #: "reverse"


# --- requests (downlink, head 0xFA) ---------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ReadEncoderCarry:
    """0x30 read the encoder value (carry) -> :class:`EncoderCarryReply`."""

    address: int
    function: ClassVar[int] = 0x30


@dataclass(frozen=True, slots=True)
class ReadEncoderAddition:
    """0x31 read the encoder value (addition) -> :class:`EncoderAdditionReply`."""

    address: int
    function: ClassVar[int] = 0x31


@dataclass(frozen=True, slots=True)
class ReadSpeed:
    """0x32 read the real-time speed (rpm) -> :class:`SpeedReply`."""

    address: int
    function: ClassVar[int] = 0x32


@dataclass(frozen=True, slots=True)
class ReadPulses:
    """0x33 read the number of pulses received -> :class:`PulsesReply`."""

    address: int
    function: ClassVar[int] = 0x33


@dataclass(frozen=True, slots=True)
class ReadIoStatus:
    """0x34 read the IO ports status -> :class:`IoStatusReply`."""

    address: int
    function: ClassVar[int] = 0x34


@dataclass(frozen=True, slots=True)
class ReadAngleError:
    """0x39 read the error of the motor shaft angle -> :class:`AngleErrorReply`."""

    address: int
    function: ClassVar[int] = 0x39


@dataclass(frozen=True, slots=True)
class ReadEnPin:
    """0x3A read the En pins status -> :class:`EnPinReply`."""

    address: int
    function: ClassVar[int] = 0x3A


@dataclass(frozen=True, slots=True)
class ReadGoBackToZeroStatus:
    """0x3B read the go back to zero status when power on -> :class:`GoBackToZeroStatusReply`."""

    address: int
    function: ClassVar[int] = 0x3B


@dataclass(frozen=True, slots=True)
class ReleaseProtection:
    """0x3D release the motor shaft locked-rotor protection state -> :class:`SetReply`."""

    address: int
    function: ClassVar[int] = 0x3D


@dataclass(frozen=True, slots=True)
class ReadProtectionState:
    """0x3E read the motor shaft protection state -> :class:`ProtectionStateReply`."""

    address: int
    function: ClassVar[int] = 0x3E


@dataclass(frozen=True, slots=True)
class RestoreDefaults:
    """0x3F restore the default parameters (the drive reboots and needs calibrating) -> :class:`SetReply`."""

    address: int
    function: ClassVar[int] = 0x3F


@dataclass(frozen=True, slots=True)
class Restart:
    """0x41 restart the motor -> :class:`SetReply`."""

    address: int
    function: ClassVar[int] = 0x41


@dataclass(frozen=True, slots=True)
class Calibrate:
    """0x80 calibrate the encoder (data byte 00; moves the shaft) -> :class:`CalibrationReply`."""

    address: int
    function: ClassVar[int] = 0x80


@dataclass(frozen=True, slots=True)
class SetWorkMode:
    """0x82 set the work mode: 0 CR_OPEN, 1 CR_CLOSE, 2 CR_vFOC, 3 SR_OPEN, 4 SR_CLOSE, 5 SR_vFOC."""

    address: int
    mode: int
    function: ClassVar[int] = 0x82


@dataclass(frozen=True, slots=True)
class SetWorkingCurrent:
    """0x83 set the working current "Ma" [mA] (uint16). ``unsaved`` (V1.0.7): the frame carries a trailing
    00 - change the current while running, not saved (answered with status 2)."""

    address: int
    current: int
    unsaved: int = 0
    function: ClassVar[int] = 0x83


@dataclass(frozen=True, slots=True)
class SetHoldingCurrent:
    """0x9B set the holding current percentage: hold 0 = 10 % ... 8 = 90 %."""

    address: int
    hold: int
    function: ClassVar[int] = 0x9B


@dataclass(frozen=True, slots=True)
class SetSubdivision:
    """0x84 set subdivision "MStep": microsteps 1-256 (256 travels as the byte 0x00)."""

    address: int
    microsteps: int
    function: ClassVar[int] = 0x84


@dataclass(frozen=True, slots=True)
class SetEnActive:
    """0x85 set the active level of the En pin: 0 low (L), 1 high (H), 2 always (Hold)."""

    address: int
    level: int
    function: ClassVar[int] = 0x85


@dataclass(frozen=True, slots=True)
class SetDirection:
    """0x86 set the direction of motor rotation (pulse interface): 0 CW, 1 CCW."""

    address: int
    direction: int
    function: ClassVar[int] = 0x86


@dataclass(frozen=True, slots=True)
class SetAutoScreenOff:
    """0x87 set auto turn off the screen: 1 enabled, 0 disabled."""

    address: int
    enable: int
    function: ClassVar[int] = 0x87


@dataclass(frozen=True, slots=True)
class SetLockedRotorProtection:
    """0x88 set the motor shaft locked-rotor protection: 1 enabled, 0 disabled."""

    address: int
    enable: int
    function: ClassVar[int] = 0x88


@dataclass(frozen=True, slots=True)
class SetSubdivisionInterpolation:
    """0x89 set the subdivision interpolation (MPlyer): 1 enabled, 0 disabled."""

    address: int
    enable: int
    function: ClassVar[int] = 0x89


@dataclass(frozen=True, slots=True)
class SetBaudRate:
    """0x8A set the baud rate: 1 9600, 2 19200, 3 25000, 4 38400, 5 57600, 6 115200, 7 256000."""

    address: int
    baud: int
    function: ClassVar[int] = 0x8A


@dataclass(frozen=True, slots=True)
class SetSlaveAddress:
    """0x8B set the slave address (00-FF; 0 is the broadcast address)."""

    address: int
    new_address: int
    function: ClassVar[int] = 0x8B


@dataclass(frozen=True, slots=True)
class SetRespondActive:
    """0x8C set the slave respond (replies to run commands) and active (completion frames)."""

    address: int
    respond: int
    active: int
    function: ClassVar[int] = 0x8C


@dataclass(frozen=True, slots=True)
class SetGroupAddress:
    """0x8D set the group address (01-FF)."""

    address: int
    group: int
    function: ClassVar[int] = 0x8D


@dataclass(frozen=True, slots=True)
class SetModbusRtu:
    """0x8E enable (1) or disable (0) the Modbus-RTU protocol (the drive then speaks Part 8 only)."""

    address: int
    enable: int
    function: ClassVar[int] = 0x8E


@dataclass(frozen=True, slots=True)
class SetKeyLock:
    """0x8F lock (1) or unlock (0) the keys."""

    address: int
    lock: int
    function: ClassVar[int] = 0x8F


@dataclass(frozen=True, slots=True)
class SetHomeParameters:
    """0x90 set the parameter of home: HmTrig (0 low, 1 high), HmDir (0 CW, 1 CCW), HmSpeed [rpm], EndLimit."""

    address: int
    trigger_level: int
    direction: int
    speed: int
    end_limit: int
    function: ClassVar[int] = 0x90


@dataclass(frozen=True, slots=True)
class GoHome:
    """0x91 go home -> :class:`RunReply` (1 start, later 2 success). ``mode`` (goZeroMode, V1.0.9 7.3.6): 0
    "origin homing" (the frame without the byte, or with 00), 1 "coordinate homing" (``FA 01 91 01 8D``)."""

    address: int
    mode: int = 0
    function: ClassVar[int] = 0x91


@dataclass(frozen=True, slots=True)
class SetAxisZero:
    """0x92 set the current axis to zero ("GoHome" without running the motor)."""

    address: int
    function: ClassVar[int] = 0x92


@dataclass(frozen=True, slots=True)
class SetNoLimitHomeParameters:
    """0x94 "noLimit" go home: reverse angle (retValue, 0x4000 = 360 degrees), hm-Mode, Hm_Ma [mA]."""

    address: int
    reverse_angle: int
    mode: int
    current: int
    function: ClassVar[int] = 0x94


@dataclass(frozen=True, slots=True)
class SetZeroMode:
    """0x9A set the parameter of 0_Mode: mode (0 Disable, 1 DirMode, 2 NearMode), Set 0, 0_Speed 0-4, 0_Dir."""

    address: int
    mode: int
    set_zero: int
    speed: int
    direction: int
    function: ClassVar[int] = 0x9A


@dataclass(frozen=True, slots=True)
class ReadRawEncoder:
    """0x35 read the raw accumulated multi-turn encoder value (V1.0.6) -> :class:`RawEncoderReply`."""

    address: int
    function: ClassVar[int] = 0x35


@dataclass(frozen=True, slots=True)
class SetTimedReturn:
    """0x01 return the reply of read command ``code`` every ``times`` ms, unasked (V1.0.9; 0 stops it)."""

    address: int
    code: int
    times: int
    function: ClassVar[int] = 0x01


@dataclass(frozen=True, slots=True)
class ReadParameter:
    """0x00 read a configuration parameter (V1.0.8, 5.1.10): ``code`` is the set command's function code ->
    :class:`ParameterReply` headed by ``code`` (the host codec must be told: :meth:`MksCodec.expect_reply`)."""

    address: int
    code: int
    function: ClassVar[int] = 0x00


@dataclass(frozen=True, slots=True)
class UserId:
    """0x42 user ID (V1.0.9, 5.1.12): ``id`` None reads it (no data) -> :class:`UserIdReply`; a uint32 writes
    it (4 data bytes) -> set status. The host codec is told which (:meth:`MksCodec.expect_reply`)."""

    address: int
    id: int | None = None
    function: ClassVar[int] = 0x42


@dataclass(frozen=True, slots=True)
class ReadVersion:
    """0x40 read version information (V1.0.9) -> :class:`VersionReply`."""

    address: int
    function: ClassVar[int] = 0x40


@dataclass(frozen=True, slots=True)
class SetHeartbeat:
    """0x98 heartbeat protection time [ms] (V1.0.9): no command for this long -> urgent stop; 0 = off."""

    address: int
    times: int
    function: ClassVar[int] = 0x98


@dataclass(frozen=True, slots=True)
class WriteIoPort:
    """0x36 write the IO port (V1.0.6): per output a mask (0 do not write, 1 write the value, 2 keep) and a
    value 0/1; one byte b7-b6 OUT2_mask, b5-b4 OUT1_mask, b3 OUT_2, b2 OUT_1, b1-b0 0 -> set status."""

    address: int
    out2_mask: int
    out1_mask: int
    out2: int
    out1: int
    function: ClassVar[int] = 0x36


@dataclass(frozen=True, slots=True)
class SetPositionErrorProtection:
    """0x9D (V1.0.6) position-error protection: byte 4 b1 g0Enable (En-triggered single-turn zero return),
    b0 Enble (protection on), then Tim (uint16, ~15 ms each) and Errors (uint16, 28000 = 360 degrees)."""

    address: int
    en_zero_return: int
    enable: int
    time: int
    errors: int
    function: ClassVar[int] = 0x9D


@dataclass(frozen=True, slots=True)
class SetPositionThreshold:
    """0x95 (V1.0.8) position-reached threshold: enable (1 default) and values (uint16, 65535 = 360 degrees)."""

    address: int
    enable: int
    values: int
    function: ClassVar[int] = 0x95


@dataclass(frozen=True, slots=True)
class SetSync:
    """0x4A (V1.0.8) synchronization flag: 1 = run commands wait for 0x4B (answered status 5) -> set status."""

    address: int
    enable: int
    function: ClassVar[int] = 0x4A


@dataclass(frozen=True, slots=True)
class SyncExecute:
    """0x4B (V1.0.8) synchronous execution: every drive starts its held run command; sent to address 0, no
    reply ("Returned data: None")."""

    address: int
    function: ClassVar[int] = 0x4B


@dataclass(frozen=True, slots=True)
class IapControl:
    """0x50 (V1.0.8) IAP control: cmd 1 enter the boot loader, 2 enter / 3 leave the silent state -> set status
    (0 "reset failed", 1 "reset successful")."""

    address: int
    cmd: int
    function: ClassVar[int] = 0x50


@dataclass(frozen=True, slots=True)
class SetVfocPid:
    """0x96 (V1.0.8) vFOC mode PID parameters Kp Ki Kd Kv (uint16 each, 0-1024) -> set status."""

    address: int
    kp: int
    ki: int
    kd: int
    kv: int
    function: ClassVar[int] = 0x96


@dataclass(frozen=True, slots=True)
class SetPulseDivider:
    """0x99 (V1.0.9, 6.4) OUT_2 as a pulse divider output (57D): divLevel (start level 0/1), divPeriod (uint32
    pulses; below 100 no output) -> set status."""

    address: int
    level: int
    period: int
    function: ClassVar[int] = 0x99


@dataclass(frozen=True, slots=True)
class SetIn1PortMode:
    """0x9F (V1.0.9, 6.2) IN_1 port mode (28D/35D/42D): type 0 input (default), 1 output -> set status."""

    address: int
    type: int
    function: ClassVar[int] = 0x9F


@dataclass(frozen=True, slots=True)
class SetClosePid:
    """0x97 (V1.0.8) CLOSE mode PID parameters Kp Ki Kd Kv (uint16 each, 0-1024) -> set status."""

    address: int
    kp: int
    ki: int
    kd: int
    kv: int
    function: ClassVar[int] = 0x97


@dataclass(frozen=True, slots=True)
class WriteAllParameters:
    """0x46 write all configuration parameters (V1.0.6): the 34 bytes of 5.7.1 -> set status."""

    address: int
    params: bytes
    function: ClassVar[int] = 0x46


@dataclass(frozen=True, slots=True)
class ReadAllParameters:
    """0x47 read all configuration parameters (V1.0.6) -> :class:`AllParametersReply`."""

    address: int
    function: ClassVar[int] = 0x47


@dataclass(frozen=True, slots=True)
class ReadAllStatus:
    """0x48 read all status parameters (V1.0.6) -> :class:`AllStatusReply`."""

    address: int
    function: ClassVar[int] = 0x48


@dataclass(frozen=True, slots=True)
class SetLimitPortRemap:
    """0x9E remap the limit ports (left -> En, right -> Dir): 1 enable, 0 disable."""

    address: int
    enable: int
    function: ClassVar[int] = 0x9E


@dataclass(frozen=True, slots=True)
class QueryStatus:
    """0xF1 query the motor status -> :class:`MotorStatusReply`."""

    address: int
    function: ClassVar[int] = 0xF1


@dataclass(frozen=True, slots=True)
class EnableMotor:
    """0xF3 enable (1) or disable (0) the motor (serial modes)."""

    address: int
    enable: int
    function: ClassVar[int] = 0xF3


@dataclass(frozen=True, slots=True)
class EmergencyStop:
    """0xF7 emergency stop the motor."""

    address: int
    function: ClassVar[int] = 0xF7


@dataclass(frozen=True, slots=True)
class RunSpeed:
    """0xF6 run in speed mode; speed 0 stops (acc 0: at once, else decelerating) -> :class:`RunReply`.

    ``run_time`` (V1.0.7, units of 10 ms, up to 0x0FFFFFFF): the drive stops by itself after it; 0 sends
    the frame without it (a frame carrying runTime 0 decodes to 0 too)."""

    address: int
    direction: RunDirection
    speed: int  #: rpm (12 bits on the wire)
    acc: int
    run_time: int = 0
    function: ClassVar[int] = 0xF6

    @property
    def is_stop(self) -> bool:
        return self.speed == 0


@dataclass(frozen=True, slots=True)
class SaveCleanSpeedMode:
    """0xFF save (state 0xC8) or clean (0xCA) the speed-mode parameters run at power-on."""

    address: int
    state: int
    function: ClassVar[int] = 0xFF


@dataclass(frozen=True, slots=True)
class RunRelativePulses:
    """0xFD position mode1: relative motion by pulses (microsteps); speed 0 stops -> :class:`RunReply`."""

    address: int
    direction: RunDirection
    speed: int  #: rpm (12 bits on the wire)
    acc: int
    pulses: int  #: uint32
    function: ClassVar[int] = 0xFD

    @property
    def is_stop(self) -> bool:
        return self.speed == 0


@dataclass(frozen=True, slots=True)
class RunAbsolutePulses:
    """0xFE position mode2: absolute motion by pulses (absPulses, int32); speed 0 stops."""

    address: int
    speed: int
    acc: int
    abs_pulses: int
    function: ClassVar[int] = 0xFE

    @property
    def is_stop(self) -> bool:
        return self.speed == 0


@dataclass(frozen=True, slots=True)
class RunRelativeAxis:
    """0xF4 position mode3: relative motion by axis (relAxis, encoder counts, int32); speed 0 stops."""

    address: int
    speed: int
    acc: int
    rel_axis: int
    function: ClassVar[int] = 0xF4

    @property
    def is_stop(self) -> bool:
        return self.speed == 0


@dataclass(frozen=True, slots=True)
class RunAbsoluteAxis:
    """0xF5 position mode4: absolute motion by axis (absAxis, int32); updates a running move; speed 0 stops."""

    address: int
    speed: int
    acc: int
    abs_axis: int
    function: ClassVar[int] = 0xF5

    @property
    def is_stop(self) -> bool:
        return self.speed == 0


@dataclass(frozen=True, slots=True)
class UnknownRequest:
    """A downlink frame with a function code the manual does not define (device role).

    ``data`` is what lies between code and checksum (FA frames: delimited by the checksum, see
    the module docstring; long-packet slots: the 8 bytes after the code).
    """

    address: int
    function: int
    data: bytes


Request = (
    ReadEncoderCarry | ReadEncoderAddition | ReadSpeed | ReadPulses | ReadIoStatus | ReadAngleError | ReadEnPin
    | ReadGoBackToZeroStatus | ReleaseProtection | ReadProtectionState | RestoreDefaults | Restart | Calibrate
    | SetWorkMode | SetWorkingCurrent | SetHoldingCurrent | SetSubdivision | SetEnActive | SetDirection
    | SetAutoScreenOff | SetLockedRotorProtection | SetSubdivisionInterpolation | SetBaudRate | SetSlaveAddress
    | SetRespondActive | SetGroupAddress | SetModbusRtu | SetKeyLock | SetHomeParameters | GoHome | SetAxisZero
    | SetNoLimitHomeParameters | SetZeroMode | SetLimitPortRemap | QueryStatus | EnableMotor | EmergencyStop
    | RunSpeed | SaveCleanSpeedMode | RunRelativePulses | RunAbsolutePulses | RunRelativeAxis | RunAbsoluteAxis
    | ReadRawEncoder | SetTimedReturn | ReadVersion | SetHeartbeat | WriteAllParameters | ReadAllParameters | ReadAllStatus
    | WriteIoPort | SetPositionErrorProtection | SetPositionThreshold | SetSync | SyncExecute | IapControl
    | SetVfocPid | SetClosePid | ReadParameter | UserId | SetPulseDivider | SetIn1PortMode
)


@dataclass(frozen=True, slots=True)
class LongPacket:
    """0xFC long data package: up to five commands for different slaves; no drive answers (5.7).

    ``commands`` always holds five slots after construction (missing ones become ``None``, an
    all-zero slot on the wire). If two slots address the same slave only the first is executed.
    """

    commands: tuple[Request | UnknownRequest | None, ...]

    def __post_init__(self) -> None:
        cmds = tuple(self.commands)
        if len(cmds) < LONG_PACKET_SLOTS:
            cmds += (None,) * (LONG_PACKET_SLOTS - len(cmds))
        object.__setattr__(self, "commands", cmds)

    def command_for(self, *addresses: int) -> Request | UnknownRequest | None:
        """The command a drive answering to ``addresses`` executes: the first slot addressed to one
        of them (5.7 note 4: of two slots for the same slave only the first is executed)."""
        for cmd in self.commands:
            if cmd is not None and cmd.address in addresses:
                return cmd
        return None


# --- replies (uplink, head 0xFB) ------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class EncoderCarryReply:
    """0x30: ``carry`` (int32, turns) and ``value`` (uint16, 0..0x3FFF within the turn)."""

    address: int
    carry: int
    value: int
    function: ClassVar[int] = 0x30

    @property
    def addition(self) -> int:
        """The same position in the addition form: carry * 0x4000 + value."""
        return self.carry * ENCODER_COUNTS_PER_TURN + self.value


@dataclass(frozen=True, slots=True)
class EncoderAdditionReply:
    """0x31: ``value`` (int48, 0x4000 per turn)."""

    address: int
    value: int
    function: ClassVar[int] = 0x31


@dataclass(frozen=True, slots=True)
class SpeedReply:
    """0x32: real-time ``speed`` [rpm] (int16; CCW > 0)."""

    address: int
    speed: int
    function: ClassVar[int] = 0x32


@dataclass(frozen=True, slots=True)
class PulsesReply:
    """0x33: number of ``pulses`` received (int32)."""

    address: int
    pulses: int
    function: ClassVar[int] = 0x33


@dataclass(frozen=True, slots=True)
class IoStatusReply:
    """0x34: IO ports ``status`` byte: bit0 IN_1, bit1 IN_2, bit2 OUT_1, bit3 OUT_2."""

    address: int
    status: int
    function: ClassVar[int] = 0x34

    @property
    def in_1(self) -> bool:
        return bool(self.status & 0x01)

    @property
    def in_2(self) -> bool:
        return bool(self.status & 0x02)

    @property
    def out_1(self) -> bool:
        return bool(self.status & 0x04)

    @property
    def out_2(self) -> bool:
        return bool(self.status & 0x08)


@dataclass(frozen=True, slots=True)
class AngleErrorReply:
    """0x39: ``error`` of the shaft angle (int32; 51200 per turn)."""

    address: int
    error: int
    function: ClassVar[int] = 0x39

    @property
    def degrees(self) -> float:
        return self.error * 360.0 / ANGLE_ERROR_PER_TURN


@dataclass(frozen=True, slots=True)
class EnPinReply:
    """0x3A: En pin status (1 enabled, 0 disabled)."""

    address: int
    enabled: bool
    function: ClassVar[int] = 0x3A


@dataclass(frozen=True, slots=True)
class GoBackToZeroStatusReply:
    """0x3B: status of the power-on (single-turn) go back to zero; ``homing`` (V1.0.7, a second byte): the
    non-single-turn zero return (go home 0x91), None in the older one-byte reply."""

    address: int
    status: GoBackToZeroStatus
    homing: GoBackToZeroStatus | None = None
    function: ClassVar[int] = 0x3B


@dataclass(frozen=True, slots=True)
class ProtectionStateReply:
    """0x3E: motor shaft locked-rotor protection state (1 protected)."""

    address: int
    protected: bool
    function: ClassVar[int] = 0x3E


@dataclass(frozen=True, slots=True)
class CalibrationReply:
    """0x80: 0 calibrating (immediate), later 1 success or 2 fail."""

    address: int
    status: CalibrationStatus
    function: ClassVar[int] = 0x80

    @property
    def is_completion(self) -> bool:
        return self.status is not CalibrationStatus.CALIBRATING


@dataclass(frozen=True, slots=True)
class MotorStatusReply:
    """0xF1: the motor status."""

    address: int
    status: MotorStatus
    function: ClassVar[int] = 0xF1


@dataclass(frozen=True, slots=True)
class UserIdReply:
    """0x42 read (V1.0.9): the user ID, uint32 big-endian."""

    address: int
    id: int
    function: ClassVar[int] = 0x42


@dataclass(frozen=True, slots=True)
class ParameterReply:
    """Reply to 0x00 (V1.0.8): ``FB addr code param chk``, ``param`` laid out as the set command ``code``'s
    data (its shorter form); ``param`` None: the drive answered ``FF FF``, "this parameter does not support
    reading"."""

    address: int
    function: int  #: the code of the parameter read (not 0x00)
    param: bytes | None


@dataclass(frozen=True, slots=True)
class VersionReply:
    """0x40 (V1.0.9): the four data bytes as one big-endian ``version`` (uint32): b31-b28 calibration
    status, b27-b24 hardware version (1 S42D_485, 2 S42D_CAN, 3 S57D_485, 4 S57D_CAN ...), b23-b0 the
    firmware version, one byte each of major, minor, patch."""

    address: int
    version: int
    function: ClassVar[int] = 0x40

    @property
    def calibrated(self) -> bool:
        return bool(self.version >> 28)

    @property
    def hardware(self) -> int:
        return (self.version >> 24) & 0x0F

    @property
    def firmware(self) -> tuple[int, int, int]:
        return ((self.version >> 16) & 0xFF, (self.version >> 8) & 0xFF, self.version & 0xFF)


@dataclass(frozen=True, slots=True)
class RawEncoderReply:
    """0x35 (V1.0.6): ``value`` (int48, 0x4000 per turn) counted since power-on, whatever zero was set."""

    address: int
    value: int
    function: ClassVar[int] = 0x35


@dataclass(frozen=True, slots=True)
class TimedReturnReply:
    """0x01 (V1.0.9): the read command ``code`` whose timed return was set, and ``status`` 1 set / 0 fail."""

    address: int
    code: int
    status: SetStatus
    function: ClassVar[int] = 0x01


@dataclass(frozen=True, slots=True)
class AllParametersReply:
    """0x47 (V1.0.6): the 34 configuration bytes (5.7.2; layout in joints.devices.mks.blocks)."""

    address: int
    params: bytes
    function: ClassVar[int] = 0x47


@dataclass(frozen=True, slots=True)
class AllStatusReply:
    """0x48 (V1.0.6): the 28 status bytes (5.7.3; layout in joints.devices.mks.blocks)."""

    address: int
    params: bytes
    function: ClassVar[int] = 0x48


@dataclass(frozen=True, slots=True)
class SetReply:
    """Status reply (0 fail, 1 success) of a set command; ``function`` is the command's code."""

    address: int
    function: int
    status: SetStatus


@dataclass(frozen=True, slots=True)
class RunReply:
    """Reply of a run command (0xF4, 0xF5, 0xF6, 0xFD, 0xFE), 0x91 go home or 0xFF save/clean.

    The immediate reply (FAIL / STARTED) and the later completion frame (COMPLETE /
    END_LIMIT_STOP, sent while other traffic goes on when "active" is on) share this type.
    """

    address: int
    function: int
    status: RunStatus

    @property
    def is_completion(self) -> bool:
        """A completion frame (2 or 3), not the immediate answer to a command (0, 1, 5)."""
        return self.status in (RunStatus.COMPLETE, RunStatus.END_LIMIT_STOP)


Reply = (
    EncoderCarryReply | EncoderAdditionReply | SpeedReply | PulsesReply | IoStatusReply | AngleErrorReply
    | EnPinReply | GoBackToZeroStatusReply | ProtectionStateReply | CalibrationReply | MotorStatusReply | SetReply
    | RunReply | VersionReply | AllParametersReply | AllStatusReply | TimedReturnReply | RawEncoderReply
    | ParameterReply | UserIdReply
)
Message = Request | UnknownRequest | LongPacket | Reply


# --- per-command layouts -------------------------------------------------------------------


def _check_u8(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFF:
        raise EncodeError(f"{name} must be an integer 0..255, got {value!r}")
    return value


def _check_int(name: str, value: object, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise EncodeError(f"{name} must be an integer {lo}..{hi}, got {value!r}")
    return int(value)


@dataclass(frozen=True, slots=True)
class _Spec:
    """How one function code's data bytes map to a message (one direction)."""

    cls: type
    size: int  #: data bytes
    pack: Callable[[Any], bytes]
    unpack: Callable[[int, int, bytes, bytes], Any]  #: (address, function, data, frame) -> message
    long: int = 0  #: data bytes of the command's longer form (V1.0.7+; 0: one form), see REQUEST_LONG_DATA_LENGTH
    plausible: Callable[[bytes], bool] | None = None  #: the longer form's data could be what it says
    #: a valid short frame could also be the head of a long one (else the short form is taken at once)
    could_grow: Callable[[bytes], bool] | None = None


def _struct(cls: type, fmt: str = "", names: tuple[str, ...] = ()) -> _Spec:
    """A command whose data is a plain struct of its fields (in order)."""
    s = struct.Struct(">" + fmt)

    def pack(msg: Any) -> bytes:
        values = [getattr(msg, n) for n in names]
        for n, v in zip(names, values):
            if isinstance(v, bool) or not isinstance(v, int):
                raise EncodeError(f"{cls.__name__}.{n} must be an integer, got {v!r}")
        try:
            return s.pack(*values)
        except struct.error as exc:
            raise EncodeError(f"{cls.__name__}: a field is out of its wire range ({exc}): {msg!r}") from None

    def unpack(address: int, function: int, data: bytes, frame: bytes) -> Any:
        return cls(address, *s.unpack(data))

    return _Spec(cls, s.size, pack, unpack)


def _pack_calibrate(msg: Any) -> bytes:
    return b"\x00"


def _unpack_calibrate(address: int, function: int, data: bytes, frame: bytes) -> Calibrate:
    if data != b"\x00":
        raise FrameError(f"calibrate (0x80) carries data 0x{data[0]:02X}, the manual's is 00: {frame.hex(' ')}",
                         data=frame)
    return Calibrate(address)


def _pack_working_current(msg: Any) -> bytes:
    current = _check_int("SetWorkingCurrent.current", msg.current, 0, 0xFFFF).to_bytes(2, "big")
    return current + b"\x00" if _check_int("SetWorkingCurrent.unsaved", msg.unsaved, 0, 1) else current


def _unpack_working_current(address: int, function: int, data: bytes, frame: bytes) -> SetWorkingCurrent:
    if len(data) > 2 and data[2]:
        raise FrameError(f"0x83: the byte after the current must be 00 (not saved), got {frame.hex(' ')}", data=frame)
    return SetWorkingCurrent(address, int.from_bytes(data[:2], "big"), int(len(data) > 2))


def _pack_user_id(msg: Any) -> bytes:
    return b"" if msg.id is None else _check_int("UserId.id", msg.id, 0, 0xFFFFFFFF).to_bytes(4, "big")


def _unpack_user_id(address: int, function: int, data: bytes, frame: bytes) -> UserId:
    return UserId(address, int.from_bytes(data, "big") if data else None)


def _pack_go_home(msg: Any) -> bytes:
    return bytes((1,)) if _check_int("GoHome.mode", msg.mode, 0, 1) else b""


def _unpack_go_home(address: int, function: int, data: bytes, frame: bytes) -> GoHome:
    if data and data[0] > 1:
        raise FrameError(f"0x91: goZeroMode must be 00 or 01, got {frame.hex(' ')}", data=frame)
    return GoHome(address, data[0] if data else 0)


def _pack_subdivision(msg: Any) -> bytes:
    n = _check_int("SetSubdivision.microsteps", msg.microsteps, 1, 256)
    return bytes((n & 0xFF,))


def _unpack_subdivision(address: int, function: int, data: bytes, frame: bytes) -> SetSubdivision:
    return SetSubdivision(address, data[0] or 256)


def _dir_speed(cls: str, direction: object, speed: object) -> bytes:
    if isinstance(direction, bool) or not isinstance(direction, int) or direction not in (0, 1):
        raise EncodeError(f"{cls}.direction must be 0 (CCW) or 1 (CW), got {direction!r}")
    s = _check_int(f"{cls}.speed", speed, 0, SPEED_FIELD_MAX)
    return bytes(((int(direction) << 7) | (s >> 8), s & 0xFF))


def _split_dir_speed(data: bytes, frame: bytes) -> tuple[RunDirection, int]:
    if data[0] & 0x70:
        raise FrameError(f"reserved bits b6-b4 of the direction/speed byte are set (0x{data[0]:02X}): "
                         f"{frame.hex(' ')}", data=frame)
    return RunDirection(data[0] >> 7), ((data[0] & 0x0F) << 8) | data[1]


RUN_TIME_MAX = 0x0FFFFFFF  #: 0xF6 runTime (V1.0.7), 10 ms units


def _pack_run_speed(msg: Any) -> bytes:
    head = _dir_speed("RunSpeed", msg.direction, msg.speed) + bytes((_check_u8("RunSpeed.acc", msg.acc),))
    run_time = _check_int("RunSpeed.run_time", msg.run_time, 0, RUN_TIME_MAX)
    return head + _U32.pack(run_time) if run_time else head


def _unpack_run_speed(address: int, function: int, data: bytes, frame: bytes) -> RunSpeed:
    direction, speed = _split_dir_speed(data, frame)
    run_time = _U32.unpack_from(data, 3)[0] if len(data) > 3 else 0
    if run_time > RUN_TIME_MAX:
        raise FrameError(f"0xF6 runTime 0x{run_time:08X} is above 0x0FFFFFFF: {frame.hex(' ')}", data=frame)
    return RunSpeed(address, direction, speed, data[2], run_time)


_U32 = struct.Struct(">I")
_HBI = struct.Struct(">HBi")


def _pack_relative_pulses(msg: Any) -> bytes:
    return (_dir_speed("RunRelativePulses", msg.direction, msg.speed)
            + bytes((_check_u8("RunRelativePulses.acc", msg.acc),))
            + _U32.pack(_check_int("RunRelativePulses.pulses", msg.pulses, 0, 0xFFFFFFFF)))


def _unpack_relative_pulses(address: int, function: int, data: bytes, frame: bytes) -> RunRelativePulses:
    direction, speed = _split_dir_speed(data, frame)
    return RunRelativePulses(address, direction, speed, data[2], _U32.unpack_from(data, 3)[0])


def _enum_value(enum_type: type[enum.IntEnum], value: int, what: str, frame: bytes) -> Any:
    try:
        return enum_type(value)
    except ValueError:
        raise FrameError(f"{what}: undocumented value {value} in {frame.hex(' ')}", data=frame) from None


def _status_spec(cls: type, field_name: str, enum_type: type[enum.IntEnum]) -> _Spec:
    """A reply whose data is one status byte (an Enum) - fixed-function classes."""

    def pack(msg: Any) -> bytes:
        try:
            return bytes((enum_type(getattr(msg, field_name)),))
        except (ValueError, TypeError):
            raise EncodeError(f"{cls.__name__}.{field_name} must be a {enum_type.__name__}, "
                              f"got {getattr(msg, field_name)!r}") from None

    def unpack(address: int, function: int, data: bytes, frame: bytes) -> Any:
        return cls(address, _enum_value(enum_type, data[0], f"{cls.__name__}.{field_name}", frame))

    return _Spec(cls, 1, pack, unpack)


def _flag_spec(cls: type, field_name: str) -> _Spec:
    """A reply whose data is one byte 0/1 read as a bool."""

    def pack(msg: Any) -> bytes:
        v = getattr(msg, field_name)
        if v not in (0, 1):
            raise EncodeError(f"{cls.__name__}.{field_name} must be a bool, got {v!r}")
        return bytes((int(v),))

    def unpack(address: int, function: int, data: bytes, frame: bytes) -> Any:
        if data[0] > 1:
            raise FrameError(f"{cls.__name__}.{field_name}: undocumented value {data[0]} in {frame.hex(' ')}",
                             data=frame)
        return cls(address, bool(data[0]))

    return _Spec(cls, 1, pack, unpack)


def _coded_spec(cls: type, enum_type: type[enum.IntEnum]) -> _Spec:
    """A reply class shared by several function codes: (address, function, status)."""

    def pack(msg: Any) -> bytes:
        try:
            return bytes((enum_type(msg.status),))
        except (ValueError, TypeError):
            raise EncodeError(f"{cls.__name__}.status must be a {enum_type.__name__}, got {msg.status!r}") from None

    def unpack(address: int, function: int, data: bytes, frame: bytes) -> Any:
        return cls(address, function, _enum_value(enum_type, data[0], f"{cls.__name__} to 0x{function:02X}", frame))

    return _Spec(cls, 1, pack, unpack)


ALL_PARAMETERS_SIZE = 34  #: data bytes of 0x46 / the 0x47 reply
ALL_STATUS_SIZE = 28  #: data bytes of the 0x48 reply


def _raw(cls: type, size: int) -> _Spec:
    """A message whose data is ``size`` bytes kept as they are (field ``params``)."""

    def pack(msg: Any) -> bytes:
        data = msg.params
        if not isinstance(data, (bytes, bytearray)) or len(data) != size:
            raise EncodeError(f"{cls.__name__}.params must be {size} bytes, got {data!r}")
        return bytes(data)

    def unpack(address: int, function: int, data: bytes, frame: bytes) -> Any:
        return cls(address, bytes(data))

    return _Spec(cls, size, pack, unpack)


def _pack_write_io(msg: Any) -> bytes:
    masks = [_check_int(f"WriteIoPort.{n}", getattr(msg, n), 0, 2) for n in ("out2_mask", "out1_mask")]
    outs = [_check_int(f"WriteIoPort.{n}", getattr(msg, n), 0, 1) for n in ("out2", "out1")]
    return bytes(((masks[0] << 6) | (masks[1] << 4) | (outs[0] << 3) | (outs[1] << 2),))


def _unpack_write_io(address: int, function: int, data: bytes, frame: bytes) -> WriteIoPort:
    b = data[0]
    if b & 0x03 or (b >> 6) == 3 or ((b >> 4) & 3) == 3:
        raise FrameError(f"0x36 write IO port: reserved bits b1-b0 set or a mask of 3 (0x{b:02X}): {frame.hex(' ')}",
                         data=frame)
    return WriteIoPort(address, b >> 6, (b >> 4) & 3, (b >> 3) & 1, (b >> 2) & 1)


def _pack_position_error(msg: Any) -> bytes:
    flags = (_check_int("SetPositionErrorProtection.en_zero_return", msg.en_zero_return, 0, 1) << 1) | \
        _check_int("SetPositionErrorProtection.enable", msg.enable, 0, 1)
    return bytes((flags,)) + struct.pack(">HH", _check_int("SetPositionErrorProtection.time", msg.time, 0, 0xFFFF),
                                         _check_int("SetPositionErrorProtection.errors", msg.errors, 0, 0xFFFF))


def _unpack_position_error(address: int, function: int, data: bytes, frame: bytes) -> SetPositionErrorProtection:
    if data[0] & 0xFC:
        raise FrameError(f"0x9D: reserved bits b7-b2 of the enable byte are set (0x{data[0]:02X}): {frame.hex(' ')}",
                         data=frame)
    time, errors = struct.unpack_from(">HH", data, 1)
    return SetPositionErrorProtection(address, (data[0] >> 1) & 1, data[0] & 1, time, errors)


def _pack_zero_status(msg: Any) -> bytes:
    try:
        statuses = (msg.status,) if msg.homing is None else (msg.status, msg.homing)
        return bytes(GoBackToZeroStatus(s) for s in statuses)
    except (ValueError, TypeError):
        raise EncodeError(f"GoBackToZeroStatusReply statuses must be GoBackToZeroStatus: {msg!r}") from None


def _unpack_zero_status(address: int, function: int, data: bytes, frame: bytes) -> GoBackToZeroStatusReply:
    status = _enum_value(GoBackToZeroStatus, data[0], "GoBackToZeroStatusReply.status", frame)
    homing = _enum_value(GoBackToZeroStatus, data[1], "GoBackToZeroStatusReply.homing", frame) if len(data) > 1 \
        else None
    return GoBackToZeroStatusReply(address, status, homing)


def _zero_status_length(buf: bytearray, silent: bool) -> int | None:
    """0x3B reply: 5 bytes (one status, before V1.0.7) or 6 (two). Byte 4 is the short frame's checksum or the
    second status (0-2): a checksum above 2 decides at once; otherwise the sixth byte must be the long frame's
    checksum (addresses 0xC8-0xCC with some statuses: the host may wait for it until silence)."""
    if len(buf) < 5:
        return None
    short_ok = sum(buf[:4]) & 0xFF == buf[4]
    if not short_ok or buf[4] > 2:
        return 6 if not short_ok and buf[4] <= 2 else 5
    if len(buf) < 6:
        return 5 if silent else None
    return 6 if sum(buf[:5]) & 0xFF == buf[5] else 5


def _pack_timed_reply(msg: Any) -> bytes:
    try:
        return bytes((_check_u8("TimedReturnReply.code", msg.code), SetStatus(msg.status)))
    except ValueError:
        raise EncodeError(f"TimedReturnReply.status must be a SetStatus, got {msg.status!r}") from None


def _unpack_timed_reply(address: int, function: int, data: bytes, frame: bytes) -> TimedReturnReply:
    return TimedReturnReply(address, data[0], _enum_value(SetStatus, data[1], "TimedReturnReply.status", frame))


def _pack_int48(msg: Any) -> bytes:
    v = _check_int(f"{type(msg).__name__}.value", msg.value, -(1 << 47), (1 << 47) - 1)
    return v.to_bytes(6, "big", signed=True)


def _unpack_int48(address: int, function: int, data: bytes, frame: bytes) -> EncoderAdditionReply:
    return EncoderAdditionReply(address, int.from_bytes(data, "big", signed=True))


def _unpack_raw_int48(address: int, function: int, data: bytes, frame: bytes) -> RawEncoderReply:
    return RawEncoderReply(address, int.from_bytes(data, "big", signed=True))


_REQUEST_SPECS: tuple[_Spec, ...] = (
    _struct(ReadEncoderCarry), _struct(ReadEncoderAddition), _struct(ReadSpeed), _struct(ReadPulses),
    _struct(ReadIoStatus), _struct(ReadAngleError), _struct(ReadEnPin), _struct(ReadGoBackToZeroStatus),
    _struct(ReleaseProtection), _struct(ReadProtectionState), _struct(RestoreDefaults), _struct(Restart),
    _Spec(Calibrate, 1, _pack_calibrate, _unpack_calibrate),
    _struct(SetWorkMode, "B", ("mode",)),
    _Spec(SetWorkingCurrent, 2, _pack_working_current, _unpack_working_current, 3, lambda d: d[2] == 0,
          lambda f: f[-1] == 0),
    _struct(SetHoldingCurrent, "B", ("hold",)),
    _Spec(SetSubdivision, 1, _pack_subdivision, _unpack_subdivision),
    _struct(SetEnActive, "B", ("level",)),
    _struct(SetDirection, "B", ("direction",)),
    _struct(SetAutoScreenOff, "B", ("enable",)),
    _struct(SetLockedRotorProtection, "B", ("enable",)),
    _struct(SetSubdivisionInterpolation, "B", ("enable",)),
    _struct(SetBaudRate, "B", ("baud",)),
    _struct(SetSlaveAddress, "B", ("new_address",)),
    _struct(SetRespondActive, "BB", ("respond", "active")),
    _struct(SetGroupAddress, "B", ("group",)),
    _struct(SetModbusRtu, "B", ("enable",)),
    _struct(SetKeyLock, "B", ("lock",)),
    _struct(SetHomeParameters, "BBHB", ("trigger_level", "direction", "speed", "end_limit")),
    _Spec(GoHome, 0, _pack_go_home, _unpack_go_home, 1, lambda d: d[0] <= 1, lambda f: f[-1] <= 1),
    _struct(SetAxisZero),
    _struct(SetNoLimitHomeParameters, "IBH", ("reverse_angle", "mode", "current")),
    _struct(SetZeroMode, "BBBB", ("mode", "set_zero", "speed", "direction")),
    _struct(SetLimitPortRemap, "B", ("enable",)),
    _struct(QueryStatus),
    _struct(EnableMotor, "B", ("enable",)),
    _struct(EmergencyStop),
    _Spec(RunSpeed, 3, _pack_run_speed, _unpack_run_speed, 7, lambda d: d[3] <= RUN_TIME_MAX >> 24,
          lambda f: f[-1] <= RUN_TIME_MAX >> 24),
    _struct(SaveCleanSpeedMode, "B", ("state",)),
    _Spec(RunRelativePulses, 7, _pack_relative_pulses, _unpack_relative_pulses),
    _struct(RunAbsolutePulses, "HBi", ("speed", "acc", "abs_pulses")),
    _struct(RunRelativeAxis, "HBi", ("speed", "acc", "rel_axis")),
    _struct(RunAbsoluteAxis, "HBi", ("speed", "acc", "abs_axis")),
    _struct(ReadRawEncoder),
    _struct(SetTimedReturn, "BH", ("code", "times")),
    _struct(ReadParameter, "B", ("code",)),
    _Spec(UserId, 0, _pack_user_id, _unpack_user_id, 4, None, lambda f: True),
    _struct(ReadVersion),
    _struct(SetHeartbeat, "I", ("times",)),
    _raw(WriteAllParameters, ALL_PARAMETERS_SIZE),
    _struct(ReadAllParameters),
    _struct(ReadAllStatus),
    _Spec(WriteIoPort, 1, _pack_write_io, _unpack_write_io),
    _Spec(SetPositionErrorProtection, 5, _pack_position_error, _unpack_position_error),
    _struct(SetPositionThreshold, "BH", ("enable", "values")),
    _struct(SetSync, "B", ("enable",)),
    _struct(SyncExecute),
    _struct(IapControl, "B", ("cmd",)),
    _struct(SetVfocPid, "HHHH", ("kp", "ki", "kd", "kv")),
    _struct(SetClosePid, "HHHH", ("kp", "ki", "kd", "kv")),
    _struct(SetPulseDivider, "BI", ("level", "period")),
    _struct(SetIn1PortMode, "B", ("type",)),
)

_REQUESTS: dict[int, _Spec] = {s.cls.function: s for s in _REQUEST_SPECS}  # type: ignore[attr-defined]
_REQUEST_BY_TYPE: dict[type, _Spec] = {s.cls: s for s in _REQUEST_SPECS}

#: function codes answered by :class:`RunReply` and by :class:`SetReply`
RUN_REPLY_FUNCTIONS = frozenset((0x91, 0xF4, 0xF5, 0xF6, 0xFD, 0xFE, 0xFF))
SET_REPLY_FUNCTIONS = frozenset((0x3D, 0x3F, 0x41, 0x82, 0x83, 0x84, 0x85, 0x86, 0x87, 0x88, 0x89, 0x8A, 0x8B,
                                 0x8C, 0x8D, 0x8E, 0x8F, 0x90, 0x92, 0x94, 0x98, 0x9A, 0x9B, 0x9E, 0xF3, 0xF7,
                                 0x46, 0x36, 0x9D, 0x95, 0x4A, 0x50, 0x96, 0x97, 0x99, 0x9F,
                                 0x4B, 0x42))  # 0x4B is never answered (the layout keeps the table total)
#: 0x42 (V1.0.9) answers a write with a set status (above), a read with the ID (UserIdReply: the host is told)
_USER_ID_REPLY = _struct(UserIdReply, "I", ("id",))
#: the codes 0x00 (V1.0.8) may read: the set commands (0x42 has its own read)
PARAMETER_CODES = SET_REPLY_FUNCTIONS - {UserId.function}

_RUN_REPLY = _coded_spec(RunReply, RunStatus)
_SET_REPLY_ANY = _coded_spec(SetReply, SetStatus)


def _unpack_set_reply(address: int, function: int, data: bytes, frame: bytes) -> SetReply:
    reply: SetReply = _SET_REPLY_ANY.unpack(address, function, data, frame)
    if reply.status is SetStatus.SUCCESS_UNSAVED and function != 0x83:
        raise FrameError(f"SetReply to 0x{function:02X}: undocumented value 2 in {frame.hex(' ')}", data=frame)
    return reply


def _pack_set_reply(msg: Any) -> bytes:
    if msg.status == SetStatus.SUCCESS_UNSAVED and msg.function != 0x83:
        raise EncodeError(f"status 2 (success without saved) answers 0x83 only, not 0x{msg.function:02X}")
    return _SET_REPLY_ANY.pack(msg)


_SET_REPLY = _Spec(SetReply, 1, _pack_set_reply, _unpack_set_reply)
_FIXED_REPLY_SPECS: tuple[_Spec, ...] = (
    _struct(EncoderCarryReply, "iH", ("carry", "value")),
    _Spec(EncoderAdditionReply, 6, _pack_int48, _unpack_int48),
    _struct(SpeedReply, "h", ("speed",)),
    _struct(PulsesReply, "i", ("pulses",)),
    _struct(IoStatusReply, "B", ("status",)),
    _struct(AngleErrorReply, "i", ("error",)),
    _flag_spec(EnPinReply, "enabled"),
    _Spec(GoBackToZeroStatusReply, 1, _pack_zero_status, _unpack_zero_status),
    _flag_spec(ProtectionStateReply, "protected"),
    _status_spec(CalibrationReply, "status", CalibrationStatus),
    _status_spec(MotorStatusReply, "status", MotorStatus),
    _struct(VersionReply, "I", ("version",)),
    _raw(AllParametersReply, ALL_PARAMETERS_SIZE),
    _raw(AllStatusReply, ALL_STATUS_SIZE),
    _Spec(TimedReturnReply, 2, _pack_timed_reply, _unpack_timed_reply),
    _Spec(RawEncoderReply, 6, _pack_int48, _unpack_raw_int48),
)
_REPLIES: dict[int, _Spec] = {s.cls.function: s for s in _FIXED_REPLY_SPECS}  # type: ignore[attr-defined]
_REPLIES.update({f: _RUN_REPLY for f in RUN_REPLY_FUNCTIONS})
_REPLIES.update({f: _SET_REPLY for f in SET_REPLY_FUNCTIONS})
_REPLY_BY_TYPE: dict[type, _Spec] = {s.cls: s for s in _FIXED_REPLY_SPECS}

#: function code -> request class / data bytes of its downlink frame
REQUEST_TYPES: Mapping[int, type] = MappingProxyType({f: s.cls for f, s in sorted(_REQUESTS.items())})
REQUEST_DATA_LENGTH: Mapping[int, int] = MappingProxyType({f: s.size for f, s in sorted(_REQUESTS.items())})
#: function code -> data bytes of the longer form of a command that has two (V1.0.7: 0xF6 with runTime)
REQUEST_LONG_DATA_LENGTH: Mapping[int, int] = MappingProxyType({f: s.long for f, s in sorted(_REQUESTS.items())
                                                                if s.long})
#: function code -> reply class / data bytes of its uplink frame
REPLY_TYPES: Mapping[int, type] = MappingProxyType({f: s.cls for f, s in sorted(_REPLIES.items())})
REPLY_DATA_LENGTH: Mapping[int, int] = MappingProxyType({f: s.size for f, s in sorted(_REPLIES.items())})

assert set(REQUEST_TYPES) - {ReadParameter.function} == set(REPLY_TYPES), "every command has a reply layout"
#: 0x00's reply is headed by the parameter's code, its data laid out as that set command's (shorter form)
NOT_READABLE = b"\xff\xff"


# --- encoding --------------------------------------------------------------------------------


def _inner(msg: Request | UnknownRequest, max_unknown: int = MAX_UNKNOWN_FRAME - MIN_FRAME) -> bytes:
    """Address, code and data of a request (a frame without head and checksum)."""
    address = _check_u8("address", msg.address)
    if isinstance(msg, UnknownRequest):
        function = _check_u8("UnknownRequest.function", msg.function)
        if function in _REQUESTS:
            raise EncodeError(f"UnknownRequest with the known function code 0x{function:02X}; "
                              f"use {_REQUESTS[function].cls.__name__}")
        if not isinstance(msg.data, (bytes, bytearray)) or len(msg.data) > max_unknown:
            raise EncodeError(f"UnknownRequest.data must be bytes of at most {max_unknown}, got {msg.data!r}")
        return bytes((address, function)) + bytes(msg.data)
    spec = _REQUEST_BY_TYPE.get(type(msg))
    if spec is None:
        raise EncodeError(f"not an MKS request: {msg!r}")
    return bytes((address, spec.cls.function)) + spec.pack(msg)  # type: ignore[attr-defined]


def _encode_long(msg: LongPacket) -> bytes:
    if len(msg.commands) != LONG_PACKET_SLOTS:
        raise EncodeError(f"a long packet holds {LONG_PACKET_SLOTS} commands, got {len(msg.commands)}")
    body = bytearray((HEAD_LONG,))
    for i, cmd in enumerate(msg.commands):
        if cmd is None:
            body += bytes(LONG_PACKET_SLOT)
            continue
        if isinstance(cmd, LongPacket):
            raise EncodeError("a long packet cannot contain a long packet")
        if isinstance(cmd, UserId) and cmd.id is None:  # (a slot's padding would read as the ID 0: a write)
            raise EncodeError(f"long packet slot {i + 1}: a 0x42 read gets no answer in a long packet")
        inner = _inner(cmd, LONG_PACKET_SLOT - 2)
        if len(inner) > LONG_PACKET_SLOT:
            raise EncodeError(f"long packet slot {i + 1}: {type(cmd).__name__} does not fit {LONG_PACKET_SLOT} bytes")
        if not any(inner):
            raise EncodeError(f"long packet slot {i + 1}: an all-zero command reads as an empty slot")
        body += inner + bytes(LONG_PACKET_SLOT - len(inner))
    return with_checksum(body)


def encode(message: Message) -> bytes:
    """Encode a request (FA frame), a reply (FB frame) or a long packet (FC frame), checksum included."""
    if isinstance(message, LongPacket):
        return _encode_long(message)
    if isinstance(message, (SetReply, RunReply)):
        allowed = SET_REPLY_FUNCTIONS if isinstance(message, SetReply) else RUN_REPLY_FUNCTIONS
        function = _check_u8("function", message.function)
        if function not in allowed:
            raise EncodeError(f"0x{function:02X} is not answered by {type(message).__name__}")
        spec = _SET_REPLY if isinstance(message, SetReply) else _RUN_REPLY
        return with_checksum(bytes((HEAD_UPLINK, _check_u8("address", message.address), function))
                             + spec.pack(message))
    if isinstance(message, UserIdReply):
        return with_checksum(bytes((HEAD_UPLINK, _check_u8("address", message.address), UserId.function))
                             + _USER_ID_REPLY.pack(message))
    if isinstance(message, ParameterReply):
        function = _check_u8("function", message.function)
        param = NOT_READABLE if message.param is None else bytes(message.param)
        if message.param is not None and len(param) != REQUEST_DATA_LENGTH.get(function, -1):
            raise EncodeError(f"ParameterReply: 0x{function:02X}'s parameter is "
                              f"{REQUEST_DATA_LENGTH.get(function)} bytes, got {param.hex(' ')}")
        return with_checksum(bytes((HEAD_UPLINK, _check_u8("address", message.address), function)) + param)
    reply_spec = _REPLY_BY_TYPE.get(type(message))
    if reply_spec is not None:
        return with_checksum(bytes((HEAD_UPLINK, _check_u8("address", message.address),
                                    reply_spec.cls.function)) + reply_spec.pack(message))  # type: ignore[attr-defined]
    if isinstance(message, UnknownRequest) or type(message) in _REQUEST_BY_TYPE:
        return with_checksum(bytes((HEAD_DOWNLINK,)) + _inner(message))  # type: ignore[arg-type]
    raise EncodeError(f"not an MKS message: {message!r}")


# --- decoding --------------------------------------------------------------------------------


def _decode_request(frame: bytes) -> Request | UnknownRequest:
    address, function = frame[1], frame[2]
    spec = _REQUESTS.get(function)
    if spec is None:
        return UnknownRequest(address, function, frame[3:-1])
    return spec.unpack(address, function, frame[3:-1], frame)  # type: ignore[no-any-return]


def parameter_request(reply: ParameterReply) -> Request:
    """The set command whose data a 0x00 reply carries, decoded as that command (its fields, by name)."""
    spec = _REQUESTS.get(reply.function)
    if reply.param is None or spec is None or len(reply.param) != spec.size:
        raise FrameError(f"not a readable parameter's reply: {reply!r}", data=encode(reply))
    return spec.unpack(reply.address, reply.function, reply.param, encode(reply))  # type: ignore[no-any-return]


def _decode_reply(frame: bytes) -> Reply:
    address, function = frame[1], frame[2]
    spec = _REPLIES[function]
    return spec.unpack(address, function, frame[3:-1], frame)  # type: ignore[no-any-return]


def _decode_long(frame: bytes) -> LongPacket:
    cmds: list[Request | UnknownRequest | None] = []
    for i in range(LONG_PACKET_SLOTS):
        slot = frame[1 + i * LONG_PACKET_SLOT: 1 + (i + 1) * LONG_PACKET_SLOT]
        if not any(slot):
            cmds.append(None)
            continue
        address, function = slot[0], slot[1]
        spec = _REQUESTS.get(function)
        if spec is None:
            cmds.append(UnknownRequest(address, function, bytes(slot[2:])))
            continue
        size = spec.long or spec.size  # a short form's absent field reads 0 from the padding
        if 2 + size > LONG_PACKET_SLOT:
            raise FrameError(f"long packet slot {i + 1}: {spec.cls.__name__} does not fit a slot: {frame.hex(' ')}",
                             data=frame)
        data, pad = slot[2:2 + size], slot[2 + size:]
        if any(pad):
            raise FrameError(f"long packet slot {i + 1} ({spec.cls.__name__}) has non-zero padding "
                             f"{pad.hex(' ')}: {frame.hex(' ')}", data=frame)
        cmds.append(spec.unpack(address, function, data, frame))
    return LongPacket(tuple(cmds))


def _unknown_length(buf: bytearray, limit: int) -> int | None:
    """Shortest checksum-delimited length (4..limit) at the head; None = need more; 0 = none."""
    total = buf[0] + buf[1] + buf[2]
    top = min(limit, len(buf))
    for n in range(MIN_FRAME, top + 1):
        if total & 0xFF == buf[n - 1]:
            return n
        total += buf[n - 1]
    return 0 if len(buf) >= limit else None


class MksCodec:
    """Incremental MKS native framer/decoder for one end of a bus (see the module docstring).

    ``Role.HOST`` decodes uplink replies (head FB); ``Role.DEVICE`` decodes downlink requests
    (head FA) and long packets (head FC). ``encode`` works for both directions.
    """

    def __init__(self, role: Role = Role.HOST) -> None:
        self.role = role
        self._buf = bytearray()
        self._echo: bytes | None = None
        self._parameter: tuple[int, int] | None = None  #: (address, code) of an open 0x00 read (host role)
        self._user_id_read: int | None = None  #: address of an open 0x42 read (host role)
        self._silent = False
        self.discarded = 0  #: bytes dropped while resynchronising (garbage, bad frames, other direction)

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
        """Drop everything buffered and any expected echo."""
        self.discarded += len(self._buf)
        self._buf.clear()
        self._echo = None

    @property
    def buffered(self) -> int:
        return len(self._buf)

    def expect_echo(self, frame: bytes) -> None:
        """Skip this exact frame once if it arrives first (RS485 adapter local echo)."""
        self._echo = bytes(frame)

    def expect_reply(self, request: object) -> None:
        """The request now open (host role), for the replies whose layout the request decides: a 0x00 read's
        reply, headed by the parameter's code from that address, is a :class:`ParameterReply`; 0x42 without
        an ID is answered by a :class:`UserIdReply`, with one by a set status. Any other request (or None)
        clears it."""
        self._user_id_read = request.address if isinstance(request, UserId) and request.id is None else None
        if isinstance(request, ReadParameter) and request.code not in PARAMETER_CODES:
            raise EncodeError(f"0x00 reads a set command's parameter; 0x{request.code:02X} is none")
        self._parameter = (request.address, request.code) if isinstance(request, ReadParameter) else None

    # -- output --
    @staticmethod
    def encode(message: Message) -> bytes:
        return encode(message)

    def _length(self, buf: bytearray) -> int | None:
        """Frame length at the head of ``buf``: None = need more bytes, 0 = not a frame start."""
        head = buf[0]
        if self.role is Role.HOST:
            if head != HEAD_UPLINK:
                return 0
            if len(buf) < 3:
                return None
            if self._parameter is not None and (buf[1], buf[2]) == self._parameter:
                return self._parameter_length(buf)
            if buf[2] == UserId.function and buf[1] == self._user_id_read:
                return MIN_FRAME + _USER_ID_REPLY.size
            if buf[2] == 0x3B:  # one or two statuses (V1.0.7)
                return _zero_status_length(buf, self._silent)
            n = REPLY_DATA_LENGTH.get(buf[2])
            return 0 if n is None else MIN_FRAME + n
        if head == HEAD_LONG:
            return LONG_PACKET_LENGTH
        if head != HEAD_DOWNLINK:
            return 0
        if len(buf) < 3:
            return None
        spec = _REQUESTS.get(buf[2])
        if spec is None:
            found = _unknown_length(buf, MAX_UNKNOWN_FRAME)
            if found is None and self._silent:
                return 0
            return found
        if spec.long:
            return self._two_forms(buf, spec)
        return MIN_FRAME + spec.size

    def _parameter_length(self, buf: bytearray) -> int | None:
        """A 0x00 reply: the parameter's data, or FF FF ("not readable") when that frame is there and valid."""
        value, refused = MIN_FRAME + REQUEST_DATA_LENGTH[buf[2]], MIN_FRAME + len(NOT_READABLE)
        if len(buf) >= refused and buf[3:5] == NOT_READABLE and checksum_ok(buf[:refused]):
            return refused
        if len(buf) >= value and checksum_ok(buf[:value]):
            return value
        return None if len(buf) < max(value, refused) and not self._silent else value

    def _two_forms(self, buf: bytearray, spec: _Spec) -> int | None:
        """A command with a short and a long form (see the module docstring): the long one if it is there
        (checksum-valid, plausible), else the short one once the line went silent or more bytes came."""
        short, long = MIN_FRAME + spec.size, MIN_FRAME + spec.long
        if len(buf) >= long and checksum_ok(buf[:long]) and (
                spec.plausible is None or spec.plausible(bytes(buf[3:long - 1]))):
            return long
        if len(buf) < long and not self._silent and (
                len(buf) < short or spec.could_grow is None or spec.could_grow(bytes(buf[:short]))):
            return None  # the long form may still be arriving
        return short

    def _next_valid_offset(self, buf: bytearray) -> int:
        """Offset (>0) of the first complete, checksum-valid frame after the head, or 0."""
        for off in range(1, len(buf) - MIN_FRAME + 1):
            view = buf[off:]
            n = self._length(view)
            if n and n <= len(view) and checksum_ok(view[:n]):
                return off
        return 0

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
            length = self._length(buf)
            if length == 0:
                del buf[0]
                self.discarded += 1
                continue
            if length is None or len(buf) < length:
                if not self._silent:
                    return None
                skip = self._next_valid_offset(buf)
                if skip:
                    del buf[:skip]
                    self.discarded += skip
                    continue
                frame = bytes(buf)
                self.discarded += len(buf)
                buf.clear()
                raise FrameError(
                    f"truncated frame: {frame.hex(' ')} has {len(frame)} bytes"
                    + (f", its head announces {length}" if length else ""),
                    data=frame,
                )
            frame = bytes(buf[:length])
            if sum(frame[:-1]) & 0xFF != frame[-1]:
                del buf[0]
                self.discarded += 1
                raise ChecksumError(
                    f"checksum mismatch in {frame.hex(' ')}: expected 0x{checksum(frame[:-1]):02X}, "
                    f"got 0x{frame[-1]:02X}",
                    data=frame,
                )
            del buf[:length]
            if self.role is Role.HOST:
                if self._parameter is not None and (frame[1], frame[2]) == self._parameter:
                    self._parameter = None
                    param = frame[3:-1]
                    return ParameterReply(frame[1], frame[2], None if len(param) != REQUEST_DATA_LENGTH[frame[2]]
                                          or (len(param) == len(NOT_READABLE) and param == NOT_READABLE) else param)
                if frame[2] == UserId.function and frame[1] == self._user_id_read:
                    self._user_id_read = None
                    return _USER_ID_REPLY.unpack(frame[1], frame[2], frame[3:-1], frame)  # type: ignore[no-any-return]
                return _decode_reply(frame)
            if frame[0] == HEAD_LONG:
                return _decode_long(frame)
            return _decode_request(frame)
        return None
