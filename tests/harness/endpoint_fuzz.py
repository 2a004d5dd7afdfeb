"""Fuzzing of every twin endpoint: the device side of a bus with real twins behind it, fed random and
mutated frames, judged against what the twins' firmware really did.

Endpoints come from the registry: every device family x every protocol it has a front for, two
drives per bus (addresses 2 and 3) so "another slave's address" is real. How to fuzz and judge a
protocol is one :class:`Adapter` entry in :data:`ADAPTERS`; a protocol without one still gets the
generic checks (no exception, no hang), and the report says so.

Adapters: Modbus RTU (eRob, ZLAC and MKS Part 8 fronts), MKS native, eRob CAN, CANopen.

Invariants (each adapter checks those its protocol can state; CANopen: exception, hang,
reply-to-other-address - one SDO answer per SDO request, from the node asked -, reply-from-absent-node,
write-outside-frame - the firmware acts only on NMT, SYNC, PDOs and SDOs to a node on the bus -,
unanswered):

* ``exception`` - the endpoint never raises (a served twin would die);
* ``hang`` - every call returns within the time limit;
* ``executed-invalid`` - every request a twin executed is a valid frame of the input, complete
  between two silences (never a corrupt one, never one cut by a silence);
* ``executed-twice`` - no frame executed more often than it occurs, no write acted on twice;
* ``write-outside-frame`` - the firmware is written only while a write request is served;
* ``ack-without-write`` - a write answered as done was done;
* ``failed-but-written`` - a write answered with a failure reply (MKS V1.0.6+: FC06 data 0xFFFF, FC16
  quantity 0) wrote nothing;
* ``reply-to-broadcast`` / ``reply-to-other-address`` - replies only to the requester's address,
  and only for addresses on the bus;
* ``reply-stream`` - the bytes out are exactly the replies the fronts built (no junk);
* ``unanswered`` - after silence, a valid request to a drive on the bus is answered.
"""

from __future__ import annotations

import itertools
import random
import struct
import traceback
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from harness import corpus
from harness.codec_fuzz import _can_text, _modbus_frame_of
from harness.report import Report, Target
from harness.watchdog import Hang, watchdog
from joints import registry
from joints.config import BusConfig
from joints.sim.world import DriveSpec

ADDRESSES = (2, 3)  #: the drives on a fuzzed bus
CASE_LIMIT = 2.0  #: s per case before it counts as a hang
REBUILD = 5000  #: cases between fresh twins (the fuzzer drives them into every state; start over now and then)


@dataclass
class Endpoint:
    """One fuzzed bus: the device bus, its twins and their fronts by address."""

    name: str
    family: Any
    protocol: str
    bus: Any
    twins: dict[int, Any]
    fronts: dict[int, Any]


def build(family: Any, protocol: str) -> Endpoint:
    """The device bus of ``protocol`` with twins of ``family`` at :data:`ADDRESSES` (as the world builds them)."""
    p = registry.PROTOCOLS[protocol]
    bus = p.device_bus(BusConfig(name="fuzz", protocol=protocol))
    twins: dict[int, Any] = {}
    fronts: dict[int, Any] = {}
    for address in ADDRESSES:
        specs = [DriveSpec(bus="fuzz", name=f"{family.name}{address}{ch or ''}", mjcf_joint="j", address=address,
                           profile=family.profile(None), device=family.devices[0], maker=family, protocol=protocol,
                           channel=ch) for ch in (family.channels or (None,))]
        twin, _steppers = family.build_twin(specs, {s.name: 0.01 for s in specs})
        front = family.front(protocol, twin, address)
        bus.add(front)
        twins[address], fronts[address] = twin, front
    return Endpoint(f"{family.name}/{protocol}", family, protocol, bus, twins, fronts)


def endpoints() -> list[tuple[str, Any, str]]:
    """(name, family, protocol) of every twin endpoint in the registry."""
    return [(f"{f.name}/{p}", f, p) for f in registry.FAMILIES.values() for p in f.fronts]


# --- what the twins did ---------------------------------------------------------------------------


@dataclass
class Ledger:
    """Filled by the wrappers around the endpoint: executions, firmware writes, replies (in order)."""

    executed: list[tuple[Any, Any, Any]] = field(default_factory=list)  #: (request, reply(s), segment so far)
    replies: list[Any] = field(default_factory=list)  #: every reply built, in order
    #: (request number, address, items) of top-level firmware writes, numbered by the request served
    writes: list[tuple[int, int, Any]] = field(default_factory=list)
    outside: list[str] = field(default_factory=list)  #: firmware writes while no write request was served
    serving_write: bool = False
    depth: int = 0

    def clear(self) -> None:
        self.executed.clear()
        self.replies.clear()
        self.writes.clear()
        self.outside.clear()


