"""Where `joints sim serve` puts a simulated CAN bus: a python-can channel another process can open.

Rule: simulated frames never reach a real bus and never leave this host.

* Default: python-can's ``udp_multicast`` (no kernel module needed) on an interface-local IPv6
  group (ff01::/16: delivered on this host only, whatever hop limit a client uses) with hop limit
  0, and a group and UDP port unique to the served world (its process id and a free port), so two
  served worlds on one host never hear each other. The library's default group (site-local) with
  hop limit 1 would put every frame on the LAN. Without IPv6 the group falls back to an IPv4
  administratively scoped group with TTL 0 (host-local).
* ``interface = "socketcan"`` with a virtual CAN device (``vcan``/``vxcan``, created by the admin:
  ``ip link add dev vcan0 type vcan``) that the kernel has: served there.
* A physical interface (socketcan on a real controller, pcan, kvaser, slcan, ixxat, vector ...)
  is refused: the twins would answer on a real bus, next to (or instead of) real drives.
* ``virtual``/``joints-sim`` (in-process buses another process cannot open) are served on the
  default udp_multicast channel.

A client joins with ``can.Bus(interface=..., channel=..., port=udp_port)`` (the JSON line that
``sim serve`` prints has the three values; a hardware config takes them as the bus keys
``interface``, ``channel`` and ``udp_port``). udp_multicast returns every frame to its sender and
drops bursts above roughly 8000 frames/s, so the serve side filters its own frames and paces what
it sends (:data:`MAX_FRAMES_PER_S`). Our own hardware transport filters the echoes too; any other
python-can program (the canopen package as a master) joins with :func:`client_bus`, which wraps
the bus in :class:`~joints.transports.can_echo.EchoFreeBus`.

Frames the twins send by themselves (boot-ups, heartbeats, event TPDOs, EMCY) travel on the device
bus's timed medium; :class:`CanEndpoint` taps the medium and forwards them, paced with the answers.
With the real bus's time (:attr:`CanEndpoint.line`) they leave when the host's adapter would pass
them on: their end on the medium (the world's clock, :attr:`CanEndpoint.wall_of` makes it wall
time) plus the adapter latency, as the answers do.
"""

from __future__ import annotations

import ipaddress
import os
import socket
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from joints.errors import ConfigError, TransportError
from joints.sim.served_timing import ServedLine

__all__ = ["MAX_FRAMES_PER_S", "CanEndpoint", "FrameLog", "ServedCan", "client_bus", "plan"]

#: (bus, "rx" (from a client) | "tx" (the twins), data, CAN id or None) - ``sim serve --verbose``
FrameLog = Callable[[str, str, bytes, "int | None"], None]

#: frames per second the serve side sends at most on one bus (udp_multicast drops bursts above ~8k/s)
MAX_FRAMES_PER_S = 4000
#: interfaces that cannot be opened from another process: served on the default channel instead
_IN_PROCESS = ("virtual", "joints-sim")
_ARPHRD_CAN = 280
_SYS_NET = Path("/sys/class/net")
_SYS_VIRTUAL = Path("/sys/devices/virtual/net")


@dataclass(frozen=True)
class ServedCan:
    """The python-can channel one simulated CAN bus is served on."""

    interface: str
    channel: str
    udp_port: int | None = None

    def line(self, bus: str) -> dict[str, Any]:
        """What ``sim serve`` prints for the bus (one JSON object)."""
        return {"bus": bus, "interface": self.interface, "channel": self.channel, "udp_port": self.udp_port}

    def kwargs(self) -> dict[str, Any]:
        """``can.Bus`` keywords (besides interface and channel) to join it."""
        return {} if self.udp_port is None else {"port": self.udp_port, "hop_limit": 0}


def _interface_local(group: str) -> bool:
    try:
        addr = ipaddress.ip_address(group.split("%")[0])
    except ValueError:
        return False
    return isinstance(addr, ipaddress.IPv6Address) and addr in ipaddress.ip_network("ff01::/16")


