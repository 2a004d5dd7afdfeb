"""Frames to fuzz with: the manuals' frames (tests/data/vectors.json), mutations, random valid frames.

Byte-stream protocols (Modbus RTU, MKS native) give ``bytes``; CAN protocols (eRob CAN, CANopen)
give ``can.Message``. A mutation may re-seal the frame's checksum (``fix``), so mutated fields
reach the decoders and the twins' handlers instead of stopping at the CRC.
"""

from __future__ import annotations

import random
import struct
from collections.abc import Callable, Sequence
from functools import cache
from typing import Any

from joints.codecs import mks
from joints.codecs import modbus as mb
from joints.codecs.crc import append_crc
from testdata import records

Fix = Callable[[bytes], bytes]


def _hex(record: dict[str, Any]) -> str | None:
    return record.get("correct_hex") or record.get("hex")


@cache
def serial_corpus(protocol: str, direction: str) -> tuple[bytes, ...]:
    """Every printed and corrected frame of ``protocol`` going ``direction`` ("request"/"response")."""
    out: list[bytes] = []
    for r in records():
        if r.get("record_type") not in ("vector", "template") or r.get("protocol") != protocol:
            continue
        if r.get("direction") != direction:
            continue
        for text in {r.get("hex"), r.get("correct_hex")} - {None, ""}:
            try:
                out.append(bytes.fromhex(str(text)))
            except ValueError:
                continue
    return tuple(sorted(set(out)))


@cache
def can_corpus(protocol: str, direction: str) -> tuple[tuple[int, bytes], ...]:
    """(CAN id, data) of every frame of ``protocol`` going ``direction`` in the vectors."""
    out: set[tuple[int, bytes]] = set()
    for r in records():
        if r.get("record_type") != "vector" or r.get("protocol") != protocol or r.get("direction") != direction:
            continue
        text, can_id = _hex(r), r.get("can_id")
        if text is None or can_id is None:
            continue
        try:
            out.add((int(str(can_id), 16), bytes.fromhex(str(text))))
        except ValueError:
            continue
    return tuple(sorted(out))


def can_frame(can_id: int, data: bytes, *, remote: bool = False, extended: bool = False) -> Any:
    import can

    return can.Message(arbitration_id=can_id, data=data[:64], is_extended_id=extended, is_remote_frame=remote,
                       is_fd=len(data) > 8, dlc=len(data) if not remote else min(len(data), 8),
                       check=False)


# --- checksums --------------------------------------------------------------------------------


def modbus_fix(frame: bytes) -> bytes:
    return append_crc(frame[:-2]) if len(frame) >= 4 else frame


def mks_fix(frame: bytes) -> bytes:
    return mks.with_checksum(frame[:-1]) if len(frame) >= 2 else frame


# --- mutations ----------------------------------------------------------------------------------


def mutate(rng: random.Random, frame: bytes, others: Sequence[bytes] = (), fix: Fix | None = None) -> bytes:
    """``frame`` with 1-3 random edits; re-sealed by ``fix`` half of the time."""
    out = bytearray(frame)
    for _ in range(rng.randint(1, 3)):
        op = rng.randrange(10)
        n = len(out)
        if op == 0 and n:  # flip 1-3 bits
            for _ in range(rng.randint(1, 3)):
                i = rng.randrange(n)
                out[i] ^= 1 << rng.randrange(8)
        elif op == 1 and n:  # a random byte
            out[rng.randrange(n)] = rng.randrange(256)
        elif op == 2 and n:  # an interesting byte
            out[rng.randrange(n)] = rng.choice((0x00, 0x01, 0x02, 0x03, 0x06, 0x10, 0x7F, 0x80, 0xFA, 0xFB, 0xFC,
                                                0xFE, 0xFF))
        elif op == 3:  # insert
            i = rng.randrange(n + 1)
            out[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 3)))
        elif op == 4 and n > 1:  # delete
            i = rng.randrange(n)
            del out[i:i + rng.randint(1, 3)]
        elif op == 5 and n > 1:  # truncate
            del out[rng.randrange(1, n):]
        elif op == 6:  # extend
            out += bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
        elif op == 7 and others:  # splice with another frame
            other = rng.choice(others)
            out = out[:rng.randrange(n + 1)] + bytearray(other[rng.randrange(len(other) + 1):])
        elif op == 8 and n > 2:  # repeat a slice
            i = rng.randrange(n)
            j = min(n, i + rng.randint(1, 4))
            out[j:j] = out[i:j]
        elif n > 1:  # swap two bytes
            i, j = rng.randrange(n), rng.randrange(n)
            out[i], out[j] = out[j], out[i]
    data = bytes(out)
    if fix is not None and rng.random() < 0.5:
        data = fix(data)
    return data


def random_bytes(rng: random.Random, most: int = 24) -> bytes:
    return bytes(rng.randrange(256) for _ in range(rng.randint(1, most)))


