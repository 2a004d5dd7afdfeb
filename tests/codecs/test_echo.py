"""RS485 local echo rule shared by the stream codecs (Modbus RTU, MKS native)."""

from __future__ import annotations

from joints.codecs.echo import echo_length

ECHO = bytes.fromhex("01 03 00 00 00 02 C4 0B")


def test_a_whole_echo_is_skipped() -> None:
    assert echo_length(ECHO + b"\x01\x03", ECHO, silent=False) == len(ECHO)


def test_a_partial_echo_waits_while_the_line_is_busy_and_is_data_after_silence() -> None:
    assert echo_length(ECHO[:5], ECHO, silent=False) is None
    assert echo_length(ECHO[:5], ECHO, silent=True) == 0


def test_other_bytes_are_not_the_echo() -> None:
    assert echo_length(b"\x02" + ECHO[1:], ECHO, silent=False) == 0
    assert echo_length(ECHO[:3] + b"\xff", ECHO, silent=False) == 0
