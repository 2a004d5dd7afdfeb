"""Waiting on the simulated clock, shared by the simulated media (the RS485 line and the CAN medium).

Rule: a medium never reads the wall clock; it lets simulated time pass by sleeping the clock it was
given (lockstep: sleeping the world's clock steps the physics) and processes its frames up to the
instant it waited for, no further (the clock calls back into the medium while it sleeps).

A medium starts a new timeline (drops what is in flight) when its clock restarts: a new ``epoch`` of a
clock that counts them (:class:`joints.clock.ManualClock`: the world restarts it on reset); a clock
that shows an earlier time than before is otherwise not a reset (the world's clock shows the exact
instant the host waited for while the physics, and the media's ticks, may stand up to one substep
ahead). Only a clock without an ``epoch`` is taken to restart when it goes back.
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
    _epoch_seen: int | None = None  #: the clock's epoch the medium last saw (None: the clock has none)

    def _see_epoch(self) -> None:
        """The clock's present epoch is the medium's timeline (at construction and after a restart)."""
        self._epoch_seen = getattr(self.clock, "epoch", None)

    def _restarted(self, c: float) -> bool:
        """Whether the clock (now at ``c``) restarted since the medium last looked (see the module docstring)."""
        if self._epoch_seen is None:
            return c < self._clock_seen - 1e-12
        epoch = getattr(self.clock, "epoch", None)
        if epoch == self._epoch_seen:
            return False
        self._epoch_seen = epoch
        return True

    def _run(self, until: float) -> None:
        """Process the medium's frames up to ``until``."""
        raise NotImplementedError

    def _wait_until(self, t: float, lazy: bool = False) -> None:
        """Let time pass until ``t``: sleep the clock if it is behind, process frames up to ``t``. ``lazy``:
        nothing acts on a drive up to ``t``, so a clock that can (``book``) books the time without physics."""
        behind = t - self.clock.now()
        if behind > 0:
            self._cap = t
            try:
                book = getattr(self.clock, "book", None) if lazy else None
                if book is not None:
                    book(behind)
                else:
                    self.clock.sleep(behind)
            finally:
                self._cap = None
            self._clock_seen = self.clock.now()
        self._run(t)
        self.now = max(self.now, t)
