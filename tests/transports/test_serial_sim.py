"""The timed half-duplex RS485 line of the sim: wire time at the baud rate, collisions corrupt both frames, and
the MKS driver survives them (reads retried, the move never sent twice, a lost completion found by a status read)."""

from __future__ import annotations

import gc
from itertools import pairwise
from pathlib import Path
from typing import Any

import pytest

from joints.clock import ManualClock
from joints.codecs import mks
from joints.transports.serial_sim import Deferred, TimedSerialLine, Transmission


class Echo:
    """A device that answers every frame with a fixed reply, and can send a frame by itself at a set time."""

    def __init__(self, reply: bytes, own: list[tuple[float, bytes]] | None = None) -> None:
        self.reply = reply
        self.own = own or []
        self.got: list[bytes] = []

    def receive(self, data: bytes) -> bytes:
        self.got.append(data)
        return self.reply if data[:1] == b"\xfa" else b""  # garbage gets no answer

    def silence(self) -> bytes:
        return b""

    def take_frames(self, now: float | None = None) -> list[tuple[float, bytes]]:
        due = [f for f in self.own if now is None or f[0] <= now]
        self.own = [f for f in self.own if f not in due]
        return due


def test_frames_take_their_wire_time_and_the_reply_follows_after_the_turnaround() -> None:
    clock = ManualClock()
    request, reply = mks.encode(mks.ReadSpeed(1)), mks.encode(mks.SpeedReply(1, 7))
    line = TimedSerialLine(Echo(reply), baudrate=38400, clock=clock, turnaround=0.0005)
    line.write(request)
    assert line.read(0.0) == b""  # nothing has arrived yet
    got = line.read(0.1)
    assert got == reply
    expected = (len(request) + len(reply)) * 10 / 38400 + 0.0005
    assert clock.now() == pytest.approx(expected, abs=1e-9)
    assert [tx.side for tx in line.log] == ["host", "device"] and line.collisions == 0


def test_overlapping_frames_are_corrupted_on_both_sides() -> None:
    clock = ManualClock()
    completion = mks.encode(mks.RunReply(1, 0xFD, mks.RunStatus.COMPLETE))
    device = Echo(mks.encode(mks.SpeedReply(1, 7)), own=[(0.0005, completion)])
    line = TimedSerialLine(device, baudrate=38400, clock=clock)
    clock.advance(0.0005)
    request = mks.encode(mks.ReadSpeed(1))
    line.write(request)  # the drive started its completion frame at the same moment
    got = line.read(0.05)
    assert line.collisions == 1
    assert got == bytes(b ^ 0xFF for b in completion)  # garbage for the host
    assert device.got == [bytes(b ^ 0xFF for b in request)]  # garbage for the drive: no reply
    assert all(tx.corrupted for tx in line.log)
    assert "COLLISION" in line.trace()


def test_frames_from_before_a_clock_reset_never_collide_with_later_ones() -> None:
    """A reset (the sim's rig.reset) takes the clock back: the next episode's frames land on the times of the last
    episode's, which are long gone from the line (before the fix, reads of the MKS env's second episode that met a
    frame of the first at the same instant were garbled and its reset timed out)."""
    clock = ManualClock()
    request, reply = mks.encode(mks.ReadSpeed(1)), mks.encode(mks.SpeedReply(1, 7))
    device = Echo(reply)
    line = TimedSerialLine(device, baudrate=38400, clock=clock, turnaround=0.0005)
    for start in (0.0, 0.002):  # the second episode's requests go out while the first's replies were on the line
        clock.restart(start)
        for _ in range(3):
            line.write(request)
            assert line.read(0.1) == reply
    assert line.collisions == 0 and not any(tx.corrupted for tx in line.log)
    assert len(line.log) == 12  # the trace keeps both episodes
    clock.restart(0.0)  # a real overlap after a reset still collides
    device.own.append((0.0005, mks.encode(mks.RunReply(1, 0xFD, mks.RunStatus.COMPLETE))))
    clock.advance(0.0005)
    line.write(request)
    line.read(0.05)
    assert line.collisions == 1


