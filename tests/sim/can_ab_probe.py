"""The eRob CAN compiled step of two checkouts in one process: an env step's CPU time with either checkout's
one-call exchange and driver step.

Not a test (pytest does not collect it): a measuring tool. ``python tests/sim/can_ab_probe.py OTHER MODE``
(``OTHER`` the root of another checkout, e.g. a ``git archive`` of the commit to compare with; ``MODE`` an action
mode of ``joints/ErobReach-v0``) runs that env at 20 ms on eRob CAN at 1 Mbit/s (``joints bench``'s CAN row) and
loads OTHER's ``joints/sim/can_exchange.py`` and ``joints/drivers/erob_can_steady.py`` under other names (its
``exchanges`` compiled from its own file). Block by block the env's compiled path steps its joint with this
checkout's :class:`~joints.drivers.erob_can_steady.ErobCanStep` (and exchange) or OTHER's, each block ``STEPS``
steps of the same seeded uniform actions from the same reset, timed by ``time.thread_time``; the blocks alternate
(``ROUNDS`` of each) and every block's observations, rewards and ends must be bit-identical to the first block's.
Prints the best and median CPU time per env step of each. Pin it to one core (``taskset -c 1``).
"""

from __future__ import annotations

import copy
import importlib.util
import os
import statistics
import sys
import time
from importlib import resources
from typing import Any

import gymnasium as gym
import numpy as np

import envs  # noqa: F401 - registers the joints/ envs
from joints.drivers import erob_can_steady as S

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

STEPS = int(os.environ.get("STEPS", "300"))
ROUNDS = int(os.environ.get("ROUNDS", "10"))


def _load(root: str, rel: str, name: str) -> Any:
    spec = importlib.util.spec_from_file_location(name, os.path.join(root, rel))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def _config() -> dict[str, Any]:
    cfg: dict[str, Any] = tomllib.loads(
        (resources.files("joints.configs") / "erob_reach.toml").read_text(encoding="utf-8"))
    on_can = copy.deepcopy(cfg)
    on_can["buses"] = {"can": {"protocol": "erob-can", "bitrate": 1_000_000}}
    for j in on_can["joints"].values():
        j["bus"] = "can"
    return on_can


def _block(env: Any, step: Any, actions: list[Any]) -> tuple[float, list[Any]]:
    u = env.unwrapped
    cp = u.compiled_path
    obs, _ = env.reset(seed=7)
    cp._units = [((0,), step)]
    cp._steppers = [step]
    record: list[Any] = [obs.tobytes()]
    t0 = time.thread_time()
    for a in actions:
        obs, reward, terminated, truncated, _ = env.step(a)
        record.append((obs.tobytes(), reward, terminated, truncated))
        if terminated or truncated:
            obs, _ = env.reset()
    return (time.thread_time() - t0) / len(actions), record


def main(other: str, mode: str) -> None:
    o_ce = _load(other, "joints/sim/can_exchange.py", "other_can_exchange")
    o_s = _load(other, "joints/drivers/erob_can_steady.py", "other_erob_can_steady")
    env = gym.make("joints/ErobReach-v0", config=_config(), control_period=0.02, action_mode=mode)
    u: Any = env.unwrapped
    env.reset(seed=7)
    (this,) = u.compiled_path._steppers
    assert isinstance(this, S.ErobCanStep)
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
