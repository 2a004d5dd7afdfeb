"""Pseudo-terminal endpoints: an emulated serial bus that any program opens like a real port.

Rule: bytes only. The device side keeps the master end; programs open :attr:`PtyEndpoint.port`
(``/dev/pts/N``) with pyserial, minimalmodbus, pymodbus or our own SerialTransport.
"""

from __future__ import annotations

import os
import sys

from joints.errors import TransportError


class PtyEndpoint:
    """The device end of a pseudo-terminal pair in raw mode."""

    def __init__(self) -> None:
        if sys.platform == "win32":  # pragma: no cover
            raise TransportError("pseudo-terminals are not available on Windows")
        import tty

        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        tty.setraw(self.master)
        os.set_blocking(self.master, False)
        self.port = os.ttyname(self._slave)

    def fileno(self) -> int:
        return self.master

    def read(self) -> bytes:
        """Whatever the other side wrote (non-blocking; b"" if nothing)."""
        try:
            return os.read(self.master, 4096)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:
            return b""

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                n = os.write(self.master, view)
            except BlockingIOError:
                import select

                select.select([], [self.master], [], 0.05)
                continue
            view = view[n:]

    def close(self) -> None:
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
