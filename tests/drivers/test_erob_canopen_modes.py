"""The eRob CANopen driver against the twin, lockstep, mode by mode (eRunner manual chapter 5): IP with the
interpolation objects 0x60C0-0x60C2, PT, CST, CSV; what a cyclic state carries (current where the bus has room,
temperature NaN); EMCY surfacing as DeviceFault by name; life guarding expiring; quick stop; fault reset."""

from __future__ import annotations

import math
from typing import Any

import pytest

pytest.importorskip("mujoco")

import joints
from joints.devices.cia402 import Mode
from joints.devices.erob.canopen import CYCLIC_TPDO1_CURRENT, ERUNNER_TPDOS
from joints.devices.erob.profiles import profile
from joints.drivers.erob_canopen import ErobCanopenDriver, SyncCycle
from joints.errors import DeviceFault
from joints.link.canopen import CanopenLink
from joints.sim import sensors
from joints.sim.erob import ErobFirmware
from joints.sim.erob_canopen import LIFE_GUARD_ERROR, CanopenFront, ErobCanopenBus
from joints.transports.can import PythonCanTransport
from joints.transports.can_sim import LockstepCanBus

PROFILE = profile("eRob80H100")


def one(mode: str | None = None, *, sync_period: float | None = None, **joint: Any) -> dict[str, Any]:
    j: dict[str, Any] = {"device": "erob", "model": "eRob80H100", "bus": "bus", "address": 2,
                         "limits": {"position": [-3.1, 3.1], "velocity": 2.0}, **joint}
    if mode is not None:
        j["mode"] = mode
    bus: dict[str, Any] = {"protocol": "canopen"}
    if sync_period is not None:
        bus["sync_period"] = sync_period
    return {"backend": "sim", "sim": {"model": "erob_stand.xml", "timestep": 0.001},
            "buses": {"bus": bus}, "joints": {"joint1": j}}


def min_jerk(x: float) -> float:
    x = min(max(x, 0.0), 1.0)
    return 10 * x**3 - 15 * x**4 + 6 * x**5


def front_of(rig: joints.Rig) -> CanopenFront:
    assert rig.world is not None
    front = rig.world.buses["bus"].front(2)
    assert front is not None
    return front  # type: ignore[no-any-return]


# --- modes ---------------------------------------------------------------------------------------


def test_ip_follows_a_smooth_move_over_the_interpolation_period() -> None:
    """IP at a 2 ms SYNC: 0x60C2 = 2 x 10^-3 s (0x60C0 linear), 0x60C1:01 streamed with controlword bit 4;
    the position follows within one period's travel, bit 12 (ip active) while enabled, bit 10 at the end."""
    period, duration, distance = 0.002, 1.5, 0.5
    with joints.open(one("ip", sync_period=period)) as rig:
        j = rig.joints["joint1"]
        j.enable()
        assert j.read("0x60C2:1") == 2 and j.read("0x60C2:2") == -3  # period value x 10^index s
        assert j.read("interpolation_sub_mode_select") == 0  # linear interpolation (CiA 402 default)
        assert j.read("communication_cycle_period") == 2000  # 0x1006 [us]
        p0 = j.state().position
        worst, worst_sent, words = 0.0, 0.0, set()
        t0 = rig.time
        for k in range(int(duration / period) + 150):
            s = (k + 1) * period
            target = p0 + distance * min_jerk(s / duration)
            state = rig.cycle({"joint1": target})["joint1"]
            words.add(state.raw.extra["statusword"] & 0x1400 if state.raw else 0)
            if 0.3 * duration < s < 0.7 * duration:
                in_force = p0 + distance * min_jerk((s - period) / duration)
                worst = max(worst, abs(state.position - in_force))
                worst_sent = max(worst_sent, abs(state.position - target))
        assert rig.time - t0 == pytest.approx(len(range(int(duration / period) + 150)) * period, rel=0.01)
        assert state.position == pytest.approx(p0 + distance, abs=math.radians(0.05))
        assert words >= {0x1000, 0x1400}  # ip active while moving; target reached too at the end
        assert math.degrees(worst) < 0.1 and math.degrees(worst_sent) < 0.2, (worst, worst_sent)
        assert front_of(rig).statusword() & 0x1000  # still interpolating (bit 4 held)


def test_pt_torque_drives_the_joint_and_stop_sets_target_torque_zero() -> None:
    """PT (fig 5-19/5-20): 0x6071 in per mille of rated torque; the state's torque is the drive's current
    0x6078 through the torque constant; stop = target torque 0."""
    with joints.open(one()) as rig:
        j = rig.joints["joint1"]
        j.enable()
        j.set_torque(10.0)
        assert j.driver.mode is Mode.PT
        rig.sleep(1.0)  # the brake releases in 0.5 s, then the torque acts
        fw = front_of(rig).firmware
        assert fw.values["target_torque"] == round(10.0 / PROFILE.rated_torque * 1000)  # 323 per mille
        s = j.state()
        assert s.torque == pytest.approx(10.0, rel=0.03) and s.current == pytest.approx(10.0 / 8.71, rel=0.03)
        assert s.velocity > 0.3 and s.moving
        j.stop()
        s = j.wait(timeout=5, poll=0.02, until=lambda st: abs(st.velocity) < 0.01)
        assert s.enabled and abs(s.torque) < 0.5 and fw.values["target_torque"] == 0


