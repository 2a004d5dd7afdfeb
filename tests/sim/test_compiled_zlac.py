"""The ZLAC8015D's steady step (joints/DiffDriveGoal-v0) on the compiled path gives the driver path's bits.

What this covers beyond tests/sim/test_compiled_path.py (which runs the same env on both paths):

* the compiled path's own work for a drive of two wheels - :meth:`ZlacDrive.velocity_words` (the plan as
  register values) and its FC16s without name lookups - is counted as taken, with numba and with
  ``JOINTS_COMPILED=0`` (the twin's kernel op :func:`joints.sim.zlac_kernel.set_velocity_target` then runs as
  Python), and both give the same bits;
* the twin's one-pass write of a light block (:meth:`ZlacFirmware._write_light`), which both paths reach, is
  taken every step and gives what the general :meth:`Firmware.write_many` gives, refusals included;
* wrong replies planted on either path leave both alike.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401 - registers the joints/ envs
import joints
from joints.codecs import modbus as mb
from joints.devices.zlac.profile import HubMotorProfile
from joints.devices.zlac.registers import ZLAC8015D
from joints.drivers.zlac_modbus import RAMP_NAMES, TARGET_NAMES, ZlacDrive
from joints.errors import ParameterRefused
from joints.sim import kernel, zlac_kernel
from joints.sim.firmware import Firmware
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
from joints.sim.zlac import ZlacFirmware

ENV = "joints/DiffDriveGoal-v0"


class _Counts:
    """Calls of the ZLAC pieces the steady step should take (wrapped, not replaced). Wrapping the twin's light
    write replaces a stock method, which turns the one-call exchange off (it then goes the lane's way)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, *, light: bool) -> None:
        self.n = {"velocity_words": 0, "light": 0, "light_refused": 0}
        words, write_light = ZlacDrive.velocity_words, ZlacFirmware._write_light

        def velocity_words(drive: ZlacDrive, *args: Any) -> Any:
            self.n["velocity_words"] += 1
            return words(drive, *args)

        def counted(fw: ZlacFirmware, items: Any) -> bool:
            done = write_light(fw, items)
            self.n["light" if done else "light_refused"] += 1
            return done

        monkeypatch.setattr(ZlacDrive, "velocity_words", velocity_words)
        if light:
            monkeypatch.setattr(ZlacFirmware, "_write_light", counted)


def _info(info: dict[str, Any]) -> list[tuple[str, Any]]:
    return [(k, (v.dtype.str, v.tobytes()) if isinstance(v, np.ndarray) else repr(v)) for k, v in sorted(info.items())]


def _run(compiled: bool, steps: int = 80, counts: _Counts | None = None, hold: bool | None = None,
         **kwargs: Any) -> dict[str, Any]:
    env = gym.make(ENV, compiled_path=compiled, **kwargs)
    u: Any = env.unwrapped
    if hold is not None:  # the world's sleeps booked (World.hold) or stepped at once, whatever the path set
        u.rig.sim.hold_sleeps = hold
    try:
        out: dict[str, Any] = {"steps": []}
        before = dict(counts.n) if counts is not None else {}
        obs, info = env.reset(seed=3)
        out["reset"] = (obs.tobytes(), _info(info))
        rng = np.random.default_rng(4)
        for i in range(steps):
            action = rng.uniform(-1.2, 1.2, 2).astype(np.float32)  # some beyond [-1, 1]: clipped
            if i % 9 == 4:
                action = action.copy()
                action[:] = action[0]  # the same speed on both wheels (a ramp time may stay)
            obs, reward, terminated, truncated, info = env.step(action)
            out["steps"].append((obs.tobytes(), reward, terminated, truncated, _info(info),
                                 [(repr(j.last_state), repr(j.last_state.raw), j.last_contact)
                                  for j in u.rig.joints.values()]))
            if terminated or truncated:
                obs, info = env.reset()
                out["steps"].append(("reset", obs.tobytes(), _info(info)))
        link = next(iter(u.rig.joints.values())).driver.access.link
        out["transactions"] = (link.transactions, link.framing.exchanges, link.retries_used)
        out["frames"] = [(tx.start, tx.end, tx.due, tx.size, tx.side) for tx in link.transport.log]
        out["images"] = [(a, tuple(sorted(f.image().items()))) for b in u.rig.sim.buses.values()
                         for a, f in sorted(b.slaves.items())]
        out["rows"] = [np.array(f.firmware.kernel_rows()).tobytes() for b in u.rig.sim.buses.values()
                       for f in b.slaves.values()]
        out["write_log"] = [list(f.firmware.write_log) for b in u.rig.sim.buses.values() for f in b.slaves.values()]
        out["time"] = (u.rig.time, u.rig.sim.steps)
        out["taken"] = u.compiled_path.taken if u.compiled_path is not None else None
        out["lane"] = u.compiled_path.lane_taken if u.compiled_path is not None else None
        out["fused"] = u.compiled_path._steppers[0].exchange.taken if u.compiled_path is not None else None
        out["reads"] = u.compiled_path._steppers[0].exchange.reads if u.compiled_path is not None else None
        #: of them, the reads whose drive's act (frame receipt, rows, reply's travel) ran in the compiled call
        out["acts"] = u.compiled_path._steppers[0].exchange.acts if u.compiled_path is not None else None
        #: the world's sleeps booked, and the one-call exchange's calls that ran a held sleep first
        out["held"] = (u.rig.sim.hold_sleeps,
                       u.compiled_path._steppers[0].exchange.held if u.compiled_path is not None else None)
        out["counts"] = {k: v - before[k] for k, v in counts.n.items()} if counts is not None else None
        twins = [f.firmware for b in u.rig.sim.buses.values() for f in b.slaves.values()]
        #: what ran compiled: the world's stepping, each twin's kernel ops (not the Python ones)
        out["kernels"] = (u.rig.sim.group.compiled, [fw._k is not zlac_kernel.PY_OPS for fw in twins])
        return out
    finally:
        env.close()


_COMPARED = ("reset", "steps", "transactions", "frames", "images", "rows", "write_log", "time")


@pytest.mark.parametrize("mode", ["compiled", "python"])
def test_the_steady_step_is_taken_and_gives_the_driver_paths_bits(mode: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Compiled: the ramp and target FC16s of a step in one exchange (ZlacExchange: frames, physics, the twin's
    ops in one compiled call); JOINTS_COMPILED=0: the lane, one request after the other (the world does not run
    fused). Either way the driver path's bits."""
    monkeypatch.setenv("JOINTS_COMPILED", "0" if mode == "python" else "1")
    counts = _Counts(monkeypatch, light=False)
    driver = _run(compiled=False, counts=counts)
    compiled = _run(compiled=True, counts=counts)
    assert driver["taken"] is None
    assert compiled["taken"] >= 2 * 80  # both wheels, every step (the compiled path's FC16s)
    assert compiled["lane"] >= 2 * 80  # the steps' requests on the lane (the exchange counts its own there)
    assert driver["held"] == (False, None)  # the driver path steps its sleeps at once
    if mode == "compiled":
        assert compiled["fused"] >= 78  # every step's FC16s in one call (not the steps after an ended episode)
        assert compiled["reads"] >= 80  # every step's status read with the world's advance in one call
        assert compiled["held"][0] and compiled["held"][1] >= 80  # ... and with the env's period hold before it
        assert compiled["acts"] == compiled["reads"]  # ... and the drive's act and the reply's travel after it
    else:
        assert compiled["fused"] == 0 and compiled["reads"] == 0 and compiled["held"] == (False, 0)
    # the drive's plan as register values, once per step on either path (velocity_plan is its dict view)
    assert compiled["counts"] == driver["counts"] and compiled["counts"]["velocity_words"] >= 80
    for key in _COMPARED:
        assert compiled[key] == driver[key], key


def test_a_replaced_twin_method_sends_the_requests_the_lanes_way(monkeypatch: pytest.MonkeyPatch) -> None:
    """The twin's light write wrapped (not stock): no one-call exchange, the lane's requests, the light write
    taken for every ramp and target block on both paths - the same bits."""
    counts = _Counts(monkeypatch, light=True)
    driver = _run(compiled=False, counts=counts)
    compiled = _run(compiled=True, counts=counts)
    assert compiled["fused"] == 0 and compiled["taken"] >= 2 * 80 and compiled["lane"] >= 3 * 80
    assert compiled["counts"] == driver["counts"]
    assert compiled["counts"]["light"] >= 2 * 80
    for key in _COMPARED:
        assert compiled[key] == driver[key], key


def test_compiled_kernels_and_python_give_the_same_bits(monkeypatch: pytest.MonkeyPatch) -> None:
    """The twin's kernel op (set_velocity_target) compiled and as Python: one run each, the same bits. The first
    run is asserted compiled (wherever numba is installed): the world's stepping and the twin's ops compiled, every
    step's FC16s and status read in one compiled call - a run that fell back to Python would compare Python with
    Python."""
    runs = []
    for value in ("1", "0"):
        monkeypatch.setenv("JOINTS_COMPILED", value)
        runs.append(_run(compiled=True, steps=60, domain_randomization=True))
    compiled, python = runs
    assert compiled["kernels"] == (kernel.AVAILABLE, [kernel.AVAILABLE])
    if kernel.AVAILABLE:
        assert compiled["fused"] >= 58 and compiled["reads"] >= 60
        assert compiled["held"][0] and compiled["held"][1] >= 60  # every step's period hold in the read's call
        assert compiled["acts"] == compiled["reads"]
    assert python["held"] == (False, 0)
    assert python["kernels"] == (False, [False]) and python["fused"] == 0 and python["reads"] == 0
    assert compiled["taken"] >= 2 * 60 and python["taken"] >= 2 * 60  # the compiled path, both runs
    for key in _COMPARED:
        assert compiled[key] == python[key], key


@pytest.mark.parametrize("randomized", [False, True])
def test_held_sleeps_give_the_eager_sleeps_bits(randomized: bool) -> None:
    """The compiled path with the world's sleeps booked (``World.hold``: the env's period hold runs on its own at
    the start of the status read's compiled call) against the same path with sleeps stepped at once: the same
    bits, the held run's every step's hold carried by the read's call."""
    if not kernel.default_mode():
        pytest.skip("the compiled stepping is off (JOINTS_COMPILED=0 or no numba): no sleep is held")
    held = _run(compiled=True, steps=70, domain_randomization=randomized)
    eager = _run(compiled=True, steps=70, hold=False, domain_randomization=randomized)
    assert held["held"][0] and held["held"][1] >= 70 and held["reads"] >= 70
    assert eager["held"] == (False, 0) and eager["reads"] >= 70
    for key in (*_COMPARED, "taken", "lane", "fused", "reads", "acts"):
        assert held[key] == eager[key], key


def test_a_replaced_status_block_is_read_by_the_bus(monkeypatch: pytest.MonkeyPatch) -> None:
    """The twin's status block replaced (here wrapped): the read's act is the bus's own (not taken from the rows
    in the compiled call), the period hold still in the read's call - the driver path's bits."""
    status_of = ZlacFirmware._status_of
    monkeypatch.setattr(ZlacFirmware, "_status_of", lambda fw, *a: status_of(fw, *a))
    driver = _run(compiled=False, steps=40)
    compiled = _run(compiled=True, steps=40)
    if kernel.default_mode():
        assert compiled["reads"] >= 40 and compiled["held"][1] >= 40
    assert compiled["acts"] == 0
    for key in _COMPARED:
        assert compiled[key] == driver[key], key


# -- the twin's light write against the general one -----------------------------------------------------

def _twin(ramp_reference_rpm: float | None = None) -> tuple[ZlacFirmware, ModbusDeviceBus]:
    fw = ZlacFirmware(HubMotorProfile(), 1, ramp_reference_rpm=ramp_reference_rpm)
    return fw, ModbusDeviceBus([ModbusFront(fw, ZLAC8015D, node_id="rs485_node_id")])


def _blocks(rng: np.random.Generator) -> list[Any]:
    """A host's blocks: ramps (0x2080), targets (0x2088), ramps..targets, light blocks by name (a ramp time
    before a target, which must act on it), by mode and state, some refused."""
    out: list[Any] = []
    for k in range(140):
        kind = k % 7
        if kind == 6:
            a, b = (int(v) for v in rng.integers(0, 900, 2))
            left, right = (int(v) for v in rng.integers(-400, 400, 2))
            out.append([("acceleration_time_left", a), ("target_velocity_left", left), ("deceleration_time_right", b),
                        ("deceleration_time_left", b), ("target_velocity_right", right), ("acceleration_time_right", a)])
            continue
        if kind == 0:
            out.append(mb.WriteMultipleRegisters(1, 0x2080, tuple(int(v) for v in rng.integers(0, 800, 4))))
        elif kind == 1:
            out.append(mb.WriteMultipleRegisters(1, 0x2088, tuple(int(v) & 0xFFFF for v in rng.integers(-300, 300, 2))))
        elif kind == 2:  # one wheel beyond +-3000 r/min: refused (exception 03)
            beyond = int(rng.integers(3001, 4000)) * (1 if k % 4 else -1)
            out.append(mb.WriteMultipleRegisters(1, 0x2088, (int(rng.integers(-300, 300)) & 0xFFFF, beyond & 0xFFFF)))
        elif kind == 3:  # a ramp time beyond 32767 ms: refused
            out.append(mb.WriteMultipleRegisters(1, 0x2080, (int(rng.integers(32768, 65536)), 200, 300, 400)))
        elif kind == 4:
            words = [int(v) for v in rng.integers(0, 500, 8)] + [int(v) & 0xFFFF for v in rng.integers(-99, 99, 2)]
            out.append(mb.WriteMultipleRegisters(1, 0x2080, tuple(words)))  # not light: quick-stop times, torque rates
        else:
            out.append(mb.ReadHoldingRegisters(1, 0x20A2, 14))
        if k == 30:
            out.append(mb.WriteSingleRegister(1, 0x200D, 4))  # torque mode: targets stored, not acted on
        if k == 50:
            out.append(mb.WriteSingleRegister(1, 0x200D, 3))
        if k == 70:
            out.append(mb.WriteSingleRegister(1, 0x200E, 0x07))  # stop: disabled
        if k == 90:
            out.append(mb.WriteSingleRegister(1, 0x200E, 0x08))
    return out


def _drive(bus: ModbusDeviceBus, fw: ZlacFirmware, requests: list[Any]) -> list[Any]:
    record: list[Any] = []
    q = [0.0, 0.0]
    t = 0.0
    for setup in (mb.WriteSingleRegister(1, 0x200D, 3), mb.WriteSingleRegister(1, 0x200E, 0x08)):
        record.append(bus.exchange(setup))
    for r in requests:
        if isinstance(r, list):  # a light block by name (as a front's FC16 of them would give it)
            fw.write_many(r)
        else:
            record.append(bus.exchange(r))
        for _ in range(3):
            t += 1e-3
            torques = [ch.step(t, 1e-3, q[i], 0.5 * i) for i, ch in enumerate(fw.channels)]
            q = [q[i] + 1e-3 * (0.5 * i + 0.01 * torques[i]) for i in range(2)]
        record.append(fw.kernel_rows())
    record.append(dict(fw.values))
    record.append(list(fw.write_log))
    return record


@pytest.mark.parametrize("ramp_reference_rpm", [None, 1000.0])
def test_the_light_write_is_the_general_write(ramp_reference_rpm: float | None, monkeypatch: pytest.MonkeyPatch) -> None:
    requests = _blocks(np.random.default_rng(9))
    fast_fw, fast_bus = _twin(ramp_reference_rpm)
    light = ZlacFirmware._write_light
    taken = [0, 0]

    def counted(fw: ZlacFirmware, items: Any) -> bool:
        done = light(fw, items)
        taken[0 if done else 1] += 1
        return done

    monkeypatch.setattr(ZlacFirmware, "_write_light", counted)
    fast = _drive(fast_bus, fast_fw, requests)
    monkeypatch.setattr(ZlacFirmware, "_write_light", lambda fw, items: False)  # the general way only
    ref_fw, ref_bus = _twin(ramp_reference_rpm)
    ref = _drive(ref_bus, ref_fw, requests)
    assert taken[0] >= 50 and taken[1] >= 20, taken  # taken for the light blocks, refused for the rest
    refusals = [r for r in fast if isinstance(r, mb.ExceptionReply)]
    assert len(refusals) >= 20 and {r.code for r in refusals} == {3}  # out of range: exception 03 both ways
    assert len(fast) == len(ref)
    for i, (a, b) in enumerate(zip(fast, ref)):
        assert a == b, f"record {i}"


@pytest.mark.parametrize("items", [
    [("target_velocity_left", 3001)],  # above the register's range
    [("acceleration_time_left", 100), ("target_velocity_right", -3001)],
    [("target_velocity_left", 1.0)],  # not an int: the general check decides
    [("target_velocity_left", True)],
])
def test_a_light_block_the_general_write_refuses_or_converts_goes_the_general_way(items: list[tuple[str, Any]]) -> None:
    fw, _ = _twin()
    assert fw._write_light(items) is False  # nothing done
    assert fw.write_log == [] and fw.values == _twin()[0].values
    ref, _ = _twin()
    try:
        Firmware.write_many(ref, items)
        want: Any = ref.values
    except ParameterRefused as exc:
        want = str(exc)
    try:
        fw.write_many(items)
        got: Any = fw.values
    except ParameterRefused as exc:
        got = str(exc)
    assert got == want


def test_a_pending_or_subclassed_twin_writes_the_general_way() -> None:
    fw, _ = _twin()
    fw.pending.append((1.0, [("target_velocity_left", 5)]))
    assert fw._write_light([("target_velocity_left", 10)]) is False

    class Other(ZlacFirmware):
        def on_write(self, name: str, value: int) -> None:
            super().on_write(name, value)

    assert Other(HubMotorProfile(), 1)._write_light([("target_velocity_left", 10)]) is False


def test_velocity_plan_is_the_dict_view_of_velocity_words() -> None:
    """Both wheels enabled in velocity mode (a drive without a link: nothing is sent by the plan)."""
    drive = ZlacDrive(_NoLink(), 1)  # type: ignore[arg-type]
    drive.state.enabled.update(("left", "right"))
    drive.state.mode = 3
    for left, right in [((600, 200), (-400, 200)), ((600, 200), (-400, 200)), ((600, 300), (100, 50))]:
        ramps, targets = drive.velocity_words(left, right)
        plan = drive.velocity_plan({"left": left, "right": right})
        assert plan[1] == dict(zip(TARGET_NAMES, targets))
        assert plan[0] == (None if ramps is None else dict(zip(RAMP_NAMES, ramps)))
        drive.note_words(TARGET_NAMES, targets)
        if ramps is not None:
            drive.note_words(RAMP_NAMES, ramps)
    with pytest.raises(joints.JointsError):
        drive.velocity_words((40000, 200), (0, 200))  # 4000 r/min: beyond the register


class _NoLink:
    clock = None


# -- wrong replies on the compiled path ------------------------------------------------------------------

def _planted_run(compiled: bool, monkeypatch: pytest.MonkeyPatch) -> tuple[list[Any], int, int]:
    """40 steps, every 5th reply of the bus wrong (silence, another slave's, a short read, a refusal)."""
    exchange = ModbusDeviceBus.exchange
    n = [0]
    on = [False]

    def faulty(bus: ModbusDeviceBus, msg: Any) -> Any:
        reply = exchange(bus, msg)
        n[0] += 1
        if reply is None or not on[0] or n[0] % 5:
            return reply
        kind = (n[0] // 5) % 4
        if kind == 0:
            return None
        if kind == 1:
            return dataclasses.replace(reply, slave=reply.slave + 1)
        if kind == 2 and isinstance(reply, mb.ReadRegistersReply):
            return mb.ReadRegistersReply(reply.slave, reply.function, reply.values[:-1])
        return mb.ExceptionReply(reply.slave, reply.function, 4)

    env = gym.make(ENV, compiled_path=compiled)
    u: Any = env.unwrapped
    monkeypatch.setattr(ModbusDeviceBus, "exchange", faulty)
    out: list[Any] = []
    try:
        u.reset(seed=2)
        on[0] = True
        rng = np.random.default_rng(8)
        for _ in range(40):
            try:
                obs, reward, terminated, _t, info = u.step(rng.uniform(-1, 1, 2).astype(np.float32))
                out.append((obs.tobytes(), reward, terminated, _info(info)))
            except joints.JointsError as exc:
                out.append((type(exc).__name__, str(exc)))
                on[0] = False
                u.reset(seed=2)
                on[0] = True
        link = next(iter(u.rig.joints.values())).driver.access.link
        out.append((link.transactions, link.framing.exchanges, link.retries_used, link.late_discarded))
        out.append([(tx.start, tx.end, tx.due, tx.size, tx.side) for tx in link.transport.log])
        out.append((u.rig.time, u.rig.sim.steps))
        taken = u.compiled_path.taken if compiled else 0
        reads = u.compiled_path._steppers[0].exchange.reads if compiled else 0
    finally:
        monkeypatch.setattr(ModbusDeviceBus, "exchange", exchange)
        env.close()
    return out, taken, reads


def test_planted_wrong_replies_leave_both_paths_alike(monkeypatch: pytest.MonkeyPatch) -> None:
    compiled, taken, reads = _planted_run(True, monkeypatch)
    driver, _, _ = _planted_run(False, monkeypatch)
    assert taken >= 20  # the compiled path sent the steps that got through
    # the status reads (silence, another slave's reply, a short read, a refusal among them) fused where the world
    # runs compiled (JOINTS_COMPILED=0: the lane's way)
    assert reads >= 30 if kernel.default_mode() else reads == 0
    assert any(isinstance(o, tuple) and isinstance(o[0], str) for o in driver)  # some steps raised
    assert compiled == driver


def test_commands_alone_leave_the_twin_as_the_rigs_commands_do() -> None:
    """Velocity commands without a status read between them (the drive's rows right after each: the frame
    instants it saw, its ramps and targets), the one-call exchange against ``rig.set_velocities``."""
    runs = []
    for compiled in (True, False):
        with gym.make(ENV, compiled_path=compiled) as env:
            u: Any = env.unwrapped
            env.reset(seed=1)
            front = next(f for b in u.rig.sim.buses.values() for f in b.slaves.values())
            out: list[Any] = []
            for left, right in [(2.5, -1.0), (2.5, -1.0), (-4.0, 3.0), (0.0, 0.5)]:
                if compiled:
                    u.compiled_path.command("velocity", [left, right])
                else:
                    u.rig.set_velocities(dict(zip(u.wheel_names, (left, right))))
                out.append((np.array(front.firmware.kernel_rows()).tobytes(), u.rig.time, u.rig.sim.steps))
                u.rig.sleep(0.013)
            fused = u.compiled_path._steppers[0].exchange.taken if compiled else None
            link = next(iter(u.rig.joints.values())).driver.access.link
            out.append([(tx.start, tx.end, tx.due, tx.size, tx.side) for tx in link.transport.log])
            runs.append((out, fused))
    assert runs[0][1] == (4 if kernel.default_mode() else 0)  # the exchange where the world runs compiled
    assert runs[0][0] == runs[1][0]
