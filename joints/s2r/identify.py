"""System identification of one joint through the Joint API, into a device-profile overlay.

Rule: only the public API moves the joint (``enable``, ``set_torque`` / ``set_velocity``,
``state``, ``stop``, ``rig.sleep``), so the same code identifies a real joint and its twin. The
excitation stays inside the joint's configured limits and is aborted (torque 0, stop) the moment
a sample leaves them.

What is identified (all at the joint's output, SI, in the model's joint frame):

====================  ======================================================================
``inertia``           J, the whole inertia about the axis [kg*m^2]; ``armature`` = J minus the
                      MJCF bodies' inertia (reflected rotor inertia + whatever load the model
                      lacks) - MuJoCo ``armature``
``coulomb_friction``  c [N*m] - MuJoCo ``frictionloss``
``viscous_friction``  b [N*m*s/rad] - MuJoCo ``damping``
``stribeck_*``        where the data show it: f_s [N*m] more friction at standstill, fading as
                      exp(-|v / v_s|^a) (``stribeck_velocity`` v_s, ``stribeck_exponent`` a)
``*_friction``        where the data show them: friction per |motor torque| (``load_friction``),
                      per motor torque^2 (``load_friction_quadratic``), per |external torque|
                      (``external_friction``) - the eRob twin applies all of them
``torque_scale``      s = true torque / the torque the driver computes from current with the
                      profile's torque constant (1 = the profile is right)
``delay``             command -> feedback delay [s] the host observes (the drive acting on a
                      command late, plus its feedback being sampled late)
====================  ======================================================================

Model: ``J dv/dt = s u(t - delay) - b v - F sign(v) - G(q)`` with u the commanded torque, G the
gravity torque of the MJCF model at q (MuJoCo ``qfrc_bias`` at rest, other joints where they stood)
and F = c + the Stribeck and torque-dependent terms the data show (:func:`_model`: forward selection,
each term kept when it lowers the residual by :data:`RELEVANT` and is :data:`SIGNIFICANT`). It is
fitted in integral form over windows (:func:`fit`: no differentiation of measured signals), on the
samples where the joint moves (friction is only a sign function while it slides), by linear least
squares for every candidate delay (and Stribeck velocity and exponent); the smallest residual wins.

What the data can tell (physics, not a choice): from current and motion alone every term scales
with s - only J/s, b/s, c/s are known. A known torque fixes the scale: identification therefore
runs on a **gravity-loaded** joint (the pendulum stand ``models/erob_pendulum.xml``, a known load
on a horizontal axis: G(q) is known from the model), or the user gives the joint's whole inertia
(``known_inertia``, ``--inertia``) for a joint without gravity torque (a vertical axis). Without
either, :func:`identify` refuses. Likewise only the SUM of the drive's command delay and its
feedback latency is observable; the overlay's ``command_delay`` is that sum minus the twin's own
feedback latency (one physics substep: a twin reports the state at the start of its last substep),
so the twin shows the delay the real joint showed.

Modes: ``"torque"`` (default; needs a restoring torque, i.e. gravity: on a joint without one a
zero-mean torque lets it drift to a limit) identifies everything; ``"speed"`` (the drive's speed
loop holds the joint on a zero-mean speed signal: any joint) fits the drive's own current
feedback instead of the command, so the delay is not identified there.

The overlay (:func:`write_overlay`) is a TOML file with a ``[profile]`` table of device-profile
overrides (the same keys as a joint's inline ``profile`` table; eRob: ``rotor_inertia`` =
armature / (N+1)^2, ``coulomb_friction``, ``viscous_friction``, ``efficiency`` (x the torque
scale), ``command_delay``) and an ``[identification]`` table of what was measured. A joint uses
it with ``profile_overlay = "<file>"`` (a path relative to the config file); keys of the joint's
inline ``profile`` table win over the file's.
"""

from __future__ import annotations

import datetime
import math
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from joints.errors import CommandError, ConfigError, JointsError, LimitError

__all__ = [
    "MAX_UNCERTAINTY",
    "MAX_VALIDATION",
    "Excitation",
    "Identification",
    "IdentificationAborted",
    "ModelTerms",
    "PoorFit",
    "Samples",
    "excite",
    "fit",
    "identify",
    "overlay_values",
    "write_overlay",
]

#: s the drive needs after "enable" before it takes motion commands (eRob: 500 ms) plus margin
ENABLE_SETTLE = 0.6
#: fraction of the position-limit span kept free at each end during the excitation
POSITION_MARGIN = 0.05
#: a window counts as moving when |v| stays above this [rad/s] in all its samples
MOVING = 0.05

Progress = Callable[[float, str], None]


class IdentificationAborted(LimitError):
    """The excitation was stopped: a sample left the joint's limits or the drive faulted."""


@dataclass(frozen=True)
class Excitation:
    """A multi-sine (Schroeder phases, log-spaced frequencies) in torque or speed, faded in and out, then
    optionally a swing (one sine of the full amplitude) that takes the joint to higher speeds.

    ``amplitude`` is the peak [N*m in torque mode, rad/s in speed mode]; None: half the joint's
    torque / velocity limit ("small": the stand's default excitation stays well inside them).
    """

    mode: str = "torque"
    duration: float = 20.0  #: s
    amplitude: float | None = None
    f_min: float = 0.2  #: Hz
    f_max: float = 3.0  #: Hz
    components: int = 15
    fade: float = 1.5  #: s of fade-in (and 2/3 of it fade-out)
    period: float | None = None  #: s between samples; None: 1 substep in sim, back to back on hardware
    #: a command is written with every this-many-th state read (a slow bus: one transaction per sample instead
    #: of two; the command is held in between, the fit integrates what was sent)
    command_every: int = 1
    #: s of a swing ending the excitation (part of ``duration``; 0: none): a sine of the full amplitude at
    #: ``f_swing`` Hz, near the stand's resonance. The multi-sine's crest factor keeps the joint slow (BAM's
    #: eRob80:100 on the pendulum stand: 1.6 rad/s at 32 N*m peak, where its Stribeck friction, v_s ~2 rad/s, has
    #: fallen by a third only, so the Coulomb and Stribeck levels trade off); the swing reaches 2.7 rad/s, where
    #: it has fallen to a tenth (docs/identification.md). A joint it drives past its velocity limit aborts.
    swing: float = 0.0
    f_swing: float = 0.6  #: Hz

    def __post_init__(self) -> None:
        if self.mode not in ("torque", "speed"):
            raise ConfigError(f"{self.mode!r} is not an excitation mode", key="mode", allowed=("torque", "speed"))
        for what in ("duration", "f_min", "f_max", "fade"):
            v = getattr(self, what)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ConfigError(f"{what} must be > 0, got {v!r}", key=what)
        if self.f_min >= self.f_max:
            raise ConfigError(f"f_min {self.f_min} Hz must be below f_max {self.f_max} Hz", key="f_min")
        if self.amplitude is not None and not (math.isfinite(self.amplitude) and self.amplitude > 0):
            raise ConfigError(f"amplitude must be > 0, got {self.amplitude!r}", key="amplitude")
        if not (isinstance(self.command_every, int) and self.command_every >= 1):
            raise ConfigError(f"command_every must be an integer >= 1, got {self.command_every!r}", key="command_every")
        if self.components < 1:
            raise ConfigError(f"components must be >= 1, got {self.components}", key="components")
        if not (math.isfinite(self.swing) and self.swing >= 0 and math.isfinite(self.f_swing) and self.f_swing > 0):
            raise ConfigError(f"swing must be >= 0 s and f_swing > 0 Hz, got {self.swing!r}, {self.f_swing!r}",
                              key="swing")
        if self.duration - self.swing < 3 * self.fade:
            raise ConfigError(f"duration {self.duration} s (less a {self.swing} s swing) is too short for the "
                              f"{self.fade} s fades", key="duration")
        if self.swing and self.swing < 2 * self.fade + 1 / self.f_swing:
            raise ConfigError(f"a swing of {self.swing} s is too short for its {self.fade} s fades and a cycle of "
                              f"{self.f_swing} Hz", key="swing")

    def shape(self) -> Callable[[float], float]:
        """The signal of unit peak as a function of time since the start [s] (0 outside the duration)."""
        import numpy as np

        n = self.components
        freqs = np.geomspace(self.f_min, self.f_max, n)
        k = np.arange(1, n + 1)
        phases = -np.pi * k * (k - 1) / n  # Schroeder: a low crest factor
        multi = self.duration - self.swing  # s of multi-sine, then the swing
        grid = np.arange(0.0, multi, 1e-3)
        peak = float(np.abs(np.sin(2 * np.pi * np.outer(grid, freqs) + phases).sum(axis=1)).max())
        w = 2 * np.pi * freqs
        fade_in, fade_out, duration, swing, f_swing = self.fade, self.fade * 2 / 3, self.duration, self.swing, \
            self.f_swing

        def smooth(x: float) -> float:  # smoothstep: no jump in the command's slope
            x = min(1.0, max(0.0, x))
            return x * x * (3 - 2 * x)

        def signal(t: float) -> float:
            if not 0.0 <= t < duration:
                return 0.0
            if t >= multi:  # the swing, faded in and out
                x = t - multi
                return smooth(min(x / fade_in, (swing - x) / fade_out)) * math.sin(2 * math.pi * f_swing * x)
            env = smooth(min(t / fade_in, (multi - t) / fade_out))
            return float(env * np.sin(w * t + phases).sum() / peak)

        return signal


