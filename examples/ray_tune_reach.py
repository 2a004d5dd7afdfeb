"""Tune a reach controller for joints/ErobReach-v0 with Ray Tune - on this machine or a Ray cluster.

Each trial is one gain of a proportional velocity controller (action = gain x position error,
normalised by the joint's velocity limit); a trial runs its episodes in a Ray worker, which
builds its own env from a plain config (``envs.make_env``: nothing but the config travels). The
trials run in parallel on as many workers as the cluster has CPUs.

    pip install -e ".[sim,gym,ray]"
    python examples/ray_tune_reach.py                          # a local Ray instance
    python examples/ray_tune_reach.py --num-envs 16            # each trial: 16 rigs batched in its worker

On a real cluster (every node with this package installed, same version):

    ray start --head --port=6379                               # on the head node
    ray start --address=HEAD_IP:6379                           # on every other node
    python examples/ray_tune_reach.py --address auto           # on the head node
    RAY_ADDRESS=ray://HEAD_IP:10001 python examples/ray_tune_reach.py   # from elsewhere (Ray client)

Nodes without the package installed can get it per job: ``--working-dir .`` ships this checkout
and ``pip install``s it on the workers (Ray's runtime_env).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))  # run from a checkout without installing

#: the env every trial builds in its worker (plain data: it pickles)
ENV_CONFIG: dict[str, Any] = {"id": "joints/ErobReach-v0", "action_mode": "velocity"}


def evaluate(gain: float, env_config: dict[str, Any], *, episodes: int, steps: int, seed: int) -> float:
    """Mean return of the controller ``action = gain x (target - position) / velocity limit``."""
    import envs

    cfg = {**env_config, "max_episode_steps": steps}
    num_envs = int(cfg.get("num_envs", 1))
    env = envs.make_env(cfg)
    try:
        vlim = float(env.unwrapped.envs[0].velocity_limits[0]) if num_envs > 1 else \
            float(env.unwrapped.velocity_limits[0])
        total = 0.0
        for episode in range(episodes):
            obs, _info = env.reset(seed=seed + episode * num_envs)
            done = np.zeros(num_envs, dtype=bool)
            ret = np.zeros(num_envs)
            while not done.all():
                error = np.atleast_2d(obs)[:, 4]  # target - position [rad]
                action = np.clip(gain * error / vlim, -1.0, 1.0).astype(np.float32).reshape(num_envs, 1)
                obs, reward, terminated, truncated, _info = env.step(action if num_envs > 1 else action[0])
                ret += np.where(done, 0.0, reward)
                done |= np.atleast_1d(terminated) | np.atleast_1d(truncated)
            total += float(ret.mean())
        return total / episodes
    finally:
        env.close()


def trainable(config: dict[str, Any]) -> None:
    """One Ray Tune trial (runs in a worker)."""
    from ray import tune

    score = evaluate(config["gain"], config["env"], episodes=config["episodes"], steps=config["steps"],
                     seed=config["seed"])
    tune.report({"mean_return": score})


def tune_gains(gains: Sequence[float], *, episodes: int = 2, steps: int = 100, seed: int = 0,
               num_envs: int = 1, storage: str | None = None) -> tuple[float, dict[float, float]]:
    """Run the trials on the Ray cluster this process is connected to: (best gain, return per gain)."""
    from ray import tune

    env = {**ENV_CONFIG, **({"num_envs": num_envs} if num_envs > 1 else {})}
    tuner = tune.Tuner(
        trainable,
        param_space={"gain": tune.grid_search(list(gains)), "env": env, "episodes": episodes, "steps": steps,
                     "seed": seed},
        tune_config=tune.TuneConfig(metric="mean_return", mode="max"),
        run_config=tune.RunConfig(storage_path=storage, verbose=0),
    )
    results = tuner.fit()
    scores = {r.config["gain"]: float(r.metrics["mean_return"]) for r in results}
    best = results.get_best_result()
    return float(best.config["gain"]), scores


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--address", default=None, help="Ray cluster: 'auto', 'ray://host:10001' (default: local)")
    ap.add_argument("--gains", type=float, nargs="+", default=[0.5, 1.0, 2.0, 4.0, 8.0])
    ap.add_argument("--episodes", type=int, default=2)
    ap.add_argument("--steps", type=int, default=100, help="steps per episode (20 ms each)")
    ap.add_argument("--num-envs", type=int, default=1, help="rigs batched in each trial's worker")
    ap.add_argument("--working-dir", default=None, help="ship this directory to the workers and pip install it")
    args = ap.parse_args(argv)
    import ray

    runtime_env = {"working_dir": args.working_dir, "pip": [f"{args.working_dir}[sim,gym]"]} \
        if args.working_dir else None
    ray.init(address=args.address, runtime_env=runtime_env, log_to_driver=False)
    try:
        best, scores = tune_gains(args.gains, episodes=args.episodes, steps=args.steps, num_envs=args.num_envs)
    finally:
        ray.shutdown()
    for gain, score in sorted(scores.items()):
        print(f"gain {gain:6.2f}: mean return {score:9.3f}")
    print(f"best gain: {best}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
