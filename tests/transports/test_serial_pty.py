"""Serial transport (pyserial) over a pseudo-terminal, the pty endpoint, t3.5 and the loopback."""

from __future__ import annotations

import os
import sys

import pytest

from joints.errors import ConfigError, TransportError
from joints.transports.loopback import LoopbackTransport
from joints.transports.serial import SerialTransport, t35

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals need POSIX")


@pytest.mark.parametrize("baud,expected", [(9600, 3.5 * 11 / 9600), (19200, 3.5 * 11 / 19200), (38400, 0.00175),
                                           (115200, 0.00175)])
def test_t35_follows_the_modbus_serial_line_rule(baud: int, expected: float) -> None:
    assert t35(baud) == pytest.approx(expected)


def test_t35_rejects_nonsense() -> None:
    with pytest.raises(ConfigError):
        t35(0)


def test_serial_transport_over_a_pty_moves_bytes_both_ways() -> None:
    from joints.transports.pty import PtyEndpoint

    ep = PtyEndpoint()
    try:
        with SerialTransport(ep.port, 115200) as port:
            assert port.silence == pytest.approx(0.00175)
            port.write(b"\x02\x03\x00\x66\x00\x02\x24\x27")
            got = b""
            import select

            while len(got) < 8:
                select.select([ep.master], [], [], 2.0)
                chunk = ep.read()
                assert chunk, "no bytes arrived on the device side"
                got += chunk
            assert got == bytes.fromhex("02 03 00 66 00 02 24 27")
            ep.write(b"\x02\x03\x04\x00\x07\xA1\x1F\x40\xAA")
            reply = port.read(timeout=2.0)
            while len(reply) < 9:
                more = port.read(timeout=2.0)
                assert more
                reply += more
            assert reply == bytes.fromhex("02 03 04 00 07 A1 1F 40 AA")
            assert port.read(timeout=0.01) == b""  # silence is an empty read, not an error
    finally:
        ep.close()


def test_missing_port_names_it() -> None:
    with pytest.raises(TransportError, match="/dev/does-not-exist"):
        SerialTransport("/dev/does-not-exist", 115200)


def test_bad_parity_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="parity"):
        SerialTransport(os.devnull, 115200, parity="X")


def test_loopback_echo_and_inject() -> None:
    t = LoopbackTransport(lambda data: b"reply", echo=True)
    t.write(b"req")
    assert t.read(0.0) == b"reqreply"
    t.inject(b"noise")
    assert t.read(0.0) == b"noise"
    t.close()
    with pytest.raises(TransportError):
        t.write(b"x")


class _FakeTime:
    """The transport's clock: ``sleep`` advances it, nothing waits."""

    def __init__(self) -> None:
        self.now = 100.0
        self.slept: list[float] = []

    def monotonic(self) -> float:
        return self.now

    def sleep(self, s: float) -> None:
        self.slept.append(s)
        self.now += s


@pytest.mark.parametrize("gap,expected", [(None, 0.00175), (0.0, 0.0)])
def test_a_write_keeps_the_gap_after_the_last_byte_and_a_read_does_not_wait_for_silence(
        monkeypatch: pytest.MonkeyPatch, gap: float | None, expected: float) -> None:
    """A Modbus RTU master keeps t3.5 between the reply it read and its next request (``gap=None``);
    the MKS protocol keeps none (``gap=0``). A read hands over a frame as soon as it is in, so the
    host does not sit out a silence the codec does not need."""
    import joints.transports.serial as serial_mod
    from joints.transports.pty import PtyEndpoint

    fake = _FakeTime()
    monkeypatch.setattr(serial_mod, "time", fake)
    ep = PtyEndpoint()
    try:
        with SerialTransport(ep.port, 115200, gap=gap) as port:
            assert port.gap == pytest.approx(expected)
            ep.write(b"\x02\x03\x04\x00\x07\xA1\x1F\x40\xAA")
            got = port.read(timeout=2.0)
            while len(got) < 9:
                got += port.read(timeout=2.0)
            assert got == bytes.fromhex("02 03 04 00 07 A1 1F 40 AA")
            assert fake.slept == []  # nothing slept for silence on the way in
            fake.now += 0.0005  # the host's own time after the reply
            port.write(b"\x02\x03\x00\x66\x00\x02\x24\x27")
            if expected:
                assert fake.slept == [pytest.approx(expected - 0.0005)]
            else:
                assert fake.slept == []
            # right after a write, the next one waits for the frame's characters and the gap
            port.write(b"\x02\x03\x00\x66\x00\x02\x24\x27")
            if expected:
                assert fake.slept[-1] == pytest.approx(8 * 10 / 115200 + expected)
            else:
                assert fake.slept == []
    finally:
        ep.close()
