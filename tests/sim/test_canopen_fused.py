"""A CANopen bus ticked only at its events: the world runs the substeps between them in one compiled call (up to
the medium's next frame edge, a heartbeat, a life-guarding timeout, or a fault the loops trip) with the bits of
ticking every substep - every frame with its instant, the states, the twins' objects."""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import can
import numpy as np
import pytest

pytest.importorskip("mujoco")
gym = pytest.importorskip("gymnasium")

import envs  # noqa: F401  (registers the joints/ ids)
import joints
from joints.bench import BASELINE_PERIOD, _baseline_config
from joints.errors import DeviceFault
from joints.sim import kernel, stepping
from joints.sim.erob_canopen import LIFE_GUARD_ERROR, ErobCanopenBus
from joints.transports.can_sim import LockstepCanBus

MODES = ["compiled", "per-substep", "python"] if kernel.AVAILABLE else ["python"]
HEARTBEAT = 0x700
EMCY = 0x080


class Spy:
    """What the world did: its ticks of the bus, and the runs of substeps a watched fault ended early."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.ticks = 0  #: the world's ticks of the bus (the bus's catch-up of a skipped substep not counted)
        self.stopped = 0  #: runs that ended before the substeps asked for (a watched fault)
        tick, run = ErobCanopenBus.tick, stepping.Group.run_watching
        spy = self

        def counted_tick(bus: ErobCanopenBus, t: float) -> None:
            spy.ticks += 1
            tick(bus, t)

        def counted_run(group: stepping.Group, world: int, n: int, cells: Any) -> int:
            ran = run(group, world, n, cells)
            spy.stopped += ran < n
            return ran

        monkeypatch.setattr(ErobCanopenBus, "tick", counted_tick)
        monkeypatch.setattr(stepping.Group, "run_watching", counted_run)


def _prepare(world: Any, mode: str) -> None:
    if mode == "per-substep":
        world.leave_fused_path()  # what the arena guard does: compiled kernels, one substep at a time
        world.group.replan()
    assert (world.group.compiled and world.group.fusable[world.group_index]) == (mode == "compiled"), mode


def _recorder(world: Any) -> Any:
    """A python-can node on the bus's medium: it sees every frame, stamped with its instant (peers ignore it)."""
    (bus,) = world.buses.values()
    assert isinstance(bus, ErobCanopenBus)
    return bus.medium.attach("recorder", receive_own=True)


def _frames(node: Any) -> list[tuple[int, bytes, float]]:
    return [(m.arbitration_id, bytes(m.data), m.timestamp) for m in node.rx]


def _arm_env(mode: str, steps: int, spy: Spy) -> tuple[list[Any], list[tuple[int, bytes, float]]]:
    found = _baseline_config("joints/ErobArmReach-v0")
    assert found is not None and found[1].startswith("canopen"), found
    env = gym.make("joints/ErobArmReach-v0", config=found[0], control_period=BASELINE_PERIOD)
    world = env.unwrapped.rig.world
    try:
        _prepare(world, mode)
        node = _recorder(world)
        out: list[Any] = [env.reset(seed=5)[0]]
        spy.ticks = 0  # counted over the steps (a reset enables the drives: ticked every substep while enabling)
        rng = np.random.default_rng(5)
        for _ in range(steps):
            obs, reward, terminated, truncated, _info = env.step(rng.uniform(-1, 1, env.action_space.shape))
            out += [obs, reward, terminated, truncated]
            if terminated or truncated:
                out.append(env.reset()[0])
        (bus,) = world.buses.values()
        out += [world.steps, world.time, bus.medium.frames, bus.medium.bits, bus.medium.busy]
        for f in bus.fronts:
            out += [f.state, f.nmt, f.fault_code, f.next_heartbeat, [e.error_code for e in f.emcy_sent],
                    sorted(f.firmware.values.items())]
        out += [np.asarray(world.data.qpos).tobytes(), np.asarray(world.data.qvel).tobytes()]
        return out, _frames(node)
    finally:
        env.close()


def _digest(items: list[Any]) -> str:
    return hashlib.sha256(repr(items).encode()).hexdigest()


