"""What every ``joints`` command shares: argument types, exit codes, output, opening a rig.

Rules:

* Exit codes: 0 ok, 1 a device or bus error (no reply, a fault, a refused frame, a port that will
  not open), 2 a usage error (bad arguments, config, unknown joint or parameter, a command refused
  before anything was sent, a missing ``--confirm``). :func:`exit_code` is the one mapping.
* Numbers are checked when the arguments are parsed (``--duration -1`` is a usage error before any
  bus is opened): use the argument types here.
* Output goes through :func:`out` / :func:`emit_json`; a reader that closes the pipe early
  (``joints registers | head -1``) ends the command quietly (``main`` handles BrokenPipeError).
* Read-only commands open the rig with ``on_exit = "none"``: leaving them never stops or disables
  a drive that somebody else enabled. Commands that enable manage shutdown themselves.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from joints.errors import (
    CommandError,
    ConfigError,
    ConfirmationRequired,
    EncodeError,
    JointsError,
    RegisterError,
    UnknownJoint,
)

if TYPE_CHECKING:
    from joints.joint import Joint
    from joints.rig import Rig

OK = 0
FAILED = 1  #: a device or bus error
USAGE = 2  #: bad arguments, config or request; nothing (harmful) was sent

#: the backends a command may force (``--backend``)
BACKENDS = ("sim", "hardware")


class UsageError(JointsError):
    """The command line asks for something that cannot be done (exit code 2)."""


def exit_code(exc: BaseException) -> int:
    """The exit code of a failed command (see the module docstring)."""
    usage = (ConfigError, ConfirmationRequired, RegisterError, UnknownJoint, CommandError, EncodeError, UsageError)
    return USAGE if isinstance(exc, usage) else FAILED


def message(exc: BaseException) -> str:
    """An error's text for the command line: a refusal names the ``--confirm`` flag, not the keyword argument."""
    text = str(exc)
    if isinstance(exc, ConfirmationRequired):
        for api, flag in (("pass confirm=True if you mean it", "add --confirm if you mean it"),
                          ("then pass confirm=True", "then add --confirm"),
                          ("pass confirm=True", "add --confirm"), ("confirm=True", "--confirm")):
            text = text.replace(api, flag)
        if "--confirm" not in text:
            text += " (add --confirm if you mean it)"
    return text


# --- argument types (checked at parse time) ----------------------------------------------------


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def number(text: str) -> float:
    """Any finite number (a target may be negative)."""
    return _number(text)


