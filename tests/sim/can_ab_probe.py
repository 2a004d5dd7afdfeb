"""The eRob CAN compiled step of two checkouts in one process: an env step's CPU time with either checkout's
one-call exchange and driver step.

Not a test (pytest does not collect it): a measuring tool. ``python tests/sim/can_ab_probe.py OTHER MODE``
(``OTHER`` the root of another checkout, e.g. a ``git archive`` of the commit to compare with; ``MODE`` an action
mode of ``joints/ErobReach-v0``) runs that env at 20 ms on eRob CAN at 1 Mbit/s (``joints bench``'s CAN row) and
loads OTHER's ``joints/sim/can_exchange.py`` and ``joints/drivers/erob_can_steady.py`` under other names (its
``exchanges`` compiled from its own file). Block by block the env's compiled path steps its joint with this
checkout's :class:`~joints.drivers.erob_can_steady.ErobCanStep` (and exchange) or OTHER's, each block ``STEPS``
steps of the same seeded uniform actions from the same reset, timed by ``time.thread_time`` (the world holding its
sleeps for a step that offers ``carried()``, as ``joints.compiled_path`` sets it; the env step in one call where
the stepper has a ``step``: ``CompiledPath.step``; ``ONE_CALL=0``: this checkout's without it); the blocks alternate
(``ROUNDS`` of each) and every block's observations, rewards and ends must be bit-identical to the first block's.
Prints the best and median CPU time per env step of each. Pin it to one core (``taskset -c 1``).
"""

from __future__ import annotations

import os
import statistics
import sys
from typing import Any

import gymnasium as gym
import numpy as np

import envs  # noqa: F401 - registers the joints/ envs

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # tests/, for probekit
from probekit import load_as, timed_steps

from joints.bench import _baseline_config
from joints.drivers import erob_can_steady as S

STEPS = int(os.environ.get("STEPS", "300"))
ROUNDS = int(os.environ.get("ROUNDS", "10"))


def _config() -> dict[str, Any]:
    """ErobReach's shipped config on eRob CAN at 1 Mbit/s, as ``joints bench`` builds its CAN row."""
    found = _baseline_config("joints/ErobReach-v0")
    assert found is not None and found[1].startswith("erob-can"), found
    config: dict[str, Any] = found[0]
    return config


def _block(env: Any, step: Any, actions: list[Any]) -> tuple[float, list[Any]]:
    u = env.unwrapped
    cp = u.compiled_path
    # the world holds its sleeps for a step that offers ``carried()`` (``compiled_path._hold_sleeps``; the read's
    # call runs them), else it sleeps at once (a checkout before that)
    step.exchange.world.hold_sleeps = callable(getattr(step, "carried", None))
    obs, _ = env.reset(seed=7)
    cp._units = [((0,), step)]
    cp._steppers = [step]
    cp._step = getattr(step, "step", None)  # the env step in one call (``CompiledPath.step``), where it has one
    return timed_steps(env, obs, actions)


def main(other: str, mode: str) -> None:
    o_ce = load_as(other, "joints/sim/can_exchange.py", "other_can_exchange")
    o_s = load_as(other, "joints/drivers/erob_can_steady.py", "other_erob_can_steady")
    env = gym.make("joints/ErobReach-v0", config=_config(), control_period=0.02, action_mode=mode)
    u: Any = env.unwrapped
    env.reset(seed=7)
    (this,) = u.compiled_path._steppers
    assert isinstance(this, S.ErobCanStep)
    if os.environ.get("ONE_CALL", "1") == "0":  # this checkout's stepper without its one-call env step
        this.step = lambda mode, values, tick: None
    ex = this.exchange
    that = o_s.ErobCanStep(this.joint, this.driver, o_ce.ErobCanExchange(ex.world, ex.bus, ex.host, ex.transport))
    rng = np.random.default_rng(11)
    space = env.action_space
    actions = [rng.uniform(space.low, space.high).astype(space.dtype) for _ in range(STEPS)]
    steps = {"this": this, "other": that}
    times: dict[str, list[float]] = {"this": [], "other": []}
    first: list[Any] | None = None
    for _ in range(ROUNDS):
        for name, step in steps.items():
            t, record = _block(env, step, actions)
            if first is None:
                first = record
            assert record == first, f"{name}: the bits differ from the first block's"
            times[name].append(t)
    env.close()
    for name, ts in times.items():
        print(f"{name:6s} best {min(ts) * 1e6:7.1f} us  median {statistics.median(ts) * 1e6:7.1f} us per env step "
              f"({ROUNDS} blocks of {STEPS} steps, CPU time)")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
