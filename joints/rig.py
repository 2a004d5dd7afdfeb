"""Rig: config -> buses, joints, (sim world) and one clock; the ``with`` block that keeps it safe.

Rules:

* Leaving the rig by any path - normal exit, an exception, KeyboardInterrupt, SIGTERM/SIGHUP, or
  interpreter exit with the rig still open - stops and disables every joint this rig enabled
  (``on_exit = "disable"``, the default), then closes the buses. A joint whose shutdown fails (or is
  interrupted) never keeps the others from being shut down; ``close()`` is idempotent and counts the
  rig closed only when everything was tried.
* Waiting is talking: :meth:`Rig.sleep` keeps every enabled drive's communication alive at a
  rate derived from its watchdog and refreshes the joints' states while it waits, so a drive
  that faults anyway is seen - by name - at the next call.
"""

from __future__ import annotations

import functools
import logging
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, TypeGuard

from joints import exits, registry
from joints.clock import Clock, MonotonicClock
from joints.config import BusConfig, RigConfig, load, parse
from joints.drivers.base import RawState, sampled_at
from joints.drivers.capabilities import (
    CommunicationWatchdog,
    CycleGroup,
    CyclicJoint,
    DriveGroup,
    GroupedChannel,
    MovedTogether,
    SampledTogether,
    SyncVelocityGroup,
)
from joints.errors import CommandError, ConfigError, DeviceFault, JointsError, UnknownJoint
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


class JointMap(dict[str, Joint]):
    """The rig's joints by name; an unknown name is an error that lists the known ones."""

    def __missing__(self, key: str) -> Joint:
        raise UnknownJoint(f"no joint named {key!r}; the rig has {sorted(self)}")