@dataclass(frozen=True)
class Samples:
    """What the excitation recorded (model frame: the MJCF joint's sign, rad, N*m)."""

    mode: str
    t: Any  #: s, state read times (numpy arrays from here on)
    w: Any  #: s, command write times (as many as ``t``, or more once uncertain states were dropped)
    u: Any  #: commanded torque [N*m] (torque mode) or speed [rad/s] (speed mode), at ``w``
    q: Any  #: rad
    v: Any  #: rad/s
    tau: Any  #: N*m, the drive's torque estimate (current x the profile's torque constant)
    #: s from each state request to its reply: how uncertain the sample's time is (None: not recorded)
    rtt: Any = None

    @property
    def period(self) -> float:
        """The sampling period achieved [s] (median of the intervals)."""
        import numpy as np

        return float(np.median(np.diff(self.t))) if len(self.t) > 1 else math.nan

    def __len__(self) -> int:
        return len(self.t)


@dataclass(frozen=True)
class ModelTerms:
    """The rigid-body terms of the MJCF model about one joint: gravity torque and inertia.

    ``gravity(q)`` is MuJoCo's bias force at rest (the torque the joint needs to hold q, other
    joints fixed at ``pose``); ``body_inertia`` the joint-space inertia of the bodies alone (no
    armature) at ``pose``.
    """

    path: Path
    joint: str
    pose: Mapping[str, float] = field(default_factory=dict)
    #: the load's mass in the model x this (the load: the heaviest geom with a stated mass); for the
    #: load-mass sensitivity of the fit
    load_factor: float = 1.0

    def __post_init__(self) -> None:
        import mujoco

        spec = mujoco.MjSpec.from_file(str(self.path))
        masses = [(float(g.mass), g) for g in spec.geoms if math.isfinite(float(g.mass)) and float(g.mass) > 0]
        load = max(masses, key=lambda x: x[0], default=None)
        object.__setattr__(self, "load", (load[1].name or "(unnamed geom)", load[0]) if load else ("", 0.0))
        if load is not None and self.load_factor != 1.0:
            load[1].mass = load[0] * self.load_factor
        m = spec.compile()
        m.dof_armature[:] = 0.0
        d = mujoco.MjData(m)
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, self.joint)
        if jid < 0:
            raise ConfigError(f"MJCF joint {self.joint!r} is not in {self.path.name}", key="mjcf_joint")
        for name, q in self.pose.items():
            other = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)
            if other >= 0:
                d.qpos[m.jnt_qposadr[other]] = q
        object.__setattr__(self, "_m", m)
        object.__setattr__(self, "_d", d)
        object.__setattr__(self, "_qadr", int(m.jnt_qposadr[jid]))
        object.__setattr__(self, "_dof", int(m.jnt_dofadr[jid]))

    def gravity(self, q: Any) -> Any:
        """G(q) [N*m] for an array of joint angles."""
        import mujoco
        import numpy as np

        m, d, qa, dof = self._m, self._d, self._qadr, self._dof  # type: ignore[attr-defined]
        out = np.empty(len(q))
        d.qvel[:] = 0.0
        for i, x in enumerate(q):
            d.qpos[qa] = x
            mujoco.mj_forward(m, d)
            out[i] = d.qfrc_bias[dof]
        return out

    def body_inertia(self, q: float = 0.0) -> float:
        """The bodies' inertia about the joint at ``q`` [kg*m^2] (no armature)."""
        import mujoco
        import numpy as np

        m, d, qa, dof = self._m, self._d, self._qadr, self._dof  # type: ignore[attr-defined]
        d.qpos[qa] = q
        mujoco.mj_forward(m, d)
        unit = np.zeros(m.nv)
        unit[dof] = 1.0
        out = np.zeros(m.nv)
        mujoco.mj_mulM(m, d, out, unit)
        return float(out[dof])


#: refusal thresholds (docs/identification.md): the held-out equation error over the RMS torque impulse,
#: and each parameter's relative uncertainty (the larger of the regression's and the held-out folds' spread)
MAX_VALIDATION = 0.15
#: ("friction": the friction curve Coulomb + Stribeck + viscous at the speeds the excitation reached, relative -
#: with a Stribeck term the Coulomb and Stribeck levels trade off against each other, the curve they make does not;
#: the Stribeck velocity and exponent and the torque-dependent terms are reported, never a reason to refuse)
MAX_UNCERTAINTY: Mapping[str, float] = {"armature": 0.10, "torque_scale": 0.10, "viscous_friction": 0.15,
                                        "friction": 0.15}
#: s of delay uncertainty above which the fit is refused
MAX_DELAY_UNCERTAINTY = 0.002
#: |correlation| of two parameters' estimates above which the data cannot tell them apart well
CORRELATED = 0.9


class PoorFit(JointsError):
    """The identification does not meet the thresholds (:data:`MAX_VALIDATION`, :data:`MAX_UNCERTAINTY`):
    no overlay is written unless forced."""