def test_reads_wait_on_the_clock_and_return_at_the_deadline() -> None:
    clock = ManualClock()
    line = TimedSerialLine(Echo(b""), baudrate=9600, clock=clock)
    assert line.read(0.02) == b""
    assert clock.now() == pytest.approx(0.02)


@pytest.mark.mks_firmware
def test_mks_driver_survives_collisions_on_the_half_duplex_line(tmp_path: Path) -> None:
    pytest.importorskip("mujoco")
    from mkskit import motor_config, motor_model

    from joints.config import parse
    from joints.link.trace import Trace
    from joints.rig import build, sim_world

    cfg = parse(motor_config(motor_model(tmp_path), timeout=0.05))
    world = sim_world(cfg)
    line = TimedSerialLine(world.buses["rs485"], baudrate=38400, clock=world.clock)
    rig = build(cfg, transports={"rs485": line}, clock=world.clock, world=world)
    trace = Trace()
    rig.trace(trace)
    try:
        j = rig.joints["m1"]
        d = j.driver
        j.enable()
        d.move_pulses(3 * 3200, speed=300, acceleration=2000)
        t0 = rig.time
        reads = 0
        while rig.time - t0 < 2.0:  # poll the encoder back to back while it runs (and after)
            d.read("encoder_addition")
            reads += 1
        assert line.collisions >= 1  # the completion frame met a poll on the line
        assert d.link.retries_used >= 1  # the poll that collided was read again
        assert not d.motion_complete  # its completion frame was lost ...
        assert d.wait_motion(5) == 1  # ... and the status read found the end
        assert abs(d.read("encoder_addition") - 3 * 16384) <= 1
        moves = [r for r in trace if r.direction == "tx" and r.data[2:3] == b"\xfd"]
        assert len(moves) == 1  # the motion command went out exactly once
        assert reads > 300
    finally:
        rig.close()


def test_frames_before_the_clock_went_back_never_collide_with_later_ones() -> None:
    """A reset takes the clock back: the line's old timeline is over, its frames overlap nothing of the new one
    (a frame of the old timeline at the same instant once corrupted the new request)."""
    clock = ManualClock()
    completion = mks.encode(mks.RunReply(1, 0xFD, mks.RunStatus.COMPLETE))
    reply = mks.encode(mks.SpeedReply(1, 7))
    device = Echo(reply, own=[(0.0, completion)])
    line = TimedSerialLine(device, baudrate=38400, clock=clock)
    clock.advance(0.01)
    assert line.read(0.0) == completion  # the drive's own frame at 0 s of the first timeline
    clock.restart(0.0)  # a reset: the world and its clock start again
    line.write(mks.encode(mks.ReadSpeed(1)))  # at 0 s again, when the old completion frame was on the wire
    assert line.read(0.05) == reply
    assert line.collisions == 0 and not any(tx.corrupted for tx in line.log)


def test_the_log_stays_bounded_and_keeps_every_frame_that_can_still_overlap(monkeypatch: pytest.MonkeyPatch) -> None:
    """A long run's wire trace keeps its latest frames (at least LOG_KEEP), and a frame still on the line is never
    dropped from the overlap check: collisions are found after the log was cut."""
    from joints.transports import serial_sim

    monkeypatch.setattr(serial_sim, "LOG_KEEP", 3)
    clock = ManualClock()
    request, reply = mks.encode(mks.ReadSpeed(1)), mks.encode(mks.SpeedReply(1, 7))
    line = TimedSerialLine(Echo(reply), baudrate=38400, clock=clock, turnaround=0.0005)
    for _ in range(5):  # within one second: every frame may still matter, nothing goes
        line.write(request)
        assert line.read(0.1) == reply
    assert len(line.log) == 10
    for _ in range(20):  # a second apart: the log is cut to the latest 3 whenever it passes 6
        clock.advance(1.0)
        line.write(request)
        assert line.read(0.1) == reply
    assert 3 <= len(line.log) <= 6 and line.log[-1].side == "device" and line.log[-1].data == reply
    assert line.collisions == 0
    completion = mks.encode(mks.RunReply(1, 0xFD, mks.RunStatus.COMPLETE))
    device = Echo(reply, own=[(clock.now() + 1.5, completion)])
    line.peer = device
    clock.advance(1.5)
    line.write(request)  # collides with the drive's own frame, as on a fresh line
    line.read(0.05)
    assert line.collisions == 1


