"""The one-call eRob CAN exchange (joints.sim.can_exchange, by joints.drivers.erob_can_steady) gives the frame by
frame path's bits.

``joints/ErobReach-v0`` at 20 ms on the eRob CAN custom protocol at 1 Mbit/s (``joints bench``'s CAN row) runs
with the same seeds and actions on the compiled path and on the driver path (``compiled_path=False``): the
observations, rewards and infos, every joint's last state and contact, every frame's end on the medium with what
it carried, the instant the host had each reply, the world's substeps when the drive acted on each request, the
medium's time and counters, the bus's last tick, the world and its clock, the firmware's parameter store, write
log, kernel row and sensors, the front's request count, the link's counts and fence bookkeeping and the driver's
cache must be equal; the one-call exchange must have carried the steady steps (where the world runs compiled).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401 - registers the joints/ envs
from joints.bench import _baseline_config
from joints.devices.erob.can import CanMap
from joints.drivers.erob_can import CAN_STATUS_NAMES, TEMPERATURE
from joints.drivers.erob_can_steady import ErobCanStep
from joints.errors import DeviceRejected, ReplyTimeout
from joints.sim import erob_kernel as K
from joints.sim import kernel

PERIOD = 0.02


def _config() -> dict[str, Any]:
    """The shipped ErobReach config with its joint on an eRob CAN bus at 1 Mbit/s (as ``joints bench`` runs it)."""
    found = _baseline_config("joints/ErobReach-v0")
    assert found is not None and found[1].startswith("erob-can"), found
    config: dict[str, Any] = found[0]
    return config


def _info(info: dict[str, Any]) -> list[tuple[str, Any]]:
    return [(k, (v.dtype.str, v.tobytes()) if isinstance(v, np.ndarray) else repr(v)) for k, v in sorted(info.items())]


class _Recorder:
    """What happens on the wire and at the drive, on either path: every frame's end (and identifier) as the
    medium delivers it, the clock when the host has each reply, the world's substeps when the drive acts."""

    def __init__(self, u: Any) -> None:
        self.frames: list[tuple[float, int]] = []
        self.host: list[float] = []
        self.acted: list[int] = []
        self.replies: list[str] = []  #: what the one-call exchange answered (its kinds)
        world = u.rig.sim
        bus = next(iter(world.buses.values()))
        medium = bus.medium
        deliver = medium._deliver

        def delivered(pend: Any, t: float) -> None:
            self.frames.append((t, pend.frame.arbitration_id))
            deliver(pend, t)

        medium._deliver = delivered
        for front in bus.fronts:
            def handled(r: Any, handle: Any = front.handle) -> Any:
                self.acted.append(world.steps)
                return handle(r)

            front.handle = handled
        for j in u.joints:
            link = j.driver.link
            request = link.request

            def timed(r: Any, *, idempotent: bool = False, request: Any = request) -> Any:
                try:
                    return request(r, idempotent=idempotent)
                finally:  # (a refusal too: the host had its reply)
                    self.host.append(world.clock.now())

            link.request = timed
        self.steps = [s for s in (u.compiled_path._steppers if u.compiled_path else []) if isinstance(s, ErobCanStep)]
        for s in self.steps:
            for method in ("run", "values", "acks"):  # (the replies, a read's values or a command's count)
                call = getattr(s.exchange, method)

                def carried(requests: Any, timeout: float, run: Any = call, s: Any = s, method: str = method) -> Any:
                    out = run(requests, timeout)
                    if out is not None:
                        if method == "acks":  # (done, the refusal or None): the Acks, and the refusal last
                            self.replies += ["Ack"] * (out[0] - (out[1] is not None))
                            self.replies += [] if out[1] is None else [type(out[1]).__name__]
                        else:
                            self.replies += [type(reply).__name__ if method == "run" else "value" for reply in out]
                        for r, (_e0, e1, _r0, r1, seen, acted) in zip(requests, s.exchange.instants):
                            self.frames += [(e1, 0x640 + r.node), (r1, 0x5C0 + r.node)]
                            self.host.append(seen)
                            self.acted.append(int(acted))
                        assert self.host[-1] == world.clock.now()
                    return out

                setattr(s.exchange, method, carried)
            self._step(world, s)

    def _step(self, world: Any, s: ErobCanStep) -> None:
        """The exchange's one-call env step recorded as its calls are (the commands, then the reads made)."""
        call = s.exchange.step

        def stepped(commands: Any, until: float, reads: Any, *args: Any) -> Any:
            got = call(commands, until, reads, *args)
            if got is not None:
                self.replies += ["Ack"] * (got.done - (got.refusal is not None))
                self.replies += [] if got.refusal is None else [type(got.refusal).__name__]
                made = [] if got.read is None else list(reads[:len(got.read[2])])
                self.replies += ["value"] * len(made)
                for r, (_e0, e1, _r0, r1, seen, acted) in zip([*commands[:got.done], *made], s.exchange.instants,
                                                              strict=True):
                    self.frames += [(e1, 0x640 + r.node), (r1, 0x5C0 + r.node)]
                    self.host.append(seen)
                    self.acted.append(int(acted))
                assert self.host[-1] == world.clock.now()
            return got

        s.exchange.step = stepped


