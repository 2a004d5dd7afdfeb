"""One script, one eRob joint: `protocol = "modbus-rtu"` and `protocol = "erob-can"` (a config change only)
end at the same position and show the same JointState fields."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import pytest

pytest.importorskip("mujoco")

import joints
from joints.joint import JointState


def config(protocol: str) -> dict[str, Any]:
    return {
        "backend": "sim",
        "sim": {"model": "erob_stand.xml", "timestep": 0.001},
        # ideal buses: the protocols' semantics compared; on the wire their timing differs (a state read
        # during the speed run comes milliseconds later on RS485), and so do positions sampled in motion
        "buses": {"bus": {"protocol": protocol, "timing": "ideal"}},
        "joints": {"joint1": {"device": "erob", "model": "eRob80H100", "bus": "bus", "address": 2,
                              "limits": {"position": [-3.1, 3.1], "velocity": 2.0, "torque": 20.0}}},
    }


def script(rig: joints.Rig) -> list[JointState]:
    """The same user script for both protocols: position moves, a speed run, a torque pulse, states."""
    j = rig.joints["joint1"]
    out = [j.state()]
    j.enable()
    j.move_to(0.8, velocity=1.0, acceleration=4.0, deceleration=4.0)
    out.append(j.wait(timeout=20, poll=0.02))
    j.move_to(-0.3, velocity=1.5, acceleration=6.0, deceleration=6.0)
    out.append(j.wait(timeout=20, poll=0.02))
    j.set_velocity(0.6, acceleration=3.0)
    rig.sleep(1.0)
    out.append(j.state())
    j.stop()
    out.append(j.wait(timeout=10, poll=0.02))
    j.move_to(0.25, velocity=1.0, acceleration=4.0, deceleration=4.0)
    out.append(j.wait(timeout=20, poll=0.02))
    j.disable()
    out.append(j.state())
    return out


def test_same_script_same_end_position_and_fields() -> None:
    with joints.open(config("modbus-rtu")) as rig:
        modbus = script(rig)
    with joints.open(config("erob-can")) as rig:
        can = script(rig)
    assert can[-1].position == pytest.approx(modbus[-1].position, abs=math.radians(0.1))
    assert abs(can[-1].position - 0.25) < math.radians(0.1)
    names = [f.name for f in dataclasses.fields(JointState)]
    for m, c in zip(modbus, can, strict=True):
        for name in names:
            a, b = getattr(m, name), getattr(c, name)
            assert type(a) is type(b), (name, a, b)
        assert (m.enabled, m.moving, m.fault) == (c.enabled, c.moving, c.fault)
        assert c.position == pytest.approx(m.position, abs=math.radians(0.2))
        assert c.temperature == pytest.approx(m.temperature, abs=1.0)
    # the speed run: both at the commanded 0.6 rad/s
    assert modbus[3].velocity == pytest.approx(0.6, rel=0.03) and can[3].velocity == pytest.approx(0.6, rel=0.03)
