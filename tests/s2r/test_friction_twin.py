"""The eRob twin's friction beyond Coulomb + viscous (issue 30: what `joints identify` fits, the twin must use):
Stribeck friction and friction growing with the motor's and the external torque, from the profile; 0 by
default (then the twin is the Coulomb + viscous one). The world sets MuJoCo's friction loss after every
substep, from the state it ended with."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest

pytest.importorskip("mujoco")
np = pytest.importorskip("numpy")

import joints

sys.path.insert(0, str(Path(__file__).resolve().parent))
from reality import NOMINAL, config

FRICTION = {"stribeck_friction": 4.0, "stribeck_velocity": 1.5, "stribeck_exponent": 3.0, "load_friction": 0.05,
            "load_friction_quadratic": 0.002, "external_friction": 0.03}


def run(rig: joints.Rig, torques: list[float]) -> list[tuple[float, float, float]]:
    j = rig.joints["joint1"]
    j.enable()
    rig.sleep(0.6)
    out = []
    for tau in torques:
        j.set_torque(tau)
        rig.sleep(0.01)
        dof = rig.sim.joint("joint1").dof
        out.append((rig.sim.joint_position("joint1"), rig.sim.joint_velocity("joint1"),
                    float(rig.sim.model.dof_frictionloss[dof])))
    return out


TORQUES = [30.0 * math.sin(0.05 * k) for k in range(150)]


def test_state_friction_is_the_profiles_and_the_same_compiled_or_not(monkeypatch: pytest.MonkeyPatch) -> None:
    runs = {}
    for compiled in ("0", "1"):
        monkeypatch.setenv("JOINTS_COMPILED", compiled)
        with joints.open(config(profile=FRICTION)) as rig:
            runs[compiled] = run(rig, TORQUES)
            m, d, dof = rig.sim.model, rig.sim.data, rig.sim.joint("joint1").dof
            aid = rig.sim.joint("joint1").actuator
            v, tau, ext = float(d.qvel[dof]), abs(float(d.actuator_force[aid])), abs(float(d.qfrc_bias[dof]))
            want = (NOMINAL.coulomb_friction + 4.0 * math.exp(-abs(v / 1.5) ** 3) + 0.05 * tau + 0.002 * tau * tau
                    + 0.03 * ext)
            assert float(m.dof_frictionloss[dof]) == pytest.approx(want, rel=1e-12)
    assert runs["0"] == runs["1"]  # compiled or Python kernels: the same bits
    q = np.array([r[0] for r in runs["1"]])
    loss = np.array([r[2] for r in runs["1"]])
    assert np.ptp(q) > 0.3  # it moves
    assert loss.max() > NOMINAL.coulomb_friction + 4.0 and np.ptp(loss) > 1.0  # it follows the state
    with joints.open(config()) as plain:
        base = run(plain, TORQUES)
        assert not plain.sim._state_friction  # the default profile adds nothing per substep
    assert {r[2] for r in base} == {NOMINAL.coulomb_friction}
    assert np.abs(np.array([r[0] for r in base]) - q).max() > 0.05  # the friction changes the motion


def test_perturb_scales_the_coulomb_part_and_restore_undoes_it() -> None:
    with joints.open(config(profile={"stribeck_friction": 2.0})) as rig:
        dof = rig.sim.joint("joint1").dof
        rig.sim.perturb("joint1", coulomb_friction=2.0)
        rig.sim.step(1)
        assert rig.sim.model.dof_frictionloss[dof] == pytest.approx(2 * NOMINAL.coulomb_friction + 2.0)
        rig.sim.restore()
        rig.sim.step(1)
        assert rig.sim.model.dof_frictionloss[dof] == pytest.approx(NOMINAL.coulomb_friction + 2.0)


