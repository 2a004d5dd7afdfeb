"""Physical profile of a ZLLG hub servo motor driven by one channel of a ZLAC8015D.

A profile holds what the host driver needs to turn register units into SI (torque constant,
encoder resolution, wheel radius, current and speed bounds) and what an emulator / MuJoCo world
needs for the motor model (torque constant, rotor inertia, friction, current and voltage limits).
All quantities are SI and at the **wheel** (the hub motor is direct drive: the wheel is the rotor,
gear ratio 1), unless the name says ``motor_``.

Where the numbers come from
    ``device-facts.md`` section 2 (ZLAC8015D + ZLLG hub motors) and the ZLAC8015D RS485 manual
    v1.04 (register defaults). ``sources`` maps every field to a text that starts with the facts
    file's kind: ``PUB`` (published), ``CFG`` (someone's working configuration / a register
    default), ``MEAS`` (third-party measurement), ``EST`` (estimate, reasoning given).
    No official ZLTECH datasheet was available: **confirm every number on the exact part**.

Two sets of currents (read this before changing a limit)
    * ``rated_current`` 15 A / ``max_current`` 30 A are the **driver's** defaults: registers
      0x2033/0x2063 (150 x 0.1 A) and 0x2034/0x2064 (300 x 0.1 A), manual lines 993-995 and
      1036-1038, also the S-s300 8-inch configuration. They are what the drive limits and
      protects with (current clamp, overload timer), so they set the emulator's power-on
      register image, :attr:`max_torque` (the MuJoCo actuator range) and the host's command
      bounds.
    * ``motor_rated_current`` 6 A / ``motor_max_current`` 11 A are the **motor's** ratings
      (S-zllg80v3 "v3 parameter", CFG). The driver defaults exceed them; a careful integrator
      writes 60/110 to 0x2033/0x2034. They are used only by the emulator's thermal model (the
      winding heats with (I / motor_rated_current)^2) and for reference.

Speeds
    ``max_speed`` is the driver's speed cap, register 0x2008 "Maximum motor speed" default
    1000 r/min (manual line 813). ``no_load_speed`` is the motor's own no-load speed at
    ``rated_voltage`` (262 r/min at 24 V, S-zllg80mon): with ``bus_voltage`` = 24 V the motor
    cannot go faster whatever 0x2008 says (the emulator's back-EMF limit).

Estimates (EST) and how they were made
    * ``rotor_inertia``: the 8-inch hub motor weighs about 4.1 kg (facts, user report); the
      rotating part (outer rotor with magnets, rim, tyre) is taken as 2.6 kg, the stator, shaft
      and windings (1.5 kg) stand still. Radius of gyration 0.07 m (a uniform disc of the wheel
      radius 0.1016 m has 0.072 m; the mass sits at the rim, the hub is light, the magnets sit
      at about 0.075 m) -> 2.6 * 0.07**2 = 0.0127 kg*m^2.
    * ``load_inertia``: the vehicle's inertia seen at one wheel in straight driving, which the
      drive's default velocity-loop gains are assumed to be tuned for: half of a 25 kg base at
      the wheel radius, 12.5 * 0.1016**2 = 0.129 kg*m^2.
    * Friction: at the maximum-efficiency point (80.7 % at 1.77 N*m, S-zllg80mon, at roughly
      240 r/min = 25 rad/s near the 24 V no-load speed) the output is ~44 W and the losses are
      ~10.6 W; copper loss at 2.2 A with ``phase_resistance`` is ~2-4 W, leaving ~7 W of
      mechanical and iron loss = 0.28 N*m at 25 rad/s. Split as ``coulomb_friction`` 0.2 N*m
      (bearings, seals, cogging) + ``viscous_friction`` 0.08 N*m / 25 rad/s = 0.003
      N*m*s/rad (iron loss grows with speed). Uncertain by ~2x; tyre rolling resistance is
      not included (that is the contact model's business).
    * ``phase_resistance`` 0.3 ohm: the 6.5-inch -L/-4096 variants measure 0.255-0.32 ohm
      (S-bear); no value for the 8-inch motor.

Overrides
    Every field except ``sources`` can be overridden from configuration through
    :meth:`HubMotorProfile.with_overrides` (validated: unknown key or bad value ->
    :class:`~joints.errors.ConfigError`; overridden fields are marked ``CFG`` in ``sources``).
    Derived values (:attr:`armature`, :attr:`max_torque`, ...) follow automatically.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from types import MappingProxyType

from joints.devices.profile import validate_fields, with_overrides
from joints.errors import ConfigError

__all__ = ["DEFAULT_MODEL", "PROFILES", "HubMotorProfile", "profile"]

_RPM = 2.0 * math.pi / 60.0  #: rad/s per r/min

#: Register limits of the ZLAC8015D the profile must fit in (0x2033/0x2034 in 0.1 A, 0x2008 r/min).
DRIVER_MAX_RATED_CURRENT = 15.0
DRIVER_MAX_CURRENT = 30.0
DRIVER_MAX_SPEED = 1000 * _RPM


# bus timing (issue 29): the drive's reply turnaround; the manual states none
#: s, EST: the ZLAC8015D log's 1.8 ms per Modbus transaction less a USB adapter's 1 ms (docs/timing.md)
TURNAROUND = 0.0008


def _sources() -> Mapping[str, str]:
    return MappingProxyType(dict(_SOURCES))


@dataclass(frozen=True, slots=True)
class HubMotorProfile:
    """One ZLLG hub motor on a ZLAC8015D channel (SI units at the wheel; see the module docstring)."""

    model: str = "ZLLG80ASM250"
    torque_constant: float = 0.8  #: N*m/A at the wheel (direct drive)
    rated_current: float = 15.0  #: A, driver rated current (0x2033 default)
    max_current: float = 30.0  #: A, driver maximum current (0x2034 default)
    motor_rated_current: float = 6.0  #: A, the motor's continuous rating (thermal model)
    motor_max_current: float = 11.0  #: A, the motor's maximum rating (reference)
    motor_peak_torque: float = 19.15  #: N*m, test-sheet peak at 23.08 A (reference)
    max_speed: float = 1000 * _RPM  #: rad/s, driver speed cap (0x2008 default 1000 r/min)
    no_load_speed: float = 262 * _RPM  #: rad/s, the motor's no-load speed at rated_voltage
    rated_voltage: float = 24.0  #: V, the motor winding's rated voltage
    bus_voltage: float = 24.0  #: V, the supply the emulated drive runs from (0x20A1)
    phase_resistance: float = 0.3  #: ohm (EST), for the back-EMF current limit
    pole_pairs: int = 15  #: 0x2045/0x2075 default
    encoder_lines: int = 1024  #: 0x2030/0x2060 default; counts/rev = 4 x lines
    wheel_radius: float = 0.1016  #: m (8-inch hub)
    rotor_inertia: float = 0.0127  #: kg*m^2 (EST), the rotating part of the hub motor
    load_inertia: float = 0.129  #: kg*m^2 (EST), vehicle inertia per wheel the gains assume
    coulomb_friction: float = 0.2  #: N*m (EST)
    viscous_friction: float = 0.003  #: N*m*s/rad (EST)
    #: s from a request's end (after t3.5) to the drive answering it (docs/timing.md)
    turnaround: float = TURNAROUND
    # -- sensors as the drive reports them (joints.sim.sensors; sources: _SENSOR_SOURCES) --
    velocity_window: float = 0.05  #: s, the velocity estimate: encoder counts over this window
    velocity_noise: float = 0.0  #: rad/s, std of noise beyond the quantisation
    position_noise: float = 0.0  #: rad, std beyond the encoder's counts
    current_noise: float = 0.05  #: A, std of the measured current
    current_resolution: float = 0.0  #: A, step of the current measurement (0: the register's 0.1 A)
    sample_jitter: float = 0.001  #: s, age of a status value: uniform in [0, this]
    sources: Mapping[str, str] = field(default_factory=_sources, compare=False, hash=False)

    def __post_init__(self) -> None:
        validate_fields(self, _INT_FIELDS, _FLOAT_FIELDS + _TIMING_FIELDS, _NON_NEGATIVE_FIELDS + _TIMING_FIELDS)
        if self.encoder_lines > 4096:
            raise ConfigError(
                f"{self.model}: encoder_lines {self.encoder_lines} exceeds register 0x2030's range 0-4096",
                key="encoder_lines",
            )
        if self.rated_current > DRIVER_MAX_RATED_CURRENT:
            raise ConfigError(
                f"{self.model}: rated_current {self.rated_current} A exceeds the driver's "
                f"{DRIVER_MAX_RATED_CURRENT} A (register 0x2033 range 0-150 x 0.1 A)",
                key="rated_current",
            )
        if self.max_current > DRIVER_MAX_CURRENT:
            raise ConfigError(
                f"{self.model}: max_current {self.max_current} A exceeds the driver's "
                f"{DRIVER_MAX_CURRENT} A (register 0x2034 range 0-300 x 0.1 A)",
                key="max_current",
            )
        if self.max_current < self.rated_current:
            raise ConfigError(
                f"{self.model}: max_current {self.max_current} A is below rated_current "
                f"{self.rated_current} A",
                key="max_current",
            )
        if self.max_speed > DRIVER_MAX_SPEED * (1 + 1e-9):
            raise ConfigError(
                f"{self.model}: max_speed {self.max_speed:.3f} rad/s exceeds the driver's 1000 r/min "
                "(register 0x2008 range 1-1000)",
                key="max_speed",
            )
        if self.max_speed < _RPM * (1 - 1e-9):
            raise ConfigError(f"{self.model}: max_speed below 1 r/min (0x2008 range 1-1000)", key="max_speed")
        object.__setattr__(self, "sources", MappingProxyType(dict(self.sources)))

    # --- derived quantities ----------------------------------------------------------------

    @property
    def counts_per_rev(self) -> int:
        """Encoder counts per wheel turn: lines x 4 (quadrature)."""
        return 4 * self.encoder_lines

    @property
    def armature(self) -> float:
        """Inertia reflected at the wheel joint [kg*m^2]: direct drive, so the rotor inertia.

        The MJCF wheel body must not carry the rotor's inertia about the axle a second time
        (``models/zlac_diffdrive.xml`` gives its wheels a near-zero axial inertia for this reason).
        """
        return self.rotor_inertia

    @property
    def tuning_inertia(self) -> float:
        """Inertia the drive's default velocity-loop gains assume at one wheel: rotor + vehicle share.

        (The emulator uses the wheel's own joint inertia + ``load_inertia``; with the default rotor
        that is this value.)
        """
        return self.rotor_inertia + self.load_inertia

    @property
    def max_torque(self) -> float:
        """Largest wheel torque the drive can command [N*m]: ``max_current * torque_constant``."""
        return self.max_current * self.torque_constant

    @property
    def rated_torque(self) -> float:
        """Torque at the driver's rated current [N*m] (the overload threshold)."""
        return self.rated_current * self.torque_constant

    @property
    def motor_rated_torque(self) -> float:
        """Torque at the motor's continuous rating [N*m] (about 4.8 N*m)."""
        return self.motor_rated_current * self.torque_constant

    @property
    def back_emf_constant(self) -> float:
        """Back-EMF per wheel speed [V*s/rad]: ``rated_voltage / no_load_speed``."""
        return self.rated_voltage / self.no_load_speed

    @property
    def max_speed_rpm(self) -> float:
        """``max_speed`` in r/min (the value of register 0x2008)."""
        return self.max_speed / _RPM

    def torque_from_current(self, amps: float) -> float:
        """Wheel torque [N*m] for a motor current [A] (linear, no friction)."""
        return amps * self.torque_constant

    def current_from_torque(self, nm: float) -> float:
        """Motor current [A] for a wheel torque [N*m]."""
        return nm / self.torque_constant

    def wheel_speed(self, rpm: float) -> float:
        """Ground speed [m/s] of a wheel turning at ``rpm`` r/min without slip."""
        return rpm * _RPM * self.wheel_radius

    # --- configuration ---------------------------------------------------------------------

    def with_overrides(self, **kw: object) -> HubMotorProfile:
        """A copy with some fields replaced (config ``profile = {...}``), validated.

        Raises :class:`ConfigError` for an unknown key (the message lists the allowed keys) and
        for a value that is not a positive finite number (friction may be 0) or does not fit the
        driver's registers.
        """
        return with_overrides(self, _OVERRIDABLE, kw)


