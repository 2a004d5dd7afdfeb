"""The MKS commands of firmware V1.0.6-V1.0.9, driver -> twin -> a state change observed, on both protocols
(native RS485 and Modbus) where the manuals give both, over every firmware profile that has the command; an
older profile refuses the call before anything is sent, naming the firmware that has it."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("mujoco")

from mkskit import open_motor

from joints.devices.mks.state import MotorStatus
from joints.devices.quirks import MKS_FIRMWARES, firmware_profile
from joints.errors import CommandError, ConfirmationRequired, RegisterError
from joints.sim.mks import MksFirmware

PROTOCOLS = ("mks-serial", "modbus-rtu")


def _having(feature: str) -> list[str]:
    return [f for f in MKS_FIRMWARES if feature in firmware_profile("mks", f).features]


def _lacking(feature: str) -> list[str]:
    return [f for f in MKS_FIRMWARES if feature not in firmware_profile("mks", f).features]


def _twin(rig) -> MksFirmware:  # type: ignore[no-untyped-def]
    fw = rig.world.drives["m1"]
    assert isinstance(fw, MksFirmware)
    return fw


def _block(world: Any, damping: float = 1e4) -> float:
    """Block the motor's shaft with a damping no motor torque can turn (or set it back); the one before."""
    dof = world.joint("m1").dof
    before = float(world.model.dof_damping[dof])
    world.model.dof_damping[dof] = damping
    return before


# -- 0x36 write the IO port ---------------------------------------------------------------------------


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _having("mks-write-io"))
def test_write_io_sets_the_outputs_the_io_status_reads(tmp_path: Path, protocol: str, firmware: str) -> None:
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware}) as rig:
        d = rig.joints["m1"].driver
        assert d.read("io_status") & 0x0C == 0  # a 42D: no output driven at power-on
        d.write_io(out2=1)
        assert d.read("io_status") & 0x0C == 0x08  # OUT_2 (bit3) high, OUT_1 untouched
        d.write_io(out1=1)
        assert d.read("io_status") & 0x0C == 0x0C  # OUT_2 kept (mask 0: not written)
        d.write_io(out1=0, out2=0)
        assert d.read("io_status") & 0x0C == 0
        assert _twin(rig).outputs == {1: 0, 2: 0}


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _lacking("mks-write-io"))
def test_write_io_needs_v106(tmp_path: Path, protocol: str, firmware: str) -> None:
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware}) as rig:
        d = rig.joints["m1"].driver
        sent = d.link.transactions
        with pytest.raises(RegisterError, match="v1.0.6"):
            d.write_io(out1=1)
        assert d.link.transactions == sent  # nothing was sent


