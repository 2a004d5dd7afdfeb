"""Issue 29: simulated serial buses take the wire's time (characters, t3.5, the drive's turnaround, the
adapter's latency) on the byte path and the direct path alike; ``timing = "ideal"`` takes none; the
planner's cycle time agrees; envs refuse rates their bus cannot carry and report overruns."""

from __future__ import annotations

from typing import Any

import pytest

pytest.importorskip("mujoco")

import joints
from envs.configs import default_config
from joints import bench, registry
from joints.errors import ConfigError, OverrunError
from joints.link.trace import TraceRecord

T35 = 0.00175  # s: Modbus RTU's silence above 19200 baud


def _arm(direct: bool, timing: str = "wire", **bus: Any) -> dict[str, Any]:
    """The shipped 3-joint eRob arm: its joints on one RS485 Modbus bus at 115200 baud."""
    cfg = default_config("erob_arm_reach")
    cfg["sim"]["direct"] = direct
    cfg["buses"]["rs485"].update(timing=timing, **bus)
    return cfg


def _reads(cfg: dict[str, Any], n: int = 100) -> tuple[float, list[TraceRecord]]:
    """Simulated seconds ``n`` read_states() take, and one traced read_states()'s frames."""
    with joints.open(cfg) as rig:
        rig.read_states()
        t0 = rig.time
        for _ in range(n):
            rig.read_states()
        elapsed = rig.time - t0
        frames: list[TraceRecord] = []
        rig.trace(frames.append)
        rig.read_states()
        rig.trace(None)
        return elapsed, frames


def _expected(frames: list[TraceRecord], n: int, *, turnaround: float, latency: float, gap: float) -> float:
    """The planner's arithmetic for n times these frames: 10-bit characters at 115200 baud, a gap after each
    frame, and per reply the drive's turnaround and the adapter's latency."""
    chars = sum(len(r.data) for r in frames)
    replies = sum(1 for r in frames if r.direction == "rx")
    return n * (chars * 10 / 115200 + gap * len(frames) + replies * (turnaround + latency))


@pytest.mark.parametrize("direct", [True, False], ids=["direct", "bytes"])
def test_read_states_of_the_arm_take_the_planners_time_on_both_paths(direct: bool) -> None:
    elapsed, frames = _reads(_arm(direct))
    assert len(frames) == 6  # three FC03 requests and their replies
    latency = registry.ADAPTER_LATENCY["serial"]
    expected = _expected(frames, 100, turnaround=0.0008, latency=latency, gap=T35)
    assert elapsed == pytest.approx(expected, rel=0.05)
    # and the planner's own cycle (commands + reads) counts the same terms per transaction
    (p,) = bench.plan(_arm(direct), 10.0)
    assert p.overhead == pytest.approx(p.transactions * (0.0008 + latency))


def test_direct_and_byte_paths_take_the_same_time() -> None:
    (t_direct, _), (t_bytes, _) = _reads(_arm(True), 20), _reads(_arm(False), 20)
    assert t_direct == pytest.approx(t_bytes, abs=1e-9)
    ends = []
    for direct in (True, False):  # enabling, position targets (FC16, FC06) and reads; a broadcast write
        with joints.open(_arm(direct)) as rig:
            for j in rig.joints.values():
                j.enable()
            rig.sleep(0.6)
            for _ in range(5):
                bench._cycle(rig)
            rig.buses["rs485"].link.write_register(0, 0x0002, 0)  # broadcast: no reply, the next frame waits its gap
            rig.read_states()
            ends.append((rig.time, [s.position for s in rig.read_states().values()]))
    assert ends[0] == ends[1]


def test_ideal_timing_takes_no_time() -> None:
    elapsed, _ = _reads(_arm(True, "ideal"))
    assert elapsed == 0.0
    elapsed, _ = _reads(_arm(False, "ideal"))
    assert elapsed == 0.0


def test_turnaround_and_adapter_latency_come_from_the_config() -> None:
    cfg = _arm(True, adapter_latency=0.004)
    for j in cfg["joints"].values():
        j["profile"] = {"turnaround": 0.002}
    elapsed, frames = _reads(cfg, 20)
    assert elapsed == pytest.approx(_expected(frames, 20, turnaround=0.002, latency=0.004, gap=T35), rel=0.05)


def test_a_state_is_sampled_inside_its_own_transaction() -> None:
    with joints.open(_arm(True)) as rig:
        j = rig.joints["joint1"]
        before = rig.time
        s = j.state()
        assert before < s.time <= rig.time


@pytest.mark.mks_firmware
def test_mks_native_bus_takes_its_wire_time_without_t35() -> None:
    cfg = default_config("mks_axis")
    bus = cfg["buses"][next(iter(cfg["buses"]))]
    assert bus["protocol"] == "mks-serial"
    baud = bus.get("baudrate", 38400)
    with joints.open(cfg) as rig:
        rig.read_states()
        t0 = rig.time
        for _ in range(50):
            rig.read_states()
        elapsed = rig.time - t0
        frames: list[TraceRecord] = []
        rig.trace(frames.append)
        rig.read_states()
        rig.trace(None)
    chars = sum(len(r.data) for r in frames)
    replies = sum(1 for r in frames if r.direction == "rx")
    expected = 50 * (chars * 10 / baud + replies * (0.0008 + registry.ADAPTER_LATENCY["serial"]))
    assert elapsed == pytest.approx(expected, rel=0.05)


def test_an_env_refuses_a_rate_its_bus_cannot_carry() -> None:
    from envs.reach import ErobArmReachEnv

    with pytest.raises(ConfigError) as err:
        ErobArmReachEnv(control_period=0.02)
    text = str(err.value)
    assert "does not fit" in text and "369%" in text and "CANopen" in text and "buses.rs485" in text


