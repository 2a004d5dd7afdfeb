"""``joints state``, ``read``, ``write`` and ``registers``: one-line answers about joints and maps.

Rule: ``state``, ``read`` and ``registers`` only look (``--json`` on each); ``write`` changes one
parameter, and a persistent one needs ``--confirm``. State reads never bring a drive up or switch
its mode (:func:`observe`).
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from joints import registry
from joints.cli.common import (
    add_config,
    add_json,
    command,
    emit_json,
    finite,
    integer,
    joint,
    joints_of,
    key,
    open_rig,
    out,
)
from joints.cli.ui import print_table
from joints.devices.params import Access, ParamMap
from joints.errors import ConfigError

if TYPE_CHECKING:
    from joints.joint import Joint, JointState
    from joints.rig import Rig


def observe(j: Joint) -> JointState:
    """A joint's state read without changing the drive (no bring-up, no mode switch) where the driver can."""
    from joints.drivers.capabilities import PassiveState

    driver = j.driver
    if isinstance(driver, PassiveState):
        return j.to_si(driver.observe())
    return j.state()


def read_all(rig: Rig, names: Sequence[str] | None = None) -> dict[str, JointState]:
    """The states of joints (all if ``names`` is None) without changing any drive; grouped reads where possible."""
    from joints.drivers.capabilities import PassiveState

    wanted = list(rig.joints) if names is None else list(names)
    passive = {n for n in wanted if isinstance(rig.joints[n].driver, PassiveState)}
    states = {n: observe(rig.joints[n]) for n in wanted if n in passive}
    rest = [n for n in wanted if n not in passive]
    if rest:
        states.update(rig.read_states(rest))
    return {n: states[n] for n in wanted}


def state_dict(name: str, s: JointState) -> dict[str, object]:
    fault = None if s.fault is None else {"code": s.fault.code, "name": s.fault.name, "text": s.fault.text,
                                          "clears": s.fault.clears}
    return {"joint": name, "position": s.position, "velocity": s.velocity, "torque": finite(s.torque),
            "current": finite(s.current), "temperature": finite(s.temperature), "enabled": s.enabled, "moving": s.moving,
            "fault": fault, "time": s.time}


def cmd_state(args: argparse.Namespace) -> int:
    with open_rig(args) as rig:
        names = [j.name for j in joints_of(rig, args.joints)]
        rows = [state_dict(n, s) for n, s in read_all(rig, names).items()]
    if args.json or not args.table:
        for r in rows:
            emit_json(r)
        return 0
    print_table(["joint", "position", "velocity", "torque", "current", "temp", "enabled", "moving", "fault"],
                [[r["joint"], r["position"], r["velocity"], r["torque"], r["current"], r["temperature"],
                  r["enabled"], r["moving"], _fault_name(r["fault"])] for r in rows])
    return 0


def _fault_name(fault: object) -> object:
    return fault.get("name") if isinstance(fault, dict) else None


def cmd_read(args: argparse.Namespace) -> int:
    with open_rig(args) as rig:
        j = joint(rig, args.joint)
        for k in args.register:
            param, where = j.driver.describe(key(k))
            emit_json({"joint": args.joint, "register": param.name, "address": where, "value": j.read(param.name),
                       "unit": param.unit})
    return 0


def cmd_write(args: argparse.Namespace) -> int:
    with open_rig(args) as rig:
        joint(rig, args.joint).write(key(args.register), args.value, confirm=args.confirm)
    return 0


# --- registers -----------------------------------------------------------------------------------


@runtime_checkable
class _Row(Protocol):
    """A row of a listing table (a Modbus register, an MKS command field)."""

    address: int
    name: str
    type: str
    access: Access
    unit: str
    persistent: bool


@dataclass(frozen=True)
class MapRow:
    """One parameter of a device on one protocol, for people."""

    where: str
    name: str
    type: str
    access: str
    unit: str
    persistent: bool


def map_rows(device: str, protocol: str) -> Iterator[MapRow]:
    """Every parameter of ``device``'s map on ``protocol`` (ConfigError if the family has no such map)."""
    fam = registry.family(device, key="--device")
    if protocol not in fam.tables:
        raise ConfigError(f"{device} has no {protocol} map", key="--protocol", allowed=tuple(fam.tables))
    table: Any = fam.tables[protocol]()
    if isinstance(table, ParamMap):
        for name in table:
            p = table.param(name)
            yield MapRow(table.where(name), name, p.type, table.access(name).value, table.unit(name), p.persistent)
        return
    rows: Iterable[Any] = table
    for r in rows:
        if isinstance(r, _Row):
            yield MapRow(f"0x{r.address:04X}", r.name, r.type, r.access.value, r.unit, r.persistent)


def default_protocol(device: str) -> str:
    """The protocol ``registers`` lists when none is named: the device's first in the registry's order
    (Modbus RTU where the device has it)."""
    fam = registry.family(device, key="--device")
    return next(p for p in registry.protocols() if p in fam.tables)


def cmd_registers(args: argparse.Namespace) -> int:
    protocol = args.protocol or default_protocol(args.device)
    rows = list(map_rows(args.device, protocol))
    if args.json:
        emit_json([{"where": r.where, "name": r.name, "type": r.type, "access": r.access, "unit": r.unit,
                    "persistent": r.persistent} for r in rows])
        return 0
    width = max(len(r.where) for r in rows) if rows else 6
    for r in rows:
        flag = "  (persistent: needs --confirm)" if r.persistent else ""
        out(f"{r.where:<{width}}  {r.name:<48} {r.type:<6} {r.access:<7} {r.unit}{flag}".rstrip())
    return 0


def register(sub: Any) -> None:
    s = command(sub, "state", help="print the state of joints (JSON lines; --table for a table)",
                example="joints state robot.toml\njoints state robot.toml shoulder --table", func=cmd_state)
    add_config(s)
    s.add_argument("joints", nargs="*", help="joint names (default: all)")
    add_json(s)
    s.add_argument("--table", action="store_true", help="a table instead of JSON lines")

    r = command(sub, "read", help="read parameters of a joint by manual name or address (JSON lines)",
                example="joints read robot.toml shoulder actual_position 0x0047", func=cmd_read)
    add_config(r)
    r.add_argument("joint")
    r.add_argument("register", nargs="+", help="manual names (snake_case) or protocol addresses")
    add_json(r)  # the output is JSON already; accepted for uniformity

    w = command(sub, "write", help="write one parameter of a joint (persistent ones need --confirm)",
                example="joints write robot.toml shoulder profile_speed 0x2710", func=cmd_write)
    add_config(w)
    w.add_argument("joint")
    w.add_argument("register", help="manual name or protocol address")
    w.add_argument("value", type=integer, help="decimal or 0x.. hex")
    w.add_argument("--confirm", action="store_true", help="allow persistent or dangerous parameters")

    g = command(sub, "registers", help="list a device's parameter map on one protocol",
                example="joints registers --device erob --protocol erob-can\njoints registers --device zlac8015d --json",
                func=cmd_registers)
    g.add_argument("--device", choices=registry.devices(), default=registry.devices()[0])
    g.add_argument("--protocol", choices=registry.protocols(), help="default: modbus-rtu where the device has it")
    add_json(g)
