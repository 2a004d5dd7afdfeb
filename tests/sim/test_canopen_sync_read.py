"""The arm on CANopen across resets and within a read (k5-sync).

* A reset restarts the world's clock (a new epoch): the link's bus time starts again with it, and the driver's
  times kept on the clock (the temperature read, the guarding) are forgotten with the drive's power cycle, so two
  episodes reset with the same seed are the same episode - the first one after ``gym.make`` too.
* A read takes only TPDOs that answer its own SYNC (each node answers every SYNC, and the host adapter's
  latency and arbitration keep the answers to a previous SYNC queued when the next read sends its own): the
  state read of the arm is one SYNC for its three joints, one sample instant, so is the acknowledge of its three
  set-points (``Rig.move_together``), and every read waits out the TPDOs still owed for the previous SYNC before it
  sends its own.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")
pytest.importorskip("gymnasium")

import envs  # noqa: F401  (registers the joints/ ids)
from joints.drivers.erob_canopen import ErobCanopenDriver
from joints.link.canopen import CanopenLink
from joints.sim.erob_canopen import ErobCanopenBus
from simkit import canopen_arm


def _episode(env: Any, seed: int, steps: int) -> list[Any]:
    obs, info = env.reset(seed=seed)
    out: list[Any] = [(obs.tobytes(), repr(info))]
    rng = np.random.default_rng(11)
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, env.action_space.shape)
                                                            .astype(np.float32))
        out.append((obs.tobytes(), reward, terminated, truncated, repr(info)))
    return out


def test_a_reset_restarts_the_bus_time_with_the_clock(arm: Any) -> None:
    u = arm.unwrapped
    _episode(arm, 4, 60)  # bus time well past where the next episode's reset ends
    link = next(iter(u.rig.joints.values())).driver.link
    assert link.bus_now() > 1.0
    restarts = getattr(link, "restarts", 0)
    arm.reset(seed=4)
    clock = u.rig.clock.now()
    # the bus's time is the last frame's stamp: at most one substep of the world from its clock
    assert abs(link.bus_now() - clock) <= 1e-3, (link.bus_now(), clock)
    assert link.restarts == restarts + 1


def test_the_same_seed_gives_the_same_episode_from_the_first_one_on(arm: Any) -> None:
    first = _episode(arm, 4, 40)
    second = _episode(arm, 4, 40)
    third = _episode(arm, 4, 40)
    assert second == third
    assert first == second


class _Link:
    """What :class:`SyncCycle` asks of a link: bus time, its clock restarts, waits and SYNCs (recorded)."""

    def __init__(self) -> None:
        self.t = 5.0
        self.restarts = 0
        self.waits: list[float] = []
        self.syncs = 0
        self.clock = self

    def now(self) -> float:  # the link's clock (the fake is its own)
        return self.bus_now()

    def bus_now(self) -> float:
        return self.t

    def wait_bus(self, until: float) -> None:
        self.waits.append(until)
        self.t = until

    def sync(self) -> None:
        self.syncs += 1


def test_the_sync_cycle_lays_a_new_grid_after_a_clock_restart() -> None:
    from joints.drivers.canopen_sync import SyncCycle

    link = _Link()
    cycle = SyncCycle(link, 0.001)
    cycle.send({})
    cycle.send({})  # on the grid: waits for its due time
    assert link.waits == [5.001] and cycle.next_due == pytest.approx(5.002)
    link.t, link.restarts = 2.0, 1  # a reset: the clock starts again, earlier than the old grid
    cycle.send({})
    assert link.waits == [5.001]  # not three seconds of waiting for the old grid's next cycle
    assert cycle.next_due == pytest.approx(2.001) and cycle.sync_time == 2.0


def test_every_tpdo_a_read_takes_answers_that_read_s_sync(monkeypatch: pytest.MonkeyPatch) -> None:
    """On the twin, 250 steps: each state read's and each set-point acknowledge's TPDOs (those the state is made
    of) end on the bus after that read's SYNC ended; the arm's three joints of one state read share its instant."""
    sync_ends: list[float] = []  # the end of every SYNC on the wire (the twins see it then, and sample)
    host_syncs = [0]
    last: dict[int, float] = {}  # COB-ID -> the end on the wire of the TPDO the driver took last
    checked = {"state": 0, "acknowledge": 0}
    stale: list[tuple[str, int, float, float]] = []
    stamps: dict[int, tuple[Any, float]] = {}  # id of a decoded message -> (it, its frame's end on the wire)
    on_frame, sync, on_tpdo = ErobCanopenBus.on_frame, CanopenLink.sync, ErobCanopenDriver.on_tpdo
    decode = CanopenLink._decode
    acknowledged, raw = ErobCanopenDriver.setpoint_acknowledged, ErobCanopenDriver._raw

    def seeing(self: Any, frame: Any) -> Any:
        if frame.arbitration_id == 0x80:
            sync_ends.append(self.medium.time())
        return on_frame(self, frame)

    def counting(self: Any, counter: Any = None) -> None:
        host_syncs[0] += 1
        sync(self, counter)

    def decoding(self: Any, frame: Any) -> Any:
        msg = decode(self, frame)
        stamps[id(msg)] = (msg, frame.timestamp)
        return msg

    def taking(self: Any, msg: Any) -> None:
        last[msg.cob_id] = stamps[id(msg)][1]
        on_tpdo(self, msg)

    def check(d: Any, what: str) -> None:
        checked[what] += 1
        k = host_syncs[0]
        end = sync_ends[k - 1] if len(sync_ends) >= k else math.inf  # the read's SYNC: the last the host sent
        for cob in (d.tpdo1_cob, d.tpdo2_cob):
            if not last[cob] > end:
                stale.append((what, cob, last[cob], end))

    def acknowledging(self: Any, since: float) -> Any:
        check(self, "acknowledge")
        return acknowledged(self, since)

    def reading(self: Any, t: float) -> Any:
        check(self, "state")
        return raw(self, t)

    monkeypatch.setattr(ErobCanopenBus, "on_frame", seeing)
    monkeypatch.setattr(CanopenLink, "sync", counting)
    monkeypatch.setattr(ErobCanopenDriver, "on_tpdo", taking)
    monkeypatch.setattr(ErobCanopenDriver, "setpoint_acknowledged", acknowledging)
    monkeypatch.setattr(ErobCanopenDriver, "_raw", reading)
    monkeypatch.setattr(CanopenLink, "_decode", decoding)
    arm = canopen_arm()
    try:
        _run(arm, check, checked, stale)
    finally:
        arm.close()


def _run(arm: Any, check: Any, checked: dict[str, int], stale: list[Any]) -> None:
    u = arm.unwrapped
    arm.reset(seed=5)
    drivers = [j.driver for j in u.rig.joints.values()]
    group = drivers[0].group
    assert all(d.group is group for d in drivers)
    checked["state"] = checked["acknowledge"] = 0
    del stale[:]
    rng = np.random.default_rng(9)
    instants = per_step = 0
    for _ in range(250):
        before, acks = group.samples, group.acknowledges
        _obs, _r, terminated, truncated, _info = arm.step(rng.uniform(-1, 1, arm.action_space.shape)
                                                          .astype(np.float32))
        instants += len({s.time for s in u._states})
        # the path taken: one SYNC for the state read, one acknowledging the three set-points
        per_step += group.samples - before == 2 and group.acknowledges - acks == 1
        if terminated or truncated:
            arm.reset()
    assert checked["state"] >= 750 and checked["acknowledge"] >= 750, checked
    assert not stale, f"{len(stale)} of {sum(checked.values())} reads took a TPDO of an earlier SYNC: {stale[:3]}"
    assert instants == 250  # one sample instant per state read of the arm
    assert per_step == 250


def test_the_rig_reads_a_bus_s_canopen_joints_with_one_sync(arm: Any) -> None:
    u = arm.unwrapped
    arm.reset(seed=2)
    rig = u.rig
    group = next(iter(rig.joints.values())).driver.group
    before = group.samples
    states = rig.read_states()
    assert group.samples - before == 1
    assert len({s.time for s in states.values()}) == 1 and list(states) == list(rig.joints)
    one = rig.read_states(["joint2"])  # a subset: one SYNC for it alone
    assert group.samples - before == 2 and list(one) == ["joint2"]
    assert one["joint2"].time > states["joint2"].time
