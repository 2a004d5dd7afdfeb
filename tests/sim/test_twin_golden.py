"""The twins' trajectories are exactly those recorded before their loops moved into array kernels.

Each scenario drives emulated eRob / ZLAC drives through the real host drivers (every mode, the
profile generator's move / continuous / repetitive legs, stops, emergency stop, the protections,
the brake, the watchdog) and the three gymnasium envs (random actions, domain randomisation), and
hashes every recorded float (physics state, torques, status registers, observations) bit for bit.
``tests/data/twin_golden.json`` holds the hashes made with the twins as they were before issue 23;
``JOINTS_RECORD_GOLDEN=1 python -m pytest tests/sim/test_twin_golden.py`` records them again (only
for a deliberate change of behaviour). Each scenario runs with the compiled kernels and with the
same kernels as plain Python, and with the world's per-substep loop: all give the same bits.
"""

from __future__ import annotations

import hashlib
import json
import os
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")

from joints.devices.erob.profiles import profile
from joints.devices.erob.registers import MotionMode
from joints.drivers.erob_modbus import ErobModbusDriver
from joints.link.modbus import ModbusLink
from joints.sim import kernel
from simkit import erob_world

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "twin_golden.json"
RECORD = os.environ.get("JOINTS_RECORD_GOLDEN") == "1"
PROFILE = profile("eRob80H100")


class Recorder:
    """Hashes floats and ints in order; keeps a few for a readable diff."""

    def __init__(self) -> None:
        self.h = hashlib.sha256()
        self.n = 0
        self.last: list[float] = []

    def add(self, *values: Any) -> None:
        flat: list[float] = []
        for v in values:
            if isinstance(v, np.ndarray):
                flat.extend(float(x) for x in v.reshape(-1))
            elif isinstance(v, (list, tuple)):
                flat.extend(float(x) for x in v)
            elif v is None:
                flat.append(float("nan"))
            else:
                flat.append(float(v))
        self.h.update(struct.pack(f"<{len(flat)}d", *flat))
        self.n += len(flat)
        self.last = flat[-6:]

    def world(self, w: Any) -> None:
        self.add(w.time, w.data.qpos, w.data.qvel, w.data.ctrl)

    def result(self) -> dict[str, Any]:
        return {"sha256": self.h.hexdigest(), "values": self.n, "last": self.last}


# -- eRob through the Modbus driver ----------------------------------------------------------------


def _erob(model: str = "erob_stand.xml", names: tuple[str, ...] = ("joint1",)) -> tuple[Any, dict[str, Any]]:
    w = erob_world(model, names, PROFILE)
    link = ModbusLink(w.transport("rs485"), clock=w.clock)
    drv = {n: ErobModbusDriver(link, i + 1, profile=PROFILE, clock=w.clock, name=n) for i, n in enumerate(names)}
    return w, drv


def _run(rec: Recorder, w: Any, drvs: list[Any], seconds: float, period: float = 0.01) -> None:
    for _ in range(round(seconds / period)):
        w.advance(period)
        rec.world(w)
        for d in drvs:
            s = d.state()
            rec.add(s.position, s.velocity, s.current, s.fault, s.enabled, s.moving, *s.extra.values())


def erob_position(rec: Recorder) -> None:
    w, drv = _erob()
    d = drv["joint1"]
    d.enable()
    _run(rec, w, [d], 0.6)
    d.move_to(200_000, speed=80_000, acceleration=150_000, deceleration=90_000)
    _run(rec, w, [d], 1.5)
    d.move_to(-60_000, speed=300_000, acceleration=400_000, deceleration=400_000)
    _run(rec, w, [d], 0.3)
    d.move_to(10_000, speed=50_000, acceleration=100_000, deceleration=100_000)  # redirected mid-move
    _run(rec, w, [d], 1.0)
    d.move_by(30_000, speed=60_000, acceleration=200_000, deceleration=200_000)
    _run(rec, w, [d], 1.0)
    d.stop()
    _run(rec, w, [d], 0.2)
    d.disable()
    _run(rec, w, [d], 0.3)


def erob_continuous_repetitive(rec: Recorder) -> None:
    w, drv = _erob()
    d = drv["joint1"]
    d.enable()
    _run(rec, w, [d], 0.6)
    d.move_continuous(60_000, acceleration=100_000, deceleration=150_000)
    _run(rec, w, [d], 0.8)
    d.move_continuous(-40_000, acceleration=100_000, deceleration=150_000)
    _run(rec, w, [d], 1.0)
    d.stop()
    _run(rec, w, [d], 0.5)
    d.move_repetitive(90_000, speed=120_000, acceleration=300_000, deceleration=300_000, dwell=4000)
    _run(rec, w, [d], 2.5)
    d.stop_repetitive()
    _run(rec, w, [d], 1.5)
    d.move_continuous(80_000, acceleration=200_000, deceleration=200_000)
    _run(rec, w, [d], 0.5)
    d.emergency_stop()
    _run(rec, w, [d], 0.3)