def _state(u: Any) -> dict[str, Any]:
    world = u.rig.sim
    bus = next(iter(world.buses.values()))
    medium = bus.medium
    out: dict[str, Any] = {
        "world": (world.steps, world._target, world._booked, world.clock.now(), u.rig.time),
        "medium": (medium.now, medium._free, medium._clock_seen, medium._ticked, medium.frames, medium.bits,
                   medium.busy, repr(medium._seq), medium._wire, len(medium._pending),
                   [(len(n.rx), len(n.held)) for n in medium._nodes]),
        "bus": (bus._last_tick, [(f.requests, f.held) for f in bus.fronts]),
    }
    for f in bus.fronts:
        fw = f.firmware
        out[f"fw{f.node}"] = (sorted(fw.values.items()), list(fw.write_log), np.asarray(fw._row, dtype=float).tobytes(),
                              fw.sensor.rng.getstate(), fw.sensor._age, repr(fw.sensor._age_t))
    for j in u.joints:
        d = j.driver
        out[j.name] = (repr(j.last_state), j.last_contact, j.enabled, sorted(d._cache.items()), d._temperature,
                       d.link.transactions, d.link.fences, sorted(d.link._unsynced), d.link.retries_used,
                       len(d.link.unsolicited))
    return out


def _run(compiled: bool, mode: str, steps: int, *, plant: Any = None, undo: Any = None,
         one_call: bool = True) -> dict[str, Any]:
    """``one_call`` False: the env's steps not in one call each (the command, the sleep and the read one after the
    other: a plant on the rig's sleep or on the exchange's ``acks`` acts there)."""
    env = gym.make("joints/ErobReach-v0", config=_config(), control_period=PERIOD, action_mode=mode,
                   compiled_path=compiled)
    u: Any = env.unwrapped
    try:
        out: dict[str, Any] = {"steps": []}
        obs, info = env.reset(seed=3)
        if not one_call and u.compiled_path is not None:
            u.compiled_path._step = None
        out["reset"] = (obs.tobytes(), _info(info))
        rec = _Recorder(u)
        rng = np.random.default_rng(5)
        for k in range(steps):
            if plant is not None:
                plant(k, u)
            action = rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32)
            try:
                obs, reward, terminated, truncated, info = env.step(action)
            except DeviceRejected as exc:
                out["steps"].append(("refused", str(exc), exc.code))
                break
            except ReplyTimeout as exc:
                out["steps"].append(("timeout", type(exc).__name__))  # (its text names the run's channel)
                break
            out["steps"].append((obs.tobytes(), reward, terminated, truncated, _info(info),
                                 [f.held for f in next(iter(u.rig.sim.buses.values())).fronts]))
            if terminated or truncated:
                obs, info = env.reset()
                out["steps"].append(("reset", obs.tobytes(), _info(info)))
        out["state"] = _state(u)
        out["frames"], out["host"], out["acted"], out["replies"] = rec.frames, rec.host, rec.acted, rec.replies
        cp = u.compiled_path
        out["taken"] = None if cp is None else (cp.taken, cp.fused, sum(s.exchange.taken for s in rec.steps))
        out["refilled"] = sum(s.exchange.refilled for s in rec.steps)  # command plans made from a kept one
        out["setpoints"] = [(s.exchange.setpoints, s.exchange.held) for s in rec.steps]
        out["values"] = sum(s.values_taken for s in rec.steps)  # state reads taken by their values
        out["acks"] = sum(s.acks_taken for s in rec.steps)  # commands taken without their Ack objects
        out["sleeps"] = sum(s.exchange.sleeps for s in rec.steps)  # calls that ran the world's held period sleep
        out["proofs"] = [(sorted(s._encoded), sorted((t.__name__, n) for t, n in s._acked)) for s in rec.steps]
        out["plain"] = [sorted(s._plain_of[1]) for s in rec.steps]  # names read without from_wire (proven)
        return out
    finally:
        if undo is not None:  # what the plant changed, put back so that closing reaches the drive
            undo(u)
        env.close()


