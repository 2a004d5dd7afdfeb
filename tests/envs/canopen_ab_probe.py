"""The arm on CANopen from two checkouts in one process: an env step's CPU time with either checkout's code.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/canopen_ab_probe.py OTHER [MODE]``
(``OTHER`` the root of another checkout, e.g. a ``git archive`` of the commit to compare with; ``MODE`` an action
mode of ``joints/ErobArmReach-v0``, default the env's) builds the arm at 20 ms on CANopen at 1 Mbit/s (``joints
bench``'s CANopen row, :func:`joints.bench._baseline_config`) twice in one process: once with this checkout's
``joints`` and ``envs`` packages, once with OTHER's (each imported whole under its own names: ``sys.modules`` holds
one checkout's modules at a time and is switched before each block, so the lazy imports of either find their own).
Block by block each env runs ``STEPS`` steps of the same seeded uniform actions from the same reset, timed by
``time.thread_time``; the blocks alternate (``ROUNDS`` of each), and every block's observations, rewards and ends
must be bit-identical to the first block's (``SAME_BITS=0``: to the first block of the same checkout, for a change
of behaviour). Prints the best and median CPU time per env step of each, and per step the frames, the bits and the
SYNCs on the medium and the bus load at the step's period. Pin it to one core (``taskset -c 1``).
"""

from __future__ import annotations

import logging
import os
import statistics
import sys
from typing import Any

import gymnasium as gym
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # tests/, for probekit
from probekit import timed_steps

STEPS = int(os.environ.get("STEPS", "300"))
ROUNDS = int(os.environ.get("ROUNDS", "10"))
SAME_BITS = os.environ.get("SAME_BITS", "1") != "0"
ENV = "joints/ErobArmReach-v0"
_OURS = ("joints", "envs")


def _ours(name: str) -> bool:
    return any(name == p or name.startswith(p + ".") for p in _OURS)


def _load(root: str) -> dict[str, Any]:
    """Every module of ``joints`` and ``envs`` as imported from ``root`` (left out of ``sys.modules``)."""
    for name in [n for n in sys.modules if _ours(n)]:
        del sys.modules[name]
    sys.path.insert(0, root)
    try:
        import envs  # noqa: F401 - registers the joints/ envs (entry points resolve at make time)
        import joints.bench  # noqa: F401
    finally:
        sys.path.remove(root)
    return {n: m for n, m in sys.modules.items() if _ours(n)}


def _use(modules: dict[str, Any]) -> None:
    for name in [n for n in sys.modules if _ours(n)]:
        del sys.modules[name]
    sys.modules.update(modules)


def _make(modules: dict[str, Any], mode: str | None) -> Any:
    _use(modules)
    found = modules["joints.bench"]._baseline_config(ENV)
    assert found is not None and found[1].startswith("canopen"), found
    kwargs: dict[str, Any] = {"config": found[0], "control_period": 0.02}
    if mode is not None:
        kwargs["action_mode"] = mode
    env = gym.make(ENV, **kwargs)
    assert type(env.unwrapped).__module__ in modules, "the env came from the other checkout"
    return env


def _block(env: Any, modules: dict[str, Any], actions: list[Any]) -> tuple[float, tuple[float, ...], list[Any]]:
    _use(modules)
    obs, _ = env.reset(seed=7)
    bus = next(iter(env.unwrapped.rig.sim.buses.values()))
    medium = bus.medium
    syncs = [0]
    on_frame = type(bus).on_frame

    def counting(frame: Any) -> Any:
        syncs[0] += frame.arbitration_id == 0x80
        return on_frame(bus, frame)

    bus.on_frame = counting  # the medium asks its peer at each frame
    f0, b0 = medium.frames, medium.bits
    t, record = timed_steps(env, obs, actions)
    del bus.on_frame
    n = len(actions)
    return t, ((medium.frames - f0) / n, (medium.bits - b0) / n, syncs[0] / n, medium.bitrate), record


def main(other: str, mode: str | None = None) -> None:
    logging.disable(logging.WARNING)  # the host-only torque limit's warning, once per env
    here = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    trees = {"this": _load(here), "other": _load(os.path.abspath(other))}
    envs = {name: _make(mods, mode) for name, mods in trees.items()}
    rng = np.random.default_rng(11)
    space = envs["this"].action_space
    actions = [rng.uniform(space.low, space.high).astype(space.dtype) for _ in range(STEPS)]
    times: dict[str, list[float]] = {"this": [], "other": []}
    frames: dict[str, tuple[float, ...]] = {}
    first: dict[str, list[Any]] = {}
    for name, env in envs.items():  # a first block of each: the host's state after a first bring-up differs
        _block(env, trees[name], actions)  # (its temperature read's time is not reset with the clock)
    for _ in range(ROUNDS):
        for name, env in envs.items():
            t, frames[name], record = _block(env, trees[name], actions)
            ref = first.setdefault("this" if SAME_BITS else name, record)
            assert record == ref, f"{name}: the bits differ from the first block's"
            times[name].append(t)
    if not SAME_BITS:
        print("bits: " + ("the same" if first["this"] == first["other"] else "differ (SAME_BITS=0: not required)"))
    period = envs["this"].unwrapped.control_period
    for name, ts in times.items():
        n, bits, syncs, rate = frames[name]
        print(f"{name:6s} best {min(ts) * 1e6:7.1f} us  median {statistics.median(ts) * 1e6:7.1f} us per env step "
              f"({ROUNDS} blocks of {STEPS} steps, CPU time); per step {n:.1f} frames, {bits:.0f} bits, "
              f"{syncs:.2f} SYNCs, bus load {bits / rate / period:.1%} at {period * 1e3:g} ms")
    b = min(times["this"]) / min(times["other"]) - 1
    m = statistics.median(times["this"]) / statistics.median(times["other"]) - 1
    print(f"this vs other: best {b * 100:+.1f} %, median {m * 100:+.1f} %")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else None)