def _wrap_firmware(ledger: Ledger, address: int, twin: Any) -> None:
    original = twin.write_many

    def write_many(items: Any) -> None:
        top = ledger.depth == 0
        ledger.depth += 1
        try:
            original(items)
        finally:
            ledger.depth -= 1
        if top:
            if ledger.serving_write:
                ledger.writes.append((len(ledger.executed), address, list(items)))
            else:
                ledger.outside.append(f"drive {address}: {list(items)!r}")

    twin.write_many = write_many


# --- the protocol adapters -------------------------------------------------------------------------


class Adapter:
    """How to fuzz and judge one protocol's endpoint."""

    generic = False
    #: the fuzzer drove the twins where a probe cannot reach them (every drive moved to one address or
    #: switched to another protocol): start over from fresh twins
    stale = False

    def __init__(self, ep: Endpoint, rng: random.Random) -> None:
        self.ep = ep
        self.rng = rng
        self.ledger = Ledger()
        for address, twin in ep.twins.items():
            if hasattr(twin, "write_many"):
                _wrap_firmware(self.ledger, address, twin)

    def case(self, t: Target) -> int:
        """Run one fuzz case; the number of frames fed."""
        raise NotImplementedError


class StreamAdapter(Adapter):
    """A byte-stream endpoint (RS485): frames cut into random chunks, silences between and inside
    them; subclasses draw the pieces (:meth:`piece`), judge what came out and probe liveness."""

    def __init__(self, ep: Endpoint, rng: random.Random) -> None:
        super().__init__(ep, rng)
        self.segment = bytearray()  #: bytes fed since the last silence
        self.silences = 0  #: numbers the segments

    def piece(self) -> bytes:
        raise NotImplementedError

    def judge(self, t: Target, fed: bytes, out: bytes) -> None:
        raise NotImplementedError

    def probe(self, t: Target) -> None:
        raise NotImplementedError

    def feed(self, data: bytes) -> bytes:
        self.segment += data
        out: bytes = self.ep.bus.receive(data)
        return out

    def silence(self) -> bytes:
        out: bytes = self.ep.bus.silence()
        self.segment.clear()
        self.silences += 1
        return out

    def case(self, t: Target) -> int:
        rng = self.rng
        n = rng.randint(1, 4)
        chunks: list[tuple[bytes, bool]] = []  #: (bytes, silence after them)
        for _ in range(n):
            frame = self.piece()
            cuts = sorted({0, len(frame), *(rng.randrange(len(frame) + 1) for _ in range(rng.randint(0, 2)))})
            for a, b in itertools.pairwise(cuts):
                chunks.append((frame[a:b], rng.random() < 0.05))  # a gap inside a frame: garbage before it
            if chunks and rng.random() < 0.5:
                chunks[-1] = (chunks[-1][0], True)
        self.run_chunks(t, chunks)
        return n

    def run_chunks(self, t: Target, chunks: Sequence[tuple[bytes, bool]]) -> None:
        """Feed ``chunks`` (each followed by a silence where flagged), judge, then probe."""
        ledger = self.ledger
        self.silence()
        ledger.clear()
        out = bytearray()
        fed = bytearray()
        for data, quiet in chunks:
            fed += data
            out += self.feed(data)
            if quiet:
                out += self.silence()
        out += self.silence()
        self.judge(t, bytes(fed), bytes(out))
        self.probe(t)


