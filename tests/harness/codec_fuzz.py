"""Fuzzing of every codec in both roles with random and mutated frames.

Invariants, per frame fed:

* ``exception`` - nothing but a :class:`~joints.errors.JointsError` comes out of a codec;
* ``hang`` - every call returns within the harness's time limit, and a stream codec makes progress
  (each message or error it yields consumes at least one byte);
* ``reencode`` - a decoded message re-encodes to a frame present in the input (nothing is decoded
  out of bytes that were not a valid frame); for CAN, to the same id and data;
* ``silence-clears`` - (stream codecs) after ``flush()`` nothing stays buffered.

Adding a codec is one entry in :func:`targets`.
"""

from __future__ import annotations

import itertools
import random
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from harness import corpus
from harness.report import Target
from harness.watchdog import Hang, watchdog
from joints.errors import EncodeError, FrameError, JointsError

#: pieces per fuzz case: 1-4 frames (corpus, mutated, random valid, other direction, random bytes)
MAX_PIECES = 4
CASE_LIMIT = 2.0  #: s a case may take before it counts as a hang


@dataclass
class StreamCodec:
    """A byte-stream codec (feed / next_message / flush) in one role."""

    name: str
    make: Callable[[], Any]  #: a fresh codec
    frame_of: Callable[[Any], bytes]  #: the wire frame of a decoded message
    same: Callable[[random.Random], bytes]  #: a frame of the direction this role decodes
    other: Callable[[random.Random], bytes]  #: a frame of the other direction (an echo, another node)
    frames: Sequence[bytes]  #: the corpus
    fix: corpus.Fix
    prepare: Callable[[Any, random.Random, bytes], bytes] | None = None  #: host expectations; may prefix

    def piece(self, rng: random.Random) -> bytes:
        r = rng.random()
        if r < 0.25 and self.frames:
            return rng.choice(self.frames)
        if r < 0.55 and self.frames:
            return corpus.mutate(rng, rng.choice(self.frames), self.frames, self.fix)
        if r < 0.75:
            return self.same(rng)
        if r < 0.85:
            return corpus.mutate(rng, self.same(rng), (), self.fix)
        if r < 0.93:
            return self.other(rng)
        return corpus.random_bytes(rng)

    def run(self, t: Target, count: int, rng: random.Random) -> None:
        while t.units < count:
            n = rng.randint(1, MAX_PIECES)
            stream = b"".join(self.piece(rng) for _ in range(n))
            t.units += n
            try:
                with watchdog(CASE_LIMIT):
                    self.case(t, rng, stream)
            except Hang:
                t.violate("hang", f"case took over {CASE_LIMIT} s: {stream.hex(' ')}")

    def case(self, t: Target, rng: random.Random, stream: bytes) -> None:
        codec = self.make()
        if self.prepare is not None:
            stream = self.prepare(codec, rng, stream)
        cuts = sorted({0, len(stream), *(rng.randrange(len(stream) + 1) for _ in range(rng.randint(0, 3)))})
        flushes = {c for c in cuts if rng.random() < 0.2}
        msgs: list[Any] = []
        for a, b in itertools.pairwise(cuts):
            codec.feed(stream[a:b])
            if not self.drain(t, codec, stream, msgs):
                return
            if b in flushes:
                codec.flush()
                if not self.drain(t, codec, stream, msgs):
                    return
        codec.flush()
        if not self.drain(t, codec, stream, msgs):
            return
        if not t.check("silence-clears", codec.buffered == 0):
            t.example("silence-clears", f"{codec.buffered} bytes left of {stream.hex(' ')}")
        bad = 0
        for m in msgs:
            try:
                frame = self.frame_of(m)
            except Exception as exc:  # noqa: BLE001 - reported as a violation
                t.violate("reencode", f"{m!r} from {stream.hex(' ')} does not encode: {exc!r}")
                bad += 1
                continue
            if frame not in stream:
                t.violate("reencode", f"{m!r} -> {frame.hex(' ')} is not in {stream.hex(' ')}")
                bad += 1
        t.passed("reencode", len(msgs) - bad)

    def drain(self, t: Target, codec: Any, stream: bytes, msgs: list[Any]) -> bool:
        """Take every message out; False after a violation (the case ends)."""
        for _ in range(len(stream) + 2):
            try:
                m = codec.next_message()
            except JointsError:
                t.passed("exception")
                continue
            except Exception as exc:  # noqa: BLE001 - reported as a violation
                t.violate("exception", f"{exc!r} on {stream.hex(' ')}")
                return False
            t.passed("exception")
            if m is None:
                t.passed("hang")
                return True
            msgs.append(m)
        t.violate("hang", f"no progress: more results than bytes from {stream.hex(' ')}")
        return False


