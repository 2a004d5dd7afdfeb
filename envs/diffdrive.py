"""joints/DiffDriveGoal-v0: drive a differential-drive base (two hub motors on one ZLAC8015D) to a
goal pose, with wheel-speed actions and wheel odometry - the same env on the emulated drive and on a
real one.

Rules (as :mod:`envs.base`):

* The env acts only through the public API: ``joint.enable / disable / clear_faults / read /
  write / stop``, ``rig.set_velocities`` (both wheels of the drive in ONE FC16),
  ``rig.read_states`` (both wheels in ONE FC03), ``rig.sleep``, ``rig.reset``. Sim-only extras
  (ground truth in ``info``, domain randomisation, rendering of the world) use ``rig.sim`` and
  only when ``rig.backend == "sim"``.
* The pose the agent sees is an estimate from wheel odometry (measured wheel angles, the wheel
  radius and the track), so observations and rewards mean the same on hardware.
* Fixed control period on the rig's clock; deterministic in sim (every draw from ``np_random``).
* The ZLAC8015D quick-stops both wheels when the host is silent longer than 0x2000 (1000 ms by
  default). Every step talks to the drive; between steps, call ``step`` at least every ~0.5 s on
  hardware (a gap longer than the watchdog ends the episode, see "Episode End").
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
from collections import deque
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

import joints
from envs import configs
from envs.base import RigEnv, clip, fault_info
from envs.randomization import GAINS, DomainRandomization
from envs.render import CameraSpec, SceneRenderer
from joints.errors import MotionTimeout

if sys.version_info >= (3, 11):
    pass
else:  # pragma: no cover
    pass

#: m, wheel radius of models/zlac_diffdrive.xml (8-inch hub)
WHEEL_RADIUS = 0.1016
#: m, wheel centre to wheel centre in models/zlac_diffdrive.xml
TRACK = 0.40
#: the shipped default config (``joints/configs/zlac_diffdrive.toml``)
CONFIG_NAME = "zlac_diffdrive"
#: domain-randomisation gain factors -> the ZLAC8015D registers they scale (per wheel: _left/_right)

#: ZLAC8015D control mode 0x200D: velocity
VELOCITY_MODE = 3
#: s the chassis gets to settle on its wheels after a sim reset (the model starts it 1 mm up)
SIM_SETTLE = 0.1
#: rad/s below which a wheel counts as standing still (hardware reset)
STANDSTILL = 0.05


def config_path() -> contextlib.AbstractContextManager[Path]:
    """A filesystem path of the shipped ``zlac_diffdrive.toml`` (valid inside the ``with`` block)."""
    return configs.config_path(CONFIG_NAME)


def default_config() -> dict[str, Any]:
    """The shipped diff-drive config as a fresh, editable dict (e.g. set the bus port for hardware)."""
    return configs.default_config(CONFIG_NAME)


def wrap_angle(a: float) -> float:
    """``a`` [rad] wrapped to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class WheelOdometry:
    """Pose (x, y, heading) of a differential-drive base from its two wheel angles.

    Sign convention of ``models/zlac_diffdrive.xml``: a positive angle increment on either wheel
    rolls that side forward; the left wheel is on +y. Increments are integrated at the midpoint
    heading (exact for constant wheel speeds between two readings).
    """

    def __init__(self, wheel_radius: float = WHEEL_RADIUS, track: float = TRACK) -> None:
        if not (math.isfinite(wheel_radius) and wheel_radius > 0 and math.isfinite(track) and track > 0):
            raise ValueError(f"wheel_radius and track must be > 0 m, got {wheel_radius!r}, {track!r}")
        self.wheel_radius = float(wheel_radius)
        self.track = float(track)
        self.x = self.y = self.heading = 0.0
        self._last: tuple[float, float] | None = None

    def restart(self, left: float, right: float) -> None:
        """Pose (0, 0, 0) at the wheel angles ``left``, ``right`` [rad]."""
        self.x = self.y = self.heading = 0.0
        self._last = (float(left), float(right))

    def update(self, left: float, right: float) -> tuple[float, float, float]:
        """Integrate to the wheel angles ``left``, ``right`` [rad]; returns (x [m], y [m], heading [rad])."""
        if self._last is None:
            self.restart(left, right)
            return self.pose
        dl = (left - self._last[0]) * self.wheel_radius
        dr = (right - self._last[1]) * self.wheel_radius
        self._last = (float(left), float(right))
        ds = 0.5 * (dl + dr)
        dth = (dr - dl) / self.track
        mid = self.heading + 0.5 * dth
        self.x += ds * math.cos(mid)
        self.y += ds * math.sin(mid)
        self.heading = wrap_angle(self.heading + dth)
        return self.pose

    @property
    def pose(self) -> tuple[float, float, float]:
        return self.x, self.y, self.heading


