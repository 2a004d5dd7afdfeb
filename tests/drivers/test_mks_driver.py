"""The MKS driver against scripted drives: dangerous commands, the image of write-only settings, whole
multi-field commands, Part 8 frames (the 0x90 quirk), lost replies of run commands, stop and units."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from joints.clock import ManualClock
from joints.codecs import mks
from joints.codecs import modbus as mb
from joints.devices.mks import blocks
from joints.devices.mks.params import DANGEROUS, MKS_PARAMS
from joints.devices.mks.state import MotorStatus
from joints.devices.quirks import MKS_ALL_PARAMETERS, MKS_VERSION, firmware_profile
from joints.drivers.mks_modbus import MksModbusDriver
from joints.drivers.mks_native import MksNativeDriver
from joints.errors import ConfigError, ConfirmationRequired, OutcomeUnknown, RegisterError
from joints.joint import Joint
from joints.link import RetryPolicy
from joints.link.mks import MksLink
from joints.link.modbus import ModbusLink
from joints.transports.loopback import LoopbackTransport
from testdata import by_id

pytestmark = pytest.mark.mks_firmware
ADDRESS = 1


class Drive:
    """A scripted native drive of the default firmware profile (the test's): answers every command it has with
    success (0x40 from V1.0.9, 0x47 from V1.0.6; none before); ``hook`` may replace an answer."""

    def __init__(self, hook: Callable[[Any], bytes | None] | None = None) -> None:
        self.features = firmware_profile("mks").features
        self.codec = mks.MksCodec(mks.Role.DEVICE)
        self.requests: list[Any] = []
        self.hook = hook
        self.status = MotorStatus.STOP
        self.position = 0
        self.held: dict[str, int] = {}  #: settings the drive holds beyond the factory ones (0x47)

    def __call__(self, data: bytes) -> bytes:
        self.codec.feed(data)
        out = b""
        while (msg := self.codec.next_message()) is not None:
            self.requests.append(msg)
            custom = self.hook(msg) if self.hook else None
            out += custom if custom is not None else self.answer(msg)
        return out

    def answer(self, msg: Any) -> bytes:
        if isinstance(msg, (mks.ReadVersion, mks.ReadAllParameters)) and (
                (MKS_VERSION if isinstance(msg, mks.ReadVersion) else MKS_ALL_PARAMETERS) not in self.features):
            return b""  # a command of a later firmware: no answer
        if isinstance(msg, mks.ReadVersion):  # a V1.0.9 drive, calibrated, S42D_485
            return mks.encode(mks.VersionReply(msg.address, 0x11_01_00_09))
        if isinstance(msg, mks.ReadAllParameters):  # 0x47: what the drive holds (factory settings + held)
            values = {n: MKS_PARAMS[n].default for n, _o, _s in blocks.ALL_PARAMETERS} | self.held
            return mks.encode(mks.AllParametersReply(msg.address, blocks.pack(blocks.ALL_PARAMETERS, values, 34)))
        if isinstance(msg, mks.QueryStatus):
            return mks.encode(mks.MotorStatusReply(msg.address, self.status))
        if isinstance(msg, mks.ReadEncoderAddition):
            return mks.encode(mks.EncoderAdditionReply(msg.address, self.position))
        if isinstance(msg, mks.Calibrate):
            return mks.encode(mks.CalibrationReply(msg.address, mks.CalibrationStatus.CALIBRATING))
        if msg.function in mks.RUN_REPLY_FUNCTIONS:
            return mks.encode(mks.RunReply(msg.address, msg.function, mks.RunStatus.STARTED))
        if msg.function in mks.SET_REPLY_FUNCTIONS:
            return mks.encode(mks.SetReply(msg.address, msg.function, mks.SetStatus.SUCCESS))
        return b""


def native(hook: Callable[[Any], bytes | None] | None = None) -> tuple[MksNativeDriver, Drive]:
    drive = Drive(hook)
    link = MksLink(LoopbackTransport(drive), clock=ManualClock(), policy=RetryPolicy(timeout=0.05, retries=2))
    return MksNativeDriver(link, ADDRESS, device="mks-servo42d"), drive


DANGEROUS_CALLS: dict[str, Callable[[MksNativeDriver], None]] = {
    "0x80 calibrate": lambda d: d.calibrate(),
    "0x8A baud rate": lambda d: d.set_baud_rate(6),
    "0x8B address": lambda d: d.set_address(7),
    "0x8E Modbus": lambda d: d.set_modbus(True),
    "0x9A 0_Mode": lambda d: d.set_zero_mode(1),
    "0xFF C8 save speed mode": lambda d: d.save_speed_mode(),
    "0x3F restore defaults": lambda d: d.restore_defaults(),
    "0x41 restart": lambda d: d.restart(),
    "0x92 set zero": lambda d: d.set_zero(),
}


@pytest.mark.parametrize("what", DANGEROUS_CALLS)
def test_each_dangerous_command_refuses_without_confirm_and_sends_nothing(what: str) -> None:
    driver, drive = native()
    with pytest.raises(ConfirmationRequired, match="confirm=True"):
        DANGEROUS_CALLS[what](driver)
    assert drive.requests == [] and driver.link.transactions == 0


def test_dangerous_parameters_by_name_need_confirm_through_the_joint_too() -> None:
    assert DANGEROUS == {"calibrate", "baud_rate", "slave_address", "modbus_rtu", "zero_mode", "zero_mode_set_zero",
                         "zero_mode_speed", "zero_mode_direction", "save_clean_speed_mode_parameter",
                         "restore_default_parameters", "restart_motor", "set_current_axis_to_zero",
                         "en_trigger_zero_return", "iap_control",  # 0x9D g0Enable (V1.0.6), 0x50 IAP (V1.0.8)
                         *(f"{m}_{k}" for m in ("vfoc", "close") for k in ("kp", "ki", "kd", "kv")),  # 0x96/0x97
                         "in1_port_mode"}  # 0x9F (V1.0.9): IN_1 as an output reads no switch
    driver, drive = native()
    joint = Joint("axis", driver, clock=driver.clock)
    for name in sorted(DANGEROUS):
        value = 0xC8 if name == "save_clean_speed_mode_parameter" else 1
        with pytest.raises(ConfirmationRequired):
            joint.write(name, value)
    assert drive.requests == []
    driver.calibrate(confirm=True)
    assert drive.requests == [mks.Calibrate(ADDRESS)]


@pytest.mark.mks_firmware("v1.0.5")  # from V1.0.6: the next test
def test_write_only_settings_are_remembered_not_read() -> None:
    driver, drive = native()
    with pytest.raises(RegisterError, match="cannot be read"):
        driver.read("working_current")
    assert drive.requests == []
    driver.set_working_current(1200)
    assert driver.written("working_current") == 1200
    assert drive.requests == [mks.SetWorkingCurrent(ADDRESS, 1200)]


@pytest.mark.mks_firmware("v1.0.6", "v1.0.9")
def test_from_v106_write_only_settings_are_read_by_0x47() -> None:
    driver, drive = native()
    drive.held = {"working_current": 1400}
    assert driver.read("working_current") == 1400
    assert drive.requests == [mks.ReadAllParameters(ADDRESS)]
    assert driver.written("working_current") == 1400  # what the drive holds: not written again
    with pytest.raises(RegisterError, match="cannot be read"):
        driver.read("zero_mode_set_zero")  # 0x47 reads it as "Reserved (FF)"


def test_multi_field_commands_send_all_their_fields() -> None:
    driver, drive = native()
    driver.set_home(trigger_level=1, direction=1, speed=90, end_limit=1)
    assert drive.requests[-1] == mks.SetHomeParameters(ADDRESS, 1, 1, 90, 1)
    driver.write("home_speed", 30)  # one field: the others as written before
    assert drive.requests[-1] == mks.SetHomeParameters(ADDRESS, 1, 1, 30, 1)
    driver.set_respond_active(True, False)
    driver.write("slave_active", 1)
    assert drive.requests[-1] == mks.SetRespondActive(ADDRESS, 1, 1)
    assert len(drive.requests) == 4


@pytest.mark.mks_firmware("v1.0.5")  # from V1.0.6: the next test
def test_enable_sets_serial_mode_subdivision_respond_active_once() -> None:
    driver, drive = native()  # no 0x40, no 0x47
    driver.enable()
    assert drive.requests == [mks.ReadVersion(ADDRESS), mks.SetWorkMode(ADDRESS, 5), mks.SetSubdivision(ADDRESS, 16),
                              mks.SetRespondActive(ADDRESS, 1, 1), mks.EnableMotor(ADDRESS, 1)]
    driver.disable()
    driver.enable()
    assert drive.requests[-2:] == [mks.EnableMotor(ADDRESS, 0), mks.EnableMotor(ADDRESS, 1)]


@pytest.mark.mks_firmware("v1.0.6", "v1.0.9")
def test_v106_enable_reads_what_the_drive_holds_and_writes_only_what_differs() -> None:
    driver, drive = native()
    drive.held = {"microsteps": 32, "work_mode": 5}  # set on the drive's menu
    driver.enable()
    assert drive.requests == [mks.ReadVersion(ADDRESS), mks.ReadAllParameters(ADDRESS), mks.EnableMotor(ADDRESS, 1)]
    assert driver.microsteps == 32 and driver.pulses_per_turn == 6400  # the drive's subdivision
    drive.requests.clear()
    given = MksNativeDriver(driver.link, ADDRESS, device="mks-servo42d", microsteps=16)
    given.enable()  # a subdivision given to the driver is written
    assert mks.SetSubdivision(ADDRESS, 16) in drive.requests and given.microsteps == 16


def test_units_speed_value_and_acc_follow_the_manual() -> None:
    driver, drive = native()
    driver.set_velocity(-600, acceleration=1000)
    assert drive.requests[-1] == mks.RunSpeed(ADDRESS, mks.RunDirection.CW, 600, 236)
    driver.set_microsteps(8)  # 6.1: at 8 microsteps the value means twice the rpm (and the ramp twice the rate)
    driver.set_velocity(600, acceleration=1000)
    assert drive.requests[-1] == mks.RunSpeed(ADDRESS, mks.RunDirection.CCW, 300, 216)  # 500 values/s
    driver.move_pulses(-1600, speed=300)
    assert drive.requests[-1] == mks.RunRelativePulses(ADDRESS, mks.RunDirection.CW, 150, 236, 1600)
    driver.move_to(-0x4000, speed=600, acceleration=0)
    assert drive.requests[-1] == mks.RunAbsoluteAxis(ADDRESS, 300, 0, -0x4000)


def test_stop_stops_the_running_mode_speed_mode_when_unknown() -> None:
    driver, drive = native()
    driver.set_velocity(1200, acceleration=1000)
    driver.stop()
    assert drive.requests[-1] == mks.RunSpeed(ADDRESS, mks.RunDirection.CCW, 0, 236)  # decelerated
    driver.move_pulses(3200, speed=100, acceleration=0)
    driver.stop()
    assert drive.requests[-1] == mks.RunRelativePulses(ADDRESS, mks.RunDirection.CCW, 0, 0, 0)  # at once, < 1000 rpm
    driver.forget()  # e.g. a new host process: nothing known to run
    driver.stop()
    assert drive.requests[-1].function == 0xF6 and drive.requests[-1].speed == 0


def test_lost_reply_of_a_started_move_is_not_sent_again() -> None:
    def lose_run(msg: Any) -> bytes | None:
        return b"" if msg.function == 0xF5 else None

    driver, drive = native(lose_run)
    drive.status = MotorStatus.SPEED_UP  # the drive took it
    driver.move_to(20000, speed=300)
    assert sum(1 for r in drive.requests if r.function == 0xF5) == 1
    assert any(isinstance(r, mks.QueryStatus) for r in drive.requests)
    assert driver.describe_running() == "abs_axis"


def test_lost_reply_of_a_move_the_drive_did_not_take_is_sent_once_more() -> None:
    sent = []

    def lose_first(msg: Any) -> bytes | None:
        if msg.function == 0xF5:
            sent.append(msg)
            return b"" if len(sent) == 1 else None
        return None

    driver, drive = native(lose_first)
    drive.position = 123  # standing still, not at the target: it did not start
    driver.move_to(20000, speed=300)
    assert len(sent) == 2


def test_lost_reply_of_a_relative_move_is_an_unknown_outcome() -> None:
    driver, drive = native(lambda m: b"" if m.function == 0xF4 else None)
    with pytest.raises(OutcomeUnknown, match="relative move"):
        driver.move_by(1000, speed=100)
    assert sum(1 for r in drive.requests if r.function == 0xF4) == 1


# --- Part 8 --------------------------------------------------------------------------------------


class ModbusDrive:
    """A scripted Modbus-mode drive: echoes writes (the 0x90 frame included), records raw frames."""

    def __init__(self) -> None:
        self.frames: list[bytes] = []

    def __call__(self, data: bytes) -> bytes:
        self.frames.append(data)
        fc = data[1]
        if fc in (0x06,):
            return data
        if fc == 0x10:
            return mb.encode(mb.WriteMultipleRegistersReply(data[0], int.from_bytes(data[2:4], "big"),
                                                            int.from_bytes(data[4:6], "big")))
        if fc == 0x04:
            count = int.from_bytes(data[4:6], "big")
            return mb.encode(mb.ReadRegistersReply(data[0], 4, (1,) * count))
        return b""


def test_modbus_home_parameters_go_out_as_the_manuals_own_frame() -> None:
    drive = ModbusDrive()
    link = ModbusLink(LoopbackTransport(drive), clock=ManualClock())
    driver = MksModbusDriver(link, 1, device="mks-servo42d")
    driver.set_home(trigger_level=0, direction=1, speed=60, end_limit=1)
    frame = drive.frames[-1]
    assert frame[:7] == bytes.fromhex("01 10 00 90 00 03 05")  # 3 registers, 5 bytes (ERRATA DOC-MKS-5)
    assert frame[7:12] == bytes((0, 1, 0, 60, 1)) and len(frame) == 14
    reply = bytes.fromhex(by_id()["mks-modbus-8.2.20-recv"]["hex"])
    assert mb.encode(mb.WriteMultipleRegistersReply(1, 0x90, 3)) == reply


def test_modbus_reads_and_native_only_parameters() -> None:
    drive = ModbusDrive()
    link = ModbusLink(LoopbackTransport(drive), clock=ManualClock())
    driver = MksModbusDriver(link, 1, device="mks-servo42d")
    assert driver.read("encoder_addition") == 0x000100010001
    assert drive.frames[-1][:6] == bytes.fromhex("01 04 00 31 00 03")
    n = len(drive.frames)
    with pytest.raises(RegisterError, match="native"):
        driver.write("slave_respond", 0)
    assert len(drive.frames) == n
    driver.set_velocity(-320, acceleration=None)  # 8.3.3: dir, acc, speed in two registers
    assert drive.frames[-1][:11] == bytes.fromhex("01 10 00 F6 00 02 04 01 EC 01 40")


def test_the_torque_limit_becomes_the_working_current_while_enabled() -> None:
    from joints.joint import Limits

    driver, drive = native()
    joint = Joint("axis", driver, clock=driver.clock, limits=Limits(torque=0.3))
    drive.hook = lambda m: (mks.encode(mks.ProtectionStateReply(1, False)) if isinstance(m, mks.ReadProtectionState)
                            else mks.encode(mks.EnPinReply(1, True)) if isinstance(m, mks.ReadEnPin)
                            else mks.encode(mks.SpeedReply(1, 0)) if isinstance(m, mks.ReadSpeed) else None)
    joint.enable()
    assert mks.SetWorkingCurrent(ADDRESS, round(0.3 / driver.profile.torque_constant * 1000)) in drive.requests
    assert driver.written("working_current") == 1017


# ------------------------------------------------------------------------------ firmware profiles


def _versioned(word: int | None) -> Callable[[Any], bytes | None]:
    """A hook: the drive answers 0x40 with ``word`` (None: not at all, like firmware before V1.0.9)."""
    def hook(msg: Any) -> bytes | None:
        if isinstance(msg, mks.ReadVersion):
            return b"" if word is None else mks.encode(mks.VersionReply(msg.address, word))
        return None
    return hook


def _driver(firmware: str, word: int | None) -> tuple[MksNativeDriver, Drive]:
    drive = Drive(_versioned(word))
    drive.features = firmware_profile("mks", firmware).features
    link = MksLink(LoopbackTransport(drive), clock=ManualClock(), policy=RetryPolicy(timeout=0.05, retries=2))
    return MksNativeDriver(link, ADDRESS, device="mks-servo42d", firmware=firmware), drive


@pytest.mark.mks_firmware(None)  # each case names its firmware
@pytest.mark.parametrize("firmware,word,refused", [
    ("v1.0.9", 0x11_01_00_09, None),
    ("v1.0.9", 0x11_01_00_0A, "reports firmware v1.0.10, the config says v1.0.9"),
    ("v1.0.9", None, "does not answer 0x40"),
    ("v1.0.6", None, None),
    ("v1.0.5", None, None),
    ("v1.0.5", 0x11_01_00_09, "reports firmware v1.0.9, the config says v1.0.5"),
])
def test_the_first_enable_checks_the_configured_firmware_against_0x40(firmware: str, word: int | None,
                                                                      refused: str | None) -> None:
    driver, drive = _driver(firmware, word)
    if refused is None:
        driver.enable()
        assert drive.requests[-1] == mks.EnableMotor(ADDRESS, 1)
        probes = [r for r in drive.requests if isinstance(r, mks.ReadVersion)]
        assert len(probes) == 1  # once; an older profile's probe is not retried either
        driver.disable()
        driver.enable()
        assert len([r for r in drive.requests if isinstance(r, mks.ReadVersion)]) == 1
    else:
        with pytest.raises(ConfigError, match=refused) as exc:
            driver.enable()
        assert exc.value.key == "firmware"
        assert all(isinstance(r, mks.ReadVersion) for r in drive.requests)  # nothing else was sent


@pytest.mark.mks_firmware(None)  # names its firmware: v1.0.6, then v1.0.9
def test_commands_of_a_later_firmware_are_refused_before_anything_is_sent() -> None:
    driver, drive = _driver("v1.0.6", None)
    with pytest.raises(RegisterError, match="v1.0.9"):
        driver.write_param("heartbeat_protection_time", 1000)
    with pytest.raises(RegisterError, match="v1.0.9"):
        driver.read("version_information")
    assert drive.requests == []
    driver, drive = _driver("v1.0.9", 0x11_01_00_09)
    driver.write_param("heartbeat_protection_time", 1000)
    assert drive.requests == [mks.SetHeartbeat(ADDRESS, 1000)]
    assert mks.encode(drive.requests[0]) == bytes.fromhex("FA 01 98 00 00 03 E8") + bytes(
        (sum(bytes.fromhex("FA 01 98 00 00 03 E8")) & 0xFF,))


@pytest.mark.mks_firmware("v1.0.6", "v1.0.9")
def test_v106_failure_replies_are_refusals_and_an_echo_of_0xffff_is_never_sent() -> None:
    """FC06 data 0xFFFF / FC16 quantity 0 (V1.0.6+ "If write fails") -> DeviceRejected code 0, not retried."""
    from joints.errors import DeviceRejected

    class Failing(ModbusDrive):
        def __call__(self, data: bytes) -> bytes:
            self.frames.append(data)
            if data[1] == 0x06:
                return mb.encode(mb.WriteSingleRegisterReply(data[0], int.from_bytes(data[2:4], "big"), 0xFFFF))
            if data[1] == 0x10:
                return mb.encode(mb.WriteMultipleRegistersReply(data[0], int.from_bytes(data[2:4], "big"), 0))
            return super().__call__(data)

    drive = Failing()
    link = ModbusLink(LoopbackTransport(drive), clock=ManualClock(), policy=RetryPolicy(timeout=0.05, retries=2))
    driver = MksModbusDriver(link, 1, device="mks-servo42d")
    with pytest.raises(DeviceRejected, match="failure reply") as fc06:
        driver.set_working_current(1000)
    with pytest.raises(DeviceRejected, match="failure reply") as fc16:
        driver.set_velocity(100)
    assert (fc06.value.code, fc16.value.code) == (0, 0)
    assert len(drive.frames) == 2  # a refusal is an answer: nothing was sent again
    assert "working_current" not in driver.image
