"""Envs never fault by design: full-length episodes of every registered env under seeded action
policies, counting drive faults and the other ways an episode ends.

For every id ``import envs`` registers (each action mode of the env; the default one among them),
``--episodes`` episodes per policy, each to its registered length (or its termination), sim
backend, shipped config:

* ``uniform`` - actions uniform over the whole action space (``action_space.sample()``, seeded);
* ``corners`` - a random corner of the action space every step (bang-bang at the extremes);
* ``hold`` - a random corner held for a random number of steps (long full-speed / full-range moves);
* ``square`` - all +1 then all -1, switching every 25 steps.

Episode ``k`` of a policy resets with ``seed + k``; the action draws are seeded from it too, so a
run is reproducible. Prints one line per env, mode and policy (episodes, steps, drive faults by
name, limit violations, other terminations, seconds) and exits 1 if any drive faulted.

    python tests/benchmarks/bench_env_faults.py                       # 100 episodes each
    python tests/benchmarks/bench_env_faults.py --episodes 10 --policies uniform
    python tests/benchmarks/bench_env_faults.py --domain-randomization
"""

from __future__ import annotations

import argparse
import collections
import importlib
import inspect
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import gymnasium as gym
import numpy as np

import envs  # registers the joints/ ids

Policy = Callable[[int], np.ndarray]
POLICIES = ("uniform", "corners", "hold", "square")


def policy(name: str, env: gym.Env[Any, Any], seed: int) -> Policy:
    """The action of step ``k`` of one episode under policy ``name``, drawn from ``seed``."""
    space = env.action_space
    rng = np.random.default_rng(seed)
    shape = space.shape
    assert shape is not None
    if name == "uniform":
        space.seed(seed)
        return lambda k: np.asarray(space.sample())
    if name == "corners":
        return lambda k: rng.choice([-1.0, 1.0], size=shape).astype(np.float32)
    if name == "square":
        return lambda k: np.full(shape, 1.0 if (k // 25) % 2 == 0 else -1.0, np.float32)
    if name == "hold":
        held = [np.zeros(shape, np.float32)]
        until = [-1]

        def hold(k: int) -> np.ndarray:
            if k >= until[0]:
                held[0] = rng.choice([-1.0, 1.0], size=shape).astype(np.float32)
                until[0] = k + int(rng.integers(5, 100))
            return held[0]

        return hold
    raise ValueError(f"unknown policy {name!r}; known: {POLICIES}")


def env_class(env_id: str) -> Any:
    module, name = str(gym.spec(env_id).entry_point).split(":")
    return getattr(importlib.import_module(module), name)


def accepts(env_id: str, argument: str) -> bool:
    """The env takes keyword ``argument`` (the JointsEnv arguments reach every subclass)."""
    cls = env_class(env_id)
    if issubclass(cls, envs.JointsEnv) and argument in inspect.signature(envs.JointsEnv.__init__).parameters:
        return True
    return argument in inspect.signature(cls.__init__).parameters


def action_modes(env_id: str) -> tuple[str, ...] | None:
    """The action modes of a registered env (its module's ``ACTION_MODES``), None if it has none."""
    cls = env_class(env_id)
    if issubclass(cls, envs.JointsEnv):
        return envs.ACTION_MODES
    if not accepts(env_id, "action_mode"):
        return None
    modes: tuple[str, ...] = sys.modules[cls.__module__].ACTION_MODES
    return modes


def env_ids() -> list[str]:
    """Every id ``import envs`` registers under ``joints/``."""
    return sorted(i for i in gym.registry if i.startswith("joints/"))


def cases() -> Iterator[tuple[str, dict[str, Any]]]:
    """(env id, gym.make keyword arguments) of every registered env and action mode."""
    for env_id in env_ids():
        modes = action_modes(env_id)
        if modes is None:
            yield env_id, {}
        else:
            for mode in modes:
                yield env_id, {"action_mode": mode}


def run_episode(env: gym.Env[Any, Any], act: Policy, seed: int) -> dict[str, Any]:
    """One episode to its end: steps, the faults seen (``info["fault"]``) and how it ended."""
    env.reset(seed=seed)
    k = 0
    while True:
        _obs, _r, terminated, truncated, info = env.step(act(k))
        k += 1
        if terminated or truncated:
            break
    fault = info.get("fault")
    if isinstance(fault, str):  # (a bare fault name)
        fault = {"joint": "-", "name": fault}
    if fault is None:  # (envs before info["fault"]: the per-joint names)
        fault = next(({"joint": j, "name": f} for j, f in info.get("faults", {}).items() if f), None)
    if fault is not None:
        end = "fault"
    elif truncated:
        end = "truncated"
    elif info.get("limit_violation"):
        end = "limit_violation"
    else:
        end = next((key for key in ("is_success", "out_of_arena", "watchdog") if info.get(key)), "terminated")
    return {"steps": k, "end": end, "fault": fault}


def run(env_id: str, kwargs: dict[str, Any], policy_name: str, episodes: int, seed: int) -> dict[str, Any]:
    env = gym.make(env_id, **kwargs)
    try:
        t0 = time.perf_counter()
        ends: collections.Counter[str] = collections.Counter()
        faults: collections.Counter[str] = collections.Counter()
        steps = 0
        for k in range(episodes):
            r = run_episode(env, policy(policy_name, env, seed + k), seed + k)
            steps += r["steps"]
            ends[r["end"]] += 1
            if r["fault"] is not None:
                faults[f"{r['fault']['joint']}:{r['fault']['name']}"] += 1
        return {"episodes": episodes, "steps": steps, "ends": dict(ends), "faults": dict(faults),
                "seconds": time.perf_counter() - t0}
    finally:
        env.close()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--episodes", type=int, default=100, help="episodes per env, mode and policy (default 100)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first episode (default 0)")
    p.add_argument("--policies", nargs="+", default=list(POLICIES), choices=POLICIES)
    p.add_argument("--env", nargs="+", default=None, help="only these ids")
    p.add_argument("--domain-randomization", action="store_true", help="joints envs with the default ranges")
    args = p.parse_args(argv)
    total_faults = 0
    print(f"{'env':26} {'mode':9} {'policy':8} {'episodes':>8} {'steps':>7} {'faults':>6} {'limit':>5}  ends; faults")
    for env_id, kwargs in cases():
        if args.env and env_id not in args.env:
            continue
        if args.domain_randomization and accepts(env_id, "domain_randomization"):
            kwargs = {**kwargs, "domain_randomization": True}
        for name in args.policies:
            r = run(env_id, kwargs, name, args.episodes, args.seed)
            n_faults = sum(r["faults"].values())
            total_faults += n_faults
            mode = kwargs.get("action_mode", "-")
            print(f"{env_id:26} {mode:9} {name:8} {r['episodes']:8d} {r['steps']:7d} {n_faults:6d} "
                  f"{r['ends'].get('limit_violation', 0):5d}  {r['ends']}; {r['faults']} ({r['seconds']:.0f} s)",
                  flush=True)
    print(f"drive faults in total: {total_faults}")
    return 1 if total_faults else 0


if __name__ == "__main__":
    raise SystemExit(main())
