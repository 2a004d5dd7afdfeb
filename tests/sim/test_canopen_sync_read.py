"""The arm on CANopen across resets and within a read (k5-sync).

* A reset restarts the world's clock (a new epoch): the link's bus time starts again with it, and the driver's
  times kept on the clock (the temperature read, the guarding) are forgotten with the drive's power cycle, so two
  episodes reset with the same seed are the same episode - the first one after ``gym.make`` too.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")
gym = pytest.importorskip("gymnasium")

import envs  # noqa: F401  (registers the joints/ ids)
from joints.bench import BASELINE_PERIOD, _baseline_config

ENV = "joints/ErobArmReach-v0"


@pytest.fixture
def arm() -> Iterator[Any]:
    found = _baseline_config(ENV)
    assert found is not None and found[1].startswith("canopen"), found
    env = gym.make(ENV, config=found[0], control_period=BASELINE_PERIOD)
    try:
        yield env
    finally:
        env.close()


def _episode(env: Any, seed: int, steps: int) -> list[Any]:
    obs, info = env.reset(seed=seed)
    out: list[Any] = [(obs.tobytes(), repr(info))]
    rng = np.random.default_rng(11)
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, env.action_space.shape)
                                                            .astype(np.float32))
        out.append((obs.tobytes(), reward, terminated, truncated, repr(info)))
    return out


def test_a_reset_restarts_the_bus_time_with_the_clock(arm: Any) -> None:
    u = arm.unwrapped
    _episode(arm, 4, 60)  # bus time well past where the next episode's reset ends
    link = next(iter(u.rig.joints.values())).driver.link
    assert link.bus_now() > 1.0
    restarts = getattr(link, "restarts", 0)
    arm.reset(seed=4)
    clock = u.rig.clock.now()
    # the bus's time is the last frame's stamp: at most one substep of the world from its clock
    assert abs(link.bus_now() - clock) <= 1e-3, (link.bus_now(), clock)
    assert link.restarts == restarts + 1


def test_the_same_seed_gives_the_same_episode_from_the_first_one_on(arm: Any) -> None:
    first = _episode(arm, 4, 40)
    second = _episode(arm, 4, 40)
    third = _episode(arm, 4, 40)
    assert second == third
    assert first == second


class _Link:
    """What :class:`SyncCycle` asks of a link: bus time, its clock restarts, waits and SYNCs (recorded)."""

    def __init__(self) -> None:
        self.now = 5.0
        self.restarts = 0
        self.waits: list[float] = []
        self.syncs = 0

    def bus_now(self) -> float:
        return self.now

    def wait_bus(self, until: float) -> None:
        self.waits.append(until)
        self.now = until

    def sync(self) -> None:
        self.syncs += 1


def test_the_sync_cycle_lays_a_new_grid_after_a_clock_restart() -> None:
    from joints.drivers.canopen_sync import SyncCycle

    link = _Link()
    cycle = SyncCycle(link, 0.001)
    cycle.send({})
    cycle.send({})  # on the grid: waits for its due time
    assert link.waits == [5.001] and cycle.next_due == pytest.approx(5.002)
    link.now, link.restarts = 2.0, 1  # a reset: the clock starts again, earlier than the old grid
    cycle.send({})
    assert link.waits == [5.001]  # not three seconds of waiting for the old grid's next cycle
    assert cycle.next_due == pytest.approx(2.001) and cycle.sync_time == 2.0
