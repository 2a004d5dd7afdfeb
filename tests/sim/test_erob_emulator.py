"""The emulated eRob's state machine, protections, register semantics and persistence.

Commands go through the real host driver (or, where the driver itself would refuse to send
something, through the same Modbus link), into the emulator on a loopback bus; physical effects
are read from MuJoCo. Time is simulated only.
"""

from __future__ import annotations

import math

import pytest

pytest.importorskip("mujoco")

from joints.codecs import modbus as mb
from joints.devices.erob import faults
from joints.devices.erob.profiles import profile
from joints.devices.erob.registers import (
    COUNTS_PER_REV,
    EROB_MODBUS,
    AchieveStatus,
    MotionMode,
    MotionStatus,
)
from joints.drivers.erob_modbus import ZERO_BASE, ErobModbusDriver
from joints.errors import DeviceFault, DeviceRejected, StateError
from joints.joint import Joint
from joints.link.modbus import ModbusLink
from joints.sim import sensors
from joints.sim.erob import FOLLOWING_ERROR, STALL
from simkit import erob_world

PROFILE = profile("eRob80H100")
C = COUNTS_PER_REV / (2.0 * math.pi)  #: counts per rad
SLAVE = 1


class Bench:
    """A world with one emulated eRob per joint and a host driver for each, on one RS485 bus."""

    def __init__(self, model: str = "erob_stand.xml", names: tuple[str, ...] = ("joint1",)) -> None:
        self.world = erob_world(model, names, PROFILE)
        self.link = ModbusLink(self.world.transport("rs485"), clock=self.world.clock)
        self.drv = {
            n: ErobModbusDriver(self.link, i + 1, profile=PROFILE, clock=self.world.clock, name=n)
            for i, n in enumerate(names)
        }

    @property
    def t(self) -> float:
        return self.world.time

    def q(self, name: str = "joint1") -> float:
        """Ground-truth joint position [rad]."""
        return self.world.joint_position(name)

    def pos(self, name: str = "joint1") -> float:
        """Ground-truth joint position [count]."""
        return self.q(name) * C

    def vel(self, name: str = "joint1") -> float:
        """Ground-truth joint velocity [count/s]."""
        dof = int(self.world.model.jnt_dofadr[self.world.model.joint(name).id])
        return float(self.world.data.qvel[dof]) * C


@pytest.fixture
def bench() -> Bench:
    return Bench()


# ------------------------------------------------------------------ 4. start refused while not ready


def test_start_while_disabled_does_not_move_and_reports_0x0027(bench: Bench) -> None:
    drv = bench.drv["joint1"]
    drv.configure_position(MotionMode.ABSOLUTE, speed=50_000, acceleration=100_000, deceleration=100_000,
                           clear_relative=True)
    drv.write("target_absolute_position", 100_000)
    q0 = bench.q()
    drv.write("start_operating", 1)  # the motor was never enabled
    bench.world.advance(1.0)
    assert abs(bench.q() - q0) < 1e-6
    s = drv.state()
    assert s.fault == faults.START_WHILE_DISABLED == 0x0027
    assert not s.enabled and s.extra["motion_status"] == MotionStatus.STOP
    with pytest.raises(DeviceFault) as info:
        drv.check_fault()
    assert info.value.code == 0x0027 and "motor is off" in info.value.text

    # enabled, but inside the manual's 500 ms: still refused, still no motion
    drv.clear_errors()
    assert drv.read("error_code") == 0
    drv.enable()
    bench.world.advance(0.2)
    drv.write("start_operating", 1)
    bench.world.advance(1.0)
    assert abs(bench.q() - q0) < 1e-6
    assert drv.read("error_code") == 0x0027

    # clear errors + enable + 500 ms: the same start works
    drv.clear_errors()
    drv.enable()
    bench.world.advance(0.5)
    drv.write("start_operating", 1)
    bench.world.advance(3.0)
    assert bench.pos() == pytest.approx(100_000, abs=100)
    s = drv.state()
    assert s.fault == 0 and s.extra["status_of_achieving_position"] == AchieveStatus.TARGET_REACHED


