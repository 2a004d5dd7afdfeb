"""``joints scan``: find the drives on a bus - what answers where, and what it says it is.

Rule: a drive is found by reading its family's scan parameter
(:attr:`~joints.registry.DeviceFamily.scan_param`) at each address, the families of the bus's
protocol tried in registry order (:func:`joints.registry.families`): a refusal (a Modbus exception,
a failed read) means "not this family", no reply means "nobody at this address". What a drive
reports about itself (:class:`~joints.drivers.capabilities.Identity`: model, serial number,
firmware) is shown; what the protocol cannot read is null ("—"), never taken from the config.
A family with several devices that the bus cannot tell apart (MKS SERVO42D/57D) is reported by
its family name. On CAN buses the scan first listens (``--listen``) and reports nodes heard
(boot-up, heartbeat) even if no probe succeeds. A protocol with a scan of its own
(:attr:`~joints.registry.BusProtocol.scan`: CANopen listens, then probes 0x1000 by SDO) finds any
node of the protocol, whatever its make: its ``device`` is null (the bus does not say which
family it is), model/serial/firmware are 0x1008/0x1018:4/0x100A where the node has them.

``--json``: a list of objects with the keys bus, protocol, device, address, model, serial,
firmware, and ``details`` (everything else the drive reported: versions, CiA 402 state, NMT
state ...; ``baudrate`` too with a baud-rate sweep).
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from joints import registry
from joints.cli.common import (
    BACKENDS,
    address_range,
    command,
    emit_json,
    int_list,
    load_config,
    nonnegative,
    note,
    positive,
)
from joints.cli.ui import Progress, print_table
from joints.errors import ConfigError, JointsError, PeerProtocolError, RegisterError, ReplyTimeout, RequestError

#: the baud rates ``--baud-sweep`` tries (what the drives in scope offer in common)
SWEEP_BAUDS = (9600, 19200, 38400, 57600, 115200, 256000)
#: serial buses: addresses probed when no ``--range`` is given (a full 1..247 sweep takes minutes)
SERIAL_DEFAULT = (1, 32)
KEYS = ("bus", "protocol", "device", "address", "model", "serial", "firmware")


@dataclass
class Found:
    bus: str
    protocol: str
    address: int
    device: str | None = None
    model: str | None = None
    serial: str | None = None
    firmware: str | None = None
    details: dict[str, object] = dataclasses.field(default_factory=dict)
    baudrate: int | None = None
    heard: bool = False

    def record(self, *, with_baud: bool) -> dict[str, object]:
        fields = dataclasses.asdict(self)
        d: dict[str, object] = {k: fields[k] for k in KEYS}
        d["details"] = dict(self.details)
        if with_baud:
            d["baudrate"] = self.baudrate
        return d


@dataclass
class ScanBus:
    """One bus to scan: its config, link and clock (and what to close afterwards)."""

    config: Any
    link: Any
    clock: Any
    medium: str


def _text(value: object) -> str | None:
    return None if value is None else str(value)


def identify(fam: registry.DeviceFamily, driver: Any, found: Found) -> None:
    """Fill what the drive reports about itself (nothing is guessed)."""
    from joints.drivers.capabilities import Identity

    found.device = fam.devices[0] if len(fam.devices) == 1 else fam.name
    if not isinstance(driver, Identity):
        return
    try:
        info: Mapping[str, object] = driver.identity()
    except JointsError as exc:
        found.details["identity"] = f"failed: {exc}"
        return
    found.model = _text(info.get("model"))
    found.serial = _text(info.get("serial_number"))
    found.firmware = _text(info.get("firmware_version"))
    found.details.update({k: v for k, v in info.items() if k not in ("model", "serial_number", "firmware_version")})


def probe(bus: ScanBus, address: int, families: Sequence[registry.DeviceFamily]) -> Found | None:
    """Who answers at ``address`` (None: nobody)."""
    from joints.config import JointConfig

    cfg = bus.config
    for fam in families:
        lo, hi = fam.address_range(cfg.protocol)
        if not lo <= address <= hi:
            continue
        jcfg = JointConfig(name=f"scan@{address}", device=fam.devices[0], bus=cfg.name, address=address,
                           channel=fam.channels[0] if fam.channels else None)
        driver = fam.driver(jcfg, bus.link, bus.clock, {}, cfg.protocol)
        try:
            driver.read(fam.scan_param)
        except ReplyTimeout:
            return None  # nobody there: no other family will answer either
        except (RequestError, PeerProtocolError, RegisterError):
            continue  # something answered, but not as this family
        found = Found(cfg.name, cfg.protocol, address)
        identify(fam, driver, found)
        return found
    return None


def listen(bus: ScanBus, seconds: float) -> set[int]:
    """Addresses of the nodes heard on a CAN bus within ``seconds`` (boot-up, heartbeat, EMCY ...)."""
    link = bus.link
    if seconds <= 0:
        return set()
    link.unsolicited.clear()
    link.poll(seconds)
    heard = set()
    for _t, msg in list(link.unsolicited):
        node = link.rule.address(msg)
        if node is not None:
            heard.add(node)
    return heard


def addresses(args: argparse.Namespace, protocol: str, medium: str) -> range:
    lo, hi = registry.protocol(protocol).addresses
    if args.range is not None:
        return range(max(lo, args.range.start), min(hi, args.range.stop - 1) + 1)
    if medium == "can":
        return range(lo, hi + 1)
    return range(max(lo, SERIAL_DEFAULT[0]), min(hi, SERIAL_DEFAULT[1]) + 1)


def protocol_scan(bus: ScanBus, args: argparse.Namespace, progress: Progress) -> list[Found]:
    """The protocol's own scan (CANopen): any node of the protocol, with what it says about itself."""
    proto = registry.protocol(bus.config.protocol)
    assert proto.scan is not None
    span = addresses(args, bus.config.protocol, bus.medium)
    out: list[Found] = []
    for record in proto.scan(bus.link, list(span), args.listen if args.listen is not None else 0.3):
        info = dict(record)
        address = info.pop("address")
        assert isinstance(address, int)
        found = Found(bus.config.name, bus.config.protocol, address, model=_text(info.pop("device_name", None)),
                      serial=_text(info.pop("serial_number", None)), firmware=_text(info.pop("software_version", None)))
        found.details.update(info)
        out.append(found)
    progress.advance(len(span))
    return out


