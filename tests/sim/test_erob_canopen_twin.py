"""The eRob CANopen twin: chapter-5 sequences replayed byte-exact, NMT gating, SDO aborts, the mode-change
refusal (0x08000022), PDOs on SYNC, the EDS the canopen package imports."""

from __future__ import annotations

from pathlib import Path

import can
import pytest

from joints.codecs import canopen as co
from joints.devices.erob.eds import eds_text
from joints.devices.erob.profiles import profile
from joints.sim.erob import ErobFirmware
from joints.sim.erob_canopen import CanopenFront, ErobCanopenBus
from joints.transports.can_sim import LockstepCanBus
from testdata import records


def write_eds(path: Path, node: int) -> Path:
    """The twin's EDS (joints.devices.erob.eds) as a file, for the canopen package."""
    path.write_text(eds_text(node), encoding="utf-8")
    return path


class Bench:
    """Twins on a timed bus of their own (no physics: replies do not depend on motion here)."""

    def __init__(self, nodes: tuple[int, ...] = (2,)) -> None:
        self.device = ErobCanopenBus()
        for n in nodes:
            self.device.add(CanopenFront(ErobFirmware(profile("eRob80H100"), n), n))
        self.device.tick(0.001)  # boot-ups
        self.bus = LockstepCanBus(medium=self.device.medium)
        while self.bus.recv(0.01) is not None:
            pass

    def exchange(self, can_id: int, data: bytes, *, remote: bool = False) -> list[can.Message]:
        if remote:
            msg = can.Message(arbitration_id=can_id, is_remote_frame=True, dlc=len(data), is_extended_id=False)
        else:
            msg = can.Message(arbitration_id=can_id, data=data, is_extended_id=False)
        self.bus.send(msg)
        out = []
        while (m := self.bus.recv(0.005)) is not None:
            out.append(m)
        return out

    def sdo(self, node: int, data: str) -> bytes:
        replies = self.exchange(0x600 + node, bytes.fromhex(data))
        assert len(replies) == 1 and replies[0].arbitration_id == 0x580 + node
        return bytes(replies[0].data)


SEQUENCES = [r for r in records() if r.get("record_type") == "sequence" and r["id"].startswith("seq-erob-canopen")]


@pytest.mark.parametrize("seq", SEQUENCES, ids=[s["id"] for s in SEQUENCES])
def test_chapter5_sequence_replays_byte_exact(seq: dict) -> None:
    b = Bench()
    checked = 0
    for step in seq["steps"]:
        replies = b.exchange(int(step["send_can_id"], 16), bytes.fromhex(step["send_hex"]))
        replies = [r for r in replies if r.arbitration_id != 0x182]  # TPDOs are not in the figures
        if step.get("expect_hex") is None:  # the figure prints no reply
            sdo = [r for r in replies if r.arbitration_id == 0x582]
            if step["send_can_id"] == "0x602":  # an SDO request: answered all the same, by its own index, no abort
                send = bytes.fromhex(step["send_hex"])
                assert len(sdo) == 1 and sdo[0].data[0] != 0x80 and bytes(sdo[0].data[1:4]) == send[1:4], step
            else:
                assert sdo == [], step
            continue
        assert replies, step
        assert f"0x{replies[0].arbitration_id:03X}" == step["expect_can_id"].upper().replace("0X", "0x")
        assert bytes(replies[0].data) == bytes.fromhex(step["expect_hex"]), step["comment"]
        checked += 1
    assert checked >= 2