def test_speed_command_inside_enable_delay_is_refused(bench: Bench) -> None:
    drv = bench.drv["joint1"]
    drv.configure_velocity(acceleration=100_000, deceleration=100_000)
    drv.enable()
    bench.world.advance(0.1)
    q0 = bench.q()
    drv.write("target_speed", 50_000)
    bench.world.advance(1.0)
    assert abs(bench.q() - q0) < 1e-6
    assert drv.read("error_code") == 0x0027


# ------------------------------------------------------------------ 7. faults


def test_following_error_disables_the_drive_and_raises_device_fault() -> None:
    bench = Bench("erob_arm3.xml", ("joint1", "joint2", "joint3"))
    drv = bench.drv["joint2"]  # the shoulder carries ~9 N*m of gravity
    drv.write("peak_current", 300)  # 2.6 N*m: cannot even hold the arm
    drv.write("max_position_error", 5000)
    drv.enable()
    drv.move_to(-50_000, speed=50_000, acceleration=100_000, deceleration=100_000)
    t0 = bench.t
    while bench.world.drives["joint2"].fault == 0 and bench.t - t0 < 2.0:
        bench.world.advance(0.005)
    s = drv.state()
    assert s.fault == FOLLOWING_ERROR == 0x8611
    assert not s.enabled and s.extra["status_of_achieving_position"] == AchieveStatus.MOTOR_OFF
    assert abs(s.extra["given_position"] - s.position) > 5000  # the error that tripped it
    joint = Joint("shoulder", drv, clock=bench.world.clock)
    with pytest.raises(DeviceFault) as info:
        joint.check()
    assert info.value.code == 0x8611
    with pytest.raises(DeviceFault):
        drv.check_fault()
    # disabled means the brake holds the arm where it tripped
    q_trip = bench.q("joint2")
    bench.world.advance(1.0)
    assert abs(bench.q("joint2") - q_trip) < 0.01
    # clear errors + enable: the drive is usable again (holds with a sane current limit)
    drv.write("peak_current", round(PROFILE.peak_current * 1000))
    drv.clear_errors()
    assert drv.read("error_code") == 0
    drv.enable()
    bench.world.advance(1.0)
    s = drv.state()
    assert s.fault == 0 and s.enabled
    assert abs(bench.q("joint2") - q_trip) < 0.01


def _block_joint(bench: Bench) -> None:
    """A hard stop 0.01 rad either side of the start (a mechanical block)."""
    model = bench.world.model
    jid = model.joint("joint1").id
    model.jnt_limited[jid] = True
    model.jnt_range[jid] = [-0.01, 0.01]


def test_stall_trips_after_struck_time(bench: Bench) -> None:
    _block_joint(bench)
    drv = bench.drv["joint1"]
    drv.write("struck_time", 2000)  # 2000 x 0.05 ms = 100 ms
    struck_current, struck_speed = drv.read("struck_current"), drv.read("struck_speed")
    assert (struck_current, struck_speed) == (4080, 500)  # 120 % of 3.4 A continuous
    drv.configure_torque(max_speed=0)
    drv.enable()
    drv.set_current(5000)  # above the struck current, pushing into the block
    t0 = bench.t
    t_blocked = t_fault = None
    while bench.t - t0 < 1.0:
        bench.world.advance(0.001)
        if abs(bench.vel()) >= struck_speed:
            t_blocked = None
        elif t_blocked is None:
            t_blocked = bench.t
        if drv.read("error_code"):
            t_fault = bench.t
            break
    assert t_fault is not None and t_blocked is not None
    assert t_fault - t_blocked == pytest.approx(0.1, abs=0.005)
    s = drv.state()
    assert s.fault == STALL == 0x7121
    assert not s.enabled and s.current == 0  # the drive cut the motor current


