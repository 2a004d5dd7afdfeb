"""``joints send``: one raw frame on a bus, its checksum completed, its reply decoded.

Rule: serial buses take hex bytes (the Modbus CRC or MKS checksum is appended when the frame does
not already end in a valid one; a frame whose checksum is wrong is refused, not fixed); CAN buses
take ``ID#DATA`` (candump syntax, hex). Only frames that read go without ``--confirm``: the
protocol's rule says which (:meth:`joints.link.base.Rule.is_read`).
"""

from __future__ import annotations

import argparse
from typing import Any

from joints import registry
from joints.cli.common import UsageError, add_config, add_json, bus_of, command, emit_json, open_rig, out
from joints.cli.monitor import line, record_dict
from joints.errors import JointsError
from joints.link.trace import Trace, TraceRecord


def parse_can(text: str) -> Any:
    """``641#4003600000000000`` -> a CAN frame."""
    from joints.transports.can import python_can

    can = python_can()
    ident, sep, data = text.replace(" ", "").partition("#")
    try:
        arbitration_id = int(ident, 16)
        payload = bytes.fromhex(data)
    except ValueError:
        raise UsageError(f"expected a CAN frame as ID#DATA in hex (e.g. 641#4003600000000000), got {text!r}") from None
    if not sep or len(payload) > 8 or arbitration_id > 0x1FFFFFFF:
        raise UsageError(f"expected a CAN frame as ID#DATA (at most 8 data bytes), got {text!r}")
    return can.Message(arbitration_id=arbitration_id, is_extended_id=arbitration_id > 0x7FF or len(ident) > 3,
                       data=payload, dlc=len(payload))


def parse_bytes(text: str) -> bytes:
    try:
        return bytes.fromhex(text.replace(" ", "").replace(":", ""))
    except ValueError:
        raise UsageError(f"expected the frame as hex bytes (e.g. \"02 03 00 66 00 02\"), got {text!r}") from None


def cmd_send(args: argparse.Namespace) -> int:
    if args.frame is None:
        args.frame, args.target = args.target, None
    bus = args.bus or args.target
    with open_rig(args) as rig:
        name = bus_of(rig, bus)
        link = rig.buses[name].link
        rule = link.rule
        medium = registry.protocol(rig.buses[name].config.protocol).medium
        frame: Any = parse_can(args.frame) if medium == "can" else rule.complete(parse_bytes(args.frame))
        try:
            msg = rule.parse_request(frame)
        except JointsError as exc:
            raise UsageError(f"not a {rule.protocol} request: {exc}") from None
        if not rule.is_read(msg) and not args.confirm:
            raise UsageError(f"{rule.describe(msg)} writes to the drive or commands it (it may move a motor or change "
                             "settings); add --confirm to send it")
        records: list[TraceRecord] = []

        def echo(r: TraceRecord) -> None:
            records.append(r)
            if not args.json:
                out(line(r))

        link.trace = Trace(echo=echo)
        try:
            if rule.expects_reply(msg):
                link.request(msg, idempotent=False)
            else:
                link.send(msg)
                link.poll(link.policy.timeout)  # whatever answers anyway is shown
        finally:
            link.trace = None
    if args.json:
        emit_json([record_dict(r) for r in records])
    return 0


def register(sub: Any) -> None:
    s = command(sub, "send", help="send one raw frame (checksum completed automatically) and show the reply decoded",
                example='joints send robot.toml "02 03 00 66 00 02"\n'
                        'joints send robot.toml --bus can "605#4064600000000000"\n'
                        'joints send robot.toml "02 06 00 F0 00 01" --confirm', func=cmd_send)
    add_config(s)
    s.add_argument("target", metavar="[BUS] FRAME",
                   help='the bus (optional) and the frame - serial: hex bytes, e.g. "02 03 00 66 00 02"; '
                        "CAN: ID#DATA, e.g. 641#0003")
    s.add_argument("frame", nargs="?", help=argparse.SUPPRESS)
    s.add_argument("--bus", help="the bus (default: the only one)")
    s.add_argument("--confirm", action="store_true", help="required for frames that write or command")
    add_json(s)
