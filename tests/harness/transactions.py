"""Transactions under fault injection: driver access -> link -> faulty transport -> twin, judged by the twin.

A setup is one device family on one protocol, built by the registry as a rig would build it (the
protocol's link factory, the family's driver factory, its twin and front on the protocol's device
bus), with a :class:`~joints.transports.faulty.FaultyTransport` (or the CAN frame variant) between
the link and the twin. In process the line runs on an injected clock; ``pty`` serves a real world
with :func:`joints.sim.serve.serve` (the code behind ``joints sim serve``) in a thread and talks
to it over a pseudo-terminal on the wall clock.

Ground truth comes from the twin's firmware, wrapped: every value a read serves is recorded with
when it was served, and after each read every parameter the harness reads or writes takes a fresh,
unique value (as a moving drive's state would; a status value the firmware computes from its motion,
such as an MKS encoder count, is served from the harness's record instead), so a stale reply cannot
carry a current value; every write the firmware accepts is recorded. Host calls are the driver's parameter access: reads of one
parameter or a block, writes of one or a block, each write idempotent or not at random, each
written value unique.

Invariants per call:

* ``exception`` - only :class:`~joints.errors.JointsError` reaches the caller;
* ``hang`` - a call ends within its policy's bound on the line's clock (attempts x (timeout +
  late window), fences included), and within the harness's wall-clock limit;
* ``wrong-value`` - every value a read returns was served by the twin for that parameter;
* ``late-reply-accepted`` - ... and served after the call began (never a reply to an earlier request);
* ``write-lost-but-ok`` - a write that returned normally was executed by the twin;
* ``write-not-outcome-unknown`` - a write that ended without an intact answer (it timed out, or a
  corrupt or wrong frame came) raises :class:`~joints.errors.OutcomeUnknown`;
* ``retry-not-idempotent`` - a non-idempotent write is sent once, never retried;
* ``executed-twice`` - (end of run, after the line drained) no write executed more often than it
  was sent (attempts + duplicates the line injected);
* ``executed-invalid`` - the twin never executed a value nobody wrote (a corrupted frame).

Adding a setup is one :class:`Setup` entry in :data:`SETUPS`.
"""

from __future__ import annotations

import bisect
import functools
import random
import threading
import time
import zlib
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from harness.report import Report, Target
from harness.watchdog import Hang, watchdog
from joints import registry
from joints.clock import Clock, ManualClock, MonotonicClock
from joints.config import BusConfig, JointConfig
from joints.errors import DeviceRejected, JointsError, OutcomeUnknown, PeerProtocolError, ReplyTimeout
from joints.transports.faulty import Faults, FaultyFrameTransport, FaultyTransport

CALL_LIMIT = 10.0  #: wall-clock seconds a call may take before it counts as a hang


@dataclass(frozen=True)
class Setup:
    """One family on one protocol: the parameters the harness reads and writes."""

    family: str
    protocol: str
    pool: tuple[str, ...]  #: plain settings the harness writes (unique values), contiguous where the protocol has blocks
    reads: tuple[str, ...] = ()  #: what it reads (default: the pool)
    address: int = 2
    channels: tuple[str | None, ...] = (None,)
    model: str = ""  #: the MJCF model for the served (pty) world
    joints: tuple[str, ...] = ()  #: MJCF joints of the drive's channels, in order
    device: str = ""  #: the config device name (default: the family's first)
    lead: float | None = None  #: m per motor turn, for a drive on a slide joint (the served world)
    max_flips: int = 3  #: bits one corruption flips: what the protocol's frame check always detects
    nonnegative: bool = False  #: the protocol carries these values unsigned

    @property
    def name(self) -> str:
        return f"{self.family}/{self.protocol}"

    @property
    def read_names(self) -> tuple[str, ...]:
        return self.reads or self.pool


