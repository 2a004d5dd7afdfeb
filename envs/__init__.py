"""Gymnasium environments over the joints API: the same env on emulated (sim) and real (hardware) drives.

Importing ``envs`` registers, under the ``joints/`` namespace:

* ``joints/ErobReach-v0`` - one eRob joint (models/erob_stand.xml) to a random target angle
  (:class:`envs.reach.ErobReachEnv`);
* ``joints/ErobArmReach-v0`` - the 3-joint eRob arm (models/erob_arm3.xml), end effector to a
  random point (:class:`envs.reach.ErobArmReachEnv`);
* ``joints/DiffDriveGoal-v0`` - a differential-drive base on one ZLAC8015D (models/zlac_diffdrive.xml)
  to a random goal pose, wheel-speed actions, wheel odometry (:class:`envs.diffdrive.DiffDriveGoalEnv`);
* ``joints/MksAxisPosition-v0`` - the carriage of a lead-screw axis on an MKS SERVO42D
  (models/mks_linear_axis.xml) to a goal position, in metres (:class:`envs.mks_axis.MksAxisPositionEnv`).

Each id also has a ``vector_entry_point``: ``gym.make_vec(id, num_envs=N)`` (or
``envs.make_vector_env(id, N, ...)``) runs N rigs in this process, stepped together
(:class:`envs.vector.JointsVectorEnv`).

>>> import gymnasium as gym, envs
>>> env = gym.make("joints/ErobReach-v0", action_mode="torque")          # doctest: +SKIP
>>> env = gym.make("joints/ErobReach-v0", config="stand.toml", backend="hardware")  # doctest: +SKIP

Headless rendering: when ``MUJOCO_GL`` is unset, no display is available and MuJoCo is not yet
imported, importing ``envs`` sets ``MUJOCO_GL=egl`` so ``render_mode="rgb_array"`` works offscreen.
"""

from __future__ import annotations

import os
import sys

if (sys.platform.startswith("linux") and "MUJOCO_GL" not in os.environ and "mujoco" not in sys.modules
        and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY")):
    os.environ["MUJOCO_GL"] = "egl"

from gymnasium.envs.registration import register, registry

from envs.base import ACTION_MODES, JointsEnv
from envs.configs import SHIPPED, config_path, default_config
from envs.diffdrive import DiffDriveGoalEnv
from envs.factory import make_env
from envs.kinematics import erob_arm3_ee
from envs.mks_axis import MksAxisPositionEnv
from envs.randomization import DomainRandomization
from envs.reach import ErobArmReachEnv, ErobReachEnv
from envs.vector import JointsVectorEnv, make_vector_env, vector_entry_point

#: id -> (entry point, max_episode_steps): the joint-space envs (JointsEnv: one action per joint, action_mode)
ENV_IDS = {
    "joints/ErobReach-v0": ("envs.reach:ErobReachEnv", 250),
    "joints/ErobArmReach-v0": ("envs.reach:ErobArmReachEnv", 250),
}
#: id -> (entry point, max_episode_steps): mobile bases (wheel-speed actions, no action_mode)
BASE_ENV_IDS = {
    "joints/DiffDriveGoal-v0": ("envs.diffdrive:DiffDriveGoalEnv", 400),
}
#: id -> (entry point, max_episode_steps): linear axes (a joint with a lead; positions in m)
AXIS_ENV_IDS = {
    "joints/MksAxisPosition-v0": ("envs.mks_axis:MksAxisPositionEnv", 200),
}


def register_envs() -> None:
    """Register the ``joints/`` ids with gymnasium (idempotent; done on ``import envs``)."""
    for env_id, (entry_point, steps) in {**ENV_IDS, **BASE_ENV_IDS, **AXIS_ENV_IDS}.items():
        if env_id not in registry:
            register(id=env_id, entry_point=entry_point, max_episode_steps=steps,
                     vector_entry_point=vector_entry_point(entry_point))


register_envs()

__all__ = [
    "ACTION_MODES",
    "AXIS_ENV_IDS",
    "BASE_ENV_IDS",
    "ENV_IDS",
    "SHIPPED",
    "DiffDriveGoalEnv",
    "DomainRandomization",
    "ErobArmReachEnv",
    "ErobReachEnv",
    "JointsEnv",
    "JointsVectorEnv",
    "MksAxisPositionEnv",
    "config_path",
    "default_config",
    "erob_arm3_ee",
    "make_env",
    "make_vector_env",
    "register_envs",
]