@dataclass
class FrameCodec:
    """A CAN codec: one frame in, one message (or a FrameError) out; ``check`` judges the result."""

    name: str
    step: Callable[[Any], Any]  #: feed one frame, return what came out
    check: Callable[[Target, Any, Any], None]  #: (target, frame, result)
    frame: Callable[[random.Random], Any]  #: a fuzz frame
    reset: Callable[[random.Random], None] | None = None  #: between cases (state machines)

    def run(self, t: Target, count: int, rng: random.Random) -> None:
        while t.units < count:
            if self.reset is not None:
                self.reset(rng)
            for _ in range(rng.randint(1, MAX_PIECES)):
                f = self.frame(rng)
                t.units += 1
                try:
                    with watchdog(CASE_LIMIT):
                        try:
                            result: Any = self.step(f)
                        except JointsError as exc:
                            result = exc
                except Hang:
                    t.violate("hang", f"over {CASE_LIMIT} s on {_can_text(f)}")
                    continue
                except Exception as exc:  # noqa: BLE001 - reported as a violation
                    t.violate("exception", f"{exc!r} on {_can_text(f)}")
                    continue
                t.passed("exception")
                t.passed("hang")
                self.check(t, f, result)


def _can_text(f: Any) -> str:
    flags = ("x" if f.is_extended_id else "") + ("r" if f.is_remote_frame else "")
    return f"0x{f.arbitration_id:03X}{flags} [{f.dlc}] {bytes(f.data).hex(' ')}"


# --- Modbus RTU ---------------------------------------------------------------------------------


def _modbus_frame_of(msg: Any) -> bytes:
    from joints.codecs import modbus as mb
    from joints.codecs.crc import append_crc

    try:
        return mb.encode(msg)
    except EncodeError:  # a device decodes quantities the encoder refuses (so a server answers 03)
        if isinstance(msg, (mb.ReadHoldingRegisters, mb.ReadInputRegisters)):
            return append_crc(struct.pack(">BBHH", msg.slave, msg.function, msg.address, msg.count))
        if isinstance(msg, mb.WriteMultipleRegisters):
            n = len(msg.values)
            return append_crc(struct.pack(f">BBHHB{n}H", msg.slave, 16, msg.address, n, 2 * n, *msg.values))
        raise


def _modbus_host_prepare(codec: Any, rng: random.Random, stream: bytes) -> bytes:
    """Half the time a request is outstanding (byte counts checked), sometimes with the adapter's echo."""
    from joints.codecs import modbus as mb

    if rng.random() < 0.5:
        request: mb.Request = rng.choice((
            mb.ReadHoldingRegisters(rng.choice((1, 2, 3)), rng.randrange(0x100), rng.randint(1, 10)),
            mb.WriteSingleRegister(rng.choice((1, 2, 3)), rng.randrange(0x100), rng.randrange(0x10000)),
            mb.WriteMultipleRegisters(rng.choice((1, 2)), rng.randrange(0x100), (1, 2)),
        ))
        codec.expect_reply_to(request)
        if rng.random() < 0.3:
            frame = mb.encode(request)
            codec.expect_echo(frame)
            return frame + stream
    return stream


