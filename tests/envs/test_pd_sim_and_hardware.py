"""The scripted PD policy of examples/pd_controller.py reaches the target in joints/ErobReach-v0 on the
sim backend and - unchanged - on the hardware backend pointed at ``joints sim serve`` (a real
pseudo-terminal, the real serial transport, the wall clock)."""

from __future__ import annotations

import importlib.util
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager as ContextManager
from pathlib import Path
from types import ModuleType

import pytest

gym = pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")

import envs

ROOT = Path(__file__).resolve().parents[2]
TARGET, START = 1.0, 0.3


@pytest.fixture(scope="module")
def pd() -> ModuleType:
    spec = importlib.util.spec_from_file_location("pd_controller", ROOT / "examples" / "pd_controller.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_pd_policy_reaches_target_in_sim(pd: ModuleType) -> None:
    env = gym.make("joints/ErobReach-v0", action_mode="torque")
    try:
        assert env.unwrapped.rig.backend == "sim"
        ok, steps, obs = pd.reach(env, target=TARGET, start=START)
        assert ok, obs
        assert abs(obs[0] - TARGET) < 0.02 and steps < 100
    finally:
        env.close()


@pytest.fixture
def served(serve_shipped: Callable[[str], ContextManager[str]]) -> Iterator[str]:
    """``joints sim serve`` of the shipped ErobReach config in another process; yields the pty port."""
    with serve_shipped("erob_reach") as port:
        yield port


def test_same_pd_policy_reaches_target_through_hardware_backend(pd: ModuleType, served: str) -> None:
    cfg = envs.default_config("erob_reach")
    cfg["buses"]["rs485"]["port"] = served
    cfg["buses"]["rs485"]["timeout"] = 0.5
    t0 = time.monotonic()
    env = gym.make("joints/ErobReach-v0", config=cfg, backend="hardware", action_mode="torque")
    try:
        u = env.unwrapped
        assert u.rig.backend == "hardware" and u.rig.world is None
        # reset moves to the start pose with the safe profile and waits for standstill, on the wall clock
        ok, _steps, obs = pd.reach(env, target=TARGET, start=START, max_steps=500)
        assert ok, obs
        assert abs(obs[0] - TARGET) < 0.02
    finally:
        env.close()
    assert time.monotonic() - t0 < 20
