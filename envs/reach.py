"""joints/ErobReach-v0 and joints/ErobArmReach-v0: reach tasks on eRob drives."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

import joints
from envs.base import JointsEnv
from envs.kinematics import (
    ARM3_FORE,
    ARM3_REACH,
    ARM3_SHOULDER_HEIGHT,
    ARM3_UPPER,
    erob_arm3_clearance,
    erob_arm3_clears,
    erob_arm3_ee,
    erob_arm3_falls_short,
    erob_stand_tip,
)
from envs.render import CameraSpec


def _range(name: str, r: Sequence[float], lo: float, hi: float) -> tuple[float, float]:
    """``r`` intersected with the limits ``[lo, hi]``; must not be empty."""
    if len(r) != 2 or not all(math.isfinite(v) for v in r) or r[0] > r[1]:
        raise ValueError(f"{name} must be (low, high) with low <= high, got {r!r}")
    a, b = max(float(r[0]), lo), min(float(r[1]), hi)
    if a > b:
        raise ValueError(f"{name} {tuple(r)} lies outside the joint limits [{lo}, {hi}]")
    return a, b


class ErobReachEnv(JointsEnv):
    """Turn one eRob joint to a random target angle.

    ## Description
    One ZeroErr eRob80H100 on a test stand (``models/erob_stand.xml``: vertical axis, a load arm
    with 1.8 kg, no gravity torque) is driven over Modbus RTU - emulated in MuJoCo with the sim
    backend, or a real drive with the hardware backend, from the same config. The agent turns
    the joint to a target angle drawn at every reset.

    ## Action Space
    ``Box(-1, 1, (1,), float32)``, the meaning set by ``action_mode``:

    | action_mode | command | unit |
    |---|---|---|
    | ``"position"`` (default) | target angle ``lo + (a+1)/2 (hi-lo)`` over the position limits, reached with the drive's own trapezoidal profile (config ``motion``) | rad |
    | ``"velocity"`` | speed ``a x limits.velocity`` | rad/s |
    | ``"torque"`` | torque ``a x limits.torque`` | N*m |

    ``env.unwrapped.command_of(a)`` / ``action_of(si)`` convert. The default config has limits
    position [-3, 3] rad, velocity 2 rad/s, torque 35 N*m (what the drive sustains on this stand
    without tripping a protection) and the profile 2 rad/s, 10 rad/s^2. The drive holds the
    command for the control period (zero-order hold, ``dt`` = 20 ms by default).

    No action can fault the drive: position targets are reached with the drive's own profile (a
    new target while moving included), velocity commands are capped near a position limit at the
    speed the drive's ramp can stop from on the limit (:meth:`envs.JointsEnv.safe_command`; the
    whole range stays reachable; ``info["command"]`` is what was sent).

    ## Observation Space
    ``Box(float64, (5,))``:

    | index | observation | unit | bounds (default config) |
    |---|---|---|---|
    | 0 | joint position | rad | [-3.5, 3.5] (limits +- 0.5) |
    | 1 | joint velocity | rad/s | [-4, 4] (+- 2 x velocity limit) |
    | 2 | joint torque (drive's estimate from its current) | N*m | [-70, 70] (+- 2 x torque limit) |
    | 3 | target angle | rad | position limits |
    | 4 | target - position | rad | +- (hi - lo) |

    Values are clipped to the bounds. With domain randomisation, index 0 carries encoder noise.

    ## Rewards
    ``reward = reward_distance + reward_action_rate`` (both in ``info``):

    - ``reward_distance = -|target - position|`` [rad];
    - ``reward_action_rate = -action_rate_weight * sum((a_t - a_{t-1})^2)``: smooth commands.

    ``info`` also holds ``distance`` [rad], ``is_success`` (``distance < success_tolerance``),
    ``time`` [s] (sim: simulated seconds since reset), ``faults`` (joint -> the drive's fault by
    name, None = none), ``limit_violation``, ``command`` (the SI command sent this step) and, when
    a drive reports a fault, ``fault`` (``joint``, ``name``, ``code``, ``text``, ``clears``).

    ## Starting State
    Sim: physics and the emulated drive at power-on, the joint at rest at an angle uniform in
    ``start_range`` (seeded), then enabled and held for the drive's 500 ms (the first observation
    is at t = 0.5 s). Hardware: the joint is enabled and moved to the drawn angle with a safe
    profile (``reset_velocity``, ``reset_acceleration``), and the env waits for standstill.
    The target is uniform in ``target_range``. ``reset(options={"start": [q], "target": t})``
    fixes either.

    ## Episode End
    - Termination: the drive reports a fault (``info["fault"]``; ``reset()`` clears it: sim power
      cycle, hardware clear + enable), or the joint passes its position limits by more than
      0.05 rad (torque actions only can drive it there; the env then stops the joint).
    - Truncation: 250 steps (10 s at the default control period of 40 ms), by the registered
      ``max_episode_steps``.
    The env does not end an episode on success: hold the target.

    ## Arguments
    ``gymnasium.make("joints/ErobReach-v0", config=None, backend=None, action_mode="position",
    control_period=0.04, render_mode=None, domain_randomization=False, target_range=(-2.5, 2.5),
    start_range=(-1.0, 1.0), success_tolerance=0.02, action_rate_weight=0.01, ...)``

    - ``config``: joints config (TOML path or dict) with one joint; default the shipped
      ``joints/configs/erob_reach.toml``. ``backend``: ``"sim"`` | ``"hardware"``, overrides it.
    - ``action_mode``, ``control_period``, ``render_mode`` (``"rgb_array"``, ``"human"``),
      ``domain_randomization`` (see :mod:`envs.randomization`), hardware reset profile
      ``reset_velocity`` [rad/s], ``reset_acceleration`` [rad/s^2], ``reset_timeout`` [s],
      ``reset_tolerance`` [rad]; ``width``/``height`` of rgb_array frames: see :class:`envs.JointsEnv`.
    - ``target_range``, ``start_range`` [rad], intersected with the position limits.
    - ``success_tolerance`` [rad], ``action_rate_weight``.

    ## Version History
    - v0: initial version (eRob over Modbus RTU; sim and hardware backends).
    """

    default_config = "erob_reach"
    #: 25 Hz: one cycle (position command + state read) takes 24.6 ms of the RS485 bus at 115200 baud,
    #: 61 % of 40 ms (50 Hz would need 123 %; docs/timing.md)
    default_control_period = 0.04
    camera = CameraSpec(lookat=(0.1, 0.0, 0.35), distance=1.1, azimuth=135.0, elevation=-40.0)

    def __init__(
        self,
        config: Any = None,
        backend: str | None = None,
        *,
        target_range: Sequence[float] = (-2.5, 2.5),
        start_range: Sequence[float] = (-1.0, 1.0),
        success_tolerance: float = 0.02,
        action_rate_weight: float = 0.01,
        **kwargs: Any,
    ) -> None:
        self._target_range_arg = tuple(target_range)
        self._start_range_arg = tuple(start_range)
        if not math.isfinite(success_tolerance) or success_tolerance <= 0:
            raise ValueError(f"success_tolerance must be > 0 rad, got {success_tolerance!r}")
        if not math.isfinite(action_rate_weight) or action_rate_weight < 0:
            raise ValueError(f"action_rate_weight must be >= 0, got {action_rate_weight!r}")
        self.success_tolerance = float(success_tolerance)
        self.action_rate_weight = float(action_rate_weight)
        self.target = 0.0
        super().__init__(config, backend, **kwargs)

    def _select_joints(self, rig: joints.Rig) -> list[str]:
        if len(rig.joints) != 1:
            raise joints.ConfigError(f"ErobReach drives exactly one joint, the config has {list(rig.joints)}",
                                     file=rig.config.source, key="joints")
        return list(rig.joints)

    def _task_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = (float(v) for v in self.position_limits[0])
        self.target_range = _range("target_range", self._target_range_arg, lo, hi)
        self.start_range = _range("start_range", self._start_range_arg, lo, hi)
        span = hi - lo
        return np.array([lo, -span]), np.array([hi, span])

    def _sample_start(self, options: Mapping[str, Any]) -> np.ndarray:
        if "start" in options:
            return np.asarray(options["start"], dtype=np.float64).reshape(-1)
        return np.array([self.np_random.uniform(*self.start_range)])

    def _sample_target(self, options: Mapping[str, Any]) -> None:
        if "target" in options:
            t = float(np.asarray(options["target"], dtype=np.float64).reshape(-1)[0])
            lo, hi = self.position_limits[0]
            if not (math.isfinite(t) and lo <= t <= hi):
                raise ValueError(f"target {t} rad is outside the position limits [{lo}, {hi}]")
            self.target = t
        else:
            self.target = float(self.np_random.uniform(*self.target_range))

    def _task_terms(self, positions: list[float]) -> list[float]:
        return [self.target, self.target - positions[0]]

    def _markers(self) -> list[tuple[np.ndarray, tuple[float, float, float, float]]]:
        return [(erob_stand_tip(self._to_model(0, self.target)), (0.1, 0.9, 0.2, 0.6))]

    @staticmethod
    def _batch_task(envs: Sequence[Any], positions: np.ndarray, change: np.ndarray, terms: np.ndarray
                    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """:meth:`_task_terms` and :meth:`_reward` of a batch's rigs, their operations across the rigs."""
        target = np.array([e.target for e in envs])
        terms[:, 0] = target
        to_target = np.subtract(target, positions[:, 0], out=terms[:, 1])
        distance = np.abs(to_target)
        r_dist = -distance
        r_rate = -np.array([e.action_rate_weight for e in envs]) * change
        return r_dist + r_rate, {
            "reward_distance": r_dist,
            "reward_action_rate": r_rate,
            "distance": distance,
            "is_success": distance < np.array([e.success_tolerance for e in envs]),
        }

    def _reward(self, positions: list[float], action_change: float) -> tuple[float, dict[str, Any]]:
        distance = abs(self.target - positions[0])
        r_dist = -distance
        r_rate = -self.action_rate_weight * action_change
        return r_dist + r_rate, {
            "reward_distance": r_dist,
            "reward_action_rate": r_rate,
            "distance": distance,
            "is_success": distance < self.success_tolerance,
        }


