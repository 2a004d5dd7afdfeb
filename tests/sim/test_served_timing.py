"""The served twins' bus time (joints.sim.served_timing): pure arithmetic, checked against the formulas."""

from __future__ import annotations

import math
import os
import select
import statistics
import sys
import threading
import time
import tty
from typing import Any

import can
import pytest

from joints.sim.served_timing import BusTiming, ServedLine, substeps_to
from joints.transports import can_timing

BAUD = 115200
CHAR = 10 / BAUD  # 8N1
T35 = 1.75e-3  # above 19200 baud


def test_rtu_transaction_request_silence_turnaround_reply_latency() -> None:
    timing = BusTiming.serial(baudrate=BAUD, adapter_latency=0.002, turnarounds={2: 0.0007})
    line = ServedLine(timing)
    acts = line.request(10.0, timing.bytes_time(8), 2)
    assert acts == pytest.approx(10.0 + 8 * CHAR + T35 + 0.0007)
    back = line.reply(acts, timing.bytes_time(55))
    assert back == pytest.approx(acts + 55 * CHAR + 0.002)
    assert back - 10.0 == pytest.approx(timing.transaction(8 * CHAR, 55 * CHAR, 2))
    # the line is silent for t3.5 after the reply: a request written at once starts after it
    nxt = line.request(back - 0.002, timing.bytes_time(8), 2)
    assert nxt == pytest.approx(acts + 55 * CHAR + T35 + 8 * CHAR + T35 + 0.0007)


def test_mks_has_no_silence_and_parity_counts() -> None:
    timing = BusTiming.serial(baudrate=38400, parity="E", stopbits=1, rtu=False, turnarounds={1: 0.001})
    assert timing.silence == 0.0 and timing.char_time == pytest.approx(11 / 38400)
    line = ServedLine(timing)
    assert line.request(0.0, timing.bytes_time(4), 1) == pytest.approx(4 * 11 / 38400 + 0.001)


def test_ideal_takes_no_time_and_scale_follows_the_realtime_factor() -> None:
    ideal = ServedLine(BusTiming.serial(baudrate=BAUD, ideal=True, adapter_latency=0.01))
    assert ideal.request(3.0, 1.0, 2) == 3.0 and ideal.reply(3.0, 1.0) == 3.0
    fast = ServedLine(BusTiming.serial(baudrate=BAUD, turnarounds={2: 0.001}), scale=0.5)
    assert fast.request(0.0, 8 * CHAR, 2) == pytest.approx(0.5 * (8 * CHAR + T35 + 0.001))


def test_can_frames_take_their_stuffed_bits() -> None:
    timing = BusTiming.can(bitrate=1_000_000, adapter_latency=0.0003, turnarounds={5: 0.0002})
    req = can.Message(arbitration_id=0x645, data=bytes(8), is_extended_id=False)
    line = ServedLine(timing)
    acts = line.request(1.0, timing.frame_time(req), 5)
    assert acts == pytest.approx(1.0 + 135e-6 + 0.0002)  # 8 data bytes, worst-case stuffing: 135 bits
    assert line.reply(acts, timing.frame_time(req)) == pytest.approx(acts + 135e-6 + 0.0003)
    assert can_timing.frame_bits(req) == 135


def test_turnaround_of_a_broadcast_is_the_slowest_drive_and_defaults() -> None:
    timing = BusTiming.serial(baudrate=BAUD, turnarounds={1: 0.001, 2: 0.003})
    assert timing.turnaround(None) == 0.003 and timing.turnaround(9) == 0.003 and timing.turnaround(1) == 0.001
    assert BusTiming.serial(baudrate=BAUD).turnaround(1) == 0.0  # no drive known: nothing to wait for