# -- 0x9D position-error protection ------------------------------------------------------------------


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _having("mks-position-error-protection"))
def test_position_error_protection_trips_after_its_window_and_0x3d_releases_it(tmp_path: Path, protocol: str,
                                                                                firmware: str) -> None:
    """0x9D with Tim = 10 (150 ms) and Errors = 7000 (90 degrees); the locked-rotor protection (0x88) stays off.
    A blocked shaft under a 200 rpm speed command: the drive protects 150 ms after the error passed 90 degrees."""
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        fw = _twin(rig)
        d.set_position_error_protection(True, window=0.15, error=math.pi / 2)
        assert (fw.values["position_error_protection"], fw.values["position_error_time"],
                fw.values["position_error_count"]) == (1, 10, 7000)
        j.enable()
        free = _block(rig.world)  # blocked before it moves (a sudden block of a turning rotor upsets MuJoCo)
        d.set_velocity(200, acceleration=0)
        big_at = tripped_at = None
        for _ in range(300):  # the twin's own state every 1 ms (bus reads would blur the timing)
            rig.clock.sleep(0.001)
            if big_at is None and abs(fw.r - fw.q) > math.pi / 2:
                big_at = rig.time
            if fw.protected:
                tripped_at = rig.time
                break
        assert big_at is not None and tripped_at is not None
        assert tripped_at - big_at == pytest.approx(0.15, abs=0.003)
        assert fw.protection_cause == "position-error" and not fw.values["locked_rotor_protection"]
        assert d.protection_state()  # 0x3E reports it
        s = j.state()
        assert s.fault is not None and not s.enabled and d.motor_status() is MotorStatus.STOP
        _block(rig.world, free)
        j.clear_faults()  # 0x3D
        assert not d.protection_state() and j.state().enabled


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_position_error_protection_off_never_trips(tmp_path: Path, protocol: str) -> None:
    with open_motor(tmp_path, protocol=protocol, joint={"watchdog_ms": 0}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        fw = _twin(rig)
        d.set_position_error_protection(False, window=0.15, error=math.pi / 2)
        j.enable()
        _block(rig.world)
        d.set_velocity(200, acceleration=0)
        rig.sleep(0.6)
        assert abs(fw.r - fw.q) > math.pi / 2 and not d.protection_state()


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_en_triggered_zero_return_needs_confirm(tmp_path: Path, protocol: str) -> None:
    with open_motor(tmp_path, protocol=protocol) as rig:
        d = rig.joints["m1"].driver
        sent = d.link.transactions
        with pytest.raises(ConfirmationRequired):
            d.set_position_error_protection(False, en_zero_return=True)
        assert d.link.transactions == sent
        d.set_position_error_protection(False, en_zero_return=True, confirm=True)
        assert _twin(rig).values["en_trigger_zero_return"] == 1


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _lacking("mks-position-error-protection"))
def test_position_error_protection_needs_v106(tmp_path: Path, protocol: str, firmware: str) -> None:
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware}) as rig:
        d = rig.joints["m1"].driver
        sent = d.link.transactions
        with pytest.raises(RegisterError, match="v1.0.6"):
            d.set_position_error_protection(True)
        assert d.link.transactions == sent


# -- 0x95 position-reached threshold (V1.0.8, native only) -------------------------------------------


def _held_off_move(rig, threshold: float | None | str) -> tuple[float, bool]:  # type: ignore[no-untyped-def]
    """A 3-degree move of a blocked shaft (error 546/65536 turn after the reference arrives); the time the
    reference arrived and whether the move completed within a second after it."""
    j = rig.joints["m1"]
    d = j.driver
    fw = _twin(rig)
    if threshold != "default":
        d.set_position_threshold(threshold)  # type: ignore[arg-type]
    j.enable()
    _block(rig.world)
    d.move_by(round(16384 * 3 / 360), speed=60)
    for _ in range(5000):  # (bounded: a broken twin fails, it does not hang)
        if fw.motion is None or fw.motion.arrived >= 0:
            break
        rig.clock.sleep(0.001)
    arrived = rig.time
    assert fw.motion is not None and abs(fw.r - fw.q) > math.radians(2.9)
    rig.clock.sleep(1.0)
    return arrived, d.motor_status() is MotorStatus.STOP


