"""The reliability harness, one command: ``python tests/harness/run.py --count N --seed S [--target ...]``.

Runs (a) fuzzing of every codec in both roles and of every twin endpoint the registry builds, N
fuzzed frames each, and (b) transactions under fault injection (``--rate``, 10 % by default) for
every setup, in process and, with ``--pty``, against a served world over a pseudo-terminal. Prints
counts per target and per invariant and exits 1 on any violation (2 on bad arguments).

Targets are named ``codec:<codec>/<role>``, ``endpoint:<family>/<protocol>`` and
``transactions:<family>/<protocol>``; ``--target`` takes shell patterns (``--target 'codec:*'``),
``--list`` prints them. ``--atheris TARGET`` runs one codec or endpoint under atheris'
coverage-guided fuzzer instead (``--count`` runs), if atheris is installed.
"""

from __future__ import annotations

import argparse
import fnmatch
import sys
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make tests/ (for harness, testdata) and the repo importable
    _TESTS = Path(__file__).resolve().parents[1]
    sys.path[:0] = [str(_TESTS), str(_TESTS.parent)]

from harness import codec_fuzz, endpoint_fuzz, transactions
from harness.report import Report


def all_targets() -> list[str]:
    return ([f"codec:{n}" for n in codec_fuzz.targets()]
            + [f"endpoint:{n}" for n, _f, _p in endpoint_fuzz.endpoints()]
            + [f"transactions:{n}" for n in transactions.SETUPS])


def select(patterns: list[str] | None) -> list[str]:
    names = all_targets()
    if not patterns:
        return names
    chosen = [n for n in names if any(fnmatch.fnmatchcase(n, p) or fnmatch.fnmatchcase(n.split(":", 1)[1], p)
                                      for p in patterns)]
    if not chosen:
        raise SystemExit(f"no target matches {patterns}; targets: {', '.join(names)}")
    return chosen


def run(args: argparse.Namespace) -> Report:
    report = Report(args.seed)
    chosen = select(args.target)
    kinds: dict[str, list[str]] = {"codec": [], "endpoint": [], "transactions": []}
    for name in chosen:
        kind, rest = name.split(":", 1)
        kinds[kind].append(rest)
    codec_fuzz.run(report, kinds["codec"], args.count, args.seed)
    endpoint_fuzz.run(report, kinds["endpoint"], args.count, args.seed)
    setups = kinds["transactions"]
    n = args.transactions
    if n:
        transactions.run(report, setups, n, args.seed, rate=args.rate)
        if args.echo:
            transactions.run(report, setups, n, args.seed, rate=args.rate, echo=True)
        if args.can_duplicates:
            transactions.run(report, setups, n, args.seed, rate=args.rate, can_duplicates=True)
        if args.flips:
            transactions.run(report, setups, n, args.seed, rate=args.rate, flips=args.flips)
        if args.pty:
            transactions.run(report, setups, args.pty, args.seed, rate=args.rate, pty=True)
    return report


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="tests/harness/run.py", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--count", type=int, default=100_000, help="fuzzed frames per codec and per endpoint")
    parser.add_argument("--transactions", type=int, default=10_000, help="transactions per setup (0: none)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--target", action="append", help="shell pattern of targets to run (repeatable)")
    parser.add_argument("--rate", type=float, default=0.1, help="fault rate per frame and direction")
    parser.add_argument("--echo", action="store_true", help="also run serial setups through an echoing adapter")
    parser.add_argument("--pty", type=int, default=0, metavar="N",
                        help="also run N transactions per serial setup against a world served on a pty")
    parser.add_argument("--can-duplicates", action="store_true",
                        help="also run CAN setups with requests duplicated (shows a protocol limit: violations "
                             "expected on eRob CAN)")
    parser.add_argument("--flips", type=int, default=0, metavar="N",
                        help="also run every setup with corruptions of up to N bits (beyond what a protocol's check "
                             "always catches: violations expected on MKS native for N >= 2)")
    parser.add_argument("--list", action="store_true", help="print the targets and exit")
    parser.add_argument("--atheris", metavar="TARGET", help="fuzz one codec/endpoint target with atheris")
    args = parser.parse_args(argv)
    if args.list:
        print("\n".join(all_targets()))
        return 0
    if args.atheris:
        from harness import fuzz_atheris

        return fuzz_atheris.main(args.atheris, args.count, args.seed)
    report = run(args)
    report.print()
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main())
