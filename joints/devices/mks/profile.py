"""Physical profiles of the MKS SERVO42D (NEMA17) and SERVO57D (NEMA23) closed-loop steppers.

A profile holds what a twin needs for the motor model (torque constant, holding torque, the
torque-speed roll-off, rotor inertia, friction, stall protection) and what a driver needs to bound
commands (current range, encoder and step resolution). SI units at the motor shaft (the drives
are direct drive; a lead screw is the joint's business).

Where the numbers come from
    ``device-facts.md`` section 3 (the MKS manual V1.0.9 via the facts file: driver limits) and
    section 4 (suggested simulation defaults: the bundled motors are not specified by MKS, so a
    typical motor is assumed: 17HS19-2004S1 for the 42D, 23HS45-4204S for the 57D), and the RS485
    manual V1.0.5 Part 3. ``sources`` maps every field to a text that starts with the facts file's
    kind: ``PUB`` (published), ``MEAS`` (measured by a third party), ``CFG`` (someone's working
    configuration), ``EST`` (estimate, reasoning given). The driver limits are solid (PUB); the
    motor numbers are PUB for the assumed motor only; inertia and friction are EST. **Confirm the
    motor on the real unit.**

Torque model (facts section 4)
    Peak torque at a current: ``min(torque_constant * I, holding_torque)`` (torque is roughly
    proportional to current up to the motor's rated current). Torque falls linearly with speed to
    zero at the no-load speed ``bus_voltage / back_emf_constant`` (Ke ~ Kt):
    ``available = peak * max(0, 1 - |w| / w0)``. For the 42D at 24 V: w0 = 81 rad/s (777 rpm); for
    the 57D: 34 rad/s (321 rpm). The facts also quote (EST) "a NEMA23 at 24 V loses about 45 % of
    its torque by 573 rpm", which a 321 rpm no-load speed contradicts: the 57D's roll-off is the
    least certain number here (override ``back_emf_constant`` or ``bus_voltage`` to change it).

Locked-rotor protection (facts section 3, "e.g. >180 degrees within 300 ms")
    ``stall_error`` [rad] and ``stall_time`` [s]: the protection (0x88 enabled) trips when the
    position error stays above ``stall_error`` for ``stall_time``. PUB as an example value, not a
    firmware specification.

Overrides
    Every field except ``model`` and ``sources`` can be overridden from configuration through
    :meth:`MksProfile.with_overrides` (validated; overridden fields are marked ``CFG``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from types import MappingProxyType

from joints.devices.profile import validate_fields, with_overrides
from joints.errors import ConfigError

__all__ = ["DEFAULT_MODEL", "PROFILES", "MksProfile", "profile"]

_RPM = 2.0 * math.pi / 60.0  #: rad/s per rpm


def _empty_sources() -> Mapping[str, str]:
    return MappingProxyType({})


@dataclass(frozen=True, slots=True)
class MksProfile:
    """One MKS closed-loop stepper with its motor (SI units at the motor shaft; see the module docstring)."""

    model: str  #: "SERVO42D" or "SERVO57D"
    motor: str  #: the assumed stepper motor
    full_steps: int  #: full steps per turn (1.8 degree motor)
    encoder_counts: int  #: encoder counts per turn
    limit_inputs: int  #: limit switch inputs (IN_1 only on the 42D; IN_1 + IN_2 on the 57D)
    bus_voltage: float  #: V
    max_working_current: float  #: A, the largest "Ma"
    default_working_current: float  #: A, "Ma" default
    default_home_current: float  #: A, "Hm_Ma" default
    rated_current: float  #: A, the motor's rated phase current
    holding_torque: float  #: N*m at the rated current
    torque_constant: float  #: N*m/A
    back_emf_constant: float  #: V*s/rad
    phase_resistance: float  #: ohm
    phase_inductance: float  #: H
    rotor_inertia: float  #: kg*m^2
    coulomb_friction: float  #: N*m
    viscous_friction: float  #: N*m*s/rad
    motor_mass: float  #: kg
    stall_error: float  #: rad, locked-rotor protection threshold
    stall_time: float  #: s, how long the error must last
    #: s from a request's end to the drive answering it (docs/timing.md)
    turnaround: float = 0.0008
    # -- sensors as the drive reports them (joints.sim.sensors; sources: _SENSOR_SOURCES) --
    velocity_window: float = 0.005  #: s, the speed estimate: encoder counts over this window
    velocity_noise: float = 0.0  #: rad/s, std of noise beyond the quantisation
    position_noise: float = 0.0  #: rad, std beyond the encoder's counts
    current_noise: float = 0.0  #: A (the drive reports no current)
    current_resolution: float = 0.0  #: A (the drive reports no current)
    sample_jitter: float = 0.0005  #: s, age of a status value: uniform in [0, this]
    sources: Mapping[str, str] = field(default_factory=_empty_sources, compare=False, hash=False)

    def __post_init__(self) -> None:
        validate_fields(self, _INT_FIELDS, _FLOAT_FIELDS + _TIMING_FIELDS, _NON_NEGATIVE_FIELDS + _TIMING_FIELDS)
        for name in ("default_working_current", "default_home_current"):
            if getattr(self, name) > self.max_working_current:
                raise ConfigError(f"{self.model}: {name} {getattr(self, name)} A exceeds max_working_current "
                                  f"{self.max_working_current} A", key=name)
        if self.limit_inputs > 2:
            raise ConfigError(f"{self.model}: limit_inputs must be 1 or 2, got {self.limit_inputs}",
                              key="limit_inputs")
        object.__setattr__(self, "sources", MappingProxyType(dict(self.sources)))

    # --- derived quantities ----------------------------------------------------------------

    @property
    def no_load_speed(self) -> float:
        """Speed [rad/s] where the available torque reaches zero: ``bus_voltage / back_emf_constant``."""
        return self.bus_voltage / self.back_emf_constant

    @property
    def no_load_rpm(self) -> float:
        return self.no_load_speed / _RPM

    @property
    def max_torque(self) -> float:
        """Largest motor torque [N*m] (the world's actuator range): the holding torque."""
        return self.holding_torque

    @property
    def armature(self) -> float:
        """Rotor inertia at the joint [kg*m^2] (direct drive)."""
        return self.rotor_inertia

    @property
    def counts_per_rad(self) -> float:
        return self.encoder_counts / (2.0 * math.pi)

    def peak_torque(self, current: float) -> float:
        """Torque [N*m] at standstill for a phase current [A]: ``min(Kt * I, holding_torque)``."""
        return min(self.torque_constant * abs(current), self.holding_torque)

    def available_torque(self, speed: float, current: float) -> float:
        """Largest torque [N*m] at ``speed`` [rad/s] and ``current`` [A] (linear roll-off to no-load speed)."""
        return self.peak_torque(current) * max(0.0, 1.0 - abs(speed) / self.no_load_speed)

    # --- configuration ---------------------------------------------------------------------

    def with_overrides(self, **kw: object) -> MksProfile:
        """A copy with some fields replaced (config ``profile = {...}``), validated."""
        return with_overrides(self, _OVERRIDABLE, kw)


_INT_FIELDS = ("full_steps", "encoder_counts", "limit_inputs")
_FLOAT_FIELDS = (
    "bus_voltage", "max_working_current", "default_working_current", "default_home_current", "rated_current",
    "holding_torque", "torque_constant", "back_emf_constant", "phase_resistance", "phase_inductance",
    "rotor_inertia", "coulomb_friction", "viscous_friction", "motor_mass", "stall_error", "stall_time",
)
_NON_NEGATIVE_FIELDS = ("coulomb_friction", "viscous_friction")
# the sensor models (joints.sim.sensors): 0 switches a term off
_SENSOR_FIELDS = ("velocity_window", "velocity_noise", "position_noise", "current_noise", "current_resolution",
                  "sample_jitter")
_FLOAT_FIELDS: tuple[str, ...] = (*_FLOAT_FIELDS, *_SENSOR_FIELDS)  # type: ignore[no-redef]
_NON_NEGATIVE_FIELDS: tuple[str, ...] = (*_NON_NEGATIVE_FIELDS, *_SENSOR_FIELDS)  # type: ignore[no-redef]
_SENSOR_SOURCES = {
    "velocity_window": ("EST: the manual states no speed estimator; the MT6816 (16384 counts) differentiated at "
                        "1 kHz steps by 0.38 rad/s, so the drive must average: a 5 ms window assumed (steps of "
                        "0.077 rad/s; the register's 1 r/min unit quantises on top)"),
    "velocity_noise": "EST: 0 - the estimate's noise is its quantisation (velocity_window)",
    "position_noise": "EST: 0 - the encoder's quantisation is the register's",
    "current_noise": "PUB: the drive reports no current (MKS-man: no current read command); 0",
    "current_resolution": "PUB: the drive reports no current; 0",
    "sample_jitter": "EST: status values refreshed every 0.5 ms; not published",
}
_TIMING_FIELDS = ("turnaround",)  # bus timing (issue 29): finite, >= 0
_OVERRIDABLE: tuple[str, ...] = tuple(f.name for f in fields(MksProfile) if f.name not in ("model", "sources"))

_COMMON_SOURCES = {
    **_SENSOR_SOURCES,
    "turnaround": ("EST 0.8 ms: no MKS manual states a reply turnaround; a real ZLAC8015D log shows 1.8 ms per "
                   "transaction beyond bytes and t3.5, less 1 ms of USB adapter latency (docs/timing.md)"),
    "full_steps": "PUB 1.8 degree motors only (facts 3, MKS-man §14)",
    "encoder_counts": "PUB MT6816 14-bit, 16384 counts/rev (facts 3, MKS-man §1.3)",
    "bus_voltage": "PUB supply 12-24 V (facts 3); 24 V assumed (the 57D's MOSFETs are 30 V parts: stay <= 24 V)",
    "stall_error": "PUB example 'e.g. >180 degrees within 300 ms' (facts 3, MKS-man §5.4): pi rad",
    "stall_time": "PUB example 'e.g. >180 degrees within 300 ms' (facts 3, MKS-man §5.4): 0.3 s",
    "back_emf_constant": "EST Ke ~ Kt (facts 3 'important physics', facts 4 torque-speed roll-off)",
}

SERVO42D = MksProfile(
    model="SERVO42D",
    motor="17HS19-2004S1",
    full_steps=200,
    encoder_counts=16384,
    limit_inputs=1,
    bus_voltage=24.0,
    max_working_current=3.0,
    default_working_current=1.6,
    default_home_current=0.8,
    rated_current=2.0,
    holding_torque=0.59,
    torque_constant=0.295,
    back_emf_constant=0.295,
    phase_resistance=1.4,
    phase_inductance=3.0e-3,
    rotor_inertia=8.2e-6,
    coulomb_friction=0.02,
    viscous_friction=1e-4,
    motor_mass=0.39,
    stall_error=math.pi,
    stall_time=0.3,
    sources={
        **_COMMON_SOURCES,
        "model": "PUB MKS SERVO42D (NEMA17), RS485 manual V1.0.5",
        "motor": "EST assumed motor: MKS does not specify the bundled motor (facts 3); 17HS19-2004S1 is the "
                 "facts' 42D simulation default (facts 4)",
        "limit_inputs": "PUB IN_1 only on the 42D (manual 2.5; remap adds a right limit on En, 5.3 #5)",
        "max_working_current": "PUB 0-3000 mA (manual 3 #3, 5.2 #3; facts 3)",
        "default_working_current": "PUB default 1600 mA (manual 3 #3; facts 3)",
        "default_home_current": "PUB Hm_Ma default 800 mA (manual 3 #23)",
        "rated_current": "PUB 2.0 A, 17HS19-2004S1 datasheet (facts 3)",
        "holding_torque": "PUB 0.59 N*m, 17HS19-2004S1 datasheet (facts 3)",
        "torque_constant": "EST 0.59 N*m / 2.0 A = 0.295 (facts 4); ~0.47 N*m at the default 1.6 A",
        "phase_resistance": "PUB 1.4 ohm, 17HS19-2004S1 datasheet (facts 3)",
        "phase_inductance": "PUB 3.0 mH, 17HS19-2004S1 datasheet (facts 3)",
        "rotor_inertia": "EST ~82 g*cm^2, typical catalogue value (facts 3, 4: 8.2e-6)",
        "coulomb_friction": "EST 0.02 N*m, detent + bearing (facts 4)",
        "viscous_friction": "EST 1e-4 N*m*s/rad (facts 4)",
        "motor_mass": "PUB 0.39 kg, 17HS19-2004S1 (facts 3)",
    },
)

SERVO57D = MksProfile(
    model="SERVO57D",
    motor="23HS45-4204S",
    full_steps=200,
    encoder_counts=16384,
    limit_inputs=2,
    bus_voltage=24.0,
    max_working_current=5.2,
    default_working_current=3.2,
    default_home_current=0.4,
    rated_current=4.2,
    holding_torque=3.0,
    torque_constant=0.714,
    back_emf_constant=0.714,
    phase_resistance=0.9,
    phase_inductance=3.6e-3,
    rotor_inertia=6.8e-5,
    coulomb_friction=0.05,
    viscous_friction=5e-4,
    motor_mass=1.4,
    stall_error=math.pi,
    stall_time=0.3,
    sources={
        **_COMMON_SOURCES,
        "model": "PUB MKS SERVO57D (NEMA23), RS485 manual V1.0.5",
        "motor": "EST assumed motor: MKS does not specify the bundled motor (facts 3); 23HS45-4204S is the "
                 "facts' 57D simulation default (facts 4)",
        "limit_inputs": "PUB IN_1 (home/left) and IN_2 (right) on the 57D (manual 2.5)",
        "max_working_current": "PUB 0-5200 mA (manual 3 #3, 5.2 #3; facts 3)",
        "default_working_current": "PUB default 3200 mA (manual 3 #3; facts 3)",
        "default_home_current": "PUB Hm_Ma default 400 mA (manual 3 #23)",
        "rated_current": "PUB 4.2 A, 23HS45-4204S (facts 3)",
        "holding_torque": "PUB 3.0 N*m, 23HS45-4204S (facts 3); ~2.3 N*m at the default 3.2 A",
        "torque_constant": "EST 3.0 N*m / 4.2 A = 0.714 (facts 4: 0.71)",
        "back_emf_constant": _COMMON_SOURCES["back_emf_constant"] + "; gives ~321 rpm no-load at 24 V (facts 3: "
                             "~320 rpm), but facts 3 also quotes (EST) '45 % torque lost by 573 rpm' for a NEMA23: "
                             "uncertain by ~2x",
        "phase_resistance": "PUB 0.88-0.9 ohm (facts 3): 0.9",
        "phase_inductance": "PUB 3.4-3.8 mH (facts 3): midpoint 3.6 mH",
        "rotor_inertia": "EST ~680 g*cm^2 (facts 3, 4: 6.8e-5)",
        "coulomb_friction": "EST 0.05 N*m (facts 4)",
        "viscous_friction": "EST 5e-4 N*m*s/rad (facts 4)",
        "motor_mass": "EST ~1.4 kg (facts 3)",
    },
)

PROFILES: Mapping[str, MksProfile] = MappingProxyType({p.model: p for p in (SERVO42D, SERVO57D)})
DEFAULT_MODEL = "SERVO42D"

# "SERVO42D", "servo42d", "mks-servo42d", "MKS SERVO42D", "42D", "servo-57d"
_MODEL_RE = re.compile(r"^(?:mks[-_\s]?)?(?:servo[-_\s]?)?(42|57)\s*d$", re.IGNORECASE)


def profile(model: str) -> MksProfile:
    """The profile of ``model`` ("SERVO42D", "mks-servo57d", "42D", ... case-insensitive)."""
    match = _MODEL_RE.match(model.strip()) if isinstance(model, str) else None
    if match is None:
        raise ConfigError(f"unknown MKS model {model!r}; expected e.g. 'SERVO42D' or 'mks-servo57d'",
                          key="model", allowed=tuple(PROFILES))
    return PROFILES[f"SERVO{match.group(1)}D"]
