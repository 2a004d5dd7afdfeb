"""A PD controller on joints/ErobReach-v0 - the same script on the simulation and on a real drive.

The controller commands torque, ``tau = KP * (target - q) - KD * dq``, through the env's torque
action mode; the env talks to the drive only through the joints API, so ``--backend`` is the
only switch between an emulated eRob and a real one.

    python examples/pd_controller.py                                   # sim, the shipped config
    python examples/pd_controller.py --target -1.5 --render            # with the MuJoCo viewer
    python examples/pd_controller.py --backend hardware --port /dev/ttyUSB0
    python examples/pd_controller.py --config my_stand.toml --backend hardware

Against a served simulation (a pseudo-terminal that behaves like the real drive)::

    joints sim serve joints/configs/erob_reach.toml        # prints {"bus": "rs485", "port": "/dev/pts/N"}
    python examples/pd_controller.py --backend hardware --port /dev/pts/N
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

import envs

KP = 300.0  #: N*m/rad
KD = 30.0  #: N*m*s/rad


def pd_action(env: gym.Env[Any, Any], obs: np.ndarray, kp: float = KP, kd: float = KD) -> np.ndarray:
    """The torque-mode action of the PD law for an ErobReach observation (index 1: dq, 4: target - q)."""
    tau = kp * float(obs[4]) - kd * float(obs[1])
    return env.unwrapped.action_of([tau])  # N*m -> normalised action, clipped at the torque limit


def reach(env: gym.Env[Any, Any], *, target: float, start: float = 0.0, seed: int = 0, max_steps: int = 250,
          tolerance: float = 0.02, still: float = 0.05, hold: int = 5) -> tuple[bool, int, np.ndarray]:
    """Run the PD law from ``start`` until the joint has stayed within ``tolerance`` [rad] of
    ``target``, slower than ``still`` [rad/s], for ``hold`` steps. Returns (reached, steps, last obs)."""
    obs, _info = env.reset(seed=seed, options={"start": [start], "target": target})
    there = 0
    for k in range(1, max_steps + 1):
        obs, _r, terminated, truncated, info = env.step(pd_action(env, obs))
        there = there + 1 if abs(obs[4]) < tolerance and abs(obs[1]) < still else 0
        if there >= hold:
            return True, k, obs
        if terminated or truncated:
            fault = info.get("fault")
            if fault:
                print(f"drive fault on {fault['joint']}: {fault['name']} (0x{fault['code']:04X}) {fault['text']}; "
                      f"{fault['clears']}", file=sys.stderr)
            break
    return False, k, obs


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--backend", choices=("sim", "hardware"), default=None, help="overrides the config's backend")
    p.add_argument("--config", help="joints TOML config (default: the shipped erob_reach.toml)")
    p.add_argument("--port", help="serial port of the RS485 bus (hardware), e.g. /dev/ttyUSB0")
    p.add_argument("--target", type=float, default=1.0, help="target angle [rad]")
    p.add_argument("--start", type=float, default=0.0, help="start angle [rad]")
    p.add_argument("--render", action="store_true", help="show the MuJoCo viewer (needs a display)")
    args = p.parse_args(argv)

    config: Any = args.config
    if config is None:
        config = envs.default_config("erob_reach")
    if args.port:
        if isinstance(config, str):
            config = envs.configs.tomllib.loads(Path(config).read_text())
        for bus in config["buses"].values():
            bus["port"] = args.port
    env = gym.make("joints/ErobReach-v0", config=config, backend=args.backend, action_mode="torque",
                   render_mode="human" if args.render else None)
    try:
        ok, steps, obs = reach(env, target=args.target, start=args.start)
    finally:
        env.close()
    where = "sim" if env.unwrapped.sim else "hardware"
    print(f"[{where}] {'reached' if ok else 'did NOT reach'} {args.target:+.3f} rad after {steps} steps "
          f"({steps * env.unwrapped.dt:.2f} s): q = {obs[0]:+.4f} rad, dq = {obs[1]:+.4f} rad/s")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
