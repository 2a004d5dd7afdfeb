"""Wall-clock pacing: ``realtime = true`` (simulated time never runs ahead of the wall clock) and mixed rigs.

Rule: the only place in sim that reads the wall clock; the emulators and the world stay lockstep.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any


class RealtimeClock:
    """A clock over a world that sleeps so that simulated time tracks wall time."""

    def __init__(self, world: Any) -> None:
        self.world = world
        self._t0_wall = time.monotonic()
        self._t0_sim = world.time

    def now(self) -> float:
        return float(self.world.time)

    def sleep(self, seconds: float) -> None:
        self.world.advance(seconds)
        ahead = (self.world.time - self._t0_sim) - (time.monotonic() - self._t0_wall)
        if ahead > 0:
            time.sleep(ahead)


class MixedClock:
    """The clock of a mixed rig: the wall clock, with the simulated world following it.

    ``now()`` is wall time (on the world's time axis: it starts at the world's time). Whenever
    someone sleeps, the world first catches up with the wall clock (whole substeps), then
    ``refresh`` runs (the rig reads its real joints' states for the world's measured joints), at
    least every ``period`` seconds of the sleep. The simulated part therefore advances in bursts
    while the host talks to its hardware buses and catches up at the next sleep.
    """

    def __init__(self, world: Any, refresh: Callable[[], None] | None = None, *, period: float = 0.005) -> None:
        self.world = world
        self.refresh = refresh
        self.period = period
        self._t0_wall = time.monotonic()
        self._t0_sim = float(world.time)
        self._sleeping = False

    def now(self) -> float:
        return self._t0_sim + (time.monotonic() - self._t0_wall)

    def catch_up(self) -> None:
        """Advance the world to the wall clock's time (it never runs backwards)."""
        behind = self.now() - self.world.time
        if behind > 0:
            self.world.advance(behind)

    def sleep(self, seconds: float) -> None:
        end = self.now() + max(seconds, 0.0)
        while True:
            self.catch_up()
            if self.refresh is not None and not self._sleeping:
                self._sleeping = True  # a refresh that sleeps (a driver's wait) does not refresh again
                try:
                    self.refresh()
                finally:
                    self._sleeping = False
            remaining = end - self.now()
            if remaining <= 0:
                return
            time.sleep(min(remaining, self.period))
