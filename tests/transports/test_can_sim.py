"""The in-process CAN medium: wire time, arbitration, bus load, lockstep waits, python-can interface."""

from __future__ import annotations

import math
import os
import random
import subprocess
import sys
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import can
import pytest

from joints.clock import ManualClock
from joints.transports import can_sim
from joints.transports.can import PythonCanTransport
from joints.transports.can_sim import INTERFACE, CanMedium, LockstepCanBus
from joints.transports.can_timing import frame_bits, frame_time

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[2]
US = 1e-6


def msg(ident: int, data: bytes = b"") -> can.Message:
    return can.Message(arbitration_id=ident, data=data, is_extended_id=False)


class Echo:
    """A peer that answers every request 0x640+n with a 5-byte value on 0x5C0+n (and counts when)."""

    def __init__(self, medium: CanMedium, *, answers: int = 1) -> None:
        self.medium = medium
        self.answers = answers
        self.seen: list[tuple[float, int]] = []

    def on_frame(self, frame: can.Message) -> Sequence[can.Message]:
        self.seen.append((self.medium.now, frame.arbitration_id))
        if 0x640 < frame.arbitration_id < 0x6C0:
            return [msg(frame.arbitration_id - 0x80, bytes([0, 0, 0, 1, 0x3E]))] * self.answers
        return []


def test_request_and_reply_take_their_wire_time_and_advance_the_clock() -> None:
    clock = ManualClock()
    medium = CanMedium(clock=clock)
    medium.attach_peer(Echo(medium))
    bus = LockstepCanBus(medium=medium)
    req = msg(0x641, b"\x00\x02")
    bus.send(req)
    reply = bus.recv(0.1)
    assert reply is not None and reply.arbitration_id == 0x5C1
    expected = frame_time(req, 1e6) + frame_time(reply, 1e6)  # 75 + 105 bits, worst-case stuffing
    assert expected == pytest.approx(180 * US)
    assert reply.timestamp == pytest.approx(expected)
    assert clock.now() == pytest.approx(expected)
    assert medium.load().load == pytest.approx(1.0)
    bus.shutdown()


def test_recv_timeout_is_simulated_time_and_costs_no_wall_clock() -> None:
    clock = ManualClock()
    bus = LockstepCanBus(medium=CanMedium(clock=clock))
    assert bus.recv(2.5) is None
    assert clock.now() == pytest.approx(2.5)
    assert bus.recv(None) is None  # nothing in flight: nothing can ever arrive in lockstep
    assert clock.now() == pytest.approx(2.5)
    bus.shutdown()


def test_waiting_frames_are_arbitrated_by_identifier() -> None:
    medium = CanMedium(clock=ManualClock())
    a, b, c, sniffer = (LockstepCanBus(medium=medium) for _ in range(4))
    a.send(msg(0x700, b"\x01"))  # takes the idle bus at once
    c.send(msg(0x300, b"\x03"))  # these two wait for the bus: the lower id wins
    b.send(msg(0x100, b"\x02"))
    a.send(msg(0x050, b"\x04"))
    got = [sniffer.recv(1.0) for _ in range(4)]
    assert [m.arbitration_id for m in got if m] == [0x700, 0x050, 0x100, 0x300]
    times = [m.timestamp for m in got if m]
    assert times == sorted(times) and len(set(times)) == 4
    for bus in (a, b, c, sniffer):
        bus.shutdown()


def test_frames_of_one_node_keep_their_order_and_a_reply_beats_a_request() -> None:
    medium = CanMedium(clock=ManualClock())
    echo = Echo(medium, answers=3)
    medium.attach_peer(echo)
    host, sniffer = LockstepCanBus(medium=medium), LockstepCanBus(medium=medium)
    host.send(msg(0x641, b"\x00\x02"))
    host.send(msg(0x642, b"\x00\x02"))  # queued behind the first; the three replies of node 1 win over it
    ids = []
    while (m := sniffer.recv(0.01)) is not None:
        ids.append(m.arbitration_id)
    assert ids == [0x641, 0x5C1, 0x5C1, 0x5C1, 0x642, 0x5C2, 0x5C2, 0x5C2]
    host.shutdown()
    sniffer.shutdown()


