"""0x94 hm_mode 2 "single lap to zero" (RS485 manual V1.0.9 7.1 #3, 7.3.3, 7.6; Modbus-RTU V1.0.9 5.1 #3, 5.3.3,
5.6), driver -> twin on both protocols, on every firmware profile. The reading and its assumptions S1-S7 are in
docs/mks-firmware.md: go home (0x91) runs it; the zero, direction and speed are 0_Mode's (0x9A); the shaft turns
less than one turn to that angle of the encoder, in the set direction only (NearMode: the shorter way); on arrival
the axis reads 0; 0x3B status1 (single-turn) goes 0 -> 1, or 2 when stopped; status2 (homing) is not touched."""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("mujoco")

from mkskit import open_motor

from joints.codecs import mks
from joints.codecs import modbus as mb
from joints.devices.mks.modbus import MKS_MODBUS_OF
from joints.devices.mks.state import ENCODER_COUNTS_PER_TURN as COUNTS
from joints.devices.mks.state import MotorStatus
from joints.devices.quirks import (
    MKS_FIRMWARES,
    MKS_HOMING_STATUS,
    MKS_MODBUS_NOLIMIT_HOME,
    MKS_SINGLE_LAP_HOME,
    firmware_profile,
)
from joints.drivers.mks import MksDriver
from joints.errors import DeviceRejected, RegisterError
from joints.sim.mks import MksFirmware

PROTOCOLS = ("mks-serial", "modbus-rtu")
ZERO = 5000  #: the single-turn zero point [counts of the turn]
CW, CCW, NEAR = (1, 0), (1, 1), (2, 0)  #: 0x9A (0_Mode, 0_Dir)


def _has(firmware: str, feature: str = MKS_SINGLE_LAP_HOME) -> bool:
    return feature in firmware_profile("mks", firmware).features


HAVING = [f for f in MKS_FIRMWARES if _has(f)]
LACKING = [f for f in MKS_FIRMWARES if not _has(f)]


def _twin(rig) -> MksFirmware:  # type: ignore[no-untyped-def]
    fw = rig.world.drives["m1"]
    assert isinstance(fw, MksFirmware)
    return fw


def _counts(rad: float) -> float:
    return rad * COUNTS / math.tau


def _prepare(rig, zero_mode: tuple[int, int]) -> MksDriver:  # type: ignore[no-untyped-def]
    """Enable, turn to axis ZERO (the shaft starts at angle 0: axis = encoder angle), set 0_Mode's zero there with
    0_Speed 4, choose hm_mode 2."""
    j = rig.joints["m1"]
    d = j.driver
    j.enable()
    d.move_to(ZERO, speed=300)
    d.wait_motion(10)
    rig.sleep(0.2)
    mode, direction = zero_mode
    d.set_zero_mode(mode, set_zero=1, speed=4, direction=direction, confirm=True)
    zero = _twin(rig).zero_point
    assert zero is not None and abs(zero - ZERO) <= 1
    d.set_nolimit_home(mode=2)
    assert _twin(rig).values["home_mode"] == 2
    assert isinstance(d, MksDriver)
    return d


def _statuses(d: MksDriver) -> tuple[int, int]:
    got = d.access.read_many(["go_back_to_zero_status", "homing_status"])
    return got["go_back_to_zero_status"], got["homing_status"]


def _expected_travel(start: float, zero_mode: tuple[int, int]) -> float:
    """Counts from ``start`` (an angle of the turn, counts) to ZERO: the manual's 0_Dir / NearMode, within one turn."""
    if zero_mode == CCW:
        return (ZERO - start) % COUNTS
    if zero_mode == CW:
        return -((start - ZERO) % COUNTS)
    return (ZERO - start + COUNTS / 2) % COUNTS - COUNTS / 2


@pytest.mark.mks_firmware(*HAVING)
@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize(("zero_mode", "start"), [
    (CW, 3000 + 2 * COUNTS),  # CW from 3000: back over the turn's end, -14384 counts (not +2000)
    (CCW, 7000 - COUNTS),  # CCW from 7000: +14384 counts, across the turn (not -2000)
    (CCW, 3000),  # CCW from 3000: +2000
    (NEAR, 15000),  # NearMode from 15000: +6384 across the turn (the shorter way)
    (NEAR, 13000 + COUNTS)])  # NearMode from 13000: -8000
