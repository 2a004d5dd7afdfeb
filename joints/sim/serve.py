"""Serve a simulated world in real time: each serial bus on a pseudo-terminal, each CAN bus on a python-can channel.

Rule: the world runs on the wall clock here (and only here); the emulated drives answer whatever
arrives between physics substeps, exactly as in process. A request is executed and answered as
soon as it is read, and the ports are read after at most :data:`SERVICE_PERIOD` of physics, so
no request waits behind a simulation that runs slower than real time. Serial buses (Modbus RTU,
MKS native) are pseudo-terminals; frames the drives send by themselves (MKS completion frames: an
:class:`~joints.transports.loopback.UnsolicitedPeer`) go out as soon as the physics produced them.
CAN buses are python-can channels another process can open
(:mod:`joints.sim.can_serve`: udp_multicast by default, a vcan device where the config names one;
never a real bus). Stops cleanly on SIGINT/SIGTERM or when ``stop`` is set.

Timing (``timing``: bus name -> :class:`~joints.sim.served_timing.BusTiming`, which ``joints sim
serve`` builds from the config): a request is held until the real bus would have carried it and
the drive turned around, executed then on the world's clock (the rule of the in-process line: it
acts on the world of the physics substep that ends at or after its instant, so a command takes
effect and a state is sampled at the same substep as in process), and its reply leaves the pty (or
goes onto the CAN channel) when the real bus and the host's adapter would have delivered it
(:mod:`joints.sim.served_timing`): the loop sleeps until :data:`SPIN` s before that instant and
waits out the rest awake, so the OS's timer slack does not make it late. A bus without an entry
(or ``timing = "ideal"``) is answered as soon as the request is read.

Options: ``realtime_factor`` runs the physics that many times faster (or slower) than the wall
clock; ``log`` gets every frame in and out (bus, direction, bytes, CAN id); ``tick`` is called in
the serving thread once per loop (power-cycling a twin, a viewer's sync: anything that touches the
world runs there, between physics steps); ``links`` puts a symlink per serial bus to its
pseudo-terminal (a stable port name for configs).
"""

from __future__ import annotations

import json
import math
import select
import signal
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TextIO

from joints.errors import TransportError
from joints.sim.can_serve import CanEndpoint, FrameLog, ServedCan
from joints.sim.served_timing import BusTiming, ServedLine, substeps_to
from joints.transports.loopback import UnsolicitedPeer
from joints.transports.pty import PtyEndpoint

IDLE_FLUSH = 0.005  #: s of silence after which a partial frame is dropped (t3.5, generously)
#: s of wall clock spent on physics at most between two looks at the ports: the longest a request
#: waits before it is executed and answered (a drive answers within a few ms)
SERVICE_PERIOD = 0.001
#: s before a reply's instant the loop stops sleeping and waits awake (a sleep's wake-up is late by the
#: OS's timer slack and scheduling: ~0.1 ms measured; a timed reply leaves within microseconds of its instant)
SPIN = 0.0003
#: a held request acts once the world's time has reached its instant (to rounding)
_EPS = 1e-9


class _Slices:
    """How many substeps fit into :data:`SERVICE_PERIOD` (their cost measured as the world runs)."""

    def __init__(self) -> None:
        self.cost: float | None = None  #: s of wall clock per substep (moving average)

    def size(self, wanted: int) -> int:
        if self.cost is None:
            return 1
        return max(1, min(wanted, int(SERVICE_PERIOD / self.cost)))

    def measured(self, steps: int, seconds: float) -> None:
        cost = seconds / steps
        self.cost = cost if self.cost is None else 0.8 * self.cost + 0.2 * cost