def erob_speed_torque(rec: Recorder) -> None:
    w, drv = _erob()
    d = drv["joint1"]
    d.configure_velocity(acceleration=200_000, deceleration=100_000)
    d.enable()
    _run(rec, w, [d], 0.6)
    d.set_velocity(90_000)
    _run(rec, w, [d], 0.6)
    d.set_velocity(-70_000)
    _run(rec, w, [d], 1.0)
    d.stop()
    _run(rec, w, [d], 0.5)
    d.disable()
    d.configure_torque(max_speed=40_000)
    d.enable()
    _run(rec, w, [d], 0.6)
    d.set_current(2500)
    _run(rec, w, [d], 1.0)
    d.set_current(-4000)
    _run(rec, w, [d], 0.8)
    d.set_current(0)
    _run(rec, w, [d], 0.3)
    d.emergency_stop()
    _run(rec, w, [d], 0.2)


def erob_arm_faults(rec: Recorder) -> None:
    w, drv = _erob("erob_arm3.xml", ("joint1", "joint2", "joint3"))
    ds = list(drv.values())
    d2 = drv["joint2"]
    d2.write("peak_current", 300)
    d2.write("max_position_error", 5000)
    for d in ds:
        d.enable()
    _run(rec, w, ds, 0.6)
    drv["joint1"].move_to(100_000, speed=100_000, acceleration=200_000, deceleration=200_000)
    drv["joint3"].move_to(-80_000, speed=100_000, acceleration=200_000, deceleration=200_000)
    d2.move_to(-50_000, speed=50_000, acceleration=100_000, deceleration=100_000)
    _run(rec, w, ds, 1.5)  # joint2 trips its following error; the brake holds it
    d2.write("peak_current", round(PROFILE.peak_current * 1000))
    d2.clear_errors()
    d2.enable()
    _run(rec, w, ds, 1.0)
    # stall against a hard stop, then the watchdog
    w2, drv2 = _erob()
    d = drv2["joint1"]
    jid = w2.model.joint("joint1").id
    w2.model.jnt_limited[jid] = True
    w2.model.jnt_range[jid] = [-0.01, 0.01]
    d.write("struck_time", 2000)
    d.configure_torque(max_speed=0)
    d.enable()
    _run(rec, w2, [d], 0.6)
    d.set_current(5000)
    _run(rec, w2, [d], 0.4)
    d.clear_errors()
    w2.model.jnt_limited[jid] = False
    d.set_communication_timeout(100)
    d.configure_position(MotionMode.ABSOLUTE, speed=50_000, acceleration=100_000, deceleration=100_000)
    d.enable()
    _run(rec, w2, [d], 0.6)
    d.move_continuous(50_000, acceleration=200_000, deceleration=200_000)
    _run(rec, w2, [d], 0.3)
    for _ in range(300):  # silence: the watchdog trips, the brake stops the joint
        w2.advance(0.001)
        rec.world(w2)
        rec.add(w2.drives["joint1"].fault)
    d.clear_errors()
    w2.drives["joint1"].write("release_brake", 1)  # CAN only (0x014F): straight to the firmware
    _run(rec, w2, [d], 0.2)


# -- the envs -------------------------------------------------------------------------------------


def _env(env_id: str, steps: int, **kwargs: Any) -> Callable[[Recorder], None]:
    def scenario(rec: Recorder) -> None:
        import gymnasium as gym

        import envs  # noqa: F401 - registers the ids

        env = gym.make(env_id, **kwargs)
        try:
            rng = np.random.default_rng(5)
            obs, _ = env.reset(seed=3)
            rec.add(obs)
            space = env.action_space
            for _ in range(steps):
                obs, r, term, trunc, _info = env.step(rng.uniform(space.low, space.high).astype(space.dtype))
                rec.add(obs, r, term, trunc)
                rec.world(env.unwrapped.rig.sim)
                if term or trunc:
                    obs, _ = env.reset()
                    rec.add(obs)
        finally:
            env.close()

    return scenario


SCENARIOS: dict[str, Callable[[Recorder], None]] = {
    "erob_position": erob_position,
    "erob_continuous_repetitive": erob_continuous_repetitive,
    "erob_speed_torque": erob_speed_torque,
    "erob_arm_faults": erob_arm_faults,
    "env_reach_position": _env("joints/ErobReach-v0", 300),
    "env_reach_velocity": _env("joints/ErobReach-v0", 300, action_mode="velocity"),
    "env_reach_torque_dr": _env("joints/ErobReach-v0", 300, action_mode="torque", domain_randomization=True),
    "env_arm_position_dr": _env("joints/ErobArmReach-v0", 300, domain_randomization=True),
    "env_arm_torque": _env("joints/ErobArmReach-v0", 200, action_mode="torque"),
    "env_diffdrive": _env("joints/DiffDriveGoal-v0", 300),
    "env_diffdrive_dr": _env("joints/DiffDriveGoal-v0", 300, domain_randomization=True),
}


def _golden() -> dict[str, Any]:
    return json.loads(GOLDEN.read_text()) if GOLDEN.is_file() else {}


MODES = ["python", "compiled"] if kernel.AVAILABLE else ["python"]


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", list(SCENARIOS))
def test_trajectory_is_the_recorded_one(name: str, mode: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Compiled kernels (fused N-substep calls) and the same kernels as Python: the recorded bits."""
    monkeypatch.setenv("JOINTS_JIT", "1" if mode == "compiled" else "0")
    rec = Recorder()
    SCENARIOS[name](rec)
    got = rec.result()
    if RECORD:
        data = _golden()
        data[name] = got
        GOLDEN.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
        return
    want = _golden()[name]
    assert got["values"] == want["values"], (got, want)
    assert got["sha256"] == want["sha256"], (got, want)