def _same(driver: dict[str, Any], compiled: dict[str, Any]) -> None:
    for key in ("reset", "steps", "frames", "host", "acted", "state"):
        if isinstance(driver[key], dict):
            for k in driver[key]:
                assert compiled[key][k] == driver[key][k], (key, k)
        assert compiled[key] == driver[key], key


@pytest.mark.parametrize("mode", ["position", "velocity", "torque"])
def test_the_compiled_can_step_gives_the_frame_by_frame_bits(mode: str) -> None:
    steps = 75  # 1.5 s: the temperature read (once a second) is among them
    driver = _run(False, mode, steps)
    compiled = _run(True, mode, steps)
    assert driver["taken"] is None
    assert len(driver["frames"]) > 14 * steps  # 7-8 transactions a step, two frames each
    _same(driver, compiled)
    taken, fused, calls = compiled["taken"]
    if kernel.default_mode():  # the one-call exchange carried the steady steps (it needs the compiled world)
        assert calls >= steps  # the state reads of every step (and the position commands)
        assert compiled["values"] >= steps  # every step's state read taken by its values, without replies
        assert compiled["acks"] >= steps - 1  # every step's command (or set-point) taken without its Ack objects
        assert compiled["sleeps"] >= steps - 1  # the period's sleep held by the world, run by the read's call
        ((encoded, acked),) = compiled["proofs"]  # a command's frame built once, its Acks asked once
        ((plain),) = compiled["plain"]  # both reads' names (with the temperature, without) decoded as read
        assert plain == sorted([CAN_STATUS_NAMES, (*CAN_STATUS_NAMES, TEMPERATURE)])
        assert len(encoded) == 1 and ("Write", encoded[0][0]) in acked
        if mode == "position":
            assert taken >= steps - 1 and fused >= 8 * steps - 8
            assert ("Command", encoded[0][0]) in acked
            assert compiled["refilled"] >= steps - 2  # the command's rows kept, its values put in each step
        else:  # a speed or current set-point: one write of 0x01FE, in a call of its own; then the state read's
            assert taken >= steps - 1 and fused >= 7 * steps - 1
            ((setpoints, held),) = compiled["setpoints"]
            assert setpoints >= steps - 1 and held == 0
    else:
        assert calls == 0 and fused == 0 and compiled["values"] == compiled["acks"] == compiled["sleeps"] == 0


@pytest.mark.skipif(not kernel.default_mode(), reason="the world holds sleeps for the one-call exchange (compiled)")
def test_the_world_holds_the_period_sleep_never_a_wait_of_the_medium_s_own(monkeypatch: pytest.MonkeyPatch) -> None:
    """On the compiled path the world holds the env's period sleep (``World.hold``: the read's call runs it) and,
    under a trace (every request frame by frame: the medium's ``_sync`` settles the world first), still the period
    sleep - never a wait the medium makes itself (its ``_cap`` set: a held one would tick it without its cap).
    (The env's steps one call each off: the command, the sleep and the read one after the other, as in
    tests/sim/test_can_step.py's reference.)"""
    env = gym.make("joints/ErobReach-v0", config=_config(), control_period=PERIOD, compiled_path=True)
    u: Any = env.unwrapped
    try:
        env.reset(seed=3)
        u.compiled_path._step = None
        world = u.rig.sim
        medium = next(iter(world.buses.values())).medium
        (step,) = [s for s in u.compiled_path._steppers if isinstance(s, ErobCanStep)]
        seen: list[tuple[bool, bool]] = []  # (the medium waiting itself, the world held the sleep) per sleep
        defer = world._defer

        def deferring(seconds: float, *, held: bool) -> None:
            waiting = medium._cap is not None
            defer(seconds, held=held)
            if held:
                seen.append((waiting, world._held))

        monkeypatch.setattr(world, "_defer", deferring)
        action = np.zeros(env.action_space.shape, dtype=np.float32)
        for _ in range(5):
            env.step(action)
        assert [h for _, h in seen] == [True] * 5 and step.exchange.sleeps == 5  # each run by the read's call
        u.rig.trace(lambda record: None)
        for _ in range(5):
            env.step(action)
        u.rig.trace(None)
        waits = [h for w, h in seen if w]
        periods = [h for w, h in seen if not w]
        assert waits and not any(waits)  # the frame-by-frame requests' own waits: never held
        assert periods == [True] * 10 and step.exchange.sleeps == 5  # held, then settled by the medium's _sync
    finally:
        env.close()


