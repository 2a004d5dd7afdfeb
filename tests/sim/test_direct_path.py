"""The sim's direct path (message objects, no bytes) gives results identical to the byte path."""

from __future__ import annotations

import copy
import math

import pytest

pytest.importorskip("mujoco")

import joints
from joints.errors import DeviceRejected, ReplyTimeout
from joints.link.base import DirectFraming
from joints.link.modbus import ModbusLink
from joints.link.trace import Trace

CFG = {
    "backend": "sim",
    "sim": {"model": "erob_arm3.xml"},
    "buses": {"rs485": {"protocol": "modbus-rtu", "port": "/dev/ttyUSB0"}},
    "joints": {
        f"joint{i}": {"device": "erob", "bus": "rs485", "address": i,
                      "limits": {"position": [-3.0, 3.0], "velocity": 2.0, "torque": 60.0}}
        for i in (1, 2, 3)
    },
}


def _run(direct: bool) -> tuple[list[object], list[tuple[str, bytes, str]]]:
    cfg = copy.deepcopy(CFG)
    cfg["sim"]["direct"] = direct
    states: list[object] = []
    trace = Trace()
    with joints.open(cfg) as rig:
        link = rig.buses["rs485"].link
        assert isinstance(link, ModbusLink) and isinstance(link.framing, DirectFraming) is direct
        rig.trace(trace)
        j1, j2, j3 = (rig.joints[f"joint{i}"] for i in (1, 2, 3))
        for j in (j1, j2, j3):
            j.enable()
        j1.move_to(0.5, velocity=1.0)
        j2.set_velocity(0.3)
        j3.set_torque(5.0)
        for _ in range(30):
            rig.sleep(0.05)
            states.append(tuple(s for s in rig.read_states().values()))
        states.append(j2.read("error_code"))
        with pytest.raises(DeviceRejected):
            link.write_register(1, 0x0003, 1)  # no such register: the drive answers exception 02 either way
        states.append(rig.world.data.qpos.copy().tolist())
    records = [(r.direction, r.data, r.meaning) for r in trace]
    return states, records


def test_direct_path_is_identical_to_bytes() -> None:
    by_bytes, trace_bytes = _run(direct=False)
    direct, trace_direct = _run(direct=True)
    assert direct == by_bytes
    assert trace_direct == trace_bytes
    assert len(trace_bytes) > 100


def test_direct_path_times_out_on_missing_slave() -> None:
    cfg = copy.deepcopy(CFG)
    cfg["sim"]["direct"] = True
    with joints.open(cfg) as rig:
        link = rig.buses["rs485"].link
        assert isinstance(link, ModbusLink)
        with pytest.raises(ReplyTimeout):
            link.read_registers(9, 0x0060, 1)
        assert math.isfinite(rig.time)
