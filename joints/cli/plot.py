"""``joints plot``: a state trace or a monitor log as a PNG (matplotlib: the ``plot`` extra).

Rule: read a file, draw, write a PNG - no bus is opened. Two inputs:

* a state trace: JSON lines (or CSV) with ``time``, ``joint`` and quantities, as ``joints watch
  --json``, ``joints state`` or ``joints move --json`` print: position, velocity, torque, current
  (and target, where a line has one) against time, one panel per quantity, one line per joint;
* a monitor log (``joints monitor --export``): with ``--config`` the Modbus register values the
  frames carry are decoded by the map of the device at each address (positions, speeds, currents,
  targets against time, in device units); otherwise the frames per 100 ms per node.
"""

from __future__ import annotations

import argparse
import csv
import json
from collections import defaultdict
from pathlib import Path
from typing import Any

from joints import registry
from joints.cli.common import UsageError, command, note
from joints.cli.logs import CAN_FORMATS
from joints.errors import JointsError, MissingDependencyError

QUANTITIES = ("position", "velocity", "torque", "current", "target")
#: words in a register name that make it worth plotting from a monitor log (when no --param is given)
PLOTTED = ("position", "speed", "velocity", "current", "torque")

Series = dict[str, dict[str, list[tuple[float, float]]]]  # panel -> line -> [(t, value)]


def _pyplot() -> Any:
    try:
        import matplotlib
    except ImportError as exc:
        raise MissingDependencyError("matplotlib", "plot") from exc
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _rows(path: Path) -> list[dict[str, Any]]:
    if path.suffix.lower() == ".csv":
        with path.open(newline="", encoding="utf-8") as fh:
            return list(csv.DictReader(fh))
    rows = []
    for line in path.read_text(encoding="utf-8").splitlines():
        line = line.strip()
        if not line:
            continue
        try:
            obj = json.loads(line)
        except ValueError:
            raise UsageError(f"{path}: not JSON lines") from None
        rows.extend(obj if isinstance(obj, list) else [obj])
    return rows


def _float(v: object) -> float | None:
    try:
        return None if v is None or v == "" else float(str(v))
    except ValueError:
        return None


def is_frame_log(rows: list[dict[str, Any]]) -> bool:
    return bool(rows) and "direction" in rows[0] and "data" in rows[0]


def state_series(rows: list[dict[str, Any]]) -> Series:
    series: Series = defaultdict(lambda: defaultdict(list))
    for r in rows:
        t = _float(r.get("time"))
        if t is None:
            continue
        name = str(r.get("joint") or "joint")
        for q in QUANTITIES:
            v = _float(r.get(q))
            if v is not None:
                series[q][name].append((t, v))
    return series


def frame_series(path: Path, config: str | None, params: list[str]) -> tuple[Series, str]:
    """Register values decoded from Modbus frames (with a config), else frames per 100 ms per node."""
    from joints.cli.logs import read

    records = read(path)
    if config is not None:
        decoded = _decode_modbus(records, config, params)
        if decoded:
            return decoded, "device units"
        note("no Modbus register values to decode in the log: plotting frames per 100 ms")
    series: Series = defaultdict(lambda: defaultdict(list))
    counts: dict[tuple[str, float], int] = defaultdict(int)
    for r in records:
        who = f"node {r.node}" if r.node is not None else (f"id 0x{r.ident:03X}" if r.ident is not None else r.bus)
        counts[(f"{who} {r.direction}", round(r.time, 1))] += 1
    for (line, t), n in sorted(counts.items(), key=lambda kv: kv[0][1]):
        series["frames / 100 ms"][line].append((t, float(n)))
    return series, "frames"