@contextmanager
def _mode(monkeypatch: pytest.MonkeyPatch, mode: str) -> Iterator[Spy]:
    with monkeypatch.context() as mp:
        mp.setenv("JOINTS_COMPILED", "0" if mode == "python" else "1")
        yield Spy(mp)


def test_arm_env_on_canopen_runs_fused_with_the_bits_of_ticking_every_substep(monkeypatch: pytest.MonkeyPatch) -> None:
    """ErobArmReach at the bench's 20 ms on CANopen (3 nodes, SYNC + TPDOs every state read, life guarding):
    compiled, the world ticks the bus only at its events; the frames (with their instants), the
    observations, rewards, twins' objects and physics are those of ticking every substep."""
    got: dict[str, tuple[str, list[tuple[int, bytes, float]]]] = {}
    spies: dict[str, Spy] = {}
    for mode in MODES:
        with _mode(monkeypatch, mode) as spy:
            out, frames = _arm_env(mode, 60, spy)
        got[mode] = (_digest(out), frames)
        spies[mode] = spy
    ref = got[MODES[0]]
    for mode, (digest, frames) in got.items():
        assert len(frames) == len(ref[1]) and frames == ref[1], mode
        assert digest == ref[0], mode
    guarding = [f for f in ref[1] if f[0] & 0x780 == HEARTBEAT and f[1] != b"\x00"]
    assert len(guarding) >= 3  # the nodes' guarding replies (the joints' watchdog: life guarding)
    if "compiled" in spies:  # the fast path was taken: far fewer bus ticks than substeps
        assert spies["compiled"].ticks < 0.6 * spies["per-substep"].ticks, {m: s.ticks for m, s in spies.items()}


def _one(**joint: Any) -> dict[str, Any]:
    j: dict[str, Any] = {"device": "erob", "model": "eRob80H100", "bus": "bus", "address": 2,
                         "limits": {"position": [-3.1, 3.1], "velocity": 2.0}, **joint}
    return {"backend": "sim", "sim": {"model": "erob_stand.xml", "timestep": 0.001},
            "buses": {"bus": {"protocol": "canopen"}}, "joints": {"joint1": j}}


def _following_error(rig: joints.Rig) -> list[Any]:
    """A following error (0x6065 small, a fast move): the loops trip 0x8611 inside a run of substeps."""
    j = rig.joints["joint1"]
    j.write("max_position_error", 50)
    j.enable()
    j.move_to(1.0, velocity=2.0, acceleration=40.0, deceleration=40.0)
    with pytest.raises(DeviceFault) as err:
        j.wait(timeout=5, poll=0.037)
    assert err.value.code == 0x8611
    rig.sleep(0.3)
    return [err.value.code, str(err.value), j.state().position, rig.time]


def _life_guarding(rig: joints.Rig) -> list[Any]:
    """Enabled, the host goes silent: the node's life-guarding timeout (its own event) trips EMCY 0x8130."""
    j = rig.joints["joint1"]
    j.enable()
    j.move_to(0.2, velocity=1.0)
    j.wait(timeout=5, poll=0.05)
    assert j.read("guard_time") == 250 and j.read("life_time_factor") == 4  # the joint's watchdog: 1 s
    assert rig.world is not None
    rig.world.advance(1.23)  # no host frame at all
    s = j.state()
    assert s.fault is not None and s.fault.code == LIFE_GUARD_ERROR
    return [s.fault.code, s.position, rig.time]


def _heartbeats(rig: joints.Rig) -> list[Any]:
    """No watchdog: the node produces heartbeats every 100 ms (from the SDO write of 0x1017), the host consumes
    them; they fall inside runs of substeps while the host moves the joint and reads its state now and then."""
    j = rig.joints["joint1"]
    j.enable()
    assert j.read("producer_heartbeat_time") == 100
    j.move_to(0.4, velocity=1.0)
    states = [j.wait(timeout=5, poll=0.043).position]
    for _ in range(5):
        rig.sleep(0.117)
        states.append(j.state().position)
    return [*states, rig.time]


