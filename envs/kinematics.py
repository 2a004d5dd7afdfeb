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

Collision geometry of erob_arm3 (for :func:`erob_arm3_clearance`): the floor (z = 0); ``base`` a
cylinder of radius 0.07 from z = 0 to 0.20 and ``link1`` one of radius 0.05 from z = 0.22 to
0.34, both about the yaw axis; ``link2`` (upper arm) a capsule of radius 0.035 from the shoulder to
the elbow; ``link3`` a cylinder of radius 0.045 across the elbow and a capsule of radius 0.03 from
the elbow to ``ee``. MuJoCo skips parent-child pairs, so the pairs that can touch are the floor,
base and link1 against the forearm, and the floor and base against the upper arm. Joint1 turns
everything about the axis of the two cylinders, so distances are taken in the arm's vertical
plane (x: along the arm from the yaw axis, z: up), where each cylinder is a rectangle.
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
#: erob_arm3 obstacles in the arm's plane: (half width |x|, z low, z high) [m] of ``base`` and ``link1``
ARM3_COLUMNS = ((0.07, 0.0, 0.20), (0.05, 0.22, 0.34))
ARM3_UPPER_RADIUS = 0.035  #: m, link2 capsule
ARM3_ELBOW_RADIUS = 0.045  #: m, link3 cylinder across the elbow
ARM3_FORE_RADIUS = 0.03  #: m, link3 capsule
_SAMPLES = 16  #: points per arm segment (the segments are at most 0.30 m: 2 cm apart)


def erob_arm3_ee(q: Sequence[float] | np.ndarray) -> np.ndarray:
    """Position [m] of the ``ee`` site of erob_arm3 for joint angles ``q`` = (joint1, joint2, joint3) [rad]."""
    q1, q2, q3 = (float(v) for v in q)
    r = ARM3_UPPER * math.cos(q2) + ARM3_FORE * math.cos(q2 + q3)  # horizontal distance from the axis
    z = ARM3_SHOULDER_HEIGHT - ARM3_UPPER * math.sin(q2) - ARM3_FORE * math.sin(q2 + q3)
    return np.array([r * math.cos(q1), r * math.sin(q1), z])


def erob_stand_tip(q: float) -> np.ndarray:
    """Position [m] of the ``tip`` site of erob_stand for the joint angle ``q`` [rad]."""
    return np.array([0.3 * math.cos(q), 0.3 * math.sin(q), 0.2 + 0.13 + 0.05])


def _column_distance(x: np.ndarray, z: np.ndarray, half: float, z0: float, z1: float) -> np.ndarray:
    """Distance [m] of points (x, z) of the arm's plane from the rectangle |x| <= half, z0 <= z <= z1."""
    dx = np.maximum(np.abs(x) - half, 0.0)
    dz = np.maximum(np.maximum(z0 - z, z - z1), 0.0)
    out: np.ndarray = np.hypot(dx, dz)
    return out


def erob_arm3_clearance(q2: np.ndarray | float, q3: np.ndarray | float) -> np.ndarray:
    """Smallest gap [m] between the moving links of erob_arm3 and the floor, ``base`` and ``link1``
    for shoulder / elbow angles ``q2``, ``q3`` [rad] (model frame; any broadcastable shapes);
    negative where they overlap. Joint1 does not change it.

    The links are sampled every 2 cm along their axes, so the gap may read up to ~1.5 mm too large
    where a column's corner meets a link between two samples.
    """
    b2, b3 = np.broadcast_arrays(np.asarray(q2, dtype=np.float64), np.asarray(q3, dtype=np.float64))
    a2, a3 = b2[..., None], b3[..., None]
    s = np.linspace(0.0, 1.0, _SAMPLES)
    # upper arm: shoulder (0, h) -> elbow
    ux = s * ARM3_UPPER * np.cos(a2)
    uz = ARM3_SHOULDER_HEIGHT - s * ARM3_UPPER * np.sin(a2)
    ex, ez = ux[..., -1:], uz[..., -1:]
    # forearm: elbow -> ee
    fx = ex + s * ARM3_FORE * np.cos(a2 + a3)
    fz = ez - s * ARM3_FORE * np.sin(a2 + a3)
    base, link1 = ARM3_COLUMNS
    gaps = [
        uz.min(axis=-1) - ARM3_UPPER_RADIUS,  # upper arm - floor
        _column_distance(ux, uz, *base).min(axis=-1) - ARM3_UPPER_RADIUS,
        ez[..., 0] - ARM3_ELBOW_RADIUS,  # elbow - floor
        _column_distance(ex, ez, *base)[..., 0] - ARM3_ELBOW_RADIUS,
        _column_distance(ex, ez, *link1)[..., 0] - ARM3_ELBOW_RADIUS,
        fz.min(axis=-1) - ARM3_FORE_RADIUS,  # forearm - floor
        _column_distance(fx, fz, *base).min(axis=-1) - ARM3_FORE_RADIUS,
        _column_distance(fx, fz, *link1).min(axis=-1) - ARM3_FORE_RADIUS,
    ]
    out: np.ndarray = np.minimum.reduce(gaps)
    return out