_INT_FIELDS = ("pole_pairs", "encoder_lines")
_FLOAT_FIELDS = (
    "torque_constant",
    "rated_current",
    "max_current",
    "motor_rated_current",
    "motor_max_current",
    "motor_peak_torque",
    "max_speed",
    "no_load_speed",
    "rated_voltage",
    "bus_voltage",
    "phase_resistance",
    "wheel_radius",
    "rotor_inertia",
    "load_inertia",
    "coulomb_friction",
    "viscous_friction",
)
# Friction and the assumed vehicle share may be 0 (ideal simulation / a wheel in the air).
_NON_NEGATIVE_FIELDS = ("coulomb_friction", "viscous_friction", "load_inertia")
# the sensor models (joints.sim.sensors): 0 switches a term off
_SENSOR_FIELDS = ("velocity_window", "velocity_noise", "position_noise", "current_noise", "current_resolution",
                  "sample_jitter")
_FLOAT_FIELDS: tuple[str, ...] = (*_FLOAT_FIELDS, *_SENSOR_FIELDS)  # type: ignore[no-redef]
_NON_NEGATIVE_FIELDS: tuple[str, ...] = (*_NON_NEGATIVE_FIELDS, *_SENSOR_FIELDS)  # type: ignore[no-redef]
_SENSOR_SOURCES = {
    "velocity_window": ("EST: the manual states no speed estimator; a 4096-count encoder differentiated at 1 kHz "
                        "steps by 1.5 rad/s, and the register reports 0.1 r/min, so the drive must average: a 50 ms "
                        "window assumed (steps of 0.03 rad/s = 0.29 r/min). Uncertain by ~3x"),
    "velocity_noise": "EST: 0 - the estimate's noise is its quantisation (velocity_window)",
    "position_noise": "EST: 0 - the encoder's quantisation is the register's",
    "current_noise": "EST: 50 mA std on a 30 A-range current measurement; not published. Uncertain by ~3x",
    "current_resolution": "EST: 0 - the register's 0.1 A unit is coarser than the measurement",
    "sample_jitter": ("EST: status values refreshed every 1 ms, so a read returns a value up to 1 ms old; "
                      "not published"),
}
_TIMING_FIELDS = ("turnaround",)  # bus timing (issue 29): finite, >= 0

