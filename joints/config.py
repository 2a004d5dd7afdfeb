"""Configuration: one TOML file (or dict) describes the buses, joints and simulation.

Rule: validate everything up front; every error names the file, the key and what is allowed.
:func:`parse` reads one section at a time (backend, ``[sim]``, ``[buses.*]``, ``[joints.*]``) into
the types of :mod:`joints.configtypes` and asks the registry what each protocol and device allows.
In ``backend = "sim"`` the hardware-only keys (port, CAN interface) are read but ignored, so one
file serves both backends. ``JOINTS_BACKEND=sim|hardware`` overrides the file.

Mixed rigs: a bus may name its own ``backend`` (``[buses.NAME] backend = "hardware"``); the bus
key wins over the file's top-level ``backend``, and ``JOINTS_BACKEND`` (or the ``backend``
argument of :func:`load` / ``joints.open``) still forces every bus. :attr:`RigConfig.backend` is
then ``"mixed"`` when the buses differ.

Identified profiles: a joint's ``profile_overlay`` names a TOML file (relative to the config
file) whose ``[profile]`` table holds device-profile overrides, as ``joints identify`` writes
them; keys of the joint's inline ``profile`` table win over the file's.

Measured timing: the top-level ``timing_overlay`` names a TOML file (relative to the config
file) as ``joints bench --hardware --write-overlay`` writes it: ``[buses.NAME]`` tables with
``adapter_latency`` (and ``timing``), ``[joints.NAME.profile]`` tables with device-profile
numbers (``turnaround``). They are merged into the config before it is validated; the config's
own keys win over the overlay's.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from joints import registry
from joints.configtypes import BACKENDS, BusConfig, JointConfig, Limits, Motion, RigConfig, SimConfig
from joints.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["BACKENDS", "BusConfig", "JointConfig", "Limits", "Motion", "RigConfig", "SimConfig", "load", "parse",
           "read_overlay"]

#: protocol and device names a config may use (the registry's, plus those planned but not built yet)
PROTOCOLS = registry.protocols() + registry.PLANNED_PROTOCOLS
DEVICES = registry.devices() + registry.PLANNED_DEVICES
PARITIES = ("N", "E", "O")
ON_EXIT = ("disable", "stop", "none")
#: a simulated bus's timing: frames take their wire time (+ turnaround, adapter latency), or none
TIMINGS = ("wire", "ideal")


class _Reader:
    def __init__(self, source: str) -> None:
        self.source = source

    def err(self, key: str, msg: str, allowed: Any = None) -> ConfigError:
        return ConfigError(msg, file=self.source, key=key, allowed=allowed)

    def table(self, data: Mapping[str, Any], key: str) -> Mapping[str, Any]:
        v = data.get(key.rsplit(".", 1)[-1], {})
        if not isinstance(v, Mapping):
            raise self.err(key, f"expected a table, got {type(v).__name__}")
        return v

    def choice(self, data: Mapping[str, Any], key: str, allowed: tuple[str, ...], default: str | None = None) -> str:
        short = key.rsplit(".", 1)[-1]
        v = data.get(short, default)
        if v is None:
            raise self.err(key, "is required", allowed)
        if v not in allowed:
            raise self.err(key, f"{v!r} is not allowed", allowed)
        return str(v)

    def number(self, data: Mapping[str, Any], key: str, default: float | None, *, positive: bool = False,
               integer: bool = False, minimum: float | None = None, maximum: float | None = None) -> Any:
        short = key.rsplit(".", 1)[-1]
        v = data.get(short, default)
        if v is None:
            return None
        if (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
                or (integer and not float(v).is_integer())):
            raise self.err(key, f"expected {'an integer' if integer else 'a finite number'}, got {v!r}")
        if positive and v <= 0:
            raise self.err(key, f"must be > 0, got {v}")
        if minimum is not None and v < minimum or maximum is not None and v > maximum:
            if minimum is not None and maximum is not None:
                allowed = f"{minimum}..{maximum}"
            else:
                allowed = f">= {minimum}" if minimum is not None else f"<= {maximum}"
            raise self.err(key, f"{v} is out of range", allowed)
        return int(v) if integer else float(v)

    def known(self, data: Mapping[str, Any], key: str, allowed: tuple[str, ...]) -> None:
        for k in data:
            if k not in allowed:
                raise self.err(f"{key}.{k}" if key else k, "unknown key", allowed)


_BUS_KEYS = tuple(f for f in BusConfig.__dataclass_fields__ if f != "name")
_JOINT_KEYS = tuple(f for f in JointConfig.__dataclass_fields__ if f not in ("name",))
_TOP_KEYS = ("backend", "sim", "buses", "joints", "on_exit", "timing_overlay")
#: what a timing overlay may set: per bus, per joint
_OVERLAY_BUS_KEYS = ("adapter_latency", "timing")
_OVERLAY_JOINT_KEYS = ("profile",)


def _limits(r: _Reader, data: Mapping[str, Any], key: str) -> Limits:
    r.known(data, key, ("position", "velocity", "torque", "acceleration"))
    pos = data.get("position")
    if pos is not None:
        if (not isinstance(pos, (list, tuple)) or len(pos) != 2
                or not all(isinstance(p, (int, float)) and not isinstance(p, bool) and math.isfinite(p) for p in pos)
                or not pos[0] < pos[1]):
            raise r.err(f"{key}.position", f"expected [min, max] in rad (m with a lead) with min < max, got {pos!r}")
        pos = (float(pos[0]), float(pos[1]))
    return Limits(
        position=pos,
        velocity=r.number(data, f"{key}.velocity", None, positive=True),
        torque=r.number(data, f"{key}.torque", None, positive=True),
        acceleration=r.number(data, f"{key}.acceleration", None, positive=True),
    )


def _motion(r: _Reader, data: Mapping[str, Any], key: str) -> Motion:
    r.known(data, key, ("velocity", "acceleration", "deceleration"))
    d = Motion()
    return Motion(
        velocity=r.number(data, f"{key}.velocity", d.velocity, positive=True),
        acceleration=r.number(data, f"{key}.acceleration", d.acceleration, positive=True),
        deceleration=r.number(data, f"{key}.deceleration", d.deceleration, positive=True),
    )


def parse(data: Mapping[str, Any], *, source: str = "<dict>", base_dir: Path | None = None,
          backend: str | None = None) -> RigConfig:
    """Validate a config mapping (the parsed TOML), one section after the other."""
    r = _Reader(source)
    r.known(data, "", _TOP_KEYS)
    if "timing_overlay" in data:
        data = _with_timing_overlay(data, r, base_dir)
    chosen, forced = _backend(r, data, backend)
    sim = _sim(r, r.table(data, "sim"))
    buses = _buses(r, r.table(data, "buses"), chosen, forced)
    joints = _joints(r, r.table(data, "joints"), buses, base_dir)
    kinds = {b.backend for b in buses.values()}
    return RigConfig(
        backend=kinds.pop() if len(kinds) == 1 else ("mixed" if kinds else chosen),
        buses=buses,
        joints=joints,
        sim=sim,
        on_exit=r.choice(data, "on_exit", ON_EXIT, "disable"),
        source=source,
        base_dir=base_dir or Path.cwd(),
    )


def _backend(r: _Reader, data: Mapping[str, Any], backend: str | None) -> tuple[str, bool]:
    """The top-level backend (the argument, then ``JOINTS_BACKEND``, then the file) and whether it is
    forced on every bus (argument or environment)."""
    env = os.environ.get("JOINTS_BACKEND")
    in_file = data.get("backend", "sim")
    if in_file not in BACKENDS:
        raise r.err("backend", f"{in_file!r} is not a backend", BACKENDS)
    chosen = backend or env or in_file
    if chosen not in BACKENDS:
        where = "backend argument" if backend else ("JOINTS_BACKEND" if env else "backend")
        raise r.err(where, f"{chosen!r} is not a backend", BACKENDS)
    return str(chosen), bool(backend or env)


def _sim(r: _Reader, s: Mapping[str, Any]) -> SimConfig:
    """``[sim]``."""
    r.known(s, "sim", ("model", "timestep", "realtime", "direct"))
    direct = s.get("direct", False)
    if not isinstance(direct, bool):
        raise r.err("sim.direct", f"expected true or false, got {direct!r}")
    realtime = s.get("realtime", False)
    if not isinstance(realtime, bool):
        raise r.err("sim.realtime", f"expected true or false, got {realtime!r}")
    return SimConfig(
        model=str(s.get("model", SimConfig.model)),
        timestep=r.number(s, "sim.timestep", SimConfig.timestep, positive=True, maximum=0.01),
        realtime=realtime,
        direct=direct,
    )


def _buses(r: _Reader, table: Mapping[str, Any], chosen: str, forced: bool) -> dict[str, BusConfig]:
    """``[buses.NAME]``: each bus with its own backend unless ``forced``."""
    buses: dict[str, BusConfig] = {}
    for name, b in table.items():
        key = f"buses.{name}"
        if not isinstance(b, Mapping):
            raise r.err(key, "expected a table")
        buses[name] = _bus(r, name, b, chosen, forced)
    return buses


def _bus(r: _Reader, name: str, b: Mapping[str, Any], chosen: str, forced: bool) -> BusConfig:
    key = f"buses.{name}"
    r.known(b, key, _BUS_KEYS)
    protocol = r.choice(b, f"{key}.protocol", PROTOCOLS)
    entry = _protocol(protocol)
    own = r.choice(b, f"{key}.backend", BACKENDS, chosen)
    bus_backend = chosen if forced else own
    port = b.get("port")
    if port is not None and not isinstance(port, str):
        raise r.err(f"{key}.port", f"expected a port name string, got {port!r}")
    echo = b.get("echo", False)
    if not isinstance(echo, bool):
        raise r.err(f"{key}.echo", f"expected true or false, got {echo!r}")
    medium = None if entry is None else entry.medium
    if bus_backend == "hardware" and medium == "serial" and not port:
        raise r.err(f"{key}.port", "is required for backend = \"hardware\" (e.g. \"/dev/ttyUSB0\")")
    interface = b.get("interface")
    if interface is not None and (not isinstance(interface, str) or not interface):
        raise r.err(f"{key}.interface", f"expected a python-can interface name, got {interface!r}",
                    ("socketcan", "pcan", "kvaser", "slcan", "udp_multicast", "virtual", "..."))
    channel = b.get("channel")
    if channel is not None and (isinstance(channel, bool) or not isinstance(channel, (str, int))):
        raise r.err(f"{key}.channel", f"expected a channel name or number, got {channel!r}")
    udp_port = r.number(b, f"{key}.udp_port", None, integer=True, minimum=1, maximum=65535)
    if udp_port is not None and interface not in (None, "udp_multicast"):
        raise r.err(f"{key}.udp_port", f"only for interface = \"udp_multicast\" (this bus: {interface!r})")
    if bus_backend == "hardware" and medium == "can" and interface is None:
        raise r.err(f"{key}.interface", "is required for a CAN bus with backend = \"hardware\"",
                    ("socketcan", "pcan", "kvaser", "slcan", "udp_multicast", "..."))
    return BusConfig(
        name=name,
        protocol=protocol,
        port=None if port is None else str(port),
        baudrate=r.number(b, f"{key}.baudrate", 115200, integer=True, positive=True),
        parity=r.choice(b, f"{key}.parity", PARITIES, "N"),
        stopbits=r.number(b, f"{key}.stopbits", 1, integer=True, minimum=1, maximum=2),
        timeout=r.number(b, f"{key}.timeout", 0.1, positive=True),
        retries=r.number(b, f"{key}.retries", 2, integer=True, minimum=0, maximum=10),
        echo=echo,
        interface=interface,
        channel=channel,
        bitrate=r.number(b, f"{key}.bitrate", 1_000_000, integer=True, positive=True),
        udp_port=udp_port,
        sync_period=_sync_period(r, b, f"{key}.sync_period", protocol),
        backend=bus_backend,
        timing=r.choice(b, f"{key}.timing", TIMINGS, "wire"),
        adapter_latency=r.number(b, f"{key}.adapter_latency", None, minimum=0.0, maximum=1.0),
    )


def _joints(r: _Reader, table: Mapping[str, Any], buses: Mapping[str, BusConfig],
            base_dir: Path | None) -> dict[str, JointConfig]:
    """``[joints.NAME]``: each joint on a bus above, one address (and channel) per joint."""
    joints: dict[str, JointConfig] = {}
    for name, j in table.items():
        if not isinstance(j, Mapping):
            raise r.err(f"joints.{name}", "expected a table")
        joints[name] = _joint(r, name, j, buses, joints, base_dir)
    if not joints:
        raise r.err("joints", "no joints defined; add a [joints.<name>] table")
    return joints


def _joint(r: _Reader, name: str, j: Mapping[str, Any], buses: Mapping[str, BusConfig],
           others: Mapping[str, JointConfig], base_dir: Path | None) -> JointConfig:
    """One joint; ``others``: the joints before it (one address per joint, one SYNC period per bus)."""
    key = f"joints.{name}"
    r.known(j, key, _JOINT_KEYS)
    device = r.choice(j, f"{key}.device", DEVICES)
    bus = j.get("bus")
    if not isinstance(bus, str) or bus not in buses:
        raise r.err(f"{key}.bus", f"{bus!r} is not a bus defined under [buses]", sorted(buses))
    protocol = buses[bus].protocol
    fam = _family(device)
    if fam is None or protocol not in fam.protocols:
        raise r.err(f"{key}.device", f"device {device!r} on protocol {protocol!r} is not supported yet",
                    registry.pairs())
    lo, hi = fam.address_range(protocol)
    address = r.number(j, f"{key}.address", None, integer=True, minimum=lo, maximum=hi)
    if address is None:
        raise r.err(f"{key}.address", f"is required ({protocol}: {lo}..{hi})")
    channel = j.get("channel")
    if fam.channels and channel not in fam.channels:
        raise r.err(f"{key}.channel", f"{channel!r}: a {device} joint must name its motor", fam.channels)
    ident = (bus, address, channel if fam.channels else None)
    for other in others.values():
        if (other.bus, other.address, other.channel) == ident:
            raise r.err(f"{key}.address", f"address {address} on bus {bus!r} is already used by joint {other.name!r}")
    if not fam.channels and channel is not None:
        raise r.err(f"{key}.channel", f"a {device} has one motor per address; remove the key")
    profile = j.get("profile", {})
    if not isinstance(profile, Mapping):
        raise r.err(f"{key}.profile", "expected a table of device-profile overrides")
    overlay = j.get("profile_overlay")
    if overlay is not None:
        if not isinstance(overlay, str) or not overlay:
            raise r.err(f"{key}.profile_overlay", f"expected the path of a profile overlay file, got {overlay!r}")
        overlay = str((base_dir or Path.cwd()) / overlay)
        profile = {**read_overlay(overlay, r.source), **profile}
    direction = j.get("direction", 1)
    if isinstance(direction, bool) or direction not in (1, -1):
        raise r.err(f"{key}.direction", f"{direction!r} is not allowed", (1, -1))
    model = j.get("model")
    if model is not None and not isinstance(model, str):
        raise r.err(f"{key}.model", f"expected a model name string, got {model!r}")
    firmware = j.get("firmware")
    if firmware is not None:
        if not isinstance(firmware, str):
            raise r.err(f"{key}.firmware", f"expected a firmware profile name, got {firmware!r}")
        try:
            fam.firmware_profile(firmware)
        except ConfigError as exc:
            raise r.err(f"{key}.firmware", exc.message, exc.allowed) from None
    eds = _eds(r, j.get("eds"), f"{key}.eds", protocol in fam.eds, base_dir)
    modes = fam.modes.get(protocol, ())
    mode = j.get("mode")
    if mode is not None and not modes:
        raise r.err(f"{key}.mode", f"protocol {protocol!r} has no operating modes to choose; remove the key")
    if mode is not None and mode not in modes:
        raise r.err(f"{key}.mode", f"{mode!r} is not allowed", modes)
    sync_period = _sync_period(r, j, f"{key}.sync_period", protocol)
    bus_sync = buses[bus].sync_period
    if sync_period is not None and bus_sync is not None and not math.isclose(sync_period, bus_sync):
        raise r.err(f"{key}.sync_period", f"{sync_period} s differs from the bus's sync_period {bus_sync} s "
                    "(one SYNC per bus)")
    for other in others.values():
        if (other.bus == bus and sync_period is not None and other.sync_period is not None
                and not math.isclose(other.sync_period, sync_period)):
            raise r.err(f"{key}.sync_period", f"{sync_period} s differs from joint {other.name!r} on the same "
                        f"bus ({other.sync_period} s; one SYNC per bus)")
    return JointConfig(
        name=name,
        device=device,
        bus=bus,
        address=address,
        model=model,
        channel=None if channel is None else str(channel),
        mjcf_joint=str(j.get("mjcf_joint", name)),
        limits=_limits(r, r.table(j, f"{key}.limits"), f"{key}.limits"),
        motion=_motion(r, r.table(j, f"{key}.motion"), f"{key}.motion"),
        profile=dict(profile),
        watchdog_ms=r.number(j, f"{key}.watchdog_ms", None, integer=True, minimum=0, maximum=4000),
        offset=r.number(j, f"{key}.offset", 0.0),
        direction=int(direction),
        lead=r.number(j, f"{key}.lead", None, positive=True),
        mode=None if mode is None else str(mode),
        sync_period=sync_period,
        profile_overlay=overlay,
        firmware=firmware,
        eds=eds,
    )


def _eds(r: _Reader, value: Any, key: str, takes_eds: bool, base_dir: Path | None) -> str | None:
    """A joint's ``eds``: a vendor EDS file (relative to the config's directory) for a CANopen driver."""
    if value is None:
        return None
    if not takes_eds:
        raise r.err(key, "only a CANopen joint has an object dictionary (EDS); remove the key")
    if not isinstance(value, str) or not value:
        raise r.err(key, f"expected the path of an EDS file, got {value!r}")
    path = (base_dir or Path.cwd()) / value
    if not path.is_file():
        raise r.err(key, f"{path} does not exist: give the path of the drive's EDS file relative to the config "
                         "file's directory (the vendor's, or one written by `joints sim eds`), or remove the key "
                         "to use the built-in dictionary")
    return str(path)


def _protocol(name: str) -> registry.BusProtocol | None:
    """The registry's entry of a protocol (None: planned, not built yet)."""
    try:
        return registry.protocol(name)
    except ConfigError:
        return None


