"""Tables, progress bars, sparklines, in-place redraw and single keys for the command line.

Rule: decoration only on a terminal. When stdout (stderr for progress) is not a terminal, output
is plain text without escape codes, so pipes and files get clean lines. ``rich`` (the ``cli``
extra) draws tables and progress bars when it is installed; without it plain text is used.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
from collections.abc import Iterator, Sequence
from typing import Any, TextIO

#: what a table shows for a value the device cannot report
MISSING = "—"
_BLOCKS = "▁▂▃▄▅▆▇█"


def is_terminal(stream: TextIO | None = None) -> bool:
    stream = stream or sys.stdout
    try:
        return stream.isatty() and os.environ.get("TERM") != "dumb"
    except (AttributeError, ValueError):
        return False


def _rich() -> Any:
    try:
        import rich
    except ImportError:
        return None
    return rich


def console(stream: TextIO | None = None) -> Any:
    """A rich console on ``stream`` when it is a terminal and rich is installed, else None."""
    stream = stream or sys.stdout
    if not is_terminal(stream) or _rich() is None:
        return None
    from rich.console import Console

    return Console(file=stream, highlight=False)


def cell(value: object) -> str:
    """A table cell: None (not reported) as an em dash, floats short."""
    if value is None:
        return MISSING
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        if not math.isfinite(value):
            return MISSING
        return f"{value:.4g}" if abs(value) < 1e5 else f"{value:.6g}"
    return str(value)


def plain_table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """Columns aligned with two spaces (no escape codes)."""
    cells = [[cell(v) for v in row] for row in rows]
    widths = [len(h) for h in headers]
    for row in cells:
        for i, c in enumerate(row):
            widths[i] = max(widths[i], len(c))
    lines = ["  ".join(h.ljust(widths[i]) for i, h in enumerate(headers)).rstrip()]
    lines += ["  ".join(c.ljust(widths[i]) for i, c in enumerate(row)).rstrip() for row in cells]
    return "\n".join(lines)


def rich_table(headers: Sequence[str], rows: Sequence[Sequence[object]], title: str | None = None) -> Any:
    from rich.table import Table

    t = Table(title=title, title_justify="left")
    for h in headers:
        t.add_column(h)
    for row in rows:
        t.add_row(*(cell(v) for v in row))
    return t


def print_table(headers: Sequence[str], rows: Sequence[Sequence[object]], *, title: str | None = None) -> None:
    """A table on stdout: rich on a terminal, aligned plain text otherwise."""
    con = console()
    if con is not None:
        con.print(rich_table(headers, rows, title))
        return
    text = plain_table(headers, rows)
    sys.stdout.write((f"{title}\n" if title else "") + text + "\n")
    sys.stdout.flush()


def sparkline(values: Sequence[float], width: int = 24) -> str:
    """The last ``width`` values as block characters (flat when they do not change)."""
    vals = [v for v in values[-width:] if math.isfinite(v)]
    if not vals:
        return ""
    lo, hi = min(vals), max(vals)
    if hi - lo < 1e-12:
        return _BLOCKS[0] * len(vals)
    top = len(_BLOCKS) - 1
    return "".join(_BLOCKS[round((v - lo) / (hi - lo) * top)] for v in vals)


class Progress:
    """A progress bar on stderr while it is a terminal (rich when installed); silent otherwise."""

    def __init__(self, total: int, description: str) -> None:
        self.total = total
        self.description = description
        self.done = 0
        self._bar: Any = None
        self._task: Any = None
        self._plain = False

    def __enter__(self) -> Progress:  # noqa: PYI034 - typing.Self needs Python 3.11
        if not is_terminal(sys.stderr):
            return self
        if _rich() is not None:
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, TextColumn
            from rich.progress import Progress as RichProgress

            self._bar = RichProgress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                                     console=Console(file=sys.stderr), transient=True)
            self._bar.__enter__()
            self._task = self._bar.add_task(self.description, total=self.total)
        else:
            self._plain = True
        return self

    def advance(self, n: int = 1, description: str | None = None) -> None:
        self.done += n
        if self._bar is not None:
            self._bar.update(self._task, advance=n, description=description or self.description)
        elif self._plain:
            sys.stderr.write(f"\r{description or self.description} {self.done}/{self.total}")
            sys.stderr.flush()

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.__exit__(None, None, None)
        elif self._plain:
            sys.stderr.write("\r\x1b[K")
            sys.stderr.flush()


class Redraw:
    """A block of text redrawn in place on a terminal (cursor up, clear, write)."""

    def __init__(self, stream: TextIO | None = None) -> None:
        self.stream = stream or sys.stdout
        self.lines = 0
        self.frames = 0

    def show(self, text: str) -> None:
        s = self.stream
        if self.lines:
            s.write(f"\x1b[{self.lines}F\x1b[J")  # to the start of the block, clear to the end
        s.write(text + "\n")
        s.flush()
        self.lines = text.count("\n") + 1
        self.frames += 1


def render(renderable: Any, width: int = 120) -> str:
    """A rich renderable as text with colours (for :class:`Redraw` on a terminal)."""
    from rich.console import Console

    con = Console(width=width, force_terminal=True, highlight=False)
    with con.capture() as cap:
        con.print(renderable)
    return str(cap.get()).rstrip("\n")


class Keys:
    """Single key presses from stdin while it is a terminal (cbreak mode, restored on exit)."""

    def __init__(self, stream: TextIO | None = None) -> None:
        self.stream = stream or sys.stdin
        self._saved: Any = None
        self.active = False

    def __enter__(self) -> Keys:  # noqa: PYI034 - typing.Self needs Python 3.11
        if not is_terminal(self.stream) or sys.platform == "win32":
            self.active = sys.platform == "win32" and is_terminal(self.stream)
            return self
        import termios
        import tty

        fd = self.stream.fileno()
        self._saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)
        self.active = True
        return self

    def read(self, timeout: float) -> str | None:
        """A key pressed within ``timeout`` s of wall time (None: none; the wait is the pacing of a view)."""
        import time

        if not self.active:
            if timeout > 0:
                time.sleep(timeout)
            return None
        if sys.platform == "win32":
            import msvcrt

            end = time.monotonic() + timeout
            while True:
                if msvcrt.kbhit():  # type: ignore[attr-defined,unused-ignore]
                    return str(msvcrt.getwch())  # type: ignore[attr-defined,unused-ignore]
                if time.monotonic() >= end:
                    return None
                time.sleep(0.01)
        import select

        ready, _, _ = select.select([self.stream], [], [], max(timeout, 0.0))
        if not ready:
            return None
        ch = os.read(self.stream.fileno(), 1)
        return ch.decode(errors="replace") if ch else None

    def __exit__(self, *exc: object) -> None:
        if self._saved is not None:
            import termios

            termios.tcsetattr(self.stream.fileno(), termios.TCSADRAIN, self._saved)
            self._saved = None


@contextlib.contextmanager
def hidden_cursor(stream: TextIO | None = None) -> Iterator[None]:
    stream = stream or sys.stdout
    if not is_terminal(stream):
        yield
        return
    stream.write("\x1b[?25l")
    try:
        yield
    finally:
        stream.write("\x1b[?25h")
        stream.flush()
