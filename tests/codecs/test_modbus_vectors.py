"""Golden Modbus RTU frames of the eRob manuals (EN v1.6 + CN v1.3) against the codec.

Source: ``tests/data/vectors.json`` (vendored from ../shared/vectors) (schema in its README, deviations in ERRATA.md).
Every eRob ``modbus-rtu`` vector: the corrected frame decodes in the right role to the
documented fields and re-encodes byte-exact; every printed frame that the errata correct is
rejected (or decodes to something else) the way its erratum kind predicts. Every eRob Modbus
sequence is replayed step by step (request in device role, reply in host role).
"""

from __future__ import annotations

import json
from typing import Any

import pytest

from joints.codecs import modbus as mb
from joints.codecs.crc import crc16_modbus, crc_ok
from joints.errors import ByteCountError, ChecksumError, FrameError
from testdata import VECTORS


def _load() -> list[dict[str, Any]]:
    if not VECTORS.is_file():
        return []
    return json.loads(VECTORS.read_text(encoding="utf-8"))


RECORDS = _load()
BY_ID = {r["id"]: r for r in RECORDS if "id" in r}
EROB = [
    r
    for r in RECORDS
    if r.get("record_type") == "vector" and r.get("protocol") == "modbus-rtu" and r.get("device") == "erob"
]
EROB_ERRATA = [r for r in EROB if r.get("correct_hex")]
EROB_SEQUENCES = [
    r for r in RECORDS if r.get("record_type") == "sequence" and "erob-modbus-rtu" in str(r.get("manual", ""))
]
OTHER_MODBUS = [
    r
    for r in RECORDS
    if r.get("record_type") == "vector"
    and r.get("protocol") == "modbus-rtu"
    and r.get("device") in ("zlac8015d", "mks-servo42d57d")
]

pytestmark = pytest.mark.skipif(not RECORDS, reason=f"vector file not found: {VECTORS}")


def _params(records: list[dict[str, Any]]) -> list[Any]:
    if not records:
        # keep the parametrised tests collectable (and skipped) when the file is absent
        return [pytest.param(None, marks=pytest.mark.skip(reason=f"no vectors in {VECTORS}"))]
    return [pytest.param(r, id=r["id"]) for r in records]


# --------------------------------------------------------------------------------- helpers


def _bytes(hex_text: str) -> bytes:
    return bytes.fromhex(hex_text)


def _corrected(record: dict[str, Any]) -> bytes:
    return _bytes(record.get("correct_hex") or record["hex"])


def _decoded(record: dict[str, Any]) -> dict[str, Any]:
    return record.get("decoded_corrected") or record["decoded"]


def _decode_all(codec: mb.ModbusRtuCodec, data: bytes, *, flush: bool = True) -> list[mb.Message]:
    codec.feed(data)
    if flush:
        codec.flush()
    out = []
    while (msg := codec.next_message()) is not None:
        out.append(msg)
    return out


def _decode_request(frame: bytes) -> mb.Message:
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    msgs = _decode_all(codec, frame)
    assert len(msgs) == 1, msgs
    assert codec.buffered == 0
    return msgs[0]


def _host_codec(request: mb.Message | None) -> mb.ModbusRtuCodec:
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    if request is not None:
        codec.expect_reply_to(request)  # type: ignore[arg-type]
    return codec


def _paired_request(record: dict[str, Any]) -> mb.Message | None:
    pair = record.get("pair")
    if not pair:
        return None
    return _decode_request(_corrected(BY_ID[pair]))


def _decode_corrected(record: dict[str, Any]) -> mb.Message:
    frame = _corrected(record)
    if record["direction"] == "request":
        return _decode_request(frame)
    assert record["direction"] == "response"
    codec = _host_codec(_paired_request(record))
    msgs = _decode_all(codec, frame)
    assert len(msgs) == 1, msgs
    assert codec.buffered == 0
    return msgs[0]


def _typed_to_words(values: list[dict[str, Any]]) -> list[int]:
    """The vector's typed values -> register words (int32: Hi word first, two's complement)."""
    words: list[int] = []
    for v in values:
        kind, value = v["type"], v["value"]
        if kind in ("int32", "uint32"):
            raw = value & 0xFFFFFFFF
            if "raw_u32" in v:
                assert v["raw_u32"] == raw
            words += [raw >> 16, raw & 0xFFFF]
        else:
            assert kind in ("uint16", "int16"), kind
            words.append(value & 0xFFFF)
    return words


