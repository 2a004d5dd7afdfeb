"""Leaving safely: every open rig is closed on SIGTERM / SIGHUP and at interpreter exit.

Rule: a signal becomes an orderly exit - :class:`Terminated` (a ``SystemExit``) is raised in the
main thread, so ``with`` blocks unwind and close their rigs; rigs left open are closed by an
``atexit`` hook. Handlers are installed only from the main thread, only while a rig is open, and
chain to the handler that was there before (called first). Where a signal does not exist (SIGHUP on
Windows) it is skipped.
"""

from __future__ import annotations

import atexit
import logging
import signal
import threading
import weakref
from types import FrameType
from typing import Any, Protocol

log = logging.getLogger("joints")

#: the signals that close rigs (those this platform has)
SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name))


class Closable(Protocol):
    def close(self) -> None: ...


class Terminated(SystemExit):
    """The process got a termination signal; open rigs are being closed on the way out."""

    def __init__(self, signum: int) -> None:
        super().__init__(128 + signum)
        self.signum = signum

    def __str__(self) -> str:
        return f"terminated by signal {signal.Signals(self.signum).name}"


_open: weakref.WeakSet[Any] = weakref.WeakSet()
_previous: dict[int, Any] = {}
_lock = threading.Lock()


def _handler(signum: int, frame: FrameType | None) -> None:
    before = _previous.get(signum)
    if callable(before):
        before(signum, frame)
    raise Terminated(signum)


def _install() -> None:
    if threading.current_thread() is not threading.main_thread():
        return  # signal handlers can only be set from the main thread; atexit still closes the rig
    for sig in SIGNALS:
        if sig in _previous:
            continue
        current = signal.getsignal(sig)
        if current is signal.SIG_IGN:
            continue  # the user (nohup ...) asked to ignore it: respect that
        _previous[sig] = current
        signal.signal(sig, _handler)


def _restore() -> None:
    if threading.current_thread() is not threading.main_thread():
        return
    for sig, before in list(_previous.items()):
        if signal.getsignal(sig) is _handler:
            signal.signal(sig, before if before is not None else signal.SIG_DFL)
        del _previous[sig]


def register(rig: Closable) -> None:
    """``rig`` is open: close it on a termination signal or at exit."""
    with _lock:
        _open.add(rig)
        _install()


def unregister(rig: Closable) -> None:
    """``rig`` closed: when no rig is open any more, the previous signal handlers come back."""
    with _lock:
        _open.discard(rig)
        if not _open:
            _restore()


def close_all() -> None:
    """Close every rig still open (the atexit hook); errors are logged, never raised."""
    for rig in list(_open):
        try:
            rig.close()
        except BaseException as exc:  # noqa: BLE001 - at exit, report and go on with the others
            log.error("closing a rig at exit failed: %s", exc)


def open_rigs() -> list[Any]:
    return list(_open)


atexit.register(close_all)

__all__: list[str] = ["SIGNALS", "Terminated", "close_all", "open_rigs", "register", "unregister"]