_SOURCES: dict[str, str] = {
    "model": "PUB ZLLG80ASM250 8-inch hub servo motor (facts 2.2)",
    "torque_constant": "PUB 0.8 N*m/A (S-zllg80mon 'datasheet', facts 2.2); direct drive",
    "rated_current": (
        "CFG driver default: 0x2033/0x2063 = 150 x 0.1 A (manual lines 993/1036; S-s300). "
        "Used for the overload timer and the register image; the motor's own rating is 6 A"
    ),
    "max_current": (
        "CFG driver default: 0x2034/0x2064 = 300 x 0.1 A (manual lines 995/1038; S-s300). "
        "Current clamp and max_torque; the motor's own maximum is 11 A"
    ),
    "motor_rated_current": "CFG 6 A, S-zllg80v3 'v3 parameter' (facts 2.2); thermal model only",
    "motor_max_current": "CFG 11 A, S-zllg80v3 'v3 parameter' (facts 2.2); reference only",
    "motor_peak_torque": "PUB? 19.15 N*m @ 23.08 A, S-zllg80mon test-sheet figure (facts 2.2)",
    "max_speed": "CFG driver default: 0x2008 = 1000 r/min (manual line 813)",
    "no_load_speed": "PUB 262 r/min no-load @ 24 V, S-zllg80mon (facts 2.2)",
    "rated_voltage": "CFG/PUB? 24 V, the '-L-24V' part (S-zllg80mon, facts 2.2)",
    "bus_voltage": "CFG 24 V: 24 V LiFePO4 systems are typical (facts 2.1)",
    "phase_resistance": "EST 0.3 ohm: 6.5-inch -L/-4096 variants measure 0.255-0.32 ohm (S-bear)",
    "pole_pairs": "CFG 15 (S-s300 8-inch config; register 0x2045 default 15, manual line 1019)",
    "encoder_lines": (
        "CFG 1024 lines (0x2030 default, manual line 988; rasheeddo ODT, S-s300) -> 4096 counts/rev; "
        "some 8-inch sets read 16384 counts/rev (a 4096-line variant): read 0x2030 on the unit"
    ),
    "wheel_radius": (
        "CFG 0.1016 m = 8 inch / 2 (nominal hub size); facts: 200 mm nominal diameter, 196 mm "
        "loaded, 208.5 mm per rasheeddo"
    ),
    "rotor_inertia": "EST 2.6 kg rotating mass x (0.07 m radius of gyration)^2 (module docstring)",
    "load_inertia": "EST half of a 25 kg base at the wheel radius: 12.5 * 0.1016^2",
    "coulomb_friction": "EST 0.2 N*m from the 80.7 % max-efficiency point (module docstring)",
    "viscous_friction": "EST 0.003 N*m*s/rad from the 80.7 % max-efficiency point (module docstring)",
    **_SENSOR_SOURCES,
}
_SOURCES["turnaround"] = ("EST 0.8 ms: a real ZLAC8015D at 115200 baud (augustocamaral2003/zlac8015d-tests, "
                          "scripts/data.csv) takes 1.8 ms per transaction beyond bytes and t3.5; less 1 ms of USB "
                          "adapter latency (docs/timing.md)")

_OVERRIDABLE: tuple[str, ...] = tuple(f.name for f in fields(HubMotorProfile) if f.name != "sources")

DEFAULT_MODEL = "ZLLG80ASM250"

PROFILES: Mapping[str, HubMotorProfile] = MappingProxyType({DEFAULT_MODEL: HubMotorProfile()})


def profile(model: str = DEFAULT_MODEL) -> HubMotorProfile:
    """The profile of ``model`` (case-insensitive); :class:`ConfigError` lists the known models."""
    key = model.strip().upper() if isinstance(model, str) else ""
    for name, prof in PROFILES.items():
        if name.upper() == key:
            return prof
    raise ConfigError(f"unknown hub motor model {model!r}", key="model", allowed=tuple(PROFILES))
