"""Waiting on the simulated clock, shared by the simulated media (the RS485 line and the CAN medium).

Rule: a medium never reads the wall clock; it lets simulated time pass by sleeping the clock it was
given (lockstep: sleeping the world's clock steps the physics) and processes its frames up to the
instant it waited for, no further (the clock calls back into the medium while it sleeps).
"""

from __future__ import annotations

from typing import Protocol

__all__ = ["ClockDriven", "ClockLike"]


class ClockLike(Protocol):
    """What a medium needs of a clock (``joints.clock.Clock``)."""

    def now(self) -> float: ...

    def sleep(self, seconds: float) -> None: ...


class ClockDriven:
    """A medium on a clock it may sleep itself: :meth:`_wait_until` lets time pass and runs the medium."""

    clock: ClockLike
    now: float  #: the medium's own time: its frames are processed up to here
    _clock_seen: float  #: the clock's time the medium last saw
    _cap: float | None  #: while the medium sleeps the clock itself: process no further than this

    def _run(self, until: float) -> None:
        """Process the medium's frames up to ``until``."""
        raise NotImplementedError

    def _wait_until(self, t: float) -> None:
        """Let time pass until ``t``: sleep the clock if it is behind, process frames up to ``t``."""
        behind = t - self.clock.now()
        if behind > 0:
            self._cap = t
            try:
                self.clock.sleep(behind)
            finally:
                self._cap = None
            self._clock_seen = self.clock.now()
        self._run(t)
        self.now = max(self.now, t)