class ModbusAdapter(StreamAdapter):
    """Modbus RTU: bytes in random chunks, silences between and inside frames."""

    def __init__(self, ep: Endpoint, rng: random.Random) -> None:
        super().__init__(ep, rng)
        from joints.codecs import modbus as mb

        self.mb = mb
        bus, ledger = ep.bus, self.ledger
        exchange = bus.exchange
        writes = (mb.WriteSingleRegister, mb.WriteMultipleRegisters)

        def recorded(msg: Any) -> Any:
            ledger.serving_write = isinstance(msg, writes)
            try:
                reply = exchange(msg)
            finally:
                ledger.serving_write = False
            ledger.executed.append((msg, reply, (self.silences, bytes(self.segment))))
            if reply is not None:
                ledger.replies.append(reply)
            return reply

        bus.exchange = recorded
        for front in ep.fronts.values():
            if hasattr(front, "malformed"):
                self._wrap_malformed(front)
        front = next(iter(ep.fronts.values()))  # the front's own map: a register table, or a block map
        self.registers, self.probe_read = _modbus_shape(getattr(front, "table", None) or front.map)
        self.requests = corpus.serial_corpus("modbus-rtu", "request")
        self.replies = corpus.serial_corpus("modbus-rtu", "response")

    def _wrap_malformed(self, front: Any) -> None:
        original, ledger = front.malformed, self.ledger

        def malformed(frame: bytes) -> Any:
            reply = original(frame)
            ledger.executed.append((("malformed", bytes(frame)), reply, (self.silences, bytes(self.segment))))
            if reply is not None:
                ledger.replies.append(reply)
            return reply

        front.malformed = malformed

    def piece(self) -> bytes:
        rng = self.rng
        r = rng.random()
        present = list(self.ep.fronts)
        if r < 0.45:
            return corpus.modbus_request(rng, present + [1, 4], self.registers)
        if r < 0.6:
            return corpus.mutate(rng, corpus.modbus_request(rng, present, self.registers), self.requests,
                                 corpus.modbus_fix)
        if r < 0.75:
            return corpus.mutate(rng, rng.choice(self.requests), self.requests, corpus.modbus_fix)
        if r < 0.82:
            return rng.choice(self.requests)
        if r < 0.92:
            return rng.choice(self.replies) if rng.random() < 0.5 else corpus.modbus_reply(rng)
        return corpus.random_bytes(rng)


    def judge(self, t: Target, fed: bytes, out: bytes) -> None:
        mb, ledger = self.mb, self.ledger
        present = set(self.ep.bus.slaves)
        seen: dict[tuple[bytes, int, bytes], int] = {}
        for i, (msg, reply, (number, segment)) in enumerate(ledger.executed):
            if isinstance(msg, tuple):  # a malformed frame offered to its slave
                frame = msg[1]
                if not t.check("executed-invalid", frame in segment and frame[0] in present):
                    t.example("executed-invalid", f"malformed {frame.hex(' ')} not in segment {segment.hex(' ')}")
                if reply is not None:
                    if not t.check("reply-to-broadcast", frame[0] != 0):
                        t.example("reply-to-broadcast", f"{reply!r} to {frame.hex(' ')}")
                    if not t.check("reply-to-other-address", reply.slave == frame[0] and frame[0] in present):
                        t.example("reply-to-other-address", f"{reply!r} to {frame.hex(' ')}")
                continue
            try:
                frame = _modbus_frame_of(msg)
            except Exception:  # noqa: BLE001 - reported
                t.violate("executed-invalid", f"{msg!r} has no frame")
                continue
            ok = frame in segment
            if not t.check("executed-invalid", ok):
                t.example("executed-invalid", f"{msg!r} ({frame.hex(' ')}) not in segment {segment.hex(' ')} (input {fed.hex(' ')})")
            key = (frame, number, segment)
            seen[key] = seen.get(key, 0) + 1
            if reply is not None:
                if not t.check("reply-to-broadcast", msg.slave != 0):
                    t.example("reply-to-broadcast", f"{reply!r} to broadcast {msg!r}")
                if not t.check("reply-to-other-address", reply.slave == msg.slave and msg.slave in present):
                    t.example("reply-to-other-address", f"{reply!r} to {msg!r}")
                if self._failure_reply(msg, reply):  # "the write failed": this request wrote nothing
                    if not t.check("failed-but-written", not any(n == i for n, _a, _i in ledger.writes)):
                        t.example("failed-but-written", f"{reply!r} to {msg!r} but the firmware was written")
                elif isinstance(msg, (mb.WriteSingleRegister, mb.WriteMultipleRegisters)) and not isinstance(
                        reply, mb.ExceptionReply):
                    done = sum(1 for _n, a, _i in ledger.writes if a == msg.slave)
                    if not t.check("ack-without-write", done >= 1):
                        t.example("ack-without-write", f"{reply!r} to {msg!r} but nothing written")
        for (frame, _number, segment), k in seen.items():
            if not t.check("executed-twice", k <= _occurrences(segment, frame)):
                t.example("executed-twice", f"{frame.hex(' ')} executed {k}x, in segment {segment.hex(' ')}")
        writes_per_request = sum(1 for m, _r, _s in ledger.executed if not isinstance(m, tuple)
                                 and isinstance(m, (mb.WriteSingleRegister, mb.WriteMultipleRegisters))
                                 for _ in (self.ep.fronts if m.slave == 0 else (m.slave,)))
        if not t.check("executed-twice", len(ledger.writes) <= writes_per_request):
            t.example("executed-twice", f"{len(ledger.writes)} firmware writes for {writes_per_request} write requests")
        _once_per_frame(t, ledger, fed)
        if not t.check("write-outside-frame", not ledger.outside):
            t.example("write-outside-frame", "; ".join(ledger.outside[:3]))
        expected = b"".join(mb.encode(r) for r in ledger.replies)
        if not t.check("reply-stream", out == expected):
            t.example("reply-stream", f"out {out.hex(' ')} != replies {expected.hex(' ')} (input {fed.hex(' ')})")
        # the bytes on the wire, judged on their own
        codec = mb.ModbusRtuCodec(mb.Role.HOST)
        codec.feed(out)
        codec.flush()
        while True:
            try:
                r = codec.next_message()
            except Exception:  # noqa: BLE001 - junk on the wire
                t.violate("reply-stream", f"undecodable output {out.hex(' ')}")
                break
            if r is None:
                break
            if not t.check("reply-to-other-address", r.slave in present):
                t.example("reply-to-other-address", f"{r!r} from an address not on the bus")

    def _failure_reply(self, msg: Any, reply: Any) -> bool:
        """A failure reply (MKS V1.0.6+, its front's ``failure_replies``): an FC06 write answered with register data
        0xFFFF (no MKS register takes 0xFFFF, so even its echo is one), an FC16 write with quantity 0."""
        mb = self.mb
        if not getattr(self.ep.fronts.get(msg.slave), "failure_replies", False):
            return False
        return (isinstance(reply, mb.WriteSingleRegisterReply) and reply.value == 0xFFFF) or (
            isinstance(reply, mb.WriteMultipleRegistersReply) and reply.count == 0)

    def probe(self, t: Target) -> None:
        """After silence a valid request to a drive on the bus is answered, alone."""
        mb, rng, ledger = self.mb, self.rng, self.ledger
        speaking = [a for a, f in self.ep.bus.slaves.items() if getattr(f, "speaks", True)]
        if not speaking:  # the fuzzer switched every drive to another protocol: nothing can answer
            self.stale = True
            return
        address = rng.choice(speaking)
        request = self.probe_read(address)
        ledger.clear()
        out = self.feed(mb.encode(request)) + self.silence()
        codec = mb.ModbusRtuCodec(mb.Role.HOST)
        codec.feed(out)
        codec.flush()
        try:
            got = codec.next_message()
            rest = codec.next_message()
        except Exception:  # noqa: BLE001
            got, rest = None, "junk"
        if not t.check("unanswered", isinstance(got, mb.ReadRegistersReply) and got.slave == address
                       and len(got.values) == request.count and rest is None):
            t.example("unanswered", f"probe {request!r}: {out.hex(' ')}")


