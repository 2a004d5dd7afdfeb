"""The compiled command/state path (joints.compiled_path) gives the driver path's bits.

For every env it supports and every action mode, the same seeds and actions run once on the compiled
path and once on the driver path (``compiled_path=False``): observations, rewards, terminations, infos,
every joint's last state (with its sample time and raw values) and last contact, every twin's register image, the link's transaction and direct-exchange counts, every frame instant on
the simulated line, the rig's time and the world's substeps must be equal, and the compiled path must
really have been taken.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401 - registers the joints/ envs
import joints
from joints.compiled_path import supported
from joints.errors import LimitError
from joints.link.trace import TraceRecord
from joints.sim import kernel

#: env id -> steps per run (the arm steps at 10 Hz: fewer steps cover as much motion)
SUPPORTED = {"joints/ErobReach-v0": 40, "joints/ErobArmReach-v0": 12, "joints/DiffDriveGoal-v0": 60}
MODES = ("position", "velocity", "torque")
#: env id -> its action modes (None: the env has one, wheel speeds, and no action_mode argument)
ENV_MODES: dict[str, tuple[str | None, ...]] = {"joints/DiffDriveGoal-v0": (None,)}
EROB = ("joints/ErobReach-v0", "joints/ErobArmReach-v0")
CASES = [(env_id, mode) for env_id in sorted(SUPPORTED) for mode in ENV_MODES.get(env_id, MODES)]


def _joints(env: Any) -> list[Any]:
    return list(env.rig.joints.values())


def _links(env: Any) -> list[Any]:
    seen: dict[int, Any] = {}
    for j in _joints(env):
        link = j.driver.access.link
        seen.setdefault(id(link), link)
    return list(seen.values())


def _images(env: Any) -> list[tuple[str, int, tuple[tuple[int, int], ...]]]:
    out = []
    env.rig.sim.sync()  # the twins' computed registers after the physics of booked time (a held sleep's too)
    for name, bus in sorted(env.rig.sim.buses.items()):
        for address, front in sorted(bus.slaves.items()):
            out.append((name, address, tuple(sorted(front.image().items()))))
    return out


def _frames(link: Any) -> list[tuple[float, float, float, int, str]]:
    return [(tx.start, tx.end, tx.due, tx.size, tx.side) for tx in link.transport.log]


def _info(info: dict[str, Any]) -> list[tuple[str, Any]]:
    """Every info entry, bit for bit (arrays as bytes, floats by their exact repr)."""
    return [(k, (v.dtype.str, v.tobytes()) if isinstance(v, np.ndarray) else repr(v)) for k, v in sorted(info.items())]


def _run(env_id: str, mode: str | None, steps: int, compiled: bool, trace: bool = False) -> dict[str, Any]:
    kwargs: dict[str, Any] = {} if mode is None else {"action_mode": mode}
    env = gym.make(env_id, compiled_path=compiled, **kwargs)
    u: Any = env.unwrapped
    records: list[TraceRecord] = []
    try:
        if trace:
            u.rig.trace(records.append)
        out: dict[str, Any] = {"steps": []}
        obs, info = env.reset(seed=7)
        out["reset"] = (obs.tobytes(), _info(info))
        rng = np.random.default_rng(11)
        for _ in range(steps):
            action = rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32)
            obs, reward, terminated, truncated, info = env.step(action)
            out["steps"].append((obs.tobytes(), reward, terminated, truncated, _info(info),
                                 [(repr(j.last_state), j.last_contact, j.enabled) for j in _joints(u)]))
            if terminated or truncated:
                obs, info = env.reset()
                out["steps"].append(("reset", obs.tobytes(), _info(info)))
        links = _links(u)
        out["transactions"] = [(lk.transactions, lk.framing.exchanges, lk.retries_used) for lk in links]
        out["frames"] = [_frames(lk) for lk in links]
        out["images"] = _images(u)
        out["time"] = (u.rig.time, u.rig.sim.steps)
        out["trace"] = [(r.time, r.direction, r.data, r.meaning) for r in records]
        out["taken"] = u.compiled_path.taken if u.compiled_path is not None else None
        out["lane"] = u.compiled_path.lane_taken if u.compiled_path is not None else None
        out["fused"] = u.compiled_path.fused if u.compiled_path is not None else None
        out["steps_taken"] = u.compiled_path.steps_taken if u.compiled_path is not None else None
        out["calls"] = _calls(u) if u.compiled_path is not None and hasattr(u.compiled_path._steppers[0], "exchange") \
            else None
        return out
    finally:
        env.close()


@pytest.mark.parametrize(("env_id", "mode"), CASES)
def test_compiled_path_gives_the_driver_paths_bits(env_id: str, mode: str | None) -> None:
    steps = SUPPORTED[env_id]
    driver = _run(env_id, mode, steps, compiled=False)
    compiled = _run(env_id, mode, steps, compiled=True)
    assert driver["taken"] is None  # compiled_path=False: the driver path only
    # the compiled path really sent the steps' commands (all but the joints of an ended episode)
    assert compiled["taken"] >= steps
    assert sum(t[0] for t in compiled["transactions"]) > 2 * steps
    assert sum(len(f) for f in compiled["frames"]) > 4 * steps  # requests and replies on the timed line
    assert compiled["lane"] >= 2 * steps  # the direct lane carried the steps' requests (joints.link.lane)
    if env_id in EROB and kernel.default_mode():  # the eRobs' one-call exchange (joints.sim.erob_exchange) carried them
        assert compiled["fused"] >= 2 * steps
    for key in ("reset", "steps", "transactions", "frames", "images", "time"):
        assert compiled[key] == driver[key], key


@pytest.mark.parametrize(("env_id", "mode", "joints_"), [("joints/ErobReach-v0", "position", 1),
                                                        ("joints/DiffDriveGoal-v0", None, 2)])
def test_a_trace_sees_the_same_frames_on_both_paths(env_id: str, mode: str | None, joints_: int) -> None:
    """A hooked trace is honoured: the compiled path's requests go through the link, which feeds it."""
    driver = _run(env_id, mode, 10, compiled=False, trace=True)
    compiled = _run(env_id, mode, 10, compiled=True, trace=True)
    assert compiled["taken"] == 10 * joints_
    assert len(compiled["trace"]) > 40  # tx and rx of 2-3 transactions per step
    assert compiled["trace"] == driver["trace"]
    assert compiled["frames"] == driver["frames"]


