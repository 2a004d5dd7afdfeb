"""Motion of the emulated eRob, commanded through the real host driver, measured in the physics.

Every command goes host driver -> Modbus link -> loopback -> emulator (the same code path as on
hardware); every measurement that matters comes from MuJoCo's state (``qpos``/``qvel``/``ctrl``),
not from the emulator's own idea of where it is. Time is simulated only.

Stand: ``models/erob_stand.xml`` (vertical axis, no gravity torque) with the eRob80H100 profile:
torque constant 8.71 N*m/A, Coulomb friction 4.5 N*m, viscous friction 9.57 N*m*s/rad, max speed
262144 count/s (30 rpm), peak current 8037 mA.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("mujoco")

import joints
from joints.devices.erob.profiles import profile
from joints.devices.erob.registers import COUNTS_PER_REV, AchieveStatus, MotionStatus
from joints.drivers.erob_modbus import ErobModbusDriver
from joints.link.modbus import ModbusLink
from joints.sim import sensors
from simkit import erob_world

MODEL = "eRob80H100"
PROFILE = profile(MODEL)
C = COUNTS_PER_REV / (2.0 * math.pi)  #: counts per rad


class Bench:
    """A world with one emulated eRob per joint and a host driver for each, on one RS485 bus."""

    def __init__(self, model: str = "erob_stand.xml", names: tuple[str, ...] = ("joint1",)) -> None:
        self.world = erob_world(model, names, PROFILE)
        self.link = ModbusLink(self.world.transport("rs485"), clock=self.world.clock)
        self.drv = {
            n: ErobModbusDriver(self.link, i + 1, profile=PROFILE, clock=self.world.clock, name=n)
            for i, n in enumerate(names)
        }
        self._dof = {n: int(self.world.model.jnt_dofadr[self.world.model.joint(n).id]) for n in names}

    @property
    def t(self) -> float:
        return self.world.time

    def pos(self, name: str = "joint1") -> float:
        """Ground-truth joint position [count]."""
        return self.world.joint_position(name) * C

    def vel(self, name: str = "joint1") -> float:
        """Ground-truth joint velocity [count/s]."""
        return float(self.world.data.qvel[self._dof[name]]) * C

    def ctrl(self, name: str = "joint1") -> float:
        """Torque the drive wrote to its MuJoCo motor [N*m]."""
        return float(self.world.data.ctrl[self.world.model.actuator(f"{name}_motor").id])


@pytest.fixture
def bench() -> Bench:
    return Bench()


# ------------------------------------------------------------------ 1. move absolute (5.1.1)


@pytest.mark.parametrize(
    ("distance", "speed", "accel"),
    [(200_000, 50_000, 100_000), (300_000, 100_000, 50_000)],  # D >= v^2/a in both; v/a = 0.5 s and 2 s
)
def test_move_absolute_takes_trapezoid_time(bench: Bench, distance: int, speed: int, accel: int) -> None:
    drv = bench.drv["joint1"]
    drv.enable()
    start = drv.read("actual_position")
    target = start + distance
    window = drv.read("position_reaches_set_precision")
    assert window == 100
    expected = distance / speed + speed / accel

    drv.move_to(target, speed=speed, acceleration=accel, deceleration=accel)  # waits out the 500 ms
    t0 = bench.t
    t_reach = None  # first time the joint (physics) is inside the precision window
    t_status_stop = None  # first time the drive reports "stop motion"
    peak_speed = 0.0
    statuses_during = set()
    while bench.t - t0 < expected + 0.5:
        bench.world.advance(0.002)
        peak_speed = max(peak_speed, abs(bench.vel()))
        if t_reach is None and abs(bench.pos() - target) <= window:
            t_reach = bench.t - t0
        if round((bench.t - t0) * 1000) % 10 == 0:  # poll the drive every 10 ms
            status = drv.read("motion_status")
            if bench.t - t0 < expected - 0.1:
                statuses_during.add(status)
            if status == MotionStatus.STOP and t_status_stop is None:
                t_status_stop = bench.t - t0
    state = drv.state()

    assert t_reach is not None
    assert t_reach == pytest.approx(expected, rel=0.02)  # measured 4.454 s / 4.5, 4.936 s / 5.0
    assert t_status_stop == pytest.approx(expected, rel=0.01)  # the profile itself is exact
    assert statuses_during == {MotionStatus.MOVING}
    assert state.extra["motion_status"] == MotionStatus.STOP
    assert state.extra["status_of_achieving_position"] == AchieveStatus.TARGET_REACHED
    assert abs(state.position - target) <= window
    assert abs(bench.pos() - target) <= window
    assert peak_speed == pytest.approx(speed, rel=0.02)  # cruises at the profile speed


def test_single_read_after_settling_reports_target_reached(bench: Bench) -> None:
    """The settle time (0x007A) runs on the drive, not on the host's polling."""
    drv = bench.drv["joint1"]
    drv.enable()
    drv.move_to(50_000, speed=100_000, acceleration=200_000, deceleration=200_000)
    bench.world.advance(2.0)  # no traffic meanwhile
    assert drv.read("status_of_achieving_position") == AchieveStatus.TARGET_REACHED