@pytest.mark.parametrize("firmware", _having("mks-position-threshold"))
@pytest.mark.parametrize(("threshold", "completes"), [("default", False), (math.radians(5), True), (None, True)])
def test_position_threshold_holds_the_completion_while_the_error_is_larger(tmp_path: Path, firmware: str,
                                                                          threshold: float | None | str,
                                                                          completes: bool) -> None:
    """Default 200 (1.1 degrees): a shaft held 3 degrees off never completes; a 5-degree threshold or the check
    off: it completes after the settle timeout, as before V1.0.8."""
    with open_motor(tmp_path, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        fw = _twin(rig)
        _arrived, done = _held_off_move(rig, threshold)
        assert done is completes
        if threshold == math.radians(5):
            assert (fw.values["position_threshold_enable"], fw.values["position_threshold"]) == (1, 910)
        if threshold is None:
            assert fw.values["position_threshold_enable"] == 0


@pytest.mark.parametrize("firmware", _lacking("mks-position-threshold"))
def test_position_threshold_needs_v109_and_older_drives_complete_after_the_settle_time(tmp_path: Path,
                                                                                      firmware: str) -> None:
    with open_motor(tmp_path, joint={"firmware": firmware}) as rig:
        d = rig.joints["m1"].driver
        sent = d.link.transactions
        with pytest.raises(RegisterError, match="v1.0.9"):
            d.set_position_threshold(0.1)
        assert d.link.transactions == sent
        _arrived, done = _held_off_move(rig, "default")
        assert done


def test_position_threshold_is_native_only(tmp_path: Path) -> None:
    with open_motor(tmp_path, protocol="modbus-rtu") as rig, pytest.raises(RegisterError, match="native"):
        rig.joints["m1"].driver.set_position_threshold(0.1)


# -- 0x4A / 0x4B multi-motor synchronous control (V1.0.8, native only) ---------------------------------


@pytest.mark.parametrize("firmware", _having("mks-sync"))
def test_sync_holds_each_run_command_until_0x4b_starts_them_together(tmp_path: Path, firmware: str) -> None:
    """12.4.3: motor 1 in speed mode, motor 2 a relative move; with 0x4A on each answers status 5 and waits;
    one broadcast 0x4B starts both in the same instant."""
    from joints.codecs import mks

    with open_motor(tmp_path, n=2, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        j1, j2 = rig.joints["m1"], rig.joints["m2"]
        d1, d2 = j1.driver, j2.driver
        f1, f2 = rig.world.drives["m1"], rig.world.drives["m2"]
        for j in (j1, j2):
            j.enable()
            j.driver.set_sync(True)
        d1.set_velocity(60)
        assert d1.access.last_reply == mks.RunReply(1, 0xF6, mks.RunStatus.SYNC_RECEIVED)
        d2.move_by(16384, speed=120)
        assert d2.access.last_reply == mks.RunReply(2, 0xF4, mks.RunStatus.SYNC_RECEIVED)
        q1, q2 = d1.read("encoder_addition"), d2.read("encoder_addition")
        rig.sleep(0.3)
        assert (d1.read("encoder_addition"), d2.read("encoder_addition")) == (q1, q2)  # held, not moving
        assert f1.motion is None and f2.motion is None
        d1.sync_execute([d2])  # one broadcast frame, nobody answers
        rig.sleep(0.01)  # (the frame's wire time)
        assert f1.sync_started_at == f2.sync_started_at >= 0  # the same instant
        rig.sleep(1.5)
        assert d1.read("real_time_speed") == pytest.approx(60, abs=2)
        assert abs(d2.read("encoder_addition") - q2 - 16384) <= 2  # the move ran to its end
        d1.sync_execute()  # nothing held: nothing starts
        assert f2.motion is None
        j1.stop()  # a stop acts at once, also with 0x4A on
        rig.sleep(0.5)
        assert abs(d1.read("real_time_speed")) <= 1


@pytest.mark.parametrize("firmware", _lacking("mks-sync"))
def test_sync_needs_v109(tmp_path: Path, firmware: str) -> None:
    with open_motor(tmp_path, joint={"firmware": firmware}) as rig:
        d = rig.joints["m1"].driver
        sent = d.link.transactions
        with pytest.raises(RegisterError, match="v1.0.9"):
            d.set_sync(True)
        with pytest.raises(RegisterError, match="v1.0.9"):
            d.sync_execute()
        assert d.link.transactions == sent


# -- 0xF6 with a run time (V1.0.7) ---------------------------------------------------------------------


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _having("mks-timed-speed"))
def test_speed_mode_with_a_run_time_stops_by_itself(tmp_path: Path, protocol: str, firmware: str) -> None:
    """60 rpm for 0.5 s with acc 0: the drive stops at once 0.5 s after the command arrived; a later command
    without a run time runs on (the last run time does not ride along)."""
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        fw = _twin(rig)
        j.enable()
        d.set_velocity(60, acceleration=0, run_time=0.5)
        assert fw.motion is not None
        until = fw.motion.until
        assert fw.values["speed_mode_run_time"] == 50
        rig.sleep(0.3)
        assert d.read("real_time_speed") == pytest.approx(60, abs=2)
        for _ in range(5000):  # (bounded: a broken twin fails, it does not hang)
            if fw.motion is None:
                break
            rig.clock.sleep(0.001)
        # stopped when its run time was over, not before (the host's exact clock may stand up to one 1 ms
        # substep behind the physics that stopped it)
        assert until - 0.001 <= rig.time <= until + 0.002
        rig.sleep(0.3)
        assert d.read("real_time_speed") == 0 and d.motor_status() is MotorStatus.STOP
        d.set_velocity(60, acceleration=0)
        rig.sleep(1.0)
        assert d.read("real_time_speed") == pytest.approx(60, abs=2)  # untimed: still running
        j.stop()


def test_speed_mode_run_time_decelerates_with_the_commands_acc_and_completes(tmp_path: Path) -> None:
    """Native, active on: the timed stop ends with the "run complete" frame (status 2), like a stop command."""
    from joints.codecs import mks

    with open_motor(tmp_path, joint={"watchdog_ms": 0}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        fw = _twin(rig)
        j.enable()
        d.set_velocity(300, acceleration=1000, run_time=0.5)  # 1000 rpm/s: 0.3 s up, 0.3 s down
        until = fw.motion.until  # type: ignore[union-attr]
        for _ in range(5000):  # (bounded: a broken twin fails, it does not hang)
            if fw.motion is None:
                break
            rig.clock.sleep(0.001)
        assert rig.time - until == pytest.approx(0.3, abs=0.02)  # the deceleration took its ramp
        rig.sleep(0.05)
        d.link.poll(0)
        assert d.completion == mks.RunReply(1, 0xF6, mks.RunStatus.COMPLETE)


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _lacking("mks-timed-speed"))
def test_speed_mode_run_time_needs_v109_and_plain_speed_mode_still_works(tmp_path: Path, protocol: str,
                                                                         firmware: str) -> None:
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        j.enable()
        sent = d.link.transactions
        with pytest.raises(RegisterError, match="v1.0.9"):
            d.set_velocity(60, run_time=0.5)
        assert d.link.transactions == sent
        d.set_velocity(60)
        rig.sleep(1.0)
        assert d.read("real_time_speed") == pytest.approx(60, abs=2)


# -- 0x50 IAP control (V1.0.8) --------------------------------------------------------------------------


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _having("mks-iap"))
def test_iap_silent_state_hears_only_0x50(tmp_path: Path, protocol: str, firmware: str) -> None:
    from joints.errors import ReplyTimeout

    with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware}) as rig:
        d = rig.joints["m1"].driver
        fw = _twin(rig)
        sent = d.link.transactions
        with pytest.raises(ConfirmationRequired):
            d.set_iap_silent(True)
        assert d.link.transactions == sent and not fw.silent
        d.set_iap_silent(True, confirm=True)
        assert fw.silent
        with pytest.raises(ReplyTimeout):
            d.read("motor_status")  # deaf to everything else
        d.set_iap_silent(False)
        assert not fw.silent and d.read("motor_status") == 1


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _having("mks-iap"))
def test_iap_boot_needs_confirm_and_leaves_the_drive_in_its_boot_loader_until_a_power_cycle(
        tmp_path: Path, protocol: str, firmware: str) -> None:
    from joints.errors import ReplyTimeout

    with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        fw = _twin(rig)
        j.enable()
        sent = d.link.transactions
        with pytest.raises(ConfirmationRequired):
            d.enter_iap_boot()
        with pytest.raises(ConfirmationRequired):
            j.write("iap_control", 1)  # by name too: a dangerous parameter
        assert d.link.transactions == sent and not fw.boot_loader
        d.enter_iap_boot(confirm=True)
        assert fw.boot_loader and not fw.enabled  # the shaft is released
        with pytest.raises(ReplyTimeout):
            d.read("motor_status")
        rig.reset()  # a power cycle: back in the (unchanged) firmware
        assert not fw.boot_loader and d.read("motor_status") == 1


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _lacking("mks-iap"))
def test_iap_needs_v109(tmp_path: Path, protocol: str, firmware: str) -> None:
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware}) as rig:
        d = rig.joints["m1"].driver
        with pytest.raises(RegisterError, match="v1.0.9"):
            d.enter_iap_boot(confirm=True)
        with pytest.raises(RegisterError, match="v1.0.9"):
            d.set_iap_silent(True, confirm=True)


