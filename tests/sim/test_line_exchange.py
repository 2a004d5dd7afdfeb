"""``line_exchange.clear``: the line's time where no logged frame can overlap the next request, else None - the
same answer as its reference formula (``line.latest_end() > max(now, free host)``) in every state of the log."""

from __future__ import annotations

import math

from joints.clock import ManualClock
from joints.sim import line_exchange as L
from joints.transports.serial_sim import TimedSerialLine


class _Silent:
    """A peer that never answers."""

    def exchange(self, message: object) -> None:
        return None


def _reference(line: TimedSerialLine) -> float | None:
    now = line._sync()
    if len(line._latest_end) != len(line._log) or line.latest_end() > max(now, line._free["host"]):
        return None
    return now


def _both(line: TimedSerialLine) -> tuple[float | None, float | None]:
    return L.clear(line), _reference(line)


def test_clear_is_its_reference_formula_in_every_state_of_the_log() -> None:
    clock = ManualClock(1.0)
    line = TimedSerialLine(_Silent(), baudrate=115200, clock=clock, gap=0.0002)
    seen: list[tuple[float | None, float | None]] = [_both(line)]  # empty log
    line.book_frames([(1.0, 1.001, 1.0015, 8, "host", None), (1.0015, 1.003, 1.003, 9, "device", None)])
    seen.append(_both(line))  # the last frame still on the line (ends after now): None
    clock.set(1.003)
    seen.append(_both(line))  # it ended exactly now: clear
    line._free["host"] = 1.01
    line.book_frames([(1.004, 1.008, 1.008, 8, "host", None)])
    seen.append(_both(line))  # ends before the host's UART is free: clear at now
    line._free["host"] = 1.007
    seen.append(_both(line))  # ends after both: None
    clock.set(2.0)
    seen.append(_both(line))
    line._epoch = len(line._log)  # a new timeline: nothing of the old one counts
    clock.set(1.5)
    seen.append(_both(line))
    line._latest_end.pop()  # an edited log: the line's own way
    seen.append(_both(line))
    fresh = TimedSerialLine(_Silent(), baudrate=115200, clock=ManualClock(1.0))
    fresh.book_frames([(1.0, 1.5, 1.5, 8, "host", None)])
    fresh._epoch = len(fresh._log)  # the frame is of an old timeline (as after a reset): it cannot overlap
    seen.append(_both(fresh))
    for got, want in seen:
        assert got == want
    assert [g is None for g, _ in seen] == [False, True, False, False, True, False, False, True, False]
    assert seen[0][0] == 1.0 and seen[2][0] == 1.003 and not math.isinf(seen[5][0] or 0.0)
