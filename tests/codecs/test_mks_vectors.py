"""Golden frames of the MKS SERVO42D/57D manual against the native codec and the Modbus-mode table.

Source: ``tests/data/vectors.json`` (schema in its README, deviations in ERRATA.md). Every MKS
record (native vectors and command templates; Modbus-mode vectors): the corrected frame
(``correct_hex``, checksum completed where the manual omits it) decodes in its role to the
documented fields and re-encodes byte-exact; every printed frame the errata correct is rejected
(or decodes to something else) as its erratum kind predicts; every MKS sequence's frames decode.
Modbus-mode frames go through :mod:`joints.codecs.modbus` and are checked against
:data:`joints.devices.mks.modbus.MKS_MODBUS` (register, count, value, the 0x90 quirk).
"""

from __future__ import annotations

from itertools import chain
from typing import Any

import pytest

from joints.codecs import mks
from joints.codecs import modbus as mb
from joints.codecs.crc import crc_ok
from joints.devices.mks.modbus import FC_READ, FC_WRITE_MULTIPLE, FC_WRITE_SINGLE, MKS_MODBUS, MKS_MODBUS_OF
from joints.devices.mks.params import MKS_PARAMS
from joints.errors import ByteCountError, ChecksumError, FrameError
from testdata import by_id, records, sequences

RECORDS = records()
BY_ID = by_id()
NATIVE = [r for r in RECORDS if r.get("protocol") == "mks-native" and r.get("record_type") in ("vector", "template")]
MODBUS = [r for r in RECORDS if r.get("record_type") == "vector" and r.get("protocol") == "modbus-rtu"
          and r.get("device") == "mks-servo42d57d"]
SEQUENCES = sequences("mks-servo42d-57d")


def _ids(rs: list[dict[str, Any]]) -> list[Any]:
    return [pytest.param(r, id=r["id"]) for r in rs]


def _corrected(r: dict[str, Any]) -> bytes:
    return bytes.fromhex(r.get("correct_hex") or r["hex"])


def _decoded(r: dict[str, Any]) -> dict[str, Any]:
    return dict(r.get("decoded_corrected") or r["decoded"])


def _decode_all(role: Any, data: bytes, codec_type: Any = mks.MksCodec) -> list[Any]:
    codec = codec_type(role)
    codec.feed(data)
    codec.flush()
    out = []
    while (m := codec.next_message()) is not None:
        out.append(m)
    assert codec.buffered == 0
    return out


def _native_role(r: dict[str, Any]) -> mks.Role:
    return mks.Role.DEVICE if r["direction"] == "request" else mks.Role.HOST


def test_the_vector_file_has_the_mks_records() -> None:
    assert (len(NATIVE), len(MODBUS), len(SEQUENCES)) == (61, 36, 2)


# --------------------------------------------------------------------------------- native

#: vector key -> message attribute
_FIELD_NAMES = {"dir": "direction", "speed": "speed", "acc": "acc", "pulses": "pulses", "absPulses": "abs_pulses",
                "relAxis": "rel_axis", "absAxis": "abs_axis", "carry": "carry", "value": "value",
                "status": "status"}


def _check_fields(msg: Any, doc: dict[str, Any]) -> None:
    assert msg.address == doc["slave"]
    assert msg.function == int(doc["function"], 16)
    for key, attr in _FIELD_NAMES.items():
        if key in doc:
            assert getattr(msg, attr) == doc[key], key
    if "state" in doc:  # 0xFF save/clean
        assert msg.state == int(doc["state"], 16)
    if doc.get("address_kind", "").startswith("broadcast"):
        assert msg.address == mks.BROADCAST
    if "data" in doc:  # 0x80: the documented data byte 00
        assert isinstance(msg, mks.Calibrate) and doc["data"] == 0


@pytest.mark.parametrize("record", _ids(NATIVE))
def test_native_frame_decodes_to_its_fields_and_reencodes(record: dict[str, Any]) -> None:
    frame = _corrected(record)
    assert mks.checksum_ok(frame)
    doc = _decoded(record)
    if "checksum" in doc:
        assert frame[-1] == int(doc["checksum"], 16)
    msgs = _decode_all(_native_role(record), frame)
    assert len(msgs) == 1
    msg = msgs[0]
    assert mks.encode(msg) == frame
    if "commands" in doc:
        assert isinstance(msg, mks.LongPacket) and len(frame) == mks.LONG_PACKET_LENGTH
        assert len(doc["commands"]) == len(msg.commands)
        for sub, cmd in zip(doc["commands"], msg.commands):
            _check_fields(cmd, sub)
    else:
        _check_fields(msg, doc)
    # byte by byte gives the same message
    codec = mks.MksCodec(_native_role(record))
    got = []
    for b in frame:
        codec.feed(bytes((b,)))
        while (m := codec.next_message()) is not None:
            got.append(m)
    assert got == [msg]


NATIVE_ERRATA = [r for r in NATIVE if r.get("correct_hex") or r.get("check") != "ok"]