def _velocity_while_enabling(rig: joints.Rig) -> list[Any]:
    """PV: a target velocity sent right after "enable" waits for the brake's 500 ms release and acts at the
    substep it ends (the node's announced event), not later."""
    j = rig.joints["joint1"]
    j.enable()
    j.set_velocity(1.0)
    states = []
    for _ in range(6):
        rig.sleep(0.113)
        s = j.state()
        states += [s.position, s.velocity]
    return [*states, rig.time]


def _slow_heartbeat_write(rig: joints.Rig) -> list[Any]:
    """At 20 kbit/s an SDO write of 0x1017 (heartbeat 100 ms) takes 6 ms on the wire: it reaches the node
    several substeps after the world last ticked the bus, and the node's heartbeats count from the substep
    before that frame's end, as ticking every substep has it."""
    assert rig.world is not None
    (bus,) = rig.world.buses.values()
    assert bus.medium.bitrate == 20_000
    host = LockstepCanBus(medium=bus.medium)
    try:
        host.send(can.Message(arbitration_id=0x602, data=bytes.fromhex("2B17100064000000"), is_extended_id=False))
        rig.world.advance(0.45)
    finally:
        host.shutdown()
    return [rig.time]


def _rig_run(mode: str, scenario: Callable[[joints.Rig], list[Any]]) -> tuple[str, list[tuple[int, bytes, float]]]:
    config = _one(**({"watchdog_ms": 0} if scenario is _heartbeats else
                     {"mode": "pv"} if scenario is _velocity_while_enabling else {}))
    if scenario is _slow_heartbeat_write:
        config["buses"]["bus"]["bitrate"] = 20_000
    with joints.open(config) as rig:
        world = rig.world
        assert world is not None
        _prepare(world, mode)
        node = _recorder(world)
        out = scenario(rig)
        (bus,) = world.buses.values()
        f = bus.fronts[0]
        out += [world.steps, bus.medium.frames, f.state, f.fault_code, [e.error_code for e in f.emcy_sent],
                sorted(f.firmware.values.items()), np.asarray(world.data.qpos).tobytes()]
        return _digest(out), _frames(node)


@pytest.mark.parametrize("scenario", [_following_error, _life_guarding, _heartbeats, _slow_heartbeat_write,
                                      _velocity_while_enabling],
                         ids=["loops-trip", "life-guarding", "heartbeats", "slow-heartbeat-write",
                              "velocity-while-enabling"])
def test_a_node_s_own_frames_inside_a_run_of_substeps_go_out_at_their_substep(
        monkeypatch: pytest.MonkeyPatch, scenario: Callable[[joints.Rig], list[Any]]) -> None:
    """What a node sends by itself inside a run of substeps - EMCY of a fault its loops trip (the run ends at
    that substep), of its life-guarding timeout (announced), its heartbeats (announced) - goes out at the same
    instant, with every other frame and state, as when the bus is ticked every substep."""
    got: dict[str, tuple[str, list[tuple[int, bytes, float]]]] = {}
    spies: dict[str, Spy] = {}
    for mode in MODES:
        with _mode(monkeypatch, mode) as spy:
            got[mode] = _rig_run(mode, scenario)
        spies[mode] = spy
    ref = got[MODES[0]]
    beats = scenario in (_heartbeats, _slow_heartbeat_write)
    own = [f for f in ref[1] if f[0] & 0x7FF == (HEARTBEAT + 2 if beats else EMCY + 2)
           and f[1][:2] not in (b"\x00", b"\x00\x00")]
    if beats:
        assert len(own) >= 3, "fewer than 3 heartbeats"
    elif scenario is not _velocity_while_enabling:
        assert own, "no EMCY on the bus"
    for mode, (digest, frames) in got.items():
        assert frames == ref[1], (mode, [f for f in frames if f[0] & 0x780 in (EMCY, HEARTBEAT)])
        assert digest == ref[0], mode
    if "compiled" in spies:
        assert spies["compiled"].ticks < 0.5 * spies["per-substep"].ticks, {m: s.ticks for m, s in spies.items()}
        if scenario is _following_error:
            assert spies["compiled"].stopped >= 1  # the watched fault ended a run early