def test_the_env_takes_the_compiled_path_only_where_every_joint_is_supported() -> None:
    with gym.make("joints/ErobReach-v0") as env:
        u: Any = env.unwrapped
        assert isinstance(u.compiled_path, joints.CompiledPath)
        assert all(supported(j) for j in u.joints)
    with gym.make("joints/ErobReach-v0", compiled_path=False) as env:
        assert getattr(env.unwrapped, "compiled_path") is None  # noqa: B009 - an env attribute mypy cannot see
    with pytest.raises(ValueError, match="cannot step"):
        joints.CompiledPath([_Unsupported()])  # type: ignore[list-item]


class _Unsupported:
    name = "other"
    driver = object()


def test_a_refused_command_is_refused_the_same_way_and_sends_nothing() -> None:
    """The joint's own checks run first: a target outside the limits raises LimitError, no frame is sent."""
    with gym.make("joints/ErobReach-v0") as env:
        u: Any = env.unwrapped
        env.reset(seed=0)
        link = _links(u)[0]
        before = link.transactions
        with pytest.raises(joints.JointsError, match="outside the limits"):
            u.compiled_path.command("position", [10.0])
        assert link.transactions == before


@pytest.mark.parametrize("values", [[100.0, 0.0], [0.0, -100.0]])
def test_a_refused_wheel_speed_is_refused_and_sends_nothing(values: list[float]) -> None:
    """Both wheels' checks run before the drive's one FC16: either wheel over its limit sends nothing."""
    with gym.make("joints/DiffDriveGoal-v0") as env:
        u: Any = env.unwrapped
        env.reset(seed=0)
        link = _links(u)[0]
        before = link.transactions
        with pytest.raises(LimitError, match="exceeds the limit"):
            u.compiled_path.command("velocity", values)
        assert link.transactions == before


