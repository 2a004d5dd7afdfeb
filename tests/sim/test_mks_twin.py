"""The MKS SERVO42D/57D twin in lockstep through the hardware driver: the acceleration law, the stepper torque
curve, mode clamps, microsteps and encoder counts, lost steps, locked-rotor protection, currents, power cycles
(0_Mode, saved speed mode, restore defaults), emergency stop and completions without polling."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("mujoco")
pytestmark = pytest.mark.mks_firmware

from mkskit import open_motor

from joints.codecs import mks
from joints.devices.mks.state import MotorStatus, WorkMode
from joints.errors import DeviceRejected
from joints.sim.mks import MksFirmware

RPM = 2 * math.pi / 60
COUNTS = 16384


def _at(rig, t: float) -> None:  # type: ignore[no-untyped-def]
    rig.sleep(t - rig.time)



def block(world: Any, damping: float = 1e4) -> float:
    """Block the motor's shaft with a damping no motor torque can turn (or set it back); the one before."""
    dof = world.joint("m1").dof
    before = float(world.model.dof_damping[dof])
    world.model.dof_damping[dof] = damping
    return before

def test_speed_0_to_600rpm_with_acc_236_reaches_speed_at_0_6s(tmp_path: Path) -> None:
    """SERVO42D, SR_vFOC, 16 microsteps, 24 V, no load: (256 - 236) x 50 us per rpm = 1000 rpm/s."""
    with open_motor(tmp_path) as rig:
        j = rig.joints["m1"]
        d = j.driver
        assert d.work_mode is WorkMode.SR_vFOC and d.microsteps == 16 and d.profile.bus_voltage == 24.0
        j.enable()
        t0 = rig.time
        d.set_velocity(600, acceleration=1000)
        assert d.written("speed_mode_acc") == 236
        speeds = {}
        for t in (0.15, 0.3, 0.45, 0.59, 0.6, 0.8):
            _at(rig, t0 + t)
            speeds[t] = d.read("real_time_speed")
            if t == 0.3:
                assert d.motor_status() is MotorStatus.SPEED_UP
        for t in (0.15, 0.3, 0.45):
            assert speeds[t] == pytest.approx(1000 * t, rel=0.01), speeds
        assert speeds[0.6] == pytest.approx(600, rel=0.01), speeds  # at 0.6 s, within 1 %
        assert speeds[0.59] < 600 and speeds[0.8] == pytest.approx(600, abs=2)
        assert d.motor_status() is MotorStatus.FULL_SPEED


def test_command_above_the_back_emf_speed_saturates_and_the_state_shows_the_real_speed(tmp_path: Path) -> None:
    with open_motor(tmp_path) as rig:
        j = rig.joints["m1"]
        d = j.driver
        j.enable()
        d.set_velocity(1200, acceleration=1000)  # vFOC allows 3000 rpm; the motor's 24 V curve does not
        rig.sleep(2.0)
        read = d.read("real_time_speed")
        true = rig.world.joint_velocity("m1") / RPM
        assert read == pytest.approx(true, abs=1)  # the rotor's speed, never the command
        assert 650 < read < d.profile.no_load_rpm < 800
        state = j.state()
        assert state.velocity == pytest.approx(true * RPM, abs=2 * RPM)
        assert d.motor_status() is MotorStatus.FULL_SPEED  # the drive's ramp reached its goal


@pytest.mark.parametrize("mode,top", [(WorkMode.SR_OPEN, 400), (WorkMode.SR_CLOSE, 1500)])
def test_work_mode_clamps_the_commanded_speed(tmp_path: Path, mode: WorkMode, top: int) -> None:
    with open_motor(tmp_path) as rig:
        j = rig.joints["m1"]
        d = j.driver
        d.work_mode = mode
        j.enable()
        d.set_velocity(600, acceleration=1000)
        rig.sleep(1.5)
        fw = rig.world.drives["m1"]
        assert isinstance(fw, MksFirmware)
        assert fw.mode is mode and fw.ramp_goal == min(600, top)
        assert d.read("real_time_speed") == pytest.approx(min(600, top), abs=5)