def test_no_stall_below_struck_current(bench: Bench) -> None:
    _block_joint(bench)
    sensors.ideal(bench.world)  # the current exactly as commanded (no measurement noise)
    drv = bench.drv["joint1"]
    drv.write("struck_time", 2000)
    drv.configure_torque(max_speed=0)
    drv.enable()
    drv.set_current(3000)  # < 4080 mA
    bench.world.advance(0.5)
    s = drv.state()
    assert s.fault == 0 and s.enabled and abs(s.velocity) < 500 and s.current == 3000


def test_communication_watchdog(bench: Bench) -> None:
    drv = bench.drv["joint1"]
    emu = bench.world.drives["joint1"]
    drv.set_communication_timeout(100)  # 0x0002 = 100 ms; armed by this very frame
    drv.enable()
    # Keep talking through the 500 ms enable delay. (Not with drv.state(): the drive reports
    # "motor off" until it is ready, and the driver would conclude it disabled itself.)
    for _ in range(12):
        bench.world.advance(0.05)
        assert drv.read("error_code") == 0
    drv.move_continuous(50_000, acceleration=200_000, deceleration=200_000)
    for _ in range(10):
        bench.world.advance(0.05)
        assert drv.state().fault == 0
    assert bench.vel() == pytest.approx(50_000, rel=0.01)
    # silence: nothing on the bus for 0.2 s of simulated time
    silent_from = bench.t
    t_fault = None
    while bench.t - silent_from < 0.2:
        bench.world.advance(0.001)
        if t_fault is None and emu.fault:
            t_fault = bench.t - silent_from
    assert t_fault == pytest.approx(0.1, abs=0.0015)
    s = drv.state()
    assert s.fault == faults.RS485_TIMEOUT == 0xFA2
    assert not s.enabled and s.extra["status_of_achieving_position"] == AchieveStatus.MOTOR_OFF
    assert abs(bench.vel()) < 100  # disabled: the brake stopped the joint
    with pytest.raises(DeviceFault) as info:
        drv.check_fault()
    assert info.value.code == 0xFA2 and "RS485 communication timeout" in info.value.text
    drv.clear_errors()
    assert drv.read("error_code") == 0
    bench.world.advance(0.05)  # talking again within the timeout: no new fault
    assert drv.read("error_code") == 0


# ------------------------------------------------------------------ 8. limits and Modbus exceptions


def test_software_position_limits_clamp_the_target(bench: Bench) -> None:
    drv = bench.drv["joint1"]
    drv.write("min_position_limit_value", -50_000)
    drv.write("max_position_limit_value", 80_000)
    drv.enable()
    fast = {"speed": 150_000, "acceleration": 300_000, "deceleration": 300_000}
    drv.move_to(200_000, **fast)
    bench.world.advance(2.5)
    assert bench.pos() == pytest.approx(80_000, abs=100)
    assert drv.read("status_of_achieving_position") == AchieveStatus.TARGET_REACHED
    drv.move_to(-300_000, **fast)
    bench.world.advance(2.5)
    assert bench.pos() == pytest.approx(-50_000, abs=100)
    drv.move_by(-100_000, **fast)  # relative moves are clamped too
    bench.world.advance(1.0)
    assert bench.pos() == pytest.approx(-50_000, abs=100)
    assert drv.read("error_code") == 0


def test_out_of_range_write_is_exception_03_and_changes_nothing(bench: Bench) -> None:
    drv = bench.drv["joint1"]
    emu = bench.world.drives["joint1"]
    logged = len(emu.write_log)
    with pytest.raises(DeviceRejected) as info:
        bench.link.write_register(SLAVE, EROB_MODBUS["operation_mode"].address, 9)
    assert info.value.code == 0x03
    assert drv.read("operation_mode") == 3
    assert len(emu.write_log) == logged
    # the bytes on the wire: 01 86 03 + CRC
    reply = bench.world.buses["rs485"].receive(mb.encode(mb.WriteSingleRegister(SLAVE, 0x0040, 9)))
    assert reply == mb.encode(mb.ExceptionReply(SLAVE, 0x06, 0x03))
    assert reply[:3] == bytes([SLAVE, 0x86, 0x03])


