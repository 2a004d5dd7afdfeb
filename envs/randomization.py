"""Domain randomisation of drive-level parameters (sim backend only).

One :class:`DomainRandomization` holds a range per parameter; every ``reset()`` draws one value
per joint (per env for the latency) from ``env.np_random``, uniformly in the closed range, so the
draw is reproducible from the reset seed. A range ``(x, x)`` fixes a parameter; the nominal value
is a factor of 1 (or 0 noise, 0 latency).

=====================  ======================================  ====================  ==============
parameter              what changes                            unit                  default range
=====================  ======================================  ====================  ==============
position_loop_gain     drive register 0x0030 (Kp), x factor    factor                [0.7, 1.3]
speed_loop_gain        drive register 0x0031 (bandwidth)       factor                [0.7, 1.3]
speed_loop_integral    drive register 0x0032 (integral time)   factor                [0.7, 1.5]
friction               Coulomb friction and viscous damping    factor                [0.5, 2.0]
                       of the joint (the profile's numbers are
                       uncertain by ~3x)
armature               reflected rotor inertia of the joint    factor                [0.8, 1.2]
torque_constant        true / nominal torque per ampere (the   factor                [0.9, 1.1]
                       drive still converts with the nominal
                       constant, as a real drive does)
encoder_noise          std of Gaussian noise on the reported   rad                   [0, 1e-4]
                       joint positions (observations)
latency                bus latency: an action takes effect     control periods       [0, 1]
                       this many periods later                 (integer)
sensor_noise           the drives' sensor noise (velocity      factor                [1, 1]
                       estimate, current, position: the
                       profile's levels, joints.sim.sensors)
=====================  ======================================  ====================  ==============

A fixed range ``(x, x)`` of ``sensor_noise`` draws nothing (the other draws keep their stream).

Everything goes through the rig's public sim API, ``rig.sim.perturb`` (in profile terms: armature,
Coulomb and viscous friction, torque constant, loop gains): the loop gains are written into the
twin's gain parameters (whatever the drive calls them: eRob 0x0030-0x0032, ZLAC Pl Kp / Vl Kp /
Vl Ki) as a write of them would, after the drives' power-on reset; friction, armature and the
torque constant change the MuJoCo model - the drive keeps tuning its loops for the nominal
inertia, as a real drive whose load was mis-estimated does. The eRob envs then derate the episode's
position profile, velocity ramps and speed cap to what the drawn plant can follow
(:meth:`envs.base.JointsEnv._derate`), so a draw never makes an action trip a drive.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

#: the loop-gain factors -> the drive's loop they scale (World.perturb gains, whatever the drive calls them)
GAINS = {"position_loop_gain": "position", "speed_loop_gain": "speed", "speed_loop_integral": "integral"}


@dataclass(frozen=True)
class DomainRandomization:
    """Ranges ``(low, high)`` of the randomised parameters (see the module docstring)."""

    position_loop_gain: tuple[float, float] = (0.7, 1.3)
    speed_loop_gain: tuple[float, float] = (0.7, 1.3)
    speed_loop_integral: tuple[float, float] = (0.7, 1.5)
    friction: tuple[float, float] = (0.5, 2.0)
    armature: tuple[float, float] = (0.8, 1.2)
    torque_constant: tuple[float, float] = (0.9, 1.1)
    encoder_noise: tuple[float, float] = (0.0, 1e-4)
    latency: tuple[int, int] = (0, 1)
    sensor_noise: tuple[float, float] = (1.0, 1.0)

    def __post_init__(self) -> None:
        for f in fields(self):
            rng = getattr(self, f.name)
            if not isinstance(rng, (tuple, list)) or len(rng) != 2:
                raise ValueError(f"domain randomisation {f.name}: expected (low, high), got {rng!r}")
            lo, hi = rng
            if any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) for v in rng):
                raise ValueError(f"domain randomisation {f.name}: expected finite numbers, got {rng!r}")
            if lo > hi:
                raise ValueError(f"domain randomisation {f.name}: low {lo} > high {hi}")
            if f.name == "latency":
                if lo < 0 or not float(lo).is_integer() or not float(hi).is_integer():
                    raise ValueError(f"domain randomisation latency: expected whole periods >= 0, got {rng!r}")
                object.__setattr__(self, f.name, (int(lo), int(hi)))
            elif f.name == "sensor_noise":
                if lo < 0:
                    raise ValueError(f"domain randomisation sensor_noise: factors must be >= 0, got {rng!r}")
                object.__setattr__(self, f.name, (float(lo), float(hi)))
            elif f.name == "encoder_noise":
                if lo < 0:
                    raise ValueError(f"domain randomisation encoder_noise: std must be >= 0, got {rng!r}")
                object.__setattr__(self, f.name, (float(lo), float(hi)))
            else:
                if lo <= 0:
                    raise ValueError(f"domain randomisation {f.name}: factors must be > 0, got {rng!r}")
                object.__setattr__(self, f.name, (float(lo), float(hi)))

    @classmethod
    def from_arg(cls, arg: bool | Mapping[str, Any] | DomainRandomization | None) -> DomainRandomization | None:
        """``False``/``None``: off; ``True``: the default ranges; a mapping: defaults with overrides."""
        if arg is None or arg is False:
            return None
        if arg is True:
            return cls()
        if isinstance(arg, cls):
            return arg
        if isinstance(arg, Mapping):
            allowed = [f.name for f in fields(cls)]
            unknown = sorted(k for k in arg if k not in allowed)
            if unknown:
                raise ValueError(f"unknown domain randomisation parameter(s) {unknown}; allowed: {allowed}")
            return cls(**{k: tuple(v) for k, v in arg.items()})
        raise TypeError(f"domain_randomization must be a bool, a mapping or DomainRandomization, got {arg!r}")

    def sample(self, rng: np.random.Generator, joints: list[str]) -> dict[str, Any]:
        """One draw: ``{"latency": int, "joints": {name: {parameter: value}}}`` (plain Python numbers)."""
        per_joint: dict[str, dict[str, float]] = {}
        for name in joints:
            per_joint[name] = {
                f.name: float(rng.uniform(*getattr(self, f.name))) for f in fields(self)
                if f.name not in ("latency", "sensor_noise")
            }
            lo, hi = self.sensor_noise
            per_joint[name]["sensor_noise"] = float(rng.uniform(lo, hi)) if hi > lo else lo
        lo_l, hi_l = self.latency
        return {"latency": int(rng.integers(lo_l, hi_l + 1)), "joints": per_joint}


def apply_sensors(world: Any, joint: str, factor: float) -> None:
    """Set joint ``joint``'s sensor noise to ``factor`` x its profile's levels (a draw's ``sensor_noise``;
    the twin's sensors: ``joints.sim.sensors``, reached through the world's drives)."""
    for sensor in getattr(world.drives[joint], "sensors", ()):
        sensor.model = sensor.nominal.scaled(factor)
