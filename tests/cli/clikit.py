"""Helpers of the command-line tests: one world with a drive of every family on every protocol.

The world (``MODEL``): eRob joints a, b (Modbus RTU), c (eRob CAN) and o (CANopen); a ZLAC8015D's
two wheels l, r (Modbus RTU); MKS SERVO42D m (Modbus RTU mode) and SERVO57D n (native protocol).
Bus rs485 holds a, b, l/r and m - four drives of three families on one Modbus line.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

MODEL = """<mujoco model="every_family">
  <option timestep="0.001"/>
  <worldbody>
    <body name="a"><joint name="a" type="hinge" axis="0 0 1"/><geom type="cylinder" size="0.05 0.05" mass="1"/></body>
    <body name="b" pos="0.3 0 0"><joint name="b" type="hinge" axis="0 0 1"/>
      <geom type="cylinder" size="0.05 0.05" mass="1"/></body>
    <body name="c" pos="0.6 0 0"><joint name="c" type="hinge" axis="0 0 1"/>
      <geom type="cylinder" size="0.05 0.05" mass="1"/></body>
    <body name="o" pos="0.9 0 0"><joint name="o" type="hinge" axis="0 0 1"/>
      <geom type="cylinder" size="0.05 0.05" mass="1"/></body>
    <body name="l" pos="0 1 0.1"><joint name="l" type="hinge" axis="0 1 0"/>
      <geom type="cylinder" size="0.1 0.02" mass="2"/></body>
    <body name="r" pos="0.3 1 0.1"><joint name="r" type="hinge" axis="0 1 0"/>
      <geom type="cylinder" size="0.1 0.02" mass="2"/></body>
    <body name="m" pos="0 2 0"><joint name="m" type="hinge" axis="0 0 1"/>
      <geom type="cylinder" size="0.03 0.03" mass="0.3"/></body>
    <body name="n" pos="0.3 2 0"><joint name="n" type="hinge" axis="0 0 1"/>
      <geom type="cylinder" size="0.03 0.03" mass="0.3"/></body>
  </worldbody>
</mujoco>
"""

#: reply timeouts that only bound a failure: a served twin answers within ~10 ms, but on a loaded machine (run queue
#: 8-9 on 2 cores) the OS delays the host or the served process: a reply came up to 0.84 s (99.9th percentile)
#: and 7 s (once in 2500) after its request while the server took at most 45 ms from reading it to answering
BUSES = """
[buses.rs485]
protocol = "modbus-rtu"
timeout = 2.0
[buses.mks]
protocol = "mks-serial"
baudrate = 38400
timeout = 2.0
[buses.can]
protocol = "erob-can"
timeout = 2.0
[buses.co]
protocol = "canopen"
timeout = 2.0
"""

LIMITS = 'limits = { position = [-3.0, 3.0], velocity = 2.0, torque = 20.0 }\n'
JOINTS = (
    '[joints.a]\ndevice = "erob"\nbus = "rs485"\naddress = 1\n' + LIMITS
    + '[joints.b]\ndevice = "erob"\nbus = "rs485"\naddress = 2\n' + LIMITS
    + '[joints.l]\ndevice = "zlac8015d"\nbus = "rs485"\naddress = 3\nchannel = "left"\n'
    + '[joints.r]\ndevice = "zlac8015d"\nbus = "rs485"\naddress = 3\nchannel = "right"\n'
    + '[joints.m]\ndevice = "mks-servo42d"\nbus = "rs485"\naddress = 4\n'
    + '[joints.n]\ndevice = "mks-servo57d"\nbus = "mks"\naddress = 5\n'
    + '[joints.c]\ndevice = "erob"\nbus = "can"\naddress = 6\n' + LIMITS
    + '[joints.o]\ndevice = "erob"\nbus = "co"\naddress = 7\n' + LIMITS
)
#: joint -> (family, protocol) of the world above
FAMILY_OF = {"a": ("erob", "modbus-rtu"), "b": ("erob", "modbus-rtu"), "l": ("zlac8015d", "modbus-rtu"),
             "r": ("zlac8015d", "modbus-rtu"), "m": ("mks", "modbus-rtu"), "n": ("mks", "mks-serial"),
             "c": ("erob", "erob-can"), "o": ("erob", "canopen")}


def write_world(tmp: Path, *, buses: str = BUSES, joints: str = JOINTS, name: str = "world.toml") -> Path:
    """The sim config of the world (its model next to it)."""
    (tmp / "every_family.xml").write_text(MODEL, encoding="utf-8")
    cfg = tmp / name
    cfg.write_text(f'backend = "sim"\n[sim]\nmodel = "every_family.xml"\n{buses}\n{joints}', encoding="utf-8")
    return cfg


def joints_cmd(*args: str, timeout: float = 120.0, shell_tail: str | None = None) -> subprocess.CompletedProcess[str]:
    """``python -m joints ARGS`` in another process (``shell_tail``: piped into this shell command)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("JOINTS_BACKEND", None)
    if shell_tail is None:
        return subprocess.run([sys.executable, "-m", "joints", *args], capture_output=True, text=True, cwd=ROOT,
                              env=env, timeout=timeout, check=False)
    import shlex

    line = " ".join(shlex.quote(a) for a in [sys.executable, "-m", "joints", *args]) + " | " + shell_tail
    return subprocess.run(["/bin/sh", "-c", line], capture_output=True, text=True, cwd=ROOT, env=env,
                          timeout=timeout, check=False)
