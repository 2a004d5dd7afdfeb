"""The env's own step of two checkouts in one process: ``gym.make``'s env of this checkout's ``envs`` against the
same env of another checkout's ``envs`` (and its ``Rig.sleep``), alternated.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/envstep_ab_probe.py OTHER
[ENV_ID MODE ...]`` (``MODE`` ``-`` for an env without action modes; ``OTHER`` the root of another checkout, e.g. a
``git archive`` of the commit to compare with; default cases: ErobReach, ErobArmReach and DiffDriveGoal in their
action modes) imports OTHER's ``envs`` package beside this one (its modules under their own names, found by
swapping ``sys.modules`` while it loads; the ``joints`` package is this checkout's, its ``Rig.sleep`` OTHER's on the
other env's rig), and makes each env by ``gym.make`` of the registered spec with the class of either checkout
(gymnasium's wrappers as ``gym.make`` builds them). Each block is ``STEPS`` steps of the same seeded uniform
actions from the same reset (resets at episode ends not timed), the two checkouts alternating for ``ROUNDS``
rounds; every block's observations, rewards, ends and infos (keys, order, types, values) must be bit-identical to
the other checkout's. Prints per step the best and median CPU time (``time.thread_time``) of the whole step, and
of the env's own step: the whole less the CPU time inside the compiled path's calls, the world's physics (the clock's
sleep, book and settle hooks, and ``world.sync`` where the env reads the physics) and ``_safe_stop``. ``STUB=1``: the
compiled calls are no-ops (the state read returns the last states) and the physics does not run, so what is timed
is only the env's own Python (cache-warm; bits not compared). Pin it to one core (``taskset -c 1``).
"""

from __future__ import annotations

import dataclasses
import gc
import os
import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

import envs  # noqa: F401 - registers the joints/ envs
import joints

ROUNDS = int(os.environ.get("ROUNDS", "10"))
STEPS = int(os.environ.get("STEPS", "300"))
STUB = os.environ.get("STUB") == "1"
CASES = [("joints/ErobReach-v0", m) for m in ("position", "velocity", "torque")] + \
        [("joints/ErobArmReach-v0", m) for m in ("position", "velocity", "torque")] + \
        [("joints/DiffDriveGoal-v0", None)]


def load_other_envs(root: str) -> dict[str, Any]:
    """OTHER's ``envs`` modules (name -> module), imported beside this checkout's: ``sys.modules`` holds OTHER's
    while they load (their ``from envs.x import`` bind to OTHER's), this checkout's again afterwards."""
    ours = {k: v for k, v in sys.modules.items() if k == "envs" or k.startswith("envs.")}
    for k in ours:
        del sys.modules[k]
    sys.path.insert(0, root)
    try:
        import envs.diffdrive
        import envs.reach  # noqa: F401
        theirs = {k: v for k, v in sys.modules.items() if k == "envs" or k.startswith("envs.")}
    finally:
        sys.path.remove(root)
        for k in list(sys.modules):
            if k == "envs" or k.startswith("envs."):
                del sys.modules[k]
        sys.modules.update(ours)
    return theirs


def other_rig_sleep(root: str) -> Callable[..., Any]:
    """OTHER's ``Rig.sleep``, its module loaded under another name."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("other_rig", os.path.join(root, "joints", "rig.py"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["other_rig"] = module
    spec.loader.exec_module(module)
    return module.Rig.sleep  # type: ignore[no-any-return]


class OtherRig(joints.Rig):
    """A rig whose ``sleep`` is OTHER's (set by :func:`main`)."""


def _make(env_id: str, mode: str | None, cls: type | None) -> Any:
    spec = gym.spec(env_id)
    if cls is not None:
        spec = dataclasses.replace(spec, entry_point=cls)
    return gym.make(spec, **({} if mode is None else {"action_mode": mode}))


