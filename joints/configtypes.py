"""The configuration's types: what a parsed config holds, as frozen dataclasses.

Rule: a leaf. These types import nothing of ``joints`` but its errors, so the config parser
(:mod:`joints.config`), the registry (:mod:`joints.registry`) and the joint (:mod:`joints.joint`)
share them without knowing each other. Validation lives in :mod:`joints.config`; a value here is
already checked. ``joints.config.BusConfig`` and ``joints.Limits`` etc. remain importable.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

from joints.errors import ConfigError

BACKENDS = ("sim", "hardware")


@dataclass(frozen=True, slots=True)
class Limits:
    """User limits of a joint (SI). ``None`` means: only the device's own limits apply."""

    position: tuple[float, float] | None = None  #: [rad, rad]
    velocity: float | None = None  #: rad/s (magnitude)
    torque: float | None = None  #: N*m (magnitude)
    acceleration: float | None = None  #: rad/s^2 (magnitude)


@dataclass(frozen=True, slots=True)
class Motion:
    """Default profile for position moves (SI)."""

    velocity: float = 0.5  #: rad/s
    acceleration: float = 2.0  #: rad/s^2
    deceleration: float = 2.0  #: rad/s^2


@dataclass(frozen=True)
class SimConfig:
    model: str = "erob_stand.xml"
    timestep: float = 0.001
    realtime: bool = False
    direct: bool = False  #: in-process direct path (message objects, no bytes); identical results


@dataclass(frozen=True)
class BusConfig:
    name: str
    protocol: str
    port: str | None = None
    baudrate: int = 115200
    parity: str = "N"
    stopbits: int = 1
    timeout: float = 0.1  #: s, reply timeout
    retries: int = 2
    echo: bool = False  #: the RS485 adapter echoes what it sends
    interface: str | None = None  #: CAN: python-can interface
    channel: str | int | None = None  #: CAN: channel
    bitrate: int = 1_000_000
    udp_port: int | None = None  #: CAN over udp_multicast: the port (`joints sim serve` prints it)
    sync_period: float | None = None  #: CANopen: s between two SYNCs of the bus (cyclic modes; default 1 ms)
    backend: str = "sim"  #: "sim" | "hardware": this bus's (the file's top-level backend unless it names one)
    timing: str = "wire"  #: sim: "wire" (frames take their wire time, turnaround and adapter latency) | "ideal" (none)
    adapter_latency: float | None = None  #: s per transaction of the host's adapter; None: the medium's default


@dataclass(frozen=True)
class JointConfig:
    name: str
    device: str
    bus: str
    address: int
    model: str | None = None  #: device variant (eRob: "eRob80H100")
    channel: str | None = None
    mjcf_joint: str | None = None
    limits: Limits = field(default_factory=Limits)
    motion: Motion = field(default_factory=Motion)
    profile: Mapping[str, float] = field(default_factory=dict)  #: device-profile overrides
    watchdog_ms: int | None = None
    offset: float = 0.0
    direction: int = 1
    lead: float | None = None  #: m of travel per motor turn: a linear joint (positions in m, forces in N)
    mode: str | None = None  #: operating mode where the protocol has several (CANopen: pp, pv, pt, csp, csv, cst, ip)
    sync_period: float | None = None  #: CANopen: s between two SYNCs (the bus's; set it on the bus or here)
    profile_overlay: str | None = None  #: the identified-profile file whose ``[profile]`` was merged into ``profile``
    firmware: str | None = None  #: the drive's firmware profile (its quirks: joints.devices.quirks); None: default
    eds: str | None = None  #: CANopen: the drive's EDS file as the driver's object dictionary (resolved path)


@dataclass(frozen=True)
class RigConfig:
    backend: str  #: "sim" | "hardware" | "mixed" (buses of both)
    buses: Mapping[str, BusConfig]
    joints: Mapping[str, JointConfig]
    sim: SimConfig = field(default_factory=SimConfig)
    on_exit: str = "disable"
    source: str = "<dict>"
    base_dir: Path = field(default_factory=Path.cwd)

    def bus_backend(self, bus: str) -> str:
        """The backend of one bus ("sim" | "hardware")."""
        return self.buses[bus].backend

    def with_backend(self, backend: str) -> RigConfig:
        """The same config with every bus forced to ``backend`` (what ``JOINTS_BACKEND`` does)."""
        if backend not in BACKENDS:
            raise ConfigError(f"{backend!r} is not a backend", key="backend", allowed=BACKENDS)
        buses = {n: replace(b, backend=backend) for n, b in self.buses.items()}
        return replace(self, backend=backend, buses=buses)
