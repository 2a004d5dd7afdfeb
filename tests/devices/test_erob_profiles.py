"""Tests of the eRob physical device profiles (joints.devices.erob.profiles)."""

from __future__ import annotations

import dataclasses
import math

import pytest

from joints.devices.erob.profiles import DEFAULT_MODEL, PROFILES, ErobProfile, profile
from joints.errors import ConfigError

RPM = 2 * math.pi / 60

PHYSICAL = (
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
)

# The full grid the facts file has torque/speed data for; '-' and '?' combos are absent.
EXPECTED_MODELS = {
    "eRob70H50", "eRob70H100",
    "eRob80H50", "eRob80H80", "eRob80H100", "eRob80H120",
    "eRob90H50", "eRob90H80", "eRob90H100", "eRob90H120",
    "eRob110H50", "eRob110H80", "eRob110H100", "eRob110H120", "eRob110H160",
    "eRob142H50", "eRob142H80", "eRob142H100", "eRob142H120", "eRob142H160",
}  # fmt: skip

# model -> rated, peak, max momentary [N*m], max speed [rpm]   (device-facts.md 1.2)
RATINGS = {
    "eRob70H50": (7, 23, 46, 60),
    "eRob70H100": (10, 36, 70, 30),
    "eRob80H50": (21, 44, 91, 60),
    "eRob80H80": (29, 56, 113, 37.5),
    "eRob80H100": (31, 70, 143, 30),
    "eRob80H120": (31, 70, 112, 25),
    "eRob90H50": (33, 73, 127, 60),
    "eRob90H80": (44, 96, 165, 37.5),
    "eRob90H100": (52, 107, 191, 30),
    "eRob90H120": (52, 113, 191, 25),
    "eRob110H50": (51, 127, 242, 60),
    "eRob110H80": (82, 178, 332, 37.5),
    "eRob110H100": (87, 204, 369, 30),
    "eRob110H120": (87, 217, 395, 25),
    "eRob110H160": (87, 229, 408, 18.75),
    "eRob142H50": (99, 281, 497, 40),
    "eRob142H80": (153, 395, 738, 25),
    "eRob142H100": (178, 433, 841, 20),
    "eRob142H120": (178, 459, 892, 16.7),
    "eRob142H160": (178, 484, 892, 12.5),
}

# size -> motor Kt [N*m/A], rated current [A], rotor inertia [kg*m^2]   (device-facts.md 1.3)
SIZE_DATA = {
    70: (0.132, 2.4, 2.27e-5),
    80: (0.134, 3.4, 6.74e-5),
    90: (0.14, 6.7, 9.58e-5),
    110: (0.128, 18.6, 3.086e-4),
    142: (0.153, 26.0, 1.245e-3),
}

# model -> Coulomb [N*m], viscous [N*m*s/rad]: measured anchors, everything else by the rule
FRICTION_ANCHORS = {
    "eRob70H100": (2.1, 0.6),
    "eRob80H50": (4.10, 1.30),
    "eRob80H100": (4.5, 9.57),
}

ALL = sorted(PROFILES)


# --- the table -------------------------------------------------------------------------------


def test_grid_is_exactly_the_facts_grid() -> None:
    assert set(PROFILES) == EXPECTED_MODELS
    for name in ("eRob70H80", "eRob70H120", "eRob70H160", "eRob80H160", "eRob90H160"):
        assert name not in PROFILES
    assert DEFAULT_MODEL == "eRob80H100"
    assert DEFAULT_MODEL in PROFILES


@pytest.mark.parametrize("name", ALL)
def test_profile_fields_positive_and_ordered(name: str) -> None:
    p = PROFILES[name]
    assert p.model == name == f"eRob{p.size}H{p.gear_ratio}"
    for field in PHYSICAL:
        value = getattr(p, field)
        assert isinstance(value, float), field
        assert math.isfinite(value) and value > 0, field
    assert p.rated_torque <= p.peak_torque <= p.max_torque
    assert 0.5 <= p.efficiency <= 0.7


@pytest.mark.parametrize("name", ALL)
def test_every_field_has_a_kind_labelled_source(name: str) -> None:
    p = PROFILES[name]
    for field in PHYSICAL:
        assert p.sources[field].split()[0].rstrip(":") in {"PUB", "MEAS", "CFG", "EST"}, field
    # things the facts say are unpublished are marked EST
    assert p.sources["peak_current"].startswith("EST")
    with pytest.raises(TypeError):
        p.sources["rated_torque"] = "x"  # type: ignore[index]


@pytest.mark.parametrize("name", ALL)
def test_ratings_match_facts(name: str) -> None:
    p = PROFILES[name]
    rated, peak, max_t, rpm = RATINGS[name]
    assert (p.rated_torque, p.peak_torque, p.max_torque) == (rated, peak, max_t)
    assert p.max_speed == pytest.approx(rpm * RPM, rel=1e-12)


