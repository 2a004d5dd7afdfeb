"""The protocol-neutral link on a fake frame bus: replies by rule, unsolicited frames to subscribers, one lock."""

from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any

import can
import pytest

from joints.clock import ManualClock
from joints.codecs import modbus as mb
from joints.errors import FrameError, ReplyTimeout
from joints.link import Link, ModbusLink, RetryPolicy, Rule, Trace
from joints.link.base import FrameFraming
from joints.transports.can import FrameTransport
from joints.transports.loopback import LoopbackTransport

REQ, REPLY, HEARTBEAT = 0x600, 0x580, 0x700


class FakeRule(Rule[can.Message]):
    """A toy request/reply protocol: request 0x600+node, reply 0x580+node echoing data[0]."""

    protocol = "fake"

    def encode(self, message: Any) -> can.Message:
        return message  # type: ignore[no-any-return]

    def expects_reply(self, request: Any) -> bool:
        return request.arbitration_id & 0x780 == REQ  # type: ignore[no-any-return]

    def is_reply(self, request: Any, message: can.Message) -> bool:
        return (message.arbitration_id == REPLY + (request.arbitration_id & 0x7F)
                and message.data[:1] == request.data[:1])

    def frame_bytes(self, message: Any) -> bytes:
        return bytes(message.data)


class FakeBus(FrameTransport):
    """A node that answers each request with frames chosen by the test (e.g. a heartbeat, then the reply)."""

    def __init__(self, answer: Any) -> None:
        self.answer = answer
        self.rx: deque[can.Message] = deque()
        self.wire: list[tuple[str, int, bytes]] = []  # what crossed the wire, in order
        self.yield_gil = False

    def send(self, frame: can.Message) -> None:
        self.wire.append(("tx", frame.arbitration_id, bytes(frame.data)))
        for out in self.answer(frame):
            self.rx.append(out)

    def recv(self, timeout: float) -> can.Message | None:
        if self.yield_gil:
            time.sleep(0)  # let another thread run here, as a real driver's blocking read would
        if not self.rx:
            return None
        frame = self.rx.popleft()
        self.wire.append(("rx", frame.arbitration_id, bytes(frame.data)))
        return frame

    def close(self) -> None:
        pass


def msg(can_id: int, *data: int) -> can.Message:
    return can.Message(arbitration_id=can_id, data=bytes(data), is_extended_id=False)


def make_link(bus: FakeBus, clock: ManualClock | None = None, trace: Trace | None = None) -> Link[can.Message]:
    clock = clock or ManualClock()
    return Link(FrameFraming(bus, lambda f: f, clock), FakeRule(), policy=RetryPolicy(timeout=0.05, retries=1),
                clock=clock, trace=trace, name="can-test")


def test_unsolicited_frame_between_request_and_reply_goes_to_the_subscriber() -> None:
    bus = FakeBus(lambda f: [msg(HEARTBEAT + 2, 0x05), msg(REPLY + 2, f.data[0], 0xAA)])
    trace = Trace()
    link = make_link(bus, trace=trace)
    heard: list[can.Message] = []
    link.subscribe(lambda m: m.arbitration_id & 0x780 == HEARTBEAT, heard.append)
    reply = link.request(msg(REQ + 2, 0x40))
    assert reply is not None and bytes(reply.data) == bytes([0x40, 0xAA])
    assert [bytes(m.data) for m in heard] == [b"\x05"]
    assert not link.unsolicited  # claimed, so not in the log of unclaimed frames
    rx = [r for r in trace if r.direction == "rx"]
    assert len(rx) == 2 and rx[0].meaning.startswith("unsolicited:") and not rx[1].meaning.startswith("unsolicited")
    assert rx[0].data == b"\x05" and rx[1].data == bytes([0x40, 0xAA])


