"""The CANopen twin's work done once (q3-canopen): a PDO a front has not mapped is only counted
(:meth:`CanopenFront.ignores_pdo`), and each statusword is made once per (state, flags) (``_STATUSWORDS``). Both
are taken on the arm's steps, and the arm's bits, every front's state and every frame on the medium are those of
the twin that offers every PDO to every front and makes every statusword anew."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")
gym = pytest.importorskip("gymnasium")

import envs  # noqa: F401  (registers the joints/ ids)
from joints.bench import BASELINE_PERIOD, _baseline_config
from joints.devices import cia402
from joints.devices.cia402 import State
from joints.sim import erob_canopen
from joints.sim.erob_canopen import CanopenFront

ENV = "joints/ErobArmReach-v0"
STEPS = 20


class _Counting(dict):  # type: ignore[type-arg]
    """The statusword memo, counting the words it hands out (``fresh``: never hands one out)."""

    def __init__(self, *, fresh: bool) -> None:
        super().__init__()
        self.fresh = fresh
        self.hits = 0

    def get(self, key: Any, default: Any = None) -> Any:
        if self.fresh:
            return default
        found = super().get(key, default)
        self.hits += found is not None
        return found


def _run(monkeypatch: pytest.MonkeyPatch, *, prepared: bool) -> tuple[list[Any], int, int]:
    memo = _Counting(fresh=not prepared)
    with monkeypatch.context() as m:
        m.setattr(erob_canopen, "_STATUSWORDS", memo)
        if not prepared:
            m.setattr(CanopenFront, "ignores_pdo", lambda self, cob: False)
        found = _baseline_config(ENV)
        assert found is not None and found[1].startswith("canopen"), found
        env = gym.make(ENV, config=found[0], control_period=BASELINE_PERIOD)
        try:
            obs, _ = env.reset(seed=3)
            u: Any = env.unwrapped
            (bus,) = u.rig.sim.buses.values()
            frames: list[Any] = []
            peer_on_frame = type(bus).on_frame

            def recording(frame: Any) -> Any:
                answers = peer_on_frame(bus, frame)
                frames.append((frame.arbitration_id, bytes(frame.data), float(bus.medium.time()),
                               [(a.arbitration_id, bytes(a.data)) for a in answers]))
                return answers

            bus.on_frame = recording
            record: list[Any] = [obs.tobytes()]
            rng = np.random.default_rng(5)
            for _ in range(STEPS):
                obs, reward, term, trunc, _info = env.step(rng.uniform(-1, 1, env.action_space.shape)
                                                           .astype(np.float32))
                record.append((obs.tobytes(), float(reward), term, trunc))
            for f in bus.fronts:
                record.append((f.frames_in, f.controlword, f.state, f.pp_active, f.pp_pending,
                               sorted(f.firmware.values.items()), [e for e in f.emcy_sent], f.now))
            record.append(frames)
            record.append((bus.medium.frames, bus.medium.bits, float(u.rig.clock.now())))
            ignored = bus.pdos_ignored
        finally:
            env.close()
    return record, ignored, memo.hits


def test_the_arm_s_twin_takes_the_prepared_work_with_the_same_bits(monkeypatch: pytest.MonkeyPatch) -> None:
    fast, ignored, hits = _run(monkeypatch, prepared=True)
    slow, ignored_slow, hits_slow = _run(monkeypatch, prepared=False)
    assert ignored >= STEPS * 12  # 6 RPDOs a step, each offered to the 2 fronts that have not mapped it
    assert hits >= STEPS * 6  # 2 SYNCs a step, a TPDO1 of each of the 3 fronts
    assert ignored_slow == 0 and hits_slow == 0
    assert fast == slow


@pytest.mark.parametrize("state", list(State))
def test_each_memoised_statusword_is_make_statusword_s(state: State, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every word the memo can hold is the one ``make_statusword`` makes of the same state and flags."""
    memo: dict[Any, int] = {}
    monkeypatch.setattr(erob_canopen, "_STATUSWORDS", memo)

    for reached, bit12, bit13 in itertools.product((False, True), repeat=3):
        want = cia402.make_statusword(state, target_reached=reached, bit12=bit12, bit13=bit13, warning=False,
                                      remote=True)
        for _ in range(2):  # made, then handed out
            assert erob_canopen._statusword_of(state, reached, bit12, bit13) == want
    assert len(memo) == 8
