"""``joints identify`` and the recording half of ``joints replay``: sim-to-real tools (:mod:`joints.s2r`).

Rule: ``identify`` excites one joint inside its limits and writes the identified profile overlay;
a recording made by :class:`joints.s2r.record.Recorder` carries its own configuration, so
``joints replay RECORDING`` (no config) builds fresh twins from it and diffs the replies (exit 1
when they differ). A monitor log is replayed with a config instead (:mod:`joints.cli.monitor`).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from joints.cli.common import add_config, command, joint, load_config, nonnegative, open_rig, positive
from joints.errors import ConfigError


def cmd_identify(args: argparse.Namespace) -> int:
    """System identification of one joint; writes its profile overlay (joints.s2r.identify)."""
    from joints.s2r.identify import Excitation, identify, write_overlay

    exc = Excitation(mode=args.mode, duration=args.duration, amplitude=args.amplitude, f_min=args.f_min,
                     f_max=args.f_max, swing=args.swing, f_swing=args.f_swing)

    def progress(fraction: float, text: str) -> None:
        bar = "#" * round(30 * fraction)
        print(f"\ridentify [{bar:<30}] {fraction:4.0%}  {text}", end="", file=sys.stderr, flush=True)

    with open_rig(args, config=load_config(args)) as rig:  # the config's on_exit: a failed run disables
        j = joint(rig, args.joint)
        print(f"identifying joint {args.joint} ({rig.backend}): {exc.mode} multi-sine {exc.f_min:g}-{exc.f_max:g} Hz "
              f"for {exc.duration:g} s" + (f" ending in a {exc.swing:g} s swing at {exc.f_swing:g} Hz" if exc.swing else "")
              + f" inside limits {j.limits}", file=sys.stderr)
        ident = identify(rig, args.joint, exc, known_inertia=args.inertia, progress=progress)
        print(file=sys.stderr)
        driver: Any = j.driver  # every family's driver holds its physical profile
        profile = driver.profile
        device = rig.config.joints[args.joint].device
    out = Path(args.output) if args.output else Path(rig.config.base_dir) / f"{args.joint}.profile.toml"
    print(ident)
    bad = ident.problems()
    if bad and not args.force:
        print(f"no overlay written: the fit misses its thresholds ({'; '.join(bad)}); see docs/identification.md, "
              "or write it anyway with --force", file=sys.stderr)
        return 1
    write_overlay(out, profile, ident, device=device, config=rig.config.source, force=args.force)
    if bad:
        print(f"WARNING: written with --force although the fit misses its thresholds: {'; '.join(bad)}",
              file=sys.stderr)
    print(f"wrote {out}; use it with  profile_overlay = \"{out.name}\"  under [joints.{args.joint}]")
    return 0


def perturbations(items: Sequence[str]) -> dict[str, dict[str, float]]:
    """``JOINT:key=value,key=value`` -> {joint: {key: value}} (``joints replay --perturb``)."""
    out: dict[str, dict[str, float]] = {}
    for item in items:
        name, _, rest = item.partition(":")
        try:
            out[name] = {k.strip(): float(v) for k, v in (kv.split("=", 1) for kv in rest.split(",") if kv)}
        except ValueError:
            raise ConfigError(f"expected JOINT:key=value,... got {item!r}", key="--perturb",
                              allowed=("armature", "coulomb_friction", "viscous_friction", "torque_constant",
                                       "command_delay")) from None
        if not name or not out[name]:
            raise ConfigError(f"expected JOINT:key=value,... got {item!r}", key="--perturb")
    return out


def replay_recording(args: argparse.Namespace) -> int:
    """Replay a recording against fresh twins of its configuration; exit 1 when the replies differ."""
    from joints.s2r.record import replay

    report = replay(args.log, perturb=perturbations(args.perturb or ()))
    print(report)
    for d in report.differences[:args.show]:
        print(f"frame {d.index} t {d.t:.6f} {d.bus}: {d.request}")
        for q, (a, b) in d.quantities.items():
            print(f"    {q}: recorded {a} replayed {b}")
    if args.report:
        Path(args.report).write_text(json.dumps(report.to_json(), indent=1) + "\n", encoding="utf-8")
    return 0 if report.identical else 1


def replay_options(p: argparse.ArgumentParser) -> None:
    """The options of a recording's replay (``joints replay RECORDING``)."""
    p.add_argument("--perturb", action="append", metavar="JOINT:key=value,...",
                   help="recordings: perturb a twin first (World.perturb: armature, coulomb_friction, "
                        "viscous_friction, torque_constant factors; command_delay in s)")
    p.add_argument("--report", help="recordings: write the whole report (every differing frame) as JSON")
    p.add_argument("--show", type=int, default=5, help="recordings: differing frames to print (default 5)")


def register(sub: Any) -> None:
    ident = command(sub, "identify", help="identify a joint's inertia, friction, torque constant and delay (a safe "
                                          "excitation inside its limits) and write its profile overlay",
                    example="joints identify stand.toml joint1\njoints identify stand.toml joint1 --amplitude 32 "
                            "--duration 26 --swing 6\njoints identify stand.toml joint1 --mode speed --duration 30",
                    func=cmd_identify)
    add_config(ident)
    ident.add_argument("joint")
    ident.add_argument("--mode", choices=("torque", "speed"), default="torque",
                       help="torque (default: needs gravity on the joint) or speed (the drive's loop holds it)")
    ident.add_argument("--duration", type=positive, default=20.0, help="seconds of excitation")
    ident.add_argument("--amplitude", type=positive, help="peak N*m (torque) or rad/s (speed); default half the limit")
    ident.add_argument("--f-min", type=positive, default=0.2, dest="f_min", help="Hz")
    ident.add_argument("--f-max", type=positive, default=3.0, dest="f_max", help="Hz")
    ident.add_argument("--swing", type=nonnegative, default=0.0,
                       help="seconds of the duration that end it in a sine of the full amplitude (higher speeds: "
                            "tells Coulomb from Stribeck friction; docs/identification.md)")
    ident.add_argument("--f-swing", type=positive, default=0.6, dest="f_swing", help="Hz of the swing")
    ident.add_argument("--inertia", type=nonnegative,
                       help="the joint's whole inertia [kg*m^2] when it has no gravity torque")
    ident.add_argument("--output", help="overlay file (default: <joint>.profile.toml next to the config)")
    ident.add_argument("--force", action="store_true",
                       help="write the overlay even when the fit misses its thresholds (the warning goes into the "
                            "file); without it such a fit exits 1 and writes nothing")
