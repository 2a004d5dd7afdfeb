"""Physical device profiles of the ZeroErr eRob rotary actuators, one per size x gear ratio.

A profile holds the numbers the host driver needs to turn motor current [A] into output torque
[N*m] and to bound commands (torque tiers, speed cap, currents), and the numbers an emulator needs
for a motor + gear model (torque constant, reflected rotor inertia, friction). Every quantity is
in SI units and on the **output** side unless its name says ``motor``/``rotor``.

Where the numbers come from
    The single source of truth is ``device-facts.md`` section 1 (compiled from secondary copies of
    the ZeroErr manual V3.39/V3.42 and from third-party measurements). Each profile carries a
    ``sources`` mapping, field name -> text, whose text starts with the facts file's kind:

    * ``PUB``  - a published vendor value (quoted through the named secondary source),
    * ``MEAS`` - measured/identified on real hardware by a third party,
    * ``CFG``  - a value from someone's working driver/config code (plausible, not a datasheet),
    * ``EST``  - an estimate; the text gives the reasoning.

    Many values are **estimates** (see ``sources``): all peak currents, the efficiency (MEAS only
    for eRob80H50), the motor torque constant of the 90/110/142 sizes, the rated current of the
    70, the 90H80/90H120 ratings, and most friction values. Treat friction as uncertain by ~3x.
    The 70 and 90 rotor inertias and the 90 rated current are CFG values.

Conventions
    * ``gear_ratio`` is the nominal N of the model name. The strain-wave gear makes the motor turn
      N+1 times per output turn (:attr:`ErobProfile.kinematic_ratio`); :attr:`ErobProfile.armature`
      uses N+1, the torque constant uses N (as the manual's ``T = Kt_m * N * eta`` does).
    * ``rated_current`` is the motor's continuous (thermal) current. The output torque tiers are
      limited by the gear, so ``rated_current * torque_constant`` need not equal ``rated_torque``.
    * ``peak_current`` is the current that gives ``peak_torque`` (no published value could be
      read; it is ``peak_torque / torque_constant``). Use it as the command current bound.
    * ``peak_torque`` is the repeated start/stop peak (the force limit for control);
      ``max_torque`` is the momentary maximum, for collision/gear-damage checks only.
    * Friction model: ``tau_f = coulomb_friction * sign(w) + viscous_friction * w`` at the output,
      plus (0 unless identified) ``(stribeck_friction * exp(-|w / stribeck_velocity|^stribeck_exponent) + load_friction
      * |tau_m| + load_friction_quadratic * tau_m^2 + external_friction * |tau_e|) * sign(w)``: Stribeck friction
      and friction growing with the motor's torque tau_m and the external (gravity) torque tau_e (BAM's M6 form).
    * ``command_delay`` is the time from a motion command's arrival at the drive to the drive
      acting on it (the twin reproduces it: :attr:`joints.sim.firmware.Firmware.command_delay`);
      0 unless identified (``joints identify`` writes it into a profile overlay).

Friction where nothing was measured (EST)
    Measured anchors: eRob70H100 (ZeroErr's own no-load current table, ZE-fric, converted with
    Kt_m*N = 13.2 N*m/A: 2.1 N*m, 0.6 N*m*s/rad), eRob80H50 (BAM M1: 4.10 N*m, 1.30 N*m*s/rad) and
    eRob80H100 (BAM M2: static 5.46 N*m, 9.57 N*m*s/rad). The other variants use the facts file's
    rule of thumb, with the constants chosen as follows:

    * ``coulomb_friction = 0.16 * rated_torque``. The anchors give 0.21 (70H100), 0.195 (80H50),
      0.176 (80H100, static) of the rated torque, falling with size; facts section 4 says
      0.15-0.2, so the lower part of that range is used for the larger sizes.
    * ``viscous_friction = rated_torque * N * 1e-3 s``. The anchors give 0.60x, 1.24x and 3.09x
      this value (geometric mean 1.3x); the facts file uses the factor 1.

Overrides
    Every field except ``sources`` can be overridden from configuration: the keys of the joint's
    ``profile = {...}`` table are field names and go to :meth:`ErobProfile.with_overrides`, which
    validates names and values (unknown key or non-positive value -> :class:`ConfigError`) and
    marks the overridden fields ``CFG`` in ``sources``. Derived values (e.g. ``peak_current``)
    are not recomputed; override them too when changing ``motor_kt`` or ``efficiency``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from types import MappingProxyType

from joints.devices.profile import validate_fields, with_overrides
from joints.errors import ConfigError

__all__ = ["DEFAULT_MODEL", "PROFILES", "ErobProfile", "profile"]


def _empty_sources() -> Mapping[str, str]:
    return MappingProxyType({})


_INT_FIELDS = ("size", "gear_ratio")
_FLOAT_FIELDS = (
    "rated_torque",
    "peak_torque",
    "max_torque",
    "max_speed",
    "motor_kt",
    "efficiency",
    "rated_current",
    "peak_current",
    "rotor_inertia",
    "coulomb_friction",
    "viscous_friction",
    "command_delay",
)
# Friction may be switched off (0) for an ideal simulation, the delay is 0 unless identified;
# everything else must be > 0.
_NON_NEGATIVE_FIELDS = ("coulomb_friction", "viscous_friction", "command_delay")
# the sensor models (joints.sim.sensors): 0 switches a term off
_SENSOR_FIELDS = ("velocity_window", "velocity_noise", "position_noise", "current_noise", "current_resolution",
                  "sample_jitter")
# state-dependent friction (issue 30; joints identify writes them): 0 = none, today's Coulomb + viscous twin
_FRICTION_FIELDS = ("stribeck_friction", "load_friction", "load_friction_quadratic", "external_friction")
_FLOAT_FIELDS: tuple[str, ...] = (*_FLOAT_FIELDS, *_SENSOR_FIELDS, *_FRICTION_FIELDS,  # type: ignore[no-redef]
                                  "stribeck_velocity", "stribeck_exponent")
_NON_NEGATIVE_FIELDS: tuple[str, ...] = (*_NON_NEGATIVE_FIELDS, *_SENSOR_FIELDS,  # type: ignore[no-redef]
                                         *_FRICTION_FIELDS)
_SENSOR_SOURCES = {
    "velocity_window": ("EST: ZeroErr publishes no speed estimator; the status speed is taken as the 19-bit output "
                        "encoder's difference over one 1 kHz speed-loop period: steps of 0.012 rad/s, quantisation "
                        "noise ~0.0049 rad/s when moving, 0 at rest. Uncertain by ~3x"),
    "velocity_noise": "EST: 0 - the estimate's noise is its quantisation (velocity_window)",
    "position_noise": "EST: 0 - an absolute encoder; the 19-bit quantisation is the register's",
    "current_noise": ("EST: 20 mA std, a 12-bit phase-current ADC over a ~+-40 A range (1 LSB = 20 mA) with "
                      "PWM ripple; not published. Uncertain by ~3x"),
    "current_resolution": "EST: 10 mA measurement step (the register's unit is 1 mA); not published",
    "sample_jitter": ("EST: 0 - the firmware latches its status in its fast loop (well under 0.1 ms) when a "
                      "request is served; the host's own timing jitter is the bus's (wire time, issue 29)"),
}

# bus timing (issue 29): the drive's reply turnaround; no eRob manual states one
#: s, EST: the ZLAC8015D log's 1.8 ms per Modbus transaction less a USB adapter's 1 ms (docs/timing.md)
TURNAROUND = 0.0008
TURNAROUND_SOURCE = ("EST: 0.8 ms - no eRob manual states a reply turnaround; a real ZLAC8015D log shows 1.8 ms "
                     "per transaction beyond bytes and t3.5, less 1 ms of USB adapter latency (docs/timing.md)")
_TIMING_FIELDS = ("turnaround",)  # bus timing (issue 29): finite, >= 0
_FRICTION_SOURCES = {
    "stribeck_friction": "EST: 0 - not modelled unless identified (`joints identify`, profile overlay)",
    "stribeck_velocity": "EST: 1 rad/s placeholder, used only when stribeck_friction > 0 (`joints identify`)",
    "stribeck_exponent": "EST: 2 (Gaussian Stribeck curve), used only when stribeck_friction > 0 (`joints identify`)",
    "load_friction": "EST: 0 - not modelled unless identified (`joints identify`, profile overlay)",
    "load_friction_quadratic": "EST: 0 - not modelled unless identified (`joints identify`, profile overlay)",
    "external_friction": "EST: 0 - not modelled unless identified (`joints identify`, profile overlay)",
}


@dataclass(frozen=True, slots=True)
class ErobProfile:
    """Physical profile of one eRob variant (output side, SI units). See the module docstring."""

    model: str  #: e.g. ``"eRob80H100"`` (size + "H" + nominal ratio)
    size: int  #: frame size: 70, 80, 90, 110, 142
    gear_ratio: int  #: nominal N (50, 80, 100, 120, 160); the motor turns N+1 per output turn
    rated_torque: float  #: N*m, continuous
    peak_torque: float  #: N*m, repeated start/stop peak
    max_torque: float  #: N*m, max momentary (collision only)
    max_speed: float  #: rad/s, firmware speed cap
    motor_kt: float  #: N*m/A (rms), motor side
    efficiency: float  #: eta_t in T_out = Kt_m * N * eta_t * I (published range 0.5-0.7)
    rated_current: float  #: A, motor continuous current
    peak_current: float  #: A, current giving peak_torque
    rotor_inertia: float  #: kg*m^2, motor side (J_in), no brake
    coulomb_friction: float  #: N*m at the output
    viscous_friction: float  #: N*m*s/rad at the output
    #: s from a motion command's arrival to the drive acting on it (the twin's; ``joints identify``)
    command_delay: float = 0.0
    #: s from a request's end (after the protocol's silence) to the drive answering it (docs/timing.md)
    turnaround: float = TURNAROUND
    # -- sensors as the drive reports them (joints.sim.sensors; sources: _SENSOR_SOURCES) --
    velocity_window: float = 0.001  #: s, the speed estimate: encoder counts over this window
    velocity_noise: float = 0.0  #: rad/s, std of noise beyond the quantisation
    position_noise: float = 0.0  #: rad, std beyond the encoder's counts
    current_noise: float = 0.02  #: A, std of the measured current
    current_resolution: float = 0.01  #: A, step of the current measurement
    sample_jitter: float = 0.0  #: s, age of a status value: uniform in [0, this]
    # -- friction beyond Coulomb + viscous (the twin: joints.sim.world; 0 = none) --
    #: N*m of friction at standstill above coulomb_friction, fading as exp(-|w / stribeck_velocity|^stribeck_exponent)
    stribeck_friction: float = 0.0
    stribeck_velocity: float = 1.0  #: rad/s (used only when stribeck_friction > 0)
    stribeck_exponent: float = 2.0  #: (used only when stribeck_friction > 0)
    load_friction: float = 0.0  #: N*m of friction per N*m of torque the motor transmits
    load_friction_quadratic: float = 0.0  #: N*m of friction per (N*m of motor torque)^2
    external_friction: float = 0.0  #: N*m of friction per N*m of external torque (gravity) on the output
    sources: Mapping[str, str] = field(default_factory=_empty_sources, compare=False, hash=False)

    def __post_init__(self) -> None:
        validate_fields(self, _INT_FIELDS, _FLOAT_FIELDS + _TIMING_FIELDS, _NON_NEGATIVE_FIELDS + _TIMING_FIELDS)
        if self.efficiency > 1.0:
            raise ConfigError(
                f"{self.model}: efficiency must be in (0, 1], got {self.efficiency!r}",
                key="efficiency",
            )
        if self.peak_torque < self.rated_torque:
            raise ConfigError(
                f"{self.model}: peak_torque {self.peak_torque} N*m is below "
                f"rated_torque {self.rated_torque} N*m",
                key="peak_torque",
            )
        if self.max_torque < self.peak_torque:
            raise ConfigError(
                f"{self.model}: max_torque {self.max_torque} N*m is below "
                f"peak_torque {self.peak_torque} N*m",
                key="max_torque",
            )
        object.__setattr__(self, "sources", MappingProxyType(dict(self.sources)))

    # --- derived quantities ----------------------------------------------------------------

    @property
    def kinematic_ratio(self) -> int:
        """Motor turns per output turn: N + 1 for the eRob strain-wave gear."""
        return self.gear_ratio + 1

    @property
    def torque_constant(self) -> float:
        """Output torque per motor current [N*m/A]: ``motor_kt * gear_ratio * efficiency``."""
        return self.motor_kt * self.gear_ratio * self.efficiency

    @property
    def armature(self) -> float:
        """Rotor inertia reflected to the output [kg*m^2]: ``rotor_inertia * kinematic_ratio**2``.

        The eRob strain-wave gear turns the motor N+1 times per output turn, so N+1 is used.
        """
        return self.rotor_inertia * self.kinematic_ratio**2

    def torque_from_current(self, amps: float) -> float:
        """Output torque [N*m] for a motor current [A] (linear model, no friction)."""
        return amps * self.torque_constant

    def current_from_torque(self, nm: float) -> float:
        """Motor current [A] for an output torque [N*m] (inverse of :meth:`torque_from_current`)."""
        return nm / self.torque_constant

    # --- configuration ---------------------------------------------------------------------

    def with_overrides(self, **kw: object) -> ErobProfile:
        """A copy with some fields replaced (config ``profile = {...}``), validated.

        Raises :class:`ConfigError` for an unknown key (the message lists the allowed keys) and
        for a value that is not a positive finite number (friction may be 0).
        """
        return with_overrides(self, _OVERRIDABLE, kw)


_OVERRIDABLE: tuple[str, ...] = tuple(f.name for f in fields(ErobProfile) if f.name != "sources")


# --- data (device-facts.md section 1) -------------------------------------------------------

_RPM = 2.0 * math.pi / 60.0  # rad/s per rpm

_ETA_DEFAULT = 0.65
_ETA_DEFAULT_SRC = (
    "EST: middle of the PUB eta_t range 0.5-0.7 (S-erobo10 §9, S-research); "
    "S-prime-doc MEAS ~0.7; S-erobhpp output Kt values imply 0.6"
)

# size -> (motor_kt, source), (rated_current, source), (rotor_inertia, source)
_SIZE_DATA: dict[int, tuple[tuple[float, str], tuple[float, str], tuple[float, str]]] = {
    70: (
        (0.132, "PUB S-prime-doc (manual §25.2, V4_MC2)"),
        (
            2.4,
            (
                "EST: 100 W / (3000 rpm = 314 rad/s * 0.132 N*m/A) = 2.4 A; S-moveit CFG 3.5 A for "
                "70H100T not used (S-moveit's 80H100T 5.5 A is 1.6x the PUB 3.4 A)"
            ),
        ),
        (2.27e-5, "CFG S-gearsonic armature 0.22674 / 100^2 (S-mjlab V5 CFG: 2.61e-5)"),
    ),
    80: (
        (0.134, "PUB S-prime-doc (manual §25.2, V5_MC2)"),
        (
            3.4,
            (
                "PUB manual Table 3-1 via S-erobo10 (module 4.1 A per S-research; CFG 5.5 A "
                "S-moveit 80H100T, 6.3 A S-80H120)"
            ),
        ),
        (6.74e-5, "PUB S-erobo10 (no brake; 7.06e-5 with brake; S-mjlab V6 CFG 4.50e-5)"),
    ),
    90: (
        (0.14, "EST: S-erobhpp output Kt 8.40 N*m/A / (100 * 0.6)"),
        (6.7, "CFG S-erobhpp (consistent with 293-314 W at 3000 rpm)"),
        (9.58e-5, "CFG S-gearsonic armature 0.95791 / 100^2"),
    ),
    110: (
        (
            0.128,
            (
                "EST: midpoint of 723 W / (314 rad/s * 18.9 A) = 0.122 and "
                "S-erobhpp 8.04 / (100 * 0.6) = 0.134"
            ),
        ),
        (18.6, "PUB manual Table 3-1 via S-erobo10 (Table 25-1: 18.9 A)"),
        (3.086e-4, "PUB S-erobo10, S-gearsonic agrees (no brake; 3.166e-4 with brake)"),
    ),
    142: (
        (0.153, "EST: S-research, same 1000 W 10-pole motor as the 170i V3_MC1 (Kt 0.153)"),
        (26.0, "PUB S-research (142 V3_MC1)"),
        (1.245e-3, "PUB S-erobo10 (no brake; 1.273e-3 with brake)"),
    ),
}

_PUB_70 = "PUB S-review, S-research"
_PUB_80 = "PUB S-erobo10 Table 2-1/12-1, S-review (agree)"
_PUB_90 = "PUB S-review"
_EST_90 = (
    "EST from the CSG-20 catalogue pattern (HD-CSG confirms CSG-20-80 = 44 rated / "
    "165 momentary); speed = 3000 rpm / N"
)
_PUB_BIG = "PUB S-erobo10, S-review"

# (size, N) -> rated, peak (start/stop), max momentary [N*m], max output speed [rpm], source.
# Size/ratio combinations marked '-' or '?' in the facts are left out.
_RATINGS: dict[tuple[int, int], tuple[float, float, float, float, str]] = {
    (70, 50): (7, 23, 46, 60, _PUB_70),
    (70, 100): (10, 36, 70, 30, _PUB_70),
    (80, 50): (21, 44, 91, 60, _PUB_80),
    (80, 80): (29, 56, 113, 37.5, _PUB_80),
    (80, 100): (31, 70, 143, 30, _PUB_80),
    (80, 120): (31, 70, 112, 25, _PUB_80),
    (90, 50): (33, 73, 127, 60, _PUB_90),
    (90, 80): (44, 96, 165, 37.5, _EST_90),
    (90, 100): (52, 107, 191, 30, _PUB_90),
    (90, 120): (52, 113, 191, 25, _EST_90),
    (110, 50): (51, 127, 242, 60, _PUB_BIG),
    (110, 80): (82, 178, 332, 37.5, _PUB_BIG),
    (110, 100): (87, 204, 369, 30, _PUB_BIG),
    (110, 120): (87, 217, 395, 25, _PUB_BIG),
    (110, 160): (87, 229, 408, 18.75, _PUB_BIG),
    (142, 50): (99, 281, 497, 40, _PUB_BIG),
    (142, 80): (153, 395, 738, 25, _PUB_BIG),
    (142, 100): (178, 433, 841, 20, _PUB_BIG),
    (142, 120): (178, 459, 892, 16.7, _PUB_BIG),
    (142, 160): (178, 484, 892, 12.5, _PUB_BIG),
}

# Variants with a measured efficiency: (size, N) -> (eta, source)
_EFFICIENCY: dict[tuple[int, int], tuple[float, str]] = {
    (80, 50): (
        0.70,
        (
            "MEAS BAM: identified output kt 4.54 (M1) / 4.90 (M6) N*m/A over Kt_m*N = 6.7 "
            "-> 0.68 / 0.73, mean 0.70"
        ),
    ),
    (80, 100): (
        0.65,
        (
            "EST: PUB range 0.5-0.7; BAM MEAS 7.71 (M2) / 9.40 (M6) N*m/A over 13.4 "
            "-> 0.58 / 0.70, S-moveit CFG 8.475 -> 0.63"
        ),
    ),
}

_COULOMB_PER_RATED = 0.16  # coulomb_friction / rated_torque where nothing was measured
_VISCOUS_SECONDS = 1e-3  # viscous_friction / (rated_torque * N) [s] where nothing was measured

# Variants with measured friction anchors: (size, N) -> (coulomb, source), (viscous, source)
_FRICTION: dict[tuple[int, int], tuple[tuple[float, str], tuple[float, str]]] = {
    (70, 100): (
        (
            2.1,
            (
                "EST from MEAS ZE-fric (eRob70H100i no-load table): 160 mA at 0.72 rpm * Kt_m*N "
                "13.2 N*m/A (with eta*Kt it would be 1.4)"
            ),
        ),
        (
            0.6,
            "EST from MEAS ZE-fric: (316 - 207 mA) * 13.2 N*m/A / (26.1 - 2.9 rpm = 2.43 rad/s)",
        ),
    ),
    (80, 50): (
        (4.10, "MEAS BAM eRob80:50 M1 (Coulomb/static)"),
        (1.30, "MEAS BAM eRob80:50 M1"),
    ),
    (80, 100): (
        (
            4.5,
            (
                "EST: facts §4 value; BAM M2 is a Stribeck model, static 5.46 N*m decaying to a "
                "~0 base above v_s = 2.08 rad/s, so one Coulomb level below the static value"
            ),
        ),
        (9.57, "MEAS BAM eRob80:100 M2"),
    ),
}


def _build(size: int, ratio: int) -> ErobProfile:
    rated, peak, max_t, rpm, ratings_src = _RATINGS[(size, ratio)]
    (kt, kt_src), (i_rated, i_rated_src), (j_in, j_in_src) = _SIZE_DATA[size]
    eta, eta_src = _EFFICIENCY.get((size, ratio), (_ETA_DEFAULT, _ETA_DEFAULT_SRC))
    kt_out = kt * ratio * eta
    if (size, ratio) in _FRICTION:
        (coulomb, coulomb_src), (viscous, viscous_src) = _FRICTION[(size, ratio)]
    else:
        coulomb = round(_COULOMB_PER_RATED * rated, 4)
        coulomb_src = (
            f"EST: {_COULOMB_PER_RATED} * rated torque (rule anchored on ZE-fric 70H100 and "
            "BAM 80H50/80H100: 0.21/0.195/0.176 of rated; facts §4 range 0.15-0.2)"
        )
        viscous = round(_VISCOUS_SECONDS * rated * ratio, 4)
        viscous_src = (
            "EST: rated torque * N * 1e-3 s (facts §4 rule; anchors are 0.6x/1.24x/3.1x it)"
        )
    model = f"eRob{size}H{ratio}"
    sources = {
        "model": "PUB size x ratio grid, facts 1.2",
        "size": "PUB",
        "gear_ratio": "PUB nominal N; kinematic N+1 (S-80H120 MEAS 121 on 80H120, S-erobo10 §1)",
        "rated_torque": ratings_src,
        "peak_torque": ratings_src,
        "max_torque": ratings_src,
        "max_speed": f"{ratings_src}; {rpm} rpm at the output",
        "motor_kt": kt_src,
        "efficiency": eta_src,
        "rated_current": i_rated_src,
        "peak_current": (
            f"EST: peak torque / torque_constant = {peak} / {kt_out:.3f} "
            "(manual Table 25-1 not readable; BAM drove eRob80 with a 12 A limit)"
        ),
        "rotor_inertia": j_in_src,
        "coulomb_friction": coulomb_src,
        "viscous_friction": viscous_src,
        **_SENSOR_SOURCES,
        **_FRICTION_SOURCES,
        "command_delay": ("EST: 0 - the twin acts on a command at its next substep; a real drive's delay comes "
                          "from `joints identify` (profile overlay)"),
        "turnaround": TURNAROUND_SOURCE,
    }
    return ErobProfile(
        model=model,
        size=size,
        gear_ratio=ratio,
        rated_torque=float(rated),
        peak_torque=float(peak),
        max_torque=float(max_t),
        max_speed=rpm * _RPM,
        motor_kt=kt,
        efficiency=eta,
        rated_current=i_rated,
        peak_current=peak / kt_out,
        rotor_inertia=j_in,
        coulomb_friction=coulomb,
        viscous_friction=viscous,
        sources=sources,
    )


PROFILES: Mapping[str, ErobProfile] = MappingProxyType(
    {p.model: p for p in (_build(size, ratio) for size, ratio in _RATINGS)}
)

DEFAULT_MODEL = "eRob80H100"

# "eRob80H100", "erob80-100", "80H100", "eRob80:100", "eRob80H-100", "erob 80 h 100"
_MODEL_RE = re.compile(r"^(?:erob)?\s*(\d+)\s*(?:h\s*[-:_/]?|[-:_/\s])\s*(\d+)$", re.IGNORECASE)
#: a whole model string of eRunner 7.5.3, e.g. "eRob70H100I-BM-18EN" (the profile's ``model`` keeps it;
#: the reducer type F/H does not change the profile: the facts are of the harmonic "H" modules)
_FULL_MODEL_RE = re.compile(r"eRob(\d+)([FH])(\d+)(BI|BT|I|T)-([FB])(HS|HM|S|M)-18([EC])([NT])")


def profile(model: str) -> ErobProfile:
    """The profile of ``model``; accepts "eRob80H100", "erob80-100", "80H100", "eRob80:100", and a
    module's whole model string ("eRob70H100I-BM-18EN", eRunner 7.5.3: kept as the profile's ``model``).

    Matching is case-insensitive. Raises :class:`ConfigError` listing the available models if
    the name is not understood or the facts have no data for that size/ratio.
    """
    text = model.strip() if isinstance(model, str) else ""
    full = _FULL_MODEL_RE.fullmatch(text)
    if full is not None:  # a module's whole model string (eRunner 7.5.3): its size and ratio pick the profile
        found = PROFILES.get(f"eRob{full.group(1)}H{full.group(3)}")
        if found is None:
            raise ConfigError(f"no eRob profile for {model!r} (size {full.group(1)}, ratio {full.group(3)}): "
                              "the device facts have no torque/speed data for it", key="model",
                              allowed=tuple(PROFILES))
        return replace(found, model=text)
    match = _MODEL_RE.match(text)
    if match is None:
        raise ConfigError(
            f"unknown eRob model {model!r}; expected e.g. 'eRob80H100'",
            key="model",
            allowed=tuple(PROFILES),
        )
    size, ratio = int(match.group(1)), int(match.group(2))
    found = PROFILES.get(f"eRob{size}H{ratio}")
    if found is None:
        raise ConfigError(
            f"no eRob profile for {model!r} (size {size}, ratio {ratio}): "
            "the device facts have no torque/speed data for it",
            key="model",
            allowed=tuple(PROFILES),
        )
    return found
