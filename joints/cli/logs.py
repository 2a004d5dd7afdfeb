"""Frame logs: the monitor's export formats, chosen by file extension, and reading them back.

Rule: CSV and JSON lines hold frames of every bus (time, direction, bus, CAN id, node, bytes,
meaning); python-can's log formats (ASC, BLF, candump .log, TRC) hold CAN frames only - an RS485
frame has no CAN identifier - so they are refused for serial buses. Any other extension is a usage
error that names the allowed ones. Reading gives the same :class:`~joints.link.trace.TraceRecord`
list whatever the format (the CAN formats carry no decoded meaning).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Iterable, Sequence
from pathlib import Path

from joints.cli.common import UsageError
from joints.link.trace import TraceRecord

#: every bus
TEXT_FORMATS = (".csv", ".jsonl", ".ndjson")
#: CAN buses only (python-can's writers and readers)
CAN_FORMATS = (".asc", ".blf", ".log", ".trc")


def suffix(path: str | Path) -> str:
    return Path(path).suffix.lower()


def export_path(text: str) -> str:
    """argparse type: a file whose extension is a known log format (checked before anything is opened)."""
    import argparse

    ext = suffix(text)
    if ext not in TEXT_FORMATS + CAN_FORMATS:
        raise argparse.ArgumentTypeError(
            f"unknown extension {ext or '(none)'!r} for {text}; allowed: {', '.join(TEXT_FORMATS)} (every bus), "
            f"{', '.join(CAN_FORMATS)} (CAN buses)")
    return text


def check_export(path: str | Path, media: Iterable[str]) -> None:
    """A usage error unless ``path``'s extension can hold frames of buses of ``media`` ("serial", "can")."""
    ext = suffix(path)
    only_can = set(media) <= {"can"}
    allowed = TEXT_FORMATS + (CAN_FORMATS if only_can else ())
    if ext in allowed:
        return
    if ext in CAN_FORMATS:
        raise UsageError(f"cannot export to {path}: {ext} is a CAN log format and cannot hold RS485 frames; "
                         f"allowed for these buses: {', '.join(allowed)}")
    raise UsageError(f"cannot export to {path}: unknown extension {ext or '(none)'!r}; allowed: "
                     f"{', '.join(allowed)}" + ("" if only_can else f" (CAN buses also: {', '.join(CAN_FORMATS)})"))


def _row(r: TraceRecord) -> dict[str, object]:
    return {"time": r.time, "direction": r.direction, "bus": r.bus,
            "ident": None if r.ident is None else f"0x{r.ident:03X}", "node": r.node,
            "data": r.data.hex(" ").upper(), "meaning": r.meaning}


def export(records: Sequence[TraceRecord], path: str | Path) -> int:
    """Write ``records`` to ``path`` in the format of its extension; returns the frames written."""
    path = Path(path)
    ext = suffix(path)
    if ext == ".csv":
        with path.open("w", newline="", encoding="utf-8") as fh:
            w = csv.DictWriter(fh, fieldnames=["time", "direction", "bus", "ident", "node", "data", "meaning"])
            w.writeheader()
            for r in records:
                w.writerow(_row(r))
        return len(records)
    if ext in (".jsonl", ".ndjson"):
        with path.open("w", encoding="utf-8") as fh:
            for r in records:
                fh.write(json.dumps(_row(r)) + "\n")
        return len(records)
    if ext in CAN_FORMATS:
        return _export_can(records, path)
    raise UsageError(f"cannot export to {path}: allowed {', '.join(TEXT_FORMATS + CAN_FORMATS)}")


def _export_can(records: Sequence[TraceRecord], path: Path) -> int:
    from joints.transports.can import python_can

    can = python_can()
    n = 0
    with can.Logger(str(path)) as writer:
        for r in records:
            if r.ident is None:
                continue  # a frame error has no identifier
            writer.on_message_received(can.Message(
                timestamp=r.time, arbitration_id=r.ident, is_extended_id=r.ident > 0x7FF, data=r.data,
                dlc=len(r.data), is_rx=r.direction == "rx", channel=0))
            n += 1
    return n


def _int(text: object) -> int | None:
    if text is None or text == "":
        return None
    if isinstance(text, int):
        return text
    return int(str(text), 0)


def read(path: str | Path) -> list[TraceRecord]:
    """The frames of a log written by :func:`export` (or any python-can log of a CAN bus)."""
    path = Path(path)
    if not path.is_file():
        raise UsageError(f"no such log file: {path}")
    ext = suffix(path)
    rows: Iterable[dict[str, object]]
    if ext == ".csv":
        with path.open(newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    elif ext in (".jsonl", ".ndjson"):
        rows = [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]
    elif ext in CAN_FORMATS:
        return _read_can(path)
    else:
        raise UsageError(f"cannot read {path}: allowed {', '.join(TEXT_FORMATS + CAN_FORMATS)}")
    out = []
    for row in rows:
        try:
            out.append(TraceRecord(float(str(row["time"])), str(row["direction"]), str(row.get("bus") or ""),
                                   bytes.fromhex(str(row.get("data") or "")), str(row.get("meaning") or ""),
                                   _int(row.get("ident")), _int(row.get("node"))))
        except (KeyError, ValueError) as exc:
            raise UsageError(f"{path}: not a joints frame log ({exc})") from None
    return out


def _read_can(path: Path) -> list[TraceRecord]:
    from joints.transports.can import python_can

    can = python_can()
    out = []
    for msg in can.LogReader(str(path)):
        if msg.is_error_frame:
            continue
        out.append(TraceRecord(float(msg.timestamp), "rx" if msg.is_rx else "tx", "", bytes(msg.data), "",
                               int(msg.arbitration_id), None))
    return out
