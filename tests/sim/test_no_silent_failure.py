"""No silent failure, in process on the twins: waiting keeps drives fed, faults surface by name,
limits hold on every path, concurrent callers cannot break the world, interrupted waits keep time."""

from __future__ import annotations

import math
import threading
from typing import Any

import pytest

pytest.importorskip("mujoco")

import joints
from joints.errors import DeviceFault, LimitError, UnknownJoint

RPM = 2 * math.pi / 60

EROB: dict[str, Any] = {
    "backend": "sim",
    "sim": {"model": "erob_stand.xml"},
    "buses": {"rs485": {"protocol": "modbus-rtu", "port": "/dev/ttyUSB0"}},
    "joints": {"joint1": {"device": "erob", "model": "eRob80H100", "bus": "rs485", "address": 2,
                          "limits": {"position": [-1.0, 1.0], "velocity": 2.0, "torque": 20.0}}},
}
ZLAC: dict[str, Any] = {
    "backend": "sim",
    "sim": {"model": "zlac_diffdrive.xml"},
    "buses": {"rs485": {"protocol": "modbus-rtu", "port": "/dev/ttyUSB0"}},
    "joints": {f"{side}_wheel": {"device": "zlac8015d", "bus": "rs485", "address": 1, "channel": side,
                                  "limits": {"velocity": 12.0}, "motion": {"acceleration": 20.0}}
               for side in ("left", "right")},
}


@pytest.fixture(autouse=True)
def _no_backend_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("JOINTS_BACKEND", raising=False)


# --- waiting is talking ---------------------------------------------------------------------------

def test_erob_keeps_turning_through_a_long_sleep_and_faults_by_name_without_keepalive() -> None:
    with joints.open(EROB) as rig:
        j = rig.joints["joint1"]
        j.enable()
        j.set_velocity(1.0)
        rig.sleep(10.0)  # ten times the 1000 ms watchdog armed while enabled
        s = j.state()
        assert s.fault is None and s.enabled and s.velocity == pytest.approx(1.0, rel=0.02)
        rig.keepalive = False  # on purpose: the host goes silent
        rig.sleep(3.0)
        rig.keepalive = True
        s = j.state()
        assert s.fault is not None and s.fault.name == "rs485_timeout" and not s.enabled
        with pytest.raises(DeviceFault, match=r"rs485_timeout \(0x0FA2\).*clear errors"):
            j.set_velocity(1.0)  # refused: the fault by name, and how to clear it
        j.clear_faults()
        j.enable()
        rig.sleep(0.6)
        j.set_velocity(0.5)
        rig.sleep(1.0)
        assert j.state().velocity == pytest.approx(0.5, rel=0.02)


def test_zlac_keeps_turning_through_a_long_sleep_and_reports_the_offline_stop_by_name() -> None:
    with joints.open(ZLAC) as rig:
        left, right = rig.joints["left_wheel"], rig.joints["right_wheel"]
        left.enable()
        right.enable()
        rig.set_velocities({"left_wheel": 100 * RPM, "right_wheel": 100 * RPM})
        rig.sleep(10.0)  # ten times the drive's 1000 ms offline time
        s = rig.read_states()
        assert all(v.fault is None and v.enabled for v in s.values())
        assert s["left_wheel"].velocity == pytest.approx(100 * RPM, rel=0.03)
        rig.keepalive = False
        rig.sleep(2.0)
        rig.keepalive = True
        s = rig.read_states()
        assert s["left_wheel"].fault is not None and s["left_wheel"].fault.name == "communication_offline"
        assert not s["left_wheel"].enabled and abs(s["left_wheel"].velocity) < 0.05  # quick-stopped
        with pytest.raises(DeviceFault, match="communication_offline"):
            left.set_velocity(1.0)
        left.clear_faults()
        left.enable()
        right.enable()  # the drive says it is off: enable() really enables it again
        rig.set_velocities({"left_wheel": 50 * RPM, "right_wheel": 50 * RPM})
        rig.sleep(1.0)
        assert rig.read_states()["right_wheel"].velocity == pytest.approx(50 * RPM, rel=0.03)


def test_joint_wait_keeps_the_other_drives_fed() -> None:
    cfg = {**EROB, "sim": {"model": "erob_arm3.xml"},
           "joints": {f"joint{i}": {"device": "erob", "bus": "rs485", "address": i,
                                    "limits": {"position": [-3.0, 3.0], "velocity": 2.0, "torque": 40.0}}
                      for i in (1, 2, 3)}}
    with joints.open(cfg) as rig:
        for j in rig.joints.values():
            j.enable()
        rig.joints["joint1"].move_to(2.5, velocity=0.5)  # a 5 s move: longer than any watchdog
        rig.joints["joint1"].wait(timeout=10.0)
        assert all(s.fault is None and s.enabled for s in rig.read_states().values())


# --- limits and names ------------------------------------------------------------------------------