def _words_to_typed(words: tuple[int, ...], values: list[dict[str, Any]]) -> list[int]:
    """Register words -> typed values laid out like the vector's ``values`` list."""
    out, i = [], 0
    for v in values:
        if v["type"] in ("int32", "uint32"):
            raw = (words[i] << 16) | words[i + 1]
            if v["type"] == "int32" and raw & 0x80000000:
                raw -= 0x100000000
            out.append(raw)
            i += 2
        else:
            raw = words[i]
            if v["type"] == "int16" and raw & 0x8000:
                raw -= 0x10000
            out.append(raw)
            i += 1
    assert i == len(words), "typed values do not cover every word"
    return out


def _register(d: dict[str, Any]) -> int:
    text = d.get("start_register") or d.get("register_hex")
    return int(str(text).split()[0], 16)


# ----------------------------------------------------------------------------- the corpus


def test_corpus_is_complete() -> None:
    """Both manuals, all function codes and every erratum kind the assertions rely on."""
    manuals = {r["manual"] for r in EROB}
    assert any("v1.6-en" in m for m in manuals) and any("v1.3-zh" in m for m in manuals)
    assert len(EROB) >= 250
    assert {_decoded(r)["function"] for r in EROB} == {3, 6, 16}
    kinds = {k for r in EROB_ERRATA for k in r["erratum_kind"].split("+")}
    assert {
        "crc-byte-order",
        "missing-byte",
        "byte-count",
        "wrong-slave",
        "wrong-register",
        "response-mismatch",
        "bad-crc",
    } <= kinds
    assert len({r["id"] for r in EROB}) == len(EROB)
    assert EROB_SEQUENCES


# ------------------------------------------------------------------------- corrected frames


@pytest.mark.parametrize("record", _params(EROB))
def test_corrected_frame_decodes_to_documented_fields(record: dict[str, Any]) -> None:
    frame = _corrected(record)
    assert crc_ok(frame)
    d = _decoded(record)
    msg = _decode_corrected(record)
    assert msg.slave == d["slave"]
    assert msg.function == d["function"]
    fc = d["function"]

    if record["direction"] == "request":
        if fc == mb.READ_HOLDING_REGISTERS:
            assert isinstance(msg, mb.ReadHoldingRegisters)
            assert msg.address == _register(d)
            assert msg.count == d["count"]
        elif fc == mb.WRITE_SINGLE_REGISTER:
            assert isinstance(msg, mb.WriteSingleRegister)
            assert msg.address == _register(d)
            assert msg.value == d["value"] & 0xFFFF
            if "value_int16" in d:
                signed = msg.value - 0x10000 if msg.value & 0x8000 else msg.value
                assert signed == d["value_int16"]
        elif fc == mb.WRITE_MULTIPLE_REGISTERS:
            assert isinstance(msg, mb.WriteMultipleRegisters)
            assert msg.address == _register(d)
            assert len(msg.values) == d["count"]
            assert 2 * len(msg.values) == d["byte_count"]
            assert list(msg.values) == d["data_words"]
            assert list(msg.values) == _typed_to_words(d["values"])
            assert _words_to_typed(msg.values, d["values"]) == [v["value"] for v in d["values"]]
            # each typed value sits at its register: consecutive from the start address
            addr = msg.address
            for v in d["values"]:
                assert int(v["register"], 16) == addr
                addr += 2 if v["type"] in ("int32", "uint32") else 1
        else:  # pragma: no cover - corpus check guards this
            pytest.fail(f"unexpected function {fc}")
    else:
        request = _paired_request(record)
        assert request is not None
        assert request.slave == msg.slave and request.function == msg.function
        if fc == mb.READ_HOLDING_REGISTERS:
            assert isinstance(msg, mb.ReadRegistersReply)
            assert 2 * len(msg.values) == d["byte_count"]
            assert list(msg.values) == d["data_words"]
            assert list(msg.values) == _typed_to_words(d["values"])
            assert _words_to_typed(msg.values, d["values"]) == [v["value"] for v in d["values"]]
            assert isinstance(request, mb.ReadHoldingRegisters)
            assert len(msg.values) == request.count
            assert int(d["values"][0]["register"], 16) == request.address == _register(d)
        elif fc == mb.WRITE_SINGLE_REGISTER:
            assert isinstance(msg, mb.WriteSingleRegisterReply)
            assert msg.address == _register(d)
            assert msg.value == d["value"] & 0xFFFF
            # an FC06 reply echoes the request
            assert isinstance(request, mb.WriteSingleRegister)
            assert (msg.address, msg.value) == (request.address, request.value)
        elif fc == mb.WRITE_MULTIPLE_REGISTERS:
            assert isinstance(msg, mb.WriteMultipleRegistersReply)
            assert msg.address == _register(d)
            assert msg.count == d["count"]
            assert isinstance(request, mb.WriteMultipleRegisters)
            assert (msg.address, msg.count) == (request.address, len(request.values))
        else:  # pragma: no cover
            pytest.fail(f"unexpected function {fc}")

    # the CRC as the vector records it (low byte first on the wire)
    assert frame[-2:] == _bytes(d["crc_bytes_lo_hi"])
    assert frame[-2:] == crc16_modbus(frame[:-2]).to_bytes(2, "little")


