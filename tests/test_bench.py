"""`joints bench`: every row of issue 23's table, the bus planner and its wire-time models, and the
bus path's transaction counts (timings themselves are never asserted)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

pytest.importorskip("mujoco")
gym = pytest.importorskip("gymnasium")

import envs
import joints
from joints import bench
from joints.cli import main
from joints.transports import can_timing, serial_timing


def test_serial_wire_time() -> None:
    assert serial_timing.char_bits("N", 1) == 10 and serial_timing.char_bits("E", 1) == 11
    assert serial_timing.char_bits("N", 2) == 11
    assert serial_timing.t35_bits(9600, "E") == 3.5 * 11  # 3.5 characters up to 19200 baud
    assert serial_timing.t35_bits(115200) == pytest.approx(1.75e-3 * 115200)  # then 1.75 ms
    # FC03 of the eRob status block: request 8 bytes, reply 55 bytes, a t3.5 after each
    load = serial_timing.cycle_load([8, 55], period=0.01, baudrate=115200)
    assert load.bits_worst == int(np.ceil(63 * 10 + 2 * 201.6))
    assert load.worst == pytest.approx(load.bits_worst / 1152.0)
    assert serial_timing.cycle_load([8, 55], period=0.01, baudrate=115200, silence=False).bits_worst == 630
    with pytest.raises(ValueError):
        serial_timing.cycle_load([8], period=0.0, baudrate=9600)


def test_one_can_capacity_function() -> None:
    """CANopen's SYNC cycle is the general cycle load of its frames (one formula for both)."""
    co = can_timing.canopen_cycle_load(3, sync_period=0.001)
    frames = [0] + [6] * 6  # SYNC, then RPDO + TPDO of 6 bytes per node
    general = can_timing.cycle_load(frames, period=0.001, bitrate=1_000_000)
    assert (co.bits_best, co.bits_worst) == (general.bits_best, general.bits_worst)
    assert co.best == pytest.approx(0.62, abs=0.01) and co.worst == pytest.approx(0.75, abs=0.01)
    assert general.max_rate == pytest.approx(1_000_000 / general.bits_worst)
    with pytest.raises(ValueError):
        can_timing.cycle_load([9], period=0.001, bitrate=1_000_000)


def test_planner_counts_the_frames_the_drivers_send() -> None:
    with envs.config_path("erob_reach") as path:
        (p,) = bench.plan(path, 50.0)
    # target (FC16: 13 + 8 bytes), start (FC06: 8 + 8), status (FC03: 8 + 55): 3 transactions
    assert (p.protocol, p.joints, p.frames, p.data_bytes) == ("modbus-rtu", 1, 6, 100)
    assert p.load.bits_worst == int(np.ceil(1000 + 6 * 1.75e-3 * 115200))
    # each of the 3 replies adds the eRob's turnaround and the USB adapter's latency (issue 29)
    assert p.transactions == 3 and p.overhead == pytest.approx(3 * (0.0008 + 0.001))
    assert p.cycle == pytest.approx(p.load.bits_worst / 115200 + p.overhead)
    assert "does NOT fit" in p.text(50.0)  # 24.6 ms: 123 % of 20 ms
    assert "(fits)" in p.text(25.0) and p.share(0.04) == pytest.approx(0.61, abs=0.01)
    with envs.config_path("erob_arm_reach") as path:
        (arm,) = bench.plan(path, 50.0)
    assert arm.frames == 18 and not arm.load.fits  # 3 joints x 3 transactions do not fit 20 ms at 115200
    assert arm.share(0.1) <= bench.CYCLE_BUDGET  # the env's 10 Hz


def test_planner_on_a_can_bus() -> None:
    cfg = {"backend": "sim", "sim": {"model": "erob_arm3.xml"},
           "buses": {"can": {"protocol": "erob-can", "bitrate": 1_000_000}},
           "joints": {f"joint{i}": {"device": "erob", "bus": "can", "address": i,
                                    "limits": {"position": [-3.0, 3.0], "velocity": 2.0, "torque": 40.0}}
                      for i in (1, 2, 3)}}
    (p,) = bench.plan(cfg, 500.0)
    assert p.protocol == "erob-can" and p.joints == 3 and p.frames > 0 and p.frames % 2 == 0
    assert p.load.bitrate == 1_000_000 and p.load.bits_worst > p.load.bits_best
    assert p.load.period == pytest.approx(0.002)


def test_bench_command_prints_every_row_of_the_table(capsys: pytest.CaptureFixture[str]) -> None:
    with envs.config_path("zlac_diffdrive") as path:
        assert main(["bench", "--quick", "--config", str(path)]) == 0
    out = capsys.readouterr().out
    for row in ("`joints/ErobReach-v0`", "`joints/ErobArmReach-v0`", "`joints/DiffDriveGoal-v0`",
                "world ratio, one eRob, disabled / holding / speed / profile absolute",
                "Modbus codec vs pymodbus, FC03 host / device", "16 rigs batched in one process"):
        assert row in out
    table = out.split("Bus planner")[0]
    for name in ("16 rigs", "256 rigs", "overhead per env step", "with resets timed", "(50 Hz, erob-can at 1 Mbit/s)",
                 "(50 Hz, canopen at 1 Mbit/s)", "Reacher-v5"):
        assert name in table
    # every row measured (gymnasium's reference needs gymnasium[mujoco]'s extras: it may say why not)
    assert all("—" not in line for line in table.splitlines() if "Reacher-v5" not in line)
    assert "Bus planner" in out and "bus rs485 (modbus-rtu" in out


