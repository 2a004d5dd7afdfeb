"""Injected time: a monotonic wall clock on hardware, a simulated clock in sim.

Rule: nothing below the rig reads the wall clock directly; it is handed a :class:`Clock`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Protocol


class Clock(Protocol):
    def now(self) -> float:
        """Seconds since an arbitrary origin (monotonic)."""
        ...

    def sleep(self, seconds: float) -> None:
        """Let ``seconds`` pass (wall clock: block; simulation: advance the world)."""
        ...


class MonotonicClock:
    """Wall-clock time for hardware."""

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)


class ManualClock:
    """A clock that only moves when told to; ``advance`` callbacks let a simulation step with it.

    :attr:`epoch` counts restarts (:meth:`restart`: a simulation reset): who keeps time of its own on
    this clock (a simulated medium) starts again when it changes - a clock that merely shows an earlier
    time than it did is not a reset.
    """

    def __init__(self, start: float = 0.0) -> None:
        self._t = start
        self.epoch = 0  #: bumped by :meth:`restart`
        self._on_book: Callable[[float], None] | None = None
        self._on_settle: Callable[[], None] | None = None
        self._on_sleep: Callable[[float], None] | None = None

    def bind(self, on_sleep: Callable[[float], None] | None, *, on_book: Callable[[float], None] | None = None,
             on_settle: Callable[[], None] | None = None) -> None:
        """Route ``sleep`` to ``on_sleep`` (which must call :meth:`set`/:meth:`advance`), :meth:`book` to
        ``on_book`` and :meth:`settle` to ``on_settle``."""
        self._on_sleep = on_sleep
        self._on_book = on_book
        self._on_settle = on_settle

    def now(self) -> float:
        return self._t

    def advance(self, seconds: float) -> None:
        if not math.isfinite(seconds):
            raise ValueError(f"cannot advance the clock by {seconds!r} s")
        if seconds < 0:
            raise ValueError("time cannot go backwards")
        self._t += seconds

    def set(self, t: float) -> None:
        self._t = t

    def restart(self, t: float = 0.0) -> None:
        """Time starts again at ``t`` (a reset): a new :attr:`epoch`."""
        self._t = t
        self.epoch += 1

    def sleep(self, seconds: float) -> None:
        if not math.isfinite(seconds):
            raise ValueError(f"cannot sleep {seconds!r} s")
        if seconds <= 0:
            return
        if self._on_sleep is not None:
            self._on_sleep(seconds)
        else:
            self.advance(seconds)

    def book(self, seconds: float) -> None:
        """Let ``seconds`` pass while nothing acts on the simulated drives (a reply travelling to the host): a
        simulation may book the time and run its physics later (:meth:`settle`); otherwise :meth:`sleep`."""
        if self._on_book is not None and math.isfinite(seconds) and seconds > 0:
            self._on_book(seconds)
        else:
            self.sleep(seconds)

    def settle(self) -> None:
        """Something is about to act on the simulated drives: the physics catches up with the booked time."""
        if self._on_settle is not None:
            self._on_settle()