def test_raw_target_writes_obey_the_joint_limits_and_the_drive_holds_them_too() -> None:
    with joints.open(EROB) as rig:
        j = rig.joints["joint1"]
        j.enable()
        rig.sleep(0.6)
        counts = 524288 / (2 * math.pi)
        with pytest.raises(LimitError, match=r"joint1.*3\.8.*\[-1\.0000, 1\.0000\]"):
            j.write("target_absolute_position", round(3.83 * counts))
        with pytest.raises(LimitError, match="exceeds the limit 2.0000 rad/s"):
            j.write("profile_speed", round(5.0 * counts))
        assert j.read("max_position_limit_value") == round(1.0 * counts)  # in the drive while enabled
        j.write("target_absolute_position", round(3.83 * counts) // 10 * 0 + round(0.9 * counts))
        j.write("start_operating", 1)
        rig.sleep(2.0)
        assert j.state().position == pytest.approx(0.9, abs=1e-3)


def test_unknown_joint_name_lists_the_known_ones() -> None:
    with joints.open(EROB) as rig:
        with pytest.raises(UnknownJoint, match=r"'nope'.*\['joint1'\]"):
            rig.joints["nope"]
        with pytest.raises(KeyError):  # still a KeyError for code that expects one
            rig.joints["nope"]


def test_readme_config_needs_no_mjcf_joint_and_a_wrong_one_lists_the_model_joints() -> None:
    with joints.open(EROB) as rig:  # no mjcf_joint: the joint's name is the MJCF joint
        assert rig.sim.joint("joint1").mjcf_joint == "joint1"
    bad = {**EROB, "joints": {"j": {**EROB["joints"]["joint1"], "mjcf_joint": "elbow"}}}
    with pytest.raises(joints.ConfigError, match=r"elbow.*allowed: 'joint1'"):
        joints.open(bad)


# --- one caller at a time ----------------------------------------------------------------------

def test_two_threads_sleeping_and_reading_share_one_world_safely() -> None:
    ideal = {**EROB, "buses": {"rs485": {**EROB["buses"]["rs485"], "timing": "ideal"}}}  # the sleeps' time only
    with joints.open(ideal) as rig:
        j = rig.joints["joint1"]
        j.enable()
        j.set_velocity(0.5)  # (after the manual's 500 ms from enable)
        t0 = rig.time
        errors: list[BaseException] = []
        times: list[float] = []

        def sleeper() -> None:
            try:
                for _ in range(500):
                    rig.sleep(0.01)
            except BaseException as exc:  # noqa: BLE001 - reported below
                errors.append(exc)

        def reader() -> None:
            try:
                for _ in range(1000):
                    times.append(j.state().time)
                    rig.sleep(0.005)
            except BaseException as exc:  # noqa: BLE001
                errors.append(exc)

        threads = [threading.Thread(target=sleeper), threading.Thread(target=reader)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert not errors
        # each thread slept 5 s in total: a sleep waits until its own end time, so with the two threads
        # interleaving the world advanced between 5 s (fully overlapped) and 10 s (one after the other)
        assert 5.0 - 0.002 <= rig.time - t0 <= 10.0 + 0.002
        assert times == sorted(times)  # time never ran backwards for a reader
        assert j.state().velocity == pytest.approx(0.5, rel=0.02)


def test_interrupted_sleep_leaves_the_clock_where_the_physics_is() -> None:
    with joints.open(EROB) as rig:
        world = rig.sim
        calls = {"n": 0}
        step = world._bind[0][0]

        def interrupting(t: float, dt: float, q: float, qd: float) -> float:
            calls["n"] += 1
            if calls["n"] == 1000:
                raise KeyboardInterrupt
            return step(t, dt, q, qd)

        world._bind[0] = (interrupting, *world._bind[0][1:])
        with pytest.raises(KeyboardInterrupt):
            rig.sleep(60.0)
        world._bind[0] = (step, *world._bind[0][1:])
        stopped = rig.time
        assert stopped == pytest.approx(0.999, abs=0.002)
        rig.sleep(0.01)
        assert rig.time == pytest.approx(stopped + 0.01, abs=0.0015)  # not a jump to 60 s


# --- leaving ---------------------------------------------------------------------------------------

def test_a_second_interrupt_during_close_leaves_nothing_enabled() -> None:
    cfg = {**EROB, "sim": {"model": "erob_arm3.xml"},
           "joints": {f"joint{i}": {"device": "erob", "bus": "rs485", "address": i} for i in (1, 2, 3)}}
    rig = joints.open(cfg)
    for j in rig.joints.values():
        j.enable()
    rig.sleep(0.6)
    for j in rig.joints.values():
        j.set_velocity(0.3)
    first = rig.joints["joint1"]
    real_stop = first.driver.stop

    def interrupted_stop() -> None:
        first.driver.stop = real_stop  # type: ignore[method-assign]
        raise KeyboardInterrupt  # the second Ctrl-C lands in the middle of close()

    first.driver.stop = interrupted_stop  # type: ignore[method-assign]
    with pytest.raises(KeyboardInterrupt):
        rig.close()
    assert rig.closed
    firmware = rig.sim.drives
    for name in ("joint1", "joint2", "joint3"):
        assert not firmware[name].enabled, name
    rig.close()  # again: nothing left to do, no error
