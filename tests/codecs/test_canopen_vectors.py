"""Golden CANopen frames of the eRunner manual (chapter 5) against the codec and the eRob map.

Source: ``tests/data/vectors.json`` (schema in its README, deviations in ERRATA.md). Every
``canopen`` vector: classifies to its service and node, decodes to its documented fields, and the
message built from those fields re-encodes byte-exact to the corrected frame. The printed frames
the errata repair (9 data bytes in the screenshot text) are rejected as a classic CAN frame must
be. Every chapter-5 sequence: each frame classifies and decodes; SDO steps come out of our
:class:`SdoClient` byte-exact and its replies finish the transfer; an object dictionary built from
the eRob map answers each request through our :class:`SdoServer` with the printed reply.
"""

from __future__ import annotations

from typing import Any

import can
import pytest

from joints.codecs import canopen as co
from joints.devices import cia402
from joints.devices.cia402 import Mode
from joints.devices.erob.canopen import EROB_CANOPEN, ERUNNER_RPDO1, mode_change_allowed, name_at
from joints.errors import DeviceRejected, FrameError
from testdata import sequences, vectors

VECTORS = vectors("canopen", "erob")
SEQUENCES = [s for s in sequences("erob-erunner-can-canopen") if s["id"].startswith("seq-erob-canopen")]
OCR_NINE_BYTES = [r for r in VECTORS if len(r["manual_text"].split()) > 8]

SERVICE_KIND = {
    "NMT": co.Kind.NMT,
    "NMT error control (heartbeat/boot-up)": co.Kind.BOOT_UP,
    "SDO request (client->server)": co.Kind.SDO_RX,
    "SDO response (server->client)": co.Kind.SDO_TX,
    "RPDO1": co.Kind.RPDO1,
}
NMT_COMMAND = {"stop remote node": co.NmtCommand.STOP, "reset communication": co.NmtCommand.RESET_COMMUNICATION}
#: section of chapter 5 -> the mode its RPDO1 frames are sent in
SECTION_MODE = {"5.1": Mode.PP, "5.2": Mode.PV, "5.3": Mode.PT, "5.4": Mode.CSP, "5.5": Mode.CSV, "5.6": Mode.CST,
                "5.7": Mode.IP}
SIGNED = {"int8": True, "int16": True, "int32": True, "uint8": False, "uint16": False, "uint32": False}


def _params(records: list[dict[str, Any]]) -> list[Any]:
    return [pytest.param(r, id=r["id"]) for r in records]


def _frame(can_id: str, hex_text: str) -> can.Message:
    return can.Message(arbitration_id=int(can_id, 16), data=bytes.fromhex(hex_text), is_extended_id=False)


def _corrected(record: dict[str, Any]) -> can.Message:
    return _frame(record["can_id"], record.get("correct_hex") or record["hex"])


def _same(a: can.Message, b: can.Message) -> bool:
    return (a.arbitration_id, bytes(a.data), a.is_remote_frame, a.is_extended_id) == (
        b.arbitration_id, bytes(b.data), b.is_remote_frame, b.is_extended_id)


def _value_bytes(decoded: dict[str, Any]) -> bytes:
    size = int(decoded["kind"].split(",")[-1].split()[0])
    return int(decoded["value"]).to_bytes(size, "little", signed=SIGNED[decoded["value_type"]])


def _expected_message(record: dict[str, Any]) -> co.Message:
    """The message the documented fields describe (built without looking at the bytes)."""
    d = record.get("decoded_corrected") or record["decoded"]
    service, node = d["service"], d["node"]
    if service == "NMT":
        return co.Nmt(NMT_COMMAND[d["command"]], node)
    if service.startswith("NMT error control"):
        assert d["state"] == "boot-up"
        return co.BootUp(node)
    if service == "RPDO1":
        mode = SECTION_MODE[record["section"][:3]]
        rpdo = ERUNNER_RPDO1[mode]
        target = d["target_int32_le"]
        values = [int(d["controlword"], 16), target] if rpdo.objects[-1] != 16 else [int(d["controlword"], 16),
                                                                                    target & 0xFFFF, target >> 16]
        return co.Pdo(rpdo.cob_id(node), co.pack_pdo(rpdo.entries, values))
    index, sub, kind = int(d["index"], 16), d["subindex"], d["kind"]
    if kind.startswith("expedited download"):
        data = _value_bytes(d)
        return co.SdoDownloadInitiate(node, index, sub, data, True, len(data))
    if kind.startswith("upload request"):
        return co.SdoUploadInitiate(node, index, sub)
    if kind.startswith("download response"):
        return co.SdoDownloadInitiateResponse(node, index, sub)
    if kind.startswith("expedited upload response"):
        data = _value_bytes(d)
        return co.SdoUploadInitiateResponse(node, index, sub, data, True, len(data))
    raise AssertionError(f"undocumented kind {kind!r}")