SETUPS: dict[str, Setup] = {s.name: s for s in (
    Setup("erob", "modbus-rtu", ("target_absolute_position", "target_relative_position", "profile_speed",
                                 "profile_acceleration", "profile_deceleration"),
          model="erob_stand.xml", joints=("joint1",)),
    Setup("zlac8015d", "modbus-rtu", ("acceleration_time_left", "acceleration_time_right",
                                      "deceleration_time_left", "deceleration_time_right"),
          address=1, channels=("left", "right"), model="zlac_diffdrive.xml", joints=("left_wheel", "right_wheel")),
    Setup("erob", "erob-can", ("target_absolute_position", "target_relative_position", "profile_speed",
                               "profile_acceleration", "profile_deceleration")),
    Setup("erob", "canopen", ("target_absolute_position", "profile_speed", "profile_acceleration",
                              "profile_deceleration"), nonnegative=True),
    # MKS settings cannot be read back (the drive reports status only): writes of settings, reads of status
    # (one pool parameter per command: a command re-sends its other fields with their last values)
    Setup("mks", "mks-serial", ("working_current", "home_speed", "home_reverse_angle"),
          reads=("encoder_carry", "real_time_speed", "number_of_pulses", "angle_error"), device="mks-servo42d",
          model="mks_linear_axis.xml", joints=("carriage",), lead=0.008, max_flips=1),
    Setup("mks", "modbus-rtu", ("working_current", "home_speed"),
          reads=("encoder_carry", "real_time_speed", "number_of_pulses", "angle_error"), device="mks-servo42d",
          model="mks_linear_axis.xml", joints=("carriage",), lead=0.008),
)}


def fault_profile(medium: str, rate: float, max_delay: float, echo: bool,
                  can_duplicates: bool = False, max_flips: int = 3) -> tuple[Faults, Faults]:
    """(tx, rx) faults: each unit faulted with probability ``rate``, by kinds the medium can suffer.

    A serial line loses, garbles, splits and delays bytes (and an adapter may echo); it never
    delivers a frame to a drive twice, so duplication is on the way back only. A CAN controller
    drops a frame whose CRC fails (no corruption reaches a node) and arbitrates frames of several
    nodes into any order. A CAN frame may also arrive twice (repeated after a lost acknowledge):
    towards the host that is harmless, but a request an eRob receives twice is answered twice, and
    the custom protocol's replies carry nothing that tells the second answer from the answer to the
    next request (joints/link/erob_can.py). That is the protocol's limit, not the link's, so
    requests are duplicated only when asked (``run.py --can-duplicates`` shows what it costs).

    Corruption flips at most ``max_flips`` bits of a frame: as many as its check is sure to catch
    (CRC-16 of Modbus RTU: 3; the checksum-8 of MKS native: 1 - two flipped top bits add 256 and
    pass it, so a garbled MKS reply can be taken as a valid one; ``run.py --flips`` shows it).
    """
    if medium == "can":
        tx_kinds = ("drop", "delay", "reorder", "duplicate") if can_duplicates else ("drop", "delay", "reorder")
        return (Faults.rate(rate, tx_kinds, max_delay=max_delay),
                Faults.rate(rate, ("drop", "duplicate", "delay", "reorder"), max_delay=max_delay))
    tx = Faults.rate(rate, ("drop", "corrupt", "split", "delay", "reorder"), max_delay=max_delay,
                     echo=1.0 if echo else 0.0, max_flips=max_flips)
    rx = Faults.rate(rate, ("drop", "corrupt", "split", "duplicate", "delay", "reorder"), max_delay=max_delay,
                     max_flips=max_flips)
    return tx, rx


# --- the twin's record --------------------------------------------------------------------------------


