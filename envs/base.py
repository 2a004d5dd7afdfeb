"""JointsEnv: a gymnasium environment over the public Joint API, on sim or hardware from one config.

Rules:

* The env acts ONLY through the public API - ``joint.enable / move_to / set_velocity / set_torque
  / stop / state / write``, ``rig.sleep``, ``rig.reset`` - so the same code runs on emulated and on
  real drives. Sim-only extras (seeded start state, domain randomisation, rendering, ground-truth
  task terms) use the rig's public sim API ``rig.sim`` (None on hardware), as gymnasium's
  ``MujocoEnv`` exposes ``model`` and ``data`` (here too, None on hardware).
* Fixed control period (``dt``, per env a rate its default bus carries): ``step`` sends the action's commands, waits on the
  rig's clock until the next tick of a fixed schedule (sim: advances physics; hardware: the wall
  clock, absorbing the bus time), then reads every joint's state. The drive holds the command
  between ticks (zero-order hold).
* Deterministic in sim: no wall clock, no global RNG; every random draw comes from
  ``self.np_random`` (seeded by ``reset(seed=...)``); the twins' sensor noise from the same seed.

Actions are normalised to ``[-1, 1]`` per joint (see :meth:`JointsEnv.command_of`):

=============  =========================================================================
action mode    a in [-1, 1] means
=============  =========================================================================
"position"     target angle ``lo + (a + 1) / 2 * (hi - lo)`` [rad] over the joint's
               position limits, reached with the drive's own trapezoidal profile
               (``joint.move_to`` every step; the profile is the config's ``motion``)
"velocity"     speed command ``a * limits.velocity`` [rad/s] (``joint.set_velocity``, ramped
               with ``motion.acceleration``)
"torque"       torque command ``a * limits.torque`` [N*m] (``joint.set_torque``)
=============  =========================================================================

Safety: any action keeps the drives inside their limits, by construction rather than by luck
(:meth:`JointsEnv.safe_command` is what is sent):

* position targets lie within the joint's position limits; the drive's own profile (the config's
  ``motion``) moves there, and a new target while moving is followed without a setpoint jump;
* velocity commands are capped, per joint and per step, at the fastest speed that the drive's
  ramp (``motion.acceleration``) reaches from the present speed during one period and still
  stops from before the position limit (5 mrad short of it; :func:`braking_speed`), so the whole
  range stays reachable (the joint slows down as it nears a limit and stops there);
* a task may add its own rule (:meth:`JointsEnv._shield`; the arm keeps its links off the floor and
  its base); torque commands are sent as they are (within the torque limit).

The shipped configs fit the physics: profile speeds and velocity limits the drives sustain within
their continuous current, accelerations within the torque limit, torque limits below the drives'
stall-detection current (see the comments in ``joints/configs/*.toml``). A drive that faults
anyway ends the episode (``terminated``; ``info["fault"]`` names the joint, the fault and its
text), the env stops the other joints, and ``reset()`` clears it (sim: power cycle; hardware:
clear the fault, enable again).

Observation (float64) starts with the joint terms, then the task's terms:
``[position_1..n [rad], velocity_1..n [rad/s], torque_1..n [N*m], task...]``. Bounds per joint:
position within its limits widened by 0.5 rad, velocity within +-2x its velocity limit, torque
within +-2x its torque limit (the drive may exceed the user's torque limit in position/velocity
mode: the limit bounds commands); values outside are clipped. Torque is the drive's estimate from
its motor current.
"""

from __future__ import annotations

import math
import os
from collections import deque
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

import joints
from envs.configs import config_path
from envs.randomization import GAINS, DomainRandomization, apply_sensors
from envs.render import CameraSpec, SceneRenderer
from joints.errors import MotionTimeout, OverrunError

ACTION_MODES = ("position", "velocity", "torque")
#: s between "enable" and the first motion command (the eRob manual's 500 ms; the emulator enforces it)
ENABLE_SETTLE = 0.5
#: rad a joint may pass its position limits (overshoot) before the episode ends as a limit violation
LIMIT_MARGIN = 0.05
#: rad the observation's position bounds extend beyond the limits
OBS_POSITION_MARGIN = 0.5
#: rad short of a position limit where velocity actions brake to (the joint lags the drive's speed
#: ramp and carries on ~2 mrad past where the ramp stops: it stops ~3 mrad inside the limit)
LIMIT_INSET = 0.005


def clip(value: float, low: float, high: float) -> float:
    """``np.clip`` of one float (NaN stays NaN; a value equal to a bound is kept, as numpy 2 keeps it), the
    same bits without an array's cost. Only a bound of signed zero could tell the tie rules of numpy
    versions apart; the envs' bounds are nonzero limits."""
    if math.isnan(value):
        return value
    return min(max(value, low), high)  # max/min keep their first argument on a tie


def braking_speed(distance: np.ndarray, acceleration: np.ndarray, period: float,
                  speed: np.ndarray | float = 0.0) -> np.ndarray:
    """Fastest speed command ``v`` >= 0 towards a stop ``distance`` [rad] away that a joint moving
    at ``speed`` [rad/s] towards it may get for one ``period`` [s] and still stop in time: the
    drive ramps from ``speed`` to ``v`` with ``acceleration`` [rad/s^2] during the period, then
    brakes with it. ``inf`` where any command is safe (the distance exceeds the run-out of a
    whole period of acceleration), 0 where none is (the joint is too fast already: brake).

    The distance covered, ``D(v)``, grows with ``v``; with ``a`` the acceleration, ``u`` the speed
    (>= 0; moving away counts as standing) and ``t = dt``:

    * ``v >= u`` (ramp up, done within the period): ``D = v t + u v / a - u^2 / (2a)``;
    * ``u - a t <= v < u`` (ramp down within the period): ``D = v^2 / a + v (t - u / a) + u^2 / (2a)``;
    * beyond those the period ends mid-ramp and ``D`` no longer depends on ``v``.
    """
    a = np.asarray(acceleration, dtype=np.float64)
    d = np.asarray(distance, dtype=np.float64)
    u = np.maximum(np.asarray(speed, dtype=np.float64), 0.0)
    t = period
    at = a * t
    d_up = (2.0 * u + at) * 0.5 * t + (u + at) ** 2 / (2.0 * a)  # a whole period of ramping up
    d_hold = u * t + u * u / (2.0 * a)  # v = u
    lo = np.maximum(u - at, 0.0)  # the lowest speed reachable in the period
    d_lo = lo * t + (u - lo) ** 2 / (2.0 * a) + lo * lo / (2.0 * a)
    up = (d + u * u / (2.0 * a)) / (t + u / a)  # D(v) = d on the ramp-up branch
    b = t - u / a
    disc = np.maximum(b * b - 4.0 / a * (u * u / (2.0 * a) - d), 0.0)
    down = np.maximum((np.sqrt(disc) - b) * a / 2.0, 0.0)  # D(v) = d on the ramp-down branch
    out: np.ndarray = np.where(d >= d_up, np.inf, np.where(d >= d_hold, up, np.where(d >= d_lo, down, 0.0)))
    return out


