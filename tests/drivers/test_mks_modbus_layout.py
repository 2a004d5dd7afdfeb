"""The MKS Part 8 layout per firmware profile, driver -> twin and on the wire: FC04 0x003B reads ``00 status``
before V1.0.7 (RS485 manuals V1.0.5 Part 8 #8, V1.0.6 8.1 #8) and ``status1 status2`` from it (Modbus-RTU
manual V1.0.9 3.1.7: the single-turn zero return, then the homing status); driver and twin take the same
profile's map (joints.devices.mks.modbus.modbus_map)."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest

pytest.importorskip("mujoco")
pytestmark = pytest.mark.mks_firmware

from mkskit import axis_config, open_motor

import joints
from joints.devices.mks.modbus import FC_READ, MKS_MODBUS_OF, REVISED, modbus_map
from joints.devices.quirks import MKS_HOMING_STATUS, firmware_profile
from joints.drivers.mks import MksDriver
from joints.errors import DeviceRejected, RegisterError
from joints.sim.mks import MksFirmware


def _has_homing(firmware: str) -> bool:
    return MKS_HOMING_STATUS in firmware_profile("mks", firmware).features


def _twin(rig: joints.Rig, name: str = "m1") -> MksFirmware:
    fw = rig.world.drives[name]
    assert isinstance(fw, MksFirmware)
    return fw


def test_each_profile_has_its_manuals_0x3b_layout(mks_firmware: str) -> None:
    block = MKS_MODBUS_OF[mks_firmware].block(FC_READ, 0x3B)
    assert block.count == 1
    layout = {f.name: (f.offset, f.size) for f in block.fields}
    if _has_homing(mks_firmware):
        assert layout == {"go_back_to_zero_status": (0, 1), "homing_status": (1, 1)}  # status1 status2
    else:
        assert layout == {"go_back_to_zero_status": (1, 1)}  # 00 status
    assert modbus_map(firmware_profile("mks", mks_firmware).features) is MKS_MODBUS_OF[mks_firmware]
    others = {(b.function, b.address) for _, b in REVISED}
    base = MKS_MODBUS_OF["v1.0.5"]
    assert all(b == base.block(b.function, b.address) for b in MKS_MODBUS_OF[mks_firmware].blocks
               if (b.function, b.address) not in others)  # only the revised requests differ


def test_the_twin_answers_0x3b_in_its_firmwares_layout(tmp_path: Path, mks_firmware: str) -> None:
    with open_motor(tmp_path, protocol="modbus-rtu") as rig:
        d = rig.joints["m1"].driver
        fw = _twin(rig)
        fw.zero_status, fw.home_status = 1, 0  # single-turn return done, a go home running
        (word,) = d.link.read_registers(1, 0x3B, 1, input_registers=True)
        assert word == (0x0100 if _has_homing(mks_firmware) else 0x0001)


def test_driver_and_twin_agree_on_0x3b_for_every_pair_of_statuses(tmp_path: Path, mks_firmware: str) -> None:
    """Every (status1, status2) the twin holds reads back as itself: a layout the driver and the twin disagree on
    swaps or zeroes one of them."""
    with open_motor(tmp_path, protocol="modbus-rtu") as rig:
        d = rig.joints["m1"].driver
        fw = _twin(rig)
        for zero, home in itertools.product(range(3), repeat=2):
            fw.zero_status, fw.home_status = zero, home
            assert d.read("go_back_to_zero_status") == zero
            if _has_homing(mks_firmware):
                sent = d.link.transactions
                assert d.access.read_many(["go_back_to_zero_status", "homing_status"]) == \
                    {"go_back_to_zero_status": zero, "homing_status": home}
                assert d.link.transactions == sent + 1  # both from one FC04 read
        if not _has_homing(mks_firmware):
            sent = d.link.transactions
            with pytest.raises(RegisterError, match="v1.0.9"):
                d.read("homing_status")
            assert d.link.transactions == sent  # refused before anything was sent


@pytest.mark.parametrize("protocol", ["mks-serial", "modbus-rtu"])
def test_homing_status_follows_go_home_on_the_switch_on_both_protocols(protocol: str, mks_firmware: str) -> None:
    """Homing on the linear axis's switch: 2 (not homed) -> 0 (going) -> 2 (stopped) -> 1 (homed), the single-turn
    status untouched (1); before V1.0.7 the one status reads 1 throughout and the homing status is refused."""
    with joints.open(axis_config(protocol=protocol)) as rig:
        j = rig.joints["carriage"]
        d = j.driver
        assert isinstance(d, MksDriver)

        def statuses() -> tuple[int, ...]:
            if _has_homing(mks_firmware):
                got = d.access.read_many(["go_back_to_zero_status", "homing_status"])
                return got["go_back_to_zero_status"], got["homing_status"]
            with pytest.raises(RegisterError, match="v1.0.9"):
                d.read("homing_status")
            return (d.read("go_back_to_zero_status"),)

        def expect(home: int) -> tuple[int, ...]:
            return (1, home) if _has_homing(mks_firmware) else (1,)

        j.enable()
        d.set_home(trigger_level=0, direction=0, speed=240, end_limit=0)  # CW = toward the low end (IN_1)
        assert statuses() == expect(2)
        d.go_home()
        rig.sleep(0.05)
        assert statuses() == expect(0)  # going
        j.stop()
        rig.sleep(0.05)
        assert statuses() == expect(2)  # stopped before it homed
        d.go_home()
        d.wait_motion(20)
        assert rig.world.joint_position("carriage") == pytest.approx(-0.075, abs=0.0002)
        assert statuses() == expect(1)
        assert _twin(rig, "carriage").home_status == 1


# -- FC16 0x0094 'noLimit' homing parameters: a request V1.0.6 added over Modbus (native 0x94 in every version) --


@pytest.mark.mks_firmware(None)
@pytest.mark.parametrize(("hm_mode", "frame"), [  # Modbus-RTU manual V1.0.9 5.4 / 5.5 / 5.6 (mode 2: V1.0.9's)
    (0, "01 10 00 94 00 04 08 00 00 20 00 00 00 02 58 83 CE"),
    (1, "01 10 00 94 00 04 08 00 00 20 00 00 01 02 58 D2 0E"),
    (2, "01 10 00 94 00 04 08 00 00 20 00 00 02 02 58 22 0E")])
def test_fc16_0x0094_is_the_manuals_frame(hm_mode: int, frame: str) -> None:
    from joints.codecs import modbus as mb

    block = MKS_MODBUS_OF["v1.0.6"].block(0x10, 0x94)
    words = block.words({"home_reverse_angle": 0x2000, "home_mode": hm_mode, "home_current": 600})
    assert mb.encode(mb.WriteMultipleRegisters(1, 0x94, words)) == bytes.fromhex(frame)
    assert mb.encode(mb.WriteMultipleRegistersReply(1, 0x94, 4)) == bytes.fromhex("01 10 00 94 00 04 80 26")
    assert MKS_MODBUS_OF["v1.0.5"].find(0x10, 0x94) is None  # not in the V1.0.5 Part 8


def test_nolimit_homing_over_modbus_from_v106(mks_firmware: str) -> None:
    """set_nolimit_home over Modbus: the twin holds what was sent and homes by stalling on the hard stop (one turn
    back off it); V1.0.5's Part 8 has no such request: refused before sending, and the twin answers exception 02."""

    with joints.open(axis_config(protocol="modbus-rtu")) as rig:
        j = rig.joints["carriage"]
        d = j.driver
        assert isinstance(d, MksDriver)
        fw = _twin(rig, "carriage")
        if mks_firmware == "v1.0.5":
            sent = d.link.transactions
            with pytest.raises(RegisterError, match="before firmware v1.0.6"):
                d.set_nolimit_home(reverse_angle=0x4000, mode=1, current=600)
            assert d.link.transactions == sent
            with pytest.raises(DeviceRejected) as raw:
                d.link.write_registers(1, 0x94, (0, 0x4000, 1, 600))
            assert raw.value.code == 2  # illegal data address
            assert fw.values["home_mode"] == 0
            return
        j.enable()
        d.set_home(direction=0, speed=240)
        d.set_nolimit_home(reverse_angle=0x4000, mode=1, current=600)  # back off one turn = 8 mm
        assert (fw.values["home_reverse_angle"], fw.values["home_mode"], fw.values["home_current"]) == (0x4000, 1, 600)
        d.go_home()
        d.wait_motion(30)
        rig.sleep(0.3)
        x = rig.world.joint_position("carriage")
        assert -0.08 + 0.008 - 0.008 < x < -0.08 + 0.008 + 0.002  # one turn off the hard stop at -80 mm
        assert abs(d.read("encoder_addition")) <= 2
