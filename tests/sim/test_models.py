"""Shipped MJCF models: they load, name the documented joints, and are packaged for installs."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest

mujoco = pytest.importorskip("mujoco")

from joints.errors import ConfigError
from joints.sim.world import resolve_model

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("name,joints", [("erob_stand.xml", ["joint1"]), ("erob_arm3.xml", ["joint1", "joint2", "joint3"]),
                                        ("zlac_diffdrive.xml", ["chassis", "left_wheel", "right_wheel"])])
def test_model_loads_with_documented_joints(name: str, joints: list[str]) -> None:
    m = mujoco.MjModel.from_xml_path(str(resolve_model(name)))
    assert [m.joint(i).name for i in range(m.njnt)][-len(joints):] == joints
    assert m.nu == 0, "actuators come from the device profile, not the XML"


def test_stand_axis_is_vertical_so_gravity_exerts_no_torque() -> None:
    m = mujoco.MjModel.from_xml_path(str(resolve_model("erob_stand.xml")))
    d = mujoco.MjData(m)
    for q in (0.0, 1.0, 2.5):
        d.qpos[0] = q
        mujoco.mj_forward(m, d)
        assert abs(d.qfrc_bias[0]) < 1e-9


def test_pendulum_stand_has_the_documented_gravity_torque() -> None:
    """models/erob_pendulum.xml (identification stand): horizontal axis, G(q) = 16.9 N*m sin(q), no actuator."""
    m = mujoco.MjModel.from_xml_path(str(resolve_model("erob_pendulum.xml")))
    d = mujoco.MjData(m)
    assert m.nu == 0 and m.njnt == 1
    for q in (0.3, -0.8, 1.2):
        d.qpos[0] = q
        mujoco.mj_forward(m, d)
        assert d.qfrc_bias[0] == pytest.approx((0.6 * 0.2 + 4.0 * 0.4) * 9.81 * math.sin(q), rel=1e-3)


def test_arm_feels_gravity() -> None:
    m = mujoco.MjModel.from_xml_path(str(resolve_model("erob_arm3.xml")))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    assert abs(d.qfrc_bias[1]) > 1.0  # shoulder holds the horizontal arm


def test_unknown_model_error_lists_shipped_models() -> None:
    with pytest.raises(ConfigError) as e:
        resolve_model("nope.xml")
    assert "erob_stand.xml" in str(e.value) and "sim.model" in str(e.value)


def test_models_are_package_data() -> None:
    if sys.version_info < (3, 11):
        pytest.skip("tomllib")
    import tomllib

    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert cfg["package-dir"]["joints.models"] == "models"
    assert "joints.models" in cfg["packages"]
    assert "*.xml" in cfg["package-data"]["joints.models"]
    # every package directory under joints/ is listed (a missing one would be absent from a wheel)
    pkgs = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "joints").rglob("__init__.py")}
    assert pkgs <= set(cfg["packages"]), pkgs - set(cfg["packages"])