def _modbus_shape(table: Any) -> tuple[list[int], Callable[[int], Any]]:
    """The register addresses a family's Modbus map serves, and a read every drive answers.

    A register table (eRob, ZLAC: FC03 of any register) or a map of fixed request blocks (MKS Part 8:
    FC04 of documented blocks only).
    """
    from joints.codecs import modbus as mb

    blocks = getattr(table, "blocks", None)
    if blocks is not None:
        reads = [b for b in blocks if b.function == mb.READ_INPUT_REGISTERS]
        first = reads[0]
        return (sorted({b.address for b in blocks}),
                lambda slave: mb.ReadInputRegisters(slave, first.address, first.count))
    reg = next(r for r in table if r.access.readable)
    return sorted({r.address for r in table}), lambda slave: mb.ReadHoldingRegisters(slave, reg.address, reg.words)


class ErobCanAdapter(Adapter):
    """eRob CAN custom protocol: one frame at a time through the bus's ``on_frame``."""

    def __init__(self, ep: Endpoint, rng: random.Random) -> None:
        super().__init__(ep, rng)
        from joints.codecs import erob_can as ec
        from joints.devices.erob.can import EROB_CAN

        self.ec = ec
        self.current: Any = None
        bus, ledger = ep.bus, self.ledger
        exchange = bus.exchange

        def recorded(request: Any) -> Any:
            ledger.serving_write = isinstance(request, (ec.Write, ec.Command))
            try:
                replies = exchange(request)
            finally:
                ledger.serving_write = False
            ledger.executed.append((request, list(replies), b""))
            ledger.replies.extend(replies)
            return replies

        bus.exchange = recorded
        keys = [EROB_CAN.key(n) for n in EROB_CAN]
        self.indexes = sorted({(k.index, k.subindex) for k in keys} | {(i, None) for i in ec.COMMANDS})
        self.readable = [(k.index, k.subindex) for n, k in ((n, EROB_CAN.key(n)) for n in EROB_CAN)
                         if EROB_CAN.access(n).readable and k.reach.value == "value"]
        self.frames = corpus.can_corpus("erob-can", "request") + corpus.can_corpus("erob-can", "response")

    def frame(self) -> Any:
        ec, rng = self.ec, self.rng
        r = rng.random()
        nodes = list(self.ep.fronts) + [1, 4, 127]
        if r < 0.55:
            index, sub = rng.choice(self.indexes)
            node = rng.choice(nodes)
            value = rng.choice((0, 1, 2, -1, rng.randrange(-(1 << 31), 1 << 31), rng.randrange(1000)))
            shape = rng.randrange(4)
            data = struct.pack(">H", index)
            if sub is not None and shape != 0:
                data += struct.pack(">H", sub)
            if shape >= 2:
                data += struct.pack(">i", value)
            return corpus.can_frame(ec.REQUEST_BASE + node, data)
        if r < 0.75:
            can_id, data = rng.choice(self.frames)
            data = corpus.mutate(rng, data)[:8]
            if rng.random() < 0.3:
                can_id = ec.REQUEST_BASE + rng.choice(nodes)
            return corpus.can_frame(can_id, data)
        if r < 0.85:
            can_id, data = rng.choice(self.frames)
            return corpus.can_frame(can_id, data)
        return corpus.can_frame(rng.randrange(0x800), corpus.random_bytes(rng, 8)[: rng.randint(0, 8)],
                                remote=rng.random() < 0.05, extended=rng.random() < 0.05)

    def case(self, t: Target) -> int:
        n = self.rng.randint(1, 4)
        self.run_frames(t, [self.frame() for _ in range(n)])
        return n

    def run_frames(self, t: Target, frames: Sequence[Any]) -> None:
        """Feed ``frames`` one by one, judging each, then probe."""
        ec, ledger = self.ec, self.ledger
        nodes = set(self.ep.fronts)
        for f in frames:
            ledger.clear()
            out = list(self.ep.bus.on_frame(f))
            try:
                valid = ec.decode(f, ec.Role.DEVICE) if not (f.is_extended_id or f.is_remote_frame) else None
            except Exception:  # noqa: BLE001 - not a request
                valid = None
            if not t.check("executed-invalid", all(req == valid for req, _r, _s in ledger.executed)):
                t.example("executed-invalid", f"{[req for req, _r, _s in ledger.executed]!r} from {_can_text(f)}")
            if not t.check("executed-twice", len(ledger.executed) <= 1):
                t.example("executed-twice", f"{len(ledger.executed)}x {_can_text(f)}")
            if not t.check("write-outside-frame", not ledger.outside):
                t.example("write-outside-frame", "; ".join(ledger.outside[:3]))
            _once_per_frame(t, ledger, _can_text(f))
            expected = [ec.encode(r) for r in ledger.replies]
            if not t.check("reply-stream", [(m.arbitration_id, bytes(m.data)) for m in out] == [(m.arbitration_id, bytes(m.data)) for m in expected]):
                t.example("reply-stream", f"{[_can_text(m) for m in out]} != {[_can_text(m) for m in expected]}")
            for m in out:
                node = m.arbitration_id - ec.REPLY_BASE
                if not t.check("reply-to-other-address", valid is not None and node == valid.node and node in nodes):
                    t.example("reply-to-other-address", f"{_can_text(m)} after {_can_text(f)}")
            acked = any(isinstance(r, ec.Ack) for _q, rs, _s in ledger.executed for r in rs)
            if isinstance(valid, ec.Write) and acked and not t.check("ack-without-write", len(ledger.writes) >= 1):
                t.example("ack-without-write", f"ack to {valid!r}, nothing written")
        self.probe(t)

    def probe(self, t: Target) -> None:
        ec, rng = self.ec, self.rng
        node = rng.choice(list(self.ep.fronts))
        index, sub = (2, None)  # actual position (7.5.1): always readable
        out = list(self.ep.bus.on_frame(ec.encode(ec.Read(node, index, sub))))
        ok = len(out) == 1 and out[0].arbitration_id == ec.REPLY_BASE + node
        if ok:
            reply = ec.decode(out[0], ec.Role.HOST)
            ok = isinstance(reply, ec.ValueReply)
        if not t.check("unanswered", ok):
            t.example("unanswered", f"probe read of actual position at {node}: {[_can_text(m) for m in out]}")


