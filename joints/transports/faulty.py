"""Fault injection on a line: drop, corrupt, split, duplicate, delay, reorder, echo - seeded, and logged.

Rule: a wrapper around any transport, a transport itself (the link cannot tell). Faults are drawn
from one seeded :class:`random.Random`, so a run repeats exactly; every fault is logged
(:attr:`FaultyLine.log`, :attr:`FaultyLine.counts`) so a harness checks invariants against what
really crossed the line. Nothing here decodes a frame.

Directions: ``tx`` is what the host writes (towards the drives), ``rx`` what it reads. Each has its
own :class:`Faults`; one unit is a write (tx) or a chunk the inner transport returned (rx; in
process a chunk is one drive's answer), or one CAN frame. Per unit, each fault happens with its
own probability:

* ``drop`` - lost: the whole unit, or (byte streams) its head or its tail (a frame cut short);
* ``corrupt`` - 1 .. ``max_flips`` bits flipped (CAN: in the data; a real CAN controller drops
  such a frame on its CRC, so this fuzzes the codec and link beyond what a bus delivers);
* ``split`` - (byte streams) delivered as 2-4 pieces back to back (no silence between them);
* ``duplicate`` - delivered twice;
* ``delay`` - delivered up to ``max_delay`` seconds late;
* ``reorder`` - held back and delivered after the next unit of its direction (or ``max_delay``
  after it was sent if none comes first);
* ``echo`` - (tx) the host also hears what it wrote, at once, as an RS485 adapter does (then
  subject to the rx drop, corrupt and split).

Duplication, delay and reorder are drawn once per unit (a duplicate follows its original back to
back, as a CAN frame repeated after a lost acknowledge does); drop, corrupt and split per copy.
Every unit is delivered within ``max_delay`` of being sent (delay and reorder hold together), so
with the two directions' ``max_delay`` summing to less than ``timeout + late`` of a link, no reply
can outlive the link's late window (:class:`~joints.link.base.RetryPolicy`); beyond that a late
reply is indistinguishable from a fresh one on protocols whose replies carry no request identity.

Time: due times are on the ``clock`` given. In process (a :class:`~joints.clock.ManualClock`, an
inner transport that never blocks) pass ``advance`` (e.g. ``clock.advance`` or a world's
``clock.sleep``): a read that has to wait moves that clock to the next due time or its timeout,
as a read on a real line lets time pass. Without ``advance`` (a serial port or pty on the wall
clock) the wrapper waits in the inner transport's own ``read``/``recv``.

Silence (byte streams in process): a line between two bursts is silent (Modbus t3.5). Pass
``silence`` (e.g. the device bus's ``silence``) and it is called after every group of pieces
delivered together; its answer travels back as rx. Over a pty the served twin detects silence
itself.
"""

from __future__ import annotations

import abc
import copy
import random
from collections import Counter, deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, fields
from typing import Any, Generic, Protocol, TypeVar

from joints.transports.base import ByteTransport
from joints.transports.can import FrameTransport

__all__ = ["KINDS", "FaultRecord", "Faults", "FaultyFrameTransport", "FaultyLine", "FaultyTransport"]

#: every fault kind, in the order they are drawn
KINDS = ("drop", "corrupt", "split", "duplicate", "delay", "reorder", "echo")

T = TypeVar("T")


class Clock(Protocol):
    """What the line needs of a clock (a :class:`joints.clock.Clock`: transports do not import it)."""

    def now(self) -> float: ...


@dataclass(frozen=True)
class Faults:
    """Per-unit probabilities of each fault in one direction (see the module docstring)."""

    drop: float = 0.0
    corrupt: float = 0.0
    split: float = 0.0
    duplicate: float = 0.0
    delay: float = 0.0
    reorder: float = 0.0
    echo: float = 0.0
    max_delay: float = 0.02  #: s, the longest delay (and the longest a reordered unit is held)
    max_flips: int = 3  #: bits flipped by one corruption (CRC-16 detects any 3 in a Modbus frame)

    def __post_init__(self) -> None:
        for kind in KINDS:
            p = getattr(self, kind)
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"probability of {kind} must be within 0..1, got {p!r}")
        if self.max_delay < 0 or self.max_flips < 1:
            raise ValueError("max_delay must be >= 0 and max_flips >= 1")

    @classmethod
    def rate(cls, total: float, kinds: Iterable[str] = ("drop", "corrupt", "split", "duplicate", "delay",
                                                          "reorder"), **settings: Any) -> Faults:
        """Each of ``kinds`` equally likely, so that a unit meets at least one fault with probability ``total``."""
        kinds = tuple(kinds)
        unknown = set(kinds) - set(KINDS)
        if unknown:
            raise ValueError(f"unknown fault kinds {sorted(unknown)}; known: {KINDS}")
        if not 0.0 <= total < 1.0:
            raise ValueError(f"total fault rate must be within 0..1, got {total!r}")
        p = 1.0 - (1.0 - total) ** (1.0 / len(kinds)) if kinds else 0.0
        values: dict[str, Any] = {k: p for k in kinds}
        return cls(**values, **settings)

    @property
    def active(self) -> bool:
        return any(getattr(self, k) for k in KINDS)

    def __str__(self) -> str:
        parts = [f"{f.name}={getattr(self, f.name):.3g}" for f in fields(self)
                 if f.name in KINDS and getattr(self, f.name)]
        return ", ".join(parts) or "none"


