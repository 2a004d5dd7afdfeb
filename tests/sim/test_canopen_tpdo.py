"""The CANopen twin's TPDO bytes are what the codec's ``pack_pdo`` packs from the twin's object values, SYNC by
SYNC (the golden trajectory does not see a statusword bit the host ignores, such as bit 14)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")
gym = pytest.importorskip("gymnasium")

import envs  # noqa: F401  (registers the joints/ ids)
from joints.bench import BASELINE_PERIOD, _baseline_config
from joints.codecs import canopen as co
from joints.sim.erob_canopen import CanopenFront

ENV = "joints/ErobArmReach-v0"


@contextmanager
def _arm(mode: str) -> Iterator[Any]:
    """The arm at the bench's 20 ms on CANopen (its config with the bus switched), reset with seed 7."""
    found = _baseline_config(ENV)
    assert found is not None and found[1].startswith("canopen"), found
    env = gym.make(ENV, config=found[0], control_period=BASELINE_PERIOD, action_mode=mode)
    try:
        yield env
    finally:
        env.close()


def test_every_tpdo_is_pack_pdo_of_the_twin_s_object_values(monkeypatch: pytest.MonkeyPatch) -> None:
    """At each SYNC of a steady run, each synchronous TPDO a twin sends is ``co.pack_pdo`` of its mapped objects
    as the object dictionary reads them (``CanopenFront.value``, clamped to the entry's bits), read at the same
    instant with the sensors' draws put back (so the run itself is not changed by the check)."""
    sync = CanopenFront._sync
    checked: list[tuple[int, bytes]] = []
    mismatched: list[tuple[int, bytes, bytes]] = []

    def checking_sync(front: CanopenFront) -> list[Any]:
        front.pdos()
        sensors = front.firmware.sensors
        saved = [(dict(vars(s)), s.rng.getstate()) for s in sensors]
        want: dict[int, bytes] = {}
        for pdo in front._sync_tpdos:
            values = [0 if name is None else max(lo, min(hi, front.value(name))) for name, lo, hi in pdo.clamps]
            want[pdo.cob_id] = co.pack_pdo(pdo.entries, values)
        for s, (attrs, state) in zip(sensors, saved):
            vars(s).update(attrs)
            s.rng.setstate(state)
        out = sync(front)
        for frame in out:
            cob = frame.arbitration_id
            if cob in want:
                checked.append((cob, bytes(frame.data)))
                if bytes(frame.data) != want[cob]:
                    mismatched.append((cob, bytes(frame.data), want[cob]))
        return out

    monkeypatch.setattr(CanopenFront, "_sync", checking_sync)
    with _arm("position") as env:
        env.reset(seed=3)
        rng = np.random.default_rng(3)
        for _ in range(30):
            env.step(rng.uniform(-1, 1, env.action_space.shape))
    assert not mismatched, mismatched[:3]
    assert len(checked) >= 30 * 2 * 6  # 2 SYNCs a step (the set-points' acknowledge, the state read), TPDO1 + TPDO2 of 3 nodes each
    words = {int.from_bytes(data[:2], "little") for cob, data in checked if cob & 0x780 == 0x180}
    assert any(w & 0x0400 for w in words) and any(w & 0x1000 for w in words)  # target reached, set-point acknowledged
