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
``torque_scale``      s = true torque / the torque the driver computes from current with the
                      profile's torque constant (1 = the profile is right)
``delay``             command -> feedback delay [s] the host observes (the drive acting on a
                      command late, plus its feedback being sampled late)
====================  ======================================================================

Model: ``J dv/dt = s u(t - delay) - b v - c sign(v) - G(q)`` with u the commanded torque and G the
gravity torque of the MJCF model at q (MuJoCo ``qfrc_bias`` at rest, other joints where they stood).
It is fitted in integral form over short windows (``J (v_b - v_a) = s int u - b (q_b - q_a) - c
int sign(v) - int G``: no differentiation of measured signals), on the samples where the joint moves
(friction is only a sign function while it slides), by linear least squares for every candidate
delay; the delay with the smallest residual wins.

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
    "Excitation",
    "Identification",
    "IdentificationAborted",
    "ModelTerms",
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
    """A multi-sine (Schroeder phases, log-spaced frequencies) in torque or speed, faded in and out.

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
        if self.components < 1:
            raise ConfigError(f"components must be >= 1, got {self.components}", key="components")
        if self.duration < 3 * self.fade:
            raise ConfigError(f"duration {self.duration} s is too short for the {self.fade} s fades",
                              key="duration")

    def shape(self) -> Callable[[float], float]:
        """The signal of unit peak as a function of time since the start [s] (0 outside the duration)."""
        import numpy as np

        n = self.components
        freqs = np.geomspace(self.f_min, self.f_max, n)
        k = np.arange(1, n + 1)
        phases = -np.pi * k * (k - 1) / n  # Schroeder: a low crest factor
        grid = np.arange(0.0, self.duration, 1e-3)
        peak = float(np.abs(np.sin(2 * np.pi * np.outer(grid, freqs) + phases).sum(axis=1)).max())
        w = 2 * np.pi * freqs
        fade_in, fade_out, duration = self.fade, self.fade * 2 / 3, self.duration

        def signal(t: float) -> float:
            if not 0.0 <= t < duration:
                return 0.0
            env = min(1.0, t / fade_in, (duration - t) / fade_out)
            env = env * env * (3 - 2 * env)  # smoothstep: no jump in the command's slope
            return float(env * np.sin(w * t + phases).sum() / peak)

        return signal


@dataclass(frozen=True)
class Samples:
    """What the excitation recorded (model frame: the MJCF joint's sign, rad, N*m)."""

    mode: str
    t: Any  #: s, state read times (numpy arrays from here on)
    w: Any  #: s, command write times
    u: Any  #: commanded torque [N*m] (torque mode) or speed [rad/s] (speed mode)
    q: Any  #: rad
    v: Any  #: rad/s
    tau: Any  #: N*m, the drive's torque estimate (current x the profile's torque constant)

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

    def __post_init__(self) -> None:
        import mujoco

        m = mujoco.MjModel.from_xml_path(str(self.path))
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
    used: int  #: samples of moving windows the fit used
    period: float  #: s, the sampling period achieved
    residual: float  #: RMS of the fit's residual over RMS of the torque impulse (0 = exact)
    std: Mapping[str, float] = field(default_factory=dict)  #: relative standard errors
    excitation: Mapping[str, Any] = field(default_factory=dict)

    @property
    def armature(self) -> float:
        """J minus the bodies' inertia: reflected rotor inertia + load missing from the model [kg*m^2]."""
        return self.inertia - self.body_inertia

    @property
    def command_delay(self) -> float | None:
        """The twin's command delay reproducing :attr:`delay` (its own feedback latency taken off)."""
        return None if self.delay is None else max(0.0, self.delay - self.feedback_latency)

    def summary(self) -> dict[str, Any]:
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in ("std", "excitation")}
        out.update(armature=self.armature, command_delay=self.command_delay, std=dict(self.std),
                   excitation=dict(self.excitation))
        return out

    def __str__(self) -> str:
        lines = [(f"joint {self.joint}: {self.samples} samples every {self.period * 1e3:.3f} ms ({self.mode} mode), "
                 f"{self.used} used, residual {self.residual:.3%}"),
                 (f"  inertia          {self.inertia:.5g} kg*m^2 (bodies {self.body_inertia:.5g}, "
                 f"armature {self.armature:.5g})"),
                 f"  coulomb friction {self.coulomb_friction:.5g} N*m",
                 f"  viscous friction {self.viscous_friction:.5g} N*m*s/rad",
                 f"  torque scale     {self.torque_scale:.5g}"]
        if self.delay is not None:
            lines.append(f"  delay            {self.delay * 1e3:.2f} ms (twin command delay "
                         f"{(self.command_delay or 0.0) * 1e3:.2f} ms)")
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
    t_, w_, u_, q_, v_, tau_ = [], [], [], [], [], []
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
            command(u * d)
            asked = rig.time
            s = j.state()
            q = (s.position - off) * d
            t_.append(0.5 * (asked + s.time))  # the drive sampled between our request and its reply
            w_.append(now)
            u_.append(u)
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
    arr = [np.asarray(x, dtype=float) for x in (t_, w_, u_, q_, v_, tau_)]
    return Samples(mode, *arr)