@dataclass
class Truth:
    """What the twin's firmware really did (filled by the wrappers in :meth:`install`)."""

    clock: Clock
    pool: tuple[str, ...]  #: written with unique values; take fresh values after every read
    ranges: dict[str, tuple[int, int]]  #: the values each pool and read parameter may take
    reads: tuple[str, ...] = ()  #: also recorded when served, and fresh after every read
    served: dict[tuple[str, int], float] = field(default_factory=dict)  #: (name, value) -> when served last
    #: when each (name, value) of a pool parameter was written by an accepted write (values recur over
    #: a long run: each execution belongs to the latest call that wrote that value before it)
    executed: dict[tuple[str, int], list[float]] = field(default_factory=dict)
    counter: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock)

    def fresh(self, name: str) -> int:
        """A value for ``name`` not used for a long time (unique per parameter across the run)."""
        self.counter += 1
        lo, hi = self.ranges[name]
        span = hi - lo + 1
        return lo + (self.counter * 7919 + zlib.crc32(name.encode())) % span

    def install(self, fw: Any) -> None:
        """Wrap ``fw`` (before its fronts make their readers): record what it serves and executes."""
        pool, served = set(self.pool), self.served
        watched_names = pool | set(self.reads)
        reader, write_many = fw.reader, fw.write_many
        #: read-only parameters: their values now (computed ones are served from here, not from the motion)
        status = {n: self.fresh(n) for n in self.reads if n not in pool}
        for n, v in status.items():
            if n in fw.computed:
                fw.computed[n] = functools.partial(status.__getitem__, n)
            else:
                fw.set(n, v)

        def wrapped_reader(names: Sequence[str]) -> Callable[[], list[int]]:
            read = reader(names)
            watched = [(i, n) for i, n in enumerate(names) if n in watched_names]

            def serve() -> list[int]:
                values: list[int] = read()
                if watched:
                    with self.lock:
                        now = self.clock.now()
                        for i, n in watched:
                            served[(n, values[i])] = now
                        for n in self.pool:  # the drive moves on: every value is new now
                            fw.set(n, self.fresh(n))
                        status.update({n: self.fresh(n) for n in status})
                        for n, v in status.items():
                            if n not in fw.computed:
                                fw.set(n, v)
                return values

            return serve

        def wrapped_write_many(items: Sequence[tuple[str, int]]) -> None:
            write_many(items)
            with self.lock:
                for n, v in items:
                    if n in pool:
                        self.executed.setdefault((n, v), []).append(self.clock.now())

        fw.reader = wrapped_reader
        fw.write_many = wrapped_write_many


# --- one setup, running ----------------------------------------------------------------------------------


@dataclass
class Bench:
    setup: Setup
    access: Any
    link: Any
    line: FaultyTransport | FaultyFrameTransport
    clock: Clock
    truth: Truth
    policy_bound: float
    close: Callable[[], None] = lambda: None
    settle: Callable[[], None] = lambda: None  #: let everything in flight arrive


def _family(setup: Setup) -> Any:
    return registry.FAMILIES[setup.family]


def _drive_configs(setup: Setup, bus: str) -> list[JointConfig]:
    family = _family(setup)
    return [JointConfig(name=f"{setup.family}{ch or ''}", device=setup.device or family.devices[0], bus=bus,
                        address=setup.address, channel=ch) for ch in setup.channels]


def _ranges(setup: Setup, params: Any = None) -> dict[str, tuple[int, int]]:
    """Values the harness writes and serves: in each parameter's range (the driver's own set: a model may narrow
    it)."""
    params = params or _family(setup).params()
    out = {}
    for name in dict.fromkeys((*setup.pool, *setup.read_names)):
        p = params[name]
        lo, hi = p.type_range
        lo = lo if p.minimum is None else max(lo, p.minimum)
        hi = hi if p.maximum is None else min(hi, p.maximum)
        out[name] = (max(lo, 0 if setup.nonnegative else -(1 << 30)), min(hi, 1 << 30))
    return out


def _bound(cfg: BusConfig, faults: tuple[Faults, Faults]) -> float:
    """The longest a call may take: every attempt (and an eRob CAN fence before it) times out and
    waits out its late window (RetryPolicy.late defaults to the timeout), plus the line's delays."""
    late = cfg.timeout
    return 2 * (cfg.retries + 1) * (cfg.timeout + late) + 2 * sum(f.max_delay for f in faults) + 0.05