@dataclass(frozen=True)
class Identification:
    """The identified parameters of one joint and how well the model explains the data."""

    joint: str
    mode: str
    inertia: float  #: J about the axis [kg*m^2]
    body_inertia: float  #: the MJCF bodies' share of J [kg*m^2]
    coulomb_friction: float  #: N*m
    viscous_friction: float  #: N*m*s/rad
    torque_scale: float  #: true torque / driver-computed torque
    delay: float | None  #: s, command -> feedback (None: not identified in speed mode)
    feedback_latency: float  #: s the twin's feedback lags (one physics substep)
    gravity_loaded: bool  #: the scale came from the gravity torque (else from ``known_inertia``)
    samples: int
    used: int  #: moving windows the fit used
    period: float  #: s, the sampling period achieved (median)
    residual: float  #: RMS of the fit's residual over RMS of the torque impulse (0 = exact)
    #: relative uncertainties (delay: absolute, s): the larger of the regression's standard error and
    #: the spread of the estimates over held-out folds
    std: Mapping[str, float] = field(default_factory=dict)
    excitation: Mapping[str, Any] = field(default_factory=dict)
    validation: float = math.nan  #: held-out equation error over the RMS torque impulse
    condition: float = math.nan  #: condition number of the column-scaled regressors
    correlations: Mapping[str, float] = field(default_factory=dict)  #: "a/b" -> correlation of the estimates
    #: d ln(parameter) / d ln(load mass): how the fit moves with an error in the stand's load mass
    load_sensitivity: Mapping[str, float] = field(default_factory=dict)
    load: str = ""  #: the model's load (the gravity-torque reference) and its mass
    load_mass: float = math.nan
    period_spread: float = math.nan  #: s, std of the sampling intervals
    window: float = math.nan  #: s, the modulating window's length
    #: N*m more friction at standstill, fading as exp(-|v / stribeck_velocity|^stribeck_exponent) (0: none seen)
    stribeck_friction: float = 0.0
    stribeck_velocity: float = math.nan  #: rad/s (nan: no Stribeck term fitted)
    stribeck_exponent: float = math.nan  #: of exp(-|v / stribeck_velocity|^this)
    load_friction: float = 0.0  #: N*m of friction per N*m of motor torque (0: the data show none)
    load_friction_quadratic: float = 0.0  #: N*m of friction per (N*m of motor torque)^2
    external_friction: float = 0.0  #: N*m of friction per N*m of external (gravity) torque

    @property
    def armature(self) -> float:
        """J minus the bodies' inertia: reflected rotor inertia + load missing from the model [kg*m^2]."""
        return self.inertia - self.body_inertia

    @property
    def command_delay(self) -> float | None:
        """The twin's command delay reproducing :attr:`delay` (its own feedback latency taken off)."""
        return None if self.delay is None else max(0.0, self.delay - self.feedback_latency)

    def friction_at(self, speed: float) -> float:
        """The friction torque [N*m] at ``speed`` [rad/s] with no torque transmitted: Coulomb + Stribeck + viscous."""
        v = abs(speed)
        excess = self.stribeck_friction * math.exp(-((v / self.stribeck_velocity) ** self.stribeck_exponent)) \
            if self.stribeck_friction else 0.0
        return self.coulomb_friction + excess + self.viscous_friction * v

    def inseparable(self) -> list[str]:
        """Pairs of parameters the data cannot tell apart well (|correlation| > :data:`CORRELATED`)."""
        return [k for k, c in self.correlations.items() if abs(c) > CORRELATED]

    def problems(self) -> list[str]:
        """Why the fit should not be trusted (empty: it meets every threshold)."""
        out = []
        if not self.validation <= MAX_VALIDATION:
            out.append(f"held-out error {self.validation:.1%} > {MAX_VALIDATION:.0%}")
        for k, limit in MAX_UNCERTAINTY.items():
            u = self.std.get(k)
            if u is not None and not u <= limit:
                out.append(f"{k} uncertainty {u:.1%} > {limit:.0%}")
        du = self.std.get("delay")
        if du is not None and not du <= MAX_DELAY_UNCERTAINTY:
            out.append(f"delay uncertainty {du * 1e3:.2f} ms > {MAX_DELAY_UNCERTAINTY * 1e3:.1f} ms")
        return out

    def summary(self) -> dict[str, Any]:
        out = {f.name: getattr(self, f.name) for f in fields(self)
               if f.name not in ("std", "excitation", "correlations", "load_sensitivity")}
        out.update(armature=self.armature, command_delay=self.command_delay, std=dict(self.std),
                   excitation=dict(self.excitation), correlations=dict(self.correlations),
                   load_sensitivity=dict(self.load_sensitivity), inseparable=self.inseparable(),
                   problems=self.problems())
        return out

    def __str__(self) -> str:
        def u(k: str) -> str:
            v = self.std.get(k)
            return f"  +-{v:.1%}" if v is not None else ""

        lines = [(f"joint {self.joint}: {self.samples} samples every {self.period * 1e3:.3f} ms "
                  f"(spread {self.period_spread * 1e3:.3f} ms, {self.mode} mode), {self.used} windows of "
                  f"{self.window * 1e3:.0f} ms used, residual {self.residual:.2%}, held-out {self.validation:.2%}"),
                 (f"  inertia          {self.inertia:.5g} kg*m^2{u('inertia')} (bodies {self.body_inertia:.5g}, "
                  f"armature {self.armature:.5g}{u('armature')})"),
                 f"  coulomb friction {self.coulomb_friction:.5g} N*m{u('coulomb_friction')}",
                 f"  viscous friction {self.viscous_friction:.5g} N*m*s/rad{u('viscous_friction')}",
                 (f"  stribeck         {self.stribeck_friction:.5g} N*m{u('stribeck_friction')} more at standstill, "
                  f"v_s {self.stribeck_velocity:.3g} rad/s{u('stribeck_velocity')}, exponent "
                  f"{self.stribeck_exponent:g}" if self.stribeck_friction
                  else "  stribeck         none seen"),
                 "  friction growing with torque: " + (", ".join(
                     f"{v:.4g}{u(k)} {unit}" for k, v, unit in (
                         ("load_friction", self.load_friction, "x |motor torque|"),
                         ("load_friction_quadratic", self.load_friction_quadratic, "N*m^-1 x motor torque^2"),
                         ("external_friction", self.external_friction, "x |external torque|")) if v)
                     or "none seen"),
                 f"  torque scale     {self.torque_scale:.5g}{u('torque_scale')}"]
        if self.delay is not None:
            lines.append(f"  delay            {self.delay * 1e3:.2f} ms +-{self.std.get('delay', 0) * 1e3:.2f} ms "
                         f"(twin command delay {(self.command_delay or 0.0) * 1e3:.2f} ms)")
        lines.append(f"  identifiability: condition number {self.condition:.3g}; "
                     + (f"cannot be told apart well: {', '.join(self.inseparable())}" if self.inseparable()
                        else "no two parameters correlated above " + f"{CORRELATED:g}"))
        if self.load_sensitivity:
            lines.append(f"  load mass ({self.load}, {self.load_mass:.4g} kg in the model) - d ln p / d ln m: "
                         + ", ".join(f"{k} {v:+.2f}" for k, v in self.load_sensitivity.items()))
        bad = self.problems()
        lines.append("  REFUSED: " + "; ".join(bad) if bad else "  meets the thresholds")
        return "\n".join(lines)


# -- excitation ---------------------------------------------------------------------------------------


def excite(rig: Any, name: str, excitation: Excitation, *, progress: Progress | None = None) -> Samples:
    """Run ``excitation`` on joint ``name`` of ``rig`` and record the drive's own feedback.

    The joint is enabled if it is not (and disabled again afterwards); every sample writes one
    command and reads one state, as fast as the bus allows on hardware and every physics substep
    in sim (or every ``excitation.period``). A sample outside the position limits (less a 5 %
    margin), above the velocity limit, or a drive fault aborts with
    :class:`IdentificationAborted` after commanding torque / speed 0 and a stop.
    """
    import numpy as np

    j = rig.joints[name]
    lim = j.limits
    mode = excitation.mode
    scale = lim.torque if mode == "torque" else lim.velocity
    if scale is None:
        raise ConfigError(f"identification needs the joint's {'torque' if mode == 'torque' else 'velocity'} limit "
                          "(it bounds the excitation)", key=f"joints.{name}.limits")
    if lim.position is None:
        raise ConfigError("identification needs the joint's position limits (the excitation must stay inside them)",
                          key=f"joints.{name}.limits.position")
    amplitude = excitation.amplitude if excitation.amplitude is not None else 0.5 * scale
    if amplitude > scale:
        raise LimitError(f"joint {name}: excitation amplitude {amplitude:g} exceeds the joint's "
                         f"{mode} limit {scale:g}; nothing was sent")
    lo, hi = lim.position
    margin = POSITION_MARGIN * (hi - lo)
    window = (lo + margin, hi - margin)
    vmax = lim.velocity
    sim = rig.world is not None and rig.backend == "sim"
    period = excitation.period if excitation.period is not None else (rig.world.timestep if sim else 0.0)
    if sim and period <= 0:
        raise ConfigError("in sim every sample must let time pass: period > 0", key="period")
    shape = excitation.shape()
    d, off = j.direction, j.offset
    here = j.state()
    if not window[0] <= here.position <= window[1]:
        raise IdentificationAborted(f"joint {name}: at {here.position:.3f}, outside the identification window "
                                    f"[{window[0]:.3f}, {window[1]:.3f}] (the limits less {POSITION_MARGIN:.0%}); "
                                    "move it inside first")
    was_enabled = j.enabled
    if not was_enabled:
        j.enable()
        rig.sleep(ENABLE_SETTLE)
    acc = lim.acceleration or 100.0  # speed mode: the drive's ramp must not filter the signal
    if mode == "torque":
        command: Callable[[float], None] = j.set_torque
    else:
        def command(v: float) -> None:
            j.set_velocity(v, acceleration=acc)
    t_: list[float] = []
    w_: list[float] = []
    u_: list[float] = []
    q_: list[float] = []
    v_: list[float] = []
    tau_: list[float] = []
    rtt_: list[float] = []
    t0 = rig.time
    next_report = 0.0
    aborted: str | None = None
    try:
        command(0.0)
        while True:
            now = rig.time
            t = now - t0
            if t >= excitation.duration:
                break
            u = amplitude * shape(t)
            if len(t_) % excitation.command_every == 0:
                command(u * d)
                asked = rig.time
                w_.append(0.5 * (now + asked))  # the drive took the command during its write, ending at `asked`
                u_.append(u)
            else:
                asked = now
            s = j.state()
            q = (s.position - off) * d
            t_.append(s.time)  # the middle of its transaction (joints.drivers.base.sampled_at)
            rtt_.append(2 * (s.time - asked))  # the transaction's length: how uncertain that time is
            q_.append(q)
            v_.append(s.velocity * d)
            tau_.append(s.torque * d)
            if s.fault is not None:
                aborted = f"the drive reports {s.fault.name}"
            elif not window[0] <= s.position <= window[1]:
                aborted = (f"position {s.position:.3f} left the window [{window[0]:.3f}, {window[1]:.3f}] "
                           "(lower the amplitude)")
            elif vmax is not None and abs(s.velocity) > vmax:
                aborted = f"velocity {s.velocity:.3f} above the limit {vmax:g} (lower the amplitude)"
            if aborted:
                break
            if progress is not None and t >= next_report:
                progress(t / excitation.duration, f"t {t:6.2f} s  q {q:+.3f} rad  u {u:+.3f}")
                next_report = t + excitation.duration / 50
            if period > 0:
                rig.sleep(period)
    finally:
        try:
            command(0.0)
            j.stop()
        finally:
            if not was_enabled:
                j.disable()
    if aborted:
        raise IdentificationAborted(f"joint {name}: excitation aborted at t = {t_[-1] - t0:.3f} s: {aborted}; "
                                    "torque/speed set to 0 and stopped")
    if progress is not None:
        progress(1.0, f"{len(t_)} samples")
    arr = [np.asarray(x, dtype=float) for x in (t_, w_, u_, q_, v_, tau_, rtt_)]
    return Samples(mode, *arr)


