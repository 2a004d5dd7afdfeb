"""The linear axis (models/mks_linear_axis.xml, lead 8 mm): SI units through the lead, end-stop switches from the
geometry, homing with the switch and 'noLimit', the end-limit stop, the same script on both protocols."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("mujoco")
pytestmark = pytest.mark.mks_firmware

from mkskit import axis_config

import joints
from joints.codecs import mks
from joints.devices.mks.state import MotorStatus
from joints.errors import ConfigError, LimitError

LEAD = 0.008
COUNTS = 16384


def _script(rig: joints.Rig) -> int:
    """The same user script for both protocols: enable, move the carriage +10 mm, wait, read the encoder."""
    j = rig.joints["carriage"]
    j.enable()
    j.move_to(0.010, velocity=0.04, acceleration=0.4)
    j.wait(timeout=10)
    rig.sleep(0.2)
    return j.read("encoder_addition")


def test_same_script_on_the_native_protocol_and_modbus_ends_within_one_count(mks_firmware: str) -> None:
    ends = {}
    for protocol in ("mks-serial", "modbus-rtu", "modbus-rtu direct"):
        cfg = axis_config(protocol=protocol.split()[0], firmware=mks_firmware)
        cfg["sim"]["direct"] = protocol.endswith("direct")  # Modbus's no-bytes path: the same results
        with joints.open(cfg) as rig:
            ends[protocol] = _script(rig)
            assert rig.joints["carriage"].state().position == pytest.approx(0.010, abs=LEAD / COUNTS)
            assert rig.world.joint_position("carriage") == pytest.approx(0.010, abs=2e-6)
    assert abs(ends["mks-serial"] - ends["modbus-rtu"]) <= 1, ends
    assert ends["modbus-rtu direct"] == ends["modbus-rtu"]
    assert abs(ends["mks-serial"] - 0.010 / LEAD * COUNTS) <= 1


def test_a_lead_makes_the_joint_linear_m_m_s_and_newton() -> None:
    with joints.open(axis_config()) as rig:
        j = rig.joints["carriage"]
        assert j.lead == LEAD and j.scale == pytest.approx(LEAD / (2 * math.pi))
        j.enable()
        j.set_velocity(0.02, acceleration=0.5)  # m/s -> 150 rpm
        assert j.driver.written("speed_mode_speed") == 150
        rig.sleep(1.0)
        s = j.state()
        assert s.velocity == pytest.approx(0.02, rel=0.01)
        assert rig.world.joint_velocity("carriage") == pytest.approx(0.02, rel=0.01)
        j.stop()
        with pytest.raises(LimitError, match="m/s"):
            j.set_velocity(0.2)  # limit 0.1 m/s
        with pytest.raises(LimitError, match=r"0\.0800 m is outside"):
            j.move_to(0.08)
        with pytest.raises(LimitError):
            j.write("position_mode4_abs_axis", round(0.09 / LEAD * COUNTS))  # a raw target checked in m too


def test_world_gives_the_slide_the_motor_through_the_lead() -> None:
    with joints.open(axis_config()) as rig:
        w = rig.world
        sj = w.joint("carriage")
        prof = rig.joints["carriage"].driver.profile
        r = 2 * math.pi / LEAD
        assert w.model.actuator_gear[sj.actuator, 0] == pytest.approx(r)
        assert w.model.dof_armature[sj.dof] == pytest.approx(prof.rotor_inertia * r * r)
        assert w.model.dof_frictionloss[sj.dof] == pytest.approx(prof.coulomb_friction * r)
        low, high = w.drives["carriage"].end_stops
        assert low == pytest.approx(-0.075 * r) and high == pytest.approx(0.075 * r)


def test_a_slide_needs_a_lead_and_a_hinge_must_not_have_one() -> None:
    cfg = axis_config()
    del cfg["joints"]["carriage"]["lead"]
    cfg["joints"]["carriage"]["limits"] = {}
    with pytest.raises(ConfigError, match="lead"):
        joints.open(cfg)


def test_homing_on_the_limit_switch_sets_the_axis_zero_there() -> None:
    with joints.open(axis_config()) as rig:
        j = rig.joints["carriage"]
        d = j.driver
        j.enable()
        d.set_home(trigger_level=0, direction=0, speed=240, end_limit=0)  # CW = toward the low end (IN_1)
        assert d.read("io_status") & 1 == 1  # IN_1 high: not triggered (effective level low)
        d.go_home()
        assert d.motor_status() is MotorStatus.HOMING
        assert d.wait_motion(20) is MotorStatus.STOP
        assert d.completion == mks.RunReply(1, 0x91, mks.RunStatus.COMPLETE)
        assert rig.world.joint_position("carriage") == pytest.approx(-0.075, abs=0.0002)
        rig.sleep(0.3)
        assert abs(d.read("encoder_addition")) <= 2 and d.read("io_status") & 1 == 0
        j.move_to(0.05)  # 50 mm from the switch
        j.wait(timeout=10)
        assert rig.world.joint_position("carriage") == pytest.approx(-0.025, abs=1e-5)


def test_homing_from_on_the_switch_leaves_it_first() -> None:
    with joints.open(axis_config()) as rig:
        rig.world.set_joint_positions({"carriage": -0.077})
        j = rig.joints["carriage"]
        d = j.driver
        j.enable()
        d.set_home(trigger_level=1, direction=0, speed=120, end_limit=0)  # a high-active switch this time
        assert d.read("io_status") & 1 == 1  # triggered: at its effective level (high)
        d.go_home()
        d.wait_motion(20)
        assert rig.world.joint_position("carriage") == pytest.approx(-0.075, abs=0.0002)


def test_nolimit_homing_stalls_on_the_end_stop_and_backs_off() -> None:
    with joints.open(axis_config()) as rig:
        j = rig.joints["carriage"]
        d = j.driver
        j.enable()
        d.set_home(direction=0, speed=240)
        d.set_nolimit_home(reverse_angle=0x4000, mode=1)  # back off one turn = 8 mm
        d.go_home()
        d.wait_motion(30)
        rig.sleep(0.3)
        x = rig.world.joint_position("carriage")
        assert -0.08 + LEAD - 0.008 < x < -0.08 + LEAD + 0.002  # one turn off the hard stop at -80 mm
        assert abs(d.read("encoder_addition")) <= 2


def test_end_limit_stops_a_move_into_the_switch_with_status_3() -> None:
    with joints.open(axis_config()) as rig:
        j = rig.joints["carriage"]
        d = j.driver
        j.enable()
        d.set_home(trigger_level=0, direction=0, speed=60, end_limit=1)
        d.move_to(round(-0.1 / LEAD * COUNTS), speed=300, acceleration=1000)  # 100 mm toward the low end
        d.wait_motion(20)
        assert d.completion == mks.RunReply(1, 0xF5, mks.RunStatus.END_LIMIT_STOP)
        assert rig.world.joint_position("carriage") == pytest.approx(-0.075, abs=0.001)
        d.move_to(round(-0.09 / LEAD * COUNTS), speed=100)  # further into it: stopped at once
        d.wait_motion(5)
        assert d.completion == mks.RunReply(1, 0xF5, mks.RunStatus.END_LIMIT_STOP)
        d.move_to(0, speed=300, acceleration=1000)  # away from it: fine
        d.wait_motion(20)
        assert d.completion == mks.RunReply(1, 0xF5, mks.RunStatus.COMPLETE)


def test_servo57d_axis_variant() -> None:
    cfg = axis_config(device="mks-servo57d", model="mks_linear_axis_57d.xml")
    with joints.open(cfg) as rig:
        j = rig.joints["carriage"]
        assert j.driver.profile.model == "SERVO57D"
        fw = rig.world.drives["carriage"]
        j.enable()
        j.move_to(0.02)
        j.wait(timeout=10)
        rig.sleep(0.3)  # "run complete" is the drive's reference; the heavier carriage settles after it
        assert rig.world.joint_position("carriage") == pytest.approx(0.02, abs=2e-6)
        assert fw.io_status() & 0b110 == 0b110  # IN_2 idle high, OUT_1 = 1 (not protected) on the 57D


def test_the_device_picks_the_profile_and_a_contradicting_model_is_refused() -> None:
    cfg = axis_config(device="mks-servo57d", model="mks_linear_axis_57d.xml")
    cfg["joints"]["carriage"]["model"] = "SERVO42D"
    with pytest.raises(ConfigError, match="not a mks-servo57d"):
        joints.open(cfg)
    cfg["joints"]["carriage"]["model"] = "servo57d"
    cfg["joints"]["carriage"]["profile"] = {"holding_torque": 2.5}
    with joints.open(cfg) as rig:
        assert rig.joints["carriage"].driver.profile.holding_torque == 2.5
        assert rig.world.drives["carriage"].profile.holding_torque == 2.5


@pytest.mark.parametrize("protocol", ["mks-serial", "modbus-rtu"])
def test_current_torque_and_temperature_are_not_reported(protocol: str) -> None:
    """Neither MKS protocol reads the motor current or a temperature: the state says so (NaN), never 0."""
    with joints.open(axis_config(protocol=protocol)) as rig:
        j = rig.joints["carriage"]
        j.enable()
        j.set_velocity(0.01)
        rig.sleep(0.3)
        s = j.state()
        assert s.velocity > 0.005
        assert math.isnan(s.current) and math.isnan(s.torque) and math.isnan(s.temperature)
