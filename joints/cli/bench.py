"""``joints bench``: every speed ratio of issue 23 (references measured in the same run), and a bus
planner for a config (how many joints fit at what control rate on its buses)."""

from __future__ import annotations

import argparse
from typing import Any

from joints.cli.common import command


def cmd_bench(args: argparse.Namespace) -> int:
    from joints import bench

    bench.run(quick=args.quick, config=args.config, rate=args.rate, speed=not args.plan_only)
    return 0


def register(sub: Any) -> None:
    b = command(sub, "bench", help="speed ratios against raw mj_step and pymodbus, and a bus planner",
                example="joints bench\njoints bench --config robot.toml --rate 100\n"
                        "joints bench --plan-only --config robot.toml", func=cmd_bench)
    b.add_argument("--config", help="plan the buses of this config: joints per bus at which control rate")
    b.add_argument("--rate", type=float, default=None, help="control rate [Hz] the planner checks (default 50)")
    b.add_argument("--quick", action="store_true", help="tiny sizes: checks that everything runs, not speed")
    b.add_argument("--plan-only", action="store_true", help="only the bus planner for --config")