@pytest.mark.parametrize("mode", [WorkMode.SR_CLOSE, WorkMode.SR_vFOC])
@pytest.mark.parametrize("pulses", [3200, 1234, -4567, 99, 200 * 16 * 7 + 3])
def test_n_pulses_at_16_microsteps_end_n_over_3200_turns_away_within_one_count(
        tmp_path: Path, mode: WorkMode, pulses: int) -> None:
    with open_motor(tmp_path) as rig:
        j = rig.joints["m1"]
        d = j.driver
        d.work_mode = mode
        j.enable()
        start = d.read("encoder_addition")
        p0 = d.read("number_of_pulses")
        d.move_pulses(pulses, speed=300, acceleration=2000)
        assert d.wait_motion(20) is MotorStatus.STOP
        rig.sleep(0.3)
        moved = d.read("encoder_addition") - start
        assert abs(moved - pulses * COUNTS / 3200) <= 1, (moved, pulses * COUNTS / 3200)
        assert d.read("number_of_pulses") - p0 == pulses


def test_absolute_axis_and_pulse_moves_end_on_their_targets(tmp_path: Path) -> None:
    with open_motor(tmp_path) as rig:
        j = rig.joints["m1"]
        d = j.driver
        j.enable()
        d.move_to(-0x4000, speed=600)  # 6.9's example: to -0x4000
        d.wait_motion(10)
        rig.sleep(0.2)
        assert abs(d.read("encoder_addition") + 0x4000) <= 1
        d.move_by(0x4000, speed=600)  # 6.8: relative +0x4000
        d.wait_motion(10)
        rig.sleep(0.2)
        assert abs(d.read("encoder_addition")) <= 1
        d.move_to_pulses(0x4000, speed=600)  # 6.7: "after move the pulses is 0x4000"
        d.wait_motion(10)
        assert d.read("number_of_pulses") == 0x4000


@pytest.mark.parametrize("mode,lost", [(WorkMode.SR_OPEN, True), (WorkMode.SR_CLOSE, False),
                                       (WorkMode.SR_vFOC, False)])
def test_open_mode_loses_steps_under_overload_closed_modes_correct_them(
        tmp_path: Path, mode: WorkMode, lost: bool) -> None:
    with open_motor(tmp_path) as rig:
        j = rig.joints["m1"]
        d = j.driver
        w = rig.world
        dof = w.joint("m1").dof
        d.work_mode = mode
        j.enable()
        start = d.read("encoder_addition")
        d.move_pulses(3200 * 5, speed=300, acceleration=2000)
        rig.sleep(0.4)
        w.data.qfrc_applied[dof] = -0.35  # beyond the ~0.29 N*m the motor has at 300 rpm, for 20 ms
        rig.sleep(0.02)
        w.data.qfrc_applied[dof] = 0.0
        d.wait_motion(10)
        rig.sleep(1.0)
        error = d.read("encoder_addition") - start - 5 * COUNTS
        cycle = COUNTS / 50  # one electrical cycle = 4 full steps = 327.68 counts
        if lost:
            assert error <= -cycle + 2  # behind by whole electrical cycles, never corrected
            assert abs(error / cycle - round(error / cycle)) < 0.02
        else:
            assert abs(error) <= 1


def test_locked_rotor_protection_trips_after_the_error_stays_above_180_degrees(tmp_path: Path) -> None:
    with open_motor(tmp_path) as rig:
        j = rig.joints["m1"]
        d = j.driver
        w = rig.world
        fw = w.drives["m1"]
        d.set_locked_rotor_protection(True)
        j.enable()
        d.set_velocity(200, acceleration=0)
        free = block(w)
        tripped_at = None
        error_big_at = None
        for _ in range(100):
            rig.sleep(0.01)
            if error_big_at is None and abs(fw.r - fw.q) > math.pi:
                error_big_at = rig.time
            if d.protection_state():
                tripped_at = rig.time
                break
        assert error_big_at is not None and tripped_at is not None
        assert tripped_at - error_big_at == pytest.approx(fw.profile.stall_time, abs=0.011)
        s = j.state()
        assert s.fault is not None and s.fault.name == "locked_rotor_protection" and not s.enabled
        assert d.motor_status() is MotorStatus.STOP
        block(w, free)
        j.clear_faults()  # 0x3D release
        s = j.state()
        assert s.fault is None and s.enabled


def test_protection_off_never_trips(tmp_path: Path) -> None:
    with open_motor(tmp_path) as rig:
        j = rig.joints["m1"]
        d = j.driver
        w = rig.world
        fw = w.drives["m1"]
        d.set_locked_rotor_protection(False)
        j.enable()
        d.set_velocity(200, acceleration=0)
        block(w)
        worst = 0.0
        for _ in range(100):  # 1 s: several times the stall time with the error past half a turn
            rig.sleep(0.01)
            worst = max(worst, abs(fw.r - fw.q))
            assert abs(w.data.qvel[w.joint("m1").dof]) < 0.01  # stalled, not pushed around
        assert worst > math.pi
        s = j.state()
        assert s.fault is None and s.enabled and not d.protection_state()


