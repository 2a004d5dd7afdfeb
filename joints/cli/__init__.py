"""The ``joints`` command: scan, inspect, drive, monitor and simulate joints on real or emulated buses.

Rule: read-only by default; anything that moves or persists needs an explicit subcommand, and
persistent or raw writes need ``--confirm``. Exit codes: 0 ok, 1 device or bus error, 2 usage.

One module per command or group (:data:`COMMANDS`); each has ``register(subparsers)``. A new
command is a module here with that function, added to :data:`COMMANDS`.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence

from joints.cli.common import exit_code, message
from joints.errors import JointsError

__all__ = ["COMMANDS", "build_parser", "main"]

#: the command modules, in the order ``joints --help`` lists them
COMMANDS: tuple[str, ...] = (
    "scan",  # find drives
    "info",  # versions, model, key parameters, faults
    "basic",  # state, read, write, registers
    "watch",  # live table
    "motion",  # move, jog, enable, disable, stop, clear
    "monitor",  # monitor, replay
    "send",  # raw frames
    "params",  # dump, load, diff
    "plot",  # trace / monitor log -> PNG
    "s2r",  # identify (replay of recordings: monitor's replay)
    "sim",  # sim serve, sim view
    "bench",  # speed ratios, bus planner
)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="joints", description=(__doc__ or "joints").splitlines()[0],
        epilog="examples:\n  joints scan --port /dev/ttyUSB0\n  joints info robot.toml shoulder\n"
               "  joints sim serve robot.toml\n\n`joints COMMAND --help` shows each command's options and an example.",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--version", action="version", version=f"joints {__import__('joints').__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"joints.cli.{name}").register(sub)
    return p


def _quiet_stdout() -> None:
    """The reader closed the pipe: send whatever is still buffered nowhere (no error at exit)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass


def main(argv: Sequence[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        try:
            code = int(args.func(args))
        except JointsError as exc:
            print(f"joints: error: {message(exc)}", file=sys.stderr)
            code = exit_code(exc)
        except KeyboardInterrupt:
            code = 130
        sys.stdout.flush()
        return code
    except BrokenPipeError:
        _quiet_stdout()
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
