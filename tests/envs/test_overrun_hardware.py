"""Overruns on the hardware backend: a fixed-rate step that its bus cannot carry is seen (``info["overrun"]``,
``overruns``, ``overrun_time``, ``raise_on_overrun``) and the period is held on the wall clock.

The bus is a served twin (``joints sim serve`` in another process) that keeps the real bus's time,
with an emulated adapter latency of 30 ms per transaction: no step of joints/ErobReach-v0 fits its
20 ms period. The checks are on wall-clock times, with bounds far from the scheduling noise.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")
pytest.importorskip("serial")
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals need POSIX")

import envs
from envs.reach import ErobReachEnv
from joints.cli.tomlout import dumps
from joints.errors import OverrunError

LATENCY = 0.030  #: s per transaction: longer than the env's 20 ms period on its own
PERIOD = 0.02


@pytest.fixture(scope="module")
def port(tmp_path_factory: pytest.TempPathFactory, sim_served) -> Iterator[str]:  # type: ignore[no-untyped-def]
    cfg = envs.default_config("erob_reach")
    cfg["buses"]["rs485"]["adapter_latency"] = LATENCY
    path = tmp_path_factory.mktemp("overrun") / "slow.toml"
    path.write_text(dumps(cfg))
    with sim_served(path) as served:
        yield served.port("rs485")


class Forced(ErobReachEnv):
    """The env with its construction-time rate check off (it would refuse this bus at 50 Hz)."""

    def _check_rate(self, mode: str = "position") -> None:
        pass


def _env(port: str, control_period: float = PERIOD, **kwargs: Any) -> Forced:
    cfg = envs.default_config("erob_reach")
    cfg["buses"]["rs485"]["port"] = port
    cfg["buses"]["rs485"]["timeout"] = 0.5
    return Forced(config=cfg, backend="hardware", control_period=control_period, **kwargs)


def test_steps_that_do_not_fit_report_overruns(port: str) -> None:
    env = _env(port)
    try:
        u = env
        env.reset(seed=0)
        action = np.zeros(env.action_space.shape, np.float32)
        late: list[float] = []
        spans: list[float] = []
        for _ in range(8):
            t = time.monotonic()
            _obs, _r, _term, _trunc, info = env.step(action)
            spans.append(time.monotonic() - t)
            late.append(info["overrun"])
        assert u.overruns == 8, late
        assert all(x > LATENCY - PERIOD for x in late), late  # one transaction alone takes longer than the period
        assert u.overrun_time == pytest.approx(sum(late))
        # held period: each step is its own bus time (the schedule starts again after an overrun), not
        # a growing backlog; a step that took s seconds overran by about s - period
        assert np.median(np.array(spans) - PERIOD - np.array(late)) == pytest.approx(0.0, abs=0.01)
        # a backlog would make every later step later still (step k: k x ~90 ms); the OS only delays some steps
        # (a loaded machine: up to +170 ms on one step), so the quietest of the last steps is compared with the
        # quietest of the first ones (the very first step has no previous step's reads and overruns less)
        assert min(late[5:]) < 2 * min(late[1:4]), late
    finally:
        env.close()


def test_raise_on_overrun(port: str) -> None:
    env = _env(port, raise_on_overrun=True)
    try:
        env.reset(seed=0)
        with pytest.raises(OverrunError, match="over its 20 ms period"):
            env.step(np.zeros(env.action_space.shape, np.float32))
    finally:
        env.close()


def test_a_step_that_fits_reports_no_overrun(port: str) -> None:
    env = _env(port, control_period=1.0)  # one step's few transactions fit a second with room
    try:
        env.reset(seed=0)
        _obs, _r, _term, _trunc, info = env.step(np.zeros(env.action_space.shape, np.float32))
        assert info["overrun"] == 0.0 and env.overruns == 0
    finally:
        env.close()


def test_sim_and_served_twin_report_the_same_overrun_time(port: str) -> None:
    """Issue 29: a forced config that does not fit (30 ms of adapter latency per transaction at a 20 ms
    period) overruns on the served twin (hardware backend, wall clock) and in sim (simulated clock) alike, step
    by step: every served step overran by at least 90 % of the sim's same step (the bus's time is a floor no
    load lowers), and the step the OS delayed least by at most 110 % of it.

    The served host's own Python and every late wake-up of either process (load 4-7 on 2 cores: 2-25 ms per
    step, most steps) add wall time the simulated clock does not have, so the totals differ by the machine's
    load (measured +2 ... +27 %): the quietest step holds the 10 % whatever the load; the median bounds the rest.
    """
    lates = {}
    for backend in ("sim", "hardware"):
        cfg = envs.default_config("erob_reach")
        cfg["buses"]["rs485"]["adapter_latency"] = LATENCY  # the sim's line and the served twin take the same
        cfg["buses"]["rs485"]["timeout"] = 0.5
        if backend == "hardware":
            cfg["buses"]["rs485"]["port"] = port
        env = Forced(config=cfg, backend=backend, control_period=PERIOD)
        try:
            env.reset(seed=0, options={"start": [0.0], "target": [1.0]})
            action = np.zeros(env.action_space.shape, np.float32)
            lates[backend] = np.array([env.step(action)[4]["overrun"] for _ in range(10)])
            assert env.overruns == 10
            assert env.overrun_time == pytest.approx(lates[backend].sum())
        finally:
            env.close()
    sim, served = lates["sim"], lates["hardware"]
    excess = served / sim - 1
    print(f"overrun time over 10 steps: sim {sim.sum() * 1e3:.1f} ms, served {served.sum() * 1e3:.1f} ms "
          f"({(served.sum() / sim.sum() - 1) * 100:+.1f} %); per step {np.round(excess * 100, 1)} %")
    assert sim[1:] == pytest.approx(sim[1], rel=1e-6)  # the simulated clock: every steady step the same
    assert excess.min() >= -0.10, excess  # no served step shorter than the bus makes it
    assert excess.min() <= 0.10, excess  # the quietest served step within 10 % of the sim's
    assert np.median(excess) <= 0.60, excess  # the others only later by the host's time and the OS's
