"""Wall-clock pacing for ``realtime = true``: simulated time never runs ahead of the wall clock.

Rule: the only place in sim that reads the wall clock; the emulators and the world stay lockstep.
"""

from __future__ import annotations

import time
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
