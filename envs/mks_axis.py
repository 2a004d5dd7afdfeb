"""joints/MksAxisPosition-v0: move the carriage of a lead-screw axis (an MKS SERVO42D) to a goal - the same env on
the emulated drive and on a real one.

Rules (as :mod:`envs.base`): the env acts only through the public API (``joint.enable / move_to /
set_velocity / stop / state``, ``rig.sleep``, ``rig.reset``); sim-only extras (the start state,
rendering) use ``rig.sim`` and only when ``rig.backend == "sim"``; a fixed control period on the
rig's clock; deterministic in sim (every draw from ``np_random``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

import joints
from envs.base import RigEnv, braking_speed, fault_info
from envs.configs import config_path
from envs.render import CameraSpec, SceneRenderer
from joints.errors import MotionTimeout

ACTION_MODES = ("velocity", "position")
#: m the carriage may pass its position limits before the episode ends as a limit violation
LIMIT_MARGIN = 0.005
#: m short of a position limit where velocity actions brake to (the carriage lags the drive's ramp a little)
LIMIT_INSET = 0.001
#: the deceleration velocity actions count on, as a share of ``motion.acceleration``: the drive's acc
#: is quantised (0.4 m/s^2 on the shipped axis ramps at 0.38 m/s^2) and its speed in whole rpm
BRAKING_SHARE = 0.8


class MksAxisPositionEnv(RigEnv):
    """Move the carriage of a linear axis to a goal position.

    ## Description
    An MKS SERVO42D closed-loop stepper turns a lead screw (8 mm per turn, the joint's ``lead``) that
    moves a carriage between two end stops (``models/mks_linear_axis.xml``, joint ``carriage``) -
    emulated in MuJoCo with the sim backend (the native MKS protocol, byte for byte, into the twin),
    or a real drive with the hardware backend, from the same config (``protocol = "modbus-rtu"``
    works unchanged). The agent brings the carriage to a goal drawn at every reset and holds it there.

    ## Action Space
    ``Box(-1, 1, (1,), float32)``, the meaning set by ``action_mode``:

    | action_mode | command | unit |
    |---|---|---|
    | ``"velocity"`` (default) | carriage speed ``a x limits.velocity`` (the drive's speed mode, ramped with ``motion.acceleration``) | m/s |
    | ``"position"`` | target ``lo + (a+1)/2 (hi-lo)`` over the position limits, reached by the drive's position mode4 (0xF5, updated in flight) | m |

    The MKS has no torque mode over its serial interface. ``env.unwrapped.command_of(a)`` /
    ``action_of(si)`` convert. The default config: position [-0.06, 0.06] m, velocity 0.08 m/s.

    No action can fault the drive or leave the limits: position targets lie within the limits,
    and a speed towards a limit is capped at the speed from which the drive's ramp
    (``motion.acceleration``) stops the carriage there after one more period
    (:meth:`safe_command`; the whole travel stays reachable). ``info["command"]`` is what was sent.

    ## Observation Space
    ``Box(float64, (4,))``: carriage position [m] (limits +- 10 mm), velocity [m/s] (+- 2 x the velocity
    limit), goal [m] (the limits), goal - position [m] (+- the travel). From the drive's encoder through
    the lead, so the same on hardware. Values are clipped to the bounds.

    ## Rewards
    ``reward = reward_distance + reward_action_rate``: ``-|goal - position| / 0.01`` (per cm) and
    ``-action_rate_weight * (a_t - a_{t-1})^2``. ``info``: ``distance`` [m], ``is_success``
    (``distance < success_tolerance`` and speed below 5 mm/s), ``time`` [s], ``faults`` (joint -> the
    drive's fault by name, None = none), ``limit_violation``, ``command`` and, when the drive reports a
    fault, ``fault`` (``joint``, ``name``, ``code``, ``text``, ``clears``).

    ## Starting State
    Sim: physics and the twin at power-on, the carriage at rest at a position uniform in
    ``start_range`` (seeded), then enabled (serial work mode, subdivision, completion frames). Hardware:
    enabled and moved to the drawn start with a safe profile; the env waits until it stands there.
    The goal is uniform in ``goal_range`` at least ``min_goal_distance`` from the start.
    ``reset(options={"start": x, "goal": g})`` fixes either.

    ## Episode End
    - Termination: the drive reports a fault (locked-rotor protection; ``info["fault"]``, cleared by
      ``reset()``: sim power cycle, hardware clear + enable), or the carriage passes its position
      limits by more than 5 mm (no action drives it there; the env then stops it).
    - Truncation: 200 steps (10 s at the default control period), by the registered ``max_episode_steps``.

    ## Arguments
    ``gymnasium.make("joints/MksAxisPosition-v0", config=None, backend=None, action_mode="velocity",
    control_period=0.05, render_mode=None, goal_range=(-0.05, 0.05), start_range=(-0.02, 0.02),
    min_goal_distance=0.01, success_tolerance=0.001, action_rate_weight=0.01, reset_velocity=0.02,
    reset_timeout=20.0, width=480, height=480)``; ``config``: a joints config (TOML path or dict) with one
    joint that has a ``lead`` (default: the shipped ``joints/configs/mks_axis.toml``).

    ## Version History
    - v0: initial version (MKS SERVO42D, native protocol or Modbus mode; sim and hardware backends).
    """

    metadata: dict[str, Any] = {"render_modes": ["human", "rgb_array"], "render_fps": 20}  # noqa: RUF012
    camera = CameraSpec(lookat=(0.0, 0.0, 0.06), distance=0.5, azimuth=90.0, elevation=-35.0)

    def __init__(
        self,
        config: str | os.PathLike[str] | Mapping[str, Any] | None = None,
        backend: str | None = None,
        *,
        action_mode: str = "velocity",
        control_period: float = 0.05,
        render_mode: str | None = None,
        goal_range: Sequence[float] = (-0.05, 0.05),
        start_range: Sequence[float] = (-0.02, 0.02),
        min_goal_distance: float = 0.01,
        success_tolerance: float = 0.001,
        action_rate_weight: float = 0.01,
        reset_velocity: float = 0.02,
        reset_timeout: float = 20.0,
        width: int = 480,
        height: int = 480,
        raise_on_overrun: bool = False,
    ) -> None:
        if action_mode not in ACTION_MODES:
            raise ValueError(f"action_mode {action_mode!r} is not one of {ACTION_MODES} (the MKS has no torque mode)")
        if isinstance(control_period, bool) or not isinstance(control_period, (int, float)) \
                or not math.isfinite(control_period) or control_period <= 0:
            raise ValueError(f"control_period must be a finite number of seconds > 0, got {control_period!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode {render_mode!r} is not one of {self.metadata['render_modes']}")
        for what, v in (("success_tolerance", success_tolerance), ("reset_velocity", reset_velocity),
                        ("reset_timeout", reset_timeout)):
            if not math.isfinite(v) or v <= 0:
                raise ValueError(f"{what} must be > 0, got {v!r}")
        if not math.isfinite(action_rate_weight) or action_rate_weight < 0 or not math.isfinite(min_goal_distance) \
                or min_goal_distance < 0:
            raise ValueError("action_rate_weight and min_goal_distance must be >= 0")
        self.action_mode = action_mode
        self.control_period = float(control_period)
        self.raise_on_overrun = bool(raise_on_overrun)
        self.render_mode = render_mode
        self._ranges = (tuple(map(float, goal_range)), tuple(map(float, start_range)))
        self.min_goal_distance = float(min_goal_distance)
        self.success_tolerance = float(success_tolerance)
        self.action_rate_weight = float(action_rate_weight)
        self.reset_velocity = float(reset_velocity)
        self.reset_timeout = float(reset_timeout)
        self.width, self.height = int(width), int(height)
        self._start(config, backend, False)

    # -- construction -----------------------------------------------------------------------
    def _open(self, config: Any, backend: str | None) -> joints.Rig:
        if config is None:
            with config_path("mks_axis") as p:
                return joints.open(p, backend=backend)
        return joints.open(config, backend=backend)

    def _setup(self, domain_randomization: Any) -> None:
        rig = self.rig
        self.sim = rig.backend == "sim"
        if len(rig.joints) != 1:
            raise joints.ConfigError(f"MksAxisPosition drives exactly one joint, the config has {list(rig.joints)}",
                                     file=rig.config.source, key="joints")
        self.joint_name = next(iter(rig.joints))
        j = self.joint = rig.joints[self.joint_name]
        key = f"joints.{self.joint_name}"
        if j.lead is None:
            raise joints.ConfigError("the axis needs the joint's lead [m per motor turn]", file=rig.config.source,
                                     key=f"{key}.lead")
        lim = j.limits
        if lim.position is None or lim.velocity is None:
            raise joints.ConfigError("the env needs the joint's position and velocity limits (they scale actions)",
                                     file=rig.config.source, key=f"{key}.limits")
        self.lo, self.hi = lim.position
        self.velocity_limit = float(lim.velocity)
        goal, start = self._ranges
        self.goal_range = _within("goal_range", goal, self.lo, self.hi)
        self.start_range = _within("start_range", start, self.lo, self.hi)
        if self.sim:
            steps = self.control_period / rig.sim.timestep
            if abs(steps - round(steps)) > 1e-6 or round(steps) < 1:
                raise ValueError(f"control_period {self.control_period} s must be a whole number of physics "
                                 f"substeps of {rig.sim.timestep} s")
        self._check_rate(self.action_mode)
        span = self.hi - self.lo
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        low = np.array([self.lo - 0.01, -2 * self.velocity_limit, self.lo, -span])
        high = np.array([self.hi + 0.01, 2 * self.velocity_limit, self.hi, span])
        self.observation_space = spaces.Box(low, high, dtype=np.float64)
        self._obs_low, self._obs_high = low, high
        self._mjcf = rig.config.joints[self.joint_name].mjcf_joint or self.joint_name
        self._renderer: SceneRenderer | None = None
        self._twin: tuple[Any, Any, int] | None = None
        self.goal = 0.0
        self._state: joints.JointState | None = None
        self._prev_action = 0.0
        self._tick = 0
        self._slip = 0.0  #: s the schedule slipped by overruns this episode
        self._t0 = 0.0
        self.overruns = 0  #: steps whose tick had passed before their commands were sent
        self.overrun_time = 0.0  #: s, the total of those steps' lateness
        self._overrun = 0.0

    # -- conversions ------------------------------------------------------------------------
    @property
    def dt(self) -> float:
        return self.control_period

    def command_of(self, action: Sequence[float] | np.ndarray) -> float:
        """The SI command (m/s or m) of a normalised action."""
        a = float(np.clip(np.asarray(action, dtype=np.float64).reshape(-1)[0], -1.0, 1.0))
        if self.action_mode == "velocity":
            return a * self.velocity_limit
        return self.lo + (a + 1.0) * 0.5 * (self.hi - self.lo)

    def action_of(self, command: float) -> np.ndarray:
        """The normalised action (float32, clipped) for an SI command; inverse of :meth:`command_of`."""
        if self.action_mode == "velocity":
            a = command / self.velocity_limit
        else:
            a = 2.0 * (command - self.lo) / (self.hi - self.lo) - 1.0
        return np.array([np.clip(a, -1.0, 1.0)], dtype=np.float32)

    def safe_command(self, command: float) -> float:
        """The SI command the env sends for ``command`` (m or m/s) in the present state: a target
        within the position limits; a speed within the velocity limit and, towards a limit, no
        faster than the drive's ramp (:data:`BRAKING_SHARE` of it) can stop from
        :data:`LIMIT_INSET` short of it after one more period (:func:`envs.base.braking_speed`)."""
        if not math.isfinite(command):
            raise ValueError(f"command must be finite, got {command!r}")
        if self.action_mode == "position":
            return min(max(command, self.lo), self.hi)
        v = min(max(command, -self.velocity_limit), self.velocity_limit)
        if self._state is None:
            return v
        x, speed = self._state.position, self._state.velocity
        a, dt = np.array([BRAKING_SHARE * self.joint.motion.acceleration]), self.control_period + self.bus_lag
        up = float(braking_speed(np.array([self.hi - LIMIT_INSET - x]), a, dt, speed)[0])
        down = float(braking_speed(np.array([x - self.lo - LIMIT_INSET]), a, dt, -speed)[0])
        return min(max(v, -down), up)

    def pd_action(self, obs: np.ndarray, *, kp: float = 4.0, kd: float = 0.0) -> np.ndarray:
        """A scripted baseline: in velocity mode ``v = kp x (goal - x) - kd x v`` [m/s]; in position mode the goal."""
        if self.action_mode == "position":
            return self.action_of(float(obs[2]))
        return self.action_of(kp * float(obs[3]) - kd * float(obs[1]))

    # -- gymnasium API ----------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode; ``options={"start": x, "goal": g}`` [m] fix the draws."""
        super().reset(seed=seed)
        self._check_open()
        options = dict(options or {})
        start = float(options["start"]) if "start" in options else float(self.np_random.uniform(*self.start_range))
        if not (math.isfinite(start) and self.lo <= start <= self.hi):
            raise ValueError(f"start {start} m is outside the position limits [{self.lo}, {self.hi}]")
        self.goal = self._draw_goal(start, options)
        if self.sim:
            rig = self.rig
            self._reset_rig()  # physics and the twin to power-on; the driver forgets what it wrote
            rig.sim.set_joint_positions({self.joint_name: (start - self.joint.offset) * self.joint.direction})
            self.joint.enable()
        else:
            self._reset_hardware(start)
        self._hold(start)
        self._prev_action = float(self.action_of(start if self.action_mode == "position" else 0.0)[0])
        self._tick = 0
        self._slip = 0.0  #: s the schedule slipped by overruns this episode
        s = self._read()
        self._t0 = self.rig.time  # the schedule starts with the first observation (its read took bus time)
        info = self._info(s)
        if self.render_mode == "human":
            self.render()
        return self._observation(s), info

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        self._check_open()
        a = np.asarray(action, dtype=np.float64)
        if a.shape != self.action_space.shape:
            raise ValueError(f"action shape {a.shape} != {self.action_space.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"action must be finite, got {a.tolist()}")
        a = a.clip(-1.0, 1.0)
        command = self.safe_command(self.command_of(a))
        if self.joint.enabled:  # a faulted drive ended the episode: never command it
            if self.action_mode == "velocity":
                self.joint.set_velocity(command)
            else:
                self.joint.move_to(command)
        self._tick += 1
        self._wait_until(self.tick_time())
        s = self._read()
        distance = abs(self.goal - s.position)
        r_dist = -distance / 0.01
        r_rate = -self.action_rate_weight * float((a[0] - self._prev_action) ** 2)
        self._prev_action = float(a[0])
        info = self._info(s)
        violation = not (self.lo - LIMIT_MARGIN <= s.position <= self.hi + LIMIT_MARGIN)
        info.update({"reward_distance": r_dist, "reward_action_rate": r_rate, "limit_violation": violation,
                     "command": command})
        terminated = violation or s.fault is not None
        if terminated and self.joint.enabled:
            try:
                self.joint.stop()
            except joints.JointsError as exc:
                gym.logger.warn(f"stopping the axis failed: {exc}")
        if self.render_mode == "human":
            self.render()
        return self._observation(s), r_dist + r_rate, bool(terminated), False, info

    # -- internals ----------------------------------------------------------------------------
    def _draw_goal(self, start: float, options: Mapping[str, Any]) -> float:
        if "goal" in options:
            g = float(options["goal"])
            if not (math.isfinite(g) and self.lo <= g <= self.hi):
                raise ValueError(f"goal {g} m is outside the position limits [{self.lo}, {self.hi}]")
            return g
        for _ in range(1000):
            g = float(self.np_random.uniform(*self.goal_range))
            if abs(g - start) >= self.min_goal_distance:
                return g
        raise ValueError("goal_range leaves no goal min_goal_distance away from the start; widen it")

    def _hold(self, start: float) -> None:
        if self.action_mode == "velocity":
            self.joint.set_velocity(0.0)
        else:
            self.joint.move_to(start)

    def _reset_hardware(self, start: float) -> None:
        j, rig = self.joint, self.rig
        s = j.state()
        if s.fault is not None:
            j.clear_faults()
            j.check()  # still faulted: raises DeviceFault by name
        if not j.enabled:
            j.enable()
        j.move_to(start, velocity=min(self.reset_velocity, self.velocity_limit))
        deadline = rig.time + self.reset_timeout
        while True:
            s = j.state()
            if s.fault is not None:
                j.check()
            if not s.moving and abs(s.position - start) < self.success_tolerance and abs(s.velocity) < 0.005:
                return
            if rig.time > deadline:
                raise MotionTimeout(f"reset: the carriage is not at {start} m after {self.reset_timeout} s "
                                    f"(at {s.position:.4f} m)")
            rig.sleep(self.control_period)

    def _read(self) -> joints.JointState:
        self._state = self.joint.state()
        return self._state

    def _observation(self, s: joints.JointState) -> np.ndarray:
        obs = np.array([s.position, s.velocity, self.goal, self.goal - s.position], dtype=np.float64)
        np.clip(obs, self._obs_low, self._obs_high, out=obs)
        return obs

    def _info(self, s: joints.JointState) -> dict[str, Any]:
        distance = abs(self.goal - s.position)
        info = {"time": float(self.rig.time - self._t0), "overrun": self._overrun, "distance": distance,
                "is_success": distance < self.success_tolerance and abs(s.velocity) < 0.005,
                "faults": {self.joint_name: s.fault.name if s.fault else None}}
        if s.fault is not None:
            info["fault"] = fault_info(self.joint_name, s)
        return info

    # -- rendering -----------------------------------------------------------------------------
    def _scene(self) -> tuple[Any, Any]:
        if self.sim:
            return self.rig.sim.model, self.rig.sim.data
        import mujoco

        model = mujoco.MjModel.from_xml_path(str(self.rig.model_path()))
        data = mujoco.MjData(model)
        adr = int(model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, self._mjcf)])
        self._twin = (model, data, adr)
        return model, data

    def _update_twin(self) -> None:
        import mujoco

        assert self._twin is not None and self._state is not None
        model, data, adr = self._twin
        data.qpos[adr] = (self._state.position - self.joint.offset) * self.joint.direction
        mujoco.mj_forward(model, data)

    def _markers(self) -> list[tuple[np.ndarray, tuple[float, float, float, float]]]:
        """The goal: where the carriage's tool site would be at the goal position."""
        import mujoco

        if self._state is None:
            return []
        if self.sim:
            model, data = self.rig.sim.model, self.rig.sim.data
        elif self._twin is not None:
            model, data = self._twin[0], self._twin[1]
        else:
            return []
        site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "tool")
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, self._mjcf)
        if site < 0 or jid < 0:
            return []
        shift = (self.goal - self._state.position) * self.joint.direction
        return [(np.array(data.site_xpos[site]) + shift * np.array(data.xaxis[jid]), (0.1, 0.9, 0.2, 0.6))]


def _within(name: str, r: Sequence[float], lo: float, hi: float) -> tuple[float, float]:
    if len(r) != 2 or not all(math.isfinite(v) for v in r) or r[0] > r[1]:
        raise ValueError(f"{name} must be (low, high) with low <= high, got {r!r}")
    a, b = max(float(r[0]), lo), min(float(r[1]), hi)
    if a > b:
        raise ValueError(f"{name} {tuple(r)} lies outside the position limits [{lo}, {hi}]")
    return a, b