def in_process(setup: Setup, seed: int, rate: float, *, echo: bool = False, timeout: float = 0.05,
               retries: int = 2, max_delay: float | None = None, can_duplicates: bool = False,
               flips: int | None = None) -> Bench:
    """The setup on an in-process device bus, the line on an injected clock."""
    family = _family(setup)
    proto = registry.protocol(setup.protocol)
    clock = ManualClock(1000.0)
    cfg = BusConfig(name="bus", protocol=setup.protocol, timeout=timeout, retries=retries, echo=echo)
    device_bus = proto.device_bus(cfg)
    if hasattr(device_bus, "bind_clock"):
        device_bus.bind_clock(clock)
    specs = [_spec(setup, family, c) for c in _drive_configs(setup, "bus")]
    twin, _steppers = family.build_twin(specs, {s.name: 0.01 for s in specs})
    device_bus.add(family.front(setup.protocol, twin, setup.address))
    truth = Truth(clock, setup.pool, _ranges(setup), setup.read_names)
    truth.install(twin)
    if hasattr(device_bus, "tick"):
        device_bus.tick(clock.now())  # the drives boot (a CANopen node sends its boot-up, then answers)
    faults = fault_profile(proto.medium, rate, 0.95 * timeout if max_delay is None else max_delay, echo,
                           can_duplicates, flips or setup.max_flips)
    inner = proto.sim_transport(device_bus)
    line: FaultyTransport | FaultyFrameTransport
    if proto.medium == "can":  # the lockstep CAN bus lets time pass on the clock it is bound to
        line = FaultyFrameTransport(inner, tx=faults[0], rx=faults[1], seed=seed, clock=clock)
    else:
        line = FaultyTransport(inner, tx=faults[0], rx=faults[1], seed=seed, clock=clock, advance=clock.advance,
                               silence=getattr(device_bus, "silence", None))
    link = proto.link(cfg, line, clock, None)
    shared: dict[Any, Any] = {}
    access = family.driver(_drive_configs(setup, "bus")[0], link, clock, shared, setup.protocol).access
    truth.ranges.update(_ranges(setup, access.params))

    def settle() -> None:
        wait = line.read if isinstance(line, FaultyTransport) else line.recv
        for _ in range(100):
            wait(0.5)  # the line delivers what is in flight (a late frame still reaches the twin)
            if not line.in_flight:
                break

    return Bench(setup, access, link, line, clock, truth, _bound(cfg, faults), close=line.close, settle=settle)


def _spec(setup: Setup, family: Any, cfg: JointConfig, mjcf: str = "j") -> Any:
    from joints.sim.world import DriveSpec

    return DriveSpec(bus=cfg.bus, name=cfg.name, mjcf_joint=mjcf, address=cfg.address, profile=family.config_profile(cfg),
                     device=cfg.device, maker=family, protocol=setup.protocol, channel=cfg.channel, lead=setup.lead)


def served(setup: Setup, seed: int, rate: float, *, echo: bool = False, timeout: float = 0.1, retries: int = 2,
           max_delay: float | None = None, can_duplicates: bool = False, flips: int | None = None) -> Bench:
    """The setup in a real world served on a pty (``joints sim serve``'s loop, in a thread), on the wall clock."""
    from joints.sim.serve import serve
    from joints.sim.world import BusSpec, World
    from joints.transports.serial import SerialTransport

    if registry.protocol(setup.protocol).medium != "serial" or not setup.model:
        raise ValueError(f"{setup.name} cannot be served on a pty")
    family = _family(setup)
    proto = registry.protocol(setup.protocol)
    cfgs = _drive_configs(setup, "rs485")
    specs = [_spec(setup, family, c, mjcf) for c, mjcf in zip(cfgs, setup.joints)]
    bus_cfg = BusConfig(name="rs485", protocol=setup.protocol)
    world = World(setup.model, specs, buses={"rs485": BusSpec("rs485", setup.protocol,
                                                              lambda: proto.device_bus(bus_cfg), proto.sim_transport)})
    clock = MonotonicClock()
    truth = Truth(clock, setup.pool, _ranges(setup), setup.read_names)
    truth.install(world.drives[specs[0].name])
    stop = threading.Event()
    ready: dict[str, Any] = {}
    started = threading.Event()

    def on_ready(ports: dict[str, Any]) -> None:
        ready.update(ports)
        started.set()

    thread = threading.Thread(target=serve, args=(world, ["rs485"]), daemon=True,
                              kwargs={"stop": stop, "on_ready": on_ready, "install_signals": False})
    thread.start()
    if not started.wait(30):
        raise RuntimeError("the served world did not start")
    port = ready["rs485"]
    port = port["port"] if isinstance(port, dict) else port
    cfg = BusConfig(name="rs485", protocol=setup.protocol, port=port, timeout=timeout, retries=retries, echo=echo)
    faults = fault_profile(proto.medium, rate, 0.95 * timeout if max_delay is None else max_delay, echo,
                           max_flips=flips or setup.max_flips)
    line = FaultyTransport(SerialTransport(port, 115200), tx=faults[0], rx=faults[1], seed=seed, clock=clock)
    link = proto.link(cfg, line, clock, None)
    access = family.driver(cfgs[0], link, clock, {}, setup.protocol).access
    truth.ranges.update(_ranges(setup, access.params))

    def close() -> None:
        stop.set()
        thread.join(10)
        line.close()

    def settle() -> None:
        end = time.monotonic() + 2.0
        while time.monotonic() < end and (line.in_flight or time.monotonic() < end - 1.5):
            line.read(0.05)

    return Bench(setup, access, link, line, clock, truth, _bound(cfg, faults), close=close, settle=settle)