# -- 0x96 / 0x97 PID parameters (V1.0.8) ---------------------------------------------------------------


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _having("mks-pid"))
def test_pid_parameters_need_confirm_and_are_kept_in_flash(tmp_path: Path, protocol: str, firmware: str) -> None:
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware}) as rig:
        d = rig.joints["m1"].driver
        fw = _twin(rig)
        assert [fw.values[f"vfoc_{k}"] for k in ("kp", "ki", "kd", "kv")] == [0xDC, 0x64, 0x10E, 0x140]  # 5.3.1
        sent = d.link.transactions
        with pytest.raises(ConfirmationRequired):
            d.set_pid("vfoc", 300, 120, 250, 400)
        assert d.link.transactions == sent
        d.set_pid("vfoc", 300, 120, 250, 400, confirm=True)
        d.set_pid("close", 210, 90, 260, 310, confirm=True)
        rig.reset()  # a power cycle: settings live in flash
        assert [fw.values[f"vfoc_{k}"] for k in ("kp", "ki", "kd", "kv")] == [300, 120, 250, 400]
        assert [fw.values[f"close_{k}"] for k in ("kp", "ki", "kd", "kv")] == [210, 90, 260, 310]
        with pytest.raises(CommandError, match="1024"):
            d.set_pid("close", 2000, 0, 0, 0, confirm=True)  # out of range: refused before anything is sent


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _lacking("mks-pid"))
def test_pid_parameters_need_v109(tmp_path: Path, protocol: str, firmware: str) -> None:
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware}) as rig, \
            pytest.raises(RegisterError, match="v1.0.9"):
        rig.joints["m1"].driver.set_pid("vfoc", 300, 120, 250, 400, confirm=True)


