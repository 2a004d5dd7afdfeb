"""The sim's direct path (message objects, no bytes) gives results identical to the byte path,
refuses every reply the byte path refuses (with the same error), and takes the same simulated time."""

from __future__ import annotations

import copy
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("mujoco")

import joints
from joints import registry
from joints.codecs import modbus as mb
from joints.errors import DeviceRejected, JointsError, ReplyTimeout
from joints.link.base import DirectFraming
from joints.link.modbus import ModbusLink
from joints.link.trace import Trace

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

CONFIGS = Path(__file__).resolve().parents[2] / "joints" / "configs"

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


def _run(direct: bool, *, traced: bool) -> tuple[list[object], list[tuple[str, bytes, str]], int, int]:
    """States of a scripted session, its trace (if ``traced``), the link's transactions and the
    direct path's fast exchanges (requests answered without building a frame)."""
    cfg = copy.deepcopy(CFG)
    cfg["sim"]["direct"] = direct
    states: list[object] = []
    trace = Trace()
    with joints.open(cfg) as rig:
        link = rig.buses["rs485"].link
        assert isinstance(link, ModbusLink) and isinstance(link.framing, DirectFraming) is direct
        if traced:
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
        fast = link.framing.exchanges if isinstance(link.framing, DirectFraming) else 0
        transactions = link.transactions
    records = [(r.direction, r.data, r.meaning) for r in trace]
    return states, records, transactions, fast


def test_direct_path_is_identical_to_bytes() -> None:
    """Untraced, every request takes the fast path (no frame built) and the results are the byte path's."""
    by_bytes, _, sent_bytes, fast_bytes = _run(direct=False, traced=False)
    direct, _, sent_direct, fast_direct = _run(direct=True, traced=False)
    assert direct == by_bytes
    assert fast_bytes == 0
    assert sent_direct == sent_bytes > 100
    assert fast_direct == sent_direct  # every exchange took the fast path


def test_traced_direct_path_frames_what_the_byte_path_sends() -> None:
    """Traced, the direct path builds every frame (the fast path is off) and traces the byte path's frames."""
    by_bytes, trace_bytes, _, _ = _run(direct=False, traced=True)
    direct, trace_direct, _, fast_direct = _run(direct=True, traced=True)
    assert direct == by_bytes
    assert trace_direct == trace_bytes
    assert len(trace_bytes) > 100
    assert fast_direct == 0


def test_direct_path_times_out_on_missing_slave_after_the_time_the_byte_path_takes() -> None:
    """3 attempts, each waiting out its timeout and then the late window: the same simulated time on both paths."""
    took = {}
    for direct in (False, True):
        cfg = copy.deepcopy(CFG)
        cfg["sim"]["direct"] = direct
        with joints.open(cfg) as rig:
            link = rig.buses["rs485"].link
            assert isinstance(link, ModbusLink)
            policy = link.policy
            start = rig.time
            with pytest.raises(ReplyTimeout, match="after 3 attempts"):
                link.read_registers(9, 0x0060, 1)
            took[direct] = rig.time - start
    assert policy.late is None and policy.retries == 2
    waited = 3 * (policy.timeout + policy.timeout)  # per attempt: its timeout, then the late window
    assert took[True] == pytest.approx(took[False], abs=1e-9)
    assert waited - 1e-9 <= took[False] <= waited + 0.05, took  # at most three requests' wire time more


# -- replies the wire cannot carry -----------------------------------------------------------------

#: protocols whose sim has a direct path -> the shipped config of each device family on them
#: (the bus's protocol set to it); a protocol given a direct path in the registry must be added here
DIRECT: dict[str, tuple[str, ...]] = {"modbus-rtu": ("erob_reach.toml", "zlac_diffdrive.toml", "mks_axis.toml")}
#: a read the first joint's drive answers: config -> (register address, count, input registers)
READS: dict[str, tuple[int, int, bool]] = {
    "erob_reach.toml": (0x0060, 2, False),  # actual position (Hi/Lo)
    "zlac_diffdrive.toml": (0x2000, 1, False),  # communication offline time
    "mks_axis.toml": (0x0031, 3, True),  # FC04 encoder addition (int48)
}