class ErobArmReachEnv(JointsEnv):
    """Bring the end effector of a 3-joint eRob arm to a random point.

    ## Description
    The arm of ``models/erob_arm3.xml`` under gravity: ``joint1`` base yaw (eRob80H100),
    ``joint2`` shoulder pitch (eRob80H100), ``joint3`` elbow pitch (eRob70H100); upper arm
    0.30 m, forearm 0.25 m to the ``ee`` site, shoulder 0.36 m above the floor. Each joint is an
    eRob drive on one Modbus RTU bus - emulated in sim, or real with the hardware backend from
    the same config. The agent moves the end effector to a target point drawn at every reset.

    ## Action Space
    ``Box(-1, 1, (3,), float32)``, one entry per joint (joint1, joint2, joint3), meaning set by
    ``action_mode`` as in :class:`ErobReachEnv`: ``"position"`` (default; target angle over the
    position limits, drive's own profile), ``"velocity"`` (``a x limits.velocity`` rad/s) or
    ``"torque"`` (``a x limits.torque`` N*m; the agent must then carry the arm against gravity).
    Default limits: position joint1 [-3, 3], joint2 [-1.6, 0.8], joint3 [-2.4, 2.4] rad; velocity
    2, 1.2, 3 rad/s; torque 35, 35, 20 N*m (what the drives sustain on this arm without tripping a
    protection, see the shipped config). Position and velocity commands are also kept from driving
    a link into the floor or the base (:meth:`ErobArmReachEnv._shield`, 2 cm of clearance); every
    other pose within the limits stays reachable.

    ## Observation Space
    ``Box(float64, (18,))``:

    | index | observation | unit | bounds |
    |---|---|---|---|
    | 0-2 | joint positions | rad | limits +- 0.5 |
    | 3-5 | joint velocities | rad/s | +- 2 x velocity limit |
    | 6-8 | joint torques (drives' estimates) | N*m | +- 2 x torque limit |
    | 9-11 | end-effector position x, y, z | m | x, y in [-0.6, 0.6]; z in [-0.25, 0.95] |
    | 12-14 | target position x, y, z | m | same |
    | 15-17 | target - end effector | m | [-1.2, 1.2] |

    The end effector is MuJoCo's ``ee`` site in sim and the forward kinematics of the measured
    joint angles on hardware (:func:`envs.kinematics.erob_arm3_ee`; they agree in sim). Values are
    clipped to the bounds.

    ## Rewards
    ``reward = reward_distance + reward_action_rate``: ``-||target - ee||`` [m] and
    ``-action_rate_weight * sum((a_t - a_{t-1})^2)``. ``info`` also holds ``distance`` [m],
    ``is_success`` (``distance < success_tolerance``), ``time``, ``faults``, ``limit_violation``,
    ``command``, and ``fault`` when a drive reports one (as in :class:`ErobReachEnv`).

    ## Starting State
    Sim: physics and the drives at power-on, the joints at rest at angles uniform in
    ``start_ranges`` (seeded), enabled and held for the drives' 500 ms (the brakes hold the arm
    meanwhile). Hardware: enable, move to the drawn pose with a safe profile, wait for standstill.
    The target is the ``ee`` position of joint angles drawn uniformly in ``target_ranges``,
    redrawn until it is at least 0.10 m above the floor and 0.15 m from the base axis and the pose
    keeps the arm's clearance (so it is
    reachable). ``reset(options={"start": [q1, q2, q3], "target": [x, y, z]})`` fixes either.

    ## Episode End
    - Termination: a drive fault (``info["fault"]``; cleared by ``reset()``), or a joint past its
      position limits by more than 0.05 rad (torque actions only).
    - Truncation: 250 steps (25 s at the default control period of 100 ms).

    ## Arguments
    ``gymnasium.make("joints/ErobArmReach-v0", config=None, backend=None, action_mode="position",
    control_period=0.1, render_mode=None, domain_randomization=False,
    start_ranges=((-0.5, 0.5), (-0.6, 0.0), (0.3, 1.2)),
    target_ranges=((-2.0, 2.0), (-1.0, 0.3), (-1.2, 1.2)), success_tolerance=0.02,
    action_rate_weight=0.01, ...)``; the common arguments as in :class:`ErobReachEnv`. The config
    needs three joints whose ``mjcf_joint`` are joint1, joint2, joint3 of ``erob_arm3.xml``
    (default: the shipped ``joints/configs/erob_arm_reach.toml``).

    ## Version History
    - v0: initial version.
    """

    default_config = "erob_arm_reach"
    #: 10 Hz: one cycle of three joints takes 73.7 ms of the RS485 bus at 115200 baud, 74 % of 100 ms
    #: (50 Hz would need 369 %; CANopen at 1 Mbit/s carries 40 Hz: docs/timing.md)
    default_control_period = 0.1
    camera = CameraSpec(lookat=(0.1, 0.0, 0.3), distance=1.8, azimuth=135.0, elevation=-25.0)
    MODEL_JOINTS = ("joint1", "joint2", "joint3")
    MIN_HEIGHT = 0.10  #: m, lowest target
    MIN_RADIUS = 0.15  #: m, closest target to the base axis
    #: m the links keep from the floor, the base and link1 (:meth:`_shield`)
    CLEARANCE = 0.02
    #: boxes :meth:`keeps_clearance` bounds before it evaluates the grid
    BOUNDS = 16
    #: rad between the shoulder/elbow poses at which the clearance is checked (<= 9 mm of gap)
    GRID = 0.02

    def __init__(
        self,
        config: Any = None,
        backend: str | None = None,
        *,
        start_ranges: Sequence[Sequence[float]] = ((-0.5, 0.5), (-0.6, 0.0), (0.3, 1.2)),
        target_ranges: Sequence[Sequence[float]] = ((-2.0, 2.0), (-1.0, 0.3), (-1.2, 1.2)),
        success_tolerance: float = 0.02,
        action_rate_weight: float = 0.01,
        **kwargs: Any,
    ) -> None:
        if len(start_ranges) != 3 or len(target_ranges) != 3:
            raise ValueError("start_ranges and target_ranges need one (low, high) per joint (3)")
        if not math.isfinite(success_tolerance) or success_tolerance <= 0:
            raise ValueError(f"success_tolerance must be > 0 m, got {success_tolerance!r}")
        if not math.isfinite(action_rate_weight) or action_rate_weight < 0:
            raise ValueError(f"action_rate_weight must be >= 0, got {action_rate_weight!r}")
        self._ranges_arg = (tuple(map(tuple, start_ranges)), tuple(map(tuple, target_ranges)))
        self.success_tolerance = float(success_tolerance)
        self.action_rate_weight = float(action_rate_weight)
        self.target = np.zeros(3)
        self._ee = [0.0, 0.0, 0.0]  #: the end effector of the last observation [m]
        self._to_target = [0.0, 0.0, 0.0]  #: target - end effector [m]
        super().__init__(config, backend, **kwargs)
        if self.sim:
            mj = self.rig.world.mujoco
            self._site = mj.mj_name2id(self.rig.world.model, mj.mjtObj.mjOBJ_SITE, "ee")
            if self._site < 0:
                self.close()
                raise joints.ConfigError("the model has no site 'ee'", file=self.rig.config.source, key="sim.model")

    @property
    def target(self) -> np.ndarray:
        """The episode's target point [m] (read-only: set the whole point, e.g. ``reset(options={"target": ...})``)."""
        return self._target

    @target.setter
    def target(self, point: Sequence[float] | np.ndarray) -> None:
        self._target = np.array(point, dtype=np.float64)  # a copy of its own
        self._target.flags.writeable = False
        self._target_list: list[float] = self._target.tolist()  #: its floats, for the per-step task terms

    def _select_joints(self, rig: joints.Rig) -> list[str]:
        by_model = {(c.mjcf_joint or n): n for n, c in rig.config.joints.items()}
        if len(rig.joints) != 3 or any(m not in by_model for m in self.MODEL_JOINTS):
            raise joints.ConfigError(
                "ErobArmReach drives three joints mapped to the MJCF joints joint1, joint2, joint3 of erob_arm3.xml; "
                f"the config maps {by_model}", file=rig.config.source, key="joints")
        return [by_model[m] for m in self.MODEL_JOINTS]

    def _task_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lim = self.position_limits
        starts, targets = self._ranges_arg
        self.start_ranges = [_range(f"start_ranges[{i}]", r, *lim[i]) for i, r in enumerate(starts)]
        self.target_ranges = [_range(f"target_ranges[{i}]", r, *lim[i]) for i, r in enumerate(targets)]
        r = ARM3_REACH + 0.05
        p_lo = np.array([-r, -r, ARM3_SHOULDER_HEIGHT - ARM3_REACH - 0.06])
        p_hi = np.array([r, r, ARM3_SHOULDER_HEIGHT + ARM3_REACH + 0.04])
        d = 2 * r
        return (np.concatenate([p_lo, p_lo, [-d] * 3]), np.concatenate([p_hi, p_hi, [d] * 3]))

    def _sample_start(self, options: Mapping[str, Any]) -> np.ndarray:
        if "start" in options:
            return np.asarray(options["start"], dtype=np.float64).reshape(-1)
        return np.array([self.np_random.uniform(*r) for r in self.start_ranges])

    def _sample_target(self, options: Mapping[str, Any]) -> None:
        if "target" in options:
            t = np.asarray(options["target"], dtype=np.float64).reshape(-1)
            if t.shape != (3,) or not np.all(np.isfinite(t)):
                raise ValueError(f"target must be a finite point [x, y, z] in m, got {options['target']!r}")
            self.target = t
            return
        for _ in range(1000):
            q = self._to_model_all(np.array([self.np_random.uniform(*r) for r in self.target_ranges]))
            p = erob_arm3_ee(q)
            if p[2] >= self.MIN_HEIGHT and math.hypot(p[0], p[1]) >= self.MIN_RADIUS \
                    and float(erob_arm3_clearance(q[1], q[2])) >= self.CLEARANCE:
                self.target = p
                return
        raise ValueError("target_ranges give no reachable target above the floor; widen them")

    def _to_model_all(self, positions: np.ndarray) -> np.ndarray:
        return np.array([self._to_model(i, float(q)) for i, q in enumerate(positions)])

    def end_effector(self, positions: np.ndarray | None = None) -> np.ndarray:
        """End-effector position [m]: MuJoCo's ``ee`` site in sim, forward kinematics on hardware
        (or of ``positions`` [rad] when given)."""
        if positions is None and self.sim:
            return np.array(self.rig.world.data.site_xpos[self._site])
        if positions is None:
            positions = np.array([s.position for s in self._states])
        return erob_arm3_ee(self._to_model_all(np.asarray(positions, dtype=np.float64)))

    def _markers(self) -> list[tuple[np.ndarray, tuple[float, float, float, float]]]:
        return [(self.target, (0.1, 0.9, 0.2, 0.6))]

    # -- safety -----------------------------------------------------------------------------
    def clearance(self, lo: Sequence[float], hi: Sequence[float]) -> float:
        """Smallest gap [m] between the arm and the floor / its base over every pose with joint2,
        joint3 (user frame, rad) anywhere in ``[lo, hi]`` (per joint; joint1 does not matter):
        :func:`~envs.kinematics.erob_arm3_clearance` on a grid of :attr:`GRID` rad."""
        axes = []
        for i in (1, 2):
            j = self.joints[i]
            n = max(2, math.ceil((hi[i] - lo[i]) / self.GRID) + 1)
            axes.append((np.linspace(lo[i], hi[i], n) - j.offset) * j.direction)  # user -> model frame
        return float(erob_arm3_clearance(axes[0][:, None], axes[1][None, :]).min())

    def keeps_clearance(self, lo: Sequence[float], hi: Sequence[float]) -> bool:
        """Whether every pose with joint2, joint3 (user frame, rad) in ``[lo, hi]`` keeps
        :attr:`CLEARANCE`; the same answer as ``clearance(lo, hi) >= CLEARANCE``, usually without
        its grid: around the box's centre a link point moves at most ``ARM3_REACH * |dq2| +
        ARM3_FORE * |dq3|``, so the exact gap at the centre (a lower bound of the grid's sampled
        one) minus that is a lower bound over the whole box. Where that cannot tell, the box is halved
        (along the joint that moves the links more) and each half bounded the same way, up to
        :attr:`BOUNDS` bounds; only where they cannot tell either is the grid evaluated, unless a corner or
        the middle of the grid surely falls short (:meth:`_short_on_grid`: False, as the grid answers). A bound
        only ever answers True where every grid pose keeps the gap, so the answer is the grid's."""
        return self._keeps(float(lo[1]), float(hi[1]), float(lo[2]), float(hi[2]))

    def _keeps(self, lo2: float, hi2: float, lo3: float, hi3: float) -> bool:
        """:meth:`keeps_clearance` of the box joint2 in ``[lo2, hi2]``, joint3 in ``[lo3, hi3]``."""
        j2, j3 = self.joints[1], self.joints[2]
        o2, d2, o3, d3 = j2.offset, j2.direction, j3.offset, j3.direction
        need = self.CLEARANCE
        boxes = [(lo2, hi2, lo3, hi3)]
        bounds = 0
        while boxes:
            a2, b2, a3, b3 = boxes.pop()
            q2 = ((a2 + b2) / 2 - o2) * d2  # user -> model frame
            q3 = ((a3 + b3) / 2 - o3) * d3
            span2, span3 = ARM3_REACH * abs(b2 - a2), ARM3_FORE * abs(b3 - a3)
            bounds += 1
            # each term of erob_arm3_clearance_bound(q2, q3), less how far its link moves over the box, - 1e-9
            # >= CLEARANCE: the forearm's (span2 / 2 + span3 / 2), the upper arm's and the elbow's less
            if erob_arm3_clears(q2, q3, span2 / 2 + span3 / 2, need, ARM3_UPPER * abs(b2 - a2) / 2):
                continue
            if bounds >= self.BOUNDS:
                return not self._short_on_grid(lo2, hi2, lo3, hi3) \
                    and self.clearance((0.0, lo2, lo3), (0.0, hi2, hi3)) >= need
            if span2 >= span3:
                m = (a2 + b2) / 2
                boxes += [(a2, m, a3, b3), (m, b2, a3, b3)]
            else:
                m = (a3 + b3) / 2
                boxes += [(a2, b2, a3, m), (a2, b2, m, b3)]
        return True

    def _short_on_grid(self, lo2: float, hi2: float, lo3: float, hi3: float) -> bool:
        """Whether a corner or the middle of :meth:`clearance`'s grid over the box surely falls short of
        :attr:`CLEARANCE` (:func:`~envs.kinematics.erob_arm3_falls_short`): the grid's answer, without the grid
        (most boxes the bounds cannot tell are ones that do not keep the gap)."""
        axes = []
        for i, (lo, hi) in ((1, (lo2, hi2)), (2, (lo3, hi3))):
            j = self.joints[i]
            n = max(2, math.ceil((hi - lo) / self.GRID) + 1)
            axes.append(((np.linspace(lo, hi, n) - j.offset) * j.direction).tolist())  # as clearance() has them
        (a, b) = axes
        for q2, q3 in ((a[0], b[0]), (a[-1], b[-1]), (a[0], b[-1]), (a[-1], b[0]), (a[len(a) // 2], b[len(b) // 2])):
            if erob_arm3_falls_short(q2, q3, self.CLEARANCE):
                return True
        return False

    def _shield(self, command: list[float]) -> list[float]:
        """Keep the arm :attr:`CLEARANCE` off the floor and its base: the shoulder and elbow commands
        go out as asked if every pose they can lead to within the next period - and while stopping
        after it - keeps the gap (:meth:`~envs.base.JointsEnv._reach`); else the shoulder, or the
        elbow, or both are stopped instead (the first of these that keeps it: a joint that moves
        away from the obstacle goes on while the other waits). Torque commands are not predicted
        and go out as they are.

        Poses in contact are not reachable anyway; the 2 cm cover the grid and the joints' tracking
        of their profiles. Every other pose in the position limits stays reachable.
        """
        if self.action_mode == "torque":
            return command
        # the shoulder's and the elbow's reach (joint1 does not matter), for their command and their stop
        dt = self.control_period + self.bus_lag
        acc = self._acc_list
        velocity = self.action_mode == "velocity"
        dec = acc if velocity else self._dec_list
        cruise = self._cruise_list
        states = self._states
        reach = self._joint_reach
        go = [reach(states[i].position, states[i].velocity, command[i], dt, acc[i], dec[i], cruise[i], velocity)
              for i in (1, 2)]
        stops: list[float] = []
        halt: list[tuple[float, float]] = []
        c = command
        for hold in ((), (1,), (2,), (1, 2)):
            if hold and not stops:
                stops = [self._stop_command(1), self._stop_command(2)]
                halt = [reach(states[i].position, states[i].velocity, stops[i - 1], dt, acc[i], dec[i], cruise[i],
                              velocity) for i in (1, 2)]
            (a2, b2), (a3, b3) = (halt[0] if 1 in hold else go[0]), (halt[1] if 2 in hold else go[1])
            c = list(command)
            for i in hold:
                c[i] = stops[i - 1]
            if self._keeps(a2, b2, a3, b3):
                return c
        return c  # nothing keeps it (the arm is there already): stop both

    def _task_terms(self, positions: list[float]) -> list[float]:
        ee: list[float]
        if self.sim:
            ee = self.rig.world.data.site_xpos[self._site].tolist()
        else:
            ee = self.end_effector(np.array(positions)).tolist()
        target = self._target_list
        to_target = [t - e for t, e in zip(target, ee)]  # the arrays' subtraction, element by element
        self._ee = ee
        self._to_target = to_target
        return ee + target + to_target

    def _reward(self, positions: list[float], action_change: float) -> tuple[float, dict[str, Any]]:
        d = np.array(self._to_target)
        distance = math.sqrt(d.dot(d))  # np.linalg.norm of a vector, as it computes it: sqrt(x.dot(x))
        r_dist = -distance
        r_rate = -self.action_rate_weight * action_change
        return r_dist + r_rate, {
            "reward_distance": r_dist,
            "reward_action_rate": r_rate,
            "distance": distance,
            "is_success": distance < self.success_tolerance,
        }