# ------------------------------------------------------------------ 2. speed mode (5.2)


@pytest.mark.parametrize("sign", [1, -1])
def test_speed_mode_ramps_with_profile_acceleration(bench: Bench, sign: int) -> None:
    sensors.ideal(bench.world)  # the speed as the drive holds it (its estimate steps by 1000 count/s)
    drv = bench.drv["joint1"]
    target, accel = sign * 100_000, 100_000  # 1 s ramp
    drv.configure_velocity(acceleration=accel, deceleration=accel)
    drv.enable()
    drv.set_velocity(target, acceleration=accel, deceleration=accel)
    t0 = bench.t
    ramp_err, hold_err = [], []
    for _ in range(30):
        bench.world.advance(0.049)
        seen = bench.vel()  # what the drive's encoder reads at the start of the next substep
        bench.world.advance(0.001)
        t = bench.t - t0
        measured = drv.state().velocity  # current_speed (0x006E)
        assert abs(measured - seen) <= 1  # the register is the physics (encoder rounding)
        ideal = sign * min(accel * t, abs(target))
        if 0.1 <= t <= 0.95:
            ramp_err.append(abs(measured - ideal) / abs(ideal))
        elif t >= 1.1:
            hold_err.append(abs(measured - target) / abs(target))
    assert max(ramp_err) < 0.03  # measured 0.8 % at 0.1 s (breakaway from static friction), 0.1 % at 0.95 s
    assert max(hold_err) < 0.02  # measured < 0.01 %


# ------------------------------------------------------------------ 3. torque mode (5.3)


def _run_torque(bench: Bench, current: int, max_speed: int) -> tuple[list[float], list[int]]:
    drv = bench.drv["joint1"]
    drv.configure_torque(max_speed=max_speed)  # 0x00D8 is written while disabled
    drv.enable()
    drv.set_current(current)
    speeds, currents = [], []
    for _ in range(40):
        bench.world.advance(0.05)
        s = drv.state()
        speeds.append(bench.vel())
        currents.append(s.current)
    return speeds, currents


def test_torque_mode_holds_at_torque_mode_max_speed(bench: Bench) -> None:
    limit = 40_000
    speeds, currents = _run_torque(bench, 3000, limit)  # 26 N*m >> 4.5 N*m Coulomb friction
    assert 0 < speeds[0] < speeds[1]  # accelerates
    hold = speeds[20:]  # 1..2 s
    assert max(abs(v - limit) for v in hold) < 0.05 * limit  # measured 40000 count/s
    # the limiter, not the target current, sets the torque: ~1.04 A (friction at that speed)
    friction = PROFILE.coulomb_friction + PROFILE.viscous_friction * limit / C
    assert currents[-1] == pytest.approx(friction / PROFILE.torque_constant * 1000, rel=0.05)
    assert currents[-1] < 3000


def test_torque_mode_without_speed_limit_is_friction_limited(bench: Bench) -> None:
    current = 3000
    sensors.ideal(bench.world)  # the current exactly as it flows (no measurement noise)
    speeds, currents = _run_torque(bench, current, 0)  # 0 = "no limit but max_speed"
    terminal = (PROFILE.torque_constant * current / 1000 - PROFILE.coulomb_friction) / PROFILE.viscous_friction * C
    assert terminal < 262_144  # friction, not max_speed, limits here: 188597 count/s
    assert speeds[-1] == pytest.approx(terminal, rel=0.05)
    assert currents[-1] == current  # full target current flows