def serve(
    world: Any,
    buses: list[str],
    *,
    can_buses: Mapping[str, ServedCan] | None = None,
    out: TextIO | None = None,
    stop: threading.Event | None = None,
    on_ready: Callable[[dict[str, dict[str, Any]]], None] | None = None,
    install_signals: bool = True,
    realtime_factor: float = 1.0,
    log: FrameLog | None = None,
    tick: Callable[[], None] | None = None,
    links: Mapping[str, str] | None = None,
    timing: Mapping[str, BusTiming] | None = None,
) -> None:
    """Expose serial ``buses`` of ``world`` on ptys and ``can_buses`` on their channels; run in real time until stopped.

    ``out`` gets one JSON line per bus (``{"bus", "port"}`` for a pty; ``{"bus", "interface",
    "channel", "udp_port"}`` for CAN); ``on_ready`` gets the same objects by bus name.
    """
    if not realtime_factor > 0:
        raise ValueError(f"realtime_factor must be > 0, got {realtime_factor}")
    stop = stop or threading.Event()
    endpoints: dict[str, PtyEndpoint] = {}
    cans: dict[str, CanEndpoint] = {}
    made_links: list[Path] = []
    previous: dict[int, Any] = {}
    try:
        for name in buses:
            endpoints[name] = PtyEndpoint()
            if links and name in links:
                made_links.append(_symlink(Path(links[name]), endpoints[name].port))
        for name, spec in (can_buses or {}).items():
            cans[name] = CanEndpoint(spec, world.buses[name], log=log, name=name)
            if timing and name in timing and not timing[name].ideal:
                cans[name].line = ServedLine(timing[name], scale=1.0 / realtime_factor)
        if install_signals and threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                previous[sig] = signal.signal(sig, lambda *_: stop.set())
        lines: dict[str, dict[str, Any]] = {
            name: {"bus": name, "port": str(links[name]) if links and name in links else ep.port}
            for name, ep in endpoints.items()}
        lines.update({name: ep.spec.line(name) for name, ep in cans.items()})
        if on_ready is not None:  # first: what it prepares (a config file) exists once the lines are out
            on_ready(lines)
        if out is not None:
            for line in lines.values():
                out.write(json.dumps(line) + "\n")
            out.flush()
        served = {name: ServedLine(timing[name], scale=1.0 / realtime_factor)
                  for name in endpoints if timing and name in timing and not timing[name].ideal}
        _run(world, endpoints, cans, stop, realtime_factor, log, tick, served)
    finally:
        for ep in endpoints.values():
            ep.close()
        for can_ep in cans.values():
            can_ep.close()
        for link in made_links:
            link.unlink(missing_ok=True)
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def _symlink(path: Path, target: str) -> Path:
    """``path`` -> the pty (replacing a stale link, never a regular file)."""
    if path.is_symlink():
        path.unlink()
    elif path.exists():
        raise TransportError(f"cannot bind the served port to {path}: the file exists and is not a symlink")
    path.symlink_to(target)
    return path