def _decode_modbus(records: list[Any], config: str, params: list[str]) -> Series:
    from joints.cli.common import UsageError as _Usage
    from joints.codecs import modbus as mb
    from joints.config import load
    from joints.devices.registers import RegisterTable

    cfg = load(config)
    tables: dict[tuple[str, int], tuple[str, RegisterTable]] = {}
    for name, jc in cfg.joints.items():
        protocol = cfg.buses[jc.bus].protocol
        table = registry.family(jc.device).tables.get(protocol)
        made = table() if table is not None else None
        if isinstance(made, RegisterTable):
            tables[(jc.bus, jc.address)] = (name, made)
    if not tables:
        return {}
    series: Series = defaultdict(lambda: defaultdict(list))
    pending: dict[str, Any] = {}
    for r in records:
        try:
            if r.direction == "tx":
                codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
                codec.feed(r.data)
                codec.flush()
                pending[r.bus] = codec.next_message()
                continue
            req = pending.pop(r.bus, None)
            if not isinstance(req, (mb.ReadHoldingRegisters, mb.ReadInputRegisters)):
                continue
            codec = mb.ModbusRtuCodec(mb.Role.HOST)
            codec.expect_reply_to(req)
            codec.feed(r.data)
            codec.flush()
            reply = codec.next_message()
        except (JointsError, _Usage):
            continue
        key = (r.bus, req.slave) if (r.bus, req.slave) in tables else next(
            (k for k in tables if k[1] == req.slave), None)
        if key is None or not isinstance(reply, mb.ReadRegistersReply):
            continue
        joint, regs = tables[key]
        for name, value in regs.decode_block(req.address, reply.values).items():
            if (params and name in params) or (not params and any(w in name for w in PLOTTED)):
                series[name][joint].append((r.time, float(value)))
    # drop panels that never change (a plot of constants says nothing)
    return {k: v for k, v in series.items() if any(len({y for _t, y in pts}) > 1 for pts in v.values())} or series


def draw(series: Series, out: Path, title: str, unit_note: str) -> None:
    plt = _pyplot()
    panels = [p for p in series if any(series[p].values())]
    if not panels:
        raise UsageError("nothing to plot: the file has no samples")
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(9, 2.4 * len(panels) + 0.6), squeeze=False)
    for ax, panel in zip(axes[:, 0], panels):
        for line, pts in sorted(series[panel].items()):
            if pts:
                xs, ys = zip(*sorted(pts))
                ax.plot(xs, ys, label=line, drawstyle="steps-post" if unit_note == "frames" else "default")
        ax.set_ylabel(panel)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize="small")
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(title + (f" ({unit_note})" if unit_note else ""))
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)


def cmd_plot(args: argparse.Namespace) -> int:
    path = Path(args.file)
    if not path.is_file():
        raise UsageError(f"no such file: {path}")
    out = Path(args.output or path.with_suffix(".png"))
    if out.suffix.lower() != ".png":
        raise UsageError(f"the plot is a PNG: name the output *.png, got {out}")
    _pyplot()  # the missing extra is said before anything is read
    if path.suffix.lower() in CAN_FORMATS:
        series, unit = frame_series(path, args.config, args.param or [])
    else:
        rows = _rows(path)
        if is_frame_log(rows):
            series, unit = frame_series(path, args.config, args.param or [])
        else:
            series, unit = state_series(rows), "SI units"
    draw(series, out, args.title or path.name, unit)
    note(f"wrote {out}")
    return 0


def register(sub: Any) -> None:
    p = command(sub, "plot", help="plot a state trace or a monitor log to PNG (needs the `plot` extra: matplotlib)",
                example="joints watch robot.toml --json --duration 5 > trace.jsonl\njoints plot trace.jsonl -o trace.png\n"
                        "joints plot frames.csv --config robot.toml -o registers.png", func=cmd_plot)
    p.add_argument("file", help="a state trace (JSON lines / CSV) or a monitor log")
    p.add_argument("-o", "--output", help="the PNG to write (default: FILE with .png)")
    p.add_argument("--config", help="monitor logs: decode the Modbus register values with this config's devices")
    p.add_argument("--param", action="append", metavar="NAME", help="monitor logs: plot this register (repeatable)")
    p.add_argument("--title", help="the plot's title (default: the file name)")