@pytest.mark.parametrize("record", _ids(NATIVE_ERRATA))
def test_printed_native_frame_is_rejected_as_its_erratum_predicts(record: dict[str, Any]) -> None:
    printed = bytes.fromhex(record["hex"])
    kind = record["erratum_kind"]
    role = _native_role(record)
    if kind in ("checksum-omitted", "template-checksum-placeholder"):
        assert record["checksum_omitted"]
        assert mks.with_checksum(printed) == _corrected(record)
        with pytest.raises(FrameError, match="truncated"):
            _decode_all(role, printed)
    elif kind == "bad-checksum":
        with pytest.raises(ChecksumError):
            _decode_all(role, printed)
    elif kind == "missing-byte":  # the 50-byte long-packet log line
        assert len(printed) == mks.LONG_PACKET_LENGTH - 2
        assert mks.checksum_ok(printed)  # sum-8 cannot see the missing zero bytes ...
        with pytest.raises(FrameError, match="truncated"):  # ... the fixed 52-byte length does
            _decode_all(role, printed)
    elif kind == "description":  # genuine bytes, imprecise prose: the printed 01 is "started"
        (msg,) = _decode_all(role, printed)
        (corrected,) = _decode_all(role, _corrected(record))
        assert msg.status is mks.RunStatus.STARTED and corrected.status is mks.RunStatus.COMPLETE
        assert not msg.is_completion and corrected.is_completion
    else:
        pytest.fail(f"unhandled erratum kind {kind}")


def test_long_packet_listing_and_log_are_the_same_frame_once_corrected() -> None:
    listing = BY_ID["mks-native-5.7-longpacket-send"]
    log = BY_ID["mks-native-5.7-longpacket-log-send"]
    assert _corrected(listing) == _corrected(log)


def test_group_examples_differ_only_in_address() -> None:
    msgs = [_decode_all(mks.Role.DEVICE, _corrected(BY_ID[f"mks-native-5.2.16-group-ex{i}-send"]))[0]
            for i in (1, 2, 3, 4)]
    assert [m.address for m in msgs] == [1, mks.BROADCAST, 0x50, 0x51]
    assert len({(m.speed, m.acc, m.pulses) for m in msgs}) == 1


# --------------------------------------------------------------------------------- sequences


@pytest.mark.parametrize("seq", _ids(SEQUENCES))
def test_every_sequence_frame_decodes(seq: dict[str, Any]) -> None:
    wire_replies = b""
    expected_replies: list[Any] = []
    for step in seq["steps"]:
        if "send_hex" not in step:
            continue
        (request,) = _decode_all(mks.Role.DEVICE, bytes.fromhex(step["send_hex"]))
        assert mks.encode(request) == bytes.fromhex(step["send_hex"])
        replies = [step["expect_hex"]] + [BY_ID[x]["hex"] for x in step.get("extra_responses", [])]
        if "expect_hex_alternative" in step:
            replies.append(step["expect_hex_alternative"])
        for text in replies:
            (reply,) = _decode_all(mks.Role.HOST, bytes.fromhex(text))
            assert isinstance(reply, mks.RunReply) and reply.function == request.function
            assert reply.address == request.address
            wire_replies += bytes.fromhex(text)
            expected_replies.append(reply)
        first = _decode_all(mks.Role.HOST, bytes.fromhex(step["expect_hex"]))[0]
        assert not first.is_completion  # the immediate answer
        for x in step.get("extra_responses", []):
            assert _decode_all(mks.Role.HOST, bytes.fromhex(BY_ID[x]["hex"]))[0].is_completion
    # the replies back to back, byte by byte, give the same messages
    codec = mks.MksCodec(mks.Role.HOST)
    got = []
    for b in wire_replies:
        codec.feed(bytes((b,)))
        while (m := codec.next_message()) is not None:
            got.append(m)
    assert got == expected_replies


# --------------------------------------------------------------------------------- Modbus mode


def _mb_decode(record: dict[str, Any], frame: bytes) -> list[Any]:
    role = mb.Role.DEVICE if record["direction"] == "request" else mb.Role.HOST
    return _decode_all(role, frame, mb.ModbusRtuCodec)


_REGISTER_TYPES = {
    "carry:int32 + value:uint16": [("encoder_carry", "int32", 0, 4), ("encoder_value", "uint16", 4, 2)],
    "int48": [("encoder_addition", "int48", 0, 6)],
    "int16": [("real_time_speed", "int16", 0, 2)],
    "int32": [("angle_error", "int32", 0, 4)],
    # ERRATA DOC-MKS-4: Part 8 says uint32, 5.1 int32; the table reads int32 (same counter)
    "uint32 (native manual says int32)": [("number_of_pulses", "int32", 0, 4)],
}


