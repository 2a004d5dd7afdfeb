"""The CPU time of a sensor's status read (``Sensor.sense``) and of an eRob env step, of whichever checkout is on
``PYTHONPATH``: run it once per checkout, alternating, pinned (``taskset -c 1``).

Not a test (pytest does not collect it): a measuring tool. ``python tests/sim/sensor_probe.py CASE [ROUNDS]``
with CASE ``sense`` (the eRob profile's model: 1 ms velocity window, 0.02 A current noise, current flowing),
``reseed`` (``Sensor.reseed()``: the stream seeded again with its seed, what a world reset costs per sensor),
``seed`` (``Sensor.reseed(k)``, each call a new seed), ``erob`` (``ErobReach-v0``, position mode, its shipped
Modbus at 1 kHz) or ``erobcan`` (the same env on its CAN protocol at 20 ms, the bench's row). Prints the best and median CPU microseconds per call / step
(``time.thread_time`` around each block, resets at episode ends included) over ROUNDS blocks, and a digest of every output (the same on both checkouts: same bits).
"""

from __future__ import annotations

import hashlib
import math
import statistics
import sys
import time
from typing import Any

import numpy as np


def _sense(rounds: int) -> tuple[list[float], str]:
    from joints.sim.sensors import Sensor, SensorModel

    s = Sensor(SensorModel(velocity_window=0.001, current_noise=0.02), "erob:1", 524288 / (2 * math.pi))
    s.reseed(0)
    rng = np.random.default_rng(0)
    n = 20_000
    reads = [(k * 1e-3, float(q), float(v), float(i)) for k, (q, v, i) in
             enumerate(rng.uniform(-3.0, 3.0, (n, 3)))]
    sense = s.sense
    digest = hashlib.sha256()
    times = []
    for _ in range(rounds):
        t0 = time.thread_time()
        out = [sense(t, q, v, i) for t, q, v, i in reads]
        times.append((time.thread_time() - t0) / n)
        digest.update(np.array(out).tobytes())
    return times, digest.hexdigest()[:16]


def _reseed(rounds: int, new: bool) -> tuple[list[float], str]:
    from joints.sim.sensors import Sensor, SensorModel

    s = Sensor(SensorModel(velocity_window=0.001, current_noise=0.02), "erob:1", 524288 / (2 * math.pi))
    n = 2000
    digest = hashlib.sha256()
    times = []
    for r in range(rounds):
        reseed = s.reseed
        t0 = time.thread_time()
        for k in range(r * n, (r + 1) * n):
            reseed(k if new else None)
        times.append((time.thread_time() - t0) / n)
        digest.update(repr(s.stream.getstate()).encode())
        s.sense(0.0, 0.1, 1.0, 0.5)
        digest.update(repr(s.stream.getstate()).encode())
    return times, digest.hexdigest()[:16]


def _env(case: str, rounds: int) -> tuple[list[float], str]:
    import gymnasium as gym

    import envs  # noqa: F401 - registers the envs
    from joints import bench

    env_id = "joints/ErobReach-v0"
    if case == "erob":
        env: Any = gym.make(f"{bench.ENV_MODULE}:{env_id}")
    else:
        found = bench._baseline_config(env_id)
        assert found is not None
        env = gym.make(f"{bench.ENV_MODULE}:{env_id}", config=found[0], control_period=bench.BASELINE_PERIOD)
    steps = 300
    space = env.action_space
    actions = np.random.default_rng(0).uniform(space.low, space.high, (steps, *space.shape)).astype(space.dtype)
    obs, _ = env.reset(seed=0)
    digest = hashlib.sha256()
    times = []
    step = env.step
    for _ in range(rounds):
        record = []
        t0 = time.thread_time()
        for a in actions:
            obs, reward, terminated, truncated, _ = step(a)
            record.append((obs, reward))
            if terminated or truncated:
                obs, _ = env.reset()
        times.append((time.thread_time() - t0) / steps)
        for obs, reward in record:
            digest.update(obs.tobytes() + np.float64(reward).tobytes())
    env.close()
    return times, digest.hexdigest()[:16]


def main() -> None:
    case = sys.argv[1]
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 10
    import joints

    if case == "sense":
        times, digest = _sense(rounds)
    elif case in ("reseed", "seed"):
        times, digest = _reseed(rounds, new=case == "seed")
    else:
        times, digest = _env(case, rounds)
    us = sorted(t * 1e6 for t in times[1:])  # the first block warms up
    print(f"{case} {joints.__file__.rsplit('/joints/', 1)[0]}: best {us[0]:.3f} us, median "
          f"{statistics.median(us):.3f} us, digest {digest}")


if __name__ == "__main__":
    main()
