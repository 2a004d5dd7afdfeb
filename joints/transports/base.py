"""The byte-stream transport ABC (RS485 serial ports, pseudo-terminals, in-process loopback).

Rule: transports move bytes and nothing else: no framing, no retries, no decoding.
``read(timeout)`` waits at most ``timeout`` seconds for the first byte and returns what is
available then (``b""`` means the line stayed silent for the whole timeout).
"""

from __future__ import annotations

import abc
from types import TracebackType


class ByteTransport(abc.ABC):
    """A bidirectional byte stream."""

    #: Inter-frame silence in seconds (Modbus RTU t3.5); 0 for in-process transports.
    silence: float = 0.0

    @abc.abstractmethod
    def write(self, data: bytes) -> None:
        """Send all of ``data``."""

    @abc.abstractmethod
    def read(self, timeout: float) -> bytes:
        """Bytes received so far, waiting up to ``timeout`` s for the first one."""

    def reset_input(self) -> None:
        """Discard bytes received but not read yet."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the port. Idempotent."""

    @property
    def name(self) -> str:
        return type(self).__name__

    def __enter__(self) -> ByteTransport:  # noqa: PYI034 - typing.Self needs Python 3.11
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