# -- fit ----------------------------------------------------------------------------------------------

#: a sampling interval longer than this many periods (the median) is a gap: no window that holds one is used
GAP = 4.0
#: s, the modulating window's default length ...
WINDOW = 0.1
#: ... and at least this many sampling periods: the fit integrates positions interpolated linearly between
#: samples, an error of order (period / window)^2 on the inertia term (measured on the issue-24 reality twin
#: sampled every 5 ms: armature -9 % +-12 % with a 100 ms window, -0.5 % +-4 % with 200 ms)
WINDOW_PERIODS = 30
#: held-out folds (contiguous blocks of the excitation)
FOLDS = 5


def _window_kernels(length: float, h: float) -> tuple[Any, Any, Any, Any]:
    """phi = sin^4(pi tau / L) on [0, L] and its first two derivatives at the grid points, and phi at
    the cells' midpoints (for the command's cell averages)."""
    import numpy as np

    m = max(8, round(length / h))
    tau = np.arange(m + 1) * h
    th = np.pi * tau / (m * h)
    k = np.pi / (m * h)
    sn, cs = np.sin(th), np.cos(th)
    phi = sn ** 4
    d1 = 4 * k * sn ** 3 * cs
    d2 = k * k * (12 * sn ** 2 * cs ** 2 - 4 * sn ** 4)
    mid = np.sin(np.pi * (np.arange(m) + 0.5) / m) ** 4
    return phi, d1, d2, mid


def _cubic(x: Any, t: Any, y: Any) -> Any:
    """``y(t)`` at ``x`` by cubic Hermite interpolation with slopes from the neighbours (Catmull-Rom on any
    spacing): an error of order period^3 where linear interpolation's is period^2 (held at the ends)."""
    import numpy as np

    if len(t) < 3 or not np.all(np.diff(t) > 0):
        return np.interp(x, t, y)
    m = np.gradient(y, t)
    i = np.clip(np.searchsorted(t, x, side="right") - 1, 0, len(t) - 2)
    h = t[i + 1] - t[i]
    s = np.clip((x - t[i]) / h, 0.0, 1.0)
    s2, s3 = s * s, s * s * s
    return ((2 * s3 - 3 * s2 + 1) * y[i] + (s3 - 2 * s2 + s) * h * m[i] + (3 * s2 - 2 * s3) * y[i + 1]
            + (s3 - s2) * h * m[i + 1])


def _correlate(x: Any, kernel: Any, h: float) -> Any:
    """out[j] = sum_k x[j + k] kernel[k] h: the windows starting at each grid point."""
    import numpy as np

    return np.convolve(x, kernel[::-1], mode="valid") * h


#: friction terms linear in their parameter, magnitudes x sign(v) (tau_m: the motor's torque at the output, the
#: command in the fit; tau_e: the external torque, the model's gravity torque): the Coulomb level, friction per
#: |tau_m| and per tau_m^2 (BAM's M6 form) and per |tau_e|
FRICTION_TERMS = ("coulomb_friction", "load_friction", "load_friction_quadratic", "external_friction")
#: the friction terms of one fit besides viscous: (Stribeck velocity [rad/s] and exponent, or None; the terms of
#: FRICTION_TERMS it has - a Coulomb level the data put below 0 is 0: friction that falls to nothing with speed)
Friction = tuple[tuple[float, float] | None, tuple[str, ...]]
COULOMB_VISCOUS: Friction = (None, ("coulomb_friction",))
#: parameters that are physical only >= 0: a least-squares value below 0 is held at 0 (its column left out)
NON_NEGATIVE = (*FRICTION_TERMS, "stribeck_friction")
#: how the fit's coefficient of a term scales with the torque scale s (it multiplies the command: k s, k s^2)
SCALED = {"load_friction": 1, "load_friction_quadratic": 2}