@pytest.mark.parametrize("record", _ids(MODBUS))
def test_modbus_frame_decodes_against_the_mks_table(record: dict[str, Any]) -> None:
    """(The vectors are the V1.0.5 manual's frames: its firmware's map; 0x3B's V1.0.9 layout: test_mks_modbus_layout.)"""
    table = MKS_MODBUS_OF["v1.0.5"]
    frame = _corrected(record)
    assert crc_ok(frame)
    (msg,) = _mb_decode(record, frame)
    assert mb.encode(msg) == frame
    doc = _decoded(record)
    assert (msg.slave, msg.function) == (doc["slave"], doc["function"])
    if isinstance(msg, mb.ReadInputRegisters):
        assert msg.address == int(doc["start_register"], 16)
        block = table.block(FC_READ, msg.address)
        assert block.count == msg.count == doc["count"]
        kind = doc["register_type"]
        if kind == "uint8 in low byte":
            (f,) = block.fields
            assert (f.offset, f.size) == (1, 1)
        else:
            assert [(f.name, f.type, f.offset, f.size) for f in block.fields] == _REGISTER_TYPES[kind]
    elif isinstance(msg, (mb.WriteSingleRegister, mb.WriteSingleRegisterReply)):
        assert msg.address == int(doc["register_hex"], 16) and msg.value == doc["value"]
        block = table.block(FC_WRITE_SINGLE, msg.address)
        values = block.decode_words((msg.value,))
        for name, value in values.items():  # (0x91 also carries V1.0.9's goZeroMode: 0 in the V1.0.5 vector)
            MKS_PARAMS[name].check(value)  # a documented value of the parameter
        assert block.words(values) == (msg.value,)
    else:
        assert isinstance(msg, mb.WriteMultipleRegistersReply)
        assert msg.address == int(doc["start_register"], 16)
        block = table.block(FC_WRITE_MULTIPLE, msg.address)
        assert block.count == msg.count == doc["count"]


MODBUS_ERRATA = [r for r in MODBUS if r.get("correct_hex") or r.get("check") != "ok"]


@pytest.mark.parametrize("record", _ids(MODBUS_ERRATA))
def test_printed_modbus_frame_is_rejected_as_its_erratum_predicts(record: dict[str, Any]) -> None:
    printed = bytes.fromhex(record["hex"])
    kind = record["erratum_kind"]
    if kind == "bad-crc":  # CRC copied from 8.1.2
        with pytest.raises(ChecksumError):
            _mb_decode(record, printed)
    elif kind == "checksum-missing":  # blank CRC cells
        assert _corrected(record)[:-2] == printed
        with pytest.raises(FrameError, match="truncated"):
            _mb_decode(record, printed)
    else:
        pytest.fail(f"unhandled erratum kind {kind}")


def test_home_parameter_quirk_frame_is_the_data_the_twin_needs() -> None:
    """8.2 #20: 3 registers announced, 5 bytes sent (ERRATA DOC-MKS-5)."""
    block = MKS_MODBUS.block(FC_WRITE_MULTIPLE, 0x90)
    assert block.quirk and "DOC-MKS-5" in block.quirk
    assert (block.count, block.byte_count) == (3, 5)
    values = {"home_trigger_level": 1, "home_direction": 0, "home_speed": 120, "end_limit": 1}
    pdu = block.request_pdu(values)
    assert pdu == bytes.fromhex("00 90 00 03 05 01 00 00 78 01")
    frame = mb.encode(mb.UnsupportedRequest(1, FC_WRITE_MULTIPLE, pdu))  # what a driver sends
    device = mb.ModbusRtuCodec(mb.Role.DEVICE)
    device.feed(frame)
    with pytest.raises(ByteCountError) as info:  # a Modbus codec rejects it ...
        device.next_message()
    got = info.value.data
    assert got == frame and device.buffered == 0
    count, byte_count = int.from_bytes(got[4:6], "big"), got[6]
    assert block.accepts(count, byte_count)  # ... the twin recognises the documented frame
    assert block.decode(got[7:7 + byte_count]) == values
    assert not block.accepts(3, 6) and not block.accepts(2, 4)  # anything else: exception 03
    with pytest.raises(Exception, match="not whole registers"):
        block.words(values)
    # the reply is the printed one
    reply = BY_ID["mks-modbus-8.2.20-recv"]
    (msg,) = _mb_decode(reply, _corrected(reply))
    assert msg == mb.WriteMultipleRegistersReply(1, 0x90, block.count)


def test_every_modbus_vector_register_is_in_the_table() -> None:
    seen = set()
    for r in MODBUS:
        (msg,) = _mb_decode(r, _corrected(r))
        seen.add((msg.function, msg.address))
    for fn, address in seen:
        assert MKS_MODBUS.find(fn, address) is not None, (fn, hex(address))
    assert len(seen) == 24


def test_native_records_cover_the_run_commands() -> None:
    functions = {int(_decoded(r)["function"], 16) for r in NATIVE if "function" in _decoded(r)}
    functions |= {int(c["function"], 16) for c in chain.from_iterable(_decoded(r).get("commands", []) for r in NATIVE)}
    assert {0x30, 0x80, 0x91, 0x92, 0xF1, 0xF4, 0xF5, 0xF6, 0xF7, 0xFD, 0xFE, 0xFF} <= functions
