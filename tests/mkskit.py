"""MKS test helpers: a bare-motor model (a rotor without load) and rig configs for the MKS twins."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import joints

#: one MKS motor shaft with nothing on it (the profile adds the rotor inertia as armature)
MOTOR_XML = """<mujoco model="bare_motor">
  <option timestep="0.001" integrator="implicitfast"/>
  <worldbody>
    {bodies}
  </worldbody>
</mujoco>
"""
BODY = """<body name="rotor{i}" pos="{x} 0 0">
      <joint name="shaft{i}" type="hinge" axis="0 0 1"/>
      <geom type="cylinder" size="0.005 0.005" mass="0.001" contype="0" conaffinity="0"/>
    </body>"""


def motor_model(tmp_path: Path, n: int = 1) -> Path:
    """A model with ``n`` unloaded motor shafts ``shaft1`` .. ``shaftn``."""
    path = tmp_path / f"motors{n}.xml"
    path.write_text(MOTOR_XML.format(bodies="\n    ".join(BODY.format(i=i, x=0.05 * i) for i in range(1, n + 1))))
    return path


def motor_config(model: Path | str, *, n: int = 1, protocol: str = "mks-serial", device: str = "mks-servo42d",
                 backend: str = "sim", port: str = "/dev/null", joint: dict[str, Any] | None = None,
                 **bus: Any) -> dict[str, Any]:
    """``n`` MKS drives at addresses 1..n, each on its own bare shaft (``joint``: keys every joint gets,
    e.g. ``{"firmware": "v1.0.5"}``)."""
    return {
        "backend": backend,
        "sim": {"model": str(model)},
        "buses": {"rs485": {"protocol": protocol, "port": port, "baudrate": 38400, **bus}},
        "joints": {f"m{i}": {"device": device, "bus": "rs485", "address": i, "mjcf_joint": f"shaft{i}",
                             **(joint or {})}
                   for i in range(1, n + 1)},
    }


def axis_config(*, protocol: str = "mks-serial", device: str = "mks-servo42d", backend: str = "sim",
                port: str = "/dev/null", model: str = "mks_linear_axis.xml", firmware: str | None = None,
                **bus: Any) -> dict[str, Any]:
    """The linear axis of models/mks_linear_axis.xml: joint ``carriage``, lead 8 mm (``firmware``: the
    joint's firmware profile, None: the default)."""
    cfg = _axis_config(protocol=protocol, device=device, backend=backend, port=port, model=model, **bus)
    if firmware is not None:
        cfg["joints"]["carriage"]["firmware"] = firmware
    return cfg


def _axis_config(*, protocol: str, device: str, backend: str, port: str, model: str, **bus: Any) -> dict[str, Any]:
    return {
        "backend": backend,
        "sim": {"model": model},
        "buses": {"rs485": {"protocol": protocol, "port": port, "baudrate": 38400, **bus}},
        "joints": {"carriage": {"device": device, "bus": "rs485", "address": 1, "lead": 0.008,
                                "limits": {"position": [-0.07, 0.07], "velocity": 0.1, "torque": 300.0},
                                "motion": {"velocity": 0.04, "acceleration": 0.4, "deceleration": 0.4}}},
    }


def open_motor(tmp_path: Path, **kw: Any) -> joints.Rig:
    n = kw.get("n", 1)
    return joints.open(motor_config(motor_model(tmp_path, n), **kw))