def test_a_replaced_reply_check_leaves_the_steps_to_the_frame_by_frame_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """From step 10 the codec's ``answers`` (what the stock ``is_reply`` asks, and what the state read's proof by
    one reply of value 0 rests on) is wrapped: from then on nothing goes by the call, with the same bits."""
    from joints.codecs import erob_can as ec

    original = ec.answers
    calls: list[tuple[int, int]] = []

    def plant(k: int, u: Any) -> None:
        if k == 10:
            monkeypatch.setattr(ec, "answers", lambda request, reply: original(request, reply))
        cp = u.compiled_path
        if cp is not None:
            (step,) = [s for s in cp._steppers if isinstance(s, ErobCanStep)]
            calls.append((cp.fused, step.values_taken))

    out = {}
    for compiled in (False, True):
        monkeypatch.setattr(ec, "answers", original)
        calls.clear()
        out[compiled] = _run(compiled, "position", 20, plant=plant)
    _same(out[False], out[True])
    if kernel.default_mode():
        assert calls[10][0] > calls[1][0] > 0 and calls[10][1] > calls[1][1] > 0  # the call carried the first steps
        assert calls[10] == calls[-1]  # then never again


def test_a_replaced_value_decode_decodes_each_value_by_it(monkeypatch: pytest.MonkeyPatch) -> None:
    """From step 10 ``CanMap.from_wire`` (what the state read's values skip where it is the identity) is wrapped:
    from then on every value the compiled path reads goes through it, with the same bits; a name whose
    ``from_wire`` is not the identity (a uint32, a scaled value) is never taken as read."""
    original = CanMap.from_wire
    decoded: list[str] = []

    def from_wire(self: CanMap, name: str, raw: int) -> int:
        decoded.append(name)
        return original(self, name, raw)

    def plant(k: int, u: Any) -> None:
        if k == 10:
            monkeypatch.setattr(CanMap, "from_wire", from_wire)

    out = {}
    for compiled in (False, True):
        monkeypatch.setattr(CanMap, "from_wire", original)
        decoded.clear()
        out[compiled] = _run(compiled, "position", 20, plant=plant)
        if compiled and kernel.default_mode():
            assert out[True]["values"] >= 19 and decoded.count("actual_position") == 10  # steps 10-19, by it
    _same(out[False], out[True])
    monkeypatch.setattr(CanMap, "from_wire", original)
    env = gym.make("joints/ErobReach-v0", config=_config(), control_period=PERIOD, compiled_path=True)
    try:
        env.reset(seed=3)
        u: Any = env.unwrapped
        if kernel.default_mode():
            (step,) = [s for s in u.compiled_path._steppers if isinstance(s, ErobCanStep)]
            assert step._plain(CAN_STATUS_NAMES)
            assert not step._plain((*CAN_STATUS_NAMES, "dwell_time"))  # scaled (20)
            assert not step._plain(("digital_inputs",))  # uint32
    finally:
        env.close()


def test_a_start_the_drive_refuses_mid_step_is_refused_the_same_way() -> None:
    """The drive is switched off behind the host's back: the host still takes the step for steady, the call
    carries the target write, the drive answers the start with 0x0027 and the host raises what the link raises;
    everything stands where the frame-by-frame path leaves it."""

    def plant(k: int, u: Any) -> None:
        if k == 12:
            fw = next(iter(u.rig.sim.buses.values())).fronts[0].firmware
            fw.write("enable_the_motor", 0)

    driver = _run(False, "position", 20, plant=plant)
    compiled = _run(True, "position", 20, plant=plant)
    assert driver["steps"][-1][0] == "refused" and driver["steps"][-1][2] == 0x0027
    _same(driver, compiled)
    if kernel.default_mode():  # the call carried the steps, and the refused start (its last reply)
        assert compiled["taken"][2] >= 12  # (one call a step: the command, the hold and the read)
        assert compiled["replies"][-2:] == ["Ack", "ErrorReply"]


@pytest.mark.parametrize("mode", ["velocity", "torque"])
def test_a_set_point_the_drive_is_no_longer_ready_for_is_held_the_same_way(mode: str) -> None:
    """Step 12's command reaches the drive after a substep in which its communication watchdog trips (planted on
    its row: the host checked it READY before sending): the front holds the set-point (0x01FE stored, no target
    written, the bus ticking every substep from then on) - inside the call as frame by frame."""

    def plant(k: int, u: Any) -> None:
        if k == 12:
            world = u.rig.sim
            dt = world.timestep
            # the clock 50 us before the substep end after the physics' last one: the command's request ends
            # past it, so the drive acts after that substep (the one in which the watchdog trips)
            u.rig.sleep(world.steps * dt + dt - 5e-5 - world.clock.now())
            fw = next(iter(world.buses.values())).fronts[0].firmware
            fw._row[K.WATCHDOG] = 1e-300

    driver = _run(False, mode, 20, plant=plant)
    compiled = _run(True, mode, 20, plant=plant)
    _same(driver, compiled)
    if kernel.default_mode():
        ((setpoints, held),) = compiled["setpoints"]
        assert held == 1 and setpoints >= 19  # the call met the hold


