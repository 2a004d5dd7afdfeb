"""ModbusLink over the in-process loopback: matching, errors, retries, broadcast, echo, trace."""

from __future__ import annotations

import csv
import dataclasses
import json
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from joints.clock import ManualClock
from joints.codecs import modbus as mb
from joints.codecs.crc import append_crc, crc_ok
from joints.devices.erob.params import EROB_PARAMS
from joints.devices.erob.registers import EROB_MODBUS
from joints.errors import (
    ChecksumError,
    DeviceRejected,
    EncodeError,
    JointsError,
    OutcomeUnknown,
    ReplyTimeout,
    TransportError,
    UnexpectedReply,
)
from joints.link import ModbusLink, RetryPolicy, Trace
from joints.sim.firmware import Firmware
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
from joints.transports.loopback import LoopbackTransport

SLAVE = 2


class Counting:
    """A peer callable wrapping the emulated bus: counts calls, can rewrite the answer."""

    def __init__(self, bus: ModbusDeviceBus, rewrite: Callable[[bytes], bytes] | None = None) -> None:
        self.bus = bus
        self.rewrite = rewrite
        self.requests: list[bytes] = []

    def __call__(self, data: bytes) -> bytes:
        self.requests.append(data)
        answer = self.bus.receive(data)
        return self.rewrite(answer) if (self.rewrite and answer) else answer

    @property
    def calls(self) -> int:
        return len(self.requests)


def flip_crc_bit(frame: bytes) -> bytes:
    out = bytearray(frame)
    out[-1] ^= 0x01
    return bytes(out)


def from_slave_3(frame: bytes) -> bytes:
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.feed(frame)
    reply = codec.next_message()
    assert reply is not None
    return mb.encode(dataclasses.replace(reply, slave=3))


@pytest.fixture
def slave() -> Firmware:
    return Firmware(EROB_PARAMS)


@pytest.fixture
def bus(slave: Firmware) -> ModbusDeviceBus:
    return ModbusDeviceBus([ModbusFront(slave, EROB_MODBUS, SLAVE)])


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock(100.0)


def make_link(peer, clock: ManualClock, *, echo: bool = False, trace=None, retries: int = 2) -> ModbusLink:
    transport = LoopbackTransport(peer, echo=echo)
    return ModbusLink(
        transport,
        policy=RetryPolicy(timeout=0.05, retries=retries),
        echo=echo,
        clock=clock,
        trace=trace,
        name="rs485-test",
    )


# --------------------------------------------------------------------------- round trips


def test_read_write_round_trip(bus: ModbusDeviceBus, slave: Firmware, clock: ManualClock) -> None:
    link = make_link(bus, clock)
    link.write_register(SLAVE, 0x0040, 3)  # operation mode = position
    assert slave.get("operation_mode") == 3
    assert link.read_registers(SLAVE, 0x0040, 1) == (3,)

    # int32 Hi word first: target absolute position -500000
    raw = -500000 & 0xFFFFFFFF
    link.write_registers(SLAVE, 0x0043, [raw >> 16, raw & 0xFFFF])
    assert slave.get("target_absolute_position") == -500000
    assert link.read_registers(SLAVE, 0x0043, 2) == (raw >> 16, raw & 0xFFFF)
    assert link.read_registers(SLAVE, 0x0043, 2, input_registers=True) == (raw >> 16, raw & 0xFFFF)

    reply = link.request(mb.ReadHoldingRegisters(SLAVE, 0x0040, 3), idempotent=True)
    assert reply == mb.ReadRegistersReply(SLAVE, 3, (3, 0, 0))
    assert link.transactions == 6 and link.retries_used == 0
    assert slave.write_log == [("operation_mode", 3), ("target_absolute_position", -500000)]


def test_encode_error_before_anything_is_sent(bus: ModbusDeviceBus, clock: ManualClock) -> None:
    peer = Counting(bus)
    link = make_link(peer, clock)
    with pytest.raises(EncodeError):
        link.write_register(SLAVE, 0x0040, 0x10000)
    with pytest.raises(EncodeError):
        link.read_registers(SLAVE, 0x0060, 126)
    assert peer.calls == 0 and link.transactions == 0


# ------------------------------------------------------------------------------- errors


