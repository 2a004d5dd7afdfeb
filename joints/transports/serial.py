"""RS485/RS232 serial port over pyserial (also pseudo-terminals: a pty path is a port).

Rule: bytes only. ``silence`` is the Modbus RTU t3.5 inter-frame gap derived from the baud rate
(3.5 character times of 11 bits; fixed 1.75 ms above 19200 bd, per the Modbus serial line spec).
A read returns the bytes that have arrived as soon as any have (the codec above knows where a frame
ends, so nothing waits for a silence after it); a write first keeps the line quiet for ``gap``
seconds after the last byte received or sent (the t3.5 a Modbus RTU master keeps between frames;
0 on protocols with no silence rule).
"""

from __future__ import annotations

import time
from typing import Any

from joints.errors import ConfigError, MissingDependencyError, TransportError
from joints.transports.base import ByteTransport

PARITIES = {"N": "N", "E": "E", "O": "O", "none": "N", "even": "E", "odd": "O"}


def t35(baudrate: int, bits_per_char: int = 11) -> float:
    """Modbus RTU inter-frame silence (seconds) for ``baudrate``."""
    if baudrate <= 0:
        raise ConfigError(f"baud rate must be positive, got {baudrate}", key="baudrate")
    if baudrate > 19200:
        return 0.00175
    return 3.5 * bits_per_char / baudrate


def _pyserial() -> Any:
    try:
        import serial
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise MissingDependencyError("pyserial", "serial") from exc
    return serial


class SerialTransport(ByteTransport):
    """A serial port (8 data bits; parity and stop bits configurable)."""

    def __init__(
        self,
        port: str,
        baudrate: int = 115200,
        *,
        parity: str = "N",
        stopbits: int = 1,
        bytesize: int = 8,
        exclusive: bool = True,
        gap: float | None = None,
    ) -> None:
        if parity not in PARITIES:
            raise ConfigError(f"unknown parity {parity!r}", key="parity", allowed=sorted(PARITIES))
        serial = _pyserial()
        self.silence = t35(baudrate)
        #: quiet time kept before each write (default: the t3.5 silence)
        self.gap = self.silence if gap is None else max(float(gap), 0.0)
        self._char = (1 + bytesize + (PARITIES[parity] != "N") + stopbits) / baudrate  #: s per character
        self._quiet_from = 0.0  #: monotonic time the line went quiet (last byte in or out)
        self.port = port
        self.baudrate = baudrate
        try:
            self._ser = serial.Serial(
                port=port,
                baudrate=baudrate,
                parity=PARITIES[parity],
                stopbits=stopbits,
                bytesize=bytesize,
                timeout=0,
                write_timeout=1.0,
                exclusive=exclusive,
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise TransportError(
                f"cannot open serial port {port!r} at {baudrate} bd: {exc}. "
                "Check the port name (ls /dev/tty*), permissions (dialout group) and that no other "
                "program holds it."
            ) from exc

    @property
    def name(self) -> str:
        return f"serial:{self.port}"

    def write(self, data: bytes) -> None:
        if self.gap:
            wait = self._quiet_from + self.gap - time.monotonic()
            if wait > 0:
                time.sleep(wait)
        try:
            self._ser.write(data)
            self._ser.flush()
            # flush() returns when the OS has the bytes; the last one leaves the adapter later
            self._quiet_from = time.monotonic() + len(data) * self._char
        except Exception as exc:
            raise TransportError(f"write to {self.port} failed: {exc}") from exc

    def read(self, timeout: float) -> bytes:
        ser = self._ser
        try:
            ser.timeout = max(timeout, 0.0)
            first = ser.read(1)
            if not first:
                return b""
            waiting = ser.in_waiting
            out = first + ser.read(waiting) if waiting else first
            self._quiet_from = max(self._quiet_from, time.monotonic())
            return bytes(out)
        except Exception as exc:
            raise TransportError(f"read from {self.port} failed: {exc}") from exc

    def reset_input(self) -> None:
        try:
            self._ser.reset_input_buffer()
        except Exception:  # noqa: BLE001, S110 - best effort
            pass

    def close(self) -> None:
        ser = getattr(self, "_ser", None)
        if ser is not None and ser.is_open:
            ser.close()
