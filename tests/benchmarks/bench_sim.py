"""Benchmark: simulated physics steps per second with drive emulation, against raw mj_step.

Prints, for the 1-joint stand and the 3-joint arm, substeps/s of World.step (every drive's loops
run every substep, drives enabled and moving) and of a plain Python loop of mujoco.mj_step on the
SAME compiled model, measured in the same run, and their ratio (goal: >= 0.5).

    python tests/benchmarks/bench_sim.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import mujoco

from joints.bench import median_pair, paired
from joints.devices.erob.profiles import profile
from joints.drivers.erob_modbus import ErobModbusDriver
from joints.link.modbus import ModbusLink
from joints.sim.world import World

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/: the simkit helpers
from simkit import erob_world

STEPS = 20000
REPEATS = 5


def _world(model: str, names: list[str]) -> World:
    w = erob_world(model, names, profile("eRob80H100"))
    for i, n in enumerate(names):
        d = ErobModbusDriver(ModbusLink(w.transport("rs485"), clock=w.clock), i + 1, clock=w.clock)
        d.enable()
        d.move_continuous(20000, acceleration=50000, deceleration=50000)
    w.advance(0.6)
    return w


def bench(model: str, names: list[str]) -> None:
    w = _world(model, names)
    m = w.model
    raw_d = mujoco.MjData(m)

    def ours() -> float:
        t = time.perf_counter()
        w.step(STEPS)
        return time.perf_counter() - t

    def raw() -> float:
        t = time.perf_counter()
        for _ in range(STEPS):
            mujoco.mj_step(m, raw_d)
        return time.perf_counter() - t

    # in pairs, the reference right after ours (load hits both alike); the median pair's figures
    pairs = paired([ours, raw], REPEATS)
    t_ours, t_raw = pairs[median_pair(len(pairs), lambda i: pairs[i][0] / pairs[i][1])]
    ours, ref = STEPS / t_ours, STEPS / t_raw
    print(f"{model:<16} {len(names)} joint(s): World.step {ours:>9.0f} steps/s | raw mj_step {ref:>9.0f} steps/s "
          f"| ratio {ours / ref:.2f} (goal >= 0.5) | real-time factor {ours * w.timestep:.0f}x")


if __name__ == "__main__":
    bench("erob_stand.xml", ["joint1"])
    bench("erob_arm3.xml", ["joint1", "joint2", "joint3"])