def test_single_lap_home_turns_less_than_a_turn_in_its_direction_and_resets_the_axis(
        tmp_path: Path, protocol: str, mks_firmware: str, zero_mode: tuple[int, int], start: int) -> None:
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": mks_firmware, "watchdog_ms": 0}) as rig:
        d = _prepare(rig, zero_mode)
        fw = _twin(rig)
        d.move_to(start, speed=600)
        d.wait_motion(10)
        rig.sleep(0.2)
        q0 = fw.q
        expected = _expected_travel(_counts(q0 % math.tau), zero_mode)
        assert abs(expected) > 1000  # a real lap, not a settling wiggle
        d.go_home()
        path = [q0]
        assert d.motor_status() is MotorStatus.HOMING
        speeds = []
        for _ in range(300):  # 3 s: a lap at 0_Speed 4 (240 rpm) takes 0.25 s
            if fw.motion is None:
                break
            rig.sleep(0.01)
            path.append(fw.q)
            speeds.append(abs(fw.qd) * 60 / math.tau)
        assert fw.motion is None
        moving = sorted(x for x in speeds if x > 50)  # rpm, sampled every 10 ms while it turned
        assert moving[len(moving) // 2] == pytest.approx(240, rel=0.1)  # 0_Speed 4, not HmSpeed (60) (S3)
        rig.sleep(0.2)
        path.append(fw.q)
        travel = _counts(fw.q - q0)
        assert abs(travel - expected) <= 2  # to the zero's angle, the way the 0_Dir / NearMode says
        assert abs(travel) < COUNTS  # within a single revolution
        sign = 1 if expected > 0 else -1
        progress = [sign * _counts(q - q0) for q in path]  # counts made in the set direction, sampled every 10 ms
        peak = progress.index(max(progress))
        assert min(progress) >= -2  # never set off against the set direction
        assert all(b >= a - 2 for a, b in itertools.pairwise(progress[:peak + 1]))  # nor turned back
        assert progress[peak] - progress[-1] <= COUNTS / 50  # but the overshoot of the unramped stop (7 deg)
        assert abs(_counts(fw.q % math.tau) - ZERO) <= 2  # at the single-turn zero
        assert abs(d.read("encoder_addition")) <= 1  # "the current position is reset to zero"
        assert d.motor_status() is MotorStatus.STOP


@pytest.mark.mks_firmware(*HAVING)
@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_single_lap_home_status_and_the_second_run_from_the_zero(tmp_path: Path, protocol: str,
                                                                 mks_firmware: str) -> None:
    """0x3B status1 (single-turn): 1 -> 0 going -> 2 stopped -> 0 -> 1 arrived; status2 (homing) stays 2. A second
    go home from the zero does not turn (0 counts) and ends at once with axis 0."""
    assert _has(mks_firmware, MKS_HOMING_STATUS)  # both statuses read on both protocols on this profile
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": mks_firmware, "watchdog_ms": 0}) as rig:
        j = rig.joints["m1"]
        d = _prepare(rig, CW)
        fw = _twin(rig)
        d.move_to(ZERO + 10000, speed=600)
        d.wait_motion(10)
        assert _statuses(d) == (1, 2)  # no zero return run yet since power-on (none at power-on: 0_Mode was unset)
        d.go_home()
        rig.sleep(0.02)
        assert _statuses(d) == (0, 2)  # going
        j.stop()
        assert _statuses(d) == (2, 2)  # stopped before it arrived
        d.wait_motion(10)
        assert _statuses(d) == (2, 2)  # and the stop running out is no arrival
        assert fw.motion is None and abs(d.read("encoder_addition") - ZERO) > 100  # axis not reset
        d.go_home()
        rig.sleep(0.02)
        assert _statuses(d) == (0, 2)
        d.wait_motion(10)
        assert _statuses(d) == (1, 2)
        assert abs(d.read("encoder_addition")) <= 1
        rig.sleep(0.2)
        q0 = fw.q
        d.go_home()  # already there
        d.wait_motion(10)
        assert abs(_counts(fw.q - q0)) <= 2 and _statuses(d) == (1, 2)
        assert abs(d.read("encoder_addition")) <= 1


@pytest.mark.mks_firmware(*HAVING)
@pytest.mark.parametrize("zero_mode", [CW, CCW, NEAR])
def test_single_lap_home_right_where_the_zero_was_set_does_not_turn(tmp_path: Path, mks_firmware: str,
                                                                   zero_mode: tuple[int, int]) -> None:
    """The zero is the encoder's count (floored), the shaft a fraction of a count past it: either way round that is
    "already there" (assumption S4), not a lap of 16383 counts."""
    with open_motor(tmp_path, joint={"firmware": mks_firmware, "watchdog_ms": 0}) as rig:
        d = rig.joints["m1"].driver
        fw = _twin(rig)
        rig.joints["m1"].enable()
        d.move_to_pulses(980, speed=300)  # 980 x 16384 / 3200 = 5017.6 counts: 0.6 of a count past the one set
        d.wait_motion(10)
        rig.sleep(0.2)
        mode, direction = zero_mode
        d.set_zero_mode(mode, set_zero=1, speed=4, direction=direction, confirm=True)
        d.set_nolimit_home(mode=2)
        assert fw.zero_point == 5017 and _counts(fw.q) == pytest.approx(5017.6, abs=0.2)
        q0 = fw.q
        d.go_home()
        d.wait_motion(10)
        assert abs(_counts(fw.q - q0)) <= 2
        assert abs(d.read("encoder_addition")) <= 1


@pytest.mark.mks_firmware(*HAVING)
def test_the_single_turn_zero_is_the_encoders_angle_whatever_axis_zero_0x92_set(tmp_path: Path,
                                                                               mks_firmware: str) -> None:
    """0x92 moves the axis zero, not the single-turn one (assumption S2): Set 0 at axis 2000 after a 0x92 at
    encoder count 3000 is encoder count 5000, and the CW lap from count 2000 turns 13384 counts to it."""
    with open_motor(tmp_path, joint={"firmware": mks_firmware, "watchdog_ms": 0}) as rig:
        d = rig.joints["m1"].driver
        fw = _twin(rig)
        rig.joints["m1"].enable()
        d.move_to(3000, speed=300)
        d.wait_motion(10)
        d.set_zero(confirm=True)  # 0x92: axis 0 at encoder count 3000
        d.move_to(2000, speed=300)  # encoder count 5000
        d.wait_motion(10)
        rig.sleep(0.2)
        d.set_zero_mode(CW[0], direction=CW[1], set_zero=1, speed=4, confirm=True)
        d.set_nolimit_home(mode=2)
        d.move_to(-1000, speed=300)  # encoder count 2000
        d.wait_motion(10)
        rig.sleep(0.2)
        q0 = fw.q
        d.go_home()
        d.wait_motion(10)
        rig.sleep(0.2)
        assert abs(_counts(fw.q - q0) + 13384) <= 2
        assert abs(_counts(fw.q % math.tau) - ZERO) <= 2 and abs(d.read("encoder_addition")) <= 1


@pytest.mark.mks_firmware(*HAVING)
@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_single_lap_home_without_a_single_turn_zero_is_refused_and_nothing_moves(tmp_path: Path, protocol: str,
                                                                                  mks_firmware: str) -> None:
    """0_Mode Disable with its zero cleaned: nothing to return to ("needs to be set in advance"): go home fails
    (native status 0 / Modbus failure reply) and the shaft stays."""
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": mks_firmware, "watchdog_ms": 0}) as rig:
        d = _prepare(rig, NEAR)
        fw = _twin(rig)
        d.set_zero_mode(0, set_zero=0, confirm=True)
        d.move_to(ZERO + 3000, speed=600)
        d.wait_motion(10)
        q0 = fw.q
        with pytest.raises(DeviceRejected):
            d.go_home()
        rig.sleep(0.3)
        assert fw.motion is None and abs(_counts(fw.q - q0)) <= 2


@pytest.mark.mks_firmware(*LACKING)
@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_single_lap_home_needs_v109(tmp_path: Path, protocol: str, mks_firmware: str) -> None:
    """Before V1.0.9 the driver refuses hm_mode 2 naming v1.0.9, nothing sent; the twin refuses it on the wire
    (native status 0; Modbus v1.0.6 failure reply, v1.0.5 exception: no 0x94 in its Part 8)."""
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": mks_firmware, "watchdog_ms": 0}) as rig:
        d: Any = rig.joints["m1"].driver  # (its link, for the raw writes)
        assert isinstance(rig.joints["m1"].driver, MksDriver)
        fw = _twin(rig)
        sent = d.link.transactions
        with pytest.raises(RegisterError, match="v1.0.9"):
            d.set_nolimit_home(mode=2)
        with pytest.raises(RegisterError, match="v1.0.9"):
            d.write_param("home_mode", 2)
        assert d.link.transactions == sent  # nothing was sent
        with pytest.raises(DeviceRejected):  # written raw, past the driver
            if protocol == "mks-serial":
                d.link.request(mks.SetNoLimitHomeParameters(1, 0x2000, 2, 600), idempotent=True)
            else:
                d.link.write_registers(1, 0x94, (0, 0x2000, 2, 600))
        assert fw.values["home_mode"] == 0
        if protocol == "mks-serial" or _has(mks_firmware, MKS_MODBUS_NOLIMIT_HOME):
            d.set_nolimit_home(mode=1)  # the older modes are still taken
            assert fw.values["home_mode"] == 1


@pytest.mark.mks_firmware(None)
def test_single_lap_frames_are_the_manuals_examples() -> None:
    """RS485 V1.0.9 7.6 steps 2-3 and Modbus-RTU V1.0.9 5.6 step 3 (its step 2, FC16 0x0094 with hm_mode 2, is in
    test_fc16_0x0094_is_the_manuals_frame): hm_mode 2, then 0_Mode NearMode with "Set 0"."""
    assert mks.encode(mks.SetNoLimitHomeParameters(1, 0x2000, 2, 0x64)) == bytes.fromhex("FA 01 94 00 00 20 00 02 00 64 15")
    assert mks.encode(mks.SetZeroMode(1, 2, 1, 2, 0)) == bytes.fromhex("FA 01 9A 02 01 02 00 9A")
    block = MKS_MODBUS_OF["v1.0.9"].block(0x10, 0x9A)
    words = block.words({"zero_mode": 2, "zero_mode_set_zero": 1, "zero_mode_speed": 2, "zero_mode_direction": 0})
    assert mb.encode(mb.WriteMultipleRegisters(1, 0x9A, words)) == bytes.fromhex("01 10 00 9A 00 02 04 02 01 02 00 2B A4")