class DiffDriveGoalEnv(RigEnv):
    """Drive a differential-drive base to a goal pose (x, y, heading).

    ## Description
    A base with two 8-inch hub motors on one ZLAC8015D dual-channel driver over Modbus RTU
    (``models/zlac_diffdrive.xml``: wheel radius 0.1016 m, track 0.40 m, 23.8 kg, two casters) -
    emulated in MuJoCo with the sim backend, or a real base with the hardware backend, from the
    same config. At every reset a goal pose is drawn relative to where the base stands; the agent
    commands the two wheel speeds and must bring the base to the goal position, facing the goal
    heading. The base pose is estimated from the measured wheel angles (wheel odometry), exactly
    as on a real robot.

    ## Action Space
    ``Box(-1, 1, (2,), float32)``: ``[left, right]`` wheel speed commands, ``a x limits.velocity``
    [rad/s] of each wheel (default config: 10 rad/s = 95 r/min = 1.02 m/s at the rim). Both are
    sent in ONE Modbus FC16 (``Rig.set_velocities``) and reached with the drive's own ramp at the
    config's ``motion.acceleration`` (default 20 rad/s^2). A positive speed on a wheel rolls that
    side forward: ``[1, 1]`` drives straight ahead, ``[1, -1]`` turns clockwise in place.
    ``env.unwrapped.command_of(a)`` / ``action_of(rad_s)`` convert. The drive holds the command
    for the control period (zero-order hold, ``dt`` = 50 ms by default).

    ## Observation Space
    ``Box(float64, (10,))`` (values clipped to the bounds; ``A`` = ``arena`` = 4 m by default,
    ``G`` = the largest goal distance, ``V`` = the wheel velocity limit):

    | index | observation | unit | bounds |
    |---|---|---|---|
    | 0, 1 | base position estimate x, y (episode frame: the pose at reset is the origin, x ahead) | m | +- 2A |
    | 2, 3 | cos, sin of the heading estimate | - | [-1, 1] |
    | 4, 5 | goal position in the base frame (x ahead, y to the left) | m | +- (2A + G) |
    | 6, 7 | cos, sin of (goal heading - heading estimate) | - | [-1, 1] |
    | 8, 9 | measured wheel speeds left, right | rad/s | +- 2V |

    The estimate integrates the measured wheel angles with ``wheel_radius`` and ``track``; in sim
    it drifts from the truth only by tyre slip and scrub (~3 % of the angle turned in place).

    ## Rewards
    ``reward = reward_progress + reward_heading + reward_action + reward_success`` (all in
    ``info``), computed from the estimate (so the same on hardware):

    - ``reward_progress = progress_weight * (d_{t-1} - d_t)``: metres gained towards the goal
      position (``progress_weight`` = 10);
    - ``reward_heading = -heading_weight * |heading error| / pi * exp(-d_t / heading_scale)``: the
      goal heading matters near the goal (``heading_weight`` = 0.2, ``heading_scale`` = 0.3 m);
    - ``reward_action = -action_weight * sum(a^2)`` (``action_weight`` = 0.01);
    - ``reward_success = success_bonus`` (5) at the step the goal is reached.

    ``info`` also holds ``distance`` [m], ``heading_error`` [rad], ``is_success`` (distance <
    ``success_distance`` = 0.1 m and |heading error| < ``success_heading`` = 0.2 rad),
    ``pose_estimate`` and ``goal`` (x, y, heading in the episode frame), ``wheel_velocities``
    [rad/s], ``time`` [s], ``faults`` (wheel -> the drive's fault by name, None = none) and, when
    a wheel reports a fault, ``fault`` (``joint``, ``name``, ``code``, ``text``, ``clears`` of the
    first). In sim also ``true_pose`` (the chassis site ``base`` from the physics, same frame) and
    ``true_distance``.

    ## Starting State
    Sim: physics and the emulated drive at power-on (``rig.reset``): the base stands at the world
    origin facing +x; both wheels enabled in velocity mode at zero speed, then 0.1 s to settle
    (the first observation is at t = 0.1 s). Hardware: faults are cleared, the drive is (re-)enabled
    in velocity mode with zero speed and the env waits until both wheels stand still; the pose
    estimate restarts at zero wherever the base is. The goal is drawn (seeded) at a distance
    uniform in ``goal_distance`` (0.5-2.0 m), a bearing uniform in [-pi, pi) and a heading
    uniform in [-pi, pi), relative to the start pose. ``reset(options={"goal": [x, y, heading]})``
    fixes it.

    ## Episode End
    - Termination: success (when ``terminate_on_success``, the default); a drive fault on either
      wheel (``info["fault"]``; ``reset()`` clears it: sim power cycle, hardware clear + enable); the
      estimate leaving the square ``|x|, |y| <= arena``; on hardware, a gap between
      steps longer than the drive's communication-offline time (the drive has quick-stopped;
      ``info["watchdog"]``). The env then commands zero speed (the drive ramps down).
      Wheel-speed actions never fault the drive by design: every speed within the velocity limit,
      ramped with ``motion.acceleration``, is one the wheels follow.
    - Truncation: 400 steps (20 s at the default control period), by the registered
      ``max_episode_steps``.

    ## Arguments
    ``gymnasium.make("joints/DiffDriveGoal-v0", config=None, backend=None, control_period=0.05,
    render_mode=None, domain_randomization=False, goal_distance=(0.5, 2.0), success_distance=0.1,
    success_heading=0.2, terminate_on_success=True, progress_weight=10.0, heading_weight=0.2,
    heading_scale=0.3, action_weight=0.01, success_bonus=5.0, arena=4.0, wheel_radius=0.1016,
    track=0.40, reset_timeout=10.0, width=480, height=480, raise_on_overrun=False, compiled_path=True)``

    - ``config``: joints config (TOML path or dict) with the two wheels of a ZLAC8015D
      (``device = "zlac8015d"``, ``channel = "left"`` / ``"right"``), each with a velocity limit; default
      the shipped ``joints/configs/zlac_diffdrive.toml`` (:func:`envs.diffdrive.default_config`).
      ``backend``: ``"sim"`` | ``"hardware"``, overrides it.
    - ``control_period`` [s] (sim: a whole number of physics substeps), ``render_mode``
      (``"rgb_array"``, ``"human"``; on hardware a kinematic twin posed from the estimate),
      ``domain_randomization`` (sim only, :class:`envs.DomainRandomization`: the gain factors
      scale the drive's Vl Kp / Vl Ki / Pl Kp registers; friction, armature, torque constant
      change the wheel joints; ``encoder_noise`` [rad] is added to the wheel angles the odometry
      sees; ``latency`` delays actions by whole periods).
    - ``wheel_radius``, ``track`` [m]: the odometry's geometry (measure your base).
    - ``reset_timeout`` [s]: hardware reset, time for the wheels to come to rest.
    - ``compiled_path``: sim only - send each step's wheel speeds and read the states by the compiled path
      (:mod:`joints.compiled_path`: the same frames as ``rig.set_velocities`` / ``rig.read_states``, less
      Python; default); False: the driver path.

    ## Version History
    - v0: initial version (ZLAC8015D over Modbus RTU; sim and hardware backends).
    """

    metadata: dict[str, Any] = {"render_modes": ["human", "rgb_array"], "render_fps": 20}  # noqa: RUF012
    camera = CameraSpec(lookat=(0.0, 0.0, 0.0), distance=6.0, azimuth=90.0, elevation=-60.0)

    def __init__(
        self,
        config: str | os.PathLike[str] | Mapping[str, Any] | None = None,
        backend: str | None = None,
        *,
        control_period: float = 0.05,
        render_mode: str | None = None,
        domain_randomization: bool | Mapping[str, Any] | DomainRandomization = False,
        goal_distance: Sequence[float] = (0.5, 2.0),
        success_distance: float = 0.1,
        success_heading: float = 0.2,
        terminate_on_success: bool = True,
        progress_weight: float = 10.0,
        heading_weight: float = 0.2,
        heading_scale: float = 0.3,
        action_weight: float = 0.01,
        success_bonus: float = 5.0,
        arena: float = 4.0,
        wheel_radius: float = WHEEL_RADIUS,
        track: float = TRACK,
        reset_timeout: float = 10.0,
        width: int = 480,
        height: int = 480,
        raise_on_overrun: bool = False,
        compiled_path: bool = True,
    ) -> None:
        if isinstance(control_period, bool) or not isinstance(control_period, (int, float)) \
                or not math.isfinite(control_period) or control_period <= 0:
            raise ValueError(f"control_period must be a finite number of seconds > 0, got {control_period!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode {render_mode!r} is not one of {self.metadata['render_modes']}")
        positive = {"success_distance": success_distance, "success_heading": success_heading,
                    "heading_scale": heading_scale, "arena": arena, "reset_timeout": reset_timeout}
        for what, v in positive.items():
            if not math.isfinite(v) or v <= 0:
                raise ValueError(f"{what} must be > 0, got {v!r}")
        weights = {"progress_weight": progress_weight, "heading_weight": heading_weight,
                   "action_weight": action_weight, "success_bonus": success_bonus}
        for what, v in weights.items():
            if not math.isfinite(v) or v < 0:
                raise ValueError(f"{what} must be >= 0, got {v!r}")
        gd = tuple(float(v) for v in goal_distance)
        if len(gd) != 2 or not all(math.isfinite(v) for v in gd) or not 0 <= gd[0] <= gd[1] or gd[1] >= arena:
            raise ValueError(f"goal_distance must be (low, high) with 0 <= low <= high < arena, got {goal_distance!r}")
        self.odometry = WheelOdometry(wheel_radius, track)  # validates the geometry
        self.control_period = float(control_period)
        self.raise_on_overrun = bool(raise_on_overrun)
        self.render_mode = render_mode
        self.goal_distance = gd
        self.success_distance = float(success_distance)
        self.success_heading = float(success_heading)
        self.terminate_on_success = bool(terminate_on_success)
        self.progress_weight = float(progress_weight)
        self.heading_weight = float(heading_weight)
        self.heading_scale = float(heading_scale)
        self.action_weight = float(action_weight)
        self.success_bonus = float(success_bonus)
        self.arena = float(arena)
        self.reset_timeout = float(reset_timeout)
        self.width, self.height = int(width), int(height)
        self._want_compiled = bool(compiled_path)
        self._start(config, backend, domain_randomization)

    # -- construction -----------------------------------------------------------------------
    @staticmethod
    def _open(config: Any, backend: str | None) -> joints.Rig:
        if config is None:
            with config_path() as p:
                return joints.open(p, backend=backend)
        return joints.open(config, backend=backend)

    def _select_wheels(self, rig: joints.Rig) -> tuple[str, str]:
        by_side: dict[str, str] = {}
        for name, jc in rig.config.joints.items():
            if jc.channel in ("left", "right"):  # a two-channel drive's wheels (config allows channels only there)
                by_side.setdefault(jc.channel, name)
        if len(rig.joints) != 2 or set(by_side) != {"left", "right"}:
            raise joints.ConfigError(
                "DiffDriveGoal drives exactly two wheels of a ZLAC8015D (device = \"zlac8015d\"), one with "
                f"channel = \"left\" and one with channel = \"right\"; the config has {list(rig.joints)}",
                file=rig.config.source, key="joints")
        return by_side["left"], by_side["right"]

    def _setup(self, domain_randomization: Any) -> None:
        rig = self.rig
        self.sim = rig.backend == "sim"
        self.wheel_names = list(self._select_wheels(rig))  #: [left, right]
        self.wheels = [rig.joints[n] for n in self.wheel_names]
        vlim = []
        for name, j in zip(self.wheel_names, self.wheels):
            if j.limits.velocity is None:
                raise joints.ConfigError("the env needs the wheel's velocity limit (it scales actions)",
                                         file=rig.config.source, key=f"joints.{name}.limits.velocity")
            vlim.append(j.limits.velocity)
        self.velocity_limits = np.array(vlim, dtype=np.float64)  #: (2,) rad/s
        self._vlim = (float(vlim[0]), float(vlim[1]))
        watchdog = [rig.config.joints[n].watchdog_ms for n in self.wheel_names]
        #: s of host silence after which the drive quick-stops (0x2000; its default 1000 ms)
        self.watchdog = min((w if w is not None else 1000) for w in watchdog) / 1000.0
        if self.sim:
            steps = self.control_period / rig.sim.timestep
            if abs(steps - round(steps)) > 1e-6 or round(steps) < 1:
                raise ValueError(f"control_period {self.control_period} s must be a whole number of physics "
                                 f"substeps of {rig.sim.timestep} s")
        self._check_rate("velocity")
        self.randomization = DomainRandomization.from_arg(domain_randomization)
        if self.randomization is not None and not self.sim:
            gym.logger.warn("domain randomisation acts on the simulation only; ignored on hardware")
            self.randomization = None

        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        a, g, v = self.arena, self.goal_distance[1], self.velocity_limits
        low = np.array([-2 * a, -2 * a, -1, -1, -2 * a - g, -2 * a - g, -1, -1, -2 * v[0], -2 * v[1]], np.float64)
        self.observation_space = spaces.Box(low, -low, dtype=np.float64)
        self._obs_lo, self._obs_hi = low.tolist(), (-low).tolist()  #: the bounds as plain floats

        #: the compiled command/state path (sim, both wheels a twin it knows, read in the rig's order), else None
        compiled = self.sim and self._want_compiled and self.wheel_names == list(rig.joints)
        self.compiled_path = joints.CompiledPath.build(self.wheels) if compiled else None
        self._mjcf = [rig.config.joints[n].mjcf_joint or n for n in self.wheel_names]
        self._site = -1
        if self.sim:
            self._setup_sim()

        self._renderer: SceneRenderer | None = None
        self._twin: tuple[Any, Any, int, list[int]] | None = None
        self.goal = np.zeros(3)
        self._queue: deque[tuple[float, float]] = deque()
        self._states: dict[str, joints.JointState] = {}
        self._angles = (0.0, 0.0)  #: the wheel angles the odometry sees [rad] (with the encoder noise)
        self._distance = 0.0
        self._tick = 0
        self._slip = 0.0  #: s the schedule slipped by overruns this episode
        self._t0 = 0.0
        self._last_io = 0.0
        self._origin = np.zeros(3)  #: sim: the true pose at which the estimate restarted
        self._frame = (0.0, 0.0, 1.0, 0.0, 0.0)  #: sim: :attr:`_origin` as (x, y, cos, sin, heading) floats
        self._noise = 0.0
        self._noise_rng: np.random.Generator | None = None
        self.randomization_sample: dict[str, Any] | None = None
        self.overruns = 0  #: steps whose tick had passed before their commands were sent
        self.overrun_time = 0.0  #: s, the total of those steps' lateness
        self._overrun = 0.0

    @property
    def goal(self) -> np.ndarray:
        """The episode's goal (x [m], y [m], heading [rad]) in the episode frame (read-only: set the whole goal, e.g.
        ``reset(options={"goal": ...})``)."""
        return self._goal

    @goal.setter
    def goal(self, goal: Sequence[float] | np.ndarray) -> None:
        self._goal = np.array(goal, dtype=np.float64)  # a copy of its own
        self._goal.flags.writeable = False
        self._goal_list: list[float] = self._goal.tolist()  #: its floats, for the per-step terms

    @property
    def model(self) -> Any:
        """The MuJoCo model in sim (as gymnasium's ``MujocoEnv``); None on hardware."""
        return self.rig.sim.model if self.sim else None

    @property
    def data(self) -> Any:
        """The MuJoCo data in sim (as gymnasium's ``MujocoEnv``); None on hardware."""
        return self.rig.sim.data if self.sim else None

    def _setup_sim(self) -> None:
        import mujoco as mj

        sim = self.rig.sim
        model = sim.model
        self._site = mj.mj_name2id(model, mj.mjtObj.mjOBJ_SITE, "base")
        if self._site < 0:
            raise joints.ConfigError("the model has no site 'base' (the chassis reference the env reports "
                                     "as ground truth)", file=self.rig.config.source, key="sim.model")
        jids = [mj.mj_name2id(model, mj.mjtObj.mjOBJ_JOINT, m) for m in self._mjcf]
        # the odometry's geometry against the model's (the axle anchors and the tyres' radius)
        data = sim.data
        anchors = [np.array(data.xanchor[j]) for j in jids]
        track = float(np.linalg.norm(anchors[0] - anchors[1]))
        bodies = [model.jnt_bodyid[j] for j in jids]
        radii = [float(model.geom_size[g][0]) for g in range(model.ngeom)
                 if model.geom_bodyid[g] in bodies and model.geom_type[g] == mj.mjtGeom.mjGEOM_CYLINDER]
        if abs(track - self.odometry.track) > 0.1 * track or \
                (radii and abs(max(radii) - self.odometry.wheel_radius) > 0.1 * max(radii)):
            gym.logger.warn(f"odometry geometry (radius {self.odometry.wheel_radius} m, track "
                            f"{self.odometry.track} m) differs from the model's (radius "
                            f"{max(radii) if radii else '?'} m, track {track:.4f} m)")

    def _side(self, wheel: str) -> str:
        return "left" if wheel == self.wheel_names[0] else "right"

    # -- conversions ------------------------------------------------------------------------
    @property
    def dt(self) -> float:
        """Seconds per step: the control period."""
        return self.control_period

    def command_of(self, action: Sequence[float] | np.ndarray) -> np.ndarray:
        """Wheel speeds [rad/s] (left, right) for a normalised action (clipped to [-1, 1])."""
        a = np.asarray(action, dtype=np.float64).reshape(-1).clip(-1.0, 1.0)
        out: np.ndarray = a * self.velocity_limits
        return out

    def action_of(self, wheel_speeds: Sequence[float] | np.ndarray) -> np.ndarray:
        """The normalised action (float32, clipped) for wheel speeds [rad/s]; inverse of :meth:`command_of`."""
        a = np.asarray(wheel_speeds, dtype=np.float64).reshape(-1) / self.velocity_limits
        out: np.ndarray = np.clip(a, -1.0, 1.0).astype(np.float32)
        return out

    def wheel_speeds_of(self, v: float, omega: float) -> np.ndarray:
        """Wheel speeds [rad/s] (left, right) for a base speed ``v`` [m/s] and yaw rate ``omega`` [rad/s]."""
        r, half = self.odometry.wheel_radius, 0.5 * self.odometry.track
        return np.array([(v - omega * half) / r, (v + omega * half) / r])

    # -- gymnasium API ----------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode; ``options={"goal": [x, y, heading]}`` fixes the goal (episode frame)."""
        super().reset(seed=seed)
        self._check_open()
        options = dict(options or {})
        self.goal = self._sample_goal(options)
        if self.sim:
            self._reset_sim()
        else:
            self._reset_hardware()
        latency = self.randomization_sample["latency"] if self.randomization_sample else 0
        self._queue = deque((0.0, 0.0) for _ in range(latency))
        self._tick = 0
        self._slip = 0.0  #: s the schedule slipped by overruns this episode
        states = self._read()
        self.odometry.restart(*self._angles)
        if self.sim:
            self._origin = self._world_pose()
            ox, oy, oth = self._origin.tolist()
            self._frame = (ox, oy, math.cos(oth), math.sin(oth), oth)
        self._t0 = self.rig.time
        pose = self.odometry.pose
        self._distance = self._goal_terms(pose)[0]
        obs = self._observation(pose)
        info = self._info(states, pose)
        if self.randomization_sample is not None:
            info["randomization"] = self.randomization_sample
        if self.render_mode == "human":
            self.render()
        return obs, info

    batchable = True

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """:meth:`RigEnv.step`; on the compiled path, where it can, both wheels' command, the wait for the tick and
        the read in one call (:meth:`~joints.compiled_path.CompiledPath.step`: the same frames, substeps and
        bits)."""
        compiled = self.compiled_path
        if compiled is None or not compiled.steps or self.raise_on_overrun \
                or not self._keeps_step_parts(DiffDriveGoalEnv):
            return super().step(action)
        token = self._token(action)
        cmd = self._wheel_command(self._queued(token[0]))
        got = None if cmd is None else compiled.step("velocity", cmd, None, self.tick_time(1), self.rig)
        if got is None:  # not the steady case (nothing sent): the command, the wait and the read one by one
            if cmd is not None:
                compiled.command("velocity", cmd)
            self._tick += 1
            self._wait_until(self.tick_time())
            return self.finish_step(token)
        self._tick += 1
        (sl, sr), remaining = got
        self.note_overrun(-remaining)
        return self._finish(token, self._took(sl, sr))

    def _token(self, action: np.ndarray) -> tuple[tuple[float, float], bool]:
        """``action`` checked (shape, finite) and clipped to [-1, 1] as plain floats, and whether the drive's
        watchdog tripped (hardware): what :meth:`finish_step` needs."""
        self._check_open()
        a = action if type(action) is np.ndarray and action.dtype.kind == "f" else np.asarray(action, dtype=np.float64)
        if a.shape != self.action_space.shape:
            raise ValueError(f"action shape {a.shape} != {self.action_space.shape}")
        left, right = a.tolist()  # plain floats (float32 exactly widened) from here: the array arithmetic's bits
        if not (math.isfinite(left) and math.isfinite(right)):
            raise ValueError(f"action must be finite, got {[left, right]}")
        clipped = (clip(left, -1.0, 1.0), clip(right, -1.0, 1.0))
        return clipped, not self.sim and self._watchdog_tripped()

    def _queued(self, clipped: tuple[float, float]) -> tuple[float, float]:
        """The action sent this step: ``clipped``, or with a bus latency (domain randomisation) the one whose turn
        it is (``clipped`` waits its turn)."""
        if self._queue:
            self._queue.append(clipped)
            return self._queue.popleft()
        return clipped

    def begin_step(self, action: np.ndarray) -> tuple[tuple[float, float], bool]:
        token = self._token(action)
        self._command(self._queued(token[0]))
        self._tick += 1
        return token

    def finish_step(self, token: tuple[tuple[float, float], bool]) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Read both wheels (one FC03), integrate the odometry, observe, reward - on plain floats."""
        return self._finish(token, self._read())

    def _finish(self, token: tuple[tuple[float, float], bool], states: dict[str, joints.JointState]
                ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """:meth:`finish_step` once both wheels' ``states`` are read (:meth:`_took`)."""
        (a_left, a_right), watchdog = token
        pose = self.odometry.update(*self._angles)
        x, y, _ = pose
        d, e = self._goal_terms(pose)
        success = d < self.success_distance and abs(e) < self.success_heading
        r_progress = self.progress_weight * (self._distance - d)
        r_heading = -self.heading_weight * abs(e) / math.pi * math.exp(-d / self.heading_scale)
        r_action = -self.action_weight * (a_left * a_left + a_right * a_right)
        r_success = self.success_bonus if success else 0.0
        self._distance = d
        obs = self._observation(pose)
        info = self._info(states, pose, (d, e, success))
        info["reward_progress"] = r_progress
        info["reward_heading"] = r_heading
        info["reward_action"] = r_action
        info["reward_success"] = r_success
        arena = self.arena
        out_of_arena = abs(x) > arena or abs(y) > arena
        info["out_of_arena"] = out_of_arena
        info["watchdog"] = watchdog
        faulted = None
        for n in self.wheel_names:  # the first wheel that reports a fault
            if states[n].fault is not None:
                faulted = n
                info["fault"] = fault_info(n, states[n])
                break
        terminated = faulted is not None or out_of_arena or watchdog or (success and self.terminate_on_success)
        if terminated:
            self._safe_stop()
        if self.render_mode == "human":
            self.render()
        return obs, float(r_progress + r_heading + r_action + r_success), bool(terminated), False, info

    # -- task -------------------------------------------------------------------------------
    def _sample_goal(self, options: Mapping[str, Any]) -> np.ndarray:
        if "goal" in options:
            g = np.asarray(options["goal"], dtype=np.float64).reshape(-1)
            if g.shape != (3,) or not np.all(np.isfinite(g)):
                raise ValueError(f"goal must be [x, y, heading] (m, m, rad), finite, got {options['goal']!r}")
            if max(abs(g[0]), abs(g[1])) >= self.arena:
                raise ValueError(f"goal {g[:2].tolist()} lies outside the arena (|x|, |y| < {self.arena} m)")
            return np.array([g[0], g[1], wrap_angle(float(g[2]))])
        rng = self.np_random
        dist = float(rng.uniform(*self.goal_distance))
        bearing = float(rng.uniform(-math.pi, math.pi))
        heading = float(rng.uniform(-math.pi, math.pi))
        return np.array([dist * math.cos(bearing), dist * math.sin(bearing), heading])

    def _goal_terms(self, pose: tuple[float, float, float]) -> tuple[float, float]:
        """(distance [m], heading error [rad]) of the estimate ``pose`` (the odometry's) to the goal."""
        x, y, th = pose
        gx, gy, gh = self._goal_list
        return math.hypot(gx - x, gy - y), wrap_angle(gh - th)

    def _observation(self, pose: tuple[float, float, float]) -> np.ndarray:
        """The observation for the odometry's ``pose`` and the last wheel states."""
        x, y, th = pose
        c, s = math.cos(th), math.sin(th)
        gx, gy, gh = self._goal_list
        dx, dy = gx - x, gy - y
        e = gh - th
        states = self._states
        left, right = self.wheel_names
        row = [x, y, c, s, c * dx + s * dy, -s * dx + c * dy, math.cos(e), math.sin(e),
               states[left].velocity, states[right].velocity]
        # np.minimum(np.maximum(row, low), high) on plain floats (no bound is a signed zero: the same bits)
        return np.array([lo if v < lo else hi if v > hi else v  # noqa: FURB136 - min(), max() without calls
                         for v, lo, hi in zip(row, self._obs_lo, self._obs_hi)])

    def _info(self, states: Mapping[str, joints.JointState], pose: tuple[float, float, float],
              terms: tuple[float, float, bool] | None = None) -> dict[str, Any]:
        """The step's info for the odometry's ``pose``; ``terms``: :meth:`_goal_terms` and the success if the caller
        has them."""
        if terms is None:
            d, e = self._goal_terms(pose)
            success = d < self.success_distance and abs(e) < self.success_heading
        else:
            d, e, success = terms
        left, right = self.wheel_names
        sl, sr = states[left], states[right]
        fl, fr = sl.fault, sr.fault
        info: dict[str, Any] = {
            "time": float(self.rig.time),  # s on the rig's clock (sim: simulated seconds since reset)
            "overrun": self._overrun,  # s this step ran over its period (0.0: none)
            "faults": {left: None if fl is None else fl.name, right: None if fr is None else fr.name},
            "distance": d,
            "heading_error": e,
            "is_success": bool(success),
            "pose_estimate": np.array(pose),
            "goal": self._goal.copy(),
            "wheel_velocities": np.array([sl.velocity, sr.velocity]),
        }
        if self.sim:
            tx, ty, th = self._true_xyth()
            info["true_pose"] = np.array([tx, ty, th])
            gx, gy, _ = self._goal_list
            info["true_distance"] = math.hypot(gx - tx, gy - ty)
        return info

    def true_pose(self) -> np.ndarray:
        """Sim: the chassis site ``base`` from the physics, (x, y, heading) in the episode frame."""
        if not self.sim:
            raise RuntimeError("the true pose is known in simulation only")
        return np.array(self._true_xyth())

    def _true_xyth(self) -> tuple[float, float, float]:
        """:meth:`true_pose` as Python floats (the same arithmetic as on numpy scalars, faster)."""
        x, y, th = self._world_xyth()
        ox, oy, c, s, oth = self._frame  # (self._origin: its floats, cos and sin)
        return c * (x - ox) + s * (y - oy), -s * (x - ox) + c * (y - oy), wrap_angle(th - oth)

    def _world_pose(self) -> np.ndarray:
        """Sim: (x, y, heading) of the chassis site ``base`` in the world frame."""
        return np.array(self._world_xyth())

    def _world_xyth(self) -> tuple[float, float, float]:
        data = self.rig.sim.data
        x, y, _ = data.site_xpos[self._site].tolist()
        m = data.site_xmat[self._site].tolist()
        return x, y, math.atan2(m[3], m[0])

    # -- bus --------------------------------------------------------------------------------
    def _read(self) -> dict[str, joints.JointState]:
        compiled = self.compiled_path
        if compiled is not None:  # the same FC03, read as rig.read_states reads it
            # (the sim: the caller reads the physics next - the true pose - so the reply's travel may run in the read's
            # call; the compiled path's one-call step reads so too)
            sl, sr = compiled.states(settle=True)
            return self._took(sl, sr)
        states = self.rig.read_states()  # one FC03 per drive
        left, right = self.wheel_names
        return self._took(states[left], states[right], states)

    def _took(self, sl: joints.JointState, sr: joints.JointState,
              states: dict[str, joints.JointState] | None = None) -> dict[str, joints.JointState]:
        """Both wheels' states just read (``states``: as the rig gave them, else made of the two): kept, the time of
        the last talk to the drive, the wheel angles the odometry takes (with the sensor noise, sim)."""
        left, right = self.wheel_names
        self._states = {left: sl, right: sr} if states is None else states
        self._last_io = self.rig.time
        ql, qr = sl.position, sr.position
        if self._noise_rng is not None and self._noise > 0:
            nl, nr = self._noise_rng.normal(0.0, self._noise, 2).tolist()
            ql, qr = ql + nl, qr + nr
        self._angles = (ql, qr)
        return self._states

    def _wheel_command(self, action: tuple[float, float]) -> list[float] | None:
        """Both wheel speeds [rad/s] for ``action`` (clipped to [-1, 1]: :meth:`command_of` on plain floats); None
        where a wheel is not enabled (a faulted/disabled drive: the episode has ended, nothing is sent)."""
        for j in self.wheels:
            if not j.enabled:
                return None
        vl, vr = self._vlim
        return [action[0] * vl, action[1] * vr]

    def _command(self, action: tuple[float, float]) -> None:
        """Both wheel speeds for ``action`` (:meth:`_wheel_command`), sent in one FC16 (none where a wheel is not
        enabled)."""
        cmd = self._wheel_command(action)
        if cmd is None:
            return
        compiled = self.compiled_path
        if compiled is not None:  # the same FC16(s), sent as rig.set_velocities sends them
            compiled.command("velocity", cmd)
            return
        left, right = self.wheel_names
        self.rig.set_velocities({left: cmd[0], right: cmd[1]})  # one FC16

    def _watchdog_tripped(self) -> bool:
        """Hardware: after a silence longer than the drive's offline time, has it quick-stopped?

        The drive shows the trip as 0x20AF "software connected status" = 0 until the next enable.
        """
        if self.rig.time - self._last_io <= 0.9 * self.watchdog:
            return False
        try:
            return self.wheels[0].read("software_connected_status") == 0
        except joints.JointsError:
            return True

    def _safe_stop(self) -> None:
        try:
            if all(j.enabled for j in self.wheels):
                self.rig.set_velocities({n: 0.0 for n in self.wheel_names})  # ramp down, keep holding
        except joints.JointsError as exc:  # keep going: the drive's own protections still apply
            gym.logger.warn(f"stopping the wheels failed: {exc}")

    def _enable_velocity_mode(self) -> None:
        """The manual's velocity-mode start: zero targets, velocity mode, enable; then hold zero speed.

        The targets go to zero first because "enable" in velocity mode runs the wheels to the
        target registers as they stand (a quick stop or a fault leaves the old ones there).
        """
        for n, j in zip(self.wheel_names, self.wheels):
            j.write(f"target_velocity_{self._side(n)}", 0)
        self.wheels[0].write("control_mode", VELOCITY_MODE)  # one mode for the drive (both wheels)
        for j in self.wheels:
            j.enable()
        self.rig.set_velocities({n: 0.0 for n in self.wheel_names})

    # -- resets -----------------------------------------------------------------------------
    def _reset_sim(self) -> None:
        self._reset_rig()  # physics + drive to power-on; drivers forget, wheels count as disabled
        self._randomize()  # (enabling arms the configured watchdog again)
        self._enable_velocity_mode()
        self.rig.sleep(SIM_SETTLE)

    def _randomize(self) -> None:
        sim = self.rig.sim
        sim.restore()
        self.randomization_sample = None
        self._noise = 0.0
        self._noise_rng = None
        if self.randomization is None:
            return
        sample = self.randomization.sample(self.np_random, self.wheel_names)
        self.randomization_sample = sample
        noise = []
        for i, n in enumerate(self.wheel_names):
            f = sample["joints"][n]
            sim.perturb(n, armature=f["armature"], coulomb_friction=f["friction"], viscous_friction=f["friction"],
                        torque_constant=f["torque_constant"], gains={g: f[field] for field, g in GAINS.items()})
            noise.append(f["encoder_noise"])
        self._noise = float(np.mean(noise))
        self._noise_rng = np.random.default_rng(int(self.np_random.integers(2**63)))

    def _reset_hardware(self) -> None:
        rig = self.rig
        self.randomization_sample = None
        states = rig.read_states()
        faulted = [n for n in self.wheel_names if states[n].fault]
        if faulted:
            self.wheels[0].clear_faults()  # one control word clears both wheels
            states = rig.read_states()
            for n, j in zip(self.wheel_names, self.wheels):
                if states[n].fault:
                    j.check()  # still faulted: raises DeviceFault by name
        tripped = self.wheels[0].read("software_connected_status") == 0  # offline watchdog stop
        if tripped or faulted or not all(j.enabled for j in self.wheels):
            for j in self.wheels:  # "stop" then "enable": the drive leaves quick stop / disabled
                j.disable()
        self._enable_velocity_mode()
        deadline = rig.time + self.reset_timeout
        while True:
            states = rig.read_states()
            for n, j in zip(self.wheel_names, self.wheels):
                if states[n].fault:
                    j.check()
            if all(abs(states[n].velocity) < STANDSTILL for n in self.wheel_names):
                break
            if rig.time > deadline:
                speeds = {n: round(states[n].velocity, 3) for n in self.wheel_names}
                raise MotionTimeout(f"reset: the wheels did not come to rest within {self.reset_timeout} s "
                                    f"(rad/s: {speeds})")
            rig.sleep(self.control_period)

    # -- rendering --------------------------------------------------------------------------
    def _markers(self) -> list[tuple[np.ndarray, tuple[float, float, float, float]]]:
        """The goal (green) and a point 0.25 m along its heading (blue), in world coordinates."""
        gx, gy, gth = (float(v) for v in self.goal)
        pts = [(gx, gy), (gx + 0.25 * math.cos(gth), gy + 0.25 * math.sin(gth))]
        if self.sim:  # episode frame -> world
            ox, oy, oth = self._origin
            c, s = math.cos(oth), math.sin(oth)
            pts = [(ox + c * x - s * y, oy + s * x + c * y) for x, y in pts]
        return [(np.array([pts[0][0], pts[0][1], 0.05]), (0.1, 0.9, 0.2, 0.6)),
                (np.array([pts[1][0], pts[1][1], 0.05]), (0.1, 0.3, 0.9, 0.6))]

    def _scene(self) -> tuple[Any, Any]:
        if self.sim:
            return self.rig.sim.model, self.rig.sim.data
        import mujoco

        model = mujoco.MjModel.from_xml_path(str(self.rig.model_path()))
        data = mujoco.MjData(model)
        free = next(j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE)
        wheels = [int(model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, m)]) for m in self._mjcf]
        self._twin = (model, data, int(model.jnt_qposadr[free]), wheels)
        return model, data

    def _update_twin(self) -> None:
        """Hardware: pose the kinematic copy of the model at the estimate, wheels at their angles."""
        import mujoco

        assert self._twin is not None
        model, data, free, wheels = self._twin
        x, y, th = self.odometry.pose
        data.qpos[free:free + 2] = (x, y)
        data.qpos[free + 3:free + 7] = (math.cos(th / 2), 0.0, 0.0, math.sin(th / 2))
        for adr, q in zip(wheels, self._angles):
            data.qpos[adr] = q
        mujoco.mj_forward(model, data)

    # -- a scripted baseline ------------------------------------------------------------------
    def go_to_goal_action(self, obs: np.ndarray, *, k_distance: float = 1.5, k_bearing: float = 3.0,
                          k_heading: float = 2.0, max_speed: float = 0.8, max_turn: float = 3.0) -> np.ndarray:
        """A scripted controller from the observation alone (works on sim and hardware): drive to
        the goal position (forwards or backwards, whichever faces it), then turn to the goal
        heading. Returns the normalised action."""
        gx, gy = float(obs[4]), float(obs[5])  # goal in the base frame
        e = math.atan2(float(obs[7]), float(obs[6]))  # heading error
        rho = math.hypot(gx, gy)
        if rho > 0.5 * self.success_distance:
            bearing = math.atan2(gy, gx)
            forward = math.cos(bearing) >= 0.0
            steer = bearing if forward else wrap_angle(bearing + math.pi)
            v = k_distance * rho * math.cos(bearing)
            omega = k_bearing * steer
        else:
            v, omega = 0.0, k_heading * e
        v = max(-max_speed, min(max_speed, v))
        omega = max(-max_turn, min(max_turn, omega))
        w = self.wheel_speeds_of(v, omega)
        scale = max(1.0, float(np.max(np.abs(w) / self.velocity_limits)))  # keep the curvature
        return self.action_of(w / scale)
