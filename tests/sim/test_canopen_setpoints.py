"""The arm's profile-position set-points on CANopen: one SYNC acknowledges them all (m2-canopen).

CiA 402's set-point handshake is controlword bit 4 up, statusword bit 12 (the drive took it), bit 4 down; the host
sees bit 12 in TPDO1, which every started node sends on every SYNC (a SYNC is a broadcast). ``Rig.move_together``
(the env's position command without a compiled path) sends each node's RPDO, then ONE SYNC for all, then each
node's RPDO clearing bit 4 (:meth:`SyncCycle.setpoints`); a lone ``joint.move_to`` is the same with one node.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")
gym = pytest.importorskip("gymnasium")

import envs  # noqa: F401  (registers the joints/ ids)
from joints.devices import cia402
from joints.drivers.erob_canopen import ErobCanopenDriver
from joints.errors import CommandError, LimitError, StateError
from joints.link.canopen import CanopenLink
from joints.sim.erob_canopen import CanopenFront
from simkit import canopen_arm

ENV = "joints/ErobArmReach-v0"


def _host_frames(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, int, int]]:
    """Every PDO and SYNC the host sends: ("rpdo", node, controlword) or ("sync", 0, 0)."""
    seen: list[tuple[str, int, int]] = []
    send_pdo, sync = CanopenLink.send_pdo, CanopenLink.sync

    def sending(self: Any, cob_id: int, data: bytes) -> None:
        seen.append(("rpdo", cob_id - 0x200, int.from_bytes(data[:2], "little")))
        send_pdo(self, cob_id, data)

    def syncing(self: Any, counter: int | None = None) -> None:
        seen.append(("sync", 0, 0))
        sync(self, counter)

    monkeypatch.setattr(CanopenLink, "send_pdo", sending)
    monkeypatch.setattr(CanopenLink, "sync", syncing)
    return seen


def test_an_arm_step_s_three_set_points_share_one_sync(arm: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    u = arm.unwrapped
    arm.reset(seed=3)
    seen = _host_frames(monkeypatch)
    group = next(iter(u.rig.joints.values())).driver.group
    nodes = [j.driver.node for j in u.rig.joints.values()]
    acked: list[bool] = []
    acknowledged = ErobCanopenDriver.setpoint_acknowledged

    def asking(self: Any, since: float) -> bool:
        acked.append(acknowledged(self, since))
        return acked[-1]

    monkeypatch.setattr(ErobCanopenDriver, "setpoint_acknowledged", asking)
    rng = np.random.default_rng(4)
    for _ in range(40):
        del seen[:]
        before = group.acknowledges
        arm.step(rng.uniform(-1, 1, arm.action_space.shape).astype(np.float32))
        assert group.acknowledges - before == 1  # the path taken
        up = [("rpdo", n, 0x003F) for n in nodes]  # enable + change set immediately + new set-point (bit 4)
        down = [("rpdo", n, 0x002F) for n in nodes]
        assert seen == [*up, ("sync", 0, 0), *down, ("sync", 0, 0)]  # the acknowledge, then the state read
    assert len(acked) == 40 * 3 and all(acked)  # each node's TPDO1 of that one SYNC acknowledged its set-point


def test_a_lone_move_to_is_still_one_sync_of_its_own(arm: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    u = arm.unwrapped
    arm.reset(seed=3)
    seen = _host_frames(monkeypatch)
    j = u.rig.joints["joint2"]
    before = j.driver.group.acknowledges
    j.move_to(j.state().position + 0.01)
    n = j.driver.node
    assert seen == [("sync", 0, 0), ("rpdo", n, 0x003F), ("sync", 0, 0), ("rpdo", n, 0x002F)]  # read, then move
    assert j.driver.group.acknowledges - before == 1


def test_every_move_is_checked_before_anything_is_sent(arm: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    u = arm.unwrapped
    arm.reset(seed=3)
    rig = u.rig
    seen = _host_frames(monkeypatch)
    here = {n: s.position for n, s in rig.read_states().items()}
    del seen[:]
    lim = rig.joints["joint3"].limits.position
    assert lim is not None
    with pytest.raises(LimitError):
        rig.move_together({"joint1": here["joint1"] + 0.01, "joint2": here["joint2"], "joint3": lim[1] + 0.1})
    assert seen == []
    drivers = [j.driver for j in rig.joints.values()]
    group = drivers[0].setpoint_group
    with pytest.raises(CommandError):  # the drive's own range (0x607A is an INTEGER32): before any frame too
        group.move_together({drivers[0]: (0, None, None, None), drivers[2]: (2**31, None, None, None)})
    assert seen == []


def test_a_node_that_does_not_acknowledge_leaves_no_set_point_up(monkeypatch: pytest.MonkeyPatch) -> None:
    deaf: list[int] = []  # the node whose statusword never shows bit 12 (once the env is reset)
    statusword = CanopenFront.statusword

    def never_acknowledging(self: Any) -> int:
        sw = statusword(self)
        return sw & ~cia402.SW_SETPOINT_ACKNOWLEDGE if self.node in deaf else sw

    monkeypatch.setattr(CanopenFront, "statusword", never_acknowledging)  # before the twins prepare their TPDOs
    arm = canopen_arm()
    try:
        arm.reset(seed=3)
        rig = arm.unwrapped.rig
        here = {n: s.position for n, s in rig.read_states().items()}
        deaf.append(rig.joints["joint2"].driver.node)
        seen = _host_frames(monkeypatch)
        group = rig.joints["joint1"].driver.group
        before = group.acknowledges
        with pytest.raises(StateError, match="joint2.*did not acknowledge"):
            rig.move_together({n: p + 0.01 for n, p in here.items()})
        assert group.acknowledges - before > 2  # the deaf node was asked again until the timeout
        last = {node: cw for kind, node, cw in seen if kind == "rpdo"}
        assert sorted(last) == sorted(j.driver.node for j in rig.joints.values())
        assert all(not cw & cia402.CW_NEW_SETPOINT for cw in last.values()), last  # every node's bit 4 is down
    finally:
        arm.close()


def test_joints_no_broadcast_acknowledges_are_moved_one_by_one(monkeypatch: pytest.MonkeyPatch) -> None:
    env = gym.make(ENV, compiled_path=False)  # the arm on its shipped RS485 bus (eRob Modbus)
    try:
        env.reset(seed=3)
        rig = env.unwrapped.rig
        here = {n: s.position for n, s in rig.read_states().items()}
        targets = {n: here[n] + 0.01 * (i + 1) for i, n in enumerate(reversed(list(rig.joints)))}
        calls: list[tuple[str, int, int | None, float]] = []
        for name, j in rig.joints.items():
            move_to = j.driver.move_to

            def recording(target: int, *, speed: int | None = None, _n: str = name, _m: Any = move_to,
                          **kw: Any) -> None:
                calls.append((_n, target, speed, rig.clock.now()))
                _m(target, speed=speed, **kw)

            monkeypatch.setattr(j.driver, "move_to", recording)
        rig.move_together(targets)
        want = [(n, *rig.joints[n].position_command(p)[:2]) for n, p in targets.items()]
        assert [c[:3] for c in calls] == want  # in the order given, each joint's own move_to
        assert calls[0][3] < calls[1][3] < calls[2][3]  # one after the other on the bus
        assert all(rig.joints[n].last_contact > t for n, _, _, t in calls)  # each joint's contact noted after it
    finally:
        env.close()