@pytest.mark.parametrize("name", ALL)
def test_size_data_match_facts(name: str) -> None:
    p = PROFILES[name]
    kt, i_rated, j_in = SIZE_DATA[p.size]
    assert (p.motor_kt, p.rated_current, p.rotor_inertia) == (kt, i_rated, j_in)
    expected_eta = 0.70 if name == "eRob80H50" else 0.65
    assert p.efficiency == expected_eta


@pytest.mark.parametrize("name", ALL)
def test_friction_anchors_and_rule(name: str) -> None:
    p = PROFILES[name]
    if name in FRICTION_ANCHORS:
        assert (p.coulomb_friction, p.viscous_friction) == FRICTION_ANCHORS[name]
        assert not p.sources["viscous_friction"].startswith("EST: rated")
    else:
        assert p.coulomb_friction == pytest.approx(0.16 * p.rated_torque, abs=1e-9)
        assert p.viscous_friction == pytest.approx(p.rated_torque * p.gear_ratio * 1e-3, abs=1e-9)
        assert p.sources["coulomb_friction"].startswith("EST")
        assert p.sources["viscous_friction"].startswith("EST")


@pytest.mark.parametrize("name", ALL)
def test_derived_quantities_follow_definitions(name: str) -> None:
    p = PROFILES[name]
    assert p.kinematic_ratio == p.gear_ratio + 1
    assert p.torque_constant == pytest.approx(p.motor_kt * p.gear_ratio * p.efficiency, rel=1e-12)
    assert p.armature == pytest.approx(p.rotor_inertia * (p.gear_ratio + 1) ** 2, rel=1e-12)
    # peak current is the (EST) current that produces the start/stop peak torque
    assert p.torque_from_current(p.peak_current) == pytest.approx(p.peak_torque, rel=1e-12)


@pytest.mark.parametrize("name", ALL)
@pytest.mark.parametrize("amps", [-7.5, -0.1, 0.0, 0.25, 3.0, 12.0])
def test_current_torque_round_trip(name: str, amps: float) -> None:
    p = PROFILES[name]
    nm = p.torque_from_current(amps)
    assert p.current_from_torque(nm) == pytest.approx(amps, rel=1e-12, abs=1e-15)
    assert p.torque_from_current(p.current_from_torque(amps * 10)) == pytest.approx(amps * 10)
    assert math.copysign(1, nm) == math.copysign(1, amps) or amps == 0


def test_erob80h100_pinned_values() -> None:
    p = PROFILES["eRob80H100"]
    assert p.size == 80 and p.gear_ratio == 100 and p.kinematic_ratio == 101
    assert p.rated_torque == 31.0
    assert p.peak_torque == 70.0
    assert p.max_torque == 143.0
    assert p.max_speed == pytest.approx(30 * 2 * math.pi / 60)
    assert p.max_speed == pytest.approx(math.pi)
    assert p.rotor_inertia == 6.74e-5
    assert p.motor_kt == 0.134
    assert p.efficiency == 0.65
    assert p.rated_current == 3.4
    assert p.torque_constant == pytest.approx(8.71)
    assert p.armature == pytest.approx(6.74e-5 * 101**2)
    assert p.armature == pytest.approx(0.68755, rel=1e-4)
    assert p.peak_current == pytest.approx(70 / 8.71)
    assert p.peak_current == pytest.approx(8.037, rel=1e-3)
    assert p.coulomb_friction == 4.5
    assert p.viscous_friction == 9.57
    assert p.torque_from_current(1.0) == pytest.approx(8.71)
    assert p.current_from_torque(31.0) == pytest.approx(3.559, rel=1e-3)


def test_other_pinned_values() -> None:
    p70 = PROFILES["eRob70H100"]
    assert p70.torque_constant == pytest.approx(8.58)
    assert p70.armature == pytest.approx(2.27e-5 * 101**2)
    p50 = PROFILES["eRob80H50"]
    assert p50.torque_constant == pytest.approx(4.69)
    p110 = PROFILES["eRob110H160"]
    assert p110.max_speed == pytest.approx(18.75 * RPM)
    assert p110.armature == pytest.approx(3.086e-4 * 161**2)
    p142 = PROFILES["eRob142H120"]
    assert p142.max_speed == pytest.approx(16.7 * RPM)
    assert p142.coulomb_friction == pytest.approx(28.48)
    assert p142.viscous_friction == pytest.approx(21.36)
    assert PROFILES["eRob90H80"].sources["rated_torque"].startswith("EST")
    assert PROFILES["eRob90H100"].sources["rated_torque"].startswith("PUB")


def test_profiles_are_frozen_and_hashable() -> None:
    p = PROFILES[DEFAULT_MODEL]
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.rated_torque = 1.0  # type: ignore[misc]
    with pytest.raises(TypeError):
        PROFILES["x"] = p  # type: ignore[index]
    assert hash(p) == hash(profile(DEFAULT_MODEL))