# --- random valid frames per protocol ---------------------------------------------------------------


def modbus_request(rng: random.Random, slaves: Sequence[int], addresses: Sequence[int]) -> bytes:
    """A CRC-valid request: mostly to the bus's slaves and its registers, sometimes odd on purpose."""
    r = rng.random()
    slave = rng.choice(slaves) if r < 0.75 and slaves else (0 if r < 0.85 else rng.randrange(256))

    def address() -> int:
        if addresses and rng.random() < 0.85:
            return (rng.choice(addresses) + rng.choice((0, 0, 0, 1, -1, 2))) & 0xFFFF
        return rng.randrange(0x10000)

    def count() -> int:
        return rng.choice((1, 1, 2, 2, 3, 4, 8, 16, rng.randint(1, 125), 0, 126, 127))

    def value() -> int:
        return rng.choice((0, 1, 2, 3, 0xFFFF, 0x8000, rng.randrange(0x10000), rng.randrange(256)))

    kind = rng.randrange(12)
    if kind < 3:
        fc = rng.choice((3, 3, 4))
        body = struct.pack(">BBHH", slave, fc, address(), count())
    elif kind < 6:
        body = struct.pack(">BBHH", slave, 6, address(), value())
    elif kind < 9:
        n = rng.choice((1, 1, 2, 2, 2, 3, 4, rng.randint(1, 123)))
        values = [value() for _ in range(n)]
        declared = n if rng.random() < 0.9 else rng.choice((0, n + 1, n - 1, 124))
        bc = 2 * n if rng.random() < 0.9 else rng.choice((2 * n + 1, 2 * n - 2, 0, 255))
        body = struct.pack(">BBHHB", slave, 16, address(), declared & 0xFFFF, bc & 0xFF) + struct.pack(
            f">{n}H", *values)
    elif kind == 9:  # known shape, not implemented: FC01/02/05
        body = struct.pack(">BBHH", slave, rng.choice((1, 2, 5)), address(), value())
    elif kind == 10:  # a function code the stack knows no shape for
        fc = rng.choice((7, 8, 11, 12, 17, 20, 23, 43, rng.randint(1, 127)))
        body = bytes((slave, fc)) + bytes(rng.randrange(256) for _ in range(rng.randint(0, 8)))
    else:  # what other slaves answer (a drive hears them on RS485)
        reply: mb.Message = rng.choice((
            mb.ReadRegistersReply(slave, 3, tuple(value() for _ in range(rng.randint(1, 4)))),
            mb.WriteSingleRegisterReply(slave, address(), value()),
            mb.ExceptionReply(slave, rng.choice((3, 6, 16)), rng.randint(1, 4)),
        ))
        return mb.encode(reply)
    return append_crc(body)


def modbus_reply(rng: random.Random) -> bytes:
    slave = rng.choice((1, 2, 3, 0, rng.randrange(256)))
    k = rng.randrange(4)
    if k == 0:
        msg: mb.Message = mb.ReadRegistersReply(slave, rng.choice((3, 4)),
                                                tuple(rng.randrange(0x10000) for _ in range(rng.randint(0, 10))))
    elif k == 1:
        msg = mb.WriteSingleRegisterReply(slave, rng.randrange(0x10000), rng.randrange(0x10000))
    elif k == 2:
        msg = mb.WriteMultipleRegistersReply(slave, rng.randrange(0x10000), rng.randint(0, 130))
    else:
        msg = mb.ExceptionReply(slave, rng.choice((1, 3, 4, 6, 16, 43, 0x17)), rng.randint(0, 255))
    return mb.encode(msg)


def mks_frame(rng: random.Random, head: int) -> bytes:
    """A checksum-valid MKS frame with a random (often known) code and a plausible data length."""
    table = mks.REQUEST_DATA_LENGTH if head == mks.HEAD_DOWNLINK else mks.REPLY_DATA_LENGTH
    if head == mks.HEAD_LONG:
        body = bytearray(51)
        body[0] = head
        for slot in range(rng.randint(0, 5)):
            code = rng.choice(tuple(mks.REQUEST_DATA_LENGTH))
            n = mks.REQUEST_DATA_LENGTH[code]
            body[1 + 10 * slot:3 + 10 * slot] = bytes((rng.randint(1, 255), code))
            body[3 + 10 * slot:3 + 10 * slot + n] = bytes(rng.randrange(256) for _ in range(n))
        return mks.with_checksum(bytes(body))
    code = rng.choice(tuple(table)) if rng.random() < 0.9 else rng.randrange(256)
    n = table.get(code, rng.randint(0, 7))
    if rng.random() < 0.1:
        n = rng.randint(0, 8)
    address = rng.choice((1, 2, 0, rng.randrange(256)))
    data = bytes(rng.choice((0, 1, 2, rng.randrange(256))) for _ in range(n))
    return mks.with_checksum(bytes((head, address, code)) + data)