class MksAdapter(StreamAdapter):
    """MKS native RS485: bytes in random chunks and silences, like Modbus; broadcast, group and long
    packets are executed by every drive they address and answered by none."""

    def __init__(self, ep: Endpoint, rng: random.Random) -> None:
        super().__init__(ep, rng)
        from joints.codecs import mks

        self.mks = mks
        bus, ledger = ep.bus, self.ledger
        exchange = bus.exchange

        def recorded(msg: Any) -> Any:
            speaking = [f for f in bus.fronts if f.speaks]
            who = ([f.address for f in speaking], [f.group for f in speaking if f.group])
            ledger.serving_write = not type(msg).__name__.startswith(("Read", "Query"))
            try:
                reply = exchange(msg)
            finally:
                ledger.serving_write = False
            ledger.executed.append((msg, reply, (self.silences, bytes(self.segment), who)))
            if reply is not None:
                ledger.replies.append(reply)
            return reply

        bus.exchange = recorded
        self.requests = corpus.serial_corpus("mks-native", "request")
        self.replies = corpus.serial_corpus("mks-native", "response")

    def piece(self) -> bytes:
        rng, mks = self.rng, self.mks
        r = rng.random()
        if r < 0.45:
            frame = corpus.mks_frame(rng, mks.HEAD_LONG if rng.random() < 0.05 else mks.HEAD_DOWNLINK)
            if rng.random() < 0.7:  # to a drive on the bus
                frame = mks.with_checksum(frame[:1] + bytes((rng.choice(list(self.ep.fronts)),)) + frame[2:-1])
            return frame
        if r < 0.65:
            return corpus.mutate(rng, rng.choice(self.requests), self.requests, corpus.mks_fix)
        if r < 0.75:
            return rng.choice(self.requests)
        if r < 0.88:
            return rng.choice(self.replies) if rng.random() < 0.5 else corpus.mks_frame(rng, mks.HEAD_UPLINK)
        return corpus.random_bytes(rng)


    def judge(self, t: Target, fed: bytes, out: bytes) -> None:
        mks, ledger = self.mks, self.ledger
        seen: dict[tuple[bytes, int, bytes], int] = {}
        for msg, reply, (number, segment, (addresses, groups)) in ledger.executed:
            frame = mks.encode(msg)
            if not t.check("executed-invalid", frame in segment):
                t.example("executed-invalid", f"{msg!r} ({frame.hex(' ')}) not in segment {segment.hex(' ')}")
            key = (frame, number, segment)
            seen[key] = seen.get(key, 0) + 1
            if reply is None:
                continue
            address = getattr(msg, "address", None)
            if not t.check("reply-to-broadcast", address not in (None, mks.BROADCAST)
                           and not isinstance(msg, mks.LongPacket)):
                t.example("reply-to-broadcast", f"{reply!r} to {msg!r}")
            if not t.check("reply-to-other-address", reply.address == address and address in addresses
                           and (address not in groups or address in addresses)):
                t.example("reply-to-other-address", f"{reply!r} to {msg!r} (drives {addresses}, groups {groups})")
        for (frame, _n, segment), k in seen.items():
            if not t.check("executed-twice", k <= _occurrences(segment, frame)):
                t.example("executed-twice", f"{frame.hex(' ')} executed {k}x in segment {segment.hex(' ')}")
        _once_per_frame(t, ledger, fed)
        if not t.check("write-outside-frame", not ledger.outside):
            t.example("write-outside-frame", "; ".join(ledger.outside[:3]))
        expected = b"".join(mks.encode(r) for r in ledger.replies)
        if not t.check("reply-stream", out == expected):
            t.example("reply-stream", f"out {out.hex(' ')} != replies {expected.hex(' ')} (input {fed.hex(' ')})")

    def probe(self, t: Target) -> None:
        mks, rng, ledger = self.mks, self.rng, self.ledger
        # (a drive the fuzzer sent into its IAP boot loader or silent state, 0x50 of V1.0.8, hears no read)
        speaking = [f for f in self.ep.bus.fronts if f.speaks and f.firmware.hears(mks.ReadEncoderCarry.function)]
        addresses = [f.address for f in speaking]
        groups = {f.group for f in self.ep.bus.fronts if f.group}
        unique = [a for a in addresses if addresses.count(a) == 1 and a not in groups and a != mks.BROADCAST]
        if not unique:  # the fuzzer moved every drive onto one address or off the protocol
            self.stale = True
            return
        address = rng.choice(unique)
        ledger.clear()
        out = self.feed(mks.encode(mks.ReadEncoderCarry(address))) + self.silence()
        codec = mks.MksCodec(mks.Role.HOST)
        codec.feed(out)
        codec.flush()
        try:
            got, rest = codec.next_message(), codec.next_message()
        except Exception:  # noqa: BLE001
            got, rest = None, "junk"
        if not t.check("unanswered", isinstance(got, mks.EncoderCarryReply) and got.address == address
                       and rest is None):
            t.example("unanswered", f"probe read of the encoder at {address}: {out.hex(' ')}")