def test_reply_from_another_slave_is_unexpected(bus: ModbusDeviceBus, clock: ManualClock) -> None:
    peer = Counting(bus, from_slave_3)
    link = make_link(peer, clock)
    with pytest.raises(UnexpectedReply) as info:
        link.read_registers(SLAVE, 0x0066, 2)
    assert "slave 3" in str(info.value)
    assert peer.calls == 3  # a read is retried on any mismatch (retries=2), and never accepts it
    assert link.retries_used == 2
    with pytest.raises(UnexpectedReply):
        link.write_register(SLAVE, 0x0040, 3, idempotent=False)
    assert peer.calls == 4  # a command is never sent twice


def test_reply_to_another_register_is_unexpected(bus: ModbusDeviceBus, clock: ManualClock) -> None:
    def other_address(frame: bytes) -> bytes:
        return mb.encode(mb.WriteSingleRegisterReply(SLAVE, 0x0041, 3))

    link = make_link(Counting(bus, other_address), clock)
    with pytest.raises(UnexpectedReply):
        link.write_register(SLAVE, 0x0040, 3)


def test_exception_reply_is_device_rejected(bus: ModbusDeviceBus, clock: ManualClock) -> None:
    peer = Counting(bus)
    link = make_link(peer, clock)
    with pytest.raises(DeviceRejected) as info:
        link.read_registers(SLAVE, 0x0010, 1)  # no register there
    assert info.value.code == 0x02 and info.value.function == 0x03
    assert "0x0010" in str(info.value) and "illegal data address" in str(info.value)
    with pytest.raises(DeviceRejected) as info:
        link.write_register(SLAVE, 0x0040, 7)  # operation mode 7 does not exist
    assert info.value.code == 0x03 and info.value.function == 0x06
    assert peer.calls == 2  # a refusal is an answer: no retry


# ------------------------------------------------------------------ failure replies (per slave)


class WithFailureReplies:
    """The eRob register file answering a refused FC06 write with register data 0xFFFF, as an MKS V1.0.6+
    does ("If write fails"): a device built for these tests - no MKS register takes 0xFFFF or can be read
    back, and the eRob answers exceptions - so that a register that takes 0xFFFF (0x0030, an unbounded
    gain) and one that does not (0x0002, at most 4000 ms) can both be read back by FC03."""

    def __init__(self, bus: ModbusDeviceBus) -> None:
        self.bus = bus
        self.requests: list[bytes] = []

    def __call__(self, data: bytes) -> bytes:
        self.requests.append(data)
        answer = self.bus.receive(data)
        if answer and answer[1] == 0x86:  # exception to an FC06 write: the failure reply instead
            return append_crc(data[:4] + b"\xff\xff")
        return answer


def test_a_declared_slaves_failure_reply_is_a_refusal_and_0xffff_is_read_back(
        bus: ModbusDeviceBus, slave: Firmware, clock: ManualClock) -> None:
    peer = WithFailureReplies(bus)
    link = make_link(peer, clock)
    link.failure_replies(SLAVE, lambda address: link.read_registers(SLAVE, address, 1) == (0xFFFF,))
    with pytest.raises(DeviceRejected, match="failure reply") as info:
        link.write_register(SLAVE, 0x0002, 5000)  # not an echo: refused at once
    assert info.value.code == 0 and len(peer.requests) == 1
    link.write_register(SLAVE, 0x0030, 0xFFFF)  # taken: its answer is also the failure reply; read back
    assert slave.get("position_loop_gain") == 0xFFFF and len(peer.requests) == 3
    with pytest.raises(DeviceRejected, match="does not hold 0xFFFF") as info:
        link.write_register(SLAVE, 0x0002, 0xFFFF)  # refused: the echo looks the same, the read back tells
    assert info.value.code == 0 and slave.get("modbus_communication_timeout_duration") == 0
    with pytest.raises(DeviceRejected, match="does not hold"):  # a raw FC06 PDU is judged alike
        link.write_pdu(SLAVE, mb.WRITE_SINGLE_REGISTER, bytes.fromhex("0002FFFF"))
    link.failure_replies(SLAVE, lambda address: None)  # a device that cannot read the register back
    with pytest.raises(OutcomeUnknown, match="outcome is unknown"):
        link.write_register(SLAVE, 0x0030, 0xFFFF)


