"""A hard time limit around a call: ``with watchdog(2.0): ...`` raises :class:`Hang` if it runs longer.

POSIX main thread only (an interval timer and SIGALRM); elsewhere the limit is measured after the
fact by the caller. :class:`Hang` is a BaseException so code under test cannot swallow it.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType


class Hang(BaseException):
    """The watched call ran past its limit."""


def _alarm(signum: int, frame: FrameType | None) -> None:
    raise Hang()


_installed = False


def _usable() -> bool:
    return sys.platform != "win32" and threading.current_thread() is threading.main_thread()


@contextmanager
def watchdog(seconds: float) -> Iterator[None]:
    global _installed
    if not _usable():
        yield
        return
    if not _installed:
        signal.signal(signal.SIGALRM, _alarm)
        _installed = True
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
