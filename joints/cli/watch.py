"""``joints watch``: a live table of joints' states and chosen parameters, redrawn in place, with sparklines.

Rule: read-only - it never enables, commands or writes, so leaving it (q, Ctrl-C, the end of
``--duration``) leaves every drive as it found it. On a terminal the table is redrawn in place and
single keys are read (q quits); otherwise each sample is one line (JSON with ``--json``). The
view is paced on the wall clock; in sim the world advances by the same period between samples.
"""

from __future__ import annotations

import argparse
from collections import deque
from typing import Any

from joints.cli.basic import read_all, state_dict
from joints.cli.common import (
    add_config,
    add_json,
    command,
    count,
    emit_json,
    joints_of,
    nonnegative,
    open_rig,
    out,
    positive,
)
from joints.cli.ui import Keys, Redraw, cell, hidden_cursor, is_terminal, plain_table, render, rich_table, sparkline
from joints.errors import JointsError, RegisterError

QUIT_KEYS = ("q", "Q", "\x1b", "\x03")


def read_params(rig: Any, names: list[str], params: list[str]) -> dict[str, dict[str, object]]:
    """joint -> {param: value} for the parameters each joint's protocol reaches (errors as text)."""
    values: dict[str, dict[str, object]] = {}
    for n in names:
        driver = rig.joints[n].driver
        row: dict[str, object] = {}
        for p in params:
            try:
                param, _where = driver.describe(p)
            except RegisterError:
                row[p] = None
                continue
            if not param.access.readable:
                row[p] = "not readable"
                continue
            try:
                row[p] = driver.read(param.name)
            except JointsError as exc:
                row[p] = f"error: {type(exc).__name__}"
        values[n] = row
    return values


def frame(names: list[str], states: dict[str, Any], params: dict[str, dict[str, object]], wanted: list[str],
          history: dict[str, dict[str, deque[float]]], t: float, width: int, fancy: bool) -> str:
    headers = ["joint", "position", "", "velocity", "", "torque", "current", "enabled", "moving", "fault", *wanted]
    rows = []
    for n in names:
        s = states[n]
        h = history[n]
        rows.append([n, s.position, sparkline(list(h["position"]), width), s.velocity,
                     sparkline(list(h["velocity"]), width), s.torque, s.current, s.enabled, s.moving,
                     None if s.fault is None else s.fault.name, *(params[n].get(p) for p in wanted)])
    footer = f"t = {t:.3f} s   q: quit"
    if fancy:
        return render(rich_table(headers, rows)) + "\n" + footer
    return plain_table(headers, rows) + "\n" + footer


def cmd_watch(args: argparse.Namespace) -> int:
    tty = is_terminal() and not args.json
    wanted = list(args.param or ())
    fancy = tty
    if fancy:
        try:
            import rich  # noqa: F401
        except ImportError:
            fancy = False
    with open_rig(args) as rig:
        names = [j.name for j in joints_of(rig, args.joints)]
        history: dict[str, dict[str, deque[float]]] = {
            n: {"position": deque(maxlen=args.history), "velocity": deque(maxlen=args.history)}
                   for n in names}
        redraw = Redraw()
        end = None if args.duration == 0 else rig.time + args.duration
        samples = 0
        with Keys() as keys, hidden_cursor() if tty else _nothing():
            try:
                while True:
                    states = read_all(rig, names)
                    params = read_params(rig, names, wanted)
                    samples += 1
                    for n, s in states.items():
                        history[n]["position"].append(s.position)
                        history[n]["velocity"].append(s.velocity)
                    if tty:
                        redraw.show(frame(names, states, params, wanted, history, rig.time, args.history, fancy))
                    else:
                        for n, s in states.items():
                            row = {**state_dict(n, s), **{k: v for k, v in params[n].items()}}
                            if args.json:
                                emit_json(row)
                            else:
                                out(" ".join(f"{k}={cell(v)}" for k, v in row.items() if k != "fault")
                                    + f" fault={cell(None if s.fault is None else s.fault.name)}")
                    if end is not None and rig.time >= end - 1e-9:
                        break
                    if args.samples and samples >= args.samples:
                        break
                    if rig.world is not None:
                        rig.sleep(args.period)
                        key = keys.read(args.period / args.realtime)
                    else:
                        key = keys.read(args.period)
                    if key in QUIT_KEYS:
                        break
            except KeyboardInterrupt:
                pass
    return 0


class _nothing:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> None:
        return None


def register(sub: Any) -> None:
    p = command(sub, "watch", help="live table of joints' states and parameters, redrawn in place (q quits)",
                example="joints watch robot.toml\njoints watch robot.toml shoulder --param error_code "
                        "--param bus_voltage --period 0.2", func=cmd_watch)
    add_config(p)
    p.add_argument("joints", nargs="*", help="joint names (default: all)")
    p.add_argument("--param", action="append", metavar="NAME", help="a parameter to show (repeatable)")
    p.add_argument("--period", type=positive, default=0.1, help="s between two samples (default 0.1)")
    p.add_argument("--duration", type=nonnegative, default=0.0, help="s to watch (0: until q or Ctrl-C)")
    p.add_argument("--samples", type=count, default=None, help="stop after this many samples")
    p.add_argument("--history", type=count, default=24, help="samples in a sparkline (default 24)")
    p.add_argument("--realtime", type=positive, default=1.0,
                   help="sim: simulated seconds per wall second (default 1; the view is paced on the wall clock)")
    add_json(p)


__all__ = ["cmd_watch", "frame", "register"]