def test_unsolicited_frame_during_an_idle_wait_is_delivered_by_poll() -> None:
    bus = FakeBus(lambda f: [])
    link = make_link(bus)
    heard: list[can.Message] = []
    link.subscribe(lambda m: m.arbitration_id == HEARTBEAT + 3, heard.append)
    bus.rx.extend([msg(HEARTBEAT + 3, 0x05), msg(0x183, 1, 2, 3)])
    assert link.poll() == 2
    assert [m.arbitration_id for m in heard] == [HEARTBEAT + 3]
    # the TPDO nobody subscribed to is kept, with its time, not dropped
    assert [(t, m.arbitration_id) for t, m in link.unsolicited] == [(0.0, 0x183)]


def test_nothing_is_lost_when_frames_for_nobody_and_somebody_mix() -> None:
    def answer(f: can.Message) -> list[can.Message]:
        return [msg(0x181, f.data[0]), msg(HEARTBEAT + 1, 5), msg(REPLY + 1, f.data[0]), msg(0x281, f.data[0])]

    bus = FakeBus(answer)
    link = make_link(bus)
    heard: list[int] = []
    link.subscribe(lambda m: m.arbitration_id == HEARTBEAT + 1, lambda m: heard.append(m.data[0]))
    for i in range(10):
        reply = link.request(msg(REQ + 1, i))
        assert reply is not None and reply.data[0] == i
    link.poll()
    assert heard == [5] * 10
    received = [x for x in bus.wire if x[0] == "rx"]
    assert len(received) == 40
    # every frame that was not a reply or a claimed heartbeat is in the log, in order
    assert [m.arbitration_id for _, m in link.unsolicited] == [0x181, 0x281] * 10


def test_wait_for_returns_the_awaited_frame_and_delivers_the_rest() -> None:
    bus = FakeBus(lambda f: [])
    link = make_link(bus)
    heard: list[int] = []
    link.subscribe(lambda m: m.arbitration_id == HEARTBEAT + 1, lambda m: heard.append(m.data[0]))
    bus.rx.extend([msg(HEARTBEAT + 1, 5), msg(0x1FB, 2)])
    got = link.wait_for(lambda m: m.arbitration_id == 0x1FB, timeout=1.0)
    assert bytes(got.data) == b"\x02" and heard == [5]
    with pytest.raises(ReplyTimeout):
        link.wait_for(lambda m: True, timeout=0.1)


def test_send_only_frames_wait_for_nothing() -> None:
    bus = FakeBus(lambda f: [])
    link = make_link(bus)
    link.send(msg(0x000, 0x01, 0x00))  # NMT start all
    link.send(msg(0x080))  # SYNC
    assert [x[:2] for x in bus.wire] == [("tx", 0x000), ("tx", 0x080)]
    assert link.transactions == 2


def test_a_failing_subscriber_never_breaks_the_bus() -> None:
    bus = FakeBus(lambda f: [msg(HEARTBEAT + 2, 5), msg(REPLY + 2, f.data[0])])
    link = make_link(bus)

    def boom(m: can.Message) -> None:
        raise RuntimeError("subscriber bug")

    link.subscribe(lambda m: True, boom)
    assert link.request(msg(REQ + 2, 7)) is not None
    assert link.callback_errors == 1


def test_cancelled_subscription_gets_nothing_more() -> None:
    bus = FakeBus(lambda f: [])
    link = make_link(bus)
    heard: list[can.Message] = []
    sub = link.subscribe(lambda m: True, heard.append)
    bus.rx.append(msg(HEARTBEAT + 1, 5))
    link.poll()
    sub.cancel()
    bus.rx.append(msg(HEARTBEAT + 1, 5))
    link.poll()
    assert len(heard) == 1 and len(link.unsolicited) == 1


def test_undecodable_frame_is_traced_and_skipped() -> None:
    def decode(f: can.Message) -> can.Message:
        if f.arbitration_id == 0x7FF:
            raise FrameError("garbage", data=bytes(f.data))
        return f

    bus = FakeBus(lambda f: [msg(0x7FF, 1), msg(REPLY + 2, f.data[0])])
    trace = Trace()
    clock = ManualClock()
    link = Link(FrameFraming(bus, decode, clock), FakeRule(), clock=clock, trace=trace)
    assert link.request(msg(REQ + 2, 3)) is not None
    assert any(r.meaning.startswith("error: garbage") for r in trace)


