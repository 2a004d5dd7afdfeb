"""``joints bench``: every speed ratio of issue 23 (references measured in the same run), and a bus
planner for a config (how many joints fit at what control rate on its buses)."""

from __future__ import annotations

import argparse
from typing import Any

from joints.cli.common import command


def cmd_bench(args: argparse.Namespace) -> int:
    from joints import bench

    if args.hardware:
        if args.config is None:
            from joints.errors import ConfigError

            raise ConfigError("--hardware needs --config ROBOT.toml (the buses to measure)", key="--config")
        bench.run_hardware(args.config, overlay=args.write_overlay, rounds=args.rounds)
        return 0
    bench.run(quick=args.quick, config=args.config, rate=args.rate, speed=not args.plan_only)
    return 0


def register(sub: Any) -> None:
    b = command(sub, "bench", help="speed ratios against raw mj_step and pymodbus, and a bus planner",
                example="joints bench\njoints bench --config robot.toml --rate 100\n"
                        "joints bench --plan-only --config robot.toml\n"
                        "joints bench --hardware --config robot.toml --write-overlay timing.toml", func=cmd_bench)
    b.add_argument("--config", help="plan the buses of this config: joints per bus at which control rate")
    b.add_argument("--rate", type=float, default=None, help="control rate [Hz] the planner checks (default 50)")
    b.add_argument("--quick", action="store_true", help="tiny sizes: checks that everything runs, not speed")
    b.add_argument("--plan-only", action="store_true", help="only the bus planner for --config")
    b.add_argument("--hardware", action="store_true",
                   help="measure the real buses of --config: round trip of every drive's read-only status "
                        "transaction, overhead per transaction (turnaround + adapter latency); reads only")
    b.add_argument("--rounds", type=int, default=50, help="--hardware: transactions measured per drive (default 50)")
    b.add_argument("--write-overlay", dest="write_overlay", metavar="FILE",
                   help="--hardware: write the measured timing to FILE, a config overlay "
                        "(timing_overlay = \"FILE\" in the config)")