def _modbus(role_name: str) -> StreamCodec:
    from joints.codecs import modbus as mb

    role = mb.Role.HOST if role_name == "host" else mb.Role.DEVICE
    requests = corpus.serial_corpus("modbus-rtu", "request")
    replies = corpus.serial_corpus("modbus-rtu", "response")

    def request(rng: random.Random) -> bytes:
        return corpus.modbus_request(rng, (1, 2, 3), (0x40, 0x43, 0x47, 0x60, 0xF0, 0x2000, 0x200E, 0x20A7))

    same, other = (corpus.modbus_reply, request) if role is mb.Role.HOST else (request, corpus.modbus_reply)
    return StreamCodec(
        name=f"modbus-rtu/{role_name}", make=lambda: mb.ModbusRtuCodec(role), frame_of=_modbus_frame_of,
        same=same, other=other, frames=replies if role is mb.Role.HOST else requests, fix=corpus.modbus_fix,
        prepare=_modbus_host_prepare if role is mb.Role.HOST else None,
    )


# --- MKS native ----------------------------------------------------------------------------------


def _mks(role_name: str) -> StreamCodec:
    from joints.codecs import mks

    host = role_name == "host"
    role = mks.Role.HOST if host else mks.Role.DEVICE
    downlink = corpus.serial_corpus("mks-native", "request")
    uplink = corpus.serial_corpus("mks-native", "response")

    def down(rng: random.Random) -> bytes:
        return corpus.mks_frame(rng, mks.HEAD_LONG if rng.random() < 0.1 else mks.HEAD_DOWNLINK)

    def up(rng: random.Random) -> bytes:
        return corpus.mks_frame(rng, mks.HEAD_UPLINK)

    def prepare(codec: Any, rng: random.Random, stream: bytes) -> bytes:
        if host and rng.random() < 0.2:
            echo = down(rng)
            codec.expect_echo(echo)
            return echo + stream
        return stream

    return StreamCodec(
        name=f"mks-native/{role_name}", make=lambda: mks.MksCodec(role), frame_of=mks.encode,
        same=up if host else down, other=down if host else up, frames=uplink if host else downlink,
        fix=corpus.mks_fix, prepare=prepare,
    )


# --- eRob CAN custom protocol ----------------------------------------------------------------------


def _can_data_frame(rng: random.Random, ids: Sequence[int], data_corpus: Sequence[tuple[int, bytes]],
                    valid: Callable[[random.Random], tuple[int, bytes]]) -> Any:
    r = rng.random()
    if r < 0.2 and data_corpus:
        can_id, data = rng.choice(data_corpus)
    elif r < 0.45 and data_corpus:
        can_id, data = rng.choice(data_corpus)
        data = corpus.mutate(rng, data)[:8]
        if rng.random() < 0.2:
            can_id = rng.choice(ids)
    elif r < 0.85:
        can_id, data = valid(rng)
    else:
        can_id, data = rng.randrange(0x800), corpus.random_bytes(rng, 8)[: rng.randint(0, 8)]
    remote = rng.random() < 0.02
    extended = rng.random() < 0.02
    if rng.random() < 0.01:
        data = corpus.random_bytes(rng, 64)  # an FD-sized payload
    return corpus.can_frame(can_id if not extended else can_id | rng.randrange(1 << 29), data, remote=remote,
                            extended=extended)


def _erob_can(role_name: str) -> FrameCodec:
    from joints.codecs import erob_can as ec

    role = ec.Role.HOST if role_name == "host" else ec.Role.DEVICE
    frames = corpus.can_corpus("erob-can", "response" if role is ec.Role.HOST else "request")
    frames += corpus.can_corpus("erob-can", "request" if role is ec.Role.HOST else "response")
    indexes = sorted({struct.unpack(">H", d[:2])[0] for _, d in corpus.can_corpus("erob-can", "request")
                      if len(d) >= 2} | set(ec.COMMANDS))
    ids = [ec.REQUEST_BASE + n for n in (1, 2, 127)] + [ec.REPLY_BASE + n for n in (1, 2, 127)] + [0x600, 0x7FF, 0]

    def valid(rng: random.Random) -> tuple[int, bytes]:
        node = rng.choice((1, 2, 3, 127, 0, 128))
        index = rng.choice(indexes) if rng.random() < 0.8 else rng.randrange(0x10000)
        n = rng.choice((0, 1, 2, 3, 4, 5, 6, 7, 8))
        if role is ec.Role.DEVICE or rng.random() < 0.1:
            body = struct.pack(">H", index) + bytes(rng.randrange(256) for _ in range(6))
            return (ec.REQUEST_BASE + node) & 0x7FF, body[: rng.choice((2, 4, 6, 8, n))]
        value = struct.pack(">i", rng.randrange(-(1 << 31), 1 << 31))
        body = rng.choice((b"\x3e", b"\x80", bytes(rng.randrange(256) for _ in range(2)) + b"\x3e", value + b"\x3e",
                           value[: rng.randint(0, 4)]))
        return (ec.REPLY_BASE + node) & 0x7FF, body

    def check(t: Target, frame: Any, result: Any) -> None:
        if isinstance(result, JointsError):
            if not t.check("error-is-frame-error", isinstance(result, FrameError)):
                t.example("error-is-frame-error", f"{result!r} on {_can_text(frame)}")
            return
        again = ec.encode(result)
        if not t.check("reencode", (again.arbitration_id, bytes(again.data)) == (frame.arbitration_id, bytes(frame.data)) and not frame.is_extended_id and not frame.is_remote_frame):
            t.example("reencode", f"{_can_text(frame)} -> {result!r} -> {_can_text(again)}")

    return FrameCodec(name=f"erob-can/{role_name}", step=lambda f: ec.decode(f, role), check=check,
                      frame=lambda rng: _can_data_frame(rng, ids, frames, valid))


