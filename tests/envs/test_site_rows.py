"""The envs' MuJoCo site rows read through views made once per data object give the bits of a fresh read per step.

ErobArmReach's end effector (``site_xpos`` of ``ee``) and DiffDriveGoal's chassis pose (``site_xpos`` and
``site_xmat`` of ``base``) are read each step; the env keeps the site's rows as views of the world's MuJoCo data
(remade where ``world.data`` is another object). Each case runs the env beside a copy whose read is the one it
replaced (the binding's array indexed every step) over two seeded episodes of random actions: every
observation, reward, end and info (keys, order, types, values) must be the same bits, and the env must have read
through its views of the world's present data.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from envs.diffdrive import DiffDriveGoalEnv
from envs.reach import ErobArmReachEnv


class _FreshArm(ErobArmReachEnv):
    def _ee_row(self) -> np.ndarray:
        row: np.ndarray = self.rig.world.data.site_xpos[self._site]  # the binding's array indexed every step
        return row


class _FreshDrive(DiffDriveGoalEnv):
    def _world_xyth(self) -> tuple[float, float, float]:
        data = self.rig.sim.data
        x, y, _ = data.site_xpos[self._site].tolist()
        m = data.site_xmat[self._site].tolist()
        return x, y, math.atan2(m[3], m[0])


def _same(a: Any, b: Any) -> bool:
    """Bit-identical: arrays by dtype, shape and bytes; floats by repr; dicts by keys in order, then values."""
    if type(a) is not type(b):
        return False
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    if isinstance(a, dict):
        return list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (tuple, list)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return repr(a) == repr(b)


def _episodes(fast: Any, fresh: Any, steps: int = 40) -> None:
    actions = np.random.default_rng(3).uniform(-1, 1, (2 * steps, *fast.action_space.shape)).astype(np.float32)
    for episode in range(2):
        assert _same(fast.reset(seed=episode), fresh.reset(seed=episode))
        for a in actions[episode * steps:(episode + 1) * steps]:
            out = fast.step(a)
            assert _same(out, fresh.step(a))
            if out[2]:
                break


def test_the_arms_end_effector_view_gives_a_fresh_reads_bits() -> None:
    fast, fresh = ErobArmReachEnv(), _FreshArm()
    try:
        _episodes(fast, fresh)
        data = fast.rig.world.data
        assert fast._ee_data is data and np.shares_memory(fast._ee_view, data.site_xpos)  # the views were read
        assert fast._ee == data.site_xpos[fast._site].tolist()
    finally:
        fast.close()
        fresh.close()


def test_the_drives_chassis_views_give_a_fresh_reads_bits() -> None:
    fast, fresh = DiffDriveGoalEnv(), _FreshDrive()
    try:
        _episodes(fast, fresh)
        data = fast.rig.sim.data
        xpos, xmat = fast._base_rows
        assert fast._base_data is data and np.shares_memory(xpos, data.site_xpos) \
            and np.shares_memory(xmat, data.site_xmat)  # the views were read
    finally:
        fast.close()
        fresh.close()
