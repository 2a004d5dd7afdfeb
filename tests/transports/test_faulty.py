"""The fault-injecting line (joints.transports.faulty): each fault does what it says, seeded, logged.

Property tests (hypothesis): without faults the line is transparent; split pieces reassemble to
the original bytes; a seed repeats a run exactly; every unit arrives within ``max_delay``.
"""

from __future__ import annotations

from typing import Any

import can
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from joints.clock import ManualClock
from joints.transports.can import FrameTransport
from joints.transports.faulty import Faults, FaultyFrameTransport, FaultyTransport
from joints.transports.loopback import LoopbackTransport

SETTINGS = settings(max_examples=150, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])


class Recorder:
    """A peer that records what reached it and answers ``reply`` to every burst."""

    def __init__(self, reply: bytes = b"") -> None:
        self.got: list[bytes] = []
        self.silences = 0
        self.reply = reply

    def receive(self, data: bytes) -> bytes:
        self.got.append(data)
        return self.reply

    def silence(self) -> bytes:
        self.silences += 1
        return b""


NONE = Faults()


def line(tx: Faults = NONE, rx: Faults = NONE, *, seed: int = 0,
         reply: bytes = b"") -> tuple[FaultyTransport, Recorder, ManualClock]:
    peer = Recorder(reply)
    clock = ManualClock()
    return (FaultyTransport(LoopbackTransport(peer), tx=tx, rx=rx, seed=seed, clock=clock, advance=clock.advance,
                            silence=peer.silence), peer, clock)


def read_all(t: FaultyTransport, timeout: float = 1.0) -> bytes:
    out = b""
    while chunk := t.read(timeout):
        out += chunk
    return out


def test_faults_are_validated() -> None:
    with pytest.raises(ValueError):
        Faults(drop=1.5)
    with pytest.raises(ValueError):
        Faults.rate(0.1, ["drop", "teleport"])
    f = Faults.rate(0.1)
    p_none = 1.0
    for kind in ("drop", "corrupt", "split", "duplicate", "delay", "reorder"):
        p_none *= 1 - getattr(f, kind)
    assert 1 - p_none == pytest.approx(0.1)
    assert f.echo == 0 and "drop=" in str(f) and str(Faults()) == "none"


@SETTINGS
@given(st.lists(st.binary(min_size=1, max_size=40), max_size=10))
def test_without_faults_the_line_is_transparent(frames: list[bytes]) -> None:
    t, peer, clock = line(reply=b"\x01\x02")
    for f in frames:
        t.write(f)
        assert t.read(0.1) == b"\x01\x02"
    assert peer.got == frames and peer.silences == len(frames)
    assert clock.now() == 0.0 and not t.counts and t.in_flight == 0


@SETTINGS
@given(st.lists(st.binary(min_size=1, max_size=40), min_size=1, max_size=10), st.integers(0, 2**32))
def test_split_pieces_reassemble_back_to_back(frames: list[bytes], seed: int) -> None:
    t, peer, _clock = line(tx=Faults(split=1.0), seed=seed)
    for f in frames:
        before = len(peer.got)
        silences = peer.silences
        t.write(f)
        assert b"".join(peer.got[before:]) == f
        assert peer.silences == silences + 1  # one burst: silence after the last piece only
    assert t.counts["tx.split"] == sum(len(f) > 1 for f in frames)


@SETTINGS
@given(st.integers(0, 2**32), st.floats(0.001, 0.1))
def test_a_seed_repeats_the_run_and_every_unit_arrives_within_max_delay(seed: int, max_delay: float) -> None:
    def run() -> tuple[list[bytes], list[tuple[str, str, str]], list[float]]:
        f = Faults.rate(0.5, max_delay=max_delay)
        t, peer, clock = line(tx=f, rx=f, seed=seed, reply=b"\xAA\xBB\xCC")
        arrivals = []
        for i in range(20):
            sent = clock.now()
            t.write(bytes((i, i + 1, i + 2)))
            while clock.now() - sent <= 2 * max_delay + 1e-9:  # the request's max_delay, then its answer's
                if t.read(2 * max_delay):
                    arrivals.append(clock.now() - sent)
            assert t.in_flight == 0  # nothing outlives that
        return peer.got, [(r.direction, r.kind, r.detail) for r in t.log], arrivals

    a, b = run(), run()
    assert a == b
    assert all(dt <= 2 * max_delay + 1e-9 for dt in a[2])