NO_FAULTS = Faults()


@dataclass(frozen=True, slots=True)
class FaultRecord:
    """One fault the line injected: when, which direction, what, to which unit (as it was before)."""

    time: float
    direction: str  #: "tx" (host -> drives) or "rx" (drives -> host)
    kind: str  #: one of :data:`KINDS`
    unit: Any  #: the unit before the fault (bytes, or a can.Message)
    detail: str = ""
    tag: object = None  #: :attr:`FaultyLine.tag` when the fault was drawn


@dataclass(slots=True)
class _Item(Generic[T]):
    due: float
    seq: int
    data: T
    tag: object


class FaultyLine(abc.ABC, Generic[T]):
    """The fault engine shared by the byte-stream and the CAN-frame wrappers."""

    def __init__(self, inner: Any, *, tx: Faults = NO_FAULTS, rx: Faults = NO_FAULTS, seed: int = 0,
                 clock: Clock, advance: Callable[[float], None] | None = None, log_limit: int = 100_000) -> None:
        self.inner = inner
        self.tx_faults = tx
        self.rx_faults = rx
        self.seed = seed
        self.rng = random.Random(seed)
        self.clock = clock
        self.advance = advance
        self.log: deque[FaultRecord] = deque(maxlen=log_limit)  #: the latest faults, oldest first
        self.counts: Counter[str] = Counter()  #: "tx.drop", "rx.corrupt" ...: faults injected
        self.units: Counter[str] = Counter()  #: "tx", "rx": units that crossed the line
        #: set by a harness: carried by every unit written from now on (see :attr:`delivering`)
        self.tag: object = None
        #: the tag of the unit being handed to the inner transport (None outside a delivery)
        self.delivering: object = None
        self._seq = 0
        self._queues: dict[str, list[_Item[T]]] = {"tx": [], "rx": []}
        self._held: dict[str, list[_Item[T]]] = {"tx": [], "rx": []}

    # -- what subclasses define ----------------------------------------------------------------
    @abc.abstractmethod
    def _deliver(self, unit: T) -> None:
        """Hand one tx unit to the inner transport."""

    @abc.abstractmethod
    def _pull(self, timeout: float) -> list[T]:
        """What the inner transport has received, waiting up to ``timeout`` s (0: do not wait)."""

    @abc.abstractmethod
    def _drop_part(self, unit: T, rng: random.Random) -> tuple[T | None, str]:
        """The unit after a drop (None: all of it) and what was dropped."""

    @abc.abstractmethod
    def _flip(self, unit: T, flips: int, rng: random.Random) -> tuple[T, str]:
        """A copy of the unit with ``flips`` bits flipped, and which."""

    def _split(self, unit: T, rng: random.Random) -> list[T] | None:
        """The unit in pieces (None: it cannot be split)."""
        return None

    def _after_group(self) -> None:
        """A group of tx units went out back to back (the line is silent after it)."""

    # -- the engine -------------------------------------------------------------------------------
    def _record(self, direction: str, kind: str, unit: T, detail: str = "") -> None:
        self.counts[f"{direction}.{kind}"] += 1
        self.log.append(FaultRecord(self.clock.now(), direction, kind, unit, detail, self.tag))

    def _inject(self, direction: str, unit: T, *, timing: bool = True) -> None:
        """Put one unit on the line, faults drawn, into the queue of its direction.

        Timing faults (delay, reorder) and duplication are drawn once per unit, so a duplicate
        follows its original back to back; drop, corrupt and split once per copy. ``timing``
        False: the unit travels at once (an adapter's echo is heard as it is sent).
        """
        f = self.tx_faults if direction == "tx" else self.rx_faults
        now = self.clock.now()
        self.units[direction] += 1
        if not f.active:
            self._enqueue(direction, [unit], now, held=False)
            return
        rng = self.rng
        copies = [unit]
        if timing and f.duplicate and rng.random() < f.duplicate:
            copies.append(unit)
            self._record(direction, "duplicate", unit)
        due = now
        if timing and f.delay and rng.random() < f.delay:
            late = rng.uniform(0.0, f.max_delay)
            due += late
            self._record(direction, "delay", unit, f"{late * 1000:.3f} ms")
        held = timing and bool(f.reorder) and rng.random() < f.reorder
        if held:
            self._record(direction, "reorder", unit)
        pieces: list[T] = []
        for one in copies:
            part = one
            if f.drop and rng.random() < f.drop:
                kept, what = self._drop_part(one, rng)
                self._record(direction, "drop", one, what)
                if kept is None:
                    continue
                part = kept
            if f.corrupt and rng.random() < f.corrupt:
                before = part
                part, what = self._flip(part, rng.randint(1, f.max_flips), rng)
                self._record(direction, "corrupt", before, what)
            split = self._split(part, rng) if f.split and rng.random() < f.split else None
            if split is not None:
                self._record(direction, "split", part, f"{len(split)} pieces")
                pieces.extend(split)
            else:
                pieces.append(part)
        if pieces:
            self._enqueue(direction, pieces, due, held=held, until=now + f.max_delay)

    def _enqueue(self, direction: str, pieces: list[T], due: float, *, held: bool, until: float = 0.0) -> None:
        """Queue ``pieces`` for ``due``; ``held`` ones wait for the next unit, at the latest until ``until``."""
        queue, waiting = self._queues[direction], self._held[direction]
        items = []
        for piece in pieces:
            self._seq += 1
            items.append(_Item(max(due, until) if held else due, self._seq, piece, self.tag))
        if held:
            waiting.extend(items)
            return
        queue.extend(items)
        if waiting:  # a held unit goes right after this one (or when its hold ends, if that is sooner)
            last = max(items, key=lambda i: (i.due, i.seq))
            for it in waiting:
                if last.due <= it.due:
                    self._seq += 1
                    it.due, it.seq = last.due, self._seq
            queue.extend(waiting)
            waiting.clear()
        queue.sort(key=lambda i: (i.due, i.seq))

    def _release_held(self, now: float) -> None:
        for direction, waiting in self._held.items():
            due = [it for it in waiting if it.due <= now]
            if due:
                self._held[direction] = [it for it in waiting if it.due > now]
                queue = self._queues[direction]
                queue.extend(due)
                queue.sort(key=lambda i: (i.due, i.seq))

    def _pump(self, now: float) -> None:
        """Deliver every tx unit due by ``now``, back to back; then the line is silent."""
        self._release_held(now)
        queue = self._queues["tx"]
        sent = False
        while queue and queue[0].due <= now:
            item = queue.pop(0)
            self.delivering = item.tag
            try:
                self._deliver(item.data)
            finally:
                self.delivering = None
            sent = True
        if sent:
            self._after_group()

    def _take_in(self, timeout: float) -> None:
        for unit in self._pull(timeout):
            self._inject("rx", unit)

    def _next_due(self, now: float) -> float | None:
        """The earliest due time after ``now`` of a unit on the line (None: nothing in flight)."""
        dues = [it.due for q in self._queues.values() for it in q if it.due > now]
        dues += [it.due for w in self._held.values() for it in w if it.due > now]
        return min(dues) if dues else None

    def _send(self, unit: T) -> None:
        now = self.clock.now()
        self._pump(now)
        f = self.tx_faults
        if f.echo and self.rng.random() < f.echo:
            self._record("tx", "echo", unit)
            self._inject("rx", unit, timing=False)
        self._inject("tx", unit)
        self._pump(now)

    def _receive(self, timeout: float) -> T | None:
        clock = self.clock
        deadline = clock.now() + max(timeout, 0.0)
        while True:
            now = clock.now()
            self._pump(now)
            self._take_in(0.0)
            queue = self._queues["rx"]
            if queue and queue[0].due <= now:
                return queue.pop(0).data
            if now >= deadline:
                return None
            due = self._next_due(now)  # everything due by now went out above
            until = deadline if due is None else min(deadline, due)
            if self.advance is not None:
                self.advance(until - now)  # in process: nothing arrives before then
            else:
                self._take_in(until - now)

    @property
    def in_flight(self) -> int:
        """Units on the line not delivered yet (both directions, held ones included)."""
        return sum(len(q) for q in self._queues.values()) + sum(len(w) for w in self._held.values())

    def summary(self) -> str:
        parts = [f"{k} {v}" for k, v in sorted(self.counts.items())]
        return (f"tx {self.units['tx']} rx {self.units['rx']} units; faults: " + (", ".join(parts) or "none")
                + f" (seed {self.seed})")


