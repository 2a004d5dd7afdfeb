"""CRC-16/MODBUS (poly 0xA001 reflected, init 0xFFFF), transmitted low byte first."""

from __future__ import annotations


def _table() -> tuple[int, ...]:
    out = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        out.append(crc)
    return tuple(out)


_TABLE = _table()


def crc16_modbus(data: bytes | bytearray | memoryview) -> int:
    """CRC-16/MODBUS of ``data`` as an integer (append ``crc.to_bytes(2, "little")``)."""
    crc = 0xFFFF
    table = _TABLE
    for b in data:
        crc = (crc >> 8) ^ table[(crc ^ b) & 0xFF]
    return crc


def append_crc(data: bytes | bytearray) -> bytes:
    """``data`` followed by its CRC, low byte first."""
    return bytes(data) + crc16_modbus(data).to_bytes(2, "little")


def crc_ok(frame: bytes | bytearray | memoryview) -> bool:
    """True if the last two bytes are the (low-first) CRC of the rest. CRC of a good frame is 0."""
    return len(frame) >= 3 and crc16_modbus(frame) == 0
