"""Build simulated worlds in tests without a config file (the rig does the same from a config)."""

from __future__ import annotations

import contextlib
import json
import random
import select
import subprocess
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from serving import stop

from joints import registry
from joints.config import BusConfig
from joints.sim.world import BusSpec, DriveSpec, World

ROOT = Path(__file__).resolve().parents[1]


def bus_spec(name: str = "rs485", protocol: str = "modbus-rtu", **settings: Any) -> BusSpec:
    """The sim side of a bus; ``settings`` are bus config keys (e.g. ``bitrate``)."""
    p = registry.protocol(protocol)
    cfg = BusConfig(name, protocol, **settings)
    return BusSpec(name, protocol, lambda: p.device_bus(cfg), p.sim_transport)


def drive(name: str, address: int, profile: Any, *, device: str = "erob", bus: str = "rs485",
          protocol: str = "modbus-rtu", mjcf_joint: str | None = None, channel: str | None = None) -> DriveSpec:
    return DriveSpec(bus=bus, name=name, mjcf_joint=mjcf_joint or name, address=address, profile=profile,
                     device=device, maker=registry.family(device), protocol=protocol, channel=channel)


def world(model: str, drives: Sequence[DriveSpec], *, timestep: float = 0.001) -> World:
    buses = {d.bus: bus_spec(d.bus, d.protocol) for d in drives}
    return World(model, drives, buses=buses, timestep=timestep)


def erob_world(model: str, names: Sequence[str], profile: Any, *, timestep: float = 0.001) -> World:
    """eRob joints ``names`` at Modbus addresses 1, 2, ... on bus "rs485"."""
    return world(model, [drive(n, i + 1, profile) for i, n in enumerate(names)], timestep=timestep)


@contextlib.contextmanager
def served_can(config: Path, startup: float = 30.0) -> Iterator[dict[str, Any]]:
    """`joints sim serve CONFIG` in another process; yield what it printed for its first bus (interface,
    channel, udp_port). The server must print within ``startup`` seconds and exit with 0 on SIGTERM."""
    proc = subprocess.Popen([sys.executable, "-m", "joints", "sim", "serve", str(config)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], startup)
        assert ready, f"joints sim serve printed nothing within {startup:.0f} s"
        assert proc.stdout is not None
        yield json.loads(proc.stdout.readline())
    finally:
        stop(proc)


def canopen_arm() -> Any:
    """``joints/ErobArmReach-v0`` on its CANopen bus at the bench's 20 ms (``joints.bench._baseline_config``): the
    arm the CANopen read and set-point tests step."""
    import gymnasium as gym

    import envs  # noqa: F401  (registers the joints/ ids)
    from joints.bench import BASELINE_PERIOD, _baseline_config

    found = _baseline_config("joints/ErobArmReach-v0")
    assert found is not None and found[1].startswith("canopen"), found
    return gym.make("joints/ErobArmReach-v0", config=found[0], control_period=BASELINE_PERIOD)


def sensor_reads(seed: int, n: int) -> list[tuple[float, float, float, float]]:
    """``n`` sensor reads (t, q, v, i) from ``seed``: read times repeat (one draw of the sample age per read time),
    speeds and currents are sometimes exactly 0 (no filter step, no current noise)."""
    rng = random.Random(seed)
    out = []
    t = 0.0
    for k in range(n):
        if k % 3:
            t += rng.choice((0.0, 1e-3, 0.02))
        v = 0.0 if k % 5 == 0 else rng.uniform(-20.0, 20.0)
        i = 0.0 if k % 7 == 0 else rng.uniform(-8.0, 8.0)
        out.append((t, rng.uniform(-50.0, 50.0), v, i))
    return out