def braking_speed_of(distance: float, acceleration: float, period: float, speed: float) -> float:
    """:func:`braking_speed` of one joint on plain floats: the same IEEE operations in the same order
    (``x ** 2`` of an array is ``x * x``; ``np.maximum(x, 0.0)`` is ``x if not x <= 0.0 else 0.0``, NaN
    kept; ``np.sqrt`` and ``math.sqrt`` both round correctly), so the same bits, for the env's per-step
    cap. Only the branch ``np.where`` picks is computed."""
    a, d, t = acceleration, distance, period
    if not a > 0.0:  # no ramp (numpy's inf / nan arithmetic, without a ZeroDivisionError)
        return float(braking_speed(np.array([d]), np.array([a]), t, speed)[0])
    u = speed if not speed <= 0.0 else 0.0
    at = a * t
    two_a = 2.0 * a
    w = u + at
    if d >= (2.0 * u + at) * 0.5 * t + w * w / two_a:  # d_up
        return math.inf
    uu = u * u
    if d >= u * t + uu / two_a:  # d_hold
        return (d + uu / two_a) / (t + u / a)
    lo = u - at
    lo = lo if not lo <= 0.0 else 0.0
    r = u - lo
    if d >= lo * t + r * r / two_a + lo * lo / two_a:  # d_lo
        b = t - u / a
        disc = b * b - 4.0 / a * (uu / two_a - d)
        disc = disc if not disc <= 0.0 else 0.0
        down = (math.sqrt(disc) - b) * a / 2.0
        return down if not down <= 0.0 else 0.0
    return 0.0


def clip_to(value: float, low: float, high: float) -> float:
    """``np.clip`` of one float between ARRAY bounds (whose loop, unlike a scalar bound's, gives the
    bound on a tie: ``np.clip([0.0], [-0.0], [1.0])`` is ``-0.0``), NaN kept: its bits on plain floats."""
    if math.isnan(value):
        return value
    m = value if value > low else low  # noqa: FURB136 - numpy's rule, not max()'s
    return m if m < high else high  # noqa: FURB136


def fault_info(name: str, state: joints.JointState) -> dict[str, Any]:
    """``info["fault"]`` of a faulted joint: its name, the fault's name, code, text and what clears it."""
    f = state.fault
    assert f is not None
    return {"joint": name, "name": f.name, "code": f.code, "text": f.text, "clears": f.clears}


#: the parts of an env's step that its one-call step (:meth:`~joints.compiled_path.CompiledPath.step`) does in one
STEP_PARTS = ("begin_step", "finish_step", "_command", "_read", "_wait_until", "_finish", "tick_time", "note_overrun")
_OWN_STEP: dict[type, bool] = {}  #: per env type: whether it keeps its one-call step's parts (RigEnv._keeps_step_parts)