def test_undeclared_slaves_are_judged_by_modbus_alone(bus: ModbusDeviceBus, slave: Firmware,
                                                      clock: ManualClock) -> None:
    """The eRob and ZLAC declare no failure replies: their writes of 0xFFFF are answered by the echo, with no read
    back; the same link declares another slave (an MKS V1.0.6+ at 1); a reply with data 0xFFFF to another value
    from an undeclared slave does not answer the write."""
    peer = Counting(bus)
    link = make_link(peer, clock)
    link.failure_replies(1, lambda address: False)
    link.write_register(SLAVE, 0x0030, 0xFFFF)
    assert slave.get("position_loop_gain") == 0xFFFF and peer.calls == 1
    with pytest.raises(DeviceRejected) as info:
        link.write_register(SLAVE, 0x0002, 0xFFFF)
    assert info.value.code == 0x03 and peer.calls == 2  # its own exception, as before
    link = make_link(WithFailureReplies(bus), clock)
    with pytest.raises(UnexpectedReply):
        link.write_register(SLAVE, 0x0002, 5000, idempotent=False)


def test_no_peer_times_out_without_waiting(clock: ManualClock) -> None:
    transport = LoopbackTransport(None)
    link = ModbusLink(transport, policy=RetryPolicy(timeout=30.0, retries=2), clock=clock)
    started = time.monotonic()
    with pytest.raises(ReplyTimeout) as info:
        link.read_registers(SLAVE, 0x0066, 2)
    assert time.monotonic() - started < 5.0  # a 30 s timeout x 3 attempts did not block
    assert clock.now() == 100.0  # nobody slept on the injected clock either
    assert isinstance(info.value, TimeoutError)
    assert isinstance(info.value, TransportError) and isinstance(info.value, JointsError)
    assert "slave 2" in str(info.value) and "3 attempts" in str(info.value)
    assert link.retries_used == 2 and link.transactions == 3
    assert transport.tx_bytes == 3 * 8


def test_no_reply_to_non_idempotent_write_is_not_retried(clock: ManualClock) -> None:
    transport = LoopbackTransport(None)
    link = ModbusLink(transport, policy=RetryPolicy(timeout=0.1, retries=2), clock=clock)
    with pytest.raises(OutcomeUnknown) as info:
        link.write_register(SLAVE, 0x00F1, 1, idempotent=False)  # start operating
    assert link.transactions == 1 and link.retries_used == 0
    assert isinstance(info.value, ReplyTimeout) and "outcome is unknown" in str(info.value)


def test_timed_out_read_is_a_plain_timeout_and_a_timed_out_write_an_unknown_outcome(clock: ManualClock) -> None:
    link = ModbusLink(LoopbackTransport(None), policy=RetryPolicy(timeout=0.1, retries=1), clock=clock)
    with pytest.raises(ReplyTimeout) as read:
        link.read_registers(SLAVE, 0x0066, 2)
    assert not isinstance(read.value, OutcomeUnknown)
    with pytest.raises(OutcomeUnknown):
        link.write_register(SLAVE, 0x0047, 100)  # idempotent: retried once, then unknown
    assert link.transactions == 4


def test_corrupt_reply_is_checksum_error_after_retries(
    bus: ModbusDeviceBus, slave: Firmware, clock: ManualClock
) -> None:
    peer = Counting(bus, flip_crc_bit)
    link = make_link(peer, clock, retries=2)
    with pytest.raises(ChecksumError) as info:
        link.read_registers(SLAVE, 0x0066, 2)
    assert not crc_ok(info.value.data)
    assert peer.calls == 3
    assert link.retries_used == 2
    # retries accumulate over transactions
    with pytest.raises(ChecksumError):
        link.write_register(SLAVE, 0x0040, 3)  # idempotent by default
    assert peer.calls == 6 and link.retries_used == 4


def test_retry_recovers_from_one_corrupt_reply(bus: ModbusDeviceBus, clock: ManualClock) -> None:
    state = {"n": 0}

    def first_corrupt(frame: bytes) -> bytes:
        state["n"] += 1
        return flip_crc_bit(frame) if state["n"] == 1 else frame

    peer = Counting(bus, first_corrupt)
    link = make_link(peer, clock)
    assert link.read_registers(SLAVE, 0x0040, 1) == (0,)
    assert peer.calls == 2 and link.retries_used == 1


