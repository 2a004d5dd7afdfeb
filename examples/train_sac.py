"""Train SAC (stable-baselines3) on joints/ErobReach-v0 in sim, then run the policy on sim or hardware.

Not run in CI. Needs ``pip install "stable-baselines3>=2.3"`` (which pulls in PyTorch).

    python examples/train_sac.py --steps 30000                       # train in sim, 4 workers, randomised drives
    python examples/train_sac.py --run sac_erob_reach.zip            # watch it in sim (MuJoCo viewer)
    python examples/train_sac.py --run sac_erob_reach.zip --backend hardware --port /dev/ttyUSB0

Training uses domain randomisation of the drives (loop gains, friction, armature, torque constant,
encoder noise, bus latency) so the policy does not over-fit the nominal emulator; running it uses
the plain env - on hardware, the same env class talks to the real drive.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

import envs

#: "module:id" makes gymnasium import ``envs`` (and so register the id) in fresh worker processes too
ENV_ID = "envs:joints/ErobReach-v0"


def train(steps: int, out: str, action_mode: str, n_envs: int, seed: int) -> None:
    from stable_baselines3 import SAC
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv

    vec = make_vec_env(ENV_ID, n_envs=n_envs, seed=seed, vec_env_cls=SubprocVecEnv,
                       env_kwargs={"action_mode": action_mode, "domain_randomization": True})
    model = SAC("MlpPolicy", vec, learning_rate=3e-4, buffer_size=200_000, batch_size=256, gamma=0.98,
                train_freq=1, gradient_steps=1, learning_starts=2_000, seed=seed, verbose=1)
    model.learn(total_timesteps=steps, log_interval=10)
    model.save(out)
    vec.close()
    print(f"saved {out}")


def run(path: str, action_mode: str, backend: str | None, port: str | None, episodes: int, render: bool) -> None:
    from stable_baselines3 import SAC

    config = envs.default_config("erob_reach")
    if port:
        config["buses"]["rs485"]["port"] = port
    env = gym.make(ENV_ID, config=config, backend=backend, action_mode=action_mode,
                   render_mode="human" if render else None)
    model = SAC.load(path)
    try:
        for ep in range(episodes):
            obs, _ = env.reset(seed=ep)
            ret, done = 0.0, False
            while not done:
                action, _ = model.predict(obs, deterministic=True)
                obs, reward, terminated, truncated, info = env.step(action)
                ret += float(reward)
                done = terminated or truncated
            print(f"episode {ep}: return {ret:8.2f}  final error {np.degrees(info['distance']):6.2f} deg  "
                  f"success {info['is_success']}  faults {info['faults']}")
    finally:
        env.close()


def main() -> None:
    p = argparse.ArgumentParser(description="SAC on joints/ErobReach-v0")
    p.add_argument("--steps", type=int, default=30_000, help="training steps (all workers together)")
    p.add_argument("--out", default="sac_erob_reach.zip")
    p.add_argument("--action-mode", default="position", choices=envs.ACTION_MODES)
    p.add_argument("--envs", type=int, default=4, help="parallel sim workers")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--run", metavar="MODEL", help="run a saved policy instead of training")
    p.add_argument("--backend", choices=("sim", "hardware"))
    p.add_argument("--port", help="RS485 port for --backend hardware")
    p.add_argument("--episodes", type=int, default=5)
    p.add_argument("--render", action="store_true")
    a = p.parse_args()
    if a.run:
        run(a.run, a.action_mode, a.backend, a.port, a.episodes, a.render)
    else:
        train(a.steps, a.out, a.action_mode, a.envs, a.seed)


if __name__ == "__main__":
    main()
