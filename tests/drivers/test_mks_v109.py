"""The MKS commands of firmware V1.0.6-V1.0.9, driver -> twin -> a state change observed, on both protocols
(native RS485 and Modbus) where the manuals give both, over every firmware profile that has the command; an
older profile refuses the call before anything is sent, naming the firmware that has it."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("mujoco")

from mkskit import open_motor

from joints.devices.quirks import MKS_FIRMWARES, firmware_profile
from joints.errors import RegisterError
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