def test_drop_corrupt_duplicate_and_echo_are_logged_with_the_unit_before() -> None:
    t, peer, _clock = line(tx=Faults(drop=1.0), seed=3)
    t.write(b"\x01\x02\x03\x04")
    rec = t.log[-1]
    assert (rec.direction, rec.kind, rec.unit) == ("tx", "drop", b"\x01\x02\x03\x04")
    assert b"".join(peer.got) != b"\x01\x02\x03\x04"

    t, peer, _clock = line(tx=Faults(corrupt=1.0, max_flips=1), seed=3)
    t.write(b"\x00\x00")
    assert int.from_bytes(peer.got[0], "big").bit_count() == 1 and t.log[-1].kind == "corrupt"

    t, peer, _clock = line(tx=Faults(duplicate=1.0), seed=3)
    t.tag = "call 7"
    t.write(b"\x05")
    assert peer.got == [b"\x05", b"\x05"] and t.log[-1].tag == "call 7"

    t, peer, _clock = line(tx=Faults(echo=1.0), reply=b"\x09")
    t.write(b"\x05\x06")
    assert read_all(t) == b"\x05\x06\x09"  # the host hears itself first, then the answer
    assert t.counts == {"tx.echo": 1}


def test_reorder_swaps_a_unit_with_the_next() -> None:
    t, peer, clock = line(tx=Faults(reorder=1.0, max_delay=0.05), seed=1)
    t.write(b"\x01")  # held
    assert peer.got == []
    t.tx_faults = Faults()
    t.write(b"\x02")  # goes first, the held one right after it
    assert peer.got == [b"\x02", b"\x01"] and clock.now() == 0.0
    t.tx_faults = Faults(reorder=1.0, max_delay=0.05)
    t.write(b"\x03")  # held, nothing follows: released when its hold ends
    assert t.read(0.1) == b"" and peer.got[-1] == b"\x03" and clock.now() == pytest.approx(0.1)


def test_delay_is_on_the_injected_clock() -> None:
    t, _peer, clock = line(rx=Faults(delay=1.0, max_delay=0.05), reply=b"\x42", seed=5)
    t.write(b"\x01")
    assert t.read(0.0) == b""  # not yet
    got = t.read(1.0)
    assert got == b"\x42" and 0 < clock.now() <= 0.05  # the read waited exactly as long as the delay
    assert t.log[-1].kind == "delay"


class Frames(FrameTransport):
    """A frame transport whose peer answers every frame with id+1 and the same data."""

    def __init__(self) -> None:
        self.rx: list[Any] = []
        self.sent: list[Any] = []

    def send(self, frame: Any) -> None:
        self.sent.append(frame)
        self.rx.append(can.Message(arbitration_id=frame.arbitration_id + 1, data=frame.data, is_extended_id=False))

    def recv(self, timeout: float) -> Any | None:
        return self.rx.pop(0) if self.rx else None

    def close(self) -> None:
        pass


def test_the_can_variant_drops_corrupts_duplicates_and_delays_frames() -> None:
    inner = Frames()
    clock = ManualClock()
    t = FaultyFrameTransport(inner, tx=Faults(duplicate=1.0), rx=Faults(corrupt=1.0, max_flips=1), seed=2,
                             clock=clock, advance=clock.advance)
    t.send(can.Message(arbitration_id=0x642, data=b"\x00\x00", is_extended_id=False))
    assert len(inner.sent) == 2  # a repeated frame
    replies = [t.recv(0.1), t.recv(0.1), t.recv(0.1)]
    assert replies[2] is None
    assert all(r.arbitration_id == 0x643 and bytes(r.data) != b"\x00\x00" for r in replies[:2])
    assert t.counts == {"tx.duplicate": 1, "rx.corrupt": 2} and t.name.startswith("faulty:")
    t.tx_faults, t.rx_faults = Faults(drop=1.0), Faults()
    t.send(can.Message(arbitration_id=0x642, data=b"\x01", is_extended_id=False))
    assert len(inner.sent) == 2 and t.recv(0.05) is None and clock.now() == pytest.approx(0.1 + 0.05)