def _point_column(x: float, z: float, half: float, z0: float, z1: float) -> float:
    return math.hypot(max(abs(x) - half, 0.0), max(z0 - z, z - z1, 0.0))


def _point_segment(x: float, z: float, px: float, pz: float, dx: float, dz: float) -> float:
    n = dx * dx + dz * dz
    t = 0.0 if n == 0.0 else min(1.0, max(0.0, ((x - px) * dx + (z - pz) * dz) / n))
    return math.hypot(x - px - t * dx, z - pz - t * dz)


def _segment_column(px: float, pz: float, qx: float, qz: float, half: float, z0: float, z1: float) -> float:
    """Exact distance [m] of the segment P-Q of the arm's plane from the rectangle |x| <= half, z0 <= z <= z1.

    Written out for speed (the env's per-step safety check): the same IEEE operations in the same order
    as :func:`_point_column` and :func:`_point_segment` (``max(a, b)`` is ``b if b > a else a``,
    ``min(a, b)`` is ``b if b < a else a``, NaN included)."""
    dx, dz = qx - px, qz - pz
    t0, t1 = 0.0, 1.0  # Liang-Barsky: the part of the segment inside the rectangle
    for p, q in ((-dx, px + half), (dx, half - px), (-dz, pz - z0), (dz, z1 - pz)):
        if p == 0.0:
            if q < 0.0:
                break
        elif p < 0.0:
            r = q / p
            t0 = r if r > t0 else t0  # noqa: FURB136 - max(t0, r) without a call
        else:
            r = q / p
            t1 = r if r < t1 else t1  # noqa: FURB136 - min(t1, r) without a call
        if t0 > t1:
            break
    else:
        return 0.0  # they meet
    hypot = math.hypot
    # the two ends, as _point_column
    a, b, c = abs(px) - half, z0 - pz, pz - z1
    b = c if c > b else b  # noqa: FURB136 - max(b, c)
    best = hypot(0.0 if 0.0 > a else a, 0.0 if 0.0 > b else b)  # noqa: FURB136 - max(a, 0.0), max(b, 0.0)
    a, b, c = abs(qx) - half, z0 - qz, qz - z1
    b = c if c > b else b  # noqa: FURB136
    d = hypot(0.0 if 0.0 > a else a, 0.0 if 0.0 > b else b)  # noqa: FURB136
    best = d if d < best else best  # noqa: FURB136 - min(best, d)
    # the four corners, as _point_segment
    n = dx * dx + dz * dz
    for cx, cz in ((-half, z0), (half, z0), (-half, z1), (half, z1)):
        if n == 0.0:
            t = 0.0
        else:
            t = ((cx - px) * dx + (cz - pz) * dz) / n
            t = t if t > 0.0 else 0.0  # noqa: FURB136 - max(0.0, t)
            t = t if t < 1.0 else 1.0  # noqa: FURB136 - min(1.0, t)
        d = hypot(cx - px - t * dx, cz - pz - t * dz)
        best = d if d < best else best  # noqa: FURB136
    return best