# --- CANopen ---------------------------------------------------------------------------------------


def _canopen_ids(rng: random.Random) -> int:
    node = rng.choice((1, 2, 3, 127, rng.randint(1, 127)))
    base = rng.choice((0x000, 0x080, 0x080, 0x100, 0x180, 0x200, 0x280, 0x300, 0x380, 0x400, 0x480, 0x500, 0x580,
                       0x600, 0x700, 0x7E4))
    return base if base in (0x000, 0x100) or (base == 0x080 and rng.random() < 0.5) else (base + node) & 0x7FF


def _canopen_valid(rng: random.Random) -> tuple[int, bytes]:
    can_id = _canopen_ids(rng)
    if can_id == 0:
        return 0, bytes((rng.choice((1, 2, 0x80, 0x81, 0x82, 5)), rng.choice((0, 1, 2, 127))))
    n = rng.choice((8, 8, 8, 0, 1, 2, 4, 6, rng.randint(0, 8)))
    first = rng.choice((0x40, 0x43, 0x4B, 0x4F, 0x23, 0x2B, 0x2F, 0x27, 0x22, 0x21, 0x60, 0x80, 0x00, 0x10, 0x70,
                        0x05, 0x7F, rng.randrange(256)))
    data = bytes((first,)) + bytes(rng.choice((0, 0x60, 0x10, rng.randrange(256))) for _ in range(7))
    return can_id, data[:n]


def _canopen_decode() -> FrameCodec:
    from joints.codecs import canopen as co

    frames = corpus.can_corpus("canopen", "request") + corpus.can_corpus("canopen", "response")

    def check(t: Target, frame: Any, result: Any) -> None:
        if isinstance(result, JointsError):
            if not t.check("error-is-frame-error", isinstance(result, FrameError)):
                t.example("error-is-frame-error", f"{result!r} on {_can_text(frame)}")
            return
        again = co.encode(result)
        if not t.check("reencode", again.arbitration_id == frame.arbitration_id and again.is_remote_frame == frame.is_remote_frame and co.decode(again) == result):
            t.example("reencode", f"{_can_text(frame)} -> {result!r} -> {_can_text(again)}")

    return FrameCodec(name="canopen/decode", step=co.decode, check=check,
                      frame=lambda rng: _can_data_frame(rng, [0x602, 0x582, 0x702, 0x80], frames, _canopen_valid))


