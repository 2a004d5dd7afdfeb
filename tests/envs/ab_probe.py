"""Two checkouts in one process: an env's (or a batch's) step with either checkout's whole ``joints`` and ``envs``.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/ab_probe.py OTHER [CASE ...]``
(``OTHER`` the root of another checkout, e.g. a ``git worktree`` of the commit to compare with) imports the
``joints`` and ``envs`` packages twice, once from this checkout and once from OTHER, each whole under its own names:
``sys.modules`` holds one checkout's modules at a time and is switched before each block, so the lazy imports of
either find their own, and the ``joints/`` ids are registered again by the checkout whose env is made. Any change
can be compared this way, whatever it renames: nothing of either checkout is patched. A ``CASE`` is

* ``ENV_ID`` or ``ENV_ID:MODE`` (an action mode): ``gym.make`` with its defaults, gymnasium's wrappers included;
* the same with ``@20ms``: at 20 ms on the bus ``joints bench`` measures it on there
  (:func:`joints.bench._baseline_config` of each checkout: eRob CAN or CANopen at 1 Mbit/s);
* ``rigs:N``: ``gym.make_vec("joints/ErobReach-v0", num_envs=N, vectorization_mode="vector_entry_point")``, its
  episodes unlimited (the bench's batched rows).

Default: ``joints/ErobReach-v0``, ``joints/ErobArmReach-v0@20ms``, ``rigs:16``. Block by block each checkout runs
``STEPS`` steps of the same seeded uniform actions from the same reset, timed in CPU time (``time.thread_time``:
other processes' load does not count; resets at episode ends not timed); the blocks alternate (``ROUNDS`` of each)
and every block's observations, rewards and ends must be bit-identical to this checkout's first block
(``SAME_BITS=0``: to the first block of the same checkout, for a change of behaviour). Prints per step (per rig step
for a batch) the best and median CPU time of each, this against other, and the Python calls of each
(``sys.setprofile``'s call events over one more block: a count, the same on every run, where the times are not).
Pin it to one core (``taskset -c 1``). The first run against a checkout compiles its kernels (numba caches them by
file: minutes once).
"""

from __future__ import annotations

import logging
import os
import statistics
import sys
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import registry

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # tests/, for probekit
from probekit import timed_steps, timed_vec_steps

STEPS = int(os.environ.get("STEPS", "300"))
ROUNDS = int(os.environ.get("ROUNDS", "10"))
SAME_BITS = os.environ.get("SAME_BITS", "1") != "0"
DEFAULT = ("joints/ErobReach-v0", "joints/ErobArmReach-v0@20ms", "rigs:16")
_OURS = ("joints", "envs")


def _ours(name: str) -> bool:
    return any(name == p or name.startswith(p + ".") for p in _OURS)


_ACTIVE: list[dict[str, Any]] = [{}]  #: the checkout whose modules sys.modules holds


def _use(modules: dict[str, Any]) -> None:
    """``modules``' checkout in ``sys.modules``; what the one there imported meanwhile (lazily) kept in its tree."""
    active = _ACTIVE[0]
    for name in [n for n in sys.modules if _ours(n)]:
        active[name] = sys.modules.pop(name)
    sys.modules.update(modules)
    _ACTIVE[0] = modules


def _load(root: str) -> dict[str, Any]:
    """Every module of ``joints`` and ``envs`` as imported from ``root`` (kept out of ``sys.modules``; the modules
    either imports later join its tree, :func:`_use`)."""
    modules: dict[str, Any] = {}
    _use(modules)
    sys.path.insert(0, root)
    try:
        import envs  # noqa: F401 - registers the joints/ envs (entry points resolve at make time)
        import joints.bench  # noqa: F401
    finally:
        sys.path.remove(root)
    modules.update((n, m) for n, m in sys.modules.items() if _ours(n))
    assert os.path.dirname(os.path.abspath(modules["joints"].__file__)) == os.path.join(os.path.abspath(root),
                                                                                      "joints"), root
    return modules


