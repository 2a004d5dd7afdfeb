"""Record a run's bus frames; replay them against fresh twins and diff the replies and the motion.

Rule: a recording is what crossed each bus's transport, with the rig's clock time of each frame -
nothing decoded, nothing dropped - plus the configuration the run used, so a fresh process can
build the same twins from the recording alone. Replay sends the recorded host frames to the
twins at their recorded times (lockstep: the world is advanced to each frame's time) and compares
what comes back, exchange by exchange, frame by frame and quantity by quantity.

Recording format (documented for users and other tools)

* ``NAME.jsonl`` - JSON lines. Line 1 is the header::

      {"joints_recording": 1, "clock": "sim" | "wall", "origin": <clock time of the twins' t = 0>,
       "config": {...the configuration as a joints config table...}, "source": "<config file>",
       "buses": {"<bus>": {"protocol": "...", "medium": "serial" | "can", "log": "<CAN log file>"}}}

  then one line per serial transfer, in order::

      {"t": 12.345678, "bus": "rs485", "dir": "tx" | "rx", "data": "02 03 00 60 00 19 .."}

  ``tx`` lines are whole frames as the host wrote them; ``rx`` lines are what the port returned
  in one read (a reply may span several). ``t`` is seconds on the rig's clock (simulated time in
  sim; ``time.monotonic()`` on hardware, ``origin`` = when the recording started).
* ``NAME.<bus>.log`` - each CAN bus in python-can's canutils log format (``(t) channel ID#DATA T|R``,
  T = sent by the host), readable by ``can.LogReader`` and the can-utils; any python-can log
  format (``.asc``, ``.blf``) is read back as well when the header names it.

Replay groups each bus's received frames by the host frame they follow (an *exchange*: a request
and what came back before the next request on that bus) and reports, per exchange that differs,
the quantities that differ (Modbus: the register names of the family's table, e.g.
``actual_position``; other protocols: the bytes of each frame) and per quantity how often and by
how much. A recording of a lockstep sim run replays with no difference against the same twins;
against perturbed twins the physics shows in the status replies.

Limits: the twins start at the model's initial state and at power-on, so a run recorded after the
rig had moved (or reset/placed its sim joints) replays from a different start; the recording
carries no record of ``rig.sim`` calls (perturbations, placements).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import asdict, dataclass, field, fields, is_dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

from joints import registry
from joints.config import RigConfig, parse
from joints.errors import ConfigError
from joints.link.base import DirectFraming

__all__ = [
    "Frame",
    "Recorder",
    "Recording",
    "ReplayReport",
    "config_table",
    "load",
    "record",
    "replay",
]

FORMAT = 1


@dataclass(frozen=True, slots=True)
class Frame:
    """One transfer on a bus: serial bytes (``can_id`` None) or one CAN frame."""

    t: float
    bus: str
    direction: str  #: "tx" (the host sent it) or "rx"
    data: bytes
    can_id: int | None = None
    extended: bool = False

    def key(self) -> tuple[Any, ...]:
        return (self.can_id, self.extended, self.data)

    def text(self) -> str:
        body = self.data.hex(" ").upper()
        return body if self.can_id is None else f"{self.can_id:03X}#{body}"


# -- configuration as a table -----------------------------------------------------------------------


def _clean(value: Any) -> Any:
    if is_dataclass(value) and not isinstance(value, type):
        return {k: _clean(v) for k, v in asdict(value).items() if v is not None}
    if isinstance(value, Mapping):
        return {str(k): _clean(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    return value


def config_table(cfg: RigConfig, model_path: str | None = None) -> dict[str, Any]:
    """``cfg`` as a config table that :func:`joints.config.parse` reads back to the same rig
    (profile overlays already merged into ``profile``; the model by absolute path when given)."""
    buses = {}
    for name, b in cfg.buses.items():
        d = {f.name: getattr(b, f.name) for f in fields(b) if f.name != "name"}
        buses[name] = {k: v for k, v in d.items() if v is not None}
    joints_ = {}
    for name, j in cfg.joints.items():
        d = {f.name: getattr(j, f.name) for f in fields(j) if f.name not in ("name", "profile_overlay")}
        d["limits"] = _clean(j.limits)
        d["motion"] = _clean(j.motion)
        d["profile"] = dict(j.profile)
        joints_[name] = {k: _clean(v) for k, v in d.items() if v is not None and v != {}}
    sim = _clean(cfg.sim)
    if model_path is not None:
        sim["model"] = model_path
    return {"backend": cfg.backend if cfg.backend != "mixed" else "hardware", "on_exit": cfg.on_exit,
            "sim": sim, "buses": buses, "joints": joints_}


# -- recording ----------------------------------------------------------------------------------------


class _Tap:
    """Wraps one bus's transport: every transfer goes to the recorder, then on (attributes pass through)."""

    def __init__(self, inner: Any, bus: str, sink: Callable[[Frame], None], now: Callable[[], float]) -> None:
        self.inner = inner
        self._bus = bus
        self._sink = sink
        self._now = now

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    # byte streams
    def write(self, data: bytes) -> None:
        self._sink(Frame(self._now(), self._bus, "tx", bytes(data)))
        self.inner.write(data)

    def read(self, timeout: float) -> bytes:
        data: bytes = self.inner.read(timeout)
        if data:
            self._sink(Frame(self._now(), self._bus, "rx", bytes(data)))
        return data

    # CAN frames
    def send(self, frame: Any) -> None:
        self._sink(Frame(self._now(), self._bus, "tx", bytes(frame.data), int(frame.arbitration_id),
                         bool(frame.is_extended_id)))
        self.inner.send(frame)

    def recv(self, timeout: float) -> Any:
        frame = self.inner.recv(timeout)
        if frame is not None:
            self._sink(Frame(self._now(), self._bus, "rx", bytes(frame.data), int(frame.arbitration_id),
                             bool(frame.is_extended_id)))
        return frame

    def close(self) -> None:
        self.inner.close()