def test_a_drive_at_another_node_id_is_not_reached_by_a_kept_plan() -> None:
    """From step 12's period hold on, the drive answers at another node id (as after a saved node-id change and a
    power cycle): the state read that follows, to the old id, goes unanswered on both paths - the read plan kept
    from before does not carry it to the drive."""

    def front(u: Any) -> Any:
        return next(iter(u.rig.sim.buses.values())).fronts[0]

    def plant(k: int, u: Any) -> None:
        if k == 12:  # the command still reaches the drive; the node id changes during the hold
            sleep = u.rig.sleep

            def then_renumber(seconds: float) -> None:
                sleep(seconds)
                front(u)._node = front(u).node + 5
                u.rig.sleep = sleep

            u.rig.sleep = then_renumber

    def undo(u: Any) -> None:
        front(u)._node = None

    driver = _run(False, "position", 20, plant=plant, undo=undo)
    compiled = _run(True, "position", 20, plant=plant, undo=undo, one_call=False)  # (the plant is on rig.sleep)
    assert driver["steps"][-1][0] == "timeout"
    _same(driver, compiled)


def test_a_trace_or_a_replaced_method_leaves_the_steps_to_the_frame_by_frame_path(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """From step 10 a trace is hooked, from step 20 the front's read is wrapped (as a test planting replies
    would): from then on nothing goes by the call, and the bits (and the trace) stay the frame-by-frame path's."""
    from joints.sim.erob_can import ErobCanFront

    records: list[Any] = []
    calls: list[int] = []
    original = ErobCanFront._read

    def plant(k: int, u: Any) -> None:
        if k == 10:
            u.rig.trace(records.append)
        elif k == 20:
            u.rig.trace(None)
            monkeypatch.setattr(ErobCanFront, "_read", lambda self, r: original(self, r))
        cp = u.compiled_path
        if cp is not None:
            calls.append(cp.fused)

    out = {}
    for compiled in (False, True):
        records.clear()
        calls.clear()
        monkeypatch.setattr(ErobCanFront, "_read", original)
        out[compiled] = _run(compiled, "position", 30, plant=plant)
        out[compiled]["trace"] = [(r.time, r.direction, r.data, r.meaning) for r in records]
        out[compiled]["calls"] = list(calls)
    _same(out[False], out[True])
    assert len(out[True]["trace"]) > 100 and out[True]["trace"] == out[False]["trace"]
    fused = out[True]["calls"]
    if kernel.default_mode():
        assert fused[10] > fused[1] > 0  # the call carried the first steps
        assert fused[10] == fused[20] == fused[-1]  # traced, then a replaced method: never again


@pytest.mark.skipif(not kernel.default_mode(), reason="the one-call exchange runs on a compiled world")
def test_a_reply_of_the_call_that_does_not_answer_its_request_raises_unexpected_reply() -> None:
    """A fault of the emulator's call (a reply from another node) is a typed error at the step, not a state."""
    from joints.codecs import erob_can as ec
    from joints.errors import UnexpectedReply

    env = gym.make("joints/ErobReach-v0", config=_config(), control_period=PERIOD, compiled_path=True)
    u: Any = env.unwrapped
    try:
        env.reset(seed=3)
        u.compiled_path._step = None  # (the env's steps one call each: the command by acks, planted here)
        (step,) = [s for s in u.compiled_path._steppers if isinstance(s, ErobCanStep)]
        acks = step.exchange.acks

        def misrouted(requests: Any, timeout: float) -> Any:  # the start refused, by another node
            got = acks(requests, timeout)
            if got is not None and len(requests) == 2:
                got = (got[0], ec.ErrorReply(requests[-1].node + 1, 0x0027))
            return got

        for _ in range(3):  # (the Acks of the command's requests asked once of the rule: then taken by their node)
            env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        assert step._acked
        step.exchange.acks = misrouted
        with pytest.raises(UnexpectedReply, match="does not answer it"):
            env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        step.exchange.acks = acks
    finally:
        env.close()