def test_a_served_request_acts_on_the_substep_ending_at_or_after_its_instant() -> None:
    """The in-process line's rule (never the nearest substep: a command would act up to half a substep early)."""
    dt = 0.001
    assert substeps_to(0.0031, 0.003, dt) == 1
    assert substeps_to(0.0039, 0.003, dt) == 1
    assert substeps_to(0.0041, 0.003, dt) == 2
    assert substeps_to(0.003, 0.003, dt) == 0  # reached: acts now
    assert substeps_to(0.0029999999999, 0.003, dt) == 0  # rounding of the clocks never costs a substep
    assert substeps_to(0.001, 0.003, dt) == 0  # overdue: acts now


class _Recorder:
    """A served device bus that notes the world's time whenever a request acts (and answers as the real one)."""

    def __init__(self, bus: Any, world: Any) -> None:
        self.bus, self.world = bus, world
        self.acted: list[float] = []

    def receive(self, data: bytes) -> bytes:
        self.acted.append(self.world.time)
        return bytes(self.bus.receive(data))

    def silence(self) -> bytes:
        return bytes(self.bus.silence())


class _World:
    """A world whose physics costs nothing (it follows the wall clock substep by substep)."""

    timestep = 0.001

    def __init__(self) -> None:
        self.steps = 0
        self.buses: dict[str, Any] = {}

    @property
    def time(self) -> float:
        return self.steps * self.timestep

    def step(self, n: int = 1) -> None:
        self.steps += n


@pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals need POSIX")
def test_served_request_acts_at_arrival_plus_turnaround_and_its_reply_waits_for_the_wire() -> None:
    """Over a real pty: the request acts (the state is sampled) on the world's clock when its 8 bytes and t3.5
    at 9600 baud and the drive's 20 ms turnaround have passed; the reply reaches the host after its own wire
    time and the adapter's 10 ms on top. Wall-clock bounds with room for a loaded machine (medians)."""
    from joints.codecs import modbus as mb
    from joints.devices.erob.params import EROB_PARAMS
    from joints.devices.erob.registers import EROB_MODBUS
    from joints.sim.firmware import Firmware
    from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
    from joints.sim.serve import serve

    world = _World()
    rec = _Recorder(ModbusDeviceBus([ModbusFront(Firmware(EROB_PARAMS), EROB_MODBUS, 2)]), world)
    world.buses["rs485"] = rec
    timing = BusTiming.serial(baudrate=9600, adapter_latency=0.010, turnarounds={2: 0.020})
    char = 10 / 9600
    t35 = 3.5 * char
    arrived: list[float] = []
    ports: dict[str, Any] = {}
    ready, stop = threading.Event(), threading.Event()

    def on_ready(lines: dict[str, Any]) -> None:
        ports.update(lines)
        ready.set()

    def log(bus: str, direction: str, data: bytes, ident: int | None) -> None:
        if direction == "rx":
            arrived.append(world.time)

    thread = threading.Thread(target=serve, args=(world, ["rs485"]), daemon=True,
                              kwargs={"stop": stop, "on_ready": on_ready, "install_signals": False, "log": log,
                                      "timing": {"rs485": timing}})
    thread.start()
    assert ready.wait(30)
    fd = os.open(ports["rs485"]["port"], os.O_RDWR | os.O_NOCTTY)
    request = mb.encode(mb.ReadHoldingRegisters(2, 0x0066, 2))  # 8 bytes; the reply: 9 bytes
    trips: list[float] = []
    try:
        tty.setraw(fd)
        for _ in range(15):
            got = b""
            t = time.perf_counter()
            os.write(fd, request)
            while len(got) < 9:
                r, _, _ = select.select([fd], [], [], 1.0)
                assert r, "no reply"
                got += os.read(fd, 64)
            done = time.perf_counter()
            trips.append(done - t)
            # a Modbus RTU master keeps the t3.5 silence after a reply before its next request (the rule, not a
            # guess at a race): the next request then finds the line free, as every request of this test must
            time.sleep(max(0.0, done + t35 - time.perf_counter()))
    finally:
        os.close(fd)
        stop.set()
        thread.join(10)
    assert len(rec.acted) == len(arrived) == 15
    delay = 8 * char + t35 + 0.020
    # never before its instant (the world was at or behind the wall clock when the request was read, and a request
    # acts on the substep that ends at or after its instant, as on the in-process line), and soon after it
    assert min(a - b for a, b in zip(rec.acted, arrived)) >= delay - 1e-9, (rec.acted, arrived, delay)
    waited = statistics.median(a - b for a, b in zip(rec.acted, arrived))
    assert delay <= waited <= delay + 0.003, (waited, delay)
    expected = delay + 9 * char + 0.010
    assert statistics.median(trips) == pytest.approx(expected, abs=0.004), (trips, expected)