# -- 0x83 while running, not saved (V1.0.7) --------------------------------------------------------------


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _having("mks-current-unsaved"))
def test_working_current_changed_while_running_is_not_saved(tmp_path: Path, protocol: str, firmware: str) -> None:
    """The unsaved current takes effect at once (the torque the motor has: a lower current, a lower speed under
    a load that needs more); after a power cycle the saved current is back."""
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        fw = _twin(rig)
        d.set_working_current(1200)  # saved
        j.enable()
        d.set_velocity(300, acceleration=1000)
        rig.sleep(0.5)
        assert fw.available_torque() > 0.0
        torque_1200 = fw.available_torque()
        d.set_working_current(400, save=False)
        if protocol == "mks-serial":
            from joints.codecs import mks
            assert d.access.last_reply == mks.SetReply(1, 0x83, mks.SetStatus.SUCCESS_UNSAVED)
        rig.sleep(0.05)
        assert fw.values["working_current"] == 400 and fw.current == pytest.approx(0.4)
        assert fw.available_torque() == pytest.approx(torque_1200 / 3, rel=0.05)  # while running
        assert d.read("real_time_speed") == pytest.approx(300, abs=3)  # still running
        j.stop()
        rig.reset()  # power cycle: flash has 1200
        assert fw.values["working_current"] == 1200
        d.set_working_current(1000)  # a later plain write is saved (the unsaved flag does not ride along)
        rig.reset()
        assert fw.values["working_current"] == 1000


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _lacking("mks-current-unsaved"))
def test_working_current_unsaved_needs_v109(tmp_path: Path, protocol: str, firmware: str) -> None:
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware}) as rig:
        d = rig.joints["m1"].driver
        with pytest.raises(RegisterError, match="v1.0.9"):
            d.set_working_current(400, save=False)
        d.set_working_current(400)  # the saved form still works
        assert _twin(rig).values["working_current"] == 400


# -- 0x3B second status: homing (V1.0.7, native) -------------------------------------------------------