def test_bus_load_of_back_to_back_frames_and_idle_time() -> None:
    clock = ManualClock()
    medium = CanMedium(clock=clock)
    tx, rx = LockstepCanBus(medium=medium), LockstepCanBus(medium=medium)
    for i in range(10):
        tx.send(msg(0x100 + i, bytes(8)))
    while rx.recv(0.0) is not None or not medium.idle():
        rx.recv(1e-3)
    busy = medium.load()
    assert busy.frames == 10 and busy.bits == 1350
    assert busy.load == pytest.approx(1350 * US / busy.elapsed)
    rx.recv(busy.elapsed)  # as long again, idle
    assert medium.load().load == pytest.approx(busy.load / 2)
    medium.reset_load()
    assert medium.load().frames == 0
    tx.shutdown()
    rx.shutdown()


class SteppedClock(ManualClock):
    """A world-like clock: sleeping runs whole 1 ms substeps and ticks the medium after each."""

    def __init__(self, medium: CanMedium | None = None) -> None:
        super().__init__()
        self.medium = medium
        self.steps = 0

    def sleep(self, seconds: float) -> None:
        n = math.ceil(seconds / 1e-3 - 1e-9)
        for _ in range(max(n, 1)):
            self.steps += 1
            self.set(self.steps * 1e-3)
            if self.medium is not None:
                self.medium.tick(self.now())


def test_round_trips_are_exact_inside_a_substep_of_a_coarse_clock() -> None:
    clock = SteppedClock()
    medium = CanMedium()
    clock.medium = medium
    medium.bind_clock(clock)
    medium.attach_peer(Echo(medium))
    bus = LockstepCanBus(medium=medium)
    stamps = []
    for _ in range(5):
        bus.send(msg(0x641, b"\x00\x02"))
        reply = bus.recv(0.1)
        assert reply is not None
        stamps.append(reply.timestamp)
    assert stamps == pytest.approx([180 * US * (i + 1) for i in range(5)])
    assert clock.steps == 1  # five request/reply pairs fit in one 1 ms physics substep
    bus.shutdown()


def test_a_frame_in_flight_reaches_its_peer_while_the_host_sleeps() -> None:
    clock = SteppedClock()
    medium = CanMedium()
    clock.medium = medium
    medium.bind_clock(clock)
    echo = Echo(medium)
    medium.attach_peer(echo)
    bus = LockstepCanBus(medium=medium)
    bus.send(msg(0x641, b"\x00\x02"))
    clock.sleep(0.01)  # the host sleeps without reading: the world's ticks carry the frame
    assert echo.seen and echo.seen[0][0] <= 1e-3
    reply = bus.recv(0.0)
    assert reply is not None and reply.timestamp == pytest.approx(180 * US)
    bus.shutdown()


def test_a_clock_going_back_drops_frames_in_flight() -> None:
    clock = ManualClock()
    medium = CanMedium(clock=clock)
    medium.attach_peer(Echo(medium))
    bus = LockstepCanBus(medium=medium)
    clock.set(1.0)
    bus.send(msg(0x641, b"\x00\x02"))
    clock.restart(0.0)  # world reset
    assert bus.recv(0.01) is None
    assert medium.now == pytest.approx(0.01)
    bus.shutdown()


def test_filters_and_own_messages() -> None:
    medium = CanMedium(clock=ManualClock())
    talker = LockstepCanBus(medium=medium, receive_own_messages=True)
    listener = LockstepCanBus(medium=medium, can_filters=[{"can_id": 0x5C0, "can_mask": 0x7C0}])
    talker.send(msg(0x641, b"\x01"))
    talker.send(msg(0x5C1, b"\x3e"))
    own = talker.recv(0.01)
    assert own is not None and own.arbitration_id == 0x641 and not own.is_rx
    got = listener.recv(0.01)
    assert got is not None and got.arbitration_id == 0x5C1 and got.is_rx
    assert listener.recv(0.01) is None
    talker.shutdown()
    listener.shutdown()


def test_python_can_transport_over_the_lockstep_bus() -> None:
    clock = ManualClock()
    medium = CanMedium("tp-test", clock=clock)
    medium.attach_peer(Echo(medium))
    transport = PythonCanTransport(LockstepCanBus(medium=medium))
    transport.send(msg(0x641, b"\x00\x02"))
    reply = transport.recv(0.1)
    assert reply is not None and bytes(reply.data) == bytes([0, 0, 0, 1, 0x3E])
    transport.close()
    transport.close()