def test_torque_mode_without_speed_limit_stops_at_max_speed(bench: Bench) -> None:
    bench.drv["joint1"].write("max_speed", 150_000)  # below the friction-limited 188597 count/s
    speeds, _ = _run_torque(bench, 3000, 0)
    assert max(speeds[20:]) == pytest.approx(150_000, rel=0.05)


# ------------------------------------------------------------------ 5. stop and emergency stop


def _run_then(bench: Bench, mode: str, speed: int, decel: int) -> ErobModbusDriver:
    drv = bench.drv["joint1"]
    drv.enable()
    if mode == "continuous":
        drv.move_continuous(speed, acceleration=1_000_000, deceleration=decel)
    else:
        drv.set_velocity(speed, acceleration=1_000_000, deceleration=decel)
    bench.world.advance(0.6)
    assert bench.vel() == pytest.approx(speed, rel=0.01)
    return drv


def _time_to_standstill(bench: Bench, v0: float, limit: float, frac: float) -> float | None:
    t0 = bench.t
    while bench.t - t0 < limit:
        bench.world.advance(0.001)
        if abs(bench.vel()) < frac * abs(v0):
            return bench.t - t0
    return None


@pytest.mark.parametrize("mode", ["continuous", "speed"])
def test_stop_operating_decelerates_with_profile_deceleration(bench: Bench, mode: str) -> None:
    speed, decel = 100_000, 50_000  # v/d = 2 s
    drv = _run_then(bench, mode, speed, decel)
    drv.stop()
    t = _time_to_standstill(bench, speed, 3.0, 0.01)
    assert t == pytest.approx(speed / decel, rel=0.05)  # measured 1.98 s
    bench.world.advance(0.3)
    s = drv.state()
    assert abs(s.velocity) < 0.01 * speed
    assert s.extra["motion_status"] == MotionStatus.STOP
    assert s.enabled and s.fault == 0


@pytest.mark.parametrize("mode", ["continuous", "speed"])
@pytest.mark.parametrize("speed", [100_000, 250_000])
def test_emergency_stop_within_50_ms(bench: Bench, mode: str, speed: int) -> None:
    drv = _run_then(bench, mode, speed, 50_000)
    drv.emergency_stop()
    t0 = bench.t
    t = _time_to_standstill(bench, speed, 0.2, 0.02)
    assert t is not None and t <= 0.05  # measured 40-47 ms
    # and it stays stopped: no rebound above 2 % of the speed from 50 ms on
    while bench.t - t0 < 0.05:
        bench.world.advance(0.001)
    residual = 0.0
    while bench.t - t0 < 0.3:
        bench.world.advance(0.001)
        residual = max(residual, abs(bench.vel()))
    assert residual < 0.02 * speed  # measured 0.7-1.6 %
    s = drv.state()
    assert s.extra["motion_status"] == MotionStatus.STOP
    assert s.enabled and s.fault == 0


# ------------------------------------------------------------------ 6. relative / continuous / repetitive


def test_move_relative_moves_from_the_current_position(bench: Bench) -> None:
    drv = bench.drv["joint1"]
    drv.enable()
    drv.move_to(30_000, speed=100_000, acceleration=200_000, deceleration=200_000)
    bench.world.advance(1.0)
    here = bench.pos()
    assert here == pytest.approx(30_000, abs=100)
    drv.move_by(100_000, speed=100_000, acceleration=200_000, deceleration=200_000)
    assert drv.read("motion_mode") == 1 and drv.read("target_relative_position") == 100_000
    bench.world.advance(2.0)
    assert bench.pos() - here == pytest.approx(100_000, abs=100)
    drv.move_by(-40_000)
    bench.world.advance(2.0)
    assert bench.pos() - here == pytest.approx(60_000, abs=100)
    assert drv.read("status_of_achieving_position") == AchieveStatus.TARGET_REACHED
    # move absolute again (the driver writes relative = 0 first, as 5.1.1 step 7 does)
    drv.move_to(0)
    bench.world.advance(3.0)
    assert bench.pos() == pytest.approx(0, abs=100)