def _family(device: str) -> registry.DeviceFamily | None:
    """The registry's family of a device (None: planned, not built yet)."""
    try:
        return registry.family(device)
    except ConfigError:
        return None


def _sync_period(r: _Reader, data: Mapping[str, Any], key: str, protocol: str) -> float | None:
    """A SYNC period [s] (protocols with a SYNC, i.e. CANopen's cyclic modes; 100 us .. 1 s)."""
    value = r.number(data, key, None, minimum=1e-4, maximum=1.0)
    entry = _protocol(protocol)
    if value is not None and not (entry is not None and entry.sync):
        raise r.err(key, f"only for a protocol with cyclic modes (this bus: {protocol!r})")
    return None if value is None else float(value)


def _with_timing_overlay(data: Mapping[str, Any], r: _Reader, base_dir: Path | None) -> dict[str, Any]:
    """``data`` with its ``timing_overlay`` file merged in (the config's own keys win)."""
    name = data["timing_overlay"]
    if not isinstance(name, str) or not name:
        raise r.err("timing_overlay", f"expected the path of a timing overlay file, got {name!r}")
    path = (base_dir or Path.cwd()) / name
    try:
        overlay = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise r.err("timing_overlay", f"timing overlay not found: {path}") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise r.err("timing_overlay", f"cannot read the timing overlay {path}: {exc}") from exc
    where = _Reader(str(path))
    where.known(overlay, "", ("buses", "joints"))
    out = dict(data)
    for section, kind, allowed in (("buses", "bus", _OVERLAY_BUS_KEYS), ("joints", "joint", _OVERLAY_JOINT_KEYS)):
        tables = where.table(overlay, section)
        own = dict(r.table(data, section))
        for item, values in tables.items():
            key = f"{section}.{item}"
            if not isinstance(values, Mapping):
                raise where.err(key, "expected a table")
            if item not in own:
                raise where.err(key, f"the config {r.source} has no {kind} {item!r}", sorted(own))
            where.known(values, key, allowed)
            mine = own[item]
            if not isinstance(mine, Mapping):
                continue  # the config's own error is reported when it is validated
            merged = {**values, **mine}
            if "profile" in values:
                if not isinstance(values["profile"], Mapping):
                    raise where.err(f"{key}.profile", "expected a table of device-profile numbers")
                inline = mine.get("profile", {})
                merged["profile"] = {**values["profile"], **inline} if isinstance(inline, Mapping) else inline
            own[item] = merged
        out[section] = own
    return out


def read_overlay(path: str | os.PathLike[str], source: str | None = None) -> dict[str, Any]:
    """The ``[profile]`` table of a profile overlay file (``joints identify`` writes them)."""
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"profile overlay not found: {p}", file=source, key="profile_overlay") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"cannot read the profile overlay {p}: {exc}", file=source, key="profile_overlay") from exc
    table = data.get("profile")
    if not isinstance(table, Mapping):
        raise ConfigError(f"{p} has no [profile] table of device-profile overrides", file=source,
                          key="profile_overlay")
    return dict(table)


def load(path: str | os.PathLike[str], *, backend: str | None = None) -> RigConfig:
    """Read and validate a TOML config file."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"config file not found: {p}", file=str(p)) from None
    except OSError as exc:
        raise ConfigError(f"cannot read config: {exc}", file=str(p)) from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(f"not a UTF-8 text file: {exc}", file=str(p)) from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"not valid TOML: {exc}", file=str(p)) from exc
    return parse(data, source=str(p), base_dir=p.resolve().parent, backend=backend)