class CanopenAdapter(Adapter):
    """CANopen: NMT, SYNC, SDO requests, guard requests, PDOs and noise, one frame at a time."""

    def __init__(self, ep: Endpoint, rng: random.Random) -> None:
        super().__init__(ep, rng)
        from joints.codecs import canopen as co
        from joints.devices.erob.canopen import EROB_CANOPEN

        self.co = co
        self.objects = sorted({(k.index, k.subindex) for k in (EROB_CANOPEN.key(n) for n in EROB_CANOPEN)})
        self.frames = corpus.can_corpus("canopen", "request") + corpus.can_corpus("canopen", "response")

    def frame(self) -> Any:
        rng = self.rng
        nodes = list(self.ep.fronts) + [0, 1, 4]
        r = rng.random()
        if r < 0.08:
            return corpus.can_frame(0, bytes((rng.choice((1, 2, 0x80, 0x81, 0x82, 3)), rng.choice(nodes))))
        if r < 0.12:
            return corpus.can_frame(0x80, b"" if rng.random() < 0.7 else bytes((rng.randint(0, 255),)))
        if r < 0.6:
            node = rng.choice(nodes) or 2
            index, sub = rng.choice(self.objects) if rng.random() < 0.9 else (rng.randrange(0x10000), 0)
            command = rng.choice((0x40, 0x40, 0x23, 0x2B, 0x2F, 0x27, 0x22, 0x21, 0x60, 0x70, 0x00, 0x10, 0x80,
                                  0xA0, 0xC0, rng.randrange(256)))
            data = bytes((command, index & 0xFF, index >> 8, sub)) + bytes(rng.randrange(256) for _ in range(4))
            return corpus.can_frame(0x600 + node, data if rng.random() < 0.95 else data[: rng.randint(0, 7)])
        if r < 0.66:
            return corpus.can_frame(0x700 + (rng.choice(nodes) or 2), b"\x00", remote=True)
        if r < 0.78:
            base = rng.choice((0x200, 0x300, 0x400, 0x500))
            return corpus.can_frame(base + (rng.choice(nodes) or 2), corpus.random_bytes(rng, 8)[: rng.randint(0, 8)])
        if r < 0.9:
            can_id, data = rng.choice(self.frames)
            return corpus.can_frame(can_id, corpus.mutate(rng, data)[:8] if rng.random() < 0.5 else data)
        return corpus.can_frame(rng.randrange(0x800), corpus.random_bytes(rng, 8)[: rng.randint(0, 8)],
                                remote=rng.random() < 0.05, extended=rng.random() < 0.05)

    def case(self, t: Target) -> int:
        n = self.rng.randint(1, 4)
        self.run_frames(t, [self.frame() for _ in range(n)])
        return n

    def run_frames(self, t: Target, frames: Sequence[Any]) -> None:
        co, ledger = self.co, self.ledger
        nodes = {f.node for f in self.ep.bus.fronts}
        for f in frames:
            ledger.clear()
            route = co.classify(f)
            # what may act on the drive: NMT, SYNC, an SDO request to a drive on the bus, a PDO
            ledger.serving_write = (route.kind in (co.Kind.NMT, co.Kind.SYNC) or route.kind.is_pdo
                                    or (route.kind is co.Kind.SDO_RX and route.node in nodes))
            try:
                out = list(self.ep.bus.on_frame(f))
            finally:
                ledger.serving_write = False
            if not t.check("write-outside-frame", not ledger.outside):
                t.example("write-outside-frame", f"{'; '.join(ledger.outside[:3])} after {_can_text(f)}")
            sdo = [m for m in out if co.classify(m).kind is co.Kind.SDO_TX]
            ok = not sdo or (route.kind is co.Kind.SDO_RX and len(sdo) == 1
                             and sdo[0].arbitration_id == 0x580 + route.node and route.node in nodes)
            if not t.check("reply-to-other-address", ok):
                t.example("reply-to-other-address", f"{[_can_text(m) for m in sdo]} after {_can_text(f)}")
            for m in out:
                kind, node = co.classify(m)
                if kind in (co.Kind.SDO_TX, co.Kind.HEARTBEAT, co.Kind.BOOT_UP, co.Kind.EMCY) and not t.check(
                        "reply-from-absent-node", node in nodes):
                    t.example("reply-from-absent-node", f"{_can_text(m)} after {_can_text(f)}")
        self.probe(t)

    def probe(self, t: Target) -> None:
        """A drive put into PRE-OPERATIONAL answers an SDO upload of the device type (0x1000).

        (One that has not booted yet - no tick since power-on - is booted by reset communication.)
        """
        co, rng = self.co, self.rng
        front = rng.choice(self.ep.bus.fronts)
        node = front.node
        command = (co.NmtCommand.RESET_COMMUNICATION if front.nmt is co.NmtState.INITIALISING
                   else co.NmtCommand.ENTER_PRE_OPERATIONAL)
        self.ep.bus.on_frame(co.encode(co.Nmt(command, node)))
        out = [m for m in self.ep.bus.on_frame(co.encode(co.SdoUploadInitiate(node, 0x1000, 0)))
               if co.classify(m).kind is co.Kind.SDO_TX]
        ok = len(out) == 1 and out[0].arbitration_id == 0x580 + node
        if ok:
            reply = co.decode(out[0])
            ok = isinstance(reply, co.SdoUploadInitiateResponse) and reply.index == 0x1000
        if not t.check("unanswered", ok):
            t.example("unanswered", f"probe upload of 0x1000 at node {node}: {[_can_text(m) for m in out]}")


