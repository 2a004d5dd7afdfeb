"""Mixed rigs (issue 24): per-bus ``backend``; real joints' measurements drive their MuJoCo joints while the
simulated joints are dynamic; ``joints/ErobArmReach-v0`` runs on a rig whose base bus is "hardware" (a
``joints sim serve`` over a pty) and whose arm bus is in process."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from joints.config import parse
from joints.errors import ConfigError, JointsError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[2]
ARM = ROOT / "joints" / "configs" / "erob_arm_reach.toml"


def mixed(port: str = "/dev/null") -> dict[str, Any]:
    """The shipped arm config split in two buses: ``base`` (joint1, hardware) and ``arm`` (joint2/3, sim)."""
    data: dict[str, Any] = tomllib.loads(ARM.read_text())
    rs485 = data["buses"].pop("rs485")
    data["buses"] = {"base": {**rs485, "port": port, "timeout": 0.5, "backend": "hardware"},
                     "arm": {"protocol": "modbus-rtu"}}
    data["joints"]["joint1"]["bus"] = "base"
    for j in ("joint2", "joint3"):
        data["joints"][j]["bus"] = "arm"
    return data


@pytest.fixture
def no_env(monkeypatch: pytest.MonkeyPatch) -> Iterator[pytest.MonkeyPatch]:
    monkeypatch.delenv("JOINTS_BACKEND", raising=False)
    yield monkeypatch


def test_bus_backend_wins_over_the_file_and_the_switch_forces_every_bus(no_env: pytest.MonkeyPatch) -> None:
    cfg = parse(mixed())
    assert cfg.backend == "mixed"
    assert cfg.bus_backend("base") == "hardware" and cfg.bus_backend("arm") == "sim"
    data = mixed()
    data["backend"] = "hardware"
    data["buses"]["arm"]["port"] = "/dev/ttyUSB1"
    data["buses"]["base"]["backend"] = "sim"
    cfg = parse(data)
    assert cfg.backend == "mixed" and cfg.bus_backend("base") == "sim" and cfg.bus_backend("arm") == "hardware"
    assert parse(mixed(), backend="sim").backend == "sim"
    assert {b.backend for b in parse(data, backend="hardware").buses.values()} == {"hardware"}
    no_env.setenv("JOINTS_BACKEND", "sim")
    assert {b.backend for b in parse(mixed()).buses.values()} == {"sim"}
    no_env.delenv("JOINTS_BACKEND")
    assert cfg.with_backend("sim").backend == "sim"


def test_a_hardware_bus_needs_its_port_and_a_bad_backend_is_named(no_env: pytest.MonkeyPatch) -> None:
    data = mixed()
    del data["buses"]["base"]["port"]
    with pytest.raises(ConfigError, match=r"buses\.base\.port"):
        parse(data)
    data = mixed()
    data["buses"]["arm"]["backend"] = "real"
    with pytest.raises(ConfigError, match=r"buses\.arm\.backend.*'real'") as e:
        parse(data)
    assert e.value.allowed == ("sim", "hardware")


def test_measured_joints_follow_their_measurements_and_the_simulated_ones_feel_them(no_env: Any) -> None:
    pytest.importorskip("mujoco")
    from joints.rig import sim_world
    from joints.sim.world import KINEMATIC_HORIZON

    world = sim_world(parse(mixed()))
    assert set(world.kinematic) == {"joint1"} and set(world.joints) == {"joint2", "joint3"}
    qa, da = world.kinematic["joint1"]
    world.set_measured("joint1", 0.5, 2.0, world.time)
    world.advance(0.01)
    assert world.data.qpos[qa] == pytest.approx(0.5 + 2.0 * 0.01, abs=1e-12)  # extrapolated at its velocity
    assert world.data.qvel[da] == 2.0
    world.advance(1.0)  # no new measurement: held at the horizon, at rest
    assert world.data.qpos[qa] == pytest.approx(0.5 + 2.0 * KINEMATIC_HORIZON, abs=1e-12)
    assert world.data.qvel[da] == 0.0
    with pytest.raises(KeyError):
        world.set_measured("joint2", 0.0, 0.0, 0.0)
    # the simulated arm (brakes released: drives off would hold it) feels a spinning base: the
    # centrifugal pull lifts the free shoulder against gravity
    world2 = sim_world(parse(mixed()))
    for name in ("joint2", "joint3"):
        world2.drives[name].brake_released = True
    world2.set_joint_positions({"joint2": -0.5, "joint3": 1.0})
    still = sim_world(parse(mixed()))
    for name in ("joint2", "joint3"):
        still.drives[name].brake_released = True
    still.set_joint_positions({"joint2": -0.5, "joint3": 1.0})
    for k in range(200):
        t = world2.time
        world2.set_measured("joint1", 6.0 * t, 6.0, t)
        world2.advance(0.001)
        still.set_measured("joint1", 0.0, 0.0, still.time)
        still.advance(0.001)
    assert world2.joint_position("joint1") == pytest.approx(6.0 * 0.2, abs=0.01)
    lifted = world2.joint_position("joint2") - still.joint_position("joint2")
    assert lifted > 0.02, lifted


def test_reset_is_refused_on_a_mixed_rig() -> None:
    pytest.importorskip("mujoco")
    import joints
    from joints.rig import Rig

    world = joints.rig.sim_world(parse(mixed()))
    rig = Rig(parse(mixed()), clock=world.clock, buses={}, joints={}, world=world)
    try:
        with pytest.raises(JointsError, match="mixed rig"):
            rig.reset()
    finally:
        rig.close()


@pytest.fixture
def served_base(tmp_path: Path, sim_server: Any, no_env: Any) -> Iterator[str]:
    """``joints sim serve`` of the mixed config (forced to sim: every bus a pty); yields the base bus's pty."""
    pytest.importorskip("serial")
    pytest.importorskip("mujoco")
    served = tmp_path / "served.toml"
    data = mixed()
    lines = ["backend = \"sim\"", "[sim]", f"model = \"{data['sim']['model']}\"", "timestep = 0.001"]
    for name, b in data["buses"].items():
        lines += [f"[buses.{name}]", f"protocol = \"{b['protocol']}\""]
    for name, j in data["joints"].items():
        lines += [f"[joints.{name}]", f"device = \"{j['device']}\"", f"model = \"{j['model']}\"",
                  f"bus = \"{j['bus']}\"", f"address = {j['address']}"]
    served.write_text("\n".join(lines) + "\n")
    with sim_server(served, bus="base") as port:
        yield port