def scan_bus(bus: ScanBus, args: argparse.Namespace, families: Sequence[registry.DeviceFamily],
             progress: Progress, baudrate: int | None) -> list[Found]:
    from joints.link.base import RetryPolicy

    can = bus.medium == "can"
    # CAN replies name their node in the identifier: a late one can never be taken for another node's
    bus.link.policy = RetryPolicy(timeout=args.timeout, retries=0, late=0.0 if can else None)
    if registry.protocol(bus.config.protocol).scan is not None:
        return protocol_scan(bus, args, progress)
    heard = listen(bus, args.listen if args.listen is not None else (0.2 if can else 0.0)) if can else set()
    out: list[Found] = []
    for addr in addresses(args, bus.config.protocol, bus.medium):
        found = probe(bus, addr, families)
        progress.advance(description=f"{bus.config.name} {addr}")
        if found is None and addr in heard:
            found = Found(bus.config.name, bus.config.protocol, addr, heard=True)
            found.details["heard"] = "sent frames, answered no probe"
        if found is not None:
            found.baudrate = baudrate
            out.append(found)
    return out


def _families(protocol: str, device: str | None) -> tuple[registry.DeviceFamily, ...]:
    fams = registry.families(protocol)
    if device is not None:
        fam = registry.family(device, key="--device")
        if fam not in fams:
            raise ConfigError(f"{device} has no driver for {protocol}", key="--device",
                              allowed=[d for f in fams for d in f.devices])
        fams = (fam,)
    return fams


def _raw_config(args: argparse.Namespace) -> Any:
    from joints.config import BusConfig

    if (args.port is None) == (args.interface is None):
        raise ConfigError("name either a serial port (--port) or a CAN interface (--interface, --channel), "
                          "or a config (--config)", key="scan")
    protocol = args.protocol or registry.default_protocol("serial" if args.port is not None else "can")
    medium = registry.protocol(protocol, key="--protocol").medium
    if (medium == "can") != (args.interface is not None):
        raise ConfigError(f"{protocol} is a {medium} protocol: use "
                          + ("--interface/--channel" if medium == "can" else "--port"), key="--protocol")
    bauds = args.baudrate or (115200,)
    return BusConfig("scan", protocol, port=args.port, baudrate=bauds[0], timeout=args.timeout, retries=0,
                     interface=args.interface, channel=args.channel, bitrate=args.bitrate, udp_port=args.udp_port)


def _open_link(cfg: Any, clock: Any) -> Any:
    proto = registry.protocol(cfg.protocol)
    return proto.link(cfg, proto.open_transport(cfg), clock, None)