class _Regression:
    """The modulating-function form of the model on one recording (see :func:`fit`)."""

    def __init__(self, samples: Samples, g: Any, *, window: float, max_delay: float, moving: float) -> None:
        import numpy as np

        t, q = samples.t, samples.q
        dt = np.diff(t)
        self.period = float(np.median(dt))
        h = min(self.period, 1e-3) / 2  # the integration grid: at least 2 points per sample
        L = max(window, WINDOW_PERIODS * self.period)
        phi, d1, d2, mid = _window_kernels(L, h)
        self.length = L = (len(phi) - 1) * h
        m = len(phi) - 1
        # the command's integral, exact for a zero-order hold, on a grid that starts max_delay earlier
        if samples.mode == "torque":
            w, u = samples.w, samples.u
        else:  # speed mode: the drive's own torque estimate drove the step that starts at its sample
            w, u = t, samples.tau
        cum = np.concatenate([[0.0], np.cumsum(u[:-1] * np.diff(w))])

        def U(x: Any) -> Any:
            i = np.clip(np.searchsorted(w, x, side="right") - 1, 0, len(w) - 1)
            return np.where(x < w[0], 0.0, cum[i] + u[i] * (x - w[i]))

        start = t[0] - max_delay - h
        grid_u = start + np.arange(int((t[-1] - start) / h) + 1) * h
        cells = np.diff(U(grid_u)) / h
        self.g0_at = grid_u[: len(cells) - m + 1]
        self.g0 = np.convolve(cells, mid[::-1], mode="valid") * h
        # the measured signals on the grid of the windows
        grid = t[0] + np.arange(int((t[-1] - t[0]) / h) + 1) * h
        Q = _cubic(grid, t, q)
        G = _cubic(grid, t, g)
        s = max(0.005, 2 * self.period)  # velocity from positions (never the drive's noisy estimate): its sign
        vhat = (np.interp(grid + s, t, q) - np.interp(grid - s, t, q)) / (2 * s)
        slow = np.abs(vhat) <= moving
        cs = np.concatenate([[0], np.cumsum(slow)])
        n_win = len(grid) - m
        first = grid[:n_win]
        # windows where the joint slides (at most 10 % of the window slow: a reversal, not a stick)
        few_slow = (cs[m + 1: m + 1 + n_win] - cs[:n_win]) <= 0.1 * (m + 1)
        edge = (first - s >= t[0]) & (first + L + s <= t[-1])
        # windows without a gap in the sampling (a host that stalled: positions there are only interpolated)
        gap = np.zeros(len(grid), dtype=bool)
        for i in np.flatnonzero(dt > GAP * self.period):
            gap[np.searchsorted(grid, t[i]): np.searchsorted(grid, t[i + 1])] = True
        cg = np.concatenate([[0], np.cumsum(gap)])
        self.gaps = int((dt > GAP * self.period).sum())  #: sampling intervals longer than GAP periods
        ok = few_slow & edge & ((cg[m + 1: m + 1 + n_win] - cg[:n_win]) == 0)
        stride = max(1, m // 8)  # windows a stride apart (overlapping: the covariance says how much)
        sel = np.flatnonzero(ok)
        sel = sel[(sel % stride) == 0]
        self.x = first[sel]
        self.f1 = _correlate(Q, d2, h)[sel]
        self.f2 = _correlate(Q, d1, h)[sel]
        sign = np.sign(vhat)
        self.f3 = _correlate(sign, phi, h)[sel]
        self.f4 = _correlate(G, phi, h)[sel]
        # friction growing with the transmitted torque: |command| (no delay: a few ms against the window) x sign
        i = np.clip(np.searchsorted(w, grid, side="right") - 1, 0, len(w) - 1)
        ua = np.where(grid < w[0], 0.0, np.abs(u[i]))
        #: friction terms linear in their parameter: int (magnitude) sign(v) phi (see FRICTION_TERMS)
        self.friction = {"coulomb_friction": self.f3,
                         "load_friction": _correlate(ua * sign, phi, h)[sel],
                         "load_friction_quadratic": _correlate(ua * ua * sign, phi, h)[sel],
                         "external_friction": _correlate(np.abs(G) * sign, phi, h)[sel]}
        self.overlap = max(1.0, L / (2 * stride * h))  #: windows per independent one
        self.used = len(sel)
        self._sliding = (vhat, sign, phi, h, sel)
        self._stribeck: dict[tuple[float, float], Any] = {}
        #: rad/s, the speeds the excitation reached (99th percentile): bounds the Stribeck-velocity search
        self.speed = float(np.quantile(np.abs(vhat), 0.99)) if len(vhat) else 0.0

    def stribeck(self, curve: tuple[float, float]) -> Any:
        """int exp(-|v / vs|^a) sign(v) phi of each window, ``curve`` = (vs, a) (cached)."""
        import numpy as np

        out = self._stribeck.get(curve)
        if out is None:
            vhat, sign, phi, h, sel = self._sliding
            vs, a = curve
            out = self._stribeck[curve] = _correlate(np.exp(-np.abs(vhat / vs) ** a) * sign, phi, h)[sel]
        return out

    def g(self, d: float) -> Any:
        import numpy as np

        return np.interp(self.x - d, self.g0_at, self.g0)

    def system(self, d: float, known_inertia: float | None, f4_scale: float = 1.0,
               friction: Friction = COULOMB_VISCOUS) -> tuple[Any, Any, list[str]]:
        """Regressors, target and parameter names (see :data:`Friction`). The coefficients of the terms that
        multiply the command are the parameter x torque_scale^:data:`SCALED`."""
        import numpy as np

        vs, terms = friction
        cols, names = [-self.f2], ["viscous_friction"]
        for k in terms:
            cols.append(self.friction[k])
            names.append(k)
        if vs is not None:
            cols.append(self.stribeck(vs))
            names.append("stribeck_friction")
        cols.append(-self.g(d))
        names.append("torque_scale")
        if known_inertia is None:
            return np.stack([self.f1, *cols], axis=1), -self.f4 * f4_scale, ["inertia", *names]
        return np.stack(cols, axis=1), -(known_inertia * self.f1 + self.f4 * f4_scale), names


def _certain(samples: Samples) -> Samples:
    """Without the samples whose time is uncertain: a reply that took more than twice the median round
    trip (the drive sampled somewhere in it; the fit reads its position at the midpoint). At most a
    fifth of the samples go; the commands stay (they are timed where they were sent)."""
    import numpy as np

    rtt = samples.rtt
    if rtt is None or len(rtt) != len(samples):
        return samples
    limit = max(2 * float(np.median(rtt)), float(np.quantile(rtt, 0.8)))
    keep = rtt <= limit
    if keep.all():
        return samples
    return Samples(samples.mode, samples.t[keep], samples.w, samples.u, samples.q[keep], samples.v[keep],
                   samples.tau[keep], rtt[keep])


def _solve(A: Any, y: Any, rows: Any = None, names: list[str] | None = None) -> tuple[Any, float]:
    """Least squares; with ``names``, the :data:`NON_NEGATIVE` parameters held >= 0 (the most negative one
    left out until none is below 0)."""
    import numpy as np

    if rows is not None:
        A, y = A[rows], y[rows]
    free = list(range(A.shape[1]))
    x = np.zeros(A.shape[1])
    while True:
        x[:] = 0.0
        x[free], *_ = np.linalg.lstsq(A[:, free], y, rcond=None)
        below = [i for i in free if names is not None and names[i] in NON_NEGATIVE and x[i] < 0]
        if not below:
            break
        free.remove(min(below, key=lambda i: x[i]))
    r = A @ x - y
    return x, float(r @ r)


def _best_delay(reg: _Regression, known_inertia: float | None, max_delay: float, rows: Any = None,
                friction: Friction = COULOMB_VISCOUS) -> float:
    import numpy as np

    step = max(reg.period / 4, 1e-4)
    grid = np.arange(0.0, max_delay + 1e-12, step)
    def cost(d: float) -> float:
        A, y, _ = reg.system(d, known_inertia, friction=friction)
        return _solve(A, y, rows)[1]

    costs = [cost(float(d)) for d in grid]
    i = int(np.argmin(costs))
    fine = np.linspace(grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)], 41)
    return float(fine[int(np.argmin([cost(float(d)) for d in fine]))])


#: rad/s, the Stribeck velocities searched: from here to 3x the speeds the excitation reached (25 log steps)
STRIBECK_MIN = 0.05
#: a Stribeck curve must fall by this fraction within the speeds the excitation reached (else the data cannot
#: tell it from Coulomb friction: it is not searched)
STRIBECK_SEEN = 0.25
#: the Stribeck curve's exponents searched (2: Gaussian; BAM's eRob80:100 fits use 3)
STRIBECK_EXPONENTS = (1.0, 1.5, 2.0, 3.0, 4.0)
#: the relative step to which the best Stribeck velocity is refined
STRIBECK_STEP = 0.002
#: the Stribeck exponent is a model choice, not a parameter the data must pin: an exponent whose refined residual
#: exceeds the smallest by less than this F value x the residual variance per independent window (F(1, inf) at
#: 5 %: the exponent's one degree of freedom not significant) fits as well, and the lowest such exponent - the
#: simplest curve - is taken; the same rule on noisy and noise-free data (BAM's M6 over the pty: exponents 3 and 4
#: within 0.1 % of each other, the noise chose between them and the Coulomb level jumped 1.4 N*m)
EXPONENT_F = 3.84


def _best_stribeck(reg: _Regression, d: float, known_inertia: float | None, terms: tuple[str, ...],
                   rows: Any = None, exponent: float | None = None) -> tuple[float, float] | None:
    """The Stribeck curve (vs, exponent) of smallest residual (the linear parameters solved at each, friction
    held >= 0): every exponent of :data:`STRIBECK_EXPONENTS` (or ``exponent``) on a log grid of vs from
    :data:`STRIBECK_MIN` to 3x the speeds the excitation reached, vs refined around the best point (golden
    section, to :data:`STRIBECK_STEP`)."""
    import numpy as np

    grid = np.geomspace(STRIBECK_MIN, max(2 * STRIBECK_MIN, 3 * reg.speed), 25)

    def cost(vs: float, a: float) -> float:
        A, y, names = reg.system(d, known_inertia, friction=((vs, a), terms))
        return _solve(A, y, rows, names)[1]

    def refined(a: float) -> tuple[float, float] | None:
        """(cost, vs) at the best vs for exponent ``a``: the grid's best point refined between its neighbours by
        golden-section search on ln vs, to STRIBECK_STEP (a grid step there moves the Coulomb level: BAM's M2 on
        the stand, 0.07 N*m per 3 % of vs)."""
        top = reg.speed / (-math.log(1 - STRIBECK_SEEN)) ** (1 / a)  # the largest vs whose curve falls by
        # STRIBECK_SEEN within the speeds reached
        on_grid = [(cost(float(v), a), i) for i, v in enumerate(grid) if v <= top]
        if not on_grid:
            return None
        _, i = min(on_grid)
        lo, hi = math.log(grid[max(i - 1, 0)]), math.log(min(grid[min(i + 1, len(grid) - 1)], top))
        inv = (math.sqrt(5) - 1) / 2
        x1, x2 = hi - inv * (hi - lo), lo + inv * (hi - lo)
        c1, c2 = cost(math.exp(x1), a), cost(math.exp(x2), a)
        while hi - lo > STRIBECK_STEP:
            if c1 <= c2:
                hi, x2, c2 = x2, x1, c1
                x1 = hi - inv * (hi - lo)
                c1 = cost(math.exp(x1), a)
            else:
                lo, x1, c1 = x1, x2, c2
                x2 = lo + inv * (hi - lo)
                c2 = cost(math.exp(x2), a)
        return (c1, math.exp(x1)) if c1 <= c2 else (c2, math.exp(x2))

    # every exponent refined before they are compared: on the grid alone the exponent whose grid point happens
    # to lie nearer its optimum wins (BAM's M6: exponent 4 by the grid, 3 refined, 2 % less residual)
    fits = [(r[0], r[1], a) for a in (STRIBECK_EXPONENTS if exponent is None else (exponent,))
            if (r := refined(a)) is not None]
    if not fits:
        return None
    # the lowest exponent whose residual the data do not tell from the smallest (see EXPONENT_F)
    least = min(f[0] for f in fits)
    A, _, _ = reg.system(d, known_inertia, friction=((fits[0][1], fits[0][2]), terms))
    dof = reg.used / reg.overlap - A.shape[1]  # independent windows less the parameters
    limit = least * (1 + EXPONENT_F / dof) if dof > 0 else math.inf
    best = min((f for f in fits if f[0] <= limit), key=lambda f: f[2])
    return best[1], best[2]


