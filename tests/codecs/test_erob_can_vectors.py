"""Golden frames of the eRunner manual (CAN custom protocol, chapters 4 and 7) against the codec.

Every ``erob-can`` vector of tests/data/vectors.json: the corrected frame decodes in its role to
the documented fields and re-encodes byte-exact. Printed frames that the errata correct are
rejected the way the erratum predicts; OCR-damaged printings that are hex are not valid replies.
Every request/reply pair (vector ``pair`` links and the 7.x/figure sequences) satisfies
``answers``, and no reply answers the same request sent to another node.
"""

from __future__ import annotations

import string
from typing import Any

import can
import pytest

from joints.codecs import erob_can as ec
from joints.errors import ByteCountError, FrameError
from testdata import by_id, sequences, vectors

VECTORS = vectors("erob-can", "erob")
ERRATA = [r for r in VECTORS if r.get("correct_hex")]
SEQUENCES = [s for s in sequences("erunner") if s["id"].startswith("seq-erob-can-")]
PAIRS = [r for r in VECTORS if r["direction"] == "response" and r.get("pair")]


def _frame(can_id: str, hex_data: str) -> can.Message:
    return can.Message(arbitration_id=int(can_id, 16), data=bytes.fromhex(hex_data), is_extended_id=False)


def _role(record: dict[str, Any]) -> ec.Role:
    return ec.Role.DEVICE if record["direction"] == "request" else ec.Role.HOST


def _corrected(record: dict[str, Any]) -> can.Message:
    return _frame(record["can_id"], record.get("correct_hex") or record["hex"])


def _int(v: int | str) -> int:
    return v if isinstance(v, int) else int(v, 16)


def _expected(record: dict[str, Any]) -> ec.Message:
    """The message the record's documented decode describes."""
    d = record.get("decoded_corrected") or record["decoded"]
    node, kind = d["node"], d["kind"]
    if kind == "write (no subindex)":
        assert d["value_type"] == "int32"
        return ec.Write(node, _int(d["index"]), d["value"])
    if kind == "read (no subindex)":
        return ec.Read(node, _int(d["index"]))
    if kind == "read (with subindex)":
        return ec.Read(node, _int(d["index"]), _int(d["subindex"]))
    if kind == "command":
        return ec.Command(node, _int(d["index"]), d.get("param"))
    if kind == "read reply":
        assert d["value_type"] == "int32" and d["terminator"] == "0x3E"
        return ec.ValueReply(node, d["value"])
    if kind == "ack (0x3E = success)":
        return ec.Ack(node)
    raise AssertionError(f"{record['id']}: undocumented kind {kind!r}")


def test_there_are_vectors() -> None:
    assert len(VECTORS) >= 200
    assert len(SEQUENCES) >= 15
    assert {"seq-erob-can-7.4.1", "seq-erob-can-7.4.2", "seq-erob-can-7.4.3", "seq-erob-can-7.4.4",
            "seq-erob-can-7.4.5"} <= {s["id"] for s in SEQUENCES}


@pytest.mark.parametrize("record", VECTORS, ids=lambda r: r["id"])
def test_vector_decodes_to_its_fields_and_reencodes(record: dict[str, Any]) -> None:
    f = _corrected(record)
    message = ec.decode(f, _role(record))
    assert message == _expected(record)
    assert message.node == record["decoded"]["node"]
    assert f.arbitration_id == (ec.request_id if record["direction"] == "request" else ec.reply_id)(message.node)
    out = ec.encode(message)
    assert out.arbitration_id == f.arbitration_id
    assert bytes(out.data) == bytes(f.data)
    assert out.is_extended_id is False


@pytest.mark.parametrize("record", ERRATA, ids=lambda r: r["id"])
def test_printed_wrong_frame_is_rejected_as_its_erratum_predicts(record: dict[str, Any]) -> None:
    printed = _frame(record["can_id"], record["hex"])
    kind = record["erratum_kind"]
    assert kind in ("missing-terminator", "extra-byte"), kind
    # a reply without its 0x3E is 4 bytes, a disable with an extra byte 7: neither length exists
    with pytest.raises(ByteCountError):
        ec.decode(printed, _role(record))


def _hexlike(text: str) -> bool:
    return all(part and all(c in string.hexdigits for c in part) and len(part) == 2 for part in text.split())


OCR_HEX = [r for r in VECTORS if r.get("ocr_repaired") and _hexlike(r["manual_text"])
           and r["manual_text"].upper() != r["hex"]]


@pytest.mark.parametrize("record", OCR_HEX, ids=lambda r: r["id"])
def test_ocr_damaged_printing_is_not_a_valid_frame(record: dict[str, Any]) -> None:
    # '36' / '2E' printed for 3E: a 1-byte reply is 3E or 80 only
    with pytest.raises(FrameError):
        ec.decode(_frame(record["can_id"], record["manual_text"]), _role(record))


def test_ocr_damaged_printings_exist() -> None:
    assert len(OCR_HEX) >= 5


@pytest.mark.parametrize("reply", PAIRS, ids=lambda r: r["id"])
def test_every_paired_reply_answers_its_request(reply: dict[str, Any]) -> None:
    request = by_id()[reply["pair"]]
    req = ec.decode(_corrected(request), ec.Role.DEVICE)
    rep = ec.decode(_corrected(reply), ec.Role.HOST)
    assert isinstance(req, (ec.Read, ec.Write, ec.Command))
    assert isinstance(rep, (ec.Ack, ec.ValueReply, ec.ErrorReply, ec.ReadFailed))
    assert ec.answers(req, rep)


@pytest.mark.parametrize("sequence", SEQUENCES, ids=lambda s: s["id"])
def test_sequence_pairs_answer(sequence: dict[str, Any]) -> None:
    checked = 0
    for step in sequence["steps"]:
        req = ec.decode(_frame(step["send_can_id"], step["send_hex"]), ec.Role.DEVICE)
        assert isinstance(req, (ec.Read, ec.Write, ec.Command))
        assert bytes(ec.encode(req).data) == bytes.fromhex(step["send_hex"])
        if "expect_hex" not in step:  # 7.4.5 step 10: the reply is not printed
            continue
        rep = ec.decode(_frame(step["expect_can_id"], step["expect_hex"]), ec.Role.HOST)
        assert isinstance(rep, (ec.Ack, ec.ValueReply, ec.ErrorReply, ec.ReadFailed))
        assert ec.answers(req, rep), step
        other = type(rep)(rep.node % 127 + 1, *[getattr(rep, f) for f in rep.__dataclass_fields__ if f != "node"])
        assert not ec.answers(req, other)
        checked += 1
    assert checked


def test_corrected_sequence_frames_are_the_corrected_vectors() -> None:
    ids = by_id()
    for sequence in SEQUENCES:
        for step in sequence["steps"]:
            sent = ids[step["request"]]
            assert step["send_hex"] == (sent.get("correct_hex") or sent["hex"])
