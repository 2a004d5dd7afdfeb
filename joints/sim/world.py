"""The simulated world: a MuJoCo model whose joints are driven by emulated drives.

Rule: two rates. Every physics substep, each emulated drive runs its own loops from its own
registers and writes a torque to its MuJoCo ``motor`` actuator; register traffic happens between
substeps, at the caller's rate, on the simulated clock (lockstep). Actuator and joint parameters
(armature = reflected rotor inertia, damping, friction loss, torque range) come from the device
profile, not from the XML. Nothing here reads the wall clock.

Measured joints (a mixed rig's real joints, ``kinematic``): the latest measurement of position
and velocity is written into the joint after every substep (extrapolated at the measured velocity
for at most :data:`KINEMATIC_HORIZON`), so the emulated joints feel the real ones through the
model - their motion, not the forces the emulated ones exert back on them. During a substep a
measured joint is prescribed, not free: its armature is :data:`KINEMATIC_ARMATURE` (and it has no
damping or friction), so no force of the model accelerates it and it moves on at its measured
velocity while the emulated joints are integrated against that motion.

Joints: a hinge is driven directly (joint angle = motor angle). A slide is driven through a lead
screw: its drive's ``lead`` [m per motor turn] gives the ratio r = 2 pi / lead [rad per m]; the
motor torque becomes the force r x torque on the slide (the actuator's gear), the rotor inertia
the armature r^2 J, the motor's viscous and Coulomb friction r^2 b and r c; the twin sees the
motor angle r x q. End-stop switches: a slide whose model has the sites ``<joint>_switch_low`` and
``<joint>_switch_high`` (fixed) and ``<joint>_switch_flag`` (on the moving body) tells a twin that
has end-stop inputs (:class:`EndStops`) the motor angles where the flag reaches each switch.
"""

from __future__ import annotations

import logging
import math
import threading
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

from joints.clock import ManualClock
from joints.errors import ConfigError, MissingDependencyError
from joints.sim import firmware, kernel, sensors, stepping

#: s a measured joint's last measurement is extrapolated at its velocity (then it is held)
KINEMATIC_HORIZON = 0.05
#: kg*m^2 (kg on a slide) of armature that makes a measured joint prescribed: any force the model puts
#: on it (1e3 N*m) accelerates it by 1e-6 rad/s^2
KINEMATIC_ARMATURE = 1e9


def _mujoco() -> Any:
    try:
        import mujoco
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise MissingDependencyError("mujoco", "sim") from exc
    return mujoco


def model_dirs() -> list[Path]:
    """Where bundled models are looked for: the installed ``joints.models`` package, then ./models."""
    dirs: list[Path] = []
    try:
        dirs.append(Path(str(resources.files("joints.models"))))
    except (ModuleNotFoundError, TypeError):
        pass
    dirs.append(Path(__file__).resolve().parents[2] / "models")
    return dirs


def resolve_model(name: str | Path, base_dir: Path | None = None) -> Path:
    """A model file: an existing path (relative to ``base_dir``), or a file shipped in models/."""
    p = Path(name)
    candidates = [p] if p.is_absolute() else [(base_dir or Path.cwd()) / p, p]
    candidates += [d / p.name for d in model_dirs()]
    for c in candidates:
        if c.is_file():
            return c
    shipped = sorted({f.name for d in model_dirs() if d.is_dir() for f in d.glob("*.xml")})
    raise ConfigError(f"model {str(name)!r} not found", key="sim.model", allowed=shipped)


log = logging.getLogger("joints.sim")

#: a profile's friction beyond Coulomb + viscous (optional fields; their defaults add nothing): Stribeck friction
#: N*m at standstill, its velocity and exponent; friction per |motor torque|, per motor torque^2, per |external torque|
STATE_FRICTION = {"stribeck_friction": 0.0, "stribeck_velocity": 1.0, "stribeck_exponent": 2.0, "load_friction": 0.0,
                  "load_friction_quadratic": 0.0, "external_friction": 0.0}
STATE_FRICTION_ON = ("stribeck_friction", "load_friction", "load_friction_quadratic", "external_friction")


class JointProfile(Protocol):
    """What the world needs from a device profile to set up a joint and its motor."""

    armature: float
    viscous_friction: float
    coulomb_friction: float
    max_torque: float


class Stepper(Protocol):
    """What runs one joint's drive loops every substep."""

    def step(self, t: float, dt: float, q: float, qd: float) -> float:
        """Run the loops for the substep ending at ``t``; return the motor torque [N*m]."""
        ...

    def place(self, q: float) -> None:
        """The joint is at ``q`` and at rest (start state): encoder and setpoints follow."""
        ...


class TwinMaker(Protocol):
    """Builds one drive's twin and its protocol front (the registry's device families are makers)."""

    def build_twin(self, specs: Sequence[DriveSpec], inertia: Mapping[str, float]) -> tuple[Any, Mapping[Any, Stepper]]:
        """The twin of one drive serving ``specs`` (one per channel; it has ``power_cycle()`` and a ``time``
        attribute) and the stepper of each spec's channel (``None`` for a single-channel drive)."""
        ...

    def front(self, protocol: str, twin: Any, address: int) -> Any:
        """The object that answers ``protocol`` frames for ``twin`` at ``address`` on a device bus."""
        ...


@runtime_checkable
class EndStops(Protocol):
    """A twin with end-stop switch inputs (the world computes where they trigger from the geometry)."""

    def set_end_stops(self, low: float | None, high: float | None) -> None:
        """Motor angles [rad] at or below / at or above which the low / high switch is triggered."""
        ...


@runtime_checkable
class TimedDeviceBus(Protocol):
    """A device bus that lives on the simulated clock (a CAN medium: frames take wire time)."""

    def bind_clock(self, clock: Any) -> None:
        """Run on the world's clock from now on."""
        ...

    def tick(self, t: float) -> None:
        """The world finished the physics substep ending at ``t``."""
        ...


@runtime_checkable
class Announcing(Protocol):
    """A timed device bus that says when its next tick has work: the world runs the substeps before it in
    one compiled call and ticks once (ticks before it would only move the bus's time)."""

    def next_event(self) -> float:
        """The earliest substep end ``t`` at which ``tick(t)`` acts (``math.inf``: none is queued;
        ``-math.inf``: tick every substep)."""
        ...