def erob_arm3_clearance_bound(q2: float, q3: float) -> float:
    """A lower bound [m] of :func:`erob_arm3_clearance` at one pose: the same pairs, with exact
    distances of the links' axes instead of samples along them (0 where an axis meets an obstacle,
    so never above the true gap); scalar and numpy-free, for the env's per-step safety check."""
    h, base, link1 = ARM3_SHOULDER_HEIGHT, ARM3_COLUMNS[0], ARM3_COLUMNS[1]
    ex, ez = ARM3_UPPER * math.cos(q2), h - ARM3_UPPER * math.sin(q2)
    fx, fz = ex + ARM3_FORE * math.cos(q2 + q3), ez - ARM3_FORE * math.sin(q2 + q3)
    return min(
        min(h, ez) - ARM3_UPPER_RADIUS,  # upper arm - floor
        _segment_column(0.0, h, ex, ez, *base) - ARM3_UPPER_RADIUS,
        ez - ARM3_ELBOW_RADIUS,  # elbow - floor
        _point_column(ex, ez, *base) - ARM3_ELBOW_RADIUS,
        _point_column(ex, ez, *link1) - ARM3_ELBOW_RADIUS,
        min(ez, fz) - ARM3_FORE_RADIUS,  # forearm - floor
        _segment_column(ex, ez, fx, fz, *base) - ARM3_FORE_RADIUS,
        _segment_column(ex, ez, fx, fz, *link1) - ARM3_FORE_RADIUS,
    )


#: m the shield's bound gives away for rounding (:meth:`envs.reach.ErobArmReachEnv.keeps_clearance`)
BOUND_SLACK = 1e-9


def erob_arm3_clears(q2: float, q3: float, less: float, need: float, less_upper: float | None = None) -> bool:
    """``erob_arm3_clearance_bound(q2, q3) - less - BOUND_SLACK >= need``, the same answer for every input,
    faster: each of the bound's terms is computed by the same IEEE operations, and since ``t - less - slack``
    never decreases as ``t`` grows, the smallest term passes exactly when every term passes - so the cheap
    terms go first and the first that fails ends it. (``min()`` keeps a NaN only as its first argument, the
    upper arm - floor term: that term fails on NaN, the others on ``<`` alone, which a NaN never is.)

    ``less_upper`` (default ``less``): what the five terms of the upper arm and the elbow give away instead of
    ``less`` - over a box of poses a point of the upper arm moves at most ``ARM3_UPPER * |dq2|``, one of the
    forearm ``ARM3_UPPER * |dq2| + ARM3_FORE * |dq2 + dq3|``: each term then bounds its own pair over the box."""
    slack = BOUND_SLACK
    lu = less if less_upper is None else less_upper
    h = ARM3_SHOULDER_HEIGHT
    ex, ez = ARM3_UPPER * math.cos(q2), h - ARM3_UPPER * math.sin(q2)
    r = ARM3_ELBOW_RADIUS
    if ez - r - lu - slack < need:  # elbow - floor
        return False
    t = (h if not ez < h else ez) - ARM3_UPPER_RADIUS  # min(h, ez), NaN as min() has it
    if not t - lu - slack >= need:  # upper arm - floor (min()'s first argument)
        return False
    fx, fz = ex + ARM3_FORE * math.cos(q2 + q3), ez - ARM3_FORE * math.sin(q2 + q3)
    if (ez if not fz < ez else fz) - ARM3_FORE_RADIUS - less - slack < need:  # forearm - floor; min(ez, fz)
        return False
    (bh, b0, b1), (lh, l0, l1) = ARM3_COLUMNS
    # elbow - base and elbow - link1: _point_column written out (max(a, b) is ``b if b > a else a``)
    ax = abs(ex)
    dx, dz, w = ax - bh, b0 - ez, ez - b1
    dz = w if w > dz else dz  # noqa: FURB136
    if math.hypot(0.0 if 0.0 > dx else dx, 0.0 if 0.0 > dz else dz) - r - lu - slack < need:  # noqa: FURB136
        return False
    dx, dz, w = ax - lh, l0 - ez, ez - l1
    dz = w if w > dz else dz  # noqa: FURB136
    if math.hypot(0.0 if 0.0 > dx else dx, 0.0 if 0.0 > dz else dz) - r - lu - slack < need:  # noqa: FURB136
        return False
    r = ARM3_FORE_RADIUS
    if _apart(ex, ez, fx, fz, bh, b0, b1) - r - less - slack < need \
            and _segment_column(ex, ez, fx, fz, bh, b0, b1) - r - less - slack < need:  # forearm - base
        return False
    if _apart(ex, ez, fx, fz, lh, l0, l1) - r - less - slack < need \
            and _segment_column(ex, ez, fx, fz, lh, l0, l1) - r - less - slack < need:  # forearm - link1
        return False
    r = ARM3_UPPER_RADIUS  # upper arm - base
    return not (_apart(0.0, h, ex, ez, bh, b0, b1) - r - lu - slack < need
                and _segment_column(0.0, h, ex, ez, bh, b0, b1) - r - lu - slack < need)


