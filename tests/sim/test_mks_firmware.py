"""MKS firmware profiles against the twin: V1.0.9's heartbeat protection is the watchdog (armed while enabled,
restored on disable, fed by waiting, stops a silent host's axis), V1.0.6+'s Modbus failure replies, 0x40 version."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest

pytest.importorskip("mujoco")
pytestmark = pytest.mark.mks_firmware

from mkskit import open_motor

from joints.codecs import modbus as mb
from joints.devices.mks.state import MotorStatus, WorkMode
from joints.drivers.capabilities import CommunicationWatchdog
from joints.errors import DeviceRejected, RegisterError
from joints.sim.mks import MksFirmware

HEARTBEAT = 1.0  #: s, the family's watchdog time (1000 ms) armed while enabled
#: the longest MKS frame (11 bytes: 0xF4/0xF5/0xFD/0xFE) at 38400 baud, 10 bits per character
FRAME = 11 * 10 / 38400


def _twin(rig) -> MksFirmware:  # type: ignore[no-untyped-def]
    fw = rig.world.drives["m1"]
    assert isinstance(fw, MksFirmware)
    return fw


@pytest.mark.mks_firmware("v1.0.9")  # before: no watchdog (the next test)
@pytest.mark.parametrize("protocol", ["mks-serial", "modbus-rtu"])
def test_v109_silent_host_leaves_the_axis_stopped_within_the_heartbeat_plus_one_frame(tmp_path: Path,
                                                                                       protocol: str) -> None:
    with open_motor(tmp_path, protocol=protocol) as rig:
        j = rig.joints["m1"]
        fw = _twin(rig)
        assert isinstance(j.driver, CommunicationWatchdog)
        assert fw.values["heartbeat_protection_time"] == 0  # off at power-on
        j.enable()
        assert fw.values["heartbeat_protection_time"] == HEARTBEAT * 1000  # armed while enabled
        j.set_velocity(10.0)
        rig.sleep(3 * HEARTBEAT)  # waiting feeds it: the axis keeps running
        assert fw.heartbeat_trips == 0 and j.state().velocity == pytest.approx(10.0, rel=0.02)
        last = fw._last_frame
        while rig.time < last + HEARTBEAT + FRAME:  # the host goes silent (no frame, the world runs on)
            rig.clock.sleep(0.0005)
        assert fw.heartbeat_trips == 1
        assert last + HEARTBEAT <= fw.heartbeat_tripped_at <= last + HEARTBEAT + FRAME
        assert fw.motion is None and fw.motor_status() is MotorStatus.STOP and fw.enabled  # stopped, held
        rig.clock.sleep(0.3)
        assert abs(rig.world.joint_velocity("m1")) < 0.05
        j.disable()
        assert fw.values["heartbeat_protection_time"] == 0  # put back on disable


@pytest.mark.mks_firmware("v1.0.5", "v1.0.6")
def test_before_v109_there_is_no_watchdog_and_a_silent_host_leaves_the_axis_running(tmp_path: Path,
                                                                                   mks_firmware: str) -> None:
    with open_motor(tmp_path, joint={"firmware": mks_firmware}) as rig:
        j = rig.joints["m1"]
        assert not isinstance(j.driver, CommunicationWatchdog) and j.watchdog_ms is None
        j.enable()
        j.set_velocity(10.0)
        rig.clock.sleep(3 * HEARTBEAT)
        assert rig.world.joint_velocity("m1") == pytest.approx(10.0, rel=0.02)
        with pytest.raises(RegisterError, match="v1.0.9"):
            j.driver.write_param("heartbeat_protection_time", 500)


def test_failed_fc06_and_fc16_are_answered_as_the_firmware_does_and_refused_by_the_driver(tmp_path: Path,
                                                                                        mks_firmware: str) -> None:
    """0xF6 while disabled (FC16) and 0xF3 enable in a pulse work mode (FC06): V1.0.6+ answer with the
    manuals' failure replies, V1.0.5 with exceptions 04; the driver raises DeviceRejected either way."""
    with open_motor(tmp_path, protocol="modbus-rtu", joint={"firmware": mks_firmware}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        j.enable()
        d.disable()
        fw = _twin(rig)
        before = dict(fw.values)
        replies: list[object] = []
        exchange = d.link.rule.is_reply

        def spy(request: object, reply: object) -> bool:
            replies.append(reply)
            return exchange(request, reply)

        d.link.rule.is_reply = spy  # type: ignore[method-assign]
        with pytest.raises(DeviceRejected) as fc16:
            d.set_velocity(100)
        answers = [replies[-1]]
        assert fw.values == before  # a failure: the twin carried out nothing, not even the command's fields
        d.set_work_mode(WorkMode.CR_vFOC)
        before = dict(fw.values)
        with pytest.raises(DeviceRejected) as fc06:
            d.write_param("motor_enable", 1)
        answers.append(replies[-1])
        assert fw.values == before and not fw.enabled
        if mks_firmware == "v1.0.5":
            assert answers == [mb.ExceptionReply(1, 0x10, 4), mb.ExceptionReply(1, 0x06, 4)]
            assert (fc16.value.code, fc06.value.code) == (4, 4)
        else:
            assert answers == [mb.WriteMultipleRegistersReply(1, 0xF6, 0), mb.WriteSingleRegisterReply(1, 0xF3, 0xFFFF)]
            assert (fc16.value.code, fc06.value.code) == (0, 0)
            assert "failure reply" in str(fc16.value)
        assert d.image.get("speed_mode_speed", 0) == 0  # a refused command is not remembered as sent


def test_a_raw_fc06_write_of_0xffff_the_drive_refuses_is_a_refusal_not_an_echo(tmp_path: Path, mks_firmware: str) -> None:
    """0xFFFF to 0x83 (working current 65535 mA): V1.0.6+ answer the failure reply, whose data equal the value
    sent; the driver declared the slave's failure replies to the link, and no MKS register takes 0xFFFF."""
    with open_motor(tmp_path, protocol="modbus-rtu", joint={"firmware": mks_firmware}) as rig:
        d = rig.joints["m1"].driver
        fw = _twin(rig)
        before = dict(fw.values)
        with pytest.raises(DeviceRejected) as fc06:
            d.link.write_register(1, 0x83, 0xFFFF)
        with pytest.raises(DeviceRejected) as raw:
            d.link.write_pdu(1, mb.WRITE_SINGLE_REGISTER, bytes.fromhex("0083FFFF"))
        assert fw.values == before
        assert fc06.value.code == raw.value.code == (3 if mks_firmware == "v1.0.5" else 0)  # V1.0.5: exception 03


@pytest.mark.parametrize("protocol", ["mks-serial", "modbus-rtu"])
def test_identity_reads_0x40_where_the_firmware_has_it(tmp_path: Path, protocol: str, mks_firmware: str) -> None:
    with open_motor(tmp_path, protocol=protocol, joint={"firmware": mks_firmware}) as rig:
        ident = rig.joints["m1"].driver.identity()
        if mks_firmware == "v1.0.9":
            assert ident == {"firmware_version": "v1.0.9", "hardware_version": "S42D_485", "calibrated": True}
        else:
            assert "older than v1.0.9" in str(ident["firmware_version"])
        rig.joints["m1"].enable()  # the configured firmware agrees with the drive's


def test_v109_timed_returns_arrive_unsolicited_through_the_links_subscriptions(tmp_path: Path,
                                                                                mks_firmware: str) -> None:
    from joints.codecs import mks

    with open_motor(tmp_path, joint={"watchdog_ms": 0}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        if mks_firmware != "v1.0.9":
            sent = d.link.transactions
            with pytest.raises(RegisterError, match="v1.0.9"):
                d.timed_return("encoder_addition", 100)
            assert d.link.transactions == sent  # refused before anything was sent
            return
        got: list[tuple[float, int]] = []
        j.enable()
        j.set_velocity(2 * 3.141592653589793)  # one turn per second: 16384 counts/s
        rig.sleep(2.0)  # at speed
        d.timed_return("encoder_addition", 100, lambda v: got.append((rig.time, v["encoder_addition"])))
        sent = d.link.transactions
        for _ in range(10):
            rig.sleep(0.1)
            d.link.poll(0)  # deliver what arrived; sends nothing
        assert d.link.transactions == sent  # nothing was asked: the drive sent them by itself
        assert 9 <= len(got) <= 11
        steps = [b - a for (_t, a), (_u, b) in itertools.pairwise(got)]
        assert all(abs(s - 1638) <= 20 for s in steps), steps  # 0.1 s apart at 16384 counts/s
        assert d.returned[0x31]["encoder_addition"] == got[-1][1]
        d.timed_return("encoder_addition", 0)
        n = len(got)
        rig.sleep(0.5)
        d.link.poll(0)
        assert len(got) == n  # stopped
        assert mks.encode(mks.SetTimedReturn(1, 0x31, 1000)) == bytes.fromhex("FA 01 01 31 03 E8 18")  # 5.1.9
        assert mks.encode(mks.TimedReturnReply(1, 0x31, mks.SetStatus.SUCCESS)) == bytes.fromhex("FB 01 01 31 01 2F")


def test_raw_encoder_counts_from_power_on_whatever_zero_was_set(tmp_path: Path, mks_firmware: str) -> None:
    """0x35 (V1.0.6): the accumulated encoder since power-on; 0x92 set zero moves 0x31's zero, not 0x35's."""
    with open_motor(tmp_path, joint={"firmware": mks_firmware}) as rig:
        j = rig.joints["m1"]
        d = j.driver
        if mks_firmware == "v1.0.5":
            with pytest.raises(RegisterError, match="v1.0.6"):
                d.read("raw_encoder_value")
            return
        j.enable()
        j.move_by(3.141592653589793)
        j.wait(timeout=10)
        d.set_zero(confirm=True)
        j.move_by(3.141592653589793)
        j.wait(timeout=10)
        axis, raw = d.read("encoder_addition"), d.read("raw_encoder_value")
        assert abs(axis - 8192) <= 2 and abs(raw - 16384) <= 2
        assert abs(d.read_all_status()["raw_encoder_value"] - raw) <= 2  # a later read: the shaft may settle a count
