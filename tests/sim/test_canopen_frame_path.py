"""The arm's CANopen frames take the prepared per-frame path (k3-canopen): every answer of the twins is handed to
the host's bus as it is (no second python-can frame), a received PDO is offered only to the driver that mapped it,
the RPDO1 is packed by the driver's prepared packer and unpacked by the twin's prepared unpacker - and every RPDO
carries ``pack_pdo``'s bytes of the driver's values."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")
gym = pytest.importorskip("gymnasium")

import envs  # noqa: F401  (registers the joints/ ids)
from joints.bench import BASELINE_PERIOD, _baseline_config
from joints.codecs import canopen as co
from joints.drivers.erob_canopen import ErobCanopenDriver

ENV = "joints/ErobArmReach-v0"


def test_the_arm_s_frames_take_the_prepared_path(monkeypatch: pytest.MonkeyPatch) -> None:
    found = _baseline_config(ENV)
    assert found is not None and found[1].startswith("canopen"), found
    sent: list[tuple[ErobCanopenDriver, list[int]]] = []
    send_rpdo = ErobCanopenDriver._send_rpdo

    def recording(driver: ErobCanopenDriver, values: Any) -> None:
        sent.append((driver, list(values)))
        send_rpdo(driver, values)

    monkeypatch.setattr(ErobCanopenDriver, "_send_rpdo", recording)
    env = gym.make(ENV, config=found[0], control_period=BASELINE_PERIOD)
    try:
        env.reset(seed=3)
        u: Any = env.unwrapped
        (bus,) = u.rig.sim.buses.values()
        medium = bus.medium
        drivers = [j.driver for j in u.rig.joints.values()]
        link = drivers[0].link
        assert all(d.link is link for d in drivers)
        f0, tx0, h0 = medium.frames, link.transactions, medium.handed_over
        rng = np.random.default_rng(5)
        for _ in range(20):
            env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        twins_sent = (medium.frames - f0) - (link.transactions - tx0)
        assert twins_sent >= 20 * 12  # 12 TPDOs a step (2 SYNCs: the set-points' acknowledge, the read)
        assert medium.handed_over - h0 == twins_sent  # each reached the host as the frame the twin made
        for d in drivers:  # a TPDO of a node is offered to its driver's subscription only
            for cob in (d.tpdo1_cob, d.tpdo2_cob):
                assert [s.callback for s in link._routes[cob]] == [d.on_tpdo]
            assert d._pack is not None and d._pack[0] is d._rpdo and d._pack[2] == d._rpdo.cob_id(d.node)
        for front in bus.fronts:
            rpdo = front.pdos()[("rpdo", 1)]
            assert rpdo.unpack is not None and rpdo.bits == sum(e[2] for e in rpdo.entries)
        assert len(sent) >= 20 * 3 * 2
    finally:
        env.close()
    for driver, values in sent:  # the prepared packer's bytes are pack_pdo's (the twin's side: the goldens)
        assert driver._pack is not None
        assert driver._pack[1](values) == co.pack_pdo(driver._rpdo.entries, values)