def test_nmt_gates_sdo_and_pdos() -> None:
    b = Bench()
    b.exchange(0x000, bytes((co.NmtCommand.STOP, 2)))
    assert b.exchange(0x602, bytes.fromhex("40 41 60 00 00 00 00 00")) == []  # no SDO while STOPPED
    reply = b.exchange(0x702, b"\x00", remote=True)  # node guarding still answers: state 4, toggle 0
    assert [bytes(r.data) for r in reply] == [b"\x04"]
    reply = b.exchange(0x702, b"\x00", remote=True)
    assert [bytes(r.data) for r in reply] == [b"\x84"]  # the toggle alternates
    b.exchange(0x000, bytes((co.NmtCommand.ENTER_PRE_OPERATIONAL, 2)))
    assert b.exchange(0x080, b"") == []  # PRE-OPERATIONAL: SYNC, but no TPDO
    b.exchange(0x000, bytes((co.NmtCommand.START, 0)))
    assert [r.arbitration_id for r in b.exchange(0x080, b"")] == []  # power-on TPDO1 is event-driven (255)
    assert b.sdo(2, "2F 00 18 02 01 00 00 00")[0] == 0x60  # a valid PDO's transmission type may change


def test_sdo_aborts_and_mode_change_refused_while_enabled() -> None:
    b = Bench()
    assert b.sdo(2, "40 00 20 00 00 00 00 00") == bytes.fromhex("80 00 20 00 00 00 02 06")  # no object
    assert b.sdo(2, "40 18 10 09 00 00 00 00") == bytes.fromhex("80 18 10 09 11 00 09 06")  # no sub-index
    assert b.sdo(2, "2B 41 60 00 00 00 00 00") == bytes.fromhex("80 41 60 00 02 00 01 06")  # read-only
    assert b.sdo(2, "2F 60 60 00 06 00 00 00") == bytes.fromhex("80 60 60 00 30 00 09 06")  # homing: not in 0x6502
    assert b.sdo(2, "43 02 65 00 00 00 00 00") == bytes.fromhex("43 02 65 00 CD 03 00 00")  # supported modes
    b.sdo(2, "2F 60 60 00 08 00 00 00")  # CSP
    front = b.device.front(2)
    assert front is not None
    for cw in (0x06, 0x07, 0x0F):
        b.sdo(2, f"2B 40 60 00 {cw:02X} 00 00 00")
    front.firmware.time = 1.0  # the brake released
    front.tick(1.0)
    assert front.state.name == "OPERATION_ENABLED"
    assert b.sdo(2, "2F 60 60 00 01 00 00 00") == bytes.fromhex("80 60 60 00 22 00 00 08")
    b.sdo(2, "2B 40 60 00 07 00 00 00")  # disable operation -> SWITCHED ON: the mode may change
    assert b.sdo(2, "2F 60 60 00 01 00 00 00") == bytes.fromhex("60 60 60 00 00 00 00 00")


def test_pdo_mapping_and_sync_tpdos() -> None:
    b = Bench((3,))
    for data in ("23 00 18 01 83 01 00 80", "2F 00 18 02 01 00 00 00", "2F 00 1A 00 00 00 00 00",
                 "23 00 1A 02 20 00 64 60", "2F 00 1A 00 02 00 00 00", "23 00 18 01 83 01 00 00"):
        assert b.sdo(3, data)[0] == 0x60, data
    assert b.sdo(3, "23 00 1A 01 10 00 41 60")[0] == 0x80  # mapping of a valid PDO: refused
    b.exchange(0x000, bytes((co.NmtCommand.START, 3)))
    replies = b.exchange(0x080, b"")
    assert [r.arbitration_id for r in replies] == [0x183]
    sw, pos = co.unpack_pdo(((0x6041, 0, 16, False), (0x6064, 0, 32, True)), bytes(replies[0].data))
    assert sw & 0x4F == 0x40 and pos == 0  # SWITCH ON DISABLED, at 0


def test_eds_imports_with_the_canopen_package(tmp_path) -> None:  # type: ignore[no-untyped-def]
    canopen = pytest.importorskip("canopen")
    path = write_eds(tmp_path / "erob.eds", 2)
    od = canopen.import_od(str(path), 5)
    assert od[0x6041].name == "Statusword"
    assert od[0x1400][1].default == 0x205  # $NODEID+0x200 on node 5
    assert od[0x6502].default == 0x3CD
    assert od[0x1A00][1].default == 0x60410010