#: m below the gap of two boxes that :func:`_segment_column` can read for it (its rounding is ~1e-16 m)
_ROUNDING = 1e-9


def _apart(px: float, pz: float, qx: float, qz: float, half: float, z0: float, z1: float) -> float:
    """A lower bound [m] of what :func:`_segment_column` computes for the segment P-Q and the rectangle: how far
    the segment's bounding box is from the rectangle along x or z (never more than the distance itself), less
    :data:`_ROUNDING`. Where it already clears the gap the exact distance, at least as large, does too."""
    lo, hi = (px, qx) if px < qx else (qx, px)
    dx = lo - half if lo - half > -half - hi else -half - hi  # noqa: FURB136 - max() without a call
    lo, hi = (pz, qz) if pz < qz else (qz, pz)
    dz = lo - z1 if lo - z1 > z0 - hi else z0 - hi  # noqa: FURB136
    return (dx if dx > dz else dz) - _ROUNDING  # noqa: FURB136


def erob_arm3_falls_short(q2: float, q3: float, need: float) -> bool:
    """Whether some sample point of :func:`erob_arm3_clearance` at the pose ``q2``, ``q3`` [rad] (model frame) is
    closer than ``need`` [m] to the floor, ``base`` or ``link1`` by more than rounding: then the sampled gap of
    that pose, the smallest over all its sample points, is below ``need`` too. Scalar, with an early exit, for
    the shield's grid (:meth:`envs.reach.ErobArmReachEnv.keeps_clearance`): a pose of the grid that falls
    short answers for the whole grid without it."""
    limit = need - _ROUNDING
    h, (bh, b0, b1), (lh, l0, l1) = ARM3_SHOULDER_HEIGHT, ARM3_COLUMNS[0], ARM3_COLUMNS[1]
    c2, s2, c23, s23 = math.cos(q2), math.sin(q2), math.cos(q2 + q3), math.sin(q2 + q3)
    ex, ez = ARM3_UPPER * c2, h - ARM3_UPPER * s2
    if ez - ARM3_ELBOW_RADIUS < limit or _point_column(ex, ez, bh, b0, b1) - ARM3_ELBOW_RADIUS < limit \
            or _point_column(ex, ez, lh, l0, l1) - ARM3_ELBOW_RADIUS < limit:
        return True
    for k in range(_SAMPLES):
        s = k / (_SAMPLES - 1)
        x, z = s * ARM3_UPPER * c2, h - s * ARM3_UPPER * s2
        if z - ARM3_UPPER_RADIUS < limit or _point_column(x, z, bh, b0, b1) - ARM3_UPPER_RADIUS < limit:
            return True
        x, z = ex + s * ARM3_FORE * c23, ez - s * ARM3_FORE * s23
        if z - ARM3_FORE_RADIUS < limit or _point_column(x, z, bh, b0, b1) - ARM3_FORE_RADIUS < limit \
                or _point_column(x, z, lh, l0, l1) - ARM3_FORE_RADIUS < limit:
            return True
    return False