@runtime_checkable
class Watching(Protocol):
    """An announcing timed bus whose devices report a drive's fault by themselves at the substep it trips (a
    CANopen EMCY): a run of substeps in one compiled call ends at the first substep whose end shows one."""

    def watched(self) -> Sequence[tuple[Any, int]]:
        """Kernel cells (twin, column of its first row) whose turning non-zero ends a run of substeps."""
        ...


@dataclass(frozen=True)
class DriveSpec:
    """One emulated joint: which bus/address (and channel) answers for it and which MJCF joint it drives."""

    bus: str
    name: str
    mjcf_joint: str
    address: int
    profile: Any  #: the device profile (anything with the JointProfile fields)
    device: str
    maker: TwinMaker
    protocol: str = "modbus-rtu"
    channel: str | None = None  #: a multi-channel drive's channel ("left" / "right")
    extra: dict[str, Any] = field(default_factory=dict)
    lead: float | None = None  #: m of slide travel per motor turn (a slide joint on a lead screw)


@dataclass(frozen=True)
class BusSpec:
    """One emulated bus: its protocol's device side and the in-process transport to it."""

    name: str
    protocol: str
    device_bus: Callable[[], Any]
    transport: Callable[..., Any]  #: (device bus, clock=the world's clock) -> the host's transport


@dataclass
class _Bound:
    name: str
    emulator: Any  #: the drive's twin (shared by its channels)
    stepper: Stepper  #: what runs the loops of this joint
    qadr: int
    dadr: int
    aid: int
    channel: str | None = None
    mjcf_joint: str = ""
    ratio: float = 1.0  #: motor rad per joint unit (2 pi / lead for a slide, 1 for a hinge)


@dataclass(frozen=True)
class SimJoint:
    """Where one joint of the rig lives in the MuJoCo model (indices into ``model``/``data`` arrays)."""

    name: str  #: the joint's name in the config
    mjcf_joint: str  #: the MJCF joint it drives
    qpos: int  #: index into ``data.qpos``
    dof: int  #: index into ``data.qvel`` and the ``model.dof_*`` arrays
    actuator: int  #: index into ``data.ctrl`` and the ``model.actuator_*`` arrays (its motor)


class Tunable(Protocol):
    """A twin whose loop gains can be scaled (domain randomisation): parameter names per channel."""

    def gain_params(self, channel: str | None) -> Mapping[str, str]:
        """``{"position": name, "speed": name, "integral": name}`` for the channel's loop gains."""
        ...


def _ratio(mj: Any, jnt: Any, d: DriveSpec) -> float:
    """Motor rad per joint unit: 1 for a hinge, 2 pi / lead for a slide (which needs the lead)."""
    if jnt.type == mj.mjtJoint.mjJNT_HINGE:
        if d.lead is not None:
            raise ConfigError(f"MJCF joint {d.mjcf_joint!r} is a hinge: a joint with a lead must be a slide",
                              key=f"joints.{d.name}.lead")
        return 1.0
    if jnt.type == mj.mjtJoint.mjJNT_SLIDE:
        if d.lead is None:
            raise ConfigError(f"MJCF joint {d.mjcf_joint!r} is a slide: give the joint's lead [m per motor turn]",
                              key=f"joints.{d.name}.lead")
        return 2.0 * math.pi / d.lead
    raise ConfigError(f"MJCF joint {d.mjcf_joint!r} must be a hinge (or a slide with a lead)",
                      key=f"joints.{d.name}.mjcf_joint")


def _pending_due(emu: Any) -> Callable[[], float] | None:
    """When a drive with delayed commands next acts (:meth:`joints.sim.firmware.Firmware.tick`: its oldest
    pending write's time, less that tick's 1e-9 s tolerance); None for a twin whose tick does more."""
    if type(emu).tick is not firmware.Firmware.tick:
        return None

    def due() -> float:
        pending = emu.pending
        return pending[0][0] - 1e-9 if pending else math.inf

    return due


def _make_twins(specs: Sequence[DriveSpec], inertia: Mapping[str, float]) -> dict[str, tuple[Any, Stepper]]:
    """Build one twin per drive (bus, address); returns joint name -> (twin, stepper)."""
    out: dict[str, tuple[Any, Stepper]] = {}
    groups: dict[tuple[str, int], list[DriveSpec]] = {}
    for d in specs:
        groups.setdefault((d.bus, d.address), []).append(d)
    for (bus, address), group in groups.items():
        if any(g.device != group[0].device for g in group):
            raise ConfigError(f"bus {bus!r} address {address}: joints of different devices share one address",
                              key=f"joints.{group[0].name}.address")
        channels = [g.channel for g in group]
        if len(set(channels)) != len(channels):
            raise ConfigError(f"bus {bus!r} address {address} is used by {[g.name for g in group]}",
                              key=f"joints.{group[1].name}.address")
        twin, steppers = group[0].maker.build_twin(group, inertia)
        for g in group:
            out[g.name] = (twin, steppers[g.channel])
    return out