class RigEnv(gym.Env[np.ndarray, np.ndarray]):
    """What every ``joints/`` env shares: a rig, a fixed control schedule, rendering and closing.

    Subclasses set ``rig``, ``sim``, ``overruns``, ``_t0``, ``_closed``, ``_renderer``, ``width``,
    ``height`` and implement ``_scene``, ``_update_twin`` and ``_markers``.
    """

    rig: joints.Rig
    sim: bool
    control_period: float
    overruns: int
    overrun_time: float
    _overrun: float
    _tick: int
    width: int
    height: int
    _t0: float
    _slip: float
    _closed: bool = True  #: until ``_start`` opened the rig (close() of an env whose setup failed does nothing)
    _renderer: SceneRenderer | None
    #: how the renderer looks at the model
    camera = CameraSpec()

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() was called without a render_mode; pass render_mode='rgb_array' or 'human'")
            return None
        self._check_open()
        if self._renderer is None:
            model, data = self._scene()
            self._renderer = SceneRenderer(self.render_mode, model, data, width=self.width, height=self.height,
                                           camera=self.camera)
        if not self.sim:
            self._update_twin()
        return self._renderer.render(self.rig.time - self._t0, self._markers())

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            if self._renderer is not None:
                self._renderer.close()
                self._renderer = None
        finally:
            self.rig.close()

    # -- internals --------------------------------------------------------------------------
    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError("the env is closed")

    _noise_seeded: np.random.Generator | None = None  #: the generator the sensors' episodes are counted from
    _episode = 0  #: sim resets since :attr:`_noise_seeded` was made (the sensors' seed counts them)

    def _reset_rig(self) -> None:
        """Sim: physics and every twin to power-on (``rig.reset``), the twins' sensor noise seeded from the env's
        seed (``np_random_seed``) and the episode's number since it was seeded, leaving ``np_random``'s own draws
        as they were: ``reset(seed=s)`` replays an episode's noise, every other episode and every rig of a batch
        (seeded ``s + i``) draws its own."""
        rng = self.np_random
        if self._noise_seeded is rng:
            self._episode += 1
        else:  # a new generator: the first reset, or one with a seed
            self._noise_seeded, self._episode = rng, 0
        seed = self.np_random_seed  # -1: np_random was set directly, its seed unknown (then a draw from it)
        world_seed = np.random.SeedSequence([seed, self._episode]).generate_state(1)[0] if seed >= 0 \
            else rng.integers(2**32)
        self.rig.reset(seed=int(world_seed))

    #: step is begin_step (check the action, send its commands), a wait for the next tick,
    #: finish_step (read, observe, reward): a batched env (envs.vector) waits for all its rigs at once
    batchable = False

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        token = self.begin_step(action)
        self._wait_until(self.tick_time())
        return self.finish_step(token)

    def tick_time(self, ahead: int = 0) -> float:
        """Rig time of the tick the last action waits for (``ahead``: of the tick that many later)."""
        return self._t0 + self._slip + (self._tick + ahead) * self.control_period

    def begin_step(self, action: np.ndarray) -> Any:
        """The first half of :meth:`step`: check ``action`` and send its commands (returns what
        :meth:`finish_step` needs)."""
        raise NotImplementedError

    def finish_step(self, token: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """The second half of :meth:`step`, once the rig's clock reached :meth:`tick_time`: read the
        joints, observe, reward."""
        raise NotImplementedError

    def _wait_until(self, t: float) -> None:
        remaining = t - self.rig.time
        if remaining > 0:
            self.rig.sleep(remaining)
        self.note_overrun(-remaining)

    #: raise :class:`~joints.errors.OverrunError` on an overrun instead of counting it
    raise_on_overrun = False

    def note_overrun(self, late: float) -> None:
        """This step reached its tick ``late`` s after it (<= 0: in time): counted in :attr:`overruns` and
        :attr:`overrun_time`, shown as ``info["overrun"]``; the schedule goes on from the late tick (later
        steps are not charged for this one)."""
        if late <= 1e-9:
            self._overrun = 0.0
            return
        self._overrun = late
        self.overruns += 1
        self.overrun_time += late
        self._slip += late
        if self.raise_on_overrun:
            raise OverrunError(f"step {self._tick} ran {late * 1e3:.2f} ms over its {self.control_period * 1e3:g} ms "
                               "period: the bus cannot carry this rate (see joints.cycle_times)")

    #: s from a state's sample to the next command taking effect, at most: one cycle of bus traffic (the
    #: planner's, for the env's action mode; 0 on ideal buses). Safety shields extend their horizon by it.
    bus_lag = 0.0

    def _keeps_step_parts(self, base: type) -> bool:
        """Whether this env's type keeps ``base``'s parts of the step (:data:`STEP_PARTS`), which ``base``'s one-call
        step (:meth:`~joints.compiled_path.CompiledPath.step`) does in one; a type that replaces one of them is stepped
        by its parts (asked once per type)."""
        kind = type(self)
        own = _OWN_STEP.get(kind)
        if own is None:
            own = _OWN_STEP[kind] = all(getattr(kind, n) is getattr(base, n) for n in STEP_PARTS)
        return own

    def _check_rate(self, mode: str = "position") -> None:
        """Refuse a control period one cycle of this env's bus traffic does not fit (:func:`joints.check_rate`),
        and note the cycle as :attr:`bus_lag`."""
        plans = joints.check_rate(self.rig.config, self.control_period, mode)  # {} without MuJoCo (it warned)
        self.bus_lag = max((p.cycle for p in plans.values()), default=0.0)

    def _start(self, config: Any, backend: str | None, domain_randomization: Any) -> None:
        """Open the rig and set the task up; the rig is closed again if the setup fails."""
        # per instance: render_fps follows the control period
        self.metadata = {**type(self).metadata, "render_fps": round(1.0 / self.control_period)}
        self.rig = self._open(config, backend)
        try:
            self._setup(domain_randomization)
        except BaseException:
            self.rig.close()
            raise
        self._closed = False

    def _open(self, config: Any, backend: str | None) -> joints.Rig:
        raise NotImplementedError

    def _setup(self, domain_randomization: Any) -> None:
        raise NotImplementedError

    def _scene(self) -> tuple[Any, Any]:
        raise NotImplementedError

    def _update_twin(self) -> None:
        raise NotImplementedError

    def _markers(self) -> list[tuple[np.ndarray, tuple[float, float, float, float]]]:
        return []


class JointsEnv(RigEnv):
    """Base of the ``joints/`` environments. Subclasses define the task (see :class:`envs.ErobReachEnv`).

    Args:
        config: a joints config - TOML path or dict; ``None``: the shipped default of the task.
        backend: ``"sim"`` | ``"hardware"``; overrides the config (as ``joints.open``).
        action_mode: ``"position"`` | ``"velocity"`` | ``"torque"``.
        control_period: seconds per step (``dt``; None: the env's ``default_control_period``); in sim a
            whole number of physics substeps; one cycle of bus traffic must fit it on every bus
            (:func:`joints.check_rate`, a :class:`~joints.errors.ConfigError` otherwise).
        raise_on_overrun: raise :class:`~joints.errors.OverrunError` when a step misses its tick
            (default: count it in ``overruns`` / ``overrun_time`` and show it as ``info["overrun"]``).
        compiled_path: sim only - send the step's commands and state reads by the compiled path
            (:mod:`joints.compiled_path`) where every joint is an in-process twin it knows (default);
            ``False``: always the driver path. Both give the same bits.
        render_mode: ``None`` | ``"rgb_array"`` | ``"human"``.
        domain_randomization: sim only - ``False``, ``True`` (default ranges), a mapping of ranges,
            or a :class:`~envs.randomization.DomainRandomization`.
        reset_velocity, reset_acceleration: hardware reset - the safe profile [rad/s, rad/s^2]
            (capped by the joint's limits) of the move to the start pose.
        reset_timeout: hardware reset - seconds to reach the start pose and stand still.
        reset_tolerance: hardware reset - rad from the start pose that counts as there.
        width, height: ``rgb_array`` image size in pixels.
    """

    metadata: dict[str, Any] = {"render_modes": ["human", "rgb_array"], "render_fps": 50}  # noqa: RUF012 - gymnasium declares it so

    #: the shipped config used when ``config`` is None (file stem in ``joints/configs``)
    default_config: str = ""
    #: s per step when ``control_period`` is None: a rate the default config's bus carries (docs/timing.md)
    default_control_period: float = 0.02

    def __init__(
        self,
        config: str | os.PathLike[str] | Mapping[str, Any] | None = None,
        backend: str | None = None,
        *,
        action_mode: str = "position",
        control_period: float | None = None,
        render_mode: str | None = None,
        domain_randomization: bool | Mapping[str, Any] | DomainRandomization = False,
        reset_velocity: float = 0.5,
        reset_acceleration: float = 1.0,
        reset_timeout: float = 30.0,
        reset_tolerance: float = 0.02,
        width: int = 480,
        height: int = 480,
        raise_on_overrun: bool = False,
        compiled_path: bool = True,
    ) -> None:
        if action_mode not in ACTION_MODES:
            raise ValueError(f"action_mode {action_mode!r} is not one of {ACTION_MODES}")
        if control_period is None:
            control_period = self.default_control_period
        if isinstance(control_period, bool) or not isinstance(control_period, (int, float)) \
                or not math.isfinite(control_period) or control_period <= 0:
            raise ValueError(f"control_period must be a finite number of seconds > 0, got {control_period!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode {render_mode!r} is not one of {self.metadata['render_modes']}")
        for what, v in (("reset_velocity", reset_velocity), ("reset_acceleration", reset_acceleration),
                        ("reset_timeout", reset_timeout), ("reset_tolerance", reset_tolerance)):
            if not math.isfinite(v) or v <= 0:
                raise ValueError(f"{what} must be > 0, got {v!r}")
        self.action_mode = action_mode
        self.raise_on_overrun = bool(raise_on_overrun)
        self.control_period = float(control_period)
        self.render_mode = render_mode
        self.reset_velocity = float(reset_velocity)
        self.reset_acceleration = float(reset_acceleration)
        self.reset_timeout = float(reset_timeout)
        self.reset_tolerance = float(reset_tolerance)
        self.width, self.height = int(width), int(height)
        self._want_compiled = bool(compiled_path)
        self._start(config, backend, domain_randomization)

    # -- construction -----------------------------------------------------------------------
    def _open(self, config: Any, backend: str | None) -> joints.Rig:
        if config is None:
            if not self.default_config:
                raise ValueError(f"{type(self).__name__} has no default config; pass config=")
            with config_path(self.default_config) as p:
                return joints.open(p, backend=backend)
        return joints.open(config, backend=backend)

    def _setup(self, domain_randomization: Any) -> None:
        rig = self.rig
        self.sim = rig.backend == "sim"
        self.joint_names: list[str] = self._select_joints(rig)
        self.joints = [rig.joints[n] for n in self.joint_names]
        n = len(self.joints)
        lo, hi, vlim, tlim = [], [], [], []
        for name, j in zip(self.joint_names, self.joints):
            lim = j.limits
            for field_, value in (("position", lim.position), ("velocity", lim.velocity), ("torque", lim.torque)):
                if value is None:
                    raise joints.ConfigError(
                        f"the env needs the joint's {field_} limit (it scales actions and bounds observations)",
                        file=rig.config.source, key=f"joints.{name}.limits.{field_}",
                    )
            assert lim.position is not None and lim.velocity is not None and lim.torque is not None
            lo.append(lim.position[0]); hi.append(lim.position[1])
            vlim.append(lim.velocity); tlim.append(lim.torque)
        #: (n,) the drives' own profile for position actions [rad/s, rad/s^2] (config ``motion``);
        #: velocity actions ramp with ``profile_acceleration`` both ways
        self.profile_velocity = np.array([j.motion.velocity for j in self.joints], dtype=np.float64)
        self.profile_acceleration = np.array([j.motion.acceleration for j in self.joints], dtype=np.float64)
        self.profile_deceleration = np.array([j.motion.deceleration for j in self.joints], dtype=np.float64)
        self._nominal_motion = [j.motion for j in self.joints]  #: the config's profiles (domain randomisation derates)
        self.position_limits = np.array([lo, hi], dtype=np.float64).T  #: (n, 2) rad
        self.velocity_limits = np.array(vlim, dtype=np.float64)  #: (n,) rad/s
        #: (n,) rad/s: the speed velocity actions may ask this episode (the limit; less under domain randomisation)
        self.speed_cap = self.velocity_limits.copy()
        self.torque_limits = np.array(tlim, dtype=np.float64)  #: (n,) N*m
        if self.sim:
            steps = self.control_period / rig.sim.timestep
            if abs(steps - round(steps)) > 1e-6 or round(steps) < 1:
                raise ValueError(
                    f"control_period {self.control_period} s must be a whole number of physics substeps "
                    f"of {rig.sim.timestep} s"
                )
            self.substeps = round(steps)  #: physics substeps per env step (sim)
        else:
            self.substeps = 0
        self.randomization = DomainRandomization.from_arg(domain_randomization)
        if self.randomization is not None and not self.sim:
            gym.logger.warn("domain randomisation acts on the simulation only; ignored on hardware")
            self.randomization = None

        self.action_space = spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)
        t_lo, t_hi = self._task_bounds()
        low = np.concatenate([self.position_limits[:, 0] - OBS_POSITION_MARGIN, -2 * self.velocity_limits,
                              -2 * self.torque_limits, t_lo]).astype(np.float64)
        high = np.concatenate([self.position_limits[:, 1] + OBS_POSITION_MARGIN, 2 * self.velocity_limits,
                               2 * self.torque_limits, t_hi]).astype(np.float64)
        self.observation_space = spaces.Box(low, high, dtype=np.float64)
        self._obs_low, self._obs_high = self.observation_space.low.copy(), self.observation_space.high.copy()
        self._obs_lo, self._obs_hi = self._obs_low.tolist(), self._obs_high.tolist()  #: the bounds as plain floats
        self._obs_dim = int(low.shape[0])
        self._lo_stop = self.position_limits[:, 0] - LIMIT_MARGIN
        self._hi_stop = self.position_limits[:, 1] + LIMIT_MARGIN
        self._lo_list, self._hi_list = self._lo_stop.tolist(), self._hi_stop.tolist()
        #: the limits as plain floats (per-step arithmetic on a few joints)
        self._pos_lo, self._pos_hi = self.position_limits[:, 0].tolist(), self.position_limits[:, 1].tolist()
        self._vel_list, self._torque_list = self.velocity_limits.tolist(), self.torque_limits.tolist()
        self._pos_span = (self.position_limits[:, 1] - self.position_limits[:, 0]).tolist()  #: hi - lo per joint
        self._profile_floats()
        #: where velocity actions brake to: LIMIT_INSET inside the limits (plain floats)
        self._inset_lo = (self.position_limits[:, 0] + LIMIT_INSET).tolist()
        self._inset_hi = (self.position_limits[:, 1] - LIMIT_INSET).tolist()
        self._action_shape = (n,)
        self._shielded = type(self)._shield is not type(self)._no_shield  #: the task has a rule of its own

        self._mjcf_joints = [rig.config.joints[nm].mjcf_joint or nm for nm in self.joint_names]

        self._renderer: SceneRenderer | None = None
        self._twin: tuple[Any, Any, np.ndarray] | None = None  # hardware: (model, data, qpos addresses)
        self._queue: deque[np.ndarray] = deque()
        #: the last action (clipped): as an array (several joints, np.dot's operand) and as plain floats
        self._prev_action = np.zeros(n)
        self._prev_values = self._prev_action.tolist()
        self._states: list[joints.JointState] = []
        self._sent = np.zeros(n)  # the SI command of the last step (after safe_command)
        self._tick = 0
        self._slip = 0.0  #: s the schedule slipped by overruns this episode
        self._t0 = 0.0
        self._noise = np.zeros(n)
        self._noisy = False  #: any joint's encoder noise above 0
        self._noise_rng: np.random.Generator | None = None
        self.randomization_sample: dict[str, Any] | None = None
        self.overruns = 0  #: steps whose tick had passed before their commands were sent
        self.overrun_time = 0.0  #: s, the total of those steps' lateness
        self._overrun = 0.0
        #: the compiled command/state path (sim, every joint a twin it knows), else None: the driver path
        self.compiled_path = joints.CompiledPath.build(self.joints) if self.sim and self._want_compiled else None
        self._check_rate(self.action_mode)

    def _select_joints(self, rig: joints.Rig) -> list[str]:
        """The joints this env drives, in action/observation order (default: the config's order)."""
        return list(rig.joints)

    def _profile_floats(self) -> None:
        """The episode's profiles and speed cap as plain floats for the per-step safety arithmetic (they change at
        construction and at reset only: :meth:`_derate`)."""
        self._acc_list: list[float] = self.profile_acceleration.tolist()
        self._dec_list: list[float] = self.profile_deceleration.tolist()
        self._cruise_list: list[float] = self.profile_velocity.tolist()
        self._cap_list: list[float] = self.speed_cap.tolist()

    # -- task hooks (subclasses) ------------------------------------------------------------
    def _task_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of the task terms appended to the observation."""
        return np.zeros(0), np.zeros(0)

    def _sample_start(self, options: Mapping[str, Any]) -> np.ndarray:
        """Start joint positions [rad] (user frame), drawn from ``self.np_random``."""
        raise NotImplementedError

    def _sample_target(self, options: Mapping[str, Any]) -> None:
        """Draw the task's goal from ``self.np_random``."""

    def _task_terms(self, positions: list[float]) -> list[float]:
        """Task terms of the observation for the measured joint positions (plain floats)."""
        return []

    def _reward(self, positions: list[float], action_change: float) -> tuple[float, dict[str, Any]]:
        """Reward and its terms (``info``) for the measured joint positions and ``action_change``, the
        action's squared change ``sum((a_t - a_{t-1})^2)``."""
        return 0.0, {}

    @staticmethod
    def _batch_task(envs: Sequence[Any], positions: np.ndarray, change: np.ndarray, terms: np.ndarray
                    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """:meth:`_task_terms` and :meth:`_reward` of every rig of a batch (``envs``, all of this type; ``positions``
        (N, joints), ``change`` (N,)) by the same IEEE operations across the rigs: the task terms written into
        ``terms`` (N, k); returns the rewards (N,) and one array per info term, in ``_reward``'s order. A task
        that does not write it (the default) is called rig by rig (:mod:`envs.batch`)."""
        raise NotImplementedError

    def _markers(self) -> list[tuple[np.ndarray, tuple[float, float, float, float]]]:
        """Points to draw in renders: [(position [m], rgba)] (the task's goal)."""
        return []

    # -- units ------------------------------------------------------------------------------
    @property
    def dt(self) -> float:
        """Seconds per step: the control period."""
        return self.control_period

    def command_of(self, action: Sequence[float] | np.ndarray) -> np.ndarray:
        """SI commands (rad | rad/s | N*m per the action mode) of a normalised action."""
        a = [clip(v, -1.0, 1.0) for v in np.asarray(action, dtype=np.float64).reshape(-1).tolist()]
        return np.array(self._commands(a))

    def _commands(self, a: list[float]) -> list[float]:
        """:meth:`command_of` of an action already clipped to [-1, 1], on plain floats (the same IEEE
        operations as the arrays, the same bits)."""
        if self.action_mode == "position":
            out = []
            for v, lo, hi, span in zip(a, self._pos_lo, self._pos_hi, self._pos_span):
                x = lo + (v + 1.0) * 0.5 * span
                out.append(x if x != x else min(max(x, lo), hi))  # noqa: PLR0124 - clip(x, lo, hi), NaN kept
            return out
        scale = self._vel_list if self.action_mode == "velocity" else self._torque_list
        return [v * s for v, s in zip(a, scale)]

    def action_of(self, command: Sequence[float] | np.ndarray) -> np.ndarray:
        """The normalised action (float32, clipped to [-1, 1]) for SI commands; inverse of :meth:`command_of`."""
        c = np.asarray(command, dtype=np.float64).reshape(-1)
        if self.action_mode == "position":
            lo, hi = self.position_limits[:, 0], self.position_limits[:, 1]
            a = 2.0 * (c - lo) / (hi - lo) - 1.0
        elif self.action_mode == "velocity":
            a = c / self.velocity_limits
        else:
            a = c / self.torque_limits
        clipped: np.ndarray = np.clip(a, -1.0, 1.0).astype(np.float32)
        return clipped

    # -- safety ---------------------------------------------------------------------------
    def safe_command(self, command: Sequence[float] | np.ndarray) -> np.ndarray:
        """The SI command the env sends for ``command`` (rad | rad/s | N*m per the action mode) in
        the present state (the joint states of the last observation).

        Position targets are clipped to the position limits; a velocity is capped towards each
        limit at the :func:`braking_speed` of the present speed and the distance left to
        :data:`LIMIT_INSET` short of it (the drive's ramp stops the joint there); torque is clipped
        to the torque limit. Then the task's rule (:meth:`_shield`) applies. Without a state yet
        (before ``reset``) only the limits apply.
        """
        values = np.asarray(command, dtype=np.float64).reshape(-1).tolist()
        if len(values) != len(self.joints) or any(v - v != 0.0 for v in values):  # NaN or infinite
            raise ValueError(f"command must be one finite value per joint, got {command!r}")
        return np.array(self._safe(self._limit(values)))

    def _limit(self, values: list[float]) -> list[float]:
        """The limit clip of :meth:`safe_command` on plain floats (np.clip's rule: the same bits as the arrays)."""
        mode = self.action_mode
        if mode == "position":
            return [clip(v, lo, hi) for v, lo, hi in zip(values, self._pos_lo, self._pos_hi)]
        cap = self._cap_list if mode == "velocity" else self._torque_list
        return [clip(v, -m, m) for v, m in zip(values, cap)]

    def _safe(self, values: list[float]) -> list[float]:
        """:meth:`safe_command` after the limit clip: the braking cap (velocity) and the task's rule."""
        mode = self.action_mode
        if mode == "torque" or not self._states:
            return values
        if mode == "velocity":
            dt = self.control_period + self.bus_lag
            acc = self._acc_list
            capped = []
            for c, s, a, lo, hi in zip(values, self._states, acc, self._inset_lo, self._inset_hi):
                p, v = s.position, s.velocity
                # np.clip(c, -braking_speed(p - lo, a, dt, -v), braking_speed(hi - p, a, dt, v)), per joint
                capped.append(clip_to(c, -braking_speed_of(p - lo, a, dt, -v), braking_speed_of(hi - p, a, dt, v)))
            values = capped
        return self._shield(values) if self._shielded else values

    def _shield(self, command: list[float]) -> list[float]:
        """The task's own safety rule on a position or velocity command (SI, within the limits, one
        float per joint); default: none. See :meth:`_reach` and :meth:`_stop_command` for the motion it
        may predict."""
        return command

    #: the default :meth:`_shield` (no rule): a task whose ``_shield`` is another has a rule of its own
    _no_shield = _shield

    def _stop_command(self, i: int) -> float:
        """The command that stops joint ``i`` as soon as the drive can: the target where its
        profile stops it (position mode, within the limits) or zero speed (velocity mode)."""
        if self.action_mode == "velocity":
            return 0.0
        s = self._states[i]
        stop = s.position + s.velocity * abs(s.velocity) / (2.0 * self._dec_list[i])
        return clip(stop, self._pos_lo[i], self._pos_hi[i])  # np.clip of a scalar: the value on a tie, NaN kept

    def _reach(self, command: Sequence[float]) -> tuple[list[float], list[float]]:
        """Per joint, the lowest and highest position [rad] it can pass through if ``command``
        (position or velocity, SI) is held for one period and the joint is then stopped with the
        drive's deceleration - a conservative envelope of the drive's own profile
        (:meth:`_joint_reach` of each joint)."""
        dt = self.control_period + self.bus_lag  # the state is older, the command later, by up to a bus cycle
        acc = self._acc_list
        velocity = self.action_mode == "velocity"
        dec = acc if velocity else self._dec_list
        cruise = self._cruise_list
        lows: list[float] = []
        highs: list[float] = []
        for i, (s, c) in enumerate(zip(self._states, list(command))):
            lo, hi = self._joint_reach(s.position, s.velocity, float(c), dt, acc[i], dec[i], cruise[i], velocity)
            lows.append(lo)
            highs.append(hi)
        return lows, highs

    @staticmethod
    def _joint_reach(p: float, v: float, c: float, dt: float, a: float, b: float, cruise: float,
                     velocity: bool) -> tuple[float, float]:
        """One joint of :meth:`_reach`: at ``p`` [rad] moving at ``v`` [rad/s], ``c`` held for ``dt`` [s]
        (velocity: ramped with ``a``; position: the profile of top speed ``cruise`` and ramps ``a``),
        then stopped with ``b`` [rad/s^2]. Plain floats (a few joints: cheaper than arrays)."""
        stop_now = p + v * abs(v) / (2.0 * b)
        if velocity:
            step = a * dt
            v1 = c if abs(c - v) <= step else v + math.copysign(step, c - v)
            p1 = p + 0.5 * (v + v1) * dt
            end = p1 + v1 * abs(v1) / (2.0 * b)
            return min(p, stop_now, p1, end), max(p, stop_now, p1, end)
        u = min(max(cruise, abs(v)), abs(v) + a * dt)
        travel = u * dt + u * u / (2.0 * b)
        d = c - p
        end = p + math.copysign(min(travel, abs(d)), d)
        return min(p, stop_now, end), max(p, stop_now, end)

    def _to_model(self, i: int, position: float) -> float:
        """Joint position (user frame) -> MJCF joint angle: ``(position - offset) * direction``."""
        j = self.joints[i]
        return (position - j.offset) * j.direction

    # -- gymnasium API ----------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode. ``options``: ``{"start": [rad per joint], "target": task goal}`` fix the draws.

        Sim: physics and every emulated drive to power-on (``rig.reset``), the domain randomisation
        draw, the seeded start pose written into the physics before the drives are enabled.
        Hardware: clear faults, enable, move to the start pose with a safe profile inside the
        limits and wait for standstill. Both: enable, wait the drive's 500 ms, hold.
        """
        super().reset(seed=seed)
        self._check_open()
        options = dict(options or {})
        start = self._sample_start(options)
        lo, hi = self.position_limits[:, 0], self.position_limits[:, 1]
        if start.shape != (len(self.joints),) or not np.all(np.isfinite(start)) \
                or np.any(start < lo) or np.any(start > hi):
            raise ValueError(f"start pose {start.tolist()} is not one finite angle per joint inside the limits")
        self._sample_target(options)
        if self.sim:
            self._reset_sim(start)
        else:
            self._reset_hardware(start)
        neutral = self.action_of(start) if self.action_mode == "position" else np.zeros(len(self.joints), np.float32)
        self._prev_action = neutral.astype(np.float64)
        self._prev_values = self._prev_action.tolist()
        self._sent = start.copy() if self.action_mode == "position" else np.zeros(len(self.joints))
        latency = self.randomization_sample["latency"] if self.randomization_sample else 0
        self._queue = deque(neutral.astype(np.float64) for _ in range(latency))
        self._tick = 0
        self._slip = 0.0  #: s the schedule slipped by overruns this episode
        states = self._read()
        self._t0 = self.rig.time  # the schedule starts with the first observation (its read took bus time)
        obs = self._observation(states)
        info = self._info(states)
        if self.randomization_sample is not None:
            info["randomization"] = self.randomization_sample
        if self.render_mode == "human":
            self.render()
        return obs, info

    batchable = True

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """:meth:`RigEnv.step`; on the compiled path, where it can, the command, the wait for the tick and the
        state read in one call (:meth:`~joints.compiled_path.CompiledPath.step`: the same frames, substeps and
        bits)."""
        compiled = self.compiled_path
        if compiled is None or not compiled.steps or self.raise_on_overrun or not self._keeps_step_parts(JointsEnv):
            return super().step(action)
        values = self._action_values(action)
        cmd = self._safe_command(self._queued(values))
        mode = self.action_mode
        skip = [not j.enabled for j in self.joints]  # faulted/disabled drives: never commanded (see _command)
        got = compiled.step(mode, cmd, skip, self.tick_time(1), self.rig)
        if got is None:  # not the steady case (nothing sent): the command, the wait and the read one by one
            compiled.command(mode, cmd, skip)
            self._tick += 1
            self._wait_until(self.tick_time())
            return self._finish(self._token(values), self._read())
        self._tick += 1
        states, remaining = got
        self.note_overrun(-remaining)
        self._states = states
        return self._finish(self._token(values), states)

    def _action_values(self, action: np.ndarray) -> list[float]:
        """``action`` checked (shape, finite) and clipped to [-1, 1], as plain floats."""
        if self._closed:
            self._check_open()  # raises
        # a float array's own floats (float32 widened exactly, as float64 would have them); else as float64
        a = action if type(action) is np.ndarray and action.dtype.kind == "f" and action.itemsize <= 8 \
            else np.asarray(action, dtype=np.float64)
        if a.shape != self._action_shape:
            raise ValueError(f"action shape {a.shape} != {self.action_space.shape}")
        given = a.tolist()
        values = []
        for v in given:
            if v - v != 0.0:  # NaN or infinite
                raise ValueError(f"action must be finite, got {given}")
            # a.clip(-1.0, 1.0) on plain floats (clip() of a finite value: the same bits)
            values.append(v if -1.0 <= v <= 1.0 else (-1.0 if v < -1.0 else 1.0))
        return values

    def _queued(self, values: list[float]) -> list[float]:
        """The action sent this step: ``values``, or with a bus latency (domain randomisation) the one whose turn
        it is (``values`` wait theirs)."""
        if self._queue:
            self._queue.append(np.array(values))
            return self._queue.popleft().tolist()  # type: ignore[no-any-return]
        return values

    @staticmethod
    def _token(values: list[float]) -> tuple[np.ndarray | None, list[float]]:
        """What :meth:`finish_step` needs of the step's action ``values``: the action as an array for np.dot's
        change (several joints; one joint's change is a square of floats), and the values."""
        return (np.array(values) if len(values) > 1 else None), values

    def begin_step(self, action: np.ndarray) -> tuple[np.ndarray | None, list[float]]:
        values = self._action_values(action)
        self._command(self._queued(values))
        self._tick += 1
        return self._token(values)

    def finish_step(self, token: tuple[np.ndarray | None, list[float]]
                    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        return self._finish(token, self._read())

    def _finish(self, token: tuple[np.ndarray | None, list[float]], states: list[joints.JointState]
                ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """:meth:`finish_step` once the joints' ``states`` are read."""
        a, values = token
        positions = [s.position for s in states]
        obs = self._observation(states, positions)
        if len(values) == 1:  # np.dot of one difference is its square
            d = values[0] - self._prev_values[0]
            change = d * d
        else:
            assert a is not None
            diff = a - self._prev_action
            change = float(np.dot(diff, diff))
            self._prev_action = a
        reward, terms = self._reward(positions, change)
        self._prev_values = values
        faults: dict[str, str | None] = {}
        faulted = None
        violation = False
        for name, s, p, lo, hi in zip(self.joint_names, states, positions, self._lo_list, self._hi_list):
            f = s.fault
            if f is None:
                faults[name] = None
            else:
                faults[name] = f.name
                if faulted is None:
                    faulted = (name, s)
            if p < lo or p > hi:
                violation = True
        # "command": a new array every step, never changed in place
        info = {"time": float(self.rig.time), "overrun": self._overrun, "faults": faults, **terms,
                "limit_violation": violation, "command": self._sent}
        if faulted is not None:
            info["fault"] = fault_info(*faulted)
        terminated = violation or faulted is not None
        if terminated:
            self._safe_stop()
        if self.render_mode == "human":
            self.render()
        return obs, float(reward), terminated, False, info

    #: (the joints, the names of those read together by ``rig.read_states`` or None), made at the first read
    _sample_plan: tuple[list[joints.Joint], list[str] | None] | None = None

    def _read(self) -> list[joints.JointState]:
        """Every joint's state: the compiled path's, else joint by joint - the joints one broadcast samples
        together (the CANopen joints of a bus: one SYNC, ``rig.samples_together``) by one ``rig.read_states`` of
        them all, at the first of them."""
        compiled = self.compiled_path
        if compiled is not None:
            self._states = compiled.states()
            return self._states
        plan = self._sample_plan
        if plan is None or plan[0] is not self.joints:
            shared = [n for n in self.joint_names if self.rig.samples_together(n)]
            plan = self._sample_plan = (self.joints, shared or None)
        together = plan[1]
        if together is None:
            self._states = [j.state() for j in self.joints]
            return self._states
        states: list[joints.JointState] = []
        read: dict[str, joints.JointState] | None = None
        for name, j in zip(self.joint_names, self.joints):
            if name not in together:
                states.append(j.state())
                continue
            if read is None:
                read = self.rig.read_states(together)
            states.append(read[name])
        self._states = states
        return states

    def _observation(self, states: Sequence[joints.JointState], positions: list[float] | None = None) -> np.ndarray:
        if positions is None:
            positions = [s.position for s in states]
        row = list(positions)  # [positions, velocities, torques, task terms]
        for s in states:
            row.append(s.velocity)
        for s in states:
            row.append(s.torque)
        row += self._task_terms(positions)
        if self._noise_rng is not None and self._noisy:
            obs = np.array(row)
            n = len(positions)
            obs[:n] += self._noise_rng.normal(0.0, 1.0, n) * self._noise
            np.maximum(obs, self._obs_low, out=obs)
            np.minimum(obs, self._obs_high, out=obs)
            return obs
        # np.minimum(np.maximum(row, low), high) on plain floats: the value unless beyond a bound, NaN kept (a value
        # equal to a bound is kept: the bits differ only where a bound is a signed zero and the value the other one)
        return np.array([lo if v < lo else hi if v > hi else v  # noqa: FURB136 - min(), max() without calls
                         for v, lo, hi in zip(row, self._obs_lo, self._obs_hi)])

    def _info(self, states: Sequence[joints.JointState]) -> dict[str, Any]:
        return {
            "time": float(self.rig.time),  # s on the rig's clock (sim: simulated seconds since reset)
            "overrun": self._overrun,  # s this step ran over its period (0.0: none)
            "faults": {n: (s.fault.name if s.fault else None) for n, s in zip(self.joint_names, states)},
        }

    def _safe_command(self, action: list[float]) -> list[float]:
        """The safe command of ``action`` (clipped to [-1, 1], plain floats), kept as what was sent."""
        values = self._commands(action)
        if self.action_mode != "position":  # the limit clip (position: command_of clipped to the limits already)
            values = self._limit(values)
        cmd = self._safe(values)
        self._sent = np.array(cmd)
        return cmd

    def _command(self, action: list[float]) -> None:
        """Send the safe command of ``action`` (clipped to [-1, 1], plain floats)."""
        mode = self.action_mode
        cmd = self._safe_command(action)
        compiled = self.compiled_path
        if compiled is not None:  # faulted/disabled drives: the episode has ended; never command them
            compiled.command(mode, cmd, [not j.enabled for j in self.joints])
            return
        plan = self._sample_plan
        if mode == "position" and plan is not None and plan[1] is not None:  # CANopen: one SYNC acknowledges all
            self.rig.move_together({n: c for n, j, c in zip(self.joint_names, self.joints, cmd) if j.enabled})
            return
        for j, c in zip(self.joints, cmd):
            if not j.enabled:  # faulted/disabled drive: the episode has ended; never command it
                continue
            if mode == "torque":
                j.set_torque(c)
            elif mode == "velocity":
                j.set_velocity(c)
            else:
                j.move_to(c)

    def _hold(self, start: np.ndarray) -> None:
        """The action mode's neutral command: hold the start pose, zero speed or zero torque."""
        for j, q in zip(self.joints, start):
            if self.action_mode == "position":
                j.move_to(float(q))
            elif self.action_mode == "velocity":
                j.set_velocity(0.0)
            else:
                j.set_torque(0.0)

    def _safe_stop(self) -> None:
        for j in self.joints:
            if j.enabled:
                try:
                    j.stop()
                except joints.JointsError as exc:  # keep stopping the others
                    gym.logger.warn(f"stopping joint {j.name} failed: {exc}")

    # -- sim reset --------------------------------------------------------------------------
    @property
    def model(self) -> Any:
        """The MuJoCo model in sim (as gymnasium's ``MujocoEnv``); None on hardware."""
        return self.rig.sim.model if self.sim else None

    @property
    def data(self) -> Any:
        """The MuJoCo data in sim (as gymnasium's ``MujocoEnv``); None on hardware."""
        return self.rig.sim.data if self.sim else None

    def _reset_sim(self, start: np.ndarray) -> None:
        rig = self.rig
        self._reset_rig()  # physics + drives to power-on; drivers forget, joints count as disabled
        self._randomize()
        rig.sim.set_joint_positions({nm: self._to_model(i, float(q))
                                     for i, (nm, q) in enumerate(zip(self.joint_names, start))})
        for j in self.joints:
            j.enable()
        rig.sleep(ENABLE_SETTLE)
        self._hold(start)

    def _derate(self, i: int, scale: float) -> None:
        """Joint ``i``'s profile (position moves, velocity ramps) and top speed for this episode:
        the config's times ``scale`` (at most 1).

        Domain randomisation gives a twin up to twice the friction and 1.2 times the armature the
        shipped profiles were sized for, and 10 % less torque per ampere: the drive then cannot
        follow them and trips (following error, speed error), as such a drive would. The env knows
        its draw, so it asks of the joint what that plant can do: profile speed, ramps and speed
        cap times torque constant / max(friction, armature) factors."""
        m = self._nominal_motion[i]
        s = min(1.0, scale)
        self.speed_cap[i] = self.velocity_limits[i] * s
        j = self.joints[i]
        j.motion = joints.Motion(velocity=m.velocity * s, acceleration=m.acceleration * s,
                                 deceleration=m.deceleration * s)
        self.profile_velocity[i] = j.motion.velocity
        self.profile_acceleration[i] = j.motion.acceleration
        self.profile_deceleration[i] = j.motion.deceleration
        self._profile_floats()

    def _randomize(self) -> None:
        sim = self.rig.sim
        sim.restore()
        for i in range(len(self.joints)):
            self._derate(i, 1.0)
        self.randomization_sample = None
        self._noise = np.zeros(len(self.joints))
        self._noisy = False
        self._noise_rng = None
        if self.randomization is None:
            return
        sample = self.randomization.sample(self.np_random, self.joint_names)
        self.randomization_sample = sample
        for i, nm in enumerate(self.joint_names):
            f = sample["joints"][nm]
            sim.perturb(nm, armature=f["armature"], coulomb_friction=f["friction"], viscous_friction=f["friction"],
                        torque_constant=f["torque_constant"], gains={g: f[field] for field, g in GAINS.items()})
            self._noise[i] = f["encoder_noise"]
            apply_sensors(sim, nm, f["sensor_noise"])
            if self.action_mode != "torque":
                self._derate(i, f["torque_constant"] / max(1.0, f["friction"], f["armature"]))
        self._noisy = bool(self._noise.any())
        self._noise_rng = np.random.default_rng(int(self.np_random.integers(2**63)))

    # -- hardware reset ---------------------------------------------------------------------
    def _reset_hardware(self, start: np.ndarray) -> None:
        rig = self.rig
        self.randomization_sample = None
        need_enable = []
        for j in self.joints:
            s = j.state()
            if s.fault:
                j.clear_faults()
                j.check()  # still faulted: raises DeviceFault by name
                s = j.state()
            if not (s.enabled and j.enabled):
                need_enable.append(j)
        for j in need_enable:
            j.enable()
        if need_enable:
            rig.sleep(ENABLE_SETTLE)
        for i, (j, q) in enumerate(zip(self.joints, start)):
            lim = j.limits
            v = min(self.reset_velocity, lim.velocity or math.inf)
            acc = min(self.reset_acceleration, lim.acceleration or math.inf)
            j.move_to(float(q), velocity=v, acceleration=acc, deceleration=acc)
        deadline = rig.time + self.reset_timeout
        while True:
            states = [j.state() for j in self.joints]
            for j, s in zip(self.joints, states):
                if s.fault:
                    j.check()
            if all(not s.moving and abs(s.position - q) <= self.reset_tolerance and abs(s.velocity) < 0.05
                   for s, q in zip(states, start)):
                break
            if rig.time > deadline:
                far = {j.name: round(s.position - q, 4) for j, s, q in zip(self.joints, states, start)}
                raise MotionTimeout(f"reset: joints not at the start pose after {self.reset_timeout} s "
                                    f"(error per joint [rad]: {far})")
            rig.sleep(self.control_period)
        self._hold(start)

    # -- rendering --------------------------------------------------------------------------
    def _scene(self) -> tuple[Any, Any]:
        if self.sim:
            return self.rig.sim.model, self.rig.sim.data
        import mujoco

        model = mujoco.MjModel.from_xml_path(str(self.rig.model_path()))
        data = mujoco.MjData(model)
        adr = np.array([model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, m)]
                        for m in self._mjcf_joints])
        self._twin = (model, data, adr)
        return model, data

    def _update_twin(self) -> None:
        """Hardware: pose the kinematic copy of the model with the measured joint angles."""
        import mujoco

        assert self._twin is not None
        model, data, adr = self._twin
        for i, s in enumerate(self._states):
            data.qpos[adr[i]] = self._to_model(i, s.position)
        mujoco.mj_forward(model, data)
