"""``joints sim serve`` and ``joints sim view``: the twins of a config, served in real time for other programs.

Rule: serial buses become pseudo-terminals, CAN buses python-can channels that never reach a real
bus (:mod:`joints.sim.can_serve`). One JSON line per bus on stdout says where each one is. Replies
leave after the time the real bus would take (wire time, the drive's turnaround, the bus's
``adapter_latency``; :mod:`joints.sim.served_timing`; ``timing = "ideal"``: at once). While
serving, a twin can be power-cycled (``--control``: commands on stdin; SIGUSR1: every twin), which
is what a drive does when its supply is switched off and on. Everything that touches the world runs
in the serving loop (:func:`joints.sim.serve.serve` ``tick``). ``sim view`` serves the same way
and shows the world in MuJoCo's viewer.
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import signal
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from joints import registry
from joints.cli.common import command, command_group, positive
from joints.errors import ConfigError

#: the subcommands of ``joints sim`` (module, function that adds its parser); other modules may add theirs
SIM_COMMANDS: list[Callable[[Any], None]] = []


def _bind(text: str) -> tuple[str, str]:
    bus, sep, where = text.partition("=")
    if not sep or not bus or not where:
        raise argparse.ArgumentTypeError(f"expected BUS=NAME (e.g. rs485=/tmp/ttyJOINTS0, can=vcan0), got {text!r}")
    return bus, where


def plan_buses(cfg: Any, binds: Mapping[str, str]) -> tuple[list[str], dict[str, Any], dict[str, str]]:
    """Serial buses, CAN buses with their channels, and serial symlinks, from the config and ``--bind``."""
    from joints.sim import can_serve

    for name in binds:
        if name not in cfg.buses:
            raise ConfigError(f"--bind names no bus {name!r}", file=cfg.source, key="buses", allowed=sorted(cfg.buses))
    serial: list[str] = []
    cans: dict[str, can_serve.ServedCan] = {}
    links: dict[str, str] = {}
    for i, (name, b) in enumerate(cfg.buses.items()):
        medium = registry.protocol(b.protocol, key=f"buses.{name}.protocol").medium
        if medium == "can":
            interface, channel, port = b.interface, b.channel, b.udp_port
            if name in binds:
                where = binds[name]
                group, _, udp = where.partition("@")
                if ":" in group or group[:1].isdigit():  # a multicast group (ff01::..., 239.x.y.z)
                    interface, channel, port = "udp_multicast", group, int(udp) if udp else None
                else:
                    interface, channel = "socketcan", group
            try:
                cans[name] = can_serve.plan(name, interface, channel, port, index=i)
            except ConfigError as exc:
                raise ConfigError(exc.message, file=cfg.source, key=exc.key, allowed=exc.allowed) from None
        else:
            serial.append(name)
            if name in binds:
                links[name] = binds[name]
    return serial, cans, links


def hardware_config(cfg_path: Path, lines: Mapping[str, Mapping[str, Any]]) -> str:
    """The config as a hardware config whose buses are the served ones (for `joints ... --config` on the twins)."""
    from joints.cli.tomlout import dumps

    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib

    data = tomllib.loads(cfg_path.read_text(encoding="utf-8"))
    data["backend"] = "hardware"
    buses = data.setdefault("buses", {})
    for name, line in lines.items():
        b = buses.setdefault(name, {})
        if "port" in line:
            b["port"] = line["port"]
        else:
            b["interface"] = line["interface"]
            b["channel"] = line["channel"]
            if line.get("udp_port") is not None:
                b["udp_port"] = line["udp_port"]
            else:
                b.pop("udp_port", None)
    overlay = data.get("timing_overlay")
    if isinstance(overlay, str) and not Path(overlay).is_absolute() and (cfg_path.parent / overlay).exists():
        data["timing_overlay"] = str((cfg_path.parent / overlay).resolve())  # the file is written elsewhere
    sim = data.get("sim")
    if isinstance(sim, dict) and "model" in sim:
        model = Path(str(sim["model"]))
        if not model.is_absolute() and (cfg_path.parent / model).exists():
            sim["model"] = str((cfg_path.parent / model).resolve())
    return dumps(data, header=f"hardware config for the twins served from {cfg_path} (joints sim serve)")


class Control:
    """Requests to the serving loop (power cycles), from stdin lines and SIGUSR1, run in the loop's thread."""

    def __init__(self, world: Any, stop: threading.Event, out: Callable[[dict[str, Any]], None]) -> None:
        self.world = world
        self.stop = stop
        self.out = out
        self.requests: queue.Queue[list[str]] = queue.Queue()

    def power_cycle(self, joints: Sequence[str]) -> list[str]:
        """Power-cycle the drives of ``joints`` (every drive if empty); returns the joints affected."""
        drives: dict[str, Any] = self.world.drives
        unknown = [j for j in joints if j not in drives]
        if unknown:
            raise ConfigError(f"no joint named {unknown[0]!r}", key="power-cycle", allowed=sorted(drives))
        names = list(joints) or list(drives)
        done: dict[int, Any] = {}
        with self.world.lock:
            for n in names:
                twin = drives[n]
                if id(twin) not in done:
                    twin.power_cycle()
                    done[id(twin)] = twin
        return sorted(n for n in drives if id(drives[n]) in done)

    def tick(self) -> None:
        while True:
            try:
                words = self.requests.get_nowait()
            except queue.Empty:
                return
            cmd, args = (words[0], words[1:]) if words else ("", [])
            try:
                if cmd in ("power-cycle", "power_cycle", "reset"):
                    self.out({"power_cycled": self.power_cycle(args), "time": self.world.time})
                elif cmd in ("quit", "exit", "stop"):
                    self.stop.set()
                elif cmd in ("time", "status"):
                    self.out({"time": self.world.time, "joints": sorted(self.world.drives)})
                else:
                    self.out({"error": f"unknown command {cmd!r}", "allowed": ["power-cycle [JOINT ...]", "status",
                                                                               "quit"]})
            except ConfigError as exc:
                self.out({"error": str(exc)})

    def read_stdin(self) -> None:
        """A daemon thread: every line of stdin is one command."""
        def run() -> None:
            for line in sys.stdin:
                if line.strip():
                    self.requests.put(line.split())
            self.requests.put(["quit"])  # stdin closed: the controlling program is gone
        threading.Thread(target=run, name="sim-serve-control", daemon=True).start()