# -- fit ----------------------------------------------------------------------------------------------


def _cum(x: Any, dt: Any) -> Any:
    """Running integral with a left sum: out[k] = sum_{i<k} x[i] dt[i] (len(x) values)."""
    import numpy as np

    return np.concatenate([[0.0], np.cumsum(x[:-1] * dt)])


def fit(samples: Samples, terms: ModelTerms | None, *, known_inertia: float | None = None,
        feedback_latency: float = 0.0, window: float | None = None, max_delay: float = 0.05,
        moving: float = MOVING, joint: str = "", excitation: Mapping[str, Any] | None = None) -> Identification:
    """Fit inertia, friction, torque scale and delay to ``samples`` (see the module docstring).

    ``terms`` supplies G(q) and the bodies' inertia (None: no model, no gravity); with no gravity
    torque worth the name ``known_inertia`` [kg*m^2, the whole J] is required. ``window`` [s] is
    the integration window (a low-pass against measurement noise and timing jitter; default 10
    sampling periods, at least 10 ms), ``max_delay`` [s] the largest delay tried.
    """
    import numpy as np

    n = len(samples)
    if n < 50:
        raise JointsError(f"identification needs more samples than {n}")
    t, w, u, q, v, tau = samples.t, samples.w, samples.u, samples.q, samples.v, samples.tau
    dt = np.diff(t)
    period = float(np.median(dt))
    win = max(1, round((window if window is not None else max(0.01, 10 * period)) / period))
    a = np.arange(0, n - win)
    b = a + win
    g = terms.gravity(q) if terms is not None else np.zeros(n)
    body = terms.body_inertia(float(q[0])) if terms is not None else 0.0
    # integral form over each window [t_a, t_b]: state samples are the physics at the start of a step
    cum_g = _cum(g, dt)  # left sum: gravity at the start of each step
    cum_s = np.concatenate([[0.0], np.cumsum(np.sign(v[1:]) * dt)])  # right sum: friction on the step's end
    dv, dq = v[b] - v[a], q[b] - q[a]
    int_g, int_s = cum_g[b] - cum_g[a], cum_s[b] - cum_s[a]
    mv = np.abs(v) > moving
    run = np.concatenate([[0], np.cumsum(~mv)])
    ok = (run[b + 1] - run[a]) == 0  # every sample of the window moving
    used = int(ok.sum())
    if used < 20:
        raise JointsError(f"joint {joint}: only {used} moving windows (|v| > {moving} rad/s): the excitation "
                          "barely moved the joint; raise the amplitude")
    rms_g = float(np.sqrt(np.mean(g[mv] ** 2)))

    if samples.mode == "torque":
        cum_u_w = _cum(u, np.diff(w)) if n > 1 else np.zeros(1)

        def int_u(d: float) -> Any:
            """Integral over each window of the zero-order-held command, delayed by d."""
            def at(x: Any) -> Any:
                i = np.clip(np.searchsorted(w, x, side="right") - 1, 0, n - 1)
                return cum_u_w[i] + u[i] * (x - w[i])
            return at(t[b] - d) - at(t[a] - d)
    else:
        cum_tau = _cum(tau, dt)  # the current a sample reports drove the step that starts at it
        fixed = cum_tau[b] - cum_tau[a]

        def int_u(d: float) -> Any:
            return fixed

    scale_from_gravity = rms_g > 0.05 * float(np.sqrt(np.mean(tau[mv] ** 2)) or 1.0)
    if known_inertia is None and not scale_from_gravity:
        raise ConfigError(
            f"joint {joint}: the model gives no gravity torque about this joint, so inertia and torque constant "
            "are known only as a ratio; identify on a gravity-loaded stand (e.g. models/erob_pendulum.xml) or "
            "give the joint's whole inertia (known_inertia, joints identify --inertia)", key="known_inertia")

    def solve(d: float) -> tuple[Any, float, Any, Any]:
        iu = int_u(d)
        if known_inertia is None:
            A = np.stack([dv, dq, int_s, -iu], axis=1)[ok]
            y = -int_g[ok]
        else:
            A = np.stack([dq, int_s, -iu], axis=1)[ok]
            y = -(known_inertia * dv + int_g)[ok]
        x, *_ = np.linalg.lstsq(A, y, rcond=None)
        r = A @ x - y
        return x, float(r @ r), A, iu

    if samples.mode == "torque":
        grid = np.arange(0.0, max_delay + 1e-12, max(period / 4, 1e-4))
        costs = [solve(float(d))[1] for d in grid]
        i = int(np.argmin(costs))
        lo_, hi_ = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        fine = np.linspace(lo_, hi_, 41)
        delay: float | None = float(fine[int(np.argmin([solve(float(d))[1] for d in fine]))])
    else:
        delay = None
    x, cost, A, iu = solve(delay or 0.0)
    if known_inertia is None:
        inertia, visc, coul, s = (float(z) for z in x)
    else:
        visc, coul, s = (float(z) for z in x)
        inertia = float(known_inertia)
    dof = max(1, A.shape[0] - A.shape[1])
    sigma2 = cost / dof
    try:
        cov = sigma2 * np.linalg.inv(A.T @ A)
        se = np.sqrt(np.clip(np.diag(cov), 0, None))
    except np.linalg.LinAlgError:
        se = np.full(A.shape[1], math.inf)
    names = ["inertia", "viscous_friction", "coulomb_friction", "torque_scale"]
    if known_inertia is not None:
        names = names[1:]
    std = {nm: float(e / abs(val)) if val else math.inf for nm, e, val in zip(names, se, x)}
    impulse = float(np.sqrt(np.mean((s * iu[ok]) ** 2))) or 1.0
    residual = math.sqrt(cost / used) / impulse
    if s <= 0 or inertia <= 0:
        raise JointsError(f"joint {joint}: the fit is not physical (inertia {inertia:.4g}, torque scale {s:.4g}); "
                          "the excitation did not move the joint enough or the model is not the joint's")
    return Identification(
        joint=joint, mode=samples.mode, inertia=inertia, body_inertia=body, coulomb_friction=max(coul, 0.0),
        viscous_friction=max(visc, 0.0), torque_scale=s, delay=delay, feedback_latency=feedback_latency,
        gravity_loaded=known_inertia is None, samples=n, used=used, period=period, residual=residual, std=std,
        excitation=dict(excitation or {}))


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
    return fit(samples, terms, known_inertia=known_inertia, feedback_latency=rig.config.sim.timestep,
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
                  config: str = "") -> Path:
    """Write the profile overlay of ``ident`` (TOML, see the module docstring) and return its path."""
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
    }
    lines = [
        (f"# Device-profile overlay of joint {ident.joint!r}, written by `joints identify` "
        f"{datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')}."),
        "# Use it from the joint's config: profile_overlay = \"<this file>\" (inline `profile` keys win).",
        "",
        "[profile]",
    ]
    for k, v in values.items():
        lines.append(f"{k} = {_toml_value(v)}  # {notes.get(k, '')}".rstrip(" #"))
    lines += ["", "[identification]"]
    summary = ident.summary()
    summary.update(device=device, model=str(getattr(profile, "model", "")), config=config)
    for k, v in summary.items():
        if isinstance(v, Mapping) or v is None:
            continue
        lines.append(f"{k} = {_toml_value(v)}")
    lines += ["", "[identification.std]  # relative standard errors of the least-squares fit"]
    lines += [f"{k} = {_toml_value(v)}" for k, v in ident.std.items()]
    lines += ["", "[identification.excitation]"]
    lines += [f"{k} = {_toml_value(v)}" for k, v in ident.excitation.items() if v is not None]
    p = Path(path)
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return p