def test_a_line_keeps_its_latest_log_keep_frames_at_least_and_each_line_sets_its_own() -> None:
    """The documented guarantee at the shipped number: the wire trace holds the latest LOG_KEEP frames at least and
    at most twice as many (frames spaced so the last second's floor holds fewer); a line's ``log_keep`` is its own."""
    from joints.transports.serial_sim import LOG_KEEP

    clock = ManualClock()
    request, reply = mks.encode(mks.ReadSpeed(1)), mks.encode(mks.SpeedReply(1, 7))
    short = TimedSerialLine(Echo(reply), baudrate=38400, clock=clock, turnaround=0.0005)
    long = TimedSerialLine(Echo(reply), baudrate=38400, clock=clock, turnaround=0.0005)
    assert short.log_keep == long.log_keep == LOG_KEEP
    short.log_keep, long.log_keep = 50, 3 * LOG_KEEP
    with pytest.raises(ValueError, match="log_keep"):
        short.log_keep = 0  # the latest frame always stays (the overlap check's latest end)
    default = TimedSerialLine(Echo(reply), baudrate=38400, clock=clock, turnaround=0.0005)
    sizes: dict[str, list[int]] = {"default": [], "short": [], "long": []}
    for _ in range(3 * LOG_KEEP):  # 6 * LOG_KEEP frames each, 20 a second
        clock.advance(0.1)
        for name, line in (("default", default), ("short", short), ("long", long)):
            line.write(request)
            assert line.read(0.1) == reply
            sizes[name].append(len(line.log))
    first = [tx.start for tx in default.log[:1]]
    assert min(sizes["default"][2 * LOG_KEEP:]) >= LOG_KEEP and max(sizes["default"]) <= 2 * LOG_KEEP + 1
    assert first and first[0] > 0.1 * LOG_KEEP  # the oldest frames went
    assert 50 <= min(sizes["short"][100:]) and max(sizes["short"]) <= 100 + 1
    assert sizes["long"] == list(range(2, 2 * 3 * LOG_KEEP + 1, 2))  # nothing went yet
    kept = default.log
    assert [tx.side for tx in kept] == ["host", "device"] * (len(kept) // 2) and kept[-1].data == reply
    assert all(a.start < b.start for a, b in pairwise(kept))  # the latest frames, in order, none missing
    assert all(b.start - a.start < 0.2 for a, b in zip(kept[::2], kept[2::2]))  # 0.1 s apart and the reads


def test_a_line_busier_than_its_log_keep_a_second_stays_bounded_and_keeps_its_last_second() -> None:
    """More than ``log_keep`` frames a second: the frames beyond the latest ``log_keep`` that ended a second
    before go (the log does not grow for ever); the last second's frames stay (a new frame may overlap them)."""
    clock = ManualClock()
    request, reply = mks.encode(mks.ReadSpeed(1)), mks.encode(mks.SpeedReply(1, 7))
    line = TimedSerialLine(Echo(reply), baudrate=38400, clock=clock, turnaround=0.0005)
    line.log_keep = 3
    sizes = []
    for _ in range(400):  # 40 frames a second for 10 s
        clock.advance(0.05)
        line.write(request)
        assert line.read(0.1) == reply
        sizes.append(len(line.log))
        kept = line.log  # the last second, whole: no transaction missing, and reaching a second back
        assert all(b.start - a.start < 0.06 for a, b in zip(kept[::2], kept[2::2]))
        assert kept[0].start <= kept[-1].start - 0.95 or len(kept) == 2 * len(sizes)
    assert max(sizes) <= 2 * 3 + 2 * 41 and min(sizes[100:]) >= 38
    assert line.collisions == 0 and line.latest_end() == line.log[-1].end


class _Made:
    """A packed reply's maker (``TimedSerialLine.book_frames``): the message of values is ("packed", values)."""

    def __call__(self, values: tuple[int, ...]) -> tuple[str, tuple[int, ...]]:
        return ("packed", values)


class _Lazy(Deferred):
    """A deferred reply whose message is ("lazy", n)."""

    __slots__ = ("n",)

    def __init__(self, n: int) -> None:
        self.n = n

    def message(self) -> tuple[str, int]:
        return ("lazy", self.n)


def test_booked_frames_hold_no_tracked_object_and_each_keeps_its_reply_through_trims_and_reads() -> None:
    """Frames a one-call exchange books (no reply, a shared reply, a packed reply, a deferred one), among frames of
    the byte path, the log read now and then and cut many times: every entry still booked holds nothing the garbage
    collector tracks, and every frame read from the log carries the reply it was booked with."""
    clock = ManualClock()
    request, reply = mks.encode(mks.ReadSpeed(1)), mks.encode(mks.SpeedReply(1, 7))
    line = TimedSerialLine(Echo(reply), baudrate=38400, clock=clock, turnaround=0.0005)
    line.log_keep = 5
    shared, made = mks.SpeedReply(1, 7), _Made()  # (a dataclass: an object the collector tracks)
    want: dict[float, Any] = {}
    t, cuts, reads = 0.0, 0, 0
    for k in range(240):
        t += 0.3  # a frame of more than a second ago goes once the log passes twice log_keep
        host = (t, t + 0.001, t + 0.002, 4, "host", None)
        kind = k % 4
        payload: Any = (shared, (made, [k, k + 1]), _Lazy(k), None)[kind]
        dev = (t + 0.002, t + 0.003, t + 0.004, 4, "device", *(payload if kind == 1 else (payload,)))
        want[t + 0.002] = (shared, ("packed", (k, k + 1)), ("lazy", k), None)[kind]
        before = len(line._log)
        line.book_frames([host, dev])
        cuts += len(line._log) < before + 2
        if k % 37 == 36:  # read now and then: what was booked becomes transmissions
            reads += 1
            assert [tx.payload for tx in line.log if tx.side == "device" and tx.start in want] == \
                [want[tx.start] for tx in line.log if tx.side == "device" and tx.start in want]
        if k % 11 == 10:  # a byte-path transaction among the booked frames
            t += 0.1
            clock.advance(t - clock.now())
            line.write(request)
            assert line.read(0.1) == reply
        if k % 20 == 19:  # the collector untracks what holds nothing it tracks
            gc.collect()
            raw: list[Any] = line._log
            booked = [x for x in raw if type(x) is tuple]
            assert booked and not any(gc.is_tracked(x) for x in booked)
            assert len(line._replies) == sum(x[5] is not None for x in booked)
    assert cuts > 20 and reads > 5 and line.collisions == 0
    kept = line.log
    devices = [tx for tx in kept if tx.side == "device" and tx.start in want]
    assert len(devices) >= 4 and {type(tx.payload) for tx in devices} >= {type(shared), tuple, type(None)}
    assert [tx.payload for tx in devices] == [want[tx.start] for tx in devices]
    assert all(tx.payload is shared for tx in devices if want[tx.start] is shared)  # the reply itself, not a copy
    assert not line._replies and all(type(tx) is Transmission for tx in kept)