def test_two_threads_hammering_one_bus_never_interleave_frames() -> None:
    def answer(f: can.Message) -> list[can.Message]:
        return [msg(REPLY + (f.arbitration_id & 0x7F), *f.data)]

    bus = FakeBus(answer)
    bus.yield_gil = True
    link = make_link(bus)
    errors: list[BaseException] = []

    def worker(node: int) -> None:
        try:
            for i in range(400):
                reply = link.request(msg(REQ + node, i & 0xFF, node))
                assert reply is not None and reply.arbitration_id == REPLY + node and reply.data[0] == i & 0xFF
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=worker, args=(n,)) for n in (1, 2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert len(bus.wire) == 1600
    # strictly tx, rx, tx, rx ... and every rx answers the tx right before it
    for (d1, id1, data1), (d2, id2, data2) in zip(bus.wire[0::2], bus.wire[1::2]):
        assert (d1, d2) == ("tx", "rx")
        assert id2 == REPLY + (id1 & 0x7F) and data2 == data1


def test_modbus_late_reply_before_a_request_is_unsolicited_not_an_answer() -> None:
    # a reply that arrived after its request had given up: the next read must not take it
    from joints.devices.erob.registers import EROB_MODBUS
    from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront

    slave = ModbusFront.plain(EROB_MODBUS, 2, values={"actual_position": 1234})
    transport = LoopbackTransport(ModbusDeviceBus([slave]))
    link = ModbusLink(transport, clock=ManualClock(), name="rs485")
    stale = mb.encode(mb.ReadRegistersReply(2, 3, (0, 999)))
    transport.inject(stale)
    assert link.read_registers(2, 0x0066, 2) == (0, 1234)
    assert [m for _, m in link.unsolicited] == [mb.ReadRegistersReply(2, 3, (0, 999))]


class KeyedRule(FakeRule):
    """FakeRule whose frames are keyed by their identifier (``Rule.route_key``)."""

    def route_key(self, message: can.Message) -> object:
        return message.arbitration_id


def test_a_subscriber_is_offered_only_the_frames_of_its_keys() -> None:
    bus = FakeBus(lambda f: [])
    clock = ManualClock()
    link = Link(FrameFraming(bus, lambda f: f, clock), KeyedRule(), clock=clock, name="can-test")
    asked: list[int] = []
    keyed: list[int] = []
    everything: list[int] = []

    def asking(m: can.Message) -> bool:
        asked.append(m.arbitration_id)
        return True

    link.subscribe(asking, lambda m: keyed.append(m.data[0]), only=(0x181,))
    link.subscribe(lambda m: True, lambda m: everything.append(m.data[0]))
    bus.rx.extend([msg(0x181, 1), msg(0x182, 2), msg(0x181, 3)])
    link.poll()
    assert asked == [0x181, 0x181]  # the predicate never saw 0x182
    assert keyed == [1, 3] and everything == [1, 2, 3]
    late: list[int] = []  # a subscriber added later is offered its key's frames too (the key's list is rebuilt)
    sub = link.subscribe(lambda m: True, lambda m: late.append(m.data[0]), only=(0x182,))
    bus.rx.extend([msg(0x182, 4), msg(0x181, 5)])
    link.poll()
    assert late == [4] and keyed == [1, 3, 5] and everything == [1, 2, 3, 4, 5]
    sub.cancel()
    bus.rx.append(msg(0x182, 6))
    link.poll()
    assert late == [4] and everything[-1] == 6


def test_a_rule_without_keys_asks_every_subscriber() -> None:
    bus = FakeBus(lambda f: [])
    link = make_link(bus)  # FakeRule: no route key
    heard: list[int] = []
    link.subscribe(lambda m: True, lambda m: heard.append(m.arbitration_id), only=(0x181,))
    bus.rx.extend([msg(0x181, 1), msg(0x182, 2)])
    link.poll()
    assert heard == [0x181, 0x182]  # ``only`` sorts by key; a frame without one is offered to everyone