class FaultyTransport(FaultyLine[bytes], ByteTransport):
    """A byte stream (loopback, serial port, pty) with faults (see the module docstring)."""

    def __init__(self, inner: ByteTransport, *, tx: Faults = NO_FAULTS, rx: Faults = NO_FAULTS, seed: int = 0,
                 clock: Clock, advance: Callable[[float], None] | None = None,
                 silence: Callable[[], bytes | None] | None = None, log_limit: int = 100_000) -> None:
        super().__init__(inner, tx=tx, rx=rx, seed=seed, clock=clock, advance=advance, log_limit=log_limit)
        self.on_silence = silence
        self.silence = inner.silence  # t3.5 of the line underneath

    @property
    def name(self) -> str:
        return f"faulty:{self.inner.name}"

    def write(self, data: bytes) -> None:
        self._send(bytes(data))

    def read(self, timeout: float) -> bytes:
        got = self._receive(timeout)
        return b"" if got is None else got

    def reset_input(self) -> None:
        now = self.clock.now()
        self._queues["rx"] = [it for it in self._queues["rx"] if it.due > now]
        self.inner.reset_input()

    def close(self) -> None:
        self.inner.close()

    # -- the engine's operations on bytes ----------------------------------------------------------
    def _deliver(self, unit: bytes) -> None:
        self.inner.write(unit)

    def _pull(self, timeout: float) -> list[bytes]:
        data = self.inner.read(timeout)
        return [data] if data else []

    def _after_group(self) -> None:
        if self.on_silence is None:
            return
        self._take_in(0.0)  # what the drives answered during the burst comes first
        answer = self.on_silence()
        if answer:
            self._inject("rx", bytes(answer))

    def _drop_part(self, unit: bytes, rng: random.Random) -> tuple[bytes | None, str]:
        n = len(unit)
        how = rng.randrange(3) if n > 1 else 0
        if how == 0:
            return None, "all"
        k = rng.randint(1, n - 1)
        if how == 1:
            return unit[:k], f"tail: {n - k} of {n} bytes"
        return unit[k:], f"head: {k} of {n} bytes"

    def _flip(self, unit: bytes, flips: int, rng: random.Random) -> tuple[bytes, str]:
        if not unit:
            return unit, "empty"
        out = bytearray(unit)
        bits = rng.sample(range(8 * len(out)), min(flips, 8 * len(out)))
        for bit in bits:
            out[bit // 8] ^= 1 << (bit % 8)
        return bytes(out), "bits " + ",".join(map(str, sorted(bits)))

    def _split(self, unit: bytes, rng: random.Random) -> list[bytes] | None:
        if len(unit) < 2:
            return None
        cuts = sorted(rng.sample(range(1, len(unit)), min(len(unit) - 1, rng.randint(1, 3))))
        return [unit[a:b] for a, b in zip([0, *cuts], [*cuts, len(unit)])]


class FaultyFrameTransport(FaultyLine[Any], FrameTransport):
    """A CAN frame transport with faults (no split: a CAN frame arrives whole or not at all)."""

    def __init__(self, inner: FrameTransport, *, tx: Faults = NO_FAULTS, rx: Faults = NO_FAULTS, seed: int = 0,
                 clock: Clock, advance: Callable[[float], None] | None = None, log_limit: int = 100_000) -> None:
        super().__init__(inner, tx=tx, rx=rx, seed=seed, clock=clock, advance=advance, log_limit=log_limit)

    @property
    def name(self) -> str:
        return f"faulty:{self.inner.name}"

    def send(self, frame: Any) -> None:
        self._send(frame)

    def recv(self, timeout: float) -> Any | None:
        return self._receive(timeout)

    def close(self) -> None:
        self.inner.close()

    def _deliver(self, unit: Any) -> None:
        self.inner.send(unit)

    def _pull(self, timeout: float) -> list[Any]:
        out = []
        frame = self.inner.recv(timeout)
        while frame is not None:
            out.append(frame)
            frame = self.inner.recv(0.0)
        return out

    def _drop_part(self, unit: Any, rng: random.Random) -> tuple[Any | None, str]:
        return None, "all"

    def _flip(self, unit: Any, flips: int, rng: random.Random) -> tuple[Any, str]:
        out = copy.copy(unit)
        data = bytearray(unit.data)
        if data:
            bits = rng.sample(range(8 * len(data)), min(flips, 8 * len(data)))
            for bit in bits:
                data[bit // 8] ^= 1 << (bit % 8)
            out.data = data
            return out, "data bits " + ",".join(map(str, sorted(bits)))
        bit = rng.randrange(11)
        out.arbitration_id = unit.arbitration_id ^ (1 << bit)
        return out, f"id bit {bit}"