def test_one_wheel_alone_is_commanded_as_the_rig_commands_it() -> None:
    """A skipped wheel leaves the other to the driver's own set_velocity, as rig.set_velocities of one wheel."""
    runs = []
    for compiled in (True, False):
        with gym.make("joints/DiffDriveGoal-v0", compiled_path=compiled) as env:
            u: Any = env.unwrapped
            env.reset(seed=0)
            if compiled:
                u.compiled_path.command("velocity", [2.5, 0.0], [False, True])
                assert u.compiled_path.taken == 0
            else:
                u.rig.set_velocities({u.wheel_names[0]: 2.5})
            u.rig.sleep(0.05)
            runs.append((_frames(_links(u)[0]), _images(u), _links(u)[0].transactions, u.rig.time))
    assert runs[0] == runs[1]
    assert runs[0][2] > 0


@pytest.mark.parametrize(("env_id", "mode"), [("joints/ErobReach-v0", "position"), ("joints/ErobArmReach-v0", "torque"),
                                              ("joints/DiffDriveGoal-v0", None)])
def test_the_idle_lines_shortcut_gives_the_general_lines_bits(env_id: str, mode: str | None,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """A transaction on an idle line (TimedSerialLine._transact_idle) gives the frames, instants, clock and
    physics of the line's general event loop, which runs where the shortcut is refused."""
    from joints.transports.serial_sim import TimedSerialLine

    taken = [0]
    idle = TimedSerialLine._transact_idle

    def counted(self: TimedSerialLine, *args: Any) -> Any:
        taken[0] += 1
        return idle(self, *args)

    monkeypatch.setattr(TimedSerialLine, "_transact_idle", counted)
    short = _run(env_id, mode, 12, compiled=True)
    assert taken[0] > 2 * 12  # the shortcut carried the steps' transactions
    monkeypatch.setattr(TimedSerialLine, "_plain_peer", lambda self: False)
    general = _run(env_id, mode, 12, compiled=True)
    for key in ("reset", "steps", "transactions", "frames", "images", "time"):
        assert short[key] == general[key], key


class _Faulty:
    """Every ``every``-th request the bus gets is answered wrongly (cycling: silence, another slave's reply, a
    reply the host's decoder refuses, a refusal) - the replies the direct lane hands back to the link's way."""

    def __init__(self, every: int) -> None:
        self.every = every
        self.n = 0
        self.on = True  #: off: every reply plain (resets)

    def wrap(self, exchange: Any) -> Any:
        from joints.codecs import modbus as mb

        def faulty(bus: Any, msg: Any) -> Any:
            reply = exchange(bus, msg)
            self.n += 1
            if reply is None or not self.on or self.n % self.every:
                return reply
            kind = (self.n // self.every) % 4
            if kind == 0:
                return None  # silence: the attempt times out, an idempotent request is sent again
            if kind == 1:
                return dataclasses.replace(reply, slave=reply.slave + 1)
            if kind == 2 and isinstance(reply, mb.ReadRegistersReply):
                return mb.ReadRegistersReply(reply.slave, reply.function, reply.values[:-1])  # a byte count refused
            return mb.ExceptionReply(reply.slave, reply.function, 4)  # a refusal (device failure)
        return faulty


def _faulty_run(env_id: str, mode: str | None, every: int, compiled: bool, monkeypatch: pytest.MonkeyPatch
                ) -> tuple[list[Any], int, int | None]:
    """30 steps with every ``every``-th reply wrong (resets get plain ones): (what happened, wrong replies
    planted, requests on the lane)."""
    from joints.sim.modbus_front import ModbusDeviceBus

    exchange = ModbusDeviceBus.exchange
    outcome: list[Any] = []
    kwargs: dict[str, Any] = {} if mode is None else {"action_mode": mode}
    env = gym.make(env_id, compiled_path=compiled, **kwargs)
    u: Any = env.unwrapped
    plant = _Faulty(every)
    monkeypatch.setattr(ModbusDeviceBus, "exchange", plant.wrap(exchange))

    def reset() -> None:
        plant.on = False
        u.reset(seed=3)  # the env itself: a failed reset leaves gymnasium's checker nothing to check
        plant.on = True

    try:
        reset()
        rng = np.random.default_rng(5)
        for _ in range(30):
            try:
                obs, reward, terminated, _truncated, info = u.step(
                    rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32))
                outcome.append((obs.tobytes(), reward, terminated, _info(info)))
            except joints.JointsError as exc:
                outcome.append((type(exc).__name__, str(exc)))
                reset()
        links = _links(u)
        outcome.append([(lk.transactions, lk.framing.exchanges, lk.retries_used, lk.late_discarded)
                        for lk in links])
        outcome.append([_frames(lk) for lk in links])
        outcome.append((_images(u), u.rig.time, u.rig.sim.steps))
        lane = u.compiled_path.lane_taken if compiled else None
    finally:
        monkeypatch.setattr(ModbusDeviceBus, "exchange", exchange)  # the rig shuts down on plain replies
        env.close()
    return outcome, plant.n // every, lane


@pytest.mark.parametrize("every", [7, 2])
@pytest.mark.parametrize(("env_id", "mode"), [("joints/ErobReach-v0", "position"), ("joints/ErobReach-v0", "velocity"),
                                              ("joints/DiffDriveGoal-v0", None)])
def test_wrong_replies_leave_the_lane_as_the_link_handles_them(env_id: str, mode: str | None, every: int,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """Silence, another slave's reply, a refused frame and a refusal, planted alike on both paths: the same
    retries, errors, frames, images and times (the lane's rest is the link's attempt and retries)."""
    compiled, planted, lane = _faulty_run(env_id, mode, every, True, monkeypatch)
    driver, _, _ = _faulty_run(env_id, mode, every, False, monkeypatch)
    assert planted > 4
    assert lane is not None and lane > 10
    assert any(isinstance(o, tuple) and isinstance(o[0], str) for o in driver)  # some steps raised
    assert compiled == driver


def test_a_silent_twin_gives_the_links_errors_on_the_lane(monkeypatch: pytest.MonkeyPatch) -> None:
    """A twin that never answers: the lane's read and command end in the link's errors (its retries, its
    timeout and unknown-outcome texts), counts, frames and times."""
    from joints.sim.modbus_front import ModbusDeviceBus

    exchange = ModbusDeviceBus.exchange
    runs = []
    for via in ("lane", "link"):
        env = gym.make("joints/ErobReach-v0")
        u: Any = env.unwrapped
        env.reset(seed=0)
        stepper = u.compiled_path._steppers[0]
        send = stepper.lane.request if via == "lane" else stepper.link.request
        monkeypatch.setattr(ModbusDeviceBus, "exchange", lambda bus, msg: (exchange(bus, msg), None)[1])
        out: list[Any] = []
        try:
            for request, idempotent in ((stepper.status, True), (stepper.start, False)):
                with pytest.raises(joints.JointsError) as caught:
                    send(request, idempotent=idempotent)
                out.append((type(caught.value).__name__, str(caught.value)))
            link = stepper.link
            out.append((link.transactions, link.framing.exchanges, link.retries_used, link.late_discarded,
                        _frames(link), u.rig.time))
        finally:
            monkeypatch.setattr(ModbusDeviceBus, "exchange", exchange)
            env.close()
        runs.append(out)
    assert "attempts" in runs[0][0][1] and "outcome is unknown" in runs[0][1][1]
    assert runs[0] == runs[1]


def _mixed_run(env_id: str, mode: str, compiled: bool, monkeypatch: pytest.MonkeyPatch) -> tuple[list[Any], list[int]]:
    """36 steps in which some are not the steady case: wrong replies planted for one step (every reply of it), a
    drive tripped by a fault, a command delay for two steps (the world then ticks after substeps), a joint's
    stepping replaced for the last steps (off the fused stepping). Returns (what happened, requests the one-call
    exchange carried in each step)."""
    from joints.sim.modbus_front import ModbusDeviceBus

    exchange = ModbusDeviceBus.exchange
    env = gym.make(env_id, compiled_path=compiled, action_mode=mode)
    u: Any = env.unwrapped
    name = u.joint_names[0]
    world = u.rig.sim
    outcome: list[Any] = []
    fused: list[int] = []
    plant = _Faulty(1)
    try:
        u.reset(seed=3)
        rng = np.random.default_rng(9)
        for step in range(36):
            phase = step % 12
            if phase == 3:
                monkeypatch.setattr(ModbusDeviceBus, "exchange", plant.wrap(exchange))
            elif phase == 5:
                world.drives[name].trip(0x8611)  # a following error: the next read reports it, the episode ends
            elif phase == 7:
                world.perturb(name, command_delay=0.002)
            elif step == 34:  # from here on the joint steps in Python (the same loops, wrapped): not fused
                world.intercept(name, lambda step: lambda t, dt, q, qd: step(t, dt, q, qd))
            before = u.compiled_path.fused if compiled else 0
            try:
                obs, reward, terminated, _truncated, info = u.step(
                    rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32))
                outcome.append((obs.tobytes(), reward, terminated, _info(info)))
            except joints.JointsError as exc:
                outcome.append((type(exc).__name__, str(exc)))
                terminated = True
            fused.append((u.compiled_path.fused if compiled else 0) - before)
            monkeypatch.setattr(ModbusDeviceBus, "exchange", exchange)
            if phase == 8:
                world.restore()
            if terminated:
                u.reset(seed=step)
                outcome.append("reset")
        links = _links(u)
        outcome.append([(lk.transactions, lk.framing.exchanges, lk.retries_used, lk.late_discarded) for lk in links])
        outcome.append([_frames(lk) for lk in links])
        outcome.append((_images(u), u.rig.time, world.steps))
    finally:
        monkeypatch.setattr(ModbusDeviceBus, "exchange", exchange)
        env.close()
    return outcome, fused


@pytest.mark.parametrize(("env_id", "mode"), [("joints/ErobReach-v0", "position"), ("joints/ErobReach-v0", "torque"),
                                              ("joints/ErobArmReach-v0", "velocity")])
def test_the_one_call_exchange_leaves_what_is_not_steady_to_the_driver_path(env_id: str, mode: str,
                                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """Planted wrong replies, a fault, a command delay, a joint stepped in Python: those steps go the usual way
    (decided before anything is sent), the others by the one-call exchange, and every bit is the driver path's."""
    compiled, fused = _mixed_run(env_id, mode, True, monkeypatch)
    driver, _ = _mixed_run(env_id, mode, False, monkeypatch)
    assert compiled == driver
    assert any(isinstance(o, tuple) and o[0] in ("UnexpectedReply", "ReplyTimeout", "DeviceRejected",
                                                  "OutcomeUnknownReplyTimeout", "ChecksumError", "FrameError")
               or (isinstance(o, tuple) and len(o) == 4 and "fault" in dict(o[3])) for o in driver)
    if kernel.default_mode():
        assert all(fused[k] == 0 for k in range(len(fused)) if k % 12 in (3, 7, 8) or k >= 34)  # the usual way
        assert sum(1 for k in range(len(fused)) if fused[k] > 0) >= 20


def test_a_refusal_in_a_batch_is_raised_after_the_joints_before_it_were_sent() -> None:
    """The arm's three eRobs go in one call; a refused second joint: the first is sent (as joint by joint), the
    second raises its own LimitError, the third is not sent - frames, counts and images as the driver path's."""
    runs = []
    for compiled in (True, False):
        with gym.make("joints/ErobArmReach-v0", compiled_path=compiled) as env:
            u: Any = env.unwrapped
            env.reset(seed=0)
            js = u.joints
            targets = [float(j.last_state.position) for j in js]
            targets[1] = 10.0
            fused = u.compiled_path.fused if compiled else 0
            with pytest.raises(LimitError, match="outside the limits"):
                if compiled:
                    u.compiled_path.command("position", targets)
                else:
                    for j, q in zip(js, targets):
                        j.move_to(q)
            if compiled and kernel.default_mode():
                assert u.compiled_path.fused - fused == 2  # the first joint's target and start, in one call
            link = _links(u)[0]
            runs.append((_frames(link), link.transactions, _images(u), u.rig.time,
                         [j.last_contact for j in js]))
    assert runs[0] == runs[1]


def test_a_batch_checks_every_drive_not_only_the_first() -> None:
    """The arm's batch goes in one call only where every drive in it is steady: joint 2's firmware replaced (a
    subclass: not the stock one) - the batch goes joint by joint (joints 1 and 3 each in their own call, joint 2
    the usual way), with the driver path's bits."""
    from joints.sim.erob import ErobFirmware

    class Replaced(ErobFirmware):
        pass

    runs = []
    for compiled in (True, False):
        with gym.make("joints/ErobArmReach-v0", compiled_path=compiled, action_mode="position") as env:
            u: Any = env.unwrapped
            env.reset(seed=0)
            u.rig.sim.drives[u.joint_names[1]].__class__ = Replaced
            fused = u.compiled_path.fused if compiled else 0
            rng = np.random.default_rng(1)
            out = []
            for _ in range(4):
                obs, reward, _term, _trunc, _info = env.step(
                    rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32))
                out.append((obs.tobytes(), reward))
            if compiled and kernel.default_mode():  # per step: joints 1 and 3's target + start and read
                assert u.compiled_path.fused - fused == 4 * (2 * 2 + 2)
            link = _links(u)[0]
            runs.append((out, _frames(link), link.transactions, _images(u), u.rig.time, u.rig.sim.steps))
    assert runs[0] == runs[1]


def test_the_status_reads_shape_is_kept_for_that_request_only() -> None:
    """The one-call exchange keeps the status read's shape by the request's identity: another FC03 (the same block
    for another slave) is not taken from it (nothing sent: None), the status read still is."""
    if not kernel.default_mode():
        pytest.skip("the one-call exchange needs the compiled world")
    with gym.make("joints/ErobReach-v0") as env:
        u: Any = env.unwrapped
        env.reset(seed=0)
        s = u.compiled_path._steppers[0]
        status = s.status
        other = type(status)(status.slave + 1, status.address, status.count)
        assert s.lane.exchange(s.exchange.run, (status,), idempotent=True) is not None
        transactions = s.link.transactions
        assert s.lane.exchange(s.exchange.run, (other,), idempotent=True) is None
        assert s.link.transactions == transactions
        assert s.lane.exchange(s.exchange.run, (status,), idempotent=True) is not None


def _split(monkeypatch: pytest.MonkeyPatch) -> None:
    """Env steps as three calls again: the command, the wait for the tick, the read (no CompiledPath.step)."""
    monkeypatch.setattr(joints.CompiledPath, "step", lambda self, *args, **kwargs: None)


def _calls(env: Any) -> int:
    """The one-call exchanges' calls so far (each counts the calls it ran)."""
    return sum(s.exchange.taken for s in env.compiled_path._steppers)


@pytest.mark.parametrize(("env_id", "mode"), [(e, m) for e in EROB for m in MODES])
def test_an_env_step_in_one_call_gives_the_three_calls_bits(env_id: str, mode: str,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """The command, the wait for the tick and the read in one compiled call (CompiledPath.step) give what the
    three give one after the other: every observation, reward, info, state, frame, count, image and the clock;
    each env step the one call took is one call fewer."""
    steps = SUPPORTED[env_id]
    runs = []
    for split in (False, True):
        if split:
            _split(monkeypatch)
        runs.append(_run(env_id, mode, steps, compiled=True))
    one, three = runs
    for key in ("reset", "steps", "transactions", "frames", "images", "time", "taken", "lane", "fused"):
        assert one[key] == three[key], key
    if kernel.default_mode():
        assert one["steps_taken"] >= steps - 2 and three["steps_taken"] == 0
        assert three["calls"] - one["calls"] == one["steps_taken"]  # each such step: one call, not two
    else:  # no compiled exchange: every step goes the usual way
        assert one["steps_taken"] == 0


@pytest.mark.parametrize("env_id", EROB)
def test_the_steps_hold_is_the_envs_wait_to_its_tick(env_id: str) -> None:
    """CompiledPath.step against its three parts called by hand, for ticks far ahead, just ahead, at and behind
    the clock: the same states and ``remaining`` (<= 0: late, no sleep), frames, counts, image and clock."""
    offsets = (0.05, 0.0004, 0.0, -0.003, 0.0011, 0.02)  # s from the clock before the command to the tick
    runs = []
    for fused in (True, False):
        env = gym.make(env_id, action_mode="position")
        u: Any = env.unwrapped
        path, rig = u.compiled_path, u.rig
        out: list[Any] = []
        try:
            env.reset(seed=5)
            rng = np.random.default_rng(2)
            for k in range(3 * len(offsets)):
                cmd = [float(x) for x in u.command_of(rng.uniform(-1.0, 1.0, env.action_space.shape))]
                tick = rig.time + offsets[k % len(offsets)]
                if fused:
                    got = path.step("position", cmd, None, tick, rig)
                    assert got is not None or not kernel.default_mode()
                if not fused or got is None:
                    path.command("position", cmd)
                    remaining = tick - rig.time
                    if remaining > 0:
                        rig.sleep(remaining)
                    got = (path.states(), remaining)
                states, remaining = got
                out.append(([repr(s) for s in states], remaining, rig.time))
            link = _links(u)[0]
            out.append((link.transactions, _frames(link), _images(u), rig.time, rig.sim.steps))
            if fused and kernel.default_mode():
                assert path.steps_taken == 3 * len(offsets)
        finally:
            env.close()
        runs.append(out)
    assert runs[0] == runs[1]
    assert any(r[1] <= 0 for r in runs[0][:-1]) and any(r[1] > 0 for r in runs[0][:-1])  # late ticks and waits


@pytest.mark.parametrize("case", ["keep-alive due", "raise on overrun"])
def test_a_step_whose_wait_is_not_the_worlds_hold_alone_goes_in_three(case: str) -> None:
    """A keep-alive read due before the tick (a joint's watchdog of 100 ms: the rig's sleep reads it) or an env
    that raises on overruns: the step's command, wait and read go one after the other, with the driver path's
    bits; CompiledPath.step took none."""
    runs = []
    for compiled in (True, False):
        env = gym.make("joints/ErobReach-v0", compiled_path=compiled, raise_on_overrun=case == "raise on overrun")
        u: Any = env.unwrapped
        out: list[Any] = []
        try:
            env.reset(seed=4)
            if case == "keep-alive due":
                for j in u.joints:
                    j.watchdog_ms = 100
            before = _links(u)[0].transactions
            rng = np.random.default_rng(8)
            for _ in range(12):
                obs, reward, terminated, _truncated, info = env.step(
                    rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32))
                out.append((obs.tobytes(), reward, terminated, _info(info)))
            link = _links(u)[0]
            out.append((link.transactions - before, _frames(link), _images(u), u.rig.time))
            if compiled:
                assert u.compiled_path.steps_taken == 0
                assert u.compiled_path.taken >= 12
        finally:
            env.close()
        runs.append(out)
    assert runs[0] == runs[1]
    # the steps' own 3 transactions each (target, start, status read); with the keep-alive, the sleeps' reads too
    if case == "keep-alive due":
        assert runs[0][-1][0] > 3 * 12
    else:
        assert runs[0][-1][0] == 3 * 12


@pytest.mark.parametrize("base", ["ErobReachEnv", "DiffDriveGoalEnv"])
def test_an_env_type_with_its_own_step_parts_is_stepped_by_them(base: str) -> None:
    """An env subclass that replaces a part of the step (here its read) gets that part called every step: its
    steps never go in one call (the compiled path's command and read calls still do)."""
    from envs.diffdrive import DiffDriveGoalEnv
    from envs.reach import ErobReachEnv

    reads = []
    kind: Any = ErobReachEnv if base == "ErobReachEnv" else DiffDriveGoalEnv

    class Counted(kind):  # type: ignore[misc, valid-type]
        def _read(self) -> Any:
            reads.append(1)
            return super()._read()

    env = Counted()
    try:
        env.reset(seed=0)
        reads.clear()  # (the reset's read)
        for _ in range(5):
            env.step(env.action_space.sample())
        assert len(reads) == 5 and env.compiled_path is not None and env.compiled_path.steps_taken == 0
        assert env.compiled_path.taken >= 4
    finally:
        env.close()


@pytest.mark.parametrize("replaced", [
    pytest.param("World.hold", marks=pytest.mark.skipif(not kernel.default_mode(),
                                                        reason="the world holds the rig's sleep only compiled")),
    "Rig.sleep"])
def test_a_replaced_wait_is_called_and_the_step_goes_in_three(replaced: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A replaced method on the env's way to the world's hold (a wrapper that counts): the one-call step never
    stands in for it - every step waits through it, one after the other, with the driver path's bits."""
    from joints.sim.world import World

    owner, name = (World, "hold") if replaced == "World.hold" else (joints.Rig, "sleep")
    original = getattr(owner, name)
    calls = [0]

    def counted(self: Any, seconds: float) -> None:
        calls[0] += 1
        original(self, seconds)

    monkeypatch.setattr(owner, name, counted)
    for env_id, mode in (("joints/ErobReach-v0", "position"), ("joints/DiffDriveGoal-v0", None)):
        calls[0] = 0
        runs = [_run(env_id, mode, 12, compiled=c) for c in (True, False)]
        for key in ("reset", "steps", "transactions", "frames", "images", "time"):
            assert runs[0][key] == runs[1][key], key
        assert runs[0]["steps_taken"] == 0 and runs[0]["taken"] >= 12
        assert calls[0] >= 2 * 12  # each step's wait, on both runs