def test_a_served_frame_a_drive_sends_by_itself_waits_for_the_host_adapter_like_an_answer() -> None:
    """Over a served udp_multicast channel: a twin that sends a frame by itself 20 ms after any frame it gets (as a
    CANopen drive sends its boot-up, a heartbeat or an event TPDO: on its timed medium, not as an answer) - the
    frame reaches the client after the request's wire time, the 20 ms, its own wire time on the medium and the
    bus's 30 ms adapter latency (before: without the adapter latency, ~20 ms). Medians, wall-clock bounds with room."""
    from joints.sim.can_serve import client_bus, plan
    from joints.sim.serve import serve
    from joints.transports.can_sim import CanMedium

    class TickingWorld(_World):
        """Steps the twin's medium with its substeps (as the world ticks a timed device bus)."""

        def now(self) -> float:
            return self.time

        def sleep(self, seconds: float) -> None:  # the medium's own waits (none here: the serving loop steps)
            self.step(math.ceil(seconds / self.timestep))

        def step(self, n: int = 1) -> None:
            for _ in range(n):
                self.steps += 1
                twin.medium.tick(self.time)

    class Twin:
        def __init__(self) -> None:
            self.medium = CanMedium(f"selfsent-{os.getpid()}", bitrate=1_000_000)
            self.medium.bind_clock(world)
            self.node = self.medium.attach_peer(self, name="twins")

        def on_frame(self, frame: can.Message) -> list[can.Message]:
            heartbeat = can.Message(arbitration_id=0x705, data=b"\x05", is_extended_id=False)
            self.medium.send_at(self.node, heartbeat, self.medium.time() + 0.020)
            return []

    world = TickingWorld()
    twin = Twin()
    world.buses["can"] = twin
    spec = plan("can", None, None, None)
    timing = BusTiming.can(bitrate=1_000_000, adapter_latency=0.030)
    ports: dict[str, Any] = {}
    ready, stop = threading.Event(), threading.Event()

    def on_ready(lines: dict[str, Any]) -> None:
        ports.update(lines)
        ready.set()

    thread = threading.Thread(target=serve, args=(world, []), daemon=True,
                              kwargs={"can_buses": {"can": spec}, "stop": stop, "on_ready": on_ready,
                                      "install_signals": False, "timing": {"can": timing}})
    thread.start()
    assert ready.wait(30)
    bus = client_bus(ports["can"])
    trips: list[float] = []
    try:
        request = can.Message(arbitration_id=0x000, data=b"\x01\x00", is_extended_id=False)
        for _ in range(7):
            t = time.monotonic()
            bus.send(request)
            while True:
                got = bus.recv(1.0)
                assert got is not None, "no frame from the twin"
                if got.arbitration_id == 0x705:
                    break
            trips.append(time.monotonic() - t)
    finally:
        bus.shutdown()
        stop.set()
        thread.join(10)
    wire = timing.frame_time(request) + timing.frame_time(can.Message(arbitration_id=0x705, data=b"\x05",
                                                                       is_extended_id=False))
    expected = wire + 0.020 + 0.030
    assert expected - 0.0015 <= statistics.median(trips) <= expected + 0.004, (trips, expected)
