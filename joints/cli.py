"""The ``joints`` command: inspect and drive joints on real or emulated buses.

Rule: read-only by default; anything that moves or persists needs an explicit subcommand and,
for persistent writes, ``--confirm``.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterator, Sequence

from joints import registry
from joints.errors import ConfigError, JointsError


def _parse_range(text: str) -> range:
    lo, _, hi = text.partition("-")
    try:
        a = int(lo)
        b = int(hi) if hi else a
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an address range like 1-32, got {text!r}") from None
    if not 1 <= a <= b <= 247:
        raise argparse.ArgumentTypeError(f"address range must be within 1-247, got {text!r}")
    return range(a, b + 1)


def integer(text: str) -> int:
    """A register value: decimal, 0x.. hex, 0b.. binary (argparse type)."""
    return int(text, 0)


def _joint(rig, name: str):  # type: ignore[no-untyped-def]
    """The rig's joint ``name``; an unknown name is a configuration error listing the joints."""
    from joints.errors import ConfigError

    try:
        return rig.joints[name]
    except KeyError:
        raise ConfigError(f"no joint named {name!r}", file=rig.config.source, key="joints",
                          allowed=sorted(rig.joints)) from None


def _key(text: str) -> str | int:
    try:
        return int(text, 0)
    except ValueError:
        return text


def cmd_scan(args: argparse.Namespace) -> int:
    """Find drives on a bus: every address of the range that answers a read of the family's status
    (``error_code``; the MKS: ``motor_status``).

    The bus is a serial port (``--port``), a CAN channel (``--interface``/``--channel``) or a bus
    of a config (``--config``/``--bus``; twins in sim). Drives that report what they are (eRob
    over CAN: model, serial number, versions) say so on their line. A protocol with a scan of its
    own (CANopen: heartbeats and boot-ups heard for ``--listen`` s, then an SDO probe) finds any
    node of the protocol, whatever its device family.
    """
    from joints.clock import MonotonicClock
    from joints.config import BusConfig, JointConfig
    from joints.drivers.capabilities import Identity
    from joints.link.base import RetryPolicy

    rig = None
    if args.config is not None:
        rig = _open(args)
        if args.bus not in rig.buses:
            raise ConfigError(f"no bus {args.bus!r}", file=rig.config.source, key="buses", allowed=sorted(rig.buses))
        bus = rig.buses[args.bus]
        cfg, link, clock = bus.config, bus.link, rig.clock
        where = f"bus {args.bus} of {args.config} ({rig.backend})"
    else:
        if (args.port is None) == (args.interface is None):
            raise ConfigError("name either a serial port (--port) or a CAN interface (--interface, --channel), "
                              "or a config (--config, --bus)", key="scan")
        protocol = args.protocol or ("modbus-rtu" if args.port is not None else "erob-can")
        cfg = BusConfig("scan", protocol, port=args.port, baudrate=args.baudrate, timeout=args.timeout, retries=0,
                        interface=args.interface, channel=args.channel, bitrate=args.bitrate, udp_port=args.udp_port)
        proto = registry.protocol(protocol, key="--protocol")
        clock = MonotonicClock()
        link = proto.link(cfg, proto.open_transport(cfg), clock, None)
        where = args.port or f"{args.interface} {args.channel}"
    proto = registry.protocol(cfg.protocol)
    fam = registry.family(args.device, key="--device")
    lo, hi = fam.address_range(cfg.protocol)
    addresses = args.range or (range(lo, hi + 1) if proto.medium == "can" else range(lo, min(hi, 32) + 1))
    # CAN replies name their node in the identifier: a late one can never be taken for another node's
    link.policy = RetryPolicy(timeout=args.timeout, retries=0, late=0.0 if proto.medium == "can" else None)
    found = 0

    def probe() -> Iterator[dict[str, object]]:
        for addr in addresses:
            if not lo <= addr <= hi:
                continue
            jcfg = JointConfig(name=f"{args.device}@{addr}", device=args.device, bus=cfg.name, address=addr)
            driver = fam.driver(jcfg, link, clock, {}, cfg.protocol)
            try:
                record: dict[str, object] = {"address": addr, fam.scan_param: driver.read(fam.scan_param)}
            except JointsError:
                continue
            if isinstance(driver, Identity):
                try:
                    record.update(driver.identity())
                except JointsError as exc:
                    record["identity"] = f"failed: {exc}"
            yield record

    try:
        records = probe() if proto.scan is None else \
            proto.scan(link, [a for a in addresses if lo <= a <= hi], args.listen)
        for record in records:
            found += 1
            print(json.dumps(record), flush=True)
    finally:
        if rig is not None:
            rig.close()
        else:
            link.close()
    if not found:
        what = f"{cfg.protocol} node" if proto.scan is not None else args.device
        print(f"no {what} answered on {where} ({cfg.protocol}) at addresses {addresses.start}-"
              f"{addresses.stop - 1}", file=sys.stderr)
        return 1
    return 0