class World:
    """MuJoCo model + data + emulated drives + the simulated clock."""

    def __init__(self, model: str | Path, drives: Sequence[DriveSpec], *, buses: Mapping[str, BusSpec],
                 timestep: float = 0.001, base_dir: Path | None = None,
                 kinematic: Mapping[str, str] | None = None, compiled: bool | None = None,
                 jit: bool | None = None) -> None:
        mj = _mujoco()
        self._booked = False  #: time is booked on the clock that the physics has not run yet (:meth:`book`)
        #: of it, the last is a sleep's (:meth:`hold`): its substeps run on their own, before any other advance
        self._held = False
        #: the clock's sleep books its time (:meth:`hold`) instead of stepping at once (:meth:`advance`): for a
        #: world every medium of which settles it (``clock.settle``) before a drive acts on a frame - set by the
        #: compiled path (:class:`joints.CompiledPath`) over the one-call exchanges' timed lines; an ideal
        #: (untimed) transport hands frames to the drives without settling
        self.hold_sleeps = False
        if jit is not None:  # the older name of ``compiled``
            warnings.warn("World(jit=...) is deprecated: use World(compiled=...)", DeprecationWarning, stacklevel=2)
            compiled = jit if compiled is None else compiled
        #: the drives' loops run compiled (numba; :mod:`joints.sim.kernel`) - default: when installed and not
        #: turned off (``JOINTS_COMPILED=0``)
        self.compiled = kernel.default_mode() if compiled is None else bool(compiled and kernel.AVAILABLE)
        self.mujoco = mj
        self.path = resolve_model(model, base_dir)
        spec = mj.MjSpec.from_file(str(self.path))
        spec.option.timestep = timestep
        joint_names = [j.name for j in spec.joints]
        for d in drives:
            jnt = spec.joint(d.mjcf_joint)
            if jnt is None:
                raise ConfigError(
                    f"joint {d.name!r}: MJCF joint {d.mjcf_joint!r} is not in {self.path.name}",
                    key=f"joints.{d.name}.mjcf_joint", allowed=joint_names,
                )
            r = _ratio(mj, jnt, d)
            prof = d.profile
            jnt.armature = prof.armature * r * r
            damping = jnt.damping
            if hasattr(damping, "__len__"):  # MuJoCo >= 4: [linear, quadratic, cubic] coefficients
                jnt.damping = [prof.viscous_friction * r * r] + [0.0] * (len(damping) - 1)
            else:
                jnt.damping = prof.viscous_friction * r * r
            jnt.frictionloss = prof.coulomb_friction * r
            for act in list(spec.actuators):
                if act.target == d.mjcf_joint:
                    spec.delete(act)
            act = spec.add_actuator()
            act.name = f"{d.name}_motor"
            act.trntype = mj.mjtTrn.mjTRN_JOINT
            act.target = d.mjcf_joint
            act.gainprm[0] = 1.0
            act.gear[0] = r  # ctrl is the motor torque; the slide gets r x torque
            act.ctrllimited = 1
            act.ctrlrange = [-prof.max_torque, prof.max_torque]
        self._model = spec.compile()
        self._data = mj.MjData(self._model)
        self.timestep = float(self.model.opt.timestep)
        mj.mj_forward(self.model, self.data)
        self.steps = 0
        self._target = 0.0
        self.clock = ManualClock()
        self.clock.bind(self._sleep, on_book=self.book, on_settle=self.sync)
        addr: dict[str, tuple[int, int, int]] = {}
        ratios: dict[str, float] = {}
        for d in drives:
            jid = mj.mj_name2id(self.model, mj.mjtObj.mjOBJ_JOINT, d.mjcf_joint)
            aid = mj.mj_name2id(self.model, mj.mjtObj.mjOBJ_ACTUATOR, f"{d.name}_motor")
            addr[d.name] = (int(self.model.jnt_qposadr[jid]), int(self.model.jnt_dofadr[jid]), aid)
            ratios[d.name] = float(self.model.actuator_gear[aid, 0])
        # the inertia each drive sees at its motor (joint-space inertia / r^2)
        inertia = {name: self._dof_inertia(dof) / ratios[name] ** 2 for name, (_qa, dof, _aid) in addr.items()}
        made = _make_twins(drives, inertia)
        self._drives: dict[str, Any] = {}  #: joint name -> its drive's twin (shared by channels)
        self.bus_specs = dict(buses)
        self._buses: dict[str, Any] = {name: b.device_bus() for name, b in self.bus_specs.items()}
        self._offer_world()
        self._bound: list[_Bound] = []
        fronts: set[tuple[str, int]] = set()
        for d in drives:
            twin, stepper = made[d.name]
            self._drives[d.name] = twin
            if (d.bus, d.address) not in fronts:
                self._buses[d.bus].add(d.maker.front(d.protocol, twin, d.address))
                fronts.add((d.bus, d.address))
                turnarounds = getattr(self._buses[d.bus], "turnarounds", None)  # bus timing: the drive's turnaround
                if turnarounds is not None:
                    turnarounds[d.address] = float(getattr(d.profile, "turnaround", 0.0))
            qa, da, aid = addr[d.name]
            r = ratios[d.name]
            self._bound.append(_Bound(d.name, twin, stepper, qa, da, aid, d.channel, d.mjcf_joint, r))
            if isinstance(stepper, EndStops):
                stepper.set_end_stops(*self._switches(d.mjcf_joint, qa, r))
            stepper.place(float(self.data.qpos[qa]) * r)
        #: per joint, what steps it: (step function, qpos address, dof address, actuator, motor rad
        #: per joint unit)
        self._bind = [(b.stepper.step, b.qadr, b.dadr, b.aid, b.ratio) for b in self._bound]
        self._bind_seen = list(self._bind)
        self._python_bind = self._stepped_in_python()
        timed = [bus for bus in self._buses.values() if isinstance(bus, TimedDeviceBus)]
        for bus in timed:
            bus.bind_clock(self.clock)
            bind_substep = getattr(bus, "bind_substep", None)
            if bind_substep is not None:  # a bus that ticks only at its events needs the substep (erob_canopen)
                bind_substep(self.timestep)
        #: per timed bus that reports faults by itself (:class:`Watching`), the kernel cells it watches
        self._bus_watches = [bus.watched for bus in timed if isinstance(bus, Watching)]
        self._bus_ticks = [bus.tick for bus in timed]
        #: per timed bus, when its tick next has work (None: the bus does not say; it is ticked every substep)
        self._bus_events: list[Callable[[], float] | None] = [
            bus.next_event if isinstance(bus, Announcing) else None for bus in timed]
        #: what else runs after every substep (drives acting on delayed commands, kinematic joints)
        self._extra_ticks: list[Callable[[float], None]] = []
        self._ticks: list[Callable[[float], None]] = []
        #: when each of ``_ticks`` next has work (None: one of them does not say, so every substep is ticked)
        self._events: list[Callable[[], float]] | None = []
        self._unfused = False
        self._nominal_delay = {id(e): float(getattr(e, "command_delay", 0.0)) for e in self._emulators()}
        self._update_ticks()
        self.joints: dict[str, SimJoint] = {b.name: SimJoint(b.name, b.mjcf_joint, b.qadr, b.dadr, b.aid)
                                            for b in self._bound}
        m = self.model
        self._nominal = {"armature": m.dof_armature.copy(), "frictionloss": m.dof_frictionloss.copy(),
                         "damping": m.dof_damping.copy(), "gear": m.actuator_gear[:, 0].copy()}
        #: friction that depends on the state (a profile's STATE_FRICTION fields, 0 by default: then nothing is
        #: added): (dof, actuator, ratio, stribeck friction, velocity, exponent, load, quadratic, external) per
        #: joint, and the Coulomb friction loss it adds to (perturb scales it)
        self._state_friction = [(addr[d.name][1], addr[d.name][2], ratios[d.name],
                                 *(float(getattr(d.profile, k, v)) for k, v in STATE_FRICTION.items()))
                                for d in drives if any(getattr(d.profile, k, 0.0) for k in STATE_FRICTION_ON)]
        self._coulomb = m.dof_frictionloss.copy()
        if self._state_friction:
            self._friction_tick(0.0)
            self._extra_ticks.append(self._friction_tick)
            self._update_ticks()
        self._nominal_gains: dict[str, dict[str, int]] = {}
        #: one caller steps the physics at a time (two threads sleeping on one rig must not share MjData)
        self.lock = threading.RLock()
        #: joints that follow measurements (a mixed rig's real joints): name -> (qpos address, dof address)
        self.kinematic: dict[str, tuple[int, int]] = {}
        self._measured: dict[str, tuple[float, float, float]] = {}
        for name, mjcf in (kinematic or {}).items():
            jid = mj.mj_name2id(self.model, mj.mjtObj.mjOBJ_JOINT, mjcf)
            if jid < 0:
                raise ConfigError(f"joint {name!r}: MJCF joint {mjcf!r} is not in {self.path.name}",
                                  key=f"joints.{name}.mjcf_joint", allowed=joint_names)
            if name in self.joints:
                raise ConfigError(f"joint {name!r} is both emulated and measured", key=f"joints.{name}")
            self.kinematic[name] = (int(self.model.jnt_qposadr[jid]), int(self.model.jnt_dofadr[jid]))
            dof = self.kinematic[name][1]
            for what, value in (("armature", KINEMATIC_ARMATURE), ("frictionloss", 0.0), ("damping", 0.0)):
                getattr(self.model, f"dof_{what}")[dof] = value  # prescribed motion (module docstring)
                self._nominal[what][dof] = value
        #: the table of the drives' kernel rows this world is stepped with (shared with the worlds
        #: it is batched with: :func:`advance_together`), and this world's index in it
        self.group = stepping.Group([self], self.compiled)
        self.group_index = 0
        self._me: tuple[int, ...] = (0,)  #: (group_index,): what this world's group steps for it
        if self.kinematic:
            self._extra_ticks.append(self._drive_kinematic)
            self._update_ticks()

    def _offer_world(self) -> None:
        """Device buses that take part in a one-call exchange (twin ops and the physics between frames in one
        compiled call: ``ModbusDeviceBus.fused``) learn which world steps between their frames."""
        for bus in self._buses.values():
            if hasattr(bus, "world") and getattr(bus, "world", None) is None:
                bus.world = self

    # -- joints driven by measurements (mixed rigs) -------------------------------------------
    def set_measured(self, name: str, q: float, qd: float, t: float) -> None:
        """A measured joint's position [rad] and velocity [rad/s] (MJCF frame) at time ``t`` [s]."""
        if name not in self.kinematic:
            raise KeyError(f"no measured joint {name!r} (have {sorted(self.kinematic)})")
        if not (math.isfinite(q) and math.isfinite(qd) and math.isfinite(t)):
            raise ValueError(f"joint {name}: measurement must be finite, got {q!r}, {qd!r} at {t!r}")
        self._measured[name] = (float(q), float(qd), float(t))

    def _drive_kinematic(self, t: float) -> None:
        """Every substep: measured joints to their latest measurement, extrapolated at its velocity
        for at most :data:`KINEMATIC_HORIZON` (then held)."""
        qpos, qvel = self.data.qpos, self.data.qvel
        for name, (qa, da) in self.kinematic.items():
            m = self._measured.get(name)
            if m is None:
                continue
            q, qd, tm = m
            age = t - tm
            if age > KINEMATIC_HORIZON:
                qpos[qa] = q + qd * KINEMATIC_HORIZON
                qvel[da] = 0.0
            else:
                qpos[qa] = q + qd * max(age, 0.0)
                qvel[da] = qd

    def _friction_tick(self, t: float) -> None:
        """After every substep: the friction loss of joints with Stribeck or load friction, from the velocity
        and the torques the substep ended with: ``coulomb + r excess exp(-|w / v_s|^a) + load |tau| + quadratic
        tau^2 + external |tau_e|`` (w the motor's velocity, tau the actuator's force on the joint, tau_e the
        joint's bias force: gravity and coupling)."""
        m, d = self.model, self.data
        for dof, aid, r, excess, vs, a, load, quadratic, external in self._state_friction:
            w = abs(float(d.qvel[dof]) * r / vs)
            tau = abs(float(d.actuator_force[aid]))
            m.dof_frictionloss[dof] = (self._coulomb[dof] + r * excess * math.exp(-(w ** a)) + load * tau
                                       + quadratic * tau * tau + external * abs(float(d.qfrc_bias[dof])))

    def _update_ticks(self) -> None:
        """Who is called after substeps: timed buses, drives with a command delay, extra ticks; and whether
        all of them say when they next have work (then only those substeps are ticked, see :meth:`_step`)."""
        delayed = [e for e in self._emulators()
                   if getattr(e, "command_delay", 0.0) > 0 or getattr(e, "pending", None)]
        self._ticks = [*self._bus_ticks, *(e.tick for e in delayed), *self._extra_ticks]
        events = [*self._bus_events, *(_pending_due(e) for e in delayed)]
        self._events = None if self._extra_ticks or any(ev is None for ev in events) else \
            [ev for ev in events if ev is not None]
        group = getattr(self, "group", None)
        if group is not None:  # who can run N substeps in one call changed
            group.replan()

    # -- how the drives are stepped ---------------------------------------------------------------
    def kernel_joints(self) -> list[_Bound]:
        """The joints whose twin runs its loops as kernel rows (:mod:`joints.sim.stepping`)."""
        return [b for b in self._bound if stepping.has_kernel(b.emulator)]

    def kernel_stepped(self, b: _Bound) -> bool:
        """Whether joint ``b`` is stepped by its kernel row (not by a function put in its place)."""
        i = self._bound.index(b)
        return bool(self._bind[i][0] == b.stepper.step)

    def arena_crowded(self, fraction: float) -> bool:
        """Whether MuJoCo's arena was ever more than ``fraction`` full (many contacts/constraints)."""
        return bool(self.data.maxuse_arena > fraction * self.model.narena)

    def leave_fused_path(self) -> None:
        """Step substep by substep from now on (see :data:`joints.sim.stepping.ARENA_GUARD`)."""
        if not self._unfused:
            self._unfused = True
            log.warning("world %s: MuJoCo's arena is over %d%% full; stepping without the fused compiled call "
                        "from now on (an arena overflow then raises mujoco.FatalError; raise <size memory=...>)",
                        self.path.name, round(100 * stepping.ARENA_GUARD))

    def fusable(self) -> bool:
        """Whether N substeps can run in one compiled call: every drive a kernel row, every tick announcing its
        next work (timed buses, delayed commands), an arena with room (the compiled call cannot turn MuJoCo's
        fatal errors into exceptions)."""
        return not self._unfused and self._events is not None and all(self.kernel_stepped(b) for b in self._bound
                                       if stepping.has_kernel(b.emulator)) \
            and len(self.kernel_joints()) == len(self._bound)

    def _switches(self, joint: str, qadr: int, ratio: float) -> tuple[float | None, float | None]:
        """Motor angles where the ``<joint>_switch_flag`` site reaches ``<joint>_switch_low`` / ``_high``
        (a slide's sites; None where the model has no such switch)."""
        mj, m, d = self.mujoco, self.model, self.data
        jid = mj.mj_name2id(m, mj.mjtObj.mjOBJ_JOINT, joint)
        flag = mj.mj_name2id(m, mj.mjtObj.mjOBJ_SITE, f"{joint}_switch_flag")
        if flag < 0 or m.jnt_type[jid] != mj.mjtJoint.mjJNT_SLIDE:
            return None, None
        axis = d.xaxis[jid]
        q = float(d.qpos[qadr])
        out: list[float | None] = []
        for end in ("low", "high"):
            sid = mj.mj_name2id(m, mj.mjtObj.mjOBJ_SITE, f"{joint}_switch_{end}")
            if sid < 0:
                out.append(None)
                continue
            at = q + float((d.site_xpos[sid] - d.site_xpos[flag]) @ axis)  # joint position where they meet
            out.append(at * ratio)
        return out[0], out[1]

    def _dof_inertia(self, dof: int) -> float:
        """Diagonal of the joint-space inertia (incl. armature) at the current pose [kg*m^2]."""
        import numpy as np

        unit = np.zeros(self.model.nv)
        unit[dof] = 1.0
        out = np.zeros(self.model.nv)
        self.mujoco.mj_mulM(self.model, self.data, out, unit)
        return float(out[dof])

    @property
    def time(self) -> float:
        """Simulated seconds of the physics since the last reset (it first catches up with booked time)."""
        if self._booked:
            self.sync()
        return self.steps * self.timestep

    # -- lazy physics: the one rule for reaching the physics or the twins ---------------------------
    @property
    def model(self) -> Any:
        """The MuJoCo model (the physics first catches up with booked time: :meth:`sync`)."""
        if self._booked:
            self.sync()
        return self._model

    @property
    def data(self) -> Any:
        """The MuJoCo data (the physics first catches up with booked time: :meth:`sync`)."""
        if self._booked:
            self.sync()
        return self._data

    @property
    def buses(self) -> dict[str, Any]:
        """Bus name -> its emulated device bus (its fronts reach the twins: the physics first catches up: :meth:`sync`)."""
        if self._booked:
            self.sync()
        return self._buses

    @property
    def drives(self) -> dict[str, Any]:
        """Joint name -> its drive's twin (shared by channels; the physics first catches up: :meth:`sync`)."""
        if self._booked:
            self.sync()
        return self._drives

    def book(self, seconds: float) -> None:
        """Let ``seconds`` pass while nothing acts on the drives (a reply travelling to the host): the clock
        shows the booked instant, the physics runs later - at :meth:`sync` (before anything reads or writes
        the physics or a twin: :attr:`model`, :attr:`data`, :attr:`drives`, a medium about to hand a frame to
        a drive) or at the next :meth:`advance` - in one compiled call with what follows. A world with ticks
        (timed device buses, delayed commands, measured joints, state friction) steps at once."""
        self._defer(seconds, held=False)

    def _defer(self, seconds: float, *, held: bool) -> None:
        """Book ``seconds`` on the clock, the physics run later (:meth:`book`; ``held``: a sleep's, :meth:`hold`).
        An earlier held sleep's substeps run first, on their own (as :meth:`advance` runs them)."""
        if seconds <= 0:
            return
        if self._ticks and not (held and self._ticks_hold()):
            self.advance(seconds)
            return
        with self.lock:
            if self._held:
                self.sync()
            self._target += seconds  # as advance: with any booked time before it, in one count
            self._booked = True
            self._held = held
            self.clock.set(self._target)

    def _ticks_hold(self) -> bool:
        """Whether a sleep may be held on this world with ticks: each tick's owner says so (its ``holds()``: its
        ticks would only move its time over the sleep, and whatever it carries settles the world before use)."""
        for tick in self._ticks:
            holds = getattr(getattr(tick, "__self__", None), "holds", None)
            if holds is None or not holds():
                return False
        return True

    def _sleep(self, seconds: float) -> None:
        """The clock's sleep: :meth:`hold` where :attr:`hold_sleeps`, else :meth:`advance`."""
        if self.hold_sleeps:
            self.hold(seconds)
        else:
            self.advance(seconds)

    def hold(self, seconds: float) -> None:
        """:meth:`advance` by ``seconds``, its physics run lazily - at the next :meth:`sync` (any access to the
        physics or a twin, a timed medium about to hand a frame to a drive), or at the start of the next
        :meth:`advance`/:meth:`book` or one-call exchange (:mod:`joints.sim.line_exchange`), on its own: the
        same substeps as :meth:`advance` runs now, counted the same way. A world with ticks advances at once,
        unless every tick's owner holds the sleep (:meth:`_ticks_hold`: an eRob CAN bus with nothing in flight).
        The clock's sleep where :attr:`hold_sleeps`."""
        self._defer(seconds, held=True)

    def sync(self) -> None:
        """Run the physics up to booked time: the substeps that end at or before it and the one that reaches
        it (as :meth:`advance` would have)."""
        with self.lock:
            if not self._booked:
                return
            self._booked = self._held = False
            self._step_due(self._due(0.0))
            if self._ticks:  # (a held sleep: its last tick set the clock to the substep's end) as advance leaves it
                self.clock.set(self._target)

    def transport(self, bus: str) -> Any:
        """An in-process transport whose peer is every emulated drive on ``bus``."""
        if bus not in self._buses:
            raise ConfigError(f"no emulated bus {bus!r}", key="buses", allowed=sorted(self._buses))
        return self.bus_specs[bus].transport(self._buses[bus], clock=self.clock)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics substeps (drives' loops every substep), one caller at a time.

        Timed device buses (a CAN medium) and drives with delayed commands are ticked with the clock at a
        substep's end: after every substep, or - where each of them announces its next work
        (:class:`Announcing`) - after the substep that reaches it and at the end, the substeps between run
        in one compiled call (the same bits: a tick before its next work only moves its time).
        """
        with self.lock:
            self.sync()
            try:
                self._step(n)
            finally:  # an interrupted step leaves the clock where the physics is
                self._target = max(self._target, self.time)
                self.clock.set(self.time)

    def _step_prepare(self) -> None:
        """Before stepping: a joint whose stepping was replaced (tests) leaves its kernel row."""
        if self._bind != self._bind_seen:
            self._bind_seen = list(self._bind)
            self._python_bind = self._stepped_in_python()
            self.group.replan()

    def _stepped_in_python(self) -> list[tuple[Any, ...]]:
        """The joints this world steps from Python (no kernel row, or its stepping replaced): their bindings."""
        kernel = self.kernel_joints()
        return [self._bind[i] for i, b in enumerate(self._bound) if b not in kernel or not self.kernel_stepped(b)]

    def _until_event(self, n: int) -> int:
        """Of ``n`` due substeps, how many run before a tick has work: up to the first substep end at or after
        the earliest announced event (at least 1; ``n`` if nothing is announced)."""
        events = self._events
        if not events:
            return n
        e = min([ev() for ev in events])
        if e == math.inf:
            return n
        dt, s = self.timestep, self.steps
        if e <= (s + 1) * dt:
            return 1
        k = max(1, math.ceil(e / dt) - s)
        while k > 1 and (s + k - 1) * dt >= e:  # the substep end exactly as the per-substep loop computes it
            k -= 1
        while (s + k) * dt < e:
            k += 1
        return min(k, n)

    def _run_fused(self, k: int) -> int:
        """Up to ``k`` substeps in compiled calls; with watched kernel cells (:class:`Watching`) they end at the
        first substep whose end shows one non-zero. Returns the substeps run."""
        cells = [c for watched in self._bus_watches for c in watched()] if self._bus_watches and k > 1 else None
        if not cells:
            self.group.run(self._me, k)
            return k
        return self.group.run_watching(self.group_index, k, cells)

    def _tick_now(self) -> None:
        """The ticks, with the clock at the end of the last substep run (an advance then shows the clock at the
        instant it booked)."""
        t = self.steps * self.timestep
        self.clock.set(t)
        for tick in self._ticks:
            tick(t)

    def _step(self, n: int) -> None:
        group = self.group
        self._step_prepare()
        if n <= 0:
            return
        me = self._me
        index = self.group_index
        if group.compiled and group.fusable[index]:
            if not self._ticks:
                group.run(me, n)
                return
            while n > 0 and group.fusable[index]:
                k = self._until_event(n)
                n -= self._run_fused(k)
                self._tick_now()
            if n <= 0:
                return
        mj_step = self.mujoco.mj_step
        m, d = self.model, self.data
        qpos, qvel, ctrl = d.qpos, d.qvel, d.ctrl
        dt = self.timestep
        python = self._python_bind
        kernel_rows = len(python) < len(self._bound)
        ticks = self._ticks
        for _ in range(n):
            t = (self.steps + 1) * dt
            if kernel_rows:
                group.substep(me)
            for step, qa, da, aid, r in python:
                ctrl[aid] = step(t, dt, float(qpos[qa]) * r, float(qvel[da]) * r)
            mj_step(m, d)
            self.steps += 1
            if ticks:
                self.clock.set(t)
                for tick in ticks:
                    tick(t)

    def advance(self, seconds: float) -> None:
        """Advance simulated time by ``seconds``: the clock shows the exact instant booked (no drift), the
        physics runs the substeps that end at or before it and the one that reaches it (so it stands up to
        one substep ahead of the clock; docs/timing.md).

        Interrupted (KeyboardInterrupt, a signal), the world stops where it got to: the next
        advance starts from there, never from the interrupted target.
        """
        if seconds <= 0:
            return
        with self.lock:
            if self._held:  # a sleep's substeps, on their own (as they ran at the sleep)
                self.sync()
            self._booked = False  # booked time runs now, with this
            self._step_due(self._due(seconds))
            self.clock.set(self._target)

    def _step_due(self, n: int) -> None:
        """Run ``n`` due substeps; interrupted, the target falls back to where the physics got (the next advance
        starts from there)."""
        if n <= 0:
            return
        try:
            self._step(n)
        except BaseException:
            self._target = self.time
            self.clock.set(self._target)
            raise

    def _due(self, seconds: float) -> int:
        """Book ``seconds`` more on the world's target time: the substeps that are now due."""
        self._target += seconds
        return math.ceil((self._target - self.time) / self.timestep - 1e-9)

    def emulators(self) -> list[Any]:
        """Every drive's twin, once each."""
        return self._emulators()

    def _emulators(self) -> list[Any]:
        seen: dict[int, Any] = {}
        for b in self._bound:
            seen.setdefault(id(b.emulator), b.emulator)
        return list(seen.values())

    def reset(self, seed: int | None = None) -> None:
        """Physics to the model's initial state, every drive to its power-on state (saved settings kept).

        ``seed``: every twin's sensor noise restarts from it, each twin its own stream
        (:func:`joints.sim.sensors.seed`); None: each from its last seed (0 until one is given)."""
        self._booked = self._held = False  # booked time of the old episode never runs
        mj = self.mujoco
        mj.mj_resetData(self.model, self.data)
        mj.mj_forward(self.model, self.data)
        self.steps = 0
        self._target = 0.0
        self.clock.restart(0.0)  # a new epoch: the media drop what was in flight
        if seed is not None:
            sensors.seed(self, seed)  # before the power cycles, which restart each stream from its seed
        for emu in self._emulators():
            emu.power_cycle()
            emu.time = 0.0
        for b in self._bound:
            b.stepper.place(float(self.data.qpos[b.qadr]) * b.ratio)
        if self._state_friction:
            self._friction_tick(0.0)

    def set_joint_positions(self, positions: Mapping[str, float]) -> None:
        """Place drives' joints at ``positions`` (joint name -> MJCF position: rad, m for a slide) at rest.

        For a start state right after :meth:`reset`, while the drives are disabled: sets the joint
        angles, zeroes their velocities, recomputes the kinematics and lets each drive's encoder
        (and holding brake) see the new angle.
        """
        names = [b.name for b in self._bound]
        for name, q in positions.items():
            if name not in names:
                raise KeyError(f"no emulated drive {name!r} (have {names})")
            if not math.isfinite(q):
                raise ValueError(f"joint {name}: position must be finite, got {q!r}")
        for b in self._bound:
            if b.name in positions:
                self.data.qpos[b.qadr] = float(positions[b.name])
                self.data.qvel[b.dadr] = 0.0
        self.mujoco.mj_forward(self.model, self.data)
        for b in self._bound:
            if b.name in positions:
                b.stepper.place(float(self.data.qpos[b.qadr]) * b.ratio)

    def joint_position(self, name: str) -> float:
        """Ground truth joint angle [rad] from the physics (for tests and envs' task terms)."""
        for b in self._bound:
            if b.name == name:
                return float(self.data.qpos[b.qadr])
        if name in self.kinematic:  # a measured joint (mixed rig)
            return float(self.data.qpos[self.kinematic[name][0]])
        raise KeyError(name)

    def joint_velocity(self, name: str) -> float:
        """Ground truth joint velocity [rad/s] from the physics."""
        for b in self._bound:
            if b.name == name:
                return float(self.data.qvel[b.dadr])
        if name in self.kinematic:
            return float(self.data.qvel[self.kinematic[name][1]])
        raise KeyError(name)

    # -- the public sim API (envs and tests use only this) ----------------------------------------
    def joint(self, name: str) -> SimJoint:
        """Where joint ``name`` of the rig lives in the model."""
        try:
            return self.joints[name]
        except KeyError:
            raise KeyError(f"no simulated joint {name!r} (have {sorted(self.joints)})") from None

    def perturb(self, name: str, *, armature: float = 1.0, coulomb_friction: float = 1.0,
                viscous_friction: float = 1.0, torque_constant: float = 1.0,
                gains: Mapping[str, float] | None = None, command_delay: float = 0.0) -> None:
        """Scale one joint's physics and its drive's loop gains by factors of their nominal values.

        ``armature`` (reflected rotor inertia), ``coulomb_friction`` (MuJoCo frictionloss),
        ``viscous_friction`` (damping) and ``torque_constant`` (the motor's true torque per ampere;
        the drive still converts with the nominal constant, as a real drive whose constant is off
        does) change the model; ``gains`` (``"position"``, ``"speed"``, ``"integral"``) scale the
        twin's loop-gain parameters as a write of them would; ``command_delay`` [s] is added to
        the drive's command-to-motion delay (:attr:`joints.sim.firmware.Firmware.command_delay`).
        Factors and the delay act on the nominal values, so calls do not compound; :meth:`restore`
        undoes every perturbation.
        """
        j = self.joint(name)
        m, nom = self.model, self._nominal
        for what, f in (("armature", armature), ("coulomb_friction", coulomb_friction),
                        ("viscous_friction", viscous_friction), ("torque_constant", torque_constant)):
            if isinstance(f, bool) or not isinstance(f, (int, float)) or not math.isfinite(f) or f <= 0:
                raise ValueError(f"perturb {name}: {what} must be a factor > 0, got {f!r}")
        if isinstance(command_delay, bool) or not isinstance(command_delay, (int, float)) \
                or not math.isfinite(command_delay):
            raise ValueError(f"perturb {name}: command_delay must be a finite number of seconds, got {command_delay!r}")
        emu = next(b.emulator for b in self._bound if b.name == name)
        delay = self._nominal_delay.get(id(emu), 0.0) + float(command_delay)
        if delay < 0:
            raise ValueError(f"perturb {name}: the command delay would be {delay} s (< 0)")
        if delay != getattr(emu, "command_delay", 0.0):
            if not getattr(emu, "DELAYED", None):
                raise ValueError(f"perturb {name}: this twin has no command delay (no delayed motion commands)")
            emu.command_delay = delay
            self._update_ticks()
        m.dof_armature[j.dof] = nom["armature"][j.dof] * armature
        m.dof_frictionloss[j.dof] = self._coulomb[j.dof] = nom["frictionloss"][j.dof] * coulomb_friction
        m.dof_damping[j.dof] = nom["damping"][j.dof] * viscous_friction
        m.actuator_gear[j.actuator, 0] = nom["gear"][j.actuator] * torque_constant
        if gains:
            b = next(b for b in self._bound if b.name == name)
            names = b.emulator.gain_params(b.channel)
            nominal = self._nominal_gains.setdefault(name, {k: b.emulator.get(v) for k, v in names.items()})
            writes = []
            for k, f in gains.items():
                if k not in names:
                    raise ValueError(f"perturb {name}: unknown gain {k!r} (allowed: {sorted(names)})")
                p = b.emulator.params[names[k]]
                lo, hi = p.type_range
                writes.append((names[k], max(max(lo, 1), min(hi, round(nominal[k] * f)))))
            b.emulator.write_many(writes)

    def intercept(self, name: str, wrap: Callable[[Callable[[float, float, float, float], float]],
                                                  Callable[[float, float, float, float], float]]) -> None:
        """Put ``wrap(step)`` in place of joint ``name``'s per-substep drive step ``step(t, dt, q, qd) -> torque``:
        effects the twin's model lacks (a test's reality twin: current-loop lag, torque ripple, friction that
        depends on state) go between the drive and the joint. The joint then steps in Python (same results,
        off the fused compiled path)."""
        self.sync()  # booked time runs with the step it was booked under
        for i, b in enumerate(self._bound):
            if b.name == name:
                step, qa, da, aid, r = self._bind[i]
                self._bind[i] = (wrap(step), qa, da, aid, r)  # type: ignore[assignment]
                return
        raise KeyError(f"no simulated joint {name!r} (have {sorted(self.joints)})")

    def restore(self) -> None:
        """Every joint's physics and loop gains back to their nominal values."""
        m, nom = self.model, self._nominal
        m.dof_armature[:] = nom["armature"]
        m.dof_frictionloss[:] = self._coulomb[:] = nom["frictionloss"]
        m.dof_damping[:] = nom["damping"]
        m.actuator_gear[:, 0] = nom["gear"]
        for name, gains in self._nominal_gains.items():
            b = next(b for b in self._bound if b.name == name)
            names = b.emulator.gain_params(b.channel)
            b.emulator.write_many([(names[k], v) for k, v in gains.items()])
        self._nominal_gains.clear()
        for emu in self._emulators():
            nominal = self._nominal_delay.get(id(emu), 0.0)
            if getattr(emu, "command_delay", 0.0) != nominal:
                emu.command_delay = nominal
                if not nominal:
                    emu.tick(math.inf)  # what was waiting is acted on now
        self._update_ticks()

    def close(self) -> None:
        """Nothing to release for an in-process world (kept for symmetry with served worlds)."""


#: what a clock's sleep goes through to the world's hold, as defined (captured with the class: a replaced one means a
#: one-call exchange does not stand in for it, :func:`joints.sim.line_exchange.sleeps_held`)
SLEEP_STOCK = ((ManualClock, "sleep", ManualClock.__dict__["sleep"]),
               *((World, name, World.__dict__[name]) for name in ("_sleep", "hold", "_defer", "_ticks_hold")))


def join(worlds: Sequence[World]) -> stepping.Group:
    """One stepping group holding ``worlds`` (their drives' rows in one table), made once and kept:
    a group that already holds them all (and maybe more: the other rigs of a batch) steps any of them."""
    group = worlds[0].group
    if all(w.group is group for w in worlds):
        return group
    for w in worlds:  # booked time runs on the tables the drives are in now, before they move to the new one
        w.sync()
    group = stepping.Group(worlds, all(w.compiled for w in worlds))
    for i, w in enumerate(worlds):
        w.group, w.group_index, w._me = group, i, (i,)
    return group


def advance_together(worlds: Sequence[World], seconds: Sequence[float]) -> None:
    """Advance each world by its ``seconds`` as :meth:`World.advance` does, stepping them together.

    The worlds (separate models: N rigs of a batched env) join one stepping group; while all of
    them still have substeps due, one compiled call runs the loops of every drive and every
    world's physics for as many substeps as they share, up to the next event a world's ticks
    announce (then that world is ticked). A world that cannot run fused (a bus that does not
    announce its events, a twin stepping in Python) advances on its own. The results are those of
    advancing each world alone.
    """
    if len(worlds) != len(seconds):
        raise ValueError(f"{len(worlds)} worlds but {len(seconds)} times")
    if len({id(w) for w in worlds}) != len(worlds):
        raise ValueError("a world appears twice")
    locks = [w.lock for w in sorted(worlds, key=id)]  # one order for every caller: no lock-order deadlock
    held = 0
    try:
        for lock in locks:
            lock.acquire()
            held += 1
        _advance_locked(worlds, seconds)
    finally:
        for lock in reversed(locks[:held]):
            lock.release()


def _advance_locked(worlds: Sequence[World], seconds: Sequence[float]) -> None:
    """:func:`advance_together` with every world's lock held: one pass over the worlds per compiled call."""
    group = join(worlds)
    due: list[int] = []
    for w, s in zip(worlds, seconds):
        if w._held:  # a sleep's substeps, on their own (as they ran at the sleep)
            w.sync()
        w._booked = False  # booked time runs now, with this
        due.append(w._due(s) if s > 0 else 0)
    try:
        while True:
            left: list[int] = []
            n = 0
            for i, w in enumerate(worlds):
                d = due[i]
                if d <= 0:
                    continue
                if w._bus_watches or not (group.compiled and group.fusable[w.group_index]):
                    w._step_due(d)  # on its own: a world that cannot (or no longer can) run fused
                    due[i] = 0
                    continue
                k = w._until_event(d) if w._events else d
                n = k if not left or k < n else n
                left.append(i)
            if not left:
                break
            for i in left:
                w = worlds[i]
                if w._bind != w._bind_seen:
                    w._step_prepare()
            group.run([worlds[i].group_index for i in left], n)
            for i in left:
                due[i] -= n
                if worlds[i]._ticks:
                    worlds[i]._tick_now()
    except BaseException:
        for w in worlds:
            w._target = w.time
        raise
    finally:
        for w in worlds:
            w.clock.set(w._target)  # as World.advance: the exact instant booked