def test_non_idempotent_write_sent_once_even_if_reply_corrupt(
    bus: ModbusDeviceBus, slave: Firmware, clock: ManualClock
) -> None:
    peer = Counting(bus, flip_crc_bit)
    link = make_link(peer, clock, retries=5)
    with pytest.raises(ChecksumError):
        link.write_register(SLAVE, 0x00F1, 1, idempotent=False)  # start operating
    assert peer.calls == 1
    assert link.retries_used == 0
    assert slave.write_log == [("start_operating", 1)]  # the device did act, exactly once
    with pytest.raises(ChecksumError):
        link.write_registers(SLAVE, 0x0043, [0, 10], idempotent=False)
    assert peer.calls == 2
    assert slave.write_log[-1] == ("target_absolute_position", 10)


# ------------------------------------------------------------------------------ broadcast


def test_broadcast_write_returns_none_and_slave_executes(
    bus: ModbusDeviceBus, slave: Firmware, clock: ManualClock
) -> None:
    peer = Counting(bus)
    link = make_link(peer, clock)
    assert link.request(mb.WriteSingleRegister(0, 0x0040, 2)) is None
    assert slave.get("operation_mode") == 2
    link.write_registers(0, 0x0047, [0, 10000])  # profile speed
    assert slave.get("profile_speed") == 10000
    assert peer.calls == 2
    assert slave.write_log == [("operation_mode", 2), ("profile_speed", 10000)]


def test_broadcast_read_is_refused_before_sending(bus: ModbusDeviceBus, clock: ManualClock) -> None:
    """Modbus broadcasts only writes; a broadcast read could never be answered."""
    peer = Counting(bus)
    link = make_link(peer, clock)
    with pytest.raises(EncodeError):
        link.read_registers(0, 0x0060, 1)
    with pytest.raises(EncodeError):
        link.read_registers(0, 0x0060, 1, input_registers=True)
    assert peer.calls == 0 and link.transactions == 0


def test_broadcast_reaches_every_slave(clock: ManualClock) -> None:
    slaves = [ModbusFront.plain(EROB_MODBUS, a) for a in (1, 2, 5)]
    link = make_link(ModbusDeviceBus(slaves), clock)
    link.write_register(0, 0x0041, 1)
    assert [s.firmware.get("motion_mode") for s in slaves] == [1, 1, 1]
    assert link.read_registers(5, 0x0041, 1) == (1,)


# ----------------------------------------------------------------------------------- echo


def test_echo_transport(bus: ModbusDeviceBus, slave: Firmware, clock: ManualClock) -> None:
    link = make_link(bus, clock, echo=True)
    assert link.transport.echo is True  # type: ignore[attr-defined]
    link.write_register(SLAVE, 0x0040, 3)  # FC06: the echo and the reply are the same bytes
    assert link.read_registers(SLAVE, 0x0040, 1) == (3,)
    link.write_registers(SLAVE, 0x0049, [0, 10000])
    assert link.read_registers(SLAVE, 0x0049, 2) == (0, 10000)
    assert slave.get("profile_acceleration") == 10000
    assert link.retries_used == 0


def test_echo_transport_exception_reply(bus: ModbusDeviceBus, clock: ManualClock) -> None:
    link = make_link(bus, clock, echo=True)
    with pytest.raises(DeviceRejected) as info:
        link.write_register(SLAVE, 0x0060, 1)  # error code is read-only
    assert info.value.code == 0x02


def test_echo_only_no_device_times_out(clock: ManualClock) -> None:
    link = make_link(None, clock, echo=True, retries=0)
    with pytest.raises(ReplyTimeout):
        link.write_register(SLAVE, 0x0040, 3)  # the echo alone is never taken for the reply


# ---------------------------------------------------------------------------------- trace