def test_cst_cycle_torque_accelerates_both_ways_and_the_state_reports_the_current() -> None:
    with joints.open(one("cst")) as rig:
        assert rig.world is not None
        sensors.ideal(rig.world)  # the current as the drive holds it (its measurement noise is ~2 % of this)
        j = rig.joints["joint1"]
        j.enable()
        assert j.driver.reports_current
        up = [rig.cycle({"joint1": 10.0})["joint1"] for _ in range(300)]
        down = [rig.cycle({"joint1": -10.0})["joint1"] for _ in range(300)]
        # viscous + Coulomb friction bound the speed: (10 - 4.5) / 9.57 rad/s
        assert up[-1].velocity == pytest.approx(5.5 / 9.57, rel=0.1) and down[-1].velocity < -0.4
        # speeding up all along (near the bound within the velocity's resolution: not slower)
        assert all(a.velocity <= b.velocity for a, b in zip(up[::25], up[25::25]))
        assert all(a.velocity < b.velocity for a, b in zip(up[:200:25], up[25:200:25]))
        assert up[-1].torque == pytest.approx(10.0, rel=0.03) and down[-1].torque == pytest.approx(-10.0, rel=0.03)
        fw = front_of(rig).firmware
        # the temperature as state() last read 0x22A2 (no SDO in the cycle): the Modbus 0x0078 value
        assert up[-1].raw is not None and up[-1].temperature == pytest.approx(fw.read("part_of_power_temperature"),
                                                                              abs=1.0)
        assert down[-1].raw is not None
        assert down[-1].current == pytest.approx(fw.read("motor_current") * 1e-3, abs=0.05)
        rig.cycle({"joint1": 0.0})
        rig.cycle({"joint1": 0.0})
        assert fw.values["target_torque"] == 0


def test_csv_cycle_velocity_ramps_with_the_profile_and_holds() -> None:
    with joints.open(one("csv")) as rig:
        j = rig.joints["joint1"]
        j.enable()
        run = [rig.cycle({"joint1": 1.0})["joint1"] for _ in range(1000)]
        assert run[-1].velocity == pytest.approx(1.0, abs=0.02)
        assert rig.world is not None and rig.world.joint_velocity("joint1") == pytest.approx(1.0, abs=0.01)
        # the steady current holds viscous + Coulomb friction: (9.57 + 4.5) N*m / 8.71 N*m/A
        assert run[-1].current == pytest.approx(14.07 / 8.71, rel=0.05)
        p = run[-1].position
        stop = [rig.cycle({"joint1": 0.0})["joint1"] for _ in range(600)]
        assert abs(stop[-1].velocity) < 0.01 and stop[-1].enabled
        assert 0.1 < stop[-1].position - p < 0.6  # decelerated on a ramp, not on the spot


# --- what a cyclic state carries -------------------------------------------------------------------


def bus_of_own(nodes: int, period: float = 0.001) -> tuple[list[ErobCanopenDriver], SyncCycle, ErobCanopenBus]:
    device = ErobCanopenBus()
    for n in range(1, nodes + 1):
        device.add(CanopenFront(ErobFirmware(PROFILE, n), n))
    link = CanopenLink(PythonCanTransport(LockstepCanBus(medium=device.medium)), clock=device.medium.clock,
                       bus_clock=True)
    cycle = SyncCycle(link, period)
    drivers = [ErobCanopenDriver(link, n, mode="csp", heartbeat_ms=0, cycle=cycle) for n in range(1, nodes + 1)]
    device.tick(0.001)
    for d in drivers:
        d.bring_up()
    link.poll(0.01)  # the bring-up's traffic is over
    return drivers, cycle, device


@pytest.mark.parametrize("nodes,period,current", [(3, 0.001, True), (4, 0.001, False), (4, 0.002, True)])
def test_cyclic_tpdo_carries_the_current_where_the_bus_has_room(nodes: int, period: float, current: bool) -> None:
    drivers, cycle, device = bus_of_own(nodes, period)
    assert all(d.feedback_tpdo() == (CYCLIC_TPDO1_CURRENT if current else ERUNNER_TPDOS[0]) for d in drivers)
    device.medium.reset_load()
    late = cycle.late
    for _ in range(100):
        cycle.send({d: d.position for d in drivers})
        states = cycle.collect()
    assert cycle.late == late  # no TPDO missed its cycle with the mapping chosen
    assert all(math.isnan(s.current) != current and math.isnan(s.temperature) for s in states.values())
    assert device.medium.load().load < 1.0


# --- faults, guarding, quick stop --------------------------------------------------------------------