def _free_udp_port() -> int:
    for family, host in ((socket.AF_INET6, "::"), (socket.AF_INET, "")):
        try:
            with socket.socket(family, socket.SOCK_DGRAM) as s:
                s.bind((host, 0))
                return int(s.getsockname()[1])
        except OSError:
            continue
    raise TransportError("no free UDP port for the served CAN bus")


def is_virtual_can(name: str) -> bool | None:
    """True for a virtual CAN netdev (vcan, vxcan), False for a real one, None if the kernel has no such device."""
    dev = _SYS_NET / name
    if not dev.exists():
        return None
    try:
        kind = int((dev / "type").read_text().strip())
    except (OSError, ValueError):
        return False
    return kind == _ARPHRD_CAN and (_SYS_VIRTUAL / name).exists()


def plan(bus: str, interface: str | None, channel: str | int | None, udp_port: int | None, *,
         index: int = 0) -> ServedCan:
    """The channel to serve bus ``bus`` on, from its config keys (ConfigError for a real bus)."""
    key = f"buses.{bus}"
    if interface is None or interface in _IN_PROCESS or interface == "udp_multicast":
        group = str(channel) if interface == "udp_multicast" and channel is not None else None
        if group is not None and not _interface_local(group):
            raise ConfigError(
                f"udp_multicast group {group!r} is not interface-local: simulated frames would reach the LAN; "
                "use a group in ff01::/16 or remove the channel key (sim serve picks one)", key=f"{key}.channel")
        pid = os.getpid()
        group = group or f"ff01::6a6f:{(pid >> 16) & 0xFFFF:x}:{pid & 0xFFFF:x}:{index & 0xFFFF:x}"
        return ServedCan("udp_multicast", group, udp_port or _free_udp_port())
    if interface == "socketcan" and channel is not None:
        virtual = is_virtual_can(str(channel))
        if virtual:
            return ServedCan("socketcan", str(channel))
        if virtual is None and str(channel).startswith(("vcan", "vxcan")):
            raise ConfigError(
                f"the kernel has no CAN device {channel!r}: create it (sudo modprobe vcan; sudo ip link add dev "
                f"{channel} type vcan; sudo ip link set up {channel}) or remove interface/channel to serve on "
                "udp_multicast", key=f"{key}.channel")
    where = f"{interface} {channel}" if channel is not None else str(interface)
    raise ConfigError(
        f"refusing to serve simulated drives on {where}: that is a real CAN interface, and the twins would answer "
        "on a physical bus next to (or instead of) real drives. Remove interface/channel (served on an "
        "interface-local udp_multicast group) or name a vcan device (interface = \"socketcan\", channel = "
        "\"vcan0\")", key=f"{key}.interface")


def client_bus(line: Mapping[str, Any]) -> Any:
    """A python-can bus joined to a served CAN bus, from the JSON line ``sim serve`` printed for it.

    On udp_multicast the bus is wrapped so that its own frames never come back to it (a real
    controller's behaviour; see :mod:`joints.transports.can_echo`).
    """
    from joints.transports.can import python_can

    can = python_can()
    interface, channel, port = line["interface"], line["channel"], line.get("udp_port")
    if interface != "udp_multicast":
        return can.Bus(interface=interface, channel=channel)
    from joints.transports.can_echo import EchoFreeBus

    return EchoFreeBus(can.Bus(interface=interface, channel=channel, port=port, hop_limit=0))