@pytest.mark.parametrize("firmware", _having("mks-homing-status"))
def test_homing_status_follows_go_home(tmp_path: Path, firmware: str) -> None:
    """'noLimit' homing against a blocked shaft: 2 (not homed) -> 0 (going) -> 1 (homed); a stop during it: 2."""
    with open_motor(tmp_path, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        assert d.read("homing_status") == 2 and d.read("go_back_to_zero_status") == 1
        j.enable()
        d.set_nolimit_home(reverse_angle=0x1000, mode=1, current=400)
        d.go_home()
        rig.sleep(0.05)
        assert d.read("homing_status") == 0  # going
        j.stop()
        rig.sleep(0.05)
        assert d.read("homing_status") == 2  # stopped before it homed
        d.go_home()
        rig.sleep(0.1)
        _block(rig.world)  # the mechanical end: the 'noLimit' homing stalls there, backs off, zeroes
        d.wait_motion(10)
        assert d.read("homing_status") == 1


@pytest.mark.parametrize("firmware", _lacking("mks-homing-status"))
def test_homing_status_needs_v109_and_older_drives_send_one_byte(tmp_path: Path, firmware: str) -> None:
    from joints.codecs import mks

    with open_motor(tmp_path, joint={"firmware": firmware}) as rig:
        d = rig.joints["m1"].driver
        with pytest.raises(RegisterError, match="v1.0.9"):
            d.read("homing_status")
        assert d.read("go_back_to_zero_status") == 1
        reply = d.link.request(mks.ReadGoBackToZeroStatus(1), idempotent=True)
        assert reply == mks.GoBackToZeroStatusReply(1, mks.GoBackToZeroStatus.SUCCESS)  # homing None: one byte


@pytest.mark.parametrize("firmware", _having("mks-homing-status"))
def test_homing_status_over_modbus_is_the_low_byte_of_0x3b(tmp_path: Path, firmware: str) -> None:
    """FC04 0x003B "status1 status2" (Modbus-RTU V1.0.9 3.1.7); the layouts per profile: test_mks_modbus_layout."""
    with open_motor(tmp_path, protocol="modbus-rtu", joint={"firmware": firmware}) as rig:
        d = rig.joints["m1"].driver
        assert d.read("homing_status") == 2 and d.read("go_back_to_zero_status") == 1
        assert d.link.read_registers(1, 0x3B, 1, input_registers=True) == (0x0102,)


# -- 0x91 goZeroMode 01: coordinate homing (V1.0.9) ----------------------------------------------------


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _having("mks-coordinate-homing"))
def test_coordinate_homing_runs_back_to_the_coordinate_zero_without_a_search(tmp_path: Path, protocol: str,
                                                                             firmware: str) -> None:
    """Away from axis 0 by a move, coordinate homing runs the shaft back to it (RS485 7.7: "return to the zero
    point position at the zero-point speed") and ends with go home's completion; the zero is not moved."""
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        fw = _twin(rig)
        j.enable()
        d.move_by(3200, speed=300)
        d.wait_motion(10)
        away = d.read("encoder_addition")
        assert abs(away) > 3000
        zero = fw.enc_zero
        d.coordinate_home()
        d.wait_motion(10)
        assert abs(d.read("encoder_addition")) <= 2
        assert fw.enc_zero == zero and abs(fw.q - zero) < 2 * math.tau / 0x4000  # the shaft moved, not the zero
        assert d.motor_status() is MotorStatus.STOP


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _lacking("mks-coordinate-homing"))
def test_coordinate_homing_needs_v109_and_go_home_keeps_its_older_form(tmp_path: Path, protocol: str,
                                                                      firmware: str) -> None:
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        j.enable()
        sent = d.link.transactions
        with pytest.raises(RegisterError, match="v1.0.9"):
            d.coordinate_home()
        assert d.link.transactions == sent  # nothing was sent
        d.go_home()  # the older frame (FA 01 91 8C / register 1) still homes
        assert _twin(rig).motion is not None and _twin(rig).motion.kind == "home"
        j.stop()


# -- 0x00 read a configuration parameter (V1.0.8, profile v1.0.9, native only) ----------------------------