#: a joint's keep-alive period is this fraction of its watchdog time
KEEPALIVE_FRACTION = 0.25


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
        self.joints: JointMap = JointMap(joints)
        self.world = world  #: the simulation (sim backend) or None
        #: keep enabled drives fed while waiting (switch off only to test what a silent host does)
        self.keepalive = True
        for j in self.joints.values():
            j.sleep = self.sleep  # a joint's waits keep the other drives fed too
        self._closed = False
        self._shut: set[str] = set()
        self._order: list[tuple[str, Joint]] | None = None
        self._channels: dict[str, GroupedChannel | None] = {}
        self._together: dict[str, SampledTogether | None] = {}
        self._moved: dict[str, MovedTogether | None] = {}
        self._sync_groups: dict[int, tuple[DriveGroup, bool]] = {}
        exits.register(self)

    @property
    def backend(self) -> str:
        return self.config.backend

    @property
    def sim(self) -> Any:
        """The simulated world (:class:`joints.sim.world.World`: ``model``, ``data``, ``joint(name)``,
        ``perturb``, ``restore``, ``set_joint_positions``, ``joint_position`` ...); None on hardware."""
        return self.world

    def model_path(self) -> Path:
        """The MJCF file the config names (``[sim] model``), on either backend (e.g. to render a twin)."""
        from joints.sim.world import resolve_model

        return resolve_model(self.config.sim.model, self.config.base_dir)

    @property
    def time(self) -> float:
        """Seconds on the rig's clock (simulated time in sim)."""
        return self.clock.now()

    def sleep(self, seconds: float) -> None:
        """Sim: advance the world by ``seconds``; hardware: wait on the wall clock.

        Meanwhile every enabled joint whose drive has a communication watchdog is read at least
        every quarter of its watchdog time (its state refreshed, its watchdog fed).
        """
        if (type(seconds) is not float or not 0.0 <= seconds < math.inf) and (  # a finite float >= 0 is fine
                isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not math.isfinite(seconds)
                or seconds < 0):
            raise ValueError(f"cannot sleep {seconds!r} s (need a finite time >= 0)")
        clock = self.clock
        end = clock.now() + seconds
        while True:
            now = clock.now()
            for j in self.joints.values() if self.keepalive else ():
                w = j.watchdog_ms
                if w and j.last_contact + w * 1e-3 * KEEPALIVE_FRACTION < end:
                    break  # this joint's keep-alive falls due before the end, if it is enabled
            else:  # no joint's falls due before the end, enabled or not: nothing to ask
                if end > now:
                    clock.sleep(end - now)
                return
            due, names = self._keepalive_due()
            if due is None or due >= end:
                if end > now:
                    clock.sleep(end - now)
                return
            if due > now:
                clock.sleep(due - now)
            self.read_states(names)

    def sleeps_quietly(self, end: float) -> bool:
        """Whether :meth:`sleep` until rig time ``end`` (give or take a microsecond) would be the clock's sleep
        alone: this class's own :meth:`sleep`, and no joint's keep-alive falls due before ``end``."""
        if type(self).sleep is not _RIG_SLEEP or "sleep" in vars(self):
            return False
        if self.keepalive:
            margin = end + 1e-6
            for j in self.joints.values():
                w = j.watchdog_ms
                if w and j.last_contact + w * 1e-3 * KEEPALIVE_FRACTION < margin:
                    return False
        return True

    def _keepalive_due(self) -> tuple[float | None, list[str]]:
        """The earliest time an enabled joint must be talked to, and which joints are due then."""
        if not self.keepalive:
            return None, []
        due: float | None = None
        names: list[str] = []
        for name, j in self.joints.items():
            if not j.watchdog_ms or not j.enabled:
                continue
            t = j.last_contact + j.watchdog_ms * 1e-3 * KEEPALIVE_FRACTION
            if due is None or t < due - 1e-9:
                due, names = t, [name]
            elif t <= due + 1e-9:
                names.append(name)
        return due, names

    def read_states(self, names: Iterable[str] | None = None) -> dict[str, JointState]:
        """State of every joint (or of ``names``), bus by bus: one status transaction per drive.

        Joints that are channels of one drive (the two wheels of a ZLAC8015D) are served by one
        status read of that drive; the joints one broadcast samples together (the CANopen joints of a
        bus: one SYNC) by one read of them all, at the first of them.
        """
        wanted = set(self.joints) if names is None else {self.joints[n].name for n in names}
        out: dict[str, JointState] = {}
        groups: dict[int, tuple[Mapping[str, int], float]] = {}
        sampled: dict[int, Mapping[Any, RawState]] = {}
        for name, j in self._bus_order():
            if name not in wanted:
                continue
            driver = self._grouped(name)
            if driver is None:
                together = self._sampled_together(name)
                if together is None:
                    out[name] = j.state()
                    continue
                sample = together.sample_group
                if id(sample) not in sampled:
                    sampled[id(sample)] = sample.read_states(
                        [self.joints[n].driver for n, _ in self._bus_order() if n in wanted
                         and (other := self._sampled_together(n)) is not None and other.sample_group is sample])
                out[name] = j.to_si(sampled[id(sample)][j.driver])
                continue
            group: DriveGroup = driver.group
            if id(group) not in groups:
                t0 = self.clock.now()
                block = group.read_status()
                groups[id(group)] = (block, sampled_at(t0, self.clock.now()))
            block, t = groups[id(group)]
            out[name] = j.to_si(driver.state_from(block, t))
        return {name: out[name] for name in self.joints if name in out}

    def _bus_order(self) -> list[tuple[str, Joint]]:
        """The joints bus by bus (the order read_states talks to them)."""
        order = self._order
        if order is None:
            order = self._order = [(name, j) for bus in self.buses for name, j in self.joints.items()
                                   if self.config.joints[name].bus == bus]
        return order

    def samples_together(self, name: str) -> bool:
        """Whether joint ``name`` is sampled with others of its bus by one broadcast (a CANopen SYNC):
        :meth:`read_states` reads those together, one sample instant for all."""
        return self._sampled_together(self.joints[name].name) is not None

    def _sampled_together(self, name: str) -> SampledTogether | None:
        """The joint's driver if its bus samples it with others (checked once per joint)."""
        if name not in self._together:
            driver = self.joints[name].driver
            self._together[name] = driver if isinstance(driver, SampledTogether) else None
        return self._together[name]

    def _grouped(self, name: str) -> GroupedChannel | None:
        """The joint's driver if it is a channel of a multi-channel drive (checked once per joint)."""
        if name not in self._channels:
            driver = self.joints[name].driver
            self._channels[name] = driver if isinstance(driver, GroupedChannel) else None
        return self._channels[name]

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
            grouped = self._grouped(name)
            if grouped is not None and self._sync(grouped.group):
                group = grouped.group
                members: dict[str, GroupedChannel] = {}
                for n in checked:
                    d = self._grouped(n)
                    if d is not None and d.group is group:
                        members[n] = d
                if {d.channel for d in members.values()} == set(group.channels):
                    group.set_channel_velocities({d.channel: checked[n] for n, d in members.items()})
                    done.update(members)
                    continue
            driver.set_velocity(v, acceleration=acc, deceleration=acc)
            done.add(name)

    def move_together(self, positions: Mapping[str, float]) -> None:
        """Move several joints to positions [rad], each with its configured profile (as ``joint.move_to``); every
        command is checked first.

        The joints whose set-points one broadcast acknowledges (the CANopen joints of a bus in profile position:
        each RPDO, then one SYNC for all) are sent together at the first of them; the others one by one.
        """
        checked = {name: self.joints[name].position_command(p) for name, p in positions.items()}
        done: set[str] = set()
        for name, (target, speed, acc, dec) in checked.items():
            if name in done:
                continue
            joint = self.joints[name]
            mover = self._moved_together(name)
            if mover is None:
                joint.driver.move_to(target, speed=speed, acceleration=acc, deceleration=dec)
                joint.note_contact()
                done.add(name)
                continue
            group = mover.setpoint_group
            members = [n for n in checked if n not in done
                       and (other := self._moved_together(n)) is not None and other.setpoint_group is group]
            group.move_together({self.joints[n].driver: checked[n] for n in members})
            for n in members:
                self.joints[n].note_contact()
            done.update(members)

    def _moved_together(self, name: str) -> MovedTogether | None:
        """The joint's driver if its bus acknowledges its set-points with others' (checked once per joint)."""
        if name not in self._moved:
            driver = self.joints[name].driver
            self._moved[name] = driver if isinstance(driver, MovedTogether) else None
        return self._moved[name]

    def _sync(self, group: DriveGroup) -> TypeGuard[SyncVelocityGroup]:
        """Whether a drive takes its channels' velocities in one command (checked once per drive)."""
        known = self._sync_groups.get(id(group))
        if known is None or known[0] is not group:
            known = self._sync_groups[id(group)] = (group, isinstance(group, SyncVelocityGroup))
        return known[1]

    def cycle(self, targets: Mapping[str, float]) -> dict[str, JointState]:
        """One control cycle of cyclic joints (CANopen csp/csv/cst/ip): set-points in, that cycle's feedback out.

        ``targets``: joint name -> position [rad] (csp, ip), velocity [rad/s] (csv) or torque [N*m]
        (cst), each checked against the joint's limits before anything is sent. Per bus: wait until
        the cycle is due (``sync_period`` after the last one: lockstep on the simulated clock in
        sim), send every joint's RPDO and ONE SYNC, then return as soon as every joint's TPDO of
        that cycle is in (a TPDO later than the period counts as late: ``rig.cycle_late()``).
        Buses run side by side. A node that goes silent (heartbeat consumer, node guarding) stops
        every other joint of the call and raises :class:`~joints.errors.DeviceFault` naming it.
        """
        plans: dict[int, tuple[CycleGroup, dict[object, int]]] = {}
        names: dict[int, str] = {}
        for name, value in targets.items():
            j = self.joints[name]
            driver = j.driver
            if not isinstance(driver, CyclicJoint):
                raise CommandError(f"joint {name}: {driver.device} over {driver.protocol} has no cyclic mode")
            raw = j.cycle_target(value, driver.cycle_kind)
            group = driver.group
            plans.setdefault(id(group), (group, {}))[1][driver] = raw
            names[id(driver)] = name
        for group, cmds in plans.values():
            group.send(cmds)
        out: dict[str, JointState] = {}
        try:
            for group, _cmds in plans.values():
                for member, raw_state in group.collect().items():
                    name = names[id(member)]
                    out[name] = self.joints[name].to_si(raw_state)
        except DeviceFault as exc:
            for name in targets:
                if name != exc.device and self.joints[name].enabled:
                    try:
                        self.joints[name].stop()
                    except JointsError as stop_exc:  # keep stopping the others
                        log.error("stopping joint %s after %s failed: %s", name, exc, stop_exc)
            raise
        return {name: out[name] for name in targets}

    def cycle_late(self) -> int:
        """Feedback frames (TPDOs) that missed their cycle, over every bus, since the rig opened."""
        groups = {id(j.driver.group): j.driver.group for j in self.joints.values() if isinstance(j.driver, CyclicJoint)}
        return sum(g.late for g in groups.values())

    def reset(self, seed: int | None = None) -> None:
        """Sim: physics to the model's initial state and every emulated drive to power-on.

        Drivers forget what they wrote (the drives lost it) and joints count as disabled. ``seed``: the
        twins' sensor noise restarts from it (each twin its own stream); None: from the last seed given.
        On hardware this raises: a real robot cannot be reset by software.
        """
        if self.world is None or self.backend != "sim":
            raise JointsError("reset() is only available with backend = \"sim\" (a mixed rig has real joints)")
        self.world.reset(seed)
        for j in self.joints.values():
            j.driver_reset()


    def trace(self, sink: Callable[[TraceRecord], None] | None) -> None:
        """Route every frame of every bus to ``sink`` (None stops tracing)."""
        for b in self.buses.values():
            b.link.trace = sink

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Stop and disable what this rig enabled (per ``on_exit``), then close the buses.

        Every joint is tried even if another one fails or a KeyboardInterrupt / signal arrives in
        the middle (that interruption is raised again once everything was tried). Calling it again
        after an interrupted close finishes what was left; after a complete close it does nothing.
        """
        if self._closed:
            return
        errors: list[BaseException] = []
        interrupted: BaseException | None = None
        if self.config.on_exit != "none":
            for name, j in self.joints.items():
                if name in self._shut:
                    continue
                try:
                    if self.config.on_exit == "disable":
                        j.shutdown()
                    elif j.enabled:
                        j.stop()
                    self._shut.add(name)
                except Exception as exc:  # noqa: BLE001 - keep shutting the others down
                    log.error("shutdown of joint %s failed: %s", j.name, exc)
                    errors.append(exc)
                    self._shut.add(name)  # tried: a second close() would fail the same way
                except BaseException as exc:  # noqa: BLE001 - KeyboardInterrupt, a signal: finish the others first
                    log.error("shutdown of joint %s interrupted (%s); shutting the others down", j.name,
                              type(exc).__name__)
                    interrupted = interrupted or exc
                    try:  # the interrupted joint gets one more, uninterrupted try
                        j.shutdown()
                        self._shut.add(name)
                    except BaseException as again:  # noqa: BLE001 - reported with the others below
                        errors.append(again)
        if interrupted is not None and len(self._shut) < len(self.joints) and self.config.on_exit != "none":
            raise interrupted  # something is left: close() again finishes it
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
        self._closed = True
        exits.unregister(self)
        if interrupted is not None:
            raise interrupted
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


#: :meth:`Rig.sleep` as defined (:meth:`Rig.sleeps_quietly`: a replaced one is not the clock's sleep alone)
_RIG_SLEEP = Rig.sleep


def sleep_together(rigs: Sequence[Rig], seconds: float | Sequence[float]) -> None:
    """:meth:`Rig.sleep` of several rigs (``seconds`` each, or one time for all), at once.

    Simulated rigs advance together: their worlds join one stepping group and one compiled call
    runs every drive's loops and every world's physics (N rigs of a batched env in one process,
    each with its own model). The result is that of sleeping each rig in turn. A rig that must
    talk to a drive during the sleep (a watchdog keep-alive falls due) or runs on hardware sleeps
    on its own.
    """
    from joints.sim.world import advance_together

    times = [seconds] * len(rigs) if isinstance(seconds, (int, float)) else list(seconds)
    if len(times) != len(rigs):
        raise ValueError(f"{len(rigs)} rigs but {len(times)} times")
    worlds: list[Any] = []
    spans: list[float] = []
    for rig, t in zip(rigs, times):
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t) or t < 0:
            raise ValueError(f"cannot sleep {t!r} s (need a finite time >= 0)")
        now = rig.clock.now()
        end = now + t
        due, _names = rig._keepalive_due()
        if rig.world is None or (due is not None and due < end):
            rig.sleep(t)
        elif end > now:  # as Rig.sleep: the clock sleeps end - now
            worlds.append(rig.world)
            spans.append(end - now)
    if worlds:
        advance_together(worlds, spans)


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
            watchdog = jcfg.watchdog_ms if jcfg.watchdog_ms is not None else fam.watchdog_ms
            joints[name] = Joint(name, driver, clock=clock, limits=jcfg.limits, motion=jcfg.motion,
                                 offset=jcfg.offset, direction=jcfg.direction, lead=jcfg.lead,
                                 watchdog_ms=watchdog if isinstance(driver, CommunicationWatchdog) else None)
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
        cfg = config if backend is None else config.with_backend(backend)
    elif isinstance(config, Mapping):
        cfg = parse(config, backend=backend)
    else:
        cfg = load(Path(config), backend=backend)
    try:
        if cfg.backend == "sim":
            return open_sim(cfg)
        if cfg.backend == "mixed":
            return open_mixed(cfg)
        return build(cfg)
    except ConfigError as exc:
        if exc.file is None:
            raise _in_file(exc, cfg.source) from exc
        raise


def sim_world(cfg: RigConfig) -> Any:
    """The simulated world for a config: its model with one twin per drive, on one device bus per bus.

    A mixed config's hardware buses get no twins: their joints are the world's measured
    (kinematic) joints instead.
    """
    from joints.sim.world import BusSpec, DriveSpec, World

    try:
        buses = {}
        for name, b in cfg.buses.items():
            if b.backend != "sim":
                continue
            proto = registry.protocol(b.protocol, key=f"buses.{name}.protocol")
            buses[name] = BusSpec(name, b.protocol, functools.partial(proto.device_bus, b),
                                  functools.partial(proto.sim_transport, config=b))
        drives = []
        kinematic = {}
        for name, j in cfg.joints.items():
            if j.bus not in buses:
                kinematic[name] = j.mjcf_joint or name
                continue
            fam = registry.family(j.device, key=f"joints.{name}.device")
            drives.append(DriveSpec(bus=j.bus, name=name, mjcf_joint=j.mjcf_joint or name, address=j.address,
                                    profile=fam.config_profile(j), device=j.device, channel=j.channel,
                                    protocol=cfg.buses[j.bus].protocol, maker=fam, lead=j.lead,
                                    extra={"firmware": j.firmware} if j.firmware is not None else {}))
        return World(cfg.sim.model, drives, buses=buses, timestep=cfg.sim.timestep, base_dir=cfg.base_dir,
                     kinematic=kinematic or None)
    except ConfigError as exc:  # `joints sim serve` comes here directly: name the file too
        if exc.file is None:
            raise _in_file(exc, cfg.source) from exc
        raise


def served_timing(cfg: RigConfig) -> dict[str, Any]:
    """The real bus's time of every simulated bus of ``cfg`` (:class:`joints.sim.served_timing.BusTiming`):
    wire time from the bus's line settings, each drive's turnaround from its profile, the bus's
    ``adapter_latency`` (the medium's default where it sets none, as in process) and ``timing`` (what ``joints sim serve`` holds requests and replies for)."""
    from joints.sim import served_timing as st

    out: dict[str, Any] = {}
    for name, b in cfg.buses.items():
        if b.backend != "sim":
            continue
        proto = registry.protocol(b.protocol, key=f"buses.{name}.protocol")
        turnarounds: dict[int, float] = {}
        for jname, j in cfg.joints.items():
            if j.bus == name:
                prof = registry.family(j.device, key=f"joints.{jname}.device").config_profile(j)
                turnarounds[j.address] = max(turnarounds.get(j.address, 0.0), float(prof.turnaround))
        latency = registry.adapter_latency(b)  # as in process: the medium's default where the bus sets none
        ideal = b.timing == "ideal"
        if proto.medium == "can":
            out[name] = st.BusTiming.can(bitrate=b.bitrate, adapter_latency=latency, turnarounds=turnarounds,
                                         ideal=ideal)
        else:
            out[name] = st.BusTiming.serial(baudrate=b.baudrate, parity=b.parity, stopbits=b.stopbits,
                                            rtu=proto.silence, adapter_latency=latency, turnarounds=turnarounds,
                                            ideal=ideal)
    return out


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


#: s between two reads of a mixed rig's real joints while it sleeps (the world's measured joints)
MIXED_REFRESH = 0.005


def open_mixed(cfg: RigConfig) -> Rig:
    """A rig with hardware and simulated buses (see :class:`joints.sim.pacing.MixedClock`).

    The simulated buses are in-process twins in one world; the hardware buses' joints are the
    world's measured joints: at every transaction (and while the rig sleeps) the world catches up
    with the wall clock and the real joints' measured positions and velocities drive their MuJoCo
    joints (prescribed motion),
    so the simulated joints feel them through the model. The real joints do not feel the
    simulated ones (no force goes back to hardware).
    """
    from joints.sim.pacing import MixedClock

    world = sim_world(cfg)
    clock = MixedClock(world, period=MIXED_REFRESH)
    sim_buses = [name for name, b in cfg.buses.items() if b.backend == "sim"]
    # the timed lines wait on the mixed clock (the wall clock), not the world's own: the world follows it
    transports = {name: world.bus_specs[name].transport(world.buses[name], clock=clock) for name in sim_buses}
    peers = ({name: world.buses[name] for name in sim_buses
              if registry.protocol(cfg.buses[name].protocol).direct} if cfg.sim.direct else None)
    rig = build(cfg, transports=transports, clock=clock, world=world, peers=peers)
    measured = [(name, rig.joints[name]) for name in world.kinematic]
    last = [-math.inf]

    def refresh() -> None:
        now = clock.wall()
        if now - last[0] < MIXED_REFRESH:
            return
        last[0] = now
        for name, j in measured:
            s = j.last_state
            if s is None or now - s.time > MIXED_REFRESH:
                try:
                    s = j.state()
                except JointsError as exc:  # the next command or state read reports it
                    log.warning("mixed rig: reading joint %s for the simulation failed: %s", name, exc)
                    continue
            world.set_measured(name, (s.position - j.offset) * j.direction, s.velocity * j.direction, s.time)

    def feed() -> None:
        """The real joints' latest states (whatever the host read last) to the world: no bus traffic."""
        for name, j in measured:
            s = j.last_state
            if s is not None:
                world.set_measured(name, (s.position - j.offset) * j.direction, s.velocity * j.direction, s.time)

    clock.refresh = refresh
    clock.feed = feed
    return rig