def test_working_current_sets_the_torque_and_the_speed_the_motor_reaches(tmp_path: Path) -> None:
    speeds = {}
    for ma in (1600, 400):
        with open_motor(tmp_path) as rig:
            j = rig.joints["m1"]
            d = j.driver
            d.set_working_current(ma)
            j.enable()
            fw = rig.world.drives["m1"]
            assert fw.available_torque() == pytest.approx(d.profile.peak_torque(ma / 1000), rel=1e-3)
            d.set_velocity(1200, acceleration=1000)
            rig.sleep(2.0)
            speeds[ma] = d.read("real_time_speed")
    assert speeds[400] < speeds[1600] - 40


def test_holding_current_applies_at_rest_in_open_and_close_modes_not_vfoc(tmp_path: Path) -> None:
    with open_motor(tmp_path) as rig:
        j = rig.joints["m1"]
        d = j.driver
        fw = rig.world.drives["m1"]
        d.set_holding_current(2)  # 30 %
        j.enable()
        full = d.profile.peak_torque(1.6)
        assert fw.available_torque() == pytest.approx(full)  # vFOC: adaptive up to Ma
        d.set_work_mode(WorkMode.SR_CLOSE)
        assert fw.available_torque() == pytest.approx(0.3 * full)
        d.set_velocity(100, acceleration=0)
        rig.sleep(0.1)
        assert fw.available_torque() > 0.8 * full  # running: the working current


def test_microstep_speed_scaling_of_6_1(tmp_path: Path) -> None:
    for microsteps, rpm in ((8, 600), (128, 37.5)):
        with open_motor(tmp_path) as rig:
            j = rig.joints["m1"]
            fw = rig.world.drives["m1"]
            d = j.driver
            d.set_microsteps(microsteps)  # the drive holds it: the driver computes with it (0x47 at enable)
            j.enable()
            assert d.microsteps == microsteps
            assert fw.microsteps == microsteps
            d.access.write_many({"speed_mode_direction": 0, "speed_mode_speed": 300, "speed_mode_acc": 0},
                                idempotent=False)
            rig.sleep(0.5)
            assert rig.world.joint_velocity("m1") / RPM == pytest.approx(rpm, rel=0.02)


def test_emergency_stop_stops_at_once_without_completion(tmp_path: Path) -> None:
    with open_motor(tmp_path) as rig:
        j = rig.joints["m1"]
        d = j.driver
        j.enable()
        d.set_velocity(300, acceleration=1000)
        rig.sleep(0.5)
        before = d.completions
        j.emergency_stop()
        assert d.motor_status() is MotorStatus.STOP
        steps = d.read("number_of_pulses")
        rig.sleep(0.3)
        assert d.read("number_of_pulses") == steps  # the drive stopped stepping at once
        assert d.read("real_time_speed") == 0
        d.link.poll(0)
        assert d.completions == before