@pytest.mark.parametrize("firmware", _having("mks-read-parameter"))
def test_read_parameter_reads_back_what_was_written_the_pid_gains_included(tmp_path: Path, firmware: str) -> None:
    """0x00's reply is headed by the parameter's code with that parameter's length (1 byte for 0x82, 2 for 0x83,
    8 for 0x96): the link tells the host codec which request is open, else none of these could be framed."""
    with open_motor(tmp_path, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        d = rig.joints["m1"].driver
        fw = _twin(rig)
        assert d.read_parameter("work_mode") == {"work_mode": fw.values["work_mode"]}
        d.set_working_current(1234)
        assert d.read_parameter("working_current") == {"working_current": 1234}
        assert d.read_pid("vfoc") == (0xDC, 0x64, 0x10E, 0x140)  # the manual's defaults
        d.set_pid("close", 100, 90, 80, 70, confirm=True)
        assert d.read_pid("close") == (100, 90, 80, 70)
        assert d.read_pid("vfoc") == (0xDC, 0x64, 0x10E, 0x140)
        assert d.read("encoder_addition") is not None  # the ordinary replies are framed as before
        with pytest.raises(RegisterError, match="FF FF"):
            d.read_parameter("emergency_stop")  # a command, no setting: the twin answers FF FF


@pytest.mark.parametrize("firmware", _lacking("mks-read-parameter"))
def test_read_parameter_needs_v109(tmp_path: Path, firmware: str) -> None:
    with open_motor(tmp_path, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        d = rig.joints["m1"].driver
        sent = d.link.transactions
        with pytest.raises(RegisterError, match="v1.0.9"):
            d.read_parameter("work_mode")
        with pytest.raises(RegisterError, match="v1.0.9"):
            d.read_pid("vfoc")
        assert d.link.transactions == sent  # nothing was sent


def test_read_parameter_is_native_only(tmp_path: Path) -> None:
    with open_motor(tmp_path, protocol="modbus-rtu") as rig, pytest.raises(RegisterError, match="native"):
        rig.joints["m1"].driver.read_pid("vfoc")


# -- 0x42 user ID (V1.0.9, native only) ----------------------------------------------------------------


@pytest.mark.parametrize("firmware", _having("mks-user-id"))
def test_user_id_is_written_and_read_back(tmp_path: Path, firmware: str) -> None:
    """A read (no data) is answered by the 4-byte ID, a write (4 bytes) by a status: the link tells the codec."""
    with open_motor(tmp_path, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        d = rig.joints["m1"].driver
        assert d.read("user_id") == 0
        d.write_param("user_id", 0x12345678)
        assert _twin(rig).values["user_id"] == 0x12345678
        assert d.read("user_id") == 0x12345678
        assert d.read("encoder_addition") is not None  # the next reads are framed as before


@pytest.mark.parametrize("firmware", _lacking("mks-user-id"))
def test_user_id_needs_v109(tmp_path: Path, firmware: str) -> None:
    with open_motor(tmp_path, joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        d = rig.joints["m1"].driver
        sent = d.link.transactions
        with pytest.raises(RegisterError, match="v1.0.9"):
            d.read("user_id")
        with pytest.raises(RegisterError, match="v1.0.9"):
            d.write_param("user_id", 7)
        assert d.link.transactions == sent  # nothing was sent


def test_user_id_is_native_only(tmp_path: Path) -> None:
    with open_motor(tmp_path, protocol="modbus-rtu") as rig, pytest.raises(RegisterError):
        rig.joints["m1"].driver.read("user_id")


# -- 0x99 pulse divider output (V1.0.9, 57D) -------------------------------------------------------------------


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("firmware", _having("mks-pulse-divider"))
def test_pulse_divider_toggles_out2_once_per_period_of_travel(tmp_path: Path, protocol: str, firmware: str) -> None:
    """divPeriod 3200 at 16 microsteps: OUT_2 flips once per turn of the shaft (RS485 6.4's example), from divLevel."""
    with open_motor(tmp_path, protocol=protocol, device="mks-servo57d",
                    joint={"firmware": firmware, "watchdog_ms": 0}) as rig:
        j = rig.joints["m1"]
        d = j.driver

        def out2() -> int:
            return (d.read("io_status") >> 3) & 1

        j.enable()
        d.set_pulse_divider(3200)  # starts low
        assert (_twin(rig).values["pulse_divider_period"], out2()) == (3200, 0)
        for turns, level in ((0.5, 0), (1.5, 1), (2.5, 0), (-0.5, 1)):  # floor(turns) odd: toggled
            d.move_to(round(turns * 16384), speed=300)
            d.wait_motion(10)
            assert out2() == level, turns
        d.set_pulse_divider(3200, start_high=True)  # counts from here again, high
        d.move_by(16384 + 8192, speed=300)
        d.wait_motion(10)
        assert out2() == 0  # high, toggled once
        d.set_pulse_divider(None)  # off: OUT_2 is the written output again (0)
        d.write_io(out2=1)
        assert out2() == 1
        with pytest.raises(CommandError, match="100"):
            d.set_pulse_divider(99)  # "When divPeriod < 100, no frequency divider output"


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_pulse_divider_is_refused_on_a_42d_and_before_v109(tmp_path: Path, protocol: str) -> None:
    from joints.errors import DeviceRejected

    with open_motor(tmp_path, protocol=protocol, joint={"firmware": "v1.0.9"}) as rig:  # a 42D: "only for 57D"
        with pytest.raises(DeviceRejected):
            rig.joints["m1"].driver.set_pulse_divider(3200)
        assert _twin(rig).values["pulse_divider_period"] == 0
    for firmware in _lacking("mks-pulse-divider"):
        with open_motor(tmp_path, protocol=protocol, device="mks-servo57d", joint={"firmware": firmware}) as rig:
            d = rig.joints["m1"].driver
            sent = d.link.transactions
            with pytest.raises(RegisterError, match="v1.0.9"):
                d.set_pulse_divider(3200)
            assert d.link.transactions == sent


# -- 0x9F IN_1 as an output (V1.0.9, 28D/35D/42D, native only) ---------------------------------------------------


@pytest.mark.parametrize("firmware", _having("mks-in1-port-mode"))
def test_in1_as_an_output_reads_what_0x36_writes_and_no_switch(firmware: str) -> None:
    """On the linear axis, parked on the home switch (IN_1, low-active: reads 0 there): as an output IN_1 reads the
    level 0x36 bit 2 writes, whatever OUT1_mask, and homing no longer finds the switch; back to an input, it does."""
    from mkskit import axis_config

    import joints
    from joints.codecs import mks as codec
    from joints.errors import ConfirmationRequired

    with joints.open(axis_config(firmware=firmware)) as rig:
        rig.world.set_joint_positions({"carriage": -0.077})  # on the switch
        j = rig.joints["carriage"]
        d = j.driver
        fw = rig.world.drives["carriage"]
        assert isinstance(fw, MksFirmware)
        assert d.read("io_status") & 1 == 0  # triggered (effective level low)
        sent = d.link.transactions
        with pytest.raises(ConfirmationRequired):
            d.set_in1_mode(True)
        assert d.link.transactions == sent
        d.set_in1_mode(True, confirm=True)
        assert fw.values["in1_port_mode"] == 1
        d.write_io(out1=1)
        assert d.read("io_status") & 1 == 1  # the written level, not the switch
        d.link.request(codec.WriteIoPort(1, 0, 0, 0, 0), idempotent=True)
        assert d.read("io_status") & 1 == 0  # mask 0 ("do not write") still writes IN_1
        assert not fw._switches()[0]  # the home switch is not read
        d.set_in1_mode(False)
        assert d.read("io_status") & 1 == 0 and fw._switches()[0]


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_in1_port_mode_is_native_42d_and_v109_only(tmp_path: Path, protocol: str) -> None:
    from joints.errors import DeviceRejected

    with open_motor(tmp_path, protocol=protocol, device="mks-servo57d", joint={"firmware": "v1.0.9"}) as rig:
        d = rig.joints["m1"].driver
        if protocol == "modbus-rtu":  # the Modbus-RTU manual has no such request
            with pytest.raises(RegisterError, match="native"):
                d.set_in1_mode(True, confirm=True)
        else:  # "This only applies to setting the IN_1 port of 28D/35D/42D"
            with pytest.raises(DeviceRejected):
                d.set_in1_mode(True, confirm=True)
        assert _twin(rig).values["in1_port_mode"] == 0
    for firmware in _lacking("mks-in1-port-mode"):
        with open_motor(tmp_path, protocol=protocol, joint={"firmware": firmware}) as rig, \
                pytest.raises(RegisterError, match="v1.0.9"):
            rig.joints["m1"].driver.set_in1_mode(True, confirm=True)
