"""The served twins' bus time (joints.sim.served_timing): pure arithmetic, checked against the formulas."""

from __future__ import annotations

import can
import pytest

from joints.sim.served_timing import FALLBACK_TURNAROUND, BusTiming, ServedLine, adapter_latency, turnaround
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
    assert BusTiming.serial(baudrate=BAUD).turnaround(1) == FALLBACK_TURNAROUND

    class Profile:
        turnaround = 0.0042

    assert turnaround(Profile()) == 0.0042 and turnaround(object()) == FALLBACK_TURNAROUND
    assert adapter_latency(None) == 0.0 and adapter_latency(0.003) == 0.003