# --------------------------------------------------------------------------------- vectors


def test_the_vector_set_is_the_one_described() -> None:
    assert len(VECTORS) == 102
    assert {r["decoded"]["service"] for r in VECTORS} == set(SERVICE_KIND)
    assert len(SEQUENCES) == 10
    assert len(OCR_NINE_BYTES) == 36  # ERRATA.md section E: "9 data bytes (one duplicated 00)"


@pytest.mark.parametrize("record", _params(VECTORS))
def test_vector_classifies_to_its_service_and_node(record: dict[str, Any]) -> None:
    d = record["decoded"]
    kind, node = co.classify(_corrected(record))
    assert kind is SERVICE_KIND[d["service"]]
    assert node == (0 if kind is co.Kind.NMT else d["node"])


@pytest.mark.parametrize("record", _params(VECTORS))
def test_vector_decodes_to_its_documented_fields(record: dict[str, Any]) -> None:
    d = record["decoded"]
    msg = co.decode(_corrected(record))
    assert msg == _expected_message(record)
    if isinstance(msg, co.Nmt):
        assert msg.command == int(d["command_specifier"], 16)
    if isinstance(msg, co.SdoDownloadInitiate | co.SdoUploadInitiateResponse):
        value = int.from_bytes(msg.data, "little", signed=SIGNED[d["value_type"]])
        assert value == d["value"]
        # the object's CANopen data type in the eRob map has the size the frame carries
        obj = EROB_CANOPEN.key(name_at(msg.index, msg.subindex))
        assert obj.size == len(msg.data)
        assert obj.decode(msg.data) == d["value"]
        assert d["ccs_scs"] == f"0x{record_command(record):02X}"
    if isinstance(msg, co.Pdo):
        cw = int(d["controlword"], 16)
        assert msg.data[:2] == cw.to_bytes(2, "little")
        bits = d["controlword_bits"]
        assert bool(cw & cia402.CW_SWITCH_ON) == bool(bits["switch_on"])
        assert bool(cw & cia402.CW_ENABLE_VOLTAGE) == bool(bits["enable_voltage"])
        assert bool(cw & cia402.CW_QUICK_STOP) == bool(bits["quick_stop_inactive"])
        assert bool(cw & cia402.CW_ENABLE_OPERATION) == bool(bits["enable_operation"])
        assert bool(cw & cia402.CW_NEW_SETPOINT) == bool(bits["bit4_new_setpoint_or_mode_specific"])
        assert bool(cw & cia402.CW_CHANGE_SET_IMMEDIATELY) == bool(bits["bit5_change_set_immediately_or_mode_specific"])


def record_command(record: dict[str, Any]) -> int:
    return bytes.fromhex(record.get("correct_hex") or record["hex"])[0]


@pytest.mark.parametrize("record", _params(VECTORS))
def test_vector_reencodes_byte_exact(record: dict[str, Any]) -> None:
    assert _same(co.encode(_expected_message(record)), _corrected(record))


@pytest.mark.parametrize("record", _params([r for r in VECTORS if r["decoded"]["service"] == "RPDO1"]))
def test_rpdo1_vectors_unpack_with_erunner_mapping(record: dict[str, Any]) -> None:
    d = record["decoded"]
    mode = SECTION_MODE[record["section"][:3]]
    rpdo = ERUNNER_RPDO1[mode]
    values = co.unpack_pdo(rpdo.entries, bytes.fromhex(record["hex"]))
    assert values[0] == int(d["controlword"], 16)
    assert values[1] == d["target_int32_le"]  # PT/CST: 16-bit torque, then 16 bits of padding (all 0 here)
    assert rpdo.size == 6 == len(bytes.fromhex(record["hex"]))
    command = cia402.command_of(values[0])
    assert command in (cia402.Command.ENABLE_OPERATION, cia402.Command.SHUTDOWN)


@pytest.mark.parametrize("record", _params(OCR_NINE_BYTES))
def test_printed_nine_byte_frames_are_rejected(record: dict[str, Any]) -> None:
    """ERRATA E: the screenshot text shows 9 data bytes; a classic CAN frame carries at most 8."""
    assert "9 data bytes" in record["erratum"] and record["erratum_kind"] == "ocr"
    printed = bytes.fromhex(record["manual_text"])
    assert len(printed) == 9
    frame = can.Message(arbitration_id=int(record["can_id"], 16), data=printed, is_extended_id=False)
    with pytest.raises(FrameError, match="at most 8"):
        co.decode(frame)
    # the repaired frame is the printed one minus one duplicated 00
    assert printed.replace(b"\x00", b"", 1) == bytes.fromhex(record["hex"]) or printed[:8] == bytes.fromhex(
        record["hex"])


# ------------------------------------------------------------------------------- sequences