def test_emcy_is_a_device_fault_by_name_and_fault_reset_clears_it() -> None:
    """A following error (0x6065 set small, then a fast move): the twin sends EMCY 0x8611 with the error
    register's generic bit; the joint raises DeviceFault with the code, its name and its text; clear_faults()
    resets it (EMCY 0x0000) and the joint moves again."""
    with joints.open(one()) as rig:
        j = rig.joints["joint1"]
        j.write("max_position_error", 50)  # 0x6065 following error window [count]
        j.enable()
        j.move_to(1.0, velocity=2.0, acceleration=40.0, deceleration=40.0)
        with pytest.raises(DeviceFault) as err:
            j.wait(timeout=5, poll=0.01)
        assert err.value.code == 0x8611 and err.value.name == "following_error"
        assert "following error" in str(err.value)
        driver = j.driver
        assert isinstance(driver, ErobCanopenDriver)
        emcy = [e for e in driver.emcys if e.error_code == 0x8611]
        assert emcy and emcy[-1].error_register & 0x01 and emcy[-1].node == 2
        s = j.state()
        assert s.fault is not None and s.fault.name == "following_error" and not s.enabled
        j.clear_faults()
        assert j.state().fault is None
        assert driver.emcys[-1].error_code == 0x0000  # "error reset / no error"
        j.write("max_position_error", 100000)
        j.enable()
        j.move_to(0.3, velocity=1.0)
        assert j.wait(timeout=10, poll=0.02).position == pytest.approx(0.3, abs=math.radians(0.1))


def test_life_guarding_expires_when_the_host_goes_silent() -> None:
    """Enabled, the joint's watchdog is life guarding (1000 ms = 250 ms x 4): the host guards at every state read.
    Silent for longer (the world runs without host traffic), the node trips EMCY 0x8130 and FAULT: reported by
    name; a fault reset and enable bring it back."""
    with joints.open(one()) as rig:
        j = rig.joints["joint1"]
        j.enable()
        assert j.read("guard_time") == 250 and j.read("life_time_factor") == 4
        assert j.read("producer_heartbeat_time") == 0  # heartbeat off while guarding (CiA 301)
        rig.sleep(2.0)  # the rig keeps the node guarded while it sleeps
        assert j.state().fault is None
        assert rig.world is not None
        front = front_of(rig)
        silent_from = rig.time
        rig.world.advance(1.2)  # no host frame at all
        assert front.fault_code == LIFE_GUARD_ERROR and not front.firmware.enabled
        trip = [e for e in front.emcy_sent if e.error_code == LIFE_GUARD_ERROR]
        assert trip
        s = j.state()
        assert s.fault is not None and s.fault.name == "life_guard_error" and not s.enabled
        with pytest.raises(DeviceFault) as err:
            j.check()
        assert err.value.code == LIFE_GUARD_ERROR and "life guarding" in str(err.value)
        assert rig.time - silent_from > 1.0
        j.clear_faults()
        j.enable()
        j.move_to(0.2, velocity=1.0)
        assert j.wait(timeout=10, poll=0.02).position == pytest.approx(0.2, abs=math.radians(0.1))


def test_quick_stop_halts_within_the_emergency_stop_time_and_leaves_the_drive_off() -> None:
    with joints.open(one()) as rig:
        j = rig.joints["joint1"]
        j.enable()
        j.set_velocity(1.5, acceleration=6.0)
        j.wait(timeout=5, poll=0.02, until=lambda s: abs(s.velocity - 1.5) < 0.02)
        assert rig.world is not None
        front = front_of(rig)
        t0 = rig.time
        j.emergency_stop()
        while abs(rig.world.joint_velocity("joint1")) > 0.01:
            assert rig.time - t0 < 0.2, "still turning 200 ms after the quick stop"
            rig.world.step()
        stopped_in = rig.time - t0
        rig.sleep(0.05)
        assert front.state.name == "SWITCH_ON_DISABLED"  # quick stop option code 2: then switch on disabled
        s = j.state()
        assert not s.enabled and s.fault is None
        assert stopped_in < 0.06, stopped_in  # eRob: < 50 ms (+ one frame and a physics step)
        j.enable()
        j.move_to(0.0, velocity=1.0)
        assert j.wait(timeout=10, poll=0.02).position == pytest.approx(0.0, abs=math.radians(0.1))


def test_fault_reset_is_a_rising_controlword_bit_7() -> None:
    """The driver's clear_errors sends 0x0000, 0x0080, 0x0000 in RPDO1 (a rising edge whatever came before)."""
    with joints.open(one()) as rig:
        j = rig.joints["joint1"]
        j.enable()
        sent: list[bytes] = []
        rig.trace(lambda r: sent.append(r.data) if r.direction == "tx" and r.meaning.startswith("PDO 0x202") else None)
        j.clear_faults()
        rig.trace(None)
        words = [int.from_bytes(d[:2], "little") for d in sent]
        assert words[:3] == [0x0000, 0x0080, 0x0000]
