"""The ZLAC8015D driver counts what the drive is set to: 4 x the encoder lines of 0x2030/0x2060, read at connect;
a config naming another line count is refused with both numbers."""

from __future__ import annotations

import copy
import math
from typing import Any

import pytest

pytest.importorskip("mujoco")

import joints
from joints.errors import ConfigError

CONFIG: dict[str, Any] = {
    "backend": "sim",
    "sim": {"model": "zlac_diffdrive.xml"},
    "buses": {"rs485": {"protocol": "modbus-rtu", "port": "/dev/ttyUSB0"}},
    "joints": {f"{side}_wheel": {"device": "zlac8015d", "bus": "rs485", "address": 1, "channel": side,
                                 "limits": {"velocity": 30.0}, "motion": {"acceleration": 50.0}}
               for side in ("left", "right")},
}


def _set_drive_lines(rig: joints.Rig, lines: int) -> None:
    """The drive's owner set both motors' encoder lines (the vendor tool): the twin holds ``lines``."""
    rig.world.drives["left_wheel"].write_many([("encoder_line_left", lines), ("encoder_line_right", lines)])


def _turn(rig: joints.Rig, radians: float) -> tuple[int, float]:
    """Move the left wheel by ``radians``: (the drive's count change, the wheel's turn in the physics)."""
    j = rig.joints["left_wheel"]
    j.enable()
    c0, q0 = j.read("actual_motor_position_left"), rig.world.joint_position("left_wheel")
    j.move_by(radians, velocity=5.0)
    rig.sleep(0.2)
    while j.state().moving:
        rig.sleep(0.05)
    rig.sleep(0.3)
    return j.read("actual_motor_position_left") - c0, rig.world.joint_position("left_wheel") - q0


@pytest.mark.parametrize("lines", [1024, 4096])
def test_a_config_silent_on_the_lines_counts_what_the_drive_is_set_to(lines: int) -> None:
    with joints.open(CONFIG) as rig:
        _set_drive_lines(rig, lines)
        counts, turned = _turn(rig, 2 * math.pi)
        assert rig.joints["left_wheel"].driver.counts_per_rev == 4 * lines
        assert abs(counts - 4 * lines) <= 2  # a 2 pi move changes the drive's count by 4 x lines
        assert turned == pytest.approx(2 * math.pi, abs=0.01)
        assert rig.joints["left_wheel"].driver.identity()["encoder_lines"] == lines


def test_a_config_that_contradicts_the_drive_is_refused_with_both_numbers() -> None:
    cfg = copy.deepcopy(CONFIG)
    cfg["joints"]["left_wheel"]["profile"] = {"encoder_lines": 1024}
    with joints.open(cfg) as rig:
        _set_drive_lines(rig, 4096)
        j = rig.joints["left_wheel"]
        with pytest.raises(ConfigError, match=r"encoder_lines = 1024 \(4096 counts/rev\).*4096 lines.*16384") as exc:
            j.enable()
        assert exc.value.key == "profile.encoder_lines"
        assert rig.world.joint_velocity("left_wheel") == 0.0  # nothing moved


def test_a_config_that_names_the_drives_lines_is_taken() -> None:
    cfg = copy.deepcopy(CONFIG)
    for side in ("left", "right"):
        cfg["joints"][f"{side}_wheel"]["profile"] = {"encoder_lines": 4096}  # the twin is built with 4096 too
    with joints.open(cfg) as rig:
        counts, turned = _turn(rig, math.pi)
        assert abs(counts - 8192) <= 2 and turned == pytest.approx(math.pi, abs=0.01)