def _named(x: Any, names: list[str], known_inertia: float | None) -> dict[str, float]:
    out = {n: float(v) for n, v in zip(names, x)}
    if known_inertia is not None:
        out["inertia"] = float(known_inertia)
    return out


#: a friction term beyond Coulomb + viscous is kept when its estimate is this many standard errors above 0
SIGNIFICANT = 3.0
#: ... and when it lowers the fit's residual (sum of squares) by this fraction or more
RELEVANT = 0.10


def _model(reg: _Regression, known_inertia: float | None, max_delay: float, torque_mode: bool,
           extended: bool) -> tuple[float, Friction]:
    """The delay and the friction terms of the fit. Besides Coulomb + viscous: Stribeck friction (its velocity
    and exponent profiled by a search, the linear parameters solved at each) and friction growing with the
    motor's and the external torque (:data:`FRICTION_TERMS`; torque mode only: in speed mode the drive's own
    torque stands for the command). Forward selection from Coulomb + viscous: the term that lowers the residual
    most is added while it lowers it by :data:`RELEVANT` or more and every added term stays above
    :data:`SIGNIFICANT` standard errors (friction held >= 0). Relevance, not only significance: on data whose
    residual is the model's own error (current lag, ripple), not noise, a spurious term is always "significant"."""
    import numpy as np

    def delay_of(friction: Friction) -> float:
        return _best_delay(reg, known_inertia, max_delay, None, friction) if torque_mode else 0.0

    d = delay_of(COULOMB_VISCOUS)
    if not extended:
        return d, COULOMB_VISCOUS

    def rss_of(friction: Friction) -> float:
        A, y, names = reg.system(d, known_inertia, friction=friction)
        x, rss = _solve(A, y, None, names)
        added = [i for i, k in enumerate(names) if k in NON_NEGATIVE and k != "coulomb_friction"]
        if any(x[i] == 0.0 for i in added):
            return math.inf  # an added term held at 0: the smaller model covers it
        try:
            se = np.sqrt(np.clip(np.diag(rss / max(1, A.shape[0] - A.shape[1]) * reg.overlap
                                         * np.linalg.inv(A.T @ A)), 0, None))
        except np.linalg.LinAlgError:
            return math.inf
        return rss if all(x[i] > SIGNIFICANT * se[i] for i in added) else math.inf

    vs: tuple[float, float] | None = None
    terms: tuple[str, ...] = ("coulomb_friction",)
    current = rss_of((vs, terms))
    candidates = ["stribeck_friction", *(FRICTION_TERMS[1:] if torque_mode else ())]
    while candidates:
        tried: list[tuple[float, str, Friction]] = []
        for k in candidates:
            if k == "stribeck_friction":
                curve = _best_stribeck(reg, d, known_inertia, terms)
                if curve is not None:
                    tried.append((rss_of((curve, terms)), k, (curve, terms)))
            else:
                tried.append((rss_of((vs, (*terms, k))), k, (vs, (*terms, k))))
        if not tried:
            break
        rss, k, friction = min(tried, key=lambda c: c[0])
        if not rss <= (1 - RELEVANT) * current:
            break
        current, (vs, terms) = rss, friction
        candidates.remove(k)
    d = delay_of((vs, terms))
    if vs is not None:  # the exponent too: it was chosen before the terms added after the Stribeck term
        vs = _best_stribeck(reg, d, known_inertia, terms)
    return d, (vs, terms)