def test_every_shipped_env_fits_its_bus_with_margin() -> None:
    from envs.diffdrive import DiffDriveGoalEnv
    from envs.mks_axis import MksAxisPositionEnv
    from envs.reach import ErobArmReachEnv, ErobReachEnv

    for make, config, mode in ((ErobReachEnv, "erob_reach", "position"), (ErobArmReachEnv, "erob_arm_reach", "position"),
                               (DiffDriveGoalEnv, "zlac_diffdrive", "velocity"),
                               (MksAxisPositionEnv, "mks_axis", "position")):
        env = make()  # refuses a rate it cannot carry
        try:
            period = env.unwrapped.control_period
            env.reset(seed=0)
            for _ in range(20):
                env.step(env.action_space.sample())
            assert env.overruns == 0 and env.overrun_time == 0.0, config  # and keeps its schedule
        finally:
            env.close()
        for backend in ("sim", "hardware"):  # the hardware form of the config too (planned on its twins)
            cfg = default_config(config)
            cfg["backend"] = backend
            for p in bench.cycle_times(cfg, mode).values():
                assert p.share(period) <= bench.CYCLE_BUDGET, (config, p.text(1 / period))


def test_a_step_that_does_not_fit_reports_its_overrun() -> None:
    from envs.reach import ErobReachEnv

    class Forced(ErobReachEnv):
        def _check_rate(self, mode: str = "position") -> None:  # the check would refuse 50 Hz
            pass

    env = Forced(control_period=0.02)
    try:
        env.reset(seed=0)
        lates = []
        for _ in range(10):
            info = env.step(env.action_space.sample())[4]
            lates.append(info["overrun"])
        # the first step's commands start a period's schedule; from then on every cycle is late
        assert lates[0] == 0.0 and env.overruns == 9 and all(x > 0 for x in lates[1:])
        assert env.overrun_time == pytest.approx(sum(lates))
        (p,) = bench.plan(default_config("erob_reach"), 50.0)
        assert env.overrun_time / 9 == pytest.approx(p.cycle - 0.02, rel=0.25)  # the cycle's excess per step
    finally:
        env.close()
    env = Forced(control_period=0.02, raise_on_overrun=True)
    try:
        env.reset(seed=0)
        env.step(env.action_space.sample())  # in time: the schedule starts with it
        with pytest.raises(OverrunError, match="over its 20 ms period"):
            env.step(env.action_space.sample())
    finally:
        env.close()



@pytest.mark.parametrize("protocol", ["erob-can", "canopen"])
def test_can_buses_add_turnaround_and_adapter_latency(protocol: str) -> None:
    cfg = default_config("erob_arm_reach")
    cfg["buses"]["rs485"] = {"protocol": protocol, "bitrate": 1_000_000}
    (p,) = bench.plan(cfg, 50.0)
    with joints.open(cfg) as rig:
        for j in rig.joints.values():
            j.enable()
        rig.sleep(0.6)
        bench._cycle(rig)
        t0 = rig.time
        for _ in range(20):
            bench._cycle(rig)
        per_cycle = (rig.time - t0) / 20
    latency = registry.ADAPTER_LATENCY["can"]
    if protocol == "erob-can":  # request/reply: the sim's cycle is the planner's, turnaround and latency included
        assert p.overhead == pytest.approx(p.transactions * (0.0008 + latency))
        assert per_cycle == pytest.approx(p.cycle, rel=0.05)
    else:  # PDOs at the SYNC: no turnaround, the host sees each TPDO after the adapter's latency
        assert p.overhead == pytest.approx(p.transactions * latency)
        assert p.wire < per_cycle <= p.cycle * 1.05
    if protocol == "canopen":
        return  # its state reads wait for the SYNC schedule's TPDOs: protocol time, not bus time
    cfg["buses"]["rs485"]["timing"] = "ideal"
    with joints.open(cfg) as rig:
        t0 = rig.time
        for _ in range(20):
            rig.read_states()
        assert rig.time == t0


def test_the_zlac_log_loop_takes_what_the_real_drive_took() -> None:
    """The public log of a real ZLAC8015D at 115200 baud (augustocamaral2003/zlac8015d-tests, scripts/data.csv:
    754 samples in 10.0 s) runs one FC06 write and one FC03 read of one register per loop in 13.3 ms; the
    twin's bus with the default turnaround and adapter latency takes the same."""
    cfg = default_config("zlac_diffdrive")
    address = cfg["joints"]["left_wheel"]["address"]
    with joints.open(cfg) as rig:
        link = rig.buses["rs485"].link
        t0 = rig.time
        for _ in range(100):
            link.write_register(address, 0x2088, 0)  # target velocity (left), r/min
            link.read_registers(address, 0x20AB, 1)  # actual velocity (left)
        per_loop = (rig.time - t0) / 100
    assert per_loop == pytest.approx(10.005854807 / 753, rel=0.02)


def test_the_host_clock_shows_bus_time_exactly() -> None:
    """Bus time is not rounded to physics substeps: n read_states take exactly the planner's time on the host's
    clock, and the physics stands at the end of the substep that reaches the clock (at most one substep ahead)."""
    elapsed, frames = _reads(_arm(True), 10)
    latency = registry.ADAPTER_LATENCY["serial"]
    assert elapsed == pytest.approx(_expected(frames, 10, turnaround=0.0008, latency=latency, gap=T35),
                                    rel=1e-9)
    with joints.open(_arm(True)) as rig:
        rig.read_states()
        world = rig.sim
        assert world.time - world.timestep < rig.time <= world.time
        assert 1e-6 < rig.time % world.timestep < world.timestep - 1e-6  # between substep ends