def test_erob_arm_reach_runs_on_a_mixed_rig(served_base: str) -> None:
    gym = pytest.importorskip("gymnasium")
    np = pytest.importorskip("numpy")
    import envs  # noqa: F401 - registers the ids

    env = gym.make("joints/ErobArmReach-v0", config=mixed(served_base))
    try:
        u = env.unwrapped
        rig = u.rig
        assert rig.backend == "mixed" and rig.world is not None and not u.sim
        assert type(rig.buses["base"].transport).__name__ == "SerialTransport"
        obs, info = env.reset(seed=3, options={"start": [0.4, -0.3, 0.5]})
        assert np.allclose(obs[:3], [0.4, -0.3, 0.5], atol=0.03)
        world = rig.world
        # the measured base joint stands where the served ("real") drive says; the arm is simulated
        assert world.joint_position("joint1") == pytest.approx(float(obs[0]), abs=0.02)
        action = u.action_of([0.6, -0.2, 0.7])  # one goal per joint, held (the drives' own profiles get there)
        for _ in range(40):
            obs, _reward, terminated, _truncated, info = env.step(action)
            assert not any(info["faults"].values()), info["faults"]
            assert not terminated
        state = rig.joints["joint1"].state()
        rig.sleep(0.02)  # the world catches up and takes the last measurement
        assert world.joint_position("joint1") == pytest.approx(state.position, abs=0.05)
        for j in ("joint2", "joint3"):
            assert world.joint_position(j) == pytest.approx(rig.joints[j].state().position, abs=1e-3)
        assert info["time"] > 0.7
        assert np.allclose(obs[:3], [0.6, -0.2, 0.7], atol=0.05)  # real and simulated joints got there
    finally:
        env.close()


def test_measured_joints_are_prescribed_during_a_substep(no_env: Any) -> None:
    """A spinning base (measured) with the free arm lifting: no force of the model accelerates the base within a
    substep (it is prescribed), where a free base would be sped up by the arm (1.5 rad/s^2 here)."""
    pytest.importorskip("mujoco")
    from joints.rig import sim_world

    world = sim_world(parse(mixed()))
    _qa, da = world.kinematic["joint1"]
    for name in ("joint2", "joint3"):
        world.drives[name].brake_released = True
    world.set_joint_positions({"joint2": -0.5, "joint3": 1.0})
    worst = 0.0
    for _ in range(100):
        t = world.time
        world.set_measured("joint1", 6.0 * t, 6.0, t)
        world.advance(0.001)
        worst = max(worst, abs(float(world.data.qacc[da])))
    assert worst < 1e-6, worst
    world.restore()  # perturbations come back to the prescribed joint, not to a free one
    assert world.model.dof_armature[da] == world._nominal["armature"][da] > 1e6


def test_mixed_clock_warns_when_physics_falls_behind(monkeypatch: pytest.MonkeyPatch,
                                                     caplog: pytest.LogCaptureFixture) -> None:
    """A world whose physics takes twice real time: the lag after each catch-up grows; warned once."""
    from joints.sim import pacing

    wall = [100.0]
    monkeypatch.setattr(pacing.time, "monotonic", lambda: wall[0])

    class SlowWorld:
        time = 0.0

        def advance(self, seconds: float) -> None:
            self.time += seconds
            wall[0] += 2 * seconds  # physics at half real time

    world = SlowWorld()
    clock = pacing.MixedClock(world)
    wall[0] += 0.01
    with caplog.at_level("WARNING", logger="joints"):
        for _ in range(8):
            clock.now()
    assert clock.max_lag > 0.05
    assert [r.message for r in caplog.records if "behind real time" in r.message][:1] and sum(
        "behind real time" in r.message for r in caplog.records) == 1


def test_a_mixed_rig_whose_loop_never_sleeps_sees_its_simulated_joints_move(served_base: str) -> None:
    import time

    import joints

    with joints.open(mixed(served_base)) as rig:
        assert rig.backend == "mixed"
        arm = rig.joints["joint2"]
        arm.enable()
        before = rig.read_states()["joint2"].position
        arm.move_to(before + 0.3, velocity=1.0, acceleration=5.0, deceleration=5.0)
        t0 = time.monotonic()
        n = 0
        while time.monotonic() - t0 < 1.0:  # talk, never sleep: the real base and the simulated arm
            states = rig.read_states()
            n += 1
        assert n > 5
        assert states["joint2"].position == pytest.approx(before + 0.3, abs=0.05)
        assert rig.world.joint_position("joint2") == pytest.approx(before + 0.3, abs=0.05)