class CanEndpoint:
    """A served CAN bus: frames in to the device bus, its answers out, paced (no threads)."""

    def __init__(self, spec: ServedCan, device_bus: Any, *, max_rate: float = MAX_FRAMES_PER_S,
                 log: FrameLog | None = None, name: str = "can") -> None:
        from joints.transports.can import PythonCanTransport, python_can

        can = self._can = python_can()
        try:
            bus = can.Bus(interface=spec.interface, channel=spec.channel, **spec.kwargs())
        except can.CanInitializationError:
            if spec.interface != "udp_multicast" or ":" not in spec.channel:
                raise
            pid = os.getpid()  # no IPv6 multicast here: an IPv4 group with TTL 0 stays on this host
            spec = ServedCan(spec.interface, f"239.255.{(pid >> 8) & 0xFF}.{pid & 0xFF}", spec.udp_port)
            bus = can.Bus(interface=spec.interface, channel=spec.channel, **spec.kwargs())
        self.spec = spec
        self.transport = PythonCanTransport(bus, echoes=spec.interface == "udp_multicast")
        self.device_bus = device_bus
        medium = getattr(device_bus, "medium", None)
        #: frames the twins send by themselves on their timed medium (heartbeats, event PDOs, EMCY)
        self._tap = medium.attach("sim serve") if medium is not None else None
        self.spacing = 1.0 / max_rate
        self.out: deque[Any] = deque()
        self.next_send = 0.0
        self.frames_in = 0
        self.frames_out = 0
        self.log = log
        self.name = name  #: the bus's name in the config (for the frame log)
        #: the real bus's time (:mod:`joints.sim.served_timing`); None: answered at once
        self.line: ServedLine | None = None
        self.held: deque[tuple[float, Any]] = deque()  #: requests waiting to act (wall time, frame)
        self.timed: deque[tuple[float, Any]] = deque()  #: answers waiting for the real bus (wall time, frame)
        #: the wall time of a world time (the serving loop's); with :attr:`line`, frames the twins send by
        #: themselves wait for the host's adapter too
        self.wall_of: Callable[[float], float] | None = None

    def fileno(self) -> int:
        return int(self.transport.bus.fileno())

    def receive(self, now: float = 0.0) -> None:
        """Every frame waiting (read at wall time ``now``): the device bus answers (queued to be sent, paced);
        with a :attr:`line`, each frame is held until the drive acts on it (:meth:`act`)."""
        line = self.line
        while (frame := self.transport.recv(0.0)) is not None:
            self.frames_in += 1
            if self.log is not None:
                self.log(self.name, "rx", bytes(frame.data), int(frame.arbitration_id))
            if line is not None:
                node = int(frame.arbitration_id) & 0x7F  # eRob CAN 0x640+id, CANopen COB-IDs: function + node
                self.held.append((line.request(now, line.timing.frame_time(frame), node or None), frame))
                continue
            self.out.extend(self.device_bus.on_frame(frame))
        self.collect()

    def first_act(self) -> float | None:
        """Wall time the first held request acts (None: none held)."""
        return self.held[0][0] if self.held else None

    def act(self, until: float) -> None:
        """The held requests due by wall time ``until`` act; their answers wait for the real bus."""
        line = self.line
        while line is not None and self.held and self.held[0][0] <= until:
            at, frame = self.held.popleft()
            for answer in self.device_bus.on_frame(frame):
                self.timed.append((line.reply(at, line.timing.frame_time(answer)), answer))

    def collect(self) -> None:
        """Queue what the twins sent by themselves on their medium since the last call."""
        tap = self._tap
        line, wall_of = self.line, self.wall_of
        while tap is not None and tap.rx:
            f = tap.rx.popleft()
            msg = self._can.Message(arbitration_id=f.arbitration_id, is_extended_id=f.is_extended_id,
                                    is_remote_frame=f.is_remote_frame, dlc=f.dlc, data=f.data)
            if line is None or wall_of is None:
                self.out.append(msg)
                continue
            due = line.sent(wall_of(f.timestamp))  # f.timestamp: its last bit on the medium (world time)
            i = len(self.timed)
            while i and self.timed[i - 1][0] > due:  # in time order with the answers waiting
                i -= 1
            self.timed.insert(i, (due, msg))

    def send_due(self, now: float) -> float | None:
        """Send what the pacing allows at wall time ``now``; the time of the next send, if any wait."""
        self.collect()
        while self.timed and self.timed[0][0] <= now:
            self.out.append(self.timed.popleft()[1])
        while self.out and now >= self.next_send:
            frame = self.out.popleft()
            if self.log is not None:
                self.log(self.name, "tx", bytes(frame.data), int(frame.arbitration_id))
            self.transport.send(frame)
            self.frames_out += 1
            self.next_send = max(self.next_send, now) + self.spacing
        if self.out:
            return self.next_send
        return self.timed[0][0] if self.timed else None

    def close(self) -> None:
        self.transport.close()