def _printer(lock: threading.Lock) -> Callable[[dict[str, Any]], None]:
    def out(obj: dict[str, Any]) -> None:
        with lock:
            sys.stdout.write(json.dumps(obj) + "\n")
            sys.stdout.flush()
    return out


def _frame_log(t0: float) -> Callable[[str, str, bytes, int | None], None]:
    def log(bus: str, direction: str, data: bytes, ident: int | None) -> None:
        arrow = "->" if direction == "tx" else "<-"
        ident_text = "" if ident is None else f"{ident:03X} "
        sys.stderr.write(f"{time.monotonic() - t0:10.4f} {bus} {arrow} {ident_text}{data.hex(' ').upper()}\n")
    return log


def launch_viewer(world: Any) -> Any:
    """MuJoCo's passive viewer on the world (needs a display)."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise ConfigError("sim view needs a display (DISPLAY or WAYLAND_DISPLAY is not set); use `joints sim serve` "
                          "to serve the twins without one", key="sim view")
    import mujoco.viewer

    return mujoco.viewer.launch_passive(world.model, world.data)


def serve_config(args: argparse.Namespace, *, view: bool = False) -> int:
    from joints.config import load
    from joints.rig import served_timing, sim_world
    from joints.sim.serve import serve

    cfg = load(args.config, backend="sim")
    serial, cans, links = plan_buses(cfg, dict(args.bind or ()))
    world = sim_world(cfg)
    stop = threading.Event()
    lock = threading.Lock()
    printer = _printer(lock)
    control = Control(world, stop, printer)
    viewer: Any = None
    if view:
        viewer = launch_viewer(world)

    def tick() -> None:
        control.tick()
        if viewer is not None:
            if not viewer.is_running():
                stop.set()
                return
            with world.lock:
                viewer.sync()

    def ready(lines: dict[str, dict[str, Any]]) -> None:
        if args.hardware_config:
            Path(args.hardware_config).write_text(hardware_config(Path(args.config), lines), encoding="utf-8")
        if args.control:
            control.read_stdin()

    usr1 = None if sys.platform == "win32" else signal.SIGUSR1
    before = None
    if usr1 is not None and threading.current_thread() is threading.main_thread():
        before = signal.signal(usr1, lambda *_: control.requests.put(["power-cycle"]))
    try:
        serve(world, serial, can_buses=cans, out=sys.stdout, stop=stop, on_ready=ready,
              realtime_factor=args.realtime_factor, log=_frame_log(time.monotonic()) if args.verbose else None,
              tick=tick, links=links, timing=served_timing(cfg))
    finally:
        if usr1 is not None and before is not None:
            signal.signal(usr1, before)
        if viewer is not None:
            viewer.close()
        world.close()
    return 0


def cmd_serve(args: argparse.Namespace) -> int:
    return serve_config(args)


def cmd_view(args: argparse.Namespace) -> int:
    return serve_config(args, view=True)


def cmd_eds(args: argparse.Namespace) -> int:
    """Write the EDS of the emulated drive at node NODE of CONFIG (to ``-o FILE``, else to stdout)."""
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
        sys.stdout.flush()
    else:
        Path(args.output).write_text(text, encoding="utf-8")
        print(f"{args.output}: EDS of joint {found[0][0]} (node {args.node})", file=sys.stderr)
    return 0


def _serve_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("config")
    p.add_argument("--realtime-factor", type=positive, default=1.0, dest="realtime_factor",
                   help="physics this many times faster than the wall clock (default 1)")
    p.add_argument("--verbose", action="store_true", help="log every frame in and out on stderr")
    p.add_argument("--bind", action="append", type=_bind, metavar="BUS=NAME",
                   help="serial bus: a symlink NAME to its pseudo-terminal; CAN bus: a vcan device (can=vcan0) or "
                        "an interface-local udp_multicast group (can=ff01::1234@43210)")
    p.add_argument("--control", action="store_true",
                   help="read commands on stdin: `power-cycle [JOINT ...]`, `status`, `quit` (answers: JSON lines)")
    p.add_argument("--hardware-config", dest="hardware_config", metavar="PATH",
                   help="write a hardware config whose buses are the served ones")


def register(sub: Any) -> None:
    sim = command_group(sub, "sim", help="simulation tools: serve twins, view a served world",
                        description="simulation tools: serve a config's twins on pseudo-terminals and CAN channels, "
                                    "view them",
                        example="joints sim serve robot.toml --hardware-config twins.toml\njoints sim view robot.toml")
    sv = command(sim, "serve", help="serve the twins of CONFIG: serial buses on pseudo-terminals, CAN buses on "
                                    "python-can channels (one JSON line per bus)",
                 example="joints sim serve robot.toml --hardware-config twins.toml\n"
                         "joints sim serve robot.toml --bind rs485=/tmp/ttyJOINTS0 --control\n"
                         "kill -USR1 <pid>    # power-cycle every twin", func=cmd_serve)
    _serve_options(sv)
    vw = command(sim, "view", help="serve the twins of CONFIG and show the world in MuJoCo's viewer",
                 example="joints sim view robot.toml", func=cmd_view)
    _serve_options(vw)
    ed = command(sim, "eds", help="write the CANopen EDS of the emulated drive at NODE of CONFIG",
                 example="joints sim eds robot.toml 3 -o node3.eds", func=cmd_eds)
    ed.add_argument("config")
    ed.add_argument("node", type=int)
    ed.add_argument("-o", "--output", help="the .eds file to write (default: stdout)")
    for add in SIM_COMMANDS:
        add(sim)


__all__ = ["SIM_COMMANDS", "Control", "hardware_config", "launch_viewer", "plan_buses", "register", "serve_config"]
