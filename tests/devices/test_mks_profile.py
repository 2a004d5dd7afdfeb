"""MKS SERVO42D/57D physical profiles: data, sources, derived quantities, lookup and overrides."""

from __future__ import annotations

import math

import pytest

from joints.devices.mks.params import model_params
from joints.devices.mks.profile import DEFAULT_MODEL, PROFILES, MksProfile, profile
from joints.errors import ConfigError

KINDS = ("PUB", "MEAS", "CFG", "EST")


@pytest.mark.parametrize("p", PROFILES.values(), ids=list(PROFILES))
def test_every_number_has_a_source_with_its_kind(p: MksProfile) -> None:
    numbers = [f for f in MksProfile.__dataclass_fields__ if f != "sources"]
    assert set(p.sources) == set(numbers)
    for name, text in p.sources.items():
        assert text.startswith(KINDS), (name, text)


@pytest.mark.parametrize("p", PROFILES.values(), ids=list(PROFILES))
def test_profile_agrees_with_the_parameters(p: MksProfile) -> None:
    params = model_params(f"mks-{p.model.lower()}")
    assert params["working_current"].maximum == round(p.max_working_current * 1000)
    assert params["working_current"].default == round(p.default_working_current * 1000)
    assert params["home_current"].default == round(p.default_home_current * 1000)


def test_device_facts_numbers() -> None:
    d42, d57 = PROFILES["SERVO42D"], PROFILES["SERVO57D"]
    assert (d42.encoder_counts, d42.full_steps) == (16384, 200)
    assert (d42.holding_torque, d42.rated_current) == (0.59, 2.0)
    assert (d57.holding_torque, d57.rated_current) == (3.0, 4.2)
    assert (d42.limit_inputs, d57.limit_inputs) == (1, 2)
    # facts 3: no-load ~780 rpm (42D) and ~320 rpm (57D) at 24 V
    assert d42.no_load_rpm == pytest.approx(780, rel=0.01)
    assert d57.no_load_rpm == pytest.approx(320, rel=0.01)
    # facts 3: >180 degrees within 300 ms
    assert (d42.stall_error, d42.stall_time) == (math.pi, 0.3)
    assert d42.armature == d42.rotor_inertia


def test_torque_model() -> None:
    p = PROFILES["SERVO42D"]
    assert p.peak_torque(1.6) == pytest.approx(0.472)  # facts 4: ~0.47 N*m at the default 1.6 A
    assert p.peak_torque(3.0) == p.holding_torque  # capped above the rated current
    assert p.available_torque(0.0, 1.6) == p.peak_torque(1.6)
    assert p.available_torque(p.no_load_speed / 2, 1.6) == pytest.approx(p.peak_torque(1.6) / 2)
    assert p.available_torque(-2 * p.no_load_speed, 1.6) == 0.0
    # the 600 rpm test case is below the 42D's modelled no-load speed
    assert p.available_torque(600 * 2 * math.pi / 60, 1.6) > 0


@pytest.mark.parametrize("name,model", [("SERVO42D", "SERVO42D"), ("mks-servo42d", "SERVO42D"),
                                        ("MKS SERVO57D", "SERVO57D"), ("servo-57d", "SERVO57D"), ("42d", "SERVO42D")])
def test_lookup(name: str, model: str) -> None:
    assert profile(name).model == model
    assert DEFAULT_MODEL in PROFILES


@pytest.mark.parametrize("bad", ["SERVO28D", "erob80", "", 42])
def test_unknown_model(bad: object) -> None:
    with pytest.raises(ConfigError):
        profile(bad)  # type: ignore[arg-type]


def test_overrides_are_validated_and_recorded() -> None:
    p = PROFILES["SERVO57D"].with_overrides(back_emf_constant=0.3)
    assert p.no_load_rpm == pytest.approx(24 / 0.3 * 60 / (2 * math.pi))
    assert p.sources["back_emf_constant"].startswith("CFG")
    with pytest.raises(ConfigError):
        PROFILES["SERVO57D"].with_overrides(bogus=1)
    with pytest.raises(ConfigError):
        PROFILES["SERVO42D"].with_overrides(rotor_inertia=-1.0)
    with pytest.raises(ConfigError):
        PROFILES["SERVO42D"].with_overrides(default_working_current=4.0)
    with pytest.raises(ConfigError):
        PROFILES["SERVO42D"].with_overrides(limit_inputs=3)