def buses(args: argparse.Namespace) -> Iterator[tuple[ScanBus, int | None]]:
    """Every bus (and baud rate) to scan, opened one at a time and closed after its scan."""
    from joints.clock import MonotonicClock

    if args.config is None:
        cfgs = [_raw_config(args)]
        backend = "hardware"
    else:
        rig_cfg = load_config(args, on_exit="none")
        names = args.bus or list(rig_cfg.buses)
        for n in names:
            if n not in rig_cfg.buses:
                raise ConfigError(f"no bus {n!r}", file=rig_cfg.source, key="buses", allowed=sorted(rig_cfg.buses))
        backend = rig_cfg.backend
        if backend == "sim":
            if args.baudrate or args.baud_sweep:
                note("the twins of a sim config answer at any baud rate: --baudrate/--baud-sweep ignored")
            yield from _sim_buses(rig_cfg, names)
            return
        cfgs = [rig_cfg.buses[n] for n in names]
    assert backend == "hardware"
    for cfg in cfgs:
        medium = registry.protocol(cfg.protocol).medium
        bauds: Sequence[int | None] = [None]
        if medium == "serial":
            bauds = args.baudrate or (SWEEP_BAUDS if args.baud_sweep else (cfg.baudrate,))
        for baud in bauds:
            bcfg = dataclasses.replace(cfg, baudrate=baud) if baud is not None else cfg
            link = _open_link(bcfg, MonotonicClock())
            try:
                yield ScanBus(bcfg, link, link.clock, medium), baud if medium == "serial" else None
            finally:
                link.close()


def _sim_buses(rig_cfg: Any, names: Sequence[str]) -> Iterator[tuple[ScanBus, int | None]]:
    import joints

    with joints.open(rig_cfg) as rig:
        for n in names:
            b = rig.buses[n]
            medium = registry.protocol(b.config.protocol).medium
            yield ScanBus(b.config, b.link, rig.clock, medium), None


def cmd_scan(args: argparse.Namespace) -> int:
    found: list[Found] = []
    scanned: list[str] = []
    for bus, baud in buses(args):
        families = _families(bus.config.protocol, args.device)
        span = addresses(args, bus.config.protocol, bus.medium)
        where = bus.config.name + (f" at {baud} bd" if baud else "")
        scanned.append(f"{where} ({bus.config.protocol}, addresses {span.start}-{span.stop - 1})")
        with Progress(len(span), f"scanning {where}") as progress:
            found += scan_bus(bus, args, families, progress, baud)
    sweep = bool(args.baudrate and len(args.baudrate) > 1) or args.baud_sweep
    if args.json:
        emit_json([f.record(with_baud=sweep) for f in found])
    elif found:
        headers = ["bus", "protocol", "address", "device", "model", "serial", "firmware", "details"]
        if sweep:
            headers.insert(2, "baud")
        rows = []
        for f in found:
            details = ", ".join(f"{k}={v}" for k, v in f.details.items()) or None
            row: list[object] = [f.bus, f.protocol, f.address, f.device, f.model, f.serial, f.firmware, details]
            if sweep:
                row.insert(2, f.baudrate)
            rows.append(row)
        print_table(headers, rows)
    if not found:
        note("nothing answered on " + "; ".join(scanned))
        return 1
    return 0


def register(sub: Any) -> None:
    s = command(sub, "scan", help="find drives on a serial port, a CAN channel or the buses of a config",
                example="joints scan --port /dev/ttyUSB0 --range 1-16\n"
                        "joints scan --port /dev/ttyUSB0 --protocol mks-serial --baud-sweep\n"
                        "joints scan --interface socketcan --channel can0 --protocol canopen --json\n"
                        "joints scan --config robot.toml", func=cmd_scan)
    s.add_argument("--config", help="scan the buses of this config (sim backend: its twins)")
    s.add_argument("--bus", action="append", help="only this bus of --config (repeatable)")
    s.add_argument("--backend", choices=BACKENDS, help="override the config's backend")
    s.add_argument("--port", help="a serial port (RS485 adapter)")
    s.add_argument("--baudrate", type=int_list, help="serial baud rate, or several to try: 9600,115200")
    s.add_argument("--baud-sweep", action="store_true", dest="baud_sweep",
                   help=f"try every common baud rate ({', '.join(map(str, SWEEP_BAUDS))})")
    s.add_argument("--interface", help="python-can interface (socketcan, pcan, udp_multicast ...)")
    s.add_argument("--channel", help="CAN channel (can0, the udp_multicast group ...)")
    s.add_argument("--udp-port", type=int, dest="udp_port", help="udp_multicast port (as `sim serve` printed)")
    s.add_argument("--bitrate", type=int, default=1_000_000)
    s.add_argument("--protocol", choices=registry.protocols(),
                   help="with --port/--interface (default: modbus-rtu on a port, erob-can on a CAN channel)")
    s.add_argument("--device", choices=registry.devices(), help="probe for this device only (default: every "
                                                                 "family the protocol has)")
    s.add_argument("--range", type=address_range, default=None,
                   help="addresses, e.g. 1-32 (default: 1-32 on serial buses, the protocol's whole range on CAN)")
    s.add_argument("--timeout", type=positive, default=0.05, help="s to wait for each answer (default 0.05)")
    s.add_argument("--listen", type=nonnegative, default=None,
                   help="CAN: s to listen for boot-up/heartbeat frames first (default 0.2; CANopen 0.3)")
    s.add_argument("--json", action="store_true",
                   help="a JSON list of objects with the keys " + ", ".join(KEYS) + " (and details)")
