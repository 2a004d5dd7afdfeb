"""``joints monitor`` (every frame on a bus, decoded) and ``joints replay`` (a recorded log against a twin).

Rules:

* The monitor shows every frame the host exchanges on the chosen buses - time, direction, CAN id
  or bus address, bytes, decoded meaning - while it polls the joints' states (read-only: nothing is
  written) or, with ``--listen`` on a CAN bus, while it only listens (frames of other hosts and
  the drives' own heartbeats, PDOs, EMCY). Filters (``--node``, ``--kind``, ``--direction``)
  choose what is shown and exported. Ctrl-C ends it; what was recorded is still exported.
* Export formats by extension (:mod:`joints.cli.logs`), checked before any bus is opened.
* Replay sends the requests of a log, in order and with their recorded spacing, and compares each
  reply with the recorded one. It writes what the log wrote: on hardware it needs ``--confirm``.
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Sequence
from typing import Any

from joints import registry
from joints.cli.common import (
    USAGE,
    UsageError,
    add_config,
    add_json,
    bus_of,
    command,
    emit_json,
    load_config,
    nonnegative,
    note,
    open_rig,
    out,
    positive,
)
from joints.cli.logs import CAN_FORMATS, TEXT_FORMATS, check_export, export, export_path, read
from joints.cli.s2r import replay_options
from joints.errors import ConfigError, JointsError
from joints.link.trace import Trace, TraceRecord


@dataclasses.dataclass(frozen=True)
class Filter:
    """Which frames the monitor shows and exports."""

    nodes: frozenset[int] = frozenset()
    kinds: tuple[str, ...] = ()
    direction: str | None = None

    def __call__(self, r: TraceRecord) -> bool:
        if self.nodes and r.node not in self.nodes:
            return False
        if self.direction and r.direction != self.direction:
            return False
        if self.kinds:
            text = r.meaning.lower()
            return any(k in text for k in self.kinds)
        return True


def record_dict(r: TraceRecord) -> dict[str, object]:
    return {"time": r.time, "direction": r.direction, "bus": r.bus,
            "ident": None if r.ident is None else f"0x{r.ident:03X}", "node": r.node,
            "data": r.data.hex(" ").upper(), "meaning": r.meaning}


def line(r: TraceRecord) -> str:
    arrow = "->" if r.direction == "tx" else "<-"
    where = f"{r.ident:03X}" if r.ident is not None else (f"@{r.node}" if r.node is not None else "")
    return f"{r.time:12.6f} {r.bus} {arrow} {where:>4} {r.data.hex(' ').upper():<32} {r.meaning}"


def cmd_monitor(args: argparse.Namespace) -> int:
    cfg = load_config(args, on_exit="none")
    names = args.bus or list(cfg.buses)
    for n in names:
        if n not in cfg.buses:
            raise ConfigError(f"no bus {n!r}", file=cfg.source, key="buses", allowed=sorted(cfg.buses))
    media = {registry.protocol(cfg.buses[n].protocol).medium for n in names}
    if args.export:
        check_export(args.export, media)
    if args.listen and media != {"can"}:
        raise UsageError("--listen needs CAN buses: on RS485 the host is the only one talking (drop --listen)")
    flt = Filter(frozenset(args.node or ()), tuple(k.lower() for k in args.kind or ()), args.direction)
    shown: list[TraceRecord] = []
    closed: list[BrokenPipeError] = []  # the reader went away (| head): stop, quietly

    def echo(r: TraceRecord) -> None:
        if r.bus in names and flt(r):
            shown.append(r)
            try:
                if args.json:
                    emit_json(record_dict(r))
                elif not args.quiet:
                    out(line(r))
            except BrokenPipeError as exc:  # the trace swallows errors of its echo: remember it
                closed.append(exc)

    trace = Trace(maxlen=None, echo=echo)
    from joints.cli.basic import read_all

    with open_rig(args, config=cfg) as rig:
        joints = [j for j, jc in cfg.joints.items() if jc.bus in names]
        for n in names:
            rig.buses[n].link.trace = trace
        end = None if args.duration == 0 else rig.time + args.duration
        try:
            while end is None or rig.time < end:
                if closed:
                    raise closed[0]
                if args.listen:
                    for n in names:
                        rig.buses[n].link.poll(args.period)
                    if rig.world is not None:
                        rig.sleep(0.0)
                else:
                    if joints:
                        read_all(rig, joints)
                    rig.sleep(args.period)
        except KeyboardInterrupt:
            pass
        finally:
            for n in names:
                rig.buses[n].link.trace = None
    if args.export:
        n = export(shown, args.export)
        note(f"exported {n} frames to {args.export}")
    return 0


# --- replay ------------------------------------------------------------------------------------


@dataclasses.dataclass
class Exchange:
    """One recorded request and the frames that answered it."""

    request: TraceRecord
    replies: list[TraceRecord]


def exchanges(records: Sequence[TraceRecord], bus: str | None) -> list[Exchange]:
    out_: list[Exchange] = []
    for r in records:
        if bus and r.bus and r.bus != bus:
            continue
        if r.direction == "tx":
            out_.append(Exchange(r, []))
        elif out_:
            out_[-1].replies.append(r)
    return out_


def _frame(r: TraceRecord, medium: str) -> Any:
    if medium == "can":
        from joints.transports.can import python_can

        can = python_can()
        if r.ident is None:
            raise UsageError(f"a CAN frame of the log has no identifier: {r}")
        return can.Message(arbitration_id=r.ident, is_extended_id=r.ident > 0x7FF, data=r.data, dlc=len(r.data))
    return r.data


def _key(r: TraceRecord) -> tuple[int | None, str]:
    return r.ident, r.data.hex(" ").upper()


def cmd_replay(args: argparse.Namespace) -> int:
    if args.config is None:  # a Recorder's recording carries its configuration
        from joints.cli.s2r import replay_recording

        return replay_recording(args)
    records = read(args.log)
    cfg = load_config(args, on_exit="none")
    if cfg.backend != "sim" and not args.confirm:
        raise UsageError("replay sends every request of the log, writes included, to a "
                         f"{cfg.backend} bus; add --confirm if that bus holds twins or you mean it")
    results: list[dict[str, object]] = []
    with open_rig(args, config=cfg) as rig:
        name = bus_of(rig, args.bus)
        link = rig.buses[name].link
        medium = registry.protocol(cfg.buses[name].protocol).medium
        rule = link.rule
        got: list[TraceRecord] = []
        link.trace = Trace(maxlen=None, echo=got.append)
        items = exchanges(records, None if not args.bus else name)
        last: float | None = None
        try:
            for i, ex in enumerate(items):
                if last is not None and ex.request.time > last:
                    rig.sleep(min(ex.request.time - last, args.max_gap))
                last = ex.request.time
                try:
                    msg = rule.parse_request(_frame(ex.request, medium))
                except JointsError as exc:
                    results.append({"index": i, "request": ex.request.data.hex(" ").upper(),
                                    "error": f"not a request: {exc}", "same": False})
                    continue
                got.clear()
                error = None
                try:
                    if rule.expects_reply(msg):
                        link.request(msg)
                    else:
                        link.send(msg)
                except JointsError as exc:
                    error = str(exc)
                replies = [r for r in got if r.direction == "rx"]
                recorded = [_key(r) for r in ex.replies]
                replayed = [_key(r) for r in replies]
                results.append({"index": i, "request": rule.describe(msg),
                                "recorded": [d for _i, d in recorded], "replayed": [d for _i, d in replayed],
                                "same": recorded == replayed, **({"error": error} if error else {})})
        finally:
            link.trace = None
    differ = [r for r in results if not r["same"]]
    if args.json:
        emit_json(results)
    else:
        for r in results:
            mark = "same   " if r["same"] else "DIFFERS"
            out(f"{r['index']:5d} {mark} {r['request']}")
            if not r["same"]:
                out(f"        recorded: {r.get('recorded')}")
                out(f"        replayed: {r.get('replayed')}" + (f" ({r['error']})" if "error" in r else ""))
        out(f"{len(results)} requests, {len(results) - len(differ)} same replies, {len(differ)} different")
    return 1 if differ else 0


def _kinds(text: str) -> str:
    return text


def register(sub: Any) -> None:
    allowed = ", ".join(TEXT_FORMATS) + "; CAN buses also " + ", ".join(CAN_FORMATS)
    m = command(sub, "monitor", help="frame monitor: every frame on the buses (time, direction, id, bytes, meaning)",
                example="joints monitor robot.toml --duration 5 --export frames.csv\n"
                        "joints monitor robot.toml --bus can --node 3 --kind sdo --export frames.asc\n"
                        "joints monitor robot.toml --bus can --listen --duration 0   # until Ctrl-C",
                func=cmd_monitor)
    add_config(m)
    m.add_argument("--bus", action="append", help="only this bus (repeatable; default: every bus)")
    m.add_argument("--duration", type=nonnegative, default=1.0,
                   help="s to monitor (simulated time in sim; 0: until Ctrl-C)")
    m.add_argument("--period", type=positive, default=0.1, help="s between two polls of the joints")
    m.add_argument("--listen", action="store_true", help="CAN: only listen, send nothing")
    m.add_argument("--node", action="append", type=int, help="only frames for/from this node or slave (repeatable)")
    m.add_argument("--kind", action="append", type=_kinds,
                   help="only frames whose meaning contains this (e.g. sdo, pdo, heartbeat, ReadHolding, Write)")
    m.add_argument("--direction", choices=("tx", "rx"), help="only frames sent (tx) or received (rx)")
    m.add_argument("--export", metavar="FILE", type=export_path,
                   help=f"write the frames to FILE, format by extension: {allowed}")
    m.add_argument("--quiet", action="store_true", help="print nothing (with --export)")
    add_json(m)

    r = command(sub, "replay", help="send the requests of a recorded log to a twin and compare the replies",
                description="Replay a monitor log (with CONFIG: the twins or drives to send it to) or a recording "
                            "of joints.s2r.record.Recorder (without CONFIG: fresh twins of the configuration it "
                            "carries); compare the replies; exit 1 when they differ.",
                example="joints monitor robot.toml --export run.jsonl\njoints replay run.jsonl robot.toml\n"
                        "joints replay recorded.jsonl --perturb joint1:armature=1.4",
                func=cmd_replay)
    r.add_argument("log", help="a log written by `joints monitor --export` (or a python-can CAN log), or a "
                               "Recorder's recording")
    r.add_argument("config", nargs="?", help="monitor logs: the config of the bus to replay on")
    r.add_argument("--backend", choices=("sim", "hardware"), help="override the config's backend")
    replay_options(r)
    r.add_argument("--bus", help="the bus to replay on (default: the only one)")
    r.add_argument("--max-gap", type=nonnegative, default=1.0, dest="max_gap",
                   help="s at most between two requests (the recorded spacing is kept up to this)")
    r.add_argument("--confirm", action="store_true", help="allow replaying on a hardware bus (the log may write)")
    add_json(r)


__all__ = ["USAGE", "Filter", "cmd_monitor", "cmd_replay", "exchanges", "register"]