@pytest.mark.parametrize("record", _params(EROB))
def test_corrected_frame_reencodes_byte_exact(record: dict[str, Any]) -> None:
    frame = _corrected(record)
    msg = _decode_corrected(record)
    assert mb.encode(msg) == frame
    assert mb.ModbusRtuCodec.encode(msg) == frame


@pytest.mark.parametrize("record", _params(EROB))
def test_corrected_frame_decodes_byte_by_byte(record: dict[str, Any]) -> None:
    """RTU has no length field: the frame end must be found from the header alone."""
    frame = _corrected(record)
    expected = _decode_corrected(record)
    if record["direction"] == "request":
        codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    else:
        codec = _host_codec(_paired_request(record))
    got = []
    for i in range(len(frame)):
        codec.feed(frame[i : i + 1])
        msg = codec.next_message()
        if i < len(frame) - 1:
            assert msg is None, f"message after {i + 1} of {len(frame)} bytes"
        else:
            got.append(msg)
    assert got == [expected]
    assert codec.buffered == 0 and codec.discarded == 0


# --------------------------------------------------------------------------- printed errors

#: what the printed frame of each erratum kind does (by the vectors' own analysis)
_DIFFERS = "decodes to a different message"


def _expected_outcome(kind: str, printed: bytes) -> type[Exception] | str:
    kinds = set(kind.split("+"))
    if "missing-byte" in kinds:
        return FrameError
    if "byte-count" in kinds:
        return ByteCountError
    if kinds & {"crc-byte-order", "bad-crc"}:
        return ChecksumError
    if "wrong-slave" in kinds:
        # the slave byte was copied together with its frame's CRC: a valid frame for slave 2
        assert crc_ok(printed)
        return _DIFFERS
    if kinds & {"wrong-register", "response-mismatch"}:
        # the printed CRC belongs to the intended frame, so the typo breaks the CRC
        assert not crc_ok(printed)
        return ChecksumError
    pytest.fail(f"no expectation for erratum kind {kind!r}")


@pytest.mark.parametrize("record", _params(EROB_ERRATA))
def test_printed_frame_is_rejected_or_differs(record: dict[str, Any]) -> None:
    printed = _bytes(record["hex"])
    corrected = _decode_corrected(record)
    assert printed != _corrected(record)
    outcome = _expected_outcome(record["erratum_kind"], printed)

    if record["direction"] == "request":
        codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    else:
        codec = _host_codec(_paired_request(record))

    codec.feed(printed)
    if outcome is FrameError:
        # a frame with a byte missing waits for that byte; only silence ends it
        assert codec.next_message() is None
        codec.flush()
        with pytest.raises(FrameError) as info:
            codec.next_message()
        assert type(info.value) is FrameError  # truncated, not a CRC or byte-count error
        assert info.value.data == printed
        assert codec.next_message() is None
        assert codec.buffered == 0
        return

    codec.flush()
    if outcome is _DIFFERS:
        msgs = []
        while (msg := codec.next_message()) is not None:
            msgs.append(msg)
        assert len(msgs) == 1
        assert msgs[0] != corrected
        assert type(msgs[0]) is type(corrected)
        assert msgs[0].slave != corrected.slave  # wrong-slave: only the slave differs
        assert mb.encode(msgs[0]) == printed
        return

    assert isinstance(outcome, type)
    with pytest.raises(outcome) as info:
        codec.next_message()
    if outcome is ChecksumError:
        assert not crc_ok(printed)
        assert info.value.data == printed
    # whatever follows the rejected head is garbage, never a message
    while True:
        try:
            msg = codec.next_message()
        except FrameError:
            continue
        assert msg is None
        break