def fit(samples: Samples, terms: ModelTerms | None, *, known_inertia: float | None = None,
        feedback_latency: float = 0.0, window: float | None = None, max_delay: float = 0.05,
        moving: float = MOVING, joint: str = "", excitation: Mapping[str, Any] | None = None,
        folds: int = FOLDS, extended_friction: bool = True) -> Identification:
    """Fit inertia, friction, torque scale and delay to ``samples``.

    The model ``J q'' + b q' + c sign(q') + G(q) = s u(t - d)`` is multiplied by a smooth window
    ``phi`` (sin^4, ``window`` s long, vanishing with its slope at both ends) and integrated by
    parts, so no measured signal is differentiated: ``J int q phi'' - b int q phi' + c int sign phi
    + int G phi = s int u(t - d) phi``. The regressors hold only the position (the drive's encoder,
    low noise: its noise enters through a band-pass, the bias is below 1e-4 relative at 1e-4 rad)
    and the command; the drive's velocity estimate is never used (the sign of the motion comes from
    positions too). Windows where the joint slides (slower than ``moving`` in at most 10 % of them) are fitted
    by linear least squares for each candidate delay; the smallest residual picks the delay.

    Uncertainty: the larger of the regression's standard error (overlap of the windows taken into
    account) and the spread of the estimates over ``folds`` held-out contiguous blocks (a
    jackknife); ``validation`` is the equation error on the held-out blocks. Identifiability: the
    condition number of the column-scaled regressors and the estimates' correlations. Load mass:
    every parameter's d ln p / d ln m of the model's load (refitted with the load 1 % heavier).
    """
    import numpy as np

    n = len(samples)
    if n < 50:
        raise JointsError(f"identification needs more samples than {n}")
    samples = _certain(samples)
    q = samples.q
    g = terms.gravity(q) if terms is not None else np.zeros(n)
    body = terms.body_inertia(float(q[0])) if terms is not None else 0.0
    reg = _Regression(samples, g, window=window if window is not None else WINDOW, max_delay=max_delay,
                      moving=moving)
    if reg.used < 20:
        raise JointsError(f"joint {joint}: only {reg.used} moving windows (|v| > {moving} rad/s for "
                          f"{reg.length * 1e3:.0f} ms): the excitation barely moved the joint; raise the amplitude")
    rms_g = float(np.sqrt(np.mean(reg.f4 ** 2)))
    rms_u = float(np.sqrt(np.mean(reg.g(0.0) ** 2))) or 1.0
    if known_inertia is None and rms_g < 0.05 * rms_u:
        raise ConfigError(
            f"joint {joint}: the model gives no gravity torque about this joint, so inertia and torque constant "
            "are known only as a ratio; identify on a gravity-loaded stand (e.g. models/erob_pendulum.xml) or "
            "give the joint's whole inertia (known_inertia, joints identify --inertia)", key="known_inertia")
    torque_mode = samples.mode == "torque"
    delay, friction = _model(reg, known_inertia, max_delay, torque_mode, extended_friction)
    vs, extra = friction
    A, y, names = reg.system(delay, known_inertia, friction=friction)
    x, rss = _solve(A, y, None, names)  # friction held >= 0, as in the model's choice
    est = _named(x, names, known_inertia)
    est.setdefault("coulomb_friction", 0.0)
    # the regression's standard errors (overlapping windows are not independent: inflate)
    dof = max(1, A.shape[0] - A.shape[1])
    scale = np.sqrt((A ** 2).sum(axis=0))
    As = A / scale
    cov = np.full((len(names), len(names)), math.inf)
    try:
        inv = np.linalg.inv(As.T @ As)
        cov = rss / dof * reg.overlap * inv / np.outer(scale, scale)
        se = dict(zip(names, np.sqrt(np.clip(np.diag(cov), 0, None))))
        sd = np.sqrt(np.clip(np.diag(inv), 1e-300, None))
        corr = inv / np.outer(sd, sd)
    except np.linalg.LinAlgError:
        se = {k: math.inf for k in names}
        corr = np.full((len(names), len(names)), 1.0)
    condition = float(np.linalg.cond(As))
    correlations = {f"{names[i]}/{names[j]}": float(corr[i, j])
                    for i in range(len(names)) for j in range(i + 1, len(names))}
    # held-out folds: contiguous blocks of the windows (each refits the delay and the Stribeck velocity)
    block = np.minimum((np.arange(reg.used) * folds) // reg.used, folds - 1)
    fold_est: list[dict[str, float]] = []
    held_r, held_u = 0.0, 0.0
    for k in range(folds):
        train, test = block != k, block == k
        if test.sum() == 0 or train.sum() < 20:
            continue
        dk = _best_delay(reg, known_inertia, max_delay, train, friction) if torque_mode else 0.0
        vk = _best_stribeck(reg, dk, known_inertia, extra, train, vs[1]) if vs is not None else None
        Ak, yk, _ = reg.system(dk, known_inertia, friction=(vk, extra))
        xk, _ = _solve(Ak, yk, train, names)
        e = _named(xk, names, known_inertia)
        e["delay"] = dk
        if vk is not None:
            e["stribeck_velocity"] = vk[0]
        fold_est.append(e)
        r = Ak[test] @ xk - yk[test]
        held_r += float(r @ r)
        held_u += float(((xk[-1] * Ak[test, -1]) ** 2).sum())
    validation = math.sqrt(held_r / held_u) if held_u > 0 else math.inf
    kf = len(fold_est)

    def jack(key: str, value: Any) -> float:
        vals = np.array([value(e) for e in fold_est])
        return float(np.sqrt((kf - 1) / kf * ((vals - vals.mean()) ** 2).sum())) if kf > 1 else math.inf

    armature = est["inertia"] - body
    # the Coulomb and Stribeck levels' uncertainties are stated relative to the friction at standstill (their sum):
    # with a Stribeck term the Coulomb level alone can be near 0 (BAM's M2)
    static = est["coulomb_friction"] + est.get("stribeck_friction", 0.0)
    std: dict[str, float] = {}
    for key in names:
        size = abs(static) if key in ("coulomb_friction", "stribeck_friction") else abs(est[key])
        std[key] = max(float(se[key]), jack(key, lambda e, k=key: e[k])) / size if size else math.inf
    # the friction curve at 10 speeds up to those the excitation reached: regression error and spread over folds
    speeds = np.linspace(0.1, 1.0, 10) * max(reg.speed, 2 * moving)
    grad = np.zeros((len(speeds), len(names)))
    grad[:, names.index("viscous_friction")] = speeds
    if "coulomb_friction" in names:
        grad[:, names.index("coulomb_friction")] = 1.0
    if vs is not None:
        grad[:, names.index("stribeck_friction")] = np.exp(-np.abs(speeds / vs[0]) ** vs[1])

    def curve(e: Mapping[str, float]) -> Any:
        s_vs = e.get("stribeck_velocity", vs[0] if vs is not None else 1.0)
        excess = e.get("stribeck_friction", 0.0) * np.exp(-np.abs(speeds / s_vs) ** (vs[1] if vs else 2.0))
        return e.get("coulomb_friction", 0.0) + excess + e["viscous_friction"] * speeds

    level = curve(est)
    on_folds = np.array([curve(e) for e in fold_est])
    jack_curve = np.sqrt((kf - 1) / kf * ((on_folds - on_folds.mean(axis=0)) ** 2).sum(axis=0)) if kf > 1 else math.inf
    reg_curve = np.sqrt(np.clip(np.einsum("ij,jk,ik->i", grad, cov, grad), 0, None))
    std["friction"] = float(np.max(np.maximum(reg_curve, jack_curve) / np.abs(level)))
    for key, power in SCALED.items():  # estimated as the parameter x torque scale^power
        if key in est:
            std[key] = max(std[key], power * std["torque_scale"])
            est[key] /= est["torque_scale"] ** power
    if vs is not None:  # the spread over the folds, at least the search's step
        std["stribeck_velocity"] = max(jack("stribeck_velocity", lambda e: e["stribeck_velocity"]) / vs[0],
                                       STRIBECK_STEP)
    if known_inertia is None:
        arm_unc = max(float(se["inertia"]), jack("armature", lambda e: e["inertia"] - body))
        std["armature"] = arm_unc / abs(armature) if armature else math.inf
    if torque_mode:
        std["delay"] = max(jack("delay", lambda e: e["delay"]), reg.period / 4)
    impulse = float(np.sqrt(np.mean((est["torque_scale"] * A[:, -1]) ** 2))) or 1.0
    residual = math.sqrt(rss / reg.used) / impulse
    # load-mass sensitivity: refit with the model's load 1 % heavier (gravity and the bodies' inertia)
    sensitivity: dict[str, float] = {}
    load_name, load_mass = "", math.nan
    if terms is not None:
        load_name, load_mass = terms.load  # type: ignore[attr-defined]
        if load_mass > 0:
            heavier = ModelTerms(terms.path, terms.joint, terms.pose, load_factor=1.01)
            g2 = heavier.gravity(q)
            body2 = heavier.body_inertia(float(q[0]))
            ratio = float(np.sqrt(np.mean(g2 ** 2)) / (np.sqrt(np.mean(g ** 2)) or 1.0))
            A2, y2, _ = reg.system(delay, known_inertia, f4_scale=ratio, friction=friction)
            x2, _ = _solve(A2, y2, None, names)
            e2 = _named(x2, names, known_inertia)
            e2["armature"] = e2["inertia"] - body2
            for key, power in SCALED.items():
                if key in e2:
                    e2[key] /= e2["torque_scale"] ** power
            base = dict(est, armature=armature)
            for key in ("armature", "inertia", "coulomb_friction", "viscous_friction", "stribeck_friction",
                        *FRICTION_TERMS[1:], "torque_scale"):
                if key in e2 and base[key]:
                    sensitivity[key] = (e2[key] / base[key] - 1.0) / 0.01
    if est["torque_scale"] <= 0 or est["inertia"] <= 0:
        raise JointsError(f"joint {joint}: the fit is not physical (inertia {est['inertia']:.4g}, torque scale "
                          f"{est['torque_scale']:.4g}); the excitation did not move the joint enough or the model is "
                          "not the joint's")
    spread = float(np.std(np.diff(samples.t)))
    return Identification(
        joint=joint, mode=samples.mode, inertia=est["inertia"], body_inertia=body,
        coulomb_friction=max(est["coulomb_friction"], 0.0), viscous_friction=max(est["viscous_friction"], 0.0),
        torque_scale=est["torque_scale"], delay=delay if torque_mode else None, feedback_latency=feedback_latency,
        gravity_loaded=known_inertia is None, samples=n, used=reg.used, period=reg.period, residual=residual,
        std=std, excitation=dict(excitation or {}), validation=validation, condition=condition,
        correlations=correlations, load_sensitivity=sensitivity, load=load_name, load_mass=load_mass,
        period_spread=spread, window=reg.length, stribeck_friction=max(est.get("stribeck_friction", 0.0), 0.0),
        stribeck_velocity=vs[0] if vs is not None else math.nan,
        stribeck_exponent=vs[1] if vs is not None else math.nan,
        **{k: max(est.get(k, 0.0), 0.0) for k in FRICTION_TERMS[1:]})


# -- the whole procedure ------------------------------------------------------------------------------


def model_terms(rig: Any, name: str) -> ModelTerms:
    """The MJCF terms of joint ``name`` with the other joints where they stand now."""
    cfg = rig.config
    pose = {}
    for other, jc in cfg.joints.items():
        if other != name:
            oj = rig.joints[other]
            s = oj.last_state or oj.state()
            pose[jc.mjcf_joint or other] = (s.position - oj.offset) * oj.direction
    jc = cfg.joints[name]
    return ModelTerms(rig.model_path(), jc.mjcf_joint or name, pose)


def identify(rig: Any, name: str, excitation: Excitation | None = None, *, known_inertia: float | None = None,
             progress: Progress | None = None) -> Identification:
    """Excite joint ``name`` of ``rig`` and fit its parameters (see the module docstring).

    The same call runs on hardware and on a twin. ``known_inertia`` [kg*m^2]: the joint's whole
    inertia about its axis, for a joint with no gravity torque.
    """
    excitation = excitation or Excitation()
    j = rig.joints[name]
    if j.lead is not None:
        raise CommandError(f"joint {name}: identification covers rotary joints (this one has a lead)")
    if known_inertia is not None and not (math.isfinite(known_inertia) and known_inertia > 0):
        raise ConfigError(f"known_inertia must be > 0 kg*m^2, got {known_inertia!r}", key="known_inertia")
    terms = model_terms(rig, name)
    if known_inertia is None and j.limits.position is not None:
        import numpy as np

        lo, hi = j.limits.position
        grid = (np.linspace(lo, hi, 41) - j.offset) * j.direction
        lim = j.limits.torque if excitation.mode == "torque" else None
        peak = float(np.abs(terms.gravity(grid)).max())
        if peak < 0.02 * (lim or 1.0):
            raise ConfigError(
                f"joint {name}: the model gives no gravity torque about this joint (at most {peak:.3g} N*m inside "
                "its limits), so inertia and torque constant are known only as a ratio; identify on a "
                "gravity-loaded stand (e.g. models/erob_pendulum.xml) or give the joint's whole inertia "
                "(known_inertia, joints identify --inertia)", key="known_inertia")
    samples = excite(rig, name, excitation, progress=progress)
    info = {k: v for k, v in asdict(excitation).items()}
    if info.get("amplitude") is None:
        lim = j.limits.torque if excitation.mode == "torque" else j.limits.velocity
        info["amplitude"] = 0.5 * lim if lim is not None else None
    # a twin's positions lag its physics by half a substep (semi-implicit Euler: the position steps with the
    # velocity at the step's end, a state is read at the start of the last substep): the latency the
    # position-based fit sees in a twin of the same delay
    return fit(samples, terms, known_inertia=known_inertia, feedback_latency=0.5 * rig.config.sim.timestep,
               joint=name, excitation=info)


# -- the overlay --------------------------------------------------------------------------------------


def overlay_values(profile: Any, ident: Identification) -> dict[str, float]:
    """Device-profile overrides that make ``profile`` (the one the driver used) the identified joint.

    eRob: ``rotor_inertia`` = armature / (N+1)^2, ``efficiency`` x torque scale, friction,
    ``command_delay``. A family whose profile has a plain ``torque_constant`` field gets it scaled
    instead, and ``rotor_inertia`` = armature (a direct drive).
    """
    names = {f.name for f in fields(profile)}
    out: dict[str, float] = {}
    if ident.armature <= 0:
        raise JointsError(f"joint {ident.joint}: identified inertia {ident.inertia:.4g} is below the model's "
                          f"bodies' {ident.body_inertia:.4g} kg*m^2: the model's load is heavier than the real one")
    if "rotor_inertia" in names:
        ratio = float(getattr(profile, "kinematic_ratio", 1))
        out["rotor_inertia"] = ident.armature / ratio ** 2
    out["coulomb_friction"] = ident.coulomb_friction
    out["viscous_friction"] = ident.viscous_friction
    if "stribeck_friction" in names:  # 0 where the data showed none (it clears an older overlay's)
        out["stribeck_friction"] = ident.stribeck_friction
        if ident.stribeck_friction > 0:
            out["stribeck_velocity"] = ident.stribeck_velocity
            out["stribeck_exponent"] = ident.stribeck_exponent
    for k in FRICTION_TERMS[1:]:
        if k in names:
            out[k] = getattr(ident, k)
    if "efficiency" in names and "motor_kt" in names:
        eff = float(profile.efficiency) * ident.torque_scale
        if not 0 < eff <= 1:
            raise JointsError(f"joint {ident.joint}: torque scale {ident.torque_scale:.4g} would make the efficiency "
                              f"{eff:.4g} (must be in (0, 1])")
        out["efficiency"] = eff
    elif "torque_constant" in names:
        out["torque_constant"] = float(profile.torque_constant) * ident.torque_scale
    if "command_delay" in names and ident.command_delay is not None:
        out["command_delay"] = round(ident.command_delay, 6)  # us: the fit's resolution is coarser
    return out


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(float(v)) if isinstance(v, float) else str(v)
    if v is None:
        return '"none"'
    return '"' + str(v).replace("\\", "\\\\").replace('"', '\\"') + '"'


def write_overlay(path: str | Path, profile: Any, ident: Identification, *, device: str = "",
                  config: str = "", force: bool = False) -> Path:
    """Write the profile overlay of ``ident`` (TOML, see the module docstring) and return its path.

    A fit that misses a threshold (:meth:`Identification.problems`) raises :class:`PoorFit` and
    writes nothing; ``force=True`` writes it with the warning inside the file.
    """
    bad = ident.problems()
    if bad and not force:
        raise PoorFit(f"joint {ident.joint}: the identification is not trustworthy ({'; '.join(bad)}); no overlay "
                      "written (joints identify --force writes it anyway, with this warning inside)")
    values = overlay_values(profile, ident)
    notes = {
        "rotor_inertia": f"armature {ident.armature:.6g} kg*m^2 at the output (inertia {ident.inertia:.6g} "
                         f"- bodies {ident.body_inertia:.6g})",
        "efficiency": f"torque constant x {ident.torque_scale:.5f} (was {getattr(profile, 'efficiency', 0):.5g})",
        "torque_constant": f"x {ident.torque_scale:.5f}",
        "command_delay": (f"observed delay {(ident.delay or 0) * 1e3:.2f} ms - the twin's feedback latency "
                          f"{ident.feedback_latency * 1e3:.2f} ms"),
        "coulomb_friction": "N*m (MuJoCo frictionloss)",
        "viscous_friction": "N*m*s/rad (MuJoCo damping)",
        "stribeck_friction": "N*m more at standstill, fading as exp(-|v / stribeck_velocity|^stribeck_exponent)",
        "stribeck_velocity": "rad/s",
        "load_friction": "N*m per N*m of motor torque",
        "load_friction_quadratic": "N*m per (N*m of motor torque)^2",
        "external_friction": "N*m per N*m of external (gravity) torque",
    }
    lines = [
        (f"# Device-profile overlay of joint {ident.joint!r}, written by `joints identify` "
        f"{datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')}."),
        "# Use it from the joint's config: profile_overlay = \"<this file>\" (inline `profile` keys win).",
    ]
    if bad:
        lines.append(f"# WARNING: written with --force although the fit misses its thresholds: {'; '.join(bad)}")
    lines += ["", "[profile]"]
    for k, v in values.items():
        lines.append(f"{k} = {_toml_value(v)}  # {notes.get(k, '')}".rstrip(" #"))
    lines += ["", "[identification]"]
    summary = ident.summary()
    summary.update(device=device, model=str(getattr(profile, "model", "")), config=config)
    summary.pop("problems", None)
    summary.pop("inseparable", None)
    if bad:
        summary["warning"] = "forced: " + "; ".join(bad)
    for k, v in summary.items():
        if isinstance(v, Mapping) or v is None:
            continue
        lines.append(f"{k} = {_toml_value(v)}")
    lines.append(f"inseparable = [{', '.join(_toml_value(k) for k in ident.inseparable())}]")
    lines += ["", "[identification.std]  # relative uncertainties (delay: s): regression or held-out spread"]
    lines += [f"{k} = {_toml_value(v)}" for k, v in ident.std.items()]
    lines += ["", "[identification.correlations]  # of the estimates"]
    lines += [f'"{k}" = {_toml_value(v)}' for k, v in ident.correlations.items()]
    lines += ["", "[identification.load_sensitivity]  # d ln(parameter) / d ln(load mass)"]
    lines += [f"{k} = {_toml_value(v)}" for k, v in ident.load_sensitivity.items()]
    lines += ["", "[identification.excitation]"]
    lines += [f"{k} = {_toml_value(v)}" for k, v in ident.excitation.items() if v is not None]
    p = Path(path)
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return p

