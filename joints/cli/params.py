"""``joints params dump | load | diff``: a drive's parameters to a TOML file, back onto a drive, compared.

Rules:

* ``dump`` reads every parameter the joint's protocol reaches and can read. The file sorts them:
  ``[settings]`` (what load and diff work on), ``[identity]`` (address, node id, baud rate,
  protocol switch: :attr:`~joints.registry.DeviceFamily.identity_params`), ``[live]`` (set-points
  and control words, as read: never loaded), ``[status]`` (read-only values) and
  ``[not_readable]`` (write-only settings, listed as "not readable" - never a value the host
  remembers writing). Commands are not parameters and are left out.
* ``load`` is a dry run unless ``--apply``: it shows what differs and writes only that. Identity
  and line settings stay out unless ``--include-identity --confirm`` (so a second drive keeps its
  own address); persistent parameters need ``--confirm``, checked before anything is written;
  ``--save`` stores the settings in the drive's memory (``--confirm``).
* ``diff`` compares two dumps, or a drive against a dump: settings only (identity with
  ``--include-identity``); no output means no difference.
* Drives with a read/write-all block (:class:`AllParameters`: MKS firmware V1.0.6+ on the native
  protocol, 0x47/0x46) are dumped with one 0x47 - their write-only settings then have values - and
  ``load --apply --confirm`` writes what differs in one 0x46 (without ``--confirm``: one command per
  setting, as for every drive).
"""

from __future__ import annotations

import argparse
import datetime
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from joints import registry
from joints.cli.common import UsageError, add_json, command, command_group, emit_json, joint, load_config, open_rig, out
from joints.cli.tomlout import dumps
from joints.errors import ConfirmationRequired, JointsError, RegisterError

if TYPE_CHECKING:
    from joints.joint import Joint
    from joints.rig import Rig

SECTIONS = ("settings", "identity", "live", "status", "not_readable", "read_failed")


@runtime_checkable
class AllParameters(Protocol):
    """A driver that reads and writes every configuration setting in one transaction (MKS 0x47/0x46).

    ``read_all_parameters`` raises :class:`~joints.errors.RegisterError` where the drive's firmware lacks it.
    """

    def read_all_parameters(self) -> dict[str, int]: ...

    def write_all_parameters(self, values: Mapping[str, int], *, confirm: bool = False) -> None: ...


def read_block(driver: object) -> dict[str, int]:
    """Every setting by one block read where the driver and the drive's firmware have it, else {}."""
    if not isinstance(driver, AllParameters):
        return {}
    try:
        return driver.read_all_parameters()
    except RegisterError:
        return {}
NOT_READABLE = "not readable"


def _toml() -> Any:
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    return tomllib


def section(fam: registry.DeviceFamily, name: str, readable: bool, writable: bool) -> str:
    if not readable:
        return "not_readable"
    if name in fam.identity_params:
        return "identity"
    if name in fam.live_params:
        return "live"
    return "settings" if writable else "status"


def dump_joint(rig: Rig, j: Joint) -> dict[str, Any]:
    """Every parameter of the joint's drive that its protocol reaches, sorted into the file's sections."""
    from joints.devices.params import Access

    jc = rig.config.joints[j.name]
    fam = registry.family(jc.device)
    protocol = rig.config.buses[jc.bus].protocol
    data: dict[str, Any] = {"drive": {"joint": j.name, "device": jc.device, "protocol": protocol,
                                      "address": jc.address, "dumped": datetime.datetime.now().isoformat(
                                          timespec="seconds")}}
    if jc.channel:
        data["drive"]["channel"] = jc.channel
    for s in SECTIONS:
        data[s] = {}
    driver = j.driver
    block = read_block(driver)
    for p in driver.params:
        if p.access is Access.COMMAND:
            continue
        try:
            name = driver.access.resolve(p.name)
        except RegisterError:
            continue  # not on this protocol
        if name in block:
            data[section(fam, name, True, p.access.writable)][name] = block[name]
            continue
        where = section(fam, name, p.access.readable, p.access.writable)
        if where == "not_readable":
            data[where][name] = NOT_READABLE
            continue
        try:
            data[where][name] = driver.read(name)
        except RegisterError:
            data["not_readable"][name] = NOT_READABLE  # the protocol reaches it as a command only
        except JointsError as exc:
            data["read_failed"][name] = f"{type(exc).__name__}: {exc}"
    return {k: v for k, v in data.items() if v or k == "settings"}