@pytest.mark.parametrize("speed", [60_000, -60_000])
def test_move_continuous_runs_at_profile_speed_until_stop(bench: Bench, speed: int) -> None:
    drv = bench.drv["joint1"]
    drv.enable()
    drv.move_continuous(speed, acceleration=120_000, deceleration=120_000)  # 0.5 s ramp
    bench.world.advance(0.6)
    p0, t0 = bench.pos(), bench.t
    for _ in range(10):
        bench.world.advance(0.1)
        assert bench.vel() == pytest.approx(speed, rel=0.01)
        assert drv.read("motion_status") == MotionStatus.MOVING
    assert (bench.pos() - p0) / (bench.t - t0) == pytest.approx(speed, rel=0.01)
    drv.stop()
    bench.world.advance(0.7)
    stopped_at = bench.pos()
    bench.world.advance(1.0)
    assert abs(bench.pos() - stopped_at) < 100
    assert drv.read("motion_status") == MotionStatus.STOP


def test_move_repetitive_with_dwell_and_stop_repetitive(bench: Bench) -> None:
    drv = bench.drv["joint1"]
    drv.enable()
    home = drv.read("actual_position")
    target = home + 100_000
    # leg: 100000 count at 100000 count/s, 400000 count/s^2 -> 1.25 s; dwell 10000 x 0.05 ms = 0.5 s
    drv.move_repetitive(target, speed=100_000, acceleration=400_000, deceleration=400_000, dwell=10_000)
    t0 = bench.t
    samples = []  # (t, where): where = "target" | "home" | "between"
    stop_sent = None
    while bench.t - t0 < 6.0:
        bench.world.advance(0.005)
        p = bench.pos()
        where = "target" if abs(p - target) <= 100 else "home" if abs(p - home) <= 100 else "between"
        samples.append((bench.t - t0, where))
        if stop_sent is None and bench.t - t0 >= 4.0:  # on the third leg (home -> target)
            drv.stop_repetitive()
            stop_sent = bench.t - t0
            assert drv.read("motion_status") == MotionStatus.STOP_REPETITIVE

    # segments of consecutive samples with the same place
    segments: list[list[float | str]] = []
    for t, where in samples:
        if segments and segments[-1][2] == where:
            segments[-1][1] = t
        else:
            segments.append([t, t, where])
    places = [s[2] for s in segments]
    assert places[:6] == ["home", "between", "target", "between", "home", "between"]
    assert places[6] == "target" and len(places) == 7  # stops at the target, goes no further
    arrive_target, leave_target = segments[2][0], segments[2][1]
    arrive_home, leave_home = segments[4][0], segments[4][1]
    assert arrive_target == pytest.approx(1.25, abs=0.05)
    assert leave_target - arrive_target == pytest.approx(0.5, abs=0.06)  # dwell (+ window crossing)
    assert arrive_home == pytest.approx(1.25 + 0.5 + 1.25, abs=0.08)
    assert leave_home - arrive_home == pytest.approx(0.5, abs=0.06)
    assert drv.read("motion_status") == MotionStatus.STOP
    assert abs(bench.pos() - target) <= 100


# ------------------------------------------------------------------ 10. brake and holding under gravity


ARM = {
    "backend": "sim",
    "sim": {"model": "erob_arm3.xml", "timestep": 0.001},
    "buses": {"rs485": {"protocol": "modbus-rtu"}},
    "joints": {
        name: {"device": "erob", "model": MODEL, "bus": "rs485", "address": i + 1}
        for i, name in enumerate(("joint1", "joint2", "joint3"))
    },
}


def test_brake_holds_a_disabled_arm_under_gravity() -> None:
    with joints.open(ARM) as rig:
        world = rig.world
        q0 = [world.joint_position(n) for n in ("joint2", "joint3")]
        rig.sleep(2.0)
        drift = [abs(world.joint_position(n) - q) for n, q in zip(("joint2", "joint3"), q0)]
        assert max(drift) < 0.01  # measured 2.3e-4 rad (shoulder), 3.5e-5 rad (elbow)
        # it is the brake that holds: gravity loads the shoulder with ~9 N*m (> 4.5 N*m friction)
        shoulder = world.model.actuator("joint2_motor").id
        assert abs(world.data.ctrl[shoulder]) > PROFILE.coulomb_friction
        for j in rig.joints.values():
            assert not j.state().enabled