def test_channels_name_media_in_this_process() -> None:
    first = CanMedium("arm")
    second = CanMedium("arm")  # the name is taken while the first is alive
    assert first.channel == "arm" and second.channel == "arm#2"
    bus = LockstepCanBus("arm#2")
    assert bus.medium is second
    bus.shutdown()
    with pytest.raises(can.CanOperationError):
        bus.send(msg(1))


def test_fd_frames_are_refused() -> None:
    bus = LockstepCanBus(medium=CanMedium(clock=ManualClock()))
    with pytest.raises(can.CanOperationError, match="classic"):
        bus.send(can.Message(arbitration_id=1, data=bytes(12), is_fd=True))
    bus.shutdown()


def test_the_pyproject_entry_point_opens_the_bus_by_name(tmp_path: Path) -> None:
    """``can.Bus(interface="joints-sim")`` in a fresh interpreter, with the entry point pyproject declares."""
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    points = declared["project"]["entry-points"]["can.interface"]
    assert points[INTERFACE] == "joints.transports.can_sim:LockstepCanBus"
    entries = [f"{k} = {v}" for k, v in points.items()]
    dist = tmp_path / "joints_entry_point_probe-0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: joints-entry-point-probe\nVersion: 0\n")
    (dist / "entry_points.txt").write_text('[can.interface]\n' + "\n".join(entries) + "\n")
    code = textwrap.dedent(f"""
        import can
        a = can.Bus(interface={INTERFACE!r}, channel="probe")
        b = can.Bus(interface={INTERFACE!r}, channel="probe")
        a.send(can.Message(arbitration_id=0x123, data=b"hi", is_extended_id=False))
        m = b.recv(1.0)
        print(type(b).__name__, hex(m.arbitration_id), bytes(m.data))
        a.shutdown(); b.shutdown()
    """)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), str(ROOT)]))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60,
                          check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["LockstepCanBus", "0x123", "b'hi'"]


def test_a_clock_behind_the_media_ticks_is_not_a_reset() -> None:
    """The world's clock shows the exact instant the host waited for while the physics - and the ticks it gives
    the media - stand up to a substep ahead: only a restart (a new epoch) drops the frames in flight."""
    clock = ManualClock()
    medium = CanMedium(clock=clock)
    medium.attach_peer(Echo(medium))
    bus = LockstepCanBus(medium=medium)
    bus.send(msg(0x641, b"\x00\x02"))
    medium.tick(0.001)  # the world ran the substep ending at 1 ms: request and reply went over the wire
    clock.set(0.0004)  # the instant the host booked, inside that substep
    reply = bus.recv(0.0)
    assert reply is not None and reply.timestamp == pytest.approx(180 * US)
    bus.shutdown()


# -- the medium's hot paths against their plain definitions -----------------------------------------------


def _reference_priority(frame: can.Message) -> tuple[int, int, int]:
    """Arbitration order as CAN defines it: base identifier, then standard before extended, then the extension."""
    if frame.is_extended_id:
        return (frame.arbitration_id >> 18, 1, frame.arbitration_id & 0x3FFFF)
    return (frame.arbitration_id, 0, 0)


def _random_frames(rng: random.Random, n: int) -> list[can.Message]:
    out = []
    for _ in range(n):
        ext = rng.random() < 0.4
        ident = rng.randrange(1 << 29) if ext else rng.randrange(1 << 11)
        if rng.random() < 0.3:  # collide: an extended frame on a standard one's base id, equal ids
            ident = (rng.randrange(1 << 11) << 18 | rng.randrange(4)) if ext else rng.randrange(4)
        remote = rng.random() < 0.1
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(9)))
        out.append(can.Message(arbitration_id=ident, is_extended_id=ext, is_remote_frame=remote,
                               data=b"" if remote else data, dlc=len(data)))
    return out