class Recorder:
    """Records every frame of every bus of ``rig`` into ``path`` (see the module docstring).

    Attach before the run (``with record(rig, "run.jsonl"):``); :meth:`close` detaches and writes.
    The sim's direct path carries no frames: record a sim rig with ``[sim] direct = false``.
    """

    def __init__(self, rig: Any, path: str | Path, *, can_format: str = ".log") -> None:
        self.rig = rig
        self.path = Path(path)
        self.frames: list[Frame] = []
        self.can_format = can_format
        cfg: RigConfig = rig.config
        sim = rig.backend == "sim"
        self.clock = "sim" if sim else "wall"
        self.origin = 0.0 if sim else float(rig.clock.now())
        self._taps: list[tuple[Any, Any, Any]] = []
        for name, bus in rig.buses.items():
            framing = bus.link.framing
            if isinstance(framing, DirectFraming):
                raise ConfigError(f"bus {name!r} takes the sim's direct path, which carries no frames: set "
                                  "[sim] direct = false to record", file=cfg.source, key="sim.direct")
            tap = _Tap(bus.transport, name, self.frames.append, rig.clock.now)
            self._taps.append((bus, framing, bus.transport))
            bus.transport = tap
            framing.transport = tap
        model = str(rig.model_path()) if cfg.sim.model else None
        self.header: dict[str, Any] = {
            "joints_recording": FORMAT, "clock": self.clock, "origin": self.origin,
            "config": config_table(cfg, model), "source": cfg.source, "buses": {},
        }
        for name, b in cfg.buses.items():
            medium = registry.protocol(b.protocol).medium
            entry: dict[str, Any] = {"protocol": b.protocol, "medium": medium}
            if medium == "can":
                entry["log"] = f"{self.path.stem}.{name}{can_format}"
            self.header["buses"][name] = entry
        self.closed = False

    def close(self) -> Path:
        """Detach from the buses and write the recording; returns the JSON-lines file."""
        if self.closed:
            return self.path
        for bus, framing, inner in self._taps:
            bus.transport = inner
            framing.transport = inner
        self.closed = True
        with self.path.open("w", encoding="utf-8") as fh:
            fh.write(json.dumps(self.header) + "\n")
            for f in self.frames:
                if f.can_id is None:
                    fh.write(json.dumps({"t": f.t, "bus": f.bus, "dir": f.direction,
                                         "data": f.data.hex(" ").upper()}) + "\n")
        for name, entry in self.header["buses"].items():
            if entry["medium"] == "can":
                _write_can_log(self.path.parent / entry["log"], [f for f in self.frames if f.bus == name], name)
        return self.path

    def __enter__(self) -> Recorder:  # noqa: PYI034 - typing.Self needs Python 3.11
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