def _canopen_sdo_server() -> FrameCodec:
    """The node side (a twin's SDO server) fed what a bus may carry to it."""
    from joints.codecs import canopen as co
    from joints.errors import DeviceRejected

    node = 2
    store: dict[tuple[int, int], bytes] = {}

    def read(index: int, subindex: int) -> bytes:
        if index >= 0x8000:
            raise DeviceRejected("no such object", code=co.SdoAbortCode.OBJECT_DOES_NOT_EXIST)
        return store.get((index, subindex), bytes(((index + subindex) % 13,)))

    def write(index: int, subindex: int, data: bytes) -> None:
        if index >= 0x8000:
            raise DeviceRejected("read only", code=co.SdoAbortCode.WRITE_READ_ONLY)
        store[(index, subindex)] = data

    server = [co.SdoServer(node, read, write)]
    frames = corpus.can_corpus("canopen", "request")

    def frame(rng: random.Random) -> Any:
        f = _can_data_frame(rng, [0x602], frames, _canopen_valid)
        if rng.random() < 0.7 and not f.is_extended_id:
            f.arbitration_id = 0x600 + node
        return f

    def check(t: Target, f: Any, result: Any) -> None:
        if isinstance(result, JointsError):
            t.violate("server-raises", f"{result!r} on {_can_text(f)}")  # a twin must answer, not raise
            return
        t.passed("server-raises")
        if result is None:
            return
        if not t.check("reply-shape", result.arbitration_id == 0x580 + node and result.dlc == 8 and not result.is_remote_frame):
            t.example("reply-shape", f"{_can_text(f)} -> {_can_text(result)}")

    def reset(rng: random.Random) -> None:
        if rng.random() < 0.1:
            server[0] = co.SdoServer(node, read, write)

    return FrameCodec(name="canopen/sdo-server", step=lambda f: server[0].feed(f), check=check, frame=frame,
                      reset=reset)


def _canopen_sdo_client() -> FrameCodec:
    """The master side fed whatever comes back on 0x580+node during a transfer."""
    from joints.codecs import canopen as co

    node = 2
    client = [co.SdoClient(node)]
    frames = corpus.can_corpus("canopen", "response")

    def frame(rng: random.Random) -> Any:
        f = _can_data_frame(rng, [0x582], frames, _canopen_valid)
        if rng.random() < 0.8 and not f.is_extended_id:
            f.arbitration_id = 0x580 + node
        return f

    def reset(rng: random.Random) -> None:
        c = client[0] = co.SdoClient(node)
        index, sub = rng.choice(((0x6064, 0), (0x1008, 0), (0x6040, 0), (rng.randrange(0x10000), rng.randrange(256))))
        if rng.random() < 0.5:
            c.upload(index, sub)
        else:
            c.download(index, sub, corpus.random_bytes(rng, 12), segmented=rng.random() < 0.3)

    def check(t: Target, f: Any, result: Any) -> None:
        if isinstance(result, JointsError):
            t.passed("step-type")
            return
        if not t.check("step-type", isinstance(result, (co.SdoSend, co.SdoDone, co.SdoFailed))):
            t.example("step-type", f"{result!r}")
        if isinstance(result, co.SdoSend):
            if not t.check("send-shape", result.frame.arbitration_id == 0x600 + node and result.frame.dlc == 8):
                t.example("send-shape", f"{_can_text(f)} -> {_can_text(result.frame)}")
        elif (isinstance(result, co.SdoFailed) and result.frame is not None
              and not t.check("send-shape", result.frame.arbitration_id == 0x600 + node)):
            t.example("send-shape", _can_text(result.frame))

    def step(f: Any) -> Any:
        return client[0].feed(f)

    return FrameCodec(name="canopen/sdo-client", step=step, check=check, frame=frame, reset=reset)


def targets() -> dict[str, Callable[[], StreamCodec | FrameCodec]]:
    """Every codec, both roles: name -> maker (makers import lazily: python-can only where used)."""
    return {
        "modbus-rtu/host": lambda: _modbus("host"),
        "modbus-rtu/device": lambda: _modbus("device"),
        "mks-native/host": lambda: _mks("host"),
        "mks-native/device": lambda: _mks("device"),
        "erob-can/host": lambda: _erob_can("host"),
        "erob-can/device": lambda: _erob_can("device"),
        "canopen/decode": _canopen_decode,
        "canopen/sdo-server": _canopen_sdo_server,
        "canopen/sdo-client": _canopen_sdo_client,
    }


def run(report: Any, names: Sequence[str], count: int, seed: int) -> None:
    for name in names:
        maker = targets()[name]
        codec = maker()
        t = report.target(f"codec {name}", "codec")
        rng = random.Random(f"{seed}/codec/{name}")
        with report.timed(t):
            codec.run(t, count, rng)