def test_an_env_row_is_the_median_of_its_pairs_not_the_best_env_beside_the_best_reference(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Each env block is set against the reference timed right after it: an env block that hit a fast moment
    (0.5 s) beside references that all ran slow (1.0 s) is one pair of three, not the row's figure (the best
    of each side would say 2.0)."""
    env_s, raw_s, nstep_s = iter([0.5, 1.0, 1.0]), iter([1.0, 1.0, 1.0]), iter([0.5, 0.5, 0.5])

    def block(env: object, steps: int, seed: int, out: bench.EnvTiming) -> object:
        def timed() -> float:
            t = next(env_s)
            out.seconds.append(t)
            out.substeps.append(1000)  # the raw reference's count: raw_steps substeps in raw_s
            out.with_resets.append(2 * t)
            return t
        return timed

    monkeypatch.setattr(bench, "_env_block", block)
    monkeypatch.setattr(bench, "_raw", lambda model, steps, nstep=1: (lambda: next(raw_s if nstep == 1 else nstep_s)))
    ratio, resets, overhead = bench._env_rows("fake", None, object(), 10, 100, 1000, 3, 0, 0.6, None, 0.01)
    assert ratio.ratio == 1.0 and resets.ratio == 0.5
    assert overhead.ratio == 0.0  # the median pair: 1.0 s of steps, 1000 substeps x 1 ms
    assert "0.50 of `mj_step(m, d, nstep=10)`" in ratio.detail  # the median of 1.0, 0.5, 0.5


def test_the_batch_reference_runs_each_model_its_period_in_a_row_as_the_batch_does(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Each rig's world runs its period's substeps in one go, rig after rig: so does the reference (one substep per
    model in turn made it pay cache misses the batch does not, and 256 rigs read up to 1.37 of it)."""
    mujoco = pytest.importorskip("mujoco")
    models = [object(), object(), object()]
    called: list[object] = []
    monkeypatch.setattr(mujoco, "MjData", lambda m: None)
    monkeypatch.setattr(mujoco, "mj_step", lambda m, d: called.append(m))
    bench._raw_many(models, 24, 4)()
    assert called == [m for _ in range(2) for m in models for _ in range(4)]


@pytest.mark.parametrize("direct", [True, False])
def test_erob_position_step_is_three_transactions(direct: bool) -> None:
    """Target (0x0043), start (0x00F1), status read (one FC03 of the adjacent block): 3, both paths."""
    cfg = copy.deepcopy(envs.default_config("erob_reach"))
    cfg["sim"]["direct"] = direct
    env = gym.make("joints/ErobReach-v0", config=cfg)
    try:
        env.reset(seed=0)
        link = env.unwrapped.rig.buses["rs485"].link
        before = link.transactions
        rng = np.random.default_rng(0)
        for _ in range(10):
            env.step(rng.uniform(-1, 1, (1,)).astype(np.float32))
        assert link.transactions - before == 30
    finally:
        env.close()


def test_sleep_together_argument_checks() -> None:
    with envs.config_path("erob_reach") as path, joints.open(path) as rig:
        with pytest.raises(ValueError, match="finite"):
            joints.sleep_together([rig], [-1.0])
        joints.sleep_together([rig], 0.01)
        assert rig.time == pytest.approx(0.01)


def test_diffdrive_cycle_counts_the_ramp_write_a_changing_command_sends() -> None:
    """A policy's wheel speeds change every step, and the ZLAC driver then writes the ramp times (0x2080-0x2083,
    one FC16) before the speeds: the planner counts that cycle (3 transactions, not the 2 of a repeated command),
    so it agrees with what the env sends, and a 20 ms period that cycle does not fit is refused (before, the
    planner's 16.0 ms let it through and the env overran every step by 3.5 ms)."""
    with envs.config_path("zlac_diffdrive") as path:
        p = joints.cycle_times(str(path), "velocity")["rs485"]
    assert p.transactions == 3 and p.frames == 6
    env = gym.make("joints/DiffDriveGoal-v0").unwrapped
    try:
        env.reset(seed=0)
        link = env.rig.buses["rs485"].link
        rng = np.random.default_rng(0)
        for _ in range(10):
            before = link.transactions
            env.step(rng.uniform(-1, 1, (2,)).astype(np.float32))
            assert link.transactions - before == p.transactions
        assert env.overruns == 0  # 23.5 ms in the 50 ms period
    finally:
        env.close()
    with pytest.raises(joints.ConfigError, match="does not fit"):
        gym.make("joints/DiffDriveGoal-v0", control_period=0.02)
