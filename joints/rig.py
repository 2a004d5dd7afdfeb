"""Rig: config -> buses, joints, (sim world) and one clock; the ``with`` block that keeps it safe.

Rule: leaving the rig - normally or by an exception - stops and disables every joint this rig
enabled (``on_exit = "disable"``, the default), then closes the buses. Shutdown errors of one
joint never prevent the others from being shut down.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

from joints.clock import Clock, MonotonicClock
from joints.config import BusConfig, RigConfig, load, parse
from joints.errors import ConfigError, JointsError
from joints.joint import Joint, JointState
from joints.link.modbus import ModbusLink, RetryPolicy
from joints.link.trace import TraceRecord
from joints.transports.base import ByteTransport

log = logging.getLogger("joints")


@dataclass
class Bus:
    """One configured bus: its transport and link."""

    config: BusConfig
    transport: ByteTransport
    link: ModbusLink


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
        groups: dict[int, Any] = {}
        for bus in self.buses:
            for name, j in self.joints.items():
                if self.config.joints[name].bus != bus:
                    continue
                group = getattr(j.driver, "status_group", None)
                if group is None:
                    out[name] = j.state()
                    continue
                if id(group) not in groups:
                    groups[id(group)] = (group.read_status(), self.clock.now())
                block, t = groups[id(group)]
                out[name] = j.to_si(j.driver.state_from(block, t))  # type: ignore[attr-defined]
        return {name: out[name] for name in self.joints if name in out}

    def set_velocities(self, velocities: Mapping[str, float]) -> None:
        """Set several joints' velocities [rad/s] at once; every command is checked first.

        Joints on one drive that supports synchronous commands (both wheels of a ZLAC8015D) get one
        FC16 for both targets; the others are commanded one by one.
        """
        checked = {name: self.joints[name].velocity_command(v) for name, v in velocities.items()}
        done: set[str] = set()
        for name, (v, acc) in checked.items():
            driver = self.joints[name].driver
            group = getattr(driver, "status_group", None)
            sync = getattr(group, "set_velocity_pair", None)
            if sync is not None and name not in done:
                pair = {n: self.joints[n] for n in checked if getattr(self.joints[n].driver, "status_group", None) is group}
                if len(pair) == 2:
                    sync({getattr(j.driver, "side"): checked[n] for n, j in pair.items()})  # noqa: B009
                    done.update(pair)
                    continue
            if name not in done:
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
            setter = getattr(j.driver, "set_communication_timeout", None)
            if watchdog is not None and setter is not None:
                setter(watchdog)  # the power cycle restored the drive's default: re-apply the config

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
        if self.world is not None and hasattr(self.world, "close"):
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


def _open_hardware_transport(cfg: BusConfig) -> ByteTransport:
    if cfg.protocol == "modbus-rtu":
        from joints.transports.serial import SerialTransport

        if cfg.port is None:  # e.g. a sim config opened with backend="hardware"
            raise ConfigError("is required for backend = \"hardware\" (e.g. \"/dev/ttyUSB0\")",
                              key=f"buses.{cfg.name}.port")
        return SerialTransport(cfg.port, cfg.baudrate, parity=cfg.parity, stopbits=cfg.stopbits)
    raise ConfigError(f"protocol {cfg.protocol!r} has no transport yet", key=f"buses.{cfg.name}.protocol")


def _in_file(exc: ConfigError, source: str) -> ConfigError:
    """The same error, naming the config file (errors from below the config know only the key)."""
    return ConfigError(exc.message, file=source, key=exc.key, allowed=exc.allowed)


def build(config: RigConfig, *, transports: Mapping[str, ByteTransport] | None = None,
          clock: Clock | None = None, world: Any = None, peers: Mapping[str, Any] | None = None) -> Rig:
    """Assemble a rig from a validated config and ready transports (one per bus).

    ``peers`` (sim): bus name -> emulated bus answering message objects; those buses get the
    direct link (no bytes) instead of the byte path.
    """
    from joints.drivers import make_driver

    clock = clock or MonotonicClock()
    opened: dict[str, ByteTransport] = dict(transports or {})
    buses: dict[str, Bus] = {}
    try:
        for name, bcfg in config.buses.items():
            if name not in opened:
                opened[name] = _open_hardware_transport(bcfg)
            link = ModbusLink(
                opened[name],
                peer=peers.get(name) if peers else None,
                policy=RetryPolicy(timeout=bcfg.timeout, retries=bcfg.retries),
                echo=bcfg.echo,
                clock=clock,
                name=name,
            )
            buses[name] = Bus(bcfg, opened[name], link)
        joints: dict[str, Joint] = {}
        shared: dict[Any, Any] = {}
        for name, jcfg in config.joints.items():
            driver = make_driver(jcfg, buses[jcfg.bus].link, clock, shared)
            joints[name] = Joint(name, driver, clock=clock, limits=jcfg.limits, motion=jcfg.motion,
                                 offset=jcfg.offset, direction=jcfg.direction)
            if jcfg.watchdog_ms is not None and hasattr(driver, "set_communication_timeout"):
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
    """The simulated world for a config: its model with one emulated drive per joint."""
    from joints.drivers import device_profile
    from joints.sim.world import DriveSpec, World

    drives = []
    try:
        for name, j in cfg.joints.items():
            drives.append(DriveSpec(bus=j.bus, name=name, mjcf_joint=j.mjcf_joint or name, address=j.address,
                                    profile=device_profile(j), device=j.device, channel=j.channel))
        return World(cfg.sim.model, drives, timestep=cfg.sim.timestep, base_dir=cfg.base_dir)
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
    peers = {name: world.buses[name] for name in cfg.buses if name in world.buses} if cfg.sim.direct else None
    return build(cfg, transports=transports, clock=clock, world=world, peers=peers)