def test_enabled_arm_holds_commanded_position_under_gravity() -> None:
    with joints.open(ARM) as rig:
        world = rig.world
        shoulder, elbow = rig.joints["joint2"], rig.joints["joint3"]
        for j in (shoulder, elbow):
            j.enable()
        shoulder.move_to(-0.6, velocity=0.5, acceleration=2.0, deceleration=2.0)  # lift the arm
        elbow.move_to(0.8, velocity=0.5, acceleration=2.0, deceleration=2.0)
        shoulder.wait(timeout=5.0)
        elbow.wait(timeout=5.0)
        rig.sleep(0.2)
        window = shoulder.read("position_reaches_set_precision") / C  # rad
        worst = 0.0
        for _ in range(40):  # 2 s
            rig.sleep(0.05)
            worst = max(worst, abs(world.joint_position("joint2") + 0.6), abs(world.joint_position("joint3") - 0.8))
        assert worst <= window  # measured < 1 count
        assert shoulder.read("status_of_achieving_position") == AchieveStatus.TARGET_REACHED
        assert abs(shoulder.state().torque) > 1.0  # the motor, not a brake, holds the arm up


# ------------------------------------------------------------------ 11. two rates, no teleport


def test_motion_comes_from_torque_not_from_written_positions(bench: Bench) -> None:
    world = bench.world
    emu = world.drives["joint1"]
    drv = bench.drv["joint1"]
    drv.enable()
    drv.move_to(100_000, speed=100_000, acceleration=200_000, deceleration=200_000)
    dt = world.timestep
    qpos, qvel, ctrl, amps = [], [], [], []
    for _ in range(1700):  # no register traffic at all: the drive's loops run every substep alone
        qpos.append(float(world.data.qpos[0]))
        world.step(1)
        qvel.append(float(world.data.qvel[0]))
        ctrl.append(bench.ctrl())
        amps.append(emu.i_out)
        assert emu.time == pytest.approx(world.time)
    qpos.append(float(world.data.qpos[0]))
    qpos_a, qvel_a = np.array(qpos), np.array(qvel)
    # every position change is the integral of the physics' velocity (implicit-fast Euler):
    # nothing ever set qpos directly
    assert np.allclose(np.diff(qpos_a), qvel_a * dt, rtol=0, atol=1e-12)
    assert np.max(np.abs(qvel_a)) * C == pytest.approx(100_000, rel=0.02)
    assert np.count_nonzero(np.abs(qvel_a) > 0.01) > 1000
    # the drive's output is a torque: motor current x torque constant, on the MuJoCo motor
    assert np.max(np.abs(ctrl)) > 5.0
    assert np.allclose(ctrl, np.array(amps) * 1e-3 * PROFILE.torque_constant, atol=1e-9)
    assert bench.pos() == pytest.approx(100_000, abs=100)


def test_new_target_inside_the_stopping_distance_overshoots_and_returns_without_a_fault(bench: Bench) -> None:
    """A move retargeted while cruising to a point it cannot stop at: the drive's own profile runs past
    it and comes back (a real drive's setpoint never jumps). The profile used to snap to the new
    target at rest, a setpoint speed jump that tripped the drive's speed error (0x8400)."""
    drv = bench.drv["joint1"]
    drv.enable()
    speed, accel = 150_000, 300_000  # stopping distance 37500 counts
    drv.move_to(400_000, speed=speed, acceleration=accel, deceleration=accel)
    while bench.pos() < 100_000:
        bench.world.advance(0.002)
    here = bench.pos()
    assert bench.vel() == pytest.approx(speed, rel=0.02)
    target = round(here + 10_000)
    drv.move_to(target, speed=speed, acceleration=accel, deceleration=accel)
    peak = here
    for _ in range(1000):
        bench.world.advance(0.002)
        peak = max(peak, bench.pos())
        assert drv.read("error_code") == 0
    assert peak == pytest.approx(here + speed**2 / (2 * accel), abs=3000)  # ran on to where it could stop
    state = drv.state()
    assert state.fault == 0 and state.extra["status_of_achieving_position"] == AchieveStatus.TARGET_REACHED
    assert abs(bench.pos() - target) <= drv.read("position_reaches_set_precision")
