"""A ``lead`` turns any rotary joint into a linear one: m, m/s, m/s^2 and N in the Joint API, the drive's units
unchanged (an eRob on a 5 mm screw here, the MKS axis in tests/sim/test_mks_axis.py); config validation."""

from __future__ import annotations

import math

import pytest

from joints.clock import ManualClock
from joints.config import parse
from joints.devices.erob.params import EROB_PARAMS
from joints.devices.erob.profiles import DEFAULT_MODEL, profile
from joints.devices.erob.registers import COUNTS_PER_REV, EROB_MODBUS
from joints.drivers.erob_modbus import ErobModbusDriver
from joints.errors import CommandError, ConfigError, LimitError
from joints.joint import Joint, Limits, Motion
from joints.link.modbus import ModbusLink
from joints.sim.firmware import Firmware
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
from joints.transports.loopback import LoopbackTransport

LEAD = 0.005  #: m per turn
M_PER_COUNT = LEAD / COUNTS_PER_REV
KT = profile(DEFAULT_MODEL).torque_constant


def linear(limits: Limits | None = None) -> tuple[Joint, Firmware]:
    fw = Firmware(EROB_PARAMS)
    clock = ManualClock()
    link = ModbusLink(LoopbackTransport(ModbusDeviceBus([ModbusFront(fw, EROB_MODBUS, 2)])), clock=clock)
    driver = ErobModbusDriver(link, 2, clock=clock)
    joint = Joint("slide", driver, clock=clock, lead=LEAD, limits=limits,
                  motion=Motion(velocity=0.01, acceleration=0.1, deceleration=0.1))
    return joint, fw


def test_state_in_metres_metres_per_second_and_newton() -> None:
    joint, fw = linear()
    fw.set("actual_position", 1000)
    fw.set("current_speed", 2000)
    fw.set("motor_current", 1500)  # mA
    s = joint.state()
    assert s.position == pytest.approx(1000 * M_PER_COUNT)
    assert s.velocity == pytest.approx(2000 * M_PER_COUNT)
    assert s.torque == pytest.approx(1.5 * KT * 2 * math.pi / LEAD)  # N: motor torque through an ideal screw


def test_commands_convert_through_the_lead() -> None:
    joint, fw = linear(Limits(position=(-0.1, 0.1), velocity=0.05, torque=5000.0))
    fw.set("status_of_achieving_position", 1)
    joint.driver._enabled = True
    joint.driver._enabled_at = -10.0
    joint.move_to(0.02)
    assert fw.get("target_absolute_position") == round(0.02 / M_PER_COUNT)
    assert fw.get("profile_speed") == round(0.01 / M_PER_COUNT)
    joint.set_torque(1000.0)  # N -> motor torque 1000 x lead / 2 pi -> mA
    assert fw.get("target_current") == round(1000.0 * LEAD / (2 * math.pi) / KT * 1000)
    with pytest.raises(LimitError, match=r"0\.2000 m is outside"):
        joint.move_to(0.2)
    with pytest.raises(LimitError, match="m/s"):
        joint.set_velocity(0.06)
    with pytest.raises(LimitError, match=" N "):
        joint.set_torque(6000.0)


def test_cyclic_set_points_convert_through_the_lead_like_the_commands() -> None:
    joint, _fw = linear(Limits(position=(-0.1, 0.1), velocity=0.05, torque=5000.0))
    assert joint.cycle_target(0.02, "position") == round(0.02 / M_PER_COUNT)
    assert joint.cycle_target(0.01, "velocity") == round(0.01 / M_PER_COUNT)
    # N -> motor torque 1000 x lead / 2 pi -> mA, as set_torque (it was sent without the lead: 1257x too much)
    assert joint.cycle_target(1000.0, "torque") == round(1000.0 * LEAD / (2 * math.pi) / KT * 1000)


def test_lead_must_be_a_positive_number() -> None:
    driver = linear()[0].driver
    for bad in (-0.01, 0.0, math.nan):
        with pytest.raises(CommandError, match="lead"):
            Joint("x", driver, clock=ManualClock(), lead=bad)


def _cfg(lead: object) -> dict[str, object]:
    return {"buses": {"rs485": {"protocol": "modbus-rtu", "port": "/dev/null"}},
            "joints": {"slide": {"device": "erob", "bus": "rs485", "address": 2, "lead": lead}}}


def test_config_lead_is_validated_and_named() -> None:
    assert parse(_cfg(0.008)).joints["slide"].lead == 0.008
    assert parse({**_cfg(0.008), "joints": {"j": {"device": "erob", "bus": "rs485", "address": 2}}}).joints["j"].lead \
        is None
    for bad in (0, -0.01, "8mm", float("inf")):
        with pytest.raises(ConfigError, match=r"joints\.slide\.lead"):
            parse(_cfg(bad))
