"""Rig: config -> buses, joints, (sim world) and one clock; the ``with`` block that keeps it safe.

Rule: leaving the rig - normally or by an exception - stops and disables every joint this rig
enabled (``on_exit = "disable"``, the default), then closes the buses. Shutdown errors of one
joint never prevent the others from being shut down.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

from joints import registry
from joints.clock import Clock, MonotonicClock
from joints.config import BusConfig, RigConfig, load, parse
from joints.drivers.capabilities import CommunicationWatchdog, DriveGroup, GroupedChannel, SyncVelocityGroup
from joints.errors import ConfigError, JointsError
from joints.joint import Joint, JointState
from joints.link.base import Link
from joints.link.trace import TraceRecord

log = logging.getLogger("joints")


@dataclass
class Bus:
    """One configured bus: its transport and link."""

    config: BusConfig
    transport: Any  #: a byte transport (serial, pty, loopback) or a CAN frame transport
    link: Link[Any]


class Rig:
    """Buses, joints and a clock built from one config."""

    def __init__(
        self,
        config: RigConfig,
        *,
        clock: Clock,
        buses: Mapping[str, Bus],
        joints: Mapping[str, Joint],
        world: Any = None,
    ) -> None:
        self.config = config
        self.clock = clock
        self.buses = dict(buses)
        self.joints: dict[str, Joint] = dict(joints)
        self.world = world  #: the simulation (sim backend) or None
        self._closed = False

    @property
    def backend(self) -> str:
        return self.config.backend

    @property
    def time(self) -> float:
        """Seconds on the rig's clock (simulated time in sim)."""
        return self.clock.now()

    def sleep(self, seconds: float) -> None:
        """Sim: advance the world by ``seconds``; hardware: wait on the wall clock."""
        if not math.isfinite(seconds) or seconds < 0:
            raise ValueError(f"cannot sleep {seconds!r} s (need a finite time >= 0)")
        self.clock.sleep(seconds)

    def read_states(self) -> dict[str, JointState]:
        """State of every joint, bus by bus: one status transaction per drive.

        Joints whose drivers share a ``status_group`` (the two wheels of a ZLAC8015D) are served
        by one block read of that drive.
        """
        out: dict[str, JointState] = {}
        groups: dict[int, tuple[Mapping[str, int], float]] = {}
        for bus in self.buses:
            for name, j in self.joints.items():
                if self.config.joints[name].bus != bus:
                    continue
                driver = j.driver
                if not isinstance(driver, GroupedChannel):
                    out[name] = j.state()
                    continue
                group: DriveGroup = driver.group
                if id(group) not in groups:
                    groups[id(group)] = (group.read_status(), self.clock.now())
                block, t = groups[id(group)]
                out[name] = j.to_si(driver.state_from(block, t))
        return {name: out[name] for name in self.joints if name in out}

    def set_velocities(self, velocities: Mapping[str, float]) -> None:
        """Set several joints' velocities [rad/s] at once; every command is checked first.

        Joints on one drive that supports synchronous commands (both wheels of a ZLAC8015D) get one
        FC16 for both targets; the others are commanded one by one.
        """
        checked = {name: self.joints[name].velocity_command(v) for name, v in velocities.items()}
        done: set[str] = set()
        for name, (v, acc) in checked.items():
            if name in done:
                continue
            driver = self.joints[name].driver
            if isinstance(driver, GroupedChannel) and isinstance(driver.group, SyncVelocityGroup):
                group = driver.group
                members: dict[str, GroupedChannel] = {}
                for n in checked:
                    d = self.joints[n].driver
                    if isinstance(d, GroupedChannel) and d.group is group:
                        members[n] = d
                if {d.channel for d in members.values()} == set(group.channels):
                    group.set_channel_velocities({d.channel: checked[n] for n, d in members.items()})
                    done.update(members)
                    continue
            driver.set_velocity(v, acceleration=acc, deceleration=acc)
            done.add(name)

    def reset(self) -> None:
        """Sim: physics to the model's initial state and every emulated drive to power-on.

        Drivers forget what they wrote (the drives lost it) and joints count as disabled.
        On hardware this raises: a real robot cannot be reset by software.
        """
        if self.world is None:
            raise JointsError("reset() is only available with backend = \"sim\"")
        self.world.reset()
        for name, j in self.joints.items():
            j.driver_reset()
            watchdog = self.config.joints[name].watchdog_ms
            if watchdog is not None and isinstance(j.driver, CommunicationWatchdog):
                j.driver.set_communication_timeout(watchdog)  # the power cycle restored the default: re-apply

    def trace(self, sink: Callable[[TraceRecord], None] | None) -> None:
        """Route every frame of every bus to ``sink`` (None stops tracing)."""
        for b in self.buses.values():
            b.link.trace = sink

    def close(self) -> None:
        """Stop and disable what this rig enabled (per ``on_exit``), then close the buses."""
        if self._closed:
            return
        self._closed = True
        errors: list[BaseException] = []
        if self.config.on_exit != "none":
            for j in self.joints.values():
                try:
                    if self.config.on_exit == "disable":
                        j.shutdown()
                    elif j.enabled:
                        j.stop()
                except Exception as exc:  # noqa: BLE001 - keep shutting the others down
                    log.error("shutdown of joint %s failed: %s", j.name, exc)
                    errors.append(exc)
        for b in self.buses.values():
            try:
                b.transport.close()
            except Exception as exc:  # noqa: BLE001
                errors.append(exc)
        if self.world is not None:
            try:
                self.world.close()
            except Exception as exc:  # noqa: BLE001 - report with the others
                errors.append(exc)
        if errors:
            raise JointsError(f"errors while closing the rig: {'; '.join(map(str, errors))}") from errors[0]

    def __enter__(self) -> Rig:  # noqa: PYI034 - typing.Self needs Python 3.11
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if exc is None:
            self.close()
        else:
            try:
                self.close()
            except JointsError as close_exc:  # the original exception matters more
                log.error("%s", close_exc)

    def __repr__(self) -> str:
        return f"Rig(backend={self.backend!r}, joints={list(self.joints)})"