def read_settings(j: Joint, fam: registry.DeviceFamily) -> dict[str, int]:
    """The joint's drive's settings as they are now: readable, writable, not persistent, not identity and not
    live - plus its mode parameters (what a one-shot command puts back when it is done)."""
    driver = j.driver
    found: dict[str, int] = {}
    block = read_block(driver)
    for p in driver.params:
        if p.name in block and not p.persistent and (p.name in fam.mode_params
                                                      or section(fam, p.name, True, True) == "settings"):
            found[p.name] = block[p.name]  # write-only, but the drive's block read reports it
            continue
        if not (p.access.readable and p.access.writable) or p.persistent:
            continue
        if p.name not in fam.mode_params and section(fam, p.name, True, True) != "settings":
            continue
        try:
            name = driver.access.resolve(p.name)
            found[name] = driver.read(name)
        except JointsError:
            continue  # not on this protocol, or not readable there
    return found


def read_dump(path: str) -> dict[str, Any]:
    p = Path(path)
    if not p.is_file():
        raise UsageError(f"no such parameter file: {path}")
    try:
        data: dict[str, Any] = _toml().loads(p.read_text(encoding="utf-8"))
    except ValueError as exc:
        raise UsageError(f"{path}: not a TOML file ({exc})") from None
    if "settings" not in data or "drive" not in data:
        raise UsageError(f"{path}: not a `joints params dump` file (no [drive] / [settings])")
    return data


def comparable(data: Mapping[str, Any], identity: bool) -> dict[str, int]:
    out_: dict[str, int] = {}
    for s in ("settings", "identity") if identity else ("settings",):
        for k, v in dict(data.get(s, {})).items():
            if isinstance(v, int) and not isinstance(v, bool):
                out_[k] = v
    return out_


def differences(a: Mapping[str, int], b: Mapping[str, int]) -> list[tuple[str, int | None, int | None]]:
    names = list(a) + [k for k in b if k not in a]
    return [(n, a.get(n), b.get(n)) for n in names if a.get(n) != b.get(n)]


def _show(diffs: Sequence[tuple[str, int | None, int | None]], a: str, b: str, as_json: bool) -> None:
    if as_json:
        emit_json([{"name": n, a: x, b: y} for n, x, y in diffs])
        return
    for n, x, y in diffs:
        out(f"{n}: {'—' if x is None else x} ({a}) != {'—' if y is None else y} ({b})")


# --- commands ------------------------------------------------------------------------------------


def cmd_dump(args: argparse.Namespace) -> int:
    with open_rig(args) as rig:
        j = joint(rig, args.joint)
        data = dump_joint(rig, j)
    if args.json:
        emit_json(data)
        return 0
    text = dumps(data, header=f"joints params dump of joint {args.joint} ({args.config})\n"
                              "[settings] is what `joints params load` writes; [identity] only with "
                              "--include-identity --confirm")
    if args.output:
        Path(args.output).write_text(text, encoding="utf-8")
    else:
        sys.stdout.write(text)
        sys.stdout.flush()
    return 0


def cmd_load(args: argparse.Namespace) -> int:
    from joints.drivers.capabilities import SaveParameters

    if args.include_identity and not args.confirm:
        raise ConfirmationRequired("loading identity and line settings (address, node id, baud rate, protocol) can "
                                   "take the drive off this bus; add --confirm if you mean it")
    wanted = read_dump(args.file)
    with open_rig(args, config=load_config(args, on_exit="none")) as rig:
        j = joint(rig, args.joint)
        driver = j.driver
        values = comparable(wanted, args.include_identity)
        block = read_block(driver)
        here: dict[str, int | None] = {}
        for name in values:
            try:
                param, _ = driver.describe(name)
            except RegisterError:
                raise UsageError(f"{args.file}: {name} is not a parameter {driver.device} over "
                                 f"{driver.protocol} reaches") from None
            here[name] = block[name] if name in block else driver.read(name) if param.access.readable else None
        diffs = [(n, here[n], v) for n, v in values.items() if here[n] != v]
        _show(diffs, "drive", "file", args.json)
        if not args.apply:
            if diffs and not args.json:
                out(f"dry run: {len(diffs)} parameter(s) differ; add --apply to write them")
            return 0
        persistent = [n for n, _x, _y in diffs if driver.params[n].persistent]
        if persistent and not args.confirm:
            raise ConfirmationRequired(f"{', '.join(persistent)} are persistent or dangerous to write; nothing was "
                                       "written; add --confirm if you mean it")
        for n, _x, v in diffs:
            driver.params[n].check(v)  # every value checked before the first write
        if diffs and block and args.confirm and isinstance(driver, AllParameters) and all(n in block for n, _x, _v in diffs):
            driver.write_all_parameters({n: v for n, _x, v in diffs}, confirm=True)  # one 0x46
        else:
            for n, _x, v in diffs:
                j.write(n, v, confirm=args.confirm)
        if args.save:
            if not isinstance(driver, SaveParameters):
                raise UsageError(f"{driver.device} over {driver.protocol} has no save command (its settings are "
                                 "stored as they are written, or not at all)")
            driver.save_parameters(confirm=args.confirm)
        if not args.json:
            out(f"wrote {len(diffs)} parameter(s)" + (" and saved them" if args.save else ""))
    return 0