class GenericAdapter(Adapter):
    """No protocol knowledge: random and mutated bytes or frames; checks no exception and no hang."""

    generic = True

    def case(self, t: Target) -> int:
        rng, bus = self.rng, self.ep.bus
        n = rng.randint(1, 4)
        if hasattr(bus, "receive"):
            for _ in range(n):
                bus.receive(corpus.random_bytes(rng, 32))
                if rng.random() < 0.5 and hasattr(bus, "silence"):
                    bus.silence()
        elif hasattr(bus, "on_frame"):
            for _ in range(n):
                bus.on_frame(corpus.can_frame(rng.randrange(0x800), corpus.random_bytes(rng, 8)[: rng.randint(0, 8)]))
        return n


#: protocol -> adapter; a protocol missing here gets :class:`GenericAdapter` (and a note in the report)
ADAPTERS: dict[str, Callable[[Endpoint, random.Random], Adapter]] = {
    "modbus-rtu": ModbusAdapter,
    "erob-can": ErobCanAdapter,
    "mks-serial": MksAdapter,
    "canopen": CanopenAdapter,
}


def _once_per_frame(t: Target, ledger: Ledger, what: object) -> None:
    """No firmware write (drive, parameter, value) applied twice by one frame (a front may write
    several parameters for one frame, as the eRob CAN analog set-point does)."""
    items: dict[tuple[int, int, str, int], int] = {}
    for number, address, written in ledger.writes:
        for name, value in written:
            key = (number, address, name, value)
            items[key] = items.get(key, 0) + 1
    twice = [k for k, n in items.items() if n > 1]
    if not t.check("executed-twice", not twice):
        t.example("executed-twice", f"{twice} written twice by {what!r}")


