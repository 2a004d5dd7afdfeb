"""Frame trace: every frame with time, direction, bytes and decoded meaning (the frame monitor).

Rule: recording never raises into the bus code and never blocks it.
"""

from __future__ import annotations

import csv
import json
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass
from pathlib import Path


@dataclass(frozen=True, slots=True)
class TraceRecord:
    time: float  #: seconds on the link's clock
    direction: str  #: "tx" (we sent) or "rx" (we received)
    bus: str
    data: bytes
    meaning: str = ""  #: decoded message or error text
    ident: int | None = None  #: the CAN identifier (None on byte streams)
    node: int | None = None  #: the node / slave address the frame is for or from (None: broadcast, unknown)

    def as_dict(self) -> dict[str, object]:
        d = asdict(self)
        d["data"] = self.data.hex(" ").upper()
        return d

    def __str__(self) -> str:
        arrow = "->" if self.direction == "tx" else "<-"
        ident = "" if self.ident is None else f"{self.ident:03X} "
        return f"{self.time:12.6f} {self.bus} {arrow} {ident}{self.data.hex(' ').upper():<40} {self.meaning}"


class Trace:
    """A bounded in-memory recorder; callable, so it plugs into ``ModbusLink(trace=...)``."""

    def __init__(self, maxlen: int | None = 100_000, *, echo: Callable[[TraceRecord], None] | None = None) -> None:
        self.records: deque[TraceRecord] = deque(maxlen=maxlen)
        self._echo = echo

    def __call__(self, record: TraceRecord) -> None:
        self.records.append(record)
        if self._echo is not None:
            try:
                self._echo(record)
            except Exception:  # noqa: BLE001, S110 - a monitor must never break the bus
                pass

    def __iter__(self) -> Iterator[TraceRecord]:
        return iter(self.records)

    def __len__(self) -> int:
        return len(self.records)

    def clear(self) -> None:
        self.records.clear()

    def export(self, path: str | Path) -> Path:
        """Write the trace as .csv or .jsonl (by suffix)."""
        path = Path(path)
        rows = [r.as_dict() for r in self.records]
        if path.suffix == ".csv":
            with path.open("w", newline="") as fh:
                w = csv.DictWriter(fh, fieldnames=["time", "direction", "bus", "ident", "node", "data", "meaning"])
                w.writeheader()
                w.writerows(rows)
        else:
            with path.open("w") as fh:
                for r in rows:
                    fh.write(json.dumps(r) + "\n")
        return path
