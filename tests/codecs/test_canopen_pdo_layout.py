"""PDO packing through a layout prepared once per mapping: the bytes and values of packing bit by bit."""

from __future__ import annotations

import functools
import random

import pytest

from joints.codecs.canopen import pack_pdo, pdo_packer, pdo_unpacker, unpack_pdo
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


def test_a_prepared_packer_and_unpacker_give_what_pack_pdo_and_unpack_pdo_give() -> None:
    """The twin packs its TPDOs and the host decodes them through ``pdo_packer`` / ``pdo_unpacker``: the same bytes,
    values and errors as ``pack_pdo`` / ``unpack_pdo``, whole-byte layouts through the prepared ``struct``."""
    rng = random.Random(11)
    by_struct = 0
    for _ in range(3000):
        entries = tuple((0x6000 + k, k, rng.choice([1, 4, 8, 16, 32, 8, 16, 64]), rng.random() < 0.5)
                        for k in range(rng.randint(1, 4)))
        values = [rng.randint(-(1 << (b - 1)), (1 << (b - 1)) - 1) if signed else rng.randint(0, (1 << b) - 1)
                  for _i, _s, b, signed in entries]
        pack, unpack = pdo_packer(entries), pdo_unpacker(entries)
        whole = all(e[2] in (8, 16, 32, 64) for e in entries) and sum(e[2] for e in entries) <= 64
        assert isinstance(pack, functools.partial) is not whole  # pack_pdo itself where there is no struct
        by_struct += whole
        if sum(e[2] for e in entries) > 64:
            with pytest.raises(EncodeError, match="exceeds 64"):
                pack(values)
            with pytest.raises(EncodeError, match="exceeds 64"):
                unpack(bytes(8))
            continue
        data = pack_pdo(entries, values)
        assert pack(values) == data, (entries, values)
        assert unpack(data) == unpack_pdo(entries, data) == tuple(values)
        assert unpack(data + b"\x5a") == tuple(values)
        short = data[:-1]
        with pytest.raises(FrameError) as prepared:
            unpack(short)
        with pytest.raises(FrameError) as plain:
            unpack_pdo(entries, short)
        assert str(prepared.value) == str(plain.value)
    assert by_struct > 1000
    entries = ((0x6040, 0, 16, False), (0x607A, 0, 32, True))
    pack = pdo_packer(entries)
    for bad, text in (([0, 1 << 31], "0x607A:00: value 2147483648 out of range"),
                      ([-1, 0], "0x6040:00: value -1 out of range"), ([0], "2 mapped objects, got 1")):
        with pytest.raises(EncodeError, match=text):
            pack(bad)
