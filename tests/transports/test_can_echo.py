"""Echo filtering for python-can programs on udp_multicast (a bus that returns a sender's own frames), and the
serve side's pacing: never two frames closer than its rate allows, nothing lost."""

from __future__ import annotations

import itertools

import can

from joints.sim.can_serve import CanEndpoint, ServedCan
from joints.sim.erob_canopen import ErobCanopenBus
from joints.transports.can import EchoFilter
from joints.transports.can_echo import EchoFreeBus

_ids = itertools.count()


def channel() -> str:
    return f"echo-test-{next(_ids)}"


def frame(can_id: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False)


def test_echo_free_bus_drops_its_own_frames_and_keeps_everyone_elses() -> None:
    ch = channel()
    inner = can.Bus(interface="virtual", channel=ch, receive_own_messages=True)  # echoes, like udp_multicast
    other = can.Bus(interface="virtual", channel=ch)
    bus = EchoFreeBus(inner)
    try:
        bus.send(frame(0x202, b"\x0f\x00"))
        bus.send(frame(0x602, b"\x40\x41\x60\x00\x00\x00\x00\x00"))
        other.send(frame(0x182, b"\x37\x02"))
        other.send(frame(0x202, b"\x0f\x00"))  # the same frame from someone else, after our echo came back
        got = []
        while (m := bus.recv(0.05)) is not None:
            got.append((m.arbitration_id, bytes(m.data)))
        assert got == [(0x182, b"\x37\x02"), (0x202, b"\x0f\x00")]
        assert bus.echoes_dropped == 2
    finally:
        bus.shutdown()
        other.shutdown()
    assert inner._is_shutdown  # the wrapped bus is shut down with the wrapper


def test_echo_filter_forgets_lost_echoes_and_unsent_frames() -> None:
    f = EchoFilter()
    a, b, c = frame(1, b"a"), frame(2, b"b"), frame(3, b"c")
    for m in (a, b, c):
        f.sent(m)
    f.unsent(c)  # its send failed: no echo will come
    assert f.is_echo(b)  # a's echo was lost: forgotten on the way
    assert not f.is_echo(a) and not f.is_echo(c)
    assert f.dropped == 1


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += max(seconds, 0.0)


def test_serve_side_paces_what_it_sends_and_loses_nothing() -> None:
    ch = channel()
    device = ErobCanopenBus()
    endpoint = CanEndpoint(ServedCan("virtual", ch), device, max_rate=1000.0)
    listener = can.Bus(interface="virtual", channel=ch)
    try:
        for i in range(50):
            endpoint.out.append(frame(0x180 + (i % 8), bytes((i,))))
        sent_at = []
        now = 0.0
        while endpoint.out:
            before = endpoint.frames_out
            due = endpoint.send_due(now)
            sent_at += [now] * (endpoint.frames_out - before)
            now = due if due is not None else now  # the serve loop sleeps until then
            now += 1e-5
        assert endpoint.frames_out == 50
        gaps = [b - a for a, b in itertools.pairwise(sent_at)]
        assert min(gaps) >= 1e-3 - 1e-9  # 1000 frames/s at most, no burst
        got = []
        while (m := listener.recv(0.05)) is not None:
            got.append(m.data[0])
        assert got == list(range(50))  # in order, none lost
    finally:
        endpoint.close()
        listener.shutdown()


def test_serve_side_forwards_what_the_twins_send_by_themselves() -> None:
    """Boot-ups and heartbeats go on the device bus's medium (on the world's clock): the endpoint taps them."""
    from joints.devices.erob.profiles import profile
    from joints.sim.erob import ErobFirmware
    from joints.sim.erob_canopen import CanopenFront

    ch = channel()
    clock = FakeClock()
    device = ErobCanopenBus()
    device.bind_clock(clock)
    front = CanopenFront(ErobFirmware(profile("eRob80H100"), 4), 4)
    device.add(front)
    front.firmware.write("producer_heartbeat_time", 10)
    endpoint = CanEndpoint(ServedCan("virtual", ch), device)
    listener = can.Bus(interface="virtual", channel=ch)
    try:
        for k in range(1, 36):  # 35 ms of simulated time
            clock.t = k * 1e-3
            device.tick(clock.t)
            endpoint.send_due(float(k))  # wall time far apart: pacing never holds a frame back here
        got = []
        while (m := listener.recv(0.05)) is not None:
            got.append((m.arbitration_id, bytes(m.data)))
        assert got[0] == (0x704, b"\x00")  # boot-up
        assert got[1:] == [(0x704, b"\x7f")] * 3  # PRE-OPERATIONAL heartbeats every 10 ms
    finally:
        endpoint.close()
        listener.shutdown()