def _open(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    import joints

    return joints.open(args.config, backend=args.backend)


def cmd_state(args: argparse.Namespace) -> int:
    with _open(args) as rig:
        for name, s in rig.read_states().items():
            d = {"position": s.position, "velocity": s.velocity, "torque": s.torque, "current": s.current,
                 "temperature": s.temperature, "enabled": s.enabled, "moving": s.moving, "fault": s.fault,
                 "time": s.time}
            print(json.dumps({"joint": name, **d}))
    return 0


def cmd_read(args: argparse.Namespace) -> int:
    with _open(args) as rig:
        j = _joint(rig, args.joint)
        for key in args.register:
            param, where = j.driver.describe(_key(key))
            print(json.dumps({"joint": args.joint, "register": param.name, "address": where,
                              "value": j.read(param.name), "unit": param.unit}))
    return 0


def cmd_write(args: argparse.Namespace) -> int:
    with _open(args) as rig:
        _joint(rig, args.joint).write(_key(args.register), args.value, confirm=args.confirm)
    return 0


def cmd_registers(args: argparse.Namespace) -> int:
    from joints.errors import ConfigError

    fam = registry.family(args.device)
    protocol = args.protocol or ("modbus-rtu" if "modbus-rtu" in fam.tables else next(iter(fam.tables)))
    if protocol not in fam.tables:
        raise ConfigError(f"{args.device} has no {protocol} map", key="--protocol", allowed=tuple(fam.tables))
    table = fam.tables[protocol]()
    for r in table:
        flag = "  (persistent: needs --confirm)" if r.persistent else ""
        print(f"0x{r.address:04X}  {r.name:<48} {r.type:<6} {r.access.value:<7} {r.unit}{flag}")
    return 0


def cmd_monitor(args: argparse.Namespace) -> int:
    """Frame monitor: poll every joint's state and print each frame (time, direction, bus, data, meaning)."""
    from joints.link.trace import Trace

    trace = Trace(echo=lambda r: print(str(r), flush=True))
    with _open(args) as rig:
        rig.trace(trace)
        end = rig.time + args.duration
        while rig.time < end:
            rig.read_states()
            rig.sleep(args.period)
        rig.trace(None)
    if args.export:
        path = trace.export(args.export)
        print(f"exported {len(trace)} frames to {path}", file=sys.stderr)
    return 0


def cmd_send(args: argparse.Namespace) -> int:
    """Send one custom Modbus frame on a bus and print the decoded reply."""
    from joints.codecs import modbus as mb
    from joints.codecs.crc import append_crc, crc_ok
    from joints.errors import FrameError

    raw = bytes.fromhex(args.frame.replace(" ", ""))
    if not crc_ok(raw):
        raw = append_crc(raw)  # accept frames typed without their CRC
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    codec.feed(raw)
    codec.flush()
    try:
        msg = codec.next_message()
    except FrameError as exc:
        raise FrameError(f"not a Modbus request: {exc}", data=raw) from exc
    if not isinstance(msg, (mb.ReadHoldingRegisters, mb.ReadInputRegisters, mb.WriteSingleRegister,
                            mb.WriteMultipleRegisters)):
        print(f"joints: error: unsupported request {msg!r}", file=sys.stderr)
        return 2
    if not isinstance(msg, (mb.ReadHoldingRegisters, mb.ReadInputRegisters)) and not args.confirm:
        print("joints: error: this frame writes to the drive (it may move a motor or change settings); "
              "add --confirm to send it", file=sys.stderr)
        return 2
    from joints.link.trace import Trace

    trace = Trace(echo=lambda r: print(str(r), flush=True))
    with _open(args) as rig:
        if args.bus not in rig.buses:
            print(f"joints: error: no bus {args.bus!r} (have {', '.join(rig.buses)})", file=sys.stderr)
            return 2
        link = rig.buses[args.bus].link
        link.trace = trace
        link.request(msg, idempotent=False)
    return 0


def cmd_sim_serve(args: argparse.Namespace) -> int:
    """Run the configured world in real time; serial buses on pseudo-terminals, CAN buses on python-can channels."""
    from joints.config import load
    from joints.errors import ConfigError
    from joints.rig import sim_world
    from joints.sim import can_serve
    from joints.sim.serve import serve

    cfg = load(args.config, backend="sim")
    serial: list[str] = []
    cans: dict[str, can_serve.ServedCan] = {}
    for i, (name, b) in enumerate(cfg.buses.items()):
        medium = registry.protocol(b.protocol, key=f"buses.{name}.protocol").medium
        if medium == "can":
            try:
                cans[name] = can_serve.plan(name, b.interface, b.channel, b.udp_port, index=i)
            except ConfigError as exc:
                raise ConfigError(exc.message, file=cfg.source, key=exc.key, allowed=exc.allowed) from None
        else:
            serial.append(name)
    world = sim_world(cfg)
    serve(world, serial, can_buses=cans, out=sys.stdout)
    return 0


def cmd_identify(args: argparse.Namespace) -> int:
    """System identification of one joint; writes its profile overlay (joints.s2r.identify)."""
    from pathlib import Path

    from joints.s2r.identify import Excitation, identify, write_overlay

    exc = Excitation(mode=args.mode, duration=args.duration, amplitude=args.amplitude, f_min=args.f_min,
                     f_max=args.f_max)

    def progress(fraction: float, text: str) -> None:
        bar = "#" * round(30 * fraction)
        print(f"\ridentify [{bar:<30}] {fraction:4.0%}  {text}", end="", file=sys.stderr, flush=True)

    with _open(args) as rig:
        j = _joint(rig, args.joint)
        print(f"identifying joint {args.joint} ({rig.backend}): {exc.mode} multi-sine {exc.f_min:g}-{exc.f_max:g} Hz "
              f"for {exc.duration:g} s inside limits {j.limits}", file=sys.stderr)
        ident = identify(rig, args.joint, exc, known_inertia=args.inertia, progress=progress)
        print(file=sys.stderr)
        profile = j.driver.profile
        device = rig.config.joints[args.joint].device
    out = Path(args.output) if args.output else Path(rig.config.base_dir) / f"{args.joint}.profile.toml"
    write_overlay(out, profile, ident, device=device, config=rig.config.source)
    print(ident)
    print(f"wrote {out}; use it with  profile_overlay = \"{out.name}\"  under [joints.{args.joint}]")
    return 0


def _perturbations(items: Sequence[str]) -> dict[str, dict[str, float]]:
    """``JOINT:key=value,key=value`` -> {joint: {key: value}} (``joints replay --perturb``)."""
    out: dict[str, dict[str, float]] = {}
    for item in items:
        joint, _, rest = item.partition(":")
        try:
            out[joint] = {k.strip(): float(v) for k, v in (kv.split("=", 1) for kv in rest.split(",") if kv)}
        except ValueError:
            raise ConfigError(f"expected JOINT:key=value,... got {item!r}", key="--perturb",
                              allowed=("armature", "coulomb_friction", "viscous_friction", "torque_constant",
                                       "command_delay")) from None
        if not joint or not out[joint]:
            raise ConfigError(f"expected JOINT:key=value,... got {item!r}", key="--perturb")
    return out


def cmd_replay(args: argparse.Namespace) -> int:
    """Replay a recording against fresh twins of its configuration; exit 1 when the replies differ."""
    from joints.s2r.record import replay

    report = replay(args.recording, perturb=_perturbations(args.perturb or ()))
    print(report)
    for d in report.differences[:args.show]:
        print(f"frame {d.index} t {d.t:.6f} {d.bus}: {d.request}")
        for q, (a, b) in d.quantities.items():
            print(f"    {q}: recorded {a} replayed {b}")
    if args.report:
        from pathlib import Path

        Path(args.report).write_text(json.dumps(report.to_json(), indent=1) + "\n", encoding="utf-8")
    return 0 if report.identical else 1


def cmd_sim_eds(args: argparse.Namespace) -> int:
    """Write the EDS of the emulated drive at node NODE of CONFIG (to ``-o FILE``, else to stdout)."""
    from pathlib import Path

    from joints.config import load

    cfg = load(args.config, backend="sim")
    found = []
    for name, j in cfg.joints.items():
        protocol = cfg.buses[j.bus].protocol
        make = registry.family(j.device, key=f"joints.{name}.device").eds.get(protocol)
        if make is not None and j.address == args.node:
            found.append((name, make))
    if len(found) != 1:
        nodes = sorted({j.address for n, j in cfg.joints.items()
                        if registry.family(j.device).eds.get(cfg.buses[j.bus].protocol) is not None})
        what = "no joint" if not found else f"{len(found)} joints ({', '.join(n for n, _ in found)})"
        raise ConfigError(f"{what} at node {args.node} on a bus with an EDS (CANopen)", file=cfg.source,
                          key="joints", allowed=nodes)
    text = found[0][1](args.node)
    if args.output is None:
        sys.stdout.write(text)
    else:
        Path(args.output).write_text(text, encoding="utf-8")
        print(f"{args.output}: EDS of joint {found[0][0]} (node {args.node})", file=sys.stderr)
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="joints", description=(__doc__ or "joints").splitlines()[0])
    p.add_argument("--version", action="version", version=f"joints {__import__('joints').__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("scan", help="find drives on a serial port, a CAN channel or a configured bus")
    s.add_argument("--port", help="serial port (Modbus RTU)")
    s.add_argument("--baudrate", type=int, default=115200)
    s.add_argument("--interface", help="python-can interface (socketcan, pcan, udp_multicast ...)")
    s.add_argument("--channel", help="CAN channel (can0, the udp_multicast group ...)")
    s.add_argument("--udp-port", type=int, dest="udp_port", help="udp_multicast port (as `sim serve` printed)")
    s.add_argument("--bitrate", type=int, default=1_000_000)
    s.add_argument("--protocol", choices=registry.protocols(),
                   help="default: modbus-rtu on a serial port, erob-can on a CAN channel")
    s.add_argument("--config", help="scan a bus of this config instead (sim: the twins)")
    s.add_argument("--bus", help="the bus of --config")
    s.add_argument("--backend", choices=("sim", "hardware"))
    s.add_argument("--device", choices=registry.devices(), default="erob")
    s.add_argument("--range", type=_parse_range, default=None,
                   help="addresses, e.g. 1-32 (default: 1-32 serial, the protocol's whole range on CAN: 1-127)")
    s.add_argument("--timeout", type=float, default=0.05)
    s.add_argument("--listen", type=float, default=0.3,
                   help="CANopen: seconds to listen for heartbeats/boot-ups before the SDO probe")
    s.set_defaults(func=cmd_scan)

    for name, func, helptext in (("state", cmd_state, "print the state of every joint (JSON lines)"),
                                 ("read", cmd_read, "read registers of a joint by manual name or address"),
                                 ("write", cmd_write, "write a register of a joint")):
        c = sub.add_parser(name, help=helptext)
        c.add_argument("config")
        c.add_argument("--backend", choices=("sim", "hardware"))
        if name in ("read", "write"):
            c.add_argument("joint")
            c.add_argument("register", nargs="+" if name == "read" else None)
        if name == "write":
            c.add_argument("value", type=integer, help="decimal or 0x.. hex")
            c.add_argument("--confirm", action="store_true", help="allow persistent/dangerous registers")
        c.set_defaults(func=func)

    sim = sub.add_parser("sim", help="simulation tools").add_subparsers(dest="sim_command", required=True)
    sv = sim.add_parser("serve", help="serve the emulated drives of CONFIG: serial buses on pseudo-terminals, CAN "
                                      "buses on python-can channels (one JSON line per bus)")
    sv.add_argument("config")
    sv.set_defaults(func=cmd_sim_serve)
    ed = sim.add_parser("eds", help="write the CANopen EDS of the emulated drive at NODE of CONFIG")
    ed.add_argument("config")
    ed.add_argument("node", type=int)
    ed.add_argument("-o", "--output", help="the .eds file to write (default: stdout)")
    ed.set_defaults(func=cmd_sim_eds)

    ident = sub.add_parser("identify", help="identify a joint's inertia, friction, torque constant and delay (a "
                                            "safe excitation inside its limits) and write its profile overlay")
    ident.add_argument("config")
    ident.add_argument("joint")
    ident.add_argument("--backend", choices=("sim", "hardware"))
    ident.add_argument("--mode", choices=("torque", "speed"), default="torque",
                       help="torque (default: needs gravity on the joint) or speed (the drive's loop holds it)")
    ident.add_argument("--duration", type=float, default=20.0, help="seconds of excitation")
    ident.add_argument("--amplitude", type=float, help="peak N*m (torque) or rad/s (speed); default half the limit")
    ident.add_argument("--f-min", type=float, default=0.2, dest="f_min", help="Hz")
    ident.add_argument("--f-max", type=float, default=3.0, dest="f_max", help="Hz")
    ident.add_argument("--inertia", type=float, help="the joint's whole inertia [kg*m^2] when it has no gravity torque")
    ident.add_argument("--output", help="overlay file (default: <joint>.profile.toml next to the config)")
    ident.set_defaults(func=cmd_identify)

    rp = sub.add_parser("replay", help="replay a recorded run against fresh twins of its configuration and diff "
                                       "the replies (exit 1 if they differ)")
    rp.add_argument("recording", help="the .jsonl file a joints.s2r.record.Recorder wrote")
    rp.add_argument("--perturb", action="append", metavar="JOINT:key=value,...",
                    help="perturb a twin first (World.perturb: armature, coulomb_friction, viscous_friction, "
                         "torque_constant factors; command_delay in s)")
    rp.add_argument("--report", help="write the whole report (every differing frame) as JSON")
    rp.add_argument("--show", type=int, default=5, help="differing frames to print (default 5)")
    rp.set_defaults(func=cmd_replay)

    r = sub.add_parser("registers", help="list a device's register table (its map on one protocol)")
    r.add_argument("--device", choices=registry.devices(), default="erob")
    r.add_argument("--protocol", choices=registry.protocols(), help="default: modbus-rtu where the device has it")
    r.set_defaults(func=cmd_registers)

    m = sub.add_parser("monitor", help="frame monitor: poll the joints and print every frame")
    m.add_argument("config")
    m.add_argument("--backend", choices=("sim", "hardware"))
    m.add_argument("--duration", type=float, default=1.0, help="seconds (simulated time in sim)")
    m.add_argument("--period", type=float, default=0.1, help="seconds between polls")
    m.add_argument("--export", help="write the frames to a .csv or .jsonl file")
    m.set_defaults(func=cmd_monitor)

    se = sub.add_parser("send", help="send one custom Modbus frame (hex, CRC optional) and print the reply")
    se.add_argument("config")
    se.add_argument("bus")
    se.add_argument("frame", help='e.g. "02 03 00 66 00 02"')
    se.add_argument("--backend", choices=("sim", "hardware"))
    se.add_argument("--confirm", action="store_true", help="required for frames that write")
    se.set_defaults(func=cmd_send)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except JointsError as exc:
        print(f"joints: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