def _make(modules: dict[str, Any], case: str) -> tuple[Any, int]:
    """The env (or batch) of ``case`` from ``modules``' checkout, and the rigs it steps."""
    _use(modules)
    for env_id in [i for i in registry if i.startswith("joints/")]:  # the ids as this checkout registers them
        del registry[env_id]  # (its vector entry point is a function of its own)
    modules["envs"].register_envs()
    if case.startswith("rigs:"):
        n = int(case[5:])
        env: Any = gym.make_vec("joints/ErobReach-v0", num_envs=n, vectorization_mode="vector_entry_point")
        env.unwrapped.max_episode_steps = None
    else:
        env_id, _, period = case.partition("@")
        env_id, _, mode = env_id.partition(":")
        kwargs: dict[str, Any] = {"action_mode": mode} if mode else {}
        if period:
            if period != "20ms":
                raise SystemExit(f"{case}: only @20ms (the bench's baseline period) is known")
            bench = modules["joints.bench"]
            found = bench._baseline_config(env_id)
            if found is None:
                raise SystemExit(f"{case}: no bus of this env carries 20 ms")
            kwargs.update(config=found[0], control_period=bench.BASELINE_PERIOD)
        env = gym.make(env_id, **kwargs)
        n = 1
    cls = type(env.unwrapped)
    assert modules[cls.__module__].__dict__.get(cls.__name__) is cls, f"{case}: the env came from the other checkout"
    return env, n


def _actions(env: Any, rigs: int) -> list[Any]:
    rng = np.random.default_rng(11)
    vector = hasattr(env, "num_envs")
    space = env.single_action_space if vector else env.action_space
    shape = (rigs, *space.shape) if vector else space.shape
    return [rng.uniform(space.low, space.high, shape).astype(space.dtype) for _ in range(STEPS)]


def _block(env: Any, modules: dict[str, Any], actions: list[Any], profile: Callable[..., Any] | None = None
           ) -> tuple[float, list[Any]]:
    """CPU seconds per rig step over ``actions`` from a seeded reset, and the record compared (observations,
    rewards, an env's ends: :func:`probekit.timed_steps`, :func:`probekit.timed_vec_steps`)."""
    _use(modules)
    obs, _ = env.reset(seed=7)
    if hasattr(env, "num_envs"):
        t, got = timed_vec_steps(env, actions, profile)
        return t, [(o.tobytes(), r.tobytes()) for o, r in got]  # (compared by ==, as an env's)
    return timed_steps(env, obs, actions, profile)


def _calls(env: Any, modules: dict[str, Any], actions: list[Any], rigs: int) -> float:
    """Python calls per rig step over one block (deterministic)."""
    count = [0]

    def profile(frame: Any, event: str, arg: Any) -> None:
        if event == "call":
            count[0] += 1

    _block(env, modules, actions, profile)
    return count[0] / (len(actions) * rigs)


def run(case: str, trees: dict[str, dict[str, Any]]) -> None:
    made = {name: _make(mods, case) for name, mods in trees.items()}
    rigs = made["this"][1]
    actions = _actions(made["this"][0], rigs)
    times: dict[str, list[float]] = {name: [] for name in trees}
    first: dict[str, list[Any]] = {}
    for name, (env, _) in made.items():  # a first block of each, untimed: first bring-ups differ
        _block(env, trees[name], actions)
    for _ in range(ROUNDS):
        for name, (env, _) in made.items():
            t, record = _block(env, trees[name], actions)
            ref = first.setdefault("this" if SAME_BITS else name, record)
            assert record == ref, f"{case}, {name}: the bits differ from the first block's"
            times[name].append(t)
    calls = {name: _calls(env, trees[name], actions, rigs) for name, (env, _) in made.items()}
    for env, _ in made.values():
        env.close()
    unit = "rig step" if rigs > 1 else "step"
    print(f"{case}: {ROUNDS} blocks of {STEPS} steps each, CPU time per {unit}"
          + ("" if SAME_BITS else ", bits " + ("the same" if first["this"] == first["other"] else "differ")))
    for name, ts in times.items():
        print(f"  {name:6s} best {min(ts) * 1e6:8.1f} us  median {statistics.median(ts) * 1e6:8.1f} us  "
              f"Python calls {calls[name]:7.1f}")
    b = min(times["this"]) / min(times["other"]) - 1
    m = statistics.median(times["this"]) / statistics.median(times["other"]) - 1
    print(f"  this vs other: best {b * 100:+.1f} %, median {m * 100:+.1f} %, calls "
          f"{calls['this'] / calls['other'] * 100 - 100:+.1f} %")


def main(other: str, cases: list[str]) -> None:
    logging.disable(logging.WARNING)  # e.g. the CANopen arm's host-only torque limit, once per env
    here = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    if os.path.abspath(other) == here:
        raise SystemExit("OTHER is this checkout: give another one (e.g. `git worktree add /tmp/base REV`)")
    trees = {"this": _load(here), "other": _load(os.path.abspath(other))}
    for case in cases or DEFAULT:
        run(case, trees)


if __name__ == "__main__":
    if len(sys.argv) < 2:
        raise SystemExit(__doc__)
    main(sys.argv[1], sys.argv[2:])