def test_trace_records_and_exports(bus: ModbusDeviceBus, clock: ManualClock, tmp_path: Path) -> None:
    trace = Trace()
    link = make_link(bus, clock, trace=trace)
    link.write_register(SLAVE, 0x0040, 3)
    clock.advance(0.5)
    assert link.read_registers(SLAVE, 0x0040, 1) == (3,)

    records = list(trace)
    assert [r.direction for r in records] == ["tx", "rx", "tx", "rx"]
    assert [r.time for r in records] == [100.0, 100.0, 100.5, 100.5]
    assert all(r.bus == "rs485-test" for r in records)
    assert records[0].data == mb.encode(mb.WriteSingleRegister(SLAVE, 0x40, 3))
    assert records[1].data == mb.encode(mb.WriteSingleRegisterReply(SLAVE, 0x40, 3))
    assert records[2].data == mb.encode(mb.ReadHoldingRegisters(SLAVE, 0x40, 1))
    assert records[3].data == mb.encode(mb.ReadRegistersReply(SLAVE, 3, (3,)))
    assert "WriteSingleRegister(" in records[0].meaning and "address=64" in records[0].meaning
    assert "ReadHoldingRegisters(" in records[2].meaning and "count=1" in records[2].meaning
    assert "values=(3,)" in records[3].meaning
    assert "<-" in str(records[3]) and "->" in str(records[2])

    csv_path = trace.export(tmp_path / "trace.csv")
    with csv_path.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["direction"] for r in rows] == ["tx", "rx", "tx", "rx"]
    assert rows[2]["data"] == mb.encode(mb.ReadHoldingRegisters(SLAVE, 0x40, 1)).hex(" ").upper()
    assert float(rows[3]["time"]) == 100.5
    assert rows[3]["meaning"] == records[3].meaning

    jsonl_path = trace.export(tmp_path / "trace.jsonl")
    lines = [json.loads(line) for line in jsonl_path.read_text().splitlines()]
    assert len(lines) == 4
    assert set(lines[0]) == {"time", "direction", "bus", "ident", "node", "data", "meaning"}
    assert lines[0]["node"] == SLAVE and lines[0]["ident"] is None
    assert lines[1]["data"] == records[1].data.hex(" ").upper()
    assert bytes.fromhex(lines[1]["data"]) == records[1].data


def test_trace_records_errors(bus: ModbusDeviceBus, clock: ManualClock) -> None:
    trace = Trace()
    link = make_link(Counting(bus, flip_crc_bit), clock, trace=trace, retries=1)
    with pytest.raises(ChecksumError):
        link.read_registers(SLAVE, 0x0040, 1)
    tx = [r for r in trace if r.direction == "tx"]
    rx = [r for r in trace if r.direction == "rx"]
    assert len(tx) == 2
    assert rx and all(r.meaning.startswith("error:") for r in rx)
    assert any("CRC" in r.meaning for r in rx)


def test_a_failing_trace_never_breaks_the_bus(bus: ModbusDeviceBus, clock: ManualClock) -> None:
    def broken(record: object) -> None:
        raise RuntimeError("monitor crashed")

    link = make_link(bus, clock, trace=broken)
    link.write_register(SLAVE, 0x0040, 3)
    assert link.read_registers(SLAVE, 0x0040, 1) == (3,)


class DelayedLine(LoopbackTransport):
    """A line on the injected clock: each answer arrives ``delay`` s after its request (reads wait for it)."""

    def __init__(self, peer: ModbusDeviceBus, clock: ManualClock, delay: float) -> None:
        super().__init__(None)
        self.bus = peer
        self.clock = clock
        self.delay = delay
        self.pending: list[tuple[float, bytes]] = []

    def write(self, data: bytes) -> None:
        answer = self.bus.receive(data)
        if answer:
            self.pending.append((self.clock.now() + self.delay, answer))

    def read(self, timeout: float) -> bytes:
        due = [p for p in self.pending if p[0] <= self.clock.now() + timeout]
        if not due:
            self.clock.advance(max(timeout, 0.0))
            return b""
        first = min(due)
        self.pending.remove(first)
        self.clock.set(max(self.clock.now(), first[0]))
        return first[1]


def test_a_late_reply_never_answers_the_next_request(slave: Firmware, bus: ModbusDeviceBus,
                                                      clock: ManualClock) -> None:
    line = DelayedLine(bus, clock, delay=0.15)
    link = ModbusLink(line, policy=RetryPolicy(timeout=0.1, retries=0), clock=clock)
    slave.set("profile_speed", 111)
    with pytest.raises(ReplyTimeout):
        link.read_registers(SLAVE, 0x0047, 2)  # its answer (111) comes 50 ms too late
    slave.set("profile_speed", 222)
    line.delay = 0.01
    assert link.read_registers(SLAVE, 0x0047, 2) == (0, 222)  # the fresh value, never the late 111
    assert link.late_discarded == 1
