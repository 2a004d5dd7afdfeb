"""A twin's command-to-motion delay (firmware ``command_delay``, ``World.perturb(command_delay=)``) and the
eRob torque mode following its command substep by substep."""

from __future__ import annotations

import math

import pytest

from joints.devices.erob.profiles import PROFILES
from joints.errors import ParameterRefused
from joints.sim.erob import ErobFirmware

pytest.importorskip("mujoco")

import joints
from joints.sim import sensors
from simkit import erob_world

PROFILE = PROFILES["eRob80H100"]


def test_motion_commands_act_after_the_delay_and_in_order() -> None:
    fw = ErobFirmware(PROFILE, 1)
    fw.command_delay = 0.002
    fw.time = 1.000
    fw.write("target_current", 500)  # a motion command: waits
    assert fw.get("target_current") == 0 and len(fw.pending) == 1
    fw.write("position_loop_gain", 600)  # queued behind it: the drive keeps the order
    assert fw.get("position_loop_gain") == 500
    fw.tick(1.0015)
    assert fw.get("target_current") == 0
    fw.tick(1.002)
    assert fw.get("target_current") == 500 and fw.get("position_loop_gain") == 600 and not fw.pending
    fw.write("profile_speed", 1234)  # settings alone are never delayed
    assert fw.get("profile_speed") == 1234
    with pytest.raises(ParameterRefused):  # refusals are answered at once, nothing queued
        fw.write("target_current", 2**40)
    assert not fw.pending
    fw.write("target_current", 100)
    fw.power_cycle()  # what the drive had not acted on is lost with the power
    assert not fw.pending and fw.get("target_current") == 0


def test_zero_delay_acts_at_once() -> None:
    fw = ErobFirmware(PROFILE, 1)
    assert fw.command_delay == PROFILE.command_delay == 0.0
    fw.write("target_current", 500)
    assert fw.get("target_current") == 500 and not fw.pending


def _first_motion(world: object, rig_joint: joints.Joint, rig: joints.Rig) -> float:
    """Seconds from a torque command to the first substep the joint moves."""
    rig_joint.enable()
    rig.sleep(0.6)
    rig_joint.set_torque(0.0)
    start, q0 = rig.time, rig.sim.joint_position("joint1")
    rig_joint.set_torque(30.0)
    while abs(rig.sim.joint_position("joint1") - q0) < 1e-9:
        rig.sleep(rig.sim.timestep)
    return rig.time - start


def test_world_perturb_adds_the_delay_and_restore_removes_it() -> None:
    # ideal bus: the delay is measured from the command's arrival, which on the wire hides in its reply's time
    cfg = {"sim": {"model": "erob_stand.xml"}, "buses": {"b": {"protocol": "modbus-rtu", "timing": "ideal"}},
           "joints": {"joint1": {"device": "erob", "bus": "b", "address": 1,
                                 "limits": {"position": [-3, 3], "torque": 40.0}}}}
    with joints.open(cfg) as rig:
        base = _first_motion(rig.sim, rig.joints["joint1"], rig)
    with joints.open(cfg) as rig:
        rig.sim.perturb("joint1", command_delay=0.005)
        assert rig.sim.drives["joint1"].command_delay == 0.005
        delayed = _first_motion(rig.sim, rig.joints["joint1"], rig)
        rig.sim.restore()
        assert rig.sim.drives["joint1"].command_delay == 0.0 and not rig.sim.drives["joint1"].pending
    assert delayed - base == pytest.approx(0.005, abs=1e-9)
    with pytest.raises(ValueError, match="command delay would be"):
        erob_world("erob_stand.xml", ["joint1"], PROFILE).perturb("joint1", command_delay=-0.001)


def test_torque_mode_current_follows_every_command() -> None:
    """The torque-mode speed limiter stays out of the way below the speed limit: the current of the
    substep after a write is the written one, also while the joint accelerates (it used to clip
    every other substep of a rising command)."""
    cfg = {"sim": {"model": "erob_stand.xml"}, "buses": {"b": {"protocol": "modbus-rtu"}},
           "joints": {"joint1": {"device": "erob", "bus": "b", "address": 1,
                                 "limits": {"position": [-3, 3], "torque": 40.0, "velocity": 3.0}}}}
    with joints.open(cfg) as rig:
        sensors.ideal(rig.sim)  # the drive's own current, not as measured (noise, resolution)
        j = rig.joints["joint1"]
        j.enable()
        rig.sleep(0.6)
        j.set_torque(0.0)
        sent = []
        got = []
        for k in range(400):
            ma = round(3000 * math.sin(k * 0.02))
            j.write("target_current", ma)
            sent.append(ma)
            rig.sleep(0.001)
            got.append(j.read("motor_current"))
        assert max(abs(a - b) for a, b in zip(sent, got)) <= 1
        assert abs(j.state().velocity) > 0.2  # it did accelerate