class _Dictionary:
    """The eRob map as a dict-backed object dictionary (0x6061 shows the last 0x6060 written)."""

    def __init__(self) -> None:
        self.values: dict[str, int] = {}
        self.writes: list[tuple[str, int]] = []

    def read(self, index: int, subindex: int) -> bytes:
        name = name_at(index, subindex)
        if name == "modes_of_operation_display":
            name = "modes_of_operation"
        return EROB_CANOPEN.key(name).encode(self.values.get(name, EROB_CANOPEN.param(name).default))

    def write(self, index: int, subindex: int, data: bytes) -> None:
        name = name_at(index, subindex)
        obj = EROB_CANOPEN.key(name)
        if not obj.access.writable:
            raise DeviceRejected("read only", code=co.SdoAbortCode.WRITE_READ_ONLY)
        self.values[name] = obj.decode(data)
        self.writes.append((name, self.values[name]))


def _steps(sequence: dict[str, Any]) -> list[Any]:
    return [pytest.param(sequence, step, id=f"{sequence['id']}-{step['step'].replace(' ', '')}")
            for step in sequence["steps"]]


ALL_STEPS = [p for s in SEQUENCES for p in _steps(s)]


@pytest.mark.parametrize("sequence,step", ALL_STEPS)
def test_sequence_frames_classify_and_decode(sequence: dict[str, Any], step: dict[str, Any]) -> None:
    sent = _frame(step["send_can_id"], step["send_hex"])
    kind, _node = co.classify(sent)
    assert kind in (co.Kind.NMT, co.Kind.SDO_RX, co.Kind.RPDO1)
    co.decode(sent)
    if "expect_hex" in step:
        reply = _frame(step["expect_can_id"], step["expect_hex"])
        assert co.classify(reply).kind in (co.Kind.BOOT_UP, co.Kind.SDO_TX)
        assert co.classify(reply).node == 2
        co.decode(reply)


@pytest.mark.parametrize("sequence", [pytest.param(s, id=s["id"]) for s in SEQUENCES])
def test_sequence_replays_through_our_sdo_client_and_server(sequence: dict[str, Any]) -> None:
    od = _Dictionary()
    client = co.SdoClient(2)
    server = co.SdoServer(2, od.read, od.write)
    disabled = False
    for step in sequence["steps"]:
        sent = _frame(step["send_can_id"], step["send_hex"])
        msg = co.decode(sent)
        if isinstance(msg, co.Nmt):
            assert msg.node == 2
            assert _same(co.encode(co.Nmt(msg.command, 2)), sent)
            if msg.command is co.NmtCommand.RESET_COMMUNICATION:
                assert step["expect_hex"] == "00" and step["expect_can_id"] == "0x702"
                assert _same(co.encode(co.BootUp(2)), _frame(step["expect_can_id"], step["expect_hex"]))
                assert co.nmt_transition(co.NmtState.OPERATIONAL, msg.command) is co.NmtState.INITIALISING
            continue
        if isinstance(msg, co.Pdo):
            # fig 5-12 row 1: "disable" (shutdown) before the mode change, as section 5.1 requires
            (cw, _target) = co.unpack_pdo(ERUNNER_RPDO1[Mode.PP].entries, msg.data)
            state = cia402.next_state(cia402.State.OPERATION_ENABLED, cw)
            assert state is cia402.State.READY_TO_SWITCH_ON and mode_change_allowed(state)
            disabled = True
            continue
        assert isinstance(msg, co.SdoDownloadInitiate | co.SdoUploadInitiate)
        # the master side: our client produces the printed request ...
        if isinstance(msg, co.SdoDownloadInitiate):
            value = EROB_CANOPEN.key(name_at(msg.index, msg.subindex)).decode(msg.data)
            request = client.download(msg.index, msg.subindex,
                                      EROB_CANOPEN.key(name_at(msg.index, msg.subindex)).encode(value))
        else:
            request = client.upload(msg.index, msg.subindex)
        assert _same(request, sent)
        # ... the node side: a dictionary from the eRob map answers with the printed reply ...
        reply = server.feed(request)
        assert reply is not None
        if "expect_hex" in step:
            assert _same(reply, _frame(step["expect_can_id"], step["expect_hex"]))
        # ... and the client takes it as the end of the transfer
        result = client.feed(reply)
        assert isinstance(result, co.SdoDone)
        if isinstance(msg, co.SdoUploadInitiate):
            assert result.data == reply.data[4:4 + len(result.data)]
    assert not client.busy
    if "configuration" in sequence["title"]:
        # every configuration sets the mode of operation first (after NMT stop/reset and, where the drive
        # was enabled, a shutdown), as chapter 5 requires
        assert od.writes[0][0] == "modes_of_operation"
        assert Mode(od.writes[0][1]) in SECTION_MODE.values()
    else:  # the 'Apply' buttons write profile parameters only
        assert {name for name, _ in od.writes} <= {"profile_speed", "profile_acceleration", "profile_deceleration"}
    assert disabled == sequence["id"].endswith("fig5-12")