# --- the calls ----------------------------------------------------------------------------------------------


@dataclass
class Call:
    number: int
    kind: str  #: "read", "read-block", "write", "write-block"
    items: dict[str, int]  #: written values
    idempotent: bool
    retries: int = 0
    outcome: str = ""
    start: float = 0.0  #: on the line's clock


def run_bench(bench: Bench, t: Target, count: int, rng: random.Random) -> None:
    setup, access, link, line, clock, truth = bench.setup, bench.access, bench.link, bench.line, bench.clock, bench.truth
    pool, reads = setup.pool, setup.read_names
    calls: list[Call] = []
    for number in range(count):
        line.tag = number
        kind = rng.choice(("read", "read", "read-block", "write", "write", "write-block"))
        idempotent = rng.random() < 0.5
        if kind == "read":
            names: tuple[str, ...] = (rng.choice(reads),)
        elif kind == "read-block":
            names = reads
        else:
            chosen = pool if kind == "write-block" else (rng.choice(pool),)
            with truth.lock:
                items = {n: truth.fresh(n) for n in chosen}
        call = Call(number, kind, items if kind.startswith("write") else {}, idempotent)
        retries0 = link.retries_used
        start = call.start = clock.now()
        wall = time.monotonic()
        result: dict[str, int] | None = None
        error: BaseException | None = None
        try:
            with watchdog(CALL_LIMIT):
                if kind == "read":
                    result = {names[0]: access.read(names[0])}
                elif kind == "read-block":
                    result = access.read_many(list(names))
                elif kind == "write":
                    (n, v), = call.items.items()
                    access.write(n, v, idempotent=idempotent)
                else:
                    access.write_many(call.items, idempotent=idempotent)
        except Hang:
            t.violate("hang", f"call {number} ({kind}) ran over {CALL_LIMIT} s of wall clock (seed {line.seed})")
            continue
        except JointsError as exc:
            error = exc
        except Exception as exc:  # noqa: BLE001 - reported as a violation
            t.violate("exception", f"call {number} ({kind}): {exc!r}")
            continue
        t.units += 1
        t.passed("exception")
        elapsed = clock.now() - start
        if not t.check("hang", elapsed <= bench.policy_bound and time.monotonic() - wall < CALL_LIMIT):
            t.example("hang", f"call {number} ({kind}) took {elapsed:.3f} s > {bench.policy_bound:.3f} s")
        call.retries = link.retries_used - retries0
        call.outcome = "ok" if error is None else type(error).__name__
        t.notes[f"{kind} {call.outcome}"] += 1
        if kind.startswith("read"):
            if result is not None:
                _judge_read(t, truth, number, result, start)
            continue
        calls.append(call)
        if not idempotent and not t.check("retry-not-idempotent", call.retries == 0):
            t.example("retry-not-idempotent", f"call {number}: {call.items} sent {1 + call.retries}x")
        no_answer = isinstance(error, (ReplyTimeout, PeerProtocolError))  # none, corrupt, or not its answer
        if no_answer and not t.check("write-not-outcome-unknown", isinstance(error, OutcomeUnknown)):
            t.example("write-not-outcome-unknown", f"call {number}: {error!r}")
        if error is None:
            with truth.lock:
                missing = [k for k in call.items.items() if not any(w >= start for w in truth.executed.get(k, ()))]
            if not t.check("write-lost-but-ok", not missing):
                t.example("write-lost-but-ok", f"call {number}: {missing} reported written, never executed")
        elif isinstance(error, DeviceRejected):
            t.notes["write refused by the drive"] += 1
    bench.settle()
    _judge_executions(t, bench, calls)


