"""The batch's rigs in ONE compiled call (:class:`joints.CompiledRigs`, :mod:`joints.sim.rigs_exchange`): every rig's
whole step in one call (its commands, its wait for its tick, its state reads) - or, where the step may not go whole,
every rig's commands in one call and every rig's state read in another - gives each rig the bits of its own single
env - the step's outcomes, and after the run every twin's register image and parameter store, the links'
transaction and frame counts, each line's frame log, the compiled path's counts, the rig's clock and the world's
substeps - with the call asserted taken (its counter), and declined (nothing sent, every rig its own way) where one
rig is not the steady case. Compiled and with ``JOINTS_COMPILED=0`` (then the call is never taken and every rig
goes its own way)."""

from __future__ import annotations

import dataclasses
import gc
from typing import Any

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")

from gymnasium.vector import AutoresetMode
from test_batch_path import KERNELS, _pair, _run, _same

import envs  # noqa: F401 - registers the joints/ envs
from joints.errors import JointsError
from joints.sim import kernel

N = 5


@pytest.fixture(params=KERNELS)
def kernels(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    monkeypatch.setenv(kernel.SWITCH, "1" if request.param == "compiled" else "0")
    monkeypatch.delenv(kernel.OLD_SWITCH, raising=False)
    return str(request.param)


def _frames(line: Any) -> list[tuple[Any, ...]]:
    return [(t.start, t.end, t.side, t.due, t.size, t.delivered, t.data, repr(t.payload)) for t in line.log]


def _rig_bits(u: Any) -> tuple[Any, ...]:
    """What a rig keeps beyond its step's outcomes: register images and parameter stores of every twin, each link's
    counts, each line's frame log, time and UART free times, the compiled path's counts, the clock and the substeps."""
    images = []
    for name, bus in sorted(u.rig.sim.buses.items()):
        for address, front in sorted(bus.slaves.items()):
            images.append((name, address, tuple(sorted(front.image().items())),
                           tuple(sorted(front.firmware.values.items())), tuple(front.firmware.write_log)))
    links = {}
    for j in u.rig.joints.values():
        link = j.driver.access.link
        line = link.framing.transport  # its frame log, and where its time and its UARTs stand
        links[id(link)] = (link.transactions, link.framing.exchanges, link.retries_used, _frames(line),
                           line.now, line._clock_seen, tuple(sorted(line._free.items())))
    path = u.compiled_path
    counts = (path.taken, path.fused, path.lane_taken)
    states = [(s.position, s.velocity, s.torque, s.time) for s in u._states]
    states += [(j.last_contact, tuple(sorted(j.driver._cache.items()))) for j in u.joints]  # what the driver holds
    world = u.rig.world
    return (images, list(links.values()), counts, states, u.rig.time, world.steps, u._tick, u._sent.tobytes())


def _each_rig_same(vec: Any, ref: Any) -> None:
    for i, (a, b) in enumerate(zip(vec.unwrapped.envs, ref.envs)):
        _same(_rig_bits(a), _rig_bits(b.unwrapped), f"rig {i}")


def _calls(vec: Any) -> int:
    rigs = vec.unwrapped._batch.rigs
    return 0 if rigs is None else int(rigs.taken)


CASES = [
    ("joints/ErobReach-v0", {}),
    ("joints/ErobReach-v0", {"action_mode": "velocity", "domain_randomization": True}),
    ("joints/ErobReach-v0", {"action_mode": "torque"}),
    ("joints/ErobArmReach-v0", {}),  # three eRobs per rig on one line: each rig's three in the batch's call
    ("joints/ErobArmReach-v0", {"action_mode": "torque", "domain_randomization": True}),
]


@pytest.mark.parametrize(("env_id", "kwargs"), CASES)
def test_rigs_in_one_call_give_each_rig_its_single_env_bits(env_id: str, kwargs: dict[str, Any],
                                                           kernels: str) -> None:
    vec, ref = _pair(env_id, dict(kwargs, max_episode_steps=15), AutoresetMode.NEXT_STEP, n=N)
    try:
        u = vec.unwrapped
        assert u._batch is not None and (u._batch.rigs is not None) == (kernels == "compiled")
        steps = 30  # a truncation: the reset after it goes rig by rig; the last step is a batched one
        rng = np.random.default_rng(9)
        _run(vec, ref, rng.uniform(-1.2, 1.2, (steps, *vec.action_space.shape)).astype(np.float32),
             AutoresetMode.NEXT_STEP)
        if kernels == "compiled":  # the batch's status replies logged as their values, nothing the collector tracks
            gc.collect()
            for rig in u.envs:
                line = next(iter(rig.rig.joints.values())).driver.access.link.framing.transport
                booked = [x for x in line._log if type(x) is tuple]
                assert sum(x[5] is False for x in booked) >= len(rig.rig.joints) * (u.batched_steps - 5)
                assert not any(gc.is_tracked(x) for x in booked)
        _each_rig_same(vec, ref)  # (reads every log: its frames and replies are the single envs')
        if kernels == "compiled":  # each batched step whole in one call: commands, waits, reads
            assert u._batch.joined()
            whole = u._batch.rigs.steps_taken
            # (the few steps that are not whole - a settle wait not over - a call for commands and one for reads)
            assert whole >= u.batched_steps - 3 and whole <= _calls(vec) <= whole + 6, \
                (_calls(vec), whole, u.batched_steps)
            assert u.batched_steps >= steps // 2
            assert all(e.compiled_path.steps_taken >= whole for e in u.envs)
        else:  # no compiled world: never taken, every rig its own way
            assert _calls(vec) == 0
    finally:
        vec.close()
        ref.close()


def test_without_the_whole_step_commands_and_reads_go_in_a_call_each(kernels: str) -> None:
    """Rigs whose step may not go whole (an overrun raised, so the wait is each rig's own, as a single env's
    ``step`` takes its parts then): their commands in one call and their reads (and booked sleeps) in another,
    with each rig's single env bits."""
    vec, ref = _pair("joints/ErobReach-v0", {"max_episode_steps": 15}, AutoresetMode.NEXT_STEP, n=N)
    try:
        for env in [*vec.unwrapped.envs, *(e.unwrapped for e in ref.envs)]:
            env.raise_on_overrun = True
        rng = np.random.default_rng(4)
        _run(vec, ref, rng.uniform(-1, 1, (12, N, 1)).astype(np.float32), AutoresetMode.NEXT_STEP)
        _each_rig_same(vec, ref)
        u = vec.unwrapped
        if kernels == "compiled":
            assert u._batch.rigs.steps_taken == 0
            assert _calls(vec) >= 2 * (u.batched_steps - 1) and u.batched_steps >= 10
        else:
            assert _calls(vec) == 0
    finally:
        vec.close()
        ref.close()


def test_one_rig_not_steady_sends_every_rig_its_own_way(kernels: str) -> None:
    """A trace on one rig's link (a frame-level observer: its requests go through ``Link.request``) declines the
    batch's call before anything is sent; every rig then goes its own way, with the same bits."""
    vec, ref = _pair("joints/ErobReach-v0", {"max_episode_steps": 40}, AutoresetMode.NEXT_STEP, n=N)
    try:
        traces: list[list[Any]] = [[], []]
        for env, seen in zip((vec.unwrapped.envs[3], ref.envs[3].unwrapped), traces):
            link = next(iter(env.rig.joints.values())).driver.access.link
            link.trace = seen.append
        rng = np.random.default_rng(3)
        _run(vec, ref, rng.uniform(-1, 1, (12, N, 1)).astype(np.float32), AutoresetMode.NEXT_STEP)
        _each_rig_same(vec, ref)
        assert _calls(vec) == 0
        assert vec.unwrapped.batched_steps >= 11
        assert len(traces[0]) == len(traces[1]) > 0
        assert [(r.time, r.direction) for r in traces[0]] == [(r.time, r.direction) for r in traces[1]]
    finally:
        vec.close()
        ref.close()


def test_a_refused_command_is_raised_by_the_rigs_own_way(kernels: str) -> None:
    """A command one rig's joint refuses (a position limit narrowed on that rig): the batch's call sends nothing,
    the rigs before it are commanded their own way and its own command raises its error - each rig as the batch
    leaves it without the call (its reference here: the same batch with the call off), and the error the single
    env's."""
    vec, ref = _pair("joints/ErobReach-v0", {}, AutoresetMode.NEXT_STEP, n=N)
    off = gym.make_vec("joints/ErobReach-v0", num_envs=N, vectorization_mode="vector_entry_point")
    try:
        off.unwrapped._batch.rigs = None
        for v in (vec, ref, off):
            v.reset(seed=0)
        a = np.zeros((N, 1), dtype=np.float32)
        for t in range(3):
            out = vec.step(a)
            _same(out, ref.step(a), f"step {t}")
            _same(out, off.step(a), f"step {t}")
        calls = _calls(vec)
        errors = []
        for env in (vec.unwrapped.envs[2], ref.envs[2].unwrapped, off.unwrapped.envs[2]):
            joint = env.joints[0]
            joint.limits = dataclasses.replace(joint.limits, position=(0.5, 0.6))
        for v in (vec, ref, off):
            with pytest.raises(JointsError) as got:  # the same error as the single env's, compared below
                v.step(a)
            errors.append((type(got.value), str(got.value)))
        assert errors[0] == errors[1] == errors[2]
        assert _calls(vec) == calls  # declined: nothing sent by it
        for i, (x, y) in enumerate(zip(vec.unwrapped.envs, off.unwrapped.envs)):
            _same(_rig_bits(x), _rig_bits(y), f"rig {i}")
        taken = [e.compiled_path.taken for e in vec.unwrapped.envs]
        assert taken[:2] == [4, 4] and taken[2:] == [3, 3, 3]  # the two rigs before it commanded, their own way
    finally:
        for v in (vec, ref, off):
            v.close()


def test_only_rigs_of_their_own_worlds_of_erobs_are_carried_together() -> None:
    """The call carries each rig on its own state vector: two rigs of one world (one path twice) are not carried
    together; a rig of another kind (the ZLAC8015D's diff drive) is not carried at all; one rig is; without compiled
    worlds (``JOINTS_COMPILED=0``) none is."""
    import joints

    vec = gym.make_vec("joints/ErobReach-v0", num_envs=2, vectorization_mode="vector_entry_point")
    other = gym.make_vec("joints/DiffDriveGoal-v0", num_envs=2, vectorization_mode="vector_entry_point")
    try:
        paths = [e.compiled_path for e in vec.unwrapped.envs]
        compiled = kernel.default_mode()  # (the call runs compiled worlds only)
        assert (joints.CompiledRigs.build(paths) is not None) == compiled
        assert joints.CompiledRigs.build([paths[0], paths[0]]) is None
        assert (joints.CompiledRigs.build(paths[:1]) is not None) == compiled  # one rig too: its step in the call
        assert joints.CompiledRigs.build([e.compiled_path for e in other.unwrapped.envs]) is None
    finally:
        vec.close()
        other.close()