def test_the_priority_key_orders_frames_as_can_arbitration_does() -> None:
    rng = random.Random(3)
    frames = _random_frames(rng, 400)
    by_key = sorted(range(len(frames)), key=lambda i: (can_sim._priority(frames[i]), i))
    by_reference = sorted(range(len(frames)), key=lambda i: (_reference_priority(frames[i]), i))
    assert by_key == by_reference


def test_the_winner_is_the_lowest_identifier_among_each_hosts_oldest_and_every_peer_frame() -> None:
    """``CanMedium._winner`` (one pass over the queue) against the rule written out: the contenders are every
    ready frame of a peer and the oldest ready frame of each python-can node; the lowest priority, then the
    oldest, wins."""
    rng = random.Random(5)
    for _ in range(300):
        medium = CanMedium(register=False)
        nodes = [medium.attach(f"host{i}") for i in range(2)] + \
            [medium.attach_peer(Echo(medium), name=f"peer{i}") for i in range(2)]
        for frame in _random_frames(rng, rng.randrange(1, 8)):
            medium._enqueue(frame, rng.choice(nodes), rng.choice((0.0, 1e-4, 2e-4)))
        start = rng.choice((0.0, 1e-4, 2e-4))
        if not any(p.ready <= start for p in medium._pending):
            continue
        heads: dict[int, can_sim._Pending] = {}
        contenders = []
        for p in medium._pending:
            if p.ready > start:
                continue
            if p.sender.peer is not None:
                contenders.append(p)
            elif id(p.sender) not in heads or p.seq < heads[id(p.sender)].seq:
                heads[id(p.sender)] = p
        contenders.extend(heads.values())
        want = min(contenders, key=lambda p: (_reference_priority(p.frame), p.seq))
        assert medium._winner(start) is want


@pytest.mark.parametrize("stuffing", ["worst", "exact", "none"])
def test_the_bits_cache_gives_each_frame_its_own_bit_count(stuffing: str) -> None:
    medium = CanMedium(register=False, stuffing=stuffing)
    for frame in _random_frames(random.Random(7), 500):
        assert medium._bits(frame) == frame_bits(frame, stuffing), frame


def test_a_poll_with_nothing_due_returns_at_once_as_the_waiting_loop_would() -> None:
    """``receive(node, 0)`` with nothing due takes the short path (no wait at all) and leaves the medium and
    the clock as the waiting loop leaves them; with a frame due now it waits as before."""
    runs = []
    for short in (True, False):
        clock = ManualClock()
        medium = CanMedium(register=False, clock=clock)
        medium.attach_peer(Echo(medium), latency=50 * US)
        bus = LockstepCanBus(medium=medium, adapter_latency=20 * US)
        waits: list[float] = []
        wait = medium._wait_until
        medium._wait_until = (  # type: ignore[method-assign]
            lambda t, lazy=False, waits=waits, wait=wait: (waits.append(t), wait(t, lazy))[1])
        bus.send(msg(0x641, b"\x00\x01"))
        polls = []
        for _ in range(3):
            if not short:  # the reference: the waiting loop (what the short path must equal)
                node, timeout = bus._node, 0.0
                deadline = medium.now + timeout
                target = min(medium._next_event(), node.held[0][0] if node.held else math.inf, deadline)
                medium._wait_until(target)
                polls.append(node.rx.popleft() if node.rx else None)
            else:
                polls.append(bus.recv(0.0))
        got = bus.recv(1.0)
        runs.append((waits, [p is None for p in polls], got.timestamp if got else None, clock.now(), medium.now,
                     medium.frames, medium.bits))
        bus.shutdown()
    short_run, reference = runs
    assert short_run[0] == reference[0][3:] and len(reference[0]) == len(short_run[0]) + 3  # the polls did not wait
    assert short_run[1:] == reference[1:]


def test_a_poll_with_a_frame_due_now_still_delivers_it() -> None:
    clock = ManualClock()
    medium = CanMedium(register=False, clock=clock)
    bus = LockstepCanBus(medium=medium)
    other = LockstepCanBus(medium=medium)
    other.send(msg(0x123, b"\x01"))
    assert bus.recv(0.0) is None  # on the wire: not there yet
    clock.advance(frame_time(msg(0x123, b"\x01"), medium.bitrate))  # the host slept past its end
    got = bus.recv(0.0)
    assert got is not None and got.arbitration_id == 0x123
    bus.shutdown()
    other.shutdown()