# --- lookup ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "alias",
    [
        "eRob80H100",
        "erob80h100",
        "EROB80H100",
        "erob80-100",
        "80H100",
        "80h100",
        "eRob80:100",
        "eRob80H-100",
        " erob 80 h 100 ",
        "80_100",
    ],
)
def test_lookup_aliases(alias: str) -> None:
    assert profile(alias) is PROFILES["eRob80H100"]


def test_lookup_other_sizes() -> None:
    assert profile("erob142-160") is PROFILES["eRob142H160"]
    assert profile("70h50") is PROFILES["eRob70H50"]
    assert profile("eRob110:120") is PROFILES["eRob110H120"]


@pytest.mark.parametrize("bad", ["eRob80", "eRob80H999", "eRob70H160", "foo", "", "80H100x"])
def test_unknown_model_lists_available(bad: str) -> None:
    with pytest.raises(ConfigError) as info:
        profile(bad)
    text = str(info.value)
    assert repr(bad) in text
    for name in PROFILES:
        assert repr(name) in text
    assert info.value.key == "model"
    assert tuple(info.value.allowed) == tuple(PROFILES)  # type: ignore[arg-type]


def test_unknown_model_not_a_string() -> None:
    with pytest.raises(ConfigError):
        profile(80)  # type: ignore[arg-type]


# --- overrides -------------------------------------------------------------------------------


def test_with_overrides_replaces_and_marks_source() -> None:
    base = PROFILES[DEFAULT_MODEL]
    p = base.with_overrides(efficiency=0.6, viscous_friction=3, rotor_inertia=9.5e-5)
    assert p is not base
    assert p.efficiency == 0.6
    assert p.viscous_friction == 3.0 and isinstance(p.viscous_friction, float)
    assert p.torque_constant == pytest.approx(0.134 * 100 * 0.6)
    assert p.armature == pytest.approx(9.5e-5 * 101**2)
    assert p.sources["efficiency"].startswith("CFG")
    assert p.sources["rated_torque"] == base.sources["rated_torque"]
    # the table itself is untouched
    assert base.efficiency == 0.65
    assert PROFILES[DEFAULT_MODEL].viscous_friction == 9.57
    assert base.with_overrides() is base


def test_with_overrides_friction_may_be_zero() -> None:
    p = PROFILES[DEFAULT_MODEL].with_overrides(coulomb_friction=0, viscous_friction=0.0)
    assert p.coulomb_friction == 0.0 and p.viscous_friction == 0.0


def test_with_overrides_unknown_key_lists_allowed() -> None:
    with pytest.raises(ConfigError) as info:
        PROFILES[DEFAULT_MODEL].with_overrides(ratted_torque=30)
    text = str(info.value)
    assert "'ratted_torque'" in text
    for key in PHYSICAL:
        assert repr(key) in text
    assert "'sources'" not in text
    assert info.value.key == "ratted_torque"
    with pytest.raises(ConfigError):
        PROFILES[DEFAULT_MODEL].with_overrides(sources={})


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("rated_torque", 0),
        ("rated_torque", -1.0),
        ("peak_current", 0.0),
        ("rotor_inertia", -6.74e-5),
        ("max_speed", float("nan")),
        ("max_speed", float("inf")),
        ("motor_kt", "0.134"),
        ("motor_kt", True),
        ("efficiency", 0.0),
        ("efficiency", 1.2),
        ("coulomb_friction", -0.1),
        ("viscous_friction", -1),
        ("gear_ratio", 0),
        ("gear_ratio", 100.5),
        ("size", -80),
        ("model", ""),
    ],
)
def test_with_overrides_rejects_bad_values(key: str, value: object) -> None:
    with pytest.raises(ConfigError) as info:
        PROFILES[DEFAULT_MODEL].with_overrides(**{key: value})
    assert info.value.key == key


def test_with_overrides_checks_torque_order() -> None:
    with pytest.raises(ConfigError) as info:
        PROFILES[DEFAULT_MODEL].with_overrides(rated_torque=80)
    assert info.value.key == "peak_torque"
    with pytest.raises(ConfigError) as info:
        PROFILES[DEFAULT_MODEL].with_overrides(peak_torque=150)
    assert info.value.key == "max_torque"
    ok = PROFILES[DEFAULT_MODEL].with_overrides(peak_torque=150, max_torque=150)
    assert ok.peak_torque == 150.0


def test_direct_construction_is_validated() -> None:
    good: dict[str, object] = {
        "model": "eRobX", "size": 80, "gear_ratio": 100, "rated_torque": 1, "peak_torque": 2,
        "max_torque": 3, "max_speed": 1, "motor_kt": 0.1, "efficiency": 0.6, "rated_current": 1,
        "peak_current": 2, "rotor_inertia": 1e-5, "coulomb_friction": 0.1, "viscous_friction": 0.1,
    }  # fmt: skip
    p = ErobProfile(**good)  # type: ignore[arg-type]
    assert dict(p.sources) == {}
    with pytest.raises(ConfigError):
        ErobProfile(**{**good, "max_speed": 0})  # type: ignore[arg-type]