def record(rig: Any, path: str | Path, *, can_format: str = ".log") -> Recorder:
    """Start recording ``rig``'s buses into ``path`` (a context manager; see :class:`Recorder`)."""
    return Recorder(rig, path, can_format=can_format)


def _write_can_log(path: Path, frames: Iterable[Frame], channel: str) -> None:
    import can

    with can.Logger(str(path)) as logger:
        for f in frames:
            logger.on_message_received(can.Message(
                timestamp=f.t, arbitration_id=f.can_id or 0, is_extended_id=f.extended, data=f.data,
                is_rx=f.direction == "rx", channel=channel))


# -- reading ------------------------------------------------------------------------------------------


@dataclass
class Recording:
    """A recording read back: its header and every frame in time order."""

    header: dict[str, Any]
    frames: list[Frame]
    path: Path

    @property
    def config(self) -> RigConfig:
        """The recorded configuration, for twins (every bus simulated)."""
        return parse(self.header["config"], source=f"{self.path} (recorded config)", backend="sim")


def load(path: str | Path) -> Recording:
    """Read a recording (the JSON-lines file and the CAN logs its header names)."""
    p = Path(path)
    try:
        lines = p.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise ConfigError(f"cannot read the recording: {exc}", file=str(p)) from exc
    try:
        header = json.loads(lines[0]) if lines else {}
    except json.JSONDecodeError as exc:
        raise ConfigError(f"not a joints recording (line 1: {exc})", file=str(p)) from exc
    if header.get("joints_recording") != FORMAT:
        raise ConfigError("not a joints recording (line 1 has no \"joints_recording\": 1 header)", file=str(p))
    frames: list[Frame] = []
    for n, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        try:
            d = json.loads(line)
            frames.append(Frame(float(d["t"]), str(d["bus"]), str(d["dir"]), bytes.fromhex(d["data"])))
        except (json.JSONDecodeError, KeyError, ValueError, TypeError) as exc:
            raise ConfigError(f"line {n}: not a frame record ({exc})", file=str(p)) from exc
    for name, entry in header.get("buses", {}).items():
        if entry.get("medium") == "can" and entry.get("log"):
            frames.extend(_read_can_log(p.parent / entry["log"], name))
    order = {id(f): i for i, f in enumerate(frames)}
    frames.sort(key=lambda f: (f.t, order[id(f)]))
    return Recording(header, frames, p)


def _read_can_log(path: Path, bus: str) -> list[Frame]:
    import can

    if not path.is_file():
        raise ConfigError(f"the CAN log of bus {bus!r} is missing: {path}", file=str(path))
    out = []
    for m in can.LogReader(str(path)):
        if m.is_error_frame:
            continue
        out.append(Frame(float(m.timestamp), bus, "rx" if m.is_rx else "tx", bytes(m.data), int(m.arbitration_id),
                         bool(m.is_extended_id)))
    return out


# -- replay -------------------------------------------------------------------------------------------


@dataclass
class Exchange:
    """A host frame and the frames its bus returned before the bus's next host frame."""

    index: int  #: the host frame's number in the recording (0 = first)
    t: float
    bus: str
    request: Frame
    recorded: list[Frame] = field(default_factory=list)
    replayed: list[Frame] = field(default_factory=list)


@dataclass(frozen=True)
class Difference:
    """One exchange whose replies differ."""

    index: int
    t: float
    bus: str
    request: str
    recorded: str
    replayed: str
    quantities: Mapping[str, tuple[Any, Any]]  #: quantity -> (recorded, replayed)