def _judge_read(t: Target, truth: Truth, number: int, result: dict[str, int], start: float) -> None:
    with truth.lock:
        for name, value in result.items():
            if name not in truth.ranges and name not in truth.reads:
                continue
            when = truth.served.get((name, value))
            if not t.check("wrong-value", when is not None):
                t.example("wrong-value", f"call {number}: {name} = {value} was never served")
                continue
            assert when is not None
            if not t.check("late-reply-accepted", when >= start):
                t.example("late-reply-accepted", f"call {number}: {name} = {value} was served {start - when:.4f} s "
                                                 "before the call began")


def _judge_executions(t: Target, bench: Bench, calls: list[Call]) -> None:
    """Every execution of a written value belongs to the latest call that wrote it before; none to nobody."""
    truth, line = bench.truth, bench.line
    duplicated: Counter[object] = Counter(r.tag for r in line.log if r.direction == "tx" and r.kind == "duplicate")
    writers: dict[tuple[str, int], list[Call]] = {}
    for call in calls:
        for item in call.items.items():
            writers.setdefault(item, []).append(call)
    counts: Counter[tuple[int, tuple[str, int]]] = Counter()
    invalid: list[tuple[str, int]] = []
    with truth.lock:
        executed = {k: list(v) for k, v in truth.executed.items()}
    for item, times in executed.items():
        starts = sorted((c.start, c.number) for c in writers.get(item, ()))
        for when in times:
            owner = bisect.bisect_right(starts, (when, float("inf"))) - 1
            if owner < 0:
                invalid.append(item)
            else:
                counts[(starts[owner][1], item)] += 1
    for call in calls:
        allowed = (1 + call.retries) * (1 + duplicated[call.number])
        for item in call.items.items():
            n = counts[(call.number, item)]
            if not t.check("executed-twice", n <= allowed):
                t.example("executed-twice", f"call {call.number}: {item} executed {n}x, sent at most {allowed}x "
                                            f"({'' if call.idempotent else 'not '}idempotent, {call.outcome})")
    if not t.check("executed-invalid", not invalid):
        t.example("executed-invalid", f"executed before anybody wrote it: {invalid[:5]}")


@contextmanager
def _bench(make: Callable[..., Bench], *args: Any, **kwargs: Any) -> Iterator[Bench]:
    bench = make(*args, **kwargs)
    try:
        yield bench
    finally:
        bench.close()


def run(report: Report, names: Sequence[str], count: int, seed: int, *, rate: float = 0.1, pty: bool = False,
        echo: bool = False, can_duplicates: bool = False, flips: int | None = None) -> None:
    for name in names:
        setup = SETUPS[name]
        if (pty or echo) and registry.protocol(setup.protocol).medium != "serial":
            continue
        if pty and not setup.model:
            report.uncovered.append(f"transactions {name}: no served world (Setup.model) for a pty run")
            continue
        if can_duplicates and registry.protocol(setup.protocol).medium != "can":
            continue
        mode = ("pty" if pty else "in process") + (", adapter echo" if echo else "") + (
            ", requests duplicated" if can_duplicates else "") + (f", {flips}-bit corruption" if flips else "")
        t = report.target(f"transactions {name} ({mode})", "transactions", "calls")
        rng = random.Random(f"{seed}/transactions/{name}/{pty}/{echo}")
        maker = served if pty else in_process
        with report.timed(t), _bench(maker, setup, seed, rate, echo=echo, can_duplicates=can_duplicates,
                                     flips=flips) as bench:
            run_bench(bench, t, count, rng)
            t.notes[f"line: {bench.line.summary()}"] += 1
            t.notes["link retries"] += bench.link.retries_used
            t.notes["late replies discarded"] += bench.link.late_discarded