def _occurrences(haystack: bytes, needle: bytes) -> int:
    n, i = 0, haystack.find(needle)
    while i >= 0:
        n += 1
        i = haystack.find(needle, i + 1)
    return n


@contextmanager
def _guard(t: Target, what: str) -> Iterator[None]:
    try:
        with watchdog(CASE_LIMIT):
            yield
    except Hang:
        t.violate("hang", f"over {CASE_LIMIT} s: {what}")
    except Exception as exc:  # noqa: BLE001 - reported as a violation
        t.violate("exception", f"{exc!r} ({what}): {traceback.format_exc(limit=-3)}")


def run(report: Report, names: Sequence[str], count: int, seed: int) -> None:
    known = {name: (f, p) for name, f, p in endpoints()}
    for name in names:
        family, protocol = known[name]
        make = ADAPTERS.get(protocol, GenericAdapter)
        t = report.target(f"endpoint {name}", "endpoint")
        if make is GenericAdapter:
            report.uncovered.append(f"endpoint {name}: no fuzz adapter for {protocol!r}, generic checks only")
        rng = random.Random(f"{seed}/endpoint/{name}")
        with report.timed(t):
            cases = 0
            adapter: Adapter | None = None
            while t.units < count:
                if adapter is None or adapter.stale or cases % REBUILD == 0:
                    adapter = make(build(family, protocol), rng)
                cases += 1
                fed = [0]
                before = t.violations["exception"] + t.violations["hang"]
                with _guard(t, f"case {cases} of seed {seed}"):
                    fed[0] = adapter.case(t)
                    t.passed("exception")
                    t.passed("hang")
                if t.violations["exception"] + t.violations["hang"] > before:
                    adapter = None  # the case stopped half-way: start again from fresh twins
                t.units += max(fed[0], 1)