@dataclass
class ReplayReport:
    """What a replay found: per exchange, per quantity."""

    exchanges: int
    differences: list[Difference]
    perturbations: Mapping[str, Mapping[str, float]] = field(default_factory=dict)

    @property
    def identical(self) -> bool:
        return not self.differences

    def by_quantity(self) -> dict[str, dict[str, float]]:
        """quantity -> {"frames": how many exchanges differ in it, "max_abs": the largest difference}."""
        out: dict[str, dict[str, float]] = {}
        for d in self.differences:
            for q, (a, b) in d.quantities.items():
                s = out.setdefault(q, {"frames": 0, "max_abs": 0.0})
                s["frames"] += 1
                if isinstance(a, (int, float)) and isinstance(b, (int, float)):
                    s["max_abs"] = max(s["max_abs"], abs(float(a) - float(b)))
                else:
                    s["max_abs"] = math.inf
        return dict(sorted(out.items()))

    def summary(self) -> dict[str, Any]:
        return {"exchanges": self.exchanges, "differing": len(self.differences), "identical": self.identical,
                "perturbations": {k: dict(v) for k, v in self.perturbations.items()},
                "by_quantity": self.by_quantity()}

    def to_json(self, *, limit: int | None = None) -> dict[str, Any]:
        diffs = self.differences if limit is None else self.differences[:limit]
        return {**self.summary(), "differences": [
            {"index": d.index, "t": d.t, "bus": d.bus, "request": d.request, "recorded": d.recorded,
             "replayed": d.replayed, "quantities": {k: list(v) for k, v in d.quantities.items()}} for d in diffs]}

    def __str__(self) -> str:
        lines = [f"{self.exchanges} exchanges replayed, {len(self.differences)} differ"]
        for q, s in self.by_quantity().items():
            lines.append(f"  {q:<48} {int(s['frames']):6d} frames  max |diff| {s['max_abs']:.6g}")
        return "\n".join(lines)


def _quantities(protocol: str, bus_joints: Mapping[int, tuple[str, Any]], request: Frame, frames: list[Frame]) -> dict[str, Any]:
    """The quantities the replies of one exchange carry, by name where the protocol allows, else by byte."""
    values = registry.protocol(protocol).values
    named = values(bus_joints, request, frames) if values is not None else None
    if named is not None:
        return named
    out: dict[str, Any] = {}
    for n, fr in enumerate(frames):
        where = f"{fr.can_id:03X}" if fr.can_id is not None else f"rx{n}"
        for i, b in enumerate(fr.data):
            out[f"{where}[{i}]"] = b
        out[f"{where}.len"] = len(fr.data)
    return out


def _tables(cfg: RigConfig, bus: str) -> dict[int, tuple[str, Any]]:
    """Bus address -> (its joint, its device family's parameter map on the bus's protocol), for naming quantities."""
    out: dict[int, tuple[str, Any]] = {}
    protocol = cfg.buses[bus].protocol
    for name, j in cfg.joints.items():
        if j.bus != bus:
            continue
        make = registry.family(j.device).tables.get(protocol)
        out[j.address] = (name if j.channel is None else f"{name}@{j.address}", make() if make is not None else None)
    return out