def test_a_poll_still_waits_where_the_waiting_loop_would_act() -> None:
    """The short path of ``receive(node, 0)`` is taken only where waiting until now does nothing: a frame due
    now is still processed (here on an ideal medium: delivered at once), and a clock behind the medium's time
    still sleeps up to it."""
    clock = ManualClock()
    medium = CanMedium(register=False, clock=clock, ideal=True)
    bus = LockstepCanBus(medium=medium)
    other = medium.attach_peer(Echo(medium), name="other")
    medium._enqueue(msg(0x123, b"\x01"), other, medium.now)  # due now, not yet processed
    got = bus.recv(0.0)
    assert got is not None and got.arbitration_id == 0x123
    medium.now = clock.now() + 1e-9  # the medium stands ahead of the clock (as after an inexact sleep)
    assert bus.recv(0.0) is None
    assert clock.now() == medium.now  # the poll let the clock catch up, as waiting until now does
    bus.shutdown()


class _Lockstep:
    """A world in miniature for the medium: physics in 1 ms substeps; sleeping runs the substeps that end at or
    before the instant and the one that reaches it, ticking the medium at each substep's end; the clock shows
    the instant slept to."""

    def __init__(self) -> None:
        self.t = 0.0
        self.steps = 0
        self.medium: CanMedium | None = None
        self.ticks: list[Any] = []  #: what else the world ticks (a drive sending by itself)

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        target = self.t + seconds
        while self.steps * 1e-3 < target - 1e-12:
            self.steps += 1
            assert self.medium is not None
            self.medium.tick(self.steps * 1e-3)
            for tick in self.ticks:
                tick(self.steps * 1e-3)
        self.t = target


class _Drive:
    """A peer that answers every request after its turnaround and notes the physics substep it saw it at."""

    def __init__(self, world: _Lockstep, medium: CanMedium) -> None:
        self.world, self.medium = world, medium
        self.node: Any = None  #: its attachment to the medium
        self.seen: list[tuple[float, int]] = []

    def on_frame(self, frame: can.Message) -> Sequence[can.Message]:
        self.seen.append((self.medium.time(), self.world.steps))
        return [msg(frame.arbitration_id - 0x80, bytes([0, 0, 0, self.world.steps & 0xFF, 0x3E]))]

    def turnaround(self, frame: can.Message) -> float:
        return 1300 * US  # longer than a substep: ticks come between a request and its answer

    def tick(self, t: float) -> None:
        """Every third substep a frame of its own (an EMCY), sent at the substep's end."""
        if self.world.steps % 3 == 0:
            self.medium.send_at(self.node, msg(0x081, bytes([self.world.steps & 0xFF])), t)  # beats the answers


def _transactions(answers_only: bool, skip: bool, monkeypatch: pytest.MonkeyPatch) -> tuple[list[Any], int]:
    """A long run from time 0, then 400 short ones that start at odd instants of the first substep (where the
    clock's sleeps round: ``t - c`` is exact only for ``t <= 2c``)."""
    out: list[Any] = []
    waits = 0
    rng = random.Random(11)
    for start in [0.0] + [rng.uniform(1e-7, 4e-5) for _ in range(400)]:
        got, n = _run_transactions(answers_only, skip, monkeypatch, start, 200 if start == 0.0 else 4, rng)
        out.append(got)
        waits += n
    return out, waits