def positive(text: str) -> float:
    """A finite number > 0 (a period, a speed)."""
    value = _number(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def nonnegative(text: str) -> float:
    """A finite number >= 0 (a duration, a timeout)."""
    value = _number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def integer(text: str) -> int:
    """An integer: decimal, 0x.. hex, 0b.. binary (a register value may be negative)."""
    try:
        return int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer (decimal or 0x.. hex), got {text!r}") from None


def count(text: str) -> int:
    """An integer >= 1."""
    value = integer(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text}")
    return value


def address_range(text: str) -> range:
    """``7`` or ``1-32``: bus addresses (0..255; each protocol narrows it)."""
    lo, _, hi = text.partition("-")
    try:
        a = int(lo, 0)
        b = int(hi, 0) if hi else a
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an address range like 1-32, got {text!r}") from None
    if not 0 <= a <= b <= 255:
        raise argparse.ArgumentTypeError(f"address range must be within 0-255 (low-high), got {text!r}")
    return range(a, b + 1)


def int_list(text: str) -> tuple[int, ...]:
    """``9600,115200``: positive integers."""
    try:
        values = tuple(int(v, 0) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected integers separated by commas, got {text!r}") from None
    if not values or any(v <= 0 for v in values):
        raise argparse.ArgumentTypeError(f"expected positive integers separated by commas, got {text!r}")
    return values


def key(text: str) -> str | int:
    """A parameter by manual name or by protocol address (``0x0066``)."""
    try:
        return int(text, 0)
    except ValueError:
        return text


# --- building the parser -----------------------------------------------------------------------


Handler = Callable[[argparse.Namespace], int]


def command(sub: Any, name: str, *, help: str, example: str, func: Handler,
            description: str | None = None) -> argparse.ArgumentParser:
    """A subcommand with its help, an example in its ``--help`` and its handler."""
    lines = "\n".join(f"  {line}" for line in example.strip().splitlines())
    p: argparse.ArgumentParser = sub.add_parser(
        name, help=help, description=description or help, epilog=f"example:\n{lines}",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.set_defaults(func=func)
    return p


def command_group(sub: Any, name: str, *, help: str, example: str, description: str | None = None) -> Any:
    """A command group (``joints NAME COMMAND ...``) with an example in its ``--help``; returns its subparsers."""
    lines = "\n".join(f"  {line}" for line in example.strip().splitlines())
    p: argparse.ArgumentParser = sub.add_parser(
        name, help=help, description=description or help, epilog=f"example:\n{lines}",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    return p.add_subparsers(dest=f"{name}_command", required=True, metavar="COMMAND")


def add_config(p: argparse.ArgumentParser, *, optional: bool = False) -> None:
    """The config file and ``--backend``."""
    if optional:
        p.add_argument("--config", help="a rig config (TOML)")
    else:
        p.add_argument("config", help="the rig config (TOML)")
    p.add_argument("--backend", choices=BACKENDS, help="override the config's backend")


def add_json(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="machine-readable output (JSON)")


# --- output ------------------------------------------------------------------------------------


def out(text: str = "") -> None:
    """One line to stdout, flushed (a live pipe sees it at once)."""
    sys.stdout.write(text + "\n")
    sys.stdout.flush()


def emit_json(obj: object) -> None:
    out(json.dumps(obj, default=_jsonable))


def _jsonable(obj: object) -> object:
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return dataclasses.asdict(obj)
    if isinstance(obj, bytes):
        return obj.hex(" ").upper()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return str(obj)


def finite(value: float) -> float | None:
    """JSON has no NaN: a quantity the drive does not report is null."""
    return value if math.isfinite(value) else None


def note(text: str) -> None:
    """A remark for a person (stderr), never mixed into machine-readable output."""
    sys.stderr.write(f"joints: {text}\n")
    sys.stderr.flush()


def warn(text: str) -> None:
    sys.stderr.write(f"joints: warning: {text}\n")
    sys.stderr.flush()


# --- rigs --------------------------------------------------------------------------------------


def load_config(args: argparse.Namespace, *, on_exit: str | None = None, path: str | None = None) -> Any:
    """The rig config of ``args.config`` (``--backend`` applied; ``on_exit`` overridden if given)."""
    from joints.config import load

    cfg = load(Path(path or args.config), backend=args.backend)
    if on_exit is not None:
        cfg = dataclasses.replace(cfg, on_exit=on_exit)
    return cfg


def open_rig(args: argparse.Namespace, *, on_exit: str = "none", config: Any = None) -> Rig:
    """The rig of ``args.config``. Read-only commands keep ``on_exit = "none"`` (leave every drive as found)."""
    import joints

    return joints.open(config if config is not None else load_config(args, on_exit=on_exit))


def joint(rig: Rig, name: str) -> Joint:
    """The rig's joint ``name``; an unknown name is a configuration error listing the joints."""
    try:
        return rig.joints[name]
    except KeyError:
        raise ConfigError(f"no joint named {name!r}", file=rig.config.source, key="joints",
                          allowed=sorted(rig.joints)) from None


def joints_of(rig: Rig, names: Sequence[str]) -> list[Joint]:
    """The named joints (every joint when ``names`` is empty)."""
    return [joint(rig, n) for n in names] if names else list(rig.joints.values())


def bus_of(rig: Rig, name: str | None) -> str:
    """A bus of the rig by name (the only bus when ``name`` is None)."""
    if name is None:
        if len(rig.buses) == 1:
            return next(iter(rig.buses))
        raise ConfigError("the config has several buses: name one (--bus)", file=rig.config.source, key="buses",
                          allowed=sorted(rig.buses))
    if name not in rig.buses:
        raise ConfigError(f"no bus {name!r}", file=rig.config.source, key="buses", allowed=sorted(rig.buses))
    return name


def wall_sleep(seconds: float) -> None:
    """Pace a live view on the wall clock (the only wall-clock wait of the command line)."""
    import time

    if seconds > 0:
        time.sleep(seconds)
