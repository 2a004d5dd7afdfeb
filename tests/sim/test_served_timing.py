"""The served twins' bus time (joints.sim.served_timing): pure arithmetic, checked against the formulas."""

from __future__ import annotations

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