def _run(world: Any, endpoints: Mapping[str, PtyEndpoint], cans: Mapping[str, CanEndpoint],
         stop: threading.Event, factor: float = 1.0, log: FrameLog | None = None,
         tick: Callable[[], None] | None = None, lines: Mapping[str, ServedLine] | None = None) -> None:
    by_fd: dict[int, tuple[str, Any]] = {ep.master: (name, ep) for name, ep in endpoints.items()}
    by_fd.update({ep.fileno(): (name, ep) for name, ep in cans.items()})
    lines = lines or {}
    last_rx = {name: 0.0 for name in endpoints}
    pending = {name: False for name in endpoints}
    #: timed serial buses: requests waiting to act (wall time, bytes), replies waiting to leave (wall time, bytes)
    inbox: dict[str, deque[tuple[float, bytes]]] = {name: deque() for name in lines}
    outbox: dict[str, deque[tuple[float, bytes]]] = {name: deque() for name in lines}
    t0_wall = time.monotonic()
    t0_sim = world.time
    dt = world.timestep
    next_send: float | None = None
    slices = _Slices()

    def reply(name: str, ep: PtyEndpoint, data: bytes, at: float) -> None:
        """Reply bytes the drives sent at wall time ``at``: out now, or when the real bus delivers them."""
        if not data:
            return
        line = lines.get(name)
        if line is not None:
            outbox[name].append((line.reply(at, line.timing.bytes_time(len(data))), data))
            return
        if log is not None:
            log(name, "tx", data, None)
        ep.write(data)

    def act(until: float) -> None:
        """Execute the held requests due by wall time ``until`` (the world is at their instant)."""
        for name, held in inbox.items():
            bus = world.buses[name]
            while held and held[0][0] <= until:
                at, data = held.popleft()
                reply(name, endpoints[name], bus.receive(data), at)
                last_rx[name] = at
                pending[name] = True
        for can_ep in cans.values():
            can_ep.act(until)

    def sim_wall(t_sim: float) -> float:
        """The wall time of simulated time ``t_sim``."""
        return float(t0_wall + (t_sim - t0_sim) / factor)

    for can_ep in cans.values():
        can_ep.wall_of = sim_wall

    while not stop.is_set():
        if tick is not None:
            tick()
            if world.time < t0_sim:  # the world was reset: time starts again
                t0_wall, t0_sim = time.monotonic(), world.time
        sim_behind = (time.monotonic() - t0_wall) * factor - (world.time - t0_sim)
        timeout = max(0.0, dt - sim_behind) if sim_behind < dt else 0.0
        timed = [q[0][0] for q in (*outbox.values(), *(c.timed for c in cans.values())) if q]
        if timed:  # a timed reply: wake SPIN before its instant (then wait awake, below)
            timeout = min(timeout, max(0.0, min(timed) - SPIN - time.monotonic()))
        if next_send is not None:  # the CAN channel's pacing
            timeout = min(timeout, max(0.0, next_send - time.monotonic()))
        ready, _, _ = select.select(list(by_fd), [], [], timeout)
        now = time.monotonic()
        for fd in ready:
            name, ep = by_fd[fd]
            if isinstance(ep, CanEndpoint):
                ep.receive(now)
                continue
            data = ep.read()
            if data:
                if log is not None:
                    log(name, "rx", data, None)
                line = lines.get(name)
                if line is not None:  # held until the drive has it and turned around
                    inbox[name].append((line.request(now, line.timing.bytes_time(len(data)), data[0]), data))
                    continue
                reply(name, ep, world.buses[name].receive(data), now)
                last_rx[name] = now
                pending[name] = True
        # requests whose instant the world has reached act now (on the substep ending at or after it)
        act(sim_wall(world.time) + _EPS)
        for name, ep in endpoints.items():
            if pending[name] and now - last_rx[name] > IDLE_FLUSH and not inbox.get(name):
                reply(name, ep, world.buses[name].silence(), now)
                pending[name] = False
        behind = (now - t0_wall) * factor - (world.time - t0_sim)
        if behind >= dt:
            # catch up in slices of about SERVICE_PERIOD of wall clock: a request that arrives
            # meanwhile waits for one slice at most, never for a backlog of physics; a held
            # request's instant is never stepped over
            n = slices.size(min(int(behind / dt), max(1, int(0.05 / dt))))
            first = min((q[0][0] for q in inbox.values() if q), default=None)
            first = min((t for t in (first, *(c.first_act() for c in cans.values())) if t is not None),
                        default=None)
            if first is not None:  # up to the substep that ends at or after its instant
                n = max(1, min(n, substeps_to(t0_sim + (first - t0_wall) * factor, world.time, dt)))
            started = time.monotonic()
            world.step(n)
            slices.measured(n, time.monotonic() - started)
            act(sim_wall(world.time) + _EPS)
            for name, ep in endpoints.items():
                bus = world.buses[name]
                if isinstance(bus, UnsolicitedPeer):
                    reply(name, ep, bus.take_unsolicited(), time.monotonic())
        now = time.monotonic()
        # a timed reply's instant (not the CAN channel's pacing): the last moments before it awake, not asleep
        soon = min((q[0][0] for q in (*outbox.values(), *(c.timed for c in cans.values())) if q), default=math.inf)
        while now < soon <= now + SPIN:
            now = time.monotonic()
        for name, waiting in outbox.items():
            while waiting and waiting[0][0] <= now:
                data = waiting.popleft()[1]
                if log is not None:
                    log(name, "tx", data, None)
                endpoints[name].write(data)
        next_send = None
        for can_ep in cans.values():
            due_at = can_ep.send_due(now)
            if due_at is not None:
                next_send = due_at if next_send is None else min(next_send, due_at)