#: a twin bug: given the request and the twin's reply, the reply it sends instead
Plant = Callable[[Any, Any], Any]
PLANTS: dict[str, Plant] = {
    # the case: a register read answered with a value no register holds
    "register value 65536": lambda req, rep: mb.ReadRegistersReply(req.slave, req.function, (65536,) * req.count),
    "negative register value": lambda req, rep: mb.ReadRegistersReply(req.slave, req.function, (-1,) * req.count),
    "register value not an integer": lambda req, rep: mb.ReadRegistersReply(req.slave, req.function,
                                                                            (1.5,) * req.count),
    "more registers than asked": lambda req, rep: mb.ReadRegistersReply(req.slave, req.function,
                                                                        (0,) * (req.count + 1)),
    "130 registers (over 125)": lambda req, rep: mb.ReadRegistersReply(req.slave, req.function, (0,) * 130),
    "exception code 300": lambda req, rep: mb.ExceptionReply(req.slave, req.function, 300),
    "exception to a function no reply has": lambda req, rep: mb.ExceptionReply(req.slave, 0x55, 1),
}


def _config(name: str, protocol: str, direct: bool) -> dict[str, Any]:
    data: dict[str, Any] = tomllib.loads((CONFIGS / name).read_text())
    data["backend"] = "sim"
    data["sim"]["direct"] = direct
    for bus in data["buses"].values():
        bus["protocol"] = protocol
    return data


def _read_with(name: str, protocol: str, direct: bool, plant: Plant) -> tuple[Any, int]:
    """Read :data:`READS` of the first joint's drive with ``plant`` in its twin's front: the values or
    the error raised, and the direct path's fast exchanges."""
    address, count, input_registers = READS[name]
    with joints.open(_config(name, protocol, direct)) as rig:
        joint = next(iter(rig.config.joints.values()))
        link = rig.buses[joint.bus].link
        front = rig.world.buses[joint.bus].slaves[joint.address]
        handle = front.handle
        front.handle = lambda request: plant(request, handle(request))
        fast = link.framing.exchanges if isinstance(link.framing, DirectFraming) else 0
        try:
            got: Any = link.read_registers(joint.address, address, count, input_registers=input_registers)
        except JointsError as exc:
            got = exc
        if isinstance(link.framing, DirectFraming):
            fast = link.framing.exchanges - fast
        return got, fast


def test_every_protocol_with_a_direct_path_has_its_planted_replies() -> None:
    assert {p.name for p in registry.PROTOCOLS.values() if p.direct} == set(DIRECT)


@pytest.mark.parametrize("plant", list(PLANTS))
@pytest.mark.parametrize(("protocol", "config"), [(p, c) for p, cs in DIRECT.items() for c in cs])
def test_a_reply_the_wire_refuses_raises_the_same_error_on_the_direct_path(protocol: str, config: str,
                                                                           plant: str) -> None:
    by_bytes, _ = _read_with(config, protocol, False, PLANTS[plant])
    direct, fast = _read_with(config, protocol, True, PLANTS[plant])
    assert isinstance(by_bytes, JointsError), f"the byte path accepted {plant}: {by_bytes!r}"
    assert type(direct) is type(by_bytes), (direct, by_bytes)
    assert str(direct) == str(by_bytes)
    assert fast >= 1  # the planted reply came over the fast path


def test_a_plain_reply_crosses_the_direct_path_as_the_byte_path_decodes_it() -> None:
    """The control of the plants: the same read without a bug gives the same values on both paths."""
    def keep(request: Any, reply: Any) -> Any:
        return reply

    for protocol, configs in DIRECT.items():
        for config in configs:
            by_bytes, _ = _read_with(config, protocol, False, keep)
            direct, fast = _read_with(config, protocol, True, keep)
            assert direct == by_bytes and isinstance(direct, tuple) and fast == 1, (config, direct, by_bytes)
