"""Wall-clock pacing: ``realtime = true`` (simulated time never runs ahead of the wall clock) and mixed rigs.

Rule: the only place in sim that reads the wall clock; the emulators and the world stay lockstep.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

log = logging.getLogger("joints")


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

    ``now()`` is wall time (on the world's time axis: it starts at the world's time). Every time
    someone asks it - every transaction on any bus of the rig asks it for its deadline - the world
    first catches up with the wall clock (whole substeps), after ``feed`` gave it the measured
    joints' latest states (no bus traffic), so the simulated joints move while a loop only talks
    and never sleeps. Whenever someone sleeps, ``refresh`` also runs (the rig reads its real
    joints' states for the world's measured joints), at least every ``period`` seconds of the sleep.
    Physics that cannot keep up with the wall clock (the world is more than :attr:`lag_warning` s
    behind it after catching up) is reported once with a logged warning, and :attr:`max_lag` keeps
    the worst lag seen.
    """

    #: s the world may lag the wall clock after catching up before a warning is logged
    lag_warning = 0.05

    def __init__(self, world: Any, refresh: Callable[[], None] | None = None, *, period: float = 0.005,
                 feed: Callable[[], None] | None = None) -> None:
        self.world = world
        self.refresh = refresh
        self.feed = feed
        self.period = period
        self._t0_wall = time.monotonic()
        self._t0_sim = float(world.time)
        self._sleeping = False
        self._catching = False
        self.max_lag = 0.0  #: the most the world lagged the wall clock right after catching up [s]
        self._warned = False

    def wall(self) -> float:
        """Wall time on the world's time axis (no catching up)."""
        return self._t0_sim + (time.monotonic() - self._t0_wall)

    def now(self) -> float:
        self.catch_up()
        return self.wall()

    def catch_up(self) -> None:
        """Advance the world to the wall clock's time (it never runs backwards)."""
        if self._catching:  # a feed that reads the clock does not catch up again
            return
        self._catching = True
        try:
            behind = self.wall() - self.world.time
            if behind > 0:
                if self.feed is not None:
                    self.feed()
                self.world.advance(behind)
            lag = self.wall() - self.world.time
            self.max_lag = max(self.max_lag, lag)
            if lag > self.lag_warning and not self._warned:
                self._warned = True
                log.warning("mixed rig: the simulation is %.0f ms behind real time (physics slower than the wall "
                            "clock): the simulated joints lag the real ones; use a larger [sim] timestep or a "
                            "simpler model", lag * 1e3)
        finally:
            self._catching = False

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
            remaining = end - self.wall()
            if remaining <= 0:
                return
            time.sleep(min(remaining, self.period))
