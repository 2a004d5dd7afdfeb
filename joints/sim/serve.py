"""Serve a simulated world in real time: each serial bus becomes a pseudo-terminal.

Rule: the world runs on the wall clock here (and only here); the emulated drives answer whatever
arrives on a pty between physics substeps, exactly as in process, and frames they send by
themselves (MKS completion frames: an :class:`~joints.transports.loopback.UnsolicitedPeer`) go out
as soon as the physics produced them. Stops cleanly on SIGINT/SIGTERM or when ``stop`` is set.
"""

from __future__ import annotations

import json
import select
import signal
import threading
import time
from collections.abc import Callable
from typing import Any, TextIO

from joints.transports.loopback import UnsolicitedPeer
from joints.transports.pty import PtyEndpoint

IDLE_FLUSH = 0.005  #: s of silence after which a partial frame is dropped (t3.5, generously)


def serve(
    world: Any,
    buses: list[str],
    *,
    out: TextIO | None = None,
    stop: threading.Event | None = None,
    on_ready: Callable[[dict[str, str]], None] | None = None,
    install_signals: bool = True,
) -> None:
    """Expose ``buses`` of ``world`` on ptys and run the world in real time until stopped."""
    stop = stop or threading.Event()
    endpoints = {name: PtyEndpoint() for name in buses}
    if install_signals and threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
    ports = {name: ep.port for name, ep in endpoints.items()}
    if out is not None:
        for name, port in ports.items():
            out.write(json.dumps({"bus": name, "port": port}) + "\n")
        out.flush()
    if on_ready is not None:
        on_ready(ports)
    by_fd = {ep.master: (name, ep) for name, ep in endpoints.items()}
    last_rx = {name: 0.0 for name in endpoints}
    pending = {name: False for name in endpoints}
    t0_wall = time.monotonic()
    t0_sim = world.time
    dt = world.timestep
    try:
        while not stop.is_set():
            sim_behind = (time.monotonic() - t0_wall) - (world.time - t0_sim)
            timeout = max(0.0, dt - sim_behind) if sim_behind < dt else 0.0
            ready, _, _ = select.select(list(by_fd), [], [], timeout)
            now = time.monotonic()
            for fd in ready:
                name, ep = by_fd[fd]
                data = ep.read()
                if data:
                    reply = world.buses[name].receive(data)
                    if reply:
                        ep.write(reply)
                    last_rx[name] = now
                    pending[name] = True
            for name, ep in endpoints.items():
                if pending[name] and now - last_rx[name] > IDLE_FLUSH:
                    reply = world.buses[name].silence()
                    if reply:
                        ep.write(reply)
                    pending[name] = False
            behind = (now - t0_wall) - (world.time - t0_sim)
            if behind >= dt:
                # catch up, but never more than 50 ms of physics in one go (stay responsive)
                world.step(min(int(behind / dt), max(1, int(0.05 / dt))))
                for name, ep in endpoints.items():
                    bus = world.buses[name]
                    if isinstance(bus, UnsolicitedPeer):
                        data = bus.take_unsolicited()
                        if data:
                            ep.write(data)
    finally:
        for ep in endpoints.values():
            ep.close()