def cmd_diff(args: argparse.Namespace) -> int:
    paths = args.items
    if len(paths) == 2:
        a, b = read_dump(paths[0]), read_dump(paths[1])
        diffs = differences(comparable(a, args.include_identity), comparable(b, args.include_identity))
        _show(diffs, Path(paths[0]).name, Path(paths[1]).name, args.json)
    elif len(paths) == 3:
        config, name, file = paths
        args.config = config
        wanted = read_dump(file)
        with open_rig(args) as rig:
            j = joint(rig, name)
            live = dump_joint(rig, j)
        diffs = differences(comparable(live, args.include_identity), comparable(wanted, args.include_identity))
        _show(diffs, "drive", Path(file).name, args.json)
    else:
        raise UsageError("params diff takes two dump files, or CONFIG JOINT FILE")
    return 1 if diffs and args.exit_code else 0


def register(sub: Any) -> None:
    params = command_group(sub, "params", help="dump a drive's parameters to TOML, load them onto a drive, compare",
                           description="parameter files (TOML): dump a drive's parameters, load them onto a drive, "
                                       "compare",
                           example="joints params dump robot.toml shoulder -o shoulder.toml\n"
                                   "joints params diff robot.toml elbow shoulder.toml")

    d = command(params, "dump", help="read every readable parameter of a joint's drive to TOML",
                example="joints params dump robot.toml shoulder -o shoulder.toml", func=cmd_dump)
    d.add_argument("config")
    d.add_argument("joint")
    d.add_argument("-o", "--output", help="write to this file (default: stdout)")
    d.add_argument("--backend", choices=("sim", "hardware"))
    add_json(d)

    ld = command(params, "load", help="write a dump's settings onto a joint's drive (a dry run unless --apply)",
                 example="joints params load robot.toml elbow shoulder.toml            # shows the diff\n"
                         "joints params load robot.toml elbow shoulder.toml --apply\n"
                         "joints params load robot.toml elbow shoulder.toml --apply --save --confirm", func=cmd_load)
    ld.add_argument("config")
    ld.add_argument("joint")
    ld.add_argument("file")
    ld.add_argument("--apply", action="store_true", help="write what differs (default: only show it)")
    ld.add_argument("--include-identity", action="store_true", dest="include_identity",
                    help="also address, node id, baud rate, protocol switch (needs --confirm)")
    ld.add_argument("--save", action="store_true", help="store the settings in the drive's memory (needs --confirm)")
    ld.add_argument("--confirm", action="store_true", help="allow persistent writes and saves")
    ld.add_argument("--backend", choices=("sim", "hardware"))
    add_json(ld)

    df = command(params, "diff", help="compare two dumps, or a joint's drive against a dump (no output: same)",
                 example="joints params diff a.toml b.toml\njoints params diff robot.toml elbow shoulder.toml",
                 func=cmd_diff)
    df.add_argument("items", nargs="+", metavar="FILE | CONFIG JOINT FILE")
    df.add_argument("--include-identity", action="store_true", dest="include_identity",
                    help="compare identity and line settings too")
    df.add_argument("--exit-code", action="store_true", dest="exit_code", help="exit 1 when something differs")
    df.add_argument("--backend", choices=("sim", "hardware"))
    add_json(df)
