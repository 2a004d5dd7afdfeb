"""Coulomb / Stribeck / viscous recovery on the reality twins over several seeds (docs/identification.md).

Not a test: the numbers behind the tables. Each twin is identified once on its noise-free readings (the
reference) and once per seed with sensors at the judged levels, in process at 1 kHz::

    python tests/s2r/measure_friction.py                 # the tests' excitation (20 s multi-sine + 6 s swing)
    python tests/s2r/measure_friction.py --no-swing      # the multi-sine alone (20 s)
    python tests/s2r/measure_friction.py --seeds 0 1 --twins M2
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from reality import REALITIES, open_real

from joints.s2r.identify import Excitation, Identification, identify


def row(name: str, got: Identification, ref: Identification | None = None) -> str:
    def rel(key: str) -> str:
        a, b = getattr(got, key), getattr(ref, key)
        return f" d{key.split('_')[0][:4]} {(a / b - 1) * 100:+.1f}%" if b else f" d{key.split('_')[0][:4]} {a - b:+.3f}"

    out = (f"{name:5s} coulomb {got.coulomb_friction:6.3f} stribeck {got.stribeck_friction:6.3f} v_s "
           f"{got.stribeck_velocity:5.2f} a {got.stribeck_exponent:3.1f} viscous {got.viscous_friction:6.3f} "
           f"armature {got.armature:.4f} scale {got.torque_scale:.4f} delay {(got.delay or 0) * 1e3:.2f} ms"
           f"{' REFUSED' if got.problems() else ''}")
    if ref is not None:
        out += "  vs ref:" + "".join(rel(k) for k in ("coulomb_friction", "stribeck_friction", "viscous_friction"))
    return out


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    p.add_argument("--twins", nargs="+", default=[r.name.split()[-1] for r in REALITIES])
    p.add_argument("--no-swing", action="store_true")
    args = p.parse_args()
    exc = Excitation(duration=20.0, amplitude=32.0) if args.no_swing else \
        Excitation(duration=26.0, amplitude=32.0, swing=6.0)
    for reality in REALITIES:
        if reality.name.split()[-1] not in args.twins:
            continue
        print(f"{reality.name}: truth coulomb {reality.coulomb} stribeck {reality.stribeck} v_s {reality.v_stribeck} "
              f"a {reality.alpha} viscous {reality.viscous} armature {reality.armature:.4f} scale "
              f"{reality.torque_scale:.4f} delay {reality.delay * 1e3:.2f} ms")
        runs: dict[int | None, Identification] = {}
        for seed in (None, *args.seeds):
            rig = open_real(reality, noise=seed is not None, seed=seed or 0)
            try:
                runs[seed] = identify(rig, "joint1", exc)
            finally:
                rig.close()
            print(row("ref" if seed is None else f"s{seed}", runs[seed], None if seed is None else runs[None]),
                  flush=True)


if __name__ == "__main__":
    main()
