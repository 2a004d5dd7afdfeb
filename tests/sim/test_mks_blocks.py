"""MKS V1.0.6's read/write-all commands: the manual's 0x46 example, 0x47/0x46/0x48 between driver and twin,
confirmation, older firmware, and ``joints params dump/load`` using them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("mujoco")
pytestmark = pytest.mark.mks_firmware

from mkskit import motor_config, motor_model, open_motor

from joints.cli import main
from joints.cli.tomlout import dumps
from joints.codecs import mks
from joints.devices.mks import blocks
from joints.errors import ConfirmationRequired, RegisterError

#: manual V1.0.9 5.7.1 "The default write parameters are as follows" (the last byte 6C the checksum)
EXAMPLE_0x46 = bytes.fromhex("FA 01 46 02 0C 80 04 10 00 00 00 00 01 04 01 00 01 01 00 00 00 00 "
                             "00 3C 00 00 00 20 00 00 03 20 00 00 00 02 00 6C")


def test_the_manuals_0x46_example_decodes_to_the_documented_defaults() -> None:
    codec = mks.MksCodec(mks.Role.DEVICE)
    codec.feed(EXAMPLE_0x46)
    msg = codec.next_message()
    assert isinstance(msg, mks.WriteAllParameters) and mks.encode(msg) == EXAMPLE_0x46
    values = blocks.unpack(blocks.ALL_PARAMETERS, msg.params)
    assert {k: values[k] for k in ("work_mode", "working_current", "holding_current", "microsteps", "baud_rate",
                                   "slave_address", "slave_respond", "slave_active", "home_speed",
                                   "home_reverse_angle", "home_current", "zero_mode_speed")} == {
        "work_mode": 2, "working_current": 3200, "holding_current": 4, "microsteps": 16, "baud_rate": 4,
        "slave_address": 1, "slave_respond": 1, "slave_active": 1, "home_speed": 60, "home_reverse_angle": 0x2000,
        "home_current": 800, "zero_mode_speed": 2}
    assert blocks.pack(blocks.ALL_PARAMETERS, values, 34) == msg.params


@pytest.mark.mks_firmware("v1.0.6", "v1.0.9")
def test_read_and_write_all_parameters_round_trip_with_the_twin(tmp_path: Path, mks_firmware: str) -> None:
    with open_motor(tmp_path, joint={"firmware": mks_firmware}) as rig:
        d = rig.joints["m1"].driver
        fw = rig.world.drives["m1"]
        got = d.read_all_parameters()
        assert got == {n: fw.values[n] for n, _o, _s in blocks.ALL_PARAMETERS if n not in blocks.NOT_READ_BACK}
        sent = d.link.transactions
        with pytest.raises(ConfirmationRequired):
            d.write_all_parameters({"working_current": 1200}, confirm=False)
        assert d.link.transactions == sent  # nothing was sent
        d.write_all_parameters({"working_current": 1200, "microsteps": 256, "holding_current": 2}, confirm=True)
        assert (fw.values["working_current"], fw.values["microsteps"], fw.values["holding_current"]) == (1200, 256, 2)
        assert fw.current == pytest.approx(1.2) and d.microsteps == 256  # the twin runs on them, the driver knows
        assert d.read_all_parameters()["working_current"] == 1200
        with pytest.raises(RegisterError, match="0x46 carries no"):
            d.write_all_parameters({"motor_enable": 1}, confirm=True)
        status = d.read_all_status()
        singles = d.access.read_many(("encoder_addition", "motor_status", "en_pin_status", "protection_state"))
        assert {k: status[k] for k in singles} == singles


@pytest.mark.mks_firmware("v1.0.5")
def test_before_v106_the_blocks_are_refused_and_the_twin_ignores_them(tmp_path: Path) -> None:
    with open_motor(tmp_path) as rig:
        d = rig.joints["m1"].driver
        with pytest.raises(RegisterError, match="v1.0.6"):
            d.read_all_parameters()
        assert rig.world.buses["rs485"].receive(mks.encode(mks.ReadAllParameters(1))) == b""


def test_params_dump_reads_the_write_only_settings_by_0x47_where_the_firmware_has_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], mks_firmware: str) -> None:
    readable = mks_firmware != "v1.0.5"  # 0x47 came with V1.0.6
    cfg = motor_config(motor_model(tmp_path))
    path = tmp_path / "mks.toml"
    path.write_text(dumps(cfg))
    assert main(["params", "dump", str(path), "m1", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    if readable:
        assert data["settings"]["working_current"] == 1600 and data["settings"]["microsteps"] == 16
        assert data["identity"]["slave_address"] == 1
        assert "working_current" not in data.get("not_readable", {})
    else:
        assert data["not_readable"]["working_current"] == "not readable"


@pytest.mark.mks_firmware("v1.0.6", "v1.0.9")
def test_params_load_with_confirm_writes_the_differences_in_one_0x46(tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    cfg = motor_config(motor_model(tmp_path))
    path = tmp_path / "mks.toml"
    path.write_text(dumps(cfg))
    dump = tmp_path / "m1.toml"
    assert main(["params", "dump", str(path), "m1", "-o", str(dump)]) == 0
    text = dump.read_text()
    assert "working_current = 1600" in text and "key_lock = 0" in text
    dump.write_text(text.replace("working_current = 1600", "working_current = 1100")
                    .replace("key_lock = 0", "key_lock = 1"))
    capsys.readouterr()
    sent: list[object] = []
    from joints.sim.mks_front import MksNativeFront
    handle = MksNativeFront.handle

    def spy(self: MksNativeFront, request: object, *, answer: bool = True) -> object:
        sent.append(request)
        return handle(self, request, answer=answer)

    MksNativeFront.handle = spy  # type: ignore[method-assign]
    try:
        assert main(["params", "load", str(path), "m1", str(dump), "--apply", "--confirm"]) == 0
    finally:
        MksNativeFront.handle = handle  # type: ignore[method-assign]
    writes = [m for m in sent if isinstance(m, mks.WriteAllParameters)]
    assert len(writes) == 1 and not any(isinstance(m, (mks.SetWorkingCurrent, mks.SetKeyLock)) for m in sent)
    values = blocks.unpack(blocks.ALL_PARAMETERS, writes[0].params)
    assert (values["working_current"], values["key_lock"], values["slave_address"]) == (1100, 1, 1)