def replay(recording: Recording | str | Path, *, perturb: Mapping[str, Mapping[str, float]] | None = None,
           progress: Callable[[float], None] | None = None) -> ReplayReport:
    """Send the recorded host frames to fresh twins of the recorded configuration; diff what comes back.

    ``perturb``: joint -> keyword arguments of :meth:`joints.sim.world.World.perturb` (factors, and
    ``command_delay`` in s), applied to the fresh twins before the first frame.
    """
    from joints.rig import sim_world

    rec = recording if isinstance(recording, Recording) else load(recording)
    cfg = rec.config
    world = sim_world(cfg)
    for name, kw in (perturb or {}).items():
        world.perturb(name, **dict(kw))
    origin = float(rec.header.get("origin", 0.0))
    # untimed transports: each recorded frame reaches the twins at its recorded time (the wire's time is in it)
    transports = {name: registry.protocol(b.protocol).sim_transport(world.buses[name]) for name, b in cfg.buses.items()}
    for name, t in transports.items():
        if hasattr(t, "echo"):
            t.echo = cfg.buses[name].echo
    medium = {name: registry.protocol(b.protocol).medium for name, b in cfg.buses.items()}
    exchanges: list[Exchange] = []
    last: dict[str, Exchange] = {}
    for f in rec.frames:  # the recorded replies, grouped by the host frame they follow
        if f.direction == "tx":
            ex = Exchange(len(exchanges), f.t, f.bus, f)
            exchanges.append(ex)
            last[f.bus] = ex
        elif f.bus in last:
            last[f.bus].recorded.append(f)
    current: dict[str, Exchange] = {}
    dt = world.timestep

    def collect(until: float) -> None:
        """Let simulated time reach ``until`` (as the host's sleeps did); what arrived meanwhile
        belongs to each bus's open exchange."""
        steps = math.ceil((until - world.time) / dt - 1e-6)
        if steps > 0:
            world.advance(steps * dt)
        for name, t in transports.items():
            if medium[name] == "can":
                while (frame := t.recv(0.0)) is not None:
                    _take(name, frame)
            else:
                data = t.read(0.0)
                if data:
                    _take(name, data)

    def _take(bus: str, got: Any) -> None:
        ex = current.get(bus)
        if ex is None:
            return
        if isinstance(got, bytes):
            ex.replayed.append(Frame(world.time, bus, "rx", got))
        else:
            ex.replayed.append(Frame(world.time, bus, "rx", bytes(got.data), int(got.arbitration_id),
                                     bool(got.is_extended_id)))

    n = len(exchanges)
    for i, ex in enumerate(exchanges):
        collect(ex.t - origin)
        f = ex.request
        current[ex.bus] = ex
        t = transports[ex.bus]
        if f.can_id is None:
            t.write(f.data)
        else:
            import can

            t.send(can.Message(arbitration_id=f.can_id, is_extended_id=f.extended, data=f.data))
            # the host waited for what came back (a CAN reply takes wire time): wait as it did
            for _ in ex.recorded:
                got = t.recv(cfg.buses[ex.bus].timeout)
                if got is None:
                    break
                _take(ex.bus, got)
        if progress is not None and i % 1000 == 0:
            progress(i / max(n, 1))
    if rec.frames:
        collect(rec.frames[-1].t - origin + dt)
    for t in transports.values():
        t.close()
    diffs: list[Difference] = []
    tables = {name: _tables(cfg, name) for name in cfg.buses}
    for ex in exchanges:
        a = [f.key() for f in ex.recorded]
        b = [f.key() for f in ex.replayed]
        if medium[ex.bus] != "can":  # a byte stream: chunking is the port's business, compare the bytes
            a = [b"".join(f.data for f in ex.recorded)]  # type: ignore[list-item]
            b = [b"".join(f.data for f in ex.replayed)]  # type: ignore[list-item]
        if a == b:
            continue
        protocol = cfg.buses[ex.bus].protocol
        qa = _quantities(protocol, tables[ex.bus], ex.request, ex.recorded)
        qb = _quantities(protocol, tables[ex.bus], ex.request, ex.replayed)
        changed = {k: (qa.get(k), qb.get(k)) for k in sorted(set(qa) | set(qb)) if qa.get(k) != qb.get(k)}
        diffs.append(Difference(ex.index, ex.t, ex.bus, ex.request.text(),
                                " | ".join(f.text() for f in ex.recorded) if medium[ex.bus] == "can"
                                else b"".join(f.data for f in ex.recorded).hex(" ").upper(),
                                " | ".join(f.text() for f in ex.replayed) if medium[ex.bus] == "can"
                                else b"".join(f.data for f in ex.replayed).hex(" ").upper(),
                                changed))
    return ReplayReport(len(exchanges), diffs, dict(perturb or {}))
