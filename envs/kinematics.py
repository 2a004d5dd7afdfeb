"""Forward kinematics of the bundled models, from joint angles alone (no MuJoCo needed).

On hardware the envs compute their task terms (the end-effector position) from the measured joint
positions with these functions; in sim they read MuJoCo's ``site_xpos`` instead, and a test checks
that both agree. Geometry transcribed from ``models/erob_arm3.xml`` (metres, radians, world frame,
z up):

* ``base`` body at z = 0.10; ``link1`` 0.12 above it turns about z (``joint1``, base yaw);
* ``link2`` 0.14 above ``link1`` turns about y (``joint2``, shoulder pitch; a positive angle
  lowers the arm: rotation about +y takes +x towards -z);
* ``link3`` 0.30 along ``link2``'s x turns about y (``joint3``, elbow pitch);
* the ``ee`` site is 0.25 along ``link3``'s x.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: erob_arm3 dimensions [m]
ARM3_SHOULDER_HEIGHT = 0.10 + 0.12 + 0.14  #: height of joint2's axis above the floor
ARM3_UPPER = 0.30  #: joint2 -> joint3
ARM3_FORE = 0.25  #: joint3 -> ee site
ARM3_REACH = ARM3_UPPER + ARM3_FORE


def erob_arm3_ee(q: Sequence[float] | np.ndarray) -> np.ndarray:
    """Position [m] of the ``ee`` site of erob_arm3 for joint angles ``q`` = (joint1, joint2, joint3) [rad]."""
    q1, q2, q3 = (float(v) for v in q)
    r = ARM3_UPPER * math.cos(q2) + ARM3_FORE * math.cos(q2 + q3)  # horizontal distance from the axis
    z = ARM3_SHOULDER_HEIGHT - ARM3_UPPER * math.sin(q2) - ARM3_FORE * math.sin(q2 + q3)
    return np.array([r * math.cos(q1), r * math.sin(q1), z])


def erob_stand_tip(q: float) -> np.ndarray:
    """Position [m] of the ``tip`` site of erob_stand for the joint angle ``q`` [rad]."""
    return np.array([0.3 * math.cos(q), 0.3 * math.sin(q), 0.2 + 0.13 + 0.05])
