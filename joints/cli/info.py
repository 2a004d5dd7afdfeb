"""``joints info``: what a drive is and how it is set - versions, model, serial number, key parameters, faults.

Rule: read-only. Identity comes from the drive (:class:`~joints.drivers.capabilities.Identity`;
what it cannot report is null / "—", never taken from the config). Key parameters are the
family's :attr:`~joints.registry.DeviceFamily.info_params` that the joint's protocol reaches;
write-only settings (most MKS ones) are shown as "not readable". An active fault is shown by name
with the manual's text and what clears it.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from joints import registry
from joints.cli.basic import read_all, state_dict
from joints.cli.common import add_config, add_json, command, emit_json, joints_of, open_rig, out
from joints.cli.ui import MISSING, cell, print_table
from joints.errors import JointsError, RegisterError

if TYPE_CHECKING:
    from joints.joint import Joint, JointState
    from joints.rig import Rig

NOT_READABLE = "not readable"


def key_params(j: Joint, names: tuple[str, ...]) -> list[dict[str, object]]:
    """The reachable ones of ``names``: value (or "not readable" / the read's error), unit and address."""
    driver = j.driver
    rows: list[dict[str, object]] = []
    for name in names:
        try:
            param, where = driver.describe(name)
        except RegisterError:
            continue  # this protocol does not reach it
        value: object
        if not param.access.readable:
            value = NOT_READABLE
        else:
            try:
                value = driver.read(name)
            except JointsError as exc:
                value = f"read failed: {exc}"
        rows.append({"name": name, "value": value, "unit": param.unit, "where": where})
    return rows


def identity(j: Joint) -> dict[str, object]:
    from joints.drivers.capabilities import Identity

    ident: dict[str, object] = {"model": None, "serial": None, "firmware": None}
    driver = j.driver
    if isinstance(driver, Identity):
        try:
            facts = dict(driver.identity())
        except JointsError as exc:
            return {**ident, "identity": f"failed: {exc}"}
        ident["model"] = facts.pop("model", None)
        ident["serial"] = facts.pop("serial_number", None)
        ident["firmware"] = facts.pop("firmware_version", None)
        ident.update(facts)
    return ident


def describe(rig: Rig, j: Joint, s: JointState) -> dict[str, object]:
    jc = rig.config.joints[j.name]
    fam = registry.family(jc.device)
    bus = rig.config.buses[jc.bus]
    fault = None
    if s.fault is not None:
        fault = {"code": s.fault.code, "name": s.fault.name, "text": s.fault.text, "what_to_do": s.fault.clears,
                 "source": s.fault.source}
    return {
        "joint": j.name, "device": jc.device, "family": fam.name, "protocol": bus.protocol, "bus": jc.bus,
        "address": jc.address, "channel": jc.channel, **identity(j),
        "watchdog_ms": j.watchdog_ms, "limits": {"position": j.limits.position, "velocity": j.limits.velocity,
                                                   "torque": j.limits.torque},
        "state": state_dict(j.name, s), "fault": fault,
        "parameters": key_params(j, fam.info_params),
    }


def show(d: dict[str, Any]) -> None:
    title = f"{d['joint']}: {d['device']} on {d['protocol']} (bus {d['bus']}, address {d['address']}" + (
        f", channel {d['channel']})" if d["channel"] else ")")
    rows: list[list[object]] = []
    for k in ("model", "serial", "firmware"):
        rows.append([k, cell(d[k]), "", "drive"])
    skip = {"joint", "device", "family", "protocol", "bus", "address", "channel", "model", "serial", "firmware",
            "watchdog_ms", "limits", "state", "fault", "parameters"}
    for k, v in d.items():
        if k not in skip:
            rows.append([k, cell(v), "", "drive"])
    st = d["state"]
    state = (f"position {cell(st['position'])}, velocity {cell(st['velocity'])}, "
             f"{'enabled' if st['enabled'] else 'disabled'}, {'moving' if st['moving'] else 'still'}")
    rows.append(["state", state, "", "drive"])
    f = d["fault"]
    rows.append(["fault", "none" if f is None else f"{f['name']} (0x{f['code']:X}): {f['text']}", "", "drive"])
    if f is not None:
        rows.append(["what to do", f["what_to_do"], "", f["source"]])
    lim = d["limits"]
    limits = f"position {cell(lim['position'])}, velocity {cell(lim['velocity'])}, torque {cell(lim['torque'])}"
    rows.append(["limits", limits, "", "config"])
    rows.append(["watchdog while enabled", MISSING if d["watchdog_ms"] is None else f"{d['watchdog_ms']} ms", "",
                 "config"])
    for p in d["parameters"]:
        rows.append([p["name"], cell(p["value"]), p["unit"], p["where"]])
    print_table(["", "value", "unit", "from"], rows, title=title)


def cmd_info(args: argparse.Namespace) -> int:
    with open_rig(args) as rig:
        chosen = joints_of(rig, args.joints)
        states = read_all(rig, [j.name for j in chosen])
        infos = [describe(rig, j, states[j.name]) for j in chosen]
    if args.json:
        emit_json(infos)
        return 0
    for i, d in enumerate(infos):
        if i:
            out()
        show(d)
    return 0


def register(sub: Any) -> None:
    p = command(sub, "info", help="versions, model, serial number, key parameters and faults of joints' drives",
                example="joints info robot.toml shoulder\njoints info robot.toml --json", func=cmd_info)
    add_config(p)
    p.add_argument("joints", nargs="*", help="joint names (default: all)")
    add_json(p)