def test_read_of_unknown_address_is_exception_02(bench: Bench) -> None:
    with pytest.raises(DeviceRejected) as info:
        bench.link.read_registers(SLAVE, 0x0010, 1)
    assert info.value.code == 0x02
    reply = bench.world.buses["rs485"].receive(mb.encode(mb.ReadHoldingRegisters(SLAVE, 0x0010, 1)))
    assert reply[:3] == bytes([SLAVE, 0x83, 0x02])


def test_torque_mode_max_speed_only_while_disabled(bench: Bench) -> None:
    drv = bench.drv["joint1"]
    drv.configure_torque(max_speed=30_000)
    drv.enable()
    reg = EROB_MODBUS["torque_control_mode_max_speed"]
    with pytest.raises(DeviceRejected) as info:  # the drive refuses it (raw write, same link)
        bench.link.write_registers(SLAVE, reg.address, reg.to_words(50_000))
    assert info.value.code == 0x03
    assert drv.read("torque_control_mode_max_speed") == 30_000
    with pytest.raises(StateError):  # and the driver does not even send it
        drv.set_torque_speed_limit(50_000)
    drv.disable()
    drv.set_torque_speed_limit(50_000)
    assert drv.read("torque_control_mode_max_speed") == 50_000


# ------------------------------------------------------------------ 9. zero calibration, save, power cycle


def test_saved_position_offset_survives_power_cycle(bench: Bench) -> None:
    drv = bench.drv["joint1"]
    emu = bench.world.drives["joint1"]
    drv.enable()
    drv.move_to(10_000, speed=50_000, acceleration=100_000, deceleration=100_000)  # "desired zero"
    bench.world.advance(1.0)
    result = drv.calibrate_zero(confirm=True)  # chapter 7.2: disable, offset 0, read, offset, save
    assert result.actual_position == pytest.approx(10_000, abs=100)
    assert result.position_offset == ZERO_BASE - result.actual_position
    assert drv.read("actual_position") == ZERO_BASE
    default_speed = emu.get("profile_speed")
    # changes after the save are not in flash
    drv.write("profile_speed", 12_345)
    drv.write("position_offset", 0)
    assert drv.read("actual_position") == result.actual_position

    emu.power_cycle()
    drv.forget()
    assert drv.read("position_offset") == result.position_offset  # saved: kept
    assert drv.read("actual_position") == ZERO_BASE  # chapter 7, step 12
    assert drv.read("profile_speed") == default_speed  # written after the save: lost
    assert drv.read("error_code") == 0 and not drv.state().enabled

    # targets are in the offset frame: +50000 from the new zero moves the joint 50000 counts
    here = bench.pos()
    drv.enable()
    drv.move_to(ZERO_BASE + 50_000, speed=50_000, acceleration=100_000, deceleration=100_000)
    bench.world.advance(2.0)
    assert bench.pos() - here == pytest.approx(50_000, abs=100)
    assert drv.read("actual_position") == pytest.approx(ZERO_BASE + 50_000, abs=100)


def test_unsaved_settings_are_lost_on_power_cycle(bench: Bench) -> None:
    drv = bench.drv["joint1"]
    emu = bench.world.drives["joint1"]
    drv.write("position_offset", 1000)
    drv.write("dwell_time", 777)
    assert drv.read("actual_position") == 1000
    emu.power_cycle()
    drv.forget()
    assert drv.read("position_offset") == 0
    assert drv.read("dwell_time") == 20_000  # the power-on default
    assert drv.read("actual_position") == 0
    # World.reset() is a power cycle too: saved settings survive it
    drv.write("position_offset", 2000)
    drv.save_parameters(confirm=True)
    drv.write("position_offset", 3000)
    bench.world.reset()
    drv.forget()
    assert drv.read("position_offset") == 2000