def test_completion_frames_tell_the_driver_the_move_ended_without_polling(tmp_path: Path, mks_firmware: str) -> None:
    # watchdog 0: no keep-alive reads of a V1.0.9 heartbeat (they are its food, not a poll for the end)
    with open_motor(tmp_path, joint={"firmware": mks_firmware, "watchdog_ms": 0}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        j.enable()
        d.move_pulses(3200, speed=300, acceleration=1000)
        sent = d.link.transactions
        while not d.motion_complete:
            rig.sleep(0.01)
            d.link.poll(0)  # deliver what arrived; sends nothing
        assert d.link.transactions == sent  # no status was polled
        assert d.completion == mks.RunReply(1, 0xFD, mks.RunStatus.COMPLETE)
        assert rig.time < 1.5


@pytest.mark.parametrize("protocol", ["mks-serial", "modbus-rtu"])
def test_run_commands_fail_while_disabled_or_in_a_pulse_work_mode(tmp_path: Path, protocol: str,
                                                                  mks_firmware: str) -> None:
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": mks_firmware}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        j.enable()
        d.disable()
        with pytest.raises(DeviceRejected):
            d.set_velocity(100)
        d.set_work_mode(WorkMode.CR_vFOC)
        with pytest.raises(DeviceRejected):
            d.write_param("motor_enable", 1)  # 0xF3 needs a serial work mode


def test_zero_mode_returns_to_the_set_zero_after_a_power_cycle(tmp_path: Path) -> None:
    with open_motor(tmp_path) as rig:
        j = rig.joints["m1"]
        d = j.driver
        j.enable()
        d.move_to(5000, speed=300)
        d.wait_motion(10)
        rig.sleep(0.2)
        zero = d.read("encoder_addition") % COUNTS
        d.set_zero_mode(2, set_zero=1, speed=4, confirm=True)  # NearMode, Set 0 here
        d.move_to(9000, speed=300)
        d.wait_motion(10)
        rig.reset()  # power cycle: flash keeps 0_Mode and its zero; the shaft starts at 0
        assert d.read("go_back_to_zero_status") == 0  # going
        rig.sleep(2.0)
        assert d.read("go_back_to_zero_status") == 1
        assert abs(d.read("encoder_addition") % COUNTS - zero) <= 1


def test_saved_speed_mode_runs_after_a_power_cycle(tmp_path: Path) -> None:
    with open_motor(tmp_path) as rig:
        j = rig.joints["m1"]
        d = j.driver
        j.enable()
        d.set_velocity(320, acceleration=500)
        d.save_speed_mode(confirm=True)
        d.stop()
        rig.sleep(1.0)
        assert d.read("real_time_speed") == 0
        rig.reset()
        rig.sleep(2.0)
        assert d.read("real_time_speed") == pytest.approx(320, abs=3)  # runs by itself at power-on
        d.clean_speed_mode()
        rig.reset()
        rig.sleep(1.0)
        assert d.read("real_time_speed") == 0


def test_settings_survive_a_restart_restore_defaults_needs_calibration(tmp_path: Path) -> None:
    with open_motor(tmp_path) as rig:
        j = rig.joints["m1"]
        d = j.driver
        fw = rig.world.drives["m1"]
        j.enable()
        d.set_working_current(1000)
        d.restart(confirm=True)
        rig.sleep(0.01)
        assert fw.values["working_current"] == 1000 and fw.values["work_mode"] == WorkMode.SR_vFOC
        d.restore_defaults(confirm=True)
        rig.sleep(0.01)
        assert fw.values["working_current"] == 1600 and fw.values["work_mode"] == WorkMode.CR_vFOC
        d.set_work_mode(WorkMode.SR_vFOC)
        with pytest.raises(DeviceRejected):
            d.set_velocity(100)  # not calibrated
        d.calibrate(confirm=True)
        assert d.motor_status() is MotorStatus.CALIBRATING
        d.wait_motion(5)
        d.link.poll(0)
        assert d.completion == mks.CalibrationReply(1, mks.CalibrationStatus.SUCCESS)
        d.set_velocity(100)
        rig.sleep(0.3)
        assert d.read("real_time_speed") == 100


def test_respond_off_run_commands_get_no_reply_queries_still_answer(tmp_path: Path) -> None:
    with open_motor(tmp_path) as rig:
        j = rig.joints["m1"]
        d = j.driver
        j.enable()
        d.set_respond_active(False, True)
        d.set_velocity(200, acceleration=2000)
        assert d.access.last_reply is None  # nothing came back, nothing was waited for
        rig.sleep(0.5)
        assert d.read("real_time_speed") == 200  # it runs; queries answer
        d.move_pulses(3200, speed=300, acceleration=2000)
        assert d.wait_motion(5) is MotorStatus.STOP  # found by polling 0xF1: no completion frames now
        d.link.poll(0)
        assert d.completions == 0


def test_decelerated_and_immediate_stops(tmp_path: Path) -> None:
    with open_motor(tmp_path) as rig:
        j = rig.joints["m1"]
        d = j.driver
        j.enable()
        d.set_velocity(500, acceleration=1000)
        rig.sleep(0.6)
        t0 = rig.time
        d.stop()  # decelerates with the same acc: 0.5 s from 500 rpm
        while not d.motion_complete:
            rig.sleep(0.01)
            d.link.poll(0)
        assert rig.time - t0 == pytest.approx(0.5, abs=0.02)
        assert d.completion == mks.RunReply(1, 0xF6, mks.RunStatus.COMPLETE)
        d.set_velocity(500, acceleration=1000)
        rig.sleep(0.6)
        steps = d.read("number_of_pulses")
        before = d.completions
        d.stop_now()
        d.link.poll(0.01)  # the completion frame follows the reply on the wire (a few ms at 38400 baud)
        assert d.completions == before + 1  # complete at once
        assert d.completion == mks.RunReply(1, 0xF6, mks.RunStatus.COMPLETE)
        stopped = d.read("number_of_pulses")  # it ran on only while the stop was on the wire (~5 ms at 500 rpm)
        assert 0 <= stopped - steps < 500 * 3200 / 60 * 0.01
        rig.sleep(0.1)
        assert d.read("number_of_pulses") == stopped