@pytest.mark.parametrize(
    "record",
    _params([r for r in EROB_ERRATA if "byte-count" in r["erratum_kind"].split("+")]),
)
def test_byte_count_error_without_request_is_still_rejected(record: dict[str, Any]) -> None:
    """Without the request the printed 02-byte-count reply fails its CRC at the short length."""
    printed = _bytes(record["hex"])
    assert crc_ok(printed)  # the manual's CRC covers the malformed frame
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.feed(printed)
    codec.flush()
    msgs, errors = [], []
    while True:
        try:
            msg = codec.next_message()
        except FrameError as exc:
            errors.append(exc)
            continue
        if msg is None:
            break
        msgs.append(msg)
    assert errors
    assert _decode_corrected(record) not in msgs


# -------------------------------------------------------------------------------- sequences


def _sequence_steps() -> list[Any]:
    out = []
    for seq in EROB_SEQUENCES:
        for step in seq["steps"]:
            if "send_hex" in step:
                out.append(pytest.param(seq, step, id=f"{seq['id']}-step{step['step']}"))
    return out or [pytest.param(None, None, marks=pytest.mark.skip(reason="no sequences"))]


@pytest.mark.parametrize(("sequence", "step"), _sequence_steps())
def test_sequence_step_replays(sequence: dict[str, Any], step: dict[str, Any]) -> None:
    send = _bytes(step["send_hex"])
    request = _decode_request(send)
    assert isinstance(request, (mb.ReadHoldingRegisters, mb.WriteSingleRegister, mb.WriteMultipleRegisters))
    assert mb.encode(request) == send
    if step.get("request"):
        assert send == _corrected(BY_ID[step["request"]])
    expect = step.get("expect_hex")
    if expect is None:
        assert not step.get("response")
        return
    reply_frame = _bytes(expect)
    codec = _host_codec(request)
    replies = _decode_all(codec, reply_frame)
    assert len(replies) == 1
    reply = replies[0]
    assert mb.encode(reply) == reply_frame
    assert reply.slave == request.slave and reply.function == request.function
    if isinstance(request, mb.ReadHoldingRegisters):
        assert isinstance(reply, mb.ReadRegistersReply)
        assert len(reply.values) == request.count
    elif isinstance(request, mb.WriteSingleRegister):
        assert reply == mb.WriteSingleRegisterReply(request.slave, request.address, request.value)
        assert reply_frame == send  # FC06 reply echoes the request
    else:
        assert reply == mb.WriteMultipleRegistersReply(request.slave, request.address, len(request.values))
    if step.get("response"):
        assert reply_frame == _corrected(BY_ID[step["response"]])


@pytest.mark.parametrize("sequence", _params(EROB_SEQUENCES))
def test_sequence_as_one_stream(sequence: dict[str, Any]) -> None:
    """All requests of a sequence back to back on one device codec, all replies on one host codec."""
    steps = [s for s in sequence["steps"] if "send_hex" in s]
    assert steps
    device = mb.ModbusRtuCodec(mb.Role.DEVICE)
    requests = _decode_all(device, b"".join(_bytes(s["send_hex"]) for s in steps), flush=False)
    assert [mb.encode(r) for r in requests] == [_bytes(s["send_hex"]) for s in steps]
    host = mb.ModbusRtuCodec(mb.Role.HOST)
    for step, request in zip(steps, requests):
        if step.get("expect_hex") is None:
            continue
        host.expect_reply_to(request)  # type: ignore[arg-type]
        host.feed(_bytes(step["expect_hex"]))
        reply = host.next_message()
        assert reply is not None and mb.encode(reply) == _bytes(step["expect_hex"])
        assert host.next_message() is None


# ------------------------------------------------- other devices: CRC + framing round trip


@pytest.mark.parametrize("record", _params(OTHER_MODBUS))
def test_other_modbus_devices_crc_and_round_trip(record: dict[str, Any]) -> None:
    """ZLAC8015D and MKS Modbus frames: the corrected frame has a valid low-first CRC, frames in
    its role and re-encodes byte-exact (register meanings are not checked here)."""
    if not record.get("correct_hex") and record.get("check") != "ok":
        pytest.skip("printed frame is known bad and has no correction")
    frame = _corrected(record)
    assert crc_ok(frame)
    assert frame[-2:] == crc16_modbus(frame[:-2]).to_bytes(2, "little")
    msg = _decode_corrected(record)
    assert not isinstance(msg, mb.UnsupportedRequest)
    assert msg.slave == frame[0] and msg.function == frame[1]
    assert mb.encode(msg) == frame
