"""PDO packing through a layout prepared once per mapping: the bytes and values of packing bit by bit."""

from __future__ import annotations

import random

import pytest

from joints.codecs.canopen import pack_pdo, unpack_pdo
from joints.errors import EncodeError, FrameError


def _bit_by_bit(entries: tuple[tuple[int, int, int, bool], ...], values: list[int]) -> bytes:
    raw = offset = 0
    for (_index, _sub, bits, _signed), value in zip(entries, values):
        raw |= (value & ((1 << bits) - 1)) << offset
        offset += bits
    return raw.to_bytes((offset + 7) // 8, "little")


def test_prepared_packing_gives_the_bytes_and_values_of_packing_bit_by_bit() -> None:
    rng = random.Random(7)
    checked = 0
    for _ in range(5000):
        entries = tuple((0x6000 + k, k, rng.choice([1, 4, 8, 16, 32, 8, 16]), rng.random() < 0.5)
                        for k in range(rng.randint(1, 5)))
        if sum(e[2] for e in entries) > 64:
            continue
        values = [rng.randint(-(1 << (b - 1)), (1 << (b - 1)) - 1) if signed else rng.randint(0, (1 << b) - 1)
                  for _i, _s, b, signed in entries]
        data = pack_pdo(entries, values)
        assert data == _bit_by_bit(entries, values), (entries, values)
        assert unpack_pdo(entries, data) == tuple(values)
        assert unpack_pdo(list(entries), data + b"\x5a") == tuple(values)  # longer data: the mapping's bits only
        checked += 1
    assert checked > 3000


def test_prepared_packing_refuses_what_packing_bit_by_bit_refuses() -> None:
    entries = ((0x6040, 0, 16, False), (0x607A, 0, 32, True))
    with pytest.raises(EncodeError, match="0x607A:00: value 2147483648 out of range"):
        pack_pdo(entries, [0, 1 << 31])
    with pytest.raises(EncodeError, match="0x6040:00: value -1 out of range"):
        pack_pdo(entries, [-1, 0])
    with pytest.raises(EncodeError, match="2 mapped objects, got 1"):
        pack_pdo(entries, [0])
    with pytest.raises(EncodeError, match="exceeds 64"):
        pack_pdo(((0x6040, 0, 32, False), (0x607A, 0, 32, True), (0x6041, 0, 8, False)), [0, 0, 0])
    with pytest.raises(TypeError):
        pack_pdo(entries, [0, 1.5])  # type: ignore[list-item]
    with pytest.raises(FrameError, match="mapping needs 6"):
        unpack_pdo(entries, b"\x00" * 5)