def _in_file(exc: ConfigError, source: str) -> ConfigError:
    """The same error, naming the config file (errors from below the config know only the key)."""
    return ConfigError(exc.message, file=source, key=exc.key, allowed=exc.allowed)


def build(config: RigConfig, *, transports: Mapping[str, Any] | None = None,
          clock: Clock | None = None, world: Any = None, peers: Mapping[str, Any] | None = None) -> Rig:
    """Assemble a rig from a validated config and ready transports (one per bus; missing ones are opened).

    ``peers`` (sim): bus name -> emulated bus answering message objects; those buses get the
    direct path (no bytes) instead of the byte path.
    """
    clock = clock or MonotonicClock()
    opened: dict[str, Any] = dict(transports or {})
    buses: dict[str, Bus] = {}
    try:
        for name, bcfg in config.buses.items():
            proto = registry.protocol(bcfg.protocol, key=f"buses.{name}.protocol")
            if name not in opened:
                opened[name] = proto.open_transport(bcfg)
            link = proto.link(bcfg, opened[name], clock, peers.get(name) if peers else None)
            buses[name] = Bus(bcfg, opened[name], link)
        joints: dict[str, Joint] = {}
        shared: dict[Any, Any] = {}
        for name, jcfg in config.joints.items():
            bus = buses[jcfg.bus]
            fam = registry.family(jcfg.device, key=f"joints.{name}.device")
            driver = fam.driver(jcfg, bus.link, clock, shared, bus.config.protocol)
            joints[name] = Joint(name, driver, clock=clock, limits=jcfg.limits, motion=jcfg.motion,
                                 offset=jcfg.offset, direction=jcfg.direction)
            if jcfg.watchdog_ms is not None and isinstance(driver, CommunicationWatchdog):
                driver.set_communication_timeout(jcfg.watchdog_ms)
    except BaseException as exc:
        for t in opened.values():
            t.close()
        if isinstance(exc, ConfigError) and exc.file is None:
            raise _in_file(exc, config.source) from exc
        raise
    return Rig(config, clock=clock, buses=buses, joints=joints, world=world)


def open(config: str | os.PathLike[str] | Mapping[str, Any] | RigConfig, *, backend: str | None = None) -> Rig:
    """Open a rig from a TOML path, a dict or a parsed config.

    ``backend`` (or the environment variable ``JOINTS_BACKEND``) overrides the file's backend.
    """
    if isinstance(config, RigConfig):
        if backend is not None and backend not in ("sim", "hardware"):
            raise ConfigError(f"{backend!r} is not a backend", key="backend", allowed=("sim", "hardware"))
        cfg = config if backend is None else dataclasses.replace(config, backend=backend)
    elif isinstance(config, Mapping):
        cfg = parse(config, backend=backend)
    else:
        cfg = load(Path(config), backend=backend)
    try:
        if cfg.backend == "sim":
            return open_sim(cfg)
        return build(cfg)
    except ConfigError as exc:
        if exc.file is None:
            raise _in_file(exc, cfg.source) from exc
        raise


def sim_world(cfg: RigConfig) -> Any:
    """The simulated world for a config: its model with one twin per drive, on one device bus per bus."""
    from joints.sim.world import BusSpec, DriveSpec, World

    try:
        buses = {}
        for name, b in cfg.buses.items():
            proto = registry.protocol(b.protocol, key=f"buses.{name}.protocol")
            buses[name] = BusSpec(name, b.protocol, functools.partial(proto.device_bus, b), proto.sim_transport)
        drives = []
        for name, j in cfg.joints.items():
            fam = registry.family(j.device, key=f"joints.{name}.device")
            drives.append(DriveSpec(bus=j.bus, name=name, mjcf_joint=j.mjcf_joint or name, address=j.address,
                                    profile=fam.config_profile(j), device=j.device, channel=j.channel,
                                    protocol=cfg.buses[j.bus].protocol, maker=fam))
        return World(cfg.sim.model, drives, buses=buses, timestep=cfg.sim.timestep, base_dir=cfg.base_dir)
    except ConfigError as exc:  # `joints sim serve` comes here directly: name the file too
        if exc.file is None:
            raise _in_file(exc, cfg.source) from exc
        raise


def open_sim(cfg: RigConfig) -> Rig:
    """Build the sim backend: world + emulated drives + in-process links, same drivers as hardware."""
    world = sim_world(cfg)
    transports = {name: world.transport(name) for name in cfg.buses}
    clock: Clock = world.clock
    if cfg.sim.realtime:
        from joints.sim.pacing import RealtimeClock

        clock = RealtimeClock(world)
    peers = ({name: world.buses[name] for name in cfg.buses
              if registry.protocol(cfg.buses[name].protocol).direct} if cfg.sim.direct else None)
    return build(cfg, transports=transports, clock=clock, world=world, peers=peers)