def _enc(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return ("nd", v.dtype.str, v.shape, v.tobytes())
    if isinstance(v, dict):
        return ("d", [(k, _enc(x)) for k, x in v.items()])
    return (type(v).__name__, repr(v))


spent = [0.0]
clock = time.thread_time  #: CPU time of this thread: other processes' load does not count


depth = [0]


def _timed(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn``, its CPU time added to ``spent`` (the outermost of nested timed calls only)."""
    def timed(*args: Any, **kwargs: Any) -> Any:
        if depth[0]:
            return fn(*args, **kwargs)
        depth[0] = 1
        t = clock()
        try:
            return fn(*args, **kwargs)
        finally:
            spent[0] += clock() - t
            depth[0] = 0
    return timed


def _instrument(env: Any) -> None:
    u = env.unwrapped
    env.reset(seed=0)
    cp = u.compiled_path
    clock = u.rig.clock
    if STUB:
        last = cp.states(settle=True) if hasattr(u, "wheels") else cp.states()
        js = u.wheels if hasattr(u, "wheels") else u.joints

        def states(*args: Any, last: Any = last, **kwargs: Any) -> Any:
            for j in js:  # as the compiled read: the drives were talked to (no keep-alive read falls due)
                j.last_contact = clock.now()
            return last
        cp.command = lambda *args, **kwargs: None
        cp.states = states
        clock._on_sleep = clock.advance
        clock._on_book = clock._on_settle = None
        return
    cp.command, cp.states = _timed(cp.command), _timed(cp.states)
    for hook in ("_on_sleep", "_on_book", "_on_settle"):
        if getattr(clock, hook) is not None:
            setattr(clock, hook, _timed(getattr(clock, hook)))
    u._safe_stop = _timed(u._safe_stop)
    world = u.rig.world
    world.sync = _timed(world.sync)  # the physics catching up where the env reads it (world.data)


def _block(env: Any, actions: np.ndarray) -> tuple[float, float, list[Any]]:
    obs, _ = env.reset(seed=0)
    record: list[Any] = [obs.tobytes()]
    spent[0] = 0.0
    t0 = clock()
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        record.append((obs, reward, terminated, truncated, info))  # encoded after the block (not timed)
        if terminated or truncated:
            rig, c = spent[0], clock()
            obs, _ = env.reset()
            t0 += clock() - c  # resets not timed
            spent[0] = rig
    total = (clock() - t0) / len(actions)
    if STUB:
        return total, total - spent[0] / len(actions), []
    out = [record[0]] + [(o.tobytes(), repr(r), te, tr, _enc(i)) for o, r, te, tr, i in record[1:]]
    return total, total - spent[0] / len(actions), out


def main() -> None:
    if os.environ.get("GC") == "0":
        gc.disable()
    other = sys.argv[1]
    args = sys.argv[2:]
    cases = [(args[i], None if args[i + 1] == "-" else args[i + 1]) for i in range(0, len(args), 2)] or CASES
    theirs = load_other_envs(other)
    OtherRig.sleep = other_rig_sleep(other)  # type: ignore[method-assign]
    print(f"load {os.getloadavg()[0]:.1f}; us per step, best / median of {ROUNDS} x {STEPS} steps"
          + (" (STUB: compiled calls and physics stubbed)" if STUB else ""))
    for env_id, mode in cases:
        entry = gym.spec(env_id).entry_point
        assert isinstance(entry, str)
        module, name = entry.split(":")
        a = _make(env_id, mode, None)
        b = _make(env_id, mode, getattr(theirs[module], name))
        b.unwrapped.rig.__class__ = OtherRig
        for env in (a, b):
            _instrument(env)
        actions = np.random.default_rng(0).uniform(-1, 1, (STEPS, *a.action_space.shape)).astype(np.float32)
        times: dict[str, list[tuple[float, float]]] = {"this": [], "other": []}
        for r in range(ROUNDS):
            records = {}
            for label, env in (("this", a), ("other", b)) if r % 2 == 0 else (("other", b), ("this", a)):
                total, own, records[label] = _block(env, actions)
                times[label].append((total, own))
            assert records["this"] == records["other"], f"{env_id} {mode}: the checkouts' steps differ"
        line = f"{env_id:26s} {mode or '':9s}"
        for label in ("other", "this"):
            tot = [t for t, _ in times[label]]
            own = [o for _, o in times[label]]
            line += f" | {label}: step {min(tot) * 1e6:6.1f} / {statistics.median(tot) * 1e6:6.1f}" \
                    f" own {min(own) * 1e6:5.1f} / {statistics.median(own) * 1e6:5.1f}"
        print(line)
        a.close()
        b.close()


if __name__ == "__main__":
    main()