def _run_transactions(answers_only: bool, skip: bool, monkeypatch: pytest.MonkeyPatch, start: float, n: int,
                      rng: random.Random) -> tuple[list[Any], int]:
    world = _Lockstep()
    medium = CanMedium(register=False, clock=world)
    world.medium = medium
    medium.answers_only = answers_only
    if not skip:  # the reference: a wait for every edge
        monkeypatch.setattr(medium, "_skippable", lambda edge, held: False)
    drive = _Drive(world, medium)
    drive.node = medium.attach_peer(drive)
    if not answers_only:
        world.ticks.append(drive.tick)
    bus = LockstepCanBus(medium=medium, adapter_latency=200 * US)
    waits = []
    wait = medium._wait_until
    monkeypatch.setattr(medium, "_wait_until", lambda t, lazy=False: (waits.append(t), wait(t, lazy))[1])
    out: list[Any] = []
    world.sleep(start)
    for i in range(n):
        if i % 3 == 0:  # the host waits for the next substep's end (a control period): the physics stands there
            world.sleep(math.ceil(world.t * 1e3 + 1e-9) * 1e-3 - world.t)
        elif i % 3 == 1:
            world.sleep(rng.choice((0.0, 37 * US, 410 * US)))
        bus.send(msg(0x641, bytes(rng.randrange(256) for _ in range(rng.choice((2, 4, 6, 8))))))
        got = bus.recv(0.01)
        while got is not None and got.arbitration_id == 0x081:  # the drive's own frames: noted, not the answer
            out.append((got.timestamp, bytes(got.data)))
            got = bus.recv(0.01)
        assert got is not None
        out.append((got.timestamp, bytes(got.data), world.t, world.steps, medium.now, medium.frames, medium.busy))
    out.append(drive.seen)
    bus.shutdown()
    return out, len(waits)


@pytest.mark.parametrize(("answers_only", "fewer"), [(True, 0.7), (False, 0.9)])
def test_edges_processed_without_their_waits_give_what_waiting_for_each_gives(
        answers_only: bool, fewer: float, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each request still reaches the drive with the physics at the substep that reaches it, the drive's own
    frames (where it sends some at ticks) contend as before, the clock shows the same instants, the host gets
    the same frames at the same times; with fewer waits (most where the drive only answers)."""
    fast, fast_waits = _transactions(answers_only, True, monkeypatch)
    reference, reference_waits = _transactions(answers_only, False, monkeypatch)
    assert fast_waits < fewer * reference_waits, (fast_waits, reference_waits)
    assert fast == reference


class FreshEcho(Echo):
    """:class:`Echo` with new answer frames each time (``fresh_answers``: the medium may hand them over)."""

    fresh_answers = True

    def on_frame(self, frame: can.Message) -> Sequence[can.Message]:
        self.sent = [msg(f.arbitration_id, bytes(f.data)) for f in super().on_frame(frame)]
        return self.sent


@pytest.mark.parametrize("latency", [0.0, 200 * US])
def test_a_fresh_answer_to_the_only_host_is_handed_over_as_a_received_frame(latency: float) -> None:
    clock = ManualClock()
    medium = CanMedium(clock=clock, channel="handover")
    peer = FreshEcho(medium)
    medium.attach_peer(peer)
    bus = LockstepCanBus(medium=medium, adapter_latency=latency)
    copy_medium = CanMedium(clock=ManualClock(), channel="handover-copied")  # the same, its peer not fresh
    copy_medium.attach_peer(Echo(copy_medium))
    copied_bus = LockstepCanBus(medium=copy_medium, adapter_latency=latency)
    bus.send(msg(0x641, b"\x00\x02"))
    copied_bus.send(msg(0x641, b"\x00\x02"))
    got, copied = bus.recv(0.1), copied_bus.recv(0.1)
    assert got is peer.sent[0] and medium.handed_over == 1  # no second object made
    assert copy_medium.handed_over == 0
    assert copied is not None and got is not None
    fields = ("timestamp", "arbitration_id", "is_extended_id", "is_remote_frame", "is_error_frame", "dlc", "is_rx",
              "is_fd", "bitrate_switch", "error_state_indicator")
    assert [getattr(got, f) for f in fields] == [getattr(copied, f) for f in fields]
    assert bytes(got.data) == bytes(copied.data) and (got.channel, copied.channel) == (medium.channel, copy_medium.channel)
    bus.shutdown()
    copied_bus.shutdown()


def test_a_fresh_answer_two_python_can_nodes_receive_is_copied_for_each() -> None:
    medium = CanMedium(clock=ManualClock())
    peer = FreshEcho(medium)
    medium.attach_peer(peer)
    bus, tap = LockstepCanBus(medium=medium), LockstepCanBus(medium=medium)
    bus.send(msg(0x641, b"\x00\x02"))
    a, b = bus.recv(0.1), tap.recv(0.1)
    assert a is not None and b is not None and a is not b and peer.sent[0] not in (a, b)
    assert medium.handed_over == 0
    bus.shutdown()
    tap.shutdown()
