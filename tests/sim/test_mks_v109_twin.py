"""The MKS twin's V1.0.6-V1.0.9 behaviour where a driver alone cannot show it: hardware inputs (the En line)
and power cycles (what is kept in flash)."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("mujoco")

from mkskit import open_motor

from joints.devices.mks.state import ENCODER_COUNTS_PER_TURN as COUNTS
from joints.devices.mks.state import WorkMode
from joints.sim.mks import MksFirmware


def _twin(rig) -> MksFirmware:  # type: ignore[no-untyped-def]
    fw = rig.world.drives["m1"]
    assert isinstance(fw, MksFirmware)
    return fw


def _set_zero_off_start(rig) -> int:  # type: ignore[no-untyped-def]
    """Enable, turn the shaft away from its power-on position and set 0_Mode's zero there (NearMode, "Set 0");
    returns that zero's single-turn count."""
    j = rig.joints["m1"]
    d = j.driver
    j.enable()
    d.move_to(5000, speed=300)
    d.wait_motion(10)
    rig.sleep(0.2)
    zero = int(d.read("encoder_addition")) % COUNTS
    d.set_zero_mode(2, set_zero=1, speed=4, confirm=True)
    return zero


@pytest.mark.parametrize("firmware", ["v1.0.6", "v1.0.9"])
def test_en_triggered_zero_return_runs_on_an_en_pulse_not_at_power_on(tmp_path: Path, firmware: str) -> None:
    """0x9D g0Enable (V1.0.6 5.10): with 0_Mode set, the single-turn zero return no longer runs at power-on
    but on an En pulse of about 200 ms, in a pulse work mode."""
    with open_motor(tmp_path, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        d = rig.joints["m1"].driver
        fw = _twin(rig)
        zero = _set_zero_off_start(rig)
        d.set_position_error_protection(False, en_zero_return=True, confirm=True)
        d.move_to(9000, speed=300)
        d.wait_motion(10)
        rig.reset()  # power cycle: flash keeps 0_Mode, its zero and g0Enable; the shaft starts at 0
        rig.sleep(1.0)
        start = d.read("encoder_addition") % COUNTS
        assert abs(start - zero) > 1000 and fw.motion is None  # no zero return at power-on
        d.set_work_mode(WorkMode.CR_vFOC)  # the En line rules in the pulse work modes
        assert not fw.en_pulse(1.0)  # a long En level is no trigger pulse
        assert fw.en_pulse(0.2)
        assert d.read("go_back_to_zero_status") == 0  # going
        rig.sleep(2.0)
        assert d.read("go_back_to_zero_status") == 1
        assert abs(d.read("encoder_addition") % COUNTS - zero) <= 1


def test_without_en_trigger_the_zero_return_runs_at_power_on_and_an_en_pulse_does_nothing(tmp_path: Path) -> None:
    with open_motor(tmp_path, joint={"firmware": "v1.0.9", "watchdog_ms": 0}) as rig:
        d = rig.joints["m1"].driver
        fw = _twin(rig)
        _set_zero_off_start(rig)
        rig.reset()
        assert fw.motion is not None  # returning to zero at power-on
        rig.sleep(2.0)
        d.set_work_mode(WorkMode.CR_vFOC)
        assert not fw.en_pulse(0.2)


@pytest.mark.parametrize(("firmware", "released"), [("v1.0.5", False), ("v1.0.6", True), ("v1.0.9", True)])
def test_an_en_pulse_releases_the_protection_from_v106(tmp_path: Path, firmware: str, released: bool) -> None:
    with open_motor(tmp_path, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        fw = _twin(rig)
        j.enable()
        fw.protected = True  # as the locked-rotor protection leaves it (its trip: tests/sim/test_mks_twin.py)
        assert d.protection_state()
        assert fw.en_pulse(0.2) is released
        assert d.protection_state() is not released


@pytest.mark.parametrize("firmware", ["v1.0.5", "v1.0.6"])
def test_a_coordinate_homing_frame_is_unknown_to_firmware_before_v109(tmp_path: Path, firmware: str) -> None:
    """Sent raw (the driver refuses it first): native ``FA 01 91 01 8D`` gets no answer and nothing moves;
    Modbus FC06 0x0091 = 2 is a value the older register does not take (V1.0.5 exception 03, V1.0.6 the
    failure reply); = 1 still homes."""
    from joints.codecs import mks
    from joints.errors import DeviceRejected, ReplyTimeout

    with open_motor(tmp_path, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        rig.joints["m1"].enable()
        with pytest.raises(ReplyTimeout):
            rig.joints["m1"].driver.link.request(mks.GoHome(1, 1))
        assert _twin(rig).motion is None
    with open_motor(tmp_path, protocol="modbus-rtu", joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        rig.joints["m1"].enable()
        link = rig.joints["m1"].driver.link
        with pytest.raises(DeviceRejected) as refused:
            link.write_register(1, 0x91, 2)
        assert refused.value.code == (3 if firmware == "v1.0.5" else 0) and _twin(rig).motion is None
        link.write_register(1, 0x91, 1)
        assert _twin(rig).motion is not None and _twin(rig).motion.kind == "home"


def test_the_user_id_is_kept_at_power_off(tmp_path: Path) -> None:
    with open_motor(tmp_path, joint={"firmware": "v1.0.9", "watchdog_ms": 0}) as rig:
        d = rig.joints["m1"].driver
        d.write_param("user_id", 4711)
        rig.reset()
        rig.sleep(0.5)
        assert d.read("user_id") == 4711
